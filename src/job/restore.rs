//! `epfilt restore`: a denoiser's output with the energy of the image it was
//! made from put back ([`crate::filter::restore`]), file to file or on
//! arrays. Both inputs are checked against each other before a row is read;
//! the output is put in place only once the ledger balances.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::error::{Error, Result, Side};
use crate::filter::channels::{rule_for, ChannelRule, RuleOverride};
use crate::filter::restore::{LevelSummary, RestoreParams, DEFAULT_SCALE, KEEP_GAIN_FILTERED};
use crate::filter::Method;
use crate::host::{cpu_seconds, default_max_memory, peak_rss_bytes};
use crate::io::output::OutputLayout;
use crate::io::{
    find_guides, find_stats, ExrInput, Format, GuideKind, GuideRequest, OutputSettings, Selection,
    StatsRequest,
};
use crate::pipeline::counts::{MethodCounts, RestoreCounts};
use crate::pipeline::ledger::ChannelLedger;
use crate::pipeline::restore::{
    restore_planar, restore_stream, EnergyLayout, RenderStats, RestoreRun,
};
use crate::pipeline::stage::WindowUse;
use crate::pipeline::stream::MAX_CHANNELS;
use crate::pipeline::{
    fit_restore_memory, NonFinite, PipelineConfig, Precision, Progress, StageSeconds, StripLayout,
    PROGRAM_BYTES,
};

use super::array::{interleaved, planar, ArrayStats};
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

/// What a restore did (`--report`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct RestoreReport {
    /// The denoiser's output, the energy image and the result (`<array>`
    /// for arrays).
    pub denoised: String,
    /// The image whose energy was kept.
    pub energy: String,
    /// The result.
    pub output: String,
    /// Width and height in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The side of the blocks whose energy is kept, pixels.
    pub scale: usize,
    /// Input rows per strip (fewer under a small `--max-memory`).
    pub strip_rows: usize,
    /// What the run was estimated to hold, with the strips chosen
    /// (checked against `--max-memory`; 0 where not estimated: arrays).
    pub memory_estimate_bytes: u64,
    /// The keep gain beside the evidence, and what chose it: `--keep-gain`,
    /// or the energy image being epfilt's output of a method that spreads
    /// fireflies; `null` for a render (its pixels stay in place on evidence
    /// alone: the guide, agreeing samples, the denoiser's own peak).
    pub keep_gain: Option<f64>,
    /// What chose [`Self::keep_gain`].
    pub keep_gain_from: String,
    /// The energy image's emission guide (its channels, or `emission` for
    /// an array), whose light beyond the denoiser's share around stays in
    /// place; empty where there is none.
    pub emission_guide: Vec<String>,
    /// The energy image's variance pass and sample count, where it has
    /// them: the uncertainty of its blocks' energy, and evidence that keeps
    /// a pixel whose samples agree (its relative standard error under one
    /// half; not with `--guides none`); empty where none was read.
    pub variance_pass: String,
    /// What measured the render's uncertainty: `variance pass`, or
    /// `residual` (its difference from the denoiser's output, where it has
    /// no variance pass).
    pub uncertainty_from: String,
    /// Per level of blocks, from `--scale` up to the whole image: its block
    /// side (pixels), the blocks (over channels), those whose target lies
    /// nearer the render's energy than the denoiser's, and those whose
    /// target is the render's energy exactly.
    pub levels: Vec<LevelSummary>,
    /// The block sides at which every block's energy is the render's (the
    /// whole image's always; its side is the image's, rounded up to a
    /// power of two times `--scale`).
    pub exact_scales: Vec<usize>,
    /// The energy image's channels the denoiser did not write (an alpha),
    /// kept as the energy image has them.
    pub copied_channels: Vec<String>,
    /// The energy image's channels beside the beauty (depth, normals, ids,
    /// light AOVs), carried into the result as it has them.
    pub carried_channels: Vec<String>,
    /// Per channel: the energy image's total, the result's, their relative
    /// difference (before and after rounding).
    pub ledger: Vec<ChannelLedger>,
    /// Where the denoiser's output could not carry the energy alone.
    pub counts: RestoreCounts,
    /// Of the energy, the share kept in place.
    pub kept_share: f64,
    /// Energy values that were not finite, zeroed (`--nonfinite zero`).
    pub nonfinite_zeroed: u64,
    /// FNV-1a digest of the unrounded result.
    pub digest: String,
    /// Seconds of the run.
    pub seconds: f64,
    /// Seconds each stage of the second pass was busy: reading and
    /// decoding both inputs, restoring, encoding and writing.
    pub stage_seconds: StageSeconds,
    /// Seconds of the first pass (both inputs read and checked, the
    /// blocks' sums taken).
    pub survey_seconds: f64,
    /// CPU seconds (user + system) the run used, where the platform tells
    /// it.
    pub cpu_seconds: Option<f64>,
    /// Worker threads.
    pub threads: usize,
    /// The process's peak resident memory.
    pub peak_rss_bytes: Option<u64>,
    /// Every rolling window: its name, the most rows it held and the bytes
    /// of a row.
    pub windows: Vec<WindowUse>,
}

