//! Run: a [`FilterPlan`]'s first pass (ep-box's `L_ave`), the output's
//! settings, the stream (whole, or a band's window), the ledger check and the
//! commit. The report is made from the plan and the [`Outcome`] in
//! [`crate::report`].

use crate::error::{Error, Result, Side};
use crate::filter::Method;
use crate::host::cpu_seconds;
use crate::io::output::Output;
use crate::io::provenance;
use crate::io::OutputSettings;
use crate::pipeline::band::{BandSink, BandSource, FinishHook};
use crate::pipeline::edge::{Coverage, Cropped};
use crate::pipeline::ledger::ChannelLedger;
use crate::pipeline::{run, ChannelMode, Progress, RunStats};
use crate::report::{BandReport, Report, RunFacts};

use super::plan::{BandPlan, FilterPlan};
use super::LEDGER_LIMIT;

/// What a run did, beside its plan.
pub struct Outcome {
    /// The pipeline's counters, timings and ledger.
    pub stats: RunStats,
    /// The ledger, with the energy on disk where the output is lossy.
    pub ledger: Vec<ChannelLedger>,
    /// ep-box's first pass: the mean luminance.
    pub l_ave: Option<f64>,
    /// The settings the output records, in order.
    pub settings: Vec<(&'static str, serde_json::Value)>,
    /// The output's compression, by name.
    pub compression: String,
    /// The values on disk differ from those written (the ledger's energy on
    /// disk was decoded from the file).
    pub lossy: bool,
    /// A band's own rows and energies.
    pub band: Option<BandReport>,
}

impl FilterPlan<'_> {
    /// Filter the input into the output, check the ledger and put the
    /// output in place; the report of the run.
    pub fn run(mut self, progress: Progress<'_>) -> Result<Report> {
        // ep-box's first pass reads the input once before the stream: each
        // is half of the progress.
        let l_ave = self.first_pass(&|done, rows| progress(done, 2 * rows))?;
        let second = |done, rows| progress(rows + done, 2 * rows);
        let progress: Progress<'_> = if l_ave.is_some() { &second } else { progress };
        let settings = self.settings();
        let out_settings = self.output_settings(&settings);
        let mut output = self.layout.create(
            &self.job.output,
            self.job.output_format()?,
            self.job.params.supersample,
            &self.channels,
            &out_settings,
        )?;
        let (stats, band) = self.stream(&mut output, progress).map_err(|e| match e {
            Error::StreamValue { side, reason } => Error::Value {
                path: match side {
                    Side::Input | Side::SecondInput => self.job.input.clone(),
                    Side::Output => self.job.output.clone(),
                },
                reason,
            },
            e => e,
        })?;
        self.check_ledger(&stats)?;
        let mut ledger = stats.ledger.clone();
        if output.is_lossy() {
            // A lossy codec changed what was written: the energy on disk is
            // what the file decodes to.
            let sums = output.decoded_sums()?;
            let s2 = (self.job.params.supersample.pow(2)) as f64;
            for (l, sum) in ledger.iter_mut().zip(sums) {
                l.set_on_disk(sum * s2);
            }
        }
        if let Some(n) = output.note() {
            let note = format!("{}: {n}", self.job.output.display());
            self.warnings.push(note);
        }
        let outcome = Outcome {
            compression: output.compression_name(),
            lossy: output.is_lossy(),
            stats,
            ledger,
            l_ave,
            settings,
            band,
        };
        output.commit()?;
        Ok(report(&self, &outcome))
    }

    /// ep-box without `--ltvis`: `L_tvis = L_ave / N_MID` from a first pass
    /// over the input (Eq. 9).
    fn first_pass(&mut self, progress: Progress<'_>) -> Result<Option<f64>> {
        let ep = &self.params.ep_box;
        if self.params.method != Method::EpBox || ep.ltvis.is_some() {
            return Ok(None);
        }
        let mean = crate::pipeline::mean_luminance(
            self.source(),
            &self.pipe_job,
            self.pipeline.strip_rows,
            progress,
        )?;
        let l = crate::filter::ep_box::ltvis(mean, ep.nmid);
        if !(l.is_finite() && l > 0.0) {
            return Err(Error::Value {
                path: self.job.input.clone(),
                reason: format!(
                    "the mean luminance is {mean:e}, so L_tvis = L_ave / N_MID is not positive; give --ltvis"
                ),
            });
        }
        self.params.ep_box.ltvis = Some(l);
        Ok(Some(mean))
    }

