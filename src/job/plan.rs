//! Build: a [`FilterJob`] (the raw request) becomes a [`FilterPlan`], with
//! the input open and its channels, statistics, geometry, output and memory
//! settled, without a pixel read. [`FilterPlan::run`] (in `run.rs`) then
//! does the work.

use crate::error::{Error, Result};
use crate::filter::channels::{self, ChannelRule};
use crate::filter::{FilterParams, Method};
use crate::geometry::Grid;
use crate::host::{cpu_seconds, default_max_memory};
use crate::io::output::OutputLayout;
use crate::io::provenance::Fingerprint;
use crate::io::{
    find_guides, find_stats, ExrInput, Format, FoundGuides, StatsChannels, Verdict, ViewSelect,
};
use crate::pipeline::stream::MAX_CHANNELS;
use crate::pipeline::{ChannelMode, NonFinite, StripLayout};

use super::{Decided, Edge, FilterJob, Opened};

/// A run settled: everything checked that can be checked before the stream.
pub struct FilterPlan<'a> {
    pub(crate) job: &'a FilterJob,
    pub(crate) fingerprint: &'a Fingerprint,
    /// What the input decided of the job.
    pub(crate) decided: &'a Decided,
    pub(crate) input: ExrInput,
    /// The job's settings (ep-box's `L_tvis` is settled by the first pass).
    pub(crate) params: FilterParams,
    /// The statistics channels found (ep-box).
    pub(crate) found: Option<StatsChannels>,
    /// The guide passes found and used.
    pub(crate) guides: FoundGuides,
    pub(crate) geometry: Geometry,
    /// The pipeline's channel layout.
    pub(crate) pipe_job: StripLayout,
    /// How the work is cut: the job's, with shorter strips and fewer blocks
    /// read ahead where its memory asks ([`crate::pipeline::fit_memory`]).
    pub(crate) pipeline: crate::pipeline::PipelineConfig,
    /// What the run is estimated to hold with it.
    pub(crate) memory_bytes: u64,
    pub(crate) channels: Vec<String>,
    pub(crate) layout: OutputLayout,
    pub(crate) band: Option<BandPlan>,
    pub(crate) warnings: Vec<String>,
    /// The process's CPU time when the build began.
    pub(crate) cpu_start: f64,
}

/// Which samples of the input are filtered.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geometry {
    /// Samples per row of the file.
    pub full_w: usize,
    /// Samples the filter works on (cropped, or padded to a multiple of S).
    pub w: usize,
    pub h: usize,
    /// Samples read per row and rows (the crop, or every sample with padding).
    pub read_w: usize,
    pub read_h: usize,
    /// `--edge pad`: the real size of the padded grid.
    pub padded_from: Option<(usize, usize)>,
}

/// Where a band's rows are.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BandPlan {
    pub k: usize,
    pub n: usize,
    /// Output rows of the band.
    pub a: usize,
    pub b: usize,
    /// Output rows of the window its run reads.
    pub wa: usize,
    pub wb: usize,
    pub out_h: usize,
}

impl BandPlan {
    pub fn label(&self, s: usize) -> String {
        format!(
            "{}/{} rows {}-{} of {} S={s}",
            self.k, self.n, self.a, self.b, self.out_h
        )
    }
}

