//! The streaming engine: scatter as the mirror image of gather.
//!
//! Rows flow through four stages, each a cursor over output (pixel) rows:
//!
//! 1. **box luminance** `Ybox` of pixel row `y` once its S input rows are in;
//! 2. **classification** of row `y` (the base noise test, which reads `Ybox`
//!    rows `y ± xbar_reach`): noisy samples are set aside (with their values)
//!    and zeroed in the input, and every input row gets its horizontal gather
//!    pass;
//! 3. **spreading** of the noisy samples of row `y` (the width search reads
//!    `Ybox` rows `y ± search_reach`) into tile accumulators that own output
//!    pixels, visited in input row-major order;
//! 4. **output** of row `y` once no later input row can reach it: the vertical
//!    gather of the base kernel (`y ± base_reach` input pixel rows classified)
//!    plus the accumulator (all noisy samples of rows `≤ y + spread_reach`
//!    spread).
//!
//! Each cursor advances only when what it reads is present, so the result does
//! not depend on how rows arrive (strip height). Every output value is built
//! by the same operations in the same order whatever the tile size or thread
//! count: the gather sums its taps in index order, the accumulator receives
//! noisy samples in input row-major order. Output is bit-identical across
//! `--tile`, `--strip-rows` and `--threads`.
//!
//! Memory: the windows hold `O(lag)` rows of the output width (`lag` from
//! [`crate::geometry::Halo`]) and `O(S * (strip + xbar_reach))` input rows,
//! whatever the image height.

use rayon::prelude::*;

use super::books::Books;
use super::window::RowWindow;
use super::{Precision, Strip};
use crate::error::{Error, Result};
use crate::filter::ep_gauss::{EpGauss, LumRows, Support};
use crate::filter::kernel::{ColumnTaps, Kernel1d};
use crate::filter::{FilterParams, Method};
use crate::geometry::{mirror, Grid, Halo};

/// Noisy samples spread per chunk (bounds the folded-weight arena to about
/// 4096 x 1.5 KiB at the widest kernel).
const SPREAD_CHUNK: usize = 4096;

/// Most channels one job filters (R, G, B, A).
pub const MAX_CHANNELS: usize = 4;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halo_from_params_equals_the_engines() {
        for m in [Method::EpGauss, Method::Gauss, Method::Box] {
            for (s, r, mr, cut) in [
                (3, 0.6, 16.0, 3.0),
                (4, 0.9, 5.5, 2.5),
                (2, 0.3, 0.3, 1.0),
                (1, 2.0, 40.0, 6.0),
            ] {
                let mut p = FilterParams::new(m, s);
                (p.radius, p.max_radius, p.cutoff) = (r, mr, cut);
                let grid = Grid {
                    in_w: 30 * s,
                    in_h: 20 * s,
                    s,
                };
                let e =
                    Engine::new(grid, vec!["Y".into()], vec![1.0], &p, 16, Precision::F32).unwrap();
                assert_eq!(
                    e.halo(),
                    crate::filter::halo(&p),
                    "{m:?} {s} {r} {mr} {cut}"
                );
            }
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Noisy {
    i: u32,
    j: u32,
    x0: f64,
    xbar0: f64,
    v: [f32; MAX_CHANNELS],
    level: u16,
    capped: bool,
}

#[derive(Clone, Copy, Debug)]
struct Spread {
    xs: usize,
    xl: usize,
    ys: usize,
    yl: usize,
    off: usize,
    v: [f64; MAX_CHANNELS],
}

struct YView<'a> {
    win: &'a RowWindow<f64>,
    h: usize,
}

impl LumRows for YView<'_> {
    #[inline]
    fn row(&self, vy: i64) -> &[f64] {
        self.win.get(mirror(vy, self.h))
    }
}