    /// The input's samples the filter reads, from sample row `y`, in the
    /// run's window of blocks (ep-box's first pass decodes with no decoder
    /// thread: in batches of `READ_AHEAD_BYTES`, whatever `--max-memory`
    /// chose).
    fn source_from(&self, y: usize) -> Cropped<crate::io::reader::InputSource<'_>> {
        let g = &self.geometry;
        let source = (self.input.source_from(y)).with_batch_blocks(self.pipeline.window_blocks);
        Cropped::new(source, g.full_w, g.read_w, g.read_h)
    }

    fn source(&self) -> Cropped<crate::io::reader::InputSource<'_>> {
        self.source_from(0)
    }

    /// What the file and the report say about how they were made: the
    /// method's settings, each channel's sample type, and how the input was
    /// cut (a cropped run is the filtering of the cropped image).
    fn settings(&self) -> Vec<(&'static str, serde_json::Value)> {
        let job = self.job;
        let mut settings = self.params.settings();
        let types = crate::io::writer::types_name(self.layout.types());
        settings.push(("pixel_type", types.into()));
        if self.geometry.padded_from.is_some() {
            settings.push(("edge", "pad".into()));
        }
        if let Some(p) = &job.part {
            settings.push(("part", format!("{p:?}").into()));
        }
        if let Some(l) = &job.layer {
            settings.push(("layer", l.as_str().into()));
        }
        if !job.channel_rules.is_empty() {
            let rules: Vec<String> = job
                .channel_rules
                .iter()
                .map(|o| format!("{}={}", o.pattern(), o.rule.name()))
                .collect();
            settings.push(("channel_rules", rules.join(";").into()));
        }
        settings
    }

    /// The job's output settings with the provenance, the fingerprint and a
    /// band's label and (empty) ledger.
    fn output_settings(&self, settings: &[(&'static str, serde_json::Value)]) -> OutputSettings {
        let provenance = settings
            .iter()
            .map(|(k, v)| match v {
                serde_json::Value::String(s) => format!("{k}={s}"),
                v => format!("{k}={v}"),
            })
            .collect::<Vec<_>>()
            .join(" ");
        let mut out = OutputSettings {
            provenance: Some(provenance),
            write_ahead: self.pipe_job.write_ahead_bytes(&self.pipeline),
            ..self.job.output_settings.clone()
        };
        out.extra
            .push((provenance::FINGERPRINT.into(), self.fingerprint.text()));
        if let Some(plan) = &self.band {
            let s = self.job.params.supersample;
            out.extra.push((provenance::BAND.into(), plan.label(s)));
            out.extra.push((
                provenance::BAND_LEDGER.into(),
                provenance::band_ledger_text(&self.channels, &[], &[]),
            ));
        }
        out
    }

    /// `--edge pad`: what each output pixel of the file's rows `a..b` stands for.
    fn coverage(&self, a: usize, b: usize) -> Option<Coverage> {
        let real = self.geometry.padded_from?;
        let cov = Coverage::of(&self.params, self.pipe_job.grid, real);
        Some(Coverage {
            x: cov.x,
            y: cov.y[a..b].to_vec(),
        })
    }

    /// The stream into `output`: the whole image, or a band's window.
    fn stream(
        &self,
        output: &mut Output,
        progress: Progress<'_>,
    ) -> Result<(RunStats, Option<BandReport>)> {
        let out_h = self.geometry.h / self.job.params.supersample;
        let Some(plan) = &self.band else {
            if let Some(cov) = self.coverage(0, out_h) {
                output.set_coverage(cov);
            }
            let stats = run(
                self.source(),
                output,
                &self.pipe_job,
                &self.params,
                &self.pipeline,
                progress,
            )?;
            return Ok((stats, None));
        };
        if let Some(cov) = self.coverage(plan.a, plan.b) {
            output.set_coverage(cov);
        }
        let (stats, band) = self.stream_band(plan, output, progress)?;
        Ok((stats, Some(band)))
    }

    /// A band's run: the rows of its window in, its own rows out, with the
    /// energies of both in the file's band ledger.
    fn stream_band(
        &self,
        plan: &BandPlan,
        output: &mut Output,
        progress: Progress<'_>,
    ) -> Result<(RunStats, BandReport)> {
        let s = self.job.params.supersample;
        let g = &self.geometry;
        let mut window_job = self.pipe_job.clone();
        window_job.grid.in_h = (plan.wb - plan.wa) * s;
        // The window's real rows: all of them, or up to the input's end.
        window_job.padded_from = g
            .padded_from
            .map(|(rw, rh)| (rw, rh.min(plan.wb * s) - plan.wa * s));
        let src = BandSource::new(
            self.source_from(plan.wa * s),
            plan.wa * s,
            plan.wb * s,
            (plan.a * s, plan.b * s),
            g.read_w,
            self.channels.len(),
        );
        let owned_in = src.owned_sums();
        let hook_in = owned_in.clone();
        let names = self.channels.clone();
        let s2 = (s * s) as f64;
        let hook: FinishHook<&mut Output> = Box::new(move |out, sums_out| {
            let energy_in_owned = crate::pipeline::band::values(&hook_in);
            let out_e: Vec<f64> = sums_out.iter().map(|v| v * s2).collect();
            out.fill_attribute(
                provenance::BAND_LEDGER,
                provenance::band_ledger_text(&names, &energy_in_owned, &out_e),
            );
        });
        let mut sink = BandSink::new(
            output,
            plan.a - plan.wa,
            plan.b - plan.wa,
            g.w / s,
            self.channels.len(),
            hook,
        );
        if let Some(cov) = self.coverage(plan.a, plan.b) {
            sink.set_coverage(cov);
        }
        let stats = run(
            src,
            &mut sink,
            &window_job,
            &self.params,
            &self.pipeline,
            progress,
        )?;
        let energy_out_owned: Vec<f64> = sink.sums().iter().map(|v| v * s2).collect();
        let band = BandReport {
            index: plan.k,
            count: plan.n,
            rows: (plan.a, plan.b),
            window: (plan.wa, plan.wb),
            energy_in_owned: crate::pipeline::band::values(&owned_in),
            energy_out_owned,
        };
        Ok((stats, band))
    }

    /// The ledger must balance for every channel whose energy the method
    /// keeps: the foils lose energy by design (their ledger is reported, not
    /// enforced), and ids and masks take the nearest sample.
    fn check_ledger(&self, stats: &RunStats) -> Result<()> {
        for (l, mode) in stats.ledger.iter().zip(&self.pipe_job.modes) {
            if self.params.method.preserves_energy()
                && *mode != ChannelMode::Nearest
                && !(l.rel_error <= LEDGER_LIMIT)
            {
                return Err(Error::Ledger {
                    channel: l.channel.clone(),
                    rel_error: l.rel_error,
                });
            }
        }
        Ok(())
    }
}

/// The report of a run: what its plan settled and what the run did.
fn report(plan: &FilterPlan<'_>, outcome: &Outcome) -> Report {
    let (job, stats) = (plan.job, &outcome.stats);
    let g = &plan.geometry;
    let s = job.params.supersample;
    let pipe_job = &plan.pipe_job;
    let channel_rules = (plan.channels.iter())
        .zip(plan.input.channel_rules())
        .zip(&pipe_job.luminance)
        .map(|((c, r), &l)| {
            let name = match r {
                Some(r) => r.name(),
                None if l != 0.0 => "colour",
                None => "alpha",
            };
            (c.clone(), name.to_string())
        })
        .collect();
    let settings = (outcome.settings.iter())
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect();
    let run = RunFacts {
        layout: pipe_job,
        cfg: &plan.pipeline,
        params: &plan.params,
        stats,
        found: plan.found.as_ref(),
        l_ave: outcome.l_ave,
    };
    let mut report = Report {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        supersample_from: (plan.decided.verdict.as_ref())
            .map_or("--supersample".into(), |v| v.supersample_from.clone()),
        method_from: (plan.decided.verdict.as_ref())
            .map_or("--method".into(), |v| v.method_from.clone()),
        guides: plan.guides.describe(),
        width: g.read_w,
        height: g.read_h,
        out_width: g.w / s,
        out_height: g.h / s,
        channel_rules,
        channels: plan.channels.clone(),
        dropped_channels: plan.input.dropped_channels().to_vec(),
        megapixels_per_second: (g.w * g.h) as f64 / stats.seconds.max(1e-9) / 1e6,
        cpu_seconds: cpu_seconds().map(|c| c - plan.cpu_start),
        compression: outcome.compression.clone(),
        energy_on_disk_decoded: outcome.lossy,
        band: outcome.band.clone(),
        ..Report::of_run(&run, settings, plan.warnings.clone())
    };
    // The file's ledger: after rounding, what the file holds (a lossy
    // codec's decoded, a picture's RGBE), not the run's.
    report.memory_estimate_bytes = plan.memory_bytes;
    report.set_ledger(&outcome.ledger);
    report
}
