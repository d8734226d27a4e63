//! `epfilt restore`'s stage: the energy image's pixels spread in the
//! denoiser's shape ([`crate::filter::restore`]), streamed.
//!
//! The strips hold the energy image's channels, then the denoiser's (the
//! books' ledger counts the first ones: the total it checks is the energy
//! image's). A strip's work is three passes, each a parallel loop over rows:
//!
//! 1. `arrive`: each new row's shape `s = max(d, 0)`, blurred along the row;
//! 2. the rows whose column of those is in: `q = G s`, the split of `e` into
//!    the gain `t` and the leftover `l`, both blurred along the row;
//! 3. the rows whose column of those is in: `r = s G t + G l`.
//!
//! Each row's values depend only on rows that are in, never on how they
//! came, so the output is the same for any strip height and thread count.

use rayon::prelude::*;

use super::counts::{MethodCounts, RestoreCounts};
use super::memory::{MemorySink, MemorySource};
use super::pair::Pair;
use super::stage::{Output, Stage, WindowUse};
use super::stream::{Streamer, MAX_CHANNELS};
use super::window::RowWindow;
use super::{
    run_streamer, PipelineConfig, Precision, Progress, RunStats, Sink, Source, StripLayout,
};
use crate::error::{Error, Result};
use crate::filter::restore::{blur_column, blur_row, check_scale, reflect, shape, split, taps};
use crate::geometry::{Grid, Halo};

/// The kernel, the image's height (its columns reflect at its ends) and the
/// 2-D kernel's centre weight.
struct Kernel {
    taps: Vec<f64>,
    h: usize,
    centre: f64,
}

impl Kernel {
    fn r(&self) -> usize {
        self.taps.len() / 2
    }

    /// The rows of row `y`'s column, reflected at the image's ends, with
    /// their taps.
    fn column(&self, y: usize) -> impl Iterator<Item = usize> + '_ {
        let r = self.r() as isize;
        (-r..=r).map(move |i| reflect(y as isize + i, self.h))
    }
}

/// The stage of one restore: sizes, the kernel and three windows.
pub struct RestoreStage {
    nch: usize,
    w: usize,
    h: usize,
    k: Kernel,
    /// Per input row: the shape blurred along the row, `[channel][x]`.
    shape_rows: RowWindow<f64>,
    /// Per row whose split is done: `G_x t` then `G_x (l / n)`, and whether
    /// that row has any leftover (most have none: its blur is skipped).
    split_rows: RowWindow<f64>,
    leftover: std::collections::VecDeque<bool>,
    /// Final rows.
    out: RowWindow<f64>,
    counts: RestoreCounts,
}

impl RestoreStage {
    /// The stage for `nch` channels of a `w x h` image at `scale` pixels.
    pub fn new(nch: usize, w: usize, h: usize, scale: f64) -> Self {
        let taps = taps(scale);
        RestoreStage {
            nch,
            w,
            h,
            k: Kernel {
                centre: taps[taps.len() / 2].powi(2),
                taps,
                h,
            },
            shape_rows: RowWindow::new(nch * w),
            split_rows: RowWindow::new(2 * nch * w),
            leftover: Default::default(),
            out: RowWindow::new(nch * w),
            counts: RestoreCounts::default(),
        }
    }

