//! The energy ledger: per channel, the sum of input values and the sum of
//! output values times S², before and after rounding to the output type.
//!
//! Sums are Neumaier-compensated in f64, merged in row order, so the ledger is
//! accurate to about one unit in the last place of the total whatever the
//! image size, and identical for any tile size, strip height or thread count.

use serde::Serialize;

/// The tests' bound on a run's relative ledger error before rounding (unit
/// and behaviour tests alike): each sample's weights sum to one within
/// ~1e-16 and every sum is compensated, so 1e-12 leaves a wide margin and
/// still catches one lost sample in 1e12.
pub const LEDGER_TOL: f64 = 1e-12;

/// What a picture output (Radiance, PFM) holds per colour channel, summed
/// as it is stored: the ledger's "on disk" column, each pixel weighed by its
/// coverage under `--edge pad`.
#[derive(Clone, Debug, Default)]
pub struct StoredSums {
    sums: [CompensatedSum; 3],
    coverage: Option<super::edge::Coverage>,
}

impl StoredSums {
    /// `--edge pad`: weigh each pixel by its coverage.
    pub fn set_coverage(&mut self, coverage: super::edge::Coverage) {
        self.coverage = Some(coverage);
    }

    /// Add pixel `(x, y)`'s stored values.
    #[inline]
    pub fn add(&mut self, (x, y): (usize, usize), rgb: [f64; 3]) {
        let weight = self.coverage.as_ref().map_or(1.0, |cov| cov.at(x, y));
        for (s, v) in self.sums.iter_mut().zip(rgb) {
            s.add(v * weight);
        }
    }

    /// Per channel, the sum.
    pub fn values(&self) -> Vec<f64> {
        self.sums.iter().map(|s| s.value()).collect()
    }
}

/// A compensated (Neumaier) sum.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CompensatedSum {
    sum: f64,
    comp: f64,
}

impl CompensatedSum {
    /// Add one value.
    #[inline]
    pub fn add(&mut self, v: f64) {
        let t = self.sum + v;
        if self.sum.abs() >= v.abs() {
            self.comp += (self.sum - t) + v;
        } else {
            self.comp += (v - t) + self.sum;
        }
        self.sum = t;
    }

    /// Add another compensated sum.
    pub fn merge(&mut self, other: &CompensatedSum) {
        self.add(other.sum);
        self.add(other.comp);
    }

    /// The sum.
    pub fn value(&self) -> f64 {
        self.sum + self.comp
    }
}

/// Lanes of [`sum_lanes`]: independent compensated sums that the compiler
/// can keep in vector registers.
const LANES: usize = 8;

/// Compensated sum and plain absolute sum of `values`, in a fixed order (8
/// interleaved lanes of Knuth's branch-free TwoSum, merged lane by lane), so
/// the result is the same on every run and accurate to about one unit in the
/// last place of the total. About 8x the throughput of a serial Neumaier sum.
pub fn sum_lanes<T: Copy + Into<f64>>(values: &[T]) -> (CompensatedSum, f64) {
    let mut s = [0.0f64; LANES];
    let mut c = [0.0f64; LANES];
    let mut m = [0.0f64; LANES];
    let mut chunks = values.chunks_exact(LANES);
    for ch in &mut chunks {
        for k in 0..LANES {
            let v: f64 = ch[k].into();
            let t = s[k] + v;
            let z = t - s[k];
            c[k] += (s[k] - (t - z)) + (v - z);
            s[k] = t;
            m[k] += v.abs();
        }
    }
    let mut total = CompensatedSum::default();
    let mut mass = 0.0;
    for k in 0..LANES {
        total.add(s[k]);
        total.add(c[k]);
        mass += m[k];
    }
    for &v in chunks.remainder() {
        let v: f64 = v.into();
        total.add(v);
        mass += v.abs();
    }
    (total, mass)
}

/// Per-channel sums of one row (or more).
#[derive(Clone, Debug, Default)]
pub struct Sums {
    /// Sum of values, one per channel.
    pub values: Vec<CompensatedSum>,
    /// Sum of absolute values, one per channel.
    pub mass: Vec<CompensatedSum>,
}

impl Sums {
    /// Add the values of channel `c` (see [`sum_lanes`]); returns whether
    /// they were all finite, as their absolute sum is for `f32` values: a
    /// sum of finite `f32` values (at most 3.4e38 each, fewer than 2^60 of
    /// them) cannot reach infinity in `f64`, and one infinity or NaN makes it
    /// infinite or NaN.
    pub fn add_slice<T: Copy + Into<f64>>(&mut self, c: usize, values: &[T]) -> bool {
        let (s, m) = sum_lanes(values);
        self.values[c].merge(&s);
        self.mass[c].add(m);
        m.is_finite()
    }
}

