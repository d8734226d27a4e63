//! One band of output rows (`filter --band K/N`): the pipeline runs over a
//! window of input rows that reaches [`margin`] output rows beyond the band
//! on either side, so every row of the band is filtered from the same
//! samples, with the same kernels, summed in the same order as in a run over
//! the whole image, and `merge` can put the bands together bit for bit.
//! Rows move here; what to filter is the stage's.

use std::sync::{Arc, Mutex};

use super::edge::Coverage;
use super::ledger::CompensatedSum;
use super::{Precision, Sink, Source, Strip};
use crate::error::Result;
use crate::filter::FilterParams;

/// Output rows either side of a band that its run reads. A row is final once
/// the input `lag` rows past it has been read (the stage's halo: its noise
/// tests, searches and kernels, and everything those read), and what a row
/// depends on reaches as far above it as below; the window's own edges are
/// reflected, which changes only what is read past them. The widest kernel's
/// reach is added as a margin of safety, and the tests hold bands thinner
/// than this margin to one run's bytes on images taller than it.
pub fn margin(params: &FilterParams) -> usize {
    let h = crate::filter::halo(params);
    h.lag() + h.spread_reach + 2
}

/// Output rows `[a, b)` of band `index` (0-based) of `count` over `rows`
/// output rows, cut on multiples of `unit` rows (the output's block height,
/// so that `merge` copies whole compressed blocks). `None` when the band
/// would be empty.
pub fn band_rows(rows: usize, unit: usize, index: usize, count: usize) -> Option<(usize, usize)> {
    let blocks = rows.div_ceil(unit.max(1));
    let a = (index * blocks / count) * unit;
    let b = (((index + 1) * blocks / count) * unit).min(rows);
    (a < b).then_some((a, b))
}

/// The input rows `[y0, y1)` of `inner`, renumbered from 0, with the sum per
/// channel (of the first `nch`) of the rows `[own0, own1)` (global rows):
/// the input energy the band owns.
pub struct BandSource<S> {
    inner: S,
    y0: usize,
    y1: usize,
    own: (usize, usize),
    w: usize,
    nch: usize,
    sums: Arc<Mutex<Vec<CompensatedSum>>>,
    done: bool,
}

/// Per channel, the sums a [`BandSource`] has taken of the rows it owns.
pub type OwnedSums = Arc<Mutex<Vec<CompensatedSum>>>;

impl<S: Source> BandSource<S> {
    /// Rows `y0..y1` of `inner` (rows `w` samples wide, `nch` channels
    /// counted), owning input rows `own`.
    pub fn new(inner: S, y0: usize, y1: usize, own: (usize, usize), w: usize, nch: usize) -> Self {
        BandSource {
            inner,
            y0,
            y1,
            own,
            w,
            nch,
            sums: Arc::new(Mutex::new(vec![CompensatedSum::default(); nch])),
            done: false,
        }
    }

    /// The sums of the owned rows (complete once every row was read).
    pub fn owned_sums(&self) -> OwnedSums {
        self.sums.clone()
    }
}

/// The values of shared sums.
pub fn values(sums: &OwnedSums) -> Vec<f64> {
    sums.lock()
        .map(|s| s.iter().map(|c| c.value()).collect())
        .unwrap_or_default()
}

impl<S: Source> Source for BandSource<S> {
    super::decode_ahead_in_inner!();

    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        loop {
            if self.done {
                return Ok(None);
            }
            let Some(mut strip) = self.inner.next_strip(max_rows)? else {
                self.done = true;
                return Ok(None);
            };
            if strip.rows == 0 {
                continue;
            }
            let row_len = strip.data.len() / strip.rows;
            let (a, b) = (strip.y0, strip.y0 + strip.rows);
            if b <= self.y0 {
                continue; // before the window
            }
            if a >= self.y1 {
                self.done = true;
                return Ok(None);
            }
            let (from, to) = (a.max(self.y0), b.min(self.y1));
            if to >= self.y1 {
                self.done = true;
            }
            strip.data.truncate((to - a) * row_len);
            strip.data.drain(..(from - a) * row_len);
            if let Ok(mut sums) = self.sums.lock() {
                for y in from.max(self.own.0)..to.min(self.own.1) {
                    let row = &strip.data[(y - from) * row_len..][..row_len];
                    for (c, sum) in sums.iter_mut().enumerate().take(self.nch) {
                        for &v in &row[c * self.w..(c + 1) * self.w] {
                            sum.add(v as f64);
                        }
                    }
                }
            }
            return Ok(Some(Strip {
                y0: from - self.y0,
                rows: to - from,
                data: strip.data,
            }));
        }
    }
}

