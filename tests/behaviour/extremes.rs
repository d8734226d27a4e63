//! Numerical extremes: finite output, exact ledger, no panic — each a named
//! case with its assertion.

use crate::common::*;
use epfilt::{filter_in_memory, Grid, Method, PipelineConfig, Precision, StripLayout};

fn all_methods_exact(img: &Img, s: usize, what: &str) -> Vec<Img> {
    GAUSSIAN_FAMILY
        .iter()
        .map(|&m| {
            let (out, stats) = run(img, s, &params(m, s), &PipelineConfig::default());
            assert_balanced(&stats, &format!("{what} {m:?}"));
            assert!(
                out.data.iter().all(|v| v.is_finite()),
                "{what} {m:?}: non-finite output"
            );
            out
        })
        .collect()
}

#[test]
fn subnormal_values() {
    let img = Img::new(15, 12, 3, |x, y, c| {
        f32::from_bits(1 + ((x * 7 + y * 3 + c) % 50) as u32)
    });
    for out in all_methods_exact(&img, 3, "subnormals") {
        assert!(out.data.iter().all(|v| *v >= 0.0));
    }
}

#[test]
fn tiny_and_huge_values_inside_one_kernel() {
    let mut img = Img::new(24, 24, 3, |_, _, _| 1e-30);
    for (x, y) in [(10, 10), (11, 10), (0, 0), (23, 23)] {
        for c in 0..3 {
            img.set(x, y, c, 1e30);
        }
    }
    all_methods_exact(&img, 3, "1e-30 next to 1e30");
}

#[test]
fn values_near_f32_max_accumulate_without_overflow_or_are_refused_on_output() {
    // Every sample at f32::MAX / 2: the f64 sums cannot overflow; the output
    // (the same mean) fits in f32.
    let img = Img::new(9, 9, 3, |_, _, _| f32::MAX / 2.0);
    all_methods_exact(&img, 3, "near f32::MAX");
    // A firefly of f32::MAX among them spreads; its output stays finite.
    let mut img = Img::new(9, 9, 1, |_, _, _| 1.0);
    img.set(4, 4, 0, f32::MAX);
    all_methods_exact(&img, 3, "f32::MAX firefly");
    // S = 1 box of f32::MAX is f32::MAX itself; in f16 it cannot be held: refused.
    let img = Img::new(3, 3, 1, |_, _, _| f32::MAX);
    let job = StripLayout::new(
        Grid {
            in_w: 3,
            in_h: 3,
            s: 1,
        },
        vec!["Y".into()],
        vec![1.0],
    );
    let err = epfilt::pipeline::run(
        epfilt::pipeline::MemorySource::new(img.data.clone(), 3),
        epfilt::pipeline::MemorySink::with_precision(Precision::F16),
        &job,
        &params(Method::Box, 1),
        &PipelineConfig::default(),
        &|_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("does not fit in f16"), "{err}");
}

#[test]
fn all_zero_and_constant_images() {
    for out in all_methods_exact(&Img::new(12, 9, 3, |_, _, _| 0.0), 3, "zeros") {
        assert!(out.data.iter().all(|v| *v == 0.0));
    }
    for out in all_methods_exact(&Img::new(12, 9, 3, |_, _, _| -2.5), 3, "negative constant") {
        assert!(out.data.iter().all(|v| (*v + 2.5).abs() < 1e-6));
    }
}

#[test]
fn one_by_one_one_by_n_n_by_one_and_narrower_than_the_kernel() {
    for (w, h) in [(1, 1), (1, 17), (17, 1), (2, 2), (3, 40)] {
        let mut img = Img::new(w * 3, h * 3, 3, |x, y, c| 0.3 + 0.01 * (x + y + c) as f32);
        img.set(0, 0, 1, 5e3);
        all_methods_exact(&img, 3, &format!("{w}x{h}"));
        // With max-radius 16 the widest kernel (3 x 16 = 48 pixels) is far wider
        // than these images: reflection folds it many times, energy stays exact.
    }
}

#[test]
fn supersample_larger_than_the_image_is_refused() {
    let img = Img::new(2, 5, 1, |_, _, _| 1.0);
    let job = StripLayout::new(
        Grid {
            in_w: 2,
            in_h: 5,
            s: 3,
        },
        vec!["Y".into()],
        vec![1.0],
    );
    let err = filter_in_memory(
        img.data,
        &job,
        &params(Method::Gauss, 3),
        &PipelineConfig::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("larger than the image"), "{err}");
}

