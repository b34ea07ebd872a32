//! Procedural textures as Cycles computes them: Noise (Perlin fBm), Voronoi, Checker and Gradient,
//! evaluated per shading point on the point's coordinates (the mesh's Generated or Object
//! coordinates, or its UV map) after an affine map (Blender's Mapping node and the node's
//! Scale). Bit-for-bit the arithmetic of Cycles' kernel for the same inputs, so a render
//! shows the same pattern at the same place:
//!
//! - Perlin's improved gradient noise (Perlin 2002) on the integer lattice, with gradients
//!   picked by Bob Jenkins' lookup3 hash of the lattice point (the `final` mix, seeded as
//!   Cycles seeds it), the quintic fade, scaled by 0.9820 to about [−1, 1] (the factor OSL's
//!   authors measured); coordinates wrapped every 10⁵ units as Cycles wraps them;
//! - fractal Brownian motion over `detail` octaves (fractional: the last octave blended in),
//!   `roughness` the gain per octave, `lacunarity` the frequency step, normalised to [0, 1];
//!   `distortion` displaces the point by three noises at hashed offsets first, and the Color
//!   output adds two more fBm at hashed offsets;
//! - Voronoi (Worley 1996): per unit cell one feature point at a hashed offset (times
//!   `randomness`), the nearest (F1) or second nearest (F2) of the 27 cells around by the
//!   chosen metric, its distance and a hashed colour per cell; fractal over `detail` octaves
//!   as Cycles sums them, normalised by the largest distance when asked;
//! - Checker: the parity of the integer cells of (p + 10⁻⁶)·(1 − 10⁻⁶) per axis;
//! - Gradient: linear, quadratic, easing, diagonal, radial, spherical and quadratic sphere,
//!   clamped to [0, 1].
//!
//! What follows a pattern in the node graph (Color Ramp, Math, Mix with constants…) is a
//! function of its output alone, so the exporter tabulates it once as a lookup table over the
//! output's range (`Procedural::lut`), interpolated linearly; a colour output passes each
//! channel through the table's channel.

use glam::Vec3;

/// What a pattern computes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pattern {
    /// The Noise Texture node (3D). `color`: its Color output (three noises), else Fac.
    Noise { noise: NoiseParams, color: bool },
    /// The Wave Texture node (Fac; its Color is the same grey).
    Wave(WaveParams),
    /// The Brick Texture node. `color`: its Color output (the bricks' tint between Color1 and
    /// Color2, the mortar's colour over the mortar), else Fac (the mortar's weight).
    Brick { brick: BrickParams, color: bool },
    /// The Voronoi Texture node (3D, F1 or F2). `color`: its Color output, else Distance.
    Voronoi { voronoi: VoronoiParams, color: bool },
    /// The Checker Texture node's Fac (1 in the cells of Color1).
    Checker,
    /// The Gradient Texture node's Fac.
    Gradient(GradientKind),
}

/// The Noise Texture node's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseParams {
    pub kind: NoiseKind,
    pub detail: f32,
    pub roughness: f32,
    pub lacunarity: f32,
    /// The multifractal terrains' offset and gain.
    pub offset: f32,
    pub gain: f32,
    pub distortion: f32,
    /// fBm only: mapped to [0, 1].
    pub normalize: bool,
}

impl NoiseParams {
    /// The node's defaults (fBm, detail 2, roughness ½, lacunarity 2, normalised).
    pub fn fbm(detail: f32, roughness: f32, lacunarity: f32, distortion: f32, normalize: bool) -> NoiseParams {
        NoiseParams {
            kind: NoiseKind::Fbm,
            detail,
            roughness,
            lacunarity,
            offset: 0.0,
            gain: 1.0,
            distortion,
            normalize,
        }
    }
}

/// The Noise Texture node's types (Blender's former Musgrave Texture).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoiseKind {
    Fbm,
    Multifractal,
    HybridMultifractal,
    RidgedMultifractal,
    HeteroTerrain,
}

impl NoiseKind {
    /// Blender's enum identifiers (`ShaderNodeTexNoise.noise_type`).
    pub fn parse(s: &str) -> Option<NoiseKind> {
        Some(match s.to_ascii_uppercase().as_str() {
            "FBM" => NoiseKind::Fbm,
            "MULTIFRACTAL" => NoiseKind::Multifractal,
            "HYBRID_MULTIFRACTAL" => NoiseKind::HybridMultifractal,
            "RIDGED_MULTIFRACTAL" => NoiseKind::RidgedMultifractal,
            "HETERO_TERRAIN" => NoiseKind::HeteroTerrain,
            _ => return None,
        })
    }
}

/// The Wave Texture node's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WaveParams {
    /// Rings (else bands).
    pub rings: bool,
    /// Bands: X, Y, Z, diagonal; rings: X, Y, Z, spherical (0..3).
    pub direction: u8,
    pub profile: WaveProfile,
    pub distortion: f32,
    pub detail: f32,
    pub detail_scale: f32,
    pub detail_roughness: f32,
    pub phase: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WaveProfile {
    Sine,
    Saw,
    Triangle,
}

/// The Brick Texture node's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrickParams {
    pub mortar_size: f32,
    pub mortar_smooth: f32,
    pub bias: f32,
    pub brick_width: f32,
    pub row_height: f32,
    /// Every `offset_frequency`-th row shifted by this fraction of a brick.
    pub offset: f32,
    pub offset_frequency: i32,
    /// Every `squash_frequency`-th row's bricks this much wider.
    pub squash: f32,
    pub squash_frequency: i32,
    pub color1: Vec3,
    pub color2: Vec3,
    pub mortar: Vec3,
}

/// The Voronoi Texture node's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoronoiParams {
    /// F2 (the second nearest point), else F1.
    pub f2: bool,
    pub metric: Metric,
    /// Minkowski's exponent.
    pub exponent: f32,
    pub randomness: f32,
    pub detail: f32,
    pub roughness: f32,
    pub lacunarity: f32,
    pub normalize: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Metric {
    Euclidean,
    Manhattan,
    Chebychev,
    Minkowski,
}

