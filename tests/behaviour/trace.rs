//! `filter --trace FILE`: the trace is one valid Chrome trace of every
//! strip's work, and tracing does not change the output (the lab's tests
//! hold the scaling model to a real trace).

use std::collections::{HashMap, HashSet};

use crate::common::epfilt_ok;
use crate::exr_io::tmpdir;

/// Write a synthetic input and filter it with and without `--trace` (small
/// strips, so that there are many, and 2 threads); the trace's events.
fn traced_run(method: &str) -> Vec<serde_json::Value> {
    let dir = tmpdir();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let (inp, plain, out, tr) = (
        p("in.exr"),
        p("plain.exr"),
        p("traced.exr"),
        p("trace.json"),
    );
    let common = [
        "-s",
        "3",
        "--method",
        method,
        "--strip-rows",
        "24",
        "--threads",
        "2",
        "-q",
    ];
    epfilt_ok(&["synth", "-q", "--size", "96x80", "-o", &inp]);
    let mut args = vec!["filter", &inp, &plain];
    args.extend(common);
    epfilt_ok(&args);
    let mut args = vec!["filter", &inp, &out, "--trace", &tr];
    args.extend(common);
    epfilt_ok(&args);
    assert_eq!(
        std::fs::read(&plain).unwrap(),
        std::fs::read(&out).unwrap(),
        "{method}: --trace changed the output"
    );
    let text = std::fs::read_to_string(&tr).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).expect("the trace is JSON");
    json["traceEvents"].as_array().expect("traceEvents").clone()
}

#[test]
fn a_trace_holds_every_strips_work_with_its_dependencies_and_changes_nothing() {
    for method in ["ep-gauss", "box"] {
        let events = traced_run(method);
        let mut ids = HashSet::new();
        let mut strips: HashMap<&str, Vec<u64>> = HashMap::new();
        for e in &events {
            // Complete spans: a begin and an end each, never out of order.
            assert_eq!(e["ph"], "X", "{e}");
            assert!(e["dur"].as_f64().unwrap() >= 0.0 && e["ts"].as_f64().unwrap() >= 0.0);
            assert!(
                ids.insert(e["args"]["id"].as_u64().unwrap()),
                "ids are unique"
            );
            if e["cat"] == "segment" {
                let lane = e["args"]["lane"].as_str().unwrap();
                strips
                    .entry(lane)
                    .or_default()
                    .push(e["args"]["strip"].as_u64().unwrap());
            }
        }
        for e in &events {
            for d in e["args"]["deps"].as_array().unwrap() {
                assert!(
                    ids.contains(&d.as_u64().unwrap()),
                    "{method}: {e} waits for a missing event"
                );
            }
            if e["cat"] != "segment" {
                assert_eq!(e["args"]["deps"].as_array().unwrap().len(), 1, "{e}");
            }
        }
        // 240 sample rows in strips of at most 24: at least 10 strips, each
        // filtered once, in order, after its read (and a read that finds the
        // end of the file).
        let read: HashSet<u64> = strips["read"].iter().copied().collect();
        let filter: Vec<u64> = strips["filter"].clone();
        let n = filter.len() as u64;
        assert!(n >= 10, "{method}: {n} strips");
        assert_eq!(filter, (0..n).collect::<Vec<u64>>(), "{method}");
        assert!((0..n).all(|k| read.contains(&k)), "{method}: {read:?}");
        assert!(!strips["write"].is_empty());
        // The reader decodes ahead on a lane of its own: every block row
        // once (they end in any order), each waited for by the read that
        // hands over its first rows.
        let mut decode = strips["decode"].clone();
        decode.sort_unstable();
        assert_eq!(
            decode,
            (0..decode.len() as u64).collect::<Vec<u64>>(),
            "{method}"
        );
        let seg_id = |e: &serde_json::Value| e["args"]["id"].as_u64().unwrap();
        let lane_of = |e: &serde_json::Value| e["args"]["lane"].as_str().unwrap_or("").to_string();
        let decodes: HashSet<u64> = events
            .iter()
            .filter(|e| e["cat"] == "segment" && lane_of(e) == "decode")
            .map(seg_id)
            .collect();
        let waited: HashSet<u64> = events
            .iter()
            .filter(|e| e["cat"] == "segment" && lane_of(e) == "read")
            .flat_map(|e| e["args"]["deps"].as_array().unwrap().clone())
            .map(|d| d.as_u64().unwrap())
            .filter(|d| decodes.contains(d))
            .collect();
        assert_eq!(waited, decodes, "{method}: a batch no read waited for");
        let names: HashSet<&str> = events.iter().map(|e| e["name"].as_str().unwrap()).collect();
        for n in ["decode", "compress", "ledger in", "finish rows"] {
            assert!(names.contains(n), "{method}: no {n} in the trace");
        }
    }
}
