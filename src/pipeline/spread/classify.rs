//! Classification (the second cursor): which samples of a pixel row are
//! noise (the base test, the feature rules), set aside with their values,
//! and the horizontal gather pass of the base kernel with them taken out.

use rayon::prelude::*;

use super::scatter::{Accs, Batch, Placed, SearchPlace};
use super::*;
use crate::trace::Span;

/// The 5th smallest of eight values (their upper median): what three
/// outliers on either side cannot move past the others. NaN sorts last.
fn ring_median(ring: &mut [f64; 8]) -> f64 {
    ring.sort_unstable_by(f64::total_cmp);
    ring[4]
}

/// One classification task's scratch, reused from pixel row to pixel row.
#[derive(Default)]
struct FindScratch {
    /// The pixel row's super-sample luminance, `S` sample rows.
    lrows: Vec<f64>,
    /// Its pixels that hold a noisy sample: column, xbar and bounds.
    flagged: Vec<(usize, f64, f64, f64)>,
    /// Each pixel's brightest sample.
    pmax: Vec<f64>,
    /// The base width's averages, and their horizontal pass.
    xbars: Vec<f64>,
    xbar_h: Vec<f64>,
}

/// A pixel row's noisy samples (row-major), their values (`nch` each: what
/// the emission guide leaves of them) and how many noisy samples were kept
/// as features.
type Found = (Vec<Noisy>, Vec<f64>, u64);

/// Samples of one input row that one classification task searches for
/// noise: a pixel row of a wider image is cut into column ranges, searched
/// by tasks of their own, so that one row is not the longest task of its
/// strip. Rows up to this wide are one task, the search and the pass
/// together. With a task per pixel row, a strip of a wide image has fewer
/// tasks than 16 cores and its loop waits for the slowest; a few tasks a
/// row shorten the span without costing fewer threads anything (the
/// result does not depend on the cut).
const FIND_TASK_SAMPLES: usize = 3_072;

/// What [`FindCtx::find_cols`] found in a column range of a pixel row.
struct FoundPart {
    found: Found,
    /// Where each sample row's entries end in `found.0` (S <= 8).
    ends: [usize; 8],
}

/// A pixel row's parts, from left to right, in the row-major order of one
/// search over the whole row: by sample row, then column.
fn merge_parts(parts: &[FoundPart], s: usize, nch: usize) -> Found {
    let mut out: Found = (Vec::new(), Vec::new(), 0);
    for bb in 0..s {
        for p in parts {
            let start = if bb == 0 { 0 } else { p.ends[bb - 1] };
            let end = p.ends[bb];
            out.0.extend_from_slice(&p.found.0[start..end]);
            out.1.extend_from_slice(&p.found.1[start * nch..end * nch]);
        }
    }
    out.2 = parts.iter().map(|p| p.found.2).sum();
    out
}

/// What classification reads, shared by its tasks.
#[derive(Clone, Copy)]
struct FindCtx<'a> {
    s: usize,
    w: usize,
    in_w: usize,
    in_h: usize,
    h: usize,
    nch: usize,
    pad: usize,
    ep: Option<&'a EpGauss>,
    view: &'a YView<'a>,
    lum: &'a Luminance,
    modes: &'a [ChannelMode],
    cols: &'a ColumnTaps,
    support: Support,
    pixel_stats: Option<&'a (StatsLayout, Carriers)>,
    input: &'a RowWindow<f32>,
    emission: Option<&'a EmissionParts>,
}

