//! Blender's camera framing, reproduced exactly (docs/blender.md, "Camera framing"): sensor fit, shift,
//! resolution percentage, pixel aspect, clipping, orthographic scale and thin-lens depth
//! of field (aperture radius = lens·1e-3 / (2·fstop), Cycles' convention).

use super::desc::{CameraDesc, Projection, SensorFit};
use crate::error::SceneError;
use crate::math::square_to_disk_concentric;
use glam::{Mat4, Vec2, Vec3, Vec4};

/// A camera ray; one with `tmax` 0 carries no light (`is_dead`: outside a fisheye's circle).
#[derive(Clone, Copy, Debug, Default)]
pub struct CameraRay {
    pub origin: Vec3,
    /// Unit direction.
    pub dir: Vec3,
    pub tmin: f32,
    pub tmax: f32,
}

impl CameraRay {
    /// The ray carries no light: the image has no view in this direction (Cycles' zero
    /// direction outside a fisheye's circle: the sample adds nothing).
    #[inline]
    pub fn is_dead(&self) -> bool {
        self.tmax <= 0.0
    }
}

#[derive(Clone, Debug)]
pub struct Camera {
    to_world: Mat4,
    /// Its inverse (world → camera), for light tracing's projections.
    to_camera: Mat4,
    projection: Projection,
    /// The rendered image (the render region when there is one).
    pub width: u32,
    pub height: u32,
    /// The full frame, and the region's top-left corner in it.
    full: Vec2,
    offset: Vec2,
    ext: Vec2,
    center: Vec2,
    clip_start: f32,
    clip_end: f32,
    aperture_radius: f32,
    focus_distance: f32,
    /// Polygonal aperture: corners (0 = round), rotation, and 1/anamorphic ratio.
    blades: u32,
    blade_rotation: f32,
    inv_aperture_ratio: f32,
    /// Where a pixel's samples fall (pixel_filter.rs).
    pub filter: crate::pixel_filter::PixelFilter,
    /// The world seen by camera rays is left out of the image (CameraDesc::film_transparent;
    /// also when a backdrop replaces it).
    pub film_transparent: bool,
    /// The radiance composited where camera rays leave the scene (`CameraDesc::backdrop`;
    /// None with a transparent film).
    pub backdrop: Option<crate::math::Spectrum>,
    /// An equirectangular camera's map from image coordinates (u, v) ∈ [0, 1]² (v up) to
    /// spherical angles, Cycles' range: φ = a·u + b, θ = c·v + d.
    equirect: Vec4,
    /// A fisheye camera's field of view (radians) and lens (mm; `ext` is then its sensor, mm).
    fisheye_fov: f32,
    fisheye_lens: f32,
}

fn mat_from_rows(m: &[[f32; 4]; 4]) -> Mat4 {
    Mat4::from_cols(
        Vec4::new(m[0][0], m[1][0], m[2][0], m[3][0]),
        Vec4::new(m[0][1], m[1][1], m[2][1], m[3][1]),
        Vec4::new(m[0][2], m[1][2], m[2][2], m[3][2]),
        Vec4::new(m[0][3], m[1][3], m[2][3], m[3][3]),
    )
}

pub(crate) fn matrix_from_rows(m: &[[f32; 4]; 4]) -> Mat4 {
    mat_from_rows(m)
}

/// The clipping range used: Clip Start ≥ 0; a Clip End before it read as the two swapped (a
/// range that clips everything would render a black frame), one equal to it or negative, and
/// NaN or Inf, as none.
fn clip_range(d: &CameraDesc) -> (f32, f32) {
    let start = if d.clip_start.is_finite() { d.clip_start.max(0.0) } else { 0.0 };
    let end = if d.clip_end.is_finite() { d.clip_end } else { f32::INFINITY };
    if end < start && end >= 0.0 {
        (end, start)
    } else if end <= start {
        (start, f32::INFINITY)
    } else {
        (start, end)
    }
}

/// The warnings for the camera's inputs read in another way than given (`clip_range`).
pub fn range_warnings(d: &CameraDesc) -> Vec<String> {
    let mut out = Vec::new();
    if d.clip_start.is_finite() && d.clip_start < 0.0 {
        out.push(format!("camera: clip start {} is negative; 0 is used", d.clip_start));
    }
    let (start, end) = clip_range(d);
    if d.clip_end.is_finite() && d.clip_end <= d.clip_start.max(0.0) {
        out.push(format!(
            "camera: clip start {} is not before clip end {} (everything would be clipped); {start} to {end} is used",
            d.clip_start, d.clip_end
        ));
    }
    out
}