    /// Pass 2 for rows `a..b`.
    fn split(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        let (nch, w) = (self.nch, self.w);
        for _ in a..b {
            self.split_rows.push_stale(0.0);
        }
        let (k, shapes) = (&self.k, &self.shape_rows);
        let mut rows = self.split_rows.range_mut(a, b);
        let per_row: Vec<(bool, RestoreCounts)> = rows
            .par_iter_mut()
            .enumerate()
            .map_init(
                || (vec![0.0f64; w], vec![0.0f64; w], vec![0.0f64; w]),
                |(q, t, l), (i, out)| {
                    let y = a + i;
                    let e_row = input.get(y);
                    let mut c = RestoreCounts::default();
                    let mut any = false;
                    for ch in 0..nch {
                        let col = k.column(y).map(|v| &shapes.get(v)[ch * w..(ch + 1) * w]);
                        blur_column(col, &k.taps, q);
                        let e = &e_row[ch * w..(ch + 1) * w];
                        for x in 0..w {
                            let ev = f64::from(e[x]);
                            (t[x], l[x]) = split(ev, q[x], k.centre);
                            if l[x] != 0.0 {
                                any = true;
                                c.count(ev, q[x]);
                                c.plain_energy += l[x].abs();
                            }
                        }
                        let (gt, gl) = out.split_at_mut(nch * w);
                        blur_row(t, &k.taps, &mut gt[ch * w..(ch + 1) * w]);
                        gl[ch * w..(ch + 1) * w].copy_from_slice(l);
                    }
                    (any, c)
                },
            )
            .collect();
        // Summed in row order: the counts' energy is the same for any strips.
        for (any, c) in per_row {
            self.leftover.push_back(any);
            self.counts += c;
        }
    }

    /// Pass 3 for rows `a..b`.
    fn finish(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        let (nch, w) = (self.nch, self.w);
        for _ in a..b {
            self.out.push_stale(0.0);
        }
        let (k, splits, leftover) = (&self.k, &self.split_rows, &self.leftover);
        let mut rows = self.out.range_mut(a, b);
        rows.par_iter_mut().enumerate().for_each_init(
            || vec![0.0f64; w],
            |gt, (i, out)| {
                let y = a + i;
                let d_row = &input.get(y)[nch * w..];
                let base = splits.first();
                let own = &splits.get(y)[nch * w..];
                let any = leftover[y - base];
                for ch in 0..nch {
                    let col = k.column(y).map(|v| &splits.get(v)[ch * w..(ch + 1) * w]);
                    blur_column(col, &k.taps, gt);
                    let d = &d_row[ch * w..(ch + 1) * w];
                    let o = &mut out[ch * w..(ch + 1) * w];
                    for x in 0..w {
                        o[x] = shape(d[x]) * gt[x];
                    }
                    if any {
                        for (o, &l) in o.iter_mut().zip(&own[ch * w..(ch + 1) * w]) {
                            *o += l;
                        }
                    }
                }
            },
        );
    }
}

impl Stage for RestoreStage {
    fn halo(&self) -> Halo {
        // Two blurs down the columns: the shape's, then the gain's.
        let r = self.k.r();
        Halo {
            xbar_reach: 0,
            base_reach: r,
            search_reach: 0,
            spread_reach: 2 * r,
        }
    }

    fn arrive(&mut self, input: &mut RowWindow<f32>, a: usize, b: usize) {
        let (nch, w) = (self.nch, self.w);
        for _ in a..b {
            self.shape_rows.push_stale(0.0);
        }
        let mut rows = self.shape_rows.range_mut(a, b);
        let (input, taps) = (&*input, &self.k.taps);
        rows.par_iter_mut().enumerate().for_each_init(
            || vec![0.0f64; w],
            |s, (k, out)| {
                let d_row = &input.get(a + k)[nch * w..];
                for ch in 0..nch {
                    for (v, &d) in s.iter_mut().zip(&d_row[ch * w..(ch + 1) * w]) {
                        *v = shape(d);
                    }
                    blur_row(s, taps, &mut out[ch * w..(ch + 1) * w]);
                }
            },
        );
    }

