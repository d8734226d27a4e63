//! The stage of the Gaussian family (ep-gauss, gauss, box, and the clamp
//! foil): scatter as the mirror image of gather.
//!
//! Its passes over output (pixel) rows, each declared with what it reads
//! (`passes`) and scheduled as the pixel stage's are
//! ([`crate::pipeline::schedule`]: a pass makes a row once what it reads
//! is made):
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
//! The first two are a strip's first passes (`Front`), the others its
//! later ones (`Back`); with two strips in flight a strip's first passes
//! run beside the previous strip's later ones, which go as far as the rows
//! made before it allow (`GaussianStage::run`). No pass is held back to
//! what its readers need (the pixel stage's rule): here that would hold the
//! horizontal pass, S input rows a pixel row, for the spread's reach. When
//! a pass runs may differ, never what it computes.
//!
//! Each pass advances only when what it reads is present, so the result does
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

use std::collections::VecDeque;

use coarse::CoarseGrid;

use super::counts::{MethodCounts, SpreadCounts};
use super::schedule::{forward, read_from, Reads};
use super::stage::{Output, Stage, WindowUse};
use super::window::{RowWindow, Rows};
use super::ChannelMode;
use crate::filter::ep_gauss::{csum_add, csum_prefix, AreaSums, EpGauss, Folded, LumRows, Support};
use crate::filter::guides::EmissionParts;
use crate::filter::kernel::{ColumnTaps, Kernel1d, TentTaps};
use crate::filter::luminance::Luminance;
use crate::filter::{Method, ValidParams};
use crate::geometry::{mirror, Grid, Halo};

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
mod tests;

/// The passes, over pixel rows (pass 0: the pixel rows whose S input rows
/// are in): the box luminance;
const YBOX: usize = 1;
/// the classification, which lists a row's noisy samples;
const NOISY: usize = 2;
/// the horizontal pass of its input rows, noisy samples taken out, made
/// with the classification in one loop but declared apart: its rows go
/// once the base rows have read them, while the spread reads the list;
const HPASS: usize = 3;
/// the spread of the listed samples;
const SPREAD: usize = 4;
/// the base rows (the vertical gather of the horizontal pass);
const BASE: usize = 5;
/// the final rows, base plus every spread that reaches them.
const FINAL: usize = 6;

/// What each pass reads ([`crate::pipeline::schedule`]), its reaches the
/// halo's: the classification reads the input row below its own (the
/// support of samples on its last row) and, for ep-gauss, the box
/// luminance of its base test.
fn passes(halo: &Halo, ep: bool) -> Vec<Reads> {
    let classify = match ep {
        true => vec![(0, 1), (YBOX, halo.xbar_reach)],
        false => vec![(0, 1)],
    };
    vec![
        vec![(0, 0)],
        classify,
        vec![(NOISY, 0)],
        vec![(YBOX, halo.search_reach), (NOISY, 0)],
        vec![(HPASS, halo.base_reach)],
        vec![(SPREAD, halo.spread_reach), (BASE, 0)],
    ]
}

/// A noisy sample waiting for its spread: its input position, its
/// luminance and its pixel's average (what the width search reads). The
/// search's answer is used at once and not kept: the list is held over the
/// width search's reach of rows.
#[derive(Clone, Copy, Debug)]
struct Noisy {
    i: u32,
    j: u32,
    x0: f64,
    xbar0: f64,
}

/// The box luminance rows a batch of searches reads (a search fetches
/// dozens of rows: each is a slice at hand, not a lookup in the window).
#[derive(Clone)]
struct YView<'a> {
    rows: Rows<'a, f32>,
    h: usize,
    /// The summed-area table's rows and block, where the search reads them.
    csums: Option<Rows<'a, f64>>,
    block: usize,
}

impl<'a> YView<'a> {
    fn new(rows: Rows<'a, f32>, h: usize) -> Self {
        YView {
            rows,
            h,
            csums: None,
            block: 1,
        }
    }

