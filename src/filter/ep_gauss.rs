//! The energy-preserving variable-width Gaussian of Rushmeier & Ward, §5.2.
//!
//! Rule 1 (which samples are noise): Relation 14,
//! `|x0/xbar - 1| / (1/w0 - x0/xbar) > tolerance`, on luminance. `x0` is the
//! sample's luminance; `xbar` the Gaussian-weighted average luminance around
//! the sample's nearest output pixel `p`; `w0` the sample's weight in that
//! average. The average is taken over the super-samples of the pixels `q`
//! around `p`, each weighted `g(|q - p| / rho)` with `g(u) = exp(-u^2)` cut off
//! at `u = cutoff` (a kernel whose weights over the super-samples sum to one,
//! as Relation 14 requires), so
//! `xbar = sum_q g * Ybox(q) / sum_q g` and `w0 = 1 / (S^2 * sum_q g)`, where
//! `Ybox(q)` is the mean luminance of pixel `q`'s `S^2` samples. For
//! `rho = 0.6`, `S = 3` this gives `w0 = 0.088`: the sample's own normalized
//! scatter weight at its pixel (0.79) divided by `S^2`.
//!
//! Rule 2 (where noise goes): a noisy sample is spread with the normalized
//! Gaussian of the smallest radius `rho = m * radius` on a geometric ladder
//! (`radius * (1 + width_step)^k`, capped at `max_radius`) that satisfies
//! Relation 14. The search works as the paper's: ring sums of box luminance
//! about `p` (grown only as far as the candidate radius needs), one dot product
//! per candidate width, the next width guessed from the current `D_ar`
//! (`D_ar ~ w0 ~ 1/rho^2`), then bisection; it is bounded by the ladder's
//! length. A sample that still fails at the cap is spread at the cap and
//! counted.
//!
//! Samples with `x0 <= 0` or `xbar <= 0` (or non-finite ratios) keep the base
//! kernel: the test is not defined there.

use super::kernel::Kernel1d;

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

/// One rung of the width ladder.
#[derive(Clone, Debug)]
pub struct Level {
    /// Gaussian radius in output pixels.
    pub rho: f64,
    /// Its scatter kernel.
    pub kernel: Kernel1d,
    /// Chebyshev radius of the ring sums it needs.
    shell: usize,
    /// Ring weights `g(sqrt(d2)/rho)` of the bins it uses.
    ring_w: Vec<f64>,
    /// `sum_q g(|q-p|/rho)`.
    norm: f64,
    /// Weight of one super-sample of `p` in the average.
    pub w0: f64,
}

/// Outcome of the width search for one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Choice {
    /// Index into the ladder (0 = base kernel).
    pub level: u16,
    /// Relation 14 still failed at the cap.
    pub capped: bool,
}

/// Access to rows of box luminance, mirrored at the borders and padded by
/// [`EpGauss::pad`] columns on each side.
pub trait LumRows {
    /// Row for virtual pixel row `vy` (any integer; the implementor mirrors it).
    /// Index `x + pad` holds virtual column `x`.
    fn row(&self, vy: i64) -> &[f64];
}

