//! The restore pipeline's unit tests.
use super::*;
use crate::filter::ep_box::{Spp, StatsLayout, VarianceKind};
use crate::filter::restore::{taps, KEEP_SIGMA, LOOKAHEAD};
use crate::pipeline::counts::{MethodCounts, RestoreCounts};

use crate::pipeline::ledger::LEDGER_TOL;
/// A block's sum of f32 outputs against its f64 energy: a few f32
/// roundings (2^-24 each) over up to a thousand values.
const BLOCK_TOL: f64 = 1e-5;

/// The evidence-free default: a render, no gain.
const RENDER: RestoreParams = RestoreParams {
    scale: 8,
    keep_gain: None,
};

/// A pseudo-random stream in [0, 1), the same on every platform.
fn stream(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 33) as f64 / (1u64 << 31) as f64
    }
}

/// A noisy image with fireflies, and a smooth "denoised" one with holes.
fn images(w: usize, h: usize, nch: usize) -> (Vec<f32>, Vec<f32>) {
    let mut rnd = stream(12345);
    let (mut e, mut d) = (Vec::new(), Vec::new());
    for y in 0..h {
        for c in 0..nch {
            for x in 0..w {
                let base = 1.0 + 0.5 * ((x + 2 * y + c) as f32 * 0.1).sin();
                let r = rnd() as f32;
                e.push(if r > 0.98 {
                    base * 200.0
                } else {
                    base * (0.5 + r)
                });
                d.push(if (x / 7 + y / 5) % 9 == 0 { 0.0 } else { base });
            }
        }
    }
    (e, d)
}

/// The counts of a restore.
fn counts(run: &RestoreRun) -> RestoreCounts {
    match run.run.method {
        MethodCounts::Restore(c) => c,
        ref other => panic!("{other:?}"),
    }
}

/// A restore of [`images`]; `lamps`: with an emission guide that
/// holds most of every 23rd pixel's energy.
fn run(
    (w, h, nch): (usize, usize, usize),
    scale: usize,
    cfg: &PipelineConfig,
    lamps: bool,
) -> (Vec<f32>, RestoreRun) {
    let (mut e, d) = images(w, h, nch);
    let names = (0..nch).map(|c| format!("c{c}")).collect();
    let mut layout = EnergyLayout::plain(names, vec![0.0; nch]);
    if lamps {
        let row = nch * w;
        e = (e.chunks(row).enumerate())
            .flat_map(|(y, r)| {
                let lamp = r.iter().enumerate().map(move |(i, &v)| {
                    let x = i % w;
                    if (x * 7 + y * 3) % 23 == 0 {
                        0.9 * v
                    } else {
                        0.0
                    }
                });
                r.iter().copied().chain(lamp).collect::<Vec<f32>>()
            })
            .collect();
        layout.emission = (nch..2 * nch).map(Some).collect();
    }
    let params = RestoreParams { scale, ..RENDER };
    restore_planar(e, d, (w, h), layout, params, cfg, Precision::F32).unwrap()
}

/// The rows of a one-channel energy image `e` (`w` wide) with its sample
/// variance `var` beside it, and the layout that reads it (`n` samples).
fn with_variance(
    e: &[f32],
    w: usize,
    n: f64,
    var: impl Fn(usize) -> f32,
) -> (Vec<f32>, EnergyLayout) {
    let mut rows = Vec::new();
    for (y, row) in e.chunks(w).enumerate() {
        rows.extend_from_slice(row);
        rows.extend((0..w).map(|x| var(y * w + x)));
    }
    let stats = StatsLayout {
        variance: vec![1],
        kind: VarianceKind::Sample,
        mean_y: None,
        spp: Spp::Fixed(n),
    };
    let layout = EnergyLayout {
        stats: Some(RenderStats::new(stats, &[1.0], vec!["var.Y".into()])),
        ..EnergyLayout::plain(vec!["Y".into()], vec![1.0])
    };
    (rows, layout)
}

