//! Shrinking rows by area: each output pixel is the mean of the input
//! area it covers, so a preview of a huge render keeps each region's
//! brightness (a firefly becomes a faint dot, not a lost or a saturated one).

/// An area-averaging shrink of a `w_in` x `h_in` image of `k` values per
/// pixel to `w_out` x `h_out`, fed one input row at a time.
///
/// In units of 1/`w_out` of an input column, input column `x` covers
/// `[x w_out, (x + 1) w_out)` and output column `j` covers
/// `[j w_in, (j + 1) w_in)`; rows likewise. The overlaps are whole numbers,
/// so the weights are exact and sum to `w_in h_in` over each output pixel.
/// Shrinking only (`w_out <= w_in`, `h_out <= h_in`): an input pixel
/// reaches at most two output columns and two output rows.
pub struct AreaShrink {
    k: usize,
    w_in: u64,
    h_in: u64,
    w_out: u64,
    h_out: u64,
    /// Per input column: its first output column and its overlap with it.
    cols: Vec<(usize, f64)>,
    /// The output row being made and the next one, `w_out * k` sums each.
    acc: [Vec<f64>; 2],
    /// Input rows taken.
    y_in: u64,
    /// Output rows given.
    y_out: u64,
    row: Vec<f64>,
}

impl AreaShrink {
    /// The shrink of `w_in` x `h_in` to `w_out` pixels wide, keeping the
    /// aspect ratio (at least one row).
    pub fn to_width(k: usize, (w_in, h_in): (usize, usize), w_out: usize) -> Self {
        let w_out = w_out.clamp(1, w_in.max(1));
        let h_out = ((h_in as u128 * w_out as u128 + w_in as u128 / 2) / w_in.max(1) as u128)
            .clamp(1, h_in.max(1) as u128) as usize;
        Self::new(k, (w_in, h_in), (w_out, h_out))
    }

    /// The shrink of `w_in` x `h_in` to `w_out` x `h_out` (each at most the
    /// input's).
    pub fn new(k: usize, (w_in, h_in): (usize, usize), (w_out, h_out): (usize, usize)) -> Self {
        debug_assert!(w_out <= w_in && h_out <= h_in);
        let (wi, wo) = (w_in as u64, w_out as u64);
        let cols = (0..wi)
            .map(|x| {
                let j = x * wo / wi;
                let part = ((x + 1) * wo).min((j + 1) * wi) - x * wo;
                (j as usize, part as f64)
            })
            .collect();
        AreaShrink {
            k,
            w_in: wi,
            h_in: h_in as u64,
            w_out: wo,
            h_out: h_out as u64,
            cols,
            acc: [vec![0.0; w_out * k], vec![0.0; w_out * k]],
            y_in: 0,
            y_out: 0,
            row: vec![0.0; w_out * k],
        }
    }

    /// The output's size.
    pub fn size(&self) -> (usize, usize) {
        (self.w_out as usize, self.h_out as usize)
    }

    /// Take the next input row (`w_in * k` values, pixel after pixel); give
    /// `emit` each output row it finishes.
    pub fn push<E>(
        &mut self,
        row: &[f64],
        mut emit: impl FnMut(&[f64]) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.w_out == self.w_in && self.h_out == self.h_in {
            // As read: no sum to round.
            self.y_in += 1;
            return emit(row);
        }
        let (k, y) = (self.k, self.y_in);
        let first = ((y + 1) * self.h_out).min((self.y_out + 1) * self.h_in) - y * self.h_out;
        let rest = self.h_out - first;
        let wo = self.w_out;
        for (x, &(j, part)) in self.cols.iter().enumerate() {
            let px = &row[x * k..(x + 1) * k];
            let other = wo as f64 - part;
            for (r, wy) in [(0, first), (1, rest)] {
                if wy == 0 {
                    continue;
                }
                let wy = wy as f64;
                let acc = &mut self.acc[r];
                for (c, &v) in px.iter().enumerate() {
                    acc[j * k + c] += v * part * wy;
                    if other > 0.0 {
                        acc[(j + 1) * k + c] += v * other * wy;
                    }
                }
            }
        }
        self.y_in += 1;
        if self.y_in * self.h_out >= (self.y_out + 1) * self.h_in {
            let norm = (self.w_in * self.h_in) as f64;
            for (o, a) in self.row.iter_mut().zip(&self.acc[0]) {
                *o = a / norm;
            }
            self.acc.swap(0, 1);
            self.acc[1].iter_mut().for_each(|a| *a = 0.0);
            self.y_out += 1;
            emit(&self.row)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sums of a few hundred products of small whole numbers and values
    /// near 1: rounding, not method, error.
    const SUM_TOL: f64 = 1e-12;

    fn shrink(w: usize, h: usize, to: (usize, usize), img: &[f64]) -> Vec<f64> {
        let mut s = AreaShrink::new(1, (w, h), to);
        let mut out = Vec::new();
        for row in img.chunks(w) {
            s.push(row, |r| {
                out.extend_from_slice(r);
                Ok::<(), ()>(())
            })
            .unwrap();
        }
        out
    }

    #[test]
    fn the_mean_is_kept_and_each_output_pixel_is_its_areas_mean() {
        let (w, h) = (7, 5);
        let img: Vec<f64> = (0..w * h).map(|i| ((i * 37) % 11) as f64).collect();
        for to in [(1, 1), (3, 2), (4, 3), (7, 5), (2, 5), (7, 1)] {
            let out = shrink(w, h, to, &img);
            assert_eq!(out.len(), to.0 * to.1);
            let mean_in = img.iter().sum::<f64>() / img.len() as f64;
            let mean_out = out.iter().sum::<f64>() / out.len() as f64;
            assert!((mean_in - mean_out).abs() < SUM_TOL * mean_in, "{to:?}");
        }
        // A whole-number factor: plain block means.
        let out = shrink(4, 2, (2, 1), &[1.0, 3.0, 5.0, 7.0, 1.0, 3.0, 5.0, 7.0]);
        assert_eq!(out, vec![2.0, 6.0]);
        // The same size: the image itself, bit for bit.
        assert_eq!(shrink(w, h, (w, h), &img), img);
    }

    #[test]
    fn to_width_keeps_the_aspect_and_at_least_a_row() {
        assert_eq!(
            AreaShrink::to_width(3, (32769, 32769), 1024).size(),
            (1024, 1024)
        );
        assert_eq!(AreaShrink::to_width(3, (4000, 10), 100).size(), (100, 1));
        assert_eq!(AreaShrink::to_width(3, (100, 50), 400).size(), (100, 50));
    }
}
