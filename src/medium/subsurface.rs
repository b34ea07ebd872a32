//! Subsurface scattering as Cycles' random walk (Chiang, Kutz and Burley 2016, "Practical and
//! Controllable Subsurface Scattering for Production Path Tracing"): light that enters a
//! surface walks through the object's interior as through a homogeneous medium, and leaves
//! where the walk crosses the surface again; there it scatters as a white Lambertian.
//!
//! The interior's coefficients come from what an artist sets — the surface's albedo `A` (its
//! base colour) and mean free path `d` (Subsurface Radius × Scale) — per channel:
//!
//! * σt from `d` (the method's rescale of `d`, below), σs = α σt with the single-scattering
//!   albedo α fitted so that a half-space lit from outside reflects about `A` in all;
//! * the walk's throughput starts at the closure's weight divided by `A` (the walk returns
//!   about `A`), and a channel whose α is below 0.2 walks with α = 0.2, its throughput
//!   scaled by α/0.2 (Cycles' rule: it bounds the number of steps in dark channels);
//! * Henyey–Greenstein scattering of mean cosine g (Subsurface Anisotropy), for the first ten
//!   steps; after them the walk scatters isotropically with the reduced coefficient
//!   σs(1 − g) (the similarity relation, as Cycles);
//! * free flights by spectral MIS: a channel picked ∝ its throughput × α, the distance drawn
//!   from its σt, the throughput weighted by the balance heuristic over the channels;
//! * at most [`MAX_STEPS`] segments, and a throughput below 1e-6 ends the walk (the light is
//!   lost, as in Cycles).
//!
//! The methods (Principled BSDF's Subsurface Method, Cycles' `bssrdf_setup`):
//! * [`SubsurfaceMethod::RandomWalk`] (Blender 5.2's and later "Random Walk"): σt = 1/d, α from the
//!   van de Hulst relation for a half-space, s² = (4.20863A − √(9.59217 + 41.6808A +
//!   17.7126A²) + 4.09712)², α = (1 − s²)/(1 − g s²); g within ±0.99; it enters through the
//!   specular layer's rough interface (a GGX microfacet refraction of IOR `ior`).
//! * [`SubsurfaceMethod::Legacy`] (Blender 4.x–5.1's "Random Walk", 5.2's "Random Walk
//!   (Legacy)"): d/(4π) as the mean free path, σt = 1/(d(1 − g)), α from Cycles' fit in g of
//!   the Christensen–Burley inversion; g within [−0.99, 0.9] (Blender before 5.2: [0, 0.9],
//!   the exporter's clamp), a negative g taking the van de Hulst α and σt = 1/d; the same
//!   entry.
//! * [`SubsurfaceMethod::Skin`] ("Random Walk (Skin)"): the Legacy walk with `d` rescaled by
//!   √(3(1 − α′)), α′ the albedo inverting the dipole's total reflectance for the Subsurface
//!   IOR, and an entry that is half cosine-weighted, half a refraction of roughness 1.
//!
//! The entry has weight 1 (no Fresnel term beyond the specular layer's share above it); the
//! walk exits at the first crossing of a surface of the same material.

use super::phase::HenyeyGreenstein;
use crate::bsdf::microfacet::Ggx;
use crate::math::{square_to_cosine_hemisphere, Spectrum};
use crate::sampler::Sampler;
use glam::{Vec2, Vec3};

/// A walk ends, its light lost, after this many segments (Cycles' `BSSRDF_MAX_BOUNCES`).
pub const MAX_STEPS: u32 = 256;
/// Steps after which the walk scatters isotropically with the reduced coefficients.
const ANISOTROPIC_STEPS: u32 = 10;
/// The smallest single-scattering albedo a channel walks with (its throughput scaled).
const MIN_ALPHA: f32 = 0.2;
/// A walk whose largest throughput channel falls below this ends.
const MIN_THROUGHPUT: f32 = 1e-6;

/// Principled BSDF's Subsurface Method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SubsurfaceMethod {
    RandomWalk,
    Legacy,
    Skin,
}

