//! Bidirectional path tracing, `bdpt` (Veach 1997 ch. 10; Lafortune & Willems 1993; laid
//! out as pbrt-v3's bdpt.cpp): per pixel sample, a camera subpath and a light subpath, and
//! every way of joining them, weighted by multiple importance sampling over all strategies
//! of the full path (power heuristic).
//!
//! A full path of n vertices z₀ (on a light) … z_{n−1} (the camera) is made by strategy
//! (s, t), s + t = n: s vertices from the light subpath, t from the camera subpath:
//! * s = 0: the camera subpath hits the light (an emissive surface, an area or sphere light
//!   it crosses, the world);
//! * s = 1: next-event estimation at the camera subpath's last vertex (`Scene::sample_light`,
//!   the light tree: the same light samples `pt` takes);
//! * s ≥ 2, t ≥ 2: a shadow ray joins the two subpaths' last vertices;
//! * t = 1: light tracing — the light subpath's vertex is joined to a point of the lens and
//!   its light lands in whichever pixels the pixel filter gives it (`Camera::importance`).
//!   (s, t) = (1, 1), a light seen directly through a lens sample, is left to s = 0.
//!
//! What the full path is worth is the function `pt` integrates (docs/bidirectional.md):
//! Le · Π f(ωo, ωi)·|n_s·ωi| · Π |n_g·ω|/d² over segments, the geometric cosine taken at each
//! segment's light-side end — so that every strategy estimates what `pt` and Cycles
//! estimate, shading normals included. The light subpath carries it with the adjoint update
//! (Veach §5.3): f(ω_next, ω_prev)·|n_s·ω_prev|·|n_g·ω_next| / (|n_g·ω_prev|·pdf).
//!
//! MIS weights come from each vertex's two densities (area measure; solid angle at a light
//! at infinity): of being made by the light-side walk and by the camera-side walk, as pbrt
//! keeps them (`pdf_fwd`, `pdf_rev`), with the joined vertices' densities computed at the
//! join. The light point's density differs by strategy: s = 1 chooses it as next-event
//! estimation does (light tree), s ≥ 2 as light subpaths do (by power): both are used.
//! Light tracing is weighed pixel by pixel with the pixel filter's density, and its N light
//! paths (one per camera sample) against each pixel's own samples.
//!
//! Parameters (RenderSettings): `spp` (one camera and one light subpath per sample), `seed`,
//! the bounce limits of `path` (Cycles' meaning, as `pt`; the kind of the two joined
//! vertices' scattering is drawn from the BSDF's lobes, `Bsdf::diffuse_share`), `nee` (off:
//! no strategy with s = 1, so no delta light is found by it — light tracing still finds
//! them). Not applied: clamping, path guiding, adaptive sampling.

use super::{RenderControl, RenderOutput, RenderSettings, RenderStats};
use crate::accel::TriHit;
use crate::bsdf::{Bsdf, LobeKind, Scatter};
use crate::film::{Film, Image};
use crate::math::Frame;
use crate::math::{is_finite_spectrum, power_heuristic, Spectrum};
use crate::medium::{FreeFlight, MediumStack, Phase};
use crate::path::{survival_probability, PathContribution, PathSettings, NO_KIND_LIMIT, RR_START_DEPTH};
use crate::sampler::{Sampler, SobolSampler};
use crate::scene::emit::EmitterSelection;
use crate::scene::{Scene, SurfaceInteraction};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Camera,
    Light,
    Surface,
    /// A scattering in a medium (`crate::medium`): no surface, a phase function.
    Medium,
}

/// The scattering label of a vertex in a medium (the per-kind limits' fourth, Volume).
const VOLUME_LABEL: u8 = 3;

/// No scattering label (endpoints, and vertices whose walk ended there).
const NO_LABEL: u8 = 4;

/// One vertex of a subpath, camera or light side alike.
#[derive(Clone, Copy, Debug)]
struct Vertex {
    kind: Kind,
    /// Position (the lens point for the camera; unused for a light at infinity).
    p: Vec3,
    /// Geometric normal; zero where there is no surface (the camera, a point light, a light
    /// at infinity): no cosine is taken there.
    ng: Vec3,
    /// A light at infinity (the sun, the world); `dir` is the unit direction towards it.
    infinite: bool,
    dir: Vec3,
    si: Option<SurfaceInteraction>,
    /// The BSDF as seen from the side the walk arrived on (`facing` turns it round).
    bsdf: Option<Bsdf>,
    hit: Option<TriHit>,
    /// Throughput arriving here (for light subpaths: without the pending 1/|n_g·ω_prev|,
    /// which the join or the next scattering supplies).
    beta: Spectrum,
    /// Density of this vertex made by its own walk, and by the walk from the other side.
    pdf_fwd: f32,
    pdf_rev: f32,
    /// The walk left a surface vertex by a delta lobe; a light vertex: no ray can hit it.
    delta: bool,
    /// A join may end here (a surface with a non-delta lobe, a light, a perspective camera).
    connectible: bool,
    /// The kind of the scattering the walk made here (0 diffuse, 1 glossy, 2 transmission).
    label: u8,
    /// Light index of a light vertex.
    light: u32,
    /// The camera vertex's pixel centre (raster).
    pixel: Vec2,
    /// The walk went straight through here (a transparent surface's pass-through lobe): the
    /// vertex ends joins only, the walk goes on from the vertex before (module comment).
    branch: bool,
    /// Next-event estimation's density of the light origin seen from here (light-subpath
    /// vertices that follow the origin directly).
    origin_nee: f32,
    /// The media the walk arrived here in (a surface's: on the side it arrived from).
    media: MediumStack,
    /// A vertex in a medium: its phase function.
    phase: Option<Phase>,
    /// Where a camera subpath's walk beneath a surface left it (`path::walk_beneath`): the
    /// vertex after it (towards the camera) is the entry, the walk between them a transition
    /// only the camera side makes.
    walk_exit: bool,
    /// Walks beneath surfaces the camera subpath made up to here: its vertices count that
    /// many fewer bounces (entering is not one, as in Cycles).
    walks: u8,
}

impl Vertex {
    fn endpoint(kind: Kind, p: Vec3) -> Vertex {
        Vertex {
            kind,
            p,
            ng: Vec3::ZERO,
            infinite: false,
            dir: Vec3::ZERO,
            si: None,
            bsdf: None,
            hit: None,
            beta: Spectrum::ONE,
            pdf_fwd: 0.0,
            pdf_rev: 0.0,
            delta: false,
            connectible: true,
            label: NO_LABEL,
            light: u32::MAX,
            pixel: Vec2::ZERO,
            branch: false,
            origin_nee: 0.0,
            media: MediumStack::default(),
            phase: None,
            walk_exit: false,
            walks: 0,
        }
    }

    #[inline]
    fn is_surface(&self) -> bool {
        self.kind == Kind::Surface
    }
}

/// Unit direction from a to b and the squared distance (1 towards or from infinity).
#[inline]
fn direction(a: &Vertex, b: &Vertex) -> (Vec3, f32) {
    if b.infinite {
        (b.dir, 1.0)
    } else if a.infinite {
        (-a.dir, 1.0)
    } else {
        let d = b.p - a.p;
        let l2 = d.length_squared();
        (d / l2.sqrt(), l2)
    }
}

/// The camera's endpoint vertex at lens point `p`: an orthographic camera's as a vertex at
/// infinity (`Camera::parallel`), its direction the way back to the camera, so that densities
/// from it are per unit area projected along its rays and its joins carry no 1/d².
fn camera_vertex(scene: &Scene, p: Vec3) -> Vertex {
    let mut v = Vertex::endpoint(Kind::Camera, p);
    if scene.camera.parallel() {
        v.infinite = true;
        v.dir = -scene.camera.forward();
    }
    v
}

/// A density per solid angle at `a` towards `b` as a density of `b` (area; solid angle
/// when b is at infinity; from a light at infinity, the disc's density projected on b).
#[inline]
fn convert(pdf: f32, a: &Vertex, b: &Vertex) -> f32 {
    if b.infinite {
        return pdf;
    }
    let (w, d2) = direction(a, b);
    let cos = if b.ng == Vec3::ZERO { 1.0 } else { b.ng.dot(w).abs() };
    if a.infinite {
        pdf * cos
    } else {
        pdf * cos / d2
    }
}

/// Surface vertex `v`'s BSDF and shading frame as seen from the side of `wo` (world): the
/// BSDFs are built for the side a ray arrives on (their ωo above the frame), so a pair with
/// ωo on the other side — light subpaths seen through a surface, reverse densities across
/// one — is evaluated with the surface built for a ray from there.
fn facing(scene: &Scene, v: &Vertex, wo: Vec3) -> Option<(Bsdf, Frame)> {
    let (si, bsdf) = (v.si.as_ref()?, v.bsdf?);
    // (a walk's exit: its camera-side neighbour is the entry, reached beneath the surface —
    // its white Lambertian faces out, whatever the direction between the two points)
    if wo.dot(si.ng) >= 0.0 || v.walk_exit {
        return Some((bsdf, si.frame));
    }
    if !bsdf.transmits() {
        // no non-delta lobe crosses the surface: nothing reaches the other side's pairs
        // (value and density 0), so the surface is not rebuilt to say so
        return None;
    }
    let hit = v.hit?;
    let other = SurfaceInteraction { camera: si.camera, ..scene.interaction(&hit, -wo) };
    Some((scene.bsdf_at(&other), other.frame))
}

/// What every subpath and join of one render shares.
pub(crate) struct Context<'a> {
    scene: &'a Scene,
    cfg: &'a PathSettings,
    emitters: EmitterSelection,
    /// Pixels of the image (light tracing's N light paths per camera sample of a pixel).
    pixels: f32,
    /// Some per-kind bounce limit binds before the total.
    kind_limits: bool,
    /// A diagnostic (`GDMLT_BDPT_ONLY=k`): each full path of n vertices from strategy
    /// min(k, n − 1) alone, unweighted (n = 2 from the camera): every strategy must render
    /// the same image.
    only: Option<usize>,
    /// Estimate `pt`'s second moment per pixel from this render's samples
    /// (`RenderSettings::predict_pt`, `PtMoments`).
    predict_pt: bool,
}

impl<'a> Context<'a> {
    /// The context of a render of `scene` with path settings `cfg`.
    pub(crate) fn new(scene: &'a Scene, cfg: &'a PathSettings, only: Option<usize>) -> Context<'a> {
        let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
        Context {
            scene,
            cfg,
            emitters: scene.emitter_selection(),
            pixels: (w * h) as f32,
            kind_limits: [cfg.diffuse_bounces, cfg.glossy_bounces, cfg.transmission_bounces, cfg.volume_bounces]
                .iter()
                .any(|&k| k < cfg.max_bounces && k < NO_KIND_LIMIT),
            only,
            predict_pt: false,
        }
    }
}

