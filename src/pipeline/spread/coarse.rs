//! The coarse grids of the spread (`--coarse-from`): wide kernels are
//! scattered on grids 2x and 4x coarser than the output, whose rows are
//! brought back up with a tent (the 4x grid's into the 2x grid's, the 2x
//! grid's into the accumulator's), each row once, in tap order.

use super::{Back, RowWindow, TentTaps};

/// A coarse grid of the spread (`--coarse-from`): its accumulator (`[c][X]`
/// rows of cells `factor` times coarser than the grid it feeds), the tent's
/// taps, and whether anything was spread on it.
pub(super) struct CoarseGrid {
    pub(super) acc: RowWindow<f64>,
    pub(super) tent_x: TentTaps,
    pub(super) tent_y: TentTaps,
    pub(super) used: bool,
    /// The 2x grid: rows before this one have been read by the accumulator's
    /// (final, with the 4x grid's share in).
    pub(super) read: usize,
}

impl CoarseGrid {
    /// A grid `factor` times coarser than the `(w, h)` one it feeds
    /// (taps only when it is `on`).
    pub(super) fn new(nch: usize, (w, h): (usize, usize), factor: usize, on: bool) -> Self {
        CoarseGrid {
            acc: RowWindow::new(nch * w.div_ceil(factor)),
            tent_x: TentTaps::new(if on { w } else { 0 }),
            tent_y: TentTaps::new(if on { h } else { 0 }),
            used: false,
            read: 0,
        }
    }

    /// The last of its rows that rows `a..b` of the grid it feeds read.
    fn last_read(&self, a: usize, b: usize) -> usize {
        (a..b)
            .map(|y| {
                let (c, w) = self.tent_y.of(y);
                c + w.len() - 1
            })
            .max()
            .unwrap_or(0)
    }

    /// Its rows up to `last`, the new ones zero.
    fn grow_to(&mut self, last: usize) {
        while self.acc.end() <= last {
            self.acc.push(0.0);
        }
    }
}

impl Back {
    /// The coarse grids' rows that the accumulator's final rows `a..b` read
    /// (every one of them final), grown where new; returns the 2x rows that
    /// are read for the first time and must take the 4x grid's share first
    /// (its 4x rows are final too: each reaches every fine row the 2x rows
    /// it feeds reach), where the 4x grid is used.
    /// [`Back::coarse_share`] then brings them up, a task a row:
    /// each task upsamples the coarse rows it reads across itself (one or
    /// two), then down.
    pub(super) fn coarse_rows_read(&mut self, a: usize, b: usize) -> Option<(usize, usize)> {
        let Back { c2, c4, .. } = self;
        let last = c2.last_read(a, b);
        c2.grow_to(last);
        // Rows the accumulator no longer reaches were released unread (no
        // coarse spread reached them before the grid was used).
        let from = c2.read.max(c2.acc.first());
        if last < from {
            return None;
        }
        c2.read = last + 1;
        if !c4.used {
            return None;
        }
        c4.grow_to(c4.last_read(from, last + 1));
        Some((from, last + 1))
    }
}

/// Bring the final rows of `coarse` into row `y` of the grid twice as fine
/// (`[c][x]`, `n_fine` columns per channel; the coarse rows are `[c][X]` of
/// `n_fine.div_ceil(2)`): the coarse rows it reads upsampled across into
/// `up` (the same sums whichever row's task does it), then down, each value
/// `0 + w0 * a (+ w1 * b)`, added where it is not zero.
pub(super) fn tent_row(
    coarse: &CoarseGrid,
    n_fine: usize,
    y: usize,
    row: &mut [f64],
    [u0, u1]: &mut [Vec<f64>; 2],
) {
    let n_coarse = n_fine.div_ceil(2);
    let (acc, tent_x) = (&coarse.acc, &coarse.tent_x);
    let across = |y: usize, out: &mut Vec<f64>| {
        out.resize(row.len(), 0.0);
        for (src, dst) in acc
            .get(y)
            .chunks_exact(n_coarse)
            .zip(out.chunks_exact_mut(n_fine))
        {
            tent_x.gather(src, dst);
        }
    };
    // The same sum as the gather across: `0 + w0 * a (+ w1 * b)`.
    let add = |d: &mut f64, u: f64| {
        if u != 0.0 {
            *d += u;
        }
    };
    let (c, w) = coarse.tent_y.of(y);
    match *w {
        [w0] => {
            across(c, u0);
            for (d, &v0) in row.iter_mut().zip(u0.iter()) {
                let mut u = 0.0;
                u += w0 * v0;
                add(d, u);
            }
        }
        [w0, w1] => {
            across(c, u0);
            across(c + 1, u1);
            for ((d, &v0), &v1) in row.iter_mut().zip(u0.iter()).zip(u1.iter()) {
                let mut u = 0.0;
                u += w0 * v0;
                u += w1 * v1;
                add(d, u);
            }
        }
        _ => unreachable!("one or two coarse rows per fine row"),
    }
}