/// The subsurface share of a diffuse base and its parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Subsurface {
    /// Subsurface Weight: the share of the diffuse base that enters (0: none).
    pub weight: f32,
    /// Mean free path per channel in world units (Subsurface Radius × Scale), as given.
    pub radius: Vec3,
    /// Subsurface Anisotropy g.
    pub anisotropy: f32,
    /// Subsurface IOR (the Skin method's entry and radius rescale).
    pub ior: f32,
    pub method: SubsurfaceMethod,
}

impl Subsurface {
    pub const NONE: Subsurface =
        Subsurface { weight: 0.0, radius: Vec3::ZERO, anisotropy: 0.0, ior: 1.4, method: SubsurfaceMethod::Legacy };

    #[inline]
    pub fn is_some(&self) -> bool {
        self.weight > 0.0
    }

    /// The anisotropy as the method clamps it.
    #[inline]
    fn g(&self) -> f32 {
        let g = if self.anisotropy.is_finite() { self.anisotropy } else { 0.0 };
        match self.method {
            SubsurfaceMethod::RandomWalk => g.clamp(-0.99, 0.99),
            _ => g.clamp(-0.99, 0.9),
        }
    }

    /// The interior's coefficients for surface albedo `albedo` (per channel in [0, 1]).
    pub fn coefficients(&self, albedo: Spectrum) -> Interior {
        let g = self.g();
        let a = albedo.clamp(Spectrum::ZERO, Spectrum::ONE);
        let mut sigma_t = Spectrum::ZERO;
        let mut alpha = Spectrum::ZERO;
        let mut scale = Spectrum::ZERO;
        for c in 0..3 {
            let (d, ac) = (self.radius[c].max(0.0), a[c]);
            let (st, al) = match self.method {
                SubsurfaceMethod::RandomWalk => (1.0 / d.max(1e-16), van_de_hulst_alpha(ac, g)),
                SubsurfaceMethod::Legacy | SubsurfaceMethod::Skin => {
                    let d = if self.method == SubsurfaceMethod::Skin {
                        d * (3.0 * (1.0 - dipole_alpha_prime(ac, self.ior))).sqrt()
                    } else {
                        d / (4.0 * std::f32::consts::PI)
                    };
                    if g < 0.0 {
                        (1.0 / d.max(1e-16), van_de_hulst_alpha(ac, g))
                    } else {
                        (1.0 / d.max(1e-16) / (1.0 - g), fitted_alpha(ac, g))
                    }
                }
            };
            // the walk returns about the albedo: it is divided out of the closure's weight
            let mut s = if ac > 0.0 { 1.0 / ac } else { 0.0 };
            let mut al = al.clamp(0.0, 0.999_999);
            if al < MIN_ALPHA {
                s *= al / MIN_ALPHA;
                al = MIN_ALPHA;
            }
            sigma_t[c] = st;
            alpha[c] = al;
            scale[c] = s;
        }
        Interior { sigma_t, alpha, scale, phase: HenyeyGreenstein::new(g) }
    }

    /// The direction into the surface for `wo` (towards the viewer, local frame: z the shading
    /// normal), through a specular layer of relative IOR `layer_ior` and Blender roughness
    /// `layer_roughness` (the Principled BSDF's), from `u_choice` and `u`. None when `wo` is
    /// below the shading hemisphere or the refraction fails (the light is then lost, as in
    /// Cycles). The entry's weight is 1.
    pub fn entry(&self, wo: Vec3, layer_ior: f32, layer_roughness: f32, u_choice: f32, u: Vec2) -> Option<Vec3> {
        entry(self.skin_ior(), wo, layer_ior, layer_roughness, u_choice, u)
    }

    /// The Subsurface IOR the Skin method enters with (None for the other methods: the layer's).
    #[inline]
    pub fn skin_ior(&self) -> Option<f32> {
        (self.method == SubsurfaceMethod::Skin).then_some(self.ior)
    }
}

