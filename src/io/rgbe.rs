//! Radiance RGBE / XYZE pictures (`.hdr`, `.pic`), read and written one
//! scanline at a time.
//!
//! A picture is a text header (`#?RADIANCE`, variable lines such as
//! `FORMAT=32-bit_rle_rgbe`, `EXPOSURE=`, `VIEW=`, `PRIMARIES=`, comments and
//! the commands that made it, then an empty line), a resolution line
//! (`-Y H +X W`, top row first) and H scanlines of W pixels of four bytes: a
//! shared exponent and three mantissas. Scanlines are flat, old-style
//! run-length encoded (`1 1 1 n` repeats the previous pixel), or new-style
//! (`2 2 W/256 W%256`, then each component run-length encoded on its own);
//! every kind is read, new-style is written (flat where it cannot be, below 8
//! or above 32767 pixels wide), as Radiance's `fwritecolrs` does.
//!
//! Values are true radiance on read: each `EXPOSURE=` line (they multiply)
//! and `COLORCORR=` is divided out, so a picture that `pfilt` scaled filters
//! like the original. Written pictures carry no `EXPOSURE=` (it is 1), keep
//! the other header lines, and add `SOFTWARE=` saying how they were made.
//! RGBE keeps 8 bits of mantissa per channel (about 1% of the pixel's largest
//! channel): the energy on disk is what the encoded bytes decode to, and the
//! writer sums exactly that for the ledger.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use exr::math::Vec2;
use exr::meta::attribute::Chromaticities;
use exr::meta::header::Header;

use crate::error::{Error, Result};
use crate::pipeline::{Precision, Sink, Source, Strip};

/// The longest header read before the resolution line: a file without an
/// empty line in its first 1 MiB is not a picture.
const MAX_HEADER: usize = 1 << 20;
/// The widest and tallest picture accepted (a resolution line can claim any
/// number; memory is one scanline, so this only bounds nonsense).
const MAX_SIDE: usize = 1 << 24;
/// The most bytes of f32 rows one strip holds.
const STRIP_BYTES: usize = 64 << 20;

/// Whether `bytes` begin as a Radiance picture does (`#?`).
pub fn is_rgbe(bytes: &[u8]) -> bool {
    bytes.starts_with(b"#?")
}

/// What a picture's header says.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbeHeader {
    /// Width in pixels.
    pub w: usize,
    /// Height in pixels.
    pub h: usize,
    /// CIE XYZ (`32-bit_rle_xyze`) rather than RGB primaries.
    pub xyze: bool,
    /// Per channel: the factor a stored value was multiplied by (the product
    /// of `EXPOSURE=` lines times `COLORCORR=`); reading divides by it.
    pub scale: [f64; 3],
    /// `PRIMARIES= rx ry gx gy bx by wx wy`, when given.
    pub primaries: Option<[f64; 8]>,
    /// The header lines kept on output (all but the first, `FORMAT=`,
    /// `EXPOSURE=`, `COLORCORR=`, `SOFTWARE=` and epfilt's own).
    pub lines: Vec<String>,
    /// epfilt's own variables (`epfiltFingerprint=`, `epfiltBand=`...): what
    /// a picture epfilt wrote records of how it was made
    /// ([`super::provenance`]); not carried into an output.
    pub epfilt: Vec<(String, String)>,
    /// Byte offset of the first scanline.
    pub data: usize,
}

impl RgbeHeader {
    /// The picture described as an OpenEXR header (one part of three f32
    /// channels, R, G, B or X, Y, Z, with its primaries), what the rest of
    /// epfilt reads; with the channels in the picture's order and in the
    /// header's (sorted) order.
    pub(crate) fn exr_header(&self) -> (Header, [&'static str; 3], [&'static str; 3]) {
        let names: [&'static str; 3] = if self.xyze {
            ["X", "Y", "Z"]
        } else {
            ["R", "G", "B"]
        };
        let mut sorted = names;
        sorted.sort_unstable();
        let mut header = super::pfm::float_header((self.w, self.h), &names);
        if let Some(p) = self.primaries {
            let v = |i: usize| Vec2(p[i] as f32, p[i + 1] as f32);
            header.shared_attributes.chromaticities = Some(Chromaticities {
                red: v(0),
                green: v(2),
                blue: v(4),
                white: v(6),
            });
        }
        (header, names, sorted)
    }
}

