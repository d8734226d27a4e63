//! ep-box (§5.1) as a [`Rule`] of [`super::PixelStage`] (the rules are in
//! [`crate::filter::ep_box`]).
//!
//! Input is at pixel resolution: colour channels, then the statistics
//! channels (variance, and perhaps the sample count), all in one strip row.
//! Its passes over pixel rows:
//!
//! 1. the **statistics**: luminance, `t * S_p` and the noise flag;
//! 2. the **decision**: noisy by the paper's test and, with the carriers
//!    guard, not a compact bright feature (the flags within
//!    [`CLUSTER_REACH`]);
//! 3. the **treatment**: the passes over the band `y ± passes` decide each
//!    noisy pixel's excess (see `filter::ep_box`), the pixel keeps the
//!    rest, and it is listed as a source whose ring prefix receives it
//!    (with guides, the receivers' surfaces within the ring's reach).
//!
//! The treatment of a pixel reads only the input within `passes` of it (its
//! receivers' within the ring).

use std::ops::Range;

use rayon::iter::{IndexedParallelIterator, IntoParallelIterator, ParallelIterator};

use super::guided::GuideReader;
use super::{Placed, Rule};
use crate::error::{Error, Result};
use crate::filter::ep_box::{
    cluster_count, colour_fraction, excess, passes::chebyshev_passes, receivers, EpBoxParams,
    Guard, PixelTest, Ring, Spp, StatsLayout, TFactor,
};
use crate::filter::guides::{keeps_to_surface, GuideLayout, Surface, SurfaceRule};
use crate::filter::ValidParams;
use crate::pipeline::counts::{ExcessCounts, MethodCounts};
use crate::pipeline::schedule::Reads;
use crate::pipeline::stage::WindowUse;
use crate::pipeline::window::RowWindow;
use crate::pipeline::ChannelMode;

/// A pixel whose excess is spread.
#[derive(Clone, Copy, Debug)]
pub struct Source {
    x: u32,
    y: u32,
    /// Offsets of the ring walked.
    m: u32,
    /// Its surface guides (with surface guides on: only the pixels of its
    /// surface receive, where it keeps to it).
    surface: Surface,
    /// It keeps to its surface (else only clear of lights).
    on_surface: bool,
}

impl Placed for Source {
    fn at(&self) -> (usize, usize) {
        (self.x as usize, self.y as usize)
    }
}

/// The excess rule's settings and factors, set once.
struct Factors {
    params: EpBoxParams,
    ltvis: f64,
    dl: f64,
    t: TFactor,
    /// Factors of the `stderr` guard's bound.
    tg: TFactor,
    ring: Ring,
    /// The ring's offsets by row: `rows[dy + reach]` lists the index and
    /// `dx` of each offset of row `dy`, in the ring's order.
    ring_rows: Vec<Vec<(u32, i32)>>,
    passes: usize,
    reach: usize,
}

/// The rows the passes hold, each of the image's width.
struct Windows {
    ylum: RowWindow<f64>,
    /// `t_g * S_p`: the most of a pixel's excess that noise can explain.
    cap: RowWindow<f64>,
    /// What the statistics say of each pixel ([`RAW_NOISY`] ...).
    raw: RowWindow<u8>,
    /// The decision: 1 noisy, 0 converged (or reliable).
    noisy: RowWindow<u8>,
}

/// ep-box's rule, and what its passes hold.
pub struct ExcessRule {
    w: usize,
    h: usize,
    nch: usize,
    lum: Vec<f64>,
    /// The channels that give up the excess (the colour and additive
    /// layers).
    spread: Vec<usize>,
    stats: StatsLayout,
    factors: Factors,
    win: Windows,
    counters: ExcessCounts,
    guides: GuideReader,
}

