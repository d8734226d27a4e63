//! `epfilt plan`: how many samples per pixel a render needs, from a pilot
//! render with variance (§5.1, Eqs. 8–10).
//!
//! One streaming pass over the pilot gives `L_ave` (mean luminance), the mean
//! standard error of the pixel means `S̄` (Eq. 5) and the brightest pixel.
//! Then:
//!
//! * `L_tvis = L_ave / N_MID` (Eq. 9);
//! * `M_t = (s̄ / (D L_tvis))^2` (Eq. 10), `s̄` the mean deviation of single
//!   samples (`S_p sqrt(n)`): the paper's `(4 S̄_{p-16} / (D L_tvis))^2` for its
//!   16-sample pilot, for any pilot count;
//! * `M_t,ceiling = 4 M_t`, the paper's heuristic margin;
//! * Purgathofer's worst case (Eq. 8) for `d = D L_tvis / L_max`, samples
//!   scaled so that the largest radiance `L_max` is 1.

use std::path::Path;

use rayon::iter::{IndexedParallelIterator, ParallelIterator};
use rayon::slice::ParallelSlice;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::filter::ep_box::{self, StatsLayout, VarianceKind};
use crate::filter::luminance::Luminance;
use crate::filter::ValidParams;
use crate::io::{find_stats, ExrInput, PartSelect, StatsRequest};
use crate::pipeline::ledger::CompensatedSum;
use crate::pipeline::Source;

/// The plan (the `--json` keys).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Plan {
    /// Pilot file.
    pub input: String,
    /// Pilot size.
    pub width: usize,
    /// Pilot size.
    pub height: usize,
    /// Mean samples per pixel of the pilot.
    pub pilot_spp: f64,
    /// Mean luminance.
    pub l_ave: f64,
    /// Visibility threshold, Eq. 9.
    pub l_tvis: f64,
    /// `S̄`: mean over pixels of the standard error of the pixel mean.
    pub mean_std_error: f64,
    /// Mean over pixels of the deviation of single samples.
    pub mean_sample_std: f64,
    /// Eq. 10.
    pub m_t: f64,
    /// `4 M_t`.
    pub m_t_ceiling: f64,
    /// Eq. 8 for `d = D L_tvis / L_max`.
    pub m_t_worst_case: f64,
    /// The `d` of Eq. 8.
    pub d_relative: f64,
    /// Largest radiance used for Eq. 8.
    pub l_max: f64,
    /// Allowed interval, in units of L_tvis.
    pub d: f64,
    /// N_MID.
    pub nmid: f64,
    /// Confidence.
    pub confidence: f64,
    /// Fraction of the pilot's pixels that fail the noise test at the pilot's count.
    pub noisy_fraction: f64,
    /// Variance channels used and what they hold.
    pub variance_channels: Vec<String>,
    /// sample, mean or moment.
    pub variance_kind: String,
}

impl Plan {
    /// The human table.
    pub fn table(&self) -> String {
        let rows = [
            (
                "pilot",
                format!(
                    "{} ({}x{}, {} spp)",
                    self.input, self.width, self.height, self.pilot_spp
                ),
            ),
            (
                "variance",
                format!(
                    "{} ({})",
                    self.variance_channels.join(", "),
                    self.variance_kind
                ),
            ),
            (
                "D, N_MID, confidence",
                format!("{}, {}, {}%", self.d, self.nmid, self.confidence * 100.0),
            ),
            ("L_ave", format!("{:.6e}", self.l_ave)),
            (
                "L_tvis = L_ave / N_MID (Eq. 9)",
                format!("{:.6e}", self.l_tvis),
            ),
            (
                "mean standard error S̄",
                format!("{:.6e}", self.mean_std_error),
            ),
            (
                "noisy pixels at the pilot's count",
                format!("{:.2}%", self.noisy_fraction * 100.0),
            ),
            ("M_t (Eq. 10)", format!("{:.0}", self.m_t.ceil())),
            (
                "M_t,ceiling = 4 M_t",
                format!("{:.0}", self.m_t_ceiling.ceil()),
            ),
            (
                "worst case (Eq. 8)",
                format!(
                    "{:.0}  (d = D L_tvis / L_max = {:.3e}, L_max {:.4e})",
                    self.m_t_worst_case, self.d_relative, self.l_max
                ),
            ),
        ];
        let mut s = String::new();
        for (k, v) in rows {
            s.push_str(&format!("{k:<36} {v}\n"));
        }
        s
    }
}

