//! Running a sequence: each frame of a task filtered with the job template,
//! going on past a failed frame unless asked to stop, with a report of every
//! frame.

use super::{
    band_path, existing_output, filter_opened, Error, Existing, FilterJob, FramePattern, InputFile,
    Instant, Progress, Report, Task,
};
use crate::error::Result;
use serde::Serialize;

/// A sequence to filter: one job template, whose input and output paths are
/// replaced by each frame's.
#[derive(Clone, Debug)]
pub struct SequenceJob {
    /// Method, settings, pipeline and output settings for every frame.
    pub template: FilterJob,
    /// Input frames.
    pub input: FramePattern,
    /// Output frames.
    pub output: FramePattern,
    /// Every frame of the sequence, in order.
    pub frames: Vec<i64>,
    /// This process's share; `None`: every frame.
    pub task: Option<Task>,
    /// Leave frames whose output is already a complete output of their
    /// input and these settings ([`existing_output`]); redo the others.
    pub skip_existing: bool,
    /// Stop at the first failed frame (the rest are reported as not run).
    pub fail_fast: bool,
}

/// What became of one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameStatus {
    /// Filtered and written.
    Done,
    /// Its output was already a complete output of its input and the
    /// settings (`skip_existing`).
    Skipped,
    /// Its input is missing or damaged, or its output could not be written.
    Failed,
    /// Not attempted: an earlier frame failed under `fail_fast`.
    NotRun,
}

/// One frame's outcome, with its run's report (energy ledger included).
#[derive(Clone, Debug, Serialize)]
pub struct FrameOutcome {
    /// Frame number.
    pub frame: i64,
    /// Its input file.
    pub input: String,
    /// Its output file.
    pub output: String,
    /// Done, skipped, failed or not run.
    pub status: FrameStatus,
    /// Why it failed, as one line.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// `skip_existing` found a file at its output that was not a complete
    /// output of its input and the settings: why, and so it was redone.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub redone: Option<String>,
    /// The run's report (`done` frames).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub report: Option<Box<Report>>,
    /// Wall time in seconds.
    pub seconds: f64,
}

/// The whole task's report (the `--report` JSON of a sequence).
#[derive(Clone, Debug, Serialize)]
pub struct SequenceReport {
    /// Input pattern.
    pub input: String,
    /// Output pattern.
    pub output: String,
    /// Frames in the sequence (all tasks).
    pub frames_in_sequence: usize,
    /// This process's task, if any.
    pub task: Option<Task>,
    /// Frames done.
    pub done: usize,
    /// Frames skipped (their outputs were complete).
    pub skipped: usize,
    /// Frames redone although a file was at their output (it was not a
    /// complete output of their input and the settings).
    pub redone: usize,
    /// Frames that failed.
    pub failed: usize,
    /// Frames not run (after a failure, with fail-fast).
    pub not_run: usize,
    /// The largest relative energy error before rounding of the frames done.
    pub worst_ledger_error: f64,
    /// Wall time in seconds.
    pub seconds: f64,
    /// Each frame of the task, in order.
    pub frames: Vec<FrameOutcome>,
}

impl SequenceReport {
    /// One line for the end of a run.
    pub fn summary(&self) -> String {
        let task = self
            .task
            .as_ref()
            .map(|t| {
                format!(
                    " (task index {} of {} tasks, from {}: {} of {} frames)",
                    t.index,
                    t.count,
                    t.from,
                    self.frames.len(),
                    self.frames_in_sequence
                )
            })
            .unwrap_or_default();
        let not_run = if self.not_run > 0 {
            format!(", {} not run", self.not_run)
        } else {
            String::new()
        };
        let redone = if self.redone > 0 {
            format!(
                " ({} redone: a file was there that was not a complete output of its input and these settings)",
                self.redone
            )
        } else {
            String::new()
        };
        format!(
            "{} -> {}{task}: {} done{redone}, {} skipped, {} failed{not_run} in {:.2} s; worst ledger error {:.1e}\n",
            self.input,
            self.output,
            self.done,
            self.skipped,
            self.failed,
            self.seconds,
            self.worst_ledger_error
        )
    }
}

/// Where a frame is in its task, told to [`run_sequence`]'s listener when it
/// starts (`outcome: None`) and when it ends.
#[derive(Clone, Copy, Debug)]
pub struct FrameEvent<'a> {
    /// 0-based place in the task.
    pub position: usize,
    /// Frames in the task.
    pub of: usize,
    /// Frame number.
    pub frame: i64,
    /// How it ended; `None` at its start.
    pub outcome: Option<&'a FrameOutcome>,
}

