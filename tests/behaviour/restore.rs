//! `epfilt restore` from the command line: the energy image's total kept
//! exactly, the same bytes at any thread count, and the guards a user meets
//! (sizes, channels, NaN, an empty denoiser output), none of which leaves
//! an output behind.

use exr::image::FlatSamples;

use crate::common::{epfilt_ok, epfilt_run, read_json, ENERGY_TOL};
use crate::exr_io::{read_channels, read_samples, tmpdir, write_flat};

/// Sums of a few hundred f32 outputs against their f64 energy: each
/// rounding is 2^-24 of a value.
const F32_SUMS: f64 = 1e-6;

/// An R, G, B image `w x h` from `f(x, y, c)`.
fn write(path: &std::path::Path, (w, h): (usize, usize), f: impl Fn(usize, usize, usize) -> f32) {
    let plane = |c| FlatSamples::F32((0..w * h).map(|i| f(i % w, i / w, c)).collect());
    write_flat(
        path,
        (w, h),
        vec![("B", plane(2)), ("G", plane(1)), ("R", plane(0))],
    );
}

/// A `w x h` channel of f32 from `f(x, y)`.
fn flat((w, h): (usize, usize), f: &dyn Fn(usize, usize) -> f32) -> FlatSamples {
    FlatSamples::F32((0..w * h).map(|i| f(i % w, i / w)).collect())
}

/// A noisy render with fireflies.
fn render(x: usize, y: usize, c: usize) -> f32 {
    let h = ((x * 7919 + y * 104729 + c * 31) % 1000) as f32 / 1000.0;
    let base = 1.0 + ((x + y) as f32 * 0.2).sin() * 0.5;
    if h > 0.99 {
        base * 300.0
    } else {
        base * (0.5 + h)
    }
}

/// A smooth "denoised" picture, too dark by a third.
fn denoised(x: usize, y: usize, _c: usize) -> f32 {
    0.66 * (1.0 + ((x + y) as f32 * 0.2).sin() * 0.5)
}

fn restore(
    d: &std::path::Path,
    e: &std::path::Path,
    out: &std::path::Path,
    extra: &[&str],
) -> std::process::Output {
    let mut args = vec![
        "restore",
        d.to_str().unwrap(),
        e.to_str().unwrap(),
        out.to_str().unwrap(),
        "-q",
    ];
    args.extend_from_slice(extra);
    epfilt_run(&args)
}

