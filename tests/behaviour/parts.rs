//! Multi-part inputs: the parts epfilt does not filter are carried through
//! bit for bit at S = 1, `--part all` filters every part into one
//! multi-part output, and nothing is lost without a word.

use std::collections::HashMap;
use std::path::Path;

use epfilt::io::PartSelect;
use epfilt::{filter_file, Method};

use crate::common::ENERGY_TOL;
use crate::exr_io::{job, tmpdir, write_flat};

/// Four parts written by the OpenEXR library (`tests/data/exr/generated/
/// make_generated.py`): 0 RGB float PIZ, 1 Y half tiled ZIP in decreasing
/// line order, 2 a uint `id` (no colour) with its data window at (-10, -20),
/// 3 RGBA half DWAB.
pub const MULTI: &str = "tests/data/exr/generated/multipart_mixed_4parts.exr";

/// Every channel of every part, by part name, as read by the `exr` crate:
/// (sample type, the samples' bits).
type Parts = HashMap<String, HashMap<String, (String, Vec<u64>)>>;

fn parts_of(path: &Path) -> Parts {
    use exr::prelude::*;
    let img = read_all_flat_layers_from_file(path).expect("read every part");
    img.layer_data
        .iter()
        .map(|layer| {
            let name = layer
                .attributes
                .layer_name
                .as_ref()
                .map(|t| t.to_string())
                .unwrap_or_default();
            let chans = layer
                .channel_data
                .list
                .iter()
                .map(|c| {
                    let (kind, bits): (&str, Vec<u64>) = match &c.sample_data {
                        FlatSamples::F16(v) => {
                            ("f16", v.iter().map(|x| x.to_bits() as u64).collect())
                        }
                        FlatSamples::F32(v) => {
                            ("f32", v.iter().map(|x| x.to_bits() as u64).collect())
                        }
                        FlatSamples::U32(v) => ("u32", v.iter().map(|&x| x as u64).collect()),
                    };
                    (c.name.to_string(), (kind.to_string(), bits))
                })
                .collect();
            (name, chans)
        })
        .collect()
}

fn names(path: &Path) -> Vec<String> {
    exr::meta::MetaData::read_from_file(path, false)
        .expect("headers")
        .headers
        .iter()
        .map(|h| {
            h.own_attributes
                .layer_name
                .as_ref()
                .map(|t| t.to_string())
                .unwrap_or_default()
        })
        .collect()
}

#[test]
fn at_s1_the_other_parts_are_copied_bit_for_bit() {
    let dir = tmpdir();
    let out = dir.path().join("out.exr");
    let input = parts_of(Path::new(MULTI));
    for chosen in [0usize, 3] {
        let mut j = job(Path::new(MULTI), &out, Method::EpGauss, 1);
        j.part = Some(PartSelect::Index(chosen));
        let r = filter_file(&j, &|_, _| {}).unwrap();
        // Every part, in the input's order, under its own name.
        assert_eq!(names(&out), names(Path::new(MULTI)));
        let output = parts_of(&out);
        let in_names = names(Path::new(MULTI));
        for (i, name) in in_names.iter().enumerate() {
            let want = if i == chosen { "filtered" } else { "copied" };
            assert_eq!(r.parts[i].action, want, "part {i}");
            if i != chosen {
                assert_eq!(
                    output[name], input[name],
                    "part {name} is not bit-identical"
                );
            }
        }
        // The filtered one keeps its energy (the report is that part's).
        for e in &r.energy_rel_error {
            assert!(*e <= ENERGY_TOL, "{e}");
        }
        assert_eq!(r.parts[chosen].action, "filtered");
    }
}