/// Counters of a run.
#[derive(Clone, Copy, Debug, Default)]
pub struct Counters {
    /// Samples that failed the base test (ep-box: pixels that failed the
    /// noise test).
    pub noisy: u64,
    /// Samples spread wider than the base kernel (m > 1; ep-box: pixels whose
    /// excess was spread).
    pub spread: u64,
    /// Samples that still failed Relation 14 at the cap (ep-box: pixels
    /// whose excess did not fit under `L_tvis` per pixel within the radius).
    pub capped: u64,
    /// ep-gauss: noisy samples kept as features (the support rule); ep-box:
    /// noisy pixels the range guard left alone.
    pub guarded: u64,
    /// ep-box: pixels whose excess the `stderr` guard cut to what noise can
    /// explain.
    pub trimmed: u64,
    /// ep-box: noisy pixels with no converged pixel within the passes' reach.
    pub unresolved: u64,
    /// ep-box: the most passes any pixel needed.
    pub passes: u64,
    /// ep-box: pixels noisy by the paper's test whose mean rests on enough
    /// samples to be reliable (the `carriers` guard): not treated as noise.
    pub reliable: u64,
}

/// A finished batch of output rows, `[row][channel][x]`.
pub struct OutRows {
    /// First output row.
    pub y0: usize,
    /// Number of rows.
    pub rows: usize,
    /// Values, already rounded to the output precision.
    pub data: Vec<f32>,
}

/// The filter state between strips.
pub struct Engine {
    grid: Grid,
    w: usize,
    h: usize,
    nch: usize,
    inv_s2: f64,
    lum: Vec<f64>,
    base: Kernel1d,
    cols: ColumnTaps,
    ep: Option<EpGauss>,
    halo: Halo,
    pad: usize,
    tile: usize,
    precision: Precision,
    input: RowWindow<f32>,
    ybox: RowWindow<f64>,
    hpass: RowWindow<f64>,
    based: RowWindow<f64>,
    acc: RowWindow<f64>,
    pending: Vec<Noisy>,
    arena: Vec<f64>,
    rows_in: usize,
    cls_done: usize,
    spread_done: usize,
    out_done: usize,
    counters: Counters,
    books: Books,
    clamp: Option<f32>,
    support: Support,
}

impl Engine {
    /// Build the engine: kernels, taps and halo are settled here, once.
    pub fn new(
        grid: Grid,
        names: Vec<String>,
        lum: Vec<f64>,
        params: &FilterParams,
        tile: usize,
        precision: Precision,
    ) -> Result<Self> {
        params.validate()?;
        let nch = names.len();
        if nch == 0 || nch > MAX_CHANNELS || lum.len() != nch {
            return Err(Error::Config(format!(
                "1..={MAX_CHANNELS} channels with luminance weights needed, got {nch}"
            )));
        }
        let s = grid.s;
        if grid.in_w == 0 || grid.in_h == 0 {
            return Err(Error::Config("the image is empty".into()));
        }
        if grid.in_w < s || grid.in_h < s {
            return Err(Error::Config(format!(
                "--supersample {s} is larger than the image ({}x{} samples)",
                grid.in_w, grid.in_h
            )));
        }
        if grid.in_w % s != 0 || grid.in_h % s != 0 {
            return Err(Error::Config(format!(
                "image size {}x{} is not a multiple of --supersample {s}",
                grid.in_w, grid.in_h
            )));
        }
        if tile == 0 {
            return Err(Error::Config("--tile must be at least 1".into()));
        }
        let (w, h) = (grid.out_w(), grid.out_h());
        let base = match params.method {
            Method::Box => Kernel1d::boxed(s),
            _ => Kernel1d::gaussian(s, params.radius, params.cutoff),
        };
        let ep = (params.method == Method::EpGauss).then(|| {
            EpGauss::new(
                s,
                params.radius,
                params.max_radius,
                params.cutoff,
                params.tolerance,
                params.width_step,
            )
        });
        let halo = Halo {
            xbar_reach: ep.as_ref().map_or(0, |e| e.xbar_reach()),
            base_reach: base.reach(),
            search_reach: ep.as_ref().map_or(0, |e| e.search_reach()),
            spread_reach: ep.as_ref().map_or(0, |e| e.spread_reach()),
        };
        let pad = ep.as_ref().map_or(0, |e| e.pad());
        let cols = ColumnTaps::new(&base, w, grid.in_w);
        Ok(Engine {
            grid,
            w,
            h,
            nch,
            inv_s2: 1.0 / (s * s) as f64,
            lum,
            base,
            cols,
            ep,
            halo,
            pad,
            tile,
            precision,
            input: RowWindow::new(nch * grid.in_w),
            ybox: RowWindow::new(w + 2 * pad),
            hpass: RowWindow::new(nch * w),
            based: RowWindow::new(nch * w),
            acc: RowWindow::new(nch * w),
            pending: Vec::new(),
            arena: Vec::new(),
            rows_in: 0,
            cls_done: 0,
            spread_done: 0,
            out_done: 0,
            counters: Counters::default(),
            books: Books::new(names, nch),
            clamp: (params.method == Method::Clamp).then_some(params.clamp as f32),
            support: Support::new(params.support, params.support_ratio),
        })
    }

