//! The stage of the Gaussian family (ep-gauss, gauss, box, and the clamp
//! foil): scatter as the mirror image of gather.
//!
//! Rows flow through four cursors over output (pixel) rows:
//!
//! 1. **box luminance** `Ybox` of pixel row `y` once its S input rows are in;
//! 2. **classification** of row `y` (the base noise test, which reads `Ybox`
//!    rows `y ± xbar_reach`, and the support of noisy samples, which reads
//!    the input rows just above and below): noisy samples are set aside (with
//!    their values), and every input row gets its horizontal gather pass with
//!    them taken out;
//! 3. **spreading** of the noisy samples of row `y` (the width search reads
//!    `Ybox` rows `y ± search_reach`) into tile accumulators that own output
//!    pixels, visited in input row-major order;
//! 4. **output** of row `y` once no later input row can reach it: the vertical
//!    gather of the base kernel (`y ± base_reach` input pixel rows classified)
//!    plus the accumulator (all noisy samples of rows `≤ y + spread_reach`
//!    spread).
//!
//! Which parallel loop does a cursor's work may differ (the box luminance and
//! the base rows run beside the skeleton's books, the spread beside the
//! classification: `rows.rs`, `classify.rs`), never what it computes.
//!
//! Each cursor advances only when what it reads is present, so the result does
//! not depend on how rows arrive (strip height). Every output value is built
//! by the same operations in the same order whatever the tile size or thread
//! count: the gather sums its taps in index order, the accumulator receives
//! noisy samples in input row-major order. Output is bit-identical across
//! `--tile`, `--strip-rows` and `--threads`.
//!
//! Memory: the windows hold `O(lag)` rows of the output width (`lag` from
//! [`crate::geometry::Halo`]) and `O(S * (strip + xbar_reach))` input rows,
//! whatever the image height.

mod classify;
mod coarse;
mod rows;
mod scatter;

use coarse::CoarseGrid;
use rows::Due;

use super::counts::{MethodCounts, SpreadCounts};
use super::stage::{Early, Output, Stage, WindowUse};
use super::window::RowWindow;
use super::ChannelMode;
use crate::filter::ep_box::{cluster_count, StatsLayout};
use crate::filter::ep_gauss::{
    csum_add, csum_prefix, AreaSums, Carriers, EpGauss, Folded, LumRows, Support,
};
use crate::filter::guides::EmissionParts;
use crate::filter::kernel::{ColumnTaps, Kernel1d, TentTaps};
use crate::filter::luminance::Luminance;
use crate::filter::{Method, ValidParams};
use crate::geometry::{mirror, Grid, Halo};
use crate::trace::Span;

/// The memory of a spread chunk: that of this many noisy samples whose every
/// kernel is reflected at an edge (about 8192 x 1.5 KiB of folded weights at
/// the widest kernel). A chunk of the interior, whose kernels are read in
/// place, holds far more samples in the same memory: at 12288x12288 a strip's
/// noisy samples are one chunk, two parallel loops (searching and placing,
/// scattering), where chunks of 8192 samples were 2.4 a strip, and each loop's
/// end costs a wake-up on many cores (docs/DESIGN.md, "The trace and the scaling model").
/// The chunks do not change the result (each pixel takes its contributions
/// in the batch's order).
const SPREAD_CHUNK: usize = 8192;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterParams;

    /// A one-channel stage of `p` on `grid`, tiles of 16.
    pub(super) fn stage(p: &FilterParams, grid: Grid) -> GaussianStage {
        GaussianStage::new(
            grid,
            vec![1.0],
            vec![ChannelMode::Spread],
            &p.validated().unwrap(),
            16,
            None,
        )
    }

    #[test]
    fn halo_from_params_equals_the_stages() {
        for m in [Method::EpGauss, Method::Gauss, Method::Box] {
            for (s, r, mr, cut) in [
                (3, 0.6, 16.0, 3.0),
                (4, 0.9, 5.5, 2.5),
                (2, 0.3, 0.3, 1.0),
                (1, 2.0, 40.0, 6.0),
            ] {
                if m == Method::EpGauss && s == 1 {
                    continue; // the pixel stage's (pixel.rs)
                }
                let mut p = FilterParams::new(m, s);
                (p.radius, p.max_radius, p.cutoff) = (r, mr, cut);
                let grid = Grid {
                    in_w: 30 * s,
                    in_h: 20 * s,
                    s,
                };
                let e = stage(&p, grid);
                assert_eq!(
                    e.halo(),
                    crate::filter::halo(&p),
                    "{m:?} {s} {r} {mr} {cut}"
                );
            }
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Noisy {
    i: u32,
    j: u32,
    x0: f64,
    xbar0: f64,
    level: u16,
    capped: bool,
}

/// The box luminance rows a batch of searches reads, each looked up in the
/// window once (a search fetches dozens of rows; the window's lookup is two
/// ring-buffer indexings deep).
struct YView<'a> {
    rows: Vec<&'a [f32]>,
    first: usize,
    h: usize,
    /// The summed-area table's rows (from `csum_first`) and block, where the
    /// search reads them.
    csums: Vec<&'a [f64]>,
    csum_first: usize,
    block: usize,
}

impl<'a> YView<'a> {
    fn new(win: &'a RowWindow<f32>, h: usize) -> Self {
        YView {
            rows: (win.first()..win.end()).map(|y| win.get(y)).collect(),
            first: win.first(),
            h,
            csums: Vec::new(),
            csum_first: 0,
            block: 1,
        }
    }

    /// With the summed-area table `csum` (blocks of `block` rows).
    fn with_csums(mut self, csum: &'a RowWindow<f64>, block: usize) -> Self {
        self.csums = (csum.first()..csum.end()).map(|y| csum.get(y)).collect();
        self.csum_first = csum.first();
        self.block = block;
        self
    }
}

impl LumRows for YView<'_> {
    #[inline]
    fn row(&self, vy: i64) -> &[f32] {
        self.rows[mirror(vy, self.h) - self.first]
    }
}

