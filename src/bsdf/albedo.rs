//! Directional albedos of GGX lobes, tabulated at build time and read by interpolation
//! (as Cycles keeps its `ggx_E` tables):
//! * the dielectric specular layer, E(cos θo, roughness, η), which weights the diffuse base
//!   under it (layered.rs);
//! * the white single-scattering GGX lobe, E(cos θo, roughness) and its cosine-weighted mean
//!   E_avg(roughness), which compensate the energy that single scattering loses (Blender's
//!   "Multiscatter GGX", conductor.rs);
//! * the rough glass interface, reflection plus transmission, E(cos θo, roughness, η) from
//!   either side and its mean E_avg(roughness, η), for the same compensation of glass
//!   (dielectric.rs).
//!
//! Each entry integrates ∫ F·D·G2 / (4 cos θo) dωi with the visible-normal estimator F·G2/G1
//! on a stratified grid (albedo_tables.rs), once, when the crate is built.

pub use super::albedo_tables::glass_albedo_integral;
pub use super::albedo_tables::{ggx_albedo_integral, specular_albedo_integral};
use super::albedo_tables::{N_ETA, N_MU, N_ROUGH, N_ROUGH_WHITE};

/// The tables, tabulated by the build script (build.rs, from albedo_tables.rs).
mod compiled {
    include!(concat!(env!("OUT_DIR"), "/albedo_tables.rs"));
}

fn dielectric_table() -> &'static [f32] {
    &compiled::DIELECTRIC
}

fn white_table() -> &'static [f32] {
    &compiled::WHITE
}

fn white_average_table() -> &'static [f32] {
    &compiled::WHITE_AVERAGE
}

fn glass_table() -> &'static [f32] {
    &compiled::GLASS
}

fn glass_average_table() -> &'static [f32] {
    &compiled::GLASS_AVERAGE
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

/// The tabulated albedo (E, E_avg) of a white rough glass interface of relative IOR `eta`
/// (above 1 from outside, below from inside; |η| beyond 3 reads the η = 3 entries) at cos θo:
/// E trilinear in (√cos θo, roughness, (η − 1)/(η + 1)), E_avg bilinear in the last two.
pub fn glass_albedo(cos_o: f32, roughness: f32, eta: f32) -> (f32, f32) {
    let (side, eta) = if eta >= 1.0 { (0, eta) } else { (1, 1.0 / eta) };
    let (k, fk) = axis(2.0 * (eta - 1.0) / (eta + 1.0), N_ETA);
    let layer = N_MU * N_ROUGH;
    let base = side * N_ETA * layer;
    let (t, avg) = (glass_table(), glass_average_table());
    let e = lerp(
        plane(t, base + k * layer, N_ROUGH, cos_o, roughness),
        plane(t, base + (k + 1) * layer, N_ROUGH, cos_o, roughness),
        fk,
    );
    let (j, fj) = axis(roughness, N_ROUGH);
    let at = |k: usize, j: usize| avg[side * N_ETA * N_ROUGH + k * N_ROUGH + j];
    let e_avg = lerp(lerp(at(k, j), at(k, j + 1), fj), lerp(at(k + 1, j), at(k + 1, j + 1), fj), fk);
    (e, e_avg)
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

    /// The glass table reads back its integral off grazing angles (measured worst over these
    /// 400 points: 0.0019 from outside, 0.011 from inside, where E steps up at the critical
    /// angle), E_avg is E's cosine-weighted mean, and a smooth interface loses nothing.
    #[test]
    fn glass_table_and_average() {
        let mut s = crate::sampler::IndependentSampler::new(5, 0);
        use crate::sampler::Sampler;
        let mut worst = [0.0f32; 2];
        for _ in 0..400 {
            let (mu, r, eta) = (0.15 + 0.85 * s.next_1d(), s.next_1d(), 1.05 + 1.5 * s.next_1d());
            for (side, eta) in [eta, 1.0 / eta].into_iter().enumerate() {
                let (t, d) = (glass_albedo(mu, r, eta).0, glass_albedo_integral(mu, r, eta));
                worst[side] = worst[side].max((t - d).abs());
            }
        }
        eprintln!("glass table: worst |table − integral| outside {}, inside {}", worst[0], worst[1]);
        // from inside, E steps up at the critical angle: the interpolation is worst there
        assert!(worst[0] < 0.005 && worst[1] < 0.015, "{worst:?}");
        for eta in [1.5f32, 1.0 / 1.5] {
            assert!((glass_albedo(0.8, 0.0, eta).0 - 1.0).abs() < 1e-3);
            for r in [0.3f32, 0.7, 1.0] {
                let n = 400;
                let fine: f32 = (0..n)
                    .map(|i| {
                        let mu = (i as f32 + 0.5) / n as f32;
                        2.0 * glass_albedo_integral(mu, r, eta) * mu / n as f32
                    })
                    .sum();
                let avg = glass_albedo(0.5, r, eta).1;
                assert!((avg - fine).abs() < 0.01, "η={eta} r={r}: E_avg {avg} vs {fine}");
            }
        }
    }

    /// The tables compiled in are the ones albedo_tables.rs defines, entry for entry (a few
    /// spot checks per table: the whole of them would take the 0.2 s the build saves).
    #[test]
    fn compiled_tables_are_their_definition() {
        use super::super::albedo_tables::{dielectric_entry, white_averages, white_entry};
        assert_eq!(dielectric_table().len(), N_MU * N_ROUGH * N_ETA);
        assert_eq!(white_table().len(), N_MU * N_ROUGH_WHITE);
        for n in (0..dielectric_table().len()).step_by(97) {
            assert_eq!(dielectric_table()[n], dielectric_entry(n), "dielectric entry {n}");
        }
        for n in (0..white_table().len()).step_by(13) {
            assert_eq!(white_table()[n], white_entry(n), "white entry {n}");
        }
        assert_eq!(white_average_table(), white_averages(white_table()).as_slice());
        use super::super::albedo_tables::{glass_entry, hemispherical_averages, N_SIDE};
        assert_eq!(glass_table().len(), N_SIDE * N_MU * N_ROUGH * N_ETA);
        for n in (0..glass_table().len()).step_by(101) {
            assert_eq!(glass_table()[n], glass_entry(n), "glass entry {n}");
        }
        assert_eq!(glass_average_table(), hemispherical_averages(glass_table()).as_slice());
    }
}
