//! Separable, per-sub-offset normalized 1-D kernels, their reflection at the
//! borders (method of images) and their gather form.
//!
//! A sample at sub-offset `a` of output pixel `px` gives output index
//! `px + d` (for `d` in `-reach..=reach`) the weight `w[a][d]`; the weights of
//! each row of the table sum to one, so every sample's 2-D weights
//! `wx[a][dx] * wy[b][dy]` sum to one. Weights that fall outside the image are
//! reflected back inside ([`crate::geometry::mirror`]): the sum stays one, and
//! because a reflected flat field is flat, a flat image stays flat up to its
//! borders and corners.

use crate::geometry::{mirror, sub_offset};

/// One normalized weight row per sub-offset.
#[derive(Clone, Debug, PartialEq)]
pub struct Kernel1d {
    s: usize,
    reach: usize,
    w: Vec<f64>,
}

impl Kernel1d {
    /// Gaussian `exp(-(d/rho)^2)` of radius `rho` (output pixels), cut off where
    /// the distance from the sample exceeds `cutoff * rho`, normalized per row.
    /// A row whose every tap is cut off (a radius far below a pixel) puts its
    /// whole weight on the sample's own pixel.
    pub fn gaussian(s: usize, rho: f64, cutoff: f64) -> Self {
        let limit = cutoff * rho;
        let reach = (limit + 0.5).floor().max(0.0) as usize;
        let width = 2 * reach + 1;
        let mut w = vec![0.0; s * width];
        for a in 0..s {
            let delta = sub_offset(a, s);
            let row = &mut w[a * width..(a + 1) * width];
            let mut sum = 0.0;
            for (k, slot) in row.iter_mut().enumerate() {
                let dist = (k as f64 - reach as f64) - delta;
                if dist.abs() <= limit {
                    let u = dist / rho;
                    *slot = (-u * u).exp();
                    sum += *slot;
                }
            }
            if sum > 0.0 && sum.is_finite() {
                for slot in row.iter_mut() {
                    *slot /= sum;
                }
            } else {
                row.iter_mut().for_each(|x| *x = 0.0);
                row[reach] = 1.0;
            }
        }
        Kernel1d { s, reach, w }
    }

    /// The S x S box: every sample goes to its own pixel with weight one.
    pub fn boxed(s: usize) -> Self {
        Kernel1d {
            s,
            reach: 0,
            w: vec![1.0; s],
        }
    }

    /// How far (in output pixels) a sample reaches.
    pub fn reach(&self) -> usize {
        self.reach
    }

    /// The super-sampling factor.
    pub fn s(&self) -> usize {
        self.s
    }

    /// The weights of sub-offset `a`, for `d = -reach..=reach`.
    #[inline]
    pub fn row(&self, a: usize) -> &[f64] {
        let width = 2 * self.reach + 1;
        &self.w[a * width..(a + 1) * width]
    }

    /// Where the weights of a sample in output pixel `p` start when all of
    /// them land inside `0..n` (no reflection: [`Kernel1d::fold`] would
    /// write [`Kernel1d::row`] as it is); `None` near the edges.
    #[inline]
    pub fn interior(&self, p: usize, n: usize) -> Option<usize> {
        (p >= self.reach && p + self.reach < n).then(|| p - self.reach)
    }

    /// Reflect the weights of a sample at sub-offset `a` in output pixel `p`
    /// onto `0..n`. Writes the weights of the contiguous targets
    /// `start..start + out.len()` into `out` and returns `start`.
    #[inline]
    pub fn fold(&self, a: usize, p: usize, n: usize, out: &mut Vec<f64>) -> usize {
        let row = self.row(a);
        let r = self.reach as i64;
        let lo = p as i64 - r;
        let hi = p as i64 + r;
        out.clear();
        if lo >= 0 && hi < n as i64 {
            out.extend_from_slice(row);
            return lo as usize;
        }
        let (start, end) = if self.reach >= n {
            (0, n - 1)
        } else {
            (lo.max(0) as usize, hi.min(n as i64 - 1) as usize)
        };
        out.resize(end - start + 1, 0.0);
        for (k, &w) in row.iter().enumerate() {
            let t = mirror(lo + k as i64, n);
            out[t - start] += w;
        }
        start
    }