    /// With the summed-area table `csum` (blocks of `block` rows).
    fn with_csums(mut self, csum: Rows<'a, f64>, block: usize) -> Self {
        self.csums = Some(csum);
        self.block = block;
        self
    }
}

impl LumRows for YView<'_> {
    #[inline]
    fn row(&self, vy: i64) -> &[f32] {
        self.rows.get(mirror(vy, self.h))
    }
}

impl AreaSums for YView<'_> {
    #[inline]
    fn csum(&self, y: usize) -> Option<&[f64]> {
        self.csums.as_ref().and_then(|c| c.try_get(y))
    }
    fn height(&self) -> usize {
        self.h
    }
    fn block(&self) -> usize {
        self.block
    }
}

/// The grid's sizes, read by every pass.
#[derive(Clone, Copy, Debug)]
struct Shape {
    grid: Grid,
    /// Output pixels across and down.
    w: usize,
    h: usize,
    nch: usize,
    inv_s2: f64,
    /// Mirrored pixels each side of a box luminance row (the search's
    /// reach across).
    pad: usize,
    tile: usize,
    halo: Halo,
}

/// The kernels and the tests, set once.
struct Rules {
    lum: Luminance,
    modes: Vec<ChannelMode>,
    base: Kernel1d,
    cols: ColumnTaps,
    ep: Option<EpGauss>,
    /// The clamp foil's limit.
    clamp: Option<f32>,
    support: Support,
    /// `--edge pad`: real samples per output column and row (S where the
    /// pixel is whole), so that `Ybox` is the mean of what exists.
    real_counts: Option<(Vec<usize>, Vec<usize>)>,
    /// The emission guide: its light is set aside before any test and
    /// keeps the base kernel.
    emission: Option<EmissionParts>,
}

/// What the first passes of a strip make (the box luminance, the
/// classification with its horizontal pass) and hold for the later ones,
/// each window indexed by its own rows.
struct Front {
    /// The box luminance of pixel rows, `pad` mirrored pixels each side.
    ybox: RowWindow<f32>,
    /// The summed-area table of `ybox` (`--bound-from`), one row more above,
    /// and its block; `None` where no width is bounded.
    csum: Option<(RowWindow<f64>, usize)>,
    /// The horizontal pass of the base kernel over input rows, noisy
    /// samples taken out.
    hpass: RowWindow<f64>,
    /// Samples of an input row per classification task (0: automatic).
    classify_samples: usize,
}

/// What the later passes of a strip make (the spread, the base rows, the
/// final rows) and hold: the output rows and the noisy samples waiting.
struct Back {
    /// The vertical gather of the horizontal pass: output rows without the
    /// noise.
    base_rows: RowWindow<f64>,
    /// The spread noise, on the output grid and the 2x and 4x coarse ones.
    acc: RowWindow<f64>,
    c2: CoarseGrid,
    c4: CoarseGrid,
    pending: Pending,
    counts: SpreadCounts,
    /// Noisy samples at an edge per spread chunk (0: [`SPREAD_CHUNK`]).
    spread_chunk: usize,
}

/// The first passes' rows as the later passes read them, and the rows
/// each had made when they started (passes 0 to [`HPASS`]).
struct Made<'a> {
    ybox: Rows<'a, f32>,
    csum: Option<(Rows<'a, f64>, usize)>,
    hpass: Rows<'a, f64>,
    done: Vec<usize>,
}

impl<'a> Made<'a> {
    /// The box luminance (and its summed-area table) as the width search
    /// reads it, `h` rows high.
    fn view(&self, h: usize) -> YView<'a> {
        let view = YView::new(self.ybox.clone(), h);
        match &self.csum {
            Some((c, block)) => view.with_csums(c.clone(), *block),
            None => view,
        }
    }
}

/// Bytes a pending noisy sample holds besides its values (the memory
/// estimate counts them).
pub const PENDING_SAMPLE_BYTES: usize = std::mem::size_of::<Noisy>();

