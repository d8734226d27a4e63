//! Every setting of the filters, defined once.
//!
//! [`KNOBS`] holds, for each setting a method reads, its name (the field of
//! [`FilterParams`]; on the command line with `-` between words), its help,
//! its default for a method, S and `--quality` preset, which methods read it,
//! whether and under which key a file's record of its settings names it, and
//! the check its value must pass. The command line's options, `--help`'s
//! preset listing, [`FilterParams::new`], [`FilterParams::settings`] (the
//! report and the output's provenance, whose order is the table's),
//! [`FilterParams::validate`] and the Python bindings all read it: adding a
//! setting is a field, one entry here, and the rule that uses it.

use serde_json::Value as Json;

use super::ep_box::{Guard, DEFAULT_MAX_RADIUS};
use super::ep_gauss::pixel::TOLERANCE as PIXEL_TOLERANCE;
use super::{default_tolerance, scaled_tolerance, FilterParams, Method, Quality};

/// What a setting's default depends on.
#[derive(Clone, Copy, Debug)]
pub struct Defaults {
    /// The method.
    pub method: Method,
    /// Super-sampling factor S.
    pub s: usize,
    /// The `--quality` preset (read by ep-gauss only).
    pub quality: Quality,
}

impl Defaults {
    /// `other` for every method but ep-gauss, whose value is its preset's
    /// (`fast`, `default`, `best`).
    fn preset<T>(&self, other: T, [fast, default, best]: [T; 3]) -> T {
        match (self.method, self.quality) {
            (Method::EpGauss, Quality::Fast) => fast,
            (Method::EpGauss, Quality::Default) => default,
            (Method::EpGauss, Quality::Best) => best,
            _ => other,
        }
    }

    /// `other` for every method but ep-gauss, whose value is `every` for
    /// every preset.
    fn ep_gauss<T: Copy>(&self, other: T, every: T) -> T {
        self.preset(other, [every; 3])
    }
}

/// A setting's value: how the command line (and Python's `str()`) spells
/// it, and how a record shows it.
pub trait Value: Sized {
    /// Parse the command line's spelling.
    fn parse(raw: &str) -> Result<Self, String>;
    /// As a file's record of its settings shows it.
    fn json(&self) -> Json;
    /// As the command line spells it.
    fn show(&self) -> String;
}

impl Value for f64 {
    fn parse(raw: &str) -> Result<Self, String> {
        raw.trim()
            .parse()
            .map_err(|_| format!("{raw:?} is not a number"))
    }
    fn json(&self) -> Json {
        Json::from(*self)
    }
    fn show(&self) -> String {
        self.to_string()
    }
}

macro_rules! whole_numbers {
    ($($t:ty),*) => {$(
        impl Value for $t {
            fn parse(raw: &str) -> Result<Self, String> {
                raw.trim()
                    .parse()
                    .map_err(|_| format!("{raw:?} is not a whole number >= 0"))
            }
            fn json(&self) -> Json {
                Json::from(*self)
            }
            fn show(&self) -> String {
                self.to_string()
            }
        }
    )*};
}
whole_numbers!(usize, u32, u64);

/// A number that may be absent (derived from the image when it is).
impl Value for Option<f64> {
    fn parse(raw: &str) -> Result<Self, String> {
        f64::parse(raw).map(Some)
    }
    fn json(&self) -> Json {
        self.map_or(Json::Null, Json::from)
    }
    fn show(&self) -> String {
        self.map_or_else(|| "auto".to_string(), |v| v.to_string())
    }
}

impl Value for Quality {
    fn parse(raw: &str) -> Result<Self, String> {
        Quality::parse(raw.trim()).map_err(|_| format!("{raw:?} is not fast, default or best"))
    }
    fn json(&self) -> Json {
        Json::from(self.name())
    }
    fn show(&self) -> String {
        self.name().to_string()
    }
}

impl Value for Guard {
    fn parse(raw: &str) -> Result<Self, String> {
        Guard::parse(raw.trim()).map_err(|_| {
            format!("{raw:?} is not none, range, stderr, both (range + stderr), carriers or all")
        })
    }
    fn json(&self) -> Json {
        Json::from(self.name())
    }
    fn show(&self) -> String {
        self.name().to_string()
    }
}

