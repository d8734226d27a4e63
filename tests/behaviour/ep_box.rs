//! The ep-box filter (§5.1): energy, invariance, minimal disruption, colour,
//! order independence, passes, and the plan.
#![allow(clippy::needless_range_loop)] // pixel loops read clearer with indices

use epfilt::filter::ep_box::{se2, Guard, Ring, Spp, TFactor, VarianceKind};
use epfilt::{filter_in_memory, FilterParams, Method, PipelineConfig, RunStats, StripLayout};
use proptest::prelude::*;

use crate::common::*;

const LUM: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// An RGB image with per-colour sample variances: channels R, G, B, vR, vG, vB.
fn rgbv(w: usize, h: usize) -> Img {
    Img::new(w, h, 6, |_, _, c| if c < 3 { 1.0 } else { 0.0 })
}

fn job(w: usize, h: usize, spp: f64) -> StripLayout {
    rgb_variance_job(w, h, spp)
}

fn params(guard: Guard, ltvis: f64, radius: f64) -> FilterParams {
    let mut p = FilterParams::new(Method::EpBox, 1);
    p.max_radius = radius;
    p.ep_box.guard = guard;
    p.ep_box.ltvis = Some(ltvis);
    p
}

fn filter(img: &Img, spp: f64, p: &FilterParams, c: &PipelineConfig) -> (Img, RunStats) {
    let (out, stats) =
        filter_in_memory(img.data.clone(), &job(img.w, img.h, spp), p, c).expect("ep-box");
    (
        Img {
            w: img.w,
            h: img.h,
            nch: 3,
            data: out,
        },
        stats,
    )
}

/// A firefly of colour `rgb` at (x, y): a pixel whose mean holds one hot
/// sample of `n`, with the matching sample variance.
fn firefly(img: &mut Img, x: usize, y: usize, rgb: [f32; 3], n: f32) {
    for c in 0..3 {
        let base = img.at(x, y, c);
        let hot = rgb[c];
        // n - 1 samples at `base`, one at `hot`: mean and unbiased variance.
        let mean = base + (hot - base) / n;
        let var = (hot - base) * (hot - base) / n;
        img.set(x, y, c, mean);
        img.set(x, y, 3 + c, var);
    }
}

fn lum(img: &Img, x: usize, y: usize) -> f64 {
    (0..3).map(|c| LUM[c] * img.at(x, y, c) as f64).sum()
}

