//! ep-gauss at pixel resolution (S = 1), as a [`Rule`] of
//! [`super::PixelStage`] (the rules are in
//! [`crate::filter::ep_gauss::pixel`], the guides' in
//! [`crate::filter::guides`]). Its passes over pixel rows:
//!
//! 0. on arrival, with the emission guide, the **lights** and, with surface
//!    guides, each pixel's **surface**;
//! 1. the **luminance** of what the emission guide leaves (a lamp's own
//!    light is never tested);
//! 2. the **classification**: the background (the median of the 5 x 5
//!    about a pixel) of each local maximum, and whether it is noisy;
//! 3. the **treatment**: the feature rules, the width, and each spread
//!    pixel as a source (what it keeps, what its kernel carries). With
//!    guides, the receivers a spread may not reach, lights and other
//!    surfaces, are read within the widest reach.
//!
//! Each pixel's decision reads only the input within 4 rows and columns of
//! it (with guides, its receivers' within `R`).

use std::ops::Range;

use rayon::iter::{IndexedParallelIterator, IntoParallelIterator, ParallelIterator};

use super::guided::GuideReader;
use super::{Placed, Rule};
use crate::error::Result;
use crate::filter::ep_gauss::pixel::{
    gaussian_taps, local_max, median, noisy, Widths, BACKGROUND_REACH, BACKGROUND_SAMPLES,
};
use crate::filter::guides::{GuideLayout, SurfaceGuides, SurfaceRule};
use crate::filter::ValidParams;
use crate::geometry::mirror;
use crate::pipeline::counts::{MethodCounts, SpreadCounts};
use crate::pipeline::schedule::Reads;
use crate::pipeline::stage::WindowUse;
use crate::pipeline::window::RowWindow;
use crate::pipeline::ChannelMode;

mod treat;
use treat::Treat;

/// Rows past a row whose classification its treatment reads (the range
/// rule looks at the flags within [`BACKGROUND_REACH`]).
const DECIDE_REACH: usize = BACKGROUND_REACH;

/// The passes after the input and what each reads: the luminance, the
/// classification, the treatment (with guides that choose receivers,
/// theirs within `reach`).
pub fn passes(choose: bool, reach: usize) -> Vec<Reads> {
    vec![
        vec![(0, 0)],
        vec![(1, BACKGROUND_REACH), (0, 0)],
        vec![
            (2, DECIDE_REACH),
            (1, BACKGROUND_REACH),
            (0, if choose { reach } else { 0 }),
        ],
    ]
}

/// A pixel whose excess is spread (`G`: how the render's surface guides
/// are held).
#[derive(Clone, Copy, Debug)]
pub struct Source<G> {
    x: u32,
    y: u32,
    /// Its rung on the ladder of widths.
    k: u32,
    /// The surface it keeps to, where the guides choose its receivers and
    /// it does (else, with them, it keeps clear of lights only).
    on_surface: Option<G>,
}

impl<G> Placed for Source<G> {
    fn at(&self) -> (usize, usize) {
        (self.x as usize, self.y as usize)
    }
}

/// The widths and the tests, set once.
struct Ladder {
    tolerance: f64,
    /// The feature rules (`--guard` other than `none`).
    features: bool,
    widths: Widths,
    /// Unnormalised taps of each rung (`2 reach + 1`).
    taps: Vec<Vec<f64>>,
    reach: usize,
}

/// The rows the passes hold, each of the image's width.
struct Windows<G> {
    /// Luminance of what is left after the emission guide.
    ylum: RowWindow<f64>,
    /// The background of local maxima (NaN elsewhere).
    bg: RowWindow<f64>,
    /// 1 where a pixel is noisy by Rule 1.
    cand: RowWindow<u8>,
    /// 1 where the emission guide says a pixel is a light.
    light: RowWindow<u8>,
    /// Each pixel's surface guides (with them), for the rows a spread may
    /// reach (as `light`).
    surf: RowWindow<G>,
}

/// ep-gauss's rule at S = 1, and what its passes hold (`G`: how the
/// surface guides are held, [`SurfaceGuides`]).
pub struct GaussRule<G> {
    w: usize,
    h: usize,
    nch: usize,
    /// The channels a spread moves.
    spread: Vec<usize>,
    guides: GuideReader,
    ladder: Ladder,
    win: Windows<G>,
    /// Pixels whose emission guide set light aside (counted on arrival).
    emissive: u64,
    counts: SpreadCounts,
}

