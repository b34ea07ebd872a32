//! Cycles' shadow-terminator geometry offset (Object › Shading › Shadow Terminator ›
//! Geometry Offset, 0.1 by default): where a smooth-shaded triangle is lit at a grazing angle,
//! Cycles starts the light sample's shadow ray not on the flat triangle but lifted towards the
//! smooth surface its corner normals describe, so a coarse mesh's facets do not shadow their
//! own terminator. The lift is Cycles' own (kernel/light/sample.h, `shadow_ray_offset` and
//! `shadow_ray_smooth_surface_offset`), reproduced because it changes the image: on a thick
//! low-poly slab whose corner normals lean 55° from its faces the lifted start lands outside
//! the slab, and its shadow rays see light a flat start would not (a veranda floor under such
//! a roof 5–20% brighter in Cycles, issue 45). Only light samples' shadow rays are lifted;
//! BSDF-sampled rays and path segments start on the triangle, as in Cycles.
//!
//! The smooth surface, after Cycles: over the triangle (vertices Vᵢ, unit corner normals Nᵢ,
//! barycentrics u, v, w of V₀, V₁, V₂) a parabola in the barycentrics that takes each corner
//! normal's slope, h = a·u(u−1) + (a+b+c)·uv + b·v(v−1) with a = (N₂−N₀)·(V₀−V₂),
//! b = (N₂−N₁)·(V₁−V₂), c = (N₁−N₀)·(V₁−V₀), bounded below by the local linear envelope of the
//! corners' tangent planes (on the side the geometric normal faces); the start point moves by
//! h along the interpolated (unnormalised) normal n = uN₀ + vN₁ + wN₂.

use glam::Vec3;

/// Cycles' default Geometry Offset of an object.
pub const DEFAULT_GEOMETRY_OFFSET: f32 = 0.1;

/// The lift of the point at barycentrics `b` (of `v[0]`, `v[1]`, `v[2]`) onto the smooth
/// surface of corner normals `n`, towards the side `ng` faces (Cycles'
/// `shadow_ray_smooth_surface_offset`). Zero at the corners and on a flat-shaded triangle.
pub fn smooth_surface_lift(v: &[Vec3; 3], n: &[Vec3; 3], b: [f32; 3], ng: Vec3) -> Vec3 {
    let [u, vv, w] = b;
    let p = v[0] * u + v[1] * vv + v[2] * w;
    let normal = n[0] * u + n[1] * vv + n[2] * w;
    // the parabola through the corners with their normals' slopes
    let a = (n[2] - n[0]).dot(v[0] - v[2]);
    let bb = (n[2] - n[1]).dot(v[1] - v[2]);
    let c = (n[1] - n[0]).dot(v[1] - v[0]);
    let parabola = a * u * (u - 1.0) + (a + bb + c) * u * vv + bb * vv * (vv - 1.0);
    // each corner's tangent plane, raised to clear the other two corners: the envelope
    let envelope = |i: usize, j: usize, k: usize, sign: f32| {
        let raise = (sign * (v[j] - v[i]).dot(n[i])).max(sign * (v[k] - v[i]).dot(n[i])).max(0.0);
        (sign * (v[i] - p).dot(n[i]) + raise).max(0.0)
    };
    let h = if normal.dot(ng) > 0.0 {
        let e = envelope(0, 1, 2, 1.0).min(envelope(1, 0, 2, 1.0)).min(envelope(2, 0, 1, 1.0));
        e.max(parabola * 0.5)
    } else {
        let e = envelope(0, 1, 2, -1.0).min(envelope(1, 0, 2, -1.0)).min(envelope(2, 0, 1, -1.0));
        (-e).min(parabola * 0.5)
    };
    normal * h
}

/// How much of the lift a shadow ray towards `l` (unit) takes, 0…1, for an object of Geometry
/// Offset `cutoff`, with `ns` and `ng` the shading and geometric normals on the viewer's side:
/// full where the light is grazing on either normal, fading out by twice the cutoff (10–20% of
/// light samples at 0.1). Also the geometric normal on the light's side, which the lift
/// heads to (a light behind the shading normal is a transmission sample).
pub fn lift_amount(ns: Vec3, ng: Vec3, l: Vec3, cutoff: f32) -> (f32, Vec3) {
    if !(cutoff > 0.0) {
        return (0.0, ng);
    }
    let nl = ns.dot(l);
    let ng = if nl < 0.0 { -ng } else { ng };
    let (nl, ngl) = (nl.abs(), ng.dot(l));
    let amount = if nl < cutoff { 2.0 - (ngl + nl) / cutoff } else { 1.0 - ngl / cutoff };
    (amount.clamp(0.0, 1.0), ng)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> [Vec3; 3] {
        [Vec3::ZERO, Vec3::X, Vec3::Y]
    }

    #[test]
    fn a_flat_shaded_triangle_is_not_lifted() {
        let n = [Vec3::Z; 3];
        for b in [[1.0, 0.0, 0.0], [0.2, 0.3, 0.5], [1.0 / 3.0; 3]] {
            assert_eq!(smooth_surface_lift(&tri(), &n, b, Vec3::Z), Vec3::ZERO);
        }
    }

    #[test]
    fn the_lift_is_zero_at_the_corners_and_follows_outward_leaning_normals() {
        // corner normals leaning outwards (a convex, sphere-like patch): the smooth surface
        // bulges above the flat triangle, most inside it
        let centre = Vec3::new(1.0 / 3.0, 1.0 / 3.0, -1.0);
        let n = tri().map(|v| (v - centre).normalize());
        for b in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
            assert!(smooth_surface_lift(&tri(), &n, b, Vec3::Z).length() < 1e-6);
        }
        let mid = smooth_surface_lift(&tri(), &n, [1.0 / 3.0; 3], Vec3::Z);
        let edge = smooth_surface_lift(&tri(), &n, [0.5, 0.5, 0.0], Vec3::Z);
        assert!(mid.z > edge.z && edge.z > 0.0, "{mid} {edge}");
        // the same surface seen from below: the lift goes down, by the same height
        let below = smooth_surface_lift(&tri(), &n.map(|x| -x), [1.0 / 3.0; 3], -Vec3::Z);
        assert!(below.z < 0.0);
        // the parabola's height matches the sphere's sagitta to first order: for normals
        // leaning by θ over a triangle of size ~1, a height of order θ/4
        assert!(mid.z > 0.01 && mid.z < 0.5, "{mid}");
    }

    #[test]
    fn the_amount_is_full_at_grazing_light_and_none_at_steep_light() {
        let (ns, ng) = (Vec3::Z, Vec3::Z);
        let steep = Vec3::new(0.0, 0.6, 0.8);
        assert_eq!(lift_amount(ns, ng, steep, 0.1).0, 0.0);
        let grazing = Vec3::new(0.0, (1.0f32 - 0.05 * 0.05).sqrt(), 0.05);
        assert_eq!(lift_amount(ns, ng, grazing, 0.1).0, 1.0);
        // fading out (with the two normals equal, between half the cutoff and the cutoff)
        let l = Vec3::new(0.0, (1.0f32 - 0.075 * 0.075).sqrt(), 0.075);
        assert!((lift_amount(ns, ng, l, 0.1).0 - 0.5).abs() < 1e-5);
        // no offset at all: never lifted
        assert_eq!(lift_amount(ns, ng, grazing, 0.0).0, 0.0);
        // a light behind the shading normal: the lift heads to the other side
        assert_eq!(lift_amount(ns, ng, -grazing, 0.1).1, -Vec3::Z);
    }
}
