//! The stage's row work beside other loops: the box luminance of new rows,
//! and what one advance plans for the next push (base rows, the coarse
//! grids' share of final rows), done beside that push's first loops: the
//! books' loop takes the box luminance, the base rows and the 4x grid's
//! share of 2x rows; classification's first loop the share of final rows
//! (docs/DESIGN.md, "The trace and the scaling model"). A row's values are the
//! same whichever loop computes them.

use rayon::prelude::*;

use super::scatter::Accs;
use super::*;

/// Work an advance plans for the next push: base rows, the 2x rows that
/// take the 4x grid's share, the accumulator rows that take the coarse
/// share, and the output rows that are final once all of it is done.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Due {
    pub(super) base: Option<(usize, usize)>,
    pub(super) four: Option<(usize, usize)>,
    pub(super) up: Option<(usize, usize)>,
    pub(super) out: usize,
}

impl GaussianStage {
    /// Plan the base rows up to `base_target` and the coarse share of the
    /// rows the spreading has made final (`by_spread`), after the last plan's
    /// work is done; at the image's end (`all_in`) do them now. Returns the
    /// end of the output rows whose work is done.
    pub(super) fn plan_rows(
        &mut self,
        base_target: usize,
        by_spread: usize,
        all_in: bool,
    ) -> usize {
        // The last plan's work ran in this push's loops (the books' and
        // classification's, or `run`'s own).
        debug_assert!(self.due.base.is_none() && self.due.four.is_none() && self.due.up.is_none());
        let done = self.due.out;
        let base = (base_target > self.base_planned).then_some((self.base_planned, base_target));
        self.base_planned = self.base_planned.max(base_target);
        let out = self.base_planned.min(by_spread).max(done);
        // The coarse grid's share of final rows (none before it was used:
        // no coarse spread reaches a row that was final before it).
        let up = (out > self.up_done && self.c2.used).then_some((self.up_done, out));
        self.up_done = self.up_done.max(out);
        // The 2x rows that take the 4x share before the accumulator reads
        // them.
        let four = up.and_then(|(a, b)| self.coarse_rows_read(a, b));
        self.due = Due {
            base,
            four,
            up,
            out,
        };
        if !all_in {
            return done;
        }
        self.run_due_rows();
        self.run_due_up();
        out
    }

    /// The planned base rows and 4x share, as a loop of their own (where no
    /// books' loop took them), and the horizontal-pass rows no base row
    /// reads any more go.
    pub(super) fn run_due_rows(&mut self) {
        if let (_, Some(work)) = self.books_work(None, (0, 0)) {
            work(&crate::trace::region("base rows, upsample"));
        }
        let keep = self.base_rows.end().saturating_sub(self.halo.base_reach);
        self.hpass.evict_below(keep * self.grid.s);
    }

    /// The planned share of final rows, as a loop of its own (where
    /// classification's first loop did not take it).
    pub(super) fn run_due_up(&mut self) {
        if let Some(up) = self.due.up.take() {
            let ep = self.ep.as_ref().expect("a coarse share only with ep-gauss");
            let mut accs = Accs::new(
                ep,
                (&mut self.acc, &mut self.c2, &mut self.c4),
                self.w,
                self.nch,
                self.tile,
            );
            accs.upsample(up, &crate::trace::region("upsample"));
        }
    }

