//! `epfilt restore`'s rules: put the energy of one image (`e`, the render or
//! epfilt's output of it) back into another (`d`, a denoiser's output), so
//! that every block of `--scale` pixels and the whole hold `e`'s energy
//! exactly while the picture stays the denoiser's.
//!
//! Two parts, per channel:
//!
//! 1. **What the denoiser lost, kept in place.** Where one pixel of `e`
//!    holds more than [`KEEP_GAIN`] times what the denoiser put around it
//!    (`q`, the denoiser's shape `s = max(d, 0)` under a Gaussian of
//!    [`KEEP_SIGMA`] pixels), the excess `l` stays where it is: a lamp,
//!    a bulb or a highlight the denoiser dimmed or removed. Where the
//!    denoiser has nothing at all (`q = 0`), all of `e` stays.
//! 2. **The rest in the denoiser's shape.** `a = e - l` is carried by the
//!    denoiser's picture times a smooth field: `r = s f g + l`, where `f`
//!    interpolates one coefficient per block bilinearly between block
//!    centres, solved so that each block's `Σ s f` is close to its `Σ a`,
//!    and `g` is the last, exact step: per block, `Σ a / Σ s f`. With the
//!    field solved, `g` is within a fraction of a percent of one (no seams);
//!    it makes every block's energy, and so the total, `e`'s to the rounding
//!    of f64 sums. A block where the denoiser has no light keeps `e`.

/// Most one pixel's energy may exceed what the denoiser put around it
/// before the excess is kept in place: sixteen times the denoiser's energy
/// there, weighted by the kernel's centre (a lamp the denoiser dimmed is
/// thousands of times over; grain in the energy image stays below it).
pub const KEEP_GAIN: f64 = 16.0;

/// The standard deviation (pixels) of the Gaussian that measures what the
/// denoiser put around a pixel: a few pixels, the size of the features a
/// denoiser removes as noise.
pub const KEEP_SIGMA: f64 = 2.0;

/// Kernel radius in units of its standard deviation: the weight beyond is
/// below 1.2% of the centre's.
pub const REACH_SIGMAS: f64 = 3.0;

/// The default `--scale`: blocks of 32 x 32 pixels (a lighting study's
/// region; the denoiser's look within it).
pub const DEFAULT_SCALE: usize = 32;

/// Largest `--scale`: a block's rows are held in memory.
pub const MAX_SCALE: usize = 4096;

/// Jacobi iterations of the field's solve: each brings every block's sum
/// closer to its target by the share its own coefficient carries (about
/// half); twenty leave `g` within about 1e-3 of one where the denoiser's
/// picture is smooth.
pub const FIELD_ITERATIONS: usize = 20;

/// A checked `--scale` (pixels per block side).
pub fn check_scale(scale: usize) -> Result<usize, String> {
    if (2..=MAX_SCALE).contains(&scale) {
        Ok(scale)
    } else {
        Err(format!(
            "--scale must be a block side of 2 to {MAX_SCALE} pixels, not {scale}"
        ))
    }
}

/// The normalised 1-D Gaussian of standard deviation `sigma` pixels,
/// `2r + 1` taps with `r = ceil(3 sigma)`.
pub fn taps(sigma: f64) -> Vec<f64> {
    let r = ((REACH_SIGMAS * sigma).ceil() as usize).max(1);
    let w: Vec<f64> = (0..=2 * r)
        .map(|i| {
            let d = i as f64 - r as f64;
            (-0.5 * d * d / (sigma * sigma)).exp()
        })
        .collect();
    let sum: f64 = w.iter().sum();
    w.into_iter().map(|v| v / sum).collect()
}

/// Position `p` of a row `n` long, reflected at its ends (half-sample
/// symmetric: `-1` is `0`, `n` is `n - 1`), as often as needed.
#[inline]
pub fn reflect(p: isize, n: usize) -> usize {
    let n = n as isize;
    let m = p.rem_euclid(2 * n);
    (if m < n { m } else { 2 * n - 1 - m }) as usize
}

/// The denoiser's value as a shape: its negative and non-finite values are
/// nothing to shape energy with.
#[inline]
pub fn shape(d: f32) -> f64 {
    if d.is_finite() && d > 0.0 {
        f64::from(d)
    } else {
        0.0
    }
}

/// The part of energy `e` kept in place, where the denoiser's own value is
/// `own` and `q()` measures what it put around (the shape under the 2-D
/// kernel whose centre weight is `centre`, so `q >= centre own`): nothing
/// within [`KEEP_GAIN`] times the denoiser's own value (then within it of
/// its share around, and `q` is never measured: the common case), else the
/// excess over that gain on its share around, all of it where the denoiser
/// has nothing, and negative energy (a render's rare negative samples:
/// nothing to scale a shape by).
#[inline]
pub fn kept(e: f64, own: f64, q: impl FnOnce() -> f64, centre: f64) -> f64 {
    if e <= 0.0 {
        return e;
    }
    if e <= KEEP_GAIN * own {
        return 0.0;
    }
    let q = q();
    if q <= 0.0 {
        return e;
    }
    (e - KEEP_GAIN * q / centre).max(0.0)
}

