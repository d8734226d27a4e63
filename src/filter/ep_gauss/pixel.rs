//! ep-gauss at pixel resolution (S = 1): §5.2's rule for a render whose
//! pixels are the means of their samples, with no variance to test them by.
//!
//! At S > 1 a super-sample is one of `S²` in its output pixel, and Relation
//! 14 asks how much it moves the Gaussian average that makes the pixel. At
//! S = 1 the pixel *is* the sample: whatever base kernel it gets, it is its
//! own output's largest part, so the relation cannot tell noise from signal,
//! and any base Gaussian blurs every pixel the renderer got right (against
//! the paper's minimal disruption, §2). So at S = 1:
//!
//! * **Background** `bg`: the median luminance of the 24 pixels of the 5 x 5
//!   about the pixel (reflected at the borders). A median, because a
//!   neighbour may be a firefly too; 5 x 5, because the 8 neighbours of a
//!   bulb's edge pixel are half bulb (the 3 x 3 median spreads big bulbs).
//! * **Noise** (Rule 1): a pixel is noisy when it is a strict local maximum
//!   of its 8 neighbours and above [`NOISE_RATIO`] times its background.
//! * **Features** (beyond the paper, with `--guard`): a noisy pixel is kept
//!   when two neighbours (one, far above the room: [`SUPPORT_BRIGHT`]) carry
//!   at least [`SUPPORT_SHARE`] of its excess (a firefly is one sample in
//!   one pixel; a bulb, a line or a rim lights the pixels beside it too), or
//!   when it is no brighter than a calm pixel within 2 and at least `1 /`
//!   [`RANGE_RATIO`] of it (a light source's edge, a highlight's rim beside
//!   its core).
//! * **Excess**: what the pixel holds above its background, `Y - bg`. The
//!   pixel keeps `bg` (every channel in proportion, so its colour stays) and
//!   only the excess is spread: the paper's §5.1 excess, with §5.2's kernel.
//! * **Width** (Rule 2): the excess `E` goes into the normalised Gaussian
//!   `exp(-(d/rho)^2)` of the smallest radius on the ladder whose peak weight
//!   `w0` gives no pixel more than `tolerance` times the background:
//!   `E w0 <= tolerance bg`. This is the paper's criterion ("spread out
//!   sufficiently that its influence on any given output pixel is smaller
//!   than a specified tolerance") with the influence measured against the
//!   background the pixel sits in.
//! * **Reach**: an excess that no radius up to `--max-radius` can spread
//!   within the tolerance is left where it is (counted): spread wider than it
//!   may be, a lamp taken for a firefly would light a disc of the room. With
//!   an emission guide, which names the lamps, it is spread at the cap
//!   (counted as capped), as at S > 1.
//!
//! Pixels that are not noisy keep their values bit for bit; a pixel changes
//! only by what it gives away or receives. Every spread's weights sum to one,
//! so the energy is exact.
//!
//! The constants were chosen on real renders (`scripts/eval-renders`,
//! `docs/bench/renders-s1.md`): each one's reason is beside it.

/// ep-gauss's tolerance at S = 1 (`--tolerance`): a spread adds to no pixel
/// more than this share of the background (of the room the firefly is in).
pub const TOLERANCE: f64 = 0.25;

/// Pixels either side of a pixel whose luminance makes its background (the
/// 5 x 5 about it).
pub const BACKGROUND_REACH: usize = 2;

/// The neighbours of the 5 x 5 whose median is the background.
pub const BACKGROUND_SAMPLES: usize = (2 * BACKGROUND_REACH + 1) * (2 * BACKGROUND_REACH + 1) - 1;

/// A local maximum is noisy above this many times its background: half as
/// much again as the room is twice the relative standard error of 16
/// samples on a lit diffuse wall (about 0.25), and what is spread below it
/// is grain, which spreading only smooths (on the real renders 2 removed
/// less error everywhere: `docs/bench/renders-as-written.md`, DESIGN).
pub const NOISE_RATIO: f64 = 1.5;

/// A neighbour that holds at least this share of a noisy pixel's excess
/// (above the same background) supports it: one firefly lights one pixel; a
/// bulb, a line or a rim lights its neighbours too.
pub const SUPPORT_SHARE: f64 = 0.5;

