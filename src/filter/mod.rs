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
pub mod restore;
pub mod settings;

use crate::error::{Error, Result};

/// Which filter to run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Method {
    /// Energy-preserving variable-width Gaussian (§5.2).
    #[default]
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

    /// Whether the method spreads noisy samples (fireflies) rather than
    /// blurring or dropping them: its output holds no fireflies to keep out.
    pub fn spreads_noise(self) -> bool {
        matches!(self, Method::EpGauss | Method::EpBox)
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

    /// The command line's names, in [`Method::ALL`]'s order.
    pub const NAMES: [&'static str; 7] = [
        "ep-gauss",
        "ep-box",
        "gauss",
        "box",
        "clamp",
        "median",
        "alpha-trim",
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
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Quality {
    /// The fastest point that still removes most of the noise.
    Fast,
    /// The knee of the front: the defaults.
    #[default]
    Default,
    /// The least error, at a higher cost.
    Best,
}

impl Quality {
    /// Every preset, fastest first.
    pub const ALL: [Quality; 3] = [Quality::Fast, Quality::Default, Quality::Best];

    /// The names `--quality` takes, in [`Quality::ALL`]'s order.
    pub const NAMES: [&'static str; 3] = ["fast", "default", "best"];

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

    /// The preset's knob values in words, as `--help` prints them
    /// (tolerance at S = 3).
    pub fn describe(self) -> String {
        let p = FilterParams::new(Method::EpGauss, 3).with_quality(self);
        (settings::KNOBS.iter())
            .filter(|k| k.preset)
            .map(|k| format!("--{} {}", k.option(), k.show(&p)))
            .collect::<Vec<_>>()
            .join(" ")
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
        Method::EpGauss if p.supersample == 1 => {
            let spread = ep_gauss::pixel::reach_of(p.max_radius, p.cutoff);
            crate::geometry::Halo {
                search_reach: (2 * ep_gauss::pixel::BACKGROUND_REACH).max(spread),
                spread_reach: spread,
                ..Default::default()
            }
        }
        Method::EpGauss => crate::geometry::Halo {
            xbar_reach: shell(p.radius).max(ep_gauss::RING_REACH),
            base_reach: reach(p.radius),
            search_reach: shell(max_rho).max(ep_gauss::RING_REACH),
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

/// ep-gauss at S > 1: cells either side that its spread writes on the
/// output grid and on the 2x and 4x coarse ones
/// ([`ep_gauss::EpGauss::grid_reach`]; the ladder is built, as the stage
/// builds it); the spread's reach on the output grid for the others.
pub fn grid_reaches(p: &FilterParams) -> [usize; 3] {
    if p.method != Method::EpGauss || p.supersample <= 1 {
        return [halo(p).spread_reach, 0, 0];
    }
    let ep = ladder(p, p.supersample);
    [1, 2, 4].map(|f| ep.grid_reach(f))
}

/// ep-gauss's ladder of widths at S = `s` from its settings, with its
/// coarse grids (`--coarse-from`): what the stage spreads with and the
/// memory estimate counts.
pub fn ladder(p: &FilterParams, s: usize) -> ep_gauss::EpGauss {
    ep_gauss::EpGauss::new(
        s,
        p.radius,
        p.max_radius,
        p.cutoff,
        p.tolerance,
        p.width_step,
    )
    .with_coarse(p.coarse_from)
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

/// Filter settings as asked for; [`FilterParams::validated`] checks them
/// once into [`ValidParams`], which is what the pipeline takes. Each field
/// but the method and S is a setting of [`settings::KNOBS`], which gives its
/// help, default and check (`Default` is all zeros: [`FilterParams::new`]
/// gives the defaults).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FilterParams {
    /// Method.
    pub method: Method,
    /// Super-sampling factor S, 1..=8.
    pub supersample: usize,
    /// `--radius`: the base Gaussian's radius, output pixels.
    pub radius: f64,
    /// `--cutoff`: every Gaussian's cut-off, in radii.
    pub cutoff: f64,
    /// `--tolerance`: Relation 14's.
    pub tolerance: f64,
    /// `--max-radius`: the widest spread, output pixels.
    pub max_radius: f64,
    /// `--width-step`: the width ladder's relative step.
    pub width_step: f64,
    /// ep-box's settings (§5.1); `max_radius` is its spread radius.
    pub ep_box: ep_box::EpBoxParams,
    /// `--clamp`: the clamp foil's ceiling.
    pub clamp: f64,
    /// `--alpha`: alpha-trim's fraction trimmed from each end.
    pub alpha: f64,
    /// `--support`: ep-gauss's feature rule ([`ep_gauss::Support`]).
    pub support: usize,
    /// `--support-ratio`: see [`ep_gauss::Support`].
    pub support_ratio: f64,
    /// `--support-group`: see [`ep_gauss::Support`].
    pub support_group: usize,
    /// `--support-compact`: see [`ep_gauss::Support`].
    pub support_compact: usize,
    /// `--support-over`: see [`ep_gauss::Support`].
    pub support_over: f64,
    /// `--support-region`: see [`ep_gauss::Support`].
    pub support_region: usize,
    /// `--support-level`: see [`ep_gauss::Support`].
    pub support_level: f64,
    /// `--coarse-from`: spreads this wide go on a coarser grid ([`kernel::Coarse`]).
    pub coarse_from: f64,
    /// `--bound-from`: widths this wide are checked on [`ep_gauss::Bound`] first.
    pub bound_from: f64,
    /// `--quality`: the preset the knobs came from.
    pub quality: Quality,
}

impl FilterParams {
    /// The settings this method records, in the table's order: what a file
    /// and a report say about how they were made.
    pub fn settings(&self) -> Vec<(&'static str, serde_json::Value)> {
        use serde_json::json;
        let mut v = vec![
            ("method", json!(self.method.name())),
            ("supersample", json!(self.supersample)),
        ];
        v.extend(settings::KNOBS.iter().filter_map(|k| k.record(self)));
        v
    }

    /// Whether this method, at this S, reads the setting `option` (its
    /// long name, `-` or `_` between words): an option it does not read is
    /// worth a warning, since the user expected it to change something.
    /// Names that are not settings are read by every method.
    pub fn reads(&self, option: &str) -> bool {
        settings::knob(option).is_none_or(|k| (k.reads)(self.method, self.supersample))
    }

    /// `self` with the knobs of preset `q` (tolerance scaled to this S).
    pub fn with_quality(mut self, q: Quality) -> Self {
        self.quality = q;
        let d = self.defaults();
        for k in settings::KNOBS.iter().filter(|k| k.preset) {
            k.reset(&mut self, d);
        }
        self
    }

    /// What this method's, S's and preset's defaults depend on.
    fn defaults(&self) -> settings::Defaults {
        settings::Defaults {
            method: self.method,
            s: self.supersample,
            quality: self.quality,
        }
    }

    /// The preset's knob values as `(option, value)`, tolerance at S = 3:
    /// what `--quality` sets, for reports and the sweep.
    pub fn quality_settings(&self) -> Vec<(&'static str, String)> {
        let p = FilterParams::new(Method::EpGauss, 3).with_quality(self.quality);
        (settings::KNOBS.iter())
            .filter(|k| k.preset)
            .map(|k| (k.name, k.show(&p)))
            .collect()
    }

    /// Defaults for `method` at super-sampling `s` ([`settings::KNOBS`];
    /// ep-gauss's are [`Quality::Default`]'s).
    pub fn new(method: Method, s: usize) -> Self {
        let mut p = FilterParams {
            method,
            supersample: s,
            ..Default::default()
        };
        let d = p.defaults();
        for k in settings::KNOBS {
            k.reset(&mut p, d);
        }
        p
    }

    /// Set the setting `name` (`support_region` or `support-region`) from
    /// its command-line spelling; `quality` resets its preset's knobs.
    pub fn set(&mut self, name: &str, raw: &str) -> Result<()> {
        let k = settings::knob(name)
            .ok_or_else(|| Error::Config(format!("unknown setting {name:?}")))?;
        k.set(self, raw)?;
        if k.name == "quality" {
            *self = self.clone().with_quality(self.quality);
        }
        Ok(())
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
        for k in settings::KNOBS {
            k.check(self)?;
        }
        if self.max_radius < self.radius {
            return bad(format!(
                "--max-radius must be at least --radius ({}), got {}",
                self.radius, self.max_radius
            ));
        }
        if self.method == Method::EpBox {
            if self.supersample != 1 {
                return bad(format!(
                    "ep-box filters pixel-resolution renders with variance: use --supersample 1, not {}",
                    self.supersample
                ));
            }
            if self.max_radius < 1.0 {
                return bad(format!(
                    "--max-radius must be in 1..=128 pixels for ep-box, got {}",
                    self.max_radius
                ));
            }
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
