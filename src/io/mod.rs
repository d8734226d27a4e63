//! EXR in and out: the only place that knows the `exr` crate.
//!
//! * [`reader`]: a memory-mapped file, its headers and offset tables, and a
//!   [`crate::pipeline::Source`] that decodes blocks in increasing y, in
//!   parallel, into planar f32 rows;
//! * [`chunk_sizes`]: the sizes a compressed chunk claims, checked before a
//!   decoder allocates them;
//! * [`destination`]: output paths checked (links written through, `-` for
//!   standard output, devices refused) and written through temporary files;
//! * [`format`](mod@format): which format an output is written in (its extension, or
//!   `--format`), never by accident; [`stdin`]: `-` as an input;
//! * [`provenance`]: the fingerprint of input and settings every output
//!   records, the band attributes, and the check that an existing output is
//!   complete; [`views`]: multi-view files, and `--view all`'s output;
//! * [`info`](mod@info): what a file holds, as text or JSON, and its raw attributes;
//! * [`verdict`](mod@verdict): how a file is filtered when the user does not say (its
//!   super-sampling, its method); [`guides`]: its guide passes, by name;
//! * [`writer`]: a [`crate::pipeline::Sink`] that builds scan-line blocks,
//!   compresses them in parallel and writes them with the chunk writer into a
//!   temporary file in the destination directory.

pub mod bands;
pub mod chunk_sizes;
pub mod destination;
pub mod format;
pub mod guides;
mod headers;
pub mod info;
pub mod mapped;
pub mod output;
pub mod parts;
pub mod pfm;
pub mod provenance;
pub mod reader;
pub mod rgbe;
pub mod stdin;
pub mod variance;
pub mod verdict;
pub mod views;
pub mod writer;
pub mod zip;

pub use destination::{write_file, Destination, Staged};
/// The codecs an EXR output can be written with.
pub use exr::prelude::Compression;
pub use format::Format;
pub use guides::{find_guides, FoundGuides, GuideKind, GuideRequest};
pub use info::info;
pub use reader::{ExrInput, InputFile, PartSelect, Selection, ViewSelect};
pub use variance::{find_stats, SppFrom, StatsChannels, StatsRequest};
pub use verdict::{verdict, Verdict, SUPERSAMPLE_ATTRIBUTES};
pub use writer::{ExrOutput, OutputSettings};

use exr::meta::attribute::Chromaticities;

/// The format of an input file by its first bytes (`-`: standard input).
pub fn input_format(path: &std::path::Path) -> crate::Result<Format> {
    let map = mapped::MappedFile::open(path)?;
    Ok(match Format::sniff(map.bytes()) {
        Some(Format::Rgbe) => Format::Rgbe,
        _ => Format::Exr,
    })
}

/// Luminance weights (the Y row of the RGB→XYZ matrix) of a file's
/// chromaticities; Rec. 709 / sRGB primaries when absent or degenerate.
pub fn luminance_weights(ch: Option<&Chromaticities>) -> [f64; 3] {
    const REC709: [f64; 3] = [0.2126, 0.7152, 0.0722];
    let Some(c) = ch else { return REC709 };
    let xy = |v: exr::math::Vec2<f32>| (v.0 as f64, v.1 as f64);
    let prim = [xy(c.red), xy(c.green), xy(c.blue)];
    let (xw, yw) = xy(c.white);
    if prim.iter().any(|&(_, y)| y.abs() < 1e-9) || yw.abs() < 1e-9 {
        return REC709;
    }
    // Columns: XYZ of each primary at Y = 1; solve M * S = white (Y = 1).
    let m: Vec<[f64; 3]> = prim
        .iter()
        .map(|&(x, y)| [x / y, 1.0, (1.0 - x - y) / y])
        .collect();
    let w = [xw / yw, 1.0, (1.0 - xw - yw) / yw];
    let a = [
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ];
    let det = |a: &[[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(&a);
    if d.abs() < 1e-12 {
        return REC709;
    }
    let mut s = [0.0; 3];
    for (k, sk) in s.iter_mut().enumerate() {
        let mut ak = a;
        for r in 0..3 {
            ak[r][k] = w[r];
        }
        *sk = det(&ak) / d;
    }
    if s.iter().all(|v| v.is_finite()) {
        s
    } else {
        REC709
    }
}

/// A compression's name as on the command line.
pub fn compression_name(c: Compression) -> String {
    match c {
        Compression::Uncompressed => "none".into(),
        Compression::RLE => "rle".into(),
        Compression::ZIP1 => "zips".into(),
        Compression::ZIP16 => "zip".into(),
        Compression::PIZ => "piz".into(),
        Compression::PXR24 => "pxr24".into(),
        Compression::B44 => "b44".into(),
        Compression::B44A => "b44a".into(),
        Compression::DWAA(_) => "dwaa".into(),
        Compression::DWAB(_) => "dwab".into(),
        other => format!("{other:?}").to_lowercase(),
    }
}

/// Whether `c` changes samples of `precision` (measured with OpenEXR 3.5 on
/// files epfilt wrote: DWAA/DWAB quantize half and float alike, B44/B44A
/// only half (float channels are stored as they are), PXR24 only float (it
/// keeps 24 of 32 bits; half is lossless)).
pub fn is_lossy(c: Compression, precision: crate::pipeline::Precision) -> bool {
    use crate::pipeline::Precision;
    match c {
        Compression::DWAA(_) | Compression::DWAB(_) => true,
        Compression::B44 | Compression::B44A => precision == Precision::F16,
        Compression::PXR24 => precision == Precision::F32,
        Compression::HTJ2K32 | Compression::HTJ2K256 => true,
        _ => false,
    }
}

/// Parse a compression name (`none rle zips zip piz pxr24 b44 b44a dwaa dwab`).
pub fn parse_compression(s: &str) -> Option<Compression> {
    Some(match s.to_ascii_lowercase().as_str() {
        "none" | "uncompressed" => Compression::Uncompressed,
        "rle" => Compression::RLE,
        "zips" | "zip1" => Compression::ZIP1,
        "zip" | "zip16" => Compression::ZIP16,
        "piz" => Compression::PIZ,
        "pxr24" => Compression::PXR24,
        "b44" => Compression::B44,
        "b44a" => Compression::B44A,
        "dwaa" => Compression::DWAA(None),
        "dwab" => Compression::DWAB(None),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::math::Vec2;

    #[test]
    fn rec709_chromaticities_give_rec709_weights() {
        let c = Chromaticities {
            red: Vec2(0.64, 0.33),
            green: Vec2(0.30, 0.60),
            blue: Vec2(0.15, 0.06),
            white: Vec2(0.3127, 0.3290),
        };
        let w = luminance_weights(Some(&c));
        for (a, b) in w.iter().zip([0.2126, 0.7152, 0.0722]) {
            assert!((a - b).abs() < 2e-4, "{w:?}");
        }
        assert_eq!(luminance_weights(None), [0.2126, 0.7152, 0.0722]);
    }
}