/// Supporting neighbours that make a noisy pixel a feature: two (a line's
/// pixel has two along it, a bulb's corner three), where two fireflies
/// that touch are common in glossy grain ...
pub const SUPPORT_NEIGHBOURS: usize = 2;

/// ... and one for a pixel this many times its background: a bulb is tens
/// to thousands of times its room (a 2-pixel one has one neighbour), two
/// fireflies that bright that touch are rare.
pub const SUPPORT_BRIGHT: f64 = 30.0;

/// The `range` rule keeps a noisy pixel no brighter than a calm one within
/// [`BACKGROUND_REACH`] when it is at least this fraction of it: the edge of
/// a lamp or of a highlight's core, not a firefly beside a bright region.
pub const RANGE_RATIO: f64 = 16.0;

/// The median of `v` (the mean of its two middle values), reordering `v`.
pub fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    debug_assert!(n > 0);
    let hi = n / 2;
    let (_, upper, _) = v.select_nth_unstable_by(hi, f64::total_cmp);
    let upper = *upper;
    if n % 2 == 1 {
        return upper;
    }
    let lower = v[..hi].iter().copied().fold(f64::NEG_INFINITY, f64::max);
    0.5 * (lower + upper)
}

/// Whether `y` is above every one of its 8 neighbours `n8`: only a strict
/// local maximum can be a firefly (a neighbour at least as bright would carry
/// more than [`SUPPORT_SHARE`] of its excess).
#[inline]
pub fn local_max(y: f64, n8: &[f64; 8]) -> bool {
    n8.iter().all(|&q| y > q)
}

/// Rule 1 on a local maximum of luminance `y` in background `bg`.
#[inline]
pub fn noisy(y: f64, bg: f64) -> bool {
    bg > 0.0 && y > NOISE_RATIO * bg
}

/// Whether enough neighbours of `n8` ([`SUPPORT_NEIGHBOURS`], one above
/// [`SUPPORT_BRIGHT`] times the background) carry [`SUPPORT_SHARE`] of the
/// excess of a pixel `y` over `bg`.
#[inline]
pub fn supported(y: f64, bg: f64, n8: &[f64; 8]) -> bool {
    let share = (y - bg) * SUPPORT_SHARE;
    let carry = n8.iter().filter(|&&q| q - bg >= share).count();
    let need = if y > SUPPORT_BRIGHT * bg {
        1
    } else {
        SUPPORT_NEIGHBOURS
    };
    carry >= need
}

/// The `range` rule: `y` lies between its background and `brightest_calm`,
/// the brightest pixel within [`BACKGROUND_REACH`] that is not itself noisy
/// (`-inf` where there is none).
#[inline]
pub fn in_range(y: f64, brightest_calm: f64) -> bool {
    y <= brightest_calm && y * RANGE_RATIO >= brightest_calm
}

/// The ladder of spread radii at S = 1 and each one's centre weight.
#[derive(Clone, Debug, PartialEq)]
pub struct Widths {
    /// Radii, ascending, the last the cap.
    pub rho: Vec<f64>,
    /// `1 / (sum of exp(-(d/rho)^2) over the plane's pixels within the
    /// cut-off)`: the weight of the centre pixel away from any border.
    pub w0: Vec<f64>,
    /// Pixels either side each radius reaches ([`reach_of`]).
    pub reach: Vec<usize>,
}

impl Widths {
    /// Radii `radius (1 + step)^k` up to `max_radius` (which ends the
    /// ladder), cut off at `cutoff` radii.
    pub fn new(radius: f64, max_radius: f64, step: f64, cutoff: f64) -> Self {
        let mut rho = Vec::new();
        let mut r = radius;
        while r < max_radius * (1.0 - 1e-9) {
            rho.push(r);
            r *= 1.0 + step;
        }
        rho.push(max_radius);
        let reach: Vec<usize> = rho.iter().map(|&r| reach_of(r, cutoff)).collect();
        let w0 = rho
            .iter()
            .zip(&reach)
            .map(|(&r, &k)| {
                let g = gaussian_taps(r, k, cutoff);
                let s: f64 = g.iter().sum();
                1.0 / (s * s)
            })
            .collect();
        Widths { rho, w0, reach }
    }

