//! The spreads of a pixel-resolution stage (ep-gauss at S = 1, ep-box),
//! held as their sources until the rows they reach are written.
//!
//! A stage that spreads sparse sources at pixel resolution would need, as an
//! accumulator, f64 rows of the whole width from the row being written to
//! the widest kernel's reach past the rows treated: twice the reach, for a
//! few fireflies a row. Instead each source is kept (its pixel, what its
//! pixel keeps, what one unit of its kernel carries) and an output row is
//! made when it is final ([`Gathered`]): the input row, the kept values of the
//! sources on it, plus every source's share that reaches it. Memory then
//! follows what is spread, not the width times the reach.
//!
//! Sources are listed in row-major order and each output pixel adds its
//! shares in that order, from `-0.0`, as an accumulator that received them
//! as they were treated would: the same bits, whatever the strips, tiles
//! or threads. A row no source reaches is the input row, bit for bit.

use std::sync::Mutex;

use rayon::iter::{IndexedParallelIterator, IntoParallelIterator, ParallelIterator};

use crate::pipeline::stage::{Output, WindowUse};
use crate::pipeline::window::RowWindow;

/// Where a source sits.
pub trait Placed {
    /// Its column and row.
    fn at(&self) -> (usize, usize);
}

/// The sources treated and not yet written past, in row-major order, with
/// their values: per source, what its pixel keeps of each spread channel
/// then what one unit of its kernel's weight carries of each (the other
/// channels keep their bits: a source holds nothing of them).
pub(super) struct Sources<S> {
    list: Vec<S>,
    values: Vec<f64>,
    /// The channels spread (an output row's planes).
    spread: Vec<usize>,
    /// The widest kernel's reach in rows.
    reach: usize,
    high_water: usize,
}

impl<S: Placed + Sync> Sources<S> {
    /// No sources yet, spreading channels `spread`, kernels reaching
    /// `reach` rows.
    pub(super) fn new(spread: Vec<usize>, reach: usize) -> Self {
        Sources {
            list: Vec::new(),
            values: Vec::new(),
            spread,
            reach,
            high_water: 0,
        }
    }

    /// Add the sources of rows below any held (`values`: two a spread
    /// channel each).
    pub(super) fn extend(&mut self, list: Vec<S>, values: Vec<f64>) {
        debug_assert_eq!(values.len(), list.len() * self.stride());
        debug_assert!(list.windows(2).all(|p| order(&p[0]) <= order(&p[1])));
        self.list.extend(list);
        self.values.extend(values);
        self.high_water = self.high_water.max(self.list.len());
    }

    /// Rows below `y` are written: drop the sources that reach no further.
    pub(super) fn release(&mut self, y: usize) {
        let n = self.list.partition_point(|s| s.at().1 + self.reach < y);
        self.list.drain(..n);
        self.values.drain(..n * self.stride());
    }

    /// Values a source holds (a treatment's lists are merged at this
    /// stride).
    pub(super) fn stride(&self) -> usize {
        2 * self.spread.len()
    }

    /// The most sources held at once.
    pub(super) fn high_water(&self) -> usize {
        self.high_water
    }

    /// Bytes a source holds beside its entry.
    pub(super) fn value_bytes(&self) -> usize {
        self.stride() * 8
    }

