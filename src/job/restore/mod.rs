//! `epfilt restore`: a denoiser's output with the energy of the image it was
//! made from put back ([`crate::filter::restore`]), file to file or on
//! arrays. Both inputs are checked against each other before a row is read;
//! the output is put in place only once the ledger balances.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

mod arrays;
mod report;

pub use arrays::{restore_array, RestoreArrays};
pub use report::RestoreReport;

use crate::error::{Error, Result, Side};
use crate::filter::channels::{rule_for, ChannelRule, RuleOverride};
use crate::filter::restore::{RestoreParams, DEFAULT_SCALE, KEEP_GAIN_FILTERED};
use crate::filter::Method;
use crate::host::{cpu_seconds, default_max_memory};
use crate::io::output::OutputLayout;
use crate::io::{
    find_guides, find_stats, ExrInput, Format, GuideKind, GuideRequest, InputFile, OutputSettings,
    Selection, StatsRequest,
};
use crate::pipeline::restore::{restore_stream, EnergyLayout, RenderStats, RestoreRun};
use crate::pipeline::stream::MAX_CHANNELS;
use crate::pipeline::{
    fit_restore_memory, NonFinite, PipelineConfig, Progress, StripLayout, PROGRAM_BYTES,
};

use super::check_not_same_file;

/// `restore`'s ledger must balance to this before rounding: every energy
/// pixel's weights sum to one by construction, so what is left is the
/// rounding of a few f64 blurs and compensated sums (about 1e-15).
pub const RESTORE_LEDGER_LIMIT: f64 = 1e-12;

/// A file-to-file restore.
#[derive(Clone, Debug)]
pub struct RestoreJob {
    /// The denoiser's output.
    pub denoised: PathBuf,
    /// The image whose energy is right.
    pub energy: PathBuf,
    /// Where the result goes.
    pub output: PathBuf,
    /// The side of the blocks whose energy is kept, pixels.
    pub scale: usize,
    /// A keep gain beside the evidence (`None`: [`KEEP_GAIN_FILTERED`]
    /// where `energy` is epfilt's ep-gauss or ep-box output, else none: a
    /// render's pixels stay in place on evidence alone).
    pub keep_gain: Option<f64>,
    /// Worker threads (0: one per core).
    pub threads: usize,
    /// What to do with non-finite energy values.
    pub nonfinite: NonFinite,
    /// The output's compression and sample type.
    pub output_settings: OutputSettings,
    /// Which emission guide to read beside the energy (`--guides`,
    /// `--guide emission=LAYER`; default: found by name where the file has
    /// one).
    pub guides: GuideRequest,
    /// The energy image's part and beauty layer (`--part`, `--layer`); the
    /// part is the denoiser's output's too where it has it.
    pub select: Selection,
    /// Stops the run.
    pub cancel: Option<Arc<AtomicBool>>,
    /// Memory the run may use, bytes, by its estimate
    /// ([`crate::pipeline::restore_bytes`]); `None`:
    /// [`crate::host::default_max_memory`].
    pub max_memory: Option<u64>,
    /// The energy image's channels beside the beauty (depth, normals, ids,
    /// light AOVs) are carried into the output as it has them, bit for
    /// bit, but for those a `drop` rule matches (`--channel-rule`, the
    /// last match wins, as `filter`'s; any other rule carries), and the
    /// other views' of a stereo file.
    pub channel_rules: Vec<RuleOverride>,
}

impl RestoreJob {
    /// A job with the default scale and settings.
    pub fn new(
        denoised: impl Into<PathBuf>,
        energy: impl Into<PathBuf>,
        output: impl Into<PathBuf>,
    ) -> Self {
        RestoreJob {
            denoised: denoised.into(),
            energy: energy.into(),
            output: output.into(),
            scale: DEFAULT_SCALE,
            keep_gain: None,
            threads: 0,
            nonfinite: NonFinite::Error,
            output_settings: OutputSettings::default(),
            guides: GuideRequest::default(),
            select: Selection::default(),
            cancel: None,
            max_memory: None,
            channel_rules: Vec::new(),
        }
    }
}

