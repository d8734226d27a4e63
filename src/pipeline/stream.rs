//! The one streaming skeleton every method runs in.
//!
//! [`Streamer`] owns what all methods share: the rolling window of input
//! rows, the cursor of rows in and rows out, the [`Books`] (ledger, digest,
//! non-finite policy) and the output precision. What differs is a [`Stage`]:
//! the method's own windows and cursors, fed rows as they arrive and asked to
//! go as far as the rows in allow.
//!
//! ```text
//!  strip ──▶ books.take ──▶ input window ──▶ stage.arrive ──▶ stage.advance
//!                                                 (rows final: 0..end)
//!  stage.output (base + accumulator) ──▶ books.finish (round, ledger, digest) ──▶ rows out
//! ```
//!
//! The contract that makes the output bit-identical for any strip height: a
//! stage's decisions may depend only on which rows are in, never on how they
//! came; every stage's cursors advance to the same targets whatever the
//! batching (each checks its own "rows final" condition).

use super::books::{Books, Finish, OutRows, Take};
use super::counts::MethodCounts;
use super::edge::Coverage;
use super::stage::{Output, Stage, WindowUse};
use super::window::RowWindow;
use super::{PipelineConfig, Precision, Strip, StripLayout};
use crate::error::{Error, Result};
use crate::filter::{Method, ValidParams};
use crate::geometry::{Grid, Halo};

/// Most channels one job filters: the beauty (R, G, B, A) and what it
/// carries beside it.
pub const MAX_CHANNELS: usize = 1024;

/// The skeleton: input window, cursors, books, precision, and one stage.
pub struct Streamer {
    stage: Box<dyn Stage>,
    input: RowWindow<f32>,
    books: Books,
    grid: Grid,
    nall: usize,
    w: usize,
    /// Per channel.
    precision: Vec<Precision>,
    rows_in: usize,
    out_done: usize,
}

impl Streamer {
    /// The skeleton and stage of `job` with `params` (validated), writing at
    /// `precision`.
    pub fn new(
        job: &StripLayout,
        params: &ValidParams,
        cfg: &PipelineConfig,
        precision: Vec<Precision>,
    ) -> Result<Self> {
        let grid = job.grid;
        let s = grid.s;
        check_layout(job, params, cfg)?;
        // --edge pad: the grid completes the source's samples with zeros to
        // a multiple of S; outputs are normalised by their coverage.
        let coverage = match job.padded_from {
            None => None,
            Some((rw, rh)) => {
                if rw > grid.in_w
                    || rh > grid.in_h
                    || rw == 0
                    || rh == 0
                    || grid.in_w - rw >= s
                    || grid.in_h - rh >= s
                {
                    return Err(Error::Config(format!(
                        "--edge pad: {rw}x{rh} samples do not complete to the {}x{} grid of S = {s}",
                        grid.in_w, grid.in_h
                    )));
                }
                if matches!(
                    params.method,
                    Method::Median | Method::AlphaTrim | Method::EpBox
                ) {
                    return Err(Error::Config(format!(
                        "--edge pad is for the Gaussian family and box; {} takes whole S x S blocks (give --edge crop)",
                        params.method.name()
                    )));
                }
                Some(Coverage::of(params, grid, (rw, rh)))
            }
        };
        let stage = super::stages::make(job, params, cfg)?;
        let nall = job.strip_channels();
        let mut books = Books::new(job.channels.clone(), nall);
        books.set_nonfinite(cfg.nonfinite);
        // Guides are data: a sky's depth or a miss's normal may be anything.
        let mut data = job.data.clone();
        data.resize(nall, false);
        let g = &job.guides;
        let guides = (g.emission.iter().flatten())
            .chain(g.albedo.iter().flatten())
            .chain(g.normal.iter().flatten())
            .chain(g.depth.iter());
        for &i in guides {
            if let Some(d) = data.get_mut(i) {
                *d = true;
            }
        }
        books.set_data(data);
        if let Some(st) = &job.stats {
            let mut checked = vec![false; nall];
            let count = match st.spp {
                crate::filter::ep_box::Spp::Channel(i) => Some(i),
                crate::filter::ep_box::Spp::Fixed(_) => None,
            };
            for i in st.variance.iter().copied().chain(st.mean_y).chain(count) {
                if let Some(c) = checked.get_mut(i) {
                    *c = true;
                }
            }
            books.set_checked(checked);
        }
        if let Some(cov) = coverage {
            books.set_coverage(cov);
        }
        Ok(Streamer {
            stage,
            input: RowWindow::new(nall * grid.in_w),
            books,
            grid,
            nall,
            w: grid.out_w(),
            precision,
            rows_in: 0,
            out_done: 0,
        })
    }

