//! Filtering an image held in memory (the Python bindings' `filter`): the
//! channel layout, settings, rounding and report a file of the same samples
//! would get from [`super::filter_file`], without files.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::error::{Error, Result};
use crate::filter::ep_box::{Spp, StatsLayout, VarianceKind};
use crate::filter::{FilterParams, Method};
use crate::geometry::Grid;
use crate::io::{luminance_weights, SppFrom, StatsChannels};
use crate::pipeline::{filter_planar, Precision, StripLayout};
use crate::report::Report;

use super::FilterOptions;

/// An image in memory.
#[derive(Clone, Copy, Debug)]
pub struct ArrayInput<'a> {
    /// Samples, interleaved: `samples[(y * width + x) * channels.len() + c]`.
    pub samples: &'a [f32],
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Channel names: `Y`, or `R`, `G`, `B` and optionally `A`.
    pub channels: &'a [String],
    /// The samples were half floats: with `pixel_type` `same`, the output is
    /// rounded to half floats, as a file of them would be.
    pub half: bool,
    /// Per-pixel statistics (ep-box, the method chosen where they are given
    /// at S = 1).
    pub stats: Option<ArrayStats<'a>>,
}

/// Per-pixel statistics of an image in memory.
#[derive(Clone, Copy, Debug)]
pub struct ArrayStats<'a> {
    /// The variance of each pixel, interleaved: one luminance value, or one
    /// per colour channel (R, G, B); what it holds is `variance_kind`'s
    /// (default: of single samples).
    pub variance: &'a [f32],
    /// Values per pixel in `variance`: 1 or 3.
    pub variance_channels: usize,
    /// Each pixel's sample count (`None`: one count for the image, the
    /// `spp` setting).
    pub spp: Option<&'a [f32]>,
}

/// The outcome of [`filter_array`].
#[derive(Clone, Debug)]
pub struct ArrayOutput {
    /// Output pixels, interleaved as the input (`channels` per pixel),
    /// rounded to the output's precision.
    pub samples: Vec<f32>,
    /// Output width and height in pixels.
    pub width: usize,
    /// See `width`.
    pub height: usize,
    /// The output's precision.
    pub precision: Precision,
    /// The run's report (the `--report` fields; input and output `<array>`).
    pub report: Report,
}

/// Each channel's luminance weight, as a file's reader gives it (Rec. 709
/// primaries, no chromaticities attribute); names other than the beauty's
/// are refused.
fn luminance_of(channels: &[String]) -> Result<Vec<f64>> {
    let rgb = luminance_weights(None);
    let names: Vec<&str> = channels.iter().map(String::as_str).collect();
    match names.as_slice() {
        ["Y"] => Ok(vec![1.0]),
        ["R", "G", "B"] => Ok(rgb.to_vec()),
        ["R", "G", "B", "A"] => Ok(vec![rgb[0], rgb[1], rgb[2], 0.0]),
        ["Y", "A"] => Ok(vec![1.0, 0.0]),
        _ => Err(Error::Config(format!(
            "channels {names:?}: an array holds Y, Y A, R G B or R G B A (other channels: write a file and use filter_file)"
        ))),
    }
}

/// Filter an image in memory with `opts` (`given`: the method options
/// set, for warnings; `cancel` stops the run). Every size is checked before
/// anything is allocated.
pub fn filter_array(
    input: &ArrayInput<'_>,
    opts: &FilterOptions,
    given: &[String],
    cancel: Option<Arc<AtomicBool>>,
) -> Result<ArrayOutput> {
    let files = opts.files_only_given();
    if !files.is_empty() {
        return Err(Error::Config(format!(
            "{} appl{} to files: use filter_file",
            files.join(", "),
            if files.len() == 1 { "ies" } else { "y" }
        )));
    }
    // As a file's: ep-box where the variance is given at S = 1, unless
    // the method is.
    let s = opts.supersample.unwrap_or(1);
    let (params, mut warnings) = match (&opts.method, input.stats) {
        (None, Some(_)) if s == 1 => opts.params_for(Method::EpBox, 1, given)?,
        _ => opts.params(given)?,
    };
    let (cfg, capped) = opts.pipeline(cancel)?;
    warnings.extend(capped);
    let (w, h, nch) = (input.width, input.height, input.channels.len());
    let luminance = luminance_of(input.channels)?;
    if w.checked_mul(h).and_then(|n| n.checked_mul(nch)) != Some(input.samples.len()) {
        return Err(Error::Config(format!(
            "{} samples for a {w}x{h} image of {nch} channels",
            input.samples.len()
        )));
    }
    let s = params.supersample;
    if w < s || h < s || w % s != 0 || h % s != 0 {
        return Err(Error::Config(format!(
            "a {w}x{h} array is not a whole number of {s}x{s} pixels (supersample {s}): crop it to {}x{}",
            w / s * s,
            h / s * s
        )));
    }
    let grid = Grid {
        in_w: w,
        in_h: h,
        s,
    };
    let mut layout = StripLayout::new(grid, input.channels.to_vec(), luminance);
    let found = stats_layout(input, opts, &params, &mut layout, &mut warnings)?;
    let planar = planar_rows(input, found.as_ref().and(input.stats));
    let precision = opts.precision().unwrap_or(if input.half {
        Precision::F16
    } else {
        Precision::F32
    });
    let run = filter_planar(planar, &layout, &params, &cfg, precision)?;
    let (ow, oh) = (w / s, h / s);
    let samples = interleaved(&run.data, ow, nch);
    let mut settings = run.params.settings();
    settings.push(("pixel_type", precision.name().into()));
    let report = Report::of_array(
        &layout,
        &cfg,
        &run,
        found.as_ref(),
        Report::array_settings(settings),
        warnings,
    );
    Ok(ArrayOutput {
        samples,
        width: ow,
        height: oh,
        precision,
        report,
    })
}

