//! Spreading (the third cursor): the width search of a batch of noisy
//! samples, their kernels placed (read in place, or reflected into an
//! arena), and the scatter into tile accumulators that own output columns,
//! at full resolution or on the 2x and 4x coarse grids.

use rayon::prelude::*;

use super::*;

/// Where the weights of one axis of a spread are.
#[derive(Clone, Copy, Debug)]
enum Weights {
    /// Reflected at an edge: at this offset in the chunk's arena.
    Arena(usize),
    /// Inside the image: a row of the level's kernel as it is (level,
    /// phase), read in place instead of copied.
    Kernel(u16, u16),
}

#[derive(Clone, Copy, Debug)]
struct Spread {
    xs: usize,
    xl: usize,
    ys: usize,
    yl: usize,
    wx: Weights,
    wy: Weights,
    /// Where its value in each channel is, in the chunk's values.
    voff: usize,
}

impl Spread {
    fn new(
        (xs, xl, wx): (usize, usize, Weights),
        (ys, yl, wy): (usize, usize, Weights),
        voff: usize,
    ) -> Self {
        Spread {
            xs,
            xl,
            ys,
            yl,
            wx,
            wy,
            voff,
        }
    }
}

/// Samples per task of the kernels' placement (each a few hundred
/// nanoseconds where it is reflected at an edge, a few dozen inside).
const PLACE_TASK: usize = 512;

/// The spreads of a run of noisy samples, at each resolution (fine, 2x and
/// 4x coarse), with the reflected weights and the values they read, and
/// what was counted: a part placed by one task, or the parts of a chunk
/// joined in order.
#[derive(Default)]
pub(super) struct Placed {
    lists: [Vec<Spread>; 3],
    arenas: [Vec<f64>; 3],
    vals: Vec<f64>,
    counts: SpreadCounts,
}

impl Placed {
    fn clear(&mut self) {
        self.lists.iter_mut().for_each(Vec::clear);
        self.arenas.iter_mut().for_each(Vec::clear);
        self.vals.clear();
        self.counts = SpreadCounts::default();
    }

    /// `part`'s spreads after this one's: its offsets into the arenas and
    /// the values moved past what this one holds.
    fn append(&mut self, part: Placed) {
        let voff = self.vals.len();
        for k in 0..3 {
            let aoff = self.arenas[k].len();
            self.lists[k].extend(part.lists[k].iter().map(|sp| Spread {
                wx: sp.wx.moved(aoff),
                wy: sp.wy.moved(aoff),
                voff: sp.voff + voff,
                ..*sp
            }));
            self.arenas[k].extend_from_slice(&part.arenas[k]);
        }
        self.vals.extend_from_slice(&part.vals);
        self.counts += part.counts;
    }
}

impl Weights {
    /// The same weights after the arena they are in moved by `by`.
    fn moved(self, by: usize) -> Weights {
        match self {
            Weights::Arena(off) => Weights::Arena(off + by),
            k => k,
        }
    }
}

/// What placing a sample's kernels reads: the ladder, the channels, the
/// grids' sizes.
struct PlaceCtx<'a> {
    ep: &'a EpGauss,
    modes: &'a [ChannelMode],
    inv_s2: f64,
    s: usize,
    nch: usize,
    /// Columns and rows of the fine, 2x and 4x grids.
    fine: (usize, usize),
    c2: (usize, usize),
    c4: (usize, usize),
}