    /// Gather form: the weights with which output index `x` (of `n_out`)
    /// receives the input samples `start..start + out.len()` (of `n_in`).
    /// Equal to the sum of the folded scatter weights, in the same order.
    pub fn gather(&self, x: usize, n_out: usize, n_in: usize, out: &mut Vec<f64>) -> usize {
        let s = self.s;
        let r = self.reach;
        let (i0, i1) = if r >= n_out {
            (0, n_in)
        } else {
            (x.saturating_sub(r) * s, ((x + r + 1) * s).min(n_in))
        };
        out.clear();
        out.resize(i1 - i0, 0.0);
        for i in i0..i1 {
            let (px, a) = (i / s, i % s);
            let row = self.row(a);
            let lo = px as i64 - r as i64;
            let mut acc = 0.0;
            for (k, &w) in row.iter().enumerate() {
                if mirror(lo + k as i64, n_out) == x {
                    acc += w;
                }
            }
            out[i - i0] = acc;
        }
        // Trim zero taps at both ends so the hot loop does less work.
        let first = out.iter().position(|&w| w != 0.0).unwrap_or(0);
        let last = out
            .iter()
            .rposition(|&w| w != 0.0)
            .map_or(first, |l| l + 1)
            .max(first);
        out.truncate(last);
        out.drain(..first);
        i0 + first
    }
}

/// Gather taps of every output column, built once per job (memory: width).
#[derive(Clone, Debug)]
pub struct ColumnTaps {
    start: Vec<usize>,
    offset: Vec<usize>,
    w: Vec<f64>,
}

impl ColumnTaps {
    /// Build the taps of all `n_out` columns.
    pub fn new(k: &Kernel1d, n_out: usize, n_in: usize) -> Self {
        let mut start = Vec::with_capacity(n_out);
        let mut offset = Vec::with_capacity(n_out + 1);
        let mut w = Vec::new();
        let mut scratch = Vec::new();
        offset.push(0);
        for x in 0..n_out {
            start.push(k.gather(x, n_out, n_in, &mut scratch));
            w.extend_from_slice(&scratch);
            offset.push(w.len());
        }
        ColumnTaps { start, offset, w }
    }

    /// First input index and weights of output column `x`.
    #[inline]
    pub fn taps(&self, x: usize) -> (usize, &[f64]) {
        (self.start[x], &self.w[self.offset[x]..self.offset[x + 1]])
    }
}

/// The 2x upsampling of the coarse grid: coarse cell `C` gives the fine
/// indices `2C - 1 ..= 2C + 2` these weights (a tent, variance 0.75 px^2),
/// reflected at the borders like every kernel: they sum to one.
pub const TENT: [f64; 4] = [0.125, 0.375, 0.375, 0.125];

/// A Gaussian of the ladder spread on a grid `F` = 2 or 4 times coarser
/// and brought back with [`TENT`] (`--coarse-from`), once per halving (the
/// 4x grid goes to the 2x grid, then to the pixels): `1 / F^2` of the taps.
/// The coarse kernel is a [`Kernel1d`] with `F S` phases (a sample's place
/// in its coarse cell: its pixel's place in the cell and its sub-offset) and
/// radius `sqrt(rho^2 - (F^2 - 1) / 2) / F` coarse cells, so that with the
/// tents' variance (0.75 of a cell of the grid each comes from) the spread
/// has the fine Gaussian's (`rho^2 / 2`). It is cut short of the fine
/// kernel's reach `R` (first `R - 2` fine pixels from the sample, less until
/// it fits), so with the tents it reaches no further than the fine kernel;
/// and it is widened until no fine pixel receives more than the fine kernel
/// gives any (Relation 14 bounds a spread sample's influence on every
/// output pixel by that weight).
#[derive(Clone, Debug, PartialEq)]
pub struct Coarse {
    /// The coarse kernel, `F S` phases, in coarse cells.
    pub kernel: Kernel1d,
    /// `F`: fine pixels per coarse cell, 2 or 4.
    pub factor: usize,
}

impl Coarse {
    /// The form of `Kernel1d::gaussian(s, rho, cutoff)` on the 2x coarser
    /// grid; `None` when the fine kernel is too narrow for one (reach under
    /// 4 pixels).
    pub fn new(s: usize, rho: f64, cutoff: f64) -> Option<Self> {
        Self::with_factor(s, rho, cutoff, 2)
    }