impl Metric {
    /// Blender's enum identifiers (`ShaderNodeTexVoronoi.distance`).
    pub fn parse(s: &str) -> Option<Metric> {
        Some(match s.to_ascii_uppercase().as_str() {
            "EUCLIDEAN" => Metric::Euclidean,
            "MANHATTAN" => Metric::Manhattan,
            "CHEBYCHEV" => Metric::Chebychev,
            "MINKOWSKI" => Metric::Minkowski,
            _ => return None,
        })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GradientKind {
    Linear,
    Quadratic,
    Easing,
    Diagonal,
    Radial,
    QuadraticSphere,
    Spherical,
}

impl GradientKind {
    /// Blender's enum identifiers (`ShaderNodeTexGradient.gradient_type`).
    pub fn parse(s: &str) -> Option<GradientKind> {
        Some(match s.to_ascii_uppercase().as_str() {
            "LINEAR" => GradientKind::Linear,
            "QUADRATIC" => GradientKind::Quadratic,
            "EASING" => GradientKind::Easing,
            "DIAGONAL" => GradientKind::Diagonal,
            "RADIAL" => GradientKind::Radial,
            "QUADRATIC_SPHERE" => GradientKind::QuadraticSphere,
            "SPHERICAL" => GradientKind::Spherical,
            _ => return None,
        })
    }
}

/// The coordinates a pattern reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Space {
    /// The mesh's UV map, as (u, v, 0).
    Uv,
    /// Blender's Generated coordinates: the undeformed mesh in its texture space (the
    /// bounding box by default) as [0, 1]³ (`MeshDesc::corner_generated`).
    Generated,
    /// Object coordinates: the point in the object's own frame (`MeshDesc::corner_object`).
    Object,
}

// --- hashing: Bob Jenkins' lookup3 `final` mix -----------------------------------------------

#[inline]
fn final_mix(mut a: u32, mut b: u32, mut c: u32) -> u32 {
    c ^= b;
    c = c.wrapping_sub(b.rotate_left(14));
    a ^= c;
    a = a.wrapping_sub(c.rotate_left(11));
    b ^= a;
    b = b.wrapping_sub(a.rotate_left(25));
    c ^= b;
    c = c.wrapping_sub(b.rotate_left(16));
    a ^= c;
    a = a.wrapping_sub(c.rotate_left(4));
    b ^= a;
    b = b.wrapping_sub(a.rotate_left(14));
    c ^= b;
    c.wrapping_sub(b.rotate_left(24))
}

/// lookup3's hash of two words (initial state 0xdeadbeef + 4·2 + 13).
#[inline]
pub fn hash2(x: u32, y: u32) -> u32 {
    let s = 0xdeadbeefu32.wrapping_add((2 << 2) + 13);
    final_mix(s.wrapping_add(x), s.wrapping_add(y), s)
}

/// lookup3's hash of three words (initial state 0xdeadbeef + 4·3 + 13).
#[inline]
pub fn hash3(x: u32, y: u32, z: u32) -> u32 {
    let s = 0xdeadbeefu32.wrapping_add((3 << 2) + 13);
    final_mix(s.wrapping_add(x), s.wrapping_add(y), s.wrapping_add(z))
}

#[inline]
fn unit(h: u32) -> f32 {
    h as f32 * (1.0 / u32::MAX as f32)
}

/// A hash of two floats' bit patterns into [0, 1] (both ends included).
fn hash_floats_to_unit(x: f32, y: f32) -> f32 {
    unit(hash2(x.to_bits(), y.to_bits()))
}

/// Three hashes in [0, 1] of an integer cell (a Voronoi cell's feature point and colour):
/// the 3D PCG hash of Jarzynski & Olano 2020 on signed integers, as Cycles computes it.
fn hash_cell_to_unit3(c: [i32; 3]) -> Vec3 {
    let mut v = c.map(|x| x.wrapping_mul(1664525).wrapping_add(1013904223));
    let round = |v: &mut [i32; 3]| {
        v[0] = v[0].wrapping_add(v[1].wrapping_mul(v[2]));
        v[1] = v[1].wrapping_add(v[2].wrapping_mul(v[0]));
        v[2] = v[2].wrapping_add(v[0].wrapping_mul(v[1]));
    };
    round(&mut v);
    v = v.map(|x| x ^ (x >> 16));
    round(&mut v);
    Vec3::from_array(v.map(|x| (x & 0x7FFFFFFF) as f32 * (1.0 / 0x7FFFFFFF as f32)))
}

/// The offset in [100, 200]³ that seeds one of a noise's decorrelated copies.
fn seed_offset(seed: f32) -> Vec3 {
    Vec3::new(
        100.0 + hash_floats_to_unit(seed, 0.0) * 100.0,
        100.0 + hash_floats_to_unit(seed, 1.0) * 100.0,
        100.0 + hash_floats_to_unit(seed, 2.0) * 100.0,
    )
}

// --- Perlin noise ----------------------------------------------------------------------------

#[inline]
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// The dot product of the point's offset with one of 12 edge gradients (16 hash values).
#[inline]
fn grad3(hash: u32, x: f32, y: f32, z: f32) -> f32 {
    let h = hash & 15;
    let u = if h < 8 { x } else { y };
    let v = if h < 4 {
        y
    } else if h == 12 || h == 14 {
        x
    } else {
        z
    };
    (if h & 1 != 0 { -u } else { u }) + (if h & 2 != 0 { -v } else { v })
}

#[inline]
fn floor_frac(x: f32) -> (i32, f32) {
    let f = x.floor();
    (f as i32, x - f)
}

/// Perlin's improved noise at `p`, unscaled (about ±1.02).
fn perlin(p: Vec3) -> f32 {
    let (ix, fx) = floor_frac(p.x);
    let (iy, fy) = floor_frac(p.y);
    let (iz, fz) = floor_frac(p.z);
    let (u, v, w) = (fade(fx), fade(fy), fade(fz));
    let g = |dx: i32, dy: i32, dz: i32| {
        let h = hash3(ix.wrapping_add(dx) as u32, iy.wrapping_add(dy) as u32, iz.wrapping_add(dz) as u32);
        grad3(h, fx - dx as f32, fy - dy as f32, fz - dz as f32)
    };
    let (x1, y1, z1) = (1.0 - u, 1.0 - v, 1.0 - w);
    z1 * (y1 * (g(0, 0, 0) * x1 + g(1, 0, 0) * u) + v * (g(0, 1, 0) * x1 + g(1, 1, 0) * u))
        + w * (y1 * (g(0, 0, 1) * x1 + g(1, 0, 1) * u) + v * (g(0, 1, 1) * x1 + g(1, 1, 1) * u))
}

/// Signed noise in about [−1, 1], the coordinates wrapped every 10⁵ (half a cell further
/// beyond 10⁶), as Cycles' `snoise_3d`.
pub fn snoise(p: Vec3) -> f32 {
    // (fmod only where it changes something: below 10⁵ it returns x itself)
    let wrap = |x: f32| {
        if x.abs() < 100000.0 {
            x
        } else {
            x % 100000.0 + if x.abs() >= 1000000.0 { 0.5 } else { 0.0 }
        }
    };
    0.9820 * perlin(Vec3::new(wrap(p.x), wrap(p.y), wrap(p.z)))
}

/// Fractal Brownian motion: `detail` octaves (the fractional part blends the next in).
pub fn fbm(p: Vec3, detail: f32, roughness: f32, lacunarity: f32, normalize: bool) -> f32 {
    let (mut fscale, mut amp, mut maxamp, mut sum) = (1.0f32, 1.0f32, 0.0f32, 0.0f32);
    for _ in 0..=(detail as i32) {
        sum += snoise(fscale * p) * amp;
        maxamp += amp;
        amp *= roughness;
        fscale *= lacunarity;
    }
    let rmd = detail - detail.floor();
    if rmd != 0.0 {
        let sum2 = sum + snoise(fscale * p) * amp;
        return if normalize {
            mix(0.5 * sum / maxamp + 0.5, 0.5 * sum2 / (maxamp + amp) + 0.5, rmd)
        } else {
            mix(sum, sum2, rmd)
        };
    }
    if normalize {
        0.5 * sum / maxamp + 0.5
    } else {
        sum
    }
}

/// Multifractal: the product of (1 + amplitude·noise) over the octaves.
fn multifractal(mut p: Vec3, detail: f32, roughness: f32, lacunarity: f32) -> f32 {
    let (mut value, mut pwr) = (1.0f32, 1.0f32);
    for _ in 0..=(detail as i32) {
        value *= pwr * snoise(p) + 1.0;
        pwr *= roughness;
        p *= lacunarity;
    }
    let rmd = detail - detail.floor();
    if rmd != 0.0 {
        value *= rmd * pwr * snoise(p) + 1.0;
    }
    value
}

/// Heterogeneous terrain: each octave's increment scaled by the value so far.
fn hetero_terrain(mut p: Vec3, detail: f32, roughness: f32, lacunarity: f32, offset: f32) -> f32 {
    let mut pwr = roughness;
    let mut value = offset + snoise(p);
    p *= lacunarity;
    for _ in 1..=(detail as i32) {
        value += (snoise(p) + offset) * pwr * value;
        pwr *= roughness;
        p *= lacunarity;
    }
    let rmd = detail - detail.floor();
    if rmd != 0.0 {
        value += rmd * (snoise(p) + offset) * pwr * value;
    }
    value
}

/// Hybrid additive/multiplicative multifractal terrain.
fn hybrid_multifractal(mut p: Vec3, detail: f32, roughness: f32, lacunarity: f32, offset: f32, gain: f32) -> f32 {
    let (mut pwr, mut value, mut weight) = (1.0f32, 0.0f32, 1.0f32);
    let mut i = 0;
    while weight > 0.001 && i <= detail as i32 {
        weight = weight.min(1.0);
        let signal = (snoise(p) + offset) * pwr;
        pwr *= roughness;
        value += weight * signal;
        weight *= gain * signal;
        p *= lacunarity;
        i += 1;
    }
    let rmd = detail - detail.floor();
    if rmd != 0.0 && weight > 0.001 {
        weight = weight.min(1.0);
        value += rmd * weight * (snoise(p) + offset) * pwr;
    }
    value
}

/// Ridged multifractal terrain (whole octaves only, as Cycles).
fn ridged_multifractal(mut p: Vec3, detail: f32, roughness: f32, lacunarity: f32, offset: f32, gain: f32) -> f32 {
    let mut pwr = roughness;
    let mut signal = offset - snoise(p).abs();
    signal *= signal;
    let mut value = signal;
    for _ in 1..=(detail as i32) {
        p *= lacunarity;
        let weight = (signal * gain).clamp(0.0, 1.0);
        signal = offset - snoise(p).abs();
        signal *= signal;
        signal *= weight;
        value += signal * pwr;
        pwr *= roughness;
    }
    value
}

/// The Noise node's fractal of its type at `p`.
fn noise_select(p: Vec3, n: &NoiseParams) -> f32 {
    match n.kind {
        NoiseKind::Fbm => fbm(p, n.detail, n.roughness, n.lacunarity, n.normalize),
        NoiseKind::Multifractal => multifractal(p, n.detail, n.roughness, n.lacunarity),
        NoiseKind::HybridMultifractal => hybrid_multifractal(p, n.detail, n.roughness, n.lacunarity, n.offset, n.gain),
        NoiseKind::RidgedMultifractal => ridged_multifractal(p, n.detail, n.roughness, n.lacunarity, n.offset, n.gain),
        NoiseKind::HeteroTerrain => hetero_terrain(p, n.detail, n.roughness, n.lacunarity, n.offset),
    }
}

/// The Wave Texture node at `p` (already scaled): its Fac.
pub fn wave_texture(p: Vec3, w: &WaveParams) -> f32 {
    use std::f32::consts::{FRAC_PI_2, TAU};
    let p = (p + Vec3::splat(0.000001)) * 0.999999;
    let mut n = if !w.rings {
        match w.direction {
            0 => p.x * 20.0,
            1 => p.y * 20.0,
            2 => p.z * 20.0,
            _ => (p.x + p.y + p.z) * 10.0,
        }
    } else {
        let keep = match w.direction {
            0 => Vec3::new(0.0, 1.0, 1.0),
            1 => Vec3::new(1.0, 0.0, 1.0),
            2 => Vec3::new(1.0, 1.0, 0.0),
            _ => Vec3::ONE,
        };
        (p * keep).length() * 20.0
    };
    n += w.phase;
    if w.distortion != 0.0 {
        n += w.distortion * (fbm(p * w.detail_scale, w.detail, w.detail_roughness, 2.0, true) * 2.0 - 1.0);
    }
    match w.profile {
        WaveProfile::Sine => 0.5 + 0.5 * (n - FRAC_PI_2).sin(),
        WaveProfile::Saw => {
            let n = n / TAU;
            n - n.floor()
        }
        WaveProfile::Triangle => {
            let n = n / TAU;
            (n - (n + 0.5).floor()).abs() * 2.0
        }
    }
}

#[inline]
fn mix(a: f32, b: f32, t: f32) -> f32 {
    (1.0 - t) * a + t * b
}

/// The Noise Texture node (3D) at `p` (already scaled): its Fac, and with `color` its
/// Color (two more noises; else the Fac in all three channels).
pub fn noise_texture(p: Vec3, n: &NoiseParams, color: bool) -> (f32, Vec3) {
    let n = NoiseParams { detail: n.detail.clamp(0.0, 15.0), roughness: n.roughness.max(0.0), ..*n };
    let distortion = n.distortion;
    let mut p = p;
    if distortion != 0.0 {
        p += Vec3::new(
            snoise(p + seed_offset(0.0)) * distortion,
            snoise(p + seed_offset(1.0)) * distortion,
            snoise(p + seed_offset(2.0)) * distortion,
        );
    }
    let value = noise_select(p, &n);
    if !color {
        return (value, Vec3::splat(value));
    }
    (value, Vec3::new(value, noise_select(p + seed_offset(3.0), &n), noise_select(p + seed_offset(4.0), &n)))
}

fn voronoi_distance(a: Vec3, b: Vec3, v: &VoronoiParams) -> f32 {
    let d = (a - b).abs();
    match v.metric {
        Metric::Euclidean => a.distance(b),
        Metric::Manhattan => d.x + d.y + d.z,
        Metric::Chebychev => d.max_element(),
        Metric::Minkowski => {
            (d.x.powf(v.exponent) + d.y.powf(v.exponent) + d.z.powf(v.exponent)).powf(1.0 / v.exponent)
        }
    }
}

/// One octave: (distance, colour) of the nearest (F1) or second nearest (F2) feature point.
fn voronoi_octave(p: Vec3, v: &VoronoiParams) -> (f32, Vec3) {
    let cell_f = p.floor();
    let local = p - cell_f;
    let cell = [cell_f.x as i32, cell_f.y as i32, cell_f.z as i32];
    let at = |o: [i32; 3]| [cell[0].wrapping_add(o[0]), cell[1].wrapping_add(o[1]), cell[2].wrapping_add(o[2])];
    let (mut d1, mut d2) = (f32::MAX, f32::MAX);
    let (mut o1, mut o2) = ([0i32; 3], [0i32; 3]);
    for k in -1..=1 {
        for j in -1..=1 {
            for i in -1..=1 {
                let offset = [i, j, k];
                let point = Vec3::new(i as f32, j as f32, k as f32) + hash_cell_to_unit3(at(offset)) * v.randomness;
                let d = voronoi_distance(point, local, v);
                if d < d1 {
                    (d2, o2) = (d1, o1);
                    (d1, o1) = (d, offset);
                } else if d < d2 {
                    (d2, o2) = (d, offset);
                }
            }
        }
    }
    let (d, o) = if v.f2 { (d2, o2) } else { (d1, o1) };
    (d, hash_cell_to_unit3(at(o)))
}

/// The Voronoi Texture node (3D, F1/F2) at `p` (already scaled): (Distance, Color).
pub fn voronoi_texture(p: Vec3, v: &VoronoiParams) -> (f32, Vec3) {
    let v = VoronoiParams {
        detail: v.detail.clamp(0.0, 15.0),
        roughness: v.roughness.clamp(0.0, 1.0),
        randomness: v.randomness.clamp(0.0, 1.0),
        ..*v
    };
    let max_distance =
        voronoi_distance(Vec3::ZERO, Vec3::splat(0.5 + 0.5 * v.randomness), &v) * if v.f2 { 2.0 } else { 1.0 };
    let single = v.detail == 0.0 || v.roughness == 0.0 || v.lacunarity == 0.0;
    let (mut amp, mut max_amp, mut scale) = (1.0f32, 0.0f32, 1.0f32);
    let (mut dist, mut color) = (0.0f32, Vec3::ZERO);
    for i in 0..=(v.detail.ceil() as i32) {
        let (d, c) = voronoi_octave(p * scale, &v);
        if single {
            (max_amp, dist, color) = (1.0, d, c);
            break;
        } else if i as f32 <= v.detail {
            max_amp += amp;
            dist += d * amp;
            color += c * amp;
            scale *= v.lacunarity;
            amp *= v.roughness;
        } else {
            let rmd = v.detail - v.detail.floor();
            if rmd != 0.0 {
                max_amp = mix(max_amp, max_amp + amp, rmd);
                dist = mix(dist, dist + d * amp, rmd);
                color = color.lerp(color + c * amp, rmd);
            }
        }
    }
    if v.normalize {
        dist /= max_amp * max_distance;
        color /= max_amp;
    }
    (dist, color)
}

/// Cycles' integer noise of a brick's number: in [0, 1).
fn brick_noise(n: u32) -> f32 {
    let mut n = n.wrapping_add(1013) & 0x7fffffff;
    n ^= n >> 13;
    let nn = n.wrapping_mul(n.wrapping_mul(n).wrapping_mul(60493).wrapping_add(19990303)).wrapping_add(1376312589)
        & 0x7fffffff;
    0.5 * (nn as f32 / 1073741824.0)
}

/// The Brick Texture node at `p` (already scaled): (the brick's tint, the mortar's weight).
pub fn brick(p: Vec3, b: &BrickParams) -> (f32, f32) {
    let row = (p.y / b.row_height).floor() as i32;
    let (mut width, mut offset) = (b.brick_width, 0.0);
    if b.offset_frequency != 0 && b.squash_frequency != 0 {
        width *= if row % b.squash_frequency != 0 { 1.0 } else { b.squash };
        offset = if row % b.offset_frequency != 0 { 0.0 } else { width * b.offset };
    }
    let number = ((p.x + offset) / width).floor() as i32;
    let x = (p.x + offset) - width * number as f32;
    let y = p.y - b.row_height * row as f32;
    let key = (row.wrapping_shl(16)).wrapping_add(number & 0xFFFF) as u32;
    let tint = (brick_noise(key) + b.bias).clamp(0.0, 1.0);
    let min_dist = x.min(y).min((width - x).min(b.row_height - y));
    let mortar = if min_dist >= b.mortar_size {
        0.0
    } else if b.mortar_smooth == 0.0 {
        1.0
    } else {
        let f = (1.0 - min_dist / b.mortar_size) / b.mortar_smooth;
        if f <= 0.0 {
            0.0
        } else if f >= 1.0 {
            1.0
        } else {
            3.0 * f * f - 2.0 * f * f * f
        }
    };
    (tint, mortar)
}

/// The Brick Texture node's Color from (tint, mortar weight).
fn brick_color(b: &BrickParams, tint: f32, mortar: f32) -> Vec3 {
    let c1 = if mortar != 1.0 { b.color1 * (1.0 - tint) + b.color2 * tint } else { b.color1 };
    c1 * (1.0 - mortar) + b.mortar * mortar
}

/// The Checker Texture node's Fac at `p` (already scaled): 1 or 0.
pub fn checker(p: Vec3) -> f32 {
    let cell = |x: f32| (((x + 0.000001) * 0.999999).floor() as i32).unsigned_abs() % 2;
    let (x, y, z) = (cell(p.x), cell(p.y), cell(p.z));
    if (x == y) == (z == 1) {
        1.0
    } else {
        0.0
    }
}

/// The Gradient Texture node's Fac at `p`, in [0, 1].
pub fn gradient(p: Vec3, kind: GradientKind) -> f32 {
    let f = match kind {
        GradientKind::Linear => p.x,
        GradientKind::Quadratic => p.x.max(0.0).powi(2),
        GradientKind::Easing => {
            let r = p.x.clamp(0.0, 1.0);
            let t = r * r;
            3.0 * t - 2.0 * t * r
        }
        GradientKind::Diagonal => (p.x + p.y) * 0.5,
        GradientKind::Radial => p.y.atan2(p.x) / std::f32::consts::TAU + 0.5,
        GradientKind::QuadraticSphere | GradientKind::Spherical => {
            // (0.999999: a unit vector gives exactly 0, as in Cycles)
            let r = (0.999999 - (p.x * p.x + p.y * p.y + p.z * p.z).sqrt()).max(0.0);
            if kind == GradientKind::Spherical {
                r
            } else {
                r * r
            }
        }
    };
    f.clamp(0.0, 1.0)
}

/// A pattern on its coordinates, followed by the graph after it as a lookup table.
#[derive(Clone, Debug)]
pub struct Procedural {
    pub pattern: Pattern,
    pub space: Space,
    /// Row-major 3×4 affine map of the coordinates (Mapping node, then the node's Scale).
    pub transform: [f32; 12],
    /// The table's range of the pattern's output: entry 0 at `domain.0`, the last at `domain.1`.
    pub domain: (f32, f32),
}

impl Procedural {
    /// The pattern's output at coordinates `point` (before the transform): its Fac in all
    /// three channels, or its colour.
    pub fn output(&self, point: Vec3) -> Vec3 {
        self.pattern_at(self.to_pattern(point))
    }

