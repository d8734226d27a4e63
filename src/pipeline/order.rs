//! The order-statistic foils: `median` and `alpha-trim` (Lee & Redner's
//! alpha-trimmed mean). Each output pixel gathers the S x S samples of its
//! pixel (at S = 1: the 3 x 3 pixels around it, reflected at the borders),
//! per channel, sorts them and averages what is left after trimming from
//! each end. They discard energy by design; the ledger reports how much.
//! Carried ids and masks (`nearest`) take the centre sample instead: a
//! median of ids is an id only by luck.

use rayon::iter::{IndexedParallelIterator, IntoParallelIterator, ParallelIterator};

use super::counts::MethodCounts;
use super::schedule::{forward, lag, read_from, Reads};
use super::stage::{Output, Stage, WindowUse};
use super::window::RowWindow;
use super::ChannelMode;
use crate::filter::{Method, ValidParams};
use crate::geometry::{mirror, Grid, Halo};

pub use crate::filter::foils::Trim;

/// Streaming state of an order-statistic foil.
pub struct OrderStage {
    grid: Grid,
    w: usize,
    h: usize,
    nch: usize,
    modes: Vec<ChannelMode>,
    trim: Trim,
    /// Its one pass: an output row reads its input rows, and one row
    /// either side at S = 1 (the 3 x 3 window), over pixel rows.
    passes: Vec<Reads>,
    out: RowWindow<f64>,
    out_done: usize,
}

impl OrderStage {
    /// A stage for `grid` over channels of `modes` (the skeleton has checked
    /// them).
    pub fn new(grid: Grid, modes: Vec<ChannelMode>, params: &ValidParams) -> Self {
        let nch = modes.len();
        let trim = match params.method {
            Method::Median => Trim::Median,
            _ => Trim::Alpha(params.alpha),
        };
        OrderStage {
            grid,
            w: grid.out_w(),
            h: grid.out_h(),
            nch,
            modes,
            trim,
            passes: vec![vec![(0, usize::from(grid.s == 1))]],
            out: RowWindow::new(nch * grid.out_w()),
            out_done: 0,
        }
    }
}

impl Stage for OrderStage {
    /// One row of input either side at S = 1 (the 3 x 3 window), none above.
    fn halo(&self) -> Halo {
        Halo {
            base_reach: lag(&self.passes),
            ..Default::default()
        }
    }

    fn arrive(&mut self, _input: &mut RowWindow<f32>, _a: usize, _b: usize) {}

    fn advance(&mut self, input: &RowWindow<f32>, rows_in: usize, _all_in: bool) -> usize {
        let (in_w, s) = (self.grid.in_w, self.grid.s);
        let ready = forward(&self.passes, self.h, &[rows_in / s], usize::MAX)[1];
        if ready <= self.out_done {
            return self.out_done;
        }
        let (a, b) = (self.out_done, ready);
        for _ in a..b {
            self.out.push_stale(0.0);
        }
        let (w, h, nch, trim) = (self.w, self.h, self.nch, self.trim);
        let modes = &self.modes;
        let rows = self.out.range_mut(a, b);
        let region = crate::trace::region("order");
        rows.into_par_iter()
            .enumerate()
            .for_each_init(Vec::new, |vals, (k, row)| {
                let _task = region.task("order");
                let y = a + k;
                for c in 0..nch {
                    if modes[c] == ChannelMode::Nearest {
                        // The centre sample, as it is.
                        let r = &input.get(y * s + (s - 1) / 2)[c * in_w..(c + 1) * in_w];
                        for x in 0..w {
                            row[c * w + x] = r[x * s + (s - 1) / 2] as f64;
                        }
                        continue;
                    }
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
        self.out_done = b;
        b
    }

    fn input_needed(&self) -> usize {
        read_from(&self.passes, &[0, self.out_done], 0) * self.grid.s
    }

    fn output(&self, rows: (usize, usize)) -> Output<'_> {
        Output::of(&self.out, None, rows)
    }

    fn release(&mut self, y: usize) {
        self.out.evict_below(y);
    }

    fn counts(&self) -> MethodCounts {
        MethodCounts::Plain
    }

    fn windows(&self) -> Vec<WindowUse> {
        vec![WindowUse {
            name: "output",
            rows: self.out.high_water(),
            row_bytes: self.nch * self.w * 8,
        }]
    }
}