/// The energy image's rows: its `channels`, and the emission guide beside
/// them where `req` finds one (read where `carried` has it, else after
/// them: [`ExrInput::read_beside`]). Found by
/// name (`auto`), a file whose guides are ambiguous, not whole or hold ids
/// gets none: the other evidence decides there. Asked for (`--guides
/// emission`, `--guide emission=LAYER`), each of those is an error naming
/// the file.
fn emission_guide(
    path: &std::path::Path,
    energy: &mut ExrInput,
    (channels, carried): (Vec<String>, &[(String, ChannelRule)]),
    req: &GuideRequest,
) -> Result<EnergyLayout> {
    let luminance = energy.luminance();
    let beauty: Vec<String> = (channels.iter().zip(&luminance))
        .filter(|(_, l)| **l != 0.0)
        .map(|(c, _)| c.clone())
        .collect();
    let mut layout = EnergyLayout::plain(channels, luminance);
    let mut kinds = req
        .kinds
        .iter()
        .flatten()
        .chain(req.named.iter().map(|(k, _)| k));
    if let Some(k) = kinds.find(|k| **k != GuideKind::Emission) {
        return Err(Error::Config(format!(
            "restore reads the emission guide only, not the {} guide (filter's)",
            k.name()
        )));
    }
    if req.none() {
        return Ok(layout);
    }
    let asked = !req.named.is_empty() || req.kinds.is_some();
    // The emission guide alone: another kind's trouble (two normal
    // layers) is no reason to lose it.
    let emission_only = GuideRequest {
        kinds: Some(vec![GuideKind::Emission]),
        named: req.named.clone(),
    };
    let bad = |why: String| Error::Channels {
        path: path.to_path_buf(),
        reason: format!("the emission guide: {why}"),
    };
    // Restore reads the default view (as the reader does).
    let scope = crate::io::reader::view_scope(path, energy.header(), None, false)?;
    let found = find_guides(path, energy.header(), &beauty, &emission_only, &scope).and_then(|f| {
        let names = f.emission.ok_or_else(|| bad("not found".into()))?;
        if let Some(c) = names.iter().find(|c| energy.is_uint(c)) {
            return Err(bad(format!("{c} holds integers (ids), not light")));
        }
        if names.len() != beauty.len() {
            return Err(bad(format!(
                "{} channels for the {} of the image ({})",
                names.len(),
                beauty.len(),
                beauty.join(", ")
            )));
        }
        Ok(names)
    });
    let names = if asked { Some(found?) } else { found.ok() };
    if let Some(names) = names {
        let mut at = energy.read_beside(&names, carried)?.into_iter();
        for (c, e) in layout.channels.iter().zip(&mut layout.emission) {
            if beauty.contains(c) {
                *e = at.next();
            }
        }
        layout.guide = names;
    }
    Ok(layout)
}

/// Per energy channel, its place among the denoiser's `denoised`: the same
/// name, else the one of the same name after its layer (a render's
/// `ViewLayer.Combined.R`, a denoiser's `R`). A channel of no colour the
/// denoiser did not write (an alpha) is `None`: it stays as the energy has
/// it. `None` where a colour channel has no match.
fn match_channels(
    energy: &[String],
    luminance: &[f64],
    denoised: &[String],
) -> Option<Vec<Option<usize>>> {
    use crate::io::reader::base_name;
    let by_name = |c: &String| denoised.iter().position(|d| d == c);
    let by_base = |c: &String| {
        let mut same = (denoised.iter().enumerate()).filter(|(_, d)| base_name(d) == base_name(c));
        match (same.next(), same.next()) {
            (Some((j, _)), None) => Some(j),
            _ => None,
        }
    };
    let picks: Vec<Option<usize>> = energy
        .iter()
        .map(|c| by_name(c).or_else(|| by_base(c)))
        .collect();
    let mut used = vec![false; denoised.len()];
    for (p, &l) in picks.iter().zip(luminance) {
        match p {
            None if l != 0.0 => return None,
            // One denoiser channel for two of the energy's.
            Some(j) if std::mem::replace(&mut used[*j], true) => return None,
            _ => {}
        }
    }
    Some(picks)
}

fn check_ledger(restored: &RestoreRun) -> Result<()> {
    for l in &restored.run.ledger {
        if !(l.rel_error <= RESTORE_LEDGER_LIMIT) {
            return Err(Error::Ledger {
                channel: l.channel.clone(),
                rel_error: l.rel_error,
            });
        }
    }
    Ok(())
}