#[test]
fn energy_is_exact_and_bytes_do_not_depend_on_strips_or_threads() {
    let sizes = [(37, 29, 8), (5, 4, 2), (64, 3, 32), (70, 45, 16)];
    for ((w, h, scale), lamps) in sizes.into_iter().flat_map(|s| [(s, false), (s, true)]) {
        let base = PipelineConfig {
            threads: 1,
            strip_rows: 1,
            ..Default::default()
        };
        let (out, restored) = run((w, h, 2), scale, &base, lamps);
        for l in &restored.run.ledger {
            assert!(l.rel_error <= LEDGER_TOL, "{w}x{h} {scale}: {l:?}");
        }
        for (threads, strip_rows) in [(2, 1), (1, 7), (3, 64), (2, 0)] {
            let cfg = PipelineConfig {
                threads,
                strip_rows,
                ..Default::default()
            };
            let (o, s) = run((w, h, 2), scale, &cfg, lamps);
            assert_eq!(
                s.run.digest, restored.run.digest,
                "{w}x{h} threads {threads} strips {strip_rows}"
            );
            assert_eq!(o, out);
        }
    }
}

/// Where the render is sure (a variance pass of zero), every block holds
/// its energy: the render's energy is the target at every scale.
#[test]
fn a_sure_render_keeps_every_blocks_energy() {
    let (w, h, scale) = (37, 29, 8);
    let (e, d) = images(w, h, 1);
    let (rows, layout) = with_variance(&e, w, 16.0, |_| 0.0);
    let params = RestoreParams { scale, ..RENDER };
    let cfg = PipelineConfig::default();
    let (out, restored) =
        restore_planar(rows, d, (w, h), layout, params, &cfg, Precision::F32).unwrap();
    let nbx = w.div_ceil(scale);
    let mut sums = vec![[0.0f64; 2]; nbx * h.div_ceil(scale)];
    for y in 0..h {
        for x in 0..w {
            let k = (y / scale) * nbx + x / scale;
            sums[k][0] += f64::from(e[y * w + x]);
            sums[k][1] += f64::from(out[y * w + x]);
        }
    }
    for [se, so] in sums {
        assert!((so - se).abs() <= BLOCK_TOL * se.abs(), "{so} vs {se}");
    }
    assert!(restored.levels.iter().all(|l| l.exact == l.blocks));
}

/// Once the input is all in, the rows of blocks still held are
/// finished one a call: the final rows held never reach more than one
/// row of blocks and the rows a strip brings, however many rows of
/// blocks the field looks ahead. The input comes in one strip here,
/// the worst case: before, every row was final at once.
#[test]
fn the_last_rows_of_blocks_are_finished_one_at_a_time() {
    let (w, h, scale) = (23, 200, 8);
    for strip_rows in [1, 16, h] {
        let cfg = PipelineConfig {
            threads: 2,
            strip_rows,
            ..Default::default()
        };
        let (_, restored) = run((w, h, 2), scale, &cfg, false);
        let out = (restored.run.windows.iter())
            .find(|u| u.name == "output")
            .unwrap();
        assert!(
            out.rows <= scale + strip_rows.min(h - LOOKAHEAD * scale),
            "strips of {strip_rows}: {} final rows held",
            out.rows
        );
    }
}

/// Where the denoiser has nothing, the energy stays where it was.
#[test]
fn an_empty_denoiser_output_keeps_the_energy_in_place() {
    let (w, h) = (9, 6);
    let e: Vec<f32> = (0..w * h).map(|i| (i % 5) as f32).collect();
    let (out, restored) = restore_planar(
        e.clone(),
        vec![0.0; w * h],
        (w, h),
        EnergyLayout::plain(vec!["Y".into()], vec![1.0]),
        RestoreParams { scale: 4, ..RENDER },
        &PipelineConfig::default(),
        Precision::F32,
    )
    .unwrap();
    assert_eq!(out, e);
    let lit = e.iter().filter(|&&v| v > 0.0).count();
    assert_eq!(counts(&restored).unshaped as usize, lit);
}