impl Camera {
    pub fn new(d: &CameraDesc) -> Result<Camera, SceneError> {
        let err = |s: &str| Err(SceneError::Camera(s.to_string()));
        if d.to_world.iter().flatten().any(|x| !x.is_finite()) {
            return err("matrix has NaN or Inf");
        }
        if d.backdrop.is_some_and(|b| b.iter().any(|x| !x.is_finite() || *x < 0.0)) {
            return err("backdrop must be finite and ≥ 0");
        }
        let pct = d.resolution_percentage;
        // in u64: resolution × percentage overflows u32 for sizes a file can store
        let (width, height) = (d.resolution_x as u64 * pct as u64 / 100, d.resolution_y as u64 * pct as u64 / 100);
        if width == 0 || height == 0 {
            return Err(SceneError::Camera(format!(
                "image size is {width}×{height} pixels (resolution {}×{} at {pct}%): nothing to render",
                d.resolution_x, d.resolution_y
            )));
        }
        if width > 65536 || height > 65536 {
            return Err(SceneError::Camera(format!(
                "image size {width}×{height} pixels (resolution {}×{} at {pct}%) is larger than 65536 pixels on a side",
                d.resolution_x, d.resolution_y
            )));
        }
        let (width, height) = (width as u32, height as u32);
        if !(d.shift_x.is_finite() && d.shift_y.is_finite()) {
            return err("shift is NaN or Inf");
        }
        // Blender's f-stop field stops at 0.1 in its UI; far below it the lens opening is
        // kilometres wide and every pixel averages the whole scene: refuse what no lens is
        if d.fstop.is_nan() || (d.fstop > 0.0 && d.fstop < 1e-3) {
            return Err(SceneError::Camera(format!(
                "f-stop {} is not a lens (use 0 for no depth of field, or at least 0.001)",
                d.fstop
            )));
        }
        let positive = |x: f32| x.is_finite() && x > 0.0;
        if !positive(d.pixel_aspect_x) || !positive(d.pixel_aspect_y) {
            return err("pixel aspect must be positive");
        }
        let xr = width as f32 * d.pixel_aspect_x;
        let yr = height as f32 * d.pixel_aspect_y;
        let fit = match d.sensor_fit {
            SensorFit::Auto => {
                if xr >= yr {
                    SensorFit::Horizontal
                } else {
                    SensorFit::Vertical
                }
            }
            f => f,
        };
        let sensor = if d.sensor_fit == SensorFit::Vertical { d.sensor_height } else { d.sensor_width };
        if d.panorama.iter().any(|x| !x.is_finite()) || d.panorama[0] >= d.panorama[1] || d.panorama[2] >= d.panorama[3]
        {
            return err("panorama latitude and longitude ranges must be finite and not empty");
        }
        if matches!(d.projection, Projection::FisheyeEquidistant | Projection::FisheyeEquisolid)
            && !(positive(d.fisheye_fov) && positive(d.fisheye_lens) && positive(sensor))
        {
            return err("fisheye field of view, lens and sensor size must be positive");
        }
        let s = match d.projection {
            Projection::Equirectangular | Projection::FisheyeEquidistant => 1.0, // (the image spans angles)
            Projection::FisheyeEquisolid => sensor, // (ext: the sensor, mm, as its fit gives it)
            Projection::Perspective => {
                if !positive(d.lens) || !positive(sensor) {
                    return err("lens and sensor size must be positive");
                }
                sensor / d.lens
            }
            Projection::Orthographic => {
                if !positive(d.ortho_scale) {
                    return err("orthographic scale must be positive");
                }
                d.ortho_scale
            }
        };
        let ext = if fit == SensorFit::Horizontal { Vec2::new(s, s * yr / xr) } else { Vec2::new(s * xr / yr, s) };
        let center = Vec2::new(d.shift_x * s, d.shift_y * s);
        // Remove scale from the rotation part (Blender's normalized matrix).
        let m = mat_from_rows(&d.to_world);
        let (x, y, z) = (m.x_axis.truncate(), m.y_axis.truncate(), m.z_axis.truncate());
        if x.length() == 0.0 || y.length() == 0.0 || z.length() == 0.0 {
            return err("matrix is singular");
        }
        let to_world =
            Mat4::from_cols(x.normalize().extend(0.0), y.normalize().extend(0.0), z.normalize().extend(0.0), m.w_axis);
        let (clip_start, clip_end) = clip_range(d);
        let aperture_radius = if d.projection == Projection::Perspective && d.fstop > 0.0 && d.fstop.is_finite() {
            d.lens * 1e-3 / (2.0 * d.fstop)
        } else {
            0.0
        };
        let filter = if d.filter_width.is_finite() && (0.01..=10.0).contains(&d.filter_width) {
            crate::pixel_filter::PixelFilter::from_name(&d.pixel_filter, d.filter_width)
        } else {
            None
        }
        .ok_or_else(|| {
            SceneError::Camera(format!(
                "pixel filter '{}' of width {} (expected BLACKMAN_HARRIS or BOX, width 0.01 to 10 pixels)",
                d.pixel_filter, d.filter_width
            ))
        })?;
        let focus_distance =
            if d.focus_distance.is_finite() && d.focus_distance > 0.0 { d.focus_distance } else { 1.0 };
        let (offset, size) = match d.window {
            None => (Vec2::ZERO, (width, height)),
            Some([x, y, w, h]) => {
                if w == 0 || h == 0 || x.saturating_add(w) > width || y.saturating_add(h) > height {
                    return Err(SceneError::Camera(format!(
                        "render region {w}×{h} at ({x}, {y}) is empty or outside the {width}×{height} image"
                    )));
                }
                (Vec2::new(x as f32, y as f32), (w, h))
            }
        };
        Ok(Camera {
            to_world,
            to_camera: to_world.inverse(),
            projection: d.projection,
            width: size.0,
            height: size.1,
            full: Vec2::new(width as f32, height as f32),
            offset,
            ext,
            center,
            clip_start,
            clip_end,
            aperture_radius,
            focus_distance,
            blades: if d.aperture_blades >= 3 { d.aperture_blades.min(1024) } else { 0 },
            blade_rotation: if d.aperture_rotation.is_finite() { d.aperture_rotation } else { 0.0 },
            inv_aperture_ratio: if d.aperture_ratio.is_finite() && d.aperture_ratio > 0.0 {
                1.0 / d.aperture_ratio
            } else {
                1.0
            },
            filter,
            // a backdrop is what a transparent film leaves out, put back behind the image
            // (a textured backdrop is seen by the camera's rays instead: Scene::backdrop)
            film_transparent: d.film_transparent || (d.backdrop.is_some() && d.backdrop_texture.is_none()),
            backdrop: d.backdrop.filter(|_| !d.film_transparent && d.backdrop_texture.is_none()).map(Vec3::from_array),
            equirect: {
                let [lat_min, lat_max, lon_min, lon_max] = d.panorama;
                Vec4::new(lon_min - lon_max, -lon_min, lat_min - lat_max, std::f32::consts::FRAC_PI_2 - lat_min)
            },
            fisheye_fov: d.fisheye_fov,
            fisheye_lens: d.fisheye_lens,
        })
    }

