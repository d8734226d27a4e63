//! `epfilt restore`'s pipeline: the energy image's energy put back into
//! the denoiser's output ([`crate::filter::restore`]), in two passes over
//! both inputs.
//!
//! 1. **The survey** (`survey.rs`): every value checked and each `--scale`
//!    block's sums taken (the render's energy less what is kept in place,
//!    the denoiser's, the render's variance). The targets
//!    ([`crate::filter::restore::targets()`]) need them all: the whole
//!    image's total is the top of their tree.
//! 2. **The restore** ([`RestoreStage`]), behind the skeleton as the
//!    filters are: each block's target carried in the denoiser's shape.
//!
//! The strips hold the energy image's channels, then its guide's and its
//! statistics', then the denoiser's (the books' ledger counts the first
//! ones: the total it checks is the energy image's).

use super::memory::{MemorySink, MemorySource};
use super::pair::{Pair, Pick};
use super::stream::{Streamer, MAX_CHANNELS};
use super::{
    run_streamer, PipelineConfig, Precision, Progress, RunStats, Sink, Source, StripLayout,
};
use crate::error::{Error, Result};
use crate::filter::restore::{targets, FieldRows, LevelSummary, RestoreParams};
use crate::geometry::Grid;

pub(super) mod estimate;
mod kept;
mod stage;
mod stats;
mod survey;

use kept::KeptLayout;
pub use stage::RestoreStage;
pub use stats::RenderStats;
pub use survey::Survey;

/// Workers per output block restore's writer compresses at once, at the
/// least: one each. Restore's own work is light beside its two inputs'
/// decoding and its output's compression, which is what its workers wait
/// on; one block for two workers was slower on two.
pub const RESTORE_WORKERS_PER_WRITE_BLOCK: usize = 1;

/// The energy image's rows: its `channels`, then the channels of its
/// emission guide and statistics that are not among them (a pass the
/// energy carries is read where it is carried, once).
#[derive(Clone, Debug)]
pub struct EnergyLayout {
    /// The energy's channels, the ones restored.
    pub channels: Vec<String>,
    /// Per channel, its emission guide's place in the rows: among the
    /// channels where the energy carries it, else after them.
    pub emission: Vec<Option<usize>>,
    /// The luminance weights (for the layout).
    pub luminance: Vec<f64>,
    /// The guide's channel names, in their order (for the report).
    pub guide: Vec<String>,
    /// Per channel, its place among the denoiser's channels; `None`: the
    /// denoiser did not write it (an alpha), and it stays as the energy
    /// image has it.
    pub denoised: Vec<Option<usize>>,
    /// The channels of the denoiser's rows.
    pub denoised_channels: usize,
    /// The energy image's statistics (its variance pass), read after its
    /// channels (and its guide's) where it has them: the uncertainty of its
    /// blocks, and evidence that keeps a pixel whose samples agree.
    pub stats: Option<RenderStats>,
    /// Whether agreeing samples keep a pixel in place (`--guides none`:
    /// not; the statistics still measure the blocks' uncertainty).
    pub sure_keeps: bool,
    /// Per channel, whether it is data carried beside the beauty (copied,
    /// with no denoiser's pick): out of the ledger, and its non-finite
    /// values (a sky's depth) pass as they are.
    pub data: Vec<bool>,
}

impl EnergyLayout {
    /// `channels` without an emission guide.
    pub fn plain(channels: Vec<String>, luminance: Vec<f64>) -> Self {
        EnergyLayout {
            emission: vec![None; channels.len()],
            denoised: (0..channels.len()).map(Some).collect(),
            denoised_channels: channels.len(),
            data: vec![false; channels.len()],
            stats: None,
            sure_keeps: true,
            channels,
            luminance,
            guide: Vec::new(),
        }
    }