impl FindCtx<'_> {
    /// Phase 1, reading the input as it came (neighbour rows included):
    /// which samples of pixel row `y` are noise, and which of those are kept
    /// as features. The row's noisy samples in row-major order, their values
    /// (`nch` each, in the same order) and how many were kept.
    fn find_cols(&self, sc: &mut FindScratch, y: usize, cols: std::ops::Range<usize>) -> FoundPart {
        let FindCtx {
            s,
            in_w,
            in_h,
            nch,
            ep,
            view: yview,
            lum,
            support,
            input,
            ..
        } = *self;
        let FindScratch {
            lrows,
            flagged,
            pmax,
            xbars,
            xbar_h,
        } = sc;
        let mut found = Vec::new();
        let mut vals = Vec::new();
        let mut kept = 0u64;
        let mut ends = [0usize; 8];
        let Some(ep) = ep else {
            return FoundPart {
                found: (found, vals, kept),
                ends,
            };
        };
        let view = yview;
        ep.xbar0_cols_into(view, y as i64, cols.clone(), xbars, xbar_h);
        // This part's samples, `i0..i1` of each row (`n` of them).
        let (i0, i1) = (cols.start * s, cols.end * s);
        let n = i1 - i0;
        let emission = self.emission;
        let luma = |row: &[f32], i: usize| {
            let y = lum.of(|c| row[c * in_w + i] as f64);
            emission.map_or(y, |e| y - e.luminance(row, in_w, i))
        };
        // The luminance of the pixel row's samples, a row at a time
        // (the same sum, in the same order, as `luma`).
        lrows.clear();
        lrows.resize(s * n, 0.0f64);
        for (bb, lrow) in lrows.chunks_exact_mut(n).enumerate() {
            let row = input.get(y * s + bb);
            lum.cols_into(row, in_w, i0..i1, lrow);
            if let Some(e) = emission {
                for (k, l) in lrow.iter_mut().enumerate() {
                    *l -= e.luminance(row, in_w, i0 + k);
                }
            }
        }
        // Which pixels hold a noisy sample: one branch-free test of
        // all their samples first (most hold none).
        flagged.clear();
        if ep.low_outliers() {
            for (k, &xbar) in xbars.iter().enumerate() {
                let Some((hi, lo)) = ep.bounds(xbar) else {
                    continue;
                };
                let mut any = false;
                for bb in 0..s {
                    for &x0 in &lrows[bb * n + k * s..bb * n + (k + 1) * s] {
                        any |= EpGauss::outside(x0, (hi, lo));
                    }
                }
                if any {
                    flagged.push((cols.start + k, xbar, hi, lo));
                }
            }
        } else {
            // Only bright samples can fail (`lo <= 0`): a pixel
            // holds one iff its brightest sample is above `hi`.
            pmax.clear();
            pmax.resize(cols.len(), f64::NEG_INFINITY);
            for lrow in lrows.chunks_exact(n) {
                row_max(pmax, lrow, s);
            }
            for (k, (&xbar, &m)) in xbars.iter().zip(pmax.iter()).enumerate() {
                let Some((hi, lo)) = ep.bounds(xbar) else {
                    continue;
                };
                if m > hi {
                    flagged.push((cols.start + k, xbar, hi, lo));
                }
            }
        }
        // Row-major order: by input row, then column.
        for bb in 0..s {
            let j = y * s + bb;
            let lrow = &lrows[bb * n..(bb + 1) * n];
            for &(px, xbar, hi, lo) in flagged.iter() {
                for i in px * s..(px + 1) * s {
                    let x0 = lrow[i - i0];
                    if !EpGauss::outside(x0, (hi, lo)) {
                        continue;
                    }
                    let neighbour = |di: i64, dj: i64| {
                        let (ni, nj) = (i as i64 + di, j as i64 + dj);
                        if !(ni >= 0 && nj >= 0 && (ni as usize) < in_w && (nj as usize) < in_h) {
                            return None;
                        }
                        let (ni, nj) = (ni as usize, nj as usize);
                        // This part's samples are in `lrows`.
                        Some(match nj.checked_sub(y * s).filter(|&b| b < s) {
                            Some(b) if (i0..i1).contains(&ni) => lrows[b * n + ni - i0],
                            _ => luma(input.get(nj), ni),
                        })
                    };
                    let background = || self.background(px, y);
                    if support.keeps(x0, xbar, hi, lo, neighbour, background) {
                        kept += 1;
                        continue;
                    }
                    if x0 > hi && self.carried(ep, x0, (i, j), px) {
                        kept += 1;
                        continue;
                    }
                    let row = input.get(j);
                    vals.extend((0..nch).map(|c| {
                        let v = row[c * in_w + i] as f64;
                        emission.map_or(v, |e| v - e.part(row, in_w, c, i))
                    }));
                    found.push(Noisy {
                        i: i as u32,
                        j: j as u32,
                        x0,
                        xbar0: xbar,
                        level: 0,
                        capped: false,
                    });
                }
            }
            ends[bb] = found.len();
        }
        FoundPart {
            found: (found, vals, kept),
            ends,
        }
    }

    /// The box luminance of the eight pixels about pixel `(px, y)`
    /// (mirrored at the borders), its median: up to three of them may hold
    /// the feature itself.
    fn background(&self, px: usize, y: usize) -> f64 {
        let mut ring = [0.0f64; 8];
        let mut k = 0;
        for dy in -1i64..=1 {
            let row = self.view.row(y as i64 + dy);
            for dx in -1i64..=1 {
                if dx != 0 || dy != 0 {
                    ring[k] = row[(self.pad as i64 + px as i64 + dx) as usize] as f64;
                    k += 1;
                }
            }
        }
        ring_median(&mut ring)
    }

    /// S = 1 with per-pixel statistics: whether the carriers rule keeps the
    /// bright sample `x0` at input `(i, j)`, pixel column `px` (the sample is
    /// the pixel).
    fn carried(&self, ep: &EpGauss, x0: f64, (i, j): (usize, usize), px: usize) -> bool {
        let Some((st, carriers)) = self.pixel_stats else {
            return false;
        };
        let (view, pad, in_w, y) = (self.view, self.pad, self.in_w, j);
        let row = self.input.get(j);
        let (n, se2) = st.pixel(self.lum.weights(), x0, |c| row[c * in_w + i] as f64);
        let hot = || {
            cluster_count(
                (px, y),
                (self.w, self.h),
                x0,
                |xx, yy| view.row(yy as i64)[pad + xx] as f64,
                |xx, yy| {
                    let (v, xb) = (
                        view.row(yy as i64)[pad + xx] as f64,
                        ep.xbar0(view, xx, yy as i64),
                    );
                    ep.bounds(xb).is_some_and(|(hi, _)| v > hi)
                },
            )
        };
        carriers.keeps(x0, se2, n, hot)
    }

    /// Phase 2: the horizontal pass of the base kernel over the `S` sample
    /// rows of pixel row `y` into `hs`, the spread samples `list` taken out
    /// (zeroed in a copy of their row, `scratch`).
    fn pass(&self, scratch: &mut Vec<f32>, y: usize, hs: &mut [&mut [f64]], list: &[Noisy]) {
        let FindCtx {
            s,
            w,
            in_w,
            nch,
            modes,
            cols,
            input,
            emission,
            ..
        } = *self;
        for (bb, hrow) in hs.iter_mut().enumerate() {
            let j = y * s + bb;
            let mut row = input.get(j);
            let first = list.partition_point(|n| (n.j as usize) < j);
            let last = list.partition_point(|n| (n.j as usize) <= j);
            if first < last {
                scratch.clear();
                scratch.extend_from_slice(row);
                for n in &list[first..last] {
                    // Coverage (alpha) and averaged data are not
                    // spread: they keep the base kernel, as does the
                    // emission guide's part of the colour.
                    let i = n.i as usize;
                    for c in (0..nch).filter(|&c| modes[c] == ChannelMode::Spread) {
                        scratch[c * in_w + i] =
                            emission.map_or(0.0, |e| e.part(row, in_w, c, i) as f32);
                    }
                }
                row = scratch.as_slice();
            }
            for c in 0..nch {
                let src = &row[c * in_w..(c + 1) * in_w];
                let dst = &mut hrow[c * w..(c + 1) * w];
                if modes[c] == ChannelMode::Nearest {
                    // The centre sample, as it is.
                    for (x, d) in dst.iter_mut().enumerate() {
                        *d = src[x * s + (s - 1) / 2] as f64;
                    }
                    continue;
                }
                for (x, d) in dst.iter_mut().enumerate() {
                    let (start, taps) = cols.taps(x);
                    // -0.0 is the additive identity: a sum of -0.0
                    // samples stays -0.0 (an input -0.0 survives).
                    let mut acc = -0.0;
                    for (t, &v) in taps.iter().zip(&src[start..start + taps.len()]) {
                        acc += t * v as f64;
                    }
                    *d = acc;
                }
            }
        }
    }
}

