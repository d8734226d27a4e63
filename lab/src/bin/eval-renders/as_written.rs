//! `eval_renders --as-written`: renders as renderers write them, from every
//! folder given (default `../shared/renders`).
//!
//! **At final resolution** (`<scene>_px_<res>_spp<N>.exr` beside
//! `<scene>_ref_<res>.exr`), filtered at S = 1:
//!
//! * **ep-gauss without variance or guides** (`--guides none`; ep-gauss at
//!   S = 1 reads no variance): what a render with nothing beside its beauty
//!   gets;
//! * ep-gauss with the **emission** guide only, and with **every** guide the
//!   file has (emission, albedo, normal, depth);
//! * **ep-box** (the variance) without guides (as before guides existed), and
//!   with every guide.
//!
//! Measures, each against the reference itself (no linear filter: at S = 1
//! nothing is blurred):
//!
//! * **ratio**: relMSE(out) / relMSE(input), relMSE `= mean (x - ref)^2 /
//!   (ref^2 + 1e-2)` over pixels and channels; below 1 the filter removed
//!   error, above 1 it made the render worse;
//! * **lost**: lights the input had and the output lost: the reference's
//!   lights (connected pixels above 30 times the median, grown by a pixel)
//!   whose brightest input pixel is at least half the reference's and whose
//!   brightest output pixel is below half; **lamps** are the lights with a
//!   pixel the emission guide calls a light (the rest: caustics, highlights);
//! * **emit**: over the pixels whose emission guide holds at least half the
//!   beauty's luminance, the largest relative change of luminance (the
//!   guide's promise: those keep their values);
//! * **ledger**: the largest relative energy error before rounding.
//!
//! **Super-sampled** (`<scene>_ss<S>x_<res>_spp<N>.exr` beside
//! `<scene>_ssref<S>x_<res>.exr`, with guides): ep-gauss with and without
//! the emission guide; the **factor** is the defaults' table's (relMSE
//! against the reference's Gaussian over the relMSE the input's Gaussian
//! leaves), lost lights against the input's Gaussian.
//!
//! Writes `renders-as-written.md` and `.csv` into `--out` (default
//! `docs/bench`) with the command, machine, versions and date, and prints
//! the Markdown.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use epfilt::io::{ExrInput, GuideRequest};
use epfilt::pipeline::Source;
use epfilt::{filter_file, FilterJob, FilterParams, Method};

use super::{inputs, lights, rel_mse, Image};

/// A light the input had: its peak at least this share of the reference's;
/// lost when the output's falls below it.
const LIGHT_KEPT: f64 = 0.5;

/// One setting of the table.
struct Setting {
    name: &'static str,
    method: Method,
    guides: &'static str,
}

const SETTINGS: [Setting; 5] = [
    Setting {
        name: "ep-gauss",
        method: Method::EpGauss,
        guides: "none",
    },
    Setting {
        name: "ep-gauss + emission",
        method: Method::EpGauss,
        guides: "emission",
    },
    Setting {
        name: "ep-gauss + guides",
        method: Method::EpGauss,
        guides: "auto",
    },
    Setting {
        name: "ep-box",
        method: Method::EpBox,
        guides: "none",
    },
    Setting {
        name: "ep-box + guides",
        method: Method::EpBox,
        guides: "auto",
    },
];

/// One filtered render at final resolution.
struct Row {
    input: String,
    spp: u32,
    setting: &'static str,
    input_rel_mse: f64,
    rel_mse: f64,
    lost: usize,
    lights: usize,
    lamps_lost: usize,
    lamps: usize,
    emit: Option<f64>,
    ledger: f64,
    seconds: f64,
    /// `+ guides` rows: the share of what ep-gauss with the emission guide
    /// moves that the surface guides send elsewhere (`sum |all - emission|
    /// / 2 sum |emission - input|`).
    redirected: Option<f64>,
}

/// One super-sampled render, ep-gauss without and with the emission guide.
struct SsRow {
    input: String,
    s: usize,
    spp: u32,
    /// (factor, lights lost, ledger) without, then with the guide.
    runs: [(f64, usize, f64); 2],
    lights: usize,
}

/// The luminance of an image's pixels.
fn luminance(img: &Image) -> Vec<f64> {
    (0..img.h)
        .flat_map(|y| (0..img.w).map(move |x| (x, y)))
        .map(|(x, y)| img.y(x, y))
        .collect()
}