/// `Subsurface::entry` for a method that enters as Skin at `skin_ior`, or (None) through the
/// layer: what a BSDF keeps of a subsurface to sample its entry.
pub fn entry(
    skin_ior: Option<f32>,
    wo: Vec3,
    layer_ior: f32,
    layer_roughness: f32,
    u_choice: f32,
    u: Vec2,
) -> Option<Vec3> {
    {
        if wo.z <= 0.0 {
            return None;
        }
        let (ior, roughness) = match skin_ior {
            Some(_) if u_choice < 0.5 => {
                let w = square_to_cosine_hemisphere(u);
                return Some(Vec3::new(w.x, w.y, -w.z));
            }
            Some(ior) => (ior, 1.0),
            None => (layer_ior, layer_roughness),
        };
        let ior = if ior.is_finite() { ior.clamp(1.01, 3.8) } else { 1.4 };
        let h = Ggx::from_roughness(roughness).sample_visible(wo, u);
        let eta = 1.0 / ior;
        let cos_h = h.dot(wo);
        let k = 1.0 - eta * eta * (1.0 - cos_h * cos_h);
        if k < 0.0 {
            return None;
        }
        let wi = -eta * wo + (eta * cos_h - k.sqrt()) * h;
        (wi.z < 0.0).then(|| wi.normalize())
    }
}

/// The interior medium of a walk (`Subsurface::coefficients`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interior {
    pub sigma_t: Spectrum,
    /// Single-scattering albedo α (σs = α σt).
    pub alpha: Spectrum,
    /// The throughput factor the walk starts with (1/albedo, and the low-α scaling).
    pub scale: Spectrum,
    pub phase: HenyeyGreenstein,
}

/// Where a walk left the object.
#[derive(Clone, Copy, Debug)]
pub struct Exit<H> {
    /// The hit of the surface it crossed, and the direction it crossed it in.
    pub hit: H,
    pub dir: Vec3,
    /// The walk's throughput (the `scale` included).
    pub weight: Spectrum,
    /// Segments walked.
    pub steps: u32,
}

impl Interior {
    /// Walks from `origin` along `dir` (into the object) until `intersect(o, d, t_max)` — the
    /// closest crossing of the object's surface within `t_max`, with its distance — finds one
    /// before the next scattering. None when the light is lost inside.
    pub fn walk<H, S: Sampler>(
        &self,
        origin: Vec3,
        dir: Vec3,
        rng: &mut S,
        mut intersect: impl FnMut(Vec3, Vec3, f32) -> Option<(f32, H)>,
    ) -> Option<Exit<H>> {
        let (mut o, mut d) = (origin, dir);
        let mut beta = self.scale;
        let (sigma_s, g) = (self.alpha * self.sigma_t, self.phase.g);
        let reduced = sigma_s * (1.0 - g);
        let isotropic = HenyeyGreenstein::new(0.0);
        for step in 0..MAX_STEPS {
            let anisotropic = step < ANISOTROPIC_STEPS;
            let (sigma_t, sigma_s) =
                if anisotropic { (self.sigma_t, sigma_s) } else { (self.sigma_t - sigma_s + reduced, reduced) };
            if step > 0 {
                let phase = if anisotropic { self.phase } else { isotropic };
                d = phase.sample(-d, rng.next_2d()).0;
            }
            // the channel: ∝ throughput × α (uniform when all are 0)
            let w = (beta * self.alpha).abs();
            let total = w.x + w.y + w.z;
            let p = if total > 0.0 { w / total } else { Spectrum::splat(1.0 / 3.0) };
            let u = rng.next_1d();
            let c = if u < p.x {
                0
            } else if u < p.x + p.y || p.z <= 0.0 {
                1
            } else {
                2
            };
            let c = if p[c] > 0.0 { c } else { (0..3).find(|&i| p[i] > 0.0).unwrap_or(0) };
            let t = -(1.0 - rng.next_1d()).ln() / sigma_t[c];
            let hit = intersect(o, d, t);
            match hit {
                Some((t_hit, h)) => {
                    let tr = (-sigma_t * t_hit).exp();
                    beta *= tr / p.dot(tr).max(1e-30);
                    return Some(Exit { hit: h, dir: d, weight: beta, steps: step + 1 });
                }
                None => {
                    let tr = (-sigma_t * t).exp();
                    beta *= sigma_s * tr / p.dot(sigma_t * tr).max(1e-30);
                    o += d * t;
                }
            }
            if !(beta.max_element() >= MIN_THROUGHPUT) {
                return None;
            }
        }
        None
    }
}

