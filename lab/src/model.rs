//! The scaling model: work `T1`, span `T∞` and the wall time on `P` cores,
//! from replaying a trace's units of work with the pipeline's constraints.
//!
//! A trace (`epfilt filter --trace`, [`epfilt::trace`]) is three lanes of segments, one per strip, each a
//! sequence of serial pieces (run on the lane's own thread) and regions
//! (parallel loops whose tasks run on any core). The replay keeps:
//!
//! * each lane's strips in order, one segment at a time;
//! * `filter` of strip `k` after `read` of strip `k`; `write` after the
//!   `filter` segment that made its rows;
//! * the strip queue: `read` of strip `k` starts once `filter` of strip
//!   `k - QUEUE` has started (the channel holds [`QUEUE`] strips);
//! * a region ends when its last task does;
//! * what a segment says it waited for (`args.deps` naming another lane's
//!   segment): a `read` that hands over a new batch waits for its `decode`
//!   (the reader's decoder lane, a segment per batch), and a `decode` for the
//!   `read` that gave its buffer back.
//!
//! Units are given to free cores first come, first served (a lane's next
//! piece and a region's tasks as they become ready).
//!
//! **The join.** A parallel loop on `P` cores ends some time after its last
//! task: the threads that waited are woken, idle workers look for work and
//! go to sleep. A 1-thread trace cannot show that, so the replay adds
//! [`JOIN_S`] `* log2 P` to its lane after every region of the read, filter
//! and write lanes (the decoding lane's block rows are spawned, not joined).
//! The constant was fitted on the one 16-core machine measured (the time its
//! runs took beyond the replay without it, over their regions), and it
//! brought the model closer to runs it was not fitted on; `scripts/
//! bench-scaling` prints both. How long a wake-up takes depends on the
//! machine: `--join-us` sets it. [`Model::span`] is the
//! replay on unbounded cores without it: the trace's own critical path.
//!
//! **Two strips in flight** ([`Model::from_events_in_flight`], what
//! `GaussianStage::run` does from two threads), from a trace taken with one:
//! each filter segment is cut by its tasks' names into four parts, each on
//! a lane of its own: the input's ledger, the first passes (box luminance,
//! classification: [`FRONT`]), the rest, and the finishing of rows. Strip
//! `k`'s ledger waits for strip `k - 1`'s first passes and strip `k - 2`'s
//! finishing (a strip's call begins when the last one's has ended); its rest
//! runs beside strip `k + 1`'s first passes, once that strip's ledger is in;
//! its rows are finished after both (the join).
//!
//! Not modelled: memory bandwidth and caches (each unit takes on `P` cores
//! the time it took in the trace), SMT, the operating system's scheduling
//! of more threads than cores (the decoding pool's beside the filter's),
//! and the output queue (the writer is never far behind). `scripts/
//! bench-scaling` prints the prediction beside measured times.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap, HashMap, VecDeque};

use anyhow::{anyhow, Result};
use epfilt::trace::Event;

/// What the end of a parallel loop costs its lane, in seconds per doubling
/// of the cores (see the module's header).
pub const JOIN_S: f64 = 44e-6;

/// Strips the reader may hold ahead of the filter (the strip channel's
/// capacity, `pipeline::runner`).
pub const QUEUE: usize = 2;

/// One piece of a segment.
#[derive(Clone, Debug, PartialEq)]
pub enum Phase {
    /// Serial code on the lane's thread, seconds.
    Serial(f64),
    /// A parallel loop: its tasks' seconds.
    Region(Vec<f64>),
}

/// One lane's work on one strip.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    /// 0 read, 1 filter, 2 write, 3 decode.
    pub lane: usize,
    /// The strip (`write`: the filter strip whose rows it writes; `decode`:
    /// the batch).
    pub strip: usize,
    /// Its pieces, in order.
    pub phases: Vec<Phase>,
    /// Segments (indices) that must be done before it starts, besides the
    /// lanes' rules: what the trace says it waited for.
    pub after: Vec<usize>,
}

/// The lanes, by their names in a trace (the last only in a model of two
/// strips in flight).
pub const LANES: [&str; 7] = [
    "read",
    "filter",
    "write",
    "decode",
    "filter rest",
    "filter in",
    "filter out",
];

