//! Portable float maps (PFM), the format Intel OIDN's `oidnDenoise` reads and
//! writes: a text header (`PF` colour or `Pf` grey, width and height, a
//! scale whose sign gives the byte order), then 32-bit floats, rows from the
//! bottom of the picture up, a pixel's channels together. A denoiser's
//! output goes straight into `restore` (or any command that reads), and
//! `--format pfm` (or a `.pfm` name) writes one for `oidnDenoise`
//! ([`PfmOutput`]: R, G, B, little-endian).

use std::path::{Path, PathBuf};

use exr::math::Vec2;
use exr::meta::attribute::{ChannelDescription, ChannelList, SampleType, Text};
use exr::meta::header::Header;
use exr::prelude::Compression;

use crate::error::{Error, Result};
use crate::pipeline::{Source, Strip};

/// A side longer than this is a damaged header, not a picture.
const MAX_SIDE: usize = 1 << 24;
/// A strip's decoded bytes at most, whatever the caller asks.
const STRIP_BYTES: usize = 64 << 20;
/// The header's four tokens and their separators fit in this many bytes.
const MAX_HEADER: usize = 256;

/// Whether `bytes` start as a PFM does: `PF` or `Pf` and a white space.
pub fn is_pfm(bytes: &[u8]) -> bool {
    matches!(bytes, [b'P', b'F' | b'f', c, ..] if c.is_ascii_whitespace())
}

/// What a map's header says.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PfmHeader {
    /// Width in pixels.
    pub w: usize,
    /// Height in pixels.
    pub h: usize,
    /// Channels per pixel: 3 (`PF`, R, G, B) or 1 (`Pf`, Y).
    pub channels: usize,
    /// Little-endian floats (a negative scale).
    pub little: bool,
    /// Byte offset of the first stored row (the picture's bottom one).
    pub data: usize,
}

fn invalid(path: &Path, reason: impl Into<String>) -> Error {
    Error::InvalidFloatMap {
        path: path.into(),
        reason: reason.into(),
    }
}

/// Parse the header of the map in `bytes`, and check that the file holds
/// every float it claims (before anything is allocated for them).
pub fn parse_header(path: &Path, bytes: &[u8]) -> Result<PfmHeader> {
    if !is_pfm(bytes) {
        return Err(invalid(path, "not a portable float map (no PF or Pf)"));
    }
    let channels = if bytes[1] == b'F' { 3 } else { 1 };
    // Three tokens after the magic, each after white space; the floats
    // start after the single white-space byte that ends the scale.
    let mut at = 2;
    let mut token = || -> Option<&[u8]> {
        while at < bytes.len().min(MAX_HEADER) && bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        let start = at;
        while at < bytes.len().min(MAX_HEADER) && !bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        (at > start && at < bytes.len()).then(|| &bytes[start..at])
    };
    let number = |t: Option<&[u8]>, what: &str| -> Result<String> {
        t.and_then(|t| std::str::from_utf8(t).ok())
            .map(str::to_string)
            .ok_or_else(|| invalid(path, format!("no {what} in the header")))
    };
    let (w, h, scale) = (
        number(token(), "width")?,
        number(token(), "height")?,
        number(token(), "scale")?,
    );
    let side = |s: &str, what: &str| match s.parse::<usize>() {
        Ok(v) if v > 0 && v <= MAX_SIDE => Ok(v),
        _ => Err(invalid(
            path,
            format!("the {what} {s:?} is not a side of 1 to {MAX_SIDE} pixels"),
        )),
    };
    let (w, h) = (side(&w, "width")?, side(&h, "height")?);
    let scale: f64 = match scale.parse() {
        Ok(s) if s != 0.0 && f64::is_finite(s) => s,
        _ => {
            return Err(invalid(
                path,
                format!("the scale {scale:?} is not a non-zero number"),
            ))
        }
    };
    let data = at + 1;
    let need = (w as u128) * (h as u128) * (channels as u128) * 4;
    let have = bytes.len().saturating_sub(data) as u128;
    if need > have {
        return Err(invalid(
            path,
            format!("{w}x{h} pixels of {channels} floats need {need} bytes, the file holds {have} (truncated)"),
        ));
    }
    Ok(PfmHeader {
        w,
        h,
        channels,
        little: scale < 0.0,
        data,
    })
}

impl PfmHeader {
    /// The channel names, in the map's order.
    pub fn names(&self) -> &'static [&'static str] {
        if self.channels == 3 {
            &["R", "G", "B"]
        } else {
            &["Y"]
        }
    }

    /// The map described as an OpenEXR header (one part of f32 channels, R,
    /// G, B or Y, Rec. 709 primaries), what the rest of epfilt reads.
    pub(crate) fn exr_header(&self) -> Header {
        float_header((self.w, self.h), self.names())
    }
}

