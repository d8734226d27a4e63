//! Radiance pictures (`.hdr`) wherever an EXR is accepted.

use std::path::Path;

use crate::exr_io::tmpdir;
use epfilt::io::ExrInput;
use epfilt::pipeline::Source;

use crate::common::{epfilt_ok as ok, epfilt_run as epfilt};

/// Every value of a file (EXR or picture), as epfilt reads it: (channels, rows).
fn values(path: &Path) -> (Vec<String>, Vec<f32>) {
    let input = ExrInput::open(path, None).expect("open");
    let mut src = input.source();
    let mut all = Vec::new();
    while let Some(s) = src.next_strip(7).expect("read") {
        all.extend(s.data);
    }
    (input.channels(), all)
}

fn sums(path: &Path) -> Vec<f64> {
    let (names, data) = values(path);
    let w = ExrInput::open(path, None).unwrap().size().0;
    let mut s = vec![0.0f64; names.len()];
    for (k, v) in data.iter().enumerate() {
        s[(k / w) % names.len()] += *v as f64;
    }
    s
}

use crate::common::read_json as report;

#[test]
fn a_picture_filters_as_the_same_pixels_in_an_exr_do() {
    let dir = tmpdir();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    ok(&[
        "synth",
        "-q",
        "--size",
        "40x30",
        "--scene",
        "mixed",
        "-o",
        &p("in.hdr"),
    ]);
    // S = 1 box is the identity: the picture's values as an EXR.
    ok(&[
        "filter",
        &p("in.hdr"),
        &p("in.exr"),
        "-s",
        "1",
        "--method",
        "box",
        "-q",
    ]);
    assert_eq!(values(&d.join("in.hdr")), values(&d.join("in.exr")));
    for method in ["ep-gauss", "gauss", "box"] {
        ok(&[
            "filter",
            &p("in.hdr"),
            &p("a.exr"),
            "--method",
            method,
            "-q",
        ]);
        ok(&[
            "filter",
            &p("in.exr"),
            &p("b.exr"),
            "--method",
            method,
            "-q",
        ]);
        assert_eq!(
            values(&d.join("a.exr")),
            values(&d.join("b.exr")),
            "{method}"
        );
    }
}

/// RGBE keeps 8 bits of mantissa: a pixel's largest channel is within
/// 2^-8 of itself, so any sum of them is too.
const RGBE_REL: f64 = 1.0 / 256.0;

#[test]
fn a_picture_output_reports_the_energy_it_holds() {
    let dir = tmpdir();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    ok(&["synth", "-q", "--size", "40x30", "-o", &p("in.exr")]);
    ok(&[
        "filter",
        &p("in.exr"),
        &p("out.hdr"),
        "--report",
        &p("r.json"),
        "-q",
    ]);
    let r = report(&d.join("r.json"));
    assert_eq!(r["compression"], "rgbe");
    assert_eq!(r["energy_on_disk_decoded"], true);
    let on_disk = sums(&d.join("out.hdr"));
    let s2 = 9.0;
    for c in 0..3 {
        let ledger = r["energy_out_rounded"][c].as_f64().unwrap();
        let file = on_disk[c] * s2;
        // The ledger's after-rounding energy is the file's, to summation order.
        assert!(
            (ledger - file).abs() <= 1e-9 * file,
            "{c}: {ledger} vs {file}"
        );
        let before = r["energy_in"][c].as_f64().unwrap();
        let err = r["energy_rel_error_rounded"][c].as_f64().unwrap();
        assert!(err > 0.0 && err <= RGBE_REL, "{c}: {err}");
        assert!(((file - before) / before).abs() <= RGBE_REL);
    }
}

#[test]
fn header_lines_survive_and_exposure_gives_true_radiance() {
    let dir = tmpdir();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    ok(&[
        "synth",
        "-q",
        "--size",
        "16x12",
        "-s",
        "1",
        "-o",
        &p("plain.hdr"),
    ]);
    let bytes = std::fs::read(d.join("plain.hdr")).unwrap();
    let end = bytes.windows(2).position(|w| w == b"\n\n").unwrap();
    // As pfilt leaves a picture: view, aspect, primaries, its command, and an
    // exposure (values stored twice as large).
    let extra = "\tpfilt -x /3 -y /3 -r .6\nVIEW= -vtv -vp 0 0 1 -vd 0 1 0 -vh 40 -vv 30\nPIXASPECT=1.0\nPRIMARIES= 0.640 0.330 0.300 0.600 0.150 0.060 0.3127 0.3290\nEXPOSURE=2\n";
    let mut exposed = bytes[..end + 1].to_vec();
    exposed.extend_from_slice(extra.as_bytes());
    exposed.extend_from_slice(&bytes[end + 1..]);
    std::fs::write(d.join("exposed.hdr"), &exposed).unwrap();
    let plain = sums(&d.join("plain.hdr"));
    let true_radiance = sums(&d.join("exposed.hdr"));
    for c in 0..3 {
        assert!((true_radiance[c] * 2.0 - plain[c]).abs() <= 1e-9 * plain[c]);
    }
    let info = ok(&["info", &p("exposed.hdr")]);
    assert!(
        info.contains("stored values x 2") && info.contains("from PRIMARIES"),
        "{info}"
    );
    ok(&[
        "filter",
        &p("exposed.hdr"),
        &p("out.hdr"),
        "-s",
        "1",
        "--method",
        "ep-gauss",
        "-q",
    ]);
    let out = std::fs::read(d.join("out.hdr")).unwrap();
    let end = out.windows(2).position(|w| w == b"\n\n").unwrap();
    let head = String::from_utf8_lossy(&out[..end]);
    for kept in extra.lines().filter(|l| !l.starts_with("EXPOSURE")) {
        assert!(head.lines().any(|l| l == kept), "{kept:?} lost: {head}");
    }
    assert!(!head.contains("EXPOSURE"), "{head}");
    assert!(
        head.contains("SOFTWARE=epfilt") && head.contains("method=ep-gauss"),
        "{head}"
    );
    // Written at exposure 1: the output holds true radiance.
    let out_sums = sums(&d.join("out.hdr"));
    for c in 0..3 {
        assert!(((out_sums[c] - true_radiance[c]) / true_radiance[c]).abs() <= RGBE_REL);
    }
}