/// The emission layer's R, G, B, where the file has one.
fn emission(path: &Path) -> Option<Image> {
    let input = ExrInput::open_view(path, None, Some("emission"), None).ok()?;
    let (w, h) = input.size();
    if input.channels().len() < 3 {
        return None;
    }
    let n = input.channels().len();
    let mut src = input.source();
    let mut data = Vec::with_capacity(w * h * 3);
    while let Some(strip) = src.next_strip(64).ok()? {
        for r in 0..strip.rows {
            data.extend_from_slice(&strip.data[r * n * w..(r * n + 3) * w]);
        }
    }
    Some(Image { w, h, data })
}

/// The peaks of `img` over each light's footprint.
fn peaks(img: &Image, lights: &[Vec<(usize, usize)>]) -> Vec<f64> {
    lights
        .iter()
        .map(|fp| fp.iter().map(|&(x, y)| img.y(x, y)).fold(0.0, f64::max))
        .collect()
}

/// Filter `input` into `out` with `method` at S = `s` and `guides`; the
/// image written and the report.
fn filter(
    input: &Path,
    out: &Path,
    (method, s): (Method, usize),
    guides: &str,
) -> Result<(Image, epfilt::report::Report)> {
    let mut job = FilterJob::new(input, out, FilterParams::new(method, s));
    job.guides = GuideRequest::parse(guides, &[])?;
    let report = filter_file(&job, &|_, _| {})
        .with_context(|| format!("{} {}", method.name(), input.display()))?;
    Ok((Image::read(out)?, report))
}

/// How many lights (of `of`, indices) the input had and the output lost.
fn lost(inp: &[f64], out: &[f64], reference: &[f64], of: impl Iterator<Item = usize>) -> usize {
    of.filter(|&k| inp[k] >= LIGHT_KEPT * reference[k] && out[k] < LIGHT_KEPT * reference[k])
        .count()
}

/// Run `--as-written` (argument list as given to the example).
pub fn run(argv: &[String]) -> Result<()> {
    let mut dirs: Vec<PathBuf> = Vec::new();
    let mut out_dir = PathBuf::from("docs/bench");
    let mut args = argv.iter();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--as-written" => {}
            "--renders" => dirs.push(args.next().context("--renders DIR")?.into()),
            "--out" => out_dir = args.next().context("--out DIR")?.into(),
            other => anyhow::bail!("--as-written: unknown argument {other:?}"),
        }
    }
    if dirs.is_empty() {
        dirs.push("../shared/renders".into());
    }
    let tmp = tempfile::tempdir()?;
    let (mut rows, mut ss_rows) = (Vec::new(), Vec::new());
    for dir in &dirs {
        for inp in inputs(dir)? {
            eprintln!("{}", inp.name);
            if inp.s == 1 {
                rows.extend(final_resolution(&inp, tmp.path())?);
            } else if inp.reference_s == inp.s && emission(&inp.path).is_some() {
                ss_rows.push(super_sampled(&inp, tmp.path())?);
            }
        }
    }
    let md = markdown(&rows, &ss_rows, &dirs, argv);
    print!("{md}");
    std::fs::create_dir_all(&out_dir)?;
    std::fs::write(out_dir.join("renders-as-written.md"), &md)?;
    std::fs::write(out_dir.join("renders-as-written.csv"), csv(&rows))?;
    eprintln!("wrote {}", out_dir.join("renders-as-written.md").display());
    Ok(())
}