    fn advance(&mut self, input: &RowWindow<f32>, rows_in: usize, all_in: bool) -> usize {
        let r = self.k.r();
        // A row is split once its column of shapes is in, final once its
        // column of splits is.
        let split_done = self.split_rows.end();
        let split_to = if all_in {
            self.h
        } else {
            rows_in.saturating_sub(r)
        };
        if split_to > split_done {
            self.split(input, split_done, split_to);
        }
        let (out_done, split_end) = (self.out.end(), self.split_rows.end());
        let out_to = if split_end == self.h {
            self.h
        } else {
            split_end.saturating_sub(r)
        };
        if out_to > out_done {
            self.finish(input, out_done, out_to);
        }
        // Rows no longer read by either column.
        let keep_shape = self.split_rows.end().saturating_sub(r);
        self.shape_rows.evict_below(keep_shape);
        let keep_split = self.out.end().saturating_sub(r);
        let before = self.split_rows.first();
        self.split_rows.evict_below(keep_split);
        for _ in before..self.split_rows.first() {
            self.leftover.pop_front();
        }
        self.out.end()
    }

    fn input_needed(&self) -> usize {
        // The energy of rows not yet split; the shape of rows not yet final.
        self.split_rows.end().min(self.out.end())
    }

    fn output(&self, (a, b): (usize, usize)) -> Output<'_> {
        Output::of(&self.out, None, (a, b))
    }

    fn release(&mut self, y: usize) {
        self.out.evict_below(y);
    }

    fn counts(&self) -> MethodCounts {
        MethodCounts::Restore(self.counts)
    }

    fn windows(&self) -> Vec<WindowUse> {
        let row = self.nch * self.w * 8;
        vec![
            WindowUse {
                name: "shape blurred along rows",
                rows: self.shape_rows.high_water(),
                row_bytes: row,
            },
            WindowUse {
                name: "gain and leftover blurred along rows",
                rows: self.split_rows.high_water(),
                row_bytes: 2 * row,
            },
            WindowUse {
                name: "output",
                rows: self.out.high_water(),
                row_bytes: row,
            },
        ]
    }
}

/// Restore `denoised` from `energy`'s energy at `scale` pixels into `sink`:
/// both sources `w x h` with `channels` (`luminance`: their weights, for
/// the layout), read side by side; the books' ledger counts `energy`.
#[allow(clippy::too_many_arguments)]
pub fn restore_stream<A: Source, B: Source, K: Sink>(
    energy: A,
    denoised: B,
    sink: K,
    (w, h): (usize, usize),
    channels: Vec<String>,
    luminance: Vec<f64>,
    scale: f64,
    cfg: &PipelineConfig,
    progress: Progress<'_>,
) -> Result<RunStats> {
    let nch = channels.len();
    if w == 0 || h == 0 || nch == 0 || nch > MAX_CHANNELS {
        return Err(Error::Config(format!(
            "restore needs a non-empty image of 1..={MAX_CHANNELS} channels, not {w}x{h} of {nch}"
        )));
    }
    let scale = check_scale(scale).map_err(Error::Config)?;
    let grid = Grid {
        in_w: w,
        in_h: h,
        s: 1,
    };
    let mut layout = StripLayout::new(grid, channels.clone(), luminance);
    layout.aux = channels.iter().map(|c| format!("denoised.{c}")).collect();
    let stage = RestoreStage::new(nch, w, h, scale);
    let streamer = Streamer::of_stage(
        &layout,
        Box::new(stage),
        cfg.nonfinite,
        sink.precisions(nch),
    );
    let pair = Pair::new(energy, denoised, w, nch, nch);
    run_streamer(pair, sink, &layout, streamer, cfg, progress)
}

