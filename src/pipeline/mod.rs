//! The streaming pipeline: a reader stage, the filter (one skeleton,
//! [`stream::Streamer`], around each method's [`stream::Stage`]), a writer
//! stage, joined by bounded channels and sharing one rayon pool.
//!
//! ```text
//!  Source ──strips──▶ Streamer + Stage (halo windows, tiles) ──rows──▶ Sink
//!  (reader thread)    (this thread, rayon pool)                  (writer thread)
//! ```
//!
//! The pipeline never sees EXR types: sources and sinks speak planar `f32`
//! rows (`[row][channel][x]`). Back-pressure through the two-slot channels,
//! not the image size, bounds memory.
//!
//! * [`stream`]: the skeleton (input window, cursors, books, precision);
//! * [`spread`]: the Gaussian family's stage (ep-gauss, gauss, box, clamp);
//! * [`excess`]: ep-box's stage (§5.1);
//! * [`order`]: the median and alpha-trim foils' stage;
//! * [`books`], [`ledger`], [`window`]: what every stage shares.

pub mod band;
pub mod books;
pub mod edge;
pub mod excess;
pub mod ledger;
pub mod order;
pub mod spread;
pub mod stream;
pub mod window;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::filter::channels::ChannelRule;
use crate::filter::ep_box::StatsLayout;
use crate::filter::{FilterParams, Method};
use crate::geometry::{Grid, Halo};
pub use excess::ExcessStats;
pub use ledger::{ChannelLedger, Ledger};
pub use spread::SpreadStats;
pub use stream::{MethodStats, OutRows, Stage, Streamer, WindowUse};

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
    /// The precision it stores: the pipeline rounds to it (and refuses what
    /// it cannot hold), so the ledger's "after rounding" is what is stored.
    fn precision(&self) -> Precision {
        Precision::F32
    }
    /// The precision of each of `nch` channels (in the rows' order): the
    /// pipeline rounds each channel to its own.
    fn precisions(&self, nch: usize) -> Vec<Precision> {
        vec![self.precision(); nch]
    }
    /// Rows `y0..y0 + rows`, `[row][channel][x]`, already rounded to
    /// [`Sink::precisions`].
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
    /// 32-bit unsigned integer (ids: written as the integers they hold,
    /// refusing anything else).
    U32,
}

impl Precision {
    /// Name as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F16 => "f16",
            Precision::U32 => "u32",
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
            cancel: None,
            nonfinite: NonFinite::Error,
        }
    }
}

pub use crate::filter::channels::ChannelMode;

/// What one job filters: the grid and its channels.
#[derive(Clone, Debug)]
pub struct Job {
    /// Sizes.
    pub grid: Grid,
    /// Channel names, in the order of the strips.
    pub channels: Vec<String>,
    /// Luminance weight of each channel (0 for alpha and carried channels).
    pub luminance: Vec<f64>,
    /// What the stage does with each channel ([`Job::new`]: spread where
    /// the luminance weight is not 0, else the base filter).
    pub modes: Vec<ChannelMode>,
    /// Channels of data, not light (carried `average` and `nearest`: depth,
    /// normals, ids): out of the ledger, and their values may be infinite
    /// (a sky's depth) or NaN, which pass as they are.
    pub data: Vec<bool>,
    /// Channels read after `channels` but not written: the statistics of
    /// `ep-box` (variance, sample count).
    pub aux: Vec<String>,
    /// Where the statistics are (indices into `channels` then `aux`).
    pub stats: Option<StatsLayout>,
    /// `--edge pad`: the source holds this many samples (columns, rows), and
    /// the grid is that size completed with zero samples to a multiple of S
    /// ([`edge::Padded`], [`edge::Coverage`]).
    pub padded_from: Option<(usize, usize)>,
}

impl Job {
    /// A job over `channels` with no statistics channels.
    pub fn new(grid: Grid, channels: Vec<String>, luminance: Vec<f64>) -> Self {
        let modes = luminance
            .iter()
            .map(|&l| ChannelMode::of(l, None, grid.s))
            .collect();
        let data = vec![false; channels.len()];
        Job {
            grid,
            channels,
            luminance,
            modes,
            data,
            aux: Vec::new(),
            stats: None,
            padded_from: None,
        }
    }

    /// Carried channels: `rules[c]` for each channel (`None`: the beauty's).
    pub fn with_rules(mut self, rules: &[Option<ChannelRule>]) -> Self {
        for ((m, &l), &r) in self.modes.iter_mut().zip(&self.luminance).zip(rules) {
            *m = ChannelMode::of(l, r, self.grid.s);
        }
        for (d, &r) in self.data.iter_mut().zip(rules) {
            *d = matches!(r, Some(ChannelRule::Average | ChannelRule::Nearest));
        }
        self
    }