impl RestoreReport {
    fn of(
        job: (&str, &str, &str),
        (w, h): (usize, usize),
        (params, keep_gain_from, emission_guide, copied_channels): (
            RestoreParams,
            String,
            Vec<String>,
            Vec<String>,
        ),
        restored: &RestoreRun,
        threads: usize,
        cpu_start: Option<f64>,
    ) -> Self {
        let stats = &restored.run;
        let counts = match stats.method {
            MethodCounts::Restore(c) => c,
            _ => RestoreCounts::default(),
        };
        let mass: f64 = stats.ledger.iter().map(|l| l.mass_in).sum();
        RestoreReport {
            denoised: job.0.into(),
            energy: job.1.into(),
            output: job.2.into(),
            width: w,
            height: h,
            scale: params.scale,
            strip_rows: 0,
            memory_estimate_bytes: 0,
            keep_gain: params.keep_gain,
            keep_gain_from,
            emission_guide,
            copied_channels,
            variance_pass: String::new(),
            uncertainty_from: "residual".into(),
            exact_scales: (restored.levels.iter())
                .filter(|l| l.exact == l.blocks)
                .map(|l| l.side)
                .collect(),
            levels: restored.levels.clone(),
            carried_channels: Vec::new(),
            ledger: stats.ledger.clone(),
            kept_share: if mass > 0.0 {
                counts.kept_energy / mass
            } else {
                0.0
            },
            counts,
            nonfinite_zeroed: stats.nonfinite_zeroed.iter().sum(),
            digest: format!("{:016x}", stats.digest),
            seconds: stats.seconds + restored.survey_seconds,
            stage_seconds: stats.stages,
            survey_seconds: restored.survey_seconds,
            cpu_seconds: cpu_seconds().zip(cpu_start).map(|(c, s)| c - s),
            threads,
            peak_rss_bytes: peak_rss_bytes(),
            windows: stats.windows.clone(),
        }
    }
}

