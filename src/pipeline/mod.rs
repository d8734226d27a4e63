//! The streaming pipeline: a reader stage, the filter engine, a writer stage,
//! joined by bounded channels and sharing one rayon pool.
//!
//! ```text
//!  Source ──strips──▶ Engine (halo windows, tiles) ──rows──▶ Sink
//!  (reader thread)    (this thread, rayon pool)           (writer thread)
//! ```
//!
//! The pipeline never sees EXR types: sources and sinks speak planar `f32`
//! rows (`[row][channel][x]`). Back-pressure through the two-slot channels,
//! not the image size, bounds memory.

pub mod books;
pub mod box_engine;
pub mod engine;
pub mod ledger;
pub mod order_engine;
pub mod window;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::filter::ep_box::StatsLayout;
use crate::filter::{FilterParams, Method};
use crate::geometry::{Grid, Halo};
pub use box_engine::BoxEngine;
pub use engine::{Counters, Engine, OutRows};
pub use ledger::{ChannelLedger, Ledger};

/// Rows of input samples, `[row][channel][x]`.
#[derive(Clone, Debug)]
pub struct Strip {
    /// First row.
    pub y0: usize,
    /// Number of rows.
    pub rows: usize,
    /// The values.
    pub data: Vec<f32>,
}

/// Something that delivers input rows in increasing order.
pub trait Source: Send {
    /// The next `max_rows` rows (fewer at the end); `None` when done.
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>>;
}

/// Something that takes finished output rows in increasing order.
pub trait Sink: Send {
    /// Rows `y0..y0 + rows`, `[row][channel][x]`.
    fn write_rows(&mut self, y0: usize, rows: usize, data: &[f32]) -> Result<()>;
    /// All rows have been written.
    fn finish(&mut self) -> Result<()>;
}

/// Precision of the output samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// 32-bit float.
    F32,
    /// 16-bit float (refuses values beyond ±65504).
    F16,
}

impl Precision {
    /// Name as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F16 => "f16",
        }
    }
}

/// What to do with NaN and infinite input samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NonFinite {
    /// Refuse the input, naming the first such sample (default).
    #[default]
    Error,
    /// Treat them as zero, and count them (per channel) in the report.
    Zero,
}

/// How the work is cut up; none of it changes the result.
#[derive(Clone, Debug)]
pub struct PipelineConfig {
    /// Tile width of the accumulators, in output pixels.
    pub tile: usize,
    /// Input rows per strip (0: automatic, [`auto_strip_rows`]).
    pub strip_rows: usize,
    /// Worker threads (0: one per core).
    pub threads: usize,
    /// Output precision.
    pub precision: Precision,
    /// Set to stop the run early (e.g. on SIGINT).
    pub cancel: Option<Arc<AtomicBool>>,
    /// NaN and infinite input samples.
    pub nonfinite: NonFinite,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig {
            tile: 256,
            strip_rows: 0,
            threads: 0,
            precision: Precision::F32,
            cancel: None,
            nonfinite: NonFinite::Error,
        }
    }
}

/// What one job filters: the grid and its channels.
#[derive(Clone, Debug)]
pub struct Job {
    /// Sizes.
    pub grid: Grid,
    /// Channel names, in the order of the strips.
    pub channels: Vec<String>,
    /// Luminance weight of each channel (0 for alpha).
    pub luminance: Vec<f64>,
    /// Channels read after `channels` but not written: the statistics of
    /// `ep-box` (variance, sample count).
    pub aux: Vec<String>,
    /// Where the statistics are (indices into `channels` then `aux`).
    pub stats: Option<StatsLayout>,
}

impl Job {
    /// A job over `channels` with no statistics channels.
    pub fn new(grid: Grid, channels: Vec<String>, luminance: Vec<f64>) -> Self {
        Job {
            grid,
            channels,
            luminance,
            aux: Vec::new(),
            stats: None,
        }
    }

    /// Channels per strip row: filtered ones, then statistics.
    pub fn strip_channels(&self) -> usize {
        self.channels.len() + self.aux.len()
    }
}

