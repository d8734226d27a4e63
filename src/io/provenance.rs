//! What an output records about how it was made, and the checks that read it
//! back: the **fingerprint** of its input and settings (every output), the
//! **band label** and the **band ledger** (`filter --band`), so that `merge`
//! refuses bands of different inputs or settings and `--skip-existing` takes
//! a file as done only when it is a complete output of this very input and
//! these settings.
//!
//! * The input's fingerprint is a 128-bit xxh3 of the file's length, its
//!   headers and offset tables (for compressed files every block's size, so
//!   almost any change of content shows there) and 64 spans of 4 KiB spread
//!   evenly over the pixel data (an uncompressed file's offsets do not
//!   change with its content). It reads a few hundred KiB whatever the
//!   image, so a band, which reads only its rows, can afford it.
//! * The settings' fingerprint is a 64-bit xxh3 of every setting that
//!   decides the output's bytes (not the threads, tiles or strips, which do
//!   not) and epfilt's version.
//!
//! In an EXR they are text attributes ([`FINGERPRINT`], [`BAND`],
//! [`BAND_LEDGER`]); in a Radiance picture, header lines `NAME=value` of the
//! same names.

use std::path::Path;

use serde::Serialize;

use super::mapped::MappedFile;
use super::reader::InputFile;
use crate::error::Error;

/// The attribute (or Radiance header variable) holding the fingerprint:
/// `input=<32 hex> settings=<16 hex>`.
pub const FINGERPRINT: &str = "epfiltFingerprint";
/// The attribute of a band file: `K/N rows A-B of H S=s`.
pub const BAND: &str = "epfiltBand";
/// The attribute of a band file holding, per channel, the energy of the
/// input rows it owns and of the output rows it holds (times S²), as the bits
/// of f64 in hexadecimal: `NAME:IN:OUT;` per channel.
pub const BAND_LEDGER: &str = "epfiltBandLedger";

/// Spans of the pixel data the input's fingerprint reads.
const SAMPLED_SPANS: usize = 64;
/// Bytes of each span.
const SPAN_BYTES: usize = 4096;

/// What identifies a run: its input and its settings.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Fingerprint {
    /// The input's (32 hex digits).
    pub input: String,
    /// The settings' (16 hex digits).
    pub settings: String,
}

impl Fingerprint {
    /// As recorded: `input=... settings=...`.
    pub fn text(&self) -> String {
        format!("input={} settings={}", self.input, self.settings)
    }

    /// Read [`Fingerprint::text`].
    pub fn parse(text: &str) -> Option<Self> {
        let mut input = None;
        let mut settings = None;
        for item in text.split_whitespace() {
            match item.split_once('=') {
                Some(("input", v)) => input = Some(v.to_string()),
                Some(("settings", v)) => settings = Some(v.to_string()),
                _ => {}
            }
        }
        Some(Fingerprint {
            input: input?,
            settings: settings?,
        })
    }

    /// `input`'s fingerprint with these settings (the text that decides the
    /// output, see [`settings_fingerprint`]).
    pub fn of(input: &InputFile, settings: &str) -> Self {
        Fingerprint {
            input: input_fingerprint(input),
            settings: settings_fingerprint(settings),
        }
    }
}

/// The fingerprint of the settings text.
pub fn settings_fingerprint(settings: &str) -> String {
    format!("{:016x}", xxhash_rust::xxh3::xxh3_64(settings.as_bytes()))
}

/// The fingerprint of an input file: its length, its headers and offset
/// tables (a picture's header), and spans sampled through its pixel data. A
/// picture whose header does not parse is hashed from its first MiB.
pub fn input_fingerprint(input: &InputFile) -> String {
    let bytes = input.bytes();
    let data = input.data_start().unwrap_or(1 << 20).min(bytes.len());
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    h.update(&(bytes.len() as u64).to_le_bytes());
    h.update(&bytes[..data]);
    let rest = bytes.len() - data;
    for k in 0..SAMPLED_SPANS {
        let at = data + rest / SAMPLED_SPANS * k;
        h.update(&bytes[at..(at + SPAN_BYTES).min(bytes.len())]);
    }
    // Each span read maps the page cache's whole folio around it (up to
    // megabytes), held until the reader passed each span, and outside what
    // `--max-memory` counts (docs/bench/memory-s1.md).
    input.release(data, bytes.len());
    format!("{:032x}", h.digest128())
}

