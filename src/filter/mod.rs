//! Filter kernels and the rules that choose them.
//!
//! * [`kernel`]: separable, normalized, border-reflected 1-D kernels (every
//!   sample's weights sum to one: energy is exact by construction).
//! * [`ep_gauss`]: §5.2 of the paper, Relation 14 and the width search.
//! * [`ep_box`]: §5.1, excess spreading for path-traced images with variance,
//!   the guards that keep real features, and the sample planning of Eqs. 8–10.
//! * [`foils`]: the energy-losing filters' rules (median, alpha-trim).
//! * [`channels`]: what the channels beside the beauty get (`--channel-rule`).
//!
//! Methods: `ep-gauss` (the paper's filter, default), `ep-box` (§5.1, pixel
//! resolution input with variance), `gauss` (the same base Gaussian for every
//! sample: the linear foil) and `box` (S x S average: the I/O floor).

pub mod channels;
pub mod ep_box;
pub mod ep_gauss;
pub mod foils;
pub mod guides;
pub mod kernel;
pub mod luminance;

use crate::error::{Error, Result};

/// Which filter to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// Energy-preserving variable-width Gaussian (§5.2).
    EpGauss,
    /// Energy-preserving excess spreading with a box (§5.1).
    EpBox,
    /// Fixed-width normalized Gaussian.
    Gauss,
    /// S x S box average.
    Box,
    /// Foil: clamp each sample to `--clamp` (renderers' "clamp"), then the
    /// base Gaussian. Loses energy.
    Clamp,
    /// Foil: per-channel median of the S x S samples (3 x 3 pixels at S = 1).
    /// Loses energy.
    Median,
    /// Foil: Lee & Redner's alpha-trimmed mean of the same samples, `--alpha`
    /// trimmed from each end. Loses energy.
    AlphaTrim,
}

impl Method {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::EpGauss => "ep-gauss",
            Method::EpBox => "ep-box",
            Method::Gauss => "gauss",
            Method::Box => "box",
            Method::Clamp => "clamp",
            Method::Median => "median",
            Method::AlphaTrim => "alpha-trim",
        }
    }

    /// Whether the method keeps the image's energy (the foils do not: their
    /// ledger reports the loss and the output is written anyway).
    pub fn preserves_energy(self) -> bool {
        !matches!(self, Method::Clamp | Method::Median | Method::AlphaTrim)
    }

    /// Every method, in the order of the docs.
    pub const ALL: [Method; 7] = [
        Method::EpGauss,
        Method::EpBox,
        Method::Gauss,
        Method::Box,
        Method::Clamp,
        Method::Median,
        Method::AlphaTrim,
    ];

    /// Parse a command-line name.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "ep-gauss" => Ok(Method::EpGauss),
            "ep-box" => Ok(Method::EpBox),
            "gauss" => Ok(Method::Gauss),
            "box" => Ok(Method::Box),
            "clamp" => Ok(Method::Clamp),
            "median" => Ok(Method::Median),
            "alpha-trim" => Ok(Method::AlphaTrim),
            _ => Err(Error::Config(format!(
                "unknown method {s:?} (choose ep-gauss, ep-box, gauss, box, clamp, median or alpha-trim)"
            ))),
        }
    }
}

/// The exponent of the power law through the paper's two tolerances (0.25 at
/// S = 3, 0.15 at S = 4, §5.2): a tolerance `t` at S = 3 is `t (3/S)^1.776`
/// at S, following the expected relative deviation of a pixel average
/// shrinking as S grows.
pub const TOLERANCE_EXPONENT: f64 = 1.775_693_214_568_475;

/// The paper's tolerance for S x S super-sampling: 0.25 at S = 3 and 0.15 at
/// S = 4 (§5.2). Between and beyond, the power law through those two points,
/// `0.25 * (3/S)^1.776` (S = 2: 0.51, S = 8: 0.044). The defaults of
/// ep-gauss are [`Quality::Default`]'s, which scale the same way.
pub fn default_tolerance(s: usize) -> f64 {
    scaled_tolerance(0.25, s)
}