impl<'a> FilterPlan<'a> {
    /// Open the part, layer and view `job` names of its input (`opened`),
    /// and settle the run. `exclusive`: one view of `--view all`, which
    /// carries nothing of the others; the fingerprint goes into the output.
    pub fn build(job: &'a FilterJob, opened: &'a Opened<'_>, exclusive: bool) -> Result<Self> {
        let cpu_start = cpu_seconds().unwrap_or(0.0);
        let view = match &job.view {
            Some(ViewSelect::Name(v)) => Some(v.as_str()),
            _ => None,
        };
        let mut input = (opened.file).input(job.part.as_ref(), job.layer.as_deref(), view)?;
        // A picture (Radiance, PFM) holds the colour alone.
        let to_rgbe = job.output_format()? != Format::Exr;
        let scope = crate::io::reader::view_scope(&job.input, input.header(), view, exclusive)?;
        let mut warnings = opened.decided.notes.clone();
        let found_guides = guides(job, &input, &scope, &mut warnings)?;
        let carried = carry(job, &mut input, &scope, to_rgbe, &found_guides)?;
        let found = statistics(job, &mut input, &carried)?;
        let guide_layout = found_guides.attach(&mut input, &carried)?;
        warnings.extend(super::dropped_warnings(job, &input, &scope, to_rgbe));
        warnings.extend(beauty_warnings(job, &input, &scope));
        let verdict = opened.decided.verdict.as_ref();
        let geometry = geometry(job, verdict, &input, &mut warnings)?;
        let channels = input.channels();
        let mut pipe_job = pipeline_job(job, &input, &geometry, found.as_ref().map(|f| &f.1))?;
        pipe_job.guides = guide_layout;
        pipe_job.surface_rule = job.surface_rule;
        pipe_job.aux = input.aux_channels();
        pipe_job.block_scratch = !input.decodes_in_place();
        pipe_job.stored_block_bytes = input.stored_block_bytes();
        let mut layout = OutputLayout::of(&input, &channels, &job.output_settings);
        if !to_rgbe {
            pipe_job.out_block_lines = layout.block_lines(&job.output, &job.output_settings)?;
        }
        let (pipeline, memory_bytes) = fit_memory(job, &input, &pipe_job, carried.len())?;
        if geometry.w != geometry.full_w || geometry.h != input.size().1 {
            layout.crop(geometry.w, geometry.h);
        }
        let s = job.params.supersample;
        let band = match job.band {
            None => None,
            Some((k, n)) => {
                let plan = plan_band(job, &layout, geometry.h / s, k, n)?;
                layout.rows(plan.a * s..plan.b * s);
                Some(plan)
            }
        };
        Ok(FilterPlan {
            job,
            fingerprint: &opened.fingerprint,
            decided: &opened.decided,
            input,
            params: job.params.clone(),
            found: found.map(|f| f.0),
            guides: found_guides,
            geometry,
            pipe_job,
            pipeline,
            memory_bytes,
            channels,
            layout,
            band,
            warnings,
            cpu_start,
        })
    }
}

/// Give every channel beside the beauty its carry rule (none into a Radiance
/// picture, which holds R, G, B only); ids (unsigned integers) only take the
/// nearest sample. Returns how many are carried.
fn carry(
    job: &FilterJob,
    input: &mut ExrInput,
    scope: &channels::ViewScope,
    to_rgbe: bool,
    guides: &FoundGuides,
) -> Result<Vec<(String, ChannelRule)>> {
    // The emission guide's channels are carried as they are (averaged at
    // S > 1): the beauty's emission is never spread, nor is the layer.
    let emission = guides.emission.clone().unwrap_or_default();
    let carried = if to_rgbe {
        Vec::new()
    } else {
        input.carry_channels(|name, uint| {
            let given = job.channel_rules.iter().any(|r| r.matches(name));
            if !given && emission.iter().any(|e| e == name) {
                return ChannelRule::Average;
            }
            channels::rule_for(name, uint, &job.channel_rules, scope)
        })
    };
    for (name, rule) in &carried {
        if input.is_uint(name) && *rule != ChannelRule::Nearest {
            return Err(Error::Config(format!(
                "{}: --channel-rule: {name} holds unsigned integers (ids): nearest or drop, not {}",
                job.input.display(),
                rule.name()
            )));
        }
    }
    let nfiltered = input.channels().len();
    if nfiltered > MAX_CHANNELS {
        return Err(Error::Channels {
            path: job.input.clone(),
            reason: format!(
                "{nfiltered} channels to filter and carry, at most {MAX_CHANNELS}: drop some with --channel-rule 'PATTERN=drop' (carried: {})",
                carried.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>().join(", ")
            ),
        });
    }
    Ok(carried)
}