/// The decode lane: its segments (block rows decoding ahead, each a task on
/// the pool) run at once, started in order.
const DECODE: usize = 3;

/// With two strips in flight, the lane of a filter strip's later passes
/// (its rest: spread, base rows, upsampling), run beside the next strip's
/// first passes (`rayon::join` in `GaussianStage::run`).
pub const BACK: usize = 4;

/// With two strips in flight, the lane of the skeleton's work before the
/// stage's (the input's ledger) and after it (finishing the rows made):
/// they run on their own, between one join and the next.
const PRE: usize = 5;
const FIN: usize = 6;

/// The tasks of a strip's first passes: what the next strip runs beside
/// the rest of this one (two strips in flight).
pub const FRONT: [&str; 3] = ["box luminance", "classify", "classify pass"];

/// The skeleton's tasks before a strip's passes and after them.
const BEFORE: [&str; 1] = ["ledger in"];
const AFTER: [&str; 1] = ["finish rows"];

/// The part of a filter strip a task of `name` is in, with two strips in
/// flight: 0 before the passes, 1 the first passes, 2 the rest, 3 after.
fn part(name: &str) -> usize {
    if BEFORE.contains(&name) {
        0
    } else if FRONT.contains(&name) {
        1
    } else if AFTER.contains(&name) {
        3
    } else {
        2
    }
}

/// The lane of each part of a filter strip ([`part`]).
const PART_LANES: [usize; 4] = [PRE, 1, BACK, FIN];

/// A run to replay.
#[derive(Clone, Debug, Default)]
pub struct Model {
    /// Segments of every lane, each lane's in strip order.
    pub segments: Vec<Segment>,
    /// Serial seconds by lane.
    pub serial_by_lane: BTreeMap<String, f64>,
    /// Seconds in the tasks of each name (a region may hold tasks of two
    /// loops run side by side, each named for its work).
    pub parallel_by_task: BTreeMap<String, f64>,
}

impl Model {
    /// The model of a trace's events.
    pub fn from_events(events: &[Event]) -> Result<Model> {
        Self::build(events, false)
    }

    /// The model of a trace's events with two filter strips in flight (see
    /// the module's header).
    pub fn from_events_in_flight(events: &[Event]) -> Result<Model> {
        Self::build(events, true)
    }

