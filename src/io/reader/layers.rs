//! Which channels of an EXR are read: views, layers, the beauty's colour
//! channels and their luminance weights, and what is left out.

use super::{channel_names, unsupported, Error, Header, Path, Selected};
use crate::error::Result;
use crate::filter::channels::ViewScope;

/// The views of a multi-view file (`multiView`), the default first; empty
/// for a file without views.
pub(crate) fn views(header: &Header) -> Vec<String> {
    header
        .own_attributes
        .multi_view_names
        .iter()
        .flatten()
        .map(|t| t.to_string())
        .collect()
}

/// Which view of a multi-view file to filter (`--view`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ViewSelect {
    /// One view, by name.
    Name(String),
    /// Every view, each filtered as its own image, into one output.
    All,
}

impl ViewSelect {
    /// Parse `--view`: `all`, or a view's name.
    pub fn parse(s: &str) -> Self {
        match s {
            "all" => ViewSelect::All,
            name => ViewSelect::Name(name.to_string()),
        }
    }
}

/// The view a run of `header`'s part writes: `view` by name, or the
/// default; an unknown name is refused with the file's views.
pub fn view_scope(
    path: &Path,
    header: &Header,
    view: Option<&str>,
    exclusive: bool,
) -> Result<ViewScope> {
    let views = views(header);
    let this = match view {
        None => 0,
        Some(v) => views.iter().position(|n| n == v).ok_or_else(|| {
            Error::Config(format!(
                "{}: --view {v:?}: {}",
                path.display(),
                if views.is_empty() {
                    "the file has no views (no multiView attribute)".to_string()
                } else {
                    format!("its views are {}", views.join(", "))
                }
            ))
        })?,
    };
    Ok(ViewScope {
        views,
        this,
        exclusive,
    })
}

pub(crate) fn base_name(name: &str) -> &str {
    name.rsplit('.').next().unwrap_or(name)
}

/// Layer names (last dot-component, any case) that renderers give the beauty
/// image: Blender's `ViewLayer.Combined`, `beauty`/`RGBA` (Arnold, Houdini),
/// RenderMan's `Ci`, and the generic ones.
pub(super) const BEAUTY_LAYERS: &[&str] = &[
    "combined",
    "beauty",
    "rgba",
    "rgb",
    "ci",
    "color",
    "colour",
    "composite",
    "image",
];

/// The colour channels of `layer` ("" or ending in '.'): R, G, B (+ A), or
/// Y (+ A); `None` when it has neither.
pub(super) fn layer_colour(names: &[String], layer: &str) -> Option<Vec<&'static str>> {
    let has = |c: &str| names.iter().any(|n| *n == format!("{layer}{c}"));
    // In a named layer, Y beside an X is a vector's component (normals
    // `N.X N.Y N.Z`, motion `vel.X vel.Y`), not a luminance.
    let vector = !layer.is_empty() && has("X");
    let mut wanted = if has("R") && has("G") && has("B") {
        vec!["R", "G", "B"]
    } else if has("Y") && !vector {
        vec!["Y"]
    } else {
        return None;
    };
    if has("A") {
        wanted.push("A");
    }
    Some(wanted)
}

/// Whether `layer` (a prefix: "" or ending in '.') has a beauty's name.
fn beauty_named(layer: &str) -> bool {
    let last = layer.trim_end_matches('.').rsplit('.').next().unwrap_or("");
    BEAUTY_LAYERS.iter().any(|b| last.eq_ignore_ascii_case(b))
}

/// What holds `layer` (a prefix: "" or ending in '.'), its render's passes
/// beside it: `ViewLayer.` for `ViewLayer.Combined.`, "" at the top.
pub(crate) fn scope(layer: &str) -> &str {
    let l = layer.trim_end_matches('.');
    l.rsplit_once('.')
        .map_or("", |(s, _)| &layer[..s.len() + 1])
}

