//! The Henyey–Greenstein phase function (Henyey and Greenstein 1941), Cycles' default for
//! Principled Volume and Volume Scatter:
//!
//! p(θ) = (1 − g²) / (4π (1 + g² − 2g cos θ)^{3/2}),
//!
//! θ the angle between the direction of travel and the scattered direction, g ∈ (−1, 1) the
//! mean cosine (g > 0 forward scattering). Directions follow the BSDFs' convention: `wo`
//! points back to where the path came from, so the direction of travel is −wo.

use crate::math::Frame;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// |g| above this is clamped (Cycles clamps to ±(1 − 1e-3)): a delta lobe is not a medium.
const MAX_ANISOTROPY: f32 = 1.0 - 1e-3;
/// |g| below this is isotropic (the closed-form inverse divides by g).
const ISOTROPIC: f32 = 1e-3;

/// A Henyey–Greenstein lobe of mean cosine `g`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HenyeyGreenstein {
    pub g: f32,
}

impl HenyeyGreenstein {
    pub fn new(g: f32) -> HenyeyGreenstein {
        let g = if g.is_finite() { g } else { 0.0 };
        HenyeyGreenstein { g: g.clamp(-MAX_ANISOTROPY, MAX_ANISOTROPY) }
    }

    /// The density (per steradian) of scattering by angle θ with cos θ = `cos_theta`.
    #[inline]
    pub fn density(&self, cos_theta: f32) -> f32 {
        let g = self.g;
        let denom = 1.0 + g * g - 2.0 * g * cos_theta;
        (1.0 - g * g) / (4.0 * PI * denom * denom.max(1e-12).sqrt())
    }

    /// The phase function from `wo` (towards the previous vertex) to `wi`; it is also the
    /// density of [`HenyeyGreenstein::sample`] (sampled exactly).
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.density((-wo).dot(wi))
    }

    /// A direction scattered from `wo` (towards the previous vertex), by inverting the CDF of
    /// cos θ: cos θ = (1 + g² − ((1 − g²)/(1 − g + 2g u₀))²) / 2g. Returns (wi, density); the
    /// sample's weight p/pdf is 1.
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> (Vec3, f32) {
        let g = self.g;
        let cos_theta = if g.abs() < ISOTROPIC {
            1.0 - 2.0 * u.x
        } else {
            let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
            ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
        };
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        let frame = Frame::from_normal(-wo);
        let wi = frame.to_world(Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta));
        (wi, self.density(cos_theta))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫ p dω = 1 for every g (midpoint rule in cos θ; the density is rotationally symmetric).
    #[test]
    fn henyey_greenstein_integrates_to_one() {
        for g in [-0.9, -0.5, 0.0, 0.3, 0.7, 0.95] {
            let hg = HenyeyGreenstein::new(g);
            let n = 200_000;
            let sum: f64 = (0..n).map(|i| hg.density(-1.0 + 2.0 * (i as f32 + 0.5) / n as f32) as f64).sum::<f64>()
                * 2.0
                / n as f64;
            let total = sum * 2.0 * std::f64::consts::PI;
            assert!((total - 1.0).abs() < 2e-3, "g = {g}: ∫p = {total}");
        }
    }

    /// The mean cosine of the density is g.
    #[test]
    fn henyey_greenstein_mean_cosine_is_g() {
        for g in [-0.6, 0.0, 0.4, 0.8] {
            let hg = HenyeyGreenstein::new(g);
            let n = 400_000;
            let mean: f64 = (0..n)
                .map(|i| {
                    let c = -1.0 + 2.0 * (i as f32 + 0.5) / n as f32;
                    (c * hg.density(c)) as f64
                })
                .sum::<f64>()
                * 2.0
                / n as f64
                * 2.0
                * std::f64::consts::PI;
            assert!((mean - g as f64).abs() < 3e-3, "g = {g}: mean cosine {mean}");
        }
    }

    /// Samples follow the density they report: χ² of cos θ about the direction of travel
    /// (40 bins, expected counts from ∫p over each) and of the azimuth about it (16 bins,
    /// uniform), from an oblique wo; the reported density is `eval`'s.
    #[test]
    fn henyey_greenstein_sampling_chi_square() {
        use crate::sampler::{IndependentSampler, Sampler};
        use crate::test_stats::{chi_square, critical_1e3};
        let wo = Vec3::new(0.3, -0.5, 0.8).normalize();
        let frame = Frame::from_normal(-wo);
        let (n, bins, azimuths) = (200_000usize, 40usize, 16usize);
        for (k, g) in [-0.7f32, 0.0, 0.5, 0.9].into_iter().enumerate() {
            let hg = HenyeyGreenstein::new(g);
            let mut s = IndependentSampler::new(17 + k as u64, 0);
            let (mut by_cos, mut by_phi) = (vec![0usize; bins], vec![0usize; azimuths]);
            for _ in 0..n {
                let (wi, pdf) = hg.sample(wo, s.next_2d());
                assert!((pdf - hg.eval(wo, wi)).abs() <= 1e-3 * pdf.max(1.0), "g = {g}: pdf {pdf}");
                let local = frame.to_local(wi);
                let c = local.z.clamp(-1.0, 1.0);
                by_cos[(((c + 1.0) * 0.5 * bins as f32) as usize).min(bins - 1)] += 1;
                let phi = local.y.atan2(local.x).rem_euclid(2.0 * PI);
                by_phi[((phi / (2.0 * PI) * azimuths as f32) as usize).min(azimuths - 1)] += 1;
            }
            let pmf: Vec<f64> = (0..bins)
                .map(|b| {
                    let (c0, m) = (-1.0 + 2.0 * b as f64 / bins as f64, 256);
                    (0..m)
                        .map(|i| {
                            let c = c0 + (i as f64 + 0.5) / m as f64 * 2.0 / bins as f64;
                            hg.density(c as f32) as f64 * 2.0 * std::f64::consts::PI * 2.0 / bins as f64 / m as f64
                        })
                        .sum()
                })
                .collect();
            let (chi2, df) = chi_square(&by_cos, &pmf, n);
            assert!(chi2 < critical_1e3(df), "g = {g}: cos θ χ² {chi2:.1} (df {df})");
            let (chi2, df) = chi_square(&by_phi, &vec![1.0 / azimuths as f64; azimuths], n);
            assert!(chi2 < critical_1e3(df), "g = {g}: azimuth χ² {chi2:.1} (df {df})");
        }
    }
}
