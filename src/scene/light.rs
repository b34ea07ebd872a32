//! Lights with Cycles' radiometric conventions (docs/blender.md, "Radiance conventions of Cycles"), their
//! sampling for next-event estimation, and their intersection by BSDF-sampled rays.
//!
//! Analytic lights are transparent: they never occlude, a ray that crosses one picks up its
//! emission and continues (as in Cycles). Emissive triangles are lights too (two-sided).

use super::desc::{AreaShape, LightDesc};
use crate::error::SceneError;
use crate::math::{luminance, square_to_disk_concentric, square_to_uniform_cone, Frame, Spectrum};
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;

#[derive(Clone, Debug)]
pub enum LightShape {
    /// Sphere (radius > 0) or point (radius 0) with optional spot cone.
    /// `soft_falloff`: Cycles' default for point and spot lights since 4.0, which shades
    /// the sphere like a disc of radius r facing the shading point: irradiance
    /// π·L·r²/(d²+r²) instead of the sphere's π·L·r²/d² (measured against Cycles 5.0 on
    /// axis). Implemented as the factor d²/(d²+r²) on the sphere's radiance, applied
    /// identically to light samples and to rays that hit the sphere, so MIS stays exact.
    Sphere { center: Vec3, radius: f32, spot: Option<Spot>, soft_falloff: bool },
    /// Planar emitter: centre, half-axes (world, carrying scale), normal = emitting side;
    /// `spread` narrows its emission (None: Lambertian).
    Planar { center: Vec3, axis_u: Vec3, axis_v: Vec3, normal: Vec3, disk: bool, area: f32, spread: Option<Spread> },
    /// Distant light towards `dir` (unit, pointing at the light); `cos_half` of its cone.
    Distant { dir: Vec3, cos_half: f32, frame: Frame },
    /// Emissive triangle `prim` of the scene mesh.
    Triangle { prim: u32, area: f32 },
}

/// Blender's area light Spread, as Cycles models it: a soft box whose grid of slats lets
/// through the fraction max(0, 1 − tan θ / tan h) of the light leaving at angle θ from the
/// normal (h = half the spread), renormalised so that the light's power is unchanged:
/// radiance × N·max(0, tan h − tan θ) with N = 1/(tan h − h), since
/// ∫ (tan h − tan θ) cos θ dω over θ < h = π(tan h − h). (Small h: N → 3/h³, used below
/// 0.05 rad where tan h − h loses its digits.) The light is sampled by area as before: the
/// factor is part of the radiance, identical for light samples and for rays that hit it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spread {
    pub tan_half: f32,
    pub normalize: f32,
}

impl Spread {
    /// None for a spread of π or more (Lambertian); below a hundredth of a degree the cone
    /// is held there (Cycles' zero spread is a delta beam, which no area sample can meet).
    pub fn new(spread: f32) -> Option<Spread> {
        let h = (spread.min(PI) * 0.5).max(1e-4) as f64;
        if h >= std::f64::consts::FRAC_PI_2 - 1e-6 {
            return None;
        }
        let t = h.tan();
        let normalize = if h > 0.05 { 1.0 / (t - h) } else { 3.0 / (h * h * h) };
        Some(Spread { tan_half: t as f32, normalize: normalize as f32 })
    }

    /// The factor on the radiance leaving at cos θ from the normal (cos θ > 0).
    #[inline]
    pub fn attenuation(&self, cos_theta: f32) -> f32 {
        let tan = (1.0 - cos_theta * cos_theta).max(0.0).sqrt() / cos_theta;
        ((self.tan_half - tan) * self.normalize).max(0.0)
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Spot {
    pub dir: Vec3,
    pub cos_half: f32,
    pub smooth: f32,
    /// For a light object of uneven scale: world direction → the object's scaled frame with
    /// z along the spot (the cone is round there, as in Cycles, so elliptical in the world).
    /// None: round around `dir`.
    pub to_local: Option<Mat3>,
    /// The widest angle between `dir` and a direction inside the cone (the light tree's θ_o).
    pub theta_o: f32,
}

impl Spot {
    /// A spot of full angle `size` and blend around `dir` (unit), shaped by the object's
    /// 3×3 matrix `m` (its axes as columns, scale included) when that scales unevenly.
    pub fn new(dir: Vec3, size: f32, blend: f32, m: Option<Mat3>) -> Spot {
        let cos_half = (size.clamp(0.0, PI) * 0.5).cos();
        let smooth = (1.0 - cos_half) * blend.clamp(0.0, 1.0);
        let round = Spot { dir, cos_half, smooth, to_local: None, theta_o: cos_half.clamp(-1.0, 1.0).acos() };
        let Some(m) = m else { return round };
        let (x, y, z) = (m.x_axis.length(), m.y_axis.length(), m.z_axis.length());
        let even = (x - z).abs() <= 1e-5 * z && (y - z).abs() <= 1e-5 * z;
        let orthogonal = [m.x_axis.dot(m.y_axis), m.y_axis.dot(m.z_axis), m.z_axis.dot(m.x_axis)]
            .iter()
            .all(|d| d.abs() <= 1e-5 * (x * y).max(y * z).max(z * x));
        if (even && orthogonal) || m.determinant().abs() < 1e-30 {
            return round;
        }
        // local = diag(1, 1, −1)·M⁻¹·d: the object frame, its −z (where the spot points) as +z
        let to_local = Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0)) * m.inverse();
        // θ_o: the cone's edge (round in the local frame) taken to the world, widest angle
        let (sin_h, cos_h) = ((1.0 - cos_half * cos_half).max(0.0).sqrt(), cos_half);
        let theta_o = (0..256)
            .map(|k| {
                let phi = 2.0 * PI * k as f32 / 256.0;
                let w = (m * Vec3::new(sin_h * phi.cos(), sin_h * phi.sin(), -cos_h)).normalize_or(dir);
                w.dot(dir).clamp(-1.0, 1.0).acos()
            })
            .fold(0.0f32, f32::max);
        // (the 256 edge directions miss the widest by at most a part in 10⁴; margin of 1%)
        Spot { to_local: Some(to_local), theta_o: (theta_o * 1.01 + 1e-3).min(PI), ..round }
    }

