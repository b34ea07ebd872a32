//! THE path builder: a camera path from a stream of primary samples (Kajiya 1986), with
//! optional next-event estimation combined by multiple importance sampling (Veach 1997,
//! power heuristic). Every integrator builds its paths here; Metropolis samplers drive it by
//! supplying a mutated primary-sample stream instead of independent numbers.
//!
//! Primary samples are consumed in a fixed order — lens (2), then per vertex: light choice
//! (1), light point (2), BSDF lobe (1), BSDF direction (2), Russian roulette (1), and the
//! free-flight distance of the segment that reached it (1) — whether or not they are used,
//! so that a coordinate always means the same thing to a Markov chain. A vertex in a medium
//! (`crate::medium`) reads the same eight: its phase function takes the BSDF direction's.
//!
//! Bounce limit as in Cycles' "Max Bounces" B: a path scatters at most B+1 times, so B = 0
//! is direct lighting (light sampled at, or hit after, the first surface).

use crate::accel::TriHit;
use crate::bsdf::{Guide, Scatter};
use crate::guiding::{self, DTree, Guiding, PathRecords};
use crate::math::{is_finite_spectrum, power_heuristic, Frame, Spectrum};
use crate::medium::{Medium, MediumStack};
use crate::sampler::Sampler;
use crate::scene::{CameraRay, Scene, SurfaceInteraction, TexCoord};
use glam::{Vec2, Vec3};

/// Russian roulette: the probability that a path of throughput β goes on, min(1, (max β)^¼)
/// ([`RR_EXPONENT`]). Cycles takes the square root; a gentler roulette lets more of the long
/// paths that light closed interiors survive, at the price of longer paths. Measured at equal
/// time (2 s, 128², 8 bounces, 3 seeds, relMSE less the reference's noise, 2026-12-05), ¼
/// against ½: `pt` raw −13% on the door-ajar room, −18% on the gap and on a world-lit scene,
/// −9% on the glass box, −5% on area + point + sun + world, −3% on the 64-lamp hall (after
/// OIDN −11%, −8%, −8%, −4%, −5%, +3%); `gdpt` −18% on the gap, +3% on the world-lit scene;
/// `gdpssmlt` on the door +9% (within its spread). ⅛ was better still on the closed rooms
/// and 14% worse on the hall; no roulette at all (paths to the bounce limit) was no better
/// than ½ on the door at half the samples. Earlier (2026-12-02): ½ against max β, `pt` 1.2–1.45×
/// lower error on a world-lit scene, the gap and the Cornell box.
#[inline]
pub fn survival_probability(beta: Spectrum) -> f32 {
    beta.max_element().sqrt().sqrt().min(1.0)
}

/// The exponent of the roulette's survival probability (max β)^RR_EXPONENT.
pub const RR_EXPONENT: f32 = 0.25;

/// Russian roulette starts after this many scattering events.
pub const RR_START_DEPTH: u32 = 3;
/// Crossings of transparent surfaces (pass-through lobe) do not count as bounces; a path
/// ends after this many by default, as Cycles' "Transparent Max Bounces"
/// (`PathSettings::transparent_bounces`).
pub const MAX_TRANSPARENT_BOUNCES: u32 = 16;
/// Primary samples used per path vertex (see the module comment).
pub const SAMPLES_PER_VERTEX: usize = 8;

/// Path length limits, with Cycles' meaning: a path may scatter `max_bounces` times in all
/// and at most `diffuse_bounces` / `glossy_bounces` / `transmission_bounces` times of each
/// kind (bsdf::Scatter); the vertex after the last allowed scattering still adds direct light,
/// the one after that only the emission its ray hits (so 0 = direct light only). Crossings
/// of transparent surfaces count separately, up to `transparent_bounces`.
#[derive(Clone, Copy, Debug)]
pub struct PathSettings {
    pub max_bounces: u32,
    /// Next-event estimation with MIS; off = the paper's naive mode (lights only by hitting).
    pub nee: bool,
    pub diffuse_bounces: u32,
    pub glossy_bounces: u32,
    pub transmission_bounces: u32,
    /// Scatterings in media (Cycles' "Volume" bounces; Blender's default is 0: single
    /// scattering, light sampled at the first scattering in a medium and no further).
    pub volume_bounces: u32,
    pub transparent_bounces: u32,
    /// Cycles' Clamp Direct / Clamp Indirect (0 = off): a light contribution whose RGB sum
    /// exceeds 3 × the limit is scaled down to it (Cycles' scale: the sum of three channels) — direct for light reaching the camera ray or
    /// sampled from its first vertex, indirect after a bounce (Cycles' rule: light found by
    /// the first vertex's BSDF sample is already indirect). Biased, as in Cycles; `pt` and
    /// `pssmlt` apply it (the gradient-domain methods do not: see integrator::render).
    pub clamp_direct: f32,
    pub clamp_indirect: f32,
    /// Light samples through rough glass evaluated by the BSDF itself (`Bsdf::eval`), where
    /// next-event estimation and BSDF sampling alone then agree exactly; off (the default),
    /// as Cycles evaluates them (`Bsdf::eval_light`: a little more light through rough glass
    /// with NEE than without, as Cycles renders it). For tests of NEE against naive sampling.
    pub strict_glass_nee: bool,
}

/// A per-kind limit that never binds before the total does.
pub const NO_KIND_LIMIT: u32 = 1024;

impl PathSettings {
    /// Total limit `max_bounces`, no per-kind limit, NEE on or off.
    pub fn new(max_bounces: u32, nee: bool) -> PathSettings {
        PathSettings { max_bounces, nee, ..Default::default() }
    }

    /// Cycles' sample clamping of a light contribution `c` added after `bounces` scatterings:
    /// its RGB sum at most 3 × the direct (0 bounces) or indirect limit (0 = no limit).
    #[inline]
    pub fn clamp(&self, c: Spectrum, bounces: u32) -> Spectrum {
        let limit = 3.0 * if bounces == 0 { self.clamp_direct } else { self.clamp_indirect };
        let sum = c.x.abs() + c.y.abs() + c.z.abs();
        if limit > 0.0 && sum > limit {
            c * (limit / sum)
        } else {
            c
        }
    }

    /// The per-kind limits: diffuse, glossy, transmission.
    #[inline]
    fn kind_limits(&self) -> [u32; 4] {
        [self.diffuse_bounces, self.glossy_bounces, self.transmission_bounces, self.volume_bounces]
    }
}

impl Default for PathSettings {
    fn default() -> Self {
        PathSettings {
            max_bounces: 8,
            nee: true,
            diffuse_bounces: NO_KIND_LIMIT,
            glossy_bounces: NO_KIND_LIMIT,
            transmission_bounces: NO_KIND_LIMIT,
            volume_bounces: NO_KIND_LIMIT,
            transparent_bounces: MAX_TRANSPARENT_BOUNCES,
            clamp_direct: 0.0,
            clamp_indirect: 0.0,
            strict_glass_nee: false,
        }
    }
}

/// One scattering vertex of a path, as the shift mapping and the passes need it.
#[derive(Clone, Copy, Debug)]
pub struct Vertex {
    pub p: Vec3,
    pub ng: Vec3,
    pub frame: Frame,
    pub material: u32,
    pub prim: u32,
    pub front: bool,
    /// Texture coordinates and vertex colour.
    pub tex: TexCoord,
    pub color: Spectrum,
    /// The unmapped shading normal in `frame` (`SurfaceInteraction::unmapped`).
    pub unmapped: Vec3,
    /// Seen by the camera's ray (`SurfaceInteraction::camera`).
    pub camera: bool,
    /// The shift mapping's class of the BSDF here, seen from `wo` (`Bsdf::is_diffuse`),
    /// kept so that the offsets of one base path do not rebuild the BSDF to ask.
    pub diffuse: bool,
    /// Unit direction towards the previous vertex (world).
    pub wo: Vec3,
    /// Path throughput arriving at this vertex (product of f·cos/pdf and 1/RR so far).
    pub throughput: Spectrum,
    /// Solid-angle pdf of the direction that reached this vertex (0 for the camera ray).
    pub pdf_in: f32,
    /// The direction sampled here (world; zero when the path ended at this vertex), with
    /// its f·|cos| (for a delta lobe: weight·probability), pdf (for a delta lobe: the
    /// discrete probability), whether a delta lobe produced it, the relative IOR crossed
    /// (1 for reflection) and the Russian-roulette survival probability applied after it.
    pub wi: Vec3,
    pub f_out: Spectrum,
    pub pdf_out: f32,
    pub delta_out: bool,
    pub eta_out: f32,
    pub rr: f32,
    /// The path went beneath the surface here (`Scatter::Subsurface`): the next vertex is
    /// where its walk left the object.
    pub subsurface: bool,
}

