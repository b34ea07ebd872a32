//! GDMLT core: gradient-domain primary-sample-space Metropolis light transport.
//!
//! Data flow: scene arrays (`scene::SceneDesc`) → `scene::Scene` → `integrator` (built on
//! `path`, the one path builder) → `film` → output (`output`: EXR/PNG) and the Python
//! binding (`python`, behind the `python` feature).

// `!(x > 0.0)` is this crate's NaN-safe test (true for NaN), used on purpose throughout.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod accel;
pub mod bsdf;
pub mod distribution;
pub mod error;
pub mod film;
pub mod guiding;
pub mod instancing;
pub mod integrator;
pub mod math;
pub mod medium;
pub mod output;
pub mod path;
pub mod pixel_filter;
pub mod reconstruct;
pub mod sampler;
pub mod scene;
pub mod shift;
pub mod sobol;
#[cfg(test)]
pub(crate) mod test_stats;

#[cfg(feature = "python")]
mod python;

pub use error::{RenderError, SceneError};
pub use integrator::{render, Method, RenderControl, RenderOutput, RenderSettings};
pub use scene::{Scene, SceneDesc};