    fn build(events: &[Event], split: bool) -> Result<Model> {
        let bad = |why: String| anyhow!("trace: {why}");
        // Each task's seconds and its part of a strip ([`part`]).
        let mut tasks: HashMap<u64, Vec<(f64, usize)>> = HashMap::new();
        let mut regions: HashMap<u64, Vec<&Event>> = HashMap::new();
        let mut by_task: BTreeMap<String, f64> = BTreeMap::new();
        for e in events {
            match e.cat.as_str() {
                "task" => {
                    let r = *e
                        .args
                        .deps
                        .first()
                        .ok_or_else(|| bad("a task without its region".into()))?;
                    tasks
                        .entry(r)
                        .or_default()
                        .push((e.dur * 1e-6, part(&e.name)));
                    *by_task.entry(e.name.clone()).or_default() += e.dur * 1e-6;
                }
                "region" => {
                    if let Some(&s) = e.args.deps.first() {
                        regions.entry(s).or_default().push(e);
                    }
                }
                _ => {}
            }
        }
        let mut model = Model {
            parallel_by_task: by_task,
            ..Model::default()
        };
        let mut segs: Vec<&Event> = events.iter().filter(|e| e.cat == "segment").collect();
        segs.sort_by(|a, b| a.ts.total_cmp(&b.ts));
        let no_deps = Vec::new();
        let mut ids = Vec::with_capacity(segs.len());
        let mut deps = Vec::with_capacity(segs.len());
        for seg in segs {
            let lane = LANES[..BACK]
                .iter()
                .position(|l| *l == seg.args.lane)
                .ok_or_else(|| bad(format!("unknown lane {:?}", seg.args.lane)))?;
            let strip = seg
                .args
                .strip
                .ok_or_else(|| bad("a segment without its strip".into()))?;
            let mut inner = regions.remove(&seg.args.id).unwrap_or_default();
            inner.sort_by(|a, b| a.ts.total_cmp(&b.ts));
            // The segment's phases; with `split` those of each part.
            let split = split && lane == 1;
            let mut parts: [Vec<Phase>; 4] = Default::default();
            let mut at = seg.ts;
            let mut serial = 0.0;
            for r in inner {
                let gap = (r.ts - at).max(0.0) * 1e-6;
                let t = tasks.remove(&r.args.id).unwrap_or_default();
                // What the region took beyond its tasks (handing them out,
                // joining) stays on the lane.
                let over = (r.dur * 1e-6 - t.iter().map(|t| t.0).sum::<f64>()).max(0.0);
                serial += gap + over;
                // The serial time goes with the first part that has tasks.
                let mut serial_left = gap + over;
                for (k, side) in parts.iter_mut().enumerate() {
                    let mine: Vec<f64> = t
                        .iter()
                        .filter(|t| !split || t.1 == k)
                        .map(|t| t.0)
                        .collect();
                    if mine.is_empty() || (!split && k != 1) {
                        continue;
                    }
                    side.push(Phase::Serial(serial_left));
                    side.push(Phase::Region(mine));
                    serial_left = 0.0;
                }
                if serial_left > 0.0 {
                    parts[1].push(Phase::Serial(serial_left));
                }
                at = at.max(r.ts + r.dur);
            }
            let tail = (seg.ts + seg.dur - at).max(0.0) * 1e-6;
            serial += tail;
            parts[if split { 3 } else { 1 }].push(Phase::Serial(tail));
            *model.serial_by_lane.entry(LANES[lane].into()).or_default() += serial;
            if !split {
                ids.push(seg.args.id);
                deps.push(&seg.args.deps);
                model.segments.push(Segment {
                    lane,
                    strip,
                    phases: std::mem::take(&mut parts[1]),
                    after: Vec::new(),
                });
                continue;
            }
            // Each part on its lane; the part before takes the segment's
            // place (what waits for it and what it waits for).
            for (k, phases) in parts.into_iter().enumerate() {
                ids.push(if k == 0 { seg.args.id } else { u64::MAX });
                deps.push(if k == 0 { &seg.args.deps } else { &no_deps });
                let phases = if phases.is_empty() {
                    vec![Phase::Serial(0.0)]
                } else {
                    phases
                };
                model.segments.push(Segment {
                    lane: PART_LANES[k],
                    strip,
                    phases,
                    after: Vec::new(),
                });
            }
        }
        let at: HashMap<u64, usize> = ids.iter().enumerate().map(|(i, &id)| (id, i)).collect();
        for (seg, d) in model.segments.iter_mut().zip(deps) {
            seg.after = d.iter().filter_map(|id| at.get(id).copied()).collect();
        }
        Ok(model)
    }

    /// Total seconds of work, `T1`.
    pub fn work(&self) -> f64 {
        self.segments
            .iter()
            .flat_map(|s| &s.phases)
            .map(|p| match p {
                Phase::Serial(d) => *d,
                Phase::Region(t) => t.iter().sum(),
            })
            .sum()
    }

    /// The critical path, `T∞`: the replay with a core for every unit (and
    /// no join cost).
    pub fn span(&self) -> f64 {
        self.replay(usize::MAX)
    }

    /// The wall time on `cores` cores, the units alone (no join cost).
    pub fn replay(&self, cores: usize) -> f64 {
        self.replay_joined(cores, 0.0)
    }

    /// The wall time on `cores` cores, each region of the read, filter and
    /// write lanes followed by `join_s * log2(cores)` on its lane ([`JOIN_S`]).
    pub fn replay_joined(&self, cores: usize, join_s: f64) -> f64 {
        let cores = cores.max(1);
        let join = join_s * (cores as f64).log2();
        Replay::new(self, join).run(cores)
    }