impl PlaceCtx<'_> {
    /// Place noisy sample `n` (values `x`) in `out`: its values, and its
    /// kernels on the grid its width goes to (read in place inside the
    /// image, reflected into the arena at an edge).
    fn place(&self, n: &Noisy, x: &[f32], out: &mut Placed, tmp: &mut Vec<f64>) {
        let s = self.s;
        out.counts.noisy += 1;
        out.counts.spread += (n.level > 0) as u64;
        out.counts.capped += n.capped as u64;
        let level = &self.ep.levels()[n.level as usize];
        let (i, j) = (n.i as usize, n.j as usize);
        let voff = out.vals.len();
        out.vals.extend(x.iter().zip(self.modes).map(|(&x, &m)| {
            if m == ChannelMode::Spread {
                x as f64 * self.inv_s2
            } else {
                0.0
            }
        }));
        debug_assert_eq!(out.vals.len(), voff + self.nch);
        // Wide kernels on a coarse grid, the others at full resolution; each
        // list keeps the batch order.
        let lv = n.level;
        let (sp, k) = match &level.coarse {
            Some(c) => {
                out.counts.coarse += 1;
                let four = c.factor == 4;
                out.counts.coarse4 += u64::from(four);
                let (k, cells) = if four { (2, self.c4) } else { (1, self.c2) };
                let arena = &mut out.arenas[k];
                let mut axis = |q: usize, n: usize| {
                    let (a, p) = (q % s, q / s);
                    let inside = c.interior(a, p, n);
                    place(&c.kernel, inside, lv, arena, tmp, |t| c.fold(a, p, n, t))
                };
                let (x, y) = (axis(i, cells.0), axis(j, cells.1));
                (Spread::new(x, y, voff), k)
            }
            None => {
                let kernel = &level.kernel;
                let arena = &mut out.arenas[0];
                let mut axis = |q: usize, n: usize| {
                    let (a, p) = (q % s, q / s);
                    let inside = kernel.interior(p, n).map(|st| (a, st));
                    place(kernel, inside, lv, arena, tmp, |t| kernel.fold(a, p, n, t))
                };
                let (x, y) = (axis(i, self.fine.0), axis(j, self.fine.1));
                (Spread::new(x, y, voff), 0)
            }
        };
        out.counts.spread_taps += (sp.xl * sp.yl) as u64;
        out.lists[k].push(sp);
    }
}

/// Samples per task of the width search: a search takes about a
/// microsecond, so a task of 64 is long enough for its scheduling (and its
/// trace event) to cost little, and short enough to balance the load.
const SEARCH_TASK: usize = 64;

