//! Every channel beside the beauty is carried through, by its rule: light
//! AOVs spread with the beauty's own kernels (so they still sum to it, and
//! each keeps its energy), averaged data through the base filter (copied at
//! S = 1), ids by the centre sample; nothing silently disappears.

use std::collections::HashMap;
use std::path::Path;

use epfilt::filter::channels::RuleOverride;
use epfilt::{filter_file, Method, PipelineConfig};

use crate::common::{epfilt_run, read_json, ENERGY_TOL};
use crate::exr_io::{job, tmpdir, write_flat, write_named};

/// A multi-layer render written by the OpenEXR library (see
/// `tests/data/exr/README.md`): R, G, B, A = diffuse + specular + emission,
/// those three layers, Z, N.X/Y/Z and a uint `id`.
const AOVS: &str = "tests/data/exr/small/aovs_multilayer.exr";

/// Beauty and the sum of its AOVs agree per pixel to this, relative: each
/// of the four values is rounded to f32 once on writing (4 half-ulps, 2.4e-7),
/// and the input's own sums were rounded too (5e-8 there).
const SUM_TOL: f64 = 1e-6;

/// Each channel's samples as f64 (ids too: they are below 2^24 here).
fn planes(path: &Path) -> HashMap<String, Vec<f64>> {
    let img = exr::prelude::read_all_flat_layers_from_file(path).expect("read");
    img.layer_data[0]
        .channel_data
        .list
        .iter()
        .map(|c| {
            (
                c.name.to_string(),
                c.sample_data.values_as_f32().map(f64::from).collect(),
            )
        })
        .collect()
}

/// Every pixel's R, G, B equal the sum of `layers`' within [`SUM_TOL`].
fn assert_sums_to_beauty(o: &HashMap<String, Vec<f64>>, layers: &[&str], tag: &str) {
    for c in ["R", "G", "B"] {
        for (k, &b) in o[c].iter().enumerate() {
            let sum: f64 = layers.iter().map(|l| o[&format!("{l}.{c}")][k]).sum();
            assert!(
                (b - sum).abs() <= SUM_TOL * b.abs().max(1e-30),
                "{tag}: {c} at {k}: beauty {b} vs layers {sum}"
            );
        }
    }
}

#[test]
fn aovs_still_sum_to_the_beauty_and_every_channel_is_carried() {
    let dir = tmpdir();
    let input = planes(Path::new(AOVS));
    for method in crate::common::GAUSSIAN_FAMILY {
        for s in [1, 3] {
            let out = dir.path().join(format!("{}_{s}.exr", method.name()));
            let r = filter_file(&job(Path::new(AOVS), &out, method, s), &|_, _| {})
                .unwrap_or_else(|e| panic!("{} S={s}: {e}", method.name()));
            let tag = format!("{} S={s}", method.name());
            let o = planes(&out);
            // Every channel is written, nothing dropped.
            for name in input.keys() {
                assert!(o.contains_key(name), "{tag}: {name} missing");
            }
            assert!(
                r.dropped_channels.is_empty(),
                "{tag}: {:?}",
                r.dropped_channels
            );
            // Ids stay u32 and take only values of the input.
            assert_eq!(r.channel_rules["id"], "nearest", "{tag}");
            assert!(
                o["id"].iter().all(|v| input["id"].contains(v)),
                "{tag}: an id that is not in the input"
            );
            if s == 1 {
                assert_eq!(o["id"], input["id"], "{tag}: ids not copied");
            }
            assert_eq!(r.channel_rules["diffuse.R"], "additive", "{tag}");
            assert_eq!(r.channel_rules["Z"], "average", "{tag}");
            assert_eq!(r.channel_rules["R"], "colour", "{tag}");
            assert_sums_to_beauty(&o, &["diffuse", "specular", "emission"], &tag);
            // Each additive channel keeps its energy (before rounding).
            for (c, e) in r.channels.iter().zip(&r.energy_rel_error) {
                if r.channel_rules[c] == "additive" {
                    assert!(e.abs() <= ENERGY_TOL, "{tag}: {c} {e}");
                }
            }
            // Averaged data: copied at S = 1, an average at S = 3 (within
            // the input's range); alpha stays opaque.
            let (zi, zo) = (&input["Z"], &o["Z"]);
            if s == 1 {
                assert!(
                    zi.iter().zip(zo).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{tag}: Z not copied"
                );
            } else {
                let (lo, hi) = zi
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
                assert!(
                    zo.iter().all(|&v| v >= lo && v <= hi),
                    "{tag}: Z out of range"
                );
            }
            assert!(o["A"].iter().all(|&a| a == 1.0), "{tag}: alpha");
        }
    }
    // ep-gauss did spread something here: the sums are a real test.
    let r = filter_file(
        &job(
            Path::new(AOVS),
            &dir.path().join("x.exr"),
            Method::EpGauss,
            3,
        ),
        &|_, _| {},
    )
    .unwrap();
    assert!(r.samples_spread > 50, "{}", r.samples_spread);
}

