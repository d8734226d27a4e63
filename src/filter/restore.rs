//! `epfilt restore`'s rules: put the energy of one image (`e`, the render or
//! epfilt's output of it) back into the shape of another (`d`, a denoiser's
//! output), locally and exactly.
//!
//! Each pixel `y` of `e` is a sample whose energy `e(y)` is spread, as the
//! paper's filters spread a sample, over a Gaussian `K` of `--scale` pixels
//! around it, but in proportion to the denoiser's picture there:
//!
//! ```text
//!   weight of x for y = K(x, y) s(x) / q(y),   s = max(d, 0),   q = G s
//!   r(x) = s(x) (G t)(x) + (G l)(x),           t = e / q,       l = e - t q
//! ```
//!
//! The weights of every `y` sum to one, so the total is `e`'s exactly, and no
//! energy moves further than the kernel: the local energy at the scale is
//! `e`'s, the detail within it the denoiser's. `K` is the separable Gaussian
//! reflected at the image's edges (half-sample symmetric): it is symmetric in
//! `x` and `y` and each of its rows and columns sums to one, so the same blur
//! `G` serves both sides (what makes `Σ r = Σ e` an identity rather than an
//! approximation) and an image the denoiser got right stays as it was, up to
//! its edges (`e = d` constant gives `r = d`).
//!
//! Where `d` has too little to shape the energy with (`q` is zero, or one
//! pixel's energy would scale the denoiser's value there by more than
//! [`MAX_GAIN`]), the gain is capped and the rest, `l`, is spread by the
//! kernel alone: the denoiser's output is never multiplied without bound, and
//! the shortfall is placed, not lost. Negative `e` (a render's rare negative
//! samples) is spread the same way.

/// Most one energy pixel scales the denoiser's value at its own place: four
/// times (its gain `t` times the kernel's centre weight). A denoiser that
/// removed a firefly leaves a `q` far below its energy; scaling the few dim
/// pixels around it by hundreds would draw the firefly back as a hard speck,
/// so beyond this its energy is spread as a plain Gaussian instead. A real
/// light the denoiser kept has a gain of about one there.
pub const MAX_GAIN: f64 = 4.0;

/// Kernel radius in units of its standard deviation: the weight beyond is
/// below 1.2% of the centre's.
pub const REACH_SIGMAS: f64 = 3.0;

/// Largest `--scale` (pixels): the halo's rows are held in memory.
pub const MAX_SCALE: f64 = 256.0;

/// The default `--scale` (the kernel's standard deviation, pixels).
pub const DEFAULT_SCALE: f64 = 2.0;

/// The normalised 1-D Gaussian of standard deviation `scale` pixels,
/// `2r + 1` taps with `r = ceil(3 scale)` (at least one).
pub fn taps(scale: f64) -> Vec<f64> {
    let r = reach(scale);
    let w: Vec<f64> = (0..=2 * r)
        .map(|i| {
            let d = i as f64 - r as f64;
            (-0.5 * d * d / (scale * scale)).exp()
        })
        .collect();
    let sum: f64 = w.iter().sum();
    w.into_iter().map(|v| v / sum).collect()
}

/// The kernel's radius in pixels at `scale`.
pub fn reach(scale: f64) -> usize {
    ((REACH_SIGMAS * scale).ceil() as usize).max(1)
}

/// A checked `--scale`.
pub fn check_scale(scale: f64) -> Result<f64, String> {
    if scale.is_finite() && scale > 0.0 && scale <= MAX_SCALE {
        Ok(scale)
    } else {
        Err(format!(
            "--scale must be a number of pixels above 0 and at most {MAX_SCALE}, not {scale}"
        ))
    }
}

/// Position `p` of a row `n` long, reflected at its ends (half-sample
/// symmetric: `-1` is `0`, `n` is `n - 1`), as often as needed.
#[inline]
pub fn reflect(p: isize, n: usize) -> usize {
    let n = n as isize;
    let m = p.rem_euclid(2 * n);
    (if m < n { m } else { 2 * n - 1 - m }) as usize
}

/// `out[x] = Σ_i taps[i] src[reflect(x + i - r)]`.
pub fn blur_row<T: Copy + Into<f64>>(src: &[T], taps: &[f64], out: &mut [f64]) {
    let n = src.len();
    let r = taps.len() / 2;
    for (x, o) in out.iter_mut().enumerate().take(n) {
        let mut acc = 0.0;
        if x >= r && x + r < n {
            for (&t, &v) in taps.iter().zip(&src[x - r..=x + r]) {
                acc += t * v.into();
            }
        } else {
            for (i, &t) in taps.iter().enumerate() {
                acc += t * src[reflect(x as isize + i as isize - r as isize, n)].into();
            }
        }
        *o = acc;
    }
}

