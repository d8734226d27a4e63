//! `epfilt filter`: the flags turned into the library's [`FilterJob`], one
//! file or a frame sequence run, and what the user is told.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::Result;
use epfilt::job::{Existing, FilterOptions};
use epfilt::sequence::{FramePattern, FrameStatus, SequenceJob};
use epfilt::FilterJob;

use crate::args::FilterArgs;
use crate::{
    check_binary_stdout, fail, image_pixels, progress_bar, read_stdin, usage, warn, write_report,
    Exit,
};

/// A frame's share of a sequence's progress bar, in steps.
const FRAME_STEPS: u64 = 1000;

/// Run `filter`: one file, or a frame sequence.
pub fn run(mut a: FilterArgs, cancel: Arc<AtomicBool>) -> Result<(), Exit> {
    if a.json {
        a.report = Some("-".into());
    }
    let (opts, given) = FilterOptions::from_settings(a.opts.settings.clone()).map_err(usage)?;
    let env = |k: &str| std::env::var(k).ok();
    if a.trace.is_some() && FramePattern::parse(&a.input).map_err(usage)?.is_some() {
        return Err(usage(anyhow::anyhow!(
            "--trace records the run of one file: filter one frame with it, not a sequence"
        )));
    }
    let epfilt::sequence::Share { band, task } = opts.share(&env).map_err(usage)?;
    let template = filter_job(&a, &opts, band, &given, cancel).map_err(usage)?;
    match opts.sequence(template.clone(), task).map_err(usage)? {
        Some(job) => sequence(&a, job),
        None => one_file(&a, opts.skip_existing, template),
    }
}

fn one_file(a: &FilterArgs, skip_existing: bool, job: FilterJob) -> Result<(), Exit> {
    check_binary_stdout(&a.output)?;
    // The output's name and folder, and the report's, now: not after a long run.
    epfilt::io::Destination::resolve(&a.output).map_err(fail)?;
    job.output_format().map_err(fail)?;
    for path in a.report.iter().chain(&a.trace) {
        epfilt::io::Destination::resolve(path).map_err(fail)?;
    }
    read_stdin(a.quiet, [job.input.as_path()]);
    let file = epfilt::io::InputFile::open(&job.input).map_err(fail)?;
    if skip_existing {
        match epfilt::job::existing_output(&job, &file).map_err(fail)? {
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
    let pixels = || {
        let i = file
            .input(job.part.as_ref(), job.layer.as_deref(), None)
            .ok()?;
        Some(i.size().0 as f64 * i.size().1 as f64)
    };
    let bar = progress_bar(a.quiet, pixels);
    let progress = |done: usize, total: usize| {
        if let Some(b) = &bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    };
    let session = a.trace.as_ref().map(|_| epfilt::trace::start());
    let report = epfilt::filter_opened(&job, &file, &progress);
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
fn filter_job(
    a: &FilterArgs,
    opts: &FilterOptions,
    band: Option<(usize, usize)>,
    given: &[String],
    cancel: Arc<AtomicBool>,
) -> Result<FilterJob> {
    if a.output.as_os_str() == "-" && a.report.as_deref() == Some(std::path::Path::new("-")) {
        anyhow::bail!("the output and --report cannot both be standard output");
    }
    let (job, warnings) = opts.job(a.input.clone(), a.output.clone(), band, given, Some(cancel))?;
    for w in &warnings {
        warn(w);
    }
    Ok(job)
}

/// The first frame's output says whether the folder and the format are
/// right, as for one file; and the report's path.
fn check_outputs(a: &FilterArgs, job: &SequenceJob) -> Result<(), Exit> {
    if let Some(&first) = job.frames.first() {
        let mut one = job.template.clone();
        one.output = job.output.path(first);
        epfilt::io::Destination::resolve(&one.output).map_err(fail)?;
        one.output_format().map_err(fail)?;
    }
    if let Some(path) = &a.report {
        epfilt::io::Destination::resolve(path).map_err(fail)?;
    }
    Ok(())
}

/// One bar for the whole sequence: each frame [`FRAME_STEPS`] steps of
/// it, the rate from the first frame's size, the ETA the sequence's.
fn sequence_bar(quiet: bool, job: &SequenceJob) -> Option<indicatif::ProgressBar> {
    let pixels = || {
        let first = job.input.path(*job.frames.first()?);
        let select = epfilt::io::Selection {
            part: job.template.part.clone(),
            layer: job.template.layer.clone(),
        };
        Some(image_pixels(&first, &select)? * job.frames.len() as f64)
    };
    progress_bar(quiet, pixels)
}

/// A frame sequence, or this task's share of it: each frame as `filter`
/// would do it, a line per frame, a summary, and exit 1 when any failed.
/// (Long: it reads as the command runs: frames, task, each frame, summary,
/// exit status; each step is a few lines.)
fn sequence(a: &FilterArgs, job: SequenceJob) -> Result<(), Exit> {
    use epfilt::sequence::run_sequence;
    check_outputs(a, &job)?;
    let n = job.frames.len();
    let bar = sequence_bar(a.quiet, &job);
    let position = std::sync::atomic::AtomicUsize::new(0);
    let progress = |done: usize, total: usize| {
        if let Some(b) = &bar {
            let k = position.load(std::sync::atomic::Ordering::Relaxed);
            b.set_length(n as u64 * FRAME_STEPS);
            b.set_position(
                k as u64 * FRAME_STEPS + (done * FRAME_STEPS as usize / total.max(1)) as u64,
            );
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
            position.store(k, std::sync::atomic::Ordering::Relaxed);
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