    /// The falloff of light leaving a spot of centre `center` and squared radius `r2`
    /// along the unit direction `d` towards `p`: as Cycles, by the direction of the ray itself
    /// (so a spot of some radius blurs its cone's edge by the sphere's angular size), and
    /// none at points inside the sphere — well inside (by 1% of the radius): a ray leaving a
    /// surface that touches the sphere starts a hair off it, where Cycles' starts on it.
    #[inline]
    pub fn along(&self, center: Vec3, r2: f32, p: Vec3, d: Vec3) -> f32 {
        if r2 > 0.0 && (p - center).length_squared() < 0.98 * r2 {
            return 1.0;
        }
        self.attenuation(d)
    }

    /// A falloff for choosing the light at `p`: positive wherever `along` can be for a ray
    /// from some point of the sphere (centre, squared radius r2) to p — the direction from the
    /// centre turned towards the axis by the sphere's angular radius, and a floor of 10⁻³
    /// inside the widest cone that angle can reach (an elliptical cone need not be entered
    /// along that turn) — so that light selection never leaves out a light that reaches p.
    pub fn bound(&self, center: Vec3, r2: f32, p: Vec3) -> f32 {
        let to = p - center;
        let d2 = to.length_squared();
        if r2 <= 0.0 {
            return self.attenuation(to.normalize_or_zero());
        }
        if d2 < 0.98 * r2 {
            return 1.0;
        }
        let t = to / d2.sqrt();
        let alpha = (r2 / d2).sqrt().min(1.0).asin();
        let theta = t.dot(self.dir).clamp(-1.0, 1.0).acos();
        let beta = alpha.min(theta);
        let turned = if theta > 1e-6 { (t * (theta - beta).sin() + self.dir * beta.sin()) / theta.sin() } else { t };
        let a = self.attenuation(turned.normalize_or(t));
        if a > 0.0 {
            a
        } else if theta <= self.theta_o + alpha {
            1e-3
        } else {
            0.0
        }
    }

    /// Cycles' spot falloff: smoothstep over the blend region of the cone.
    #[inline]
    pub fn attenuation(&self, to_point: Vec3) -> f32 {
        let c = match &self.to_local {
            None => to_point.dot(self.dir),
            Some(m) => (*m * to_point).normalize_or_zero().z,
        };
        if c <= self.cos_half {
            return 0.0;
        }
        if self.smooth <= 0.0 {
            return 1.0;
        }
        let t = ((c - self.cos_half) / self.smooth).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    }
}

#[derive(Clone, Debug)]
pub struct Light {
    pub name: String,
    pub shape: LightShape,
    /// Radiance of the surface; for a delta point light the intensity [W/sr]; for a delta
    /// sun the irradiance [W/m²].
    pub emission: Spectrum,
    pub visible_camera: bool,
    /// Its shadow rays are blocked by surfaces (Blender's Cast Shadow; off for fill lights).
    pub cast_shadow: bool,
}

/// A point chosen on a light for next-event estimation.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    pub p: Vec3,
    pub n: Vec3,
    /// Unit direction from the shading point to the light point.
    pub wi: Vec3,
    /// Distance to the light point (INFINITY for distant lights).
    pub dist: f32,
    /// Radiance arriving along `wi` (delta lights: intensity/d² or irradiance).
    pub radiance: Spectrum,
    /// Solid-angle pdf, light selection excluded (delta lights: 1).
    pub pdf: f32,
    pub is_delta: bool,
}

/// The warnings for a light's inputs that `Light::from_desc` reads in another way than
/// given: a negative area light size (its magnitude is used) and a spot cone outside 0…180°.
pub fn range_warnings(d: &LightDesc) -> Vec<String> {
    let mut out = Vec::new();
    match d {
        LightDesc::Area { name, size_x, size_y, shape, .. } => {
            let sizes: &[(&str, f32)] = match shape {
                AreaShape::Square | AreaShape::Disk => &[("size", *size_x)],
                _ => &[("size x", *size_x), ("size y", *size_y)],
            };
            for &(what, x) in sizes {
                if x.is_finite() && x < 0.0 {
                    out.push(format!("light '{name}': {what} {x} is negative; {} is used", -x));
                }
            }
        }
        LightDesc::Spot { name, spot_size, .. } if spot_size.is_finite() && !(0.0..=PI).contains(spot_size) => {
            out.push(format!(
                "light '{name}': spot size {:.1}° is outside 0…180°; {:.1}° is used",
                spot_size.to_degrees(),
                spot_size.clamp(0.0, PI).to_degrees()
            ));
        }
        _ => {}
    }
    out
}

impl Light {
    pub fn from_desc(d: &LightDesc) -> Result<Light, SceneError> {
        Ok(Light { cast_shadow: d.cast_shadow(), ..Self::shape_from_desc(d)? })
    }

