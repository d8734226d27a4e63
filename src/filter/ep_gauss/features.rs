//! ep-gauss's feature rules, beyond the paper: which samples that fail
//! Relation 14 are parts of a real feature (a bulb, a lamp-shade rim, a
//! highlight) and keep the base kernel. Pure functions of a sample and the
//! neighbours passed in; the spread stage asks them per noisy sample.

use crate::filter::ep_box;

/// Rule 1b, beyond the paper: a noisy sample with noisy neighbours is a
/// feature. A firefly is one sample far above its surroundings; the samples
/// of a directly seen lamp, a bulb a fraction of a pixel wide, the rim of a
/// lamp shade or a glossy highlight come in groups, because the feature
/// covers several super-samples (partly covered ones carry a share of its
/// radiance). A sample that fails Relation 14 keeps the base kernel when at
/// least `min` of its 8 neighbouring super-samples fail the same test (are
/// above the same bound, on the same side) and are within a factor `ratio`
/// of it: comparable in brightness, as parts of one feature are, where
/// fireflies' heavy-tailed magnitudes rarely are. `min = 0` is the paper's
/// rule as written.
///
/// **Compact pairs** (`compact > 0`): a sample with fewer than `min` but at
/// least one such neighbour is kept too when the group is compact: at most
/// `compact` samples within [`SUPPORT_REACH`] of it (itself included) fail
/// the same test. A bulb a fraction of a pixel wide is two or three hot
/// samples with nothing like them around; two fireflies that happen to touch
/// lie among others like them (a caustic, a glossy floor, the halo of a
/// light), which the count sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Support {
    min: usize,
    ratio: f64,
    compact: usize,
    group: usize,
    over: f64,
    level: f64,
    region: usize,
}

/// Chebyshev reach, in super-samples, of the compact-pair count of
/// [`Support`]: the 5 x 5 samples about a sample.
pub const SUPPORT_REACH: usize = 2;

impl Support {
    /// At least `min` supporting neighbours within a factor `ratio`; with
    /// `compact > 0`, one is enough where at most `compact` samples within
    /// [`SUPPORT_REACH`] fail the test.
    pub fn new(min: usize, ratio: f64, compact: usize) -> Self {
        Support {
            min,
            ratio,
            compact,
            group: 0,
            over: 0.0,
            level: 0.0,
            region: 0,
        }
    }

    /// A bright sample at most `level` times its pixel's base average is
    /// kept too when at least `region` of the 24 samples within
    /// [`SUPPORT_REACH`] are above that average and above `1/level` of it:
    /// grain inside a bright feature (a glossy
    /// highlight at a few samples per pixel), not a firefly on a dark
    /// ground (`region = 0`: off).
    pub fn with_region(mut self, region: usize, level: f64) -> Self {
        self.region = region;
        self.level = level;
        self
    }

    /// A compact group is kept only when its sample is at least `over`
    /// times the background about it (the median box luminance of the eight
    /// pixels around its own, which the group's own pixels cannot move): a
    /// bulb is hundreds to thousands of times its room, two fireflies that
    /// touch rarely are.
    pub fn with_over(mut self, over: f64) -> Self {
        self.over = over;
        self
    }

    /// A sample with fewer than `min` supporting neighbours is kept too
    /// when its group holds at least `group` samples, itself included: the
    /// samples joined to it through supporting neighbours (8-connected, each
    /// failing the same test within `ratio` of it) within [`SUPPORT_REACH`].
    /// A thin line or a lamp-shade rim partly covering its samples is hit
    /// in runs, whose ends have one neighbour each; two fireflies that touch
    /// are a group of two (`group = 0`: off).
    pub fn with_group(mut self, group: usize) -> Self {
        self.group = group;
        self
    }

    /// Super-sample rows either side the rule reads.
    pub fn reach(&self) -> usize {
        if ((self.compact > 0 || self.group > 2) && self.min > 1) || self.region > 0 {
            SUPPORT_REACH
        } else {
            1
        }
    }

