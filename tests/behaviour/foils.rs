//! The foils the paper argues against: clamp, median, alpha-trimmed mean.
//! Same pipeline and seam guarantees; their ledger shows the energy they lose.

use crate::common::*;
use epfilt::Method;
use proptest::prelude::*;

#[test]
fn clamp_loses_exactly_what_it_cuts() {
    let img = fireflies(60, 45, 3, 0.03, 5);
    let mut p = params(Method::Clamp, 3);
    p.clamp = 10.0;
    let (_, stats) = run(&img, 3, &p, &cfg(256, 0, 2));
    for (c, l) in stats.ledger.iter().enumerate() {
        let mut total = 0.0f64;
        let mut cut = 0.0f64;
        for y in 0..img.h {
            for x in 0..img.w {
                let v = img.at(x, y, c) as f64;
                total += v;
                cut += (v - 10.0).max(0.0);
            }
        }
        let lost = (l.energy_in - l.energy_out) / l.energy_in;
        // Both sums are exact to ~1e-15 relative; 1e-9 leaves room and still
        // tells a cut of 30% from any other.
        assert!(
            (lost - cut / total).abs() <= 1e-9,
            "{}: {lost} vs {}",
            l.channel,
            cut / total
        );
        assert!(lost > 0.05, "fireflies must be cut: {lost}");
    }
}

#[test]
fn median_and_alpha_trim_gather_the_pixels_samples() {
    let img = fireflies(12, 9, 1, 0.2, 9);
    let (med, _) = run(&img, 3, &params(Method::Median, 3), &cfg(256, 0, 1));
    let mut p = params(Method::AlphaTrim, 3);
    p.alpha = 0.2;
    let (trim, _) = run(&img, 3, &p, &cfg(256, 0, 1));
    for y in 0..3 {
        for x in 0..4 {
            let mut v: Vec<f64> = (0..9)
                .map(|k| img.at(x * 3 + k % 3, y * 3 + k / 3, 0) as f64)
                .collect();
            v.sort_by(|a, b| a.total_cmp(b));
            assert_eq!(med.at(x, y, 0), v[4] as f32);
            // 9 samples, alpha 0.2: one trimmed from each end.
            let want = v[1..8].iter().sum::<f64>() / 7.0;
            assert_eq!(trim.at(x, y, 0), want as f32);
        }
    }
    // At S = 1: the 3x3 window, reflected at the borders.
    let (m1, _) = run(&img, 1, &params(Method::Median, 1), &cfg(256, 0, 1));
    let mut v: Vec<f64> = [
        (0, 0),
        (1, 0),
        (0, 0),
        (0, 1),
        (1, 1),
        (0, 1),
        (0, 0),
        (1, 0),
        (0, 0),
    ]
    .iter()
    .map(|&(x, y)| img.at(x, y, 0) as f64)
    .collect();
    v.sort_by(|a, b| a.total_cmp(b));
    assert_eq!(m1.at(0, 0, 0), v[4] as f32);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, .. ProptestConfig::default() })]

    #[test]
    fn foils_are_bit_identical_for_any_cut(
        w in 1usize..12, h in 1usize..12, s in 1usize..4, seed in any::<u64>(),
        tile in 1usize..20, strip in 1usize..30, threads in 1usize..4,
    ) {
        let img = fireflies(w * s, h * s, 3, 0.05, seed);
        for m in [Method::Clamp, Method::Median, Method::AlphaTrim] {
            let p = params(m, s);
            let cuts = [(256, 0, 1), (tile, strip, threads)].map(Cut::from);
            let (a, _) = invariant(&img.data, &job_for(&img, s), &p, &cuts)
                .map_err(TestCaseError::fail)?;
            prop_assert!(a.iter().all(|v| v.is_finite()));
        }
    }
}
