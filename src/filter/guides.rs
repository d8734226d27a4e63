//! Guide passes: what a renderer writes beside the beauty that tells a lamp
//! from a firefly and one surface from another (the channels are found by
//! [`crate::io::guides`]).
//!
//! * **Emission** (the directly visible emission: a bulb, a neon tube, an
//!   emissive rim). Per channel, the part `e' = clamp(e, 0, max(x, 0))` of a
//!   pixel `x` (or super-sample) is set aside before any test and added back
//!   after, untouched: the rest `x - e'` is filtered as usual. A lamp is
//!   never spread and never counts as noise; a firefly beside it is tested
//!   against the room, not the lamp. `x = (x - e') + e'` exactly, so the
//!   ledger covers both parts. A pixel that is mostly emission
//!   ([`LIGHT_SHARE`]) is a light and keeps its value whole.
//! * **Surface** (albedo, normal, depth): a spread reaches only the pixels on
//!   the same surface as its source ([`Surface::same`]); each spread's
//!   weights are normalised over the pixels it reaches, so they still sum to
//!   one. A caustic's firefly on a table is not spread onto the wall behind.

/// Which channels of a strip row hold each guide (indices into the row's
/// channel list; `None` where there is no such guide).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GuideLayout {
    /// Emission R, G, B, in the order of the beauty's colour channels.
    pub emission: Option<Vec<usize>>,
    /// Albedo R, G, B.
    pub albedo: Option<[usize; 3]>,
    /// Normal X, Y, Z.
    pub normal: Option<[usize; 3]>,
    /// Depth.
    pub depth: Option<usize>,
}

impl GuideLayout {
    /// Whether any surface guide is present.
    pub fn surface(&self) -> bool {
        self.albedo.is_some() || self.normal.is_some() || self.depth.is_some()
    }

    /// Whether albedo is the only surface guide ([`AlbedoOnly`] holds it).
    pub fn albedo_only(&self) -> bool {
        self.albedo.is_some() && self.normal.is_none() && self.depth.is_none()
    }

    /// Whether no guide is present.
    pub fn is_empty(&self) -> bool {
        self.emission.is_none() && !self.surface()
    }
}

/// How alike two pixels' surface guides must be for a spread to reach from
/// one to the other (`--guide-normal`, `--guide-albedo`, `--guide-depth`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceRule {
    /// The largest angle between normals, in degrees.
    pub normal_degrees: f64,
    /// The largest difference of albedo, in any channel.
    pub albedo: f64,
    /// The largest relative difference of depth, per pixel of distance
    /// (a slanted floor's depth changes along it; a wall behind a table
    /// jumps).
    pub depth: f64,
}

impl Default for SurfaceRule {
    /// 30 degrees: a curved object's normals turn by a few degrees a pixel
    /// (a sphere of 60 pixels across: 2 degrees), a table's edge or the
    /// floor meeting a wall by 90. Albedo 0.1: one material's texture
    /// varies less than two materials differ. Depth 5% a pixel: steeper
    /// than a floor seen at 80 degrees from its normal, shallower than the
    /// jump from an object to what is behind it.
    fn default() -> Self {
        SurfaceRule {
            normal_degrees: 30.0,
            albedo: 0.1,
            depth: 0.05,
        }
    }
}

impl SurfaceRule {
    /// Check the settings.
    pub fn validate(&self) -> crate::error::Result<()> {
        let ok = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;
        if !ok(self.normal_degrees, 0.0, 180.0) {
            return Err(crate::error::Error::Config(format!(
                "--guide-normal must be 0..=180 degrees, got {}",
                self.normal_degrees
            )));
        }
        if !ok(self.albedo, 0.0, f64::MAX) || !ok(self.depth, 0.0, f64::MAX) {
            return Err(crate::error::Error::Config(format!(
                "--guide-albedo and --guide-depth must be finite numbers >= 0, got {} and {}",
                self.albedo, self.depth
            )));
        }
        Ok(())
    }
}

