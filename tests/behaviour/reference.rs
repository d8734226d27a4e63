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
        // ep-gauss at S = 1 has a stage of its own (below).
        let mut settings: Vec<FilterParams> = Quality::ALL
            .iter()
            .filter(|_| s > 1)
            .map(|&q| params(Method::EpGauss, s).with_quality(q))
            .collect();
        let mut group = params(Method::EpGauss, s);
        (group.support, group.support_group) = (2, 3);
        (group.support_compact, group.support_region) = (0, 0);
        if s > 1 {
            settings.push(group);
        }
        settings.extend([params(Method::Gauss, s), params(Method::Box, s)]);
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

/// ep-gauss at S = 1, written from `filter::ep_gauss::pixel`'s rules with
/// nothing of the stage's: every pixel's background (the median of the 5 x 5
/// about it, reflected at the borders), the noise test and the feature
/// rules, then each noisy pixel's excess over its background spread with the
/// first rung's Gaussian that keeps its centre within the tolerance,
/// normalised over the pixels it reaches. Returns the output and the number
/// of pixels spread.
fn pixel_reference(img: &Img, p: &FilterParams, lum: &[f64; 3]) -> (Vec<f64>, usize) {
    use epfilt::filter::ep_gauss::pixel::*;
    let (w, h) = (img.w, img.h);
    let y = |x: i64, yy: i64| {
        let (x, yy) = (mirror(x, w), mirror(yy, h));
        (0..3)
            .map(|c| lum[c] * img.at(x, yy, c) as f64)
            .sum::<f64>()
    };
    let n8 = |x: i64, yy: i64| {
        let mut v = [0.0; 8];
        let mut k = 0;
        for dy in -1..=1 {
            for dx in -1..=1 {
                if dx != 0 || dy != 0 {
                    v[k] = y(x + dx, yy + dy);
                    k += 1;
                }
            }
        }
        v
    };
    let bg = |x: i64, yy: i64| {
        let mut v = Vec::new();
        for dy in -2..=2 {
            for dx in -2..=2 {
                if dx != 0 || dy != 0 {
                    v.push(y(x + dx, yy + dy));
                }
            }
        }
        median(&mut v)
    };
    let noisy_at = |x: i64, yy: i64| {
        let v = y(x, yy);
        local_max(v, &n8(x, yy)) && noisy(v, bg(x, yy))
    };
    let widths = Widths::new(p.radius, p.max_radius, p.width_step, p.cutoff);
    let mut out: Vec<f64> = img.data.iter().map(|&v| v as f64).collect();
    let mut acc = vec![0.0f64; out.len()];
    let mut spread = 0;
    for yy in 0..h as i64 {
        for x in 0..w as i64 {
            if !noisy_at(x, yy) {
                continue;
            }
            let (v, b) = (y(x, yy), bg(x, yy));
            if supported(v, b, &n8(x, yy)) {
                continue;
            }
            let mut calm = f64::NEG_INFINITY;
            for qy in (yy - 2).max(0)..(yy + 3).min(h as i64) {
                for qx in (x - 2).max(0)..(x + 3).min(w as i64) {
                    if !noisy_at(qx, qy) {
                        calm = calm.max(y(qx, qy));
                    }
                }
            }
            if in_range(v, calm) {
                continue;
            }
            let excess = v - b;
            let Some(first) = widths.first_within(excess, b, p.tolerance) else {
                continue;
            };
            let reach = |k: usize| widths.reach[k] as i64;
            let norm = |k: usize| {
                let g = gaussian_taps(widths.rho[k], widths.reach[k], p.cutoff);
                let r = reach(k);
                let mut n = 0.0;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (tx, ty) = (x + dx, yy + dy);
                        if tx >= 0 && ty >= 0 && tx < w as i64 && ty < h as i64 {
                            n += g[(dy + r) as usize] * g[(dx + r) as usize];
                        }
                    }
                }
                (g, n)
            };
            let Some((k, (g, n))) = (first..widths.rho.len())
                .map(|k| (k, norm(k)))
                .find(|(_, (_, n))| excess <= p.tolerance * b * n)
            else {
                continue;
            };
            spread += 1;
            let f = excess / v;
            let r = reach(k);
            for c in 0..3 {
                let i = (yy as usize * 3 + c) * w + x as usize;
                let removed = img.data[i] as f64 * f;
                out[i] -= removed;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (tx, ty) = (x + dx, yy + dy);
                        if tx >= 0 && ty >= 0 && tx < w as i64 && ty < h as i64 {
                            let wgt = g[(dy + r) as usize] * g[(dx + r) as usize];
                            acc[(ty as usize * 3 + c) * w + tx as usize] += removed * wgt / n;
                        }
                    }
                }
            }
        }
    }
    for (o, a) in out.iter_mut().zip(&acc) {
        *o += a;
    }
    (out, spread)
}

/// The image's edge, reflected ([`epfilt::geometry::mirror`]'s rule).
fn mirror(v: i64, n: usize) -> usize {
    epfilt::geometry::mirror(v, n)
}

#[test]
fn ep_gauss_at_pixel_resolution_equals_its_reference() {
    let lum = [0.2126, 0.7152, 0.0722];
    for (w, h, seed) in [(40, 31, 5), (17, 60, 6), (3, 2, 7)] {
        let mut img = fireflies(w, h, 3, 0.02, seed);
        // A bulb of four pixels (support keeps it), an edge of a bright
        // region (range keeps it).
        for (x, y) in [(5, 5), (6, 5), (5, 6), (6, 6)] {
            if x < w && y < h {
                for c in 0..3 {
                    img.set(x, y, c, 3000.0);
                }
            }
        }
        for p in Quality::ALL.map(|q| params(Method::EpGauss, 1).with_quality(q)) {
            let (want, spread) = pixel_reference(&img, &p, &lum);
            for c in [cfg(16, 7, 2), cfg(5, 3, 1), cfg(256, 0, 0)] {
                let (out, stats) = run(&img, 1, &p, &c);
                assert_eq!(
                    stats.eg().spread as usize,
                    spread,
                    "{w}x{h} {:?}",
                    p.quality
                );
                for (k, (&o, &r)) in out.data.iter().zip(&want).enumerate() {
                    let scale = r.abs().max(1e-3);
                    assert!(
                        ((o as f64 - r) / scale).abs() <= MATCH_TOL,
                        "{w}x{h} value {k}: {o} vs {r}"
                    );
                }
            }
        }
    }
}
