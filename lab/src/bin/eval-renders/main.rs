//! Every method at its defaults on every file of a folder of real renders
//! with high-sample references (`scripts/eval-renders`; default folder
//! `../shared/renders`, whose README defines the roles and the measures).
//!
//! ```text
//! cargo run --release -p epfilt-lab --bin eval-renders -- [--renders DIR] [--out DIR] [--methods a,b]
//!     [--set KEY=VALUE]... [--no-write]
//! ```
//!
//! Files are found by role from their names: `<scene>_px_<res>_spp<N>.exr`
//! (mean and variance, filtered at S = 1), `<scene>_ref_<res>.exr` (the
//! reference for those), `<scene>_ss<S>x_<res>_spp<N>.exr` (super-sampled,
//! filtered at S) and `<scene>_ssref<S>x_<res>.exr` (its reference). Measures:
//!
//! * **factor**: `relMSE(out) / relMSE(L(input))` against `L(reference)`,
//!   `L` the linear filter the method is built on: gauss for ep-gauss, gauss
//!   and clamp; the box for ep-box, box, median and alpha-trim (at S = 1 the
//!   box is the identity, so for ep-box this is `relMSE(out) /
//!   relMSE(input)` against the reference itself). Below 1: less error than
//!   the linear filter of the same family (than the unfiltered input, for
//!   ep-box). Without a super-sampled reference of the same S, `L` of the
//!   pixel-resolution reference at S = 1 stands in.
//! * relMSE `= mean (x - ref)^2 / (ref^2 + 1e-2)` over pixels and channels,
//!   RMSE, the energy ratio `sum(out) S^2 / sum(in)` of the file as written
//!   (worst channel) and the ledger's relative error before rounding, the
//!   share of **untouched** pixels (bit-identical to the linear filter's
//!   output: for ep-box, to the input), and the wall time of the run.
//! * **peak**: the lights of the reference (connected pixels whose luminance
//!   exceeds 30 times the median, and the pixel around them): the smallest
//!   ratio, over lights, of the output's brightest pixel in the footprint to
//!   the reference's (1: every light kept its peak).
//!
//! Writes `renders.md`, `renders.csv` and a montage PNG per input
//! (`renders/<input>.png`: input, linear, methods, reference) into `--out`
//! (default `docs`), and prints the Markdown.
//!
//! `--as-written` measures renders as renderers write them: at final
//! resolution with and without variance and guides, and super-sampled with
//! the emission guide (`as_written.rs`, `docs/bench/renders-as-written.md`);
//! `--sweep` runs ep-gauss over a grid of its knobs (`sweep.rs`; `--replot
//! DIR` draws its plot again from `DIR/pareto.csv`);
//! `--sweep-ep-box` runs ep-box over given settings of its knobs
//! (`box_sweep.rs`, `scripts/joint-search --method ep-box`).

mod as_written;
mod box_sweep;
mod sweep;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use epfilt::io::ExrInput;
use epfilt::pipeline::Source;
use epfilt::{filter_file, FilterJob, FilterParams, Method};

/// A light: connected reference pixels this many times the median luminance.
const LIGHT_OVER_MEDIAN: f64 = 30.0;

/// An image as planar rows `[row][channel][x]` of R, G, B.
#[derive(Clone)]
struct Image {
    w: usize,
    h: usize,
    data: Vec<f32>,
}

impl Image {
    fn read(path: &Path) -> Result<Image> {
        let input = ExrInput::open(path, None)?;
        let (w, h) = input.size();
        if input.channels().len() < 3 {
            bail!("{}: needs R, G, B", path.display());
        }
        let n = input.channels().len();
        let mut src = input.source();
        let mut data = Vec::with_capacity(w * h * 3);
        while let Some(strip) = src.next_strip(64)? {
            for r in 0..strip.rows {
                data.extend_from_slice(&strip.data[r * n * w..(r * n + 3) * w]);
            }
        }
        Ok(Image { w, h, data })
    }

    fn y(&self, x: usize, y: usize) -> f64 {
        let at = |c: usize| self.data[(y * 3 + c) * self.w + x] as f64;
        0.2126 * at(0) + 0.7152 * at(1) + 0.0722 * at(2)
    }