impl ExcessRule {
    /// The rule for a `w x h` image whose strips hold `nch` filtered colour
    /// channels (luminance weights `lum`) followed by `aux` statistics
    /// channels laid out as `stats` says. `ltvis` is the visibility
    /// threshold (Eq. 9); the spread radius is `params.max_radius`. The
    /// skeleton has checked the grid, the channels and the tile.
    pub fn new(
        (w, h): (usize, usize),
        (lum, modes, aux): (Vec<f64>, Vec<ChannelMode>, usize),
        stats: StatsLayout,
        (params, ltvis): (&ValidParams, f64),
        (guides, rule): (GuideLayout, SurfaceRule),
    ) -> Result<Self> {
        let nch = modes.len();
        let max_radius = params.max_radius;
        let params: &EpBoxParams = &params.ep_box;
        // Statistics are read beside the filtered channels, or where they
        // are carried as they are read (never a channel that gives up light).
        let nall = nch + aux;
        let in_range = |i: usize| i < nall && modes.get(i) != Some(&ChannelMode::Spread);
        let var_ok = (stats.variance.len() == 1 || stats.variance.len() == 3)
            && stats.variance.iter().all(|&i| in_range(i))
            && stats.mean_y.is_none_or(in_range)
            && match stats.spp {
                Spp::Channel(i) => in_range(i),
                Spp::Fixed(n) => n.is_finite() && n >= 2.0,
            };
        if !var_ok {
            return Err(Error::Config(
                "ep-box needs one or three variance channels and a sample count of at least 2"
                    .into(),
            ));
        }
        if stats.variance.len() == 3 && lum.iter().filter(|&&l| l > 0.0).count() != 3 {
            return Err(Error::Config(
                "three variance channels need three colour channels (R, G, B)".into(),
            ));
        }
        if !(ltvis.is_finite() && ltvis > 0.0) {
            return Err(Error::Config(format!(
                "the visibility threshold L_tvis is {ltvis:e}: the image's mean luminance is not positive; give --ltvis"
            )));
        }
        if !(max_radius.is_finite() && (1.0..=128.0).contains(&max_radius)) {
            return Err(Error::Config(format!(
                "--max-radius must be in 1..=128 pixels for ep-box, got {max_radius}"
            )));
        }
        let ring = Ring::new(max_radius);
        let reach = ring.radius();
        let mut ring_rows = vec![Vec::new(); 2 * reach + 1];
        for (i, &(dx, dy)) in ring.offsets().iter().enumerate() {
            ring_rows[(dy + reach as i32) as usize].push((i as u32, dx));
        }
        let guides = GuideReader::new(guides, rule, &lum, nch, w)?;
        Ok(ExcessRule {
            w,
            h,
            nch,
            lum,
            spread: (0..nch)
                .filter(|&c| modes[c] == ChannelMode::Spread)
                .collect(),
            stats,
            factors: Factors {
                params: params.clone(),
                ltvis,
                dl: params.d * ltvis,
                t: TFactor::new(params.confidence),
                tg: TFactor::new(params.guard_confidence),
                passes: params.passes,
                reach,
                ring,
                ring_rows,
            },
            win: Windows {
                ylum: RowWindow::new(w),
                cap: RowWindow::new(w),
                raw: RowWindow::new(w),
                noisy: RowWindow::new(w),
            },
            counters: ExcessCounts::default(),
            guides,
        })
    }
}

/// The passes after the input and what each reads: the statistics, the
/// decision (the cluster look's), the treatment (the passes' and the
/// guards'; its receivers' guides within the ring's `reach`).
pub fn passes(passes: usize, reach: usize) -> Vec<Reads> {
    let band = passes + GUARD_REACH;
    vec![
        vec![(0, 0)],
        vec![(1, CLUSTER_REACH)],
        vec![(2, band), (1, band), (0, reach)],
    ]
}

impl Rule for ExcessRule {
    type Source = Source;
    type Tally = ExcessCounts;
    /// Each task recomputes `2 * passes` rows of band around its own, so
    /// tasks should be several times taller than that.
    const TREAT_ROWS: usize = 32;
    /// A task's passes run over its pixels and `passes` either side: a
    /// wide strip is cut in columns, whose margins are a few columns more.
    const TREAT_COLUMNS: usize = 4096;

    fn shape(&self) -> (usize, usize, usize) {
        (self.w, self.h, self.nch)
    }

