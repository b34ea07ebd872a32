//! Emission sampling: where a light subpath starts and in which direction it leaves
//! (Veach 1997 §10.2; pbrt-v3 `Light::Sample_Le` / `Pdf_Le`), for every light kind the scene
//! holds, and the densities bidirectional MIS needs of a light point found another way.
//!
//! A light is chosen in proportion to its estimated power (`Light::power_estimate`; lights
//! whose Cast Shadow is off are left out: their light passes through surfaces, which a
//! light subpath cannot follow — camera paths and light samples find them). Then:
//! * emissive triangles: a uniform point, a cosine-weighted direction on either side (they
//!   emit from both), density |cos|/(2π);
//! * area lights (rectangle, square, disc, ellipse): a uniform point, a cosine-weighted
//!   direction on the emitting side (the Spread is part of the radiance, as for light samples);
//! * sphere lights (point and spot with a radius): a uniform point of the sphere, a
//!   cosine-weighted direction around its normal;
//! * point and spot lights without radius: a delta position, a uniform direction (inside a
//!   round spot's cone when there is one);
//! * the sun and the world: a direction towards the light (the sun's cone, or the world's
//!   importance map), then a uniform point of a disc of the scene's bounding radius that
//!   faces it, outside the scene.
//!
//! The radiance a light subpath carries is not taken here: the first surface it meets asks
//! `Scene::light_eval` from there, so Cycles' receiver-dependent terms (the soft falloff of
//! sphere lights, a spot's blur by the ray's own direction, textured emission) are exactly
//! those a light sample from that surface sees.

