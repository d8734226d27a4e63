//! What happens to the channels that are not the beauty's colour: the rules
//! of `--channel-rule` and the defaults chosen by name.
//!
//! * **additive** (light AOVs: diffuse, specular, emission, per-light and
//!   LPE layers...): spread with the beauty's own per-sample kernels, so that
//!   layers that summed to the beauty in the input still do in the output,
//!   and each keeps its energy exactly.
//! * **average** (depth, normals, positions, motion, albedo, variance, and
//!   anything not recognised): the base filter, never spread (a depth is not
//!   energy); at S = 1 copied bit for bit.
//! * **nearest** (ids, masks, cryptomatte): the centre sample of each pixel,
//!   never a mix of values.
//! * **drop**: not written.
//!
//! The beauty's own channels (R, G, B or Y, and A) are not ruled here.

use crate::error::{Error, Result};

/// How one carried channel is resampled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ChannelRule {
    /// Spread with the beauty's kernels (energy exact, sums kept).
    Additive,
    /// The base filter (S = 1: copied).
    Average,
    /// The centre sample of each pixel.
    Nearest,
    /// Not written.
    Drop,
}

impl ChannelRule {
    /// The name `--channel-rule` takes and reports show.
    pub fn name(self) -> &'static str {
        match self {
            ChannelRule::Additive => "additive",
            ChannelRule::Average => "average",
            ChannelRule::Nearest => "nearest",
            ChannelRule::Drop => "drop",
        }
    }

    /// Parse a rule's name.
    pub fn parse(s: &str) -> Result<Self> {
        Ok(match s.trim().to_ascii_lowercase().as_str() {
            "additive" => ChannelRule::Additive,
            "average" => ChannelRule::Average,
            "nearest" => ChannelRule::Nearest,
            "drop" => ChannelRule::Drop,
            other => {
                return Err(Error::Config(format!(
                    "--channel-rule: unknown rule {other:?} (additive, average, nearest or drop)"
                )))
            }
        })
    }
}

/// One `--channel-rule PATTERN=RULE`: channels whose full name matches the
/// glob `PATTERN` (`*`, `?`, `[...]`; e.g. `diffuse.*`, `*.Z`) get `RULE`.
#[derive(Clone, Debug)]
pub struct RuleOverride {
    pattern: glob::Pattern,
    text: String,
    /// The rule.
    pub rule: ChannelRule,
}

impl RuleOverride {
    /// Parse `PATTERN=RULE`.
    pub fn parse(s: &str) -> Result<Self> {
        let (pat, rule) = s.rsplit_once('=').ok_or_else(|| {
            Error::Config(format!(
                "--channel-rule {s:?}: expected PATTERN=RULE, e.g. 'diffuse.*=additive'"
            ))
        })?;
        let pattern = glob::Pattern::new(pat)
            .map_err(|e| Error::Config(format!("--channel-rule {s:?}: bad pattern: {e}")))?;
        Ok(RuleOverride {
            pattern,
            text: pat.to_string(),
            rule: ChannelRule::parse(rule)?,
        })
    }

    /// The pattern as given.
    pub fn pattern(&self) -> &str {
        &self.text
    }

    /// Whether `name` matches.
    pub fn matches(&self, name: &str) -> bool {
        self.pattern.matches(name)
    }
}

/// Words (of a layer name, any case) of light that adds up to the beauty:
/// Blender's passes (DiffDir, GlossInd, Emit, Env; light groups
/// `Combined_<group>`), Arnold's (`diffuse_direct`, `RGBA_<group>`),
/// RenderMan's (`directDiffuse`), V-Ray's (`VRayLighting`,
/// `VRayGlobalIllumination`) and the generic ones.
const ADDITIVE_WORDS: &[&str] = &[
    "diffuse",
    "diff",
    "diffdir",
    "diffind",
    "specular",
    "spec",
    "glossy",
    "gloss",
    "glossdir",
    "glossind",
    "transmission",
    "trans",
    "transdir",
    "transind",
    "emission",
    "emit",
    "env",
    "environment",
    "background",
    "direct",
    "indirect",
    "ind",
    "dir",
    "sss",
    "subsurface",
    "volume",
    "coat",
    "sheen",
    "light",
    "lights",
    "lighting",
    "illumination",
    "gi",
    "lpe",
    "caustic",
    "caustics",
    "reflection",
    "reflect",
    "refraction",
    "refract",
    "combined",
    "beauty",
    "rgba",
    "ci",
];

/// Words of ids and masks.
const NEAREST_WORDS: &[&str] = &["id", "ids", "index", "indexob", "indexma", "mask", "matte"];