impl Context<'_> {
    /// The density with which vertex `a` (reached from `prev`) makes `b`: its BSDF's, the
    /// camera's (through the pixel of `a`), or the light's emission.
    fn pdf(&self, a: &Vertex, prev: Option<&Vertex>, b: &Vertex) -> f32 {
        match a.kind {
            Kind::Surface => {
                let Some(prev) = prev else { return 0.0 };
                let (wn, _) = direction(a, b);
                let (wp, _) = direction(a, prev);
                let Some((bsdf, frame)) = facing(self.scene, a, wp) else { return 0.0 };
                convert(bsdf.pdf(frame.to_local(wp), frame.to_local(wn)), a, b)
            }
            Kind::Medium => {
                let (Some(prev), Some(phase)) = (prev, a.phase) else { return 0.0 };
                convert(phase.pdf(direction(a, prev).0, direction(a, b).0), a, b)
            }
            Kind::Camera => self.camera_pdf(a, b),
            Kind::Light => {
                let (w, _) = direction(a, b);
                let n = if a.infinite { Vec3::ZERO } else { a.ng };
                convert(self.scene.light_emit_pdf(a.light, n, w), a, b)
            }
        }
    }

    /// The density of b made by the camera's ray through the pixel of camera vertex `cam`,
    /// relative to light tracing's N light paths (÷ pixels): filter × W / pixels.
    fn camera_pdf(&self, cam: &Vertex, b: &Vertex) -> f32 {
        if b.infinite {
            return 0.0;
        }
        let Some((raster, we)) = self.scene.camera.importance(cam.p, b.p) else { return 0.0 };
        // (a panorama sees b at more than one place near its edges: the filter over each)
        convert(self.scene.camera.filter_weight(raster, cam.pixel) * we / self.pixels, cam, b)
    }

    /// The light-origin density of light vertex `v` (light subpaths' choice by power).
    fn origin_pdf(&self, v: &Vertex) -> f32 {
        self.scene.light_origin_pdf(&self.emitters, v.light, if v.infinite { v.dir } else { v.p })
    }

    /// Next-event estimation's density (solid angle at `from`, selection included) of light
    /// vertex `v`, as a density of the light point (the measure of `origin_pdf`).
    fn nee_pdf_of(&self, v: &Vertex, pdf_sa: f32, from: Vec3) -> f32 {
        if v.infinite || self.scene.is_delta_light(v.light) {
            return pdf_sa;
        }
        let to = from - v.p;
        let d2 = to.length_squared();
        let cos = if v.ng == Vec3::ZERO { 1.0 } else { v.ng.dot(to).abs() / d2.sqrt() };
        pdf_sa * cos / d2
    }
}

/// Light found by the camera subpath (strategy s = 0).
#[derive(Clone, Copy, Debug)]
struct Emission {
    /// The camera subpath's length when it was found: its chain is the vertices the walk
    /// scattered at before index `t` (branch vertices on the way are not on it).
    t: usize,
    light: Vertex,
    /// Throughput × radiance.
    value: Spectrum,
    /// Next-event estimation's density of the light point from C_{t−1} (light's measure).
    pdf_nee: f32,
    /// Only the camera path can find it (a backdrop, a surface that glows for the camera
    /// only): weight 1.
    alone: bool,
}

/// The scratch of one sample (reused: no allocation once warm).
#[derive(Default)]
pub(crate) struct Scratch {
    camera: Vec<Vertex>,
    light: Vec<Vertex>,
    events: Vec<Emission>,
    fwd_l: Vec<f64>,
    fwd_c: Vec<f64>,
    /// The indices of the vertices each subpath scattered at (not branches).
    camera_reals: Vec<u32>,
    light_reals: Vec<u32>,
    /// `pt`'s moments this sample's camera contributions estimate at its pixel, and those of
    /// its light-tracing splats, per pixel (`Context::predict_pt` only).
    moments: PtMoments,
    moment_splats: Vec<(u32, u32, PtMoments)>,
}

/// What a camera sample gives its own pixel.
#[derive(Default)]
struct CameraResult {
    out: PathContribution,
}

