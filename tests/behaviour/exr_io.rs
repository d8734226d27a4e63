//! Files in, files out: every layout and codec the reader handles gives the
//! same result as filtering the decoded pixels in memory.

use std::path::Path;

use crate::common::*;
use epfilt::pipeline::Sink;
use epfilt::{filter_file, FilterJob, Method, PipelineConfig, Precision};
use exr::prelude::*;

pub fn tmpdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("tempdir")
}

/// Write an RGB image (planar rows) with the `exr` crate's high-level API.
pub fn write_rgb(
    path: &Path,
    img: &Img,
    compression: Compression,
    blocks: Blocks,
    half: bool,
    order: LineOrder,
) {
    let (w, nch) = (img.w, img.nch);
    let data = img.data.clone();
    let px = move |Vec2(x, y): Vec2<usize>, c: usize| data[(y * nch + c) * w + x];
    let enc = Encoding {
        compression,
        blocks,
        line_order: order,
    };
    if half {
        let ch = SpecificChannels::rgb(move |p| {
            (
                f16::from_f32(px(p, 0)),
                f16::from_f32(px(p, 1)),
                f16::from_f32(px(p, 2)),
            )
        });
        let layer = Layer::new((img.w, img.h), LayerAttributes::named(""), enc, ch);
        Image::from_layer(layer)
            .write()
            .to_file(path)
            .expect("write test input");
    } else {
        let ch = SpecificChannels::rgb(move |p| (px(p, 0), px(p, 1), px(p, 2)));
        let layer = Layer::new((img.w, img.h), LayerAttributes::named(""), enc, ch);
        Image::from_layer(layer)
            .write()
            .to_file(path)
            .expect("write test input");
    }
}

/// Read R, G, B (or Y) of the first layer with `exr`'s high-level reader, as
/// planar f32 rows: an independent check of our block reader.
pub fn read_planar(path: &Path) -> Img {
    let layer = first_layer(path);
    let (w, h) = (layer.size.0, layer.size.1);
    let find = |n: &str| {
        layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == n)
    };
    let chans: Vec<_> = if find("R").is_some() {
        ["R", "G", "B"].iter().filter_map(|n| find(n)).collect()
    } else {
        vec![find("Y").expect("Y")]
    };
    let nch = chans.len();
    Img::new(w, h, nch, |x, y, c| {
        chans[c].sample_data.value_by_flat_index(y * w + x).to_f32()
    })
}

/// The first layer of `path`, every channel, with `exr`'s high-level reader.
fn first_layer(path: &Path) -> Layer<AnyChannels<FlatSamples>> {
    read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .expect("read")
        .layer_data
}

/// Every channel of `path`'s first layer, by name (in the file's order), as
/// f32.
pub fn read_channels(path: &Path) -> Vec<(String, Vec<f32>)> {
    (first_layer(path).channel_data.list.iter())
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect()
}

/// Every channel of `path`'s first layer, by name, as the file stores it
/// (its sample type and bits).
pub fn read_samples(path: &Path) -> Vec<(String, FlatSamples)> {
    (first_layer(path).channel_data.list.into_iter())
        .map(|c| (c.name.to_string(), c.sample_data))
        .collect()
}

/// Write one unnamed layer of `channels` (any order, any sample types) with
/// the `exr` crate's high-level API.
pub fn write_flat(path: &Path, size: (usize, usize), channels: Vec<(&str, FlatSamples)>) {
    write_encoded(path, size, channels, Encoding::FAST_LOSSLESS);
}

/// [`write_flat`] with `encoding`.
pub fn write_encoded(
    path: &Path,
    size: (usize, usize),
    channels: Vec<(&str, FlatSamples)>,
    encoding: Encoding,
) {
    write_layer(path, size, channels, encoding, LayerAttributes::named(""));
}

/// [`write_flat`] of a multi-view file, `views` its `multiView` (the
/// default first).
pub fn write_views(
    path: &Path,
    size: (usize, usize),
    channels: Vec<(&str, FlatSamples)>,
    views: &[&str],
) {
    let mut attrs = LayerAttributes::named("");
    attrs.multi_view_names = Some(views.iter().map(|v| Text::from(*v)).collect());
    write_layer(path, size, channels, Encoding::FAST_LOSSLESS, attrs);
}

