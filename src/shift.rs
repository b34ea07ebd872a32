//! THE shift mapping (Kettunen et al. 2015; docs/algorithm.md §4): given a recorded base path
//! through one pixel, the offset path through a neighbouring pixel and the MIS-weighted
//! contributions of both, event by event. `gdpt` and `gdpssmlt` both call [`shift`].
//!
//! The offset starts with the camera ray through the neighbour pixel at the same sub-pixel
//! position and lens sample (J = 1), hitting y0. Then, vertex by vertex, while the offset
//! is still *free* (has its own vertex y_k):
//! * x_k, y_k and x_{k+1} all diffuse (roughness above [`crate::bsdf::SPECULAR_ROUGHNESS_THRESHOLD`]):
//!   **reconnect** y_k → x_{k+1}; the paths share every vertex after that;
//! * otherwise **copy the half-vector** of the base's bounce at x_k into y_k's local frame and
//!   reflect or refract y_k's incoming direction about it, trace to y_{k+1}, and require
//!   y_{k+1} to be of the same class (diffuse or not) as x_{k+1}, which keeps the map
//!   invertible (the inverse shift makes the same decisions from the offset's side).
//!
//! Light events (docs/algorithm.md §4, "next-event estimation"): a light sample taken at x_k is
//! reconnected from y_k to the same light point; a light found by the BSDF ray leaving x_k
//! is reconnected to the same point when x_k is diffuse, and otherwise is whatever light
//! the offset's own half-vector ray finds (the same analytic light, the world, or the
//! emission of the surface it hits).
//!
//! Jacobians (docs/algorithm.md §4; each checked against finite differences below):
//! reconnection |cos θ'_z|·‖x−z‖² / (|cos θ_z|·‖y−z‖²); half-vector reflection
//! |ω'_o·h| / |ω_o·h|; refraction (‖h'_u‖²/η'²|ω'_i·h|) / (‖h_u‖²/η²|ω_i·h|); 1 for delta lobes
//! (point evaluations) and after the paths join.
//!
//! Weights: balance heuristic over {base, offset} × {BSDF, light} strategies, every pdf
//! expressed in the base path's measure (the public GDPT code's rule). A failed offset gives
//! the base full weight and contributes zero — never a dropped sample. The failure rules
//! (miss, occlusion, class mismatch, total internal reflection on one side) are symmetric in
//! base and offset, which is what makes that rule unbiased.
//!
//! Media (`crate::medium`) are not shifted through: a base event whose path a medium has
//! touched (`Event::medium`: a segment in one, a scattering, a vertex on a boundary, a
//! shadow ray through one) takes full weight, and an offset vertex on a medium's boundary
//! fails — the same rule seen from either side, as every segment of a path that lies in a
//! medium starts at the camera in one or past such a vertex.

use crate::accel::TriHit;
use crate::bsdf::{refraction_half_vector, Bsdf};
use crate::math::Spectrum;
use crate::path::{Event, Path, Vertex, CAMERA_VERTEX};
use crate::scene::{CameraRay, Scene, SurfaceInteraction};
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

/// The half-vector copy in local frames: the base's bounce (wo_x → wi_x, relative IOR
/// `eta_x` if it refracted) mapped to the offset's incoming direction `wo_y` (relative IOR
/// `eta_y` on its side). Returns (wi_y, Jacobian dω_y/dω_x), None where the copy does not
/// exist (the reflected direction leaves the hemisphere, total internal reflection, η = 1).
pub fn half_vector_copy(wo_x: Vec3, wi_x: Vec3, eta_x: f32, wo_y: Vec3, eta_y: f32) -> Option<(Vec3, f32)> {
    if wi_x.z >= 0.0 {
        let h = (wo_x + wi_x).normalize_or_zero();
        let (cx, cy) = (wo_x.dot(h), wo_y.dot(h));
        if !(cx > 0.0 && cy > 0.0) {
            return None;
        }
        let wi_y = 2.0 * cy * h - wo_y;
        (wi_y.z > 0.0).then_some((wi_y, cy / cx))
    } else {
        if (eta_x - 1.0).abs() < 1e-5 || (eta_y - 1.0).abs() < 1e-5 {
            return None;
        }
        let hu_x = refraction_half_vector(wo_x, wi_x, eta_x);
        let h = if hu_x.z < 0.0 { -hu_x } else { hu_x }.normalize_or_zero();
        let cos_o = wo_y.dot(h);
        if !(cos_o > 0.0 && wo_x.dot(h) > 0.0) {
            return None;
        }
        let sin2_t = (1.0 - cos_o * cos_o).max(0.0) / (eta_y * eta_y);
        if sin2_t >= 1.0 {
            return None; // total internal reflection on the offset's side only
        }
        let wi_y = -wo_y / eta_y + (cos_o / eta_y - (1.0 - sin2_t).sqrt()) * h;
        if wi_y.z >= 0.0 {
            return None;
        }
        let hu_y = refraction_half_vector(wo_y, wi_y, eta_y);
        // dω_i/dω_h = ‖h_u‖² / (η²|ω_i·h|) (Walter 2007, eq. 17, inverted)
        let dx = hu_x.length_squared() / (eta_x * eta_x * wi_x.dot(h).abs());
        let dy = hu_y.length_squared() / (eta_y * eta_y * wi_y.dot(h).abs());
        let j = dy / dx;
        (j.is_finite() && j > 0.0).then_some((wi_y, j))
    }
}

/// The BSDF at path vertex `v`, seen from its own incoming direction.
#[inline]
fn bsdf_at(scene: &Scene, v: &Vertex) -> Bsdf {
    bsdf_seen(scene, v, v.frame.to_local(v.wo))
}

/// The BSDF at path vertex `v` seen from direction `wo` (its shading frame): an offset path
/// joined to the base at `v` arrives from elsewhere (what a blend by the view reads).
#[inline]
fn bsdf_seen(scene: &Scene, v: &Vertex, wo: Vec3) -> Bsdf {
    scene.bsdf(v.material, v.front, v.tex, v.color, v.unmapped, wo, v.camera)
}

/// Visibility from a surface point to a point (or, at infinity, along a direction) on a
/// side the path builder scatters or samples lights towards, and nothing in the way, as
/// `blocking` says. A path segment (a reconnection) goes where BSDF sampling continues: on
/// one side of both the geometric and the shading normal, and on the far side only where the
/// surface transmits through a non-delta lobe (rough glass). A shadow ray goes wherever the
/// BSDF's value (which its caller weighs) says, as the path builder's light samples do.
fn visible(scene: &Scene, si: &SurfaceInteraction, z: Vec3, at_infinity: bool, blocking: Blocking) -> bool {
    let dir = if at_infinity { z } else { z - si.p };
    let (cg, cs) = (dir.dot(si.ng), dir.dot(si.frame.n));
    let side = blocking != Blocking::Path
        || if cg > 0.0 { cs > 0.0 } else { cg < 0.0 && cs < 0.0 && scene.bsdf_at(si).transmits() };
    side && match blocking {
        Blocking::Path => scene.segment_clear(si, z, at_infinity),
        Blocking::Shadow => scene.shadow_clear(si, z, at_infinity),
        Blocking::Nothing => true,
    }
}