/// A channel the denoiser did not write (an alpha) stays as the energy
/// has it, bit for bit, beside one restored as before, at any strips.
#[test]
fn a_channel_the_denoiser_lacks_stays_as_the_energy_has_it() {
    let (w, h) = (37, 29);
    let (e, d) = images(w, h, 2);
    // The denoiser's rows: its first channel only.
    let d1: Vec<f32> = d.chunks(w).step_by(2).flatten().copied().collect();
    let one = |layout: EnergyLayout, d: Vec<f32>, strip_rows| {
        let cfg = PipelineConfig {
            strip_rows,
            ..Default::default()
        };
        restore_planar(e.clone(), d, (w, h), layout, RENDER, &cfg, Precision::F32).unwrap()
    };
    let names = vec!["R".to_string(), "A".to_string()];
    let both = EnergyLayout::plain(names.clone(), vec![1.0, 0.0]);
    let (full, _) = one(both.clone(), d.clone(), 0);
    let alpha = EnergyLayout {
        denoised: vec![Some(0), None],
        denoised_channels: 1,
        ..both
    };
    for strip_rows in [0, 1, 5] {
        let (out, restored) = one(alpha.clone(), d1.clone(), strip_rows);
        for (y, (o, (f, e))) in out
            .chunks(w)
            .zip(full.chunks(w).zip(e.chunks(w)))
            .enumerate()
        {
            // Rows alternate R, A: R as with both channels, A the energy's.
            assert_eq!(o, if y % 2 == 0 { f } else { e }, "row {y}");
        }
        assert!(restored
            .run
            .ledger
            .iter()
            .all(|l| l.rel_error <= LEDGER_TOL));
    }
}

/// The share around a flat denoiser of 1: its value over the kernel's
/// centre weight (what stays beside a kept pixel).
fn flat_share() -> f64 {
    1.0 / taps(KEEP_SIGMA)[taps(KEEP_SIGMA).len() / 2].powi(2)
}

/// A bright pixel the denoiser flattened, on a flat field of one: what
/// restore writes there, with the ledger checked.
fn one_bright_pixel(e: Vec<f32>, layout: EnergyLayout, at: usize) -> f32 {
    let (w, h) = (24, 24);
    let cfg = PipelineConfig::default();
    let (out, restored) = restore_planar(
        e,
        vec![1.0; w * h],
        (w, h),
        layout,
        RENDER,
        &cfg,
        Precision::F32,
    )
    .unwrap();
    let l = &restored.run.ledger[0];
    assert!(l.rel_error <= LEDGER_TOL, "{l:?}");
    out[at]
}

/// No gain alone decides: a lone firefly of any size on a flat field the
/// denoiser left flat is spread with its region's energy, never kept in
/// place as a lamp (before, one of 500 was written as 100).
#[test]
fn a_lone_firefly_of_any_size_is_never_kept_in_place() {
    let (w, h, at) = (24, 24, 13 * 24 + 9);
    for hot in [5.0, 500.0, 5e4, 5e7] {
        let mut e = vec![1.0f32; w * h];
        e[at] = hot;
        let got = one_bright_pixel(e, EnergyLayout::plain(vec!["Y".into()], vec![1.0]), at);
        // Its energy joins the whole image's: a flat share of it here.
        let even = 1.0 + (hot - 1.0) / (w * h) as f32;
        assert!(got <= 2.0 * even, "{hot}: {got} (even {even})");
    }
}

/// Without a guide, a render's variance pass tells a bulb (every sample
/// bright: its mean is sure) from a firefly (one bright sample: its
/// standard error is its mean).
#[test]
fn a_sure_pixel_stays_and_a_firefly_spreads() {
    let (w, n) = (24, 16.0);
    let (bulb, firefly) = (4 * 24 + 4, 17 * 24 + 19);
    let mut e = vec![1.0f32; w * w];
    e[bulb] = 101.0;
    e[firefly] = 101.0;
    // Sample variances: a tenth of the mean for the bulb's standard
    // error, all of it for the firefly's (one hit among n), the rest flat.
    let var = |i: usize| match i {
        i if i == bulb => (0.1f32 * 101.0).powi(2) * n as f32,
        i if i == firefly => 101.0f32.powi(2) * n as f32,
        _ => 0.01,
    };
    let (rows, layout) = with_variance(&e, w, n, var);
    let got_bulb = one_bright_pixel(rows.clone(), layout.clone(), bulb);
    let got_firefly = one_bright_pixel(rows, layout, firefly);
    assert!(f64::from(got_bulb) >= 100.0 - flat_share(), "{got_bulb}");
    assert!(got_firefly < 5.0, "{got_firefly}");
}

