//! The field that carries each block's target in the denoiser's shape:
//! `c = max(s + t (f - 1), 0)`, `f` bilinear between block centres, one
//! coefficient per block, solved a few rows of blocks at a time.

use std::collections::VecDeque;

/// Jacobi iterations of the field's solve: each brings every block's sum
/// closer to its target by the share its own coefficient carries (about
/// half of a block's sum), so the error shrinks geometrically and a few
/// dozen steps leave `g` close to one; the unit test bounds what is left.
pub const FIELD_ITERATIONS: usize = 20;

/// Block rows the field looks ahead when it fixes a row's coefficients:
/// each block couples only to its neighbours, and what a block row two
/// below does to this one is a few percent of a few percent.
pub const LOOKAHEAD: usize = 2;

/// Where pixel `p` of a line `n` long lies between the centres of blocks
/// of `b`: the two blocks' indices and weights (`w0 + w1 = 1`; one block
/// with weight one before the first centre and after the last).
#[inline]
pub fn tent(p: usize, n: usize, b: usize) -> (usize, usize, f64, f64) {
    let nb = n.div_ceil(b);
    let c = (p as f64 + 0.5) / b as f64 - 0.5;
    if c <= 0.0 {
        return (0, 0, 1.0, 0.0);
    }
    let i0 = c.floor() as usize;
    if i0 + 1 >= nb {
        return (nb - 1, nb - 1, 1.0, 0.0);
    }
    let w1 = c - i0 as f64;
    (i0, i0 + 1, 1.0 - w1, w1)
}

/// One row of blocks being solved: per block its carrier's sum (`Σ t`)
/// and moments (`Σ t φ_k` over its pixels for the tents `φ_k` of its
/// 3 x 3 neighbours, `(dj + 1) * 3 + (di + 1)`) and, once fixed, its
/// coefficient.
#[derive(Clone, Debug)]
struct BlockRow {
    carried: Vec<f64>,
    moments: Vec<[f64; 9]>,
    rho: Option<Vec<f64>>,
}

impl BlockRow {
    fn new(nbx: usize) -> Self {
        BlockRow {
            carried: vec![0.0; nbx],
            moments: vec![[0.0; 9]; nbx],
            rho: None,
        }
    }
}

/// The field of one channel over a `w x h` image in blocks of `b`. Every
/// block's target and shape sum are known before a row comes (the first
/// pass); the rows then come in order with their carrier's moments
/// ([`FieldRows::add_moments`]), a row of blocks is fixed once the rows
/// [`LOOKAHEAD`] below it have theirs ([`FieldRows::fix`]), and rows no
/// longer read are dropped ([`FieldRows::release`]).
#[derive(Clone, Debug)]
pub struct FieldRows {
    /// Block side, pixels.
    pub b: usize,
    h: usize,
    /// Blocks per row.
    pub nbx: usize,
    /// Blocks per column.
    pub nby: usize,
    /// Per block (row-major): its target and what the denoiser's shape
    /// holds there.
    target: Vec<f64>,
    shape: Vec<f64>,
    w: usize,
    /// The block row of `rows[0]`.
    first: usize,
    rows: VecDeque<BlockRow>,
    /// [`tent`] of every column.
    tents_x: Vec<(usize, usize, f64, f64)>,
}

impl FieldRows {
    /// The field of a `w x h` image in blocks of `b` whose blocks (row-major)
    /// have these targets and shape sums.
    pub fn new(w: usize, h: usize, b: usize, target: Vec<f64>, shape: Vec<f64>) -> Self {
        let (nbx, nby) = (w.div_ceil(b), h.div_ceil(b));
        assert_eq!((target.len(), shape.len()), (nbx * nby, nbx * nby));
        FieldRows {
            b,
            h,
            nbx,
            nby,
            target,
            shape,
            w,
            first: 0,
            rows: Default::default(),
            tents_x: (0..w).map(|x| tent(x, w, b)).collect(),
        }
    }

    /// Block `(i, j)`'s carrier choice: the mean of its shape, and 1 where
    /// its target is more than the shape holds, else 0.
    fn choice(&self, i: usize, j: usize) -> (f64, f64) {
        let b = self.b;
        let n = (b.min(self.w - i * b) * b.min(self.h - j * b)) as f64;
        let (t, s) = (self.target[j * self.nbx + i], self.shape[j * self.nbx + i]);
        (s / n, if t > s { 1.0 } else { 0.0 })
    }

