//! The energy-preserving variable-width Gaussian of Rushmeier & Ward, §5.2.
//!
//! Rule 1 (which samples are noise): Relation 14,
//! `|x0/xbar - 1| / (1/w0 - x0/xbar) > tolerance`, on luminance. `x0` is the
//! sample's luminance; `xbar` the Gaussian-weighted average luminance around
//! the sample's nearest output pixel `p`; `w0` the sample's weight in that
//! average. The average is taken over the super-samples of the pixels `q`
//! around `p`, each weighted `g(|q - p| / rho)` with `g(u) = exp(-u^2)` over
//! the disc `dx^2 + dy^2 <= (a rho)^2`, `a = min(cutoff, AVG_CUTOFF)` (a
//! kernel whose weights over the super-samples sum to one, as Relation 14
//! requires; [`AVG_CUTOFF`] says how much of the Gaussian's weight it holds), so
//! `xbar = sum_q g * Ybox(q) / sum_q g` and `w0 = 1 / (S^2 * sum_q g)`, where
//! `Ybox(q)` is the mean luminance of pixel `q`'s `S^2` samples. For
//! `rho = 0.6`, `S = 3` this gives `w0 = 0.088`: the centre sample's own
//! normalized scatter weight at its pixel (0.79) divided by `S^2`.
//!
//! Rule 2 (where noise goes): a noisy sample is spread with the normalized
//! Gaussian of the smallest radius `rho = m * radius` on a geometric ladder
//! (`radius * (1 + width_step)^k`, capped at `max_radius`) that satisfies
//! Relation 14. The next width is guessed from the current one, as the paper
//! does, but exactly: with `bg` the average without the sample (Relation 12),
//! Relation 14 reads `D_ar = (x0/bg - 1) * w0`, so the guess is the first
//! width whose tabulated `w0` is small enough; `bg` is re-estimated from
//! each width evaluated, six times at most, then bisection. A width costs its
//! area, and where fireflies are dense `bg` grows with the width (the next
//! firefly enters the average), so guesses overshoot: until a width passes,
//! the search climbs at most as many rungs as double the area (a gallop),
//! which bounds its cost by a few times the area of the width it finds
//! (unbounded guesses then bisection cost many times more where fireflies
//! are dense). There `log D` falls about linearly with the rung, so once two
//! widths have failed the search follows the line through them (up to twice
//! the gallop), and once bracketed it interpolates the same way: fewer
//! widths evaluated, the same widths found. The bracket shrinks at every
//! step, so the search is bounded by the ladder's length. A sample that still fails at the cap is spread at the cap
//! and counted.
//!
//! The paper sums rings about `p` so that each candidate width costs one 1-D
//! dot product instead of many `exp()` calls. Here the weights of every width
//! are tabulated once per job, and the Gaussian is separable, so a candidate
//! costs one contiguous row dot product per row of its disc, which
//! vectorize (the ring sums do not).
//!
//! Samples with `x0 <= 0` or `xbar <= 0` (or non-finite ratios) keep the base
//! kernel: the test is not defined there.

use super::kernel::{Coarse, Kernel1d};

mod bound;
mod features;
pub mod pixel;
mod search;
pub use bound::{csum_add, csum_block_for, csum_prefix, csum_row, AreaSums, Bound, BOUND_KEEP};
pub use features::{Carriers, Support, COMPACT_REACH, SUPPORT_REACH};
pub use search::{Choice, Folded};

/// `D_ar` of Relation 14 for `t = x0 / xbar` and weight `w0`; infinite where
/// the sample outweighs everything else (`1/w0 - t <= 0`).
#[inline]
pub fn relation14(t: f64, w0: f64) -> f64 {
    let den = 1.0 / w0 - t;
    if den > 0.0 {
        (t - 1.0).abs() / den
    } else {
        f64::INFINITY
    }
}

/// Dot product in four interleaved lanes, merged in a fixed order (measured
/// faster than 16 lanes here: rows are at most ~100 long).
#[inline]
fn dot4(a: &[f64], b: &[f64]) -> f64 {
    let mut l = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            l[k] += x[k] * y[k];
        }
    }
    let mut tail = 0.0;
    for (x, y) in ra.iter().zip(rb) {
        tail += x * y;
    }
    (l[0] + l[1]) + (l[2] + l[3]) + tail
}