    fn passes(&self) -> Vec<Reads> {
        passes(self.factors.passes, self.factors.reach)
    }

    fn spread(&self) -> &[usize] {
        &self.spread
    }

    fn reach(&self) -> usize {
        self.factors.reach
    }

    fn make(&mut self, pass: usize, input: &RowWindow<f32>, a: usize, b: usize) {
        match pass {
            1 => self.statistics(input, a, b),
            _ => self.decide(a, b),
        }
    }

    fn evict(&mut self, pass: usize, y: usize) {
        match pass {
            0 => {}
            1 => {
                self.win.ylum.evict_below(y);
                self.win.cap.evict_below(y);
                self.win.raw.evict_below(y);
            }
            _ => self.win.noisy.evict_below(y),
        }
    }

    fn treat(
        &self,
        input: &RowWindow<f32>,
        rows: Range<usize>,
        columns: Range<usize>,
    ) -> (Vec<Source>, Vec<f64>, ExcessCounts) {
        self.band(input).treat(rows, columns)
    }

    fn tally(&mut self, c: ExcessCounts, _: &[Source]) {
        let k = &mut self.counters;
        k.noisy += c.noisy;
        k.spread += c.spread;
        k.capped += c.capped;
        k.guarded += c.guarded;
        k.trimmed += c.trimmed;
        k.unresolved += c.unresolved;
        k.passes = k.passes.max(c.passes);
    }

    /// A source's share to each in-image pixel of row `ty` in its ring
    /// prefix (those its guides accept, where they choose receivers).
    fn add(&self, input: &RowWindow<f32>, s: &Source, shares: &[f64], ty: usize, acc: &mut [f64]) {
        let (w, reach) = (self.w, self.factors.reach);
        let g = self.guides.chooses_receivers().then_some(&self.guides);
        let (sx, sy, m) = (s.x as usize, s.y as usize, s.m);
        if ty + reach < sy || ty > sy + reach {
            return;
        }
        let from = s.on_surface.then_some((&s.surface, sx, sy));
        let row = input.get(ty);
        for &(i, dx) in &self.factors.ring_rows[ty + reach - sy] {
            if i >= m {
                break;
            }
            let tx = sx as i64 + dx as i64;
            if tx < 0 || tx >= w as i64 {
                continue;
            }
            let tx = tx as usize;
            if g.is_some_and(|g| !g.accepts_in(row, (tx, ty), from)) {
                continue;
            }
            for (j, s) in shares.iter().enumerate() {
                acc[j * w + tx] += s;
            }
        }
    }

    fn counts(&self) -> MethodCounts {
        MethodCounts::EpBox(self.counters)
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
                name: "guard bound",
                rows: self.win.cap.high_water(),
                row_bytes: w * 8,
            },
            WindowUse {
                name: "flags",
                rows: self.win.raw.high_water() + self.win.noisy.high_water(),
                row_bytes: w,
            },
        ]
    }
}

impl ExcessRule {
    /// Luminance, what the statistics say ([`RAW_NOISY`], [`RAW_CARRIED`],
    /// [`RAW_FEW`]) and the stderr guard's bound of rows `a..b`.
    fn statistics(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        for _ in a..b {
            self.win.ylum.push_stale(0.0);
            self.win.cap.push_stale(0.0);
            self.win.raw.push_stale(0);
        }
        let w = self.w;
        let (lum, stats, dl) = (&self.lum, &self.stats, self.factors.dl);
        let (t, tg) = (&self.factors.t, &self.factors.tg);
        let ys = self.win.ylum.range_mut(a, b);
        let cs = self.win.cap.range_mut(a, b);
        let fs = self.win.raw.range_mut(a, b);
        let params = &self.factors.params;
        let guides = &self.guides;
        let region = crate::trace::region("ep-box statistics");
        ys.into_par_iter()
            .zip(cs)
            .zip(fs)
            .enumerate()
            .for_each(|(k, ((yrow, crow), frow))| {
                let _task = region.task("ep-box statistics");
                let row = input.get(a + k);
                let ch = |c: usize, x: usize| row[c * w + x] as f64;
                for x in 0..w {
                    // What the emission guide leaves: a lamp's own light
                    // is neither an excess nor a neighbour's mean.
                    let y = guides.residual_luminance(row, x);
                    yrow[x] = y;
                    let (n, se2) = stats.pixel(lum, y, |c| ch(c, x));
                    let mut test = PixelTest::new(y, se2, n, t.get(n), dl, params);
                    if guides.is_light(row, x, y) {
                        test = PixelTest::default();
                    }
                    let f = (u8::from(test.noisy) * RAW_NOISY)
                        | (u8::from(test.carried) * RAW_CARRIED)
                        | (u8::from(test.few) * RAW_FEW);
                    crow[x] = tg.get(n) * se2.sqrt();
                    frow[x] = f;
                }
            });
    }

