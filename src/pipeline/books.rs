//! The books the skeleton keeps beside the stages' windows: the channel names, the
//! energy ledger, the digest of the unrounded output, and the non-finite
//! policy with its counts. Strips come in through [`Books::take`] (checked,
//! counted) and output rows go out through [`Books::finish`] (rounded,
//! counted), so every method accounts the same way.

use rayon::prelude::*;

use super::edge::Coverage;
use super::ledger::{Ledger, Sums};
use super::stream::OutRows;
use super::window::RowWindow;
use super::{NonFinite, Precision, Strip};
use crate::error::{Error, Result, Side};

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
        }
    }

    /// Channels of data (one flag per filtered channel): their samples are
    /// neither checked for NaN and infinities nor zeroed (a sky's depth is
    /// infinite), and they stay out of the ledger.
    pub fn set_data(&mut self, data: Vec<bool>) {
        self.data = data;
    }

    /// `--edge pad`: output values are divided by their pixel's coverage,
    /// and the ledger weighs them by it.
    pub fn set_coverage(&mut self, coverage: Coverage) {
        self.coverage = Some(coverage);
    }

    /// Take the next strip: it must start at row `next` of `in_h` rows of
    /// `in_w` samples; non-finite samples are refused or zeroed, and the
    /// filtered channels enter the ledger.
    pub fn take(&mut self, strip: &mut Strip, next: usize, in_w: usize, in_h: usize) -> Result<()> {
        let row_len = self.zeroed.len() * in_w;
        if strip.y0 != next || strip.data.len() != strip.rows * row_len || next + strip.rows > in_h
        {
            return Err(Error::Internal(format!(
                "source delivered rows {}..{} but row {next} was expected (source bug)",
                strip.y0,
                strip.y0 + strip.rows,
            )));
        }
        let sums = ingest(
            strip,
            in_w,
            &self.names,
            &self.data,
            self.nonfinite,
            &mut self.zeroed,
            &mut self.first_nonfinite,
        )?;
        self.ledger.input.merge(&sums);
        Ok(())
    }

    /// Output rows `a..b` of `base_rows + acc` (or `base_rows`), `w` wide, rounded to
    /// `precision`; the ledger and digest take them in row order.
    pub fn finish(
        &mut self,
        base_rows: &RowWindow<f64>,
        acc: Option<&RowWindow<f64>>,
        a: usize,
        b: usize,
        w: usize,
        precision: &[Precision],
    ) -> Result<OutRows> {
        let (out, raw, rounded, digests) = finish_rows(
            base_rows,
            acc,
            (a, b, w),
            &self.names,
            &self.data,
            precision,
            self.coverage.as_ref(),
        )?;
        for d in digests {
            self.digest = fnv(self.digest, d);
        }
        self.ledger.output.merge(&raw);
        self.ledger.rounded.merge(&rounded);
        Ok(out)
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

/// Check a strip's samples (all its channels) for NaN and infinities — refuse
/// them, or zero and count them — and return the sums of its first
/// `names.len()` channels (the filtered ones) for the ledger.
fn ingest(
    strip: &mut Strip,
    in_w: usize,
    names: &[String],
    data: &[bool],
    nonfinite: NonFinite,
    zeroed: &mut [u64],
    first_nonfinite: &mut Option<(usize, usize, usize)>,
) -> Result<Sums> {
    let nall = zeroed.len();
    let row_len = nall * in_w;
    let nch = names.len();
    let is_data = |c: usize| data.get(c).copied().unwrap_or(false);
    if nonfinite == NonFinite::Zero {
        // Zero them (counted, first one kept) before anything reads them.
        for (r, row) in strip.data.chunks_mut(row_len).enumerate() {
            for c in (0..nall).filter(|&c| !is_data(c)) {
                for (x, v) in row[c * in_w..(c + 1) * in_w].iter_mut().enumerate() {
                    if !v.is_finite() {
                        *v = 0.0;
                        zeroed[c] += 1;
                        first_nonfinite.get_or_insert((x, strip.y0 + r, c));
                    }
                }
            }
        }
    }
    // Ledger of the input, row by row in parallel, merged in order.
    let region = crate::trace::region("ledger in");
    let sums: Vec<std::result::Result<Sums, (usize, usize)>> = strip
        .data
        .par_chunks(row_len)
        .map(|row| {
            let _task = region.task("ledger in");
            let mut s = Sums::new(nch);
            for c in (0..nall).filter(|&c| !is_data(c)) {
                let ch = &row[c * in_w..(c + 1) * in_w];
                // The sum says whether every value was finite: the slice is
                // searched only when one was not.
                if !(c < nch && s.add_slice(c, ch)) {
                    if let Some(x) = ch.iter().position(|v| !v.is_finite()) {
                        return Err((x, c));
                    }
                }
            }
            Ok(s)
        })
        .collect();
    let mut total = Sums::new(nch);
    for (r, s) in sums.into_iter().enumerate() {
        match s {
            Ok(s) => total.merge(&s),
            Err((x, c)) => {
                return Err(Error::StreamValue {
                    side: Side::Input,
                    reason: format!(
                        "non-finite input value at sample ({x}, {}) in channel {} \
                         (--nonfinite zero treats such samples as 0 and counts them)",
                        strip.y0 + r,
                        channel_name(names, c)
                    ),
                })
            }
        }
    }
    Ok(total)
}

fn channel_name(names: &[String], c: usize) -> String {
    names
        .get(c)
        .cloned()
        .unwrap_or_else(|| format!("#{c} (statistics)"))
}

/// Output rows `a..b`: `base_rows + acc` (or `base_rows`), rounded to `precision`,
/// with their raw and rounded sums and each row's digest of its unrounded
/// values (fold them in row order: the result does not depend on batching).
///
/// With a [`Coverage`] (`--edge pad`), each value is divided by its pixel's
/// coverage before rounding, and both sums weigh values by it: the raw sum
/// is that of `base_rows + acc`, as without padding.
fn finish_rows(
    base_rows: &RowWindow<f64>,
    acc: Option<&RowWindow<f64>>,
    (a, b, w): (usize, usize, usize),
    names: &[String],
    data_ch: &[bool],
    precision: &[Precision],
    coverage: Option<&Coverage>,
) -> Result<(OutRows, Sums, Sums, Vec<u64>)> {
    let nch = names.len();
    let mut data = vec![0.0f32; (b - a) * nch * w];
    let region = crate::trace::region("finish rows");
    let sums: Vec<Result<(Sums, Sums, u64)>> = data
        .par_chunks_mut(nch * w)
        .enumerate()
        .map_init(
            || (vec![0.0f64; w], vec![0.0f64; w]),
            |(tmp, weighted), (k, out)| {
                let _task = region.task("finish rows");
                let y = a + k;
                let mut raw = Sums::new(nch);
                let mut rounded = Sums::new(nch);
                let mut digest = FNV_OFFSET;
                for c in 0..nch {
                    let base_row = &base_rows.get(y)[c * w..(c + 1) * w];
                    match acc {
                        Some(acc) => {
                            let n = &acc.get(y)[c * w..(c + 1) * w];
                            for ((v, &b), &n) in tmp.iter_mut().zip(base_row).zip(n) {
                                *v = b + n;
                            }
                        }
                        None => tmp.copy_from_slice(base_row),
                    }
                    let is_data = data_ch.get(c).copied().unwrap_or(false);
                    if !is_data {
                        raw.add_slice(c, tmp);
                    }
                    if let Some(cov) = coverage {
                        for (x, v) in tmp.iter_mut().enumerate() {
                            let share = cov.at(x, y);
                            if share != 1.0 {
                                *v /= share;
                            }
                        }
                    }
                    let dst = &mut out[c * w..(c + 1) * w];
                    for (x, (d, &val)) in dst.iter_mut().zip(tmp.iter()).enumerate() {
                        let p = precision[c];
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
                                names[c],
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
                    match coverage {
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
            },
        )
        .collect();
    let (mut raw_all, mut rounded_all) = (Sums::new(nch), Sums::new(nch));
    let mut digest = Vec::with_capacity(b - a);
    for s in sums {
        let (raw, rounded, d) = s?;
        digest.push(d);
        raw_all.merge(&raw);
        rounded_all.merge(&rounded);
    }
    Ok((
        OutRows {
            y0: a,
            rows: b - a,
            data,
        },
        raw_all,
        rounded_all,
        digest,
    ))
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
