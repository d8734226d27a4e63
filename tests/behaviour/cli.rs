//! The `epfilt` command as a user meets it.

use std::path::Path;
use std::process::{Command, Output};

use crate::common::*;
use crate::exr_io::{corpus_dir, tmpdir, write_rgb};
use exr::prelude::*;

fn epfilt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_epfilt"))
        .args(args)
        .output()
        .expect("run epfilt")
}

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

fn one_line_error(out: &Output, needle: &str) {
    assert_eq!(out.status.code(), Some(2));
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
        .all(|e| e.as_f64().unwrap() <= 1e-12));
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
        "nope.exr",
    );
    let nodir = dir.path().join("no/such/dir/out.exr");
    one_line_error(
        &epfilt(&["filter", &inp, nodir.to_str().unwrap()]),
        "no/such/dir",
    );
    one_line_error(
        &epfilt(&["filter", &inp, "x.exr", "-s", "9"]),
        "--supersample",
    );
    one_line_error(
        &epfilt(&["filter", &inp, "x.exr", "--method", "sharpen"]),
        "unknown method",
    );
    let text = dir.path().join("text.exr");
    std::fs::write(&text, "this is not an image").unwrap();
    one_line_error(
        &epfilt(&["filter", text.to_str().unwrap(), "x.exr"]),
        "text.exr",
    );
}

#[test]
fn output_equal_to_input_is_refused_and_input_untouched() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let before = std::fs::read(&inp).unwrap();
    one_line_error(&epfilt(&["filter", &inp, &inp]), "is the input file");
    let link = dir.path().join("link.exr");
    std::os::unix::fs::symlink(&inp, &link).unwrap();
    one_line_error(
        &epfilt(&["filter", &inp, link.to_str().unwrap()]),
        "is the input file",
    );
    let hard = dir.path().join("hard.exr");
    std::fs::hard_link(&inp, &hard).unwrap();
    one_line_error(
        &epfilt(&["filter", &inp, hard.to_str().unwrap()]),
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
    let f = corpus_dir().join("Tiles/GoldenGate.exr");
    let o = epfilt(&["info", f.to_str().unwrap()]);
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(
        s.contains("1262x860")
            && s.contains("piz")
            && s.contains("tiles 128x128")
            && s.contains("R half")
            && s.contains("filtered: R, G, B"),
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
    one_line_error(&o, "out.exr");
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
/// permissions are not enforced (root), `/sys`, which refuses file creation to
/// root too. `None` if neither is available.
fn read_only_dir(dir: &Path) -> Option<std::path::PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let ro = dir.join("ro");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    if std::fs::write(ro.join("probe"), b"x").is_err() {
        return Some(ro);
    }
    let sys = Path::new("/sys");
    (sys.is_dir() && std::fs::write(sys.join("epfilt-probe"), b"x").is_err())
        .then(|| sys.to_path_buf())
}

#[test]
fn read_only_destination_is_one_line_and_leaves_nothing() {
    let dir = tmpdir();
    let inp = input(dir.path());
    let before = std::fs::read(&inp).unwrap();
    let Some(ro) = read_only_dir(dir.path()) else {
        eprintln!("no read-only directory on this machine; skipped");
        return;
    };
    let out = ro.join("out.exr");
    let o = epfilt(&["filter", &inp, out.to_str().unwrap(), "-q"]);
    one_line_error(&o, &ro.display().to_string());
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
fn sigterm_and_sigint_mid_run_leave_no_output_and_the_input_untouched() {
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
        assert_eq!(o.status.code(), Some(2), "signal {sig}: {err}");
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