    fn sums(&self) -> [f64; 3] {
        let mut s = [0.0; 3];
        for (k, v) in self.data.iter().enumerate() {
            s[(k / self.w) % 3] += *v as f64;
        }
        s
    }
}

fn rel_mse(a: &Image, r: &Image) -> f64 {
    let n = a.data.len() as f64;
    a.data
        .iter()
        .zip(&r.data)
        .map(|(&x, &y)| {
            let (x, y) = (x as f64, y as f64);
            (x - y) * (x - y) / (y * y + 1e-2)
        })
        .sum::<f64>()
        / n
}

fn rmse(a: &Image, r: &Image) -> f64 {
    let n = a.data.len() as f64;
    (a.data
        .iter()
        .zip(&r.data)
        .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

/// Share of pixels whose three channels are bit-identical.
fn same_share(a: &Image, b: &Image) -> f64 {
    let mut same = 0usize;
    for y in 0..a.h {
        for x in 0..a.w {
            same += (0..3).all(|c| {
                let k = (y * 3 + c) * a.w + x;
                a.data[k].to_bits() == b.data[k].to_bits()
            }) as usize;
        }
    }
    same as f64 / (a.w * a.h) as f64
}

/// The oracle's thresholds: a sample is an outlier when its luminance is
/// above this many times the truth's mean over its 3x3 samples.
const ORACLE_OVER: [f64; 4] = [2.0, 3.0, 4.0, 8.0];

/// The oracle's input and the share of samples it corrected: `input` with
/// every sample whose luminance is above `over` times the mean of the
/// truth's luminance over its 3x3 samples (at least 1e-3) replaced by the
/// truth's sample, and the light they held above the truth spread evenly
/// over every sample, per channel, so the energy is the input's. It knows
/// which samples are outliers and what they should be, and spreads their
/// excess so thinly that it adds no visible error: no outlier-only filter
/// that treats that share of the samples can expect to do better, so its
/// gauss factor estimates the floor for such filters.
fn oracle_input(input: &Image, truth: &Image, over: f64) -> (Image, f64) {
    let (w, h) = (input.w, input.h);
    let mut out = input.clone();
    let mut excess = [0.0f64; 3];
    let mut n = 0usize;
    for y in 0..h {
        for x in 0..w {
            let mut local = 0.0;
            for yy in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                for xx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                    local += truth.y(xx, yy);
                }
            }
            let cells = ((y + 1).min(h - 1) + 1 - y.saturating_sub(1))
                * ((x + 1).min(w - 1) + 1 - x.saturating_sub(1));
            if input.y(x, y) <= over * (local / cells as f64).max(1e-3) {
                continue;
            }
            n += 1;
            for (c, e) in excess.iter_mut().enumerate() {
                let k = (y * 3 + c) * w + x;
                *e += input.data[k] as f64 - truth.data[k] as f64;
                out.data[k] = truth.data[k];
            }
        }
    }
    for (k, v) in out.data.iter_mut().enumerate() {
        *v = (*v as f64 + excess[(k / w) % 3] / (w * h) as f64) as f32;
    }
    (out, n as f64 / (w * h) as f64)
}

impl Image {
    fn write(&self, path: &Path) -> Result<()> {
        let (w, at) = (self.w, |x: usize, y: usize, c: usize| {
            self.data[(y * 3 + c) * self.w + x]
        });
        exr::prelude::write_rgb_file(path, w, self.h, |x, y| {
            (at(x, y, 0), at(x, y, 1), at(x, y, 2))
        })
        .with_context(|| path.display().to_string())
    }
}

/// The oracle floors of one super-sampled input (see [`oracle_input`]).
#[derive(Clone, Debug)]
struct Oracle {
    input: String,
    /// Share of the samples ep-gauss spread at its defaults.
    spread: f64,
    /// ep-gauss's factor at its defaults.
    ep_gauss: f64,
    /// Per [`ORACLE_OVER`]: the share of samples the oracle corrected and
    /// the gauss factor of its input.
    factors: Vec<(f64, f64)>,
}

