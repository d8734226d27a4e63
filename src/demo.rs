//! `epfilt demo`: the newcomer's first run. A `mixed` scene with exact truth
//! is rendered (synthetically), filtered by every method, scored against the
//! truth, and shown side by side in a PNG.

use std::path::Path;
use std::time::Instant;

use exr::prelude::Compression;

use crate::compare::compare_files;
use crate::error::{Error, Result};
use crate::filter::{FilterParams, Method};
use crate::io::ExrOutput;
use crate::job::{filter_file, FilterJob};
use crate::pipeline::{Precision, Sink};
use crate::synth::{synth, Sampling, Scene, SceneKind, SynthJob};

/// Run the demo in `dir` at `w` x `h` output pixels; `log` receives progress
/// lines. Returns the Markdown table (also written to `dir/demo.md`).
pub fn run(dir: &Path, w: usize, h: usize, log: &dyn Fn(&str)) -> Result<String> {
    if w == 0 || h == 0 || w > 4096 || h > 4096 {
        return Err(Error::Config(format!(
            "demo size {w}x{h}: choose 1..=4096 on each side"
        )));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let s = 3;
    let scene = Scene {
        kind: SceneKind::Mixed,
        w,
        h,
        seed: 1994,
        hot: 1e4,
    };
    let noisy = dir.join("noisy_3x.exr");
    let truth = dir.join("truth.exr");
    log(&format!(
        "epfilt demo: `mixed` scene (light edge, penumbra, glossy highlight, caustic; hot/base = 1e4), \
         {}x{} samples (S={s}) -> {w}x{h} pixels, in {}",
        w * s,
        h * s,
        dir.display()
    ));
    let t = Instant::now();
    synth(
        &SynthJob {
            scene: scene.clone(),
            sampling: Sampling::Supersample(s),
            output: noisy.clone(),
            truth: Some(truth.clone()),
            variance: false,
            compression: Compression::ZIP16,
            threads: 0,
        },
        &|_, _| {},
    )?;
    // The truth seen through the Gaussian: the expected sample values filtered
    // with the base Gaussian, i.e. what gauss/ep-gauss would give with no noise.
    let expected = dir.join("expected_3x.exr");
    let truth_gauss = dir.join("truth_gauss.exr");
    {
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
    }
    let job = |input: &Path, output: &Path, m: Method| {
        FilterJob::new(input, output, FilterParams::new(m, s))
    };
    filter_file(&job(&expected, &truth_gauss, Method::Gauss), &|_, _| {})?;
    std::fs::remove_file(&expected).map_err(|e| Error::io(&expected, e))?;
    log(&format!(
        "  scene, truth and noise-free Gaussian written in {:.2} s",
        t.elapsed().as_secs_f64()
    ));

    let mut table = String::from(
        "| method | RMSE vs truth | rel. MSE vs truth | PSNR vs truth | noise RMSE | energy out/in (ledger) | samples spread | capped | time |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    let mut panels = Vec::new();
    for method in [Method::Box, Method::Gauss, Method::EpGauss] {
        let out = dir.join(format!("{}.exr", method.name()));
        let report = filter_file(&job(&noisy, &out, method), &|_, _| {})?;
        let cmp = compare_files(&out, &truth)?;
        let through = if method == Method::Box {
            &truth
        } else {
            &truth_gauss
        };
        let noise = compare_files(&out, through)?;
        let ratio: f64 =
            report.energy_out.iter().sum::<f64>() / report.energy_in.iter().sum::<f64>();
        log(&format!(
            "  {:<9} done in {:.2} s",
            method.name(),
            report.seconds
        ));
        table.push_str(&format!(
            "| {} | {:.4} | {:.3} | {:.2} dB | {:.4} | {:.15} | {} | {} | {:.2} s |\n",
            method.name(),
            cmp.rmse,
            cmp.rel_mse,
            cmp.psnr,
            noise.rmse,
            ratio,
            report.samples_spread,
            report.samples_capped,
            report.seconds
        ));
        let label = if method == Method::Box {
            "noisy (box)".to_string()
        } else {
            method.name().to_string()
        };
        panels.push((out, label));
    }
    panels.push((truth.clone(), "truth".to_string()));
    let png = dir.join("demo.png");
    crate::preview::write_png(&panels, &png, 0.0)?;
    table.push_str(&format!(
        "\nFiles in `{dir}`: `noisy_3x.exr` (input), `box.exr`, `gauss.exr`, `ep-gauss.exr`, `truth.exr`, and \
         `demo.png` (noisy | gauss | ep-gauss | truth under one display mapping).\n\n\
         The truth is each pixel's exact expected value (its area, as a box), so the Gaussian methods also pay \
         for their blur in the first three columns. *noise RMSE* compares each method with its own noise-free \
         result (box: the truth; gauss and ep-gauss: `truth_gauss.exr`, the expected samples through the base \
         Gaussian) and isolates the sampling noise left. rel. MSE = mean (a-b)^2/(b^2 + eps), \
         eps = (0.01 * mean |truth|)^2; PSNR after the display mapping of `epfilt preview`.\n",
        dir = dir.display()
    ));
    crate::io::write_file(&dir.join("demo.md"), table.as_bytes())?;
    Ok(table)
}