/// The §5.1 rule written for clarity over the whole image: pass numbers by
/// repeated dilation, noisy pixels visited in a *shuffled* order within each
/// pass (the result must not depend on it), then every excess spread to its
/// ring. Returns the output (f64) and the number of unresolved pixels.
fn reference(img: &Img, spp: f64, p: &FilterParams, seed: u64) -> (Vec<f64>, usize) {
    let (w, h) = (img.w, img.h);
    let e = &p.ep_box;
    let ltvis = e.ltvis.unwrap();
    let dl = e.d * ltvis;
    let (t, tg) = (TFactor::new(e.confidence), TFactor::new(e.guard_confidence));
    let idx = |x: usize, y: usize| y * w + x;
    let mut noisy = vec![false; w * h];
    // The stderr guard's bound: t at the guard's confidence times S_p.
    let mut bound = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let var: Vec<f64> = (3..6).map(|c| img.at(x, y, c) as f64).collect();
            let se = se2(VarianceKind::Sample, &var, &LUM, 0.0, spp).sqrt();
            bound[idx(x, y)] = tg.get(spp) * se;
            noisy[idx(x, y)] = t.get(spp) * se > dl;
        }
    }
    // The carriers guard: the samples' luminance deviation is taken as
    // sum w_c s_c, so the population variance is that squared times
    // (n - 1) / n; k = n Y^2 / (var + Y^2). A pixel is reliable when
    // k >= min(K, max(fraction n, n / (1 + (n - 1) rse^2), 2)), or when
    // k >= 3 and at most 4 noisy pixels of at least 1/16 of its luminance
    // lie within 2 pixels (itself included).
    if matches!(e.guard, Guard::Carriers | Guard::All) {
        let raw = noisy.clone();
        for y in 0..h {
            for x in 0..w {
                if !raw[idx(x, y)] {
                    continue;
                }
                let var: Vec<f64> = (3..6).map(|c| img.at(x, y, c) as f64).collect();
                let sd: f64 = var.iter().zip(&LUM).map(|(v, l)| l * v.sqrt()).sum();
                let yv = lum(img, x, y);
                let k = spp * yv * yv / (sd * sd * (spp - 1.0) / spp + yv * yv);
                let rse = e.carriers_rse;
                let by_error = spp / (1.0 + (spp - 1.0) * rse * rse);
                let needed = e
                    .carriers
                    .min((e.carriers_fraction * spp).max(by_error).max(2.0));
                let mut cluster = 0;
                for yy in y.saturating_sub(2)..(y + 3).min(h) {
                    for xx in x.saturating_sub(2)..(x + 3).min(w) {
                        cluster += usize::from(raw[idx(xx, yy)] && lum(img, xx, yy) >= yv / 16.0);
                    }
                }
                if k >= needed || (k >= 3.0 && cluster <= 4) {
                    noisy[idx(x, y)] = false;
                }
            }
        }
    }
    let mut pass = vec![0usize; w * h];
    let mut refv: Vec<f64> = (0..w * h).map(|i| lum(img, i % w, i / w)).collect();
    let mut out: Vec<f64> = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for c in 0..3 {
            for x in 0..w {
                out.push(img.at(x, y, c) as f64);
            }
        }
    }
    let mut excess = vec![0.0f64; w * h];
    let mut pending: Vec<usize> = (0..w * h).filter(|&i| noisy[i]).collect();
    for v in &pending {
        pass[*v] = usize::MAX;
    }
    let mut rng = Rng(seed);
    for k in 1..=e.passes {
        // Shuffle: the order of visits must not matter.
        for i in (1..pending.len()).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            pending.swap(i, j);
        }
        let mut rest = Vec::new();
        for &i in &pending {
            let (x, y) = (i % w, i / w);
            let mut nb = Vec::new();
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                    if (dx, dy) == (0, 0) || xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                        continue;
                    }
                    let j = idx(xx as usize, yy as usize);
                    if pass[j] < k {
                        nb.push(refv[j]);
                    }
                }
            }
            if nb.is_empty() {
                rest.push(i);
                continue;
            }
            pass[i] = k;
            let yv = lum(img, x, y);
            let mean = nb.iter().sum::<f64>() / nb.len() as f64;
            // The brightest converged input within 2 pixels.
            let mut max = f64::NEG_INFINITY;
            for yy in y.saturating_sub(2)..(y + 3).min(h) {
                for xx in x.saturating_sub(2)..(x + 3).min(w) {
                    if !noisy[idx(xx, yy)] {
                        max = max.max(lum(img, xx, yy));
                    }
                }
            }
            let mut ex = yv - mean - dl;
            if matches!(e.guard, Guard::Range | Guard::Both | Guard::All) && yv <= max {
                ex = 0.0;
            }
            if matches!(e.guard, Guard::StdError | Guard::Both | Guard::All) {
                ex = ex.min(bound[i]);
            }
            if ex > 0.0 && yv > 0.0 && (ex / ltvis).ceil() >= 2.0 {
                excess[i] = ex;
                refv[i] = yv - ex;
            }
        }
        pending = rest;
    }
    // Spread, source by source in row-major order.
    let ring = Ring::new(p.max_radius);
    for i in 0..w * h {
        if excess[i] <= 0.0 {
            continue;
        }
        let (x, y) = (i % w, i / w);
        let f = excess[i] / lum(img, x, y);
        let wanted = (excess[i] / ltvis).ceil() as usize;
        let targets: Vec<(usize, usize)> = ring
            .offsets()
            .iter()
            .map(|&(dx, dy)| (x as i64 + dx as i64, y as i64 + dy as i64))
            .filter(|&(tx, ty)| tx >= 0 && ty >= 0 && tx < w as i64 && ty < h as i64)
            .map(|(tx, ty)| (tx as usize, ty as usize))
            .take(wanted)
            .collect();
        for c in 0..3 {
            // Of the pixel's own value: what others spread onto it stays.
            let removed = img.at(x, y, c) as f64 * f;
            out[(y * 3 + c) * w + x] -= removed;
            for &(tx, ty) in &targets {
                out[(ty * 3 + c) * w + tx] += removed / targets.len() as f64;
            }
        }
    }
    (out, pending.len())
}

/// A pixel whose `hits` samples of `n` saw `rgb` and the rest its value: a
/// feature partly covering the pixel (or, for one hit, a firefly).
fn partly_covered(img: &mut Img, x: usize, y: usize, rgb: [f32; 3], hits: f32, n: f32) {
    for c in 0..3 {
        let (base, hot) = (img.at(x, y, c), rgb[c]);
        img.set(x, y, c, base + (hot - base) * hits / n);
        img.set(
            x,
            y,
            3 + c,
            hits * (n - hits) / (n * (n - 1.0)) * (hot - base).powi(2),
        );
    }
}

