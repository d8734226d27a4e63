//! What the examples' plots share: 8x8 text drawn into an RGB buffer (the
//! plots are built without a font backend) and the buffer written as a PNG.

use std::path::Path;

/// Draw `s` in 8x8 glyphs of colour `c` with its top left at `(x0, y0)`.
pub fn text(buf: &mut [u8], w: usize, x0: usize, y0: usize, s: &str, c: (u8, u8, u8)) {
    use font8x8::UnicodeFonts;
    for (k, ch) in s.chars().enumerate() {
        let Some(glyph) = font8x8::BASIC_FONTS.get(ch) else {
            continue;
        };
        for (gy, bits) in glyph.iter().enumerate() {
            for bx in 0..8 {
                let (x, y) = (x0 + k * 8 + bx, y0 + gy);
                if bits & (1 << bx) != 0 && x < w && (y * w + x) * 3 + 3 <= buf.len() {
                    buf[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[c.0, c.1, c.2]);
                }
            }
        }
    }
}

/// Write an RGB buffer of `w` x `h` as an 8-bit PNG.
pub fn save_png(path: &Path, buf: &[u8], w: usize, h: usize) -> anyhow::Result<()> {
    let file = std::fs::File::create(path)?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()?.write_image_data(buf)?;
    Ok(())
}