/// [`dot4`] of f64 weights with f32 values (the box luminance is stored in
/// f32: half the bytes for the search to read; every sum is in f64).
#[inline]
fn dot4_f32(a: &[f64], b: &[f32]) -> f64 {
    let mut l = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            l[k] += x[k] * y[k] as f64;
        }
    }
    let mut tail = 0.0;
    for (x, y) in ra.iter().zip(rb) {
        tail += x * *y as f64;
    }
    (l[0] + l[1]) + (l[2] + l[3]) + tail
}

/// Radius of the average's support in units of `rho`, at most the kernel's
/// cutoff: the disc of `AVG_CUTOFF rho` holds all but `e^-5.06 = 0.6%` of a
/// 2-D Gaussian's weight, and reading it costs 0.44x the square of `3 rho`
/// (0.81x the disc of `2.5 rho` it was before the second real-renders round).
pub const AVG_CUTOFF: f64 = 2.25;

/// Pixels either side of a flagged pixel whose box luminance makes its
/// background at S > 1 (the median of the ring of eight about it, read by
/// the support rule): the box luminance rows keep at least this many
/// columns of padding, and the classification reads at least this many
/// rows either side, however narrow the kernels.
pub const RING_REACH: usize = 1;

/// The average's support radius for kernel cutoff `cutoff`, in `rho`.
pub fn avg_cutoff(cutoff: f64) -> f64 {
    cutoff.min(AVG_CUTOFF)
}

/// Half-widths of the rows `dy = 0..=floor(r)` of the disc of radius `r`:
/// the largest `dx` with `dx^2 + dy^2 <= r^2`.
pub fn disc_spans(r: f64) -> Vec<usize> {
    let c = r.max(0.0).floor() as usize;
    (0..=c)
        .map(|dy| {
            let mut dx = (r * r - (dy * dy) as f64).max(0.0).sqrt().floor() as usize;
            while dx > 0 && ((dx * dx + dy * dy) as f64) > r * r {
                dx -= 1;
            }
            while (((dx + 1) * (dx + 1) + dy * dy) as f64) <= r * r {
                dx += 1;
            }
            dx
        })
        .collect()
}

/// One rung of the width ladder.
#[derive(Clone, Debug)]
pub struct Level {
    /// Gaussian radius in output pixels.
    pub rho: f64,
    /// Its scatter kernel.
    pub kernel: Kernel1d,
    /// Radius in pixels of the average's support, `floor(avg_cutoff * rho)`.
    shell: usize,
    /// The support is the disc `dx^2 + dy^2 <= (avg_cutoff * rho)^2`: row
    /// `dy` (`0..=shell`) holds `|dx| <= span[dy]`.
    span: Vec<usize>,
    /// 1-D weights `g(d/rho)`, `d = -shell..=shell`.
    g1: Vec<f64>,
    /// `sum_q g(|q-p|/rho)` over the disc: `sum_dy g(dy) sum_{|dx| <= span} g(dx)`.
    norm: f64,
    /// Weight of one super-sample of `p` in the average.
    pub w0: f64,
    /// The search's cost of this width: luminance values its support sums
    /// into the quadrant (entry 0 of a row sums its one or two values, the
    /// others twice as many), and quadrant entries its average weighs.
    grow_cost: u64,
    avg_cost: u64,
    /// `1 / norm`, `1 / w0 = S^2 norm` and `1 / (1 - w0)`: the search's
    /// steps as products (a division costs ten of them, and each of the 4-5
    /// widths a search evaluates took five in a row).
    inv_norm: f64,
    inv_w0: f64,
    inv_1mw0: f64,
    /// Its spread on the 2x coarser grid (`--coarse-from`), when on.
    pub coarse: Option<Coarse>,
    /// The lower bound the search checks it against (`--bound-from`), when
    /// on.
    pub bound: Option<Bound>,
}

/// Access to rows of box luminance, mirrored at the borders and padded by
/// [`EpGauss::pad`] columns on each side. The values are f32 (the mean of a
/// pixel's samples, computed in f64 and rounded once): the search reads them
/// by the hundred million, and half the bytes is what it waits for; every
/// average over them is summed in f64.
pub trait LumRows {
    /// Row for virtual pixel row `vy` (any integer; the implementor mirrors it).
    /// Index `x + pad` holds virtual column `x`.
    fn row(&self, vy: i64) -> &[f32];
}