    fn block_row(&mut self, jb: usize) -> &mut BlockRow {
        while self.first + self.rows.len() <= jb {
            self.rows.push_back(BlockRow::new(self.nbx));
        }
        &mut self.rows[jb - self.first]
    }

    /// The carrier `t` along pixel row `y`, `s` its shape: `s^2 / m` where
    /// the blocks need more energy than the denoiser gave, `s` where they
    /// need less, bilinear between block centres as the field is (`m` the
    /// block means of `s`; zero where either is). A denoiser loses energy
    /// at its brightest features (it dims and spreads them), so what a
    /// block lacks goes back mostly to the pixels brighter than their
    /// surroundings; a surplus comes off in proportion, so no highlight is
    /// dimmed more than its block. Where the shape is flat (`s = m`) both
    /// are `s`.
    pub fn carrier(&self, y: usize, s: &[f64], t: &mut [f64]) {
        let (j0, j1, wy0, wy1) = tent(y, self.h, self.b);
        let nbx = self.nbx;
        // Block by block: the means and choices of its row's neighbours
        // blended down the column once, then across per pixel.
        let down = |i: usize| {
            let (a, b) = (self.choice(i, j0), self.choice(i, j1));
            (wy0 * a.0 + wy1 * b.0, wy0 * a.1 + wy1 * b.1)
        };
        let cols = (t.chunks_mut(self.b).zip(s.chunks(self.b))).zip(self.tents_x.chunks(self.b));
        for (ib, ((t, s), tents)) in cols.enumerate() {
            let v =
                [ib.wrapping_sub(1), ib, ib + 1].map(
                    |i| {
                        if i < nbx {
                            down(i)
                        } else {
                            (0.0, 0.0)
                        }
                    },
                );
            if v.iter().all(|v| v.1 == 0.0) {
                // Every block around needs less: the shape itself.
                t.copy_from_slice(s);
                continue;
            }
            for ((t, &sx), &(i0, i1, wx0, wx1)) in t.iter_mut().zip(s).zip(tents) {
                let (a, b) = (v[i0 + 1 - ib], v[i1 + 1 - ib]);
                let m = wx0 * a.0 + wx1 * b.0;
                let more = wx0 * a.1 + wx1 * b.1;
                *t = if sx > 0.0 && m > 0.0 {
                    sx * (1.0 - more + more * sx / m)
                } else {
                    0.0
                };
            }
        }
    }

    /// Row `y`'s carrier `t` as block sums `(Σ t, moments)` of `nbx`
    /// blocks into `out` (zeroed by the caller).
    pub fn moment_sums(&self, y: usize, t: &[f64], out: &mut [(f64, [f64; 9])]) {
        let (j0, j1, wy0, wy1) = tent(y, self.h, self.b);
        let jb = y / self.b;
        let (k0, k1) = ((j0 + 1 - jb) * 3, (j1 + 1 - jb) * 3);
        // Block by block (no division per pixel); each moment takes
        // `(t wx) wy`.
        let cols = t.chunks(self.b).zip(self.tents_x.chunks(self.b));
        for (ib, (t, tents)) in cols.enumerate().take(self.nbx) {
            let o = &mut out[ib];
            for (&tx, &(i0, i1, wx0, wx1)) in t.iter().zip(tents) {
                if tx == 0.0 {
                    continue;
                }
                o.0 += tx;
                let (c0, c1) = (i0 + 1 - ib, i1 + 1 - ib);
                let (t0, t1) = (tx * wx0, tx * wx1);
                o.1[k0 + c0] += t0 * wy0;
                o.1[k0 + c1] += t1 * wy0;
                o.1[k1 + c0] += t0 * wy1;
                o.1[k1 + c1] += t1 * wy1;
            }
        }
    }

    /// Add row `y`'s carrier sums (rows come in order).
    pub fn add_moments(&mut self, y: usize, sums: &[(f64, [f64; 9])]) {
        let row = self.block_row(y / self.b);
        for (i, (t, m)) in sums.iter().enumerate() {
            row.carried[i] += t;
            for (acc, v) in row.moments[i].iter_mut().zip(m) {
                *acc += v;
            }
        }
    }

    /// Whether block row `j` can be fixed once the pixel rows below
    /// `rows_done` have their moments: the rows [`LOOKAHEAD`] below it are
    /// complete.
    pub fn can_fix(&self, j: usize, rows_done: usize) -> bool {
        let last = (j + LOOKAHEAD).min(self.nby - 1);
        rows_done >= ((last + 1) * self.b).min(self.h)
    }

