//! The speed/accuracy trade study behind `scripts/tradeoff`: runs the built
//! `epfilt` binary over a grid of settings on `synth` scenes with exact truth,
//! and writes `tradeoff.csv`, `tradeoff.png` (error against time, one series
//! per method, the Pareto front marked) and `tradeoff.md`.
//!
//! ```text
//! cargo run --release -p epfilt-lab --bin tradeoff -- [--quick] [--out DIR] [--bin PATH] [--repeat N] [--guards-only]
//! ```
//!
//! Every scene is made twice with the same budget of 9 samples per pixel: as
//! 3x3 super-samples (for ep-gauss, gauss, box and the foils) and as the mean
//! and variance of 9 samples (for ep-box), each scored against its own exact
//! truth. Time is the wall time of the whole `epfilt filter` process (both
//! passes of ep-box, decoding and encoding included); `mpx_per_s` is output
//! megapixels per second of it.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};

use epfilt_lab::chart::{save, Chart, Rgb, Series, Style};
use serde_json::Value;

/// Every method, by the command line's names.
const METHODS: [&str; 7] = epfilt::Method::NAMES;
const SETTINGS: [&str; 13] = [
    "tolerance",
    "support",
    "coarse_from",
    "carriers_fraction",
    "width_step",
    "max_radius",
    "cutoff",
    "d",
    "confidence",
    "guard",
    "guard_confidence",
    "clamp",
    "alpha",
];

#[derive(Clone, Debug)]
struct Run {
    scene: String,
    method: String,
    /// Setting name -> value, as passed on the command line.
    settings: BTreeMap<&'static str, String>,
    /// Whether every setting is the method's default.
    default: bool,
}

#[derive(Clone, Debug)]
struct Row {
    run: Run,
    seconds: f64,
    mpx_per_s: f64,
    peak_rss_bytes: u64,
    rel_mse: f64,
    rmse: f64,
    psnr: f64,
    energy_ratio: f64,
    samples_noisy: u64,
    samples_spread: u64,
    samples_capped: u64,
}

fn defaults(method: &str) -> BTreeMap<&'static str, String> {
    let mut m = BTreeMap::new();
    let mut set = |k: &'static str, v: &str| {
        m.insert(k, v.to_string());
    };
    match method {
        "ep-gauss" => {
            set("tolerance", "0.25");
            set("width_step", "0.1");
            set("max_radius", "16");
            set("cutoff", "3");
            set("support", "1");
            set("coarse_from", "2");
        }
        "ep-box" => {
            set("d", "5");
            set("confidence", "0.8");
            set("max_radius", "8");
            set("guard", "all");
            set("guard_confidence", "0.99");
            set("carriers_fraction", "0.2");
        }
        "gauss" => set("cutoff", "3"),
        "clamp" => set("clamp", "10"),
        "alpha-trim" => set("alpha", "0.25"),
        _ => {}
    }
    m
}

/// A setting and the values it takes.
type Axis = (&'static str, Vec<&'static str>);

