//! What a job will hold, from its sizes alone: the strips' height and the
//! memory estimate checked against `--max-memory` before anything is
//! allocated.

use super::{ChannelMode, FilterParams, Halo, Method, PipelineConfig, StripLayout};
use crate::filter::guides::{AlbedoOnly, Surface};

/// Bytes of input one strip should hold by default: four strips are in
/// flight at most (two queued, one being read, one being filtered), so this
/// bounds their memory to 16 MiB whatever the width (and [`STRIPS_RECYCLED`]
/// more wait to be filled again).
pub const STRIP_BYTES: usize = 4 << 20;

/// Strip buffers held at most: four in flight and [`STRIPS_RECYCLED`] waiting
/// to be filled again.
pub(super) const STRIPS_HELD: u64 = 4 + STRIPS_RECYCLED as u64;

/// Strip buffers the filter hands back to the reader at most, waiting to be
/// filled again (a new buffer is mapped and faulted in page by page: on wide
/// inputs they were most of the reader's page faults).
pub const STRIPS_RECYCLED: usize = 2;

/// Default strip height: [`STRIP_BYTES`] of f32 rows, between 1 and 96 rows.
pub fn auto_strip_rows(in_w: usize, channels: usize) -> usize {
    (STRIP_BYTES / (in_w * channels * 4).max(1)).clamp(1, 96)
}

/// Pixel rows a filtered strip holds at the least where there are workers
/// for them: a strip's rows are the tasks of its parallel loops
/// (classification, base rows, ledger), so a strip of few pixel rows bounds
/// the speed-up whatever the cores (on the widest inputs [`STRIP_BYTES`]
/// holds only a few pixel rows at S = 3). Six, not more, because each pixel
/// row more is paid in memory on those inputs: the window, and each of the
/// strips in flight ([`STRIPS_HELD`]).
pub const MIN_STRIP_PIXEL_ROWS: usize = 6;

/// Pixel rows a filtered strip holds at the least on few workers:
/// `STRIP_PIXEL_ROWS_PER_THREAD` a worker gives each its two tasks a loop
/// sooner, so one or two workers are not paid the memory of six rows.
/// Fewer than four make a strip's rounds (loops, hand-overs) the cost.
pub const FEWEST_STRIP_PIXEL_ROWS: usize = 4;

/// The least pixel rows of a strip on `threads` workers: two a worker,
/// between [`FEWEST_STRIP_PIXEL_ROWS`] and [`MIN_STRIP_PIXEL_ROWS`].
pub fn min_strip_pixel_rows(threads: usize) -> usize {
    (STRIP_PIXEL_ROWS_PER_THREAD * threads).clamp(FEWEST_STRIP_PIXEL_ROWS, MIN_STRIP_PIXEL_ROWS)
}

/// Pixel rows a strip holds where they fit in `TALL_STRIP_BYTES`: each of
/// a strip's loops (classification, base rows, finishing) has a task a
/// pixel row, and fewer strips are fewer loops.
pub const TALL_STRIP_PIXEL_ROWS: usize = 16;

/// The most input bytes a strip grown to `TALL_STRIP_PIXEL_ROWS` holds:
/// twice [`STRIP_BYTES`], so the widest inputs keep their
/// `MIN_STRIP_PIXEL_ROWS`.
pub const TALL_STRIP_BYTES: usize = 2 * STRIP_BYTES;

/// Pixel rows a strip holds per worker thread where they fit: two tasks a
/// worker in each of a strip's row loops, so that many workers are not left
/// waiting on a strip's last rows.
pub const STRIP_PIXEL_ROWS_PER_THREAD: usize = 2;

/// Input bytes a tall strip may hold per worker thread, beyond
/// `TALL_STRIP_BYTES`: a pixel row or two a worker at ordinary widths, and
/// the widest inputs keep their shorter strips.
pub const STRIP_BYTES_PER_THREAD: usize = 1 << 20;

impl StripLayout {
    /// Input rows per strip for `cfg`: `--strip-rows` where given, else
    /// [`Self::auto_strip_rows`] for its worker threads.
    pub fn strip_rows(&self, cfg: &PipelineConfig) -> usize {
        match cfg.strip_rows {
            0 => self.auto_strip_rows(cfg.geometry_workers()),
            n => n,
        }
    }

    /// Bytes of output rows the sink holds before it encodes them:
    /// `cfg.write_ahead`, or [`WRITE_AHEAD_BYTES_PER_THREAD`] a worker and
    /// at least a block of output rows ([`StripLayout::out_block_lines`]) for
    /// every [`WORKERS_PER_WRITE_BLOCK`] workers.
    pub fn write_ahead_bytes(&self, cfg: &PipelineConfig) -> usize {
        match cfg.write_ahead {
            0 => {
                let workers = cfg.geometry_workers();
                let block = (self.grid.out_w() * self.channels.len() * 4)
                    .saturating_mul(self.out_block_lines.max(1));
                let blocks = workers.div_ceil(WORKERS_PER_WRITE_BLOCK);
                (WRITE_AHEAD_BYTES_PER_THREAD * workers).max(block.saturating_mul(blocks))
            }
            n => n,
        }
    }

