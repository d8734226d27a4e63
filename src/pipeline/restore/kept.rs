//! The part of the energy kept in place (`l`), row by row, on evidence
//! ([`crate::filter::restore`]'s first part): both passes compute it the
//! same way.

use std::collections::VecDeque;

use rayon::iter::{IntoParallelIterator, ParallelIterator};

use super::RenderStats;
use crate::filter::restore::{
    denoiser_peak, kept, reflect, shape, taps, EMISSION_KEEP_GAIN, KEEP_SIGMA,
};
use crate::pipeline::counts::RestoreCounts;
use crate::pipeline::schedule::{forward, Reads};
use crate::pipeline::window::RowWindow;

/// Where the input rows hold what the kept part reads.
#[derive(Clone, Debug)]
pub(super) struct KeptLayout {
    /// Per energy channel, its emission guide's place in the rows, if the
    /// energy image has one ([`super::EnergyLayout::emission`]).
    pub emission: Vec<Option<usize>>,
    /// Channels the denoiser did not write: nothing kept, they stay whole.
    pub copied: Vec<bool>,
    /// The energy image's statistics (its variance pass), if read.
    pub stats: Option<RenderStats>,
    /// Whether agreeing samples count as evidence (`--guides none`: not).
    pub sure_keeps: bool,
    /// A gain that keeps beside the evidence (epfilt's output, the user's).
    pub gain: Option<f64>,
}

impl KeptLayout {
    /// The first of the denoiser's channels in the input rows: after the
    /// energy's, and its guide's and statistics' read after them.
    pub fn d_at(&self) -> usize {
        let nch = self.emission.len();
        let guide = self.emission.iter().flatten().filter(|&&k| k >= nch);
        let stats = self.stats.as_ref().map_or(0, |r| r.channels.len());
        nch + guide.count() + stats
    }
}

/// The shape's blur and the part of the energy kept in place, row by row.
pub(super) struct Kept {
    nch: usize,
    layout: KeptLayout,
    /// The first of the denoiser's channels in the input rows.
    pub(super) d_at: usize,
    w: usize,
    h: usize,
    taps: Vec<f64>,
    /// The 2-D kernel's centre weight.
    centre: f64,
    /// Per row from `first` whose rows around are in: its `l`,
    /// `[channel][x]`, where it has any (most rows have none).
    rows: VecDeque<Option<Vec<f64>>>,
    first: usize,
    /// Buffers of rows released, for the next rows that keep something.
    spare: std::sync::Mutex<Vec<Vec<f64>>>,
    /// Most rows with a part kept held at once.
    pub(super) high_water: usize,
    pub(super) counts: RestoreCounts,
}

/// Why a pixel's light stays in place, most specific first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Evidence {
    /// Its emission guide.
    Guide,
    /// Its samples agree.
    Variance,
    /// The denoiser kept a peak there.
    Denoiser,
}

impl Kept {
    pub(super) fn new(layout: KeptLayout, (w, h): (usize, usize)) -> Self {
        let taps = taps(KEEP_SIGMA);
        let nch = layout.emission.len();
        Kept {
            nch,
            d_at: layout.d_at(),
            layout,
            w,
            h,
            centre: taps[taps.len() / 2].powi(2),
            taps,
            rows: VecDeque::new(),
            first: 0,
            spare: Default::default(),
            high_water: 0,
            counts: RestoreCounts::default(),
        }
    }

    pub(super) fn r(&self) -> usize {
        self.taps.len() / 2
    }

    /// What a row's `l` reads ([`crate::pipeline::schedule`]): the input
    /// rows `r` either side.
    pub(super) fn reads(&self) -> Reads {
        vec![(0, self.r())]
    }

    /// The rows of `l` that `rows_in` input rows allow ([`Kept::reads`]).
    pub(super) fn target(&self, rows_in: usize) -> usize {
        forward(&[self.reads()], self.h, &[rows_in], usize::MAX)[1]
    }

