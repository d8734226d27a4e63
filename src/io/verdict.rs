//! The input decides: how a render is filtered when the user does not say.
//!
//! * **Super-sampling** `S`: `--supersample S`, else the header attribute
//!   [`SUPERSAMPLE_ATTRIBUTES`] (an integer 1..=8 that the renderer or
//!   `epfilt synth` writes into a super-sampled render), else 1: an image is
//!   never reduced unless asked (as Radiance's `pfilt`).
//! * **Method**: `--method`, else ep-box where the file holds per-pixel
//!   variance at S = 1 (§5.1: the paper's filter for renders with variance),
//!   else ep-gauss (§5.2).
//!
//! `epfilt filter` prints the verdict in its summary and report, `epfilt
//! info` before any filtering.

use std::path::Path;

use exr::meta::attribute::AttributeValue;
use exr::meta::header::Header;

use crate::error::{Error, Result};
use crate::filter::Method;
use crate::io::{find_stats, StatsChannels, StatsRequest};

/// Header attributes that say a file is super-sampled, and by how much
/// (the first is what `epfilt synth` writes).
pub const SUPERSAMPLE_ATTRIBUTES: [&str; 2] = ["epfiltSupersample", "epfilt_supersample"];

/// The super-sampling a header's attribute states, with the attribute's
/// name; an attribute that is not an integer 1..=8 is an error naming it.
pub fn supersample_attribute(path: &Path, header: &Header) -> Result<Option<(usize, String)>> {
    let attrs = header
        .own_attributes
        .other
        .iter()
        .chain(header.shared_attributes.other.iter());
    for (k, v) in attrs {
        let key = k.to_string();
        if !SUPERSAMPLE_ATTRIBUTES.contains(&key.as_str()) {
            continue;
        }
        let n = match v {
            AttributeValue::I32(i) => Some(*i as f64),
            AttributeValue::F32(f) => Some(*f as f64),
            AttributeValue::F64(f) => Some(*f),
            AttributeValue::Text(t) => t.to_string().trim().parse::<f64>().ok(),
            _ => None,
        };
        return match n {
            Some(n) if n.fract() == 0.0 && (1.0..=8.0).contains(&n) => {
                Ok(Some((n as usize, key)))
            }
            _ => Err(Error::Config(format!(
                "{}: the header attribute {key} should be the super-sampling factor, an integer 1..=8, not {v:?}; give --supersample to override it",
                path.display()
            ))),
        };
    }
    Ok(None)
}

/// How a file is filtered, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    /// The super-sampling factor.
    pub supersample: usize,
    /// Where it came from, in words.
    pub supersample_from: String,
    /// The method.
    pub method: Method,
    /// Why, in words.
    pub method_from: String,
    /// The statistics channels found (whatever the method).
    pub stats: Option<StatsChannels>,
}

impl Verdict {
    /// One line: `ep-box at S = 1 (S: ...; method: ...)`.
    pub fn line(&self) -> String {
        format!(
            "{} at S = {} (S: {}; method: {})",
            self.method.name(),
            self.supersample,
            self.supersample_from,
            self.method_from
        )
    }
}

/// Decide S and the method for the file `path` with header `header`, given
/// what the user said (`method`, `supersample`; `None`: not given).
pub fn verdict(
    path: &Path,
    header: &Header,
    stats: &StatsRequest,
    method: Option<Method>,
    supersample: Option<usize>,
) -> Result<Verdict> {
    let (s, s_from) = match supersample {
        Some(s) => (s, "--supersample".to_string()),
        None => match supersample_attribute(path, header)? {
            Some((s, key)) => (s, format!("header attribute {key}")),
            None => (
                1,
                format!(
                    "pixel resolution (no --supersample, no {} attribute)",
                    SUPERSAMPLE_ATTRIBUTES[0]
                ),
            ),
        },
    };
    let found = find_stats(path, header, stats).ok();
    let (m, m_from) = match method {
        Some(m) => (m, "--method".to_string()),
        None => match (&found, s) {
            (Some(f), 1) => (
                Method::EpBox,
                format!("per-pixel variance found ({})", f.variance.join(", ")),
            ),
            (Some(_), _) => (
                Method::EpGauss,
                format!("variance found, but ep-box filters at S = 1, not {s}"),
            ),
            (None, _) => (Method::EpGauss, "no per-pixel variance found".to_string()),
        },
    };
    Ok(Verdict {
        supersample: s,
        supersample_from: s_from,
        method: m,
        method_from: m_from,
        stats: found,
    })
}