/// Plan from the pilot at `path` with ep-box's settings in `params`.
pub fn plan_file(
    path: &Path,
    part: Option<&PartSelect>,
    layer: Option<&str>,
    req: &StatsRequest,
    params: &ValidParams,
    lmax: Option<f64>,
) -> Result<Plan> {
    let params = &params.ep_box;
    let mut input = ExrInput::open_layer(path, part, layer)?;
    let found = find_stats(path, input.header(), req)?;
    let layout = found.attach(&mut input, path, &[])?;
    let (w, h) = input.size();
    let lum = input.luminance();
    let aux = input.aux_channels();
    let t = ep_box::TFactor::new(params.confidence);
    let kind = found.kind;
    // Pass 1: L_ave (the noise test of pass 2 needs L_tvis).
    let mut job = crate::pipeline::StripLayout::new(
        crate::geometry::Grid {
            in_w: w,
            in_h: h,
            s: 1,
        },
        input.channels(),
        lum.clone(),
    );
    job.aux = aux.clone();
    let l_ave = crate::pipeline::mean_luminance(input.source(), &job, 0, &|_, _| {})?;
    let l_tvis = params
        .ltvis
        .unwrap_or_else(|| ep_box::ltvis(l_ave, params.nmid));
    if !(l_tvis.is_finite() && l_tvis > 0.0) {
        return Err(Error::Value {
            path: path.into(),
            reason: format!("the mean luminance is {l_ave:e}: L_tvis is not positive"),
        });
    }
    let dl = params.d * l_tvis;
    let luminance = Luminance::new(&lum);
    let total = pilot_statistics(&input, path, &layout, &luminance, &t, dl)?;
    if total.tested == 0 {
        return Err(Error::Value {
            path: path.into(),
            reason: "no pixel of the pilot has 2 or more samples: nothing to plan from".into(),
        });
    }
    let tested = total.tested as f64;
    let mean_se = total.se.value() / tested;
    let mean_sd = total.sd.value() / tested;
    let m_t = ep_box::trials_eq10(mean_sd, 1.0, params.d, l_tvis);
    let l_max = lmax.unwrap_or(total.max);
    let d_rel = params.d * l_tvis / l_max;
    let worst = if d_rel >= 1.0 {
        1.0
    } else {
        ep_box::purgathofer_trials(params.confidence, d_rel)
    };
    Ok(Plan {
        input: path.display().to_string(),
        width: w,
        height: h,
        pilot_spp: total.n.value() / tested,
        l_ave,
        l_tvis,
        mean_std_error: mean_se,
        mean_sample_std: mean_sd,
        m_t,
        m_t_ceiling: 4.0 * m_t,
        m_t_worst_case: worst,
        d_relative: d_rel,
        l_max,
        d: params.d,
        nmid: params.nmid,
        confidence: params.confidence,
        noisy_fraction: total.noisy as f64 / total.pixels as f64,
        variance_channels: found.variance.clone(),
        variance_kind: match kind {
            VarianceKind::Sample => "sample",
            VarianceKind::OfMean => "mean",
            VarianceKind::SecondMoment => "moment",
        }
        .into(),
    })
}

/// What the second pass over the pilot sums: standard errors, single-sample
/// deviations and counts of the pixels with 2 samples or more, the brightest
/// pixel, and the pixels the noise test calls noisy.
#[derive(Default, Clone)]
struct Acc {
    se: CompensatedSum,
    sd: CompensatedSum,
    n: CompensatedSum,
    tested: usize,
    max: f64,
    pixels: usize,
    noisy: usize,
}

/// The second pass over the pilot at `path`: each pixel's luminance (`lum`),
/// statistics (`layout`) and noise test (`t S_p > dl`).
fn pilot_statistics(
    input: &ExrInput,
    path: &Path,
    layout: &StatsLayout,
    lum: &Luminance,
    t: &ep_box::TFactor,
    dl: f64,
) -> Result<Acc> {
    let (w, _) = input.size();
    let nall = input.channels().len() + input.aux_channels().len();
    let mut total = Acc {
        max: f64::NEG_INFINITY,
        ..Default::default()
    };
    let mut source = input.source();
    let strip_rows = crate::pipeline::auto_strip_rows(w, nall);
    while let Some(strip) = source.next_strip(strip_rows)? {
        let parts: Vec<Result<Acc>> = strip
            .data
            .par_chunks(nall * w)
            .enumerate()
            .map(|(r, row)| {
                let mut a = Acc {
                    max: f64::NEG_INFINITY,
                    ..Default::default()
                };
                let ch = |c: usize, x: usize| row[c * w + x] as f64;
                for x in 0..w {
                    let y = lum.of(|c| ch(c, x));
                    let (n, s2) = layout.pixel(lum.weights(), y, |c| ch(c, x));
                    let var_finite = layout.variance.iter().all(|&i| ch(i, x).is_finite());
                    if !(y.is_finite() && var_finite && n.is_finite()) {
                        return Err(Error::Value {
                            path: path.into(),
                            reason: format!(
                                "non-finite value at pixel ({x}, {}) in the pilot",
                                strip.y0 + r
                            ),
                        });
                    }
                    a.max = a.max.max(y);
                    a.pixels += 1;
                    if n >= 2.0 {
                        let se = s2.sqrt();
                        a.se.add(se);
                        a.sd.add(se * n.sqrt());
                        a.n.add(n);
                        a.tested += 1;
                        a.noisy += usize::from(t.get(n) * se > dl);
                    }
                }
                Ok(a)
            })
            .collect();
        for p in parts {
            let p = p?;
            total.se.merge(&p.se);
            total.sd.merge(&p.sd);
            total.n.merge(&p.n);
            total.tested += p.tested;
            total.pixels += p.pixels;
            total.max = total.max.max(p.max);
            total.noisy += p.noisy;
        }
    }
    Ok(total)
}
