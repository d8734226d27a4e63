//! `epfilt filter`: the flags turned into the library's [`FilterJob`], one
//! file or a frame sequence run, and what the user is told.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::{Context, Result};
use clap::parser::ValueSource;
use epfilt::filter::channels::RuleOverride;
use epfilt::io::{parse_compression, Format, OutputSettings, PartSelect, ViewSelect};
use epfilt::job::Existing;
use epfilt::pipeline::NonFinite;
use epfilt::sequence::{FramePattern, FrameStatus, SequenceJob};
use epfilt::{FilterJob, FilterParams, Method, PipelineConfig, Precision};

use crate::args::{FilterArgs, METHOD_OPTIONS};
use crate::{
    cap_threads, check_binary_stdout, ep_box_params, fail, progress_bar, stats_request, usage,
    warn, write_report, Exit,
};

/// The method options the user gave (on the command line or in the
/// environment), as clap names them.
pub fn given_options(m: &clap::ArgMatches) -> Vec<String> {
    METHOD_OPTIONS
        .iter()
        .filter(|id| {
            matches!(
                m.value_source(id),
                Some(ValueSource::CommandLine | ValueSource::EnvVariable)
            )
        })
        .map(|id| id.to_string())
        .collect()
}

/// Run `filter`: one file, or a frame sequence.
pub fn run(a: FilterArgs, given: &[String], cancel: Arc<AtomicBool>) -> Result<(), Exit> {
    let input_pattern = FramePattern::parse(&a.input).map_err(usage)?;
    let output_pattern = FramePattern::parse(&a.output).map_err(usage)?;
    let env = |k: &str| std::env::var(k).ok();
    let epfilt::sequence::Share { band, task } = epfilt::sequence::band_and_task(
        a.band.as_deref(),
        a.band_index,
        a.band_count,
        a.task_index,
        a.task_count,
        &env,
    )
    .map_err(usage)?;
    let template = filter_job(&a, band, given, cancel).map_err(usage)?;
    match (input_pattern, output_pattern) {
        (Some(i), Some(o)) => return sequence(&a, template, i, o, task),
        (Some(i), None) => {
            return Err(usage(anyhow::anyhow!(
                "the input {i} is a frame sequence: give the output a frame field too (e.g. out/render.####.exr)"
            )))
        }
        (None, Some(o)) => {
            return Err(usage(anyhow::anyhow!(
                "the output {o} has a frame field but the input {} does not",
                a.input.display()
            )))
        }
        (None, None) => {}
    }
    if a.frames.is_some() || a.task_index.is_some() || a.task_count.is_some() {
        return Err(usage(anyhow::anyhow!(
            "--frames, --task-index and --task-count need a frame sequence (render.####.exr)"
        )));
    }
    one_file(&a, template)
}

fn one_file(a: &FilterArgs, job: FilterJob) -> Result<(), Exit> {
    check_binary_stdout(&a.output)?;
    // The output's name and folder, and the report's, now: not after a long run.
    epfilt::io::Destination::resolve(&a.output).map_err(fail)?;
    job.output_format().map_err(fail)?;
    for path in a.report.iter().chain(&a.trace) {
        epfilt::io::Destination::resolve(path).map_err(fail)?;
    }
    if a.skip_existing {
        match epfilt::job::existing_output(&job).map_err(fail)? {
            Existing::Done => {
                if !a.quiet {
                    eprintln!(
                        "{}: a complete output of this input and these settings exists, skipped (--skip-existing)",
                        a.output.display()
                    );
                }
                return Ok(());
            }
            Existing::Redo(why) if !a.quiet => {
                eprintln!("{}: {why}: redone", a.output.display());
            }
            _ => {}
        }
    }
    let bar = progress_bar(a.quiet);
    let progress = |done: usize, total: usize| {
        if let Some(b) = &bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    };
    let session = a.trace.as_ref().map(|_| epfilt::trace::start());
    let report = epfilt::filter_file(&job, &progress);
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let events = session.map(|s| s.finish());
    let report = report.map_err(fail)?;
    if let (Some(path), Some(events)) = (&a.trace, &events) {
        epfilt::trace::write(path, events).map_err(fail)?;
    }
    for w in &report.warnings {
        warn(w);
    }
    if let Some(path) = &a.report {
        write_report(path, &report)?;
    }
    if !a.quiet {
        eprint!("{}", report.summary());
    }
    Ok(())
}