impl GaussianStage {
    /// The width search of the pending samples `from..to`, in tasks of
    /// [`SEARCH_TASK`] samples (each sample is independent of the rest).
    fn search_widths(&mut self, from: usize, to: usize) {
        let Some(ep) = self.ep.as_ref() else { return };
        let s = self.grid.s;
        let batch = &mut self.pending[from..to];
        let mut view = YView::new(&self.ybox, self.h);
        if let Some((csum, block)) = &self.csum {
            view = view.with_csums(csum, *block);
        }
        let region = crate::trace::region("width search");
        let (cost, bounded): (u64, u64) = batch
            .par_chunks_mut(SEARCH_TASK)
            .map_init(Folded::default, |fold, chunk| {
                let _task = region.task("width search");
                let (mut cost, mut bounded) = (0, 0);
                for n in chunk {
                    let c = ep.search_in(
                        &view,
                        n.i as usize / s,
                        n.j as usize / s,
                        n.x0,
                        n.xbar0,
                        fold,
                    );
                    n.level = c.level;
                    n.capped = c.capped;
                    cost += c.cost;
                    bounded += u64::from(c.bounded);
                }
                (cost, bounded)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        self.counts.search_cost += cost;
        self.counts.bounded += bounded;
    }

    /// Spread the pending samples of pixel rows before `target`: their
    /// widths, their kernels placed in chunks of [`SPREAD_CHUNK`], and the
    /// scatter into the accumulators, in the pending (row-major) order.
    /// (Long: one chunk loop places each kernel at one of three resolutions;
    /// the three lists share the chunk's arena and values.)
    pub(super) fn spread(&mut self, target: usize) {
        let (s, w, h, nch) = (self.grid.s, self.w, self.h, self.nch);
        let first = self.pending_first;
        let split = first + self.pending[first..].partition_point(|n| (n.j as usize) / s < target);
        self.search_widths(first, split);
        let Some(ep) = self.ep.as_ref() else { return };
        // Accumulator rows down to the widest reach of this batch.
        let need = (target + self.halo.spread_reach).min(h);
        grow_filled(&mut self.acc, need, -0.0);
        // Coarse rows reaching fine rows below `need` (and a spare).
        let (ncw, coarse_rows) = (w.div_ceil(2), h.div_ceil(2));
        grow_filled(
            &mut self.c2.acc,
            (need.div_ceil(2) + 1).min(coarse_rows),
            0.0,
        );
        // 4x row K reaches fine rows 4K - 3 ..= 4K + 6.
        let (ncw4, coarse_rows4) = (w.div_ceil(4), h.div_ceil(4));
        grow_filled(
            &mut self.c4.acc,
            (need.div_ceil(4) + 1).min(coarse_rows4),
            0.0,
        );
        // Spread in chunks of the (row-major) batch: the folded weights of one
        // chunk at a time bound the arena, and the order of contributions to
        // every pixel stays the batch order.
        let ctx = PlaceCtx {
            ep,
            modes: &self.modes,
            inv_s2: self.inv_s2,
            s,
            nch,
            fine: (w, h),
            c2: (ncw, coarse_rows),
            c4: (ncw4, coarse_rows4),
        };
        let mut placed = std::mem::take(&mut self.placed);
        for c0 in (first..split).step_by(SPREAD_CHUNK) {
            let c1 = (c0 + SPREAD_CHUNK).min(split);
            // Each sample's kernels placed (reflected where they cross an
            // edge) in parallel parts, joined in order.
            let region = crate::trace::region("place kernels");
            let parts: Vec<Placed> = self.pending[c0..c1]
                .par_chunks(PLACE_TASK)
                .zip(self.pending_v[c0 * nch..c1 * nch].par_chunks(PLACE_TASK * nch))
                .map_init(Vec::new, |tmp, (samples, values)| {
                    let _task = region.task("place kernels");
                    let mut part = Placed::default();
                    for (n, x) in samples.iter().zip(values.chunks_exact(nch)) {
                        ctx.place(n, x, &mut part, tmp);
                    }
                    part
                })
                .collect();
            drop(region);
            placed.clear();
            for part in parts {
                placed.append(part);
            }
            self.counts += placed.counts;
            let fine_rows = |l: u16, ph: u16| ep.levels()[l as usize].kernel.row(ph as usize);
            let coarse_rows = |l: u16, ph: u16| {
                ep.levels()[l as usize]
                    .coarse
                    .as_ref()
                    .map_or(&[][..], |c| c.kernel.row(ph as usize))
            };
            // The 4x grid goes through the 2x one: its rows carry the share.
            let [_, two, four] = placed.lists.each_ref().map(|l| !l.is_empty());
            self.c2.used |= two || four;
            self.c4.used |= four;
            // The three grids' tiles in one parallel loop: one join a chunk,
            // not three (each costs its lane a wake-up; docs/DESIGN.md, "The
            // model's join"). Each pixel still gets its grid's spreads in
            // order, from one task.
            let grids: [(_, _, &KernelRows<'_>, _); 3] = [
                (&mut self.acc, w, &fine_rows, 1),
                (&mut self.c2.acc, ncw, &coarse_rows, 2),
                (&mut self.c4.acc, ncw4, &coarse_rows, 4),
            ];
            let grids = grids
                .into_iter()
                .zip(placed.lists.iter().zip(&placed.arenas))
                .filter(|(_, (spreads, _))| !spreads.is_empty())
                .map(|((acc, w, rows, k), (spreads, arena))| GridScatter {
                    acc,
                    src: SpreadSrc {
                        arena,
                        rows,
                        spreads,
                    },
                    w,
                    tile: (self.tile / k).max(1),
                })
                .collect();
            scatter(grids, &placed.vals, nch);
        }
        self.placed = placed;
        self.pending_first = split;
        if 2 * split >= self.pending.len() {
            self.pending.drain(..split);
            self.pending_v.drain(..split * nch);
            self.pending_first = 0;
        }
    }
}

/// Rows of `win` up to `end` (absolute), the new ones filled with `fill`
/// in parallel (an accumulator row of 2048 pixels and 3 channels is 48 KiB:
/// filled one after another, they were a serial stretch of every strip).
fn grow_filled(win: &mut RowWindow<f64>, end: usize, fill: f64) {
    let from = win.end();
    if end <= from {
        return;
    }
    for _ in from..end {
        win.push_stale(fill);
    }
    win.range_mut(from, end)
        .into_par_iter()
        .for_each(|r| r.fill(fill));
}

/// One axis of a sample's spread: its first target, its length and where
/// its weights are. `inside` (phase, first target) when the kernel's row
/// lands whole inside the image, read in place; otherwise `fold` reflects
/// it into `tmp` and it is appended to `arena`.
fn place(
    kernel: &Kernel1d,
    inside: Option<(usize, usize)>,
    level: u16,
    arena: &mut Vec<f64>,
    tmp: &mut Vec<f64>,
    fold: impl FnOnce(&mut Vec<f64>) -> usize,
) -> (usize, usize, Weights) {
    match inside {
        Some((phase, start)) => (
            start,
            kernel.row(phase).len(),
            Weights::Kernel(level, phase as u16),
        ),
        None => {
            let start = fold(tmp);
            let off = arena.len();
            arena.extend_from_slice(tmp);
            (start, tmp.len(), Weights::Arena(off))
        }
    }
}

/// The kernel row a spread names by level and phase.
type KernelRows<'k> = dyn Fn(u16, u16) -> &'k [f64] + Sync + 'k;

/// A chunk's spreads for one grid (in order), their folded weights and the
/// kernel rows they name.
#[derive(Clone, Copy)]
struct SpreadSrc<'a, 'k> {
    arena: &'a [f64],
    rows: &'a KernelRows<'k>,
    spreads: &'a [Spread],
}

/// One accumulator grid and what it receives from a chunk.
struct GridScatter<'a, 'k> {
    acc: &'a mut RowWindow<f64>,
    src: SpreadSrc<'a, 'k>,
    /// Columns of the grid, and of one of its tiles.
    w: usize,
    tile: usize,
}

/// Add each grid's spreads (in order) into its accumulator: every column
/// tile of every grid is a task of one loop, so each pixel receives its
/// contributions in the given order from one task, whatever the tile size.
fn scatter(grids: Vec<GridScatter<'_, '_>>, vals: &[f64], nch: usize) {
    let mut tasks = Vec::new();
    for g in grids {
        let first = g.acc.first();
        let (w, tile) = (g.w, g.tile);
        let tiles = crate::pipeline::tiles::column_tiles(g.acc, w, nch, tile);
        for (t, parts) in tiles.into_iter().enumerate() {
            tasks.push((t * tile..((t + 1) * tile).min(w), parts, first, g.src));
        }
    }
    if tasks.is_empty() {
        return;
    }
    let region = crate::trace::region("scatter");
    tasks
        .into_par_iter()
        .for_each(|(cols, mut parts, first, src)| {
            let _task = region.task("scatter");
            scatter_tile(cols, &mut parts, first, src, vals, nch);
        });
}

/// [`scatter`]'s task: `src`'s spreads added into one column tile of a grid
/// (`parts` as [`crate::pipeline::tiles::column_tiles`] lists them, from
/// the window's row `first`).
fn scatter_tile(
    cols: std::ops::Range<usize>,
    parts: &mut [&mut [f64]],
    first: usize,
    src: SpreadSrc<'_, '_>,
    vals: &[f64],
    nch: usize,
) {
    let SpreadSrc {
        arena,
        rows,
        spreads,
    } = src;
    let (x0, x1) = (cols.start, cols.end);
    for sp in spreads {
        let (cx0, cx1) = (sp.xs.max(x0), (sp.xs + sp.xl).min(x1));
        if cx0 >= cx1 {
            continue;
        }
        let weights = |at: Weights, len: usize| match at {
            Weights::Arena(off) => &arena[off..off + len],
            Weights::Kernel(l, ph) => rows(l, ph),
        };
        let wx = &weights(sp.wx, sp.xl)[cx0 - sp.xs..cx1 - sp.xs];
        let wy = weights(sp.wy, sp.yl);
        let v = &vals[sp.voff..sp.voff + nch];
        // Colour without alpha, the common case: the three channels in one
        // loop (each value gets the same products in the same order as
        // channel by channel).
        let rgb = nch >= 3 && v[..3].iter().all(|&v| v != 0.0) && v[3..].iter().all(|&v| v == 0.0);
        for (dy, &wyv) in wy.iter().enumerate() {
            let r = sp.ys + dy - first;
            if rgb {
                let (k0, k1, k2) = (v[0] * wyv, v[1] * wyv, v[2] * wyv);
                if let [a, b, c, ..] = &mut parts[r * nch..(r + 1) * nch] {
                    let span = cx0 - x0..cx1 - x0;
                    let (a, b, c) = (&mut a[span.clone()], &mut b[span.clone()], &mut c[span]);
                    for (((a, b), c), &wv) in a.iter_mut().zip(b).zip(c).zip(wx) {
                        *a += k0 * wv;
                        *b += k1 * wv;
                        *c += k2 * wv;
                    }
                }
                continue;
            }
            for c in (0..nch).filter(|&c| v[c] != 0.0) {
                let coef = v[c] * wyv;
                let dst = &mut parts[r * nch + c][cx0 - x0..cx1 - x0];
                for (d, &wv) in dst.iter_mut().zip(wx) {
                    *d += coef * wv;
                }
            }
        }
    }
}