/// One-at-a-time variations around each method's defaults.
fn grid(quick: bool) -> Vec<(&'static str, Vec<Axis>)> {
    if quick {
        vec![
            (
                "ep-gauss",
                vec![
                    ("tolerance", vec!["0.1", "0.25", "1"]),
                    ("width_step", vec!["0.1", "0.4"]),
                    ("max_radius", vec!["4", "16"]),
                    ("support", vec!["0", "1"]),
                    ("coarse_from", vec!["0", "2"]),
                ],
            ),
            (
                "ep-box",
                vec![
                    ("d", vec!["2", "5", "20"]),
                    ("max_radius", vec!["4", "16"]),
                    ("guard", vec!["none", "range", "both", "all"]),
                ],
            ),
            ("gauss", vec![]),
            ("box", vec![]),
            ("clamp", vec![("clamp", vec!["10"])]),
            ("median", vec![]),
            ("alpha-trim", vec![]),
        ]
    } else {
        vec![
            (
                "ep-gauss",
                vec![
                    (
                        "tolerance",
                        vec!["0.05", "0.1", "0.15", "0.25", "0.4", "0.6", "1"],
                    ),
                    ("width_step", vec!["0.02", "0.05", "0.1", "0.2", "0.4"]),
                    ("max_radius", vec!["2", "4", "8", "16", "32", "64"]),
                    ("cutoff", vec!["2", "2.5", "3", "4"]),
                    ("support", vec!["0", "1", "2", "3"]),
                    ("coarse_from", vec!["0", "2", "3", "4", "8"]),
                ],
            ),
            (
                "ep-box",
                vec![
                    ("d", vec!["1", "2", "5", "10", "20"]),
                    ("confidence", vec!["0.5", "0.8", "0.95", "0.99"]),
                    ("max_radius", vec!["2", "4", "8", "16", "32", "64"]),
                    (
                        "guard",
                        vec!["none", "range", "stderr", "both", "carriers", "all"],
                    ),
                    ("guard_confidence", vec!["0.8", "0.95", "0.99", "0.999"]),
                    ("carriers_fraction", vec!["0.1", "0.15", "0.2", "0.3"]),
                ],
            ),
            ("gauss", vec![("cutoff", vec!["2", "3", "4"])]),
            ("box", vec![]),
            ("clamp", vec![("clamp", vec!["1", "10", "100", "1000"])]),
            ("median", vec![]),
            ("alpha-trim", vec![("alpha", vec!["0.1", "0.25", "0.4"])]),
        ]
    }
}

fn runs(scenes: &[&str], quick: bool) -> Vec<Run> {
    let mut out = Vec::new();
    for scene in scenes {
        for (method, axes) in grid(quick) {
            let base = defaults(method);
            let mut seen: Vec<BTreeMap<&'static str, String>> = vec![base.clone()];
            for (key, values) in &axes {
                for v in values {
                    let mut s = base.clone();
                    s.insert(key, v.to_string());
                    if !seen.contains(&s) {
                        seen.push(s);
                    }
                }
            }
            // ep-gauss: the cheaper knobs again at its most accurate tolerance,
            // to find the fastest setting near its best error.
            if method == "ep-gauss" && !quick {
                for (ws, mr) in [
                    ("0.2", "16"),
                    ("0.4", "16"),
                    ("0.1", "8"),
                    ("0.4", "8"),
                    ("0.4", "4"),
                ] {
                    let mut s = base.clone();
                    s.insert("tolerance", "0.05".into());
                    s.insert("width_step", ws.into());
                    s.insert("max_radius", mr.into());
                    if !seen.contains(&s) {
                        seen.push(s);
                    }
                }
            }
            for s in seen {
                out.push(Run {
                    scene: scene.to_string(),
                    method: method.to_string(),
                    default: s == base,
                    settings: s,
                });
            }
        }
    }
    out
}

fn run_cmd(bin: &Path, args: &[String]) -> Result<String> {
    let o = Command::new(bin)
        .args(args)
        .output()
        .with_context(|| format!("run {}", bin.display()))?;
    if !o.status.success() {
        bail!(
            "epfilt {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr).trim()
        );
    }
    Ok(String::from_utf8_lossy(&o.stdout).into_owned())
}