    /// The halo this job needs.
    pub fn halo(&self) -> Halo {
        self.halo
    }

    /// Output rows finished so far.
    pub fn rows_out(&self) -> usize {
        self.out_done
    }

    /// Counters so far.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Names, ledger, digest and non-finite counts.
    pub fn books(&self) -> &Books {
        &self.books
    }

    /// The same, to set the non-finite policy.
    pub fn books_mut(&mut self) -> &mut Books {
        &mut self.books
    }

    /// Most rows each window held at once: input, box luminance, horizontal
    /// pass, base rows, accumulator.
    pub fn high_water(&self) -> [usize; 5] {
        [
            self.input.high_water(),
            self.ybox.high_water(),
            self.hpass.high_water(),
            self.based.high_water(),
            self.acc.high_water(),
        ]
    }

    /// Feed the next strip of input rows; returns the output rows it finished.
    pub fn push(&mut self, mut strip: Strip) -> Result<Option<OutRows>> {
        let (nch, in_w) = (self.nch, self.grid.in_w);
        let row_len = nch * in_w;
        self.books
            .take(&mut strip, self.rows_in, in_w, self.grid.in_h)?;
        if let Some(limit) = self.clamp {
            // The clamp foil: colour samples above the limit are cut (after
            // the ledger took the input, so the loss shows).
            for row in strip.data.chunks_mut(row_len) {
                for (c, ch) in row.chunks_mut(in_w).enumerate() {
                    if self.lum[c] != 0.0 {
                        ch.iter_mut().for_each(|v| *v = v.min(limit));
                    }
                }
            }
        }
        for row in strip.data.chunks(row_len) {
            self.input.push_copy(row);
        }
        self.rows_in += strip.rows;
        self.advance()
    }

    fn advance(&mut self) -> Result<Option<OutRows>> {
        let s = self.grid.s;
        // 1. box luminance
        let ready = self.rows_in / s;
        if ready > self.ybox.end() {
            self.make_ybox(self.ybox.end(), ready);
        }
        let yb = self.ybox.end();
        let all_in = yb == self.h;
        // 2. classification + horizontal pass
        // A row's classification reads the input row just below it (the
        // support of samples on its last row): one pixel row more than
        // `xbar_reach` when that is 0.
        let cls_target = if all_in {
            self.h
        } else {
            yb.saturating_sub(self.halo.xbar_reach.max(1))
        };
        if cls_target > self.cls_done {
            self.classify(self.cls_done, cls_target);
            self.cls_done = cls_target;
            // ... and the row just above it.
            self.input
                .evict_below((self.cls_done * s).saturating_sub(1));
        }
        // 3. spreading
        if self.ep.is_some() {
            let sp_target = if all_in {
                self.cls_done
            } else {
                self.cls_done.min(yb.saturating_sub(self.halo.search_reach))
            };
            if sp_target > self.spread_done {
                self.spread(sp_target);
                self.spread_done = sp_target;
            }
        }
        // 4. base rows: the vertical gather, as soon as its input rows are
        // classified; the short-lived horizontal-pass rows go, the (S times
        // fewer) base rows wait for the spreading.
        let h = self.h;
        let base_target = if self.cls_done == h {
            h
        } else {
            self.cls_done.saturating_sub(self.halo.base_reach)
        };
        if base_target > self.based.end() {
            self.make_base_rows(self.based.end(), base_target);
            self.hpass
                .evict_below(base_target.saturating_sub(self.halo.base_reach) * s);
        }
        // 5. output: base plus spread noise, once no later row can reach it.
        let by_spread = match &self.ep {
            Some(_) if self.spread_done < h => {
                self.spread_done.saturating_sub(self.halo.spread_reach)
            }
            _ => h,
        };
        let out_target = self.based.end().min(by_spread);
        let mut out = None;
        if out_target > self.out_done {
            out = Some(self.finish_rows(self.out_done, out_target)?);
            self.out_done = out_target;
            self.based.evict_below(out_target);
            self.acc.evict_below(out_target);
        }
        let keep = if self.ep.is_some() {
            self.cls_done
                .saturating_sub(self.halo.xbar_reach)
                .min(self.spread_done.saturating_sub(self.halo.search_reach))
        } else {
            yb
        };
        self.ybox.evict_below(keep.min(yb));
        Ok(out)
    }