/// The guide passes `job` asks for, found by name (none for the methods
/// that spread nothing, or with `--guides none`).
fn guides(
    job: &FilterJob,
    input: &ExrInput,
    scope: &channels::ViewScope,
    warnings: &mut Vec<String>,
) -> Result<FoundGuides> {
    let p = &job.params;
    let spreads = matches!(p.method, Method::EpGauss | Method::EpBox);
    if !spreads || job.guides.none() {
        return Ok(FoundGuides::default());
    }
    let beauty: Vec<String> = (input.channels().into_iter())
        .zip(input.luminance())
        .filter(|(_, l)| *l != 0.0)
        .map(|(c, _)| c)
        .collect();
    let mut found = find_guides(&job.input, input.header(), &beauty, &job.guides, scope)?;
    if let Some(c) = found.channels().iter().find(|c| input.is_uint(c)) {
        return Err(Error::Channels {
            path: job.input.clone(),
            reason: format!(
                "the guide channel {c} holds unsigned integers (an id), not a guide's values: name another with --guide KIND=NAME, or give --guides none"
            ),
        });
    }
    if p.supersample > 1 && found.surface() {
        // A super-sample's spread is a separable Gaussian: the emission
        // guide is read, the surface guides are not.
        if job.guides.kinds.is_some() || !job.guides.named.is_empty() {
            warnings.push(format!(
                "{}: the surface guides (albedo, normal, depth) are read at S = 1 only; at S = {} the emission guide is",
                job.input.display(),
                p.supersample
            ));
        }
        (found.albedo, found.normal, found.depth) = (None, None, None);
    }
    Ok(found)
}

/// The statistics step: ep-box needs them.
fn statistics(
    job: &FilterJob,
    input: &mut ExrInput,
    carried: &[(String, ChannelRule)],
) -> Result<Option<(StatsChannels, crate::filter::ep_box::StatsLayout)>> {
    if job.params.method != Method::EpBox {
        return Ok(None);
    }
    let found = find_stats(&job.input, input.header(), &job.stats)?;
    // The books check the statistics as they check light: with `--nonfinite
    // zero` they would zero a copy that is carried as it is, so the
    // statistics are then read on their own.
    let carried = match job.pipeline.nonfinite {
        NonFinite::Error => carried,
        NonFinite::Zero => &[],
    };
    let layout = found.attach(input, &job.input, carried)?;
    Ok(Some((found, layout)))
}