/// Footprints of the reference's lights: connected components above the
/// threshold, each grown by one pixel.
fn lights(r: &Image) -> Vec<Vec<(usize, usize)>> {
    let mut ys: Vec<f64> = (0..r.h)
        .flat_map(|y| (0..r.w).map(move |x| (x, y)))
        .map(|(x, y)| r.y(x, y))
        .collect();
    ys.sort_by(f64::total_cmp);
    let t = LIGHT_OVER_MEDIAN * ys[ys.len() / 2].max(1e-6);
    let mut seen = vec![false; r.w * r.h];
    let mut out = Vec::new();
    for y0 in 0..r.h {
        for x0 in 0..r.w {
            if seen[y0 * r.w + x0] || r.y(x0, y0) <= t {
                continue;
            }
            let mut comp = Vec::new();
            let mut stack = vec![(x0, y0)];
            seen[y0 * r.w + x0] = true;
            while let Some((x, y)) = stack.pop() {
                comp.push((x, y));
                for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= r.w as i64 || ny >= r.h as i64 {
                        continue;
                    }
                    let (nx, ny) = (nx as usize, ny as usize);
                    if !seen[ny * r.w + nx] && r.y(nx, ny) > t {
                        seen[ny * r.w + nx] = true;
                        stack.push((nx, ny));
                    }
                }
            }
            let mut grown = comp.clone();
            for &(x, y) in &comp {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        if nx >= 0 && ny >= 0 && nx < r.w as i64 && ny < r.h as i64 {
                            grown.push((nx as usize, ny as usize));
                        }
                    }
                }
            }
            grown.sort_unstable();
            grown.dedup();
            out.push(grown);
        }
    }
    out
}

/// A peak ratio as the tables print it: `–` where the reference has no
/// light (the ratio over no lights is infinite).
fn peak_text(p: f64) -> String {
    if p.is_finite() {
        format!("{p:.2}")
    } else {
        "–".into()
    }
}

/// Smallest ratio over lights of the output's peak to the reference's.
fn peak_ratio(out: &Image, r: &Image, lights: &[Vec<(usize, usize)>]) -> f64 {
    lights
        .iter()
        .map(|fp| {
            let peak = |img: &Image| fp.iter().map(|&(x, y)| img.y(x, y)).fold(0.0, f64::max);
            peak(out) / peak(r).max(1e-12)
        })
        .fold(f64::INFINITY, f64::min)
}

/// One scene's montage: the pixel-resolution panels, the super-sampled
/// ones, the reference.
type Montage = (
    Vec<(PathBuf, String)>,
    Vec<(PathBuf, String)>,
    Option<PathBuf>,
);

#[derive(Clone, Debug)]
struct Input {
    scene: String,
    path: PathBuf,
    name: String,
    s: usize,
    spp: u32,
    reference: PathBuf,
    /// The reference is at output resolution while the input is
    /// super-sampled: `L(reference)` is taken at S = 1.
    reference_s: usize,
}

/// The inputs of a folder, by role.
fn inputs(dir: &Path) -> Result<Vec<Input>> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| dir.display().to_string())?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".exr"))
        .collect();
    names.sort();
    let mut out = Vec::new();
    for n in &names {
        let stem = n.trim_end_matches(".exr");
        let parts: Vec<&str> = stem.split('_').collect();
        let Some(role_at) = parts.iter().position(|p| {
            *p == "px" || (p.starts_with("ss") && p.ends_with('x') && !p.starts_with("ssref"))
        }) else {
            continue;
        };
        let scene = parts[..role_at].join("_");
        let role = parts[role_at];
        let Some(spp) = parts
            .last()
            .and_then(|p| p.strip_prefix("spp"))
            .and_then(|v| v.parse().ok())
        else {
            continue;
        };
        let res = parts.get(role_at + 1).copied().unwrap_or("");
        let (s, reference, reference_s) = if role == "px" {
            (1, dir.join(format!("{scene}_ref_{res}.exr")), 1)
        } else {
            let s: usize = role[2..role.len() - 1].parse()?;
            let ssref = names
                .iter()
                .find(|m| m.starts_with(&format!("{scene}_ssref{s}x_")))
                .map(|m| dir.join(m));
            match ssref {
                Some(r) => (s, r, s),
                None => {
                    let r = names
                        .iter()
                        .find(|m| m.starts_with(&format!("{scene}_ref_")))
                        .map(|m| dir.join(m))
                        .with_context(|| format!("{n}: no reference"))?;
                    (s, r, 1)
                }
            }
        };
        if !reference.exists() {
            bail!("{n}: reference {} is missing", reference.display());
        }
        out.push(Input {
            scene,
            path: dir.join(n),
            name: stem.to_string(),
            s,
            spp,
            reference,
            reference_s,
        });
    }
    Ok(out)
}

