//! A cheap lower bound of a wide width's average (`--bound-from`): Relation
//! 14 checked against it is conservative (a sample above its average fails
//! more easily when the average is lower), so a width that passes on the
//! bound passes on the exact average too, and the search stays as it is.
//!
//! The exact average reads every row of its disc: `2 * 2.25 rho + 1` rows,
//! and starting a row is what the search pays for (docs/DESIGN.md). The
//! bound reads a few dozen values: the Gaussian is replaced by a staircase
//! below it, `g(a_i) g(a_j)` on the cell `a_{i-1} < |dx| <= a_i`,
//! `a_{j-1} < |dy| <= a_j` of `m` steps per axis (0 where the cell's outer
//! corner is outside the disc), so every pixel's weight is at most its exact
//! one and the sum is a lower bound wherever the luminance is at least 0. A
//! staircase is a sum of centred rectangles (the mixed differences of the
//! cells' weights), and each rectangle's sum is four entries of a
//! **summed-area table** of the box luminance (six where it crosses a
//! block): the table is restarted every [`csum_block_for`] rows on a grid
//! fixed by the image, so that every strip, tile, thread and band computes
//! the same values. The steps are those that keep the most of the Gaussian
//! on a flat field, one axis at a time (a dynamic programme), as few as keep
//! [`BOUND_KEEP`] of the level's weight.
//!
//! Where the bound cannot be trusted the search reads the exact average:
//! rows outside the image (mirrored), a row of negative or non-finite
//! luminance among the rows read, or a sum whose rounding (bounded from the
//! values read, [`Bound::average`]) is not small against it.

use super::{disc_spans, LumRows};

/// The share of a width's weight (on a flat field) its bound keeps at
/// least; steps are added until it does (at most `MAX_STEPS` per axis).
/// At 0.7 a bound is at most 30% below the exact average where the
/// luminance is flat, so the width found is about two rungs (at
/// `--width-step 0.1`) wider at most, and a bound is 16-25 rectangles: the
/// search is faster than with exact averages, the spreads a little wider,
/// and the real renders' error no higher (their wide spreads gain from it).
pub const BOUND_KEEP: f64 = 0.7;

/// At most this many steps per axis (up to `MAX_STEPS^2` rectangles).
const MAX_STEPS: usize = 8;

/// The bound is used only while its rounding margin is at most this share
/// of it; beyond (a dark region beside a much brighter one in the same
/// block), the exact average is read.
const MAX_ROUNDING_SHARE: f64 = 1e-3;

/// Rows per block of the summed-area table for luminance rows padded by
/// `pad`: at least `2 pad + 2`, so the rows one bound reads (at most
/// `2 pad + 2`: its rectangles and the row above them) cross at most one
/// block boundary, and a multiple of 4 (band windows start on a block,
/// which keeps them on the 4x coarse grid too).
pub fn csum_block_for(pad: usize) -> usize {
    (2 * pad + 2).div_ceil(4) * 4
}

/// Rows of a summed-area table of the box luminance: row `y` (`0 <= y <
/// h`) holds at index `k + 1` the sum of the padded luminance columns
/// `0..=k` over the rows from the first of `y`'s block ([`csum_block_for`])
/// down to `y`, in f64; index 0 holds 0, and one entry more at the end the
/// count of rows of that range holding a value below 0 or not finite.
pub trait AreaSums: LumRows {
    /// Row `y` of the table (`0 <= y < height()`); `None` where it is not
    /// held.
    fn csum(&self, y: usize) -> Option<&[f64]>;
    /// Rows in the image.
    fn height(&self) -> usize;
    /// Rows per block of the table.
    fn block(&self) -> usize;
}

/// Fill `out` (the padded row's length plus two) with the table's row for
/// a luminance row `lum` (padded), given the row above's `prev` (`None` at
/// the first row of a block): what every implementor of [`AreaSums`]
/// computes, in this order ([`csum_prefix`], then [`csum_add`]).
pub fn csum_row(lum: &[f32], prev: Option<&[f64]>, out: &mut [f64]) {
    csum_prefix(lum, out);
    if let Some(p) = prev {
        csum_add(p, out);
    }
}

