//! BSDFs in the local shading frame (z = shading normal, flipped to face the outgoing
//! direction). Every BSDF answers the same three questions — eval, sample, pdf — and says
//! which kind of lobe produced a sample, which the shift mapping needs to decide between
//! reconnection and half-vector copy (Kettunen et al. 2015).

pub mod albedo;
#[allow(dead_code)] // its entries are computed by build.rs; the crate uses its integrals and tests the rest
mod albedo_tables;
mod blend;
mod bump_shadowing;
mod coat;
mod conductor;
mod dielectric;
mod lambert;
mod layered;
pub mod microfacet;
mod oren_nayar;
#[cfg(test)]
pub(crate) mod testing;
mod translucent;

pub use coat::Coat;
pub use conductor::Conductor;
pub use dielectric::{refraction_half_vector, Dielectric};
pub use lambert::Lambert;
pub use layered::Layered;
pub use oren_nayar::ColourPower;
pub use translucent::Translucent;

use crate::math::{luminance, power_heuristic, Spectrum};
use glam::{Vec2, Vec3};

/// Roughness at or below which a lobe is treated as specular by the shift mapping
/// (the public GDPT code uses 0.001; docs/algorithm.md §4).
pub const SPECULAR_ROUGHNESS_THRESHOLD: f32 = 1e-3;

/// Lobes at least this rough may be sampled by path guiding (`Bsdf::guidable`): below it a
/// lobe is narrow enough that BSDF sampling alone does better than a share of its samples
/// spent on the incident light (Cycles guides every non-delta closure, weighing the guide by
/// roughness; here the choice is all or none per vertex).
pub const GUIDE_MIN_ROUGHNESS: f32 = 0.25;

/// What kind of lobe a sample came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LobeKind {
    /// Smooth, reconnectable (Lambertian, rough microfacet above the threshold).
    Diffuse,
    /// Dirac delta: mirror or smooth dielectric.
    Specular,
}

/// What kind of scattering a BSDF sample is, for the per-kind bounce limits (Cycles' labels:
/// diffuse and glossy reflection, transmission through glass, transparent pass-through).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scatter {
    Diffuse,
    Glossy,
    Transmission,
    Transparent,
    /// Into the surface, where the path builder walks beneath it (`medium::subsurface`): not a
    /// bounce by itself (the Lambertian scattering where the walk leaves is a diffuse one, as
    /// in Cycles), and not evaluable (a discrete event for MIS).
    Subsurface,
}

/// The result of importance-sampling a BSDF.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Incident direction (local frame), the direction the path continues in.
    pub wi: Vec3,
    /// f(wo, wi)·|cos θi| / pdf.
    pub weight: Spectrum,
    /// Solid-angle pdf of `wi` (for a delta lobe: the discrete lobe probability).
    pub pdf: f32,
    pub lobe: LobeKind,
    /// Relative IOR crossed (1 for reflection).
    pub eta: f32,
    pub scatter: Scatter,
}

impl BsdfSample {
    /// Whether the sample went straight through (the pass-through lobe: a delta transmission
    /// with relative IOR exactly 1 — glass keeps its IOR off 1).
    #[inline]
    pub fn is_pass_through(&self, wo: Vec3) -> bool {
        self.lobe == LobeKind::Specular
            && self.eta == 1.0
            && self.wi.z * wo.z < 0.0
            && self.scatter != Scatter::Subsurface
    }
}

/// The pass-through lobe's sample: straight through, f = τ·tint as a discrete measure,
/// probability τ.
fn straight_through(wo: Vec3, pass: f32, pass_tint: Spectrum) -> BsdfSample {
    BsdfSample {
        wi: -wo,
        weight: pass_tint,
        pdf: pass,
        lobe: LobeKind::Specular,
        eta: 1.0,
        scatter: Scatter::Transparent,
    }
}

/// A BSDF instance at one surface point. An enum, not a trait object: no allocation and
/// static dispatch on the hot path.
#[derive(Clone, Copy, Debug)]
pub enum Bsdf {
    Lambert(Lambert),
    Conductor(Conductor),
    Dielectric(Dielectric),
    /// Principled's opaque dielectric: a specular layer over a Lambertian base.
    Layered(Layered),
    /// Blender's Principled BSDF as a stochastic mixture of a (layered) diffuse base, a metal
    /// and a glass lobe with weights (1−m)(1−t), m, (1−m)t (m = metallic, t = transmission),
    /// all times 1 − τ, and a pass-through lobe of probability τ = `pass` (Transparent BSDF;
    /// alpha as coverage): a delta lobe that continues the ray unchanged, tinted `pass_tint`.
    /// Over the three lobes (not the pass-through) lies the `coat`, which reflects with
    /// weight 1 − τ and dims and tints the lobes beneath by K(ωo) (`coat.rs`).
    Principled {
        diffuse: Layered,
        metal: Conductor,
        glass: Dielectric,
        w: [f32; 3],
        pass: f32,
        pass_tint: Spectrum,
        coat: Coat,
        /// Diffuse transmission (Translucent BSDF), its weight a fourth share beside w.
        translucent: Translucent,
    },
}

/// Lobes at most this rough are mirror-like for the denoising guides (Cycles' threshold).
pub const GUIDE_SPECULAR_ROUGHNESS: f32 = 0.075;

/// What the denoising guides take from a surface (`Bsdf::guide`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Guide {
    /// The surface is the guide: its albedo (and its normal).
    Surface(Spectrum),
    /// The guides look through it, their throughput multiplied by this colour.
    Through(Spectrum),
}