    /// Regions (with tasks) of the lanes that join them: what the join cost
    /// multiplies.
    pub fn joins(&self) -> usize {
        self.segments
            .iter()
            .filter(|s| s.lane != DECODE)
            .flat_map(|s| &s.phases)
            .filter(|p| matches!(p, Phase::Region(t) if !t.is_empty()))
            .count()
    }
}

/// What the model predicts for a trace.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Prediction {
    /// Total work, seconds (`T1`).
    pub work_s: f64,
    /// Critical path, seconds (`T∞`).
    pub span_s: f64,
    /// `T1 / T∞`: the most cores that can help.
    pub parallelism: f64,
    /// The join cost used, seconds per doubling of the cores ([`JOIN_S`]).
    pub join_s: f64,
    /// Regions whose end costs the join.
    pub joins: usize,
    /// Predicted wall time on each number of cores.
    pub predicted_s: BTreeMap<String, f64>,
    /// Predicted speed-up over 1 core.
    pub speedup: BTreeMap<String, f64>,
    /// Serial seconds of each lane (what no core count shortens).
    pub serial_s: BTreeMap<String, f64>,
    /// Seconds in the tasks of each parallel loop.
    pub parallel_s: BTreeMap<String, f64>,
}

impl Prediction {
    /// The model's figures for `cores`, with a join cost of `join_s` per
    /// doubling of the cores ([`JOIN_S`]; 0: none).
    pub fn of(m: &Model, cores: &[usize], join_s: f64) -> Prediction {
        let one = m.replay(1);
        let span = m.span();
        let mut predicted = BTreeMap::new();
        let mut speedup = BTreeMap::new();
        for &p in cores {
            let t = m.replay_joined(p, join_s);
            predicted.insert(p.to_string(), t);
            speedup.insert(p.to_string(), one / t.max(1e-12));
        }
        Prediction {
            work_s: m.work(),
            span_s: span,
            parallelism: m.work() / span.max(1e-12),
            join_s,
            joins: m.joins(),
            predicted_s: predicted,
            speedup,
            serial_s: m.serial_by_lane.clone(),
            parallel_s: m.parallel_by_task.clone(),
        }
    }

    /// The figures as a few lines of text.
    pub fn table(&self, cores: &[usize]) -> String {
        let mut s = format!(
            "work T1 {:.3} s, span T∞ {:.3} s, parallelism {:.1}\n\
             {} parallel loops joined at {:.0} µs per doubling of the cores\n\n\
             cores  predicted s  speed-up\n",
            self.work_s,
            self.span_s,
            self.parallelism,
            self.joins,
            self.join_s * 1e6
        );
        for p in cores {
            let k = p.to_string();
            s.push_str(&format!(
                "{p:>5}  {:>11.3}  {:>7.2}x\n",
                self.predicted_s[&k], self.speedup[&k]
            ));
        }
        let mut parts: Vec<(String, f64)> = self
            .serial_s
            .iter()
            .map(|(k, v)| (format!("serial: {k} lane"), *v))
            .chain(
                self.parallel_s
                    .iter()
                    .map(|(k, v)| (format!("parallel: {k}"), *v)),
            )
            .collect();
        parts.sort_by(|a, b| b.1.total_cmp(&a.1));
        s.push_str("\nwhere the work is, largest first\n");
        for (k, v) in parts {
            s.push_str(&format!(
                "  {k:<34} {v:>8.3} s  {:>5.1}%\n",
                100.0 * v / self.work_s.max(1e-12)
            ));
        }
        s
    }
}

/// A unit on a core: a lane's serial piece or one task of a region.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Unit {
    Serial(usize),
    /// Task `k` of segment `i`'s current region.
    Task(usize, usize),
}

struct Replay<'a> {
    m: &'a Model,
    /// Each lane's segments in order.
    lanes: [Vec<usize>; LANES.len()],
    /// Per lane: the next segment to start, and the phase it is in.
    next: [usize; LANES.len()],
    phase: Vec<usize>,
    /// Tasks left in the running region of each segment.
    left: Vec<usize>,
    started: Vec<Option<f64>>,
    done: Vec<bool>,
    /// (lane, strip) -> segment.
    index: HashMap<(usize, usize), usize>,
    /// Whether each lane is inside a segment.
    busy: [bool; LANES.len()],
    /// Seconds a lane's serial piece after a region starts with.
    join: f64,
}

