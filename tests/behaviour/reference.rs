//! The streaming engine against the reference filter of `common`.

use crate::common::*;
use epfilt::filter::Quality;
use epfilt::{FilterParams, Method, PipelineConfig};

/// The engine gathers the base kernel separably while the reference scatters
/// every sample; both sum the same products in another order, so values agree
/// to a few f64 rounding steps, then both round to f32 (2^-24 = 6e-8).
const MATCH_TOL: f64 = 2e-7;

#[test]
fn streaming_equals_the_reference_for_every_method() {
    let lum = [0.2126, 0.7152, 0.0722];
    for (s, w, h) in [(3, 25, 17), (2, 9, 30), (4, 6, 5), (1, 30, 20)] {
        let mut img = fireflies(w * s, h * s, 3, 0.004, 99 + s as u64);
        // A small bright feature (two samples across a pixel boundary): the
        // support rule keeps it.
        for (x, y) in [(2 * s - 1, s + 1), (2 * s, s + 1)] {
            for c in 0..3 {
                img.set(x, y, c, 2000.0);
            }
        }
        // A run of three along a diagonal (a thin line's hits): its ends have
        // one neighbour each, the group rule keeps them.
        for k in 0..3 {
            for c in 0..3 {
                img.set(w * s / 2 + k, h * s / 2 + k, c, 1500.0 + 100.0 * k as f32);
            }
        }
        // Every preset and a group rule with neither compact nor region.
        let mut settings: Vec<FilterParams> = Quality::ALL
            .iter()
            .map(|&q| params(Method::EpGauss, s).with_quality(q))
            .collect();
        let mut group = params(Method::EpGauss, s);
        (group.support, group.support_group) = (2, 3);
        (group.support_compact, group.support_region) = (0, 0);
        settings.extend([group, params(Method::Gauss, s), params(Method::Box, s)]);
        for p in settings {
            let m = p.method;
            let cfg = PipelineConfig {
                strip_rows: 7,
                tile: 16,
                ..Default::default()
            };
            let (out, stats) = run(&img, s, &p, &cfg);
            if m == Method::EpGauss {
                assert!(stats.eg().kept >= 2, "S={s}: {:?}", stats.eg());
                // Wide fireflies go through the coarse grid.
                assert!(s == 1 || stats.eg().coarse > 0, "S={s}: {:?}", stats.eg());
            }
            let (want, spread) = reference(&img, s, &p, &lum);
            assert_eq!(
                stats.ep_gauss().map_or(0, |g| g.spread) as usize,
                spread,
                "S={s} {m:?} {:?}: samples spread",
                p.quality
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