    /// The books' loop's company: the box luminance of new rows (pixel rows
    /// `a..b` of `input`, and the summed-area table's row sums), the planned
    /// base rows and 4x share; and the final rows `finish` for the books,
    /// read beside them.
    /// (Long: every window borrowed one by one for the three jobs, and the
    /// box luminance's task.)
    pub(super) fn books_work<'s>(
        &'s mut self,
        new_rows: Option<((usize, usize), &'s RowWindow<f32>)>,
        finish: (usize, usize),
    ) -> (Output<'s>, Option<Box<Early<'s>>>) {
        let (base, four) = (self.due.base.take(), self.due.four.take());
        if new_rows.is_none() && base.is_none() && four.is_none() {
            return (self.output(finish), None);
        }
        let (s, w, pad, in_w, inv) = (self.grid.s, self.w, self.pad, self.grid.in_w, self.inv_s2);
        let ncw = w.div_ceil(2);
        if let Some(((a, b), _)) = new_rows {
            for _ in a..b {
                self.ybox.push_stale(0.0); // every value is written below
            }
            if let Some((csum, _)) = &mut self.csum {
                for _ in a..b {
                    csum.push_stale(0.0); // every value is written below
                }
            }
        }
        if let Some((a, b)) = base {
            for _ in a..b {
                self.base_rows.push_stale(0.0); // every value is written below
            }
        }
        let GaussianStage {
            ref mut ybox,
            ref mut csum,
            ref lum,
            ref emission,
            ref real_counts,
            ref mut base_rows,
            ref hpass,
            base: ref kernel,
            ref modes,
            ref mut c2,
            ref c4,
            ref acc,
            ref ep,
            h,
            nch,
            grid,
            ..
        } = *self;
        // The box luminance's rows, and the summed-area table's.
        let luminance = new_rows.map(|((a, b), input)| {
            let csum_rows: Vec<Option<&mut [f64]>> = match csum {
                Some((csum, _)) => csum.range_mut(a, b).into_iter().map(Some).collect(),
                None => (a..b).map(|_| None).collect(),
            };
            (a, input, ybox.range_mut(a, b), csum_rows)
        });
        let real_counts = real_counts.as_ref();
        // The base rows to make, and the rows to finish beside them.
        let (finish_base, mut jobs) = match base {
            Some((a, b)) => {
                // No rows to finish: none read, from the first made.
                let (f0, f1) = if finish.1 > finish.0 { finish } else { (a, a) };
                let mut rows = base_rows.range_mut(f0, b);
                let made = rows.split_off(a - f0);
                let read: Vec<&[f64]> = rows.into_iter().take(f1 - f0).map(|r| &*r).collect();
                let jobs: Vec<RowJob<'_>> = made
                    .into_iter()
                    .zip(a..)
                    .map(|(row, y)| RowJob::Base(y, row))
                    .collect();
                (read, jobs)
            }
            None => (
                (finish.0..finish.1).map(|y| base_rows.get(y)).collect(),
                Vec::new(),
            ),
        };
        if let Some((f, l)) = four {
            jobs.extend(share_jobs(c2.acc.range_mut(f, l), f, c4, ncw));
        }
        let out = Output {
            a: finish.0,
            base: finish_base,
            acc: ep
                .as_ref()
                .map(|_| (finish.0..finish.1).map(|y| acc.get(y)).collect()),
        };
        let ctx = BaseCtx {
            base: kernel,
            hpass,
            modes,
            w,
            h,
            nch,
            s,
            in_h: grid.in_h,
            inv,
        };
        let work = move |region: &Span| {
            let luminance = move || {
                let Some((a, input, mut rows, mut csum_rows)) = luminance else {
                    return;
                };
                rows.par_iter_mut()
                    .zip(csum_rows.par_iter_mut())
                    .enumerate()
                    .for_each_init(Vec::<f64>::new, |core, (k, (row, csum_row))| {
                        let _task = region.task("box luminance");
                        let y = a + k;
                        // The mean in f64, stored in f32 (`LumRows`).
                        core.clear();
                        core.resize(w, 0.0);
                        for j in y * s..(y + 1) * s {
                            lum.box_row_add(input.get(j), in_w, s, core);
                            // The emission guide's light is not tested.
                            if let Some(em) = emission {
                                let row = input.get(j);
                                for (px, v) in core.iter_mut().enumerate() {
                                    for i in px * s..(px + 1) * s {
                                        *v -= em.luminance(row, in_w, i);
                                    }
                                }
                            }
                        }
                        core.iter_mut().for_each(|v| *v *= inv);
                        // --edge pad: a partial pixel's mean is over its real samples.
                        if let Some((nx, ny)) = real_counts {
                            for (v, &n) in core.iter_mut().zip(nx) {
                                let real = n * ny[y];
                                if real != s * s {
                                    *v *= (s * s) as f64 / real as f64;
                                }
                            }
                        }
                        for (o, &v) in row[pad..pad + w].iter_mut().zip(core.iter()) {
                            *o = v as f32;
                        }
                        for i in 0..pad {
                            row[i] = row[pad + mirror(i as i64 - pad as i64, w)];
                            row[pad + w + i] = row[pad + mirror((w + i) as i64, w)];
                        }
                        if let Some(c) = csum_row {
                            csum_prefix(row, c);
                        }
                    });
            };
            rayon::join(luminance, || run_rows(Some(&ctx), jobs, region));
        };
        (out, Some(Box::new(work)))
    }
}

