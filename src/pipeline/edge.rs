//! Inputs whose size is not a multiple of the super-sampling factor.
//!
//! * `--edge crop` ([`Cropped`]): the source cut to its first columns and
//!   rows. Each strip is compacted in place (rows are `[channel][x]`), so the
//!   pipeline sees an image whose size is a multiple of S and never the
//!   dropped samples.
//! * `--edge pad` ([`Padded`], [`Coverage`]): the source completed with zero
//!   samples to the next multiple of S, so the last output column and row are
//!   made of fewer super-samples. Zeros add no energy, and every sample's
//!   weights still sum to one; an output pixel's value is then divided by its
//!   coverage, the share of its kernel's weight that fell on real samples, so
//!   it is the kernel average over what exists (a flat field stays flat to
//!   the last partial pixel). The pixel stands for that share of a pixel's
//!   area: energy is `sum(value * coverage) * S^2`, which is what the ledger
//!   counts, exact as before.

use super::{Source, Strip};
use crate::error::Result;
use crate::filter::kernel::Kernel1d;
use crate::filter::{FilterParams, Method};
use crate::geometry::Grid;

/// The first `w` columns and `h` rows of a source `full_w` samples wide.
pub struct Cropped<S> {
    inner: S,
    full_w: usize,
    w: usize,
    h: usize,
    done: bool,
}

impl<S: Source> Cropped<S> {
    /// `inner` (rows `full_w` samples wide) cut to `w` x `h`; `w <= full_w`.
    pub fn new(inner: S, full_w: usize, w: usize, h: usize) -> Self {
        assert!(w <= full_w, "a crop cannot widen the image");
        Cropped {
            inner,
            full_w,
            w,
            h,
            done: false,
        }
    }
}

impl<S: Source> Source for Cropped<S> {
    super::decode_ahead_in_inner!();

    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        if self.done {
            return Ok(None);
        }
        let Some(mut strip) = self.inner.next_strip(max_rows)? else {
            self.done = true;
            return Ok(None);
        };
        if strip.y0 >= self.h || strip.rows == 0 {
            self.done = true;
            return Ok(None);
        }
        let rows = strip.rows.min(self.h - strip.y0);
        let nch = strip.data.len() / (strip.rows * self.full_w);
        if self.w != self.full_w {
            // Forward copies: each destination lies at or before its source.
            for line in 0..rows * nch {
                let src = line * self.full_w;
                strip.data.copy_within(src..src + self.w, line * self.w);
            }
        }
        strip.data.truncate(rows * nch * self.w);
        strip.rows = rows;
        if strip.y0 + rows >= self.h {
            self.done = true;
        }
        Ok(Some(strip))
    }
}

/// A source completed with zero samples: rows `real_w` samples wide become
/// `w` wide, and rows `real_h..h` are zero rows (`w >= real_w`,
/// `h >= real_h`). A source that starts below row 0 (a band's window) is
/// completed the same way.
pub struct Padded<S> {
    inner: S,
    real: (usize, usize),
    size: (usize, usize),
    nch: usize,
    next_y: Option<usize>,
    inner_done: bool,
}

impl<S: Source> Padded<S> {
    /// `inner` (`real.0` x `real.1` samples, `nch` channels per row)
    /// completed to `size`; with `real == size` strips pass unchanged.
    pub fn new(inner: S, real: (usize, usize), size: (usize, usize), nch: usize) -> Self {
        assert!(
            real.0 <= size.0 && real.1 <= size.1,
            "padding cannot shrink"
        );
        Padded {
            inner,
            real,
            size,
            nch,
            next_y: None,
            inner_done: false,
        }
    }
}

