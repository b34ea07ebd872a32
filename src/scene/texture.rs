//! Image textures as Cycles samples them: RGB pixels, row 0 at the bottom (v = 0), pixel
//! centres at (i + ½)/width, bilinear ("Linear") or nearest ("Closest") lookup, Blender's
//! extension modes (Repeat, Extend, Clip, Mirror). 8-bit sRGB images keep their encoded values and
//! are decoded after interpolation — Cycles' NODE_IMAGE_COMPRESS_AS_SRGB path, which a
//! checker texture shows: interpolating decoded values instead renders it 40% brighter.

use super::desc::{TextureDesc, TextureExtension};
use super::procedural::{Procedural, Space};
use crate::error::SceneError;
use crate::math::Spectrum;
use glam::{Vec2, Vec3};

/// The step, in a procedural pattern's own space (lattice cells), of the differences that
/// bump a surface by it.
pub const PROCEDURAL_BUMP_STEP: f32 = 1e-3;

/// Where a surface texture is looked up: the UV map's coordinates and the mesh's Generated
/// and Object coordinates (zero where the mesh carries none).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TexCoord {
    pub uv: Vec2,
    pub generated: Vec3,
    pub object: Vec3,
}

impl TexCoord {
    /// The coordinates of `space`, as a point ((u, v, 0) for the UV map).
    #[inline]
    pub fn point(&self, space: Space) -> Vec3 {
        match space {
            Space::Uv => self.uv.extend(0.0),
            Space::Generated => self.generated,
            Space::Object => self.object,
        }
    }
}

#[derive(Clone, Debug)]
pub struct Texture {
    pub name: String,
    width: usize,
    height: usize,
    pixels: Vec<Spectrum>,
    closest: bool,
    extension: TextureExtension,
    srgb: bool,
    transform: Option<[f32; 6]>,
    /// A procedural pattern; `pixels` is then its table (scene/procedural.rs).
    procedural: Option<Procedural>,
}

/// The sRGB transfer function, inverted (IEC 61966-2-1).
#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The derivative of `srgb_to_linear` at `c`.
#[inline]
fn srgb_slope(c: f32) -> f32 {
    if c <= 0.04045 {
        1.0 / 12.92
    } else {
        2.4 / 1.055 * ((c + 0.055) / 1.055).powf(1.4)
    }
}

/// Texel index `i` of a row of `n` repeated with every other copy mirrored: …, 1, 0 | 0, 1,
/// …, n − 1 | n − 1, … (Cycles' mirror wrap).
#[inline]
fn mirrored(i: i64, n: i64) -> i64 {
    let m = i.rem_euclid(2 * n);
    if m >= n {
        2 * n - 1 - m
    } else {
        m
    }
}

impl Texture {
    pub fn from_desc(d: &TextureDesc) -> Result<Texture, SceneError> {
        let bad = |what: String| SceneError::Texture { texture: d.name.clone(), what };
        if d.width == 0 || d.height == 0 {
            return Err(bad("has no pixels (zero width or height)".into()));
        }
        // checked: width·height wrapped for sizes a script can pass (a 2-pixel list then
        // passed as a texture of 2^32 × 2^32 + … and, as a world, asked for 240 GB)
        if d.width.checked_mul(d.height) != Some(d.pixels.len()) {
            return Err(bad(format!("{} pixels for {}×{}", d.pixels.len(), d.width, d.height)));
        }
        if d.transform.is_some_and(|m| m.iter().any(|v| !v.is_finite())) {
            return Err(bad("NaN or Inf in its coordinate transform".into()));
        }
        if let Some(p) = &d.procedural {
            if p.transform.iter().chain([&p.domain.0, &p.domain.1]).any(|v| !v.is_finite()) {
                return Err(bad("NaN or Inf in its procedural pattern's transform or domain".into()));
            }
            if d.height != 1 || d.width < 2 {
                return Err(bad(format!("a procedural table of {}×{} (needs width ≥ 2, height 1)", d.width, d.height)));
            }
        }
        // NaN/Inf pixels (a broken EXR) are replaced by black rather than poisoning the render.
        let pixels = d
            .pixels
            .iter()
            .map(|p| {
                let v = Spectrum::from_array(*p);
                if v.is_finite() {
                    v.max(Spectrum::ZERO)
                } else {
                    Spectrum::ZERO
                }
            })
            .collect();
        Ok(Texture {
            name: d.name.clone(),
            width: d.width,
            height: d.height,
            pixels,
            closest: d.closest,
            extension: d.extension,
            srgb: d.srgb,
            transform: d.transform,
            procedural: d.procedural.clone(),
        })
    }