/// Precomputed tables of the filter: built once per job, read-only after.
#[derive(Clone, Debug)]
pub struct EpGauss {
    s: usize,
    tol: f64,
    levels: Vec<Level>,
    ln_step: f64,
    /// Squared distance of each non-empty ring bin, increasing.
    bin_d2: Vec<u32>,
    /// Bin index of each squared distance (u32::MAX where no lattice point).
    bin_of: Vec<u32>,
    /// Base-level stencil: (dx, dy, weight / norm).
    stencil: Vec<(i32, i32, f64)>,
    t_hi: f64,
    t_lo: f64,
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
        let max_shell = (cutoff * rhos[rhos.len() - 1]).floor() as usize;
        let max_d2 = 2 * max_shell * max_shell;
        let mut count = vec![0u32; max_d2 + 1];
        for dy in 0..=max_shell {
            for dx in 0..=max_shell {
                let mult = if dx == 0 && dy == 0 {
                    1
                } else if dx == 0 || dy == 0 {
                    2
                } else {
                    4
                };
                count[dx * dx + dy * dy] += mult;
            }
        }
        let mut bin_of = vec![u32::MAX; max_d2 + 1];
        let mut bin_d2 = Vec::new();
        let mut bin_count = Vec::new();
        for (d2, &c) in count.iter().enumerate() {
            if c > 0 {
                bin_of[d2] = bin_d2.len() as u32;
                bin_d2.push(d2 as u32);
                bin_count.push(c as f64);
            }
        }
        let s2 = (s * s) as f64;
        let levels: Vec<Level> = rhos
            .iter()
            .map(|&rho| {
                let limit = cutoff * rho;
                let lim2 = limit * limit;
                let ring_w: Vec<f64> = bin_d2
                    .iter()
                    .take_while(|&&d2| (d2 as f64) <= lim2)
                    .map(|&d2| (-(d2 as f64) / (rho * rho)).exp())
                    .collect();
                let norm: f64 = ring_w.iter().zip(&bin_count).map(|(w, c)| w * c).sum();
                Level {
                    rho,
                    kernel: Kernel1d::gaussian(s, rho, cutoff),
                    shell: limit.floor() as usize,
                    ring_w,
                    norm,
                    w0: 1.0 / (s2 * norm),
                }
            })
            .collect();
        let base = &levels[0];
        let sh = base.shell as i32;
        let mut stencil = Vec::new();
        for dy in -sh..=sh {
            for dx in -sh..=sh {
                let d2 = (dx * dx + dy * dy) as usize;
                if d2 < bin_of.len() && (bin_of[d2] as usize) < base.ring_w.len() {
                    stencil.push((dx, dy, base.ring_w[bin_of[d2] as usize] / base.norm));
                }
            }
        }
        let a = 1.0 / base.w0;
        let t_hi = (1.0 + tol * a) / (1.0 + tol);
        let t_lo = if tol < 1.0 {
            (1.0 - tol * a) / (1.0 - tol)
        } else {
            f64::NEG_INFINITY
        };
        EpGauss {
            s,
            tol,
            levels,
            ln_step: (1.0 + width_step).ln(),
            bin_d2,
            bin_of,
            stencil,
            t_hi,
            t_lo,
        }
    }

    /// The ladder; level 0 is the base kernel.
    pub fn levels(&self) -> &[Level] {
        &self.levels
    }

    /// Columns of padding the luminance rows need (the largest ring radius).
    pub fn pad(&self) -> usize {
        self.levels.iter().map(|l| l.shell).max().unwrap_or(0)
    }

    /// Rows either side the base test reads.
    pub fn xbar_reach(&self) -> usize {
        self.levels[0].shell
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

    /// Length of the ring-sum scratch a worker needs.
    pub fn scratch_len(&self) -> usize {
        self.bin_d2.len()
    }

    /// `xbar` at the base width for pixel `px` (row `y`), from mirrored,
    /// padded rows: the base-level stencil.
    #[inline]
    pub fn xbar0(&self, rows: &impl LumRows, px: usize, y: i64) -> f64 {
        let pad = self.pad() as i64;
        let mut acc = 0.0;
        let mut cur_dy = i32::MIN;
        let mut row: &[f64] = &[];
        for &(dx, dy, w) in &self.stencil {
            if dy != cur_dy {
                cur_dy = dy;
                row = rows.row(y + dy as i64);
            }
            acc += w * row[(px as i64 + pad + dx as i64) as usize];
        }
        acc
    }

    /// `xbar` at the base width for every pixel of row `y` (width `w`): the
    /// stencil with its rows fetched once.
    pub fn xbar0_row(&self, rows: &impl LumRows, y: i64, w: usize) -> Vec<f64> {
        let pad = self.pad();
        let sh = self.levels[0].shell as i64;
        let mut out = vec![0.0; w];
        for dy in -sh..=sh {
            let row = rows.row(y + dy);
            for &(dx, _, wt) in self.stencil.iter().filter(|t| t.1 as i64 == dy) {
                let off = (pad as i64 + dx as i64) as usize;
                for (o, &v) in out.iter_mut().zip(&row[off..off + w]) {
                    *o += wt * v;
                }
            }
        }
        out
    }

    /// Cheap path: is the sample noisy at the base width? Only the few that are
    /// go to [`EpGauss::search`].
    #[inline]
    pub fn is_noisy(&self, x0: f64, xbar: f64) -> bool {
        if !(x0 > 0.0 && xbar > 0.0) {
            return false;
        }
        let t = x0 / xbar;
        t.is_finite() && (t > self.t_hi || t < self.t_lo)
    }

    fn level_for(&self, rho: f64) -> usize {
        let last = self.levels.len() - 1;
        if !(rho > self.levels[0].rho) {
            return 0;
        }
        let k = ((rho / self.levels[0].rho).ln() / self.ln_step).ceil();
        if k.is_finite() && k < last as f64 {
            k as usize
        } else {
            last
        }
    }

    /// Find the width of a sample at pixel `(px, py)` with luminance `x0`
    /// that failed the base test against `xbar0`. `rs` is a zeroed scratch of
    /// [`EpGauss::scratch_len`]; it is zeroed again on return.
    pub fn search(
        &self,
        rows: &impl LumRows,
        px: usize,
        py: usize,
        x0: f64,
        xbar0: f64,
        rs: &mut [f64],
    ) -> Choice {
        let last = self.levels.len() - 1;
        if last == 0 {
            return Choice {
                level: 0,
                capped: true,
            };
        }
        let pad = self.pad() as i64;
        let (cx, cy) = (px as i64 + pad, py as i64);
        let mut grown: usize = 0; // shells 0..grown are in rs
        let mut grow = |to: usize, rs: &mut [f64]| {
            if to >= grown {
                self.add_shells(rows, cx, cy, grown, to, rs);
                grown = to + 1;
            }
        };
        let mut eval = |l: usize, rs: &mut [f64]| -> f64 {
            let lv = &self.levels[l];
            grow(lv.shell, rs);
            let dot: f64 = lv.ring_w.iter().zip(rs.iter()).map(|(w, s)| w * s).sum();
            let xbar = dot / lv.norm;
            if !(xbar > 0.0) || !xbar.is_finite() {
                return f64::INFINITY;
            }
            let t = x0 / xbar;
            if !t.is_finite() {
                return f64::INFINITY;
            }
            relation14(t, lv.w0)
        };

        let mut lo = 0usize;
        let mut d_lo = relation14(x0 / xbar0, self.levels[0].w0);
        let mut hi: Option<usize> = None;
        let mut guesses = 0;
        let choice = loop {
            match hi {
                Some(h) if h - lo <= 1 => {
                    break Choice {
                        level: h as u16,
                        capped: false,
                    }
                }
                None if lo == last => {
                    break Choice {
                        level: last as u16,
                        capped: true,
                    }
                }
                _ => {}
            }
            let upper = hi.map_or(last, |h| h - 1);
            let guess = if guesses < 3 && d_lo.is_finite() {
                // D_ar ~ w0 ~ 1/rho^2: the radius that would bring D_ar to the tolerance.
                self.level_for(self.levels[lo].rho * (d_lo / self.tol).sqrt())
            } else if hi.is_none() {
                self.level_for(2.0 * self.levels[lo].rho)
            } else {
                (lo + upper).div_ceil(2)
            };
            let cand = guess.clamp(lo + 1, upper);
            guesses += 1;
            let d = eval(cand, rs);
            if d <= self.tol {
                hi = Some(cand);
            } else {
                lo = cand;
                d_lo = d;
            }
        };
        let touched = 2 * grown.saturating_sub(1).pow(2);
        let end = (self.bin_of[touched.min(self.bin_of.len() - 1)] as usize + 1).min(rs.len());
        rs[..end].iter_mut().for_each(|x| *x = 0.0);
        choice
    }

    /// Add the box luminance of ring shells `g..=c` (Chebyshev radius) about
    /// padded column `cx`, row `cy` into the ring-sum bins, one row lookup per
    /// row: rows `|dy| >= g` are new over `-c..=c`, the others only where
    /// `|dx| >= g`.
    fn add_shells(
        &self,
        rows: &impl LumRows,
        cx: i64,
        cy: i64,
        g: usize,
        c: usize,
        rs: &mut [f64],
    ) {
        let (g, c) = (g as i64, c as i64);
        for dy in -c..=c {
            let r = rows.row(cy + dy);
            let dy2 = (dy * dy) as usize;
            let mut add = |dx: i64| {
                rs[self.bin_of[dy2 + (dx * dx) as usize] as usize] += r[(cx + dx) as usize];
            };
            if dy.abs() >= g {
                (-c..=c).for_each(&mut add);
            } else {
                (-c..=-g).chain(g..=c).for_each(&mut add);
            }
        }
    }

    /// The super-sampling factor.
    pub fn s(&self) -> usize {
        self.s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mirror;

    struct Field {
        h: usize,
        rows: Vec<Vec<f64>>,
    }
    impl Field {
        fn new(w: usize, h: usize, pad: usize, f: impl Fn(usize, usize) -> f64) -> Self {
            let rows = (0..h)
                .map(|y| {
                    (0..w + 2 * pad)
                        .map(|i| f(mirror(i as i64 - pad as i64, w), y))
                        .collect()
                })
                .collect();
            Field { h, rows }
        }
    }
    impl LumRows for Field {
        fn row(&self, vy: i64) -> &[f64] {
            &self.rows[mirror(vy, self.h)]
        }
    }

    #[test]
    fn base_weight_matches_the_issue() {
        let ep = EpGauss::new(3, 0.6, 16.0, 3.0, 0.25, 0.1);
        let w0 = ep.levels()[0].w0;
        assert!((w0 - 0.088).abs() < 0.001, "w0 = {w0}");
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
    fn lone_firefly_search_meets_tolerance_or_caps() {
        let ep = EpGauss::new(3, 0.6, 16.0, 3.0, 0.25, 0.1);
        let mut rs = vec![0.0; ep.scratch_len()];
        for &mag in &[10.0, 100.0, 1e3, 1e5] {
            let (w, h) = (120, 120);
            // Box luminance of the firefly's pixel: (8*1 + mag)/9.
            let f = Field::new(w, h, ep.pad(), |x, y| {
                if (x, y) == (60, 60) {
                    (8.0 + mag) / 9.0
                } else {
                    1.0
                }
            });
            let xb = ep.xbar0(&f, 60, 60);
            assert!(ep.is_noisy(mag, xb), "mag {mag}");
            let c = ep.search(&f, 60, 60, mag, xb, &mut rs);
            assert!(rs.iter().all(|&v| v == 0.0), "scratch must be cleared");
            let lv = &ep.levels()[c.level as usize];
            // Recompute D at the chosen level directly.
            let mut sum = 0.0;
            let mut norm = 0.0;
            let lim = 3.0 * lv.rho;
            for dy in -(lim as i64)..=(lim as i64) {
                for dx in -(lim as i64)..=(lim as i64) {
                    let d2 = (dx * dx + dy * dy) as f64;
                    if d2 <= lim * lim {
                        let g = (-d2 / (lv.rho * lv.rho)).exp();
                        sum += g * f.row(60 + dy)[(60 + dx + ep.pad() as i64) as usize];
                        norm += g;
                    }
                }
            }
            let d = relation14(mag / (sum / norm), lv.w0);
            if c.capped {
                assert!(d > 0.25 && c.level as usize == ep.levels().len() - 1);
            } else {
                assert!(d <= 0.25, "mag {mag}: D = {d}");
                // and one rung narrower fails (the search found the edge)
                let below = &ep.levels()[c.level as usize - 1];
                assert!(below.rho < lv.rho);
            }
        }
    }

    #[test]
    fn rings_grown_in_steps_equal_rings_grown_at_once() {
        let ep = EpGauss::new(3, 0.6, 6.0, 3.0, 0.25, 0.1);
        let f = Field::new(50, 45, ep.pad(), |x, y| {
            ((x * 7919 + y * 104_729) % 1000) as f64 * 0.01 + 0.5
        });
        let (cx, cy) = (20 + ep.pad() as i64, 22);
        let mut once = vec![0.0; ep.scratch_len()];
        ep.add_shells(&f, cx, cy, 0, 14, &mut once);
        for steps in [vec![0, 1, 2, 14], vec![3, 9, 14], vec![0, 13, 14]] {
            let mut stepped = vec![0.0; ep.scratch_len()];
            let mut g = 0;
            for to in steps {
                ep.add_shells(&f, cx, cy, g, to, &mut stepped);
                g = to + 1;
            }
            for (a, b) in once.iter().zip(&stepped) {
                assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0), "{a} vs {b}");
            }
        }
        // and the bins hold every point of the square exactly once
        let total: f64 = once.iter().sum();
        let mut direct = 0.0;
        for dy in -14..=14 {
            for dx in -14..=14 {
                direct += f.row(cy + dy)[(cx + dx) as usize];
            }
        }
        assert!((total - direct).abs() < 1e-9 * direct);
    }

    #[test]
    fn zero_tolerance_goes_to_the_cap() {
        let ep = EpGauss::new(3, 0.6, 4.0, 3.0, 0.0, 0.1);
        let mut rs = vec![0.0; ep.scratch_len()];
        let f = Field::new(40, 40, ep.pad(), |x, y| 1.0 + 0.01 * ((x + y) % 3) as f64);
        let xb = ep.xbar0(&f, 20, 20);
        let c = ep.search(&f, 20, 20, 1.5, xb, &mut rs);
        assert!(c.capped);
    }
}