/// A one-part header of f32 scan lines describing a picture that is not an
/// EXR (`w x h`, channels `names` in any order, listed sorted as OpenEXR
/// has them), what the rest of epfilt reads.
pub(crate) fn float_header((w, h): (usize, usize), names: &[&str]) -> Header {
    let mut sorted = names.to_vec();
    sorted.sort_unstable();
    let list: exr::prelude::SmallVec<[ChannelDescription; 5]> = sorted
        .iter()
        .map(|n| ChannelDescription::new(Text::from(*n), SampleType::F32, false))
        .collect();
    let mut header = Header::new(Text::from(""), Vec2(w, h), list).with_encoding(
        Compression::ZIP16,
        exr::meta::BlockDescription::ScanLines,
        exr::meta::attribute::LineOrder::Increasing,
    );
    header.channels = ChannelList::new(header.channels.list.clone());
    header.own_attributes.layer_name = None;
    header
}

/// A [`Source`] of the map's rows, top first: `[row][channel][x]`.
pub struct PfmSource<'a> {
    path: PathBuf,
    bytes: &'a [u8],
    header: PfmHeader,
    y: usize,
}

impl<'a> PfmSource<'a> {
    /// Rows of the map in `bytes` (its header already parsed and checked
    /// against the file's length).
    pub fn new(path: &Path, bytes: &'a [u8], header: PfmHeader) -> Self {
        PfmSource {
            path: path.into(),
            bytes,
            header,
            y: 0,
        }
    }
}

impl Source for PfmSource<'_> {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        let PfmHeader {
            w,
            h,
            channels: nch,
            little,
            data: start,
        } = self.header;
        if self.y >= h {
            return Ok(None);
        }
        let row_bytes = w * nch * 4;
        let rows = (max_rows.max(1))
            .min((STRIP_BYTES / row_bytes).max(1))
            .min(h - self.y);
        let mut data = vec![0.0f32; rows * nch * w];
        for r in 0..rows {
            // The file holds the bottom row first.
            let at = start + (h - 1 - (self.y + r)) * row_bytes;
            let stored = self
                .bytes
                .get(at..at + row_bytes)
                .ok_or_else(|| invalid(&self.path, "the file is shorter than its header says"))?;
            for (x, px) in stored.chunks_exact(4 * nch).enumerate() {
                for (c, v) in px.chunks_exact(4).enumerate() {
                    let b = [v[0], v[1], v[2], v[3]];
                    data[(r * nch + c) * w + x] = if little {
                        f32::from_le_bytes(b)
                    } else {
                        f32::from_be_bytes(b)
                    };
                }
            }
        }
        let strip = Strip {
            y0: self.y,
            rows,
            data,
        };
        self.y += rows;
        Ok(Some(strip))
    }
}

/// A PFM being written (`PF`, little-endian): rows arrive top first and
/// are written where the file keeps them, bottom first, into the staged
/// file (a pixel's three floats together), so nothing is held.
pub struct PfmOutput {
    dest: PathBuf,
    staged: Option<super::Staged>,
    w: usize,
    h: usize,
    header_len: u64,
    rows_done: usize,
    line: Vec<u8>,
    /// Sum per channel of the stored values (the ledger's "on disk").
    sums: crate::pipeline::ledger::StoredSums,
}

impl PfmOutput {
    /// Start a `w` x `h` map at `dest` (checked as every output is).
    pub fn create(dest: &Path, w: usize, h: usize) -> Result<Self> {
        let staged = super::Staged::new(dest, ".pfm.tmp")?;
        let header = format!("PF\n{w} {h}\n-1.0\n");
        let len = header.len() as u64 + (w as u64 * h as u64 * 12);
        let file = staged.file();
        std::io::Write::write_all(&mut &*file, header.as_bytes())
            .and_then(|()| file.set_len(len))
            .map_err(|e| Error::io(dest, e))?;
        Ok(PfmOutput {
            dest: dest.into(),
            staged: Some(staged),
            w,
            h,
            header_len: header.len() as u64,
            rows_done: 0,
            line: Vec::with_capacity(12 * w),
            sums: Default::default(),
        })
    }

    /// `--edge pad`: weigh each pixel of the sums by its coverage.
    pub fn set_coverage(&mut self, coverage: crate::pipeline::edge::Coverage) {
        self.sums.set_coverage(coverage);
    }

    /// Per channel, the sum of the values the file holds.
    pub fn decoded_sums(&self) -> Vec<f64> {
        self.sums.values()
    }

    /// Put the finished map in place.
    pub fn commit(mut self) -> Result<()> {
        let staged = self.staged.take().ok_or(Error::Interrupted)?;
        staged.file().sync_all().ok();
        staged.commit()
    }
}