/// The layers of `names` with colour and a beauty's name (prefixes ending
/// in '.'), in file order.
pub(crate) fn beauty_layers(names: &[String]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for n in names {
        if let Some((l, _)) = n.rsplit_once('.') {
            let l = format!("{l}.");
            if !out.contains(&l) && beauty_named(&l) && layer_colour(names, &l).is_some() {
                out.push(l);
            }
        }
    }
    out
}

/// The layer to filter among those with colour (`coloured`: each layer's
/// prefix and colour channels; `names`: every channel): `layer` when given,
/// else the unlayered channels, a beauty layer or the only one
/// ([`choose_channels`]). Of several beauty layers, the render's own: the
/// one beside the most of its render's passes. Blender writes the
/// compositor's `Composite.Combined` beside `ViewLayer.Combined` and its
/// passes, and one `Combined` per view layer: the composite is made after
/// the render, and a view layer without passes is rarely the picture.
fn choose_layer<'a>(
    path: &Path,
    names: &[String],
    coloured: &'a [(&'a String, Vec<&'a str>)],
    layer: Option<&str>,
) -> Result<&'a (&'a String, Vec<&'a str>)> {
    let shown = |l: &str| {
        if l.is_empty() {
            "(unlayered)".to_string()
        } else {
            l.trim_end_matches('.').to_string()
        }
    };
    let list = || {
        coloured
            .iter()
            .map(|(l, _)| shown(l))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Some(want) = layer {
        let want = want.trim_end_matches('.');
        let key = if want.is_empty() {
            String::new()
        } else {
            format!("{want}.")
        };
        match coloured.iter().find(|(l, _)| **l == key) {
            Some(c) => Ok(c),
            None => Err(Error::Config(format!(
                "{}: --layer {want:?} has no R,G,B or Y channels (layers with colour: {})",
                path.display(),
                list()
            ))),
        }
    } else {
        let passes = |l: &str| {
            let s = scope(l);
            (names.iter())
                .filter(|n| n.starts_with(s) && !n.starts_with(l))
                .count()
        };
        // The first of those beside the most passes.
        let beauty = (coloured.iter())
            .filter(|(l, _)| beauty_named(l))
            .rev()
            .max_by_key(|(l, _)| passes(l));
        match coloured.iter().find(|(l, _)| l.is_empty()).or(beauty) {
            Some(c) => Ok(c),
            None => match coloured {
                [only] => Ok(only),
                _ => Err(Error::Config(format!(
                        "{}: several layers have colour and none is named as the beauty ({}): choose one with --layer NAME",
                        path.display(),
                    list()
                ))),
            },
        }
    }
}

/// The channels to filter: R, G, B (+ A), or Y (+ A) of one layer, and the
/// rest (dropped, and listed). The layer is `layer` when given; otherwise the
/// unlayered channels, else a layer with a beauty name ([`BEAUTY_LAYERS`]),
/// else the only layer with colour; several candidates and no beauty is an
/// error that lists them (filtering an AOV by mistake would be silent).
///
/// In a multi-view file the channels are chosen among the run's view's, as
/// it sees them ([`ViewScope::seen_names`]): `--layer ViewLayer.Combined`
/// (or `ViewLayer.Combined.left`) is `ViewLayer.Combined.left.R...` in the
/// left view's run and `ViewLayer.Combined.right.R...` in the right's.
pub(crate) fn choose_channels(
    path: &Path,
    header: &Header,
    layer: Option<&str>,
    scope: &ViewScope,
) -> Result<(Vec<Selected>, Vec<String>)> {
    let all = channel_names(header);
    let seen = scope.seen_names(&all);
    // A layer named with the run's view is the layer the view sees.
    let layer = match layer.map(|l| l.trim_end_matches('.')) {
        Some(l) => Some(match l.rsplit_once('.') {
            Some((rest, v)) if scope.name() == Some(v) => rest,
            Some((rest, v)) if scope.views.iter().any(|o| o == v) => {
                return Err(Error::Config(format!(
                    "{}: --layer {l:?} is of the view {v:?}, not of this run's {:?}: --view {v} --layer {rest:?} filters it",
                    path.display(),
                    scope.name().unwrap_or_default()
                )));
            }
            _ => l,
        }),
        None => None,
    };
    let (chosen, _) = choose_among(path, seen.iter().map(|(s, _)| s.clone()).collect(), layer)?;
    let selected: Vec<Selected> = (chosen.into_iter())
        .map(|c| {
            let name = (seen.iter())
                .find(|(s, _)| *s == c.name)
                .map_or(c.name, |(_, n)| n.clone());
            Selected {
                index: all.iter().position(|x| *x == name).unwrap_or(0),
                name,
            }
        })
        .collect();
    let dropped = (all.iter())
        .filter(|n| !selected.iter().any(|s| &s.name == *n))
        .cloned()
        .collect();
    Ok((selected, dropped))
}