    /// The first rung whose centre weight spreads `excess` within
    /// `tolerance * bg`, or `None` when even the cap cannot.
    pub fn first_within(&self, excess: f64, bg: f64, tolerance: f64) -> Option<usize> {
        let limit = tolerance * bg;
        let k = self.w0.partition_point(|&w| excess * w > limit);
        (k < self.w0.len()).then_some(k)
    }

    /// The widest reach.
    pub fn max_reach(&self) -> usize {
        self.reach.last().copied().unwrap_or(0)
    }
}

/// Pixels either side a Gaussian of radius `rho` cut off at `cutoff` radii
/// reaches: every tap within it is above zero (a pixel a spread does not
/// reach is not touched, not even by a zero).
pub fn reach_of(rho: f64, cutoff: f64) -> usize {
    (cutoff * rho).floor().max(0.0) as usize
}

/// `exp(-(d/rho)^2)` for `d` in `-reach..=reach`, zero beyond `cutoff * rho`
/// (unnormalised: each spread is normalised over the pixels it reaches).
pub fn gaussian_taps(rho: f64, reach: usize, cutoff: f64) -> Vec<f64> {
    let limit = cutoff * rho;
    (0..2 * reach + 1)
        .map(|k| {
            let d = k as f64 - reach as f64;
            if d.abs() <= limit {
                let u = d / rho;
                (-u * u).exp()
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_even_and_odd_counts() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        let mut v: Vec<f64> = (0..24).map(|k| ((k * 7) % 24) as f64).collect();
        assert_eq!(median(&mut v), 11.5);
    }

    #[test]
    fn a_firefly_is_noisy_and_alone_a_line_is_not() {
        let n8 = [1.0; 8];
        assert!(local_max(10.0, &n8) && noisy(10.0, 1.0) && !supported(10.0, 1.0, &n8));
        // Two neighbours with half the excess: a line's pixel.
        let mut line = n8;
        (line[3], line[4]) = (6.0, 5.5);
        assert!(supported(10.0, 1.0, &line));
        line[4] = 5.0; // 4/9 of the excess
        assert!(!supported(10.0, 1.0, &line));
        // One such neighbour: a pair of fireflies, or a bulb far above the
        // room.
        let mut pair = n8;
        pair[3] = 6.0;
        assert!(!supported(10.0, 1.0, &pair));
        pair[3] = 25.0;
        assert!(supported(40.0, 1.0, &pair));
        assert!(!noisy(1.4, 1.0) && !noisy(5.0, 0.0));
        assert!(!local_max(1.0, &n8));
    }

    #[test]
    fn range_keeps_an_edge_beside_a_brighter_core_only() {
        assert!(in_range(10.0, 100.0));
        assert!(!in_range(5.0, 100.0)); // below 1/16 of it: a firefly beside a lamp
        assert!(!in_range(101.0, 100.0));
        assert!(!in_range(1.0, f64::NEG_INFINITY));
    }

    #[test]
    fn widths_grow_until_the_peak_is_within_tolerance() {
        let w = Widths::new(0.6, 16.0, 0.1, 3.0);
        assert_eq!(*w.rho.last().unwrap(), 16.0);
        assert!(w.w0.windows(2).all(|p| p[1] < p[0]));
        // A big excess needs a wide kernel; the chosen rung passes, the one
        // below fails.
        let k = w.first_within(100.0, 1.0, 0.25).unwrap();
        assert!(100.0 * w.w0[k] <= 0.25 && 100.0 * w.w0[k - 1] > 0.25);
        // About pi rho^2 pixels share it.
        let area = std::f64::consts::PI * w.rho[k] * w.rho[k];
        assert!((area * 0.25 / 100.0 - 1.0).abs() < 0.25, "{area}");
        // Beyond the cap: nothing.
        assert_eq!(w.first_within(1e6, 1.0, 0.25), None);
        // A tiny excess: the first rung.
        assert_eq!(w.first_within(0.01, 1.0, 0.25), Some(0));
    }
}
