//! §5.1 of the paper: the excess-spreading box filter for path-traced images
//! that carry a per-pixel variance, and the sample planning of Eqs. 8–10.
//!
//! * **Visibility threshold** (Eq. 9): `L_tvis = L_ave / N_MID`.
//! * **Noise test** (Eqs. 5–6): a pixel is noisy when `t * S_p > D * L_tvis`,
//!   `S_p` the standard error of its mean and `t` the Student-t factor
//!   `t_{1-α/2, n-1}` for the confidence `α`.
//! * **Excess**: `L_excess = Y_u - mean(neighbours) - D * L_tvis`, the mean
//!   taken over the reference values of the 8-neighbours that count as
//!   converged in this pass. A positive excess leaves the pixel and
//!   is shared equally by the `ceil(L_excess / L_tvis)` in-image pixels
//!   nearest to it, in [`Ring`] order (the pixel itself first), each channel in
//!   proportion to the pixel's own values (its colour is kept).
//! * **Guards** against the rule's known failure, real bright features taken
//!   for noise ([`Guard`]).
//!
//! Passes: converged pixels are pass 0; a noisy pixel is treated in pass `k`
//! when its Chebyshev distance to the nearest converged pixel is `k` (it then
//! has a neighbour treated in pass `k - 1`). Its neighbour mean uses pass `< k`
//! neighbours only, each at its reference value: the original luminance of a
//! converged pixel, the kept luminance (`Y_u - L_excess`) of a treated one.
//! Spread energy never enters a mean. So the result depends only on the
//! input within `passes` pixels, not on any traversal order, and a pixel
//! further than `passes` from every converged pixel is left as it is
//! (counted as unresolved).

pub mod passes;

use statrs::distribution::{ContinuousCDF, StudentsT};

use crate::error::{Error, Result};

/// What keeps a real bright feature from being spread as noise.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Guard {
    /// The paper's rule as written (§5.1).
    None,
    /// Leave alone a noisy pixel whose luminance does not exceed the brightest
    /// converged pixel within [`GUARD_REACH`] pixels: it lies between a bright
    /// converged feature and its surroundings (a light source's edge, the rim
    /// of a highlight with a converged core), it is not an outlier above
    /// everything near it.
    Range,
    /// Spread at most `t_g * S_p` of the excess, with `t_g` the Student-t
    /// factor at the guard's confidence (99% by default, stricter than the
    /// noise test's 80%): the part that noise can explain; the rest is taken
    /// to be real. This is what stops a bright region whose pixels are all
    /// noisy (too few samples for its brightness) from being eaten from its
    /// edges inwards, one pass at a time.
    StdError,
    /// Both: `Range` first, then `StdError`.
    Both,
    /// A pixel is noise only when few samples carry its mean
    /// ([`carriers`] below [`EpBoxParams::carriers`]): a firefly is one or
    /// two samples far above the rest, while a lamp, a bulb a fraction of a
    /// pixel wide, a lamp-shade rim or a highlight is hit by many of the
    /// pixel's samples. The paper's absolute test (`t S_p > D L_tvis`) takes
    /// every bright pixel for noise; a pixel whose estimate rests on many
    /// samples is reliable, however bright.
    Carriers,
    /// `Carriers`, `Range` and `StdError` together.
    #[default]
    All,
}

impl Guard {
    /// Every name `--guard` takes.
    pub const NAMES: [&'static str; 6] = ["none", "range", "stderr", "both", "carriers", "all"];

    /// Name as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Guard::None => "none",
            Guard::Range => "range",
            Guard::StdError => "stderr",
            Guard::Both => "both",
            Guard::Carriers => "carriers",
            Guard::All => "all",
        }
    }

    /// Parse a command-line name.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "none" => Ok(Guard::None),
            "range" => Ok(Guard::Range),
            "stderr" => Ok(Guard::StdError),
            "both" => Ok(Guard::Both),
            "carriers" => Ok(Guard::Carriers),
            "all" => Ok(Guard::All),
            _ => Err(Error::Config(format!(
                "unknown --guard {s:?} (choose none, range, stderr, both (range + stderr), carriers or all)"
            ))),
        }
    }

    /// Whether the `range` guard is on.
    pub fn range(self) -> bool {
        matches!(self, Guard::Range | Guard::Both | Guard::All)
    }

    /// Whether the `stderr` guard is on.
    pub fn stderr(self) -> bool {
        matches!(self, Guard::StdError | Guard::Both | Guard::All)
    }

    /// Whether the `carriers` guard is on.
    pub fn carriers(self) -> bool {
        matches!(self, Guard::Carriers | Guard::All)
    }
}