/// The energy image's rows: its `channels`, and the emission guide beside
/// them where `req` finds one (read as guide channels after them). Found by
/// name (`auto`), a file whose guides are ambiguous, not whole or hold ids
/// gets none: the keep gain alone decides there. Asked for (`--guides
/// emission`, `--guide emission=LAYER`), each of those is an error naming
/// the file.
fn emission_guide(
    path: &std::path::Path,
    energy: &mut ExrInput,
    channels: Vec<String>,
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
    let found = find_guides(path, energy.header(), &beauty, &emission_only).and_then(|f| {
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
        energy.add_aux_channels(&names)?;
        let mut k = 0;
        for (c, e) in layout.channels.iter().zip(&mut layout.emission) {
            if beauty.contains(c) {
                *e = Some(k);
                k += 1;
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
    // Both checked before anything is read.
    let asked = RestoreParams {
        scale: job.scale,
        keep_gain: job.keep_gain,
    }
    .check()
    .map_err(Error::Config)?;
    let scale = asked.scale;
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
    let mut energy = job.select.open(&job.energy)?;
    // A denoiser writes one image: the energy's part where it has parts
    // too, else its only one.
    let part = job.select.part.as_ref();
    let denoised = match part.map(|p| ExrInput::open(&job.denoised, Some(p))) {
        Some(Ok(d)) => d,
        _ => ExrInput::open(&job.denoised, None)?,
    };
    let (keep_gain, keep_gain_from) = match job.keep_gain {
        Some(g) => (Some(g), "--keep-gain".to_string()),
        None => match crate::io::provenance::filtered_by(&energy) {
            Some(m) if Method::parse(&m).is_ok_and(Method::spreads_noise) => (
                Some(KEEP_GAIN_FILTERED),
                format!("the energy image is epfilt's {m} output"),
            ),
            _ => (
                None,
                "the energy image is a render: evidence alone".to_string(),
            ),
        },
    };
    let params = RestoreParams { scale, keep_gain };
    let carried = carry(job, &mut energy)?;
    let (size, channels) = (energy.size(), energy.channels());
    let beauty = channels.len() - carried.len();
    let picks = pair(job, &energy, &denoised, beauty)?;
    let gain = keep_gain.map_or("none".to_string(), |g| g.to_string());
    let provenance = format!(
        "restore scale={scale} keep_gain={gain} denoised={}",
        job.denoised
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    let settings = OutputSettings {
        provenance: Some(provenance),
        ..job.output_settings.clone()
    };
    // The output's layout from the energy's own channels, before its guide
    // is read beside them.
    let layout = OutputLayout::of(&energy, &channels, &settings);
    let mut energy_layout =
        emission_guide(&job.energy, &mut energy, channels.clone(), &job.guides)?;
    let copied = (channels[..beauty].iter().zip(&picks))
        .filter(|(_, p)| p.is_none())
        .map(|(c, _)| c.clone())
        .collect();
    // A render's own statistics measure its uncertainty, and keep in place
    // the pixels whose samples agree (not with `--guides none`).
    let mut variance_pass = String::new();
    if let Some((r, from)) = statistics(&job.energy, &mut energy, &energy_layout.luminance)? {
        energy_layout.stats = Some(r);
        energy_layout.sure_keeps = !job.guides.none();
        variance_pass = from;
    }
    energy_layout.denoised = picks;
    energy_layout.denoised_channels = denoised.channels().len();
    energy_layout.data = (0..channels.len()).map(|c| c >= beauty).collect();
    let guide = energy_layout.guide.clone();
    let cfg = config(job.threads, job.nonfinite, job.cancel.clone());
    // Sized before the output exists or a row is read.
    let strips = energy_layout.strips(size);
    if strips.strip_channels() > MAX_CHANNELS {
        return Err(Error::Channels {
            path: job.energy.clone(),
            reason: format!(
                "{} channels to restore and carry, and restore reads {} in all (the energy's, its guide's and the denoiser's), at most {MAX_CHANNELS}: drop some with --channel-rule 'PATTERN=drop' (carried: {})",
                channels.len(),
                strips.strip_channels(),
                carried.join(", ")
            ),
        });
    }
    let blocks = [energy.block_bytes(), denoised.block_bytes()];
    let (cfg, memory) = fit_memory(job, &strips, scale, &cfg, blocks)?;
    let mut output = layout.create(&job.output, false, 1, &channels, &settings)?;
    let cpu_start = cpu_seconds();
    let stats = restore_stream(
        || Ok((energy.source(), denoised.source())),
        &mut output,
        size,
        energy_layout,
        params,
        &cfg,
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
    check_ledger(&stats)?;
    output.commit()?;
    let report = RestoreReport::of(
        (
            &job.denoised.display().to_string(),
            &job.energy.display().to_string(),
            &job.output.display().to_string(),
        ),
        size,
        (params, keep_gain_from, guide, copied),
        &stats,
        cfg.workers(),
        cpu_start,
    );
    Ok(RestoreReport {
        strip_rows: strips.strip_rows(&cfg),
        memory_estimate_bytes: memory,
        // The carried channels are copies, out of the ledger.
        ledger: report.ledger[..beauty].to_vec(),
        uncertainty_from: if variance_pass.is_empty() {
            report.uncertainty_from.clone()
        } else {
            "variance pass".into()
        },
        variance_pass,
        carried_channels: carried,
        ..report
    })
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
) -> Result<Option<(RenderStats, String)>> {
    let Ok(found) = find_stats(path, energy.header(), &StatsRequest::default()) else {
        return Ok(None);
    };
    // Three variances need R, G and B (`attach` refuses the rest).
    if found.variance.len() == 3 && lum.iter().filter(|&&l| l != 0.0).count() != 3 {
        return Ok(None);
    }
    let before = energy.aux_channels().len();
    let stats = found.attach(energy, path)?;
    let channels = energy.aux_channels()[before..].to_vec();
    let from = format!(
        "{}; samples: {}",
        found.variance.join(", "),
        found.spp_from()
    );
    Ok(Some((RenderStats::new(stats, lum, channels), from)))
}

/// Carry the energy image's channels beside the beauty into the output:
/// restore changes the beauty alone, so each is copied as the file has it,
/// bit for bit, whatever its rule but `drop` (`job.channel_rules`, as
/// `filter`'s; a stereo file's other views are dropped). Their names, in
/// strip order after the beauty's.
fn carry(job: &RestoreJob, energy: &mut ExrInput) -> Result<Vec<String>> {
    let scope = crate::io::reader::view_scope(&job.energy, energy.header(), None, false)?;
    let carried = energy
        .carry_channels(
            |name, uint| match rule_for(name, uint, &job.channel_rules, &scope) {
                ChannelRule::Drop => ChannelRule::Drop,
                // Copied, which is what `nearest` does at S = 1.
                _ => ChannelRule::Nearest,
            },
        )
        .into_iter()
        .map(|(name, _)| name)
        .collect();
    Ok(carried)
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
        layout.emission = (0..nch).map(Some).collect();
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
    let uncertainty_from = if variance_pass.is_empty() {
        report.uncertainty_from.clone()
    } else {
        "variance pass".to_string()
    };
    Ok((
        inter,
        RestoreReport {
            variance_pass,
            uncertainty_from,
            ..report
        },
    ))
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