/// A tolerance `t3` given at S = 3, at S (the paper's pair exactly at 3, 4).
pub fn scaled_tolerance(t3: f64, s: usize) -> f64 {
    match s {
        3 => t3,
        4 if t3 == 0.25 => 0.15,
        _ => t3 * (3.0 / s.max(1) as f64).powf(TOLERANCE_EXPONENT),
    }
}

/// A named point on ep-gauss's speed/accuracy front (`--quality`), chosen on
/// real renders (`scripts/eval-renders --sweep`, `docs/pareto.md`): each is a
/// set of knob values, which the other options override one by one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Quality {
    /// The fastest point that still removes most of the noise.
    Fast,
    /// The knee of the front: the defaults.
    Default,
    /// The least error, at a higher cost.
    Best,
}

impl Quality {
    /// Every preset, fastest first.
    pub const ALL: [Quality; 3] = [Quality::Fast, Quality::Default, Quality::Best];

    /// The name `--quality` takes.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Fast => "fast",
            Quality::Default => "default",
            Quality::Best => "best",
        }
    }

    /// Parse `--quality`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "fast" => Ok(Quality::Fast),
            "default" => Ok(Quality::Default),
            "best" => Ok(Quality::Best),
            other => Err(Error::Config(format!(
                "--quality {other:?}: fast, default or best"
            ))),
        }
    }

    /// The preset's knob values in words, as `--help` prints them.
    pub fn describe(self) -> String {
        let k = self.knobs();
        format!(
            "--tolerance {} (at S = 3) --support {} --support-ratio {} --support-group {} --support-compact {} --support-over {} --support-region {} --support-level {} --radius {} --cutoff {} --max-radius {} --width-step {} --bound-from {}",
            k.tolerance,
            k.support,
            k.support_ratio,
            k.support_group,
            k.support_compact,
            k.support_over,
            k.support_region,
            k.support_level,
            k.radius,
            k.cutoff,
            k.max_radius,
            k.width_step,
            k.bound_from
        )
    }

    /// The preset's knobs: tolerance (at S = 3; scaled with S), the
    /// feature rules', base radius, cut-off and the width ladder's.
    pub fn knobs(self) -> Knobs {
        match self {
            // The default with the cap at 8 px: the widest spreads, which
            // cost the most, go (docs/pareto.md: 1.25x gauss against the
            // default's 1.28x on 1e2..1e6 fireflies; it loses most on the
            // held-out caustics).
            Quality::Fast => Knobs {
                max_radius: 8.0,
                ..Quality::Default.knobs()
            },
            // The knee of the front on the real renders (docs/pareto.md):
            // the third round's joint sweep added the bound from 3 px and
            // the coarser ladder, which are faster and have less error on
            // the renders chosen on and the held-out ones alike.
            Quality::Default => Knobs {
                tolerance: 0.08,
                support: 2,
                support_ratio: 16.0,
                support_group: 0,
                support_compact: 2,
                support_over: 150.0,
                support_region: 8,
                support_level: 4.0,
                radius: 0.6,
                cutoff: 3.0,
                max_radius: 16.0,
                width_step: 0.2,
                bound_from: 3.0,
            },
            // The least error measured with every light kept: the cap at
            // 32 px (docs/pareto.md), twice the default's halo: more memory
            // on wide images.
            Quality::Best => Knobs {
                max_radius: 32.0,
                ..Quality::Default.knobs()
            },
        }
    }
}

/// The knob values of a [`Quality`] preset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Knobs {
    /// Relation 14 tolerance at S = 3.
    pub tolerance: f64,
    /// [`FilterParams::support`].
    pub support: usize,
    /// [`FilterParams::support_ratio`].
    pub support_ratio: f64,
    /// [`FilterParams::support_group`].
    pub support_group: usize,
    /// [`FilterParams::support_compact`].
    pub support_compact: usize,
    /// [`FilterParams::support_over`].
    pub support_over: f64,
    /// [`FilterParams::support_region`].
    pub support_region: usize,
    /// [`FilterParams::support_level`].
    pub support_level: f64,
    /// [`FilterParams::radius`].
    pub radius: f64,
    /// [`FilterParams::cutoff`].
    pub cutoff: f64,
    /// [`FilterParams::max_radius`].
    pub max_radius: f64,
    /// [`FilterParams::width_step`].
    pub width_step: f64,
    /// [`FilterParams::bound_from`].
    pub bound_from: f64,
}