/// What an existing output says of itself.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Recorded {
    /// Its fingerprint, if it has one (not an epfilt output otherwise).
    pub fingerprint: Option<Fingerprint>,
    /// Its band label, if it is a band file.
    pub band: Option<String>,
}

/// Read what `path` records, after checking that it is whole: every block
/// an EXR's offset tables name lies inside the file, each chunk's leader
/// fits and claims no more bytes than the file has; a Radiance picture
/// decodes to every scanline its resolution line says. `Err` says why the
/// file is not a complete output.
pub fn recorded(path: &Path) -> std::result::Result<Recorded, String> {
    let map = MappedFile::open(path).map_err(|e| match e {
        Error::InvalidFile { reason, .. } => reason,
        e => crate::error::one_line(&e),
    })?;
    let bytes = map.bytes();
    if super::rgbe::is_rgbe(bytes) {
        let header = super::rgbe::parse_header(path, bytes).map_err(|e| one_line(&e))?;
        let input = super::ExrInput::open(path, None).map_err(|e| one_line(&e))?;
        let mut src = input.source();
        let mut rows = 0;
        while let Some(strip) =
            crate::pipeline::Source::next_strip(&mut src, 256).map_err(|e| one_line(&e))?
        {
            rows += strip.rows;
        }
        if rows != header.h {
            return Err(format!("{rows} of its {} scanlines", header.h));
        }
        let get = |name: &str| {
            header
                .epfilt
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, v)| v.clone())
        };
        return Ok(Recorded {
            fingerprint: get(FINGERPRINT).and_then(|t| Fingerprint::parse(&t)),
            band: get(BAND),
        });
    }
    let (meta, tables) = super::reader::check_chunks(path, bytes).map_err(|e| one_line(&e))?;
    let _ = tables;
    let text = |name: &str| super::reader::text_attribute(&meta.headers[0], name);
    Ok(Recorded {
        fingerprint: text(FINGERPRINT).and_then(|t| Fingerprint::parse(&t)),
        band: text(BAND),
    })
}

fn one_line(e: &Error) -> String {
    crate::error::one_line(e)
}

/// The method of epfilt's `filter` that made `input`, read from the
/// settings attribute it writes (the `software` attribute of files
/// written before it had one): `None` for any other file, and for a
/// Radiance picture (whose header lines are not read).
pub fn filtered_by(input: &super::ExrInput) -> Option<String> {
    method_of(&settings_text(input.header())?)
}

/// epfilt's settings text in `header` (`epfilt VERSION (settings)`), where
/// it wrote one.
pub fn settings_text(header: &exr::meta::header::Header) -> Option<String> {
    let own = &header.own_attributes;
    let key = exr::meta::attribute::Text::from(super::writer::SETTINGS_ATTRIBUTE);
    match own.other.get(&key) {
        Some(exr::meta::attribute::AttributeValue::Text(t)) => Some(t.to_string()),
        _ => own.software_name.as_ref().map(|s| s.to_string()),
    }
}

/// The `method=` of epfilt's software text, `epfilt VERSION (settings)`.
fn method_of(software: &str) -> Option<String> {
    let settings = software
        .strip_prefix("epfilt ")?
        .split_once(" (")?
        .1
        .strip_suffix(')')?;
    settings
        .split_whitespace()
        .find_map(|kv| kv.strip_prefix("method="))
        .map(str::to_string)
}

/// The text of [`BAND_LEDGER`] (zeros where no sums are given yet: the
/// header is written with it and filled in, same length, at the end).
pub fn band_ledger_text(names: &[String], energy_in: &[f64], energy_out: &[f64]) -> String {
    names
        .iter()
        .enumerate()
        .map(|(c, n)| {
            let i = energy_in.get(c).copied().unwrap_or(0.0);
            let o = energy_out.get(c).copied().unwrap_or(0.0);
            format!("{n}:{:016x}:{:016x};", i.to_bits(), o.to_bits())
        })
        .collect()
}