    /// Default strip height of this job on `threads` workers:
    /// [`auto_strip_rows`], at least `min_strip_pixel_rows` pixel rows
    /// (whole pixel rows: `S` input rows each); and `TALL_STRIP_PIXEL_ROWS`
    /// pixel rows, or `STRIP_PIXEL_ROWS_PER_THREAD` a worker, where that is
    /// more and they fit in `TALL_STRIP_BYTES` (or `STRIP_BYTES_PER_THREAD`
    /// a worker).
    pub fn auto_strip_rows(&self, threads: usize) -> usize {
        let s = self.grid.s.max(1);
        let (w, nch) = (self.grid.in_w.max(1), self.strip_channels().max(1));
        let rows = auto_strip_rows(w, nch).max(min_strip_pixel_rows(threads) * s);
        let tall = TALL_STRIP_PIXEL_ROWS.max(STRIP_PIXEL_ROWS_PER_THREAD * threads) * s;
        let limit = TALL_STRIP_BYTES.max(STRIP_BYTES_PER_THREAD * threads);
        let bytes = tall.saturating_mul(w).saturating_mul(nch * 4);
        if tall > rows && bytes <= limit {
            tall
        } else {
            rows
        }
    }
}

/// Decoded bytes the reader asks for at once (beyond one strip's rows),
/// whatever the thread count: enough chunks to keep 16 workers busy at
/// ordinary widths, few enough that memory stays small at 32k. Decoding
/// ahead, the reader holds a window of [`READ_AHEAD_BATCHES`] such batches'
/// blocks.
pub const READ_AHEAD_BYTES: u64 = 24 << 20;

/// Batches of [`read_ahead_blocks`] the reader's window of blocks decoding
/// ahead holds at once (`io::reader::ahead`).
pub const READ_AHEAD_BATCHES: u64 = 2;

/// Blocks (chunks) of `block_bytes` decoded bytes in a batch of the reader:
/// [`READ_AHEAD_BYTES`] of them, two at the least: the window of blocks
/// decoding ahead has no batch boundary to wait at, so a few blocks keep the
/// decoders busy, and more are paid in memory on wide inputs.
pub fn read_ahead_blocks(block_bytes: u64) -> u64 {
    (READ_AHEAD_BYTES / block_bytes.max(1)).max(2)
}

/// Blocks the reader's window of blocks decoding ahead holds at the least
/// where the threads ask for them: a block decodes on one core, so the
/// window bounds the cores decoding at once, and on the widest inputs
/// [`READ_AHEAD_BATCHES`] of [`read_ahead_blocks`] are too few blocks to
/// keep 16 cores decoding.
pub const WINDOW_MIN_BLOCKS: u64 = 8;

/// Blocks (chunks) of `block_bytes` decoded bytes the reader's window holds
/// for `cfg`: [`READ_AHEAD_BATCHES`] batches of [`read_ahead_blocks`], or
/// `WINDOW_MIN_BLOCKS` where that is more; at most
/// `WINDOW_BLOCKS_PER_THREAD` a worker thread, and a worker's second block
/// only where the batches' bytes hold it (`queued_blocks`).
/// [`fit_memory`] takes fewer under a small budget.
pub fn window_blocks(cfg: &PipelineConfig, block_bytes: u64) -> u64 {
    let threads = cfg.geometry_workers() as u64;
    let by_threads = (WINDOW_BLOCKS_PER_THREAD * threads).max(FEWEST_WINDOW_BLOCKS as u64);
    let by_bytes = READ_AHEAD_BATCHES * read_ahead_blocks(block_bytes);
    let queued = queued_blocks(threads, block_bytes);
    by_bytes.max(WINDOW_MIN_BLOCKS).min(by_threads).min(queued)
}

/// The most blocks a window of `threads` workers holds where a worker's
/// second block is queued only within [`READ_AHEAD_BATCHES`] x
/// [`READ_AHEAD_BYTES`]: one block a worker at the least. On the widest
/// inputs of many channels one block a worker decodes as fast at 2 threads,
/// and the second is paid in memory (docs/bench/s1-memory.md); on many
/// threads the window is bounded before.
pub fn queued_blocks(threads: u64, block_bytes: u64) -> u64 {
    let by_bytes = READ_AHEAD_BATCHES * READ_AHEAD_BYTES / block_bytes.max(1);
    threads.max(by_bytes).max(FEWEST_WINDOW_BLOCKS as u64)
}

