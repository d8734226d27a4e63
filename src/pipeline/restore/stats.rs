//! The render's own statistics (a variance pass and its sample count, as
//! `ep-box` finds them), read beside its energy: how sure each pixel's mean
//! is, for the evidence that keeps a pixel in place and for the
//! uncertainty of each block's energy.

use crate::filter::ep_box::{se2, StatsLayout};
use crate::filter::restore::RELIABLE_RSE;

/// The energy image's statistics and where its colour channels are.
#[derive(Clone, Debug)]
pub struct RenderStats {
    /// Where the statistics are in the energy's rows.
    stats: StatsLayout,
    /// The colour channels (luminance weight not 0) and their weights.
    colour: Vec<(usize, f64)>,
    /// The statistics' channels, read after the energy's.
    pub channels: Vec<String>,
}

impl RenderStats {
    /// The statistics at `stats` (in the energy's rows, after its channels
    /// of luminance weights `lum`), read from the channels `channels`.
    pub fn new(stats: StatsLayout, lum: &[f64], channels: Vec<String>) -> Self {
        let colour = (lum.iter().copied().enumerate())
            .filter(|(_, l)| *l != 0.0)
            .collect();
        RenderStats {
            stats,
            colour,
            channels,
        }
    }

    /// Pixel `x` of an energy row (`w` wide): its luminance, sample count
    /// and the squared standard error of its luminance.
    fn luminance(&self, row: &[f32], w: usize, x: usize) -> (f64, f64, f64) {
        let mut weights = [0.0f64; 3];
        for (wt, (_, l)) in weights.iter_mut().zip(&self.colour) {
            *wt = *l;
        }
        let y: f64 = (self.colour.iter())
            .map(|&(c, l)| l * f64::from(row[c * w + x]))
            .sum();
        let (n, se2) = self.stats.pixel(&weights, y, |i| f64::from(row[i * w + x]));
        (y, n, se2)
    }

    /// Per pixel of an energy row (`w` wide), whether its mean is sure: its
    /// relative standard error under [`RELIABLE_RSE`] (its samples agree).
    pub(super) fn mark(&self, row: &[f32], w: usize, sure: &mut [bool]) {
        for (x, s) in sure.iter_mut().enumerate().take(w) {
            let (y, n, se2) = self.luminance(row, w, x);
            *s = y > 0.0 && n >= 2.0 && se2 < (RELIABLE_RSE * y).powi(2);
        }
    }

    /// The variance of the mean of channel `ch` at pixel `x` of an energy
    /// row (`w` wide): from the channel's own variance where the pass has
    /// one per colour channel, else the luminance's in the channel's share
    /// of the luminance (a path bright in one channel is bright in all).
    /// `None` where the pass says nothing usable (no samples, a value that
    /// is not finite or below zero): the caller estimates it otherwise.
    pub(super) fn channel_var(&self, row: &[f32], w: usize, x: usize, ch: usize) -> Option<f64> {
        let k = self.colour.iter().position(|&(c, _)| c == ch)?;
        let v = if self.stats.variance.len() == self.colour.len() && self.colour.len() > 1 {
            let n = self.stats.samples(|i| f64::from(row[i * w + x]));
            let var = f64::from(row[self.stats.variance[k] * w + x]);
            let mean = f64::from(row[ch * w + x]);
            // A second moment per channel goes with the channel's mean.
            let kind = self.stats.kind;
            if !(n >= 1.0) || !var.is_finite() || var < 0.0 {
                return None;
            }
            se2(kind, &[var], &[1.0], mean, n)
        } else {
            let (y, n, se2) = self.luminance(row, w, x);
            if !(n >= 1.0) || !se2.is_finite() || se2 < 0.0 {
                return None;
            }
            let e = f64::from(row[ch * w + x]);
            if y > 0.0 {
                se2 * (e / y).powi(2)
            } else {
                se2
            }
        };
        (v.is_finite() && v >= 0.0).then_some(v)
    }
}