    /// Coordinates `point` in the pattern's own space (after the transform).
    #[inline]
    pub fn to_pattern(&self, point: Vec3) -> Vec3 {
        let m = &self.transform;
        Vec3::new(
            m[0] * point.x + m[1] * point.y + m[2] * point.z + m[3],
            m[4] * point.x + m[5] * point.y + m[6] * point.z + m[7],
            m[8] * point.x + m[9] * point.y + m[10] * point.z + m[11],
        )
    }

    /// A gradient `g` in the pattern's space brought back to the coordinates' (Mᵀ·g).
    #[inline]
    pub fn gradient_to_coordinates(&self, g: Vec3) -> Vec3 {
        let m = &self.transform;
        Vec3::new(
            m[0] * g.x + m[4] * g.y + m[8] * g.z,
            m[1] * g.x + m[5] * g.y + m[9] * g.z,
            m[2] * g.x + m[6] * g.y + m[10] * g.z,
        )
    }

    /// The pattern's output at `p` in its own space.
    pub fn pattern_at(&self, p: Vec3) -> Vec3 {
        match self.pattern {
            Pattern::Noise { noise, color } => noise_texture(p, &noise, color).1,
            Pattern::Voronoi { voronoi, color } => {
                let (d, c) = voronoi_texture(p, &voronoi);
                if color {
                    c
                } else {
                    Vec3::splat(d)
                }
            }
            Pattern::Wave(wave) => Vec3::splat(wave_texture(p, &wave)),
            Pattern::Brick { brick: b, color } => {
                let (tint, mortar) = brick(p, &b);
                if color {
                    brick_color(&b, tint, mortar)
                } else {
                    Vec3::splat(mortar)
                }
            }
            Pattern::Checker => Vec3::splat(checker(p)),
            Pattern::Gradient(kind) => Vec3::splat(gradient(p, kind)),
        }
    }