/// Every setting on one render at final resolution.
fn final_resolution(inp: &super::Input, tmp: &Path) -> Result<Vec<Row>> {
    let input = Image::read(&inp.path)?;
    let reference = Image::read(&inp.reference)?;
    let ls = lights(&reference);
    let (ref_peaks, in_peaks) = (peaks(&reference, &ls), peaks(&input, &ls));
    let base = rel_mse(&input, &reference);
    let em = emission(&inp.path);
    let lamp: Vec<bool> = match &em {
        Some(e) => luminance(e)
            .iter()
            .zip(luminance(&input))
            .map(|(&e, y)| y > 0.0 && e >= 0.5 * y)
            .collect(),
        None => Vec::new(),
    };
    let lamps: Vec<usize> = (0..ls.len())
        .filter(|&k| {
            ls[k]
                .iter()
                .any(|&(x, y)| lamp.get(y * input.w + x) == Some(&true))
        })
        .collect();
    let mut rows = Vec::new();
    let mut emission_only: Option<Image> = None;
    for st in &SETTINGS {
        if st.guides != "none" && em.is_none() {
            continue; // a file without guides: the row without them is it
        }
        let out = tmp.join(format!("{}-{}.exr", inp.name, st.name));
        let (img, report) = filter(&inp.path, &out, (st.method, 1), st.guides)?;
        let out_peaks = peaks(&img, &ls);
        let redirected = match (st.name, &emission_only) {
            ("ep-gauss + guides", Some(e)) => {
                let moved: f64 = (e.data.iter().zip(&input.data))
                    .map(|(&a, &b)| (a as f64 - b as f64).abs())
                    .sum();
                let sent: f64 = (img.data.iter().zip(&e.data))
                    .map(|(&a, &b)| (a as f64 - b as f64).abs())
                    .sum();
                Some(sent / (2.0 * moved).max(f64::MIN_POSITIVE))
            }
            _ => None,
        };
        if st.name == "ep-gauss + emission" {
            emission_only = Some(img.clone());
        }
        let emit = (!lamp.is_empty()).then(|| {
            let (yi, yo) = (luminance(&input), luminance(&img));
            (0..yi.len())
                .filter(|&k| lamp[k])
                .map(|k| (yo[k] - yi[k]).abs() / yi[k])
                .fold(0.0, f64::max)
        });
        rows.push(Row {
            input: inp.name.clone(),
            spp: inp.spp,
            setting: st.name,
            input_rel_mse: base,
            rel_mse: rel_mse(&img, &reference),
            lost: lost(&in_peaks, &out_peaks, &ref_peaks, 0..ls.len()),
            lights: ls.len(),
            lamps_lost: lost(&in_peaks, &out_peaks, &ref_peaks, lamps.iter().copied()),
            lamps: lamps.len(),
            emit,
            ledger: report.energy_rel_error.iter().fold(0.0, |a, &b| a.max(b)),
            seconds: report.seconds,
            redirected,
        });
    }
    Ok(rows)
}

/// ep-gauss with and without the emission guide on a super-sampled render.
fn super_sampled(inp: &super::Input, tmp: &Path) -> Result<SsRow> {
    let t = |what: &str| tmp.join(format!("{}-{what}.exr", inp.name));
    let (gref, _) = filter(
        &inp.reference,
        &t("ref-gauss"),
        (Method::Gauss, inp.s),
        "none",
    )?;
    let (gin, _) = filter(&inp.path, &t("gauss"), (Method::Gauss, inp.s), "none")?;
    let base = rel_mse(&gin, &gref);
    let ls = lights(&gref);
    let (ref_peaks, in_peaks) = (peaks(&gref, &ls), peaks(&gin, &ls));
    let mut runs = [(0.0, 0, 0.0); 2];
    for (k, guides) in ["none", "emission"].into_iter().enumerate() {
        let (img, report) = filter(&inp.path, &t(guides), (Method::EpGauss, inp.s), guides)?;
        runs[k] = (
            rel_mse(&img, &gref) / base,
            lost(&in_peaks, &peaks(&img, &ls), &ref_peaks, 0..ls.len()),
            report
                .energy_rel_error
                .iter()
                .fold(0.0f64, |a, &b| a.max(b)),
        );
    }
    Ok(SsRow {
        input: inp.name.clone(),
        s: inp.s,
        spp: inp.spp,
        runs,
        lights: ls.len(),
    })
}

fn csv(rows: &[Row]) -> String {
    let mut s = String::from(
        "input,spp,setting,input_rel_mse,rel_mse,ratio,lights_lost,lights,lamps_lost,lamps,emission_change,ledger_rel_error,seconds,redirected\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{:.6e},{:.6e},{:.6},{},{},{},{},{},{:.3e},{:.4},{}",
            r.input,
            r.spp,
            r.setting,
            r.input_rel_mse,
            r.rel_mse,
            r.rel_mse / r.input_rel_mse,
            r.lost,
            r.lights,
            r.lamps_lost,
            r.lamps,
            r.emit.map_or(String::new(), |e| format!("{e:.6}")),
            r.ledger,
            r.seconds,
            r.redirected.map_or(String::new(), |v| format!("{v:.4}"))
        );
    }
    s
}

/// What made the table: command, machine, versions, date.
fn provenance(dirs: &[PathBuf], argv: &[String]) -> String {
    let run = |cmd: &str, args: &[&str]| {
        std::process::Command::new(cmd)
            .args(args)
            .output()
            .ok()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
            .unwrap_or_default()
    };
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let dirs: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
    format!(
        "Made by `scripts/eval-renders {}` ({}) on {} ({} cores), epfilt {} ({}), {}, {}.",
        argv.join(" "),
        dirs.join(", "),
        cpu,
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        env!("CARGO_PKG_VERSION"),
        run("git", &["rev-parse", "--short", "HEAD"]),
        run("rustc", &["--version"]),
        run("date", &["-u", "+%Y-%m-%d %H:%M UTC"]),
    )
}

