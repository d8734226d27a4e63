//! The books the skeleton keeps beside the stages' windows: the channel names, the
//! energy ledger, the digest of the unrounded output, and the non-finite
//! policy with its counts. Strips come in through [`Books::take`] (checked,
//! counted) and output rows go out through [`Books::finish`] (rounded,
//! counted), so every method accounts the same way.

use rayon::iter::{IntoParallelIterator, ParallelIterator};

use super::edge::Coverage;
use super::ledger::{Ledger, Sums};
use super::stage::Output;
use super::{NonFinite, Precision, Strip};
use crate::error::{Error, Result, Side};

/// A finished batch of output rows, `[row][channel][x]`.
#[derive(Debug)]
pub struct OutRows {
    /// First output row.
    pub y0: usize,
    /// Number of rows.
    pub rows: usize,
    /// Values, already rounded to the output precision.
    pub data: Vec<f32>,
}

/// Names, ledger, digest and non-finite counts of one run.
#[derive(Debug)]
pub struct Books {
    names: Vec<String>,
    ledger: Ledger,
    digest: u64,
    nonfinite: NonFinite,
    zeroed: Vec<u64>,
    first_nonfinite: Option<(usize, usize, usize)>,
    coverage: Option<Coverage>,
    /// Channels of data, not light ([`super::StripLayout::data`]).
    data: Vec<bool>,
    /// Channels of data checked all the same ([`Books::set_checked`]).
    checked: Vec<bool>,
    /// Buffers of output rows the writer is done with
    /// ([`Books::recycle_rows`]).
    recycled: Option<crossbeam_channel::Receiver<Vec<f32>>>,
}

impl Books {
    /// Books for the filtered channels `names`, of `inputs` input channels
    /// in all (filtered ones first, then statistics).
    pub fn new(names: Vec<String>, inputs: usize) -> Self {
        Books {
            ledger: Ledger::new(names.len()),
            names,
            digest: FNV_OFFSET,
            nonfinite: NonFinite::Error,
            zeroed: vec![0; inputs],
            first_nonfinite: None,
            coverage: None,
            data: Vec::new(),
            checked: Vec::new(),
            recycled: None,
        }
    }

    /// Channels of data (one flag per filtered channel): their samples are
    /// neither checked for NaN and infinities nor zeroed (a sky's depth is
    /// infinite), and they stay out of the ledger.
    pub fn set_data(&mut self, data: Vec<bool>) {
        self.data = data;
    }

    /// Take the buffers of output rows from `rx` once the writer is done
    /// with them: on wide images a strip's rows are megabytes, and a fresh
    /// buffer a strip costs as much in page faults as rounding them.
    pub fn recycle_rows(&mut self, rx: crossbeam_channel::Receiver<Vec<f32>>) {
        self.recycled = Some(rx);
    }

    /// Channels whose input a rule reads as light's evidence (statistics
    /// read where they are carried as data): a non-finite sample is refused
    /// as in the channels of light, though the channel is data.
    pub fn set_checked(&mut self, checked: Vec<bool>) {
        self.checked = checked;
    }

    /// `--edge pad`: output values are divided by their pixel's coverage,
    /// and the ledger weighs them by it.
    pub fn set_coverage(&mut self, coverage: Coverage) {
        self.coverage = Some(coverage);
    }

    /// Check the next strip before its rows enter the window: it must start
    /// at row `next` of `in_h` rows of `in_w` samples; its non-finite
    /// samples are zeroed and counted here where the policy says so (the
    /// ledger refuses them otherwise, [`Self::take`]).
    pub fn check(
        &mut self,
        strip: &mut Strip,
        next: usize,
        in_w: usize,
        in_h: usize,
    ) -> Result<()> {
        let row_len = self.zeroed.len() * in_w;
        if strip.y0 != next || strip.data.len() != strip.rows * row_len || next + strip.rows > in_h
        {
            return Err(Error::Internal(format!(
                "source delivered rows {}..{} but row {next} was expected (source bug)",
                strip.y0,
                strip.y0 + strip.rows,
            )));
        }
        self.zero_nonfinite(strip, in_w);
        Ok(())
    }

    /// Take a checked strip's rows into the ledger.
    pub fn take(&mut self, take: Take<'_>) -> Result<()> {
        self.take_and_finish(Some(take), None).map(|_| ())
    }

