//! Bit-identical output whatever the tile size, strip height and thread count.

use crate::common::*;
use epfilt::{Method, RunStats, StripLayout};
use proptest::prelude::*;

/// Every method, through every cut of `common::CUTS`: one answer.
#[test]
fn every_method_gives_the_same_bits_for_every_cut() {
    // 70 output columns: tile 16 does not divide it.
    let s = 3;
    let mut img = fireflies(70 * s, 40 * s, 3, 0.01, 5);
    // Small bright features (2x2 and 3x1 samples) across pixel, strip and
    // tile boundaries: ep-gauss keeps them (support), so both of its paths
    // are cut every way.
    for &(x0, y0, dx, dy) in &[
        (47, 14, 2, 2),
        (95, 20, 3, 1),
        (140, 59, 2, 2),
        (20, 95, 1, 3),
    ] {
        for y in y0..y0 + dy {
            for x in x0..x0 + dx {
                for c in 0..3 {
                    img.set(x, y, c, 3000.0);
                }
            }
        }
    }
    for m in Method::ALL {
        if m == Method::EpBox {
            continue; // pixel resolution with variance: below
        }
        let (_, stats) = same_for_every_cut(&img.data, &job_for(&img, s), &params(m, s));
        if m == Method::EpGauss {
            let c = stats.eg();
            assert!(c.kept >= 4 && c.spread > 0, "{c:?}");
        }
    }
    // ep-box: the mean and variance of 16 samples per pixel, fireflies and
    // partly covered pixels (epfilt synth's lights scene).
    let sc = epfilt::synth::Scene {
        kind: epfilt::synth::SceneKind::Lights,
        w: 70,
        h: 41,
        seed: 4,
        hot: 1e4,
    };
    let mut job = job_for(&Img::new(70, 41, 3, |_, _, _| 0.0), 1);
    with_variance(&mut job);
    let (_, stats) = same_for_every_cut(&sc.spp_rows(16, 0, 41), &job, &params(Method::EpBox, 1));
    let c = stats.eb();
    assert!(c.spread > 0 && c.reliable > 0, "{c:?}");
}

/// `job` with a variance pass of 16 samples per pixel after its channels
/// (`variance.R`, `.G`, `.B`), as ep-box reads it.
fn with_variance(job: &mut StripLayout) {
    let at = job.channels.len();
    job.aux = ["variance.R", "variance.G", "variance.B"]
        .map(String::from)
        .to_vec();
    job.stats = Some(epfilt::filter::ep_box::StatsLayout {
        variance: vec![at, at + 1, at + 2],
        kind: epfilt::filter::ep_box::VarianceKind::Sample,
        mean_y: None,
        spp: epfilt::filter::ep_box::Spp::Fixed(16.0),
    });
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, .. ProptestConfig::default() })]

    /// Random sizes, super-sampling, extreme values: energy exact and the same
    /// bits for any cut of the work.
    #[test]
    fn energy_and_invariance_hold_for_random_images(
        w in 1usize..14, h in 1usize..14, s in 1usize..5,
        seed in any::<u64>(),
        tile in 1usize..20, strip in 1usize..40, threads in 1usize..4,
        extreme in 0u8..4,
    ) {
        let mut rng = Rng(seed);
        let mut img = Img::new(w * s, h * s, 3, |_, _, _| 0.0);
        for v in img.data.iter_mut() {
            let u = rng.unit();
            *v = match extreme {
                0 => (u * 2.0) as f32,
                1 => if u < 0.05 { 1e30 } else if u < 0.5 { 1e-30 } else { (u as f32) * 1e-3 },
                2 => if u < 0.1 { f32::from_bits(1 + (rng.next_u64() % 1000) as u32) } else { 0.0 },
                _ => ((u - 0.4) * 1e5) as f32,
            };
        }
        for m in GAUSSIAN_FAMILY {
            let p = params(m, s);
            let cuts = [(256, 96, 1), (tile, strip, threads)].map(Cut::from);
            let (a, stats) = invariant(&img.data, &job_for(&img, s), &p, &cuts)
                .map_err(TestCaseError::fail)?;
            for l in &stats.ledger {
                prop_assert!(l.rel_error <= ENERGY_TOL, "{:?} {}: {:e}", m, l.channel, l.rel_error);
            }
            prop_assert!(a.iter().all(|v| v.is_finite()));
        }
    }

    /// `--edge pad`: sizes that are not a multiple of S, completed with zero
    /// samples; energy exact (the ledger weighs partial pixels by their
    /// coverage), every value finite, the same bits for any cut.
    #[test]
    fn a_padded_edge_keeps_energy_and_invariance(
        w in 1usize..20, h in 1usize..20, s in 2usize..5,
        seed in any::<u64>(),
        tile in 1usize..20, strip in 1usize..40, threads in 1usize..4,
    ) {
        let mut rng = Rng(seed);
        let mut img = Img::new(w, h, 3, |_, _, _| 0.0);
        for v in img.data.iter_mut() {
            let u = rng.unit();
            *v = if u < 0.05 { (1e2 + u * 1e6) as f32 } else { (u * 2.0) as f32 };
        }
        let mut job = rgb_job(w.div_ceil(s) * s, h.div_ceil(s) * s, s);
        job.padded_from = Some((w, h));
        for m in GAUSSIAN_FAMILY {
            let p = params(m, s);
            let cuts = [(256, 96, 1), (tile, strip, threads)].map(Cut::from);
            let (a, stats) = invariant(&img.data, &job, &p, &cuts).map_err(TestCaseError::fail)?;
            prop_assert_eq!(a.len(), 3 * w.div_ceil(s) * h.div_ceil(s));
            for l in &stats.ledger {
                prop_assert!(l.rel_error <= ENERGY_TOL, "{:?} {}: {:e}", m, l.channel, l.rel_error);
            }
            prop_assert!(a.iter().all(|v| v.is_finite()));
        }
    }
}

