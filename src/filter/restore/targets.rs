//! Each block's energy target: the render's energy where it is sure, the
//! denoiser's where it is not, at every scale from the whole image down to
//! `--scale` blocks, children summing to their parent.
//!
//! Per block of one channel the render gives `R` (its energy, less what is
//! kept in place) with variance `V` (the render's uncertainty: its variance
//! pass, or its residual against the denoiser), and the denoiser gives `D`.
//! The render is an unbiased but noisy estimate of the block's energy, the
//! denoiser a steady but biased one. From the top:
//!
//! 1. The whole image's target is the render's total (the ledger's).
//! 2. Each block's children split their parent's target `T`. The denoiser's
//!    split, `D' = D T / Σ D` over the siblings, carries the denoiser's bias
//!    as measured at the parent, where the render is surer. The render's
//!    disagreement beyond its noise, `b² = (R - D')² - V'`, estimates the
//!    denoiser's remaining bias, where `V'` is the larger of the block's
//!    variance and its region's (the 3 x 3 blocks' variance per unit of
//!    energy: a block's own variance pass misses the rare bright paths its
//!    pixels did not catch). As a share of `D'²` it is averaged over the
//!    3 x 3 blocks around (a denoiser's bias is regional; one block's
//!    disagreement is mostly noise), then taken back to the block's scale.
//! 3. A child's estimate is `X = D' + k (R - D')`, `k = b² / (b² + V)`:
//!    the render's energy where it is sure (its relative standard error
//!    under [`SURE_RSE`]: `k = 1`), the denoiser's where it agrees with the
//!    render within its noise.
//! 4. The siblings' estimates are brought to their parent's target by
//!    moving each in proportion to its uncertainty `k V` and never past
//!    the render's or the denoiser's value (the box `[min, max]` of the
//!    two, which holds the parent's target since the `D'` sum to it): a
//!    block the render is sure of does not move.
//!
//! A block where the denoiser has no light keeps the render's energy: its
//! pixels have nothing to shape another target with (the stage then keeps
//! the render's values there). The sums are f64, in a fixed order: the
//! targets do not depend on threads or strips.

/// What a block's pixels hold, one channel: the render's energy (less what
/// is kept in place), the denoiser's, and the variance of the first.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BlockSums {
    /// `Σ (e - l)`: the render's energy that the field places.
    pub rest: f64,
    /// `Σ max(d, 0)`: the denoiser's.
    pub shape: f64,
    /// The variance of `rest`: the sum of its pixels' (independent) variances.
    pub var: f64,
}

impl std::ops::AddAssign for BlockSums {
    fn add_assign(&mut self, o: BlockSums) {
        self.rest += o.rest;
        self.shape += o.shape;
        self.var += o.var;
    }
}

/// How the targets of one level came out: for the report.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct LevelSummary {
    /// The block side at this level, in `--scale` blocks times the scale
    /// (pixels); the top level is the whole image.
    pub side: usize,
    /// Blocks (per channel, summed over channels).
    pub blocks: u64,
    /// Of them, those whose target lies nearer the render's energy than
    /// the denoiser's (`k >= 1/2`).
    pub following_render: u64,
    /// Those whose target is the render's energy exactly.
    pub exact: u64,
    /// How sure the render is at this level: the root mean square over its
    /// blocks of the relative standard error of their energy (`√V / R`;
    /// over channels where summed).
    pub render_rse: f64,
}

/// The root mean square of the blocks' relative standard errors.
fn render_rse(sums: &[BlockSums]) -> f64 {
    let (mut sum, mut n) = (0.0, 0.0);
    for s in sums.iter().filter(|s| s.rest != 0.0) {
        sum += s.var / (s.rest * s.rest);
        n += 1.0;
    }
    if n > 0.0 {
        (sum / n).sqrt()
    } else {
        0.0
    }
}

/// A block whose energy the render knows within this share (its relative
/// standard error) is sure: its target is the render's energy. A lighting
/// study reads a region's energy to a percent; the denoiser's regional
/// bias is a few percent (docs/bench/restore-truth.md).
pub const SURE_RSE: f64 = 0.01;

/// The ways the children's estimates are brought to their parent: at most
/// this many passes of moving the free ones and clamping those that reach
/// their box (each pass clamps one at least, and a parent has four).
const SPLIT_PASSES: usize = 5;

/// A grid of `nbx x nby` blocks (row-major) of one channel: the finest
/// the caller's, the ones above (a third more) the solve's own.
#[derive(Clone, Debug)]
struct Level<'a> {
    nbx: usize,
    nby: usize,
    sums: std::borrow::Cow<'a, [BlockSums]>,
}