/// Parse [`band_ledger_text`]: (name, input energy, output energy).
pub fn parse_band_ledger(text: &str) -> Option<Vec<(String, f64, f64)>> {
    text.split_terminator(';')
        .map(|item| {
            let mut parts = item.rsplitn(3, ':');
            let o = u64::from_str_radix(parts.next()?, 16).ok()?;
            let i = u64::from_str_radix(parts.next()?, 16).ok()?;
            let n = parts.next()?;
            Some((n.to_string(), f64::from_bits(i), f64::from_bits(o)))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_method_comes_from_epfilts_own_software_text_only() {
        let text = |m: &str| format!("epfilt 0.1.0 (method={m} supersample=1 tolerance=0.08)");
        assert_eq!(method_of(&text("ep-gauss")).as_deref(), Some("ep-gauss"));
        assert_eq!(method_of(&text("ep-box")).as_deref(), Some("ep-box"));
        // restore's own output, another program's, and a torn text.
        assert_eq!(
            method_of("epfilt 0.1.0 (restore scale=32 keep_gain=16)"),
            None
        );
        assert_eq!(method_of("Blender 4.2 (method=ep-gauss)"), None);
        assert_eq!(method_of("epfilt 0.1.0 (method=ep-gauss"), None);
        assert_eq!(method_of("epfilt 0.1.0"), None);
    }

    #[test]
    fn fingerprints_round_trip_and_tell_inputs_apart() {
        let f = Fingerprint {
            input: "0123456789abcdef0123456789abcdef".into(),
            settings: "fedcba9876543210".into(),
        };
        assert_eq!(Fingerprint::parse(&f.text()), Some(f));
        assert_eq!(Fingerprint::parse("input=1"), None);
        assert_ne!(settings_fingerprint("a"), settings_fingerprint("b"));
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.hdr"), dir.path().join("b.hdr"));
        // Same header, same length, one byte of pixel data apart.
        let mut bytes = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 2\n".to_vec();
        bytes.extend([128, 64, 32, 129, 128, 64, 32, 129]);
        std::fs::write(&a, &bytes).unwrap();
        *bytes.last_mut().unwrap() = 130;
        std::fs::write(&b, &bytes).unwrap();
        let print = |p: &Path| input_fingerprint(&InputFile::open(p).unwrap());
        assert_ne!(print(&a), print(&b));
        assert_eq!(print(&a), print(&a));
    }

    /// The resident kilobytes of the mapping of `path` in this process.
    #[cfg(target_os = "linux")]
    fn mapped_kb(path: &Path) -> Option<u64> {
        let smaps = std::fs::read_to_string("/proc/self/smaps").ok()?;
        let name = path.to_str()?;
        let mut lines = smaps.lines().skip_while(|l| !l.ends_with(name));
        lines.next()?;
        let rss = lines.find(|l| l.starts_with("Rss:"))?;
        rss.split_whitespace().nth(1)?.parse().ok()
    }

    #[test]
    #[cfg(target_os = "linux")]
    fn a_fingerprint_leaves_no_pixel_pages_mapped() {
        // The page before the pixel data holds the header.
        const HEADER_KB: u64 = 4;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.hdr");
        let mut bytes = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1024 +X 2048\n".to_vec();
        bytes.resize(8 << 20, 7);
        std::fs::write(&path, &bytes).unwrap();
        let input = InputFile::open(&path).unwrap();
        let _ = input_fingerprint(&input);
        let kb = mapped_kb(&path).expect("the input's mapping in smaps");
        // Before the release, the 64 spans read kept at least a page each.
        assert!(kb <= HEADER_KB, "{kb} KB of the input still mapped");
    }

    #[test]
    fn band_ledgers_round_trip() {
        let names = vec!["R".to_string(), "odd:name".to_string()];
        let text = band_ledger_text(&names, &[1.5, -2.0], &[3.0, 4.25]);
        assert_eq!(
            parse_band_ledger(&text).unwrap(),
            vec![("R".into(), 1.5, 3.0), ("odd:name".into(), -2.0, 4.25)]
        );
    }
}