impl<S: Source> Source for Padded<S> {
    super::decode_ahead_in_inner!();

    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        let ((rw, rh), (w, h), nch) = (self.real, self.size, self.nch);
        if !self.inner_done {
            match self.inner.next_strip(max_rows)? {
                Some(mut strip) => {
                    if w != rw {
                        // Backward copies: each line moves to or after its
                        // place, last line first.
                        strip.data.resize(strip.rows * nch * w, 0.0);
                        for line in (0..strip.rows * nch).rev() {
                            strip.data.copy_within(line * rw..line * rw + rw, line * w);
                            strip.data[line * w + rw..(line + 1) * w].fill(0.0);
                        }
                    }
                    self.next_y = Some(strip.y0 + strip.rows);
                    return Ok(Some(strip));
                }
                None => self.inner_done = true,
            }
        }
        // Zero rows from where the input ended (an empty source: nothing).
        let Some(y0) = self.next_y.filter(|&y| y >= rh && y < h) else {
            return Ok(None);
        };
        let rows = max_rows.max(1).min(h - y0);
        self.next_y = Some(y0 + rows);
        Ok(Some(Strip {
            y0,
            rows,
            data: vec![0.0; rows * nch * w],
        }))
    }
}

/// Per output column and row of a padded grid, the share of the base
/// kernel's weight that falls on real samples; `1.0` exactly where no padded
/// sample is in reach. A pixel's coverage is `x[px] * y[py]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Coverage {
    /// Per output column.
    pub x: Vec<f64>,
    /// Per output row.
    pub y: Vec<f64>,
}

impl Coverage {
    /// The coverage under the base kernel of `params`' method (the box for
    /// `box`, the base Gaussian for the others that pad).
    pub fn of(params: &FilterParams, grid: Grid, real: (usize, usize)) -> Self {
        let base = match params.method {
            Method::Box => Kernel1d::boxed(grid.s),
            _ => Kernel1d::gaussian(grid.s, params.radius, params.cutoff),
        };
        Coverage::new(&base, grid, real)
    }

    /// A pixel's coverage: `x[px] * y[py]`.
    #[inline]
    pub fn at(&self, px: usize, py: usize) -> f64 {
        self.x[px] * self.y[py]
    }