    /// The strips of a `w x h` restore: the energy's channels, its guide's
    /// and the denoiser's ([`crate::pipeline::restore_bytes`] sizes them).
    pub fn strips(&self, (w, h): (usize, usize)) -> StripLayout {
        let grid = Grid {
            in_w: w,
            in_h: h,
            s: 1,
        };
        let channels = &self.channels;
        let mut layout = StripLayout::new(grid, channels.clone(), self.luminance.clone());
        layout.data = self.data.clone();
        layout.workers_per_write_block = RESTORE_WORKERS_PER_WRITE_BLOCK;
        let guide = (channels.iter().zip(&self.emission))
            .filter(|(_, e)| e.is_some_and(|k| k >= channels.len()))
            .map(|(c, _)| format!("emission.{c}"));
        let stats = self.stats.iter().flat_map(|r| r.channels.iter().cloned());
        layout.aux = guide
            .chain(stats)
            .chain(
                channels[..self.denoised_slots()]
                    .iter()
                    .map(|c| format!("denoised.{c}")),
            )
            .collect();
        layout
    }

    /// Channels of the denoiser's half of a strip: one per energy channel up
    /// to the last one restored (the data carried after it is never read
    /// there; a render's dozens of passes would double the strips).
    fn denoised_slots(&self) -> usize {
        self.data.iter().rposition(|d| !d).map_or(0, |i| i + 1)
    }

    /// What the kept part reads (both passes): the guide, the statistics,
    /// which channels are copied, and the gain.
    fn kept_layout(&self, params: RestoreParams) -> KeptLayout {
        // Data is the energy's, whatever the denoiser wrote.
        let copied = (self.denoised.iter().zip(&self.data))
            .map(|(p, &d)| p.is_none() || d)
            .collect();
        KeptLayout {
            emission: self.emission.clone(),
            copied,
            stats: self.stats.clone(),
            sure_keeps: self.sure_keeps,
            gain: params.keep_gain,
        }
    }

    /// Channels the energy's rows hold: its own, then the guide's and the
    /// statistics' read after them.
    fn row_channels(&self) -> usize {
        let nch = self.channels.len();
        let guide = self.emission.iter().flatten().filter(|&&k| k >= nch);
        let stats = self.stats.as_ref().map_or(0, |r| r.channels.len());
        nch + guide.count() + stats
    }
}

/// What a restore did beyond the run: per level of blocks from the
/// finest up, how the targets came out (summed over channels), and the
/// first pass's seconds.
#[derive(Clone, Debug)]
pub struct RestoreRun {
    /// The second pass: the books, the counts, the timings.
    pub run: RunStats,
    /// Per level, from `--scale` blocks up to the whole image.
    pub levels: Vec<LevelSummary>,
    /// Seconds of the first pass (checking, the blocks' sums).
    pub survey_seconds: f64,
}