    /// Channels per strip row: filtered ones, then statistics.
    pub fn strip_channels(&self) -> usize {
        self.channels.len() + self.aux.len()
    }
}

/// Seconds each stage of a run was busy: reading and decoding (the reader
/// thread), filtering (the streamer), encoding and writing (the writer
/// thread). Their sum above the wall time is the overlap; the largest is the
/// stage that bounds the run.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageSeconds {
    /// In `Source::next_strip`.
    pub read: f64,
    /// In `Streamer::push`.
    pub filter: f64,
    /// In `Sink::write_rows` and `Sink::finish`.
    pub write: f64,
    /// The filter waiting for the next strip (the reader is behind).
    pub filter_waiting_for_input: f64,
    /// The filter waiting for room in the writer's queue (the writer is
    /// behind).
    pub filter_waiting_for_output: f64,
}

/// The result of a run.
#[derive(Clone, Debug)]
pub struct RunStats {
    /// What the method counted.
    pub method: MethodStats,
    /// Per-channel ledger.
    pub ledger: Vec<ChannelLedger>,
    /// Wall time in seconds.
    pub seconds: f64,
    /// Busy time of each stage.
    pub stages: StageSeconds,
    /// Halo of the job.
    pub halo: Halo,
    /// Every window held: most rows and row size.
    pub windows: Vec<WindowUse>,
    /// Digest of the unrounded output ([`books::Books::digest`]).
    pub digest: u64,
    /// Non-finite input samples treated as zero, per channel (`NonFinite::Zero`).
    pub nonfinite_zeroed: Vec<u64>,
    /// The first of them: (x, y, channel index).
    pub first_nonfinite: Option<(usize, usize, usize)>,
}

impl RunStats {
    /// ep-gauss's counts, if the run was ep-gauss.
    pub fn ep_gauss(&self) -> Option<SpreadStats> {
        match self.method {
            MethodStats::EpGauss(s) => Some(s),
            _ => None,
        }
    }

    /// ep-box's counts, if the run was ep-box.
    pub fn ep_box(&self) -> Option<ExcessStats> {
        match self.method {
            MethodStats::EpBox(s) => Some(s),
            _ => None,
        }
    }

    /// Bytes the windows held at most (each window's high-water mark).
    pub fn window_bytes(&self) -> u64 {
        self.windows
            .iter()
            .map(|w| (w.rows * w.row_bytes) as u64)
            .sum()
    }
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
/// the stage's windows (input rows, horizontal pass, base, accumulator, box
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
        0 => auto_strip_rows(job.grid.in_w.max(1), job.strip_channels().max(1)),
        n => n,
    } as u64;
    // Input rows carry the statistics too (ep-gauss at S = 1 reads them).
    let in_row = w
        .saturating_mul(job.strip_channels() as u64)
        .saturating_mul(4);
    let out_row = ow.saturating_mul(nch).saturating_mul(8);
    let lag = (halo.lag() + halo.spread_reach) as u64 + strip / s + 4;
    let windows = in_row.saturating_mul(s * (halo.xbar_reach as u64 + 1) + strip)
        + out_row.saturating_mul(s * (2 * halo.base_reach as u64 + 1) + strip)
        + out_row.saturating_mul(2 * lag)
        + (ow + 2 * halo.search_reach as u64)
            .saturating_mul(8 * (2 * halo.search_reach as u64 + strip / s + 4));
    // The coarse grid: accumulator rows of half the width over half the
    // lag, and a few rows upsampled across.
    let coarse = if params.method == Method::EpGauss && params.coarse_from > 0.0 {
        out_row.saturating_mul(lag / 4 + 8)
    } else {
        0
    };
    let strips = in_row.saturating_mul(strip).saturating_mul(4);
    let blocks = block_bytes.saturating_mul(3 * 4);
    windows
        .saturating_add(coarse)
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

