//! Comparing two images, streamed row by row: error against a reference and
//! energy ratio.

use std::path::Path;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::io::Selection;
use crate::pipeline::ledger::CompensatedSum;
use crate::pipeline::{Progress, Source};

/// Differences of image A against reference B, over all channels and pixels.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// Root mean square error.
    pub rmse: f64,
    /// Mean of `(a - b)^2 / (b^2 + eps)` with `eps = (0.01 * mean |b|)^2`,
    /// which keeps dark pixels from dominating.
    pub rel_mse: f64,
    /// PSNR in dB of A against B after the display mapping of
    /// [`crate::preview::Display`] set from B's average luminance (sRGB values
    /// 0..1, not quantized); infinite when they map identically.
    pub psnr: f64,
    /// Largest absolute difference.
    pub max_abs_diff: f64,
    /// `sum(A) / sum(B)` per channel.
    pub energy_ratio: Vec<f64>,
    /// Pixels where any channel differs.
    pub differing_pixels: u64,
    /// Bit-identical.
    pub identical: bool,
}

impl Comparison {
    /// A small human table.
    pub fn table(&self, channels: &[String]) -> String {
        let mut s = format!(
            "rmse              {:.6e}\nrel_mse           {:.6e}\npsnr              {:.2} dB\nmax_abs_diff      {:.6e}\ndiffering_pixels  {}\nidentical         {}\n",
            self.rmse, self.rel_mse, self.psnr, self.max_abs_diff, self.differing_pixels, self.identical
        );
        for (c, r) in channels.iter().zip(&self.energy_ratio) {
            s.push_str(&format!("energy_ratio {:<4} {:.15}\n", c, r));
        }
        s
    }
}

/// Limits a comparison must stay within (`compare --max-...`): what a
/// script or a CI job checks, as `idiff` does.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Thresholds {
    /// Largest RMSE allowed.
    pub max_rmse: Option<f64>,
    /// Largest relative MSE allowed.
    pub max_rel_mse: Option<f64>,
    /// Largest `|energy ratio - 1|` of any channel allowed.
    pub max_energy_error: Option<f64>,
}

impl Comparison {
    /// The worst `|sum(A) / sum(B) - 1|` over the channels.
    pub fn energy_error(&self) -> f64 {
        self.energy_ratio
            .iter()
            .map(|r| (r - 1.0).abs())
            .fold(
                0.0,
                |m: f64, e| if e.is_nan() { f64::INFINITY } else { m.max(e) },
            )
    }

    /// Each threshold exceeded, in words (empty: within every one).
    pub fn exceeded(&self, t: &Thresholds) -> Vec<String> {
        let mut out = Vec::new();
        let mut check = |name: &str, value: f64, limit: Option<f64>| {
            if let Some(l) = limit {
                if !(value <= l) {
                    out.push(format!("{name} {value:.6e} exceeds {l:e}"));
                }
            }
        };
        check("rmse", self.rmse, t.max_rmse);
        check("rel_mse", self.rel_mse, t.max_rel_mse);
        check("energy error", self.energy_error(), t.max_energy_error);
        out
    }
}

/// Refuse two images that differ in size or channels, saying how.
fn check_alike(
    (a, ia): (&Path, &crate::io::ExrInput),
    (b, ib): (&Path, &crate::io::ExrInput),
) -> Result<()> {
    if ia.size() == ib.size() && ia.channels() == ib.channels() {
        return Ok(());
    }
    let say = |p: &Path, i: &crate::io::ExrInput| {
        let (w, h) = i.size();
        format!(
            "{} is {w}x{h} with channels {}",
            p.display(),
            i.channels().join(", ")
        )
    };
    let what = match (ia.size() != ib.size(), ia.channels() != ib.channels()) {
        (true, true) => "size and channels",
        (true, false) => "size",
        _ => "channels",
    };
    Err(Error::Mismatch {
        path: a.to_path_buf(),
        reason: format!("{}; {}: they differ in {what}", say(a, ia), say(b, ib)),
    })
}

/// Compare `a` against the reference `b` (same size and channels), each
/// read as `select` says (`--part`, `--layer`); `progress(rows, total)`
/// over its two reads.
pub fn compare_files(
    a: &Path,
    b: &Path,
    select: &Selection,
    progress: Progress<'_>,
) -> Result<Comparison> {
    let (ia, ib) = (select.open(a)?, select.open(b)?);
    check_alike((a, &ia), (b, &ib))?;
    let (w, h) = ia.size();
    let nch = ia.channels().len();
    // Pass 1: mean |b| for the relative error's eps (a second read of B keeps
    // memory flat instead of holding per-pixel terms).
    let mut sum_b = CompensatedSum::default();
    let mut lum_b = CompensatedSum::default();
    let lum = ib.luminance();
    let mut n = 0u64;
    let mut sb = ib.source();
    while let Some(rb) = sb.next_strip(64)? {
        for (k, v) in rb.data.iter().enumerate() {
            sum_b.add((*v as f64).abs());
            lum_b.add(lum[(k / w) % nch] * *v as f64);
            n += 1;
        }
        progress(rb.y0 + rb.rows, 2 * h);
    }
    let mean_b = sum_b.value() / n.max(1) as f64;
    let display = crate::preview::Display::for_average(
        lum_b.value() / (n.max(1) / nch as u64).max(1) as f64,
        0.0,
    );
    let mut disp_sq = CompensatedSum::default();
    let eps = (0.01 * mean_b).powi(2).max(f64::MIN_POSITIVE);
    // Pass 2: everything else.
    let (mut sa, mut sb) = (ia.source(), ib.source());
    let mut sum_sq = CompensatedSum::default();
    let mut rel = CompensatedSum::default();
    let mut ea = vec![CompensatedSum::default(); nch];
    let mut eb = vec![CompensatedSum::default(); nch];
    let (mut max_abs, mut differing) = (0.0f64, 0u64);
    while let (Some(ra), Some(rb)) = (sa.next_strip(64)?, sb.next_strip(64)?) {
        for r in 0..ra.rows {
            for x in 0..w {
                let mut diff = false;
                for c in 0..nch {
                    let k = (r * nch + c) * w + x;
                    let (va, vb) = (ra.data[k] as f64, rb.data[k] as f64);
                    diff |= ra.data[k].to_bits() != rb.data[k].to_bits();
                    let d = va - vb;
                    sum_sq.add(d * d);
                    let dd = display.encode(va) - display.encode(vb);
                    disp_sq.add(dd * dd);
                    rel.add(d * d / (vb * vb + eps));
                    max_abs = max_abs.max(d.abs());
                    ea[c].add(va);
                    eb[c].add(vb);
                }
                differing += diff as u64;
            }
        }
        progress(h + ra.y0 + ra.rows, 2 * h);
    }
    let n = n.max(1) as f64;
    Ok(Comparison {
        rmse: (sum_sq.value() / n).sqrt(),
        psnr: {
            let mse = disp_sq.value() / n;
            if mse > 0.0 {
                -10.0 * mse.log10()
            } else {
                f64::INFINITY
            }
        },
        rel_mse: rel.value() / n,
        max_abs_diff: max_abs,
        energy_ratio: ea
            .iter()
            .zip(&eb)
            .map(|(a, b)| a.value() / b.value())
            .collect(),
        differing_pixels: differing,
        identical: differing == 0,
    })
}