impl<G: SurfaceGuides> GaussRule<G> {
    /// The rule for a `w x h` image whose strip rows hold `nch` filtered
    /// channels (luminance weights `lum`, modes `modes`) and then the aux
    /// channels; `guides` indexes that whole row. Checked by the skeleton:
    /// the grid and the channels.
    pub fn new(
        (w, h): (usize, usize),
        lum: Vec<f64>,
        modes: Vec<ChannelMode>,
        (guides, rule): (GuideLayout, SurfaceRule),
        params: &ValidParams,
    ) -> Result<Self> {
        let nch = modes.len();
        let guides = GuideReader::new(guides, rule, &lum, nch, w)?;
        let widths = Widths::new(
            params.radius,
            params.max_radius,
            params.width_step,
            params.cutoff,
        );
        let taps = (widths.rho.iter().zip(&widths.reach))
            .map(|(&r, &k)| gaussian_taps(r, k, params.cutoff))
            .collect();
        let reach = widths.max_reach();
        Ok(GaussRule {
            w,
            h,
            nch,
            spread: (0..nch)
                .filter(|&c| modes[c] == ChannelMode::Spread)
                .collect(),
            guides,
            ladder: Ladder {
                tolerance: params.tolerance,
                features: params.ep_box.guard != crate::filter::ep_box::Guard::None,
                widths,
                taps,
                reach,
            },
            win: Windows {
                ylum: RowWindow::new(w),
                bg: RowWindow::new(w),
                cand: RowWindow::new(w),
                light: RowWindow::new(w),
                surf: RowWindow::new(w),
            },
            emissive: 0,
            counts: SpreadCounts::default(),
        })
    }
}

impl<G: SurfaceGuides> Rule for GaussRule<G> {
    type Source = Source<G>;
    type Tally = SpreadCounts;
    const TREAT_ROWS: usize = 16;
    /// A pixel is decided alone: a wide strip is cut in columns.
    const TREAT_COLUMNS: usize = 4096;

    fn shape(&self) -> (usize, usize, usize) {
        (self.w, self.h, self.nch)
    }

    fn passes(&self) -> Vec<Reads> {
        passes(self.guides.chooses_receivers(), self.ladder.reach)
    }

    fn spread(&self) -> &[usize] {
        &self.spread
    }

    fn reach(&self) -> usize {
        self.ladder.reach
    }

    fn arrive(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        for _ in a..b {
            self.win.light.push_stale(0);
        }
        if self.guides.surface() {
            for _ in a..b {
                self.win.surf.push_stale(G::default());
            }
            let guides = &self.guides;
            let rows = self.win.surf.range_mut(a, b);
            rows.into_par_iter().enumerate().for_each(|(k, srow)| {
                let row = input.get(a + k);
                for (x, q) in srow.iter_mut().enumerate() {
                    *q = guides.surface_of(row, x);
                }
            });
        }
        if !self.guides.emission() {
            return;
        }
        // The lights, for the rows a spread may reach (their luminance is
        // made again when their rows are classified: held until then, it
        // would cost the width times the reach).
        let guides = &self.guides;
        let region = crate::trace::region("pixel lights");
        let lights = self.win.light.range_mut(a, b);
        let emissive: u64 = lights
            .into_par_iter()
            .enumerate()
            .map(|(k, lrow)| {
                let _task = region.task("pixel lights");
                let row = input.get(a + k);
                let mut emissive = 0;
                for (x, l) in lrow.iter_mut().enumerate() {
                    let light = guides.is_light(row, x, guides.residual_luminance(row, x));
                    *l = u8::from(light);
                    emissive += u64::from(light || guides.has_emission(row, x));
                }
                emissive
            })
            .sum();
        self.emissive += emissive;
    }

    fn make(&mut self, pass: usize, input: &RowWindow<f32>, a: usize, b: usize) {
        match pass {
            1 => self.luminance(input, a, b),
            _ => self.classify(a, b),
        }
    }

    fn evict(&mut self, pass: usize, y: usize) {
        match pass {
            0 => {
                self.win.light.evict_below(y);
                self.win.surf.evict_below(y);
            }
            1 => self.win.ylum.evict_below(y),
            _ => {
                self.win.bg.evict_below(y);
                self.win.cand.evict_below(y);
            }
        }
    }

    fn treat(
        &self,
        input: &RowWindow<f32>,
        rows: Range<usize>,
        columns: Range<usize>,
    ) -> (Vec<Source<G>>, Vec<f64>, SpreadCounts) {
        Treat { stage: self, input }.pixels(rows, columns)
    }

