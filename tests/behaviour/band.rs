//! One image across machines: `filter --band K/N` and `merge` give the file
//! of one run, for every method, band count and S.

use std::path::Path;

use crate::exr_io::tmpdir;

use crate::common::{epfilt_ok as ok, epfilt_run as epfilt};

/// The merge adds the bands' sums compensated, this test plainly: a few
/// ulps apart.
const SUM_ORDER: f64 = 1e-14;
/// The bands' output energy is of the stored f32 values: each within 2^-24
/// of the exact one, so their sums too.
const F32_ROUNDING: f64 = 6e-8;

use crate::common::read_json as json;

/// Filter `input` whole and in `n` bands, merge, and hold the merged file to
/// the whole run's bytes and the merge's ledger to the bands' sums.
fn bands_equal_one_run(dir: &Path, input: &str, extra: &[&str], n: usize, what: &str) {
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let mut args = vec!["filter", input, "-q", "--compression", "none"];
    args.extend_from_slice(extra);
    let whole = p("whole.exr");
    let mut a = args.clone();
    a.insert(2, &whole);
    ok(&a);
    let mut parts = Vec::new();
    let mut sums_in = [0.0f64; 3];
    for k in 1..=n {
        let part = p(&format!("part{k}.exr"));
        let rep = p(&format!("part{k}.json"));
        let band = format!("{k}/{n}");
        let mut a = args.clone();
        a.insert(2, &part);
        a.extend_from_slice(&["--band", &band, "--report", &rep]);
        ok(&a);
        let r = json(Path::new(&rep));
        for (c, s) in sums_in.iter_mut().enumerate() {
            *s += r["band"]["energy_in_owned"][c].as_f64().unwrap();
        }
        parts.push(part);
    }
    // Any order.
    parts.reverse();
    let merged = p("merged.exr");
    let rep = p("merge.json");
    let mut a: Vec<&str> = vec!["merge", "-q", "--report", &rep];
    a.extend(parts.iter().map(String::as_str));
    a.push(&merged);
    ok(&a);
    assert!(
        std::fs::read(&merged).unwrap() == std::fs::read(&whole).unwrap(),
        "{what}, {n} bands: merged file differs from one run"
    );
    let r = json(Path::new(&rep));
    for (c, s) in sums_in.iter().enumerate() {
        let merged_in = r["energy_in"][c].as_f64().unwrap();
        assert!(
            (merged_in - s).abs() <= SUM_ORDER * s.abs(),
            "{what}: channel {c}"
        );
        // And it balances with what the bands hold (the foils lose energy by design).
        let foil = ["clamp", "median", "alpha-trim"].contains(&what);
        assert!(
            foil || r["energy_rel_error"][c].as_f64().unwrap() <= F32_ROUNDING,
            "{what}"
        );
    }
    for p in parts {
        std::fs::remove_file(p).unwrap();
    }
}

