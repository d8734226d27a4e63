//! Frame sequences and render-farm tasks: `render.####.exr` patterns, frame
//! specs (`1-100x2`, `3,4,10-20x5`), the task of an array job (Slurm,
//! Kubernetes Indexed Jobs, AWS Batch, or `--task-index`/`--task-count`) and a
//! runner that filters each frame of a task with one [`FilterJob`] template,
//! going on past a failed frame unless asked to stop.
//!
//! Every output is written whole or not at all (as for one file), so a task
//! that is retried after a crash redoes only what is missing when
//! `skip_existing` is set, and writes the same bytes when it is not.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::job::{existing_output, filter_file, Existing, FilterJob};
use crate::pipeline::Progress;
use crate::report::Report;

/// The most frames one spec may name: a typo such as `1-1000000000` is an
/// error, not a billion-entry list.
pub const MAX_FRAMES: usize = 1_000_000;

/// A path with one frame-number field: a run of `#` (one padded digit each,
/// `####` = 0001), or printf's `%d` / `%0Nd`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FramePattern {
    prefix: String,
    suffix: String,
    width: usize,
    /// As the user wrote it.
    text: String,
}

impl FramePattern {
    /// The pattern in `path`, `None` when it names one file (no `#`, no `%d`).
    /// Two frame fields, or a `%` field other than `%d`/`%0Nd`, are errors.
    pub fn parse(path: &Path) -> Result<Option<FramePattern>> {
        let Some(s) = path.to_str() else {
            return if path.to_string_lossy().contains('#') {
                Err(Error::Config(format!(
                    "{}: a frame pattern must be valid UTF-8",
                    path.display()
                )))
            } else {
                Ok(None)
            };
        };
        let mut fields = Vec::new(); // (start, end, width)
        let b = s.as_bytes();
        let mut i = 0;
        while i < b.len() {
            if b[i] == b'#' {
                let start = i;
                while i < b.len() && b[i] == b'#' {
                    i += 1;
                }
                fields.push((start, i, i - start));
                continue;
            }
            if b[i] == b'%' {
                let start = i;
                let mut j = i + 1;
                while j < b.len() && b[j].is_ascii_digit() {
                    j += 1;
                }
                if j < b.len() && b[j] == b'd' {
                    let digits = &s[i + 1..j];
                    let width = if digits.is_empty() {
                        1
                    } else if digits.starts_with('0') && digits.len() > 1 {
                        digits[1..].parse().unwrap_or(0)
                    } else {
                        return Err(Error::Config(format!(
                            "{s}: %{digits}d pads with spaces; write %0{digits}d for zero-padded frame numbers"
                        )));
                    };
                    if !(1..=18).contains(&width) {
                        return Err(Error::Config(format!(
                            "{s}: frame field {} must be 1 to 18 digits wide",
                            &s[start..=j]
                        )));
                    }
                    fields.push((start, j + 1, width));
                    i = j + 1;
                    continue;
                }
            }
            i += 1;
        }
        match fields.as_slice() {
            [] => Ok(None),
            [(start, end, width)] => {
                if *width > 18 {
                    return Err(Error::Config(format!(
                        "{s}: a frame field of {width} '#' is wider than 18 digits"
                    )));
                }
                Ok(Some(FramePattern {
                    prefix: s[..*start].to_string(),
                    suffix: s[*end..].to_string(),
                    width: *width,
                    text: s.to_string(),
                }))
            }
            _ => Err(Error::Config(format!(
                "{s}: more than one frame field (#### or %04d); a pattern has exactly one"
            ))),
        }
    }

    /// The file of `frame`: zero-padded to the field's width (wider numbers
    /// keep all their digits; negative ones get a leading `-`).
    pub fn path(&self, frame: i64) -> PathBuf {
        PathBuf::from(format!(
            "{}{}{}",
            self.prefix,
            pad(frame, self.width),
            self.suffix
        ))
    }