    /// Make output rows `a..b` into `out` (one slice a row, `w` columns
    /// per channel): the input row, with the kept values of the sources on
    /// it, plus the shares `add(source, shares, row, acc)` adds to row `row`
    /// of every source within the reach (in row-major order, into `acc`
    /// from `-0.0`).
    pub(super) fn make<F>(
        &self,
        input: &RowWindow<f32>,
        (a, out): (usize, Vec<&mut [f64]>),
        w: usize,
        spare: &Mutex<Vec<Vec<f64>>>,
        add: F,
    ) where
        F: Fn(&S, &[f64], usize, &mut [f64]) + Sync,
    {
        let (reach, spread) = (self.reach, &self.spread);
        let n = spread.len();
        let region = crate::trace::region("spread rows");
        let scratch = || Scratch {
            acc: spare
                .lock()
                .map(|mut v| v.pop())
                .ok()
                .flatten()
                .unwrap_or_default(),
            spare,
        };
        out.into_par_iter()
            .enumerate()
            .for_each_init(scratch, |scratch, (k, out)| {
                let _task = region.task("spread rows");
                let y = a + k;
                // The row's channels: the input row's first.
                for (o, &v) in out.iter_mut().zip(input.get(y)) {
                    *o = v as f64;
                }
                let lo = self.list.partition_point(|s| s.at().1 + reach < y);
                let hi = self.list.partition_point(|s| s.at().1 <= y + reach);
                if lo == hi {
                    return;
                }
                let acc = &mut scratch.acc;
                acc.clear();
                acc.resize(n * w, -0.0);
                for (i, s) in self.list[lo..hi].iter().enumerate() {
                    let v = &self.values[(lo + i) * 2 * n..(lo + i + 1) * 2 * n];
                    let (x, sy) = s.at();
                    if sy == y {
                        for (&c, &k) in spread.iter().zip(&v[..n]) {
                            out[c * w + x] = k;
                        }
                    }
                    add(s, &v[n..], y, acc);
                }
                // Adding `-0.0` keeps every value's bits: the channels no
                // source spreads are left as read.
                for (&c, acc) in spread.iter().zip(acc.chunks_exact(w)) {
                    for (o, &a) in out[c * w..(c + 1) * w].iter_mut().zip(acc) {
                        *o += a;
                    }
                }
            });
    }
}

/// A task's accumulator row, back to the stage's spares when the task ends.
struct Scratch<'a> {
    acc: Vec<f64>,
    spare: &'a Mutex<Vec<Vec<f64>>>,
}

impl Drop for Scratch<'_> {
    fn drop(&mut self) {
        if let Ok(mut v) = self.spare.lock() {
            v.push(std::mem::take(&mut self.acc));
        }
    }
}

/// A pixel-resolution stage's spreads and what it makes of them: the
/// sources held until the rows they reach are made, and the output rows
/// made from the input and the sources, from the last row written to the
/// last final row.
pub(super) struct Gathered<S> {
    pub(super) sources: Sources<S>,
    pub(super) rows: RowWindow<f64>,
    /// Accumulator rows the tasks making rows reuse.
    spare: Mutex<Vec<Vec<f64>>>,
    /// Output rows written.
    released: usize,
}

impl<S: Placed + Sync> Gathered<S> {
    /// Nothing yet, for rows of `nch` channels `w` wide and sources that
    /// spread channels `spread` and reach `reach` rows.
    pub(super) fn new(nch: usize, spread: Vec<usize>, w: usize, reach: usize) -> Self {
        Gathered {
            sources: Sources::new(spread, reach),
            rows: RowWindow::new(nch * w),
            spare: Mutex::new(Vec::new()),
            released: 0,
        }
    }

    /// Make the rows up to `end` ([`Sources::make`]).
    pub(super) fn make_to<F>(&mut self, input: &RowWindow<f32>, (end, w): (usize, usize), add: F)
    where
        F: Fn(&S, &[f64], usize, &mut [f64]) + Sync,
    {
        let a = self.rows.end();
        if end <= a {
            return;
        }
        for _ in a..end {
            self.rows.push_stale(0.0);
        }
        let out = self.rows.range_mut(a, end);
        self.sources.make(input, (a, out), w, &self.spare, add);
    }

    /// Output rows written.
    pub(super) fn released(&self) -> usize {
        self.released
    }