/// Background 1.0 with `count` random fireflies of random colours and sizes,
/// and `count / 4` pixels partly covered by a bright feature (2 to 15 of 16
/// samples hit it).
fn scene(w: usize, h: usize, count: usize, seed: u64) -> Img {
    let mut rng = Rng(seed);
    let mut img = rgbv(w, h);
    for y in 0..h {
        for x in 0..w {
            let g = 0.5 + rng.unit() as f32;
            for c in 0..3 {
                img.set(x, y, c, g);
                img.set(x, y, 3 + c, 1e-6);
            }
        }
    }
    for _ in 0..count {
        let (x, y) = (rng.next_u64() as usize % w, rng.next_u64() as usize % h);
        let hot = (10f64).powf(1.0 + 3.0 * rng.unit()) as f32;
        let rgb = [hot, hot * rng.unit() as f32, hot * rng.unit() as f32];
        firefly(&mut img, x, y, rgb, 16.0);
    }
    for _ in 0..count / 4 {
        let (x, y) = (rng.next_u64() as usize % w, rng.next_u64() as usize % h);
        let hot = (10f64).powf(1.0 + 3.0 * rng.unit()) as f32;
        let hits = 2 + rng.next_u64() % 14;
        partly_covered(&mut img, x, y, [hot; 3], hits as f32, 16.0);
    }
    img
}

#[test]
fn matches_the_reference_in_any_visiting_order() {
    for (seed, guard, guard_confidence) in [
        (1, Guard::None, 0.99),
        (2, Guard::Range, 0.99),
        (3, Guard::StdError, 0.8),
        (4, Guard::Both, 0.8),
        (5, Guard::Both, 0.99),
        (6, Guard::Carriers, 0.99),
        (7, Guard::All, 0.99),
    ] {
        let img = scene(40, 33, 60, seed);
        let mut p = params(guard, 0.01, 6.0);
        p.ep_box.guard_confidence = guard_confidence;
        let (out, stats) = filter(&img, 16.0, &p, &cfg(256, 0, 2));
        for order in 0..3 {
            let (want, unresolved) = reference(&img, 16.0, &p, seed * 10 + order);
            assert_eq!(unresolved as u64, stats.eb().unresolved);
            for (k, (&a, &b)) in out.data.iter().zip(&want).enumerate() {
                // f32 rounding of the output (6e-8 relative) plus the
                // reference's own summation order (a few ulps of f64).
                let tol = 1e-6 * b.abs().max(1.0);
                assert!(
                    (a as f64 - b).abs() <= tol,
                    "{guard:?} order {order} value {k}: {a} vs {b}"
                );
            }
        }
        assert!(stats.eb().spread > 0, "{guard:?}: nothing spread");
        // The stderr bound at 80% is active in these scenes (else those
        // cases test nothing the others do not).
        if guard_confidence == 0.8 {
            assert!(stats.eb().trimmed > 0, "{guard:?}: nothing trimmed");
        }
        // Likewise the carriers guard.
        if guard.carriers() {
            assert!(stats.eb().reliable > 0, "{guard:?}: nothing reliable");
        }
    }
}

#[test]
fn energy_is_exact_for_every_cut() {
    let img = scene(70, 45, 120, 7);
    let p = params(Guard::None, 0.005, 9.0);
    let (a, sa) = filter(&img, 16.0, &p, &cfg(256, 0, 1));
    // Compensated sums and shares that sum to the excess within a few ulps:
    // 1e-12 relative is far above the ~1e-16 seen, far below a lost or
    // doubled pixel (1e-4 here).
    assert_balanced(&sa, "the first cut");
    assert!(sa.eb().spread > 50);
    let (b, _) = same_for_every_cut(&img.data, &job(img.w, img.h, 16.0), &p);
    assert!(bits(&a).iter().zip(&b).all(|(x, y)| *x == y.to_bits()));
}