/// Noisy samples classified and not yet spread, in input row-major order:
/// classification pushes at the back, the spread takes from the front.
#[derive(Default)]
struct Pending {
    samples: VecDeque<Noisy>,
    /// Their values, `nch` each, in the same order (what the emission
    /// guide leaves of them).
    values: VecDeque<f64>,
}

impl Pending {
    /// Append one classification task's samples and values. The lists grow
    /// by an eighth beyond what they hold, not by doubling: they are held
    /// for the whole run, and their length is set by the noise of the rows
    /// between the two cursors.
    fn push(&mut self, samples: Vec<Noisy>, values: Vec<f64>) {
        grow_by_eighth(&mut self.samples, samples.len());
        grow_by_eighth(&mut self.values, values.len());
        self.samples.extend(samples);
        self.values.extend(values);
    }
}

/// Room in `q` for `more` items, reserved an eighth beyond the length when
/// it has to grow (amortised constant time, at most an eighth idle).
fn grow_by_eighth<T>(q: &mut VecDeque<T>, more: usize) {
    let need = q.len() + more;
    if need > q.capacity() {
        q.reserve_exact(need + need / 8 - q.len());
    }
}

/// The Gaussian family's state between strips: the shape and rules (set
/// once), what the first passes hold and what the later ones hold.
pub struct GaussianStage {
    shape: Shape,
    rules: Rules,
    /// What each pass reads, and the rows each has made.
    passes: Vec<Reads>,
    done: Vec<usize>,
    front: Front,
    back: Back,
    /// Strips worked on at once: with 2, a strip's first passes run beside
    /// the previous strip's later ones ([`GaussianStage::run`]).
    in_flight: usize,
}

impl GaussianStage {
    /// Build the stage: kernels, taps and halo are settled here, once. The
    /// skeleton has checked the grid, the channels and the tile.
    pub fn new(
        grid: Grid,
        lum: Vec<f64>,
        modes: Vec<ChannelMode>,
        params: &ValidParams,
        tile: usize,
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
            .then(|| crate::filter::ladder(params, s).with_bound(params.bound_from))
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
        let coarse_factor = |f: Option<usize>| {
            ep.as_ref().is_some_and(|e| {
                e.levels().iter().any(|l| {
                    l.coarse
                        .as_ref()
                        .is_some_and(|c| f.is_none_or(|f| c.factor == f))
                })
            })
        };
        let (coarse, coarse4) = (coarse_factor(None), coarse_factor(Some(4)));
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
        let passes = passes(&halo, ep.is_some());
        GaussianStage {
            done: vec![0; passes.len() + 1],
            passes,
            shape: Shape {
                grid,
                w,
                h,
                nch,
                inv_s2: 1.0 / (s * s) as f64,
                pad,
                tile,
                halo,
            },
            rules: Rules {
                lum: Luminance::new(&lum),
                modes,
                base,
                cols,
                clamp: (params.method == Method::Clamp).then_some(params.clamp as f32),
                support: Support::new(params.support, params.support_ratio, params.support_compact)
                    .with_over(params.support_over)
                    .with_region(params.support_region, params.support_level)
                    .with_group(params.support_group),
                ep,
                real_counts: None,
                emission: None,
            },
            front: Front {
                ybox: RowWindow::new(w + 2 * pad),
                csum,
                hpass: RowWindow::new(nch * w),
                classify_samples: 0,
            },
            back: Back {
                base_rows: RowWindow::new(nch * w),
                acc: RowWindow::new(nch * w),
                c2: CoarseGrid::new(nch, (w, h), 2, coarse),
                c4: CoarseGrid::new(nch, (w.div_ceil(2), h.div_ceil(2)), 2, coarse4),
                pending: Pending::default(),
                counts: SpreadCounts::default(),
                spread_chunk: 0,
            },
            in_flight: 1,
        }
    }

    /// Samples of an input row per classification task
    /// ([`super::PipelineConfig::classify_samples`]; 0: automatic).
    pub fn set_classify_samples(&mut self, n: usize) {
        self.front.classify_samples = n;
    }