impl Level<'_> {
    /// The 2 x 2 sums of `self`: the level above.
    fn parent(&self) -> Level<'static> {
        let (nbx, nby) = (self.nbx.div_ceil(2), self.nby.div_ceil(2));
        let mut sums = vec![BlockSums::default(); nbx * nby];
        for j in 0..self.nby {
            for i in 0..self.nbx {
                sums[(j / 2) * nbx + i / 2] += self.sums[j * self.nbx + i];
            }
        }
        Level {
            nbx,
            nby,
            sums: sums.into(),
        }
    }
}

/// The targets of one channel's `nbx x nby` blocks (row-major, `sums`),
/// and per level from the finest up, how they came out (`side`: the
/// finest blocks' side in pixels).
pub fn targets(
    sums: &[BlockSums],
    nbx: usize,
    nby: usize,
    side: usize,
) -> (Vec<f64>, Vec<LevelSummary>) {
    assert_eq!(sums.len(), nbx * nby, "one sum per block");
    let mut levels = vec![Level {
        nbx,
        nby,
        sums: sums.into(),
    }];
    while levels.last().is_some_and(|l| l.nbx > 1 || l.nby > 1) {
        let p = levels.last().map(Level::parent).expect("a level");
        levels.push(p);
    }
    let top = levels.last().expect("a level");
    let mut t: Vec<f64> = top.sums.iter().map(|s| s.rest).collect();
    let mut summary = vec![LevelSummary {
        side: side << (levels.len() - 1),
        blocks: 1,
        following_render: 1,
        exact: 1,
        render_rse: render_rse(&top.sums),
    }];
    for (depth, level) in levels.iter().enumerate().rev().skip(1) {
        let parent = &levels[depth + 1];
        let (next, s) = split(level, parent, &t);
        t = next;
        summary.push(LevelSummary {
            side: side << depth,
            render_rse: render_rse(&level.sums),
            ..s
        });
    }
    summary.reverse();
    (t, summary)
}

/// One child's estimate, its box and its weight in the split.
#[derive(Clone, Copy, Debug, Default)]
struct Child {
    /// The estimate, then the target.
    x: f64,
    lo: f64,
    hi: f64,
    /// `k V`: how far it may move.
    weight: f64,
    /// Whether it is still free to move.
    free: bool,
}

