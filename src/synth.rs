//! Noisy scenes with exact ground truth.
//!
//! Each super-sample sees, with probability `p(x, y)`, a bright source of
//! radiance `L_hot * colour_hot`, and otherwise a smooth dim base
//! `b(x, y) * colour_base` — the two-valued mixtures of the paper's Fig. 1.
//! The expected value `p * L_hot + (1 - p) * b` is known for every sample
//! cell, so the truth of every output pixel is exact. Random numbers come from
//! a counter-based hash of (seed, sample x, sample y): any strip can be made
//! alone, at any thread count, with the same bytes.
//!
//! The `mixed` scene holds the four high-variance cases of §4.1: a light
//! source edge (a bright disc partly covering pixels: `p` is the cell's
//! coverage), a penumbra (`p` ramps smoothly), a glossy highlight (small `p`
//! in a soft blob) and a caustic (small `p` in a sharp-edged pattern).

use rayon::prelude::*;

/// Scene parameters.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Output width in pixels.
    pub w: usize,
    /// Output height in pixels.
    pub h: usize,
    /// Super-sampling factor.
    pub s: usize,
    /// Random seed.
    pub seed: u64,
    /// Ratio of the hot radiance to the base.
    pub hot: f64,
}

const BASE_RGB: [f64; 3] = [0.80, 0.70, 0.55];

fn hash(seed: u64, i: u64, j: u64) -> u64 {
    let mut z =
        seed ^ i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ j.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl Scene {
    /// Input size in samples.
    pub fn input_size(&self) -> (usize, usize) {
        (self.w * self.s, self.h * self.s)
    }

    /// Base radiance at output-pixel coordinates `(u, v)`.
    fn base(&self, u: f64, v: f64) -> f64 {
        let (w, h) = (self.w as f64, self.h as f64);
        0.05 * (1.0 + 0.4 * (u / w * 5.0).sin() * (v / h * 3.0).cos() + 0.3 * v / h)
    }

    /// Probability of a hot sample, its radiance and colour, for the sample
    /// cell with corner `(u, v)` and side `d` (output pixels).
    fn hot_at(&self, u: f64, v: f64, d: f64) -> (f64, f64, [f64; 3]) {
        let (w, h) = (self.w as f64, self.h as f64);
        let m = w.min(h);
        let (cu, cv) = (u + d / 2.0, v + d / 2.0);
        // Light source edge: coverage of the cell by a disc, 4x4 sub-points.
        let (lx, ly, lr) = (0.18 * w, 0.28 * h, 0.09 * m);
        if (cu - lx).hypot(cv - ly) < lr + d {
            let mut n = 0;
            for a in 0..4 {
                for b in 0..4 {
                    let (x, y) = (
                        u + (a as f64 + 0.5) * d / 4.0,
                        v + (b as f64 + 0.5) * d / 4.0,
                    );
                    n += ((x - lx).hypot(y - ly) < lr) as u32;
                }
            }
            if n > 0 {
                return (n as f64 / 16.0, self.hot * 0.05, [1.0, 0.97, 0.92]);
            }
        }
        // Caustic: a sharp-edged ring, p = 2%.
        let (ccx, ccy) = (0.72 * w, 0.70 * h);
        let rr = (cu - ccx).hypot(cv - ccy);
        if (0.10 * m..0.13 * m).contains(&rr) && cv > ccy - 0.05 * m {
            return (0.02, self.hot * 0.05 * 0.3, [0.55, 0.75, 1.0]);
        }
        // Glossy highlight: p up to 3% in a soft blob.
        let (gx, gy, gs) = (0.55 * w, 0.30 * h, 0.06 * m);
        let g = (-((cu - gx).powi(2) + (cv - gy).powi(2)) / (gs * gs)).exp();
        if g > 1e-3 {
            return (0.03 * g, self.hot * 0.05 * 0.5, [1.0, 0.85, 0.6]);
        }
        // Penumbra: p ramps from 0 to 25% across a band.
        if cu > 0.08 * w && cu < 0.45 * w && cv > 0.62 * h && cv < 0.92 * h {
            let p = 0.25 * smoothstep(0.08 * w, 0.45 * w, cu);
            return (p, self.hot * 0.05 * 0.2, [1.0, 0.97, 0.92]);
        }
        (0.0, 0.0, [0.0; 3])
    }

    /// Input rows `j0..j0 + rows` as planar RGB (`[row][channel][x]`).
    pub fn noisy_rows(&self, j0: usize, rows: usize) -> Vec<f32> {
        let (iw, _) = self.input_size();
        let d = 1.0 / self.s as f64;
        let mut out = vec![0.0f32; rows * 3 * iw];
        out.par_chunks_mut(3 * iw).enumerate().for_each(|(r, row)| {
            let j = j0 + r;
            let v = j as f64 * d;
            for i in 0..iw {
                let u = i as f64 * d;
                let (p, l, col) = self.hot_at(u, v, d);
                let x = (hash(self.seed, i as u64, j as u64) >> 11) as f64 / (1u64 << 53) as f64;
                let rgb: [f64; 3] = if x < p {
                    [l * col[0], l * col[1], l * col[2]]
                } else {
                    let b = self.base(u + d / 2.0, v + d / 2.0);
                    [b * BASE_RGB[0], b * BASE_RGB[1], b * BASE_RGB[2]]
                };
                for c in 0..3 {
                    row[c * iw + i] = rgb[c] as f32;
                }
            }
        });
        out
    }

    /// The expected value of every sample cell (input resolution), rows
    /// `j0..j0 + rows`, planar RGB: what an infinitely sampled render would
    /// hold. Filtered with a method's base kernel it gives that method's
    /// noise-free result.
    pub fn expected_rows(&self, j0: usize, rows: usize) -> Vec<f32> {
        let (iw, _) = self.input_size();
        let d = 1.0 / self.s as f64;
        let mut out = vec![0.0f32; rows * 3 * iw];
        out.par_chunks_mut(3 * iw).enumerate().for_each(|(r, row)| {
            let v = (j0 + r) as f64 * d;
            for i in 0..iw {
                let u = i as f64 * d;
                let (p, l, col) = self.hot_at(u, v, d);
                let base = self.base(u + d / 2.0, v + d / 2.0);
                for c in 0..3 {
                    row[c * iw + i] = (p * l * col[c] + (1.0 - p) * base * BASE_RGB[c]) as f32;
                }
            }
        });
        out
    }

    /// Truth at output resolution, rows `y0..y0 + rows`, planar RGB.
    pub fn truth_rows(&self, y0: usize, rows: usize) -> Vec<f32> {
        let (s, w) = (self.s, self.w);
        let d = 1.0 / s as f64;
        let mut out = vec![0.0f32; rows * 3 * w];
        out.par_chunks_mut(3 * w).enumerate().for_each(|(r, row)| {
            let y = y0 + r;
            for x in 0..w {
                let mut acc = [0.0f64; 3];
                for b in 0..s {
                    for a in 0..s {
                        let (u, v) = ((x * s + a) as f64 * d, (y * s + b) as f64 * d);
                        let (p, l, col) = self.hot_at(u, v, d);
                        let base = self.base(u + d / 2.0, v + d / 2.0);
                        for c in 0..3 {
                            acc[c] += p * l * col[c] + (1.0 - p) * base * BASE_RGB[c];
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
}
