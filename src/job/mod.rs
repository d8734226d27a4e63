//! A filtering job from file to file: validate everything first, stream, check
//! the ledger, and only then put the output in place.

pub mod array;
pub mod options;
mod plan;
pub mod restore;
mod run;

use std::path::{Path, PathBuf};
use std::sync::Arc;

pub use options::{FilterOptions, PixelType, Setting};
pub use plan::FilterPlan;
pub use run::Outcome;

use crate::error::{Error, Result};
use crate::filter::channels::{self, RuleOverride};
use crate::filter::guides::SurfaceRule;
use crate::filter::{FilterParams, Method};
use crate::io::provenance::{self, Fingerprint};
use crate::io::{
    ExrInput, Format, GuideRequest, InputFile, OutputSettings, PartSelect, StatsRequest, Verdict,
    ViewSelect,
};
use crate::pipeline::{PipelineConfig, Progress};
use crate::report::{PartReport, Report};

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
    /// ([`crate::pipeline::estimate_bytes`]); `None`: [`crate::host::default_max_memory`].
    pub max_memory: Option<u64>,
    /// Where `ep-box` finds its statistics (found by name when empty).
    pub stats: StatsRequest,
    /// What to do with an input whose size is not a multiple of S.
    pub edge: Edge,
    /// What the user left to the input (`--method`, `--supersample`):
    /// [`FilterJob::settle`] decides it from the file's header.
    pub undecided: Undecided,
    /// Which guide passes to use.
    pub guides: GuideRequest,
    /// How alike surface guides must be for a spread to cross them.
    pub surface_rule: SurfaceRule,
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

/// What settling a job decided from its input ([`FilterJob::settle`]).
#[derive(Clone, Debug, Default)]
pub struct Decided {
    /// How S and the method were decided (`None` with `--part all`: the
    /// settings as given).
    pub verdict: Option<Verdict>,
    /// Warnings from settling (options the method decided does not read).
    pub notes: Vec<String>,
}

/// A job's input, opened once, with what its output records of it and
/// what settling decided: what every plan of the run reads.
pub struct Opened<'a> {
    /// The input.
    pub file: &'a InputFile,
    /// What the output records of the input and the settings.
    pub fingerprint: Fingerprint,
    /// What the input decided.
    pub decided: Decided,
}

/// Builds a job's settings for the method and S its input decides, with
/// the options the user gave applied ([`FilterJob::settle`]), and the
/// warnings for options that method does not read.
pub type Rebuild = Arc<
    dyn Fn(Method, usize) -> Result<(FilterParams, Vec<String>)>
        + Send
        + Sync
        + std::panic::RefUnwindSafe,
>;

/// What a job leaves to its input's header.
#[derive(Clone, Default)]
pub struct Undecided {
    /// `--method` was not given.
    pub method: bool,
    /// `--supersample` was not given.
    pub supersample: bool,
    /// The settings for what the file decides (`None`: `params` as they
    /// are, whatever the file says).
    pub rebuild: Option<Rebuild>,
}

impl std::fmt::Debug for Undecided {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Undecided")
            .field("method", &self.method)
            .field("supersample", &self.supersample)
            .finish()
    }
}