    /// The light of `d`, checked, before its Cast Shadow setting.
    fn shape_from_desc(d: &LightDesc) -> Result<Light, SceneError> {
        let v = |a: [f32; 3]| Vec3::from_array(a);
        let check = |name: &str, ok: bool, what: &str| {
            if ok {
                Ok(())
            } else {
                Err(SceneError::Light { light: name.to_string(), what: what.to_string() })
            }
        };
        let finite3 = |a: &[f32; 3]| a.iter().all(|x| x.is_finite());
        // Cycles subtracts light for a negative strength; GDMLT's estimators (light selection
        // by power, Metropolis targets) need light ≥ 0, so it is refused, as negative emission is
        let (strength, name) = match d {
            LightDesc::Point { power, name, .. }
            | LightDesc::Spot { power, name, .. }
            | LightDesc::Area { power, name, .. } => (power, name),
            LightDesc::Sun { irradiance, name, .. } => (irradiance, name),
        };
        check(name, strength.iter().all(|x| !x.is_nan()), "NaN power (its strength or colour is not a number)")?;
        check(name, strength.iter().all(|&x| !(x < 0.0)), "negative power (GDMLT does not render negative light)")?;
        check(
            name,
            strength.iter().all(|&x| x <= super::material::MAX_RADIANCE),
            "power too large for single precision (an infinite strength in Blender is stored as 3.4e38)",
        )?;
        match d {
            LightDesc::Point { name, position, radius, power, soft_falloff, visible_camera, .. } => {
                check(
                    name,
                    finite3(position) && finite3(power) && radius.is_finite(),
                    "NaN or Inf in position, power or radius",
                )?;
                Ok(Self::sphere(name, v(*position), *radius, v(*power), None, *soft_falloff, *visible_camera))
            }
            LightDesc::Spot {
                name,
                position,
                direction,
                radius,
                power,
                spot_size,
                spot_blend,
                soft_falloff,
                visible_camera,
                matrix,
                ..
            } => {
                check(
                    name,
                    finite3(position) && finite3(direction) && finite3(power),
                    "NaN or Inf in position, direction or power",
                )?;
                check(name, v(*direction).length() > 0.0, "zero direction")?;
                check(name, spot_size.is_finite() && spot_blend.is_finite(), "NaN or Inf spot size or blend")?;
                let m = match matrix {
                    Some(m) => {
                        check(name, m.iter().flatten().all(|x| x.is_finite()), "NaN or Inf in its matrix")?;
                        Some(Mat3::from_cols_array_2d(&[0, 1, 2].map(|c| [m[0][c], m[1][c], m[2][c]])))
                    }
                    None => None,
                };
                let spot = Spot::new(v(*direction).normalize(), *spot_size, *spot_blend, m);
                Ok(Self::sphere(name, v(*position), *radius, v(*power), Some(spot), *soft_falloff, *visible_camera))
            }
            LightDesc::Area {
                name, to_world, shape, size_x, size_y, power, normalize, spread, visible_camera, ..
            } => {
                check(
                    name,
                    to_world.iter().flatten().all(|x| x.is_finite()) && finite3(power),
                    "NaN or Inf in matrix or power",
                )?;
                check(name, spread.is_finite() && *spread >= 0.0, "spread must be a finite angle ≥ 0")?;
                let m = super::camera::matrix_from_rows(to_world);
                let sy = match shape {
                    AreaShape::Square | AreaShape::Disk => *size_x,
                    _ => *size_y,
                };
                let axis_u = m.transform_vector3(Vec3::X) * (*size_x * 0.5);
                let axis_v = m.transform_vector3(Vec3::Y) * (sy * 0.5);
                let normal_raw = m.transform_vector3(Vec3::NEG_Z);
                let disk = matches!(shape, AreaShape::Disk | AreaShape::Ellipse);
                let area = 4.0 * axis_u.cross(axis_v).length() * if disk { PI / 4.0 } else { 1.0 };
                check(name, area > 0.0 && area.is_finite() && normal_raw.length() > 0.0, "zero area")?;
                // Emission towards local −Z; orient the normal consistently with the axes.
                let n_geo = axis_u.cross(axis_v).normalize();
                let normal = if n_geo.dot(normal_raw) >= 0.0 { n_geo } else { -n_geo };
                let radiance = if *normalize { v(*power) / (PI * area) } else { v(*power) / PI };
                Ok(Light {
                    name: name.clone(),
                    shape: LightShape::Planar {
                        center: m.transform_point3(Vec3::ZERO),
                        axis_u,
                        axis_v,
                        normal,
                        disk,
                        area,
                        spread: Spread::new(*spread),
                    },
                    emission: radiance,
                    visible_camera: *visible_camera,
                    cast_shadow: true,
                })
            }
            LightDesc::Sun { name, direction, irradiance, angle, visible_camera, .. } => {
                check(
                    name,
                    finite3(direction) && finite3(irradiance) && angle.is_finite(),
                    "NaN or Inf in direction, strength or angle",
                )?;
                check(name, v(*direction).length() > 0.0, "zero direction")?;
                let dir = v(*direction).normalize();
                let half = (angle * 0.5).clamp(0.0, PI * 0.5);
                let cos_half = half.cos();
                // A disc of radiance L and half-angle θ gives irradiance L·π·sin²θ at normal incidence.
                let emission = if half > 1e-4 { v(*irradiance) / (PI * half.sin().powi(2)) } else { v(*irradiance) };
                Ok(Light {
                    name: name.clone(),
                    shape: LightShape::Distant {
                        dir,
                        cos_half: if half > 1e-4 { cos_half } else { 1.0 },
                        frame: Frame::from_normal(dir),
                    },
                    emission,
                    visible_camera: *visible_camera,
                    cast_shadow: true,
                })
            }
        }
    }