/// Where pixel `p` of a line `n` long lies between the centres of blocks
/// of `b`: the two blocks' indices and weights (`w0 + w1 = 1`; one block
/// with weight one before the first centre and after the last).
#[inline]
pub fn tent(p: usize, n: usize, b: usize) -> (usize, usize, f64, f64) {
    let nb = n.div_ceil(b);
    let c = (p as f64 + 0.5) / b as f64 - 0.5;
    if c <= 0.0 {
        return (0, 0, 1.0, 0.0);
    }
    let i0 = c.floor() as usize;
    if i0 + 1 >= nb {
        return (nb - 1, nb - 1, 1.0, 0.0);
    }
    let w1 = c - i0 as f64;
    (i0, i0 + 1, 1.0 - w1, w1)
}

/// The field of one channel: per block, its target (`Σ a`), its moments
/// (`Σ s φ_k` over its pixels for the tents `φ_k` of its 3 x 3 neighbours)
/// and its coefficient.
#[derive(Clone, Debug)]
pub struct BlockField {
    /// Block side, pixels.
    pub b: usize,
    /// Blocks per row and per column.
    pub nbx: usize,
    /// Blocks per column.
    pub nby: usize,
    /// `Σ a` per block.
    pub target: Vec<f64>,
    /// Moments per block, neighbour `(dj + 1) * 3 + (di + 1)`.
    pub moments: Vec<[f64; 9]>,
    /// Coefficients, once solved.
    pub rho: Vec<f64>,
}

impl BlockField {
    /// An empty field for a `w x h` image in blocks of `b`.
    pub fn new(w: usize, h: usize, b: usize) -> Self {
        let (nbx, nby) = (w.div_ceil(b), h.div_ceil(b));
        BlockField {
            b,
            nbx,
            nby,
            target: vec![0.0; nbx * nby],
            moments: vec![[0.0; 9]; nbx * nby],
            rho: vec![0.0; nbx * nby],
        }
    }

    /// Add row `y` (`w` wide; `h` rows in all) of shape `s` and rest `a`
    /// into a row of block sums `(target, moments)` of `nbx` blocks.
    pub fn row_sums(&self, y: usize, h: usize, s: &[f64], a: &[f64], out: &mut [(f64, [f64; 9])]) {
        let w = s.len();
        let (j0, j1, wy0, wy1) = tent(y, h, self.b);
        let jb = y / self.b;
        for x in 0..w {
            let ib = x / self.b;
            let o = &mut out[ib];
            o.0 += a[x];
            if s[x] == 0.0 {
                continue;
            }
            let (i0, i1, wx0, wx1) = tent(x, w, self.b);
            for (j, wy) in [(j0, wy0), (j1, wy1)] {
                for (i, wx) in [(i0, wx0), (i1, wx1)] {
                    let k = (j + 1 - jb) * 3 + (i + 1 - ib);
                    o.1[k] += s[x] * wx * wy;
                }
            }
        }
    }

    /// The block sums of `Σ s f` the coefficients give.
    fn reached(&self, rho: &[f64], bi: usize, bj: usize) -> f64 {
        let m = &self.moments[bj * self.nbx + bi];
        let mut r = 0.0;
        for dj in 0..3 {
            for di in 0..3 {
                let (i, j) = ((bi + di).wrapping_sub(1), (bj + dj).wrapping_sub(1));
                if m[dj * 3 + di] != 0.0 && i < self.nbx && j < self.nby {
                    r += rho[j * self.nbx + i] * m[dj * 3 + di];
                }
            }
        }
        r
    }

    /// Solve for the coefficients: each block's own ratio first, then
    /// [`FIELD_ITERATIONS`] multiplicative Jacobi steps (deterministic: each
    /// step reads only the last). A block whose denoiser shape is empty
    /// keeps a coefficient of zero (its energy stays in place).
    pub fn solve(&mut self) {
        let n = self.nbx * self.nby;
        for k in 0..n {
            let s: f64 = self.moments[k].iter().sum();
            self.rho[k] = if s > 0.0 && self.target[k] > 0.0 {
                self.target[k] / s
            } else {
                0.0
            };
        }
        let mut next = self.rho.clone();
        for _ in 0..FIELD_ITERATIONS {
            for (k, nk) in next.iter_mut().enumerate() {
                let (bi, bj) = (k % self.nbx, k / self.nbx);
                let r = self.reached(&self.rho, bi, bj);
                *nk = if r > 0.0 && self.rho[k] > 0.0 {
                    self.rho[k] * self.target[k] / r
                } else {
                    self.rho[k]
                };
            }
            std::mem::swap(&mut self.rho, &mut next);
        }
    }

