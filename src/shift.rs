//! THE shift mapping (Kettunen et al. 2015; ALGORITHM.md §4): given a recorded base path
//! through one pixel, the offset path through a neighbouring pixel and the MIS-weighted
//! contributions of both, event by event.
//!
//! Offset path: the camera ray through the neighbour pixel at the same sub-pixel position
//! and lens sample (J = 1), hitting y0. When x0, x1 and y0 are all diffuse the offset
//! reconnects y0 → x1 (Jacobian |cos θ'_{x1}|·‖x0−x1‖² / (|cos θ_{x1}|·‖y0−x1‖²)) and is
//! identical to the base from x1 on; light events at x0 reconnect y0 to the same light point
//! (J = |cos θ'_z|·‖x0−z‖² / (|cos θ_z|·‖y0−z‖²), 1 for points and lights at infinity).
//! Specular vertices near the camera (half-vector copy) are not handled yet: such a shift is
//! treated as failed, which keeps the pair of estimators unbiased (the failure rule is
//! symmetric in x0 and y0) but gives those pixels no gradient variance reduction.
//!
//! Weights: balance heuristic over {base, offset} × {BSDF, light} strategies, every pdf
//! expressed in the base path's measure (the public GDPT code's rule). A failed offset gives
//! the base full weight and contributes zero — never a dropped sample.

use crate::bsdf::SPECULAR_ROUGHNESS_THRESHOLD;
use crate::math::{ray_epsilon, Spectrum};
use crate::path::{Event, Path, CAMERA_VERTEX};
use crate::scene::{Scene, SurfaceInteraction};
use glam::{Vec2, Vec3};

/// MIS-weighted contributions of one base/offset pair, summed over the base's events.
#[derive(Clone, Copy, Debug, Default)]
pub struct PairContribution {
    /// To the base pixel.
    pub base: Spectrum,
    /// To the neighbour pixel (already multiplied by the Jacobian).
    pub offset: Spectrum,
}

/// Jacobian of reconnecting to point `z` (normal `nz`) from `y` instead of `x` (solid angle
/// at the previous vertex → area at z → solid angle at the other vertex).
#[inline]
pub fn reconnection_jacobian(x: Vec3, y: Vec3, z: Vec3, nz: Vec3) -> f32 {
    let (dx, dy) = (x - z, y - z);
    let (lx2, ly2) = (dx.length_squared(), dy.length_squared());
    let cos_x = (dx.dot(nz) / lx2.sqrt()).abs();
    let cos_y = (dy.dot(nz) / ly2.sqrt()).abs();
    if cos_x <= 0.0 || ly2 <= 0.0 {
        return 0.0;
    }
    cos_y * lx2 / (cos_x * ly2)
}

#[inline]
fn is_diffuse(scene: &Scene, si_material: u32) -> bool {
    scene.materials[si_material as usize].bsdf(true).min_roughness() > SPECULAR_ROUGHNESS_THRESHOLD
}

/// Visibility from a surface point to a point (or, at infinity, along a direction).
fn visible(scene: &Scene, si: &SurfaceInteraction, z: Vec3, at_infinity: bool) -> bool {
    let (dir, tmax) = if at_infinity {
        (z, f32::INFINITY)
    } else {
        let to = z - si.p;
        let len = to.length();
        if len <= 0.0 {
            return false;
        }
        (to / len, len)
    };
    if dir.dot(si.ng) <= 0.0 {
        return false;
    }
    let o = si.spawn_origin(dir);
    let tmax = if at_infinity { tmax } else { (z - o).length() * (1.0 - 1e-4) - ray_epsilon(z) };
    tmax <= 0.0 || !scene.occluded(o, dir, 0.0, tmax)
}