fn write_layer(
    path: &Path,
    size: (usize, usize),
    channels: Vec<(&str, FlatSamples)>,
    encoding: Encoding,
    attrs: LayerAttributes,
) {
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = channels
        .into_iter()
        .map(|(n, v)| AnyChannel::new(n, v))
        .collect();
    Image::from_layer(Layer::new(size, attrs, encoding, AnyChannels::sort(list)))
        .write()
        .to_file(path)
        .expect("write");
}

/// A xorshift generator from `seed` (not 0): test values, the same every run.
fn xorshift(mut seed: u64) -> impl FnMut() -> u64 {
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    }
}

/// ZIP and ZIPS blocks are decoded by epfilt's own `io::zip` (not the `exr`
/// crate's, which keeps a block-sized buffer per thread): every sample type,
/// odd sizes (odd byte counts per line for half), scan lines and tiles,
/// values over the whole range, each read back bit for bit.
#[test]
fn zip_blocks_of_every_sample_type_decode_exactly() {
    let (w, h) = (37usize, 23usize);
    let n = w * h;
    let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
    let f16s: Vec<f16> = (0..n)
        .map(|i| match i % 5 {
            0 => f16::from_f32(65504.0),
            1 => f16::from_bits(1 + (next() % 1023) as u16), // subnormal
            _ => f16::from_f32((next() % 100_000) as f32 / 7.0),
        })
        .collect();
    let f32s: Vec<f32> = (0..n)
        .map(|i| match i % 4 {
            0 => 1e30,
            1 => 1e-40, // subnormal
            _ => f32::from_bits((next() % 0x7f00_0000) as u32),
        })
        .collect();
    let u32s: Vec<u32> = (0..n).map(|_| (next() % (1 << 24)) as u32).collect();
    let dir = tmpdir();
    for compression in [Compression::ZIP1, Compression::ZIP16] {
        for blocks in [Blocks::ScanLines, Blocks::Tiles(Vec2(16, 8))] {
            let input = dir.path().join("in.exr");
            let channels = vec![
                ("R", FlatSamples::F16(f16s.clone())),
                ("G", FlatSamples::F32(f32s.clone())),
                ("B", FlatSamples::U32(u32s.clone())),
            ];
            let encoding = Encoding {
                compression,
                blocks,
                line_order: LineOrder::Increasing,
            };
            write_encoded(&input, (w, h), channels, encoding);
            let out = dir.path().join("out.exr");
            filter_file(&job(&input, &out, Method::Box, 1), &|_, _| {}).expect("filter");
            let got = read_planar(&out);
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    let want = [f16s[i].to_f32(), f32s[i], u32s[i] as f32];
                    for (c, v) in want.iter().enumerate() {
                        let g = got.data[(y * 3 + c) * w + x];
                        assert_eq!(
                            g.to_bits(),
                            v.to_bits(),
                            "{compression:?} {blocks:?} ({x}, {y}) channel {c}: {g} vs {v}"
                        );
                    }
                }
            }
        }
    }
}

/// The memory estimate counts a decoded block per decoding worker except
/// where blocks are inflated into the reader's window: ZIP and ZIPS scan
/// lines, every channel a 32-bit float.
#[test]
fn only_float_zip_scan_lines_decode_in_place() {
    let dir = tmpdir();
    let (w, h) = (16usize, 8usize);
    let plane: Vec<f32> = (0..w * h).map(|i| i as f32 * 0.25).collect();
    let halves: Vec<f16> = plane.iter().map(|&v| f16::from_f32(v)).collect();
    let float = |_| FlatSamples::F32(plane.clone());
    for (compression, blocks, half_g, in_place) in [
        (Compression::ZIP16, Blocks::ScanLines, false, true),
        (Compression::ZIP1, Blocks::ScanLines, false, true),
        (Compression::PIZ, Blocks::ScanLines, false, false),
        (Compression::Uncompressed, Blocks::ScanLines, false, false),
        (Compression::ZIP16, Blocks::Tiles(Vec2(8, 8)), false, false),
        (Compression::ZIP16, Blocks::ScanLines, true, false),
    ] {
        let input = dir.path().join("in.exr");
        let g = match half_g {
            true => FlatSamples::F16(halves.clone()),
            false => float(()),
        };
        let encoding = Encoding {
            compression,
            blocks,
            line_order: LineOrder::Increasing,
        };
        write_encoded(
            &input,
            (w, h),
            vec![("R", float(())), ("G", g), ("B", float(()))],
            encoding,
        );
        let reader = epfilt::io::ExrInput::open(&input, None).expect("open");
        assert_eq!(
            reader.decodes_in_place(),
            in_place,
            "{compression:?} {blocks:?} half G {half_g}"
        );
    }
}