    /// `l` of rows up to `b` (their rows around in, [`Kept::target`]);
    /// returns the rows done now. The input window holds the rows `r`
    /// above and below.
    pub(super) fn advance(&mut self, input: &RowWindow<f32>, b: usize) -> (usize, usize) {
        let h = self.h;
        let a = self.end();
        if b <= a {
            return (a, a);
        }
        let this = Rows {
            nch: self.nch,
            w: self.w,
            h,
            d_at: self.d_at,
            layout: &self.layout,
            taps: &self.taps,
            centre: self.centre,
            cross: self.taps[self.r() + 1] / self.taps[self.r()],
            input,
        };
        let (n, spare) = (self.nch * self.w, &self.spare);
        let per_row: Vec<(Option<Vec<f64>>, RestoreCounts)> = (a..b)
            .into_par_iter()
            .map_init(
                || (vec![false; self.w], vec![0.0; n]),
                |(sure, l), y| {
                    let (any, c) = this.row(y, l, sure);
                    // Kept only where it holds something: a buffer of a row
                    // released, else a new one.
                    let kept = any.then(|| {
                        let mut v = spare
                            .lock()
                            .map(|mut s| s.pop())
                            .ok()
                            .flatten()
                            .unwrap_or_default();
                        v.clear();
                        v.extend_from_slice(l);
                        v
                    });
                    (kept, c)
                },
            )
            .collect();
        // Summed in row order: the counts' energy is the same for any strips.
        for (kept, c) in per_row {
            self.rows.push_back(kept);
            self.counts += c;
        }
        let held = self.rows.iter().filter(|r| r.is_some()).count();
        self.high_water = self.high_water.max(held);
        (a, b)
    }

    /// The first input row still read: `r` above the next row of `l`.
    pub(super) fn input_needed(&self) -> usize {
        self.end().saturating_sub(self.r())
    }

    /// Rows whose `l` is known.
    pub(super) fn end(&self) -> usize {
        self.first + self.rows.len()
    }

    /// `l` of row `y` (`None`: all zero).
    pub(super) fn row(&self, y: usize) -> Option<&[f64]> {
        self.rows[y - self.first].as_deref()
    }

    /// Rows below `y` are no longer read.
    pub(super) fn release(&mut self, y: usize) {
        let mut spare = self.spare.lock().ok();
        while self.first < y && !self.rows.is_empty() {
            if let (Some(v), Some(s)) = (self.rows.pop_front().flatten(), spare.as_mut()) {
                s.push(v);
            }
            self.first += 1;
        }
    }
}

/// What a row's `l` reads, shared by the row tasks.
struct Rows<'a> {
    nch: usize,
    w: usize,
    h: usize,
    d_at: usize,
    layout: &'a KeptLayout,
    taps: &'a [f64],
    centre: f64,
    /// A four-neighbour's weight under the kernel over the centre's.
    cross: f64,
    input: &'a RowWindow<f32>,
}

