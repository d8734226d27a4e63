//! `epfilt restore`'s stage: the energy image's energy put back into the
//! denoiser's output ([`crate::filter::restore`]), streamed in one pass.
//!
//! The strips hold the energy image's channels, then the denoiser's (the
//! books' ledger counts the first ones: the total it checks is the energy
//! image's). A strip's work is four steps, each a parallel loop over rows:
//!
//! 1. the part of the energy kept in place (`l`) for the rows whose rows
//!    around are in, with the denoiser's energy around a pixel (`q`)
//!    measured only where its energy exceeds the gain on the denoiser's own
//!    value (rare: lamps, fireflies);
//! 2. those rows' rest `e - l` and shape added into their blocks' sums;
//! 3. the carrier's moments of the rows whose next row of blocks is summed
//!    (the carrier reads the block means around a row);
//! 4. each row of blocks whose field can be fixed (the rows of blocks
//!    [`LOOKAHEAD`] below it with their moments): `c = s + t (f - 1)` for
//!    its rows, each block's exact factor `g`, and the rows `c g + l`.
//!
//! Each row's values depend only on rows that are in, and block sums are
//! added row by row in order, never by how rows came: the output is the
//! same for any strip height and thread count.

use rayon::prelude::*;

use super::counts::MethodCounts;
use super::memory::{MemorySink, MemorySource};
use super::pair::{Pair, Pick};
use super::stage::{Output, Stage, WindowUse};
use super::stream::{Streamer, MAX_CHANNELS};
use super::window::RowWindow;
use super::{
    run_streamer, PipelineConfig, Precision, Progress, RunStats, Sink, Source, StripLayout,
};
use crate::error::{Error, Result};
use crate::filter::ep_box::StatsLayout;
use crate::filter::restore::{shape, FieldRows, RestoreParams, LOOKAHEAD, RELIABLE_RSE};
use crate::geometry::{Grid, Halo};

mod kept;
use kept::Kept;

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
    /// The field of each channel.
    fields: Vec<FieldRows>,
    /// Pixel rows summed into the fields.
    summed: usize,
    /// Pixel rows whose carrier's moments are in the fields.
    momented: usize,
    /// Final rows.
    out: RowWindow<f64>,
    /// Blocks whose denoiser shape carried nothing: their energy stayed.
    unshaped_blocks: u64,
}

impl RestoreStage {
    /// The stage for `nch` channels of a `w x h` image, blocks of
    /// `params.scale`, its keep gain.
    pub fn new(
        emission: Vec<Option<usize>>,
        copied: Vec<bool>,
        reliable: Option<Reliable>,
        (w, h): (usize, usize),
        params: RestoreParams,
    ) -> Self {
        let nch = emission.len();
        let kept = Kept::new(emission, copied.clone(), reliable, (w, h), params.keep_gain);
        RestoreStage {
            nch,
            copied,
            d_at: kept.d_at,
            w,
            h,
            kept,
            fields: (0..nch)
                .map(|_| FieldRows::new(w, h, params.scale))
                .collect(),
            summed: 0,
            momented: 0,
            out: RowWindow::new(nch * w),
            unshaped_blocks: 0,
        }
    }

    fn b(&self) -> usize {
        self.fields[0].b
    }

    /// Rows `a..b` (their `l` known) into the fields' block sums.
    fn add_sums(&mut self, input: &RowWindow<f32>, a: usize, b: usize) {
        let (nch, w, d_at) = (self.nch, self.w, self.d_at);
        let (fields, kept, copied) = (&self.fields, &self.kept, &self.copied);
        let nbx = fields[0].nbx;
        let sums: Vec<Vec<(f64, f64)>> = (a..b)
            .into_par_iter()
            .map_init(
                || (vec![0.0f64; w], vec![0.0f64; w]),
                |(s, rest), y| {
                    let row = input.get(y);
                    let l = kept.row(y);
                    let mut out = vec![(0.0, 0.0); nch * nbx];
                    // A copied channel's field stays empty: it is never read.
                    for ch in (0..nch).filter(|&ch| !copied[ch]) {
                        let e = &row[ch * w..(ch + 1) * w];
                        let d = &row[(d_at + ch) * w..(d_at + ch + 1) * w];
                        for x in 0..w {
                            s[x] = shape(d[x]);
                            rest[x] = f64::from(e[x]) - l.map_or(0.0, |l| l[ch * w + x]);
                        }
                        fields[ch].row_sums(s, rest, &mut out[ch * nbx..(ch + 1) * nbx]);
                    }
                    out
                },
            )
            .collect();
        // Added in row order: the sums are the same for any strips.
        for (y, row) in (a..b).zip(sums) {
            for (ch, f) in self.fields.iter_mut().enumerate() {
                f.add(y, &row[ch * nbx..(ch + 1) * nbx]);
            }
        }
        self.summed = b;
    }