/// The first half of [`csum_row`]: the running sum along the row, and
/// whether the row holds a value below 0 or not finite (1 or 0, last).
pub fn csum_prefix(lum: &[f32], out: &mut [f64]) {
    let n = lum.len();
    let mut bad = false;
    let mut run = 0.0f64;
    out[0] = 0.0;
    for (o, &v) in out[1..=n].iter_mut().zip(lum) {
        bad |= !(v >= 0.0 && v.is_finite());
        run += v as f64;
        *o = run;
    }
    out[n + 1] = f64::from(u8::from(bad));
}

/// The second half of [`csum_row`] on any range of entries: add the row
/// above's (the same entries of `prev`).
pub fn csum_add(prev: &[f64], out: &mut [f64]) {
    for (o, &q) in out.iter_mut().zip(prev) {
        *o += q;
    }
}

/// One rectangle of a bound: `|dx| <= a`, `|dy| <= b`, weight `c`.
#[derive(Clone, Copy, Debug)]
struct Rect {
    a: usize,
    b: usize,
    c: f64,
}

/// The lower bound of one level's average: its rectangles (grouped by
/// height, outermost first), its norm, and what evaluating it costs (table
/// entries read).
#[derive(Clone, Debug)]
pub struct Bound {
    rects: Vec<Rect>,
    /// `(b, first, end)`: the rectangles of height `b` are `rects[first..end]`.
    groups: Vec<(usize, usize, usize)>,
    /// The outermost row either side.
    reach: usize,
    inv_norm: f64,
    /// Share of the level's weight the bound keeps on a flat field.
    pub keep: f64,
    /// Table entries read per evaluation (the search's cost units).
    pub cost: u64,
}

impl Bound {
    /// The bound of the level of radius `rho` whose average is over the disc
    /// of radius `r` (`norm`: its exact sum of weights).
    pub fn new(rho: f64, r: f64, norm: f64) -> Bound {
        let span = disc_spans(r);
        let n = span.len() - 1;
        let g = |d: usize| (-((d * d) as f64) / (rho * rho)).exp();
        let mut steps = Steps1d::new((0..=n).map(g).collect());
        let mut best = None;
        for m in 1..=MAX_STEPS.min(n + 1) {
            let ends = steps.ends(m);
            // Cell weights (0 where the outer corner is outside the disc) and
            // their mixed differences as rectangles.
            let k = ends.len();
            let w = |i: usize, j: usize| -> f64 {
                if i < k && j < k && span[ends[j]] >= ends[i] {
                    g(ends[i]) * g(ends[j])
                } else {
                    0.0
                }
            };
            let mut rects = Vec::new();
            let mut kept = 0.0;
            for j in (0..k).rev() {
                for i in 0..k {
                    let c = w(i, j) - w(i + 1, j) - w(i, j + 1) + w(i + 1, j + 1);
                    if c != 0.0 {
                        let (a, b) = (ends[i], ends[j]);
                        rects.push(Rect { a, b, c });
                        kept += c * ((2 * a + 1) * (2 * b + 1)) as f64;
                    }
                }
            }
            let keep = kept / norm;
            let done = keep >= BOUND_KEEP || m == MAX_STEPS.min(n + 1);
            best = Some((rects, keep));
            if done {
                break;
            }
        }
        let (rects, keep) = best.expect("at least one step");
        let mut groups: Vec<(usize, usize, usize)> = Vec::new();
        for (k, r) in rects.iter().enumerate() {
            match groups.last_mut() {
                Some(g) if g.0 == r.b => g.2 = k + 1,
                _ => groups.push((r.b, k, k + 1)),
            }
        }
        let reach = groups.first().map_or(0, |g| g.0);
        let cost = (4 * rects.len() + 3 * groups.len()) as u64;
        Bound {
            rects,
            groups,
            reach,
            inv_norm: 1.0 / norm,
            keep,
            cost,
        }
    }

    /// Rows either side of the pixel the bound reads (and one above those).
    pub fn reach(&self) -> usize {
        self.reach
    }