fn invalid(path: &Path, reason: impl Into<String>) -> Error {
    Error::InvalidPicture {
        path: path.into(),
        reason: reason.into(),
    }
}

/// Parse the header and resolution line of the picture in `bytes`.
pub fn parse_header(path: &Path, bytes: &[u8]) -> Result<RgbeHeader> {
    if !is_rgbe(bytes) {
        return Err(invalid(path, "not a Radiance picture (no #? line)"));
    }
    let head = &bytes[..bytes.len().min(MAX_HEADER)];
    // The header ends at the first empty line.
    let end = head
        .windows(2)
        .position(|w| w == b"\n\n")
        .ok_or_else(|| invalid(path, "Radiance header without an end (no empty line)"))?;
    let text = String::from_utf8_lossy(&head[..end]);
    let mut xyze = false;
    let mut scale = [1.0f64; 3];
    let mut primaries = None;
    let mut lines = Vec::new();
    let mut epfilt = Vec::new();
    for line in text.lines().skip(1) {
        let num = |s: &str| -> Result<Vec<f64>> {
            s.split_whitespace()
                .map(|t| {
                    t.parse::<f64>().map_err(|_| {
                        invalid(path, format!("header line {line:?}: {t:?} is not a number"))
                    })
                })
                .collect()
        };
        if let Some(f) = line.strip_prefix("FORMAT=") {
            match f.trim() {
                "32-bit_rle_rgbe" => xyze = false,
                "32-bit_rle_xyze" => xyze = true,
                other => {
                    return Err(Error::Unsupported {
                        path: path.into(),
                        reason: format!("Radiance format {other:?} (epfilt reads 32-bit_rle_rgbe and 32-bit_rle_xyze)"),
                    })
                }
            }
        } else if let Some(e) = line.strip_prefix("EXPOSURE=") {
            let v = num(e)?;
            let e = *v
                .first()
                .ok_or_else(|| invalid(path, "EXPOSURE= without a value"))?;
            if !(e.is_finite() && e > 0.0) {
                return Err(invalid(
                    path,
                    format!("EXPOSURE={e} is not a positive number"),
                ));
            }
            scale.iter_mut().for_each(|s| *s *= e);
        } else if let Some(c) = line.strip_prefix("COLORCORR=") {
            let v = num(c)?;
            if v.len() != 3 || v.iter().any(|c| !(c.is_finite() && *c > 0.0)) {
                return Err(invalid(
                    path,
                    format!("{line:?}: three positive numbers expected"),
                ));
            }
            for k in 0..3 {
                scale[k] *= v[k];
            }
        } else if let Some((name, value)) = line
            .split_once('=')
            .filter(|(n, _)| n.starts_with("epfilt") && !n.contains(' '))
        {
            epfilt.push((name.to_string(), value.to_string()));
        } else {
            if let Some(p) = line.strip_prefix("PRIMARIES=") {
                let v = num(p)?;
                if v.len() == 8 {
                    primaries = Some([v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7]]);
                }
            }
            lines.push(line.to_string());
        }
    }
    let (w, h, nl) = resolution(path, &bytes[end + 2..])?;
    Ok(RgbeHeader {
        w,
        h,
        xyze,
        scale,
        primaries,
        lines,
        epfilt,
        data: end + 2 + nl + 1,
    })
}

