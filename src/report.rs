//! Reports: the summary a run prints and the JSON `--report` writes.

use serde::Serialize;

use crate::filter::{FilterParams, Method};
use crate::host::peak_rss_bytes;
use crate::io::StatsChannels;
use crate::pipeline::{
    ChannelLedger, MemoryRun, MethodCounts, PipelineConfig, RunStats, StageSeconds, StripLayout,
    WindowUse,
};

/// Summary of one filtering run (the `--report` JSON).
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Input file.
    pub input: String,
    /// Output file.
    pub output: String,
    /// Method name.
    pub method: String,
    /// Super-sampling factor.
    pub supersample: usize,
    /// Where S came from: `--supersample`, the file's attribute, or pixel
    /// resolution by default ([`crate::io::verdict()`]).
    pub supersample_from: String,
    /// Why this method: `--method`, or what the file holds.
    pub method_from: String,
    /// The guide passes used (`none`, or each kind with its channels).
    pub guides: String,
    /// Input width (samples).
    pub width: usize,
    /// Input height (samples).
    pub height: usize,
    /// Output width (pixels).
    pub out_width: usize,
    /// Output height (pixels).
    pub out_height: usize,
    /// Written channels: the beauty's, then those carried beside it.
    pub channels: Vec<String>,
    /// What each written channel got: `colour` and `alpha` (the beauty's),
    /// or its rule (`additive`, `average`, `nearest`;
    /// [`crate::filter::channels`]).
    pub channel_rules: std::collections::BTreeMap<String, String>,
    /// Channels of the input that were not filtered nor written.
    pub dropped_channels: Vec<String>,
    /// Relation 14 tolerance (ep-gauss).
    pub tolerance: f64,
    /// Base radius (output pixels).
    pub radius: f64,
    /// Largest radius (output pixels).
    pub max_radius: f64,
    /// Wall time in seconds.
    pub seconds: f64,
    /// Input samples per second, in millions.
    pub megapixels_per_second: f64,
    /// Samples that failed the noise test (ep-gauss: super-samples; ep-box:
    /// pixels; 0 for the other methods).
    pub samples_noisy: u64,
    /// Of those, spread wider than the base kernel (ep-box: whose excess was
    /// spread).
    pub samples_spread: u64,
    /// Spread ones that still failed at the radius cap.
    pub samples_capped: u64,
    /// ep-gauss: noisy samples kept with the base kernel as parts of a
    /// feature (the support rule).
    pub samples_kept: u64,
    /// ep-gauss at S = 1: noisy pixels left as they were, no width up to
    /// --max-radius spreading their excess within the tolerance.
    pub samples_left: u64,
    /// Samples (pixels) whose emission guide set some light aside.
    pub samples_emissive: u64,
    /// ep-gauss: the width search's work, the luminance values the widths
    /// it tried need plus average weights applied (0 for the other methods).
    pub search_cost: u64,
    /// ep-gauss: widths the search decided on a lower bound of their
    /// average (`--bound-from`) instead of the average itself.
    pub search_bounded: u64,
    /// ep-gauss: weights the spreading wrote, per channel (0 for the others).
    pub spread_taps: u64,
    /// Per channel: sum of input values.
    pub energy_in: Vec<f64>,
    /// Per channel: sum of output values times S², before rounding.
    pub energy_out: Vec<f64>,
    /// Per channel: relative difference before rounding.
    pub energy_rel_error: Vec<f64>,
    /// Per channel: sum of output values as written, times S².
    pub energy_out_rounded: Vec<f64>,
    /// Per channel: relative difference after rounding.
    pub energy_rel_error_rounded: Vec<f64>,
    /// Digest of the unrounded output (equal digests: bit-identical results).
    pub digest: String,
    /// Accumulator tile width used (output pixels).
    pub tile: usize,
    /// Input rows per strip.
    pub strip_rows: usize,
    /// Strips the filter worked on at once (two: a strip's first passes
    /// beside the previous strip's later ones).
    pub strips_in_flight: usize,
    /// Blocks the reader decodes ahead at most where `--max-memory` set
    /// them (`None`: as many as the job's default window).
    pub window_blocks: Option<usize>,
    /// Bytes of output rows the writer held before it compressed them.
    pub write_ahead_bytes: usize,
    /// What the run was estimated to hold, with the strips and window
    /// chosen (checked against `--max-memory`; 0 where not estimated).
    pub memory_estimate_bytes: u64,
    /// Worker threads.
    pub threads: usize,
    /// Peak resident set size, where the platform tells it.
    pub peak_rss_bytes: Option<u64>,
    /// Every rolling window: its name, the most rows it held and the bytes of
    /// a row (the halo in practice).
    pub windows: Vec<WindowUse>,
    /// Bytes those windows held at most.
    pub window_bytes: u64,
    /// Seconds each stage was busy: read/decode, filter, encode/write.
    pub stage_seconds: StageSeconds,
    /// CPU seconds (user + system) the run used, where the platform tells it.
    pub cpu_seconds: Option<f64>,
    /// NaN/infinite input samples treated as zero (`--nonfinite zero`), per channel.
    pub nonfinite_zeroed: Vec<u64>,
    /// Where the first of them was: `[x, y]` in the data window, and its channel.
    pub first_nonfinite: Option<(usize, usize, String)>,
    /// Statistics channels read (ep-box), after `channels` in `nonfinite_zeroed`.
    pub stats_channels: Vec<String>,
    /// The ep-box run's settings and findings.
    pub ep_box: Option<EpBoxReport>,
    /// ep-gauss at S = 1: the per-pixel statistics its carriers rule read
    /// (`None`: the file has none, or `--support 0`).
    pub carriers_rule: Option<StatsReport>,
    /// epfilt's version.
    pub version: String,
    /// Every setting of the run's method, the output's sample type, the part
    /// and layer (also in the output's `software` attribute).
    pub settings: serde_json::Map<String, serde_json::Value>,
    /// The output's compression.
    pub compression: String,
    /// Whether that compression is lossy for the output's samples, so the
    /// "after rounding" energy is the sum of the decoded file (`--allow-lossy`).
    pub energy_on_disk_decoded: bool,
    /// What the user should know about the run (one line each).
    pub warnings: Vec<String>,
    /// `--band`: which rows this file holds, and their share of the energy.
    pub band: Option<BandReport>,
    /// A multi-part input: what became of every part, in the file's order
    /// (empty for a single-part input). With `--part all` the fields above
    /// are the first filtered part's.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<PartReport>,
}