/// `out = Σ_i taps[i] rows[i]`: the column's rows, reflected at the image's
/// edges by the caller (a row may come more than once).
pub fn blur_column<'a>(rows: impl Iterator<Item = &'a [f64]>, taps: &[f64], out: &mut [f64]) {
    out.fill(0.0);
    for (row, &t) in rows.zip(taps) {
        for (o, &v) in out.iter_mut().zip(row) {
            *o += t * v;
        }
    }
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

/// What pixel `y` of energy `e` gives, where the denoiser's energy around it
/// is `q` and the kernel's centre weight `centre`: the gain `t` on the
/// denoiser's shape and the leftover `l`, spread as a plain Gaussian;
/// `t q + l = e`. The gain is capped where it would scale the denoiser's own
/// value by more than [`MAX_GAIN`].
#[inline]
pub fn split(e: f64, q: f64, centre: f64) -> (f64, f64) {
    if e > 0.0 && q > 0.0 {
        let gain = e / q;
        let cap = MAX_GAIN / centre;
        if gain <= cap {
            (gain, 0.0)
        } else {
            (cap, e - cap * q)
        }
    } else {
        (0.0, e)
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
            assert_eq!(t.len(), 2 * reach(s) + 1);
            assert!((t.iter().sum::<f64>() - 1.0).abs() < SUM_TOL);
            for i in 0..t.len() {
                assert_eq!(t[i], t[t.len() - 1 - i]);
            }
            assert!(t.windows(2).take(reach(s)).all(|w| w[0] < w[1]));
        }
    }

    /// A 1-D restore of `e` in the shape of `d` at `scale`.
    fn restore_1d(d: &[f32], e: &[f64], scale: f64) -> Vec<f64> {
        let t = taps(scale);
        let n = d.len();
        let s: Vec<f64> = d.iter().map(|&v| shape(v)).collect();
        let mut q = vec![0.0; n];
        blur_row(&s, &t, &mut q);
        let (mut tt, mut ll) = (vec![0.0; n], vec![0.0; n]);
        for y in 0..n {
            (tt[y], ll[y]) = split(e[y], q[y], t[t.len() / 2]);
        }
        let (mut gt, mut gl) = (vec![0.0; n], vec![0.0; n]);
        blur_row(&tt, &t, &mut gt);
        blur_row(&ll, &t, &mut gl);
        (0..n).map(|x| s[x] * gt[x] + gl[x]).collect()
    }

    /// The scatter of each `y` sums to one: the total of a restore is the
    /// energy's, whatever the shape (a zero, a negative, a firefly the
    /// shape lacks).
    #[test]
    fn restore_keeps_the_total() {
        let d: Vec<f32> = vec![0.0, 0.1, 5.0, 0.0, 0.0, 0.2, 1.0, -3.0, 0.4, 0.0, 0.0, 0.0];
        let e: Vec<f64> = vec![1.0, 0.0, 2.0, 9.0, 0.5, 0.2, 0.0, 1.0, -0.1, 3.0, 0.0, 90.0];
        for scale in [0.5, 1.5, 4.0, 20.0] {
            let r = restore_1d(&d, &e, scale);
            let (sr, se) = (r.iter().sum::<f64>(), e.iter().sum::<f64>());
            assert!(
                (sr - se).abs() <= SUM_TOL * se.abs(),
                "{scale}: {sr} vs {se}"
            );
        }
    }

    /// Minimal disruption: where the denoiser's picture is flat and its
    /// energy the energy image's, nothing moves, edges included.
    #[test]
    fn a_right_flat_image_stays() {
        let d = vec![2.5f32; 17];
        let e = vec![2.5f64; 17];
        for scale in [0.5, 2.0, 6.0] {
            for v in restore_1d(&d, &e, scale) {
                assert!((v - 2.5).abs() < SUM_TOL, "{scale}: {v}");
            }
        }
    }

    #[test]
    fn reflect_is_half_sample_symmetric() {
        let got: Vec<usize> = (-4..8).map(|p| reflect(p, 3)).collect();
        assert_eq!(got, vec![2, 2, 1, 0, 0, 1, 2, 2, 1, 0, 0, 1]);
    }

    #[test]
    fn split_caps_the_gain_and_places_the_rest() {
        assert_eq!(split(2.0, 1.0, 0.5), (2.0, 0.0));
        let (t, l) = split(100.0, 1.0, 0.5);
        assert_eq!(t, MAX_GAIN / 0.5);
        assert!((t * 1.0 + l - 100.0).abs() < SUM_TOL);
        assert_eq!(split(3.0, 0.0, 0.5), (0.0, 3.0));
        assert_eq!(split(-1.0, 2.0, 0.5), (0.0, -1.0));
    }

    #[test]
    fn scale_is_checked() {
        assert!(check_scale(2.0).is_ok());
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, MAX_SCALE * 2.0] {
            assert!(check_scale(bad).is_err(), "{bad}");
        }
    }
}
