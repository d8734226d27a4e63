//! Frame sequences and farm tasks, as docs/farm.md describes them: the Slurm
//! script and the Kubernetes manifest's command run here with the variables
//! their engines set.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::common::*;
use crate::exr_io::{tmpdir, write_rgb};
use exr::prelude::*;

/// Variables of the array engines, removed from every run so that the
/// machine running the tests (perhaps itself a Slurm job) cannot steer them.
const ARRAY_VARS: [&str; 7] = [
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_STEP",
    "SLURM_ARRAY_TASK_COUNT",
    "JOB_COMPLETION_INDEX",
    "AWS_BATCH_JOB_ARRAY_INDEX",
    "AWS_BATCH_JOB_ARRAY_SIZE",
];

fn command(program: &str, args: &[String], env: &[(&str, String)]) -> Output {
    let mut c = Command::new(program);
    c.args(args);
    for v in ARRAY_VARS {
        c.env_remove(v);
    }
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("run")
}

fn epfilt(args: &[&str], env: &[(&str, String)]) -> Output {
    let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
    command(env!("CARGO_BIN_EXE_epfilt"), &args, env)
}

/// Frames `frames` of a small noisy sequence, `<dir>/beauty.####.exr`.
fn sequence(dir: &Path, frames: impl IntoIterator<Item = i64>) {
    for f in frames {
        write_rgb(
            &dir.join(format!("beauty.{f:04}.exr")),
            &fireflies(24, 18, 3, 0.02, 100 + f as u64),
            Compression::ZIP16,
            Blocks::ScanLines,
            false,
            LineOrder::Increasing,
        );
    }
}

use crate::common::read_json as report;

/// Frame -> status of a sequence report.
fn statuses(r: &serde_json::Value) -> BTreeMap<i64, String> {
    r["frames"]
        .as_array()
        .expect("frames")
        .iter()
        .map(|f| {
            (
                f["frame"].as_i64().expect("frame"),
                f["status"].as_str().expect("status").to_string(),
            )
        })
        .collect()
}

/// Each frame's output equals filtering that frame alone.
fn outputs_match_single_runs(input: &Path, output: &Path, frames: impl IntoIterator<Item = i64>) {
    let single = tmpdir();
    for f in frames {
        let name = format!("beauty.{f:04}.exr");
        let alone = single.path().join(&name);
        let out = epfilt(
            &[
                "filter",
                input.join(&name).to_str().unwrap(),
                alone.to_str().unwrap(),
                "-q",
            ],
            &[],
        );
        assert!(out.status.success(), "{out:?}");
        let a = std::fs::read(output.join(&name)).expect("sequence output");
        let b = std::fs::read(&alone).expect("single output");
        assert!(
            a == b,
            "frame {f}: the sequence's output differs from a run of that frame alone"
        );
    }
}

/// `--array=A-B` of the script's `#SBATCH` lines.
fn slurm_array(script: &str) -> (i64, i64) {
    let spec = script
        .lines()
        .find_map(|l| l.strip_prefix("#SBATCH --array="))
        .expect("#SBATCH --array line");
    let (a, b) = spec.trim().split_once('-').expect("A-B");
    (a.parse().unwrap(), b.parse().unwrap())
}