/// Re-evaluates event `e` (whose last segment leaves x0) from the offset's first vertex y0.
/// Returns (offset numerator in the base's measure, offset pdf sum in the base's measure).
fn event_from_y0(scene: &Scene, e: &Event, x0: Vec3, y0: &SurfaceInteraction, wo_y: Vec3) -> Option<(Spectrum, f32)> {
    if !visible(scene, y0, e.z, e.at_infinity) {
        return None;
    }
    let dir = if e.at_infinity { e.z } else { (e.z - y0.p).normalize() };
    let (le, pdf_l) = if e.light == u32::MAX { (scene.world, 0.0) } else { scene.light_eval(e.light, y0.p, e.z)? };
    let bsdf = scene.materials[y0.material as usize].bsdf(y0.front);
    let wi = y0.frame.to_local(dir);
    let f = bsdf.eval(wo_y, wi);
    let pdf_b = if e.delta { 0.0 } else { bsdf.pdf(wo_y, wi) };
    let pdf_l = if e.pdf_l > 0.0 { pdf_l } else { 0.0 }; // same strategies as the base
    let j = if e.at_infinity || e.delta {
        1.0
    } else {
        let nz = if e.light == u32::MAX { Vec3::ZERO } else { scene.light_normal(e.light, e.z) };
        if nz == Vec3::ZERO {
            1.0
        } else {
            reconnection_jacobian(x0, y0.p, e.z, nz)
        }
    };
    if !(j > 0.0) || !j.is_finite() {
        return None;
    }
    // numerator: f·Le·J for both NEE and BSDF-hit events (the base's β at x0 is 1)
    Some((f * le * j, (pdf_b + pdf_l) * j))
}