    /// The field along row `y` (`h` rows in all), `out.len()` wide.
    pub fn row(&self, y: usize, h: usize, out: &mut [f64]) {
        let w = out.len();
        let (j0, j1, wy0, wy1) = tent(y, h, self.b);
        let (r0, r1) = (
            &self.rho[j0 * self.nbx..(j0 + 1) * self.nbx],
            &self.rho[j1 * self.nbx..(j1 + 1) * self.nbx],
        );
        for (x, o) in out.iter_mut().enumerate() {
            let (i0, i1, wx0, wx1) = tent(x, w, self.b);
            *o = wy0 * (wx0 * r0[i0] + wx1 * r0[i1]) + wy1 * (wx0 * r1[i0] + wx1 * r1[i1]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sums of a few dozen f64 terms agree to a few units in the last place.
    const SUM_TOL: f64 = 1e-12;

    #[test]
    fn taps_are_a_normalised_symmetric_gaussian() {
        for s in [0.3, 1.0, 2.0, 4.5] {
            let t = taps(s);
            assert!((t.iter().sum::<f64>() - 1.0).abs() < SUM_TOL);
            for i in 0..t.len() {
                assert_eq!(t[i], t[t.len() - 1 - i]);
            }
        }
    }

    #[test]
    fn reflect_is_half_sample_symmetric() {
        let got: Vec<usize> = (-4..8).map(|p| reflect(p, 3)).collect();
        assert_eq!(got, vec![2, 2, 1, 0, 0, 1, 2, 2, 1, 0, 0, 1]);
    }

    /// The tents are a partition of unity, each pixel between the centres
    /// of its own block and a neighbour.
    #[test]
    fn tents_sum_to_one_and_stay_beside_the_block() {
        for (n, b) in [(100, 32), (7, 2), (64, 64), (5, 8)] {
            for p in 0..n {
                let (i0, i1, w0, w1) = tent(p, n, b);
                assert!((w0 + w1 - 1.0).abs() < SUM_TOL && w0 >= 0.0 && w1 >= 0.0);
                assert!(i0 + 1 >= p / b && i1 <= p / b + 1 && i1 < n.div_ceil(b));
            }
        }
    }

    #[test]
    fn kept_is_the_excess_over_the_denoisers_share() {
        let never = || -> f64 { panic!("q measured where the own value settles it") };
        assert_eq!(kept(1.0, 1.0, never, 0.04), 0.0);
        assert_eq!(kept(-2.0, 1.0, never, 0.04), -2.0);
        assert_eq!(kept(3.0, 0.0, || 0.0, 0.04), 3.0);
        // A lamp the denoiser dimmed to a glow: q around, little of its own.
        let l = kept(1000.0, 0.5, || 0.05, 0.04);
        assert!((l - (1000.0 - KEEP_GAIN * 0.05 / 0.04)).abs() < SUM_TOL * 1000.0);
        assert_eq!(kept(10.0, 0.5, || 1.0, 0.04), 0.0);
    }

    /// On a smooth shape the solved field reaches every block's target
    /// closely, and a flat image that was right stays (coefficients one).
    #[test]
    fn the_field_reaches_the_block_targets() {
        let (w, h, b) = (40, 30, 8);
        let shape = |x: usize, y: usize| 1.0 + 0.5 * ((x + 2 * y) as f64 * 0.15).sin();
        let energy = |x: usize, y: usize| shape(x, y) * (1.0 + 0.3 * (x as f64 / 40.0));
        for (e, flat) in [
            (&energy as &dyn Fn(usize, usize) -> f64, false),
            (&shape, true),
        ] {
            let mut f = BlockField::new(w, h, b);
            for y in 0..h {
                let s: Vec<f64> = (0..w).map(|x| shape(x, y)).collect();
                let a: Vec<f64> = (0..w).map(|x| e(x, y)).collect();
                let mut row = vec![(0.0, [0.0; 9]); f.nbx];
                f.row_sums(y, h, &s, &a, &mut row);
                for (k, (t, m)) in row.into_iter().enumerate() {
                    let at = (y / b) * f.nbx + k;
                    f.target[at] += t;
                    for (acc, v) in f.moments[at].iter_mut().zip(m) {
                        *acc += v;
                    }
                }
            }
            f.solve();
            let mut got = vec![0.0; f.nbx * f.nby];
            let mut fr = vec![0.0; w];
            for y in 0..h {
                f.row(y, h, &mut fr);
                for x in 0..w {
                    got[(y / b) * f.nbx + x / b] += shape(x, y) * fr[x];
                }
            }
            for (k, g) in got.iter().enumerate() {
                let rel = (g / f.target[k] - 1.0).abs();
                assert!(rel < 2e-3, "block {k}: {rel}");
                if flat {
                    assert!((f.rho[k] - 1.0).abs() < 1e-9, "{}", f.rho[k]);
                }
            }
        }
    }

    #[test]
    fn scale_is_checked() {
        assert!(check_scale(32).is_ok());
        for bad in [0, 1, MAX_SCALE + 1] {
            assert!(check_scale(bad).is_err(), "{bad}");
        }
    }
}