    /// Strips worked on at once, 1 or 2
    /// ([`super::PipelineConfig::strips_in_flight`]).
    pub fn set_strips_in_flight(&mut self, n: usize) {
        self.in_flight = n.clamp(1, 2);
    }

    /// Noisy samples whose kernels may reach an edge per spread chunk
    /// ([`super::PipelineConfig::spread_chunk`]; 0: automatic).
    pub fn set_spread_chunk(&mut self, n: usize) {
        self.back.spread_chunk = n;
    }

    /// The emission guide (ep-gauss): each sample's emission part is set
    /// aside before any test, keeps the base kernel, and only the rest of a
    /// noisy sample is spread ([`crate::filter::guides`]).
    pub fn set_emission(&mut self, parts: EmissionParts) {
        if self.rules.ep.is_some() {
            self.rules.emission = Some(parts);
        }
    }

    /// `--edge pad`: the grid's first `real.0` x `real.1` samples are real,
    /// the rest zeros.
    pub fn set_real_size(&mut self, real: (usize, usize)) {
        let Shape { grid, w, h, .. } = self.shape;
        let counts = |n: usize, n_real: usize| -> Vec<usize> {
            (0..n)
                .map(|p| n_real.saturating_sub(p * grid.s).min(grid.s))
                .collect()
        };
        self.rules.real_counts = Some((counts(w, real.0), counts(h, real.1)));
    }
}

impl Stage for GaussianStage {
    fn halo(&self) -> Halo {
        self.shape.halo
    }