impl Vertex {
    /// The vertex at `si`, reached from direction `wo` (towards where the path came from)
    /// with throughput `throughput` by a sample of pdf `pdf_in`; its outgoing half is filled
    /// in when the path continues.
    #[inline]
    fn at(si: &SurfaceInteraction, wo: Vec3, throughput: Spectrum, pdf_in: f32, diffuse: bool) -> Vertex {
        Vertex {
            p: si.p,
            ng: si.ng,
            frame: si.frame,
            material: si.material,
            prim: si.prim,
            front: si.front,
            tex: si.tex,
            color: si.color,
            unmapped: si.unmapped,
            camera: si.camera,
            diffuse,
            wo,
            throughput,
            pdf_in,
            wi: Vec3::ZERO,
            f_out: Spectrum::ZERO,
            pdf_out: 0.0,
            delta_out: false,
            eta_out: 1.0,
            rr: 1.0,
            subsurface: false,
        }
    }

    /// The path went straight through here (the pass-through lobe of a transparent surface:
    /// a delta transmission with relative IOR exactly 1, see `BsdfSample::is_pass_through`).
    #[inline]
    pub fn passed_through(&self) -> bool {
        self.delta_out && self.eta_out == 1.0 && !self.subsurface && self.wi.dot(self.ng) * self.wo.dot(self.ng) < 0.0
    }
}

/// Index used for events whose last segment starts at the camera (very-direct light).
pub const CAMERA_VERTEX: u32 = u32::MAX;

/// One way the path picked up light: an emitter hit after a BSDF sample from vertex
/// `vertex` (or an escape to the world), or a next-event estimate at `vertex`. The shift
/// mapping re-evaluates these for offset paths (docs/algorithm.md §4).
#[derive(Clone, Copy, Debug)]
pub struct Event {
    pub nee: bool,
    /// The vertex the last segment leaves from (`CAMERA_VERTEX` for camera rays).
    pub vertex: u32,
    /// Light index (`Scene::env_light()` for the world background).
    pub light: u32,
    /// Point on the light; for lights at infinity the unit direction towards them.
    pub z: Vec3,
    pub at_infinity: bool,
    pub delta: bool,
    /// Radiance arriving from z.
    pub le: Spectrum,
    /// BSDF·|cos| at `vertex` towards z.
    pub f: Spectrum,
    /// Solid-angle pdfs at `vertex` of z by BSDF sampling and by light sampling (selection
    /// included; 0 when that strategy cannot produce it; delta lights: pdf_l = selection).
    pub pdf_b: f32,
    pub pdf_l: f32,
    /// Throughput-weighted numerator: the balance-heuristic contribution is
    /// numerator / (pdf_b + pdf_l) (docs/algorithm.md §4, "MIS between base and offset").
    pub numerator: Spectrum,
    /// The last segment crossed transparent surfaces (a shadow ray through them, or
    /// pass-through vertices after `vertex`); `le` then includes their transmittance. The
    /// shift does not re-create such segments from a free offset vertex (it fails there,
    /// on both sides alike).
    pub through_transparent: bool,
    /// The light is direct (`PathContribution::direct`): the segment leaves the camera or a
    /// vertex reached before any scattering (crossings of transparent surfaces are not
    /// scatterings).
    pub direct: bool,
    /// The path's light events count what Cycles' light sampling adds through rough glass
    /// (`Bsdf::eval_light_sample`; NEE on and `PathSettings::strict_glass_nee` off): an
    /// offset re-evaluates a light sample *and* a BSDF hit with it, since either may shift
    /// to a pair of directions there that only light sampling reaches.
    pub as_cycles_light: bool,
    /// A medium touched the path up to this light (a segment through one, a scattering in
    /// one, a vertex on a medium's boundary) or the light's own segment: the shift does not
    /// follow paths through media (`shift.rs`, the base then takes full weight).
    pub medium: bool,
}

impl Event {
    /// (f·|cos θi|, BSDF pdf) of `bsdf` from wo towards wi for this event, whose light pdf
    /// there is `pdf_l`: the integrand every strategy of the path shares (a base's own BSDF
    /// hits are pairs the interface connects, where it is the BSDF).
    #[inline]
    pub fn bsdf_eval(&self, bsdf: &crate::bsdf::Bsdf, wo: Vec3, wi: Vec3, pdf_l: f32) -> (Spectrum, f32) {
        if self.as_cycles_light {
            bsdf.eval_light_sample(wo, wi, true, (!self.delta).then_some(pdf_l))
        } else {
            bsdf.eval_pdf(wo, wi)
        }
    }
}

/// A recorded path (reused between samples: no allocation once warm).
#[derive(Clone, Debug, Default)]
pub struct Path {
    pub vertices: Vec<Vertex>,
    pub events: Vec<Event>,
    /// The lens sample of the camera ray (offset paths reuse it).
    pub lens: Vec2,
}

/// What one camera path contributes.
#[derive(Clone, Copy, Debug, Default)]
pub struct PathContribution {
    /// Total radiance (including `very_direct`).
    pub radiance: Spectrum,
    /// Emission seen directly by the camera ray (docs/algorithm.md §4: never differenced).
    pub very_direct: Spectrum,
    /// Direct light, `very_direct` included: what the same path gives with `max_bounces` 0
    /// (Cycles' "direct lighting"): light reached after at most one scattering, and light
    /// samples taken before any (`Event::direct`). The Metropolis methods render it apart.
    pub direct: Spectrum,
    /// Albedo and normal of the first surface, for denoising passes.
    pub albedo: Spectrum,
    pub normal: Vec3,
    /// With a transparent film: the throughput (mean over RGB) with which the camera ray
    /// reached the world — 1 for a miss, less through tinted transparent surfaces, 0 when it
    /// stopped at a surface. Its mean is 1 − alpha, as Cycles' "transparent" sum.
    pub transparent: f32,
    /// The path's segments (closest-hit rays, the camera ray's included; shadow rays not):
    /// its length, which Russian roulette and the bounce limits set.
    pub segments: u32,
}

/// A path's camera ray and what it hits first: the start of `trace_path_from` (a caller may
/// trace the camera rays of several paths together, as one packet).
#[derive(Clone, Copy, Debug)]
pub struct Primary {
    /// The lens sample (the path's first two primary samples).
    pub lens: Vec2,
    pub ray: CameraRay,
    pub hit: Option<TriHit>,
}

/// Builds one path through `raster` (pixels, y from the top) and returns its contribution.
pub fn trace_path<S: Sampler>(
    scene: &Scene,
    cfg: &PathSettings,
    raster: Vec2,
    sampler: &mut S,
    record: Option<&mut Path>,
) -> PathContribution {
    let lens = sampler.next_2d();
    let ray = scene.camera.generate_ray(raster, lens);
    let hit = scene.intersect_camera(ray.origin, ray.dir, ray.tmin, ray.tmax);
    trace_path_from(scene, cfg, Primary { lens, ray, hit }, sampler, record)
}

/// The same path from its traced camera ray on (`sampler` then stands after the lens sample).
///
/// Each segment, in order: trace it (the camera ray's hit is given); add the analytic lights
/// it crosses; at a miss, the world (or, for a camera ray through a transparent film, the
/// film's transparency) and stop; at a surface, its emission, then the vertex (recorded for
/// the shift), its primary samples, the bounce limits, next-event estimation, and the BSDF
/// sample that continues the path (`PathState::scatter`, with Russian roulette).
pub fn trace_path_from<S: Sampler>(
    scene: &Scene,
    cfg: &PathSettings,
    primary: Primary,
    sampler: &mut S,
    record: Option<&mut Path>,
) -> PathContribution {
    trace_path_guided(scene, cfg, primary, sampler, record, None)
}

