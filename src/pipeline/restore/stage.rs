//! Restore's second pass, a stage behind the skeleton: every block's
//! target known (the first pass), the rows are carried in the denoiser's
//! shape one row of blocks at a time.
//!
//! A strip's work is three passes, each a parallel loop over rows, declared
//! with what they read and taken as far as that allows by the schedule the
//! filters' stages share ([`crate::pipeline::schedule`]):
//!
//! 1. the carrier's moments of the rows that came (the carrier reads the
//!    block means and targets, known from the first pass);
//! 2. the part of the energy kept in place (`l`) for the rows whose rows
//!    around are in (as the first pass computed it);
//! 3. each row of blocks whose field can be fixed (the rows of blocks
//!    [`LOOKAHEAD`] below it with their moments) and whose `l` is known:
//!    `c = s + t (f - 1)` for its rows, each block's exact factor `g`, and
//!    the rows `c g + l`.
//!
//! Each row's values depend only on rows that are in, and block sums are
//! added row by row in order, never by how rows came: the output is the
//! same for any strip height and thread count.

use rayon::iter::{
    IndexedParallelIterator, IntoParallelIterator, IntoParallelRefMutIterator, ParallelIterator,
};

use super::kept::{Kept, KeptLayout};
use crate::filter::restore::{shape, FieldRows, LOOKAHEAD};
use crate::geometry::Halo;
use crate::pipeline::counts::{MethodCounts, RestoreCounts};
use crate::pipeline::schedule::{forward, read_from, Reads};
use crate::pipeline::stage::{Output, Stage, WindowUse};
use crate::pipeline::window::RowWindow;

/// The passes over pixel rows ([`crate::pipeline::schedule`]; pass 0: the
/// input rows in): the carrier's moments of a row, its input row;
pub(super) const MOMENTS: usize = 1;
/// the part kept in place, the input rows around ([`Kept::reads`]);
pub(super) const KEPT: usize = 2;
/// the final rows, a row of blocks at a time: a block's last row once the
/// field of its row of blocks and the next can be fixed (the moments of the
/// [`LOOKAHEAD`] rows of blocks after the next: `(LOOKAHEAD + 1) b` rows
/// past it) and its `l` is known.
pub(super) const FINAL: usize = 3;

/// What each pass reads, for the kept part's `kept` and blocks of `b`.
pub(super) fn passes(kept: Reads, b: usize) -> Vec<Reads> {
    vec![
        vec![(0, 0)],
        kept,
        vec![(0, 0), (MOMENTS, (LOOKAHEAD + 1) * b), (KEPT, 0)],
    ]
}

/// One row of blocks at a time: `c g + l`, `c = s + t (f - 1)`.
pub struct RestoreStage {
    nch: usize,
    /// Channels the denoiser did not write: kept as the energy has them.
    copied: Vec<bool>,
    /// The first of the denoiser's channels in the input rows.
    d_at: usize,
    w: usize,
    h: usize,
    kept: Kept,
    /// The field of each channel (a copied channel's is never read).
    fields: Vec<FieldRows>,
    /// What each pass reads.
    passes: Vec<Reads>,
    /// Pixel rows whose carrier's moments are in the fields.
    momented: usize,
    /// Final rows.
    out: RowWindow<f64>,
    /// Blocks whose denoiser shape carried nothing: their energy stayed.
    unshaped_blocks: u64,
    /// What the first pass counted (the denoiser's values).
    surveyed: RestoreCounts,
}

impl RestoreStage {
    /// The stage for a `w x h` image whose rows the kept part reads as
    /// `layout` says, with one field per energy channel.
    pub(super) fn new(
        layout: KeptLayout,
        (w, h): (usize, usize),
        fields: Vec<FieldRows>,
        surveyed: RestoreCounts,
    ) -> Self {
        let nch = layout.emission.len();
        let copied = layout.copied.clone();
        let kept = Kept::new(layout, (w, h));
        let passes = passes(kept.reads(), fields[0].b);
        RestoreStage {
            passes,
            nch,
            copied,
            d_at: kept.d_at,
            w,
            h,
            kept,
            fields,
            momented: 0,
            out: RowWindow::new(nch * w),
            unshaped_blocks: 0,
            surveyed,
        }
    }

