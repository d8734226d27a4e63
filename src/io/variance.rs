//! Finding a render's per-pixel statistics: the variance channels and the
//! sample count, under the names real renderers give them.
//!
//! | renderer | variance | kind | sample count |
//! |---|---|---|---|
//! | `epfilt synth --spp N --variance` | `variance.R/G/B` | sample | attribute `spp` |
//! | Arnold (noice set-up) | layer `variance` (or `RGBA_variance`) `.R/G/B` | sample | `--spp` |
//! | MoonRay variance AOV | one channel, e.g. `beauty_var` (luminance) | sample | `--spp` |
//! | RenderMan denoise AOVs | `mse.R/G/B` (error of the mean) | mean | channel `sampleCount` |
//! | Cycles (2.8–2.9x denoising data) | `<layer>.Denoising Variance.R/G/B` | mean | attribute `cycles.<layer>.samples` |
//! | Mitsuba 3 `moment` integrator | `m2_<name>.Y` with `<name>.Y` | moment | `--spp` |
//!
//! "sample" is the variance of single samples, "mean" the variance of the
//! pixel mean, "moment" the raw second moment; `--variance-kind` overrides the
//! guess, `--variance-channel` the choice, `--spp` / `--spp-channel` the count.

use std::path::Path;

use exr::meta::attribute::AttributeValue;
use exr::meta::header::Header;

use crate::error::{Error, Result};
use crate::filter::channels::ChannelRule;
use crate::filter::ep_box::{Spp, StatsLayout, VarianceKind};
use crate::io::ExrInput;

/// What the user asked for (every field optional).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StatsRequest {
    /// A channel (luminance variance) or a layer with `.R/.G/.B` (or `.Y`).
    pub variance_channel: Option<String>,
    /// Override what the variance channels hold.
    pub kind: Option<VarianceKind>,
    /// Samples per pixel, the same for every pixel.
    pub spp: Option<u32>,
    /// A channel holding each pixel's sample count.
    pub spp_channel: Option<String>,
}

/// Where the sample count comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum SppFrom {
    /// One count for the image (flag or header attribute, named).
    Fixed(f64, String),
    /// Per pixel, from this channel.
    Channel(String),
}

/// The statistics channels found.
#[derive(Clone, Debug, PartialEq)]
pub struct StatsChannels {
    /// One luminance channel, or R, G, B.
    pub variance: Vec<String>,
    /// What they hold.
    pub kind: VarianceKind,
    /// With `moment`: the mean luminance channel the moment goes with.
    pub mean_y: Option<String>,
    /// The sample count.
    pub spp: SppFrom,
}

/// A candidate group of variance channels.
#[derive(Clone, Debug)]
struct Candidate {
    label: String,
    channels: Vec<String>,
    kind: VarianceKind,
    mean_y: Option<String>,
    /// 0: a name renderers use for the main image's variance; 1: another
    /// variance-like name (an AOV's own, say).
    tier: u8,
}

fn kind_of(label: &str) -> Option<(VarianceKind, u8)> {
    let l = label.to_ascii_lowercase();
    let last = l.rsplit('.').next().unwrap_or(&l).to_string();
    match last.as_str() {
        "variance" | "var" | "rgba_variance" | "beauty_variance" | "beauty_var" | "ci_var" => {
            Some((VarianceKind::Sample, 0))
        }
        "mse" => Some((VarianceKind::OfMean, 0)),
        "denoising variance" => Some((VarianceKind::OfMean, 0)),
        _ if last.ends_with("_variance") || last.ends_with("_var") => {
            Some((VarianceKind::Sample, 1))
        }
        _ if last.ends_with("_mse") => Some((VarianceKind::OfMean, 1)),
        _ => None,
    }
}

/// The variance channels of layer `layer` (no trailing dot; "" for
/// unlayered): its `Y` when it has one (the variance of the samples'
/// luminance itself; from R, G, B it can only be bounded), else R, G, B.
fn colour_group(names: &[String], layer: &str) -> Option<Vec<String>> {
    let full = |c: &str| {
        if layer.is_empty() {
            c.to_string()
        } else {
            format!("{layer}.{c}")
        }
    };
    let has = |n: &str| names.iter().any(|x| x == n);
    for y in ["Y", "y"] {
        if has(&full(y)) {
            return Some(vec![full(y)]);
        }
    }
    for set in [["R", "G", "B"], ["r", "g", "b"]] {
        let v: Vec<String> = set.iter().map(|c| full(c)).collect();
        if v.iter().all(|n| has(n)) {
            return Some(v);
        }
    }
    None
}

