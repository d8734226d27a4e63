//! The part of the energy kept in place (`l`), row by row: step 1 of the
//! stage ([`super::RestoreStage`]).

use std::collections::VecDeque;

use rayon::prelude::*;

use super::Reliable;
use crate::filter::restore::{kept, reflect, shape, taps, EMISSION_KEEP_GAIN, KEEP_SIGMA};
use crate::pipeline::counts::RestoreCounts;
use crate::pipeline::window::RowWindow;

/// The shape's blur and the part of the energy kept in place, row by row.
pub(super) struct Kept {
    nch: usize,
    /// Where each channel's emission guide is in the input rows (after the
    /// energy's channels), if the energy image has one.
    emission: Vec<Option<usize>>,
    /// Channels the denoiser did not write: nothing kept, they stay whole.
    copied: Vec<bool>,
    /// The energy image's statistics, where they stand in for a guide.
    reliable: Option<Reliable>,
    /// The first of the denoiser's channels in the input rows.
    pub(super) d_at: usize,
    w: usize,
    h: usize,
    taps: Vec<f64>,
    /// The 2-D kernel's centre weight.
    centre: f64,
    /// The keep gain.
    gain: f64,
    /// Per row whose column is in: `l`, `[channel][x]`, and whether the row
    /// has any (most have none).
    pub(super) kept_rows: RowWindow<f64>,
    any: VecDeque<bool>,
    pub(super) counts: RestoreCounts,
}

impl Kept {
    pub(super) fn new(
        emission: Vec<Option<usize>>,
        copied: Vec<bool>,
        reliable: Option<Reliable>,
        (w, h): (usize, usize),
        gain: f64,
    ) -> Self {
        let taps = taps(KEEP_SIGMA);
        let nch = emission.len();
        let stats = reliable.as_ref().map_or(0, |r| r.channels.len());
        Kept {
            nch,
            d_at: nch + emission.iter().flatten().count() + stats,
            emission,
            copied,
            reliable,
            w,
            h,
            gain,
            centre: taps[taps.len() / 2].powi(2),
            taps,
            kept_rows: RowWindow::new(nch * w),
            any: VecDeque::new(),
            counts: RestoreCounts::default(),
        }
    }

    pub(super) fn r(&self) -> usize {
        self.taps.len() / 2
    }

    /// `l` for every row whose rows around are in (`rows_in`, all of them
    /// when `all_in`); returns the rows done now. The input window holds
    /// the rows `r` above and below.
    pub(super) fn advance(
        &mut self,
        input: &RowWindow<f32>,
        rows_in: usize,
        all_in: bool,
    ) -> (usize, usize) {
        let (nch, w, h, r, d_at) = (self.nch, self.w, self.h, self.r(), self.d_at);
        let a = self.kept_rows.end();
        let b = if all_in { h } else { rows_in.saturating_sub(r) };
        if b <= a {
            return (a, a);
        }
        for _ in a..b {
            self.kept_rows.push_stale(0.0);
        }
        let (taps, centre, gain) = (&self.taps, self.centre, self.gain);
        let (emission, copied, reliable) = (&self.emission, &self.copied, &self.reliable);
        let mut rows = self.kept_rows.range_mut(a, b);
        let per_row: Vec<(bool, RestoreCounts)> = rows
            .par_iter_mut()
            .enumerate()
            .map_init(
                || vec![false; w],
                |sure, (i, out)| {
                    let y = a + i;
                    let row = input.get(y);
                    let mut c = RestoreCounts::default();
                    let mut any = false;
                    if let Some(r) = reliable {
                        r.mark(row, w, sure);
                    }
                    for ch in 0..nch {
                        let l = &mut out[ch * w..(ch + 1) * w];
                        if copied[ch] {
                            l.fill(0.0);
                            continue;
                        }
                        let e = &row[ch * w..(ch + 1) * w];
                        let d = &row[(d_at + ch) * w..(d_at + ch + 1) * w];
                        let em = emission[ch].map(|k| &row[(nch + k) * w..(nch + k + 1) * w]);
                        for x in 0..w {
                            let ev = f64::from(e[x]);
                            // Measured once, for the emission and the energy.
                            let mut q_at = None;
                            let mut q = || {
                                *q_at.get_or_insert_with(|| {
                                    around(input, (x, y), (w, h), (d_at + ch) * w, taps)
                                })
                            };
                            let own = shape(d[x]);
                            // The guide's light, or all of a pixel its samples
                            // agree on.
                            let guide = match em {
                                Some(em) => Some(shape(em[x])),
                                None if reliable.is_some() && sure[x] => Some(ev.max(0.0)),
                                None => None,
                            };
                            let lit = guide.map_or(0.0, |v| {
                                kept(v, own, &mut q, centre, EMISSION_KEEP_GAIN)
                                    .clamp(0.0, ev.max(0.0))
                            });
                            l[x] = lit + kept(ev - lit, own, &mut q, centre, gain);
                            if l[x] != 0.0 {
                                any = true;
                                c.count(ev, l[x] == ev);
                                c.kept_energy += l[x].abs();
                            }
                        }
                    }
                    (any, c)
                },
            )
            .collect();
        // Summed in row order: the counts' energy is the same for any strips.
        for (any, c) in per_row {
            self.any.push_back(any);
            self.counts += c;
        }
        (a, b)
    }

    /// The first input row still read: `r` above the next row of `l`.
    pub(super) fn input_needed(&self) -> usize {
        self.kept_rows.end().saturating_sub(self.r())
    }

    /// `l` of row `y` (`None`: all zero).
    pub(super) fn row(&self, y: usize) -> Option<&[f64]> {
        self.any[y - self.kept_rows.first()].then(|| self.kept_rows.get(y))
    }

    /// Rows below `y` are no longer read.
    pub(super) fn release(&mut self, y: usize) {
        let before = self.kept_rows.first();
        self.kept_rows.evict_below(y);
        for _ in before..self.kept_rows.first() {
            self.any.pop_front();
        }
    }
}

/// The denoiser's energy around pixel `at` of a `size` image: its shape
/// under the 2-D kernel `taps x taps`, reflected at the edges, from the
/// input rows' channel at `offset`. Only for the few pixels whose energy
/// exceeds the gain on the denoiser's own value.
fn around(
    input: &RowWindow<f32>,
    (x, y): (usize, usize),
    (w, h): (usize, usize),
    offset: usize,
    taps: &[f64],
) -> f64 {
    let r = (taps.len() / 2) as isize;
    let mut q = 0.0;
    for (i, &ty) in taps.iter().enumerate() {
        let d = &input.get(reflect(y as isize + i as isize - r, h))[offset..offset + w];
        let mut row = 0.0;
        for (k, &tx) in taps.iter().enumerate() {
            row += tx * shape(d[reflect(x as isize + k as isize - r, w)]);
        }
        q += ty * row;
    }
    q
}