/// The result of a run.
#[derive(Clone, Debug)]
pub struct RunStats {
    /// Counters of the noise test.
    pub counters: Counters,
    /// Per-channel ledger.
    pub ledger: Vec<ChannelLedger>,
    /// Wall time in seconds.
    pub seconds: f64,
    /// Halo of the job.
    pub halo: Halo,
    /// Most rows each window held (input, luminance, horizontal pass, base, accumulator).
    pub window_rows: [usize; 5],
    /// Digest of the unrounded output ([`Engine::digest`]).
    pub digest: u64,
    /// Non-finite input samples treated as zero, per channel (`NonFinite::Zero`).
    pub nonfinite_zeroed: Vec<u64>,
    /// The first of them: (x, y, channel index).
    pub first_nonfinite: Option<(usize, usize, usize)>,
}

/// Bytes of input one strip should hold by default: four strips are in
/// flight at most (two queued, one being read, one being filtered), so this
/// bounds their memory to 16 MiB whatever the width.
pub const STRIP_BYTES: usize = 4 << 20;

/// Default strip height: [`STRIP_BYTES`] of f32 rows, between 1 and 96 rows.
pub fn auto_strip_rows(in_w: usize, channels: usize) -> usize {
    (STRIP_BYTES / (in_w * channels * 4).max(1)).clamp(1, 96)
}

/// Bytes a job will hold at most, from its sizes alone: the strips in flight,
/// the engine's windows (input rows, horizontal pass, base, accumulator, box
/// luminance) and the decoder's and encoder's blocks (`block_bytes`: one
/// decompressed input block). Checked against `--max-memory` before anything
/// is allocated, so a header claiming an absurd size gives an error instead of
/// an allocation failure (which would abort the process).
pub fn estimate_bytes(
    job: &Job,
    params: &FilterParams,
    cfg: &PipelineConfig,
    block_bytes: u64,
) -> u64 {
    let halo = crate::filter::halo(params);
    if params.method == Method::EpBox {
        return estimate_box_bytes(job, cfg, block_bytes, halo);
    }
    let s = job.grid.s as u64;
    let nch = job.channels.len() as u64;
    let (w, ow) = (
        job.grid.in_w as u64,
        (job.grid.in_w / job.grid.s.max(1)) as u64,
    );
    let strip = match cfg.strip_rows {
        0 => auto_strip_rows(job.grid.in_w.max(1), job.channels.len().max(1)),
        n => n,
    } as u64;
    let in_row = w.saturating_mul(nch).saturating_mul(4);
    let out_row = ow.saturating_mul(nch).saturating_mul(8);
    let lag = (halo.lag() + halo.spread_reach) as u64 + strip / s + 4;
    let windows = in_row.saturating_mul(s * (halo.xbar_reach as u64 + 1) + strip)
        + out_row.saturating_mul(s * (2 * halo.base_reach as u64 + 1) + strip)
        + out_row.saturating_mul(2 * lag)
        + (ow + 2 * halo.search_reach as u64)
            .saturating_mul(8 * (2 * halo.search_reach as u64 + strip / s + 4));
    let strips = in_row.saturating_mul(strip).saturating_mul(4);
    let blocks = block_bytes.saturating_mul(3 * 4);
    windows
        .saturating_add(strips)
        .saturating_add(blocks)
        .saturating_add(out_row.saturating_mul(16 * 4))
}

fn estimate_box_bytes(job: &Job, cfg: &PipelineConfig, block_bytes: u64, halo: Halo) -> u64 {
    let w = job.grid.in_w as u64;
    let (nch, nall) = (job.channels.len() as u64, job.strip_channels() as u64);
    let strip = match cfg.strip_rows {
        0 => auto_strip_rows(job.grid.in_w.max(1), job.strip_channels().max(1)),
        n => n,
    } as u64;
    let (p, r) = (halo.search_reach as u64, halo.spread_reach as u64);
    let threads = if cfg.threads == 0 {
        rayon::current_num_threads()
    } else {
        cfg.threads
    } as u64;
    // Input rows with their luminance, guard bound, raw flags and decision;
    // kept and accumulator rows; each task's band arrays; strips in flight;
    // the codec's blocks.
    let per_in = w.saturating_mul(nall * 4 + 8 + 8 + 1 + 1);
    let windows = per_in.saturating_mul(2 * p + strip + 2)
        + w.saturating_mul(nch * 8)
            .saturating_mul(2 * (2 * r + strip + 2));
    let bands = w
        .saturating_mul(9 + 4)
        .saturating_mul((32 + 2 * p) * threads.max(1));
    let strips = w.saturating_mul(nall * 4).saturating_mul(strip * 4);
    windows
        .saturating_add(bands)
        .saturating_add(strips)
        .saturating_add(block_bytes.saturating_mul(3 * 4))
        .saturating_add(w.saturating_mul(nch * 8 * 16 * 4))
}