/// A mean carried by fewer samples than this is never reliable, whatever the
/// fraction of the pixel's samples that is (one sample cannot tell a firefly
/// from a lamp that covers part of the pixel).
pub const CARRIERS_FLOOR: f64 = 2.0;

/// The number of carrier samples from which a mean of `n` samples is
/// reliable: `min(k_max, max(fraction n, n / (1 + (n - 1) rse^2), 2))`. The
/// middle term is the carrier count at which the relative standard error of
/// the mean falls to `rse` ([`carriers`]: `k = n / (1 + (n - 1) rse^2)`), so a
/// few hits among few samples are not enough.
#[inline]
pub fn carriers_needed(k_max: f64, fraction: f64, rse: f64, n: f64) -> f64 {
    let by_error = n / (1.0 + (n - 1.0) * rse * rse);
    k_max.min((fraction * n).max(by_error).max(CARRIERS_FLOOR))
}

/// The effective number of samples that carry a pixel's mean: `n Y^2 /
/// (var + Y^2)` with `var` the population variance of its `n` samples
/// (`S_p^2 (n - 1)` from the variance of the mean). Exactly `k` when `k` of
/// the `n` samples hold one value and the rest zero; `n` when every sample
/// holds the mean; about 1 for a pixel whose mean one firefly makes.
#[inline]
pub fn carriers(y: f64, se2: f64, n: f64) -> f64 {
    let var = se2.max(0.0) * (n - 1.0);
    let y2 = y * y;
    if y2 + var > 0.0 {
        n * y2 / (var + y2)
    } else {
        n
    }
}

/// Default spread radius of `ep-box`, in pixels (`docs/tradeoff.md`: the
/// error-time front of the trade study).
pub const DEFAULT_MAX_RADIUS: f64 = 8.0;

/// Chebyshev radius of the `range` guard's look at converged pixels.
pub const GUARD_REACH: usize = 2;

/// Chebyshev radius within which the `carriers` guard counts noisy pixels
/// to tell a compact feature from a stretch of noise.
pub const CLUSTER_REACH: usize = 2;

/// At most this many noisy pixels within [`CLUSTER_REACH`] (the pixel
/// itself included) make a compact feature: a bulb up to a pixel across hits
/// at most a 2 x 2 block.
pub const COMPACT_MAX: usize = 4;

/// A compact feature's pixel needs at least this many carriers: two hits in
/// one quiet pixel are still as likely a pair of fireflies as a lamp (at a
/// firefly rate that leaves the neighbours quiet, three are 25 times rarer).
pub const COMPACT_CARRIERS: f64 = 3.0;

/// Noisy pixels count towards a cluster when at least this fraction of the
/// pixel's luminance (1/16): parts of one feature, or of one stretch of
/// noise, are comparable; faint fireflies around a bulb are not.
pub const COMPACT_RATIO: f64 = 16.0;

/// Settings of the `ep-box` filter (and of `epfilt plan`); their defaults
/// and checks are in [`crate::filter::settings`] (`Default` is all zeros:
/// take `FilterParams::new(Method::EpBox, 1).ep_box` for the defaults).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EpBoxParams {
    /// `--d`: the allowed interval `±D`, in units of `L_tvis`.
    pub d: f64,
    /// `--nmid`: `N_MID` of Eq. 9.
    pub nmid: f64,
    /// `--confidence`: the noise test's `α`, in (0, 1).
    pub confidence: f64,
    /// `--ltvis`: `L_tvis` given, instead of `L_ave / N_MID`.
    pub ltvis: Option<f64>,
    /// `--passes`: the most passes over noisy clusters.
    pub passes: usize,
    /// `--guard`: what keeps real features from being spread.
    pub guard: Guard,
    /// `--guard-confidence`: the `stderr` guard's bound's.
    pub guard_confidence: f64,
    /// `--carriers`: see [`carriers`].
    pub carriers: f64,
    /// `--carriers-fraction`: see [`carriers_needed`].
    pub carriers_fraction: f64,
    /// `--carriers-rse`: see [`carriers_needed`].
    pub carriers_rse: f64,
}