    /// The skeleton around a stage built by its caller (`epfilt restore`'s):
    /// the books count `job.channels` (the strips' first channels) but its
    /// `data` and apply `nonfinite` to them; `job.aux` are data the stage
    /// reads as it sees fit.
    pub fn of_stage(
        job: &StripLayout,
        stage: Box<dyn Stage>,
        nonfinite: super::NonFinite,
        precision: Vec<Precision>,
    ) -> Self {
        let nall = job.strip_channels();
        let mut books = Books::new(job.channels.clone(), nall);
        books.set_nonfinite(nonfinite);
        let mut data = job.data.clone();
        data.resize(nall, true);
        books.set_data(data);
        Streamer {
            stage,
            input: RowWindow::new(nall * job.grid.in_w),
            books,
            grid: job.grid,
            nall,
            w: job.grid.out_w(),
            precision,
            rows_in: 0,
            out_done: 0,
        }
    }

    /// Feed the next strip of input rows; returns the output rows it finished.
    ///
    /// A push is three steps, each its own parallel loop or loops: the new
    /// rows into the ledger, the stage's advance, and the rows it made final
    /// finished (rounded, into the ledger and the digest).
    pub fn push(&mut self, mut strip: Strip) -> Result<Option<OutRows>> {
        let (in_w, in_h) = (self.grid.in_w, self.grid.in_h);
        self.books.check(&mut strip, self.rows_in, in_w, in_h)?;
        let a = self.rows_in;
        // The strip's buffer becomes the window's rows (no copy).
        self.input
            .push_rows(std::mem::take(&mut strip.data), strip.rows);
        self.rows_in += strip.rows;
        self.books.take(Take {
            rows: (a..self.rows_in).map(|y| self.input.get(y)).collect(),
            y0: a,
            in_w,
        })?;
        self.stage.arrive(&mut self.input, a, self.rows_in);
        let end = self
            .stage
            .advance(&self.input, self.rows_in, self.rows_in == in_h);
        self.finish_to(end)
    }

    /// With every input row in but not every output row final: advance
    /// the stage again (it may hand its last rows over a few at a time);
    /// `None` when that made no row final.
    pub fn drain(&mut self) -> Result<Option<OutRows>> {
        if self.rows_in < self.grid.in_h {
            return Ok(None);
        }
        let end = self.stage.advance(&self.input, self.rows_in, true);
        if end <= self.out_done {
            return Ok(None);
        }
        self.finish_to(end)
    }

    /// Release the input the stage no longer reads, and finish the output
    /// rows up to `end`.
    fn finish_to(&mut self, end: usize) -> Result<Option<OutRows>> {
        self.input.evict_below(self.stage.input_needed());
        let done = (self.out_done, end.max(self.out_done));
        let rows = self.stage.output(done);
        let Some(finish) = unfinished(rows, done, self.w, &self.precision) else {
            return Ok(None);
        };
        let out = self.books.finish(finish)?;
        self.out_done = done.1;
        self.stage.release(self.out_done);
        Ok(Some(out))
    }

    /// Output rows finished so far.
    pub fn rows_out(&self) -> usize {
        self.out_done
    }

    /// The method's halo.
    pub fn halo(&self) -> Halo {
        self.stage.halo()
    }

    /// Send each strip's buffer to `tx` once its rows have left the input
    /// window ([`RowWindow::recycle_strips`]).
    pub fn recycle_strips(&mut self, tx: crossbeam_channel::Sender<Vec<f32>>) {
        self.input.recycle_strips(tx);
    }

    /// Take the output rows' buffers back from `rx` ([`Books::recycle_rows`]).
    pub fn recycle_rows(&mut self, rx: crossbeam_channel::Receiver<Vec<f32>>) {
        self.books.recycle_rows(rx);
    }