#[test]
fn part_all_filters_every_part_into_one_file_the_same_for_any_cut() {
    let dir = tmpdir();
    for s in [1usize, 2] {
        let mut outs = Vec::new();
        for (k, (strip, tile, threads)) in [(13, 20, 0), (3, 7, 1)].into_iter().enumerate() {
            let out = dir.path().join(format!("all{s}_{k}.exr"));
            let mut j = job(Path::new(MULTI), &out, Method::EpGauss, s);
            j.part = Some(PartSelect::All);
            j.pipeline.strip_rows = strip;
            j.pipeline.tile = tile;
            j.pipeline.threads = threads;
            let r = filter_file(&j, &|_, _| {}).unwrap();
            let actions: Vec<&str> = r.parts.iter().map(|p| p.action.as_str()).collect();
            // Part 2 has no colour: copied at S = 1; at S = 2 its display
            // window could not match the others', so it is left out, saying so.
            if s == 1 {
                assert_eq!(actions, ["filtered", "filtered", "copied", "filtered"]);
            } else {
                assert_eq!(actions, ["filtered", "filtered", "left out", "filtered"]);
                assert!(
                    r.warnings
                        .iter()
                        .any(|w| w.contains("ids_uint_none_negorigin")),
                    "{:?}",
                    r.warnings
                );
            }
            for p in r.parts.iter().filter_map(|p| p.report.as_ref()) {
                for e in &p.energy_rel_error {
                    assert!(*e <= ENERGY_TOL, "{e}");
                }
            }
            // Every written part has the same display window (OpenEXR's rule).
            let meta = exr::meta::MetaData::read_from_file(&out, false).unwrap();
            let windows: Vec<_> = meta
                .headers
                .iter()
                .map(|h| h.shared_attributes.display_window)
                .collect();
            assert!(windows.windows(2).all(|w| w[0] == w[1]), "{windows:?}");
            assert_eq!(meta.headers[0].layer_size.0, 100 / s);
            outs.push(std::fs::read(&out).unwrap());
        }
        assert!(outs[0] == outs[1], "S={s}: bytes differ between cuts");
    }
}

#[test]
fn at_s2_one_part_is_written_and_the_others_are_named_as_left_out() {
    let dir = tmpdir();
    let out = dir.path().join("out.exr");
    let mut j = job(Path::new(MULTI), &out, Method::Gauss, 2);
    j.part = Some(PartSelect::Name("rgba_half_dwab".into()));
    let r = filter_file(&j, &|_, _| {}).unwrap();
    assert_eq!(names(&out).len(), 1);
    let w = r.warnings.join("\n");
    assert!(
        w.contains("beauty_float_piz") && w.contains("--part all"),
        "{w}"
    );
    assert_eq!(r.parts.iter().filter(|p| p.action == "left out").count(), 3);
}

/// Write `bytes` as `name` in `dir` and filter its part 0 at S = 1 (the
/// others to be copied), which must fail: the error and the output path.
fn refused_with_part0(
    dir: &Path,
    name: &str,
    bytes: &[u8],
    method: Method,
) -> (String, std::path::PathBuf) {
    let input = dir.join(name);
    std::fs::write(&input, bytes).unwrap();
    let out = dir.join("out.exr");
    let mut j = job(&input, &out, method, 1);
    j.part = Some(PartSelect::Index(0));
    let e = filter_file(&j, &|_, _| {}).unwrap_err().to_string();
    (e, out)
}

#[test]
fn a_damaged_part_that_would_be_copied_is_an_error_and_leaves_no_output() {
    use exr::io::{PeekRead, Tracking};
    let dir = tmpdir();
    let bytes = std::fs::read(MULTI).unwrap();
    // The first chunk of part 1 (ZIP): its compressed bytes garbled.
    let mut read = PeekRead::new(Tracking::new(&bytes[..]));
    assert!(exr::meta::magic_number::is_exr(&mut read).unwrap());
    let req = exr::meta::Requirements::read(&mut read).unwrap();
    let headers = exr::meta::header::Header::read_all(&mut read, &req, false).unwrap();
    let tables = exr::meta::MetaData::read_offset_tables(&mut read, &headers).unwrap();
    let at = tables[1][0] as usize;
    let mut bad = bytes.clone();
    // part number (4), tile coordinates (16), size (4), then the data.
    for b in &mut bad[at + 24..at + 40] {
        *b ^= 0x5a;
    }
    let (e, out) = refused_with_part0(dir.path(), "bad.exr", &bad, Method::EpGauss);
    assert!(e.contains("bad.exr") && e.lines().count() == 1, "{e}");
    assert!(!out.exists(), "a half-written output was left");
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "bad.exr")
        .collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
}

#[test]
fn a_uint_channel_named_like_colour_stays_uint() {
    use exr::prelude::*;
    let dir = tmpdir();
    let (w, h) = (6, 6);
    let path = dir.path().join("in.exr");
    let f = |v: f32| FlatSamples::F32(vec![v; w * h]);
    let ids: Vec<u32> = (0..(w * h) as u32).collect();
    write_flat(
        &path,
        (w, h),
        vec![
            ("B", f(0.2)),
            ("G", f(0.5)),
            ("R", f(0.9)),
            ("matte.A", FlatSamples::U32(ids)),
        ],
    );
    let out = dir.path().join("out.exr");
    for s in [1, 3] {
        filter_file(&job(&path, &out, Method::EpGauss, s), &|_, _| {}).unwrap();
        let got = parts_of(&out);
        let (kind, values) = &got[""]["matte.A"];
        assert_eq!(kind, "u32", "S={s}");
        assert!(values.iter().all(|&v| v < (w * h) as u64), "S={s}");
    }
}

