//! The foils' rules: what the energy-losing filters the paper argues against
//! do with a pixel's samples (Lee & Redner's alpha-trimmed mean, the median,
//! the clamp).

/// The clamp foil: colour samples above `limit` are cut to it (`f32::min`:
/// a NaN would become the limit, but non-finite input is refused or zeroed
/// before any stage sees it). The ledger has counted the input before, so
/// the loss shows.
#[inline]
pub fn clamp_samples(samples: &mut [f32], limit: f32) {
    samples.iter_mut().for_each(|v| *v = v.min(limit));
}

/// What is kept of the sorted values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Trim {
    /// The median (the mean of the two middle values for an even count).
    Median,
    /// Trim `floor(alpha * n)` values from each end (at least one is kept).
    Alpha(f64),
}

impl Trim {
    /// The mean of `v` after trimming (sorts `v`).
    pub fn apply(self, v: &mut [f64]) -> f64 {
        let n = v.len();
        v.sort_unstable_by(|a, b| a.total_cmp(b));
        let k = match self {
            Trim::Median => (n - 1) / 2,
            Trim::Alpha(a) => ((a * n as f64).floor() as usize).min((n - 1) / 2),
        };
        let kept = &v[k..n - k];
        kept.iter().sum::<f64>() / kept.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clamp_cuts_what_is_above_its_limit_only() {
        let mut v = [0.5, 10.0, 1e30, -3.0, f32::INFINITY, f32::NAN];
        clamp_samples(&mut v, 10.0);
        assert_eq!(v, [0.5, 10.0, 10.0, -3.0, 10.0, 10.0]);
    }

    #[test]
    fn trims() {
        assert_eq!(Trim::Median.apply(&mut [5.0, 1.0, 3.0]), 3.0);
        assert_eq!(Trim::Median.apply(&mut [4.0, 1.0, 3.0, 100.0]), 3.5);
        assert_eq!(Trim::Alpha(0.0).apply(&mut [1.0, 2.0, 6.0]), 3.0);
        // 9 values, alpha 0.2: one from each end.
        let mut v = [9.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 1000.0];
        assert_eq!(
            Trim::Alpha(0.2).apply(&mut v),
            (2.0 + 3.0 + 4.0 + 5.0 + 6.0 + 7.0 + 9.0) / 7.0
        );
        assert_eq!(Trim::Alpha(0.49).apply(&mut [1.0, 2.0]), 1.5);
    }
}