#[test]
fn carried_channels_are_bit_identical_for_any_tile_strip_and_threads() {
    let dir = tmpdir();
    let mut digests = Vec::new();
    for (k, (tile, strip_rows, threads)) in
        [(7, 5, 1), (64, 0, 2), (16, 48, 3)].into_iter().enumerate()
    {
        let out = dir.path().join(format!("cut{k}.exr"));
        let mut j = job(Path::new(AOVS), &out, Method::EpGauss, 3);
        j.pipeline = PipelineConfig {
            tile,
            strip_rows,
            threads,
            ..Default::default()
        };
        let r = filter_file(&j, &|_, _| {}).unwrap();
        assert_eq!(r.channels.len(), 18);
        digests.push(r.digest);
    }
    assert!(digests.windows(2).all(|d| d[0] == d[1]), "{digests:?}");
}

#[test]
fn ep_box_gives_up_the_same_share_of_every_additive_layer() {
    // A pixel-resolution render with variance: a firefly in the specular
    // layer makes its pixel noisy; the beauty and both layers lose the same
    // fraction, so they still add up, and Z is copied.
    let dir = tmpdir();
    let input = dir.path().join("px.exr");
    let names = [
        "R",
        "G",
        "B",
        "diffuse.R",
        "diffuse.G",
        "diffuse.B",
        "specular.R",
        "specular.G",
        "specular.B",
        "var.R",
        "var.G",
        "var.B",
        "Z",
    ];
    let (w, h) = (24, 20);
    let spec = |x: usize, y: usize| if (x, y) == (11, 9) { 400.0 } else { 0.05 };
    let diff = |x: usize, y: usize| 0.3 + 0.01 * ((x * 7 + y * 3) % 5) as f32;
    write_named(
        &input,
        w,
        h,
        &names,
        &[("epfilt_spp", 16)],
        |x, y, c| match c {
            0..=2 => diff(x, y) + spec(x, y),
            3..=5 => diff(x, y),
            6..=8 => spec(x, y),
            // One of 16 samples carries the firefly: the samples' variance is
            // 16 m^2 for a mean m.
            9..=11 if (x, y) == (11, 9) => 16.0 * spec(x, y) * spec(x, y),
            9..=11 => 1e-4,
            _ => 2.0 + x as f32,
        },
    );
    let out = dir.path().join("out.exr");
    let r = filter_file(&job(&input, &out, Method::EpBox, 1), &|_, _| {}).unwrap();
    assert!(r.samples_spread >= 1, "nothing spread");
    assert_eq!(r.channel_rules["specular.G"], "additive");
    assert_eq!(r.channel_rules["var.R"], "average");
    let (i, o) = (planes(&input), planes(&out));
    assert_sums_to_beauty(&o, &["diffuse", "specular"], "ep-box");
    // The firefly's light moved (the pixel is darker), and Z did not.
    assert!(o["specular.G"][9 * w + 11] < 400.0);
    assert_eq!(i["Z"], o["Z"]);
    assert_eq!(i["var.G"], o["var.G"]);
}