fn config(threads: usize, nonfinite: NonFinite, cancel: Option<Arc<AtomicBool>>) -> PipelineConfig {
    PipelineConfig {
        threads,
        nonfinite,
        cancel,
        ..PipelineConfig::default()
    }
}

/// Restore `job.denoised` with `job.energy`'s energy into `job.output`.
pub fn restore_file(job: &RestoreJob, progress: Progress<'_>) -> Result<RestoreReport> {
    let plan = RestorePlan::build(job)?;
    plan.run(job, progress)
}

/// A file restore, checked and sized before a row is read:
/// [`RestorePlan::build`] opens and matches both inputs and fits the
/// memory; [`RestorePlan::run`] makes the output.
pub struct RestorePlan {
    energy: ExrInput,
    denoised: ExrInput,
    params: RestoreParams,
    keep_gain_from: String,
    /// The energy image's channels: the beauty's, then those carried.
    channels: Vec<String>,
    beauty: usize,
    carried: Vec<String>,
    /// A stereo file's other views' channels, left out.
    other_views: Vec<String>,
    /// The beauty's channels the denoiser did not write.
    copied: Vec<String>,
    layout: EnergyLayout,
    /// The variance pass read, in words (empty: none).
    variance_pass: String,
    /// Blender's render and denoised layers ([`energy_of`]).
    blender: Option<(String, String)>,
    output: OutputLayout,
    settings: OutputSettings,
    strips: StripLayout,
    cfg: PipelineConfig,
    memory: u64,
}

/// At most [`MAX_CHANNELS`] read a strip row: `written` channels and the
/// guide's, statistics' and denoiser's beside them.
fn check_channels(
    job: &RestoreJob,
    strips: &StripLayout,
    written: usize,
    carried: &[String],
) -> Result<()> {
    if strips.strip_channels() <= MAX_CHANNELS {
        return Ok(());
    }
    Err(Error::Channels {
        path: job.energy.clone(),
        reason: format!(
            "{written} channels to restore and carry, and restore reads {} in all (the energy's, its guide's and the denoiser's), at most {MAX_CHANNELS}: drop some with --channel-rule 'PATTERN=drop' (carried: {})",
            strips.strip_channels(),
            carried.join(", ")
        ),
    })
}