/// A two-part file written by the `exr` crate: `depth` (Z only) first, then
/// `beauty` (R, G, B) unless `colour` is false.
fn write_two_parts(path: &Path, colour: bool) {
    use exr::prelude::*;
    let (w, h) = (8, 6);
    let f = |v: f32| FlatSamples::F32((0..w * h).map(|i| v + i as f32).collect());
    let layer = |name: &str, chans: Vec<(&str, f32)>| {
        let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = chans
            .into_iter()
            .map(|(n, v)| AnyChannel::new(n, f(v)))
            .collect();
        Layer::new(
            (w, h),
            LayerAttributes::named(name),
            Encoding::FAST_LOSSLESS,
            AnyChannels::sort(list),
        )
    };
    let second = if colour {
        layer("beauty", vec![("R", 1.0), ("G", 2.0), ("B", 3.0)])
    } else {
        layer("normals", vec![("N.X", 1.0), ("N.Y", 2.0)])
    };
    let layers: SmallVec<[_; 2]> = [layer("depth", vec![("Z", 5.0)]), second]
        .into_iter()
        .collect();
    Image::from_layers(
        ImageAttributes::new(IntegerBounds::from_dimensions((w, h))),
        layers,
    )
    .write()
    .to_file(path)
    .expect("write");
}

#[test]
fn part_all_reports_the_first_part_it_filters_and_refuses_a_file_with_none() {
    let dir = tmpdir();
    let input = dir.path().join("two.exr");
    write_two_parts(&input, true);
    let out = dir.path().join("out.exr");
    let mut j = job(&input, &out, Method::EpGauss, 1);
    j.part = Some(PartSelect::All);
    let r = filter_file(&j, &|_, _| {}).unwrap();
    let actions: Vec<&str> = r.parts.iter().map(|p| p.action.as_str()).collect();
    assert_eq!(actions, ["copied", "filtered"]);
    assert_eq!(r.channels, ["R", "G", "B"]);
    assert_eq!(parts_of(&out)["depth"], parts_of(&input)["depth"]);
    // Nothing to filter anywhere: refused, and no output.
    let none = dir.path().join("none.exr");
    write_two_parts(&none, false);
    let out2 = dir.path().join("out2.exr");
    let mut j = job(&none, &out2, Method::EpGauss, 1);
    j.part = Some(PartSelect::All);
    let e = filter_file(&j, &|_, _| {}).unwrap_err().to_string();
    assert!(e.contains("none.exr") && e.contains("no part"), "{e}");
    assert!(!out2.exists());
}

#[test]
fn info_says_what_filter_does_with_the_parts_and_the_cli_reports_each() {
    let text = crate::common::epfilt_ok(&["info", MULTI]);
    assert!(
        text.contains("--part all") && text.contains("copied"),
        "{text}"
    );
    let dir = tmpdir();
    let out = dir.path().join("out.exr");
    let o = crate::common::epfilt_run(&[
        "filter",
        MULTI,
        out.to_str().unwrap(),
        "-s",
        "1",
        "--part",
        "all",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said =
        String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr);
    assert!(
        said.contains("parts of the input") && said.contains("\"ids_uint_none_negorigin\": copied"),
        "{said}"
    );
}

#[test]
fn a_copied_part_claiming_huge_blocks_is_refused_before_decoding() {
    // Part 1's tile description (32 x 16) made to claim 2^20 x 2^20 tiles:
    // a decoder would allocate terabytes for one of them.
    let bytes = std::fs::read(MULTI).unwrap();
    let key = b"tiles\0tiledesc\0";
    let at = bytes
        .windows(key.len())
        .position(|w| w == key)
        .expect("a tiled part")
        + key.len()
        + 4;
    let mut bad = bytes.clone();
    bad[at..at + 4].copy_from_slice(&(1u32 << 20).to_le_bytes());
    bad[at + 4..at + 8].copy_from_slice(&(1u32 << 20).to_le_bytes());
    let dir = tmpdir();
    let (e, out) = refused_with_part0(dir.path(), "huge.exr", &bad, Method::Gauss);
    assert!(e.contains("huge.exr") && e.lines().count() == 1, "{e}");
    assert!(!out.exists());
}