/// A confidence as 0.8, 80 or 80%.
fn confidence(raw: &str) -> Result<f64, String> {
    let c = raw.trim();
    let (num, pct) = match c.strip_suffix('%') {
        Some(n) => (n, true),
        None => (c, false),
    };
    let v: f64 = f64::parse(num.trim()).map_err(|_| format!("{c:?} is not a number"))?;
    Ok(if pct || v > 1.0 { v / 100.0 } else { v })
}

/// `Ok` when `ok`, else `must be {what}`.
fn need(ok: bool, what: &str) -> Result<(), String> {
    if ok {
        Ok(())
    } else {
        Err(format!("must be {what}"))
    }
}

/// The help heading a setting is listed under.
pub const METHOD: &str = "Method";
/// See [`METHOD`].
pub const EP_GAUSS: &str = "ep-gauss";
/// See [`METHOD`].
pub const EP_BOX: &str = "ep-box";

/// One setting of [`KNOBS`].
pub struct Knob {
    /// The field's name; the option is `--` and this with `-` for `_`.
    pub name: &'static str,
    /// The help heading.
    pub heading: &'static str,
    /// What the option's value is, for `--help`.
    pub value_name: &'static str,
    /// The help text (one paragraph).
    help: &'static str,
    /// Set by `--quality` (listed in its help).
    pub preset: bool,
    /// Whether `method` at S reads it (an option it does not read is
    /// warned about).
    pub reads: fn(Method, usize) -> bool,
    /// The key a file's record of `method`'s settings gives it, if any.
    record: fn(Method, &'static str) -> Option<&'static str>,
    /// Set the field to its default.
    default: fn(&mut FilterParams, Defaults),
    /// Parse a value and set the field to it.
    set: fn(&mut FilterParams, &str) -> Result<(), String>,
    /// The field's value, recorded.
    get: fn(&FilterParams) -> Json,
    /// The field's value, as the command line spells it.
    show: fn(&FilterParams) -> String,
    /// The check the field's value must pass (`Err`: "must be ...").
    check: fn(&FilterParams) -> Result<(), String>,
}

impl std::fmt::Debug for Knob {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Knob({})", self.name)
    }
}

impl Knob {
    /// The option's long name (`support-region`).
    pub fn option(&self) -> String {
        self.name.replace('_', "-")
    }

    /// The help text as one paragraph.
    pub fn help(&self) -> String {
        self.help
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// Parse `raw` into the field of `p`; an error names the option.
    pub fn set(&self, p: &mut FilterParams, raw: &str) -> crate::Result<()> {
        (self.set)(p, raw).map_err(|e| crate::Error::Config(format!("--{} {e}", self.option())))
    }

    /// The field's value in `p`, as the command line spells it.
    pub fn show(&self, p: &FilterParams) -> String {
        (self.show)(p)
    }

    /// The default, where every method that reads the setting has the same
    /// one at every S (for `--help`).
    pub fn fixed_default(&self) -> Option<String> {
        if self.preset {
            return None;
        }
        let mut shown = (Method::ALL.iter())
            .flat_map(|&m| (1..=8).map(move |s| (m, s)))
            .filter(|&(m, s)| (self.reads)(m, s))
            .map(|(m, s)| (self.show)(&FilterParams::new(m, s)));
        let first = shown.next()?;
        shown.all(|v| v == first).then_some(first)
    }

    /// Set the field of `p` to its default under `d`.
    pub fn reset(&self, p: &mut FilterParams, d: Defaults) {
        (self.default)(p, d)
    }

    /// The key and value `p`'s record gives the field, if it records it.
    pub fn record(&self, p: &FilterParams) -> Option<(&'static str, Json)> {
        (self.record)(p.method, self.name).map(|k| (k, (self.get)(p)))
    }

    /// The field's check; the error names the option and the value.
    pub fn check(&self, p: &FilterParams) -> crate::Result<()> {
        (self.check)(p).map_err(|e| {
            crate::Error::Config(format!("--{} {e}, got {}", self.option(), (self.show)(p)))
        })
    }
}

/// The setting named `name` (`support_region` or `support-region`).
pub fn knob(name: &str) -> Option<&'static Knob> {
    let name = name.replace('-', "_");
    KNOBS.iter().find(|k| k.name == name)
}

