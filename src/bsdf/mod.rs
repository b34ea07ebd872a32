//! BSDFs in the local shading frame (z = shading normal, flipped to face the outgoing
//! direction). Every BSDF answers the same three questions — eval, sample, pdf — and says
//! which kind of lobe produced a sample, which the shift mapping needs to decide between
//! reconnection and half-vector copy (Kettunen et al. 2015).

mod lambert;
#[cfg(test)]
pub(crate) mod testing;

pub use lambert::Lambert;

use crate::math::Spectrum;
use glam::{Vec2, Vec3};

/// Roughness at or below which a lobe is treated as specular by the shift mapping
/// (the public GDPT code uses 0.001; ALGORITHM.md §4).
pub const SPECULAR_ROUGHNESS_THRESHOLD: f32 = 1e-3;

/// What kind of lobe a sample came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LobeKind {
    /// Smooth, reconnectable (Lambertian, rough microfacet above the threshold).
    Diffuse,
    /// Dirac delta: mirror or smooth dielectric.
    Specular,
}

/// The result of importance-sampling a BSDF.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Incident direction (local frame), the direction the path continues in.
    pub wi: Vec3,
    /// f(wo, wi)·|cos θi| / pdf.
    pub weight: Spectrum,
    /// Solid-angle pdf of `wi` (for a delta lobe: the discrete lobe probability).
    pub pdf: f32,
    pub lobe: LobeKind,
    /// Relative IOR crossed (1 for reflection).
    pub eta: f32,
}

/// A BSDF instance at one surface point. An enum, not a trait object: no allocation and
/// static dispatch on the hot path.
#[derive(Clone, Copy, Debug)]
pub enum Bsdf {
    Lambert(Lambert),
}

impl Bsdf {
    /// f(wo, wi)·|cos θi| for non-delta lobes; zero for delta lobes.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Spectrum {
        match self {
            Bsdf::Lambert(b) => b.eval(wo, wi),
        }
    }

    /// Solid-angle density with which `sample` returns `wi` (non-delta lobes only).
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Bsdf::Lambert(b) => b.pdf(wo, wi),
        }
    }

    /// Samples an incident direction from two primary samples plus one for lobe selection.
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let _ = u_lobe;
        match self {
            Bsdf::Lambert(b) => b.sample(wo, u),
        }
    }

    /// True when every lobe is a Dirac delta (no light connection is possible).
    #[inline]
    pub fn is_delta(&self) -> bool {
        match self {
            Bsdf::Lambert(_) => false,
        }
    }

    /// Smallest roughness over the lobes (1 for Lambert); the shift mapping compares it with
    /// [`SPECULAR_ROUGHNESS_THRESHOLD`].
    #[inline]
    pub fn min_roughness(&self) -> f32 {
        match self {
            Bsdf::Lambert(_) => 1.0,
        }
    }

    /// Diffuse-like albedo, written to the denoising albedo pass.
    pub fn albedo(&self) -> Spectrum {
        match self {
            Bsdf::Lambert(b) => b.albedo,
        }
    }
}