impl RestorePlan {
    /// Both inputs opened and matched, the energy image's guide and
    /// statistics found, the memory fitted: every check before a row is
    /// read.
    pub fn build(job: &RestoreJob) -> Result<Self> {
        let scale = RestoreParams {
            scale: job.scale,
            keep_gain: job.keep_gain,
        }
        .check()
        .map_err(Error::Config)?
        .scale;
        check_not_same_file(&job.energy, &job.output)?;
        check_not_same_file(&job.denoised, &job.output)?;
        // OpenEXR only (`-`: to standard output): a Radiance picture would
        // round the exact energy to 8 bits of mantissa.
        crate::io::format::output_format(
            &job.output,
            None,
            Some(Format::Exr),
            &[Format::Exr],
            "restore",
        )?;
        let (mut energy, blender) = energy_of(job)?;
        // A denoiser writes one image: the energy's part where it has parts
        // too, else its only one.
        let denoised = InputFile::open(&job.denoised)?;
        let part = job.select.part.as_ref();
        let denoised = denoised.input(part.filter(|_| denoised.parts().len() > 1), None, None)?;
        let (keep_gain, keep_gain_from) = keep_gain(job, &energy);
        let params = RestoreParams { scale, keep_gain };
        // The names the result takes: a channel of the file of the same name
        // is not carried beside it (Blender's denoised picture).
        let taken = written(energy.channels(), usize::MAX, blender.as_ref());
        let (carried, other_views) = carry(job, &mut energy, &taken)?;
        let read = energy.channels();
        let beauty = read.len() - carried.len();
        let picks = pair(job, &energy, &denoised, beauty)?;
        let channels = written(read, beauty, blender.as_ref());
        let settings = OutputSettings {
            provenance: Some(provenance(job, params)),
            ..job.output_settings.clone()
        };
        // The output's layout from the energy's own channels, before its
        // guide and statistics are read beside them.
        let output = OutputLayout::of(&energy, &channels, &settings);
        // A guide or a variance pass the output carries is read where it
        // is carried: restore reads the energy's carried channels as they
        // are (data: never zeroed, never altered), so it is held once.
        let rules: Vec<_> = (carried.iter())
            .map(|c| (c.clone(), ChannelRule::Nearest))
            .collect();
        let both = (channels.clone(), rules.as_slice());
        let mut layout = emission_guide(&job.energy, &mut energy, both, &job.guides)?;
        let copied = (channels[..beauty].iter().zip(&picks))
            .filter(|(_, p)| p.is_none())
            .map(|(c, _)| c.clone())
            .collect();
        // A render's own statistics measure its uncertainty, and keep in
        // place the pixels whose samples agree (not with `--guides none`).
        let mut variance_pass = String::new();
        if let Some((r, from)) = statistics(&job.energy, &mut energy, &layout.luminance, &rules)? {
            layout.stats = Some(r);
            layout.sure_keeps = !job.guides.none();
            variance_pass = from;
        }
        layout.denoised = picks;
        layout.denoised_channels = denoised.channels().len();
        layout.data = (0..channels.len()).map(|c| c >= beauty).collect();
        let mut strips = layout.strips(energy.size());
        strips.out_block_lines = output.block_lines(&job.output, &settings)?;
        check_channels(job, &strips, channels.len(), &carried)?;
        let cfg = config(job.threads, job.nonfinite, job.cancel.clone());
        let blocks = [energy.block_bytes(), denoised.block_bytes()];
        let (cfg, memory) = fit_memory(job, &strips, scale, &cfg, blocks)?;
        // The writer's batch follows the rule the estimate counted.
        let settings = OutputSettings {
            write_ahead: strips.write_ahead_bytes(&cfg),
            ..settings
        };
        Ok(RestorePlan {
            energy,
            denoised,
            params,
            keep_gain_from,
            channels,
            beauty,
            carried,
            other_views,
            copied,
            layout,
            variance_pass,
            blender,
            output,
            settings,
            strips,
            cfg,
            memory,
        })
    }

    /// The energy image's size (width, height).
    pub fn size(&self) -> (usize, usize) {
        self.energy.size()
    }

    /// Both passes, the ledger checked, the output put in place; the
    /// report.
    pub fn run(self, job: &RestoreJob, progress: Progress<'_>) -> Result<RestoreReport> {
        let RestorePlan {
            energy, denoised, ..
        } = &self;
        let mut output =
            (self.output).create(&job.output, Format::Exr, 1, &self.channels, &self.settings)?;
        let cpu_start = cpu_seconds();
        let guide = self.layout.guide.clone();
        let restored = restore_stream(
            || Ok((energy.source(), denoised.source())),
            &mut output,
            energy.size(),
            self.layout.clone(),
            self.params,
            &self.cfg,
            progress,
        )
        .map_err(|e| match e {
            Error::StreamValue { side, reason } => Error::Value {
                path: match side {
                    Side::SecondInput => job.denoised.clone(),
                    Side::Input | Side::Output => job.energy.clone(),
                },
                reason,
            },
            e => e,
        })?;
        check_ledger(&restored)?;
        output.commit()?;
        let (d, e, o) = (
            job.denoised.display().to_string(),
            job.energy.display().to_string(),
            job.output.display().to_string(),
        );
        let names = (d.as_str(), e.as_str(), o.as_str());
        let setup = (
            self.params,
            self.keep_gain_from.clone(),
            guide,
            self.copied.clone(),
        );
        let report = RestoreReport::of(
            names,
            energy.size(),
            setup,
            &restored,
            self.cfg.workers(),
            cpu_start,
        );
        Ok(RestoreReport {
            strip_rows: self.strips.strip_rows(&self.cfg),
            memory_estimate_bytes: self.memory,
            // The carried channels are copies, out of the ledger.
            ledger: report.ledger[..self.beauty].to_vec(),
            carried_channels: self.carried.clone(),
            views_left_out: self.other_views.clone(),
            blender_layers: self.blender.clone(),
            ..report.with_variance_pass(self.variance_pass.clone())
        })
    }
}

