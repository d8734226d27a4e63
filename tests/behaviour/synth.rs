//! `synth`, `compare` and `preview`: exact truth, determinism, formats.

use crate::exr_io::{read_planar, tmpdir};
use epfilt::synth::{synth, Sampling, Scene, SceneKind, SynthJob};
use exr::prelude::Compression;

use crate::common::epfilt_run as epfilt;

/// Over K seeds, the mean of each pixel's estimate is compared with its exact
/// expected value using its exact variance (`Scene::pixel_moments`). Where a
/// pixel expects at least 5 hot samples over all seeds, the normal
/// approximation holds and z^2 ~ chi^2(1): (sum z^2 - n) / sqrt(2n) ~ N(0, 1),
/// and rejecting above 5 has a false-alarm rate of about 3e-7. Elsewhere the
/// mean must lie between the pixel's all-cold and all-hot values.
const Z_LIMIT: f64 = 5.0;
const MIN_HITS: f64 = 5.0;

/// (normalized chi-square statistic, values tested, values out of range)
fn check(scene: &Scene, sampling: Sampling, means: &[Vec<f64>], bias: f64) -> (f64, usize, usize) {
    let k = means.len() as f64;
    let (w, h) = (scene.w, scene.h);
    let (mut chi2, mut n, mut bad) = (0.0, 0usize, 0usize);
    for y in 0..h {
        for x in 0..w {
            let (mean, var, hits) = scene.pixel_moments(sampling, x, y);
            for c in 0..3 {
                let m: f64 = means.iter().map(|v| v[(y * 3 + c) * w + x]).sum::<f64>() / k;
                let t = mean[c] * bias;
                if hits * k >= MIN_HITS && var[c] > 0.0 {
                    chi2 += (m - t).powi(2) / (var[c] / k);
                    n += 1;
                } else if var[c] == 0.0 && ((m - t) / t.abs().max(1e-30)).abs() > 1e-6 {
                    bad += 1; // a noiseless value must equal the truth (f32 rounding: 1e-6)
                }
            }
        }
    }
    ((chi2 - n as f64) / (2.0 * n as f64).sqrt(), n, bad)
}

/// Mean of each pixel's S x S samples, planar [row][channel][x].
fn box_means(sc: &Scene, s: usize) -> Vec<f64> {
    let (w, h) = (sc.w, sc.h);
    let rows = sc.noisy_rows(s, 0, h * s);
    let mut out = vec![0.0f64; 3 * w * h];
    for y in 0..h {
        for c in 0..3 {
            for x in 0..w {
                let mut acc = 0.0;
                for b in 0..s {
                    for a in 0..s {
                        acc += rows[((y * s + b) * 3 + c) * w * s + x * s + a] as f64;
                    }
                }
                out[(y * 3 + c) * w + x] = acc / (s * s) as f64;
            }
        }
    }
    out
}

#[test]
fn the_mean_over_seeds_converges_to_the_truth() {
    for kind in [
        SceneKind::Mixed,
        SceneKind::LightEdge,
        SceneKind::Caustic,
        SceneKind::Penumbra,
        SceneKind::Glossy,
    ] {
        let (w, h, s) = (24, 16, 2);
        let base = Scene {
            kind,
            w,
            h,
            seed: 0,
            hot: 1e3,
        };
        let means: Vec<Vec<f64>> = (0..400u64)
            .map(|seed| {
                box_means(
                    &Scene {
                        seed,
                        ..base.clone()
                    },
                    s,
                )
            })
            .collect();
        let sampling = Sampling::Supersample(s);
        let (z, n, bad) = check(&base, sampling, &means, 1.0);
        assert!(n >= 20, "{kind:?}: too few noisy values ({n}) to test");
        assert!(z < Z_LIMIT, "{kind:?}: z = {z} over {n} values");
        assert_eq!(bad, 0, "{kind:?}: noiseless values off the truth");
        // The truth files hold the same expected values.
        let truth = base.truth_rows(s, 0, h);
        for y in 0..h {
            for x in 0..w {
                let (mean, _, _) = base.pixel_moments(sampling, x, y);
                for c in 0..3 {
                    let t = truth[(y * 3 + c) * w + x] as f64;
                    assert!(
                        (t - mean[c]).abs() <= 1e-6 * mean[c].abs(),
                        "truth file off at ({x},{y})"
                    );
                }
            }
        }
        // The test has power: where the frame has noiseless pixels a truth 2%
        // off is rejected exactly; everywhere the z statistic alone sees a 30%
        // bias (measured: z = 18 for the caustic, the weakest, up to 2757).
        let noiseless = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .any(|(x, y)| base.pixel_moments(sampling, x, y).2 == 0.0);
        if noiseless {
            let (zb, _, badb) = check(&base, sampling, &means, 1.02);
            assert!(
                zb > Z_LIMIT || badb > 0,
                "{kind:?}: a 2% bias went unnoticed"
            );
        }
        let z30 = check(&base, sampling, &means, 1.3).0;
        assert!(
            z30 > Z_LIMIT,
            "{kind:?}: the z test misses a 30% bias (z = {z30})"
        );
    }
}