/// The halo of a job from its settings alone (no kernels built): what the
/// stage will need, for sizing memory before anything is allocated. Equal to
/// the stage's own halo (tested beside each stage).
pub fn halo(p: &FilterParams) -> crate::geometry::Halo {
    let reach = |rho: f64| (p.cutoff * rho + 0.5).floor().max(0.0) as usize;
    let shell = |rho: f64| (ep_gauss::avg_cutoff(p.cutoff) * rho).floor().max(0.0) as usize;
    let max_rho = p.max_radius.max(p.radius);
    match p.method {
        Method::Box => crate::geometry::Halo::default(),
        Method::Gauss | Method::Clamp => crate::geometry::Halo {
            base_reach: reach(p.radius),
            ..Default::default()
        },
        Method::Median | Method::AlphaTrim => crate::geometry::Halo {
            base_reach: usize::from(p.supersample == 1),
            ..Default::default()
        },
        Method::EpGauss if p.supersample == 1 => {
            let spread = ep_gauss::pixel::reach_of(p.max_radius, p.cutoff);
            crate::geometry::Halo {
                search_reach: (2 * ep_gauss::pixel::BACKGROUND_REACH).max(spread),
                spread_reach: spread,
                ..Default::default()
            }
        }
        Method::EpGauss => crate::geometry::Halo {
            xbar_reach: shell(p.radius)
                + if p.supersample == 1 {
                    ep_gauss::COMPACT_REACH
                } else {
                    0
                },
            base_reach: reach(p.radius),
            search_reach: shell(max_rho),
            spread_reach: reach(max_rho),
        },
        Method::EpBox => {
            let spread = p.max_radius.max(0.0).floor() as usize;
            crate::geometry::Halo {
                search_reach: (p.ep_box.passes + ep_box::GUARD_REACH + ep_box::CLUSTER_REACH)
                    .max(spread),
                spread_reach: spread,
                ..Default::default()
            }
        }
    }
}

/// Rows a band's window must start on a multiple of (output rows), so
/// that what the stage computes on a grid fixed by the image is the whole
/// image's there: the 4x coarse grid (`--coarse-from`), and the blocks of
/// the summed-area table the bound reads (`--bound-from`).
pub fn window_align(p: &FilterParams) -> usize {
    if uses_bound(p) {
        ep_gauss::csum_block_for(halo(p).search_reach)
    } else {
        4
    }
}

/// Whether a job checks some widths against the bound of
/// [`ep_gauss::Bound`] (`--bound-from` at or below the cap), and so holds
/// the summed-area table it reads.
pub fn uses_bound(p: &FilterParams) -> bool {
    p.method == Method::EpGauss
        && p.bound_from > 0.0
        && p.max_radius > p.radius
        && p.max_radius >= p.bound_from
}

/// Default `--coarse-from`: widths from 2 output pixels are spread on the
/// coarser grid (`docs/tradeoff.md` measures the switch; from 2 rather than 4
/// px: fewer spread taps, no factor on `../shared/renders` higher, more
/// pixels untouched).
pub const DEFAULT_COARSE_FROM: f64 = 2.0;