/// The walk of one subpath from its endpoint (`path[0]`), whose first segment (o, d) was
/// sampled with solid-angle density `pdf_dir` (the disc's density from a light at infinity).
/// Camera walks (`radiance`) record the light they find in `events`; light walks (with
/// `origin_light`) take their throughput at the first surface from the light's radiance
/// there.
#[allow(clippy::too_many_arguments)]
fn random_walk<S: Sampler + ?Sized>(
    ctx: &Context,
    sampler: &mut S,
    path: &mut Vec<Vertex>,
    mut o: Vec3,
    mut d: Vec3,
    mut tmin: f32,
    mut tmax: f32,
    mut beta: Spectrum,
    mut pdf_dir: f32,
    radiance: bool,
    mut events: Option<&mut Vec<Emission>>,
    out: &mut PathContribution,
    mut media: MediumStack,
) {
    let scene = ctx.scene;
    let cfg = ctx.cfg;
    let has_media = scene.has_media();
    let max_surface = cfg.max_bounces as usize + 1;
    let mut transparent = 0u32;
    let mut scattered = false; // (camera walks: past the first scattering)
    let mut surfaces = 0usize;
    let mut guide = Some(Spectrum::ONE);
    let mut first_light_hit = !radiance;
    // a scattering past a per-kind bounce limit (pt's path stops there: the segments after it
    // gather no emission in a medium)
    let limits = [cfg.diffuse_bounces, cfg.glossy_bounces, cfg.transmission_bounces, cfg.volume_bounces];
    let (mut kinds, mut past_limits) = ([0u32; 4], false);
    // Russian roulette on the throughput relative to the first vertex's (a light subpath
    // carries the light's power)
    let mut beta_ref = Spectrum::ONE;
    let mut last = 0usize; // the last vertex the walk scattered at (not a branch)
                           // where a camera walk beneath a surface left it (`path::walk_beneath`): the next vertex
    let mut exit: Option<(SurfaceInteraction, TriHit)> = None;
    loop {
        let prev = path[last];
        let exited = exit.is_some();
        let (si, hit, camera_ray) = if let Some((si, hit)) = exit.take() {
            (si, hit, false)
        } else {
            let camera_ray = radiance && !scattered;
            // (light linking: the object of the vertex the ray left, none from the camera)
            let receiver = prev.si.as_ref().map_or(u32::MAX, |s| s.prim);
            let hit =
                if camera_ray { scene.intersect_camera(o, d, tmin, tmax) } else { scene.intersect(o, d, tmin, tmax) };
            let mut t_surface = hit.map_or(tmax, |h| h.t);
            // the medium the segment runs through (pt's free flight: path.rs): its emission (found
            // by the camera alone), a scattering before the surface or the weight of passing
            let u_dist = if has_media { sampler.next_1d() } else { 0.0 };
            let medium = if has_media { scene.medium(&media) } else { None };
            let (mut scatter_at, mut pass) = (None, Spectrum::ONE);
            let from_medium = prev.kind == Kind::Medium;
            // (only built in a medium: it is a few hundred bytes)
            let mut crossings = None;
            if let Some(m) = medium {
                let crossings = crossings.insert(crate::medium::Crossings::default());
                if events.is_some() {
                    let push = |li, t, le, pdf| crossings.push(li, t, le, pdf);
                    scene.for_each_light_crossed_in(prev.p, from_medium, o, d, t_surface, camera_ray, push);
                }
                let flight = scene.fly(&m, o, d, t_surface, u_dist, crossings);
                let e = flight.emitted * beta;
                if radiance && !past_limits && e.max_element() > 0.0 {
                    out.radiance += e;
                    if camera_ray {
                        out.very_direct += e;
                    }
                }
                match flight.free {
                    FreeFlight::Scatter { t, weight } => {
                        scatter_at = Some((m, t, weight));
                        t_surface = t;
                    }
                    FreeFlight::Pass { weight } => pass = weight,
                }
            }
            if let Some(ev) = events.as_deref_mut() {
                // lights crossed (strategy s = 0), as a light sample from the vertex the ray left
                // sees them (from a medium: `light::FacingDisk`), reached in a medium with the
                // flight's weight where it passed them
                let t = path.len();
                let mut light_crossed = |li: u32, tl: f32, le: Spectrum, pdf_l: f32| {
                    if !scene.lights_receiver(li, receiver) {
                        return; // (light linking: it does not light the vertex the ray left)
                    }
                    let inf = !tl.is_finite();
                    let z = if inf { d } else { o + d * tl };
                    let mut lv = Vertex::endpoint(Kind::Light, z);
                    lv.light = li;
                    lv.infinite = inf;
                    lv.dir = d;
                    lv.ng = scene.light_normal(li, z);
                    lv.pdf_fwd = ctx.origin_pdf(&lv);
                    let pdf_nee = ctx.nee_pdf_of(&lv, pdf_l, prev.p);
                    ev.push(Emission { t, light: lv, value: beta * le, pdf_nee, alone: false });
                };
                if let Some(crossings) = &crossings {
                    for i in (0..crossings.n).filter(|&i| crossings.weight[i].max_element() > 0.0) {
                        let le = crossings.le[i] * crossings.weight[i];
                        light_crossed(crossings.light[i], crossings.t[i], le, crossings.pdf[i]);
                    }
                } else {
                    scene.for_each_light_crossed_in(prev.p, from_medium, o, d, t_surface, camera_ray, light_crossed);
                }
            }
            if let Some((m, t, weight)) = scatter_at {
                // a scattering in the medium: a vertex of its own, the phase function's sample
                beta *= weight;
                if !(beta.max_element() > 0.0) {
                    break;
                }
                let p = o + d * t;
                // a soft-falloff sphere light is a disk facing a point in a medium, which light
                // subpaths do not start from (`Context::mis_weight`: disk paths) — also after
                // the transparent boundaries crossed on the way
                if prev.kind == Kind::Light && scene.sees_facing_disk(prev.light) {
                    break;
                }
                if first_light_hit {
                    // the light's radiance as this point receives it (as at a surface, below)
                    first_light_hit = false;
                    let l0 = &path[0];
                    let z = if l0.infinite { l0.dir } else { l0.p };
                    let Some((le, _)) = scene.light_eval_in(l0.light, p, z, true) else { break };
                    let factor = if l0.infinite {
                        1.0
                    } else if l0.ng == Vec3::ZERO {
                        (p - l0.p).length_squared()
                    } else {
                        l0.ng.dot(d).abs()
                    };
                    beta *= le * factor;
                    beta_ref = beta.max(Spectrum::splat(1e-30));
                }
                if surfaces >= max_surface {
                    break; // (no pass-through in a medium)
                }
                let mut v = Vertex::endpoint(Kind::Medium, p);
                if prev.kind == Kind::Light {
                    let z = if prev.infinite { prev.dir } else { prev.p };
                    let pdf = scene.light_eval_in(prev.light, p, z, true).map_or(0.0, |x| x.1);
                    v.origin_nee = ctx.nee_pdf_of(&prev, pdf, p);
                }
                v.beta = beta;
                v.pdf_fwd = convert(pdf_dir, &prev, &v);
                v.media = media;
                v.phase = Some(m.phase);
                v.label = VOLUME_LABEL;
                path.push(v);
                past_limits |= kinds.iter().zip(&limits).any(|(n, max)| n > max);
                kinds[VOLUME_LABEL as usize] += 1;
                surfaces += 1;
                scattered = true;
                let before = last;
                last = path.len() - 1;
                let _u_lobe = sampler.next_1d();
                let u_phase = sampler.next_2d();
                let u_rr = sampler.next_1d();
                let (wi, pdf, w) = m.phase.sample(-d, u_phase);
                beta *= w; // (p/pdf: 1 for Henyey–Greenstein; p is symmetric, so the adjoint too)
                           // (the density depends on cos θ alone: the reverse density is the forward one)
                path[before].pdf_rev = convert(pdf, &path[last], &path[before]);
                if surfaces as u32 >= RR_START_DEPTH {
                    let q = survival_probability(beta / beta_ref);
                    if !(q > 0.0) || u_rr >= q {
                        break;
                    }
                    beta /= q;
                }
                if !is_finite_spectrum(beta) || !(beta.max_element() > 0.0) || !(pdf > 0.0) {
                    break;
                }
                pdf_dir = pdf;
                o = p;
                d = wi;
                tmin = 0.0;
                tmax = f32::INFINITY;
                continue;
            }
            beta *= pass;
            if !(beta.max_element() > 0.0) {
                break;
            }
            let Some(hit) = hit else {
                if let Some(ev) = events.as_deref_mut() {
                    if camera_ray && scene.camera.film_transparent {
                        out.transparent += (beta.x + beta.y + beta.z) / 3.0;
                    } else if let Some(backdrop) = scene.backdrop.as_ref().filter(|_| camera_ray) {
                        let le = backdrop.eval(&scene.textures, d);
                        let lv = Vertex::endpoint(Kind::Light, Vec3::ZERO);
                        ev.push(Emission { t: path.len(), light: lv, value: beta * le, pdf_nee: 0.0, alone: true });
                    } else {
                        let (le, pdf_l) = scene.world_eval(prev.p, d);
                        if le.max_element() > 0.0 {
                            let mut lv = Vertex::endpoint(Kind::Light, Vec3::ZERO);
                            lv.light = scene.env_light();
                            lv.infinite = true;
                            lv.dir = d;
                            lv.pdf_fwd = ctx.origin_pdf(&lv);
                            ev.push(Emission {
                                t: path.len(),
                                light: lv,
                                value: beta * le,
                                pdf_nee: pdf_l,
                                alone: false,
                            });
                        }
                    }
                }
                break;
            };
            if camera_ray && scene.is_holdout(hit.prim) {
                // a holdout the camera sees: the film's transparency, and no vertex to join
                out.transparent += (beta.x + beta.y + beta.z) / 3.0;
                break;
            }
            let si = SurfaceInteraction { camera: camera_ray, ..scene.interaction(&hit, d) };
            if first_light_hit {
                // the light's radiance as this surface receives it (module comment of scene/emit.rs)
                first_light_hit = false;
                let l0 = &path[0];
                if !scene.lights_receiver(l0.light, si.prim) {
                    break; // (light linking: the light does not light what it meets first)
                }
                let z = if l0.infinite { l0.dir } else { l0.p };
                let Some((le, pdf_nee)) = scene.light_eval(l0.light, si.p, z) else { break };
                let factor = if l0.infinite {
                    1.0
                } else if l0.ng == Vec3::ZERO {
                    (si.p - l0.p).length_squared() // a point light: light_eval divided by d²
                } else {
                    l0.ng.dot(d).abs()
                };
                beta *= le * factor;
                beta_ref = beta.max(Spectrum::splat(1e-30));
                let _ = pdf_nee;
            }
            if let Some(ev) = events.as_deref_mut() {
                let emission = scene
                    .surface_emission(&si, prev.p, d)
                    .filter(|_| scene.triangle_light(si.prim).is_none_or(|li| scene.lights_receiver(li, receiver)));
                if let Some((le, pdf_l)) = emission {
                    let li = scene.triangle_light(si.prim);
                    let mut lv = Vertex::endpoint(Kind::Light, si.p);
                    lv.ng = si.ng;
                    lv.light = li.unwrap_or(u32::MAX);
                    if li.is_some() {
                        lv.pdf_fwd = ctx.origin_pdf(&lv);
                    }
                    let pdf_nee = if li.is_some() { ctx.nee_pdf_of(&lv, pdf_l, prev.p) } else { 0.0 };
                    ev.push(Emission { t: path.len(), light: lv, value: beta * le, pdf_nee, alone: li.is_none() });
                }
            }
            (si, hit, camera_ray)
        };
        if surfaces >= max_surface {
            // (the segment after the last vertex found its light; no vertex beyond.) A camera
            // path goes on through transparent surfaces to the light behind them, as Cycles'
            // PATH_RAY_TERMINATE_AFTER_TRANSPARENT and pt do: their pass-through weight.
            let pass = if radiance { scene.bsdf_at(&si).pass_through() } else { Spectrum::ZERO };
            transparent += 1;
            beta *= pass;
            if !(pass.max_element() > 0.0) || transparent > cfg.transparent_bounces || !(beta.max_element() > 0.0) {
                break;
            }
            media = scene.media_towards(media, &si, d);
            o = si.spawn_origin(d);
            tmin = 0.0;
            tmax = if tmax.is_finite() { (tmax - si.t).max(0.0) } else { f32::INFINITY };
            continue;
        }
        // (the exit of a walk: a white Lambertian facing out, Cycles' subsurface exit)
        let bsdf = if exited { Bsdf::Lambert(crate::bsdf::Lambert::new(Spectrum::ONE)) } else { scene.bsdf_at(&si) };
        if radiance {
            crate::path::denoising_guides(out, &mut guide, &bsdf, si.frame.n, camera_ray);
        }
        let wo = si.frame.to_local(-d);
        let u_lobe = sampler.next_1d();
        let u_bsdf = sampler.next_2d();
        let u_rr = sampler.next_1d();
        let Some(bs) = bsdf.sample(wo, u_lobe, u_bsdf) else {
            push_vertex(ctx, path, &si, &hit, bsdf, beta, pdf_dir, &prev, media);
            path.last_mut().expect("pushed").walk_exit = exited;
            break;
        };
        let wi = si.frame.to_world(bs.wi);
        if bs.scatter == Scatter::Subsurface {
            // beneath the surface: an entry vertex (its other lobes join), then — camera
            // subpaths only — the walk and its exit as the next vertex. The walk is a Dirac
            // transition for MIS (entry `delta`, exit `walk_exit`): light subpaths never walk,
            // so the strategies whose light side would are left out (`mis_weight`)
            push_vertex(ctx, path, &si, &hit, bsdf, beta, pdf_dir, &prev, media);
            if !radiance || wi.dot(si.ng) >= 0.0 {
                break;
            }
            let entry = path.len() - 1;
            path[last].pdf_rev = 0.0;
            path[entry].delta = true;
            last = entry;
            scattered = true;
            let Some(albedo) = bsdf.subsurface() else { break };
            let sss = scene.material(&si).walk();
            let seed = [u_lobe, u_bsdf.x, u_bsdf.y, u_rr]
                .iter()
                .fold(0x5eed_b0d7_u64, |h, x| crate::sampler::mix64(h ^ x.to_bits() as u64));
            let Some((out, dir_out, weight, exit_hit)) = crate::path::walk_beneath(scene, &si, wi, sss, albedo, seed)
            else {
                break;
            };
            beta *= bs.weight * weight;
            if !is_finite_spectrum(beta) || !(beta.max_element() > 0.0) {
                break;
            }
            exit = Some((out, exit_hit));
            d = -dir_out;
            pdf_dir = 0.0;
            continue;
        }
        if bs.is_pass_through(wo) {
            // straight through a transparent surface: the segment goes on, and a branch
            // vertex here lets joins reach the surface's other lobes — as often as when they
            // were sampled (pt takes its light sample there before it continues)
            if !bsdf.is_delta() {
                push_vertex(ctx, path, &si, &hit, bsdf, beta, pdf_dir, &prev, media);
                path.last_mut().expect("pushed").branch = true;
            }
            transparent += 1;
            beta *= bs.weight;
            if transparent > cfg.transparent_bounces || !(beta.max_element() > 0.0) {
                break;
            }
            media = scene.media_towards(media, &si, d);
            o = si.spawn_origin(d);
            tmin = 0.0;
            tmax = if tmax.is_finite() { (tmax - si.t).max(0.0) } else { f32::INFINITY };
            continue;
        }
        push_vertex(ctx, path, &si, &hit, bsdf, beta, pdf_dir, &prev, media);
        path.last_mut().expect("pushed").walk_exit = exited;
        surfaces += 1;
        scattered = true;
        let before = last;
        last = path.len() - 1;
        if wi.dot(si.ng) * bs.wi.z <= 0.0 {
            break; // the shading normal sent the ray through the geometric surface
        }
        let delta = bs.lobe == LobeKind::Specular;
        // the reverse density of the vertex before, and this vertex's scattering
        let turned = if wi.dot(si.ng) >= 0.0 { None } else { facing(scene, &path[last], wi) };
        let (bsdf_wi, frame_wi) = turned.unwrap_or((bsdf, si.frame));
        let rev = if delta {
            0.0
        } else {
            let pdf = bsdf_wi.pdf(frame_wi.to_local(wi), frame_wi.to_local(-d));
            convert(pdf, &path[last], &path[before])
        };
        path[before].pdf_rev = rev;
        {
            let v = &mut path[last];
            v.delta = delta;
            v.label = match bs.scatter {
                Scatter::Diffuse => 0,
                Scatter::Glossy => 1,
                _ => 2,
            };
            past_limits |= kinds.iter().zip(&limits).any(|(n, max)| n > max);
            kinds[v.label as usize] += 1;
        }
        if radiance {
            beta *= bs.weight;
        } else {
            // the adjoint: f(ω_next, ω_prev)·|n_s·ω_prev|·|n_g·ω_next| / (|n_g·ω_prev|·pdf)
            let cos_prev = si.ng.dot(-d).abs();
            let cos_next = si.ng.dot(wi).abs();
            if !(cos_prev > 0.0) {
                break;
            }
            if delta {
                // a Dirac lobe: f(ω_next, ω_prev)·|n_s·ω_prev| integrated over ω_next is its
                // weight × the Jacobian of ω_next in ω_prev — 1 for a mirror; for refraction
                // (η_prev/η_next)²·cos_prev/cos_next (Snell's law about the shading normal): the
                // adjoint of a BTDF without radiance scaling (Veach §5.2; without it, light from
                // a filament inside smooth glass was 40% short)
                let mut k = cos_next / cos_prev;
                if bs.eta != 1.0 {
                    k *= wo.z.abs() / (bs.wi.z.abs().max(1e-8) * bs.eta * bs.eta);
                }
                beta *= bs.weight * k;
            } else {
                beta *= bsdf_wi.eval(frame_wi.to_local(wi), frame_wi.to_local(-d)) * (cos_next / (cos_prev * bs.pdf));
            }
        }
        if surfaces as u32 >= RR_START_DEPTH {
            // (pt's (max β)^¼, on the throughput relative to the first vertex's; ½ and 1 were
            // measured on the window and caustics rooms, 6 s, one seed pair: relative variance
            // within ±6%, block error −8…+16% — no clear gain)
            let q = survival_probability(beta / beta_ref);
            if !(q > 0.0) || u_rr >= q {
                break;
            }
            beta /= q;
        }
        if !is_finite_spectrum(beta) || !(beta.max_element() > 0.0) {
            break;
        }
        pdf_dir = if delta { 0.0 } else { bs.pdf };
        media = scene.media_towards(media, &si, wi);
        o = si.spawn_origin(wi);
        d = wi;
        tmin = 0.0;
        tmax = f32::INFINITY;
    }
}