    /// Rows `a..b` (the block rows around them summed) into the fields'
    /// carrier moments.
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
                f.add_moments(y, &row[ch * nbx..(ch + 1) * nbx]);
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
                    // Nothing to shape the rest with: it stays (below).
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
        // The kept part's rows around, then the rows of blocks the field
        // looks ahead, the row of blocks below them (the carrier's means),
        // and the row of blocks being finished.
        let r = self.kept.r();
        Halo {
            xbar_reach: 0,
            base_reach: r,
            search_reach: 0,
            spread_reach: r + (LOOKAHEAD + 3) * self.b(),
        }
    }

    fn arrive(&mut self, _input: &mut RowWindow<f32>, _a: usize, _b: usize) {}

    fn advance(&mut self, input: &RowWindow<f32>, rows_in: usize, all_in: bool) -> usize {
        let (ka, kb) = self.kept.advance(input, rows_in, all_in);
        self.add_sums(input, ka, kb);
        let to = self.fields[0].moments_to(self.summed);
        if to > self.momented {
            self.add_moments(input, self.momented, to);
        }
        let (bs, h) = (self.b(), self.h);
        let nby = self.fields[0].nby;
        // A row of blocks is finished once its field and the next row's are
        // fixed (its lower half reads both). Once the input is all in, one
        // row of blocks a call: the skeleton calls again, so the rows of
        // blocks still held are never all final rows at once.
        let from = self.out.end();
        while self.out.end() < h && !(all_in && self.out.end() > from) {
            let j = self.out.end() / bs;
            let next = (j + 1).min(nby - 1);
            if !self.fields[0].can_fix(next, self.momented) {
                break;
            }
            for f in &mut self.fields {
                f.fix(j);
                f.fix(next);
            }
            let b = ((j + 1) * bs).min(h);
            self.finish_blocks(input, j * bs, b);
            self.kept.release(b);
            for f in &mut self.fields {
                f.release(j);
            }
        }
        self.out.end()
    }

    fn input_needed(&self) -> usize {
        // The energy and shape of rows not yet final, and the rows around
        // the next row of `l`.
        self.out.end().min(self.kept.input_needed())
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
        MethodCounts::Restore(c)
    }

    fn windows(&self) -> Vec<WindowUse> {
        let row = self.nch * self.w * 8;
        vec![
            WindowUse {
                name: "energy kept in place",
                rows: self.kept.kept_rows.high_water(),
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

/// The energy image's own statistics (a variance pass and its sample
/// count, as `ep-box` finds them), read where it has no emission guide: a
/// pixel whose mean is sure (relative standard error under
/// [`RELIABLE_RSE`]) is kept as a guide's light is.
#[derive(Clone, Debug)]
pub struct Reliable {
    /// Where the statistics are in the energy's rows.
    stats: StatsLayout,
    /// The colour channels (luminance weight not 0) and their weights.
    colour: Vec<(usize, f64)>,
    /// The statistics' channels, read after the energy's.
    channels: Vec<String>,
}

impl Reliable {
    /// The statistics at `stats` (in the energy's rows, after its channels
    /// of luminance weights `lum`), read from the channels `channels`.
    pub fn new(stats: StatsLayout, lum: &[f64], channels: Vec<String>) -> Self {
        let colour = (lum.iter().copied().enumerate())
            .filter(|(_, l)| *l != 0.0)
            .collect();
        Reliable {
            stats,
            colour,
            channels,
        }
    }

    /// Per pixel of an energy row (`w` wide), whether its mean is sure.
    fn mark(&self, row: &[f32], w: usize, sure: &mut [bool]) {
        let mut weights = [0.0f64; 3];
        for (wt, (_, l)) in weights.iter_mut().zip(&self.colour) {
            *wt = *l;
        }
        for (x, s) in sure.iter_mut().enumerate().take(w) {
            let y: f64 = (self.colour.iter())
                .map(|&(c, l)| l * f64::from(row[c * w + x]))
                .sum();
            let (n, se2) = self.stats.pixel(&weights, y, |i| f64::from(row[i * w + x]));
            *s = y > 0.0 && n >= 2.0 && se2 < (RELIABLE_RSE * y).powi(2);
        }
    }
}

/// The energy image's rows: its `channels`, then the emission guide of
/// those `emission` names (`Some(k)`: the `k`-th guide channel after them).
#[derive(Clone, Debug)]
pub struct EnergyLayout {
    /// The energy's channels, the ones restored.
    pub channels: Vec<String>,
    /// Per channel, its emission guide's place among the guide channels.
    pub emission: Vec<Option<usize>>,
    /// The luminance weights (for the layout).
    pub luminance: Vec<f64>,
    /// The guide's channel names, in their order (for the report).
    pub guide: Vec<String>,
    /// Per channel, its place among the denoiser's channels; `None`: the
    /// denoiser did not write it (an alpha), and it stays as the energy
    /// image has it.
    pub denoised: Vec<Option<usize>>,
    /// The channels of the denoiser's rows.
    pub denoised_channels: usize,
    /// The energy image's statistics, read after its channels where it has
    /// no emission guide.
    pub reliable: Option<Reliable>,
    /// Per channel, whether it is data carried beside the beauty (copied,
    /// with no denoiser's pick): out of the ledger, and its non-finite
    /// values (a sky's depth) pass as they are.
    pub data: Vec<bool>,
}

impl EnergyLayout {
    /// `channels` without an emission guide.
    pub fn plain(channels: Vec<String>, luminance: Vec<f64>) -> Self {
        EnergyLayout {
            emission: vec![None; channels.len()],
            denoised: (0..channels.len()).map(Some).collect(),
            denoised_channels: channels.len(),
            data: vec![false; channels.len()],
            reliable: None,
            channels,
            luminance,
            guide: Vec::new(),
        }
    }

    /// The strips of a `w x h` restore: the energy's channels, its guide's
    /// and the denoiser's ([`crate::pipeline::restore_bytes`] sizes them).
    pub fn strips(&self, (w, h): (usize, usize)) -> StripLayout {
        let grid = Grid {
            in_w: w,
            in_h: h,
            s: 1,
        };
        let channels = &self.channels;
        let mut layout = StripLayout::new(grid, channels.clone(), self.luminance.clone());
        layout.data = self.data.clone();
        let guide = (channels.iter().zip(&self.emission))
            .filter_map(|(c, e)| e.map(|_| format!("emission.{c}")));
        let stats = self
            .reliable
            .iter()
            .flat_map(|r| r.channels.iter().cloned());
        layout.aux = guide
            .chain(stats)
            .chain(
                channels[..self.denoised_slots()]
                    .iter()
                    .map(|c| format!("denoised.{c}")),
            )
            .collect();
        layout
    }

    /// Channels of the denoiser's half of a strip: one per energy channel up
    /// to the last one restored (the data carried after it is never read
    /// there; a render's dozens of passes would double the strips).
    fn denoised_slots(&self) -> usize {
        self.data.iter().rposition(|d| !d).map_or(0, |i| i + 1)
    }

    /// Channels the energy's rows hold: its own and the guide's.
    fn row_channels(&self) -> usize {
        let stats = self.reliable.as_ref().map_or(0, |r| r.channels.len());
        self.channels.len() + self.emission.iter().flatten().count() + stats
    }
}

/// Restore the denoiser's output with the energy image's energy by
/// `params` into `sink`: both `w x h`; the energy's rows as `energy_layout`
/// says, the denoiser's of its channels; the books' ledger counts `energy`.
#[allow(clippy::too_many_arguments)]
pub fn restore_stream<A: Source, B: Source, K: Sink>(
    energy: A,
    denoised: B,
    sink: K,
    (w, h): (usize, usize),
    energy_layout: EnergyLayout,
    params: RestoreParams,
    cfg: &PipelineConfig,
    progress: Progress<'_>,
) -> Result<RunStats> {
    let nch = energy_layout.channels.len();
    let na = energy_layout.row_channels();
    let slots = energy_layout.denoised_slots();
    if w == 0 || h == 0 || nch == 0 || na + slots > MAX_CHANNELS {
        return Err(Error::Config(format!(
            "restore needs a non-empty image with at most {MAX_CHANNELS} channels in all (the energy's, its guide's and the denoiser's), not {w}x{h} with {}",
            na + slots
        )));
    }
    let params = params.check().map_err(Error::Config)?;
    let layout = energy_layout.strips((w, h));
    let EnergyLayout {
        emission,
        denoised: picks,
        denoised_channels,
        reliable,
        data,
        ..
    } = energy_layout;
    // Data is the energy's, whatever the denoiser wrote.
    let copied: Vec<bool> = (picks.iter().zip(&data))
        .map(|(p, &d)| p.is_none() || d)
        .collect();
    let stage = RestoreStage::new(emission, copied, reliable, (w, h), params);
    let streamer = Streamer::of_stage(
        &layout,
        Box::new(stage),
        cfg.nonfinite,
        sink.precisions(nch),
    );
    // A channel the denoiser did not write has the energy's own values in
    // its place: the stage keeps them as they are.
    let picks = (picks[..slots].iter().enumerate())
        .map(|(ch, p)| p.map_or(Pick::First(ch), Pick::Second))
        .collect();
    let pair = Pair::new(energy, denoised, w, (na, denoised_channels), picks);
    run_streamer(pair, sink, &layout, streamer, cfg, progress)
}

/// [`restore_stream`] of two whole images in memory (planar
/// `[row][channel][x]`; the energy's rows as `energy_layout` says),
/// rounded to `precision`: the output and the run.
pub fn restore_planar(
    energy: Vec<f32>,
    denoised: Vec<f32>,
    (w, h): (usize, usize),
    energy_layout: EnergyLayout,
    params: RestoreParams,
    cfg: &PipelineConfig,
    precision: Precision,
) -> Result<(Vec<f32>, RunStats)> {
    let nch = energy_layout.channels.len();
    let na = energy_layout.row_channels();
    let nd = energy_layout.denoised_channels;
    let pixels = w.checked_mul(h);
    let n = pixels.and_then(|p| p.checked_mul(nd));
    if pixels.and_then(|p| p.checked_mul(na)) != Some(energy.len()) || n != Some(denoised.len()) {
        return Err(Error::Config(format!(
            "{} energy and {} denoised values for a {w}x{h} image of {nch} channels ({na} with the guide)",
            energy.len(),
            denoised.len(),
        )));
    }
    let mut sink = MemorySink::with_precision(precision);
    let stats = restore_stream(
        MemorySource::new(energy, na * w),
        MemorySource::new(denoised, nd * w),
        &mut sink,
        (w, h),
        energy_layout,
        params,
        cfg,
        &|_, _| {},
    )?;
    Ok((sink.data, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::restore::{taps, KEEP_GAIN, KEEP_SIGMA};
    use crate::pipeline::RunStats;

    /// What a restore's ledger balances to (see the job's limit).
    const LEDGER_TOL: f64 = 1e-12;
    /// A block's sum of f32 outputs against its f64 energy: a few f32
    /// roundings (2^-24 each) over up to a thousand values.
    const BLOCK_TOL: f64 = 1e-5;

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

    /// A restore of [`images`]; `lamps`: with an emission guide that
    /// holds most of every 23rd pixel's energy.
    fn run(
        (w, h, nch): (usize, usize, usize),
        scale: usize,
        cfg: &PipelineConfig,
        lamps: bool,
    ) -> (Vec<f32>, RunStats) {
        let (mut e, d) = images(w, h, nch);
        let names = (0..nch).map(|c| format!("c{c}")).collect();
        let mut layout = EnergyLayout::plain(names, vec![0.0; nch]);
        if lamps {
            let row = nch * w;
            e = (e.chunks(row).enumerate())
                .flat_map(|(y, r)| {
                    let lamp = r.iter().enumerate().map(move |(i, &v)| {
                        let x = i % w;
                        if (x * 7 + y * 3) % 23 == 0 {
                            0.9 * v
                        } else {
                            0.0
                        }
                    });
                    r.iter().copied().chain(lamp).collect::<Vec<f32>>()
                })
                .collect();
            layout.emission = (0..nch).map(Some).collect();
        }
        restore_planar(
            e,
            d,
            (w, h),
            layout,
            RestoreParams {
                scale,
                keep_gain: KEEP_GAIN,
            },
            cfg,
            Precision::F32,
        )
        .unwrap()
    }

    #[test]
    fn energy_is_exact_and_bytes_do_not_depend_on_strips_or_threads() {
        let sizes = [(37, 29, 8), (5, 4, 2), (64, 3, 32), (70, 45, 16)];
        for ((w, h, scale), lamps) in sizes.into_iter().flat_map(|s| [(s, false), (s, true)]) {
            let base = PipelineConfig {
                threads: 1,
                strip_rows: 1,
                ..Default::default()
            };
            let (out, stats) = run((w, h, 2), scale, &base, lamps);
            for l in &stats.ledger {
                assert!(l.rel_error <= LEDGER_TOL, "{w}x{h} {scale}: {l:?}");
            }
            // Every block holds the energy image's energy (to the output's
            // f32 rounding).
            let (e, _) = images(w, h, 2);
            let (nbx, nby) = (w.div_ceil(scale), h.div_ceil(scale));
            let mut sums = vec![[0.0f64; 2]; 2 * nbx * nby];
            for y in 0..h {
                for c in 0..2 {
                    for x in 0..w {
                        let k = 2 * ((y / scale) * nbx + x / scale) + c;
                        sums[k][0] += f64::from(e[(y * 2 + c) * w + x]);
                        sums[k][1] += f64::from(out[(y * 2 + c) * w + x]);
                    }
                }
            }
            for [se, so] in sums {
                assert!(
                    (so - se).abs() <= BLOCK_TOL * se.abs(),
                    "{w}x{h} {scale}: {so} vs {se}"
                );
            }
            for (threads, strip_rows) in [(2, 1), (1, 7), (3, 64), (2, 0)] {
                let cfg = PipelineConfig {
                    threads,
                    strip_rows,
                    ..Default::default()
                };
                let (o, s) = run((w, h, 2), scale, &cfg, lamps);
                assert_eq!(
                    s.digest, stats.digest,
                    "{w}x{h} threads {threads} strips {strip_rows}"
                );
                assert_eq!(o, out);
            }
        }
    }

    /// Once the input is all in, the rows of blocks still held are
    /// finished one a call: the final rows held never reach more than one
    /// row of blocks and the rows a strip brings, however many rows of
    /// blocks the field looks ahead. The input comes in one strip here,
    /// the worst case: before, every row was final at once.
    #[test]
    fn the_last_rows_of_blocks_are_finished_one_at_a_time() {
        let (w, h, scale) = (23, 200, 8);
        for strip_rows in [1, 16, h] {
            let cfg = PipelineConfig {
                threads: 2,
                strip_rows,
                ..Default::default()
            };
            let (_, stats) = run((w, h, 2), scale, &cfg, false);
            let out = stats.windows.iter().find(|u| u.name == "output").unwrap();
            assert!(
                out.rows <= scale + strip_rows.min(h - LOOKAHEAD * scale),
                "strips of {strip_rows}: {} final rows held",
                out.rows
            );
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
            EnergyLayout::plain(vec!["Y".into()], vec![1.0]),
            RestoreParams {
                scale: 4,
                keep_gain: KEEP_GAIN,
            },
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

    /// A channel the denoiser did not write (an alpha) stays as the energy
    /// has it, bit for bit, beside one restored as before, at any strips.
    #[test]
    fn a_channel_the_denoiser_lacks_stays_as_the_energy_has_it() {
        let (w, h) = (37, 29);
        let (e, d) = images(w, h, 2);
        // The denoiser's rows: its first channel only.
        let d1: Vec<f32> = d.chunks(w).step_by(2).flatten().copied().collect();
        let params = RestoreParams {
            scale: 8,
            keep_gain: KEEP_GAIN,
        };
        let one = |layout: EnergyLayout, d: Vec<f32>, strip_rows| {
            let cfg = PipelineConfig {
                strip_rows,
                ..Default::default()
            };
            restore_planar(e.clone(), d, (w, h), layout, params, &cfg, Precision::F32).unwrap()
        };
        let names = vec!["R".to_string(), "A".to_string()];
        let both = EnergyLayout::plain(names.clone(), vec![1.0, 0.0]);
        let (full, _) = one(both.clone(), d.clone(), 0);
        let alpha = EnergyLayout {
            denoised: vec![Some(0), None],
            denoised_channels: 1,
            ..both
        };
        for strip_rows in [0, 1, 5] {
            let (out, stats) = one(alpha.clone(), d1.clone(), strip_rows);
            for (y, (o, (f, e))) in out
                .chunks(w)
                .zip(full.chunks(w).zip(e.chunks(w)))
                .enumerate()
            {
                // Rows alternate R, A: R as with both channels, A the energy's.
                assert_eq!(o, if y % 2 == 0 { f } else { e }, "row {y}");
            }
            assert!(stats.ledger.iter().all(|l| l.rel_error <= LEDGER_TOL));
        }
    }

    /// A lamp the denoiser removed, within the keep gain of the denoiser's
    /// own value: spread through its block without the emission guide,
    /// kept in place with it (beyond the denoiser's share around), and the
    /// energy exact either way.
    /// Without a guide, a render's variance pass tells a bulb (every sample
    /// bright: its mean is sure) from a firefly (one bright sample: its
    /// standard error is its mean), which the gain alone cannot.
    #[test]
    fn a_sure_pixel_stays_and_a_firefly_spreads() {
        use crate::filter::ep_box::{Spp, VarianceKind};
        let (w, h, n) = (16, 16, 16.0);
        let (bulb, firefly) = (4 * 16 + 4, 11 * 16 + 11);
        let mut e = vec![1.0f32; w * h];
        e[bulb] = 101.0;
        e[firefly] = 101.0;
        // Sample variances: a tenth of the mean for the bulb's standard
        // error, all of it for the firefly's (one hit among n), the rest
        // flat.
        let var = |i: usize, v: f32| match i {
            i if i == bulb => (0.1 * v).powi(2) * n as f32,
            i if i == firefly => v * v * n as f32,
            _ => 0.01,
        };
        let mut rows = Vec::new();
        for (y, row) in e.chunks(w).enumerate() {
            rows.extend_from_slice(row);
            rows.extend(row.iter().enumerate().map(|(x, &v)| var(y * w + x, v)));
        }
        let stats = StatsLayout {
            variance: vec![1],
            kind: VarianceKind::Sample,
            mean_y: None,
            spp: Spp::Fixed(n),
        };
        let layout = EnergyLayout {
            reliable: Some(Reliable::new(stats, &[1.0], vec!["var.Y".into()])),
            ..EnergyLayout::plain(vec!["Y".into()], vec![1.0])
        };
        let params = RestoreParams {
            scale: 8,
            keep_gain: KEEP_GAIN,
        };
        let cfg = PipelineConfig::default();
        let (out, stats) = restore_planar(
            rows,
            vec![1.0f32; w * h],
            (w, h),
            layout,
            params,
            &cfg,
            Precision::F32,
        )
        .unwrap();
        let around = 1.0 / taps(KEEP_SIGMA)[taps(KEEP_SIGMA).len() / 2].powi(2);
        assert!(out[bulb] as f64 >= 100.0 - around, "{} {around}", out[bulb]);
        assert!(out[firefly] < 20.0, "{}", out[firefly]);
        assert!(
            stats.ledger[0].rel_error <= LEDGER_TOL,
            "{:?}",
            stats.ledger
        );
    }

    #[test]
    fn the_emission_guide_keeps_a_lamp_the_denoiser_removed() {
        let (w, h, lamp) = (16, 16, 8 * 16 + 8);
        let mut e = vec![1.0f32; w * h];
        e[lamp] = 101.0;
        let d = vec![1.0f32; w * h];
        let mut with_guide = Vec::new();
        for row in e.chunks(w) {
            with_guide.extend_from_slice(row);
            with_guide.extend(row.iter().map(|&v| if v > 1.0 { 100.0 } else { 0.0 }));
        }
        let plain = EnergyLayout::plain(vec!["Y".into()], vec![1.0]);
        let guided = EnergyLayout {
            emission: vec![Some(0)],
            ..plain.clone()
        };
        let params = RestoreParams {
            scale: 8,
            keep_gain: KEEP_GAIN,
        };
        let cfg = PipelineConfig::default();
        let run = |energy, layout| {
            restore_planar(
                energy,
                d.clone(),
                (w, h),
                layout,
                params,
                &cfg,
                Precision::F32,
            )
            .unwrap()
        };
        let (spread, s0) = run(e.clone(), plain);
        let (kept, s1) = run(with_guide, guided);
        // The share around a flat denoiser: its value over the kernel's
        // centre weight.
        let around = 1.0 / taps(KEEP_SIGMA)[taps(KEEP_SIGMA).len() / 2].powi(2);
        assert!(spread[lamp] < 20.0, "{}", spread[lamp]);
        assert!(
            kept[lamp] as f64 >= 100.0 - around,
            "{} {around}",
            kept[lamp]
        );
        for s in [s0, s1] {
            assert!(s.ledger[0].rel_error <= LEDGER_TOL, "{:?}", s.ledger);
        }
    }
}