    fn b(&self) -> usize {
        self.fields[0].b
    }

    /// Rows `a..b` into the fields' carrier moments.
    fn add_moments(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        let (nch, w, d_at) = (self.nch, self.w, self.d_at);
        let (fields, copied) = (&self.fields, &self.copied);
        let nbx = fields[0].nbx;
        let sums: Vec<Vec<(f64, [f64; 9])>> = (a..b)
            .into_par_iter()
            .map_init(
                || (vec![0.0f64; w], vec![0.0f64; w]),
                |(s, t), y| {
                    let d_row = &input.get(y)[d_at * w..];
                    let mut out = vec![(0.0, [0.0; 9]); nch * nbx];
                    for ch in (0..nch).filter(|&ch| !copied[ch]) {
                        for (s, &d) in s.iter_mut().zip(&d_row[ch * w..(ch + 1) * w]) {
                            *s = shape(d);
                        }
                        fields[ch].carrier(y, s, t);
                        fields[ch].moment_sums(y, t, &mut out[ch * nbx..(ch + 1) * nbx]);
                    }
                    out
                },
            )
            .collect();
        for (y, row) in (a..b).zip(sums) {
            for (ch, f) in self.fields.iter_mut().enumerate() {
                if !self.copied[ch] {
                    f.add_moments(y, &row[ch * nbx..(ch + 1) * nbx]);
                }
            }
        }
        self.momented = b;
    }

    /// Rows `a..b`, a whole row of blocks, their fields fixed.
    fn finish_blocks(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        let (nch, w, d_at) = (self.nch, self.w, self.d_at);
        for _ in a..b {
            self.out.push_stale(0.0);
        }
        let (fields, bs, copied) = (&self.fields, self.b(), &self.copied);
        let nbx = fields[0].nbx;
        // c = s + t (f - 1) per pixel, and per row its block sums.
        let mut rows = self.out.range_mut(a, b);
        let sums: Vec<Vec<f64>> = rows
            .par_iter_mut()
            .enumerate()
            .map_init(
                || (vec![0.0f64; w], vec![0.0f64; w]),
                |(f, t), (i, out)| {
                    let y = a + i;
                    let d_row = &input.get(y)[d_at * w..];
                    let mut sums = vec![0.0; nch * nbx];
                    // A copied channel is the energy's, written below.
                    for ch in (0..nch).filter(|&ch| !copied[ch]) {
                        fields[ch].row(y, f);
                        let o = &mut out[ch * w..(ch + 1) * w];
                        for (o, &d) in o.iter_mut().zip(&d_row[ch * w..(ch + 1) * w]) {
                            *o = shape(d);
                        }
                        // The carrier again rather than held from its
                        // moments: holding it would keep f64 rows of the
                        // rows of blocks ahead.
                        fields[ch].carrier(y, o, t);
                        let blocks = o.chunks_mut(bs).zip(t.chunks(bs)).zip(f.chunks(bs));
                        for (sum, ((o, t), f)) in sums[ch * nbx..].iter_mut().zip(blocks) {
                            for ((o, &t), &f) in o.iter_mut().zip(t).zip(f) {
                                // Never below zero: a pixel brighter than the
                                // block needs gives what it has.
                                *o = (*o + t * (f - 1.0)).max(0.0);
                                *sum += *o;
                            }
                        }
                    }
                    sums
                },
            )
            .collect();
        // Each block's exact factor, from the sums in row order.
        let jb = a / bs;
        let mut reached = vec![0.0f64; nch * nbx];
        for row in &sums {
            for (r, v) in reached.iter_mut().zip(row) {
                *r += v;
            }
        }
        let mut g = vec![0.0f64; nch * nbx];
        for ch in 0..nch {
            if self.copied[ch] {
                // Not the denoiser's: the energy's values stay (below).
                g[ch * nbx..(ch + 1) * nbx].fill(f64::NAN);
                continue;
            }
            for i in 0..nbx {
                let (t, r) = (fields[ch].target(jb, i), reached[ch * nbx + i]);
                g[ch * nbx + i] = if r > 0.0 {
                    t / r
                } else {
                    if t != 0.0 {
                        self.unshaped_blocks += 1;
                    }
                    // Nothing to shape the rest with: it stays (below; the
                    // targets gave such a block the render's energy).
                    f64::NAN
                };
            }
        }
        let kept = &self.kept;
        let mut rows = self.out.range_mut(a, b);
        rows.par_iter_mut().enumerate().for_each(|(i, out)| {
            let y = a + i;
            let e_row = input.get(y);
            let l = kept.row(y);
            for ch in 0..nch {
                let o = &mut out[ch * w..(ch + 1) * w];
                for (ib, &gb) in g[ch * nbx..(ch + 1) * nbx].iter().enumerate() {
                    for x in ib * bs..((ib + 1) * bs).min(w) {
                        let lv = l.map_or(0.0, |l| l[ch * w + x]);
                        o[x] = if gb.is_nan() {
                            f64::from(e_row[ch * w + x])
                        } else {
                            o[x] * gb + lv
                        };
                    }
                }
            }
        });
    }
}