/// The children's targets of `level`, whose parents' targets (at `parent`)
/// are `tp`.
fn split(level: &Level<'_>, parent: &Level<'_>, tp: &[f64]) -> (Vec<f64>, LevelSummary) {
    let (nbx, nby) = (level.nbx, level.nby);
    let at = |i: usize, j: usize| (j / 2) * parent.nbx + i / 2;
    // What the children the denoiser left dark keep (the render's energy),
    // per parent: the others split the rest.
    let mut dark = vec![0.0f64; parent.sums.len()];
    for j in 0..nby {
        for i in 0..nbx {
            let c = &level.sums[j * nbx + i];
            if c.shape <= 0.0 {
                dark[at(i, j)] += c.rest;
            }
        }
    }
    // The denoiser's split of each parent's target.
    let dp: Vec<f64> = (0..nby)
        .flat_map(|j| (0..nbx).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (c, p) = (&level.sums[j * nbx + i], &parent.sums[at(i, j)]);
            let t = tp[at(i, j)] - dark[at(i, j)];
            if p.shape > 0.0 {
                c.shape * t / p.shape
            } else if p.rest != 0.0 {
                c.rest * t / p.rest
            } else {
                0.0
            }
        })
        .collect();
    // The render's variance per unit of energy, and its regional mean: a
    // block's own variance pass misses the rare bright paths its pixels
    // did not happen to catch, its neighbours' catch them.
    let per_energy: Vec<f64> = (level.sums.iter().zip(&dp))
        .map(|(c, &d)| if d > 0.0 { c.var / d } else { 0.0 })
        .collect();
    // The denoiser's squared bias beyond the render's noise (the larger of
    // its own variance and its region's), relative.
    let noise: Vec<f64> = (0..nby)
        .flat_map(|j| (0..nbx).map(move |i| (i, j)))
        .map(|(i, j)| {
            level.sums[j * nbx + i]
                .var
                .max(around(&per_energy, nbx, nby, i, j) * dp[j * nbx + i])
        })
        .collect();
    let rel: Vec<f64> = (level.sums.iter().zip(&dp).zip(&noise))
        .map(|((c, &d), &v)| {
            let dis = (c.rest - d).powi(2) - v;
            if dis > 0.0 && d > 0.0 {
                dis / (d * d)
            } else {
                0.0
            }
        })
        .collect();
    let mut kids: Vec<Child> = Vec::with_capacity(nbx * nby);
    let mut summary = LevelSummary::default();
    for j in 0..nby {
        for i in 0..nbx {
            let c = &level.sums[j * nbx + i];
            let d = dp[j * nbx + i];
            let b2 = around(&rel, nbx, nby, i, j) * d * d;
            let sure = c.var.sqrt() < SURE_RSE * c.rest.abs();
            let k = if c.var > 0.0 && !sure {
                b2 / (b2 + c.var)
            } else {
                1.0
            };
            // No light of the denoiser's: the render's energy stays.
            let fixed = c.shape <= 0.0;
            let (lo, hi) = if fixed {
                (c.rest, c.rest)
            } else {
                (c.rest.min(d), c.rest.max(d))
            };
            let x = if fixed { c.rest } else { d + k * (c.rest - d) };
            kids.push(Child {
                x: x.clamp(lo, hi),
                lo,
                hi,
                weight: if fixed { 0.0 } else { k * noise[j * nbx + i] },
                free: !fixed,
            });
            summary.blocks += 1;
            summary.following_render += u64::from(fixed || k >= 0.5);
        }
    }
    for pj in 0..parent.nby {
        for pi in 0..parent.nbx {
            let ids: Vec<usize> = (2 * pj..(2 * pj + 2).min(nby))
                .flat_map(|j| (2 * pi..(2 * pi + 2).min(nbx)).map(move |i| j * nbx + i))
                .collect();
            bring_to(&mut kids, &ids, tp[pj * parent.nbx + pi]);
        }
    }
    summary.exact = (kids.iter().zip(level.sums.iter()))
        .filter(|(k, s)| k.x == s.rest)
        .count() as u64;
    (kids.into_iter().map(|k| k.x).collect(), summary)
}

/// The mean of `rel` over the 3 x 3 blocks around `(i, j)` that exist.
fn around(rel: &[f64], nbx: usize, nby: usize, i: usize, j: usize) -> f64 {
    let (mut sum, mut n) = (0.0, 0.0);
    for jj in j.saturating_sub(1)..(j + 2).min(nby) {
        for ii in i.saturating_sub(1)..(i + 2).min(nbx) {
            sum += rel[jj * nbx + ii];
            n += 1.0;
        }
    }
    sum / n
}