fn main() -> Result<()> {
    let mut quick = false;
    let mut out_dir = PathBuf::from("docs");
    let mut bin = PathBuf::from("target/release/epfilt");
    let mut repeat = 1usize;
    let mut size: Option<String> = None;
    let mut guards_only = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--quick" => quick = true,
            "--out" => out_dir = args.next().context("--out DIR")?.into(),
            "--bin" => bin = args.next().context("--bin PATH")?.into(),
            "--repeat" => repeat = args.next().context("--repeat N")?.parse()?,
            "--size" => size = Some(args.next().context("--size WxH")?),
            "--guards-only" => guards_only = true,
            "--replot" => return replot(&out_dir),
            other => bail!("unknown argument {other:?}"),
        }
    }
    let size = size.unwrap_or_else(|| if quick { "512x512" } else { "1024x1024" }.into());
    let (w, h) = size
        .split_once('x')
        .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
        .context("--size WxH")?;
    std::fs::create_dir_all(&out_dir)?;
    let work = tempfile::Builder::new()
        .prefix("tradeoff-")
        .tempdir_in(&out_dir)?;
    if guards_only {
        // Only the guard study, spliced into an existing tradeoff.md.
        let section = guard_study(&bin, work.path(), &out_dir, &size, quick)?;
        let path = out_dir.join("tradeoff.md");
        let old = std::fs::read_to_string(&path).unwrap_or_default();
        let head = old
            .split("## ep-box guards")
            .next()
            .unwrap_or("")
            .to_string();
        std::fs::write(&path, head + &section)?;
        print!("{section}");
        return Ok(());
    }
    let scenes = ["mixed", "caustic", "lights"];
    let s = |p: &Path| p.to_string_lossy().into_owned();
    for scene in scenes {
        let d = work.path();
        eprintln!("synth {scene} {size} (3x3 and 9 spp with variance)");
        run_cmd(
            &bin,
            &[
                "synth",
                "-q",
                "--scene",
                scene,
                "--size",
                &size,
                "-s",
                "3",
                "-o",
                &s(&d.join(format!("{scene}-s3.exr"))),
                "--truth",
                &s(&d.join(format!("{scene}-s3-truth.exr"))),
            ]
            .map(String::from),
        )?;
        run_cmd(
            &bin,
            &[
                "synth",
                "-q",
                "--scene",
                scene,
                "--size",
                &size,
                "--spp",
                "9",
                "--variance",
                "-o",
                &s(&d.join(format!("{scene}-spp.exr"))),
                "--truth",
                &s(&d.join(format!("{scene}-spp-truth.exr"))),
            ]
            .map(String::from),
        )?;
    }
    let all = runs(&scenes, quick);
    let mut rows = Vec::new();
    let started = Instant::now();
    for (k, run) in all.iter().enumerate() {
        let d = work.path();
        let spp = run.method == "ep-box";
        let tag = if spp { "spp" } else { "s3" };
        let input = d.join(format!("{}-{tag}.exr", run.scene));
        let truth = d.join(format!("{}-{tag}-truth.exr", run.scene));
        let output = d.join("out.exr");
        let report = d.join("report.json");
        let mut a: Vec<String> = [
            "filter",
            &s(&input),
            &s(&output),
            "-q",
            "--method",
            &run.method,
            "-s",
            if spp { "1" } else { "3" },
            "--report",
            &s(&report),
        ]
        .map(String::from)
        .to_vec();
        for (key, v) in &run.settings {
            a.push(format!("--{}", key.replace('_', "-")));
            a.push(v.clone());
        }
        let mut best = f64::INFINITY;
        for _ in 0..repeat.max(1) {
            let t = Instant::now();
            run_cmd(&bin, &a)?;
            best = best.min(t.elapsed().as_secs_f64());
        }
        let r: Value = serde_json::from_str(&std::fs::read_to_string(&report)?)?;
        let c: Value = serde_json::from_str(&run_cmd(
            &bin,
            &["compare", &s(&output), &s(&truth), "--json"].map(String::from),
        )?)?;
        let sum = |k: &str| -> f64 {
            r[k].as_array()
                .map(|v| v.iter().filter_map(|x| x.as_f64()).sum())
                .unwrap_or(f64::NAN)
        };
        let f = |v: &Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        let u = |k: &str| r[k].as_u64().unwrap_or(0);
        rows.push(Row {
            run: run.clone(),
            seconds: best,
            mpx_per_s: (w * h) as f64 / best / 1e6,
            peak_rss_bytes: u("peak_rss_bytes"),
            rel_mse: f(&c, "rel_mse"),
            rmse: f(&c, "rmse"),
            psnr: f(&c, "psnr"),
            energy_ratio: sum("energy_out") / sum("energy_in"),
            samples_noisy: u("samples_noisy"),
            samples_spread: u("samples_spread"),
            samples_capped: u("samples_capped"),
        });
        eprintln!(
            "[{}/{}] {:>5.1} s  {} {} {:?}: {:.3} s, rmse {:.4}",
            k + 1,
            all.len(),
            started.elapsed().as_secs_f64(),
            run.scene,
            run.method,
            run.settings,
            best,
            rows.last().map_or(0.0, |r| r.rmse)
        );
    }
    write_csv(&out_dir.join("tradeoff.csv"), &rows)?;
    let points: Vec<Point> = rows.iter().map(Point::of).collect();
    plot(&out_dir.join("tradeoff"), &points, &scenes)?;
    let mut md = markdown(&rows, &scenes, &size, quick);
    md.push_str(&guard_study(&bin, work.path(), &out_dir, &size, quick)?);
    std::fs::write(out_dir.join("tradeoff.md"), &md)?;
    print!("{md}");
    Ok(())
}