    /// The form on the grid `factor` (2 or 4) times coarser; `None` when the
    /// fine kernel is too narrow for one (reach under `2 factor` pixels, or
    /// a radius the tents alone exceed).
    pub fn with_factor(s: usize, rho: f64, cutoff: f64, factor: usize) -> Option<Self> {
        assert!(factor == 2 || factor == 4, "coarse factor {factor}");
        let fine = Kernel1d::gaussian(s, rho, cutoff);
        let reach = fine.reach();
        let tents = ((factor * factor - 1) as f64) / 2.0;
        if reach < 2 * factor || rho * rho <= tents {
            return None;
        }
        let fine_max: Vec<f64> = (0..s)
            .map(|a| fine.row(a).iter().cloned().fold(0.0, f64::max))
            .collect();
        // Cut a whole number of fine pixels short of the fine reach (less
        // where a phase's weights would still reach past it), widened where
        // a phase's peak would exceed the fine kernel's.
        let mut cut = (reach - 2) as f64; // fine pixels
        let mut rho_f = (rho * rho - tents).sqrt();
        let f = factor as f64;
        for _ in 0..400 {
            if cut < 1.0 {
                return None;
            }
            let kernel = Kernel1d::gaussian(factor * s, rho_f / f, cut / rho_f);
            let c = Coarse { kernel, factor };
            let (mut inside, mut below) = (true, true);
            for (a, &peak) in fine_max.iter().enumerate() {
                for p in 0..factor {
                    let (lo, w) = c.effective(a, p);
                    let first = w.iter().position(|&v| v > 0.0).unwrap_or(0) as i64 + lo;
                    let last = w.iter().rposition(|&v| v > 0.0).unwrap_or(0) as i64 + lo;
                    inside &= first >= -(reach as i64) && last <= reach as i64;
                    below &= w.iter().all(|&v| v <= peak);
                }
            }
            if !inside {
                cut -= 0.5;
            } else if !below {
                rho_f *= 1.005;
            } else {
                return Some(c);
            }
        }
        None
    }

    /// The fine weights, unreflected, of a sample at sub-offset `a` of the
    /// pixel `p` (`0..F`) of its coarse cell: `(first offset from the pixel,
    /// weights)`.
    pub fn effective(&self, a: usize, p: usize) -> (i64, Vec<f64>) {
        let f = self.factor;
        let s = self.kernel.s() / f;
        let rc = self.kernel.reach() as i64;
        let row = self.kernel.row(p * s + a);
        // The sample's coarse cell is 0 (its pixel is F*0 + p): cell d
        // weighs d; each halving takes index m to 2m - 1 ..= 2m + 2.
        let (mut lo, mut w) = (-rc, row.to_vec());
        let mut g = f;
        while g > 1 {
            let mut next = vec![0.0; 2 * w.len() + 2];
            for (k, &v) in w.iter().enumerate() {
                for (t, &tw) in TENT.iter().enumerate() {
                    next[2 * k + t] += v * tw;
                }
            }
            (lo, w, g) = (2 * lo - 1, next, g / 2);
        }
        (lo - p as i64, w)
    }

    /// Reflected coarse weights of a sample at sub-offset `a` of fine pixel
    /// `px`, onto `0..n_coarse` coarse cells (see [`Kernel1d::fold`]).
    #[inline]
    pub fn fold(&self, a: usize, px: usize, n_coarse: usize, out: &mut Vec<f64>) -> usize {
        let f = self.factor;
        let s = self.kernel.s() / f;
        self.kernel.fold((px % f) * s + a, px / f, n_coarse, out)
    }

    /// The phase (row of `kernel`) and first coarse cell of a sample at
    /// sub-offset `a` of fine pixel `px` when its weights need no reflection
    /// ([`Kernel1d::interior`]).
    #[inline]
    pub fn interior(&self, a: usize, px: usize, n_coarse: usize) -> Option<(usize, usize)> {
        let f = self.factor;
        let s = self.kernel.s() / f;
        let phase = (px % f) * s + a;
        self.kernel.interior(px / f, n_coarse).map(|st| (phase, st))
    }
}

/// Gather taps of the tent upsampling: for each of `n_fine` fine indices,
/// the coarse cells (of `n_fine.div_ceil(2)`) that give it weight, in
/// increasing order, with the reflected [`TENT`] weights. A fine index takes
/// one cell or two neighbouring ones (the tent spans four fine indices, and
/// reflection only folds a cell's weights onto indices it already reaches),
/// so the taps are kept flat: a first cell and two weights, the second 0
/// where there is one cell.
#[derive(Clone, Debug)]
pub struct TentTaps {
    /// Per fine index: first cell, weights, whether the second is a tap.
    taps: Vec<(usize, [f64; 2], bool)>,
}