    /// Depth of world point `p` as Cycles' Depth pass has it: its distance along the camera's
    /// viewing axis (camera-space z; not the ray length).
    pub fn axial_depth(&self, p: Vec3) -> f32 {
        if self.is_panoramic() {
            return (p - self.to_world.w_axis.truncate()).length(); // (a panorama has no axis)
        }
        let forward = -self.to_world.z_axis.truncate(); // a Blender camera looks down its −Z
        (p - self.to_world.w_axis.truncate()).dot(forward)
    }

    /// The raster position of pixel (x, y)'s sample `u` ∈ [0, 1)²: the pixel centre plus the
    /// filter's offset on each axis (every integrator takes its camera samples here).
    #[inline]
    pub fn pixel_raster(&self, x: f32, y: f32, u: Vec2) -> Vec2 {
        Vec2::new(x + 0.5 + self.filter.offset(u.x), y + 0.5 + self.filter.offset(u.y))
    }

    /// Point on the image plane (x, y at depth 1 for perspective) for a raster position
    /// with y measured from the top of the image (of the render region, if any).
    #[inline]
    fn plane_point(&self, raster: Vec2) -> Vec2 {
        let raster = raster + self.offset;
        let u = raster.x / self.full.x;
        let v = 1.0 - raster.y / self.full.y;
        Vec2::new(self.center.x + (u - 0.5) * self.ext.x, self.center.y + (v - 0.5) * self.ext.y)
    }

    /// A point of the unit aperture, uniform over its area, as Cycles samples it: the disk,
    /// or the regular polygon of `blades` corners inscribed in it (a corner's triangle chosen
    /// by u.x, a uniform point in it, turned by the rotation), its width divided by the
    /// anamorphic ratio.
    pub fn aperture_point(&self, u: Vec2) -> Vec2 {
        let mut p = if self.blades < 3 {
            square_to_disk_concentric(u)
        } else {
            let n = self.blades as f32;
            let corner = (u.x * n).floor().min(n - 1.0);
            let s = (u.x * n - corner).clamp(0.0, 1.0).sqrt();
            let (a, b) = (1.0 - s, u.y * s); // barycentrics of the two outer corners
            let half = std::f32::consts::PI / n;
            let q = Vec2::new((a + b) * half.cos(), (a - b) * half.sin());
            let (sin, cos) = (self.blade_rotation + corner * 2.0 * half).sin_cos();
            Vec2::new(cos * q.x - sin * q.y, sin * q.x + cos * q.y)
        };
        p.x *= self.inv_aperture_ratio;
        p
    }

    /// A panoramic camera (equirectangular or fisheye): no view plane, clipping along the ray.
    #[inline]
    pub fn is_panoramic(&self) -> bool {
        matches!(
            self.projection,
            Projection::Equirectangular | Projection::FisheyeEquidistant | Projection::FisheyeEquisolid
        )
    }

    /// The direction (camera space: −Z forward, +Y up) a panoramic camera sees at image
    /// coordinates (u, v) ∈ [0, 1]², v up, as Cycles maps them in its panorama frame (+X
    /// forward, +Z up), turned onto Blender's camera (forward −Z, up +Y, left −X); None
    /// outside a fisheye's circle, where the image receives no light.
    #[inline]
    fn panorama_direction(&self, u: f32, v: f32) -> Option<Vec3> {
        let d = match self.projection {
            Projection::Equirectangular => {
                let r = self.equirect;
                let (phi, theta) = (r.x * u + r.y, r.z * v + r.w);
                let (sin_t, cos_t) = theta.sin_cos();
                let (sin_p, cos_p) = phi.sin_cos();
                Vec3::new(sin_t * cos_p, sin_t * sin_p, cos_t)
            }
            // angle θ from the axis by the distance from the centre: r·fov/2 (equidistant, r
            // ∈ [0, 1] over the frame's half width and height), 2·asin(r/2f) (equisolid, r in
            // mm on the sensor); φ the direction around the axis
            _ => {
                let (x, y, theta) = if self.projection == Projection::FisheyeEquidistant {
                    let (x, y) = (2.0 * u - 1.0, 2.0 * v - 1.0);
                    let r = (x * x + y * y).sqrt();
                    if r > 1.0 {
                        return None;
                    }
                    (x, y, r * self.fisheye_fov * 0.5)
                } else {
                    let (x, y) = ((u - 0.5) * self.ext.x, (v - 0.5) * self.ext.y);
                    let r = (x * x + y * y).sqrt();
                    let theta = 2.0 * (r / (2.0 * self.fisheye_lens)).min(1.0).asin();
                    if theta > self.fisheye_fov * 0.5 || r > 2.0 * self.fisheye_lens {
                        return None;
                    }
                    (x, y, theta)
                };
                let r = (x * x + y * y).sqrt();
                let (cos_p, sin_p) = if r > 0.0 { (x / r, y / r) } else { (1.0, 0.0) };
                let (sin_t, cos_t) = theta.sin_cos();
                Vec3::new(cos_t, -cos_p * sin_t, sin_p * sin_t)
            }
        };
        Some(Vec3::new(-d.y, d.z, -d.x))
    }