    /// (width, height) in pixels.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The mean linear colour over the image (each pixel decoded), for light power estimates.
    pub fn mean(&self) -> Spectrum {
        let sum: glam::DVec3 = self
            .pixels
            .iter()
            .map(|p| {
                let c = if self.srgb {
                    Spectrum::new(srgb_to_linear(p.x), srgb_to_linear(p.y), srgb_to_linear(p.z))
                } else {
                    *p
                };
                c.as_dvec3()
            })
            .sum();
        (sum / self.pixels.len() as f64).as_vec3()
    }

    /// The pixel at integer coordinates after the extension mode (None = transparent black).
    #[inline]
    fn texel(&self, x: i64, y: i64) -> Option<Spectrum> {
        let (w, h) = (self.width as i64, self.height as i64);
        let (x, y) = match self.extension {
            TextureExtension::Repeat => (x.rem_euclid(w), y.rem_euclid(h)),
            TextureExtension::Extend => (x.clamp(0, w - 1), y.clamp(0, h - 1)),
            TextureExtension::Clip => {
                if x < 0 || y < 0 || x >= w || y >= h {
                    return None;
                }
                (x, y)
            }
            TextureExtension::Mirror => (mirrored(x, w), mirrored(y, h)),
        };
        Some(self.pixels[(y * w + x) as usize])
    }

    /// The texture's coordinate transform: its matrix M and translation t as
    /// [m00, m01, t0, m10, m11, t1] (identity without one).
    fn affine(&self) -> [f32; 6] {
        self.transform.unwrap_or([1.0, 0.0, 0.0, 0.0, 1.0, 0.0])
    }

    /// `uv` mapped by the texture's transform.
    fn mapped(&self, uv: Vec2) -> Vec2 {
        let m = self.affine();
        Vec2::new(m[0] * uv.x + m[1] * uv.y + m[2], m[3] * uv.x + m[4] * uv.y + m[5])
    }

    /// Linear colour of a surface texture at `tc`: an image at its UV coordinates, a
    /// procedural pattern at its own coordinates through its table.
    #[inline]
    pub fn at(&self, tc: TexCoord) -> Spectrum {
        let Some(p) = &self.procedural else { return self.eval(tc.uv) };
        self.table(p, p.output(tc.point(p.space)))
    }

    /// A procedural pattern's output `out` through the texture's table, channel by channel.
    #[inline]
    fn table(&self, p: &Procedural, out: Vec3) -> Spectrum {
        let channel = |c: usize| {
            let (i, t) = p.table_position(out[c], self.width);
            self.pixels[i][c] * (1.0 - t) + self.pixels[i + 1][c] * t
        };
        Spectrum::new(channel(0), channel(1), channel(2))
    }

    /// The largest value of any channel the texture gives (its table's, for a procedural
    /// pattern: an upper bound wherever the pattern stays within the table's domain).
    pub fn max_value(&self) -> f32 {
        self.pixels.iter().fold(0.0f32, |m, p| m.max(p.max_element()))
    }

    /// The value of a procedural texture at the Object coordinates `object` and Generated
    /// `generated` of a point (a medium's density field; an image reads its UV (0, 0)).
    #[inline]
    pub fn at_point(&self, object: Vec3, generated: Vec3) -> Spectrum {
        self.at(TexCoord { uv: Vec2::ZERO, generated, object })
    }

    /// The coordinates a procedural texture reads; None for an image (its UV map's).
    pub fn procedural_space(&self) -> Option<Space> {
        self.procedural.as_ref().map(|p| p.space)
    }

