//! Conductors: a perfect mirror (roughness at or below the specular threshold) or a GGX
//! microfacet conductor (Walter et al. 2007) with visible-normal sampling. Fresnel: Schlick's
//! approximation with F0 = the base colour (Blender's metallic colour), bent at grazing
//! angles by the F82 tint as Cycles' Principled metal (Hoffman 2023's F82-tint model:
//! F = Schlick(F0) − b·μ(1 − μ)⁶, b chosen so that F(1/7) = F82·Schlick(F0, 1/7); F82 = the
//! Specular Tint, white: plain Schlick). Blender's Glossy BSDF has no Fresnel term at all:
//! its colour is the reflectance at every angle (`constant`; Cycles bakes the colour into the
//! closure's weight and compensates multiple scattering with F_avg = the colour).
//!
//! Blender's "Multiscatter GGX" (its default) adds the energy single scattering loses: the
//! lobe is scaled by 1 + F_ms·(1 − E(θo))/E(θo), where E is the white lobe's albedo and
//! F_ms = F_avg·E_avg / (1 − F_avg·(1 − E_avg)) the Fresnel colour of the multiply scattered
//! light (Kulla & Conty 2017, appendix; applied as a scale of the single-scattering lobe as
//! Turquin 2019 and Cycles do). A white multiscatter conductor reflects exactly all light.

use super::albedo::{ggx_albedo, ggx_albedo_average};
use super::microfacet::{reflect, Ggx};
use super::{BsdfSample, LobeKind, Scatter, SPECULAR_ROUGHNESS_THRESHOLD};
use crate::math::Spectrum;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Conductor {
    pub f0: Spectrum,
    /// Blender roughness (α = roughness²).
    pub roughness: f32,
    /// Energy compensation for multiple scattering (Blender's Multiscatter GGX).
    pub multiscatter: bool,
    /// The F82 tint (white: Schlick's Fresnel).
    pub f82: Spectrum,
    /// The reflectance is f0 at every angle (the Glossy BSDF), not Schlick's.
    pub constant: bool,
}

#[inline]
fn schlick(f0: Spectrum, cos: f32) -> Spectrum {
    let m = (1.0 - cos.clamp(0.0, 1.0)).powi(5);
    f0 + (Spectrum::ONE - f0) * m
}

impl Conductor {
    /// A conductor with Schlick's Fresnel from `f0` (no F82 tint; the Principled metal's
    /// default), single-scattering or with Blender's Multiscatter GGX compensation.
    pub fn new(f0: Spectrum, roughness: f32, multiscatter: bool) -> Conductor {
        Conductor { f0, roughness, multiscatter, f82: Spectrum::ONE, constant: false }
    }

    /// b of the F82-tint model: Schlick(F0, 1/7)·(1 − F82) / ((1/7)(6/7)⁶).
    #[inline]
    fn f82_b(&self) -> Spectrum {
        let f = 6.0f32 / 7.0;
        schlick(self.f0, 1.0 / 7.0) * (7.0 / f.powi(6)) * (Spectrum::ONE - self.f82)
    }

    /// The Fresnel term at cos θ.
    #[inline]
    fn fresnel(&self, cos: f32) -> Spectrum {
        if self.constant {
            return self.f0;
        }
        if self.f82 == Spectrum::ONE {
            return schlick(self.f0, cos);
        }
        let c = cos.clamp(0.0, 1.0);
        (schlick(self.f0, c) - self.f82_b() * (c * (1.0 - c).powi(6))).clamp(Spectrum::ZERO, Spectrum::ONE)
    }

    #[inline]
    pub fn is_delta(&self) -> bool {
        self.roughness <= SPECULAR_ROUGHNESS_THRESHOLD
    }

    /// The multiple-scattering scale of the lobe seen from cos θo (1 without compensation).
    #[inline]
    fn energy_scale(&self, cos_o: f32) -> Spectrum {
        if !self.multiscatter || self.is_delta() {
            return Spectrum::ONE;
        }
        let e = ggx_albedo(cos_o, self.roughness).max(1e-3);
        let e_avg = ggx_albedo_average(self.roughness);
        // hemispherical average of the Fresnel term: F0 + (1 − F0)/21 − b/126 (2∫μ²(1−μ)⁶ dμ = 1/126)
        let mut f_avg = if self.constant { self.f0 } else { self.f0 + (Spectrum::ONE - self.f0) / 21.0 };
        if self.f82 != Spectrum::ONE && !self.constant {
            f_avg -= self.f82_b() / 126.0;
        }
        let f_ms = f_avg * e_avg / (Spectrum::ONE - f_avg * (1.0 - e_avg));
        Spectrum::ONE + f_ms * ((1.0 - e) / e)
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Spectrum {
        if self.is_delta() || wo.z <= 0.0 || wi.z <= 0.0 {
            return Spectrum::ZERO;
        }
        let h = (wo + wi).normalize();
        let g = Ggx::from_roughness(self.roughness);
        // f·cos θi = F·D·G2 / (4 cos θo)
        self.fresnel(wo.dot(h)) * (g.d(h) * g.g2(wo, wi) / (4.0 * wo.z)) * self.energy_scale(wo.z)
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.is_delta() || wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wo + wi).normalize();
        Ggx::from_roughness(self.roughness).pdf_visible(wo, h) / (4.0 * wo.dot(h).abs().max(1e-12))
    }

