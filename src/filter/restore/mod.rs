//! `epfilt restore`'s rules: put the energy of one image (`e`, the render or
//! epfilt's output of it) back into another (`d`, a denoiser's output),
//! closer to the truth than either: the render's energy where the render
//! is sure, the denoiser's where it is not, the total exactly the render's,
//! while the picture stays the denoiser's.
//!
//! Three parts, per channel:
//!
//! 1. **Kept in place, on evidence.** A pixel's light beyond what the
//!    denoiser put around it (`q`, the denoiser's shape `s = max(d, 0)`
//!    under a Gaussian of [`KEEP_SIGMA`] pixels, over the kernel's centre
//!    weight: its share around) stays where it is (`l`) only where
//!    something says it is real: the emission guide (directly seen
//!    light), the render's variance (its samples agree: [`RELIABLE_RSE`]),
//!    or the denoiser itself (it kept a peak there: [`DENOISER_PEAK`]).
//!    Where the energy image is epfilt's ep-gauss or ep-box output (its
//!    fireflies already spread) or the user gives `--keep-gain`, a gain
//!    keeps too ([`KEEP_GAIN_FILTERED`]). A firefly, one bright sample the
//!    denoiser rightly removed, has none of these: its energy joins its
//!    region's target and is never kept as a lamp.
//! 2. **A target per block** ([`targets()`]): the rest `a = e - l` of every
//!    `--scale` block combined with the denoiser's by how sure each is,
//!    from the whole image (the render's total) down, children summing to
//!    their parent.
//! 3. **The rest in the denoiser's shape** ([`field`]): each block's target
//!    carried by the denoiser's picture and a smooth field: `r = (s + t
//!    (f - 1)) g + l`, where `t` is the carrier ([`FieldRows::carrier`]:
//!    `s^2 / m` where the blocks need more energy than the denoiser gave,
//!    `m` the block means of `s`; `s` where they need less; bilinear
//!    between block centres), `f` interpolates one coefficient per block
//!    bilinearly between block centres, solved so that each block's `Σ (s
//!    + t (f - 1))` (never below zero per pixel) is close to its target,
//!    and `g` is the last, exact step: per block, the target over that
//!    sum. With the field solved, `g` is close to one (no visible seams).
//!    A block where the denoiser has no light keeps `e`.

pub mod field;
pub mod targets;

pub use field::{tent, FieldRows, FIELD_ITERATIONS, LOOKAHEAD};
pub use targets::{targets, BlockSums, LevelSummary};

/// The gain kept in place where the energy image is epfilt's ep-gauss or
/// ep-box output: its fireflies are already spread, so what still exceeds
/// the denoiser's share around a pixel is a feature the denoiser dimmed
/// (bulbs' cores, lamps), kept in place instead of scaling the block around
/// it through the field. Of the gains 1, 1.5, 2 and 3 on the lab's renders,
/// 1 gave the least error over the denoiser's.
pub const KEEP_GAIN_FILTERED: f64 = 1.0;

/// The gain for the evidence that a pixel's light is real (the emission
/// guide, agreeing samples, the denoiser's own peak): all of it that
/// exceeds the denoiser's share around a pixel stays in place.
pub const EMISSION_KEEP_GAIN: f64 = 1.0;

/// A pixel of a render with a variance pass whose mean lies more than
/// this share of itself from zero in standard errors (relative standard
/// error under it) is light its samples saw again and again (a bulb, a lit
/// edge) and is kept as the emission guide is. A firefly, one hit among
/// `n` samples, has a relative standard error near one (`sqrt((n - k) /
/// (k n))` for `k` hits: 0.97 for one hit of 16, 0.66 for two); under one
/// half needs four hits or more at any `n`.
pub const RELIABLE_RSE: f64 = 0.5;

/// The denoiser kept a peak at a pixel where its value is more than this
/// many times the mean of the eight around it: it judged the light real
/// (a bulb, a spark of a highlight), and what the render has there beyond
/// the denoiser's share around stays in place. A firefly the denoiser
/// removed leaves it level with its neighbours (ratio about one).
pub const DENOISER_PEAK: f64 = 3.0;

