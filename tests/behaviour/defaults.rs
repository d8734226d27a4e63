//! ep-gauss's defaults and `--quality` presets: the defaults remove more of a
//! synthetic scene's noise than the paper's rule and the old defaults, the
//! presets are ordered, and every preset's knob values reach the report.

use epfilt::filter::Quality;
use epfilt::synth::{Scene, SceneKind};
use epfilt::{filter_file, FilterJob, FilterParams, Method, PipelineConfig};

use crate::common::*;

/// The scenes' output size: odd, not a multiple of a tile.
const W: usize = 150;
const H: usize = 113;

/// relMSE as `scripts/eval-renders` measures it: `(x - r)^2 / (r^2 + 0.01)`
/// per value, averaged (0.01 keeps black pixels from dominating).
fn rel_mse(a: &Img, r: &Img) -> f64 {
    a.data
        .iter()
        .zip(&r.data)
        .map(|(&x, &y)| {
            let (x, y) = (x as f64, y as f64);
            (x - y).powi(2) / (y * y + 1e-2)
        })
        .sum::<f64>()
        / a.data.len() as f64
}

/// ep-gauss's defaults before the second real-renders round (issue 30).
fn old_defaults(s: usize) -> FilterParams {
    let mut p = FilterParams::new(Method::EpGauss, s);
    p.tolerance = epfilt::filter::default_tolerance(s);
    p.support = 1;
    p.support_compact = 0;
    p.support_over = 0.0;
    p.support_region = 0;
    p.support_group = 0;
    p.radius = 0.6;
    p.cutoff = 3.0;
    p.max_radius = 16.0;
    p.width_step = 0.1;
    p.bound_from = 0.0;
    p
}

/// The factor of `scripts/eval-renders` on one synthetic frame: relMSE of a
/// setting against the Gaussian of the expected image, over the relMSE the
/// Gaussian of the noisy frame leaves (0: all noise removed, 1: none).
fn factors(kind: SceneKind, seed: u64, settings: &[FilterParams]) -> Vec<f64> {
    let s = 3;
    let sc = Scene {
        kind,
        w: W,
        h: H,
        seed,
        hot: 1e4,
    };
    let img = |data| Img {
        w: W * s,
        h: H * s,
        nch: 3,
        data,
    };
    let noisy = img(sc.noisy_rows(s, 0, H * s));
    let expected = img(sc.expected_rows(s, 0, H * s));
    let cfg = PipelineConfig::default();
    let gauss = params(Method::Gauss, s);
    let (reference, _) = run(&expected, s, &gauss, &cfg);
    let (linear, _) = run(&noisy, s, &gauss, &cfg);
    let base = rel_mse(&linear, &reference);
    settings
        .iter()
        .map(|p| {
            let (out, stats) = run(&noisy, s, p, &cfg);
            assert!(stats.ledger.iter().all(|l| l.rel_error <= ENERGY_TOL));
            rel_mse(&out, &reference) / base
        })
        .collect()
}

/// Seeds of the `lights` scene the factors are summed over: one seed's
/// fireflies can land on a bulb or the line and decide a comparison alone
/// (seed 7 alone, second-round defaults: 0.1216 against the old defaults'
/// 0.0857, the line's ends; summed over these three, the third round's
/// defaults 0.291 against 0.330).
const SEEDS: [u64; 3] = [3, 7, 11];

/// The factor of each setting summed over [`SEEDS`] of `kind`.
fn summed(kind: SceneKind, settings: &[FilterParams]) -> Vec<f64> {
    let mut sum = vec![0.0; settings.len()];
    for seed in SEEDS {
        for (a, f) in sum.iter_mut().zip(factors(kind, seed, settings)) {
            *a += f;
        }
    }
    sum
}