/// [`restore`] with `extra` and a report beside `out`, which must succeed
/// with the ledger balanced: the report.
fn restore_report(
    d: &std::path::Path,
    e: &std::path::Path,
    out: &std::path::Path,
    extra: &[&str],
) -> serde_json::Value {
    let rep = out.with_extension("json");
    let mut args = vec!["--report", rep.to_str().unwrap()];
    args.extend_from_slice(extra);
    let o = restore(d, e, out, &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = read_json(&rep);
    for l in r["ledger"].as_array().unwrap() {
        assert!(l["rel_error"].as_f64().unwrap() <= ENERGY_TOL, "{l}");
    }
    r
}

#[test]
fn restore_keeps_the_energy_and_the_bytes_at_any_thread_count() {
    let dir = tmpdir();
    let (e, d) = (dir.path().join("e.exr"), dir.path().join("d.exr"));
    write(&e, (70, 45), render);
    write(&d, (70, 45), denoised);
    let mut digests = Vec::new();
    for threads in ["1", "2", "3"] {
        let (out, rep) = (dir.path().join("o.exr"), dir.path().join("r.json"));
        let o = restore(
            &d,
            &e,
            &out,
            &["--threads", threads, "--report", rep.to_str().unwrap()],
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r = read_json(&rep);
        for l in r["ledger"].as_array().unwrap() {
            assert!(l["rel_error"].as_f64().unwrap() <= ENERGY_TOL, "{l}");
        }
        digests.push(r["digest"].as_str().unwrap().to_string());
    }
    assert!(digests.windows(2).all(|p| p[0] == p[1]), "{digests:?}");
}

#[test]
fn restore_refuses_images_that_do_not_match() {
    let dir = tmpdir();
    let (e, d, out) = (
        dir.path().join("e.exr"),
        dir.path().join("d.exr"),
        dir.path().join("o.exr"),
    );
    write(&e, (20, 10), render);
    write(&d, (21, 10), denoised);
    let o = restore(&d, &e, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("d.exr") && err.contains("21x10"),
        "{err}"
    );
    assert!(!out.exists());
    let y = FlatSamples::F32(vec![1.0; 200]);
    write_flat(&d, (20, 10), vec![("Y", y)]);
    let o = restore(&d, &e, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("channels"), "{err}");
    assert!(!out.exists());
    let o = restore(&e, &e, &e, &[]);
    assert!(!o.status.success());
    let hdr = dir.path().join("o.hdr");
    let o = restore(&d, &e, &hdr, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.code() == Some(2) && err.contains("restore writes"),
        "{err}"
    );
    assert!(!hdr.exists());
    let o = restore(&d, &e, &out, &["--scale", "1"]);
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn restore_refuses_nan_energy_unless_told_and_keeps_what_the_denoiser_lacks() {
    let dir = tmpdir();
    let (e, d, out) = (
        dir.path().join("e.exr"),
        dir.path().join("d.exr"),
        dir.path().join("o.exr"),
    );
    write(&e, (16, 12), |x, y, c| {
        if (x, y, c) == (3, 4, 1) {
            f32::NAN
        } else {
            render(x, y, c)
        }
    });
    // The denoiser's output is black on the left half and NaN in a corner:
    // nothing to shape that energy with.
    write(&d, (16, 12), |x, y, c| match (x, y) {
        (0, 0) => f32::NAN,
        (x, _) if x < 8 => 0.0,
        _ => denoised(x, y, c),
    });
    let before = std::fs::read(&e).unwrap();
    // The first non-finite value in row order is the denoiser's: refused,
    // naming its file and pixel, before anything is written.
    let o = restore(&d, &e, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("d.exr") && err.contains("(0, 0)"),
        "{err}"
    );
    assert!(!out.exists());
    // The energy's alone: that file named.
    let clean = dir.path().join("clean.exr");
    write(&clean, (16, 12), |x, y, c| match (x, y) {
        (x, _) if x < 8 => 0.0,
        _ => denoised(x, y, c),
    });
    let o = restore(&clean, &e, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("e.exr") && err.contains("(3, 4)"),
        "{err}"
    );
    assert!(!out.exists());
    let rep = dir.path().join("r.json");
    let o = restore(
        &d,
        &e,
        &out,
        &["--nonfinite", "zero", "--report", rep.to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = read_json(&rep);
    assert_eq!(r["nonfinite_zeroed"], 1);
    // The denoiser's NaN pixel: its three channels.
    assert_eq!(r["counts"]["denoised_nonfinite"], 3);
    assert!(r["counts"]["unshaped"].as_u64().unwrap() > 0, "{r}");
    for l in r["ledger"].as_array().unwrap() {
        assert!(l["rel_error"].as_f64().unwrap() <= ENERGY_TOL, "{l}");
    }
    assert_eq!(std::fs::read(&e).unwrap(), before, "the input was touched");
}

#[test]
fn restore_keeps_more_in_place_over_epfilts_output_and_takes_keep_gain() {
    let dir = tmpdir();
    let (e, d, ep, out) = (
        dir.path().join("e.exr"),
        dir.path().join("d.exr"),
        dir.path().join("ep.exr"),
        dir.path().join("o.exr"),
    );
    write(&e, (40, 30), render);
    write(&d, (40, 30), denoised);
    epfilt_ok(&[
        "filter",
        e.to_str().unwrap(),
        ep.to_str().unwrap(),
        "--method",
        "ep-gauss",
        "-q",
    ]);
    let run = |energy: &std::path::Path, extra: &[&str]| restore_report(&d, energy, &out, extra);
    // A render: no gain, evidence alone; epfilt's ep-gauss output, read
    // from its header: a gain of one; the user's, whatever the image.
    let r = run(&e, &[]);
    assert!(r["keep_gain"].is_null(), "{r}");
    assert!(
        r["keep_gain_from"].as_str().unwrap().contains("render"),
        "{r}"
    );
    let r = run(&ep, &[]);
    assert_eq!(r["keep_gain"], 1.0);
    assert!(
        r["keep_gain_from"].as_str().unwrap().contains("ep-gauss"),
        "{r}"
    );
    let high = run(&e, &[]);
    let low = run(&e, &["--keep-gain", "2"]);
    assert_eq!(low["keep_gain_from"], "--keep-gain");
    // A lower gain keeps at least as much of the same render in place.
    assert!(
        low["kept_share"].as_f64().unwrap() >= high["kept_share"].as_f64().unwrap(),
        "{low} {high}"
    );
    std::fs::remove_file(&out).unwrap();
    for bad in ["0.5", "nan", "2e6"] {
        let o = restore(&d, &e, &out, &["--keep-gain", bad]);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{bad}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(!out.exists(), "{bad}");
    }
}

/// A render with an emission guide: a lamp the denoiser removed, within the
/// render's keep gain of the denoiser's value, comes back in place (the
/// guide's light beyond the denoiser's share around); without the guide it
/// is spread through its block. The report names the guide.
/// The lamp of the emission tests: one pixel, 100 of its 101 emitted.
const LAMP: (usize, usize) = (12, 9);

/// A 24x24 render of 1 with [`LAMP`], its emission pass (layer `layer`,
/// `None`: no pass) beside it, into `path`.
fn lamp_render(path: &std::path::Path, layer: Option<&str>) {
    let (w, h) = (24, 24);
    let at = |x, y| (x, y) == LAMP;
    let plane = |f: &dyn Fn(usize, usize) -> f32| flat((w, h), f);
    let beauty = |x, y| if at(x, y) { 101.0 } else { 1.0 };
    let emission = |x, y| if at(x, y) { 100.0 } else { 0.0 };
    let mut channels = vec![
        ("B".to_string(), plane(&beauty)),
        ("G".to_string(), plane(&beauty)),
        ("R".to_string(), plane(&beauty)),
    ];
    for c in layer.map_or(&[][..], |_| &["B", "G", "R"][..]) {
        channels.push((format!("{}.{c}", layer.unwrap()), plane(&emission)));
    }
    let channels = channels
        .iter()
        .map(|(n, p)| (n.as_str(), p.clone()))
        .collect();
    write_flat(path, (w, h), channels);
}

/// Restore a flat denoiser output onto `energy` with `extra`: the report's
/// emission guide (sorted) and the lamp's value, the ledger checked.
fn restore_lamp(
    dir: &std::path::Path,
    energy: &std::path::Path,
    extra: &[&str],
) -> (Vec<String>, f32) {
    let (d, out) = (dir.join("d.exr"), dir.join("o.exr"));
    write(&d, (24, 24), |_, _, _| 1.0);
    let r = restore_report(&d, energy, &out, extra);
    let mut names: Vec<String> = (r["emission_guide"].as_array().unwrap().iter())
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    names.sort();
    (
        names,
        crate::exr_io::read_planar(&out).at(LAMP.0, LAMP.1, 0),
    )
}

/// Without the guide the lamp is spread over its block; with it, all but
/// the denoiser's share around (a flat 1 over the 2-D kernel's centre
/// weight, about 25) stays: below and above these.
const SPREAD_BELOW: f32 = 20.0;
const KEPT_ABOVE: f32 = 70.0;

#[test]
fn restore_keeps_the_emission_guides_lamp_in_place() {
    let dir = tmpdir();
    let (e, bare) = (dir.path().join("e.exr"), dir.path().join("bare.exr"));
    lamp_render(&bare, None);
    lamp_render(&e, Some("emission"));
    let (names, spread) = restore_lamp(dir.path(), &bare, &[]);
    assert!(names.is_empty(), "{names:?}");
    assert!(spread < SPREAD_BELOW, "{spread}");
    let (names, kept) = restore_lamp(dir.path(), &e, &[]);
    assert_eq!(names, ["emission.B", "emission.G", "emission.R"]);
    assert!(kept > KEPT_ABOVE, "{kept}");
}

#[test]
fn restore_keeps_a_lamp_its_samples_agree_on_without_a_guide() {
    // No guide passes, but a variance pass and a sample count: the lamp's
    // samples all saw it (a small standard error), so it stays; with a
    // firefly's variance (one sample saw it) it spreads, as with --guides
    // none.
    let dir = tmpdir();
    let (w, h) = (24, 24);
    let at = |x, y| (x, y) == LAMP;
    let n = 16.0f32;
    let render = |path: &std::path::Path, rse: f32| {
        let plane = |f: &dyn Fn(usize, usize) -> f32| flat((w, h), f);
        let beauty = |x, y| if at(x, y) { 101.0 } else { 1.0 };
        // The sample variance whose mean's relative standard error is `rse`.
        let var = |x, y| (rse * beauty(x, y)).powi(2) * n;
        let mut channels = Vec::new();
        for c in ["B", "G", "R"] {
            channels.push((c.to_string(), plane(&beauty)));
            channels.push((format!("variance.{c}"), plane(&var)));
        }
        channels.push(("sampleCount".to_string(), plane(&|_, _| n)));
        let channels = channels
            .iter()
            .map(|(n, p)| (n.as_str(), p.clone()))
            .collect();
        write_flat(path, (w, h), channels);
    };
    let (sure, firefly) = (dir.path().join("sure.exr"), dir.path().join("firefly.exr"));
    render(&sure, 0.05);
    render(&firefly, 1.0);
    let (d, out) = (dir.path().join("d.exr"), dir.path().join("o.exr"));
    write(&d, (w, h), |_, _, _| 1.0);
    let lamp = |energy: &std::path::Path, extra: &[&str]| {
        let r = restore_report(&d, energy, &out, extra);
        let v = crate::exr_io::read_planar(&out).at(LAMP.0, LAMP.1, 0);
        (r["variance_pass"].as_str().unwrap().to_string(), v)
    };
    let (from, kept) = lamp(&sure, &[]);
    assert!(
        from.contains("variance.R") && from.contains("sampleCount"),
        "{from}"
    );
    assert!(kept > KEPT_ABOVE, "{kept}");
    let (_, spread) = lamp(&firefly, &[]);
    assert!(spread < SPREAD_BELOW, "{spread}");
    // --guides none: the pass still measures the render's uncertainty, but
    // keeps nothing in place.
    let (from, spread) = lamp(&sure, &["--guides", "none"]);
    assert!(!from.is_empty() && spread < SPREAD_BELOW, "{from} {spread}");
}

/// A render's emission pass, variance pass and sample count, carried into
/// the output, are what restore reads of them: held once in its rows, not
/// again beside them. Dropped from the output, they are read beside the
/// beauty, and the beauty comes out the same.
#[test]
fn restore_reads_a_carried_guide_and_variance_once() {
    let dir = tmpdir();
    let (w, h) = (40, 24);
    let plane = |f: &dyn Fn(usize, usize) -> f32| flat((w, h), f);
    let mut channels = Vec::new();
    for (c, name) in ["B", "G", "R"].into_iter().enumerate() {
        let beauty = move |x, y| render(x, y, c);
        channels.push((name.to_string(), plane(&beauty)));
        let glow = move |x, y| if (x, y) == LAMP { 100.0 } else { 0.0 };
        channels.push((format!("emission.{name}"), plane(&glow)));
        let var = move |x, y| (0.2 * beauty(x, y)).powi(2) * 16.0;
        channels.push((format!("variance.{name}"), plane(&var)));
    }
    channels.push(("sampleCount".to_string(), plane(&|_, _| 16.0)));
    let e = dir.path().join("e.exr");
    let named = channels.iter().map(|(n, p)| (n.as_str(), p.clone()));
    write_flat(&e, (w, h), named.collect());
    let d = dir.path().join("d.exr");
    write(&d, (w, h), denoised);
    let input_row = |r: &serde_json::Value| {
        let windows = r["windows"].as_array().unwrap();
        let input = windows.iter().find(|w| w["name"] == "input").unwrap();
        input["row_bytes"].as_u64().unwrap() as usize
    };
    // The energy's 10 channels and the denoiser's 3; dropped, the 7 passes
    // are read beside the beauty's 3.
    const ROW_CHANNELS: usize = 13;
    let (carried, dropped) = (
        dir.path().join("carried.exr"),
        dir.path().join("dropped.exr"),
    );
    let r = restore_report(&d, &e, &carried, &[]);
    assert_eq!(input_row(&r), ROW_CHANNELS * 4 * w, "{r}");
    assert!(
        r["variance_pass"].as_str().unwrap().contains("variance.R"),
        "{r}"
    );
    assert_eq!(r["emission_guide"].as_array().unwrap().len(), 3, "{r}");
    let drop = ["emission.*=drop", "variance.*=drop", "sampleCount=drop"];
    let args: Vec<&str> = drop.iter().flat_map(|d| ["--channel-rule", d]).collect();
    let r = restore_report(&d, &e, &dropped, &args);
    assert_eq!(input_row(&r), ROW_CHANNELS * 4 * w, "{r}");
    let map = |p| {
        read_channels(p)
            .into_iter()
            .collect::<std::collections::HashMap<_, _>>()
    };
    let (a, b) = (map(&carried), map(&dropped));
    assert!(!b.contains_key("variance.R") && a.contains_key("variance.R"));
    for c in ["R", "G", "B"] {
        let same = a[c]
            .iter()
            .zip(&b[c])
            .all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same, "{c}");
    }
}

/// Blender with its denoiser on writes its denoised picture as
/// `ViewLayer.Combined` and the render as `ViewLayer.Noisy Image`: one file
/// given twice restores the one with the other's energy, the result in the
/// denoised picture's place and names.
#[test]
fn restore_of_a_blender_file_puts_its_renders_energy_into_its_denoised_picture() {
    let dir = tmpdir();
    let (w, h) = (40, 24);
    let plane = |f: &dyn Fn(usize, usize) -> f32| flat((w, h), f);
    let mut channels = Vec::new();
    for (c, name) in ["B", "G", "R"].into_iter().enumerate() {
        let noisy = move |x, y| render(x, y, c);
        channels.push((
            format!("ViewLayer.Combined.{name}"),
            plane(&|x, y| denoised(x, y, c)),
        ));
        channels.push((format!("ViewLayer.Noisy Image.{name}"), plane(&noisy)));
    }
    channels.push(("ViewLayer.Depth.Z".to_string(), plane(&|_, _| 3.0)));
    let f = dir.path().join("blender.exr");
    write_flat(
        &f,
        (w, h),
        channels
            .iter()
            .map(|(n, p)| (n.as_str(), p.clone()))
            .collect(),
    );
    let out = dir.path().join("out.exr");
    let r = restore_report(&f, &f, &out, &[]);
    assert_eq!(r["blender_layers"][0], "ViewLayer.Noisy Image", "{r}");
    let o: std::collections::HashMap<_, _> = read_channels(&out).into_iter().collect();
    assert!(
        !o.keys().any(|k| k.contains("Noisy Image")),
        "{:?}",
        o.keys()
    );
    assert!(o.contains_key("ViewLayer.Depth.Z"));
    for (c, name) in ["B", "G", "R"].into_iter().enumerate() {
        let got: f64 = o[&format!("ViewLayer.Combined.{name}")]
            .iter()
            .map(|&v| f64::from(v))
            .sum();
        let want: f64 = (0..w * h).map(|i| f64::from(render(i % w, i / w, c))).sum();
        assert!(
            ((got - want) / want).abs() <= F32_SUMS,
            "{name}: {got} {want}"
        );
    }
    // Asked for, Blender's denoised picture is the energy, as any layer.
    let r = restore_report(&f, &f, &out, &["--layer", "ViewLayer.Combined"]);
    assert!(r["blender_layers"].is_null(), "{r}");
}

#[test]
fn restore_takes_the_emission_guide_it_is_told() {
    let dir = tmpdir();
    let (glow, e) = (dir.path().join("glow.exr"), dir.path().join("e.exr"));
    lamp_render(&glow, Some("glow"));
    lamp_render(&e, Some("emission"));
    // A layer no renderer's name finds: not read unless named.
    let (names, spread) = restore_lamp(dir.path(), &glow, &[]);
    assert!(names.is_empty(), "{names:?}");
    assert!(spread < SPREAD_BELOW, "{spread}");
    let (names, kept) = restore_lamp(dir.path(), &glow, &["--guide", "emission=glow"]);
    assert_eq!(names, ["glow.B", "glow.G", "glow.R"]);
    assert!(kept > KEPT_ABOVE, "{kept}");
    // --guides none leaves a pass found by name.
    let (names, spread) = restore_lamp(dir.path(), &e, &["--guides", "none"]);
    assert!(names.is_empty(), "{names:?}");
    assert!(spread < SPREAD_BELOW, "{spread}");
    // Asked for and absent, or a guide restore does not read: one line
    // naming the cause, and no output.
    let (d, out) = (dir.path().join("d.exr"), dir.path().join("absent.exr"));
    for (extra, says) in [
        (
            &["--guides", "emission"][..],
            "glow.exr: the emission guide",
        ),
        (
            &["--guide", "emission=light"][..],
            "glow.exr: the emission guide",
        ),
        (&["--guides", "albedo"][..], "emission guide only"),
    ] {
        let o = restore(&d, &glow, &out, extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains(says),
            "{extra:?}: {err}"
        );
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(!out.exists());
    }
}

#[test]
fn restore_matches_a_layered_render_to_a_plain_denoiser_output() {
    // A Blender render: its beauty in a layer, with alpha and passes; the
    // denoiser wrote plain R, G, B. Colour pairs by name after the layer,
    // the alpha stays as the render has it, and the result is named as
    // the render's beauty.
    let dir = tmpdir();
    let (e, d, out, rep) = (
        dir.path().join("e.exr"),
        dir.path().join("d.exr"),
        dir.path().join("o.exr"),
        dir.path().join("r.json"),
    );
    let (w, h) = (40, 30);
    let plane = |f: &dyn Fn(usize, usize) -> f32| flat((w, h), f);
    let alpha = |x: usize, y: usize| ((x * 3 + y * 5) % 7) as f32 / 6.0;
    let c = |ch| move |x, y| render(x, y, ch);
    write_flat(
        &e,
        (w, h),
        vec![
            ("ViewLayer.Combined.A", plane(&alpha)),
            ("ViewLayer.Combined.B", plane(&c(2))),
            ("ViewLayer.Combined.G", plane(&c(1))),
            ("ViewLayer.Combined.R", plane(&c(0))),
            ("ViewLayer.Depth.Z", plane(&|_, _| 3.0)),
        ],
    );
    write(&d, (w, h), denoised);
    let o = restore(&d, &e, &out, &["--report", rep.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = read_json(&rep);
    assert_eq!(
        r["copied_channels"],
        serde_json::json!(["ViewLayer.Combined.A"]),
        "{r}"
    );
    for l in r["ledger"].as_array().unwrap() {
        assert!(l["rel_error"].as_f64().unwrap() <= ENERGY_TOL, "{l}");
    }
    let got = read_channels(&out);
    let names: Vec<&str> = got.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "ViewLayer.Combined.A",
            "ViewLayer.Combined.B",
            "ViewLayer.Combined.G",
            "ViewLayer.Combined.R",
            "ViewLayer.Depth.Z"
        ]
    );
    let want: Vec<f32> = (0..w * h).map(|i| alpha(i % w, i / w)).collect();
    assert_eq!(got[0].1, want, "the alpha, bit for bit");
    // A colour channel the denoiser lacks is still an error.
    write_flat(
        &d,
        (w, h),
        vec![("G", plane(&|_, _| 1.0)), ("R", plane(&|_, _| 1.0))],
    );
    let o = restore(&d, &e, &dir.path().join("o2.exr"), &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("channels"), "{err}");
}

#[test]
fn restore_carries_the_renders_other_channels_as_they_are() {
    // A render's passes beside the beauty (a sky's infinite depth, half
    // normals, integer ids, a light AOV) come out bit for bit and of their
    // own types; they change nothing in the beauty, stay out of the
    // ledger, and a drop rule leaves them out.
    let dir = tmpdir();
    let (e, d) = (dir.path().join("e.exr"), dir.path().join("d.exr"));
    let (w, h) = (37, 29);
    let f32s = |f: &dyn Fn(usize, usize) -> f32| flat((w, h), f);
    let depth = |x: usize, y: usize| if y < 5 { f32::INFINITY } else { (x + y) as f32 };
    let normal = FlatSamples::F16(
        (0..w * h)
            .map(|i| half::f16::from_f32(((i % 13) as f32 - 6.0) / 6.0))
            .collect(),
    );
    let ids = FlatSamples::U32(
        (0..w * h)
            .map(|i| (i as u32).wrapping_mul(2654435761) >> 8)
            .collect(),
    );
    let c = |ch| move |x, y| render(x, y, ch);
    write_flat(
        &e,
        (w, h),
        vec![
            ("B", f32s(&c(2))),
            ("G", f32s(&c(1))),
            ("R", f32s(&c(0))),
            ("Z", f32s(&depth)),
            ("N.X", normal),
            ("id", ids),
            ("diffuse.R", f32s(&|x, y| 0.25 * render(x, y, 0))),
        ],
    );
    write(&d, (w, h), denoised);
    let run = |out: &str, extra: &[&str]| {
        let (out, rep) = (dir.path().join(out), dir.path().join(format!("{out}.json")));
        let mut args = vec!["--report", rep.to_str().unwrap()];
        args.extend(extra);
        let o = restore(&d, &e, &out, &args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (read_samples(&out), read_json(&rep))
    };
    let (all, r) = run("all.exr", &[]);
    let (bare, _) = run("bare.exr", &["--channel-rule", "*=drop"]);
    let names = |s: &[(String, FlatSamples)]| s.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    assert_eq!(names(&bare), ["B", "G", "R"]);
    assert_eq!(
        r["carried_channels"],
        serde_json::json!(["N.X", "Z", "diffuse.R", "id"]),
        "{r}"
    );
    let ledger: Vec<&str> = (r["ledger"].as_array().unwrap().iter())
        .map(|l| l["channel"].as_str().unwrap())
        .collect();
    assert_eq!(ledger, ["R", "G", "B"], "the copies are out of the ledger");
    let bits = |s: &FlatSamples| -> (&'static str, Vec<u32>) {
        match s {
            FlatSamples::F16(v) => ("f16", v.iter().map(|x| u32::from(x.to_bits())).collect()),
            FlatSamples::F32(v) => ("f32", v.iter().map(|x| x.to_bits()).collect()),
            FlatSamples::U32(v) => ("u32", v.clone()),
        }
    };
    let input = read_samples(&e);
    for (name, samples) in &all {
        let (_, want) = input.iter().find(|(n, _)| n == name).unwrap();
        match bare.iter().find(|(n, _)| n == name) {
            // The beauty is what it is without the passes.
            Some((_, b)) => assert_eq!(bits(samples), bits(b), "{name}"),
            None => assert_eq!(bits(samples), bits(want), "{name}, as the render has it"),
        }
    }
    assert_eq!(all.len(), input.len());
    let (some, r) = run(
        "some.exr",
        &["--channel-rule", "*.*=drop", "--channel-rule", "id=drop"],
    );
    assert_eq!(names(&some), ["B", "G", "R", "Z"]);
    assert_eq!(r["carried_channels"], serde_json::json!(["Z"]), "{r}");
}

/// `f` as a portable float map, OIDN's format: rows from the bottom up,
/// big-endian floats (a positive scale).
fn write_pfm(
    path: &std::path::Path,
    (w, h): (usize, usize),
    f: impl Fn(usize, usize, usize) -> f32,
) {
    let mut b = format!("PF\n{w} {h}\n1.0\n").into_bytes();
    for y in (0..h).rev() {
        for x in 0..w {
            for c in 0..3 {
                b.extend(f(x, y, c).to_be_bytes());
            }
        }
    }
    std::fs::write(path, b).unwrap();
}

#[test]
fn restore_reads_oidns_portable_float_map() {
    // `oidnDenoise` writes PFM: the same picture as a PFM and as an EXR
    // gives the same result, bit for bit; a truncated map is one line
    // naming the file, and nothing is written.
    let dir = tmpdir();
    let p = |n: &str| dir.path().join(n);
    let (w, h) = (41, 23);
    let tinted = |x, y, c: usize| denoised(x, y, c) * (1.0 + 0.1 * c as f32) + 0.01 * x as f32;
    write(&p("e.exr"), (w, h), render);
    write(&p("d.exr"), (w, h), tinted);
    write_pfm(&p("d.pfm"), (w, h), tinted);
    let from_exr = restore_report(&p("d.exr"), &p("e.exr"), &p("o1.exr"), &[]);
    let from_pfm = restore_report(&p("d.pfm"), &p("e.exr"), &p("o2.exr"), &[]);
    assert_eq!(from_exr["digest"], from_pfm["digest"]);
    let bytes = std::fs::read(p("d.pfm")).unwrap();
    std::fs::write(p("cut.pfm"), &bytes[..bytes.len() - 5]).unwrap();
    let o = restore(&p("cut.pfm"), &p("e.exr"), &p("o3.exr"), &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("cut.pfm") && err.contains("truncated"),
        "{err}"
    );
    // Named as what it is, not as an EXR.
    assert!(
        err.contains("portable float map") && !err.contains("EXR"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!p("o3.exr").exists());
}

#[test]
fn restore_takes_a_part_and_a_layer_of_the_energy_image() {
    let dir = tmpdir();
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let multi = std::path::Path::new(crate::parts::MULTI);
    let (d, out) = (dir.path().join("d.exr"), dir.path().join("o.exr"));
    // Without a part: one line saying how to choose, and no output.
    let o = restore(multi, multi, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--part"), "{err}");
    assert!(!out.exists());
    // Its part in both files, then a single-part denoiser output of it.
    let o = restore(multi, multi, &out, &["--part", "beauty_float_piz"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    epfilt_ok(&[
        "filter",
        &s(multi),
        &s(&d),
        "--part",
        "0",
        "-s",
        "1",
        "--method",
        "gauss",
        "-q",
    ]);
    let rep = dir.path().join("r.json");
    let o = restore(&d, multi, &out, &["--part", "0", "--report", &s(&rep)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for l in read_json(&rep)["ledger"].as_array().unwrap() {
        assert!(l["rel_error"].as_f64().unwrap() <= ENERGY_TOL, "{l}");
    }
    // A layer other than the beauty.
    let layered = std::path::Path::new("tests/data/exr/small/aovs_multilayer.exr");
    let o = restore(
        layered,
        layered,
        &out,
        &["--layer", "diffuse", "--report", &s(&rep)],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = read_json(&rep);
    let ledger: Vec<&str> = (r["ledger"].as_array().unwrap().iter())
        .map(|l| l["channel"].as_str().unwrap())
        .collect();
    assert_eq!(ledger, ["diffuse.R", "diffuse.G", "diffuse.B"], "{r}");
    // The rest of the file, the render's beauty too, as it has them.
    let carried = r["carried_channels"].as_array().unwrap();
    assert!(
        carried.iter().any(|c| c == "R") && !carried.iter().any(|c| c == "diffuse.R"),
        "{r}"
    );
    let names: Vec<String> = read_channels(&out).into_iter().map(|(n, _)| n).collect();
    assert_eq!(names.len(), 18, "{names:?}");
}

/// `--max-memory`: a budget below the default estimate runs shorter strips
/// and writes the same bytes; below the floor it is refused, naming the
/// floor and the scale, and nothing is written. A larger scale holds more
/// rows of the image: its floor is higher.
#[test]
fn restore_runs_within_its_memory_or_refuses_naming_the_floor() {
    let dir = tmpdir();
    let (e, d) = (dir.path().join("e.exr"), dir.path().join("d.exr"));
    // Wide: the rows held are most of what a restore holds.
    write(&e, (4096, 96), render);
    write(&d, (4096, 96), denoised);
    let out = dir.path().join("o.exr");
    let full = restore_report(&d, &e, &out, &["--scale", "16"]);
    let default_mib = full["memory_estimate_bytes"].as_u64().unwrap() >> 20;
    let floor_of = |scale: &str| {
        let none = dir.path().join("none.exr");
        let o = restore(&d, &e, &none, &["--scale", scale, "--max-memory", "1"]);
        assert_eq!(o.status.code(), Some(2));
        let text = String::from_utf8_lossy(&o.stderr).to_string();
        assert!(
            text.contains("--scale") && text.contains("--max-memory"),
            "{text}"
        );
        assert!(!none.exists(), "nothing written when refused");
        text.split("at least about ")
            .nth(1)
            .and_then(|t| t.split(' ').next())
            .and_then(|n| n.parse::<u64>().ok())
            .expect("the error names its floor")
    };
    let floor = floor_of("16");
    assert!(floor < default_mib, "{floor} {default_mib}");
    assert!(floor_of("64") > floor, "a larger scale holds more rows");
    // Between the floor and the default: shorter strips, the same bytes.
    let budget = ((floor + default_mib) / 2).to_string();
    let small = dir.path().join("small.exr");
    let r = restore_report(&d, &e, &small, &["--scale", "16", "--max-memory", &budget]);
    assert!(r["memory_estimate_bytes"].as_u64().unwrap() <= budget.parse::<u64>().unwrap() << 20);
    assert!(
        r["strip_rows"].as_u64() < full["strip_rows"].as_u64(),
        "{r}"
    );
    assert_eq!(r["digest"], full["digest"]);
}