/// `L_tvis = L_ave / N_MID` (Eq. 9).
pub fn ltvis(l_ave: f64, nmid: f64) -> f64 {
    l_ave / nmid
}

/// What a pixel's own statistics say, before its neighbours are looked at.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PixelTest {
    /// Noisy by the paper's test, `t S_p > D L_tvis` (Eqs. 5-6).
    pub noisy: bool,
    /// Its mean rests on enough samples to be reliable ([`carriers_needed`]).
    pub carried: bool,
    /// ... on enough for a compact feature ([`COMPACT_CARRIERS`]).
    pub few: bool,
}

impl PixelTest {
    /// The test of a pixel of luminance `y` whose mean of `n` samples has
    /// squared standard error `se2`: `t_n` is the noise test's Student-t
    /// factor for `n` samples, `dl = D L_tvis`.
    #[inline]
    pub fn new(y: f64, se2: f64, n: f64, t_n: f64, dl: f64, p: &EpBoxParams) -> Self {
        // NaN (fewer than 2 samples) is not noisy: it cannot be tested.
        if !(t_n * se2.sqrt() > dl) {
            return PixelTest::default();
        }
        let k = carriers(y, se2, n);
        PixelTest {
            noisy: true,
            carried: k >= carriers_needed(p.carriers, p.carriers_fraction, p.carriers_rse, n),
            few: k >= COMPACT_CARRIERS,
        }
    }

    /// The decision: noise, unless the carriers guard finds the pixel
    /// reliable (carried by enough samples, or a compact feature of a few:
    /// `compact` is whether [`cluster_count`] neighbours within
    /// [`CLUSTER_REACH`] are at most [`COMPACT_MAX`]).
    #[inline]
    pub fn is_noise(self, guard: Guard, compact: impl FnOnce() -> bool) -> bool {
        self.noisy && !(guard.carriers() && (self.carried || (self.few && compact())))
    }
}

/// The compact feature test's count: the pixels within [`CLUSTER_REACH`] of
/// `(x, y)` in a `w` x `h` image (itself included, clipped to the image)
/// whose luminance `lum` is at least `y0 / COMPACT_RATIO` and that `noisy`
/// calls noise. ep-box asks its flags, ep-gauss at S = 1 Relation 14 (so
/// `lum` is asked first: `noisy` may cost a base average). A compact feature
/// has at most [`COMPACT_MAX`].
pub fn cluster_count(
    (x, y): (usize, usize),
    (w, h): (usize, usize),
    y0: f64,
    lum: impl Fn(usize, usize) -> f64,
    noisy: impl Fn(usize, usize) -> bool,
) -> usize {
    let mut n = 0;
    for yy in y.saturating_sub(CLUSTER_REACH)..(y + CLUSTER_REACH + 1).min(h) {
        for xx in x.saturating_sub(CLUSTER_REACH)..(x + CLUSTER_REACH + 1).min(w) {
            n += usize::from(lum(xx, yy) >= y0 / COMPACT_RATIO && noisy(xx, yy));
        }
    }
    n
}

/// A noisy pixel's excess after the guards.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Excess {
    /// What leaves the pixel (0: nothing).
    pub value: f64,
    /// The `range` guard kept it.
    pub guarded: bool,
    /// The `stderr` guard cut it.
    pub trimmed: bool,
}

/// The excess of a noisy pixel of luminance `y` over the mean of its
/// converged neighbours (§5.1: `y - mean - D L_tvis`), after the guards:
/// `range` keeps a pixel no brighter than `brightest_converged` (the
/// brightest converged pixel within [`GUARD_REACH`], `-inf` for none),
/// `stderr` spreads at most `bound = t_g S_p`. An excess that would put less
/// than one visibility step `ltvis` on a second pixel is nothing.
#[inline]
pub fn excess(
    y: f64,
    mean: f64,
    dl: f64,
    ltvis: f64,
    guard: Guard,
    brightest_converged: impl FnOnce() -> f64,
    bound: f64,
) -> Excess {
    let mut e = Excess {
        value: y - mean - dl,
        guarded: false,
        trimmed: false,
    };
    if guard.range() && e.value > 0.0 && y <= brightest_converged() {
        e.value = 0.0;
        e.guarded = true;
    }
    if guard.stderr() && e.value > bound {
        e.value = bound;
        e.trimmed = true;
    }
    // Below one visibility step it would come back to the pixel itself.
    if !(e.value > 0.0 && y > 0.0 && (e.value / ltvis).ceil() >= 2.0) {
        e.value = 0.0;
    }
    e
}

