//! The `epfilt` command as a user meets it.

use std::path::Path;
use std::process::{Command, Output};

use crate::common::*;
use crate::exr_io::{tmpdir, write_rgb};
use exr::prelude::*;

use crate::common::epfilt_run as epfilt;

fn input(dir: &Path) -> String {
    let p = dir.join("in.exr");
    write_rgb(
        &p,
        &fireflies(30, 21, 3, 0.02, 1),
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    p.to_string_lossy().into()
}

/// Exit status of a failed run (a bad or damaged input, an I/O error).
const FAILURE: i32 = 1;
/// Exit status of a usage error (arguments, output paths epfilt refuses).
const USAGE: i32 = 2;

fn one_line_error(out: &Output, code: i32, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{err}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(err.starts_with("epfilt: ") && err.contains(needle), "{err}");
}

#[test]
fn filter_writes_output_and_json_report() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let out = dir.path().join("out.exr");
    let rep = dir.path().join("r.json");
    let o = epfilt(&[
        "filter",
        &inp,
        out.to_str().unwrap(),
        "-s",
        "3",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("energy ledger"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    for key in [
        "input",
        "output",
        "method",
        "supersample",
        "width",
        "height",
        "out_width",
        "out_height",
        "seconds",
        "megapixels_per_second",
        "samples_spread",
        "samples_capped",
        "energy_in",
        "energy_out",
        "energy_rel_error",
        "peak_rss_bytes",
    ] {
        assert!(json.get(key).is_some(), "report lacks {key}");
    }
    assert_eq!(json["out_width"], 10);
    assert_eq!(json["method"], "ep-gauss");
    assert!(json["energy_rel_error"]
        .as_array()
        .unwrap()
        .iter()
        .all(|e| e.as_f64().unwrap() <= ENERGY_TOL));
    let o = epfilt(&["filter", &inp, out.to_str().unwrap(), "-s", "3", "-q"]);
    assert!(o.status.success() && o.stderr.is_empty());
}

#[test]
fn errors_are_one_line_naming_the_file() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let missing = dir.path().join("nope.exr");
    one_line_error(
        &epfilt(&["filter", missing.to_str().unwrap(), "o.exr"]),
        FAILURE,
        "nope.exr",
    );
    // A missing output folder: one usage error, as for a sequence.
    let nodir = dir.path().join("no/such/dir/out.exr");
    one_line_error(
        &epfilt(&["filter", &inp, nodir.to_str().unwrap()]),
        USAGE,
        "no/such/dir: the output folder does not exist",
    );
    one_line_error(
        &epfilt(&["filter", &inp, "x.exr", "-s", "9"]),
        USAGE,
        "--supersample",
    );
    one_line_error(
        &epfilt(&["filter", &inp, "x.exr", "--method", "sharpen"]),
        USAGE,
        "unknown method",
    );
    let text = dir.path().join("text.exr");
    std::fs::write(&text, "this is not an image").unwrap();
    one_line_error(
        &epfilt(&["filter", text.to_str().unwrap(), "x.exr"]),
        FAILURE,
        "text.exr",
    );
}

#[test]
fn output_equal_to_input_is_refused_and_input_untouched() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let before = std::fs::read(&inp).unwrap();
    one_line_error(&epfilt(&["filter", &inp, &inp]), USAGE, "is the input file");
    let link = dir.path().join("link.exr");
    std::os::unix::fs::symlink(&inp, &link).unwrap();
    one_line_error(
        &epfilt(&["filter", &inp, link.to_str().unwrap()]),
        USAGE,
        "is the input file",
    );
    let hard = dir.path().join("hard.exr");
    std::fs::hard_link(&inp, &hard).unwrap();
    one_line_error(
        &epfilt(&["filter", &inp, hard.to_str().unwrap()]),
        USAGE,
        "is the input file",
    );
    assert_eq!(std::fs::read(&inp).unwrap(), before);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(names.len(), 3, "stray files: {names:?}");
}

#[test]
fn info_describes_a_file() {
    let f = crate::corpus::data_dir().join("MultiResolution/ColorCodedLevels.exr");
    let o = epfilt(&["info", f.to_str().unwrap()]);
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(
        s.contains("512x512")
            && s.contains("pxr24")
            && s.contains("tiles 64x64")
            && s.contains("R half")
            && s.contains("filtered: R, G, B, A"),
        "{s}"
    );
}

#[test]
fn output_files_are_byte_identical_for_any_tile_strip_and_threads() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let mut first: Option<(Vec<u8>, serde_json::Value)> = None;
    for (k, cut) in [["256", "0", "1"], ["3", "1", "2"], ["7", "5", "4"]]
        .iter()
        .enumerate()
    {
        let out = dir.path().join(format!("o{k}.exr"));
        let rep = dir.path().join(format!("r{k}.json"));
        let o = epfilt(&[
            "filter",
            &inp,
            out.to_str().unwrap(),
            "-s",
            "3",
            "-q",
            "--tile",
            cut[0],
            "--strip-rows",
            cut[1],
            "--threads",
            cut[2],
            "--report",
            rep.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let bytes = std::fs::read(&out).unwrap();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
        match &first {
            None => first = Some((bytes, json)),
            Some((b, j)) => {
                assert!(bytes == *b, "output file differs for {cut:?}");
                assert_eq!(json["digest"], j["digest"]);
                assert_eq!(json["energy_out"], j["energy_out"]);
            }
        }
    }
}

#[test]
fn a_full_disk_is_one_clear_error_and_leaves_no_file() {
    // A file-size limit (ulimit -f, in 512- or 1024-byte blocks depending on the
    // shell) stands in for a full disk: the 50x40 float output is ~24 KB.
    let dir = tmpdir();
    let inp = dir.path().join("in.exr");
    write_rgb(
        &inp,
        &fireflies(150, 120, 3, 0.01, 2),
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    let out = dir.path().join("out.exr");
    let o = Command::new("sh")
        .args(["-c", "ulimit -f 8; exec \"$0\" \"$@\""])
        .arg(env!("CARGO_BIN_EXE_epfilt"))
        .args([
            "filter",
            inp.to_str().unwrap(),
            out.to_str().unwrap(),
            "--compression",
            "none",
            "-q",
        ])
        .output()
        .expect("sh");
    one_line_error(&o, FAILURE, "out.exr");
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("too large"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(
        names,
        vec![std::ffi::OsString::from("in.exr")],
        "left behind: {names:?}"
    );
}

/// A directory the process may not write into: a 0555 folder, or, where
/// permissions are not enforced (root), `/sys` or `/proc`, which refuse file
/// creation to root too. `None` if none is.
fn read_only_dir(dir: &Path) -> Option<std::path::PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let ro = dir.join("ro");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    if std::fs::write(ro.join("probe"), b"x").is_err() {
        return Some(ro);
    }
    ["/sys", "/proc"]
        .iter()
        .map(Path::new)
        .find(|d| d.is_dir() && std::fs::write(d.join("epfilt-probe"), b"x").is_err())
        .map(Path::to_path_buf)
}

#[test]
fn read_only_destination_is_one_line_and_leaves_nothing() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let before = std::fs::read(&inp).unwrap();
    let ro = read_only_dir(dir.path())
        .expect("a read-only folder: a 0555 one, or /sys or /proc where the user is root");
    let out = ro.join("out.exr");
    let o = epfilt(&["filter", &inp, out.to_str().unwrap(), "-q"]);
    one_line_error(&o, FAILURE, &ro.display().to_string());
    assert!(!out.exists());
    let leftovers: Vec<_> = std::fs::read_dir(&ro)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("epfilt"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    assert_eq!(std::fs::read(&inp).unwrap(), before);
}

#[test]
fn sigterm_and_sigint_mid_run_exit_143_and_130_leave_no_output_and_the_input_untouched() {
    let dir = tmpdir();
    let inp = dir.path().join("big.exr");
    // 4608x4608 samples: long enough (about a second) to be signalled mid-run.
    let o = epfilt(&[
        "synth",
        "-q",
        "--size",
        "1536x1536",
        "-o",
        inp.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let before = std::fs::read(&inp).unwrap();
    let outdir = dir.path().join("out");
    std::fs::create_dir(&outdir).unwrap();
    let out = outdir.join("filtered.exr");
    let mut interrupted = 0;
    for sig in [libc::SIGTERM, libc::SIGINT] {
        let child = Command::new(env!("CARGO_BIN_EXE_epfilt"))
            .args(["filter", inp.to_str().unwrap(), out.to_str().unwrap(), "-q"])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("spawn epfilt");
        // Wait until the temporary output exists: the run is under way.
        let t0 = std::time::Instant::now();
        while std::fs::read_dir(&outdir).unwrap().next().is_none() {
            assert!(t0.elapsed().as_secs() < 30, "no temporary file appeared");
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        // SAFETY: kill(2) on our own child's pid; no memory is involved.
        let rc = unsafe { libc::kill(child.id() as libc::pid_t, sig) };
        assert_eq!(rc, 0);
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        if o.status.success() {
            // The run finished before the signal was handled: then the
            // output is complete; remove it and try nothing more.
            eprintln!("signal {sig} arrived after the run finished");
            std::fs::remove_file(&out).unwrap();
            continue;
        }
        assert_eq!(o.status.code(), Some(128 + sig), "signal {sig}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
        assert!(err.contains("interrupted"), "{err}");
        let left: Vec<_> = std::fs::read_dir(&outdir).unwrap().flatten().collect();
        assert!(left.is_empty(), "signal {sig} left {left:?}");
        interrupted += 1;
    }
    assert!(
        interrupted > 0,
        "no run was interrupted: the input is too small"
    );
    assert!(std::fs::read(&inp).unwrap() == before, "input changed");
}

/// Every command that writes a file, each with `out` as that file.
fn writers(inp: &str, dir: &Path, out: &str) -> Vec<Vec<String>> {
    let other = dir.join("other.exr").to_string_lossy().into_owned();
    let v = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    vec![
        v(&["filter", inp, out, "-q"]),
        v(&["filter", inp, &other, "-q", "--report", out]),
        v(&["preview", inp, out]),
        v(&["synth", "-q", "--size", "8x8", "-o", out]),
        v(&["synth", "-q", "--size", "8x8", "-o", &other, "--truth", out]),
    ]
}

#[test]
fn outputs_that_are_not_regular_files_are_refused_and_left_as_they_are() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let fifo = dir.path().join("fifo");
    let made = Command::new("mkfifo").arg(&fifo).status();
    let mut targets = vec![
        (dir.path().to_path_buf(), "is a directory"),
        ("/dev/zero".into(), "is a character device"),
    ];
    if made.is_ok_and(|s| s.success()) {
        targets.push((fifo.clone(), "is a FIFO"));
    }
    for (target, why) in &targets {
        let t = target.to_str().unwrap();
        for args in writers(&inp, dir.path(), t) {
            let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
            let o = epfilt(&args);
            one_line_error(&o, USAGE, why);
            assert!(String::from_utf8_lossy(&o.stderr).contains(t), "{args:?}");
        }
    }
    use std::os::unix::fs::FileTypeExt;
    if fifo.exists() {
        assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    }
    assert!(std::fs::metadata("/dev/zero")
        .unwrap()
        .file_type()
        .is_char_device());
    let stray: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(".epfilt"))
        .collect();
    assert!(stray.is_empty(), "{stray:?}");
}

#[test]
fn a_link_output_is_written_through_and_stays_a_link() {
    let dir = tmpdir();
    let inp = input(dir.path());
    for (k, args_of) in [0usize, 1, 2, 3].iter().enumerate() {
        // A link to an existing file, and a dangling one (its target is made).
        for existing in [true, false] {
            let real = dir.path().join(format!("real{k}{existing}"));
            if existing {
                std::fs::write(&real, b"old").unwrap();
            }
            let ext = ["exr", "json", "png", "exr"][k];
            let link = dir.path().join(format!("link{k}{existing}.{ext}"));
            std::os::unix::fs::symlink(&real, &link).unwrap();
            let args = &writers(&inp, dir.path(), link.to_str().unwrap())[*args_of];
            let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
            let o = epfilt(&args);
            assert!(
                o.status.success(),
                "{args:?}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            let meta = std::fs::symlink_metadata(&link).unwrap();
            assert!(
                meta.file_type().is_symlink(),
                "{args:?}: the link was replaced"
            );
            let bytes = std::fs::read(&real).unwrap();
            assert!(
                bytes.len() > 3 && bytes != b"old",
                "{args:?}: target not written"
            );
        }
    }
}

#[test]
fn dash_is_standard_output_for_images_reports_and_previews() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let file = dir.path().join("file.exr");
    let o = epfilt(&["filter", &inp, file.to_str().unwrap(), "-q"]);
    assert!(o.status.success());
    let o = epfilt(&["filter", &inp, "-", "-q"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        o.stdout == std::fs::read(&file).unwrap(),
        "stdout differs from the file"
    );
    let o = epfilt(&[
        "filter",
        &inp,
        file.to_str().unwrap(),
        "-q",
        "--report",
        "-",
    ]);
    assert!(o.status.success());
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(json["method"], "ep-gauss");
    let o = epfilt(&["preview", &inp, "-"]);
    assert!(o.status.success());
    assert!(o.stdout.starts_with(b"\x89PNG"));
    one_line_error(
        &epfilt(&["filter", &inp, "-", "--report", "-"]),
        USAGE,
        "cannot both be standard output",
    );
    let stray: Vec<_> = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(".epfilt-"))
        .filter(|e| {
            e.metadata().is_ok_and(|m| {
                m.modified()
                    .is_ok_and(|t| t.elapsed().is_ok_and(|d| d.as_secs() < 60))
            })
        })
        .collect();
    assert!(stray.is_empty(), "temporary files left: {stray:?}");
}

#[test]
fn help_states_the_exit_statuses_and_usage_errors_exit_2() {
    let o = epfilt(&["--help"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("Exit status") && text.contains("130"),
        "{text}"
    );
    let o = epfilt(&["filter", "a.exr"]);
    assert_eq!(o.status.code(), Some(USAGE));
    let o = epfilt(&["filter", "a.exr", "b.exr", "--tolerance=-1"]);
    one_line_error(&o, USAGE, "--tolerance");
}

/// Per channel (by name): the sum of what an EXR file decodes to.
fn decoded_sums(path: &Path) -> Vec<(String, f64)> {
    let image = read_first_flat_layer_from_file(path).expect("decode");
    image
        .layer_data
        .channel_data
        .list
        .iter()
        .map(|c| {
            let sum = match &c.sample_data {
                FlatSamples::F16(v) => v.iter().map(|x| x.to_f64()).sum(),
                FlatSamples::F32(v) => v.iter().map(|&x| x as f64).sum(),
                FlatSamples::U32(v) => v.iter().map(|&x| x as f64).sum(),
            };
            (c.name.to_string(), sum)
        })
        .collect()
}

#[test]
fn lossy_output_codecs_are_refused_unless_allowed_and_then_measured_on_disk() {
    // Which codecs change which samples (OpenEXR's behaviour, checked with
    // its Python bindings): DWA both, B44 half only, PXR24 float only.
    let dir = tmpdir();
    let inp = input(dir.path());
    let out = dir.path().join("out.exr");
    let out_s = out.to_str().unwrap();
    let run_codec = |codec: &str, ty: &str, more: &[&str]| {
        let mut args = vec!["filter", &inp, out_s, "-s", "3", "-q"];
        args.extend(["--compression", codec, "--pixel-type", ty]);
        args.extend(more);
        epfilt(&args)
    };
    for (codec, ty) in [
        ("dwaa", "f32"),
        ("dwab", "f16"),
        ("pxr24", "f32"),
        ("b44", "f16"),
        ("b44a", "f16"),
    ] {
        let o = run_codec(codec, ty, &[]);
        one_line_error(&o, USAGE, "lossy");
        assert!(String::from_utf8_lossy(&o.stderr).contains(out_s));
        assert!(!out.exists(), "{codec} {ty}: an output was left");
    }
    // Lossless for these samples: written, no warning.
    for (codec, ty) in [("b44", "f32"), ("pxr24", "f16"), ("piz", "f32")] {
        let o = run_codec(codec, ty, &[]);
        assert!(
            o.status.success(),
            "{codec} {ty}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(
            o.stderr.is_empty(),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    // Allowed: the report's energy after rounding is the decoded file's.
    // The two sums (compensated, and plain in file order) of ~600 values agree
    // far within this bound.
    const SUM_ORDER_TOL: f64 = 1e-12;
    let rep = dir.path().join("r.json");
    for (codec, ty) in [("dwaa", "f32"), ("pxr24", "f32"), ("b44", "f16")] {
        let o = run_codec(
            codec,
            ty,
            &["--allow-lossy", "--report", rep.to_str().unwrap()],
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
        assert_eq!(r["compression"], codec);
        assert_eq!(r["energy_on_disk_decoded"], true);
        let on_disk = decoded_sums(&out);
        let mut moved = false;
        for (k, name) in r["channels"].as_array().unwrap().iter().enumerate() {
            let name = name.as_str().unwrap();
            let (_, sum) = on_disk
                .iter()
                .find(|(n, _)| n == name)
                .expect("channel on disk");
            let reported = r["energy_out_rounded"][k].as_f64().unwrap() / 9.0;
            assert!(
                (reported - sum).abs() <= SUM_ORDER_TOL * sum.abs(),
                "{codec} {name}: report {reported} vs file {sum}"
            );
            let before = r["energy_out"][k].as_f64().unwrap() / 9.0;
            moved |= (before - sum).abs() > 1e-9 * sum.abs();
        }
        assert!(moved, "{codec} {ty}: the codec changed nothing measurable");
    }
}

#[test]
fn a_lossy_input_codec_is_not_inherited_silently() {
    let dir = tmpdir();
    let out = dir.path().join("out.exr");
    let rep = dir.path().join("r.json");
    // f32 output rounds each value within 2^-24 of itself, so the sum too.
    const ROUNDING_TOL: f64 = 6e-8;
    let inp = crate::corpus::data_dir().join("small/dwaa_half_rgba.exr");
    let o = epfilt(&[
        "filter",
        inp.to_str().unwrap(),
        out.to_str().unwrap(),
        "-q",
        "--pixel-type",
        "f32",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("warning") && err.contains("dwaa") && err.contains("zip"),
        "{err}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
    assert_eq!(r["compression"], "zip");
    assert_eq!(r["warnings"].as_array().unwrap().len(), 1);
    for e in r["energy_rel_error_rounded"].as_array().unwrap() {
        assert!(e.as_f64().unwrap() <= ROUNDING_TOL, "{e}");
    }
}

#[test]
fn the_output_and_the_report_say_how_they_were_made() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let out = dir.path().join("out.exr");
    let rep = dir.path().join("r.json");
    for (method, key) in [("ep-gauss", "tolerance=0.2"), ("median", "alpha=")] {
        let o = epfilt(&[
            "filter",
            &inp,
            out.to_str().unwrap(),
            "-s",
            "3",
            "--method",
            method,
            "--tolerance",
            "0.2",
            "-q",
            "--report",
            rep.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let meta = exr::meta::MetaData::read_from_file(&out, false).expect("header");
        let own = &meta.headers[0].own_attributes;
        let software = text_attribute(own, "epfiltSettings").expect("epfiltSettings");
        let text = software
            .strip_prefix(&format!("epfilt {} (", env!("CARGO_PKG_VERSION")))
            .and_then(|t| t.strip_suffix(')'))
            .unwrap_or_else(|| panic!("settings: {software}"));
        assert!(
            text.starts_with(&format!("method={method} supersample=3 ")),
            "{text}"
        );
        assert!(
            text.contains(key) && text.contains("pixel_type=f32"),
            "{text}"
        );
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&rep).unwrap()).unwrap();
        assert_eq!(r["version"], env!("CARGO_PKG_VERSION"));
        assert_eq!(r["settings"]["method"], method);
        assert_eq!(r["settings"]["supersample"], 3);
    }
}

#[test]
fn a_size_not_a_multiple_of_s_is_refused_with_the_options_or_cropped() {
    let dir = tmpdir();
    let d = dir.path();
    let full = fireflies(32, 23, 3, 0.03, 7);
    let full_path = d.join("full.exr");
    let opts = (
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    write_rgb(&full_path, &full, opts.0, opts.1, opts.2, opts.3);
    let full_arg = full_path.to_str().unwrap();
    let out = d.join("out.exr");
    let out_arg = out.to_str().unwrap();

    // Without --supersample (nor the attribute) the image is at pixel
    // resolution: any size fits.
    let o = epfilt(&["filter", full_arg, out_arg]);
    assert!(o.status.success(), "{o:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("32x23 -> 32x23"), "{err}");
    std::fs::remove_file(&out).unwrap();
    let o = epfilt(&["filter", full_arg, out_arg, "-s", "4"]);
    one_line_error(&o, USAGE, "--edge crop");
    assert!(!out.exists());

    for (s, method) in [(3, "ep-gauss"), (3, "gauss"), (3, "box"), (4, "ep-gauss")] {
        let (cw, ch) = (32 - 32 % s, 23 - 23 % s);
        let cut = Img::new(cw, ch, 3, |x, y, c| full.at(x, y, c));
        let cut_path = d.join(format!("cut{s}.exr"));
        write_rgb(&cut_path, &cut, opts.0, opts.1, opts.2, opts.3);
        let expected = d.join("expected.exr");
        let s_arg = s.to_string();
        let o = epfilt(&[
            "filter",
            cut_path.to_str().unwrap(),
            expected.to_str().unwrap(),
            "-s",
            &s_arg,
            "--method",
            method,
            "-q",
        ]);
        assert!(o.status.success(), "{o:?}");
        let rep = d.join("r.json");
        filter_at_edge(&full_path, &out, &rep, s, method, "crop", "cropped");
        assert!(
            crate::common::image_bytes(&out) == crate::common::image_bytes(&expected),
            "{method} S={s}: cropping differs from filtering the cropped image"
        );
        let json = read_json(&rep);
        assert_eq!(json["out_width"], cw / s);
        assert_eq!(json["out_height"], ch / s);
        assert!(json["warnings"][0].as_str().unwrap().contains("cropped"));
    }
    let o = epfilt(&["filter", full_arg, out_arg, "--edge", "nope"]);
    one_line_error(&o, USAGE, "crop or pad");
}

/// `filter` with `--edge`, a report, and the warning that names `word`.
fn filter_at_edge(
    input: &Path,
    out: &Path,
    rep: &Path,
    s: usize,
    method: &str,
    edge: &str,
    word: &str,
) {
    let s_arg = s.to_string();
    let o = epfilt(&[
        "filter",
        input.to_str().unwrap(),
        out.to_str().unwrap(),
        "-s",
        &s_arg,
        "--method",
        method,
        "--edge",
        edge,
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{method} S={s}: {o:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("epfilt: warning: ") && err.contains(word),
        "{err}"
    );
}

#[test]
fn a_padded_edge_keeps_flat_fields_flat_and_energy_exact() {
    // Pixels of fewer samples: each kernel normalised over what exists.
    const FLAT_TOL: f32 = 1e-6; // f32 rounding of a divided sum near 1
    let dir = tmpdir();
    let d = dir.path();
    let opts = (
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    let (w, h) = (32, 23);
    let flat = Img::new(w, h, 3, |_, _, c| [0.5, 1.0, 2.0][c]);
    let flat_path = d.join("flat.exr");
    write_rgb(&flat_path, &flat, opts.0, opts.1, opts.2, opts.3);
    let noisy = fireflies(w, h, 3, 0.05, 11);
    let noisy_path = d.join("noisy.exr");
    write_rgb(&noisy_path, &noisy, opts.0, opts.1, opts.2, opts.3);
    let out = d.join("out.exr");
    let rep = d.join("r.json");
    for (s, method) in [
        (3, "ep-gauss"),
        (3, "gauss"),
        (3, "box"),
        (4, "ep-gauss"),
        (2, "clamp"),
    ] {
        let run = |input: &Path| {
            filter_at_edge(input, &out, &rep, s, method, "pad", "padded");
            (crate::exr_io::read_planar(&out), read_json(&rep))
        };
        let (img, json) = run(&flat_path);
        assert_eq!(
            (img.w, img.h),
            (w.div_ceil(s), h.div_ceil(s)),
            "{method} S={s}"
        );
        assert_eq!(
            (json["width"].as_u64(), json["height"].as_u64()),
            (Some(32), Some(23))
        );
        for y in 0..img.h {
            for x in 0..img.w {
                for c in 0..3 {
                    let want = [0.5, 1.0, 2.0][c];
                    assert!(
                        (img.at(x, y, c) - want).abs() <= FLAT_TOL * want,
                        "{method} S={s} ({x}, {y}) {c}: {}",
                        img.at(x, y, c)
                    );
                }
            }
        }
        let (_, json) = run(&noisy_path);
        let sum = |c: usize| -> f64 {
            (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .map(|(x, y)| noisy.at(x, y, c) as f64)
                .sum()
        };
        for c in 0..3 {
            if method != "clamp" {
                let e = json["energy_rel_error"][c].as_f64().unwrap();
                assert!(e <= ENERGY_TOL, "{method} S={s}: {e:e}");
            }
            // The ledger's input is every sample; padded ones added nothing.
            let e_in = json["energy_in"][c].as_f64().unwrap();
            assert!(
                (e_in - sum(c)).abs() <= ENERGY_TOL * sum(c),
                "{e_in} vs {}",
                sum(c)
            );
        }
        if method == "box" {
            // On disk: a partial box pixel is the mean of its k of S^2
            // samples and stands for k / S^2 of a pixel.
            let img = crate::exr_io::read_planar(&out);
            for c in 0..3 {
                let mut on_disk = 0.0;
                for y in 0..img.h {
                    for x in 0..img.w {
                        let k = (w - x * s).min(s) * (h - y * s).min(s);
                        on_disk += img.at(x, y, c) as f64 * k as f64;
                    }
                }
                // f32 rounding of each stored mean: well under 1e-6.
                assert!(
                    (on_disk - sum(c)).abs() <= 1e-6 * sum(c),
                    "box on disk {on_disk} vs {}",
                    sum(c)
                );
            }
        }
    }
    let o = epfilt(&[
        "filter",
        noisy_path.to_str().unwrap(),
        out.to_str().unwrap(),
        "-s",
        "3",
        "--method",
        "median",
        "--edge",
        "pad",
    ]);
    one_line_error(&o, USAGE, "--edge crop");
}

#[test]
fn completions_and_a_man_page_come_from_the_command_line_definition() {
    for shell in ["bash", "zsh", "fish"] {
        let text = epfilt_ok(&["completions", shell]);
        assert!(
            text.len() > 1000 && text.contains("filter") && text.contains("skip-existing"),
            "{shell}: {} bytes",
            text.len()
        );
    }
    // Options with a fixed set of values complete to them, not to files.
    let bash = epfilt_ok(&["completions", "bash"]);
    for values in [
        "ep-gauss ep-box gauss box",
        "fast default best",
        "crop pad",
        "error zero",
    ] {
        assert!(bash.contains(values), "bash completions lack {values:?}");
    }
    let man = epfilt_ok(&["man"]);
    assert!(man.starts_with(".ie") || man.contains(".TH"), "{man:.200}");
    assert!(
        man.contains("epfilt") && man.contains("filter"),
        "{man:.200}"
    );
    let o = epfilt(&["completions", "tcsh"]);
    assert_eq!(o.status.code(), Some(USAGE));
}

#[test]
fn man_dir_writes_a_page_for_every_command() {
    let dir = tmpdir();
    let pages = dir.path().join("man1");
    let o = epfilt(&["man", "--dir", pages.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for command in [
        "", "-filter", "-restore", "-info", "-compare", "-merge", "-preview",
    ] {
        let page = std::fs::read_to_string(pages.join(format!("epfilt{command}.1"))).unwrap();
        assert!(page.contains(".TH"), "epfilt{command}.1: {page:.200}");
    }
    let filter = std::fs::read_to_string(pages.join("epfilt-filter.1")).unwrap();
    assert!(filter.contains("max\\-memory"), "{filter:.400}");
    // A directory that cannot be made: one line naming it.
    let blocked = dir.path().join("file");
    std::fs::write(&blocked, b"x").unwrap();
    let o = epfilt(&["man", "--dir", blocked.join("sub").to_str().unwrap()]);
    one_line_error(&o, 1, "sub");
}

#[test]
fn filter_help_is_grouped_under_headings_with_examples() {
    let text = epfilt_ok(&["filter", "--help"]);
    for heading in [
        "Input:",
        "Method:",
        "ep-gauss:",
        "ep-box:",
        "Channels:",
        "Output:",
        "Farm:",
        "Performance:",
        "Examples:",
    ] {
        assert!(text.contains(heading), "no {heading}: {text}");
    }
    assert!(text.contains("EPFILT_THREADS") && text.contains("EPFILT_MAX_MEMORY"));
}

#[test]
fn an_option_the_method_ignores_and_too_many_threads_are_warnings() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let out = dir.path().join("o.exr");
    let o = epfilt(&[
        "filter",
        &inp,
        out.to_str().unwrap(),
        "-q",
        "--method",
        "box",
        "--tolerance",
        "0.2",
        "--d",
        "3",
        "--threads",
        "100000",
    ]);
    assert!(o.status.success(), "{o:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("warning: --tolerance has no effect with --method box"),
        "{err}"
    );
    assert!(err.contains("--d has no effect"), "{err}");
    assert!(err.contains("--threads 100000 is more than"), "{err}");
    // The method's own options are silent; so are the environment's
    // defaults when they fit.
    let o = Command::new(env!("CARGO_BIN_EXE_epfilt"))
        .args([
            "filter",
            &inp,
            out.to_str().unwrap(),
            "-q",
            "--tolerance",
            "0.2",
        ])
        .env("EPFILT_THREADS", "1")
        .output()
        .unwrap();
    assert!(o.status.success() && o.stderr.is_empty(), "{o:?}");
}

#[test]
fn oversubscribe_runs_more_threads_than_cores_without_the_warning() {
    // More than any machine this runs on has: the run uses them all (to
    // measure memory at a core count the machine lacks).
    const THREADS: usize = 24;
    let dir = tmpdir();
    let inp = input(dir.path());
    let out = dir.path().join("o.exr");
    let rep = dir.path().join("r.json");
    let threads = THREADS.to_string();
    let o = epfilt(&[
        "filter",
        &inp,
        out.to_str().unwrap(),
        "-q",
        "--threads",
        &threads,
        "--oversubscribe",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{o:?}");
    assert!(o.stderr.is_empty(), "{o:?}");
    assert_eq!(read_json(&rep)["threads"], THREADS);
}

#[test]
fn the_environment_sets_defaults_under_the_flags() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let out = dir.path().join("o.exr");
    let rep = dir.path().join("r.json");
    let run = |env: &[(&str, &str)], extra: &[&str]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_epfilt"));
        c.args(["filter", &inp, out.to_str().unwrap(), "-q", "--report"])
            .arg(&rep)
            .args(extra);
        for (k, v) in env {
            c.env(k, v);
        }
        c.output().unwrap()
    };
    let o = run(&[("EPFILT_THREADS", "1")], &[]);
    assert!(o.status.success(), "{o:?}");
    assert_eq!(read_json(&rep)["threads"], 1);
    let o = run(&[("EPFILT_THREADS", "1")], &["--threads", "2"]);
    assert!(o.status.success(), "{o:?}");
    assert_eq!(read_json(&rep)["threads"], 2, "the flag wins");
    // A memory limit too small for the job is refused, naming the option.
    let o = run(&[("EPFILT_MAX_MEMORY", "0")], &[]);
    one_line_error(&o, USAGE, "--max-memory");
}

#[test]
fn info_lists_every_attribute_and_speaks_json() {
    let f = crate::corpus::data_dir().join("MultiResolution/ColorCodedLevels.exr");
    let text = epfilt_ok(&["info", f.to_str().unwrap(), "--attributes"]);
    for needle in [
        "attributes:",
        "channels (chlist): ",
        "compression (compression): pxr24",
        "dataWindow (box2i): (0, 0) - (511, 511)",
        "tiles (tiledesc): 64x64",
    ] {
        assert!(text.contains(needle), "no {needle:?}: {text}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&epfilt_ok(&["info", f.to_str().unwrap(), "--json"])).unwrap();
    assert_eq!(json["format"], "exr");
    assert_eq!(json["parts"][0]["width"], 512);
    assert_eq!(json["parts"][0]["compression"], "pxr24");
    assert_eq!(json["parts"][0]["filtered"][0], "R");
    assert_eq!(
        json["parts"][0]["attributes"]["lineOrder"][1],
        "increasing y"
    );
}

/// `--json` puts the report on standard output for the commands that write
/// one with `--report` (as `--report -`), and the two cannot both be given.
#[test]
fn json_puts_the_report_on_standard_output_for_filter_restore_and_merge() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let p = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    let json = |args: &[&str]| -> serde_json::Value {
        let text = epfilt_ok(args);
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("{args:?}: {e}: {text:.200}"))
    };
    let r = json(&["filter", &inp, &p("f.exr"), "-s", "3", "-q", "--json"]);
    assert_eq!(r["method"], "ep-gauss");
    let r = json(&[
        "restore",
        &p("f.exr"),
        &p("f.exr"),
        &p("r.exr"),
        "-q",
        "--json",
    ]);
    assert!(r["ledger"].is_array(), "{r}");
    // Bands of one scan line each: the output's blocks are that high.
    for k in ["1/2", "2/2"] {
        let band = p(&format!("band{}.exr", &k[..1]));
        let args = ["-s", "3", "-q", "--compression", "none", "--band", k];
        epfilt_ok(&[&["filter", inp.as_str(), band.as_str()][..], &args].concat());
    }
    let r = json(&[
        "merge",
        &p("band1.exr"),
        &p("band2.exr"),
        &p("m.exr"),
        "-q",
        "--json",
    ]);
    assert_eq!(r["bands"], 2);
    let o = epfilt(&[
        "filter",
        &inp,
        &p("g.exr"),
        "--json",
        "--report",
        &p("g.json"),
    ]);
    assert_eq!(o.status.code(), Some(USAGE));
}

/// `/dev/null` as an output runs the whole command and writes nothing (as
/// other tools take it); another device is still refused.
#[cfg(unix)]
#[test]
fn dev_null_runs_the_command_and_writes_nothing() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let temp_files = || {
        std::fs::read_dir(std::env::temp_dir())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().starts_with(".epfilt-"))
            .count()
    };
    let before = temp_files();
    let text = epfilt_ok(&["filter", &inp, "/dev/null", "-s", "3", "-q", "--json"]);
    let r: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(r["output"], "/dev/null");
    assert!(r["energy_rel_error"][0].as_f64().unwrap() < ENERGY_TOL);
    epfilt_ok(&["preview", &inp, "/dev/null"]);
    epfilt_ok(&["restore", &inp, &inp, "/dev/null", "-q"]);
    assert!(temp_files() <= before, "a temporary file was left behind");
    let o = epfilt(&["filter", &inp, "/dev/zero", "-s", "3"]);
    one_line_error(&o, 2, "character device");
}

/// A text attribute of a header, by name.
fn text_attribute(own: &exr::meta::header::LayerAttributes, name: &str) -> Option<String> {
    match own.other.get(&Text::from(name)) {
        Some(AttributeValue::Text(t)) => Some(t.to_string()),
        _ => None,
    }
}

/// The input's `software` stays the renderer's; each run appends its
/// version and settings to the history (an EXR attribute; a Radiance header
/// line, as Radiance's own programs do), and the bytes stay those of any
/// cut of the same run.
#[test]
fn software_is_kept_and_each_run_appends_itself_to_the_history() {
    let dir = tmpdir();
    let p = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    let version = env!("CARGO_PKG_VERSION");
    epfilt_ok(&["synth", "-q", "--size", "24x16", "-o", &p("in.exr")]);
    epfilt_ok(&["filter", &p("in.exr"), &p("a.exr"), "-q"]);
    epfilt_ok(&[
        "filter",
        &p("a.exr"),
        &p("b.exr"),
        "-q",
        "--method",
        "gauss",
    ]);
    let meta = exr::meta::MetaData::read_from_file(p("b.exr"), false).expect("header");
    let own = &meta.headers[0].own_attributes;
    let software = own.software_name.as_ref().map(|s| s.to_string());
    assert_eq!(
        software.as_deref(),
        Some(format!("epfilt {version}").as_str())
    );
    let history = text_attribute(own, "epfiltHistory").expect("history");
    let lines: Vec<&str> = history.lines().collect();
    assert_eq!(lines.len(), 2, "{history}");
    assert!(
        lines[0].starts_with(&format!("epfilt {version} (method=ep-gauss ")),
        "{history}"
    );
    assert!(
        lines[1].starts_with(&format!("epfilt {version} (method=gauss ")),
        "{history}"
    );
    let settings = text_attribute(own, "epfiltSettings").expect("settings");
    assert_eq!(settings, lines[1]);
    // A Radiance picture: its SOFTWARE= stays, the run is a line of its own.
    epfilt_ok(&["synth", "-q", "--size", "24x16", "-o", &p("in.hdr")]);
    epfilt_ok(&["filter", &p("in.hdr"), &p("out.hdr"), "-q"]);
    let bytes = std::fs::read(p("out.hdr")).unwrap();
    let end = bytes.windows(2).position(|w| w == b"\n\n").unwrap();
    let head = String::from_utf8_lossy(&bytes[..end]);
    let software: Vec<&str> = head
        .lines()
        .filter(|l| l.starts_with("SOFTWARE="))
        .collect();
    assert_eq!(
        software,
        [format!("SOFTWARE=epfilt {version} synth").as_str()],
        "{head}"
    );
    let ran = head
        .lines()
        .filter(|l| l.starts_with(&format!("epfilt {version} (method=ep-gauss ")))
        .count();
    assert_eq!(ran, 1, "{head}");
}

/// `.pfm` (or `--format pfm` for standard output) writes a portable float
/// map, what `oidnDenoise` reads: the same values as the EXR of the same
/// run, bottom row first, and read back by every command.
#[test]
fn pfm_outputs_hold_the_exrs_values_and_read_back() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let p = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    epfilt_ok(&["filter", &inp, &p("o.exr"), "-s", "3", "-q"]);
    let r: serde_json::Value = serde_json::from_str(&epfilt_ok(&[
        "filter",
        &inp,
        &p("o.pfm"),
        "-s",
        "3",
        "-q",
        "--json",
    ]))
    .unwrap();
    assert!(r["energy_rel_error"][0].as_f64().unwrap() < ENERGY_TOL);
    let bytes = std::fs::read(p("o.pfm")).unwrap();
    assert!(bytes.starts_with(b"PF\n10 7\n-1.0\n"), "{:?}", &bytes[..16]);
    assert_eq!(bytes.len(), 13 + 10 * 7 * 12);
    let cmp: serde_json::Value =
        serde_json::from_str(&epfilt_ok(&["compare", &p("o.pfm"), &p("o.exr"), "--json"])).unwrap();
    assert_eq!(cmp["identical"], true, "{cmp}");
    let o = epfilt(&["filter", &inp, "-", "-s", "3", "-q", "--format", "pfm"]);
    assert!(
        o.status.success() && o.stdout == bytes,
        "standard output differs"
    );
    let o = epfilt(&[
        "filter",
        &inp,
        &p("z.pfm"),
        "-s",
        "3",
        "--compression",
        "zip",
    ]);
    one_line_error(&o, USAGE, "a PFM stores f32");
}
