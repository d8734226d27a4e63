//! Finding a render's guide passes under the names real renderers give them
//! (what they are for: [`crate::filter::guides`]).
//!
//! A layer is matched by its last name component, case, spaces and `_`
//! aside (`ViewLayer.Denoising Albedo.R` is `denoisingalbedo`); its channels
//! by their last component (`R/G/B` for emission and albedo, `X/Y/Z` or
//! `R/G/B` for normals, one channel for depth).
//!
//! | renderer | emission | albedo | normal | depth |
//! |---|---|---|---|---|
//! | Blender Cycles | `Emit` (`Emission`) | `Denoising Albedo`, `DiffCol` | `Normal`, `Denoising Normal` | `Depth.Z`, `Denoising Depth` |
//! | Arnold | `emission` | `albedo`, `diffuse_albedo` | `N` | `Z` |
//! | RenderMan | `emission`, `emissive` | `albedo` | `Nn`, `normal` | `z`, `depth` |
//! | V-Ray | `VRaySelfIllumination`, `selfIllum` | `VRayDiffuseFilter`, `diffuseFilter` | `VRayNormals`, `normals` | `VRayZDepth`, `zDepth` |
//! | Karma | `emission` | `albedo` | `N` | `Z`, `depth` |
//! | Mitsuba 3 (`aov`; epfilt's `scripts/render-scenes`) | `emission` | `albedo` | `sh_normal`, `nn`, `N` | `depth`, `dd`, `Z` |
//! | generic | `emission.R/G/B` | `albedo.R/G/B` | `N.X/Y/Z` | `Z` |
//!
//! The directly visible emission is what a path tracer returns at the first
//! hit (Arnold `C[LO]`-style, Cycles' `Emit` pass). `--guide KIND=NAME` names
//! a layer (or depth's channel) instead; `--guides none` turns them off.

use std::path::Path;

use exr::meta::header::Header;

use crate::error::{Error, Result};
use crate::filter::channels::{ChannelRule, ViewScope};
use crate::filter::guides::GuideLayout;
use crate::io::reader::{beauty_layers, scope};
use crate::io::ExrInput;

/// A kind of guide pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GuideKind {
    /// The directly visible emission.
    Emission,
    /// The albedo.
    Albedo,
    /// The shading normal.
    Normal,
    /// The depth.
    Depth,
}

impl GuideKind {
    /// Every kind, in the order reports list them.
    pub const ALL: [GuideKind; 4] = [
        GuideKind::Emission,
        GuideKind::Albedo,
        GuideKind::Normal,
        GuideKind::Depth,
    ];

    /// The name `--guides` and `--guide` take.
    pub fn name(self) -> &'static str {
        match self {
            GuideKind::Emission => "emission",
            GuideKind::Albedo => "albedo",
            GuideKind::Normal => "normal",
            GuideKind::Depth => "depth",
        }
    }

    /// Parse a kind's name.
    pub fn parse(s: &str) -> Result<Self> {
        GuideKind::ALL
            .into_iter()
            .find(|k| k.name() == s.trim())
            .ok_or_else(|| {
                Error::Config(format!(
                    "unknown guide {s:?} (emission, albedo, normal or depth)"
                ))
            })
    }

    /// Layer names (normalised: lower case, no spaces or `_`) that hold it,
    /// in order of preference.
    fn layers(self) -> &'static [&'static str] {
        match self {
            GuideKind::Emission => &[
                "emission",
                "emit",
                "emissive",
                "vrayselfillumination",
                "selfillum",
                "selfillumination",
            ],
            GuideKind::Albedo => &[
                "albedo",
                "denoisingalbedo",
                "diffusealbedo",
                "vraydiffusefilter",
                "diffusefilter",
                "diffcol",
            ],
            GuideKind::Normal => &[
                "n",
                "nn",
                "normal",
                "normals",
                "shnormal",
                "denoisingnormal",
                "vraynormals",
            ],
            GuideKind::Depth => &["z", "depth", "denoisingdepth", "zdepth", "vrayzdepth", "dd"],
        }
    }
}