/// A polynomial's value at g (coefficients of g⁰, g¹, …).
#[inline]
fn poly(c: &[f64], g: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &k| acc * g + k)
}

/// The single-scattering albedo for surface albedo `a` and anisotropy g by Cycles' fit (in
/// g) of the inversion of Christensen and Burley's multiple-scattering albedo (the Legacy
/// and Skin methods).
fn fitted_alpha(a: f32, g: f32) -> f32 {
    // (in f64: the exponents' terms cancel to a few units)
    const A: [f64; 8] = [
        1.8260523782,
        -1.28451056436,
        -1.79904629312,
        9.19393289202,
        -22.8215585862,
        32.0234874259,
        -23.6264803333,
        7.21067002658,
    ];
    const B: [f64; 8] = [
        0.0,
        31.1491581433,
        -201.847017512,
        841.576016723,
        -2018.09288505,
        2731.71560286,
        -1935.41424244,
        559.009054474,
    ];
    const C: [f64; 8] = [
        1.09686102424,
        -0.394704063468,
        1.05258115941,
        -8.83963712726,
        28.8643230661,
        -46.8802913581,
        38.5402837518,
        -12.7181042538,
    ];
    const D: [f64; 8] = [
        0.496310210422,
        0.360146581622,
        -2.15139309747,
        17.8896899217,
        -55.2984010333,
        82.065982243,
        -58.5106008578,
        15.8478295021,
    ];
    const E: [f64; 8] =
        [0.0, 76.7316253952, -594.356773233, 2448.8834203, -5576.68528998, 7116.60171912, -4763.54467887, 1303.5318055];
    const F: [f64; 8] = [
        2.40602999408,
        -2.51814844609,
        9.18494908356,
        -79.2191708682,
        259.082868209,
        -403.613804597,
        302.85712436,
        -87.4370473567,
    ];
    let (a, g) = (a as f64, g as f64);
    let b_ = 4.98511194385 + 0.127355959438 * poly(&B, g).exp();
    let e_ = 4.23190299701 + 0.00310603949088 * poly(&E, g).exp();
    let blend = a.powf(0.25);
    let alpha = (1.0 - blend) * poly(&A, g) * (b_ * a).atan().powf(poly(&C, g))
        + blend * poly(&D, g) * (e_ * a).atan().powf(poly(&F, g));
    alpha as f32
}

/// The single-scattering albedo for surface albedo `a` and anisotropy g by the van de Hulst
/// relation for a half-space (the Random Walk method of Blender 5.2 and later).
fn van_de_hulst_alpha(a: f32, g: f32) -> f32 {
    let s = 4.208_63 * a - (9.592_17 + 41.680_8 * a + 17.712_6 * a * a).sqrt() + 4.097_12;
    let s2 = s * s;
    (1.0 - s2) / (1.0 - g * s2)
}