/// Steps of a quantised albedo (0..=1) and normal component (-1..=1): far
/// finer than the rule's thresholds (0.1; 30 degrees), and a pixel's guides
/// fit in 12 bytes, which every pixel a guided spread reaches is read for.
const ALBEDO_STEPS: f32 = 255.0;
const NORMAL_STEPS: f32 = 127.0;

/// One pixel's surface guides, quantised (absent ones are zero and compare
/// equal).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Surface {
    /// Albedo, in 1/255 (clamped to 0..=1).
    pub albedo: [u8; 3],
    /// Normal, unit length in 1/127 (zero where the pixel saw no surface).
    pub normal: [i8; 3],
    /// The pixel saw a surface (its normal is not zero).
    pub hit: bool,
    /// Depth (zero where none).
    pub depth: f32,
}

impl Surface {
    /// The guides of a pixel from its channel values (`ch(i)` reads channel
    /// `i` of the row), the normal made unit length (a pixel's normal is the
    /// mean of its samples': shorter than one on an edge).
    pub fn read(layout: &GuideLayout, ch: impl Fn(usize) -> f32) -> Self {
        let mut s = Surface::default();
        if let Some(a) = layout.albedo {
            // NaN becomes 0.
            s.albedo = a.map(|i| (ch(i).clamp(0.0, 1.0) * ALBEDO_STEPS).round() as u8);
        }
        if let Some(n) = layout.normal {
            let v = n.map(&ch);
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if len.is_finite() && len > 1e-6 {
                s.normal = v.map(|c| (c / len * NORMAL_STEPS).round() as i8);
                s.hit = true;
            }
        }
        if let Some(d) = layout.depth {
            let z = ch(d);
            s.depth = if z.is_finite() { z } else { 0.0 };
        }
        s
    }

    /// Whether `other`, `sqrt(dist2)` pixels away, is on the same surface
    /// under `rule` (with `cos_max` the cosine of its angle, computed once).
    #[inline]
    pub fn same(&self, other: &Surface, dist2: f32, rule: &SurfaceRule, cos_max: f32) -> bool {
        // Branch-light: this runs for every pixel a guided spread reaches.
        // Two misses match; a miss and a hit do not.
        let (n, m) = (&self.normal, &other.normal);
        let dot = n[0] as i32 * m[0] as i32 + n[1] as i32 * m[1] as i32 + n[2] as i32 * m[2] as i32;
        let turn = dot as f32 >= cos_max * NORMAL_STEPS * NORMAL_STEPS;
        let normal = self.hit == other.hit && (turn || !self.hit);
        // |z - w| <= depth * max(dist, 1) * max(|z|, |w|), squared.
        let (z, w) = (self.depth, other.depth);
        let (d, lim) = (z - w, rule.depth as f32 * z.abs().max(w.abs()));
        albedo_within(&self.albedo, &other.albedo, rule)
            && normal
            && d * d <= lim * lim * dist2.max(1.0)
    }
}

/// Whether two quantised albedos differ by at most `rule.albedo` in every
/// channel.
#[inline]
fn albedo_within(a: &[u8; 3], b: &[u8; 3], rule: &SurfaceRule) -> bool {
    let da = a[0]
        .abs_diff(b[0])
        .max(a[1].abs_diff(b[1]))
        .max(a[2].abs_diff(b[2]));
    da as f32 <= rule.albedo as f32 * ALBEDO_STEPS
}

/// A pixel's surface guides as a window over a spread's reach holds them:
/// [`Surface`], or [`AlbedoOnly`] for a render whose only surface guide is
/// albedo (what is not there is not held). Each decides as [`Surface`]
/// does.
pub trait SurfaceGuides: Copy + Default + Send + Sync + 'static {
    /// The guides of a pixel from its channel values ([`Surface::read`]).
    fn read(layout: &GuideLayout, ch: impl Fn(usize) -> f32) -> Self;
    /// [`Surface::same`].
    fn same(&self, other: &Self, dist2: f32, rule: &SurfaceRule, cos_max: f32) -> bool;
}

impl SurfaceGuides for Surface {
    #[inline]
    fn read(layout: &GuideLayout, ch: impl Fn(usize) -> f32) -> Self {
        Surface::read(layout, ch)
    }

