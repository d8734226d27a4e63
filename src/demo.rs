//! `epfilt demo`: the newcomer's first run. Two scenes with exact truth are
//! rendered (synthetically): `mixed` (the paper's four cases of high variance)
//! and `lights` (tiny bulbs and a thin line among fireflies); each is filtered
//! by every method, ep-gauss also by the paper's rule as written, scored
//! against the truth, and shown side by side in a PNG.

use std::path::Path;
use std::time::Instant;

use crate::io::Compression;

use crate::compare::compare_files;
use crate::error::{Error, Result};
use crate::filter::{FilterParams, Method};
use crate::io::ExrOutput;
use crate::job::{filter_file, FilterJob};
use crate::pipeline::{Precision, Sink};
use crate::synth::{synth, Sampling, Scene, SceneKind, SynthJob};

/// Run the demo in `dir` at `w` x `h` output pixels; `log` receives progress
/// lines. Returns the Markdown tables (also written to `dir/demo.md`).
pub fn run(dir: &Path, w: usize, h: usize, log: &dyn Fn(&str)) -> Result<String> {
    if w == 0 || h == 0 || w > 4096 || h > 4096 {
        return Err(Error::Config(format!(
            "demo size {w}x{h}: choose 1..=4096 on each side"
        )));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut text = String::new();
    for (kind, what) in [
        (
            SceneKind::Mixed,
            "the paper's four cases: light edge, penumbra, glossy highlight, caustic; hot/base = 1e4",
        ),
        (
            SceneKind::Lights,
            "tiny bulbs 0.5 to 3 px and a 0.4 px line among fireflies",
        ),
    ] {
        text.push_str(&scene_table(dir, kind, what, w, h, log)?);
    }
    text.push_str(&format!(
        "\nFiles in `{dir}`, per scene: `<scene>_noisy_3x.exr` (input), `<scene>_<method>.exr`, \
         `<scene>_truth.exr`, and `<scene>.png` (noisy | gauss | ep-gauss | paper's rule | truth under \
         one display mapping).\n\n\
         The truth is each pixel's exact expected value (its area, as a box), so the Gaussian methods also pay \
         for their blur in the first three columns. *noise RMSE* compares each method with its own noise-free \
         result (box: the truth; the Gaussians: `<scene>_truth_gauss.exr`, the expected samples through the \
         base Gaussian) and isolates the sampling noise left. rel. MSE = mean (a-b)^2/(b^2 + eps), \
         eps = (0.01 * mean |truth|)^2; PSNR after the display mapping of `epfilt preview`. *kept*: noisy \
         samples ep-gauss keeps as parts of a feature (noisy neighbours, compact pairs, bright regions); the paper's rule \
         (`--guard none`) spreads them all.\n",
        dir = dir.display()
    ));
    crate::io::write_file(&dir.join("demo.md"), text.as_bytes())?;
    Ok(text)
}

/// The scene's noisy samples (`s` x `s` a pixel) and its truth.
fn render(scene: &Scene, s: usize, noisy: &Path, truth: &Path) -> Result<()> {
    synth(
        &SynthJob {
            scene: scene.clone(),
            sampling: Sampling::Supersample(s),
            output: noisy.to_path_buf(),
            truth: Some(truth.to_path_buf()),
            variance: false,
            compression: Compression::ZIP16,
            threads: 0,
            format: None,
        },
        &|_, _| {},
    )
    .map(|_| ())
}

/// The truth seen through the Gaussian: the expected sample values filtered
/// with the base Gaussian, i.e. what gauss/ep-gauss would give with no
/// noise. Its path.
fn truth_through_gauss(dir: &Path, scene: &Scene, s: usize) -> Result<std::path::PathBuf> {
    let (name, w, h) = (scene.kind.name(), scene.w, scene.h);
    let expected = dir.join(format!("{name}_expected_3x.exr"));
    let truth_gauss = dir.join(format!("{name}_truth_gauss.exr"));
    let names: Vec<String> = ["R", "G", "B"].iter().map(|c| c.to_string()).collect();
    let mut out = ExrOutput::create_new(
        &expected,
        w * s,
        h * s,
        &names,
        Compression::ZIP16,
        Precision::F32,
        &[],
    )?;
    let mut y = 0;
    while y < h * s {
        let n = 64.min(h * s - y);
        out.write_rows(y, n, &scene.expected_rows(s, y, n))?;
        y += n;
    }
    out.finish()?;
    out.commit()?;
    let job = FilterJob::new(&expected, &truth_gauss, FilterParams::new(Method::Gauss, s));
    filter_file(&job, &|_, _| {})?;
    std::fs::remove_file(&expected).map_err(|e| Error::io(&expected, e))?;
    Ok(truth_gauss)
}

/// One scene: render, filter with every method, score, montage.
/// (Long: each method's run and scores are a row of one table, written in
/// one place so that the columns stay in step.)
fn scene_table(
    dir: &Path,
    kind: SceneKind,
    what: &str,
    w: usize,
    h: usize,
    log: &dyn Fn(&str),
) -> Result<String> {
    let s = 3;
    let name = kind.name();
    let scene = Scene {
        kind,
        w,
        h,
        seed: 1994,
        hot: 1e4,
    };
    let noisy = dir.join(format!("{name}_noisy_3x.exr"));
    let truth = dir.join(format!("{name}_truth.exr"));
    log(&format!(
        "epfilt demo: `{name}` scene ({what}), {}x{} samples (S={s}) -> {w}x{h} pixels, in {}",
        w * s,
        h * s,
        dir.display()
    ));
    let t = Instant::now();
    render(&scene, s, &noisy, &truth)?;
    let truth_gauss = truth_through_gauss(dir, &scene, s)?;
    let job = |input: &Path, output: &Path, p: FilterParams| FilterJob::new(input, output, p);
    log(&format!(
        "  scene, truth and noise-free Gaussian written in {:.2} s",
        t.elapsed().as_secs_f64()
    ));

    let mut table = format!(
        "\n`{name}` scene ({what}), {w}x{h} pixels from {}x{} samples:\n\n\
         | method | RMSE vs truth | rel. MSE vs truth | PSNR vs truth | noise RMSE | energy out/in (ledger) | spread | kept | capped | time |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
        w * s,
        h * s
    );
    let mut paper = FilterParams::new(Method::EpGauss, s);
    paper.support = 0;
    let runs = [
        ("box", "box", FilterParams::new(Method::Box, s)),
        ("gauss", "gauss", FilterParams::new(Method::Gauss, s)),
        (
            "ep-gauss",
            "ep-gauss",
            FilterParams::new(Method::EpGauss, s),
        ),
        ("ep-gauss, paper's rule", "ep-gauss-paper", paper),
    ];
    let mut panels = Vec::new();
    for (label, file, params) in runs {
        let out = dir.join(format!("{name}_{file}.exr"));
        let method = params.method;
        let report = filter_file(&job(&noisy, &out, params), &|_, _| {})?;
        let cmp = compare_files(&out, &truth, &Default::default(), &|_, _| {})?;
        let through = if method == Method::Box {
            &truth
        } else {
            &truth_gauss
        };
        let noise = compare_files(&out, through, &Default::default(), &|_, _| {})?;
        let ratio: f64 =
            report.energy_out.iter().sum::<f64>() / report.energy_in.iter().sum::<f64>();
        log(&format!("  {label:<22} done in {:.2} s", report.seconds));
        table.push_str(&format!(
            "| {label} | {:.4} | {:.3} | {:.2} dB | {:.4} | {:.15} | {} | {} | {} | {:.2} s |\n",
            cmp.rmse,
            cmp.rel_mse,
            cmp.psnr,
            noise.rmse,
            ratio,
            report.samples_spread,
            report.samples_kept,
            report.samples_capped,
            report.seconds
        ));
        let label = match method {
            Method::Box => "noisy (box)".to_string(),
            _ if file == "ep-gauss-paper" => "paper's rule".to_string(),
            _ => method.name().to_string(),
        };
        panels.push((out, label));
    }
    panels.push((truth.clone(), "truth".to_string()));
    let png = dir.join(format!("{name}.png"));
    crate::preview::write_png(&panels, &png, &Default::default(), &|_, _| {})?;
    Ok(table)
}