/// The ep-box guards from few to many samples per pixel: RMSE against truth
/// of the input and of each guard, as a Markdown section (and
/// `tradeoff-guards.csv`). The 9-sample trade above cannot show it: a guard
/// that is best at 9 samples can leave a 256-sample render worse than it was.
fn guard_study(bin: &Path, work: &Path, out_dir: &Path, size: &str, quick: bool) -> Result<String> {
    let (scenes, spps): (&[&str], &[&str]) = if quick {
        (&["mixed", "lights"], &["4", "64"])
    } else {
        (
            &[
                "mixed",
                "penumbra",
                "glossy",
                "light-edge",
                "caustic",
                "lights",
            ],
            &["4", "16", "64", "256"],
        )
    };
    // The default last.
    let guards: [(&str, &str, &str); 6] = [
        ("none", "none", "0.99"),
        ("range", "range", "0.99"),
        ("stderr", "stderr", "0.99"),
        ("both (range + stderr)", "both", "0.99"),
        ("carriers", "carriers", "0.99"),
        ("all (default)", "all", "0.99"),
    ];
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let input = work.join("g.exr");
    let truth = work.join("g-truth.exr");
    let output = work.join("g-out.exr");
    // (RMSE, rel. MSE) against the truth.
    let rmse = |a: &Path| -> Result<(f64, f64)> {
        let c: Value = serde_json::from_str(&run_cmd(
            bin,
            &["compare", &s(a), &s(&truth), "--json"].map(String::from),
        )?)?;
        Ok((
            c["rmse"].as_f64().unwrap_or(f64::NAN),
            c["rel_mse"].as_f64().unwrap_or(f64::NAN),
        ))
    };
    let header = |what: &str| {
        let mut h = format!("\n{what}\n\n| scene | spp | input |");
        for (name, _, _) in &guards {
            let _ = write!(h, " {name} |");
        }
        h.push_str("\n|---|---|---|");
        h.push_str(&"---|".repeat(guards.len()));
        h.push('\n');
        h
    };
    let mut md = format!(
        "## ep-box guards from 4 to 256 samples per pixel ({size})\n\n\
         Error against truth of the input and of ep-box with each guard (other settings at their \
         defaults); bold: the lowest of the row. `stderr` spreads at most `t * S_p` of a \
         pixel's excess, `t` at the bound's confidence (99%); `range` leaves a pixel no brighter \
         than a converged one within 2 pixels; `carriers` treats a pixel as noise only when fewer \
         than min(16, max(0.2 n, n / (1 + (n - 1) 0.25), 2)) of its n samples carry its mean and it \
         is not a compact feature; `all` is the three. RMSE is dominated by the brightest pixels' \
         errors, rel. MSE (`(a - b)^2 / (b^2 + eps)`) weighs every pixel by its own brightness.\n"
    );
    let mut rmse_md = header("RMSE:");
    let mut rel_md = header("rel. MSE:");
    let mut csv =
        String::from("scene,spp,guard,guard_confidence,rmse,input_rmse,rel_mse,input_rel_mse\n");
    let (mut worst_ratio, mut worst_rel) = (0.0f64, 0.0f64);
    for scene in scenes {
        for spp in spps {
            eprintln!("guard study: {scene} at {spp} spp");
            run_cmd(
                bin,
                &[
                    "synth",
                    "-q",
                    "--scene",
                    scene,
                    "--size",
                    size,
                    "--spp",
                    spp,
                    "--variance",
                    "-o",
                    &s(&input),
                    "--truth",
                    &s(&truth),
                ]
                .map(String::from),
            )?;
            let (base, base_rel) = rmse(&input)?;
            let mut errs = Vec::new();
            for (_, g, gc) in &guards {
                run_cmd(
                    bin,
                    &[
                        "filter",
                        &s(&input),
                        &s(&output),
                        "-q",
                        "--method",
                        "ep-box",
                        "--guard",
                        g,
                        "--guard-confidence",
                        gc,
                    ]
                    .map(String::from),
                )?;
                let (e, r) = rmse(&output)?;
                let _ = writeln!(
                    csv,
                    "{scene},{spp},{g},{gc},{e:.6e},{base:.6e},{r:.6e},{base_rel:.6e}"
                );
                errs.push((e, r));
            }
            let last = errs[errs.len() - 1];
            worst_ratio = worst_ratio.max(last.0 / base);
            worst_rel = worst_rel.max(last.1 / base_rel);
            for (md, pick, base) in [
                (&mut rmse_md, 0usize, base),
                (&mut rel_md, 1usize, base_rel),
            ] {
                let val = |e: &(f64, f64)| if pick == 0 { e.0 } else { e.1 };
                let best = errs.iter().map(val).fold(f64::INFINITY, f64::min);
                let _ = write!(md, "| {scene} | {spp} | {base:.4} |");
                for e in &errs {
                    let v = val(e);
                    if v == best {
                        let _ = write!(md, " **{v:.4}** |");
                    } else {
                        let _ = write!(md, " {v:.4} |");
                    }
                }
                md.push('\n');
            }
        }
    }
    md.push_str(&rmse_md);
    md.push_str(&rel_md);
    let _ = writeln!(
        md,
        "\nThe default's error is at most {worst_ratio:.3} x the input's in RMSE and {worst_rel:.3} x in \
         rel. MSE in every row."
    );
    std::fs::write(out_dir.join("tradeoff-guards.csv"), csv)?;
    Ok(md)
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    let mut s = String::from("scene,method,default");
    for k in SETTINGS {
        write!(s, ",{k}")?;
    }
    s.push_str(",seconds,mpx_per_s,peak_rss_bytes,rel_mse,rmse,psnr,energy_ratio,samples_noisy,samples_spread,samples_capped\n");
    for r in rows {
        write!(s, "{},{},{}", r.run.scene, r.run.method, r.run.default)?;
        for k in SETTINGS {
            write!(s, ",{}", r.run.settings.get(k).map_or("", |v| v.as_str()))?;
        }
        writeln!(
            s,
            ",{:.4},{:.3},{},{:.6e},{:.6e},{:.3},{:.15},{},{},{}",
            r.seconds,
            r.mpx_per_s,
            r.peak_rss_bytes,
            r.rel_mse,
            r.rmse,
            r.psnr,
            r.energy_ratio,
            r.samples_noisy,
            r.samples_spread,
            r.samples_capped
        )?;
    }
    std::fs::write(path, s)?;
    Ok(())
}

