//! Luminance, computed one way.
//!
//! Every rule that tests a sample (Relation 14, the feature rules, §5.1's
//! noise test, ep-box's first pass) reads its luminance, and several stages
//! compute it for the same samples: a sample's luminance here and a pixel's
//! box luminance there, a row at a time in one place and one sample at a time
//! in another. Output is bit-identical across tiles, strips and threads only
//! if they all agree to the last bit, so the arithmetic lives here:
//!
//! * a sample: `0.0 + w_c v_c` over the channels of non-zero weight, in
//!   channel order, in f64 ([`Luminance::of`], [`Luminance::row_into`]);
//! * a pixel's box sum: for each such channel, its S x S samples summed in f64
//!   row by row, left to right, times `w_c`, added to the pixel's value
//!   ([`Luminance::box_row_add`]).

/// The luminance weights of a strip's channels (0 for alpha, carried data
/// and statistics).
#[derive(Clone, Debug, PartialEq)]
pub struct Luminance {
    weights: Vec<f64>,
    /// Channels of non-zero weight, in order.
    used: Vec<usize>,
}

impl Luminance {
    /// Weights per channel, in strip order.
    pub fn new(weights: &[f64]) -> Self {
        Luminance {
            weights: weights.to_vec(),
            used: (0..weights.len()).filter(|&c| weights[c] != 0.0).collect(),
        }
    }

    /// The weights, per channel.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The luminance of one sample, its channel `c` being `v(c)`.
    #[inline]
    pub fn of(&self, v: impl Fn(usize) -> f64) -> f64 {
        let mut x = 0.0;
        for &c in &self.used {
            x += self.weights[c] * v(c);
        }
        x
    }

    /// The luminance of one sample, leaving out non-finite values (a mean
    /// over an image: the filter reports those samples, the mean ignores them).
    #[inline]
    pub fn of_finite(&self, v: impl Fn(usize) -> f64) -> f64 {
        let mut x = 0.0;
        for &c in &self.used {
            let v = v(c);
            if v.is_finite() {
                x += self.weights[c] * v;
            }
        }
        x
    }

    /// `out[i]` = the luminance of sample `i` of a planar row (`[c][i]`, `w`
    /// samples per channel): [`Luminance::of`] for every sample, a channel at
    /// a time.
    pub fn row_into(&self, row: &[f32], w: usize, out: &mut [f64]) {
        self.cols_into(row, w, 0..w, out);
    }

    /// [`Luminance::row_into`] for the samples `cols` of the row only
    /// (`out[i - cols.start]`): the same sum for each.
    pub fn cols_into(&self, row: &[f32], w: usize, cols: std::ops::Range<usize>, out: &mut [f64]) {
        let out = &mut out[..cols.len()];
        let ch = |c: usize| &row[c * w + cols.start..c * w + cols.end];
        // Colour, the common case: one pass.
        if let [c0, c1, c2] = self.used[..] {
            let (l0, l1, l2) = (self.weights[c0], self.weights[c1], self.weights[c2]);
            let rows = ch(c0).iter().zip(ch(c1)).zip(ch(c2));
            for (l, ((&v0, &v1), &v2)) in out.iter_mut().zip(rows) {
                let mut x = 0.0;
                x += l0 * v0 as f64;
                x += l1 * v1 as f64;
                x += l2 * v2 as f64;
                *l = x;
            }
            return;
        }
        out.fill(0.0);
        for &c in &self.used {
            let lw = self.weights[c];
            for (l, &v) in out.iter_mut().zip(ch(c)) {
                *l += lw * v as f64;
            }
        }
    }

    /// Add one sample row's share of its pixels' box sums: `out[px] += w_c
    /// (sum of the row's samples px*s .. (px+1)*s of channel c)` for every
    /// channel of non-zero weight (`row` planar, `in_w` samples per channel).
    /// Called for the S sample rows of a pixel row in order, from zeros.
    pub fn box_row_add(&self, row: &[f32], in_w: usize, s: usize, out: &mut [f64]) {
        for &c in &self.used {
            box_add(out, &row[c * in_w..(c + 1) * in_w], s, self.weights[c]);
        }
    }
}