impl FilterJob {
    /// The job with S and the method decided: by the user where given, else
    /// by the input's header ([`crate::io::verdict()`]: the super-sampling
    /// attribute, else 1; ep-box where the file holds variance at S = 1,
    /// else ep-gauss), its settings rebuilt for them, from `file` (this
    /// job's input, opened): its header only. The job keeps what the user
    /// asked; what the file decided comes beside it.
    pub fn settle(&self, file: &InputFile) -> Result<(FilterJob, Decided)> {
        let u = &self.undecided;
        let given_m = (!u.method).then_some(self.params.method);
        let given_s = (!u.supersample).then_some(self.params.supersample);
        let verdict = match (&u.rebuild, given_m, given_s) {
            (None, _, _) | (_, Some(_), Some(_)) => Verdict {
                supersample: self.params.supersample,
                supersample_from: "--supersample".into(),
                method: self.params.method,
                method_from: "--method".into(),
                stats: None,
            },
            // Every part with the same settings: the parts may say different
            // things, so what is not given keeps its default.
            _ if self.part == Some(PartSelect::All) => {
                return Ok((self.clone(), Decided::default()))
            }
            _ => {
                let view = match &self.view {
                    Some(ViewSelect::Name(v)) => Some(v.as_str()),
                    _ => None,
                };
                let input = file.input(self.part.as_ref(), self.layer.as_deref(), view)?;
                crate::io::verdict(&self.input, input.header(), &self.stats, given_m, given_s)?
            }
        };
        let mut job = self.clone();
        let mut notes = Vec::new();
        if let Some(rebuild) = &u.rebuild {
            (job.params, notes) = rebuild(verdict.method, verdict.supersample)?;
        }
        let decided = Decided {
            verdict: Some(verdict),
            notes,
        };
        Ok((job, decided))
    }
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
    /// single-part file, [`crate::host::default_max_memory`].
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
                write_ahead: 0,
            },
            part: None,
            layer: None,
            max_memory: None,
            stats: StatsRequest::default(),
            edge: Edge::Exact,
            undecided: Undecided::default(),
            guides: GuideRequest::default(),
            surface_rule: SurfaceRule::default(),
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
pub const WRITES: &[Format] = &[Format::Exr, Format::Rgbe, Format::Pfm];

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
            "epfilt {}; {}; format={}; compression={}; pixel_type={:?}; allow_lossy={}; part={:?}; layer={:?}; view={:?}; channel_rules={}; edge={:?}; nonfinite={:?}; stats={:?}; guides={:?}; surface={:?}",
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
            self.guides,
            self.surface_rule,
        ))
    }

    /// What this job's output records of its input (`file`, opened) and
    /// settings.
    pub fn fingerprint(&self, file: &InputFile) -> Result<Fingerprint> {
        Ok(Fingerprint::of(file, &self.settings_text()?))
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
/// or none. `file` is the job's input, opened.
pub fn existing_output(job: &FilterJob, file: &InputFile) -> Result<Existing> {
    let job = &job.settle(file)?.0;
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
    let want = job.fingerprint(file)?;
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
    filter_opened(job, &InputFile::open(&job.input)?, progress)
}

/// [`filter_file`] of `job`'s input opened as `file`: every question asked
/// of the input before the first pixel is read is answered from it.
pub fn filter_opened(job: &FilterJob, file: &InputFile, progress: Progress<'_>) -> Result<Report> {
    let (job, decided) = job.settle(file)?;
    job.params.validate()?;
    check_not_same_file(&job.input, &job.output)?;
    let job = &FilterJob {
        format: Some(job.output_format()?),
        ..job
    };
    let opened = &Opened {
        file,
        fingerprint: job.fingerprint(file)?,
        decided,
    };
    // A picture (Radiance, PFM) holds the colour alone.
    let to_rgbe = job.format.is_some_and(|f| f != Format::Exr);
    let parts = file.parts();
    if parts.len() < 2 {
        return filter_views(job, opened, progress);
    }
    if job.view == Some(ViewSelect::All) {
        return Err(Error::Config(format!(
            "{}: --view all filters the views of one image; with a multi-part file, choose one part with --part",
            job.input.display()
        )));
    }
    let filter_part =
        |job: &FilterJob, progress: Progress<'_>| filter_part(job, opened, false, progress);
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
        filter_and_assemble(job, opened, &parts, &chosen, progress)
    } else {
        filter_one_part_of_many(job, opened, &parts, chosen[0], to_rgbe, progress)
    }
}

