//! Smooth dielectric (glass): Fresnel-weighted choice between mirror reflection and
//! refraction (pbrt-v4 §9.5). `eta` is the relative IOR η_t/η_i for the side the ray arrives
//! from (the material flips it when the ray exits). Transmitted radiance is scaled by 1/η²
//! (radiance, not importance, is transported from the camera).

use super::microfacet::{fresnel_dielectric, refract};
use super::{BsdfSample, LobeKind};
use crate::math::Spectrum;
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub struct SmoothDielectric {
    pub eta: f32,
    pub tint: Spectrum,
}

impl SmoothDielectric {
    pub fn sample(&self, wo: Vec3, u_lobe: f32) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let f = fresnel_dielectric(wo.z, self.eta);
        if u_lobe < f {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            return Some(BsdfSample { wi, weight: self.tint, pdf: f, lobe: LobeKind::Specular, eta: 1.0 });
        }
        let wi = refract(wo, Vec3::Z, self.eta)?;
        Some(BsdfSample {
            wi,
            weight: self.tint / (self.eta * self.eta),
            pdf: 1.0 - f,
            lobe: LobeKind::Specular,
            eta: self.eta,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Energy: reflection probability F and transmission 1−F; refraction obeys Snell's law and
    /// the weights (without the 1/η² radiance scaling) sum to one over the two lobes.
    #[test]
    fn fresnel_split_and_snell() {
        let d = SmoothDielectric { eta: 1.5, tint: Spectrum::ONE };
        for &cos in &[1.0f32, 0.8, 0.3, 0.05] {
            let wo = Vec3::new((1.0 - cos * cos).sqrt(), 0.0, cos);
            let f = fresnel_dielectric(cos, 1.5);
            let r = d.sample(wo, 0.0).unwrap();
            let t = d.sample(wo, 0.999_999).unwrap();
            assert!((r.pdf - f).abs() < 1e-6 && (t.pdf - (1.0 - f)).abs() < 1e-6);
            let sin_t = (-t.wi.x).max(0.0);
            assert!(t.wi.z < 0.0 && ((1.0 - cos * cos).sqrt() - 1.5 * sin_t).abs() < 1e-4, "Snell");
            assert!((t.weight.x * 1.5 * 1.5 - 1.0).abs() < 1e-5);
        }
        // normal incidence reflectance ((η−1)/(η+1))² = 0.04
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-4);
        // total internal reflection from inside
        let inside = SmoothDielectric { eta: 1.0 / 1.5, tint: Spectrum::ONE };
        let wo = Vec3::new(0.9, 0.0, (1.0f32 - 0.81).sqrt());
        assert_eq!(inside.sample(wo, 0.999).unwrap().lobe, LobeKind::Specular);
        assert!(inside.sample(wo, 0.999).unwrap().wi.z > 0.0);
    }
}