/// The statistics the run reads, appended to the layout's channels (ep-box
/// needs them).
fn stats_layout(
    input: &ArrayInput<'_>,
    opts: &FilterOptions,
    params: &FilterParams,
    layout: &mut StripLayout,
    warnings: &mut Vec<String>,
) -> Result<Option<StatsChannels>> {
    let reads = params.method == Method::EpBox;
    let Some(st) = input.stats.filter(|_| reads) else {
        if params.method == Method::EpBox {
            return Err(Error::Config(
                "ep-box needs each pixel's variance: give variance= (and spp=, or the spp setting)"
                    .into(),
            ));
        }
        if input.stats.is_some() {
            warnings.push(format!(
                "the per-pixel statistics have no effect with --method {} at S = {}",
                params.method.name(),
                params.supersample
            ));
        }
        return Ok(None);
    };
    let pixels = input.width * input.height;
    let nv = st.variance_channels;
    if !(nv == 1 || (nv == 3 && layout.luminance.iter().filter(|&&l| l > 0.0).count() == 3)) {
        return Err(Error::Config(format!(
            "{nv} variance values per pixel: give one (of the luminance) or, for an R G B image, three"
        )));
    }
    if st.variance.len() != pixels * nv {
        return Err(Error::Config(format!(
            "variance holds {} values for {pixels} pixels of {nv}",
            st.variance.len()
        )));
    }
    let kind = opts.variance_kind.unwrap_or(VarianceKind::Sample);
    let nch = layout.channels.len();
    let names: Vec<String> = match nv {
        1 => vec!["variance".into()],
        _ => ["R", "G", "B"]
            .iter()
            .map(|c| format!("variance.{c}"))
            .collect(),
    };
    layout.aux = names.clone();
    let spp = match (st.spp, opts.spp) {
        (Some(counts), _) => {
            if counts.len() != pixels {
                return Err(Error::Config(format!(
                    "spp holds {} counts for {pixels} pixels",
                    counts.len()
                )));
            }
            layout.aux.push("spp".into());
            SppFrom::Channel("spp".into())
        }
        (None, Some(n)) => SppFrom::Fixed(n as f64, "spp setting".into()),
        (None, None) => {
            return Err(Error::Config(
                "the per-pixel statistics need the sample count: spp= (an array or a number)"
                    .into(),
            ))
        }
    };
    layout.stats = Some(StatsLayout {
        variance: (nch..nch + nv).collect(),
        kind,
        mean_y: None,
        spp: match &spp {
            SppFrom::Fixed(n, _) => Spp::Fixed(*n),
            SppFrom::Channel(_) => Spp::Channel(nch + nv),
        },
    });
    Ok(Some(StatsChannels {
        variance: names,
        kind,
        mean_y: None,
        spp,
    }))
}

/// The pipeline's rows, `[row][channel][x]`: the image's channels, then
/// the statistics (`stats`: the ones read).
/// Rows `[row][channel][x]` of `w` pixels and `nch` channels as an array's
/// `[row][x][channel]`.
pub(crate) fn interleaved(planar: &[f32], w: usize, nch: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; planar.len()];
    for (row, dst) in planar
        .chunks_exact(w * nch)
        .zip(out.chunks_exact_mut(w * nch))
    {
        for c in 0..nch {
            for (x, &v) in row[c * w..(c + 1) * w].iter().enumerate() {
                dst[x * nch + c] = v;
            }
        }
    }
    out
}

/// An array's `[row][x][channel]` of `w` pixels and `nch` channels as
/// rows `[row][channel][x]`.
pub(crate) fn planar(samples: &[f32], w: usize, nch: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; samples.len()];
    for (src, row) in samples
        .chunks_exact(w * nch)
        .zip(out.chunks_exact_mut(w * nch))
    {
        for c in 0..nch {
            for (x, d) in row[c * w..(c + 1) * w].iter_mut().enumerate() {
                *d = src[x * nch + c];
            }
        }
    }
    out
}

