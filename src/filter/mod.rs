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
pub mod kernel;

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

/// The paper's tolerance for S x S super-sampling: 0.25 at S = 3 and 0.15 at
/// S = 4 (§5.2). Between and beyond, the power law through those two points,
/// `0.25 * (3/S)^1.776`, which follows the expected relative deviation of a
/// pixel average shrinking as S grows (S = 2: 0.51, S = 8: 0.044).
pub fn default_tolerance(s: usize) -> f64 {
    match s {
        3 => 0.25,
        4 => 0.15,
        _ => 0.25 * (3.0 / s as f64).powf((0.25f64 / 0.15).ln() / (4.0f64 / 3.0).ln()),
    }
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
        Method::EpBox => crate::geometry::Halo {
            search_reach: p.ep_box.passes + ep_box::GUARD_REACH + ep_box::CLUSTER_REACH,
            spread_reach: p.max_radius.max(0.0).floor() as usize,
            ..Default::default()
        },
    }
}

/// Default `--coarse-from`: widths from 2 output pixels are spread on the
/// coarser grid (`docs/tradeoff.md` measures the switch; from 2 rather than 4
/// px: 29% fewer spread taps, every factor on `../shared/renders` equal or
/// lower, more pixels untouched).
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
    /// ep-gauss: widths of this radius (output pixels) and more are spread
    /// on the 2x coarser grid ([`kernel::Coarse`]); 0: none.
    pub coarse_from: f64,
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
                ("tolerance", json!(self.tolerance)),
                ("radius", json!(self.radius)),
                ("max_radius", json!(self.max_radius)),
                ("cutoff", json!(self.cutoff)),
                ("width_step", json!(self.width_step)),
                ("support", json!(self.support)),
                ("support_ratio", json!(self.support_ratio)),
                ("coarse_from", json!(self.coarse_from)),
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
        // ep-gauss at S = 1 reads ep-box's statistics for its carriers rule.
        let carriers = m == EpBox || (m == EpGauss && self.supersample == 1);
        match option.replace('-', "_").as_str() {
            "tolerance" | "support" | "support_ratio" | "width_step" | "coarse_from" => {
                m == EpGauss
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
            coarse_from: DEFAULT_COARSE_FROM,
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
        if !(self.clamp.is_finite() && self.clamp >= 0.0) {
            return bad(format!(
                "--clamp must be a finite number >= 0, got {}",
                self.clamp
            ));
        }
        if self.support > 8 {
            return bad(format!(
                "--support must be 0..=8 neighbours, got {}",
                self.support
            ));
        }
        if !(self.support_ratio.is_finite() && self.support_ratio >= 1.0) {
            return bad(format!(
                "--support-ratio must be a number >= 1, got {}",
                self.support_ratio
            ));
        }
        if !(self.coarse_from.is_finite() && self.coarse_from >= 0.0) {
            return bad(format!(
                "--coarse-from must be a radius >= 0 output pixels (0: off), got {}",
                self.coarse_from
            ));
        }
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
