//! Pictures people look at: previews shrunk by area or cropped, false
//! colour with a legend, and `compare --diff`'s image of where two images
//! differ.

use std::path::Path;

use crate::common::{epfilt_ok as ok, epfilt_run as epfilt, Img};
use crate::exr_io::{tmpdir, write_rgb};
use exr::prelude::*;

/// Exit status of a usage error.
const USAGE: i32 = 2;
/// The legend beside false-colour panels, and the gap before it (pixels).
const LEGEND: usize = 96 + 4;
/// The label band above labelled or false-colour panels (pixels).
const BAND: usize = 12;

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

fn write(dir: &Path, name: &str, img: &Img) -> std::path::PathBuf {
    let p = dir.join(name);
    write_rgb(
        &p,
        img,
        Compression::ZIP16,
        Blocks::ScanLines,
        false,
        LineOrder::Increasing,
    );
    p
}

/// A PNG's size and its RGB bytes.
fn read_png(path: &Path) -> (usize, usize, Vec<u8>) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    (info.width as usize, info.height as usize, buf)
}

fn pixel(png: &(usize, usize, Vec<u8>), x: usize, y: usize) -> [u8; 3] {
    let at = (y * png.0 + x) * 3;
    [png.2[at], png.2[at + 1], png.2[at + 2]]
}

#[test]
fn width_shrinks_by_area_and_crop_shows_a_rectangle() {
    let dir = tmpdir();
    // Left half 1, right half 0, and one bright pixel in the right half.
    let img = Img::new(64, 32, 3, |x, y, _| match (x, y) {
        (48, 8) => 16.0,
        (x, _) if x < 32 => 1.0,
        _ => 0.0,
    });
    let inp = write(dir.path(), "in.exr", &img);
    let out = dir.path().join("small.png");
    ok(&["preview", s(&inp), s(&out), "--width", "16"]);
    let small = read_png(&out);
    assert_eq!((small.0, small.1), (16, 8));
    // Each preview pixel is the mean of 4x4 samples: the left half's 1s,
    // the right half's 0s, and the bright one spread over its 16 (not lost,
    // not clipped to one white pixel among black).
    assert_eq!(pixel(&small, 3, 4), pixel(&small, 0, 0));
    assert_eq!(pixel(&small, 8, 4), [0, 0, 0]);
    assert_eq!(pixel(&small, 12, 2), pixel(&small, 0, 0));
    assert!(pixel(&small, 0, 0)[0] > 0);
    // Never enlarged.
    ok(&["preview", s(&inp), s(&out), "--width", "1000"]);
    assert_eq!(read_png(&out).0, 64);
    // A crop of the right half: black but for the bright pixel.
    ok(&["preview", s(&inp), s(&out), "--crop", "32x16+32+0"]);
    let crop = read_png(&out);
    assert_eq!((crop.0, crop.1), (32, 16));
    assert_eq!(pixel(&crop, 0, 0), [0, 0, 0]);
    assert_eq!(pixel(&crop, 16, 8), [255, 255, 255]);
    // Outside the image, or not a geometry: one line, a usage error.
    for bad in ["32x16+40+0", "32x16", "0x4+0+0"] {
        let o = epfilt(&["preview", s(&inp), s(&out), "--crop", bad]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(USAGE), "{bad}: {e}");
        assert_eq!(e.trim().lines().count(), 1, "{e}");
        assert!(e.contains("crop"), "{e}");
    }
}

#[test]
fn false_colour_has_a_legend_and_orders_values() {
    let dir = tmpdir();
    // Luminance rising by factors of ten across the image.
    let img = Img::new(40, 10, 3, |x, _, _| 10f32.powi(x as i32 / 10));
    let inp = write(dir.path(), "in.exr", &img);
    let out = dir.path().join("fc.png");
    ok(&[
        "preview",
        s(&inp),
        s(&out),
        "--false-color",
        "--fc-top",
        "1000",
        "--fc-decades",
        "3",
    ]);
    let fc = read_png(&out);
    assert_eq!((fc.0, fc.1), (40 + LEGEND, 10 + BAND));
    // 1 is the cold end, 1000 the warm one: dark, then red over blue.
    let (cold, warm) = (pixel(&fc, 2, BAND + 5), pixel(&fc, 35, BAND + 5));
    let sum = |c: [u8; 3]| c.iter().map(|&v| v as u32).sum::<u32>();
    assert!(sum(cold) < 100, "{cold:?}");
    assert!(warm[0] > warm[2], "{warm:?}");
    // The legend's bar: warm at the top, cold at the bottom, as the panel.
    let bar = 40 + 4 + 10;
    assert_eq!(pixel(&fc, bar, BAND), warm);
    assert_eq!(pixel(&fc, bar, BAND + 9), cold);
    // A scale that cannot be: a usage error.
    let o = epfilt(&[
        "preview",
        s(&inp),
        s(&out),
        "--false-color",
        "--fc-top",
        "-1",
    ]);
    assert_eq!(o.status.code(), Some(USAGE));
}

#[test]
fn compare_diff_shows_where_the_images_differ() {
    let dir = tmpdir();
    let a = Img::new(20, 10, 3, |_, _, _| 0.5);
    let mut b = Img::new(20, 10, 3, |_, _, _| 0.5);
    for c in 0..3 {
        b.data[(7 * 3 + c) * 20 + 13] = 50.0;
    }
    let (pa, pb) = (
        write(dir.path(), "a.exr", &a),
        write(dir.path(), "b.exr", &b),
    );
    let diff = dir.path().join("diff.png");
    ok(&["compare", s(&pa), s(&pb), "--diff", s(&diff)]);
    let d = read_png(&diff);
    assert_eq!((d.0, d.1), (20 + LEGEND, 10 + BAND));
    let (same, differ) = (pixel(&d, 2, BAND + 2), pixel(&d, 13, BAND + 7));
    assert_ne!(same, differ);
    // Where they agree: the scale's cold end (the legend's bottom).
    assert_eq!(same, pixel(&d, 20 + 4 + 10, BAND + 9));
    // The same image: nothing warm anywhere.
    ok(&["compare", s(&pa), s(&pa), "--diff", s(&diff)]);
    let d = read_png(&diff);
    assert!((0..10).all(|y| (0..20).all(|x| pixel(&d, x, BAND + y) == same)));
    // Images of different sizes: idiff's status 3, and no picture.
    let small = write(dir.path(), "small.exr", &Img::new(10, 10, 3, |_, _, _| 0.5));
    let other = dir.path().join("other.png");
    let o = epfilt(&["compare", s(&pa), s(&small), "--diff", s(&other)]);
    assert_eq!(o.status.code(), Some(3));
    assert!(!other.exists());
}