    fn tally(&mut self, tally: SpreadCounts, sources: &[Source<G>]) {
        let taps: u64 = (sources.iter())
            .map(|s| (2 * self.ladder.widths.reach[s.k as usize] as u64 + 1).pow(2))
            .sum();
        self.counts += tally;
        self.counts.spread_taps += taps * self.nch as u64;
    }

    /// A source's shares to the pixels of row `ty` its kernel reaches (on
    /// its surface, or clear of lights, where the guides choose receivers).
    fn add(&self, _: &RowWindow<f32>, s: &Source<G>, shares: &[f64], ty: usize, acc: &mut [f64]) {
        let (w, guides) = (self.w, &self.guides);
        let (taps, widths) = (&self.ladder.taps, &self.ladder.widths);
        let k = s.k as usize;
        let r = widths.reach[k];
        let (sx, sy) = (s.x as usize, s.y as usize);
        if ty + r < sy || ty > sy + r {
            return;
        }
        let g = &taps[k];
        let gy = g[ty + r - sy];
        if gy == 0.0 {
            return;
        }
        let (xa, xb) = (sx.saturating_sub(r), (sx + r + 1).min(w));
        let gx = &g[xa + r - sx..xb + r - sx];
        if guides.chooses_receivers() {
            // The receivers the guides allowed when the width was chosen
            // ([`Treat::norm`]).
            let lights = self.win.light.get(ty);
            let on = s
                .on_surface
                .as_ref()
                .map(|from| (from, self.win.surf.get(ty)));
            for (tx, &wx) in (xa..xb).zip(gx) {
                let ok = match on {
                    Some((from, surfs)) => {
                        let q = (lights[tx] != 0, &surfs[tx]);
                        guides.accepts(q, (tx, ty), Some((from, sx, sy)))
                    }
                    None => lights[tx] == 0,
                };
                if ok {
                    for (j, s) in shares.iter().enumerate() {
                        acc[j * w + tx] += s * gy * wx;
                    }
                }
            }
            return;
        }
        for (j, s) in shares.iter().enumerate() {
            let a = s * gy;
            for (d, &wx) in acc[j * w + xa..j * w + xb].iter_mut().zip(gx) {
                *d += a * wx;
            }
        }
    }

    fn counts(&self) -> MethodCounts {
        MethodCounts::EpGauss(SpreadCounts {
            emissive: self.emissive,
            ..self.counts
        })
    }

    fn windows(&self) -> Vec<WindowUse> {
        let w = self.w;
        vec![
            WindowUse {
                name: "luminance",
                rows: self.win.ylum.high_water(),
                row_bytes: w * 8,
            },
            WindowUse {
                name: "background",
                rows: self.win.bg.high_water(),
                row_bytes: w * 8,
            },
            WindowUse {
                name: "flags",
                rows: self.win.cand.high_water() + self.win.light.high_water(),
                row_bytes: w,
            },
            WindowUse {
                name: "surface guides",
                rows: self.win.surf.high_water(),
                row_bytes: w * std::mem::size_of::<G>(),
            },
        ]
    }
}

impl<G: SurfaceGuides> GaussRule<G> {
    /// The luminance of what the emission guide leaves of rows `a..b`.
    fn luminance(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        for _ in a..b {
            self.win.ylum.push_stale(0.0);
        }
        let guides = &self.guides;
        let region = crate::trace::region("pixel luminance");
        let rows = self.win.ylum.range_mut(a, b);
        rows.into_par_iter().enumerate().for_each(|(k, yrow)| {
            let _task = region.task("pixel luminance");
            let row = input.get(a + k);
            for (x, y) in yrow.iter_mut().enumerate() {
                *y = guides.residual_luminance(row, x);
            }
        });
    }