    /// The mirror lobe (roughness at or below the threshold): (F as a discrete measure,
    /// probability 1, mirror direction).
    pub fn delta_eval(&self, wo: Vec3) -> Option<(Spectrum, f32, Vec3)> {
        if !self.is_delta() || wo.z <= 0.0 {
            return None;
        }
        Some((self.fresnel(wo.z), 1.0, Vec3::new(-wo.x, -wo.y, wo.z)))
    }

    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        if self.is_delta() {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            return Some(BsdfSample {
                wi,
                weight: self.fresnel(wo.z),
                pdf: 1.0,
                lobe: LobeKind::Specular,
                eta: 1.0,
                scatter: Scatter::Glossy,
            });
        }
        let g = Ggx::from_roughness(self.roughness);
        let h = g.sample_visible(wo, u);
        let wi = reflect(wo, h);
        if wi.z <= 0.0 {
            return None;
        }
        let pdf = g.pdf_visible(wo, h) / (4.0 * wo.dot(h).abs().max(1e-12));
        if !(pdf > 0.0) {
            return None;
        }
        // weight = F·G2/G1(wo) (the VNDF estimator)
        let weight = self.fresnel(wo.dot(h)) * (g.g2(wo, wi) / g.g1(wo)) * self.energy_scale(wo.z);
        Some(BsdfSample { wi, weight, pdf, lobe: LobeKind::Diffuse, eta: 1.0, scatter: Scatter::Glossy })
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{chi2_test, white_furnace};
    use super::super::Bsdf;
    use super::*;