/// Words of averaged data, checked before the additive ones (`DiffCol` and
/// `VRayDiffuseFilter` are albedos, not light).
const AVERAGE_WORDS: &[&str] = &[
    "z",
    "depth",
    "n",
    "normal",
    "normals",
    "p",
    "position",
    "pref",
    "motion",
    "vector",
    "velocity",
    "uv",
    "albedo",
    "col",
    "color",
    "colour",
    "filter",
    "diffcol",
    "glosscol",
    "transcol",
    "ao",
    "occlusion",
    "shadow",
    "variance",
    "var",
    "se",
    "mist",
    "alpha",
];

/// The words of one component of a channel name, lowercased: split at
/// `_`, `-`, spaces and digits, and where lower case turns to upper
/// (`diffuse_direct`, `directDiffuse`, `Combined_Key`, `light00`).
fn words(component: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut prev_lower = false;
    for ch in component.chars() {
        if !ch.is_alphabetic() {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            prev_lower = false;
            continue;
        }
        if ch.is_uppercase() && prev_lower && !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
        prev_lower = ch.is_lowercase();
        cur.extend(ch.to_lowercase());
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// The default rule of a carried channel `name` (`uint`: its samples are
/// unsigned integers).
pub fn default_rule(name: &str, uint: bool) -> ChannelRule {
    if uint {
        return ChannelRule::Nearest;
    }
    let parts: Vec<&str> = name.split('.').collect();
    let (layers, last) = parts.split_at(parts.len() - 1);
    // Each component as a whole (`IndexOB`, `DiffCol`) and its words.
    let has = |comps: &[&str], list: &[&str]| {
        comps.iter().any(|c| {
            list.contains(&c.to_ascii_lowercase().as_str())
                || words(c).iter().any(|w| list.contains(&w.as_str()))
        })
    };
    if name.to_ascii_lowercase().contains("crypto") || has(&parts, NEAREST_WORDS) {
        return ChannelRule::Nearest;
    }
    if layers.is_empty() || has(layers, AVERAGE_WORDS) {
        // Unlayered channels beside the beauty (Z, a mask...) and data.
        return ChannelRule::Average;
    }
    // An AOV's alpha is coverage, not light.
    if last[0].eq_ignore_ascii_case("a") {
        return ChannelRule::Average;
    }
    if has(layers, ADDITIVE_WORDS) {
        return ChannelRule::Additive;
    }
    ChannelRule::Average
}

/// Which view of a multi-view file a run writes, by OpenEXR's convention
/// (`multiView`, the default view first): a channel of one name component
/// (`R`) is the default view's; of more, its second-to-last component names
/// its view when that is a view (`right.R`, `diffuse.right.R`), and
/// otherwise it belongs to no view in particular (`diffuse.R`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ViewScope {
    /// The file's views, the default first (none: not a multi-view file).
    pub views: Vec<String>,
    /// The index of the view this run writes.
    pub this: usize,
    /// `--view all`: each view is a run of its own, so nothing of another
    /// view is carried whatever the overrides, and channels of no view go
    /// with the default view's run only.
    pub exclusive: bool,
}

impl ViewScope {
    /// The view of `name` (an index into `views`), if it has one.
    pub fn view_of(&self, name: &str) -> Option<usize> {
        let parts: Vec<&str> = name.split('.').collect();
        match parts.as_slice() {
            [] => None,
            [_] => (!self.views.is_empty()).then_some(0),
            [.., view, _] => self.views.iter().position(|v| v == view),
        }
    }

    /// Whether `name` belongs to a view other than this run's.
    pub fn excludes(&self, name: &str) -> bool {
        if self.views.len() < 2 {
            return false;
        }
        match self.view_of(name) {
            Some(v) => v != self.this,
            None => self.exclusive && self.this != 0,
        }
    }

    /// The name of this run's view, if the file has views.
    pub fn name(&self) -> Option<&str> {
        self.views.get(self.this).map(String::as_str)
    }

    /// `name` as this run sees it: without its view's component where it
    /// is of this run's view (`ViewLayer.Combined.left.R`, as Blender names
    /// the default view's channels too, is `ViewLayer.Combined.R`; `right.R`
    /// is `R`), as it is where it is of no view, and `None` where it is of
    /// another view. The beauty and the guides are found among these names:
    /// a view's layers are the layers of an image of its own.
    pub fn seen(&self, name: &str) -> Option<String> {
        match self.view_of(name) {
            _ if self.views.is_empty() => Some(name.to_string()),
            Some(v) if v != self.this => None,
            Some(_) => match name.rsplit_once('.') {
                Some((rest, channel)) => Some(match rest.rsplit_once('.') {
                    Some((layer, _view)) => format!("{layer}.{channel}"),
                    None => channel.to_string(),
                }),
                None => Some(name.to_string()),
            },
            None => Some(name.to_string()),
        }
    }

    /// The channels `names` (in file order) as this run sees them
    /// ([`ViewScope::seen`]), each beside its name in the file. A channel of
    /// no view that a view's channel is seen as is left out.
    pub fn seen_names(&self, names: &[String]) -> Vec<(String, String)> {
        let mut out: Vec<(String, String)> = (names.iter())
            .filter_map(|n| self.seen(n).map(|s| (s, n.clone())))
            .collect();
        let viewed: Vec<String> = (out.iter())
            .filter(|(s, n)| s != n)
            .map(|(s, _)| s.clone())
            .collect();
        out.retain(|(s, n)| s != n || !viewed.contains(s));
        out
    }
}

/// The rule for `name`: the last override that matches, else the default;
/// the channels of a stereo file's other views (`right.R` where `multiView`
/// names `left, right`) are dropped, unless an override keeps them in a
/// single-view run: a view is an image of its own, not a layer of the
/// beauty's.
pub fn rule_for(
    name: &str,
    uint: bool,
    overrides: &[RuleOverride],
    scope: &ViewScope,
) -> ChannelRule {
    let given = overrides.iter().rev().find(|o| o.matches(name));
    if scope.excludes(name) && (scope.exclusive || given.is_none()) {
        return ChannelRule::Drop;
    }
    given.map_or_else(|| default_rule(name, uint), |o| o.rule)
}

/// What the stage does with one channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelMode {
    /// The base filter, and noisy samples spread (the beauty's colour, and
    /// additive layers with the beauty's kernels).
    Spread,
    /// The base filter only (alpha, averaged data).
    Base,
    /// The centre sample of each pixel (ids; averaged data at S = 1, which
    /// is then copied bit for bit). Not energy: out of the ledger's check.
    Nearest,
}

