//! Renders as renderers write them: the input decides S and the method,
//! a pixel-resolution render keeps its clean pixels, and the guide passes
//! (emission, albedo, normal, depth) keep lamps and surfaces apart, under
//! the same energy and invariance as everything else.

use std::path::Path;

use exr::image::FlatSamples;

use crate::common::{epfilt_run as epfilt, image_bytes, read_json, ENERGY_TOL};
use crate::exr_io::{tmpdir, write_flat, write_named, write_views};

/// A grey room (about 0.5) with a few pixels set, R, G, B alike.
fn room(lit: &[((usize, usize), f32)]) -> impl Fn(usize, usize) -> f32 + '_ {
    move |x, y| {
        lit.iter()
            .find(|(p, _)| *p == (x, y))
            .map_or(0.5 + 0.02 * ((x * 7 + y * 3) % 5) as f32, |(_, v)| *v)
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `epfilt info --json`'s first part, which must succeed.
fn info_part(path: &Path) -> serde_json::Value {
    let info = epfilt(&["info", s(path), "--json"]);
    assert!(
        info.status.success(),
        "{}",
        String::from_utf8_lossy(&info.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    j["parts"][0].clone()
}

/// Run `epfilt filter` with a JSON report; the report.
fn filter(args: &[&str], dir: &Path) -> serde_json::Value {
    let rep = dir.join("r.json");
    let mut all = vec!["filter", "-q", "--report", s(&rep)];
    all.extend_from_slice(args);
    let o = epfilt(&all);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r = read_json(&rep);
    for e in r["energy_rel_error"].as_array().unwrap() {
        assert!(e.as_f64().unwrap().abs() <= ENERGY_TOL, "{args:?}: {r}");
    }
    r
}

/// Every channel of a file, by name.
fn planes(path: &Path) -> std::collections::HashMap<String, Vec<f32>> {
    let img = exr::prelude::read_all_flat_layers_from_file(path).expect("read");
    img.layer_data[0]
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect()
}

#[test]
fn the_input_decides_s_and_the_method() {
    let dir = tmpdir();
    let d = dir.path();
    let (w, h) = (24, 18);
    let px = room(&[((5, 5), 60.0)]);
    // A render at final resolution: never reduced, ep-gauss.
    let plain = d.join("plain.exr");
    write_named(&plain, w, h, &["R", "G", "B"], &[], |x, y, _| px(x, y));
    let r = filter(&[s(&plain), s(&d.join("o.exr"))], d);
    assert_eq!(
        (r["supersample"].as_u64(), r["out_width"].as_u64()),
        (Some(1), Some(24))
    );
    assert_eq!(r["method"], "ep-gauss");
    assert!(
        r["supersample_from"]
            .as_str()
            .unwrap()
            .contains("pixel resolution"),
        "{r}"
    );
    assert!(
        r["method_from"]
            .as_str()
            .unwrap()
            .contains("no per-pixel variance"),
        "{r}"
    );
    // With variance and a sample count: ep-box, and info says so first.
    let var = d.join("var.exr");
    write_named(
        &var,
        w,
        h,
        &["R", "G", "B", "variance.R", "variance.G", "variance.B"],
        &[("spp", 16)],
        |x, y, c| if c < 3 { px(x, y) } else { 0.01 },
    );
    let info = epfilt(&["info", s(&var)]);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(
        text.contains("filter by default: ep-box at S = 1"),
        "{text}"
    );
    let r = filter(&[s(&var), s(&d.join("o.exr"))], d);
    assert_eq!(r["method"], "ep-box");
    assert!(
        r["method_from"].as_str().unwrap().contains("variance"),
        "{r}"
    );
    // A super-sampled render that says so: reduced S times; --supersample 1
    // overrides it.
    let ss = d.join("ss.exr");
    write_named(
        &ss,
        w,
        h,
        &["R", "G", "B"],
        &[("epfiltSupersample", 3)],
        |x, y, _| px(x, y),
    );
    let r = filter(&[s(&ss), s(&d.join("o.exr"))], d);
    assert_eq!(
        (r["supersample"].as_u64(), r["out_width"].as_u64()),
        (Some(3), Some(8))
    );
    assert!(
        r["supersample_from"]
            .as_str()
            .unwrap()
            .contains("epfiltSupersample"),
        "{r}"
    );
    let r = filter(&[s(&ss), s(&d.join("o.exr")), "-s", "1"], d);
    assert_eq!(r["out_width"].as_u64(), Some(24));
    // An attribute that is no factor: one line naming it.
    let bad = d.join("bad.exr");
    write_named(
        &bad,
        w,
        h,
        &["R", "G", "B"],
        &[("epfiltSupersample", 9)],
        |x, y, _| px(x, y),
    );
    let o = epfilt(&["filter", s(&bad), s(&d.join("o.exr"))]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("epfiltSupersample") && e.lines().count() == 1,
        "{e}"
    );
}

#[test]
fn at_pixel_resolution_clean_pixels_keep_their_bits() {
    let dir = tmpdir();
    let d = dir.path();
    let (w, h) = (80, 60);
    let px = room(&[((30, 20), 40.0)]);
    let input = d.join("in.exr");
    write_named(&input, w, h, &["R", "G", "B"], &[], |x, y, _| px(x, y));
    let out = d.join("out.exr");
    let r = filter(&[s(&input), s(&out)], d);
    assert_eq!(r["samples_spread"].as_u64(), Some(1), "{r}");
    let (i, o) = (planes(&input), planes(&out));
    let reach = 3 * 16; // --cutoff times --max-radius
    let mut changed = 0;
    for k in 0..w * h {
        let (x, y) = (k % w, k / w);
        let same = i["G"][k].to_bits() == o["G"][k].to_bits();
        changed += usize::from(!same);
        if x.abs_diff(30) > reach || y.abs_diff(20) > reach {
            assert!(same, "({x}, {y}) changed, out of the spread's reach");
        }
    }
    assert!(changed > 8, "the firefly's excess went somewhere");
    assert!(o["G"][20 * w + 30] < 2.0, "{}", o["G"][20 * w + 30]);
}

/// The channels of [`guided_room`]'s file.
const GUIDED_CHANNELS: [&str; 10] = [
    "R",
    "G",
    "B",
    "emission.R",
    "emission.G",
    "emission.B",
    "N.X",
    "N.Y",
    "N.Z",
    "Z",
];

/// A room with a one-pixel bulb at (20, 20), named by the emission guide,
/// and a firefly as bright at (26, 20); normals: up left of x = 40, facing
/// the camera from there (a floor meeting a wall).
fn guided_room(path: &Path, w: usize, h: usize, extra: &[(&str, i32)]) {
    let lit = [((20, 20), 40.0), ((26, 20), 40.0), ((37, 30), 30.0)];
    let px = room(&lit);
    write_named(path, w, h, &GUIDED_CHANNELS, extra, |x, y, c| match c {
        0..=2 => px(x, y),
        3..=5 => {
            if (x, y) == (20, 20) {
                39.5
            } else {
                0.0
            }
        }
        6..=8 => {
            let n = if x < 40 {
                [0.0, 1.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            };
            n[c - 6]
        }
        _ if y < 2 => f32::INFINITY, // a sky's depth: data, any value
        _ => 3.0 + 0.01 * y as f32,
    });
}

#[test]
fn the_emission_guide_keeps_a_bulb_and_spreads_the_firefly_beside_it() {
    let dir = tmpdir();
    let d = dir.path();
    let (w, h) = (72, 60);
    let input = d.join("in.exr");
    guided_room(&input, w, h, &[]);
    let (bulb, firefly) = (20 * w + 20, 20 * w + 26);
    let plain = d.join("plain.exr");
    let r = filter(&[s(&input), s(&plain), "--guides", "none"], d);
    assert_eq!(r["guides"], "none");
    let p = planes(&plain);
    assert!(
        p["G"][bulb] < 20.0 && p["G"][firefly] < 20.0,
        "alike without it"
    );
    let guided = d.join("guided.exr");
    let r = filter(&[s(&input), s(&guided)], d);
    assert!(
        r["guides"]
            .as_str()
            .unwrap()
            .contains("emission (emission.R"),
        "{r}"
    );
    let (i, g) = (planes(&input), planes(&guided));
    assert_eq!(
        g["G"][bulb].to_bits(),
        i["G"][bulb].to_bits(),
        "the bulb keeps its value"
    );
    assert!(g["G"][firefly] < 5.0, "{}", g["G"][firefly]);
    // The guides are carried as they are.
    for c in ["emission.R", "N.Y", "Z"] {
        assert!(
            i[c].iter()
                .zip(&g[c])
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{c}"
        );
    }
    // And at S = 3 (the file says so), where the emission guide is read too.
    let ss = d.join("ss.exr");
    guided_room(&ss, w, h, &[("epfiltSupersample", 3)]);
    let r = filter(&[s(&ss), s(&d.join("o3.exr"))], d);
    assert_eq!(r["supersample"].as_u64(), Some(3));
    assert!(r["guides"].as_str().unwrap().starts_with("emission"), "{r}");
}

/// A guide carried as it is read is held once: the stage reads it where it
/// is carried. Dropped from the output, it is read beside the channels, and
/// the beauty comes out the same.
#[test]
fn a_carried_guide_is_read_where_it_is_carried() {
    let dir = tmpdir();
    let d = dir.path();
    let (w, h) = (72, 60);
    let input = d.join("in.exr");
    guided_room(&input, w, h, &[]);
    let input_row = |r: &serde_json::Value| {
        let windows = r["windows"].as_array().unwrap();
        let input = windows.iter().find(|w| w["name"] == "input").unwrap();
        input["row_bytes"].as_u64().unwrap() as usize
    };
    let carried = d.join("carried.exr");
    let r = filter(&[s(&input), s(&carried)], d);
    assert_eq!(input_row(&r), GUIDED_CHANNELS.len() * 4 * w, "{r}");
    let dropped = d.join("dropped.exr");
    let r = filter(&[s(&input), s(&dropped), "--channel-rule", "N.*=drop"], d);
    // The three normals are read beside the seven channels carried.
    assert_eq!(input_row(&r), GUIDED_CHANNELS.len() * 4 * w, "{r}");
    assert!(r["guides"].as_str().unwrap().contains("normal"), "{r}");
    let (a, b) = (planes(&carried), planes(&dropped));
    assert!(!b.contains_key("N.X"));
    for c in ["R", "G", "B"] {
        assert!(
            a[c].iter()
                .zip(&b[c])
                .all(|(x, y)| x.to_bits() == y.to_bits()),
            "{c}"
        );
    }
}

/// The summary's ledger lists the channels of light; the guide passes,
/// carried as read, are data out of the ledger (their zeros there would
/// read as passes of no light) and are listed as carried.
#[test]
fn the_summarys_ledger_lists_light_and_the_carried_passes_apart() {
    let dir = tmpdir();
    let d = dir.path();
    let input = d.join("in.exr");
    guided_room(&input, 48, 40, &[]);
    let out = d.join("out.exr");
    let o = epfilt(&["filter", s(&input), s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    let ledger: Vec<&str> = (err.lines())
        .skip_while(|l| !l.contains("energy ledger"))
        .skip(1)
        .take_while(|l| l.starts_with("                  "))
        .map(|l| l.split_whitespace().next().unwrap_or(""))
        .collect();
    assert_eq!(ledger, ["R", "G", "B"], "{err}");
    let carried = err.lines().find(|l| l.contains("carried:")).unwrap_or("");
    for c in &GUIDED_CHANNELS[3..] {
        assert!(carried.contains(c), "{c}: {err}");
    }
}

/// Blender with the compositor on writes `Composite.Combined` (made after
/// the render) beside `ViewLayer.Combined` and its passes, and a second view
/// layer has a `Combined` of its own: the render beside its passes is the
/// one filtered, with its own guides, and the others are named in a
/// warning; another layer asked for gets none of the passes of the view
/// layer beside it. With its denoiser on, the warning says where the
/// render is.
#[test]
fn of_blenders_layers_the_view_layers_render_is_filtered_with_its_passes() {
    let dir = tmpdir();
    let (w, h) = (16, 12);
    let path = dir.path().join("blender.exr");
    let flat = |v: f32| FlatSamples::F32(vec![v; w * h]);
    let mut names = Vec::new();
    for layer in [
        "Composite.Combined",
        "Second.Combined",
        "ViewLayer.Combined",
    ] {
        names.extend(["A", "B", "G", "R"].map(|c| format!("{layer}.{c}")));
    }
    names.extend(["B", "G", "R"].map(|c| format!("ViewLayer.Emit.{c}")));
    names.extend(["X", "Y", "Z"].map(|c| format!("ViewLayer.Normal.{c}")));
    // Its denoiser on, Cycles writes the render as `Noisy Image` too.
    names.extend(["A", "B", "G", "R"].map(|c| format!("ViewLayer.Noisy Image.{c}")));
    let channels = names.iter().map(|n| (n.as_str(), flat(1.0))).collect();
    write_flat(&path, (w, h), channels);
    let part = &info_part(&path);
    assert_eq!(part["filtered"][0], "ViewLayer.Combined.R", "{part}");
    assert_eq!(
        part["guide_channels"]["emission"][0], "ViewLayer.Emit.R",
        "{part}"
    );
    let out = dir.path().join("out.exr");
    let r = filter(&[s(&path), s(&out)], dir.path());
    let said = r["warnings"].to_string();
    assert!(
        said.contains(
            "filtered ViewLayer.Combined; Composite.Combined, Second.Combined carried unfiltered"
        ),
        "{r}"
    );
    let noisy = "--layer 'ViewLayer.Noisy Image' filters the render";
    assert!(said.contains(noisy), "{r}");
    for layer in ["Composite.Combined", "Second.Combined"] {
        let r = filter(&[s(&path), s(&out), "--layer", layer], dir.path());
        assert_eq!(r["guides"], "none", "{layer}: {r}");
    }
}

/// A stereo render as Blender writes it: one part, `multiView` left and
/// right, and every pass of each view named with it, the default view's
/// too (`ViewLayer.Combined.left.R`): the room with a bright pixel at
/// `lamp` in each of `layers` (`Combined`...), and an `Emit` pass that
/// names it a lamp in the right view only.
fn write_blender_stereo(
    path: &Path,
    (w, h): (usize, usize),
    lamp: (usize, usize),
    layers: &[&str],
) {
    let lit = [(lamp, 60.0)];
    let px = room(&lit);
    let mut channels = Vec::new();
    for view in ["left", "right"] {
        for c in ["R", "G", "B"] {
            for layer in layers.iter().chain(&["Emit"]) {
                let emits = |x, y| view == "right" && (x, y) == lamp;
                let v = |x, y| match *layer == "Emit" {
                    true if emits(x, y) => px(x, y),
                    true => 0.0,
                    false => px(x, y),
                };
                let plane = (0..w * h).map(|i| v(i % w, i / w)).collect();
                channels.push((
                    format!("ViewLayer.{layer}.{view}.{c}"),
                    FlatSamples::F32(plane),
                ));
            }
        }
    }
    let named = channels
        .iter()
        .map(|(n, v)| (n.as_str(), v.clone()))
        .collect();
    write_views(path, (w, h), named, &["left", "right"]);
}

/// Blender's stereo file ([`write_blender_stereo`]): each view is filtered
/// with its own passes: the bright pixel is a lamp in the right view (its
/// emission pass says so) and a firefly in the left one.
#[test]
fn blenders_stereo_file_filters_each_view_with_its_own_passes() {
    let dir = tmpdir();
    let d = dir.path();
    let (w, h) = (32, 24);
    let lamp = (12, 10);
    let input = d.join("stereo.exr");
    write_blender_stereo(&input, (w, h), lamp, &["Combined"]);
    let part = &info_part(&input);
    assert_eq!(part["filtered"][0], "ViewLayer.Combined.left.R", "{part}");
    assert_eq!(
        part["guide_channels"]["emission"][0], "ViewLayer.Emit.left.R",
        "{part}"
    );
    let at = lamp.1 * w + lamp.0;
    let left = d.join("left.exr");
    filter(&[s(&input), s(&left)], d);
    let l = planes(&left);
    assert!(l["ViewLayer.Combined.left.G"][at] < 60.0, "a firefly there");
    let right = d.join("right.exr");
    let r = filter(&[s(&input), s(&right), "--view", "right"], d);
    assert!(
        r["guides"].to_string().contains("ViewLayer.Emit.right.G"),
        "{r}"
    );
    let rp = planes(&right);
    assert_eq!(rp["ViewLayer.Combined.right.G"][at], 60.0, "a lamp there");
    // Another view's layer named in this view's run: the way to it.
    let o = epfilt(&[
        "filter",
        s(&input),
        s(&right),
        "--layer",
        "ViewLayer.Combined.right",
    ]);
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && said.contains("--view right"),
        "{said}"
    );
    // --view all: each view as filtering it alone gives.
    let all = d.join("all.exr");
    filter(&[s(&input), s(&all), "--view", "all"], d);
    let a = planes(&all);
    for (p, view) in [(&l, "left"), (&rp, "right")] {
        let name = format!("ViewLayer.Combined.{view}.G");
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a[&name]), bits(&p[&name]), "{view}");
    }
}

/// One-file restore of Blender's stereo file with its denoiser on: the
/// default view's render (`Noisy Image.left`) is the energy, the result
/// takes its denoised `Combined.left`'s names, and the other view is left
/// out with a warning.
#[test]
fn restore_of_blenders_stereo_file_takes_its_default_views_render() {
    let dir = tmpdir();
    let d = dir.path();
    let input = d.join("stereo.exr");
    write_blender_stereo(&input, (32, 24), (12, 10), &["Combined", "Noisy Image"]);
    let (out, rep) = (d.join("out.exr"), d.join("r.json"));
    let o = epfilt(&[
        "restore",
        s(&input),
        s(&input),
        s(&out),
        "--report",
        s(&rep),
    ]);
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("other views left out"), "{said}");
    let r = read_json(&rep);
    assert_eq!(r["blender_layers"][0], "ViewLayer.Noisy Image", "{r}");
    let left_out = r["views_left_out"].to_string();
    assert!(left_out.contains("ViewLayer.Combined.right.R"), "{r}");
    let p = planes(&out);
    assert!(
        p.contains_key("ViewLayer.Combined.left.G"),
        "{:?}",
        p.keys()
    );
    assert!(
        !p.keys().any(|k| k.contains("right") || k.contains("Noisy")),
        "{:?}",
        p.keys()
    );
    // `filter` says where the render is, as `--layer` names it.
    let r = filter(&[s(&input), s(&out)], d);
    let noisy = "--layer 'ViewLayer.Noisy Image' filters the render";
    assert!(r["warnings"].to_string().contains(noisy), "{r}");
}

#[test]
fn a_surface_guide_keeps_a_spread_on_its_side_of_an_edge() {
    let dir = tmpdir();
    let d = dir.path();
    let (w, h) = (72, 60);
    let input = d.join("in.exr");
    guided_room(&input, w, h, &[]);
    let i = planes(&input);
    // The firefly at (37, 30) is three pixels from the wall at x = 40.
    let right = |p: &std::collections::HashMap<String, Vec<f32>>| {
        (0..h)
            .flat_map(|y| (40..w).map(move |x| y * w + x))
            .filter(|&k| p["G"][k].to_bits() != i["G"][k].to_bits())
            .count()
    };
    let out = d.join("out.exr");
    filter(&[s(&input), s(&out), "--guides", "emission"], d);
    assert!(right(&planes(&out)) > 0, "without the normals it crosses");
    filter(&[s(&input), s(&out)], d);
    assert_eq!(right(&planes(&out)), 0, "with them it stays on the floor");
}

/// ep-box on a surface one pixel wide (a sliver of other normals down
/// column 30): the noisy pixel's nearest receivers are mostly off its
/// surface, so it keeps clear of lights only (`SURFACE_SHARE`) and shares
/// its excess with its nearest pixels, where keeping to the column (which
/// has receivers enough for it) would hand it all to pixels up and down the
/// sliver.
#[test]
fn ep_box_on_a_sliver_shares_with_its_nearest_pixels() {
    let dir = tmpdir();
    let d = dir.path();
    let (w, h) = (60, 48);
    let noisy = (30, 20);
    // A flat room, and an excess small enough that the column alone has
    // receivers for it within --max-radius.
    let px = |x: usize, y: usize| if (x, y) == noisy { 0.56 } else { 0.5 };
    let input = d.join("in.exr");
    let f = |n: &str| -> Vec<f32> {
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| match n {
                "R" | "G" | "B" => px(x, y),
                "N.X" => f32::from(x == 30),
                "N.Z" => f32::from(x != 30),
                "N.Y" => 0.0,
                _ if (x, y) == noisy => 4.0,
                _ => 1e-4,
            })
            .collect()
    };
    let names = [
        "R",
        "G",
        "B",
        "N.X",
        "N.Y",
        "N.Z",
        "variance.R",
        "variance.G",
        "variance.B",
    ];
    let list = names
        .iter()
        .map(|&n| (n, exr::prelude::FlatSamples::F32(f(n))))
        .collect();
    write_flat(&input, (w, h), list);
    let out = d.join("out.exr");
    let r = filter(&[s(&input), s(&out), "--spp", "16"], d);
    assert_eq!(r["method"], "ep-box", "{r}");
    assert!(r["guides"].as_str().unwrap().contains("normal"), "{r}");
    let (i, o) = (planes(&input), planes(&out));
    let gained = |on: bool| -> f64 {
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| (x == 30) == on && (x, y) != noisy)
            .map(|(x, y)| f64::from(o["G"][y * w + x] - i["G"][y * w + x]))
            .sum()
    };
    let (on, off) = (gained(true), gained(false));
    // Most of it lands off the sliver (keeping to it would leave none there).
    assert!(off > on, "on the sliver {on}, off it {off}");
}

