//! A filtering job from file to file: validate everything first, stream, check
//! the ledger, and only then put the output in place.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result, Side};
use crate::filter::channels::{self, RuleOverride};
use crate::filter::ep_box::{Spp, StatsLayout};
use crate::filter::{FilterParams, Method};
use crate::geometry::Grid;
use crate::host::{cpu_seconds, default_max_memory, peak_rss_bytes};
use crate::io::provenance::{self, Fingerprint};
use crate::io::{
    find_stats, ExrInput, Format, OutputSettings, PartSelect, SppFrom, StatsRequest, ViewSelect,
};
use crate::pipeline::edge::{Coverage, Cropped};
use crate::pipeline::stream::MAX_CHANNELS;
use crate::pipeline::{run, ChannelMode, Job, MethodStats, PipelineConfig, Progress};
use crate::report::{EpBoxReport, PartReport, Report, StatsReport};

/// The ledger must balance to this relative error before rounding, or the
/// output is not written. The pipeline's own bound is 1e-12 (each sample's
/// weights sum to one within a few ulps, sums are compensated); 1e-9 leaves a
/// wide margin and still catches any lost or doubled sample.
pub const LEDGER_LIMIT: f64 = 1e-9;

/// Everything a file-to-file run needs.
#[derive(Clone, Debug)]
pub struct FilterJob {
    /// Input file.
    pub input: PathBuf,
    /// Output file.
    pub output: PathBuf,
    /// Filter settings.
    pub params: FilterParams,
    /// How the work is cut (does not change the result).
    pub pipeline: PipelineConfig,
    /// Output file settings.
    pub output_settings: OutputSettings,
    /// Part of a multi-part input.
    pub part: Option<PartSelect>,
    /// Layer whose colour channels are filtered (see [`ExrInput::open_layer`]).
    pub layer: Option<String>,
    /// Refuse a job whose estimated memory exceeds this many bytes
    /// ([`crate::pipeline::estimate_bytes`]); `None`: [`default_max_memory`].
    pub max_memory: Option<u64>,
    /// Where `ep-box` finds its statistics (found by name when empty).
    pub stats: StatsRequest,
    /// What to do with an input whose size is not a multiple of S.
    pub edge: Edge,
    /// `params.supersample` is a default, not the user's choice: the summary
    /// says what was assumed, and a size that does not fit says how to fix it.
    pub supersample_assumed: bool,
    /// Only band `K` of `N` (1-based) of the output rows, for `merge`.
    pub band: Option<(usize, usize)>,
    /// `--channel-rule`s for the channels beside the beauty (the last that
    /// matches wins; the rest get [`channels::default_rule`]).
    pub channel_rules: Vec<RuleOverride>,
    /// `--format`: the output's format where its name does not say (`-`, a
    /// name without an image extension). `None`: by the extension, and for
    /// `-` the input's ([`crate::io::format::output_format`]).
    pub format: Option<Format>,
    /// `--view`: the view of a multi-view file to filter, or every view
    /// (each as an image of its own, into one output); `None`: the default
    /// view, the others left out with a warning.
    pub view: Option<ViewSelect>,
}

/// An input whose width or height is not a multiple of the super-sampling
/// factor S.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Edge {
    /// Refuse it, naming the options (the default).
    #[default]
    Exact,
    /// Drop the last `w % S` columns and `h % S` rows of samples (the last
    /// partial output column and row); the ledger counts what was kept.
    Crop,
    /// Keep them: the last output column and row are made of fewer samples,
    /// each pixel's kernel normalised over what exists; energy exact
    /// ([`crate::pipeline::edge`]).
    Pad,
}

impl Edge {
    /// `crop` or `pad`.
    pub fn parse(s: &str) -> Result<Edge> {
        match s {
            "crop" => Ok(Edge::Crop),
            "pad" => Ok(Edge::Pad),
            other => Err(Error::Config(format!(
                "--edge must be crop or pad, not {other:?}"
            ))),
        }
    }
}

impl FilterJob {
    /// `input` to `output` with `params`, and defaults for the rest: automatic
    /// strips and threads, output samples of the input's type compressed like
    /// the input, part 0 of a
    /// single-part file, [`default_max_memory`].
    pub fn new(
        input: impl Into<PathBuf>,
        output: impl Into<PathBuf>,
        params: FilterParams,
    ) -> Self {
        FilterJob {
            input: input.into(),
            output: output.into(),
            params,
            pipeline: PipelineConfig::default(),
            output_settings: OutputSettings {
                compression: None,
                precision: None,
                allow_lossy: false,
                provenance: None,
                extra: Vec::new(),
            },
            part: None,
            layer: None,
            max_memory: None,
            stats: StatsRequest::default(),
            edge: Edge::Exact,
            supersample_assumed: false,
            band: None,
            channel_rules: Vec::new(),
            format: None,
            view: None,
        }
    }

    /// The format the output is written in: its extension's, or `format`,
    /// or for `-` the input's; refused when the name says something filter
    /// cannot write ([`crate::io::format::output_format`]).
    pub fn output_format(&self) -> Result<Format> {
        if let Some(f) = self.format.filter(|_| self.output.as_os_str() != "-") {
            // Already resolved, or given: the name must agree.
            return crate::io::format::output_format(&self.output, Some(f), None, WRITES, "filter");
        }
        let input = match self.format {
            Some(_) => None,
            None if self.output.as_os_str() == "-" => Some(crate::io::input_format(&self.input)?),
            None => None,
        };
        crate::io::format::output_format(&self.output, self.format, input, WRITES, "filter")
    }
}