impl TentTaps {
    /// Taps of `n_fine` fine indices.
    pub fn new(n_fine: usize) -> Self {
        let n_coarse = n_fine.div_ceil(2);
        let mut taps: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n_fine];
        for c in 0..n_coarse {
            for (t, &tw) in TENT.iter().enumerate() {
                let f = mirror(2 * c as i64 - 1 + t as i64, n_fine);
                let list = &mut taps[f];
                match list.last_mut() {
                    Some(last) if last.0 == c => last.1 += tw,
                    _ => list.push((c, tw)),
                }
            }
        }
        let taps = taps
            .into_iter()
            .map(|list| match list[..] {
                [(c, w)] => (c, [w, 0.0], false),
                [(c, w0), (c1, w1)] if c1 == c + 1 => (c, [w0, w1], true),
                _ => unreachable!("a fine index takes one cell or two neighbours: {list:?}"),
            })
            .collect();
        TentTaps { taps }
    }

    /// The coarse cells and weights of fine index `f`: the first cell, and
    /// one weight per cell from it.
    #[inline]
    pub fn of(&self, f: usize) -> (usize, &[f64]) {
        let (c, ref w, two) = self.taps[f];
        (c, &w[..1 + usize::from(two)])
    }

    /// The tent gather of one row of coarse cells `src` into fine row `dst`
    /// (`dst.len()` fine indices): each value is `0 + w0 * a (+ w1 * b)`,
    /// summed in the order of [`TentTaps::of`].
    #[inline]
    pub fn gather(&self, src: &[f64], dst: &mut [f64]) {
        for (d, &(c, [w0, w1], two)) in dst.iter_mut().zip(&self.taps) {
            let mut u = 0.0;
            u += w0 * src[c];
            if two {
                u += w1 * src[c + 1];
            }
            *d = u;
        }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // index loops mirror the maths
mod tests {
    use super::*;

    /// Sum of weights is one up to a few rounding steps of f64 (2^-52 each, at
    /// most ~100 taps): 1e-13 leaves a wide margin.
    const SUM_TOL: f64 = 1e-13;

    #[test]
    fn coarse_spreads_keep_the_sum_the_reach_and_the_peak() {
        for factor in [2, 4] {
            for s in 1..=4 {
                // The default ladder (0.6 * 1.1^k, to the cap) and a few more.
                let ladder = (0..30).map(|k| 0.6 * 1.1f64.powi(k)).filter(|&r| r < 16.0);
                for rho in ladder.chain([1.5, 2.0, 3.0, 4.0, 4.7, 8.0, 16.0]) {
                    check_coarse(factor, s, rho);
                }
            }
        }
    }

    fn check_coarse(factor: usize, s: usize, rho: f64) {
        // Where a grid is used (from `factor` px), the spread's centre stays
        // within a fraction of a pixel of the fine kernel's: a coarse kernel
        // about one cell wide samples its sub-cell offset coarsely (measured
        // at most 0.016 px on the 2x grid, 0.022 px on the 4x).
        const MEAN_TOL: f64 = 0.05;
        let fine = Kernel1d::gaussian(s, rho, 3.0);
        let Some(c) = Coarse::with_factor(s, rho, 3.0, factor) else {
            assert!(
                rho < 1.5 * factor as f64,
                "F={factor} s={s} rho={rho}: no coarse form"
            );
            return;
        };
        let r = fine.reach() as i64;
        for a in 0..s {
            let fine_max = fine.row(a).iter().cloned().fold(0.0, f64::max);
            for p in 0..factor {
                let (lo, w) = c.effective(a, p);
                let at = format!("F={factor} s={s} rho={rho} a={a} p={p}");
                let sum: f64 = w.iter().sum();
                assert!((sum - 1.0).abs() < SUM_TOL, "{at}: {sum}");
                let first = lo + w.iter().position(|&v| v > 0.0).unwrap() as i64;
                let last = lo + w.iter().rposition(|&v| v > 0.0).unwrap() as i64;
                assert!(first >= -r && last <= r, "{at}: {first}..{last} vs {r}");
                // Centred on the sample as the fine kernel is.
                let mean: f64 = w
                    .iter()
                    .enumerate()
                    .map(|(k, &v)| (lo + k as i64) as f64 * v)
                    .sum();
                let fine_mean: f64 = fine
                    .row(a)
                    .iter()
                    .enumerate()
                    .map(|(k, &v)| (k as i64 - r) as f64 * v)
                    .sum();
                if rho >= factor as f64 {
                    assert!(
                        (mean - fine_mean).abs() < MEAN_TOL,
                        "{at}: mean {mean} vs {fine_mean}"
                    );
                }
                let max = w.iter().cloned().fold(0.0, f64::max);
                assert!(max <= fine_max, "{at}");
                // Close to the fine kernel where it is used (from 1.5 cells:
                // the tents are small against it).
                if rho >= 1.5 * factor as f64 {
                    assert!(max >= 0.95 * fine_max, "{at}: {max} vs {fine_max}");
                }
            }
        }
    }

    #[test]
    fn tent_taps_give_every_coarse_cell_a_total_weight_of_one() {
        for n in 1..12 {
            let t = TentTaps::new(n);
            let mut per_cell = vec![0.0; n.div_ceil(2)];
            for f in 0..n {
                let (first, w) = t.of(f);
                for (k, &w) in w.iter().enumerate() {
                    per_cell[first + k] += w;
                }
            }
            for (c, &w) in per_cell.iter().enumerate() {
                assert!((w - 1.0).abs() < SUM_TOL, "n={n} cell {c}: {w}");
            }
        }
    }

    #[test]
    fn tent_gather_is_the_sum_of_the_listed_taps() {
        for n in (1..40).chain([255, 256, 2047, 2048]) {
            let t = TentTaps::new(n);
            let src: Vec<f64> = (0..n.div_ceil(2)).map(|c| 1.5 + c as f64 * 0.37).collect();
            let mut got = vec![f64::NAN; n];
            t.gather(&src, &mut got);
            for (f, &g) in got.iter().enumerate() {
                let (first, w) = t.of(f);
                let mut want = 0.0;
                for (k, &w) in w.iter().enumerate() {
                    want += w * src[first + k];
                }
                assert_eq!(g.to_bits(), want.to_bits(), "n={n} f={f}");
            }
        }
    }

    #[test]
    fn rows_sum_to_one() {
        for s in 1..=8 {
            for &rho in &[0.05, 0.3, 0.6, 1.0, 4.7, 16.0] {
                let k = Kernel1d::gaussian(s, rho, 3.0);
                for a in 0..s {
                    let sum: f64 = k.row(a).iter().sum();
                    assert!(
                        (sum - 1.0).abs() < SUM_TOL,
                        "s={s} rho={rho} a={a} sum={sum}"
                    );
                }
            }
        }
    }

    #[test]
    fn folding_keeps_sum_and_targets_inside() {
        let k = Kernel1d::gaussian(3, 2.0, 3.0);
        let mut out = Vec::new();
        for &n in &[1usize, 2, 3, 7, 40] {
            for p in 0..n {
                for a in 0..3 {
                    let start = k.fold(a, p, n, &mut out);
                    assert!(start + out.len() <= n);
                    let sum: f64 = out.iter().sum();
                    assert!((sum - 1.0).abs() < SUM_TOL);
                }
            }
        }
    }

    #[test]
    fn gather_column_sums_are_s_so_flat_stays_flat() {
        // Every output index receives total weight S from the S*n samples:
        // the reflected lattice is complete.
        for &(s, rho) in &[(3usize, 0.6), (4, 0.6), (2, 5.0), (1, 0.6), (3, 9.0)] {
            let k = Kernel1d::gaussian(s, rho, 3.0);
            for &n in &[1usize, 2, 5, 33] {
                let mut out = Vec::new();
                for x in 0..n {
                    k.gather(x, n, n * s, &mut out);
                    let sum: f64 = out.iter().sum();
                    assert!(
                        (sum - s as f64).abs() < 1e-12,
                        "s={s} rho={rho} n={n} x={x} sum={sum}"
                    );
                }
            }
        }
    }

    #[test]
    fn gather_equals_folded_scatter() {
        let k = Kernel1d::gaussian(3, 0.6, 3.0);
        let n = 6;
        let mut m = vec![vec![0.0; n * 3]; n];
        let mut out = Vec::new();
        for i in 0..n * 3 {
            let start = k.fold(i % 3, i / 3, n, &mut out);
            for (t, &w) in out.iter().enumerate() {
                m[start + t][i] += w;
            }
        }
        for x in 0..n {
            let start = k.gather(x, n, n * 3, &mut out);
            for i in 0..n * 3 {
                let g = if i >= start && i < start + out.len() {
                    out[i - start]
                } else {
                    0.0
                };
                assert!((g - m[x][i]).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn radius_point_six_matches_the_issue_figures() {
        // Centre sample of S=3 at r=0.6: normalized scatter weight at its own
        // pixel ~0.79 (the issue's "about 0.8").
        let k = Kernel1d::gaussian(3, 0.6, 3.0);
        let w = k.row(1)[k.reach()];
        assert!((w * w - 0.79).abs() < 0.01, "{}", w * w);
    }
}