/// Which guides to use (`--guides`, `--guide`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GuideRequest {
    /// `None`: every guide found by name (`--guides auto`, the default);
    /// `Some(kinds)`: these only, each of which must be found (`--guides
    /// none` is the empty list).
    pub kinds: Option<Vec<GuideKind>>,
    /// Layers (depth: channels) named for a kind (`--guide KIND=NAME`).
    pub named: Vec<(GuideKind, String)>,
}

impl GuideRequest {
    /// Parse `--guides` (`auto`, `none` or a comma list of kinds) and the
    /// `--guide KIND=NAME`s.
    pub fn parse(guides: &str, named: &[String]) -> Result<Self> {
        let kinds = match guides.trim() {
            "auto" => None,
            "none" => Some(Vec::new()),
            list => Some(
                list.split(',')
                    .map(GuideKind::parse)
                    .collect::<Result<Vec<_>>>()?,
            ),
        };
        let named = named
            .iter()
            .map(|n| {
                let (k, v) = n.split_once('=').ok_or_else(|| {
                    Error::Config(format!(
                        "--guide {n:?}: expected KIND=NAME, e.g. emission=ViewLayer.Emit"
                    ))
                })?;
                Ok((GuideKind::parse(k)?, v.trim().to_string()))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(GuideRequest { kinds, named })
    }

    /// Whether guides are off.
    pub fn none(&self) -> bool {
        self.kinds.as_ref().is_some_and(|k| k.is_empty()) && self.named.is_empty()
    }
}

/// The guide channels found, by name.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FoundGuides {
    /// Emission, one per colour channel of the beauty, in its order.
    pub emission: Option<Vec<String>>,
    /// Albedo R, G, B.
    pub albedo: Option<[String; 3]>,
    /// Normal X, Y, Z.
    pub normal: Option<[String; 3]>,
    /// Depth.
    pub depth: Option<String>,
}

impl FoundGuides {
    /// Whether none was found.
    pub fn is_empty(&self) -> bool {
        self.emission.is_none()
            && self.albedo.is_none()
            && self.normal.is_none()
            && self.depth.is_none()
    }

    /// Whether a surface guide (albedo, normal, depth) was found.
    pub fn surface(&self) -> bool {
        self.albedo.is_some() || self.normal.is_some() || self.depth.is_some()
    }

    /// Every channel found.
    pub fn channels(&self) -> Vec<String> {
        let mut v: Vec<String> = Vec::new();
        v.extend(self.emission.iter().flatten().cloned());
        v.extend(self.albedo.iter().flatten().cloned());
        v.extend(self.normal.iter().flatten().cloned());
        v.extend(self.depth.iter().cloned());
        v
    }

    /// Each kind found with its channels, by the kind's name.
    pub fn by_kind(&self) -> std::collections::BTreeMap<String, Vec<String>> {
        let kinds = [
            (GuideKind::Emission, self.emission.clone()),
            (GuideKind::Albedo, self.albedo.clone().map(Vec::from)),
            (GuideKind::Normal, self.normal.clone().map(Vec::from)),
            (GuideKind::Depth, self.depth.clone().map(|d| vec![d])),
        ];
        (kinds.into_iter())
            .filter_map(|(k, ch)| ch.map(|ch| (k.name().to_string(), ch)))
            .collect()
    }

    /// What was found, in words (`emission (emission.R, ...), depth (Z)`;
    /// `none` for nothing).
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        let mut add = |k: GuideKind, ch: Vec<String>| {
            if !ch.is_empty() {
                parts.push(format!("{} ({})", k.name(), ch.join(", ")));
            }
        };
        add(
            GuideKind::Emission,
            self.emission.clone().unwrap_or_default(),
        );
        add(
            GuideKind::Albedo,
            self.albedo.clone().map(Vec::from).unwrap_or_default(),
        );
        add(
            GuideKind::Normal,
            self.normal.clone().map(Vec::from).unwrap_or_default(),
        );
        add(GuideKind::Depth, self.depth.clone().into_iter().collect());
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join(", ")
        }
    }

    /// Where these channels are in a strip row of `input`, read where
    /// `carried` has them as they are read, else after the filtered ones
    /// ([`ExrInput::read_beside`]).
    pub fn attach(
        &self,
        input: &mut ExrInput,
        carried: &[(String, ChannelRule)],
    ) -> Result<GuideLayout> {
        let names = self.channels();
        let placed = input.read_beside(&names, carried)?;
        let at = |name: &String| {
            names
                .iter()
                .position(|n| n == name)
                .map_or(0, |i| placed[i])
        };
        Ok(GuideLayout {
            emission: self.emission.as_ref().map(|e| e.iter().map(at).collect()),
            albedo: self.albedo.as_ref().map(|a| a.each_ref().map(at)),
            normal: self.normal.as_ref().map(|n| n.each_ref().map(at)),
            depth: self.depth.as_ref().map(at),
        })
    }
}