/// What reaches `si` of light sample `lsmp` of light `li` through what lies between (the
/// media `media` it starts in included); None when blocked. A light whose Cast Shadow is off
/// reaches it whole.
fn shadow_transmittance(
    scene: &Scene,
    si: &SurfaceInteraction,
    li: u32,
    lsmp: &crate::scene::LightSample,
    media: MediumStack,
) -> Option<Spectrum> {
    if !scene.casts_shadow(li) {
        return Some(Spectrum::ONE);
    }
    scene.transmittance_in(si, lsmp, media).map(|(tr, _, _)| tr)
}

/// The light vertex of light sample `lsmp` of light `li` (strategy s = 1).
fn light_sample_vertex(ctx: &Context, li: u32, lsmp: &crate::scene::LightSample) -> Vertex {
    let inf = !lsmp.dist.is_finite();
    let mut lv = Vertex::endpoint(Kind::Light, if inf { Vec3::ZERO } else { lsmp.p });
    lv.light = li;
    lv.infinite = inf;
    lv.dir = lsmp.wi;
    lv.ng = if inf { Vec3::ZERO } else { ctx.scene.light_normal(li, lsmp.p) };
    lv.delta = lsmp.is_delta;
    lv.pdf_fwd = ctx.origin_pdf(&lv);
    lv
}

/// Next-event estimation at camera vertex `b`, a point in a medium reached from `before`
/// (strategy s = 1): a light sample as `pt` takes one there (`Scene::sample_light_in`), the
/// phase function towards it, the transmittance through the media and boundaries on its way.
/// Calls `add(light vertex, unweighted value, NEE density of the light point)`.
fn nee_in_medium(
    ctx: &Context,
    b: &Vertex,
    before: &Vertex,
    (u_sel, u_l): (f32, Vec2),
    mut add: impl FnMut(&Vertex, Spectrum, f32),
) {
    let scene = ctx.scene;
    let Some(phase) = b.phase else { return };
    let Some((li, lsmp)) = scene.sample_light_in(b.p, u_sel, u_l, true) else { return };
    let wo = direction(b, before).0;
    let f = phase.eval(wo, lsmp.wi);
    if !(f > 0.0) {
        return;
    }
    let Some(tr) = shadow_transmittance(scene, &Scene::medium_point(b.p, wo), li, &lsmp, b.media) else { return };
    let lv = light_sample_vertex(ctx, li, &lsmp);
    let pdf_nee = ctx.nee_pdf_of(&lv, lsmp.pdf, b.p);
    add(&lv, b.beta * lsmp.radiance * tr * (f / lsmp.pdf), pdf_nee);
}

/// Appends the surface vertex at `si`, reached from `prev` with throughput `beta` by a
/// direction of density `pdf_dir` (0: a delta lobe).
#[allow(clippy::too_many_arguments)]
fn push_vertex(
    ctx: &Context,
    path: &mut Vec<Vertex>,
    si: &SurfaceInteraction,
    hit: &TriHit,
    bsdf: Bsdf,
    beta: Spectrum,
    pdf_dir: f32,
    prev: &Vertex,
    media: MediumStack,
) {
    let mut v = Vertex::endpoint(Kind::Surface, si.p);
    v.media = media;
    if prev.kind == Kind::Light {
        let z = if prev.infinite { prev.dir } else { prev.p };
        let pdf = ctx.scene.light_eval(prev.light, si.p, z).map_or(0.0, |x| x.1);
        v.origin_nee = ctx.nee_pdf_of(prev, pdf, si.p);
    }
    v.ng = si.ng;
    v.si = Some(*si);
    v.hit = Some(*hit);
    v.connectible = !bsdf.is_delta();
    v.bsdf = Some(bsdf);
    v.beta = beta;
    v.pdf_fwd = convert(pdf_dir, prev, &v);
    path.push(v);
}

/// f·|n_s·ω_light| of surface vertex `v` between its neighbour on the camera side
/// (`towards_camera`) and on the light side (`towards_light`), directions from `v`.
#[inline]
fn eval(scene: &Scene, v: &Vertex, towards_camera: Vec3, towards_light: Vec3) -> Spectrum {
    if let Some(phase) = v.phase {
        return Spectrum::splat(phase.eval(towards_camera, towards_light));
    }
    match facing(scene, v, towards_camera) {
        Some((b, frame)) => b.eval(frame.to_local(towards_camera), frame.to_local(towards_light)),
        None => Spectrum::ZERO,
    }
}

/// A strategy's MIS weight `w` for a full path x, and `pt`'s factor `pt` = Σⱼ wⱼ²/rⱼ over
/// `pt`'s two strategies j (the camera finds the light, k = 0; next-event estimation, k = 1)
/// with rⱼ = pⱼ(x)/p_own(x) and wⱼ their power-heuristic weights between themselves:
/// (r₀³ + r₁³)/(r₀² + r₁²)². A contribution C = w·f/p_own then adds C²·pt/w to an unbiased
/// estimate of `pt`'s second moment ∫ f² Σⱼ wⱼ²/pⱼ (docs/bidirectional.md, "Predicting
/// pt's noise"); infinite where neither of `pt`'s strategies makes x.
#[derive(Clone, Copy, Debug)]
struct Weight {
    w: f32,
    pt: f64,
}

impl Weight {
    /// A weight for a path that `pt` makes with the same strategy and weight: C²·pt/w = C².
    fn own(w: f32) -> Weight {
        Weight { w, pt: w as f64 }
    }
}

/// `pt`'s per-pixel moments a bidirectional sample estimates (`Context::predict_pt`): the
/// second moment of `pt`'s estimator (Σ C²·pt/w) and the light `pt` cannot make at all.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PtMoments {
    pub second: Spectrum,
    pub unsampled: Spectrum,
}

impl PtMoments {
    /// Notes the contribution `c` made with weight `wt`. A second moment beyond `MAX_SECOND`
    /// (or a factor that is not finite) is light `pt` all but never makes: unsampled.
    #[inline]
    fn add(&mut self, c: Spectrum, wt: Weight) {
        const MAX_SECOND: f64 = 1e30;
        if !(wt.w > 0.0) {
            return;
        }
        let factor = wt.pt / wt.w as f64;
        let cc = c.as_dvec3() * c.as_dvec3() * factor;
        if factor.is_finite() && cc.max_element() <= MAX_SECOND {
            self.second += cc.as_vec3();
        } else {
            self.unsampled += c;
        }
    }
}

/// A full path laid out as s light vertices then t camera vertices (in reverse). Each side
/// is a chain of a subpath: the vertices it scattered at before its end (`*_reals`, in
/// order), then the end vertex (`*_end`, which may be a branch). `ls`/`cs` replace the light
/// endpoint or the camera. The path was made by strategy `k`: k = s (a join of the two
/// subpaths), or k = 0 with s = 1 (the camera subpath found the light `ls`).
struct FullPath<'a> {
    light: &'a [Vertex],
    light_reals: &'a [u32],
    light_end: usize,
    camera: &'a [Vertex],
    camera_reals: &'a [u32],
    camera_end: usize,
    s: usize,
    t: usize,
    k: usize,
    ls: Option<&'a Vertex>,
    cs: Option<&'a Vertex>,
}

impl<'a> FullPath<'a> {
    /// The camera chain ending at `camera[camera_end]` (t vertices), then the light point
    /// `light`: found by the camera walk (k = 0) or by a light sample (k = 1).
    fn to_light(
        camera: &'a [Vertex],
        reals: &'a [u32],
        camera_end: usize,
        t: usize,
        light: &'a Vertex,
        k: usize,
    ) -> Self {
        FullPath {
            light: &[],
            light_reals: &[],
            light_end: 0,
            camera,
            camera_reals: reals,
            camera_end,
            s: 1,
            t,
            k,
            ls: Some(light),
            cs: None,
        }
    }

    /// The light chain ending at `light[light_end]` (s vertices) joined to the camera chain
    /// ending at `camera[camera_end]` (t vertices), or to the lens point `lens` (t = 1).
    #[allow(clippy::too_many_arguments)]
    fn joined(
        light: &'a [Vertex],
        light_reals: &'a [u32],
        light_end: usize,
        s: usize,
        camera: &'a [Vertex],
        camera_reals: &'a [u32],
        camera_end: usize,
        t: usize,
        lens: Option<&'a Vertex>,
    ) -> Self {
        FullPath { light, light_reals, light_end, camera, camera_reals, camera_end, s, t, k: s, ls: None, cs: lens }
    }

    #[inline]
    fn n(&self) -> usize {
        self.s + self.t
    }
    #[inline]
    fn at(&self, i: usize) -> &'a Vertex {
        if i < self.s {
            if i == 0 {
                if let Some(v) = self.ls {
                    return v;
                }
            }
            let idx = if i + 1 == self.s { self.light_end } else { self.light_reals[i] as usize };
            &self.light[idx]
        } else {
            let j = self.n() - 1 - i;
            if j == 0 {
                if let Some(v) = self.cs {
                    return v;
                }
            }
            let idx = if j + 1 == self.t { self.camera_end } else { self.camera_reals[j] as usize };
            &self.camera[idx]
        }
    }
}