    fn sphere(
        name: &str,
        center: Vec3,
        radius: f32,
        power: Vec3,
        spot: Option<Spot>,
        soft_falloff: bool,
        visible_camera: bool,
    ) -> Light {
        let radius = radius.max(0.0);
        // Point: intensity P/(4π). Sphere: radiance P/(4π·πr²) (uniform sphere emitter of power P).
        let emission = if radius > 0.0 { power / (4.0 * PI * PI * radius * radius) } else { power / (4.0 * PI) };
        Light {
            name: name.to_string(),
            shape: LightShape::Sphere { center, radius, spot, soft_falloff },
            emission,
            visible_camera,
            cast_shadow: true,
        }
    }

    /// True when no ray can hit the light (point, sun of angle 0).
    pub fn is_delta(&self) -> bool {
        match &self.shape {
            LightShape::Sphere { radius, .. } => *radius == 0.0,
            LightShape::Distant { cos_half, .. } => *cos_half >= 1.0,
            _ => false,
        }
    }

    /// Approximate emitted power, used only to choose lights for NEE.
    pub fn power_estimate(&self, scene_radius: f32, tri_area: f32) -> f32 {
        let l = luminance(self.emission).max(0.0);
        match &self.shape {
            LightShape::Sphere { radius, .. } => {
                if *radius > 0.0 {
                    l * 4.0 * PI * PI * radius * radius
                } else {
                    l * 4.0 * PI
                }
            }
            LightShape::Planar { area, .. } => l * PI * area,
            LightShape::Distant { cos_half, .. } => {
                let e = if *cos_half >= 1.0 { l } else { l * PI * (1.0 - cos_half * cos_half) };
                e * PI * scene_radius * scene_radius
            }
            LightShape::Triangle { .. } => l * 2.0 * PI * tri_area,
        }
    }
}

/// Cycles' soft falloff of sphere lights seen from `p`: d²/(d²+r²) (1 when off).
#[inline]
pub fn soft_falloff_factor(on: bool, p: Vec3, c: Vec3, r: f32) -> f32 {
    if !on {
        return 1.0;
    }
    let d2 = (c - p).length_squared();
    d2 / (d2 + r * r)
}

/// Samples a point on a sphere of radius r around c, visible from p: uniform in the cone of
/// directions subtended by the sphere (pbrt-v4 §6.2.4). Returns (point, normal, wi, dist, pdf).
pub fn sample_sphere_cone(p: Vec3, c: Vec3, r: f32, u: Vec2) -> Option<(Vec3, Vec3, Vec3, f32, f32)> {
    let to_c = c - p;
    let d2 = to_c.length_squared();
    if d2 <= r * r {
        return None; // inside the light
    }
    let d = d2.sqrt();
    let sin2_max = r * r / d2;
    let cos_max = (1.0 - sin2_max).max(0.0).sqrt();
    let frame = Frame::from_normal(to_c / d);
    let w_local = square_to_uniform_cone(u, cos_max);
    let wi = frame.to_world(w_local).normalize();
    let t = ray_sphere(p, wi, c, r)?;
    let pt = p + wi * t;
    let pdf = 1.0 / (2.0 * PI * (1.0 - cos_max).max(1e-12));
    Some((pt, (pt - c).normalize(), wi, t, pdf))
}

/// Solid-angle pdf of `sample_sphere_cone` (any direction inside the cone).
pub fn sphere_cone_pdf(p: Vec3, c: Vec3, r: f32) -> f32 {
    let d2 = (c - p).length_squared();
    if d2 <= r * r {
        return 0.0;
    }
    let cos_max = (1.0 - r * r / d2).max(0.0).sqrt();
    1.0 / (2.0 * PI * (1.0 - cos_max).max(1e-12))
}

/// Nearest positive intersection of a ray with a sphere.
pub fn ray_sphere(o: Vec3, d: Vec3, c: Vec3, r: f32) -> Option<f32> {
    let oc = o - c;
    let b = oc.dot(d);
    let cc = oc.length_squared() - r * r;
    let disc = b * b - cc;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    // numerically stable roots
    let q = -b - s.copysign(b);
    let (t0, t1) = if q != 0.0 { (cc / q, q) } else { (-b, -b) };
    let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
    if t0 > 0.0 {
        Some(t0)
    } else if t1 > 0.0 {
        Some(t1)
    } else {
        None
    }
}

/// Cycles' model of a point or spot light with Soft Falloff, seen from a point in a medium:
/// a disk of the light's radius facing that point (`kernel/light/point.h`, "ad-hoc radius
/// based on oriented disk"; `is_sphere` is off). Surfaces see the sphere with the soft
/// falloff d²/(d² + r²) (`soft_falloff_factor`: its far-field limit, which bidirectional light
/// subpaths can start from); in fog near the light the two differ (a point light of radius
/// 0.2 m in fog of density 0.12: the image 2% bright with the sphere, 2026-12-07), and fog
/// inside the sphere would be lit by nothing. (centre, radius, spot) of such a light.
#[derive(Clone, Copy, Debug)]
pub struct FacingDisk {
    center: Vec3,
    radius: f32,
    spot: Option<Spot>,
}

impl FacingDisk {
    /// The disk's normal: towards the point `from` it faces.
    #[inline]
    fn normal(&self, from: Vec3) -> Option<Vec3> {
        let n = (from - self.center).normalize_or_zero();
        (n != Vec3::ZERO).then_some(n)
    }

    /// The spot's falloff of light leaving along `dir` (towards the receiver).
    #[inline]
    fn attenuation(&self, dir: Vec3) -> f32 {
        self.spot.map_or(1.0, |s| s.attenuation(dir))
    }