#[test]
fn untouched_pixels_keep_their_bits_and_spread_is_a_box_of_the_pixels_colour() {
    let (w, h) = (41, 41);
    let mut img = rgbv(w, h);
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                img.set(
                    x,
                    y,
                    c,
                    [0.25, 0.5, 0.75][c] + 0.001 * ((x * 7 + y * 3) % 5) as f32,
                );
            }
        }
    }
    let rgb = [400.0, 200.0, 100.0];
    firefly(&mut img, 20, 20, rgb, 16.0);
    let ltvis = 0.1;
    let p = params(Guard::Range, ltvis, 12.0);
    let (out, stats) = filter(&img, 16.0, &p, &cfg(8, 3, 2));
    assert_eq!((stats.eb().noisy, stats.eb().spread), (1, 1));
    // The excess over the 8 neighbours' mean and D L_tvis, spread equally
    // over ceil(excess / L_tvis) pixels in ring order.
    let y0 = lum(&img, 20, 20);
    let mean: f64 = [
        (19, 19),
        (20, 19),
        (21, 19),
        (19, 20),
        (21, 20),
        (19, 21),
        (20, 21),
        (21, 21),
    ]
    .iter()
    .map(|&(x, y)| lum(&img, x, y))
    .sum::<f64>()
        / 8.0;
    let excess = y0 - mean - 5.0 * ltvis;
    let n = (excess / ltvis).ceil() as usize;
    let ring = Ring::new(12.0);
    assert!(n < ring.offsets().len());
    let reached: Vec<(usize, usize)> = ring.offsets()[..n]
        .iter()
        .map(|&(dx, dy)| ((20 + dx) as usize, (20 + dy) as usize))
        .collect();
    let f = excess / y0;
    for y in 0..h {
        for x in 0..w {
            let inside = reached.contains(&(x, y));
            for c in 0..3 {
                let (a, b) = (out.at(x, y, c), img.at(x, y, c));
                if !inside {
                    assert_eq!(a.to_bits(), b.to_bits(), "({x}, {y}) changed");
                    continue;
                }
                // Each reached pixel gains removed/n of the firefly's own
                // channel: its colour, not grey.
                let gain = img.at(20, 20, c) as f64 * f / n as f64;
                let want = b as f64 + gain
                    - if (x, y) == (20, 20) {
                        img.at(20, 20, c) as f64 * f
                    } else {
                        0.0
                    };
                assert!(
                    (a as f64 - want).abs() <= 1e-6 * want.abs().max(1.0),
                    "({x}, {y}) channel {c}: {a} vs {want}"
                );
            }
        }
    }
    // The added colour has the firefly's chromaticity.
    let (x, y) = reached[n / 2];
    let d: Vec<f64> = (0..3)
        .map(|c| out.at(x, y, c) as f64 - img.at(x, y, c) as f64)
        .collect();
    let src: Vec<f64> = (0..3).map(|c| img.at(20, 20, c) as f64).collect();
    for c in 1..3 {
        // f32 output rounding of values near 0.5 (6e-8) over gains of ~0.003.
        assert!(
            (d[c] / d[0] - src[c] / src[0]).abs() < 1e-3,
            "{d:?} vs {src:?}"
        );
    }
}

#[test]
fn a_cluster_without_converged_neighbours_resolves_over_passes() {
    let (w, h) = (21, 21);
    let mut img = rgbv(w, h);
    // A 5x5 block of noisy pixels: its centre is 3 pixels from the nearest
    // converged one.
    for y in 8..13 {
        for x in 8..13 {
            firefly(&mut img, x, y, [50.0, 50.0, 50.0], 16.0);
        }
    }
    let mut p = params(Guard::None, 0.01, 8.0);
    let (_, s) = filter(&img, 16.0, &p, &cfg(256, 0, 1));
    assert_eq!((s.eb().noisy, s.eb().unresolved, s.eb().passes), (25, 0, 3));
    assert_eq!(s.eb().spread, 25);
    // Two passes: the centre waits, and stays as it was.
    p.ep_box.passes = 2;
    let (out, s) = filter(&img, 16.0, &p, &cfg(256, 0, 1));
    assert_eq!((s.eb().unresolved, s.eb().passes), (1, 2));
    for l in &s.ledger {
        assert!(l.rel_error <= ENERGY_TOL);
    }
    // The centre's own value changes only by what neighbours spread onto it.
    assert!(out.at(10, 10, 0) >= img.at(10, 10, 0));
}

#[test]
fn light_edge_is_left_alone_by_the_range_guard_and_hazed_by_the_papers_rule() {
    // A light (1000) beside a dim wall (1); two columns between them see the
    // light through a quarter and three quarters of each pixel.
    let (w, h) = (30, 20);
    let mut img = rgbv(w, h);
    let var = 998_001.0 * 0.1875; // (1000 - 1)^2 p (1 - p), p = 1/4 or 3/4
    for y in 0..h {
        for x in 0..w {
            let (v, s2) = match x {
                0..=14 => (1.0, 0.0),
                15 => (250.75, var),
                16 => (750.25, var),
                _ => (1000.0, 0.0),
            };
            for c in 0..3 {
                img.set(x, y, c, v);
                img.set(x, y, 3 + c, s2);
            }
        }
    }
    let colour_only = Img {
        nch: 3,
        data: img
            .data
            .chunks(w)
            .enumerate()
            .filter(|(i, _)| i % 6 < 3)
            .flat_map(|(_, row)| row.to_vec())
            .collect(),
        ..img.clone()
    };
    let (guarded, s) = filter(
        &img,
        64.0,
        &params(Guard::Range, 2.0, 16.0),
        &cfg(256, 0, 2),
    );
    assert_eq!((s.eb().noisy, s.eb().spread), (40, 0));
    assert_eq!(s.eb().guarded, 20, "the quarter-lit column");
    assert_eq!(bits(&guarded), bits(&colour_only));
    let (hazed, s) = filter(&img, 64.0, &params(Guard::None, 2.0, 16.0), &cfg(256, 0, 2));
    assert_eq!(s.eb().spread, 20);
    // The paper's rule moves the edge's energy into the dim wall.
    assert!(hazed.at(12, 10, 1) > 2.0, "{}", hazed.at(12, 10, 1));
}