    /// The decision for rows `a..b` (rows `a - 2 .. b + 2` have their
    /// statistics): noisy by the paper's test and, with the carriers guard,
    /// neither carried by enough samples nor a compact bright feature.
    fn decide(&mut self, a: usize, b: usize) {
        let (w, h) = (self.w, self.h);
        for _ in a..b {
            self.win.noisy.push_stale(0);
        }
        let (raw, ylum) = (&self.win.raw, &self.win.ylum);
        let guard = self.factors.params.guard;
        let rows = self.win.noisy.range_mut(a, b);
        let region = crate::trace::region("ep-box decide");
        let reliable: u64 = rows
            .into_par_iter()
            .enumerate()
            .map(|(k, frow)| {
                let _task = region.task("ep-box decide");
                let y = a + k;
                let mut reliable = 0;
                let r = raw.get(y);
                for x in 0..w {
                    let f = r[x];
                    let test = PixelTest {
                        noisy: f & RAW_NOISY != 0,
                        carried: f & RAW_CARRIED != 0,
                        few: f & RAW_FEW != 0,
                    };
                    let noise = test.is_noise(guard, || compact(raw, ylum, x, y, w, h));
                    frow[x] = u8::from(noise);
                    reliable += u64::from(test.noisy && !noise);
                }
                reliable
            })
            .sum();
        self.counters.reliable += reliable;
    }

    /// What a treatment task reads.
    fn band<'a>(&'a self, input: &'a RowWindow<f32>) -> Band<'a> {
        Band {
            w: self.w,
            h: self.h,
            input,
            ylum: &self.win.ylum,
            cap: &self.win.cap,
            noisy: &self.win.noisy,
            spread: &self.spread,
            passes: self.factors.passes,
            dl: self.factors.dl,
            ltvis: self.factors.ltvis,
            guard: self.factors.params.guard,
            ring: &self.factors.ring,
            guides: &self.guides,
        }
    }
}

/// What one treatment task reads.
struct Band<'a> {
    w: usize,
    h: usize,
    input: &'a RowWindow<f32>,
    ylum: &'a RowWindow<f64>,
    cap: &'a RowWindow<f64>,
    noisy: &'a RowWindow<u8>,
    spread: &'a [usize],
    passes: usize,
    dl: f64,
    ltvis: f64,
    guard: Guard,
    ring: &'a Ring,
    guides: &'a GuideReader,
}

/// Raw flags: noisy by the paper's test (`t S_p > D L_tvis`) ...
const RAW_NOISY: u8 = 1;
/// ... its mean carried by enough samples to be reliable ...
const RAW_CARRIED: u8 = 2;
/// ... by enough for a compact feature ([`COMPACT_CARRIERS`]).
const RAW_FEW: u8 = 4;

