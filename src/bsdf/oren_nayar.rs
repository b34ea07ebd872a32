//! Rough diffuse reflection as Cycles renders a Diffuse BSDF of Roughness σ > 0 and the
//! Principled BSDF's Diffuse Roughness: Fujii's "improved" Oren–Nayar model (a qualitative
//! form of Oren & Nayar 1994 whose single-scattering albedo has a closed form) plus the
//! energy-preserving multiple-scattering term of OpenPBR's EON diffuse (Portsmouth, Kutz &
//! Hill 2025).
//!
//! With cosines μi = n·wi, μo = n·wo and s = wi·wo − μi·μo, the single-scattering lobe is
//!
//!   f_ss = A + B·s/t,   t = max(μi, μo) if s > 0 else 1,
//!   A = 1 / (π + σ(π/2 − 2/3)),   B = σ·A,
//!
//! whose directional albedo is E(μ) = A·π + B·G(μ) with
//!
//!   G(μ) = sin θ (θ − 2/3 − sin θ cos θ) + 2/3 · tan θ · (1 − sin³θ),
//!
//! and E's hemispherical average E_avg ≈ A·π + (2π − 5.6)/3 · B. The multiple-scattering lobe
//! gives back what single scattering misses, shaped by what each direction lost:
//!
//!   f_ms = ρ·E_avg / (π (1 − E_avg)(1 − ρ(1 − E_avg))) · (1 − E(μo))(1 − E(μi)),
//!
//! so a white surface (ρ = 1) reflects all light. As in Cycles the whole lobe, f_ms included,
//! is weighted by the colour ρ: f = ρ·(f_ss + f_ms), which is OpenPBR's ρ·f_ss + f_ms with its
//! ρ² in f_ms. Cycles 4.5–5.2 wrote ρ² into f_ms (ρ³ with the weight; `ColourPower::Cubed`,
//! a rough orange surface some percent darker); Cycles 5.3 writes ρ (`ColourPower::Squared`).
//! Both are 1 at ρ = 1. Sampled as a Lambertian (cosine-weighted), as Cycles does.

use crate::math::Spectrum;
use std::f32::consts::{FRAC_1_PI, FRAC_PI_2, PI};

/// The colour's power in the multiple-scattering lobe, the lobe's weight ρ included: ρ² as
/// OpenPBR's EON and Cycles 5.3 (the default), or ρ³ as Cycles 4.5–5.2 (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ColourPower {
    #[default]
    Squared,
    Cubed,
}

/// The precomputed lobe for one roughness and colour: f·cos θi for a pair of cosines.
#[derive(Clone, Copy, Debug)]
pub struct OrenNayar {
    a: f32,
    b: f32,
    /// ρ·E_avg / (π (1 − E_avg)(1 − ρ(1 − E_avg))) per channel (ρ² in the numerator for
    /// `ColourPower::Cubed`).
    ms: Spectrum,
}

/// G(μ) of the single-scattering albedo E(μ) = A·π + B·G(μ).
#[inline]
pub fn g(cos: f32) -> f32 {
    if cos < 1e-6 {
        // tan θ blows up at grazing angles: the expansion of G about μ = 0
        return (FRAC_PI_2 - 2.0 / 3.0) - cos;
    }
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let theta = cos.clamp(-1.0, 1.0).acos();
    sin * (theta - 2.0 / 3.0 - sin * cos) + 2.0 / 3.0 * (sin / cos) * (1.0 - sin * sin * sin)
}

impl OrenNayar {
    /// σ = the roughness in [0, 1], ρ = the colour (clamped to [0, 1]).
    pub fn new(sigma: f32, rho: Spectrum, power: ColourPower) -> OrenNayar {
        let sigma = sigma.clamp(0.0, 1.0);
        let a = 1.0 / (PI + sigma * (FRAC_PI_2 - 2.0 / 3.0));
        let b = sigma * a;
        let e_avg = a * PI + (2.0 * PI - 5.6) / 3.0 * b;
        let rho = rho.clamp(Spectrum::ZERO, Spectrum::ONE);
        let numerator = if power == ColourPower::Cubed { rho * rho } else { rho };
        let ms = numerator * (FRAC_1_PI * e_avg / (1.0 - e_avg)) / (Spectrum::ONE - rho * (1.0 - e_avg));
        OrenNayar { a, b, ms }
    }

    /// Directional albedo E(μ) of the single-scattering lobe (colour 1).
    #[inline]
    pub fn albedo(&self, cos: f32) -> f32 {
        self.a * PI + self.b * g(cos.max(0.0))
    }

