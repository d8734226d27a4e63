//! Looking at HDR results: the paper's display mapping and PNG previews.
//!
//! The tone operator is the simple linear one of §5.1 (Eq. 9): the image's
//! average luminance goes to the middle of the display range, values are
//! clamped and sRGB-encoded. `exposure` (stops) scales on top. A montage puts
//! several images side by side under one mapping, each with a label, so that
//! noisy | linear | epfilt | truth can be compared at a glance. Everything
//! streams row by row.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::io::{ExrInput, Format, Selection};
use crate::pipeline::ledger::CompensatedSum;
use crate::pipeline::{Source, Strip};

/// Height of the label band above each panel, in pixels.
const LABEL_BAND: usize = 12;
/// Gap between panels, in pixels.
const GAP: usize = 4;

/// The linear display mapping: `display = value * scale`, clamped to 0..1.
#[derive(Clone, Copy, Debug)]
pub struct Display {
    /// Multiplier from radiance to display units.
    pub scale: f64,
}

impl Display {
    /// Map average luminance `l_ave` to the middle of the display (0.5),
    /// times `2^exposure`.
    pub fn for_average(l_ave: f64, exposure: f64) -> Self {
        let base = if l_ave > 0.0 && l_ave.is_finite() {
            0.5 / l_ave
        } else {
            1.0
        };
        Display {
            scale: base * exposure.exp2(),
        }
    }

    /// Display value 0..1 (linear), then sRGB-encoded 0..1.
    #[inline]
    pub fn encode(&self, v: f64) -> f64 {
        let x = (v * self.scale).clamp(0.0, 1.0);
        if x.is_nan() {
            0.0
        } else if x <= 0.003_130_8 {
            12.92 * x
        } else {
            1.055 * x.powf(1.0 / 2.4) - 0.055
        }
    }
}

/// What `preview` writes.
pub const WRITES: &[Format] = &[Format::Png];

/// Average luminance of an EXR file (one streaming pass).
pub fn average_luminance(path: &Path) -> Result<f64> {
    luminance_of(&ExrInput::open(path, None)?)
}

fn luminance_of(input: &ExrInput) -> Result<f64> {
    let (w, h) = input.size();
    let lum = crate::filter::luminance::Luminance::new(&input.luminance());
    let nch = lum.weights().len();
    let mut src = input.source();
    let mut sum = CompensatedSum::default();
    let mut y = vec![0.0; w];
    while let Some(strip) = src.next_strip(64)? {
        for row in strip.data.chunks_exact(nch * w).take(strip.rows) {
            lum.row_into(row, w, &mut y);
            y.iter().for_each(|&v| sum.add(v));
        }
    }
    Ok(sum.value() / (w * h).max(1) as f64)
}