impl<'a> Replay<'a> {
    fn new(m: &'a Model, join: f64) -> Self {
        let mut lanes: [Vec<usize>; LANES.len()] = Default::default();
        let mut index = HashMap::new();
        for (i, s) in m.segments.iter().enumerate() {
            lanes[s.lane].push(i);
            index.entry((s.lane, s.strip)).or_insert(i);
        }
        // Decoding starts block rows in order; their segments begin (and
        // end) in any.
        lanes[DECODE].sort_by_key(|&i| m.segments[i].strip);
        let n = m.segments.len();
        Replay {
            m,
            lanes,
            next: [0; LANES.len()],
            phase: vec![0; n],
            left: vec![0; n],
            started: vec![None; n],
            done: vec![false; n],
            index,
            busy: [false; LANES.len()],
            join,
        }
    }

    /// Whether segment `i` may start.
    fn can_start(&self, i: usize) -> bool {
        let s = &self.m.segments[i];
        let done = |lane: usize, strip: usize| {
            self.index.get(&(lane, strip)).is_none_or(|&j| self.done[j])
        };
        // A strip's first segment on the filter lanes: its part before
        // the passes where two strips are in flight.
        let first = |strip: usize| {
            self.index
                .get(&(PRE, strip))
                .or(self.index.get(&(1, strip)))
        };
        let (k, next) = (s.strip, s.strip + 1);
        let by_lane = match s.lane {
            0 => k
                .checked_sub(QUEUE)
                .is_none_or(|j| first(j).is_none_or(|&j| self.started[j].is_some())),
            // Two strips in flight (`GaussianStage::run`): a strip's work
            // begins once the last one's has ended (its first passes and
            // the previous strip's rest, joined, then that strip's rows
            // finished); its rest runs beside the next strip's first passes
            // once that strip's ledger is in; its rows are finished after
            // both.
            PRE => {
                done(0, k)
                    && k.checked_sub(1).is_none_or(|j| done(1, j))
                    && k.checked_sub(2).is_none_or(|j| done(FIN, j))
            }
            1 => done(0, k) && done(PRE, k),
            BACK => done(1, k) && done(PRE, next),
            FIN => done(BACK, k) && done(1, next),
            2 => done(1, k) && done(BACK, k) && done(FIN, k),
            _ => true,
        };
        by_lane && s.after.iter().all(|&j| self.done[j])
    }

    fn run(mut self, cores: usize) -> f64 {
        let mut now = 0.0f64;
        let mut free = cores;
        let mut ready: VecDeque<Unit> = VecDeque::new();
        // (end, unit), earliest first.
        let mut running: BinaryHeap<Reverse<(Ordered, Unit)>> = BinaryHeap::new();
        self.start_lanes(now, &mut ready);
        loop {
            while free > 0 {
                let Some(u) = ready.pop_front() else { break };
                free -= 1;
                running.push(Reverse((Ordered(now + self.duration(u)), u)));
            }
            let Some(Reverse((Ordered(end), u))) = running.pop() else {
                break;
            };
            now = end;
            free += 1;
            self.finish(u, now, &mut ready);
        }
        now
    }

    fn duration(&self, u: Unit) -> f64 {
        match u {
            Unit::Serial(i) => {
                let seg = &self.m.segments[i];
                let p = self.phase[i];
                let joined = seg.lane != DECODE
                    && p > 0
                    && matches!(&seg.phases[p - 1], Phase::Region(t) if !t.is_empty());
                let join = if joined { self.join } else { 0.0 };
                match seg.phases[p] {
                    Phase::Serial(d) => d + join,
                    Phase::Region(_) => join,
                }
            }
            Unit::Task(i, k) => match &self.m.segments[i].phases[self.phase[i]] {
                Phase::Region(t) => t[k],
                Phase::Serial(_) => 0.0,
            },
        }
    }