/// [`trace_path_from`] with path guiding (`guiding`): at a guidable vertex whose region has
/// learned where light comes from, the continuation is drawn from the guide or the BSDF
/// (`guiding::sample_mixture`; both the BSDF sample and the light sample's MIS see the
/// mixture's density), and in a training iteration the path records what it brings back.
pub fn trace_path_guided<S: Sampler>(
    scene: &Scene,
    cfg: &PathSettings,
    primary: Primary,
    sampler: &mut S,
    mut record: Option<&mut Path>,
    guiding: Option<Guiding>,
) -> PathContribution {
    if let Some(p) = record.as_deref_mut() {
        p.vertices.clear();
        p.events.clear();
        p.lens = primary.lens;
    }
    let mut out = PathContribution::default();
    if primary.ray.is_dead() {
        return out; // (outside a fisheye's circle: no light)
    }
    let mut st =
        PathState::new(primary.ray, cfg.nee && scene.has_lights(), !cfg.strict_glass_nee, scene.camera_media());
    let mut pending_hit = Some(primary.hit); // the camera ray's, traced by the caller
    let mut guide = Some(Spectrum::ONE); // the denoising guides' throughput, until they are written
                                         // what the path brings back through its guidable vertices, for the guide's training
    let mut learn = guiding.filter(|g| g.record).map(|_| PathRecords::default());
    loop {
        // 0. where a walk beneath a surface left it (`PathState::walk_beneath`): a vertex no
        // segment reached — a white Lambertian facing out, no emission, no holdout (Cycles'
        // `subsurface_shader_data_setup`) — else the next segment and the vertex it reaches
        let (si, bsdf, u) = if let Some((hit, wo)) = st.exit.take() {
            // (shaded as if reached from outside, against the walk: its normals face out)
            let si = SurfaceInteraction { camera: false, ..scene.interaction(&hit, -wo) };
            let bsdf = crate::bsdf::Bsdf::Lambert(crate::bsdf::Lambert::new(Spectrum::ONE));
            if let Some(p) = record.as_deref_mut() {
                p.vertices.push(Vertex::at(&si, wo, st.beta, 0.0, true));
            }
            (si, bsdf, VertexSamples::draw(sampler))
        } else {
            // 1. the segment, and the primary samples of the vertex it reaches
            out.segments += 1;
            let hit = match pending_hit.take() {
                Some(h) => h,
                // (what the camera sees through transparent surfaces, before any scattering)
                None if st.depth == 0 => scene.intersect_camera(st.o, st.d, st.tmin, st.tmax),
                None => scene.intersect(st.o, st.d, st.tmin, st.tmax),
            };
            let mut t_surface = hit.map_or(st.tmax, |h| h.t);
            // the camera ray itself (very-direct light); lamps stay invisible to the camera
            // through transparent surfaces too (depth counts scattering, not crossings)
            let camera_ray = st.nvert == 0;
            let camera_visibility = st.depth == 0;
            let u = VertexSamples::draw(sampler);

            // 2. the medium the segment runs through, if any: the lights it crosses, its
            // emission, then a free flight that may end before the surface (the lights
            // crossed are attenuated by the flight's weight where it passed them)
            let (mut in_medium, mut pass_weight) = (None, Spectrum::ONE);
            let (prev_p, o, d) = (st.prev_p, st.o, st.d);
            let medium = scene.medium(&st.media);
            let from_medium = st.prev_in_medium;
            // (only built in a medium: it is a few hundred bytes)
            let mut crossings = None;
            if let Some(m) = medium {
                st.touched_medium = true;
                let crossings = crossings.insert(crate::medium::Crossings::default());
                let push = |li, t, le, pdf| crossings.push(li, t, le, pdf);
                scene.for_each_light_crossed_in(prev_p, from_medium, o, d, t_surface, camera_visibility, push);
                let flight = scene.fly(&m, o, d, t_surface, u.distance, crossings);
                if flight.emitted.max_element() > 0.0 {
                    let c = cfg.clamp(st.beta * flight.emitted, st.depth);
                    add(&mut out, &mut learn, c, camera_ray, st.direct_emission());
                    st.record_medium_emission(&mut record, c);
                }
                match flight.free {
                    crate::medium::FreeFlight::Scatter { t, weight } => {
                        in_medium = Some((m, t, weight));
                        t_surface = t;
                    }
                    crate::medium::FreeFlight::Pass { weight } => pass_weight = weight,
                }
            }

            // 3. analytic lights crossed before the surface (lights are transparent). After
            // pass-throughs the light pdf is NEE's from the vertex the segment started at.
            let mut crossed = Spectrum::ZERO;
            let mut light_crossed = |li: u32, t: f32, le: Spectrum, pdf_light: f32| {
                if !scene.lights_receiver(li, st.prev_prim) {
                    return; // (light linking: it does not light the vertex the ray left)
                }
                let inf = !t.is_finite();
                let z = if inf { d } else { o + d * t };
                let pdf_light = if st.passed {
                    scene.light_eval_in(li, prev_p, z, from_medium).map_or(0.0, |x| x.1)
                } else {
                    pdf_light
                };
                crossed += le * st.mis(pdf_light);
                st.record_emission(&mut record, li, z, inf, le, pdf_light);
            };
            if let Some(crossings) = &crossings {
                // (in a medium: reached with the flight's weight where it passed t)
                for i in (0..crossings.n).filter(|&i| crossings.weight[i].max_element() > 0.0) {
                    let le = crossings.le[i] * crossings.weight[i];
                    light_crossed(crossings.light[i], crossings.t[i], le, crossings.pdf[i]);
                }
            } else {
                scene.for_each_light_crossed_in(prev_p, from_medium, o, d, t_surface, camera_visibility, light_crossed);
            }
            add(&mut out, &mut learn, cfg.clamp(st.beta * crossed, st.depth), camera_ray, st.direct_emission());
            st.beta *= pass_weight;
            if !(st.beta.max_element() > 0.0) {
                break; // (a medium absorbed every channel the path carried)
            }

            // 4. a scattering in the medium: a vertex of its own (light sample, phase function)
            if let Some((m, t, weight)) = in_medium {
                st.beta *= weight;
                if !st.scatter_in_medium(scene, cfg, &m, t, &u, &mut out, &mut learn, record.as_deref_mut()) {
                    break;
                }
                continue;
            }

            // 5. a miss: the world, or the film's transparency
            let Some(hit) = hit else {
                if camera_visibility && scene.camera.film_transparent {
                    // the world behind the camera ray (or behind the transparent surfaces it
                    // crossed) is the film's transparency, not light
                    out.transparent += (st.beta.x + st.beta.y + st.beta.z) / 3.0;
                    break;
                }
                if let Some(backdrop) = scene.backdrop.as_ref().filter(|_| camera_visibility) {
                    // what the camera sees instead of the world (no light sampling finds it)
                    let le = backdrop.eval(&scene.textures, st.d);
                    add(&mut out, &mut learn, cfg.clamp(st.beta * le, st.depth), camera_ray, st.direct_emission());
                    st.record_emission(&mut record, scene.env_light(), st.d, true, le, 0.0);
                    break;
                }
                let (le, pdf_light) = scene.world_eval(st.prev_p, st.d);
                if le.max_element() > 0.0 {
                    let c = cfg.clamp(st.beta * le * st.mis(pdf_light), st.depth);
                    add(&mut out, &mut learn, c, camera_ray, st.direct_emission());
                    st.record_emission(&mut record, scene.env_light(), st.d, true, le, pdf_light);
                }
                break;
            };

            // 6. the surface: a holdout the camera sees ends the path as the film's transparency;
            // else its emission, the vertex
            if camera_visibility && scene.is_holdout(hit.prim) {
                out.transparent += (st.beta.x + st.beta.y + st.beta.z) / 3.0;
                break;
            }
            let si = SurfaceInteraction { camera: camera_visibility, ..scene.interaction(&hit, st.d) };
            let linked = |li: Option<u32>| li.is_none_or(|li| scene.lights_receiver(li, st.prev_prim));
            let emission =
                scene.surface_emission(&si, st.prev_p, st.d).filter(|_| linked(scene.triangle_light(si.prim)));
            if let Some((le, pdf_light)) = emission {
                add(
                    &mut out,
                    &mut learn,
                    cfg.clamp(st.beta * le * st.mis(pdf_light), st.depth),
                    camera_ray,
                    st.direct_emission(),
                );
                let li = scene.triangle_light(si.prim).unwrap_or(u32::MAX);
                st.record_emission(&mut record, li, si.p, false, le, pdf_light);
            }
            // (a medium's boundary: the shift does not follow the path past it)
            st.touched_medium |= scene.has_medium(si.material);
            let bsdf = scene.bsdf_at(&si);
            denoising_guides(&mut out, &mut guide, &bsdf, si.frame.n, camera_ray);
            if let Some(p) = record.as_deref_mut() {
                p.vertices.push(Vertex::at(&si, -st.d, st.beta, st.prev_pdf, bsdf.is_diffuse()));
            }
            (si, bsdf, u)
        };
        let VertexSamples {
            light_select: u_light_select, light: u_light, lobe: u_lobe, bsdf: u_bsdf, rr: u_rr, ..
        } = u;

        // 7. the bounce limits. Past them the path still goes through transparent surfaces to
        // the light behind them, as Cycles' PATH_RAY_TERMINATE_AFTER_TRANSPARENT: only the
        // pass-through lobe, taken as `Bsdf::sample` takes it (`sample_pass_through`: the
        // recorded vertex is the one a sampled pass-through records, the shift follows it, and
        // the path cut at 0 bounces is the full path's direct light), no light sample.
        let wo = si.frame.to_local(-st.d);
        if st.depth > cfg.max_bounces || st.by_kind.iter().zip(&cfg.kind_limits()).any(|(n, max)| n > max) {
            let through = bsdf.sample_pass_through(wo, u_lobe);
            if through.is_some_and(|bs| st.scatter(scene, &si, wo, &bs, u_rr, cfg, record.as_deref_mut())) {
                continue;
            }
            break;
        }
        // The continuation is sampled first: it does not depend on the light sample, so the
        // processor overlaps the two computations before the shadow ray's traversal. At a
        // guided vertex, from the guide or the BSDF.
        let guided =
            guiding.filter(|_| st.depth < guiding::MAX_GUIDED_DEPTH && bsdf.guidable()).map(|g| g.field.at(si.p));
        let dist = guided.and_then(|g| g.dist);
        let sampled = match dist {
            Some(d) => guiding::sample_mixture(&bsdf, &si.frame, d, wo, u_lobe, u_bsdf),
            None => bsdf.sample(wo, u_lobe, u_bsdf),
        };

        // 8. next-event estimation
        if st.use_nee && !bsdf.is_delta() {
            let nee = next_event(scene, &si, &bsdf, wo, u_light_select, u_light, st.as_cycles_light, dist, st.media);
            if let Some(e) = nee {
                let c = cfg.clamp(st.beta * e.f * e.le * (e.weight / e.pdf_l), st.depth);
                add(&mut out, &mut learn, c, false, st.depth == 0);
                let numerator = st.beta * e.f * e.le;
                if let (Some(p), true) = (record.as_deref_mut(), numerator.max_element() > 0.0) {
                    let medium = st.touched_medium || e.event.medium;
                    p.events.push(Event { vertex: st.nvert, numerator, direct: st.depth == 0, medium, ..e.event });
                }
            }
        }

        // 9. the BSDF sample that continues the path (or beneath the surface)
        let Some(bs) = sampled else {
            break;
        };
        if bs.scatter == Scatter::Subsurface {
            if !st.walk_beneath(scene, &si, &bs, bsdf.subsurface(), &u, record.as_deref_mut()) {
                break;
            }
            continue;
        }
        if !st.scatter(scene, &si, wo, &bs, u_rr, cfg, record.as_deref_mut()) {
            break;
        }
        if let (Some(l), Some(g)) = (learn.as_mut(), guided) {
            if bs.lobe != crate::bsdf::LobeKind::Specular {
                l.push(g.leaf, st.d, bs.pdf, st.beta);
            }
        }
    }
    if let (Some(l), Some(g)) = (learn.as_ref(), guiding) {
        l.flush(g.field);
    }
    out
}