    fn arrive(&mut self, input: &mut RowWindow<f32>, a: usize, b: usize) {
        let Some(limit) = self.rules.clamp else {
            return;
        };
        // The clamp foil: colour samples above the limit are cut (after the
        // ledger took the input, so the loss shows).
        let in_w = self.shape.grid.in_w;
        for row in input.range_mut(a, b) {
            for (c, ch) in row.chunks_mut(in_w).enumerate() {
                if self.rules.lum.weights()[c] != 0.0 {
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
        // (the support rule's reach, in input rows: finer than the passes').
        (self.done[NOISY] * self.shape.grid.s).saturating_sub(self.rules.support.reach())
    }

    fn output(&self, rows: (usize, usize)) -> Output<'_> {
        let acc = self.rules.ep.as_ref().map(|_| &self.back.acc);
        Output::of(&self.back.base_rows, acc, rows)
    }

    fn release(&mut self, y: usize) {
        let win = &mut self.back;
        win.base_rows.evict_below(y);
        win.acc.evict_below(y);
        // Coarse row C reaches fine rows 2C - 1 ..= 2C + 2.
        let c = y.saturating_sub(2) / 2;
        win.c2.acc.evict_below(c);
        // And 4x row K reaches 2x rows 2K - 1 ..= 2K + 2.
        let k = c.saturating_sub(2) / 2;
        win.c4.acc.evict_below(k);
    }

    fn counts(&self) -> MethodCounts {
        match self.rules.ep {
            Some(_) => MethodCounts::EpGauss(self.back.counts),
            None => MethodCounts::Plain,
        }
    }

    fn windows(&self) -> Vec<WindowUse> {
        let Shape { nch, w, pad, .. } = self.shape;
        let (front, win) = (&self.front, &self.back);
        let rows = |name, rows, row_bytes| WindowUse {
            name,
            rows,
            row_bytes,
        };
        vec![
            rows("box luminance", front.ybox.high_water(), (w + 2 * pad) * 4),
            rows(
                "summed-area table",
                front.csum.as_ref().map_or(0, |c| c.0.high_water()),
                (w + 2 * pad + 2) * 8,
            ),
            rows("horizontal pass", front.hpass.high_water(), nch * w * 8),
            rows("base rows", win.base_rows.high_water(), nch * w * 8),
            rows("accumulator", win.acc.high_water(), nch * w * 8),
            rows(
                "coarse accumulator",
                win.c2.acc.high_water(),
                nch * w.div_ceil(2) * 8,
            ),
            rows(
                "4x accumulator",
                win.c4.acc.high_water(),
                nch * w.div_ceil(4) * 8,
            ),
        ]
    }
}

impl GaussianStage {
    /// Advance as far as `rows_in` input rows allow; returns the end of the
    /// final output rows. A strip's work is two lists of passes, each pass
    /// a parallel loop over rows (or tiles) that reads only what the passes
    /// before it made:
    ///
    /// - the first passes ([`front_passes`]): the box luminance of the new
    ///   pixel rows, then their classification with the horizontal pass;
    /// - the later ones ([`Back::run`]): the spread of the noisy samples
    ///   whose width search has its rows, the base rows whose input rows
    ///   are classified, and the rows no later sample reaches, final.
    ///
    /// With one strip in flight the later passes follow the first. With
    /// two they run beside them (`rayon::join`), as far as the rows made
    /// before this strip allow, and this strip's follow with the next
    /// strip's first passes (or at once when it is the last): the windows
    /// hold a strip more, and each pass computes what it would have, in the
    /// same order.
    fn run(&mut self, input: &RowWindow<f32>, rows_in: usize) -> usize {
        let Shape { grid, h, .. } = self.shape;
        let ep = self.rules.ep.is_some();
        let s = grid.s;
        let ready = rows_in / s;
        let all_in = ready == h;
        let t = forward(&self.passes, h, &[ready], usize::MAX);
        let front = &mut self.front;
        let (c0, c1) = (self.done[NOISY], t[NOISY].max(self.done[NOISY]));
        // Room for the first passes' rows (only ep-gauss reads the box
        // luminance: the others go by the rows that are in).
        let y0 = front.ybox.end();
        let y1 = if ep { t[YBOX].max(y0) } else { y0 };
        for _ in y0..y1 {
            front.ybox.push_stale(0.0); // every value is written
            if let Some((c, _)) = &mut front.csum {
                c.push_stale(0.0);
            }
        }
        for _ in c0 * s..c1 * s {
            front.hpass.push_stale(0.0); // every value is written
        }
        let (ybox, ybox_new) = front.ybox.split_at(y0);
        let (csum, csum_new) = match &mut front.csum {
            Some((c, block)) => {
                let (old, new) = c.split_at(y0);
                (Some((old, *block)), new)
            }
            None => (None, Vec::new()),
        };
        let (hpass, hpass_new) = front.hpass.split_at(c0 * s);
        let made = Made {
            ybox: ybox.clone(),
            csum: csum.clone(),
            hpass,
            done: self.done[..=HPASS].to_vec(),
        };
        let rows = FrontRows {
            ybox: (ybox, y0, ybox_new),
            csum: csum.map(|(old, block)| TableRows {
                old,
                new: csum_new,
                block,
            }),
            hpass: hpass_new,
            classify: (c0, c1),
        };
        let (shape, rules, back) = (&self.shape, &self.rules, &mut self.back);
        let (passes, back_done) = (&self.passes, &mut self.done[SPREAD..]);
        let per_task = front.classify_samples;
        let found = if self.in_flight > 1 {
            let seg = crate::trace::current_segment();
            rayon::join(
                || {
                    crate::trace::in_segment(seg, || {
                        front_passes(shape, rules, input, rows, per_task)
                    })
                },
                || {
                    crate::trace::in_segment(seg, || {
                        back.run(shape, rules, &made, passes, back_done)
                    })
                },
            )
            .0
        } else {
            front_passes(shape, rules, input, rows, per_task)
        };
        for (list, vals, kept) in found {
            // Kept samples failed the test too; the spread ones are counted
            // when they are spread.
            back.counts.noisy += kept;
            back.counts.kept += kept;
            back.pending.push(list, vals);
        }
        self.done[..=HPASS].copy_from_slice(&[ready, t[YBOX], c1, c1]);
        if self.in_flight == 1 || all_in {
            let made = self.front.made(&self.done[..=HPASS]);
            let done = &mut self.done[SPREAD..];
            self.back
                .run(&self.shape, &self.rules, &made, &self.passes, done);
        }
        self.evict();
        self.done[FINAL]
    }

    /// What no later pass reads goes.
    fn evict(&mut self) {
        let (passes, done, front) = (&self.passes, &self.done, &mut self.front);
        let keep = read_from(passes, done, YBOX).min(done[0]);
        front.ybox.evict_below(keep);
        if let Some((c, _)) = &mut front.csum {
            // The bound reads the row above its topmost.
            c.evict_below(keep.saturating_sub(1));
        }
        let hpass = read_from(passes, done, HPASS);
        front.hpass.evict_below(hpass * self.shape.grid.s);
    }
}

impl Back {
    /// A strip's later passes, as far as the first passes' rows `made`
    /// allow (`passes` the stage's; `done` the rows made by these, from
    /// [`SPREAD`] on). Where targets come from rows made later, they only
    /// grow, so a pass makes exactly its target.
    fn run(
        &mut self,
        shape: &Shape,
        rules: &Rules,
        made: &Made<'_>,
        passes: &[Reads],
        done: &mut [usize],
    ) {
        let (w, h) = (shape.w, shape.h);
        let t = forward(passes, h, &made.done, usize::MAX);
        let [spread, base, out] = [SPREAD, BASE, FINAL].map(|p| t[p].max(done[p - SPREAD]));
        if rules.ep.is_some() && spread > done[0] {
            self.spread(shape, rules, &made.view(h), spread);
        }
        self.base_rows(shape, rules, &made.hpass, base);
        // Final rows, with the coarse grids' share added.
        if out > done[2] && self.c2.used {
            self.coarse_share(w, done[2], out);
        }
        done.copy_from_slice(&[spread, base, out]);
    }
}

impl Front {
    /// Every row made, as the later passes read them (`done`: the rows
    /// each first pass made).
    fn made(&self, done: &[usize]) -> Made<'_> {
        Made {
            ybox: self.ybox.rows(),
            csum: self.csum.as_ref().map(|(c, block)| (c.rows(), *block)),
            hpass: self.hpass.rows(),
            done: done.to_vec(),
        }
    }
}

/// The rows a strip's first passes write, beside the rows before them that
/// they read: the box luminance from its first new row, the summed-area
/// table's, and the horizontal pass of the pixel rows to classify.
struct FrontRows<'a> {
    ybox: (Rows<'a, f32>, usize, Vec<&'a mut [f32]>),
    csum: Option<TableRows<'a>>,
    hpass: Vec<&'a mut [f64]>,
    classify: (usize, usize),
}

/// The summed-area table's rows a strip adds (`new`), the rows before them
/// (`old`: a row adds the one above it) and its block.
struct TableRows<'a> {
    old: Rows<'a, f64>,
    new: Vec<&'a mut [f64]>,
    block: usize,
}

/// A strip's first passes: the box luminance of its new pixel rows (with the
/// summed-area table's), then the classification of the pixel rows they
/// allow (`per_task`: samples of an input row per task, 0 automatic).
/// Returns what each classified row found, in order.
fn front_passes(
    shape: &Shape,
    rules: &Rules,
    input: &RowWindow<f32>,
    rows: FrontRows<'_>,
    per_task: usize,
) -> Vec<classify::Found> {
    let (ybox, y0, ybox_new) = rows.ybox;
    let ybox_new = rows::box_luminance(shape, rules, input, y0, ybox_new, rows.csum);
    let ybox = ybox.with(ybox_new);
    let (a, b) = rows.classify;
    if b > a {
        classify::classify(
            shape,
            rules,
            input,
            YView::new(ybox, shape.h),
            rows.hpass,
            a,
            per_task,
        )
    } else {
        Vec::new()
    }
}