#[test]
fn the_emission_guide_keeps_a_lamp_the_denoiser_removed() {
    let (w, lamp) = (24, 12 * 24 + 12);
    let mut e = vec![1.0f32; w * w];
    e[lamp] = 101.0;
    let mut with_guide = Vec::new();
    for row in e.chunks(w) {
        with_guide.extend_from_slice(row);
        with_guide.extend(row.iter().map(|&v| if v > 1.0 { 100.0 } else { 0.0 }));
    }
    let plain = EnergyLayout::plain(vec!["Y".into()], vec![1.0]);
    let guided = EnergyLayout {
        emission: vec![Some(1)],
        ..plain.clone()
    };
    let spread = one_bright_pixel(e, plain, lamp);
    let kept = one_bright_pixel(with_guide, guided, lamp);
    assert!(spread < 5.0, "{spread}");
    assert!(f64::from(kept) >= 100.0 - flat_share(), "{kept}");
}

/// A peak the denoiser kept (ten times its neighbours), dimmed: the
/// render's light there beyond the denoiser's share around stays in place.
#[test]
fn a_peak_the_denoiser_kept_keeps_the_renders_light() {
    let (w, h, at) = (24, 24, 12 * 24 + 12);
    let mut e = vec![1.0f32; w * h];
    e[at] = 400.0;
    let mut d = vec![1.0f32; w * h];
    d[at] = 10.0;
    let cfg = PipelineConfig::default();
    let layout = EnergyLayout::plain(vec!["Y".into()], vec![1.0]);
    let (out, restored) =
        restore_planar(e, d, (w, h), layout, RENDER, &cfg, Precision::F32).unwrap();
    assert!(
        f64::from(out[at]) >= 400.0 - flat_share() - 10.0,
        "{}",
        out[at]
    );
    assert_eq!(counts(&restored).kept_denoiser, 1);
}

/// A denoiser's NaN is refused, naming the pixel and its side; with
/// `--nonfinite zero` it is nothing to shape with, and counted, as are
/// its negative values.
#[test]
fn non_finite_denoiser_values_are_refused_or_counted() {
    let (w, h) = (9, 7);
    let e = vec![1.0f32; w * h];
    let mut d = vec![1.0f32; w * h];
    d[3 * w + 5] = f32::NAN;
    d[4 * w + 1] = f32::INFINITY;
    d[6 * w] = -0.5;
    let layout = EnergyLayout::plain(vec!["Y".into()], vec![1.0]);
    let go = |nonfinite| {
        let cfg = PipelineConfig {
            nonfinite,
            ..Default::default()
        };
        restore_planar(
            e.clone(),
            d.clone(),
            (w, h),
            layout.clone(),
            RENDER,
            &cfg,
            Precision::F32,
        )
    };
    match go(crate::pipeline::NonFinite::Error) {
        Err(crate::error::Error::StreamValue { side, reason }) => {
            assert_eq!(side, crate::error::Side::SecondInput);
            assert!(
                reason.contains("(5, 3)") && reason.contains("channel Y"),
                "{reason}"
            );
        }
        other => panic!("{other:?}"),
    }
    let (out, restored) = go(crate::pipeline::NonFinite::Zero).unwrap();
    let c = counts(&restored);
    assert_eq!((c.denoised_nonfinite, c.denoised_negative), (2, 1));
    assert!(out.iter().all(|v| v.is_finite()));
    assert!(restored.run.ledger[0].rel_error <= LEDGER_TOL);
}