impl Context<'_> {
    /// The power-heuristic weight of strategy (s, t) for the full path `fp` whose light
    /// point next-event estimation reaches with density `pdf_nee` (the light's measure), and
    /// `pt`'s factor of it (`Weight::pt`).
    #[allow(clippy::needless_range_loop)]
    fn mis_weight(&self, fp: &FullPath, pdf_nee: f32, scratch_l: &mut Vec<f64>, scratch_c: &mut Vec<f64>) -> Weight {
        let (s, n, own_k) = (fp.s, fp.n(), fp.k);
        if let Some(k) = self.only {
            let chosen = if n == 2 { 0 } else { k.min(n - 1) };
            return Weight::own(if own_k == chosen { 1.0 } else { 0.0 });
        }
        if n == 2 {
            return Weight::own(1.0);
        }
        let v = |i: usize| fp.at(i);
        // a surface vertex left by a delta lobe: the densities it makes are Dirac (both
        // directions); the strategies that include one include exactly one of them, so 1.
        // The joined vertices' own walks left them towards vertices not on this path.
        let is_conn = |i: usize| own_k > 0 && (i + 1 == own_k || i == own_k);
        let delta = |i: usize| v(i).is_surface() && v(i).delta && !is_conn(i);
        scratch_l.clear();
        scratch_c.clear();
        scratch_l.resize(n, 0.0);
        scratch_c.resize(n, 0.0);
        let (fl, fc) = (scratch_l, scratch_c);
        // light-side densities
        for i in 0..n {
            fl[i] = if i == 0 {
                v(0).pdf_fwd
            } else if i < s {
                v(i).pdf_fwd
            } else if i == s {
                self.pdf(v(i - 1), (i >= 2).then(|| v(i - 2)), v(i))
            } else if i == s + 1 && s >= 1 {
                self.pdf(v(s), Some(v(s - 1)), v(i))
            } else {
                v(i).pdf_rev
            } as f64;
            if i >= 1 && delta(i - 1) {
                fl[i] = 1.0;
            }
        }
        // camera-side densities
        for i in 0..n {
            fc[i] = if i == n - 1 {
                1.0
            } else if i >= s {
                v(i).pdf_fwd
            } else if i + 1 == s {
                self.pdf(v(s), (s + 1 < n).then(|| v(s + 1)), v(i))
            } else if i + 2 == s {
                self.pdf(v(s - 1), Some(v(s)), v(i))
            } else {
                v(i).pdf_rev
            } as f64;
            if i + 1 < n && delta(i + 1) {
                fc[i] = 1.0;
            }
        }
        let connectible = |i: usize| v(i).connectible && !delta(i);
        let light_hittable = !v(0).delta && v(0).light != u32::MAX;
        // a soft-falloff sphere light seen from a medium is the disk facing that point, which
        // only the camera side makes (`light::FacingDisk`): no light subpath starts there
        let disk_path = v(1).kind == Kind::Medium && self.scene.sees_facing_disk(v(0).light);
        // a walk beneath a surface (exit j, entry j + 1) only the camera side makes: the
        // strategies whose light subpath reaches past the exit are not made
        let walk = (0..n).find(|&i| v(i).walk_exit);
        let valid = |k: usize| {
            if walk.is_some_and(|j| k > j) {
                false
            } else if k == 0 {
                light_hittable
            } else if k == 1 && !self.cfg.nee || k >= 2 && disk_path {
                false
            } else {
                connectible(k - 1) && connectible(k) && !(k == 1 && n - k == 1)
            }
        };
        let p = |k: usize| -> f64 {
            let mut x = 1.0f64;
            for (i, f) in fl.iter().enumerate().take(k) {
                x *= if i == 0 && k == 1 { pdf_nee as f64 } else { *f };
            }
            for f in &fc[k..n - 1] {
                x *= *f;
            }
            x
        };
        let own = p(own_k);
        if !(own > 0.0) || !own.is_finite() || own_k >= 2 && disk_path || walk.is_some_and(|j| own_k > j) {
            return Weight::own(0.0);
        }
        let (mut sum, mut r_pt) = (0.0f64, [0.0f64; 2]);
        for k in 0..n {
            if k == own_k || valid(k) {
                let r = p(k) / own;
                if r.is_finite() {
                    sum += r * r;
                    if k < 2 {
                        r_pt[k] = r;
                    }
                }
            }
        }
        // (r₀³ + r₁³)/(r₀² + r₁²)² with both ratios scaled by the larger, so that neither
        // underflows: (a³ + b³)/((a² + b²)²·m)
        let m = r_pt[0].max(r_pt[1]);
        let (a, b) = (r_pt[0] / m, r_pt[1] / m);
        let pt = if m > 0.0 { (a * a * a + b * b * b) / ((a * a + b * b).powi(2) * m) } else { f64::INFINITY };
        Weight { w: (1.0 / sum) as f32, pt }
    }

    /// The per-kind bounce limits hold for the full path (labels of z₂ … z_{n−2}; the
    /// joined vertices' labels `label_l`, `label_c` drawn at the join).
    fn kinds_allowed(&self, fp: &FullPath, label_l: u8, label_c: u8) -> bool {
        let (k, n) = (fp.k, fp.n());
        let mut count = [0u32; 4];
        for i in 2..n.saturating_sub(1) {
            let l = if k >= 1 && i == k - 1 {
                label_l
            } else if k >= 1 && i == k {
                label_c
            } else {
                fp.at(i).label
            };
            if (l as usize) < 4 {
                count[l as usize] += 1;
            }
        }
        count[0] <= self.cfg.diffuse_bounces
            && count[1] <= self.cfg.glossy_bounces
            && count[2] <= self.cfg.transmission_bounces
            && count[3] <= self.cfg.volume_bounces
    }
}

/// A number in [0, 1) for the label of the join of light vertex `jl` and camera vertex `jc`.
#[inline]
fn label_u(seed: u64, jl: usize, jc: usize) -> f32 {
    crate::sampler::u32_to_unit_f32((crate::sampler::mix64(seed ^ ((jl as u64) << 16 | jc as u64)) >> 32) as u32)
}

/// The scattering label of a joined vertex `v` between `wo` (camera side) and `wi` (light
/// side): transmission across the surface, else diffuse with the probability BSDF sampling
/// gives the pair that label (`Bsdf::diffuse_share`).
fn join_label(scene: &Scene, v: &Vertex, wo: Vec3, wi: Vec3, u: f32) -> u8 {
    if v.kind == Kind::Medium {
        return VOLUME_LABEL;
    }
    if v.walk_exit {
        return 0; // (a walk's exit scatters diffusely, as Cycles counts it)
    }
    let Some((b, frame)) = facing(scene, v, wo) else { return NO_LABEL };
    let (lo, li) = (frame.to_local(wo), frame.to_local(wi));
    if lo.z * li.z < 0.0 {
        return 2;
    }
    let share = b.diffuse_share(lo, li, b.pdf(lo, li));
    if u < share {
        0
    } else {
        1
    }
}

/// A splat target of light tracing: the film's running sums, added to from every thread.
struct Splats {
    data: Vec<AtomicU32>,
    width: usize,
    height: usize,
}

impl Splats {
    fn new(width: usize, height: usize) -> Splats {
        Splats { data: (0..width * height * 3).map(|_| AtomicU32::new(0)).collect(), width, height }
    }

    fn add(&self, x: usize, y: usize, c: Spectrum) {
        let i = 3 * (y * self.width + x);
        for (k, v) in [c.x, c.y, c.z].into_iter().enumerate() {
            let a = &self.data[i + k];
            let mut cur = a.load(Ordering::Relaxed);
            loop {
                let next = (f32::from_bits(cur) + v).to_bits();
                match a.compare_exchange_weak(cur, next, Ordering::Relaxed, Ordering::Relaxed) {
                    Ok(_) => break,
                    Err(x) => cur = x,
                }
            }
        }
    }
}

/// The random numbers of one bidirectional sample: the camera subpath's stream and the light
/// subpath's, or one stream for both (a Metropolis state, `light` None).
pub(crate) struct Streams<'a> {
    pub cam: &'a mut dyn Sampler,
    pub light: Option<&'a mut dyn Sampler>,
}

impl Streams<'_> {
    #[inline]
    fn cam(&mut self) -> &mut dyn Sampler {
        &mut *self.cam
    }
    #[inline]
    fn light(&mut self) -> &mut dyn Sampler {
        match &mut self.light {
            Some(l) => &mut **l,
            None => &mut *self.cam,
        }
    }
}

/// One sample of pixel (x, y) with `pt`'s sample streams (camera and light apart); light
/// tracing's share goes to `splats`.
#[allow(clippy::too_many_arguments)]
fn sample_pixel(
    ctx: &Context,
    settings: &RenderSettings,
    splats: &Splats,
    scratch: &mut Scratch,
    x: usize,
    y: usize,
    index: u32,
) -> CameraResult {
    let w = ctx.scene.camera.width as usize;
    let pixel = y * w + x;
    let mut cs = SobolSampler::for_subpaths(settings.seed, pixel as u64, index);
    let mut ls = SobolSampler::for_subpaths(settings.seed ^ 0x9e37_79b9_7f4a_7c15, pixel as u64, index);
    let u_pixel = cs.next_2d();
    let mut streams = Streams { cam: &mut cs, light: Some(&mut ls) };
    let (sw, sh) = (splats.width, splats.height);
    let out = sample(ctx, scratch, &mut streams, x, y, u_pixel, |px, py, v| {
        if px < sw && py < sh {
            splats.add(px, py, v)
        }
    });
    CameraResult { out }
}

