//! Whole images in memory as a source and a sink: for tests, benches and
//! small jobs.

use super::{
    mean_luminance, run, FilterParams, Method, PipelineConfig, Precision, RunStats, Sink, Source,
    Strip, StripLayout,
};
use crate::error::Result;

/// An in-memory source: a whole planar image (`[row][channel][x]`).
#[derive(Clone, Debug)]
pub struct MemorySource {
    data: Vec<f32>,
    row_len: usize,
    rows: usize,
    next: usize,
}

impl MemorySource {
    /// Wrap `data` of `rows` rows of `row_len` values.
    pub fn new(data: Vec<f32>, row_len: usize) -> Self {
        let rows = data.len().checked_div(row_len).unwrap_or(0);
        MemorySource {
            data,
            row_len,
            rows,
            next: 0,
        }
    }
}

impl Source for MemorySource {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        if self.next >= self.rows {
            return Ok(None);
        }
        let n = max_rows.min(self.rows - self.next);
        let data = self.data[self.next * self.row_len..(self.next + n) * self.row_len].to_vec();
        let strip = Strip {
            y0: self.next,
            rows: n,
            data,
        };
        self.next += n;
        Ok(Some(strip))
    }
}

/// An in-memory sink collecting the output image.
#[derive(Clone, Debug, Default)]
pub struct MemorySink {
    /// Output rows, `[row][channel][x]`.
    pub data: Vec<f32>,
    /// The precision the values are rounded to (f32 by default).
    pub precision: Option<Precision>,
}

impl MemorySink {
    /// A sink that stores `precision` (f16 refuses what it cannot hold).
    pub fn with_precision(precision: Precision) -> Self {
        MemorySink {
            data: Vec::new(),
            precision: Some(precision),
        }
    }
}

impl Sink for MemorySink {
    fn precision(&self) -> Precision {
        self.precision.unwrap_or(Precision::F32)
    }
    fn write_rows(&mut self, _y0: usize, _rows: usize, data: &[f32]) -> Result<()> {
        self.data.extend_from_slice(data);
        Ok(())
    }
    fn finish(&mut self) -> Result<()> {
        Ok(())
    }
}

impl<K: Sink> Sink for &mut K {
    fn precision(&self) -> Precision {
        (**self).precision()
    }
    fn precisions(&self, nch: usize) -> Vec<Precision> {
        (**self).precisions(nch)
    }
    fn write_rows(&mut self, y0: usize, rows: usize, data: &[f32]) -> Result<()> {
        (**self).write_rows(y0, rows, data)
    }
    fn finish(&mut self) -> Result<()> {
        (**self).finish()
    }
}

/// A whole in-memory run ([`filter_planar`]).
#[derive(Clone, Debug)]
pub struct MemoryRun {
    /// Output rows, `[row][channel][x]`, rounded to the precision asked for.
    pub data: Vec<f32>,
    /// What the run counted and its ledger.
    pub stats: RunStats,
    /// The settings used (ep-box's `L_tvis` settled by the first pass).
    pub params: FilterParams,
    /// ep-box: the mean luminance the first pass found (`None` when `L_tvis`
    /// was given, or another method).
    pub l_ave: Option<f64>,
}

/// Filter a whole in-memory image (planar `[row][channel][x]`) into values
/// rounded to `precision` (as a file of that sample type would hold them).
pub fn filter_planar(
    data: Vec<f32>,
    job: &StripLayout,
    params: &FilterParams,
    cfg: &PipelineConfig,
    precision: Precision,
) -> Result<MemoryRun> {
    // Rows as the source holds them (`--edge pad` completes them in `run`).
    let row_len = job.strip_channels() * job.padded_from.map_or(job.grid.in_w, |r| r.0);
    let mut params = params.clone();
    let mut l_ave = None;
    if params.method == Method::EpBox && params.ep_box.ltvis.is_none() {
        let source = MemorySource::new(data.clone(), row_len);
        let mean = mean_luminance(source, job, cfg.strip_rows, &|_, _| {})?;
        params.ep_box.ltvis = Some(crate::filter::ep_box::ltvis(mean, params.ep_box.nmid));
        l_ave = Some(mean);
    }
    let mut sink = MemorySink::with_precision(precision);
    let stats = run(
        MemorySource::new(data, row_len),
        &mut sink,
        job,
        &params,
        cfg,
        &|_, _| {},
    )?;
    Ok(MemoryRun {
        data: sink.data,
        stats,
        params,
        l_ave,
    })
}

/// Filter a whole in-memory image (planar `[row][channel][x]`) — for tests,
/// the demo and small jobs. Returns the output image and the statistics.
pub fn filter_in_memory(
    data: Vec<f32>,
    job: &StripLayout,
    params: &FilterParams,
    cfg: &PipelineConfig,
) -> Result<(Vec<f32>, RunStats)> {
    let run = filter_planar(data, job, params, cfg, Precision::F32)?;
    Ok((run.data, run.stats))
}
