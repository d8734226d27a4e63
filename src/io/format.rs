//! Which format a file is written in: chosen by the name's extension, or by
//! `--format` where the name does not say (standard output, a name without
//! an extension epfilt knows), never by accident.
//!
//! * `.exr` is OpenEXR; `.hdr`, `.pic` (and `.rgbe`) a Radiance picture;
//!   `.png` a picture for people (`preview`).
//! * `-` (standard output) follows the input's format, or `--format`.
//! * A name whose extension is another image format's (`.tif`, `.jpg`, ...)
//!   or a format the command does not write is refused with one line that
//!   lists what the command accepts; so is a `--format` that contradicts the
//!   extension.

use std::path::Path;

use crate::error::{Error, Result};

/// A file format epfilt reads or writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// OpenEXR.
    Exr,
    /// Radiance RGBE / XYZE picture.
    Rgbe,
    /// PNG (sRGB, 8 bits: pictures for people).
    Png,
    /// Portable float map (R, G, B floats: what `oidnDenoise` reads).
    Pfm,
}

/// Extensions of image formats epfilt does not write: a name ending in one
/// of them is never given another format's bytes, even with `--format`.
const FOREIGN: &[&str] = &[
    "tif", "tiff", "jpg", "jpeg", "jpe", "jp2", "jxl", "bmp", "gif", "webp", "tga", "dpx", "cin",
    "psd", "ppm", "pgm", "pbm", "pnm", "avif", "heic", "heif", "sgi", "rgb", "iff", "dds", "ktx",
    "svg", "pdf",
];

impl Format {
    /// Parse `--format`: `exr`, `hdr` (also `pic`, `rgbe`, `radiance`) or `png`.
    pub fn parse(s: &str) -> Result<Format> {
        match s.trim().to_ascii_lowercase().as_str() {
            "exr" | "openexr" => Ok(Format::Exr),
            "hdr" | "pic" | "rgbe" | "radiance" => Ok(Format::Rgbe),
            "png" => Ok(Format::Png),
            "pfm" => Ok(Format::Pfm),
            other => Err(Error::Config(format!(
                "--format {other:?}: exr, hdr, pfm or png"
            ))),
        }
    }

    /// The name `--format` takes.
    pub fn name(self) -> &'static str {
        match self {
            Format::Exr => "exr",
            Format::Rgbe => "hdr",
            Format::Png => "png",
            Format::Pfm => "pfm",
        }
    }

    /// The extensions that name it, the first the usual one.
    pub fn extensions(self) -> &'static [&'static str] {
        match self {
            Format::Exr => &["exr"],
            Format::Rgbe => &["hdr", "pic", "rgbe"],
            Format::Png => &["png"],
            Format::Pfm => &["pfm"],
        }
    }

    /// In words, for messages.
    pub fn describe(self) -> &'static str {
        match self {
            Format::Exr => "OpenEXR (.exr)",
            Format::Rgbe => "Radiance (.hdr, .pic)",
            Format::Png => "PNG (.png)",
            Format::Pfm => "PFM (.pfm)",
        }
    }

    /// The format a file's first bytes show: OpenEXR's magic number or a
    /// Radiance picture's `#?`; `None` for anything else.
    pub fn sniff(bytes: &[u8]) -> Option<Format> {
        if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
            Some(Format::Exr)
        } else if super::rgbe::is_rgbe(bytes) {
            Some(Format::Rgbe)
        } else if bytes.starts_with(b"\x89PNG") {
            Some(Format::Png)
        } else if super::pfm::is_pfm(bytes) {
            Some(Format::Pfm)
        } else {
            None
        }
    }
}

/// What a path's extension says: `Some(Ok(format))` for one epfilt writes,
/// `Some(Err(ext))` for another image format's, `None` when it says nothing
/// (no extension, or one that is not an image format's).
fn by_extension(path: &Path) -> Option<std::result::Result<Format, String>> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    for f in [Format::Exr, Format::Rgbe, Format::Png, Format::Pfm] {
        if f.extensions().contains(&ext.as_str()) {
            return Some(Ok(f));
        }
    }
    FOREIGN.contains(&ext.as_str()).then_some(Err(ext))
}

