//! Directional albedos of GGX lobes, tabulated once per process and read by interpolation
//! (as Cycles keeps its `ggx_E` tables):
//! * the dielectric specular layer, E(cos θo, roughness, η), which weights the diffuse base
//!   under it (layered.rs);
//! * the white single-scattering GGX lobe, E(cos θo, roughness) and its cosine-weighted mean
//!   E_avg(roughness), which compensate the energy that single scattering loses (Blender's
//!   "Multiscatter GGX", conductor.rs).
//!
//! Each entry integrates ∫ F·D·G2 / (4 cos θo) dωi with the visible-normal estimator F·G2/G1
//! on a stratified grid.

use super::microfacet::{fresnel_dielectric, reflect, Ggx};
use glam::{Vec2, Vec3};
use std::sync::OnceLock;

/// Stratified visible-normal samples per table entry (STRATA²).
const STRATA: usize = 20;

/// The albedo of a GGX reflection lobe of Blender roughness `roughness` with Fresnel term
/// `fresnel(ωo·h)`, at cos θo.
pub fn ggx_albedo_integral(cos_o: f32, roughness: f32, fresnel: impl Fn(f32) -> f32) -> f32 {
    let cos_o = cos_o.clamp(1e-4, 1.0);
    let wo = Vec3::new((1.0 - cos_o * cos_o).sqrt(), 0.0, cos_o);
    let g = Ggx::from_roughness(roughness);
    let mut sum = 0.0f64;
    for i in 0..STRATA {
        for j in 0..STRATA {
            let u = Vec2::new((i as f32 + 0.5) / STRATA as f32, (j as f32 + 0.5) / STRATA as f32);
            let h = g.sample_visible(wo, u);
            let wi = reflect(wo, h);
            if wi.z > 0.0 {
                sum += (fresnel(wo.dot(h)) * g.g2(wo, wi) / g.g1(wo)) as f64;
            }
        }
    }
    (sum / (STRATA * STRATA) as f64) as f32
}

/// E(θo) of the dielectric layer: F = the dielectric Fresnel term of η.
pub fn specular_albedo_integral(cos_o: f32, roughness: f32, eta: f32) -> f32 {
    ggx_albedo_integral(cos_o, roughness, |c| fresnel_dielectric(c, eta))
}

/// Nodes along √cos θo, roughness and x = (η − 1)/(η + 1) ∈ [0, 1/2] (η ∈ [1, 3]).
const N_MU: usize = 32;
const N_ROUGH: usize = 24;
const N_ETA: usize = 16;
/// The white lobe's table is 2D: finer in roughness.
const N_ROUGH_WHITE: usize = 64;

fn build(n: usize, entry: impl Fn(usize) -> f32 + Sync + Send) -> Vec<f32> {
    use rayon::prelude::*;
    (0..n).into_par_iter().map(entry).collect()
}

/// cos θo of node i along the √cos θo axis, and roughness of node j of `n_rough`.
#[inline]
fn node(i: usize, j: usize, n_rough: usize) -> (f32, f32) {
    let s = i as f32 / (N_MU - 1) as f32;
    (s * s, j as f32 / (n_rough - 1) as f32)
}

fn dielectric_table() -> &'static [f32] {
    static TABLE: OnceLock<Vec<f32>> = OnceLock::new();
    TABLE.get_or_init(|| {
        build(N_MU * N_ROUGH * N_ETA, |n| {
            let (i, j, k) = (n % N_MU, (n / N_MU) % N_ROUGH, n / (N_MU * N_ROUGH));
            let x = 0.5 * k as f32 / (N_ETA - 1) as f32;
            let (mu, r) = node(i, j, N_ROUGH);
            specular_albedo_integral(mu, r, (1.0 + x) / (1.0 - x))
        })
    })
}

fn white_table() -> &'static [f32] {
    static TABLE: OnceLock<Vec<f32>> = OnceLock::new();
    TABLE.get_or_init(|| {
        build(N_MU * N_ROUGH_WHITE, |n| {
            let (mu, r) = node(n % N_MU, n / N_MU, N_ROUGH_WHITE);
            ggx_albedo_integral(mu, r, |_| 1.0)
        })
    })
}

/// E_avg(roughness) = 2∫ E(μ) μ dμ per roughness node, by the trapezoid rule over the
/// table's nodes (μ = s², dμ = 2s ds).
fn white_average_table() -> &'static [f32] {
    static TABLE: OnceLock<Vec<f32>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let t = white_table();
        (0..N_ROUGH_WHITE)
            .map(|j| {
                let f = |i: usize| {
                    let s = i as f32 / (N_MU - 1) as f32;
                    2.0 * t[j * N_MU + i] * s * s * 2.0 * s // 2·E·μ·dμ/ds
                };
                let h = 1.0 / (N_MU - 1) as f32;
                h * ((1..N_MU - 1).map(f).sum::<f32>() + 0.5 * (f(0) + f(N_MU - 1)))
            })
            .collect()
    })
}

/// Position of `v` on an axis of `n` nodes over [0, 1]: (lower node, fraction).
#[inline]
fn axis(v: f32, n: usize) -> (usize, f32) {
    let p = v.clamp(0.0, 1.0) * (n - 1) as f32;
    let i = (p as usize).min(n - 2);
    (i, p - i as f32)
}

