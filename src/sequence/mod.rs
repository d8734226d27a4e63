//! Frame sequences and render-farm tasks: `render.####.exr` patterns, frame
//! specs (`1-100x2`, `3,4,10-20x5`), the task of an array job (Slurm,
//! Kubernetes Indexed Jobs, AWS Batch, or `--task-index`/`--task-count`) and a
//! runner that filters each frame of a task with one [`FilterJob`] template,
//! going on past a failed frame unless asked to stop.
//!
//! Every output is written whole or not at all (as for one file), so a task
//! that is retried after a crash redoes only what is missing when
//! `skip_existing` is set, and writes the same bytes when it is not.

mod farm;
mod run;

pub use farm::{band_and_task, band_path, task_from, Share, Task};
pub use run::{run_sequence, FrameEvent, FrameOutcome, FrameStatus, SequenceJob, SequenceReport};

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{Error, Result};
use crate::io::InputFile;
use crate::job::{existing_output, filter_opened, Existing, FilterJob};
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