#[allow(clippy::too_many_arguments)]
/// [`restore_stream`] of two whole images in memory (planar
/// `[row][channel][x]`), rounded to `precision`: the output and the run.
pub fn restore_planar(
    energy: Vec<f32>,
    denoised: Vec<f32>,
    (w, h): (usize, usize),
    channels: Vec<String>,
    luminance: Vec<f64>,
    scale: f64,
    cfg: &PipelineConfig,
    precision: Precision,
) -> Result<(Vec<f32>, RunStats)> {
    let n = w.checked_mul(h).and_then(|p| p.checked_mul(channels.len()));
    if n != Some(energy.len()) || n != Some(denoised.len()) {
        return Err(Error::Config(format!(
            "{} energy and {} denoised values for a {w}x{h} image of {} channels",
            energy.len(),
            denoised.len(),
            channels.len()
        )));
    }
    let row = channels.len() * w;
    let mut sink = MemorySink::with_precision(precision);
    let stats = restore_stream(
        MemorySource::new(energy, row),
        MemorySource::new(denoised, row),
        &mut sink,
        (w, h),
        channels,
        luminance,
        scale,
        cfg,
        &|_, _| {},
    )?;
    Ok((sink.data, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::RunStats;

    /// What a restore's ledger balances to (see the job's limit).
    const LEDGER_TOL: f64 = 1e-12;

    /// A noisy image with fireflies, and a smooth "denoised" one with holes.
    fn images(w: usize, h: usize, nch: usize) -> (Vec<f32>, Vec<f32>) {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 33) as f64 / (1u64 << 31) as f64) as f32
        };
        let (mut e, mut d) = (Vec::new(), Vec::new());
        for y in 0..h {
            for c in 0..nch {
                for x in 0..w {
                    let base = 1.0 + 0.5 * ((x + 2 * y + c) as f32 * 0.1).sin();
                    let r = rnd();
                    e.push(if r > 0.98 {
                        base * 200.0
                    } else {
                        base * (0.5 + r)
                    });
                    d.push(if (x / 7 + y / 5) % 9 == 0 { 0.0 } else { base });
                }
            }
        }
        (e, d)
    }

    fn run(
        w: usize,
        h: usize,
        nch: usize,
        scale: f64,
        cfg: &PipelineConfig,
    ) -> (Vec<f32>, RunStats) {
        let (e, d) = images(w, h, nch);
        let names = (0..nch).map(|c| format!("c{c}")).collect();
        restore_planar(
            e,
            d,
            (w, h),
            names,
            vec![0.0; nch],
            scale,
            cfg,
            Precision::F32,
        )
        .unwrap()
    }

    #[test]
    fn energy_is_exact_and_bytes_do_not_depend_on_strips_or_threads() {
        for (w, h, scale) in [(37, 29, 2.0), (5, 4, 3.0), (64, 3, 0.7)] {
            let base = PipelineConfig {
                threads: 1,
                strip_rows: 1,
                ..Default::default()
            };
            let (out, stats) = run(w, h, 2, scale, &base);
            for l in &stats.ledger {
                assert!(l.rel_error <= LEDGER_TOL, "{w}x{h} {scale}: {l:?}");
            }
            for (threads, strip_rows) in [(2, 1), (1, 7), (3, 64), (2, 0)] {
                let cfg = PipelineConfig {
                    threads,
                    strip_rows,
                    ..Default::default()
                };
                let (o, s) = run(w, h, 2, scale, &cfg);
                assert_eq!(
                    s.digest, stats.digest,
                    "{w}x{h} threads {threads} strips {strip_rows}"
                );
                assert_eq!(o, out);
            }
        }
    }

    /// Where the denoiser has nothing, the energy stays where it was.
    #[test]
    fn an_empty_denoiser_output_keeps_the_energy_in_place() {
        let (w, h) = (9, 6);
        let e: Vec<f32> = (0..w * h).map(|i| (i % 5) as f32).collect();
        let (out, stats) = restore_planar(
            e.clone(),
            vec![0.0; w * h],
            (w, h),
            vec!["Y".into()],
            vec![1.0],
            2.0,
            &PipelineConfig::default(),
            Precision::F32,
        )
        .unwrap();
        assert_eq!(out, e);
        match stats.method {
            MethodCounts::Restore(c) => {
                assert_eq!(c.unshaped as usize, e.iter().filter(|&&v| v > 0.0).count())
            }
            other => panic!("{other:?}"),
        }
    }
}