/// Move the siblings `ids` so that their targets sum to `t`: each free one
/// in proportion to its weight, clamped to its box; what is left after
/// [`SPLIT_PASSES`] (rounding, or weights all zero) in proportion to the
/// room each has, and past the boxes only where none is left.
fn bring_to(kids: &mut [Child], ids: &[usize], t: f64) {
    let gap = |kids: &[Child]| t - ids.iter().map(|&c| kids[c].x).sum::<f64>();
    for _ in 0..SPLIT_PASSES {
        let delta = gap(kids);
        let total: f64 = ids
            .iter()
            .filter(|&&c| kids[c].free)
            .map(|&c| kids[c].weight)
            .sum();
        if delta == 0.0 || total <= 0.0 {
            break;
        }
        for &c in ids {
            let k = &mut kids[c];
            if !k.free {
                continue;
            }
            let x = k.x + delta * k.weight / total;
            if x >= k.hi || x <= k.lo {
                k.x = x.clamp(k.lo, k.hi);
                k.free = false;
            } else {
                k.x = x;
            }
        }
    }
    let delta = gap(kids);
    if delta == 0.0 {
        return;
    }
    let room = |k: &Child| if delta > 0.0 { k.hi - k.x } else { k.x - k.lo };
    let total: f64 = ids.iter().map(|&c| room(&kids[c])).sum();
    if total > 0.0 {
        for &c in ids {
            let r = room(&kids[c]);
            kids[c].x += delta * r / total;
        }
    } else {
        // No room in any box (a parent beyond its children's values, which
        // the boxes rule out but for rounding): in proportion to size.
        let size: f64 = ids.iter().map(|&c| kids[c].x.abs()).sum();
        for &c in ids {
            let share = if size > 0.0 {
                kids[c].x.abs() / size
            } else {
                1.0 / ids.len() as f64
            };
            kids[c].x += delta * share;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sums of a few hundred f64 terms agree to a few units in the last
    /// place of the largest.
    const SUM_TOL: f64 = 1e-12;

    fn grid(nbx: usize, nby: usize, f: impl Fn(usize, usize) -> BlockSums) -> Vec<BlockSums> {
        (0..nby)
            .flat_map(|j| (0..nbx).map(move |i| (i, j)))
            .map(|(i, j)| f(i, j))
            .collect()
    }

    /// Children sum to their parent at every level, and the whole to the
    /// render's total, on grids of any shape.
    #[test]
    fn children_sum_to_their_parent_at_every_scale() {
        for (nbx, nby) in [(1, 1), (7, 5), (8, 8), (3, 13), (16, 1)] {
            let sums = grid(nbx, nby, |i, j| BlockSums {
                rest: 10.0 + ((i * 7 + j * 3) % 5) as f64,
                shape: 9.0 + ((i + 2 * j) % 3) as f64,
                var: ((i * j) % 4) as f64,
            });
            let (t, levels) = targets(&sums, nbx, nby, 32);
            let total: f64 = sums.iter().map(|s| s.rest).sum();
            assert!((t.iter().sum::<f64>() - total).abs() <= SUM_TOL * total);
            // Every level: the sums of the finest targets over its blocks
            // lie in the boxes of the level above, and the top is exact.
            let top = levels.last().unwrap();
            assert_eq!((top.blocks, top.exact), (1, 1));
            assert_eq!(levels[0].side, 32);
            let mut level = Level {
                nbx,
                nby,
                sums: (t.iter().zip(&sums))
                    .map(|(&x, s)| BlockSums { rest: x, ..*s })
                    .collect::<Vec<_>>()
                    .into(),
            };
            while level.nbx > 1 || level.nby > 1 {
                level = level.parent();
            }
            assert!((level.sums[0].rest - total).abs() <= SUM_TOL * total);
        }
    }

    /// Where the render is sure (no variance) its energy is the target;
    /// where the two agree within the render's noise, the denoiser's.
    #[test]
    fn a_sure_render_is_kept_and_noise_follows_the_denoiser() {
        let (nbx, nby) = (4, 4);
        let sure = grid(nbx, nby, |i, j| BlockSums {
            rest: 100.0 + (i + j) as f64 * 10.0,
            shape: 100.0,
            var: 0.0,
        });
        let (t, levels) = targets(&sure, nbx, nby, 16);
        for (x, s) in t.iter().zip(&sure) {
            assert!((x - s.rest).abs() <= SUM_TOL * s.rest, "{x} {}", s.rest);
        }
        assert!(levels.iter().all(|l| l.exact == l.blocks));
        // Noise of 10 (variance 100) about a flat 100 the denoiser has.
        let noisy = grid(nbx, nby, |i, j| BlockSums {
            rest: 100.0 + if (i + j) % 2 == 0 { 8.0 } else { -8.0 },
            shape: 100.0,
            var: 100.0,
        });
        let (t, _) = targets(&noisy, nbx, nby, 16);
        for x in &t {
            assert!((x - 100.0).abs() < 2.0, "{x}");
        }
    }

    /// A denoiser that lost a third of one region's light (far beyond the
    /// render's noise) is overruled there, and stays elsewhere.
    #[test]
    fn a_biased_region_follows_the_render() {
        let (nbx, nby) = (8, 8);
        let lost = |i: usize, j: usize| i < 3 && j < 3;
        let sums = grid(nbx, nby, |i, j| BlockSums {
            rest: 100.0,
            shape: if lost(i, j) { 66.0 } else { 100.0 },
            var: 4.0,
        });
        let (t, _) = targets(&sums, nbx, nby, 32);
        for j in 0..nby {
            for i in 0..nbx {
                let x = t[j * nbx + i];
                assert!((x - 100.0).abs() < 5.0, "({i}, {j}): {x}");
            }
        }
    }

    /// A block the denoiser left dark keeps the render's energy, and its
    /// siblings take the rest of their parent's.
    #[test]
    fn a_block_without_the_denoisers_light_keeps_the_render() {
        let sums = grid(2, 2, |i, j| BlockSums {
            rest: 50.0,
            shape: if (i, j) == (0, 0) { 0.0 } else { 40.0 },
            var: 25.0,
        });
        let (t, _) = targets(&sums, 2, 2, 8);
        assert_eq!(t[0], 50.0);
        assert!((t.iter().sum::<f64>() - 200.0).abs() <= SUM_TOL * 200.0);
    }
}
