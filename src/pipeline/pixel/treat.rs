//! The treatment of ep-gauss's pixel stage: each noisy pixel's feature
//! rules, its width (the search over the ladder, with the guides' receivers)
//! and the kept rows, one task per band of rows.

use super::{neighbours8, PixelStage, Source, SURFACE_SHARE};
use crate::filter::ep_gauss::pixel::{in_range, supported, BACKGROUND_REACH};
use crate::filter::guides::Surface;
use crate::geometry::mirror;
use crate::pipeline::counts::SpreadCounts;
use crate::pipeline::window::RowWindow;
use crate::pipeline::ChannelMode;

/// What a treatment task found: the sources, their shares and masks, and
/// what it counted.
pub(super) struct Treated {
    pub(super) sources: Vec<Source>,
    pub(super) shares: Vec<f64>,
    pub(super) masks: Vec<u64>,
    pub(super) counts: SpreadCounts,
}

/// What a treatment task reads.
pub(super) struct Treat<'a> {
    pub(super) stage: &'a PixelStage,
    pub(super) input: &'a RowWindow<f32>,
}

impl Treat<'_> {
    /// Treat rows `y0..y0 + kept.len()`: copy them into `kept`, then take
    /// each noisy pixel's excess out and list it as a source.
    pub(super) fn rows(&self, y0: usize, mut kept: Vec<&mut [f64]>) -> Treated {
        let st = self.stage;
        let (w, h, nch) = (st.w, st.h, st.nch);
        let mut counts = SpreadCounts::default();
        let (mut sources, mut shares, mut masks) = (Vec::new(), Vec::new(), Vec::new());
        let (mut cur, mut best) = (Vec::new(), Vec::new());
        for (k, out) in kept.iter_mut().enumerate() {
            let y = y0 + k;
            let src = self.input.get(y);
            for (d, &v) in out.iter_mut().zip(&src[..nch * w]) {
                *d = v as f64;
            }
            let r = BACKGROUND_REACH as i64;
            let lrows: Vec<&[f64]> = (-1..=1)
                .map(|d| st.win.ylum.get(mirror(y as i64 + d, h)))
                .collect();
            let cand = st.win.cand.get(y);
            let bgrow = st.win.bg.get(y);
            for x in (0..w).filter(|&x| cand[x] != 0) {
                counts.noisy += 1;
                let (v, bg) = (lrows[1][x], bgrow[x]);
                if st.rule.features {
                    let n8 = neighbours8(&lrows, x, w);
                    let calm = || {
                        let mut m = f64::NEG_INFINITY;
                        for yy in (y as i64 - r).max(0)..(y as i64 + r + 1).min(h as i64) {
                            let (f, l) =
                                (st.win.cand.get(yy as usize), st.win.ylum.get(yy as usize));
                            for xx in (x as i64 - r).max(0)..(x as i64 + r + 1).min(w as i64) {
                                let xx = xx as usize;
                                if f[xx] == 0 {
                                    m = m.max(l[xx]);
                                }
                            }
                        }
                        m
                    };
                    if supported(v, bg, &n8) || in_range(v, calm()) {
                        counts.kept += 1;
                        continue;
                    }
                }
                let excess = v - bg;
                let surface = st.guides.surface_of(src, x);
                let scratch = (&mut cur, &mut best);
                let Some((k, norm, capped)) = self.width((x, y), excess, bg, &surface, scratch)
                else {
                    counts.beyond += 1;
                    continue;
                };
                counts.spread += 1;
                counts.capped += u64::from(capped);
                let f = excess / v;
                let off = shares.len();
                for c in 0..nch {
                    let mut share = 0.0;
                    if st.modes[c] == ChannelMode::Spread {
                        let removed = st.guides.residual(src, c, x) * f;
                        out[c * w + x] -= removed;
                        share = removed / norm;
                    }
                    shares.push(share);
                }
                let mask = masks.len();
                if st.guides.chooses_receivers() {
                    masks.extend_from_slice(&best);
                }
                sources.push(Source {
                    x: x as u32,
                    y: y as u32,
                    k: k as u32,
                    off,
                    mask,
                });
            }
        }
        Treated {
            sources,
            shares,
            masks,
            counts,
        }
    }

    /// The first rung, from the ladder's guess up, whose kernel (normalised
    /// over the in-image pixels it reaches, those the guides allow) gives
    /// its centre at most `tolerance * bg` of `excess`, and that
    /// normalisation; when no rung within the cap does, the cap (flagged)
    /// where the guides' receivers alone made it so, else `None`.
    fn width(
        &self,
        (x, y): (usize, usize),
        excess: f64,
        bg: f64,
        surface: &Surface,
        (cur, best): (&mut Vec<u64>, &mut Vec<u64>),
    ) -> Option<(usize, f64, bool)> {
        let st = self.stage;
        let limit = st.rule.tolerance * bg;
        let cap = st.rule.widths.rho.len() - 1;
        // Even the whole plane's kernel at the cap is too narrow: left.
        let first = st.rule.widths.first_within(excess, bg, st.rule.tolerance)?;
        let passes = |norm: f64| norm > 0.0 && excess <= limit * norm;
        // A source keeps to its surface where the surface has room for it:
        // one with little of its kernel there sits on an edge or a sliver
        // (its guides a mix of its samples'), and one whose surface cannot
        // hold its excess within the tolerance would pile it on the few
        // pixels that match. Both keep clear of lights only.
        let mut on_surface = st.guides.surface().then_some(surface);
        let at_first = self.norm(first, x, y, on_surface, cur);
        if on_surface.is_some() {
            if at_first >= SURFACE_SHARE * self.plain_norm(first, x, y) {
                if let Some(found) =
                    self.search((x, y), first, at_first, on_surface, passes, (cur, best))
                {
                    return Some((found.0, found.1, false));
                }
            }
            on_surface = None;
        }
        let at_first = if st.guides.surface() {
            self.norm(first, x, y, None, cur)
        } else {
            at_first
        };
        if let Some((k, norm)) =
            self.search((x, y), first, at_first, on_surface, passes, (cur, best))
        {
            return Some((k, norm, false));
        }
        // The lights the guides leave out made the kernel too narrow: a
        // pixel the kernel over every pixel spreads within the cap is spread
        // at the cap clear of them (the guides never leave in place what
        // ep-gauss spreads without them). `best` holds the cap's bits.
        let plain = st.guides.chooses_receivers() && excess <= limit * self.plain_norm(cap, x, y);
        let at_cap = self.norm(cap, x, y, None, best);
        (plain && at_cap > 0.0).then_some((cap, at_cap, true))
    }

    /// The first rung from `first` (whose sum is `at_first`) up to the cap
    /// whose kernel over the receivers `on_surface` allows `passes`, and its
    /// sum; its receivers' bits in `best`. The sum grows with the rung
    /// (every weight does): gallop up from the ladder's guess (most kernels
    /// pass there or a rung or two above, and a width costs its area), then
    /// bisect.
    fn search(
        &self,
        (x, y): (usize, usize),
        first: usize,
        at_first: f64,
        on_surface: Option<&Surface>,
        passes: impl Fn(f64) -> bool,
        (cur, best): (&mut Vec<u64>, &mut Vec<u64>),
    ) -> Option<(usize, f64)> {
        let cap = self.stage.rule.widths.rho.len() - 1;
        let (mut lo, mut step) = (None, 1);
        let mut k = first;
        let (mut hi, mut at_hi) = loop {
            let at = if k == first {
                at_first
            } else {
                self.norm(k, x, y, on_surface, cur)
            };
            if passes(at) {
                std::mem::swap(cur, best);
                break (k, at);
            }
            if k == cap {
                return None;
            }
            lo = Some(k);
            k = (k + step).min(cap);
            step *= 2;
        };
        let Some(mut lo) = lo else {
            return Some((hi, at_hi));
        };
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            let at_mid = self.norm(mid, x, y, on_surface, cur);
            if passes(at_mid) {
                std::mem::swap(cur, best);
                (hi, at_hi) = (mid, at_mid);
            } else {
                lo = mid;
            }
        }
        Some((hi, at_hi))
    }

    /// The sum of rung `k`'s weights over the in-image pixels it reaches
    /// from `(x, y)`, every one of them.
    fn plain_norm(&self, k: usize, x: usize, y: usize) -> f64 {
        let st = self.stage;
        let r = st.rule.widths.reach[k];
        let g = &st.rule.taps[k];
        let (xa, xb) = (x.saturating_sub(r), (x + r + 1).min(st.w));
        let (ya, yb) = (y.saturating_sub(r), (y + r + 1).min(st.h));
        let sx: f64 = (xa..xb).map(|tx| g[tx + r - x]).sum();
        let sy: f64 = (ya..yb).map(|ty| g[ty + r - y]).sum();
        sx * sy
    }

    /// The sum of rung `k`'s weights over the in-image pixels it reaches
    /// from `(x, y)` (those on the source's surface, with surface guides).
    fn norm(
        &self,
        k: usize,
        x: usize,
        y: usize,
        surface: Option<&Surface>,
        mask: &mut Vec<u64>,
    ) -> f64 {
        let st = self.stage;
        let (w, h) = (st.w, st.h);
        let r = st.rule.widths.reach[k];
        let g = &st.rule.taps[k];
        let (xa, xb) = (x.saturating_sub(r), (x + r + 1).min(w));
        let (ya, yb) = (y.saturating_sub(r), (y + r + 1).min(h));
        if !st.guides.chooses_receivers() {
            return self.plain_norm(k, x, y);
        }
        let gx = &g[xa + r - x..xb + r - x];
        let side = 2 * r + 1;
        mask.clear();
        mask.resize((side * side).div_ceil(64), 0);
        let mut sum = 0.0;
        for ty in ya..yb {
            let gy = g[ty + r - y];
            let lights = &st.win.light.get(ty)[xa..xb];
            let row = (ty + r - y) * side + xa + r - x;
            let mut part = 0.0;
            match surface {
                Some(from) => {
                    let surfs = &st.win.surf.get(ty)[xa..xb];
                    for (k, (tx, &wx)) in (xa..xb).zip(gx).enumerate() {
                        let q = (lights[k] != 0, &surfs[k]);
                        if st.guides.accepts(q, (tx, ty), Some((from, x, y))) {
                            part += wx;
                            mask[(row + k) / 64] |= 1 << ((row + k) % 64);
                        }
                    }
                }
                None => {
                    for (k, &wx) in gx.iter().enumerate() {
                        if lights[k] == 0 {
                            part += wx;
                            mask[(row + k) / 64] |= 1 << ((row + k) % 64);
                        }
                    }
                }
            }
            sum += gy * part;
        }
        sum
    }
}