/// Blocks the reader's window holds per worker thread at most: a block
/// decodes on one core, and with two a worker's next block is queued while
/// it decodes one; fewer were slower on 4 and 16 cores and more only held
/// memory (docs/bench/windows.md). A run on few threads no longer pays for a
/// window sized for many.
pub const WINDOW_BLOCKS_PER_THREAD: u64 = 2;

/// Bytes of output rows the sink holds per worker thread before it encodes
/// them in parallel: a block or two a worker at ordinary widths, so that a
/// batch keeps the workers compressing and few threads hold little.
pub const WRITE_AHEAD_BYTES_PER_THREAD: usize = 1 << 20;

/// Workers per output block the sink compresses at once, at the least.
/// A batch's blocks are its parallel tasks, and the workers share the cores
/// with the filter: a block for every two keeps the compression beside a
/// filter on many cores, where wide outputs of many channels (a few blocks
/// in `WRITE_AHEAD_BYTES_PER_THREAD` a worker) left it waiting for the
/// writer; on two workers one block was as fast as two.
pub const WORKERS_PER_WRITE_BLOCK: usize = 2;

/// The share of samples the estimate counts as noisy at once (one in this
/// many): ep-gauss keeps each noisy sample from its classification to its
/// spread, and the share is not known before the run. Denser noise holds
/// more than the estimate (the report's `samples_noisy` says how many a run
/// had; docs/bench/memory.md).
pub const NOISY_SHARE_INV: u64 = 10;

/// What the process holds beside a job's buffers: its code and libraries,
/// the threads' stacks, and the freed pages the allocator keeps for reuse
/// (the peak beside the heap's, docs/bench/memory.md). `--max-memory`
/// counts it. The binary's four arenas each keep up to their trim
/// threshold of freed memory, which varies from run to run with the thread
/// that freed last: the share counts all four (docs/bench/memory.md).
pub const PROGRAM_BYTES: u64 = 24 << 20;

/// The input file's bytes handed over before the reader releases their
/// pages (each release interrupts every core): at most this much of the
/// mapped input is resident beside the window of blocks decoding.
pub const MAPPED_RELEASE_BYTES: usize = 8 << 20;

/// The decoding workers' own blocks ([`StripLayout::block_scratch`]).
pub(super) fn scratch(job: &StripLayout, cfg: &PipelineConfig, block_bytes: u64) -> u64 {
    match job.block_scratch {
        true => block_bytes.saturating_mul(cfg.workers() as u64),
        false => 0,
    }
}

/// The reader's window of `blocks` blocks in bytes (at most
/// [`READ_AHEAD_BATCHES`] whole images of `h` rows of `row` bytes).
pub(super) fn read_ahead(row: u64, h: usize, block_bytes: u64, blocks: u64) -> u64 {
    let image = row.saturating_mul(h as u64).max(block_bytes);
    blocks
        .saturating_mul(block_bytes)
        .min(image.saturating_mul(READ_AHEAD_BATCHES))
}

/// Bytes a job will hold at most, from its sizes alone: the strips in flight,
/// the stage's windows (input rows, horizontal pass, base, accumulator, box
/// luminance) and the decoder's and encoder's blocks (`block_bytes`: one
/// decompressed input block). Checked against `--max-memory` before anything
/// is allocated, so a header claiming an absurd size gives an error instead of
/// an allocation failure (which would abort the process).
pub fn estimate_bytes(
    job: &StripLayout,
    params: &FilterParams,
    cfg: &PipelineConfig,
    block_bytes: u64,
) -> u64 {
    let blocks = match cfg.window_blocks {
        0 => window_blocks(cfg, block_bytes),
        n => n as u64,
    };
    estimate_with(job, params, cfg, block_bytes, blocks)
}

/// Blocks the reader decodes ahead at the least ([`fit_memory`]): one being
/// handed over while the next decodes.
pub const FEWEST_WINDOW_BLOCKS: usize = 2;

/// Bytes the sink holds before it encodes at the least ([`fit_memory`]):
/// one byte, so one block (a sink encodes a block at the least).
pub const FEWEST_WRITE_AHEAD: usize = 1;

/// How `cfg` runs `job` within `limit` bytes ([`estimate_bytes`]): as it is
/// where it fits; else with one strip in flight and shorter strips (halved
/// down to one pixel row, unless `--strip-rows` gave them), and the reader's
/// window and the sink's rows down to `FEWEST_WINDOW_BLOCKS` and one block,
/// the first that fits, tallest strips first. None
/// of it changes the result. `Err` holds what the smallest of them needs
/// (the halo's rows and one strip: the floor the job cannot go below).
pub fn fit_memory(
    job: &StripLayout,
    params: &FilterParams,
    cfg: &PipelineConfig,
    block_bytes: u64,
    limit: u64,
) -> std::result::Result<(PipelineConfig, u64), u64> {
    fit(job, cfg, limit, |c| {
        estimate_bytes(job, params, c, block_bytes)
    })
}

