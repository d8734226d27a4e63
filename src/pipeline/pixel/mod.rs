//! The stage of the pixel-resolution methods: ep-gauss at S = 1
//! ([`gauss`]) and ep-box ([`excess`]). Each is a [`Rule`] that declares
//! its passes over pixel rows and what each reads; [`PixelStage`] owns the
//! schedule.
//!
//! Pass 0 is the input (with what a rule makes of each row as it arrives:
//! the lights, the surface guides); each later pass makes its rows of
//! per-pixel windows from the rows earlier passes made; the last pass is
//! the treatment, which decides each noisy pixel and lists the spread ones
//! as sources (`gather.rs`). An output row is made once every source that
//! reaches it is listed: the input row, the kept values of its sources,
//! plus every source's shares that reach it.
//!
//! The schedule, in one paragraph ([`crate::pipeline::schedule`], the
//! Gaussian stage's too): a pass may make row `y` once every pass it reads
//! has made the rows within its reach of `y` (all of them at the image's
//! end). The treatment goes as far as that allows; each earlier
//! pass goes only as far as the passes that read it need, since what waits
//! is held across the whole width. A pass's rows leave once no pass reads
//! them; input rows once no pass reads them and their output rows are made.
//! When every input row is in, the treatment goes a strip's rows at a
//! time ([`PixelStage::set_last_rows`]), so that the last rows are handed
//! over as the others were rather than all held at once. The halo is
//! derived from the same declarations.
//!
//! A rule's decision for a pixel reads only the rows it declares, and each
//! output pixel adds its shares in source order, so the output is
//! bit-identical across `--tile`, `--strip-rows` and `--threads`. A pixel
//! neither spread nor reached keeps its input bits.

use std::ops::Range;

use rayon::iter::{IntoParallelIterator, ParallelIterator};

use super::counts::MethodCounts;
use super::schedule::{forward, hold_back, lag, read_from, Reads};
use super::stage::{Output, Stage, WindowUse};
use super::window::RowWindow;
use crate::geometry::Halo;
use gather::{Gathered, Placed};

pub mod excess;
mod gather;
pub mod gauss;
mod guided;

pub use excess::ExcessRule;
pub use gauss::GaussRule;
pub use guided::GuideReader;

/// Rows handed over at once when every input row is in, unless the
/// skeleton says its strips' ([`PixelStage::set_last_rows`]).
const LAST_ROWS: usize = 16;

/// What a pixel-resolution method computes: its passes, and the rule for
/// each. The stage calls them in the order the schedule gives.
pub trait Rule: Send + Sync {
    /// A spread pixel.
    type Source: Placed + Send + Sync;
    /// What a treatment task counts.
    type Tally: Send;
    /// Rows a treatment task takes.
    const TREAT_ROWS: usize;
    /// Columns a treatment task takes at most (where fewer than the image's,
    /// a task takes one row).
    const TREAT_COLUMNS: usize;

    /// The image's width and height, and the filtered channels.
    fn shape(&self) -> (usize, usize, usize);
    /// The channels a spread moves (a source's values and its
    /// [`Rule::add`]'s accumulator planes are theirs, in this order).
    fn spread(&self) -> &[usize];
    /// What each pass after the input reads, in order; the last is the
    /// treatment.
    fn passes(&self) -> Vec<Reads>;
    /// The widest spread's reach in rows.
    fn reach(&self) -> usize;
    /// Input rows `a..b` have arrived: what the rule makes of each on
    /// arrival (pass 0's own windows; none by default).
    fn arrive(&mut self, _input: &RowWindow<f32>, _a: usize, _b: usize) {}
    /// Make rows `a..b` of pass `pass` (neither the input nor the
    /// treatment).
    fn make(&mut self, pass: usize, input: &RowWindow<f32>, a: usize, b: usize);
    /// No pass reads rows of pass `pass` below `y` any more.
    fn evict(&mut self, pass: usize, y: usize);
    /// Treat the pixels of rows `rows` and columns `columns`: the spread
    /// pixels in row-major order, their values (per source what its pixel
    /// keeps, then what one unit of its kernel's weight carries, a value a
    /// spread channel each) and what it counted.
    fn treat(
        &self,
        input: &RowWindow<f32>,
        rows: Range<usize>,
        columns: Range<usize>,
    ) -> (Vec<Self::Source>, Vec<f64>, Self::Tally);
    /// Add what a treatment task counted of `sources`.
    fn tally(&mut self, tally: Self::Tally, sources: &[Self::Source]);
    /// Add to `acc` (row `ty`, `w` columns per spread channel) the shares
    /// of `source`, one unit of its weight carrying `shares` (one a spread
    /// channel).
    fn add(
        &self,
        input: &RowWindow<f32>,
        source: &Self::Source,
        shares: &[f64],
        ty: usize,
        acc: &mut [f64],
    );
    /// What the rule counted.
    fn counts(&self) -> MethodCounts;
    /// The windows its passes hold.
    fn windows(&self) -> Vec<WindowUse>;
}