/// Float-only ZIP and ZIPS scan lines decode straight into the rows, the
/// block's bytes in place, its channel planes then put in the order filtered
/// (`R G B` from the file's `B G R`, and beside alpha), decoding ahead or not:
/// every value bit for bit, blocks short at the bottom, widths of one and
/// more.
#[test]
fn float_zip_scan_lines_decode_in_place_in_any_channel_order() {
    let mut next = xorshift(0x2545_f491_4f6c_dd1d);
    let dir = tmpdir();
    for (w, h) in [(37usize, 23usize), (1, 40), (300, 17)] {
        let n = w * h;
        let planes: Vec<Vec<f32>> = (0..4)
            .map(|c| {
                (0..n)
                    .map(|i| match (i + c) % 5 {
                        0 => 1e30,
                        1 => 1e-40, // subnormal
                        2 => -0.0,
                        _ => f32::from_bits((next() % 0x7f00_0000) as u32),
                    })
                    .collect()
            })
            .collect();
        for names in [&["R", "G", "B"][..], &["R", "G", "B", "A"][..]] {
            for compression in [Compression::ZIP1, Compression::ZIP16] {
                let input = dir.path().join("in.exr");
                let channels = names
                    .iter()
                    .zip(&planes)
                    .map(|(name, p)| (*name, FlatSamples::F32(p.clone())))
                    .collect();
                let encoding = Encoding {
                    compression,
                    blocks: Blocks::ScanLines,
                    line_order: LineOrder::Increasing,
                };
                write_encoded(&input, (w, h), channels, encoding);
                // Strips read without decoding ahead hold the channels in
                // the reader's order.
                let reader = epfilt::io::ExrInput::open(&input, None).expect("open");
                let order: Vec<usize> = reader
                    .channels()
                    .iter()
                    .map(|c| {
                        names
                            .iter()
                            .position(|n| n == c)
                            .expect("a channel written")
                    })
                    .collect();
                let mut src = reader.source();
                let mut y = 0;
                while let Some(strip) =
                    epfilt::pipeline::Source::next_strip(&mut src, 5).expect("read")
                {
                    for (r, row) in strip.data.chunks_exact(order.len() * w).enumerate() {
                        for (k, &c) in order.iter().enumerate() {
                            let want = &planes[c][(y + r) * w..][..w];
                            let got: Vec<u32> =
                                row[k * w..][..w].iter().map(|v| v.to_bits()).collect();
                            let want: Vec<u32> = want.iter().map(|v| v.to_bits()).collect();
                            assert_eq!(
                                got,
                                want,
                                "{w}x{h} {names:?} {compression:?} row {}",
                                y + r
                            );
                        }
                    }
                    y += strip.rows;
                }
                assert_eq!(y, h);
                let out = dir.path().join("out.exr");
                filter_file(&job(&input, &out, Method::Box, 1), &|_, _| {}).expect("filter");
                let got = read_planar(&out);
                // Read back as R, G, B (alpha is carried beside them).
                let rgb: Vec<(&str, &Vec<f32>)> =
                    names.iter().copied().zip(&planes).take(3).collect();
                let nch = 3;
                for y in 0..h {
                    for (c, (name, plane)) in rgb.iter().enumerate() {
                        for x in 0..w {
                            let (g, v) = (got.data[(y * nch + c) * w + x], plane[y * w + x]);
                            assert_eq!(
                                g.to_bits(),
                                v.to_bits(),
                                "{w}x{h} {names:?} {compression:?} ({x}, {y}) {name}: {g} vs {v}"
                            );
                        }
                    }
                }
            }
        }
    }
}

pub fn job(input: &Path, output: &Path, method: Method, s: usize) -> FilterJob {
    let mut j = FilterJob::new(input, output, params(method, s));
    j.pipeline = PipelineConfig {
        strip_rows: 13,
        tile: 20,
        ..Default::default()
    };
    j.output_settings.compression = Some(Compression::Uncompressed);
    j
}

