//! Diffuse transmission, Blender's Translucent BSDF (Cycles' `bsdf_translucent`): light leaves
//! on the side away from the viewer, f = albedo/π, sampled cosine-weighted there. As a lobe of
//! the Principled mixture its `weight` is its share of the BSDF (0: none).

use super::bump_shadowing::diffuse_bump_shadowing;
use crate::math::{cosine_hemisphere_pdf, square_to_cosine_hemisphere, Spectrum};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Clone, Copy, Debug)]
pub struct Translucent {
    pub weight: f32,
    pub albedo: Spectrum,
    /// The unmapped normal in the shading frame (`bump_shadowing.rs`; +Z: none).
    pub unmapped: Vec3,
}

impl Translucent {
    /// No diffuse transmission.
    pub const NONE: Translucent = Translucent { weight: 0.0, albedo: Spectrum::ZERO, unmapped: Vec3::Z };

    #[inline]
    pub fn is_some(&self) -> bool {
        self.weight > 0.0
    }

    /// weight·f·|cos θi| (zero on the viewer's side).
    #[inline]
    pub fn eval(&self, wi: Vec3) -> Spectrum {
        if !self.is_some() || wi.z >= 0.0 {
            return Spectrum::ZERO;
        }
        self.albedo * (self.weight * FRAC_1_PI * -wi.z * diffuse_bump_shadowing(self.unmapped, wi))
    }

    /// The lobe's own density of `wi` (the caller weighs it by the lobe's probability).
    #[inline]
    pub fn pdf(&self, wi: Vec3) -> f32 {
        if wi.z >= 0.0 {
            return 0.0;
        }
        cosine_hemisphere_pdf(-wi.z)
    }

    /// A direction on the far side, cosine-weighted.
    #[inline]
    pub fn sample_wi(&self, u: Vec2) -> Option<Vec3> {
        let w = square_to_cosine_hemisphere(u);
        (w.z > 0.0).then(|| Vec3::new(w.x, w.y, -w.z))
    }
}