    #[inline]
    fn same(&self, other: &Self, dist2: f32, rule: &SurfaceRule, cos_max: f32) -> bool {
        Surface::same(self, other, dist2, rule, cos_max)
    }
}

/// The quantised albedo alone (3 bytes a pixel, where a [`Surface`] takes
/// 12): for a render with an albedo pass and neither normals nor depth,
/// whose [`Surface`]s would compare their absent guides as equal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AlbedoOnly(pub [u8; 3]);

impl SurfaceGuides for AlbedoOnly {
    #[inline]
    fn read(layout: &GuideLayout, ch: impl Fn(usize) -> f32) -> Self {
        AlbedoOnly(Surface::read(layout, ch).albedo)
    }

    #[inline]
    fn same(&self, other: &Self, _: f32, rule: &SurfaceRule, _: f32) -> bool {
        albedo_within(&self.0, &other.0, rule)
    }
}

/// A pixel whose emission holds at least this share of its luminance is a
/// light seen directly (a bulb, a neon tube, a lamp's edge): it keeps its
/// value whole, never tested, never spread. What is left of it beside the
/// emission is a lamp's glow or the wall half seen behind its edge, not a
/// firefly.
pub const LIGHT_SHARE: f64 = 0.5;

/// Whether a pixel of luminance `y` whose emission's luminance is `e` is a
/// light ([`LIGHT_SHARE`]).
#[inline]
pub fn is_light(y: f64, e: f64) -> bool {
    e > 0.0 && e >= LIGHT_SHARE * y
}

/// A source keeps to its surface (with surface guides) when at least this
/// share of its nearest receivers lies on it: less, and it sits on an edge
/// or a sliver, its own guides a mix of its samples', and keeping to them
/// would pile its excess on the few pixels that match (docs/bench's
/// renders-as-written.md measures the surface guides with this rule).
pub const SURFACE_SHARE: f64 = 0.5;

/// Whether a source keeps to its surface, `on` of its nearest receivers'
/// weight lying on it out of `all` ([`SURFACE_SHARE`]); else it keeps clear
/// of lights only.
#[inline]
pub fn keeps_to_surface(on: f64, all: f64) -> bool {
    on >= SURFACE_SHARE * all
}

/// The emission part of a channel value `x` whose emission guide reads `e`:
/// never negative, never more than the value itself (so the rest, `x - e'`,
/// is never below zero where `x` is not).
#[inline]
pub fn emission_part(x: f64, e: f64) -> f64 {
    if e.is_finite() {
        e.clamp(0.0, x.max(0.0))
    } else {
        0.0
    }
}

/// The emission guide's parts of the colour channels of planar rows
/// (`[channel][x]`, `w` samples a channel): which channel pairs with which
/// emission channel, and the luminance weight of each.
#[derive(Clone, Debug, PartialEq)]
pub struct EmissionParts {
    /// (colour channel, its emission channel, luminance weight).
    pairs: Vec<(usize, usize, f64)>,
}

impl EmissionParts {
    /// The parts of the channels `colour[k]` (weights `weights[k]`), whose
    /// emission is channel `emission[k]`.
    pub fn new(colour: &[usize], emission: &[usize], weights: &[f64]) -> Self {
        EmissionParts {
            pairs: (colour.iter().zip(emission).zip(weights))
                .map(|((&c, &e), &l)| (c, e, l))
                .collect(),
        }
    }

    /// The emission part ([`emission_part`]) of channel `c` of sample `i`,
    /// 0 for a channel without emission.
    #[inline]
    pub fn part(&self, row: &[f32], w: usize, c: usize, i: usize) -> f64 {
        match self.pairs.iter().find(|p| p.0 == c) {
            Some(&(c, e, _)) => emission_part(row[c * w + i] as f64, row[e * w + i] as f64),
            None => 0.0,
        }
    }