#[test]
fn guides_keep_the_output_across_tiles_strips_threads_and_bands() {
    let dir = tmpdir();
    let d = dir.path();
    let (w, h) = (72, 60);
    let input = d.join("in.exr");
    guided_room(&input, w, h, &[]);
    let var = d.join("var.exr");
    {
        // The same with variance (ep-box), where the lit pixels are noisy.
        let p = planes(&input);
        let ch = |n: &str| exr::prelude::FlatSamples::F32(p[n].clone());
        let v: Vec<f32> = p["G"]
            .iter()
            .map(|&g| if g > 5.0 { 400.0 } else { 0.01 })
            .collect();
        let mut list = vec![];
        for n in GUIDED_CHANNELS {
            list.push((n, ch(n)));
        }
        for n in ["variance.R", "variance.G", "variance.B"] {
            list.push((n, exr::prelude::FlatSamples::F32(v.clone())));
        }
        write_flat(&var, (w, h), list);
    }
    for (file, extra) in [(&input, vec![]), (&var, vec!["--spp", "16"])] {
        let whole = d.join("whole.exr");
        let mut args = vec![s(file), s(&whole)];
        args.extend(extra.iter().copied());
        filter(&args, d);
        let want = image_bytes(&whole);
        for (tile, strip, threads) in [("5", "3", "1"), ("16", "7", "2"), ("64", "1", "3")] {
            let o = d.join("o.exr");
            let mut a = vec![s(file), s(&o), "--tile", tile, "--strip-rows", strip];
            a.extend(["--threads", threads, "--oversubscribe"]);
            a.extend(extra.iter().copied());
            filter(&a, d);
            assert!(
                image_bytes(&o) == want,
                "{file:?} tile {tile} strips {strip} threads {threads}"
            );
        }
        let parts: Vec<String> = (1..=3)
            .map(|k| {
                let part = d.join(format!("part{k}.exr"));
                let band = format!("{k}/3");
                let mut a = vec![s(file), s(&part), "--band", band.as_str()];
                a.extend(extra.iter().copied());
                filter(&a, d);
                part.to_string_lossy().into_owned()
            })
            .collect();
        let merged = d.join("merged.exr");
        let mut a = vec!["merge"];
        a.extend(parts.iter().map(String::as_str));
        a.push(s(&merged));
        let o = epfilt(&a);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(
            image_bytes(&merged) == want,
            "{file:?}: bands merged differ"
        );
    }
}