    /// Start what can start on each idle lane (the decode lane's segments,
    /// block rows decoding as tasks of their own, in order and at once).
    fn start_lanes(&mut self, now: f64, ready: &mut VecDeque<Unit>) {
        let mut again = true;
        while again {
            again = false;
            for lane in 0..LANES.len() {
                if self.busy[lane] {
                    continue;
                }
                let Some(&i) = self.lanes[lane].get(self.next[lane]) else {
                    continue;
                };
                if !self.can_start(i) {
                    continue;
                }
                self.busy[lane] = lane != DECODE;
                self.next[lane] += 1;
                self.started[i] = Some(now);
                self.enter(i, ready);
                again = true;
            }
        }
    }

    /// Segment `i` enters its current phase.
    fn enter(&mut self, i: usize, ready: &mut VecDeque<Unit>) {
        match &self.m.segments[i].phases[self.phase[i]] {
            Phase::Serial(_) => ready.push_back(Unit::Serial(i)),
            Phase::Region(t) if t.is_empty() => ready.push_back(Unit::Serial(i)),
            Phase::Region(t) => {
                self.left[i] = t.len();
                ready.extend((0..t.len()).map(|k| Unit::Task(i, k)));
            }
        }
    }

    fn finish(&mut self, u: Unit, now: f64, ready: &mut VecDeque<Unit>) {
        let i = match u {
            Unit::Serial(i) => i,
            Unit::Task(i, _) => {
                self.left[i] -= 1;
                if self.left[i] > 0 {
                    return;
                }
                i
            }
        };
        self.phase[i] += 1;
        if self.phase[i] < self.m.segments[i].phases.len() {
            self.enter(i, ready);
            return;
        }
        self.done[i] = true;
        self.busy[self.m.segments[i].lane] = false;
        self.start_lanes(now, ready);
    }
}

/// An f64 with a total order (the heap's key).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Ordered(f64);
impl Eq for Ordered {}
impl PartialOrd for Ordered {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Ordered {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&o.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Replays are sums of the given durations: exact in f64 for these.
    const EXACT: f64 = 1e-12;

    fn seg(lane: usize, strip: usize, phases: Vec<Phase>) -> Segment {
        Segment {
            lane,
            strip,
            phases,
            after: Vec::new(),
        }
    }

    /// A replay of `m` with what can start at time 0 started.
    fn at_start(m: &Model) -> (Replay<'_>, VecDeque<Unit>) {
        let mut r = Replay::new(m, 0.0);
        let mut ready = VecDeque::new();
        r.start_lanes(0.0, &mut ready);
        (r, ready)
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= EXACT * b.abs().max(1.0)
    }

    #[test]
    fn a_chain_is_its_own_span_on_any_number_of_cores() {
        // Three serial pieces of one lane: T1 = T∞ = 6.
        let m = Model {
            segments: (0..3)
                .map(|k| seg(1, k, vec![Phase::Serial(k as f64 + 1.0)]))
                .collect(),
            ..Model::default()
        };
        assert!(close(m.work(), 6.0));
        assert!(close(m.span(), 6.0));
        for p in [1, 2, 16] {
            assert!(close(m.replay(p), 6.0), "P = {p}");
        }
    }

    #[test]
    fn a_fork_join_gives_the_textbook_speed_ups() {
        // 1 s serial, 8 tasks of 1 s, 1 s serial: T1 = 10, T∞ = 3.
        let m = Model {
            segments: vec![seg(
                1,
                0,
                vec![
                    Phase::Serial(1.0),
                    Phase::Region(vec![1.0; 8]),
                    Phase::Serial(1.0),
                ],
            )],
            ..Model::default()
        };
        assert!(close(m.work(), 10.0));
        assert!(close(m.span(), 3.0));
        for (p, want) in [(1, 10.0), (2, 6.0), (4, 4.0), (8, 3.0), (64, 3.0)] {
            assert!(close(m.replay(p), want), "P = {p}: {}", m.replay(p));
        }
    }