impl AreaSums for YView<'_> {
    #[inline]
    fn csum(&self, y: usize) -> Option<&[f64]> {
        y.checked_sub(self.csum_first)
            .and_then(|k| self.csums.get(k).copied())
    }
    fn height(&self) -> usize {
        self.h
    }
    fn block(&self) -> usize {
        self.block
    }
}

/// The Gaussian family's state between strips.
pub struct GaussianStage {
    grid: Grid,
    w: usize,
    h: usize,
    nch: usize,
    inv_s2: f64,
    lum: Luminance,
    modes: Vec<ChannelMode>,
    base: Kernel1d,
    cols: ColumnTaps,
    ep: Option<EpGauss>,
    halo: Halo,
    pad: usize,
    tile: usize,
    ybox: RowWindow<f32>,
    /// The summed-area table of `ybox` (`--bound-from`), one row more above, and
    /// their block; `None` where no width is bounded.
    csum: Option<(RowWindow<f64>, usize)>,
    /// Rows of the summed-area table added down (the box luminance rows
    /// may come first, beside the books' loop).
    csums_done: usize,
    hpass: RowWindow<f64>,
    base_rows: RowWindow<f64>,
    acc: RowWindow<f64>,
    pending: Vec<Noisy>,
    /// The pending samples' values, `nch` each, in the same order (what
    /// the emission guide leaves of them).
    pending_v: Vec<f64>,
    /// The emission guide: its light is set aside before any test and
    /// keeps the base kernel.
    emission: Option<EmissionParts>,
    /// Samples of `pending` before this one are spread (dropped from the
    /// front once they are half of it, so that dropping them moves no more
    /// than was spread: a drain per strip moved every later one).
    pending_first: usize,
    classified: usize,
    spread_done: usize,
    counts: SpreadCounts,
    clamp: Option<f32>,
    support: Support,
    /// ep-gauss at S = 1 on a file with per-pixel statistics: where they
    /// are in the input rows, and the carriers rule that reads them.
    pixel_stats: Option<(StatsLayout, Carriers)>,
    /// `--edge pad`: real samples per output column and row (S where the
    /// pixel is whole), so that `Ybox` is the mean of what exists.
    real_counts: Option<(Vec<usize>, Vec<usize>)>,
    /// The 2x coarse grid (`--coarse-from`), whose rows are upsampled into
    /// the accumulator's, and the output rows it has been added to.
    c2: CoarseGrid,
    up_done: usize,
    /// What the last advance planned for the next push's loops, and the
    /// end of the base rows planned.
    due: Due,
    base_planned: usize,
    /// The 4x grid, whose rows are upsampled into the 2x grid's: its share
    /// enters a 2x row once, just before that row is upsampled.
    c4: CoarseGrid,
    /// Samples of an input row per classification task (0: automatic).
    classify_samples: usize,
    /// Noisy samples at an edge per spread chunk (0: [`SPREAD_CHUNK`]).
    spread_chunk: usize,
}