/// The path being built: its current segment, throughput and bounce counts, and what MIS
/// and the recorded events need of the last scattering vertex.
struct PathState {
    /// The segment being traced.
    o: Vec3,
    d: Vec3,
    tmin: f32,
    tmax: f32,
    /// Throughput (BSDF·cos/pdf products, Russian roulette included).
    beta: Spectrum,
    /// Scattering events so far (bounces; pass-through crossings excluded), pass-through
    /// crossings, and scattering events of each kind (diffuse, glossy, transmission).
    depth: u32,
    transparent: u32,
    by_kind: [u32; 4],
    /// Surface vertices so far (the index of the next one).
    nvert: u32,
    /// The last scattering vertex (the camera's position at first): where the segment's
    /// light pdfs are taken from, the pdf of the BSDF sample that left it (0: camera ray),
    /// whether that was specular or the camera (no MIS with NEE), and its BSDF·cos.
    prev_p: Vec3,
    /// The triangle of the last scattering vertex (u32::MAX: the camera), the receiver of
    /// the light a ray from there meets (light linking).
    prev_prim: u32,
    prev_pdf: f32,
    prev_delta: bool,
    prev_fcos: Spectrum,
    /// Whether the segment from the last scattering vertex has gone through transparent
    /// surfaces (MIS and events see through them: the segment continues), and their tints.
    passed: bool,
    pass_tint: Spectrum,
    /// Index of the last vertex that scattered (CAMERA_VERTEX before the first).
    last_vertex: u32,
    use_nee: bool,
    /// Light events are evaluated with what Cycles' light sampling adds through rough glass
    /// (NEE on, `strict_glass_nee` off).
    as_cycles_light: bool,
    /// The media the segment runs through, and whether any medium has touched the path yet
    /// (`Event::medium`).
    media: MediumStack,
    touched_medium: bool,
    /// The last scattering vertex is in a medium (its light pdfs: `Scene::sample_light_in`).
    prev_in_medium: bool,
    /// Where a walk beneath a surface left it, and the direction out (`walk_beneath`): the
    /// next vertex.
    exit: Option<(TriHit, Vec3)>,
}

impl PathState {
    fn new(cam: CameraRay, use_nee: bool, as_cycles_light: bool, media: MediumStack) -> PathState {
        PathState {
            o: cam.origin,
            d: cam.dir,
            tmin: cam.tmin,
            tmax: cam.tmax,
            beta: Spectrum::ONE,
            depth: 0,
            transparent: 0,
            by_kind: [0; 4],
            nvert: 0,
            prev_p: cam.origin,
            prev_prim: u32::MAX,
            prev_pdf: 0.0,
            prev_delta: true,
            prev_fcos: Spectrum::ONE,
            passed: false,
            pass_tint: Spectrum::ONE,
            last_vertex: CAMERA_VERTEX,
            use_nee,
            as_cycles_light: use_nee && as_cycles_light,
            media,
            touched_medium: false,
            prev_in_medium: false,
            exit: None,
        }
    }

    /// Emission found now is direct light: what the path cut at `max_bounces` 0 finds too —
    /// before any scattering, or on the segment straight after the first (through transparent
    /// surfaces too: the cut path goes on through them, past its limit).
    #[inline]
    fn direct_emission(&self) -> bool {
        self.depth <= 1
    }

    /// MIS weight of emission found by BSDF sampling whose light-sampling pdf is `pdf_light`.
    #[inline]
    fn mis(&self, pdf_light: f32) -> f32 {
        if !self.use_nee || self.prev_delta {
            1.0
        } else {
            power_heuristic(self.prev_pdf, pdf_light)
        }
    }