/// Lists of sources and their values (`stride` a source), each in
/// row-major order over its own columns, the columns in order: one list in
/// row-major order.
fn row_major<S: Placed>(lists: Vec<(Vec<S>, Vec<f64>)>, stride: usize) -> (Vec<S>, Vec<f64>) {
    if lists.len() <= 1 {
        return lists.into_iter().next().unwrap_or_default();
    }
    let n = lists.iter().map(|l| l.0.len()).sum();
    let (mut sources, mut values) = (Vec::with_capacity(n), Vec::with_capacity(n * stride));
    let mut lists: Vec<_> = (lists.into_iter())
        .map(|(s, v)| (s.into_iter().peekable(), v.into_iter()))
        .collect();
    while let Some(y) = (lists.iter_mut())
        .filter_map(|(s, _)| s.peek().map(|p| p.at().1))
        .min()
    {
        for (s, v) in &mut lists {
            while let Some(source) = s.next_if(|p| p.at().1 == y) {
                sources.push(source);
                values.extend(v.by_ref().take(stride));
            }
        }
    }
    (sources, values)
}

/// A pixel-resolution method's stage: its rule and the schedule.
pub struct PixelStage<R: Rule> {
    rule: R,
    w: usize,
    h: usize,
    /// What each pass reads (`passes[i - 1]` for pass `i`).
    passes: Vec<Reads>,
    /// Per pass, the rows made (pass 0: the input rows in).
    done: Vec<usize>,
    /// The spreads, and the final output rows not yet written.
    gathered: Gathered<R::Source>,
    /// Columns a treatment task takes at most (0: the rule's).
    task_columns: usize,
    /// Rows treated at once when every input row is in.
    last_rows: usize,
}

impl<R: Rule> PixelStage<R> {
    /// The stage of `rule`.
    pub fn new(rule: R) -> Self {
        let (w, h, nch) = rule.shape();
        let passes = rule.passes();
        let reach = rule.reach();
        PixelStage {
            done: vec![0; passes.len() + 1],
            passes,
            w,
            h,
            gathered: Gathered::new(nch, rule.spread().to_vec(), w, reach),
            rule,
            task_columns: 0,
            last_rows: LAST_ROWS,
        }
    }

    /// Treat `n` rows at a time (at least one) once every input row is in:
    /// the strips' rows, so that the last output rows are held as the
    /// others were; the output does not change.
    pub fn set_last_rows(&mut self, n: usize) {
        self.last_rows = n.max(1);
    }

    /// Cut the treatment's tasks at `n` columns (0: the rule's
    /// [`Rule::TREAT_COLUMNS`]); the output does not change.
    pub fn set_task_columns(&mut self, n: usize) {
        self.task_columns = n;
    }

    /// The treatment's pass.
    fn last(&self) -> usize {
        self.passes.len()
    }

    /// Make every pass's rows up to its target (`treat` the treatment's
    /// most), then let go of the rows no pass reads any more.
    fn step(&mut self, input: &RowWindow<f32>, rows_in: usize, treat: usize) {
        self.done[0] = rows_in;
        let mut targets = forward(&self.passes, self.h, &[rows_in], treat);
        hold_back(&self.passes, self.h, &mut targets);
        let n = self.last();
        for (i, &target) in targets.iter().enumerate().take(n).skip(1) {
            if target > self.done[i] {
                self.rule.make(i, input, self.done[i], target);
                self.done[i] = target;
            }
        }
        if targets[n] > self.done[n] {
            self.treat(input, self.done[n], targets[n]);
            self.done[n] = targets[n];
        }
        for j in 1..n {
            self.rule.evict(j, read_from(&self.passes, &self.done, j));
        }
        self.rule.evict(0, self.input_needed());
    }