    /// A point of the disk facing `p`, uniform in area: (point, normal, wi, dist, solid-angle
    /// pdf, falloff).
    pub fn sample(&self, p: Vec3, u: Vec2) -> Option<(Vec3, Vec3, Vec3, f32, f32, f32)> {
        let n = self.normal(p)?;
        let frame = Frame::from_normal(n);
        let q = square_to_disk_concentric(u) * self.radius;
        let lp = self.center + frame.s * q.x + frame.t * q.y;
        let to = lp - p;
        let d2 = to.length_squared();
        let dist = d2.sqrt();
        let wi = to / dist;
        let cos = -wi.dot(n);
        if !(cos > 0.0 && dist > 0.0) {
            return None;
        }
        Some((lp, n, wi, dist, d2 / (cos * PI * self.radius * self.radius), self.attenuation(-wi)))
    }

    /// The solid-angle pdf at `from` of disk point `z` (of the disk facing `from`), and the
    /// falloff of the light it sends there.
    pub fn eval(&self, from: Vec3, z: Vec3) -> Option<(f32, f32)> {
        let n = self.normal(from)?;
        let to = from - z;
        let d2 = to.length_squared();
        let cos = n.dot(to) / d2.sqrt();
        (cos > 0.0).then(|| (d2 / (cos * PI * self.radius * self.radius), self.attenuation(to / d2.sqrt())))
    }

    /// Where the ray (o, d) in [0, tmax) meets the disk facing `from` (a point on the ray's
    /// line before o, or o): t.
    pub fn intersect(&self, from: Vec3, o: Vec3, d: Vec3, tmax: f32) -> Option<f32> {
        let n = self.normal(from)?;
        let denom = d.dot(n);
        if denom >= 0.0 {
            return None;
        }
        let t = (self.center - o).dot(n) / denom;
        if !(t > 0.0 && t < tmax) {
            return None;
        }
        ((o + d * t - self.center).length_squared() <= self.radius * self.radius).then_some(t)
    }
}

impl Light {
    /// The disk a point in a medium sees this light as, if it is a sphere light with Soft
    /// Falloff (`FacingDisk`).
    #[inline]
    pub fn facing_disk(&self) -> Option<FacingDisk> {
        match self.shape {
            LightShape::Sphere { center, radius, spot, soft_falloff: true } if radius > 0.0 => {
                Some(FacingDisk { center, radius, spot })
            }
            _ => None,
        }
    }

    /// `sample` from a point in a medium: a soft-falloff sphere light as its facing disk.
    pub fn sample_from_medium(&self, p: Vec3, u: Vec2) -> Option<LightSample> {
        let Some(disk) = self.facing_disk() else { return self.sample(p, u) };
        let (lp, n, wi, dist, pdf, att) = disk.sample(p, u)?;
        (att > 0.0).then(|| LightSample { p: lp, n, wi, dist, radiance: self.emission * att, pdf, is_delta: false })
    }

    /// `intersect` for a segment whose light pdfs are taken at `from`, a point in a medium: a
    /// soft-falloff sphere light as the disk facing `from`.
    pub fn intersect_from_medium(&self, from: Vec3, o: Vec3, d: Vec3, tmax: f32) -> Option<(f32, Spectrum, f32)> {
        let Some(disk) = self.facing_disk() else { return self.intersect(o, d, tmax) };
        let t = disk.intersect(from, o, d, tmax)?;
        let (pdf, att) = disk.eval(from, o + d * t)?;
        (att > 0.0).then(|| (t, self.emission * att, pdf))
    }

    /// Sample a point for NEE from shading point `p` (non-triangle lights).
    pub fn sample(&self, p: Vec3, u: Vec2) -> Option<LightSample> {
        match &self.shape {
            LightShape::Sphere { center, radius, spot, soft_falloff } => {
                let (lp, n, wi, dist, pdf, radiance) = if *radius > 0.0 {
                    let (lp, n, wi, dist, pdf) = sample_sphere_cone(p, *center, *radius, u)?;
                    (lp, n, wi, dist, pdf, self.emission * soft_falloff_factor(*soft_falloff, p, *center, *radius))
                } else {
                    let to = *center - p;
                    let d2 = to.length_squared();
                    if d2 == 0.0 {
                        return None;
                    }
                    let dist = d2.sqrt();
                    (*center, -to / dist, to / dist, dist, 1.0, self.emission / d2)
                };
                let att = spot.map_or(1.0, |s| s.along(*center, radius * radius, p, -wi));
                if att <= 0.0 {
                    return None;
                }
                Some(LightSample { p: lp, n, wi, dist, radiance: radiance * att, pdf, is_delta: *radius == 0.0 })
            }
            LightShape::Planar { center, axis_u, axis_v, normal, disk, area, spread } => {
                let q = if *disk { square_to_disk_concentric(u) } else { u * 2.0 - Vec2::ONE };
                let lp = *center + *axis_u * q.x + *axis_v * q.y;
                let to = lp - p;
                let d2 = to.length_squared();
                if d2 == 0.0 {
                    return None;
                }
                let dist = d2.sqrt();
                let wi = to / dist;
                let cos_l = -wi.dot(*normal);
                if cos_l <= 0.0 {
                    return None; // behind the one-sided emitter
                }
                let att = spread.map_or(1.0, |s| s.attenuation(cos_l));
                if att <= 0.0 {
                    return None; // outside the spread's cone
                }
                Some(LightSample {
                    p: lp,
                    n: *normal,
                    wi,
                    dist,
                    radiance: self.emission * att,
                    pdf: d2 / (cos_l * area),
                    is_delta: false,
                })
            }
            LightShape::Distant { dir, cos_half, frame } => {
                if *cos_half >= 1.0 {
                    Some(LightSample {
                        p: p + *dir * 1e30,
                        n: -*dir,
                        wi: *dir,
                        dist: f32::INFINITY,
                        radiance: self.emission,
                        pdf: 1.0,
                        is_delta: true,
                    })
                } else {
                    let wi = frame.to_world(square_to_uniform_cone(u, *cos_half)).normalize();
                    let pdf = 1.0 / (2.0 * PI * (1.0 - cos_half));
                    Some(LightSample {
                        p: p + wi * 1e30,
                        n: -wi,
                        wi,
                        dist: f32::INFINITY,
                        radiance: self.emission,
                        pdf,
                        is_delta: false,
                    })
                }
            }
            LightShape::Triangle { .. } => None, // sampled by the scene, which owns the mesh
        }
    }