impl ChannelMode {
    /// The mode of a channel with luminance weight `lum` and carried by
    /// `rule` (`None`: the beauty's own channel) at super-sampling `s`.
    pub fn of(lum: f64, rule: Option<ChannelRule>, s: usize) -> Self {
        match rule {
            None if lum != 0.0 => ChannelMode::Spread,
            None => ChannelMode::Base,
            Some(ChannelRule::Additive) => ChannelMode::Spread,
            Some(ChannelRule::Average | ChannelRule::Drop) if s > 1 => ChannelMode::Base,
            Some(_) => ChannelMode::Nearest,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_rule_has_its_stage_mode() {
        use ChannelMode::*;
        assert_eq!(ChannelMode::of(0.2126, None, 3), Spread); // beauty colour
        assert_eq!(ChannelMode::of(0.0, None, 3), Base); // alpha
        assert_eq!(ChannelMode::of(0.0, Some(ChannelRule::Additive), 3), Spread);
        assert_eq!(ChannelMode::of(0.0, Some(ChannelRule::Average), 3), Base);
        // At S = 1 averaged data is copied bit for bit: the centre sample.
        assert_eq!(ChannelMode::of(0.0, Some(ChannelRule::Average), 1), Nearest);
        assert_eq!(ChannelMode::of(0.0, Some(ChannelRule::Drop), 2), Base);
        assert_eq!(ChannelMode::of(0.0, Some(ChannelRule::Nearest), 4), Nearest);
    }

    #[test]
    fn views_by_openexr_convention() {
        let s = ViewScope {
            views: vec!["left".into(), "right".into()],
            this: 1,
            exclusive: false,
        };
        assert_eq!(s.view_of("R"), Some(0));
        assert_eq!(s.view_of("right.R"), Some(1));
        assert_eq!(s.view_of("diffuse.right.R"), Some(1));
        assert_eq!(s.view_of("left.R"), Some(0));
        assert_eq!(s.view_of("diffuse.R"), None);
        assert!(s.excludes("R") && s.excludes("diffuse.left.G"));
        assert!(!s.excludes("right.G") && !s.excludes("diffuse.R"));
        let exclusive = ViewScope {
            exclusive: true,
            ..s.clone()
        };
        assert!(exclusive.excludes("diffuse.R"));
        assert!(!ViewScope::default().excludes("right.R"));
    }

    #[test]
    fn a_view_sees_its_own_channels_without_their_views_name() {
        let names: Vec<String> = [
            "R",
            "right.R",
            "ViewLayer.Combined.left.R",
            "ViewLayer.Combined.right.R",
            "diffuse.R",
            "ViewLayer.Emit.left.R",
        ]
        .map(String::from)
        .to_vec();
        let left = ViewScope {
            views: vec!["left".into(), "right".into()],
            this: 0,
            exclusive: false,
        };
        let seen = |s: &ViewScope| -> Vec<(String, String)> { s.seen_names(&names) };
        let pair = |a: &str, b: &str| (a.to_string(), b.to_string());
        assert_eq!(
            seen(&left),
            vec![
                pair("R", "R"),
                pair("ViewLayer.Combined.R", "ViewLayer.Combined.left.R"),
                pair("diffuse.R", "diffuse.R"),
                pair("ViewLayer.Emit.R", "ViewLayer.Emit.left.R"),
            ]
        );
        let right = ViewScope { this: 1, ..left };
        assert_eq!(
            seen(&right),
            vec![
                pair("R", "right.R"),
                pair("ViewLayer.Combined.R", "ViewLayer.Combined.right.R"),
                pair("diffuse.R", "diffuse.R"),
            ]
        );
        // A channel of no view that a view's channel is seen as gives way.
        let both = ["diffuse.R", "diffuse.right.R"].map(String::from);
        assert_eq!(
            right.seen_names(&both),
            vec![pair("diffuse.R", "diffuse.right.R")]
        );
        // Without views every name is seen as it is.
        assert_eq!(ViewScope::default().seen_names(&names).len(), names.len());
    }

    #[test]
    fn defaults_by_name_and_type() {
        use ChannelRule::*;
        for (name, rule) in [
            ("diffuse.R", Additive),
            ("specular.B", Additive),
            ("ViewLayer.DiffDir.G", Additive),
            ("ViewLayer.DiffCol.G", Average),
            ("emission.R", Additive),
            ("diffuse.A", Average),
            ("Z", Average),
            ("depth.Z", Average),
            ("N.X", Average),
            ("P.Y", Average),
            ("var.R", Average),
            ("albedo.G", Average),
            ("id", Nearest),
            ("CryptoObject00.R", Nearest),
            ("objectId.R", Nearest),
            ("mystery.R", Average),
            // Production names: Arnold, Blender light groups, RenderMan, V-Ray.
            ("diffuse_direct.R", Additive),
            ("specular_indirect.G", Additive),
            ("RGBA_key.B", Additive),
            ("ViewLayer.Combined_Key.R", Additive),
            ("directDiffuse.R", Additive),
            ("VRayLighting.G", Additive),
            ("VRayGlobalIllumination.B", Additive),
            ("VRayReflection.R", Additive),
            ("light00.R", Additive),
            ("VRayDiffuseFilter.R", Average),
            ("VRayZDepth.Z", Average),
            ("VRayObjectID.R", Nearest),
            ("ViewLayer.Denoising Albedo.G", Average),
            ("ViewLayer.Denoising Normal.X", Average),
            ("ViewLayer.IndexOB.X", Nearest),
            ("ViewLayer.Emit.B", Additive),
            ("ViewLayer.AO.R", Average),
            ("ViewLayer.DiffInd.R", Additive),
            ("ViewLayer.Vector.X", Average),
            ("diffuse_indirect.A", Average),
        ] {
            assert_eq!(default_rule(name, false), rule, "{name}");
        }
        assert_eq!(default_rule("anything", true), Nearest);
        assert_eq!(
            words("VRayGlobalIllumination"),
            ["vray", "global", "illumination"]
        );
        assert_eq!(words("diffuse_direct2"), ["diffuse", "direct"]);
        assert_eq!(words("Denoising Albedo"), ["denoising", "albedo"]);
    }

    #[test]
    fn overrides_win_and_the_last_match_counts() {
        let o = [
            RuleOverride::parse("*=drop").unwrap(),
            RuleOverride::parse("mystery.*=additive").unwrap(),
        ];
        let none = ViewScope::default();
        assert_eq!(
            rule_for("mystery.R", false, &o, &none),
            ChannelRule::Additive
        );
        assert_eq!(rule_for("Z", false, &o, &none), ChannelRule::Drop);
        let stereo = ViewScope {
            views: vec!["left".into(), "right".into()],
            this: 0,
            exclusive: false,
        };
        assert_eq!(rule_for("right.R", false, &[], &stereo), ChannelRule::Drop);
        let keep = [RuleOverride::parse("right.*=average").unwrap()];
        assert_eq!(
            rule_for("right.R", false, &keep, &stereo),
            ChannelRule::Average
        );
        // --view all: another view's channel is never carried.
        let all = ViewScope {
            exclusive: true,
            ..stereo.clone()
        };
        assert_eq!(rule_for("right.R", false, &keep, &all), ChannelRule::Drop);
        assert!(RuleOverride::parse("nope").is_err());
        assert!(RuleOverride::parse("a=blur").is_err());
        assert!(RuleOverride::parse("[=drop").is_err());
    }
}
