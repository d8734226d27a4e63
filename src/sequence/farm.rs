//! The task of an array job: which frames (or which band of one frame) this
//! process filters, from Slurm, Kubernetes Indexed Jobs, AWS Batch or
//! `--task-index`/`--task-count`.

use super::{Error, Path, PathBuf};
use crate::error::Result;
use serde::Serialize;

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