/// How many pixels share an excess: `ceil(excess / L_tvis)` (each takes at
/// most one visibility step), at most the ring's `ring_len` offsets and the
/// pixel itself.
#[inline]
pub fn receivers(excess: f64, ltvis: f64, ring_len: usize) -> usize {
    (excess / ltvis).ceil().min(ring_len as f64 + 1.0) as usize
}

/// The share of each channel of a pixel of luminance `y` that leaves it with
/// an excess: the same for every channel, so the pixel keeps its colour.
#[inline]
pub fn colour_fraction(excess: f64, y: f64) -> f64 {
    excess / y
}

/// Student-t factors `t_{(1+α)/2, n-1}` by sample count, tabled once.
#[derive(Clone, Debug)]
pub struct TFactor {
    table: Vec<f64>,
    z: f64,
    p: f64,
}

/// Sample counts up to this are tabled from statrs; beyond, the
/// Cornish–Fisher expansion in `1/ν` (within 1e-7 of statrs there).
const T_TABLE: usize = 4096;

impl TFactor {
    /// Factors for two-sided confidence `confidence` (0.8 → the 0.9 quantile).
    pub fn new(confidence: f64) -> Self {
        let p = 0.5 + confidence / 2.0;
        let mut table = vec![f64::NAN; T_TABLE + 1];
        for (n, t) in table.iter_mut().enumerate().skip(2) {
            *t = student_t_quantile(p, (n - 1) as f64);
        }
        let z = statrs::distribution::Normal::standard().inverse_cdf(p);
        TFactor { table, z, p }
    }

    /// The factor for `n` samples (`n >= 2`; NaN below).
    #[inline]
    pub fn get(&self, n: f64) -> f64 {
        if !(n >= 2.0) {
            return f64::NAN;
        }
        let k = n.floor();
        if k <= T_TABLE as f64 {
            return self.table[k as usize];
        }
        let (z, v) = (self.z, k - 1.0);
        let z3 = z * z * z;
        let z5 = z3 * z * z;
        z + (z3 + z) / (4.0 * v) + (5.0 * z5 + 16.0 * z3 + 3.0 * z) / (96.0 * v * v)
    }

    /// The quantile this table holds (`(1 + α) / 2`).
    pub fn quantile(&self) -> f64 {
        self.p
    }
}

/// The `p` quantile of Student's t with `dof` degrees of freedom.
pub fn student_t_quantile(p: f64, dof: f64) -> f64 {
    match StudentsT::new(0.0, 1.0, dof) {
        Ok(t) => t.inverse_cdf(p),
        Err(_) => f64::NAN,
    }
}

/// Pixels nearest to a centre, in a fixed order: by squared distance, then
/// row offset, then column offset; all within a radius.
#[derive(Clone, Debug)]
pub struct Ring {
    offsets: Vec<(i32, i32)>,
    /// `reach_x[m]`: largest `|dx|` among the first `m + 1` offsets.
    reach_x: Vec<u32>,
    radius: usize,
}

impl Ring {
    /// Every offset within `radius` pixels (Euclidean) of the centre.
    pub fn new(radius: f64) -> Self {
        let r = radius.max(0.0).floor() as i32;
        let r2 = (radius * radius).floor() as i64;
        let mut offsets = Vec::new();
        for dy in -r..=r {
            for dx in -r..=r {
                if (dx as i64 * dx as i64 + dy as i64 * dy as i64) <= r2 {
                    offsets.push((dx, dy));
                }
            }
        }
        offsets.sort_by_key(|&(dx, dy)| (dx * dx + dy * dy, dy, dx));
        let mut reach_x = Vec::with_capacity(offsets.len());
        let mut m = 0u32;
        for &(dx, _) in &offsets {
            m = m.max(dx.unsigned_abs());
            reach_x.push(m);
        }
        Ring {
            offsets,
            reach_x,
            radius: r.max(0) as usize,
        }
    }

    /// The offsets `(dx, dy)` in order.
    pub fn offsets(&self) -> &[(i32, i32)] {
        &self.offsets
    }

    /// Largest `|dx|` of the first `m` offsets (`m >= 1`).
    pub fn reach_x(&self, m: usize) -> usize {
        self.reach_x[m.clamp(1, self.offsets.len()) - 1] as usize
    }