/// Work run beside classification's loops (pending samples classified
/// before: [`GaussianStage::classify_spreading`]): the first chunk of a batch
/// searched and placed beside the search for noise, with the coarse share
/// the last advance planned (`up`); then scattered beside the pass (after
/// the one loop where a row is one task).
pub(super) struct Beside<'s> {
    place: SearchPlace<'s>,
    samples: &'s mut [Noisy],
    values: &'s [f64],
    accs: Accs<'s>,
    fresh: &'s mut [Option<usize>; 3],
    up: Option<(usize, usize)>,
}

/// What [`GaussianStage::classify_with`] spreads beside classification: a
/// batch's samples up to `end`, and the coarse share `up`.
struct Chunk<'b> {
    batch: &'b mut Batch,
    end: usize,
    up: Option<(usize, usize)>,
}

impl Beside<'_> {
    /// The search and placement, and the coarse share, as tasks of
    /// `region`; the parts placed.
    fn first(&mut self, region: &Span) -> Vec<Placed> {
        let Beside {
            place,
            samples,
            values,
            accs,
            up,
            ..
        } = self;
        let up = up.take();
        let upsample = || {
            if let Some(up) = up {
                accs.upsample(up, region);
            }
        };
        rayon::join(|| place.run(samples, values, region), upsample).0
    }

    /// The scatter of `parts`, as tasks of `region`.
    fn then(&mut self, parts: &[Placed], region: &Span) {
        self.accs.scatter(parts, self.fresh, region);
    }
}

