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

/// A medium's phase function: Henyey–Greenstein, or one of the others Cycles' Volume Scatter
/// offers — Rayleigh (small particles: p = 3(1 + cos²θ)/(16π)), Draine (HG times
/// (1 + α cos²θ), normalised: p = (1 − g²)(1 + α cos²θ) / (4π (1 + α(1 + 2g²)/3)
/// (1 + g² − 2g cos θ)^{3/2})) and Mie (water droplets of a diameter d: HG and Draine mixed by
/// Jendersie and d'Eon's 2023 fit in d, as Cycles).
///
/// Sampling: HG and Rayleigh exactly (their inverse CDFs; weight 1); Draine from its HG
/// factor, Mie from the mixture of its two HG factors, weighted p/pdf (bounded by 1 + α over
/// the normalisation). The density a sampler reports (`pdf`) is then the proposal's, which
/// depends on cos θ alone, as p does: both are symmetric in the two directions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    Hg(HenyeyGreenstein),
    Rayleigh,
    Draine {
        hg: HenyeyGreenstein,
        alpha: f32,
    },
    /// (1 − w)·HG(g) + w·Draine(g_d, α).
    Mie {
        w: f32,
        hg: HenyeyGreenstein,
        draine: HenyeyGreenstein,
        alpha: f32,
    },
}

impl Phase {
    /// Cycles' Draine: |α| below 1e-3 is HG, and a near-isotropic one with α near 1 Rayleigh.
    pub fn draine(g: f32, alpha: f32) -> Phase {
        let hg = HenyeyGreenstein::new(g);
        let alpha = if alpha.is_finite() { alpha.max(0.0) } else { 0.0 };
        if alpha.abs() < 1e-3 {
            Phase::Hg(hg)
        } else if hg.g.abs() < 1e-3 && alpha > 0.999 && alpha < 1.001 {
            Phase::Rayleigh
        } else {
            Phase::Draine { hg, alpha }
        }
    }

    /// Mie for droplets of diameter `d` micrometres (the fit is made for 0 < d < 50).
    pub fn mie(d: f32) -> Phase {
        let d = if d.is_finite() { d.max(0.0) } else { 0.0 };
        let l = d.max(1e-6).ln();
        let (g_hg, g_d, alpha, w) = if d <= 0.1 {
            (13.8 * d * d, 1.1456 * d * (9.29044 * d).sin(), 250.0, 0.252977 - 312.983 * d.powf(4.3))
        } else if d < 1.5 {
            let a = (l - 0.238604) * (l + 1.00667);
            let b = 0.507522 - 0.15677 * l;
            let c = 1.19692 * (a / b).cos() + 1.37932 * l + 0.0625835;
            (
                0.862 - 0.143 * l * l,
                0.379685 * c.cos() + 0.344213,
                250.0,
                0.146209 * (3.38707 * l + 2.11193).cos() + 0.316072 + 0.0778917 * l,
            )
        } else if d < 5.0 {
            (
                0.0604931 * l.ln() + 0.940256,
                0.500411 - 0.081287 / (-2.0 * l + l.tan() + 1.27551),
                7.30354 * l + 6.31675,
                0.026914 * (l - (5.68947 * (l.ln() - 0.0292149)).cos()) + 0.3764,
            )
        } else {
            (
                (-0.0990567 / (d - 1.67154)).exp(),
                (-2.20679 / (d + 3.91029) - 0.428934).exp(),
                (3.62489 - 8.29288 / (d + 5.52825)).exp(),
                (-0.599085 / (d - 0.641583) - 0.665888).exp(),
            )
        };
        Phase::Mie {
            w: w.clamp(0.0, 1.0),
            hg: HenyeyGreenstein::new(g_hg),
            draine: HenyeyGreenstein::new(g_d),
            alpha: alpha.max(0.0),
        }
    }

