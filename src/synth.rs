//! `epfilt synth`: noisy scenes with exact ground truth.
//!
//! A renderer is not needed to know the truth. The paper (§4.1, Fig. 1) names
//! four sources of high variance, and each is a pixel whose samples come from
//! a known two-valued mixture: with probability `p` a sample sees a bright
//! source of radiance `L_hot * colour_hot`, otherwise a smooth dim base
//! `b * colour_base`. The expected value `p * L_hot + (1 - p) * b` of every
//! sample cell is known, so the truth of every output pixel is exact.
//!
//! Scenes: `light-edge` (a bright disc partly covering cells: `p` is the
//! cell's coverage), `penumbra` (`p` ramps smoothly across an occluded area
//! light's shadow edge), `glossy` (small `p` in a soft blob: a light inside a
//! glossy lobe), `caustic` (small `p` in a sharp-edged ring on a dim wall) and
//! `mixed` (all four). `L_hot` is `--hot` times the base (default 1e4).
//!
//! Beyond the paper, what real interiors show: `lights` holds tiny light
//! sources seen directly (bulbs 0.5 to 3 pixels across, `p` the share of a
//! cell they cover, 500 to 2500 times the base at the default `--hot`) and a
//! thin bright line (a neon tube 0.4 pixels wide), among fireflies sprinkled
//! over the whole frame (a rare path to a bright light: `p = 0.3%`, 100 times
//! the base): real
//! features and noise in one frame, each with exact truth.
//!
//! Random numbers come from a counter-based hash of (seed, x, y, sample): any
//! strip of any image can be made alone, at any thread count, with the same
//! bytes, and memory stays flat whatever the size.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::io::Compression;
use rayon::iter::{IndexedParallelIterator, ParallelIterator};
use rayon::slice::ParallelSliceMut;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::io::{ExrOutput, Format};
use crate::pipeline::{Precision, Sink};

/// The high-variance case to model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneKind {
    /// A light source seen directly, partly covering pixels (Fig. 1a).
    LightEdge,
    /// A partly occluded area light: p ramps across the penumbra (Fig. 1b).
    Penumbra,
    /// A small light inside a glossy lobe (Fig. 1c).
    Glossy,
    /// Light focused by a specular object onto a dim wall (Fig. 1d).
    Caustic,
    /// All four in one frame.
    Mixed,
    /// Tiny bulbs and a thin bright line among fireflies (beyond the paper).
    Lights,
}

impl SceneKind {
    /// Parse a `--scene` name.
    pub fn parse(s: &str) -> Result<Self> {
        Ok(match s {
            "light-edge" => SceneKind::LightEdge,
            "penumbra" => SceneKind::Penumbra,
            "glossy" => SceneKind::Glossy,
            "caustic" => SceneKind::Caustic,
            "mixed" => SceneKind::Mixed,
            "lights" => SceneKind::Lights,
            _ => {
                return Err(Error::Config(format!(
                    "unknown scene {s:?} (choose light-edge, penumbra, glossy, caustic, mixed or lights)"
                )))
            }
        })
    }

    /// The `--scene` name.
    pub fn name(self) -> &'static str {
        match self {
            SceneKind::LightEdge => "light-edge",
            SceneKind::Penumbra => "penumbra",
            SceneKind::Glossy => "glossy",
            SceneKind::Caustic => "caustic",
            SceneKind::Mixed => "mixed",
            SceneKind::Lights => "lights",
        }
    }
}

/// A scene at an output size.
#[derive(Clone, Debug)]
pub struct Scene {
    /// What it shows.
    pub kind: SceneKind,
    /// Output width in pixels.
    pub w: usize,
    /// Output height in pixels.
    pub h: usize,
    /// Random seed.
    pub seed: u64,
    /// `L_hot` over the base level.
    pub hot: f64,
}

const BASE_RGB: [f64; 3] = [0.80, 0.70, 0.55];

/// The bulbs of the `lights` scene: centre (fractions of the frame), diameter
/// in output pixels, radiance over the default hot level `hot * 0.05`.
pub const BULBS: [(f64, f64, f64, f64); 6] = [
    (0.15, 0.35, 0.5, 0.25),
    (0.31, 0.30, 0.8, 0.12),
    (0.47, 0.37, 1.2, 0.08),
    (0.63, 0.31, 2.0, 0.05),
    (0.79, 0.36, 3.0, 0.05),
    (0.50, 0.55, 0.6, 0.20),
];

