//! The streaming engine against the reference filter of `common`.

use crate::common::*;
use epfilt::{Method, PipelineConfig};

/// The engine gathers the base kernel separably while the reference scatters
/// every sample; both sum the same products in another order, so values agree
/// to a few f64 rounding steps, then both round to f32 (2^-24 = 6e-8).
const MATCH_TOL: f64 = 2e-7;

#[test]
fn streaming_equals_the_reference_for_every_method() {
    let lum = [0.2126, 0.7152, 0.0722];
    for (s, w, h) in [(3, 25, 17), (2, 9, 30), (4, 6, 5), (1, 30, 20)] {
        let img = fireflies(w * s, h * s, 3, 0.004, 99 + s as u64);
        for m in [Method::EpGauss, Method::Gauss, Method::Box] {
            let p = params(m, s);
            let cfg = PipelineConfig {
                strip_rows: 7,
                tile: 16,
                ..Default::default()
            };
            let (out, stats) = run(&img, s, &p, &cfg);
            let (want, spread) = reference(&img, s, &p, &lum);
            assert_eq!(
                stats.counters.spread as usize, spread,
                "S={s} {m:?}: samples spread"
            );
            for (k, (&o, &r)) in out.data.iter().zip(&want).enumerate() {
                let scale = r.abs().max(1e-3);
                assert!(
                    ((o as f64 - r) / scale).abs() <= MATCH_TOL,
                    "S={s} {m:?} value {k}: {o} vs {r}"
                );
            }
        }
    }
}