/// What a [`BandSink`] does before its sink finishes, given the sums of what
/// it passed on (to note them in the file, say).
pub type FinishHook<K> = Box<dyn FnOnce(&mut K, &[f64]) + Send>;

/// Passes output rows `[a, b)` of the window (window rows) to `inner`,
/// renumbered from 0, and sums each channel of what it passes.
pub struct BandSink<K> {
    inner: K,
    a: usize,
    b: usize,
    row_len: usize,
    nch: usize,
    sums: Vec<CompensatedSum>,
    hook: Option<FinishHook<K>>,
    coverage: Option<Coverage>,
}

impl<K: Sink> BandSink<K> {
    /// Keep window rows `a..b` (`nch` channels of `w` pixels); `hook` runs
    /// before `inner` finishes.
    pub fn new(inner: K, a: usize, b: usize, w: usize, nch: usize, hook: FinishHook<K>) -> Self {
        BandSink {
            inner,
            a,
            b,
            row_len: w * nch,
            nch,
            sums: vec![CompensatedSum::default(); nch],
            hook: Some(hook),
            coverage: None,
        }
    }

    /// `--edge pad`: weigh the values passed on by their pixels' coverage
    /// (`coverage.y` indexed from the band's first row).
    pub fn set_coverage(&mut self, coverage: Coverage) {
        self.coverage = Some(coverage);
    }

    /// Per channel, the sum of the (rounded) values passed on (weighed by
    /// coverage with `--edge pad`).
    pub fn sums(&self) -> Vec<f64> {
        self.sums.iter().map(|s| s.value()).collect()
    }
}

impl<K: Sink> Sink for BandSink<K> {
    fn precision(&self) -> Precision {
        self.inner.precision()
    }

    fn precisions(&self, nch: usize) -> Vec<Precision> {
        self.inner.precisions(nch)
    }

    fn write_rows(&mut self, y0: usize, rows: usize, data: &[f32]) -> Result<()> {
        let (from, to) = (y0.max(self.a), (y0 + rows).min(self.b));
        if from >= to {
            return Ok(());
        }
        let kept = &data[(from - y0) * self.row_len..(to - y0) * self.row_len];
        let w = self.row_len / self.nch.max(1);
        for (r, row) in kept.chunks_exact(self.row_len).enumerate() {
            for (c, sum) in self.sums.iter_mut().enumerate() {
                let vals = &row[c * w..(c + 1) * w];
                match &self.coverage {
                    None => vals.iter().for_each(|&v| sum.add(v as f64)),
                    Some(cov) => {
                        let y = from - self.a + r;
                        for (x, &v) in vals.iter().enumerate() {
                            sum.add(v as f64 * cov.at(x, y));
                        }
                    }
                }
            }
        }
        self.inner.write_rows(from - self.a, to - from, kept)
    }

    fn finish(&mut self) -> Result<()> {
        if let Some(hook) = self.hook.take() {
            let sums = self.sums();
            hook(&mut self.inner, &sums);
        }
        self.inner.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_tile_the_rows_on_block_boundaries() {
        for rows in 1..80 {
            for unit in [1, 16, 32] {
                for count in 1..9 {
                    let mut next = 0;
                    for i in 0..count {
                        if let Some((a, b)) = band_rows(rows, unit, i, count) {
                            assert_eq!(a, next);
                            assert_eq!(a % unit, 0);
                            next = b;
                        }
                    }
                    assert_eq!(next, rows, "{rows} rows, unit {unit}, {count} bands");
                }
            }
        }
    }
}
