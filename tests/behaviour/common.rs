//! Shared helpers of the behaviour tests: images, a reference filter written
//! for clarity, and comparison tools.
#![allow(dead_code)]

use epfilt::filter::ep_gauss::{relation14, EpGauss};
use epfilt::{filter_in_memory, FilterParams, Grid, Method, PipelineConfig, RunStats, StripLayout};

/// Relative energy error allowed before rounding: the ledger's own bound.
pub use epfilt::pipeline::ledger::LEDGER_TOL as ENERGY_TOL;

/// The methods of the Gaussian family's stage (`pipeline/spread.rs`), which
/// most stream tests run: one list, so a method added there is tested
/// everywhere at once.
pub const GAUSSIAN_FAMILY: [Method; 3] = [Method::EpGauss, Method::Gauss, Method::Box];

/// The method's counts of a run, by method (the run must be of it).
pub trait Counts {
    /// ep-gauss's.
    fn eg(&self) -> epfilt::pipeline::SpreadCounts;
    /// ep-box's.
    fn eb(&self) -> epfilt::pipeline::ExcessCounts;
}

impl Counts for RunStats {
    fn eg(&self) -> epfilt::pipeline::SpreadCounts {
        self.ep_gauss().expect("an ep-gauss run")
    }
    fn eb(&self) -> epfilt::pipeline::ExcessCounts {
        self.ep_box().expect("an ep-box run")
    }
}

/// A small deterministic generator (SplitMix64).
pub struct Rng(pub u64);
impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A planar image `[row][channel][x]`.
#[derive(Clone, Debug)]
pub struct Img {
    pub w: usize,
    pub h: usize,
    pub nch: usize,
    pub data: Vec<f32>,
}

impl Img {
    pub fn new(w: usize, h: usize, nch: usize, f: impl Fn(usize, usize, usize) -> f32) -> Self {
        let mut data = Vec::with_capacity(w * h * nch);
        for y in 0..h {
            for c in 0..nch {
                for x in 0..w {
                    data.push(f(x, y, c));
                }
            }
        }
        Img { w, h, nch, data }
    }
    pub fn at(&self, x: usize, y: usize, c: usize) -> f32 {
        self.data[(y * self.nch + c) * self.w + x]
    }
    pub fn set(&mut self, x: usize, y: usize, c: usize, v: f32) {
        self.data[(y * self.nch + c) * self.w + x] = v;
    }
}

pub fn rgb_job(w: usize, h: usize, s: usize) -> StripLayout {
    StripLayout::new(
        Grid {
            in_w: w,
            in_h: h,
            s,
        },
        vec!["R".into(), "G".into(), "B".into()],
        vec![0.2126, 0.7152, 0.0722],
    )
}

/// An RGB render at pixel resolution with per-colour sample variances
/// (`variance.R/G/B` after the colour) from `spp` samples: the job of ep-box.
pub fn rgb_variance_job(w: usize, h: usize, spp: f64) -> StripLayout {
    let mut j = rgb_job(w, h, 1);
    j.aux = vec![
        "variance.R".into(),
        "variance.G".into(),
        "variance.B".into(),
    ];
    j.stats = Some(epfilt::filter::ep_box::StatsLayout {
        variance: vec![3, 4, 5],
        kind: epfilt::filter::ep_box::VarianceKind::Sample,
        mean_y: None,
        spp: epfilt::filter::ep_box::Spp::Fixed(spp),
    });
    j
}

pub fn job_for(img: &Img, s: usize) -> StripLayout {
    match img.nch {
        3 => rgb_job(img.w, img.h, s),
        4 => StripLayout::new(
            Grid {
                in_w: img.w,
                in_h: img.h,
                s,
            },
            vec!["R".into(), "G".into(), "B".into(), "A".into()],
            vec![0.2126, 0.7152, 0.0722, 0.0],
        ),
        _ => StripLayout::new(
            Grid {
                in_w: img.w,
                in_h: img.h,
                s,
            },
            vec!["Y".into()],
            vec![1.0],
        ),
    }
}