/// What `filter` writes.
pub const WRITES: &[Format] = &[Format::Exr, Format::Rgbe];

impl FilterJob {
    /// Every setting that decides the output's bytes, as text: the
    /// method's settings, the output's format, compression and sample types,
    /// the channels, parts, views and edge chosen, and epfilt's version; not
    /// the threads, tiles, strips or memory limit, which do not change a
    /// byte, nor the band (a band's bytes are the whole run's).
    pub fn settings_text(&self) -> Result<String> {
        let method: Vec<String> = self
            .params
            .settings()
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        let o = &self.output_settings;
        let rules: Vec<String> = self
            .channel_rules
            .iter()
            .map(|r| format!("{}={}", r.pattern(), r.rule.name()))
            .collect();
        Ok(format!(
            "epfilt {}; {}; format={}; compression={}; pixel_type={:?}; allow_lossy={}; part={:?}; layer={:?}; view={:?}; channel_rules={}; edge={:?}; nonfinite={:?}; stats={:?}",
            env!("CARGO_PKG_VERSION"),
            method.join(" "),
            self.output_format()?.name(),
            o.compression.map_or("input".into(), crate::io::compression_name),
            o.precision,
            o.allow_lossy,
            self.part,
            self.layer,
            self.view,
            rules.join(";"),
            self.edge,
            self.pipeline.nonfinite,
            self.stats,
        ))
    }

    /// What this job's output records of its input and settings.
    pub fn fingerprint(&self) -> Result<Fingerprint> {
        Fingerprint::of(&self.input, &self.settings_text()?)
    }

    /// The band label an output of this job carries (`None` without a band;
    /// it is checked against the band's file by [`existing_output`]).
    fn band_text(&self) -> Option<String> {
        self.band.map(|(k, n)| format!("{k}/{n}"))
    }
}

/// What `--skip-existing` finds at a job's output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Existing {
    /// Nothing there.
    Missing,
    /// A complete output of this input and these settings: done.
    Done,
    /// Something that is not: it is redone, for this reason.
    Redo(String),
}

/// Whether `job`'s output already exists as a complete output of its input
/// and settings: readable, whole (every block present), made by epfilt from
/// the same input with the same settings ([`provenance`]), and the same band
/// or none.
pub fn existing_output(job: &FilterJob) -> Result<Existing> {
    let out = &job.output;
    if out.as_os_str() == "-" {
        return Ok(Existing::Missing);
    }
    match std::fs::metadata(out) {
        Err(_) => return Ok(Existing::Missing),
        Ok(m) if !m.is_file() => return Ok(Existing::Missing), // refused later
        Ok(m) if m.len() == 0 => return Ok(Existing::Redo("it is empty".into())),
        Ok(_) => {}
    }
    let recorded = match provenance::recorded(out) {
        Ok(r) => r,
        Err(why) => return Ok(Existing::Redo(format!("it is not a whole image ({why})"))),
    };
    let Some(found) = recorded.fingerprint else {
        return Ok(Existing::Redo("it was not written by epfilt".into()));
    };
    let want = job.fingerprint()?;
    let recorded_band = recorded
        .band
        .as_deref()
        .map(|b| b.split_whitespace().next().unwrap_or(b).to_string());
    Ok(if found.input != want.input {
        Existing::Redo("it was made from another input".into())
    } else if found.settings != want.settings {
        Existing::Redo("it was made with other settings".into())
    } else if recorded_band != job.band_text() {
        Existing::Redo(match recorded.band {
            Some(b) => format!("it is band {b}, not the whole image"),
            None => "it is the whole image, not this band".into(),
        })
    } else {
        Existing::Done
    })
}

/// Refuse an output that is the input, also through a symbolic or hard link.
pub fn check_not_same_file(input: &Path, output: &Path) -> Result<()> {
    let same = match (std::fs::metadata(input), std::fs::metadata(output)) {
        (Ok(a), Ok(b)) => {
            #[cfg(unix)]
            {
                use std::os::unix::fs::MetadataExt;
                a.dev() == b.dev() && a.ino() == b.ino()
            }
            #[cfg(not(unix))]
            {
                let _ = (a, b);
                std::fs::canonicalize(input).ok() == std::fs::canonicalize(output).ok()
            }
        }
        _ => false,
    };
    if same {
        return Err(Error::Config(format!(
            "the output {} is the input file; choose another output path",
            output.display()
        )));
    }
    Ok(())
}