/// Progress callback: (output rows done, output rows in all).
pub type Progress<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// Build the thread pool that every stage shares.
pub fn thread_pool(threads: usize) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("epfilt-{i}"))
        .build()
        .map_err(|e| Error::Config(format!("cannot start {threads} threads: {e}")))
}

/// Run `job` from `source` to `sink`.
pub fn run<S: Source, K: Sink>(
    source: S,
    sink: K,
    job: &Job,
    params: &FilterParams,
    cfg: &PipelineConfig,
    progress: Progress<'_>,
) -> Result<RunStats> {
    let pool = thread_pool(cfg.threads)?;
    let start = Instant::now();
    let mut engine = AnyEngine::new(job, params, cfg)?;
    let total = job.grid.out_h();
    let cancelled = || {
        cfg.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
    };
    let (strip_tx, strip_rx) = crossbeam_channel::bounded::<Result<Strip>>(2);
    let (row_tx, row_rx) = crossbeam_channel::bounded::<OutRows>(2);
    let strip_rows = match cfg.strip_rows {
        0 => auto_strip_rows(job.grid.in_w, job.strip_channels()),
        n => n,
    };
    let pool = &pool;

    let result = std::thread::scope(|scope| -> Result<()> {
        let reader = scope.spawn(move || {
            let mut source = source;
            loop {
                let next = pool.install(|| source.next_strip(strip_rows));
                let stop = !matches!(next, Ok(Some(_)));
                let msg = match next {
                    Ok(Some(s)) => Ok(s),
                    Ok(None) => break,
                    Err(e) => Err(e),
                };
                if strip_tx.send(msg).is_err() || stop {
                    break;
                }
            }
        });
        let writer = scope.spawn(move || -> Result<()> {
            let mut sink = sink;
            let mut written = 0;
            for rows in row_rx.iter() {
                pool.install(|| sink.write_rows(rows.y0, rows.rows, &rows.data))?;
                written += rows.rows;
            }
            // Finish only a complete image: when the engine stopped early its
            // error is the one reported, and the sink is dropped unfinished
            // (an EXR output then removes its temporary file).
            if written == total {
                pool.install(|| sink.finish())
            } else {
                Ok(())
            }
        });
        let mut engine_result = Ok(());
        let mut writer_failed = false;
        for strip in strip_rx.iter() {
            if cancelled() {
                engine_result = Err(Error::Interrupted);
                break;
            }
            match strip.and_then(|s| pool.install(|| engine.push(s))) {
                Ok(Some(rows)) => {
                    progress(rows.y0 + rows.rows, total);
                    if row_tx.send(rows).is_err() {
                        writer_failed = true; // its error is reported below
                        break;
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    engine_result = Err(e);
                    break;
                }
            }
        }
        drop(strip_rx);
        if engine_result.is_ok() && !writer_failed && engine.rows_out() != total {
            engine_result = Err(Error::Internal(format!(
                "the source ended after {} of {} output rows",
                engine.rows_out(),
                total
            )));
        }
        drop(row_tx);
        let _ = reader.join();
        // A panic on the writer thread is a bug: report it first, never
        // behind another error.
        match writer.join() {
            Ok(write_result) => engine_result.and(write_result),
            Err(_) => Err(Error::Internal(
                "the writer thread panicked (please report this file)".into(),
            )),
        }
    });
    result?;
    let s2 = (job.grid.s * job.grid.s) as f64;
    Ok(RunStats {
        counters: engine.counters(),
        ledger: engine.ledger().balance(engine.names(), s2),
        seconds: start.elapsed().as_secs_f64(),
        halo: engine.halo(),
        window_rows: engine.high_water(),
        digest: engine.digest(),
        nonfinite_zeroed: engine.nonfinite_zeroed().to_vec(),
        first_nonfinite: engine.first_nonfinite(),
    })
}

/// The engine of a job's method.
enum AnyEngine {
    Gauss(Box<Engine>),
    Box(Box<BoxEngine>),
    Order(Box<order_engine::OrderEngine>),
}

macro_rules! delegate {
    ($self:ident, $e:ident => $body:expr) => {
        match $self {
            AnyEngine::Gauss($e) => $body,
            AnyEngine::Box($e) => $body,
            AnyEngine::Order($e) => $body,
        }
    };
}

impl AnyEngine {
    fn new(job: &Job, params: &FilterParams, cfg: &PipelineConfig) -> Result<Self> {
        let mut e = if params.method == Method::EpBox {
            params.validate()?;
            let stats = job
                .stats
                .clone()
                .ok_or_else(|| Error::Config("ep-box needs per-pixel variance channels".into()))?;
            let ltvis = params.ep_box.ltvis.ok_or_else(|| {
                Error::Config("ep-box needs L_tvis: measure L_ave first (mean_luminance)".into())
            })?;
            AnyEngine::Box(Box::new(BoxEngine::new(
                job.grid.in_w,
                job.grid.in_h,
                job.channels.clone(),
                job.luminance.clone(),
                job.aux.len(),
                stats,
                &params.ep_box,
                ltvis,
                params.max_radius,
                cfg.tile,
                cfg.precision,
            )?))
        } else if matches!(params.method, Method::Median | Method::AlphaTrim) {
            params.validate()?;
            let trim = match params.method {
                Method::Median => order_engine::Trim::Median,
                _ => order_engine::Trim::Alpha(params.alpha),
            };
            if job.grid.in_w < job.grid.s || job.grid.in_h < job.grid.s {
                return Err(Error::Config(format!(
                    "--supersample {} is larger than the image ({}x{} samples)",
                    job.grid.s, job.grid.in_w, job.grid.in_h
                )));
            }
            AnyEngine::Order(Box::new(order_engine::OrderEngine::new(
                job.grid,
                job.channels.clone(),
                trim,
                cfg.precision,
            )?))
        } else {
            if !job.aux.is_empty() {
                return Err(Error::Config(format!(
                    "{} reads no statistics channels",
                    params.method.name()
                )));
            }
            AnyEngine::Gauss(Box::new(Engine::new(
                job.grid,
                job.channels.clone(),
                job.luminance.clone(),
                params,
                cfg.tile,
                cfg.precision,
            )?))
        };
        let r = &mut e;
        delegate!(r, x => x.books_mut().set_nonfinite(cfg.nonfinite));
        Ok(e)
    }
    fn push(&mut self, strip: Strip) -> Result<Option<OutRows>> {
        delegate!(self, e => e.push(strip))
    }
    fn rows_out(&self) -> usize {
        delegate!(self, e => e.rows_out())
    }
    fn counters(&self) -> Counters {
        delegate!(self, e => e.counters())
    }
    fn ledger(&self) -> &Ledger {
        delegate!(self, e => e.books().ledger())
    }
    fn names(&self) -> &[String] {
        delegate!(self, e => e.books().names())
    }
    fn halo(&self) -> Halo {
        delegate!(self, e => e.halo())
    }
    fn high_water(&self) -> [usize; 5] {
        delegate!(self, e => e.high_water())
    }
    fn digest(&self) -> u64 {
        delegate!(self, e => e.books().digest())
    }
    fn nonfinite_zeroed(&self) -> &[u64] {
        delegate!(self, e => e.books().nonfinite_zeroed())
    }
    fn first_nonfinite(&self) -> Option<(usize, usize, usize)> {
        delegate!(self, e => e.books().first_nonfinite())
    }
}

/// The mean luminance of a source's filtered channels (the first pass of
/// `ep-box`, for `L_ave` of Eq. 9), summed exactly (compensated) in row order.
pub fn mean_luminance<S: Source>(mut source: S, job: &Job, strip_rows: usize) -> Result<f64> {
    let w = job.grid.in_w;
    let nall = job.strip_channels();
    let strip_rows = match strip_rows {
        0 => auto_strip_rows(w, nall),
        n => n,
    };
    let mut total = ledger::CompensatedSum::default();
    let mut count = 0usize;
    while let Some(strip) = source.next_strip(strip_rows)? {
        let sums: Vec<ledger::CompensatedSum> = strip
            .data
            .par_chunks(nall * w)
            .map(|row| {
                let mut s = ledger::CompensatedSum::default();
                for x in 0..w {
                    let mut y = 0.0;
                    for (c, &l) in job.luminance.iter().enumerate() {
                        let v = row[c * w + x] as f64;
                        // Non-finite samples are the filter's to report.
                        if v.is_finite() {
                            y += l * v;
                        }
                    }
                    s.add(y);
                }
                s
            })
            .collect();
        for s in &sums {
            total.merge(s);
        }
        count += strip.rows * w;
    }
    Ok(if count == 0 {
        0.0
    } else {
        total.value() / count as f64
    })
}

/// An in-memory source: a whole planar image (`[row][channel][x]`).
#[derive(Clone, Debug)]
pub struct MemorySource {
    data: Vec<f32>,
    row_len: usize,
    rows: usize,
    next: usize,
}

impl MemorySource {
    /// Wrap `data` of `rows` rows of `row_len` values.
    pub fn new(data: Vec<f32>, row_len: usize) -> Self {
        let rows = data.len().checked_div(row_len).unwrap_or(0);
        MemorySource {
            data,
            row_len,
            rows,
            next: 0,
        }
    }
}

impl Source for MemorySource {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        if self.next >= self.rows {
            return Ok(None);
        }
        let n = max_rows.min(self.rows - self.next);
        let data = self.data[self.next * self.row_len..(self.next + n) * self.row_len].to_vec();
        let strip = Strip {
            y0: self.next,
            rows: n,
            data,
        };
        self.next += n;
        Ok(Some(strip))
    }
}