    /// Treat rows `a..b` and list the sources in row-major order: a task
    /// per [`Rule::TREAT_ROWS`] rows and [`Rule::TREAT_COLUMNS`] columns (a
    /// wide image's strip is a few rows: cut only by rows, its treatment
    /// would be one task). A band's tasks are merged row by row.
    fn treat(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        let (w, rows) = (self.w.max(1), R::TREAT_ROWS.max(1));
        let cols = match self.task_columns {
            0 => R::TREAT_COLUMNS,
            n => n,
        }
        .clamp(1, w);
        let tasks: Vec<(usize, usize)> = (a..b)
            .step_by(rows)
            .flat_map(|y| (0..w).step_by(cols).map(move |x| (y, x)))
            .collect();
        let rule = &self.rule;
        let region = crate::trace::region("pixel treat");
        let results: Vec<_> = tasks
            .into_par_iter()
            .map(|(y, x)| {
                let _task = region.task("pixel treat");
                rule.treat(input, y..(y + rows).min(b), x..(x + cols).min(w))
            })
            .collect();
        let mut results = results.into_iter();
        let stride = self.gathered.sources.stride();
        loop {
            let band: Vec<_> = results.by_ref().take(w.div_ceil(cols)).collect();
            if band.is_empty() {
                break;
            }
            let mut lists = Vec::with_capacity(band.len());
            for (sources, values, tally) in band {
                self.rule.tally(tally, &sources);
                lists.push((sources, values));
            }
            let (sources, values) = row_major(lists, stride);
            self.gathered.sources.extend(sources, values);
        }
    }

    /// The end of the final output rows: those no untreated row reaches.
    fn end(&self) -> usize {
        match self.done[self.last()] {
            y if y == self.h => y,
            y => y.saturating_sub(self.rule.reach()),
        }
    }
}

impl<R: Rule> Stage for PixelStage<R> {
    /// `search_reach`: the input rows the treatment reads past its row,
    /// through its passes; `spread_reach`: the widest spread's.
    fn halo(&self) -> Halo {
        Halo {
            xbar_reach: 0,
            base_reach: 0,
            search_reach: lag(&self.passes),
            spread_reach: self.rule.reach(),
        }
    }

    fn arrive(&mut self, input: &mut RowWindow<f32>, a: usize, b: usize) {
        self.rule.arrive(input, a, b);
    }

    fn advance(&mut self, input: &RowWindow<f32>, rows_in: usize, all_in: bool) -> usize {
        let end = if rows_in < self.h || !all_in {
            self.step(input, rows_in, rows_in);
            self.end()
        } else {
            let released = self.gathered.released();
            loop {
                let treat = self.done[self.last()] + self.last_rows;
                self.step(input, rows_in, treat);
                if self.end() > released || self.done[self.last()] == self.h {
                    break;
                }
            }
            self.end().min(released + self.last_rows)
        };
        let rule = &self.rule;
        let add = |s: &R::Source, shares: &[f64], ty: usize, acc: &mut [f64]| {
            rule.add(input, s, shares, ty, acc)
        };
        self.gathered.make_to(input, (end, self.w), add);
        end
    }

    fn input_needed(&self) -> usize {
        // An output row is made from its input row.
        read_from(&self.passes, &self.done, 0).min(self.gathered.rows.end())
    }

    fn output(&self, rows: (usize, usize)) -> Output<'_> {
        self.gathered.output(rows)
    }

    fn release(&mut self, y: usize) {
        self.gathered.release(y);
    }

    fn counts(&self) -> MethodCounts {
        self.rule.counts()
    }

    fn windows(&self) -> Vec<WindowUse> {
        let mut v = self.rule.windows();
        v.extend(self.gathered.windows());
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_cut_by_columns_merge_row_by_row() {
        #[derive(Debug, PartialEq)]
        struct Dot(usize, usize);
        impl Placed for Dot {
            fn at(&self) -> (usize, usize) {
                (self.0, self.1)
            }
        }
        let dots = |v: &[(usize, usize)]| -> (Vec<Dot>, Vec<f64>) {
            let values = v.iter().flat_map(|&(x, y)| [x as f64, y as f64]).collect();
            (v.iter().map(|&(x, y)| Dot(x, y)).collect(), values)
        };
        // Rows 3..6, columns 0..4 then 4..8.
        let left = dots(&[(1, 3), (0, 5), (2, 5)]);
        let right = dots(&[(4, 3), (7, 4), (5, 5)]);
        let (sources, values) = row_major(vec![left, right], 2);
        let want = [(1, 3), (4, 3), (7, 4), (0, 5), (2, 5), (5, 5)];
        assert_eq!(sources, want.map(|(x, y)| Dot(x, y)));
        let expect: Vec<f64> = want
            .iter()
            .flat_map(|&(x, y)| [x as f64, y as f64])
            .collect();
        assert_eq!(values, expect);
    }
}