    /// Take a checked strip's rows (`take`) into the ledger and finish the
    /// output rows of `finish`, row tasks of one parallel loop. Returns the
    /// finished rows.
    fn take_and_finish(
        &mut self,
        take: Option<Take<'_>>,
        finish: Option<Finish<'_>>,
    ) -> Result<Option<OutRows>> {
        let BooksLoop { input, output } = self.run_rows(take.as_ref(), finish.as_ref());
        self.ledger.input.merge(&input?);
        let Some((out, raw, rounded, digests)) = output.transpose()? else {
            return Ok(None);
        };
        for d in digests {
            self.digest = fnv(self.digest, d);
        }
        self.ledger.output.merge(&raw);
        self.ledger.rounded.merge(&rounded);
        Ok(Some(out))
    }

    /// Finish output rows: rounded, into the ledger and the digest.
    pub fn finish(&mut self, finish: Finish<'_>) -> Result<OutRows> {
        Ok(self
            .take_and_finish(None, Some(finish))?
            .unwrap_or(OutRows {
                y0: 0,
                rows: 0,
                data: Vec::new(),
            }))
    }

    /// Filtered channel names.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The ledger so far.
    pub fn ledger(&self) -> &Ledger {
        &self.ledger
    }

    /// FNV-1a digest of the bits of every unrounded (f64) output value, in
    /// row-major order: equal digests mean bit-identical results before
    /// rounding, which the f32 output alone cannot show.
    pub fn digest(&self) -> u64 {
        self.digest
    }

    /// What to do with NaN and infinite input samples.
    pub fn set_nonfinite(&mut self, n: NonFinite) {
        self.nonfinite = n;
    }

    /// Non-finite input samples treated as zero, per input channel.
    pub fn nonfinite_zeroed(&self) -> &[u64] {
        &self.zeroed
    }

    /// The first of them: (x, y, input channel).
    pub fn first_nonfinite(&self) -> Option<(usize, usize, usize)> {
        self.first_nonfinite
    }
}

/// A checked strip's rows ([`Books::check`]) for [`Books::take`]
/// to take into the ledger.
pub struct Take<'a> {
    /// Its rows, every channel of each.
    pub rows: Vec<&'a [f32]>,
    /// The first one's row in the image.
    pub y0: usize,
    /// Samples per row.
    pub in_w: usize,
}

/// Output rows `a..b` for [`Books::finish`] to finish: `base_rows +
/// acc` (or `base_rows`), `w` wide, rounded to `precision`; the ledger and
/// digest take them in row order.
pub struct Finish<'a> {
    /// The rows (`base + acc`, from row `a`).
    pub rows: Output<'a>,
    /// The first row.
    pub a: usize,
    /// The end of the rows.
    pub b: usize,
    /// Pixels per row.
    pub w: usize,
    /// The output precision, per channel.
    pub precision: &'a [Precision],
}

/// The finished rows, with their raw and rounded sums and each row's digest.
type Finished = (OutRows, Sums, Sums, Vec<u64>);

/// What one loop of the books gave: the strip's sums, and the finished rows.
struct BooksLoop {
    input: Result<Sums>,
    output: Option<Result<Finished>>,
}