/// The render's uncertainty, both ways, against a known one: Gaussian
/// noise of a known deviation about a truth the denoiser found exactly.
/// The variance pass gives each block's standard error itself; the
/// residual estimates it (here all the residual is noise) within a few
/// percent over many blocks.
#[test]
fn the_uncertainty_is_the_renders_known_variance() {
    /// 64 blocks' mean square of 64 squared normals each: within 5%.
    const RESIDUAL_TOL: f64 = 0.05;
    let (w, h, n) = (64, 64, 16.0);
    let mut rnd = stream(7);
    let truth: Vec<f32> = (0..w * h)
        .map(|i| 2.0 + ((i % w) as f32 * 0.05).sin())
        .collect();
    // Deviation a tenth of the truth in the left half, a fifth on the right.
    let sd = |i: usize| if i % w < w / 2 { 0.1 } else { 0.2 } * f64::from(truth[i]);
    let normal = |r: &mut dyn FnMut() -> f64| {
        let (u, v) = (r().max(1e-12), r());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    let e: Vec<f32> = (0..w * h)
        .map(|i| (f64::from(truth[i]) + sd(i) * normal(&mut rnd)) as f32)
        .collect();
    let cfg = PipelineConfig::default();
    let (rows, layout) = with_variance(&e, w, n, |i| (sd(i).powi(2) * n) as f32);
    let known = restore_planar(
        rows,
        truth.clone(),
        (w, h),
        layout,
        RENDER,
        &cfg,
        Precision::F32,
    )
    .unwrap()
    .1;
    let plain = EnergyLayout::plain(vec!["Y".into()], vec![1.0]);
    let residual = restore_planar(
        e,
        truth.clone(),
        (w, h),
        plain,
        RENDER,
        &cfg,
        Precision::F32,
    )
    .unwrap()
    .1;
    // The exact relative standard error of the 8 x 8 blocks.
    let nbx = w / 8;
    let mut var = vec![0.0f64; nbx * nbx];
    let mut sum = vec![0.0f64; nbx * nbx];
    for (i, t) in truth.iter().enumerate() {
        let k = (i / w / 8) * nbx + (i % w) / 8;
        var[k] += sd(i).powi(2);
        sum[k] += f64::from(*t);
    }
    let exact =
        (var.iter().zip(&sum).map(|(v, s)| v / (s * s)).sum::<f64>() / var.len() as f64).sqrt();
    let (k, r) = (known.levels[0].render_rse, residual.levels[0].render_rse);
    assert!(
        (k / exact - 1.0).abs() < RESIDUAL_TOL,
        "pass {k} exact {exact}"
    );
    assert!(
        (r / exact - 1.0).abs() < RESIDUAL_TOL,
        "residual {r} exact {exact}"
    );
}

/// The final rows' declared reads agree with the field's own rule: a row of
/// blocks may be finished once its field and the next row's can be fixed
/// (`FieldRows::can_fix`), whatever the height, block and moments made.
#[test]
fn a_row_of_blocks_is_final_when_its_fields_can_be_fixed() {
    use crate::filter::restore::FieldRows;
    use crate::pipeline::schedule::forward;
    use stage::{passes, FINAL, KEPT, MOMENTS};
    for (h, b) in [
        (1usize, 2usize),
        (5, 32),
        (37, 8),
        (64, 16),
        (100, 32),
        (129, 4),
    ] {
        let nby = h.div_ceil(b);
        let f = FieldRows::new(1, h, b, vec![0.0; nby], vec![0.0; nby]);
        let p = passes(vec![(0, 3)], b);
        for m in 0..=h {
            // Every input row in and every row's `l` known: the moments decide.
            let mut made = vec![h; FINAL];
            made[MOMENTS] = m;
            made[KEPT] = h;
            let t = forward(&p, h, &made, usize::MAX)[FINAL];
            for j in 0..nby {
                let last = ((j + 1) * b).min(h);
                let by_field = f.can_fix((j + 1).min(nby - 1), m);
                assert_eq!(last <= t, by_field, "h {h} b {b} m {m} j {j}");
            }
        }
    }
}
