//! Real files written by other programs: each one filters exactly as the
//! `exr` crate decodes it, or is refused with one clear line naming it and the
//! reason the table below gives; damaged files give an error, never a panic.
//!
//! By default the files are the licensed subset in `tests/data/exr` (see its
//! README); the ignored `the_whole_corpus_gives_what_the_table_says` walks
//! the whole corpus named by `EPFILT_CORPUS=DIR` (`.ci/run` runs it with
//! `../shared/exr-corpus`). Both use the same
//! table of expectations, keyed by the path below the corpus root.

use std::path::{Path, PathBuf};

use crate::exr_io::{read_planar, tmpdir};
use epfilt::io::{OutputSettings, PartSelect};
use epfilt::{filter_file, FilterJob, FilterParams, Method, Precision};

/// What a file must give.
#[derive(Clone, Copy, Debug)]
enum Expect {
    /// Filters at S = 1 with the box, bit-identical to `exr`'s own decode.
    Filters,
    /// Refused, with an error that contains this.
    Refused(&'static str),
}

use Expect::{Filters, Refused};

const MULTI_PART: &str = "choose one with --part";
const NO_COLOUR: &str = "no colour channels to filter";
const DEEP: &str = "deep data";
const SUBSAMPLED: &str = "subsampling";
const NON_FINITE: &str = "non-finite input value";
const MISSING_BYTES: &str = "reference to missing bytes";

/// Every image file of the corpus and what it must give (files under
/// `Damaged/` must all be refused, whatever the reason).
const EXPECTED: &[(&str, Expect)] = &[
    ("Beachball/multipart.0001.exr", Refused(MULTI_PART)),
    ("Beachball/singlepart.0001.exr", Filters),
    ("Beachball/singlepart.0007.exr", Filters),
    ("Chromaticities/Rec709_YC.exr", Refused(SUBSAMPLED)),
    ("DisplayWindow/t01.exr", Filters),
    ("DisplayWindow/t02.exr", Filters),
    ("DisplayWindow/t03.exr", Filters),
    ("DisplayWindow/t04.exr", Filters),
    ("DisplayWindow/t05.exr", Filters),
    ("DisplayWindow/t06.exr", Filters),
    ("DisplayWindow/t07.exr", Filters),
    ("DisplayWindow/t08.exr", Filters),
    ("DisplayWindow/t09.exr", Filters),
    ("DisplayWindow/t10.exr", Filters),
    ("DisplayWindow/t11.exr", Filters),
    ("DisplayWindow/t12.exr", Filters),
    ("DisplayWindow/t13.exr", Filters),
    ("DisplayWindow/t14.exr", Filters),
    ("DisplayWindow/t15.exr", Filters),
    ("DisplayWindow/t16.exr", Filters),
    ("LuminanceChroma/Flowers.exr", Refused(SUBSAMPLED)),
    ("LuminanceChroma/Garden.exr", Filters),
    ("MultiResolution/ColorCodedLevels.exr", Filters),
    ("MultiResolution/MirrorPattern.exr", Filters),
    ("MultiResolution/PeriodicPattern.exr", Filters),
    ("MultiResolution/StageEnvLatLong.exr", Filters),
    ("MultiResolution/WavyLinesCube.exr", Filters),
    ("MultiResolution/WavyLinesSphere.exr", Filters),
    ("MultiView/Adjuster.exr", Filters),
    ("MultiView/Fog.exr", Filters),
    ("ScanLines/Cannon.exr", Filters),
    ("ScanLines/Carrots.exr", Filters),
    ("TestImages/AllHalfValues.exr", Refused(NON_FINITE)),
    ("TestImages/BrightRings.exr", Filters),
    ("TestImages/BrightRingsNanInf.exr", Refused(NON_FINITE)),
    ("TestImages/GammaChart.exr", Filters),
    ("TestImages/GrayRampsDiagonal.exr", Filters),
    ("TestImages/GrayRampsHorizontal.exr", Filters),
    ("TestImages/RgbRampsDiagonal.exr", Filters),
    ("TestImages/SquaresSwirls.exr", Filters),
    ("TestImages/WideColorGamut.exr", Filters),
    ("TestImages/WideFloatRange.exr", Refused(NO_COLOUR)),
    ("TestImages/stripes.exr", Filters),
    ("Tiles/GoldenGate.exr", Filters),
    ("generated/alpha_only_float_zips.exr", Refused(NO_COLOUR)),
    ("generated/carrots_mipmap_dwaa.exr", Filters),
    ("generated/float_uint_pxr24.exr", Refused(NO_COLOUR)),
    ("generated/htj2k256_half_rgb.exr", Refused("HTJ2K256")),
    ("generated/htj2k32_half_rgb.exr", Refused("HTJ2K32")),
    ("generated/multipart_mixed_4parts.exr", Refused(MULTI_PART)),
    ("generated/neg_origin_uint_half_rle_decreasing.exr", Filters),
    ("generated/stripes_ripmap_rle.exr", Filters),
    ("generated/stripes_ripmap_roundup_b44a.exr", Filters),
    (
        "generated/widefloat_tiled_float_dwab.exr",
        Refused(NO_COLOUR),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_b44.exr",
        Refused(SUBSAMPLED),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_b44_piz.exr",
        Filters,
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_bad_bounds_piz.exr",
        Refused(MISSING_BYTES),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_bad_neg_bounds_pxr24.exr",
        Refused(MISSING_BYTES),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_bad_pos_bounds_piz.exr",
        Refused(MISSING_BYTES),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_bad_pos_bounds_pxr24.exr",
        Refused(MISSING_BYTES),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_dwaa_piz.exr",
        Filters,
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_dwaa_v1.exr",
        Filters,
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_dwaa_v2.exr",
        Filters,
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_dwab_piz.exr",
        Filters,
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_dwab_v1.exr",
        Filters,
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_dwab_v2.exr",
        Filters,
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_early_eof_piz.exr",
        Refused("attribute size"),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_invalid_unknown.exr",
        Refused(MISSING_BYTES),
    ),
    ("openexr-repo/src/test/OpenEXRTest/comp_none.exr", Filters),
    ("openexr-repo/src/test/OpenEXRTest/comp_piz.exr", Filters),
    ("openexr-repo/src/test/OpenEXRTest/comp_rle.exr", Filters),
    (
        "openexr-repo/src/test/OpenEXRTest/comp_short_decode_piz.exr",
        Refused(MISSING_BYTES),
    ),
    ("openexr-repo/src/test/OpenEXRTest/comp_zip.exr", Filters),
    ("openexr-repo/src/test/OpenEXRTest/comp_zips.exr", Filters),
    (
        "openexr-repo/src/test/OpenEXRTest/invalid.exr",
        Refused("not an OpenEXR file"),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/invalid_shared_attrs_multipart.exr",
        Refused("offset table does not fit"),
    ),
    // Alpha holds NaN in these two.
    (
        "openexr-repo/src/test/OpenEXRTest/lineOrder_decreasing.exr",
        Refused(NON_FINITE),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/lineOrder_increasing.exr",
        Refused(NON_FINITE),
    ),
    // The `type` attribute contradicts the file (the exr crate trusts it).
    (
        "openexr-repo/src/test/OpenEXRTest/scanline_with_deepscanline_type.exr",
        Refused(DEEP),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/scanline_with_deeptiled_type.exr",
        Refused("block type"),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/scanline_with_tiledimage_type.exr",
        Refused("tiles attribute"),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/tiled.exr",
        Refused("outside the pixel data"),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/tiled_with_deepscanline_type.exr",
        Refused(DEEP),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/tiled_with_deeptile_type.exr",
        Refused("block type"),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/tiled_with_scanlineimage_type.exr",
        Refused("block at byte"),
    ),
    ("openexr-repo/src/test/OpenEXRTest/v1.7.test.1.exr", Filters),
    (
        "openexr-repo/src/test/OpenEXRTest/v1.7.test.interleaved.exr",
        Refused(NO_COLOUR),
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/v1.7.test.planar.exr",
        Filters,
    ),
    (
        "openexr-repo/src/test/OpenEXRTest/v1.7.test.tiled.exr",
        Refused(NO_COLOUR),
    ),
    (
        "openexr-repo/src/test/bin/test_images/11.deep.exr",
        Refused(DEEP),
    ),
    (
        "openexr-repo/src/wrappers/python/tests/manifest_id.exr",
        Filters,
    ),
    ("openexr-repo/src/wrappers/python/tests/test.exr", Filters),
    (
        "openexr-repo/src/wrappers/python/tests/unfinished_multipart.exr",
        Refused(MULTI_PART),
    ),
    (
        "openexr-repo/website/downloads/sample.exr",
        Refused(NO_COLOUR),
    ),
    ("v2/LowResLeftView/Trunks.exr", Refused(DEEP)),
    ("v2/LowResLeftView/composited.exr", Filters),
    ("v2/Stereo/Trunks.exr", Refused(DEEP)),
    // Written for tests/data/exr by small/make_small.py.
    ("small/aovs_multilayer.exr", Filters),
    ("small/b44_half_rgb.exr", Filters),
    ("small/b44a_half_rgba.exr", Filters),
    ("small/dwaa_half_rgba.exr", Filters),
    ("small/dwaa_tiled_half_rgb.exr", Filters),
    ("small/dwab_half_rgb_float_z.exr", Filters),
    ("small/nan_inf_half_rgb.exr", Refused(NON_FINITE)),
];

/// The subset kept in the repository.
pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/exr")
}

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