/// Whether the pixels the paper's test calls noisy within [`CLUSTER_REACH`]
/// of `(x, y)` (itself included) whose luminance is within a factor
/// [`COMPACT_RATIO`] of its own are at most [`COMPACT_MAX`]: a small bright
/// feature (a bulb a fraction of a pixel wide hits up to four pixels), faint
/// noise around it or not; not a stretch of noise of its own brightness (a
/// caustic, a penumbra, a glossy floor where many pixels are hit alike).
fn compact(
    raw: &RowWindow<u8>,
    ylum: &RowWindow<f64>,
    x: usize,
    y: usize,
    w: usize,
    h: usize,
) -> bool {
    let n = cluster_count(
        (x, y),
        (w, h),
        ylum.get(y)[x],
        |xx, yy| ylum.get(yy)[xx],
        |xx, yy| raw.get(yy)[xx] & RAW_NOISY != 0,
    );
    n <= COMPACT_MAX
}

pub use crate::filter::ep_box::{CLUSTER_REACH, COMPACT_MAX, GUARD_REACH};

impl Band<'_> {
    /// The brightest converged pixel within [`GUARD_REACH`] of band row `r`
    /// (of `bh` from image row `ba`), column `x`: the `range` guard's bound.
    fn brightest_converged(&self, ba: usize, bh: usize, r: usize, x: usize) -> f64 {
        let mut max = f64::NEG_INFINITY;
        for rr in r.saturating_sub(GUARD_REACH)..(r + GUARD_REACH + 1).min(bh) {
            let (fl, yl) = (self.noisy.get(ba + rr), self.ylum.get(ba + rr));
            for xx in x.saturating_sub(GUARD_REACH)..(x + GUARD_REACH + 1).min(self.w) {
                if fl[xx] == 0 {
                    max = max.max(yl[xx]);
                }
            }
        }
        max
    }

    /// The ring prefix a source at `(x, yy)` on `surface` spreads `wanted`
    /// receivers' worth over: the offsets walked, the receivers found, and
    /// whether it keeps to its surface (where the guides choose receivers).
    fn ring_prefix(
        &self,
        (x, yy): (usize, usize),
        surface: &Surface,
        wanted: usize,
    ) -> (usize, usize, bool) {
        let (w, h, g) = (self.w, self.h, self.guides);
        if g.chooses_receivers() {
            let walk = |on: bool| {
                let from = on.then_some((surface, x, yy));
                let accepts =
                    |tx: usize, ty: usize| g.accepts_in(self.input.get(ty), (tx, ty), from);
                self.ring.prefix_where(x, yy, (w, h), wanted, accepts)
            };
            // A source whose nearest receivers are mostly on other
            // surfaces sits on an edge or a sliver, and one whose
            // surface has too few within the ring would pile its excess
            // on them: both keep clear of lights only (`keeps_to_surface`).
            let (m0, found0) = walk(false);
            let kept = g.surface().then(|| walk(true)).filter(|&(_, found)| {
                let mine = self.ring.offsets()[..m0]
                    .iter()
                    .filter(|&&(dx, dy)| {
                        let (tx, ty) = (x as i64 + dx as i64, yy as i64 + dy as i64);
                        tx >= 0
                            && ty >= 0
                            && (tx as usize) < w
                            && (ty as usize) < h
                            && g.accepts_in(
                                self.input.get(ty as usize),
                                (tx as usize, ty as usize),
                                Some((surface, x, yy)),
                            )
                    })
                    .count();
                found >= found0 && keeps_to_surface(mine as f64, found0 as f64)
            });
            match kept {
                Some((m, found)) => (m, found, true),
                None => (m0, found0, false),
            }
        } else {
            let (m, found) = self.ring.prefix(x, yy, w, h, wanted);
            (m, found, false)
        }
    }

    /// Treat the pixels of `rows` and `columns`: the passes over the band of
    /// pixels `passes` (and the guard's reach) either side, which holds
    /// everything their decisions read (see `filter::ep_box`). The sources in row-major order, their
    /// values (per source what its pixel keeps, then what each receiver
    /// gets, a value a spread channel each) and what it counted.
    fn treat(
        &self,
        rows: Range<usize>,
        columns: Range<usize>,
    ) -> (Vec<Source>, Vec<f64>, ExcessCounts) {
        let (w, h, n) = (self.w, self.h, self.spread.len());
        let margin = self.passes + GUARD_REACH;
        let ba = rows.start.saturating_sub(margin);
        let bb = (rows.end + margin).min(h);
        let bh = bb - ba;
        // The band's columns: the same margin either side.
        let xa = columns.start.saturating_sub(margin);
        let xb = (columns.end + margin).min(w);
        let mut counters = ExcessCounts::default();
        let in_target = |r: usize, x: usize| rows.contains(&(ba + r)) && columns.contains(&x);
        counters.noisy = (rows.clone())
            .map(|y| {
                self.noisy.get(y)[columns.clone()]
                    .iter()
                    .filter(|&&f| f != 0)
                    .count() as u64
            })
            .sum();
        let (mut sources, mut values) = (Vec::new(), Vec::new());
        let settle = |r: usize, bx: usize, k: u8, mean: f64| -> f64 {
            let x = xa + bx;
            let y = self.ylum.get(ba + r)[x];
            let target = in_target(r, x);
            if target {
                counters.passes = counters.passes.max(k as u64);
            }
            let e = excess(
                y,
                mean,
                self.dl,
                self.ltvis,
                self.guard,
                || self.brightest_converged(ba, bh, r, x),
                self.cap.get(ba + r)[x],
            );
            if target {
                counters.guarded += u64::from(e.guarded);
                counters.trimmed += u64::from(e.trimmed);
            }
            let excess = e.value;
            if excess == 0.0 || !target {
                return excess;
            }
            let yy = ba + r;
            let wanted = receivers(excess, self.ltvis, self.ring.offsets().len());
            let g = self.guides;
            let src = self.input.get(yy);
            let surface = g.surface_of(src, x);
            let (m, found, on_surface) = self.ring_prefix((x, yy), &surface, wanted);
            counters.spread += 1;
            counters.capped += u64::from(found < wanted);
            let f = colour_fraction(excess, y);
            g.give_up(&mut values, (src, x), self.spread, (f, found as f64));
            sources.push(Source {
                x: x as u32,
                y: yy as u32,
                m: m as u32,
                surface,
                on_surface,
            });
            excess
        };
        let bw = xb - xa;
        let unresolved = chebyshev_passes(
            (bw, bh),
            |r| &self.noisy.get(ba + r)[xa..xb],
            |r| &self.ylum.get(ba + r)[xa..xb],
            self.passes,
            settle,
        );
        counters.unresolved = unresolved
            .iter()
            .filter(|&&i| in_target(i as usize / bw, xa + i as usize % bw))
            .count() as u64;
        // The passes settle pixels ring by ring: row-major for the output.
        let mut order: Vec<usize> = (0..sources.len()).collect();
        order.sort_by_key(|&i| (sources[i].y, sources[i].x));
        let values = (order.iter())
            .flat_map(|&i| values[i * 2 * n..(i + 1) * 2 * n].iter().copied())
            .collect();
        let sources = order.iter().map(|&i| sources[i]).collect();
        (sources, values, counters)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::ep_box::VarianceKind;
    use crate::filter::{FilterParams, Method};
    use crate::pipeline::pixel::PixelStage;
    use crate::pipeline::stage::Stage;

    #[test]
    fn the_halo_is_the_settings_halo() {
        for (passes, max_radius) in [(8, 16.0), (1, 1.0), (2, 40.0), (30, 3.0)] {
            let mut p = FilterParams::new(Method::EpBox, 1);
            (p.ep_box.passes, p.max_radius) = (passes, max_radius);
            let stats = StatsLayout {
                variance: vec![3],
                kind: VarianceKind::Sample,
                mean_y: None,
                spp: Spp::Fixed(16.0),
            };
            let rule = ExcessRule::new(
                (30, 20),
                (
                    vec![0.2126, 0.7152, 0.0722],
                    vec![ChannelMode::Spread; 3],
                    1,
                ),
                stats,
                (&p.validated().unwrap(), 0.01),
                (GuideLayout::default(), SurfaceRule::default()),
            );
            let stage = PixelStage::new(rule.unwrap());
            assert_eq!(
                stage.halo(),
                crate::filter::halo(&p),
                "{passes} {max_radius}"
            );
        }
    }
}
