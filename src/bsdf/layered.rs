//! The opaque dielectric of Blender's Principled BSDF (and of UsdPreviewSurface): a GGX
//! specular layer with the dielectric Fresnel term of IOR η over a Lambertian base. The
//! base is weighted by 1 − s·E(θo), where E is the directional albedo of the specular layer
//! and s its coverage: the "albedo scaling" layering Cycles uses since 4.0, which keeps a
//! white base exactly energy-conserving (E + (1 − E)·1 = 1 for every θo).
//!
//! E(cos θo, roughness, η) comes from albedo.rs's table.
//!
//! Specular Tint colours the layer as Cycles does: its Fresnel term is the real one remapped
//! from F0 to the tinted F0·tint, F_t = F0·tint + (1 − F0·tint)·(F − F0)/(1 − F0), so the
//! layer's albedo is F0·tint·E_ggx + (1 − F0·tint)·(E − F0·E_ggx)/(1 − F0) with E_ggx the
//! white GGX albedo (linear in F: exact from the two tables), and the base keeps 1 − the
//! largest channel of it (Cycles' `closure_layering_weight`).

use super::albedo::{ggx_albedo, specular_albedo};
use super::microfacet::{fresnel_dielectric, reflect, Ggx};
use super::{BsdfSample, Lambert, LobeKind, Scatter, SPECULAR_ROUGHNESS_THRESHOLD};
use crate::math::{luminance, Spectrum};
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Layered {
    pub base: Lambert,
    /// Relative IOR of the specular layer (1 = no layer: a plain Lambertian).
    pub eta: f32,
    /// Blender roughness of the specular layer (α = roughness²).
    pub roughness: f32,
    /// Coverage s ∈ [0, 1] of the layer (1 for Principled; a Mix of Diffuse and Principled
    /// covers part of the base).
    pub coverage: f32,
    /// Specular Tint (white: the plain dielectric layer).
    pub tint: Spectrum,
    /// The share of the base that scatters beneath the surface (Subsurface Weight;
    /// `medium::subsurface`): a lobe of its own, not evaluable — sampling it returns the
    /// direction into the surface (`Scatter::Subsurface`), from where the path builder walks
    /// with the material's parameters. The Lambertian keeps 1 − weight.
    pub subsurface: f32,
    /// The Subsurface IOR the Skin method enters with; 0: through the layer (the others).
    pub subsurface_ior: f32,
}

impl Layered {
    /// A Lambertian without a layer.
    #[inline]
    pub fn plain(base: Lambert) -> Layered {
        Layered {
            base,
            eta: 1.0,
            roughness: 1.0,
            coverage: 0.0,
            tint: Spectrum::ONE,
            subsurface: 0.0,
            subsurface_ior: 0.0,
        }
    }

    #[inline]
    pub fn has_layer(&self) -> bool {
        self.coverage > 0.0 && self.eta != 1.0
    }

    /// The layer's roughness, or 1 (Lambertian) without one: what the shift mapping compares
    /// with the specular threshold.
    #[inline]
    pub fn min_roughness(&self) -> f32 {
        if self.has_layer() {
            self.roughness
        } else {
            1.0
        }
    }

    #[inline]
    pub fn is_smooth(&self) -> bool {
        self.roughness <= SPECULAR_ROUGHNESS_THRESHOLD
    }

    #[inline]
    fn tinted(&self) -> bool {
        self.tint != Spectrum::ONE
    }

    /// F0 of the layer's IOR.
    #[inline]
    fn f0(&self) -> f32 {
        let r = (self.eta - 1.0) / (self.eta + 1.0);
        r * r
    }

    /// The layer's Fresnel term at cos θ (per channel: Specular Tint remaps it).
    #[inline]
    fn fresnel(&self, cos: f32) -> Spectrum {
        let f = fresnel_dielectric(cos, self.eta);
        if !self.tinted() {
            return Spectrum::splat(f);
        }
        let (f0, f0t) = (self.f0(), self.tint * self.f0());
        f0t + (Spectrum::ONE - f0t) * ((f - f0) / (1.0 - f0)).clamp(0.0, 1.0)
    }