/// S = 1 box filtering is the identity: the output must equal the input as
/// `exr` decodes it.
fn identity_job(input: &Path, output: &Path, part: Option<PartSelect>) -> FilterJob {
    let mut job = FilterJob::new(input, output, FilterParams::new(Method::Box, 1));
    job.pipeline.threads = 2;
    job.output_settings = OutputSettings {
        compression: Some(exr::prelude::Compression::ZIP16),
        precision: Some(Precision::F32),
        ..OutputSettings::default()
    };
    job.part = part;
    job
}

/// Filter every file below `root` and hold each to the table. `strict`: a
/// file the table does not know is an error (the repository's subset must be
/// listed; a corpus may grow).
fn walk(root: &Path, strict: bool) {
    let mut all = Vec::new();
    files(root, &mut all);
    assert!(!all.is_empty(), "no files under {}", root.display());
    let dir = tmpdir();
    let mut unknown = Vec::new();
    for (k, file) in all.iter().enumerate() {
        let rel = file
            .strip_prefix(root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        let damaged = rel.starts_with("Damaged/");
        let expect = EXPECTED.iter().find(|(p, _)| *p == rel).map(|(_, e)| *e);
        if expect.is_none() && !damaged {
            unknown.push(rel.clone());
        }
        let out = dir.path().join(format!("{k}.exr"));
        let result =
            std::panic::catch_unwind(|| filter_file(&identity_job(file, &out, None), &|_, _| {}))
                .unwrap_or_else(|_| panic!("panic on {rel}"));
        match result {
            Ok(report) => {
                assert!(!damaged, "damaged file accepted: {rel}");
                if let Some(Refused(why)) = expect {
                    panic!("{rel} filtered, but must be refused ({why})");
                }
                assert!(report.energy_rel_error.iter().all(|e| *e == 0.0), "{rel}");
                let (got, want) = (read_planar(&out), read_planar(file));
                assert_eq!(got.data.len(), want.data.len(), "{rel}");
                for (a, b) in got.data.iter().zip(&want.data) {
                    assert!(a.to_bits() == b.to_bits(), "{rel}: {a} vs {b}");
                }
            }
            Err(e) => {
                let msg = e.to_string();
                assert!(!msg.contains('\n'), "multi-line error for {rel}: {msg}");
                let name = file.file_name().unwrap().to_string_lossy().to_string();
                assert!(msg.contains(&name), "error does not name {name}: {msg}");
                assert!(!out.exists(), "{rel}: output left behind");
                match expect {
                    Some(Filters) => panic!("{rel} must filter, but: {msg}"),
                    Some(Refused(why)) => assert!(msg.contains(why), "{rel}: {msg} (want {why})"),
                    None => {}
                }
            }
        }
    }
    if strict {
        assert!(
            unknown.is_empty(),
            "files missing from the table in corpus.rs: {unknown:?}"
        );
    } else if !unknown.is_empty() {
        eprintln!("not in the table (checked for a clear outcome only): {unknown:?}");
    }
}

#[test]
fn every_file_kept_in_the_repository_gives_what_the_table_says() {
    walk(&data_dir(), true);
}

/// The whole corpus: `EPFILT_CORPUS` names it (`.ci/run` sets it to
/// `../shared/exr-corpus` and runs this test).
#[test]
#[ignore = "needs the whole EXR corpus: EPFILT_CORPUS=../shared/exr-corpus cargo test --test behaviour -- --ignored whole_corpus"]
fn the_whole_corpus_gives_what_the_table_says() {
    let dir = std::env::var_os("EPFILT_CORPUS")
        .map(PathBuf::from)
        .expect("EPFILT_CORPUS names the corpus folder (../shared/exr-corpus)");
    assert!(
        dir.is_dir(),
        "EPFILT_CORPUS={} is not a folder",
        dir.display()
    );
    walk(&dir, false);
}

#[test]
fn multi_part_files_need_and_accept_a_part() {
    let file = data_dir().join("generated/multipart_mixed_4parts.exr");
    let dir = tmpdir();
    let out = dir.path().join("o.exr");
    let err = filter_file(&identity_job(&file, &out, None), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("--part"), "{err}");
    // Every part with colour: scan lines (PIZ float), tiles in decreasing
    // order (ZIP), DWAB half.
    for part in [
        PartSelect::Index(0),
        PartSelect::Index(1),
        PartSelect::Name("rgba_half_dwab".into()),
    ] {
        filter_file(&identity_job(&file, &out, Some(part.clone())), &|_, _| {})
            .unwrap_or_else(|e| panic!("{part:?}: {e}"));
        assert!(out.exists());
    }
    let err = filter_file(
        &identity_job(&file, &out, Some(PartSelect::Index(9))),
        &|_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("--part 9") && err.contains("4 part"), "{err}");
}