fn script_path(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

#[test]
fn the_slurm_array_script_filters_each_frame_once_and_a_rerun_redoes_only_what_is_missing() {
    let dir = tmpdir();
    let frames_dir = dir.path().join("render");
    let out_dir = dir.path().join("filtered");
    std::fs::create_dir(&frames_dir).unwrap();
    const FRAMES: i64 = 11; // not a multiple of the 8 tasks: chunks of 2 and 1
    sequence(&frames_dir, 1..=FRAMES);
    let script = script_path("docs/farm/slurm-array.sh");
    let (min, max) = slurm_array(&std::fs::read_to_string(&script).unwrap());
    let count = max - min + 1;
    let run_task = |id: i64| {
        let env = [
            ("EPFILT", env!("CARGO_BIN_EXE_epfilt").to_string()),
            ("FRAMES", frames_dir.display().to_string()),
            ("OUT", out_dir.display().to_string()),
            ("RANGE", format!("1-{FRAMES}")),
            ("SLURM_ARRAY_TASK_ID", id.to_string()),
            ("SLURM_ARRAY_TASK_MIN", min.to_string()),
            ("SLURM_ARRAY_TASK_COUNT", count.to_string()),
            ("SLURM_CPUS_PER_TASK", "2".to_string()),
        ];
        let out = command("bash", &[script.display().to_string()], &env);
        assert!(out.status.success(), "task {id}: {out:?}");
        report(&out_dir.join(format!("report.task-{id}.json")))
    };
    let mut owner = BTreeMap::new();
    let mut previous_last = 0;
    for id in min..=max {
        let r = run_task(id);
        assert_eq!(r["task"]["index"].as_i64(), Some(id - min));
        assert_eq!(r["task"]["from"].as_str(), Some("SLURM_ARRAY_TASK_ID"));
        for (f, status) in statuses(&r) {
            assert_eq!(status, "done", "frame {f}");
            assert!(owner.insert(f, id).is_none(), "frame {f} filtered twice");
            // Contiguous chunks, in task order.
            assert_eq!(f, previous_last + 1);
            previous_last = f;
        }
        assert!(r["worst_ledger_error"].as_f64().unwrap() < ENERGY_TOL);
    }
    assert_eq!(owner.len() as i64, FRAMES);
    outputs_match_single_runs(&frames_dir, &out_dir, 1..=FRAMES);

    // A requeued task: everything exists, nothing is redone.
    let r = run_task(min + 2);
    assert!(statuses(&r).values().all(|s| s == "skipped"), "{r}");
    // A lost output is the only thing its task redoes.
    std::fs::remove_file(out_dir.join("beauty.0005.exr")).unwrap();
    let task_of_5 = owner[&5];
    let r = run_task(task_of_5);
    for (f, s) in statuses(&r) {
        assert_eq!(s, if f == 5 { "done" } else { "skipped" }, "frame {f}");
    }
    outputs_match_single_runs(&frames_dir, &out_dir, [5]);
}

#[test]
fn the_kubernetes_indexed_jobs_command_splits_the_frames_by_completion_index() {
    let manifest = std::fs::read_to_string(script_path("docs/farm/k8s-indexed-job.yaml")).unwrap();
    let completions: i64 = manifest
        .lines()
        .find_map(|l| l.trim().strip_prefix("completions:"))
        .expect("completions")
        .trim()
        .parse()
        .unwrap();
    let command_line = manifest
        .lines()
        .find_map(|l| l.trim().strip_prefix("command:"))
        .expect("command");
    let args: Vec<String> = serde_json::from_str(command_line.trim()).expect("command as a list");
    assert_eq!(args[0], "epfilt");
    let at = args
        .iter()
        .position(|a| a == "--task-count")
        .expect("--task-count");
    assert_eq!(
        args[at + 1],
        completions.to_string(),
        "--task-count must equal completions"
    );

    let dir = tmpdir();
    let root = dir.path().display().to_string();
    std::fs::create_dir_all(dir.path().join("sh010/render")).unwrap();
    std::fs::create_dir_all(dir.path().join("sh010/filtered")).unwrap();
    const FRAMES: i64 = 9;
    sequence(&dir.path().join("sh010/render"), 1..=FRAMES);
    // The manifest's command with the volume at the test's folder and a
    // shorter frame range.
    let mut args: Vec<String> = args[1..]
        .iter()
        .map(|a| a.replace("/shots", &root))
        .collect();
    let f = args.iter().position(|a| a == "--frames").expect("--frames");
    args[f + 1] = format!("1-{FRAMES}");
    let mut seen = BTreeMap::new();
    for index in 0..completions {
        let report_path = dir.path().join(format!("report-{index}.json"));
        let mut a = args.clone();
        a.extend(["--report".to_string(), report_path.display().to_string()]);
        let out = command(
            env!("CARGO_BIN_EXE_epfilt"),
            &a,
            &[("JOB_COMPLETION_INDEX", index.to_string())],
        );
        assert!(out.status.success(), "index {index}: {out:?}");
        for (frame, s) in statuses(&report(&report_path)) {
            assert_eq!(s, "done");
            assert!(seen.insert(frame, index).is_none(), "frame {frame} twice");
        }
    }
    assert_eq!(
        seen.keys().copied().collect::<Vec<_>>(),
        (1..=FRAMES).collect::<Vec<_>>()
    );
    outputs_match_single_runs(
        &dir.path().join("sh010/render"),
        &dir.path().join("sh010/filtered"),
        1..=FRAMES,
    );
}

#[test]
fn a_damaged_or_missing_frame_fails_alone_unless_fail_fast() {
    let dir = tmpdir();
    let d = dir.path();
    sequence(d, [1, 2, 4, 5]);
    std::fs::write(d.join("beauty.0002.exr"), b"not an exr").unwrap();
    let out_dir = d.join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let input = d.join("beauty.%04d.exr");
    let output = out_dir.join("beauty.%04d.exr");
    let rep = d.join("r.json");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "filter",
            input.to_str().unwrap(),
            output.to_str().unwrap(),
            "--frames",
            "1-5",
            "--report",
            rep.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        epfilt(&args, &[])
    };
    let out = run(&[]);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("epfilt: frame 2: ") && err.contains("beauty.0002.exr"),
        "{err}"
    );
    assert!(
        err.contains("epfilt: frame 3: ") && err.contains("no such file"),
        "{err}"
    );
    assert!(err.contains("2 of 5 frames failed"), "{err}");
    let r = report(&rep);
    let st = statuses(&r);
    assert_eq!(st[&1], "done");
    assert_eq!(st[&2], "failed");
    assert_eq!(st[&3], "failed");
    assert_eq!(st[&4], "done");
    assert_eq!(st[&5], "done");
    assert!(r["frames"][1]["error"]
        .as_str()
        .unwrap()
        .contains("beauty.0002.exr"));
    // A failed frame leaves no output.
    assert!(!out_dir.join("beauty.0002.exr").exists());
    outputs_match_single_runs(d, &out_dir, [1, 4, 5]);

    // --fail-fast: nothing after the first failure is attempted.
    std::fs::remove_dir_all(&out_dir).unwrap();
    std::fs::create_dir(&out_dir).unwrap();
    let out = run(&["--fail-fast"]);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let st = statuses(&report(&rep));
    assert_eq!(st[&1], "done");
    assert_eq!(st[&2], "failed");
    assert_eq!(st[&3], "not_run");
    assert!(!out_dir.join("beauty.0004.exr").exists());
}