/// Restore the denoiser's output with the energy image's energy by
/// `params` into `sink`: both `w x h`; the energy's rows as `energy_layout`
/// says, the denoiser's of its channels; the books' ledger counts the
/// energy. `open` gives both sources from their first row, once per pass.
#[allow(clippy::too_many_arguments)]
pub fn restore_stream<A: Source, B: Source, K: Sink>(
    mut open: impl FnMut() -> Result<(A, B)>,
    sink: K,
    (w, h): (usize, usize),
    energy_layout: EnergyLayout,
    params: RestoreParams,
    cfg: &PipelineConfig,
    progress: Progress<'_>,
) -> Result<RestoreRun> {
    let nch = energy_layout.channels.len();
    let na = energy_layout.row_channels();
    let slots = energy_layout.denoised_slots();
    if w == 0 || h == 0 || nch == 0 || na + slots > MAX_CHANNELS {
        return Err(Error::Config(format!(
            "restore needs a non-empty image with at most {MAX_CHANNELS} channels in all (the energy's, its guide's and the denoiser's), not {w}x{h} with {}",
            na + slots
        )));
    }
    let params = params.check().map_err(Error::Config)?;
    let layout = energy_layout.strips((w, h));
    let strip_rows = layout.strip_rows(cfg);
    let kept = energy_layout.kept_layout(params);
    // A channel the denoiser did not write has the energy's own values in
    // its place: the stage keeps them as they are.
    let picks: Vec<Pick> = (energy_layout.denoised[..slots].iter().enumerate())
        .map(|(ch, p)| p.map_or(Pick::First(ch), Pick::Second))
        .collect();
    let nd = energy_layout.denoised_channels;
    let mut pair = || -> Result<Pair<A, B>> {
        let (a, b) = open()?;
        Ok(Pair::new(a, b, w, (na, nd), picks.clone()))
    };
    // Each pass is half the progress.
    let half = |done: usize, _| progress(done, 2 * h);
    let plan = survey::SurveyPlan {
        kept: kept.clone(),
        names: &energy_layout.channels,
        data: &energy_layout.data,
        row_channels: layout.strip_channels(),
        size: (w, h),
        scale: params.scale,
        nonfinite: cfg.nonfinite,
    };
    let surveyed = survey::survey(pair()?, plan, cfg, strip_rows, &half)?;
    let (nbx, nby) = (w.div_ceil(params.scale), h.div_ceil(params.scale));
    let survey_seconds = surveyed.seconds;
    let mut levels: Vec<LevelSummary> = Vec::new();
    // Each channel's sums give way to its targets and shape as they are
    // solved: what the second pass holds is two words per block.
    let fields = (surveyed.sums.into_iter())
        .map(|sums| {
            if sums.is_empty() {
                return FieldRows::new(
                    w,
                    h,
                    params.scale,
                    vec![0.0; nbx * nby],
                    vec![0.0; nbx * nby],
                );
            }
            let shape: Vec<f64> = sums.iter().map(|s| s.shape).collect();
            let (t, l) = targets(&sums, nbx, nby, params.scale);
            drop(sums);
            merge_levels(&mut levels, l);
            FieldRows::new(w, h, params.scale, t, shape)
        })
        .collect();
    let stage = RestoreStage::new(kept, (w, h), fields, surveyed.counts);
    let streamer = Streamer::of_stage(
        &layout,
        Box::new(stage),
        cfg.nonfinite,
        sink.precisions(nch),
    );
    let second = |done: usize, _| progress(h + done, 2 * h);
    let run = run_streamer(pair()?, sink, &layout, streamer, cfg, &second)?;
    Ok(RestoreRun {
        run,
        levels,
        survey_seconds,
    })
}

/// Add one channel's levels into `levels` (the first channel's as they are).
fn merge_levels(levels: &mut Vec<LevelSummary>, l: Vec<LevelSummary>) {
    if levels.is_empty() {
        *levels = l;
        return;
    }
    for (a, b) in levels.iter_mut().zip(l) {
        // The channels' mean squares, weighed by their blocks.
        let n = (a.blocks + b.blocks) as f64;
        a.render_rse =
            ((a.render_rse.powi(2) * a.blocks as f64 + b.render_rse.powi(2) * b.blocks as f64) / n)
                .sqrt();
        a.blocks += b.blocks;
        a.following_render += b.following_render;
        a.exact += b.exact;
    }
}

/// [`restore_stream`] of two whole images in memory (planar
/// `[row][channel][x]`; the energy's rows as `energy_layout` says),
/// rounded to `precision`: the output and the run.
pub fn restore_planar(
    energy: Vec<f32>,
    denoised: Vec<f32>,
    (w, h): (usize, usize),
    energy_layout: EnergyLayout,
    params: RestoreParams,
    cfg: &PipelineConfig,
    precision: Precision,
) -> Result<(Vec<f32>, RestoreRun)> {
    let nch = energy_layout.channels.len();
    let na = energy_layout.row_channels();
    let nd = energy_layout.denoised_channels;
    let pixels = w.checked_mul(h);
    let n = pixels.and_then(|p| p.checked_mul(nd));
    if pixels.and_then(|p| p.checked_mul(na)) != Some(energy.len()) || n != Some(denoised.len()) {
        return Err(Error::Config(format!(
            "{} energy and {} denoised values for a {w}x{h} image of {nch} channels ({na} with the guide and statistics)",
            energy.len(),
            denoised.len(),
        )));
    }
    let mut sink = MemorySink::with_precision(precision);
    let (energy, denoised) = (
        MemorySource::new(energy, na * w),
        MemorySource::new(denoised, nd * w),
    );
    let run = restore_stream(
        || Ok((energy.clone(), denoised.clone())),
        &mut sink,
        (w, h),
        energy_layout,
        params,
        cfg,
        &|_, _| {},
    )?;
    Ok((sink.data, run))
}

#[cfg(test)]
mod tests;