/// The filter job the arguments describe (every check that needs no file);
/// options the method does not read are warned about.
/// (Long: one field of `FilterJob` per option group, in `--help` order; in
/// pieces it would be the same list, harder to check against the options.)
fn filter_job(
    a: &FilterArgs,
    band: Option<(usize, usize)>,
    given: &[String],
    cancel: Arc<AtomicBool>,
) -> Result<FilterJob> {
    let method = Method::parse(&a.method)?;
    let s = a
        .supersample
        .unwrap_or(if method == Method::EpBox { 1 } else { 3 });
    let mut params = FilterParams::new(method, s);
    if let Some(q) = &a.quality {
        let q = epfilt::filter::Quality::parse(q)?;
        if method == Method::EpGauss {
            params = params.with_quality(q);
        }
    }
    params.ep_box = epfilt::filter::ep_box::EpBoxParams {
        ltvis: a.ltvis,
        passes: a.passes,
        guard: epfilt::filter::ep_box::Guard::parse(&a.guard)?,
        guard_confidence: a.guard_confidence,
        carriers: a.carriers,
        carriers_fraction: a.carriers_fraction,
        carriers_rse: a.carriers_rse,
        ..ep_box_params(&a.stats)?
    };
    if let Some(r) = a.radius {
        params.radius = r;
    }
    if let Some(c) = a.cutoff {
        params.cutoff = c;
    }
    if let Some(n) = a.support {
        params.support = n;
    }
    if a.guard == "none" {
        params.support = 0;
    }
    if let Some(r) = a.support_ratio {
        params.support_ratio = r;
    }
    if let Some(n) = a.support_group {
        params.support_group = n;
    }
    if let Some(n) = a.support_compact {
        params.support_compact = n;
    }
    if let Some(o) = a.support_over {
        params.support_over = o;
    }
    if let Some(n) = a.support_region {
        params.support_region = n;
    }
    if let Some(l) = a.support_level {
        params.support_level = l;
    }
    params.clamp = a.clamp;
    params.alpha = a.alpha;
    if let Some(r) = a.max_radius {
        params.max_radius = r;
    }
    if let Some(w) = a.width_step {
        params.width_step = w;
    }
    params.coarse_from = a.coarse_from;
    if let Some(t) = a.tolerance {
        params.tolerance = t;
    }
    params.validate()?;
    for option in given.iter().filter(|o| !params.reads(o)) {
        warn(&format!(
            "--{} has no effect with --method {}{}",
            option.replace('_', "-"),
            method.name(),
            if method == Method::EpGauss {
                format!(" at S = {s}")
            } else {
                String::new()
            }
        ));
    }
    let precision = match a.pixel_type.as_str() {
        "same" => None,
        "f32" | "float" => Some(Precision::F32),
        "f16" | "half" => Some(Precision::F16),
        other => anyhow::bail!("--pixel-type must be same, f32 or f16, not {other:?}"),
    };
    let compression = match &a.compression {
        Some(c) => {
            Some(parse_compression(c).with_context(|| format!("unknown --compression {c:?}"))?)
        }
        None => None,
    };
    if a.output.as_os_str() == "-" && a.report.as_deref() == Some(std::path::Path::new("-")) {
        anyhow::bail!("the output and --report cannot both be standard output");
    }
    Ok(FilterJob {
        input: a.input.clone(),
        output: a.output.clone(),
        params,
        pipeline: PipelineConfig {
            tile: a.tile,
            strip_rows: a.strip_rows,
            threads: cap_threads(a.threads),
            cancel: Some(cancel),
            nonfinite: match a.nonfinite.as_str() {
                "error" => NonFinite::Error,
                "zero" => NonFinite::Zero,
                other => anyhow::bail!("--nonfinite must be error or zero, not {other:?}"),
            },
        },
        output_settings: OutputSettings {
            compression,
            precision,
            allow_lossy: a.allow_lossy,
            provenance: None,
            extra: Vec::new(),
        },
        part: a.part.as_deref().map(PartSelect::parse),
        layer: a.layer.clone(),
        max_memory: a.max_memory.map(|m| m.saturating_mul(1 << 20)),
        stats: stats_request(&a.stats)?,
        edge: match &a.edge {
            Some(e) => epfilt::job::Edge::parse(e)?,
            None => epfilt::job::Edge::Exact,
        },
        supersample_assumed: a.supersample.is_none() && s > 1,
        band,
        channel_rules: a
            .channel_rule
            .iter()
            .map(|r| RuleOverride::parse(r))
            .collect::<Result<_, _>>()?,
        format: a.format.as_deref().map(Format::parse).transpose()?,
        view: a.view.as_deref().map(ViewSelect::parse),
    })
}

