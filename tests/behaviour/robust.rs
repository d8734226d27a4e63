//! Damaged input: every variant gives a clear error or a correct result,
//! never a panic or an abort (an abort would end this test binary).

use crate::common::*;
use crate::exr_io::{job, tmpdir, write_rgb};
use epfilt::{filter_file, Method};
use exr::prelude::*;

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

#[test]
fn a_header_claiming_a_huge_image_is_refused_before_allocating() {
    let dir = tmpdir();
    let good = dir.path().join("good.exr");
    write_rgb(
        &good,
        &Img::new(12, 9, 3, |_, _, _| 1.0),
        Compression::ZIP1,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    let mut bytes = std::fs::read(&good).unwrap();
    // dataWindow box2i: xMin yMin xMax yMax after the attribute's name, type and size.
    let at = find(&bytes, b"dataWindow\0box2i\0").unwrap() + "dataWindow\0box2i\0".len() + 4;
    bytes[at + 8..at + 12].copy_from_slice(&((1i32 << 30) - 1).to_le_bytes());
    let bad = dir.path().join("huge.exr");
    std::fs::write(&bad, &bytes).unwrap();
    let out = dir.path().join("o.exr");
    let err = filter_file(&job(&bad, &out, Method::EpGauss, 3), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("huge.exr"), "{err}");
    assert!(!out.exists());
}

#[test]
fn truncated_and_bit_flipped_files_never_panic() {
    let dir = tmpdir();
    let img = fireflies(36, 27, 3, 0.02, 11);
    // (name, bytes, S): files written here by the exr crate, and real ones
    // written by OpenEXR (DWAA, DWAB with a float channel, tiled PXR24).
    let mut files: Vec<(String, Vec<u8>, usize)> = Vec::new();
    for (name, comp, blocks) in [
        ("zip", Compression::ZIP16, Blocks::ScanLines),
        ("piz", Compression::PIZ, Blocks::ScanLines),
        ("rle", Compression::RLE, Blocks::Tiles(Vec2(8, 8))),
        ("b44", Compression::B44, Blocks::ScanLines),
    ] {
        let good = dir.path().join(format!("{name}.exr"));
        let mut half = img.clone();
        half.data.iter_mut().for_each(|v| *v = v.min(6e4));
        write_rgb(
            &good,
            &half,
            comp,
            blocks,
            name == "b44" || name == "piz",
            LineOrder::Increasing,
        );
        files.push((name.into(), std::fs::read(&good).unwrap(), 3));
    }
    for real in [
        "small/dwaa_half_rgba.exr",
        "small/dwab_half_rgb_float_z.exr",
        "MultiResolution/ColorCodedLevels.exr",
    ] {
        let bytes = std::fs::read(crate::corpus::data_dir().join(real)).unwrap();
        files.push((real.into(), bytes, 1));
    }
    for (name, bytes, s) in files {
        let bad = dir.path().join("bad.exr");
        let out = dir.path().join("out.exr");
        let mut variants: Vec<Vec<u8>> = (0..bytes.len())
            .step_by(bytes.len() / 60 + 1)
            .map(|n| bytes[..n].to_vec())
            .collect();
        let mut rng = Rng(7);
        for _ in 0..120 {
            let mut v = bytes.clone();
            let k = (rng.next_u64() % v.len() as u64) as usize;
            v[k] ^= 1 << (rng.next_u64() % 8);
            variants.push(v);
        }
        for v in variants {
            std::fs::write(&bad, &v).unwrap();
            let r = std::panic::catch_unwind(|| {
                filter_file(&job(&bad, &out, Method::EpGauss, s), &|_, _| {})
            });
            match r {
                Err(_) => panic!("{name}: panic on a damaged file"),
                Ok(Err(e)) => {
                    let msg = e.to_string();
                    assert!(
                        msg.contains("bad.exr") && !msg.contains('\n'),
                        "{name}: unclear error: {msg}"
                    );
                }
                Ok(Ok(report)) => assert!(report.energy_rel_error.iter().all(|e| *e <= ENERGY_TOL)),
            }
        }
    }
}

/// A value the output cannot hold is the output's fault, and the error says
/// so by naming the output file; a non-finite sample names the input (the
/// pipeline says which side, the job which file).
#[test]
fn a_value_too_large_for_the_output_names_the_output() {
    let dir = tmpdir();
    let input = dir.path().join("bright.exr");
    let mut img = Img::new(12, 9, 3, |_, _, _| 0.5);
    img.set(4, 4, 0, 1e6); // above half's 65504 after any filter at S = 1
    write_rgb(
        &input,
        &img,
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    let out = dir.path().join("half.exr");
    let mut j = job(&input, &out, Method::Box, 1);
    j.output_settings.precision = Some(epfilt::Precision::F16);
    let err = filter_file(&j, &|_, _| {}).unwrap_err().to_string();
    assert!(
        err.starts_with(&out.display().to_string()) && err.contains("does not fit in f16"),
        "{err}"
    );
    assert!(!out.exists());
}

#[test]
fn nonfinite_samples_are_refused_or_counted_as_zero() {
    use epfilt::pipeline::NonFinite;
    let dir = tmpdir();
    let input = dir.path().join("nan.exr");
    let mut img = Img::new(30, 21, 3, |_, _, _| 0.5);
    img.set(7, 4, 1, f32::NAN);
    img.set(29, 20, 0, f32::INFINITY);
    img.set(0, 0, 2, f32::NEG_INFINITY);
    write_rgb(
        &input,
        &img,
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    let out = dir.path().join("out.exr");
    let err = filter_file(&job(&input, &out, Method::EpGauss, 3), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("nan.exr") && err.contains("(0, 0)") && err.contains("channel B"),
        "{err}"
    );
    assert!(!out.exists());
    let mut j = job(&input, &out, Method::EpGauss, 3);
    j.pipeline.nonfinite = NonFinite::Zero;
    let report = filter_file(&j, &|_, _| {}).unwrap();
    assert_eq!(report.nonfinite_zeroed, vec![1, 1, 1]);
    assert_eq!(report.first_nonfinite, Some((0, 0, "B".to_string())));
    assert!(report.energy_rel_error.iter().all(|e| *e <= ENERGY_TOL));
    let got = crate::exr_io::read_planar(&out);
    assert!(got.data.iter().all(|v| v.is_finite()));
    // A file written by OpenEXR with NaN in R, +Inf in G and -Inf in B.
    let real = crate::corpus::data_dir().join("small/nan_inf_half_rgb.exr");
    let err = filter_file(&job(&real, &out, Method::EpGauss, 1), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("(4, 3)") && err.contains("channel R"), "{err}");
    let mut j = job(&real, &out, Method::EpGauss, 1);
    j.pipeline.nonfinite = NonFinite::Zero;
    let report = filter_file(&j, &|_, _| {}).unwrap();
    assert_eq!(report.channels, vec!["R", "G", "B"]);
    assert_eq!(report.nonfinite_zeroed, vec![1, 1, 1]);
    assert_eq!(report.first_nonfinite, Some((4, 3, "R".to_string())));
}

/// Inputs the fuzzer (`scripts/fuzz`) crashed epfilt with, kept once fixed:
/// every method at S = 1..3 must give an error or a result, never a panic.
#[test]
fn fuzzer_regressions_never_panic() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let out_dir = tmpdir();
    for entry in std::fs::read_dir(&dir).expect("tests/data/fuzz") {
        let file = entry.unwrap().path();
        for s in 1..=3 {
            for m in GAUSSIAN_FAMILY {
                let out = out_dir.path().join("o.exr");
                // As the fuzz target runs it: output compressed like the input.
                let mut j = job(&file, &out, m, s);
                j.output_settings.compression = None;
                j.pipeline.threads = 1;
                let r = std::panic::catch_unwind(|| filter_file(&j, &|_, _| {}));
                let r =
                    r.unwrap_or_else(|_| panic!("panic on {} with {m:?} S={s}", file.display()));
                // A panic on a worker thread surfaces as an error mentioning it.
                if let Err(e) = r {
                    assert!(!e.to_string().contains("panicked"), "{m:?} S={s}: {e}");
                }
            }
        }
    }
}

/// ep-box reads the variance pass where it is carried (as it is read), so
/// it is held once, and checks it as light: a non-finite variance is
/// refused naming its channel; with `--nonfinite zero` the statistics are
/// read on their own (zeroed and counted) and the carried pass keeps its
/// values.
#[test]
fn a_carried_variance_is_read_once_and_checked_as_light() {
    use epfilt::pipeline::NonFinite;
    let dir = tmpdir();
    let (w, h) = (24, 18);
    let names = ["R", "G", "B", "variance.R", "variance.G", "variance.B"];
    let input = dir.path().join("var.exr");
    let write = |nan: bool| {
        crate::exr_io::write_named(&input, w, h, &names, &[("spp", 16)], |x, y, c| match c {
            _ if nan && (x, y, c) == (5, 7, 4) => f32::NAN,
            0..=2 if (x, y) == (9, 9) => 30.0,
            0..=2 => 0.5,
            _ if (x, y) == (9, 9) => 900.0,
            _ => 1e-6,
        })
    };
    write(false);
    let out = dir.path().join("out.exr");
    let report = filter_file(&job(&input, &out, Method::EpBox, 1), &|_, _| {}).unwrap();
    let input_row = report.windows.iter().find(|u| u.name == "input").unwrap();
    assert_eq!(input_row.row_bytes, names.len() * 4 * w);
    // The paper's test, on the variance read, finds the bright pixel noisy
    // (the carriers guard then keeps it: a compact feature).
    let ep_box = report.ep_box.as_ref().unwrap();
    assert_eq!(report.samples_noisy + ep_box.reliable, 1, "{ep_box:?}");
    write(true);
    let err = filter_file(&job(&input, &out, Method::EpBox, 1), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("(5, 7)") && err.contains("variance.G"),
        "{err}"
    );
    let mut j = job(&input, &out, Method::EpBox, 1);
    j.pipeline.nonfinite = NonFinite::Zero;
    let report = filter_file(&j, &|_, _| {}).unwrap();
    assert_eq!(report.first_nonfinite.map(|f| (f.0, f.1)), Some((5, 7)));
    let img = read_all_flat_layers_from_file(&out).expect("read");
    let list = &img.layer_data[0].channel_data.list;
    let var_g = list
        .iter()
        .find(|c| c.name.to_string() == "variance.G")
        .unwrap();
    let v: Vec<f32> = var_g.sample_data.values_as_f32().collect();
    assert!(v[7 * w + 5].is_nan(), "carried as it was");
}