#[derive(Clone, Debug)]
struct Row {
    input: String,
    scene: String,
    s: usize,
    spp: u32,
    method: &'static str,
    factor: f64,
    rel_mse: f64,
    rmse: f64,
    energy: f64,
    ledger: f64,
    untouched: f64,
    peak: f64,
    lights: usize,
    seconds: f64,
    spread: u64,
}

/// The linear filter a method is built on (ep-box spreads excess over
/// pixels: the box, which at S = 1 is the identity).
fn linear_of(m: Method) -> Method {
    match m {
        Method::EpBox | Method::Box | Method::Median | Method::AlphaTrim => Method::Box,
        _ => Method::Gauss,
    }
}

fn set(params: &mut FilterParams, key: &str, value: &str) -> Result<()> {
    params
        .set(key, value)
        .map_err(|e| anyhow::anyhow!("--set {key}={value}: {e}"))
}

struct Ctx {
    tmp: tempfile::TempDir,
    sets: Vec<(String, String)>,
}

impl Ctx {
    /// Filter `input` with `method` at S, defaults plus `--set`s; the output
    /// image and the report.
    fn run(
        &self,
        input: &Path,
        method: Method,
        s: usize,
        tag: &str,
    ) -> Result<(Image, epfilt::report::Report)> {
        let mut params = FilterParams::new(method, s);
        for (k, v) in &self.sets {
            set(&mut params, k, v)?;
        }
        let out = self.tmp.path().join(format!("{tag}.exr"));
        let job = FilterJob::new(input, &out, params);
        let report = filter_file(&job, &|_, _| {})
            .with_context(|| format!("{} {}", method.name(), input.display()))?;
        Ok((Image::read(&out)?, report))
    }

    fn path(&self, tag: &str) -> PathBuf {
        self.tmp.path().join(format!("{tag}.exr"))
    }
}

