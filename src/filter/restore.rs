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
//!    denoiser's picture and a smooth field: `r = (s + t (f - 1)) g + l`,
//!    where `t` is the carrier ([`FieldRows::carrier`]: `s^2 / m` where the
//!    blocks need more energy, `m` the block means of `s`; `s` where they
//!    need less; bilinear between block centres), `f`
//!    interpolates one coefficient per block bilinearly between block
//!    centres, solved so that each block's `Σ (s + t (f - 1))` (never
//!    below zero per pixel) is close to its `Σ a`, and `g` is the last, exact step: per block, `Σ a` over
//!    that sum. Where the shape is flat (`t = s`) this is `s f g`; what a
//!    block lacks goes back mostly to the pixels brighter than their
//!    surroundings, where a denoiser dims and spreads light.
//!    With the field solved, `g` is close to one (no visible seams); it
//!    makes every block's energy, and so the total, `e`'s to the rounding
//!    of f64 sums. A block where the denoiser has no light keeps `e`.

/// Most one pixel of a render may exceed what the denoiser put around it
/// before the excess is kept in place: sixteen times the denoiser's energy
/// there, weighted by the kernel's centre (a lamp the denoiser dimmed is
/// thousands of times over; a render's fireflies, which the denoiser
/// rightly removed, mostly stay below it).
pub const KEEP_GAIN: f64 = 16.0;

/// The same for an energy image epfilt's ep-gauss or ep-box made: its
/// fireflies are already spread, so what still exceeds the denoiser's share
/// around a pixel is a feature the denoiser dimmed (bulbs' cores, lamps),
/// kept in place instead of scaling the block around it through the field.
/// Of the gains 1, 1.5, 2 and 3 on the lab's renders, 1 gave the least
/// error over the denoiser's (docs/bench/oidn.md has the one chosen).
pub const KEEP_GAIN_FILTERED: f64 = 1.0;

/// The gain for the energy image's emission guide (the directly visible
/// emission a renderer writes beside the beauty): emission is never a
/// firefly, so all of it that exceeds the denoiser's share around a pixel
/// stays in place, as on epfilt's output; the rest of the pixel's energy
/// then meets the image's own gain.
pub const EMISSION_KEEP_GAIN: f64 = 1.0;

/// Where the energy image is a render with a variance pass and no emission
/// guide, a pixel whose mean lies more than three of its standard errors
/// above zero (relative standard error under this) is light its samples saw
/// again and again, a bulb or a lit edge, and is kept as the emission guide
/// is: a firefly, one hit among `n` samples, has a relative standard error
/// near one (`sqrt((n - k) / (k n))` for `k` hits). On the fairy lights at
/// 64 spp (no guide passes) this took restore from 1.27x OIDN's error to
/// 1.00x; 0.25 to 0.5 gave the same there.
pub const RELIABLE_RSE: f64 = 1.0 / 3.0;

/// The gains `--keep-gain` takes: at least one (below, the denoiser's own
/// energy would be kept), at most a million (above, nothing is kept).
pub const KEEP_GAIN_RANGE: std::ops::RangeInclusive<f64> = 1.0..=1e6;

/// What a restore is asked for: the blocks' side and the keep gain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RestoreParams {
    /// The side of the blocks whose energy is kept, pixels.
    pub scale: usize,
    /// [`KEEP_GAIN`] or [`KEEP_GAIN_FILTERED`], or the user's.
    pub keep_gain: f64,
}

impl RestoreParams {
    /// Checked: the scale by [`check_scale`], the gain within
    /// [`KEEP_GAIN_RANGE`].
    pub fn check(self) -> Result<Self, String> {
        check_scale(self.scale)?;
        if !KEEP_GAIN_RANGE.contains(&self.keep_gain) {
            return Err(format!(
                "--keep-gain must be from {} to {}, not {}",
                KEEP_GAIN_RANGE.start(),
                KEEP_GAIN_RANGE.end(),
                self.keep_gain
            ));
        }
        Ok(self)
    }
}

/// The standard deviation (pixels) of the Gaussian that measures what the
/// denoiser put around a pixel: a few pixels, the size of the features a
/// denoiser removes as noise.
pub const KEEP_SIGMA: f64 = 2.0;