pub fn run(img: &Img, s: usize, params: &FilterParams, cfg: &PipelineConfig) -> (Img, RunStats) {
    let job = job_for(img, s);
    let (out, stats) = filter_in_memory(img.data.clone(), &job, params, cfg).expect("filter");
    (
        Img {
            w: img.w / s,
            h: img.h / s,
            nch: img.nch,
            data: out,
        },
        stats,
    )
}

/// How the work is cut: tile width, strip rows (0: automatic), threads.
pub fn cfg(tile: usize, strip_rows: usize, threads: usize) -> PipelineConfig {
    PipelineConfig {
        tile,
        strip_rows,
        threads,
        ..Default::default()
    }
}

/// One way of cutting the work, every dimension the invariance tests vary
/// named: accumulator tile width, input rows a strip (0: automatic),
/// worker threads, strips in flight, and `small_chunks`: each row's
/// classification cut into column ranges of `3 tile + 1` samples and the
/// spread into chunks of the memory of `tile + 1` samples at an edge
/// (wide images get such cuts; small ones only when asked).
#[derive(Clone, Copy, Debug)]
pub struct Cut {
    pub tile: usize,
    pub strip_rows: usize,
    pub threads: usize,
    pub strips_in_flight: usize,
    pub small_chunks: bool,
}

impl From<(usize, usize, usize)> for Cut {
    /// A cut from (tile, strip rows, threads) as the property tests draw
    /// them: one strip in flight or two by the strip height's parity (so
    /// every list of cuts has both), small chunks under 32-column tiles.
    fn from((tile, strip_rows, threads): (usize, usize, usize)) -> Self {
        Cut {
            tile,
            strip_rows,
            threads,
            strips_in_flight: 1 + strip_rows % 2,
            small_chunks: tile < 32,
        }
    }
}

const fn cut(
    tile: usize,
    strip_rows: usize,
    threads: usize,
    strips_in_flight: usize,
    small_chunks: bool,
) -> Cut {
    Cut {
        tile,
        strip_rows,
        threads,
        strips_in_flight,
        small_chunks,
    }
}

/// The cuts of the work every method must give the same bits for: tiles
/// that divide the width and that do not (1 and 7 columns, a whole row),
/// strips of 1, 5 and 1000 rows and the automatic height, 1 to 4 threads,
/// one strip in flight and two, whole and small chunks.
pub const CUTS: [Cut; 9] = [
    cut(256, 0, 1, 1, false),
    cut(1, 1, 2, 2, true),
    cut(7, 5, 3, 2, true),
    cut(16, 13, 1, 2, true),
    cut(70, 96, 1, 1, false),
    cut(256, 1, 1, 2, false),
    cut(256, 1000, 1, 1, false),
    cut(16, 7, 2, 2, true),
    cut(64, 200, 4, 1, false),
];

/// The one invariance tester: runs `data` (planar, as `job` says) with
/// `params` through every cut of `cuts` ([`Cut`]) and demands one answer:
/// the same output bits, the same digest of the unrounded output, the same
/// ledger bits and the same counts. Returns the first run's output and
/// statistics, or what differed where (a `Result`, so a property test can
/// report it as its failure).
pub fn invariant(
    data: &[f32],
    job: &StripLayout,
    params: &FilterParams,
    cuts: &[Cut],
) -> Result<(Vec<f32>, RunStats), String> {
    let mut first: Option<(Vec<f32>, RunStats)> = None;
    for c in cuts {
        let (tile, strip, threads) = (c.tile, c.strip_rows, c.threads);
        let mut cut = cfg(tile, strip, threads);
        cut.strips_in_flight = c.strips_in_flight;
        if c.small_chunks {
            cut.classify_samples = 3 * tile + 1;
            cut.spread_chunk = tile + 1;
        }
        let (out, stats) = filter_in_memory(data.to_vec(), job, params, &cut)
            .map_err(|e| format!("{} {tile}/{strip}/{threads}: {e}", params.method.name()))?;
        let Some((o, s)) = &first else {
            first = Some((out, stats));
            continue;
        };
        let what = format!(
            "{} tile {tile} strip {strip} threads {threads}",
            params.method.name()
        );
        if !(o.len() == out.len() && o.iter().zip(&out).all(|(a, b)| a.to_bits() == b.to_bits())) {
            return Err(format!("{what}: output bits differ"));
        }
        if s.digest != stats.digest {
            return Err(format!(
                "{what}: digest {:x} vs {:x}",
                s.digest, stats.digest
            ));
        }
        if ledger_bits(s) != ledger_bits(&stats) {
            return Err(format!("{what}: ledger"));
        }
        if s.method != stats.method {
            return Err(format!(
                "{what}: counts {:?} vs {:?}",
                s.method, stats.method
            ));
        }
    }
    first.ok_or_else(|| "no cut".to_string())
}