/// [`choose_channels`] among the channel names `names`, in file order.
fn choose_among(
    path: &Path,
    names: Vec<String>,
    layer: Option<&str>,
) -> Result<(Vec<Selected>, Vec<String>)> {
    let mut layers: Vec<String> = vec![String::new()];
    for n in &names {
        if let Some((l, _)) = n.rsplit_once('.') {
            let l = format!("{l}.");
            if !layers.contains(&l) {
                layers.push(l);
            }
        }
    }
    let coloured: Vec<(&String, Vec<&str>)> = layers
        .iter()
        .filter_map(|l| layer_colour(&names, l).map(|c| (l, c)))
        .collect();
    if coloured.is_empty() {
        return Err(unsupported(
            path,
            format!(
                "no colour channels to filter (need R,G,B or Y; the file has: {})",
                names.join(", ")
            ),
        ));
    }
    let chosen = choose_layer(path, &names, &coloured, layer)?;
    let (layer, wanted) = chosen;
    if wanted[0] == "Y" {
        let has = |c: &str| names.iter().any(|n| *n == format!("{layer}{c}"));
        if has("RY") && has("BY") {
            return Err(unsupported(
                path,
                "luminance/chroma (Y, RY, BY) images are not supported",
            ));
        }
    }
    let selected: Vec<Selected> = wanted
        .iter()
        .map(|c| {
            let name = format!("{layer}{c}");
            Selected {
                index: names.iter().position(|x| *x == name).unwrap_or(0),
                name,
            }
        })
        .collect();
    let dropped = names
        .iter()
        .filter(|n| !selected.iter().any(|s| &s.name == *n))
        .cloned()
        .collect();
    Ok((selected, dropped))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The beauty chosen among `names` (written in this order).
    fn beauty(names: &[String]) -> String {
        let (selected, _) = choose_among(Path::new("x.exr"), names.to_vec(), None).unwrap();
        selected[0]
            .name
            .rsplit_once('.')
            .map_or("", |(l, _)| l)
            .to_string()
    }

    #[test]
    fn of_several_beauty_layers_the_render_beside_its_passes_is_filtered() {
        let rgb = |l: &str| ["A", "B", "G", "R"].map(|c| format!("{l}.{c}")).to_vec();
        // Blender with the compositor on: the composite is made after the
        // render; the render is the view layer beside its passes.
        let mut names = rgb("Composite.Combined");
        names.extend(rgb("ViewLayer.Combined"));
        names.extend(rgb("ViewLayer.Emit")[1..].to_vec());
        names.push("ViewLayer.Depth.Z".into());
        assert_eq!(beauty(&names), "ViewLayer.Combined");
        // Two view layers: the one with the passes.
        let mut names = rgb("Second.Combined");
        names.push("Second.Depth.Z".into());
        names.extend(rgb("ViewLayer.Combined"));
        names.extend(rgb("ViewLayer.Emit")[1..].to_vec());
        assert_eq!(beauty(&names), "ViewLayer.Combined");
        // As many passes each: the first in the file, as before.
        let mut names = rgb("A.Combined");
        names.extend(rgb("B.Combined"));
        assert_eq!(beauty(&names), "A.Combined");
        // The unlayered channels first, whatever the layers.
        let mut names = rgb("ViewLayer.Combined");
        names.extend(["B", "G", "R"].map(String::from));
        assert_eq!(beauty(&names), "");
    }
}