/// An in-memory field of box luminance with mirrored rows and padded,
/// mirrored columns: the [`LumRows`] of small jobs, tests and benches (the
/// spread stage streams its own).
#[derive(Clone, Debug)]
pub struct LumImage {
    h: usize,
    rows: Vec<Vec<f32>>,
    /// The summed-area table ([`AreaSums`]) in blocks of [`csum_block_for`]`(pad)`.
    csums: Vec<Vec<f64>>,
    block: usize,
}

impl LumImage {
    /// A `w` x `h` field with `pad` mirrored columns each side; `f(x, y)` gives
    /// the value of pixel (x, y).
    pub fn new(w: usize, h: usize, pad: usize, f: impl Fn(usize, usize) -> f64) -> Self {
        let rows = (0..h)
            .map(|y| {
                (0..w + 2 * pad)
                    .map(|i| f(crate::geometry::mirror(i as i64 - pad as i64, w), y) as f32)
                    .collect()
            })
            .collect::<Vec<Vec<f32>>>();
        let block = csum_block_for(pad);
        let mut csums: Vec<Vec<f64>> = Vec::with_capacity(h);
        for (y, r) in rows.iter().enumerate() {
            let mut out = vec![0.0; r.len() + 2];
            let prev = (y % block != 0).then(|| csums[y - 1].as_slice());
            csum_row(r, prev, &mut out);
            csums.push(out);
        }
        LumImage {
            h,
            rows,
            csums,
            block,
        }
    }
}

impl LumRows for LumImage {
    fn row(&self, vy: i64) -> &[f32] {
        &self.rows[crate::geometry::mirror(vy, self.h)]
    }
}

impl AreaSums for LumImage {
    fn csum(&self, y: usize) -> Option<&[f64]> {
        self.csums.get(y).map(Vec::as_slice)
    }
    fn height(&self) -> usize {
        self.h
    }
    fn block(&self) -> usize {
        self.block
    }
}

/// Precomputed tables of the filter: built once per job, read-only after.
#[derive(Clone, Debug)]
pub struct EpGauss {
    s: usize,
    tol: f64,
    levels: Vec<Level>,
    /// Each level's `w0`, packed for the guess's binary search.
    w0s: Vec<f64>,
    t_hi: f64,
    t_lo: f64,
    /// Rungs that double a width's area (its cost in the search).
    jump: usize,
    /// The widest shell: the luminance rows' padding.
    pad: usize,
    /// `ln tol`, for the search's line through log D.
    ln_tol: f64,
    cutoff: f64,
}

/// Rungs of relative step `width_step` that (at least) double `rho^2`.
fn rungs_to_double_area(width_step: f64) -> usize {
    let r = (2f64.ln() / (2.0 * (1.0 + width_step).ln())).ceil();
    if r.is_finite() && r >= 1.0 {
        (r as usize).min(1 << 16)
    } else {
        1
    }
}

