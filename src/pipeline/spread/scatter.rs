//! Spreading (the third cursor): the width search of a batch of noisy
//! samples, their kernels placed (read in place, or reflected into an
//! arena), and the scatter into tile accumulators that own output columns,
//! at full resolution or on the 2x and 4x coarse grids.

use crate::filter::ep_gauss::Choice;
use rayon::iter::{IndexedParallelIterator, IntoParallelIterator, ParallelIterator};
use rayon::slice::ParallelSlice;

use super::{
    Back, ChannelMode, CoarseGrid, EpGauss, Folded, Kernel1d, Noisy, RowWindow, Rules, Shape,
    SpreadCounts, YView, SPREAD_CHUNK,
};

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

/// The spreads of a run of noisy samples placed by one task, at each
/// resolution (fine, 2x and 4x coarse), with the reflected weights and the
/// values they read, and what was counted (the width search's too). A
/// chunk's parts are scattered as they are, in order (joining them was a
/// serial copy of every spread).
#[derive(Default)]
pub(super) struct Placed {
    lists: [Vec<Spread>; 3],
    arenas: [Vec<f64>; 3],
    vals: Vec<f64>,
    counts: SpreadCounts,
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
    fn place(&self, n: &Noisy, c: &Choice, x: &[f64], out: &mut Placed, tmp: &mut Vec<f64>) {
        let s = self.s;
        out.counts.noisy += 1;
        out.counts.spread += (c.level > 0) as u64;
        out.counts.capped += c.capped as u64;
        let level = &self.ep.levels()[c.level as usize];
        let (i, j) = (n.i as usize, n.j as usize);
        let voff = out.vals.len();
        out.vals.extend(x.iter().zip(self.modes).map(|(&x, &m)| {
            if m == ChannelMode::Spread {
                x * self.inv_s2
            } else {
                0.0
            }
        }));
        debug_assert_eq!(out.vals.len(), voff + self.nch);
        // Wide kernels on a coarse grid, the others at full resolution; each
        // list keeps the batch order.
        let lv = c.level;
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

/// Samples per task of the width search and placement: a search takes
/// about a microsecond and a placement a few dozen nanoseconds (a few
/// hundred where a kernel is reflected at an edge), so a task of 64 is long
/// enough for its scheduling (and its trace event) to cost little, and
/// short enough to balance the load.
const SEARCH_TASK: usize = 256;

/// How far from an image edge (in pixels of the grid) a sample's kernels may
/// be reflected at it, and the longest row of weights one axis of a spread
/// can fold into the arena: what bounds a chunk's memory before its widths
/// are known.
#[derive(Clone, Copy, Debug)]
pub(super) struct EdgeBound {
    margin: usize,
    row_len: usize,
}

impl EdgeBound {
    fn of(ep: &EpGauss) -> Self {
        let (mut margin, mut row_len) = (0, 0);
        for l in ep.levels() {
            let r = l.kernel.reach();
            margin = margin.max(r);
            row_len = row_len.max(2 * r + 1);
            if let Some(c) = &l.coarse {
                // A coarse cell `p / f` is inside when `f * reach` pixels
                // from either edge (`Coarse::interior`).
                let rc = c.kernel.reach();
                margin = margin.max(c.factor * rc);
                row_len = row_len.max(2 * rc + 1);
            }
        }
        EdgeBound { margin, row_len }
    }

    /// The input samples `lo..hi` of each axis (columns, rows) whose pixel
    /// is at least `margin` from both edges of `0..n` pixels, `s` samples
    /// each: what [`Self::arena_len`] compares with.
    fn inner(&self, s: usize, (w, h): (usize, usize)) -> [(u32, u32); 2] {
        let lim = |n: usize| {
            let lo = (self.margin * s).min(u32::MAX as usize) as u32;
            let hi = (n.saturating_sub(self.margin) * s).min(u32::MAX as usize) as u32;
            (lo, hi)
        };
        [lim(w), lim(h)]
    }

    /// The weights sample `n` may add to its chunk's arena (0 where no
    /// kernel it could get reaches an edge), given [`Self::inner`].
    #[inline]
    fn arena_len(&self, n: &Noisy, [(x0, x1), (y0, y1)]: [(u32, u32); 2]) -> usize {
        let near = |q: u32, lo: u32, hi: u32| usize::from(q < lo || q >= hi);
        self.row_len * (near(n.i, x0, x1) + near(n.j, y0, y1))
    }
}

impl Back {
    /// The end of the chunk of pending samples that starts at `c0` (before
    /// `end`): as many as fit the memory of [`SPREAD_CHUNK`] samples whose
    /// every kernel is reflected at an edge, so that a chunk of the
    /// interior, whose kernels are read in place, takes a whole strip's
    /// samples, and the worst case holds [`SPREAD_CHUNK`] samples' weights.
    pub(super) fn chunk_end(
        &self,
        shape: &Shape,
        bound: EdgeBound,
        c0: usize,
        end: usize,
    ) -> usize {
        let per_sample = std::mem::size_of::<Spread>() + shape.nch * std::mem::size_of::<f64>();
        let weight = std::mem::size_of::<f64>();
        let chunk = match self.spread_chunk {
            0 => SPREAD_CHUNK,
            n => n,
        };
        let budget = chunk * (per_sample + 2 * bound.row_len * weight);
        if (end - c0) <= chunk {
            return end;
        }
        let Shape { grid, w, h, .. } = *shape;
        let inner = bound.inner(grid.s, (w, h));
        let mut used = 0;
        for (k, n) in self.pending.samples.range(c0..end).enumerate() {
            used += per_sample + bound.arena_len(n, inner) * weight;
            if used > budget {
                return c0 + k.max(1);
            }
        }
        end
    }

    /// Spread the pending samples of pixel rows before `target`, in the
    /// pending (row-major) order, chunk by chunk, the width search reading
    /// `view`: in one loop each sample's width searched and its kernels
    /// placed, in the next the scatter into the accumulators. The batch's
    /// samples then leave the pending list.
    pub(super) fn spread(&mut self, shape: &Shape, rules: &Rules, view: &YView<'_>, target: usize) {
        let Shape {
            grid,
            w,
            h,
            nch,
            inv_s2,
            tile,
            ..
        } = *shape;
        let Some(ep) = rules.ep.as_ref() else {
            return;
        };
        let bound = EdgeBound::of(ep);
        self.pending.samples.make_contiguous();
        self.pending.values.make_contiguous();
        let split = self
            .pending
            .samples
            .as_slices()
            .0
            .partition_point(|n| (n.j as usize) / grid.s < target);
        // Each grid's rows down to what its own kernels reach from this
        // batch's last row (and a spare on the coarse ones), not the widest
        // kernel's: the output grid's kernels reach a few rows, and its
        // rows are the widest. The batch's first scatter fills them, a tile
        // each.
        let [fine, r2, r4] = [1, 2, 4].map(|f| ep.grid_reach(f));
        let mut fresh = [
            grow(&mut self.acc, (target + fine).min(h)),
            grow(
                &mut self.c2.acc,
                (target.div_ceil(2) + r2 + 1).min(h.div_ceil(2)),
            ),
            grow(
                &mut self.c4.acc,
                (target.div_ceil(4) + r4 + 1).min(h.div_ceil(4)),
            ),
        ]
        .map(Some);
        let place = SearchPlace::new(ep, view, &rules.modes, inv_s2, (grid.s, nch), (w, h));
        let mut next = 0;
        loop {
            let c1 = self.chunk_end(shape, bound, next, split);
            let region = crate::trace::region("search and place");
            let parts = place.run(
                &self.pending.samples.as_slices().0[next..c1],
                &self.pending.values.as_slices().0[next * nch..c1 * nch],
                &region,
            );
            drop(region);
            let region = crate::trace::region("scatter");
            let mut accs = Accs::new(
                ep,
                (&mut self.acc, &mut self.c2, &mut self.c4),
                w,
                nch,
                tile,
            );
            accs.scatter(&parts, &mut fresh, &region);
            drop(region);
            for part in &parts {
                self.counts += part.counts;
            }
            next = c1;
            if next >= split {
                break;
            }
        }
        self.pending.samples.drain(..split);
        self.pending.values.drain(..split * nch);
    }
}

/// What a chunk's width search and placement read.
pub(super) struct SearchPlace<'a> {
    view: &'a YView<'a>,
    ctx: PlaceCtx<'a>,
}

impl<'a> SearchPlace<'a> {
    /// The search reads the box luminance (and its summed-area table with
    /// its block), the placement the channels' modes, the grids' sizes (`w`
    /// x `h` pixels, S, channels).
    pub(super) fn new(
        ep: &'a EpGauss,
        view: &'a YView<'a>,
        modes: &'a [ChannelMode],
        inv_s2: f64,
        (s, nch): (usize, usize),
        (w, h): (usize, usize),
    ) -> Self {
        SearchPlace {
            view,
            ctx: PlaceCtx {
                ep,
                modes,
                inv_s2,
                s,
                nch,
                fine: (w, h),
                c2: (w.div_ceil(2), h.div_ceil(2)),
                c4: (w.div_ceil(4), h.div_ceil(4)),
            },
        }
    }