    /// The frame a path names, when it fits the pattern exactly (the number
    /// written as [`FramePattern::path`] writes it).
    pub fn frame_of(&self, path: &str) -> Option<i64> {
        let field = path
            .strip_prefix(&self.prefix)?
            .strip_suffix(&self.suffix)?;
        let digits = field.strip_prefix('-').unwrap_or(field);
        if digits.is_empty() || !digits.bytes().all(|c| c.is_ascii_digit()) {
            return None;
        }
        let frame: i64 = field.parse().ok()?;
        (pad(frame, self.width) == field).then_some(frame)
    }

    /// The frames whose files exist, in ascending order. The frame field must
    /// be in the file name (not in a folder's).
    pub fn on_disk(&self) -> Result<Vec<i64>> {
        let shown = self.to_string();
        // The folder is everything up to the prefix's last separator.
        let dir = match self.prefix.rfind('/') {
            Some(i) => &self.prefix[..=i],
            None => "",
        };
        if self.suffix.contains('/') {
            return Err(Error::Config(format!(
                "{shown}: the frame field is in a folder name; give the frames with --frames"
            )));
        }
        let read_dir = if dir.is_empty() {
            Path::new(".")
        } else {
            Path::new(dir)
        };
        let entries = std::fs::read_dir(read_dir).map_err(|source| Error::Io {
            path: read_dir.to_path_buf(),
            source,
        })?;
        let mut frames = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|source| Error::Io {
                path: read_dir.to_path_buf(),
                source,
            })?;
            let Some(name) = entry.file_name().to_str().map(str::to_string) else {
                continue;
            };
            if let Some(f) = self.frame_of(&format!("{dir}{name}")) {
                frames.push(f);
            }
        }
        frames.sort_unstable();
        frames.dedup();
        if frames.is_empty() {
            return Err(Error::Config(format!(
                "no file matches {shown} in {}",
                read_dir.display()
            )));
        }
        Ok(frames)
    }
}

impl std::fmt::Display for FramePattern {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

fn pad(frame: i64, width: usize) -> String {
    if frame < 0 {
        format!("-{:0width$}", frame.unsigned_abs())
    } else {
        format!("{frame:0width$}")
    }
}

/// The frames of a spec: comma-separated items, each a frame `N`, a range
/// `A-B` (descending when A > B), or a range with a step `A-BxK`; negative
/// frames are written `-5`, `-10--2`. Order is kept and repeats dropped.
pub fn parse_frames(spec: &str) -> Result<Vec<i64>> {
    let bad = |why: &str| Error::Config(format!("--frames {spec:?}: {why}"));
    let mut frames = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for item in spec.split(',') {
        let item = item.trim();
        if item.is_empty() {
            return Err(bad("an empty item"));
        }
        let (range, step) = match item.split_once(['x', 'X']) {
            Some((r, k)) => {
                let k: i64 = k
                    .trim()
                    .parse()
                    .map_err(|_| bad(&format!("step {k:?} is not a number")))?;
                if k < 1 {
                    return Err(bad("a step must be 1 or more"));
                }
                (r.trim(), k)
            }
            None => (item, 1),
        };
        // The range's '-' is the first one after the first character (which
        // may be the sign of the start).
        let (a, b) = match range
            .char_indices()
            .skip(1)
            .find(|&(_, c)| c == '-')
            .map(|(i, _)| i)
        {
            Some(i) => (&range[..i], &range[i + 1..]),
            None => (range, range),
        };
        let num = |t: &str| -> Result<i64> {
            t.trim()
                .parse()
                .map_err(|_| bad(&format!("{t:?} is not a frame number")))
        };
        let (a, b) = (num(a)?, num(b)?);
        let span = a.abs_diff(b) / step.unsigned_abs() + 1;
        if span > MAX_FRAMES as u64 || frames.len() as u64 + span > MAX_FRAMES as u64 {
            return Err(bad(&format!("more than {MAX_FRAMES} frames")));
        }
        for k in 0..span as i64 {
            let f = if a <= b { a + k * step } else { a - k * step };
            if seen.insert(f) {
                frames.push(f);
            }
        }
    }
    Ok(frames)
}

/// One task of an array job: the `index`-th of `count` contiguous chunks of
/// the frame list.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Task {
    /// 0-based.
    pub index: usize,
    /// How many tasks share the frames.
    pub count: usize,
    /// Where the index came from (`--task-index`, `SLURM_ARRAY_TASK_ID`, ...).
    pub from: String,
}

