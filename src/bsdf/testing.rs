//! Statistical tests shared by every BSDF (in the spirit of Mitsuba 3's `chi2` module):
//! a chi-square goodness-of-fit test of `sample` against `pdf`, and a white-furnace check.

use super::Bsdf;
use crate::math::{luminance, square_to_uniform_sphere};
use crate::sampler::{IndependentSampler, Sampler};
use glam::{Vec2, Vec3};
use std::f64::consts::PI;

const THETA_BINS: usize = 10;
const PHI_BINS: usize = 20;

fn bin_of(w: Vec3) -> usize {
    let z = w.z.clamp(-1.0, 1.0) as f64;
    let phi = (w.y as f64).atan2(w.x as f64).rem_euclid(2.0 * PI);
    let i = (((z + 1.0) * 0.5 * THETA_BINS as f64) as usize).min(THETA_BINS - 1);
    let j = ((phi / (2.0 * PI) * PHI_BINS as f64) as usize).min(PHI_BINS - 1);
    i * PHI_BINS + j
}

/// Chi-square test of the non-delta lobes, with bins uniform in (cos θ, φ) (equal solid angle); expected counts
/// integrate `pdf` with a 48×16 (θ, φ) midpoint rule per bin. Bins with expected count < 5 are
/// pooled. Fails at significance 1e-3 (Wilson–Hilferty approximation of the quantile).
pub fn chi2_test(bsdf: &Bsdf, wo: Vec3, seed: u64) {
    let n = 500_000usize;
    let mut observed = vec![0.0f64; THETA_BINS * PHI_BINS];
    let mut s = IndependentSampler::new(seed, 0);
    for _ in 0..n {
        let (ul, u) = (s.next_1d(), s.next_2d());
        if let Some(bs) = bsdf.sample(wo, ul, u) {
            assert!(bs.pdf > 0.0 && bs.weight.is_finite());
            if bs.lobe == super::LobeKind::Specular {
                continue; // delta lobes have no density; pdf() integrates to the rest
            }
            // the pdf that sample reports must equal pdf()
            let p = bsdf.pdf(wo, bs.wi);
            assert!((p - bs.pdf).abs() <= 1e-3 * p.max(1e-3), "pdf mismatch {p} vs {}", bs.pdf);
            observed[bin_of(bs.wi)] += 1.0;
        }
    }
    // Expected counts: midpoint rule per bin with sub-cells uniform in θ (not in cos θ) so
    // that lobes squeezed against a pole (refraction into a denser medium) are resolved;
    // each sub-cell is weighted by its exact solid angle.
    let (sub_t, sub_p) = (48, 16);
    let mut expected = vec![0.0f64; THETA_BINS * PHI_BINS];
    let dz = 2.0 / THETA_BINS as f64;
    let dphi = 2.0 * PI / PHI_BINS as f64;
    for i in 0..THETA_BINS {
        let (z0, z1) = (-1.0 + i as f64 * dz, -1.0 + (i + 1) as f64 * dz);
        let (t_hi, t_lo) = (z0.clamp(-1.0, 1.0).acos(), z1.clamp(-1.0, 1.0).acos());
        for j in 0..PHI_BINS {
            let mut acc = 0.0;
            for a in 0..sub_t {
                let ta = t_lo + (t_hi - t_lo) * a as f64 / sub_t as f64;
                let tb = t_lo + (t_hi - t_lo) * (a + 1) as f64 / sub_t as f64;
                let area = (ta.cos() - tb.cos()) * dphi / sub_p as f64;
                let (st, ct) = ((0.5 * (ta + tb)).sin(), (0.5 * (ta + tb)).cos());
                for b in 0..sub_p {
                    let phi = (j as f64 + (b as f64 + 0.5) / sub_p as f64) * dphi;
                    let w = Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                    acc += bsdf.pdf(wo, w) as f64 * area;
                }
            }
            expected[i * PHI_BINS + j] = acc * n as f64;
        }
    }
    let (mut chi2, mut dof, mut pool_o, mut pool_e) = (0.0, 0usize, 0.0, 0.0);
    for k in 0..expected.len() {
        if expected[k] < 5.0 {
            pool_o += observed[k];
            pool_e += expected[k];
            assert!(expected[k] > 0.0 || observed[k] == 0.0, "sample in a zero-pdf bin {k}");
        } else {
            chi2 += (observed[k] - expected[k]).powi(2) / expected[k];
            dof += 1;
        }
    }
    if pool_e >= 5.0 {
        chi2 += (pool_o - pool_e).powi(2) / pool_e;
        dof += 1;
    }
    let dof = (dof.max(2) - 1) as f64;
    let z = 3.09; // one-sided normal quantile for 1e-3
    let q = dof * (1.0 - 2.0 / (9.0 * dof) + z * (2.0 / (9.0 * dof)).sqrt()).powi(3);
    assert!(chi2 < q, "chi-square {chi2:.1} exceeds {q:.1} (dof {dof}) for wo={wo:?}");
}

/// Directional albedo ∫ f·|cos| dωi two ways: by the BSDF's own sampling and by uniform
/// sphere quadrature of `eval`. For an energy-conserving lossless BSDF both are 1.
pub fn white_furnace(bsdf: &Bsdf, wo: Vec3, n: usize, seed: u64) -> (f64, f64) {
    let mut s = IndependentSampler::new(seed, 1);
    let mut by_sampling = 0.0f64;
    let mut by_quadrature = 0.0f64;
    for _ in 0..n {
        if let Some(bs) = bsdf.sample(wo, s.next_1d(), s.next_2d()) {
            by_sampling += luminance(bs.weight) as f64;
        }
        let w = square_to_uniform_sphere(Vec2::new(s.next_1d(), s.next_1d()));
        by_quadrature += luminance(bsdf.eval(wo, w)) as f64 * 4.0 * PI;
    }
    (by_sampling / n as f64, by_quadrature / n as f64)
}