fn candidates(names: &[String]) -> Vec<Candidate> {
    let mut out: Vec<Candidate> = Vec::new();
    let mut layers: Vec<String> = Vec::new();
    for n in names {
        if let Some((layer, _)) = n.rsplit_once('.') {
            if !layers.iter().any(|l| l == layer) {
                layers.push(layer.to_string());
            }
        }
    }
    for layer in &layers {
        // Mitsuba 3: m2_<name>.Y is E[Y^2] of the samples of <name>.Y.
        if let Some(rest) = layer.strip_prefix("m2_") {
            let (m2, m1) = (format!("{layer}.Y"), format!("{rest}.Y"));
            if names.contains(&m2) && names.contains(&m1) {
                out.push(Candidate {
                    label: layer.clone(),
                    channels: vec![m2],
                    kind: VarianceKind::SecondMoment,
                    mean_y: Some(m1),
                    tier: 0,
                });
            }
            continue;
        }
        if let (Some((kind, tier)), Some(channels)) = (kind_of(layer), colour_group(names, layer)) {
            out.push(Candidate {
                label: layer.clone(),
                channels,
                kind,
                mean_y: None,
                tier,
            });
        }
    }
    // Single channels named as a variance (MoonRay's `beauty_var`).
    for n in names {
        if n.contains('.') {
            continue;
        }
        if let Some((kind, tier)) = kind_of(n) {
            out.push(Candidate {
                label: n.clone(),
                channels: vec![n.clone()],
                kind,
                mean_y: None,
                tier,
            });
        }
    }
    out
}

fn guess_kind(label: &str) -> VarianceKind {
    if label.starts_with("m2_") || label.contains(".m2_") {
        VarianceKind::SecondMoment
    } else {
        kind_of(label).map_or(VarianceKind::Sample, |(k, _)| k)
    }
}

fn number(v: &AttributeValue) -> Option<f64> {
    match v {
        AttributeValue::I32(i) => Some(*i as f64),
        AttributeValue::F32(f) => Some(*f as f64),
        AttributeValue::F64(f) => Some(*f),
        AttributeValue::Text(t) => t.to_string().trim().parse::<f64>().ok(),
        _ => None,
    }
}

fn spp_attribute(header: &Header) -> Option<(f64, String)> {
    let attrs = header
        .own_attributes
        .other
        .iter()
        .chain(header.shared_attributes.other.iter());
    let mut found: Vec<(String, f64)> = attrs
        .filter_map(|(k, v)| {
            let key = k.to_string();
            let l = key.to_ascii_lowercase();
            let named = matches!(
                l.as_str(),
                "spp" | "samples" | "samplecount" | "samples_per_pixel" | "aa_samples"
            ) || l.ends_with(".samples")
                || l.ends_with("_spp")
                || l.ends_with(".spp");
            if !named {
                return None;
            }
            number(v).map(|n| (key, n))
        })
        .collect();
    found.sort_by(|a, b| a.0.cmp(&b.0));
    found.into_iter().next().map(|(k, n)| (n, k))
}

impl StatsChannels {
    /// Where these channels are in a strip's channel list of `input`
    /// (`path` names it in messages): read where `carried` has them as they
    /// are read, else after the filtered ones ([`ExrInput::read_beside`]).
    /// The statistics step of `epfilt filter`, `epfilt plan` and restore.
    pub fn attach(
        &self,
        input: &mut ExrInput,
        path: &Path,
        carried: &[(String, ChannelRule)],
    ) -> Result<StatsLayout> {
        let mut names = self.variance.clone();
        names.extend(self.mean_y.clone());
        if let SppFrom::Channel(c) = &self.spp {
            names.push(c.clone());
        }
        let placed = input.read_beside(&names, carried)?;
        if self.variance.len() == 3 && input.luminance().iter().filter(|&&l| l > 0.0).count() != 3 {
            return Err(Error::Channels {
                path: path.to_path_buf(),
                reason: format!(
                    "three variance channels ({}) need an R, G, B image; name a luminance variance with --variance-channel",
                    self.variance.join(", ")
                ),
            });
        }
        let at = |name: &str| {
            names
                .iter()
                .position(|n| n == name)
                .map_or(0, |i| placed[i])
        };
        Ok(StatsLayout {
            variance: self.variance.iter().map(|v| at(v)).collect(),
            kind: self.kind,
            mean_y: self.mean_y.as_deref().map(at),
            spp: match &self.spp {
                SppFrom::Fixed(n, _) => Spp::Fixed(*n),
                SppFrom::Channel(c) => Spp::Channel(at(c)),
            },
        })
    }

    /// Where the sample count came from, for reports.
    pub fn spp_from(&self) -> String {
        match &self.spp {
            SppFrom::Fixed(n, from) => format!("{n} ({from})"),
            SppFrom::Channel(c) => format!("channel {c}"),
        }
    }
}

