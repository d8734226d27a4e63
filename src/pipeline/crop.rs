//! A source cut to its first columns and rows: `--edge crop`, for inputs whose
//! size is not a multiple of the super-sampling factor. Each strip is compacted
//! in place (rows are `[channel][x]`), so the pipeline sees an image whose
//! size is a multiple of S and never the dropped samples.

use super::{Source, Strip};
use crate::error::Result;

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
