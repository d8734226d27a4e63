//! The foils' rules: what the energy-losing filters the paper argues against
//! do with a pixel's samples (Lee & Redner's alpha-trimmed mean, the median;
//! the clamp is one `min` in the Gaussian stage).

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