    /// Each sample's width searched and its kernels placed (reflected where
    /// they cross an edge), in tasks of `region`. The parts in order.
    pub(super) fn run(
        &self,
        samples: &[Noisy],
        values: &[f64],
        region: &crate::trace::Span,
    ) -> Vec<Placed> {
        let (ctx, view) = (&self.ctx, self.view);
        let (s, nch, ep) = (ctx.s, ctx.nch, ctx.ep);
        samples
            .par_chunks(SEARCH_TASK)
            .zip(values.par_chunks(SEARCH_TASK * nch))
            .map_init(
                <(Folded, Vec<f64>)>::default,
                |(fold, tmp), (samples, values)| {
                    let _task = region.task("search and place");
                    let mut part = Placed::default();
                    for (n, x) in samples.iter().zip(values.chunks_exact(nch)) {
                        let (px, py) = (n.i as usize / s, n.j as usize / s);
                        let c = ep.search_in(view, px, py, n.x0, n.xbar0, fold);
                        part.counts.search_cost += c.cost;
                        part.counts.bounded += u64::from(c.bounded);
                        ctx.place(n, &c, x, &mut part, tmp);
                    }
                    part
                },
            )
            .collect()
    }
}

/// The accumulators a chunk is scattered into: the fine grid's and the
/// coarse grids'.
pub(super) struct Accs<'a> {
    ep: &'a EpGauss,
    acc: &'a mut RowWindow<f64>,
    c2: &'a mut CoarseGrid,
    c4: &'a mut CoarseGrid,
    w: usize,
    nch: usize,
    tile: usize,
}