/// [`invariant`] over every cut of [`CUTS`], which must hold.
pub fn same_for_every_cut(
    data: &[f32],
    job: &StripLayout,
    params: &FilterParams,
) -> (Vec<f32>, RunStats) {
    invariant(data, job, params, &CUTS).unwrap_or_else(|e| panic!("{e}"))
}

/// Every channel of `stats`' ledger balances within [`ENERGY_TOL`]; `what`
/// names the run in the message.
pub fn assert_balanced(stats: &RunStats, what: &str) {
    for l in &stats.ledger {
        assert!(
            l.rel_error <= ENERGY_TOL,
            "{what} {}: rel error {:e}",
            l.channel,
            l.rel_error
        );
    }
}

pub fn params(method: Method, s: usize) -> FilterParams {
    FilterParams::new(method, s)
}

/// Smooth background with sparse fireflies (1e2..1e5 x), some forced onto the
/// borders and corners.
pub fn fireflies(w: usize, h: usize, nch: usize, frac: f64, seed: u64) -> Img {
    let mut rng = Rng(seed);
    let mut img = Img::new(w, h, nch, |x, y, c| {
        0.5 + 0.3 * ((x as f32 * 0.07).sin() * (y as f32 * 0.05).cos()) + 0.05 * c as f32
    });
    let n = ((w * h) as f64 * frac).ceil() as usize;
    let mut spots: Vec<(usize, usize)> = (0..n)
        .map(|_| {
            (
                (rng.next_u64() % w as u64) as usize,
                (rng.next_u64() % h as u64) as usize,
            )
        })
        .collect();
    spots.extend([
        (0, 0),
        (w - 1, 0),
        (0, h - 1),
        (w - 1, h - 1),
        (w / 2, 0),
        (0, h / 2),
    ]);
    for (x, y) in spots {
        let mag = 10f64.powf(2.0 + 3.0 * rng.unit()) as f32;
        for c in 0..nch {
            let v = img.at(x, y, c);
            img.set(x, y, c, v * mag);
        }
    }
    img
}