impl Task {
    /// The task's frames: chunk `index` of `count` near-equal contiguous
    /// chunks (the first `len % count` chunks one frame longer), so that the
    /// tasks together cover every frame once and neighbouring frames go to
    /// one task.
    pub fn chunk<'a>(&self, frames: &'a [i64]) -> &'a [i64] {
        let (n, c, i) = (frames.len(), self.count, self.index);
        let start = i * (n / c) + i.min(n % c);
        let len = n / c + usize::from(i < n % c);
        &frames[start..start + len]
    }
}

/// The task this process runs: `--task-index`/`--task-count` when given,
/// else the array job's environment (read through `env`): Slurm
/// (`SLURM_ARRAY_TASK_ID` less `SLURM_ARRAY_TASK_MIN`, divided by
/// `SLURM_ARRAY_TASK_STEP`; count `SLURM_ARRAY_TASK_COUNT`), Kubernetes
/// Indexed Jobs (`JOB_COMPLETION_INDEX`; count from `--task-count`), AWS
/// Batch (`AWS_BATCH_JOB_ARRAY_INDEX`, `AWS_BATCH_JOB_ARRAY_SIZE`). `None`:
/// not a task, every frame.
pub fn task_from(
    index: Option<usize>,
    count: Option<usize>,
    env: &dyn Fn(&str) -> Option<String>,
) -> Result<Option<Task>> {
    let var = |name: &str| -> Result<Option<i64>> {
        match env(name) {
            None => Ok(None),
            Some(v) if v.trim().is_empty() => Ok(None),
            Some(v) => v
                .trim()
                .parse()
                .map(Some)
                .map_err(|_| Error::Config(format!("{name}={v:?} is not a whole number"))),
        }
    };
    let task = |index: i64, count: Option<usize>, from: String, count_hint: &str| {
        let count = count.ok_or_else(|| {
            Error::Config(format!(
                "{from} is set but the number of tasks is not: give --task-count ({count_hint})"
            ))
        })?;
        if count == 0 {
            return Err(Error::Config("--task-count must be 1 or more".into()));
        }
        if index < 0 || index as u64 >= count as u64 {
            return Err(Error::Config(format!(
                "task index {index} (from {from}) is not below the task count {count}"
            )));
        }
        Ok(Some(Task {
            index: index as usize,
            count,
            from,
        }))
    };
    if let Some(i) = index {
        return task(
            i as i64,
            count,
            "--task-index".into(),
            "how many tasks share the frames",
        );
    }
    if let Some(id) = var("SLURM_ARRAY_TASK_ID")? {
        let min = var("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
        let step = var("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
        if (id - min) % step != 0 {
            return Err(Error::Config(format!(
                "SLURM_ARRAY_TASK_ID={id} is not MIN + k * STEP ({min} + k * {step}): \
                 for an array that is not a range, pass --task-index and --task-count"
            )));
        }
        let env_count = var("SLURM_ARRAY_TASK_COUNT")?.and_then(|c| usize::try_from(c).ok());
        return task(
            (id - min) / step,
            count.or(env_count),
            "SLURM_ARRAY_TASK_ID".into(),
            "SLURM_ARRAY_TASK_COUNT is missing",
        );
    }
    if let Some(i) = var("JOB_COMPLETION_INDEX")? {
        return task(
            i,
            count,
            "JOB_COMPLETION_INDEX".into(),
            "the Job's completions",
        );
    }
    if let Some(i) = var("AWS_BATCH_JOB_ARRAY_INDEX")? {
        let env_count = var("AWS_BATCH_JOB_ARRAY_SIZE")?.and_then(|c| usize::try_from(c).ok());
        return task(
            i,
            count.or(env_count),
            "AWS_BATCH_JOB_ARRAY_INDEX".into(),
            "AWS_BATCH_JOB_ARRAY_SIZE is missing",
        );
    }
    if count.is_some() {
        return Err(Error::Config(
            "--task-count needs --task-index, or an array job's index in the environment \
             (SLURM_ARRAY_TASK_ID, JOB_COMPLETION_INDEX, AWS_BATCH_JOB_ARRAY_INDEX)"
                .into(),
        ));
    }
    Ok(None)
}

/// The file of band `k` of `n` of an output: `.bandKofN` before the
/// extension (`beauty.0001.exr` -> `beauty.0001.band2of4.exr`), a name no
/// frame pattern takes for a frame and `merge` puts back together.
pub fn band_path(path: &Path, k: usize, n: usize) -> PathBuf {
    let tag = format!("band{k}of{n}");
    match (path.file_stem(), path.extension()) {
        (Some(stem), Some(ext)) => path.with_file_name(format!(
            "{}.{tag}.{}",
            stem.to_string_lossy(),
            ext.to_string_lossy()
        )),
        _ => PathBuf::from(format!("{}.{tag}", path.display())),
    }
}

/// What one process of a farm does: a band of the rows (K of N, from 1)
/// and a task's share of the frames.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Share {
    /// `K` of `N` bands, `K` from 1.
    pub band: Option<(usize, usize)>,
    /// The task's share of a sequence's frames.
    pub task: Option<Task>,
}

/// The band and the task of a run, from the flags and the array job's
/// environment (read through `env`), by one rule:
///
/// * `--band K/N` counts from 1 (band 1/4 is the first of four, as the
///   band files and `merge` say); `--band-index I --band-count N` counts
///   from 0, as `--task-index` and the array indices do;
/// * `--band env`, or `--band-count N` without an index, takes the index
///   (and, where the engine sets it, the count) from the array job's
///   environment as [`task_from`] does; the environment then picks the band,
///   not the frames: a sequence's task is every frame unless
///   `--task-index`/`--task-count` say otherwise;
/// * otherwise the environment picks the task, as before.
pub fn band_and_task(
    band: Option<&str>,
    band_index: Option<usize>,
    band_count: Option<usize>,
    task_index: Option<usize>,
    task_count: Option<usize>,
    env: &dyn Fn(&str) -> Option<String>,
) -> Result<Share> {
    let bad = |why: String| Error::Config(why);
    let from_env =
        band == Some("env") || (band.is_none() && band_index.is_none() && band_count.is_some());
    if band.is_some() && (band_index.is_some() || band_count.is_some()) {
        return Err(bad(
            "--band and --band-index/--band-count say the same thing twice: give one".into(),
        ));
    }
    let chosen = if from_env {
        let t = task_from(None, band_count, env)?.ok_or_else(|| {
            bad("--band env: no array job index in the environment (SLURM_ARRAY_TASK_ID, JOB_COMPLETION_INDEX, AWS_BATCH_JOB_ARRAY_INDEX); give --band K/N".into())
        })?;
        Some((t.index + 1, t.count))
    } else if let Some(i) = band_index {
        let n = band_count.ok_or_else(|| bad("--band-index needs --band-count".into()))?;
        if i >= n {
            return Err(bad(format!(
                "--band-index {i} is not below --band-count {n} (band indices count from 0)"
            )));
        }
        Some((i + 1, n))
    } else if let Some(spec) = band {
        let (k, n) = spec
            .split_once('/')
            .ok_or_else(|| bad(format!("--band {spec:?} is not K/N (or env)")))?;
        let num = |s: &str, what: &str| {
            s.trim()
                .parse::<usize>()
                .map_err(|_| bad(format!("--band {spec:?}: {what} is not a whole number")))
        };
        let (k, n) = (num(k, "K")?, num(n, "N")?);
        if k == 0 || k > n {
            return Err(bad(format!(
                "--band {spec}: K counts from 1 to N in K/N (1/{n} is the first band, {n}/{n} the last); --band-index counts from 0, like --task-index"
            )));
        }
        Some((k, n))
    } else {
        None
    };
    let task = if from_env {
        task_from(task_index, task_count, &|_| None)?
    } else {
        task_from(task_index, task_count, env)?
    };
    Ok(Share { band: chosen, task })
}

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
        let mut fj = job.template.clone();
        fj.input = input.clone();
        fj.output = output;
        let existing = if job.skip_existing && input.exists() {
            existing_output(&fj)
        } else {
            Ok(Existing::Missing)
        };
        if !input.exists() {
            outcome.status = FrameStatus::Failed;
            outcome.error = Some(format!("{}: no such file", input.display()));
        } else if let Err(e) = existing {
            outcome.status = FrameStatus::Failed;
            outcome.error = Some(crate::error::one_line(&e));
        } else if existing.as_ref().is_ok_and(|e| *e == Existing::Done) {
            outcome.status = FrameStatus::Skipped;
        } else {
            if let Ok(Existing::Redo(why)) = existing {
                outcome.redone = Some(why);
            }
            match filter_file(&fj, progress) {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(s: &str) -> FramePattern {
        FramePattern::parse(Path::new(s)).unwrap().unwrap()
    }

    #[test]
    fn bands_count_from_1_in_k_of_n_and_from_0_by_index_or_environment() {
        let none = env_of(&[]);
        let share = |b: Option<&str>, i, n, env: &dyn Fn(&str) -> Option<String>| {
            band_and_task(b, i, n, None, None, env)
        };
        assert_eq!(
            share(Some("3/8"), None, None, &none).unwrap().band,
            Some((3, 8))
        );
        assert_eq!(
            share(None, Some(2), Some(8), &none).unwrap().band,
            Some((3, 8))
        );
        for bad in ["0/8", "9/8", "3", "a/b"] {
            assert!(share(Some(bad), None, None, &none).is_err(), "{bad}");
        }
        assert!(share(None, Some(8), Some(8), &none).is_err());
        assert!(share(None, Some(1), None, &none).is_err());
        assert!(share(Some("1/2"), Some(0), Some(2), &none).is_err());
        assert!(share(Some("env"), None, None, &none).is_err());
        // From the array's environment: the band, and then not the frames.
        let slurm = env_of(&[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        let s = share(Some("env"), None, None, &slurm).unwrap();
        assert_eq!((s.band, s.task), (Some((3, 4)), None));
        let s = share(None, None, Some(4), &slurm).unwrap();
        assert_eq!(s.band, Some((3, 4)));
        // Without a band the environment is the task's, as before.
        let s = share(None, None, None, &slurm).unwrap();
        assert_eq!((s.band, s.task.map(|t| t.index)), (None, Some(2)));
    }

    #[test]
    fn band_files_are_named_apart_from_frames() {
        let p = pattern("out/beauty.####.exr");
        let band = band_path(&p.path(7), 2, 4);
        assert_eq!(band, PathBuf::from("out/beauty.0007.band2of4.exr"));
        assert_eq!(p.frame_of(band.to_str().unwrap()), None);
        assert_eq!(
            band_path(Path::new("plain"), 1, 2),
            PathBuf::from("plain.band1of2")
        );
    }

    #[test]
    fn hashes_and_printf_fields_pad_alike() {
        for p in ["a/render.####.exr", "a/render.%04d.exr"] {
            let p = pattern(p);
            assert_eq!(p.path(7), PathBuf::from("a/render.0007.exr"));
            assert_eq!(p.path(12345), PathBuf::from("a/render.12345.exr"));
            assert_eq!(p.path(-3), PathBuf::from("a/render.-0003.exr"));
            assert_eq!(p.frame_of("a/render.0007.exr"), Some(7));
            assert_eq!(p.frame_of("a/render.12345.exr"), Some(12345));
            assert_eq!(p.frame_of("a/render.-0003.exr"), Some(-3));
            // Not written the way the pattern writes it.
            assert_eq!(p.frame_of("a/render.007.exr"), None);
            assert_eq!(p.frame_of("a/render.00007.exr"), None);
            assert_eq!(p.frame_of("a/render.00a7.exr"), None);
            assert_eq!(p.frame_of("a/render.0007.exr.tmp"), None);
        }
        assert_eq!(pattern("f#.exr").path(3), PathBuf::from("f3.exr"));
        assert_eq!(pattern("f%d.exr").path(42), PathBuf::from("f42.exr"));
        assert_eq!(FramePattern::parse(Path::new("plain.exr")).unwrap(), None);
        assert_eq!(FramePattern::parse(Path::new("100%.exr")).unwrap(), None);
        for bad in ["a.##.b.##.exr", "a.%4d.exr", "a.%04d.%d.exr"] {
            assert!(FramePattern::parse(Path::new(bad)).is_err(), "{bad}");
        }
    }

    #[test]
    fn frame_specs() {
        assert_eq!(parse_frames("1-5").unwrap(), vec![1, 2, 3, 4, 5]);
        assert_eq!(parse_frames("1-10x3").unwrap(), vec![1, 4, 7, 10]);
        assert_eq!(parse_frames("1-100x2").unwrap().len(), 50);
        assert_eq!(parse_frames("3,4,10-20x5").unwrap(), vec![3, 4, 10, 15, 20]);
        assert_eq!(parse_frames("5-1x2").unwrap(), vec![5, 3, 1]);
        assert_eq!(parse_frames("-2-1").unwrap(), vec![-2, -1, 0, 1]);
        assert_eq!(parse_frames("-5--3").unwrap(), vec![-5, -4, -3]);
        assert_eq!(parse_frames("7").unwrap(), vec![7]);
        assert_eq!(parse_frames("1-3,2-4").unwrap(), vec![1, 2, 3, 4]);
        for bad in ["", "1-", "a-3", "1-5x0", "1-5x-1", "1,,2", "1-2000000"] {
            assert!(parse_frames(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn chunks_cover_every_frame_once_in_order() {
        for n in 0..30 {
            let frames: Vec<i64> = (0..n).collect();
            for count in 1..12 {
                let mut all = Vec::new();
                let mut longest = 0;
                let mut shortest = usize::MAX;
                for index in 0..count {
                    let t = Task {
                        index,
                        count,
                        from: String::new(),
                    };
                    let c = t.chunk(&frames);
                    longest = longest.max(c.len());
                    shortest = shortest.min(c.len());
                    all.extend_from_slice(c);
                }
                assert_eq!(all, frames, "{n} frames in {count} tasks");
                assert!(longest - shortest <= 1);
            }
        }
    }

    fn env_of(vars: &'static [(&'static str, &'static str)]) -> impl Fn(&str) -> Option<String> {
        move |k| {
            vars.iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn tasks_from_flags_and_each_engines_environment() {
        let none = env_of(&[]);
        assert_eq!(task_from(None, None, &none).unwrap(), None);
        let t = task_from(Some(2), Some(4), &none).unwrap().unwrap();
        assert_eq!((t.index, t.count), (2, 4));
        assert!(task_from(Some(2), None, &none).is_err());
        assert!(task_from(Some(4), Some(4), &none).is_err());
        assert!(task_from(None, Some(4), &none).is_err());

        let slurm = env_of(&[
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "5"),
        ]);
        let t = task_from(None, None, &slurm).unwrap().unwrap();
        assert_eq!(
            (t.index, t.count, t.from.as_str()),
            (3, 5, "SLURM_ARRAY_TASK_ID")
        );
        // Flags win over the environment.
        let t = task_from(Some(0), Some(2), &slurm).unwrap().unwrap();
        assert_eq!((t.index, t.count), (0, 2));
        let off_grid = env_of(&[
            ("SLURM_ARRAY_TASK_ID", "4"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "5"),
        ]);
        assert!(task_from(None, None, &off_grid).is_err());

        let k8s = env_of(&[("JOB_COMPLETION_INDEX", "3")]);
        let e = task_from(None, None, &k8s).unwrap_err().to_string();
        assert!(e.contains("--task-count"), "{e}");
        let t = task_from(None, Some(8), &k8s).unwrap().unwrap();
        assert_eq!((t.index, t.count), (3, 8));

        let aws = env_of(&[
            ("AWS_BATCH_JOB_ARRAY_INDEX", "9"),
            ("AWS_BATCH_JOB_ARRAY_SIZE", "10"),
        ]);
        let t = task_from(None, None, &aws).unwrap().unwrap();
        assert_eq!((t.index, t.count), (9, 10));
        let garbage = env_of(&[("JOB_COMPLETION_INDEX", "x")]);
        assert!(task_from(None, Some(2), &garbage).is_err());
    }
}