fn planar_rows(input: &ArrayInput<'_>, stats: Option<ArrayStats<'_>>) -> Vec<f32> {
    let (w, h, nch) = (input.width, input.height, input.channels.len());
    let nv = stats.map_or(0, |s| s.variance_channels);
    let nspp = usize::from(stats.is_some_and(|s| s.spp.is_some()));
    let row_len = (nch + nv + nspp) * w;
    let mut rows = vec![0.0f32; row_len * h];
    for (y, row) in rows.chunks_exact_mut(row_len).enumerate() {
        let mut put = |first: usize, n: usize, src: &[f32]| {
            let src = &src[y * w * n..(y + 1) * w * n];
            for c in 0..n {
                let dst = &mut row[(first + c) * w..(first + c + 1) * w];
                for (x, d) in dst.iter_mut().enumerate() {
                    *d = src[x * n + c];
                }
            }
        };
        put(0, nch, input.samples);
        if let Some(st) = stats {
            put(nch, nv, st.variance);
            if let Some(spp) = st.spp {
                put(nch + nv, 1, spp);
            }
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::job::Setting;

    fn opts(pairs: &[(&str, &str)]) -> (FilterOptions, Vec<String>) {
        FilterOptions::from_settings(
            pairs
                .iter()
                .map(|(k, v)| (k.to_string(), Setting::Value(v.to_string()))),
        )
        .unwrap()
    }

    fn grey_with_firefly(w: usize, h: usize) -> Vec<f32> {
        let mut v = vec![0.5f32; w * h * 3];
        v[(7 * w + 8) * 3 + 1] = 4000.0;
        v
    }

    #[test]
    fn an_array_filters_as_its_planar_rows_do() {
        let (w, h) = (24, 18);
        let rgb: Vec<String> = ["R", "G", "B"].iter().map(|s| s.to_string()).collect();
        let samples = grey_with_firefly(w, h);
        let input = ArrayInput {
            samples: &samples,
            width: w,
            height: h,
            channels: &rgb,
            half: false,
            stats: None,
        };
        let (o, given) = opts(&[("supersample", "3")]);
        let out = filter_array(&input, &o, &given, None).unwrap();
        assert_eq!((out.width, out.height), (8, 6));
        assert!(out.report.samples_spread >= 1);
        // The same run on planar rows, as the library's own entry takes them.
        let (params, _) = o.params(&given).unwrap();
        let layout = StripLayout::new(
            Grid {
                in_w: w,
                in_h: h,
                s: 3,
            },
            rgb.clone(),
            luminance_weights(None).to_vec(),
        );
        let planar = planar_rows(&input, None);
        let (want, _) =
            crate::filter_in_memory(planar, &layout, &params, &Default::default()).unwrap();
        for y in 0..6 {
            for c in 0..3 {
                for x in 0..8 {
                    let a = out.samples[(y * 8 + x) * 3 + c];
                    assert_eq!(a.to_bits(), want[(y * 3 + c) * 8 + x].to_bits());
                }
            }
        }
        assert!((out.report.energy_rel_error.iter())
            .all(|e| e.abs() < crate::pipeline::ledger::LEDGER_TOL));
    }

    #[test]
    fn sizes_channels_and_file_options_are_checked() {
        let rgb: Vec<String> = ["R", "G", "B"].iter().map(|s| s.to_string()).collect();
        let samples = vec![1.0f32; 10 * 9 * 3];
        let input = ArrayInput {
            samples: &samples,
            width: 10,
            height: 9,
            channels: &rgb,
            half: false,
            stats: None,
        };
        // An array is at pixel resolution unless told otherwise.
        let (o, given) = opts(&[]);
        let out = filter_array(&input, &o, &given, None).unwrap();
        assert_eq!((out.width, out.height), (10, 9));
        let (o, given) = opts(&[("supersample", "3")]);
        let e = filter_array(&input, &o, &given, None).unwrap_err();
        assert!(e.to_string().contains("crop it to 9x9"), "{e}");
        let short = ArrayInput {
            samples: &samples[1..],
            width: 9,
            ..input
        };
        assert!(filter_array(&short, &o, &given, None).is_err());
        let xyz: Vec<String> = ["X", "Y", "Z"].iter().map(|s| s.to_string()).collect();
        let odd = ArrayInput {
            channels: &xyz,
            width: 9,
            samples: &samples[..81 * 3],
            ..input
        };
        assert!(filter_array(&odd, &o, &given, None).is_err());
        let (o, given) = opts(&[("compression", "zip")]);
        let fine = ArrayInput {
            width: 9,
            samples: &samples[..81 * 3],
            ..input
        };
        let e = filter_array(&fine, &o, &given, None).unwrap_err();
        assert!(
            e.to_string().contains("compression applies to files"),
            "{e}"
        );
        let (o, given) = opts(&[("method", "ep-box")]);
        let e = filter_array(&fine, &o, &given, None).unwrap_err();
        assert!(e.to_string().contains("variance"), "{e}");
    }
}