/// The resolution line at the start of `rest` (after the header): width,
/// height and the line's length.
fn resolution(path: &Path, rest: &[u8]) -> Result<(usize, usize, usize)> {
    let nl = rest
        .iter()
        .take(256)
        .position(|&b| b == b'\n')
        .ok_or_else(|| invalid(path, "no resolution line after the header"))?;
    let res = String::from_utf8_lossy(&rest[..nl]);
    let t: Vec<&str> = res.split_whitespace().collect();
    let (h, w) = match t.as_slice() {
        ["-Y", h, "+X", w] => (h.parse::<usize>().ok(), w.parse::<usize>().ok()),
        [a, _, b, _] if a.len() == 2 && b.len() == 2 => {
            return Err(Error::Unsupported {
                path: path.into(),
                reason: format!(
                    "Radiance orientation {res:?} (epfilt reads the standard -Y H +X W; `pflip` or `protate` make it)"
                ),
            })
        }
        _ => (None, None),
    };
    let (Some(h), Some(w)) = (h, w) else {
        return Err(invalid(path, format!("bad resolution line {res:?}")));
    };
    if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
        return Err(invalid(
            path,
            format!("picture size {w}x{h} is empty or too large"),
        ));
    }
    Ok((w, h, nl))
}

/// The value of one channel of an RGBE pixel, as Radiance's `colr_color`:
/// `(m + 0.5) 2^(e - 136)`, 0 when the exponent is 0.
fn channel(m: u8, e: u8) -> f32 {
    if e == 0 {
        0.0
    } else {
        ((m as f64 + 0.5) * (2f64).powi(e as i32 - 136)) as f32
    }
}

/// Decode the scanline at `bytes[*at..]` into `out` (`w` pixels of 4 bytes),
/// advancing `at`. `prev` is the previous scanline's last pixel for old-style
/// runs that continue across lines (Radiance allows it).
fn read_scanline(
    path: &Path,
    bytes: &[u8],
    at: &mut usize,
    out: &mut [[u8; 4]],
    y: usize,
) -> Result<()> {
    let w = out.len();
    let short = || invalid(path, format!("picture ends early, in scanline {y}"));
    let get = |at: usize, n: usize| bytes.get(at..at + n).ok_or_else(short);
    let first = get(*at, 4)?;
    if (8..=0x7fff).contains(&w) && first[0] == 2 && first[1] == 2 && first[2] & 0x80 == 0 {
        let n = ((first[2] as usize) << 8) | first[3] as usize;
        if n != w {
            return Err(invalid(
                path,
                format!("scanline {y} claims {n} pixels, the picture is {w} wide"),
            ));
        }
        *at += 4;
        for c in 0..4 {
            let mut x = 0;
            while x < w {
                let code = *bytes.get(*at).ok_or_else(short)? as usize;
                *at += 1;
                if code > 128 {
                    let run = code - 128;
                    if x + run > w {
                        return Err(invalid(path, format!("run past the end of scanline {y}")));
                    }
                    let v = *bytes.get(*at).ok_or_else(short)?;
                    *at += 1;
                    out[x..x + run].iter_mut().for_each(|p| p[c] = v);
                    x += run;
                } else {
                    if code == 0 || x + code > w {
                        return Err(invalid(
                            path,
                            format!("bad literal of {code} in scanline {y}"),
                        ));
                    }
                    let lit = get(*at, code)?;
                    for (p, &v) in out[x..x + code].iter_mut().zip(lit) {
                        p[c] = v;
                    }
                    *at += code;
                    x += code;
                }
            }
        }
        return Ok(());
    }
    // Flat or old-style run-length encoded.
    let mut x = 0;
    let mut shift = 0u32;
    while x < w {
        let p = get(*at, 4)?;
        *at += 4;
        if p[0] == 1 && p[1] == 1 && p[2] == 1 {
            if x == 0 || shift > 16 {
                return Err(invalid(path, format!("bad repeat code in scanline {y}")));
            }
            let n = (p[3] as usize) << shift;
            if x + n > w {
                return Err(invalid(path, format!("run past the end of scanline {y}")));
            }
            let last = out[x - 1];
            out[x..x + n].iter_mut().for_each(|q| *q = last);
            x += n;
            shift += 8;
        } else {
            out[x] = [p[0], p[1], p[2], p[3]];
            x += 1;
            shift = 0;
        }
    }
    Ok(())
}

