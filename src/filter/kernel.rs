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

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // index loops mirror the maths
mod tests {
    use super::*;

    /// Sum of weights is one up to a few rounding steps of f64 (2^-52 each, at
    /// most ~100 taps): 1e-13 leaves a wide margin.
    const SUM_TOL: f64 = 1e-13;

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