use super::light::LightShape;
use super::Scene;
use crate::distribution::Distribution1D;
use crate::math::{square_to_cosine_hemisphere, square_to_disk_concentric, square_to_triangle};
use crate::math::{square_to_uniform_cone, square_to_uniform_sphere, Frame};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Chooses the light a light subpath starts from, ∝ estimated power (index `lights.len()` is
/// the world).
#[derive(Clone, Debug)]
pub struct EmitterSelection {
    dist: Distribution1D,
}

impl EmitterSelection {
    pub fn is_empty(&self) -> bool {
        self.dist.is_empty()
    }
    #[inline]
    pub fn pmf(&self, li: u32) -> f32 {
        self.dist.pmf(li as usize)
    }
}

/// The start of a light subpath.
#[derive(Clone, Copy, Debug)]
pub struct LightOrigin {
    pub light: u32,
    /// The point on the light; for the sun and the world, the point on the disc outside the
    /// scene the ray starts from.
    pub p: Vec3,
    /// The light's surface normal at `p` (zero for point lights, the sun and the world).
    pub n: Vec3,
    /// The unit direction the light leaves in.
    pub dir: Vec3,
    /// Selection × the density of the origin: of the point (area) for lights at a finite
    /// distance — 1 for a point light's delta position —, of the direction (solid angle) for
    /// the sun and the world — 1 for a sun without angle.
    pub pdf_origin: f32,
    /// The other half: the density of the direction (solid angle) for lights at a finite
    /// distance, of the point on the disc (area) for the sun and the world.
    pub pdf_emit: f32,
    /// No ray can hit the light: a point light, a sun without angle.
    pub delta: bool,
    pub infinite: bool,
}

/// The density (solid angle) with which `origin_direction` leaves a point of triangle or area
/// light shapes: cosine-weighted, one-sided or two-sided.
#[inline]
fn cosine_pdf(n: Vec3, dir: Vec3, two_sided: bool) -> f32 {
    let c = n.dot(dir);
    if two_sided {
        c.abs() / (2.0 * PI)
    } else {
        c.max(0.0) / PI
    }
}

impl Scene {
    /// The light choice of light subpaths (module comment).
    pub fn emitter_selection(&self) -> EmitterSelection {
        let r = self.disc_radius();
        let mut w: Vec<f32> = self
            .lights
            .iter()
            .map(|l| {
                if !l.cast_shadow {
                    return 0.0;
                }
                let area = match l.shape {
                    LightShape::Triangle { area, .. } => area,
                    _ => 0.0,
                };
                l.power_estimate(r, area)
            })
            .collect();
        // the world: radiance through the disc from every direction
        w.push(if self.env.is_black() { 0.0 } else { self.env.mean_radiance() * 4.0 * PI * PI * r * r });
        EmitterSelection { dist: Distribution1D::new(&w) }
    }

    /// The radius of the disc distant lights start from: the scene's bounds, with a margin.
    #[inline]
    pub fn disc_radius(&self) -> f32 {
        self.bounds_radius * 1.01
    }

    /// The start of a light subpath from samples `u_select`, `u_pos`, `u_dir`.
    pub fn sample_light_origin(
        &self,
        sel: &EmitterSelection,
        u_select: f32,
        u_pos: Vec2,
        u_dir: Vec2,
    ) -> Option<LightOrigin> {
        let (li, pmf) = sel.dist.sample(u_select)?;
        if li == self.lights.len() {
            let (wi, _, pdf_dir) = self.env.sample(&self.textures, u_dir)?;
            return self.disc_origin(li as u32, wi, pmf * pdf_dir, false, u_pos);
        }
        let light = &self.lights[li];
        let o = match &light.shape {
            LightShape::Triangle { prim, area } => {
                let t = *prim as usize;
                let v = &self.positions[t];
                let (b1, b2) = square_to_triangle(u_pos);
                let p = v[0] * (1.0 - b1 - b2) + v[1] * b1 + v[2] * b2;
                let n = self.geo_normal(t);
                // the side from the first sample's half, then a cosine-weighted direction
                let (side, ux) = if u_dir.x < 0.5 { (n, 2.0 * u_dir.x) } else { (-n, 2.0 * u_dir.x - 1.0) };
                let dir = Frame::from_normal(side).to_world(square_to_cosine_hemisphere(Vec2::new(ux, u_dir.y)));
                LightOrigin {
                    light: li as u32,
                    p,
                    n,
                    dir,
                    pdf_origin: pmf / area,
                    pdf_emit: cosine_pdf(n, dir, true),
                    delta: false,
                    infinite: false,
                }
            }
            LightShape::Planar { center, axis_u, axis_v, normal, disk, area, .. } => {
                let q = if *disk { square_to_disk_concentric(u_pos) } else { u_pos * 2.0 - Vec2::ONE };
                let p = *center + *axis_u * q.x + *axis_v * q.y;
                let dir = Frame::from_normal(*normal).to_world(square_to_cosine_hemisphere(u_dir));
                LightOrigin {
                    light: li as u32,
                    p,
                    n: *normal,
                    dir,
                    pdf_origin: pmf / area,
                    pdf_emit: cosine_pdf(*normal, dir, false),
                    delta: false,
                    infinite: false,
                }
            }
            LightShape::Sphere { center, radius, spot, .. } => {
                if *radius > 0.0 {
                    let n = square_to_uniform_sphere(u_pos);
                    let dir = Frame::from_normal(n).to_world(square_to_cosine_hemisphere(u_dir));
                    LightOrigin {
                        light: li as u32,
                        p: *center + n * *radius,
                        n,
                        dir,
                        pdf_origin: pmf / (4.0 * PI * radius * radius),
                        pdf_emit: cosine_pdf(n, dir, false),
                        delta: false,
                        infinite: false,
                    }
                } else {
                    let (dir, pdf) = match spot.filter(|s| s.to_local.is_none() && s.cos_half > -1.0) {
                        Some(s) => (
                            Frame::from_normal(s.dir).to_world(square_to_uniform_cone(u_dir, s.cos_half)),
                            1.0 / (2.0 * PI * (1.0 - s.cos_half)),
                        ),
                        None => (square_to_uniform_sphere(u_dir), 1.0 / (4.0 * PI)),
                    };
                    LightOrigin {
                        light: li as u32,
                        p: *center,
                        n: Vec3::ZERO,
                        dir,
                        pdf_origin: pmf,
                        pdf_emit: pdf,
                        delta: true,
                        infinite: false,
                    }
                }
            }
            LightShape::Distant { dir, cos_half, frame } => {
                if *cos_half >= 1.0 {
                    return self.disc_origin(li as u32, *dir, pmf, true, u_pos);
                }
                let wi = frame.to_world(square_to_uniform_cone(u_dir, *cos_half)).normalize();
                return self.disc_origin(li as u32, wi, pmf / (2.0 * PI * (1.0 - cos_half)), false, u_pos);
            }
        };
        (o.pdf_origin > 0.0 && o.pdf_emit > 0.0 && o.pdf_origin.is_finite()).then_some(o)
    }

    /// A distant light's origin: towards `wi` (unit, pointing at the light), a point of the
    /// disc facing it outside the scene; the ray leaves along −wi.
    fn disc_origin(&self, li: u32, wi: Vec3, pdf_origin: f32, delta: bool, u: Vec2) -> Option<LightOrigin> {
        let r = self.disc_radius();
        let f = Frame::from_normal(wi);
        let q = square_to_disk_concentric(u) * r;
        let p = self.bounds_center + wi * r + f.s * q.x + f.t * q.y;
        (pdf_origin > 0.0 && pdf_origin.is_finite()).then_some(LightOrigin {
            light: li,
            p,
            n: Vec3::ZERO,
            dir: -wi,
            pdf_origin,
            pdf_emit: 1.0 / (PI * r * r),
            delta,
            infinite: true,
        })
    }

    /// `LightOrigin::pdf_origin` of light `li`'s point `z` (for the sun and the world: `z` is
    /// the unit direction towards the light) found by a camera path or a light sample.
    pub fn light_origin_pdf(&self, sel: &EmitterSelection, li: u32, z: Vec3) -> f32 {
        let pmf = sel.pmf(li);
        if pmf <= 0.0 {
            return 0.0;
        }
        if li == self.env_light() {
            return pmf * self.env.pdf(z);
        }
        match &self.lights[li as usize].shape {
            LightShape::Triangle { area, .. } => pmf / area,
            LightShape::Planar { area, .. } => pmf / area,
            LightShape::Sphere { radius, .. } if *radius > 0.0 => pmf / (4.0 * PI * radius * radius),
            LightShape::Sphere { .. } => pmf,
            LightShape::Distant { cos_half, .. } if *cos_half >= 1.0 => pmf,
            LightShape::Distant { cos_half, .. } => pmf / (2.0 * PI * (1.0 - cos_half)),
        }
    }

    /// `LightOrigin::pdf_emit` of light `li` leaving its point `z` (normal `n`) in the unit
    /// direction `dir`; for the sun and the world the disc's density.
    pub fn light_emit_pdf(&self, li: u32, n: Vec3, dir: Vec3) -> f32 {
        if li == self.env_light() {
            return 1.0 / (PI * self.disc_radius().powi(2));
        }
        match &self.lights[li as usize].shape {
            LightShape::Triangle { .. } => cosine_pdf(n, dir, true),
            LightShape::Planar { normal, .. } => cosine_pdf(*normal, dir, false),
            LightShape::Sphere { radius, .. } if *radius > 0.0 => cosine_pdf(n, dir, false),
            LightShape::Sphere { spot, .. } => match spot.filter(|s| s.to_local.is_none() && s.cos_half > -1.0) {
                Some(s) if dir.dot(s.dir) >= s.cos_half => 1.0 / (2.0 * PI * (1.0 - s.cos_half)),
                Some(_) => 0.0,
                None => 1.0 / (4.0 * PI),
            },
            LightShape::Distant { .. } => 1.0 / (PI * self.disc_radius().powi(2)),
        }
    }

    /// True when no ray can hit light `li` (a point light, a sun without angle).
    pub fn is_delta_light(&self, li: u32) -> bool {
        self.lights.get(li as usize).is_some_and(|l| l.is_delta())
    }

    /// True when light `li` is at infinity (the sun, the world).
    pub fn is_infinite_light(&self, li: u32) -> bool {
        li == self.env_light() || matches!(self.lights[li as usize].shape, LightShape::Distant { .. })
    }

    /// The triangle is hidden from camera rays (its object's Camera ray visibility is off).
    #[inline]
    pub fn camera_invisible(&self, prim: u32) -> bool {
        self.masked(prim, super::RAY_CAMERA_INVISIBLE)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};
    use crate::scene::builtin;

    /// Every light kind's origin has the densities `light_origin_pdf` and `light_emit_pdf`
    /// give the same point and direction (MIS meets a light point from both sides), and the
    /// direction leaves the emitting side.
    #[test]
    fn origin_densities_agree_with_their_evaluation() {
        let scene = Scene::build(&builtin::cornell_mixed_lights(16, 16)).unwrap();
        let sel = scene.emitter_selection();
        let mut s = IndependentSampler::new(3, 1);
        let mut seen = std::collections::HashSet::new();
        for _ in 0..4000 {
            let Some(o) = scene.sample_light_origin(&sel, s.next_1d(), s.next_2d(), s.next_2d()) else { continue };
            seen.insert(o.light);
            let z = if o.infinite { -o.dir } else { o.p };
            let po = scene.light_origin_pdf(&sel, o.light, z);
            assert!((po - o.pdf_origin).abs() <= 1e-3 * po, "light {}: origin {po} vs {}", o.light, o.pdf_origin);
            let pe = scene.light_emit_pdf(o.light, o.n, o.dir);
            assert!((pe - o.pdf_emit).abs() <= 1e-3 * pe, "light {}: emit {pe} vs {}", o.light, o.pdf_emit);
            if o.n != Vec3::ZERO && !scene.is_triangle_light(o.light) {
                assert!(o.n.dot(o.dir) > 0.0);
            }
            assert_eq!(o.infinite, scene.is_infinite_light(o.light));
        }
        assert!(seen.len() >= 3, "lights sampled: {seen:?}");
    }
}