    /// The luminance of sample `i`'s emission parts: what the emission
    /// guide takes out of its luminance.
    #[inline]
    pub fn luminance(&self, row: &[f32], w: usize, i: usize) -> f64 {
        let mut y = 0.0;
        for &(c, e, l) in &self.pairs {
            y += l * emission_part(row[c * w + i] as f64, row[e * w + i] as f64);
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn surface(albedo: f32, normal: [f32; 3], depth: f32) -> Surface {
        let layout = GuideLayout {
            albedo: Some([0, 1, 2]),
            normal: Some([3, 4, 5]),
            depth: Some(6),
            emission: None,
        };
        let v = [
            albedo, albedo, albedo, normal[0], normal[1], normal[2], depth,
        ];
        Surface::read(&layout, |i| v[i])
    }

    #[test]
    fn a_table_is_not_the_wall_behind_it() {
        let rule = SurfaceRule::default();
        let cos = (rule.normal_degrees.to_radians().cos()) as f32;
        let table = surface(0.5, [0.0, 2.0, 0.0], 3.0); // normal made unit
        assert_eq!(table.normal, [0, 127, 0]);
        let table_far = surface(0.52, [0.05, 1.0, 0.0], 3.3);
        let wall = surface(0.5, [0.0, 0.0, 1.0], 3.0);
        let behind = surface(0.5, [0.0, 1.0, 0.0], 6.0);
        let paint = surface(0.8, [0.0, 1.0, 0.0], 3.0);
        assert!(table.same(&table_far, 16.0, &rule, cos));
        assert!(!table.same(&wall, 1.0, &rule, cos));
        assert!(!table.same(&behind, 4.0, &rule, cos));
        assert!(!table.same(&paint, 1.0, &rule, cos));
        // Without a hit (zero normal) only other misses match.
        let sky = surface(0.0, [0.0; 3], 0.0);
        assert!(sky.same(&sky, 9.0, &rule, cos));
        assert!(!sky.same(&surface(0.0, [0.0, 1.0, 0.0], 0.0), 1.0, &rule, cos));
    }

    #[test]
    fn albedo_alone_decides_as_the_surface_it_stands_for() {
        let layout = GuideLayout {
            albedo: Some([0, 1, 2]),
            ..GuideLayout::default()
        };
        assert!(layout.albedo_only());
        let values = [0.0, 0.03, 0.05, 0.1, 0.11, 0.5, 0.55, 0.9, 1.0, 1.7, -0.2];
        let pixel = |i: usize| [values[i % 11], values[i / 11 % 11], values[i / 121 % 11]];
        for rule in [
            SurfaceRule::default(),
            SurfaceRule {
                albedo: 0.0,
                ..SurfaceRule::default()
            },
            SurfaceRule {
                albedo: 0.3,
                depth: 0.0,
                ..SurfaceRule::default()
            },
        ] {
            let cos = rule.normal_degrees.to_radians().cos() as f32;
            for (i, j) in (0..1331).map(|i| (i, (i * 37 + 5) % 1331)) {
                let (a, b) = (pixel(i), pixel(j));
                let (sa, sb) = (
                    Surface::read(&layout, |k| a[k]),
                    Surface::read(&layout, |k| b[k]),
                );
                let (qa, qb) = (
                    AlbedoOnly::read(&layout, |k| a[k]),
                    AlbedoOnly::read(&layout, |k| b[k]),
                );
                assert_eq!(qa.0, sa.albedo);
                for dist2 in [0.0, 1.0, 50.0] {
                    assert_eq!(
                        qa.same(&qb, dist2, &rule, cos),
                        sa.same(&sb, dist2, &rule, cos),
                        "{a:?} {b:?} {rule:?}"
                    );
                }
            }
        }
        // With another surface guide a render needs the whole Surface.
        let normal = GuideLayout {
            normal: Some([3, 4, 5]),
            ..layout.clone()
        };
        assert!(!normal.albedo_only() && !GuideLayout::default().albedo_only());
    }

    #[test]
    fn emission_is_at_most_the_value() {
        assert_eq!(emission_part(10.0, 4.0), 4.0);
        assert_eq!(emission_part(3.0, 4.0), 3.0);
        assert_eq!(emission_part(3.0, -1.0), 0.0);
        assert_eq!(emission_part(-2.0, 1.0), 0.0);
        assert_eq!(emission_part(3.0, f64::NAN), 0.0);
    }
}
