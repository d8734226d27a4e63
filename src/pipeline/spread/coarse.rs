//! The coarse grids of the spread (`--coarse-from`): wide kernels are
//! scattered on grids 2x and 4x coarser than the output, whose rows are
//! brought back up with a tent (the 4x grid's into the 2x grid's, the 2x
//! grid's into the accumulator's), each row once, in tap order.

use rayon::prelude::*;

use super::*;

/// A coarse grid of the spread (`--coarse-from`): its accumulator (`[c][X]`
/// rows of cells `factor` times coarser than the grid it feeds), its rows
/// upsampled across to that grid (`[c][x]`), the tent's taps, and whether
/// anything was spread on it.
pub(super) struct CoarseGrid {
    pub(super) acc: RowWindow<f64>,
    pub(super) up: RowWindow<f64>,
    pub(super) tent_x: TentTaps,
    pub(super) tent_y: TentTaps,
    pub(super) used: bool,
}

impl CoarseGrid {
    /// A grid `factor` times coarser than the `(w, h)` one it feeds
    /// (taps only when it is `on`).
    pub(super) fn new(nch: usize, (w, h): (usize, usize), factor: usize, on: bool) -> Self {
        CoarseGrid {
            acc: RowWindow::new(nch * w.div_ceil(factor)),
            up: RowWindow::new(nch * w),
            tent_x: TentTaps::new(if on { w } else { 0 }),
            tent_y: TentTaps::new(if on { h } else { 0 }),
            used: false,
        }
    }
}

impl GaussianStage {
    /// Add the coarse grids' share to the accumulator's final rows `a..b`:
    /// each 2x row upsampled across once (when first needed: final, as
    /// every coarse row a final row reads is), then down, in tap order. Just
    /// before a 2x row is upsampled, the 4x grid's share enters it the same
    /// way (its 4x rows are final too: each reaches every fine row the 2x
    /// rows it feeds reach).
    pub(super) fn upsample(&mut self, a: usize, b: usize) {
        let (w, ncw) = (self.w, self.w.div_ceil(2));
        let four = self.c4.used;
        let (cacc4, hup4) = (&mut self.c4.acc, &mut self.c4.up);
        let tents4 = (&self.c4.tent_x, &self.c4.tent_y);
        tent_up(
            (&mut self.c2.acc, &mut self.c2.up),
            (&self.c2.tent_x, &self.c2.tent_y),
            w,
            &mut self.acc,
            (a, b),
            |cacc, from, last| {
                if four {
                    tent_up(
                        (cacc4, hup4),
                        tents4,
                        ncw,
                        cacc,
                        (from, last + 1),
                        |_, _, _| {},
                    );
                }
            },
        );
    }
}

/// Bring a coarse grid into rows `a..b` of the grid twice as fine, `dst`
/// (`[c][x]` rows of `n_fine` per channel; the coarse rows are `[c][X]` of
/// `n_fine.div_ceil(2)`): each coarse row upsampled across into `up` once,
/// when first needed (`before` sees the coarse rows `from..=last` just
/// before), then down: each value `0 + w0 * a (+ w1 * b)`, added where it
/// is not zero.
fn tent_up(
    (coarse, up): (&mut RowWindow<f64>, &mut RowWindow<f64>),
    (tent_x, tent_y): (&TentTaps, &TentTaps),
    n_fine: usize,
    dst: &mut RowWindow<f64>,
    (a, b): (usize, usize),
    before: impl FnOnce(&mut RowWindow<f64>, usize, usize),
) {
    let n_coarse = n_fine.div_ceil(2);
    let last = (a..b)
        .map(|y| {
            let (c, w) = tent_y.of(y);
            c + w.len() - 1
        })
        .max()
        .unwrap_or(0);
    while coarse.end() <= last {
        coarse.push(0.0);
    }
    let from = up.end();
    if last >= from {
        before(coarse, from, last);
        for _ in from..=last {
            up.push_stale(0.0); // every value is written below
        }
        let coarse = &*coarse;
        let region = crate::trace::region("upsample across");
        let mut rows = up.range_mut(from, last + 1);
        rows.par_iter_mut().enumerate().for_each(|(k, row)| {
            let _task = region.task("upsample across");
            let src = coarse.get(from + k);
            for (src, dst) in src.chunks_exact(n_coarse).zip(row.chunks_exact_mut(n_fine)) {
                tent_x.gather(src, dst);
            }
        });
    }
    let up = &*up;
    let region = crate::trace::region("upsample down");
    let mut rows = dst.range_mut(a, b);
    rows.par_iter_mut().enumerate().for_each(|(k, row)| {
        let _task = region.task("upsample down");
        // The same sum as the gather across: `0 + w0 * a (+ w1 * b)`.
        let (c, w) = tent_y.of(a + k);
        let add = |d: &mut f64, u: f64| {
            if u != 0.0 {
                *d += u;
            }
        };
        match *w {
            [w0] => {
                let r0 = up.get(c);
                for (d, &v0) in row.iter_mut().zip(r0) {
                    let mut u = 0.0;
                    u += w0 * v0;
                    add(d, u);
                }
            }
            [w0, w1] => {
                let (r0, r1) = (up.get(c), up.get(c + 1));
                for ((d, &v0), &v1) in row.iter_mut().zip(r0).zip(r1) {
                    let mut u = 0.0;
                    u += w0 * v0;
                    u += w1 * v1;
                    add(d, u);
                }
            }
            _ => unreachable!("one or two coarse rows per fine row"),
        }
    });
}