#[test]
fn damaged_pictures_and_misfit_outputs_are_one_line_errors() {
    let dir = tmpdir();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    ok(&["synth", "-q", "--size", "16x12", "-o", &p("in.hdr")]);
    let bytes = std::fs::read(d.join("in.hdr")).unwrap();
    std::fs::write(d.join("short.hdr"), &bytes[..bytes.len() * 2 / 3]).unwrap();
    let mut flipped = bytes.clone();
    let at = bytes.windows(2).position(|w| w == b"\n\n").unwrap() + 20;
    for k in (at..bytes.len()).step_by(7) {
        flipped[k] ^= 0x5a;
    }
    std::fs::write(d.join("flipped.hdr"), &flipped).unwrap();
    std::fs::write(
        d.join("nohead.hdr"),
        b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n",
    )
    .unwrap();
    for (name, code) in [("short.hdr", 1), ("flipped.hdr", 1), ("nohead.hdr", 1)] {
        for args in [
            vec!["filter", &p(name)[..], &p("o.exr")[..], "-q"],
            vec!["info", &p(name)[..]],
            vec!["preview", &p(name)[..], &p("o.png")[..]],
        ] {
            let o = epfilt(&args);
            let err = String::from_utf8_lossy(&o.stderr);
            if args[0] == "info" && name != "nohead.hdr" {
                // The header is intact: info reads only that.
                assert!(o.status.success(), "{args:?}: {err}");
                continue;
            }
            assert_eq!(o.status.code(), Some(code), "{args:?}: {err}");
            assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
            assert!(err.contains(name), "{args:?}: {err}");
        }
    }
    assert!(!d.join("o.exr").exists() && !d.join("o.png").exists());
    // A picture stores RGBE, not f16.
    let o = epfilt(&["filter", &p("in.hdr"), &p("o.hdr"), "--pixel-type", "f16"]);
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    assert!(!d.join("o.hdr").exists());
}

#[test]
fn bit_flipped_pictures_give_errors_or_pictures_never_panics() {
    let dir = tmpdir();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    // Wide enough for new-style runs; a flat one (below 8 pixels) too.
    ok(&["synth", "-q", "--size", "12x5", "-o", &p("rle.hdr")]);
    ok(&["synth", "-q", "--size", "2x2", "-o", &p("flat.hdr")]);
    let mut rng = crate::common::Rng(11);
    for name in ["rle.hdr", "flat.hdr"] {
        let good = std::fs::read(d.join(name)).unwrap();
        for trial in 0..300 {
            let mut bad = good.clone();
            for _ in 0..1 + trial % 4 {
                let k = (rng.next_u64() % bad.len() as u64) as usize;
                bad[k] ^= 1 << (rng.next_u64() % 8);
            }
            let path = d.join("bad.hdr");
            std::fs::write(&path, &bad).unwrap();
            if let Ok(input) = ExrInput::open(&path, None) {
                let mut src = input.source();
                while let Ok(Some(_)) = src.next_strip(3) {}
            }
        }
    }
}

/// OpenCV decodes a mantissa m as m 2^(e-136), Radiance and epfilt as
/// (m + 0.5) 2^(e-136): half a mantissa step, at most 1/256 of the pixel's
/// largest channel (m >= 128 there), plus f32 rounding.
const OPENCV_OFFSET_REL: f64 = 1.0 / 256.0 + 1e-6;

#[test]
fn pictures_written_by_opencv_read_as_opencv_reads_them() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/rgbe");
    for name in ["opencv_rle", "opencv_flat"] {
        let (names, ours) = values(&dir.join(format!("{name}.hdr")));
        assert_eq!(names, ["R", "G", "B"]);
        let raw = std::fs::read(dir.join(format!("{name}.f32"))).unwrap();
        let cv: Vec<f32> = raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let w = ExrInput::open(&dir.join(format!("{name}.hdr")), None)
            .unwrap()
            .size()
            .0;
        assert_eq!(ours.len(), cv.len(), "{name}");
        for (i, px) in cv.chunks_exact(3).enumerate() {
            let (y, x) = (i / w, i % w);
            let largest = px.iter().fold(0.0f32, |m, v| m.max(*v)) as f64;
            for c in 0..3 {
                let a = ours[(y * 3 + c) * w + x] as f64;
                let b = px[c] as f64;
                assert!(
                    a >= b && a - b <= OPENCV_OFFSET_REL * largest,
                    "{name} ({x}, {y}) channel {c}: epfilt {a} OpenCV {b}"
                );
            }
        }
    }
}