/// Dense fireflies of the paper's dynamic range (10% of the samples at
/// 1e2..1e5, some on the borders and corners): wide kernels, a width search
/// whose `D` is not monotone, reflections on every side. One answer for every
/// cut, energy within the ledger's bound, and the search's work reported.
/// Widths up to 8 px: the 2x and the 4x coarse grids both take part.
#[test]
fn dense_wide_fireflies_give_one_answer_and_keep_energy() {
    let s = 3;
    let img = fireflies(50 * s, 37 * s, 3, 0.1, 11);
    let mut p = params(Method::EpGauss, s);
    p.max_radius = 8.0; // wider than the image is tall in places: reflections
    let (_, stats) = same_for_every_cut(&img.data, &job_for(&img, s), &p);
    let c = stats.eg();
    assert!(c.spread > 300, "{c:?}");
    assert!(c.search_cost > 0 && c.spread_taps > c.spread, "{c:?}");
    // Both coarse grids take part (from 2 px the 2x one, from 4 px the 4x),
    // and the widths from 3 px are checked on the summed-area table's bound
    // (the defaults' `--bound-from`) wherever its rows are in the image.
    assert!(c.coarse4 > 0 && c.coarse > c.coarse4, "{c:?}");
    assert!(p.bound_from > 0.0 && c.bounded > 0, "{c:?}");
    assert_balanced(&stats, "dense fireflies");
}

/// A run under a smaller `--max-memory` takes shorter strips and fewer
/// blocks read ahead, says so in its report, and writes the same bytes; below
/// its floor it is refused, naming the floor.
#[test]
fn a_smaller_memory_budget_runs_smaller_and_gives_the_same_bytes() {
    use epfilt::{filter_file, FilterJob, FilterParams};
    let dir = crate::exr_io::tmpdir();
    let input = dir.path().join("in.exr");
    // Wide and short: strips and the reader's window are most of what it holds.
    let path = |name: &str| dir.path().join(name);
    let p = |name: &str| path(name).display().to_string();
    epfilt_ok(&[
        "synth",
        "-q",
        "--scene",
        "mixed",
        "--size",
        "2048x48",
        "-s",
        "3",
        "-o",
        &p("in.exr"),
    ]);
    for m in [Method::EpGauss, Method::Box, Method::Gauss] {
        let job = |out: &str, limit: Option<u64>| {
            let mut j = FilterJob::new(&input, path(out), FilterParams::new(m, 3));
            j.max_memory = limit;
            j
        };
        let full = filter_file(&job("full.exr", None), &|_, _| {}).expect("default run");
        assert_eq!(full.window_blocks, None, "{m:?}");
        let by_default = if full.threads > 1 { 2 } else { 1 };
        assert_eq!(full.strips_in_flight, by_default, "{m:?}");
        let floor = filter_file(&job("none.exr", Some(1)), &|_, _| {}).unwrap_err();
        let text = floor.to_string();
        assert!(
            text.contains("--max-memory") && text.contains("at least about"),
            "{text}"
        );
        assert!(
            !path("none.exr").exists(),
            "{m:?}: nothing written when refused"
        );
        // Budgets from the default estimate down to the floor: each run fits
        // its budget by the estimate, and every one writes the default
        // run's bytes.
        let floor: u64 = text
            .split("at least about ")
            .nth(1)
            .and_then(|t| t.split(' ').next())
            .and_then(|n| n.parse::<u64>().ok())
            .expect("the error names its floor")
            << 20;
        assert!(floor < full.memory_estimate_bytes, "{m:?}");
        let mut smallest = full.strip_rows;
        for k in 1..=6 {
            let limit = floor + (full.memory_estimate_bytes - floor) * (6 - k) / 6;
            let out = format!("b{k}.exr");
            match filter_file(&job(&out, Some(limit)), &|_, _| {}) {
                Ok(r) => {
                    assert!(r.memory_estimate_bytes <= limit, "{m:?} {k}");
                    assert!(r.strip_rows <= smallest, "{m:?} {k}");
                    // Under any budget smaller than the default's, one strip
                    // in flight: the second is the first thing given up.
                    assert_eq!(r.strips_in_flight, 1, "{m:?} {k}");
                    smallest = r.strip_rows;
                    assert_eq!(r.digest, full.digest, "{m:?} {k}");
                    assert_eq!(image_bytes(&path(&out)), image_bytes(&path("full.exr")));
                }
                Err(e) => assert!(e.to_string().contains("at least about"), "{m:?} {k}: {e}"),
            }
        }
        assert!(
            smallest < full.strip_rows,
            "{m:?}: some budget shortened the strips"
        );
    }
}

