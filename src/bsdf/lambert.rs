//! Lambertian diffuse reflection: f = albedo/π (pbrt-v4 §9.2).
//!
//! As Cycles' Diffuse BSDF, it does not look at the side `wo` arrives from: an interpolated
//! (smooth-shading) normal can leave `wo` below the shading hemisphere while the ray still
//! arrives above the geometric surface, and the surface then scatters as usual into the
//! shading hemisphere (the path builder drops directions below the geometric surface, as
//! Cycles' `bsdf_diffuse_sample` does). Refusing such `wo` darkened smooth-shaded low-poly
//! meshes by 5–50% against Cycles.

use super::{BsdfSample, LobeKind, Scatter};
use crate::math::{cosine_hemisphere_pdf, square_to_cosine_hemisphere, Spectrum};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Clone, Copy, Debug)]
pub struct Lambert {
    pub albedo: Spectrum,
}

impl Lambert {
    #[inline]
    pub fn eval(&self, _wo: Vec3, wi: Vec3) -> Spectrum {
        if wi.z <= 0.0 {
            return Spectrum::ZERO;
        }
        self.albedo * (FRAC_1_PI * wi.z)
    }

    #[inline]
    pub fn pdf(&self, _wo: Vec3, wi: Vec3) -> f32 {
        cosine_hemisphere_pdf(wi.z)
    }

    #[inline]
    pub fn sample(&self, _wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let wi = square_to_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wi.z);
        if pdf <= 0.0 {
            return None;
        }
        // f·cos/pdf = (albedo/π)·cos / (cos/π) = albedo
        Some(BsdfSample { wi, weight: self.albedo, pdf, lobe: LobeKind::Diffuse, eta: 1.0, scatter: Scatter::Diffuse })
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{chi2_test, white_furnace};
    use super::super::Bsdf;
    use super::*;

    #[test]
    fn lambert_chi2() {
        let b = Bsdf::Lambert(Lambert { albedo: Spectrum::ONE });
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.3, 0.9, 0.316).normalize()] {
            chi2_test(&b, wo, 0xC0FFEE);
        }
    }

    #[test]
    fn lambert_white_furnace() {
        let b = Bsdf::Lambert(Lambert { albedo: Spectrum::ONE });
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8)] {
            let (by_sampling, by_quadrature) = white_furnace(&b, wo, 400_000, 11);
            assert!((by_sampling - 1.0).abs() < 1e-3, "sampled albedo {by_sampling}");
            assert!((by_quadrature - 1.0).abs() < 1e-2, "integrated albedo {by_quadrature}");
        }
    }

    /// A view direction below the shading hemisphere (smooth shading on a coarse mesh) still
    /// scatters: the same f, pdf and samples as from above (Cycles' Diffuse BSDF), so the
    /// white furnace still gives 1. Returned black before (the smooth-room test's dark corners).
    #[test]
    fn lambert_ignores_the_side_wo_arrives_from() {
        let b = Bsdf::Lambert(Lambert { albedo: Spectrum::ONE });
        let below = Vec3::new(0.8, 0.0, -0.6);
        let wi = Vec3::new(-0.3, 0.2, 0.93).normalize();
        assert_eq!(b.eval(below, wi), b.eval(Vec3::Z, wi));
        assert_eq!(b.pdf(below, wi), b.pdf(Vec3::Z, wi));
        assert!(b.eval(below, wi).x > 0.0);
        let (by_sampling, _) = white_furnace(&b, below, 100_000, 12);
        assert!((by_sampling - 1.0).abs() < 1e-3, "sampled albedo {by_sampling}");
        chi2_test(&b, below, 0xBE10);
    }
}