/// Classify pixel rows `a..` (their input rows' horizontal passes `hrows`,
/// `S` each), searching a row in `parts` column ranges, with `beside`'s
/// work in the same loops (two loops' tasks in one region: one join, not
/// two). Returns what each row found, and what `beside` placed.
fn classify_rows(
    ctx: &FindCtx<'_>,
    mut hrows: Vec<&mut [f64]>,
    a: usize,
    parts: usize,
    mut beside: Option<Beside<'_>>,
) -> (Vec<Found>, Option<Vec<Placed>>) {
    let s = ctx.s;
    let rows = hrows.len() / s;
    let names = if beside.is_some() {
        ["classify, search and place", "classify pass, scatter"]
    } else {
        ["classify", "classify pass"]
    };
    let mut beside_first = |region: &Span| beside.as_mut().map(|b| b.first(region));
    let region = crate::trace::region(names[0]);
    if parts == 1 {
        // Both phases row by row in one task: the pass reads the rows the
        // search for noise has just read.
        let (found, placed) = rayon::join(
            || {
                hrows
                    .par_chunks_mut(s)
                    .enumerate()
                    .map_init(
                        <(FindScratch, Vec<f32>)>::default,
                        |(scratch, copy), (k, hs)| {
                            let _task = region.task("classify");
                            let y = a + k;
                            let f = ctx.find_cols(scratch, y, 0..ctx.w).found;
                            ctx.pass(copy, y, hs, &f.0);
                            f
                        },
                    )
                    .collect::<Vec<Found>>()
            },
            || beside_first(&region),
        );
        drop(region);
        if let (Some(b), Some(placed)) = (&mut beside, &placed) {
            b.then(placed, &crate::trace::region("scatter"));
        }
        return (found, placed);
    }
    // A wide row: its column ranges searched by tasks of their own, then
    // each row's pass with what they found, in its order.
    let span = ctx.w.div_ceil(parts);
    // No empty range at the end (10 pixels in 6 parts: 5 of 2).
    let parts = ctx.w.div_ceil(span);
    let (found_parts, placed) = rayon::join(
        || {
            (0..rows * parts)
                .into_par_iter()
                .map_init(FindScratch::default, |scratch, t| {
                    let _task = region.task("classify");
                    let x0 = (t % parts) * span;
                    ctx.find_cols(scratch, a + t / parts, x0..(x0 + span).min(ctx.w))
                })
                .collect::<Vec<FoundPart>>()
        },
        || beside_first(&region),
    );
    // Each row's parts merged in the task of its pass: one loop (one join)
    // less a strip. A loop of its own, so a region of its own (the model
    // replays a region's tasks as independent).
    drop(region);
    let region = crate::trace::region(names[1]);
    let (found, ()) = rayon::join(
        || {
            hrows
                .par_chunks_mut(s)
                .zip(found_parts.par_chunks(parts))
                .enumerate()
                .map_init(Vec::new, |copy, (k, (hs, row))| {
                    let _task = region.task("classify pass");
                    let f = merge_parts(row, s, ctx.nch);
                    ctx.pass(copy, a + k, hs, &f.0);
                    f
                })
                .collect::<Vec<Found>>()
        },
        || {
            if let (Some(b), Some(placed)) = (&mut beside, &placed) {
                b.then(placed, &region);
            }
        },
    );
    (found, placed)
}

impl GaussianStage {
    /// Classify pixel rows `a..b`: their noisy samples join the pending
    /// list.
    pub(super) fn classify(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        self.classify_with(input, (a, b), None);
    }