    /// The staircase's weight at offset `(dx, dy)` from the pixel, over the
    /// level's exact sum of weights: the bound is `sum weight * Ybox` over
    /// the offsets (what [`Bound::average`] computes from the table, up to
    /// rounding), each weight at most the exact average's.
    pub fn weight(&self, dx: i64, dy: i64) -> f64 {
        let (ax, ay) = (dx.unsigned_abs() as usize, dy.unsigned_abs() as usize);
        self.rects
            .iter()
            .filter(|r| ax <= r.a && ay <= r.b)
            .map(|r| r.c)
            .sum::<f64>()
            * self.inv_norm
    }

    /// The lower bound of the average about padded column `cx`, row `cy`;
    /// `None` where it cannot be trusted (rows outside the image or not
    /// held, a row with a value below 0 or not finite, rounding not small).
    #[inline]
    pub fn average(&self, sums: &impl AreaSums, cx: usize, cy: usize) -> Option<f64> {
        let (h, blk) = (sums.height(), sums.block());
        if cy < self.reach || cy + self.reach >= h {
            return None;
        }
        // The signed sum, and the sum of |c| times the entries it read (for
        // the rounding margin).
        let (mut acc, mut abs) = (0.0f64, 0.0f64);
        let mut last = 0;
        for (gi, &(b, r0, r1)) in self.groups.iter().enumerate() {
            // Rows a..=e: the table's row e, minus the row above a within
            // e's block, or (crossing into it from the block before) plus
            // that block's last row minus the row above a there.
            let (a, e) = (cy - b, cy + b);
            let start = e - e % blk;
            let p = sums.csum(e)?;
            let (p2, m) = if a >= start {
                (
                    None,
                    if a > start {
                        Some(sums.csum(a - 1)?)
                    } else {
                        None
                    },
                )
            } else {
                (
                    Some(sums.csum(start - 1)?),
                    if a > start - blk {
                        Some(sums.csum(a - 1)?)
                    } else {
                        None
                    },
                )
            };
            if gi == 0 {
                // The outermost rows hold every row read: none may be unusable.
                last = p.len() - 1;
                if p[last] + p2.map_or(0.0, |r| r[last]) - m.map_or(0.0, |r| r[last]) != 0.0 {
                    return None;
                }
            }
            let rects = &self.rects[r0..r1];
            let mut one = |row: &[f64], sign: f64| {
                for r in rects {
                    let (x1, x2) = (cx - r.a, cx + r.a + 1);
                    let (hi, lo) = (row[x2], row[x1]);
                    acc += sign * r.c * (hi - lo);
                    abs += r.c.abs() * (hi + lo);
                }
            };
            one(p, 1.0);
            if let Some(p2) = p2 {
                one(p2, 1.0);
            }
            if let Some(m) = m {
                one(m, -1.0);
            }
        }
        // Every table entry is a sum of non-negative values in a chain at
        // most a padded row plus a block long; each difference read and each
        // product added rounds once more: the result is within (that + the
        // terms + slack) u of sum |c| (entries).
        let chain = last + blk + 6 * self.rects.len() + 16;
        let margin = chain as f64 * f64::EPSILON * abs;
        let v = acc - margin;
        (v > 0.0 && v.is_finite() && margin <= MAX_ROUNDING_SHARE * v).then_some(v * self.inv_norm)
    }
}

/// The dynamic programme of the steps along one axis: for `k` steps, the
/// outer rows `b_1 < ... < b_k <= n` that keep the most of the 1-D weights
/// `g(0..=n)` (both sides) when each row of a step `(b_{j-1}, b_j]` weighs
/// `g(b_j)`, rows past the last one dropped. Each step more extends the
/// table of the ones before, so trying `m = 1, 2, ...` computes it once.
struct Steps1d {
    /// `g(0..=n)`.
    g: Vec<f64>,
    /// `best[k][a]`: the most `k` steps keep over rows `a..=n`, and where
    /// the first of them ends (`usize::MAX`: it uses fewer).
    best: Vec<Vec<(f64, usize)>>,
}