/// A layer's name as the tables hold it: its last component, lower case,
/// without spaces, `_` or `-`.
fn normalised(layer: &str) -> String {
    let last = layer.rsplit('.').next().unwrap_or(layer);
    last.chars()
        .filter(|c| !matches!(c, ' ' | '_' | '-'))
        .flat_map(char::to_lowercase)
        .collect()
}

/// The channel of `layer` whose last component is one of `comps` (any case).
fn component(names: &[String], layer: &str, comps: &[&str]) -> Option<String> {
    comps.iter().find_map(|c| {
        names
            .iter()
            .find(|n| {
                n.rsplit_once('.')
                    .is_some_and(|(l, k)| l == layer && k.eq_ignore_ascii_case(c))
            })
            .cloned()
    })
}

/// What holds `layer` (a layer's name, no trailing '.'): its prefix up to
/// and with its last '.', "" at the top (as [`scope`] of the prefix).
fn scope_of(layer: &str) -> &str {
    layer
        .rsplit_once('.')
        .map_or("", |(s, _)| &layer[..s.len() + 1])
}

/// The layers of `names` (all the file's `all` but the beauty's) a guide
/// may come from: a pass beside another beauty is that render's (another
/// view layer's), not this one's; the beauty's own passes come first.
fn guide_layers(all: &[String], names: &[String], beauty: &[String]) -> Vec<String> {
    let own = beauty.first().and_then(|b| b.rsplit_once('.'));
    let own = own.map_or("", |(l, _)| scope_of(l));
    let others: Vec<String> = (beauty_layers(all).iter())
        .filter(|l| !beauty.iter().any(|b| b.starts_with(l.as_str())))
        .map(|l| scope(l).to_string())
        .collect();
    let mut layers = layers(names);
    layers.retain(|l| scope_of(l) == own || !others.iter().any(|o| o == scope_of(l)));
    layers.sort_by_key(|l| scope_of(l) != own);
    layers
}

/// The layers of `names` (every prefix before a last `.`), in file order.
fn layers(names: &[String]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for n in names {
        if let Some((l, _)) = n.rsplit_once('.') {
            if !out.iter().any(|o| o == l) {
                out.push(l.to_string());
            }
        }
    }
    out
}

/// Find the guides of `header` (of `path`, for messages) beside the
/// beauty's colour channels `beauty` (never guides themselves), as `req`
/// asks, among the channels of the run's view (`scope`) as it sees them
/// ([`ViewScope::seen_names`]). A kind asked for by name (`--guides
/// emission`, `--guide`) that is not there, or not whole, is an error naming
/// what the file has.
pub fn find_guides(
    path: &Path,
    header: &Header,
    beauty: &[String],
    req: &GuideRequest,
    scope: &ViewScope,
) -> Result<FoundGuides> {
    let seen = scope.seen_names(&super::reader::channel_names(header));
    let as_seen =
        |n: &String| (seen.iter().find(|(_, a)| a == n)).map_or(n.clone(), |(s, _)| s.clone());
    let as_named = |n: String| (seen.iter().find(|(s, _)| *s == n)).map_or(n, |(_, a)| a.clone());
    let names: Vec<String> = seen.iter().map(|(s, _)| s.clone()).collect();
    let beauty: Vec<String> = beauty.iter().map(as_seen).collect();
    let found = guides_among(path, &names, &beauty, req)?;
    Ok(FoundGuides {
        emission: found
            .emission
            .map(|e| e.into_iter().map(as_named).collect()),
        albedo: found.albedo.map(|c| c.map(as_named)),
        normal: found.normal.map(|c| c.map(as_named)),
        depth: found.depth.map(as_named),
    })
}