impl Sums {
    /// Zeroed sums for `n` channels.
    pub fn new(n: usize) -> Self {
        Sums {
            values: vec![CompensatedSum::default(); n],
            mass: vec![CompensatedSum::default(); n],
        }
    }

    /// Merge `other` (channel by channel).
    pub fn merge(&mut self, other: &Sums) {
        for (a, b) in self.values.iter_mut().zip(&other.values) {
            a.merge(b);
        }
        for (a, b) in self.mass.iter_mut().zip(&other.mass) {
            a.merge(b);
        }
    }
}

/// One channel's line of the ledger.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ChannelLedger {
    /// Channel name.
    pub channel: String,
    /// Sum of input values.
    pub energy_in: f64,
    /// Sum of output values before rounding, times S².
    pub energy_out: f64,
    /// Sum of output values as written (after rounding), times S².
    pub energy_out_rounded: f64,
    /// `|out - in| / sum|in|` before rounding (`|out - in| / |in|` for
    /// non-negative images; the absolute mass keeps it meaningful when signed
    /// values cancel). 0 when the input is all zero and so is the output.
    pub rel_error: f64,
    /// The same after rounding.
    pub rel_error_rounded: f64,
    /// Sum of absolute input values (the mass the errors are relative to).
    pub mass_in: f64,
}

impl ChannelLedger {
    /// Replace the "after rounding" figures by what the file holds, `sum`
    /// (times S²), where a lossy codec changed the values written.
    pub fn set_on_disk(&mut self, sum: f64) {
        self.energy_out_rounded = sum;
        self.rel_error_rounded = rel(sum, self.energy_in, self.mass_in);
    }
}

/// The ledger of a run.
#[derive(Clone, Debug, Default)]
pub struct Ledger {
    /// Input sums.
    pub input: Sums,
    /// Output sums before rounding (not yet times S²).
    pub output: Sums,
    /// Output sums after rounding (not yet times S²).
    pub rounded: Sums,
}

fn rel(a: f64, b: f64, mass: f64) -> f64 {
    let d = (a - b).abs();
    if d == 0.0 {
        0.0
    } else if mass > 0.0 {
        d / mass
    } else {
        f64::INFINITY
    }
}

impl Ledger {
    /// A ledger for `n` channels.
    pub fn new(n: usize) -> Self {
        Ledger {
            input: Sums::new(n),
            output: Sums::new(n),
            rounded: Sums::new(n),
        }
    }

    /// The per-channel balance, `s2` = S².
    pub fn balance(&self, names: &[String], s2: f64) -> Vec<ChannelLedger> {
        names
            .iter()
            .enumerate()
            .map(|(c, name)| {
                let e_in = self.input.values[c].value();
                let mass = self.input.mass[c].value();
                let e_out = self.output.values[c].value() * s2;
                let e_round = self.rounded.values[c].value() * s2;
                ChannelLedger {
                    channel: name.clone(),
                    energy_in: e_in,
                    energy_out: e_out,
                    energy_out_rounded: e_round,
                    rel_error: rel(e_out, e_in, mass),
                    rel_error_rounded: rel(e_round, e_in, mass),
                    mass_in: mass,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn add_slice_says_whether_every_value_was_finite() {
        let mut s = Sums::new(1);
        // The largest finite values, many of them: the absolute sum stays
        // finite in f64.
        assert!(s.add_slice(0, &vec![f32::MAX; 100_003]));
        assert!(s.add_slice(0, &[f32::MIN, f32::MAX, -0.0, 1e-45]));
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            for at in [0, 5, 16, 17] {
                let mut v = vec![1.0f32; 18];
                v[at] = bad;
                assert!(!Sums::new(1).add_slice(0, &v), "{bad} at {at}");
            }
        }
        // Infinities of both signs do not cancel in the absolute sum.
        assert!(!Sums::new(1).add_slice(0, &[f32::INFINITY, f32::NEG_INFINITY]));
    }

    #[test]
    fn lane_sums_are_exact_on_cancelling_extremes() {
        let mut v = vec![1.0f64; 1001];
        v[3] = 1e30;
        v[500] = -1e30;
        let (s, m) = sum_lanes(&v);
        assert_eq!(s.value(), 999.0);
        assert_eq!(m, 2e30 + 999.0);
    }

    #[test]
    fn compensated_sum_recovers_small_terms() {
        let mut s = CompensatedSum::default();
        s.add(1e30);
        for _ in 0..1000 {
            s.add(1.0);
        }
        s.add(-1e30);
        assert_eq!(s.value(), 1000.0);
    }
}
