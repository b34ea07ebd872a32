//! The world as a light: a constant background colour, or an equirectangular environment
//! texture (HDRI) mapped as Cycles' Environment Texture node does, importance-sampled by a
//! piecewise-constant 2-D distribution over its pixels (luminance × sin θ; pbrt-v4's
//! ImageInfiniteLight) when next-event estimation is on.

use super::texture::Texture;
use crate::distribution::Distribution1D;
use crate::math::{luminance, square_to_uniform_sphere, Spectrum};
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;

#[derive(Clone, Debug, Default)]
pub struct Environment {
    /// Background colour × strength; with a texture, the strength that multiplies it.
    pub scale: Spectrum,
    pub texture: Option<u32>,
    /// World direction → texture frame (a rotation).
    to_local: Mat3,
    /// Mean luminance of the texture over the sphere (its pixels weighted by sin θ).
    mean_texture_luminance: f32,
    /// Rows (v, from the bottom) and, per row, columns (u).
    rows: Distribution1D,
    cols: Vec<Distribution1D>,
}

/// Cycles' direction_to_equirectangular: u = (π − atan2(y, x))/2π, v = 1 − θ/π (θ from +z).
#[inline]
pub fn direction_to_equirect(d: Vec3) -> Vec2 {
    let u = (PI - d.y.atan2(d.x)) / (2.0 * PI);
    let v = 1.0 - d.z.clamp(-1.0, 1.0).acos() / PI;
    Vec2::new(u, v)
}

#[inline]
pub fn equirect_to_direction(uv: Vec2) -> Vec3 {
    let phi = PI - 2.0 * PI * uv.x;
    let theta = PI * (1.0 - uv.y);
    let s = theta.sin();
    Vec3::new(s * phi.cos(), s * phi.sin(), theta.cos())
}

impl Environment {
    pub fn new(scale: Spectrum, texture: Option<(u32, &Texture)>, to_local: Mat3) -> Environment {
        let Some((index, tex)) = texture else {
            return Environment { scale, texture: None, to_local, ..Default::default() };
        };
        let (w, h) = tex.size();
        let mut cols = Vec::with_capacity(h);
        let mut row_weights = Vec::with_capacity(h);
        let mut weighted_sum = 0.0f64;
        for j in 0..h {
            let v = (j as f32 + 0.5) / h as f32;
            let sin_theta = (PI * (1.0 - v)).sin();
            let lum: Vec<f32> =
                (0..w).map(|i| luminance(tex.eval(Vec2::new((i as f32 + 0.5) / w as f32, v)))).collect();
            // a floor keeps every direction reachable (bilinear lookup spreads light into
            // neighbours of bright pixels)
            let mean = lum.iter().sum::<f32>() / w as f32;
            weighted_sum += (mean * sin_theta) as f64;
            let floor = 1e-3 * mean.max(1e-8);
            let weights: Vec<f32> = lum.iter().map(|l| (l + floor) * sin_theta).collect();
            row_weights.push(weights.iter().sum::<f32>());
            cols.push(Distribution1D::new(&weights));
        }
        // ∫ sin θ dθ over [0, π] = 2 with h rows of width π/h: mean = Σ_rows mean·sin θ · π/(2h)
        let mean_texture_luminance = (weighted_sum * std::f64::consts::PI / (2.0 * h as f64)) as f32;
        Environment {
            scale,
            texture: Some(index),
            to_local,
            mean_texture_luminance,
            rows: Distribution1D::new(&row_weights),
            cols,
        }
    }

    pub fn is_black(&self) -> bool {
        self.scale.max_element() <= 0.0
    }

    /// Radiance arriving from direction `d` (unit, world).
    #[inline]
    pub fn eval(&self, textures: &[Texture], d: Vec3) -> Spectrum {
        match self.texture {
            None => self.scale,
            Some(t) => textures[t as usize].eval(direction_to_equirect(self.to_local * d)) * self.scale,
        }
    }

    /// Solid-angle density with which `sample` returns `d`.
    #[inline]
    pub fn pdf(&self, d: Vec3) -> f32 {
        if self.texture.is_none() {
            return 1.0 / (4.0 * PI);
        }
        let uv = direction_to_equirect(self.to_local * d);
        let sin_theta = (PI * (1.0 - uv.y)).sin();
        if sin_theta <= 0.0 {
            return 0.0;
        }
        let (h, w) = (self.cols.len(), self.cols.first().map_or(0, |c| c.len()));
        let j = ((uv.y * h as f32) as usize).min(h - 1);
        let i = ((uv.x * w as f32).rem_euclid(w as f32) as usize).min(w - 1);
        let pdf_uv = self.rows.pmf(j) * h as f32 * self.cols[j].pmf(i) * w as f32;
        pdf_uv / (2.0 * PI * PI * sin_theta)
    }