/// One bidirectional sample through pixel (x, y) at the filter sample `u_pixel`: both
/// subpaths and every strategy. Returns what the pixel's camera path gives it; light tracing's
/// contributions go to `splat(x, y, value)` — per light path, to be divided by the number of
/// light paths traced (the image's pixels × samples per pixel).
pub(crate) fn sample(
    ctx: &Context,
    scratch: &mut Scratch,
    streams: &mut Streams,
    x: usize,
    y: usize,
    u_pixel: Vec2,
    mut splat: impl FnMut(usize, usize, Spectrum),
) -> PathContribution {
    let scene = ctx.scene;
    let cfg = ctx.cfg;
    let mut res = CameraResult::default();
    // the joins' scattering labels (per-kind bounce limits) draw from a hash of the sample's
    // first numbers: a function of the sample (as a Markov state needs), without a primary
    // dimension per join (one each made the Sobol sampler 11% of the time)
    let label_seed = u64::from(u_pixel.x.to_bits()) << 32 | u64::from(u_pixel.y.to_bits());

    // 1. the camera subpath
    let raster = scene.camera.pixel_raster(x as f32, y as f32, u_pixel);
    let lens = streams.cam().next_2d();
    let ray = scene.camera.generate_ray(raster, lens);
    scratch.camera.clear();
    scratch.events.clear();
    scratch.moments = PtMoments::default();
    scratch.moment_splats.clear();
    let mut c0 = camera_vertex(scene, ray.origin);
    c0.pixel = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
    scratch.camera.push(c0);
    // the camera's density of its ray (relative to light tracing's; the pixel filter over
    // every place a panorama sees that way), or 1 where no light path reaches the camera (a
    // common factor of every strategy then)
    let mut pdf_cam = scene.camera.filter_weight(raster, c0.pixel) * scene.camera.ray_density(ray.dir) / ctx.pixels;
    if !(pdf_cam > 0.0) {
        // no light path reaches the camera here (another projection, or a ray it cannot
        // place back): the camera's density is then a common factor of every strategy
        pdf_cam = 1.0;
        scratch.camera[0].connectible = false;
    }
    // (a camera ray outside a fisheye's circle sees nothing, but the light subpath is still
    // traced: light tracing's splats are averaged over every pixel sample)
    if !ray.is_dead() {
        let Scratch { camera, events, .. } = scratch;
        random_walk(
            ctx,
            streams.cam(),
            camera,
            ray.origin,
            ray.dir,
            ray.tmin,
            ray.tmax,
            Spectrum::ONE,
            pdf_cam,
            true,
            Some(events),
            &mut res.out,
            scene.camera_media(),
        );
        let mut walks = 0u8;
        for v in camera.iter_mut() {
            walks = walks.saturating_add(v.walk_exit as u8);
            v.walks = walks;
        }
    }
    // 2. the light subpath
    scratch.light.clear();
    let u_sel = streams.light().next_1d();
    let (u_pos, u_dir) = (streams.light().next_2d(), streams.light().next_2d());
    let origin = scene.sample_light_origin(&ctx.emitters, u_sel, u_pos, u_dir);
    // (from infinitely far through an extinguishing world medium, no light arrives)
    if let Some(o) = origin.filter(|o| !(o.infinite && scene.world_medium_extinguishes())) {
        let mut l0 = Vertex::endpoint(Kind::Light, o.p);
        l0.light = o.light;
        l0.ng = o.n;
        l0.infinite = o.infinite;
        l0.dir = if o.infinite { -o.dir } else { Vec3::ZERO };
        l0.delta = o.delta;
        l0.pdf_fwd = o.pdf_origin;
        scratch.light.push(l0);
        let start =
            if o.n != Vec3::ZERO { o.p + o.n * (crate::math::ray_epsilon(o.p) * o.n.dot(o.dir).signum()) } else { o.p };
        let beta = Spectrum::splat(1.0 / (o.pdf_origin * o.pdf_emit));
        let mut unused = PathContribution::default();
        random_walk(
            ctx,
            streams.light(),
            &mut scratch.light,
            start,
            o.dir,
            0.0,
            f32::INFINITY,
            beta,
            o.pdf_emit,
            false,
            None,
            &mut unused,
            scene.light_media(o.light),
        );
    }

    // 3. every strategy, over the chains that end at each vertex
    let Scratch { camera, light, events, fwd_l, fwd_c, camera_reals, light_reals, moments, moment_splats } = scratch;
    let predict = ctx.predict_pt;
    let (camera, light) = (&camera[..], &light[..]);
    camera_reals.clear();
    camera_reals.extend((0..camera.len() as u32).filter(|&i| !camera[i as usize].branch));
    light_reals.clear();
    light_reals.extend((0..light.len() as u32).filter(|&i| !light[i as usize].branch));
    // the chain ending at vertex `end`: the real vertices before it, then it
    let chain = |reals: &[u32], end: usize| reals.partition_point(|&r| (r as usize) < end) + 1;
    let max_n = cfg.max_bounces as usize + 3;
    let (cr, lr) = (&camera_reals[..], &light_reals[..]);

    // s = 0: light the camera subpath found (after the real vertices before `t`)
    for e in events.iter() {
        let t = cr.partition_point(|&r| (r as usize) < e.t);
        if e.alone || (t == 1 && ctx.only.is_none()) {
            res.out.radiance += e.value;
            if predict {
                moments.add(e.value, Weight::own(1.0));
            }
            if t == 1 {
                res.out.very_direct += e.value;
            }
            continue;
        }
        let fp = FullPath::to_light(camera, cr, cr[t - 1] as usize, t, &e.light, 0);
        if ctx.kind_limits && !ctx.kinds_allowed(&fp, NO_LABEL, NO_LABEL) {
            continue;
        }
        let wgt = ctx.mis_weight(&fp, e.pdf_nee, fwd_l, fwd_c);
        res.out.radiance += e.value * wgt.w;
        if predict {
            moments.add(e.value * wgt.w, wgt);
        }
    }

    // s = 1: next-event estimation at each camera vertex
    if cfg.nee && scene.has_lights() {
        for jc in 1..camera.len() {
            let b = &camera[jc];
            let t = chain(cr, jc);
            if t + 1 > max_n + b.walks as usize || !b.connectible {
                continue;
            }
            let (u_sel, u_l) = (streams.cam().next_1d(), streams.cam().next_2d());
            let u_label = label_u(label_seed, 0, jc);
            if b.kind == Kind::Medium {
                // a light sample from a point in a medium, through the media on its way
                nee_in_medium(ctx, b, &camera[cr[t - 2] as usize], (u_sel, u_l), |lv, value, pdf_nee| {
                    let fp = FullPath::to_light(camera, cr, jc, t, lv, 1);
                    if ctx.kind_limits && !ctx.kinds_allowed(&fp, NO_LABEL, VOLUME_LABEL) {
                        return;
                    }
                    let wgt = ctx.mis_weight(&fp, pdf_nee, fwd_l, fwd_c);
                    res.out.radiance += value * wgt.w;
                    if predict {
                        moments.add(value * wgt.w, wgt);
                    }
                });
                continue;
            }
            let (Some(si), Some(bsdf)) = (b.si.as_ref(), b.bsdf.as_ref()) else { continue };
            let Some((li, lsmp)) = scene.sample_light(b.p, u_sel, u_l) else { continue };
            if !scene.lights_receiver(li, si.prim) {
                continue; // (light linking)
            }
            let wo = direction(b, &camera[cr[t - 2] as usize]).0;
            let (lo, li_local) = (si.frame.to_local(wo), si.frame.to_local(lsmp.wi));
            let f = bsdf.eval(lo, li_local);
            // What Cycles' light samples add through rough glass on pairs no microfacet
            // connects (`Bsdf::eval_light_sample`): only this strategy reaches them, so it
            // adds them unweighted, as pt does (off with `strict_glass_nee`).
            let extra = if cfg.strict_glass_nee {
                Spectrum::ZERO
            } else {
                (bsdf.eval_light_sample(lo, li_local, true, (!lsmp.is_delta).then_some(lsmp.pdf)).0 - f)
                    .max(Spectrum::ZERO)
            };
            if !(f.max_element() > 0.0) && !(extra.max_element() > 0.0) {
                continue;
            }
            let media = scene.media_towards(b.media, si, lsmp.wi);
            let Some(tr) = shadow_transmittance(scene, si, li, &lsmp, media) else { continue };
            let lv = light_sample_vertex(ctx, li, &lsmp);
            let fp = FullPath::to_light(camera, cr, jc, t, &lv, 1);
            let label = if ctx.kind_limits { join_label(scene, b, wo, lsmp.wi, u_label) } else { NO_LABEL };
            if ctx.kind_limits && !ctx.kinds_allowed(&fp, NO_LABEL, label) {
                continue;
            }
            let pdf_nee = ctx.nee_pdf_of(&lv, lsmp.pdf, b.p);
            let wgt = if !(f.max_element() > 0.0) {
                Weight::own(0.0)
            } else if scene.casts_shadow(li)
                && scene.has_shadow_invisible()
                && scene.segment_transmittance(si, lsmp.p, false).is_none()
            {
                // the light came through an object that casts no shadow: only a light sample
                // reaches it (every other ray stops there), weighed as pt and Cycles weigh it
                // against the BSDF's sample, which cannot
                Weight::own(if lsmp.is_delta { 1.0 } else { power_heuristic(lsmp.pdf, bsdf.pdf(lo, li_local)) })
            } else {
                ctx.mis_weight(&fp, pdf_nee, fwd_l, fwd_c)
            };
            let unit = b.beta * lsmp.radiance * tr / lsmp.pdf;
            res.out.radiance += unit * (f * wgt.w + extra);
            if predict {
                moments.add(unit * f * wgt.w, wgt);
                moments.add(unit * extra, Weight::own(1.0));
            }
        }
    }

    // s ≥ 2: each light vertex, joined to the lens (t = 1) and to each camera vertex
    for jl in 1..light.len() {
        let a = &light[jl];
        let s = chain(lr, jl);
        if !a.connectible || s < 2 {
            continue;
        }
        let a_prev = &light[lr[s - 2] as usize];
        let w_prev = direction(a, a_prev).0;
        // (a point in a medium: no surface, no cosines)
        let in_medium = a.kind == Kind::Medium;
        let point = Scene::medium_point(a.p, w_prev);
        let asi = if in_medium {
            &point
        } else if let Some(si) = a.si.as_ref() {
            si
        } else {
            continue;
        };
        let cos_prev = if in_medium { 1.0 } else { a.ng.dot(w_prev).abs() };
        if !(cos_prev > 0.0) {
            continue;
        }
        // the adjoint's geometric cosines of a towards `w` over towards its predecessor
        let cos_ratio = |w: Vec3| if in_medium { 1.0 } else { a.ng.dot(w).abs() / cos_prev };
        // the media a ray from a towards `w` starts in
        let media_a = |w: Vec3| if in_medium { a.media } else { scene.media_towards(a.media, asi, w) };
        // (z₁ of this chain: a itself, or the first vertex the walk scattered at)
        let origin_nee = if s == 2 { a.origin_nee } else { light[lr[1] as usize].origin_nee };

        // t = 1, light tracing: join a to a lens point, splat where it lands
        let u_lens = streams.light().next_2d();
        let u_label = label_u(label_seed, jl, 0);
        // (a holdout where the camera sees it sends it nothing)
        if s < max_n && (in_medium || !scene.camera_invisible(asi.prim) && !scene.is_holdout(asi.prim)) {
            let lens_p = scene.camera.lens_point(u_lens, a.p);
            if let Some((raster, we)) = scene.camera.importance(lens_p, a.p) {
                let mut cam = camera_vertex(scene, lens_p);
                let (wc, d2) = direction(a, &cam);
                let fa = eval(scene, a, wc, w_prev) * cos_ratio(wc);
                // (a camera ray: objects hidden from the camera let it pass)
                let tr = if fa.max_element() > 0.0 {
                    scene.segment_transmittance_in(asi, lens_p, true, media_a(wc))
                } else {
                    None
                };
                if let Some(tr) = tr {
                    let value = a.beta * fa * tr * (we / d2);
                    let label = if ctx.kind_limits { join_label(scene, a, wc, w_prev, u_label) } else { NO_LABEL };
                    // (a panorama sees a at more than one place near its edges: a splat at each)
                    for (px, py, fw) in scene.camera.footprint(raster).filter(|_| is_finite_spectrum(value)) {
                        cam.pixel = Vec2::new(px as f32 + 0.5, py as f32 + 0.5);
                        let fp = FullPath::joined(light, lr, jl, s, &[], &[], 0, 1, Some(&cam));
                        if ctx.kind_limits && !ctx.kinds_allowed(&fp, label, NO_LABEL) {
                            continue;
                        }
                        let wgt = ctx.mis_weight(&fp, origin_nee, fwd_l, fwd_c);
                        let c = value * (fw * wgt.w);
                        splat(px as usize, py as usize, c);
                        if predict {
                            let mut m = PtMoments::default();
                            m.add(c, wgt);
                            moment_splats.push((px, py, m));
                        }
                    }
                }
            }
        }

        // t ≥ 2: a shadow ray joins a and b
        for jc in 1..camera.len() {
            let b = &camera[jc];
            let t = chain(cr, jc);
            let u_label = label_u(label_seed, jl, jc);
            if s + t > max_n + b.walks as usize || !b.connectible {
                continue;
            }
            let (w, d2) = direction(a, b);
            let point_b = Scene::medium_point(b.p, -w);
            let bsi = if b.kind == Kind::Medium {
                &point_b
            } else if let Some(si) = b.si.as_ref() {
                si
            } else {
                continue;
            };
            let fa = eval(scene, a, w, w_prev) * cos_ratio(w);
            if !(fa.max_element() > 0.0) {
                continue;
            }
            let wo_b = direction(b, &camera[cr[t - 2] as usize]).0;
            let fb = eval(scene, b, wo_b, -w);
            if !(fb.max_element() > 0.0) {
                continue;
            }
            // (a ray between surfaces: what casts no shadow still blocks it, as in Cycles,
            // where only shadow rays to lights pass such objects)
            let media_b = if b.kind == Kind::Medium { b.media } else { scene.media_towards(b.media, bsi, -w) };
            let Some(tr) = scene.segment_transmittance_in(bsi, a.p, false, media_b) else { continue };
            let fp = FullPath::joined(light, lr, jl, s, camera, cr, jc, t, None);
            if ctx.kind_limits {
                let (ll, lc) = (join_label(scene, a, w, w_prev, u_label), join_label(scene, b, wo_b, -w, u_label));
                if !ctx.kinds_allowed(&fp, ll, lc) {
                    continue;
                }
            }
            let wgt = ctx.mis_weight(&fp, origin_nee, fwd_l, fwd_c);
            let c = a.beta * fa * fb * b.beta * tr * (wgt.w / d2);
            res.out.radiance += c;
            if predict {
                moments.add(c, wgt);
            }
        }
    }
    res.out
}

pub fn render(scene: &Scene, settings: &RenderSettings, control: &RenderControl) -> RenderOutput {
    let only = std::env::var("GDMLT_BDPT_ONLY").ok().and_then(|v| v.parse().ok());
    render_with(scene, settings, control, only)
}