/// Filter settings as asked for; [`FilterParams::validated`] checks them
/// once into [`ValidParams`], which is what the pipeline takes.
#[derive(Clone, Debug, PartialEq)]
pub struct FilterParams {
    /// Method.
    pub method: Method,
    /// Super-sampling factor S, 1..=8.
    pub supersample: usize,
    /// Base Gaussian radius in output pixels (`exp(-(d/r)^2)`).
    pub radius: f64,
    /// Cut-off of every Gaussian, in multiples of its radius.
    pub cutoff: f64,
    /// Relation 14 tolerance.
    pub tolerance: f64,
    /// Largest Gaussian radius a noisy sample may get, in output pixels.
    pub max_radius: f64,
    /// Relative spacing of the ladder of widths the search chooses from.
    pub width_step: f64,
    /// Settings of `ep-box` (§5.1); `max_radius` is its spread radius.
    pub ep_box: ep_box::EpBoxParams,
    /// `clamp`: the largest sample value kept (per channel).
    pub clamp: f64,
    /// `alpha-trim`: the fraction trimmed from each end, in 0..0.5.
    pub alpha: f64,
    /// ep-gauss: a noisy sample with at least this many noisy neighbours is
    /// kept as a feature ([`ep_gauss::Support`]; 0: the paper's rule).
    pub support: usize,
    /// ep-gauss: neighbours support a sample when within this factor of it.
    pub support_ratio: f64,
    /// ep-gauss: a sample with fewer than `support` supporting neighbours is
    /// kept when its group (joined through supporting neighbours within 2
    /// samples) holds at least this many ([`ep_gauss::Support`]; 0: off).
    pub support_group: usize,
    /// ep-gauss: a sample with one supporting neighbour (fewer than
    /// `support`) is kept when at most this many samples around it fail the
    /// test: a compact pair ([`ep_gauss::Support`]; 0: off).
    pub support_compact: usize,
    /// ep-gauss: a compact pair is kept only when its sample is at least this
    /// many times the median box luminance of the eight pixels about its own
    /// (0: any).
    pub support_over: f64,
    /// ep-gauss: a bright sample at most `support_level` times its pixel's
    /// base average is kept when at least this many of the 24 samples within
    /// 2 are above that average and above `1/support_level` of it (grain
    /// inside a bright feature; 0: off).
    pub support_region: usize,
    /// See `support_region`.
    pub support_level: f64,
    /// ep-gauss: widths of this radius (output pixels) and more are spread
    /// on the 2x coarser grid ([`kernel::Coarse`]); 0: none.
    pub coarse_from: f64,
    /// ep-gauss: widths of this radius (output pixels) and more are checked
    /// against a lower bound of their average read from a summed-area table
    /// ([`ep_gauss::Bound`]: conservative, a few rows instead of the disc's
    /// every row); 0: never.
    pub bound_from: f64,
    /// The preset the knobs came from (`--quality`); options given one by
    /// one override its values.
    pub quality: Quality,
}

/// `Ok` when `v` is finite and at least `lo`, else the error that says
/// `option` must be `what`.
fn at_least(option: &str, v: f64, lo: f64, what: &str) -> Result<()> {
    if v.is_finite() && v >= lo {
        Ok(())
    } else {
        Err(Error::Config(format!("{option} must be {what}, got {v}")))
    }
}

/// `Ok` when the count `n` is at most `hi`, else the error that says
/// `option` must be `0..=hi` `unit`.
fn at_most(option: &str, n: usize, hi: usize, unit: &str) -> Result<()> {
    if n <= hi {
        Ok(())
    } else {
        Err(Error::Config(format!(
            "{option} must be 0..={hi} {unit}, got {n}"
        )))
    }
}

impl FilterParams {
    /// The settings this method uses, in a fixed order: what a file and a
    /// report say about how they were made.
    pub fn settings(&self) -> Vec<(&'static str, serde_json::Value)> {
        use serde_json::json;
        let mut v = vec![
            ("method", json!(self.method.name())),
            ("supersample", json!(self.supersample)),
        ];
        match self.method {
            Method::EpGauss => v.extend([
                ("quality", json!(self.quality.name())),
                ("tolerance", json!(self.tolerance)),
                ("radius", json!(self.radius)),
                ("max_radius", json!(self.max_radius)),
                ("cutoff", json!(self.cutoff)),
                ("width_step", json!(self.width_step)),
                ("support", json!(self.support)),
                ("support_ratio", json!(self.support_ratio)),
                ("support_group", json!(self.support_group)),
                ("support_compact", json!(self.support_compact)),
                ("support_over", json!(self.support_over)),
                ("support_region", json!(self.support_region)),
                ("support_level", json!(self.support_level)),
                ("coarse_from", json!(self.coarse_from)),
                ("bound_from", json!(self.bound_from)),
            ]),
            Method::Gauss => v.extend([
                ("radius", json!(self.radius)),
                ("cutoff", json!(self.cutoff)),
            ]),
            Method::Clamp => v.extend([
                ("clamp", json!(self.clamp)),
                ("radius", json!(self.radius)),
                ("cutoff", json!(self.cutoff)),
            ]),
            Method::Median | Method::AlphaTrim => v.push(("alpha", json!(self.alpha))),
            Method::Box => {}
            Method::EpBox => {
                let e = &self.ep_box;
                v.extend([
                    ("d", json!(e.d)),
                    ("nmid", json!(e.nmid)),
                    ("ltvis", json!(e.ltvis)),
                    ("confidence", json!(e.confidence)),
                    ("passes", json!(e.passes)),
                    ("radius", json!(self.max_radius)),
                    ("guard", json!(e.guard.name())),
                    ("guard_confidence", json!(e.guard_confidence)),
                    ("carriers", json!(e.carriers)),
                    ("carriers_fraction", json!(e.carriers_fraction)),
                ])
            }
        }
        v
    }