/// What blocks a segment the offset re-traces: any surface (a path segment); a surface that
/// casts shadows (a shadow ray, next-event estimation, as the base's was); nothing (the
/// shadow ray of a light whose Cast Shadow is off).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Blocking {
    Path,
    Shadow,
    Nothing,
}

/// An offset vertex of its own (not yet joined to the base path).
#[derive(Clone, Copy, Debug)]
struct Free {
    y: SurfaceInteraction,
    /// Unit direction towards the previous offset vertex (world).
    wo: Vec3,
    /// Offset throughput arriving at y, in the base's measure (f·J products over the base's
    /// pdfs and roulette probabilities).
    beta: Spectrum,
    /// Offset prefix pdf (times the Jacobian) over the base's.
    r: f32,
    /// Class of x_k and y_k (they are equal, or the shift has failed).
    diffuse: bool,
}

impl Free {
    /// f·|cos θ| and solid-angle pdf of the offset's BSDF at y (`bsdf`, `Offset::bsdf`)
    /// towards world direction `dir` (for light event `e` of light pdf p_l at y, if any: as
    /// the base evaluated it).
    fn scatter(&self, bsdf: &Bsdf, dir: Vec3, e: Option<(&Event, f32)>) -> (Spectrum, f32) {
        let (wo, wi) = (self.y.frame.to_local(self.wo), self.y.frame.to_local(dir));
        match e {
            Some((e, pdf_l)) => e.bsdf_eval(bsdf, wo, wi, pdf_l),
            None => bsdf.eval_pdf(wo, wi),
        }
    }
}

/// The offset's half-vector bounce at a free vertex, traced.
#[derive(Clone, Copy, Debug)]
struct Step {
    origin: Vec3,
    dir: Vec3,
    hit: Option<SurfaceInteraction>,
    /// f·|cos| (discrete value for a delta lobe), pdf (solid angle or discrete) and Jacobian
    /// of the offset's bounce.
    f: Spectrum,
    pdf: f32,
    j: f32,
    /// The offset's own local sampled direction and relative IOR (for recording).
    eta: f32,
    delta: bool,
}

/// Where the offset stands relative to base vertex k.
#[derive(Clone, Copy, Debug)]
enum State {
    Failed,
    Free(Free),
    /// Joined at x_k by reconnection: the BSDF at x_k sees the offset's direction `wo`
    /// (local), everything after x_k is shared.
    Joined {
        wo: Vec3,
        beta: Spectrum,
        r: f32,
    },
    /// Identical to the base from here on: the offset's throughput arriving at x_k is
    /// `beta` (base measure) and its pdfs are the base's times `r`. (Its own throughput, not
    /// a per-channel ratio to the base's: a channel the base has lost — a pure red wall —
    /// the offset may still carry.)
    Same {
        beta: Spectrum,
        r: f32,
    },
}

/// The offset path as it walks along the base, vertex by vertex.
struct Offset<'a> {
    scene: &'a Scene,
    base: &'a Path,
    k: usize,
    state: State,
    /// Cached half-vector step of the current free vertex.
    step: Option<Option<Step>>,
    /// The BSDF at the current free vertex y_k seen from its `wo` (while the state is
    /// `Free`): built once, to compare its class with the base's, and kept for the vertex's
    /// light events, its bounce and its reconnection. (Here rather than in `Free`, so that
    /// the state stays small to copy.)
    bsdf: Bsdf,
}

/// `Offset::bsdf` while the state is not `Free`.
const NO_BSDF: Bsdf = Bsdf::Lambert(crate::bsdf::Lambert {
    albedo: Spectrum::ZERO,
    roughness: 0.0,
    power: crate::bsdf::ColourPower::Squared,
    unmapped: Vec3::Z,
});