    /// s·E(θo) per channel: the share of light the layer reflects (the base keeps 1 − its
    /// largest channel). Zero when wo lies below the shading hemisphere (a smooth-shaded
    /// coarse mesh): the specular layer reflects nothing there and the base scatters alone,
    /// as Cycles' closures do (its microfacet lobe is black for such wo, its diffuse lobe
    /// ignores wo's side).
    #[inline]
    fn layer_albedo(&self, cos_o: f32) -> Spectrum {
        if !self.has_layer() || cos_o <= 0.0 {
            return Spectrum::ZERO;
        }
        let e = if self.is_smooth() {
            self.fresnel(cos_o)
        } else if !self.tinted() {
            Spectrum::splat(specular_albedo(cos_o, self.roughness, self.eta))
        } else {
            let (e, white) = (specular_albedo(cos_o, self.roughness, self.eta), ggx_albedo(cos_o, self.roughness));
            let (f0, f0t) = (self.f0(), self.tint * self.f0());
            (f0t * white + (Spectrum::ONE - f0t) * ((e - f0 * white) / (1.0 - f0)).max(0.0)).min(Spectrum::ONE)
        };
        e * self.coverage
    }

    /// Probability of sampling the layer for this wo: its reflected energy (its largest
    /// channel, `e`) against the base's.
    #[inline]
    fn layer_probability(&self, e: f32) -> f32 {
        if e <= 0.0 {
            return 0.0;
        }
        let base = (1.0 - e) * luminance(self.base.albedo).max(0.05);
        e / (e + base)
    }

    /// The rough layer's f·cos θi = s·F·D·G2 / (4 cos θo) and its sampling density.
    #[inline]
    fn rough_layer(&self, wo: Vec3, wi: Vec3) -> (Spectrum, f32) {
        let h = (wo + wi).normalize();
        let g = Ggx::from_roughness(self.roughness);
        let f = if self.tinted() {
            self.fresnel(wo.dot(h)) * (self.coverage * g.d(h) * g.g2(wo, wi) / (4.0 * wo.z))
        } else {
            Spectrum::splat(
                self.coverage * fresnel_dielectric(wo.dot(h), self.eta) * g.d(h) * g.g2(wo, wi) / (4.0 * wo.z),
            )
        };
        let pdf = g.pdf_visible(wo, h) / (4.0 * wo.dot(h).abs().max(1e-12));
        (f, pdf)
    }

    /// f·cos θi and the sampling density together, for the layer albedo `e` = s·E(θo): the
    /// table is read and the microfacet terms evaluated once for both.
    #[inline]
    fn eval_pdf_with(&self, wo: Vec3, wi: Vec3, e: Spectrum) -> (Spectrum, f32) {
        if wi.z <= 0.0 {
            return (Spectrum::ZERO, 0.0);
        }
        let e_max = e.max_element();
        let ps = self.layer_probability(e_max);
        let lambert = 1.0 - self.subsurface;
        let mut f = self.base.eval(wo, wi) * ((1.0 - e_max) * lambert);
        let mut p = (1.0 - ps) * lambert * self.base.pdf(wo, wi);
        if e_max > 0.0 && !self.is_smooth() {
            let (fl, pl) = self.rough_layer(wo, wi);
            f += fl;
            p += ps * pl;
        }
        (f, p)
    }

    /// The density with which `sample` returns `wi` through the base (the Diffuse-labelled
    /// share of `pdf`).
    #[inline]
    pub fn base_pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wi.z <= 0.0 {
            return 0.0;
        }
        (1.0 - self.layer_probability(self.layer_albedo(wo.z).max_element()))
            * (1.0 - self.subsurface)
            * self.base.pdf(wo, wi)
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Spectrum {
        self.eval_pdf(wo, wi).0
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(wo, wi).1
    }