/// Write `inputs` (path, label) side by side as one sRGB PNG at `output`,
/// under one display mapping (from the first image's average luminance and
/// `exposure` stops), each read as `select` says. With one input and no
/// label, a plain preview. `format`: `--format`, for a name that does not
/// end in `.png`.
pub fn write_png(
    inputs: &[(PathBuf, String)],
    output: &Path,
    exposure: f64,
    select: &Selection,
    format: Option<Format>,
) -> Result<()> {
    crate::io::format::output_format(output, format, Some(Format::Png), WRITES, "preview")?;
    if inputs.is_empty() {
        return Err(Error::Config("preview needs at least one input".into()));
    }
    let opened: Vec<ExrInput> = inputs
        .iter()
        .map(|(p, _)| select.open(p))
        .collect::<Result<_>>()?;
    let display = Display::for_average(luminance_of(&opened[0])?, exposure);
    let labelled = inputs.len() > 1 || !inputs[0].1.is_empty();
    let band = if labelled { LABEL_BAND } else { 0 };
    let widths: Vec<usize> = opened.iter().map(|i| i.size().0).collect();
    let height = opened.iter().map(|i| i.size().1).max().unwrap_or(0) + band;
    let width = widths.iter().sum::<usize>() + GAP * (inputs.len() - 1);
    if width > 1 << 20 || height > 1 << 20 {
        return Err(Error::Config(format!(
            "preview of {width}x{height} pixels is too large"
        )));
    }
    let temp = crate::io::Staged::new(output, ".png.tmp")?;
    let png_err = |e: png::EncodingError| Error::io(output, std::io::Error::other(e));
    {
        let file = temp
            .file()
            .try_clone()
            .map_err(|e| Error::io(temp.path(), e))?;
        let mut enc = png::Encoder::new(BufWriter::new(file), width as u32, height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = enc.write_header().map_err(png_err)?;
        let mut stream = writer.stream_writer().map_err(png_err)?;
        let mut row = vec![0u8; width * 3];
        // Label band: dark grey with white 8x8 text.
        for y in 0..band {
            row.iter_mut().for_each(|b| *b = 40);
            let mut x0 = 0;
            for ((_, label), &w) in inputs.iter().zip(&widths) {
                draw_text(&mut row, x0, w, y as i64 - 2, label);
                x0 += w + GAP;
            }
            stream.write_all(&row).map_err(|e| Error::io(output, e))?;
        }
        let mut sources: Vec<_> = opened
            .iter()
            .map(|i| (i.source(), i.channels(), None::<(Strip, usize)>))
            .collect();
        for y in 0..height - band {
            row.iter_mut().for_each(|b| *b = 40);
            let mut x0 = 0;
            for ((src, names, cur), &w) in sources.iter_mut().zip(&widths) {
                if cur.as_ref().is_none_or(|(s, r)| *r >= s.rows) {
                    *cur = src.next_strip(64)?.map(|s| (s, 0));
                }
                if let Some((strip, r)) = cur {
                    if y < strip.y0 + strip.rows {
                        let nch = names.len();
                        let pick = |want: &str| {
                            names
                                .iter()
                                .position(|n| n.rsplit('.').next() == Some(want))
                        };
                        let rgb = match (pick("R"), pick("G"), pick("B")) {
                            (Some(a), Some(b), Some(c)) => [a, b, c],
                            _ => [0, 0, 0], // luminance only: grey
                        };
                        for x in 0..w {
                            for (k, &c) in rgb.iter().enumerate() {
                                let v = strip.data[(*r * nch + c) * w + x] as f64;
                                row[(x0 + x) * 3 + k] = (display.encode(v) * 255.0 + 0.5) as u8;
                            }
                        }
                        *r += 1;
                    }
                }
                x0 += w + GAP;
            }
            stream.write_all(&row).map_err(|e| Error::io(output, e))?;
        }
        stream.finish().map_err(png_err)?;
    }
    temp.commit()
}

/// Draw `text` in white 8x8 glyphs into band row `gy` (glyph row) of a panel
/// starting at pixel `x0`, `w` wide.
fn draw_text(row: &mut [u8], x0: usize, w: usize, gy: i64, text: &str) {
    use font8x8::UnicodeFonts;
    if !(0..8).contains(&gy) {
        return;
    }
    for (k, ch) in text.chars().enumerate() {
        let Some(glyph) = font8x8::BASIC_FONTS.get(ch) else {
            continue;
        };
        let bits = glyph[gy as usize];
        for bx in 0..8 {
            let x = 2 + k * 8 + bx;
            if x < w && bits & (1 << bx) != 0 {
                let at = (x0 + x) * 3;
                row[at..at + 3].copy_from_slice(&[255, 255, 255]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn average_luminance_maps_to_mid_grey() {
        let d = Display::for_average(0.2, 0.0);
        let mid = d.encode(0.2);
        assert!((mid - 0.7354).abs() < 1e-3, "{mid}"); // sRGB(0.5)
                                                       // sRGB(1) = 1.055 - 0.055 is 1 - 1e-16 in f64: still byte 255.
        assert!((d.encode(1e9) - 1.0).abs() < 1e-12);
        assert_eq!(d.encode(-1.0), 0.0);
        assert_eq!(d.encode(f64::NAN), 0.0);
        assert!((Display::for_average(0.2, 1.0).scale - 2.0 * d.scale).abs() < 1e-12);
    }
}