fn markdown(rows: &[Row], ss: &[SsRow], dirs: &[PathBuf], argv: &[String]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Renders as renderers write them\n\n{}\n\n## At final resolution (S = 1)\n\n\
         Each render at pixel resolution filtered at S = 1 (`lab/src/bin/eval-renders/as_written.rs` \
         defines every measure). **ratio**: relMSE(output) / relMSE(input) against the reference \
         (below 1: less error than the render had); **lost**: lights the input had (peak at least \
         half the reference's) whose output peak fell below half, of all the reference's lights \
         (lamps: those the emission guide names); \
         **emit**: the largest relative change of a pixel whose emission guide holds at least half \
         its luminance; **redirected**: of what ep-gauss with the emission guide moves, the share the \
         surface guides send elsewhere (what they can change at most); **ledger**: the largest \
         relative energy error. `ep-gauss` reads neither the \
         variance nor any guide; `+ emission`: the emission guide; `+ guides`: every guide the file \
         has.\n",
        provenance(dirs, argv)
    );
    let mut inputs: Vec<&str> = rows.iter().map(|r| r.input.as_str()).collect();
    inputs.dedup();
    let _ = write!(s, "| input | relMSE in |");
    for st in &SETTINGS {
        let _ = write!(s, " {} |", st.name);
    }
    let _ = writeln!(s, "\n|---|---|{}", "---|".repeat(SETTINGS.len()));
    for i in &inputs {
        let of = |name: &str| rows.iter().find(|r| r.input == *i && r.setting == name);
        let first = rows.iter().find(|r| r.input == *i).expect("a row");
        let _ = write!(s, "| {} | {:.4} |", i, first.input_rel_mse);
        for st in &SETTINGS {
            let cell = of(st.name).map_or("–".to_string(), |r| {
                format!(
                    "{:.3}; lost {}/{}{}{}",
                    r.rel_mse / r.input_rel_mse,
                    r.lost,
                    r.lights,
                    if r.lamps > 0 {
                        format!(" (lamps {}/{})", r.lamps_lost, r.lamps)
                    } else {
                        String::new()
                    },
                    r.emit.map_or(String::new(), |e| format!("; emit {:.3}", e))
                ) + &r
                    .redirected
                    .map_or(String::new(), |v| format!("; redirected {:.1}%", 100.0 * v))
            });
            let _ = write!(s, " {cell} |");
        }
        let _ = writeln!(s);
    }
    let worst = |name: &str| {
        rows.iter()
            .filter(|r| r.setting == name)
            .map(|r| (r.rel_mse / r.input_rel_mse, r.input.as_str()))
            .fold((0.0f64, ""), |a, b| if b.0 > a.0 { b } else { a })
    };
    let _ = writeln!(
        s,
        "\n| setting | worst ratio | on | largest ledger error | seconds (all) |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|");
    for st in &SETTINGS {
        let (w, on) = worst(st.name);
        let ledger = rows
            .iter()
            .filter(|r| r.setting == st.name)
            .map(|r| r.ledger)
            .fold(0.0f64, f64::max);
        let secs: f64 = rows
            .iter()
            .filter(|r| r.setting == st.name)
            .map(|r| r.seconds)
            .sum();
        let _ = writeln!(
            s,
            "| {} | {:.3} | {} | {:.1e} | {:.2} |",
            st.name, w, on, ledger, secs
        );
    }
    if !ss.is_empty() {
        let _ = writeln!(
            s,
            "\n## Super-sampled renders: ep-gauss and the emission guide\n\n\
             **factor**: relMSE against the reference's Gaussian over the relMSE the input's Gaussian \
             leaves (below 1: less error than the linear filter); **lost**: lights the Gaussian of the \
             input kept (peak at least half the reference's) that the output lost.\n"
        );
        let _ = writeln!(
            s,
            "| input | S | spp | ep-gauss | + emission | change | ledger |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|");
        for r in ss {
            let [(f0, l0, e0), (f1, l1, e1)] = r.runs;
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.3}; lost {}/{} | {:.3}; lost {}/{} | {:+.0}% | {:.1e} |",
                r.input,
                r.s,
                r.spp,
                f0,
                l0,
                r.lights,
                f1,
                l1,
                r.lights,
                100.0 * (f1 / f0 - 1.0),
                e0.max(e1)
            );
        }
    }
    s
}