/// What became of one part of a multi-part input.
#[derive(Clone, Debug, Serialize)]
pub struct PartReport {
    /// Its index in the input.
    pub index: usize,
    /// Its name.
    pub name: String,
    /// `filtered`, `copied` (bit for bit) or `left out`.
    pub action: String,
    /// Why it was left out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub why: Option<String>,
    /// The filtered part's own report.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub report: Option<Box<Report>>,
}

/// One band of a `--band` run.
#[derive(Clone, Debug, Serialize)]
pub struct BandReport {
    /// 1-based.
    pub index: usize,
    /// Bands in all.
    pub count: usize,
    /// Output rows `[first, end)` the file holds.
    pub rows: (usize, usize),
    /// Output rows the run read to filter them (the band and its margins).
    pub window: (usize, usize),
    /// Per channel, the energy of the input rows the band owns.
    pub energy_in_owned: Vec<f64>,
    /// Per channel, the energy (times S²) of the output rows it holds.
    pub energy_out_owned: Vec<f64>,
}

/// Which per-pixel statistics a run read.
#[derive(Clone, Debug, Serialize)]
pub struct StatsReport {
    /// Variance channels.
    pub variance_channels: Vec<String>,
    /// What they hold.
    pub variance_kind: String,
    /// Where the sample count came from.
    pub spp_from: String,
}