    // Roughness ≥ 0.3: the harness's bins (and its 48×16 quadrature per bin) resolve the lobe;
    // sharper lobes are checked by the furnace test's sampled albedo.
    #[test]
    fn rough_conductor_chi2() {
        for r in [0.3f32, 0.5, 0.7, 1.0] {
            let b = Bsdf::Conductor(Conductor::new(Spectrum::ONE, r, false));
            for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.9, 0.2, 0.15).normalize()] {
                chi2_test(&b, wo, 7);
            }
        }
    }

    /// White furnace (F = 1): the sampled and the integrated albedo agree, and single-scattering
    /// GGX loses energy only at grazing angles and high roughness (never gains).
    #[test]
    fn rough_conductor_white_furnace() {
        for r in [0.1f32, 0.3, 0.5, 1.0] {
            let b = Bsdf::Conductor(Conductor::new(Spectrum::ONE, r, false));
            for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8)] {
                let (s, q) = white_furnace(&b, wo, 400_000, 3);
                assert!(s <= 1.0 + 1e-3 && (r > 0.5 || s > 0.75), "r={r} sampled albedo {s}");
                if r == 1.0 && wo == Vec3::Z {
                    // α = 1 at normal incidence: 0.30685 by a 400×400 quadrature of D·G2/(4 cos θo)
                    assert!((s - 0.30685).abs() < 0.005, "r=1 albedo {s}");
                }
                if r >= 0.5 {
                    // uniform-sphere quadrature has the variance to check only wide lobes
                    assert!((s - q).abs() < 0.03 * s.max(0.1), "r={r}: sampled {s} vs integrated {q}");
                }
            }
        }
    }

    #[test]
    fn mirror_reflects_with_fresnel_one_at_f0_one() {
        let b = Conductor::new(Spectrum::ONE, 0.0, true);
        let wo = Vec3::new(0.3, -0.2, 0.93).normalize();
        let s = b.sample(wo, Vec2::new(0.5, 0.5)).unwrap();
        assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-6);
        assert!((s.weight - Spectrum::ONE).abs().max_element() < 1e-6);
        assert_eq!(s.lobe, LobeKind::Specular);
    }

    /// Multiscatter GGX: a white conductor reflects all light at every angle and roughness
    /// (the single-scattering lobe alone loses up to 70% at α = 1); a coloured one reflects
    /// more than single scattering and less than white; sampling still matches the pdf.
    #[test]
    fn multiscatter_conductor_conserves_energy() {
        for r in [0.2f32, 0.5, 0.8, 1.0] {
            for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.9, 0.0, 0.2).normalize()] {
                let white = Bsdf::Conductor(Conductor::new(Spectrum::ONE, r, true));
                let (a, _) = white_furnace(&white, wo, 200_000, 11);
                assert!((a - 1.0).abs() < 0.015, "r={r} wo={wo}: albedo {a}");
                let gold = Spectrum::new(0.9, 0.7, 0.3);
                let ms = Bsdf::Conductor(Conductor::new(gold, r, true));
                let ss = Bsdf::Conductor(Conductor::new(gold, r, false));
                let (a_ms, a_ss) = (white_furnace(&ms, wo, 100_000, 12).0, white_furnace(&ss, wo, 100_000, 12).0);
                assert!(a_ss < a_ms && a_ms < 1.0, "r={r}: single {a_ss}, multi {a_ms}");
            }
            let b = Bsdf::Conductor(Conductor::new(Spectrum::new(0.9, 0.7, 0.3), r, true));
            chi2_test(&b, Vec3::new(0.6, 0.0, 0.8), 13);
        }
    }

    /// The F82-tint Fresnel (Principled metal's Specular Tint): F(1) = F0, F(0) = 1,
    /// F(1/7) = F82·Schlick(F0, 1/7); its hemispherical average 2∫F(μ)μ dμ is the closed form
    /// the multiscatter scale uses; white F82 is Schlick's; sampling matches pdf (χ²).
    #[test]
    fn f82_tint_bends_the_edge_as_its_definition() {
        let (f0, f82) = (Spectrum::new(0.95, 0.65, 0.3), Spectrum::new(0.9, 0.5, 0.8));
        let c = Conductor { f0, roughness: 0.3, multiscatter: true, f82, constant: false };
        assert!((c.fresnel(1.0) - f0).abs().max_element() < 1e-6);
        assert!((c.fresnel(0.0) - Spectrum::ONE).abs().max_element() < 1e-6);
        let want = f82 * schlick(f0, 1.0 / 7.0);
        assert!((c.fresnel(1.0 / 7.0) - want).abs().max_element() < 1e-5, "{} vs {want}", c.fresnel(1.0 / 7.0));
        let n = 100_000;
        let avg = (0..n).fold(Spectrum::ZERO, |a, k| {
            let mu = (k as f32 + 0.5) / n as f32;
            a + c.fresnel(mu) * (2.0 * mu / n as f32)
        });
        let closed = f0 + (Spectrum::ONE - f0) / 21.0 - c.f82_b() / 126.0;
        assert!((avg - closed).abs().max_element() < 1e-4, "{avg} vs {closed}");
        let white = Conductor { f82: Spectrum::ONE, ..c };
        for mu in [0.05f32, 0.3, 0.8] {
            assert_eq!(white.fresnel(mu), schlick(f0, mu));
        }
        chi2_test(&Bsdf::Conductor(c), Vec3::new(0.6, 0.0, 0.8), 23);
    }

    /// The Glossy BSDF's constant Fresnel: the lobe is exactly its colour times the white
    /// lobe, at normal and grazing incidence, with or without multiscatter (whose F_avg is the
    /// colour then); Schlick's curve would brighten it towards white at grazing angles.
    #[test]
    fn a_constant_fresnel_lobe_is_its_colour_times_the_white_lobe() {
        let colour = Spectrum::new(0.5, 0.3, 0.1);
        for multiscatter in [false, true] {
            let glossy = Conductor { f0: colour, roughness: 0.25, multiscatter, f82: Spectrum::ONE, constant: true };
            let white = Conductor { f0: Spectrum::ONE, ..glossy };
            for (wo, wi) in [
                (Vec3::Z, Vec3::new(0.1, 0.0, 0.995).normalize()),
                (Vec3::new(0.97, 0.0, 0.243).normalize(), Vec3::new(-0.95, 0.1, 0.3).normalize()),
            ] {
                let (g, w) = (glossy.eval(wo, wi), white.eval(wo, wi));
                let ratio = if multiscatter {
                    // the scale 1 + F_ms(1 − E)/E with F_avg = the colour, against white's
                    let e = ggx_albedo(wo.z, 0.25).max(1e-3);
                    let e_avg = ggx_albedo_average(0.25);
                    let f_ms = colour * e_avg / (Spectrum::ONE - colour * (1.0 - e_avg));
                    colour * (Spectrum::ONE + f_ms * ((1.0 - e) / e)) / (1.0 + (1.0 - e) / e)
                } else {
                    colour
                };
                assert!((g - w * ratio).abs().max_element() < 1e-5 * w.max_element().max(1.0), "{g} vs {}", w * ratio);
            }
        }
        let schlick_one = Conductor::new(colour, 0.25, false);
        let grazing = (Vec3::new(0.97, 0.0, 0.243).normalize(), Vec3::new(-0.95, 0.1, 0.3).normalize());
        let constant = Conductor { constant: true, ..schlick_one };
        assert!(schlick_one.eval(grazing.0, grazing.1).z > 1.5 * constant.eval(grazing.0, grazing.1).z);
    }
}