/// [`find_guides`] among the channel names `all`.
fn guides_among(
    path: &Path,
    all: &[String],
    beauty: &[String],
    req: &GuideRequest,
) -> Result<FoundGuides> {
    let names: Vec<String> = all
        .iter()
        .filter(|n| !beauty.contains(n))
        .cloned()
        .collect();
    let mut found = FoundGuides::default();
    if req.none() {
        return Ok(found);
    }
    let refuse = |k: GuideKind, why: String| Error::Channels {
        path: path.to_path_buf(),
        reason: format!(
            "the {} guide: {why} ({}; name it with --guide {}=LAYER, or give --guides none)",
            k.name(),
            match names.is_empty() {
                true => "the file has no channels besides the image's".to_string(),
                false => format!("the file has: {}", names.join(", ")),
            },
            k.name()
        ),
    };
    let all_layers = guide_layers(all, &names, beauty);
    for kind in GuideKind::ALL {
        let named = req.named.iter().rev().find(|(k, _)| *k == kind);
        let wanted = req.kinds.as_ref().is_none_or(|k| k.contains(&kind)) || named.is_some();
        if !wanted {
            continue;
        }
        let candidates: Vec<String> = match named {
            Some((_, n)) => vec![n.trim_end_matches('.').to_string()],
            None => kind
                .layers()
                .iter()
                .flat_map(|want| all_layers.iter().filter(move |l| normalised(l) == *want))
                .cloned()
                .collect(),
        };
        let mut pick = |layer: &String| -> Option<()> {
            match kind {
                GuideKind::Emission => {
                    let comps: Option<Vec<String>> = beauty
                        .iter()
                        .map(|b| {
                            let c = b.rsplit('.').next().unwrap_or(b);
                            component(&names, layer, &[c])
                        })
                        .collect();
                    found.emission = Some(comps?);
                }
                GuideKind::Albedo => {
                    let [r, g, b] = ["R", "G", "B"].map(|c| component(&names, layer, &[c]));
                    found.albedo = Some([r?, g?, b?]);
                }
                GuideKind::Normal => {
                    let [x, y, z] =
                        [["X", "R"], ["Y", "G"], ["Z", "B"]].map(|c| component(&names, layer, &c));
                    found.normal = Some([x?, y?, z?]);
                }
                GuideKind::Depth => {
                    found.depth = Some(component(&names, layer, &["Z", "Y", "R", "V", "depth"])?);
                }
            }
            Some(())
        };
        let mut ok = candidates.iter().any(|l| pick(l).is_some());
        if !ok && kind == GuideKind::Depth {
            // Depth is often a channel of its own: `Z`, `depth`.
            let bare = match named {
                Some((_, n)) => names.iter().find(|c| *c == n).cloned(),
                None => names
                    .iter()
                    .find(|c| matches!(c.as_str(), "Z" | "z" | "depth" | "Depth"))
                    .cloned(),
            };
            if let Some(c) = bare {
                found.depth = Some(c);
                ok = true;
            }
        }
        let asked = named.is_some() || req.kinds.is_some();
        if !ok && asked {
            let why = match named {
                Some((_, n)) => format!("no layer or channel {n:?} with the channels it needs"),
                None => "none found by the names renderers give it".into(),
            };
            return Err(refuse(kind, why));
        }
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn found(names: &[&str], beauty: &[&str], req: &GuideRequest) -> Result<FoundGuides> {
        let all: Vec<String> = names.iter().map(|s| s.to_string()).collect();
        let beauty: Vec<String> = beauty.iter().map(|s| s.to_string()).collect();
        guides_among(Path::new("x.exr"), &all, &beauty, req)
    }

    /// Blender's view layers: each `Combined` beside its own passes. The
    /// beauty's passes are taken, never another view layer's.
    #[test]
    fn a_view_layers_passes_are_its_own() {
        let rgb = |l: &str| ["R", "G", "B"].map(|c| format!("{l}.{c}"));
        let mut names: Vec<String> = rgb("Second.Combined").to_vec();
        names.push("Second.Depth.Z".into());
        names.extend(rgb("ViewLayer.Combined"));
        names.extend(rgb("ViewLayer.Emit"));
        names.push("ViewLayer.Depth.Z".into());
        let all: Vec<&str> = names.iter().map(String::as_str).collect();
        let auto = GuideRequest::default();
        let guides = |layer: &str| {
            let beauty = rgb(layer);
            found(&all, &beauty.each_ref().map(String::as_str), &auto).unwrap()
        };
        let g = guides("ViewLayer.Combined");
        assert_eq!(g.emission.unwrap(), rgb("ViewLayer.Emit"));
        assert_eq!(g.depth.unwrap(), "ViewLayer.Depth.Z");
        let g = guides("Second.Combined");
        assert!(g.emission.is_none(), "{:?}", g.emission);
        assert_eq!(g.depth.unwrap(), "Second.Depth.Z");
    }

    #[test]
    fn renderers_names_are_found() {
        let auto = GuideRequest::default();
        let g = found(
            &[
                "B",
                "G",
                "R",
                "emission.B",
                "emission.G",
                "emission.R",
                "albedo.B",
                "albedo.G",
                "albedo.R",
                "N.X",
                "N.Y",
                "N.Z",
                "Z",
            ],
            &["R", "G", "B"],
            &auto,
        )
        .unwrap();
        assert_eq!(
            g.emission.unwrap(),
            vec!["emission.R", "emission.G", "emission.B"]
        );
        assert_eq!(g.albedo.unwrap(), ["albedo.R", "albedo.G", "albedo.B"]);
        assert_eq!(g.normal.unwrap(), ["N.X", "N.Y", "N.Z"]);
        assert_eq!(g.depth.unwrap(), "Z");
        // Cycles' view-layer passes.
        let g = found(
            &[
                "ViewLayer.Combined.R",
                "ViewLayer.Combined.G",
                "ViewLayer.Combined.B",
                "ViewLayer.Emit.R",
                "ViewLayer.Emit.G",
                "ViewLayer.Emit.B",
                "ViewLayer.Denoising Normal.X",
                "ViewLayer.Denoising Normal.Y",
                "ViewLayer.Denoising Normal.Z",
                "ViewLayer.Depth.Z",
            ],
            &[
                "ViewLayer.Combined.R",
                "ViewLayer.Combined.G",
                "ViewLayer.Combined.B",
            ],
            &auto,
        )
        .unwrap();
        assert_eq!(
            g.emission.unwrap(),
            vec!["ViewLayer.Emit.R", "ViewLayer.Emit.G", "ViewLayer.Emit.B"]
        );
        assert_eq!(g.normal.unwrap()[0], "ViewLayer.Denoising Normal.X");
        assert_eq!(g.depth.unwrap(), "ViewLayer.Depth.Z");
        assert!(g.albedo.is_none());
    }

    #[test]
    fn asked_for_and_missing_is_an_error_none_is_nothing() {
        let names = ["R", "G", "B", "N.X", "N.Y"];
        let req = GuideRequest::parse("normal", &[]).unwrap();
        let e = found(&names, &["R", "G", "B"], &req)
            .unwrap_err()
            .to_string();
        assert!(e.contains("normal guide") && e.contains("N.X"), "{e}");
        assert!(found(&names, &["R", "G", "B"], &GuideRequest::default())
            .unwrap()
            .is_empty());
        let none = GuideRequest::parse("none", &[]).unwrap();
        let all = ["R", "G", "B", "emission.R", "emission.G", "emission.B"];
        assert!(found(&all, &["R", "G", "B"], &none).unwrap().is_empty());
        let named = GuideRequest::parse("auto", &["emission=glow".into()]).unwrap();
        let g = found(
            &["R", "G", "B", "glow.R", "glow.G", "glow.B"],
            &["R", "G", "B"],
            &named,
        )
        .unwrap();
        assert_eq!(g.emission.unwrap()[2], "glow.B");
        assert!(GuideRequest::parse("emission,light", &[]).is_err());
    }
}