    /// The range of the pattern's output channels over 32768 points spread through a cube of
    /// 200 lattice cells (its patterns are the same everywhere), widened by 2% each side: the
    /// domain of the table of a pattern whose bounds have no closed form (the multifractal
    /// noises).
    pub fn sampled_range(&self) -> (f32, f32) {
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for i in 0..32768u32 {
            let p = Vec3::new(unit(hash3(i, 0, 7)), unit(hash3(i, 1, 7)), unit(hash3(i, 2, 7))) * 200.0 - 100.0;
            let v = self.pattern_at(p);
            if v.is_finite() {
                (lo, hi) = (lo.min(v.min_element()), hi.max(v.max_element()));
            }
        }
        if lo > hi {
            return (0.0, 1.0);
        }
        let margin = 0.02 * (hi - lo).max(1e-6);
        (lo - margin, hi + margin)
    }

    /// Where `s` falls in a table of `n` entries over the domain: (entry, weight of the next).
    #[inline]
    pub fn table_position(&self, s: f32, n: usize) -> (usize, f32) {
        let (lo, hi) = self.domain;
        let x = if hi > lo { ((s - lo) / (hi - lo)).clamp(0.0, 1.0) } else { 0.0 } * (n - 1) as f32;
        let x = if x.is_finite() { x } else { 0.0 };
        let i = (x as usize).min(n.saturating_sub(2));
        (i, (x - i as f32).min(1.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// lookup3's published test vectors are for `hashword`; the `final` mix alone is checked
    /// by its defining property here and by the pattern tests below against Cycles' own
    /// renders (tests/test_blender.py). These pin the values so a change is noticed.
    #[test]
    fn hash_is_deterministic_and_spreads_neighbours() {
        assert_eq!(hash3(0, 0, 0), hash3(0, 0, 0));
        let hs: Vec<u32> = (0..64).map(|i| hash3(i, 0, 0)).collect();
        let mut sorted = hs.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), 64, "neighbouring lattice points share a hash");
        // about half the bits flip between neighbours (avalanche)
        let flips: u32 = hs.windows(2).map(|w| (w[0] ^ w[1]).count_ones()).sum();
        let mean = flips as f64 / 63.0;
        assert!((12.0..20.0).contains(&mean), "mean bit flips {mean}");
    }

    #[test]
    fn perlin_vanishes_on_the_lattice_and_is_continuous() {
        for p in [Vec3::ZERO, Vec3::new(3.0, -7.0, 12.0), Vec3::new(-1.0, 5.0, -2.0)] {
            assert_eq!(perlin(p), 0.0);
        }
        // continuity across a cell face, and values within about ±1
        let mut max = 0.0f32;
        for i in 0..2000 {
            let t = i as f32 * 0.0137;
            let p = Vec3::new(t * 1.3 - 7.1, t * 0.7 + 0.2, -t * 0.9 + 3.3);
            let (a, b) = (snoise(p), snoise(p + Vec3::splat(1e-4)));
            assert!((a - b).abs() < 2e-3, "jump at {p}: {a} {b}");
            max = max.max(a.abs());
        }
        assert!(max > 0.4 && max <= 1.05, "range {max}");
    }

    #[test]
    fn fbm_of_fractional_detail_blends_the_octaves_around_it() {
        let p = Vec3::new(0.3, 1.7, -2.2);
        let (a, b) = (fbm(p, 2.0, 0.5, 2.0, true), fbm(p, 3.0, 0.5, 2.0, true));
        let mid = fbm(p, 2.25, 0.5, 2.0, true);
        assert!((mid - (0.75 * a + 0.25 * b)).abs() < 1e-6);
        // detail 0 is one octave: the noise itself, mapped to [0, 1]
        assert!((fbm(p, 0.0, 0.5, 2.0, true) - (0.5 * snoise(p) + 0.5)).abs() < 1e-7);
        assert!((fbm(p, 0.0, 0.5, 2.0, false) - snoise(p)).abs() < 1e-7);
        // normalised fBm stays within [0, 1] and averages about ½
        let vals: Vec<f32> =
            (0..4000).map(|i| fbm(Vec3::new(i as f32 * 0.173, i as f32 * 0.071, 0.5), 6.0, 0.6, 2.0, true)).collect();
        let mean = vals.iter().sum::<f32>() / vals.len() as f32;
        assert!(vals.iter().all(|v| (-0.01..=1.01).contains(v)));
        assert!((mean - 0.5).abs() < 0.03, "mean {mean}");
    }

    #[test]
    fn distortion_moves_the_pattern_and_colour_channels_differ() {
        let p = Vec3::new(1.3, 0.4, 2.9);
        let (v0, c0) = noise_texture(p, &NoiseParams::fbm(2.0, 0.5, 2.0, 0.0, true), true);
        let (v1, _) = noise_texture(p, &NoiseParams::fbm(2.0, 0.5, 2.0, 1.0, true), true);
        assert_eq!(noise_texture(p, &NoiseParams::fbm(2.0, 0.5, 2.0, 0.0, true), false), (v0, Vec3::splat(v0)));
        // the wrap every 10⁵ leaves smaller coordinates as they are
        assert_eq!(snoise(Vec3::new(99999.5, 3.3, -7.7)), 0.9820 * perlin(Vec3::new(99999.5, 3.3, -7.7)));
        assert_eq!(snoise(Vec3::new(100000.25, 3.3, 0.0)), 0.9820 * perlin(Vec3::new(0.25, 3.3, 0.0)));
        assert_eq!(c0.x, v0);
        assert!(v0 != v1 && c0.y != c0.x && c0.z != c0.y);
        // the seed offsets lie in [100, 200]
        for s in 0..5 {
            let o = seed_offset(s as f32);
            assert!(o.cmpge(Vec3::splat(100.0)).all() && o.cmple(Vec3::splat(200.0)).all());
        }
    }

    fn voronoi(f2: bool, metric: Metric) -> VoronoiParams {
        VoronoiParams {
            f2,
            metric,
            exponent: 0.5,
            randomness: 1.0,
            detail: 0.0,
            roughness: 0.5,
            lacunarity: 2.0,
            normalize: false,
        }
    }

    /// F1 is the distance to the nearest feature point, F2 to the second: checked against a
    /// brute-force search over the 5³ cells around; the colour is constant within a cell's
    /// region and the distance vanishes at the feature points.
    #[test]
    fn voronoi_finds_the_nearest_feature_points() {
        let points = |c: Vec3| {
            (-2..=2).flat_map(move |k| {
                (-2..=2).flat_map(move |j| {
                    (-2..=2).map(move |i| {
                        let cell = c.floor() + Vec3::new(i as f32, j as f32, k as f32);
                        cell + hash_cell_to_unit3([cell.x as i32, cell.y as i32, cell.z as i32])
                    })
                })
            })
        };
        let mut exact_f2 = 0;
        for n in 0..300 {
            let p = Vec3::new(n as f32 * 0.377 - 40.0, n as f32 * 0.213 + 3.1, -(n as f32) * 0.119);
            let mut d: Vec<f32> = points(p).map(|q| q.distance(p)).collect();
            d.sort_by(|a, b| a.partial_cmp(b).unwrap());
            let (f1, _) = voronoi_texture(p, &voronoi(false, Metric::Euclidean));
            let (f2, _) = voronoi_texture(p, &voronoi(true, Metric::Euclidean));
            assert!((f1 - d[0]).abs() < 1e-5, "{p}: {f1} vs {}", d[0]);
            // (the 27 cells around may miss the true second point, rarely: never nearer)
            assert!(f2 >= d[1] - 1e-5, "{p}: {f2} vs {}", d[1]);
            exact_f2 += usize::from((f2 - d[1]).abs() < 1e-5);
            let m = |metric| voronoi_texture(p, &voronoi(false, metric)).0;
            assert!(m(Metric::Chebychev) <= f1 + 1e-6 && f1 <= m(Metric::Manhattan) + 1e-6);
        }
        assert!(exact_f2 >= 290, "{exact_f2}");
        let site = Vec3::new(3.0, -2.0, 5.0) + hash_cell_to_unit3([3, -2, 5]);
        let (d, c) = voronoi_texture(site, &voronoi(false, Metric::Euclidean));
        assert!(d < 1e-5);
        assert_eq!(c, hash_cell_to_unit3([3, -2, 5]));
        // normalised F1 of randomness 1 lies within [0, 1] for the most part
        let mut v = voronoi(false, Metric::Euclidean);
        v.normalize = true;
        let vals: Vec<f32> =
            (0..2000).map(|i| voronoi_texture(Vec3::new(i as f32 * 0.37, i as f32 * 0.11, 0.5), &v).0).collect();
        assert!(vals.iter().all(|&x| (0.0..1.2).contains(&x)));
        // fractional detail blends the octaves around it, as for noise
        let at = |detail| {
            let v = VoronoiParams { detail, ..voronoi(false, Metric::Euclidean) };
            voronoi_texture(Vec3::new(0.3, 1.7, -2.2), &v).0
        };
        assert!((at(1.25) - (0.75 * at(1.0) + 0.25 * at(2.0))).abs() < 1e-5);
    }

    /// At detail 0 each multifractal type is its first octave's formula; the sampled range
    /// holds what the pattern gives elsewhere.
    #[test]
    fn noise_types_start_from_their_first_octave() {
        let p = Vec3::new(0.37, -1.21, 2.9);
        let n = snoise(p);
        let with = |kind| NoiseParams {
            kind,
            detail: 0.0,
            offset: 0.8,
            gain: 1.5,
            ..NoiseParams::fbm(0.0, 0.5, 2.0, 0.0, true)
        };
        let at = |kind| noise_texture(p, &with(kind), false).0;
        assert!((at(NoiseKind::Multifractal) - (1.0 + n)).abs() < 1e-6);
        assert!((at(NoiseKind::RidgedMultifractal) - (0.8 - n.abs()).powi(2)).abs() < 1e-6);
        assert!((at(NoiseKind::HeteroTerrain) - (0.8 + n)).abs() < 1e-6);
        assert!((at(NoiseKind::HybridMultifractal) - (n + 0.8)).abs() < 1e-6);
        let pr = Procedural {
            pattern: Pattern::Noise {
                noise: NoiseParams { kind: NoiseKind::Multifractal, ..NoiseParams::fbm(4.0, 0.6, 2.0, 0.0, true) },
                color: false,
            },
            space: Space::Generated,
            transform: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            domain: (0.0, 1.0),
        };
        let (lo, hi) = pr.sampled_range();
        assert!(lo < 0.5 && hi > 1.5, "{lo} {hi}");
        let inside = (0..5000)
            .filter(|&i| {
                let v = pr.pattern_at(Vec3::new(i as f32 * 0.731 + 500.0, i as f32 * 0.117, -(i as f32) * 0.31)).x;
                (lo..=hi).contains(&v)
            })
            .count();
        assert!(inside >= 4990, "{inside}");
    }

    /// Wave bands and rings follow their profiles: a sine band is ½ − ½·cos(20x) (after the
    /// 10⁻⁶ nudge), a saw rises from 0 to 1 over 2π/20, a triangle peaks at half a period.
    #[test]
    fn waves_follow_their_profiles() {
        let w = |rings, direction, profile| WaveParams {
            rings,
            direction,
            profile,
            distortion: 0.0,
            detail: 2.0,
            detail_scale: 1.0,
            detail_roughness: 0.5,
            phase: 0.0,
        };
        let nudge = |x: f32| (x + 0.000001) * 0.999999;
        for x in [0.0f32, 0.05, 0.1, 0.3, 0.77] {
            let p = Vec3::new(x, 0.4, -0.2);
            let sine = wave_texture(p, &w(false, 0, WaveProfile::Sine));
            assert!((sine - (0.5 - 0.5 * (20.0 * nudge(x)).cos())).abs() < 1e-5, "{x}");
            let saw = wave_texture(p, &w(false, 0, WaveProfile::Saw));
            let t = 20.0 * nudge(x) / std::f32::consts::TAU;
            assert!((saw - (t - t.floor())).abs() < 1e-5);
            let tri = wave_texture(p, &w(false, 0, WaveProfile::Triangle));
            assert!((tri - 2.0 * (t - (t + 0.5).floor()).abs()).abs() < 1e-5);
        }
        // rings around Z ignore z; spherical rings see all three
        let a = wave_texture(Vec3::new(0.3, 0.4, 0.0), &w(true, 2, WaveProfile::Sine));
        let b = wave_texture(Vec3::new(0.3, 0.4, 5.0), &w(true, 2, WaveProfile::Sine));
        assert!((a - b).abs() < 1e-5);
        let c = wave_texture(Vec3::new(0.3, 0.4, 0.2), &w(true, 3, WaveProfile::Sine));
        assert!((a - c).abs() > 1e-3);
    }

    /// Bricks: mortar along the rows' and bricks' edges (smoothly within the mortar when
    /// asked), every other row offset, the tint constant within a brick and varying between.
    #[test]
    fn bricks_lie_in_offset_rows_between_mortar() {
        let b = BrickParams {
            mortar_size: 0.02,
            mortar_smooth: 0.0,
            bias: 0.0,
            brick_width: 0.5,
            row_height: 0.25,
            offset: 0.5,
            offset_frequency: 2,
            squash: 1.0,
            squash_frequency: 2,
            color1: Vec3::ZERO,
            color2: Vec3::ONE,
            mortar: Vec3::new(5.0, 0.0, 0.0),
        };
        // row 1 (y in [0.25, 0.5)) is not offset: bricks start at x = 0, 0.5, …
        assert_eq!(brick(Vec3::new(0.25, 0.375, 0.0), &b).1, 0.0);
        assert_eq!(brick(Vec3::new(0.51, 0.375, 0.0), &b).1, 1.0);
        assert_eq!(brick(Vec3::new(0.25, 0.26, 0.0), &b).1, 1.0);
        // row 0 (and row 2) is offset by a quarter: its joints at x = 0.25, 0.75
        assert_eq!(brick(Vec3::new(0.5, 0.125, 0.0), &b).1, 0.0);
        assert_eq!(brick(Vec3::new(0.26, 0.125, 0.0), &b).1, 1.0);
        let t = |x, y| brick(Vec3::new(x, y, 0.0), &b).0;
        assert_eq!(t(0.1, 0.3), t(0.4, 0.45));
        let tints: Vec<f32> = (0..20).map(|i| t(0.25 + 0.5 * i as f32, 0.375)).collect();
        assert!(tints.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(tints.windows(2).filter(|w| w[0] != w[1]).count() > 15);
        assert_eq!(brick_color(&b, 0.3, 1.0), Vec3::new(5.0, 0.0, 0.0));
        assert_eq!(brick_color(&b, 0.3, 0.0), Vec3::splat(0.3));
        let smooth = BrickParams { mortar_smooth: 0.5, ..b };
        let m = brick(Vec3::new(0.515, 0.375, 0.0), &smooth).1; // a quarter into the mortar: ½
        assert!((m - 0.5).abs() < 1e-3, "{m}");
    }

    #[test]
    fn checker_alternates_per_cell_in_every_axis() {
        let c = |x: f32, y: f32, z: f32| checker(Vec3::new(x, y, z));
        assert_eq!(c(0.5, 0.5, 0.5), 0.0);
        assert_eq!(c(1.5, 0.5, 0.5), 1.0);
        assert_eq!(c(0.5, 1.5, 0.5), 1.0);
        assert_eq!(c(0.5, 0.5, 1.5), 1.0);
        assert_eq!(c(1.5, 1.5, 0.5), 0.0);
        // negative cells: floor, then |·|, so cell −1 is odd like cell 1
        assert_eq!(c(-0.5, 0.5, 0.5), 1.0);
        assert_eq!(c(-1.5, 0.5, 0.5), 0.0);
    }

    #[test]
    fn gradients_follow_their_formulas() {
        let g = |x: f32, y: f32, z: f32, k| gradient(Vec3::new(x, y, z), k);
        assert_eq!(g(0.3, 9.0, 9.0, GradientKind::Linear), 0.3);
        assert_eq!(g(1.7, 0.0, 0.0, GradientKind::Linear), 1.0);
        assert!((g(0.5, 0.0, 0.0, GradientKind::Quadratic) - 0.25).abs() < 1e-7);
        assert!((g(0.5, 0.0, 0.0, GradientKind::Easing) - 0.5).abs() < 1e-7);
        assert!((g(0.2, 0.6, 0.0, GradientKind::Diagonal) - 0.4).abs() < 1e-7);
        assert!((g(0.0, 1.0, 0.0, GradientKind::Radial) - 0.75).abs() < 1e-6);
        assert!((g(0.0, 0.0, 0.5, GradientKind::Spherical) - 0.499999).abs() < 1e-6);
        assert!((g(0.0, 0.0, 0.5, GradientKind::QuadraticSphere) - 0.499999f32.powi(2)).abs() < 1e-6);
        assert_eq!(g(0.0, 1.0, 0.0, GradientKind::Spherical), 0.0);
    }

    #[test]
    fn the_transform_maps_before_the_pattern_and_the_table_clamps() {
        let mut pr = Procedural {
            pattern: Pattern::Gradient(GradientKind::Linear),
            space: Space::Generated,
            transform: [2.0, 0.0, 0.0, 0.1, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            domain: (0.0, 1.0),
        };
        assert!((pr.output(Vec3::new(0.2, 0.0, 0.0)).x - 0.5).abs() < 1e-6);
        assert_eq!(pr.table_position(0.5, 5), (2, 0.0));
        assert_eq!(pr.table_position(-3.0, 5), (0, 0.0));
        assert_eq!(pr.table_position(7.0, 5), (3, 1.0));
        pr.domain = (0.0, 0.0);
        assert_eq!(pr.table_position(0.3, 5), (0, 0.0));
        assert_eq!(pr.table_position(f32::NAN, 2), (0, 0.0));
    }
}
