//! Restore's first pass: both inputs read once, each `--scale` block's
//! sums taken (the render's energy less what is kept in place, the
//! denoiser's, the render's variance) and every value checked, before a
//! row is written. The targets need the whole image: its total is the top
//! of their tree.

use std::time::Instant;

use rayon::iter::{IntoParallelIterator, ParallelIterator};

use super::kept::{Kept, KeptLayout};
use crate::error::{Error, Result, Side};
use crate::filter::restore::{shape, BlockSums};
use crate::pipeline::counts::RestoreCounts;
use crate::pipeline::window::RowWindow;
use crate::pipeline::Strip;
use crate::pipeline::{NonFinite, PipelineConfig, Progress, ReadAhead, Source};

/// What the first pass found: per channel, every block's sums (row-major),
/// and what it counted.
#[derive(Clone, Debug)]
pub struct Survey {
    /// Per energy channel (empty for the channels the denoiser did not
    /// write: they are copied), `nbx * nby` blocks.
    pub sums: Vec<Vec<BlockSums>>,
    /// The denoiser's non-finite and negative values.
    pub counts: RestoreCounts,
    /// Seconds the pass took.
    pub seconds: f64,
}

/// The first pass's geometry and rules.
pub(super) struct SurveyPlan<'a> {
    pub kept: KeptLayout,
    /// The energy's channels (names for errors) and which are data.
    pub names: &'a [String],
    pub data: &'a [bool],
    /// Channels of an input row.
    pub row_channels: usize,
    pub size: (usize, usize),
    pub scale: usize,
    pub nonfinite: NonFinite,
}