#[test]
fn without_frames_the_frames_on_disk_and_aws_batch_arrays() {
    let dir = tmpdir();
    let d = dir.path();
    sequence(d, [3, 7, 8, 20]);
    std::fs::write(d.join("beauty.007.exr"), b"not the pattern's padding").unwrap();
    let out_dir = d.join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let input = d.join("beauty.####.exr");
    let output = out_dir.join("beauty.####.exr");
    let rep = d.join("r.json");
    let mut done = Vec::new();
    for index in 0..2 {
        let out = epfilt(
            &[
                "filter",
                input.to_str().unwrap(),
                output.to_str().unwrap(),
                "--report",
                rep.to_str().unwrap(),
            ],
            &[
                ("AWS_BATCH_JOB_ARRAY_INDEX", index.to_string()),
                ("AWS_BATCH_JOB_ARRAY_SIZE", "2".to_string()),
            ],
        );
        assert!(out.status.success(), "{out:?}");
        let r = report(&rep);
        assert_eq!(r["frames_in_sequence"].as_u64(), Some(4));
        done.extend(statuses(&r).into_keys());
    }
    assert_eq!(done, vec![3, 7, 8, 20]);
    outputs_match_single_runs(d, &out_dir, [3, 7, 8, 20]);

    // One file: --skip-existing leaves a complete output of this input and
    // these settings as it is, and redoes anything else, saying why.
    let existing = out_dir.join("beauty.0003.exr");
    let done = std::fs::read(&existing).unwrap();
    let out = epfilt(
        &[
            "filter",
            d.join("beauty.0003.exr").to_str().unwrap(),
            existing.to_str().unwrap(),
            "--skip-existing",
        ],
        &[],
    );
    assert!(out.status.success(), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("exists, skipped"));
    assert_eq!(std::fs::read(&existing).unwrap(), done);
    std::fs::write(&existing, b"kept").unwrap();
    let out = epfilt(
        &[
            "filter",
            d.join("beauty.0003.exr").to_str().unwrap(),
            existing.to_str().unwrap(),
            "--skip-existing",
        ],
        &[],
    );
    assert!(out.status.success(), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("redone"));
    assert_eq!(std::fs::read(&existing).unwrap(), done);
}