/// What `command` writes, in words: "OpenEXR (.exr) or Radiance (.hdr, .pic)".
fn accepted_text(accepted: &[Format]) -> String {
    let names: Vec<&str> = accepted.iter().map(|f| f.describe()).collect();
    match names.as_slice() {
        [] => String::new(),
        [one] => one.to_string(),
        [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
    }
}

fn format_flags(accepted: &[Format]) -> String {
    accepted
        .iter()
        .map(|f| f.name())
        .collect::<Vec<_>>()
        .join("|")
}

/// The format `command` writes `path` in. `explicit` is `--format`;
/// `follow` the input's format, which standard output takes when `--format`
/// is not given; `accepted` what the command can write. The path is checked
/// as an output first ([`super::Destination::resolve`]: a directory or a
/// device is refused as such, whatever its name).
pub fn output_format(
    path: &Path,
    explicit: Option<Format>,
    follow: Option<Format>,
    accepted: &[Format],
    command: &str,
) -> Result<Format> {
    let dest = super::Destination::resolve(path)?;
    let refuse = |why: String| Error::Output {
        path: path.into(),
        reason: why,
    };
    let writes = accepted_text(accepted);
    let flags = format_flags(accepted);
    let check = |f: Format, how: &str| {
        if accepted.contains(&f) {
            Ok(f)
        } else {
            Err(refuse(format!(
                "{command} writes {writes}, not {} ({how}): give the name one of those extensions, or --format {flags} for - or a name without an image extension",
                f.describe()
            )))
        }
    };
    // Nothing is written to /dev/null: any format the command writes.
    if dest == super::Destination::Null {
        if let Some(f) = explicit.or(follow).or(accepted.first().copied()) {
            return check(f, "--format");
        }
    }
    if path.as_os_str() == "-" {
        return match explicit.or(follow) {
            Some(f) => check(
                f,
                if explicit.is_some() {
                    "--format"
                } else {
                    "the input's format"
                },
            ),
            None => Err(refuse(format!(
                "standard output needs --format {flags}: {command} writes {writes}"
            ))),
        };
    }
    match (by_extension(path), explicit) {
        (Some(Ok(f)), None) => check(f, "by its extension"),
        (Some(Ok(f)), Some(e)) if f == e => check(f, "by its extension"),
        (Some(Ok(f)), Some(e)) => Err(refuse(format!(
            "the name says {} but --format says {}; {command} never writes one format under another's name",
            f.describe(),
            e.describe()
        ))),
        (Some(Err(ext)), _) => Err(refuse(format!(
            "{command} cannot write .{ext} files: it writes {writes}; give the name one of those extensions (or --format {flags} for a name without an image extension)"
        ))),
        (None, Some(e)) => check(e, "--format"),
        (None, None) => Err(refuse(format!(
            "{command} writes {writes}: give the name one of those extensions, or --format {flags}"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILTER: &[Format] = &[Format::Exr, Format::Rgbe];

    fn of(path: &str, explicit: Option<Format>, follow: Option<Format>) -> Result<Format> {
        output_format(Path::new(path), explicit, follow, FILTER, "filter")
    }

    #[test]
    fn the_extension_decides_and_format_fills_in_only_where_it_says_nothing() {
        assert_eq!(of("a.exr", None, None).unwrap(), Format::Exr);
        assert_eq!(of("a.EXR", None, None).unwrap(), Format::Exr);
        assert_eq!(of("a.hdr", None, None).unwrap(), Format::Rgbe);
        assert_eq!(of("a.pic", None, Some(Format::Exr)).unwrap(), Format::Rgbe);
        assert_eq!(of("a", Some(Format::Rgbe), None).unwrap(), Format::Rgbe);
        assert_eq!(of("a.tmp", Some(Format::Exr), None).unwrap(), Format::Exr);
        assert_eq!(of("-", None, Some(Format::Rgbe)).unwrap(), Format::Rgbe);
        assert_eq!(
            of("-", Some(Format::Exr), Some(Format::Rgbe)).unwrap(),
            Format::Exr
        );
        for (path, explicit) in [
            ("a.png", None),
            ("a.tif", None),
            ("a.tif", Some(Format::Exr)),
            ("a.jpg", None),
            ("a", None),
            ("a.exr", Some(Format::Rgbe)),
            ("-", None),
            ("-", Some(Format::Png)),
        ] {
            let e = of(path, explicit, None).unwrap_err().to_string();
            assert!(e.contains(".exr") && e.contains(".hdr"), "{path}: {e}");
        }
    }

    #[test]
    fn magic_bytes() {
        assert_eq!(
            Format::sniff(&[0x76, 0x2f, 0x31, 0x01, 2]),
            Some(Format::Exr)
        );
        assert_eq!(Format::sniff(b"#?RADIANCE\n"), Some(Format::Rgbe));
        assert_eq!(Format::sniff(b"\x89PNG\r\n"), Some(Format::Png));
        assert_eq!(Format::sniff(b"hello"), None);
        assert_eq!(Format::parse("HDR").unwrap(), Format::Rgbe);
        assert_eq!(Format::parse("pfm").unwrap(), Format::Pfm);
        assert_eq!(Format::sniff(b"PF\n2 2\n-1.0\n"), Some(Format::Pfm));
        assert!(Format::parse("tiff").is_err());
    }
}