impl<'a> Accs<'a> {
    /// The fine, 2x and 4x grids, `w` pixels wide, `nch` channels, tiles of
    /// `tile` fine pixels.
    pub(super) fn new(
        ep: &'a EpGauss,
        (acc, c2, c4): (
            &'a mut RowWindow<f64>,
            &'a mut CoarseGrid,
            &'a mut CoarseGrid,
        ),
        w: usize,
        nch: usize,
        tile: usize,
    ) -> Self {
        Accs {
            ep,
            acc,
            c2,
            c4,
            w,
            nch,
            tile,
        }
    }

    /// Scatter `parts` (in order): the three grids' tiles are the tasks of
    /// one loop, each pixel getting its grid's spreads in order, from one
    /// task. The tiles first fill their
    /// grid's `fresh` rows (-0.0 on the accumulator, whose untouched pixels
    /// keep the sign of the base's zero; 0.0 on the coarse grids), which
    /// are then filled.
    pub(super) fn scatter(
        &mut self,
        parts: &[Placed],
        fresh: &mut [Option<usize>; 3],
        region: &crate::trace::Span,
    ) {
        let ep = self.ep;
        let mut used = [false; 3];
        for part in parts {
            for (u, list) in used.iter_mut().zip(&part.lists) {
                *u |= !list.is_empty();
            }
        }
        // The 4x grid goes through the 2x one: its rows carry the share.
        self.c2.used |= used[1] || used[2];
        self.c4.used |= used[2];
        let fine_rows = |l: u16, ph: u16| ep.levels()[l as usize].kernel.row(ph as usize);
        let coarse_rows = |l: u16, ph: u16| {
            ep.levels()[l as usize]
                .coarse
                .as_ref()
                .map_or(&[][..], |c| c.kernel.row(ph as usize))
        };
        let (w, tile) = (self.w, self.tile);
        let grids: [(_, _, &KernelRows<'_>, _); 3] = [
            (&mut *self.acc, w, &fine_rows, 1),
            (&mut self.c2.acc, w.div_ceil(2), &coarse_rows, 2),
            (&mut self.c4.acc, w.div_ceil(4), &coarse_rows, 4),
        ];
        let fills = [-0.0, 0.0, 0.0];
        let grids = grids
            .into_iter()
            .enumerate()
            .filter(|&(k, (ref acc, ..))| used[k] || fresh[k].is_some_and(|f| f < acc.end()))
            .map(|(k, (acc, w, rows, f))| GridScatter {
                acc,
                src: SpreadSrc {
                    parts,
                    grid: k,
                    rows,
                },
                fresh: fresh[k].map(|from| (from, fills[k])),
                w,
                tile: (tile / f).max(1),
            })
            .collect();
        scatter(grids, self.nch, region);
        *fresh = [None; 3];
    }
}

/// Rows of `win` up to `end` (absolute), not yet filled; returns the
/// first of them (what the scatter fills, [`GridScatter::fresh`]).
fn grow(win: &mut RowWindow<f64>, end: usize) -> usize {
    let from = win.end();
    for _ in from..end {
        win.push_stale(0.0); // the first scatter of the batch fills them
    }
    from
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

/// A chunk's spreads for one grid: its parts (each with its spreads in
/// order, their folded weights and values), the grid's index in them, and
/// the kernel rows they name.
#[derive(Clone, Copy)]
struct SpreadSrc<'a, 'k> {
    parts: &'a [Placed],
    grid: usize,
    rows: &'a KernelRows<'k>,
}

/// One accumulator grid and what it receives from a chunk.
struct GridScatter<'a, 'k> {
    acc: &'a mut RowWindow<f64>,
    src: SpreadSrc<'a, 'k>,
    /// The first row the batch added and the value its rows start from,
    /// which this scatter's tasks write first (the batch's first scatter).
    fresh: Option<(usize, f64)>,
    /// Columns of the grid, and of one of its tiles.
    w: usize,
    tile: usize,
}

/// Add each grid's spreads (in order) into its accumulator: every column
/// tile of every grid is a task of one loop, so each pixel receives its
/// contributions in the given order from one task, whatever the tile size.
fn scatter(grids: Vec<GridScatter<'_, '_>>, nch: usize, region: &crate::trace::Span) {
    let mut tasks = Vec::new();
    for g in grids {
        let first = g.acc.first();
        let (w, tile) = (g.w, g.tile);
        let tiles = crate::pipeline::tiles::column_tiles(g.acc, w, nch, tile);
        for (t, parts) in tiles.into_iter().enumerate() {
            tasks.push(TileJob {
                cols: t * tile..((t + 1) * tile).min(w),
                parts,
                first,
                src: g.src,
                fresh: g.fresh,
            });
        }
    }
    if tasks.is_empty() {
        return;
    }
    tasks.into_par_iter().for_each(|mut job| {
        let _task = region.task("scatter");
        scatter_tile(&mut job, nch);
    });
}

/// One column tile of a grid and what [`scatter_tile`] adds into it.
struct TileJob<'a, 'k> {
    cols: std::ops::Range<usize>,
    /// The tile's slices as [`crate::pipeline::tiles::column_tiles`] lists
    /// them, from the window's row `first`.
    parts: Vec<&'a mut [f64]>,
    first: usize,
    src: SpreadSrc<'a, 'k>,
    fresh: Option<(usize, f64)>,
}

/// [`scatter`]'s task: the tile's new rows filled, then the spreads of
/// `src` added into it, in order.
fn scatter_tile(job: &mut TileJob<'_, '_>, nch: usize) {
    let TileJob {
        cols,
        parts,
        first,
        src: SpreadSrc {
            parts: placed,
            grid,
            rows,
        },
        fresh,
    } = job;
    let (first, grid, rows) = (*first, *grid, *rows);
    if let Some((from, fill)) = *fresh {
        parts[(from - first) * nch..]
            .iter_mut()
            .for_each(|p| p.fill(fill));
    }
    let (x0, x1) = (cols.start, cols.end);
    let spreads = placed.iter().flat_map(|p| {
        let (arena, vals) = (&p.arenas[grid][..], &p.vals[..]);
        p.lists[grid].iter().map(move |sp| (sp, arena, vals))
    });
    for (sp, arena, vals) in spreads {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterParams;
    use crate::filter::Method;
    use crate::geometry::Grid;
    use crate::pipeline::spread::GaussianStage;

    /// An ep-gauss stage of 400x400 pixels at S = 1, with `n` pending
    /// samples at pixel `(x, y)`.
    fn stage_with(n: usize, (x, y): (u32, u32)) -> GaussianStage {
        let p = FilterParams::new(Method::EpGauss, 1);
        let grid = Grid {
            in_w: 400,
            in_h: 400,
            s: 1,
        };
        let mut st = super::super::tests::stage(&p, grid);
        let sample = Noisy {
            i: x,
            j: y,
            x0: 1.0,
            xbar0: 0.0,
        };
        st.back.pending.samples = vec![sample; n].into();
        st
    }

    #[test]
    fn a_chunk_holds_the_memory_of_spread_chunk_samples_at_an_edge() {
        // Three chunks' worth of samples, more than one chunk's count.
        let n = 3 * SPREAD_CHUNK;
        // In the middle no kernel reaches an edge: one chunk.
        let mid = stage_with(n, (200, 200));
        let bound = EdgeBound::of(mid.rules.ep.as_ref().unwrap());
        assert!(bound.margin < 200, "the test's middle is inside");
        assert_eq!(mid.back.chunk_end(&mid.shape, bound, 0, n), n);
        // In a corner every kernel may fold on both axes: SPREAD_CHUNK a
        // chunk, the memory it always had.
        let corner = stage_with(n, (0, 0));
        assert_eq!(
            corner.back.chunk_end(&corner.shape, bound, 0, n),
            SPREAD_CHUNK
        );
        assert_eq!(
            corner.back.chunk_end(&corner.shape, bound, SPREAD_CHUNK, n),
            2 * SPREAD_CHUNK
        );
        // A configured chunk still makes progress of one sample at least.
        let mut tiny = stage_with(4, (0, 0));
        tiny.set_spread_chunk(1);
        assert_eq!(tiny.back.chunk_end(&tiny.shape, bound, 0, 4), 1);
        // On one edge, one axis: about twice as many samples.
        let edge = stage_with(n, (0, 200));
        let end = edge.back.chunk_end(&edge.shape, bound, 0, n);
        assert!(end > SPREAD_CHUNK && end < 2 * SPREAD_CHUNK + 64, "{end}");
    }
}