    /// Backgrounds and Rule 1 for rows `a..b` (their luminance rows within
    /// [`BACKGROUND_REACH`] are in, reflected at the image's edges).
    fn classify(&mut self, a: usize, b: usize) {
        for _ in a..b {
            self.win.bg.push_stale(f64::NAN);
            self.win.cand.push_stale(0);
        }
        let (w, h) = (self.w, self.h);
        let (ylum, light) = (&self.win.ylum, &self.win.light);
        let bgs = self.win.bg.range_mut(a, b);
        let cands = self.win.cand.range_mut(a, b);
        let region = crate::trace::region("pixel classify");
        bgs.into_par_iter()
            .zip(cands)
            .enumerate()
            .for_each(|(k, (brow, crow))| {
                let _task = region.task("pixel classify");
                let y = a + k;
                let r = BACKGROUND_REACH as i64;
                let rows: Vec<&[f64]> = (-r..=r)
                    .map(|d| ylum.get(mirror(y as i64 + d, h)))
                    .collect();
                let mut ring = [0.0f64; BACKGROUND_SAMPLES];
                let lights = light.get(y);
                for x in 0..w {
                    let v = rows[BACKGROUND_REACH][x];
                    brow[x] = f64::NAN;
                    crow[x] = 0;
                    if lights[x] != 0 || !local_max(v, &neighbours8(&rows[1..4], x, w)) {
                        continue;
                    }
                    let mut n = 0;
                    for (dy, row) in rows.iter().enumerate() {
                        for dx in -r..=r {
                            if dy == BACKGROUND_REACH && dx == 0 {
                                continue;
                            }
                            ring[n] = row[mirror(x as i64 + dx, w)];
                            n += 1;
                        }
                    }
                    let bg = median(&mut ring);
                    brow[x] = bg;
                    crow[x] = u8::from(noisy(v, bg));
                }
            });
    }
}