#[test]
fn every_layout_and_codec_matches_the_in_memory_filter() {
    let s = 3;
    let img = fireflies(37 * s, 29 * s, 3, 0.01, 3);
    let dir = tmpdir();
    let layouts: Vec<(&str, Compression, Blocks, bool, LineOrder)> = vec![
        (
            "none",
            Compression::Uncompressed,
            Blocks::ScanLines,
            false,
            LineOrder::Increasing,
        ),
        (
            "rle-half",
            Compression::RLE,
            Blocks::ScanLines,
            true,
            LineOrder::Increasing,
        ),
        (
            "zips",
            Compression::ZIP1,
            Blocks::ScanLines,
            false,
            LineOrder::Increasing,
        ),
        (
            "zip-dec",
            Compression::ZIP16,
            Blocks::ScanLines,
            false,
            LineOrder::Decreasing,
        ),
        (
            "piz-half",
            Compression::PIZ,
            Blocks::ScanLines,
            true,
            LineOrder::Increasing,
        ),
        (
            "pxr24",
            Compression::PXR24,
            Blocks::ScanLines,
            false,
            LineOrder::Increasing,
        ),
        (
            "b44-half",
            Compression::B44,
            Blocks::ScanLines,
            true,
            LineOrder::Increasing,
        ),
        (
            "dwaa-half",
            Compression::DWAA(None),
            Blocks::ScanLines,
            true,
            LineOrder::Increasing,
        ),
        (
            "tiled16",
            Compression::ZIP16,
            Blocks::Tiles(Vec2(16, 16)),
            false,
            LineOrder::Increasing,
        ),
        (
            "tiled-odd-dec",
            Compression::RLE,
            Blocks::Tiles(Vec2(7, 5)),
            true,
            LineOrder::Decreasing,
        ),
    ];
    for (name, comp, blocks, half, order) in layouts {
        let input = dir.path().join(format!("{name}.exr"));
        // Half holds up to 65504: keep the fireflies below it there.
        let mut src = img.clone();
        if half {
            src.data.iter_mut().for_each(|v| *v = v.min(6e4));
        }
        write_rgb(&input, &src, comp, blocks, half, order);
        let decoded = read_planar(&input);
        for m in [Method::EpGauss, Method::Box] {
            let out = dir.path().join(format!("{name}-{}.exr", m.name()));
            let mut j = job(&input, &out, m, s);
            // Compared with the in-memory filter's f32 values.
            j.output_settings.precision = Some(Precision::F32);
            if m == Method::Box {
                // Our own ZIP encoder (one line per block).
                j.output_settings.compression = Some(Compression::ZIP1);
            }
            let report = filter_file(&j, &|_, _| {}).expect(name);
            assert!(
                report.energy_rel_error.iter().all(|e| *e <= ENERGY_TOL),
                "{name}"
            );
            let got = read_planar(&out);
            let want = run(&decoded, s, &params(m, s), &PipelineConfig::default()).0;
            assert_eq!(bits(&got), bits(&want), "{name} {m:?}");
        }
    }
}

#[test]
fn header_attributes_carry_over_and_windows_scale() {
    let dir = tmpdir();
    let input = dir.path().join("in.exr");
    let img = Img::new(12, 9, 3, |x, y, c| (x + y + c) as f32);
    let ch = {
        let data = img.data.clone();
        SpecificChannels::rgb(move |Vec2(x, y): Vec2<usize>| {
            (
                data[(y * 3) * 12 + x],
                data[(y * 3 + 1) * 12 + x],
                data[(y * 3 + 2) * 12 + x],
            )
        })
    };
    let mut attrs = LayerAttributes::named("beauty");
    attrs.layer_position = Vec2(-6, 3);
    attrs.comments = Some(Text::from("rendered overnight"));
    attrs.owner = Some(Text::from("studio"));
    attrs
        .other
        .insert(Text::from("renderer:spp"), AttributeValue::I32(64));
    let layer = Layer::new((12, 9), attrs, Encoding::FAST_LOSSLESS, ch);
    let mut image = Image::from_layer(layer);
    image.attributes.chromaticities = Some(exr::meta::attribute::Chromaticities {
        red: Vec2(0.708, 0.292),
        green: Vec2(0.170, 0.797),
        blue: Vec2(0.131, 0.046),
        white: Vec2(0.3127, 0.3290),
    });
    image.attributes.display_window = IntegerBounds::new(Vec2(-6, 0), Vec2(18, 15));
    image.write().to_file(&input).unwrap();
    let out = dir.path().join("out.exr");
    filter_file(&job(&input, &out, Method::Gauss, 3), &|_, _| {}).unwrap();
    let meta = exr::meta::MetaData::read_from_file(&out, false).unwrap();
    let h = &meta.headers[0];
    assert_eq!(h.layer_size, Vec2(4, 3));
    assert_eq!(h.own_attributes.layer_position, Vec2(-2, 1));
    assert_eq!(
        h.shared_attributes.display_window,
        IntegerBounds::new(Vec2(-2, 0), Vec2(6, 5))
    );
    assert_eq!(
        h.own_attributes.comments.as_ref().map(|t| t.to_string()),
        Some("rendered overnight".into())
    );
    assert_eq!(
        h.own_attributes.owner.as_ref().map(|t| t.to_string()),
        Some("studio".into())
    );
    assert!(h
        .own_attributes
        .other
        .contains_key(&Text::from("renderer:spp")));
    assert!(h.shared_attributes.chromaticities.is_some());
}