    fn make_ybox(&mut self, a: usize, b: usize) {
        let (s, w, pad, in_w, nch) = (self.grid.s, self.w, self.pad, self.grid.in_w, self.nch);
        let inv = self.inv_s2;
        for _ in a..b {
            self.ybox.push(0.0);
        }
        let input = &self.input;
        let lum = &self.lum;
        let mut rows = self.ybox.range_mut(a, b);
        rows.par_iter_mut().enumerate().for_each(|(k, row)| {
            let y = a + k;
            let (core, _) = row.split_at_mut(w + pad);
            let core = &mut core[pad..];
            core.iter_mut().for_each(|v| *v = 0.0);
            for j in y * s..(y + 1) * s {
                let r = input.get(j);
                for c in 0..nch {
                    let lw = lum[c];
                    if lw == 0.0 {
                        continue;
                    }
                    let ch = &r[c * in_w..(c + 1) * in_w];
                    for (px, out) in core.iter_mut().enumerate() {
                        let mut acc = 0.0;
                        for &v in &ch[px * s..(px + 1) * s] {
                            acc += v as f64;
                        }
                        *out += lw * acc;
                    }
                }
            }
            core.iter_mut().for_each(|v| *v *= inv);
            for i in 0..pad {
                row[i] = row[pad + mirror(i as i64 - pad as i64, w)];
                row[pad + w + i] = row[pad + mirror((w + i) as i64, w)];
            }
        });
    }