/// Rows not beaten on both time and RMSE by another row of the same scene.
/// The indices of `(seconds, error)` points no other beats in both, by
/// time.
fn pareto(pts: &[(f64, f64)]) -> Vec<usize> {
    let mut front: Vec<usize> = (0..pts.len())
        .filter(|&i| {
            !pts.iter()
                .any(|o| (o.0 <= pts[i].0 && o.1 < pts[i].1) || (o.0 < pts[i].0 && o.1 <= pts[i].1))
        })
        .collect();
    front.sort_by(|&a, &b| pts[a].0.total_cmp(&pts[b].0));
    front
}

fn colour(m: &str) -> Rgb {
    match m {
        "ep-gauss" => (214, 39, 40),
        "ep-box" => (255, 127, 14),
        "gauss" => (31, 119, 180),
        "box" => (127, 127, 127),
        "clamp" => (44, 160, 44),
        "median" => (148, 103, 189),
        _ => (140, 86, 75),
    }
}

/// One run as the plot shows it.
struct Point {
    scene: String,
    method: String,
    default: bool,
    seconds: f64,
    rmse: f64,
}

impl Point {
    fn of(r: &Row) -> Self {
        Point {
            scene: r.run.scene.clone(),
            method: r.run.method.clone(),
            default: r.run.default,
            seconds: r.seconds,
            rmse: r.rmse,
        }
    }
}