/// The pixel stages spread the colour and carry the other channels (alpha,
/// an AOV) as read: a source holds values of the spread channels only, and
/// every cut (treatment tasks cut in columns too) gives one answer, the
/// carried bits untouched and the energy exact.
#[test]
fn pixel_stages_carry_what_they_do_not_spread_through_every_cut() {
    use epfilt::pipeline::ChannelMode;
    let (w, h) = (70, 41);
    // A carried value of each kind: negative zero, signed, large.
    let aov = |x: usize, y: usize| match (x + 3 * y) % 4 {
        0 => -0.0,
        1 => -(x as f32),
        2 => 1e30,
        _ => (x * y) as f32 * 0.25,
    };
    let carry = |job: &mut StripLayout| {
        job.channels.push("aov.V".into());
        job.luminance.push(0.0);
        job.modes.push(ChannelMode::Nearest);
    };
    let check = |data: &[f32], nall: usize, out: &[f32], stats: &RunStats| {
        for y in 0..h {
            for x in 0..w {
                for c in [3, 4] {
                    let (i, o) = ((y * nall + c) * w + x, (y * 5 + c) * w + x);
                    assert_eq!(
                        out[o].to_bits(),
                        data[i].to_bits(),
                        "({x}, {y}) channel {c}"
                    );
                }
            }
        }
        assert_balanced(stats, "carried channels");
    };
    // ep-gauss: RGBA fireflies and the AOV.
    let mut img = fireflies(w, h, 5, 0.1, 9);
    for y in 0..h {
        for x in 0..w {
            img.set(x, y, 4, aov(x, y));
        }
    }
    let mut job = job_for(&Img::new(w, h, 4, |_, _, _| 0.0), 1);
    carry(&mut job);
    let (out, stats) = same_for_every_cut(&img.data, &job, &params(Method::EpGauss, 1));
    assert!(stats.eg().spread > 0, "{:?}", stats.eg());
    check(&img.data, 5, &out, &stats);
    // ep-box: the lights scene's mean and variance, alpha and the AOV
    // between the colour and the variance.
    let sc = epfilt::synth::Scene {
        kind: epfilt::synth::SceneKind::Lights,
        w,
        h,
        seed: 4,
        hot: 1e4,
    };
    let rows = sc.spp_rows(16, 0, h);
    let mut data = Vec::with_capacity(rows.len() / 6 * 8);
    for (y, row) in rows.chunks_exact(6 * w).enumerate() {
        data.extend_from_slice(&row[..3 * w]);
        data.extend((0..w).map(|x| 0.25 + x as f32 * 0.01));
        data.extend((0..w).map(|x| aov(x, y)));
        data.extend_from_slice(&row[3 * w..]);
    }
    let mut job = job_for(&Img::new(w, h, 4, |_, _, _| 0.0), 1);
    carry(&mut job);
    with_variance(&mut job);
    let (out, stats) = same_for_every_cut(&data, &job, &params(Method::EpBox, 1));
    assert!(stats.eb().spread > 0, "{:?}", stats.eb());
    check(&data, 8, &out, &stats);
}
