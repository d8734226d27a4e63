//! The streaming pipeline: a reader stage, the filter (one skeleton,
//! [`stream::Streamer`], around each method's [`stage::Stage`]), a writer
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
//! * [`pixel`]: the pixel-resolution stage and its rules: ep-box (§5.1)
//!   and ep-gauss at S = 1;
//! * [`order`]: the median and alpha-trim foils' stage;
//! * [`books`], [`ledger`], [`window`]: what every stage shares;
//! * this file: the contract (strips, sources, sinks, the job, the
//!   statistics); `runner.rs`: the run; `estimate.rs`: the memory estimate;
//!   `memory.rs`: in-memory sources and sinks.

pub mod band;
pub mod books;
pub mod counts;
pub mod edge;
mod estimate;
pub mod ledger;
mod memory;
pub mod order;
pub mod pair;
pub mod pixel;
pub mod restore;
mod runner;
pub mod schedule;
pub mod spread;
pub mod stage;
mod stages;
pub mod stream;
pub mod tiles;
pub mod window;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::filter::channels::ChannelRule;
use crate::filter::ep_box::StatsLayout;
use crate::filter::guides::{GuideLayout, SurfaceRule};
use crate::filter::{FilterParams, Method};
use crate::geometry::{Grid, Halo};
pub use books::OutRows;
pub use counts::{ExcessCounts, MethodCounts, SpreadCounts};
pub use ledger::{ChannelLedger, Ledger};
pub use stage::{Stage, WindowUse};
pub use stages::strips_in_flight;
pub use stream::Streamer;

pub use estimate::{
    auto_strip_rows, estimate_bytes, fit_memory, own_pages, read_ahead_blocks, window_blocks,
    MAPPED_ALLOCATION_BYTES, MAPPED_RELEASE_BYTES, PROGRAM_BYTES, READ_AHEAD_BATCHES,
    READ_AHEAD_BYTES, STRIPS_RECYCLED, STRIP_BYTES, WORKERS_PER_WRITE_BLOCK,
    WRITE_AHEAD_BYTES_PER_THREAD,
};
pub use memory::{filter_in_memory, filter_planar, MemoryRun, MemorySink, MemorySource};
pub use restore::estimate::{fit_restore_memory, restore_bytes};
pub use runner::{mean_luminance, run, run_streamer, thread_pool, Progress};

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

/// A loop that decodes a source's rows ahead of its strips, on a thread of
/// its own ([`Source::decoder`]).
pub type Decoder<'s> = Box<dyn FnOnce() + Send + 's>;

/// How far a decoding source reads ahead ([`Source::decoder`]).
pub struct ReadAhead<'a> {
    /// The strips' height.
    pub strip_rows: usize,
    /// Buffers of strips the filter is done with, to fill again (a new
    /// strip buffer is mapped and faulted in page by page: on wide inputs
    /// most of the reader's page faults).
    pub recycled: Option<crossbeam_channel::Receiver<Vec<f32>>>,
    /// Blocks of the window for blocks of the given decoded bytes
    /// ([`window_blocks`]).
    pub window_blocks: &'a (dyn Fn(u64) -> u64 + Sync),
}

/// Something that delivers input rows in increasing order.
pub trait Source: Send {
    /// The next `max_rows` rows (fewer at the end); `None` when done.
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>>;

    /// For a source that decodes: the loop that decodes its rows ahead, as
    /// `ahead` says, with `pool`'s threads, to run on a thread of its own
    /// while the strips are taken (it returns once the rows are decoded, on
    /// an error, or once the source is dropped). Then call
    /// [`Source::wait_ready`] before each `next_strip`. `None` (the default):
    /// `next_strip` does the work itself.
    fn decoder<'s>(
        &mut self,
        _ahead: &ReadAhead<'_>,
        _pool: &'s rayon::ThreadPool,
    ) -> Option<Decoder<'s>>
    where
        Self: 's,
    {
        None
    }

    /// Wait, outside the thread pool, until the next strip's rows are
    /// decoded (a source with a [`Source::decoder`]; else nothing).
    fn wait_ready(&mut self) {}

    /// A strip's buffer the caller is done with, for the next strip (a
    /// fresh one is faulted in page by page); dropped by default.
    fn give_back(&mut self, _buf: Vec<f32>) {}
}