    /// Records emission found by BSDF sampling (a light crossed or hit, the world) as an
    /// event for the shift. Events after pass-throughs from the camera hang on the first
    /// crossed vertex, with the camera's "pdf" 1 (they are not very direct, and the shift
    /// fails on them). An event is recorded only when it carries light (its numerator is
    /// not zero): the shift treats an offset event worth nothing as absent (the path tracer
    /// could not have recorded it), so a zero-valued base event — a black texel of a
    /// textured emitter — must be absent too, or a pair would be counted from both sides.
    #[inline]
    fn record_emission(
        &self,
        rec: &mut Option<&mut Path>,
        light: u32,
        z: Vec3,
        at_infinity: bool,
        le: Spectrum,
        pdf_l: f32,
    ) {
        let (vertex, pdf_b) = match (self.nvert == 0, self.last_vertex) {
            (true, _) => (CAMERA_VERTEX, self.prev_pdf),
            (false, CAMERA_VERTEX) => (0, 1.0),
            (false, v) => (v, self.prev_pdf),
        };
        let numerator = self.beta * le * pdf_b;
        if !(numerator.max_element() > 0.0) {
            return;
        }
        if let Some(p) = rec.as_deref_mut() {
            p.events.push(Event {
                nee: false,
                vertex,
                light,
                z,
                at_infinity,
                delta: false,
                le: le * self.pass_tint,
                f: self.prev_fcos,
                pdf_b,
                // NEE cannot produce a path whose last bounce was specular: its light pdf is then 0
                pdf_l: if self.use_nee && !self.prev_delta { pdf_l } else { 0.0 },
                numerator,
                through_transparent: self.passed,
                direct: self.direct_emission(),
                as_cycles_light: self.as_cycles_light,
                medium: self.touched_medium,
            });
        }
    }

    /// Continues the path with the BSDF sample `bs` at `si`: the throughput, the bounce
    /// counts, the recorded vertex's outgoing half, Russian roulette (after RR_START_DEPTH
    /// scatterings, `u_rr`) and the next segment. False when the path ends here.
    #[allow(clippy::too_many_arguments)]
    fn scatter(
        &mut self,
        scene: &Scene,
        si: &SurfaceInteraction,
        wo: Vec3,
        bs: &crate::bsdf::BsdfSample,
        u_rr: f32,
        cfg: &PathSettings,
        record: Option<&mut Path>,
    ) -> bool {
        let wi_world = si.frame.to_world(bs.wi);
        if wi_world.dot(si.ng) * bs.wi.z <= 0.0 {
            return false; // shading normal sent the ray through the geometric surface
        }
        self.beta *= bs.weight;
        let pass_through = bs.is_pass_through(wo);
        if pass_through {
            self.transparent += 1;
        } else {
            self.depth += 1;
            match bs.scatter {
                Scatter::Diffuse => self.by_kind[0] += 1,
                Scatter::Glossy => self.by_kind[1] += 1,
                Scatter::Transmission => self.by_kind[2] += 1,
                Scatter::Transparent | Scatter::Subsurface => {}
            }
        }
        let q = if self.depth >= RR_START_DEPTH && !pass_through { survival_probability(self.beta) } else { 1.0 };
        if let Some(v) = record.and_then(|p| p.vertices.last_mut()) {
            v.wi = wi_world;
            v.f_out = bs.weight * bs.pdf;
            v.pdf_out = bs.pdf;
            v.delta_out = bs.lobe == crate::bsdf::LobeKind::Specular;
            v.eta_out = bs.eta;
            v.rr = q;
        }
        if q < 1.0 {
            if !(q > 0.0) || u_rr >= q {
                return false;
            }
            self.beta /= q;
        }
        if !is_finite_spectrum(self.beta)
            || self.beta.max_element() <= 0.0
            || self.transparent > cfg.transparent_bounces
        {
            return false;
        }
        if pass_through {
            // the segment from the last scattering vertex goes on through this surface
            self.passed = true;
            self.pass_tint *= bs.weight;
        } else {
            self.passed = false;
            self.pass_tint = Spectrum::ONE;
            self.last_vertex = self.nvert;
            self.prev_p = si.p;
            self.prev_prim = si.prim;
            self.prev_pdf = bs.pdf;
            self.prev_fcos = bs.weight * bs.pdf;
            self.prev_delta = bs.lobe == crate::bsdf::LobeKind::Specular;
            self.prev_in_medium = false;
        }
        self.nvert += 1;
        self.media = scene.media_towards(self.media, si, wi_world);
        self.o = si.spawn_origin(wi_world);
        self.d = wi_world;
        self.tmin = 0.0;
        self.tmax = f32::INFINITY;
        true
    }
}

impl PathState {
    /// The path enters the surface at `si` by the subsurface sample `bs` and walks beneath it
    /// (`medium::subsurface`, the interior of `sss` = (parameters, albedo)) to where it leaves
    /// the object — the first crossing of a surface of the same material — which becomes the
    /// next vertex (`exit`). Entering is not a bounce; the walk draws its random numbers from
    /// a generator seeded by the vertex's primary samples (its length varies: the primary
    /// sample layout stays fixed). False when the light is lost inside, or the direction does
    /// not enter. A path that walked is not shifted (`touched_medium`).
    fn walk_beneath(
        &mut self,
        scene: &Scene,
        si: &SurfaceInteraction,
        bs: &crate::bsdf::BsdfSample,
        albedo: Option<Spectrum>,
        u: &VertexSamples,
        record: Option<&mut Path>,
    ) -> bool {
        let Some(albedo) = albedo else { return false };
        let sss = scene.material(si).walk();
        let dir = si.frame.to_world(bs.wi);
        if dir.dot(si.ng) >= 0.0 {
            return false; // (the refraction left through the geometric surface)
        }
        self.beta *= bs.weight;
        if let Some(v) = record.and_then(|p| p.vertices.last_mut()) {
            v.wi = dir;
            v.f_out = bs.weight * bs.pdf;
            v.pdf_out = bs.pdf;
            v.delta_out = true;
            v.eta_out = 1.0;
            v.subsurface = true;
        }
        self.nvert += 1;
        self.touched_medium = true;
        let seed = [u.light_select, u.light.x, u.light.y, u.lobe, u.bsdf.x, u.bsdf.y, u.rr, u.distance]
            .iter()
            .fold(0x5eed_5ab5_u64, |h, x| crate::sampler::mix64(h ^ x.to_bits() as u64));
        let Some((_, exit_dir, weight, hit)) = walk_beneath(scene, si, dir, sss, albedo, seed) else {
            return false;
        };
        self.beta *= weight;
        if !is_finite_spectrum(self.beta) || !(self.beta.max_element() > 0.0) {
            return false;
        }
        self.passed = false;
        self.pass_tint = Spectrum::ONE;
        self.exit = Some((hit, exit_dir));
        self.d = -exit_dir; // (the exit vertex is reached against the walk's last direction)
        true
    }
}

/// The walk beneath the surface at `si` from direction `dir` (into it) through the interior of
/// `sss` with surface albedo `albedo` (`medium::subsurface`), its random numbers from a
/// generator seeded by `seed`, to the first crossing of a surface of the same material: the
/// exit shaded as if reached from outside against the walk (its normals face out), the
/// direction out, the walk's weight and the hit. None when the light is lost inside.
pub fn walk_beneath(
    scene: &Scene,
    si: &SurfaceInteraction,
    dir: Vec3,
    sss: crate::medium::subsurface::Subsurface,
    albedo: Spectrum,
    seed: u64,
) -> Option<(SurfaceInteraction, Vec3, Spectrum, TriHit)> {
    let interior = sss.coefficients(albedo);
    let mut rng = crate::sampler::IndependentSampler::new(seed, 0x55);
    let material = si.material;
    let exit = interior.walk(si.spawn_origin(dir), dir, &mut rng, |o, d, t_max| {
        // the closest crossing of a surface of this material (others are not there)
        let mut t_min = 0.0;
        for _ in 0..64 {
            let hit = scene.intersect(o, d, t_min, t_max)?;
            if scene.triangle_material(hit.prim) == material {
                return Some((hit.t, hit));
            }
            t_min = hit.t * (1.0 + 1e-5) + 1e-7;
        }
        None
    })?;
    let out = SurfaceInteraction { camera: false, ..scene.interaction(&exit.hit, -exit.dir) };
    Some((out, exit.dir, exit.weight, exit.hit))
}