    /// The Henyey–Greenstein lobe of mean cosine `g` (the default).
    #[inline]
    pub fn hg(g: f32) -> Phase {
        Phase::Hg(HenyeyGreenstein::new(g))
    }

    /// The density (per steradian) of scattering by angle θ with cos θ = `c`.
    #[inline]
    pub fn density(&self, c: f32) -> f32 {
        match *self {
            Phase::Hg(hg) => hg.density(c),
            Phase::Rayleigh => 3.0 / (16.0 * PI) * (1.0 + c * c),
            Phase::Draine { hg, alpha } => draine(hg, alpha, c),
            Phase::Mie { w, hg, draine: d, alpha } => (1.0 - w) * hg.density(c) + w * draine(d, alpha, c),
        }
    }

    /// The phase function from `wo` (towards the previous vertex) to `wi`.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.density((-wo).dot(wi))
    }

    /// The density with which `sample` returns `wi` (per steradian).
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let c = (-wo).dot(wi);
        match *self {
            Phase::Hg(_) | Phase::Rayleigh => self.density(c),
            Phase::Draine { hg, .. } => hg.density(c),
            Phase::Mie { w, hg, draine, .. } => (1.0 - w) * hg.density(c) + w * draine.density(c),
        }
    }

    /// A direction scattered from `wo` from two primary samples: (wi, its density `pdf`,
    /// the weight p/pdf).
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> (Vec3, f32, f32) {
        match *self {
            Phase::Hg(hg) => {
                let (wi, pdf) = hg.sample(wo, u);
                (wi, pdf, 1.0)
            }
            Phase::Rayleigh => {
                // the inverse CDF in closed form (Cardano): μ³ + 3μ + 4 = 8ξ
                let a = 2.0 - 4.0 * u.x;
                let s = ((1.0 + a * a).sqrt() + a).cbrt();
                let c = (1.0 / s - s).clamp(-1.0, 1.0);
                let wi = around(wo, c, u.y);
                (wi, self.density(c), 1.0)
            }
            Phase::Draine { hg, .. } => {
                let (wi, pdf) = hg.sample(wo, u);
                let p = self.eval(wo, wi);
                (wi, pdf, if pdf > 0.0 { p / pdf } else { 0.0 })
            }
            Phase::Mie { w, hg, draine, .. } => {
                // the lobe by u.x, its remainder reused
                let (lobe, ux) = if u.x < w { (draine, u.x / w) } else { (hg, (u.x - w) / (1.0 - w)) };
                let (wi, _) = lobe.sample(wo, Vec2::new(ux.min(1.0 - 1e-7), u.y));
                let pdf = self.pdf(wo, wi);
                (wi, pdf, if pdf > 0.0 { self.eval(wo, wi) / pdf } else { 0.0 })
            }
        }
    }

    /// The mean cosine (what overlapping media's phase functions are averaged by), in closed
    /// form: Draine's g(1 + α(3 + 2g²)/5) / (1 + α(1 + 2g²)/3).
    pub fn mean_cosine(&self) -> f32 {
        let draine_mean = |hg: HenyeyGreenstein, alpha: f32| {
            let g = hg.g;
            g * (1.0 + alpha * (3.0 + 2.0 * g * g) / 5.0) / (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0)
        };
        match *self {
            Phase::Hg(hg) => hg.g,
            Phase::Rayleigh => 0.0,
            Phase::Draine { hg, alpha } => draine_mean(hg, alpha),
            Phase::Mie { w, hg, draine, alpha } => (1.0 - w) * hg.g + w * draine_mean(draine, alpha),
        }
    }
}

/// Draine's density: HG(g) × (1 + α c²) / (1 + α(1 + 2g²)/3).
#[inline]
fn draine(hg: HenyeyGreenstein, alpha: f32, c: f32) -> f32 {
    let g = hg.g;
    hg.density(c) * (1.0 + alpha * c * c) / (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0)
}