impl EpGauss {
    /// Build the ladder from base radius `radius` up to `max_radius` in
    /// relative steps of `width_step`.
    pub fn new(
        s: usize,
        radius: f64,
        max_radius: f64,
        cutoff: f64,
        tol: f64,
        width_step: f64,
    ) -> Self {
        let mut rhos = vec![radius];
        if max_radius > radius {
            for k in 1.. {
                let rho = radius * (1.0 + width_step).powi(k);
                if rho >= max_radius * (1.0 - 1e-12) {
                    rhos.push(max_radius);
                    break;
                }
                rhos.push(rho);
            }
        }
        let s2 = (s * s) as f64;
        let levels: Vec<Level> = rhos
            .iter()
            .map(|&rho| {
                let r = avg_cutoff(cutoff) * rho;
                let shell = r.floor() as usize;
                let span = disc_spans(r);
                let g1: Vec<f64> = (-(shell as i64)..=shell as i64)
                    .map(|d| (-((d * d) as f64) / (rho * rho)).exp())
                    .collect();
                // sum over the disc of g(dx) g(dy)
                let row_sum =
                    |dy: usize| g1[shell - span[dy]..=shell + span[dy]].iter().sum::<f64>();
                let norm = g1[shell] * row_sum(0)
                    + 2.0
                        * (1..=shell)
                            .map(|dy| g1[shell + dy] * row_sum(dy))
                            .sum::<f64>();
                let nrows = |dy: usize| 1 + u64::from(dy > 0);
                let grow_cost = span
                    .iter()
                    .enumerate()
                    .map(|(dy, &sp)| nrows(dy) * (2 * sp as u64 + 1))
                    .sum();
                let avg_cost = span.iter().map(|&sp| sp as u64 + 1).sum();
                Level {
                    rho,
                    kernel: Kernel1d::gaussian(s, rho, cutoff),
                    shell,
                    grow_cost,
                    avg_cost,
                    span,
                    g1,
                    norm,
                    w0: 1.0 / (s2 * norm),
                    inv_norm: 1.0 / norm,
                    inv_w0: s2 * norm,
                    inv_1mw0: 1.0 / (1.0 - 1.0 / (s2 * norm)),
                    coarse: None,
                    bound: None,
                }
            })
            .collect();
        let a = 1.0 / levels[0].w0;
        let t_hi = (1.0 + tol * a) / (1.0 + tol);
        let t_lo = if tol < 1.0 {
            (1.0 - tol * a) / (1.0 - tol)
        } else {
            f64::NEG_INFINITY
        };
        EpGauss {
            s,
            tol,
            pad: (levels.iter().map(|l| l.shell).max().unwrap_or(0)).max(if s > 1 {
                RING_REACH
            } else {
                0
            }),
            ln_tol: tol.ln(),
            w0s: levels.iter().map(|l| l.w0).collect(),
            levels,
            t_hi,
            t_lo,
            jump: rungs_to_double_area(width_step),
            cutoff,
        }
    }

    /// Spread the widths of radius `from` pixels and more on the 2x coarser
    /// grid, and those of `2 from` and more on the 4x coarser one
    /// ([`Coarse`]: the same size in cells; `0` or infinity: none). Level 0,
    /// the base kernel, never is.
    pub fn with_coarse(mut self, from: f64) -> Self {
        let (s, cutoff) = (self.s, self.cutoff);
        for lv in self.levels.iter_mut().skip(1) {
            lv.coarse = if from > 0.0 && lv.rho >= from {
                let four = (lv.rho >= 2.0 * from)
                    .then(|| Coarse::with_factor(s, lv.rho, cutoff, 4))
                    .flatten();
                four.or_else(|| Coarse::new(s, lv.rho, cutoff))
            } else {
                None
            };
        }
        self
    }

    /// Check the widths of radius `from` output pixels and more against a
    /// lower bound of their average ([`Bound`]) instead of the average
    /// itself where the bound can be trusted (`0` or infinity: never). The
    /// base width never is.
    pub fn with_bound(mut self, from: f64) -> Self {
        let a = avg_cutoff(self.cutoff);
        for lv in self.levels.iter_mut().skip(1) {
            lv.bound =
                (from > 0.0 && lv.rho >= from).then(|| Bound::new(lv.rho, a * lv.rho, lv.norm));
        }
        self
    }

    /// Rows per block of the summed-area table the bound reads
    /// ([`csum_block_for`] of [`EpGauss::pad`]).
    pub fn csum_block(&self) -> usize {
        csum_block_for(self.pad)
    }

    /// Whether any width is checked against a bound (the summed-area table is
    /// needed).
    pub fn uses_bound(&self) -> bool {
        self.levels.iter().any(|l| l.bound.is_some())
    }

    /// Cells either side that the kernels spread on the grid `factor`
    /// times coarser than the output write (1: the output grid; 2, 4: the
    /// coarse grids of [`EpGauss::with_coarse`]), 0 where none is.
    pub fn grid_reach(&self, factor: usize) -> usize {
        self.levels
            .iter()
            .filter_map(|l| match &l.coarse {
                None => (factor == 1).then(|| l.kernel.reach()),
                Some(c) => (c.factor == factor).then(|| c.kernel.reach()),
            })
            .max()
            .unwrap_or(0)
    }

    /// The ladder; level 0 is the base kernel.
    pub fn levels(&self) -> &[Level] {
        &self.levels
    }