/// The first of `cfg`'s geometries that `need` says fits in `limit`
/// ([`fit_memory`]'s order), or the least any of them needs.
pub(super) fn fit(
    job: &StripLayout,
    cfg: &PipelineConfig,
    limit: u64,
    need: impl Fn(&PipelineConfig) -> u64,
) -> std::result::Result<(PipelineConfig, u64), u64> {
    let full = need(cfg);
    if full <= limit {
        return Ok((cfg.clone(), full));
    }
    let s = job.grid.s.max(1);
    let mut strips = Vec::new();
    match cfg.strip_rows {
        0 => {
            let mut rows = job.auto_strip_rows(cfg.geometry_workers());
            loop {
                strips.push(rows);
                if rows <= s {
                    break;
                }
                rows = (rows / 2 / s * s).max(s);
            }
        }
        n => strips.push(n),
    }
    let mut floor = u64::MAX;
    for &strip_rows in &strips {
        let fewest = (FEWEST_WINDOW_BLOCKS, FEWEST_WRITE_AHEAD);
        for (window_blocks, write_ahead) in [(cfg.window_blocks, cfg.write_ahead), fewest] {
            let c = PipelineConfig {
                strip_rows,
                window_blocks,
                write_ahead,
                strips_in_flight: 1,
                ..cfg.clone()
            };
            let n = need(&c);
            if n <= limit {
                return Ok((c, n));
            }
            floor = floor.min(n);
        }
    }
    Err(floor)
}

/// [`estimate_bytes`] with a reader's window of `blocks` blocks.
fn estimate_with(
    job: &StripLayout,
    params: &FilterParams,
    cfg: &PipelineConfig,
    block_bytes: u64,
    blocks: u64,
) -> u64 {
    let halo = crate::filter::halo(params);
    let pixel = params.method == Method::EpGauss && job.grid.s == 1;
    if params.method == Method::EpBox || pixel {
        return estimate_pixel_bytes(job, cfg, (block_bytes, blocks), halo, pixel);
    }
    let s = job.grid.s as u64;
    let nch = job.channels.len() as u64;
    let (w, ow) = (
        job.grid.in_w as u64,
        (job.grid.in_w / job.grid.s.max(1)) as u64,
    );
    let strip = job.strip_rows(cfg) as u64;
    // Input rows carry the statistics too (ep-gauss at S = 1 reads them).
    let in_row = w
        .saturating_mul(job.strip_channels() as u64)
        .saturating_mul(4);
    let out_row = ow.saturating_mul(nch).saturating_mul(8);
    // Base rows wait from the final rows to the classified ones (the width
    // search's and the spread's reach); each accumulator holds the spread's
    // reach behind the rows spread and its own kernels' reach ahead.
    let (search, spread, base) = (
        halo.search_reach as u64,
        halo.spread_reach as u64,
        halo.base_reach as u64,
    );
    let [fine, r2, r4] = crate::filter::grid_reaches(params).map(|r| r as u64);
    let base_rows = search + spread + base + strip / s + 4;
    let acc_rows = spread + fine + strip / s + 4;
    // With two strips in flight the later passes run a strip behind: the
    // box luminance, its table, the horizontal pass and the noisy samples
    // wait a strip longer.
    let behind = match super::stages::strips_in_flight(cfg, params.method, job.grid.s) {
        1 => 0,
        _ => strip,
    };
    let windows = in_row.saturating_mul(s * (halo.xbar_reach as u64 + 1) + strip)
        + out_row.saturating_mul(s * (2 * halo.base_reach as u64 + 1) + strip + behind)
        + out_row.saturating_mul(base_rows + acc_rows)
        // The box luminance, f32 rows of the padded width.
        + (ow + 2 * halo.search_reach as u64)
            .saturating_mul(4 * (2 * halo.search_reach as u64 + (strip + behind) / s + 4));
    // The summed-area table the bound reads (--bound-from): f64 rows of the
    // padded width, one more than the box luminance's.
    let table = if crate::filter::uses_bound(params) {
        (ow + 2 * halo.search_reach as u64 + 2)
            .saturating_mul(8 * (2 * halo.search_reach as u64 + (strip + behind) / s + 5))
    } else {
        0
    };
    // The coarse grids: accumulator rows of half (and a quarter of) the
    // width, over half (a quarter of) the rows behind and their own
    // kernels' reach ahead (each upsampling task holds two rows of its own,
    // not counted).
    let coarse = if params.method == Method::EpGauss && params.coarse_from > 0.0 {
        let behind = spread + strip / s;
        (out_row / 2).saturating_mul(behind / 2 + r2 + 4)
            + (out_row / 4).saturating_mul(behind / 4 + r4 + 4)
    } else {
        0
    };
    let strips = in_row.saturating_mul(strip).saturating_mul(STRIPS_HELD);
    // ep-gauss's noisy samples classified and not yet spread: the rows
    // between the two cursors (the width search's reach and a strip, and the
    // next strip's lists), `NOISY_SHARE` of their samples, each a position,
    // two luminances and its values, in lists with an eighth to spare.
    let pending = if params.method == Method::EpGauss {
        let samples = (search + 2 * (strip / s) + behind / s + 4)
            .saturating_mul(s * s)
            .saturating_mul(ow);
        let each = super::spread::PENDING_SAMPLE_BYTES as u64 + 8 * nch;
        (samples / NOISY_SHARE_INV).saturating_mul(each + each / 8)
    } else {
        0
    };
    // A block's scratch per decoding worker where `exr` decodes, and the
    // reader's window of decoded blocks.
    let blocks_n = blocks;
    let blocks = scratch(job, cfg, block_bytes).saturating_add(read_ahead(
        in_row,
        job.grid.in_h,
        block_bytes,
        blocks,
    ));
    windows
        .saturating_add(table)
        .saturating_add(coarse)
        .saturating_add(strips)
        .saturating_add(pending)
        .saturating_add(blocks)
        .saturating_add(around(job, cfg, (block_bytes, blocks_n), ow, strip / s))
}