/// The views of a single-part input: the one chosen (or the default), or
/// with `--view all` each view filtered as an image of its own and the
/// results put together into one output.
fn filter_views(job: &FilterJob, opened: &Opened<'_>, progress: Progress<'_>) -> Result<Report> {
    if job.view != Some(ViewSelect::All) {
        return filter_part(job, opened, false, progress);
    }
    let part = opened.file.input(job.part.as_ref(), None, None)?;
    let views = crate::io::reader::views(part.header());
    if views.len() < 2 {
        let mut one = job.clone();
        one.view = None;
        let mut report = filter_part(&one, opened, false, progress)?;
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
    if job.format.is_some_and(|f| f != Format::Exr) {
        return refuse("a Radiance picture or a PFM holds one view");
    }
    if job.band.is_some() {
        return refuse("not with --band; filter one view at a time with --view NAME");
    }
    if job.output_settings.allow_lossy {
        return refuse("a lossy compression would round each view twice; choose a lossless one");
    }
    let tmp = temp_dir_beside(&job.output, ".epfilt-views-")?;
    let mut reports = Vec::new();
    let mut sources = Vec::new();
    for (i, v) in views.iter().enumerate() {
        let mut sub = job.clone();
        sub.view = Some(ViewSelect::Name(v.clone()));
        sub.output = tmp.path().join(format!("view{i}.exr"));
        sub.format = Some(Format::Exr);
        let mut r = filter_part(&sub, opened, true, progress)?;
        let own = sub.output.display().to_string();
        let named = format!("{} (view {v:?})", job.output.display());
        for w in r.warnings.iter_mut() {
            *w = w.replace(&own, &named);
        }
        sources.push(sub.output.clone());
        reports.push(r);
    }
    crate::io::views::assemble(&sources, &job.output, &views, &opened.fingerprint.text())?;
    let mut report = reports.remove(0);
    report.output = job.output.display().to_string();
    for r in reports {
        report.add_view(r);
    }
    Ok(report)
}

/// A temporary folder beside what `output` names (where the files it is
/// put together from can be renamed or copied cheaply), removed when dropped.
fn temp_dir_beside(output: &Path, prefix: &str) -> Result<tempfile::TempDir> {
    let dir = crate::io::destination::Destination::resolve(output)?
        .named()
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    tempfile::Builder::new()
        .prefix(prefix)
        .tempdir_in(&dir)
        .map_err(|e| Error::io(&dir, e))
}

/// One part of a multi-part input filtered alone: the others are named in a
/// warning and the report as left out, with why.
fn filter_one_part_of_many(
    job: &FilterJob,
    opened: &Opened<'_>,
    parts: &[crate::io::parts::PartInfo],
    chosen: usize,
    to_rgbe: bool,
    progress: Progress<'_>,
) -> Result<Report> {
    let mut report = filter_part(job, opened, false, progress)?;
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
    opened: &Opened<'_>,
    parts: &[crate::io::parts::PartInfo],
    chosen: &[usize],
    progress: Progress<'_>,
) -> Result<Report> {
    let name_of = |i: usize| parts[i].name.clone();
    let tmp = temp_dir_beside(&job.output, ".epfilt-parts-")?;
    let mut reports: Vec<Option<Report>> = vec![None; parts.len()];
    let mut sources = Vec::new();
    let mut entries = Vec::new();
    let mut warnings = Vec::new();
    for p in parts {
        let (filter_it, left_out) = part_action(job, opened.file, p, chosen);
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
            let mut r = filter_part(&sub, opened, false, progress)?;
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

/// What `--part` does with part `p`: filter it (among `chosen`, and
/// filterable), or leave it out, and why (deep, or not filterable at
/// S > 1); neither: copy it.
fn part_action(
    job: &FilterJob,
    file: &InputFile,
    p: &crate::io::parts::PartInfo,
    chosen: &[usize],
) -> (bool, Option<String>) {
    let all = matches!(job.part, Some(PartSelect::All));
    // --part all: a part with nothing to filter (no colour channels, or
    // a layout epfilt does not filter) is copied at S = 1, else left out.
    let mut unfilterable = None;
    if all && !p.deep {
        let sel = PartSelect::Index(p.index);
        if let Err(Error::Unsupported { reason, .. }) =
            file.input(Some(&sel), job.layer.as_deref(), None)
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
    (filter_it, left_out)
}

/// Filter one part of the input (the only one, or `job.part`) into
/// `job.output`, which records `fingerprint`. `exclusive`: one view of
/// `--view all`, which carries nothing of the others.
fn filter_part(
    job: &FilterJob,
    opened: &Opened<'_>,
    exclusive: bool,
    progress: Progress<'_>,
) -> Result<Report> {
    FilterPlan::build(job, opened, exclusive)?.run(progress)
}

/// What the output leaves out of the input's channels, said as a warning
/// (even under `-q`): other views, and what a Radiance picture cannot hold.
/// Channels the user dropped with `--channel-rule` are not repeated back.
pub(crate) fn dropped_warnings(
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