fn main() -> Result<()> {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    if let Some(k) = argv.iter().position(|a| a == "--replot") {
        let dir = argv
            .get(k + 1)
            .context("--replot DIR (where pareto.csv is)")?;
        return sweep::replot(std::path::Path::new(dir));
    }
    if argv.iter().any(|a| a == "--sweep") {
        return sweep::run(&argv);
    }
    if argv.iter().any(|a| a == "--sweep-ep-box") {
        return box_sweep::run(&argv);
    }
    if argv.iter().any(|a| a == "--as-written") {
        return as_written::run(&argv);
    }
    let mut dir = PathBuf::from("../shared/renders");
    let mut out_dir = PathBuf::from("docs");
    let mut methods: Vec<Method> = Method::ALL.to_vec();
    let mut write = true;
    let mut sets = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--renders" => dir = args.next().context("--renders DIR")?.into(),
            "--out" => out_dir = args.next().context("--out DIR")?.into(),
            "--methods" => {
                methods = args
                    .next()
                    .context("--methods a,b")?
                    .split(',')
                    .map(Method::parse)
                    .collect::<epfilt::Result<_>>()?
            }
            "--set" => {
                let kv = args.next().context("--set KEY=VALUE")?;
                let (k, v) = kv.split_once('=').context("--set KEY=VALUE")?;
                sets.push((k.to_string(), v.to_string()));
            }
            "--no-write" => write = false,
            other => bail!("unknown argument {other:?}"),
        }
    }
    let ctx = Ctx {
        tmp: tempfile::tempdir()?,
        sets,
    };
    let list = inputs(&dir)?;
    if list.is_empty() {
        bail!("no renders in {}", dir.display());
    }
    let mut rows = Vec::new();
    let mut oracles = Vec::new();
    // Per scene: the lowest-spp pixel-resolution input and ep-box, the
    // lowest-spp super-sampled input's gauss and ep-gauss, the reference.
    let mut montages: BTreeMap<String, Montage> = BTreeMap::new();
    for inp in &list {
        eprintln!("{}", inp.name);
        let input_img = Image::read(&inp.path)?;
        let mut shown: Vec<(PathBuf, String)> = Vec::new();
        let label = |what: &str| {
            format!(
                "{} spp{} {what}",
                inp.spp,
                if inp.s > 1 {
                    format!(" {0}x{0}", inp.s)
                } else {
                    String::new()
                }
            )
        };
        // Each linear filter of the reference and of the input (the box at
        // S = 1 is the identity: the files themselves).
        let mut refs: BTreeMap<&'static str, Image> = BTreeMap::new();
        let mut linear_noisy: BTreeMap<&'static str, Image> = BTreeMap::new();
        let mut linear_reports = BTreeMap::new();
        for lin in [Method::Gauss, Method::Box] {
            let tag = format!("ref-{}-{}", inp.name, lin.name());
            let (r, _) = ctx.run(&inp.reference, lin, inp.reference_s, &tag)?;
            refs.insert(lin.name(), r);
            let tag = format!("{}-{}", inp.name, lin.name());
            let (n, r) = ctx.run(&inp.path, lin, inp.s, &tag)?;
            linear_noisy.insert(lin.name(), n);
            linear_reports.insert(lin.name(), r);
        }
        if inp.s == 1 {
            shown.push((inp.path.clone(), label("input")));
        } else {
            shown.push((ctx.path(&format!("{}-gauss", inp.name)), label("gauss")));
        }
        for &m in &methods {
            if m == Method::EpBox && inp.s != 1 {
                continue; // needs per-pixel variance
            }
            let tag = format!("{}-{}", inp.name, m.name());
            let (out, report) = match linear_noisy.get(m.name()) {
                // Already made as the linear filter.
                Some(img) => (img.clone(), linear_reports.get(m.name()).cloned()),
                None => {
                    let (o, r) = ctx.run(&inp.path, m, inp.s, &tag)?;
                    (o, Some(r))
                }
            };
            let lin = linear_of(m).name();
            let (reference, base) = (&refs[lin], rel_mse(&linear_noisy[lin], &refs[lin]));
            let rm = rel_mse(&out, reference);
            let (si, so) = (input_img.sums(), out.sums());
            let s2 = (inp.s * inp.s) as f64;
            let energy = (0..3).map(|c| so[c] * s2 / si[c]).fold(1.0f64, |w, r| {
                if (r - 1.0).abs() > (w - 1.0).abs() {
                    r
                } else {
                    w
                }
            });
            let untouched = same_share(&out, &linear_noisy[lin]);
            let ls = lights(reference);
            let report_seconds = report.as_ref().map_or(f64::NAN, |r| r.seconds);
            rows.push(Row {
                input: inp.name.clone(),
                scene: inp.scene.clone(),
                s: inp.s,
                spp: inp.spp,
                method: m.name(),
                factor: rm / base,
                rel_mse: rm,
                rmse: rmse(&out, reference),
                energy,
                ledger: report.as_ref().map_or(f64::NAN, |r| {
                    r.energy_rel_error.iter().fold(0.0, |a, &b| a.max(b))
                }),
                untouched,
                peak: peak_ratio(&out, reference, &ls),
                lights: ls.len(),
                seconds: report_seconds,
                spread: report.as_ref().map_or(0, |r| r.samples_spread),
            });
            if (inp.s == 1 && m == Method::EpBox) || (inp.s > 1 && m == Method::EpGauss) {
                shown.push((ctx.path(&tag), m.name().into()));
            }
        }
        if inp.s > 1 && inp.reference_s == inp.s {
            let truth = Image::read(&inp.reference)?;
            let base = rel_mse(&linear_noisy["gauss"], &refs["gauss"]);
            let mut factors = Vec::new();
            for over in ORACLE_OVER {
                let tag = format!("{}-oracle-{over}", inp.name);
                let (img, share) = oracle_input(&input_img, &truth, over);
                img.write(&ctx.path(&tag))?;
                let (out, _) = ctx.run(
                    &ctx.path(&tag),
                    Method::Gauss,
                    inp.s,
                    &format!("{tag}-gauss"),
                )?;
                factors.push((share, rel_mse(&out, &refs["gauss"]) / base));
            }
            if let Some(r) = rows
                .iter()
                .find(|r| r.input == inp.name && r.method == "ep-gauss")
            {
                oracles.push(Oracle {
                    input: inp.name.clone(),
                    spread: r.spread as f64 / (input_img.w * input_img.h) as f64,
                    ep_gauss: r.factor,
                    factors,
                });
            }
        }
        // Keep the montage's files: the context's folder lives to the end.
        let entry = montages.entry(inp.scene.clone()).or_default();
        let slot = if inp.s == 1 {
            &mut entry.0
        } else {
            &mut entry.1
        };
        if slot.is_empty() {
            *slot = shown;
        }
        if inp.s == 1 && entry.2.is_none() {
            entry.2 = Some(inp.reference.clone());
        }
    }
    let md = markdown(&rows, &oracles, &dir);
    print!("{md}");
    if write {
        std::fs::create_dir_all(out_dir.join("renders"))?;
        std::fs::write(out_dir.join("renders.md"), &md)?;
        std::fs::write(out_dir.join("renders.csv"), csv(&rows))?;
        for (scene, (px, ss, reference)) in &montages {
            let mut shown: Vec<(PathBuf, String)> = px.iter().chain(ss).cloned().collect();
            if let Some(r) = reference {
                shown.push((r.clone(), "reference".into()));
            }
            let png = out_dir.join("renders").join(format!("{scene}.png"));
            epfilt::preview::write_png(&shown, &png, &Default::default(), &|_, _| {})?;
        }
        eprintln!("wrote {}", out_dir.join("renders.md").display());
    }
    Ok(())
}

