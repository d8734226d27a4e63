//! `--trace FILE`: every unit of work of one run, as Chrome trace-event JSON
//! (it opens in Perfetto and `chrome://tracing`); the lab's scaling model
//! (`lab/src/model.rs`, `scripts/scaling-model`) replays it.
//!
//! Three lanes move strips: `read` (the reader thread), `filter` (the
//! coordinator) and `write` (the writer thread). Each strip is one *segment*
//! of each lane, in strip order; inside a segment the lane's thread runs
//! serial code and *regions*, parallel loops whose *tasks* run on the pool.
//! A fourth lane, `decode`, is the reader's decoding ahead: a segment per
//! block row, each a task of its own, many at once.
//! Every event carries its id and the ids of the events it depends on:
//! a segment the lane's previous segment (not a `decode`) (and, for `filter`, the `read` of
//! its strip; for `write`, the `filter` segment that made its rows; for a
//! `read`, the `decode` of each block row it is the first to hand over; for
//! a `decode`, the `read` that gave its slot back), a region its segment, a
//! task its region.
//!
//! Off by default, and then a span costs one relaxed atomic load. The
//! recorder is process-wide (one traced run at a time, as the command line
//! makes); [`start`] clears it and [`Session::finish`] takes its events.

use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use serde::Serialize;

use crate::error::{Error, Result};

static ON: AtomicBool = AtomicBool::new(false);
static NEXT_ID: AtomicU64 = AtomicU64::new(1);
static NEXT_TID: AtomicU64 = AtomicU64::new(1);
static RECORDER: Mutex<Option<Recorder>> = Mutex::new(None);

thread_local! {
    static TID: u64 = NEXT_TID.fetch_add(1, Ordering::Relaxed);
    /// The lane segment this thread is in (regions opened here belong to it).
    static SEGMENT: Cell<u64> = const { Cell::new(0) };
}

struct Recorder {
    start: Instant,
    events: Vec<Event>,
    /// Dependencies found while a segment ran ([`wait_for`]): (segment, what
    /// it waited for).
    waits: Vec<(u64, u64)>,
}

/// One event: a complete span (`ph: "X"`), times in microseconds.
#[derive(Clone, Debug, Serialize, serde::Deserialize, PartialEq)]
pub struct Event {
    /// What ran (`decode`, `classify`, ...; a segment is named for its lane).
    pub name: String,
    /// Its kind: `segment`, `region` or `task`.
    pub cat: String,
    /// Always `X` (a span with a duration).
    pub ph: String,
    /// Start, µs from the start of the session.
    pub ts: f64,
    /// Duration, µs.
    pub dur: f64,
    /// Process id (1).
    pub pid: u32,
    /// Thread (1, 2, ... in the order threads first recorded).
    pub tid: u64,
    /// Ids, lane, strip and dependencies.
    pub args: Args,
}

/// What the scaling model reads from an event.
#[derive(Clone, Debug, Default, Serialize, serde::Deserialize, PartialEq)]
pub struct Args {
    /// This event's id.
    pub id: u64,
    /// `read`, `filter` or `write` (segments and the regions in them).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub lane: String,
    /// The strip (segments): `read` and `filter` count input strips, `write`
    /// gives the `filter` strip whose rows it writes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub strip: Option<usize>,
    /// The events this one waits for.
    #[serde(default)]
    pub deps: Vec<u64>,
}

/// Whether a session is recording.
#[inline]
pub fn on() -> bool {
    ON.load(Ordering::Relaxed)
}

/// A recording session; dropping it without [`Session::finish`] discards it.
pub struct Session(());

/// Start recording (events of an earlier session are discarded).
pub fn start() -> Session {
    if let Ok(mut r) = RECORDER.lock() {
        *r = Some(Recorder {
            start: Instant::now(),
            events: Vec::new(),
            waits: Vec::new(),
        });
    }
    ON.store(true, Ordering::Relaxed);
    Session(())
}

impl Session {
    /// Stop recording; the events, in the order they ended.
    pub fn finish(self) -> Vec<Event> {
        ON.store(false, Ordering::Relaxed);
        let (mut events, waits) = RECORDER
            .lock()
            .ok()
            .and_then(|mut r| r.take())
            .map(|r| (r.events, r.waits))
            .unwrap_or_default();
        let mut found: std::collections::HashMap<u64, Vec<u64>> = Default::default();
        for (seg, dep) in waits {
            found.entry(seg).or_default().push(dep);
        }
        for e in &mut events {
            if let Some(d) = found.remove(&e.args.id) {
                e.args.deps.extend(d);
            }
        }
        link(&mut events);
        events
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        ON.store(false, Ordering::Relaxed);
    }
}

/// Fill in the segments' dependencies: the lane's previous segment, and for
/// `filter` the `read` of its strip, for `write` the `filter` that made its
/// rows (the model's constraints, so that the file says them too).
fn link(events: &mut [Event]) {
    let mut order: Vec<usize> = (0..events.len())
        .filter(|&i| events[i].cat == "segment")
        .collect();
    order.sort_by(|&a, &b| events[a].ts.total_cmp(&events[b].ts));
    let mut first: std::collections::HashMap<(String, usize), u64> = Default::default();
    for &i in &order {
        let a = &events[i].args;
        if let Some(k) = a.strip {
            first.entry((a.lane.clone(), k)).or_insert(a.id);
        }
    }
    let mut last: std::collections::HashMap<String, u64> = Default::default();
    for &i in &order {
        let (lane, strip, id) = {
            let a = &events[i].args;
            (a.lane.clone(), a.strip, a.id)
        };
        let upstream = match lane.as_str() {
            "filter" => Some("read"),
            "write" => Some("filter"),
            _ => None,
        };
        // Block rows decode at once: a decode waits for no other.
        let mut deps: Vec<u64> = if lane == "decode" {
            Vec::new()
        } else {
            last.get(&lane).copied().into_iter().collect()
        };
        if let (Some(up), Some(k)) = (upstream, strip) {
            deps.extend(first.get(&(up.to_string(), k)).copied());
        }
        events[i].args.deps.extend(deps);
        last.insert(lane, id);
    }
}