/// Run `job` from `source` to `sink`, rounding to the sink's precision.
pub fn run<S: Source, K: Sink>(
    source: S,
    sink: K,
    job: &Job,
    params: &FilterParams,
    cfg: &PipelineConfig,
    progress: Progress<'_>,
) -> Result<RunStats> {
    let params = params.validated()?;
    let pool = thread_pool(cfg.threads)?;
    let start = Instant::now();
    let mut streamer = Streamer::new(job, &params, cfg, sink.precisions(job.channels.len()))?;
    let real = job.padded_from.unwrap_or((job.grid.in_w, job.grid.in_h));
    let source = edge::Padded::new(
        source,
        real,
        (job.grid.in_w, job.grid.in_h),
        job.strip_channels(),
    );
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
    let mut stages = StageSeconds::default();

    let result = std::thread::scope(|scope| -> Result<()> {
        let reader = scope.spawn(move || -> f64 {
            let mut source = source;
            let mut busy = 0.0;
            loop {
                let t = Instant::now();
                let next = pool.install(|| source.next_strip(strip_rows));
                busy += t.elapsed().as_secs_f64();
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
            busy
        });
        let writer = scope.spawn(move || -> (Result<()>, f64) {
            let mut sink = sink;
            let mut written = 0;
            let mut busy = 0.0;
            for rows in row_rx.iter() {
                let t = Instant::now();
                let r = pool.install(|| sink.write_rows(rows.y0, rows.rows, &rows.data));
                busy += t.elapsed().as_secs_f64();
                if let Err(e) = r {
                    return (Err(e), busy);
                }
                written += rows.rows;
            }
            // Finish only a complete image: when the filter stopped early its
            // error is the one reported, and the sink is dropped unfinished
            // (an EXR output then removes its temporary file).
            let t = Instant::now();
            let r = if written == total {
                pool.install(|| sink.finish())
            } else {
                Ok(())
            };
            (r, busy + t.elapsed().as_secs_f64())
        });
        let mut filter_result = Ok(());
        let mut writer_failed = false;
        loop {
            let t = Instant::now();
            let Ok(strip) = strip_rx.recv() else { break };
            stages.filter_waiting_for_input += t.elapsed().as_secs_f64();
            if cancelled() {
                filter_result = Err(Error::Interrupted);
                break;
            }
            let t = Instant::now();
            let pushed = strip.and_then(|s| pool.install(|| streamer.push(s)));
            stages.filter += t.elapsed().as_secs_f64();
            match pushed {
                Ok(Some(rows)) => {
                    progress(rows.y0 + rows.rows, total);
                    let t = Instant::now();
                    let sent = row_tx.send(rows);
                    stages.filter_waiting_for_output += t.elapsed().as_secs_f64();
                    if sent.is_err() {
                        writer_failed = true; // its error is reported below
                        break;
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    filter_result = Err(e);
                    break;
                }
            }
        }
        drop(strip_rx);
        if filter_result.is_ok() && !writer_failed && streamer.rows_out() != total {
            filter_result = Err(Error::Internal(format!(
                "the source ended after {} of {} output rows",
                streamer.rows_out(),
                total
            )));
        }
        drop(row_tx);
        stages.read = reader.join().unwrap_or(0.0);
        // A panic on the writer thread is a bug: report it first, never
        // behind another error.
        match writer.join() {
            Ok((write_result, busy)) => {
                stages.write = busy;
                filter_result.and(write_result)
            }
            Err(_) => Err(Error::Internal(
                "the writer thread panicked (please report this file)".into(),
            )),
        }
    });
    result?;
    let s2 = (job.grid.s * job.grid.s) as f64;
    let books = streamer.books();
    Ok(RunStats {
        method: streamer.stats(),
        ledger: books.ledger().balance(books.names(), s2),
        seconds: start.elapsed().as_secs_f64(),
        stages,
        halo: streamer.halo(),
        windows: streamer.windows(),
        digest: books.digest(),
        nonfinite_zeroed: books.nonfinite_zeroed().to_vec(),
        first_nonfinite: books.first_nonfinite(),
    })
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
    /// The precision the values are rounded to (f32 by default).
    pub precision: Option<Precision>,
}

impl MemorySink {
    /// A sink that stores `precision` (f16 refuses what it cannot hold).
    pub fn with_precision(precision: Precision) -> Self {
        MemorySink {
            data: Vec::new(),
            precision: Some(precision),
        }
    }
}

impl Sink for MemorySink {
    fn precision(&self) -> Precision {
        self.precision.unwrap_or(Precision::F32)
    }
    fn write_rows(&mut self, _y0: usize, _rows: usize, data: &[f32]) -> Result<()> {
        self.data.extend_from_slice(data);
        Ok(())
    }
    fn finish(&mut self) -> Result<()> {
        Ok(())
    }
}

impl<K: Sink> Sink for &mut K {
    fn precision(&self) -> Precision {
        (**self).precision()
    }
    fn precisions(&self, nch: usize) -> Vec<Precision> {
        (**self).precisions(nch)
    }
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
    // Rows as the source holds them (`--edge pad` completes them in `run`).
    let row_len = job.strip_channels() * job.padded_from.map_or(job.grid.in_w, |r| r.0);
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