#[test]
fn f16_output_refuses_values_it_cannot_hold() {
    let dir = tmpdir();
    let input = dir.path().join("hot.exr");
    let img = Img::new(9, 9, 3, |_, _, _| 1e5);
    write_rgb(
        &input,
        &img,
        Compression::Uncompressed,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    let out = dir.path().join("out.exr");
    let mut j = job(&input, &out, Method::Box, 3);
    // The output's precision alone decides the rounding (and the refusal).
    j.output_settings.precision = Some(Precision::F16);
    let err = filter_file(&j, &|_, _| {}).unwrap_err().to_string();
    assert!(err.contains("f16") && err.contains("out.exr"), "{err}");
    assert!(!out.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "temporary file left behind"
    );
}

#[test]
fn size_not_a_multiple_of_s_is_refused() {
    let dir = tmpdir();
    let input = dir.path().join("odd.exr");
    write_rgb(
        &input,
        &Img::new(10, 9, 3, |_, _, _| 1.0),
        Compression::Uncompressed,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    let out = dir.path().join("out.exr");
    let err = filter_file(&job(&input, &out, Method::Box, 3), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("multiple of --supersample 3"), "{err}");
}

#[test]
fn an_interrupted_run_leaves_nothing_behind() {
    let dir = tmpdir();
    let input = dir.path().join("in.exr");
    write_rgb(
        &input,
        &Img::new(30, 30, 3, |_, _, _| 1.0),
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    let out = dir.path().join("out.exr");
    let mut j = job(&input, &out, Method::EpGauss, 3);
    j.pipeline.cancel = Some(std::sync::Arc::new(std::sync::atomic::AtomicBool::new(
        true,
    )));
    let err = filter_file(&j, &|_, _| {}).unwrap_err();
    assert!(matches!(err, epfilt::Error::Interrupted), "{err}");
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("in.exr")]);
}

/// A `w x h` f32 file of the named channels (any order: the writer sorts
/// them) with integer header attributes `ints`; channel `c` of pixel (x, y)
/// holds `f(x, y, c)`.
pub fn write_named(
    path: &Path,
    w: usize,
    h: usize,
    names: &[&str],
    ints: &[(&str, i32)],
    f: impl Fn(usize, usize, usize) -> f32,
) {
    let names: Vec<String> = names.iter().map(|s| s.to_string()).collect();
    let mut out = epfilt::io::ExrOutput::create_new(
        path,
        w,
        h,
        &names,
        Compression::ZIP16,
        Precision::F32,
        ints,
    )
    .unwrap();
    let mut data = Vec::new();
    for y in 0..h {
        for c in 0..names.len() {
            for x in 0..w {
                data.push(f(x, y, c));
            }
        }
    }
    out.write_rows(0, h, &data).unwrap();
    out.finish().unwrap();
    out.commit().unwrap();
}

#[test]
fn the_beauty_layer_is_filtered_not_an_aov_that_sorts_before_it() {
    let dir = tmpdir();
    // Blender's channel names: ViewLayer.AO sorts before ViewLayer.Combined.
    let names = [
        "ViewLayer.AO.R",
        "ViewLayer.AO.G",
        "ViewLayer.AO.B",
        "ViewLayer.Combined.R",
        "ViewLayer.Combined.G",
        "ViewLayer.Combined.B",
        "ViewLayer.Combined.A",
        "ViewLayer.Depth.Z",
    ];
    let input = dir.path().join("blender.exr");
    // Each channel holds its index: the output tells which were read.
    write_named(&input, 6, 4, &names, &[], |_, _, c| c as f32);
    let out = dir.path().join("out.exr");
    let r = filter_file(&job(&input, &out, Method::Box, 1), &|_, _| {}).unwrap();
    assert_eq!(
        r.channels[..4],
        [
            "ViewLayer.Combined.R",
            "ViewLayer.Combined.G",
            "ViewLayer.Combined.B",
            "ViewLayer.Combined.A"
        ]
    );
    // The AOVs are carried beside it, by their rules.
    assert_eq!(r.channel_rules["ViewLayer.Combined.R"], "colour");
    assert_eq!(r.channel_rules["ViewLayer.Combined.A"], "alpha");
    assert_eq!(r.channel_rules["ViewLayer.AO.R"], "average");
    assert_eq!(r.channel_rules["ViewLayer.Depth.Z"], "average");
    assert!(r.dropped_channels.is_empty());
    // Box at S = 1 is the identity: Combined.R (written 3rd in `names`) is 3.
    let meta = exr::meta::MetaData::read_from_file(&out, false).unwrap();
    let got: Vec<String> = meta.headers[0]
        .channels
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    assert_eq!(
        got,
        [
            "ViewLayer.AO.B",
            "ViewLayer.AO.G",
            "ViewLayer.AO.R",
            "ViewLayer.Combined.A",
            "ViewLayer.Combined.B",
            "ViewLayer.Combined.G",
            "ViewLayer.Combined.R",
            "ViewLayer.Depth.Z"
        ]
    );
    let img = exr::prelude::read_all_flat_layers_from_file(&out).unwrap();
    let r_plane = img.layer_data[0]
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "ViewLayer.Combined.R")
        .unwrap()
        .sample_data
        .values_as_f32()
        .collect::<Vec<_>>();
    assert!(r_plane.iter().all(|&v| v == 3.0), "{r_plane:?}");

    // --layer chooses another one.
    let mut j = job(&input, &out, Method::Box, 1);
    j.layer = Some("ViewLayer.AO".into());
    let r = filter_file(&j, &|_, _| {}).unwrap();
    assert_eq!(
        r.channels[..3],
        ["ViewLayer.AO.R", "ViewLayer.AO.G", "ViewLayer.AO.B"]
    );
    assert_eq!(r.channel_rules["ViewLayer.AO.R"], "colour");
}