/// What a job holds around its stage: the sink's rows waiting to be encoded
/// (`write_ahead` bytes of f32 rows, and as many encoded), the output rows
/// of three strips on their way to it (`ow` wide, `out_rows` a strip), and
/// the mapped input's resident pages (the window's compressed blocks, at
/// most their decoded size, and what waits to be released).
pub(super) fn around(
    job: &StripLayout,
    cfg: &PipelineConfig,
    (block_bytes, blocks): (u64, u64),
    ow: u64,
    out_rows: u64,
) -> u64 {
    let nch = job.channels.len() as u64;
    let out_f32 = ow.saturating_mul(nch * 4);
    (2 * job.write_ahead_bytes(cfg) as u64)
        .saturating_add(out_f32.saturating_mul(3 * out_rows))
        .saturating_add(MAPPED_RELEASE_BYTES as u64)
        .saturating_add(block_bytes.saturating_mul(blocks))
}

/// The pixel-resolution stages (ep-box; ep-gauss at S = 1): input rows
/// from the row being written to the treatment's reach past the rows
/// treated; the per-pixel windows (ep-box's from the passes' reach behind
/// the rows treated to the rows in; ep-gauss's a few rows about the rows
/// treated, and its lights and surface guides over the spreads' reach);
/// the sources waiting for their rows to be written ([`NOISY_SHARE_INV`]
/// of those rows' pixels) and the rows being made; each task's band arrays
/// (ep-box); strips in flight; the codec's blocks.
fn estimate_pixel_bytes(
    job: &StripLayout,
    cfg: &PipelineConfig,
    (block_bytes, blocks): (u64, u64),
    halo: Halo,
    gauss: bool,
) -> u64 {
    let w = job.grid.in_w as u64;
    let (nch, nall) = (job.channels.len() as u64, job.strip_channels() as u64);
    let strip = job.strip_rows(cfg) as u64;
    let (mut p, r) = (halo.search_reach as u64, halo.spread_reach as u64);
    if gauss {
        let choose = job.guides.emission.is_some() || job.guides.surface();
        p = super::schedule::lag(&super::pixel::gauss::passes(choose, r as usize)) as u64;
    }
    let threads = cfg.workers() as u64;
    let held = p + r + strip + 2;
    let input = w.saturating_mul(nall * 4).saturating_mul(held);
    let per_pixel = if gauss {
        // What the stage's window holds a pixel (`SurfaceGuides`).
        let surface = match &job.guides {
            g if g.albedo_only() => std::mem::size_of::<AlbedoOnly>() as u64,
            g if g.surface() => std::mem::size_of::<Surface>() as u64,
            _ => 0,
        };
        w.saturating_mul(8 + 8 + 1).saturating_mul(strip + 16)
            + w.saturating_mul(1 + surface).saturating_mul(held)
    } else {
        w.saturating_mul(8 + 8 + 1 + 1)
            .saturating_mul(2 * p + strip + 2)
    };
    // A source holds two values a spread channel, none of the others.
    let spread = job
        .modes
        .iter()
        .filter(|&&m| m == ChannelMode::Spread)
        .count() as u64;
    let sources = (w.saturating_mul(held) / NOISY_SHARE_INV).saturating_mul(40 + 16 * spread);
    let rows = w
        .saturating_mul(nch * 8)
        .saturating_mul(strip.max(16) + threads);
    let bands = match gauss {
        true => 0,
        // A task's band: each pixel's pass, and each noisy pixel's
        // reference, index and place in two pending lists (4 + 4 + 4 + 8 bytes).
        false => w
            .saturating_mul(1 + 20 / NOISY_SHARE_INV)
            .saturating_mul((32 + 2 * p) * threads.max(1)),
    };
    let strips = w
        .saturating_mul(nall * 4)
        .saturating_mul(strip * STRIPS_HELD);
    input
        .saturating_add(per_pixel)
        .saturating_add(sources)
        .saturating_add(rows)
        .saturating_add(bands)
        .saturating_add(strips)
        .saturating_add(scratch(job, cfg, block_bytes))
        .saturating_add(read_ahead(
            w.saturating_mul(nall * 4),
            job.grid.in_h,
            block_bytes,
            blocks,
        ))
        .saturating_add(around(job, cfg, (block_bytes, blocks), w, strip))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Grid;
    use crate::pipeline::strips_in_flight;

    #[test]
    fn a_batch_counts_bytes_two_blocks_at_the_least() {
        // 6144 x 3 samples wide, float RGB, 16-row ZIP blocks: the bytes
        // hold 7.
        let bench = 18432 * 3 * 4 * 16;
        assert_eq!(read_ahead_blocks(bench), 7);
        // Tiles of 64 x 64: bytes decide.
        let tile = 64 * 64 * 3 * 4;
        assert_eq!(read_ahead_blocks(tile), READ_AHEAD_BYTES / tile);
        // 32769 wide: 3 of its blocks.
        let wide = 32769 * 3 * 4 * 16;
        assert_eq!(read_ahead_blocks(wide), 3);
        // Blocks past the cap: two at the least.
        assert_eq!(read_ahead_blocks(READ_AHEAD_BYTES), 2);
        assert_eq!(read_ahead_blocks(0), READ_AHEAD_BYTES);
    }

    /// A float RGB job of `in_w` x `in_h` samples at S = 3.
    fn rgb(in_w: usize, in_h: usize) -> StripLayout {
        let grid = Grid { in_w, in_h, s: 3 };
        let names = ["R", "G", "B"].map(String::from).to_vec();
        StripLayout::new(grid, names, vec![0.2126, 0.7152, 0.0722])
    }

    #[test]
    fn strips_grow_to_sixteen_pixel_rows_where_they_fit() {
        // 12288 wide at S = 3: 28 rows by STRIP_BYTES (9.3 pixel rows); 48
        // fit in TALL_STRIP_BYTES.
        let square = rgb(12288, 12288);
        assert_eq!(square.auto_strip_rows(2), TALL_STRIP_PIXEL_ROWS * 3);
        // 32769 wide: 48 rows would not fit; the least pixel rows stay,
        // two a worker between four and six.
        let wide = rgb(32769, 3600);
        assert_eq!(wide.auto_strip_rows(1), FEWEST_STRIP_PIXEL_ROWS * 3);
        assert_eq!(wide.auto_strip_rows(2), FEWEST_STRIP_PIXEL_ROWS * 3);
        assert_eq!(wide.auto_strip_rows(3), MIN_STRIP_PIXEL_ROWS * 3);
        assert_eq!(wide.auto_strip_rows(4), MIN_STRIP_PIXEL_ROWS * 3);
        // Narrower: STRIP_BYTES already holds more pixel rows (56 rows).
        assert_eq!(rgb(6144, 6144).auto_strip_rows(2), 56);
        // Two pixel rows a worker where they fit: 16 workers get 32 at
        // 12288 wide; up to 8 workers keep 16.
        assert_eq!(square.auto_strip_rows(8), TALL_STRIP_PIXEL_ROWS * 3);
        assert_eq!(square.auto_strip_rows(16), 32 * 3);
        // At 32769 wide 32 pixel rows would not fit: the strip stays.
        assert_eq!(wide.auto_strip_rows(16), MIN_STRIP_PIXEL_ROWS * 3);
        // --strip-rows wins.
        let given = PipelineConfig {
            strip_rows: 7,
            threads: 16,
            ..PipelineConfig::default()
        };
        assert_eq!(square.strip_rows(&given), 7);
        // The estimate counts the taller strips.
        let (block, ep) = (12288 * 3 * 4 * 16, FilterParams::new(Method::EpGauss, 3));
        let short = PipelineConfig {
            strip_rows: 28,
            ..PipelineConfig::default()
        };
        let tall = estimate_bytes(&square, &ep, &PipelineConfig::default(), block);
        assert!(tall > estimate_bytes(&square, &ep, &short, block));
    }

    #[test]
    fn a_write_batch_holds_a_block_for_every_two_workers() {
        let on = |threads| PipelineConfig {
            threads,
            ..PipelineConfig::default()
        };
        // 8192 pixels wide at S = 1, nine channels, 16-row blocks: a block
        // is 4.5 MiB, more than a worker's bytes.
        let mut wide = rgb(8192, 4096);
        wide.grid.s = 1;
        wide.channels = (0..9).map(|c| c.to_string()).collect();
        wide.out_block_lines = 16;
        let block = 8192 * 9 * 4 * 16;
        assert_eq!(wide.write_ahead_bytes(&on(1)), block);
        assert_eq!(wide.write_ahead_bytes(&on(2)), block);
        assert_eq!(wide.write_ahead_bytes(&on(3)), 2 * block);
        assert_eq!(wide.write_ahead_bytes(&on(16)), 8 * block);
        // 4096 pixels of RGB at S = 3: a worker's bytes hold more.
        let mut narrow = rgb(12288, 12288);
        narrow.out_block_lines = 16;
        let per = WRITE_AHEAD_BYTES_PER_THREAD;
        assert_eq!(narrow.write_ahead_bytes(&on(2)), 2 * per);
        assert_eq!(narrow.write_ahead_bytes(&on(16)), 16 * per);
        // A given write-ahead wins.
        let given = PipelineConfig {
            write_ahead: 5,
            ..on(16)
        };
        assert_eq!(wide.write_ahead_bytes(&given), 5);
    }

    #[test]
    fn the_window_holds_eight_blocks_where_the_threads_ask() {
        let on = |threads| PipelineConfig {
            threads,
            ..PipelineConfig::default()
        };
        // 32769 wide, 16-row ZIP blocks: two batches hold 6; 16 threads
        // get 8, and 2 threads their 4.
        let block = 32769 * 3 * 4 * 16;
        assert_eq!(READ_AHEAD_BATCHES * read_ahead_blocks(block), 6);
        assert_eq!(window_blocks(&on(16), block), WINDOW_MIN_BLOCKS);
        assert_eq!(window_blocks(&on(2), block), 4);
        // Nine channels: a worker's second block no longer fits the
        // batches' bytes at 2 threads; 16 threads keep their 8.
        let nine = 32769 * 9 * 4 * 16;
        assert_eq!(window_blocks(&on(2), nine), 2);
        assert_eq!(window_blocks(&on(16), nine), WINDOW_MIN_BLOCKS);
        // The estimate counts the whole window, for every method.
        let wide = rgb(32769, 3600);
        for m in [Method::Box, Method::Gauss, Method::EpGauss] {
            let p = FilterParams::new(m, 3);
            let eight = estimate_bytes(&wide, &p, &on(16), block);
            let two = estimate_bytes(
                &wide,
                &p,
                &PipelineConfig {
                    window_blocks: 2,
                    ..on(16)
                },
                block,
            );
            assert!(eight >= two + 6 * block, "{m:?}");
        }
        // Narrower: two batches already hold more than 8 blocks.
        let block = 12288 * 3 * 4 * 16;
        let by_bytes = READ_AHEAD_BATCHES * read_ahead_blocks(block);
        assert!(by_bytes > WINDOW_MIN_BLOCKS);
        assert_eq!(window_blocks(&on(16), block), by_bytes);
    }

    #[test]
    fn a_smaller_budget_runs_shorter_strips_and_fewer_blocks_down_to_a_floor() {
        let job = rgb(6144, 6144);
        let block = 6144 * 3 * 4 * 16;
        let cfg = PipelineConfig::default();
        for m in [Method::EpGauss, Method::Box] {
            let p = FilterParams::new(m, 3);
            let full = estimate_bytes(&job, &p, &cfg, block);
            // Within the default estimate: nothing changes.
            let same = fit_memory(&job, &p, &cfg, block, full).unwrap().0;
            assert_eq!((same.strip_rows, same.window_blocks), (0, 0), "{m:?}");
            // The floor: strips of one pixel row, the fewest blocks.
            let floor = fit_memory(&job, &p, &cfg, block, 0).unwrap_err();
            assert!(floor < full, "{m:?}: {floor} vs {full}");
            let at_floor = fit_memory(&job, &p, &cfg, block, floor).unwrap().0;
            assert_eq!(at_floor.strip_rows, 3, "{m:?}");
            assert_eq!(at_floor.window_blocks, FEWEST_WINDOW_BLOCKS, "{m:?}");
            // Between: whatever is chosen fits, and a larger budget never
            // gets shorter strips.
            let mut last = 0;
            for k in 0..=8 {
                let limit = floor + (full - floor) * k / 8;
                let c = fit_memory(&job, &p, &cfg, block, limit).unwrap().0;
                assert!(estimate_bytes(&job, &p, &c, block) <= limit, "{m:?} {k}");
                let rows = job.strip_rows(&c);
                assert!(rows >= last, "{m:?} {k}: {rows} after {last}");
                last = rows;
            }
        }
        // Strips the user set stay as set.
        let given = PipelineConfig {
            strip_rows: 12,
            ..PipelineConfig::default()
        };
        let p = FilterParams::new(Method::EpGauss, 3);
        let floor = fit_memory(&job, &p, &given, block, 0).unwrap_err();
        assert_eq!(
            fit_memory(&job, &p, &given, block, floor)
                .unwrap()
                .0
                .strip_rows,
            12
        );
    }

    #[test]
    fn two_strips_in_flight_hold_a_strip_more_and_go_first_under_a_budget() {
        let job = rgb(6144, 6144);
        let block = 6144 * 3 * 4 * 16;
        let two = PipelineConfig {
            threads: 2,
            strips_in_flight: 2,
            ..PipelineConfig::default()
        };
        let one = PipelineConfig {
            strips_in_flight: 1,
            ..two.clone()
        };
        let strip = job.strip_rows(&two);
        for m in [Method::EpGauss, Method::Gauss, Method::Box] {
            let p = FilterParams::new(m, 3);
            let (e2, e1) = (
                estimate_bytes(&job, &p, &two, block),
                estimate_bytes(&job, &p, &one, block),
            );
            // A strip more of the horizontal pass at the least (f64 rows
            // of the output width, three channels).
            assert!(e2 >= e1 + (strip * 2048 * 3 * 8) as u64, "{m:?}: {e2} {e1}");
            // Between the two: the same strips, one in flight.
            let c = fit_memory(&job, &p, &two, block, e1).unwrap().0;
            assert_eq!(
                (c.strips_in_flight(), job.strip_rows(&c)),
                (1, strip),
                "{m:?}"
            );
        }
        // One worker, and the stages of other methods: one strip.
        let lone = PipelineConfig {
            threads: 1,
            ..PipelineConfig::default()
        };
        assert_eq!(lone.strips_in_flight(), 1);
        assert_eq!(strips_in_flight(&two, Method::Gauss, 3), 2);
        for (m, s) in [
            (Method::EpBox, 1),
            (Method::EpGauss, 1),
            (Method::Median, 3),
        ] {
            assert_eq!(strips_in_flight(&two, m, s), 1, "{m:?}");
        }
    }

    #[test]
    fn the_window_holds_two_blocks_a_thread_at_most() {
        let job = rgb(6144, 6144);
        let block = 6144 * 3 * 4 * 16;
        let p = FilterParams::new(Method::EpGauss, 3);
        let at = |threads| {
            // Sized for `threads`, run on 2; the strips and the sink's rows
            // as on 2 threads (they follow the threads too).
            let cfg = PipelineConfig {
                threads: 2,
                geometry_threads: threads,
                strip_rows: 56,
                write_ahead: 2 << 20,
                ..PipelineConfig::default()
            };
            (
                window_blocks(&cfg, block),
                estimate_bytes(&job, &p, &cfg, block),
            )
        };
        let by_bytes = READ_AHEAD_BATCHES * read_ahead_blocks(block);
        assert_eq!(at(1).0, 2);
        assert_eq!(at(2).0, 4);
        assert_eq!(at(64).0, by_bytes);
        // Fewer blocks are less memory, by the blocks' bytes: decoded, and
        // their compressed pages (counted at most as much).
        assert_eq!(at(64).1 - at(1).1, 2 * (by_bytes - 2) * block);
    }

    #[test]
    fn blocks_inflated_in_place_hold_no_scratch() {
        let block = 32769 * 3 * 4 * 16;
        let cfg = PipelineConfig {
            threads: 16,
            ..PipelineConfig::default()
        };
        let mut job = rgb(32769, 3600);
        for m in [Method::Box, Method::Gauss, Method::EpGauss] {
            let p = FilterParams::new(m, 3);
            job.block_scratch = true;
            let exr = estimate_bytes(&job, &p, &cfg, block);
            job.block_scratch = false;
            let zip = estimate_bytes(&job, &p, &cfg, block);
            assert_eq!(exr - zip, 16 * block, "{m:?}");
        }
    }

    #[test]
    fn the_accumulators_count_their_own_kernels_reach() {
        // ep-gauss at S = 3: the output grid's kernels reach a few rows
        // (the wider ones go on the coarse grids), so its accumulator holds
        // fewer rows than the widest kernel's reach twice over.
        let (job, block) = (rgb(6144, 6144), 6144 * 3 * 4 * 16);
        let mut p = FilterParams::new(Method::EpGauss, 3);
        let cfg = PipelineConfig::default();
        let [fine, r2, r4] = crate::filter::grid_reaches(&p);
        let spread = crate::filter::halo(&p).spread_reach;
        assert!(fine < spread / 4 && r2 > 0 && r4 > 0, "{fine} {r2} {r4}");
        let coarse = estimate_bytes(&job, &p, &cfg, block);
        // Without the coarse grids every width is on the output grid.
        p.coarse_from = 0.0;
        assert_eq!(crate::filter::grid_reaches(&p), [spread, 0, 0]);
        // The wide kernels' rows on coarse grids of half and a quarter the
        // rows and width cost less than on the output grid.
        assert!(estimate_bytes(&job, &p, &cfg, block) > coarse);
    }
}