#[test]
fn spp_means_converge_to_the_spp_truth() {
    let base = Scene {
        kind: SceneKind::Mixed,
        w: 20,
        h: 14,
        seed: 0,
        hot: 1e3,
    };
    let means: Vec<Vec<f64>> = (0..400u64)
        .map(|seed| {
            let rows = Scene {
                seed,
                ..base.clone()
            }
            .spp_rows(8, 0, 14);
            rows.chunks(6 * 20)
                .flat_map(|r| r[..3 * 20].iter().map(|&v| v as f64))
                .collect()
        })
        .collect();
    let (z, n, bad) = check(&base, Sampling::Spp(8), &means, 1.0);
    assert!(
        n >= 20 && z < Z_LIMIT && bad == 0,
        "z = {z}, n = {n}, bad = {bad}"
    );
    let (zb, _, badb) = check(&base, Sampling::Spp(8), &means, 1.02);
    assert!(zb > Z_LIMIT || badb > 0);
    assert!(check(&base, Sampling::Spp(8), &means, 1.3).0 > Z_LIMIT);
}

#[test]
fn same_seed_same_bytes_at_any_thread_count() {
    let dir = tmpdir();
    let mut files = Vec::new();
    for threads in [1, 3] {
        for sampling in [Sampling::Supersample(3), Sampling::Spp(16)] {
            let out = dir.path().join(format!("n{threads}-{sampling:?}.exr"));
            let truth = dir.path().join(format!("t{threads}-{sampling:?}.exr"));
            synth(
                &SynthJob {
                    scene: Scene {
                        kind: SceneKind::Mixed,
                        w: 70,
                        h: 45,
                        seed: 7,
                        hot: 1e4,
                    },
                    sampling,
                    output: out.clone(),
                    truth: Some(truth.clone()),
                    variance: true,
                    compression: Compression::ZIP16,
                    threads,
                    format: None,
                },
                &|_, _| {},
            )
            .unwrap();
            files.push((std::fs::read(out).unwrap(), std::fs::read(truth).unwrap()));
        }
    }
    assert!(
        files[0] == files[2] && files[1] == files[3],
        "bytes depend on the thread count"
    );
}

#[test]
fn synth_cli_writes_supersampled_and_spp_files() {
    let dir = tmpdir();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    let o = epfilt(&[
        "synth",
        "-o",
        &d("n.exr"),
        "--truth",
        &d("t.exr"),
        "--size",
        "64x48",
        "-s",
        "3",
        "--scene",
        "caustic",
        "-q",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        (
            read_planar(dir.path().join("n.exr").as_path()).w,
            read_planar(dir.path().join("t.exr").as_path()).w
        ),
        (192, 64)
    );
    let o = epfilt(&[
        "synth",
        "-o",
        &d("p.exr"),
        "--size",
        "32x20",
        "--spp",
        "16",
        "--variance",
        "-q",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let meta = exr::meta::MetaData::read_from_file(dir.path().join("p.exr"), false).unwrap();
    let h = &meta.headers[0];
    let names: Vec<String> = h.channels.list.iter().map(|c| c.name.to_string()).collect();
    assert!(
        names.contains(&"variance.G".to_string()) && names.contains(&"R".to_string()),
        "{names:?}"
    );
    assert_eq!(
        h.own_attributes.other.get(&exr::prelude::Text::from("spp")),
        Some(&exr::meta::attribute::AttributeValue::I32(16))
    );
    let o = epfilt(&["synth", "-o", &d("x.exr"), "--scene", "nebula"]);
    assert_eq!(o.status.code(), Some(2));
}

/// A 40x30 `mixed` scene (S=3) with its truth as n.exr and t.exr.
fn synth_small(d: &dyn Fn(&str) -> String) {
    let o = epfilt(&[
        "synth",
        "-o",
        &d("n.exr"),
        "--truth",
        &d("t.exr"),
        "--size",
        "40x30",
        "-q",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn compare_reports_identity_and_differences_as_json() {
    let dir = tmpdir();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    synth_small(&d);
    assert!(epfilt(&["filter", &d("n.exr"), &d("f.exr"), "-q"])
        .status
        .success());
    let same = epfilt(&["compare", &d("t.exr"), &d("t.exr"), "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&same.stdout).unwrap();
    assert_eq!(j["identical"], true);
    assert_eq!(j["rmse"], 0.0);
    let diff = epfilt(&["compare", &d("f.exr"), &d("t.exr"), "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&diff.stdout).unwrap();
    for key in [
        "rmse",
        "rel_mse",
        "psnr",
        "energy_ratio",
        "max_abs_diff",
        "differing_pixels",
        "identical",
    ] {
        assert!(j.get(key).is_some(), "compare JSON lacks {key}");
    }
    assert_eq!(j["identical"], false);
    assert!(j["rmse"].as_f64().unwrap() > 0.0 && j["psnr"].as_f64().unwrap() > 5.0);
    let table = epfilt(&["compare", &d("f.exr"), &d("t.exr")]);
    assert!(String::from_utf8_lossy(&table.stdout).contains("energy_ratio"));
}

#[test]
fn preview_and_montage_write_pngs_of_the_right_size() {
    let dir = tmpdir();
    let d = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    synth_small(&d);
    assert!(epfilt(&["preview", &d("t.exr"), &d("t.png")])
        .status
        .success());
    assert!(epfilt(&[
        "preview",
        &d("t.exr"),
        &d("t.exr"),
        &d("m.png"),
        "--montage",
        "--exposure",
        "-1"
    ])
    .status
    .success());
    let size = |p: &str| {
        let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(p).unwrap()));
        let r = dec.read_info().unwrap();
        (r.info().width, r.info().height)
    };
    assert_eq!(size(&d("t.png")), (40, 30));
    assert_eq!(size(&d("m.png")), (40 + 4 + 40, 30 + 12));
    let o = epfilt(&["preview", &d("t.exr"), &d("t.exr"), &d("x.png")]);
    assert_eq!(
        o.status.code(),
        Some(2),
        "two inputs without --montage must be refused"
    );
}