/// What an `ep-box` run used and found.
#[derive(Clone, Debug, Serialize)]
pub struct EpBoxReport {
    /// Mean luminance of the image (`None` when `--ltvis` was given).
    pub l_ave: Option<f64>,
    /// Visibility threshold (Eq. 9).
    pub l_tvis: f64,
    /// Allowed interval, in units of L_tvis.
    pub d: f64,
    /// N_MID of Eq. 9.
    pub nmid: f64,
    /// Confidence of the noise test.
    pub confidence: f64,
    /// Guard name.
    pub guard: String,
    /// Variance channels and what they hold.
    pub variance_channels: Vec<String>,
    /// sample, mean or moment.
    pub variance_kind: String,
    /// Where the sample count came from.
    pub spp_from: String,
    /// Confidence of the `stderr` guard's bound.
    pub guard_confidence: f64,
    /// Pixels the paper's test calls noisy whose mean rests on enough samples
    /// to be reliable (the `carriers` guard): not treated.
    pub reliable: u64,
    /// Noisy pixels the `range` guard left alone.
    pub guarded: u64,
    /// Pixels whose excess the `stderr` guard cut to what noise can explain.
    pub trimmed: u64,
    /// Noisy pixels with no converged pixel within the passes' reach (left alone).
    pub unresolved: u64,
    /// Most passes allowed.
    pub passes_allowed: usize,
    /// Most passes a pixel needed.
    pub passes_used: u64,
}

impl EpBoxReport {
    /// What ep-box used (`params`, its statistics `found`, the first pass's
    /// mean) and what its run `stats` counted.
    fn of(
        params: &FilterParams,
        found: &StatsChannels,
        l_ave: Option<f64>,
        stats: &RunStats,
    ) -> Self {
        let ep = &params.ep_box;
        let eb = stats.ep_box().unwrap_or_default();
        EpBoxReport {
            l_ave,
            l_tvis: ep.ltvis.unwrap_or(f64::NAN),
            d: ep.d,
            nmid: ep.nmid,
            confidence: ep.confidence,
            guard: ep.guard.name().into(),
            variance_channels: found.variance.clone(),
            variance_kind: found.kind.name().into(),
            spp_from: found.spp_from(),
            guard_confidence: ep.guard_confidence,
            reliable: eb.reliable,
            guarded: eb.guarded,
            trimmed: eb.trimmed,
            unresolved: eb.unresolved,
            passes_allowed: ep.passes,
            passes_used: eb.passes,
        }
    }
}

/// What a run was and did, for [`Report::of_run`].
pub struct RunFacts<'a> {
    /// The strips' layout.
    pub layout: &'a StripLayout,
    /// The pipeline's settings.
    pub cfg: &'a PipelineConfig,
    /// The method's.
    pub params: &'a FilterParams,
    /// What the run did.
    pub stats: &'a RunStats,
    /// The per-pixel statistics read, if any.
    pub found: Option<&'a StatsChannels>,
    /// ep-box's first pass: the mean luminance.
    pub l_ave: Option<f64>,
}

/// The method's own counts (noisy, spread, capped, kept): ep-gauss in
/// super-samples, ep-box in pixels.
fn method_counts(stats: &RunStats) -> (u64, u64, u64, u64) {
    match stats.method {
        MethodCounts::EpGauss(g) => (g.noisy, g.spread, g.capped, g.kept),
        MethodCounts::EpBox(b) => (b.noisy, b.spread, b.capped, 0),
        MethodCounts::Restore(r) => (0, 0, r.kept, 0),
        MethodCounts::Plain => (0, 0, 0, 0),
    }
}

impl Report {
    /// Add the run of another view of the same image (`--view all`): its
    /// channels, their ledger and rules, its counts, time and warnings join
    /// this one's; the digest lists each view's.
    pub fn add_view(&mut self, other: Report) {
        let samples = |r: &Report| r.megapixels_per_second * r.seconds;
        let total = samples(self) + samples(&other);
        self.seconds += other.seconds;
        self.megapixels_per_second = total / self.seconds.max(1e-9);
        self.cpu_seconds = self.cpu_seconds.zip(other.cpu_seconds).map(|(a, b)| a + b);
        self.samples_noisy += other.samples_noisy;
        self.samples_spread += other.samples_spread;
        self.samples_capped += other.samples_capped;
        self.samples_left += other.samples_left;
        self.samples_emissive += other.samples_emissive;
        self.samples_kept += other.samples_kept;
        self.search_cost += other.search_cost;
        self.search_bounded += other.search_bounded;
        self.spread_taps += other.spread_taps;
        self.energy_in.extend(other.energy_in);
        self.energy_out.extend(other.energy_out);
        self.energy_rel_error.extend(other.energy_rel_error);
        self.energy_out_rounded.extend(other.energy_out_rounded);
        self.energy_rel_error_rounded
            .extend(other.energy_rel_error_rounded);
        self.nonfinite_zeroed.extend(other.nonfinite_zeroed);
        self.channel_rules.extend(other.channel_rules);
        self.channels.extend(other.channels);
        // Left out: what no view's run wrote.
        let written = self.channels.clone();
        self.dropped_channels
            .retain(|d| other.dropped_channels.contains(d) && !written.contains(d));
        self.digest = format!("{},{}", self.digest, other.digest);
        self.peak_rss_bytes = self.peak_rss_bytes.max(other.peak_rss_bytes);
        self.warnings.extend(other.warnings);
        self.settings.insert("view".into(), "all".into());
    }

