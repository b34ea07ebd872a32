//! The Principled BSDF's coat, as Cycles layers it: a clear dielectric GGX reflection of its
//! own IOR and roughness over everything else, which the coat dims by what it reflects and
//! tints by its colour (Blender's Coat Weight c, Roughness, IOR and Tint).
//!
//! Cycles' layering depends on the outgoing direction only ("albedo scaling", as the
//! specular layer over the diffuse base, `layered.rs`): the lobes beneath are multiplied by
//!
//!   K(ωo) = (1 − c·E(μo)) · ((1 − c) + c·tint^(1/cos θt)),
//!
//! where E is the coat's directional albedo (the albedo table of the specular layer) and
//! θt the angle of ωo refracted into the coat: light crossing a coat of unit thickness
//! along the view ray, Beer's law normalised to normal incidence. The coat lobe itself is
//! c·F(ωo·h)·D·G2/(4 cos θo) (single scattering, as Cycles' coat), or c·F(μo) towards the
//! mirror direction when its roughness is at most the specular threshold.

use super::albedo::specular_albedo;
use super::microfacet::{fresnel_dielectric, reflect, Ggx};
use super::SPECULAR_ROUGHNESS_THRESHOLD;
use crate::math::Spectrum;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Coat {
    /// Coat Weight c ∈ [0, 1] (0: no coat).
    pub weight: f32,
    /// Relative IOR of the coat (≥ 1; the albedo table covers up to 3).
    pub eta: f32,
    /// Blender roughness (α = roughness²).
    pub roughness: f32,
    /// Coat Tint: the colour light takes crossing the coat once at normal incidence.
    pub tint: Spectrum,
}

impl Coat {
    /// No coat.
    pub const NONE: Coat = Coat { weight: 0.0, eta: 1.5, roughness: 0.03, tint: Spectrum::ONE };

    #[inline]
    pub fn is_some(&self) -> bool {
        self.weight > 0.0
    }

    #[inline]
    pub fn is_smooth(&self) -> bool {
        self.roughness <= SPECULAR_ROUGHNESS_THRESHOLD
    }

    /// c·E(μo): the share of light the coat reflects towards ωo (0 below the hemisphere).
    #[inline]
    pub fn albedo(&self, cos_o: f32) -> f32 {
        if !self.is_some() || cos_o <= 0.0 || self.eta <= 1.0 {
            return 0.0;
        }
        let e = if self.is_smooth() {
            fresnel_dielectric(cos_o, self.eta)
        } else {
            specular_albedo(cos_o, self.roughness, self.eta)
        };
        self.weight * e
    }

    /// K(ωo): what the lobes beneath keep.
    #[inline]
    pub fn factor(&self, cos_o: f32) -> Spectrum {
        if !self.is_some() {
            return Spectrum::ONE;
        }
        let k = (1.0 - self.albedo(cos_o)).max(0.0);
        if self.tint == Spectrum::ONE {
            return Spectrum::splat(k);
        }
        let cos_t = (1.0 - (1.0 - cos_o * cos_o) / (self.eta * self.eta)).max(1e-6).sqrt();
        let through = self.tint.max(Spectrum::ZERO).powf(1.0 / cos_t);
        (Spectrum::splat(1.0 - self.weight) + through * self.weight) * k
    }

    /// The rough coat's f·cos θi and its sampling density (zero for a smooth coat).
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (f32, f32) {
        if !self.is_some() || self.is_smooth() || wo.z <= 0.0 || wi.z <= 0.0 || self.eta <= 1.0 {
            return (0.0, 0.0);
        }
        let h = (wo + wi).normalize();
        let g = Ggx::from_roughness(self.roughness);
        let f = self.weight * fresnel_dielectric(wo.dot(h), self.eta) * g.d(h) * g.g2(wo, wi) / (4.0 * wo.z);
        let pdf = g.pdf_visible(wo, h) / (4.0 * wo.dot(h).abs().max(1e-12));
        (f, pdf)
    }

    /// A direction sampled from the coat lobe (the visible normals of the rough coat; the
    /// mirror direction of a smooth one). None below the hemisphere.
    #[inline]
    pub fn sample_wi(&self, wo: Vec3, u: Vec2) -> Option<Vec3> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = if self.is_smooth() {
            Vec3::new(-wo.x, -wo.y, wo.z)
        } else {
            reflect(wo, Ggx::from_roughness(self.roughness).sample_visible(wo, u))
        };
        (wi.z > 0.0).then_some(wi)
    }

    /// The smooth coat's mirror reflection as a discrete measure, c·F(μo), and its direction.
    #[inline]
    pub fn delta_eval(&self, wo: Vec3) -> Option<(f32, Vec3)> {
        if !self.is_some() || !self.is_smooth() || wo.z <= 0.0 || self.eta <= 1.0 {
            return None;
        }
        Some((self.weight * fresnel_dielectric(wo.z, self.eta), Vec3::new(-wo.x, -wo.y, wo.z)))
    }
}