    /// A direction towards the environment ∝ its radiance: (direction, radiance, pdf).
    pub fn sample(&self, textures: &[Texture], u: Vec2) -> Option<(Vec3, Spectrum, f32)> {
        if self.texture.is_none() {
            let d = square_to_uniform_sphere(u);
            return Some((d, self.scale, 1.0 / (4.0 * PI)));
        }
        let (v, _, j) = self.rows.sample_continuous(u.y)?;
        let (x, _, _) = self.cols[j].sample_continuous(u.x)?;
        let d = self.to_local.transpose() * equirect_to_direction(Vec2::new(x, v));
        // pdf(d) rather than the bins' product: identical except on bin edges, where the
        // round trip through the direction may land in the neighbour; MIS needs pdf(d)
        let pdf = self.pdf(d);
        (pdf > 0.0).then(|| (d, self.eval(textures, d), pdf))
    }

    /// Mean radiance over the sphere (for choosing between lights).
    pub fn mean_radiance(&self) -> f32 {
        match self.texture {
            None => luminance(self.scale),
            Some(_) => self.mean_texture_luminance * luminance(self.scale),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};
    use crate::scene::desc::{TextureDesc, TextureExtension};

    fn hdri() -> Texture {
        // 16×8 with one bright pixel and a smooth gradient
        let (w, h) = (16usize, 8usize);
        let mut px = vec![[0.0f32; 3]; w * h];
        for j in 0..h {
            for i in 0..w {
                px[j * w + i] = [0.1 + 0.05 * i as f32, 0.2, 0.05 * j as f32];
            }
        }
        px[5 * w + 3] = [50.0, 40.0, 30.0];
        Texture::from_desc(&TextureDesc {
            name: "sky".into(),
            width: w,
            height: h,
            pixels: px,
            closest: false,
            extension: TextureExtension::Repeat,
            srgb: false,
            transform: None,
            procedural: None,
        })
        .unwrap()
    }

    #[test]
    fn equirect_mapping_inverts_and_matches_cycles_axes() {
        for d in [Vec3::X, Vec3::Y, -Vec3::Y, Vec3::new(0.3, -0.5, 0.81).normalize()] {
            let back = equirect_to_direction(direction_to_equirect(d));
            assert!((back - d).length() < 1e-5, "{d} → {back}");
        }
        // +x looks at the image centre, +y at u = 1/4, up at the top row
        assert!((direction_to_equirect(Vec3::X) - Vec2::new(0.5, 0.5)).length() < 1e-6);
        assert!((direction_to_equirect(Vec3::Y).x - 0.25).abs() < 1e-6);
        assert!((direction_to_equirect(Vec3::Z).y - 1.0).abs() < 1e-6);
    }

    /// Importance sampling: pdf() agrees with sample()'s pdf, integrates to 1 over the
    /// sphere, and the estimator ∫ L dω by sampling matches uniform-sphere quadrature.
    #[test]
    fn sampling_is_consistent_and_unbiased() {
        let tex = [hdri()];
        // rotated: sampling and pdf must agree in world space
        let rot = Mat3::from_rotation_z(0.7) * Mat3::from_rotation_x(-1.1);
        let env = Environment::new(Spectrum::ONE, Some((0, &tex[0])), rot);
        let mut s = IndependentSampler::new(4, 4);
        let n = 400_000;
        let (mut by_sampling, mut by_uniform, mut pdf_integral) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..n {
            if let Some((_, l, pdf)) = env.sample(&tex, s.next_2d()) {
                by_sampling += (luminance(l) / pdf) as f64;
            }
            let w = square_to_uniform_sphere(s.next_2d());
            by_uniform += luminance(env.eval(&tex, w)) as f64 * 4.0 * std::f64::consts::PI;
        }
        // ∫ pdf dω by a midpoint rule on a fine (θ, φ) grid (Monte Carlo is too noisy for
        // the spike of the bright pixel)
        let (nt, np) = (600, 1200);
        for i in 0..nt {
            let theta = (i as f64 + 0.5) / nt as f64 * std::f64::consts::PI;
            for j in 0..np {
                let phi = (j as f64 + 0.5) / np as f64 * 2.0 * std::f64::consts::PI;
                let d =
                    Vec3::new((theta.sin() * phi.cos()) as f32, (theta.sin() * phi.sin()) as f32, theta.cos() as f32);
                pdf_integral += env.pdf(d) as f64
                    * theta.sin()
                    * (std::f64::consts::PI / nt as f64)
                    * (2.0 * std::f64::consts::PI / np as f64);
            }
        }
        let (a, b, p) = (by_sampling / n as f64, by_uniform / n as f64, pdf_integral);
        assert!((p - 1.0).abs() < 0.01, "pdf integrates to {p}");
        assert!((a - b).abs() < 0.02 * b, "sampling {a} vs uniform {b}");
        let mean = env.mean_radiance() as f64 * 4.0 * std::f64::consts::PI;
        assert!((mean - b).abs() < 0.05 * b, "mean radiance × 4π {mean} vs {b}");
    }
}
