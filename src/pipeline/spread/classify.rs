//! Classification (the second cursor): which samples of a pixel row are
//! noise (the base test, the feature rules), set aside with their values,
//! and the horizontal gather pass of the base kernel with them taken out.

use rayon::iter::{IndexedParallelIterator, IntoParallelIterator, ParallelIterator};
use rayon::slice::{ParallelSlice, ParallelSliceMut};

use super::{ChannelMode, EpGauss, LumRows, Noisy, RowWindow, Rules, Shape, YView};

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
pub(super) type Found = (Vec<Noisy>, Vec<f64>, u64);

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
    shape: &'a Shape,
    rules: &'a Rules,
    view: &'a YView<'a>,
    input: &'a RowWindow<f32>,
}

impl FindCtx<'_> {
    /// Phase 1, reading the input as it came (neighbour rows included):
    /// which samples of pixel row `y` are noise, and which of those are kept
    /// as features. The row's noisy samples in row-major order, their values
    /// (`nch` each, in the same order) and how many were kept.
    fn find_cols(&self, sc: &mut FindScratch, y: usize, cols: std::ops::Range<usize>) -> FoundPart {
        let FindCtx {
            shape,
            rules,
            view,
            input,
        } = *self;
        let (s, in_w, in_h, nch) = (shape.grid.s, shape.grid.in_w, shape.grid.in_h, shape.nch);
        let (ep, lum, support) = (rules.ep.as_ref(), &rules.lum, rules.support);
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
        ep.xbar0_cols_into(view, y as i64, cols.clone(), xbars, xbar_h);
        // This part's samples, `i0..i1` of each row (`n` of them).
        let (i0, i1) = (cols.start * s, cols.end * s);
        let n = i1 - i0;
        let emission = rules.emission.as_ref();
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
        flag_pixels(ep, (lrows, n, s), (xbars, cols.start), pmax, flagged);
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
                    ring[k] = row[(self.shape.pad as i64 + px as i64 + dx) as usize] as f64;
                    k += 1;
                }
            }
        }
        ring_median(&mut ring)
    }

    /// Phase 2: the horizontal pass of the base kernel over the `S` sample
    /// rows of pixel row `y` into `hs`, the spread samples `list` taken out
    /// (zeroed in a copy of their row, `scratch`).
    fn pass(&self, scratch: &mut Vec<f32>, y: usize, hs: &mut [&mut [f64]], list: &[Noisy]) {
        let FindCtx {
            shape,
            rules,
            input,
            ..
        } = *self;
        let Shape { grid, w, nch, .. } = *shape;
        let (s, in_w) = (grid.s, grid.in_w);
        let (modes, cols, emission) = (&rules.modes, &rules.cols, rules.emission.as_ref());
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

/// Classify pixel rows `a..` (their input rows' horizontal passes `hrows`,
/// `S` each), searching a row in `parts` column ranges. Returns what each
/// row found.
fn classify_rows(
    ctx: &FindCtx<'_>,
    mut hrows: Vec<&mut [f64]>,
    a: usize,
    parts: usize,
) -> Vec<Found> {
    let Shape { grid, w, nch, .. } = *ctx.shape;
    let s = grid.s;
    let rows = hrows.len() / s;
    let region = crate::trace::region("classify");
    if parts == 1 {
        // Both phases row by row in one task: the pass reads the rows the
        // search for noise has just read.
        return hrows
            .par_chunks_mut(s)
            .enumerate()
            .map_init(
                <(FindScratch, Vec<f32>)>::default,
                |(scratch, copy), (k, hs)| {
                    let _task = region.task("classify");
                    let y = a + k;
                    let f = ctx.find_cols(scratch, y, 0..w).found;
                    ctx.pass(copy, y, hs, &f.0);
                    f
                },
            )
            .collect();
    }
    // A wide row: its column ranges searched by tasks of their own, then
    // each row's pass with what they found, in its order.
    let span = w.div_ceil(parts);
    // No empty range at the end (10 pixels in 6 parts: 5 of 2).
    let parts = w.div_ceil(span);
    let found_parts = (0..rows * parts)
        .into_par_iter()
        .map_init(FindScratch::default, |scratch, t| {
            let _task = region.task("classify");
            let x0 = (t % parts) * span;
            ctx.find_cols(scratch, a + t / parts, x0..(x0 + span).min(w))
        })
        .collect::<Vec<FoundPart>>();
    drop(region);
    let region = crate::trace::region("classify pass");
    hrows
        .par_chunks_mut(s)
        .zip(found_parts.par_chunks(parts))
        .enumerate()
        .map_init(Vec::new, |copy, (k, (hs, row))| {
            let _task = region.task("classify pass");
            let f = merge_parts(row, s, nch);
            ctx.pass(copy, a + k, hs, &f.0);
            f
        })
        .collect()
}

/// Classify pixel rows `a..` (`hpass`: their input rows' horizontal
/// passes, to make; `ybox`: the box luminance the test reads; `per_task`:
/// samples of an input row a task searches, 0 automatic). Returns what each
/// row found: its noisy samples, their values, how many were kept.
pub(super) fn classify(
    shape: &Shape,
    rules: &Rules,
    input: &RowWindow<f32>,
    ybox: YView<'_>,
    hpass: Vec<&mut [f64]>,
    a: usize,
    per_task: usize,
) -> Vec<Found> {
    let Shape { grid, w, .. } = *shape;
    let per_task = match per_task {
        0 => FIND_TASK_SAMPLES,
        n => n,
    };
    // Without ep-gauss there is no noise to search for: the pass alone,
    // a task a row.
    let parts = match rules.ep {
        Some(_) => grid.in_w.div_ceil(per_task).clamp(1, w),
        None => 1,
    };
    let ctx = FindCtx {
        shape,
        rules,
        view: &ybox,
        input,
    };
    classify_rows(&ctx, hpass, a, parts)
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

/// Which pixels of a part (columns from `start`, their averages `xbars`)
/// hold a noisy sample, by the luminance of their samples (`lrows`: `s`
/// rows of `n`): each with its average and bounds, into `flagged`.
fn flag_pixels(
    ep: &EpGauss,
    (lrows, n, s): (&[f64], usize, usize),
    (xbars, start): (&[f64], usize),
    pmax: &mut Vec<f64>,
    flagged: &mut Vec<(usize, f64, f64, f64)>,
) {
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
                flagged.push((start + k, xbar, hi, lo));
            }
        }
    } else {
        // Only bright samples can fail (`lo <= 0`): a pixel
        // holds one iff its brightest sample is above `hi`.
        pmax.clear();
        pmax.resize(xbars.len(), f64::NEG_INFINITY);
        for lrow in lrows.chunks_exact(n) {
            row_max(pmax, lrow, s);
        }
        for (k, (&xbar, &m)) in xbars.iter().zip(pmax.iter()).enumerate() {
            let Some((hi, lo)) = ep.bounds(xbar) else {
                continue;
            };
            if m > hi {
                flagged.push((start + k, xbar, hi, lo));
            }
        }
    }
}
