//! What a job will hold, from its sizes alone: the strips' height and the
//! memory estimate checked against `--max-memory` before anything is
//! allocated.

use super::*;

/// Bytes of input one strip should hold by default: four strips are in
/// flight at most (two queued, one being read, one being filtered), so this
/// bounds their memory to 16 MiB whatever the width.
pub const STRIP_BYTES: usize = 4 << 20;

/// Default strip height: [`STRIP_BYTES`] of f32 rows, between 1 and 96 rows.
pub fn auto_strip_rows(in_w: usize, channels: usize) -> usize {
    (STRIP_BYTES / (in_w * channels * 4).max(1)).clamp(1, 96)
}

/// Decoded bytes the reader asks for at once (beyond one strip's rows),
/// whatever the thread count: enough chunks to keep 16 workers busy at
/// ordinary widths, few enough that memory stays small at 32k.
pub const READ_AHEAD_BYTES: u64 = 24 << 20;

/// The reader's batch: [`READ_AHEAD_BYTES`] (two blocks at the least), at
/// most the whole image (`h` rows of `row` bytes).
fn read_ahead(row: u64, h: usize, block_bytes: u64) -> u64 {
    let image = row.saturating_mul(h as u64).max(block_bytes);
    READ_AHEAD_BYTES
        .max(block_bytes.saturating_mul(2))
        .min(image)
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
    // The encoder's blocks, and the reader's batch of decoded blocks.
    let blocks = block_bytes.saturating_mul(3 * 4).saturating_add(read_ahead(
        in_row,
        job.grid.in_h,
        block_bytes,
    ));
    windows
        .saturating_add(coarse)
        .saturating_add(strips)
        .saturating_add(blocks)
        .saturating_add(out_row.saturating_mul(16 * 4))
}

fn estimate_box_bytes(
    job: &StripLayout,
    cfg: &PipelineConfig,
    block_bytes: u64,
    halo: Halo,
) -> u64 {
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
        .saturating_add(read_ahead(
            w.saturating_mul(nall * 4),
            job.grid.in_h,
            block_bytes,
        ))
        .saturating_add(w.saturating_mul(nch * 8 * 16 * 4))
}