    /// Whether a noisy sample of luminance `x0` (above `hi` or below `lo`)
    /// is kept as a feature; `neighbour(di, dj)` gives the luminance of the
    /// sample at that offset (`|di|, |dj| <= reach()`), `None` outside the
    /// image.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn keeps(
        &self,
        x0: f64,
        xbar: f64,
        hi: f64,
        lo: f64,
        neighbour: impl Fn(i64, i64) -> Option<f64>,
        background: impl FnOnce() -> f64,
    ) -> bool {
        if self.min == 0 {
            return false;
        }
        let same = |v: f64| {
            if x0 > hi {
                v > hi && v * self.ratio >= x0
            } else {
                v > 0.0 && v < lo && v <= x0 * self.ratio
            }
        };
        let mut n = 0;
        for dj in -1..=1 {
            for di in -1..=1 {
                if di == 0 && dj == 0 {
                    continue;
                }
                let Some(v) = neighbour(di, dj) else { continue };
                n += usize::from(same(v));
                if n >= self.min {
                    return true;
                }
            }
        }
        if self.region > 0 && x0 > hi && x0 <= self.level * xbar {
            // Grain inside a bright feature: many samples within 2 of it
            // are comparable to it (within `level` of it and above the
            // pixel's average), where a firefly's are not.
            let floor = xbar.max(x0 / self.level);
            let r = SUPPORT_REACH as i64;
            let mut count = 0;
            for dj in -r..=r {
                for di in -r..=r {
                    if (di != 0 || dj != 0) && neighbour(di, dj).is_some_and(|v| v > floor) {
                        count += 1;
                        if count >= self.region {
                            return true;
                        }
                    }
                }
            }
        }
        if n == 0 || !(x0 > hi) {
            return false;
        }
        if self.group > n + 1 && self.group_of(x0, hi, &neighbour) >= self.group {
            return true;
        }
        if self.compact == 0 {
            return false;
        }
        if self.over > 0.0 && !(x0 >= self.over * background()) {
            return false;
        }
        // Fewer than `min` neighbours: a compact group only.
        let r = SUPPORT_REACH as i64;
        let mut count = 1; // itself
        for dj in -r..=r {
            for di in -r..=r {
                if di == 0 && dj == 0 {
                    continue;
                }
                if neighbour(di, dj).is_some_and(|v| v > hi && v * self.ratio >= x0) {
                    count += 1;
                    if count > self.compact {
                        return false;
                    }
                }
            }
        }
        true
    }
}

impl Support {
    /// The size of the group of a bright sample `x0` (above `hi`), up to
    /// `self.group`: a flood through supporting samples (above `hi`, within
    /// `ratio` of `x0`), 8-connected, within [`SUPPORT_REACH`] of it. No
    /// allocation: the 5 x 5 window is a bit mask.
    fn group_of(&self, x0: f64, hi: f64, neighbour: &impl Fn(i64, i64) -> Option<f64>) -> usize {
        const SIDE: i64 = 2 * SUPPORT_REACH as i64 + 1;
        let r = SUPPORT_REACH as i64;
        let bit = |di: i64, dj: i64| 1u32 << ((dj + r) * SIDE + di + r);
        let mut member = 0u32;
        for dj in -r..=r {
            for di in -r..=r {
                if (di, dj) != (0, 0)
                    && neighbour(di, dj).is_some_and(|v| v > hi && v * self.ratio >= x0)
                {
                    member |= bit(di, dj);
                }
            }
        }
        let mut seen = bit(0, 0);
        let mut stack = [(0i64, 0i64); (SIDE * SIDE) as usize];
        let mut top = 1;
        let mut count = 1;
        while top > 0 && count < self.group {
            top -= 1;
            let (ci, cj) = stack[top];
            for dj in -1..=1 {
                for di in -1..=1 {
                    let (ni, nj) = (ci + di, cj + dj);
                    if ni.abs() > r || nj.abs() > r {
                        continue;
                    }
                    let b = bit(ni, nj);
                    if member & b != 0 && seen & b == 0 {
                        seen |= b;
                        stack[top] = (ni, nj);
                        top += 1;
                        count += 1;
                    }
                }
            }
        }
        count
    }
}

/// Rule 1c, beyond the paper, at pixel resolution (S = 1) when the file
/// holds each pixel's variance and sample count: a pixel that fails
/// Relation 14 keeps the base kernel when its mean is carried by enough of
/// its samples ([`ep_box::carriers`], the rule and the settings of ep-box's
/// `carriers` guard), or by a few and it is a compact feature (at most
/// [`ep_box::COMPACT_MAX`] pixels within [`COMPACT_REACH`] fail Relation 14
/// at [`ep_box::COMPACT_RATIO`] of its luminance or more). At S = 1 a bulb
/// narrower than a pixel is one sample, which the support rule cannot tell
/// from a firefly; its variance can: a lamp covering a fifth of a pixel is
/// hit by a fifth of the pixel's samples, a firefly by one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Carriers {
    k_max: f64,
    fraction: f64,
    rse: f64,
}

/// Chebyshev radius of the compact-feature test of [`Carriers`], in pixels.
pub const COMPACT_REACH: usize = ep_box::CLUSTER_REACH;

impl Carriers {
    /// The carriers settings of ep-box (`--carriers`, `--carriers-fraction`,
    /// `--carriers-rse`).
    pub fn new(p: &ep_box::EpBoxParams) -> Self {
        Carriers {
            k_max: p.carriers,
            fraction: p.carriers_fraction,
            rse: p.carriers_rse,
        }
    }