    /// Rows (and columns) the ring reaches either side.
    pub fn radius(&self) -> usize {
        self.radius
    }

    /// How many offsets a spread to `n` in-image pixels around `(x, y)` walks
    /// in a `w x h` image, and how many in-image pixels it finds (`< n` when
    /// the ring runs out: the spread is capped).
    pub fn prefix(&self, x: usize, y: usize, w: usize, h: usize, n: usize) -> (usize, usize) {
        let r = self.radius;
        if x >= r && y >= r && x + r < w && y + r < h {
            let m = n.min(self.offsets.len());
            return (m, m);
        }
        self.prefix_where(x, y, (w, h), n, |_, _| true)
    }

    /// [`Ring::prefix`] counting only the in-image pixels `(tx, ty)` that
    /// `ok` accepts (the surface guides' receivers).
    pub fn prefix_where(
        &self,
        x: usize,
        y: usize,
        (w, h): (usize, usize),
        n: usize,
        ok: impl Fn(usize, usize) -> bool,
    ) -> (usize, usize) {
        let mut found = 0;
        for (k, &(dx, dy)) in self.offsets.iter().enumerate() {
            let (tx, ty) = (x as i64 + dx as i64, y as i64 + dy as i64);
            if tx >= 0
                && ty >= 0
                && (tx as usize) < w
                && (ty as usize) < h
                && ok(tx as usize, ty as usize)
            {
                found += 1;
                if found == n {
                    return (k + 1, found);
                }
            }
        }
        (self.offsets.len(), found)
    }
}

/// The sample count, from the header, a channel or the command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Spp {
    /// The same count for every pixel.
    Fixed(f64),
    /// Per pixel, in this channel (index in the strip's channel list).
    Channel(usize),
}

/// What the variance channels hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum VarianceKind {
    /// The sample variance of single samples (`s^2`): `S_p^2 = s^2 / n`.
    Sample,
    /// The variance of the pixel mean (`S_p^2` itself; RenderMan's `mse`).
    OfMean,
    /// The raw second moment `E[Y^2]` of single samples (Mitsuba's `m2_*`):
    /// `s^2 = (E[Y^2] - E[Y]^2) n / (n - 1)`.
    SecondMoment,
}

impl VarianceKind {
    /// Name as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            VarianceKind::Sample => "sample",
            VarianceKind::OfMean => "mean",
            VarianceKind::SecondMoment => "moment",
        }
    }

    /// Parse a command-line name.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "sample" => Ok(VarianceKind::Sample),
            "mean" => Ok(VarianceKind::OfMean),
            "moment" => Ok(VarianceKind::SecondMoment),
            _ => Err(Error::Config(format!(
                "unknown --variance-kind {s:?} (choose sample, mean or moment)"
            ))),
        }
    }
}

/// Where the statistics of each pixel are in a strip's channel list.
#[derive(Clone, Debug, PartialEq)]
pub struct StatsLayout {
    /// One luminance variance channel, or one per colour channel (R, G, B).
    pub variance: Vec<usize>,
    /// What they hold.
    pub kind: VarianceKind,
    /// With `SecondMoment`: the channel of the mean luminance `E[Y]` that the
    /// moment goes with (`None`: the luminance of the colour channels).
    pub mean_y: Option<usize>,
    /// The sample count.
    pub spp: Spp,
}

/// Squared standard error of a pixel mean's luminance from its statistics.
///
/// With one variance per colour channel, the luminance's deviation is taken
/// as `sum w_c s_c` (fully correlated channels: a path that hits a light is
/// bright in every channel), an upper bound of the true value.
#[inline]
pub fn se2(kind: VarianceKind, var: &[f64], w: &[f64], mean_y: f64, n: f64) -> f64 {
    let v = if var.len() == 1 {
        var[0]
    } else {
        let sd: f64 = var
            .iter()
            .zip(w)
            .map(|(&v, &w)| w * v.max(0.0).sqrt())
            .sum();
        sd * sd
    };
    let v = v.max(0.0);
    match kind {
        VarianceKind::Sample => v / n,
        VarianceKind::OfMean => v,
        VarianceKind::SecondMoment => ((v - mean_y * mean_y).max(0.0) * n / (n - 1.0)) / n,
    }
}