/// The direction at cos θ = `c` from the direction of travel −wo, at azimuth 2π·`v`.
#[inline]
fn around(wo: Vec3, c: f32, v: f32) -> Vec3 {
    let sin_theta = (1.0 - c * c).max(0.0).sqrt();
    let phi = 2.0 * PI * v;
    Frame::from_normal(-wo).to_world(Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), c))
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

    /// Every phase function integrates to one; its sampler is unbiased for ∫p·f dω (f = 1,
    /// cos θ, cos²θ, an azimuthal lobe) with the weights it reports, and its reported pdf is
    /// `pdf`'s (Rayleigh, Draine, Mie at four diameters; Cycles' Mie fit regions).
    #[test]
    fn every_phase_function_is_normalised_and_sampled_without_bias() {
        use crate::sampler::{IndependentSampler, Sampler};
        let wo = Vec3::new(0.3, -0.5, 0.8).normalize();
        let frame = Frame::from_normal(-wo);
        let phases = [
            Phase::Rayleigh,
            Phase::draine(0.5, 0.8),
            Phase::draine(-0.3, 20.0),
            Phase::mie(0.05),
            Phase::mie(0.8),
            Phase::mie(3.0),
            Phase::mie(20.0),
        ];
        for (k, ph) in phases.into_iter().enumerate() {
            let m = 400_000;
            let integral = |f: &dyn Fn(f32) -> f32| -> f64 {
                (0..m)
                    .map(|i| {
                        let c = -1.0 + 2.0 * (i as f32 + 0.5) / m as f32;
                        (ph.density(c) * f(c)) as f64
                    })
                    .sum::<f64>()
                    * 2.0
                    / m as f64
                    * 2.0
                    * std::f64::consts::PI
            };
            let total = integral(&|_| 1.0);
            assert!((total - 1.0).abs() < 3e-3, "{ph:?}: ∫p = {total}");
            let (mean, second) = (integral(&|c| c), integral(&|c| c * c));
            assert!((mean - ph.mean_cosine() as f64).abs() < 5e-3, "{ph:?}: mean cosine {mean}");
            let mut s = IndependentSampler::new(31 + k as u64, 1);
            let n = 200_000;
            let (mut sw, mut sc, mut sc2, mut sw2, mut sc22) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
            let mut az = 0.0f64;
            for _ in 0..n {
                let (wi, pdf, w) = ph.sample(wo, s.next_2d());
                assert!((pdf - ph.pdf(wo, wi)).abs() <= 1e-3 * pdf.max(1.0), "{ph:?}: pdf {pdf}");
                let c = frame.to_local(wi).z as f64;
                let w = w as f64;
                sw += w;
                sw2 += w * w;
                sc += w * c;
                sc2 += w * c * c;
                sc22 += (w * c * c).powi(2);
                az += w * (1.0 + frame.to_local(wi).x as f64).max(0.0);
            }
            let nf = n as f64;
            let se = (sw2 / nf - (sw / nf).powi(2)).max(1e-12).sqrt() / nf.sqrt();
            assert!((sw / nf - 1.0).abs() < 5.0 * se + 1e-3, "{ph:?}: E[w] = {} ± {se}", sw / nf);
            assert!((sc / nf - mean).abs() < 5.0 * se + 2e-3, "{ph:?}: E[w cos] = {} against {mean}", sc / nf);
            let se2 = (sc22 / nf - (sc2 / nf).powi(2)).max(1e-12).sqrt() / nf.sqrt();
            assert!((sc2 / nf - second).abs() < 5.0 * se2 + 2e-3, "{ph:?}: E[w cos²] = {} against {second}", sc2 / nf);
            // (rotationally symmetric: the azimuthal lobe 1 + sin θ cos φ averages to 1)
            assert!((az / nf - 1.0).abs() < 5.0 * se + 5e-3, "{ph:?}: azimuth {}", az / nf);
        }
    }
}
