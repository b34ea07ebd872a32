//! THE path builder: a camera path from a stream of primary samples (Kajiya 1986), with
//! optional next-event estimation combined by multiple importance sampling (Veach 1997,
//! power heuristic). Every integrator builds its paths here; Metropolis samplers drive it by
//! supplying a mutated primary-sample stream instead of independent numbers.
//!
//! Primary samples are consumed in a fixed order — lens (2), then per vertex: light choice
//! (1), light point (2), BSDF lobe (1), BSDF direction (2), Russian roulette (1) — whether or
//! not they are used, so that a coordinate always means the same thing to a Markov chain.
//!
//! Bounce limit as in Cycles' "Max Bounces" B: a path scatters at most B+1 times, so B = 0
//! is direct lighting (light sampled at, or hit after, the first surface).

use crate::math::{is_finite_spectrum, power_heuristic, Frame, Spectrum};
use crate::sampler::Sampler;
use crate::scene::{Scene, SurfaceInteraction};
use glam::{Vec2, Vec3};

/// Russian roulette starts after this many scattering events.
pub const RR_START_DEPTH: u32 = 3;
/// Primary samples used per path vertex (see the module comment).
pub const SAMPLES_PER_VERTEX: usize = 7;

#[derive(Clone, Copy, Debug)]
pub struct PathSettings {
    pub max_bounces: u32,
    /// Next-event estimation with MIS; off = the paper's naive mode (lights only by hitting).
    pub nee: bool,
}

impl Default for PathSettings {
    fn default() -> Self {
        PathSettings { max_bounces: 8, nee: true }
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
    /// Unit direction towards the previous vertex (world).
    pub wo: Vec3,
    /// Path throughput arriving at this vertex (product of f·cos/pdf and 1/RR so far).
    pub throughput: Spectrum,
    /// Solid-angle pdf of the direction that reached this vertex (0 for the camera ray).
    pub pdf_in: f32,
}

/// A recorded path (reused between samples: no allocation once warm).
#[derive(Clone, Debug, Default)]
pub struct Path {
    pub vertices: Vec<Vertex>,
}

/// What one camera path contributes.
#[derive(Clone, Copy, Debug, Default)]
pub struct PathContribution {
    /// Total radiance (including `very_direct`).
    pub radiance: Spectrum,
    /// Emission seen directly by the camera ray (ALGORITHM.md §4: never differenced).
    pub very_direct: Spectrum,
    /// Albedo and normal of the first surface, for denoising passes.
    pub albedo: Spectrum,
    pub normal: Vec3,
}

/// Builds one path through `raster` (pixels, y from the top) and returns its contribution.
pub fn trace_path<S: Sampler>(
    scene: &Scene,
    cfg: &PathSettings,
    raster: Vec2,
    sampler: &mut S,
    mut record: Option<&mut Path>,
) -> PathContribution {
    if let Some(p) = record.as_deref_mut() {
        p.vertices.clear();
    }
    let mut out = PathContribution::default();
    let cam = scene.camera.generate_ray(raster, sampler.next_2d());
    let (mut o, mut d, mut tmin, mut tmax) = (cam.origin, cam.dir, cam.tmin, cam.tmax);
    let mut beta = Spectrum::ONE;
    let mut depth = 0u32; // scattering events so far
    let mut prev_p = o;
    let mut prev_pdf = 0.0f32; // pdf of the BSDF sample that produced `d` (0: camera ray)
    let mut prev_delta = true; // camera ray or specular bounce: no MIS with NEE
    let use_nee = cfg.nee && scene.has_lights();

    loop {
        let hit = scene.intersect(o, d, tmin, tmax);
        let t_surface = hit.map_or(tmax, |h| h.t);
        let camera_ray = depth == 0;
        let mis = |pdf_light: f32| {
            if !use_nee || prev_delta {
                1.0
            } else {
                power_heuristic(prev_pdf, pdf_light)
            }
        };

        // Analytic lights crossed before the surface (lights are transparent).
        let mut crossed = Spectrum::ZERO;
        scene.for_each_light_crossed(o, d, t_surface, camera_ray, |le, pdf_light| crossed += le * mis(pdf_light));
        add(&mut out, beta * crossed, camera_ray);

        let Some(hit) = hit else {
            add(&mut out, beta * scene.world, camera_ray); // the world is found by BSDF sampling only
            break;
        };
        let si: SurfaceInteraction = scene.interaction(&hit, o, d);
        let wo_world = -d;
        if let Some((le, pdf_light)) = scene.surface_emission(&si, prev_p, d) {
            add(&mut out, beta * le * mis(pdf_light), camera_ray);
        }
        let material = scene.material(&si);
        let bsdf = material.bsdf();
        if depth == 0 {
            out.albedo = bsdf.albedo();
            out.normal = si.frame.n;
        }
        if let Some(p) = record.as_deref_mut() {
            p.vertices.push(Vertex {
                p: si.p,
                ng: si.ng,
                frame: si.frame,
                material: si.material,
                prim: si.prim,
                wo: wo_world,
                throughput: beta,
                pdf_in: prev_pdf,
            });
        }
        // Consume this vertex's primary samples in their fixed order.
        let u_light_select = sampler.next_1d();
        let u_light = sampler.next_2d();
        let u_lobe = sampler.next_1d();
        let u_bsdf = sampler.next_2d();
        let u_rr = sampler.next_1d();
        if depth > cfg.max_bounces {
            break;
        }
        let wo = si.frame.to_local(wo_world);

        // Next-event estimation.
        if use_nee && !bsdf.is_delta() {
            if let Some((_, ls)) = scene.sample_light(si.p, u_light_select, u_light) {
                let wi = si.frame.to_local(ls.wi);
                let f = bsdf.eval(wo, wi);
                if f.max_element() > 0.0 && ls.wi.dot(si.ng) > 0.0 && scene.visible(&si, &ls) {
                    let w = if ls.is_delta { 1.0 } else { power_heuristic(ls.pdf, bsdf.pdf(wo, wi)) };
                    add(&mut out, beta * f * ls.radiance * (w / ls.pdf), false);
                }
            }
        }

        // BSDF sampling.
        let Some(bs) = bsdf.sample(wo, u_lobe, u_bsdf) else {
            break;
        };
        let wi_world = si.frame.to_world(bs.wi);
        if wi_world.dot(si.ng) * bs.wi.z <= 0.0 {
            break; // shading normal sent the ray through the geometric surface
        }
        beta *= bs.weight;
        depth += 1;
        if depth >= RR_START_DEPTH {
            let q = beta.max_element().min(1.0);
            if !(q > 0.0) || u_rr >= q {
                break;
            }
            beta /= q;
        }
        if !is_finite_spectrum(beta) || beta.max_element() <= 0.0 {
            break;
        }
        prev_p = si.p;
        prev_pdf = bs.pdf;
        prev_delta = bs.lobe == crate::bsdf::LobeKind::Specular;
        o = si.spawn_origin(wi_world);
        d = wi_world;
        tmin = 0.0;
        tmax = f32::INFINITY;
    }
    out
}

#[inline]
fn add(out: &mut PathContribution, c: Spectrum, very_direct: bool) {
    out.radiance += c;
    if very_direct {
        out.very_direct += c;
    }
}