/// Run `job`, reporting progress as (output rows done, output rows).
///
/// A multi-part input: the part chosen with `--part` is filtered and, at
/// S = 1 into an EXR without `--band`, every other part is copied bit for bit
/// beside it (parts of deep data are left out); at S > 1 the others cannot
/// stay (OpenEXR requires one display window in every part) and are left
/// out with a warning. `--part all` filters every part with the same
/// settings into one multi-part output.
pub fn filter_file(job: &FilterJob, progress: Progress<'_>) -> Result<Report> {
    job.params.validate()?;
    check_not_same_file(&job.input, &job.output)?;
    let job = &FilterJob {
        format: Some(job.output_format()?),
        ..job.clone()
    };
    let fingerprint = &job.fingerprint()?;
    let to_rgbe = job.format == Some(Format::Rgbe);
    let parts = crate::io::parts::list(&job.input)?;
    if parts.len() < 2 {
        return filter_views(job, fingerprint, progress);
    }
    if job.view == Some(ViewSelect::All) {
        return Err(Error::Config(format!(
            "{}: --view all filters the views of one image; with a multi-part file, choose one part with --part",
            job.input.display()
        )));
    }
    let filter_part =
        |job: &FilterJob, progress: Progress<'_>| filter_part(job, fingerprint, false, progress);
    let chosen: Vec<usize> = match &job.part {
        None => return filter_part(job, progress), // its error lists the parts
        Some(PartSelect::All) => {
            if job.band.is_some() || to_rgbe {
                return Err(Error::Config(format!(
                    "{}: --part all writes a multi-part EXR: not with --band or a Radiance output; filter one part at a time with --part",
                    job.input.display()
                )));
            }
            parts.iter().filter(|p| !p.deep).map(|p| p.index).collect()
        }
        Some(PartSelect::Index(i)) => vec![*i],
        Some(PartSelect::Name(n)) => match parts.iter().find(|p| &p.name == n) {
            Some(p) => vec![p.index],
            None => return filter_part(job, progress), // its error names the parts
        },
    };
    if chosen.iter().any(|&i| i >= parts.len()) || chosen.is_empty() {
        return filter_part(job, progress); // its error says what is wrong
    }
    let all = matches!(job.part, Some(PartSelect::All));
    if all || (job.params.supersample == 1 && job.band.is_none() && !to_rgbe) {
        filter_and_assemble(job, fingerprint, &parts, &chosen, progress)
    } else {
        filter_one_part_of_many(job, fingerprint, &parts, chosen[0], to_rgbe, progress)
    }
}

/// The views of a single-part input: the one chosen (or the default), or
/// with `--view all` each view filtered as an image of its own and the
/// results put together into one output.
fn filter_views(
    job: &FilterJob,
    fingerprint: &Fingerprint,
    progress: Progress<'_>,
) -> Result<Report> {
    if job.view != Some(ViewSelect::All) {
        return filter_part(job, fingerprint, false, progress);
    }
    let views = crate::io::views::of(&job.input, job.part.as_ref())?;
    if views.len() < 2 {
        let mut one = job.clone();
        one.view = None;
        let mut report = filter_part(&one, fingerprint, false, progress)?;
        report.warnings.push(format!(
            "{}: --view all: the file has no other view to filter",
            job.input.display()
        ));
        return Ok(report);
    }
    let refuse = |why: &str| {
        Err(Error::Config(format!(
            "{}: --view all writes every view into one EXR: {why}",
            job.output.display()
        )))
    };
    if job.format == Some(Format::Rgbe) {
        return refuse("a Radiance picture holds one view");
    }
    if job.band.is_some() {
        return refuse("not with --band; filter one view at a time with --view NAME");
    }
    if job.output_settings.allow_lossy {
        return refuse("a lossy compression would round each view twice; choose a lossless one");
    }
    let dir = crate::io::destination::Destination::resolve(&job.output)?
        .named()
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    let tmp = tempfile::Builder::new()
        .prefix(".epfilt-views-")
        .tempdir_in(&dir)
        .map_err(|e| Error::io(&dir, e))?;
    let mut reports = Vec::new();
    let mut sources = Vec::new();
    for (i, v) in views.iter().enumerate() {
        let mut sub = job.clone();
        sub.view = Some(ViewSelect::Name(v.clone()));
        sub.output = tmp.path().join(format!("view{i}.exr"));
        sub.format = Some(Format::Exr);
        let mut r = filter_part(&sub, fingerprint, true, progress)?;
        let own = sub.output.display().to_string();
        let named = format!("{} (view {v:?})", job.output.display());
        for w in r.warnings.iter_mut() {
            *w = w.replace(&own, &named);
        }
        sources.push((sub.output.clone(), (i > 0).then(|| v.clone())));
        reports.push(r);
    }
    crate::io::views::assemble(&sources, &job.output, &views, &fingerprint.text())?;
    let mut report = reports.remove(0);
    report.output = job.output.display().to_string();
    for r in reports {
        report.add_view(r);
    }
    Ok(report)
}

/// One part of a multi-part input filtered alone: the others are named in a
/// warning and the report as left out, with why.
fn filter_one_part_of_many(
    job: &FilterJob,
    fingerprint: &Fingerprint,
    parts: &[crate::io::parts::PartInfo],
    chosen: usize,
    to_rgbe: bool,
    progress: Progress<'_>,
) -> Result<Report> {
    let mut report = filter_part(job, fingerprint, false, progress)?;
    let why = if to_rgbe {
        "a Radiance picture has one part".to_string()
    } else if job.band.is_some() {
        "a --band file holds one part".to_string()
    } else {
        format!(
            "at S = {} their display windows would differ from the filtered part's, which OpenEXR does not allow; --part all filters every part",
            job.params.supersample
        )
    };
    let left: Vec<String> = parts
        .iter()
        .filter(|p| p.index != chosen)
        .map(|p| format!("{:?}", p.name))
        .collect();
    report.warnings.push(format!(
        "{}: the other parts ({}) are not in the output: {why}",
        job.input.display(),
        left.join(", ")
    ));
    report.parts = parts
        .iter()
        .map(|p| PartReport {
            index: p.index,
            name: p.name.clone(),
            action: if p.index == chosen {
                "filtered"
            } else {
                "left out"
            }
            .into(),
            why: (p.index != chosen).then(|| why.clone()),
            report: None,
        })
        .collect();
    Ok(report)
}

