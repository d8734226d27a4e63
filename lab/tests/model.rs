//! The scaling model reads a real trace: a run of the library under
//! `epfilt::trace`, replayed on 1, 2 and 16 cores.

use epfilt::io::Compression;
use epfilt::job::options::{FilterOptions, Setting};
use epfilt::synth::{synth, Sampling, Scene, SceneKind, SynthJob};
use epfilt_lab::model::{Model, Prediction, JOIN_S};

/// A traced run of `method` at 2 threads in strips of 24 input rows (so that
/// there are many) over a small synthetic render: its model.
fn traced(method: &str) -> Model {
    let dir = tempfile::tempdir().unwrap();
    let (inp, out) = (dir.path().join("in.exr"), dir.path().join("out.exr"));
    let job = SynthJob {
        scene: Scene {
            kind: SceneKind::Mixed,
            w: 96,
            h: 80,
            seed: 1,
            hot: 1e4,
        },
        sampling: Sampling::Supersample(3),
        output: inp.clone(),
        truth: None,
        variance: false,
        compression: Compression::ZIP16,
        threads: 2,
        format: None,
    };
    synth(&job, &|_, _| {}).unwrap();
    let settings = [
        ("supersample", "3"),
        ("method", method),
        ("strip_rows", "24"),
        ("threads", "2"),
    ]
    .map(|(k, v)| (k.to_string(), Setting::Value(v.to_string())));
    let (opts, given) = FilterOptions::from_settings(settings).unwrap();
    let (job, _) = opts.job(inp, out, None, &given, None).unwrap();
    let session = epfilt::trace::start();
    epfilt::filter_file(&job, &|_, _| {}).unwrap();
    Model::from_events(&session.finish()).unwrap()
}

#[test]
fn the_model_replays_a_real_trace_within_its_bounds() {
    for method in ["ep-gauss", "box"] {
        let model = traced(method);
        let cores = [1, 2, 16];
        let tasks = Prediction::of(&model, &cores, 0.0);
        let (work, span) = (tasks.work_s, tasks.span_s);
        assert!(
            work > 0.0 && span > 0.0 && span <= work * (1.0 + 1e-9),
            "{method}: work {work}, span {span}"
        );
        let p = |pr: &Prediction, k: &str| pr.predicted_s[k];
        // The tasks alone: more cores never take longer, and never beat the
        // span.
        assert!(p(&tasks, "1") >= p(&tasks, "2") && p(&tasks, "2") >= p(&tasks, "16"));
        assert!(p(&tasks, "16") >= span * (1.0 - 1e-9), "{method}");
        // With the join after each loop: the same at 1 core, longer on more.
        let joined = Prediction::of(&model, &cores, JOIN_S);
        assert!(joined.joins > 0, "{method}: no joins counted");
        assert_eq!(p(&joined, "1"), p(&tasks, "1"));
        assert!(p(&joined, "2") > p(&tasks, "2") && p(&joined, "16") > p(&tasks, "16"));
    }
}