impl StatsLayout {
    /// The sample count `n` and the squared standard error of the mean
    /// luminance of a pixel of luminance `y`, whose channel `c` holds
    /// `ch(c)`; `lum` weighs the colour channels (the first three, for three
    /// variance channels).
    #[inline]
    pub fn pixel(&self, lum: &[f64], y: f64, ch: impl Fn(usize) -> f64) -> (f64, f64) {
        let n = self.samples(&ch);
        let nv = self.variance.len().min(3);
        let mut var = [0.0f64; 3];
        for (v, &i) in var.iter_mut().zip(&self.variance) {
            *v = ch(i);
        }
        let mean_y = match (self.kind, self.mean_y) {
            (VarianceKind::SecondMoment, Some(i)) => ch(i),
            _ => y,
        };
        let weights = if nv == 3 { &lum[..3] } else { &lum[..1] };
        (n, se2(self.kind, &var[..nv], weights, mean_y, n))
    }

    /// A pixel's sample count, whose channel `c` holds `ch(c)`.
    pub fn samples(&self, ch: impl Fn(usize) -> f64) -> f64 {
        match self.spp {
            Spp::Fixed(n) => n,
            Spp::Channel(i) => ch(i),
        }
    }
}

/// Purgathofer's worst-case trial count (Eq. 8): `log(1 - α) / log(1 - d)`,
/// `d` the interval on samples scaled to 0..1; rounded up.
pub fn purgathofer_trials(confidence: f64, d: f64) -> f64 {
    ((1.0 - confidence).ln() / (1.0 - d).ln()).ceil()
}