#[test]
fn sequence_usage_errors_are_one_line_and_exit_2() {
    let dir = tmpdir();
    let d = dir.path();
    sequence(d, [1]);
    let input = d.join("beauty.####.exr").display().to_string();
    let one = d.join("beauty.0001.exr").display().to_string();
    let out = d.join("o.####.exr").display().to_string();
    type Case<'a> = (Vec<&'a str>, Vec<(&'a str, String)>, &'a str);
    let cases: Vec<Case> = vec![
        (
            vec![&input, "plain.exr"],
            vec![],
            "give the output a frame field",
        ),
        (vec![&one, &out], vec![], "has a frame field but the input"),
        (
            vec![&one, "o.exr", "--frames", "1-3"],
            vec![],
            "need a frame sequence",
        ),
        (vec![&input, &out, "--frames", "1-x"], vec![], "--frames"),
        (
            vec![&input, &out, "--task-index", "2"],
            vec![],
            "--task-count",
        ),
        (
            vec![&input, &out, "--task-index", "2", "--task-count", "2"],
            vec![],
            "not below",
        ),
        (
            vec![&input, &out],
            vec![("JOB_COMPLETION_INDEX", "0".to_string())],
            "--task-count",
        ),
        (
            vec![&input, "nowhere/o.####.exr"],
            vec![],
            "output folder does not exist",
        ),
        (
            vec![&input, &out, "--trace", "t.json"],
            vec![],
            "--trace records the run of one file",
        ),
        (
            vec!["a.##.b.##.exr", &out],
            vec![],
            "more than one frame field",
        ),
        (vec![&input, &input], vec![], "is the input's"),
    ];
    for (args, env, needle) in cases {
        let mut a = vec!["filter"];
        a.extend(args.iter().copied());
        let o = epfilt(&a, &env);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

/// `scripts/slurm-ci`'s status when Slurm cannot run (none, or not root).
const SKIPPED: i32 = 77;

#[test]
#[ignore = "needs a one-node Slurm, as root: scripts/slurm-ci --install-only, then cargo test --test behaviour -- --ignored real_slurm"]
fn a_real_slurm_cluster_runs_the_frame_array_and_the_band_merge() {
    // The script starts a one-node cluster on 127.0.0.1 (.ci/run installs
    // Slurm first), submits docs/farm/slurm-array.sh as an 8-task array and
    // docs/farm/slurm-bands.sh + slurm-merge.sh as a 4-band array with an
    // afterok merge, and compares every output with a single run.
    let script = script_path("scripts/slurm-ci");
    let out = command(
        "bash",
        &[
            script.display().to_string(),
            "--bin".into(),
            env!("CARGO_BIN_EXE_epfilt").into(),
        ],
        &[],
    );
    let text = String::from_utf8_lossy(&out.stdout);
    eprintln!("{}", text.trim());
    assert_ne!(
        out.status.code(),
        Some(SKIPPED),
        "Slurm cannot run here: {text}"
    );
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("slurm-ci: passed"), "{text}");
}
