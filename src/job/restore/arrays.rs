//! `restore` on images in memory (Python's `epfilt.restore`).

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use super::{check_ledger, config, RestoreReport};
use crate::error::{Error, Result};
use crate::filter::restore::RestoreParams;
use crate::host::cpu_seconds;
use crate::job::array::{interleaved, planar, ArrayStats};
use crate::pipeline::restore::{restore_planar, EnergyLayout, RenderStats};
use crate::pipeline::{NonFinite, Precision};

/// Images in memory to restore: interleaved `[y][x][channel]`, `w x h`.
#[derive(Clone, Copy, Debug)]
pub struct RestoreArrays<'a> {
    /// The denoiser's output, `channels` per pixel.
    pub denoised: &'a [f32],
    /// The image whose energy is right, the same shape.
    pub energy: &'a [f32],
    /// The energy image's emission guide, the same shape, where the
    /// renderer wrote one.
    pub emission: Option<&'a [f32]>,
    /// The energy image's variance pass (of single samples, as `filter`'s
    /// `variance=`): one value per pixel (of the luminance) or one per
    /// colour channel, with its sample counts.
    pub stats: Option<ArrayStats<'a>>,
    /// One sample count for the image, where `stats` has none per pixel.
    pub spp: Option<f64>,
    /// Width and height.
    pub size: (usize, usize),
    /// Channel names (for the ledger; `R G B` and `R G B A` weigh the
    /// luminance as a file's Rec. 709 would).
    pub channels: &'a [String],
}

/// Restore on arrays ([`RestoreArrays`]) at `scale` with `keep_gain`
/// (`None`: evidence alone, as a render takes). Returns the result in the
/// energy's layout and the report.
pub fn restore_array(
    input: &RestoreArrays<'_>,
    (scale, keep_gain): (usize, Option<f64>),
    threads: usize,
    nonfinite: NonFinite,
    cancel: Option<Arc<AtomicBool>>,
) -> Result<(Vec<f32>, RestoreReport)> {
    let keep_gain_from = match keep_gain {
        Some(_) => "keep_gain",
        None => "the energy image is a render: evidence alone (arrays say nothing else)",
    };
    let params = RestoreParams { scale, keep_gain }
        .check()
        .map_err(Error::Config)?;
    let (w, h) = input.size;
    let channels = input.channels;
    let nch = channels.len();
    let pixels = w.checked_mul(h);
    let n = pixels.and_then(|p| p.checked_mul(nch));
    let lens = [
        Some(input.denoised.len()),
        Some(input.energy.len()),
        input.emission.map(<[f32]>::len),
    ];
    if lens.iter().flatten().any(|&l| Some(l) != n) {
        return Err(Error::Config(format!(
            "denoised has {} values, energy {} and emission {}; a {w}x{h} image of {nch} channels has {}",
            input.denoised.len(),
            input.energy.len(),
            input.emission.map_or("none".into(), |e| e.len().to_string()),
            n.map_or("too many".into(), |n| n.to_string())
        )));
    }
    let luminance = array_luminance(channels);
    let mut layout = EnergyLayout::plain(channels.to_vec(), luminance.clone());
    // Each row: the energy's channels, then the guide's, then the
    // statistics'.
    let mut parts = vec![(planar(input.energy, w, nch), nch)];
    if let Some(em) = input.emission {
        parts.push((planar(em, w, nch), nch));
        layout.emission = (nch..2 * nch).map(Some).collect();
        layout.guide = vec!["emission".to_string()];
    }
    let mut variance_pass = String::new();
    if let Some(st) = input.stats {
        let at = parts.iter().map(|p| p.1).sum();
        let (stats, rows, from) = array_stats(&st, input.spp, (w, h), &luminance, at)?;
        parts.extend(rows);
        layout.stats = Some(stats);
        variance_pass = from;
    } else if input.spp.is_some() {
        return Err(Error::Config("spp= without variance=".into()));
    }
    let rows = (0..h)
        .flat_map(|y| {
            (parts.iter()).flat_map(move |(p, c)| p[y * c * w..(y + 1) * c * w].iter().copied())
        })
        .collect();
    let cfg = config(threads, nonfinite, cancel);
    let cpu_start = cpu_seconds();
    let guide = layout.guide.clone();
    let (out, restored) = restore_planar(
        rows,
        planar(input.denoised, w, nch),
        (w, h),
        layout,
        params,
        &cfg,
        Precision::F32,
    )?;
    check_ledger(&restored)?;
    let inter = interleaved(&out, w, nch);
    let report = RestoreReport::of(
        ("<array>", "<array>", "<array>"),
        (w, h),
        (params, keep_gain_from.to_string(), guide, Vec::new()),
        &restored,
        cfg.workers(),
        cpu_start,
    );
    Ok((inter, report.with_variance_pass(variance_pass)))
}

