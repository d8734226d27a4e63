//! The order-statistic foils: `median` and `alpha-trim` (Lee & Redner's
//! alpha-trimmed mean). Each output pixel gathers the S x S samples of its
//! pixel (at S = 1: the 3 x 3 pixels around it, reflected at the borders),
//! per channel, sorts them and averages what is left after trimming from
//! each end. They discard energy by design; the ledger reports how much.

use rayon::prelude::*;

use super::books::Books;
use super::engine::{Counters, OutRows};
use super::window::RowWindow;
use super::{Precision, Strip};
use crate::error::{Error, Result};
use crate::geometry::{mirror, Grid, Halo};

/// What is kept of the sorted values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Trim {
    /// The median (the mean of the two middle values for an even count).
    Median,
    /// Trim `floor(alpha * n)` values from each end (at least one is kept).
    Alpha(f64),
}

impl Trim {
    /// The mean of `v` after trimming (sorts `v`).
    pub fn apply(self, v: &mut [f64]) -> f64 {
        let n = v.len();
        v.sort_unstable_by(|a, b| a.total_cmp(b));
        let k = match self {
            Trim::Median => (n - 1) / 2,
            Trim::Alpha(a) => ((a * n as f64).floor() as usize).min((n - 1) / 2),
        };
        let kept = &v[k..n - k];
        kept.iter().sum::<f64>() / kept.len() as f64
    }
}

/// Streaming state of an order-statistic foil.
pub struct OrderEngine {
    grid: Grid,
    w: usize,
    h: usize,
    nch: usize,
    trim: Trim,
    precision: Precision,
    input: RowWindow<f32>,
    out: RowWindow<f64>,
    rows_in: usize,
    out_done: usize,
    books: Books,
}

impl OrderEngine {
    /// An engine for `grid` over `names`.
    pub fn new(grid: Grid, names: Vec<String>, trim: Trim, precision: Precision) -> Result<Self> {
        let s = grid.s;
        if grid.in_w == 0 || grid.in_h == 0 {
            return Err(Error::Config("the image is empty".into()));
        }
        if s == 0 || grid.in_w % s != 0 || grid.in_h % s != 0 {
            return Err(Error::Config(format!(
                "image size {}x{} is not a multiple of --supersample {s}",
                grid.in_w, grid.in_h
            )));
        }
        if let Trim::Alpha(a) = trim {
            if !(0.0..0.5).contains(&a) {
                return Err(Error::Config(format!("--alpha must be in 0..0.5, got {a}")));
            }
        }
        let nch = names.len();
        Ok(OrderEngine {
            grid,
            w: grid.out_w(),
            h: grid.out_h(),
            nch,
            trim,
            precision,
            input: RowWindow::new(nch * grid.in_w),
            out: RowWindow::new(nch * grid.out_w()),
            rows_in: 0,
            out_done: 0,
            books: Books::new(names, nch),
        })
    }

    /// One row of input either side at S = 1 (the 3 x 3 window), none above.
    pub fn halo(&self) -> Halo {
        Halo {
            base_reach: usize::from(self.grid.s == 1),
            ..Default::default()
        }
    }
    /// Output rows finished.
    pub fn rows_out(&self) -> usize {
        self.out_done
    }
    /// No noise test: all zero.
    pub fn counters(&self) -> Counters {
        Counters::default()
    }
    /// Input and output rows held at most.
    pub fn high_water(&self) -> [usize; 5] {
        [self.input.high_water(), 0, 0, self.out.high_water(), 0]
    }
    /// Names, ledger, digest and non-finite counts.
    pub fn books(&self) -> &Books {
        &self.books
    }
    /// The same, to set the non-finite policy.
    pub fn books_mut(&mut self) -> &mut Books {
        &mut self.books
    }

    /// Feed a strip; returns the output rows it finished.
    pub fn push(&mut self, mut strip: Strip) -> Result<Option<OutRows>> {
        let (in_w, in_h, s) = (self.grid.in_w, self.grid.in_h, self.grid.s);
        let row_len = self.nch * in_w;
        self.books.take(&mut strip, self.rows_in, in_w, in_h)?;
        for row in strip.data.chunks(row_len) {
            self.input.push_copy(row);
        }
        self.rows_in += strip.rows;
        // Output row y reads input rows up to (y+1)S - 1, plus one at S = 1.
        let ready = if self.rows_in == in_h {
            self.h
        } else {
            (self.rows_in.saturating_sub(usize::from(s == 1))) / s
        };
        if ready <= self.out_done {
            return Ok(None);
        }
        let (a, b) = (self.out_done, ready);
        for _ in a..b {
            self.out.push_stale(0.0);
        }
        let (w, h, nch, trim) = (self.w, self.h, self.nch, self.trim);
        let input = &self.input;
        let rows = self.out.range_mut(a, b);
        rows.into_par_iter()
            .enumerate()
            .for_each_init(Vec::new, |vals, (k, row)| {
                let y = a + k;
                for c in 0..nch {
                    for x in 0..w {
                        vals.clear();
                        if s == 1 {
                            for dy in -1i64..=1 {
                                let r = input.get(mirror(y as i64 + dy, h));
                                for dx in -1i64..=1 {
                                    vals.push(r[c * in_w + mirror(x as i64 + dx, w)] as f64);
                                }
                            }
                        } else {
                            for j in y * s..(y + 1) * s {
                                let r = &input.get(j)[c * in_w..(c + 1) * in_w];
                                vals.extend(r[x * s..(x + 1) * s].iter().map(|&v| v as f64));
                            }
                        }
                        row[c * w + x] = trim.apply(vals);
                    }
                }
            });
        let out = self
            .books
            .finish(&self.out, None, a, b, w, self.precision)?;
        self.out_done = b;
        self.out.evict_below(b);
        // Keep the last input row used (S = 1 reads row y - 1 of the next).
        self.input
            .evict_below((b * s).saturating_sub(usize::from(s == 1)));
        Ok(Some(out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trims() {
        assert_eq!(Trim::Median.apply(&mut [5.0, 1.0, 3.0]), 3.0);
        assert_eq!(Trim::Median.apply(&mut [4.0, 1.0, 3.0, 100.0]), 3.5);
        assert_eq!(Trim::Alpha(0.0).apply(&mut [1.0, 2.0, 6.0]), 3.0);
        // 9 values, alpha 0.2: one from each end.
        let mut v = [9.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 1000.0];
        assert_eq!(
            Trim::Alpha(0.2).apply(&mut v),
            (2.0 + 3.0 + 4.0 + 5.0 + 6.0 + 7.0 + 9.0) / 7.0
        );
        assert_eq!(Trim::Alpha(0.49).apply(&mut [1.0, 2.0]), 1.5);
    }
}
