//! Small geometric helpers shared by every module: spectra, shading frames, warps.

use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// RGB radiance / throughput. Linear Rec.709 primaries, as Blender's scene-linear space.
pub type Spectrum = Vec3;

/// Rec.709 luminance (the target-function norm of docs/algorithm.md §3).
#[inline]
pub fn luminance(c: Spectrum) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// Luminance of per-channel absolute values: a negative channel never cancels a positive one.
#[inline]
pub fn abs_luminance(c: Spectrum) -> f32 {
    luminance(c.abs())
}

#[inline]
pub fn is_finite_spectrum(c: Spectrum) -> bool {
    c.x.is_finite() && c.y.is_finite() && c.z.is_finite()
}

/// An orthonormal frame around a normal: local z is the normal.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    /// Duff et al. 2017, "Building an Orthonormal Basis, Revisited".
    pub fn from_normal(n: Vec3) -> Frame {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// Concentric square → disk map (Shirley & Chiu 1997), unit disk.
pub fn square_to_disk_concentric(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    // θ = π/4·(y/x), or π/2 − π/4·(x/y) (then cos θ and sin θ trade places): both need the
    // sine and cosine of an angle in [−π/4, π/4] only
    if o.x.abs() > o.y.abs() {
        let (s, c) = sin_cos_quarter((PI / 4.0) * (o.y / o.x));
        Vec2::new(o.x * c, o.x * s)
    } else {
        let (s, c) = sin_cos_quarter((PI / 4.0) * (o.x / o.y));
        Vec2::new(o.y * s, o.y * c)
    }
}

/// sin x and cos x for |x| ≤ π/4 by their Taylor polynomials to x⁹ and x⁸ (truncation error
/// below 4e-8, under f32's rounding; no range reduction and no library call on the hot path).
#[inline]
pub fn sin_cos_quarter(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0)))));
    let c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0))));
    (s, c)
}

/// sin 2πt and cos 2πt for t in [0, 1]: the nearest quarter turn q = round(4t) is taken out
/// exactly and the remainder 2π(t − q/4), within ±π/4, goes to `sin_cos_quarter`; the
/// quarter turns then swap and negate the pair (sin(x + qπ/2), cos(x + qπ/2)), by sign bits.
#[inline]
pub fn sin_cos_turns(t: f32) -> (f32, f32) {
    let q = (4.0 * t).round();
    let (s, c) = sin_cos_quarter((2.0 * PI) * (t - 0.25 * q));
    let q = q as i32 as u32;
    let (s, c) = if q & 1 != 0 { (c, s) } else { (s, c) };
    // q = 1: (c, −s); q = 2: (−s, −c); q = 3: (−c, s)
    (f32::from_bits(s.to_bits() ^ ((q & 2) << 30)), f32::from_bits(c.to_bits() ^ (((q + 1) & 2) << 30)))
}

/// atan2 by a polynomial (|error| < 1e-6 rad, as libm's f32 to a few ulps): libm's call cost
/// more than the rest of a path guide's density lookup (`guiding/quadtree.rs`).
#[inline]
pub fn atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (mx, mn) = (ax.max(ay), ax.min(ay));
    if mx == 0.0 {
        return 0.0;
    }
    let a = mn / mx;
    let s = a * a;
    // atan(a) on [0, 1]: a + a·s·P(s), least squares on Chebyshev nodes (|error| < 1e-8
    // in exact arithmetic; f32 rounding dominates)
    const C: [f32; 8] = [
        -0.333_329_8,
        0.199_902_07,
        -0.141_844_21,
        0.105_678_22,
        -0.073_537_6,
        0.040_970_22,
        -0.015_040_09,
        0.002_599_34,
    ];
    let mut p = C[7];
    for c in C[..7].iter().rev() {
        p = p * s + c;
    }
    let mut r = a + a * s * p;
    if ay > ax {
        r = std::f32::consts::FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = PI - r;
    }
    if y < 0.0 {
        -r
    } else {
        r
    }
}

/// Cosine-weighted hemisphere around +z (Malley's method: a uniform disk point lifted to the
/// hemisphere); pdf = cosθ/π. The disk point is polar, r = √u₁ at angle 2πu₂, so z = √(1 − u₁):
/// no division and no branch on the way from the primary samples to the direction (the
/// concentric map divides, and its result feeds the next ray's traversal).
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let r = u.x.sqrt();
    let (s, c) = sin_cos_turns(u.y);
    Vec3::new(r * c, r * s, (1.0 - u.x).max(0.0).sqrt())
}

#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) / PI
}

/// Uniform direction on the unit sphere; pdf = 1/(4π).
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Uniform direction inside a cone of half-angle acos(cos_max) around +z; pdf = 1/(2π(1−cos_max)).
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_t = 1.0 - u.x * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

/// Uniform barycentrics on a triangle (Heitz 2019 low-distortion map would do too).
pub fn square_to_triangle(u: Vec2) -> (f32, f32) {
    let su = u.x.sqrt();
    (1.0 - su, u.y * su)
}

