//! From values to display colours: the paper's linear tone mapping, and a
//! false-colour scale of luminance with its legend (as Radiance's
//! `falsecolor` draws one), and the 8x8 text both label with.

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

/// A logarithmic false-colour scale: `top` at the warm end, `top /
/// 10^decades` and below at the cold end.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogScale {
    /// The value shown in the warmest colour (and above).
    pub top: f64,
    /// How many factors of ten the colours span.
    pub decades: u32,
}

impl LogScale {
    /// Where `v` lies on the scale, 0 (cold) to 1 (warm).
    #[inline]
    pub fn position(&self, v: f64) -> f64 {
        if !(v > 0.0) {
            return 0.0;
        }
        let t = 1.0 + (v / self.top).log10() / self.decades.max(1) as f64;
        t.clamp(0.0, 1.0)
    }

    /// `v`'s colour as sRGB bytes.
    #[inline]
    pub fn colour(&self, v: f64) -> [u8; 3] {
        ramp(self.position(v))
    }
}

/// The colour ramp at `t` in 0..1, as sRGB bytes: Google's Turbo
/// (Mikhailov 2019, its polynomial fit), which stays ordered in lightness
/// through the middle and tells dark blue from dark red.
pub fn ramp(t: f64) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    let poly = |c: [f64; 6]| {
        let v = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))));
        (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
    };
    [
        poly([
            0.135_721_38,
            4.615_392_6,
            -42.660_322_58,
            132.131_082_34,
            -152.942_393_96,
            59.286_379_43,
        ]),
        poly([
            0.091_402_61,
            2.194_188_39,
            4.842_966_58,
            -14.185_033_33,
            4.277_298_57,
            2.829_566_04,
        ]),
        poly([
            0.106_673_3,
            12.641_946_08,
            -60.582_048_36,
            110.362_767_71,
            -89.903_109_12,
            27.348_249_73,
        ]),
    ]
}

/// The smallest of 1, 2, 5 x 10^n at or above `v` (1 for nothing positive):
/// a legend's top reads as a round number.
pub fn round_up(v: f64) -> f64 {
    if !(v > 0.0) || !v.is_finite() {
        return 1.0;
    }
    let p = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&c| c >= v * (1.0 - 1e-12))
        .unwrap_or(10.0 * p)
}

/// `v` in at most 7 characters: three significant digits between 0.01 and
/// 9999, else in exponent form.
pub fn short(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let e = v.abs().log10().floor();
    if (-2.0..4.0).contains(&e) {
        format!("{:.*}", (2.0 - e).max(0.0) as usize, v)
    } else {
        format!("{v:.1e}")
    }
}

/// Width of the legend beside false-colour panels, in pixels.
pub const LEGEND_WIDTH: usize = 96;
/// Left edge and width of the legend's colour bar.
const BAR: (usize, usize) = (6, 14);
/// Background of bands and legends.
pub const BACKGROUND: u8 = 40;

/// Row `y` (of `h`) of the legend for `scale`, into `out` (`LEGEND_WIDTH`
/// pixels of sRGB bytes): the bar's colour at that height, warm at the top,
/// and a tick and label at each factor of ten that has room.
pub fn legend_row(scale: &LogScale, y: usize, h: usize, out: &mut [u8]) {
    out.iter_mut().for_each(|b| *b = BACKGROUND);
    let span = (h.max(2) - 1) as f64;
    let c = ramp(1.0 - y as f64 / span);
    for x in BAR.0..BAR.0 + BAR.1 {
        out[x * 3..x * 3 + 3].copy_from_slice(&c);
    }
    let d = scale.decades.max(1) as usize;
    // One label in every `every` decades, 10 rows apart at least.
    let every = (10.0 * d as f64 / span).ceil().max(1.0) as usize;
    for i in (0..=d).step_by(every) {
        let at = (i as f64 * span / d as f64).round() as usize;
        let top = at.saturating_sub(3).min(h.saturating_sub(8));
        if y == at {
            for x in BAR.0 + BAR.1..BAR.0 + BAR.1 + 3 {
                out[x * 3..x * 3 + 3].copy_from_slice(&[255, 255, 255]);
            }
        }
        let label = short(scale.top / 10f64.powi(i as i32));
        draw_text(
            out,
            BAR.0 + BAR.1 + 2,
            LEGEND_WIDTH,
            y as i64 - top as i64,
            &label,
        );
    }
}

/// Draw `text` in white 8x8 glyphs into glyph row `gy` of a box starting
/// at pixel `x0` of `row`, `w` wide (2 pixels in from its left).
pub fn draw_text(row: &mut [u8], x0: usize, w: usize, gy: i64, text: &str) {
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
                if at + 3 <= row.len() {
                    row[at..at + 3].copy_from_slice(&[255, 255, 255]);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// sRGB(0.5) as the encoder computes it, to the third decimal.
    const MID_GREY_TOL: f64 = 1e-3;
    /// Arithmetic on values near 1.
    const UNIT_TOL: f64 = 1e-12;

    #[test]
    fn average_luminance_maps_to_mid_grey() {
        let d = Display::for_average(0.2, 0.0);
        let mid = d.encode(0.2);
        assert!((mid - 0.7354).abs() < MID_GREY_TOL, "{mid}");
        // sRGB(1) = 1.055 - 0.055 is 1 - 1e-16 in f64: still byte 255.
        assert!((d.encode(1e9) - 1.0).abs() < UNIT_TOL);
        assert_eq!(d.encode(-1.0), 0.0);
        assert_eq!(d.encode(f64::NAN), 0.0);
        assert!((Display::for_average(0.2, 1.0).scale - 2.0 * d.scale).abs() < UNIT_TOL);
    }

    #[test]
    fn the_log_scale_spans_its_decades_and_clamps() {
        let s = LogScale {
            top: 1000.0,
            decades: 3,
        };
        assert_eq!(s.position(1000.0), 1.0);
        assert_eq!(s.position(1e9), 1.0);
        assert!((s.position(10.0) - 1.0 / 3.0).abs() < UNIT_TOL);
        assert_eq!(s.position(1.0), 0.0);
        assert_eq!(s.position(0.0), 0.0);
        assert_eq!(s.position(f64::NAN), 0.0);
        // Dark at the cold end, then blue, green in the middle, red warm.
        let sum = |c: [u8; 3]| c.iter().map(|&v| v as u32).sum::<u32>();
        assert!(sum(ramp(0.0)) < 100, "{:?}", ramp(0.0));
        let (blue, green, red) = (ramp(0.1), ramp(0.5), ramp(0.9));
        assert!(blue[2] > blue[0] && green[1] > green[0] && green[1] > green[2]);
        assert!(red[0] > red[1] && red[0] > red[2], "{red:?}");
    }

    #[test]
    fn legends_read_in_round_short_numbers() {
        assert_eq!(round_up(730.0), 1000.0);
        assert_eq!(round_up(0.17), 0.2);
        assert_eq!(round_up(3.0), 5.0);
        assert_eq!(round_up(2.0), 2.0);
        assert_eq!(round_up(0.0), 1.0);
        assert_eq!(short(1234.5), "1234");
        assert_eq!(short(0.0316), "0.0316");
        assert_eq!(short(3.16), "3.16");
        assert_eq!(short(250000.0), "2.5e5");
        assert_eq!(short(0.001), "1.0e-3");
    }
}