    /// Whether this method, at this S, reads the setting of the command-line
    /// option `option` (its long name, `-` or `_` between words): an option
    /// it does not read is worth a warning, since the user expected it to
    /// change something.
    pub fn reads(&self, option: &str) -> bool {
        use Method::*;
        let m = self.method;
        let carriers = m == EpBox;
        let px = m == EpGauss && self.supersample == 1;
        match option.replace('-', "_").as_str() {
            "tolerance" | "width_step" | "quality" => m == EpGauss,
            "support" | "support_ratio" | "support_group" | "support_compact" | "support_over"
            | "support_region" | "support_level" | "coarse_from" | "bound_from" => {
                m == EpGauss && !px
            }
            "radius" | "cutoff" => matches!(m, EpGauss | Gauss | Clamp),
            "max_radius" => matches!(m, EpGauss | EpBox),
            "clamp" => m == Clamp,
            "alpha" => m == AlphaTrim,
            "guard" => matches!(m, EpBox | EpGauss),
            "d" | "nmid" | "confidence" | "ltvis" | "passes" | "guard_confidence" => m == EpBox,
            "carriers" | "carriers_fraction" | "carriers_rse" | "variance_channel"
            | "variance_kind" | "spp" | "spp_channel" => carriers,
            _ => true,
        }
    }

    /// `self` with the knobs of preset `q` (tolerance scaled to this S).
    pub fn with_quality(mut self, q: Quality) -> Self {
        let k = q.knobs();
        self.quality = q;
        self.tolerance = if self.supersample == 1 {
            ep_gauss::pixel::TOLERANCE
        } else {
            scaled_tolerance(k.tolerance, self.supersample)
        };
        self.support = k.support;
        self.support_ratio = k.support_ratio;
        self.support_group = k.support_group;
        self.support_compact = k.support_compact;
        self.support_over = k.support_over;
        self.support_region = k.support_region;
        self.support_level = k.support_level;
        self.radius = k.radius;
        self.cutoff = k.cutoff;
        self.max_radius = k.max_radius;
        self.width_step = k.width_step;
        self.bound_from = k.bound_from;
        self
    }

    /// The preset's knob values as `(option, value)`, tolerance at S = 3:
    /// what `--quality` sets, for reports and the sweep.
    pub fn quality_settings(&self) -> Vec<(&'static str, String)> {
        let k = self.quality.knobs();
        vec![
            ("tolerance", k.tolerance.to_string()),
            ("support", k.support.to_string()),
            ("support_ratio", k.support_ratio.to_string()),
            ("support_group", k.support_group.to_string()),
            ("support_compact", k.support_compact.to_string()),
            ("support_over", k.support_over.to_string()),
            ("support_region", k.support_region.to_string()),
            ("support_level", k.support_level.to_string()),
            ("radius", k.radius.to_string()),
            ("cutoff", k.cutoff.to_string()),
            ("max_radius", k.max_radius.to_string()),
            ("width_step", k.width_step.to_string()),
            ("bound_from", k.bound_from.to_string()),
        ]
    }

    /// Defaults for `method` at super-sampling `s` (radius 0.6 as Radiance's
    /// `pfilt -r`, cut-off 3 radii (the Gaussian has fallen to e^-9 = 1.2e-4),
    /// max radius 16, width step 10%).
    pub fn new(method: Method, s: usize) -> Self {
        FilterParams {
            method,
            supersample: s,
            radius: 0.6,
            cutoff: 3.0,
            tolerance: default_tolerance(s.max(1)),
            max_radius: if method == Method::EpBox {
                ep_box::DEFAULT_MAX_RADIUS
            } else {
                16.0
            },
            width_step: 0.1,
            ep_box: ep_box::EpBoxParams::default(),
            clamp: 10.0,
            alpha: 0.25,
            support: 1,
            support_ratio: 16.0,
            support_group: 0,
            support_compact: 0,
            support_over: 0.0,
            support_region: 0,
            support_level: 4.0,
            coarse_from: DEFAULT_COARSE_FROM,
            bound_from: 0.0,
            quality: Quality::Default,
        }
        .with_quality_if(method == Method::EpGauss)
    }