/// The keep gain beside the evidence and what chose it: the user's, a
/// gain of one over epfilt's ep-gauss or ep-box output (read from its
/// header: its fireflies are spread already), else none (a render).
fn keep_gain(job: &RestoreJob, energy: &ExrInput) -> (Option<f64>, String) {
    match job.keep_gain {
        Some(g) => (Some(g), "--keep-gain".to_string()),
        None => match crate::io::provenance::filtered_by(energy) {
            Some(m) if Method::parse(&m).is_ok_and(Method::spreads_noise) => (
                Some(KEEP_GAIN_FILTERED),
                format!("the energy image is epfilt's {m} output"),
            ),
            _ => (
                None,
                "the energy image is a render: evidence alone".to_string(),
            ),
        },
    }
}

/// What the output's header says made it.
fn provenance(job: &RestoreJob, params: RestoreParams) -> String {
    let gain = params
        .keep_gain
        .map_or("none".to_string(), |g| g.to_string());
    format!(
        "restore scale={} keep_gain={gain} denoised={}",
        params.scale,
        job.denoised
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    )
}

/// The denoiser's output against the energy image's: the same size, and
/// per energy channel its place among the denoiser's ([`match_channels`]
/// for the first `beauty`; the channels carried beside it are `None`, as
/// the energy image has them). A mismatch is an error naming the file.
fn pair(
    job: &RestoreJob,
    energy: &ExrInput,
    denoised: &ExrInput,
    beauty: usize,
) -> Result<Vec<Option<usize>>> {
    let (size, channels) = (energy.size(), energy.channels());
    let mismatch = |what: String| Error::Value {
        path: job.denoised.clone(),
        reason: format!("{what}: restore needs the denoiser's output of that very image"),
    };
    if denoised.size() != size {
        let (dw, dh) = denoised.size();
        return Err(mismatch(format!(
            "{dw}x{dh} pixels, but {} has {}x{}",
            job.energy.display(),
            size.0,
            size.1
        )));
    }
    let luminance = energy.luminance();
    let mut picks = match_channels(
        &channels[..beauty],
        &luminance[..beauty],
        &denoised.channels(),
    )
    .ok_or_else(|| {
        mismatch(format!(
            "channels {}, but {} has {}",
            denoised.channels().join(","),
            job.energy.display(),
            channels[..beauty].join(",")
        ))
    })?;
    picks.resize(channels.len(), None);
    Ok(picks)
}

/// The energy image's variance pass and sample count, found as `ep-box`
/// finds them (`None` where it has none), read after its channels: with
/// the words for the report.
fn statistics(
    path: &std::path::Path,
    energy: &mut ExrInput,
    lum: &[f64],
    carried: &[(String, ChannelRule)],
) -> Result<Option<(RenderStats, String)>> {
    let Ok(found) = find_stats(path, energy.header(), &StatsRequest::default()) else {
        return Ok(None);
    };
    // Three variances need R, G and B (`attach` refuses the rest).
    if found.variance.len() == 3 && lum.iter().filter(|&&l| l != 0.0).count() != 3 {
        return Ok(None);
    }
    let before = energy.aux_channels().len();
    let stats = found.attach(energy, path, carried)?;
    let channels = energy.aux_channels()[before..].to_vec();
    let from = format!(
        "{}; samples: {}",
        found.variance.join(", "),
        found.spp_from()
    );
    Ok(Some((RenderStats::new(stats, lum, channels), from)))
}