    /// Primary ray through `raster` (pixels, origin top-left), lens sample `u_lens`. A
    /// panoramic camera's ray outside its image circle carries no light (`CameraRay::is_dead`).
    pub fn generate_ray(&self, raster: Vec2, u_lens: Vec2) -> CameraRay {
        if self.is_panoramic() {
            let raster = raster + self.offset;
            let origin = self.to_world.w_axis.truncate();
            let Some(d) = self.panorama_direction(raster.x / self.full.x, 1.0 - raster.y / self.full.y) else {
                return CameraRay { origin, dir: -self.to_world.z_axis.truncate(), tmin: 0.0, tmax: 0.0 };
            };
            let dir = self.to_world.transform_vector3(d).normalize();
            // (clipping along the ray: a panorama has no view axis)
            return CameraRay { origin, dir, tmin: self.clip_start, tmax: self.clip_end };
        }
        let q = self.plane_point(raster);
        let (o_cam, d_cam, axial) = match self.projection {
            Projection::Perspective => {
                let d = Vec3::new(q.x, q.y, -1.0);
                if self.aperture_radius > 0.0 {
                    let lens = self.aperture_point(u_lens) * self.aperture_radius;
                    let focus = d * self.focus_distance;
                    let o = Vec3::new(lens.x, lens.y, 0.0);
                    let dir = focus - o;
                    let len = dir.length();
                    (o, dir / len, -dir.z / len)
                } else {
                    // a pinhole: the direction is normalised once, in world space
                    // (the view-axis component of d is 1, so clip distances scale by |d|)
                    let len = d.length();
                    let dir = self.to_world.transform_vector3(d).normalize();
                    return CameraRay {
                        origin: self.to_world.w_axis.truncate(),
                        dir,
                        tmin: self.clip_start * len,
                        tmax: self.clip_end * len,
                    };
                }
            }
            Projection::Orthographic => (Vec3::new(q.x, q.y, 0.0), Vec3::NEG_Z, 1.0),
            _ => unreachable!("panoramas are handled above"),
        };
        // Clipping distances are measured along the view axis, as in Blender.
        let origin = self.to_world.transform_point3(o_cam);
        let dir = self.to_world.transform_vector3(d_cam).normalize();
        CameraRay { origin, dir, tmin: self.clip_start / axial, tmax: self.clip_end / axial }
    }