#[test]
fn a_bright_region_of_noisy_pixels_keeps_its_edges_under_the_default_guard() {
    // A 12x10 patch at 100 on a converged floor at 1, every patch pixel with
    // a per-colour sample variance of 100 at 64 samples: S_p = 1.25, noisy
    // against D L_tvis = 0.05, yet the 99-unit step at its edge is far more
    // than noise can explain.
    let (w, h) = (40, 30);
    let mut img = rgbv(w, h);
    let patch = |x: usize, y: usize| (14..26).contains(&x) && (10..20).contains(&y);
    for y in 0..h {
        for x in 0..w {
            let (v, s2) = if patch(x, y) {
                (100.0, 100.0)
            } else {
                (1.0, 0.0)
            };
            for c in 0..3 {
                img.set(x, y, c, v);
                img.set(x, y, 3 + c, s2);
            }
        }
    }
    // The paper's rule, and the range guard (no converged pixel is brighter):
    // the edge is taken for excess, and each pass eats one more ring.
    for guard in [Guard::None, Guard::Range] {
        let (out, s) = filter(&img, 64.0, &params(guard, 0.01, 8.0), &cfg(256, 0, 2));
        assert_eq!(s.eb().noisy, 120);
        // The patch becomes a pyramid whose skirt reaches 8 pixels out.
        assert!(out.at(19, 15, 1) < 70.0, "{guard:?}: {}", out.at(19, 15, 1));
        assert!(out.at(14, 15, 1) < 50.0, "{guard:?}: {}", out.at(14, 15, 1));
        assert!(out.at(8, 15, 1) > 5.0, "{guard:?}: {}", out.at(8, 15, 1));
    }
    // The default: every patch pixel's mean rests on all its samples (the
    // variance of 100 is small beside a mean of 100: k = 63 carriers), so the
    // patch is reliable, not noise, and nothing moves.
    let p = params(FilterParams::new(Method::EpBox, 1).ep_box.guard, 0.01, 8.0);
    assert_eq!(p.ep_box.guard, Guard::All);
    let (out, s) = filter(&img, 64.0, &p, &cfg(256, 0, 2));
    assert_eq!((s.eb().reliable, s.eb().noisy), (120, 0));
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                assert_eq!(out.at(x, y, c).to_bits(), img.at(x, y, c).to_bits());
            }
        }
    }
    // Range and stderr guards alone, 99% bound: a pixel gives at most
    // t_99(63) S_p = 2.66 x 1.25 = 3.3 of its 100.
    let p = params(Guard::Both, 0.01, 8.0);
    let (out, s) = filter(&img, 64.0, &p, &cfg(256, 0, 2));
    assert!(s.eb().trimmed > 0);
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (out.at(x, y, 1) as f64, img.at(x, y, 1) as f64);
            if patch(x, y) {
                assert!(a >= 0.96 * b, "({x}, {y}): {a}");
            } else {
                // What leaves the patch: at most 3.3 per patch pixel, over
                // its ring; next to the patch the shares of many sources
                // add up to 2.3 (measured), against 40 for the others.
                assert!(a <= 2.5, "({x}, {y}): {a}");
            }
        }
    }
    for l in &s.ledger {
        assert!(l.rel_error <= ENERGY_TOL);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, .. ProptestConfig::default() })]

    /// Random sizes, fireflies, guards and cuts: the ledger balances and the
    /// bits do not depend on tiles, strips or threads.
    #[test]
    fn energy_and_invariance_hold_for_random_renders(
        w in 1usize..30, h in 1usize..30, count in 0usize..40, seed in any::<u64>(),
        guard in 0u8..6, radius in 1.0f64..12.0, passes in 1usize..5,
        tile in 1usize..20, strip in 1usize..40, threads in 1usize..4,
    ) {
        let img = scene(w, h, count, seed);
        let guard = [
            Guard::None,
            Guard::Range,
            Guard::StdError,
            Guard::Both,
            Guard::Carriers,
            Guard::All,
        ][guard as usize];
        let mut p = params(guard, 0.01, radius);
        p.ep_box.passes = passes;
        energy_and_invariance(&img, &p, (tile, strip, threads))?;
    }

    /// ep-gauss at S = 1 reads the same statistics (its carriers rule, whose
    /// compact test looks 2 rows away): the same invariants.
    #[test]
    fn ep_gauss_with_statistics_keeps_energy_and_invariance(
        w in 1usize..30, h in 1usize..30, count in 0usize..40, seed in any::<u64>(),
        max_radius in 0.6f64..8.0, tile in 1usize..20, strip in 1usize..40, threads in 1usize..4,
    ) {
        let img = scene(w, h, count, seed);
        let mut p = FilterParams::new(Method::EpGauss, 1);
        p.max_radius = max_radius;
        energy_and_invariance(&img, &p, (tile, strip, threads))?;
    }
}

