//! # epfilt — energy-preserving non-linear filters for huge HDR renders
//!
//! Implements Rushmeier & Ward, "Energy Preserving Non-Linear Filters"
//! (SIGGRAPH 1994): each noisy Monte Carlo sample is *spread* over a region just
//! wide enough that its influence on any output pixel is below a tolerance.
//! Every sample's weights sum to one, so the image's energy is exact; samples
//! that are not noise keep the base kernel (minimal disruption).
//!
//! The work streams: an EXR is read strip by strip from a memory map, a rolling
//! halo of rows feeds tile accumulators, and finished rows are written at once.
//! Memory depends on the width and the halo, never on the height; the output is
//! bit-identical for any tile size, strip height and thread count.
//!
//! ```
//! use epfilt::{filter_in_memory, FilterParams, Grid, StripLayout, Method, PipelineConfig};
//!
//! // A 6x6 grey image, super-sampled 3x3, with one firefly.
//! let mut img = vec![1.0f32; 36];
//! img[14] = 1000.0;
//! let job = StripLayout::new(Grid { in_w: 6, in_h: 6, s: 3 }, vec!["Y".into()], vec![1.0]);
//! let params = FilterParams::new(Method::EpGauss, 3);
//! let (out, stats) = filter_in_memory(img, &job, &params, &PipelineConfig::default()).unwrap();
//! assert_eq!(out.len(), 4);
//! assert!(stats.ledger[0].rel_error < 1e-12);   // energy is exact
//! assert_eq!(stats.ep_gauss().unwrap().noisy, 1); // only the firefly was spread
//! ```
//!
//! Modules: [`geometry`] (grid, reflection, halo), [`filter`] (kernels and the
//! noise rule), [`pipeline`] (windows, tiles, ledger, scheduling), [`io`] (EXR
//! in and out), [`report`] (the summary and `--report`), [`synth`] (scenes with exact truth),
//! [`compare`], [`preview`] (display mapping, PNG), [`demo`].
#![deny(missing_docs)]
#![deny(unsafe_code)]
// `!(x > 0.0)` is deliberate throughout: it is true for NaN, which must take
// the safe branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod compare;
pub mod demo;
pub mod error;
pub mod filter;
pub mod geometry;
pub mod host;
pub mod io;
pub mod job;
pub mod merge;
pub mod pipeline;
pub mod plan;
pub mod preview;
pub mod report;
pub mod sequence;
pub mod synth;
pub mod trace;

pub use error::{Error, Result};
pub use filter::{FilterParams, Method};
pub use geometry::Grid;
pub use job::restore::{restore_file, RestoreJob};
pub use job::{filter_file, filter_opened, FilterJob};
pub use pipeline::{filter_in_memory, PipelineConfig, Precision, RunStats, StripLayout};