/// Reference filter, written for clarity rather than speed: every sample is
/// scattered, in row-major order, with its own 2-D weights into a full-size
/// f64 image. The noise test and the feature rules use direct sums over the
/// whole Gaussian footprint (no ring sums, no cheap path); the width is the
/// width search's over an in-memory image (its guarantees are unit tests of
/// `filter::ep_gauss`), so the streamed windows, the scatter and the coarse
/// grids are what this checks.
pub fn reference(img: &Img, s: usize, p: &FilterParams, lum: &[f64]) -> (Vec<f64>, usize) {
    let (w, h) = (img.w / s, img.h / s);
    let mirror = |v: i64, n: usize| -> usize {
        let n = n as i64;
        let k = v.rem_euclid(2 * n);
        (if k < n { k } else { 2 * n - 1 - k }) as usize
    };
    let lum_at =
        |i: usize, j: usize| -> f64 { (0..img.nch).map(|c| lum[c] * img.at(i, j, c) as f64).sum() };
    // Box luminance per output pixel, stored in f32 as the engine stores it.
    let mut ybox = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for j in y * s..(y + 1) * s {
                for i in x * s..(x + 1) * s {
                    acc += lum_at(i, j);
                }
            }
            ybox[y * w + x] = (acc / (s * s) as f64) as f32 as f64;
        }
    }
    let ep = EpGauss::new(
        s,
        p.radius,
        p.max_radius,
        p.cutoff,
        p.tolerance,
        p.width_step,
    )
    .with_bound(p.bound_from);
    let ladder: Vec<f64> = if p.method == Method::EpGauss {
        ep.levels().iter().map(|l| l.rho).collect()
    } else {
        vec![p.radius]
    };
    // The widths: the search's own (its guarantees, each width found passes
    // Relation 14 on its average, or on a lower bound of it from
    // `--bound-from`, and the next narrower fails, are unit tests of
    // `filter::ep_gauss`), over an in-memory image of the box luminance
    // instead of the engine's streamed windows and summed-area table.
    let field = epfilt::filter::ep_gauss::LumImage::new(w, h, ep.pad(), |x, y| ybox[y * w + x]);
    // xbar and w0 of Relation 14 at radius rho around pixel (x, y): Gaussian
    // weights over the disc dx^2 + dy^2 <= (min(cutoff, 2.5) * rho)^2.
    let xbar_w0 = |x: usize, y: usize, rho: f64| -> (f64, f64) {
        let rr = p.cutoff.min(epfilt::filter::ep_gauss::AVG_CUTOFF) * rho;
        let r = rr.floor() as i64;
        let (mut num, mut den) = (0.0, 0.0);
        for dy in -r..=r {
            for dx in -r..=r {
                if (dx * dx + dy * dy) as f64 > rr * rr {
                    continue;
                }
                let g = (-((dx * dx + dy * dy) as f64) / (rho * rho)).exp();
                num += g * ybox[mirror(y as i64 + dy, h) * w + mirror(x as i64 + dx, w)];
                den += g;
            }
        }
        (num / den, 1.0 / ((s * s) as f64 * den))
    };
    // 1-D weights of a sample at sub-offset a, radius rho (or the box).
    let weights = |a: usize, rho: f64| -> (i64, Vec<f64>) {
        if p.method == Method::Box {
            return (0, vec![1.0]);
        }
        let delta = (a as f64 + 0.5) / s as f64 - 0.5;
        let lim = p.cutoff * rho;
        let r = (lim + 0.5).floor() as i64;
        let mut v: Vec<f64> = (-r..=r)
            .map(|d| {
                let dist = d as f64 - delta;
                if dist.abs() <= lim {
                    (-(dist / rho).powi(2)).exp()
                } else {
                    0.0
                }
            })
            .collect();
        let sum: f64 = v.iter().sum();
        v.iter_mut().for_each(|x| *x /= sum);
        (r, v)
    };
    let mut out = vec![0.0f64; w * h * img.nch];
    let mut spread = 0;
    for j in 0..img.h {
        for i in 0..img.w {
            let (px, py) = (i / s, j / s);
            let mut rho = p.radius;
            if p.method == Method::EpGauss {
                let x0 = lum_at(i, j);
                let (xb, w0) = xbar_w0(px, py, ladder[0]);
                let noisy = |v: f64| v > 0.0 && xb > 0.0 && relation14(v / xb, w0) > p.tolerance;
                // Samples within Chebyshev distance r of this one, in the
                // image, and their luminance.
                let around = |r: i64| {
                    let mut out = Vec::new();
                    for dj in -r..=r {
                        for di in -r..=r {
                            let (ni, nj) = (i as i64 + di, j as i64 + dj);
                            if (di, dj) == (0, 0) || ni < 0 || nj < 0 {
                                continue;
                            }
                            let (ni, nj) = (ni as usize, nj as usize);
                            if ni < img.w && nj < img.h {
                                out.push(lum_at(ni, nj));
                            }
                        }
                    }
                    out
                };
                // The support rule: noisy (brighter) neighbouring samples
                // within the ratio keep it at the base width.
                let same = |v: f64| v > xb && noisy(v) && v * p.support_ratio >= x0;
                let support = around(1).into_iter().filter(|&v| same(v)).count();
                // Grain inside a bright feature: comparable samples within 2.
                let region = p.support_region > 0
                    && x0 <= p.support_level * xb
                    && around(2)
                        .into_iter()
                        .filter(|&v| v > xb.max(x0 / p.support_level))
                        .count()
                        >= p.support_region;
                // A compact pair: one neighbour, few like it within 2, and far
                // above the median of the eight pixels about its own.
                let compact = p.support_compact > 0 && support >= 1 && {
                    let mut ring: Vec<f64> = (-1i64..=1)
                        .flat_map(|dy| (-1i64..=1).map(move |dx| (dx, dy)))
                        .filter(|&d| d != (0, 0))
                        .map(|(dx, dy)| {
                            ybox[mirror(py as i64 + dy, h) * w + mirror(px as i64 + dx, w)]
                        })
                        .collect();
                    ring.sort_by(f64::total_cmp);
                    x0 >= p.support_over * ring[4]
                        // At most `support_compact` with itself.
                        && around(2).into_iter().filter(|&v| same(v)).count()
                            < p.support_compact
                };
                // A group: the samples joined to it through supporting
                // neighbours within 2 (a flood over the 5 x 5).
                let group = p.support_group > 0 && support >= 1 && {
                    let mut member = [[false; 5]; 5];
                    for dj in -2i64..=2 {
                        for di in -2i64..=2 {
                            let (ni, nj) = (i as i64 + di, j as i64 + dj);
                            member[(dj + 2) as usize][(di + 2) as usize] = (di, dj) != (0, 0)
                                && ni >= 0
                                && nj >= 0
                                && (ni as usize) < img.w
                                && (nj as usize) < img.h
                                && same(lum_at(ni as usize, nj as usize));
                        }
                    }
                    let mut seen = [[false; 5]; 5];
                    seen[2][2] = true;
                    let mut todo = vec![(2i64, 2i64)];
                    let mut size = 1;
                    while let Some((ci, cj)) = todo.pop() {
                        for (di, dj) in (-1i64..=1).flat_map(|a| (-1i64..=1).map(move |b| (a, b))) {
                            let (ni, nj) = (ci + di, cj + dj);
                            if (0..5).contains(&ni)
                                && (0..5).contains(&nj)
                                && member[nj as usize][ni as usize]
                                && !seen[nj as usize][ni as usize]
                            {
                                seen[nj as usize][ni as usize] = true;
                                todo.push((ni, nj));
                                size += 1;
                            }
                        }
                    }
                    size >= p.support_group
                };
                let kept = p.support > 0 && (support >= p.support || region || compact || group);
                if x0 > xb && noisy(x0) && !kept {
                    let c = ep.search(&field, px, py, x0, ep.xbar0(&field, px, py as i64));
                    rho = ladder[c.level as usize];
                    if rho > p.radius {
                        spread += 1;
                    }
                }
            }
            // Widths from --coarse-from: spread on the 2x coarser grid, from
            // twice that on the 4x one (reflected there), brought back with
            // the tent once per halving (reflected at each grid's edges).
            let coarse = (p.method == Method::EpGauss
                && rho > p.radius
                && p.coarse_from > 0.0
                && rho >= p.coarse_from)
                .then(|| {
                    let four = (rho >= 2.0 * p.coarse_from)
                        .then(|| epfilt::filter::kernel::Coarse::with_factor(s, rho, p.cutoff, 4))
                        .flatten();
                    four.or_else(|| epfilt::filter::kernel::Coarse::new(s, rho, p.cutoff))
                })
                .flatten();
            if let Some(k) = coarse {
                let axis = |pix: usize, a: usize, n: usize| -> Vec<f64> {
                    let f = k.factor;
                    // Grid sizes from the fine one down to the coarse one.
                    let mut sizes = vec![n];
                    while sizes.len() < f.trailing_zeros() as usize + 1 {
                        sizes.push(sizes.last().unwrap().div_ceil(2));
                    }
                    let row = k.kernel.row((pix % f) * s + a);
                    let rc = k.kernel.reach() as i64;
                    let nc = *sizes.last().unwrap();
                    let mut cur = vec![0.0; nc];
                    for (kk, &g) in row.iter().enumerate() {
                        cur[mirror((pix / f) as i64 + kk as i64 - rc, nc)] += g;
                    }
                    for &nf in sizes.iter().rev().skip(1) {
                        let mut next = vec![0.0; nf];
                        for (cell, &v) in cur.iter().enumerate() {
                            for (t, &tw) in epfilt::filter::kernel::TENT.iter().enumerate() {
                                next[mirror(2 * cell as i64 - 1 + t as i64, nf)] += v * tw;
                            }
                        }
                        cur = next;
                    }
                    cur
                };
                let (fx, fy) = (axis(px, i % s, w), axis(py, j % s, h));
                for (ty, &a) in fy.iter().enumerate() {
                    for (tx, &b) in fx.iter().enumerate() {
                        for c in 0..img.nch {
                            out[(ty * img.nch + c) * w + tx] +=
                                img.at(i, j, c) as f64 * a * b / (s * s) as f64;
                        }
                    }
                }
                continue;
            }
            let (rx, wx) = weights(i % s, rho);
            let (ry, wy) = weights(j % s, rho);
            for (ky, &a) in wy.iter().enumerate() {
                let ty = mirror(py as i64 + ky as i64 - ry, h);
                for (kx, &b) in wx.iter().enumerate() {
                    let tx = mirror(px as i64 + kx as i64 - rx, w);
                    for c in 0..img.nch {
                        out[(ty * img.nch + c) * w + tx] +=
                            img.at(i, j, c) as f64 * a * b / (s * s) as f64;
                    }
                }
            }
        }
    }
    (out, spread)
}