/// The `lights` scene's line: ends (fractions of the frame), width in output
/// pixels, radiance over `hot * 0.05`.
pub const LINE: ((f64, f64), (f64, f64), f64, f64) = ((0.2, 0.75), (0.8, 0.8), 0.4, 0.06);

/// Sub-cells per side for the coverage of the `lights` scene's features.
const COVERAGE_GRID: usize = 8;
const LIGHT_RGB: [f64; 3] = [1.0, 0.97, 0.92];

fn hash(seed: u64, a: u64, b: u64, c: u64) -> u64 {
    let mut z = seed
        ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ c.wrapping_mul(0x1656_67B1_9E37_79F9);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn unit(z: u64) -> f64 {
    (z >> 11) as f64 / (1u64 << 53) as f64
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Probability of a hot sample, its radiance and colour.
type Hot = (f64, f64, [f64; 3]);

impl Scene {
    /// Base radiance at output-pixel coordinates `(u, v)`: dim and smooth.
    fn base(&self, u: f64, v: f64) -> f64 {
        let (w, h) = (self.w as f64, self.h as f64);
        0.05 * (1.0 + 0.4 * (u / w * 5.0).sin() * (v / h * 3.0).cos() + 0.3 * v / h)
    }

    /// Placement of one element: centre (fractions of the frame) and scale
    /// (fraction of the short side); one element fills the frame's middle.
    fn place(&self, k: SceneKind) -> (f64, f64, f64) {
        let single = self.kind != SceneKind::Mixed;
        match k {
            SceneKind::LightEdge if !single => (0.18, 0.28, 1.0),
            SceneKind::Caustic if !single => (0.72, 0.70, 1.0),
            SceneKind::Glossy if !single => (0.55, 0.30, 1.0),
            SceneKind::Penumbra if !single => (0.265, 0.77, 1.0),
            _ => (0.5, 0.5, 2.5),
        }
    }

    fn element(&self, k: SceneKind, u: f64, v: f64, d: f64) -> Option<Hot> {
        let (w, h) = (self.w as f64, self.h as f64);
        let (fx, fy, scale) = self.place(k);
        let m = w.min(h) * scale;
        let (cx, cy) = (fx * w, fy * h);
        let (cu, cv) = (u + d / 2.0, v + d / 2.0);
        let l = self.hot * 0.05;
        match k {
            SceneKind::LightEdge => {
                let r = 0.09 * m;
                if (cu - cx).hypot(cv - cy) >= r + d {
                    return None;
                }
                let mut n = 0;
                for a in 0..4 {
                    for b in 0..4 {
                        let (x, y) = (
                            u + (a as f64 + 0.5) * d / 4.0,
                            v + (b as f64 + 0.5) * d / 4.0,
                        );
                        n += ((x - cx).hypot(y - cy) < r) as u32;
                    }
                }
                (n > 0).then_some((n as f64 / 16.0, l, LIGHT_RGB))
            }
            SceneKind::Caustic => {
                let rr = (cu - cx).hypot(cv - cy);
                ((0.10 * m..0.13 * m).contains(&rr) && cv > cy - 0.05 * m).then_some((
                    0.02,
                    l * 0.3,
                    [0.55, 0.75, 1.0],
                ))
            }
            SceneKind::Glossy => {
                let s = 0.06 * m;
                let g = (-((cu - cx).powi(2) + (cv - cy).powi(2)) / (s * s)).exp();
                (g > 1e-3).then_some((0.03 * g, l * 0.5, [1.0, 0.85, 0.6]))
            }
            SceneKind::Penumbra => {
                let (hw, hh) = (0.7 * m, 0.3 * m);
                let inside = (cu - cx).abs() < hw && (cv - cy).abs() < hh;
                inside.then(|| (0.25 * smoothstep(cx - hw, cx + hw, cu), l * 0.2, LIGHT_RGB))
            }
            SceneKind::Lights => {
                let cover = |inside: &dyn Fn(f64, f64) -> bool| {
                    let g = COVERAGE_GRID;
                    let mut n = 0;
                    for a in 0..g {
                        for b in 0..g {
                            let x = u + (a as f64 + 0.5) * d / g as f64;
                            let y = v + (b as f64 + 0.5) * d / g as f64;
                            n += inside(x, y) as usize;
                        }
                    }
                    n as f64 / (g * g) as f64
                };
                for &(fx, fy, dia, gain) in &BULBS {
                    let (bx, by, r) = (fx * w, fy * h, dia / 2.0);
                    if (cu - bx).hypot(cv - by) < r + d {
                        let p = cover(&|x, y| (x - bx).hypot(y - by) < r);
                        if p > 0.0 {
                            return Some((p, l * gain, LIGHT_RGB));
                        }
                    }
                }
                let ((ax, ay), (ex, ey), width, gain) = LINE;
                let (ax, ay, ex, ey) = (ax * w, ay * h, ex * w, ey * h);
                let dist = |x: f64, y: f64| {
                    let (dx, dy) = (ex - ax, ey - ay);
                    let t = (((x - ax) * dx + (y - ay) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
                    (x - ax - t * dx).hypot(y - ay - t * dy)
                };
                if dist(cu, cv) < width / 2.0 + d {
                    let p = cover(&|x, y| dist(x, y) < width / 2.0);
                    if p > 0.0 {
                        return Some((p, l * gain, [0.55, 0.8, 1.0]));
                    }
                }
                // Fireflies: a rare path to a bright light, anywhere.
                Some((0.003, l * 0.01, LIGHT_RGB))
            }
            SceneKind::Mixed => None,
        }
    }

    /// Hot-sample model of the cell with corner `(u, v)` and side `d` (output
    /// pixels).
    fn hot_at(&self, u: f64, v: f64, d: f64) -> Hot {
        let kinds: &[SceneKind] = match self.kind {
            SceneKind::Mixed => &[
                SceneKind::LightEdge,
                SceneKind::Caustic,
                SceneKind::Glossy,
                SceneKind::Penumbra,
            ],
            k => match k {
                SceneKind::LightEdge => &[SceneKind::LightEdge],
                SceneKind::Caustic => &[SceneKind::Caustic],
                SceneKind::Glossy => &[SceneKind::Glossy],
                SceneKind::Lights => &[SceneKind::Lights],
                _ => &[SceneKind::Penumbra],
            },
        };
        kinds
            .iter()
            .find_map(|&k| self.element(k, u, v, d))
            .unwrap_or((0.0, 0.0, [0.0; 3]))
    }

    fn expected_cell(&self, u: f64, v: f64, d: f64) -> [f64; 3] {
        let (p, l, col) = self.hot_at(u, v, d);
        let b = self.base(u + d / 2.0, v + d / 2.0);
        [0, 1, 2].map(|c| p * l * col[c] + (1.0 - p) * b * BASE_RGB[c])
    }

    /// Exact moments of one output pixel's estimate: for an S x S render
    /// (`Sampling::Supersample(s)`) the mean of its S^2 cells' samples, for
    /// `Sampling::Spp(n)` the mean of n samples of the pixel. Returns per
    /// channel the expected value and the variance of the estimate, and the
    /// expected number of hot samples in it.
    pub fn pixel_moments(
        &self,
        sampling: Sampling,
        x: usize,
        y: usize,
    ) -> ([f64; 3], [f64; 3], f64) {
        let cell = |u: f64, v: f64, d: f64| {
            let (p, l, col) = self.hot_at(u, v, d);
            let b = self.base(u + d / 2.0, v + d / 2.0);
            let hi = col.map(|c| l * c);
            let lo = BASE_RGB.map(|c| b * c);
            (p, hi, lo)
        };
        let (mut mean, mut var, mut hits) = ([0.0; 3], [0.0; 3], 0.0);
        match sampling {
            Sampling::Supersample(s) => {
                let d = 1.0 / s as f64;
                let n = (s * s) as f64;
                for b in 0..s {
                    for a in 0..s {
                        let (p, hi, lo) = cell((x * s + a) as f64 * d, (y * s + b) as f64 * d, d);
                        for c in 0..3 {
                            mean[c] += (p * hi[c] + (1.0 - p) * lo[c]) / n;
                            var[c] += p * (1.0 - p) * (hi[c] - lo[c]).powi(2) / (n * n);
                        }
                        hits += p;
                    }
                }
            }
            Sampling::Spp(n) => {
                let (p, hi, lo) = cell(x as f64, y as f64, 1.0);
                for c in 0..3 {
                    mean[c] = p * hi[c] + (1.0 - p) * lo[c];
                    var[c] = p * (1.0 - p) * (hi[c] - lo[c]).powi(2) / n as f64;
                }
                hits = p * n as f64;
            }
        }
        (mean, var, hits)
    }

    /// Super-sampled noisy rows `j0..j0 + rows` (one sample per cell of side
    /// 1/S), planar RGB.
    pub fn noisy_rows(&self, s: usize, j0: usize, rows: usize) -> Vec<f32> {
        let iw = self.w * s;
        let d = 1.0 / s as f64;
        let mut out = vec![0.0f32; rows * 3 * iw];
        out.par_chunks_mut(3 * iw).enumerate().for_each(|(r, row)| {
            let j = j0 + r;
            let v = j as f64 * d;
            for i in 0..iw {
                let u = i as f64 * d;
                let (p, l, col) = self.hot_at(u, v, d);
                let x = unit(hash(self.seed, i as u64, j as u64, 0));
                let rgb: [f64; 3] = if x < p {
                    col.map(|c| l * c)
                } else {
                    let b = self.base(u + d / 2.0, v + d / 2.0);
                    BASE_RGB.map(|c| b * c)
                };
                for c in 0..3 {
                    row[c * iw + i] = rgb[c] as f32;
                }
            }
        });
        out
    }

    /// Expected value of every cell of side 1/S (input resolution), planar RGB:
    /// what infinitely many samples would give.
    pub fn expected_rows(&self, s: usize, j0: usize, rows: usize) -> Vec<f32> {
        let iw = self.w * s;
        let d = 1.0 / s as f64;
        let mut out = vec![0.0f32; rows * 3 * iw];
        out.par_chunks_mut(3 * iw).enumerate().for_each(|(r, row)| {
            let v = (j0 + r) as f64 * d;
            for i in 0..iw {
                let e = self.expected_cell(i as f64 * d, v, d);
                for c in 0..3 {
                    row[c * iw + i] = e[c] as f32;
                }
            }
        });
        out
    }

    /// Truth at output resolution for an S x S super-sampled render: the mean
    /// of its cells' expected values. Rows `y0..y0 + rows`, planar RGB.
    pub fn truth_rows(&self, s: usize, y0: usize, rows: usize) -> Vec<f32> {
        let w = self.w;
        let d = 1.0 / s as f64;
        let mut out = vec![0.0f32; rows * 3 * w];
        out.par_chunks_mut(3 * w).enumerate().for_each(|(r, row)| {
            let y = y0 + r;
            for x in 0..w {
                let mut acc = [0.0f64; 3];
                for b in 0..s {
                    for a in 0..s {
                        let e =
                            self.expected_cell((x * s + a) as f64 * d, (y * s + b) as f64 * d, d);
                        for c in 0..3 {
                            acc[c] += e[c];
                        }
                    }
                }
                for c in 0..3 {
                    row[c * w + x] = (acc[c] / (s * s) as f64) as f32;
                }
            }
        });
        out
    }

    /// Path-tracer-style rows: per pixel the mean of `n` samples (all of the
    /// pixel's mixture) and their unbiased sample variance, planar
    /// `[R, G, B, var.R, var.G, var.B]`. Rows `y0..y0 + rows`.
    pub fn spp_rows(&self, n: usize, y0: usize, rows: usize) -> Vec<f32> {
        let w = self.w;
        let mut out = vec![0.0f32; rows * 6 * w];
        out.par_chunks_mut(6 * w).enumerate().for_each(|(r, row)| {
            let y = y0 + r;
            for x in 0..w {
                let (u, v) = (x as f64, y as f64);
                let (p, l, col) = self.hot_at(u, v, 1.0);
                let b = self.base(u + 0.5, v + 0.5);
                let hits = (0..n)
                    .filter(|&k| unit(hash(self.seed, x as u64, y as u64, k as u64 + 1)) < p)
                    .count();
                let (k, nf) = (hits as f64, n as f64);
                for c in 0..3 {
                    let (hi, lo) = (l * col[c], b * BASE_RGB[c]);
                    let mean = (k * hi + (nf - k) * lo) / nf;
                    let var = if n > 1 {
                        k * (nf - k) / (nf * (nf - 1.0)) * (hi - lo).powi(2)
                    } else {
                        0.0
                    };
                    row[c * w + x] = mean as f32;
                    row[(3 + c) * w + x] = var as f32;
                }
            }
        });
        out
    }

    /// Truth of the `--spp` render: each pixel's expected value.
    pub fn spp_truth_rows(&self, y0: usize, rows: usize) -> Vec<f32> {
        let w = self.w;
        let mut out = vec![0.0f32; rows * 3 * w];
        out.par_chunks_mut(3 * w).enumerate().for_each(|(r, row)| {
            for x in 0..w {
                let e = self.expected_cell(x as f64, (y0 + r) as f64, 1.0);
                for c in 0..3 {
                    row[c * w + x] = e[c] as f32;
                }
            }
        });
        out
    }
}

/// What `synth` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    /// S x S samples per output pixel, one value each.
    Supersample(usize),
    /// The mean and sample variance of N samples per pixel.
    Spp(usize),
}

/// A `synth` job.
#[derive(Clone, Debug)]
pub struct SynthJob {
    /// The scene.
    pub scene: Scene,
    /// How it is sampled.
    pub sampling: Sampling,
    /// Noisy output.
    pub output: PathBuf,
    /// Truth output (output resolution, f32), if wanted.
    pub truth: Option<PathBuf>,
    /// With `Sampling::Spp`: also write the per-pixel sample variance
    /// (`variance.R/G/B`, unbiased, of single samples).
    pub variance: bool,
    /// Compression of both files.
    pub compression: Compression,
    /// Worker threads (0: all cores).
    pub threads: usize,
    /// `--format` of both files where their names do not say (`-` is
    /// OpenEXR unless told).
    pub format: Option<Format>,
}

/// What `synth` writes.
pub const WRITES: &[Format] = &[Format::Exr, Format::Rgbe];

/// Summary of a `synth` run.
#[derive(Clone, Debug, Serialize)]
pub struct SynthReport {
    /// Noisy file.
    pub output: String,
    /// Its width and height.
    pub width: usize,
    /// Height.
    pub height: usize,
    /// Truth file, if written.
    pub truth: Option<String>,
    /// Wall time.
    pub seconds: f64,
    /// Peak resident set size, where the platform tells it.
    pub peak_rss_bytes: Option<u64>,
}

/// One file `synth` writes.
struct OutSpec<'a> {
    path: &'a Path,
    format: Format,
    w: usize,
    h: usize,
    names: &'a [String],
    compression: Compression,
    strip: usize,
    ints: &'a [(&'a str, i32)],
}