/// Converts an area-measure pdf at `p` (normal `n`) seen from `from` into solid angle.
#[inline]
pub fn area_to_solid_angle(pdf_area: f32, dist2: f32, cos_at_light: f32) -> f32 {
    if cos_at_light <= 0.0 {
        0.0
    } else {
        pdf_area * dist2 / cos_at_light
    }
}

/// Power heuristic with β = 2 (Veach 1997, eq. 9.13).
#[inline]
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 == 0.0 || !a2.is_finite() {
        if a.is_infinite() {
            1.0
        } else {
            0.0
        }
    } else {
        a2 / (a2 + b2)
    }
}

/// Offset along the geometric normal that scales with the magnitude of the point, so that
/// scenes from 1e-4 to 1e5 units do not self-intersect.
#[inline]
pub fn ray_epsilon(p: Vec3) -> f32 {
    1e-4f32.max(p.abs().max_element() * 2e-6)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal() {
        for &n in &[Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.4, 0.866).normalize(), Vec3::X] {
            let f = Frame::from_normal(n);
            assert!((f.s.dot(f.t)).abs() < 1e-5);
            assert!((f.s.dot(f.n)).abs() < 1e-5);
            assert!((f.s.length() - 1.0).abs() < 1e-5);
            let v = Vec3::new(0.2, 0.5, -0.7);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }

    #[test]
    fn power_heuristic_sums_to_one() {
        let (a, b) = (0.3, 1.7);
        assert!((power_heuristic(a, b) + power_heuristic(b, a) - 1.0).abs() < 1e-6);
    }

    /// The quarter-range sine and cosine are as accurate as f32 allows (against f64), and the
    /// concentric map built on them is the trigonometric one (Shirley & Chiu) to 1e-6.
    #[test]
    fn quarter_range_sin_cos_and_the_concentric_map_are_exact_to_float_rounding() {
        let n = 100_000;
        let mut worst = 0.0f64;
        for k in 0..=n {
            let x = (k as f64 / n as f64 * 2.0 - 1.0) * std::f64::consts::FRAC_PI_4;
            let (s, c) = sin_cos_quarter(x as f32);
            worst = worst.max((s as f64 - x.sin()).abs()).max((c as f64 - x.cos()).abs());
        }
        assert!(worst < 2e-7, "largest error {worst}");
        for i in 0..=64 {
            for j in 0..=64 {
                let u = Vec2::new(i as f32 / 64.0, j as f32 / 64.0);
                let o = 2.0 * u - Vec2::ONE;
                let reference = if o.x == 0.0 && o.y == 0.0 {
                    Vec2::ZERO
                } else if o.x.abs() > o.y.abs() {
                    let t = (PI / 4.0) * (o.y / o.x);
                    Vec2::new(o.x * t.cos(), o.x * t.sin())
                } else {
                    let t = PI / 2.0 - (PI / 4.0) * (o.x / o.y);
                    Vec2::new(o.y * t.cos(), o.y * t.sin())
                };
                let d = square_to_disk_concentric(u);
                assert!((d - reference).length() < 1e-6, "{u:?}: {d:?} vs {reference:?}");
            }
        }
    }

    /// sin 2πt and cos 2πt from quarter turns and the polynomials match f64 over the whole
    /// turn (every quarter and its edges), and the cosine hemisphere built on them gives unit
    /// vectors with z = √(1 − u₁) at the polar angle 2πu₂.
    #[test]
    fn full_turn_sin_cos_and_the_cosine_hemisphere_are_exact_to_float_rounding() {
        let n = 400_000;
        let mut worst = 0.0f64;
        for k in 0..=n {
            let t = k as f32 / n as f32;
            let (s, c) = sin_cos_turns(t);
            let x = 2.0 * std::f64::consts::PI * t as f64;
            worst = worst.max((s as f64 - x.sin()).abs()).max((c as f64 - x.cos()).abs());
        }
        assert!(worst < 5e-7, "largest error {worst}");
        for i in 0..=64 {
            for j in 0..=64 {
                let u = Vec2::new(i as f32 / 64.0, j as f32 / 64.0);
                let w = square_to_cosine_hemisphere(u);
                let phi = 2.0 * std::f64::consts::PI * u.y as f64;
                let r = (u.x as f64).sqrt();
                let reference = [r * phi.cos(), r * phi.sin(), (1.0 - u.x as f64).sqrt()];
                for (a, b) in [w.x, w.y, w.z].iter().zip(reference) {
                    assert!((*a as f64 - b).abs() < 1e-6, "{u:?}: {w:?} vs {reference:?}");
                }
                assert!((w.length() - 1.0).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn polynomial_atan2_is_libms() {
        for i in 0..10000 {
            let a = i as f32 * 0.000_628_3 * 1.0001;
            for r in [1e-3f32, 1.0, 7.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                let e = (atan2(y, x) - y.atan2(x)).abs();
                assert!(e < 1e-6, "atan2({y}, {x}): {} vs {}", atan2(y, x), y.atan2(x));
            }
        }
    }
}