/// Find the statistics channels of `header` (of `path`, for messages).
pub fn find_stats(path: &Path, header: &Header, req: &StatsRequest) -> Result<StatsChannels> {
    let names = super::reader::channel_names(header);
    let listing = || names.join(", ");
    let refuse = |m: String| Error::Channels {
        path: path.to_path_buf(),
        reason: m,
    };
    let (variance, mut kind, mean_y) = match &req.variance_channel {
        Some(v) => {
            if names.contains(v) {
                (vec![v.clone()], guess_kind(v), None)
            } else if let Some(g) = colour_group(&names, v) {
                (g, guess_kind(v), None)
            } else {
                return Err(refuse(format!(
                    "no variance channel or layer {v:?} (the file has: {})",
                    listing()
                )));
            }
        }
        None => {
            let all = candidates(&names);
            let best = all.iter().map(|c| c.tier).min();
            let top: Vec<&Candidate> = all.iter().filter(|c| Some(c.tier) == best).collect();
            match top.as_slice() {
                [one] => (one.channels.clone(), one.kind, one.mean_y.clone()),
                [] => {
                    return Err(refuse(format!(
                        "no variance channels found (looked for variance.R/G/B, RGBA_variance, \
                         *_var, mse, Denoising Variance, m2_*.Y; the file has: {}); \
                         name one with --variance-channel",
                        listing()
                    )))
                }
                many => {
                    let labels: Vec<&str> = many.iter().map(|c| c.label.as_str()).collect();
                    return Err(refuse(format!(
                        "several variance layers ({}): choose one with --variance-channel",
                        labels.join(", ")
                    )));
                }
            }
        }
    };
    if let Some(k) = req.kind {
        kind = k;
    }
    if kind == VarianceKind::SecondMoment && variance.len() != 1 {
        return Err(Error::Config(
            "--variance-kind moment needs one luminance moment channel (E[Y^2])".into(),
        ));
    }
    let spp = if let Some(n) = req.spp {
        SppFrom::Fixed(n as f64, "--spp".into())
    } else if let Some(c) = &req.spp_channel {
        if !names.contains(c) {
            return Err(refuse(format!(
                "no sample-count channel {c:?} (the file has: {})",
                listing()
            )));
        }
        SppFrom::Channel(c.clone())
    } else if let Some((n, key)) = spp_attribute(header) {
        SppFrom::Fixed(n, format!("header attribute {key}"))
    } else if let Some(c) = names.iter().find(|n| {
        let l = n.rsplit('.').next().unwrap_or(n).to_ascii_lowercase();
        matches!(
            l.as_str(),
            "samplecount" | "spp" | "sample count" | "debug sample count"
        )
    }) {
        SppFrom::Channel(c.clone())
    } else {
        return Err(refuse(
            "no sample count (no spp/samples header attribute, no sampleCount channel): \
             give --spp N or --spp-channel NAME"
                .into(),
        ));
    };
    if let SppFrom::Fixed(n, from) = &spp {
        if !(n.is_finite() && *n >= 2.0) {
            return Err(refuse(format!(
                "the sample count ({from}) is {n}: the noise test needs at least 2 samples per pixel"
            )));
        }
    }
    Ok(StatsChannels {
        variance,
        kind,
        mean_y,
        spp,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    fn pick(v: &[&str]) -> Option<(Vec<String>, VarianceKind)> {
        let all = candidates(&names(v));
        let best = all.iter().map(|c| c.tier).min();
        let top: Vec<_> = all.iter().filter(|c| Some(c.tier) == best).collect();
        (top.len() == 1).then(|| (top[0].channels.clone(), top[0].kind))
    }

    #[test]
    fn renderers_names_are_found() {
        let s = VarianceKind::Sample;
        assert_eq!(
            pick(&["B", "G", "R", "variance.B", "variance.G", "variance.R"]),
            Some((names(&["variance.R", "variance.G", "variance.B"]), s))
        );
        assert_eq!(
            pick(&[
                "R",
                "G",
                "B",
                "A",
                "RGBA_variance.R",
                "RGBA_variance.G",
                "RGBA_variance.B"
            ])
            .map(|p| p.1),
            Some(s)
        );
        assert_eq!(
            pick(&["R", "G", "B", "beauty_var"]),
            Some((names(&["beauty_var"]), s))
        );
        assert_eq!(
            pick(&["R", "G", "B", "mse.R", "mse.G", "mse.B", "sampleCount"]).map(|p| p.1),
            Some(VarianceKind::OfMean)
        );
        let cycles = [
            "ViewLayer.Combined.R",
            "ViewLayer.Combined.G",
            "ViewLayer.Combined.B",
            "ViewLayer.Denoising Variance.R",
            "ViewLayer.Denoising Variance.G",
            "ViewLayer.Denoising Variance.B",
        ];
        assert_eq!(pick(&cycles).map(|p| p.1), Some(VarianceKind::OfMean));
        assert_eq!(
            pick(&[
                "R",
                "G",
                "B",
                "path.X",
                "path.Y",
                "path.Z",
                "m2_path.X",
                "m2_path.Y",
                "m2_path.Z"
            ]),
            Some((names(&["m2_path.Y"]), VarianceKind::SecondMoment))
        );
        // The beauty's variance wins over an AOV's.
        assert_eq!(
            pick(&[
                "R",
                "G",
                "B",
                "variance.R",
                "variance.G",
                "variance.B",
                "diffuse_variance.R",
                "diffuse_variance.G",
                "diffuse_variance.B"
            ])
            .map(|p| p.0[0].clone()),
            Some("variance.R".into())
        );
        // Two AOV variances and no beauty's: ambiguous.
        assert_eq!(pick(&["R", "G", "B", "diffuse_var", "specular_var"]), None);
        assert_eq!(pick(&["R", "G", "B", "Z"]), None);
    }
}
