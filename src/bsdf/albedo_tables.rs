//! The GGX albedo tables' definition: their axes and how each entry is integrated. Compiled
//! twice — into the build script (`build.rs`), which tabulates them once at build time, and
//! into the crate, whose tests check the compiled tables against these functions and the
//! integrals. (Computed at run time instead, they cost the first render of every process
//! about 0.2 s on 2 cores — once per frame on a farm that starts a process per frame.)

use super::microfacet::{fresnel_dielectric, reflect, refract, Ggx};
use glam::{Vec2, Vec3};

/// Stratified visible-normal samples per table entry (STRATA²).
pub const STRATA: usize = 20;
/// Nodes along √cos θo, roughness and x = (η − 1)/(η + 1) ∈ [0, 1/2] (η ∈ [1, 3]).
pub const N_MU: usize = 32;
pub const N_ROUGH: usize = 24;
pub const N_ETA: usize = 16;
/// The white lobe's table is 2D: finer in roughness.
pub const N_ROUGH_WHITE: usize = 64;
/// The glass table's two sides: seen from outside (η ≥ 1) and from inside (1/η).
pub const N_SIDE: usize = 2;

/// The albedo of a GGX reflection lobe of Blender roughness `roughness` with Fresnel term
/// `fresnel(ωo·h)`, at cos θo: ∫ F·D·G2 / (4 cos θo) dωi by the visible-normal estimator
/// F·G2/G1 on a stratified grid.
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

/// The albedo, reflection plus transmission, of a rough dielectric interface (glass) of
/// relative IOR `eta` = η_t/η_i — above 1 seen from outside, below 1 from inside — at cos θo,
/// without 1/η² radiance scaling (as dielectric.rs and Cycles): the visible-normal estimator
/// F·G2/G1 of the reflected direction plus (1 − F)·G2/G1 of the refracted one, each counted
/// where it leaves on its own side of the macro surface, on a stratified grid.
pub fn glass_albedo_integral(cos_o: f32, roughness: f32, eta: f32) -> f32 {
    let cos_o = cos_o.clamp(1e-4, 1.0);
    let wo = Vec3::new((1.0 - cos_o * cos_o).sqrt(), 0.0, cos_o);
    let g = Ggx::from_roughness(roughness);
    let g1 = g.g1(wo);
    let mut sum = 0.0f64;
    for i in 0..STRATA {
        for j in 0..STRATA {
            let u = Vec2::new((i as f32 + 0.5) / STRATA as f32, (j as f32 + 0.5) / STRATA as f32);
            let h = g.sample_visible(wo, u);
            let f = fresnel_dielectric(wo.dot(h), eta);
            let wr = reflect(wo, h);
            if wr.z > 0.0 {
                sum += (f * g.g2(wo, wr) / g1) as f64;
            }
            if f < 1.0 {
                if let Some(wt) = refract(wo, h, eta).filter(|wt| wt.z < 0.0) {
                    sum += ((1.0 - f) * g.g2(wo, wt) / g1) as f64;
                }
            }
        }
    }
    (sum / (STRATA * STRATA) as f64) as f32
}

/// cos θo of node i along the √cos θo axis, and roughness of node j of `n_rough`.
#[inline]
pub fn node(i: usize, j: usize, n_rough: usize) -> (f32, f32) {
    let s = i as f32 / (N_MU - 1) as f32;
    (s * s, j as f32 / (n_rough - 1) as f32)
}

/// Entry n of the dielectric table (μ fastest, then roughness, then η).
pub fn dielectric_entry(n: usize) -> f32 {
    let (i, j, k) = (n % N_MU, (n / N_MU) % N_ROUGH, n / (N_MU * N_ROUGH));
    let x = 0.5 * k as f32 / (N_ETA - 1) as f32;
    let (mu, r) = node(i, j, N_ROUGH);
    specular_albedo_integral(mu, r, (1.0 + x) / (1.0 - x))
}

/// Entry n of the white lobe's table (μ fastest, then roughness).
pub fn white_entry(n: usize) -> f32 {
    let (mu, r) = node(n % N_MU, n / N_MU, N_ROUGH_WHITE);
    ggx_albedo_integral(mu, r, |_| 1.0)
}

/// Entry n of the glass table (μ fastest, then roughness, then η, then the side: outside
/// with η = (1 + x)/(1 − x), inside with its inverse).
pub fn glass_entry(n: usize) -> f32 {
    let layer = N_MU * N_ROUGH * N_ETA;
    let (side, m) = (n / layer, n % layer);
    let (i, j, k) = (m % N_MU, (m / N_MU) % N_ROUGH, m / (N_MU * N_ROUGH));
    let x = 0.5 * k as f32 / (N_ETA - 1) as f32;
    let eta = (1.0 + x) / (1.0 - x);
    let (mu, r) = node(i, j, N_ROUGH);
    glass_albedo_integral(mu, r, if side == 0 { eta } else { 1.0 / eta })
}

/// E_avg = 2∫ E(μ) μ dμ of every run of N_MU entries of a table (one per roughness node of
/// the white table; per side, η and roughness of the glass table), by the trapezoid rule
/// over its nodes (μ = s², dμ = 2s ds).
pub fn hemispherical_averages(table: &[f32]) -> Vec<f32> {
    table
        .chunks_exact(N_MU)
        .map(|e| {
            let f = |i: usize| {
                let s = i as f32 / (N_MU - 1) as f32;
                2.0 * e[i] * s * s * 2.0 * s // 2·E·μ·dμ/ds
            };
            let h = 1.0 / (N_MU - 1) as f32;
            h * ((1..N_MU - 1).map(f).sum::<f32>() + 0.5 * (f(0) + f(N_MU - 1)))
        })
        .collect()
}

/// E_avg(roughness) of the white table.
pub fn white_averages(white: &[f32]) -> Vec<f32> {
    hemispherical_averages(white)
}