#[inline]
fn lerp(a: f32, b: f32, f: f32) -> f32 {
    a + (b - a) * f
}

/// Bilinear read of an N_MU × `n_rough` plane starting at `base`.
#[inline]
fn plane(t: &[f32], base: usize, n_rough: usize, cos_o: f32, roughness: f32) -> f32 {
    let (i, fi) = axis(cos_o.max(0.0).sqrt(), N_MU);
    let (j, fj) = axis(roughness, n_rough);
    let at = |i: usize, j: usize| t[base + j * N_MU + i];
    lerp(lerp(at(i, j), at(i + 1, j), fi), lerp(at(i, j + 1), at(i + 1, j + 1), fi), fj)
}

/// The tabulated E(cos θo, roughness, η) of the dielectric layer, trilinear (η above 3 reads
/// the η = 3 entries).
pub fn specular_albedo(cos_o: f32, roughness: f32, eta: f32) -> f32 {
    let t = dielectric_table();
    let (k, fk) = axis(2.0 * ((eta - 1.0) / (eta + 1.0)).abs(), N_ETA);
    let layer = N_MU * N_ROUGH;
    lerp(plane(t, k * layer, N_ROUGH, cos_o, roughness), plane(t, (k + 1) * layer, N_ROUGH, cos_o, roughness), fk)
}

/// The tabulated albedo E(cos θo, roughness) of a white (F = 1) single-scattering GGX lobe.
pub fn ggx_albedo(cos_o: f32, roughness: f32) -> f32 {
    plane(white_table(), 0, N_ROUGH_WHITE, cos_o, roughness)
}

/// Its cosine-weighted hemispherical mean E_avg(roughness).
pub fn ggx_albedo_average(roughness: f32) -> f32 {
    let (j, fj) = axis(roughness, N_ROUGH_WHITE);
    let t = white_average_table();
    lerp(t[j], t[j + 1], fj)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table reads back the integral between its nodes: within 0.0025 for cos θo ≥ 0.2
    /// and 0.012 at grazing angles, where E climbs steeply to 1 with low roughness (measured
    /// worst over these 300 points: 0.0017 and 0.0098; both include the integral's own
    /// quadrature error).
    #[test]
    fn albedo_table_interpolates_the_integral() {
        let mut s = crate::sampler::IndependentSampler::new(3, 0);
        use crate::sampler::Sampler;
        let (mut worst, mut worst_grazing) = (0.0f32, 0.0f32);
        for _ in 0..300 {
            let (mu, r, eta) = (s.next_1d().max(0.02), s.next_1d(), 1.05 + 1.5 * s.next_1d());
            let err = (specular_albedo(mu, r, eta) - specular_albedo_integral(mu, r, eta)).abs();
            if mu >= 0.2 {
                worst = worst.max(err);
            } else {
                worst_grazing = worst_grazing.max(err);
            }
        }
        assert!(worst < 2.5e-3 && worst_grazing < 0.012, "table off the integral by {worst} ({worst_grazing} grazing)");
        // a smooth layer reflects the Fresnel term: 4% at normal incidence for η = 1.5
        assert!((specular_albedo(1.0, 0.0, 1.5) - 0.04).abs() < 1e-3);
    }

    /// The white lobe's table reads back its integral, E_avg is its cosine-weighted mean, and
    /// both are 1 for a smooth lobe and fall with roughness (0.30685 at α = 1, normal incidence).
    #[test]
    fn white_ggx_table_and_average() {
        let mut s = crate::sampler::IndependentSampler::new(4, 0);
        use crate::sampler::Sampler;
        for _ in 0..100 {
            let (mu, r) = (0.2 + 0.8 * s.next_1d(), s.next_1d());
            let (t, d) = (ggx_albedo(mu, r), ggx_albedo_integral(mu, r, |_| 1.0));
            assert!((t - d).abs() < 2.5e-3, "μ={mu} r={r}: table {t} vs integral {d}");
        }
        assert!((ggx_albedo(1.0, 1.0) - 0.30685).abs() < 0.01, "{}", ggx_albedo(1.0, 1.0));
        assert!((ggx_albedo(0.7, 0.0) - 1.0).abs() < 1e-3 && (ggx_albedo_average(0.0) - 1.0).abs() < 5e-3);
        // E_avg by a fine midpoint rule over μ against the table's trapezoid
        for r in [0.3f32, 0.6, 1.0] {
            let n = 400;
            let fine: f32 = (0..n)
                .map(|i| {
                    let mu = (i as f32 + 0.5) / n as f32;
                    2.0 * ggx_albedo_integral(mu, r, |_| 1.0) * mu / n as f32
                })
                .sum();
            assert!((ggx_albedo_average(r) - fine).abs() < 5e-3, "r={r}: {} vs {fine}", ggx_albedo_average(r));
        }
        let avg: Vec<f32> = [0.0f32, 0.3, 0.6, 1.0].iter().map(|&r| ggx_albedo_average(r)).collect();
        assert!(avg.windows(2).all(|w| w[1] < w[0]), "{avg:?}");
    }
}