    /// What the method counted.
    pub fn counts(&self) -> MethodCounts {
        self.stage.counts()
    }

    /// Names, ledger, digest and non-finite counts.
    pub fn books(&self) -> &Books {
        &self.books
    }

    /// Every window held (the input window first): most rows and row size.
    pub fn windows(&self) -> Vec<WindowUse> {
        let mut v = vec![WindowUse {
            name: "input",
            rows: self.input.high_water(),
            row_bytes: self.nall * self.grid.in_w * 4,
        }];
        v.extend(self.stage.windows());
        v
    }
}

/// The layout's checks before anything is allocated, each with its own
/// message: channels, the grid against S, the tile, and aux channels only
/// for a stage that reads them.
fn check_layout(job: &StripLayout, params: &ValidParams, cfg: &PipelineConfig) -> Result<()> {
    let grid = job.grid;
    let nch = job.channels.len();
    if nch == 0 || nch > MAX_CHANNELS || job.luminance.len() != nch || job.modes.len() != nch {
        return Err(Error::Config(format!(
            "1..={MAX_CHANNELS} channels with luminance weights and modes needed, got {nch}"
        )));
    }
    let s = grid.s;
    if grid.in_w == 0 || grid.in_h == 0 {
        return Err(Error::Config("the image is empty".into()));
    }
    if s == 0 || grid.in_w < s || grid.in_h < s {
        return Err(Error::Config(format!(
            "--supersample {s} is larger than the image ({}x{} samples)",
            grid.in_w, grid.in_h
        )));
    }
    if grid.in_w % s != 0 || grid.in_h % s != 0 {
        return Err(Error::Config(format!(
            "image size {}x{} is not a multiple of --supersample {s}",
            grid.in_w, grid.in_h
        )));
    }
    if cfg.tile == 0 {
        return Err(Error::Config("--tile must be at least 1".into()));
    }
    let reads_aux = params.method == Method::EpBox
        || (params.method == Method::EpGauss && s == 1)
        || !job.guides.is_empty();
    if !reads_aux && !job.aux.is_empty() {
        return Err(Error::Config(format!(
            "{} reads no statistics or guide channels",
            params.method.name()
        )));
    }
    Ok(())
}

/// The final rows `a..b` not yet finished, `w` wide (none when there are
/// none).
fn unfinished<'a>(
    rows: Output<'a>,
    (a, b): (usize, usize),
    w: usize,
    precision: &'a [Precision],
) -> Option<Finish<'a>> {
    (b > a).then_some(Finish {
        rows,
        a,
        b,
        w,
        precision,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::ep_box::{Spp, StatsLayout, VarianceKind};
    use crate::filter::FilterParams;

    /// `filter::halo` sizes memory before any stage exists: it must be what
    /// every stage reports.
    #[test]
    fn halo_from_params_equals_every_stages() {
        for m in Method::ALL {
            for (r, mr, passes) in [(0.6, 16.0, 8), (0.9, 5.5, 3), (2.0, 40.0, 1)] {
                let s = if m == Method::EpBox { 1 } else { 3 };
                let mut p = FilterParams::new(m, s);
                (p.radius, p.max_radius, p.ep_box.passes) = (r, mr, passes);
                p.ep_box.ltvis = Some(0.01);
                let grid = Grid {
                    in_w: 30 * s,
                    in_h: 20 * s,
                    s,
                };
                let mut job = StripLayout::new(grid, vec!["Y".into()], vec![1.0]);
                if m == Method::EpBox {
                    job.aux = vec!["var".into()];
                    job.stats = Some(StatsLayout {
                        variance: vec![1],
                        kind: VarianceKind::Sample,
                        mean_y: None,
                        spp: Spp::Fixed(16.0),
                    });
                }
                let st = Streamer::new(
                    &job,
                    &p.validated().unwrap(),
                    &PipelineConfig::default(),
                    vec![Precision::F32; job.channels.len()],
                )
                .unwrap();
                assert_eq!(
                    st.halo(),
                    crate::filter::halo(&p),
                    "{m:?} {r} {mr} {passes}"
                );
            }
        }
    }
}