/// Kernel radius in units of its standard deviation: three, where what is
/// cut off no longer changes what the denoiser put around a pixel enough
/// to matter for a gain of [`KEEP_GAIN`].
pub const REACH_SIGMAS: f64 = 3.0;

/// The default `--scale`: blocks of 32 x 32 pixels (a lighting study's
/// region; the denoiser's look within it).
pub const DEFAULT_SCALE: usize = 32;

/// Largest `--scale`: a block's rows are held in memory.
pub const MAX_SCALE: usize = 4096;

/// Jacobi iterations of the field's solve: each brings every block's sum
/// closer to its target by the share its own coefficient carries (about
/// half of a block's sum), so the error shrinks geometrically and a few
/// dozen steps leave `g` close to one; the unit test bounds what is left.
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
/// within `gain` times the denoiser's own value (then within it of
/// its share around, and `q` is never measured: the common case), else the
/// excess over that gain on its share around, all of it where the denoiser
/// has nothing, and negative energy (a render's rare negative samples:
/// nothing to scale a shape by).
#[inline]
pub fn kept(e: f64, own: f64, q: impl FnOnce() -> f64, centre: f64, gain: f64) -> f64 {
    if e <= 0.0 {
        return e;
    }
    if e <= gain * own {
        return 0.0;
    }
    let q = q();
    if q <= 0.0 {
        return e;
    }
    (e - gain * q / centre).max(0.0)
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

/// Block rows the field looks ahead when it fixes a row's coefficients:
/// each block couples only to its neighbours, and what a block row two
/// below does to this one is a few percent of a few percent.
pub const LOOKAHEAD: usize = 2;

/// One row of blocks of the field: per block its target (`Σ a`), its
/// shape (`Σ s`, whose mean sets the carrier's scale), its carrier's sum
/// (`Σ t`) and moments (`Σ t φ_k` over its pixels for the tents `φ_k` of
/// its 3 x 3 neighbours, `(dj + 1) * 3 + (di + 1)`) and, once fixed, its
/// coefficient.
#[derive(Clone, Debug)]
struct BlockRow {
    target: Vec<f64>,
    shape: Vec<f64>,
    carried: Vec<f64>,
    moments: Vec<[f64; 9]>,
    /// Once the row is summed, per block: the mean of `s`, and 1 where it
    /// needs more energy than the denoiser gave (`Σ a > Σ s`), else 0.
    means: Vec<(f64, f64)>,
    rho: Option<Vec<f64>>,
}

impl BlockRow {
    fn new(nbx: usize) -> Self {
        BlockRow {
            target: vec![0.0; nbx],
            shape: vec![0.0; nbx],
            carried: vec![0.0; nbx],
            moments: vec![[0.0; 9]; nbx],
            means: Vec::new(),
            rho: None,
        }
    }

    /// What block `i`'s field must carry: `r = s + t (f - 1)` sums to
    /// `Σ a` where `Σ t f = Σ a - Σ s + Σ t`.
    fn goal(&self, i: usize) -> f64 {
        self.target[i] - self.shape[i] + self.carried[i]
    }
}

/// The field of one channel over a `w x h` image in blocks of `b`, held a
/// few rows of blocks at a time. Each pixel row is added twice, in order:
/// its block sums of the rest and the shape ([`FieldRows::add`]), then,
/// once the block row below is summed (the carrier reads the block means
/// around it), its carrier's moments ([`FieldRows::add_moments`]). A row's
/// coefficients are fixed once the rows [`LOOKAHEAD`] below it have their
/// moments ([`FieldRows::fix`]), and rows no longer read are dropped
/// ([`FieldRows::release`]).
#[derive(Clone, Debug)]
pub struct FieldRows {
    /// Block side, pixels.
    pub b: usize,
    w: usize,
    h: usize,
    /// Blocks per row.
    pub nbx: usize,
    /// Blocks per column.
    pub nby: usize,
    /// The block row of `rows[0]`.
    first: usize,
    rows: std::collections::VecDeque<BlockRow>,
    /// [`tent`] of every column.
    tents_x: Vec<(usize, usize, f64, f64)>,
}

impl FieldRows {
    /// An empty field for a `w x h` image in blocks of `b`.
    pub fn new(w: usize, h: usize, b: usize) -> Self {
        FieldRows {
            b,
            w,
            h,
            nbx: w.div_ceil(b),
            nby: h.div_ceil(b),
            first: 0,
            rows: Default::default(),
            tents_x: (0..w).map(|x| tent(x, w, b)).collect(),
        }
    }

    /// Row `y`'s rest `a` and shape `s` as block sums `(Σ a, Σ s)` of
    /// `nbx` blocks into `out` (zeroed by the caller).
    pub fn row_sums(&self, s: &[f64], a: &[f64], out: &mut [(f64, f64)]) {
        let cols = s.chunks(self.b).zip(a.chunks(self.b));
        for (o, (s, a)) in out.iter_mut().zip(cols) {
            for (&sx, &ax) in s.iter().zip(a) {
                o.0 += ax;
                o.1 += sx;
            }
        }
    }

    /// Add row `y`'s block sums (rows come in order).
    pub fn add(&mut self, y: usize, sums: &[(f64, f64)]) {
        let (b, w, h) = (self.b, self.w, self.h);
        let jb = y / b;
        let row = self.block_row(jb);
        for (i, (a, s)) in sums.iter().enumerate() {
            row.target[i] += a;
            row.shape[i] += s;
        }
        if y + 1 == ((jb + 1) * b).min(h) {
            let bh = b.min(h - jb * b);
            row.means = (row.shape.iter().zip(&row.target).enumerate())
                .map(|(i, (&s, &a))| {
                    let n = (b.min(w - i * b) * bh) as f64;
                    (s / n, if a > s { 1.0 } else { 0.0 })
                })
                .collect();
        }
    }

    fn block_row(&mut self, jb: usize) -> &mut BlockRow {
        while self.first + self.rows.len() <= jb {
            self.rows.push_back(BlockRow::new(self.nbx));
        }
        &mut self.rows[jb - self.first]
    }

    /// Pixel rows whose carrier can be measured once `summed` rows are
    /// added: those of every block row whose next one is complete.
    pub fn moments_to(&self, summed: usize) -> usize {
        if summed >= self.h {
            return self.h;
        }
        (summed / self.b).saturating_sub(1) * self.b
    }

    /// The carrier `t` along pixel row `y`, `s` its shape: `s^2 / m` where
    /// the blocks need more energy than the denoiser gave (`Σ a > Σ s`),
    /// `s` where they need less, bilinear between block centres as the
    /// field is (`m` the block means of `s`; zero where either is). A
    /// denoiser loses energy at its brightest features (it dims and spreads
    /// them), so what a block lacks goes back mostly to the pixels brighter
    /// than their surroundings; a surplus comes off in proportion, so no
    /// highlight is dimmed more than its block. Where the shape is flat
    /// (`s = m`) both are `s`.
    pub fn carrier(&self, y: usize, s: &[f64], t: &mut [f64]) {
        let (j0, j1, wy0, wy1) = tent(y, self.h, self.b);
        let means = |j: usize| &self.rows[j - self.first].means;
        let (r0, r1) = (means(j0), means(j1));
        // Block by block: the means and choices of its row's neighbours
        // blended down the column once, then across per pixel.
        let down = |i: usize| {
            let (a, b) = (r0[i], r1[i]);
            (wy0 * a.0 + wy1 * b.0, wy0 * a.1 + wy1 * b.1)
        };
        let cols = (t.chunks_mut(self.b).zip(s.chunks(self.b))).zip(self.tents_x.chunks(self.b));
        for (ib, ((t, s), tents)) in cols.enumerate() {
            let v = [ib.wrapping_sub(1), ib, ib + 1].map(|i| {
                if i < self.nbx {
                    down(i)
                } else {
                    (0.0, 0.0)
                }
            });
            if v.iter().all(|v| v.1 == 0.0) {
                // Every block around needs less: the shape itself.
                t.copy_from_slice(s);
                continue;
            }
            for ((t, &sx), &(i0, i1, wx0, wx1)) in t.iter_mut().zip(s).zip(tents) {
                let (a, b) = (v[i0 + 1 - ib], v[i1 + 1 - ib]);
                let m = wx0 * a.0 + wx1 * b.0;
                let more = wx0 * a.1 + wx1 * b.1;
                *t = if sx > 0.0 && m > 0.0 {
                    sx * (1.0 - more + more * sx / m)
                } else {
                    0.0
                };
            }
        }
    }

    /// Row `y`'s carrier `t` as block sums `(Σ t, moments)` of `nbx`
    /// blocks into `out` (zeroed by the caller).
    pub fn moment_sums(&self, y: usize, t: &[f64], out: &mut [(f64, [f64; 9])]) {
        let (j0, j1, wy0, wy1) = tent(y, self.h, self.b);
        let jb = y / self.b;
        let (k0, k1) = ((j0 + 1 - jb) * 3, (j1 + 1 - jb) * 3);
        // Block by block (no division per pixel); each moment takes
        // `(t wx) wy`.
        let cols = t.chunks(self.b).zip(self.tents_x.chunks(self.b));
        for (ib, (t, tents)) in cols.enumerate().take(self.nbx) {
            let o = &mut out[ib];
            for (&tx, &(i0, i1, wx0, wx1)) in t.iter().zip(tents) {
                if tx == 0.0 {
                    continue;
                }
                o.0 += tx;
                let (c0, c1) = (i0 + 1 - ib, i1 + 1 - ib);
                let (t0, t1) = (tx * wx0, tx * wx1);
                o.1[k0 + c0] += t0 * wy0;
                o.1[k0 + c1] += t1 * wy0;
                o.1[k1 + c0] += t0 * wy1;
                o.1[k1 + c1] += t1 * wy1;
            }
        }
    }

    /// Add row `y`'s carrier sums (rows come in order).
    pub fn add_moments(&mut self, y: usize, sums: &[(f64, [f64; 9])]) {
        let row = self.block_row(y / self.b);
        for (i, (t, m)) in sums.iter().enumerate() {
            row.carried[i] += t;
            for (acc, v) in row.moments[i].iter_mut().zip(m) {
                *acc += v;
            }
        }
    }

    /// Whether block row `j` can be fixed once the pixel rows below
    /// `rows_done` have their moments: the rows [`LOOKAHEAD`] below it are
    /// complete.
    pub fn can_fix(&self, j: usize, rows_done: usize) -> bool {
        let last = (j + LOOKAHEAD).min(self.nby - 1);
        rows_done >= ((last + 1) * self.b).min(self.h)
    }

    /// Fix block row `j`'s coefficients (the row above fixed, the rows
    /// [`LOOKAHEAD`] below with their moments): each block's own ratio
    /// first, then
    /// [`FIELD_ITERATIONS`] multiplicative Jacobi steps over the rows `j` to
    /// `j + LOOKAHEAD`, the row above as fixed and the row after the last
    /// taken as the last. A block whose denoiser shape is empty keeps a
    /// coefficient of zero (its energy stays in place).
    pub fn fix(&mut self, j: usize) {
        let k0 = j - self.first;
        if self.rows[k0].rho.is_some() {
            return;
        }
        let nbx = self.nbx;
        let end = (j + LOOKAHEAD).min(self.nby - 1) - self.first;
        let own = |r: &BlockRow| -> Vec<f64> {
            (0..nbx)
                .map(|i| {
                    let s: f64 = r.moments[i].iter().sum();
                    if s > 0.0 && r.goal(i) > 0.0 {
                        r.goal(i) / s
                    } else {
                        0.0
                    }
                })
                .collect()
        };
        let mut free: Vec<Vec<f64>> = (k0..=end).map(|k| own(&self.rows[k])).collect();
        let above = (k0 > 0).then(|| self.rows[k0 - 1].rho.clone()).flatten();
        let mut next = free.clone();
        for _ in 0..FIELD_ITERATIONS {
            for (f, row) in next.iter_mut().enumerate() {
                let br = &self.rows[k0 + f];
                let m = &br.moments;
                let rho_of = |dj: usize| -> Option<&Vec<f64>> {
                    match (f + dj).checked_sub(1) {
                        None => above.as_ref(),
                        Some(g) => free.get(g.min(free.len() - 1)),
                    }
                };
                for (i, v) in row.iter_mut().enumerate() {
                    let mut reached = 0.0;
                    for dj in 0..3 {
                        let Some(r) = rho_of(dj) else { continue };
                        for di in 0..3 {
                            let ii = (i + di).wrapping_sub(1);
                            let mk = m[i][dj * 3 + di];
                            if mk != 0.0 && ii < nbx {
                                reached += r[ii] * mk;
                            }
                        }
                    }
                    let cur = free[f][i];
                    *v = if reached > 0.0 && cur > 0.0 {
                        cur * br.goal(i) / reached
                    } else {
                        cur
                    };
                }
            }
            std::mem::swap(&mut free, &mut next);
        }
        self.rows[k0].rho = free.into_iter().next();
    }

    /// The target of block `i` of block row `j`.
    pub fn target(&self, j: usize, i: usize) -> f64 {
        self.rows[j - self.first].target[i]
    }

    /// The field along pixel row `y` (its block rows fixed), `w` wide.
    pub fn row(&self, y: usize, out: &mut [f64]) {
        let (j0, j1, wy0, wy1) = tent(y, self.h, self.b);
        let fixed = |j: usize| self.rows[j - self.first].rho.as_deref().unwrap_or(&[]);
        let (r0, r1) = (fixed(j0), fixed(j1));
        for (o, &(i0, i1, wx0, wx1)) in out.iter_mut().zip(&self.tents_x) {
            *o = wy0 * (wx0 * r0[i0] + wx1 * r0[i1]) + wy1 * (wx0 * r1[i0] + wx1 * r1[i1]);
        }
    }

    /// Block rows below `j` are no longer read.
    pub fn release(&mut self, j: usize) {
        while self.first < j && !self.rows.is_empty() {
            self.rows.pop_front();
            self.first += 1;
        }
    }

    /// Block rows held at most is bounded by the lookahead; this many now.
    pub fn held(&self) -> usize {
        self.rows.len()
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
        let g = KEEP_GAIN;
        assert_eq!(kept(1.0, 1.0, never, 0.04, g), 0.0);
        assert_eq!(kept(-2.0, 1.0, never, 0.04, g), -2.0);
        assert_eq!(kept(3.0, 0.0, || 0.0, 0.04, g), 3.0);
        // A lamp the denoiser dimmed to a glow: q around, little of its own.
        let l = kept(1000.0, 0.5, || 0.05, 0.04, g);
        assert!((l - (1000.0 - g * 0.05 / 0.04)).abs() < SUM_TOL * 1000.0);
        assert_eq!(kept(10.0, 0.5, || 1.0, 0.04, g), 0.0);
        // A bulb's core at five times the denoiser's: within the render's
        // gain, kept over an epfilt output's (beyond its share around).
        assert_eq!(kept(5.0, 1.0, never, 0.04, g), 0.0);
        let l = kept(5.0, 1.0, || 0.06, 0.04, KEEP_GAIN_FILTERED);
        assert!((l - (5.0 - KEEP_GAIN_FILTERED * 0.06 / 0.04)).abs() < SUM_TOL * 5.0);
    }

    #[test]
    fn params_check_the_scale_and_the_gain() {
        let p = |scale, keep_gain| RestoreParams { scale, keep_gain }.check();
        assert!(p(32, KEEP_GAIN).is_ok() && p(2, 1.0).is_ok() && p(4096, 1e6).is_ok());
        for (scale, gain) in [
            (1, 16.0),
            (32, 0.5),
            (32, f64::NAN),
            (32, f64::INFINITY),
            (32, 2e6),
        ] {
            assert!(p(scale, gain).is_err(), "{scale} {gain}");
        }
    }

    /// On a smooth shape the fixed field reaches every block's target
    /// closely, and a flat image that was right stays (coefficients one).
    #[test]
    fn the_field_reaches_the_block_targets() {
        let (w, h, b) = (40, 70, 8);
        let shape = |x: usize, y: usize| 1.0 + 0.5 * ((x + 2 * y) as f64 * 0.15).sin();
        let energy = |x: usize, y: usize| shape(x, y) * (1.0 + 0.3 * (x as f64 / 40.0));
        let s_row = |y: usize| -> Vec<f64> { (0..w).map(|x| shape(x, y)).collect() };
        for (e, flat) in [
            (&energy as &dyn Fn(usize, usize) -> f64, false),
            (&shape, true),
        ] {
            let mut f = FieldRows::new(w, h, b);
            let (mut fixed_to, mut momented) = (0, 0);
            let mut got = vec![0.0; f.nbx * f.nby];
            let mut targets = vec![0.0; f.nbx * f.nby];
            let (mut fr, mut t) = (vec![0.0; w], vec![0.0; w]);
            let mut out_block = 0;
            for y in 0..h {
                let a: Vec<f64> = (0..w).map(|x| e(x, y)).collect();
                let mut row = vec![(0.0, 0.0); f.nbx];
                f.row_sums(&s_row(y), &a, &mut row);
                f.add(y, &row);
                while momented < f.moments_to(y + 1) {
                    let mut row = vec![(0.0, [0.0; 9]); f.nbx];
                    f.carrier(momented, &s_row(momented), &mut t);
                    f.moment_sums(momented, &t, &mut row);
                    f.add_moments(momented, &row);
                    momented += 1;
                }
                // Finish every block row whose field is fixed.
                while out_block < f.nby && f.can_fix((out_block + 1).min(f.nby - 1), momented) {
                    while fixed_to <= (out_block + 1).min(f.nby - 1) {
                        f.fix(fixed_to);
                        fixed_to += 1;
                    }
                    for yy in out_block * b..((out_block + 1) * b).min(h) {
                        f.row(yy, &mut fr);
                        let s = s_row(yy);
                        f.carrier(yy, &s, &mut t);
                        for x in 0..w {
                            got[out_block * f.nbx + x / b] +=
                                (s[x] + t[x] * (fr[x] - 1.0)).max(0.0);
                        }
                    }
                    for i in 0..f.nbx {
                        targets[out_block * f.nbx + i] = f.target(out_block, i);
                    }
                    if flat {
                        let k = out_block - f.first;
                        for r in f.rows[k].rho.as_ref().unwrap() {
                            assert!((r - 1.0).abs() < 1e-9, "{r}");
                        }
                    }
                    f.release(out_block.saturating_sub(1));
                    out_block += 1;
                }
            }
            assert_eq!((out_block, momented), (f.nby, h));
            assert!(f.held() <= LOOKAHEAD + 4);
            for (k, g) in got.iter().enumerate() {
                let rel = (g / targets[k] - 1.0).abs();
                assert!(rel < 5e-3, "block {k}: {rel}");
            }
        }
    }

    /// The carrier is the shape where it is flat or the blocks need less
    /// energy, and weighs a pixel by its brightness against the block
    /// means around it where they need more.
    #[test]
    fn the_carrier_weighs_brightness_where_energy_is_missing() {
        let (w, h, b) = (16, 16, 8);
        let flat = vec![2.0; w];
        let mut peak = flat.clone();
        (peak[3], peak[4]) = (8.0, 0.0);
        for (energy, t3) in [(3.0, 8.0 * 8.0 / 2.0), (1.0, 8.0)] {
            let mut f = FieldRows::new(w, h, b);
            for y in 0..h {
                let mut row = vec![(0.0, 0.0); f.nbx];
                f.row_sums(&flat, &vec![energy; w], &mut row);
                f.add(y, &row);
            }
            let mut t = vec![0.0; w];
            f.carrier(5, &flat, &mut t);
            assert!(t.iter().all(|&v| (v - 2.0).abs() < SUM_TOL), "{t:?}");
            f.carrier(5, &peak, &mut t);
            assert!(
                (t[3] - t3).abs() < SUM_TOL && t[4] == 0.0,
                "{energy}: {t:?}"
            );
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