#[test]
fn bands_merge_into_the_file_of_one_run_for_every_method() {
    let dir = tmpdir();
    let d = dir.path();
    let p = |name: &str| d.join(name).to_str().unwrap().to_string();
    // S = 3 (the spreading and gathering methods) and S = 1 with variance
    // (ep-box). 23 output rows: 7 bands of 3-4 rows, thinner than any halo,
    // each window the whole image. Then tall images (ep-gauss reads 146 rows
    // past a band, ep-box 37): windows that start and end inside the image
    // at a reflected edge, for bands thinner and thicker than the halo.
    ok(&[
        "synth",
        "-q",
        "--size",
        "30x23",
        "--hot",
        "1e4",
        "-o",
        &p("ss.exr"),
    ]);
    ok(&[
        "synth",
        "-q",
        "--size",
        "30x23",
        "--spp",
        "16",
        "--variance",
        "-o",
        &p("px.exr"),
    ]);
    for n in [1, 2, 7] {
        for m in ["ep-gauss", "gauss", "box", "clamp", "median", "alpha-trim"] {
            bands_equal_one_run(d, &p("ss.exr"), &["--method", m], n, m);
        }
        bands_equal_one_run(d, &p("px.exr"), &["--method", "ep-box"], n, "ep-box");
        bands_equal_one_run(
            d,
            &p("ss.exr"),
            &["-s", "1", "--method", "ep-gauss"],
            n,
            "ep-gauss S=1",
        );
        // The carriers rule reads the variance, 2 rows further.
        bands_equal_one_run(
            d,
            &p("px.exr"),
            &["-s", "1", "--method", "ep-gauss"],
            n,
            "ep-gauss S=1 with variance",
        );
        // 90x69 samples at S = 4: a partial last column and row.
        for m in ["ep-gauss", "gauss", "box"] {
            bands_equal_one_run(
                d,
                &p("ss.exr"),
                &["-s", "4", "--edge", "pad", "--method", m],
                n,
                m,
            );
        }
    }
    let tall = p("tall.exr");
    let tall_px = p("tallpx.exr");
    ok(&[
        "synth", "-q", "--size", "16x700", "--hot", "1e5", "-o", &tall,
    ]);
    let px_args = [
        "--size",
        "40x300",
        "--spp",
        "16",
        "--variance",
        "-o",
        &tall_px,
    ];
    ok(&[&["synth", "-q"][..], &px_args[..]].concat());
    for n in [2, 7, 40] {
        bands_equal_one_run(d, &tall, &["--method", "ep-gauss"], n, "ep-gauss, tall");
        // The cap at 32 px: the summed-area table's blocks of 148 rows, on
        // which band windows start.
        bands_equal_one_run(
            d,
            &tall,
            &["--method", "ep-gauss", "--quality", "best"],
            n,
            "ep-gauss best, tall",
        );
        bands_equal_one_run(d, &tall, &["--method", "gauss"], n, "gauss, tall");
        bands_equal_one_run(d, &tall_px, &["--method", "ep-box"], n, "ep-box, tall");
        // 48x2100 at S = 8: the last output row holds 4 of 8 sample rows.
        bands_equal_one_run(
            d,
            &tall,
            &["-s", "8", "--edge", "pad", "--method", "ep-gauss"],
            n,
            "ep-gauss, tall, pad",
        );
    }
}

#[test]
fn merge_refuses_incomplete_or_foreign_bands_and_band_refuses_what_cannot_merge() {
    let dir = tmpdir();
    let d = dir.path();
    let p = |name: &str| d.join(name).to_str().unwrap().to_string();
    ok(&["synth", "-q", "--size", "30x40", "-o", &p("in.exr")]);
    for k in 1..=3 {
        ok(&[
            "filter",
            &p("in.exr"),
            &p(&format!("a{k}.exr")),
            "-q",
            "--band",
            &format!("{k}/3"),
        ]);
    }
    ok(&[
        "filter",
        &p("in.exr"),
        &p("b2.exr"),
        "-q",
        "--band",
        "2/3",
        "--method",
        "gauss",
    ]);
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec![p("a1.exr"), p("a3.exr"), p("out.exr")], "cover"),
        (
            vec![p("a1.exr"), p("b2.exr"), p("a3.exr"), p("out.exr")],
            "b2.exr: band 2/3 was made with other settings",
        ),
        (vec![p("in.exr"), p("out.exr")], "not a band"),
        (
            vec![p("a1.exr"), p("a2.exr"), p("a3.exr"), p("a2.exr")],
            "is the input file",
        ),
    ];
    for (args, needle) in cases {
        let mut a = vec!["merge"];
        a.extend(args.iter().map(String::as_str));
        let o = epfilt(&a);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains(needle),
            "{args:?}: {err}"
        );
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(!d.join("out.exr").exists());
    }
    // 40 output rows in zip's 16-row blocks make 3 blocks: one of 4 bands is empty.
    for (extra, needle) in [
        (vec!["--band", "1/4"], "empty"),
        (vec!["--band", "0/3"], "1 to N"),
        (
            vec!["--band", "2/3", "--compression", "dwaa", "--allow-lossy"],
            "lossless",
        ),
    ] {
        let (in_path, out_path) = (p("in.exr"), p("o.exr"));
        let mut a = vec!["filter", &in_path[..], &out_path[..]];
        a.extend(extra.iter().copied());
        let o = epfilt(&a);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(needle), "{extra:?}: {err}");
    }
}