#[test]
fn several_aov_layers_and_no_beauty_is_a_clear_error_naming_them() {
    let dir = tmpdir();
    let names = [
        "albedo.R",
        "albedo.G",
        "albedo.B",
        "diffuse.R",
        "diffuse.G",
        "diffuse.B",
        "depth.Z",
    ];
    let input = dir.path().join("aovs.exr");
    write_named(&input, 5, 3, &names, &[], |_, _, c| c as f32);
    let out = dir.path().join("out.exr");
    let e = filter_file(&job(&input, &out, Method::Box, 1), &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("aovs.exr") && e.contains("albedo, diffuse") && e.contains("--layer"),
        "{e}"
    );
    assert!(!e.contains('\n'), "one line: {e}");
    assert!(!out.exists());

    let mut j = job(&input, &out, Method::Box, 1);
    j.layer = Some("depth".into());
    let e = filter_file(&j, &|_, _| {}).unwrap_err().to_string();
    assert!(
        e.contains("\"depth\"") && e.contains("albedo, diffuse"),
        "{e}"
    );

    // A trailing dot is accepted too.
    j.layer = Some("diffuse.".into());
    let r = filter_file(&j, &|_, _| {}).unwrap();
    assert_eq!(r.channels[..3], ["diffuse.R", "diffuse.G", "diffuse.B"]);
    assert_eq!(r.channel_rules["diffuse.R"], "colour");
    assert_eq!(r.channel_rules["albedo.R"], "average");
    assert_eq!(r.channel_rules["depth.Z"], "average");

    // One layer with colour is taken without asking.
    let single = dir.path().join("single.exr");
    write_named(
        &single,
        5,
        3,
        &["render.R", "render.G", "render.B", "depth.Z"],
        &[],
        |_, _, c| c as f32,
    );
    let r = filter_file(&job(&single, &out, Method::Box, 1), &|_, _| {}).unwrap();
    assert_eq!(r.channels, ["render.R", "render.G", "render.B", "depth.Z"]);
    assert_eq!(r.channel_rules["render.G"], "colour");
    assert_eq!(r.channel_rules["depth.Z"], "average");
}