/// A [`Source`] of the picture's rows: three channels (R, G, B or X, Y, Z),
/// `[row][channel][x]`, in true radiance.
pub struct RgbeSource<'a> {
    path: PathBuf,
    bytes: &'a [u8],
    header: RgbeHeader,
    at: usize,
    y: usize,
    pixels: Vec<[u8; 4]>,
}

impl<'a> RgbeSource<'a> {
    /// Rows of the picture in `bytes` (its header already parsed).
    pub fn new(path: &Path, bytes: &'a [u8], header: RgbeHeader) -> Self {
        RgbeSource {
            path: path.into(),
            bytes,
            at: header.data,
            y: 0,
            pixels: vec![[0; 4]; header.w],
            header,
        }
    }
}

impl Source for RgbeSource<'_> {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        let (w, h) = (self.header.w, self.header.h);
        if self.y >= h {
            return Ok(None);
        }
        // A damaged header may claim a huge width over a few bytes: strips
        // stay within STRIP_BYTES (one row at least, at most 192 MiB at
        // MAX_SIDE), whatever the caller asks.
        let by_bytes = (STRIP_BYTES / (12 * w)).max(1);
        let rows = max_rows.max(1).min(by_bytes).min(h - self.y);
        let mut data = vec![0.0f32; rows * 3 * w];
        let inv = self.header.scale.map(|s| 1.0 / s);
        for r in 0..rows {
            read_scanline(
                &self.path,
                self.bytes,
                &mut self.at,
                &mut self.pixels,
                self.y + r,
            )?;
            for c in 0..3 {
                let row = &mut data[(r * 3 + c) * w..][..w];
                for (v, p) in row.iter_mut().zip(&self.pixels) {
                    let x = channel(p[c], p[3]);
                    *v = if inv[c] == 1.0 {
                        x
                    } else {
                        (x as f64 * inv[c]) as f32
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

/// Encode one pixel as Radiance's `setcolr`: the largest channel's exponent
/// shared, each mantissa `v 256 / 2^e` truncated. Negative and non-finite
/// channels are stored as 0; a value beyond ~1.7e38 is an error.
pub fn encode(rgb: [f32; 3]) -> Option<[u8; 4]> {
    let v = rgb.map(|x| {
        if x.is_finite() && x > 0.0 {
            x as f64
        } else {
            0.0
        }
    });
    let d = v[0].max(v[1]).max(v[2]);
    if d <= 1e-32 {
        return Some([0; 4]);
    }
    // d = m 2^e with m in [0.5, 1).
    let e = d.log2().floor() as i32 + 1;
    let mut e = e;
    let mut m = d / (2f64).powi(e);
    if m >= 1.0 {
        m /= 2.0;
        e += 1;
    } else if m < 0.5 {
        m *= 2.0;
        e -= 1;
    }
    if e + 128 > 255 || e + 128 < 1 {
        return if e + 128 < 1 { Some([0; 4]) } else { None };
    }
    let f = m * 255.9999 / d;
    Some([
        (v[0] * f) as u8,
        (v[1] * f) as u8,
        (v[2] * f) as u8,
        (e + 128) as u8,
    ])
}

/// Append one component's run-length encoding (runs of 4 or more as
/// `128 + n, v`, the rest as literals of at most 128).
fn encode_component(b: &[u8], out: &mut Vec<u8>) {
    let w = b.len();
    let run_at = |i: usize| {
        let mut n = 1;
        while i + n < w && n < 127 && b[i + n] == b[i] {
            n += 1;
        }
        n
    };
    let mut i = 0;
    while i < w {
        let n = run_at(i);
        if n >= 4 {
            out.push(128 + n as u8);
            out.push(b[i]);
            i += n;
            continue;
        }
        let start = i;
        while i < w && i - start < 128 && run_at(i) < 4 {
            i += 1;
        }
        out.push((i - start) as u8);
        out.extend_from_slice(&b[start..i]);
    }
}

/// Encode a scanline of pixels into `out`.
pub fn write_scanline(pixels: &[[u8; 4]], out: &mut Vec<u8>, comp: &mut Vec<u8>) {
    let w = pixels.len();
    if !(8..=0x7fff).contains(&w) {
        for p in pixels {
            out.extend_from_slice(p);
        }
        return;
    }
    out.extend_from_slice(&[2, 2, (w >> 8) as u8, (w & 0xff) as u8]);
    for c in 0..4 {
        comp.clear();
        comp.extend(pixels.iter().map(|p| p[c]));
        encode_component(comp, out);
    }
}

/// The header text of a written picture: the kept `lines` (the input's
/// `SOFTWARE=` among them), this run's `history` line (as every Radiance
/// program appends its command), epfilt's own variables `extra`
/// (`name=value`), `SOFTWARE=` where the input had none, then `FORMAT=`.
pub fn header_text(
    w: usize,
    h: usize,
    xyze: bool,
    (lines, history): (&[String], &str),
    extra: &[(String, String)],
    software: &str,
) -> String {
    let mut s = String::from("#?RADIANCE\n");
    for l in lines {
        s.push_str(l);
        s.push('\n');
    }
    s.push_str(history);
    s.push('\n');
    for (name, value) in extra {
        s.push_str(&format!("{name}={value}\n"));
    }
    if !lines.iter().any(|l| l.starts_with("SOFTWARE=")) {
        s.push_str(&format!("SOFTWARE={software}\n"));
    }
    s.push_str(if xyze {
        "FORMAT=32-bit_rle_xyze\n"
    } else {
        "FORMAT=32-bit_rle_rgbe\n"
    });
    s.push_str(&format!("\n-Y {h} +X {w}\n"));
    s
}

/// A [`Sink`] writing a picture through a temporary file: rows of three
/// channels in, RGBE scanlines out, and the sums of what the bytes decode to.
pub struct RgbeOutput {
    dest: PathBuf,
    staged: Option<super::Staged>,
    out: Option<BufWriter<std::fs::File>>,
    w: usize,
    h: usize,
    rows_done: usize,
    pixels: Vec<[u8; 4]>,
    line: Vec<u8>,
    comp: Vec<u8>,
    /// Sum per channel of the decoded stored values.
    sums: crate::pipeline::ledger::StoredSums,
}

impl RgbeOutput {
    /// Start a `w` x `h` picture at `dest` (checked as every output is) with
    /// these header lines, this run's history line and epfilt's own
    /// variables ([`header_text`]).
    pub fn create(
        dest: &Path,
        w: usize,
        h: usize,
        xyze: bool,
        lines: (&[String], &str),
        extra: &[(String, String)],
        software: &str,
    ) -> Result<Self> {
        let staged = super::Staged::new(dest, ".hdr.tmp")?;
        let file = staged
            .file()
            .try_clone()
            .map_err(|e| Error::io(staged.path(), e))?;
        let mut out = BufWriter::with_capacity(1 << 20, file);
        out.write_all(header_text(w, h, xyze, lines, extra, software).as_bytes())
            .map_err(|e| Error::io(dest, e))?;
        Ok(RgbeOutput {
            dest: dest.into(),
            staged: Some(staged),
            out: Some(out),
            w,
            h,
            rows_done: 0,
            pixels: vec![[0; 4]; w],
            line: Vec::with_capacity(4 * w + 64),
            comp: Vec::with_capacity(w),
            sums: Default::default(),
        })
    }

    /// `--edge pad`: weigh each pixel of the sums by its coverage.
    pub fn set_coverage(&mut self, coverage: crate::pipeline::edge::Coverage) {
        self.sums.set_coverage(coverage);
    }

    /// Per channel, the sum of the values the file holds (decoded).
    pub fn decoded_sums(&self) -> Vec<f64> {
        self.sums.values()
    }

    /// Put the finished picture in place.
    pub fn commit(mut self) -> Result<()> {
        let staged = self.staged.take().ok_or(Error::Interrupted)?;
        staged.commit()
    }
}

impl Sink for RgbeOutput {
    fn precision(&self) -> Precision {
        Precision::F32
    }

    fn write_rows(&mut self, _y0: usize, rows: usize, data: &[f32]) -> Result<()> {
        let w = self.w;
        let nch = data.len() / (rows * w).max(1);
        if nch != 3 {
            return Err(Error::Config(format!(
                "{}: a Radiance picture holds three channels, not {nch}",
                self.dest.display()
            )));
        }
        let out = self.out.as_mut().ok_or(Error::Interrupted)?;
        for r in 0..rows {
            let row = &data[r * 3 * w..][..3 * w];
            for x in 0..w {
                let v = [row[x], row[w + x], row[2 * w + x]];
                let p = encode(v).ok_or_else(|| Error::Value {
                    path: self.dest.clone(),
                    reason: format!(
                        "output value {:e} at pixel ({x}, {}) is too large for RGBE",
                        v[0].max(v[1]).max(v[2]),
                        self.rows_done + r
                    ),
                })?;
                let stored = [0, 1, 2].map(|c| channel(p[c], p[3]) as f64);
                self.sums.add((x, self.rows_done + r), stored);
                self.pixels[x] = p;
            }
            self.line.clear();
            write_scanline(&self.pixels, &mut self.line, &mut self.comp);
            out.write_all(&self.line)
                .map_err(|e| Error::io(&self.dest, e))?;
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
        if let Some(mut out) = self.out.take() {
            out.flush().map_err(|e| Error::io(&self.dest, e))?;
            let f = out
                .into_inner()
                .map_err(|e| Error::io(&self.dest, e.into_error()))?;
            f.sync_all().ok();
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode_all(bytes: &[u8]) -> (RgbeHeader, Vec<f32>) {
        let h = parse_header(Path::new("t.hdr"), bytes).unwrap();
        let mut src = RgbeSource::new(Path::new("t.hdr"), bytes, h.clone());
        let mut all = Vec::new();
        while let Some(s) = src.next_strip(3).unwrap() {
            all.extend(s.data);
        }
        (h, all)
    }

    fn picture(
        w: usize,
        h: usize,
        px: impl Fn(usize, usize) -> [f32; 3],
    ) -> (Vec<u8>, Vec<[u8; 4]>) {
        let mut bytes = header_text(
            w,
            h,
            false,
            (&["VIEW= -vtv -vh 45".into()], "test"),
            &[],
            "test",
        )
        .into_bytes();
        let mut all = Vec::new();
        let (mut line, mut comp) = (Vec::new(), Vec::new());
        for y in 0..h {
            let row: Vec<[u8; 4]> = (0..w).map(|x| encode(px(x, y)).unwrap()).collect();
            line.clear();
            write_scanline(&row, &mut line, &mut comp);
            bytes.extend_from_slice(&line);
            all.extend(row);
        }
        (bytes, all)
    }

    #[test]
    fn encoding_is_radiances_and_within_one_percent() {
        assert_eq!(encode([0.0, 0.0, 0.0]), Some([0; 4]));
        // Radiance's setcolr truncates 0.5 * 255.9999: 1.0 is stored as 127.
        assert_eq!(encode([1.0, 0.5, 0.25]), Some([127, 63, 31, 129]));
        assert_eq!(encode([-1.0, f32::NAN, 1.0]), Some([0, 0, 127, 129]));
        assert_eq!(encode([f32::MAX, 0.0, 0.0]), None);
        let mut x = 1e-30f32;
        while x < 1e30 {
            let p = encode([x, x * 0.3, x * 0.01]).unwrap();
            let back = channel(p[0], p[3]);
            assert!(((back - x) / x).abs() < 1.0 / 128.0, "{x} -> {back}");
            x *= 1.37;
        }
    }

    #[test]
    fn new_style_runs_round_trip_for_every_width() {
        for w in [1, 7, 8, 9, 127, 128, 129, 300, 0x7fff + 1] {
            let h = 3;
            let (bytes, stored) = picture(w, h, |x, y| {
                // Runs and literals mixed.
                let v = if (x / 5) % 2 == 0 {
                    1.0
                } else {
                    1.0 + (x * 7 + y) as f32 % 13.0
                };
                [v, v * 0.5, (x % 3) as f32]
            });
            let (hd, data) = decode_all(&bytes);
            assert_eq!((hd.w, hd.h), (w, h));
            // Every line is kept: the history's and SOFTWARE= too.
            let kept = ["VIEW= -vtv -vh 45", "test", "SOFTWARE=test"].map(String::from);
            assert_eq!(hd.lines, kept);
            for y in 0..h {
                for c in 0..3 {
                    for x in 0..w {
                        let p = stored[y * w + x];
                        assert_eq!(data[(y * 3 + c) * w + x], channel(p[c], p[3]), "w {w}");
                    }
                }
            }
        }
    }

    #[test]
    fn old_style_runs_flat_lines_exposure_and_damage() {
        // Old-style: a pixel then "repeat 3", "repeat 1 << 8" would overflow.
        let mut bytes =
            b"#?RADIANCE\nEXPOSURE=2\nEXPOSURE=2\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 5\n".to_vec();
        bytes.extend_from_slice(&[128, 64, 32, 129, 1, 1, 1, 3, 10, 20, 30, 128]);
        let (hd, data) = decode_all(&bytes);
        assert_eq!(hd.scale, [4.0; 3]);
        // 1.0 / EXPOSURE 4 in R of the first four pixels.
        let r = &data[..5];
        for v in &r[..4] {
            assert!((v - (128.5 / 128.0) / 4.0).abs() < 1e-6, "{v}");
        }
        assert!((r[4] - 10.5 / 256.0 / 4.0).abs() < 1e-6);
        // Damage: truncated, runs past the end, a bad resolution line.
        let path = Path::new("t.hdr");
        let truncated = &bytes[..bytes.len() - 2];
        let h = parse_header(path, truncated).unwrap();
        assert!(RgbeSource::new(path, truncated, h).next_strip(1).is_err());
        let mut long_run = b"#?RADIANCE\n\n-Y 1 +X 3\n".to_vec();
        long_run.extend_from_slice(&[1, 2, 3, 129, 1, 1, 1, 200]);
        let h = parse_header(path, &long_run).unwrap();
        assert!(RgbeSource::new(path, &long_run, h).next_strip(1).is_err());
        for bad in [
            &b"#?RADIANCE\n\n-Y 0 +X 3\n"[..],
            b"#?RADIANCE\n\n+Y 2 +X 3\n",
            b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n",
            b"#?RADIANCE\nFORMAT=bogus\n\n-Y 1 +X 1\n",
            b"#?RADIANCE\nEXPOSURE=-1\n\n-Y 1 +X 1\n",
            b"#?RADIANCE\n\n-Y 99999999999 +X 1\n",
        ] {
            assert!(
                parse_header(path, bad).is_err(),
                "{}",
                String::from_utf8_lossy(bad)
            );
        }
        // New-style with a wrong width or a zero literal.
        let mut wrong = b"#?RADIANCE\n\n-Y 1 +X 8\n".to_vec();
        wrong.extend_from_slice(&[2, 2, 0, 9, 0, 0]);
        let h = parse_header(path, &wrong).unwrap();
        assert!(RgbeSource::new(path, &wrong, h).next_strip(1).is_err());
    }
}
