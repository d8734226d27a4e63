//! `eval_renders --sweep`: ep-gauss over a grid of its knobs on every
//! super-sampled render of every folder given, and the time per megapixel of
//! each setting on the 6144x6144 bench input: the speed/accuracy trade, its
//! Pareto front, today's defaults and the presets on it.
//!
//! ```text
//! eval_renders --sweep [--renders DIR]... [--held-out DIR]... [--grid KEY=V1,V2,...]...
//!     [--bench FILE] [--bench-runs N] [--threads N] [--out DIR] [--no-write] [--list-lost]
//! ```
//!
//! Renders in a `--held-out` folder are filtered by every setting and
//! reported, but play no part in the error, the lights constraint, the front
//! or the choice: they check a choice on renders it was not made on.
//!
//! * **factor** per input, as for the defaults' table: relMSE of ep-gauss
//!   against the Gaussian of the reference over the relMSE the Gaussian of
//!   the same radius leaves; **error** of a setting: the geometric mean of its
//!   factors over every input (each input counts the same);
//!   **worst vs defaults**: the largest ratio of a setting's factor to the
//!   old defaults' on any one input (above 1: some render got worse);
//!   **worst vs best**: the largest ratio of a setting's factor to the best
//!   factor any setting of the sweep reached on that input (what a user loses
//!   on their worst render to the setting that would have suited it; 1: the
//!   setting is the best on every input).
//! * **peak**: per light (`lights` of the reference), its brightest pixel
//!   over the linear filter's, or over the reference's where that is lower
//!   (a firefly on a light raises the linear filter's); the worst light;
//!   **lights < 0.8**: how many lights, over every input, fell below 0.8
//!   (the issue's "within 20% of the linear filter's").
//! * **time**: seconds per input megapixel of ep-gauss on the bench file
//!   (6144x6144 S=3 float ZIP, 1% fireflies 1e2..1e5, the lab's `fireflies`),
//!   the median of `--bench-runs` runs interleaved with as many of gauss,
//!   and the ratio of the medians; without `--bench`, no times.
//! * `tolerance` in the grid is the value at S = 3; inputs at other S get
//!   `tolerance * (3/S)^1.776`, as the default does.
//!
//! Writes `pareto.md`, `pareto.csv` and `pareto.png` (error against time,
//! the front joined, the old defaults, the new ones and the presets marked).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use epfilt::filter::Quality;
use epfilt::{filter_file, FilterJob, FilterParams, Method};

use super::{inputs, lights, rel_mse, set, Image, Input, ORACLE_OVER};

/// The grid when none is given: the knobs the issue names, jointly.
const DEFAULT_GRID: &[(&str, &[&str])] = &[
    (
        "tolerance",
        &["0.25", "0.15", "0.1", "0.08", "0.06", "0.04"],
    ),
    ("support", &["0", "1", "2", "3"]),
    ("support_ratio", &["4", "16"]),
    ("radius", &["0.6", "0.65"]),
    ("cutoff", &["2.5", "3"]),
];

/// A light is kept when its peak is at least this share of the linear
/// filter's (the issue's "within 20%").
const KEPT_PEAK: f64 = 0.8;

/// One setting: key = value pairs over the defaults.
pub(super) type Setting = Vec<(String, String)>;

/// `KEY=V;KEY=V` (`--also`) as a setting.
pub(super) fn parse_setting(kv: &str) -> Result<Setting> {
    kv.split(';')
        .filter(|s| !s.is_empty())
        .map(|p| {
            let (k, v) = p.split_once('=').context("KEY=V")?;
            Ok((k.to_string(), v.to_string()))
        })
        .collect()
}

struct Args {
    renders: Vec<PathBuf>,
    held_out: Vec<PathBuf>,
    grid: Vec<(String, Vec<String>)>,
    extra: Vec<Setting>,
    bench: Option<PathBuf>,
    bench_runs: usize,
    threads: usize,
    out: PathBuf,
    write: bool,
    /// Print every light a setting lost (below [`KEPT_PEAK`]).
    list_lost: bool,
}