    /// Rows `rows` of the output.
    pub(super) fn output(&self, rows: (usize, usize)) -> Output<'_> {
        Output::of(&self.rows, None, rows)
    }

    /// The rows below `y` are written: they and the sources that reach no
    /// lower go.
    pub(super) fn release(&mut self, y: usize) {
        self.released = y;
        self.rows.evict_below(y);
        self.sources.release(y);
    }

    /// What the output rows and the sources hold, for the estimate's check.
    pub(super) fn windows(&self) -> [WindowUse; 2] {
        [
            WindowUse {
                name: "output",
                rows: self.rows.high_water(),
                row_bytes: self.rows.row_len() * 8,
            },
            WindowUse {
                name: "sources (one a row)",
                rows: self.sources.high_water(),
                row_bytes: std::mem::size_of::<S>() + self.sources.value_bytes(),
            },
        ]
    }
}

fn order<S: Placed>(s: &S) -> (usize, usize) {
    let (x, y) = s.at();
    (y, x)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Dot(usize, usize);
    impl Placed for Dot {
        fn at(&self) -> (usize, usize) {
            (self.0, self.1)
        }
    }

    fn input(w: usize, h: usize) -> RowWindow<f32> {
        let mut win = RowWindow::new(w);
        for y in 0..h {
            let row = win.push(0.0);
            for (x, v) in row.iter_mut().enumerate() {
                *v = (y * w + x) as f32;
            }
        }
        win
    }

    /// A source adding its share to the pixel beside it, one row down.
    fn below(s: &Dot, share: &[f64], y: usize, acc: &mut [f64]) {
        if y == s.1 + 1 {
            acc[s.0 + 1] += share[0];
        }
    }

    #[test]
    fn rows_hold_the_kept_values_and_the_shares_and_untouched_rows_the_input() {
        let (w, h) = (6, 5);
        let win = input(w, h);
        let mut g = Gathered::new(1, vec![0], w, 1);
        g.sources
            .extend(vec![Dot(1, 1), Dot(3, 1)], vec![0.5, 2.0, 7.0, 4.0]);
        g.make_to(&win, (h, w), below);
        let rows: Vec<&[f64]> = (0..h).map(|y| g.rows.get(y)).collect();
        assert_eq!(rows[1][1], 0.5);
        assert_eq!(rows[1][3], 7.0);
        assert_eq!(rows[2][2], 14.0 + 2.0);
        assert_eq!(rows[2][4], 16.0 + 4.0);
        for y in [0, 3, 4] {
            for (x, v) in rows[y].iter().enumerate() {
                assert_eq!(v.to_bits(), ((y * w + x) as f64).to_bits());
            }
        }
        // Row 2 is written: the sources of row 1 still reach it; past it,
        // they are dropped.
        g.release(2);
        assert_eq!(g.sources.list.len(), 2);
        g.release(3);
        assert!(g.sources.list.is_empty() && g.sources.values.is_empty());
        assert_eq!(g.sources.high_water(), 2);
    }

    #[test]
    fn channels_no_source_spreads_keep_their_bits_and_cost_a_source_nothing() {
        let (w, h) = (4, 3);
        // Channel 0 is spread; channel 1 is carried (signed zeros and a
        // NaN among its values).
        let carried = |y: usize, x: usize| match (y + x) % 3 {
            0 => -0.0,
            1 => f32::NAN,
            _ => (y * w + x) as f32,
        };
        let mut win = RowWindow::new(2 * w);
        for y in 0..h {
            let row = win.push(0.0);
            for x in 0..w {
                row[x] = 1.0;
                row[w + x] = carried(y, x);
            }
        }
        let mut g = Gathered::new(2, vec![0], w, 1);
        // Two values a source: what it keeps of channel 0 and what it
        // carries of it.
        g.sources.extend(vec![Dot(1, 1)], vec![0.25, 0.75]);
        assert_eq!(g.sources.value_bytes(), 16);
        g.make_to(&win, (h, w), below);
        assert_eq!(g.rows.get(1)[1], 0.25);
        assert_eq!(g.rows.get(2)[2], 1.75);
        for y in 0..h {
            for x in 0..w {
                let v = g.rows.get(y)[w + x];
                assert_eq!(v.to_bits(), (carried(y, x) as f64).to_bits(), "{x} {y}");
            }
        }
    }
}
