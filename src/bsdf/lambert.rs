//! Lambertian diffuse reflection: f = albedo/π (pbrt-v4 §9.2).

use super::{BsdfSample, LobeKind};
use crate::math::{cosine_hemisphere_pdf, square_to_cosine_hemisphere, Spectrum};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Clone, Copy, Debug)]
pub struct Lambert {
    pub albedo: Spectrum,
}

impl Lambert {
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Spectrum {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Spectrum::ZERO;
        }
        self.albedo * (FRAC_1_PI * wi.z)
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        cosine_hemisphere_pdf(wi.z)
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = square_to_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wi.z);
        if pdf <= 0.0 {
            return None;
        }
        // f·cos/pdf = (albedo/π)·cos / (cos/π) = albedo
        Some(BsdfSample { wi, weight: self.albedo, pdf, lobe: LobeKind::Diffuse, eta: 1.0 })
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
}