    /// The coverage of `grid` (padded) whose real samples are the first
    /// `real.0` x `real.1`, under the base kernel `k`.
    pub fn new(k: &Kernel1d, grid: Grid, real: (usize, usize)) -> Self {
        let axis = |n_out: usize, n_in: usize, n_real: usize| -> Vec<f64> {
            let mut scratch = Vec::new();
            (0..n_out)
                .map(|x| {
                    let start = k.gather(x, n_out, n_in, &mut scratch);
                    if start + scratch.len() <= n_real {
                        return 1.0;
                    }
                    // The gather weights of an output index sum to S (each
                    // sample's weights sum to one, S samples per index).
                    let real: f64 = scratch.iter().take(n_real.saturating_sub(start)).sum();
                    real / grid.s as f64
                })
                .collect()
        };
        Coverage {
            x: axis(grid.out_w(), grid.in_w, real.0),
            y: axis(grid.out_h(), grid.in_h, real.1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows of `nch` channels, value = y * 1000 + c * 100 + x.
    struct Rows {
        w: usize,
        h: usize,
        nch: usize,
        y: usize,
    }

    impl Source for Rows {
        fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
            if self.y >= self.h {
                return Ok(None);
            }
            let rows = max_rows.min(self.h - self.y);
            let mut data = Vec::new();
            for y in self.y..self.y + rows {
                for c in 0..self.nch {
                    data.extend((0..self.w).map(|x| (y * 1000 + c * 100 + x) as f32));
                }
            }
            let strip = Strip {
                y0: self.y,
                rows,
                data,
            };
            self.y += rows;
            Ok(Some(strip))
        }
    }

    #[test]
    fn padding_completes_every_channel_with_zeros_for_any_strip_height() {
        for strip_rows in [1, 2, 3, 7, 50] {
            let rows = Rows {
                w: 10,
                h: 8,
                nch: 2,
                y: 0,
            };
            let mut p = Padded::new(rows, (10, 8), (12, 9), 2);
            let mut next = 0;
            while let Some(s) = p.next_strip(strip_rows).unwrap() {
                assert_eq!(s.y0, next);
                assert_eq!(s.data.len(), s.rows * 2 * 12);
                for r in 0..s.rows {
                    let y = s.y0 + r;
                    for ch in 0..2 {
                        for x in 0..12 {
                            let v = s.data[(r * 2 + ch) * 12 + x];
                            let want = if x < 10 && y < 8 {
                                (y * 1000 + ch * 100 + x) as f32
                            } else {
                                0.0
                            };
                            assert_eq!(v, want, "({x}, {y}) {ch}, strips of {strip_rows}");
                        }
                    }
                }
                next += s.rows;
            }
            assert_eq!(next, 9, "strips of {strip_rows}");
        }
        // Nothing to pad: strips pass unchanged.
        let rows = Rows {
            w: 4,
            h: 3,
            nch: 1,
            y: 0,
        };
        let mut p = Padded::new(rows, (4, 3), (4, 3), 1);
        let s = p.next_strip(5).unwrap().unwrap();
        assert_eq!(
            s.data,
            (0..3)
                .flat_map(|y| (0..4).map(move |x| (y * 1000 + x) as f32))
                .collect::<Vec<_>>()
        );
        assert!(p.next_strip(5).unwrap().is_none());
    }

    #[test]
    fn coverage_is_the_real_share_of_each_kernel() {
        // The box: k of S columns.
        let grid = Grid {
            in_w: 12,
            in_h: 9,
            s: 3,
        };
        let c = Coverage::new(&Kernel1d::boxed(3), grid, (10, 7));
        assert_eq!(c.x, vec![1.0, 1.0, 1.0, 1.0 / 3.0]);
        assert_eq!(c.y, vec![1.0, 1.0, 1.0 / 3.0]);
        // Gaussians: exactly 1 out of reach of the padding, below 1 near it,
        // and the shares add up to the real samples over S (each sample's
        // weights sum to one).
        const SUM_TOL: f64 = 1e-12; // f64 sums of a few dozen weights
        for s in 2usize..=5 {
            for rho in [0.3, 0.6, 1.5] {
                for real in [s * 7 + 1, s * 7 + s - 1] {
                    let grid = Grid {
                        in_w: real.div_ceil(s) * s,
                        in_h: s,
                        s,
                    };
                    let c = Coverage::new(&Kernel1d::gaussian(s, rho, 3.0), grid, (real, s));
                    let sum: f64 = c.x.iter().sum();
                    assert!(
                        (sum - real as f64 / s as f64).abs() < SUM_TOL,
                        "S={s} rho={rho}: {sum}"
                    );
                    assert_eq!(c.x[0], 1.0);
                    assert!(c.x.iter().all(|&v| v > 0.0 && v <= 1.0 + SUM_TOL));
                    assert!(*c.x.last().unwrap() < 1.0);
                    assert_eq!(c.y, vec![1.0]);
                }
            }
        }
    }

    #[test]
    fn keeps_exactly_the_first_columns_and_rows_of_every_channel() {
        for strip_rows in [1, 2, 3, 7] {
            let rows = Rows {
                w: 11,
                h: 8,
                nch: 3,
                y: 0,
            };
            let mut c = Cropped::new(rows, 11, 9, 6);
            let mut seen = Vec::new();
            while let Some(s) = c.next_strip(strip_rows).unwrap() {
                assert_eq!(s.data.len(), s.rows * 3 * 9);
                for r in 0..s.rows {
                    for ch in 0..3 {
                        for x in 0..9 {
                            let v = s.data[(r * 3 + ch) * 9 + x];
                            assert_eq!(v, ((s.y0 + r) * 1000 + ch * 100 + x) as f32);
                        }
                    }
                    seen.push(s.y0 + r);
                }
            }
            assert_eq!(seen, (0..6).collect::<Vec<_>>(), "strips of {strip_rows}");
        }
    }
}
