//! What `epfilt restore` holds, from its sizes alone (beside
//! [`crate::pipeline::estimate`]'s model of the filters).

use crate::pipeline::estimate::{around, fit, read_ahead, scratch, window_blocks, STRIPS_HELD};
use crate::pipeline::{PipelineConfig, StripLayout};

/// Bytes per block and channel of `epfilt restore`'s targets: the first
/// pass's sums (three f64) and the field's target and shape (two); and,
/// one channel at a time, the targets' solve (about eleven words).
const RESTORE_BLOCK_BYTES: u64 = 5 * 8;
const RESTORE_SOLVE_BYTES: u64 = 11 * 8;

/// Bytes `epfilt restore` (blocks of `scale` pixels) holds at most for
/// `job` (its strips), from its sizes alone, beside [`crate::pipeline::PROGRAM_BYTES`]: the
/// input rows of the rows of blocks held ([`LOOKAHEAD`] ahead of the one
/// after the row being finished, and the kept part's reach), the part kept
/// and the final rows, the strips in flight, each input's blocks read ahead
/// (`block_bytes`), and every block's targets (the one part that grows with
/// the height: a few words per `scale x scale` pixels).
///
/// [`LOOKAHEAD`]: crate::filter::restore::LOOKAHEAD
pub fn restore_bytes(
    job: &StripLayout,
    scale: usize,
    cfg: &PipelineConfig,
    block_bytes: [u64; 2],
) -> u64 {
    use crate::filter::restore::{taps, KEEP_SIGMA, LOOKAHEAD};
    let (w, h) = (job.grid.in_w as u64, job.grid.in_h);
    let nch = job.channels.len() as u64;
    let strip = job.strip_rows(cfg) as u64;
    let reach = (taps(KEEP_SIGMA).len() / 2) as u64;
    let held = reach + (LOOKAHEAD as u64 + 2).saturating_mul(scale as u64) + strip;
    let in_row = w.saturating_mul(job.strip_channels() as u64 * 4);
    let out_row = w.saturating_mul(nch * 8);
    // The input rows and the part kept of each; the final rows in f64 of
    // a row of blocks and a strip, and in f32 on their way out (two queued
    // for the writer, one written). Each field's tents (four words a column).
    let finished = (scale as u64).saturating_add(strip);
    let rows = (in_row.saturating_add(out_row))
        .saturating_mul(held)
        .saturating_add((out_row + 3 * (out_row / 2)).saturating_mul(finished))
        .saturating_add(w.saturating_mul(32 * nch));
    // And the two inputs' own strips, before the pair puts them side by
    // side.
    let strips = in_row.saturating_mul(strip).saturating_mul(STRIPS_HELD + 1);
    let mut blocks = 0u64;
    let mut windows = 0u64;
    for b in block_bytes {
        let n = match cfg.window_blocks {
            0 => window_blocks(cfg, b),
            n => n as u64,
        };
        windows += n;
        blocks = blocks
            .saturating_add(scratch(job, cfg, b))
            .saturating_add(read_ahead(in_row, h, b, n));
    }
    let largest = block_bytes[0].max(block_bytes[1]);
    let grid = (w.div_ceil(scale as u64)).saturating_mul(h.div_ceil(scale) as u64);
    let targets = grid.saturating_mul(nch * RESTORE_BLOCK_BYTES + RESTORE_SOLVE_BYTES);
    let ahead = around(job, cfg, (largest, windows), w, strip);
    [strips, blocks, targets, ahead]
        .iter()
        .fold(rows, |a, &b| a.saturating_add(b))
}

/// How `cfg` runs `epfilt restore` of `job` within `limit` bytes
/// ([`restore_bytes`]), in [`crate::pipeline::fit_memory`]'s order; `Err` holds what the
/// smallest needs (the rows of blocks held and one strip).
pub fn fit_restore_memory(
    job: &StripLayout,
    scale: usize,
    cfg: &PipelineConfig,
    block_bytes: [u64; 2],
    limit: u64,
) -> std::result::Result<(PipelineConfig, u64), u64> {
    fit(job, cfg, limit, |c| {
        restore_bytes(job, scale, c, block_bytes)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Grid;

    #[test]
    fn restore_holds_its_rows_of_blocks_and_fits_a_budget_by_shorter_strips() {
        let grid = Grid {
            in_w: 16384,
            in_h: 1024,
            s: 1,
        };
        let names = ["R", "G", "B"].map(String::from).to_vec();
        let mut job = StripLayout::new(grid, names, vec![0.2126, 0.7152, 0.0722]);
        job.aux = ["dR", "dG", "dB"].map(String::from).to_vec();
        let block = 16384 * 6 * 4 * 16;
        let cfg = PipelineConfig::default();
        let at = |scale| restore_bytes(&job, scale, &cfg, [block, block]);
        // Each scale's rows of blocks: the input rows (six f32 channels) and
        // the part kept (f64, three channels) of LOOKAHEAD + 2 rows of blocks;
        // the final rows (f64, and f32 three times) of one row of blocks.
        // Less its targets (16384 blocks of 32, 1024 of 128).
        let held = 16384 * (6 * 4 + 3 * 8);
        let finished = 16384 * (3 * 8 + 3 * 3 * 4);
        let step = ((crate::filter::restore::LOOKAHEAD as u64 + 2) * held + finished) * 96;
        let per_block = 3 * RESTORE_BLOCK_BYTES + RESTORE_SOLVE_BYTES;
        assert_eq!(at(128) + (16384 - 1024) * per_block - at(32), step);
        // Under a budget between the floor and the default: shorter strips.
        let full = at(32);
        let floor = fit_restore_memory(&job, 32, &cfg, [block, block], 0).unwrap_err();
        assert!(floor < full, "{floor} {full}");
        let (c, need) =
            fit_restore_memory(&job, 32, &cfg, [block, block], (floor + full) / 2).unwrap();
        assert!(need <= (floor + full) / 2);
        assert!(job.strip_rows(&c) < job.strip_rows(&cfg));
        assert_eq!(
            fit_restore_memory(&job, 32, &cfg, [block, block], full)
                .unwrap()
                .0
                .strip_rows,
            0
        );
    }
}
