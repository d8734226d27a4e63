//! What each method counts, for the report: its own type per method.

/// What ep-gauss counted, in super-samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct SpreadCounts {
    /// Samples that failed Relation 14 at the base width.
    pub noisy: u64,
    /// Samples spread wider than the base kernel (m > 1).
    pub spread: u64,
    /// Samples spread at the cap because every narrower width failed
    /// Relation 14 (the cap itself is not evaluated: it may pass or fail).
    pub capped: u64,
    /// Noisy samples kept with the base kernel as parts of a feature (the
    /// support rule).
    pub kept: u64,
    /// The width search's work: the luminance values the widths it tried
    /// need (each counted once; it reads a few ahead) plus (folded) average
    /// weights applied.
    pub search_cost: u64,
    /// Widths the search decided on a lower bound of their average
    /// (`--bound-from`) instead of the average itself.
    pub bounded: u64,
    /// Weights the spreading wrote, per channel (the reflected kernels'
    /// areas, on the coarse grid for the coarse ones).
    pub spread_taps: u64,
    /// Samples spread on a coarser grid (`--coarse-from`), 2x or 4x.
    pub coarse: u64,
    /// Of those, the samples spread on the 4x coarser grid.
    pub coarse4: u64,
    /// At S = 1: noisy pixels left as they were because no width within
    /// the cap spreads their excess within the tolerance.
    pub beyond: u64,
    /// Samples whose emission guide set some light aside (never tested,
    /// never spread).
    pub emissive: u64,
}

impl std::ops::AddAssign for SpreadCounts {
    /// Counts of two runs of samples, together.
    fn add_assign(&mut self, o: SpreadCounts) {
        self.noisy += o.noisy;
        self.spread += o.spread;
        self.capped += o.capped;
        self.kept += o.kept;
        self.search_cost += o.search_cost;
        self.bounded += o.bounded;
        self.spread_taps += o.spread_taps;
        self.coarse += o.coarse;
        self.coarse4 += o.coarse4;
        self.beyond += o.beyond;
        self.emissive += o.emissive;
    }
}

/// What ep-box counted, in pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ExcessCounts {
    /// Pixels the noise test (and guards' carriers rule) calls noisy.
    pub noisy: u64,
    /// Noisy pixels whose excess was spread.
    pub spread: u64,
    /// Spread pixels whose excess did not fit under `L_tvis` per pixel within
    /// the radius.
    pub capped: u64,
    /// Pixels noisy by the paper's test whose mean rests on enough samples to
    /// be reliable (the `carriers` guard): not treated as noise.
    pub reliable: u64,
    /// Noisy pixels the `range` guard left alone.
    pub guarded: u64,
    /// Pixels whose excess the `stderr` guard cut to what noise can explain.
    pub trimmed: u64,
    /// Noisy pixels with no converged pixel within the passes' reach.
    pub unresolved: u64,
    /// The most passes any pixel needed.
    pub passes: u64,
}

/// What `epfilt restore` counted, in pixel channels.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct RestoreCounts {
    /// Pixel channels some of whose energy was kept in place (beyond what
    /// the denoiser put around them).
    pub kept: u64,
    /// Of them: on the emission guide's word.
    pub kept_guide: u64,
    /// On the render's variance (its samples agree).
    pub kept_variance: u64,
    /// Where the denoiser kept a peak.
    pub kept_denoiser: u64,
    /// By the keep gain (epfilt's output, or `--keep-gain`).
    pub kept_gain: u64,
    /// Where the denoiser had nothing around a pixel with energy that
    /// something vouched for: all of it kept in place.
    pub unshaped: u64,
    /// Negative energy values, kept in place.
    pub negative: u64,
    /// Blocks (per channel) with energy where the denoiser had no light:
    /// their energy stayed as it was.
    pub unshaped_blocks: u64,
    /// The energy kept in place (absolute, summed over channels).
    pub kept_energy: f64,
    /// The denoiser's non-finite values, zeroed (`--nonfinite zero`).
    pub denoised_nonfinite: u64,
    /// The denoiser's negative values (no light to shape with: taken as 0).
    pub denoised_negative: u64,
}

impl RestoreCounts {
    /// A pixel channel of energy `e` some of which was kept in place
    /// (`all`: all of it).
    pub fn count(&mut self, e: f64, all: bool) {
        if e < 0.0 {
            self.negative += 1;
        } else if all {
            self.unshaped += 1;
        } else {
            self.kept += 1;
        }
    }
}

impl std::ops::AddAssign for RestoreCounts {
    fn add_assign(&mut self, o: RestoreCounts) {
        self.kept += o.kept;
        self.kept_guide += o.kept_guide;
        self.kept_variance += o.kept_variance;
        self.kept_denoiser += o.kept_denoiser;
        self.kept_gain += o.kept_gain;
        self.unshaped += o.unshaped;
        self.negative += o.negative;
        self.unshaped_blocks += o.unshaped_blocks;
        self.kept_energy += o.kept_energy;
        self.denoised_nonfinite += o.denoised_nonfinite;
        self.denoised_negative += o.denoised_negative;
    }
}

/// What a method counted; each method its own type.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub enum MethodCounts {
    /// ep-gauss (§5.2): super-samples.
    EpGauss(SpreadCounts),
    /// ep-box (§5.1): pixels.
    EpBox(ExcessCounts),
    /// `epfilt restore`: pixel channels.
    Restore(RestoreCounts),
    /// The linear filters and the foils count nothing.
    Plain,
}