    /// Columns of padding the luminance rows need (the widest average).
    #[inline]
    pub fn pad(&self) -> usize {
        self.pad
    }

    /// Rows either side the classification reads: the base test's, and at
    /// S = 1 those of the pixels within [`COMPACT_REACH`] (the compact test
    /// of [`Carriers`]), at S > 1 at least the background's ring
    /// ([`RING_REACH`]).
    pub fn xbar_reach(&self) -> usize {
        let shell = self.levels[0].shell;
        match self.s {
            1 => shell + COMPACT_REACH,
            _ => shell.max(RING_REACH),
        }
    }

    /// Rows either side the search reads.
    pub fn search_reach(&self) -> usize {
        self.pad()
    }

    /// Rows either side the widest kernel writes.
    pub fn spread_reach(&self) -> usize {
        self.levels
            .iter()
            .map(|l| l.kernel.reach())
            .max()
            .unwrap_or(0)
    }

    /// The Gaussian-weighted average of box luminance at level `l` about
    /// padded column `cx`, row `cy`: `sum_dy g1[dy] * (g1 . row[cy + dy])`.
    #[inline]
    fn average(&self, rows: &impl LumRows, cx: i64, cy: i64, l: usize) -> f64 {
        let lv = &self.levels[l];
        let c = lv.shell as i64;
        let mut acc = 0.0;
        for (k, &gy) in lv.g1.iter().enumerate() {
            let r = rows.row(cy + k as i64 - c);
            let sp = lv.span[(k as i64 - c).unsigned_abs() as usize] as i64;
            let g = &lv.g1[(c - sp) as usize..=(c + sp) as usize];
            acc += gy * dot4_f32(g, &r[(cx - sp) as usize..=(cx + sp) as usize]);
        }
        acc / lv.norm
    }

    /// `xbar` at the base width for pixel `px` of row `y`.
    #[inline]
    pub fn xbar0(&self, rows: &impl LumRows, px: usize, y: i64) -> f64 {
        self.average(rows, (px + self.pad()) as i64, y, 0)
    }

    /// `xbar` at the base width for every pixel of row `y` (width `w`):
    /// horizontal then vertical pass, vectorized across the row. Equal to
    /// [`EpGauss::xbar0`] up to summation order.
    pub fn xbar0_row(&self, rows: &impl LumRows, y: i64, w: usize) -> Vec<f64> {
        let (mut out, mut h) = (Vec::new(), Vec::new());
        self.xbar0_row_into(rows, y, w, &mut out, &mut h);
        out
    }

    /// [`EpGauss::xbar0_row`] into `out`, with the caller's scratch `h` (no
    /// allocation once they have grown to `w`).
    pub fn xbar0_row_into(
        &self,
        rows: &impl LumRows,
        y: i64,
        w: usize,
        out: &mut Vec<f64>,
        h: &mut Vec<f64>,
    ) {
        self.xbar0_cols_into(rows, y, 0..w, out, h);
    }

    /// [`EpGauss::xbar0_row_into`] for the pixels `cols` of the row only
    /// (`out[x - cols.start]`): the same sum for each.
    pub fn xbar0_cols_into(
        &self,
        rows: &impl LumRows,
        y: i64,
        cols: std::ops::Range<usize>,
        out: &mut Vec<f64>,
        h: &mut Vec<f64>,
    ) {
        let (w, pad) = (cols.len(), self.pad() + cols.start);
        let lv = &self.levels[0];
        let c = lv.shell;
        out.clear();
        out.resize(w, 0.0);
        h.clear();
        h.resize(w, 0.0);
        for (k, &gy) in lv.g1.iter().enumerate() {
            let r = rows.row(y + k as i64 - c as i64);
            h.iter_mut().for_each(|v| *v = 0.0);
            let sp = lv.span[k.abs_diff(c)];
            for (dx, &g) in lv.g1.iter().enumerate().take(c + sp + 1).skip(c - sp) {
                for (hv, &v) in h.iter_mut().zip(&r[pad + dx - c..pad + dx - c + w]) {
                    *hv += g * v as f64;
                }
            }
            for (o, &hv) in out.iter_mut().zip(h.iter()) {
                *o += gy * hv;
            }
        }
        out.iter_mut().for_each(|v| *v /= lv.norm);
    }