/// Trials for `±D` (Eq. 10) from a pilot of `pilot_spp` samples per pixel
/// whose mean standard error is `mean_se`: the error shrinks as
/// `sqrt(pilot_spp / M)`, so `M_t = pilot_spp (S̄ / (D L_tvis))^2` — the
/// paper's `(4 S̄ / (D L_tvis))^2` at its 16-sample pilot.
pub fn trials_eq10(mean_se: f64, pilot_spp: f64, d: f64, ltvis: f64) -> f64 {
    let r = mean_se / (d * ltvis);
    pilot_spp * r * r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cluster_count_reads_the_5x5_clipped_and_asks_noise_only_above_the_ratio() {
        use std::cell::Cell;
        // A 6 x 5 image of luminance 1 with noisy pixels where x + y is even.
        let asked = Cell::new(0);
        let lum = |x: usize, y: usize| if (x, y) == (0, 0) { 0.01 } else { 1.0 };
        let noisy = |x: usize, y: usize| {
            asked.set(asked.get() + 1);
            (x + y) % 2 == 0
        };
        // At (2, 2): 25 pixels, 13 with x + y even, one of them (0, 0) too
        // dim to count.
        assert_eq!(cluster_count((2, 2), (6, 5), 1.0, lum, noisy), 12);
        // At the corner: the 3 x 3 inside the image, 5 even; (0, 0) is
        // below 1/16 of y0 = 1 and is not asked.
        asked.set(0);
        assert_eq!(cluster_count((0, 0), (6, 5), 1.0, lum, noisy), 4);
        assert_eq!(asked.get(), 8);
        // A brighter centre: nothing within 1/16 of it.
        assert_eq!(cluster_count((2, 2), (6, 5), 100.0, lum, noisy), 0);
    }

    #[test]
    fn purgathofer_matches_the_papers_worked_figures() {
        // §4.1: d = 1e-4 at 80% gives 16,094 trials; d = 0.05 gives 32.
        assert_eq!(purgathofer_trials(0.8, 1e-4), 16094.0);
        assert_eq!(purgathofer_trials(0.8, 0.05), 32.0);
        assert_eq!(purgathofer_trials(0.8, 13.0 / 255.0), 31.0);
    }

    #[test]
    fn eq10_is_the_papers_form_at_16_samples() {
        let (s, d, l) = (0.3f64, 5.0f64, 0.01f64);
        let paper = (4.0 * s / (d * l)).powi(2);
        assert!((trials_eq10(s, 16.0, d, l) - paper).abs() <= 1e-9 * paper);
    }

    #[test]
    fn student_t_factors() {
        let t = TFactor::new(0.8);
        // Tables: t_{0.9, 15} = 1.3406, t_{0.9, 63} = 1.2951, z_{0.9} = 1.2816.
        assert!((t.get(16.0) - 1.340_606).abs() < 1e-5);
        assert!((t.get(64.0) - 1.295_134).abs() < 1e-5);
        let far = t.get(1e6);
        assert!((far - 1.281_552).abs() < 1e-5, "{far}");
        // The expansion joins the table: within 1e-7, the accuracy of statrs's
        // numerical inversion (1.4e-8 apart at 4096 samples).
        let (a, b) = (t.get(T_TABLE as f64), t.get(T_TABLE as f64 + 1.0));
        let exact = student_t_quantile(0.9, T_TABLE as f64);
        assert!((b - exact).abs() < 1e-7, "{b} vs {exact}");
        assert!(a >= b);
        assert!(t.get(1.0).is_nan());
    }

    #[test]
    fn ring_order_is_by_distance_then_row_then_column() {
        let r = Ring::new(2.0);
        assert_eq!(r.offsets().len(), 13);
        assert_eq!(
            &r.offsets()[..5],
            &[(0, 0), (0, -1), (-1, 0), (1, 0), (0, 1)]
        );
        assert_eq!(r.reach_x(1), 0);
        assert_eq!(r.reach_x(13), 2);
        // A corner pixel: the ring's in-image offsets only.
        assert_eq!(r.prefix(0, 0, 10, 10, 3), (5, 3));
        assert_eq!(r.prefix(5, 5, 10, 10, 3), (3, 3));
        assert_eq!(r.prefix(0, 0, 2, 1, 5), (13, 2));
    }

    #[test]
    fn carriers_count_the_samples_that_hold_the_mean() {
        // k of n samples at one value and the rest at zero: exactly k
        // (unbiased sample variance s^2 = k (n - k) / (n (n - 1)) v^2).
        for n in [2.0f64, 4.0, 16.0, 64.0] {
            for k in 1..=n as usize {
                let (k, v) = (k as f64, 7.5);
                let y = k / n * v;
                let s2 = k * (n - k) / (n * (n - 1.0)) * v * v;
                let c = carriers(y, s2 / n, n);
                assert!((c - k).abs() < 1e-9 * n, "n {n} k {k}: {c}");
            }
        }
        // No variance: every sample carries it; no light: none does.
        assert_eq!(carriers(3.0, 0.0, 16.0), 16.0);
        assert_eq!(carriers(0.0, 0.0, 16.0), 16.0);
        assert_eq!(carriers(0.0, 1.0, 16.0), 0.0);
        // Extremes stay finite and in 0..=n.
        for (y, se2) in [
            (1e30, 1e60),
            (1e-30, 1e-60),
            (1e30, f64::INFINITY),
            (1e-30, 1e30),
        ] {
            let c = carriers(y, se2, 16.0);
            assert!(c.is_finite() && (0.0..=16.0).contains(&c), "{y} {se2}: {c}");
        }
    }

    #[test]
    fn carriers_needed_grow_with_the_samples_up_to_the_cap() {
        let need = |n: f64| carriers_needed(16.0, 0.2, 0.5, n);
        // Few samples: the relative-error term (never below 2).
        assert_eq!(need(1.0), 2.0);
        assert!((need(4.0) - 4.0 / 1.75).abs() < 1e-12);
        assert!((need(16.0) - 16.0 / 4.75).abs() < 1e-12);
        // Then the fraction, then the cap.
        assert!((need(64.0) - 12.8).abs() < 1e-12);
        assert_eq!(need(256.0), 16.0);
        assert_eq!(need(1e6), 16.0);
    }

    #[test]
    fn standard_error_of_each_kind() {
        let w = [0.2126, 0.7152, 0.0722];
        assert_eq!(se2(VarianceKind::Sample, &[4.0], &w, 0.0, 16.0), 0.25);
        assert_eq!(se2(VarianceKind::OfMean, &[0.25], &w, 0.0, 16.0), 0.25);
        // E[Y^2] = 5, E[Y] = 1: s^2 = 4 * 16/15.
        let m = se2(VarianceKind::SecondMoment, &[5.0], &w, 1.0, 16.0);
        assert!((m - 4.0 / 15.0).abs() < 1e-12);
        // Equal colour deviations: the luminance deviation is theirs.
        let c = se2(VarianceKind::Sample, &[4.0, 4.0, 4.0], &w, 0.0, 16.0);
        assert!((c - 0.25).abs() < 1e-12);
    }
}