/// Filter the `chosen` parts of a multi-part input, each into a file of its
/// own beside the output, then assemble the output from them and the input's
/// other parts (copied), in the input's order.
fn filter_and_assemble(
    job: &FilterJob,
    fingerprint: &Fingerprint,
    parts: &[crate::io::parts::PartInfo],
    chosen: &[usize],
    progress: Progress<'_>,
) -> Result<Report> {
    let all = matches!(job.part, Some(PartSelect::All));
    let name_of = |i: usize| parts[i].name.clone();
    let dir = crate::io::destination::Destination::resolve(&job.output)?
        .named()
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    let tmp = tempfile::Builder::new()
        .prefix(".epfilt-parts-")
        .tempdir_in(&dir)
        .map_err(|e| Error::io(&dir, e))?;
    let mut reports: Vec<Option<Report>> = vec![None; parts.len()];
    let mut sources = Vec::new();
    let mut entries = Vec::new();
    let mut warnings = Vec::new();
    for p in parts {
        // --part all: a part with nothing to filter (no colour channels, or
        // a layout epfilt does not filter) is copied at S = 1, else left out.
        let mut unfilterable = None;
        if all && !p.deep {
            let sel = PartSelect::Index(p.index);
            if let Err(Error::Unsupported { reason, .. }) =
                ExrInput::open_layer(&job.input, Some(&sel), job.layer.as_deref())
            {
                unfilterable = Some(reason);
            }
        }
        let filter_it = chosen.contains(&p.index) && unfilterable.is_none();
        let left_out = if filter_it {
            None
        } else if p.deep {
            Some("deep data cannot be written".to_string())
        } else {
            unfilterable
                .as_ref()
                .filter(|_| job.params.supersample > 1)
                .map(|reason| {
                    format!(
                        "it cannot be filtered ({reason}), and at S = {} a copy's display window would differ from the filtered parts'",
                        job.params.supersample
                    )
                })
        };
        if let Some(why) = left_out {
            warnings.push(format!(
                "{}: part {:?} is left out: {why}",
                job.input.display(),
                p.name
            ));
            entries.push((p.index, "left out", Some(why)));
            continue;
        }
        if filter_it {
            let mut sub = job.clone();
            sub.part = Some(PartSelect::Index(p.index));
            sub.output = tmp.path().join(format!("part{}.exr", p.index));
            let mut r = filter_part(&sub, fingerprint, false, progress)?;
            // What it says of its file, it says of its part of the output.
            let own = sub.output.display().to_string();
            let named = format!("{} (part {:?})", job.output.display(), p.name);
            for w in r.warnings.iter_mut() {
                *w = w.replace(&own, &named);
            }
            warnings.extend(r.warnings.iter().cloned());
            r.output = job.output.display().to_string();
            sources.push(crate::io::parts::PartSource {
                path: sub.output.clone(),
                part: 0,
                name: name_of(p.index),
            });
            reports[p.index] = Some(r);
            entries.push((p.index, "filtered", None));
        } else {
            sources.push(crate::io::parts::PartSource {
                path: job.input.clone(),
                part: p.index,
                name: name_of(p.index),
            });
            entries.push((p.index, "copied", None));
        }
    }
    // The report's own fields are the first filtered part's.
    let Some(first) = reports.iter().position(Option::is_some) else {
        return Err(Error::Unsupported {
            path: job.input.clone(),
            reason: "no part of this file has colour channels to filter".into(),
        });
    };
    crate::io::parts::assemble(&job.output, &sources)?;
    let part_reports: Vec<PartReport> = entries
        .into_iter()
        .map(|(i, action, why)| PartReport {
            index: i,
            name: name_of(i),
            action: action.into(),
            why,
            report: reports[i].clone().map(Box::new),
        })
        .collect();
    let mut report = reports[first]
        .take()
        .ok_or_else(|| Error::Internal("a multi-part run filtered no part".into()))?;
    report.warnings = warnings;
    report.parts = part_reports;
    Ok(report)
}