/// At 16 samples per pixel: the ledger balances to [`ENERGY_TOL`], every
/// value is finite, and `cut` (tile, strip rows, threads) gives the bits,
/// digest, ledger and counts of one whole-image pass.
fn energy_and_invariance(
    img: &Img,
    p: &FilterParams,
    cut: (usize, usize, usize),
) -> Result<(), TestCaseError> {
    let (a, sa) = invariant(
        &img.data,
        &job(img.w, img.h, 16.0),
        p,
        &[Cut::from((256, 0, 1)), Cut::from(cut)],
    )
    .map_err(TestCaseError::fail)?;
    for l in &sa.ledger {
        prop_assert!(
            l.rel_error <= ENERGY_TOL,
            "{}: {:e}",
            l.channel,
            l.rel_error
        );
    }
    prop_assert!(a.iter().all(|v| v.is_finite()));
    Ok(())
}

mod files {

    use crate::exr_io::{tmpdir, write_named as write};

    use crate::common::epfilt_run as epfilt;

    const RGBV: [&str; 6] = ["R", "G", "B", "variance.R", "variance.G", "variance.B"];

    #[test]
    fn plan_matches_hand_computed_figures() {
        let dir = tmpdir();
        let pilot = dir.path().join("pilot.exr");
        // 100x100 at 16 samples, as the paper's pilot: every pixel 0.5 grey
        // with sample variance 0.01 in each channel.
        write(&pilot, 100, 100, &RGBV, &[("spp", 16)], |_, _, c| {
            if c < 3 {
                0.5
            } else {
                0.01
            }
        });
        let o = epfilt(&["plan", pilot.to_str().unwrap(), "--json"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let get = |k: &str| j[k].as_f64().unwrap_or_else(|| panic!("no key {k}: {j}"));
        // By hand: L_ave = 0.5 (the weights sum to 1); L_tvis = 0.5 / 128;
        // S̄ = sqrt(0.01 / 16) = 0.025; M_t = (4 * 0.025 / (5 * 0.00390625))^2
        // = 5.12^2 = 26.2144; ceiling 4 M_t = 104.8576; Eq. 8 with
        // d = 5 * 0.00390625 / 0.5 = 0.0390625: ln 0.2 / ln 0.9609375 = 40.39 -> 41.
        // Tolerance 1e-9 relative: f32 inputs 0.5 and 0.01 are exact and
        // 0.01 f32 differs from 0.01 by 2e-10 relative.
        for (k, want) in [
            ("l_ave", 0.5),
            ("l_tvis", 0.00390625),
            ("mean_std_error", 0.025),
            ("m_t", 26.2144),
            ("m_t_ceiling", 104.8576),
            ("m_t_worst_case", 41.0),
        ] {
            let got = get(k);
            assert!((got - want).abs() <= 1e-6 * want, "{k}: {got} vs {want}");
        }
        let table = epfilt(&["plan", pilot.to_str().unwrap(), "--d", "1"]);
        let text = String::from_utf8_lossy(&table.stdout);
        // D = 1: M_t = 25^2 * 26.2144 / 25... = (5.12 * 5)^2 = 655.36 -> 656.
        assert!(
            text.contains("M_t (Eq. 10)") && text.contains("656"),
            "{text}"
        );
    }

    #[test]
    fn filter_finds_variance_by_name_or_says_what_the_file_has() {
        let dir = tmpdir();
        let inp = dir.path().join("pt.exr");
        write(&inp, 40, 30, &RGBV, &[("spp", 64)], |x, y, c| {
            let hot = (x, y) == (20, 15);
            match (c < 3, hot) {
                (true, true) => 200.0,
                (true, false) => 1.0,
                (false, true) => 2.5e6,
                (false, false) => 0.0,
            }
        });
        let out = dir.path().join("out.exr");
        let report = dir.path().join("r.json");
        let o = epfilt(&[
            "filter",
            inp.to_str().unwrap(),
            out.to_str().unwrap(),
            "--method",
            "ep-box",
            "-q",
            "--report",
            report.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        assert_eq!(r["samples_spread"], 1);
        assert_eq!(r["ep_box"]["variance_channels"][0], "variance.R");
        assert!(r["ep_box"]["spp_from"].as_str().unwrap().contains("spp"));
        let written: Vec<&str> = r["channels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_str().unwrap())
            .collect();
        assert_eq!(written[..3], ["R", "G", "B"]);
        // The statistics are carried too, averaged (at S = 1: copied).
        assert_eq!(r["channel_rules"]["variance.R"], "average");
        assert!(r["energy_rel_error"]
            .as_array()
            .unwrap()
            .iter()
            .all(|e| e.as_f64().unwrap() <= crate::common::ENERGY_TOL));
        // The same with the channel and count named, and --spp overriding.
        let named = dir.path().join("named.exr");
        let o = epfilt(&[
            "filter",
            inp.to_str().unwrap(),
            named.to_str().unwrap(),
            "--method",
            "ep-box",
            "--variance-channel",
            "variance",
            "--spp",
            "64",
            "-q",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_eq!(
            crate::common::image_bytes(&out),
            crate::common::image_bytes(&named)
        );
        // A colour channel may double as the (luminance) variance.
        let o = epfilt(&[
            "filter",
            inp.to_str().unwrap(),
            dir.path().join("r.exr").to_str().unwrap(),
            "--method",
            "ep-box",
            "--variance-channel",
            "R",
            "-q",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        // No variance: one line listing the channels the file has.
        let plain = dir.path().join("plain.exr");
        write(&plain, 8, 8, &["R", "G", "B", "Z"], &[], |_, _, _| 1.0);
        let o = epfilt(&[
            "filter",
            plain.to_str().unwrap(),
            "x.exr",
            "--method",
            "ep-box",
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(
            o.status.code(),
            Some(1),
            "the input lacks what the job needs: {err}"
        );
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(
            err.contains("plain.exr")
                && err.contains("no variance channels")
                && err.contains("B, G, R, Z"),
            "{err}"
        );
        // No sample count anywhere.
        let nospp = dir.path().join("nospp.exr");
        write(&nospp, 8, 8, &RGBV, &[], |_, _, _| 1.0);
        let o = epfilt(&[
            "filter",
            nospp.to_str().unwrap(),
            "x.exr",
            "--method",
            "ep-box",
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("--spp"), "{err}");
        // A wrong channel name lists the channels.
        let o = epfilt(&[
            "filter",
            inp.to_str().unwrap(),
            "x.exr",
            "--method",
            "ep-box",
            "--variance-channel",
            "var.Y",
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("var.Y") && err.contains("variance.G"), "{err}");
    }
}

/// The carriers guard at its edges: no variance, every pixel noisy (carried
/// by one sample, or by all), one and two samples per pixel, and values from
/// 1e-30 to 1e30: finite output, exact energy, and the decision each case
/// calls for.
#[test]
fn the_carriers_rule_at_its_edges() {
    let (w, h) = (23, 17);
    let default = FilterParams::new(Method::EpBox, 1);
    let unchanged = |out: &Img, img: &Img| {
        (0..h).all(|y| {
            (0..w).all(|x| (0..3).all(|c| out.at(x, y, c).to_bits() == img.at(x, y, c).to_bits()))
        })
    };
    let exact = |s: &RunStats| s.ledger.iter().all(|l| l.rel_error <= ENERGY_TOL);
    // No variance anywhere: nothing is noisy, nothing moves.
    let mut img = rgbv(w, h);
    for y in 0..h {
        for x in 0..w {
            img.set(x, y, 1, 0.5 + (x * y) as f32);
        }
    }
    let (out, s) = filter(&img, 16.0, &params(Guard::All, 0.01, 8.0), &cfg(256, 0, 2));
    assert_eq!((s.eb().noisy, s.eb().reliable), (0, 0));
    assert!(unchanged(&out, &img) && exact(&s));
    // Every pixel hit by one sample of 16: all noise, nothing converged to
    // spread onto, so all unresolved and left as they are.
    let mut img = rgbv(w, h);
    for y in 0..h {
        for x in 0..w {
            firefly(&mut img, x, y, [400.0; 3], 16.0);
        }
    }
    let (out, s) = filter(&img, 16.0, &params(Guard::All, 0.01, 8.0), &cfg(256, 0, 2));
    assert_eq!(s.eb().noisy, (w * h) as u64);
    assert_eq!(s.eb().unresolved, (w * h) as u64);
    assert!(unchanged(&out, &img) && exact(&s));
    // Every pixel hit by all its samples but for one: reliable, kept.
    let mut img = rgbv(w, h);
    for y in 0..h {
        for x in 0..w {
            partly_covered(&mut img, x, y, [400.0; 3], 15.0, 16.0);
        }
    }
    let (out, s) = filter(&img, 16.0, &params(Guard::All, 0.01, 8.0), &cfg(256, 0, 2));
    assert_eq!((s.eb().noisy, s.eb().reliable), (0, (w * h) as u64));
    assert!(unchanged(&out, &img) && exact(&s));
    // One sample per pixel: no variance to test, nothing treated (a count
    // channel of 1, so the job itself is valid); two samples: a firefly of
    // two is one hit, below the floor of 2 carriers, and is spread.
    for n in [1.0f32, 2.0] {
        let mut img = Img::new(w, h, 7, |_, _, c| match c {
            0..=2 => 1.0,
            6 => n,
            _ => 0.0,
        });
        if n == 2.0 {
            for c in 0..3 {
                img.set(11, 8, c, (1.0 + 500.0) / 2.0);
                img.set(11, 8, 3 + c, 499.0f32.powi(2) / 2.0);
            }
        }
        let mut j = job(w, h, 0.0);
        j.aux.push("spp".into());
        j.stats.as_mut().unwrap().spp = Spp::Channel(6);
        let (out, s) = filter_in_memory(
            img.data.clone(),
            &j,
            &params(Guard::All, 0.01, 8.0),
            &cfg(256, 0, 2),
        )
        .unwrap();
        let out = Img {
            w,
            h,
            nch: 3,
            data: out,
        };
        assert!(exact(&s));
        if n == 1.0 {
            assert_eq!(s.eb().noisy, 0);
            assert!(unchanged(&out, &img));
        } else {
            assert_eq!((s.eb().noisy, s.eb().spread), (1, 1), "{:?}", s.eb());
        }
    }
    // 1e-30 beside 1e30, with variances up to the largest f32 (whose
    // square roots and squares must not overflow into NaN).
    let mut img = rgbv(w, h);
    let mut rng = Rng(5);
    for y in 0..h {
        for x in 0..w {
            let (v, var) = match rng.next_u64() % 4 {
                0 => (1e30, f32::MAX),
                1 => (1e-30, 1e-30),
                2 => (1e30, 0.0),
                _ => (1e-30, 0.0),
            };
            for c in 0..3 {
                img.set(x, y, c, v);
                img.set(x, y, 3 + c, var);
            }
        }
    }
    let (out, s) = filter(&img, 16.0, &default, &cfg(256, 0, 2));
    assert!(out.data.iter().all(|v| v.is_finite()), "{:?}", s.eb());
    assert!(exact(&s));
}

#[test]
fn progress_covers_the_first_pass_then_the_stream() {
    let dir = crate::exr_io::tmpdir();
    let input = dir.path().join("pt.exr");
    let out = dir.path().join("out.exr");
    let i = input.to_str().expect("UTF-8 path");
    crate::common::epfilt_ok(&[
        "synth",
        "-q",
        "-o",
        i,
        "--spp",
        "16",
        "--variance",
        "--size",
        "48x40",
    ]);
    let job = epfilt::FilterJob::new(&input, &out, FilterParams::new(Method::EpBox, 1));
    let calls = std::sync::Mutex::new(Vec::new());
    epfilt::filter_file(&job, &|done, total| {
        calls.lock().unwrap().push((done, total))
    })
    .expect("filter");
    let calls = calls.into_inner().unwrap();
    let share: Vec<f64> = calls.iter().map(|&(d, t)| d as f64 / t as f64).collect();
    // The first pass reports the first half, the stream the second (of
    // twice the 40 rows); never backwards, and done at the end.
    assert!(calls.iter().all(|&(_, t)| t == 2 * 40), "{calls:?}");
    assert!(share.first().is_some_and(|&s| s <= 0.5), "{calls:?}");
    assert!(share.contains(&0.5), "{calls:?}");
    assert!(share.windows(2).all(|w| w[0] <= w[1]), "{calls:?}");
    assert_eq!(share.last(), Some(&1.0), "{calls:?}");
}