/// An in-memory sink collecting the output image.
#[derive(Clone, Debug, Default)]
pub struct MemorySink {
    /// Output rows, `[row][channel][x]`.
    pub data: Vec<f32>,
}

impl Sink for MemorySink {
    fn write_rows(&mut self, _y0: usize, _rows: usize, data: &[f32]) -> Result<()> {
        self.data.extend_from_slice(data);
        Ok(())
    }
    fn finish(&mut self) -> Result<()> {
        Ok(())
    }
}

impl<K: Sink> Sink for &mut K {
    fn write_rows(&mut self, y0: usize, rows: usize, data: &[f32]) -> Result<()> {
        (**self).write_rows(y0, rows, data)
    }
    fn finish(&mut self) -> Result<()> {
        (**self).finish()
    }
}

/// Filter a whole in-memory image (planar `[row][channel][x]`) — for tests,
/// the demo and small jobs. Returns the output image and the statistics.
pub fn filter_in_memory(
    data: Vec<f32>,
    job: &Job,
    params: &FilterParams,
    cfg: &PipelineConfig,
) -> Result<(Vec<f32>, RunStats)> {
    let row_len = job.strip_channels() * job.grid.in_w;
    let mut params = params.clone();
    if params.method == Method::EpBox && params.ep_box.ltvis.is_none() {
        let source = MemorySource::new(data.clone(), row_len);
        let l_ave = mean_luminance(source, job, cfg.strip_rows)?;
        params.ep_box.ltvis = Some(crate::filter::ep_box::ltvis(l_ave, params.ep_box.nmid));
    }
    let mut sink = MemorySink::default();
    let stats = run(
        MemorySource::new(data, row_len),
        &mut sink,
        job,
        &params,
        cfg,
        &|_, _| {},
    )?;
    Ok((sink.data, stats))
}