/// The 8 neighbours of column `x` in `rows` (three rows, the pixel's in the
/// middle), reflected at the row's ends.
// Always: the treatment, generic over the surface guides, stopped inlining
// it, and every noisy candidate's test reads it.
#[inline(always)]
fn neighbours8(rows: &[&[f64]], x: usize, w: usize) -> [f64; 8] {
    let (l, r) = (mirror(x as i64 - 1, w), mirror(x as i64 + 1, w));
    [
        rows[0][l], rows[0][x], rows[0][r], rows[1][l], rows[1][r], rows[2][l], rows[2][x],
        rows[2][r],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::guides::GuideLayout;
    use crate::filter::{FilterParams, Method};
    use crate::geometry::Grid;
    use crate::pipeline::ledger::LEDGER_TOL;
    use crate::pipeline::pixel::PixelStage;
    use crate::pipeline::stage::Stage;
    use crate::pipeline::{filter_in_memory, PipelineConfig, StripLayout};

    /// Rec. 709 luminance weights of R, G, B.
    const RGB: [f64; 3] = [0.2126, 0.7152, 0.0722];

    /// A `w x h` R, G, B image (planar rows) of a grainy grey ground.
    fn ground(w: usize, h: usize) -> Vec<f32> {
        let mut v = Vec::with_capacity(w * h * 3);
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..h {
            for c in 0..3 {
                for _ in 0..w {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    let g = 0.8 + 0.4 * (s >> 11) as f32 / (1u64 << 53) as f32;
                    v.push(g * [1.0, 0.9, 0.8][c]);
                }
            }
        }
        v
    }

    fn set(v: &mut [f32], w: usize, (x, y): (usize, usize), rgb: [f32; 3]) {
        for c in 0..3 {
            v[(y * 3 + c) * w + x] = rgb[c];
        }
    }

    fn layout(w: usize, h: usize, names: &[&str], lum: &[f64]) -> StripLayout {
        StripLayout::new(
            Grid {
                in_w: w,
                in_h: h,
                s: 1,
            },
            names.iter().map(|s| s.to_string()).collect(),
            lum.to_vec(),
        )
    }

    /// `img` (R, G, B planar rows) with a normal pass `normal(x)` beside it,
    /// run through ep-gauss at S = 1 with the normals as guides: the output
    /// and the run's figures.
    fn filtered_with_normals(
        img: &[f32],
        (w, h): (usize, usize),
        normal: impl Fn(usize) -> [f32; 3],
    ) -> (Vec<f32>, crate::pipeline::RunStats) {
        let mut rows = Vec::new();
        for y in 0..h {
            rows.extend_from_slice(&img[y * 3 * w..(y + 1) * 3 * w]);
            for c in 0..3 {
                rows.extend((0..w).map(|x| normal(x)[c]));
            }
        }
        let mut job = layout(w, h, &["R", "G", "B"], &RGB);
        job.aux = ["N.X", "N.Y", "N.Z"].map(String::from).to_vec();
        job.guides.normal = Some([3, 4, 5]);
        let p = FilterParams::new(Method::EpGauss, 1);
        filter_in_memory(rows, &job, &p, &PipelineConfig::default()).unwrap()
    }

    /// Once every input row is in, the last rows are treated a strip's
    /// rows at a time: the output rows made at once are never more than a
    /// strip's, and the result is the same for every strip height.
    #[test]
    fn the_last_rows_are_made_a_strip_at_a_time() {
        let (w, h) = (40, 60);
        let mut img = ground(w, h);
        for (x, y) in [(7, 50), (30, 55), (12, 58), (21, 5)] {
            set(&mut img, w, (x, y), [30.0, 28.0, 25.0]);
        }
        let job = layout(w, h, &["R", "G", "B"], &RGB);
        let p = FilterParams::new(Method::EpGauss, 1);
        let mut first = None;
        for strip_rows in [1, 3, 7, h] {
            let cfg = PipelineConfig {
                threads: 2,
                strip_rows,
                ..Default::default()
            };
            let (out, stats) = filter_in_memory(img.clone(), &job, &p, &cfg).unwrap();
            assert!(stats.ep_gauss().unwrap().spread >= 4);
            let made = stats.windows.iter().find(|u| u.name == "output").unwrap();
            assert!(
                made.rows <= strip_rows,
                "strips of {strip_rows}: {}",
                made.rows
            );
            let bits: Vec<u32> = out.iter().map(|v| v.to_bits()).collect();
            assert_eq!(
                *first.get_or_insert(bits.clone()),
                bits,
                "strips of {strip_rows}"
            );
        }
    }

    #[test]
    fn the_halo_is_the_settings_halo() {
        for (mr, cut) in [(16.0, 3.0), (0.6, 3.0), (40.0, 6.0), (2.0, 1.0)] {
            let mut p = FilterParams::new(Method::EpGauss, 1);
            (p.max_radius, p.cutoff) = (mr, cut);
            let v = p.validated().unwrap();
            let stage = |guides| {
                let rule = GaussRule::<crate::filter::guides::Surface>::new(
                    (30, 20),
                    RGB.to_vec(),
                    vec![ChannelMode::Spread; 3],
                    (guides, SurfaceRule::default()),
                    &v,
                );
                PixelStage::new(rule.unwrap())
            };
            let st = stage(GuideLayout::default());
            // Without guides a treatment reads only the flags' rows.
            let settings = crate::filter::halo(&p);
            assert_eq!(st.halo().spread_reach, settings.spread_reach);
            assert_eq!(st.halo().search_reach, 4, "{mr} {cut}");
            let guides = GuideLayout {
                emission: Some(vec![0, 1, 2]),
                ..GuideLayout::default()
            };
            let st = stage(guides);
            assert_eq!(st.halo(), settings, "{mr} {cut}");
        }
    }

    #[test]
    fn a_firefly_gives_its_excess_and_clean_pixels_keep_their_bits() {
        let (w, h) = (64, 48);
        let mut img = ground(w, h);
        set(&mut img, w, (20, 17), [40.0, 40.0, 40.0]);
        let job = layout(w, h, &["R", "G", "B"], &RGB);
        let p = FilterParams::new(Method::EpGauss, 1);
        let (out, stats) =
            filter_in_memory(img.clone(), &job, &p, &PipelineConfig::default()).unwrap();
        let counts = stats.ep_gauss().unwrap();
        assert_eq!((counts.spread, counts.beyond), (1, 0));
        // The firefly keeps about its background, its neighbours get a share
        // each, pixels beyond the kernel keep their bits.
        let at = |v: &[f32], x: usize, y: usize| v[(y * 3 + 1) * w + x];
        assert!(at(&out, 20, 17) < 2.0 && at(&out, 20, 17) > 0.5);
        assert!(at(&out, 21, 17) > at(&img, 21, 17));
        let r = p.cutoff * p.max_radius;
        for y in 0..h {
            for x in 0..w {
                let far = (x as f64 - 20.0).abs() > r || (y as f64 - 17.0).abs() > r;
                if far {
                    assert_eq!(at(&out, x, y).to_bits(), at(&img, x, y).to_bits());
                }
            }
        }
        for e in stats.ledger.iter().map(|l| l.rel_error) {
            assert!(e.abs() < LEDGER_TOL, "{e}");
        }
    }

    #[test]
    fn an_image_without_noise_is_written_bit_for_bit() {
        let (w, h) = (40, 30);
        let img = ground(w, h);
        let job = layout(w, h, &["R", "G", "B"], &RGB);
        let p = FilterParams::new(Method::EpGauss, 1);
        let (out, stats) =
            filter_in_memory(img.clone(), &job, &p, &PipelineConfig::default()).unwrap();
        assert_eq!(stats.ep_gauss().unwrap().noisy, 0);
        assert!(out
            .iter()
            .zip(&img)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    #[test]
    fn a_lamp_the_emission_guide_names_stays_a_firefly_beside_it_goes() {
        let (w, h) = (48, 40);
        let mut img = ground(w, h);
        // A one-pixel bulb and, four pixels away, a firefly of the same
        // brightness: alike without the guide.
        set(&mut img, w, (20, 20), [60.0, 60.0, 60.0]);
        set(&mut img, w, (24, 20), [60.0, 60.0, 60.0]);
        let mut rows = Vec::new();
        for y in 0..h {
            rows.extend_from_slice(&img[y * 3 * w..(y + 1) * 3 * w]);
            for c in 0..3 {
                for x in 0..w {
                    let bulb = (x, y) == (20, 20);
                    rows.push(if bulb { 59.0 + c as f32 * 0.0 } else { 0.0 });
                }
            }
        }
        let mut job = layout(w, h, &["R", "G", "B"], &RGB);
        job.aux = ["emission.R", "emission.G", "emission.B"]
            .map(String::from)
            .to_vec();
        job.guides.emission = Some(vec![3, 4, 5]);
        let p = FilterParams::new(Method::EpGauss, 1);
        let (out, stats) = filter_in_memory(rows, &job, &p, &PipelineConfig::default()).unwrap();
        let at = |x: usize, y: usize| out[(y * 3 + 1) * w + x];
        // The bulb keeps its emission (and whatever spread reaches it).
        assert!(at(20, 20) >= 59.0, "{}", at(20, 20));
        assert!(at(24, 20) < 5.0, "{}", at(24, 20));
        assert_eq!(stats.ep_gauss().unwrap().spread, 1);
        for e in stats.ledger.iter().map(|l| l.rel_error) {
            assert!(e.abs() < LEDGER_TOL, "{e}");
        }
    }

    /// A firefly on a surface one pixel wide (a sliver of other normals
    /// down column 22): its kernel is mostly off its surface, so it keeps
    /// clear of lights only ([`crate::filter::guides::SURFACE_SHARE`]) and most of its excess
    /// lands off the sliver, where keeping to its surface (which could take
    /// it) would pile all of it on the column.
    #[test]
    fn a_firefly_on_a_sliver_spreads_clear_of_lights_only() {
        let (w, h) = (48, 40);
        let mut img = ground(w, h);
        // Faint enough that the column alone could take it within the cap.
        set(&mut img, w, (22, 20), [6.0, 6.0, 6.0]);
        let (out, stats) = filtered_with_normals(&img, (w, h), |x| {
            if x == 22 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            }
        });
        assert_eq!(stats.ep_gauss().unwrap().spread, 1);
        let moved = |on: bool| -> f64 {
            (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .filter(|&(x, y)| (x == 22) == on && (x, y) != (22, 20))
                .map(|(x, y)| (out[(y * 3 + 1) * w + x] - img[(y * 3 + 1) * w + x]) as f64)
                .sum()
        };
        let (on, off) = (moved(true), moved(false));
        // Most of it lands off the sliver (keeping to it would leave none
        // there).
        assert!(off > on, "on the sliver {on}, off it {off}");
        for e in stats.ledger.iter().map(|l| l.rel_error) {
            assert!(e.abs() < LEDGER_TOL, "{e}");
        }
    }

    #[test]
    fn a_surface_guide_keeps_a_spread_on_its_side_of_an_edge() {
        let (w, h) = (48, 40);
        let mut img = ground(w, h);
        set(&mut img, w, (22, 20), [50.0, 50.0, 50.0]);
        // Normals: up on the left of x = 24, facing the camera from there.
        let (out, stats) = filtered_with_normals(&img, (w, h), |x| {
            if x < 24 {
                [0.0, 1.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            }
        });
        assert_eq!(stats.ep_gauss().unwrap().spread, 1);
        for y in 0..h {
            for x in 24..w {
                let k = (y * 3 + 1) * w + x;
                assert_eq!(out[k].to_bits(), img[k].to_bits(), "({x}, {y})");
            }
        }
        let left: f64 = (0..h)
            .flat_map(|y| (0..24).map(move |x| (x, y)))
            .map(|(x, y)| (out[(y * 3 + 1) * w + x] - img[(y * 3 + 1) * w + x]) as f64)
            .sum();
        assert!(left.abs() < 1e-3, "{left}");
        for e in stats.ledger.iter().map(|l| l.rel_error) {
            assert!(e.abs() < LEDGER_TOL, "{e}");
        }
    }
}