/// Read `source` (the pair's strips) once and take every block's sums.
pub(super) fn survey<S: Source>(
    source: S,
    plan: SurveyPlan<'_>,
    cfg: &PipelineConfig,
    strip_rows: usize,
    progress: Progress<'_>,
) -> Result<Survey> {
    let start = Instant::now();
    let pool = crate::pipeline::thread_pool(cfg.threads)?;
    let io_pool = crate::pipeline::runner::io_pool(cfg.threads)?;
    let io = io_pool.as_ref().unwrap_or(&pool);
    let window = |block_bytes| match cfg.window_blocks {
        0 => crate::pipeline::window_blocks(cfg, block_bytes),
        n => n as u64,
    };
    // The strips' buffers go back to the reader, as in any run.
    let (recycle, recycled) = crossbeam_channel::bounded(crate::pipeline::STRIPS_RECYCLED);
    let ahead = ReadAhead {
        strip_rows,
        window_blocks: &window,
        recycled: Some(recycled),
    };
    let (tx, rx) = crossbeam_channel::bounded::<Result<Strip>>(2);
    let h = plan.size.1;
    let mut state = Sums::new(plan);
    state.input.recycle_strips(recycle);
    std::thread::scope(|scope| {
        let reader =
            scope.spawn(move || crate::pipeline::runner::read_strips(source, io, ahead, tx));
        let mut result = Ok(());
        for strip in rx.iter() {
            if cfg
                .cancel
                .as_ref()
                .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed))
            {
                result = Err(Error::Interrupted);
                break;
            }
            result = strip.and_then(|s| pool.install(|| state.push(s)));
            if result.is_err() {
                break;
            }
            progress(state.rows_in / 2, h);
        }
        drop(rx);
        let _ = reader.join();
        result
    })?;
    if state.rows_in != h {
        return Err(Error::Internal(format!(
            "the inputs ended after {} of {h} rows",
            state.rows_in
        )));
    }
    Ok(Survey {
        counts: state.counts,
        sums: state.grid,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The first pass as it goes.
struct Sums<'a> {
    plan: SurveyPlan<'a>,
    input: RowWindow<f32>,
    kept: Kept,
    rows_in: usize,
    nbx: usize,
    grid: Vec<Vec<BlockSums>>,
    counts: RestoreCounts,
}

impl<'a> Sums<'a> {
    fn new(plan: SurveyPlan<'a>) -> Self {
        let (w, h) = plan.size;
        let (nbx, nby) = (w.div_ceil(plan.scale), h.div_ceil(plan.scale));
        let grid = (plan.kept.copied.iter())
            .map(|&c| {
                if c {
                    Vec::new()
                } else {
                    vec![BlockSums::default(); nbx * nby]
                }
            })
            .collect();
        Sums {
            input: RowWindow::new(plan.row_channels * w),
            kept: Kept::new(plan.kept.clone(), plan.size),
            plan,
            rows_in: 0,
            nbx,
            grid,
            counts: RestoreCounts::default(),
        }
    }

    /// A strip in: its values checked, its rows' `l` and block sums taken
    /// as far as the rows around allow.
    fn push(&mut self, mut strip: Strip) -> Result<()> {
        let (w, _) = self.plan.size;
        let row_len = self.plan.row_channels * w;
        if strip.y0 != self.rows_in || strip.data.len() != strip.rows * row_len {
            return Err(Error::Internal(format!(
                "the inputs gave rows {}..{} where row {} was next (source bug)",
                strip.y0,
                strip.y0 + strip.rows,
                self.rows_in
            )));
        }
        self.check(&mut strip)?;
        self.input
            .push_rows(std::mem::take(&mut strip.data), strip.rows);
        self.rows_in += strip.rows;
        let to = self.kept.target(self.rows_in);
        let (a, b) = self.kept.advance(&self.input, to);
        self.add(a, b);
        self.kept.release(b);
        self.input.evict_below(self.kept.input_needed());
        Ok(())
    }

    /// The energy's and the denoiser's values: a non-finite one refused
    /// (naming it) or, with `--nonfinite zero`, taken as zero and counted,
    /// as the second pass's books do for the energy; the denoiser's
    /// negative values counted.
    fn check(&mut self, strip: &mut Strip) -> Result<()> {
        let (w, _) = self.plan.size;
        let (nch, d_at, nall) = (
            self.plan.names.len(),
            self.kept.d_at,
            self.plan.row_channels,
        );
        let zero = self.plan.nonfinite == NonFinite::Zero;
        for (r, row) in strip.data.chunks_mut(nall * w).enumerate() {
            let y = strip.y0 + r;
            for c in 0..nch {
                let name = &self.plan.names[c];
                if !self.plan.data[c] {
                    for (x, v) in row[c * w..(c + 1) * w].iter_mut().enumerate() {
                        if !v.is_finite() {
                            if !zero {
                                return Err(nonfinite(Side::Input, (x, y), name));
                            }
                            *v = 0.0;
                        }
                    }
                }
                if self.plan.kept.copied[c] {
                    continue;
                }
                for (x, v) in row[(d_at + c) * w..(d_at + c + 1) * w]
                    .iter_mut()
                    .enumerate()
                {
                    if !v.is_finite() {
                        if !zero {
                            return Err(nonfinite(Side::SecondInput, (x, y), name));
                        }
                        *v = 0.0;
                        self.counts.denoised_nonfinite += 1;
                    } else if *v < 0.0 {
                        self.counts.denoised_negative += 1;
                    }
                }
            }
        }
        Ok(())
    }

    /// Rows `a..b` (their `l` known) into the blocks' sums, in row order.
    fn add(&mut self, a: usize, b: usize) {
        let (w, _) = self.plan.size;
        let (nbx, scale, d_at) = (self.nbx, self.plan.scale, self.kept.d_at);
        let (input, kept, plan) = (&self.input, &self.kept, &self.plan);
        let nch = plan.names.len();
        let stats = plan.kept.stats.as_ref();
        let rows: Vec<Vec<BlockSums>> = (a..b)
            .into_par_iter()
            .map(|y| {
                let row = input.get(y);
                let l = kept.row(y);
                let mut out = vec![BlockSums::default(); nch * nbx];
                for ch in (0..nch).filter(|&ch| !plan.kept.copied[ch]) {
                    let e = &row[ch * w..(ch + 1) * w];
                    let d = &row[(d_at + ch) * w..(d_at + ch + 1) * w];
                    let blocks = out[ch * nbx..(ch + 1) * nbx].iter_mut();
                    for (ib, sums) in blocks.enumerate() {
                        for x in ib * scale..((ib + 1) * scale).min(w) {
                            let lx = l.map_or(0.0, |l| l[ch * w + x]);
                            let rest = f64::from(e[x]) - lx;
                            let s = shape(d[x]);
                            // What is kept in place is sure; the rest's
                            // variance from the pass, else its residual.
                            let var = if lx != 0.0 {
                                0.0
                            } else {
                                stats
                                    .and_then(|st| st.channel_var(row, w, x, ch))
                                    .unwrap_or((rest - s) * (rest - s))
                            };
                            sums.rest += rest;
                            sums.shape += s;
                            sums.var += var;
                        }
                    }
                }
                out
            })
            .collect();
        for (y, row) in (a..b).zip(rows) {
            let jb = y / scale;
            for (ch, grid) in self.grid.iter_mut().enumerate() {
                if grid.is_empty() {
                    continue;
                }
                for (g, s) in grid[jb * nbx..(jb + 1) * nbx]
                    .iter_mut()
                    .zip(&row[ch * nbx..])
                {
                    *g += *s;
                }
            }
        }
    }
}

/// A non-finite value at pixel `(x, y)` of channel `name`, on `side`.
fn nonfinite(side: Side, (x, y): (usize, usize), name: &str) -> Error {
    Error::StreamValue {
        side,
        reason: format!(
            "non-finite value at pixel ({x}, {y}) in channel {name} \
             (--nonfinite zero treats such values as 0 and counts them)"
        ),
    }
}