/// α′ whose dipole total diffuse reflectance ½α′(1 + e^{−(4/3)A s}) e^{−s}, s = √(3(1 − α′)),
/// is the albedo `a` (A from the Fresnel diffuse reflectance of IOR `ior`, Jensen et al.
/// 2001), by twelve bisections as Cycles (the Skin method's radius rescale).
fn dipole_alpha_prime(a: f32, ior: f32) -> f32 {
    if a < 1e-4 {
        return 0.0;
    }
    if a >= 0.995 {
        return 0.999_999;
    }
    let eta = if ior.is_finite() { ior.clamp(1.01, 3.8) } else { 1.4 };
    let f_dr = -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta;
    let four_thirds_a = (4.0 / 3.0) * (1.0 + f_dr) / (1.0 - f_dr);
    let rd = |ap: f32| {
        let s = (3.0 * (1.0 - ap)).sqrt();
        0.5 * ap * (1.0 + (-four_thirds_a * s).exp()) * (-s).exp()
    };
    let (mut lo, mut hi, mut mid) = (0.0f32, 1.0f32, 0.5f32);
    for _ in 0..12 {
        mid = 0.5 * (lo + hi);
        if rd(mid) < a {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    mid
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::IndependentSampler;

    fn sss(method: SubsurfaceMethod, g: f32) -> Subsurface {
        Subsurface { weight: 1.0, radius: Vec3::new(1.0, 0.5, 0.25), anisotropy: g, ior: 1.4, method }
    }

    /// The half-space z < 0 bounded by the plane z = 0: its crossing along a ray.
    fn plane(o: Vec3, d: Vec3, t_max: f32) -> Option<(f32, ())> {
        (d.z > 0.0).then(|| -o.z / d.z).filter(|&t| t < t_max).map(|t| (t.max(0.0), ()))
    }

    /// Mean and standard error per channel of the light a half-space returns (walk weight ×
    /// albedo) for walks entering cosine-weighted.
    fn half_space(s: &Subsurface, albedo: Spectrum, n: u32, seed: u64) -> (Spectrum, Spectrum) {
        let interior = s.coefficients(albedo);
        let mut rng = IndependentSampler::new(seed, 0);
        let (mut sum, mut sum2) = (Spectrum::ZERO, Spectrum::ZERO);
        for _ in 0..n {
            let w = square_to_cosine_hemisphere(rng.next_2d());
            let dir = Vec3::new(w.x, w.y, -w.z);
            if let Some(e) = interior.walk(Vec3::ZERO, dir, &mut rng, plane) {
                let x = e.weight * albedo;
                sum += x;
                sum2 += x * x;
            }
        }
        let mean = sum / n as f32;
        let var = (sum2 / n as f32 - mean * mean).max(Spectrum::ZERO);
        (mean, (var / n as f32).powf(0.5))
    }

    /// The fits exist for this: a half-space of albedo A lit diffusely returns about A, for
    /// every method and anisotropy (measured within 3.5%: the fit's error, the low-α scaling
    /// and the isotropic tail make the rest).
    #[test]
    fn a_half_space_returns_about_its_albedo() {
        for method in [SubsurfaceMethod::RandomWalk, SubsurfaceMethod::Legacy, SubsurfaceMethod::Skin] {
            for g in [0.0f32, 0.5, -0.3] {
                let albedo = Spectrum::new(0.9, 0.5, 0.2);
                let (mean, se) = half_space(&sss(method, g), albedo, 40_000, 3);
                for c in 0..3 {
                    let err = (mean[c] - albedo[c]).abs();
                    assert!(
                        err < 0.05 * albedo[c] + 4.0 * se[c],
                        "{method:?} g={g} channel {c}: returns {} of albedo {} (±{})",
                        mean[c],
                        albedo[c],
                        se[c]
                    );
                }
            }
        }
    }

    /// Spectral MIS is unbiased per channel: each channel of a chromatic walk returns what a
    /// grey walk with that channel's coefficients returns.
    #[test]
    fn a_chromatic_walk_returns_each_channels_grey_walk() {
        let s = Subsurface { radius: Vec3::new(1.0, 0.3, 0.1), ..sss(SubsurfaceMethod::Legacy, 0.4) };
        let albedo = Spectrum::new(0.8, 0.4, 0.6);
        let (mean, se) = half_space(&s, albedo, 60_000, 5);
        for c in 0..3 {
            let grey = Subsurface { radius: Vec3::splat(s.radius[c]), ..s };
            let (m, e) = half_space(&grey, Spectrum::splat(albedo[c]), 60_000, 7 + c as u64);
            let tol = 4.0 * (se[c] * se[c] + e[c] * e[c]).sqrt();
            assert!((mean[c] - m[c]).abs() < tol, "channel {c}: chromatic {} grey {} (±{tol})", mean[c], m[c]);
        }
    }

    /// The coefficients: σt from the radius as each method rescales it, α within (0, 1),
    /// monotonic in the albedo; the van de Hulst α is 0 and 1 at the ends; the dipole's α′
    /// inverts its reflectance to the bisection's precision.
    #[test]
    fn coefficients_follow_the_methods() {
        let grey = |m, a: f32, g| Subsurface { radius: Vec3::splat(0.5), ..sss(m, g) }.coefficients(Spectrum::splat(a));
        let rw = grey(SubsurfaceMethod::RandomWalk, 0.5, 0.3);
        assert!((rw.sigma_t.x - 2.0).abs() < 1e-6, "{rw:?}");
        let legacy = grey(SubsurfaceMethod::Legacy, 0.5, 0.3);
        let want = 4.0 * std::f32::consts::PI / 0.5 / 0.7;
        assert!((legacy.sigma_t.x - want).abs() < 1e-3 * want, "{legacy:?}");
        assert!(van_de_hulst_alpha(0.0, 0.0).abs() < 1e-5 && (van_de_hulst_alpha(1.0, 0.0) - 1.0).abs() < 1e-5);
        for g in [0.0f32, 0.5] {
            let mut last = 0.0;
            for i in 1..18 {
                let a = i as f32 / 20.0;
                let al = fitted_alpha(a, g);
                assert!(al > last && al < 1.0, "g={g} a={a}: α {al} after {last}");
                last = al;
            }
            // (the fit passes 1 near a = 1: the coefficients clamp it)
            let near_white = grey(SubsurfaceMethod::Legacy, 0.99, g);
            assert!(near_white.alpha.x < 1.0 && near_white.alpha.x > 0.99, "{near_white:?}");
        }
        for a in [0.05f32, 0.3, 0.7, 0.95] {
            let ap = dipole_alpha_prime(a, 1.4);
            let f_dr = -1.440 / 1.96 + 0.710 / 1.4 + 0.668 + 0.0636 * 1.4;
            let k = (4.0 / 3.0) * (1.0 + f_dr) / (1.0 - f_dr);
            let rd = |ap: f32| {
                let s = (3.0 * (1.0 - ap)).sqrt();
                0.5 * ap * (1.0 + (-k * s).exp()) * (-s).exp()
            };
            // (twelve bisections: α′ within 2⁻¹² of the root)
            let step = 1.0 / 4096.0;
            assert!(rd(ap - step) <= a && a <= rd((ap + step).min(1.0)), "a={a}: α′ {ap} gives {}", rd(ap));
        }
        // a dark channel walks with α 0.2, its throughput scaled
        let dark = grey(SubsurfaceMethod::Legacy, 0.01, 0.0);
        assert!(dark.alpha.x == MIN_ALPHA && dark.scale.x < 1.0 / 0.01, "{dark:?}");
    }

    /// The entry refracts through the layer: straight down at normal incidence through a
    /// smooth layer, by Snell's law at an angle, always into the surface; Skin's cosine half
    /// too; none from below the shading hemisphere.
    #[test]
    fn the_entry_refracts_into_the_surface() {
        let s = sss(SubsurfaceMethod::Legacy, 0.0);
        let down = s.entry(Vec3::Z, 1.5, 0.0, 0.5, Vec2::new(0.3, 0.7)).unwrap();
        assert!((down - Vec3::NEG_Z).length() < 1e-3, "{down}");
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let wi = s.entry(wo, 1.5, 0.0, 0.5, Vec2::new(0.3, 0.7)).unwrap();
        let (sin_i, sin_t) = (0.6f32, (wi.x * wi.x + wi.y * wi.y).sqrt());
        assert!((sin_t - sin_i / 1.5).abs() < 2e-3 && wi.x < 0.0, "{wi}");
        assert!(s.entry(Vec3::new(0.6, 0.0, -0.8), 1.5, 0.3, 0.5, Vec2::splat(0.4)).is_none());
        let skin = sss(SubsurfaceMethod::Skin, 0.0);
        let mut rng = IndependentSampler::new(1, 1);
        for _ in 0..1000 {
            let w = skin.entry(wo, 1.5, 0.3, rng.next_1d(), rng.next_2d());
            assert!(w.is_none_or(|w| w.z < 0.0 && (w.length() - 1.0).abs() < 1e-4));
        }
    }
}
