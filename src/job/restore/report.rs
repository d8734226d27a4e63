//! What a restore did: the `--report` fields.

use crate::filter::restore::{LevelSummary, RestoreParams};
use crate::host::{cpu_seconds, peak_rss_bytes};
use crate::pipeline::counts::{MethodCounts, RestoreCounts};
use crate::pipeline::ledger::ChannelLedger;
use crate::pipeline::restore::RestoreRun;
use crate::pipeline::stage::WindowUse;
use crate::pipeline::StageSeconds;

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
    /// A stereo file's other views' channels, left out of the result
    /// (restore reads the default view).
    pub views_left_out: Vec<String>,
    /// Blender with its denoiser on: the render's layer read as the energy
    /// (`Noisy Image`) and the denoised layer whose names the result takes
    /// (`Combined`); `None` otherwise.
    pub blender_layers: Option<(String, String)>,
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
    pub(super) fn of(
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
            views_left_out: Vec::new(),
            blender_layers: None,
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

    /// The report with the energy image's variance pass read (in words;
    /// empty: none, and the residual measured the uncertainty).
    pub(super) fn with_variance_pass(self, variance_pass: String) -> Self {
        let uncertainty_from = if variance_pass.is_empty() {
            self.uncertainty_from
        } else {
            "variance pass".to_string()
        };
        RestoreReport {
            variance_pass,
            uncertainty_from,
            ..self
        }
    }
}