    /// Whether a pixel of luminance `y` that failed Relation 14, whose mean
    /// of `n` samples has squared standard error `se2`, is kept as a
    /// feature; `hot_neighbours()` counts the pixels within
    /// [`COMPACT_REACH`] (itself included) that fail Relation 14 and are at
    /// least `y / COMPACT_RATIO`. Statistics that cannot be read (fewer than
    /// 2 samples, a non-finite variance) keep the paper's rule.
    #[inline]
    pub fn keeps(&self, y: f64, se2: f64, n: f64, hot_neighbours: impl FnOnce() -> usize) -> bool {
        if !(n.is_finite() && n >= 2.0 && se2.is_finite() && y.is_finite() && y > 0.0) {
            return false;
        }
        let k = ep_box::carriers(y, se2, n);
        k >= ep_box::carriers_needed(self.k_max, self.fraction, self.rse, n)
            || (k >= ep_box::COMPACT_CARRIERS && hot_neighbours() <= ep_box::COMPACT_MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_carriers_rule_at_its_edges() {
        let c = Carriers::new(
            &crate::filter::FilterParams::new(crate::filter::Method::EpBox, 1).ep_box,
        );
        let none = || 1usize;
        let many = || 9usize;
        // One sample of 16 carries the mean (a firefly): spread. Its sample
        // variance for a mean y is y^2 (n - 1) ... here from k = 1 exactly.
        // The squared standard error of a mean y of n samples, k of which
        // hold y n / k and the rest 0: var_pop = y^2 (n / k - 1).
        let se2 = |y: f64, k: f64, n: f64| y * y * (n / k - 1.0) / (n - 1.0);
        // One sample of 16 carries the mean (a firefly): spread.
        assert!(!c.keeps(100.0, se2(100.0, 1.0, 16.0), 16.0, none));
        // Zero variance: every sample agrees, carried.
        assert!(c.keeps(100.0, 0.0, 16.0, many));
        // 4 of 16 (k = 4 >= 3.37 needed): carried.
        assert!(c.keeps(100.0, se2(100.0, 4.0, 16.0), 16.0, many));
        // 3 of 16 is short of it: kept only when compact.
        assert!(c.keeps(100.0, se2(100.0, 3.0, 16.0), 16.0, none));
        assert!(!c.keeps(100.0, se2(100.0, 3.0, 16.0), 16.0, || {
            ep_box::COMPACT_MAX + 1
        }));
        // Statistics that cannot be read: the paper's rule.
        for (y, se2, n) in [
            (100.0, 0.0, 1.0),
            (100.0, f64::NAN, 16.0),
            (100.0, f64::INFINITY, 16.0),
            (100.0, 0.0, f64::NAN),
            (f64::INFINITY, 0.0, 16.0),
            (0.0, 0.0, 16.0),
        ] {
            assert!(!c.keeps(y, se2, n, none), "{y} {se2} {n}");
        }
        // 1e30 next to 1e-30: a finite decision either way.
        assert!(c.keeps(1e30, 0.0, 2.0, none));
        assert!(!c.keeps(1e30, se2(1e30, 1.0, 16.0), 16.0, none));
        assert!(c.keeps(1e-30, 1e-90, 64.0, none));
    }

    #[test]
    fn support_keeps_samples_with_comparable_noisy_neighbours() {
        let (hi, lo) = (10.0, f64::NEG_INFINITY);
        let rule = Support::new(1, 16.0, 0);
        let field = |hot: &'static [((i64, i64), f64)]| {
            move |di: i64, dj: i64| -> Option<f64> {
                Some(
                    hot.iter()
                        .find(|(o, _)| *o == (di, dj))
                        .map_or(1.0, |(_, v)| *v),
                )
            }
        };
        // Alone: a firefly.
        assert!(!rule.keeps(1000.0, 1.0, hi, lo, field(&[]), || 1.0));
        // A neighbour above the same bound and within 16x: a feature.
        assert!(rule.keeps(1000.0, 1.0, hi, lo, field(&[((1, 1), 300.0)]), || 1.0));
        // Above the bound but 100x dimmer: a faint firefly beside a bright one.
        assert!(!rule.keeps(1000.0, 1.0, hi, lo, field(&[((0, 1), 11.0)]), || 1.0));
        // Within 16x but below the bound: not noisy, no support.
        assert!(!rule.keeps(100.0, 1.0, 200.0, lo, field(&[((0, 1), 150.0)]), || 1.0));
        // Outside the image counts for nothing.
        assert!(!rule.keeps(1000.0, 1.0, hi, lo, |_, _| None, || 1.0));
        // Two needed.
        let two = Support::new(2, 16.0, 0);
        assert!(!two.keeps(1000.0, 1.0, hi, lo, field(&[((1, 0), 900.0)]), || 1.0));
        assert!(two.keeps(
            1000.0,
            1.0,
            hi,
            lo,
            field(&[((1, 0), 900.0), ((-1, 0), 800.0)]),
            || 1.0
        ));
        // 0: the paper's rule, never kept.
        assert!(!Support::new(0, 16.0, 0).keeps(
            1000.0,
            1.0,
            hi,
            lo,
            field(&[((1, 0), 900.0)]),
            || 1.0
        ));
        // The dark side: a sample far below its pixel's average, with a
        // neighbour as dark.
        assert!(rule.keeps(
            0.1,
            1.0,
            f64::INFINITY,
            0.5,
            field(&[((1, 0), 0.2)]),
            || 1.0
        ));
    }

    #[test]
    fn groups_compact_pairs_and_regions_keep_features_and_not_fireflies() {
        let (hi, lo) = (10.0, f64::NEG_INFINITY);
        let field = |hot: Vec<((i64, i64), f64)>| {
            move |di: i64, dj: i64| -> Option<f64> {
                Some(
                    hot.iter()
                        .find(|(o, _)| *o == (di, dj))
                        .map_or(1.0, |(_, v)| *v),
                )
            }
        };
        let run = |n: i64| -> Vec<((i64, i64), f64)> { (1..n).map(|k| ((k, k), 900.0)).collect() };
        // The end of a diagonal run: one neighbour, a group of the run's length.
        let group = Support::new(2, 16.0, 0).with_group(3);
        assert!(
            !group.keeps(1000.0, 1.0, hi, lo, field(run(2)), || 1.0),
            "a pair"
        );
        assert!(
            group.keeps(1000.0, 1.0, hi, lo, field(run(3)), || 1.0),
            "a run of 3"
        );
        let four = Support::new(2, 16.0, 0).with_group(4);
        assert!(!four.keeps(1000.0, 1.0, hi, lo, field(run(3)), || 1.0));
        // A run of 4 from its end reaches (3, 3): outside the 5 x 5.
        assert!(!four.keeps(1000.0, 1.0, hi, lo, field(run(4)), || 1.0));
        // A group joined through a bend counts; a sample 2 away with no
        // link does not.
        let bend = vec![((1, 0), 900.0), ((2, 1), 900.0), ((2, 2), 900.0)];
        assert!(four.keeps(1000.0, 1.0, hi, lo, field(bend), || 1.0));
        let apart = vec![((1, 0), 900.0), ((-2, -2), 900.0), ((2, -2), 900.0)];
        assert!(!four.keeps(1000.0, 1.0, hi, lo, field(apart), || 1.0));
        // Dimmer than 1/16 of it: not part of its group.
        let dim = vec![((1, 1), 900.0), ((2, 2), 50.0)];
        assert!(!group.keeps(1000.0, 1.0, hi, lo, field(dim), || 1.0));

        // A compact pair: kept when few like it are about and it is far
        // above the ring's background.
        let compact = Support::new(2, 16.0, 2).with_over(150.0);
        let pair = vec![((1, 0), 900.0)];
        assert!(compact.keeps(1000.0, 1.0, hi, lo, field(pair.clone()), || 1.0));
        assert!(!compact.keeps(1000.0, 1.0, hi, lo, field(pair.clone()), || 10.0));
        let crowded = vec![((1, 0), 900.0), ((-2, 2), 700.0)];
        assert!(!compact.keeps(1000.0, 1.0, hi, lo, field(crowded), || 1.0));

        // A region: grain inside a bright feature (the sample at most 4x its
        // pixel's average 20, samples about it above max(20, sample / 4)
        // though below the bound 50, so none supports it).
        let region = Support::new(2, 16.0, 0).with_region(8, 4.0);
        let grain = |n: usize| -> Vec<((i64, i64), f64)> {
            (-2i64..=2)
                .flat_map(|dj| (-2i64..=2).map(move |di| (di, dj)))
                .filter(|&o| o != (0, 0))
                .take(n)
                .map(|o| (o, 30.0))
                .collect()
        };
        assert!(region.keeps(60.0, 20.0, 50.0, lo, field(grain(8)), || 1.0));
        assert!(!region.keeps(60.0, 20.0, 50.0, lo, field(grain(7)), || 1.0));
        // The same sample 100x its average: a firefly, whatever surrounds it.
        assert!(!region.keeps(2000.0, 20.0, 50.0, lo, field(grain(24)), || 1.0));
    }
}
