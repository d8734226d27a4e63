//! epfilt's lab: what measures the filter rather than filtering. The
//! binaries (`src/bin/`) are the render evaluation and its sweeps
//! (`eval-renders`), the speed/accuracy study on synthetic scenes
//! (`tradeoff`), bench inputs (`fireflies`) and the scaling model
//! (`scaling-model`), run by the scripts in `scripts/`; this library holds
//! what they share.

pub mod canvas;
pub mod chart;
pub mod model;