    /// (`eval`, `pdf`) from one evaluation.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Spectrum, f32) {
        self.eval_pdf_with(wo, wi, self.layer_albedo(wo.z))
    }

    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let e = self.layer_albedo(wo.z);
        let ps = self.layer_probability(e.max_element());
        if u_lobe < ps && self.is_smooth() {
            // the mirror lobe: e = s·F as a discrete measure, chosen with probability ps
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            return Some(BsdfSample {
                wi,
                weight: e / ps,
                pdf: ps,
                lobe: LobeKind::Specular,
                eta: 1.0,
                scatter: Scatter::Glossy,
            });
        }
        let ss = self.subsurface;
        if u_lobe >= ps && ss > 0.0 {
            // the base: beneath the surface with probability `ss`
            let v = ((u_lobe - ps) / (1.0 - ps)).min(1.0);
            if v < ss {
                let skin = (self.subsurface_ior > 0.0).then_some(self.subsurface_ior);
                let wi = crate::medium::subsurface::entry(skin, wo, self.eta, self.roughness, v / ss, u)?;
                // the closure's weight (1 − e)·ss·albedo over its probability (1 − ps)·ss
                let weight =
                    self.base.albedo.clamp(Spectrum::ZERO, Spectrum::ONE) * ((1.0 - e.max_element()) / (1.0 - ps));
                return Some(BsdfSample {
                    wi,
                    weight,
                    pdf: (1.0 - ps) * ss,
                    lobe: LobeKind::Specular,
                    eta: 1.0,
                    scatter: Scatter::Subsurface,
                });
            }
        }
        let wi = if u_lobe < ps {
            reflect(wo, Ggx::from_roughness(self.roughness).sample_visible(wo, u))
        } else {
            self.base.sample(wo, u)?.wi
        };
        let (f, pdf) = self.eval_pdf_with(wo, wi, e);
        if wi.z <= 0.0 || !(pdf > 0.0) {
            return None;
        }
        let scatter = if u_lobe < ps { Scatter::Glossy } else { Scatter::Diffuse };
        Some(BsdfSample { wi, weight: f / pdf, pdf, lobe: LobeKind::Diffuse, eta: 1.0, scatter })
    }

    /// The smooth layer's mirror lobe: (s·F as a discrete measure, its probability, wi).
    pub fn delta_eval(&self, wo: Vec3) -> Option<(Spectrum, f32, Vec3)> {
        if !self.has_layer() || !self.is_smooth() || wo.z <= 0.0 {
            return None;
        }
        let e = self.layer_albedo(wo.z);
        Some((e, self.layer_probability(e.max_element()), Vec3::new(-wo.x, -wo.y, wo.z)))
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{chi2_test, white_furnace};
    use super::super::Bsdf;
    use super::*;

    fn layered(albedo: f32, eta: f32, roughness: f32) -> Bsdf {
        Bsdf::Layered(Layered {
            base: Lambert::new(Spectrum::splat(albedo)),
            eta,
            roughness,
            coverage: 1.0,
            tint: Spectrum::ONE,
            subsurface: 0.0,
            subsurface_ior: 0.0,
        })
    }

    /// The layering keeps a white base exactly energy-conserving: albedo 1 at every angle,
    /// roughness and IOR (the sampled albedo tests the table against the sampled layer).
    #[test]
    fn white_base_under_the_layer_conserves_energy() {
        for (eta, r) in [(1.5f32, 0.5f32), (1.45, 0.2), (2.0, 0.8), (1.5, 0.0), (1.33, 1.0)] {
            for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.95, 0.0, 0.31)] {
                let (albedo, _) = white_furnace(&layered(1.0, eta, r), wo, 200_000, 4);
                assert!((albedo - 1.0).abs() < 0.01, "η={eta} r={r} wo={wo}: albedo {albedo}");
            }
        }
        // and a black base reflects exactly the layer's albedo
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let (albedo, _) = white_furnace(&layered(0.0, 1.5, 0.4), wo, 200_000, 5);
        assert!((albedo - specular_albedo(0.8, 0.4, 1.5) as f64).abs() < 0.005, "{albedo}");
    }

    #[test]
    fn layered_chi2() {
        for (eta, r) in [(1.5f32, 0.3f32), (1.5, 0.7), (2.5, 0.5), (1.5, 0.0)] {
            for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.9, 0.2, 0.15).normalize()] {
                chi2_test(&layered(0.5, eta, r), wo, 9);
            }
        }
    }

    /// The smooth layer's mirror lobe: chosen with the probability `delta_eval` reports,
    /// weight = F/probability, and the sum of both lobes is still the white furnace's 1.
    #[test]
    fn smooth_layer_mirror_lobe() {
        let b = Layered {
            base: Lambert::new(Spectrum::splat(0.5)),
            eta: 1.5,
            roughness: 0.0,
            coverage: 1.0,
            tint: Spectrum::ONE,
            subsurface: 0.0,
            subsurface_ior: 0.0,
        };
        let wo = Vec3::new(0.5, 0.1, 0.86).normalize();
        let (f, p, wi) = b.delta_eval(wo).unwrap();
        assert!((f.x - fresnel_dielectric(wo.z, 1.5)).abs() < 1e-6 && p > 0.0 && p < 1.0);
        let bs = b.sample(wo, 0.5 * p, Vec2::new(0.3, 0.3)).unwrap();
        assert_eq!(bs.lobe, LobeKind::Specular);
        assert!((bs.wi - wi).length() < 1e-6 && (bs.weight.x - f.x / p).abs() < 1e-5 && bs.pdf == p);
        assert!(b.sample(wo, p + 0.5 * (1.0 - p), Vec2::new(0.3, 0.3)).unwrap().lobe == LobeKind::Diffuse);
    }

    /// With wo below the shading hemisphere the layer reflects nothing and the base scatters
    /// as a plain Lambertian (Cycles' closures); black before.
    #[test]
    fn below_the_shading_hemisphere_only_the_base_scatters() {
        let b = layered(0.5, 1.5, 0.3);
        let plain = Bsdf::Lambert(Lambert::new(Spectrum::splat(0.5)));
        let wo = Vec3::new(0.7, 0.1, -0.2).normalize();
        for wi in [Vec3::Z, Vec3::new(-0.6, 0.0, 0.8), Vec3::new(0.3, 0.5, 0.81).normalize()] {
            assert!((b.eval(wo, wi) - plain.eval(wo, wi)).abs().max_element() < 1e-7);
            assert!((b.pdf(wo, wi) - plain.pdf(wo, wi)).abs() < 1e-7 && b.pdf(wo, wi) > 0.0);
        }
        let (albedo, _) = white_furnace(&layered(1.0, 1.5, 0.3), wo, 100_000, 6);
        assert!((albedo - 1.0).abs() < 0.01, "{albedo}");
        chi2_test(&b, wo, 10);
    }

    /// Specular Tint: over a black base the tinted layer reflects, per channel, the albedo
    /// the two tables give (F0·tint·E_ggx + (1 − F0·tint)(E − F0·E_ggx)/(1 − F0)), measured by
    /// sampling its lobe — rough and smooth, at three angles; white tint is the plain layer;
    /// sampling matches pdf (χ²).
    #[test]
    fn specular_tint_colours_the_layer_as_its_albedo_says() {
        use crate::sampler::{IndependentSampler, Sampler};
        let tint = Spectrum::new(1.0, 0.5, 0.1);
        for r in [0.0f32, 0.3, 0.7] {
            let b = Layered {
                base: Lambert::new(Spectrum::ZERO),
                eta: 1.5,
                roughness: r,
                coverage: 1.0,
                tint,
                subsurface: 0.0,
                subsurface_ior: 0.0,
            };
            for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.95, 0.0, 0.31).normalize()] {
                let mut s = IndependentSampler::new(17, 0);
                let n = 400_000;
                let mut sum = Spectrum::ZERO;
                for _ in 0..n {
                    if let Some(bs) = b.sample(wo, s.next_1d(), s.next_2d()) {
                        sum += bs.weight;
                    }
                }
                let (got, want) = (sum / n as f32, b.layer_albedo(wo.z));
                assert!(
                    (got - want).abs().max_element() < 0.004 + 0.02 * want.max_element(),
                    "r={r} wo={wo}: {got} vs {want}"
                );
                assert!(want.z < want.y && want.y < want.x, "{want}");
                let plain = Layered { tint: Spectrum::ONE, ..b };
                assert!(
                    (plain.layer_albedo(wo.z) - Spectrum::splat(plain.layer_albedo(wo.z).x)).abs().max_element() == 0.0
                );
                assert!(want.x <= plain.layer_albedo(wo.z).x + 1e-6);
            }
            chi2_test(
                &Bsdf::Layered(Layered { base: Lambert::new(Spectrum::splat(0.5)), ..b }),
                Vec3::new(0.6, 0.0, 0.8),
                19,
            );
        }
    }
}
