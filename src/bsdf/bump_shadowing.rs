//! The shadowing Cycles applies to diffuse lobes under normal and bump maps (its material
//! setting "Bump Map Correction", on by default), after Conty Estevez, Lecocq and Stein 2019,
//! "A Microfacet-Based Shadowing Function to Solve the Bump Terminator Problem".
//!
//! A mapped normal N that leans away from the surface's own (smooth, unmapped) normal Ns
//! treats the surface as if its bumps were microfacets of a GGX distribution around Ns,
//! whose spread grows with the lean: α² = min(1, tan²θd / 8), cos θd = |Ns·N|. Light from
//! the direction ωi is then masked by the Smith term of that distribution,
//! G1(θi) = 2 / (1 + √(1 + α² tan²θi)), cos θi = |Ns·ωi| — near Ns's horizon the bumps
//! shadow each other, instead of lighting up because N faces the light. A direction on one
//! side of Ns and the other side of N (light leaking through the surface) gets nothing:
//! (Ns·ωi)(Ns·N)(N·ωi) < 0.
//!
//! Everything here is in the shading frame, whose Z is the mapped normal N; `unmapped` is Ns
//! there (+Z: the normal is not mapped, and nothing is shadowed).

use glam::Vec3;

/// The factor f is multiplied by towards `wi` for a diffuse lobe of the shading frame whose
/// unmapped normal is `unmapped` (both unit vectors in that frame).
#[inline]
pub fn diffuse_bump_shadowing(unmapped: Vec3, wi: Vec3) -> f32 {
    if unmapped == Vec3::Z {
        return 1.0;
    }
    let (cos_ns_i, cos_ns_n) = (unmapped.dot(wi), unmapped.z);
    if cos_ns_i * cos_ns_n * wi.z < 0.0 {
        return 0.0;
    }
    let (cos_i, cos_d) = (cos_ns_i.abs(), cos_ns_n.abs());
    if cos_d >= 1.0 || cos_i >= 1.0 {
        return 1.0;
    }
    if cos_i < 1e-6 {
        return 0.0;
    }
    let alpha2 = (0.125 * (1.0 / (cos_d * cos_d) - 1.0)).clamp(0.0, 1.0);
    let tan2_i = (1.0 - cos_i * cos_i) / (cos_i * cos_i);
    2.0 / (1.0 + (1.0 + alpha2 * tan2_i).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// No lean, no shadowing; light along Ns is never shadowed; the factor falls towards Ns's
    /// horizon, the faster the more N leans; light leaking across Ns gets nothing; and it is
    /// the GGX Smith masking G1 of α² = tan²θd/8, checked against its Λ form.
    #[test]
    fn shadowing_follows_the_lean_and_the_horizon() {
        let lean = |deg: f32| Vec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
        let dir = |deg: f32, az: f32| {
            let (t, p) = (deg.to_radians(), az.to_radians());
            Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
        };
        assert_eq!(diffuse_bump_shadowing(Vec3::Z, dir(80.0, 0.0)), 1.0);
        for d in [10.0, 30.0, 50.0] {
            let ns = lean(-d); // Ns in the frame of N: N leans by d from Ns
            assert!((diffuse_bump_shadowing(ns, ns) - 1.0).abs() < 1e-5);
            let mut last = 1.0;
            for theta in [20.0f32, 40.0, 60.0, 75.0, 85.0] {
                // θ from Ns, on the side N leans towards (where N sees the light better)
                let wi = Vec3::new((theta - d).to_radians().sin(), 0.0, (theta - d).to_radians().cos());
                let g = diffuse_bump_shadowing(ns, wi);
                let cos_i = ns.dot(wi);
                let alpha2 = (d.to_radians().tan().powi(2) / 8.0).min(1.0);
                let lambda = 0.5 * (-1.0 + (1.0 + alpha2 * (1.0 - cos_i * cos_i) / (cos_i * cos_i)).sqrt());
                assert!((g - 1.0 / (1.0 + lambda)).abs() < 1e-5, "{d} {theta}: {g}");
                assert!(g <= last + 1e-6, "not falling towards the horizon");
                last = g;
            }
            // the same direction from Ns, under a steeper lean: more shadowed
            let from_ns = |lean: f32, theta: f32| {
                Vec3::new((theta - lean).to_radians().sin(), 0.0, (theta - lean).to_radians().cos())
            };
            let steeper = diffuse_bump_shadowing(lean(-d - 10.0), from_ns(d + 10.0, 70.0));
            assert!(steeper < diffuse_bump_shadowing(ns, from_ns(d, 70.0)), "{d}");
        }
        // below Ns's horizon while above N's: leaking light
        let ns = lean(-40.0);
        let wi = Vec3::new(0.9, 0.0, 0.2).normalize();
        assert!(ns.dot(wi) < 0.0 && wi.z > 0.0);
        assert_eq!(diffuse_bump_shadowing(ns, wi), 0.0);
    }
}