/// What a base row's task reads.
pub(super) struct BaseCtx<'a> {
    base: &'a Kernel1d,
    hpass: &'a RowWindow<f64>,
    modes: &'a [ChannelMode],
    w: usize,
    h: usize,
    nch: usize,
    s: usize,
    in_h: usize,
    inv: f64,
}

/// A row task beside other work: a base row, or a row of a grid that takes
/// a coarse grid's share (the grid, the row's columns per channel).
pub(super) enum RowJob<'a> {
    Base(usize, &'a mut [f64]),
    Up(&'a CoarseGrid, usize, usize, &'a mut [f64]),
}

/// Rows `from..` of a grid (`n_fine` columns per channel), each a job taking
/// `grid`'s share.
pub(super) fn share_jobs<'a>(
    rows: Vec<&'a mut [f64]>,
    from: usize,
    grid: &'a CoarseGrid,
    n_fine: usize,
) -> impl Iterator<Item = RowJob<'a>> {
    rows.into_iter()
        .zip(from..)
        .map(move |(row, y)| RowJob::Up(grid, n_fine, y, row))
}

/// `jobs` as tasks of `region` in one parallel loop (none when there are
/// none); `ctx` is what the base rows read.
pub(super) fn run_rows(ctx: Option<&BaseCtx<'_>>, jobs: Vec<RowJob<'_>>, region: &Span) {
    if jobs.is_empty() {
        return;
    }
    jobs.into_par_iter()
        .for_each_init(
            <(Vec<f64>, [Vec<f64>; 2])>::default,
            |(taps, up), job| match job {
                RowJob::Base(y, row) => {
                    let _task = region.task("base rows");
                    base_row(
                        ctx.expect("base rows come with what they read"),
                        y,
                        row,
                        taps,
                    );
                }
                RowJob::Up(grid, n_fine, y, row) => {
                    let _task = region.task("upsample");
                    coarse::tent_row(grid, n_fine, y, row, up);
                }
            },
        );
}

/// Base row `y`: the vertical gather of the horizontal pass (`taps`: the
/// task's scratch).
fn base_row(ctx: &BaseCtx<'_>, y: usize, row: &mut [f64], taps: &mut Vec<f64>) {
    let (w, s) = (ctx.w, ctx.s);
    let j0 = ctx.base.gather(y, ctx.h, ctx.in_h, taps);
    for c in 0..ctx.nch {
        let dst = &mut row[c * w..(c + 1) * w];
        if ctx.modes[c] == ChannelMode::Nearest {
            // The centre row's centre sample (horizontal pass).
            dst.copy_from_slice(&ctx.hpass.get(y * s + (s - 1) / 2)[c * w..(c + 1) * w]);
            continue;
        }
        dst.iter_mut().for_each(|v| *v = -0.0);
        for (t, &wt) in taps.iter().enumerate() {
            let src = &ctx.hpass.get(j0 + t)[c * w..(c + 1) * w];
            for (d, &v) in dst.iter_mut().zip(src) {
                *d += wt * v;
            }
        }
        dst.iter_mut().for_each(|v| *v *= ctx.inv);
    }
}