impl<'a> Offset<'a> {
    fn new(scene: &'a Scene, base: &'a Path, offset_raster: Option<Vec2>) -> Offset<'a> {
        let primary = offset_raster.filter(|_| !base.vertices.is_empty()).map(|raster| {
            let ray = scene.camera.generate_ray(raster, base.lens);
            (ray, scene.intersect_camera(ray.origin, ray.dir, ray.tmin, ray.tmax))
        });
        Offset::from_primary(scene, base, primary)
    }

    /// The offset path from its traced camera ray (with the base's lens sample) and what it hit.
    /// A holdout there (its path ends, `path.rs`) fails the shift, as a base path that meets
    /// one has no vertex to shift: the two sides of a holdout's edge are never paired.
    fn from_primary(scene: &'a Scene, base: &'a Path, primary: Option<(CameraRay, Option<TriHit>)>) -> Offset<'a> {
        let mut offset = Offset { scene, base, k: 0, state: State::Failed, step: None, bsdf: NO_BSDF };
        let primary = primary.filter(|(_, hit)| !hit.is_some_and(|h| scene.is_holdout(h.prim)));
        if let (Some(x0), Some((ray, Some(hit)))) = (base.vertices.first(), primary) {
            let y = SurfaceInteraction { camera: true, ..scene.interaction(&hit, ray.dir) };
            offset.bsdf = scene.bsdf_at(&y);
            // (an offset on a medium's boundary fails, as a base there flags its light)
            if x0.diffuse == offset.bsdf.is_diffuse() && !scene.has_medium(y.material) {
                let diffuse = x0.diffuse;
                offset.state = State::Free(Free { y, wo: -ray.dir, beta: Spectrum::ONE, r: 1.0, diffuse });
            }
        }
        offset
    }

    /// The half-vector bounce of the free vertex `f` at base vertex k, traced (cached).
    fn step(&mut self, f: &Free) -> Option<Step> {
        if let Some(s) = self.step {
            return s;
        }
        let s = half_vector_step(self.scene, &self.base.vertices[self.k], f, &self.bsdf);
        self.step = Some(s);
        s
    }

    /// Moves to base vertex k+1.
    fn advance(&mut self) {
        let (scene, base, k) = (self.scene, self.base, self.k);
        let next = base.vertices.get(k + 1);
        self.state = match (self.state, next) {
            (_, None) | (State::Failed, _) => State::Failed,
            (State::Same { beta, r }, _) => {
                // the base's own bounce at x_k
                let x = &base.vertices[k];
                if !(x.pdf_out > 0.0) {
                    State::Failed
                } else {
                    State::Same { beta: beta * x.f_out / (x.pdf_out * x.rr), r }
                }
            }
            (State::Joined { wo, beta, r }, Some(_)) => {
                // x_k's BSDF towards x_{k+1} with the offset's incoming direction
                let x = &base.vertices[k];
                let bsdf = bsdf_seen(scene, x, wo);
                let wi = x.frame.to_local(x.wi);
                if !(x.pdf_out > 0.0) {
                    State::Failed
                } else {
                    let (fy, pdf) = bsdf.eval_pdf(wo, wi);
                    State::Same { beta: beta * fy / (x.pdf_out * x.rr), r: r * pdf / x.pdf_out }
                }
            }
            (State::Free(f), Some(xn)) => {
                let xk = &base.vertices[k];
                let next_diffuse = xn.diffuse;
                if f.diffuse && next_diffuse {
                    reconnect(scene, xk, xn, &f, &self.bsdf).unwrap_or(State::Failed)
                } else {
                    match self.step(&f) {
                        Some(Step { hit: Some(y), dir, f: fy, pdf, j, .. }) => {
                            self.bsdf = scene.bsdf_at(&y);
                            if self.bsdf.is_diffuse() == next_diffuse && !scene.has_medium(y.material) {
                                State::Free(Free {
                                    y,
                                    wo: -dir,
                                    beta: f.beta * fy * (j / (xk.pdf_out * xk.rr)),
                                    r: f.r * pdf * j / xk.pdf_out,
                                    diffuse: next_diffuse,
                                })
                            } else {
                                State::Failed
                            }
                        }
                        _ => State::Failed,
                    }
                }
            }
        };
        self.k += 1;
        self.step = None;
    }

    /// The offset's version of base event `e` (which leaves base vertex k): its numerator
    /// and its pdf sum, both in the base's measure; None when it does not exist.
    fn event(&mut self, e: &Event) -> Option<(Spectrum, f32)> {
        // A light hit by the BSDF ray leaving x_k comes after x_k's Russian roulette: the base
        // numerator carries 1/q_k, and so must the offset's (it shares the base's decision).
        // Without it gdpt without NEE was 4–9% dark under glass (issue 14 §4).
        let rr = if e.nee { 1.0 } else { self.base.vertices[self.k].rr };
        if let State::Same { beta, r } = self.state {
            // the base's numerator is β_x·f·Le (/q_k): the same event with the offset's β
            return Some((beta * e.f * e.le / rr, r * (e.pdf_b + e.pdf_l)));
        }
        self.own_event(e).map(|(num, pdf)| (num / rr, pdf))
    }

    /// `event` for an offset that has vertex k of its own (free there, or joined at it),
    /// before the roulette factor of BSDF-hit events.
    fn own_event(&mut self, e: &Event) -> Option<(Spectrum, f32)> {
        let (scene, base, k) = (self.scene, self.base, self.k);
        match self.state {
            // (`Same` is handled by `event`)
            State::Failed | State::Same { .. } => None,
            State::Joined { wo, beta, r } => {
                let x = &base.vertices[k];
                let bsdf = bsdf_seen(scene, x, wo);
                let dir = if e.at_infinity { e.z } else { (e.z - x.p).normalize() };
                let wi = x.frame.to_local(dir);
                let (fy, pdf) = e.bsdf_eval(&bsdf, wo, wi, e.pdf_l);
                let pdf_b = if e.delta { 0.0 } else { pdf };
                // base numerator = β_x·f_x·Le (NEE) or β_x(k+1)·Le·p_b = β_x·f_x·Le/q_k (hit);
                // `event` divides by q_k
                Some((beta * fy * e.le, r * (pdf_b + e.pdf_l)))
            }
            // a segment through transparent surfaces is not re-created from a free offset
            // vertex (neither is the offset's, in reconnect_event: shadow tests stop at them)
            State::Free(_) if e.through_transparent => None,
            // light linking: the light does not light the offset's object (the path tracer
            // records no such event, so the base takes full weight)
            State::Free(f) if !scene.lights_receiver(e.light, f.y.prim) => None,
            // a light sampled or hit from a free diffuse vertex, and a delta light (no ray
            // can hit it), reconnect to the same light point
            State::Free(f) if f.diffuse || e.delta => reconnect_event(scene, e, base.vertices[k].p, &f, &self.bsdf),
            // at a free non-diffuse vertex a light sample is shifted as a BSDF sample of the
            // same direction is (half-vector copy, then whatever light the offset's ray
            // finds): one base path has one offset whichever strategy found it, so the pair's
            // MIS weights over both strategies on both sides sum to one (a light sample used
            // to reconnect while a BSDF hit of the same path copied the half-vector)
            State::Free(f) if e.nee => {
                light_along(scene, e, &f, &nee_step(scene, &base.vertices[k], &f, &self.bsdf, e)?)
            }
            State::Free(f) => light_along(scene, e, &f, &self.step(&f)?),
        }
    }
}

/// The offset's version of light event `e` found along its traced half-vector step `s`
/// from free vertex `f`: (numerator, pdf sum) in the base's measure, None if the offset's
/// ray does not find that light.
fn light_along(scene: &Scene, e: &Event, f: &Free, s: &Step) -> Option<(Spectrum, f32)> {
    let (le, pdf_l) = if e.light == scene.env_light() {
        // the base escaped: so must the offset
        if s.hit.is_some() {
            return None;
        }
        scene.world_eval(f.y.p, s.dir)
    } else if scene.is_triangle_light(e.light) {
        // the base hit an emitting surface: so must the offset's ray (if it hits a surface
        // that does not emit, the offset has no such event: the base would have no event to
        // shift back from, so the pair fails symmetrically)
        // (light linking: the emitter the offset meets must light the offset's vertex)
        let hit = s.hit?;
        if scene.triangle_light(hit.prim).is_some_and(|l| !scene.lights_receiver(l, f.y.prim)) {
            return None;
        }
        scene.surface_emission(&hit, f.y.p, s.dir)?
    } else {
        let tmax = s.hit.map_or(f32::INFINITY, |h| h.t);
        let (_, le, pdf) = scene.light_crossed(e.light, f.y.p, s.origin, s.dir, tmax)?;
        (le, pdf)
    };
    let pdf_l = if e.pdf_l > 0.0 { pdf_l } else { 0.0 }; // same strategies as the base
    Some((f.beta * s.f * le * s.j, f.r * s.j * (s.pdf + pdf_l)))
}

/// The half-vector step of a light sample taken at base vertex `x`: the bounce the BSDF
/// would have sampled towards the light (its non-delta lobes, reflection or transmission).
fn nee_step(scene: &Scene, x: &Vertex, f: &Free, bsdf: &Bsdf, e: &Event) -> Option<Step> {
    if !(e.pdf_b > 0.0) {
        return None; // no lobe samples that direction: nothing to copy
    }
    let wi = if e.at_infinity { e.z } else { (e.z - x.p).normalize() };
    let through = wi.dot(x.ng) < 0.0;
    let eta = if through { bsdf_at(scene, x).eta() } else { 1.0 };
    let as_sampled = Vertex { wi, f_out: e.f, pdf_out: e.pdf_b, delta_out: false, eta_out: eta, ..*x };
    half_vector_step(scene, &as_sampled, f, bsdf)
}