impl Bsdf {
    /// This BSDF on a normal- or bump-mapped surface whose own normal is `unmapped` in the
    /// shading frame: its diffuse lobe is bump-shadowed (`lambert.rs`).
    #[inline]
    pub fn bumped(mut self, unmapped: Vec3) -> Bsdf {
        match &mut self {
            Bsdf::Lambert(l) => l.unmapped = unmapped,
            Bsdf::Layered(l) => l.base.unmapped = unmapped,
            Bsdf::Principled { diffuse, translucent, .. } => {
                diffuse.base.unmapped = unmapped;
                translucent.unmapped = unmapped;
            }
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) => {}
        }
        self
    }

    /// The expected throughput of the pass-through lobe, τ·tint (zero without one): what a
    /// ray going straight through carries on, on average.
    #[inline]
    pub fn pass_through(&self) -> Spectrum {
        match self {
            Bsdf::Principled { pass, pass_tint, .. } => *pass_tint * *pass,
            _ => Spectrum::ZERO,
        }
    }

    /// f(wo, wi)·|cos θi| for non-delta lobes; zero for delta lobes.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Spectrum {
        match self {
            Bsdf::Lambert(b) => b.eval(wo, wi),
            Bsdf::Conductor(b) => b.eval(wo, wi),
            Bsdf::Dielectric(b) => b.eval(wo, wi),
            Bsdf::Layered(b) => b.eval(wo, wi),
            Bsdf::Principled { .. } => self.mixture_eval_pdf(wo, wi, false).0,
        }
    }

    /// Solid-angle density with which `sample` returns `wi` through a non-delta lobe.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Bsdf::Lambert(b) => b.pdf(wo, wi),
            Bsdf::Conductor(b) => b.pdf(wo, wi),
            Bsdf::Dielectric(b) => b.pdf(wo, wi),
            Bsdf::Layered(b) => b.pdf(wo, wi),
            Bsdf::Principled { .. } => self.mixture_eval_pdf(wo, wi, true).1,
        }
    }

    /// (`eval`, `pdf`) together, the same values bit for bit: a lobe that shares work
    /// between the two (the layered base's table read and microfacet terms, the coat's)
    /// does it once.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Spectrum, f32) {
        match self {
            Bsdf::Layered(b) => b.eval_pdf(wo, wi),
            Bsdf::Principled { .. } => self.mixture_eval_pdf(wo, wi, true),
            _ => (self.eval(wo, wi), self.pdf(wo, wi)),
        }
    }

    /// The Principled mixture's f·|cos θi| and, `with_pdf`, its pdf (else 0): each lobe's
    /// weighted sum, under the coat. One body for `eval`, `pdf` and `eval_pdf`, so they agree
    /// bit for bit.
    #[inline]
    fn mixture_eval_pdf(&self, wo: Vec3, wi: Vec3, with_pdf: bool) -> (Spectrum, f32) {
        let Bsdf::Principled { diffuse, metal, glass, w, pass, coat, translucent, .. } = self else {
            return (Spectrum::ZERO, 0.0);
        };
        let mut f = translucent.eval(wi);
        let mut p = if with_pdf { translucent.weight * translucent.pdf(wi) } else { 0.0 };
        if w[0] > 0.0 {
            let (fd, pd) = diffuse.eval_pdf(wo, wi);
            f += fd * w[0];
            p += pd * w[0];
        }
        if w[1] > 0.0 {
            f += metal.eval(wo, wi) * w[1];
            if with_pdf {
                p += metal.pdf(wo, wi) * w[1];
            }
        }
        if w[2] > 0.0 {
            f += glass.eval(wo, wi) * w[2];
            if with_pdf {
                p += glass.pdf(wo, wi) * w[2];
            }
        }
        if coat.is_some() {
            let (fc, pdf_c) = coat.eval_pdf(wo, wi);
            f = f * coat.factor(wo.z) + Spectrum::splat(fc * (1.0 - pass));
            if with_pdf {
                let pc = self.coat_choice(wo);
                p = p * (1.0 - pc) + pc * (1.0 - pass) * pdf_c;
            }
        }
        (f, if with_pdf { p } else { 0.0 })
    }

    /// (f·|cos θi|, BSDF pdf) of a light sample's direction, whose light pdf is `pdf_l` (None:
    /// a delta light, for which the pdf is not needed and is 0, as where f is 0). With
    /// `as_cycles`, f gains what Cycles' evaluation of rough glass adds beyond the BSDF — its value on pairs no microfacet connects (`Dielectric::eval_light`),
    /// which only light sampling reaches there — times the MIS weight Cycles gives it,
    /// p_l²/(p_l² + p_b²) with its pdf p_b of such pairs (1 for delta lights); the pdf returned
    /// stays the BSDF's, which is 0 there. A light sample then adds exactly what Cycles' adds
    /// (pt's MIS weight of it is 1), and the gradient-domain methods, whose MIS runs over
    /// base and offset paths alike, see one integrand (Cycles' total) that BSDF sampling
    /// cannot reach where it differs. (In a Principled mixture the other lobes keep their
    /// own weight, where Cycles weighs them with the glass lobe's extended pdf too.)
    #[inline]
    pub fn eval_light_sample(&self, wo: Vec3, wi: Vec3, as_cycles: bool, pdf_l: Option<f32>) -> (Spectrum, f32) {
        let (f, p_b) = if pdf_l.is_some() { self.eval_pdf(wo, wi) } else { (self.eval(wo, wi), 0.0) };
        // (the pdf is only asked for where a light sample of a non-delta light carries light)
        let pdf = |f: Spectrum| if pdf_l.is_some() && f.max_element() > 0.0 { p_b } else { 0.0 };
        if !as_cycles || wi.z >= 0.0 {
            return (f, pdf(f)); // (reflection pairs are evaluated alike)
        }
        let (glass, weight, k) = match self {
            Bsdf::Dielectric(g) => (g, 1.0, Spectrum::ONE),
            Bsdf::Principled { glass, w, coat, .. } if w[2] > 0.0 => (glass, w[2], coat.factor(wo.z)),
            _ => return (f, pdf(f)),
        };
        // (a glass BSDF's own value is f: only a mixture evaluates its glass lobe again)
        let glass_f = if matches!(self, Bsdf::Dielectric(_)) { f } else { glass.eval(wo, wi) };
        if glass_f.max_element() > 0.0 {
            return (f, pdf(f)); // the interface connects the pair: Cycles' value is the BSDF's
        }
        let extra = glass.eval_light(wo, wi) * k * weight;
        if !(extra.max_element() > 0.0) {
            return (f, pdf(f));
        }
        let p = pdf(f);
        let mis = pdf_l.map_or(1.0, |pl| power_heuristic(pl, p + weight * glass.pdf_light(wo, wi)));
        (f + extra * mis, p)
    }

    /// Samples an incident direction from two primary samples plus one for lobe selection.
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        match self {
            Bsdf::Lambert(b) => b.sample(wo, u),
            Bsdf::Conductor(b) => b.sample(wo, u),
            Bsdf::Dielectric(b) => b.sample(wo, u_lobe, u),
            Bsdf::Layered(b) => b.sample(wo, u_lobe, u),
            Bsdf::Principled { diffuse, metal, glass, w, pass, pass_tint, coat, translucent } => {
                // the coat first, with probability pc of the lobes' share 1 − τ
                let pc = if coat.is_some() { self.coat_choice(wo) } else { 0.0 };
                let pc_abs = pc * (1.0 - pass);
                if u_lobe < pc_abs {
                    let wi = coat.sample_wi(wo, u)?;
                    if coat.is_smooth() {
                        // its mirror lobe, c·F·(1 − τ) as a discrete measure, chosen with pc_abs
                        let (f, _) = coat.delta_eval(wo)?;
                        return Some(BsdfSample {
                            wi,
                            weight: Spectrum::splat(f * (1.0 - pass) / pc_abs),
                            pdf: pc_abs,
                            lobe: LobeKind::Specular,
                            eta: 1.0,
                            scatter: Scatter::Glossy,
                        });
                    }
                    let (f, pdf) = self.eval_pdf(wo, wi);
                    if !(pdf > 0.0) {
                        return None;
                    }
                    let weight = f / pdf;
                    return Some(BsdfSample {
                        wi,
                        weight,
                        pdf,
                        lobe: LobeKind::Diffuse,
                        eta: 1.0,
                        scatter: Scatter::Glossy,
                    });
                }
                // the lobes beneath: [pc_abs, 1 − τ) onto [0, 1 − τ); the pass-through keeps τ
                let u_lobe = if pc_abs > 0.0 && u_lobe < 1.0 - pass {
                    ((u_lobe - pc_abs) / (1.0 - pc)).min((1.0 - pass) * (1.0 - 1e-7))
                } else {
                    u_lobe
                };
                // choose a lobe ∝ weight, reusing the rest of u_lobe inside the lobe
                let (c2, c3) = (w[0] + w[1] + w[2], w[0] + w[1] + w[2] + translucent.weight);
                let (k, u_rest) = if u_lobe < w[0] {
                    (0, u_lobe / w[0])
                } else if u_lobe < w[0] + w[1] {
                    (1, (u_lobe - w[0]) / w[1])
                } else if u_lobe < c2 || (*pass <= 0.0 && !translucent.is_some()) {
                    (2, ((u_lobe - w[0] - w[1]) / w[2].max(1e-12)).min(0.999_999))
                } else if u_lobe < c3 || *pass <= 0.0 {
                    (3, 0.0)
                } else {
                    return Some(straight_through(wo, *pass, *pass_tint));
                };
                let mut bs = match k {
                    0 => diffuse.sample(wo, u_rest.min(0.999_999), u)?,
                    1 => metal.sample(wo, u)?,
                    2 => glass.sample(wo, u_rest, u)?,
                    _ => {
                        // (weight and pdf are the mixture's, set below)
                        let wi = translucent.sample_wi(u)?;
                        BsdfSample {
                            wi,
                            weight: Spectrum::ZERO,
                            pdf: 0.0,
                            lobe: LobeKind::Diffuse,
                            eta: 1.0,
                            scatter: Scatter::Transmission,
                        }
                    }
                };
                if bs.lobe == LobeKind::Specular {
                    // discrete probability of this delta event; its weight is the lobe's, under the coat
                    bs.pdf *= w[k] * (1.0 - pc);
                    if coat.is_some() {
                        bs.weight = bs.weight * coat.factor(wo.z) / (1.0 - pc);
                    }
                } else {
                    let (f, pdf) = self.eval_pdf(wo, bs.wi);
                    if !(pdf > 0.0) {
                        return None;
                    }
                    bs.weight = f / pdf;
                    bs.pdf = pdf;
                }
                Some(bs)
            }
        }
    }

    /// The probability of sampling a Principled BSDF's coat among its lobes (of their share
    /// 1 − τ): the light the coat reflects towards ωo against an estimate of what the lobes
    /// beneath reflect (their albedos, floored at 5%, dimmed by the coat). 0 without a coat.
    #[inline]
    fn coat_choice(&self, wo: Vec3) -> f32 {
        let Bsdf::Principled { diffuse, metal, w, coat, translucent, .. } = self else { return 0.0 };
        let c = coat.albedo(wo.z);
        if c <= 0.0 {
            return 0.0;
        }
        let lobes = w[0] + w[1] + w[2] + translucent.weight;
        let beneath = (w[0] * luminance(diffuse.base.albedo).max(0.05)
            + w[1] * luminance(metal.f0).max(0.05)
            + w[2]
            + translucent.weight * luminance(translucent.albedo).max(0.05))
            / lobes.max(1e-12);
        let p = c / (c + luminance(coat.factor(wo.z)) * beneath);
        p.clamp(0.0, 0.95)
    }

    /// True when every lobe is a Dirac delta (no light connection is possible).
    #[inline]
    pub fn is_delta(&self) -> bool {
        match self {
            Bsdf::Lambert(_) | Bsdf::Layered(_) => false,
            Bsdf::Conductor(b) => b.is_delta(),
            Bsdf::Dielectric(b) => b.is_delta(),
            Bsdf::Principled { metal, glass, w, coat, translucent, .. } => {
                // (the pass-through lobe is a delta lobe)
                w[0] <= 0.0
                    && !translucent.is_some()
                    && (w[1] <= 0.0 || metal.is_delta())
                    && (w[2] <= 0.0 || glass.is_delta())
                    && (!coat.is_some() || coat.is_smooth())
            }
        }
    }

    /// True when a non-delta lobe transmits (rough glass): light can then be sampled and
    /// paths reconnected through the surface.
    #[inline]
    pub fn transmits(&self) -> bool {
        match self {
            Bsdf::Dielectric(b) => !b.is_delta(),
            Bsdf::Principled { glass, w, translucent, .. } => {
                (w[2] > 0.0 && !glass.is_delta()) || translucent.is_some()
            }
            _ => false,
        }
    }

    /// Whether path guiding may sample this BSDF (`guiding`): opaque (no glass, translucent
    /// or pass-through lobe) and every lobe with weight at least [`GUIDE_MIN_ROUGHNESS`]
    /// rough, so that a direction drawn from the incident light is worth its sample.
    #[inline]
    pub fn guidable(&self) -> bool {
        let rough = |r: f32| r >= GUIDE_MIN_ROUGHNESS;
        match self {
            Bsdf::Lambert(_) => true,
            Bsdf::Conductor(b) => rough(b.roughness),
            Bsdf::Dielectric(_) => false,
            Bsdf::Layered(b) => !b.has_layer() || rough(b.roughness),
            Bsdf::Principled { diffuse, metal, w, pass, coat, translucent, .. } => {
                w[2] <= 0.0
                    && *pass <= 0.0
                    && !translucent.is_some()
                    && (w[0] <= 0.0 || !diffuse.has_layer() || rough(diffuse.roughness))
                    && (w[1] <= 0.0 || rough(metal.roughness))
                    && (!coat.is_some() || rough(coat.roughness))
            }
        }
    }

    /// Of a guidable BSDF's sampling density towards `wi` (`pdf`), the share of the lobes that
    /// label their samples Diffuse (the rest are Glossy): the probability that `sample`,
    /// having returned `wi`, labelled it Diffuse. A guided direction takes its label with this
    /// probability, so the per-kind bounce limits apply as to BSDF samples. `total` is
    /// `pdf(wo, wi)`, which the caller has already evaluated.
    #[inline]
    pub fn diffuse_share(&self, wo: Vec3, wi: Vec3, total: f32) -> f32 {
        if !(total > 0.0) {
            return 0.0;
        }
        let diffuse = match self {
            Bsdf::Lambert(_) => return 1.0,
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) => return 0.0,
            Bsdf::Layered(b) => b.base_pdf(wo, wi),
            Bsdf::Principled { diffuse, w, coat, .. } => {
                let pc = if coat.is_some() { self.coat_choice(wo) } else { 0.0 };
                w[0] * diffuse.base_pdf(wo, wi) * (1.0 - pc)
            }
        };
        (diffuse / total).clamp(0.0, 1.0)
    }

    /// The shift mapping's vertex class: diffuse (reconnectable) when every lobe that carries
    /// weight is rougher than [`SPECULAR_ROUGHNESS_THRESHOLD`].
    #[inline]
    pub fn is_diffuse(&self) -> bool {
        self.min_roughness() > SPECULAR_ROUGHNESS_THRESHOLD
    }

    /// Smallest roughness over the lobes that carry weight (delta lobes count as 0); the
    /// shift mapping compares it with [`SPECULAR_ROUGHNESS_THRESHOLD`].
    #[inline]
    pub fn min_roughness(&self) -> f32 {
        match self {
            Bsdf::Lambert(_) => 1.0,
            Bsdf::Conductor(b) => b.roughness,
            Bsdf::Dielectric(b) => b.roughness,
            Bsdf::Layered(b) => b.min_roughness(),
            Bsdf::Principled { diffuse, metal, glass, w, pass, coat, .. } => {
                let mut r: f32 = if *pass > 0.0 { 0.0 } else { 1.0 };
                if coat.is_some() {
                    r = r.min(coat.roughness);
                }
                if w[0] > 0.0 {
                    r = r.min(diffuse.min_roughness());
                }
                if w[1] > 0.0 {
                    r = r.min(metal.roughness);
                }
                if w[2] > 0.0 {
                    r = r.min(glass.roughness);
                }
                r
            }
        }
    }

    /// Relative IOR η_t/η_i of the transmission lobe (1 when there is none).
    #[inline]
    pub fn eta(&self) -> f32 {
        match self {
            Bsdf::Dielectric(b) => b.eta,
            Bsdf::Principled { glass, w, .. } if w[2] > 0.0 => glass.eta,
            _ => 1.0,
        }
    }

    /// The delta lobes towards the mirror direction of `wo` (or, with `refraction`, its
    /// refracted direction), as the half-vector shift evaluates them at a specular offset
    /// vertex: (f as a discrete measure = weight·probability, discrete probability, wi).
    /// None when the BSDF has no delta lobe of that kind.
    pub fn delta_eval(&self, wo: Vec3, refraction: bool) -> Option<(Spectrum, f32, Vec3)> {
        match self {
            Bsdf::Lambert(_) => None,
            Bsdf::Conductor(b) if !refraction => b.delta_eval(wo),
            Bsdf::Conductor(_) => None,
            Bsdf::Dielectric(b) => b.delta_eval(wo, refraction),
            Bsdf::Layered(b) if !refraction => b.delta_eval(wo),
            Bsdf::Layered(_) => None,
            Bsdf::Principled { diffuse, metal, glass, w, pass, coat, .. } => {
                // every delta lobe of one kind leads to the same direction: sum them (those
                // beneath the coat dimmed by it, chosen after it)
                let d = if w[0] > 0.0 && !refraction { diffuse.delta_eval(wo) } else { None };
                let m = if w[1] > 0.0 && !refraction { metal.delta_eval(wo) } else { None };
                let g = if w[2] > 0.0 { glass.delta_eval(wo, refraction) } else { None };
                let (k, pc) =
                    if coat.is_some() { (coat.factor(wo.z), self.coat_choice(wo)) } else { (Spectrum::ONE, 0.0) };
                let mut sum: Option<(Spectrum, f32, Vec3)> = None;
                for (lobe, wk) in [(d, w[0]), (m, w[1]), (g, w[2])] {
                    if let Some((f, p, wi)) = lobe {
                        let (f0, p0) = sum.map_or((Spectrum::ZERO, 0.0), |(f, p, _)| (f, p));
                        sum = Some((f0 + f * k * wk, p0 + p * wk * (1.0 - pc), wi));
                    }
                }
                if let (false, Some((f, wi))) = (refraction, coat.delta_eval(wo)) {
                    let (f0, p0) = sum.map_or((Spectrum::ZERO, 0.0), |(f, p, _)| (f, p));
                    sum = Some((f0 + Spectrum::splat(f * (1.0 - pass)), p0 + pc * (1.0 - pass), wi));
                }
                sum
            }
        }
    }

    /// The pass-through lobe alone, as `sample` takes it: straight through when `u_lobe` falls
    /// in the top τ of [0, 1) (f = τ·tint as a discrete measure, probability τ). Also what a
    /// path past its bounce limit takes (Cycles goes on through transparent surfaces there).
    pub fn sample_pass_through(&self, wo: Vec3, u_lobe: f32) -> Option<BsdfSample> {
        match self {
            Bsdf::Principled { pass, pass_tint, .. } if *pass > 0.0 && u_lobe >= 1.0 - *pass => {
                Some(straight_through(wo, *pass, *pass_tint))
            }
            _ => None,
        }
    }

    /// The pass-through lobe at `wo`, as the shift evaluates it at an offset vertex: (f as a
    /// discrete measure = τ·tint, probability τ, wi = −wo). None without one.
    pub fn pass_eval(&self, wo: Vec3) -> Option<(Spectrum, f32, Vec3)> {
        match self {
            Bsdf::Principled { pass, pass_tint, .. } if *pass > 0.0 => Some((*pass_tint * *pass, *pass, -wo)),
            _ => None,
        }
    }

    /// How the denoising guides (albedo and normal passes) see this surface, as Cycles'
    /// denoising features do: lobes at most `GUIDE_SPECULAR_ROUGHNESS` rough are mirror-like,
    /// and when they carry 75% or more of the BSDF's weight the guides look through the surface
    /// (along the path's own scattered ray), tinted by those lobes' colour — so that a denoiser
    /// keeps what a mirror reflects or a window shows. Otherwise the surface is the guide.
    pub fn guide(&self) -> Guide {
        let sharp = |roughness: f32| roughness <= GUIDE_SPECULAR_ROUGHNESS;
        let (rough_w, sharp_w, sharp_albedo) = match self {
            Bsdf::Lambert(_) | Bsdf::Layered(_) => (1.0, 0.0, Spectrum::ZERO),
            Bsdf::Conductor(b) if sharp(b.roughness) => (0.0, 1.0, b.f0),
            Bsdf::Dielectric(b) if sharp(b.roughness) => (0.0, 1.0, b.tint),
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) => (1.0, 0.0, Spectrum::ZERO),
            Bsdf::Principled { metal, glass, w, translucent, .. } => {
                let (mut rough, mut sharp_w, mut albedo) = (w[0] + translucent.weight, 0.0, Spectrum::ZERO);
                for (wk, r, a) in [(w[1], metal.roughness, metal.f0), (w[2], glass.roughness, glass.tint)] {
                    if sharp(r) {
                        sharp_w += wk;
                        albedo += a * wk;
                    } else {
                        rough += wk;
                    }
                }
                (rough, sharp_w, albedo)
            }
        };
        if sharp_w > 0.0 && 4.0 * rough_w <= rough_w + sharp_w {
            Guide::Through(sharp_albedo / sharp_w)
        } else {
            Guide::Surface(self.albedo())
        }
    }

    /// The albedo a subsurface lobe walks with, when the BSDF has one (its other parameters
    /// are the material's: `Material::subsurface`).
    #[inline]
    pub fn subsurface(&self) -> Option<Spectrum> {
        let l = match self {
            Bsdf::Layered(l) => l,
            Bsdf::Principled { diffuse, w, .. } if w[0] > 0.0 => diffuse,
            _ => return None,
        };
        (l.subsurface > 0.0).then_some(l.base.albedo)
    }

    /// Diffuse-like albedo, written to the denoising albedo pass.
    pub fn albedo(&self) -> Spectrum {
        match self {
            Bsdf::Lambert(b) => b.albedo,
            Bsdf::Conductor(b) => b.f0,
            Bsdf::Dielectric(b) => b.tint,
            Bsdf::Layered(b) => b.base.albedo,
            Bsdf::Principled { diffuse, metal, glass, w, translucent, .. } => {
                diffuse.base.albedo * w[0]
                    + metal.f0 * w[1]
                    + glass.tint * w[2]
                    + translucent.albedo * translucent.weight
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::testing::{chi2_test, white_furnace};
    use super::*;
    use crate::sampler::Sampler;

    /// The denoising guides look through a surface when its mirror-like lobes (roughness ≤
    /// 0.075) carry at least 75% of its weight, tinted by their colour; else it is the guide.
    #[test]
    fn guides_look_through_mostly_mirror_like_surfaces() {
        let tinted = |w: [f32; 3], roughness: f32| match principled(w, roughness) {
            Bsdf::Principled { diffuse, metal, glass, w, pass, pass_tint, coat, translucent } => Bsdf::Principled {
                diffuse,
                metal: Conductor { f0: Spectrum::new(0.9, 0.6, 0.3), ..metal },
                glass: Dielectric {
                    tint: Spectrum::new(0.2, 0.4, 0.8),
                    reflection_tint: Spectrum::new(0.2, 0.4, 0.8),
                    ..glass
                },
                w,
                pass,
                pass_tint,
                coat,
                translucent,
            },
            b => b,
        };
        let g = tinted([0.25, 0.75, 0.0], 0.0).guide();
        assert!(
            matches!(g, Guide::Through(t) if (t - Spectrum::new(0.9, 0.6, 0.3)).abs().max_element() < 1e-6),
            "{g:?}"
        );
        assert!(matches!(tinted([0.3, 0.7, 0.0], 0.0).guide(), Guide::Surface(_)));
        assert!(matches!(tinted([0.0, 1.0, 0.0], 0.2).guide(), Guide::Surface(_)), "a rough metal is the guide");
        // clear glass (its roughness is the glass lobe's own), half mirror half glass
        let g = tinted([0.0, 0.5, 0.5], 0.0).guide();
        let Guide::Through(t) = g else { panic!("{g:?}") };
        assert!((t - Spectrum::new(0.55, 0.5, 0.55)).abs().max_element() < 1e-6);
        assert!(matches!(Bsdf::Lambert(Lambert::new(Spectrum::ONE)).guide(), Guide::Surface(_)));
    }

    fn principled(w: [f32; 3], roughness: f32) -> Bsdf {
        Bsdf::Principled {
            diffuse: Layered::plain(Lambert::new(Spectrum::ONE)),
            metal: Conductor::new(Spectrum::ONE, roughness, false),
            glass: Dielectric::clear(1.5, 0.0),
            w,
            pass: 0.0,
            pass_tint: Spectrum::ONE,
            coat: Coat::NONE,
            translucent: Translucent::NONE,
        }
    }

    /// `eval_pdf` is `eval` and `pdf`, bit for bit, for every kind of BSDF (a layered base,
    /// rough metal and glass, a Principled mixture of all its lobes under a rough coat), on
    /// reflection and transmission pairs.
    #[test]
    fn eval_pdf_is_eval_and_pdf() {
        let layered = |roughness: f32| Layered {
            base: Lambert::new(Spectrum::new(0.7, 0.5, 0.3)),
            eta: 1.5,
            roughness,
            coverage: 1.0,
            tint: Spectrum::ONE,
            subsurface: 0.0,
            subsurface_ior: 0.0,
        };
        let bsdfs = [
            Bsdf::Lambert(Lambert::new(Spectrum::splat(0.5))),
            Bsdf::Conductor(Conductor::new(Spectrum::new(0.9, 0.6, 0.3), 0.3, true)),
            Bsdf::Dielectric(Dielectric::clear(1.5, 0.4)),
            Bsdf::Layered(layered(0.35)),
            Bsdf::Layered(layered(0.0)),
            Bsdf::Principled {
                diffuse: layered(0.35),
                metal: Conductor::new(Spectrum::ONE, 0.4, false),
                glass: Dielectric::clear(1.45, 0.3),
                w: [0.3, 0.2, 0.2],
                pass: 0.1,
                pass_tint: Spectrum::ONE,
                coat: Coat { weight: 0.7, eta: 1.5, roughness: 0.2, tint: Spectrum::new(0.9, 0.8, 1.0) },
                translucent: Translucent { weight: 0.2, albedo: Spectrum::ONE, ..Translucent::NONE },
            },
        ];
        let mut s = crate::sampler::IndependentSampler::new(17, 0);
        use crate::sampler::Sampler;
        let mut nonzero = 0;
        for b in &bsdfs {
            for _ in 0..2000 {
                let (u, v) = (s.next_2d(), s.next_2d());
                // wo above the surface, wi anywhere
                let wo = crate::math::square_to_uniform_sphere(u);
                let wo = Vec3::new(wo.x, wo.y, wo.z.abs().max(0.05)).normalize();
                let wi = crate::math::square_to_uniform_sphere(v);
                let (f, p) = b.eval_pdf(wo, wi);
                assert!(f == b.eval(wo, wi) && p.to_bits() == b.pdf(wo, wi).to_bits(), "{b:?} {wo} {wi}");
                nonzero += usize::from(p > 0.0);
            }
        }
        assert!(nonzero > 5000, "{nonzero} pairs with a density");
    }

    /// The mixture's sample/pdf/eval agree (chi-square over its non-delta part).
    #[test]
    fn principled_mixture_chi2() {
        let b = principled([0.6, 0.4, 0.0], 0.6);
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8)] {
            chi2_test(&b, wo, 21);
        }
    }

    /// The pass-through lobe: chosen with probability τ, straight through, tinted; the
    /// mixture's albedo is (1 − τ)·(its lobes') + τ·tint (white furnace with a grey tint).
    #[test]
    fn pass_through_lobe_probability_and_furnace() {
        let tint = Spectrum::new(0.5, 0.5, 0.5);
        let b = Bsdf::Principled {
            diffuse: Layered::plain(Lambert::new(Spectrum::ONE)),
            metal: Conductor::new(Spectrum::ONE, 0.5, false),
            glass: Dielectric::clear(1.5, 0.0),
            w: [0.4, 0.0, 0.0],
            pass: 0.6,
            pass_tint: tint,
            coat: Coat::NONE,
            translucent: Translucent::NONE,
        };
        let wo = Vec3::new(0.3, -0.2, 0.9).normalize();
        let mut s = crate::sampler::IndependentSampler::new(5, 0);
        use crate::sampler::Sampler;
        let (n, mut passed) = (100_000, 0);
        for _ in 0..n {
            let bs = b.sample(wo, s.next_1d(), s.next_2d()).unwrap();
            if bs.is_pass_through(wo) {
                passed += 1;
                assert!((bs.wi + wo).length() < 1e-6 && bs.pdf == 0.6 && bs.weight == tint);
            }
        }
        let p = passed as f64 / n as f64;
        assert!((p - 0.6).abs() < 4.0 * (0.24f64 / n as f64).sqrt(), "pass-through chosen {p}");
        let (albedo, _) = white_furnace(&b, wo, 200_000, 8);
        assert!((albedo - (0.4 + 0.6 * 0.5)).abs() < 0.01, "{albedo}");
        assert_eq!(b.min_roughness(), 0.0); // a delta lobe: not reconnectable
        chi2_test(&b, wo, 21); // the diffuse part samples its own pdf
    }

    /// With white lobes the mixture's albedo is the weighted sum of its lobes' albedos.
    #[test]
    fn principled_mixture_furnace() {
        let wo = Vec3::new(0.3, 0.1, 0.95).normalize();
        let (diffuse, _) = white_furnace(&principled([1.0, 0.0, 0.0], 0.6), wo, 200_000, 1);
        let (metal, _) = white_furnace(&principled([0.0, 1.0, 0.0], 0.6), wo, 200_000, 2);
        let (glass, _) = white_furnace(&principled([0.0, 0.0, 1.0], 0.6), wo, 200_000, 3);
        let (mix, _) = white_furnace(&principled([0.5, 0.3, 0.2], 0.6), wo, 400_000, 4);
        let expect = 0.5 * diffuse + 0.3 * metal + 0.2 * glass;
        assert!((mix - expect).abs() < 0.01, "mixture {mix} vs weighted lobes {expect}");
        // smooth glass without radiance scaling (as Cycles): F + (1−F) = 1 (0.46–0.5 before)
        assert!((glass - 1.0).abs() < 0.01, "{glass}");
    }

    /// A guided direction takes the Diffuse label with probability `diffuse_share`, which must
    /// be the probability that BSDF sampling labels its direction Diffuse: over BSDF samples,
    /// the mean of `diffuse_share(wo, wi)` equals the share of samples labelled Diffuse (for a
    /// layered plastic, a diffuse-metal mix under a rough coat, a rough metal, a Lambertian).
    /// `guidable` is false for glass, pass-through and near-mirror lobes.
    #[test]
    fn diffuse_share_is_the_label_probability() {
        let plastic = Layered {
            base: Lambert::new(Spectrum::new(0.6, 0.4, 0.2)),
            eta: 1.5,
            roughness: 0.4,
            coverage: 1.0,
            tint: Spectrum::ONE,
            subsurface: 0.0,
            subsurface_ior: 0.0,
        };
        let mut mix = coated(
            Spectrum::splat(0.5),
            [0.6, 0.4, 0.0],
            0.0,
            Coat { weight: 0.5, eta: 1.5, roughness: 0.35, tint: Spectrum::ONE },
        );
        if let Bsdf::Principled { diffuse, .. } = &mut mix {
            *diffuse = plastic;
        }
        let cases = [
            Bsdf::Layered(plastic),
            mix,
            Bsdf::Conductor(Conductor::new(Spectrum::ONE, 0.5, false)),
            Bsdf::Lambert(Lambert::new(Spectrum::ONE)),
        ];
        let mut sampler = crate::sampler::IndependentSampler::new(17, 0);
        for (i, b) in cases.iter().enumerate() {
            assert!(b.guidable(), "case {i}");
            for wo in [Vec3::Z, Vec3::new(0.7, 0.1, 0.5).normalize()] {
                let n = 200_000;
                let (mut labelled, mut share, mut m) = (0.0f64, 0.0f64, 0.0f64);
                for _ in 0..n {
                    let Some(bs) = b.sample(wo, sampler.next_1d(), sampler.next_2d()) else { continue };
                    m += 1.0;
                    labelled += (bs.scatter == Scatter::Diffuse) as u32 as f64;
                    share += b.diffuse_share(wo, bs.wi, b.pdf(wo, bs.wi)) as f64;
                }
                let (p, q) = (labelled / m, share / m);
                // binomial standard error of the labelled share, and 5 of them
                let tol = 5.0 * (p * (1.0 - p) / m).sqrt() + 1e-9;
                assert!((p - q).abs() <= tol, "case {i}, wo {wo}: {p} labelled Diffuse, mean share {q}");
                if i == 1 {
                    assert!(p > 0.2 && p < 0.8, "the mix has both labels: {p}");
                }
            }
        }
        assert!(!principled([0.0, 0.0, 1.0], 0.3).guidable(), "glass");
        assert!(!coated(Spectrum::ONE, [1.0, 0.0, 0.0], 0.3, Coat::NONE).guidable(), "pass-through");
        assert!(!principled([0.0, 1.0, 0.0], 0.1).guidable(), "a near-mirror metal");
        assert!(!Bsdf::Dielectric(Dielectric::clear(1.5, 0.5)).guidable());
    }

    fn coated(base: Spectrum, w: [f32; 3], pass: f32, coat: Coat) -> Bsdf {
        Bsdf::Principled {
            diffuse: Layered::plain(Lambert::new(base)),
            metal: Conductor::new(Spectrum::new(0.9, 0.7, 0.4), 0.4, false),
            glass: Dielectric::clear(1.5, 0.3),
            w,
            pass,
            pass_tint: Spectrum::splat(0.5),
            coat,
            translucent: Translucent::NONE,
        }
    }

    /// The coat as Cycles layers it: over a white Lambertian it gives back exactly what it
    /// takes (albedo c·E + (1 − c·E)·1 = 1, every angle, rough and smooth); over a black
    /// base it reflects its own albedo c·E(μo); its tint dims what lies beneath by
    /// (1 − c) + c·tint^(1/cos θt); sampling matches pdf (χ²) with the coat, its metal and
    /// glass lobes beneath and a pass-through lobe beside them.
    #[test]
    fn the_coat_layers_as_cycles() {
        let clear = |roughness: f32| Coat { weight: 0.8, eta: 1.5, roughness, tint: Spectrum::ONE };
        for r in [0.0f32, 0.03, 0.3] {
            for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.95, 0.0, 0.31).normalize()] {
                let (albedo, _) =
                    white_furnace(&coated(Spectrum::ONE, [1.0, 0.0, 0.0], 0.0, clear(r)), wo, 200_000, 31);
                assert!((albedo - 1.0).abs() < 0.01, "r={r} wo={wo}: {albedo}");
                let (black, _) =
                    white_furnace(&coated(Spectrum::ZERO, [1.0, 0.0, 0.0], 0.0, clear(r)), wo, 200_000, 32);
                let want = clear(r).albedo(wo.z) as f64;
                assert!((black - want).abs() < 0.004 + 0.02 * want, "r={r} wo={wo}: {black} vs c·E {want}");
            }
        }
        // the tint: a white base under a blue coat at normal incidence
        let blue = Coat { weight: 0.5, eta: 1.5, roughness: 0.2, tint: Spectrum::new(0.2, 0.4, 1.0) };
        let k = blue.factor(1.0);
        let layer = 1.0 - blue.albedo(1.0);
        let want = (Spectrum::splat(0.5) + Spectrum::new(0.2, 0.4, 1.0) * 0.5) * layer;
        assert!((k - want).abs().max_element() < 1e-6, "{k} {want}");
        // grazing: the path through the coat is longer, so the tint is stronger
        assert!(blue.factor(0.3).x / blue.factor(0.3).z < k.x / k.z);
        for (w, pass, coat) in [
            ([1.0, 0.0, 0.0], 0.0, clear(0.1)),
            ([0.3, 0.4, 0.0], 0.3, clear(0.25)),
            ([0.2, 0.3, 0.5], 0.0, blue),
            ([0.5, 0.0, 0.0], 0.0, clear(0.0)), // a smooth coat: a delta lobe beside the base
        ] {
            let b = coated(Spectrum::new(0.5, 0.6, 0.7), w, pass, coat);
            // (not at normal incidence with glass: its transmitted peak, 84% of the samples
            // within 4.5° of −z, is finer than the test's quadrature of the expected counts)
            let wos = if w[2] > 0.0 {
                [Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.5, 0.3, 0.81)]
            } else {
                [Vec3::Z, Vec3::new(-0.5, 0.3, 0.81)]
            };
            for wo in wos.map(|w| w.normalize()) {
                chi2_test(&b, wo, 33);
            }
        }
        // a smooth coat's mirror lobe: delta_eval sums it with the lobes beneath it
        let b = coated(Spectrum::ONE, [1.0, 0.0, 0.0], 0.0, clear(0.0));
        let wo = Vec3::new(0.5, 0.1, 0.86).normalize();
        let (f, p, wi) = b.delta_eval(wo, false).unwrap();
        assert!((f.x - clear(0.0).albedo(wo.z)).abs() < 1e-6 && p > 0.0 && p < 1.0 && (wi.z - wo.z).abs() < 1e-6);
        assert!(b.delta_eval(wo, true).is_none() && !b.is_delta() && b.min_roughness() == 0.0);
    }

    /// Diffuse transmission (Translucent BSDF) in the mixture: a white translucent lobe sends
    /// all light to the far side (white furnace 1, none on the viewer's side), beside a
    /// diffuse lobe it shares the light by weight; sampling matches pdf (χ²); the surface
    /// then transmits (light is sampled through it).
    #[test]
    fn translucent_lobe_transmits_diffusely() {
        let mixed = |wd: f32, wt: f32, coat: Coat| Bsdf::Principled {
            diffuse: Layered::plain(Lambert::new(Spectrum::splat(0.5))),
            metal: Conductor::new(Spectrum::ONE, 0.4, false),
            glass: Dielectric::clear(1.5, 0.3),
            w: [wd, 0.0, 0.0],
            pass: 1.0 - wd - wt,
            pass_tint: Spectrum::ONE,
            coat,
            translucent: Translucent { weight: wt, albedo: Spectrum::ONE, ..Translucent::NONE },
        };
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let white = mixed(0.0, 1.0, Coat::NONE);
        let (albedo, by_quadrature) = white_furnace(&white, wo, 200_000, 41);
        assert!((albedo - 1.0).abs() < 1e-3 && (by_quadrature - 1.0).abs() < 0.01, "{albedo} {by_quadrature}");
        assert!(white.eval(wo, Vec3::new(0.0, 0.6, 0.8)) == Spectrum::ZERO);
        assert!(white.eval(wo, Vec3::new(0.0, 0.6, -0.8)).x > 0.0);
        assert!(white.transmits() && !white.is_delta());
        // half diffuse (albedo ½), half translucent: ½·½ + ½·1
        let (albedo, _) = white_furnace(&mixed(0.5, 0.5, Coat::NONE), wo, 200_000, 42);
        assert!((albedo - 0.75).abs() < 0.005, "{albedo}");
        for b in [
            mixed(0.5, 0.5, Coat::NONE),
            mixed(0.3, 0.4, Coat::NONE),
            mixed(0.6, 0.4, Coat { weight: 1.0, eta: 1.5, roughness: 0.2, tint: Spectrum::ONE }),
        ] {
            for wo in [Vec3::Z, Vec3::new(-0.5, 0.3, 0.81).normalize()] {
                chi2_test(&b, wo, 43);
            }
        }
    }
}