    fn classify(&mut self, a: usize, b: usize) {
        let (s, w, in_w, nch, h) = (self.grid.s, self.w, self.grid.in_w, self.nch, self.h);
        let in_h = self.grid.in_h;
        for _ in a * s..b * s {
            self.hpass.push_stale(0.0); // every value is written below
        }
        let ep = self.ep.as_ref();
        let ybox = &self.ybox;
        let lum = &self.lum;
        let cols = &self.cols;
        let input = &self.input;
        let support = self.support;
        // Phase 1, reading the input as it came (neighbour rows included):
        // which samples are noise, and which of those are kept as features.
        let found: Vec<(Vec<Noisy>, u64)> = (a..b)
            .into_par_iter()
            .map(|y| {
                let mut found = Vec::new();
                let mut kept = 0u64;
                let Some(ep) = ep else {
                    return (found, kept);
                };
                let view = YView { win: ybox, h };
                let xbars = ep.xbar0_row(&view, y as i64, w);
                let luma = |row: &[f32], i: usize| {
                    let mut x = 0.0;
                    for c in 0..nch {
                        x += lum[c] * row[c * in_w + i] as f64;
                    }
                    x
                };
                for (px, &xbar) in xbars.iter().enumerate() {
                    let Some((hi, lo)) = ep.bounds(xbar) else {
                        continue;
                    };
                    for j in y * s..(y + 1) * s {
                        let row = input.get(j);
                        for i in px * s..(px + 1) * s {
                            let x0 = luma(row, i);
                            if !(x0 > 0.0 && (x0 > hi || x0 < lo)) {
                                continue;
                            }
                            if support.keeps(x0, hi, lo, |di, dj| {
                                let (ni, nj) = (i as i64 + di, j as i64 + dj);
                                (ni >= 0 && nj >= 0 && (ni as usize) < in_w && (nj as usize) < in_h)
                                    .then(|| luma(input.get(nj as usize), ni as usize))
                            }) {
                                kept += 1;
                                continue;
                            }
                            let mut v = [0.0f32; MAX_CHANNELS];
                            for c in 0..nch {
                                v[c] = row[c * in_w + i];
                            }
                            found.push(Noisy {
                                i: i as u32,
                                j: j as u32,
                                x0,
                                xbar0: xbar,
                                v,
                                level: 0,
                                capped: false,
                            });
                        }
                    }
                }
                // Row-major order: by input row, then column.
                found.sort_by_key(|n| (n.j, n.i));
                (found, kept)
            })
            .collect();
        // Phase 2: the horizontal pass of the base kernel, the spread
        // samples taken out (zeroed in a copy of their row).
        let mut hrows = self.hpass.range_mut(a * s, b * s);
        hrows
            .par_chunks_mut(s)
            .zip(found.par_iter())
            .enumerate()
            .for_each_init(Vec::new, |scratch, (k, (hs, (list, _)))| {
                let y = a + k;
                for (bb, hrow) in hs.iter_mut().enumerate() {
                    let j = y * s + bb;
                    let mut row = input.get(j);
                    let first = list.partition_point(|n| (n.j as usize) < j);
                    let last = list.partition_point(|n| (n.j as usize) <= j);
                    if first < last {
                        scratch.clear();
                        scratch.extend_from_slice(row);
                        for n in &list[first..last] {
                            for c in 0..nch {
                                scratch[c * in_w + n.i as usize] = 0.0;
                            }
                        }
                        row = scratch.as_slice();
                    }
                    for c in 0..nch {
                        let src = &row[c * in_w..(c + 1) * in_w];
                        let dst = &mut hrow[c * w..(c + 1) * w];
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
            });
        for (list, kept) in found {
            // Kept samples failed the test too; the spread ones are counted
            // when they are spread.
            self.counters.noisy += kept;
            self.counters.guarded += kept;
            self.pending.extend(list);
        }
    }

    fn spread(&mut self, target: usize) {
        let Some(ep) = self.ep.as_ref() else { return };
        let (s, w, h, nch) = (self.grid.s, self.w, self.h, self.nch);
        let split = self
            .pending
            .partition_point(|n| (n.j as usize) / s < target);
        let batch = &mut self.pending[..split];
        // Width search, one sample per task (each is independent of the rest).
        let view = YView { win: &self.ybox, h };
        batch.par_iter_mut().for_each(|n| {
            let c = ep.search(&view, n.i as usize / s, n.j as usize / s, n.x0, n.xbar0);
            n.level = c.level;
            n.capped = c.capped;
        });
        // Accumulator rows down to the widest reach of this batch.
        let need = (target + self.halo.spread_reach).min(h);
        while self.acc.end() < need {
            self.acc.push(-0.0);
        }
        // Spread in chunks of the (row-major) batch: the folded weights of one
        // chunk at a time bound the arena, and the order of contributions to
        // every pixel stays the batch order.
        let mut spreads = Vec::with_capacity(SPREAD_CHUNK.min(split));
        let mut tmp = Vec::new();
        for c0 in (0..split).step_by(SPREAD_CHUNK) {
            // Reflect each sample's kernel once, in order.
            self.arena.clear();
            spreads.clear();
            for n in &self.pending[c0..(c0 + SPREAD_CHUNK).min(split)] {
                self.counters.noisy += 1;
                self.counters.spread += (n.level > 0) as u64;
                self.counters.capped += n.capped as u64;
                let k = &ep.levels()[n.level as usize].kernel;
                let (i, j) = (n.i as usize, n.j as usize);
                let off = self.arena.len();
                let xs = k.fold(i % s, i / s, w, &mut tmp);
                let xl = tmp.len();
                self.arena.extend_from_slice(&tmp);
                let ys = k.fold(j % s, j / s, h, &mut tmp);
                let yl = tmp.len();
                self.arena.extend_from_slice(&tmp);
                let mut v = [0.0; MAX_CHANNELS];
                for (d, &x) in v.iter_mut().zip(&n.v).take(nch) {
                    *d = x as f64 * self.inv_s2;
                }
                spreads.push(Spread {
                    xs,
                    xl,
                    ys,
                    yl,
                    off,
                    v,
                });
            }
            scatter(&mut self.acc, &self.arena, &spreads, w, nch, self.tile);
        }
        self.pending.drain(..split);
    }

    /// The vertical gather of the base kernel for output rows `a..b`:
    /// `(sum of taps x horizontal-pass rows) / S^2`, summed in tap order.
    fn make_base_rows(&mut self, a: usize, b: usize) {
        let (w, h, nch, in_h) = (self.w, self.h, self.nch, self.grid.in_h);
        for _ in a..b {
            self.based.push_stale(0.0); // every value is written below
        }
        let base = &self.base;
        let hpass = &self.hpass;
        let inv = self.inv_s2;
        let mut rows = self.based.range_mut(a, b);
        rows.par_iter_mut()
            .enumerate()
            .for_each_init(Vec::new, |taps, (k, row)| {
                let y = a + k;
                let j0 = base.gather(y, h, in_h, taps);
                for c in 0..nch {
                    let dst = &mut row[c * w..(c + 1) * w];
                    dst.iter_mut().for_each(|v| *v = -0.0);
                    for (t, &wt) in taps.iter().enumerate() {
                        let src = &hpass.get(j0 + t)[c * w..(c + 1) * w];
                        for (d, &v) in dst.iter_mut().zip(src) {
                            *d += wt * v;
                        }
                    }
                    dst.iter_mut().for_each(|v| *v *= inv);
                }
            });
    }

    /// Output rows `a..b`: base plus accumulator, rounded, with the ledger.
    fn finish_rows(&mut self, a: usize, b: usize) -> Result<OutRows> {
        let acc = self.ep.as_ref().map(|_| &self.acc);
        self.books
            .finish(&self.based, acc, a, b, self.w, self.precision)
    }
}

/// Add `spreads` (in order) into the accumulator, one task per tile of
/// columns: each pixel receives its contributions in the given order.
fn scatter(
    acc: &mut RowWindow<f64>,
    arena: &[f64],
    spreads: &[Spread],
    w: usize,
    nch: usize,
    tile: usize,
) {
    let (first, end) = (acc.first(), acc.end());
    let ntiles = w.div_ceil(tile);
    // Planar rows [c][x]: tile t owns columns t*tile.. of every channel of
    // every row; its slices are listed row by row, channel by channel.
    let mut tiles: Vec<Vec<&mut [f64]>> = (0..ntiles)
        .map(|_| Vec::with_capacity((end - first) * nch))
        .collect();
    for row in acc.range_mut(first, end) {
        for ch in row.chunks_mut(w) {
            for (t, part) in ch.chunks_mut(tile).enumerate() {
                tiles[t].push(part);
            }
        }
    }
    tiles
        .into_par_iter()
        .enumerate()
        .for_each(|(t, mut parts)| {
            let x0 = t * tile;
            let x1 = (x0 + tile).min(w);
            for sp in spreads {
                let (cx0, cx1) = (sp.xs.max(x0), (sp.xs + sp.xl).min(x1));
                if cx0 >= cx1 {
                    continue;
                }
                let wx = &arena[sp.off + cx0 - sp.xs..sp.off + cx1 - sp.xs];
                let wy = &arena[sp.off + sp.xl..sp.off + sp.xl + sp.yl];
                for (dy, &wyv) in wy.iter().enumerate() {
                    let r = sp.ys + dy - first;
                    for c in 0..nch {
                        let coef = sp.v[c] * wyv;
                        let dst = &mut parts[r * nch + c][cx0 - x0..cx1 - x0];
                        for (d, &wv) in dst.iter_mut().zip(wx) {
                            *d += coef * wv;
                        }
                    }
                }
            }
        });
}