#[test]
fn zero_tolerance_spreads_every_varying_sample_to_the_cap_and_a_huge_one_equals_gauss() {
    let img = fireflies(45, 30, 3, 0.02, 3);
    let s = 3;
    let mut p = params(Method::EpGauss, s);
    p.tolerance = 0.0;
    p.max_radius = 2.0;
    // The paper's rule (`--support 0`, both sides of Relation 14): every
    // sample whose luminance differs from its average is noisy, and none can
    // meet a zero tolerance: all capped.
    let mut paper = p.clone();
    paper.support = 0;
    let (_, stats) = run(&img, s, &paper, &PipelineConfig::default());
    assert!(
        stats.eg().noisy > (45 * 30 / 2) as u64,
        "noisy {}",
        stats.eg().noisy
    );
    assert_eq!(stats.eg().capped, stats.eg().noisy);
    assert!(stats.ledger.iter().all(|l| l.rel_error <= ENERGY_TOL));
    // The defaults: only samples brighter than their average are noisy (at
    // least every firefly), all capped but those kept as features.
    let fireflies = (45.0f64 * 30.0 * 0.02).ceil() as u64;
    let (_, stats) = run(&img, s, &p, &PipelineConfig::default());
    assert!(stats.eg().noisy >= fireflies, "{:?}", stats.eg());
    assert!(stats.eg().kept > 0);
    assert_eq!(stats.eg().capped + stats.eg().kept, stats.eg().noisy);
    assert!(stats.ledger.iter().all(|l| l.rel_error <= ENERGY_TOL));
    p.tolerance = 1e30;
    let (huge, stats) = run(&img, s, &p, &PipelineConfig::default());
    assert_eq!(stats.eg().noisy, 0);
    let (gauss, _) = run(
        &img,
        s,
        &params(Method::Gauss, s),
        &PipelineConfig::default(),
    );
    assert_eq!(bits(&huge), bits(&gauss));
}

/// Kernels narrower than a pixel's ring (`--max-radius` under 0.45 px at
/// `--cutoff 1`): the support rule still reads the background ring about a
/// firefly, at the image's edges too, and the energy stays exact.
#[test]
fn the_narrowest_kernels_with_fireflies_on_every_edge() {
    let (w, h) = (13, 9);
    for s in [2, 3, 4] {
        let edge = |x: usize, y: usize| {
            let (px, py) = (x / s, y / s);
            // Pairs side by side: each firefly has a bright neighbour, so
            // the support rule weighs its background.
            (px == 0 || px == w - 1 || py == 0 || py == h - 1) && (x + 3 * y) % 7 < 2
        };
        let img = Img::new(w * s, h * s, 3, |x, y, c| {
            if edge(x, y) {
                5000.0 + c as f32
            } else {
                1.0 + ((x + y) % 3) as f32 * 0.1
            }
        });
        for max_radius in [0.05, 0.3, 0.8] {
            let mut p = params(Method::EpGauss, s);
            (p.radius, p.cutoff, p.max_radius) = (0.05, 1.0, max_radius);
            let (out, stats) = run(&img, s, &p, &PipelineConfig::default());
            assert!(
                stats.eg().noisy > 0,
                "S = {s}, {max_radius}: {:?}",
                stats.eg()
            );
            assert!(
                stats.ledger.iter().all(|l| l.rel_error <= ENERGY_TOL),
                "S = {s}, {max_radius}: {:?}",
                stats.ledger
            );
            assert!(out.data.iter().all(|v| v.is_finite()));
        }
    }
}

#[test]
fn half_float_input_at_its_maximum() {
    let dir = crate::exr_io::tmpdir();
    let input = dir.path().join("max.exr");
    let mut img = Img::new(18, 12, 3, |_, _, _| 1.0);
    for c in 0..3 {
        img.set(5, 5, c, 65504.0);
        img.set(0, 0, c, 65504.0);
    }
    crate::exr_io::write_rgb(
        &input,
        &img,
        exr::prelude::Compression::PIZ,
        exr::prelude::Blocks::ScanLines,
        true,
        exr::prelude::LineOrder::Increasing,
    );
    for m in GAUSSIAN_FAMILY {
        let out = dir.path().join(format!("{}.exr", m.name()));
        let report =
            epfilt::filter_file(&crate::exr_io::job(&input, &out, m, 3), &|_, _| {}).unwrap();
        assert!(report.energy_rel_error.iter().all(|e| *e <= ENERGY_TOL));
        assert!(crate::exr_io::read_planar(&out)
            .data
            .iter()
            .all(|v| v.is_finite()));
    }
}