    /// Raster position (pixels, y from the top) of a world point, if in front of the camera.
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        let pc = self.to_world.inverse().transform_point3(p);
        if self.is_panoramic() {
            let d = pc.normalize_or_zero(); // (back to Cycles' panorama frame)
            let (x, y, z) = (-d.z, -d.x, d.y);
            let (u, v) = match self.projection {
                Projection::Equirectangular => {
                    let r = self.equirect;
                    // (the longitude's turn nearest the image's range: a range across ±π)
                    let period = (std::f32::consts::TAU / r.x).abs();
                    let mut u = (y.atan2(x) - r.y) / r.x;
                    for k in [-1.0, 1.0] {
                        let other = u + k * period;
                        let out = |u: f32| (-u).max(u - 1.0).max(0.0);
                        if out(other) < out(u) {
                            u = other;
                        }
                    }
                    (u, (z.clamp(-1.0, 1.0).acos() - r.w) / r.z)
                }
                _ => {
                    let theta = x.clamp(-1.0, 1.0).acos();
                    if theta > self.fisheye_fov * 0.5 {
                        return None;
                    }
                    let phi = z.atan2(-y);
                    let (r, size) = if self.projection == Projection::FisheyeEquidistant {
                        (theta / (self.fisheye_fov * 0.5), Vec2::splat(2.0))
                    } else {
                        (2.0 * self.fisheye_lens * (theta * 0.5).sin(), self.ext)
                    };
                    (r * phi.cos() / size.x + 0.5, r * phi.sin() / size.y + 0.5)
                }
            };
            return Some(Vec2::new(u * self.full.x, (1.0 - v) * self.full.y) - self.offset);
        }
        let depth = -pc.z;
        let q = match self.projection {
            Projection::Perspective => {
                if depth <= 0.0 {
                    return None;
                }
                Vec2::new(pc.x / depth, pc.y / depth)
            }
            Projection::Orthographic => Vec2::new(pc.x, pc.y),
            _ => unreachable!("panoramas are handled above"),
        };
        let u = (q.x - self.center.x) / self.ext.x + 0.5;
        let v = (q.y - self.center.y) / self.ext.y + 0.5;
        Some(Vec2::new(u * self.full.x, (1.0 - v) * self.full.y) - self.offset)
    }

    pub fn position(&self) -> Vec3 {
        self.to_world.w_axis.truncate()
    }

    /// An orthographic camera: its rays are parallel, from every point of its film, like a
    /// light at infinity's: a point joins it along the view axis (a delta direction), and
    /// densities at its vertex are per unit film area (no 1/d², as from a distant light).
    #[inline]
    pub fn parallel(&self) -> bool {
        self.projection == Projection::Orthographic
    }

    /// The camera's viewing direction (world; a panorama's image centre).
    pub fn forward(&self) -> Vec3 {
        -self.to_world.z_axis.truncate().normalize_or_zero()
    }

    /// A panorama's W towards the camera-space unit direction `d`: 1 / the solid angle of
    /// one pixel's directions there, the image's pixel count over dω/(du dv) of its mapping
    /// (u, v ∈ [0, 1]², `panorama_direction`):
    /// - equirectangular, φ = a·u + b, θ = c·v + e: dω = sin θ dθ dφ, so |a·c|·sin θ;
    /// - fisheye equidistant, θ = r·fov/2 over (x, y) = (2u − 1, 2v − 1) = r(cos φ, sin φ):
    ///   dω = sin θ dθ dφ = sin θ (fov/2)² dx dy / θ, so 4·(fov/2)²·sin θ/θ;
    /// - fisheye equisolid, r = 2f·sin(θ/2) over the sensor (x, y) = ((u − ½)·w, (v − ½)·h):
    ///   dr = f·cos(θ/2) dθ, so dω = r dr dφ / f² = dx dy / f² (the mapping keeps areas), w·h/f².
    ///
    /// Zero outside the image (a fisheye's circle) or at an equirectangular pole.
    fn panorama_density(&self, d: Vec3) -> f32 {
        let (x, z) = (-d.z, d.y); // (Cycles' panorama frame: +X forward, +Z up)
        let per_uv = match self.projection {
            Projection::Equirectangular => {
                let r = self.equirect;
                (r.x * r.z).abs() * (1.0 - z * z).max(0.0).sqrt()
            }
            Projection::FisheyeEquidistant => {
                let theta = x.clamp(-1.0, 1.0).acos();
                if theta > self.fisheye_fov * 0.5 {
                    return 0.0;
                }
                let h = self.fisheye_fov * 0.5;
                4.0 * h * h * if theta > 1e-4 { theta.sin() / theta } else { 1.0 }
            }
            _ => {
                if x.clamp(-1.0, 1.0).acos() > self.fisheye_fov * 0.5 {
                    return 0.0;
                }
                self.ext.x * self.ext.y / (self.fisheye_lens * self.fisheye_lens)
            }
        };
        if !(per_uv > 0.0) {
            return 0.0;
        }
        self.full.x * self.full.y / per_uv
    }

    /// Every raster position (the region's pixels, y from the top, as `project` gives them)
    /// within `reach` pixels of the image where the camera looks the way it looks at
    /// `raster`. One for most cameras; an equirectangular image repeats its directions
    /// beyond its edges, as its camera rays (a pixel filter reaches past the edge) find
    /// them: every turn of longitude (u + k·2π/|a| for φ = a·u + b) and, past a pole, the
    /// mirror image (θ → −θ or 2π − θ, φ → φ + π). Light tracing splats at each, and the
    /// camera's density of a direction adds the pixel filter over all of them.
    pub fn raster_images(&self, raster: Vec2, reach: f32) -> ([Vec2; 9], usize) {
        let mut out = [raster; 9];
        if self.projection != Projection::Equirectangular {
            return (out, 1);
        }
        let r = self.equirect;
        let full = raster + self.offset;
        let (u, v) = (full.x / self.full.x, 1.0 - full.y / self.full.y);
        let (tau, pi) = (std::f32::consts::TAU, std::f32::consts::PI);
        let period = tau / r.x.abs();
        let mirrors = [(v, 0.0), (-v - 2.0 * r.w / r.z, pi / r.x), (-v + (tau - 2.0 * r.w) / r.z, pi / r.x)];
        let mut n = 0;
        for (vv, du) in mirrors {
            for k in [-1.0, 0.0, 1.0] {
                let p = Vec2::new((u + du + k * period) * self.full.x, (1.0 - vv) * self.full.y) - self.offset;
                let near =
                    p.x > -reach && p.x < self.width as f32 + reach && p.y > -reach && p.y < self.height as f32 + reach;
                if near && n < out.len() {
                    out[n] = p;
                    n += 1;
                }
            }
        }
        (out, n)
    }

    /// The pixel filter's weight at the pixel centred on `pixel` of a sample that lands at
    /// `raster`: its density over every place the camera sees that way (`raster_images`).
    #[inline]
    pub fn filter_weight(&self, raster: Vec2, pixel: Vec2) -> f32 {
        let f = &self.filter;
        if self.projection != Projection::Equirectangular {
            return f.density(raster.x - pixel.x) * f.density(raster.y - pixel.y);
            // (one place)
        }
        let (images, n) = self.raster_images(raster, f.radius() + 1.0);
        images[..n].iter().map(|r| f.density(r.x - pixel.x) * f.density(r.y - pixel.y)).sum()
    }

    /// The pixels (x, y) of the region a sample landing at `raster` reaches through the pixel
    /// filter, each with the filter's weight there (one place's: a pixel that two places of
    /// a panorama reach comes twice).
    pub fn footprint(&self, raster: Vec2) -> impl Iterator<Item = (u32, u32, f32)> + '_ {
        let f = &self.filter;
        let r = f.radius();
        let (images, n) = self.raster_images(raster, r + 1.0);
        let (w, h) = (self.width as i64, self.height as i64);
        (0..n).flat_map(move |i| {
            let p = images[i];
            let (x0, x1) = (((p.x - r).floor() as i64).max(0), ((p.x + r).floor() as i64).min(w - 1));
            let (y0, y1) = (((p.y - r).floor() as i64).max(0), ((p.y + r).floor() as i64).min(h - 1));
            (y0..=y1).flat_map(move |y| (x0..=x1).map(move |x| (x, y))).filter_map(move |(x, y)| {
                let fw = f.density(p.x - (x as f32 + 0.5)) * f.density(p.y - (y as f32 + 0.5));
                (fw > 0.0).then_some((x as u32, y as u32, fw))
            })
        })
    }

    /// The camera's importance towards world point `p` seen from the lens point `lens` (the
    /// camera's position for a pinhole): the raster position where `p` lands (the region's
    /// pixels, y from the top) and W = 1/(A·cos³θ), the density per solid angle of the
    /// directions of one pixel's camera rays at the lens (A: a pixel's area on the image plane
    /// at distance 1, θ: the angle to the view axis) — the same with depth of field, since
    /// the lens point's own density cancels (docs/bidirectional.md). A panorama's W is per
    /// solid angle too (`panorama_density`); an orthographic camera's per unit film area
    /// (1/a, `lens` unused: `p` is joined along the view axis). None behind the lens, outside
    /// the clipping range, or outside a fisheye's circle.
    pub fn importance(&self, lens: Vec3, p: Vec3) -> Option<(Vec2, f32)> {
        if self.parallel() {
            // W = 1/a: a pixel's rays start uniformly over its footprint on the film, of area a
            let pc = self.to_camera.transform_point3(p);
            let depth = -pc.z;
            if !(depth > self.clip_start && depth < self.clip_end) {
                return None;
            }
            let pixel_area = self.ext.x * self.ext.y / (self.full.x * self.full.y);
            return Some((self.project(p)?, 1.0 / pixel_area));
        }
        if self.is_panoramic() {
            // (no lens: the centre; clipped along the ray, as its camera rays are)
            let d = p - self.position();
            let dist = d.length();
            if !(dist > self.clip_start && dist < self.clip_end) {
                return None;
            }
            let w = self.panorama_density(self.to_camera.transform_vector3(d / dist));
            let raster = self.project(p)?;
            return (w > 0.0 && w.is_finite()).then_some((raster, w));
        }
        let (pc, oc) = (self.to_camera.transform_point3(p), self.to_camera.transform_point3(lens));
        let depth = -pc.z;
        if !(depth > self.clip_start && depth < self.clip_end) {
            return None;
        }
        let d = pc - oc;
        if d.z >= 0.0 {
            return None;
        }
        let q = if self.aperture_radius > 0.0 {
            // where the ray from the lens point crosses the plane in focus, seen from the centre
            let f = oc + d * (self.focus_distance / -d.z);
            Vec2::new(f.x, f.y) / self.focus_distance
        } else {
            Vec2::new(pc.x, pc.y) / depth
        };
        let u = (q.x - self.center.x) / self.ext.x + 0.5;
        let v = (q.y - self.center.y) / self.ext.y + 0.5;
        let raster = Vec2::new(u * self.full.x, (1.0 - v) * self.full.y) - self.offset;
        let cos = -d.z / d.length();
        let pixel_area = self.ext.x * self.ext.y / (self.full.x * self.full.y);
        Some((raster, 1.0 / (pixel_area * cos * cos * cos)))
    }

    /// `importance`'s W for a camera ray of unit direction `dir` (world), clipping aside.
    pub fn ray_density(&self, dir: Vec3) -> f32 {
        if self.parallel() {
            return self.full.x * self.full.y / (self.ext.x * self.ext.y); // (per film area)
        }
        if self.is_panoramic() {
            let w = self.panorama_density(self.to_camera.transform_vector3(dir).normalize_or_zero());
            return if w.is_finite() { w } else { 0.0 };
        }
        let forward = -self.to_world.z_axis.truncate().normalize_or_zero();
        let cos = dir.dot(forward);
        if !(cos > 0.0) {
            return 0.0;
        }
        let pixel_area = self.ext.x * self.ext.y / (self.full.x * self.full.y);
        1.0 / (pixel_area * cos * cos * cos)
    }

    /// A point of the lens for a light-tracing connection to `p` from sample `u` (world; the
    /// camera's position for a pinhole), as `generate_ray` picks its origin; for an
    /// orthographic camera the point of its film whose ray meets `p`, moved to the clip start
    /// (what lies before it is clipped).
    pub fn lens_point(&self, u: Vec2, p: Vec3) -> Vec3 {
        if self.parallel() {
            let pc = self.to_camera.transform_point3(p);
            return self.to_world.transform_point3(Vec3::new(pc.x, pc.y, -self.clip_start));
        }
        if self.aperture_radius > 0.0 && self.projection == Projection::Perspective {
            let l = self.aperture_point(u) * self.aperture_radius;
            self.to_world.transform_point3(Vec3::new(l.x, l.y, 0.0))
        } else {
            self.position()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn look_down_neg_z() -> CameraDesc {
        CameraDesc { resolution_x: 200, resolution_y: 100, ..Default::default() }
    }

    /// Issue 18: resolution × percentage wrapped in u32 (42949700 × 100% gave a 27-pixel-wide
    /// image, rendered with exit 0); it is now computed in u64 and refused above 65536.
    /// Infinite shifts and f-stops that are no lens (black frames before) are refused.
    #[test]
    fn sizes_that_overflow_shifts_and_f_stops_that_are_no_camera_are_refused() {
        let big = CameraDesc { resolution_x: 42_949_700, resolution_y: 16, ..Default::default() };
        let e = Camera::new(&big).expect_err("refused").to_string();
        assert!(e.contains("42949700") && e.contains("65536"), "{e}");
        let pct = CameraDesc { resolution_x: 50_000, resolution_percentage: 100_000, ..Default::default() };
        assert!(Camera::new(&pct).is_err());
        for (sx, sy) in [(f32::INFINITY, 0.0), (0.0, f32::NAN)] {
            let d = CameraDesc { shift_x: sx, shift_y: sy, ..look_down_neg_z() };
            assert!(Camera::new(&d).err().unwrap().to_string().contains("shift"));
        }
        for f in [1e-30, f32::NAN] {
            let d = CameraDesc { fstop: f, ..look_down_neg_z() };
            assert!(Camera::new(&d).err().unwrap().to_string().contains("f-stop"), "{f}");
        }
        assert!(Camera::new(&CameraDesc { fstop: 2.8, ..look_down_neg_z() }).is_ok());
    }

    #[test]
    fn centre_and_edges_of_a_known_frame() {
        // 50 mm lens, 36 mm sensor, horizontal fit: at depth 1 the frame spans 36/50 = 0.72.
        let cam = Camera::new(&look_down_neg_z()).unwrap();
        let c = cam.project(Vec3::new(0.0, 0.0, -3.0)).unwrap();
        assert!((c - Vec2::new(100.0, 50.0)).length() < 1e-4);
        let right = cam.project(Vec3::new(0.36 * 3.0, 0.0, -3.0)).unwrap();
        assert!((right.x - 200.0).abs() < 1e-3, "{right:?}");
        // vertical extent is 0.72 · 100/200 = 0.36 → top edge at y = 0.18 per unit depth
        let top = cam.project(Vec3::new(0.0, 0.18 * 2.0, -2.0)).unwrap();
        assert!(top.y.abs() < 1e-3, "{top:?}");
    }

    /// A render region renders the pixels of the full frame it covers: its pixel (i, j) gets
    /// the full camera's ray through (x + i, y + j), and bad regions are errors.
    #[test]
    fn render_region_is_a_window_of_the_full_frame() {
        let full = Camera::new(&look_down_neg_z()).unwrap();
        let mut d = look_down_neg_z();
        d.window = Some([50, 20, 60, 30]);
        let region = Camera::new(&d).unwrap();
        assert_eq!((region.width, region.height), (60, 30));
        for (i, j) in [(0.5f32, 0.5f32), (59.5, 29.5), (13.25, 7.75)] {
            let (a, b) = (
                region.generate_ray(Vec2::new(i, j), Vec2::ZERO),
                full.generate_ray(Vec2::new(50.0 + i, 20.0 + j), Vec2::ZERO),
            );
            assert!((a.dir - b.dir).length() < 1e-6 && (a.origin - b.origin).length() < 1e-6);
            let p = a.origin + a.dir * 4.0;
            assert!((region.project(p).unwrap() - Vec2::new(i, j)).length() < 1e-3);
        }
        for bad in [[0, 0, 0, 10], [190, 0, 20, 10], [0, 95, 10, 10]] {
            d.window = Some(bad);
            assert!(Camera::new(&d).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn ray_generation_inverts_projection() {
        let mut d = look_down_neg_z();
        d.to_world = [[0.0, 0.0, 1.0, 2.0], [1.0, 0.0, 0.0, -1.0], [0.0, 1.0, 0.0, 0.5], [0.0, 0.0, 0.0, 1.0]];
        d.shift_x = 0.1;
        d.shift_y = -0.2;
        d.sensor_fit = SensorFit::Vertical;
        d.resolution_percentage = 50;
        for proj in [
            Projection::Perspective,
            Projection::Orthographic,
            Projection::Equirectangular,
            Projection::FisheyeEquidistant,
            Projection::FisheyeEquisolid,
        ] {
            d.projection = proj;
            let cam = Camera::new(&d).unwrap();
            assert_eq!((cam.width, cam.height), (100, 50));
            let fisheye = matches!(proj, Projection::FisheyeEquidistant | Projection::FisheyeEquisolid);
            // (inside the fisheyes' circles: a 180° equidistant spans the frame; the equisolid's
            // 10.5 mm lens on a 12 mm-high sensor of twice that width)
            let rasters: &[Vec2] = if fisheye {
                &[Vec2::new(50.5, 25.5), Vec2::new(62.2, 20.9), Vec2::new(41.0, 33.0)]
            } else {
                &[Vec2::new(0.5, 0.5), Vec2::new(73.2, 12.9), Vec2::new(99.0, 49.0)]
            };
            if fisheye {
                assert!(cam.generate_ray(Vec2::new(0.5, 0.5), Vec2::ZERO).is_dead(), "{proj:?}: a corner sees nothing");
            }
            for &raster in rasters {
                let r = cam.generate_ray(raster, Vec2::splat(0.5));
                let p = r.origin + r.dir * 4.0;
                let back = cam.project(p).unwrap();
                assert!((back - raster).length() < 1e-3, "{proj:?} {raster:?} -> {back:?}");
            }
        }
    }

    /// An equirectangular camera as Cycles maps it: the image's centre looks down the camera's
    /// −Z, a quarter of the width to the left looks to its left (−X), the top row straight up
    /// (+Y), with the default 360° × 180° ranges; narrower ranges narrow the view, and empty
    /// or NaN ranges are errors.
    #[test]
    fn equirectangular_directions_follow_cycles() {
        let mut d = CameraDesc {
            projection: Projection::Equirectangular,
            resolution_x: 400,
            resolution_y: 200,
            ..Default::default()
        };
        let cam = Camera::new(&d).unwrap();
        let dir = |c: &Camera, x: f32, y: f32| c.generate_ray(Vec2::new(x, y), Vec2::ZERO).dir;
        let near = |a: Vec3, b: Vec3| (a - b).length() < 1e-5;
        assert!(near(dir(&cam, 200.0, 100.0), Vec3::NEG_Z));
        assert!(near(dir(&cam, 100.0, 100.0), Vec3::NEG_X));
        assert!(near(dir(&cam, 300.0, 100.0), Vec3::X));
        assert!(near(dir(&cam, 0.0, 100.0), Vec3::Z) && near(dir(&cam, 200.0, 0.0), Vec3::Y));
        d.panorama = [-0.5, 0.5, -1.0, 1.0];
        let narrow = Camera::new(&d).unwrap();
        let right_edge = dir(&narrow, 400.0, 100.0);
        assert!(near(right_edge, Vec3::new(1f32.sin(), 0.0, -1f32.cos())), "{right_edge:?}");
        assert!(near(dir(&narrow, 200.0, 0.0), Vec3::new(0.0, 0.5f32.sin(), -0.5f32.cos())));
        for bad in [[0.5, -0.5, -1.0, 1.0], [-0.5, 0.5, f32::NAN, 1.0]] {
            d.panorama = bad;
            assert!(Camera::new(&d).err().unwrap().to_string().contains("panorama"), "{bad:?}");
        }
    }

    /// Light tracing's W (`ray_density`, `importance`) is 1 / the solid angle of one pixel's
    /// camera rays: against finite differences of `generate_ray`'s directions over the raster
    /// (|∂d/∂x × ∂d/∂y|, central differences) at pixels across the frame, for every projection
    /// light tracing joins — pinhole, equirectangular (the whole sphere and a band across
    /// ±180° of longitude), fisheye equidistant and equisolid — and `importance` lands where
    /// the camera ray came from.
    #[test]
    fn light_tracings_importance_is_one_over_a_pixels_solid_angle() {
        let turned = [[0.0, 0.0, 1.0, 0.5], [1.0, 0.0, 0.0, -1.0], [0.0, 1.0, 0.0, 2.0], [0.0, 0.0, 0.0, 1.0]];
        let base = CameraDesc { resolution_x: 64, resolution_y: 40, to_world: turned, ..Default::default() };
        let cases = [
            ("pinhole", CameraDesc { lens: 30.0, ..base.clone() }),
            ("equirectangular", CameraDesc { projection: Projection::Equirectangular, ..base.clone() }),
            (
                "equirectangular band across ±180°",
                CameraDesc { projection: Projection::Equirectangular, panorama: [-0.6, 0.9, 2.0, 4.0], ..base.clone() },
            ),
            (
                "fisheye equidistant",
                CameraDesc { projection: Projection::FisheyeEquidistant, fisheye_fov: 3.3, ..base.clone() },
            ),
            (
                "fisheye equisolid",
                CameraDesc {
                    projection: Projection::FisheyeEquisolid,
                    fisheye_fov: 3.1,
                    fisheye_lens: 14.0,
                    ..base.clone()
                },
            ),
        ];
        for (name, d) in cases {
            let cam = Camera::new(&d).unwrap();
            let dir = |x: f32, y: f32| cam.generate_ray(Vec2::new(x, y), Vec2::ZERO).dir.as_dvec3();
            let mut checked = 0;
            for (x, y) in [(10.3, 7.7), (32.0, 20.0), (50.5, 12.25), (5.5, 33.5), (60.2, 38.9), (31.1, 2.6)] {
                let ray = cam.generate_ray(Vec2::new(x, y), Vec2::ZERO);
                if ray.is_dead() {
                    continue; // (outside a fisheye's circle)
                }
                let h = 1e-3;
                let dx = (dir(x + h as f32, y) - dir(x - h as f32, y)) / (2.0 * h);
                let dy = (dir(x, y + h as f32) - dir(x, y - h as f32)) / (2.0 * h);
                let solid_angle = dx.cross(dy).length();
                let w = cam.ray_density(ray.dir) as f64;
                assert!((w * solid_angle - 1.0).abs() < 0.02, "{name} at ({x}, {y}): W {w} × dω {solid_angle}");
                let p = ray.origin + ray.dir * 3.0;
                let (raster, wi) = cam.importance(ray.origin, p).unwrap();
                assert!((raster - Vec2::new(x, y)).length() < 2e-3, "{name}: ({x}, {y}) lands at {raster}");
                assert!((wi / w as f32 - 1.0).abs() < 1e-4, "{name}: {wi} against {w}");
                checked += 1;
            }
            assert!(checked >= 4, "{name}: {checked} pixels in the image");
        }
        // an orthographic camera: W per unit film area, 1 / a pixel's footprint there, and a
        // point lands where the ray along the view axis that meets it starts
        let ortho =
            Camera::new(&CameraDesc { projection: Projection::Orthographic, ortho_scale: 4.0, ..base }).unwrap();
        assert!(ortho.parallel());
        let ray = ortho.generate_ray(Vec2::new(20.3, 30.6), Vec2::ZERO);
        let p = ray.origin + ray.dir * 2.5;
        let (raster, w) = ortho.importance(Vec3::ZERO, p).unwrap();
        assert!((raster - Vec2::new(20.3, 30.6)).length() < 1e-3, "{raster}");
        let footprint = (4.0 / 64.0) * (4.0 * 40.0 / 64.0 / 40.0);
        assert!((w * footprint - 1.0).abs() < 1e-4, "{w}");
        let lens = ortho.lens_point(Vec2::ZERO, p);
        assert!((lens - (ray.origin + ray.dir * ortho.clip_start)).length() < 1e-4, "{lens} {ray:?}");
    }

    #[test]
    fn zero_size_image_is_an_error() {
        let mut d = look_down_neg_z();
        d.resolution_percentage = 0;
        assert!(Camera::new(&d).is_err());
    }

    /// The aperture as Cycles samples it: a pentagon of blades inscribed in the unit disk,
    /// turned, its width halved by an anamorphic ratio of 2 — every point inside it, spread
    /// uniformly (its mean squared radius that of the pentagon, R²(2 + cos(2π/n))/6, within
    /// 4σ); no blades is the disk (mean squared radius ½).
    #[test]
    fn the_aperture_is_the_blades_polygon_squeezed_by_the_ratio() {
        use crate::sampler::{IndependentSampler, Sampler};
        let (n, rot, ratio) = (5u32, 0.4f32, 2.0f32);
        let cam = Camera::new(&CameraDesc {
            fstop: 2.8,
            aperture_blades: n,
            aperture_rotation: rot,
            aperture_ratio: ratio,
            ..look_down_neg_z()
        })
        .unwrap();
        let round = Camera::new(&CameraDesc { fstop: 2.8, ..look_down_neg_z() }).unwrap();
        let half = std::f32::consts::PI / n as f32;
        let mut s = IndependentSampler::new(3, 0);
        let count = 200_000;
        let (mut m2, mut m2_round) = (0.0f64, 0.0f64);
        for _ in 0..count {
            let u = s.next_2d();
            let p = cam.aperture_point(u);
            let q = Vec2::new(p.x * ratio, p.y); // undo the ratio
                                                 // inside: within every edge (edge normals at rot + 2k·π/n, apothem cos(π/n))
            for k in 0..n {
                let a = rot + 2.0 * half * k as f32;
                assert!(q.dot(Vec2::new(a.cos(), a.sin())) <= half.cos() + 1e-5, "{q} outside edge {k}");
            }
            m2 += q.length_squared() as f64;
            m2_round += round.aperture_point(u).length_squared() as f64;
        }
        let want = (2.0 + (2.0 * half as f64).cos()) / 6.0;
        // (|q|² ≤ 1: its σ is below ½)
        let tol = 4.0 * 0.5 / (count as f64).sqrt();
        assert!((m2 / count as f64 - want).abs() < tol, "{} vs {want}", m2 / count as f64);
        assert!((m2_round / count as f64 - 0.5).abs() < tol);
    }
}