#[test]
fn channel_rules_on_the_command_line() {
    let dir = tmpdir();
    let out = dir.path().join("out.exr");
    let report = dir.path().join("r.json");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "filter",
            AOVS,
            out.to_str().unwrap(),
            "-s",
            "3",
            "-q",
            "--report",
            report.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        epfilt_run(&args)
    };
    // Drop a layer; take Z as the nearest sample.
    let o = run(&[
        "--channel-rule",
        "specular.*=drop",
        "--channel-rule",
        "Z=nearest",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = read_json(&report);
    let written: Vec<&str> = r["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    assert!(
        !written.iter().any(|c| c.starts_with("specular.")),
        "{written:?}"
    );
    assert_eq!(r["channel_rules"]["Z"], "nearest");
    // The file and the report say which rules were given.
    assert_eq!(r["settings"]["channel_rules"], "specular.*=drop;Z=nearest");
    let zi = &planes(Path::new(AOVS))["Z"];
    let zo = &planes(&out)["Z"];
    assert!(
        zo.iter().all(|v| zi.contains(v)),
        "nearest Z takes input values"
    );
    // A bad rule is one clear line.
    let o = run(&["--channel-rule", "Z=blur"]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("blur") && e.trim().lines().count() == 1, "{e}");
    assert!(RuleOverride::parse("Z").is_err());
}

#[test]
fn ids_stay_uint_and_ids_f32_cannot_hold_are_refused() {
    use exr::prelude::*;
    let dir = tmpdir();
    let (w, h) = (9, 6);
    let write = |path: &Path, big: u32| {
        let f = |v: f32| FlatSamples::F32(vec![v; w * h]);
        let ids: Vec<u32> = (0..w * h)
            .map(|i| if i == 7 { big } else { (i / 9) as u32 })
            .collect();
        write_flat(
            path,
            (w, h),
            vec![
                ("B", f(0.2)),
                ("G", f(0.5)),
                ("R", f(0.9)),
                ("objectId", FlatSamples::U32(ids)),
            ],
        );
    };
    let ok = dir.path().join("ok.exr");
    write(&ok, 16_777_216);
    let out = dir.path().join("out.exr");
    let r = filter_file(&job(&ok, &out, Method::Gauss, 3), &|_, _| {}).unwrap();
    assert_eq!(r.channel_rules["objectId"], "nearest");
    let meta = exr::meta::MetaData::read_from_file(&out, false).unwrap();
    let id = meta.headers[0]
        .channels
        .list
        .iter()
        .find(|c| c.name.to_string() == "objectId")
        .expect("objectId written");
    assert_eq!(id.sample_type, SampleType::U32);
    // 2^24 + 1 would come back as 2^24: refused, naming the channel and the way out.
    let big = dir.path().join("big.exr");
    write(&big, 16_777_217);
    let e = filter_file(&job(&big, &out, Method::Gauss, 3), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("objectId") && e.contains("16777217") && e.contains("--channel-rule"),
        "{e}"
    );
    // With the rule to drop it, the rest is filtered.
    let mut j = job(&big, &out, Method::Gauss, 3);
    j.channel_rules = vec![RuleOverride::parse("objectId=drop").unwrap()];
    let r = filter_file(&j, &|_, _| {}).unwrap();
    assert_eq!(r.dropped_channels, ["objectId"]);
}

#[test]
fn a_render_with_a_hundred_channels_is_carried_whole() {
    // Production files carry dozens of passes (Blender's full set, per-light
    // layers, cryptomatte): none is dropped for their number.
    let dir = tmpdir();
    let input = dir.path().join("many.exr");
    let mut names: Vec<String> = ["R", "G", "B"].iter().map(|s| s.to_string()).collect();
    for k in 0..33 {
        for c in ["R", "G", "B"] {
            names.push(format!("light{k:02}.{c}"));
        }
    }
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    // The beauty is the sum of the 33 per-light layers, one of them hot.
    let light = |x: usize, y: usize, k: usize| {
        if (x, y, k) == (7, 5, 3) {
            500.0
        } else {
            0.01 * (k + 1) as f32
        }
    };
    write_named(&input, 18, 12, &refs, &[], |x, y, c| {
        if c < 3 {
            (0..33).map(|k| light(x, y, k)).sum()
        } else {
            light(x, y, (c - 3) / 3)
        }
    });
    let out = dir.path().join("out.exr");
    let mut j = job(&input, &out, Method::EpGauss, 3);
    j.channel_rules = vec![RuleOverride::parse("light*=additive").unwrap()];
    let r = filter_file(&j, &|_, _| {}).unwrap();
    assert_eq!(r.channels.len(), 102);
    assert!(r.samples_spread >= 1);
    let o = planes(&out);
    let layers: Vec<String> = (0..33).map(|k| format!("light{k:02}")).collect();
    let layers: Vec<&str> = layers.iter().map(String::as_str).collect();
    assert_sums_to_beauty(&o, &layers, "102 channels");
}

#[test]
fn an_infinite_depth_passes_as_data_while_the_beauty_is_still_checked() {
    // Renderers write the sky's depth as infinity: depth is data, not light,
    // so it is carried as it is (and kept out of the ledger).
    let dir = tmpdir();
    let input = dir.path().join("sky.exr");
    let (w, h) = (12, 18);
    write_named(
        &input,
        w,
        h,
        &["R", "G", "B", "Z"],
        &[],
        |_, y, c| match c {
            3 if y < 3 => f32::INFINITY,
            3 => 4.0 + y as f32,
            _ => 0.5,
        },
    );
    for s in [1, 3] {
        let out = dir.path().join(format!("o{s}.exr"));
        let r = filter_file(&job(&input, &out, Method::EpGauss, s), &|_, _| {})
            .unwrap_or_else(|e| panic!("S={s}: {e}"));
        assert_eq!(r.channel_rules["Z"], "average");
        assert!(r.energy_rel_error.iter().all(|e| e.abs() <= ENERGY_TOL));
        let (i, o) = (planes(&input), planes(&out));
        if s == 1 {
            assert_eq!(i["Z"], o["Z"], "copied, infinities included");
        } else {
            // The first output row is sky, the last is not.
            assert!(o["Z"][..w / s].iter().all(|z| z.is_infinite()));
            assert!(o["Z"][(h / s - 1) * (w / s)..]
                .iter()
                .all(|z| z.is_finite()));
        }
        assert!(o["R"].iter().all(|&v| v == 0.5));
    }
    // An infinite value in the beauty is still refused.
    let bad = dir.path().join("bad.exr");
    write_named(&bad, w, h, &["R", "G", "B"], &[], |x, y, _| {
        if (x, y) == (2, 2) {
            f32::INFINITY
        } else {
            0.5
        }
    });
    let e = filter_file(
        &job(&bad, &dir.path().join("x.exr"), Method::Gauss, 3),
        &|_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("non-finite"), "{e}");
}

#[test]
fn over_the_memory_limit_the_error_says_how_many_channels_are_carried() {
    let dir = tmpdir();
    let mut j = job(
        Path::new(AOVS),
        &dir.path().join("o.exr"),
        Method::EpGauss,
        3,
    );
    j.max_memory = Some(1 << 20);
    let e = filter_file(&j, &|_, _| {}).unwrap_err().to_string();
    assert!(
        e.contains("--max-memory") && e.contains("14 of its 18 channels") && e.contains("drop"),
        "{e}"
    );
    assert!(!e.contains('\n'), "one line: {e}");
    // Dropping them is what it says: the beauty alone fits in the floor
    // the error names.
    let floor: u64 = e
        .split("at least about ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("the error names its floor");
    j.channel_rules = vec![RuleOverride::parse("*=drop").unwrap()];
    j.max_memory = Some(floor << 20);
    let r = filter_file(&j, &|_, _| {}).unwrap();
    assert_eq!(r.channels, ["R", "G", "B", "A"]);
}

#[test]
fn the_foils_carry_every_channel_too() {
    // median, alpha-trim and clamp lose energy and break sums by design,
    // but a user comparing them still gets every channel, ids intact.
    let dir = tmpdir();
    let input = planes(Path::new(AOVS));
    for method in [Method::Median, Method::AlphaTrim, Method::Clamp] {
        for s in [1, 3] {
            let tag = format!("{} S={s}", method.name());
            let out = dir.path().join(format!("{}_{s}.exr", method.name()));
            let r = filter_file(&job(Path::new(AOVS), &out, method, s), &|_, _| {})
                .unwrap_or_else(|e| panic!("{tag}: {e}"));
            assert!(r.dropped_channels.is_empty(), "{tag}");
            let o = planes(&out);
            for name in input.keys() {
                assert!(o.contains_key(name), "{tag}: {name} missing");
            }
            assert!(
                o["id"].iter().all(|v| input["id"].contains(v)),
                "{tag}: ids"
            );
            if s == 1 {
                assert_eq!(o["Z"], input["Z"], "{tag}: Z not copied");
                assert_eq!(o["id"], input["id"], "{tag}: ids not copied");
            }
        }
    }
}