    /// The cheap path's bounds on `x0` for a pixel whose base average is
    /// `xbar`: noisy iff `x0 > hi` or `x0 < lo` (with `x0 > 0`). `None` where
    /// the test is not defined (`xbar <= 0` or not finite): base kernel. One
    /// multiplication per pixel instead of a division per sample; equal to
    /// [`EpGauss::is_noisy`] but for rounding at the exact boundary.
    #[inline]
    pub fn bounds(&self, xbar: f64) -> Option<(f64, f64)> {
        (xbar > 0.0 && xbar.is_finite()).then_some((self.t_hi * xbar, self.t_lo * xbar))
    }

    /// Whether a sample of luminance `x0` lies outside the
    /// [`EpGauss::bounds`] `(hi, lo)` of its pixel: noisy. Samples at or
    /// below 0 never are (Relation 14 is not defined there).
    #[inline]
    pub fn outside(x0: f64, (hi, lo): (f64, f64)) -> bool {
        x0 > 0.0 && (x0 > hi || x0 < lo)
    }

    /// Only samples brighter than their neighbourhood can be noise: the
    /// dark side of Relation 14 (`t_lo`) is off.
    pub fn bright_only(mut self) -> Self {
        self.t_lo = f64::NEG_INFINITY;
        self
    }

    /// Whether a sample can fail the test by being too dark (`t_lo > 0`:
    /// `tol < w0`, 0.089 at the base width at S = 3, so below the old
    /// default 0.25 and above the new 0.08): otherwise only samples
    /// brighter than the bound of [`EpGauss::bounds`] are noisy.
    pub fn low_outliers(&self) -> bool {
        self.t_lo > 0.0
    }

    /// Cheap path: is the sample noisy at the base width? Only the few that are
    /// go to [`EpGauss::search`]. Relation 14 solved for `t = x0/xbar` once:
    /// noisy iff `t > (1 + tol/w0)/(1 + tol)`, or (`tol < 1`)
    /// `t < (1 - tol/w0)/(1 - tol)`.
    #[inline]
    pub fn is_noisy(&self, x0: f64, xbar: f64) -> bool {
        if !(x0 > 0.0 && xbar > 0.0) {
            return false;
        }
        let t = x0 / xbar;
        t.is_finite() && (t > self.t_hi || t < self.t_lo)
    }

    /// The super-sampling factor.
    pub fn s(&self) -> usize {
        self.s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) type Field = LumImage;

    /// Direct 2-D Gaussian average over the disc of radius
    /// `min(cutoff, AVG_CUTOFF) rho` (the definition).
    pub(crate) fn direct_average(ep: &EpGauss, f: &Field, px: usize, py: usize, l: usize) -> f64 {
        let lv = &ep.levels()[l];
        let r = ep.cutoff.min(AVG_CUTOFF) * lv.rho;
        let c = r.floor() as i64;
        let (mut num, mut den) = (0.0, 0.0);
        for dy in -c..=c {
            for dx in -c..=c {
                if (dx * dx + dy * dy) as f64 > r * r {
                    continue;
                }
                let g = (-((dx * dx + dy * dy) as f64) / (lv.rho * lv.rho)).exp();
                num +=
                    g * f.row(py as i64 + dy)[(px as i64 + ep.pad() as i64 + dx) as usize] as f64;
                den += g;
            }
        }
        num / den
    }

    #[test]
    fn disc_spans_hold_exactly_the_pixels_of_the_disc() {
        assert_eq!(disc_spans(2.5), vec![2, 2, 1]);
        assert_eq!(disc_spans(1.8), vec![1, 1]);
        assert_eq!(disc_spans(0.0), vec![0]);
        for k in 0..400 {
            let r = k as f64 * 0.137;
            let span = disc_spans(r);
            assert_eq!(span.len(), r.floor() as usize + 1);
            for (dy, &sp) in span.iter().enumerate() {
                let inside = |dx: usize| ((dx * dx + dy * dy) as f64) <= r * r;
                assert!(inside(sp) && !inside(sp + 1), "r {r} row {dy}: {sp}");
            }
        }
    }