#[test]
fn a_guide_missing_or_of_the_wrong_type_is_refused_in_one_line() {
    use exr::prelude::FlatSamples;
    let dir = tmpdir();
    let d = dir.path();
    let (w, h) = (12, 9);
    let out = d.join("out.exr");
    let one_line = |args: &[&str], needle: &str| {
        let o = epfilt(args);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            e.trim_end().lines().count() == 1 && e.contains(needle),
            "{e}"
        );
        assert!(!out.exists());
    };
    let plain = d.join("plain.exr");
    write_named(
        &plain,
        w,
        h,
        &["R", "G", "B", "N.X", "N.Y"],
        &[],
        |_, _, _| 0.5,
    );
    one_line(
        &["filter", s(&plain), s(&out), "--guides", "normal"],
        "normal guide",
    );
    one_line(
        &["filter", s(&plain), s(&out), "--guide", "emission=glow"],
        "\"glow\"",
    );
    one_line(
        &["filter", s(&plain), s(&out), "--guides", "light"],
        "unknown guide",
    );
    // An id where an albedo should be.
    let ids = d.join("ids.exr");
    let f = |v: f32| FlatSamples::F32(vec![v; w * h]);
    write_flat(
        &ids,
        (w, h),
        vec![
            ("R", f(0.5)),
            ("G", f(0.5)),
            ("B", f(0.5)),
            ("albedo.R", FlatSamples::U32(vec![1; w * h])),
            ("albedo.G", f(0.5)),
            ("albedo.B", f(0.5)),
        ],
    );
    one_line(&["filter", s(&ids), s(&out)], "unsigned integers");
    // Without the guides asked for, a file without them is filtered.
    let o = epfilt(&["filter", "-q", s(&plain), s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
