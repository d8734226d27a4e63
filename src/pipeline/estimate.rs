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
    /// every [`StripLayout::workers_per_write_block`] workers.
    pub fn write_ahead_bytes(&self, cfg: &PipelineConfig) -> usize {
        match cfg.write_ahead {
            0 => {
                let workers = cfg.geometry_workers();
                let block = (self.grid.out_w() * self.channels.len() * 4)
                    .saturating_mul(self.out_block_lines.max(1));
                let blocks = workers.div_ceil(self.workers_per_write_block.max(1));
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

/// Workers per output block the sink compresses at once, at the least,
/// for the filter ([`StripLayout::workers_per_write_block`]). A batch's
/// blocks are its parallel tasks, and the workers share the cores with the
/// filter: a block for every two keeps the compression beside a filter on
/// many cores, where wide outputs of many channels (a few blocks in
/// `WRITE_AHEAD_BYTES_PER_THREAD` a worker) left it waiting for the writer;
/// on two workers one block was as fast as two.
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

/// Bytes from which the binary's allocator gives an allocation pages of
/// its own, returned to the system when it is freed (glibc's
/// `M_MMAP_THRESHOLD`, set by the binary at start). A smaller buffer freed
/// among live ones stays in the allocator's arena.
pub const MAPPED_ALLOCATION_BYTES: usize = 4 << 20;

/// An empty buffer for `n` values that the allocator maps on its own
/// ([`MAPPED_ALLOCATION_BYTES`] at the least), so that it goes back to the
/// system when dropped, however few values it holds: buffers of short strips
/// (the memory fitting's) freed among live ones otherwise stayed in the
/// arenas, and held more than the default strips. The pages its values do
/// not fill are never touched.
pub fn own_pages<T>(n: usize) -> Vec<T> {
    Vec::with_capacity(n.max(MAPPED_ALLOCATION_BYTES / std::mem::size_of::<T>().max(1)))
}

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
/// the mapped input's resident pages (the window's blocks as the file
/// stores them, [`StripLayout::stored_block_bytes`], at most their decoded
/// size, and what waits to be released).
pub(super) fn around(
    job: &StripLayout,
    cfg: &PipelineConfig,
    (block_bytes, blocks): (u64, u64),
    ow: u64,
    out_rows: u64,
) -> u64 {
    let nch = job.channels.len() as u64;
    let out_f32 = ow.saturating_mul(nch * 4);
    let stored = match job.stored_block_bytes {
        0 => block_bytes,
        n => n.min(block_bytes),
    };
    (2 * job.write_ahead_bytes(cfg) as u64)
        .saturating_add(out_f32.saturating_mul(3 * out_rows))
        .saturating_add(MAPPED_RELEASE_BYTES as u64)
        .saturating_add(stored.saturating_mul(blocks))
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
    let rows = w.saturating_mul(nch * 8).saturating_mul(strip + threads);
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
mod tests;