/// The energy image as `job` selects it. Blender with its denoiser on
/// writes the denoised picture as `S.Combined` and the render as
/// `S.Noisy Image` beside it: with no `--layer`, the render is the energy,
/// and the layers (render, denoised) are returned, the result to take the
/// denoised picture's place and names.
fn energy_of(job: &RestoreJob) -> Result<(ExrInput, Option<(String, String)>)> {
    let energy = job.select.open(&job.energy)?;
    // The layers as the default view sees them (a stereo file's
    // `ViewLayer.Combined.left` is `ViewLayer.Combined`), as `--layer`
    // takes them.
    let scope = crate::io::reader::view_scope(&job.energy, energy.header(), None, false)?;
    let first = (energy.channels().first())
        .and_then(|c| scope.seen(c))
        .unwrap_or_default();
    let combined = first.rsplit_once('.').map(|(l, _)| l.to_string());
    let noisy = combined.as_ref().and_then(|l| {
        let noisy = format!("{}Noisy Image", l.strip_suffix("Combined")?);
        let names = scope.seen_names(&crate::io::reader::channel_names(energy.header()));
        (names.iter())
            .any(|(n, _)| n.starts_with(&format!("{noisy}.")))
            .then_some(noisy)
    });
    match (noisy, combined) {
        (Some(noisy), Some(combined)) if job.select.layer.is_none() => {
            let select = Selection {
                layer: Some(noisy.clone()),
                ..job.select.clone()
            };
            Ok((select.open(&job.energy)?, Some((noisy, combined))))
        }
        _ => Ok((energy, None)),
    }
}

/// The output's channel names: those `read`, the first `beauty` of them
/// renamed from the render's layer to the denoised one's where `blender`
/// says ([`energy_of`]).
fn written(read: Vec<String>, beauty: usize, blender: Option<&(String, String)>) -> Vec<String> {
    let Some((noisy, combined)) = blender else {
        return read;
    };
    let rename = |c: &String| match c.strip_prefix(noisy.as_str()) {
        Some(rest) => format!("{combined}{rest}"),
        None => c.clone(),
    };
    (read.iter().enumerate())
        .map(|(k, c)| if k < beauty { rename(c) } else { c.clone() })
        .collect()
}

/// Carry the energy image's channels beside the beauty into the output:
/// restore changes the beauty alone, so each is copied as the file has it,
/// bit for bit, whatever its rule but `drop` (`job.channel_rules`, as
/// `filter`'s; a stereo file's other views are dropped), but one of a name
/// the result takes (`taken`). Their names, in strip order after the
/// beauty's.
///
/// Also the channels of a stereo file's other views, left out: restore
/// reads the default view.
fn carry(
    job: &RestoreJob,
    energy: &mut ExrInput,
    taken: &[String],
) -> Result<(Vec<String>, Vec<String>)> {
    let scope = crate::io::reader::view_scope(&job.energy, energy.header(), None, false)?;
    let carried = energy
        .carry_channels(|name, uint| {
            if taken.iter().any(|t| t == name) {
                // Blender's denoised picture: the result takes its place.
                return ChannelRule::Drop;
            }
            match rule_for(name, uint, &job.channel_rules, &scope) {
                ChannelRule::Drop => ChannelRule::Drop,
                // Copied, which is what `nearest` does at S = 1.
                _ => ChannelRule::Nearest,
            }
        })
        .into_iter()
        .map(|(name, _)| name)
        .collect();
    let other_views = (energy.dropped_channels().iter())
        .filter(|n| scope.excludes(n))
        .cloned()
        .collect();
    Ok((carried, other_views))
}

/// How the restore runs within `--max-memory` ([`fit_restore_memory`]):
/// refused, naming what it needs, only where its shortest strips and
/// fewest blocks read ahead would need more.
fn fit_memory(
    job: &RestoreJob,
    strips: &StripLayout,
    scale: usize,
    cfg: &PipelineConfig,
    blocks: [u64; 2],
) -> Result<(PipelineConfig, u64)> {
    let limit = job.max_memory.unwrap_or_else(default_max_memory);
    let floor = match fit_restore_memory(
        strips,
        scale,
        cfg,
        blocks,
        limit.saturating_sub(PROGRAM_BYTES),
    ) {
        Ok((cfg, bytes)) => return Ok((cfg, bytes + PROGRAM_BYTES)),
        Err(floor) => floor + PROGRAM_BYTES,
    };
    let (w, h) = (strips.grid.in_w, strips.grid.in_h);
    Err(Error::Config(format!(
        "{}: restoring this {w}x{h} image at --scale {scale} needs at least about {} MiB (the rows of {} rows of blocks, one strip and every block's target), more than the {} MiB allowed (--max-memory); a smaller --scale holds fewer rows",
        job.energy.display(),
        floor.div_ceil(1 << 20),
        crate::filter::restore::LOOKAHEAD + 2,
        limit >> 20
    )))
}