    /// The gradient of a procedural texture's luminance at `tc` with respect to the
    /// coordinates it reads (`TexCoord::point`): central differences over
    /// `PROCEDURAL_BUMP_STEP` of the pattern's own space (Cycles' Bump node differences over
    /// a tenth of a pixel's footprint, about as much for common scales), through the
    /// transform. Zero for an image.
    pub fn procedural_luminance_gradient(&self, tc: TexCoord) -> Vec3 {
        let Some(p) = &self.procedural else { return Vec3::ZERO };
        let q = p.to_pattern(tc.point(p.space));
        let h = PROCEDURAL_BUMP_STEP;
        let lum = |d: Vec3| crate::math::luminance(self.table(p, p.pattern_at(q + d)));
        let g = Vec3::new(
            lum(Vec3::X * h) - lum(-Vec3::X * h),
            lum(Vec3::Y * h) - lum(-Vec3::Y * h),
            lum(Vec3::Z * h) - lum(-Vec3::Z * h),
        ) / (2.0 * h);
        p.gradient_to_coordinates(g)
    }

    /// Linear colour of an image at texture coordinates `uv` (mapped by the texture's transform first).
    pub fn eval(&self, uv: Vec2) -> Spectrum {
        let c = self.interpolate(self.mapped(uv));
        if self.srgb {
            Spectrum::new(srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z))
        } else {
            c
        }
    }

    /// The gradient (∂/∂u, ∂/∂v) of the luminance of `eval` at `uv` — of the bilinear
    /// interpolation within the texel cell `uv` falls in, through the sRGB decoding and the
    /// texture's coordinate transform; zero for closest lookup (piecewise constant).
    pub fn luminance_gradient(&self, uv: Vec2) -> Vec2 {
        if self.closest || self.procedural.is_some() {
            return Vec2::ZERO;
        }
        let Some(([c00, c10, c01, c11], tx, ty)) = self.cell(self.mapped(uv)) else { return Vec2::ZERO };
        // ∂/∂x and ∂/∂y of the stored values (x, y in texels), then of the decoded ones
        let mut dx = ((c10 - c00) * (1.0 - ty) + (c11 - c01) * ty) * self.width as f32;
        let mut dy = ((c01 - c00) * (1.0 - tx) + (c11 - c10) * tx) * self.height as f32;
        if self.srgb {
            let value = (c00 * (1.0 - tx) + c10 * tx) * (1.0 - ty) + (c01 * (1.0 - tx) + c11 * tx) * ty;
            let slope = Spectrum::from_array(value.to_array().map(srgb_slope));
            (dx, dy) = (dx * slope, dy * slope);
        }
        let (gx, gy) = (crate::math::luminance(dx), crate::math::luminance(dy));
        // through the transform: mapped = M·uv + t
        let m = self.affine();
        Vec2::new(gx * m[0] + gy * m[3], gx * m[1] + gy * m[4])
    }

    /// The bilinear cell around (mapped) `uv`: its four stored texels (x0y0, x1y0, x0y1,
    /// x1y1) and the fractions (tx, ty) across it; None at non-finite coordinates.
    fn cell(&self, uv: Vec2) -> Option<([Spectrum; 4], f32, f32)> {
        let (x, y) = (uv.x as f64 * self.width as f64 - 0.5, uv.y as f64 * self.height as f64 - 0.5);
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (tx, ty) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let t = |x, y| self.texel(x, y).unwrap_or(Spectrum::ZERO);
        Some(([t(x0, y0), t(x0 + 1, y0), t(x0, y0 + 1), t(x0 + 1, y0 + 1)], tx, ty))
    }

    /// Stored values interpolated at `uv` (Cycles' kernel_tex_image_interp).
    fn interpolate(&self, uv: Vec2) -> Spectrum {
        if self.closest {
            let (x, y) = (uv.x as f64 * self.width as f64, uv.y as f64 * self.height as f64);
            if !(x.is_finite() && y.is_finite()) {
                return Spectrum::ZERO;
            }
            return self.texel(x.floor() as i64, y.floor() as i64).unwrap_or(Spectrum::ZERO);
        }
        let Some(([c00, c10, c01, c11], tx, ty)) = self.cell(uv) else { return Spectrum::ZERO };
        (c00 * (1.0 - tx) + c10 * tx) * (1.0 - ty) + (c01 * (1.0 - tx) + c11 * tx) * ty
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tex(ext: TextureExtension, closest: bool) -> Texture {
        // 2×2: bottom row red, green; top row blue, white
        Texture::from_desc(&TextureDesc {
            name: "t".into(),
            width: 2,
            height: 2,
            pixels: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]],
            closest,
            extension: ext,
            srgb: false,
            transform: None,
            procedural: None,
        })
        .unwrap()
    }

    #[test]
    fn pixel_centres_return_their_pixel_and_bilinear_blends() {
        let t = tex(TextureExtension::Extend, false);
        assert_eq!(t.eval(Vec2::new(0.25, 0.25)), Spectrum::new(1.0, 0.0, 0.0)); // bottom-left is row 0
        assert_eq!(t.eval(Vec2::new(0.75, 0.75)), Spectrum::ONE);
        assert_eq!(t.eval(Vec2::new(0.25, 0.75)), Spectrum::new(0.0, 0.0, 1.0));
        let mid = t.eval(Vec2::new(0.5, 0.5)); // average of the four
        assert!((mid - Spectrum::new(0.5, 0.5, 0.5)).abs().max_element() < 1e-6, "{mid}");
        // Extend clamps beyond the edge; Repeat wraps around; Clip is black outside
        assert_eq!(t.eval(Vec2::new(-3.0, 0.25)), Spectrum::new(1.0, 0.0, 0.0));
        let r = tex(TextureExtension::Repeat, false);
        assert!((r.eval(Vec2::new(1.25, 2.25)) - Spectrum::new(1.0, 0.0, 0.0)).abs().max_element() < 1e-6);
        let edge = r.eval(Vec2::new(0.0, 0.25)); // halfway between green (wrapped) and red
        assert!((edge - Spectrum::new(0.5, 0.5, 0.0)).abs().max_element() < 1e-6, "{edge}");
        let c = tex(TextureExtension::Clip, true);
        assert_eq!(c.eval(Vec2::new(1.5, 0.5)), Spectrum::ZERO);
        assert_eq!(c.eval(Vec2::new(0.99, 0.01)), Spectrum::new(0.0, 1.0, 0.0));
        // Mirror: the next copy is flipped, so the edge texel meets itself (no blend there)
        let m = tex(TextureExtension::Mirror, false);
        assert_eq!(m.eval(Vec2::new(1.0, 0.25)), Spectrum::new(0.0, 1.0, 0.0));
        assert_eq!(m.eval(Vec2::new(1.25, 0.25)), Spectrum::new(0.0, 1.0, 0.0)); // (green, mirrored)
        assert_eq!(m.eval(Vec2::new(1.75, 0.25)), Spectrum::new(1.0, 0.0, 0.0));
        assert_eq!(m.eval(Vec2::new(-0.25, -0.25)), Spectrum::new(1.0, 0.0, 0.0));
        assert_eq!((mirrored(-1, 3), mirrored(3, 3), mirrored(5, 3), mirrored(6, 3), mirrored(-7, 3)), (0, 2, 0, 0, 0));
    }

    #[test]
    fn bad_textures_are_errors_and_nan_pixels_are_black() {
        let mut d = TextureDesc {
            name: "broken".into(),
            width: 0,
            height: 2,
            pixels: vec![],
            closest: false,
            extension: TextureExtension::Repeat,
            srgb: false,
            transform: None,
            procedural: None,
        };
        assert!(Texture::from_desc(&d).unwrap_err().to_string().contains("broken"));
        d.width = 1;
        d.pixels = vec![[f32::NAN, 1.0, 1.0]];
        assert!(Texture::from_desc(&d).is_err()); // 1 pixel for 1×2
                                                  // issue 18: a size whose product wraps to the pixel count was accepted
        let (w, h) = (usize::MAX / 2 + 1, 2);
        assert_eq!(w.wrapping_mul(h), 0);
        let wrap = TextureDesc { width: w, height: h, pixels: vec![], ..d.clone() };
        assert!(Texture::from_desc(&wrap).is_err());
        let wrap1 = TextureDesc { width: (1usize << 63) + 1, height: 2, pixels: vec![[0.0; 3]; 2], ..d.clone() };
        assert!(Texture::from_desc(&wrap1).is_err());
        d.height = 1;
        let t = Texture::from_desc(&d).unwrap();
        assert_eq!(t.eval(Vec2::new(0.5, 0.5)), Spectrum::ZERO);
    }

    /// A coordinate transform maps (u, v) before the lookup: scaled by 2 and shifted, the
    /// texture repeats twice; swapped, it turns by 90°; a NaN in it is an error.
    #[test]
    fn coordinate_transforms_map_before_the_lookup() {
        let mut d = TextureDesc {
            name: "t".into(),
            width: 2,
            height: 2,
            pixels: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]],
            closest: true,
            transform: Some([2.0, 0.0, 0.25, 0.0, 2.0, 0.0]),
            procedural: None,
            ..Default::default()
        };
        let t = Texture::from_desc(&d).unwrap();
        // u' = 2u + 0.25: u = 0.2 → 0.65 (green column), u = 0.45 → 1.15 → 0.15 (red column)
        assert_eq!(t.eval(Vec2::new(0.2, 0.1)), Spectrum::new(0.0, 1.0, 0.0));
        assert_eq!(t.eval(Vec2::new(0.45, 0.1)), Spectrum::new(1.0, 0.0, 0.0));
        d.transform = Some([0.0, 1.0, 0.0, 1.0, 0.0, 0.0]); // (u, v) → (v, u)
        let swapped = Texture::from_desc(&d).unwrap();
        assert_eq!(swapped.eval(Vec2::new(0.75, 0.25)), Spectrum::new(0.0, 0.0, 1.0));
        d.transform = Some([f32::NAN, 0.0, 0.0, 0.0, 1.0, 0.0]);
        assert!(Texture::from_desc(&d).is_err());
    }

    /// sRGB images decode after interpolating: halfway between encoded 0 and 1 is
    /// decode(0.5) = 0.214, not 0.5.
    #[test]
    fn srgb_textures_decode_after_interpolation() {
        let t = Texture::from_desc(&TextureDesc {
            name: "s".into(),
            width: 2,
            height: 1,
            pixels: vec![[0.0; 3], [1.0; 3]],
            closest: false,
            extension: TextureExtension::Extend,
            srgb: true,
            transform: None,
            procedural: None,
        })
        .unwrap();
        let mid = t.eval(Vec2::new(0.5, 0.5)).x;
        assert!((mid - 0.21404).abs() < 1e-4, "{mid}");
        assert!((t.eval(Vec2::new(0.75, 0.5)).x - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.04045) - 0.04045 / 12.92).abs() < 1e-7);
    }

    /// `luminance_gradient` is the derivative of the luminance of `eval`: central finite
    /// differences at random points (inside a texel cell: both sides in the same bilinear
    /// patch), for linear and sRGB images, Repeat and Extend, with and without a turned and
    /// scaled coordinate transform; closest lookup has none.
    #[test]
    fn luminance_gradient_is_the_derivative_of_the_lookup() {
        use rand_core::Rng;
        let mut rng = rand_pcg::Pcg32::new(7, 11);
        let mut uniform = move || (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32;
        let pixels: Vec<[f32; 3]> = (0..5 * 3).map(|_| [uniform(), uniform(), uniform()]).collect();
        let mut checked = 0;
        for (srgb, ext, transform) in [
            (false, TextureExtension::Repeat, None),
            (true, TextureExtension::Extend, None),
            (false, TextureExtension::Repeat, Some([1.6, -1.2, 0.3, 0.9, 1.2, -0.1])),
            (true, TextureExtension::Repeat, Some([0.5, 0.8, 0.0, -0.8, 0.5, 0.2])),
        ] {
            let t = Texture::from_desc(&TextureDesc {
                name: "g".into(),
                width: 5,
                height: 3,
                pixels: pixels.clone(),
                closest: false,
                extension: ext,
                srgb,
                transform,
                procedural: None,
            })
            .unwrap();
            let lum = |p: Vec2| crate::math::luminance(t.eval(p)) as f64;
            for _ in 0..200 {
                let p = Vec2::new(uniform() * 1.4 - 0.2, uniform() * 1.4 - 0.2);
                let g = t.luminance_gradient(p);
                let e = 1e-3f32;
                let (dx, dy) = (Vec2::new(e, 0.0), Vec2::new(0.0, e));
                let fd = |d: Vec2| ((lum(p + d) - lum(p - d)) / (2.0 * e as f64)) as f32;
                // one-sided differences that disagree: a cell edge between the samples
                let one = |d: Vec2| ((lum(p + d) - lum(p)) / e as f64) as f32;
                let other = |d: Vec2| ((lum(p) - lum(p - d)) / e as f64) as f32;
                if (one(dx) - other(dx)).abs() > 0.05 * (1.0 + fd(dx).abs())
                    || (one(dy) - other(dy)).abs() > 0.05 * (1.0 + fd(dy).abs())
                {
                    continue;
                }
                checked += 1;
                let want = Vec2::new(fd(dx), fd(dy));
                assert!((g - want).length() < 0.02 * (1.0 + want.length()), "{p}: {g} vs {want} ({srgb}, {ext:?})");
            }
        }
        assert!(checked > 500, "{checked}");
        let closest = Texture::from_desc(&TextureDesc {
            name: "c".into(),
            width: 5,
            height: 3,
            pixels,
            closest: true,
            ..Default::default()
        })
        .unwrap();
        assert_eq!(closest.luminance_gradient(Vec2::new(0.33, 0.61)), Vec2::ZERO);
    }

    /// A procedural texture reads its own coordinates (Generated, Object or the UV map's)
    /// and passes each channel of the pattern's output through its table, interpolated.
    #[test]
    fn procedural_textures_look_their_output_up_in_their_table() {
        use crate::scene::procedural::{GradientKind, Pattern, Procedural, Space};
        let gradient = |space| Procedural {
            pattern: Pattern::Gradient(GradientKind::Linear),
            space,
            transform: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            domain: (0.0, 1.0),
        };
        // a table of 3 entries: 0 → (0, 1, 2), ½ → (1, 1, 0), 1 → (4, 1, 0)
        let desc = |space| TextureDesc {
            name: "g".into(),
            width: 3,
            height: 1,
            pixels: vec![[0.0, 1.0, 2.0], [1.0, 1.0, 0.0], [4.0, 1.0, 0.0]],
            procedural: Some(gradient(space)),
            ..Default::default()
        };
        let t = Texture::from_desc(&desc(Space::Object)).unwrap();
        let at = |t: &Texture, uv: [f32; 2], point: [f32; 3]| {
            t.at(TexCoord { uv: Vec2::from_array(uv), generated: Vec3::splat(9.0), object: Vec3::from_array(point) })
        };
        assert!((at(&t, [0.9, 0.9], [0.25, 7.0, 7.0]) - Vec3::new(0.5, 1.0, 1.0)).length() < 1e-6);
        assert!((at(&t, [0.0, 0.0], [0.75, 0.0, 0.0]) - Vec3::new(2.5, 1.0, 0.0)).length() < 1e-6);
        assert_eq!(at(&t, [0.0, 0.0], [3.0, 0.0, 0.0]), Vec3::new(4.0, 1.0, 0.0)); // (clamped to 1)
        let t = Texture::from_desc(&desc(Space::Uv)).unwrap();
        assert!((at(&t, [0.25, 0.9], [0.9, 0.0, 0.0]) - Vec3::new(0.5, 1.0, 1.0)).length() < 1e-6);
        // the pattern is not an image: no UV gradient for bump mapping from it
        assert_eq!(t.luminance_gradient(Vec2::new(0.3, 0.3)), Vec2::ZERO);
        // tables of one entry or several rows, and non-finite transforms are refused
        for bad in [
            TextureDesc { width: 1, pixels: vec![[0.0; 3]], ..desc(Space::Uv) },
            TextureDesc { width: 3, height: 2, pixels: vec![[0.0; 3]; 6], ..desc(Space::Uv) },
            TextureDesc {
                procedural: Some(Procedural { domain: (0.0, f32::NAN), ..gradient(Space::Uv) }),
                ..desc(Space::Uv)
            },
        ] {
            assert!(Texture::from_desc(&bad).is_err());
        }
    }
}