    #[test]
    fn each_joined_loop_costs_its_lane_the_join_per_doubling_of_the_cores() {
        // The fork-join above, twice on the filter lane, and a decode lane's
        // region (spawned, never joined): the filter's two loops cost
        // `2 j log2 P` more, the decode nothing.
        let join = 0.25;
        let fork_join = || {
            vec![
                Phase::Serial(1.0),
                Phase::Region(vec![1.0; 8]),
                Phase::Serial(1.0),
                Phase::Region(vec![1.0; 8]),
                Phase::Serial(0.0),
            ]
        };
        let m = Model {
            segments: vec![
                seg(DECODE, 0, vec![Phase::Region(vec![0.5])]),
                seg(1, 0, fork_join()),
            ],
            ..Model::default()
        };
        assert_eq!(m.joins(), 2);
        for (p, tasks) in [(1, 16.0), (2, 8.0), (4, 4.0), (8, 2.0)] {
            let plain = m.replay(p);
            let joined = m.replay_joined(p, join);
            let want = 2.0 * join * (p as f64).log2();
            assert!(close(joined - plain, want), "P = {p}: {joined} - {plain}");
            // The decode's half second overlaps the filter's first piece
            // from 2 cores on.
            let decode = if p == 1 { 0.5 } else { 0.0 };
            assert!(close(plain, 2.0 + tasks + decode), "P = {p}: {plain}");
        }
        // The span is the trace's critical path: no join.
        assert!(close(m.span(), 4.0));
        // The prediction carries the constant and the count.
        let pred = Prediction::of(&m, &[1, 4], join);
        assert_eq!((pred.joins, pred.join_s), (2, join));
        assert!(close(pred.predicted_s["4"], 6.0 + 2.0 * join * 2.0));
    }

    #[test]
    fn a_pipeline_of_three_stages_overlaps_its_strips() {
        // n strips, each 1 s of read, filter and write: on one core 3n; on
        // three, the pipeline's fill and drain, n + 2.
        let n = 10;
        let mut segments = Vec::new();
        for k in 0..n {
            for lane in 0..3 {
                segments.push(seg(lane, k, vec![Phase::Serial(1.0)]));
            }
        }
        let m = Model {
            segments,
            ..Model::default()
        };
        assert!(close(m.work(), 3.0 * n as f64));
        assert!(close(m.replay(1), 3.0 * n as f64));
        assert!(close(m.replay(3), n as f64 + 2.0));
        assert!(close(m.span(), n as f64 + 2.0));
    }

    #[test]
    fn the_reader_waits_for_the_strip_queue() {
        // Reading is free, filtering 1 s a strip: the reader may run QUEUE
        // strips ahead of the filter, never more.
        let n = 6;
        let mut segments = Vec::new();
        for k in 0..n {
            segments.push(seg(0, k, vec![Phase::Serial(0.0)]));
            segments.push(seg(1, k, vec![Phase::Serial(1.0)]));
        }
        let m = Model {
            segments,
            ..Model::default()
        };
        let (r, _) = at_start(&m);
        // Only read 0 can start before anything runs.
        assert_eq!(r.next[0], 1);
        assert!(close(m.replay(4), n as f64));
    }

    #[test]
    fn a_decoder_lane_overlaps_the_next_batch_with_this_one() {
        // 4 block rows of one strip each: decoding 2 s (one task), handing
        // over free, filtering 2 s. Each read waits for its block row's
        // decode, each decode for the read that gave its slot back (a window
        // of two). Decoding ahead, block row b + 1 decodes while b is
        // filtered: 2 + 4 * 2 on two cores (the decodes inside the reads
        // would take 16).
        let n = 4;
        let mut segments = Vec::new();
        for b in 0..n {
            // Indices: decode 3b, read 3b + 1, filter 3b + 2.
            let mut decode = seg(DECODE, b, vec![Phase::Region(vec![2.0])]);
            if b >= 2 {
                decode.after = vec![3 * (b - 2) + 1];
            }
            segments.push(decode);
            let mut read = seg(0, b, vec![Phase::Serial(0.0)]);
            read.after = vec![3 * b];
            segments.push(read);
            segments.push(seg(1, b, vec![Phase::Serial(2.0)]));
        }
        let m = Model {
            segments,
            ..Model::default()
        };
        let (r, ready) = at_start(&m);
        // At first the window's two decodes start, at once: read 0 waits.
        assert_eq!((r.next[3], r.next[0]), (2, 0));
        assert_eq!(ready.len(), 2);
        assert!(close(m.work(), 16.0));
        assert!(close(m.replay(1), 16.0));
        assert!(close(m.replay(2), 10.0), "{}", m.replay(2));
        assert!(close(m.span(), 10.0));
    }