/// A wrapper's [`Source::decoder`] and [`Source::wait_ready`]: its `inner`
/// source's (the wrappers edit rows; the inner source decodes them).
macro_rules! decode_ahead_in_inner {
    () => {
        fn decoder<'s>(
            &mut self,
            ahead: &$crate::pipeline::ReadAhead<'_>,
            pool: &'s rayon::ThreadPool,
        ) -> Option<$crate::pipeline::Decoder<'s>>
        where
            Self: 's,
        {
            self.inner.decoder(ahead, pool)
        }

        fn wait_ready(&mut self) {
            self.inner.wait_ready();
        }

        fn give_back(&mut self, buf: Vec<f32>) {
            self.inner.give_back(buf);
        }
    };
}
pub(crate) use decode_ahead_in_inner;

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

    /// Bytes a sample takes in the file.
    pub fn bytes(self) -> usize {
        match self {
            Precision::F16 => 2,
            Precision::F32 | Precision::U32 => 4,
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

impl NonFinite {
    /// Parse `--nonfinite`: `error` or `zero`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "error" => Ok(NonFinite::Error),
            "zero" => Ok(NonFinite::Zero),
            other => Err(Error::Config(format!(
                "--nonfinite must be error or zero, not {other:?}"
            ))),
        }
    }
}

/// How the work is cut up; none of it changes the result.
#[derive(Clone, Debug)]
pub struct PipelineConfig {
    /// Tile width of the accumulators, in output pixels.
    pub tile: usize,
    /// Input rows per strip (0: automatic, [`StripLayout::auto_strip_rows`]).
    pub strip_rows: usize,
    /// Worker threads (0: one per core).
    pub threads: usize,
    /// Blocks the reader decodes ahead at most (0: automatic,
    /// [`window_blocks`]; [`fit_memory`] sets fewer under a small budget).
    pub window_blocks: usize,
    /// Size strips and the reader's window as for this many workers (0:
    /// [`Self::workers`]).
    pub geometry_threads: usize,
    /// Bytes of output rows the sink holds before it encodes them (0:
    /// [`StripLayout::write_ahead_bytes`]'s rule; [`fit_memory`] sets
    /// fewer under a small budget).
    pub write_ahead: usize,
    /// Set to stop the run early (e.g. on SIGINT).
    pub cancel: Option<Arc<AtomicBool>>,
    /// NaN and infinite input samples.
    pub nonfinite: NonFinite,
    /// Samples of an input row one classification task searches for noise,
    /// or pixels one pixel-resolution treatment task treats (0: automatic;
    /// rows wider than that are cut into column ranges). Does not change
    /// the result.
    pub classify_samples: usize,
    /// Noisy samples whose kernels may reach an edge per spread chunk (the
    /// memory of a chunk's reflected weights; 0: automatic). Does not change
    /// the result.
    pub spread_chunk: usize,
    /// Strips the Gaussian family works on at once (0: automatic,
    /// [`PipelineConfig::strips_in_flight`]). Does not change the result.
    pub strips_in_flight: usize,
}

impl PipelineConfig {
    /// The worker threads a run gets: `threads`, or one per core.
    pub fn workers(&self) -> usize {
        match self.threads {
            0 => rayon::current_num_threads(),
            n => n,
        }
    }