    /// If a ray (o, d) in [0, tmax) crosses this analytic light's emitting side, the distance
    /// and the radiance it carries back along −d, with the NEE solid-angle pdf of that point.
    pub fn intersect(&self, o: Vec3, d: Vec3, tmax: f32) -> Option<(f32, Spectrum, f32)> {
        match &self.shape {
            LightShape::Sphere { center, radius, spot, soft_falloff } => {
                if *radius <= 0.0 {
                    return None;
                }
                let t = ray_sphere(o, d, *center, *radius)?;
                if t >= tmax {
                    return None;
                }
                let att = spot.map_or(1.0, |s| s.along(*center, radius * radius, o, -d));
                if att <= 0.0 {
                    return None;
                }
                let soft = soft_falloff_factor(*soft_falloff, o, *center, *radius);
                Some((t, self.emission * (att * soft), sphere_cone_pdf(o, *center, *radius)))
            }
            LightShape::Planar { center, axis_u, axis_v, normal, disk, area, spread } => {
                let denom = d.dot(*normal);
                if denom >= 0.0 {
                    return None; // back side or parallel: lights are one-sided
                }
                let t = (*center - o).dot(*normal) / denom;
                if !(t > 0.0 && t < tmax) {
                    return None;
                }
                let hp = o + d * t - *center;
                let a = hp.dot(*axis_u) / axis_u.length_squared();
                let b = hp.dot(*axis_v) / axis_v.length_squared();
                let inside = if *disk { a * a + b * b <= 1.0 } else { a.abs() <= 1.0 && b.abs() <= 1.0 };
                if !inside {
                    return None;
                }
                let pdf = t * t / (-denom * area);
                Some((t, self.emission * spread.map_or(1.0, |s| s.attenuation(-denom)), pdf))
            }
            LightShape::Distant { dir, cos_half, .. } => {
                if *cos_half >= 1.0 || tmax < f32::INFINITY || d.dot(*dir) < *cos_half {
                    return None;
                }
                Some((f32::INFINITY, self.emission, 1.0 / (2.0 * PI * (1.0 - cos_half))))
            }
            LightShape::Triangle { .. } => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The disk a point in a medium sees a soft-falloff light as: its samples' pdf is what
    /// `eval` says of the same point, the ray along the sample meets the disk there, and the
    /// mean of 1/pdf is the disk's solid angle 2π(1 − d/√(d² + r²)) — also from a point closer
    /// to the centre than the radius (inside the sphere, which lights nothing there).
    #[test]
    fn the_facing_disk_samples_its_solid_angle() {
        use crate::sampler::{IndependentSampler, Sampler};
        let disk = FacingDisk { center: Vec3::new(0.3, -0.2, 1.0), radius: 0.4, spot: None };
        for p in [Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.5, -0.1, 1.2)] {
            let d = (p - disk.center).length();
            let want = 2.0 * PI as f64 * (1.0 - d as f64 / ((d * d + 0.16) as f64).sqrt());
            let mut s = IndependentSampler::new(4, 1);
            let n = 200_000;
            let mut sum = 0.0f64;
            for _ in 0..n {
                let (lp, _, wi, dist, pdf, att) = disk.sample(p, s.next_2d()).unwrap();
                assert_eq!(att, 1.0);
                let (pdf_eval, _) = disk.eval(p, lp).unwrap();
                assert!((pdf - pdf_eval).abs() <= 1e-3 * pdf, "{pdf} against {pdf_eval}");
                let t = disk.intersect(p, p, wi, f32::INFINITY).unwrap();
                assert!((t - dist).abs() <= 1e-4 * dist.max(1.0), "{t} against {dist}");
                sum += 1.0 / pdf as f64;
            }
            let got = sum / n as f64;
            assert!((got - want).abs() < 0.01 * want, "from {p}: solid angle {got} against {want}");
        }
    }

    #[test]
    fn sphere_cone_sampling_hits_the_sphere_with_its_pdf() {
        let c = Vec3::new(0.0, 0.0, 5.0);
        let mut s = crate::sampler::IndependentSampler::new(3, 0);
        use crate::sampler::Sampler;
        for _ in 0..1000 {
            let (pt, n, wi, dist, pdf) = sample_sphere_cone(Vec3::ZERO, c, 1.0, s.next_2d()).unwrap();
            assert!(((pt - c).length() - 1.0).abs() < 1e-4);
            assert!(n.dot(-wi) > -1e-4);
            assert!((pt.length() - dist).abs() < 1e-3);
            assert!((pdf - sphere_cone_pdf(Vec3::ZERO, c, 1.0)).abs() < 1e-3 * pdf);
        }
    }

    /// Issue 18: a light of negative power gave negative pixels (and a false "no light"
    /// warning); a NaN spot size dropped a third of the samples silently. Both are refused,
    /// naming the light.
    #[test]
    fn negative_power_and_nan_spot_size_are_refused_naming_the_light() {
        let area = LightDesc::Area {
            name: "Lamp.001".into(),
            to_world: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
            shape: AreaShape::Rectangle,
            size_x: 1.0,
            size_y: 1.0,
            power: [-10.0, 10.0, 10.0],
            normalize: true,
            spread: std::f32::consts::PI,
            visible_camera: false,
            cast_shadow: true,
        };
        let e = Light::from_desc(&area).expect_err("refused").to_string();
        assert!(e.contains("Lamp.001") && e.contains("negative"), "{e}");
        let sun = LightDesc::Sun {
            name: "Sun".into(),
            direction: [0.0, 0.0, -1.0],
            irradiance: [0.0, -1.0, 0.0],
            angle: 0.01,
            visible_camera: false,
            cast_shadow: true,
        };
        assert!(Light::from_desc(&sun).is_err());
        let spot = LightDesc::Spot {
            name: "Spot".into(),
            position: [0.0; 3],
            direction: [0.0, 0.0, -1.0],
            radius: 0.1,
            power: [10.0; 3],
            spot_size: f32::NAN,
            spot_blend: 0.1,
            soft_falloff: true,
            visible_camera: false,
            cast_shadow: true,
            matrix: None,
        };
        assert!(Light::from_desc(&spot).err().unwrap().to_string().contains("spot size"));
    }

    #[test]
    fn area_light_radiance_is_power_over_pi_area() {
        let d = LightDesc::Area {
            name: "a".into(),
            to_world: [[2.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 3.0], [0.0, 0.0, 0.0, 1.0]],
            shape: AreaShape::Rectangle,
            size_x: 1.0,
            size_y: 0.5,
            power: [10.0, 10.0, 10.0],
            normalize: true,
            spread: std::f32::consts::PI,
            visible_camera: false,
            cast_shadow: true,
        };
        let l = Light::from_desc(&d).unwrap();
        // world area = (1·2)·(0.5·1) = 1
        assert!((l.emission.x - 10.0 / PI).abs() < 1e-5);
        // it emits downwards: a ray going up from below hits it, a ray going down does not
        assert!(l.intersect(Vec3::ZERO, Vec3::Z, f32::INFINITY).is_some());
        assert!(l.intersect(Vec3::new(0.0, 0.0, 6.0), -Vec3::Z, f32::INFINITY).is_none());
    }

    /// Spread (Cycles' soft-box model) keeps the light's power: ∫ f(θ) cos θ dω = π over the
    /// hemisphere for spreads from 170° down to 0.5° (midpoint rule in θ, the integrand's kink
    /// at θ = h included), is 0 beyond half the spread, and is Lambertian (None) at 180°.
    #[test]
    fn spread_keeps_the_power_and_cuts_at_its_half_angle() {
        assert_eq!(Spread::new(PI), None);
        assert_eq!(Spread::new(4.0), None);
        for deg in [170.0f64, 120.0, 90.0, 45.0, 10.0, 5.73, 2.0, 0.5] {
            let spread = Spread::new(deg.to_radians() as f32).unwrap();
            let h = deg.to_radians() / 2.0;
            let n = 200_000;
            let integral: f64 = (0..n)
                .map(|k| {
                    let t = h * (k as f64 + 0.5) / n as f64; // f is 0 past h
                    spread.attenuation(t.cos() as f32) as f64 * t.cos() * t.sin() * 2.0 * std::f64::consts::PI * h
                        / n as f64
                })
                .sum();
            assert!((integral / std::f64::consts::PI - 1.0).abs() < 2e-3, "{deg}°: ∫ f cos dω = {integral}");
            assert_eq!(spread.attenuation((h + 1e-3).cos() as f32), 0.0, "{deg}°: light beyond the cone");
            assert!(spread.attenuation(1.0) > 1.0, "{deg}°: the axis is brighter than Lambertian");
        }
    }

    /// With a spread, a light sample and a ray that hits the same point carry the same
    /// radiance and pdf (MIS stays exact); light leaving outside the cone is dropped.
    #[test]
    fn spread_light_samples_and_hits_agree() {
        let d = LightDesc::Area {
            name: "Softbox".into(),
            to_world: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 2.0], [0.0, 0.0, 0.0, 1.0]],
            shape: AreaShape::Disk,
            size_x: 0.5,
            size_y: 0.5,
            power: [10.0, 10.0, 10.0],
            normalize: true,
            spread: 60f32.to_radians(),
            visible_camera: false,
            cast_shadow: true,
        };
        let l = Light::from_desc(&d).unwrap();
        let mut s = crate::sampler::IndependentSampler::new(5, 0);
        use crate::sampler::Sampler;
        let (mut inside, mut outside) = (0, 0);
        for k in 0..400 {
            // shading points on the floor 2 below the light, from its axis to 3 m off it
            let p = Vec3::new(3.0 * k as f32 / 400.0, 0.0, 0.0);
            match l.sample(p, s.next_2d()) {
                Some(ls) => {
                    // … and wholly outside it from x > 2·tan 30° + 0.25
                    assert!(p.x < 1.41, "{p}: a sample outside the cone");
                    inside += 1;
                    let (t, radiance, pdf) = l.intersect(p, ls.wi, f32::INFINITY).expect("the sampled point is hit");
                    assert!((t - ls.dist).abs() < 1e-4 * ls.dist);
                    assert!((radiance - ls.radiance).abs().max_element() < 1e-4 * ls.radiance.max_element());
                    assert!((pdf - ls.pdf).abs() < 1e-3 * ls.pdf, "pdf {pdf} vs {}", ls.pdf);
                    assert!(ls.radiance.max_element() > 0.0);
                }
                None => {
                    // the disk (radius 0.25, 2 above) is wholly inside the 30° cone seen from
                    // x < 2·tan 30° − 0.25
                    assert!(p.x > 0.9, "{p}: no sample inside the cone");
                    outside += 1;
                }
            }
        }
        assert!(inside > 50 && outside > 50, "{inside} inside the cone, {outside} outside");
    }

    /// A spot whose object is scaled unevenly has the cone Cycles gives it: round in the
    /// object's scaled frame, so an x scale of 2 widens it along x and a y scale of ½ narrows
    /// it along y (each checked against tan θ' = tan θ · s/s_z at the edge); an even scale
    /// keeps the round cone; every lit direction lies within θ_o (the light tree's bound).
    #[test]
    fn an_unevenly_scaled_spot_has_an_elliptical_cone() {
        let rot = Mat3::from_rotation_y(0.4) * Mat3::from_rotation_x(-0.3);
        let m = rot * Mat3::from_diagonal(Vec3::new(2.0, 0.5, 1.0));
        let dir = -(rot * Vec3::Z);
        let size = 60f32.to_radians();
        let spot = Spot::new(dir, size, 0.0, Some(m));
        assert!(spot.to_local.is_some());
        let half = 0.5 * size;
        let edge = |s: f32| (half.tan() * s).atan(); // the world half-angle along an axis scaled by s
        let tilt = |axis: Vec3, a: f32| (dir * a.cos() + rot * axis * a.sin()).normalize();
        for (axis, s) in [(Vec3::X, 2.0f32), (Vec3::Y, 0.5)] {
            assert_eq!(spot.attenuation(tilt(axis, edge(s) * 0.98)), 1.0, "inside along {axis}");
            assert_eq!(spot.attenuation(tilt(axis, edge(s) * 1.02)), 0.0, "outside along {axis}");
        }
        // wider than the round cone along x, narrower along y
        let round = Spot::new(dir, size, 0.0, None);
        assert_eq!(round.attenuation(tilt(Vec3::X, half * 1.2)), 0.0);
        assert_eq!(round.attenuation(tilt(Vec3::Y, half * 0.8)), 1.0);
        assert!((spot.theta_o - edge(2.0)).abs() < 0.02 && spot.theta_o >= edge(2.0), "{}", spot.theta_o);
        let mut s = crate::sampler::IndependentSampler::new(5, 0);
        use crate::sampler::Sampler;
        for _ in 0..20_000 {
            let d = crate::math::square_to_uniform_sphere(s.next_2d());
            if spot.attenuation(d) > 0.0 {
                assert!(d.dot(dir).clamp(-1.0, 1.0).acos() <= spot.theta_o, "{d}");
            }
        }
        // an even scale (and rotation) is the round cone, exactly
        let even = Spot::new(dir, size, 0.2, Some(rot * 3.0));
        assert!(even.to_local.is_none() && even.theta_o == Spot::new(dir, size, 0.2, None).theta_o);
    }

    /// A spot with a radius attenuates each ray by its own direction (Cycles), so light
    /// reaches a little beyond the cone through the centre; the light choice's `bound` is
    /// positive wherever any ray from the sphere carries light (round and elliptical cones).
    #[test]
    fn a_spot_with_a_radius_lights_by_each_rays_direction_and_is_never_left_out() {
        use crate::sampler::{IndependentSampler, Sampler};
        let dir = Vec3::new(0.2, 0.1, -1.0).normalize();
        let rot = Mat3::from_rotation_z(0.7) * Mat3::from_rotation_x(0.2);
        let (center, r) = (Vec3::new(0.3, -0.2, 1.0), 0.25f32);
        let mut s = IndependentSampler::new(7, 0);
        for m in [None, Some(rot * Mat3::from_diagonal(Vec3::new(2.5, 0.6, 1.0)))] {
            let axis = m.map_or(dir, |m| -(m * Vec3::Z).normalize());
            let spot = Spot::new(axis, 50f32.to_radians(), 0.2, m);
            let (mut beyond, mut lit) = (0, 0);
            for _ in 0..200_000 {
                let p = center + crate::math::square_to_uniform_sphere(s.next_2d()) * (0.3 + 2.0 * s.next_1d());
                let q = center + crate::math::square_to_uniform_sphere(s.next_2d()) * r; // a point of the sphere
                let a = spot.along(center, r * r, p, (p - q).normalize());
                if a > 0.0 {
                    lit += 1;
                    assert!(spot.bound(center, r * r, p) > 0.0, "{p}: lit ({a}) but never chosen");
                    if spot.attenuation((p - center).normalize()) == 0.0 {
                        beyond += 1;
                    }
                }
            }
            assert!(lit > 1000 && beyond > 100, "{lit} lit, {beyond} beyond the centre's cone");
        }
        // without a radius the ray's direction is the centre's
        let spot = Spot::new(dir, 0.8, 0.3, None);
        let p = Vec3::new(0.4, 0.0, -1.0);
        assert_eq!(spot.along(Vec3::ZERO, 0.0, p, p.normalize()), spot.attenuation(p.normalize()));
        assert_eq!(spot.bound(Vec3::ZERO, 0.0, p), spot.attenuation(p.normalize()));
    }
}