impl crate::pipeline::Sink for PfmOutput {
    fn write_rows(&mut self, _y0: usize, rows: usize, data: &[f32]) -> Result<()> {
        let w = self.w;
        if data.len() != rows * 3 * w {
            return Err(Error::Config(format!(
                "{}: a PFM holds three channels, not {}",
                self.dest.display(),
                data.len() / (rows * w).max(1)
            )));
        }
        let file = self.staged.as_ref().ok_or(Error::Interrupted)?.file();
        for r in 0..rows {
            let y = self.rows_done + r;
            let row = &data[r * 3 * w..][..3 * w];
            self.line.clear();
            for x in 0..w {
                let rgb = [0, 1, 2].map(|c| row[c * w + x]);
                self.sums.add((x, y), rgb.map(f64::from));
                for v in rgb {
                    self.line.extend_from_slice(&v.to_le_bytes());
                }
            }
            let at = self.header_len + (self.h - 1 - y) as u64 * 12 * w as u64;
            write_at(file, &self.line, at).map_err(|e| Error::io(&self.dest, e))?;
        }
        self.rows_done += rows;
        Ok(())
    }

    fn finish(&mut self) -> Result<()> {
        if self.rows_done != self.h {
            return Err(Error::Internal(format!(
                "{}: output incomplete ({} of {} rows)",
                self.dest.display(),
                self.rows_done,
                self.h
            )));
        }
        Ok(())
    }
}

/// Write `bytes` at byte `at` of `file`.
fn write_at(file: &std::fs::File, bytes: &[u8], at: u64) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        std::os::unix::fs::FileExt::write_all_at(file, bytes, at)
    }
    #[cfg(not(unix))]
    {
        use std::io::{Seek, SeekFrom, Write};
        let mut f = file;
        f.seek(SeekFrom::Start(at))?;
        f.write_all(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A map of `w x h` pixels of `nch` channels, value `f(x, y, c)` with
    /// `y` from the top, stored bottom row first.
    fn map(magic: &str, (w, h, nch): (usize, usize, usize), little: bool) -> Vec<u8> {
        let scale = if little { "-1.0" } else { "1.0" };
        let mut b = format!("{magic}\n{w} {h}\n{scale}\n").into_bytes();
        for y in (0..h).rev() {
            for x in 0..w {
                for c in 0..nch {
                    let v = value(x, y, c);
                    b.extend(if little {
                        v.to_le_bytes()
                    } else {
                        v.to_be_bytes()
                    });
                }
            }
        }
        b
    }

    fn value(x: usize, y: usize, c: usize) -> f32 {
        (x * 100 + y * 10 + c) as f32 + 0.25
    }

    fn read(bytes: &[u8], max_rows: usize) -> (PfmHeader, Vec<f32>) {
        let p = Path::new("t.pfm");
        let header = parse_header(p, bytes).unwrap();
        let mut src = PfmSource::new(p, bytes, header.clone());
        let mut all = Vec::new();
        let mut y = 0;
        while let Some(s) = src.next_strip(max_rows).unwrap() {
            assert_eq!(s.y0, y);
            y += s.rows;
            all.extend(s.data);
        }
        assert_eq!(y, header.h);
        (header, all)
    }

    #[test]
    fn rows_come_top_first_in_either_byte_order() {
        for little in [true, false] {
            for rows in [1, 2, 7] {
                let (h, got) = read(&map("PF", (5, 4, 3), little), rows);
                assert_eq!((h.w, h.h, h.channels, h.little), (5, 4, 3, little));
                let want: Vec<f32> = (0..4)
                    .flat_map(|y| (0..3).flat_map(move |c| (0..5).map(move |x| value(x, y, c))))
                    .collect();
                assert_eq!(got, want, "little {little}, rows {rows}");
            }
        }
        let (h, got) = read(&map("Pf", (3, 2, 1), true), 8);
        assert_eq!(h.names(), ["Y"]);
        assert_eq!(got[..3], [value(0, 0, 0), value(1, 0, 0), value(2, 0, 0)]);
    }

    #[test]
    fn damaged_headers_and_short_files_are_refused() {
        let p = Path::new("t.pfm");
        let good = map("PF", (4, 3, 3), true);
        assert!(parse_header(p, &good).is_ok());
        let short = &good[..good.len() - 1];
        let e = parse_header(p, short).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        for bad in [
            &b"PF\n0 3\n-1\n"[..],
            b"PF\n4 x\n-1\n",
            b"PF\n4 3\n0\n",
            b"PF\n4 3\nnan\n",
            b"PF\n99999999999 99999999999\n-1\n",
            b"PF\n4",
            b"P6\n4 3\n255\n",
        ] {
            assert!(
                parse_header(p, bad).is_err(),
                "{:?}",
                String::from_utf8_lossy(bad)
            );
        }
        // A claim far beyond the file is refused before anything is made.
        let e = parse_header(p, b"PF\n16777216 16777216\n-1\n\0\0\0\0")
            .unwrap_err()
            .to_string();
        assert!(e.contains("truncated"), "{e}");
    }
}
