//! The coarse grids of the spread (`--coarse-from`): wide kernels are
//! scattered on grids 2x and 4x coarser than the output, whose rows are
//! brought back up with a tent (the 4x grid's into the 2x grid's, the 2x
//! grid's into the accumulator's), each row once, in tap order.

use rayon::prelude::*;

use super::*;

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

impl GaussianStage {
    /// Add the coarse grids' share to the accumulator's final rows `a..b`
    /// (every coarse row a final row reads is final). Just before a 2x row is
    /// first read, the 4x grid's share enters it the same way (its 4x rows
    /// are final too: each reaches every fine row the 2x rows it feeds
    /// reach). A loop a grid: each row's task upsamples the coarse rows it
    /// reads across itself (one or two), then down, where a loop across and
    /// one down were two joins a grid (docs/DESIGN.md, "The model's join").
    pub(super) fn upsample(&mut self, a: usize, b: usize) {
        let (w, ncw) = (self.w, self.w.div_ceil(2));
        let last = self.c2.last_read(a, b);
        self.c2.grow_to(last);
        // Rows the accumulator no longer reaches were released unread (no
        // coarse spread reached them before the grid was used).
        let from = self.c2.read.max(self.c2.acc.first());
        if last >= from {
            if self.c4.used {
                let last4 = self.c4.last_read(from, last + 1);
                self.c4.grow_to(last4);
                tent_up(
                    &self.c4,
                    ncw,
                    &mut self.c2.acc,
                    (from, last + 1),
                    "upsample 4x",
                );
            }
            self.c2.read = last + 1;
        }
        tent_up(&self.c2, w, &mut self.acc, (a, b), "upsample");
    }
}

/// Bring the final rows of `coarse` into rows `a..b` of the grid twice as
/// fine, `dst` (`[c][x]` rows of `n_fine` per channel; the coarse rows are
/// `[c][X]` of `n_fine.div_ceil(2)`), a task a row: the coarse rows it reads
/// upsampled across (the same sums whichever row's task does it), then
/// down, each value `0 + w0 * a (+ w1 * b)`, added where it is not zero.
fn tent_up(
    coarse: &CoarseGrid,
    n_fine: usize,
    dst: &mut RowWindow<f64>,
    (a, b): (usize, usize),
    name: &'static str,
) {
    let n_coarse = n_fine.div_ceil(2);
    let (acc, tent_x, tent_y) = (&coarse.acc, &coarse.tent_x, &coarse.tent_y);
    let across = |y: usize, out: &mut Vec<f64>, len: usize| {
        out.resize(len, 0.0);
        let src = acc.get(y);
        for (src, dst) in src.chunks_exact(n_coarse).zip(out.chunks_exact_mut(n_fine)) {
            tent_x.gather(src, dst);
        }
    };
    let region = crate::trace::region(name);
    let mut rows = dst.range_mut(a, b);
    rows.par_iter_mut().enumerate().for_each_init(
        <(Vec<f64>, Vec<f64>)>::default,
        |(u0, u1), (k, row)| {
            let _task = region.task(name);
            // The same sum as the gather across: `0 + w0 * a (+ w1 * b)`.
            let (c, w) = tent_y.of(a + k);
            let add = |d: &mut f64, u: f64| {
                if u != 0.0 {
                    *d += u;
                }
            };
            match *w {
                [w0] => {
                    across(c, u0, row.len());
                    for (d, &v0) in row.iter_mut().zip(u0.iter()) {
                        let mut u = 0.0;
                        u += w0 * v0;
                        add(d, u);
                    }
                }
                [w0, w1] => {
                    across(c, u0, row.len());
                    across(c + 1, u1, row.len());
                    for ((d, &v0), &v1) in row.iter_mut().zip(u0.iter()).zip(u1.iter()) {
                        let mut u = 0.0;
                        u += w0 * v0;
                        u += w1 * v1;
                        add(d, u);
                    }
                }
                _ => unreachable!("one or two coarse rows per fine row"),
            }
        },
    );
}