/// The gains `--keep-gain` takes: at least one (below, the denoiser's own
/// energy would be kept), at most a million (above, nothing is kept).
pub const KEEP_GAIN_RANGE: std::ops::RangeInclusive<f64> = 1.0..=1e6;

/// What a restore is asked for: the blocks' side and the keep gain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RestoreParams {
    /// The side of the smallest blocks whose energy is a target, pixels.
    pub scale: usize,
    /// A gain that keeps in place beside the evidence: [`KEEP_GAIN_FILTERED`]
    /// on epfilt's output, or the user's; `None` (a render): evidence alone.
    pub keep_gain: Option<f64>,
}

impl RestoreParams {
    /// Checked: the scale by [`check_scale`], the gain within
    /// [`KEEP_GAIN_RANGE`].
    pub fn check(self) -> Result<Self, String> {
        check_scale(self.scale)?;
        if let Some(g) = self.keep_gain.filter(|g| !KEEP_GAIN_RANGE.contains(g)) {
            return Err(format!(
                "--keep-gain must be from {} to {}, not {g}",
                KEEP_GAIN_RANGE.start(),
                KEEP_GAIN_RANGE.end(),
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
/// cut off (the Gaussian's tails beyond three deviations) no longer changes
/// what the denoiser put around a pixel enough to matter.
pub const REACH_SIGMAS: f64 = 3.0;

/// The default `--scale`: the smallest blocks with a target are 32 x 32
/// pixels (a lighting study's region; the denoiser's look within it).
pub const DEFAULT_SCALE: usize = 32;

/// Largest `--scale`: a block's rows are held in memory.
pub const MAX_SCALE: usize = 4096;

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

/// Whether the denoiser kept a peak at a pixel: its shape `own` against
/// the mean `ring` of the eight around ([`DENOISER_PEAK`]).
#[inline]
pub fn denoiser_peak(own: f64, ring: f64) -> bool {
    own > 0.0 && own > DENOISER_PEAK * ring
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

    #[test]
    fn kept_is_the_excess_over_the_denoisers_share() {
        let never = || -> f64 { panic!("q measured where the own value settles it") };
        let g = EMISSION_KEEP_GAIN;
        assert_eq!(kept(1.0, 1.0, never, 0.04, g), 0.0);
        assert_eq!(kept(-2.0, 1.0, never, 0.04, g), -2.0);
        assert_eq!(kept(3.0, 0.0, || 0.0, 0.04, g), 3.0);
        // A lamp the denoiser dimmed to a glow: q around, little of its own.
        let l = kept(1000.0, 0.5, || 0.05, 0.04, g);
        assert!((l - (1000.0 - g * 0.05 / 0.04)).abs() < SUM_TOL * 1000.0);
        // Within the denoiser's share around: nothing kept.
        assert_eq!(kept(10.0, 0.5, || 1.0, 0.04, g), 0.0);
        let l = kept(5.0, 1.0, || 0.06, 0.04, KEEP_GAIN_FILTERED);
        assert!((l - (5.0 - KEEP_GAIN_FILTERED * 0.06 / 0.04)).abs() < SUM_TOL * 5.0);
    }

    #[test]
    fn a_peak_is_the_denoisers_own_and_a_removed_firefly_is_not() {
        assert!(denoiser_peak(10.0, 1.0) && denoiser_peak(1.0, 0.0));
        assert!(!denoiser_peak(1.1, 1.0) && !denoiser_peak(0.0, 0.0));
    }

    #[test]
    fn params_check_the_scale_and_the_gain() {
        let p = |scale, keep_gain| RestoreParams { scale, keep_gain }.check();
        assert!(p(32, None).is_ok() && p(2, Some(1.0)).is_ok() && p(4096, Some(1e6)).is_ok());
        for (scale, gain) in [
            (1, None),
            (32, Some(0.5)),
            (32, Some(f64::NAN)),
            (32, Some(f64::INFINITY)),
            (32, Some(2e6)),
        ] {
            assert!(p(scale, gain).is_err(), "{scale} {gain:?}");
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
