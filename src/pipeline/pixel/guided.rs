//! The guide passes as the pixel-resolution stages read them from a strip
//! row (the rules are [`crate::filter::guides`]'): what is left of a pixel
//! beside its emission, whether it is a light, its surface, and whether a
//! spread may reach it.

use crate::error::{Error, Result};
use crate::filter::guides::{emission_part, is_light, GuideLayout, SurfaceGuides, SurfaceRule};
use crate::filter::luminance::Luminance;

/// A stage's reader of the guides in its strip rows.
pub struct GuideReader {
    layout: GuideLayout,
    /// For each filtered channel, the channel of its emission guide.
    emission: Vec<Option<usize>>,
    lum: Luminance,
    rule: SurfaceRule,
    cos_max: f32,
    w: usize,
}

impl GuideReader {
    /// The guides of `layout` in rows of `w` pixels whose filtered channels
    /// have the luminance weights `lum` (`nch` of them): the emission guide
    /// pairs with the colour channels, in order.
    pub fn new(
        layout: GuideLayout,
        rule: SurfaceRule,
        lum: &[f64],
        nch: usize,
        w: usize,
    ) -> Result<Self> {
        rule.validate()?;
        let colour: Vec<usize> = (0..nch).filter(|&c| lum.get(c) != Some(&0.0)).collect();
        let mut emission = vec![None; nch];
        if let Some(e) = &layout.emission {
            if e.len() != colour.len() {
                return Err(Error::Config(format!(
                    "the emission guide has {} channels, the beauty {}",
                    e.len(),
                    colour.len()
                )));
            }
            for (&c, &i) in colour.iter().zip(e) {
                emission[c] = Some(i);
            }
        }
        Ok(GuideReader {
            lum: Luminance::new(&lum[..nch.min(lum.len())]),
            emission,
            cos_max: rule.normal_degrees.to_radians().cos() as f32,
            rule,
            layout,
            w,
        })
    }

    /// Whether an emission guide is read.
    pub fn emission(&self) -> bool {
        self.layout.emission.is_some()
    }

    /// Whether a surface guide is read.
    pub fn surface(&self) -> bool {
        self.layout.surface()
    }

    /// Whether a spread's receivers are chosen (lights and other surfaces
    /// left out): with any guide.
    pub fn chooses_receivers(&self) -> bool {
        self.emission() || self.surface()
    }

    /// Channel `c` of pixel `x` of `row`, less its emission guide's part.
    #[inline]
    pub fn residual(&self, row: &[f32], c: usize, x: usize) -> f64 {
        let v = row[c * self.w + x] as f64;
        match self.emission[c] {
            Some(e) => v - emission_part(v, row[e * self.w + x] as f64),
            None => v,
        }
    }

    /// The luminance of what the emission guide leaves of pixel `x`.
    #[inline]
    pub fn residual_luminance(&self, row: &[f32], x: usize) -> f64 {
        self.lum.of(|c| self.residual(row, c, x))
    }

    /// Whether pixel `x` of `row` is a light ([`is_light`]; never without an
    /// emission guide); `residual` its [`GuideReader::residual_luminance`].
    #[inline]
    pub fn is_light(&self, row: &[f32], x: usize, residual: f64) -> bool {
        if !self.emission() {
            return false;
        }
        let full = self.lum.of(|c| row[c * self.w + x] as f64);
        is_light(full, full - residual)
    }

    /// Pixel `x`'s surface guides (default without them).
    #[inline]
    pub fn surface_of<G: SurfaceGuides>(&self, row: &[f32], x: usize) -> G {
        if !self.surface() {
            return G::default();
        }
        G::read(&self.layout, |i| row[i * self.w + x])
    }

    /// Whether pixel `x` of `row` holds any emission.
    #[inline]
    pub fn has_emission(&self, row: &[f32], x: usize) -> bool {
        (self.emission.iter().flatten()).any(|&e| row[e * self.w + x] > 0.0)
    }

    /// Whether pixel `(tx, ty)` (a `light`, on surface `q`) may receive a
    /// spread from a source at `(sx, sy)` on surface `from`: not a light,
    /// and on that surface (`None`: a source that keeps clear of lights
    /// only).
    // Always: it runs for every receiver of a guided spread's every rung,
    // and the inliner left a call there once it was generic.
    #[inline(always)]
    pub fn accepts<G: SurfaceGuides>(
        &self,
        (light, q): (bool, &G),
        (tx, ty): (usize, usize),
        from: Option<(&G, usize, usize)>,
    ) -> bool {
        if light {
            return false;
        }
        let Some((surface, sx, sy)) = from.filter(|_| self.surface()) else {
            return true;
        };
        let dx = sx as f32 - tx as f32;
        let dy = sy as f32 - ty as f32;
        surface.same(q, dx * dx + dy * dy, &self.rule, self.cos_max)
    }

    /// Append a source's values for pixel `x` of `row`: what it keeps,
    /// then what one of `weight` units of its kernel carries, where it
    /// gives up the fraction `f` of
    /// what the emission guide leaves of each channel of `spread` (the
    /// other channels keep their values, and are not listed).
    pub fn give_up(
        &self,
        values: &mut Vec<f64>,
        (row, x): (&[f32], usize),
        spread: &[usize],
        (f, weight): (f64, f64),
    ) {
        let n = spread.len();
        let at = values.len();
        values.resize(at + 2 * n, 0.0);
        let (kept, shares) = values[at..].split_at_mut(n);
        for (j, &c) in spread.iter().enumerate() {
            let removed = self.residual(row, c, x) * f;
            kept[j] = row[c * self.w + x] as f64 - removed;
            shares[j] = removed / weight;
        }
    }

    /// [`GuideReader::accepts`] for pixel `(tx, ty)` read from its `row`.
    #[inline]
    pub fn accepts_in<G: SurfaceGuides>(
        &self,
        row: &[f32],
        (tx, ty): (usize, usize),
        from: Option<(&G, usize, usize)>,
    ) -> bool {
        let light = self.emission() && self.is_light(row, tx, self.residual_luminance(row, tx));
        self.accepts((light, &self.surface_of(row, tx)), (tx, ty), from)
    }
}