pub fn bits(img: &Img) -> Vec<u32> {
    img.data.iter().map(|v| v.to_bits()).collect()
}

/// Run the `epfilt` binary.
pub fn epfilt_run(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_epfilt"))
        .args(args)
        .output()
        .expect("run epfilt")
}

/// Run the `epfilt` binary, which must succeed; its standard output.
pub fn epfilt_ok(args: &[&str]) -> String {
    let o = epfilt_run(args);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A JSON file epfilt wrote (`--report`).
pub fn read_json(path: &std::path::Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).expect("JSON report")
}

/// The f32 output hides differences in the last bits of the f64 sums behind
/// rounding (and the compensated ledger is too exact to notice them): compare
/// the digest of the unrounded values too, and the ledger's bits.
pub fn ledger_bits(stats: &epfilt::RunStats) -> Vec<u64> {
    let mut v: Vec<u64> = stats
        .ledger
        .iter()
        .flat_map(|l| [l.energy_out.to_bits(), l.energy_out_rounded.to_bits()])
        .collect();
    v.push(stats.digest);
    v
}

/// The bytes of an EXR file epfilt wrote, its fingerprint's value blanked:
/// two runs whose inputs are different files (or whose settings are asked for
/// differently) record different fingerprints but must agree on the rest.
pub fn image_bytes(path: &std::path::Path) -> Vec<u8> {
    let mut bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let key = b"epfiltFingerprint\0string\0";
    if let Some(at) = bytes.windows(key.len()).position(|w| w == key) {
        let size_at = at + key.len();
        let size = u32::from_le_bytes(bytes[size_at..size_at + 4].try_into().unwrap()) as usize;
        bytes[size_at + 4..size_at + 4 + size].fill(b'-');
    }
    bytes
}
