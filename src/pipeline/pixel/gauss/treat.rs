//! The treatment of ep-gauss's pixel stage: each noisy pixel's feature
//! rules, its width (the search over the ladder, with the guides' receivers)
//! and what it keeps, one task per band of rows or row's columns.

use std::ops::Range;

use super::{neighbours8, GaussRule, Source};
use crate::filter::ep_gauss::pixel::{in_range, supported, BACKGROUND_REACH};
use crate::filter::guides::{keeps_to_surface, SurfaceGuides};
use crate::geometry::mirror;
use crate::pipeline::counts::SpreadCounts;
use crate::pipeline::window::RowWindow;

/// What a treatment task reads.
pub(super) struct Treat<'a, G> {
    pub(super) stage: &'a GaussRule<G>,
    pub(super) input: &'a RowWindow<f32>,
}

impl<G: SurfaceGuides> Treat<'_, G> {
    /// Treat the pixels of rows `rows` and columns `columns`: take each
    /// noisy pixel's excess out and list it as a source
    /// ([`super::super::Rule::treat`]).
    pub(super) fn pixels(
        &self,
        rows: Range<usize>,
        columns: Range<usize>,
    ) -> (Vec<Source<G>>, Vec<f64>, SpreadCounts) {
        let st = self.stage;
        let (w, h) = (st.w, st.h);
        let mut counts = SpreadCounts::default();
        let (mut sources, mut values) = (Vec::new(), Vec::new());
        for y in rows {
            let src = self.input.get(y);
            let r = BACKGROUND_REACH as i64;
            let lrows: Vec<&[f64]> = (-1..=1)
                .map(|d| st.win.ylum.get(mirror(y as i64 + d, h)))
                .collect();
            let cand = st.win.cand.get(y);
            let bgrow = st.win.bg.get(y);
            for x in columns.clone().filter(|&x| cand[x] != 0) {
                counts.noisy += 1;
                let (v, bg) = (lrows[1][x], bgrow[x]);
                if st.ladder.features {
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
                let Some((k, norm, capped, on_surface)) = self.width((x, y), excess, bg, &surface)
                else {
                    counts.beyond += 1;
                    continue;
                };
                counts.spread += 1;
                counts.capped += u64::from(capped);
                let f = excess / v;
                st.guides
                    .give_up(&mut values, (src, x), &st.spread, (f, norm));
                sources.push(Source {
                    x: x as u32,
                    y: y as u32,
                    k: k as u32,
                    on_surface: on_surface.then_some(surface),
                });
            }
        }
        (sources, values, counts)
    }

    /// The first rung, from the ladder's guess up, whose kernel (normalised
    /// over the in-image pixels it reaches, those the guides allow) gives
    /// its centre at most `tolerance * bg` of `excess`, and that
    /// normalisation; when no rung within the cap does, the cap (flagged)
    /// where the guides' receivers alone made it so, else `None`. Last,
    /// whether it keeps to its surface (else, with guides that choose
    /// receivers, it keeps clear of lights only).
    fn width(
        &self,
        (x, y): (usize, usize),
        excess: f64,
        bg: f64,
        surface: &G,
    ) -> Option<(usize, f64, bool, bool)> {
        let st = self.stage;
        let limit = st.ladder.tolerance * bg;
        let cap = st.ladder.widths.rho.len() - 1;
        // Even the whole plane's kernel at the cap is too narrow: left.
        let first = st
            .ladder
            .widths
            .first_within(excess, bg, st.ladder.tolerance)?;
        let passes = |norm: f64| norm > 0.0 && excess <= limit * norm;
        // A source keeps to its surface where the surface has room for it:
        // one with little of its kernel there sits on an edge or a sliver
        // (its guides a mix of its samples'), and one whose surface cannot
        // hold its excess within the tolerance would pile it on the few
        // pixels that match. Both keep clear of lights only.
        let mut on_surface = st.guides.surface().then_some(surface);
        let at_first = self.norm(first, x, y, on_surface);
        if on_surface.is_some() {
            if keeps_to_surface(at_first, self.plain_norm(first, x, y)) {
                if let Some((k, norm)) = self.search((x, y), first, at_first, on_surface, passes) {
                    return Some((k, norm, false, true));
                }
            }
            on_surface = None;
        }
        let at_first = if st.guides.surface() {
            self.norm(first, x, y, None)
        } else {
            at_first
        };
        if let Some((k, norm)) = self.search((x, y), first, at_first, on_surface, passes) {
            return Some((k, norm, false, false));
        }
        // The lights the guides leave out made the kernel too narrow: a
        // pixel the kernel over every pixel spreads within the cap is spread
        // at the cap clear of them (the guides never leave in place what
        // ep-gauss spreads without them).
        let plain = st.guides.chooses_receivers() && excess <= limit * self.plain_norm(cap, x, y);
        let at_cap = self.norm(cap, x, y, None);
        (plain && at_cap > 0.0).then_some((cap, at_cap, true, false))
    }

    /// The first rung from `first` (whose sum is `at_first`) up to the cap
    /// whose kernel over the receivers `on_surface` allows `passes`, and its
    /// sum. The sum grows with the rung
    /// (every weight does): gallop up from the ladder's guess (most kernels
    /// pass there or a rung or two above, and a width costs its area), then
    /// bisect.
    fn search(
        &self,
        (x, y): (usize, usize),
        first: usize,
        at_first: f64,
        on_surface: Option<&G>,
        passes: impl Fn(f64) -> bool,
    ) -> Option<(usize, f64)> {
        let cap = self.stage.ladder.widths.rho.len() - 1;
        let (mut lo, mut step) = (None, 1);
        let mut k = first;
        let (mut hi, mut at_hi) = loop {
            let at = if k == first {
                at_first
            } else {
                self.norm(k, x, y, on_surface)
            };
            if passes(at) {
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
            let at_mid = self.norm(mid, x, y, on_surface);
            if passes(at_mid) {
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
        let r = st.ladder.widths.reach[k];
        let g = &st.ladder.taps[k];
        let (xa, xb) = (x.saturating_sub(r), (x + r + 1).min(st.w));
        let (ya, yb) = (y.saturating_sub(r), (y + r + 1).min(st.h));
        let sx: f64 = (xa..xb).map(|tx| g[tx + r - x]).sum();
        let sy: f64 = (ya..yb).map(|ty| g[ty + r - y]).sum();
        sx * sy
    }

    /// The sum of rung `k`'s weights over the in-image pixels it reaches
    /// from `(x, y)` (those on the source's surface, with surface guides;
    /// those clear of lights, with the emission guide): the receivers
    /// [`GaussRule`]'s `add` gives its shares to.
    fn norm(&self, k: usize, x: usize, y: usize, surface: Option<&G>) -> f64 {
        let st = self.stage;
        let (w, h) = (st.w, st.h);
        let r = st.ladder.widths.reach[k];
        let g = &st.ladder.taps[k];
        let (xa, xb) = (x.saturating_sub(r), (x + r + 1).min(w));
        let (ya, yb) = (y.saturating_sub(r), (y + r + 1).min(h));
        if !st.guides.chooses_receivers() {
            return self.plain_norm(k, x, y);
        }
        let gx = &g[xa + r - x..xb + r - x];
        let mut sum = 0.0;
        for ty in ya..yb {
            let gy = g[ty + r - y];
            let lights = &st.win.light.get(ty)[xa..xb];
            let mut part = 0.0;
            match surface {
                Some(from) => {
                    let surfs = &st.win.surf.get(ty)[xa..xb];
                    for (k, (tx, &wx)) in (xa..xb).zip(gx).enumerate() {
                        let q = (lights[k] != 0, &surfs[k]);
                        if st.guides.accepts(q, (tx, ty), Some((from, x, y))) {
                            part += wx;
                        }
                    }
                }
                None => {
                    for (k, &wx) in gx.iter().enumerate() {
                        if lights[k] == 0 {
                            part += wx;
                        }
                    }
                }
            }
            sum += gy * part;
        }
        sum
    }
}
