//! The stage factory: each method's stage, built with the checks it needs,
//! behind the [`Stage`] contract the skeleton ([`super::stream`]) runs.

use super::order::OrderStage;
use super::pixel::{ExcessRule, GaussRule, PixelStage};
use super::spread::GaussianStage;
use super::stage::Stage;
use super::{PipelineConfig, StripLayout};
use crate::error::{Error, Result};
use crate::filter::ep_box::{Spp, StatsLayout};
use crate::filter::guides::{AlbedoOnly, EmissionParts, Surface, SurfaceGuides};
use crate::filter::{Method, ValidParams};

/// Strips the stage of `method` at `s` works on at once under `cfg`: the
/// Gaussian family's [`PipelineConfig::strips_in_flight`], one for the
/// others.
pub fn strips_in_flight(cfg: &PipelineConfig, method: Method, s: usize) -> usize {
    match method {
        Method::EpBox | Method::Median | Method::AlphaTrim => 1,
        Method::EpGauss if s == 1 => 1,
        _ => cfg.strips_in_flight(),
    }
}

/// The stage of `params.method` for strips laid out as `job`, its
/// accumulators cut in column tiles of `tile`.
pub fn make(
    job: &StripLayout,
    params: &ValidParams,
    cfg: &PipelineConfig,
) -> Result<Box<dyn Stage>> {
    let tile = cfg.tile;
    let (grid, nch) = (job.grid, job.channels.len());
    Ok(match params.method {
        Method::EpBox => {
            let stats = job
                .stats
                .clone()
                .ok_or_else(|| Error::Config("ep-box needs per-pixel variance channels".into()))?;
            let ltvis = params.ep_box.ltvis.ok_or_else(|| {
                Error::Config("ep-box needs L_tvis: measure L_ave first (mean_luminance)".into())
            })?;
            let mut stage = PixelStage::new(ExcessRule::new(
                (grid.in_w, grid.in_h),
                (job.luminance.clone(), job.modes.clone(), job.aux.len()),
                stats,
                (params, ltvis),
                (job.guides.clone(), job.surface_rule),
            )?);
            stage.set_task_columns(cfg.classify_samples);
            stage.set_last_rows(job.strip_rows(cfg));
            Box::new(stage)
        }
        Method::EpGauss if grid.s == 1 && job.guides.albedo_only() => {
            pixel_gauss::<AlbedoOnly>(job, params, cfg)?
        }
        Method::EpGauss if grid.s == 1 => pixel_gauss::<Surface>(job, params, cfg)?,
        Method::Median | Method::AlphaTrim => {
            Box::new(OrderStage::new(grid, job.modes.clone(), params))
        }
        _ => {
            let nall = job.strip_channels();
            let stats_ok = |st: &StatsLayout| {
                let ok = |i: usize| i >= nch && i < nall;
                (st.variance.len() == 1 || (st.variance.len() == 3 && nch >= 3))
                    && st.variance.iter().all(|&i| ok(i))
                    && st.mean_y.is_none_or(ok)
                    && match st.spp {
                        Spp::Channel(i) => ok(i),
                        Spp::Fixed(n) => n.is_finite() && n >= 2.0,
                    }
            };
            if job.stats.as_ref().is_some_and(|st| !stats_ok(st)) {
                return Err(Error::Config(
                    "ep-gauss at S = 1 reads one or three variance channels and a sample count of at least 2".into(),
                ));
            }
            let mut stage =
                GaussianStage::new(grid, job.luminance.clone(), job.modes.clone(), params, tile);
            if let Some(real) = job.padded_from {
                stage.set_real_size(real);
            }
            if let Some(e) = &job.guides.emission {
                let colour: Vec<usize> = (0..nch).filter(|&c| job.luminance[c] != 0.0).collect();
                if e.len() != colour.len() {
                    return Err(Error::Config(format!(
                        "the emission guide has {} channels, the beauty {}",
                        e.len(),
                        colour.len()
                    )));
                }
                let weights: Vec<f64> = colour.iter().map(|&c| job.luminance[c]).collect();
                stage.set_emission(EmissionParts::new(&colour, e, &weights));
            }
            stage.set_classify_samples(cfg.classify_samples);
            stage.set_spread_chunk(cfg.spread_chunk);
            stage.set_strips_in_flight(cfg.strips_in_flight());
            Box::new(stage)
        }
    })
}

/// ep-gauss's stage at S = 1, its windows holding the surface guides as
/// `G`.
fn pixel_gauss<G: SurfaceGuides>(
    job: &StripLayout,
    params: &ValidParams,
    cfg: &PipelineConfig,
) -> Result<Box<dyn Stage>> {
    let grid = job.grid;
    let mut stage = PixelStage::new(GaussRule::<G>::new(
        (grid.in_w, grid.in_h),
        job.luminance.clone(),
        job.modes.clone(),
        (job.guides.clone(), job.surface_rule),
        params,
    )?);
    stage.set_task_columns(cfg.classify_samples);
    stage.set_last_rows(job.strip_rows(cfg));
    Ok(Box::new(stage))
}