/// A renderer's header carries many custom attributes; exr keeps them in a
/// hash map whose order changes from process to process. Two runs of the
/// same command must still write the same bytes (farms compare checksums
/// and retry tasks), and every attribute must survive.
#[test]
fn files_with_many_custom_attributes_are_byte_identical_across_runs() {
    let dir = tmpdir();
    let input = dir.path().join("in.exr");
    let ch = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
        (
            1.0 + x as f32,
            2.0 + y as f32,
            if (x, y) == (4, 5) { 900.0 } else { 0.5f32 },
        )
    });
    let mut attrs = LayerAttributes::named("");
    for (k, name) in [
        "renderer:spp",
        "renderer:seed",
        "camera:iso",
        "shot",
        "take",
    ]
    .iter()
    .enumerate()
    {
        attrs
            .other
            .insert(Text::from(*name), AttributeValue::I32(k as i32 + 1));
    }
    let layer = Layer::new((12, 9), attrs, Encoding::FAST_LOSSLESS, ch);
    Image::from_layer(layer).write().to_file(&input).unwrap();
    let bytes: Vec<Vec<u8>> = (0..3)
        .map(|k| {
            let out = dir.path().join(format!("out{k}.exr"));
            let o = std::process::Command::new(env!("CARGO_BIN_EXE_epfilt"))
                .args([
                    "filter",
                    input.to_str().unwrap(),
                    out.to_str().unwrap(),
                    "-s",
                    "3",
                    "-q",
                ])
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            std::fs::read(&out).unwrap()
        })
        .collect();
    assert!(
        bytes.windows(2).all(|p| p[0] == p[1]),
        "the runs wrote different bytes"
    );
    let meta = exr::meta::MetaData::read_from_file(dir.path().join("out0.exr"), false).unwrap();
    let other = &meta.headers[0].own_attributes.other;
    for name in [
        "renderer:spp",
        "renderer:seed",
        "camera:iso",
        "shot",
        "take",
    ] {
        assert!(other.contains_key(&Text::from(name)), "{name} lost");
    }
}

/// The sample type of each channel of a file, by name.
fn sample_types(path: &Path) -> Vec<(String, SampleType)> {
    let meta = exr::meta::MetaData::read_from_file(path, false).expect("header");
    meta.headers[0]
        .channels
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_type))
        .collect()
}

#[test]
fn pixel_type_same_keeps_half_inputs_half_and_the_ledger_counts_what_is_stored() {
    let dir = tmpdir();
    let s = 3;
    let mut img = fireflies(12 * s, 9 * s, 3, 0.02, 5);
    // Half holds up to 65504.
    img.data.iter_mut().for_each(|v| *v = v.min(6e4));
    for (half, want) in [(true, SampleType::F16), (false, SampleType::F32)] {
        let input = dir.path().join(format!("in-{half}.exr"));
        write_rgb(
            &input,
            &img,
            Compression::ZIP16,
            Blocks::ScanLines,
            half,
            LineOrder::Increasing,
        );
        for m in [Method::EpGauss, Method::Gauss] {
            let out = dir.path().join(format!("out-{half}-{}.exr", m.name()));
            let j = job(&input, &out, m, s); // precision None: the input's
            let report = filter_file(&j, &|_, _| {}).expect("filter");
            let types = sample_types(&out);
            assert!(types.iter().all(|(_, t)| *t == want), "{half}: {types:?}");
            assert_eq!(report.settings["pixel_type"], want_name(want));
            ledger_holds_the_file(&report, &out, s, &format!("{half} {m:?}"));
        }
    }
    // An explicit type wins over the input's.
    let input = dir.path().join("in-true.exr");
    let out = dir.path().join("forced.exr");
    let mut j = job(&input, &out, Method::EpGauss, s);
    j.output_settings.precision = Some(Precision::F32);
    filter_file(&j, &|_, _| {}).expect("filter");
    assert!(sample_types(&out)
        .iter()
        .all(|(_, t)| *t == SampleType::F32));
}

