//! Real files from `../shared/exr-corpus`: every file filters or is refused
//! with one clear line naming it; valid RGB files decode exactly as `exr`'s own
//! reader decodes them; damaged files give an error, never a panic.

use std::path::{Path, PathBuf};

use crate::exr_io::{corpus_dir, read_planar, tmpdir};
use epfilt::io::{OutputSettings, PartSelect};
use epfilt::{filter_file, FilterJob, FilterParams, Method, PipelineConfig, Precision};

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = rd.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            files(&p, out);
        } else if p.extension().is_some_and(|e| e == "exr")
            || p.parent().is_some_and(|d| d.ends_with("Damaged"))
        {
            out.push(p);
        }
    }
}

fn corpus() -> Vec<PathBuf> {
    let dir = corpus_dir();
    assert!(
        dir.is_dir(),
        "the EXR corpus is missing at {} (clone beside ../shared)",
        dir.display()
    );
    let mut v = Vec::new();
    files(&dir, &mut v);
    v
}

/// S = 1 box filtering is the identity: the output must equal the input as
/// `exr` decodes it.
fn identity_job(input: &Path, output: &Path, part: Option<PartSelect>) -> FilterJob {
    FilterJob {
        input: input.into(),
        output: output.into(),
        params: FilterParams::new(Method::Box, 1),
        pipeline: PipelineConfig {
            threads: 2,
            ..Default::default()
        },
        output_settings: OutputSettings {
            compression: Some(exr::prelude::Compression::ZIP16),
            precision: Precision::F32,
        },
        part,
        layer: None,
        max_memory: None,
        stats: Default::default(),
    }
}

#[test]
fn every_corpus_file_filters_or_is_refused_clearly() {
    let dir = tmpdir();
    let (mut ok, mut refused, mut checked) = (0, 0, 0);
    for (k, file) in corpus().iter().enumerate() {
        let damaged = file.components().any(|c| c.as_os_str() == "Damaged");
        let out = dir.path().join(format!("{k}.exr"));
        let result =
            std::panic::catch_unwind(|| filter_file(&identity_job(file, &out, None), &|_, _| {}));
        let result = result.unwrap_or_else(|_| panic!("panic on {}", file.display()));
        match result {
            Ok(report) => {
                assert!(!damaged, "damaged file accepted: {}", file.display());
                assert!(
                    report.energy_rel_error.iter().all(|e| *e == 0.0),
                    "{}",
                    file.display()
                );
                // Bit-exact against exr's own decode, except where the file holds
                // non-finite values (refused) or lossy DWA... which still decode
                // identically: compare everything we accepted.
                let (got, want) = (read_planar(&out), read_planar(file));
                assert_eq!(got.data.len(), want.data.len(), "{}", file.display());
                for (a, b) in got.data.iter().zip(&want.data) {
                    assert!(a.to_bits() == b.to_bits(), "{}: {a} vs {b}", file.display());
                }
                checked += 1;
                ok += 1;
            }
            Err(e) => {
                let msg = e.to_string();
                assert!(
                    !msg.contains('\n'),
                    "multi-line error for {}: {msg}",
                    file.display()
                );
                let name = file.file_name().unwrap().to_string_lossy().to_string();
                assert!(
                    msg.contains(&name) || msg.contains("--part"),
                    "error does not name {name}: {msg}"
                );
                assert!(!out.exists());
                if !damaged {
                    eprintln!("refused: {msg}");
                }
                refused += 1;
            }
        }
    }
    eprintln!("corpus: {ok} filtered (checked bit-exact: {checked}), {refused} refused");
    // 59 of the 97 image files hold R,G,B or Y that the exr crate decodes; the
    // other 38 are deep, subsampled, HTJ2K, multi-part (need --part), hold no
    // colour channel, hold NaN/Inf (refused by default), or are broken on
    // purpose; all 171 Damaged/ files are refused.
    assert_eq!(ok, 59, "corpus files filtered");
    assert_eq!(refused, 268 - 59);
}

#[test]
fn multi_part_files_need_and_accept_a_part() {
    let file = corpus_dir().join("generated/multipart_mixed_4parts.exr");
    let dir = tmpdir();
    let out = dir.path().join("o.exr");
    let err = filter_file(&identity_job(&file, &out, None), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("--part"), "{err}");
    filter_file(
        &identity_job(&file, &out, Some(PartSelect::Index(0))),
        &|_, _| {},
    )
    .expect("part 0");
    assert!(out.exists());
}

#[test]
fn known_unsupported_files_are_refused_with_the_reason() {
    let cases = [
        ("v2/LowResLeftView/Trunks.exr", "deep"),
        ("LuminanceChroma/Flowers.exr", "subsampl"),
        ("generated/htj2k32_half_rgb.exr", "HTJ2K"),
        ("generated/alpha_only_float_zips.exr", "has: A"),
        (
            "openexr-repo/src/test/OpenEXRTest/invalid.exr",
            "invalid.exr",
        ),
    ];
    let dir = tmpdir();
    for (f, why) in cases {
        let out = dir.path().join("o.exr");
        let err = filter_file(&identity_job(&corpus_dir().join(f), &out, None), &|_, _| {})
            .unwrap_err()
            .to_string();
        assert!(err.contains(why), "{f}: {err}");
    }
}