/// The contributions of a base path and its offset through `offset_raster` (None when the
/// neighbour pixel is outside the image: the base then takes full weight).
pub fn shift(scene: &Scene, base: &Path, offset_raster: Option<Vec2>) -> PairContribution {
    let mut out = PairContribution::default();
    let gd_events = base.events.iter().filter(|e| e.vertex != CAMERA_VERTEX);
    let Some(x0v) = base.vertices.first() else { return out };

    // Offset's first vertex.
    let y0 = offset_raster.and_then(|r| {
        let ray = scene.camera.generate_ray(r, base.lens);
        let hit = scene.intersect(ray.origin, ray.dir, ray.tmin, ray.tmax)?;
        Some((scene.interaction(&hit, ray.dir), -ray.dir))
    });
    let y0 = y0.filter(|(y, _)| is_diffuse(scene, y.material) && is_diffuse(scene, x0v.material));
    let wo_y0 = y0.map(|(y, wo)| y.frame.to_local(wo));

    // Reconnection y0 → x1 for events at x1 and beyond.
    struct Connected {
        beta1: Spectrum, // offset throughput at x1 (base measure)
        r1: f32,         // offset/base prefix pdf ratio up to x1
        wo1: Vec3,       // offset's incoming direction at x1 (local)
        ratio2: Spectrum,
        r2: f32,
    }
    let connected = (|| {
        let (y0s, _) = y0?;
        let x1v = base.vertices.get(1)?;
        if !is_diffuse(scene, x1v.material) {
            return None;
        }
        let x1_si = SurfaceInteraction {
            p: x1v.p,
            ng: x1v.ng,
            frame: x1v.frame,
            prim: x1v.prim,
            material: x1v.material,
            t: 0.0,
            front: x1v.front,
        };
        if !visible(scene, &y0s, x1v.p, false) {
            return None;
        }
        let dir = (x1v.p - y0s.p).normalize();
        let bsdf_y0 = scene.materials[y0s.material as usize].bsdf(y0s.front);
        let wi = y0s.frame.to_local(dir);
        let wo = wo_y0?;
        let f = bsdf_y0.eval(wo, wi);
        let pdf_y = bsdf_y0.pdf(wo, wi);
        let j = reconnection_jacobian(x0v.p, y0s.p, x1v.p, x1v.ng);
        let pdf_x = x1v.pdf_in;
        if !(j > 0.0 && pdf_x > 0.0 && j.is_finite()) || (-dir).dot(x1v.ng) <= 0.0 {
            return None;
        }
        let beta1 = f * (j / pdf_x);
        let r1 = pdf_y * j / pdf_x;
        let wo1 = x1_si.frame.to_local(-dir);
        // At x1 the BSDF sees the offset's incoming direction; from x2 on all is shared.
        let (ratio2, r2) = match base.vertices.get(2) {
            Some(x2v) => {
                let bsdf1 = scene.materials[x1v.material as usize].bsdf(x1v.front);
                let w12 = x1v.frame.to_local(-x2v.wo);
                let wo_x1 = x1v.frame.to_local(x1v.wo);
                let fx = bsdf1.eval(wo_x1, w12);
                let fy = bsdf1.eval(wo1, w12);
                let b1x = x1v.throughput;
                let safe = |a: f32, b: f32| if b > 0.0 { a / b } else { 0.0 };
                let ratio = Spectrum::new(
                    safe(beta1.x * fy.x, b1x.x * fx.x),
                    safe(beta1.y * fy.y, b1x.y * fx.y),
                    safe(beta1.z * fy.z, b1x.z * fx.z),
                );
                (ratio, r1 * safe(bsdf1.pdf(wo1, w12), x2v.pdf_in))
            }
            None => (Spectrum::ZERO, 0.0),
        };
        Some(Connected { beta1, r1, wo1, ratio2, r2 })
    })();

    for e in gd_events {
        let pdf_x = e.pdf_b + e.pdf_l;
        if !(pdf_x > 0.0) {
            continue;
        }
        // (offset numerator, offset pdf sum), both in the base's measure
        let offset: Option<(Spectrum, f32)> = match e.vertex {
            0 => y0.and_then(|(y, _)| event_from_y0(scene, e, x0v.p, &y, wo_y0.unwrap_or(Vec3::Z))),
            1 => connected.as_ref().and_then(|c| {
                let x1v = &base.vertices[1];
                let bsdf1 = scene.materials[x1v.material as usize].bsdf(x1v.front);
                let dir = if e.at_infinity { e.z } else { (e.z - x1v.p).normalize() };
                let wi = x1v.frame.to_local(dir);
                let fy = bsdf1.eval(c.wo1, wi);
                let pdf_by = if e.delta { 0.0 } else { bsdf1.pdf(c.wo1, wi) };
                // base numerator = β_x(1)·f_x·Le (NEE) or β_x(2)·Le·p_b = β_x(1)·f_x·Le (hit)
                Some((c.beta1 * fy * e.le, c.r1 * (pdf_by + e.pdf_l)))
            }),
            _ => connected.as_ref().map(|c| (e.numerator * c.ratio2, c.r2 * pdf_x)),
        };
        let base_num = e.numerator;
        match offset {
            Some((num_y, pdf_y)) if pdf_y.is_finite() => {
                let denom = pdf_x + pdf_y;
                out.base += base_num / denom;
                out.offset += num_y / denom;
            }
            _ => out.base += base_num / pdf_x,
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reconnection Jacobian against a finite-difference estimate: the solid angle that a
    /// small patch around z subtends from y, divided by the one it subtends from x.
    #[test]
    fn reconnection_jacobian_matches_finite_differences() {
        let mut s = crate::sampler::IndependentSampler::new(5, 5);
        use crate::sampler::Sampler;
        let mut r = || Vec3::new(s.next_1d(), s.next_1d(), s.next_1d()) * 2.0 - Vec3::ONE;
        for _ in 0..200 {
            let (x, y, z) = (r() + Vec3::Z * 3.0, r() + Vec3::Z * 3.0, r() * 0.5);
            let nz = Vec3::Z;
            let frame = crate::math::Frame::from_normal(nz);
            let h = 1e-3f32;
            // solid angle of the patch [z, z+h·s, z+h·t] (as a parallelogram) from a point
            let solid = |p: Vec3| {
                let corners = [z, z + frame.s * h, z + frame.s * h + frame.t * h, z + frame.t * h];
                let d: Vec<Vec3> = corners.iter().map(|c| (*c - p).normalize()).collect();
                // two spherical triangles, area ≈ |(a×b)·c| / ... use planar approx for tiny patches
                ((d[1] - d[0]).cross(d[3] - d[0])).length()
            };
            let fd = solid(y) / solid(x);
            let j = reconnection_jacobian(x, y, z, nz);
            assert!((fd - j).abs() < 2e-2 * j.max(1e-3), "fd {fd} vs J {j}");
        }
    }
}