/// `render`, with the diagnostic `only` (`Context::only`).
fn render_with(scene: &Scene, settings: &RenderSettings, control: &RenderControl, only: Option<usize>) -> RenderOutput {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let cfg = &settings.path;
    let mut ctx = Context::new(scene, cfg, only);
    // (not under the diagnostic `only`, whose weights are not the strategies' own)
    ctx.predict_pt = settings.predict_pt && only.is_none();
    let mut film = Film::new(w, h);
    let splats = Splats::new(w, h);
    // pt's moments (predict_pt): second moment and unsampled light, from the camera samples
    // (over each pixel's samples) and from light tracing (over the light paths)
    let sized = |on: bool| if on { Splats::new(w, h) } else { Splats::new(0, 0) };
    let moments = [0; 4].map(|_| sized(settings.predict_pt));
    control.work_total.store(w as u64 * h as u64 * settings.spp as u64, Ordering::Relaxed);
    let mut done = 0u32;
    let mut batch = 1u32;
    while done < settings.spp && !control.should_stop() {
        let to = (done + batch).min(settings.spp);
        let t0 = std::time::Instant::now();
        film.rows.par_iter_mut().enumerate().for_each_init(Scratch::default, |scratch, (y, row)| {
            if control.should_stop() {
                return;
            }
            for x in 0..w {
                for index in done..to {
                    let r = sample_pixel(&ctx, settings, &splats, scratch, x, y, index);
                    row.add(x, &r.out);
                    if ctx.predict_pt {
                        moments[0].add(x, y, scratch.moments.second);
                        moments[1].add(x, y, scratch.moments.unsampled);
                        for &(px, py, m) in &scratch.moment_splats {
                            moments[2].add(px as usize, py as usize, m.second);
                            moments[3].add(px as usize, py as usize, m.unsampled);
                        }
                    }
                }
            }
            control.work_done.fetch_add(w as u64 * (to - done) as u64, Ordering::Relaxed);
        });
        done = to;
        control.offer_preview(|| combined(&film, &splats));
        if t0.elapsed().as_secs_f64() < 0.1 {
            batch = (batch * 2).min(64);
        }
    }
    let (spp_min, spp_max) = film.sample_count_range();
    let mut layers = vec![
        ("Combined".into(), combined(&film, &splats)),
        ("Denoising Albedo".into(), film.albedo()),
        ("Denoising Normal".into(), film.normal()),
    ];
    if scene.has_alpha() {
        layers.push(("Alpha".into(), film.alpha()));
    }
    if settings.predict_pt {
        let n = film.total_samples().max(1) as f64;
        let [second, unsampled] = [0, 1].map(|i| {
            let mut img = Image::new(w, h, 3);
            for (y, row) in film.rows.iter().enumerate() {
                for (x, &count) in row.count.iter().enumerate() {
                    for c in 0..3 {
                        let j = (y * w + x) * 3 + c;
                        let cam = f32::from_bits(moments[i].data[j].load(Ordering::Relaxed)) as f64;
                        let lt = f32::from_bits(moments[i + 2].data[j].load(Ordering::Relaxed)) as f64;
                        // (light paths: N = the samples taken; the second moment's splats
                        // estimate ∫ over the whole image's measure, 1/pixels of a pixel's)
                        let lt = if i == 0 { lt / (n * ctx.pixels as f64) } else { lt / n };
                        img.data[j] = (cam / count.max(1) as f64 + lt) as f32;
                    }
                }
            }
            img
        });
        layers.push(("PT Second Moment".into(), second));
        layers.push(("PT Unsampled".into(), unsampled));
    }
    RenderOutput {
        layers,
        stats: RenderStats {
            method: "bdpt",
            elapsed: control.elapsed(),
            spp_min,
            spp_max,
            invalid_samples: film.invalid_samples(),
            ..Default::default()
        },
    }
}