impl GaussianStage {
    /// Build the stage: kernels, taps and halo are settled here, once. The
    /// skeleton has checked the grid, the channels and the tile.
    /// `stats` (ep-gauss at S = 1 only; indices into the input rows'
    /// channels) turns on the carriers rule.
    pub fn new(
        grid: Grid,
        lum: Vec<f64>,
        modes: Vec<ChannelMode>,
        params: &ValidParams,
        tile: usize,
        stats: Option<StatsLayout>,
    ) -> Self {
        let nch = lum.len();
        assert_eq!(modes.len(), nch, "a mode per channel");
        let s = grid.s;
        let (w, h) = (grid.out_w(), grid.out_h());
        let base = match params.method {
            Method::Box => Kernel1d::boxed(s),
            _ => Kernel1d::gaussian(s, params.radius, params.cutoff),
        };
        let ep = (params.method == Method::EpGauss)
            .then(|| {
                EpGauss::new(
                    s,
                    params.radius,
                    params.max_radius,
                    params.cutoff,
                    params.tolerance,
                    params.width_step,
                )
                .with_coarse(params.coarse_from)
                .with_bound(params.bound_from)
            })
            // Beyond the paper, with its feature rules (`support > 0`): only
            // samples brighter than their neighbourhood are noise. Relation 14's
            // dark side wakes below `tolerance = w0` (0.088 at S = 3), where
            // every sample beside a firefly is "too dark" for the firefly-raised
            // average; spreading a dark sample moves at most `w0 x0`, and on the
            // real renders no figure moved in four digits (docs/DESIGN.md).
            .map(|e| {
                if params.support > 0 {
                    e.bright_only()
                } else {
                    e
                }
            });
        let coarse = ep
            .as_ref()
            .is_some_and(|e| e.levels().iter().any(|l| l.coarse.is_some()));
        let coarse4 = ep.as_ref().is_some_and(|e| {
            e.levels()
                .iter()
                .any(|l| l.coarse.as_ref().is_some_and(|c| c.factor == 4))
        });
        let halo = Halo {
            xbar_reach: ep.as_ref().map_or(0, |e| e.xbar_reach()),
            base_reach: base.reach(),
            search_reach: ep.as_ref().map_or(0, |e| e.search_reach()),
            spread_reach: ep.as_ref().map_or(0, |e| e.spread_reach()),
        };
        let pad = ep.as_ref().map_or(0, |e| e.pad());
        let csum = ep
            .as_ref()
            .filter(|e| e.uses_bound())
            .map(|e| (RowWindow::new(w + 2 * pad + 2), e.csum_block()));
        let cols = ColumnTaps::new(&base, w, grid.in_w);
        GaussianStage {
            grid,
            w,
            h,
            nch,
            inv_s2: 1.0 / (s * s) as f64,
            lum: Luminance::new(&lum),
            modes,
            base,
            cols,
            ep,
            halo,
            pad,
            tile,
            ybox: RowWindow::new(w + 2 * pad),
            csum,
            csums_done: 0,
            hpass: RowWindow::new(nch * w),
            base_rows: RowWindow::new(nch * w),
            acc: RowWindow::new(nch * w),
            pending: Vec::new(),
            pending_v: Vec::new(),
            emission: None,
            pending_first: 0,
            classified: 0,
            spread_done: 0,
            counts: SpreadCounts::default(),
            clamp: (params.method == Method::Clamp).then_some(params.clamp as f32),
            support: Support::new(params.support, params.support_ratio, params.support_compact)
                .with_over(params.support_over)
                .with_region(params.support_region, params.support_level)
                .with_group(params.support_group),
            pixel_stats: stats
                .filter(|_| params.method == Method::EpGauss && s == 1 && params.support > 0)
                .map(|st| (st, Carriers::new(&params.ep_box))),
            real_counts: None,
            c2: CoarseGrid::new(nch, (w, h), 2, coarse),
            up_done: 0,
            due: Due::default(),
            base_planned: 0,
            c4: CoarseGrid::new(nch, (w.div_ceil(2), h.div_ceil(2)), 2, coarse4),
            classify_samples: 0,
            spread_chunk: 0,
        }
    }

    /// Samples of an input row per classification task
    /// ([`super::PipelineConfig::classify_samples`]; 0: automatic).
    pub fn set_classify_samples(&mut self, n: usize) {
        self.classify_samples = n;
    }

    /// Noisy samples whose kernels may reach an edge per spread chunk
    /// ([`super::PipelineConfig::spread_chunk`]; 0: automatic).
    pub fn set_spread_chunk(&mut self, n: usize) {
        self.spread_chunk = n;
    }