fn write_streamed(
    spec: &OutSpec<'_>,
    rows: impl Fn(usize, usize) -> Vec<f32>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<()> {
    let mut out = if spec.format == Format::Rgbe {
        // A Radiance picture: R, G, B only (variance needs an EXR).
        if spec.names.len() != 3 {
            return Err(Error::Config(format!(
                "{}: a Radiance picture holds R, G, B only; write variance channels to an EXR",
                spec.path.display()
            )));
        }
        let software = format!("epfilt {} synth", env!("CARGO_PKG_VERSION"));
        crate::io::output::Output::Rgbe(Box::new(crate::io::rgbe::RgbeOutput::create(
            spec.path,
            spec.w,
            spec.h,
            false,
            (&[], &software),
            &[],
            &software,
        )?))
    } else {
        crate::io::output::Output::Exr(Box::new(ExrOutput::create_new(
            spec.path,
            spec.w,
            spec.h,
            spec.names,
            spec.compression,
            Precision::F32,
            spec.ints,
        )?))
    };
    let mut y = 0;
    while y < spec.h {
        let n = spec.strip.min(spec.h - y);
        out.write_rows(y, n, &rows(y, n))?;
        y += n;
        progress(y, spec.h);
    }
    out.finish()?;
    out.commit()
}

/// The noisy output's format and the truth's.
type Formats = (Format, Option<Format>);

/// `synth --supersample s`: the noisy samples, S x S a pixel, and the truth.
fn write_supersampled(
    job: &SynthJob,
    s: usize,
    (out_format, truth_format): Formats,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(usize, usize)> {
    let sc = &job.scene;
    let rgb: Vec<String> = ["R", "G", "B"].iter().map(|s| s.to_string()).collect();
    if !(1..=8).contains(&s) {
        return Err(Error::Config(format!(
            "--supersample must be 1..=8, got {s}"
        )));
    }
    let (iw, ih) = (sc.w.checked_mul(s), sc.h.checked_mul(s));
    let (Some(iw), Some(ih)) = (iw, ih) else {
        return Err(Error::Config(
            "--size times --supersample is too large".into(),
        ));
    };
    let strip = crate::pipeline::auto_strip_rows(iw, 3).max(s);
    // The render says it is super-sampled: `filter` reduces it
    // S times without being told (crate::io::verdict).
    let ints = [(crate::io::SUPERSAMPLE_ATTRIBUTES[0], s as i32)];
    let spec = OutSpec {
        path: &job.output,
        format: out_format,
        w: iw,
        h: ih,
        names: &rgb,
        compression: job.compression,
        strip,
        ints: &ints,
    };
    write_streamed(&spec, |j, n| sc.noisy_rows(s, j, n), progress)?;
    if let Some(t) = &job.truth {
        let spec = OutSpec {
            path: t,
            format: truth_format.unwrap_or(out_format),
            w: sc.w,
            h: sc.h,
            strip: 64,
            ints: &[],
            ..spec
        };
        write_streamed(&spec, |y, n| sc.truth_rows(s, y, n), &|_, _| {})?;
    }
    Ok((iw, ih))
}

/// `synth --spp n`: the mean of `n` samples a pixel (and their variance),
/// and the truth.
fn write_spp(
    job: &SynthJob,
    n: usize,
    (out_format, truth_format): Formats,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(usize, usize)> {
    let sc = &job.scene;
    let rgb: Vec<String> = ["R", "G", "B"].iter().map(|s| s.to_string()).collect();
    if n == 0 || n > 1 << 20 {
        return Err(Error::Config(format!("--spp must be 1..=1048576, got {n}")));
    }
    let all = ["R", "G", "B", "variance.R", "variance.G", "variance.B"];
    let nch = if job.variance { 6 } else { 3 };
    let names: Vec<String> = all[..nch].iter().map(|s| s.to_string()).collect();
    let strip = crate::pipeline::auto_strip_rows(sc.w, nch);
    let spp = i32::try_from(n).unwrap_or(i32::MAX);
    let ints = [("spp", spp)];
    let spec = OutSpec {
        path: &job.output,
        format: out_format,
        w: sc.w,
        h: sc.h,
        names: &names,
        compression: job.compression,
        strip,
        ints: &ints,
    };
    let w = sc.w;
    write_streamed(
        &spec,
        |y, k| {
            let rows = sc.spp_rows(n, y, k);
            if job.variance {
                rows
            } else {
                rows.chunks(6 * w)
                    .flat_map(|r| r[..3 * w].iter().copied())
                    .collect()
            }
        },
        progress,
    )?;
    if let Some(t) = &job.truth {
        let spec = OutSpec {
            path: t,
            format: truth_format.unwrap_or(out_format),
            names: &rgb,
            strip: 64,
            ints: &[],
            ..spec
        };
        write_streamed(&spec, |y, k| sc.spp_truth_rows(y, k), &|_, _| {})?;
    }
    Ok((sc.w, sc.h))
}

/// Run a `synth` job; `progress(rows done, rows)`.
pub fn synth(job: &SynthJob, progress: &(dyn Fn(usize, usize) + Sync)) -> Result<SynthReport> {
    let sc = &job.scene;
    if sc.w == 0 || sc.h == 0 {
        return Err(Error::Config("--size must be at least 1x1".into()));
    }
    if !(sc.hot.is_finite() && sc.hot > 0.0) {
        return Err(Error::Config(format!(
            "--hot must be a positive number, got {}",
            sc.hot
        )));
    }
    // Both names are checked before anything is written.
    let format_of = |p: &Path| {
        crate::io::format::output_format(p, job.format, Some(Format::Exr), WRITES, "synth")
    };
    let out_format = format_of(&job.output)?;
    let truth_format = job.truth.as_deref().map(format_of).transpose()?;
    let formats = (out_format, truth_format);
    let pool = crate::pipeline::thread_pool(job.threads)?;
    let start = Instant::now();
    let (width, height) = pool.install(|| -> Result<(usize, usize)> {
        match job.sampling {
            Sampling::Supersample(s) => write_supersampled(job, s, formats, progress),
            Sampling::Spp(n) => write_spp(job, n, formats, progress),
        }
    })?;
    Ok(SynthReport {
        output: job.output.display().to_string(),
        width,
        height,
        truth: job.truth.as_ref().map(|t| t.display().to_string()),
        seconds: start.elapsed().as_secs_f64(),
        peak_rss_bytes: crate::host::peak_rss_bytes(),
    })
}