/// The samples filtered: the whole data window when its size is a multiple
/// of S, else cropped or padded as `--edge` says (with a warning), or refused.
fn geometry(
    job: &FilterJob,
    verdict: Option<&Verdict>,
    input: &ExrInput,
    warnings: &mut Vec<String>,
) -> Result<Geometry> {
    let s = job.params.supersample;
    let (w, h) = input.size();
    let origin = input.origin();
    if w < s || h < s {
        return Err(Error::Config(format!(
            "{}: --supersample {s} is larger than the image ({w}x{h})",
            job.input.display()
        )));
    }
    if origin.0.rem_euclid(s as i32) != 0 || origin.1.rem_euclid(s as i32) != 0 {
        return Err(Error::Config(format!(
            "{}: the data window starts at ({}, {}), not on a multiple of --supersample {s}",
            job.input.display(),
            origin.0,
            origin.1
        )));
    }
    let whole = Geometry {
        full_w: w,
        w,
        h,
        read_w: w,
        read_h: h,
        padded_from: None,
    };
    if w % s == 0 && h % s == 0 {
        return Ok(whole);
    }
    let (cw, ch) = (w - w % s, h - h % s);
    match job.edge {
        Edge::Crop => {
            warnings.push(format!(
                "{}: {w}x{h} samples is not a multiple of S={s}: cropped to {cw}x{ch} (--edge crop dropped the last {} sample column(s) and {} row(s))",
                job.input.display(),
                w - cw,
                h - ch
            ));
            Ok(Geometry {
                w: cw,
                h: ch,
                read_w: cw,
                read_h: ch,
                ..whole
            })
        }
        Edge::Pad => {
            warnings.push(format!(
                "{}: {w}x{h} samples is not a multiple of S={s}: padded (--edge pad): the last output column is made of {} and the last row of {} of {s} sample columns / rows, each normalised over what exists",
                job.input.display(),
                if w % s == 0 { s } else { w % s },
                if h % s == 0 { s } else { h % s },
            ));
            Ok(Geometry {
                w: w.div_ceil(s) * s,
                h: h.div_ceil(s) * s,
                padded_from: Some((w, h)),
                ..whole
            })
        }
        Edge::Exact => {
            let from = match verdict {
                Some(v) if v.supersample_from != "--supersample" => {
                    format!(" (from the {})", v.supersample_from)
                }
                _ => String::new(),
            };
            Err(Error::Config(format!(
                "{}: {w}x{h} samples is not a multiple of --supersample {s}{from}: give --edge crop to drop the last partial output column and row ({}x{} pixels), or --edge pad to keep them as pixels of fewer samples ({}x{}).",
                job.input.display(),
                cw / s,
                ch / s,
                w.div_ceil(s),
                h.div_ceil(s)
            )))
        }
    }
}

/// The pipeline's channel layout: the grid, the channels, their luminance
/// weights and rules, the statistics; `--edge pad` refuses the nearest rule.
fn pipeline_job(
    job: &FilterJob,
    input: &ExrInput,
    g: &Geometry,
    stats: Option<&crate::filter::ep_box::StatsLayout>,
) -> Result<StripLayout> {
    let channels = input.channels();
    let grid = Grid {
        in_w: g.w,
        in_h: g.h,
        s: job.params.supersample,
    };
    let mut pipe_job = StripLayout::new(grid, channels.clone(), input.luminance())
        .with_rules(&input.channel_rules());
    if g.padded_from.is_some() && pipe_job.modes.contains(&ChannelMode::Nearest) {
        let nearest: Vec<&str> = channels
            .iter()
            .zip(&pipe_job.modes)
            .filter(|(_, m)| **m == ChannelMode::Nearest)
            .map(|(n, _)| n.as_str())
            .collect();
        return Err(Error::Config(format!(
            "{}: --edge pad makes pixels of fewer samples, which have no centre sample for the nearest rule of {}: give --edge crop, or --channel-rule 'PATTERN=drop' or '=average'",
            job.input.display(),
            nearest.join(", ")
        )));
    }
    pipe_job.padded_from = g.padded_from;
    if let Some(layout) = stats {
        pipe_job.stats = Some(layout.clone());
        pipe_job.aux = input.aux_channels();
    }
    Ok(pipe_job)
}

/// How the job runs within `--max-memory` ([`crate::pipeline::fit_memory`]):
/// refused only where even its shortest strips and fewest blocks read ahead
/// would need more.
fn fit_memory(
    job: &FilterJob,
    input: &ExrInput,
    pipe_job: &StripLayout,
    carried: usize,
) -> Result<(crate::pipeline::PipelineConfig, u64)> {
    let limit = job.max_memory.unwrap_or_else(default_max_memory);
    let program = crate::pipeline::PROGRAM_BYTES;
    let floor = match crate::pipeline::fit_memory(
        pipe_job,
        &job.params,
        &job.pipeline,
        input.block_bytes(),
        limit.saturating_sub(program),
    ) {
        Ok((cfg, bytes)) => return Ok((cfg, bytes + program)),
        Err(floor) => floor + program,
    };
    let hint = if carried == 0 {
        String::new()
    } else {
        format!(
            "; {carried} of its {} channels are carried beside the beauty, and --channel-rule 'PATTERN=drop' leaves some out",
            pipe_job.channels.len()
        )
    };
    let (w, h) = (pipe_job.grid.in_w, pipe_job.grid.in_h);
    Err(Error::Config(format!(
        "{}: filtering this {w}x{h} image needs at least about {} MiB (the kernels' rows and one strip), more than the {} MiB allowed (--max-memory){hint}",
        job.input.display(),
        floor.div_ceil(1 << 20),
        limit >> 20
    )))
}