/// The denoising guides (`PathContribution::albedo`, `normal`) at a surface of BSDF `bsdf`
/// and shading normal `n` that a path meets with guide throughput `guide` (None once they
/// are written): this surface, or through it if it is mirror-like; a camera ray's first
/// surface gives the normal even if the guides find no surface further on.
#[inline]
pub(crate) fn denoising_guides(
    out: &mut PathContribution,
    guide: &mut Option<Spectrum>,
    bsdf: &crate::bsdf::Bsdf,
    n: Vec3,
    camera_ray: bool,
) {
    let Some(t) = *guide else { return };
    if camera_ray {
        out.normal = n;
    }
    match bsdf.guide() {
        Guide::Surface(albedo) => {
            out.albedo = t * albedo;
            out.normal = n;
            *guide = None;
        }
        Guide::Through(tint) => *guide = Some(t * tint),
    }
}

/// A vertex's primary samples (the module comment's order).
#[derive(Clone, Copy, Debug)]
struct VertexSamples {
    light_select: f32,
    light: Vec2,
    lobe: f32,
    bsdf: Vec2,
    rr: f32,
    /// The free-flight distance of the segment that reaches the vertex.
    distance: f32,
}

impl VertexSamples {
    #[inline]
    fn draw<S: Sampler>(sampler: &mut S) -> VertexSamples {
        let light_select = sampler.next_1d();
        let light = sampler.next_2d();
        let lobe = sampler.next_1d();
        let bsdf = sampler.next_2d();
        let rr = sampler.next_1d();
        let distance = sampler.next_1d();
        VertexSamples { light_select, light, lobe, bsdf, rr, distance }
    }
}

impl PathState {
    /// Records light gathered along a segment in a medium (its emission) as an event the
    /// shift does not follow (`Event::medium`): numerator `c`, pdf 1.
    fn record_medium_emission(&self, rec: &mut Option<&mut Path>, c: Spectrum) {
        let Some(p) = rec.as_deref_mut().filter(|_| c.max_element() > 0.0) else { return };
        let vertex = match (self.nvert == 0, self.last_vertex) {
            (true, _) => CAMERA_VERTEX,
            (false, CAMERA_VERTEX) => 0,
            (false, v) => v,
        };
        p.events.push(Event {
            nee: false,
            vertex,
            light: u32::MAX,
            z: self.o,
            at_infinity: false,
            delta: false,
            le: c,
            f: Spectrum::ONE,
            pdf_b: 1.0,
            pdf_l: 0.0,
            numerator: c,
            through_transparent: self.passed,
            direct: self.direct_emission(),
            as_cycles_light: self.as_cycles_light,
            medium: true,
        });
    }

    /// A scattering in medium `m` at distance `t` along the segment (the throughput already
    /// weighted by the free flight): the vertex's bounce limits, a light sample through the
    /// media on its way (phase function × transmittance, MIS with phase sampling), and the
    /// phase-function sample that continues the path (with Russian roulette). False when
    /// the path ends here. The recorded vertex has no surface (`material` u32::MAX).
    #[allow(clippy::too_many_arguments)]
    fn scatter_in_medium(
        &mut self,
        scene: &Scene,
        cfg: &PathSettings,
        m: &Medium,
        t: f32,
        u: &VertexSamples,
        out: &mut PathContribution,
        learn: &mut Option<PathRecords>,
        mut record: Option<&mut Path>,
    ) -> bool {
        let p = self.o + self.d * t;
        let wo = -self.d;
        // (a point with no surface: no normal to offset rays along, no triangle)
        let at = SurfaceInteraction { t, ..Scene::medium_point(p, wo) };
        if let Some(rec) = record.as_deref_mut() {
            rec.vertices.push(Vertex::at(&at, wo, self.beta, self.prev_pdf, true));
        }
        // 1. the bounce limits (a medium has no pass-through: the path ends)
        if self.depth > cfg.max_bounces || self.by_kind.iter().zip(&cfg.kind_limits()).any(|(n, max)| n > max) {
            return false;
        }
        // 2. a light sample, through the media between
        if self.use_nee {
            if let Some((li, ls)) = scene.sample_light_in(p, u.light_select, u.light, true) {
                let (f, pdf_phase) = (m.phase.eval(wo, ls.wi), m.phase.pdf(wo, ls.wi));
                let reach = if scene.casts_shadow(li) {
                    scene.transmittance_in(&at, &ls, self.media)
                } else {
                    Some((Spectrum::ONE, false, false))
                };
                if let (true, Some((tr, crossed, _))) = (f > 0.0, reach) {
                    let weight = if ls.is_delta { 1.0 } else { power_heuristic(ls.pdf, pdf_phase) };
                    let le = ls.radiance * tr;
                    let numerator = self.beta * f * le;
                    add(out, learn, cfg.clamp(numerator * (weight / ls.pdf), self.depth), false, self.depth == 0);
                    if let (Some(rec), true) = (record.as_deref_mut(), numerator.max_element() > 0.0) {
                        let at_infinity = !ls.dist.is_finite();
                        rec.events.push(Event {
                            nee: true,
                            vertex: self.nvert,
                            light: li,
                            z: if at_infinity { ls.wi } else { ls.p },
                            at_infinity,
                            delta: ls.is_delta,
                            le,
                            f: Spectrum::splat(f),
                            pdf_b: if ls.is_delta { 0.0 } else { pdf_phase },
                            pdf_l: ls.pdf,
                            numerator,
                            through_transparent: crossed,
                            direct: self.depth == 0,
                            as_cycles_light: false,
                            medium: true,
                        });
                    }
                }
            }
        }
        // 3. the phase function's sample (its weight p/pdf: 1 for Henyey–Greenstein), Russian
        // roulette
        let (wi, pdf, w) = m.phase.sample(wo, u.bsdf);
        self.beta *= w;
        self.depth += 1;
        self.by_kind[3] += 1;
        let q = if self.depth >= RR_START_DEPTH { survival_probability(self.beta) } else { 1.0 };
        if let Some(v) = record.and_then(|p| p.vertices.last_mut()) {
            (v.wi, v.f_out, v.pdf_out, v.rr) = (wi, Spectrum::splat(pdf * w), pdf, q);
        }
        if q < 1.0 {
            if !(q > 0.0) || u.rr >= q {
                return false;
            }
            self.beta /= q;
        }
        if !is_finite_spectrum(self.beta) || self.beta.max_element() <= 0.0 || !(pdf > 0.0) {
            return false;
        }
        self.passed = false;
        self.pass_tint = Spectrum::ONE;
        self.last_vertex = self.nvert;
        self.prev_p = p;
        self.prev_prim = u32::MAX;
        self.prev_pdf = pdf;
        self.prev_fcos = Spectrum::splat(pdf * w); // (the phase function's value p)
        self.prev_delta = false;
        self.prev_in_medium = true;
        self.nvert += 1;
        self.o = p;
        self.d = wi;
        self.tmin = 0.0;
        self.tmax = f32::INFINITY;
        true
    }
}

/// A light sample at a vertex that reaches it: its radiance (through transparent surfaces),
/// the BSDF·cos towards it, its pdf and MIS weight, and the event to record (vertex and
/// numerator filled in by the caller).
struct NextEvent {
    le: Spectrum,
    f: Spectrum,
    pdf_l: f32,
    weight: f32,
    event: Event,
}