/// Filter one frame (`input` into `output`, unless `--skip-existing` finds
/// it done) into `outcome`; only an interruption is an error.
fn run_frame(
    job: &SequenceJob,
    outcome: &mut FrameOutcome,
    input: std::path::PathBuf,
    output: std::path::PathBuf,
    progress: Progress<'_>,
) -> Result<()> {
    let mut fj = job.template.clone();
    fj.input = input.clone();
    fj.output = output;
    if !input.exists() {
        outcome.status = FrameStatus::Failed;
        outcome.error = Some(format!("{}: no such file", input.display()));
        return Ok(());
    }
    let file = match InputFile::open(&input) {
        Ok(file) => file,
        Err(e) => {
            outcome.status = FrameStatus::Failed;
            outcome.error = Some(crate::error::one_line(&e));
            return Ok(());
        }
    };
    let existing = if job.skip_existing {
        existing_output(&fj, &file)
    } else {
        Ok(Existing::Missing)
    };
    if let Err(e) = existing {
        outcome.status = FrameStatus::Failed;
        outcome.error = Some(crate::error::one_line(&e));
    } else if existing.as_ref().is_ok_and(|e| *e == Existing::Done) {
        outcome.status = FrameStatus::Skipped;
    } else {
        if let Ok(Existing::Redo(why)) = existing {
            outcome.redone = Some(why);
        }
        match filter_opened(&fj, &file, progress) {
            Ok(report) => {
                outcome.status = FrameStatus::Done;
                outcome.report = Some(Box::new(report));
            }
            Err(Error::Interrupted) => return Err(Error::Interrupted),
            Err(e) => {
                outcome.status = FrameStatus::Failed;
                outcome.error = Some(crate::error::one_line(&e));
            }
        }
    }
    Ok(())
}

/// Filter the task's frames in order. `on_frame` hears of each frame when it
/// starts (`None`) and ends (`Some`), with its place in the task;
/// `progress` is each frame's row progress. An interruption (the template's
/// cancel flag) ends the run with [`Error::Interrupted`]; any other error is
/// the frame's and the next frame goes on (unless `fail_fast`).
pub fn run_sequence(
    job: &SequenceJob,
    on_frame: &dyn Fn(FrameEvent<'_>),
    progress: Progress<'_>,
) -> Result<SequenceReport> {
    let start = Instant::now();
    let frames = match &job.task {
        Some(t) => t.chunk(&job.frames),
        None => &job.frames[..],
    };
    let mut outcomes = Vec::with_capacity(frames.len());
    let mut stop = false;
    for (k, &frame) in frames.iter().enumerate() {
        let input = job.input.path(frame);
        let output = match job.template.band {
            Some((b, n)) => band_path(&job.output.path(frame), b, n),
            None => job.output.path(frame),
        };
        let mut outcome = FrameOutcome {
            frame,
            input: input.display().to_string(),
            output: output.display().to_string(),
            status: FrameStatus::NotRun,
            error: None,
            redone: None,
            report: None,
            seconds: 0.0,
        };
        if stop {
            outcomes.push(outcome);
            continue;
        }
        on_frame(FrameEvent {
            position: k,
            of: frames.len(),
            frame,
            outcome: None,
        });
        let t = Instant::now();
        run_frame(job, &mut outcome, input, output, progress)?;
        outcome.seconds = t.elapsed().as_secs_f64();
        if outcome.status == FrameStatus::Failed && job.fail_fast {
            stop = true;
        }
        on_frame(FrameEvent {
            position: k,
            of: frames.len(),
            frame,
            outcome: Some(&outcome),
        });
        outcomes.push(outcome);
    }
    let count = |s: FrameStatus| outcomes.iter().filter(|o| o.status == s).count();
    let worst = outcomes
        .iter()
        .filter_map(|o| o.report.as_ref())
        .flat_map(|r| r.energy_rel_error.iter().map(|e| e.abs()))
        .fold(0.0, f64::max);
    Ok(SequenceReport {
        input: job.input.to_string(),
        output: job.output.to_string(),
        frames_in_sequence: job.frames.len(),
        task: job.task.clone(),
        done: count(FrameStatus::Done),
        skipped: count(FrameStatus::Skipped),
        redone: outcomes.iter().filter(|o| o.redone.is_some()).count(),
        failed: count(FrameStatus::Failed),
        not_run: count(FrameStatus::NotRun),
        worst_ledger_error: worst,
        seconds: start.elapsed().as_secs_f64(),
        frames: outcomes,
    })
}