/// `out[px] += lw * (sum of ch[px * s .. (px + 1) * s])`, the sum taken
/// left to right in f64: the same arithmetic for every `s`, with the common
/// factors in loops of their own, which the compiler unrolls (a loop of
/// variable length does not).
#[inline]
fn box_add(out: &mut [f64], ch: &[f32], s: usize, lw: f64) {
    #[inline(always)]
    fn fixed<const S: usize>(out: &mut [f64], ch: &[f32], lw: f64) {
        for (o, v) in out.iter_mut().zip(ch.chunks_exact(S)) {
            let mut acc = 0.0;
            for &v in v {
                acc += v as f64;
            }
            *o += lw * acc;
        }
    }
    match s {
        1 => fixed::<1>(out, ch, lw),
        2 => fixed::<2>(out, ch, lw),
        3 => fixed::<3>(out, ch, lw),
        4 => fixed::<4>(out, ch, lw),
        _ => {
            for (o, v) in out.iter_mut().zip(ch.chunks_exact(s)) {
                let mut acc = 0.0;
                for &v in v {
                    acc += v as f64;
                }
                *o += lw * acc;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows with values that round differently in other orders: each
    /// check below compares bits, not values within a tolerance.
    fn planar(nch: usize, w: usize) -> Vec<f32> {
        (0..nch * w)
            .map(|k| {
                let x = (k as f32 * 0.618_034).fract();
                [1e-30, 3.7, 1e30, -0.0, 0.1, 6.5e4][k % 6] * (1.0 + x)
            })
            .collect()
    }

    #[test]
    fn a_row_at_a_time_is_the_sample_rule_bit_for_bit() {
        let w = 17;
        for weights in [
            vec![0.2126, 0.7152, 0.0722],
            vec![0.2126, 0.7152, 0.0722, 0.0],
            vec![0.0, 0.3, 0.0, 0.5, 0.2],
            vec![1.0],
        ] {
            let lum = Luminance::new(&weights);
            let row = planar(weights.len(), w);
            let mut out = vec![f64::NAN; w];
            lum.row_into(&row, w, &mut out);
            for (i, &got) in out.iter().enumerate() {
                let one = lum.of(|c| row[c * w + i] as f64);
                assert_eq!(got.to_bits(), one.to_bits(), "{weights:?} sample {i}");
            }
        }
    }

    #[test]
    fn box_sums_are_the_pixels_samples_summed_in_order_then_weighed() {
        let (s, w) = (3, 5);
        let weights = [0.25, 0.0, 0.75];
        let lum = Luminance::new(&weights);
        let rows: Vec<Vec<f32>> = (0..s)
            .map(|r| {
                let mut v = planar(3, w * s);
                v.rotate_left(r);
                v
            })
            .collect();
        let mut out = vec![0.0; w];
        for r in &rows {
            lum.box_row_add(r, w * s, s, &mut out);
        }
        for (px, &got) in out.iter().enumerate() {
            let mut want = 0.0;
            for r in &rows {
                for c in [0, 2] {
                    let mut acc = 0.0;
                    for i in px * s..(px + 1) * s {
                        acc += r[c * w * s + i] as f64;
                    }
                    want += weights[c] * acc;
                }
            }
            assert_eq!(got.to_bits(), want.to_bits(), "pixel {px}");
        }
    }

    #[test]
    fn zero_weights_are_left_out_even_when_infinite() {
        let lum = Luminance::new(&[0.5, 0.0, 0.5]);
        let v = [2.0, f64::INFINITY, 4.0];
        assert_eq!(lum.of(|c| v[c]), 3.0);
        let v = [2.0, 1.0, f64::NAN];
        assert_eq!(lum.of_finite(|c| v[c]), 1.0);
        assert!(lum.of(|c| v[c]).is_nan());
    }
}