/// Defines [`KNOBS`]: per setting, its doc (the help), the field (`name`, or
/// `name @ group` for `p.group.name`), its type, and the entries of
/// [`Knob`] as closures: `default: |d| ..` ([`Defaults`]), `reads: |m, s|
/// ..`, `record: |m, name| ..` (the key or `None`), `check: |v| ..`
/// (`need(..)`), and optionally `parse: f` where [`Value::parse`] will not
/// do.
macro_rules! knobs {
    ($(
        $(#[doc = $doc:literal])*
        $name:ident $(@ $group:ident)? : $ty:ty {
            heading: $heading:expr,
            value_name: $value_name:literal,
            preset: $preset:literal,
            default: |$d:ident| $default:expr,
            reads: |$m:ident, $s:ident| $reads:expr,
            record: |$rm:ident, $rn:ident| $record:expr,
            check: |$v:ident| $check:expr,
            $(parse: $parse:expr,)?
        }
    )*) => {
        /// Every setting, in the order a file's record lists them.
        pub static KNOBS: &[Knob] = &[$(
            Knob {
                name: stringify!($name),
                heading: $heading,
                value_name: $value_name,
                help: concat!($($doc, "\n"),*),
                preset: $preset,
                reads: |$m, $s| {
                    let _ = ($m, $s);
                    $reads
                },
                record: |$rm, $rn| {
                    let _ = ($rm, $rn);
                    $record
                },
                default: |p, $d| {
                    let _ = $d;
                    p$(.$group)?.$name = $default
                },
                set: |p, raw| {
                    let parse: fn(&str) -> Result<$ty, String> =
                        knobs!(@parse $ty $(, $parse)?);
                    p$(.$group)?.$name = parse(raw)?;
                    Ok(())
                },
                get: |p| Value::json(&p$(.$group)?.$name),
                show: |p| Value::show(&p$(.$group)?.$name),
                check: |p| {
                    let $v: $ty = p$(.$group)?.$name;
                    let _ = $v;
                    $check
                },
            },
        )*];
    };
    (@parse $ty:ty) => { <$ty as Value>::parse };
    (@parse $ty:ty, $parse:expr) => { $parse };
}

use Method::{AlphaTrim, Clamp, EpBox, EpGauss, Gauss, Median};

knobs! {
    /// ep-box: the allowed interval ±D, in units of L_tvis.
    d @ ep_box: f64 {
        heading: EP_BOX, value_name: "D", preset: false,
        default: |d| 5.0,
        reads: |m, s| m == EpBox,
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| need(v.is_finite() && v >= 0.0, "a finite number >= 0"),
    }
    /// ep-box: N_MID, the display level the mean luminance maps to (Eq. 9).
    nmid @ ep_box: f64 {
        heading: EP_BOX, value_name: "N", preset: false,
        default: |d| 128.0,
        reads: |m, s| m == EpBox,
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| need(v.is_finite() && v > 0.0, "> 0"),
    }
    /// ep-box: the visibility threshold L_tvis [default: mean luminance /
    /// N_MID, Eq. 9].
    ltvis @ ep_box: Option<f64> {
        heading: EP_BOX, value_name: "L", preset: false,
        default: |d| None,
        reads: |m, s| m == EpBox,
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| need(v.is_none_or(|l| l.is_finite() && l > 0.0), "a finite number > 0"),
    }
    /// ep-box: the confidence of the noise test (0.8, 80 or 80%).
    confidence @ ep_box: f64 {
        heading: EP_BOX, value_name: "P", preset: false,
        default: |d| 0.8,
        reads: |m, s| m == EpBox,
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| need(v > 0.0 && v < 1.0, "in (0, 1) (e.g. 0.8)"),
        parse: confidence,
    }
    /// ep-box: the most passes over clusters of noisy pixels.
    passes @ ep_box: usize {
        heading: EP_BOX, value_name: "N", preset: false,
        default: |d| 8,
        reads: |m, s| m == EpBox,
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| need((1..=64).contains(&v), "1..=64"),
    }
    /// A point on ep-gauss's speed/accuracy front (docs/pareto.md): a set of
    /// the knob values below, which each given option overrides.
    quality: Quality {
        heading: EP_GAUSS, value_name: "fast|default|best", preset: false,
        default: |d| d.quality,
        reads: |m, s| m == EpGauss,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| Ok(()),
    }
    /// clamp: the largest sample value kept, per channel (then the base
    /// Gaussian).
    clamp: f64 {
        heading: METHOD, value_name: "X", preset: false,
        default: |d| 10.0,
        reads: |m, s| m == Clamp,
        record: |m, n| (m == Clamp).then_some(n),
        check: |v| need(v.is_finite() && v >= 0.0, "a finite number >= 0"),
    }
    /// Relation 14 tolerance, at this S [default: --quality's, given at S = 3
    /// and scaled as 0.25 at 3 is to 0.15 at 4: t*(3/S)^1.776]. At S = 1: the
    /// most of its background a spread adds to any pixel [default: 0.25].
    tolerance: f64 {
        heading: EP_GAUSS, value_name: "T", preset: true,
        default: |d| match (d.method, d.s) {
            (EpGauss, 1) => PIXEL_TOLERANCE,
            (EpGauss, s) => scaled_tolerance(0.08, s),
            (_, s) => default_tolerance(s.max(1)),
        },
        reads: |m, s| m == EpGauss,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v.is_finite() && v >= 0.0, "a finite number >= 0"),
    }
    /// Base Gaussian radius in output pixels (weight exp(-(d/r)^2)): ep-gauss,
    /// gauss, clamp [default: 0.6 (Radiance's pfilt -r); ep-gauss: its
    /// --quality's].
    radius: f64 {
        heading: METHOD, value_name: "R", preset: true,
        default: |d| 0.6,
        reads: |m, s| matches!(m, EpGauss | Gauss | Clamp),
        record: |m, n| matches!(m, EpGauss | Gauss | Clamp).then_some(n),
        check: |v| need(v.is_finite() && (0.05..=16.0).contains(&v), "in 0.05..=16 output pixels"),
    }
    /// Largest Gaussian radius a noisy sample may get, in output pixels
    /// (ep-box: the largest spread radius, in pixels) [default: ep-gauss: its
    /// --quality's; ep-box: 8].
    max_radius: f64 {
        heading: METHOD, value_name: "R", preset: true,
        default: |d| if d.method == EpBox {
            DEFAULT_MAX_RADIUS
        } else {
            // The cap bounds the halo: 8 px drops the widest spreads,
            // which cost the most; 32 px has the least error with every
            // light kept, at twice the default's halo (docs/pareto.md).
            d.preset(16.0, [8.0, 16.0, 32.0])
        },
        reads: |m, s| matches!(m, EpGauss | EpBox),
        record: |m, n| match m {
            EpGauss => Some(n),
            EpBox => Some("radius"),
            _ => None,
        },
        check: |v| need(v.is_finite() && v <= 128.0, "at most 128 output pixels"),
    }
    /// Kernel cut-off in radii [default: 3 (the Gaussian has fallen to
    /// e^-9); ep-gauss: its --quality's].
    cutoff: f64 {
        heading: METHOD, value_name: "C", preset: true,
        default: |d| 3.0,
        reads: |m, s| matches!(m, EpGauss | Gauss | Clamp),
        record: |m, n| matches!(m, EpGauss | Gauss | Clamp).then_some(n),
        check: |v| need(v.is_finite() && (1.0..=6.0).contains(&v), "in 1..=6 radii"),
    }
    /// Relative step of the ladder of widths the search picks from (its
    /// precision) [default: --quality's].
    width_step: f64 {
        heading: EP_GAUSS, value_name: "F", preset: true,
        default: |d| d.ep_gauss(0.1, 0.2),
        reads: |m, s| m == EpGauss,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v.is_finite() && (0.005..=1.0).contains(&v), "in 0.005..=1"),
    }
    /// A noisy sample with at least this many noisy neighbouring
    /// super-samples (within --support-ratio of it) is a feature and keeps the
    /// base kernel (S > 1; the --support* knobs are S > 1's). 0 = the paper's
    /// rule [default: --quality's].
    support: usize {
        heading: EP_GAUSS, value_name: "N", preset: true,
        default: |d| d.ep_gauss(1, 2),
        reads: |m, s| m == EpGauss && s > 1,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v <= 8, "0..=8 neighbours"),
    }
    /// Neighbours support a sample when within this factor of its luminance
    /// [default: --quality's].
    support_ratio: f64 {
        heading: EP_GAUSS, value_name: "F", preset: true,
        default: |d| 16.0,
        reads: |m, s| m == EpGauss && s > 1,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v.is_finite() && v >= 1.0, "a number >= 1"),
    }
    /// A sample with fewer than --support supporting neighbours is kept when
    /// its group (the samples joined to it through supporting neighbours,
    /// within 2 super-samples) holds at least this many: the runs of hits
    /// along a thin line or a rim (0 = off) [default: --quality's].
    support_group: usize {
        heading: EP_GAUSS, value_name: "N", preset: true,
        default: |d| 0,
        reads: |m, s| m == EpGauss && s > 1,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v <= 25, "0..=25 samples (the 5 x 5 about a sample)"),
    }
    /// A sample with one supporting neighbour (fewer than --support) is kept
    /// when at most this many super-samples within 2 of it fail the test: a
    /// compact pair, a bulb a fraction of a pixel wide (0 = off) [default:
    /// --quality's].
    support_compact: usize {
        heading: EP_GAUSS, value_name: "N", preset: true,
        default: |d| d.ep_gauss(0, 2),
        reads: |m, s| m == EpGauss && s > 1,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v <= 25, "0..=25 samples"),
    }
    /// ... and when it is at least this many times the median box luminance
    /// of the eight pixels about its own: a bulb is hundreds of times its
    /// room, two fireflies that touch rarely are (0 = any) [default:
    /// --quality's].
    support_over: f64 {
        heading: EP_GAUSS, value_name: "F", preset: true,
        default: |d| d.ep_gauss(0.0, 150.0),
        reads: |m, s| m == EpGauss && s > 1,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v.is_finite() && v >= 0.0, "a number >= 0"),
    }
    /// A bright sample with fewer than --support noisy neighbours is kept too
    /// when at least this many super-samples within 2 of it are comparable:
    /// above its pixel's average and within --support-level of it (grain
    /// inside a glossy highlight, not a firefly on a dark ground; 0 = off)
    /// [default: --quality's].
    support_region: usize {
        heading: EP_GAUSS, value_name: "N", preset: true,
        default: |d| d.ep_gauss(0, 8),
        reads: |m, s| m == EpGauss && s > 1,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v <= 24, "0..=24 samples"),
    }
    /// See --support-region: comparable is within this factor of the sample,
    /// which is itself at most this many times its pixel's average
    /// [default: --quality's].
    support_level: f64 {
        heading: EP_GAUSS, value_name: "F", preset: true,
        default: |d| 4.0,
        reads: |m, s| m == EpGauss && s > 1,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v.is_finite() && v >= 1.0, "a number >= 1"),
    }
    /// Spread widths of this radius (output pixels) and more on a 2x coarser
    /// grid, and from twice it on a 4x coarser grid, brought back with a tent
    /// per halving: a quarter (a sixteenth) of the taps, energy exact, no
    /// pixel given more than the full-resolution kernel would; 0 = off
    /// [default: 2: no factor on the renders higher, fewer taps].
    coarse_from: f64 {
        heading: EP_GAUSS, value_name: "R", preset: false,
        default: |d| 2.0,
        reads: |m, s| m == EpGauss && s > 1,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v.is_finite() && v >= 0.0, "a radius >= 0 output pixels (0: off)"),
    }
    /// Check widths of this radius (output pixels) and more against a lower
    /// bound of their average read from a summed-area table, a few entries
    /// instead of every row of the average's disc: conservative (a width that
    /// passes on the bound passes on the average), at most about a rung
    /// wider; 0 = the exact average always [default: --quality's].
    bound_from: f64 {
        heading: EP_GAUSS, value_name: "R", preset: true,
        default: |d| d.ep_gauss(0.0, 3.0),
        reads: |m, s| m == EpGauss && s > 1,
        record: |m, n| (m == EpGauss).then_some(n),
        check: |v| need(v.is_finite() && v >= 0.0, "a radius >= 0 output pixels (0: off)"),
    }
    /// What keeps real features from being spread. ep-box: all (carriers +
    /// range + stderr), carriers, range, stderr, both (range + stderr), none
    /// (§5.1 as written). ep-gauss: none (§5.2 as written) turns off its
    /// --support rule (at S = 1: its feature rules).
    guard @ ep_box: Guard {
        heading: METHOD, value_name: "GUARD", preset: false,
        default: |d| Guard::All,
        reads: |m, s| matches!(m, EpBox | EpGauss),
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| Ok(()),
    }
    /// ep-box: the confidence of the stderr guard's bound on the excess noise
    /// can explain.
    guard_confidence @ ep_box: f64 {
        heading: EP_BOX, value_name: "P", preset: false,
        default: |d| 0.99,
        reads: |m, s| m == EpBox,
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| need(v > 0.0 && v < 1.0, "in (0, 1) (e.g. 0.99)"),
    }
    /// ep-box, carriers guard: a pixel whose mean rests on at least this many
    /// samples (n Y^2 / (var + Y^2)) is not noise...
    carriers @ ep_box: f64 {
        heading: EP_BOX, value_name: "N", preset: false,
        default: |d| 16.0,
        reads: |m, s| m == EpBox,
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| need(v.is_finite() && v >= 1.0, "a number >= 1"),
    }
    /// ... nor one whose mean rests on at least this fraction of its samples
    /// and whose relative standard error is at most --carriers-rse.
    carriers_fraction @ ep_box: f64 {
        heading: EP_BOX, value_name: "F", preset: false,
        default: |d| 0.2,
        reads: |m, s| m == EpBox,
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| need(v > 0.0 && v <= 1.0, "in (0, 1]"),
    }
    /// See --carriers-fraction.
    carriers_rse @ ep_box: f64 {
        heading: EP_BOX, value_name: "F", preset: false,
        default: |d| 0.5,
        reads: |m, s| m == EpBox,
        record: |m, n| (m == EpBox).then_some(n),
        check: |v| need(v.is_finite() && v >= 0.0, "a finite number >= 0"),
    }
    /// alpha-trim: the fraction of the sorted samples trimmed from each end
    /// (0..0.5).
    alpha: f64 {
        heading: METHOD, value_name: "F", preset: false,
        default: |d| 0.25,
        reads: |m, s| m == AlphaTrim,
        record: |m, n| matches!(m, Median | AlphaTrim).then_some(n),
        check: |v| need((0.0..0.5).contains(&v), "in 0..0.5"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_knob_is_named_once_and_found_by_either_spelling() {
        for (i, k) in KNOBS.iter().enumerate() {
            assert!(KNOBS[..i].iter().all(|o| o.name != k.name), "{}", k.name);
            assert!(std::ptr::eq(knob(&k.option()).unwrap(), k));
            assert!(
                !k.help().is_empty() && !k.help().contains('\n'),
                "{}",
                k.name
            );
        }
        assert!(knob("tolerence").is_none());
    }

    #[test]
    fn every_default_passes_its_check_for_every_method_and_s() {
        for m in Method::ALL {
            for s in 1..=8 {
                let p = FilterParams::new(m, s);
                for k in KNOBS {
                    k.check(&p).unwrap_or_else(|e| panic!("{m:?} S={s}: {e}"));
                }
            }
        }
    }

    #[test]
    fn a_value_round_trips_through_its_spelling() {
        let mut p = FilterParams::new(Method::EpBox, 1);
        for k in KNOBS {
            let shown = k.show(&p);
            if shown == "auto" {
                continue;
            }
            let before = p.clone();
            k.set(&mut p, &shown)
                .unwrap_or_else(|e| panic!("{}: {e}", k.name));
            assert_eq!(p, before, "{}", k.name);
        }
        let c = knob("confidence").unwrap();
        for raw in ["0.9", "90", "90%"] {
            c.set(&mut p, raw).unwrap();
            assert_eq!(p.ep_box.confidence, 0.9, "{raw}");
        }
        let e = knob("radius").unwrap().set(&mut p, "x").unwrap_err();
        assert_eq!(
            e.to_string(),
            "invalid configuration: --radius \"x\" is not a number"
        );
    }

    #[test]
    fn a_failed_check_names_the_option_and_the_value() {
        let mut p = FilterParams::new(Method::EpGauss, 3);
        p.support_group = 30;
        let e = knob("support_group").unwrap().check(&p).unwrap_err();
        assert!(
            e.to_string().ends_with(
                "--support-group must be 0..=25 samples (the 5 x 5 about a sample), got 30"
            ),
            "{e}"
        );
    }
}