    /// ep-gauss's defaults are [`Quality::Default`]'s knobs; the base radius
    /// and cut-off of the other methods stay 0.6 and 3.
    fn with_quality_if(self, ep_gauss: bool) -> Self {
        if ep_gauss {
            self.with_quality(Quality::Default)
        } else {
            self
        }
    }

    /// Check every field once: the settings as a type that can no longer
    /// change.
    pub fn validated(&self) -> Result<ValidParams> {
        self.validate()?;
        Ok(ValidParams(self.clone()))
    }

    /// Check every field; a typed error names the first bad one.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Config(m));
        if !(1..=8).contains(&self.supersample) {
            return bad(format!(
                "--supersample must be 1..=8, got {}",
                self.supersample
            ));
        }
        if !(self.radius.is_finite() && self.radius >= 0.05 && self.radius <= 16.0) {
            return bad(format!(
                "--radius must be in 0.05..=16 output pixels, got {}",
                self.radius
            ));
        }
        if !(self.cutoff.is_finite() && (1.0..=6.0).contains(&self.cutoff)) {
            return bad(format!(
                "--cutoff must be in 1..=6 radii, got {}",
                self.cutoff
            ));
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return bad(format!(
                "--tolerance must be a finite number >= 0, got {}",
                self.tolerance
            ));
        }
        if !(self.max_radius.is_finite()
            && self.max_radius >= self.radius
            && self.max_radius <= 128.0)
        {
            return bad(format!(
                "--max-radius must be between --radius ({}) and 128 output pixels, got {}",
                self.radius, self.max_radius
            ));
        }
        at_least("--clamp", self.clamp, 0.0, "a finite number >= 0")?;
        at_most(
            "--support-group",
            self.support_group,
            25,
            "samples (the 5 x 5 about a sample)",
        )?;
        at_most("--support-compact", self.support_compact, 25, "samples")?;
        at_most("--support-region", self.support_region, 24, "samples")?;
        at_least("--support-over", self.support_over, 0.0, "a number >= 0")?;
        at_least("--support-level", self.support_level, 1.0, "a number >= 1")?;
        at_most("--support", self.support, 8, "neighbours")?;
        at_least("--support-ratio", self.support_ratio, 1.0, "a number >= 1")?;
        at_least(
            "--coarse-from",
            self.coarse_from,
            0.0,
            "a radius >= 0 output pixels (0: off)",
        )?;
        at_least(
            "--bound-from",
            self.bound_from,
            0.0,
            "a radius >= 0 output pixels (0: off)",
        )?;
        if !(0.0..0.5).contains(&self.alpha) {
            return bad(format!("--alpha must be in 0..0.5, got {}", self.alpha));
        }
        if self.method == Method::EpBox {
            if self.supersample != 1 {
                return bad(format!(
                    "ep-box filters pixel-resolution renders with variance: use --supersample 1, not {}",
                    self.supersample
                ));
            }
            if !(1.0..=128.0).contains(&self.max_radius) {
                return bad(format!(
                    "--max-radius must be in 1..=128 pixels for ep-box, got {}",
                    self.max_radius
                ));
            }
            self.ep_box.validate()?;
        }
        if !(self.width_step.is_finite() && (0.005..=1.0).contains(&self.width_step)) {
            return bad(format!(
                "--width-step must be in 0.005..=1, got {}",
                self.width_step
            ));
        }
        Ok(())
    }
}

/// Filter settings that passed [`FilterParams::validate`]: read-only (through
/// `Deref`), so nothing downstream can break what was checked.
#[derive(Clone, Debug, PartialEq)]
pub struct ValidParams(FilterParams);

impl std::ops::Deref for ValidParams {
    type Target = FilterParams;
    fn deref(&self) -> &FilterParams {
        &self.0
    }
}