/// Next-event estimation at `si`: one light sample (`u_select`, `u_light`), unoccluded and on
/// a side BSDF sampling may continue to, or None. `as_cycles`: with what Cycles' evaluation
/// adds through rough glass (`Bsdf::eval_light_sample`). `guide`: the distribution a guided
/// vertex samples beside its BSDF, whose mixture density the MIS weight then uses.
#[inline]
#[allow(clippy::too_many_arguments)]
fn next_event(
    scene: &Scene,
    si: &SurfaceInteraction,
    bsdf: &crate::bsdf::Bsdf,
    wo: Vec3,
    u_select: f32,
    u_light: Vec2,
    as_cycles: bool,
    guide: Option<&DTree>,
    media: MediumStack,
) -> Option<NextEvent> {
    let (li, ls) = scene.sample_light(si.p, u_select, u_light)?;
    if !scene.lights_receiver(li, si.prim) {
        return None; // (light linking: it does not light this object)
    }
    let wi = si.frame.to_local(ls.wi);
    let (f, pdf_b) = bsdf.eval_light_sample(wo, wi, as_cycles, (!ls.is_delta).then_some(ls.pdf));
    // every direction the BSDF has a value towards, as Cycles takes light samples: also one
    // above the shading normal but below the geometric surface, whose shadow ray then starts
    // behind the surface (Cycles skips the triangle itself) or lifted off a smooth triangle
    // (scene/terminator.rs). (Keeping only the directions BSDF sampling continues in — one
    // side of both normals — left a veranda under a smooth low-poly roof 5–20% dark; skipping
    // the far side of a transmitting surface darkened a bulb in rough glass by 13%.)
    if !(f.max_element() > 0.0) {
        return None;
    }
    // (a light whose Cast Shadow is off reaches every point it faces, through media too: as
    // Cycles, which traces no shadow ray for it)
    let media = scene.media_towards(media, si, ls.wi);
    let (tr, crossed_transparent, medium) =
        if scene.casts_shadow(li) { scene.transmittance_in(si, &ls, media)? } else { (Spectrum::ONE, false, false) };
    let radiance = ls.radiance * tr;
    let pdf_b = match guide.filter(|_| !ls.is_delta) {
        Some(d) => guiding::mixture_pdf(d, ls.wi, pdf_b), // (BSDF sampling draws from the mixture here)
        None => pdf_b,
    };
    let weight = if ls.is_delta { 1.0 } else { power_heuristic(ls.pdf, pdf_b) };
    let at_infinity = !ls.dist.is_finite();
    let event = Event {
        nee: true,
        vertex: 0,
        light: li,
        z: if at_infinity { ls.wi } else { ls.p },
        at_infinity,
        delta: ls.is_delta,
        le: radiance,
        f,
        pdf_b,
        pdf_l: ls.pdf,
        numerator: Spectrum::ZERO,
        through_transparent: crossed_transparent,
        direct: false, // set by the caller
        as_cycles_light: as_cycles,
        medium,
    };
    Some(NextEvent { le: radiance, f, pdf_l: ls.pdf, weight, event })
}

/// What a camera ray sees first.
#[derive(Clone, Copy, Debug, Default)]
pub struct FirstHit {
    /// Emission seen directly (the very-direct image of the gradient-domain methods,
    /// estimated by plain Monte Carlo).
    pub very_direct: Spectrum,
    /// Albedo and shading normal of the first surface (denoising passes; zero on a miss).
    pub albedo: Spectrum,
    pub normal: Vec3,
}

/// What camera ray `cam` sees, given `hit`, what it hit (traced by the caller: Metropolis
/// renders trace a pixel's camera rays in packets).
pub fn first_hit(scene: &Scene, cam: &CameraRay, hit: Option<TriHit>) -> FirstHit {
    let mut out = FirstHit::default();
    if cam.is_dead() {
        return out;
    }
    let tmax = hit.map_or(cam.tmax, |h| h.t);
    // (a camera in a medium sees through it: its transmittance, and the light it emits)
    let medium = scene.medium(&scene.camera_media());
    let tr = |t: f32| medium.map_or(Spectrum::ONE, |m| scene.medium_transmittance(&m, cam.origin, cam.dir, t));
    let l = &mut out.very_direct;
    scene.for_each_light_crossed(cam.origin, cam.origin, cam.dir, tmax, true, |_, t, le, _| *l += le * tr(t));
    if let Some(m) = medium {
        out.very_direct += if m.is_heterogeneous() {
            // (the collision estimate of a flight, its numbers seeded by the ray)
            let mut rng = crate::medium::heterogeneous::rng_from(cam.dir.x + 2.0 * cam.dir.y + 3.0 * cam.dir.z, 0xf1);
            m.track(|p| scene.density_at(&m, p), (cam.origin, cam.dir), tmax, &mut rng, &[], &mut []).emitted
        } else {
            m.emitted(tmax)
        };
    }
    match hit {
        None if scene.camera.film_transparent => {}
        None => out.very_direct += scene.camera_background(cam.dir) * tr(cam.tmax),
        Some(h) if scene.is_holdout(h.prim) => {}
        Some(h) => {
            let si = SurfaceInteraction { camera: true, ..scene.interaction(&h, cam.dir) };
            if let Some((le, _)) = scene.surface_emission(&si, cam.origin, cam.dir) {
                out.very_direct += le * tr(h.t);
            }
            out.albedo = scene.bsdf_at(&si).albedo();
            out.normal = si.frame.n;
        }
    }
    out
}

/// The expected throughput with which camera ray `cam` (first hitting `hit`) reaches the
/// world (under a transparent film) or a holdout straight through transparent surfaces (the
/// product of their pass-through throughputs; 0 at an opaque surface): 1 − alpha, without
/// the noise of choosing pass-through or not (the path's own `transparent` has the same
/// mean).
pub fn camera_transparency(scene: &Scene, cam: &CameraRay, hit: Option<TriHit>, max_crossings: u32) -> f32 {
    if cam.is_dead() {
        return 0.0; // (no view there: opaque black, as a path that adds nothing leaves the film)
    }
    let mut t = Spectrum::ONE;
    let mut hit = hit;
    let mut media = scene.camera_media();
    // (the camera ray ends at the clip end; its continuations through surfaces, as the path
    // builder's, do not)
    let mut tmax = cam.tmax;
    let mut o = cam.origin;
    for _ in 0..=max_crossings {
        // (through media: their transmittance to the next surface, or to the ray's end)
        if let Some(m) = scene.medium(&media) {
            t *= scene.medium_transmittance(&m, o, cam.dir, hit.map_or(tmax, |h| h.t));
        }
        tmax = f32::INFINITY;
        let seen_through = (t.x + t.y + t.z) / 3.0;
        let Some(h) = hit else {
            return if scene.camera.film_transparent { seen_through } else { 0.0 };
        };
        if scene.is_holdout(h.prim) {
            return seen_through;
        }
        let si = SurfaceInteraction { camera: true, ..scene.interaction(&h, cam.dir) };
        t *= scene.bsdf_at(&si).pass_through();
        if !(t.max_element() > 0.0) {
            return 0.0;
        }
        media = scene.media_towards(media, &si, cam.dir);
        o = si.spawn_origin(cam.dir);
        hit = scene.intersect_camera(o, cam.dir, 0.0, f32::INFINITY);
    }
    0.0 // past the transparent-bounce limit the path tracer stops too: opaque
}