/// The offset's half-vector bounce at free vertex `f` (its BSDF `bsdf`) against base vertex
/// `x`, traced.
fn half_vector_step(scene: &Scene, x: &Vertex, f: &Free, bsdf: &Bsdf) -> Option<Step> {
    if !(x.pdf_out > 0.0) {
        return None;
    }
    let (wo_x, wi_x) = (x.frame.to_local(x.wo), x.frame.to_local(x.wi));
    let wo_y = f.y.frame.to_local(f.wo);
    let refraction = wi_x.z < 0.0;
    let (wi, fy, pdf, j, eta) = if x.passed_through() {
        // the base passed straight through a transparent surface: so does the offset, J = 1
        let (fy, pdf, wi) = bsdf.pass_eval(wo_y)?;
        (wi, fy, pdf, 1.0, 1.0)
    } else if x.delta_out {
        // both delta: a point evaluation, J = 1
        let (fy, pdf, wi) = bsdf.delta_eval(wo_y, refraction)?;
        (wi, fy, pdf, 1.0, if refraction { bsdf.eta() } else { 1.0 })
    } else {
        let eta_y = if refraction { bsdf.eta() } else { 1.0 };
        let (wi, j) = half_vector_copy(wo_x, wi_x, x.eta_out, wo_y, eta_y)?;
        let (f, pdf) = bsdf.eval_pdf(wo_y, wi);
        (wi, f, pdf, j, eta_y)
    };
    if !(pdf > 0.0) {
        return None;
    }
    let dir = f.y.frame.to_world(wi);
    if dir.dot(f.y.ng) * wi.z <= 0.0 {
        return None; // the shading normal sent the offset through the geometric surface
    }
    let origin = f.y.spawn_origin(dir);
    // (a camera ray that went straight through is still the camera's: Is Camera Ray)
    let camera = f.y.camera && x.passed_through();
    let hit = scene
        .intersect(origin, dir, 0.0, f32::INFINITY)
        .map(|h| SurfaceInteraction { camera, ..scene.interaction(&h, dir) });
    Some(Step { origin, dir, hit, f: fy, pdf, j, eta, delta: x.delta_out })
}

/// Reconnection y_k → x_{k+1} (x_k, y_k, x_{k+1} diffuse).
fn reconnect(scene: &Scene, xk: &Vertex, xn: &Vertex, f: &Free, bsdf: &Bsdf) -> Option<State> {
    if !visible(scene, &f.y, xn.p, false, Blocking::Path) {
        return None;
    }
    let dir = (xn.p - f.y.p).normalize();
    if (-dir).dot(xn.ng) <= 0.0 {
        return None; // the offset would arrive at x_{k+1} from its other side
    }
    let j = reconnection_jacobian(xk.p, f.y.p, xn.p, xn.ng);
    if !(j > 0.0 && j.is_finite() && xk.pdf_out > 0.0) {
        return None;
    }
    let (fy, pdf) = f.scatter(bsdf, dir, None);
    Some(State::Joined {
        wo: xn.frame.to_local(-dir),
        beta: f.beta * fy * (j / (xk.pdf_out * xk.rr)),
        r: f.r * pdf * j / xk.pdf_out,
    })
}

/// Re-evaluates light event `e` (leaving base vertex at `xk`) from the free offset vertex,
/// reconnected to the same light point (or direction, for lights at infinity).
fn reconnect_event(scene: &Scene, e: &Event, xk: Vec3, f: &Free, bsdf: &Bsdf) -> Option<(Spectrum, f32)> {
    let blocking = match (e.nee, scene.casts_shadow(e.light)) {
        (false, _) => Blocking::Path,
        (true, true) => Blocking::Shadow,
        (true, false) => Blocking::Nothing,
    };
    if !visible(scene, &f.y, e.z, e.at_infinity, blocking) {
        return None;
    }
    let dir = if e.at_infinity { e.z } else { (e.z - f.y.p).normalize() };
    let (le, pdf_l) = scene.light_eval(e.light, f.y.p, e.z)?;
    let pdf_l = if e.pdf_l > 0.0 { pdf_l } else { 0.0 }; // same strategies as the base
    let (fy, pdf) = f.scatter(bsdf, dir, Some((e, pdf_l)));
    let pdf_b = if e.delta { 0.0 } else { pdf };
    let j = if e.at_infinity || e.delta {
        1.0
    } else {
        let nz = scene.light_normal(e.light, e.z); // zero for points, the world and suns
        if nz == Vec3::ZERO {
            1.0
        } else {
            reconnection_jacobian(xk, f.y.p, e.z, nz)
        }
    };
    if !(j > 0.0) || !j.is_finite() {
        return None;
    }
    Some((f.beta * fy * le * j, f.r * (pdf_b + pdf_l) * j))
}

/// The contributions of a base path and its offset through `offset_raster` (None when the
/// neighbour pixel is outside the image: the base then takes full weight).
pub fn shift(scene: &Scene, base: &Path, offset_raster: Option<Vec2>) -> PairContribution {
    pair_contribution(Offset::new(scene, base, offset_raster), false)
}

/// The same for the base's indirect light only (events not `direct`): the Metropolis
/// methods render direct light apart, by plain Monte Carlo.
pub fn shift_indirect(scene: &Scene, base: &Path, offset_raster: Option<Vec2>) -> PairContribution {
    pair_contribution(Offset::new(scene, base, offset_raster), true)
}

/// The same with the offset's camera ray (through the neighbour pixel, with the base's lens
/// sample) already traced: `primary` = that ray and its hit, None outside the image. (GDPT
/// traces a base path's camera ray and its four offsets' as one packet.)
pub fn shift_from(scene: &Scene, base: &Path, primary: Option<(CameraRay, Option<TriHit>)>) -> PairContribution {
    pair_contribution(Offset::from_primary(scene, base, primary), false)
}

fn pair_contribution(mut offset: Offset<'_>, indirect_only: bool) -> PairContribution {
    let mut out = PairContribution::default();
    let base = offset.base;
    // events come in vertex order (camera events, never differenced, are skipped; so are
    // direct ones when asked)
    for e in base.events.iter().filter(|e| e.vertex != CAMERA_VERTEX && !(indirect_only && e.direct)) {
        let pdf_x = e.pdf_b + e.pdf_l;
        if !(pdf_x > 0.0) {
            continue;
        }
        if e.medium {
            // (a path through a medium is not shifted: the base takes full weight)
            out.base += e.numerator / pdf_x;
            continue;
        }
        while offset.k < e.vertex as usize {
            offset.advance();
        }
        match offset.event(e) {
            // An offset event that carries no light does not exist for the path tracer (it
            // stops at zero throughput and records no zero-valued light sample), so the
            // inverse shift from that side can never return here: its pdf counts as 0 and the
            // base takes full weight (before this rule, a ceiling next to a black-bodied light
            // lost a quarter of its light: base weighted down, offset side never sampled).
            Some((num_y, pdf_y)) if pdf_y.is_finite() && num_y.is_finite() && num_y.max_element() > 0.0 => {
                let denom = pdf_x + pdf_y;
                out.base += e.numerator / denom;
                out.offset += num_y / denom;
            }
            _ => out.base += e.numerator / pdf_x,
        }
    }
    out
}