/// `STEM.png` and `.svg`: per scene, each run's RMSE against its time (both
/// logarithmic), a colour a method, its defaults crossed, the Pareto front
/// joined and ringed.
fn plot(stem: &Path, points: &[Point], scenes: &[&str]) -> Result<()> {
    let series = Series::new;
    let charts: Vec<Chart> = (scenes.iter())
        .map(|scene| {
            let pts: Vec<&Point> = points.iter().filter(|p| p.scene == *scene).collect();
            let xy = |p: &&Point| (p.seconds, p.rmse);
            let mut all: Vec<Series> = (METHODS.iter())
                .map(|m| {
                    let of: Vec<(f64, f64)> =
                        pts.iter().filter(|p| p.method == *m).map(xy).collect();
                    series(m, colour(m), Style::Dots, of)
                })
                .collect();
            let defaults = pts.iter().filter(|p| p.default).map(xy).collect();
            all.push(series(
                "a method's defaults",
                (0, 0, 0),
                Style::Crosses,
                defaults,
            ));
            let xys: Vec<(f64, f64)> = pts.iter().map(xy).collect();
            let front: Vec<(f64, f64)> = pareto(&xys).into_iter().map(|i| xys[i]).collect();
            all.push(series("", (0, 0, 0), Style::Line, front.clone()));
            all.push(series("the Pareto front", (0, 0, 0), Style::Rings, front));
            Chart {
                title: format!("scene {scene}: error against time, one point a run"),
                x_label: "wall seconds per run (log)".into(),
                y_label: "RMSE against the truth (log)".into(),
                log: (true, true),
                series: all,
            }
        })
        .collect();
    save(&charts, stem)
}

/// Draw `DIR/tradeoff.png` and `.svg` again from `DIR/tradeoff.csv`,
/// without running anything.
fn replot(dir: &Path) -> Result<()> {
    let names = ["scene", "method", "default", "seconds", "rmse"];
    let mut points = Vec::new();
    for f in epfilt_lab::chart::csv_columns(&dir.join("tradeoff.csv"), &names)? {
        points.push(Point {
            scene: f[0].clone(),
            method: f[1].clone(),
            default: f[2] == "true",
            seconds: f[3].parse()?,
            rmse: f[4].parse()?,
        });
    }
    let mut scenes: Vec<&str> = Vec::new();
    for p in &points {
        if !scenes.contains(&p.scene.as_str()) {
            scenes.push(&p.scene);
        }
    }
    plot(&dir.join("tradeoff"), &points, &scenes)
}

fn settings_text(r: &Row) -> String {
    r.run
        .settings
        .iter()
        .map(|(k, v)| format!("{}={v}", k.replace('_', "-")))
        .collect::<Vec<_>>()
        .join(" ")
}