/// An array's luminance weights: Rec. 709 for `R G B` (and an alpha after
/// them), one for a lone `Y`, else none (its statistics then weigh each
/// channel alike).
fn array_luminance(channels: &[String]) -> Vec<f64> {
    let rgb = crate::io::luminance_weights(None);
    let names: Vec<&str> = channels.iter().map(String::as_str).collect();
    match names.as_slice() {
        ["R", "G", "B"] => rgb.to_vec(),
        ["R", "G", "B", "A"] => vec![rgb[0], rgb[1], rgb[2], 0.0],
        ["Y"] | ["Y", "A"] => {
            let mut l = vec![0.0; names.len()];
            l[0] = 1.0;
            l
        }
        _ => vec![1.0 / names.len().max(1) as f64; names.len()],
    }
}

/// An array's variance pass and sample counts as the energy rows' channels
/// from `at` on: the statistics, their planar rows (with their channel
/// counts) and the words for the report. Sizes are checked first.
#[allow(clippy::type_complexity)]
fn array_stats(
    st: &ArrayStats<'_>,
    spp: Option<f64>,
    (w, h): (usize, usize),
    luminance: &[f64],
    at: usize,
) -> Result<(RenderStats, Vec<(Vec<f32>, usize)>, String)> {
    use crate::filter::ep_box::{Spp, StatsLayout, VarianceKind};
    let nv = st.variance_channels;
    let colour = luminance.iter().filter(|&&l| l > 0.0).count();
    if !(nv == 1 || (nv == 3 && colour == 3)) || st.variance.len() != w * h * nv {
        return Err(Error::Config(format!(
            "variance holds {} values for {w}x{h} pixels: give one per pixel (of the luminance) or, for an R G B image, three",
            st.variance.len()
        )));
    }
    let mut rows = vec![(planar(st.variance, w, nv), nv)];
    let mut names: Vec<String> = match nv {
        1 => vec!["variance".into()],
        _ => ["R", "G", "B"]
            .iter()
            .map(|c| format!("variance.{c}"))
            .collect(),
    };
    let samples = match (st.spp, spp) {
        (Some(counts), _) if counts.len() == w * h => {
            rows.push((counts.to_vec(), 1));
            names.push("spp".into());
            Spp::Channel(at + nv)
        }
        (Some(counts), _) => {
            return Err(Error::Config(format!(
                "spp holds {} counts for {w}x{h} pixels",
                counts.len()
            )))
        }
        (None, Some(n)) if n >= 1.0 && n.is_finite() => Spp::Fixed(n),
        (None, Some(n)) => return Err(Error::Config(format!("spp must be at least 1, not {n}"))),
        (None, None) => {
            return Err(Error::Config(
                "the variance needs the sample count: spp= (an array or a number)".into(),
            ))
        }
    };
    let from = format!(
        "{}; samples: {}",
        names[..nv].join(", "),
        match samples {
            Spp::Fixed(n) => format!("spp={n}"),
            _ => "spp (per pixel)".into(),
        }
    );
    let layout = StatsLayout {
        variance: (at..at + nv).collect(),
        kind: VarianceKind::Sample,
        mean_y: None,
        spp: samples,
    };
    Ok((RenderStats::new(layout, luminance, names), rows, from))
}