    /// What block `i` of block row `j` must carry: `r = s + t (f - 1)`
    /// sums to the target where `Σ t f = target - Σ s + Σ t`.
    fn goal(&self, j: usize, i: usize) -> f64 {
        let k = j * self.nbx + i;
        self.target[k] - self.shape[k] + self.rows[j - self.first].carried[i]
    }

    /// Fix block row `j`'s coefficients (the row above fixed, the rows
    /// [`LOOKAHEAD`] below with their moments): each block's own ratio
    /// first, then [`FIELD_ITERATIONS`] multiplicative Jacobi steps over
    /// the rows `j` to `j + LOOKAHEAD`, the row above as fixed and the row
    /// after the last taken as the last. A block whose denoiser shape is
    /// empty keeps a coefficient of zero (its energy stays in place).
    pub fn fix(&mut self, j: usize) {
        let k0 = j - self.first;
        if self.rows[k0].rho.is_some() {
            return;
        }
        let nbx = self.nbx;
        let last = (j + LOOKAHEAD).min(self.nby - 1);
        let own = |jj: usize| -> Vec<f64> {
            let r = &self.rows[jj - self.first];
            (0..nbx)
                .map(|i| {
                    let s: f64 = r.moments[i].iter().sum();
                    let g = self.goal(jj, i);
                    if s > 0.0 && g > 0.0 {
                        g / s
                    } else {
                        0.0
                    }
                })
                .collect()
        };
        let mut free: Vec<Vec<f64>> = (j..=last).map(own).collect();
        let above = (k0 > 0).then(|| self.rows[k0 - 1].rho.clone()).flatten();
        let mut next = free.clone();
        for _ in 0..FIELD_ITERATIONS {
            for (f, row) in next.iter_mut().enumerate() {
                let m = &self.rows[k0 + f].moments;
                let rho_of = |dj: usize| -> Option<&Vec<f64>> {
                    match (f + dj).checked_sub(1) {
                        None => above.as_ref(),
                        Some(g) => free.get(g.min(free.len() - 1)),
                    }
                };
                for (i, v) in row.iter_mut().enumerate() {
                    let mut reached = 0.0;
                    for dj in 0..3 {
                        let Some(r) = rho_of(dj) else { continue };
                        for di in 0..3 {
                            let ii = (i + di).wrapping_sub(1);
                            let mk = m[i][dj * 3 + di];
                            if mk != 0.0 && ii < nbx {
                                reached += r[ii] * mk;
                            }
                        }
                    }
                    let cur = free[f][i];
                    *v = if reached > 0.0 && cur > 0.0 {
                        cur * self.goal(j + f, i) / reached
                    } else {
                        cur
                    };
                }
            }
            std::mem::swap(&mut free, &mut next);
        }
        self.rows[k0].rho = free.into_iter().next();
    }

    /// The target of block `i` of block row `j`.
    pub fn target(&self, j: usize, i: usize) -> f64 {
        self.target[j * self.nbx + i]
    }

    /// The field along pixel row `y` (its block rows fixed), `w` wide.
    pub fn row(&self, y: usize, out: &mut [f64]) {
        let (j0, j1, wy0, wy1) = tent(y, self.h, self.b);
        let fixed = |j: usize| self.rows[j - self.first].rho.as_deref().unwrap_or(&[]);
        let (r0, r1) = (fixed(j0), fixed(j1));
        for (o, &(i0, i1, wx0, wx1)) in out.iter_mut().zip(&self.tents_x) {
            *o = wy0 * (wx0 * r0[i0] + wx1 * r0[i1]) + wy1 * (wx0 * r1[i0] + wx1 * r1[i1]);
        }
    }

    /// Block rows below `j` are no longer read.
    pub fn release(&mut self, j: usize) {
        while self.first < j && !self.rows.is_empty() {
            self.rows.pop_front();
            self.first += 1;
        }
    }