impl Rows<'_> {
    /// Row `y`'s `l` into `out` (`[channel][x]`): whether it has any, and
    /// what it counted. `sure` is scratch.
    fn row(&self, y: usize, out: &mut [f64], sure: &mut [bool]) -> (bool, RestoreCounts) {
        let (nch, w, d_at) = (self.nch, self.w, self.d_at);
        let row = self.input.get(y);
        let mut c = RestoreCounts::default();
        let mut any = false;
        let reliable = self
            .layout
            .stats
            .as_ref()
            .filter(|_| self.layout.sure_keeps);
        if let Some(r) = reliable {
            r.mark(row, w, sure);
        }
        for ch in 0..nch {
            let l = &mut out[ch * w..(ch + 1) * w];
            if self.layout.copied[ch] {
                l.fill(0.0);
                continue;
            }
            let e = &row[ch * w..(ch + 1) * w];
            let offset = (d_at + ch) * w;
            let d = &row[offset..offset + w];
            let em = self.layout.emission[ch].map(|k| &row[k * w..(k + 1) * w]);
            // The rows above and below, for the share's lower bound.
            let (up, down) = (
                &self.input.get(reflect(y as isize - 1, self.h))[offset..offset + w],
                &self.input.get(reflect(y as isize + 1, self.h))[offset..offset + w],
            );
            // A lower bound of the denoiser's share around each pixel (its
            // own value and its four neighbours' under the kernel), in a
            // loop the compiler vectorises: a pixel within it (noise, the
            // common case) keeps nothing under any rule.
            bounds(d, (up, down), self.cross, l);
            for x in 0..w {
                let ev = f64::from(e[x]);
                l[x] = if ev <= 0.0 {
                    // A render's rare negative samples: nothing to scale a
                    // shape by.
                    ev
                } else if ev <= l[x] {
                    0.0
                } else {
                    let own = shape(d[x]);
                    self.pixel(
                        ev,
                        own,
                        (x, y),
                        ch,
                        (em, sure[x] && reliable.is_some()),
                        &mut c,
                    )
                };
                if l[x] != 0.0 {
                    any = true;
                    c.count(ev, l[x] == ev);
                    c.kept_energy += l[x].abs();
                }
            }
        }
        (any, c)
    }

    /// `l` of a pixel of energy `ev` over the denoiser's own `own`: the
    /// light beyond the denoiser's share around that the evidence speaks
    /// for (the guide's light, or all of it where its samples agree or the
    /// denoiser kept a peak), and what the gain keeps of the rest.
    fn pixel(
        &self,
        ev: f64,
        own: f64,
        (x, y): (usize, usize),
        ch: usize,
        (em, sure): (Option<&[f32]>, bool),
        c: &mut RestoreCounts,
    ) -> f64 {
        let offset = (self.d_at + ch) * self.w;
        // Measured once, for every rule that reads it.
        let mut q_at = None;
        let mut q = || {
            *q_at.get_or_insert_with(|| {
                around(self.input, (x, y), (self.w, self.h), offset, self.taps)
            })
        };
        let evidence = if em.is_some_and(|em| shape(em[x]) > 0.0) {
            Some(Evidence::Guide)
        } else if sure {
            Some(Evidence::Variance)
        } else if denoiser_peak(own, ring(self.input, (x, y), (self.w, self.h), offset)) {
            Some(Evidence::Denoiser)
        } else {
            None
        };
        // The denoiser has no light anywhere around (its kernel's reach):
        // nothing to shape this energy with, so it stays where it is.
        if evidence.is_none() && own == 0.0 && q() <= 0.0 {
            return ev;
        }
        let lit = match evidence {
            // The guide's light alone (the rest of the pixel is reflected
            // light, which no guide vouches for).
            Some(Evidence::Guide) => {
                let g = em.map_or(0.0, |em| shape(em[x]));
                kept(g, own, &mut q, self.centre, EMISSION_KEEP_GAIN).clamp(0.0, ev)
            }
            Some(_) => kept(ev, own, &mut q, self.centre, EMISSION_KEEP_GAIN).clamp(0.0, ev),
            None => 0.0,
        };
        let gained = self.layout.gain.map_or(0.0, |g| {
            kept(ev - lit, own, &mut q, self.centre, g).max(0.0)
        });
        if lit > 0.0 {
            match evidence {
                Some(Evidence::Guide) => c.kept_guide += 1,
                Some(Evidence::Variance) => c.kept_variance += 1,
                Some(Evidence::Denoiser) => c.kept_denoiser += 1,
                None => {}
            }
        }
        if gained > 0.0 {
            c.kept_gain += 1;
        }
        lit + gained
    }
}

/// Per pixel of the denoiser's row `d` (`up` and `down` the rows around,
/// reflected at the ends): its shape and `cross` times its four
/// neighbours', into `out`.
fn bounds(d: &[f32], (up, down): (&[f32], &[f32]), cross: f64, out: &mut [f64]) {
    let w = d.len();
    let at = |x: usize| {
        let (l, r) = (reflect(x as isize - 1, w), reflect(x as isize + 1, w));
        shape(d[x]) + cross * (shape(d[l]) + shape(d[r]) + shape(up[x]) + shape(down[x]))
    };
    if w < 3 {
        for (x, o) in out.iter_mut().enumerate() {
            *o = at(x);
        }
        return;
    }
    out[0] = at(0);
    out[w - 1] = at(w - 1);
    let inner = out[1..w - 1]
        .iter_mut()
        .zip(d.windows(3))
        .zip(up[1..].iter().zip(&down[1..]));
    for ((o, dd), (&u, &v)) in inner {
        *o = shape(dd[1]) + cross * (shape(dd[0]) + shape(dd[2]) + shape(u) + shape(v));
    }
}

/// The mean of the denoiser's shape over the eight pixels around `at`
/// (reflected at the edges), from the input rows' channel at `offset`.
fn ring(
    input: &RowWindow<f32>,
    (x, y): (usize, usize),
    (w, h): (usize, usize),
    offset: usize,
) -> f64 {
    let mut sum = 0.0;
    for dy in -1..=1isize {
        let d = &input.get(reflect(y as isize + dy, h))[offset..offset + w];
        for dx in -1..=1isize {
            if dx != 0 || dy != 0 {
                sum += shape(d[reflect(x as isize + dx, w)]);
            }
        }
    }
    sum / 8.0
}

/// The denoiser's energy around pixel `at` of a `size` image: its shape
/// under the 2-D kernel `taps x taps`, reflected at the edges, from the
/// input rows' channel at `offset`. Only for the few pixels whose energy
/// exceeds the denoiser's own value and that something vouches for.
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