/// Filter one part of the input (the only one, or `job.part`) into
/// `job.output`, which records `fingerprint`. `exclusive`: one view of
/// `--view all`, which carries nothing of the others.
fn filter_part(
    job: &FilterJob,
    fingerprint: &Fingerprint,
    exclusive: bool,
    progress: Progress<'_>,
) -> Result<Report> {
    let cpu_start = cpu_seconds().unwrap_or(0.0);
    let view = match &job.view {
        Some(ViewSelect::Name(v)) => Some(v.as_str()),
        _ => None,
    };
    let mut input = ExrInput::open_view(&job.input, job.part.as_ref(), job.layer.as_deref(), view)?;
    let mut params = job.params.clone();
    // Every channel beside the beauty is carried by its rule, except into a
    // Radiance picture (R, G, B only).
    let to_rgbe = job.output_format()? == Format::Rgbe;
    let scope = crate::io::reader::view_scope(&job.input, input.header(), view, exclusive)?;
    let carried = if to_rgbe {
        Vec::new()
    } else {
        input
            .carry_channels(|name, uint| channels::rule_for(name, uint, &job.channel_rules, &scope))
    };
    for (name, rule) in &carried {
        let uint = input.header().channels.list.iter().any(|c| {
            c.name.to_string() == *name && c.sample_type == exr::meta::attribute::SampleType::U32
        });
        if uint && *rule != channels::ChannelRule::Nearest {
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
    // ep-box needs the statistics; ep-gauss at S = 1 reads them when the
    // file has them (the carriers rule), and must find them when asked to.
    let asked = job.stats != StatsRequest::default();
    let ep_gauss_px = params.method == Method::EpGauss && params.supersample == 1;
    let found = if params.method == Method::EpBox || (ep_gauss_px && params.support > 0) {
        match find_stats(&job.input, input.header(), &job.stats) {
            Ok(found) => {
                let mut aux = found.variance.clone();
                aux.extend(found.mean_y.clone());
                if let SppFrom::Channel(c) = &found.spp {
                    aux.push(c.clone());
                }
                input.add_aux_channels(&aux)?;
                Some(found)
            }
            Err(_) if params.method == Method::EpGauss && !asked => None,
            Err(e) => return Err(e),
        }
    } else {
        None
    };
    let input = input;
    let header = input.header();
    let s = job.params.supersample;
    let (w, h) = input.size();
    let origin = header.own_attributes.layer_position;
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
    let mut warnings = dropped_warnings(job, &input, &scope, to_rgbe);
    // (samples per input row, samples read per row and rows: the crop,
    // grid size, the real size when the grid is padded)
    let mut padded_from = None;
    let (full_w, w, h) = if w % s == 0 && h % s == 0 {
        (w, w, h)
    } else {
        let (cw, ch) = (w - w % s, h - h % s);
        match job.edge {
            Edge::Crop => {
                warnings.push(format!(
                    "{}: {w}x{h} samples is not a multiple of S={s}: cropped to {cw}x{ch} (--edge crop dropped the last {} sample column(s) and {} row(s))",
                    job.input.display(),
                    w - cw,
                    h - ch
                ));
                (w, cw, ch)
            }
            Edge::Pad => {
                let (pw, ph) = (w.div_ceil(s) * s, h.div_ceil(s) * s);
                warnings.push(format!(
                    "{}: {w}x{h} samples is not a multiple of S={s}: padded (--edge pad): the last output column is made of {} and the last row of {} of {s} sample columns / rows, each normalised over what exists",
                    job.input.display(),
                    if w % s == 0 { s } else { w % s },
                    if h % s == 0 { s } else { h % s },
                ));
                padded_from = Some((w, h));
                (w, pw, ph)
            }
            Edge::Exact => {
                let hint = if job.supersample_assumed {
                    " If it is at pixel resolution, give --supersample 1."
                } else {
                    ""
                };
                return Err(Error::Config(format!(
                    "{}: {w}x{h} samples is not a multiple of --supersample {s}{}: give --edge crop to drop the last partial output column and row ({}x{} pixels), or --edge pad to keep them as pixels of fewer samples ({}x{}).{hint}",
                    job.input.display(),
                    if job.supersample_assumed { " (assumed: no --supersample given)" } else { "" },
                    cw / s,
                    ch / s,
                    w.div_ceil(s),
                    h.div_ceil(s)
                )));
            }
        }
    };
    // What is read: the crop, or with padding every sample (the pipeline
    // completes them).
    let (read_w, read_h) = padded_from.unwrap_or((w, h));
    let source = || Cropped::new(input.source(), full_w, read_w, read_h);
    let source_from = |y: usize| Cropped::new(input.source_from(y), full_w, read_w, read_h);
    let channels = input.channels();
    let mut pipe_job = Job::new(
        Grid {
            in_w: w,
            in_h: h,
            s,
        },
        channels.clone(),
        input.luminance(),
    )
    .with_rules(&input.channel_rules());
    if padded_from.is_some() && pipe_job.modes.contains(&ChannelMode::Nearest) {
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
    pipe_job.padded_from = padded_from;
    if let Some(found) = &found {
        let aux = input.aux_channels();
        let at = |name: &str| channels.len() + aux.iter().position(|a| a == name).unwrap_or(0);
        if found.variance.len() == 3 && pipe_job.luminance.iter().filter(|&&l| l > 0.0).count() != 3
        {
            return Err(Error::Channels {
                path: job.input.clone(),
                reason: format!(
                    "three variance channels ({}) need an R, G, B image; name a luminance variance with --variance-channel",
                    found.variance.join(", ")
                ),
            });
        }
        pipe_job.stats = Some(StatsLayout {
            variance: found.variance.iter().map(|v| at(v)).collect(),
            kind: found.kind,
            mean_y: found.mean_y.as_deref().map(at),
            spp: match &found.spp {
                SppFrom::Fixed(n, _) => Spp::Fixed(*n),
                SppFrom::Channel(c) => Spp::Channel(at(c)),
            },
        });
        pipe_job.aux = aux;
    }
    let need =
        crate::pipeline::estimate_bytes(&pipe_job, &params, &job.pipeline, input.block_bytes());
    let limit = job.max_memory.unwrap_or_else(default_max_memory);
    if need > limit {
        let hint = if carried.is_empty() {
            String::new()
        } else {
            format!(
                "; {} of its {} channels are carried beside the beauty, and --channel-rule 'PATTERN=drop' leaves some out",
                carried.len(),
                channels.len()
            )
        };
        return Err(Error::Config(format!(
            "{}: filtering this {w}x{h} image needs about {} MiB, more than the {} MiB allowed (--max-memory){hint}",
            job.input.display(),
            need >> 20,
            limit >> 20
        )));
    }
    // ep-box: the first pass, for L_ave (Eq. 9).
    let mut l_ave = None;
    if params.method == Method::EpBox && params.ep_box.ltvis.is_none() {
        let mean = crate::pipeline::mean_luminance(source(), &pipe_job, job.pipeline.strip_rows)?;
        l_ave = Some(mean);
        let l = crate::filter::ep_box::ltvis(mean, params.ep_box.nmid);
        if !(l.is_finite() && l > 0.0) {
            return Err(Error::Value {
                path: job.input.clone(),
                reason: format!(
                    "the mean luminance is {mean:e}, so L_tvis = L_ave / N_MID is not positive; give --ltvis"
                ),
            });
        }
        params.ep_box.ltvis = Some(l);
    }
    // What the file and the report say about how they were made.
    let mut settings = params.settings();
    // Each channel's sample type: the one asked for, or its own.
    // The filtered colour channels come first (no carry rule).
    let beauty = input
        .channel_rules()
        .iter()
        .take_while(|r| r.is_none())
        .count();
    let types = crate::io::writer::output_types(&job.output_settings, header, &channels, beauty);
    settings.push(("pixel_type", crate::io::writer::types_name(&types).into()));
    // (A cropped run is the filtering of the cropped image, header and all.)
    if padded_from.is_some() {
        settings.push(("edge", "pad".into()));
    }
    if let Some(p) = &job.part {
        settings.push(("part", format!("{p:?}").into()));
    }
    if let Some(l) = &job.layer {
        settings.push(("layer", l.as_str().into()));
    }
    if !job.channel_rules.is_empty() {
        let rules: Vec<String> = job
            .channel_rules
            .iter()
            .map(|o| format!("{}={}", o.pattern(), o.rule.name()))
            .collect();
        settings.push(("channel_rules", rules.join(";").into()));
    }
    let provenance = settings
        .iter()
        .map(|(k, v)| match v {
            serde_json::Value::String(s) => format!("{k}={s}"),
            v => format!("{k}={v}"),
        })
        .collect::<Vec<_>>()
        .join(" ");
    let mut out_settings = OutputSettings {
        provenance: Some(provenance),
        ..job.output_settings.clone()
    };
    out_settings
        .extra
        .push((provenance::FINGERPRINT.into(), fingerprint.text()));
    // A cropped input's output describes the cropped window (and a display
    // window that was the data window follows it).
    let mut out_header = header.clone();
    if w != full_w || h != input.size().1 {
        let old = exr::meta::attribute::IntegerBounds::new(origin, out_header.layer_size);
        out_header.layer_size = exr::math::Vec2(w, h);
        if out_header.shared_attributes.display_window == old {
            out_header.shared_attributes.display_window =
                exr::meta::attribute::IntegerBounds::new(origin, out_header.layer_size);
        }
    }
    // --band K/N: output rows a..b, from the input rows of a window that
    // reaches `margin` output rows beyond them.
    let out_h = h / s;
    let band = match job.band {
        None => None,
        Some((k, n)) => {
            let plan = plan_band(job, header, &out_settings, &types, out_h, k, n, &params)?;
            out_header.layer_size.1 = (plan.b - plan.a) * s;
            out_header.own_attributes.layer_position.1 = origin.1 + (plan.a * s) as i32;
            out_settings
                .extra
                .push((provenance::BAND.into(), plan.label(s)));
            out_settings.extra.push((
                provenance::BAND_LEDGER.into(),
                provenance::band_ledger_text(&channels, &[], &[]),
            ));
            Some(plan)
        }
    };
    let rgbe_lines = input.rgbe().map(|r| r.lines.clone()).unwrap_or_default();
    let mut output = crate::io::output::Output::create(
        &job.output,
        to_rgbe,
        &out_header,
        s,
        &channels,
        beauty,
        &out_settings,
        &rgbe_lines,
    )?;
    // --edge pad: what each output pixel stands for (the file's rows: the
    // band's with --band).
    let coverage = padded_from.map(|real| Coverage::of(&params, pipe_job.grid, real));
    if let Some(cov) = &coverage {
        let (a, b) = band.as_ref().map_or((0, out_h), |p| (p.a, p.b));
        output.set_coverage(Coverage {
            x: cov.x.clone(),
            y: cov.y[a..b].to_vec(),
        });
    }
    let mut band_sums = None;
    let result = match &band {
        None => run(
            source(),
            &mut output,
            &pipe_job,
            &params,
            &job.pipeline,
            progress,
        ),
        Some(plan) => {
            let mut window_job = pipe_job.clone();
            window_job.grid.in_h = (plan.wb - plan.wa) * s;
            // The window's real rows: all of them, or up to the input's end.
            window_job.padded_from =
                padded_from.map(|(rw, rh)| (rw, rh.min(plan.wb * s) - plan.wa * s));
            let src = crate::pipeline::band::BandSource::new(
                source_from(plan.wa * s),
                plan.wa * s,
                plan.wb * s,
                (plan.a * s, plan.b * s),
                read_w,
                channels.len(),
            );
            let owned_in = src.owned_sums();
            let hook_in = owned_in.clone();
            let names = channels.clone();
            let s2 = (s * s) as f64;
            let hook: crate::pipeline::band::FinishHook<&mut crate::io::output::Output> =
                Box::new(move |out, sums_out| {
                    let inn = crate::pipeline::band::values(&hook_in);
                    let out_e: Vec<f64> = sums_out.iter().map(|v| v * s2).collect();
                    out.fill_attribute(
                        provenance::BAND_LEDGER,
                        provenance::band_ledger_text(&names, &inn, &out_e),
                    );
                });
            let mut sink = crate::pipeline::band::BandSink::new(
                &mut output,
                plan.a - plan.wa,
                plan.b - plan.wa,
                w / s,
                channels.len(),
                hook,
            );
            if let Some(cov) = &coverage {
                sink.set_coverage(Coverage {
                    x: cov.x.clone(),
                    y: cov.y[plan.a..plan.b].to_vec(),
                });
            }
            let r = run(
                src,
                &mut sink,
                &window_job,
                &params,
                &job.pipeline,
                progress,
            );
            let out_e: Vec<f64> = sink.sums().iter().map(|v| v * s2).collect();
            band_sums = Some(crate::report::BandReport {
                index: plan.k,
                count: plan.n,
                rows: (plan.a, plan.b),
                window: (plan.wa, plan.wb),
                energy_in_owned: crate::pipeline::band::values(&owned_in),
                energy_out_owned: out_e,
            });
            r
        }
    };
    let stats = result.map_err(|e| match e {
        Error::StreamValue { side, reason } => Error::Value {
            path: match side {
                Side::Input => job.input.clone(),
                Side::Output => job.output.clone(),
            },
            reason,
        },
        e => e,
    })?;
    for (l, mode) in stats.ledger.iter().zip(&pipe_job.modes) {
        // The foils lose energy by design: their ledger is reported, not
        // enforced; nor is it for ids and masks (the nearest sample).
        if params.method.preserves_energy()
            && *mode != ChannelMode::Nearest
            && !(l.rel_error <= LEDGER_LIMIT)
        {
            return Err(Error::Ledger {
                channel: l.channel.clone(),
                rel_error: l.rel_error,
            });
        }
    }
    let mut ledger = stats.ledger.clone();
    if output.is_lossy() {
        // A lossy codec changed what was written: the energy on disk is what
        // the file decodes to.
        let sums = output.decoded_sums()?;
        let s2 = (s * s) as f64;
        for (l, sum) in ledger.iter_mut().zip(sums) {
            l.set_on_disk(sum * s2);
        }
    }
    if let Some(n) = output.note() {
        warnings.push(format!("{}: {n}", job.output.display()));
    }
    let compression = output.compression_name();
    let output_lossy = output.is_lossy();
    output.commit()?;
    let threads = if job.pipeline.threads == 0 {
        rayon::current_num_threads()
    } else {
        job.pipeline.threads
    };
    // The method's own counts: ep-gauss in super-samples, ep-box in pixels.
    let eb = stats.ep_box().unwrap_or_default();
    let counts = match stats.method {
        MethodStats::EpGauss(g) => (g.noisy, g.spread, g.capped, g.kept),
        MethodStats::EpBox(b) => (b.noisy, b.spread, b.capped, 0),
        MethodStats::Plain => (0, 0, 0, 0),
    };
    let mut report = Report {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        method: job.params.method.name().into(),
        supersample: s,
        supersample_assumed: job.supersample_assumed,
        width: read_w,
        height: read_h,
        out_width: w / s,
        out_height: h / s,
        channel_rules: channels
            .iter()
            .zip(input.channel_rules())
            .zip(&pipe_job.luminance)
            .map(|((c, r), &l)| {
                let name = match r {
                    Some(r) => r.name(),
                    None if l != 0.0 => "colour",
                    None => "alpha",
                };
                (c.clone(), name.to_string())
            })
            .collect(),
        channels,
        dropped_channels: input.dropped_channels().to_vec(),
        tolerance: job.params.tolerance,
        radius: job.params.radius,
        max_radius: job.params.max_radius,
        seconds: stats.seconds,
        megapixels_per_second: (w * h) as f64 / stats.seconds.max(1e-9) / 1e6,
        samples_noisy: counts.0,
        samples_spread: counts.1,
        samples_capped: counts.2,
        samples_kept: counts.3,
        search_cost: stats.ep_gauss().map_or(0, |g| g.search_cost),
        spread_taps: stats.ep_gauss().map_or(0, |g| g.spread_taps),
        energy_in: vec![],
        energy_out: vec![],
        energy_rel_error: vec![],
        energy_out_rounded: vec![],
        energy_rel_error_rounded: vec![],
        digest: format!("{:016x}", stats.digest),
        tile: job.pipeline.tile,
        strip_rows: match job.pipeline.strip_rows {
            0 => crate::pipeline::auto_strip_rows(w, pipe_job.strip_channels()),
            n => n,
        },
        threads,
        peak_rss_bytes: peak_rss_bytes(),
        nonfinite_zeroed: stats.nonfinite_zeroed.clone(),
        first_nonfinite: stats.first_nonfinite.map(|(x, y, c)| {
            let name = pipe_job.channels.iter().chain(&pipe_job.aux).nth(c);
            (x, y, name.cloned().unwrap_or_default())
        }),
        stats_channels: pipe_job.aux.clone(),
        carriers_rule: found
            .as_ref()
            .filter(|_| params.method == Method::EpGauss)
            .map(|f| StatsReport {
                variance_channels: f.variance.clone(),
                variance_kind: f.kind.name().into(),
                spp_from: spp_from(&f.spp),
            }),
        ep_box: found
            .as_ref()
            .filter(|_| params.method == Method::EpBox)
            .map(|f| EpBoxReport {
                l_ave,
                l_tvis: params.ep_box.ltvis.unwrap_or(f64::NAN),
                d: params.ep_box.d,
                nmid: params.ep_box.nmid,
                confidence: params.ep_box.confidence,
                guard: params.ep_box.guard.name().into(),
                variance_channels: f.variance.clone(),
                variance_kind: f.kind.name().into(),
                spp_from: spp_from(&f.spp),
                guard_confidence: params.ep_box.guard_confidence,
                reliable: eb.reliable,
                guarded: eb.guarded,
                trimmed: eb.trimmed,
                unresolved: eb.unresolved,
                passes_allowed: params.ep_box.passes,
                passes_used: eb.passes,
            }),
        window_bytes: stats.window_bytes(),
        windows: stats.windows.clone(),
        stage_seconds: stats.stages,
        cpu_seconds: cpu_seconds().map(|c| c - cpu_start),
        version: env!("CARGO_PKG_VERSION").into(),
        settings: settings
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
        compression,
        energy_on_disk_decoded: output_lossy,
        warnings,
        band: band_sums,
        parts: Vec::new(),
    };
    report.set_ledger(&ledger);
    Ok(report)
}

/// What the output leaves out of the input's channels, said as a warning
/// (even under `-q`): other views, and what a Radiance picture cannot hold.
/// Channels the user dropped with `--channel-rule` are not repeated back.
fn dropped_warnings(
    job: &FilterJob,
    input: &ExrInput,
    scope: &channels::ViewScope,
    to_rgbe: bool,
) -> Vec<String> {
    let asked = |name: &str| job.channel_rules.iter().any(|r| r.matches(name));
    let dropped: Vec<&String> = input
        .dropped_channels()
        .iter()
        .filter(|n| !asked(n) || scope.excludes(n))
        .collect();
    let mut warnings = Vec::new();
    let (mut views, rest): (Vec<&String>, Vec<&String>) =
        dropped.into_iter().partition(|n| scope.excludes(n));
    if scope.exclusive {
        // One view of --view all: the others are filtered by their own runs.
        views.clear();
    }
    if !views.is_empty() {
        let mut names: Vec<&str> = views
            .iter()
            .filter_map(|n| scope.view_of(n).and_then(|v| scope.views.get(v)))
            .map(String::as_str)
            .collect();
        names.dedup();
        let list: Vec<&str> = views.iter().map(|s| s.as_str()).collect();
        warnings.push(format!(
            "{}: view(s) {} left out of the output ({}): --view NAME filters another view, --view all every view",
            job.input.display(),
            names.join(", "),
            list.join(", ")
        ));
    }
    if !rest.is_empty() {
        let list: Vec<&str> = rest.iter().map(|s| s.as_str()).collect();
        let why = if to_rgbe {
            "a Radiance picture holds R, G, B only; write an EXR to keep them"
        } else {
            "no rule carries them"
        };
        warnings.push(format!(
            "{}: channel(s) {} left out of the output: {why}",
            job.input.display(),
            list.join(", ")
        ));
    }
    warnings
}

/// Where a band's rows are.
#[derive(Clone, Copy, Debug)]
struct BandPlan {
    k: usize,
    n: usize,
    /// Output rows of the band.
    a: usize,
    b: usize,
    /// Output rows of the window its run reads.
    wa: usize,
    wb: usize,
    out_h: usize,
}

impl BandPlan {
    fn label(&self, s: usize) -> String {
        format!(
            "{}/{} rows {}-{} of {} S={s}",
            self.k, self.n, self.a, self.b, self.out_h
        )
    }
}

#[allow(clippy::too_many_arguments)]
fn plan_band(
    job: &FilterJob,
    header: &exr::meta::header::Header,
    settings: &OutputSettings,
    types: &[crate::pipeline::Precision],
    out_h: usize,
    k: usize,
    n: usize,
    params: &FilterParams,
) -> Result<BandPlan> {
    if n == 0 || k == 0 || k > n {
        return Err(Error::Config(format!(
            "--band {k}/{n}: the band must be 1 to N of N"
        )));
    }
    if job.output_format()? == Format::Rgbe {
        return Err(Error::Config(format!(
            "{}: --band writes EXR bands; `epfilt merge` puts them together",
            job.output.display()
        )));
    }
    let (compression, _) =
        crate::io::writer::choose_compression(&job.output, header.compression, settings, types)?;
    if types.iter().any(|&t| crate::io::is_lossy(compression, t)) {
        return Err(Error::Config(format!(
            "--band needs a lossless output compression, not {}",
            crate::io::compression_name(compression)
        )));
    }
    let unit = compression.scan_lines_per_block();
    let (a, b) = crate::pipeline::band::band_rows(out_h, unit, k - 1, n).ok_or_else(|| {
        Error::Config(format!(
            "--band {k}/{n} is empty: the output's {out_h} rows make {} blocks of {unit} rows ({}); use at most that many bands",
            out_h.div_ceil(unit),
            crate::io::compression_name(compression)
        ))
    })?;
    let m = crate::pipeline::band::margin(params);
    Ok(BandPlan {
        k,
        n,
        a,
        b,
        // A multiple of 4, so the window's 2x and 4x coarse grids
        // (--coarse-from) are the whole image's.
        wa: a.saturating_sub(m) & !3,
        wb: (b + m).min(out_h),
        out_h,
    })
}

/// Where a sample count came from, for reports.
fn spp_from(spp: &SppFrom) -> String {
    match spp {
        SppFrom::Fixed(n, from) => format!("{n} ({from})"),
        SppFrom::Channel(c) => format!("channel {c}"),
    }
}
