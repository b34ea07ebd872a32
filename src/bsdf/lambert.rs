//! Diffuse reflection: Lambertian, f = albedo/π (pbrt-v4 §9.2), or with a roughness σ > 0
//! rough diffuse as Cycles' Oren–Nayar (`oren_nayar.rs`), sampled alike (cosine-weighted).
//!
//! As Cycles' Diffuse BSDF, it does not look at the side `wo` arrives from: an interpolated
//! (smooth-shading) normal can leave `wo` below the shading hemisphere while the ray still
//! arrives above the geometric surface, and the surface then scatters as usual into the
//! shading hemisphere (the path builder drops directions below the geometric surface, as
//! Cycles' `bsdf_diffuse_sample` does). Refusing such `wo` darkened smooth-shaded low-poly
//! meshes by 5–50% against Cycles.
//!
//! Under a normal or bump map the lobe is shadowed as Cycles shadows it (`bump_shadowing.rs`).

use super::bump_shadowing::diffuse_bump_shadowing;
use super::oren_nayar::{ColourPower, OrenNayar};
use super::{BsdfSample, LobeKind, Scatter};
use crate::math::{cosine_hemisphere_pdf, square_to_cosine_hemisphere, Spectrum};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Clone, Copy, Debug)]
pub struct Lambert {
    pub albedo: Spectrum,
    /// Blender's diffuse roughness σ ∈ [0, 1]: 0 = Lambertian, above it Oren–Nayar.
    pub roughness: f32,
    /// How Oren–Nayar's multiple scattering takes the colour (Cycles 5.3's, or 4.5–5.2's).
    pub power: ColourPower,
    /// The surface's normal before normal/bump mapping, in the shading frame (whose Z is the
    /// mapped normal): +Z where nothing maps it, and then no bump shadowing.
    pub unmapped: Vec3,
}

impl Lambert {
    /// A Lambertian of this albedo.
    #[inline]
    pub fn new(albedo: Spectrum) -> Lambert {
        Lambert { albedo, roughness: 0.0, power: ColourPower::Squared, unmapped: Vec3::Z }
    }

    /// A Lambertian (or Oren–Nayar, σ = `roughness`) of this albedo, not bumped.
    #[inline]
    pub fn rough(albedo: Spectrum, roughness: f32) -> Lambert {
        Lambert { albedo, roughness, power: ColourPower::Squared, unmapped: Vec3::Z }
    }

    /// The bump shadowing factor towards `wi` (`bump_shadowing.rs`), 1 without a mapped normal.
    #[inline]
    pub fn bump_shadowing(&self, wi: Vec3) -> f32 {
        diffuse_bump_shadowing(self.unmapped, wi)
    }

    /// Cycles treats roughness below this as Lambertian.
    const ROUGH: f32 = 1e-5;

    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Spectrum {
        if wi.z <= 0.0 {
            return Spectrum::ZERO;
        }
        let shadowing = self.bump_shadowing(wi);
        if self.roughness < Self::ROUGH {
            return self.albedo * (FRAC_1_PI * wi.z * shadowing);
        }
        self.albedo * (OrenNayar::new(self.roughness, self.albedo, self.power).eval(wo.z, wi.z, wo.dot(wi)) * shadowing)
    }

    #[inline]
    pub fn pdf(&self, _wo: Vec3, wi: Vec3) -> f32 {
        cosine_hemisphere_pdf(wi.z)
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        let wi = square_to_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wi.z);
        if pdf <= 0.0 {
            return None;
        }
        // Lambertian: f·cos/pdf = (albedo/π)·cos / (cos/π) = albedo (times the shadowing)
        let weight =
            if self.roughness < Self::ROUGH { self.albedo * self.bump_shadowing(wi) } else { self.eval(wo, wi) / pdf };
        Some(BsdfSample { wi, weight, pdf, lobe: LobeKind::Diffuse, eta: 1.0, scatter: Scatter::Diffuse })
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{chi2_test, white_furnace};
    use super::super::Bsdf;
    use super::*;