impl Stage for RestoreStage {
    fn halo(&self) -> Halo {
        // The row of blocks being finished, the next one (its lower half's
        // tents) and the rows of blocks the field looks ahead of that, and
        // the kept part's rows around.
        Halo {
            xbar_reach: 0,
            base_reach: self.kept.r(),
            search_reach: 0,
            spread_reach: self.kept.r() + (LOOKAHEAD + 2) * self.b(),
        }
    }

    fn arrive(&mut self, _input: &mut RowWindow<f32>, _a: usize, _b: usize) {}

    fn advance(&mut self, input: &RowWindow<f32>, rows_in: usize, all_in: bool) -> usize {
        let t = forward(&self.passes, self.h, &[rows_in], usize::MAX);
        if t[MOMENTS] > self.momented {
            self.add_moments(input, self.momented, t[MOMENTS]);
        }
        self.kept.advance(input, t[KEPT]);
        let (bs, h) = (self.b(), self.h);
        let nby = self.fields[0].nby;
        // A row of blocks is finished once its last row may be (its lower
        // half reads its field and the next row's). Once the input is all
        // in, one row of blocks a call: the skeleton calls again, so the
        // rows of blocks still held are never all final rows at once.
        let from = self.out.end();
        while self.out.end() < h && !(all_in && self.out.end() > from) {
            let j = self.out.end() / bs;
            let next = (j + 1).min(nby - 1);
            let b = ((j + 1) * bs).min(h);
            if b > t[FINAL] {
                break;
            }
            for (ch, f) in self.fields.iter_mut().enumerate() {
                if !self.copied[ch] {
                    f.fix(j);
                    f.fix(next);
                }
            }
            self.finish_blocks(input, j * bs, b);
            self.kept.release(b);
            for f in &mut self.fields {
                f.release(j);
            }
        }
        self.out.end()
    }

    fn input_needed(&self) -> usize {
        let done = [0, self.momented, self.kept.end(), self.out.end()];
        read_from(&self.passes, &done, 0)
    }

    fn output(&self, (a, b): (usize, usize)) -> Output<'_> {
        Output::of(&self.out, None, (a, b))
    }

    fn release(&mut self, y: usize) {
        self.out.evict_below(y);
    }

    fn counts(&self) -> MethodCounts {
        let mut c = self.kept.counts;
        c.unshaped_blocks = self.unshaped_blocks;
        c.denoised_nonfinite = self.surveyed.denoised_nonfinite;
        c.denoised_negative = self.surveyed.denoised_negative;
        MethodCounts::Restore(c)
    }

    fn windows(&self) -> Vec<WindowUse> {
        let row = self.nch * self.w * 8;
        vec![
            WindowUse {
                name: "energy kept in place",
                rows: self.kept.high_water,
                row_bytes: row,
            },
            WindowUse {
                name: "output",
                rows: self.out.high_water(),
                row_bytes: row,
            },
        ]
    }
}