/// A frame sequence, or this task's share of it: each frame as `filter`
/// would do it, a line per frame, a summary, and exit 1 when any failed.
/// (Long: it reads as the command runs: frames, task, each frame, summary,
/// exit status; each step is a few lines.)
fn sequence(
    a: &FilterArgs,
    template: FilterJob,
    input: FramePattern,
    output: FramePattern,
    task: Option<epfilt::sequence::Task>,
) -> Result<(), Exit> {
    use epfilt::sequence::{parse_frames, run_sequence};
    if input.to_string() == output.to_string() {
        return Err(usage(anyhow::anyhow!(
            "the output pattern {output} is the input's: each frame would overwrite its input"
        )));
    }
    if a.trace.is_some() {
        return Err(usage(anyhow::anyhow!(
            "--trace records the run of one file: filter one frame with it, not a sequence"
        )));
    }
    let frames = match &a.frames {
        Some(spec) => parse_frames(spec).map_err(usage)?,
        None => input.on_disk().map_err(usage)?,
    };
    // The first frame's output says whether the folder and the format are
    // right, as for one file.
    if let Some(&first) = frames.first() {
        let mut one = template.clone();
        one.output = output.path(first);
        epfilt::io::Destination::resolve(&one.output).map_err(fail)?;
        one.output_format().map_err(fail)?;
    }
    if let Some(path) = &a.report {
        epfilt::io::Destination::resolve(path).map_err(fail)?;
    }
    let job = SequenceJob {
        template,
        input,
        output,
        frames,
        task,
        skip_existing: a.skip_existing,
        fail_fast: a.fail_fast,
    };
    let bar = progress_bar(a.quiet);
    let progress = |done: usize, total: usize| {
        if let Some(b) = &bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    };
    let quiet = a.quiet;
    let say = |line: String| match &bar {
        Some(b) => b.println(line),
        None => eprintln!("{line}"),
    };
    let on_frame = |e: epfilt::sequence::FrameEvent<'_>| {
        let (k, n, frame) = (e.position, e.of, e.frame);
        let Some(o) = e.outcome else {
            if let Some(b) = &bar {
                b.set_message(format!("frame {frame} [{}/{n}]", k + 1));
            }
            return;
        };
        // Warnings about the data, even under -q.
        for w in o.report.iter().flat_map(|r| &r.warnings) {
            say(format!("epfilt: warning: frame {frame}: {w}"));
        }
        let redone = o
            .redone
            .as_ref()
            .map(|why| format!(" (redone: the file there was not a complete output of this input and these settings: {why})"))
            .unwrap_or_default();
        let line = match o.status {
            FrameStatus::Failed => {
                format!(
                    "epfilt: frame {frame}: {}",
                    o.error.as_deref().unwrap_or("failed")
                )
            }
            _ if quiet => return,
            FrameStatus::Skipped => format!(
                "frame {frame} [{}/{n}]: {} is complete, skipped",
                k + 1,
                o.output
            ),
            FrameStatus::Done => {
                let worst = o.report.as_ref().map_or(0.0, |r| {
                    r.energy_rel_error
                        .iter()
                        .fold(0.0f64, |m, e| m.max(e.abs()))
                });
                format!(
                    "frame {frame} [{}/{n}]: {} in {:.2} s, ledger {worst:.1e}{redone}",
                    k + 1,
                    o.output,
                    o.seconds
                )
            }
            FrameStatus::NotRun => return,
        };
        say(line);
    };
    let report = run_sequence(&job, &on_frame, &progress);
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let report = report.map_err(fail)?;
    if let Some(path) = &a.report {
        write_report(path, &report)?;
    }
    if !a.quiet {
        eprint!("{}", report.summary());
    }
    if report.failed > 0 {
        return Err(fail(anyhow::anyhow!(
            "{} of {} frames failed{}",
            report.failed,
            report.frames.len(),
            if report.not_run > 0 {
                format!(" ({} not run: --fail-fast)", report.not_run)
            } else {
                String::new()
            }
        )));
    }
    Ok(())
}