    /// An event of `cat` named `name`, `ts` to `ts + dur` µs.
    fn event(cat: &str, name: &str, (ts, dur): (f64, f64), id: u64, deps: Vec<u64>) -> Event {
        Event {
            name: name.into(),
            cat: cat.into(),
            ph: "X".into(),
            ts,
            dur,
            pid: 1,
            tid: 1,
            args: epfilt::trace::Args {
                id,
                lane: if cat == "segment" {
                    "filter".into()
                } else {
                    String::new()
                },
                strip: (cat == "segment").then_some(id as usize / 10),
                deps,
            },
        }
    }

    #[test]
    fn two_strips_in_flight_overlap_a_strips_rest_with_the_next_ones_first_passes() {
        // n filter strips, each a classification of one 1 s task then a
        // scatter of one 1 s task (1 µs = 1 s here: only ratios matter).
        // Built as it is, one strip at a time: 2n on any number of cores.
        // Two in flight: strip k + 1's classification beside strip k's
        // scatter, n + 1 on two cores; one core still takes 2n.
        let n = 5;
        let mut events = Vec::new();
        for k in 0..n as u64 {
            let (seg, t0) = (10 * k, 2.0 * k as f64);
            events.push(event("segment", "filter", (t0, 2.0), seg, vec![]));
            for (j, name) in ["classify", "scatter"].into_iter().enumerate() {
                let (region, ts) = (seg + 1 + 2 * j as u64, t0 + j as f64);
                events.push(event("region", name, (ts, 1.0), region, vec![seg]));
                events.push(event("task", name, (ts, 1.0), region + 1, vec![region]));
            }
        }
        let one = Model::from_events(&events).unwrap();
        let two = Model::from_events_in_flight(&events).unwrap();
        let secs = 1e-6;
        assert_eq!(one.segments.len(), n);
        assert_eq!(two.segments.len(), 4 * n);
        assert!(close(one.work(), two.work()));
        assert!(close(one.replay(2), 2.0 * n as f64 * secs));
        assert!(close(two.replay(1), 2.0 * n as f64 * secs));
        assert!(
            close(two.replay(2), (n as f64 + 1.0) * secs),
            "{}",
            two.replay(2)
        );
        // The span: the chain of classifications, then the last scatter.
        assert!(close(two.span(), (n as f64 + 1.0) * secs));
    }

    #[test]
    fn with_two_strips_in_flight_the_ledger_and_the_finish_stay_between_joins() {
        // n filter strips, each the input's ledger, a classification, a
        // scatter and the finishing of rows, one 1 s task each. As built,
        // strip k's call is its ledger, then its classification beside
        // strip k - 1's scatter, then strip k - 1's finish: 3 a strip on
        // two cores or more, 2 for the first call, and after the last the
        // last scatter (beside the finish before it) and its finish: 3n,
        // where a model letting the ledger and the finish overlap the
        // passes would give less.
        let n = 5;
        let names = ["ledger in", "classify", "scatter", "finish rows"];
        let mut events = Vec::new();
        for k in 0..n as u64 {
            let (seg, t0) = (10 * k, 4.0 * k as f64);
            events.push(event("segment", "filter", (t0, 4.0), seg, vec![]));
            for (j, name) in names.into_iter().enumerate() {
                let (region, ts) = (seg + 1 + 2 * j as u64, t0 + j as f64);
                events.push(event("region", name, (ts, 1.0), region, vec![seg]));
                events.push(event("task", name, (ts, 1.0), region + 1, vec![region]));
            }
        }
        let two = Model::from_events_in_flight(&events).unwrap();
        let secs = 1e-6;
        assert!(close(two.replay(1), 4.0 * n as f64 * secs));
        let want = 3.0 * n as f64 * secs;
        assert!(close(two.replay(2), want), "{}", two.replay(2));
        assert!(close(two.replay(8), want), "{}", two.replay(8));
    }
}
