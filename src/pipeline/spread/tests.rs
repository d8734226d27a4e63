//! The Gaussian stage's unit tests (and the stage they build).

use super::*;
use crate::filter::FilterParams;

/// A one-channel stage of `p` on `grid`, tiles of 16.
pub(super) fn stage(p: &FilterParams, grid: Grid) -> GaussianStage {
    GaussianStage::new(
        grid,
        vec![1.0],
        vec![ChannelMode::Spread],
        &p.validated().unwrap(),
        16,
    )
}

#[test]
fn grid_reaches_from_params_equal_the_stages() {
    for (s, r, mr, from) in [(3, 0.6, 16.0, 2.0), (4, 0.9, 5.5, 1.0), (2, 0.6, 32.0, 0.0)] {
        let mut p = FilterParams::new(Method::EpGauss, s);
        (p.radius, p.max_radius, p.coarse_from) = (r, mr, from);
        let grid = Grid {
            in_w: 90 * s,
            in_h: 60 * s,
            s,
        };
        let e = stage(&p, grid);
        let ep = e.rules.ep.as_ref().unwrap();
        assert_eq!(
            crate::filter::grid_reaches(&p),
            [1, 2, 4].map(|f| ep.grid_reach(f)),
            "{s} {r} {mr} {from}"
        );
    }
}

#[test]
fn halo_from_params_equals_the_stages() {
    for m in [Method::EpGauss, Method::Gauss, Method::Box] {
        for (s, r, mr, cut) in [
            (3, 0.6, 16.0, 3.0),
            (4, 0.9, 5.5, 2.5),
            (2, 0.3, 0.3, 1.0),
            (1, 2.0, 40.0, 6.0),
        ] {
            if m == Method::EpGauss && s == 1 {
                continue; // the pixel stage's (pixel.rs)
            }
            let mut p = FilterParams::new(m, s);
            (p.radius, p.max_radius, p.cutoff) = (r, mr, cut);
            let grid = Grid {
                in_w: 30 * s,
                in_h: 20 * s,
                s,
            };
            let e = stage(&p, grid);
            assert_eq!(
                e.halo(),
                crate::filter::halo(&p),
                "{m:?} {s} {r} {mr} {cut}"
            );
            // The passes' lag is the halo's, or the base kernel's reach
            // and the input row below the classification's where that is
            // more (the methods without a base test).
            let h = e.halo();
            assert_eq!(
                crate::pipeline::schedule::lag(&e.passes),
                h.lag().max(h.base_reach + 1),
                "{m:?} {s} {r} {mr} {cut}"
            );
        }
    }
}