fn csv(rows: &[Row]) -> String {
    let mut s = String::from(
        "input,scene,supersample,spp,method,factor,rel_mse,rmse,energy_ratio,ledger_rel_error,untouched,peak_ratio,lights,seconds,samples_spread\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{:.6},{:.6e},{:.6e},{:.15},{:.3e},{:.6},{:.4},{},{:.4},{}",
            r.input,
            r.scene,
            r.s,
            r.spp,
            r.method,
            r.factor,
            r.rel_mse,
            r.rmse,
            r.energy,
            r.ledger,
            r.untouched,
            r.peak,
            r.lights,
            r.seconds,
            r.spread
        );
    }
    s
}

fn markdown(rows: &[Row], oracles: &[Oracle], dir: &Path) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Real renders: every method at its defaults\n\nMade by `scripts/eval-renders` from `{}` \
         (`lab/src/bin/eval-renders/main.rs` says how each figure is measured). **factor**: relMSE against \
         the reference over the relMSE the linear filter of the method's family leaves (ep-gauss, \
         clamp: the Gaussian; ep-box, median, alpha-trim: the box, which at S = 1 is the unfiltered \
         input), both against the same linear filter of the reference; below 1 the method removed \
         noise the linear filter leaves. **untouched**: pixels bit-identical to that linear filter's \
         output; **peak**: the worst light's brightest output pixel over the reference's (lights: \
         connected reference pixels above 30 times the median); **energy**: sum(out) S² / sum(in) \
         of the file as written, the worst channel; **ledger**: the run's relative energy error \
         before rounding.\n",
        dir.display()
    );
    let worst = |m: &str, s1: bool| {
        rows.iter()
            .filter(|r| r.method == m && (r.s == 1) == s1)
            .fold((0.0f64, String::new()), |(w, n), r| {
                if r.factor > w {
                    (r.factor, r.input.clone())
                } else {
                    (w, n)
                }
            })
    };
    let (bw, bi) = worst("ep-box", true);
    let (gw, gi) = worst("ep-gauss", false);
    let (gpw, gpi) = worst("ep-gauss", true);
    let ledger = rows
        .iter()
        .filter(|r| !matches!(r.method, "clamp" | "median" | "alpha-trim"))
        .map(|r| r.ledger)
        .fold(0.0f64, f64::max);
    let peak = |m: &str, s1: bool| {
        rows.iter()
            .filter(|r| r.method == m && (r.s == 1) == s1)
            .map(|r| {
                let lin = rows
                    .iter()
                    .find(|q| {
                        q.input == r.input
                            && q.method == linear_of(Method::parse(m).unwrap()).name()
                    })
                    .map_or(1.0, |q| q.peak);
                (r.peak / lin, r.input.clone())
            })
            .fold((f64::INFINITY, String::new()), |a, b| {
                if b.0 < a.0 {
                    b
                } else {
                    a
                }
            })
    };
    let (pb, pbi) = peak("ep-box", true);
    let (pg, pgi) = peak("ep-gauss", false);
    let (pgp, pgpi) = peak("ep-gauss", true);
    let _ = writeln!(
        s,
        "Worst ep-box factor (pixel-resolution inputs): {bw:.3} ({bi}). Worst ep-gauss factor: \
         {gw:.3} on super-sampled inputs ({gi}), {gpw:.3} at pixel resolution with variance ({gpi}). \
         Largest ledger error of an energy-preserving method: {ledger:.1e}. Lights' peaks against \
         the linear filter's (the input's own noise aside): ep-box at worst {pb:.2} ({pbi}), \
         ep-gauss at worst {pg:.2} on super-sampled inputs ({pgi}), {pgp:.2} at pixel resolution \
         ({pgpi}).\n"
    );
    // Summary: the factor of ep-box and ep-gauss per input.
    let mut inputs: Vec<&str> = rows.iter().map(|r| r.input.as_str()).collect();
    inputs.dedup();
    let _ = writeln!(s, "## Summary (factor; peak)\n");
    let _ = writeln!(
        s,
        "| input | S | spp | ep-box | ep-gauss | gauss | box | clamp | median | alpha-trim |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for i in &inputs {
        let of = |m: &str| {
            rows.iter()
                .find(|r| r.input == *i && r.method == m)
                .map_or("–".to_string(), |r| {
                    format!("{:.3}; {}", r.factor, peak_text(r.peak))
                })
        };
        let r0 = rows.iter().find(|r| r.input == *i).unwrap();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            i,
            r0.s,
            r0.spp,
            of("ep-box"),
            of("ep-gauss"),
            of("gauss"),
            of("box"),
            of("clamp"),
            of("median"),
            of("alpha-trim")
        );
    }
    if !oracles.is_empty() {
        let _ = writeln!(
            s,
            "\n## How low outlier-only filtering can go (super-sampled inputs)\n\n\
             An oracle that knows the reference replaces every sample above `k` times the \
             reference's mean luminance over its 3x3 samples by the reference's sample, spreads the \
             light they held above the reference evenly over the whole frame (energy exact, too \
             thin to see), and filters with the Gaussian. It knows which samples are outliers and \
             what they should be, so its factor estimates the floor for filters that treat only \
             outliers (share of samples treated; factor). Where the outliers carry much of the frame's \
             light (tiny bulbs in a dark room) the even spread is itself an error, and the oracle is \
             no floor. **spread**: the share of samples ep-gauss \
             spread at its defaults.\n"
        );
        let head: Vec<String> = ORACLE_OVER
            .iter()
            .map(|k| format!("oracle k = {k}"))
            .collect();
        let _ = writeln!(s, "| input | ep-gauss | spread | {} |", head.join(" | "));
        let _ = writeln!(s, "|---|---|---|{}", "---|".repeat(head.len()));
        for o in oracles {
            let f: Vec<String> = o
                .factors
                .iter()
                .map(|(q, f)| format!("{:.2}%; {f:.3}", 100.0 * q))
                .collect();
            let _ = writeln!(
                s,
                "| {} | {:.3} | {:.2}% | {} |",
                o.input,
                o.ep_gauss,
                100.0 * o.spread,
                f.join(" | ")
            );
        }
    }
    let _ = writeln!(s, "\n## Every run\n");
    let _ = writeln!(
        s,
        "| input | method | factor | relMSE | RMSE | energy on disk | ledger | untouched | peak (lights) | spread | s |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {:.3} | {:.4e} | {:.4} | {:.9} | {:.1e} | {:.1}% | {} ({}) | {} | {:.3} |",
            r.input,
            r.method,
            r.factor,
            r.rel_mse,
            r.rmse,
            r.energy,
            r.ledger,
            100.0 * r.untouched,
            peak_text(r.peak),
            r.lights,
            r.spread,
            r.seconds
        );
    }
    s
}