#[test]
fn pixel_type_same_keeps_each_channels_own_type() {
    // Half colour with a float alpha (as renderers write coverage): each
    // channel keeps its type, and the ledger counts what each one stores.
    let dir = tmpdir();
    let s = 3;
    let (w, h) = (10 * s, 7 * s);
    let img = fireflies(w, h, 3, 0.02, 9);
    let half = |c: usize| {
        FlatSamples::F16(
            (0..w * h)
                .map(|i| f16::from_f32(img.at(i % w, i / w, c).min(6e4)))
                .collect(),
        )
    };
    let alpha = FlatSamples::F32((0..w * h).map(|i| ((i % 5) as f32) * 0.25).collect());
    let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = vec![
        AnyChannel::new("A", alpha),
        AnyChannel::new("B", half(2)),
        AnyChannel::new("G", half(1)),
        AnyChannel::new("R", half(0)),
    ]
    .into_iter()
    .collect();
    let input = dir.path().join("mixed.exr");
    Image::from_layer(Layer::new(
        (w, h),
        LayerAttributes::named(""),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    ))
    .write()
    .to_file(&input)
    .expect("write mixed");
    for m in GAUSSIAN_FAMILY {
        let out = dir.path().join(format!("out-{}.exr", m.name()));
        let report = filter_file(&job(&input, &out, m, s), &|_, _| {}).expect("filter");
        let types: std::collections::BTreeMap<String, SampleType> =
            sample_types(&out).into_iter().collect();
        assert_eq!(types["A"], SampleType::F32, "{m:?}: {types:?}");
        for c in ["R", "G", "B"] {
            assert_eq!(types[c], SampleType::F16, "{m:?}: {types:?}");
        }
        let name = report.settings["pixel_type"].as_str().unwrap().to_string();
        assert!(name.contains("f16") && name.contains("f32"), "{name}");
        ledger_holds_the_file(&report, &out, s, &format!("{m:?}"));
    }
}

/// "After rounding" in the ledger is the sum of what the file holds, for
/// each of its R, G, B channels.
fn ledger_holds_the_file(report: &epfilt::report::Report, out: &Path, s: usize, what: &str) {
    let stored = read_planar(out);
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        let k = report.channels.iter().position(|n| n == name).unwrap();
        let after = report.energy_out_rounded[k];
        let mut sum = 0.0f64;
        for y in 0..stored.h {
            for x in 0..stored.w {
                sum += stored.at(x, y, c) as f64;
            }
        }
        let on_disk = sum * (s * s) as f64;
        assert!(
            (on_disk - after).abs() <= SUM_ORDER_TOL * after.abs(),
            "{what} {name}: ledger {after} vs file {on_disk}"
        );
    }
}

/// The ledger and this test add the same stored values in different orders:
/// f64 sums of a few hundred values agree to far better than this.
const SUM_ORDER_TOL: f64 = 1e-12;

fn want_name(t: SampleType) -> &'static str {
    match t {
        SampleType::F16 => "f16",
        _ => "f32",
    }
}

#[test]
fn multiview_names_only_the_views_whose_channels_were_written() {
    let dir = tmpdir();
    let input = dir.path().join("stereo.exr");
    let (w, h) = (12, 9);
    let plane = |v: f32| FlatSamples::F32((0..w * h).map(|i| v + i as f32).collect());
    let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> =
        ["B", "G", "R", "right.B", "right.G", "right.R"]
            .iter()
            .enumerate()
            .map(|(k, n)| AnyChannel::new(*n, plane(k as f32)))
            .collect();
    let mut attributes = LayerAttributes::named("");
    attributes.multi_view_names = Some(vec![Text::from("left"), Text::from("right")]);
    let layer = Layer::new(
        (w, h),
        attributes,
        Encoding::UNCOMPRESSED,
        AnyChannels::sort(channels),
    );
    Image::from_layer(layer)
        .write()
        .to_file(&input)
        .expect("write stereo input");
    let views = |p: &Path| -> Option<Vec<String>> {
        let meta = exr::meta::MetaData::read_from_file(p, false).expect("header");
        meta.headers[0]
            .own_attributes
            .multi_view_names
            .as_ref()
            .map(|v| v.iter().map(|t| t.to_string()).collect())
    };
    assert_eq!(views(&input), Some(vec!["left".into(), "right".into()]));
    let out = dir.path().join("out.exr");
    filter_file(&job(&input, &out, Method::Box, 3), &|_, _| {}).expect("filter");
    // Only the default view's R, G, B were filtered and written.
    assert_eq!(views(&out), Some(vec!["left".to_string()]));
}