/// `--band K/N`: output rows `a..b`, from the input rows of a window that
/// reaches the halo's margin beyond them; bands end on the output's blocks.
fn plan_band(
    job: &FilterJob,
    layout: &OutputLayout,
    out_h: usize,
    k: usize,
    n: usize,
) -> Result<BandPlan> {
    if n == 0 || k == 0 || k > n {
        return Err(Error::Config(format!(
            "--band {k}/{n}: the band must be 1 to N of N"
        )));
    }
    if job.output_format()? != Format::Exr {
        return Err(Error::Config(format!(
            "{}: --band writes EXR bands; `epfilt merge` puts them together",
            job.output.display()
        )));
    }
    let (unit, compression) = layout.band_unit(&job.output, &job.output_settings)?;
    let (a, b) = crate::pipeline::band::band_rows(out_h, unit, k - 1, n).ok_or_else(|| {
        Error::Config(format!(
            "--band {k}/{n} is empty: the output's {out_h} rows make {} blocks of {unit} rows ({compression}); use at most that many bands",
            out_h.div_ceil(unit),
        ))
    })?;
    let m = crate::pipeline::band::margin(&job.params);
    Ok(BandPlan {
        k,
        n,
        a,
        b,
        // On the grid of the window's 2x and 4x coarse grids
        // (--coarse-from) and summed-area table's blocks (--bound-from), so they
        // are the whole image's.
        wa: {
            let align = crate::filter::window_align(&job.params);
            a.saturating_sub(m) / align * align
        },
        wb: (b + m).min(out_h),
        out_h,
    })
}

/// What a file with several beauties, or Blender's denoised one, says to
/// the user when no `--layer` chose: which beauty was filtered, which are
/// carried unfiltered, and where Blender's render is.
fn beauty_warnings(job: &FilterJob, input: &ExrInput, scope: &channels::ViewScope) -> Vec<String> {
    let mut warnings = Vec::new();
    if job.layer.is_some() {
        return warnings;
    }
    // The beauty's channels come first, before those carried; the names are
    // the run's view's as it sees them, as `--layer` takes them.
    let seen = scope.seen_names(&crate::io::reader::channel_names(input.header()));
    let names: Vec<String> = seen.into_iter().map(|(s, _)| s).collect();
    let first = (input.channels().first())
        .and_then(|c| scope.seen(c))
        .unwrap_or_default();
    let layer = first.rsplit_once('.');
    let others: Vec<String> = (crate::io::reader::beauty_layers(&names).into_iter())
        .filter(|l| !first.starts_with(l.as_str()))
        .map(|l| l.trim_end_matches('.').to_string())
        .collect();
    // Cycles with its denoiser on writes the denoised image as
    // `Combined` and the render as `Noisy Image` beside it.
    if let Some((l, _)) = layer.filter(|(l, _)| l.ends_with("Combined")) {
        let noisy = format!("{}Noisy Image.", &l[..l.len() - "Combined".len()]);
        if names.iter().any(|n| n.starts_with(&noisy)) {
            let noisy = noisy.trim_end_matches('.');
            warnings.push(format!(
                "{}: {l} is Blender's denoised image and {noisy} its render: --layer '{noisy}' filters the render",
                job.input.display()
            ));
        }
    }
    if !others.is_empty() {
        warnings.push(format!(
            "{}: filtered {}; {} carried unfiltered: --layer NAME filters another",
            job.input.display(),
            layer.map_or("the unlayered channels", |(l, _)| l),
            others.join(", ")
        ));
    }
    warnings
}