/// A task of that loop: a strip row into the ledger, or an output row.
enum RowJob<'a> {
    In(&'a [f32]),
    Out(usize, &'a mut [f32]),
}

/// What a task gave.
enum RowDone {
    In(std::result::Result<Sums, (usize, usize)>),
    Out(Result<(Sums, Sums, u64)>),
}

impl Books {
    /// Non-finite samples (all the strip's channels but data) refused later
    /// by the ledger, or with `--nonfinite zero` zeroed and counted (the
    /// first one kept) here, before anything reads them.
    fn zero_nonfinite(&mut self, strip: &mut Strip, in_w: usize) {
        if self.nonfinite != NonFinite::Zero {
            return;
        }
        let nall = self.zeroed.len();
        let data = &self.data;
        let is_data = |c: usize| data.get(c).copied().unwrap_or(false);
        for (r, row) in strip.data.chunks_mut(nall * in_w).enumerate() {
            for c in (0..nall).filter(|&c| !is_data(c)) {
                for (x, v) in row[c * in_w..(c + 1) * in_w].iter_mut().enumerate() {
                    if !v.is_finite() {
                        *v = 0.0;
                        self.zeroed[c] += 1;
                        self.first_nonfinite.get_or_insert((x, strip.y0 + r, c));
                    }
                }
            }
        }
    }

    /// The strip's rows into the ledger and the output rows of `finish`, the
    /// tasks of one parallel loop, merged in row order.
    fn run_rows(&self, input: Option<&Take<'_>>, finish: Option<&Finish<'_>>) -> BooksLoop {
        let nch = self.names.len();
        let w = finish.map_or(0, |f| f.w);
        // Every value of the rows is written (`finish_row`).
        let mut data = finish.map_or_else(Vec::new, |f| {
            let n = (f.b - f.a) * nch * w;
            let mut v = (self.recycled.as_ref())
                .and_then(|r| r.try_recv().ok())
                .unwrap_or_default();
            v.truncate(n);
            v.resize(n, 0.0);
            v
        });
        let mut jobs = Vec::new();
        if let Some(t) = input {
            jobs.extend(t.rows.iter().map(|r| RowJob::In(r)));
        }
        if let Some(f) = finish {
            let rows = data.chunks_mut(nch * w).enumerate();
            jobs.extend(rows.map(|(k, out)| RowJob::Out(f.a + k, out)));
        }
        let done: Vec<RowDone> = if jobs.is_empty() {
            Vec::new()
        } else {
            let region = crate::trace::region(match (input.is_some(), finish.is_some()) {
                (true, true) => "ledger in, finish rows",
                (true, false) => "ledger in",
                _ => "finish rows",
            });
            jobs.into_par_iter()
                .map_init(
                    || (vec![0.0f64; w], vec![0.0f64; w]),
                    |scratch, job| match (job, input, finish) {
                        (RowJob::In(row), Some(t), _) => {
                            let _task = region.task("ledger in");
                            RowDone::In(self.ledger_row(row, t.in_w))
                        }
                        (RowJob::Out(y, out), _, Some(f)) => {
                            let _task = region.task("finish rows");
                            RowDone::Out(self.finish_row(f, y, out, scratch))
                        }
                        _ => unreachable!("a row job comes with its side"),
                    },
                )
                .collect()
        };
        let mut sums = Sums::new(nch);
        let mut in_err = None;
        let (mut raw, mut rounded) = (Sums::new(nch), Sums::new(nch));
        let mut digests = Vec::new();
        let mut out_err = None;
        for (r, d) in done.into_iter().enumerate() {
            match d {
                RowDone::In(Ok(s)) => sums.merge(&s),
                RowDone::In(Err((x, c))) => {
                    in_err.get_or_insert_with(|| {
                        let y = input.map_or(0, |t| t.y0) + r;
                        Error::StreamValue {
                            side: Side::Input,
                            reason: format!(
                                "non-finite input value at sample ({x}, {y}) in channel {} \
                                 (--nonfinite zero treats such samples as 0 and counts them)",
                                channel_name(&self.names, c)
                            ),
                        }
                    });
                }
                RowDone::Out(Ok((a, b, digest))) => {
                    raw.merge(&a);
                    rounded.merge(&b);
                    digests.push(digest);
                }
                RowDone::Out(Err(e)) => {
                    out_err.get_or_insert(e);
                }
            }
        }
        BooksLoop {
            input: in_err.map_or(Ok(sums), Err),
            output: finish.map(|f| {
                let out = OutRows {
                    y0: f.a,
                    rows: f.b - f.a,
                    data,
                };
                out_err.map_or(Ok((out, raw, rounded, digests)), Err)
            }),
        }
    }

    /// The sums of a strip row's filtered channels, or the first non-finite
    /// sample (x, channel) of a channel that is not data.
    fn ledger_row(&self, row: &[f32], in_w: usize) -> std::result::Result<Sums, (usize, usize)> {
        let (nch, nall) = (self.names.len(), self.zeroed.len());
        let mut s = Sums::new(nch);
        let is = |flags: &[bool], c: usize| flags.get(c).copied().unwrap_or(false);
        for c in (0..nall).filter(|&c| !is(&self.data, c) || is(&self.checked, c)) {
            let ch = &row[c * in_w..(c + 1) * in_w];
            // The sum says whether every value was finite: the slice is
            // searched only when one was not.
            if !(c < nch && !is(&self.data, c) && s.add_slice(c, ch)) {
                if let Some(x) = ch.iter().position(|v| !v.is_finite()) {
                    return Err((x, c));
                }
            }
        }
        Ok(s)
    }

    /// Output row `y` of `f` into `out`: `base_rows + acc` (or `base_rows`),
    /// rounded to the precision, with its raw and rounded sums and the digest
    /// of its unrounded values (fold them in row order: the result does not
    /// depend on batching).
    ///
    /// With a [`Coverage`] (`--edge pad`), each value is divided by its
    /// pixel's coverage before rounding, and both sums weigh values by it:
    /// the raw sum is that of `base_rows + acc`, as without padding.
    /// (Long: one pass per channel, from the sum to the rounded sums.)
    fn finish_row(
        &self,
        f: &Finish<'_>,
        y: usize,
        out: &mut [f32],
        (tmp, weighted): &mut (Vec<f64>, Vec<f64>),
    ) -> Result<(Sums, Sums, u64)> {
        let (nch, w) = (self.names.len(), f.w);
        let mut raw = Sums::new(nch);
        let mut rounded = Sums::new(nch);
        let mut digest = FNV_OFFSET;
        for c in 0..nch {
            let k = y - f.rows.a;
            let base_row = &f.rows.base[k][c * w..(c + 1) * w];
            match &f.rows.acc {
                Some(acc) => {
                    let n = &acc[k][c * w..(c + 1) * w];
                    for ((v, &b), &n) in tmp.iter_mut().zip(base_row).zip(n) {
                        *v = b + n;
                    }
                }
                None => tmp.copy_from_slice(base_row),
            }
            let is_data = self.data.get(c).copied().unwrap_or(false);
            if !is_data {
                raw.add_slice(c, tmp);
            }
            if let Some(cov) = &self.coverage {
                for (x, v) in tmp.iter_mut().enumerate() {
                    let share = cov.at(x, y);
                    if share != 1.0 {
                        *v /= share;
                    }
                }
            }
            let dst = &mut out[c * w..(c + 1) * w];
            let p = f.precision[c];
            for (x, (d, &val)) in dst.iter_mut().zip(tmp.iter()).enumerate() {
                // Data passes as it is, infinities included.
                let r = if is_data && !val.is_finite() {
                    Some(val as f32)
                } else {
                    round(val, p)
                };
                let r = r.ok_or_else(|| Error::StreamValue {
                    side: Side::Output,
                    reason: format!(
                        "output value {val:e} at pixel ({x}, {y}) in channel {} does not fit in {}{}",
                        self.names[c],
                        p.name(),
                        if p == Precision::F16 {
                            " (--pixel-type f32 holds it)"
                        } else {
                            ""
                        }
                    ),
                })?;
                *d = r;
                digest = fnv(digest, val.to_bits());
            }
            match &self.coverage {
                _ if is_data => {}
                Some(cov) => {
                    for (x, (t, &d)) in weighted.iter_mut().zip(dst.iter()).enumerate() {
                        *t = d as f64 * cov.at(x, y);
                    }
                    rounded.add_slice(c, weighted);
                }
                None => {
                    rounded.add_slice(c, dst);
                }
            }
        }
        Ok((raw, rounded, digest))
    }
}

fn channel_name(names: &[String], c: usize) -> String {
    names
        .get(c)
        .cloned()
        .unwrap_or_else(|| format!("#{c} (statistics)"))
}

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

#[inline]
fn fnv(h: u64, word: u64) -> u64 {
    (h ^ word).wrapping_mul(0x0000_0100_0000_01b3)
}

/// Round to the output type; `None` if the value does not fit.
#[inline]
fn round(v: f64, p: Precision) -> Option<f32> {
    match p {
        Precision::F32 => {
            let f = v as f32;
            f.is_finite().then_some(f)
        }
        Precision::F16 => {
            let f = half::f16::from_f64(v);
            f.is_finite().then(|| f.to_f32())
        }
        Precision::U32 => {
            let f = v as f32;
            (f >= 0.0 && f <= u32::MAX as f32 && f.fract() == 0.0 && f as f64 == v).then_some(f)
        }
    }
}