/// The offset path's vertices in its own measure (for tests of the shift: the inverse shift
/// of this path must give back the base). Stops where the shift fails.
pub fn offset_path(scene: &Scene, base: &Path, offset_raster: Vec2) -> Path {
    let mut out = Path { vertices: Vec::new(), events: Vec::new(), lens: base.lens };
    let mut offset = Offset::new(scene, base, Some(offset_raster));
    let mut own_beta = Spectrum::ONE;
    let mut own_pdf_in = 0.0;
    while offset.k < base.vertices.len() {
        let x = base.vertices[offset.k];
        match offset.state {
            State::Failed => break,
            State::Free(f) => {
                let mut v = Vertex {
                    p: f.y.p,
                    ng: f.y.ng,
                    frame: f.y.frame,
                    material: f.y.material,
                    prim: f.y.prim,
                    front: f.y.front,
                    wo: f.wo,
                    throughput: own_beta,
                    pdf_in: own_pdf_in,
                    ..x
                };
                let next_diffuse = base.vertices.get(offset.k + 1).map(|n| n.diffuse);
                if !(f.diffuse && next_diffuse == Some(true)) {
                    if let Some(s) = offset.step(&f) {
                        v.wi = s.dir;
                        v.f_out = s.f;
                        v.pdf_out = s.pdf;
                        v.delta_out = s.delta;
                        v.eta_out = s.eta;
                        own_beta *= s.f / (s.pdf * x.rr);
                        own_pdf_in = s.pdf;
                    }
                } else if let Some(n) = base.vertices.get(offset.k + 1) {
                    let dir = (n.p - f.y.p).normalize();
                    let (fv, pdf) = f.scatter(&offset.bsdf, dir, None);
                    v.wi = dir;
                    v.f_out = fv;
                    v.pdf_out = pdf;
                    v.delta_out = false;
                    v.eta_out = 1.0;
                    own_beta *= fv / (pdf * x.rr);
                    own_pdf_in = pdf;
                }
                out.vertices.push(v);
            }
            State::Joined { wo, .. } => {
                let bsdf = bsdf_seen(scene, &x, wo);
                let wo_world = x.frame.to_world(wo);
                let wi = x.frame.to_local(x.wi);
                let (fv, pdf) = if x.pdf_out > 0.0 { bsdf.eval_pdf(wo, wi) } else { (Spectrum::ZERO, 0.0) };
                out.vertices.push(Vertex {
                    wo: wo_world,
                    throughput: own_beta,
                    pdf_in: own_pdf_in,
                    f_out: fv,
                    pdf_out: pdf,
                    ..x
                });
                own_beta *= if pdf > 0.0 { fv / (pdf * x.rr) } else { Spectrum::ZERO };
                own_pdf_in = pdf;
            }
            State::Same { .. } => {
                out.vertices.push(Vertex { throughput: own_beta, pdf_in: own_pdf_in, ..x });
                own_beta *= if x.pdf_out > 0.0 { x.f_out / (x.pdf_out * x.rr) } else { Spectrum::ZERO };
                own_pdf_in = x.pdf_out;
            }
        }
        offset.advance();
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

    /// Solid angle of the small spherical quadrilateral spanned by unit vectors a, b, c, d.
    fn patch(a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> f32 {
        0.5 * ((c - a).cross(d - b)).length()
    }

    /// The half-vector copy's Jacobian dω_y/dω_x against finite differences: a tiny patch of
    /// base directions around wi_x mapped through the copy, for reflection and refraction,
    /// entering and leaving the denser medium.
    #[test]
    fn half_vector_jacobians_match_finite_differences() {
        use crate::sampler::{IndependentSampler, Sampler};
        let mut s = IndependentSampler::new(8, 8);
        let mut upper = || {
            let v = crate::math::square_to_cosine_hemisphere(s.next_2d());
            Vec3::new(v.x, v.y, v.z.max(0.2)).normalize()
        };
        let mut checked = [0usize; 2];
        for case in 0..400 {
            let refraction = case % 2 == 1;
            let eta = if case % 4 == 1 { 1.5 } else { 1.0 / 1.33 };
            let (wo_x, wo_y) = (upper(), upper());
            let m = upper(); // microfacet normal of the base bounce
            let wi_x = if refraction {
                match crate::bsdf::microfacet::refract(wo_x, m, eta) {
                    Some(w) if w.z < -0.1 => w,
                    _ => continue,
                }
            } else {
                let w = crate::bsdf::microfacet::reflect(wo_x, m);
                if w.z < 0.1 {
                    continue;
                }
                w
            };
            let eta_x = if refraction { eta } else { 1.0 };
            let Some((wi_y, j)) = half_vector_copy(wo_x, wi_x, eta_x, wo_y, eta_x) else { continue };
            let f = crate::math::Frame::from_normal(wi_x);
            let h = 5e-4f32;
            let corners = [Vec2::new(-1.0, -1.0), Vec2::new(1.0, -1.0), Vec2::new(1.0, 1.0), Vec2::new(-1.0, 1.0)];
            let xs: Vec<Vec3> = corners.iter().map(|c| (wi_x + (f.s * c.x + f.t * c.y) * h).normalize()).collect();
            let ys: Option<Vec<Vec3>> =
                xs.iter().map(|w| half_vector_copy(wo_x, *w, eta_x, wo_y, eta_x).map(|r| r.0)).collect();
            let Some(ys) = ys else { continue };
            let fd = patch(ys[0], ys[1], ys[2], ys[3]) / patch(xs[0], xs[1], xs[2], xs[3]);
            assert!((fd - j).abs() < 3e-2 * j.max(1e-2), "refraction={refraction} eta={eta}: fd {fd} vs J {j}");
            // copying onto the base itself is the identity
            let (same, j1) = half_vector_copy(wo_x, wi_x, eta_x, wo_x, eta_x).unwrap();
            assert!((same - wi_x).length() < 1e-4 && (j1 - 1.0).abs() < 1e-3);
            let _ = wi_y;
            checked[refraction as usize] += 1;
        }
        assert!(checked[0] > 50 && checked[1] > 50, "too few configurations checked: {checked:?}");
    }

    /// The half-vector copy is an involution pair: copying the offset's bounce back onto the
    /// base's incoming direction gives back the base's outgoing direction.
    #[test]
    fn half_vector_copy_inverts() {
        use crate::sampler::{IndependentSampler, Sampler};
        let mut s = IndependentSampler::new(3, 1);
        let mut n = 0;
        for case in 0..500 {
            let (wo_x, wo_y) = (
                crate::math::square_to_cosine_hemisphere(s.next_2d()),
                crate::math::square_to_cosine_hemisphere(s.next_2d()),
            );
            let m = crate::math::square_to_cosine_hemisphere(s.next_2d());
            let eta = if case % 2 == 0 { 1.0 } else { 1.45 };
            let wi_x = if eta == 1.0 {
                crate::bsdf::microfacet::reflect(wo_x, m)
            } else {
                match crate::bsdf::microfacet::refract(wo_x, m, eta) {
                    Some(w) => w,
                    None => continue,
                }
            };
            if wi_x.z.abs() < 0.05 {
                continue;
            }
            let Some((wi_y, j)) = half_vector_copy(wo_x, wi_x, eta, wo_y, eta) else { continue };
            let (back, jb) = half_vector_copy(wo_y, wi_y, eta, wo_x, eta).expect("the inverse copy exists");
            assert!((back - wi_x).length() < 1e-3, "{back} vs {wi_x}");
            assert!((j * jb - 1.0).abs() < 1e-2, "J·J⁻¹ = {}", j * jb);
            n += 1;
        }
        assert!(n > 200);
    }

    /// Shift followed by the inverse shift gives back the base path, vertex for vertex, on a
    /// scene with a mirror sphere, a glass sphere and diffuse walls (reconnection and
    /// half-vector copies through reflection and refraction).
    /// `shift_from` with the offsets' camera rays traced as one packet (as GDPT does) gives
    /// exactly the pair contributions of `shift`, which traces each offset's ray alone.
    #[test]
    fn shift_from_packet_traced_camera_rays_matches_shift() {
        use crate::path::{trace_path, PathSettings};
        use crate::sampler::{IndependentSampler, Sampler};
        let scene = Scene::build(&crate::scene::builtin::cornell_spheres(24, 24)).unwrap();
        let cfg = PathSettings::new(5, true);
        let mut base = Path::default();
        let mut nonzero = 0;
        for i in 0..3000u64 {
            let mut smp = IndependentSampler::new(4, i);
            let raster = Vec2::new((i % 24) as f32, ((i / 24) % 24) as f32) + smp.next_2d();
            trace_path(&scene, &cfg, raster, &mut smp, Some(&mut base));
            let shifts = [Vec2::X, -Vec2::X, Vec2::Y, -Vec2::Y];
            let rays: Vec<CameraRay> =
                shifts.iter().map(|s| scene.camera.generate_ray(raster + *s, base.lens)).collect();
            let hits = scene.intersect_camera_rays(&rays);
            for k in 0..4 {
                let a = shift(&scene, &base, Some(raster + shifts[k]));
                let b = shift_from(&scene, &base, Some((rays[k], hits[k])));
                assert_eq!((a.base, a.offset), (b.base, b.offset), "path {i}, shift {k}");
                nonzero += (a.offset.max_element() > 0.0) as usize;
            }
            let none = (shift(&scene, &base, None), shift_from(&scene, &base, None));
            assert_eq!((none.0.base, none.0.offset), (none.1.base, none.1.offset));
        }
        assert!(nonzero > 1000, "too few offsets carrying light: {nonzero}");
    }

    /// The zero shift (the offset through the base's own raster position) is the identity:
    /// the offset path is the base path, so every event's offset numerator and pdf equal the
    /// base's and the pair splits each contribution in two equal halves. Checked with and
    /// without NEE, through mirrors and glass, where the offset stays free vertex after
    /// vertex and hits the light after Russian roulette has started (the offset lacked the
    /// base's 1/q there: a box with grey mirror walls lost up to 30% of such offsets, and
    /// this test failed).
    #[test]
    fn the_zero_shift_is_the_identity() {
        use crate::path::{trace_path, PathSettings};
        use crate::sampler::{IndependentSampler, Sampler};
        let mut mirrors = crate::scene::builtin::cornell_box(16, 16);
        for m in mirrors.materials.iter_mut().filter(|m| m.name == "Red" || m.name == "Green") {
            (m.metallic, m.roughness, m.base_color) = (1.0, 0.0, [0.5; 3]);
        }
        for desc in
            [mirrors, crate::scene::builtin::cornell_spheres(16, 16), crate::scene::builtin::cornell_bulb(16, 16)]
        {
            let scene = Scene::build(&desc).unwrap();
            for nee in [false, true] {
                let cfg = PathSettings::new(8, nee);
                let mut base = Path::default();
                let (mut sum_b, mut sum_o, mut n, mut equal) = (0.0f64, 0.0f64, 0, 0);
                for i in 0..50_000u64 {
                    let mut smp = IndependentSampler::new(8, i);
                    let raster = Vec2::new((i % 16) as f32, ((i / 16) % 16) as f32) + smp.next_2d();
                    trace_path(&scene, &cfg, raster, &mut smp, Some(&mut base));
                    let pc = shift(&scene, &base, Some(raster));
                    let (b, o) = (crate::math::luminance(pc.base) as f64, crate::math::luminance(pc.offset) as f64);
                    if b > 0.0 {
                        n += 1;
                        equal += ((o - b).abs() <= 1e-2 * b) as usize; // (reconnection Jacobians of 1 to rounding)
                        sum_b += b;
                        sum_o += o;
                    }
                }
                assert!(n > 100, "nee={nee}: {n} paths carry light");
                // (the bulb's glass refracts at grazing angles where the half-vector copy rounds:
                // 3 of 191 naive pairs off by 1–30% at one seed, 99.2% even with NEE)
                assert!(equal as f64 >= 0.98 * n as f64, "nee={nee}: {equal} of {n} pairs split evenly");
                assert!((sum_o - sum_b).abs() <= 2e-3 * sum_b, "nee={nee}: offsets {sum_o} vs bases {sum_b}");
            }
        }
    }

    /// One base path has one offset whichever strategy found its light: at a free
    /// non-diffuse vertex (the lacquered floor: a smooth coat over a diffuse base), the
    /// offset's version of a BSDF-sampled light hit and of the same light point taken as a
    /// light sample are the same (before, the light sample reconnected while the hit copied
    /// the half-vector, so the pair's MIS weights over both strategies did not sum to one;
    /// this test failed).
    #[test]
    fn light_samples_and_light_hits_of_one_path_shift_alike() {
        use crate::path::{trace_path, PathSettings};
        use crate::sampler::{IndependentSampler, Sampler};
        let scene = Scene::build(&crate::scene::builtin::cornell_spheres(16, 16)).unwrap();
        let cfg = PathSettings::new(4, true);
        let mut base = Path::default();
        let mut compared = 0;
        for i in 0..200_000u64 {
            let mut smp = IndependentSampler::new(31, i);
            let raster = Vec2::new((i % 16) as f32, 12.0 + ((i / 16) % 4) as f32) + smp.next_2d();
            trace_path(&scene, &cfg, raster, &mut smp, Some(&mut base));
            for e in base.events.iter().filter(|e| !e.nee && e.vertex != CAMERA_VERTEX && !e.delta) {
                let x = &base.vertices[e.vertex as usize];
                if x.delta_out || x.diffuse || !scene.is_triangle_light(e.light) {
                    continue;
                }
                let as_light_sample = Event { nee: true, ..*e };
                let at_k = || {
                    let mut o = Offset::new(&scene, &base, Some(raster + Vec2::X));
                    while o.k < e.vertex as usize {
                        o.advance();
                    }
                    o
                };
                let (hit, sampled) = (at_k().own_event(e), at_k().own_event(&as_light_sample));
                match (hit, sampled) {
                    (Some((a, pa)), Some((b, pb))) => {
                        let close = |p: f32, q: f32| (p - q).abs() <= 1e-3 * p.abs().max(q.abs()).max(1e-6);
                        assert!(
                            close(pa, pb) && (0..3).all(|c| close(a[c], b[c])),
                            "path {i}: {a} / {pa} vs {b} / {pb}"
                        );
                        compared += 1;
                    }
                    (None, None) => {}
                    other => panic!("path {i}: one strategy's offset exists, the other's not: {other:?}"),
                }
            }
        }
        assert!(compared > 50, "only {compared} light hits from free non-diffuse vertices");
    }

    /// The class a base vertex keeps (`Vertex::diffuse`, set by the path builder) is the
    /// class of its BSDF rebuilt from the vertex, on paths through diffuse, glossy, mirror and
    /// glass surfaces.
    #[test]
    fn kept_vertex_classes_are_their_bsdfs_classes() {
        use crate::path::{trace_path, PathSettings};
        use crate::sampler::{IndependentSampler, Sampler};
        let scene = Scene::build(&crate::scene::builtin::cornell_spheres(32, 32)).unwrap();
        let cfg = PathSettings::new(6, true);
        let mut base = Path::default();
        let mut seen = [0usize; 2];
        for i in 0..2000u64 {
            let mut smp = IndependentSampler::new(5, i);
            let raster = Vec2::new((i % 32) as f32, ((i / 32) % 32) as f32) + smp.next_2d();
            trace_path(&scene, &cfg, raster, &mut smp, Some(&mut base));
            for v in &base.vertices {
                assert_eq!(v.diffuse, bsdf_at(&scene, v).is_diffuse(), "sample {i} at {}", v.p);
                seen[usize::from(v.diffuse)] += 1;
            }
        }
        assert!(seen[0] > 100 && seen[1] > 1000, "vertices (specular, diffuse): {seen:?}");
    }

    #[test]
    fn shift_then_inverse_shift_is_the_identity() {
        use crate::path::{trace_path, PathSettings};
        use crate::sampler::{IndependentSampler, Sampler};
        let scene = Scene::build(&crate::scene::builtin::cornell_spheres(32, 32)).unwrap();
        let cfg = PathSettings::new(6, true);
        let mut base = Path::default();
        let (mut compared, mut through_specular) = (0, 0);
        for i in 0..4000u64 {
            let mut smp = IndependentSampler::new(21, i);
            let raster = Vec2::new(4.0 + (i % 24) as f32, 8.0 + ((i / 24) % 20) as f32) + smp.next_2d();
            trace_path(&scene, &cfg, raster, &mut smp, Some(&mut base));
            let dx = if i % 2 == 0 { Vec2::X } else { Vec2::Y };
            let offset = offset_path(&scene, &base, raster + dx);
            if offset.vertices.len() < 2 {
                continue;
            }
            let back = offset_path(&scene, &offset, raster);
            let n = offset.vertices.len();
            assert!(back.vertices.len() >= n, "inverse shift failed earlier ({} < {n})", back.vertices.len());
            for (a, b) in back.vertices.iter().zip(&base.vertices).take(n) {
                let tol = 1e-3 * (1.0 + a.p.length());
                assert!((a.p - b.p).length() < tol, "sample {i}: {} vs {}", a.p, b.p);
            }
            compared += 1;
            if offset.vertices.iter().take(n - 1).any(|v| v.delta_out) {
                through_specular += 1;
            }
        }
        assert!(compared > 1000 && through_specular > 100, "compared {compared}, through specular {through_specular}");
    }

    /// A box whose white surfaces turn to rough gold towards grazing views (a Mix Shader by
    /// Layer Weight › Facing, exponent 5: strongly view-dependent).
    fn box_seen_from_the_view(size: u32) -> crate::scene::desc::SceneDesc {
        use crate::scene::desc::{MaterialDesc, RayFactor};
        let mut d = crate::scene::builtin::cornell_box(size, size);
        for m in d.materials.iter_mut().filter(|m| m.name == "White") {
            let gold = MaterialDesc { base_color: [1.0, 0.7, 0.25], metallic: 1.0, roughness: 0.25, ..m.clone() };
            (m.blend, m.blend_ray) = (Some(Box::new(gold)), Some(RayFactor::LayerFacing(0.9)));
        }
        d
    }

    /// Each vertex of an offset path carries its BSDF's value as seen from the offset's own
    /// previous vertex, also where the offset has joined the base path (it arrives there from
    /// elsewhere): a BSDF that blends by the view differs between the two directions (this
    /// test failed with the joined vertex's BSDF taken from the base's direction).
    #[test]
    fn offset_vertices_see_their_bsdf_from_their_own_direction() {
        use crate::path::{trace_path, PathSettings};
        use crate::sampler::{IndependentSampler, Sampler};
        let scene = Scene::build(&box_seen_from_the_view(32)).unwrap();
        let cfg = PathSettings::new(6, true);
        let mut base = Path::default();
        let mut joined = 0;
        for i in 0..3000u64 {
            let mut smp = IndependentSampler::new(5, i);
            let raster = Vec2::new((i % 32) as f32, ((i / 32) % 32) as f32) + smp.next_2d();
            trace_path(&scene, &cfg, raster, &mut smp, Some(&mut base));
            let offset = offset_path(&scene, &base, raster + Vec2::X);
            // (the vertices where the offset has joined the base: the same point, the
            // offset's own incoming direction)
            for (k, v) in offset.vertices.iter().enumerate().skip(1) {
                if v.p != base.vertices[k].p || v.delta_out || !(v.pdf_out > 0.0) || v.wi == Vec3::ZERO {
                    continue;
                }
                let (wo, wi) = (v.frame.to_local(v.wo), v.frame.to_local(v.wi));
                let want = bsdf_at(&scene, v).eval(wo, wi);
                let tol = 2e-3 * (1.0 + want.max_element()); // (f32 round trips of the directions)
                assert!((v.f_out - want).abs().max_element() <= tol, "path {i} vertex {k}: {} vs {want}", v.f_out);
                if v.wo != base.vertices[k].wo {
                    joined += 1;
                }
            }
        }
        assert!(joined > 500, "{joined} joined vertices compared");
    }

    /// The pair estimator is unbiased pixel by pixel: I(q) = E_q[base part of the shift
    /// towards q−1] + E_{q−1}[offset part of the shift towards q], compared with path tracing
    /// along a row that crosses the glass sphere (reflection and refraction chains, light
    /// seen through the glass), a row of lacquered floor (a smooth specular layer over a
    /// diffuse base: mixed delta and diffuse lobes at one vertex), a row of ceiling beside the light (pixels whose neighbours
    /// see the black-bodied emitter) and rows through the semi-transparent veil and canopy
    /// (pass-through vertices, transparent shadows), with and without NEE. Tolerance: 4.5 standard errors of the
    /// difference, measured from the samples.
    #[test]
    fn pair_estimator_is_unbiased_per_pixel() {
        use crate::path::{trace_path, PathSettings};
        use crate::sampler::{IndependentSampler, Sampler};
        use crate::scene::builtin::{cornell_spheres, cornell_veil};
        let (w, n) = (16usize, 60_000u64);
        // and a box whose left wall is pure red: base paths leaving it carry no green, offsets
        // from the white wall beside it do (with the base throughput's per-channel ratio the
        // offset lost that green for good once joined: this test failed on channel G)
        let mut red = crate::scene::builtin::cornell_box(16, 16);
        red.materials.iter_mut().filter(|m| m.name == "Red").for_each(|m| m.base_color = [0.9, 0.0, 0.0]);
        // and a box whose white surfaces turn to rough gold towards grazing views (a Mix
        // Shader by Layer Weight › Facing): BSDFs that depend on the direction they are seen
        // from (`offset_vertices_see_their_bsdf_from_their_own_direction`)
        let scenes = [
            Scene::build(&cornell_spheres(16, 16)).unwrap(),
            Scene::build(&cornell_veil(16, 16)).unwrap(),
            Scene::build(&red).unwrap(),
            Scene::build(&box_seen_from_the_view(16)).unwrap(),
        ];
        // rows: along the ceiling beside the light (row 3), across the glass sphere and the
        // veil (row 11) and over the lacquered floor (row 13); channel: None = luminance
        // indirect: the pairs of indirect light only (`shift_indirect`, the Metropolis
        // methods'), against path tracing's radiance minus its direct light
        // (the twelve cases in parallel: the longest of the library's tests otherwise)
        use rayon::prelude::*;
        let cases = [
            (0, true, 3.0f32, None, false),
            (0, true, 11.0, None, false),
            (0, false, 11.0, None, false),
            (0, true, 13.0, None, false),
            (1, true, 3.0, None, false),
            (1, false, 11.0, None, false),
            (2, true, 8.0, Some(1), false),
            (0, true, 11.0, None, true),
            (1, false, 11.0, None, true),
            (1, true, 11.0, None, true),
            (3, true, 13.0, None, false),
            (3, false, 6.0, None, false),
        ];
        cases.into_par_iter().for_each(|(si, nee, row, channel, indirect)| {
            let pair = if indirect { shift_indirect } else { shift };
            let pick = |v: Spectrum| -> f64 { channel.map_or(crate::math::luminance(v), |c| v[c]) as f64 };
            let scene = &scenes[si];
            let cfg = PathSettings::new(6, nee);
            let mut base = Path::default();
            // per pixel: [Σ pt, Σ pt², Σ base, Σ base², Σ offset, Σ offset²]
            let mut acc = vec![[0.0f64; 6]; w];
            for x in 0..w {
                for i in 0..n {
                    let mut smp = IndependentSampler::new(77, i * 64 + x as u64);
                    let raster = Vec2::new(x as f32, row) + smp.next_2d();
                    let c = trace_path(scene, &cfg, raster, &mut smp, Some(&mut base));
                    let l = pick(c.radiance - if indirect { c.direct } else { c.very_direct });
                    let back = (x > 0).then(|| raster - Vec2::X);
                    let b = pick(pair(scene, &base, back).base);
                    acc[x][0] += l;
                    acc[x][1] += l * l;
                    acc[x][2] += b;
                    acc[x][3] += b * b;
                    if x + 1 < w {
                        let o = pick(pair(scene, &base, Some(raster + Vec2::X)).offset);
                        acc[x + 1][4] += o;
                        acc[x + 1][5] += o * o;
                    }
                }
            }
            let nf = n as f64;
            let var = |s: f64, s2: f64| (s2 / nf - (s / nf).powi(2)).max(0.0) / nf;
            for (x, a) in acc.iter().enumerate() {
                let (pt, gd) = (a[0] / nf, (a[2] + a[4]) / nf);
                let se = (var(a[0], a[1]) + var(a[2], a[3]) + var(a[4], a[5])).sqrt();
                assert!(
                    (pt - gd).abs() <= 4.5 * se + 1e-6,
                    "scene {si} nee={nee} row {row} {channel:?} indirect={indirect} pixel {x}: path tracing {pt} vs pair {gd} (se {se})"
                );
            }
        });
    }

    mod properties {
        use super::super::half_vector_copy;
        use glam::Vec3;
        use proptest::prelude::*;

        fn upper(a: f32, b: f32) -> Vec3 {
            crate::math::square_to_cosine_hemisphere(glam::Vec2::new(a, b)) + Vec3::new(0.0, 0.0, 0.05)
        }

        proptest! {
            /// For any base bounce and offset direction: the copy stays on the base bounce's
            /// side (reflection above, refraction below), its inverse copy returns the base
            /// direction, and the two Jacobians multiply to one.
            #[test]
            fn half_vector_copy_is_an_involution(a in 0.0f32..1.0, b in 0.0f32..1.0, c in 0.0f32..1.0,
                                                  d in 0.0f32..1.0, e in 0.0f32..1.0, f in 0.0f32..1.0,
                                                  eta in prop_oneof![Just(1.0f32), 1.05f32..2.5, 0.4f32..0.95]) {
                let (wo_x, wo_y, m) = (upper(a, b).normalize(), upper(c, d).normalize(), upper(e, f).normalize());
                let wi_x = if eta == 1.0 {
                    crate::bsdf::microfacet::reflect(wo_x, m)
                } else {
                    match crate::bsdf::microfacet::refract(wo_x, m, eta) { Some(w) => w, None => return Ok(()) }
                };
                prop_assume!(wi_x.z.abs() > 0.05);
                if let Some((wi_y, j)) = half_vector_copy(wo_x, wi_x, eta, wo_y, eta) {
                    prop_assert!((wi_y.z > 0.0) == (wi_x.z > 0.0));
                    prop_assert!(j.is_finite() && j > 0.0);
                    let (back, jb) = half_vector_copy(wo_y, wi_y, eta, wo_x, eta).expect("inverse exists");
                    prop_assert!((back - wi_x).length() < 2e-3, "{} vs {}", back, wi_x);
                    prop_assert!((j * jb - 1.0).abs() < 2e-2, "J·J⁻¹ = {}", j * jb);
                }
            }
        }
    }
}