    #[test]
    fn base_weight_matches_the_issue() {
        let ep = EpGauss::new(3, 0.6, 16.0, 3.0, 0.25, 0.1);
        let w0 = ep.levels()[0].w0;
        assert!((w0 - 0.088).abs() < 0.001, "w0 = {w0}");
    }

    #[test]
    fn separable_average_equals_the_direct_sum() {
        // Relative agreement of two f64 summation orders over <= 97^2 terms.
        const SUM_ORDER_TOL: f64 = 1e-12;
        let ep = EpGauss::new(3, 0.6, 6.0, 3.0, 0.25, 0.1);
        let f = Field::new(50, 45, ep.pad(), |x, y| {
            ((x * 7919 + y * 104_729) % 1000) as f64 * 0.01 + 0.5
        });
        for l in 0..ep.levels().len() {
            for &(px, py) in &[(0usize, 0usize), (20, 22), (49, 44), (3, 40)] {
                let a = ep.average(&f, (px + ep.pad()) as i64, py as i64, l);
                let b = direct_average(&ep, &f, px, py, l);
                assert!(
                    (a - b).abs() <= SUM_ORDER_TOL * b,
                    "level {l} ({px},{py}): {a} vs {b}"
                );
            }
        }
        let row = ep.xbar0_row(&f, 7, 50);
        for (x, v) in row.iter().enumerate() {
            let single = ep.xbar0(&f, x, 7);
            assert!((v - single).abs() <= SUM_ORDER_TOL * single);
        }
    }

    #[test]
    fn relation14_is_excess_ratio_times_weight() {
        // With xbar = w0*x0 + (1-w0)*bg (Relation 12), Relation 14 equals
        // (x0/bg - 1) * w0 for x0 > bg: the identity the width guess uses.
        for &(x0, bg, w0) in &[
            (100.0, 1.0, 0.088),
            (5.0, 2.0, 0.01),
            (1e5, 0.3, 1e-4),
            (1.5, 1.0, 0.5),
        ] {
            let xbar = w0 * x0 + (1.0 - w0) * bg;
            let d = relation14(x0 / xbar, w0);
            let want: f64 = (x0 / bg - 1.0) * w0;
            assert!((d - want).abs() <= 1e-12 * want, "{d} vs {want}");
        }
    }

    #[test]
    fn cheap_test_agrees_with_relation14() {
        for &tol in &[0.0, 0.05, 0.15, 0.25, 1.0, 3.0] {
            let ep = EpGauss::new(3, 0.6, 16.0, 3.0, tol, 0.1);
            let w0 = ep.levels()[0].w0;
            for i in 0..2000 {
                let t = (i as f64) * 0.01 + 0.0005;
                let d = relation14(t, w0);
                // The two forms are algebraically equal; skip the rounding edge.
                if (d - tol).abs() < 1e-9 {
                    continue;
                }
                assert_eq!(ep.is_noisy(t, 1.0), d > tol, "tol={tol} t={t} d={d}");
            }
        }
    }

    #[test]
    fn flat_field_has_no_noise_and_xbar_is_exact() {
        let ep = EpGauss::new(3, 0.6, 8.0, 3.0, 0.25, 0.1);
        let f = Field::new(10, 7, ep.pad(), |_, _| 2.5);
        for y in 0..7 {
            for x in 0..10 {
                let xb = ep.xbar0(&f, x, y as i64);
                assert!((xb - 2.5).abs() < 1e-12);
                assert!(!ep.is_noisy(2.5, xb));
            }
        }
    }

    #[test]
    fn outside_the_bounds_is_noisy_and_nonpositive_never_is() {
        let ep = EpGauss::new(3, 0.6, 16.0, 3.0, 0.08, 0.1);
        let (hi, lo) = ep.bounds(1.0).unwrap();
        // At the default tolerance the dark side is live (`tol < w0`).
        assert!(lo > 0.0 && hi > 1.0);
        for (x0, noisy) in [
            (hi * 1.001, true),
            (hi, false),
            (1.0, false),
            (lo, false),
            (lo * 0.999, true),
            (0.0, false),
            (-5.0, false),
            (f64::NAN, false),
        ] {
            assert_eq!(EpGauss::outside(x0, (hi, lo)), noisy, "{x0}");
            if x0 > 0.0 {
                assert_eq!(ep.is_noisy(x0, 1.0), noisy, "{x0}");
            }
        }
    }
}