fn markdown(rows: &[Row], scenes: &[&str], size: &str, quick: bool) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Speed/accuracy trade ({}run, {size} output pixels, 9 samples per pixel)\n",
        if quick { "quick " } else { "" }
    );
    let _ = writeln!(
        s,
        "Written by `scripts/tradeoff`; data in `tradeoff.csv`, plot in `tradeoff.png` and `.svg`. Time is the wall \
         time of the whole `epfilt filter` process on 2 cores; errors are against each input's exact truth.\n"
    );
    for scene in scenes {
        let pts: Vec<&Row> = rows.iter().filter(|r| r.run.scene == *scene).collect();
        let xys: Vec<(f64, f64)> = pts.iter().map(|r| (r.seconds, r.rmse)).collect();
        let front = pareto(&xys);
        let _ = writeln!(s, "## Scene `{scene}`: each method at its defaults\n");
        let _ = writeln!(s, "| method | RMSE | rel. MSE | PSNR | energy out/in | seconds | Mpx/s | peak RSS | spread | capped |");
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
        for m in METHODS {
            for r in pts.iter().filter(|r| r.run.method == m && r.run.default) {
                let _ = writeln!(
                    s,
                    "| {m} | {:.4} | {:.4} | {:.2} dB | {:.6} | {:.3} | {:.2} | {:.0} MiB | {} | {} |",
                    r.rmse,
                    r.rel_mse,
                    r.psnr,
                    r.energy_ratio,
                    r.seconds,
                    r.mpx_per_s,
                    r.peak_rss_bytes as f64 / 1048576.0,
                    r.samples_spread,
                    r.samples_capped
                );
            }
        }
        let ep: Vec<&&Row> = pts.iter().filter(|r| r.run.method == "ep-gauss").collect();
        if let Some(best) = ep.iter().min_by(|a, b| a.rmse.total_cmp(&b.rmse)) {
            let fast = ep
                .iter()
                .filter(|r| r.rmse <= best.rmse * 1.05)
                .min_by(|a, b| a.seconds.total_cmp(&b.seconds));
            let _ = writeln!(
                s,
                "\nBest ep-gauss: RMSE {:.4} at `{}` ({:.3} s).",
                best.rmse,
                settings_text(best),
                best.seconds
            );
            if let Some(f) = fast {
                let _ = writeln!(
                    s,
                    "Fastest ep-gauss within 5% of that error: RMSE {:.4} at `{}` ({:.3} s, {:.2} Mpx/s).",
                    f.rmse,
                    settings_text(f),
                    f.seconds,
                    f.mpx_per_s
                );
            }
        }
        let foils: Vec<&&Row> = pts
            .iter()
            .filter(|r| matches!(r.run.method.as_str(), "clamp" | "median" | "alpha-trim"))
            .collect();
        if !foils.is_empty() {
            let _ = writeln!(s, "\nEnergy the foils lose:\n");
            for r in foils {
                let _ = writeln!(
                    s,
                    "* {} `{}`: keeps {:.1}% of the energy (loses {:.1}%), RMSE {:.4}",
                    r.run.method,
                    settings_text(r),
                    r.energy_ratio * 100.0,
                    (1.0 - r.energy_ratio) * 100.0,
                    r.rmse
                );
            }
        }
        let _ = writeln!(s, "\nPareto front (time, RMSE):\n");
        let _ = writeln!(s, "| method | settings | seconds | RMSE | rel. MSE |");
        let _ = writeln!(s, "|---|---|---|---|---|");
        for &i in &front {
            let r = pts[i];
            let _ = writeln!(
                s,
                "| {} | `{}` | {:.3} | {:.4} | {:.4} |",
                r.run.method,
                settings_text(r),
                r.seconds,
                r.rmse,
                r.rel_mse
            );
        }
        let _ = writeln!(s, "\nAll runs:\n");
        let _ = writeln!(s, "| method | settings | seconds | RMSE | rel. MSE | PSNR | energy out/in | spread | capped |");
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
        for r in &pts {
            let _ = writeln!(
                s,
                "| {}{} | `{}` | {:.3} | {:.4} | {:.4} | {:.2} | {:.6} | {} | {} |",
                r.run.method,
                if r.run.default { " (default)" } else { "" },
                settings_text(r),
                r.seconds,
                r.rmse,
                r.rel_mse,
                r.psnr,
                r.energy_ratio,
                r.samples_spread,
                r.samples_capped
            );
        }
        s.push('\n');
    }
    s
}