/// An open span: recorded when dropped.
pub struct Span {
    open: Option<Open>,
}

struct Open {
    name: &'static str,
    cat: &'static str,
    begin: Instant,
    args: Args,
    /// The thread's segment before this one (segments only).
    outer: Option<u64>,
}

fn open(name: &'static str, cat: &'static str, args: Args) -> Span {
    Span {
        open: Some(Open {
            name,
            cat,
            begin: Instant::now(),
            args,
            outer: None,
        }),
    }
}

impl Span {
    const OFF: Span = Span { open: None };

    /// This span's id (0 when not recording).
    pub fn id(&self) -> u64 {
        self.open.as_ref().map_or(0, |o| o.args.id)
    }

    /// A task of this region, on whatever thread runs it.
    pub fn task(&self, name: &'static str) -> Span {
        match &self.open {
            Some(o) if on() => open(
                name,
                "task",
                Args {
                    id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
                    deps: vec![o.args.id],
                    ..Args::default()
                },
            ),
            _ => Span::OFF,
        }
    }
}

impl Drop for Span {
    fn drop(&mut self) {
        let Some(o) = self.open.take() else { return };
        if let Some(outer) = o.outer {
            SEGMENT.with(|s| s.set(outer));
        }
        let end = Instant::now();
        let tid = TID.with(|t| *t);
        if let Ok(mut r) = RECORDER.lock() {
            if let Some(r) = r.as_mut() {
                let ts = o.begin.saturating_duration_since(r.start).as_secs_f64() * 1e6;
                let dur = end.saturating_duration_since(o.begin).as_secs_f64() * 1e6;
                r.events.push(Event {
                    name: o.name.into(),
                    cat: o.cat.into(),
                    ph: "X".into(),
                    ts,
                    dur,
                    pid: 1,
                    tid,
                    args: o.args,
                });
            }
        }
    }
}

/// A segment of `lane` (`read`, `filter`, `write`) for `strip`, waiting for
/// `deps` (besides the lane's previous segment, which the model adds).
pub fn segment(lane: &'static str, strip: usize, deps: &[u64]) -> Span {
    if !on() {
        return Span::OFF;
    }
    let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
    let outer = SEGMENT.with(|s| s.replace(id));
    let mut span = open(
        lane,
        "segment",
        Args {
            id,
            lane: lane.into(),
            strip: Some(strip),
            deps: deps.iter().copied().filter(|&d| d != 0).collect(),
        },
    );
    if let Some(o) = span.open.as_mut() {
        o.outer = Some(outer);
    }
    span
}

/// The segment this thread is in (0 when not recording or in none).
pub fn current_segment() -> u64 {
    if !on() {
        return 0;
    }
    SEGMENT.with(|s| s.get())
}

/// Run `f` on this thread as part of segment `seg` (one that
/// [`current_segment`] gave on another thread): the regions a joined
/// closure opens on a worker belong to the segment that joined.
pub fn in_segment<R>(seg: u64, f: impl FnOnce() -> R) -> R {
    if !on() {
        return f();
    }
    let outer = SEGMENT.with(|s| s.replace(seg));
    let r = f();
    SEGMENT.with(|s| s.set(outer));
    r
}

/// The segment this thread is in waited for event `id` (found while it ran,
/// e.g. the decoding of the rows it hands over).
pub fn wait_for(id: u64) {
    let seg = current_segment();
    if seg == 0 || id == 0 {
        return;
    }
    if let Ok(mut r) = RECORDER.lock() {
        if let Some(r) = r.as_mut() {
            r.waits.push((seg, id));
        }
    }
}

/// A parallel loop opened on this thread, inside its current segment; its
/// tasks are made with [`Span::task`].
pub fn region(name: &'static str) -> Span {
    if !on() {
        return Span::OFF;
    }
    let seg = SEGMENT.with(|s| s.get());
    open(
        name,
        "region",
        Args {
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            deps: if seg == 0 { Vec::new() } else { vec![seg] },
            ..Args::default()
        },
    )
}

/// Write `events` to `path` as a Chrome trace (`{"traceEvents": [...]}`).
pub fn write(path: &std::path::Path, events: &[Event]) -> Result<()> {
    #[derive(Serialize)]
    struct File<'a> {
        #[serde(rename = "traceEvents")]
        trace_events: &'a [Event],
        #[serde(rename = "displayTimeUnit")]
        display_time_unit: &'static str,
    }
    let text = serde_json::to_string(&File {
        trace_events: events,
        display_time_unit: "ms",
    })
    .map_err(|e| Error::Internal(format!("trace: {e}")))?;
    crate::io::write_file(path, text.as_bytes())
}

/// Read a trace [`write()`] wrote.
pub fn read(path: &std::path::Path) -> Result<Vec<Event>> {
    #[derive(serde::Deserialize)]
    struct File {
        #[serde(rename = "traceEvents")]
        trace_events: Vec<Event>,
    }
    let text = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let f: File = serde_json::from_slice(&text).map_err(|e| Error::InvalidFile {
        path: path.into(),
        reason: format!("not an epfilt trace: {e}"),
    })?;
    Ok(f.trace_events)
}