    /// The emission guide (ep-gauss): each sample's emission part is set
    /// aside before any test, keeps the base kernel, and only the rest of a
    /// noisy sample is spread ([`crate::filter::guides`]).
    pub fn set_emission(&mut self, parts: EmissionParts) {
        if self.ep.is_some() {
            self.emission = Some(parts);
        }
    }

    /// `--edge pad`: the grid's first `real.0` x `real.1` samples are real,
    /// the rest zeros.
    pub fn set_real_size(&mut self, real: (usize, usize)) {
        let s = self.grid.s;
        let counts = |n: usize, n_real: usize| -> Vec<usize> {
            (0..n)
                .map(|p| n_real.saturating_sub(p * s).min(s))
                .collect()
        };
        self.real_counts = Some((counts(self.w, real.0), counts(self.h, real.1)));
    }
}

impl Stage for GaussianStage {
    fn halo(&self) -> Halo {
        self.halo
    }

    fn arrive(&mut self, input: &mut RowWindow<f32>, a: usize, b: usize) {
        let Some(limit) = self.clamp else { return };
        // The clamp foil: colour samples above the limit are cut (after the
        // ledger took the input, so the loss shows).
        let in_w = self.grid.in_w;
        for row in input.range_mut(a, b) {
            for (c, ch) in row.chunks_mut(in_w).enumerate() {
                if self.lum.weights()[c] != 0.0 {
                    crate::filter::foils::clamp_samples(ch, limit);
                }
            }
        }
    }

    fn advance(&mut self, input: &RowWindow<f32>, rows_in: usize, _all_in: bool) -> usize {
        self.run(input, rows_in)
    }

    fn input_needed(&self) -> usize {
        // Classification of the next row reads the input rows just above it
        // (the support rule's reach).
        (self.classified * self.grid.s).saturating_sub(self.support.reach())
    }

    fn output(&self, rows: (usize, usize)) -> Output<'_> {
        Output::of(&self.base_rows, self.ep.as_ref().map(|_| &self.acc), rows)
    }

    fn beside_books<'s>(
        &'s mut self,
        input: &'s RowWindow<f32>,
        (_, b): (usize, usize),
        finish: (usize, usize),
    ) -> (Output<'s>, Option<Box<Early<'s>>>) {
        // The box luminance of the pixel rows the new input rows complete,
        // and what the last advance planned.
        let (from, ready) = (self.ybox.end(), b / self.grid.s);
        let ybox = (self.ep.is_some() && ready > from).then_some((from, ready));
        self.books_work(ybox.map(|r| (r, input)), finish)
    }

    fn release(&mut self, y: usize) {
        self.base_rows.evict_below(y);
        self.acc.evict_below(y);
        // Coarse row C reaches fine rows 2C - 1 ..= 2C + 2.
        let c = y.saturating_sub(2) / 2;
        self.c2.acc.evict_below(c);
        // And 4x row K reaches 2x rows 2K - 1 ..= 2K + 2.
        let k = c.saturating_sub(2) / 2;
        self.c4.acc.evict_below(k);
    }

    fn counts(&self) -> MethodCounts {
        match self.ep {
            Some(_) => MethodCounts::EpGauss(self.counts),
            None => MethodCounts::Plain,
        }
    }

    fn windows(&self) -> Vec<WindowUse> {
        let (nch, w) = (self.nch, self.w);
        vec![
            WindowUse {
                name: "box luminance",
                rows: self.ybox.high_water(),
                row_bytes: (w + 2 * self.pad) * 8,
            },
            WindowUse {
                name: "summed-area table",
                rows: self.csum.as_ref().map_or(0, |c| c.0.high_water()),
                row_bytes: (w + 2 * self.pad + 2) * 8,
            },
            WindowUse {
                name: "horizontal pass",
                rows: self.hpass.high_water(),
                row_bytes: nch * w * 8,
            },
            WindowUse {
                name: "base rows",
                rows: self.base_rows.high_water(),
                row_bytes: nch * w * 8,
            },
            WindowUse {
                name: "accumulator",
                rows: self.acc.high_water(),
                row_bytes: nch * w * 8,
            },
            WindowUse {
                name: "coarse accumulator",
                rows: self.c2.acc.high_water(),
                row_bytes: nch * w.div_ceil(2) * 8,
            },
            WindowUse {
                name: "4x accumulator",
                rows: self.c4.acc.high_water(),
                row_bytes: nch * w.div_ceil(4) * 8,
            },
        ]
    }
}