    #[test]
    fn lambert_chi2() {
        let b = Bsdf::Lambert(Lambert::new(Spectrum::ONE));
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.3, 0.9, 0.316).normalize()] {
            chi2_test(&b, wo, 0xC0FFEE);
        }
    }

    #[test]
    fn lambert_white_furnace() {
        let b = Bsdf::Lambert(Lambert::new(Spectrum::ONE));
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
        let b = Bsdf::Lambert(Lambert::new(Spectrum::ONE));
        let below = Vec3::new(0.8, 0.0, -0.6);
        let wi = Vec3::new(-0.3, 0.2, 0.93).normalize();
        assert_eq!(b.eval(below, wi), b.eval(Vec3::Z, wi));
        assert_eq!(b.pdf(below, wi), b.pdf(Vec3::Z, wi));
        assert!(b.eval(below, wi).x > 0.0);
        let (by_sampling, _) = white_furnace(&b, below, 100_000, 12);
        assert!((by_sampling - 1.0).abs() < 1e-3, "sampled albedo {by_sampling}");
        chi2_test(&b, below, 0xBE10);
    }

    /// Rough diffuse (Oren–Nayar with its multiple-scattering term) keeps a white surface's
    /// energy at every roughness and view angle; a coloured one reflects by sampling what the
    /// quadrature of its eval gives (the sample weight is f·cos/pdf); sampling passes χ².
    #[test]
    fn rough_diffuse_white_furnace_and_chi2() {
        for sigma in [0.3f32, 0.7, 1.0] {
            let white = Bsdf::Lambert(Lambert::rough(Spectrum::ONE, sigma));
            for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.995, 0.0, 0.0999).normalize()] {
                let (by_sampling, by_quadrature) = white_furnace(&white, wo, 200_000, 13);
                assert!((by_sampling - 1.0).abs() < 3e-3, "σ={sigma} wo={wo}: sampled {by_sampling}");
                assert!((by_quadrature - 1.0).abs() < 1e-2, "σ={sigma} wo={wo}: integrated {by_quadrature}");
            }
            let orange = Bsdf::Lambert(Lambert::rough(Spectrum::new(0.9, 0.4, 0.1), sigma));
            let wo = Vec3::new(0.6, 0.0, 0.8);
            let (by_sampling, by_quadrature) = white_furnace(&orange, wo, 200_000, 14);
            assert!((by_sampling - by_quadrature).abs() < 0.01 * by_quadrature, "{by_sampling} {by_quadrature}");
            // darker than a Lambertian of the same colour: single scattering loses energy and
            // the multiple scattering gives it back only in proportion to ρ²
            assert!(by_sampling < crate::math::luminance(Spectrum::new(0.9, 0.4, 0.1)) as f64);
            chi2_test(&orange, wo, 15);
        }
    }

    /// Backscatter: a rough surface lit from the viewer's side is brighter towards grazing
    /// view than a Lambertian (Oren–Nayar's flattening), darker in forward scattering.
    #[test]
    fn rough_diffuse_scatters_back_towards_the_light() {
        let rough = Lambert::rough(Spectrum::ONE, 1.0);
        let flat = Lambert::new(Spectrum::ONE);
        let wo = Vec3::new(0.8, 0.0, 0.6);
        let back = Vec3::new(0.8, 0.0, 0.6);
        let forward = Vec3::new(-0.8, 0.0, 0.6);
        assert!(rough.eval(wo, back).x > 1.2 * flat.eval(wo, back).x);
        assert!(rough.eval(wo, forward).x < 0.8 * flat.eval(wo, forward).x);
        // roughness 0 is exactly the Lambertian
        let zero = Lambert::rough(Spectrum::ONE, 0.0);
        assert_eq!(zero.eval(wo, forward), flat.eval(wo, forward));
    }

    /// Under a normal map (the unmapped normal leaning 35° from the shading one): what
    /// sampling reflects equals the quadrature of eval (the sample weight carries the
    /// shadowing, the pdf does not), less than the unbumped lobe's, for smooth and rough
    /// diffuse; sampling still passes χ² (its density is unchanged).
    #[test]
    fn bumped_diffuse_samples_what_it_evaluates() {
        let unmapped = Vec3::new(-(35f32.to_radians().sin()), 0.0, 35f32.to_radians().cos());
        for sigma in [0.0f32, 0.7] {
            let plain = Lambert::rough(Spectrum::splat(0.8), sigma);
            let bumped = Lambert { unmapped, ..plain };
            for wo in [Vec3::Z, Vec3::new(-0.6, 0.0, 0.8), Vec3::new(0.5, 0.5, 0.707).normalize()] {
                let (by_sampling, by_quadrature) = white_furnace(&Bsdf::Lambert(bumped), wo, 200_000, 21);
                assert!((by_sampling - by_quadrature).abs() < 0.01 * by_quadrature, "σ={sigma} {wo}");
                let (unbumped, _) = white_furnace(&Bsdf::Lambert(plain), wo, 200_000, 21);
                assert!(by_sampling < unbumped - 0.01, "σ={sigma} {wo}: {by_sampling} vs {unbumped}");
            }
            chi2_test(&Bsdf::Lambert(bumped), Vec3::new(-0.6, 0.0, 0.8), 22);
        }
    }
}
