//! Never lose or mislabel a user's data: output formats chosen by name,
//! pipes both ways, parts everywhere, bands and retries that cannot be
//! mistaken for finished work, and nothing dropped without a word.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Output, Stdio};

use crate::common::{epfilt_ok as ok, epfilt_run as epfilt, fireflies, read_json};
use crate::exr_io::{tmpdir, write_rgb};
use exr::prelude::*;

/// Exit status of a usage error.
const USAGE: i32 = 2;

fn err(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// A small super-sampled EXR (30x21 samples, S = 3 -> 10x7).
fn small_exr(dir: &Path, name: &str, seed: u64) -> std::path::PathBuf {
    let p = dir.join(name);
    write_rgb(
        &p,
        &fireflies(30, 21, 3, 0.02, seed),
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    p
}

/// A Radiance picture from `synth` (`size` output pixels, S = 3).
fn synth_hdr(dir: &Path, name: &str, size: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    ok(&["synth", "-q", "--size", size, "-o", s(&p)]);
    p
}

/// Run epfilt with `stdin` fed from `input` bytes.
fn epfilt_stdin(args: &[&str], input: &[u8]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_epfilt"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn epfilt");
    let mut stdin = child.stdin.take().expect("stdin");
    let bytes = input.to_vec();
    // A writer thread, so a large input cannot fill the pipe while epfilt
    // waits to write its own output.
    let feeder = std::thread::spawn(move || {
        let _ = stdin.write_all(&bytes);
    });
    let o = child.wait_with_output().expect("wait");
    feeder.join().expect("feeder");
    o
}

// 1. Formats by name, never by accident.

#[test]
fn an_output_extension_epfilt_cannot_write_is_refused_naming_what_it_accepts() {
    let dir = tmpdir();
    let d = dir.path();
    let hdr = synth_hdr(d, "x.hdr", "40x30");
    let exr = small_exr(d, "x.exr", 1);
    for name in ["y.png", "y.tif", "y.jpg", "y.tiff", "y"] {
        let out = d.join(name);
        let o = epfilt(&["filter", s(&hdr), s(&out), "-q"]);
        assert_eq!(o.status.code(), Some(USAGE), "{name}: {}", err(&o));
        let e = err(&o);
        assert!(
            e.contains(name) && e.contains(".exr") && e.contains(".hdr") && e.contains("--format"),
            "{name}: {e}"
        );
        assert!(!out.exists(), "{name} was written");
    }
    // synth writes EXR or Radiance pictures; preview writes PNG.
    let o = epfilt(&["synth", "-q", "--size", "8x8", "-o", s(&d.join("s.png"))]);
    assert_eq!(o.status.code(), Some(USAGE), "{}", err(&o));
    assert!(!d.join("s.png").exists());
    let o = epfilt(&["preview", s(&exr), s(&d.join("pv.exr"))]);
    assert_eq!(o.status.code(), Some(USAGE), "{}", err(&o));
    assert!(err(&o).contains(".png"), "{}", err(&o));
    assert!(!d.join("pv.exr").exists());
    // merge writes EXR.
    let o = epfilt(&["merge", s(&exr), s(&d.join("m.hdr"))]);
    assert_eq!(o.status.code(), Some(USAGE), "{}", err(&o));
    // --format names the format of a name without a known extension, and a
    // contradiction is refused.
    let out = d.join("plain");
    ok(&["filter", s(&exr), s(&out), "-q", "--format", "hdr"]);
    assert!(std::fs::read(&out).unwrap().starts_with(b"#?RADIANCE"));
    let o = epfilt(&["filter", s(&exr), s(&d.join("z.exr")), "--format", "hdr"]);
    assert_eq!(o.status.code(), Some(USAGE), "{}", err(&o));
}

#[test]
fn standard_output_follows_the_input_format_unless_told() {
    let dir = tmpdir();
    let d = dir.path();
    let hdr = synth_hdr(d, "x.hdr", "40x30");
    let o = epfilt(&["filter", s(&hdr), "-", "-q"]);
    assert!(o.status.success(), "{}", err(&o));
    assert!(
        o.stdout.starts_with(b"#?RADIANCE"),
        "not a Radiance picture"
    );
    let o = epfilt(&["filter", s(&hdr), "-", "-q", "--format", "exr"]);
    assert!(o.status.success(), "{}", err(&o));
    assert!(o.stdout.starts_with(&[0x76, 0x2f, 0x31, 0x01]), "not EXR");
}

// 2. Pipes both ways, as pfilt does.

#[test]
fn standard_input_is_read_for_filter_info_compare_and_preview() {
    let dir = tmpdir();
    let d = dir.path();
    let hdr = synth_hdr(d, "x.hdr", "40x30");
    let exr = small_exr(d, "x.exr", 2);
    for input in [&hdr, &exr] {
        let ext = input.extension().unwrap().to_str().unwrap();
        let bytes = std::fs::read(input).unwrap();
        // In and out through files, through pipes, and mixed: one set of bytes.
        let file_out = d.join(format!("file.{ext}"));
        ok(&["filter", s(input), s(&file_out), "-q"]);
        let want = std::fs::read(&file_out).unwrap();
        let piped_out = d.join(format!("piped.{ext}"));
        let o = epfilt_stdin(&["filter", "-", s(&piped_out), "-q"], &bytes);
        assert!(o.status.success(), "{ext}: {}", err(&o));
        assert!(std::fs::read(&piped_out).unwrap() == want, "{ext}: - in");
        let o = epfilt_stdin(&["filter", "-", "-", "-q"], &bytes);
        assert!(o.status.success(), "{ext}: {}", err(&o));
        assert!(o.stdout == want, "{ext}: - in and out");
        let o = epfilt(&["filter", s(input), "-", "-q"]);
        assert!(o.stdout == want, "{ext}: - out");

        let o = epfilt_stdin(&["info", "-"], &bytes);
        assert!(o.status.success(), "{ext}: {}", err(&o));
        let from_file = ok(&["info", s(input)]);
        let from_pipe = String::from_utf8_lossy(&o.stdout).to_string();
        assert_eq!(
            from_pipe.replace("-:", ""),
            from_file.replace(&format!("{}:", s(input)), ""),
            "{ext}: info"
        );
        let o = epfilt_stdin(&["compare", "-", s(input), "--json"], &bytes);
        assert!(o.status.success(), "{ext}: {}", err(&o));
        let cmp: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(cmp["identical"], true);
        let o = epfilt_stdin(&["preview", "-", "-"], &bytes);
        assert!(o.status.success(), "{ext}: {}", err(&o));
        assert!(o.stdout.starts_with(b"\x89PNG"));
    }
    // Not an image: one line naming standard input.
    let o = epfilt_stdin(&["info", "-"], b"hello");
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(err(&o).contains("standard input"), "{}", err(&o));
}

// 3. preview and compare open multi-part files.

#[test]
fn preview_and_compare_take_part_and_layer() {
    let dir = tmpdir();
    let d = dir.path();
    let multi = Path::new(crate::parts::MULTI);
    let all = d.join("all.exr");
    ok(&[
        "filter",
        s(multi),
        s(&all),
        "--part",
        "all",
        "-s",
        "1",
        "-q",
    ]);
    let png = d.join("p.png");
    ok(&["preview", s(&all), s(&png), "--part", "0"]);
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
    let out = ok(&["compare", s(&all), s(multi), "--part", "3", "--json"]);
    let cmp: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(cmp["rmse"].as_f64().is_some(), "{out}");
    let layered = Path::new("tests/data/exr/small/aovs_multilayer.exr");
    let out = ok(&["compare", s(layered), s(layered), "--layer", "diffuse"]);
    assert!(out.contains("identical         true"), "{out}");
}

#[test]
fn compare_statuses_are_idiffs_and_sizes_are_said_in_words() {
    // idiff's: 0 within every limit, 1 warn, 2 fail, 3 sizes differ, 4 a
    // file unreadable.
    let dir = tmpdir();
    let d = dir.path();
    let a = small_exr(d, "a.exr", 3);
    let b = small_exr(d, "b.exr", 4);
    let o = epfilt(&["compare", s(&a), s(&b), "--max-rmse", "1e9"]);
    assert_eq!(o.status.code(), Some(0), "{}", err(&o));
    let o = epfilt(&["compare", s(&a), s(&b), "--max-rmse", "1e-9"]);
    assert_eq!(o.status.code(), Some(2), "{}", err(&o));
    assert!(err(&o).contains("rmse"), "{}", err(&o));
    let o = epfilt(&["compare", s(&a), s(&a), "--max-rel-mse", "0"]);
    assert_eq!(o.status.code(), Some(0), "{}", err(&o));
    let o = epfilt(&["compare", s(&a), s(&b), "--max-energy-error", "1e-12"]);
    assert_eq!(o.status.code(), Some(2), "{}", err(&o));
    // A warning limit alone: 1; beyond a failing one too: 2.
    let o = epfilt(&["compare", s(&a), s(&b), "--warn-rmse", "1e-9"]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    let o = epfilt(&[
        "compare",
        s(&a),
        s(&b),
        "--warn-rmse",
        "1e-9",
        "--max-rmse",
        "1e-9",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", err(&o));
    // A file that is not there: 4, naming it.
    let gone = d.join("gone.exr");
    let o = epfilt(&["compare", s(&gone), s(&a)]);
    assert_eq!(o.status.code(), Some(4), "{}", err(&o));
    assert!(err(&o).contains("gone.exr"), "{}", err(&o));
    // Different sizes: in words, not tuples.
    let big = d.join("big.exr");
    write_rgb(
        &big,
        &fireflies(33, 21, 3, 0.02, 5),
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    let o = epfilt(&["compare", s(&a), s(&big)]);
    assert_eq!(o.status.code(), Some(3), "{}", err(&o));
    let e = err(&o);
    assert!(e.contains("30x21") && e.contains("33x21"), "{e}");
    assert!(!e.contains("(30, 21)") && !e.contains("[\""), "{e}");
}

// 4. merge refuses a band of another input.

#[test]
fn merge_refuses_a_band_cut_from_another_image_naming_it() {
    let dir = tmpdir();
    let d = dir.path();
    let a = small_exr(d, "a.exr", 10);
    let b = small_exr(d, "b.exr", 11);
    let band = |input: &Path, k: usize| {
        let out = d.join(format!(
            "{}-{k}.exr",
            input.file_stem().unwrap().to_str().unwrap()
        ));
        ok(&[
            "filter",
            s(input),
            s(&out),
            "-q",
            "--compression",
            "none",
            "--band",
            &format!("{k}/4"),
        ]);
        out
    };
    let odd = band(&b, 2);
    let parts = [band(&a, 1), odd.clone(), band(&a, 3), band(&a, 4)];
    let merged = d.join("m.exr");
    let mut args = vec!["merge", "-q"];
    args.extend(parts.iter().map(|p| s(p)));
    args.push(s(&merged));
    let o = epfilt(&args);
    assert!(!o.status.success(), "merged bands of two images");
    assert!(err(&o).contains(s(&odd)), "{}", err(&o));
    assert!(err(&o).contains("input"), "{}", err(&o));
    assert!(!merged.exists());
    // Other settings: refused too, naming the odd band.
    let other = d.join("t-2.exr");
    ok(&[
        "filter",
        s(&a),
        s(&other),
        "-q",
        "--compression",
        "none",
        "--band",
        "2/4",
        "--tolerance",
        "0.1",
    ]);
    let mut args = vec!["merge", "-q", s(&parts[0]), s(&other), s(&parts[2])];
    args.extend([s(&parts[3]), s(&merged)]);
    let o = epfilt(&args);
    assert!(!o.status.success());
    assert!(
        err(&o).contains(s(&other)) && err(&o).contains("settings"),
        "{}",
        err(&o)
    );
}

// 5. Nothing dropped without a word.

/// A single-part stereo file: the default view `left` (R, G, B) and `right`
/// (right.R, right.G, right.B), as OpenEXR's multi-view convention names them.
pub fn write_stereo(path: &Path, w: usize, h: usize) {
    let img = fireflies(w, h, 3, 0.02, 21);
    let mut list: Vec<AnyChannel<FlatSamples>> = Vec::new();
    for (prefix, scale) in [("", 1.0f32), ("right.", 0.5)] {
        for (c, n) in ["R", "G", "B"].iter().enumerate() {
            let v: Vec<f32> = (0..w * h)
                .map(|i| img.at(i % w, i / w, c) * scale)
                .collect();
            list.push(AnyChannel::new(
                Text::from(format!("{prefix}{n}").as_str()),
                FlatSamples::F32(v),
            ));
        }
    }
    let mut attrs = LayerAttributes::named("");
    attrs.multi_view_names = Some(vec![Text::from("left"), Text::from("right")]);
    Image::from_layer(Layer::new(
        (w, h),
        attrs,
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(list.into_iter().collect()),
    ))
    .write()
    .to_file(path)
    .expect("write stereo");
}

#[test]
fn a_dropped_view_is_a_warning_even_when_quiet_and_view_all_keeps_every_view() {
    let dir = tmpdir();
    let d = dir.path();
    let stereo = d.join("stereo.exr");
    write_stereo(&stereo, 30, 21);
    let out = d.join("out.exr");
    let o = epfilt(&["filter", s(&stereo), s(&out), "-q", "-s", "3"]);
    assert!(o.status.success(), "{}", err(&o));
    let e = err(&o);
    assert!(e.contains("warning") && e.contains("right"), "{e}");
    // --view right filters that view; --view all every view, each its own.
    let right = d.join("right.exr");
    ok(&[
        "filter",
        s(&stereo),
        s(&right),
        "-q",
        "-s",
        "3",
        "--view",
        "right",
    ]);
    let all = d.join("all.exr");
    let rep = d.join("all.json");
    ok(&[
        "filter",
        s(&stereo),
        s(&all),
        "-s",
        "3",
        "--view",
        "all",
        "--report",
        s(&rep),
    ]);
    let names = |p: &Path| -> Vec<String> {
        let m = exr::meta::MetaData::read_from_file(p, false).unwrap();
        m.headers[0]
            .channels
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect()
    };
    assert_eq!(
        names(&all),
        ["B", "G", "R", "right.B", "right.G", "right.R"]
    );
    let r = read_json(&rep);
    for e in r["energy_rel_error"].as_array().unwrap() {
        assert!(e.as_f64().unwrap() <= crate::common::ENERGY_TOL, "{r}");
    }
    // Each view of the `all` file is what filtering that view alone gives.
    let alone = crate::exr_io::read_planar(&out);
    let both = exr::prelude::read_all_flat_layers_from_file(&all).unwrap();
    let ch = |n: &str| {
        both.layer_data[0]
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == n)
            .unwrap()
            .sample_data
            .clone()
    };
    let FlatSamples::F32(r0) = ch("R") else {
        panic!()
    };
    assert!(
        r0.iter()
            .enumerate()
            .all(|(i, v)| v.to_bits() == alone.at(i % 10, i / 10, 0).to_bits()),
        "the default view of --view all differs from filtering it alone"
    );
    let right_alone = exr::prelude::read_all_flat_layers_from_file(&right).unwrap();
    let FlatSamples::F32(rr) = &right_alone.layer_data[0]
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "right.R")
        .unwrap()
        .sample_data
    else {
        panic!()
    };
    let FlatSamples::F32(ra) = ch("right.R") else {
        panic!()
    };
    assert!(ra.iter().zip(rr).all(|(a, b)| a.to_bits() == b.to_bits()));
}

// 6. --skip-existing takes only finished work as done.

fn sequence(dir: &Path, frames: std::ops::RangeInclusive<i64>) {
    for f in frames {
        write_rgb(
            &dir.join(format!("beauty.{f:04}.exr")),
            &fireflies(24, 18, 3, 0.02, 100 + f as u64),
            Compression::ZIP16,
            Blocks::ScanLines,
            false,
            LineOrder::Increasing,
        );
    }
}

#[test]
fn skip_existing_redoes_empty_partial_foreign_and_band_files_saying_why() {
    let dir = tmpdir();
    let d = dir.path();
    let input = d.join("in");
    let out = d.join("out");
    std::fs::create_dir_all(&input).unwrap();
    std::fs::create_dir_all(&out).unwrap();
    sequence(&input, 1..=4);
    let ip = format!("{}/beauty.####.exr", input.display());
    let op = format!("{}/beauty.####.exr", out.display());
    // A band of a sequence never takes a frame's name.
    let o = epfilt(&[
        "filter",
        &ip,
        &op,
        "-q",
        "--band",
        "1/2",
        "--compression",
        "none",
    ]);
    assert!(
        o.status.success() || o.status.code() == Some(USAGE),
        "{}",
        err(&o)
    );
    for f in 1..=4 {
        assert!(
            !out.join(format!("beauty.{f:04}.exr")).exists(),
            "frame {f}"
        );
    }
    // Frame 1: empty; 2: another input's output; 3: other settings;
    // 4: this run's own output (skipped).
    std::fs::write(out.join("beauty.0001.exr"), b"").unwrap();
    ok(&[
        "filter",
        s(&input.join("beauty.0003.exr")),
        s(&out.join("beauty.0002.exr")),
        "-q",
    ]);
    ok(&[
        "filter",
        s(&input.join("beauty.0003.exr")),
        s(&out.join("beauty.0003.exr")),
        "-q",
        "--tolerance",
        "0.1",
    ]);
    ok(&[
        "filter",
        s(&input.join("beauty.0004.exr")),
        s(&out.join("beauty.0004.exr")),
        "-q",
    ]);
    let rep = d.join("r.json");
    let o = epfilt(&["filter", &ip, &op, "--skip-existing", "--report", s(&rep)]);
    assert!(o.status.success(), "{}", err(&o));
    let r = read_json(&rep);
    let status: Vec<&str> = r["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["status"].as_str().unwrap())
        .collect();
    assert_eq!(status, ["done", "done", "done", "skipped"], "{r}");
    let e = err(&o);
    assert!(e.contains("redone") || e.contains("redo"), "{e}");
    // A single file: an empty output is not done either.
    let single = d.join("single.exr");
    std::fs::write(&single, b"").unwrap();
    ok(&[
        "filter",
        s(&input.join("beauty.0001.exr")),
        s(&single),
        "-q",
        "--skip-existing",
    ]);
    assert!(std::fs::metadata(&single).unwrap().len() > 0);
}

// 7. A closed pipe ends quietly.

#[test]
fn a_reader_that_closes_the_pipe_ends_the_run_quietly_with_status_0() {
    let dir = tmpdir();
    let d = dir.path();
    let hdr = synth_hdr(d, "x.hdr", "400x400");
    for args in [
        format!("filter {} - -q", s(&hdr)),
        format!("filter {} - -q --format exr", s(&hdr)),
        format!("filter {} {} -q --report -", s(&hdr), s(&d.join("o.exr"))),
        format!("preview {} -", s(&hdr)),
    ] {
        let o = Command::new("bash")
            .arg("-c")
            .arg(format!(
                "\"$0\" {args} | head -c 10 > /dev/null; echo \"${{PIPESTATUS[0]}}\""
            ))
            .arg(env!("CARGO_BIN_EXE_epfilt"))
            .output()
            .expect("bash");
        let status = String::from_utf8_lossy(&o.stdout).trim().to_string();
        assert_eq!(status, "0", "{args}: {}", err(&o));
        assert!(o.stderr.is_empty(), "{args}: {}", err(&o));
    }
}