    /// Rows of blocks being solved now (bounded by the lookahead).
    pub fn held(&self) -> usize {
        self.rows.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sums of a few dozen f64 terms agree to a few units in the last place.
    const SUM_TOL: f64 = 1e-12;
    /// A block's sum after the field's solve, before the exact factor:
    /// within half a percent of its target (the factor does the rest).
    const SOLVE_TOL: f64 = 5e-3;

    /// The tents are a partition of unity, each pixel between the centres
    /// of its own block and a neighbour.
    #[test]
    fn tents_sum_to_one_and_stay_beside_the_block() {
        for (n, b) in [(100, 32), (7, 2), (64, 64), (5, 8)] {
            for p in 0..n {
                let (i0, i1, w0, w1) = tent(p, n, b);
                assert!((w0 + w1 - 1.0).abs() < SUM_TOL && w0 >= 0.0 && w1 >= 0.0);
                assert!(i0 + 1 >= p / b && i1 <= p / b + 1 && i1 < n.div_ceil(b));
            }
        }
    }

    /// Block sums of `f` over a `w x h` image in blocks of `b`.
    fn block_sums(w: usize, h: usize, b: usize, f: impl Fn(usize, usize) -> f64) -> Vec<f64> {
        let nbx = w.div_ceil(b);
        let mut out = vec![0.0; nbx * h.div_ceil(b)];
        for y in 0..h {
            for x in 0..w {
                out[(y / b) * nbx + x / b] += f(x, y);
            }
        }
        out
    }

    /// On a smooth shape the fixed field reaches every block's target
    /// closely, and a flat image that was right stays (coefficients one).
    #[test]
    fn the_field_reaches_the_block_targets() {
        let (w, h, b) = (40, 70, 8);
        let shape = |x: usize, y: usize| 1.0 + 0.5 * ((x + 2 * y) as f64 * 0.15).sin();
        let energy = |x: usize, y: usize| shape(x, y) * (1.0 + 0.3 * (x as f64 / 40.0));
        let s_row = |y: usize| -> Vec<f64> { (0..w).map(|x| shape(x, y)).collect() };
        for (e, flat) in [
            (&energy as &dyn Fn(usize, usize) -> f64, false),
            (&shape, true),
        ] {
            let targets = block_sums(w, h, b, e);
            let mut f = FieldRows::new(w, h, b, targets.clone(), block_sums(w, h, b, shape));
            let mut fixed_to = 0;
            let mut got = vec![0.0; f.nbx * f.nby];
            let (mut fr, mut t) = (vec![0.0; w], vec![0.0; w]);
            let mut out_block = 0;
            for y in 0..h {
                let mut row = vec![(0.0, [0.0; 9]); f.nbx];
                f.carrier(y, &s_row(y), &mut t);
                f.moment_sums(y, &t, &mut row);
                f.add_moments(y, &row);
                // Finish every block row whose field is fixed.
                while out_block < f.nby && f.can_fix((out_block + 1).min(f.nby - 1), y + 1) {
                    while fixed_to <= (out_block + 1).min(f.nby - 1) {
                        f.fix(fixed_to);
                        fixed_to += 1;
                    }
                    for yy in out_block * b..((out_block + 1) * b).min(h) {
                        f.row(yy, &mut fr);
                        let s = s_row(yy);
                        f.carrier(yy, &s, &mut t);
                        for x in 0..w {
                            got[out_block * f.nbx + x / b] +=
                                (s[x] + t[x] * (fr[x] - 1.0)).max(0.0);
                        }
                    }
                    if flat {
                        let k = out_block - f.first;
                        for r in f.rows[k].rho.as_ref().unwrap() {
                            assert!((r - 1.0).abs() < 1e-9, "{r}");
                        }
                    }
                    f.release(out_block.saturating_sub(1));
                    out_block += 1;
                }
            }
            assert_eq!(out_block, f.nby);
            assert!(f.held() <= LOOKAHEAD + 4);
            for (k, g) in got.iter().enumerate() {
                let rel = (g / targets[k] - 1.0).abs();
                assert!(rel < SOLVE_TOL, "block {k}: {rel}");
            }
        }
    }

    /// The carrier is the shape where it is flat or the blocks need less
    /// energy, and weighs a pixel by its brightness against the block
    /// means around it where they need more.
    #[test]
    fn the_carrier_weighs_brightness_where_energy_is_missing() {
        let (w, h, b) = (16, 16, 8);
        let flat = vec![2.0; w];
        let mut peak = flat.clone();
        (peak[3], peak[4]) = (8.0, 0.0);
        for (energy, t3) in [(3.0, 8.0 * 8.0 / 2.0), (1.0, 8.0)] {
            let shapes = vec![2.0 * 64.0; 4];
            let f = FieldRows::new(w, h, b, vec![energy * 64.0; 4], shapes);
            let mut t = vec![0.0; w];
            f.carrier(5, &flat, &mut t);
            assert!(t.iter().all(|&v| (v - 2.0).abs() < SUM_TOL), "{t:?}");
            f.carrier(5, &peak, &mut t);
            assert!(
                (t[3] - t3).abs() < SUM_TOL && t[4] == 0.0,
                "{energy}: {t:?}"
            );
        }
    }
}