impl Steps1d {
    fn new(g: Vec<f64>) -> Self {
        let n = g.len() - 1;
        Steps1d {
            g,
            best: vec![vec![(0.0, usize::MAX); n + 2]],
        }
    }

    /// The best `m` (or fewer) steps' outer rows, innermost first.
    fn ends(&mut self, m: usize) -> Vec<usize> {
        let n = self.g.len() - 1;
        // Rows a..=b each side of 0 (0 counted once).
        let rows_in = |a: usize, b: usize| (2 * (b + 1 - a) - usize::from(a == 0)) as f64;
        while self.best.len() <= m {
            let prev = self.best.last().expect("the table of no step");
            let mut cur = vec![(0.0, usize::MAX); n + 2];
            for a in 0..=n {
                let mut top = (prev[a].0, usize::MAX);
                for b in a..=n {
                    let v = rows_in(a, b) * self.g[b] + prev[b + 1].0;
                    if v > top.0 {
                        top = (v, b);
                    }
                }
                cur[a] = top;
            }
            self.best.push(cur);
        }
        let mut ends = Vec::new();
        let mut a = 0;
        for k in (1..=m).rev() {
            if a > n {
                break;
            }
            let (_, b) = self.best[k][a];
            if b != usize::MAX {
                ends.push(b);
                a = b + 1;
            }
        }
        ends
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{direct_average, Field};
    use super::super::EpGauss;
    use super::*;

    #[test]
    fn steps_keep_what_they_promise_on_a_flat_field() {
        for rho in [1.0, 2.0, 3.3, 4.0, 6.0, 8.0, 11.0, 16.0, 40.0] {
            let r = 2.25 * rho;
            let span = disc_spans(r);
            let g = |d: f64| (-(d * d) / (rho * rho)).exp();
            let norm: f64 = span
                .iter()
                .enumerate()
                .map(|(dy, &sp)| {
                    let row: f64 = (-(sp as i64)..=sp as i64).map(|dx| g(dx as f64)).sum();
                    row * g(dy as f64) * if dy == 0 { 1.0 } else { 2.0 }
                })
                .sum();
            let b = Bound::new(rho, r, norm);
            assert!(b.rects.len() <= MAX_STEPS * MAX_STEPS);
            assert!(b.keep <= 1.0 + 1e-12, "rho {rho}: keeps {}", b.keep);
            assert!(
                b.keep >= BOUND_KEEP || b.rects.len() > (MAX_STEPS - 1) * (MAX_STEPS - 1),
                "rho {rho}: keeps {} with {} rectangles",
                b.keep,
                b.rects.len()
            );
            // The staircase, pixel by pixel: at most the exact weight, 0
            // outside the disc.
            for dy in 0..=span.len() {
                for dx in 0..=span.len() {
                    let w: f64 = b
                        .rects
                        .iter()
                        .filter(|q| dx <= q.a && dy <= q.b)
                        .map(|q| q.c)
                        .sum();
                    let exact = if dy < span.len() && dx <= span[dy] {
                        g(dx as f64) * g(dy as f64)
                    } else {
                        0.0
                    };
                    assert!(
                        w >= -1e-15 && w <= exact + 1e-15,
                        "rho {rho} ({dx},{dy}): {w} vs {exact}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_bound_is_below_the_exact_average_and_close_to_it() {
        // Rounding of two f64 summation orders, and the flat-field promise.
        const SUM_ORDER_TOL: f64 = 1e-12;
        let ep = EpGauss::new(3, 0.6, 16.0, 3.0, 0.08, 0.1).with_bound(2.0);
        let (w, h) = (140, 130);
        let hash = |x: usize, y: usize| {
            let mut z = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (y as u64 + 99);
            z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            (z ^ (z >> 29)) as f64 / u64::MAX as f64
        };
        // Fireflies of up to 1e5 over a ground of 0.5..1, and a black patch.
        let f = Field::new(w, h, ep.pad(), |x, y| {
            let u = hash(x, y);
            if (60..80).contains(&x) && (20..40).contains(&y) {
                0.0
            } else if u < 0.05 {
                10f64.powf(1.0 + 4.0 * u / 0.05)
            } else {
                0.5 + 0.5 * u
            }
        });
        let flat = Field::new(w, h, ep.pad(), |_, _| 2.0);
        let mut used = 0;
        for (l, lv) in ep.levels().iter().enumerate() {
            let Some(b) = &lv.bound else { continue };
            for &(px, py) in &[(70usize, 40usize), (5, 60), (139, 64), (70, 30), (20, 100)] {
                let cx = px + ep.pad();
                let exact = direct_average(&ep, &f, px, py, l);
                match b.average(&f, cx, py) {
                    Some(lo) => {
                        used += 1;
                        assert!(
                            lo <= exact * (1.0 + SUM_ORDER_TOL),
                            "level {l} ({px},{py}): {lo} > {exact}"
                        );
                    }
                    None => assert!(
                        py < b.reach() || py + b.reach() >= h || (px, py) == (70, 30),
                        "level {l} ({px},{py}) no bound"
                    ),
                }
                if let Some(lo) = b.average(&flat, cx, py) {
                    assert!(
                        (lo / 2.0 - b.keep).abs() < 1e-9,
                        "flat: {lo} vs keep {}",
                        b.keep
                    );
                }
            }
        }
        assert!(used > 20, "the bound answered {used} times");
    }

    #[test]
    fn negative_or_non_finite_rows_and_borders_fall_back() {
        let ep = EpGauss::new(3, 0.6, 8.0, 3.0, 0.08, 0.1).with_bound(2.0);
        let lv = ep
            .levels()
            .iter()
            .rev()
            .find(|l| l.bound.is_some())
            .unwrap();
        let b = lv.bound.as_ref().unwrap();
        let (w, h) = (80, 90);
        let cx = 40 + ep.pad();
        for bad in [-1e-30, f64::NAN, f64::INFINITY] {
            let f = Field::new(
                w,
                h,
                ep.pad(),
                |x, y| if (x, y) == (3, 50) { bad } else { 1.0 },
            );
            assert!(b.average(&f, cx, 50).is_none(), "{bad} in a row read");
            // A negative row out of reach does not matter; a non-finite one
            // poisons the table's sums for the rest of its block (the exact
            // average is read there).
            let below = 50 + b.reach() + 1;
            assert_eq!(b.average(&f, cx, below).is_some(), bad.is_finite(), "{bad}");
        }
        let f = Field::new(w, h, ep.pad(), |_, _| 1.0);
        assert!(b.average(&f, cx, b.reach() - 1).is_none());
        assert!(b.average(&f, cx, b.reach()).is_some());
        assert!(b.average(&f, cx, h - b.reach() - 1).is_some());
        assert!(b.average(&f, cx, h - b.reach()).is_none());
        // 1e30 above 1e-30 in one block: rounding would swamp the bound.
        let f = Field::new(w, h, ep.pad(), |_, y| if y < 20 { 1e30 } else { 1e-30 });
        let y = 20 + b.reach();
        assert!(y / f.block() == 20 / f.block());
        assert!(b.average(&f, cx, y).is_none());
    }

    #[test]
    fn the_table_restarts_on_the_image_grid() {
        // Every row's entries are the sums of the block's rows so far, in
        // the order every implementor takes them.
        let pad = 5;
        let blk = csum_block_for(pad);
        assert_eq!(blk % 4, 0);
        assert!(blk >= 2 * pad + 2);
        let wp = 30 + 2 * pad;
        let f = Field::new(30, 3 * blk + 7, pad, |x, y| (x * 31 + y * 17) as f64 % 13.0);
        for y in 0..f.height() {
            let t = f.csum(y).unwrap();
            assert_eq!(t.len(), wp + 2);
            assert_eq!(t[0], 0.0);
            for k in [0, 1, 7, wp - 1] {
                let mut want = 0.0;
                for r in y - y % blk..=y {
                    want += f.row(r as i64)[..=k].iter().map(|&v| v as f64).sum::<f64>();
                }
                assert!((t[k + 1] - want).abs() <= 1e-9 * want, "row {y} col {k}");
            }
        }
    }
}