    /// The settings of an in-memory run, as a file's run records them.
    pub fn array_settings(
        settings: Vec<(&'static str, serde_json::Value)>,
    ) -> serde_json::Map<String, serde_json::Value> {
        settings
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect()
    }

    /// The report of an in-memory run ([`crate::job::array`]): the fields
    /// a file's run fills, with `<array>` for its files.
    pub fn of_array(
        layout: &StripLayout,
        cfg: &PipelineConfig,
        run: &MemoryRun,
        found: Option<&StatsChannels>,
        settings: serde_json::Map<String, serde_json::Value>,
        warnings: Vec<String>,
    ) -> Report {
        let facts = RunFacts {
            layout,
            cfg,
            params: &run.params,
            stats: &run.stats,
            found,
            l_ave: run.l_ave,
        };
        Report::of_run(&facts, settings, warnings)
    }

    /// What every run's report holds, from its layout, settings and
    /// counts; a file's run then says what its files and plan settled.
    pub fn of_run(
        run: &RunFacts<'_>,
        settings: serde_json::Map<String, serde_json::Value>,
        warnings: Vec<String>,
    ) -> Report {
        let (layout, params, stats) = (run.layout, run.params, run.stats);
        let g = layout.grid;
        let counts = method_counts(stats);
        let channel_rules = (layout.channels.iter())
            .zip(&layout.luminance)
            .map(|(c, &l)| {
                (
                    c.clone(),
                    if l != 0.0 { "colour" } else { "alpha" }.to_string(),
                )
            })
            .collect();
        let mut report = Report {
            input: "<array>".into(),
            output: "<array>".into(),
            method: params.method.name().into(),
            supersample: g.s,
            supersample_from: "given".into(),
            method_from: "given".into(),
            guides: "none".into(),
            width: g.in_w,
            height: g.in_h,
            out_width: g.in_w / g.s,
            out_height: g.in_h / g.s,
            channels: layout.channels.clone(),
            channel_rules,
            dropped_channels: Vec::new(),
            tolerance: params.tolerance,
            radius: params.radius,
            max_radius: params.max_radius,
            seconds: stats.seconds,
            megapixels_per_second: (g.in_w * g.in_h) as f64 / stats.seconds.max(1e-9) / 1e6,
            samples_noisy: counts.0,
            samples_spread: counts.1,
            samples_capped: counts.2,
            samples_kept: counts.3,
            samples_left: stats.ep_gauss().map_or(0, |g| g.beyond),
            samples_emissive: stats.ep_gauss().map_or(0, |g| g.emissive),
            search_cost: stats.ep_gauss().map_or(0, |g| g.search_cost),
            search_bounded: stats.ep_gauss().map_or(0, |g| g.bounded),
            spread_taps: stats.ep_gauss().map_or(0, |g| g.spread_taps),
            energy_in: vec![],
            energy_out: vec![],
            energy_rel_error: vec![],
            energy_out_rounded: vec![],
            energy_rel_error_rounded: vec![],
            digest: format!("{:016x}", stats.digest),
            tile: run.cfg.tile,
            strip_rows: layout.strip_rows(run.cfg),
            strips_in_flight: crate::pipeline::strips_in_flight(run.cfg, params.method, g.s),
            window_blocks: (run.cfg.window_blocks > 0).then_some(run.cfg.window_blocks),
            write_ahead_bytes: layout.write_ahead_bytes(run.cfg),
            memory_estimate_bytes: 0,
            threads: run.cfg.workers(),
            peak_rss_bytes: peak_rss_bytes(),
            windows: stats.windows.clone(),
            window_bytes: stats.window_bytes(),
            stage_seconds: stats.stages,
            cpu_seconds: None,
            nonfinite_zeroed: stats.nonfinite_zeroed.clone(),
            first_nonfinite: stats.first_nonfinite.map(|(x, y, c)| {
                let name = layout.channels.iter().chain(&layout.aux).nth(c);
                (x, y, name.cloned().unwrap_or_default())
            }),
            stats_channels: layout.aux.clone(),
            ep_box: (run.found)
                .filter(|_| params.method == Method::EpBox)
                .map(|f| EpBoxReport::of(params, f, run.l_ave, stats)),
            carriers_rule: (run.found)
                .filter(|_| params.method == Method::EpGauss)
                .map(|f| StatsReport {
                    variance_channels: f.variance.clone(),
                    variance_kind: f.kind.name().into(),
                    spp_from: f.spp_from(),
                }),
            version: env!("CARGO_PKG_VERSION").into(),
            settings,
            compression: "none".into(),
            energy_on_disk_decoded: false,
            warnings,
            band: None,
            parts: Vec::new(),
        };
        report.set_ledger(&stats.ledger);
        report
    }

    /// Fill the ledger fields from per-channel ledger lines.
    pub fn set_ledger(&mut self, ledger: &[ChannelLedger]) {
        self.energy_in = ledger.iter().map(|l| l.energy_in).collect();
        self.energy_out = ledger.iter().map(|l| l.energy_out).collect();
        self.energy_rel_error = ledger.iter().map(|l| l.rel_error).collect();
        self.energy_out_rounded = ledger.iter().map(|l| l.energy_out_rounded).collect();
        self.energy_rel_error_rounded = ledger.iter().map(|l| l.rel_error_rounded).collect();
    }

    /// The summary's ledger: a line per channel of light. Data carried as
    /// read (normals, depth, ids) is out of the ledger: its zeros would read
    /// as a channel of no light, and it is listed with the carried channels.
    fn ledger_lines(&self) -> String {
        let mut s = String::new();
        let data = |c: &String| {
            let rule = self.channel_rules.get(c).map(String::as_str);
            matches!(rule, Some("average" | "nearest"))
        };
        let light: Vec<usize> = (0..self.channels.len())
            .filter(|&k| !data(&self.channels[k]))
            .collect();
        let wide = light.iter().map(|&k| self.channels[k].len()).max();
        let wide = wide.unwrap_or(0).max(8);
        s.push_str(&format!(
            "  energy ledger   {:<wide$} {:>13} {:>13}  {:>9}   after rounding\n",
            "channel", "in", "out x S^2", "rel.err"
        ));
        for &k in &light {
            s.push_str(&format!(
                "                  {:<wide$} {:>13.6e} {:>13.6e}  {:>9.2e}   {:>9.2e}\n",
                self.channels[k],
                self.energy_in[k],
                self.energy_out[k],
                self.energy_rel_error[k],
                self.energy_rel_error_rounded[k]
            ));
        }
        s
    }

    /// The human summary, a few lines.
    pub fn summary(&self) -> String {
        let filtered: Vec<&PartReport> = self.parts.iter().filter(|p| p.report.is_some()).collect();
        if filtered.len() > 1 {
            // --part all: each filtered part's summary, then the list.
            let mut s = String::new();
            for p in &filtered {
                if let Some(r) = &p.report {
                    s.push_str(&format!(
                        "part {} {:?}: {}",
                        p.index,
                        p.name,
                        r.own_summary()
                    ));
                }
            }
            s.push_str(&self.parts_list());
            return s;
        }
        let mut s = self.own_summary();
        s.push_str(&self.parts_list());
        s
    }

    /// What became of each part of a multi-part input, a line each.
    fn parts_list(&self) -> String {
        let mut s = String::new();
        if !self.parts.is_empty() {
            s.push_str("  parts of the input:\n");
        }
        for p in &self.parts {
            s.push_str(&format!(
                "    {} {:?}: {}{}\n",
                p.index,
                p.name,
                p.action,
                p.why
                    .as_ref()
                    .map(|w| format!(" ({w})"))
                    .unwrap_or_default()
            ));
        }
        s
    }

    /// How S and the method were decided and the guides used, as a line
    /// of the summary (empty where the user gave both and there are none).
    fn decided_line(&self) -> String {
        let given = |f: &str| f == "--supersample" || f == "--method" || f == "given";
        if given(&self.supersample_from) && given(&self.method_from) && self.guides == "none" {
            return String::new();
        }
        format!(
            "S: {}; method: {}; guides: {}\n  ",
            self.supersample_from, self.method_from, self.guides
        )
    }

    /// ep-box's lines of the summary: its statistics and what it did.
    fn ep_box_lines(&self, e: &EpBoxReport) -> String {
        let mut s = String::new();
        s.push_str(&format!(
            "  ep-box statistics: variance {} ({}), samples per pixel {}\n",
            e.variance_channels.join(", "),
            e.variance_kind,
            e.spp_from
        ));
        s.push_str(&format!(
            "  ep-box: L_tvis {:.4e}{}, D {}, {}% confidence, guard {}; reliable {}, noisy pixels {}, spread {}, guarded {}, trimmed {}, unresolved {}, passes {}\n",
            e.l_tvis,
            e.l_ave.map(|l| format!(" (L_ave {l:.4e})")).unwrap_or_default(),
            e.d,
            e.confidence * 100.0,
            e.guard,
            e.reliable,
            self.samples_noisy,
            self.samples_spread,
            e.guarded,
            e.trimmed,
            e.unresolved,
            e.passes_used
        ));
        if e.unresolved > 0 {
            let pixels = (self.out_width * self.out_height).max(1) as f64;
            s.push_str(&format!(
                "  note: {} noisy pixels ({:.1}% of the image) have no converged pixel within {} passes and are left as they are; \
                 more samples (see `epfilt plan`), more --passes or a larger --ltvis would reach them\n",
                e.unresolved,
                100.0 * e.unresolved as f64 / pixels,
                e.passes_allowed
            ));
        }

        s
    }

    /// This run's (or part's) summary: a line per fact, in the order they
    /// print.
    fn own_summary(&self) -> String {
        let mut s = format!(
            "{} -> {}: {} S={} {}x{} -> {}x{}\n  {}{:.2} s, {:.1} Mpx/s; noisy {} spread {} capped {}{}\n",
            self.input,
            self.output,
            self.method,
            self.supersample,
            self.width,
            self.height,
            self.out_width,
            self.out_height,
            self.decided_line(),
            self.seconds,
            self.megapixels_per_second,
            self.samples_noisy,
            self.samples_spread,
            self.samples_capped,
            if self.method == "ep-gauss" {
                let left = if self.supersample == 1 {
                    format!(" left (beyond --max-radius) {}", self.samples_left)
                } else {
                    String::new()
                };
                format!(" kept as features {}{left}", self.samples_kept)
            } else {
                String::new()
            }
        );
        s.push_str(&self.ledger_lines());
        if let Some(st) = &self.carriers_rule {
            s.push_str(&format!(
                "  carriers rule (S = 1): variance {} ({}), samples {}\n",
                st.variance_channels.join(", "),
                st.variance_kind,
                st.spp_from
            ));
        }
        if let Some(e) = &self.ep_box {
            s.push_str(&self.ep_box_lines(e));
        }
        if let Some(r) = self.peak_rss_bytes {
            s.push_str(&format!(
                "  peak RSS {:.1} MiB\n",
                r as f64 / (1 << 20) as f64
            ));
        }
        if self.nonfinite_zeroed.iter().any(|&n| n > 0) {
            let first = self
                .first_nonfinite
                .as_ref()
                .map(|(x, y, c)| format!(", first at ({x}, {y}) in {c}"))
                .unwrap_or_default();
            s.push_str(&format!(
                "  non-finite input samples treated as zero: {}{first}\n",
                self.channels
                    .iter()
                    .chain(&self.stats_channels)
                    .zip(&self.nonfinite_zeroed)
                    .map(|(c, n)| format!("{c} {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        let carried: Vec<String> = self
            .channels
            .iter()
            .filter_map(|c| {
                let r = self.channel_rules.get(c)?;
                (r != "colour" && r != "alpha").then(|| format!("{c} {r}"))
            })
            .collect();
        if !carried.is_empty() {
            s.push_str(&format!("  carried: {}\n", carried.join(", ")));
        }
        if !self.dropped_channels.is_empty() {
            s.push_str(&format!(
                "  not filtered (dropped): {}\n",
                self.dropped_channels.join(", ")
            ));
        }
        s
    }
}