#[inline]
fn add(out: &mut PathContribution, learn: &mut Option<PathRecords>, c: Spectrum, very_direct: bool, direct: bool) {
    if let Some(l) = learn.as_mut() {
        l.add(c);
    }
    out.radiance += c;
    if very_direct {
        out.very_direct += c;
    }
    if direct {
        out.direct += c;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::IndependentSampler;
    use crate::scene::builtin::cornell_box;

    /// The roulette's survival probability is (max β)^RR_EXPONENT, capped at 1, over the
    /// throughputs paths carry (the benchmarks' Mitsuba replica reads RR_EXPONENT).
    #[test]
    fn survival_probability_is_the_documented_power() {
        for &b in &[1e-8f32, 1e-4, 0.01, 0.2, 0.5, 0.99, 1.0, 3.0, 1e6] {
            let beta = Spectrum::new(0.5 * b, b, 0.25 * b);
            let q = survival_probability(beta);
            let expected = b.powf(RR_EXPONENT).min(1.0);
            assert!((q - expected).abs() <= 1e-6 * expected, "β {b}: {q} against {expected}");
        }
        assert_eq!(survival_probability(Spectrum::ZERO), 0.0);
    }

    /// The denoising guides look through mirrors, as Cycles' do: where the camera ray meets a
    /// mirror ball, the albedo guide is the mirror's colour times the albedo of the first
    /// surface that is not mirror-like along the reflections (the normal guide that
    /// surface's); elsewhere the first surface is its own guide. (Before, every pixel's
    /// guide was its first surface: the balls were flat grey to the denoiser.)
    #[test]
    fn denoising_guides_look_through_mirrors() {
        use crate::bsdf::Guide;
        let (w, h) = (32u32, 32u32);
        let mut desc = crate::scene::builtin::cornell_spheres(w, h);
        let mirror = desc.materials.iter().position(|m| m.name == "Mirror").unwrap() as u32;
        for m in desc.meshes.iter_mut().filter(|m| m.name == "GlassSphere") {
            m.material_ids.iter_mut().for_each(|id| *id = mirror); // both balls mirrors
        }
        let scene = Scene::build(&desc).unwrap();
        let cfg = PathSettings::new(8, true);
        let (mut through, mut surface) = (0, 0);
        for (x, y) in (0..w).flat_map(|x| (0..h).map(move |y| (x, y))) {
            let raster = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let mut s = IndependentSampler::new(5, (y * w + x) as u64);
            let c = trace_path(&scene, &cfg, raster, &mut s, None);
            let ray = scene.camera.generate_ray(raster, Vec2::splat(0.5)); // no depth of field
            let (mut o, mut d, mut tint, mut bounces) = (ray.origin, ray.dir, Spectrum::ONE, 0);
            let expected = loop {
                let Some(hit) = scene.intersect(o, d, 0.0, f32::INFINITY) else { break None };
                let si = scene.interaction(&hit, d);
                match scene.bsdf_at(&si).guide() {
                    Guide::Surface(albedo) => break Some((tint * albedo, si.frame.n)),
                    Guide::Through(t) => {
                        tint *= t;
                        bounces += 1;
                        let n = si.frame.n;
                        d = (d - 2.0 * d.dot(n) * n).normalize();
                        o = si.spawn_origin(d);
                    }
                }
            };
            let Some((albedo, n)) = expected else { continue };
            assert!((c.albedo - albedo).abs().max_element() < 1e-4, "pixel ({x}, {y}): {:?} vs {albedo:?}", c.albedo);
            assert!((c.normal - n).length() < 1e-4, "pixel ({x}, {y})");
            if bounces > 0 {
                through += 1;
            } else {
                surface += 1;
            }
        }
        assert!(through > 30 && surface > 300, "{through} pixels on the balls, {surface} elsewhere");
    }

    /// The recorded events, weighted by the balance heuristic, estimate the same radiance as
    /// the path tracer's own (power-heuristic) sum: they must agree in the mean.
    #[test]
    fn recorded_events_reproduce_the_radiance() {
        for (scene, nee) in [
            (Scene::build(&cornell_box(16, 16)).unwrap(), true),
            (Scene::build(&cornell_box(16, 16)).unwrap(), false),
            (Scene::build(&crate::scene::builtin::cornell_spheres(16, 16)).unwrap(), true),
            (Scene::build(&crate::scene::builtin::cornell_veil(16, 16)).unwrap(), true),
            (Scene::build(&crate::scene::builtin::cornell_veil(16, 16)).unwrap(), false),
        ] {
            let cfg = PathSettings::new(4, nee);
            let mut path = Path::default();
            let (mut a, mut b) = (0.0f64, 0.0f64);
            let n = 200_000;
            for i in 0..n {
                let mut s = IndependentSampler::new(9, i);
                let raster =
                    Vec2::new(8.0, 8.0) + s.next_2d() * 2.0 - Vec2::ONE * 1.0 + Vec2::new((i % 7) as f32 - 3.0, 0.0);
                let c = trace_path(&scene, &cfg, raster, &mut s, Some(&mut path));
                a += crate::math::luminance(c.radiance - c.very_direct) as f64;
                for e in path.events.iter().filter(|e| e.vertex != CAMERA_VERTEX) {
                    b += crate::math::luminance(e.numerator / (e.pdf_b + e.pdf_l)) as f64;
                }
            }
            let (a, b) = (a / n as f64, b / n as f64);
            assert!((a - b).abs() < 0.01 * a, "nee={nee}: path tracer {a} vs events {b}");
        }
    }

    /// `direct` is what the same path gives cut at `max_bounces` 0 (the Metropolis methods'
    /// direct pass renders exactly that, their chains the rest): equal sample by sample, the
    /// same primary samples driving both, on scenes with transparent crossings, mirrors and
    /// glass, NEE and naive; and recorded events of both kinds occur.
    #[test]
    fn direct_light_is_the_path_cut_at_no_bounce() {
        use crate::scene::builtin::{cornell_mixed_lights, cornell_spheres, cornell_veil};
        for (k, desc) in
            [cornell_box(16, 16), cornell_spheres(16, 16), cornell_veil(16, 16), cornell_mixed_lights(16, 16)]
                .iter()
                .enumerate()
        {
            let scene = Scene::build(desc).unwrap();
            for nee in [true, false] {
                let full = PathSettings::new(6, nee);
                let cut = PathSettings { max_bounces: 0, ..full };
                let mut path = Path::default();
                let (mut direct, mut indirect) = (0usize, 0usize);
                for i in 0..4000u64 {
                    let raster = Vec2::new((i % 16) as f32, ((i / 16) % 16) as f32);
                    let mut s = IndependentSampler::new(21, i);
                    let raster = raster + s.next_2d();
                    let c = trace_path(&scene, &full, raster, &mut s, Some(&mut path));
                    let mut s = IndependentSampler::new(21, i);
                    let raster2 = Vec2::new((i % 16) as f32, ((i / 16) % 16) as f32) + s.next_2d();
                    assert_eq!(raster, raster2);
                    let d = trace_path(&scene, &cut, raster, &mut s, None);
                    assert_eq!(c.direct, d.radiance, "scene {k} nee={nee} path {i}");
                    assert_eq!(d.direct, d.radiance, "scene {k} nee={nee} path {i}: the cut path is all direct");
                    assert!((c.very_direct - c.direct).max_element() <= 0.0, "very direct light is direct");
                    for e in path.events.iter().filter(|e| e.vertex != CAMERA_VERTEX) {
                        if e.direct {
                            direct += 1;
                        } else {
                            indirect += 1;
                        }
                    }
                }
                assert!(direct > 0 && indirect > 0, "scene {k} nee={nee}: {direct} direct, {indirect} indirect events");
            }
        }
    }

    /// Every recorded event carries light: the shift counts an offset event worth nothing
    /// as absent, so the base must not record such events either (else a pair is counted
    /// from both sides). Checked on a light whose emission is a black-and-white checker, hit
    /// and sampled on its black texels too, with and without NEE (zero-valued events were
    /// recorded before, and this test failed).
    #[test]
    fn recorded_events_carry_light() {
        use crate::scene::desc::TextureDesc;
        let mut desc = cornell_box(16, 16);
        desc.textures.push(TextureDesc {
            name: "checker".into(),
            width: 8,
            height: 8,
            pixels: (0..64).map(|i| if (i % 8 + i / 8) % 2 == 0 { [1.0; 3] } else { [0.0; 3] }).collect(),
            closest: true,
            ..Default::default()
        });
        let light = desc.materials.iter().position(|m| m.name == "Light").unwrap();
        desc.materials[light].emission_texture = Some(0);
        let uv = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let quad = desc.meshes.iter_mut().find(|m| m.name == "Light").unwrap();
        quad.corner_uvs = [0, 1, 2, 0, 2, 3].iter().map(|&k| uv[k]).collect();
        let scene = Scene::build(&desc).unwrap();
        for nee in [false, true] {
            let cfg = PathSettings::new(4, nee);
            let mut path = Path::default();
            let mut events = 0;
            for i in 0..40_000u64 {
                let mut s = IndependentSampler::new(3, i);
                let raster = Vec2::new((i % 16) as f32, ((i / 16) % 16) as f32) + s.next_2d();
                trace_path(&scene, &cfg, raster, &mut s, Some(&mut path));
                for e in &path.events {
                    assert!(
                        e.numerator.max_element() > 0.0,
                        "nee={nee}: path {i} recorded an event worth {:?}",
                        e.numerator
                    );
                    events += 1;
                }
            }
            assert!(events > 200, "nee={nee}: {events} events");
        }
    }
}