    /// Classify pixel rows `a..b` while the first chunk of `batch` (samples
    /// classified before: the caller checks) is searched and placed beside
    /// the search for noise and scattered beside the pass (the same work in
    /// the same order as one after the other, in two loops fewer).
    pub(super) fn classify_spreading(
        &mut self,
        input: &RowWindow<f32>,
        (a, b): (usize, usize),
        batch: &mut Batch,
        up: Option<(usize, usize)>,
    ) {
        let c1 = self.chunk_end(batch.bound, batch.next, batch.split);
        let chunk = Chunk { batch, end: c1, up };
        let placed = self.classify_with(input, (a, b), Some(chunk));
        self.count_placed(&placed.unwrap_or_default());
    }

    /// Classify pixel rows `a..b`, with the chunk `batch.next..c1` of
    /// `spread` spread beside it; returns its parts.
    /// (Long: the stage's fields, borrowed one by one for the two jobs.)
    fn classify_with(
        &mut self,
        input: &RowWindow<f32>,
        (a, b): (usize, usize),
        spread: Option<Chunk<'_>>,
    ) -> Option<Vec<Placed>> {
        let s = self.grid.s;
        for _ in a * s..b * s {
            self.hpass.push_stale(0.0); // every value is written below
        }
        let per_task = match self.classify_samples {
            0 => FIND_TASK_SAMPLES,
            n => n,
        };
        // Without ep-gauss there is no noise to search for: the pass alone,
        // a task a row (a loop of empty searches was a join a strip).
        let parts = match self.ep {
            Some(_) => self.grid.in_w.div_ceil(per_task).clamp(1, self.w),
            None => 1,
        };
        let GaussianStage {
            grid,
            w,
            h,
            nch,
            pad,
            inv_s2,
            tile,
            support,
            ref ybox,
            ref csum,
            ref mut hpass,
            ref mut pending,
            ref pending_v,
            ref mut acc,
            ref mut c2,
            ref mut c4,
            ref ep,
            ref lum,
            ref modes,
            ref cols,
            ref pixel_stats,
            ref emission,
            ..
        } = *self;
        let yview = YView::new(ybox, h);
        let ctx = FindCtx {
            s,
            w,
            in_w: grid.in_w,
            in_h: grid.in_h,
            h,
            nch,
            pad,
            ep: ep.as_ref(),
            view: &yview,
            lum,
            modes,
            cols,
            support,
            pixel_stats: pixel_stats.as_ref(),
            input,
            emission: emission.as_ref(),
        };
        let hrows = hpass.range_mut(a * s, b * s);
        let beside = match (spread, ep.as_ref()) {
            (Some(Chunk { batch, end: c1, up }), Some(ep)) => {
                let c0 = batch.next;
                batch.next = c1;
                let place =
                    SearchPlace::new(ep, (ybox, csum.as_ref()), modes, inv_s2, (s, nch), (w, h));
                Some(Beside {
                    place,
                    samples: &mut pending[c0..c1],
                    values: &pending_v[c0 * nch..c1 * nch],
                    accs: Accs::new(ep, (acc, c2, c4), w, nch, tile),
                    fresh: &mut batch.fresh,
                    up,
                })
            }
            _ => None,
        };
        let (found, placed) = classify_rows(&ctx, hrows, a, parts, beside);
        for (list, vals, kept) in found {
            // Kept samples failed the test too; the spread ones are counted
            // when they are spread.
            self.counts.noisy += kept;
            self.counts.kept += kept;
            self.pending.extend(list);
            self.pending_v.extend(vals);
        }
        placed
    }
}

/// `out[px] = max(out[px], ch[px * s .. (px + 1) * s])`, with the common
/// factors in loops of their own, as in [`box_add`]. A comparison, not
/// `f64::max` (whose NaN rule costs a branch per value): the same result
/// while `out` holds no NaN (it starts at -inf), and a NaN value is passed
/// over by both.
#[inline]
fn row_max(out: &mut [f64], ch: &[f64], s: usize) {
    #[inline(always)]
    fn fixed<const S: usize>(out: &mut [f64], ch: &[f64]) {
        for (o, v) in out.iter_mut().zip(ch.chunks_exact(S)) {
            for &v in v {
                *o = if v > *o { v } else { *o };
            }
        }
    }
    match s {
        1 => fixed::<1>(out, ch),
        2 => fixed::<2>(out, ch),
        3 => fixed::<3>(out, ch),
        4 => fixed::<4>(out, ch),
        _ => {
            for (o, v) in out.iter_mut().zip(ch.chunks_exact(s)) {
                for &v in v {
                    *o = if v > *o { v } else { *o };
                }
            }
        }
    }
}