/// The image: each pixel's camera samples averaged, plus light tracing's splats over the
/// light paths traced (one per camera sample: a pass a time limit cut short counts the
/// samples it took).
fn combined(film: &Film, splats: &Splats) -> Image {
    let mut img = film.color();
    let n = film.total_samples().max(1) as f64;
    for (c, s) in img.data.iter_mut().zip(&splats.data) {
        *c += (f32::from_bits(s.load(Ordering::Relaxed)) as f64 / n) as f32;
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::Method;
    use crate::scene::builtin;
    use crate::scene::Projection;

    /// Per-channel means of the four quadrants (or of every pixel, `per_pixel`) over
    /// `seeds` renders: mean and standard error of the mean.
    fn means(
        scene: &Scene,
        settings: &RenderSettings,
        seeds: u64,
        only: Option<usize>,
        per_pixel: bool,
    ) -> (Vec<f64>, Vec<f64>) {
        let mut all: Vec<Vec<f64>> = Vec::new();
        for seed in 0..seeds {
            let st = RenderSettings { seed: seed + 1, ..settings.clone() };
            let out = if settings.method == Method::Bdpt {
                render_with(scene, &st, &RenderControl::new(0.0), only)
            } else {
                crate::integrator::render(scene, &st, &RenderControl::new(0.0)).unwrap()
            };
            let img = out.layer("Combined").unwrap();
            let (w, h) = (img.width, img.height);
            let cells = if per_pixel { w * h } else { 4 };
            let mut m = vec![0.0f64; 3 * cells];
            for y in 0..h {
                for x in 0..w {
                    let (q, k) = if per_pixel { (y * w + x, 1.0) } else { ((x * 2 / w) + 2 * (y * 2 / h), 4.0) };
                    for c in 0..3 {
                        let v = img.data[3 * (y * w + x) + c] as f64;
                        m[3 * q + c] += if per_pixel { v } else { v * k / (w * h) as f64 };
                    }
                }
            }
            all.push(m);
        }
        let n = seeds as f64;
        let len = all[0].len();
        let mean: Vec<f64> = (0..len).map(|i| all.iter().map(|m| m[i]).sum::<f64>() / n).collect();
        let se = (0..len)
            .map(|i| (all.iter().map(|m| (m[i] - mean[i]).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt())
            .collect();
        (mean, se)
    }

    /// The largest |difference| / its standard error between `pt` and `bdpt` (with `only`).
    #[allow(clippy::too_many_arguments)]
    fn worst_z(
        desc: &crate::scene::SceneDesc,
        path: PathSettings,
        spp_pt: u32,
        spp_bd: u32,
        seeds: u64,
        only: Option<usize>,
        per_pixel: bool,
    ) -> (f64, String) {
        let scene = Scene::build(desc).unwrap();
        let base = RenderSettings { path, threads: 2, ..Default::default() };
        let (mp, sp) =
            means(&scene, &RenderSettings { method: Method::Pt, spp: spp_pt, ..base.clone() }, seeds, None, per_pixel);
        let (mb, sb) =
            means(&scene, &RenderSettings { method: Method::Bdpt, spp: spp_bd, ..base }, seeds, only, per_pixel);
        let mut worst = (0.0f64, String::new());
        for i in 0..mp.len() {
            // (a floor for cells both renderers find black or nearly constant)
            let se = (sp[i].powi(2) + sb[i].powi(2)).sqrt().max(1e-4 * mp[i].abs()).max(1e-7);
            let z = (mb[i] - mp[i]).abs() / se;
            if z > worst.0 {
                worst = (
                    z,
                    format!(
                        "cell {} channel {}: pt {:.5} ± {:.5}, bdpt {:.5} ± {:.5}",
                        i / 3,
                        i % 3,
                        mp[i],
                        sp[i],
                        mb[i],
                        sb[i]
                    ),
                );
            }
        }
        worst
    }

    /// `bdpt` renders `pt`'s image: each quadrant's mean colour over 6 seeds within 4.5
    /// standard errors of the difference, on the Cornell box (diffuse), the spheres (mirror,
    /// smooth glass and plastic: caustics light tracing finds), the gap, the box lit by every
    /// light kind at once (emissive mesh, area, sphere, spot, sun with a disc, world), the
    /// veil (transparent surfaces: branch vertices) and the bulb (rough glass; `pt` with light
    /// samples evaluated by the BSDF itself, as bdpt's joins) and that bulb in smooth glass.
    /// Failed before the adjoint of delta refraction had its (η_prev/η_next)² (smooth bulb
    /// −40% against Cycles in the convergence suite), before the BSDFs were
    /// turned to the side a light subpath is seen from (veil +30%, bulb −50%) and before
    /// transparent surfaces kept a vertex for joins (veil: light sampled at a veil 5% short).
    /// The bulb with a filament inside smooth glass (every light path leaves the glass by a
    /// delta refraction).
    fn smooth_bulb() -> crate::scene::SceneDesc {
        let mut d = builtin::cornell_bulb(24, 24);
        d.materials.iter_mut().filter(|m| m.transmission > 0.5).for_each(|m| m.roughness = 0.0);
        d
    }

    fn ortho_box() -> crate::scene::SceneDesc {
        let mut d = builtin::cornell_box(24, 24);
        d.camera.projection = Projection::Orthographic;
        d.camera.ortho_scale = 2.4;
        d
    }

    #[test]
    fn bdpt_converges_to_pt() {
        let strict = PathSettings { strict_glass_nee: true, ..Default::default() };
        let cases = [
            ("cornell", builtin::cornell_box(24, 24), PathSettings::default()),
            ("spheres", builtin::cornell_spheres(24, 24), PathSettings::default()),
            ("gap", builtin::cornell_gap(24, 24), PathSettings::default()),
            ("lights", builtin::cornell_mixed_lights(24, 24), PathSettings::default()),
            ("veil", builtin::cornell_veil(24, 24), PathSettings::default()),
            ("bulb", builtin::cornell_bulb(24, 24), strict),
            ("bulb in smooth glass", smooth_bulb(), PathSettings::default()),
            ("cornell, orthographic", ortho_box(), PathSettings::default()),
            ("cornell, 2 bounces", builtin::cornell_box(24, 24), PathSettings::new(2, true)),
            ("lights, naive", builtin::cornell_mixed_lights(24, 24), PathSettings::new(8, false)),
        ];
        for (name, desc, path) in cases {
            let (z, at) = worst_z(&desc, path, 64, 32, 6, None, false);
            assert!(z < 4.5, "{name}: bdpt differs from pt by {z:.1}σ at {at}");
        }
    }

    /// `pssmlt` over bidirectional states (each a whole bdpt sample, light tracing's splats
    /// included) converges to `pt`: per quadrant over 6 seeds within 4.5σ, on the Cornell
    /// box, the spheres (caustics) and the veil.
    #[test]
    fn pssmlt_over_bidirectional_states_converges_to_pt() {
        for (name, desc) in [
            ("cornell", builtin::cornell_box(16, 16)),
            ("spheres", builtin::cornell_spheres(16, 16)),
            ("veil", builtin::cornell_veil(16, 16)),
        ] {
            let scene = Scene::build(&desc).unwrap();
            let base = RenderSettings { threads: 2, ..Default::default() };
            let (mp, sp) =
                means(&scene, &RenderSettings { method: Method::Pt, spp: 64, ..base.clone() }, 6, None, false);
            let mlt = RenderSettings { method: Method::Pssmlt, spp: 64, bidirectional: true, ..base };
            let (mm, sm) = means(&scene, &mlt, 6, None, false);
            for i in 0..mp.len() {
                let se = (sp[i].powi(2) + sm[i].powi(2)).sqrt().max(1e-4 * mp[i].abs()).max(1e-7);
                let z = (mm[i] - mp[i]).abs() / se;
                assert!(
                    z < 4.5,
                    "{name}: quadrant {} channel {}: pt {:.5} ± {:.5}, pssmlt {:.5} ± {:.5} ({z:.1}σ)",
                    i / 3,
                    i % 3,
                    mp[i],
                    sp[i],
                    mm[i],
                    sm[i]
                );
            }
        }
    }

    /// Through a medium (the Cornell box in haze, `builtin::cornell_fog`), every strategy
    /// alone, unweighted, renders `pt`'s image per quadrant, and so does bdpt with its MIS:
    /// vertices in the medium joined, sampled and weighed as surfaces are (phase function,
    /// no cosines, transmittance on every join and light sample, light subpaths through the
    /// haze from the light and light tracing out of it to the lens).
    #[test]
    fn every_strategy_alone_renders_pts_image_through_fog() {
        let desc = builtin::cornell_fog(16, 16);
        for k in [None, Some(0), Some(1), Some(2), Some(9)] {
            let spp = if k == Some(0) { 128 } else { 32 };
            let (z, at) = worst_z(&desc, PathSettings::new(4, true), 64, spp, 6, k, false);
            assert!(z < 4.5, "strategy {k:?} alone through the haze: {z:.1}σ at {at}");
        }
        // a soft-falloff lamp above a lower haze: fog sees it as the disk facing each point,
        // which only camera-side strategies make — also where its light subpath first
        // crossed the haze's boundary (before, light tracing and joins added those paths
        // again: the haze too bright)
        let mut lamp = builtin::cornell_fog(16, 16);
        let haze = lamp.meshes.len() - 1;
        lamp.meshes[haze] = builtin::closed_box("Haze", [-0.98, -1.6, -0.98], [0.98, 0.98, 0.2], 4);
        lamp.lights.push(crate::scene::LightDesc::Point {
            name: "Lamp".into(),
            position: [0.2, 0.1, 0.55],
            radius: 0.15,
            power: [40.0, 30.0, 20.0],
            soft_falloff: true,
            visible_camera: false,
            cast_shadow: true,
        });
        let (z, at) = worst_z(&lamp, PathSettings::new(4, true), 64, 32, 6, None, false);
        assert!(z < 4.5, "a soft lamp above the haze: {z:.1}σ at {at}");
        // a glowing haze under Blender's default Volume bounces (0): light it emits reaches
        // the camera after one scattering in it at most, as pt's paths end past the limit
        // (before, bdpt's camera walks gathered it further: the image too bright)
        let mut glow = builtin::cornell_fog(16, 16);
        glow.materials[4].volume.as_mut().unwrap().emission = [0.3, 0.2, 0.1];
        let cfg = PathSettings { volume_bounces: 0, ..PathSettings::new(4, true) };
        let (z, at) = worst_z(&glow, cfg, 64, 32, 6, None, false);
        assert!(z < 4.5, "a glowing haze, volume bounces 0: {z:.1}σ at {at}");
    }

    /// Every strategy alone, unweighted, renders `pt`'s image (`Context::only`): camera paths
    /// that hit the light (k = 0), next-event estimation (1), joins with one light vertex
    /// besides the light (2) and light tracing (every path from the light, joined to the
    /// lens) — per quadrant on the Cornell box and the veil, and pixel for pixel on a 10×8
    /// box seen through a thin lens with Cycles' Blackman–Harris filter (light tracing must
    /// land where camera rays look: the filter's density, the lens, the raster).
    #[test]
    fn every_strategy_alone_renders_pts_image() {
        for (name, desc) in [("cornell", builtin::cornell_box(16, 16)), ("veil", builtin::cornell_veil(16, 16))] {
            for k in [0, 1, 2, 9] {
                let spp = if k == 0 { 128 } else { 32 };
                let (z, at) = worst_z(&desc, PathSettings::default(), 64, spp, 6, Some(k), false);
                assert!(z < 4.5, "{name}, strategy {k} alone: {z:.1}σ at {at}");
            }
        }
        let mut lens = builtin::cornell_box(10, 8);
        lens.camera.pixel_filter = "BLACKMAN_HARRIS".into();
        lens.camera.filter_width = 1.5;
        lens.camera.fstop = 0.5;
        lens.camera.focus_distance = 2.0;
        let (z, at) = worst_z(&lens, PathSettings::new(3, true), 256, 256, 6, Some(9), true);
        // (80 pixels × 3 channels: the largest of 240 z-scores)
        assert!(z < 5.0, "light tracing through a lens and a filter: {z:.1}σ at {at}");
        // panoramas standing in the box: pixel for pixel the whole sphere (the filter's splats
        // across the seam and the poles); per quadrant an equisolid fisheye and an
        // equidistant one whose circle cuts the frame (every pixel sample traces its light
        // subpath, also where the camera's ray is outside the circle: before, the image was
        // 0.8×, the circle's share of the frame). Per pixel, a fisheye's light tracing is
        // heavy-tailed for 6 seeds (16 seeds: every pixel within 3.2σ, the image −0.16%);
        // where it lands is `light_tracings_importance_is_one_over_a_pixels_solid_angle`'s)
        for (name, projection, fov, lens, per_pixel) in [
            ("equirectangular", Projection::Equirectangular, 0.0, 8.0, true),
            ("fisheye equisolid", Projection::FisheyeEquisolid, 3.2, 12.0, false),
            ("fisheye equidistant", Projection::FisheyeEquidistant, 3.4, 8.0, false),
        ] {
            let mut pano = builtin::cornell_box(12, 8);
            pano.camera = crate::scene::CameraDesc {
                projection,
                fisheye_fov: fov,
                fisheye_lens: lens,
                pixel_filter: "BLACKMAN_HARRIS".into(),
                filter_width: 1.5,
                ..builtin::camera_looking_along_y([0.1, 0.3, -0.2], 35.0, 12, 8)
            };
            if projection == Projection::Equirectangular {
                // looking out of the box's open side: the seam behind, on the lit back wall
                pano.camera.to_world[0][0] = -1.0;
                pano.camera.to_world[1][2] = 1.0;
            }
            pano.camera.sensor_width = 24.0; // (the equisolid circle, 2f·sin(fov/4), holds the frame)
            let (z, at) = worst_z(&pano, PathSettings::new(3, true), 256, 256, 6, Some(9), per_pixel);
            assert!(z < 5.0, "light tracing into a {name} camera: {z:.1}σ at {at}");
        }
        // an orthographic camera, pixel for pixel: joined along its one direction, its
        // density per unit film area (no 1/d²); 12 seeds (with 6, a z-score has Student's
        // t-tail of 5 degrees of freedom: one of 240 beyond 5 by chance)
        let mut ortho = builtin::cornell_box(10, 8);
        ortho.camera.projection = Projection::Orthographic;
        ortho.camera.ortho_scale = 2.4;
        ortho.camera.pixel_filter = "BLACKMAN_HARRIS".into();
        ortho.camera.filter_width = 1.5;
        let (z, at) = worst_z(&ortho, PathSettings::new(3, true), 256, 256, 12, Some(9), true);
        assert!(z < 5.0, "light tracing into an orthographic camera: {z:.1}σ at {at}");
    }

    /// The grey Cornell box under a white light: every channel alike, so `pt`'s "Variance"
    /// layer (of each pixel's brightness) is each channel's.
    fn grey_box(n: u32) -> crate::scene::SceneDesc {
        let mut d = builtin::cornell_box(n, n);
        for m in &mut d.materials {
            if m.emission[0] > 0.0 {
                m.emission = [10.0; 3];
            } else {
                m.base_color = [0.6; 3];
            }
        }
        d
    }

    /// What bdpt predicts of `pt`'s noise (`predict_pt`) is `pt`'s own: without light
    /// samples, one bounce and a black lamp, `pt` makes each pixel's light by one path and
    /// one strategy, so its second moment per sample is exactly ∫ f²/p₀ — measured from
    /// `pt`'s "Variance" layer and mean, against bdpt's "PT Second Moment" (camera samples
    /// and light tracing's splats together) over the pixels that do not see the lamp (whose
    /// Le² both have exactly), 12 seeds each. (At 2 and 3 bounces the prediction measured
    /// 2% and 3% low, 8 seeds: small beside what the pilot reads it for.)
    #[test]
    fn bdpt_predicts_pts_second_moment() {
        let scene = Scene::build(&grey_box(16)).unwrap();
        let base = RenderSettings { path: PathSettings::new(1, false), threads: 2, ..Default::default() };
        let (mut pt_m2, mut bd_m2) = (Vec::new(), Vec::new());
        for seed in 1..=12u64 {
            let st = RenderSettings { method: Method::Pt, spp: 512, seed, ..base.clone() };
            let out = crate::integrator::render(&scene, &st, &RenderControl::new(0.0)).unwrap();
            let (c, v) = (out.layer("Combined").unwrap(), out.layer("Variance").unwrap());
            // (the lamp's own pixels: Le = 10)
            let unlit: Vec<usize> = (0..v.data.len()).filter(|&i| c.data[3 * i] < 5.0).collect();
            pt_m2.push(
                unlit.iter().map(|&i| v.data[i] as f64 * st.spp as f64 + (c.data[3 * i] as f64).powi(2)).sum::<f64>(),
            );
            let st = RenderSettings { method: Method::Bdpt, spp: 128, seed, predict_pt: true, ..base.clone() };
            let out = render_with(&scene, &st, &RenderControl::new(0.0), None);
            let m = out.layer("PT Second Moment").unwrap();
            bd_m2.push(unlit.iter().map(|&i| m.data[3 * i] as f64).sum::<f64>());
            // every path here is one pt makes: nothing unsampled
            assert!(out.layer("PT Unsampled").unwrap().data.iter().all(|&x| x == 0.0));
        }
        let stats = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (m, (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0) / v.len() as f64).sqrt())
        };
        let ((mp, sp), (mb, sb)) = (stats(&pt_m2), stats(&bd_m2));
        let z = (mp - mb).abs() / (sp * sp + sb * sb).sqrt();
        eprintln!("pt's second moment {mp:.4} ± {sp:.4}, bdpt's prediction {mb:.4} ± {sb:.4}: {z:.1}σ");
        assert!(z < 4.5, "pt's second moment {mp:.4} ± {sp:.4}, bdpt's prediction {mb:.4} ± {sb:.4}");
    }

    /// Light `pt` cannot make without light samples — a point lamp — is "PT Unsampled":
    /// the whole image but what the camera sees of the box's own light.
    #[test]
    fn bdpt_names_the_light_pt_cannot_make() {
        let mut d = grey_box(12);
        d.lights = vec![crate::scene::LightDesc::Point {
            name: "Lamp".into(),
            position: [0.3, 0.2, 0.5],
            radius: 0.0,
            power: [20.0; 3],
            soft_falloff: false,
            visible_camera: false,
            cast_shadow: true,
        }];
        d.materials.iter_mut().filter(|m| m.emission[0] > 0.0).for_each(|m| m.emission = [0.0; 3]);
        let scene = Scene::build(&d).unwrap();
        let st = RenderSettings {
            method: Method::Bdpt,
            spp: 16,
            path: PathSettings::new(3, false),
            predict_pt: true,
            ..Default::default()
        };
        let out = render_with(&scene, &st, &RenderControl::new(0.0), None);
        let sum = |name: &str| out.layer(name).unwrap().data.iter().map(|&x| x as f64).sum::<f64>();
        let (img, uns) = (sum("Combined"), sum("PT Unsampled"));
        assert!(img > 0.0 && (uns - img).abs() < 1e-3 * img, "image {img}, unsampled {uns}");
        assert_eq!(sum("PT Second Moment"), 0.0);
    }
}