fn parse(args: &[String]) -> Result<Args> {
    let mut a = Args {
        renders: Vec::new(),
        held_out: Vec::new(),
        grid: Vec::new(),
        extra: Vec::new(),
        bench: None,
        bench_runs: 3,
        threads: 2,
        out: PathBuf::from("docs"),
        write: true,
        list_lost: false,
    };
    let mut it = args.iter();
    while let Some(x) = it.next() {
        let mut next = |what: &str| it.next().cloned().with_context(|| what.to_string());
        match x.as_str() {
            "--sweep" => {}
            "--renders" => a.renders.push(next("--renders DIR")?.into()),
            "--held-out" => a.held_out.push(next("--held-out DIR")?.into()),
            "--grid" => {
                let kv = next("--grid KEY=V1,V2")?;
                let (k, v) = kv.split_once('=').context("--grid KEY=V1,V2")?;
                a.grid
                    .push((k.to_string(), v.split(',').map(str::to_string).collect()));
            }
            "--also" => {
                // One more setting beside the grid: KEY=V;KEY=V.
                a.extra.push(parse_setting(&next("--also KEY=V;KEY=V")?)?);
            }
            "--bench" => a.bench = Some(next("--bench FILE")?.into()),
            "--bench-runs" => a.bench_runs = next("--bench-runs N")?.parse()?,
            "--threads" => a.threads = next("--threads N")?.parse()?,
            "--out" => a.out = next("--out DIR")?.into(),
            "--no-write" => a.write = false,
            "--list-lost" => a.list_lost = true,
            other => bail!("--sweep: unknown argument {other:?}"),
        }
    }
    if a.renders.is_empty() {
        a.renders.push("../shared/renders".into());
    }
    if a.grid.is_empty() {
        a.grid = DEFAULT_GRID
            .iter()
            .map(|(k, v)| (k.to_string(), v.iter().map(|s| s.to_string()).collect()))
            .collect();
    }
    Ok(a)
}

/// Every combination of the grid's values.
fn settings(grid: &[(String, Vec<String>)]) -> Vec<Setting> {
    let mut out: Vec<Setting> = vec![Vec::new()];
    for (k, vs) in grid {
        out = out
            .into_iter()
            .flat_map(|s| {
                vs.iter().map(move |v| {
                    let mut t = s.clone();
                    t.push((k.clone(), v.clone()));
                    t
                })
            })
            .collect();
    }
    out
}