/// The `lights` scene (bulbs 0.5 to 3 px and a thin line among fireflies,
/// hot 1e4), factors summed over the seeds: the paper's rule turns the bulbs
/// into discs (16.0, worse than the linear filter's 3), the old defaults keep
/// them (0.330) and the defaults also remove the fireflies next to them
/// (0.291). The synthetic
/// penumbra, glossy and caustic scenes go the other way (every hot sample
/// there is the same light hit by independent chance, which the feature
/// rules keep: `docs/DESIGN.md`), so they are not the scene for this.
#[test]
fn the_defaults_beat_the_paper_and_the_old_defaults_on_synthetic_lights() {
    let s = 3;
    let new = FilterParams::new(Method::EpGauss, s);
    let mut paper = new.clone();
    paper.support = 0;
    let f = summed(SceneKind::Lights, &[new, paper, old_defaults(s)]);
    let (new_f, paper_f, old_f) = (f[0], f[1], f[2]);
    assert!(
        new_f < paper_f && new_f < old_f,
        "defaults {new_f:.4}, the paper's rule {paper_f:.4}, old defaults {old_f:.4}"
    );
}

/// On the same scene the presets are ordered as on the real renders: best
/// at most default at most fast (0.290, 0.291, 0.300), each far below the
/// paper's rule.
#[test]
fn the_presets_are_ordered_and_each_beats_the_paper() {
    let s = 3;
    let mut all: Vec<FilterParams> = Quality::ALL
        .iter()
        .map(|&q| FilterParams::new(Method::EpGauss, s).with_quality(q))
        .collect();
    let mut paper = FilterParams::new(Method::EpGauss, s);
    paper.support = 0;
    all.push(paper);
    let f = summed(SceneKind::Lights, &all);
    for (q, &fq) in Quality::ALL.iter().zip(&f) {
        assert!(fq < f[3], "{q:?} {fq:.4} vs the paper's rule {:.4}", f[3]);
    }
    assert!(f[2] <= f[1] && f[1] <= f[0], "fast, default, best: {f:?}");
}

/// The values preset `q` sets, as `--help` lists them (tolerance at S = 3).
fn p_at3(q: Quality) -> Vec<(&'static str, String)> {
    FilterParams::new(Method::EpGauss, 3)
        .with_quality(q)
        .quality_settings()
}

/// What `--quality Q` sets, as the report records it: every knob of the
/// preset, the tolerance scaled to S, and the preset's name.
#[test]
fn every_preset_round_trips_through_the_report() {
    let dir = crate::exr_io::tmpdir();
    let input = dir.path().join("in.exr");
    // 72 x 48: whole pixels at S = 3 and S = 4.
    let img = fireflies(72, 48, 3, 0.02, 9);
    crate::exr_io::write_rgb(
        &input,
        &img,
        exr::prelude::Compression::ZIP16,
        exr::prelude::Blocks::ScanLines,
        false,
        exr::prelude::LineOrder::Increasing,
    );
    for s in [3usize, 4] {
        for q in Quality::ALL {
            let p = FilterParams::new(Method::EpGauss, s).with_quality(q);
            let out = dir.path().join(format!("{}-{s}.exr", q.name()));
            let job = FilterJob::new(&input, &out, p);
            let report = filter_file(&job, &|_, _| {}).expect("filter");
            let json = serde_json::to_value(&report).expect("report as JSON");
            let settings = &json["settings"];
            assert_eq!(settings["quality"], q.name(), "{settings}");
            // The caps the README names for each preset.
            let cap = [8.0, 16.0, 32.0][Quality::ALL.iter().position(|&x| x == q).unwrap()];
            assert_eq!(settings["max_radius"].as_f64(), Some(cap), "{settings}");
            for (key, at3) in p_at3(q) {
                let want: f64 = at3.parse().expect("a number");
                let want = if key == "tolerance" {
                    epfilt::filter::scaled_tolerance(want, s)
                } else {
                    want
                };
                assert_eq!(
                    settings[key].as_f64(),
                    Some(want),
                    "{q:?} {key}: {settings}"
                );
            }
        }
    }
}