impl GaussianStage {
    /// Advance every cursor as far as `rows_in` input rows allow; returns
    /// the end of the final output rows.
    fn run(&mut self, input: &RowWindow<f32>, rows_in: usize) -> usize {
        // What the last advance planned and no books' loop took.
        self.run_due_rows();
        let s = self.grid.s;
        // 1. box luminance
        // (only ep-gauss reads it: the others go by the rows that are in)
        let ready = rows_in / s;
        let yb = if self.ep.is_some() {
            if ready > self.ybox.end() {
                // Not computed beside the books' loop.
                let ybox = Some(((self.ybox.end(), ready), input));
                if let (_, Some(work)) = self.books_work(ybox, (0, 0)) {
                    work(&crate::trace::region("box luminance"));
                }
            }
            let (done, end) = (self.csums_done, self.ybox.end());
            if end > done {
                self.make_csums(done, end);
                self.csums_done = end;
            }
            end
        } else {
            ready
        };
        let all_in = yb == self.h;
        // 2. classification + horizontal pass
        // A row's classification reads the input row just below it (the
        // support of samples on its last row): one pixel row more than
        // `xbar_reach` when that is 0.
        let cls_target = if all_in {
            self.h
        } else {
            yb.saturating_sub(self.halo.xbar_reach.max(1))
        };
        // 3. spreading
        let classified = self.classified.max(cls_target);
        let sp_target = if all_in {
            classified
        } else {
            classified.min(yb.saturating_sub(self.halo.search_reach))
        };
        let spreads = self.ep.is_some() && sp_target > self.spread_done;
        if cls_target > self.classified && spreads && sp_target <= self.classified {
            // Every sample to spread was classified before: its first chunk
            // is spread in classification's loops (two joins fewer a strip:
            // docs/DESIGN.md, "The trace and the scaling model"), the rest after.
            if let Some(mut batch) = self.spread_begin(sp_target) {
                // The coarse share the last advance planned, in the same
                // loop.
                let up = self.due.up.take();
                self.classify_spreading(input, (self.classified, cls_target), &mut batch, up);
                if batch.next < batch.split {
                    self.spread_chunks(&mut batch);
                }
                self.spread_end(batch);
            }
        } else {
            self.run_due_up();
            if cls_target > self.classified {
                self.classify(input, self.classified, cls_target);
            }
            if spreads {
                self.spread(sp_target);
            }
        }
        self.classified = classified;
        if spreads {
            self.spread_done = sp_target;
        }
        // 4. base rows: the vertical gather, once its input rows are
        // classified (made in the next push's first loop, rows.rs); the
        // short-lived horizontal-pass rows go then, the (S times fewer) base
        // rows wait for the spreading.
        let h = self.h;
        let base_target = if self.classified == h {
            h
        } else {
            self.classified.saturating_sub(self.halo.base_reach)
        };
        // 5. output: base plus spread noise, once no later row can reach it.
        let by_spread = match &self.ep {
            Some(_) if self.spread_done < h => {
                self.spread_done.saturating_sub(self.halo.spread_reach)
            }
            _ => h,
        };
        // Planned for the next push's loops (rows.rs); done now at the end.
        let done = self.plan_rows(base_target, by_spread, all_in);
        let keep = if self.ep.is_some() {
            self.classified
                .saturating_sub(self.halo.xbar_reach)
                .min(self.spread_done.saturating_sub(self.halo.search_reach))
        } else {
            yb
        };
        self.ybox.evict_below(keep.min(yb));
        if let Some((c, _)) = &mut self.csum {
            // The bound reads the row above its topmost.
            c.evict_below(keep.min(yb).saturating_sub(1));
        }
        done
    }

    /// The summed-area table's rows for the box luminance rows `a..b`
    /// (`--bound-from`): each row's running sum ([`Self::ybox_work`], in
    /// its row's task), plus here the row above's where the row is not the
    /// first of its block, on the image's grid of blocks, so the table does
    /// not depend on the strips. The same operations in the same order as
    /// [`csum_row`]. On the calling thread: a strip's additions cost less
    /// than a parallel loop's end on many cores.
    fn make_csums(&mut self, a: usize, b: usize) {
        let Some((csum, block)) = &mut self.csum else {
            return;
        };
        let block = *block;
        // Rows a - 1 (when held and in a's block) ..b, each added to the
        // one above.
        let first = if a % block != 0 { a - 1 } else { a };
        let mut rows = csum.range_mut(first, b);
        for (k, y) in (first..b).enumerate().skip(1) {
            if y % block != 0 {
                let (above, below) = rows.split_at_mut(k);
                csum_add(above[k - 1], below[0]);
            }
        }
    }
}