pub(super) fn label(s: &Setting) -> String {
    if s.is_empty() {
        return "(defaults)".into();
    }
    s.iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The knob values of a preset, as a setting.
fn preset_setting(q: Quality) -> Setting {
    FilterParams::new(Method::EpGauss, 3)
        .with_quality(q)
        .quality_settings()
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
}

/// The old defaults (before the presets), as a setting.
fn old_defaults() -> Setting {
    [
        ("tolerance", "0.25"),
        ("support", "1"),
        ("support_ratio", "16"),
        ("support_group", "0"),
        ("support_compact", "0"),
        ("support_over", "0"),
        ("support_region", "0"),
        ("support_level", "4"),
        ("radius", "0.6"),
        ("cutoff", "3"),
        ("max_radius", "16"),
        ("width_step", "0.1"),
        ("bound_from", "0"),
    ]
    .iter()
    .map(|(k, v)| (k.to_string(), v.to_string()))
    .collect()
}

/// `params` at S for `setting` (the grid's tolerance is at S = 3).
fn params_for(setting: &Setting, s: usize) -> Result<FilterParams> {
    let mut p = FilterParams::new(Method::EpGauss, s);
    for (k, v) in setting {
        if k == "tolerance" {
            let t: f64 = v.parse()?;
            p.tolerance = t * (3.0 / s as f64).powf(epfilt::filter::TOLERANCE_EXPONENT);
        } else if k == "quality" {
            p = p.with_quality(Quality::parse(v)?);
        } else {
            set(&mut p, k, v)?;
        }
    }
    Ok(p)
}

/// One super-sampled input with its linear filters, per radius.
struct Prepared {
    input: Input,
    /// From a `--held-out` folder: reported, never chosen on.
    held_out: bool,
    /// radius -> the linear filters at that radius.
    by_radius: BTreeMap<String, Baseline>,
    /// The oracle's best factor at radius 0.6.
    oracle: Option<f64>,
}

/// The linear filters of one input at one radius.
struct Baseline {
    /// Gauss of the reference.
    reference: Image,
    /// Its lights.
    lights: Vec<Vec<(usize, usize)>>,
    /// relMSE of gauss of the input.
    base: f64,
    /// Each light's brightest pixel in the Gaussian of the input, or in
    /// the reference where lower (a firefly on the light raises the
    /// linear filter's).
    lin_peaks: Vec<f64>,
}

struct Outcome {
    setting: Setting,
    factors: Vec<f64>,
    peaks: Vec<Option<f64>>,
    /// Lights, over every input chosen on, whose peak fell below
    /// [`KEPT_PEAK`].
    lost: usize,
    /// Lights over every input chosen on.
    lights: usize,
    /// The same over the held-out inputs.
    lost_held: usize,
    lights_held: usize,
    /// Geometric mean of the factors of the inputs chosen on, and of the
    /// held-out ones.
    error: f64,
    error_held: Option<f64>,
    seconds_per_mpx: Option<f64>,
    x_gauss: Option<f64>,
}

pub(super) fn run_filter(tmp: &Path, input: &Path, p: FilterParams, tag: &str) -> Result<Image> {
    let out = tmp.join(format!("{tag}.exr"));
    let job = FilterJob::new(input, &out, p);
    filter_file(&job, &|_, _| {}).with_context(|| format!("{tag}: {}", input.display()))?;
    Image::read(&out)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Seconds of `p` on the bench file (the run's own timer, which starts
/// after the file is opened), `threads` threads.
fn bench_seconds(bench: &Path, tmp: &Path, p: FilterParams, threads: usize) -> Result<f64> {
    let out = tmp.join("bench-out.exr");
    let mut job = FilterJob::new(bench, &out, p);
    job.pipeline.threads = threads;
    let r = filter_file(&job, &|_, _| {})?;
    Ok(r.seconds)
}

pub fn run(args: &[String]) -> Result<()> {
    let a = parse(args)?;
    let tmp = tempfile::tempdir()?;
    let mut prepared = Vec::new();
    let radii: Vec<String> = {
        let mut r: Vec<String> = a
            .grid
            .iter()
            .find(|(k, _)| k == "radius")
            .map_or_else(Vec::new, |(_, v)| v.clone());
        for s in a.extra.iter().flatten().filter(|(k, _)| k == "radius") {
            r.push(s.1.clone());
        }
        for q in Quality::ALL {
            for (k, v) in preset_setting(q) {
                if k == "radius" {
                    r.push(v);
                }
            }
        }
        r.push("0.6".into());
        r.sort();
        r.dedup();
        r
    };
    let dirs = (a.renders.iter().map(|d| (d, false))).chain(a.held_out.iter().map(|d| (d, true)));
    for (dir, held_out) in dirs {
        for inp in inputs(dir)?.into_iter().filter(|i| i.s > 1) {
            eprintln!("{}", inp.name);
            let noisy = Image::read(&inp.path)?;
            let mut by_radius = BTreeMap::new();
            for r in &radii {
                let mut pg = FilterParams::new(Method::Gauss, inp.s);
                pg.radius = r.parse()?;
                let mut pr = FilterParams::new(Method::Gauss, inp.reference_s);
                pr.radius = pg.radius;
                let reference = run_filter(tmp.path(), &inp.reference, pr, "ref")?;
                let lin = run_filter(tmp.path(), &inp.path, pg, "lin")?;
                let ls = lights(&reference);
                let base = rel_mse(&lin, &reference);
                let lin_peaks = light_peaks(&lin, &ls)
                    .into_iter()
                    .zip(light_peaks(&reference, &ls))
                    .map(|(l, r)| l.min(r))
                    .collect();
                by_radius.insert(
                    r.clone(),
                    Baseline {
                        reference,
                        lights: ls,
                        base,
                        lin_peaks,
                    },
                );
            }
            // The oracle at the default radius, where a super-sampled
            // reference of the same S exists.
            let oracle = if inp.reference_s == inp.s {
                let truth = Image::read(&inp.reference)?;
                let Baseline {
                    reference, base, ..
                } = &by_radius["0.6"];
                let mut best = f64::INFINITY;
                for over in ORACLE_OVER {
                    let (img, _) = super::oracle_input(&noisy, &truth, over);
                    let path = tmp.path().join("oracle.exr");
                    img.write(&path)?;
                    let out = run_filter(
                        tmp.path(),
                        &path,
                        FilterParams::new(Method::Gauss, inp.s),
                        "oracle-gauss",
                    )?;
                    best = best.min(rel_mse(&out, reference) / base);
                }
                Some(best)
            } else {
                None
            };
            prepared.push(Prepared {
                input: inp,
                held_out,
                by_radius,
                oracle,
            });
        }
    }
    if prepared.is_empty() {
        bail!("no super-sampled renders in {:?}", a.renders);
    }
    let mut all = settings(&a.grid);
    all.extend(a.extra.iter().cloned());
    all.push(old_defaults());
    for q in Quality::ALL {
        all.push(preset_setting(q));
    }
    // The same setting written twice runs once.
    let mut seen = std::collections::HashSet::new();
    all.retain(|s| {
        let mut k = s.clone();
        k.sort();
        seen.insert(k)
    });
    let mut outcomes = Vec::new();
    let bench_gauss = match &a.bench {
        Some(b) => {
            let mut v = Vec::new();
            for _ in 0..a.bench_runs {
                v.push(bench_seconds(
                    b,
                    tmp.path(),
                    FilterParams::new(Method::Gauss, 3),
                    a.threads,
                )?);
            }
            Some(v)
        }
        None => None,
    };
    let mut gauss_runs = bench_gauss.clone().unwrap_or_default();
    let n_all = all.len();
    for (k, setting) in all.into_iter().enumerate() {
        let mut factors = Vec::new();
        let mut peaks = Vec::new();
        let (mut lost, mut lights_seen) = (0, 0);
        let (mut lost_held, mut lights_held) = (0, 0);
        for p in &prepared {
            let params = params_for(&setting, p.input.s)?;
            let key = format!("{}", params.radius);
            let key = p
                .by_radius
                .keys()
                .find(|r| r.parse::<f64>().ok() == Some(params.radius))
                .cloned()
                .with_context(|| format!("radius {key} not prepared"))?;
            let Baseline {
                reference,
                lights: ls,
                base,
                lin_peaks,
            } = &p.by_radius[&key];
            let out = run_filter(tmp.path(), &p.input.path, params, "ep")?;
            factors.push(rel_mse(&out, reference) / base);
            // The light that lost most of its peak to the filter, against
            // the linear filter's (none where the reference shows no light).
            let ratios: Vec<f64> = light_peaks(&out, ls)
                .iter()
                .zip(lin_peaks)
                .map(|(e, l)| e / l.max(1e-12))
                .collect();
            let n_lost = ratios.iter().filter(|&&r| r < KEPT_PEAK).count();
            if p.held_out {
                lost_held += n_lost;
                lights_held += ratios.len();
            } else {
                lost += n_lost;
                lights_seen += ratios.len();
            }
            if a.list_lost {
                for (fp, r) in ls.iter().zip(&ratios).filter(|(_, &r)| r < KEPT_PEAK) {
                    let (x0, x1) = fp
                        .iter()
                        .fold((usize::MAX, 0), |(a, b), p| (a.min(p.0), b.max(p.0)));
                    let (y0, y1) = fp
                        .iter()
                        .fold((usize::MAX, 0), |(a, b), p| (a.min(p.1), b.max(p.1)));
                    eprintln!(
                        "  lost: {} light at x {x0}..={x1} y {y0}..={y1} ({} px): {r:.2}",
                        p.input.name,
                        fp.len()
                    );
                }
            }
            peaks.push(ratios.into_iter().reduce(f64::min));
        }
        let geo = |held: bool| -> Option<f64> {
            let v: Vec<f64> = (factors.iter().zip(&prepared))
                .filter(|(_, p)| p.held_out == held)
                .map(|(f, _)| f.ln())
                .collect();
            (!v.is_empty()).then(|| (v.iter().sum::<f64>() / v.len() as f64).exp())
        };
        let error = geo(false).context("no render to choose on (only --held-out)")?;
        let error_held = geo(true);
        let (mut seconds_per_mpx, mut x_gauss) = (None, None);
        if let Some(b) = &a.bench {
            let mut ep = Vec::new();
            // Pairs in alternating order (gauss first, then the setting
            // first): a run right after another method's pays for what that
            // one left in the caches, and measured 3% slower in one order.
            for r in 0..a.bench_runs {
                let g = FilterParams::new(Method::Gauss, 3);
                let e = params_for(&setting, 3)?;
                let (first, second) = if r % 2 == 0 { (g, e) } else { (e, g) };
                let t1 = bench_seconds(b, tmp.path(), first, a.threads)?;
                let t2 = bench_seconds(b, tmp.path(), second, a.threads)?;
                let (tg, te) = if r % 2 == 0 { (t1, t2) } else { (t2, t1) };
                gauss_runs.push(tg);
                ep.push(te);
            }
            // Against the gauss runs beside these (the machine drifts).
            let recent = gauss_runs[gauss_runs.len() - a.bench_runs..].to_vec();
            let mpx = 6144.0 * 6144.0 / 1e6;
            let e = median(ep);
            seconds_per_mpx = Some(e / mpx);
            x_gauss = Some(e / median(recent));
        }
        eprintln!(
            "[{}/{n_all}] {}: error {error:.4}{}{}",
            k + 1,
            label(&setting),
            error_held
                .map(|e| format!(", held out {e:.4}"))
                .unwrap_or_default(),
            x_gauss
                .map(|x| format!(", {x:.3}x gauss"))
                .unwrap_or_default()
        );
        outcomes.push(Outcome {
            setting,
            factors,
            peaks,
            lost,
            lights: lights_seen,
            lost_held,
            lights_held,
            error,
            error_held,
            seconds_per_mpx,
            x_gauss,
        });
    }
    let md = markdown(&a, &prepared, &outcomes, &gauss_runs);
    print!("{md}");
    if a.write {
        std::fs::create_dir_all(&a.out)?;
        std::fs::write(a.out.join("pareto.md"), &md)?;
        std::fs::write(a.out.join("pareto.csv"), csv(&prepared, &outcomes))?;
        if a.bench.is_some() {
            plot(&a.out.join("pareto"), &outcomes)?;
        }
        eprintln!("wrote {}", a.out.join("pareto.md").display());
    }
    Ok(())
}

/// Indices of the settings on the Pareto front (no other is both faster and
/// better), by time then error; without times, by error alone.
/// The Pareto front of time against error among the settings that keep
/// every light the old defaults keep (no more lights below [`KEPT_PEAK`]:
/// the issue's "lights within 20%" is a constraint, not a term to trade).
fn front(outcomes: &[Outcome]) -> Vec<usize> {
    let allowed = find(outcomes, &old_defaults()).map_or(usize::MAX, |j| outcomes[j].lost);
    let mut idx: Vec<usize> = (0..outcomes.len())
        .filter(|&i| outcomes[i].lost <= allowed)
        .collect();
    let t = |i: usize| outcomes[i].seconds_per_mpx.unwrap_or(0.0);
    idx.sort_by(|&a, &b| {
        t(a).total_cmp(&t(b))
            .then(outcomes[a].error.total_cmp(&outcomes[b].error))
    });
    let mut best = f64::INFINITY;
    let mut out = Vec::new();
    for i in idx {
        if outcomes[i].error < best {
            best = outcomes[i].error;
            out.push(i);
        }
    }
    out
}

fn find(outcomes: &[Outcome], s: &Setting) -> Option<usize> {
    let key = |s: &Setting| {
        let mut k = s.clone();
        k.sort();
        k
    };
    outcomes.iter().position(|o| key(&o.setting) == key(s))
}

fn markdown(a: &Args, prepared: &[Prepared], outcomes: &[Outcome], gauss: &[f64]) -> String {
    let mut s = String::new();
    let names: Vec<String> = prepared
        .iter()
        .map(|p| {
            let n = p
                .input
                .name
                .replace("_ss3x_768", "")
                .replace("_ss4x_1024", " S=4");
            if p.held_out {
                format!("{n} (held out)")
            } else {
                n
            }
        })
        .collect();
    let _ = writeln!(
        s,
        "# ep-gauss: the speed/accuracy trade on real renders\n\nMade by `scripts/eval-renders --sweep` \
         (`lab/src/bin/eval-renders/sweep.rs` defines every figure) on {} super-sampled inputs from {}. \
         **factor**: relMSE against the Gaussian of the reference over the relMSE the Gaussian of the \
         same radius leaves (below 1: noise removed); **error**: the geometric mean of a setting's \
         factors over every input; **worst vs old**: the largest ratio of its factor to the old \
         defaults' on one input (above 1: that render got worse); **worst vs best**: the largest \
         ratio of its factor to the best factor any setting of this sweep reached on one input (what \
         it loses on its worst render to the setting that would have suited that render); **lights < 0.8**: lights (bright \
         components of the reference, every input) whose brightest pixel fell below 0.8 of the linear filter's \
         (or of the reference's, where lower: a firefly on a light raises the linear filter's), of all; \
         **peak**: the worst such ratio (each input's cell: factor; its worst light's ratio, – where none). **s/Mpx**: seconds per input megapixel of \
         ep-gauss on the 6144x6144 bench input ({} threads, median of {} runs paired with gauss in alternating order), \
         **x gauss**: the ratio of the medians.{}{}\n",
        prepared.len(),
        a.renders
            .iter()
            .map(|d| format!("`{}`", d.display()))
            .collect::<Vec<_>>()
            .join(", "),
        a.threads,
        a.bench_runs,
        if prepared.iter().any(|p| p.held_out) {
            format!(
                " **Held out** ({}): renders no choice was made on; their factors are in every \
                 table, apart from the error, the lights, the front and the worst ratios, which \
                 have held-out columns of their own.",
                a.held_out
                    .iter()
                    .map(|d| format!("`{}`", d.display()))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        } else {
            String::new()
        },
        if gauss.is_empty() {
            " No bench file was given: no times.".to_string()
        } else {
            format!(
                " gauss: {:.4} s/Mpx (median of {}; its runs {:.3}..{:.3} s: on a shared \
                 host a setting's ratio moves by a few hundredths between sweeps, so points \
                 closer than that in time are a tie). The front joins the settings that lose no \
                 more lights than the old defaults.",
                median(gauss.to_vec()) / (6144.0 * 6144.0 / 1e6),
                gauss.len(),
                gauss.iter().copied().fold(f64::INFINITY, f64::min),
                gauss.iter().copied().fold(0.0, f64::max)
            )
        }
    );
    let old = find(outcomes, &old_defaults());
    let marks = |i: usize| -> String {
        let mut m = Vec::new();
        if Some(i) == old {
            m.push("old defaults".to_string());
        }
        for q in Quality::ALL {
            if find(outcomes, &preset_setting(q)) == Some(i) {
                m.push(format!("**--quality {}**", q.name()));
            }
        }
        m.join(", ")
    };
    let chosen = |k: usize| !prepared[k].held_out;
    let worst_vs_old = |o: &Outcome| -> f64 {
        old.map_or(f64::NAN, |j| {
            (0..o.factors.len())
                .filter(|&k| chosen(k))
                .map(|k| o.factors[k] / outcomes[j].factors[k])
                .fold(0.0, f64::max)
        })
    };
    // The best factor any setting reached on each input.
    let best: Vec<f64> = (0..prepared.len())
        .map(|k| {
            outcomes
                .iter()
                .map(|o| o.factors[k])
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    let worst_vs_best = |o: &Outcome, held: bool| -> f64 {
        (0..o.factors.len())
            .filter(|&k| prepared[k].held_out == held)
            .map(|k| o.factors[k] / best[k])
            .fold(0.0, f64::max)
    };
    let any_held = prepared.iter().any(|p| p.held_out);
    let row = |i: usize, o: &Outcome| -> String {
        let held = if any_held {
            format!(
                " {:.4} | {:.3} | {}/{} |",
                o.error_held.unwrap_or(f64::NAN),
                worst_vs_best(o, true),
                o.lost_held,
                o.lights_held
            )
        } else {
            String::new()
        };
        format!(
            "| {} | {} | {} | {:.4} | {:.3} | {:.3} | {}/{} | {} |{held} {} | {} |",
            label(&o.setting),
            o.seconds_per_mpx.map_or("–".into(), |t| format!("{t:.4}")),
            o.x_gauss.map_or("–".into(), |x| format!("{x:.3}")),
            o.error,
            worst_vs_old(o),
            worst_vs_best(o, false),
            o.lost,
            o.lights,
            min_peak(o).map_or("–".into(), |p| format!("{p:.2}")),
            o.factors
                .iter()
                .zip(&o.peaks)
                .map(|(f, p)| match p {
                    Some(p) => format!("{f:.3}; {p:.2}"),
                    None => format!("{f:.3}; –"),
                })
                .collect::<Vec<_>>()
                .join(" | "),
            marks(i)
        )
    };
    let held_head = if any_held {
        " held-out error | held-out worst vs best | held-out lights < 0.8 |"
    } else {
        ""
    };
    let head = format!(
        "| setting | s/Mpx | x gauss | error | worst vs old | worst vs best | lights < 0.8 | peak |{held_head} {} | |\n|---|---|---|---|---|---|---|---|{}{}---|",
        names.join(" | "),
        if any_held { "---|---|---|" } else { "" },
        "---|".repeat(names.len())
    );
    let _ = writeln!(s, "## The Pareto front\n\n{head}");
    for i in front(outcomes) {
        let _ = writeln!(s, "{}", row(i, &outcomes[i]));
    }
    let _ = writeln!(s, "\n## The old defaults and the presets\n\n{head}");
    let mut shown: Vec<usize> = old.into_iter().collect();
    for q in Quality::ALL {
        shown.extend(find(outcomes, &preset_setting(q)));
    }
    for i in shown {
        let _ = writeln!(s, "{}", row(i, &outcomes[i]));
    }
    let oracle: Vec<String> = prepared
        .iter()
        .map(|p| p.oracle.map_or("–".into(), |o| format!("{o:.3}")))
        .collect();
    let _ = writeln!(
        s,
        "| outlier-only oracle (radius 0.6; `docs/renders.md`) | | | | | | | |{} {} | |",
        if any_held { " | | |" } else { "" },
        oracle.join(" | ")
    );
    let mut order: Vec<usize> = (0..outcomes.len()).collect();
    order.sort_by(|&a, &b| outcomes[a].error.total_cmp(&outcomes[b].error));
    let _ = writeln!(s, "\n## Every setting, by error\n\n{head}");
    for i in order {
        let _ = writeln!(s, "{}", row(i, &outcomes[i]));
    }
    s
}

/// The brightest pixel of each light (its luminance).
pub(super) fn light_peaks(img: &Image, lights: &[Vec<(usize, usize)>]) -> Vec<f64> {
    lights
        .iter()
        .map(|fp| fp.iter().map(|&(x, y)| img.y(x, y)).fold(0.0, f64::max))
        .collect()
}

/// A setting's worst light over every input (none: no input shows one).
fn min_peak(o: &Outcome) -> Option<f64> {
    o.peaks.iter().flatten().copied().reduce(f64::min)
}

fn csv(prepared: &[Prepared], outcomes: &[Outcome]) -> String {
    let mut s =
        String::from("setting,seconds_per_mpx,x_gauss,error,min_peak,lights_lost,error_held_out,lights_lost_held_out");
    let tag = |p: &Prepared| if p.held_out { " (held out)" } else { "" };
    for p in prepared {
        let _ = write!(s, ",{}{}", p.input.name, tag(p));
    }
    for p in prepared {
        let _ = write!(s, ",peak {}{}", p.input.name, tag(p));
    }
    s.push('\n');
    for o in outcomes {
        let _ = write!(
            s,
            "{},{},{},{:.6},{}",
            label(&o.setting),
            o.seconds_per_mpx
                .map_or(String::new(), |t| format!("{t:.6}")),
            o.x_gauss.map_or(String::new(), |t| format!("{t:.4}")),
            o.error,
            min_peak(o).map_or(String::new(), |p| format!("{p:.4}")),
        );
        let _ = write!(
            s,
            ",{},{},{}",
            o.lost,
            o.error_held.map_or(String::new(), |e| format!("{e:.6}")),
            o.lost_held
        );
        for f in &o.factors {
            let _ = write!(s, ",{f:.6}");
        }
        for p in &o.peaks {
            let _ = write!(s, ",{}", p.map_or(String::new(), |p| format!("{p:.4}")));
        }
        s.push('\n');
    }
    s
}

/// `STEM.png` and `STEM.svg`: each setting's error against its time, the
/// Pareto front, the old defaults and the presets. Only the settings that
/// lose no more lights than the old defaults are drawn (the others are not
/// eligible, and the paper's rule, far off in both, would squash the rest
/// into a corner).
fn plot(stem: &Path, outcomes: &[Outcome]) -> Result<()> {
    use epfilt_lab::chart::{save, Chart, Series, Style};
    let allowed = find(outcomes, &old_defaults()).map_or(usize::MAX, |j| outcomes[j].lost);
    let point = |o: &Outcome| o.seconds_per_mpx.map(|t| (t, o.error));
    let eligible: Vec<(f64, f64)> = (outcomes.iter().filter(|o| o.lost <= allowed))
        .filter_map(point)
        .collect();
    if eligible.is_empty() {
        return Ok(());
    }
    let series = Series::new;
    let front: Vec<(f64, f64)> = (front(outcomes).into_iter())
        .filter_map(|i| point(&outcomes[i]))
        .collect();
    let marked = |s: &Setting| find(outcomes, s).and_then(|i| point(&outcomes[i]));
    let mut old = series("the old defaults", (200, 0, 0), Style::Crosses, Vec::new());
    old.points.extend(marked(&old_defaults()));
    old.labels.push("old defaults".into());
    let mut presets = series(
        "the --quality presets",
        (0, 130, 0),
        Style::Crosses,
        Vec::new(),
    );
    for q in Quality::ALL {
        if let Some(p) = marked(&preset_setting(q)) {
            presets.points.push(p);
            presets.labels.push(format!("--quality {}", q.name()));
        }
    }
    let chart = Chart {
        title: "ep-gauss on real renders: error against time, one point a setting".into(),
        x_label: "seconds per input megapixel (6144x6144 bench, S = 3)".into(),
        y_label: "error: geometric mean of the renders' factors (lower is better)".into(),
        log: (false, false),
        series: vec![
            series(
                "a setting losing no more lights than the old defaults",
                (150, 150, 150),
                Style::Dots,
                eligible,
            ),
            series("the Pareto front", (0, 0, 200), Style::Line, front),
            old,
            presets,
        ],
    };
    save(&[chart], stem)
}

/// Draw `DIR/pareto.png` and `.svg` again from `DIR/pareto.csv`, without
/// measuring anything.
pub fn replot(dir: &Path) -> Result<()> {
    let names = ["setting", "seconds_per_mpx", "error", "lights_lost"];
    let rows = epfilt_lab::chart::csv_columns(&dir.join("pareto.csv"), &names)?;
    let mut outcomes = Vec::new();
    for f in rows {
        let setting = (f[0].split_whitespace())
            .filter_map(|kv| kv.split_once('='))
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        outcomes.push(Outcome {
            setting,
            factors: Vec::new(),
            peaks: Vec::new(),
            lost: f[3].parse()?,
            lights: 0,
            lost_held: 0,
            lights_held: 0,
            error: f[2].parse()?,
            error_held: None,
            seconds_per_mpx: f[1].parse().ok(),
            x_gauss: None,
        });
    }
    plot(&dir.join("pareto"), &outcomes)
}