    /// Strips the Gaussian family works on at once: `strips_in_flight`, or
    /// two where there are two workers or more. With two, a strip's first
    /// passes (box luminance, classification) run beside the previous
    /// strip's later ones (spread, base rows), so that the end of one
    /// parallel loop does not leave the workers waiting; the windows hold
    /// a strip more. One worker gains nothing from it.
    pub fn strips_in_flight(&self) -> usize {
        match self.strips_in_flight {
            0 if self.workers() > 1 => 2,
            0 => 1,
            n => n.min(2),
        }
    }

    /// The workers strips and the reader's window are sized for:
    /// `geometry_threads`, or [`Self::workers`].
    pub fn geometry_workers(&self) -> usize {
        match self.geometry_threads {
            0 => self.workers(),
            n => n,
        }
    }
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig {
            tile: 256,
            strip_rows: 0,
            threads: 0,
            window_blocks: 0,
            geometry_threads: 0,
            write_ahead: 0,
            cancel: None,
            nonfinite: NonFinite::Error,
            classify_samples: 0,
            spread_chunk: 0,
            strips_in_flight: 0,
        }
    }
}

pub use crate::filter::channels::ChannelMode;

/// What the pipeline moves: the grid of samples, the channels of each strip
/// row (the filtered ones, then the statistics read beside them), their
/// luminance weights and rules, and the per-pixel statistics' places.
#[derive(Clone, Debug)]
pub struct StripLayout {
    /// Sizes.
    pub grid: Grid,
    /// Channel names, in the order of the strips.
    pub channels: Vec<String>,
    /// Luminance weight of each channel (0 for alpha and carried channels).
    pub luminance: Vec<f64>,
    /// What the stage does with each channel ([`StripLayout::new`]: spread where
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
    /// Where the guide passes are (indices into `channels` then `aux`).
    pub guides: GuideLayout,
    /// How alike surface guides must be for a spread to cross them.
    pub surface_rule: SurfaceRule,
    /// `--edge pad`: the source holds this many samples (columns, rows), and
    /// the grid is that size completed with zero samples to a multiple of S
    /// ([`edge::Padded`], [`edge::Coverage`]).
    pub padded_from: Option<(usize, usize)>,
    /// Whether each decoding worker holds a decoded block of its own (the
    /// codecs `exr` decodes); blocks inflated straight into the reader's
    /// window (ZIP, ZIPS) need none.
    pub block_scratch: bool,
    /// Output rows the sink compresses together (an EXR block's scan
    /// lines; 1 where the output has no blocks).
    pub out_block_lines: usize,
    /// Bytes an input block takes in the file at most (0: as many as it
    /// decodes to): the mapped pages the reader's window holds a block.
    pub stored_block_bytes: u64,
    /// Workers per output block the sink compresses at once, at the least
    /// ([`WORKERS_PER_WRITE_BLOCK`] for the filter).
    pub workers_per_write_block: usize,
}

impl StripLayout {
    /// A job over `channels` with no statistics channels.
    pub fn new(grid: Grid, channels: Vec<String>, luminance: Vec<f64>) -> Self {
        let modes = luminance
            .iter()
            .map(|&l| ChannelMode::of(l, None, grid.s))
            .collect();
        let data = vec![false; channels.len()];
        StripLayout {
            grid,
            channels,
            luminance,
            modes,
            data,
            aux: Vec::new(),
            stats: None,
            guides: GuideLayout::default(),
            surface_rule: SurfaceRule::default(),
            padded_from: None,
            block_scratch: true,
            out_block_lines: 1,
            stored_block_bytes: 0,
            workers_per_write_block: WORKERS_PER_WRITE_BLOCK,
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
    pub method: MethodCounts,
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
    pub fn ep_gauss(&self) -> Option<SpreadCounts> {
        match self.method {
            MethodCounts::EpGauss(s) => Some(s),
            _ => None,
        }
    }

    /// ep-box's counts, if the run was ep-box.
    pub fn ep_box(&self) -> Option<ExcessCounts> {
        match self.method {
            MethodCounts::EpBox(s) => Some(s),
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