    /// (f_ss + f_ms)·cos θi for cosines μo, μi and wi·wo (the caller multiplies by ρ).
    #[inline]
    pub fn eval(&self, cos_o: f32, cos_i: f32, cos_io: f32) -> Spectrum {
        let (mu_o, mu_i) = (cos_o.max(0.0), cos_i.max(0.0));
        let mut s = cos_io - mu_i * mu_o;
        if s > 0.0 {
            s /= mu_i.max(mu_o) + f32::MIN_POSITIVE;
        }
        let single = self.a + self.b * s;
        let multiple = self.ms * ((1.0 - self.albedo(mu_o)) * (1.0 - self.albedo(mu_i)));
        (Spectrum::splat(single) + multiple) * mu_i
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Numerical ∫ f_ss cos dω over the hemisphere for view cosine μ (colour 1).
    fn single_scattering_albedo(on: &OrenNayar, mu: f64) -> f64 {
        let wo = [(1.0 - mu * mu).sqrt(), 0.0, mu];
        let (nt, np) = (400, 400);
        let mut sum = 0.0;
        for i in 0..nt {
            let t = (i as f64 + 0.5) / nt as f64 * std::f64::consts::FRAC_PI_2;
            for j in 0..np {
                let p = (j as f64 + 0.5) / np as f64 * 2.0 * std::f64::consts::PI;
                let wi = [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()];
                let cos_io = wi[0] * wo[0] + wi[1] * wo[1] + wi[2] * wo[2];
                let (mi, mo) = (wi[2], mu);
                let mut s = cos_io - mi * mo;
                if s > 0.0 {
                    s /= mi.max(mo);
                }
                sum += (on.a as f64 + on.b as f64 * s) * mi * t.sin();
            }
        }
        sum * (std::f64::consts::FRAC_PI_2 / nt as f64) * (2.0 * std::f64::consts::PI / np as f64)
    }

    /// E(μ) = A·π + B·G(μ) is the single-scattering lobe's albedo (G checked against the
    /// integral of its definition, the grazing expansion included), and E_avg's closed form
    /// is its hemispherical average 2∫E(μ)μ dμ within 1e-3.
    #[test]
    fn albedo_is_the_integral_of_the_single_scattering_lobe() {
        for sigma in [0.3f32, 1.0] {
            let on = OrenNayar::new(sigma, Spectrum::ONE, ColourPower::Squared);
            for mu in [1e-7f64, 0.05, 0.3, 0.6, 0.9, 1.0] {
                let numeric = single_scattering_albedo(&on, mu);
                let closed = on.albedo(mu as f32) as f64;
                assert!((numeric - closed).abs() < 2e-3, "σ={sigma} μ={mu}: {numeric} vs {closed}");
            }
            let n = 2000;
            let avg: f64 = (0..n)
                .map(|k| {
                    let mu = (k as f64 + 0.5) / n as f64;
                    2.0 * on.albedo(mu as f32) as f64 * mu / n as f64
                })
                .sum();
            let closed = (on.a * PI + (2.0 * PI - 5.6) / 3.0 * on.b) as f64;
            assert!((avg - closed).abs() < 1e-3, "σ={sigma}: E_avg {avg} vs {closed}");
        }
    }

    /// Reciprocal: f(wo, wi)/μi = f(wi, wo)/μo.
    #[test]
    fn the_lobe_is_reciprocal() {
        let on = OrenNayar::new(0.8, Spectrum::new(0.9, 0.5, 0.1), ColourPower::Cubed);
        for (mo, mi, c) in [(0.9f32, 0.3f32, 0.5f32), (0.2, 0.7, -0.4), (0.5, 0.5, 0.9)] {
            let a = on.eval(mo, mi, c) / mi;
            let b = on.eval(mi, mo, c) / mo;
            assert!((a - b).abs().max_element() < 1e-6, "{a} {b}");
        }
    }

    /// The whole lobe's albedo ρ·∫(f_ss + f_ms) cos dω, integrated numerically per channel,
    /// is OpenPBR's EON albedo ρ·E(μ) + ρ_ms·(1 − E(μ)), ρ_ms = ρ²·E_avg / (1 − ρ(1 − E_avg)),
    /// with `Squared` (Cycles 5.3), and ρ times its multiple-scattering part with `Cubed`
    /// (Cycles 4.5–5.2): a mid-grey channel (ρ = 0.5) 0.7–5% apart.
    #[test]
    fn the_lobes_albedo_is_eons_with_either_colour_power() {
        let rho = Spectrum::new(0.9, 0.5, 0.1);
        for sigma in [0.5f32, 1.0] {
            for mu in [0.2f32, 0.7] {
                let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let albedo = |power| {
                    let on = OrenNayar::new(sigma, rho, power);
                    let (nt, np) = (300, 300);
                    let mut sum = glam::DVec3::ZERO;
                    for i in 0..nt {
                        let t = (i as f32 + 0.5) / nt as f32 * FRAC_PI_2;
                        for j in 0..np {
                            let p = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
                            let wi = Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos());
                            sum += (rho * on.eval(wo.z, wi.z, wo.dot(wi))).as_dvec3() * t.sin() as f64;
                        }
                    }
                    sum * (FRAC_PI_2 as f64 / nt as f64) * (2.0 * PI as f64 / np as f64)
                };
                let on = OrenNayar::new(sigma, rho, ColourPower::Squared);
                let (e, e_avg) = (on.albedo(mu), on.a * PI + (2.0 * PI - 5.6) / 3.0 * on.b);
                let rho_ms = rho * rho * e_avg / (Spectrum::ONE - rho * (1.0 - e_avg));
                let (single, multiple) = ((rho * e).as_dvec3(), (rho_ms * (1.0 - e)).as_dvec3());
                let squared = albedo(ColourPower::Squared);
                let cubed = albedo(ColourPower::Cubed);
                let close = |a: glam::DVec3, b: glam::DVec3| (a - b).abs().max_element() < 2e-3;
                assert!(close(squared, single + multiple), "σ={sigma} μ={mu}: {squared} vs EON {}", single + multiple);
                assert!(close(cubed, single + multiple * rho.as_dvec3()), "σ={sigma} μ={mu}: {cubed}");
                assert!(squared.y > cubed.y * 1.005, "{squared} {cubed}");
            }
        }
    }
}
