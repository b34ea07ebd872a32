//! Gradient-domain path tracing (Kettunen et al. 2015): every base path is shifted to its
//! four neighbours (shift.rs); the pair contributions give a primal image and forward-
//! difference gradients, reconstructed by screened Poisson (reconstruct/). Light seen
//! directly by the camera goes to a separate very-direct image, added afterwards.
//!
//! Splats reach the rows above and below, so rows are processed in three phases (y mod 3):
//! within a phase the 3-row windows are disjoint, which makes the accumulation lock-free and
//! the image identical for any thread count.

use super::{RenderControl, RenderOutput, RenderSettings, RenderStats};
use crate::film::Image;
use crate::math::{is_finite_spectrum, Spectrum};
use crate::path::{trace_path_from, Path, Primary};
use crate::reconstruct::gradient_domain_image;
use crate::sampler::Sampler;
use crate::scene::{CameraRay, Scene};
use crate::shift::shift_from;
use glam::Vec2;
use rayon::prelude::*;
use std::sync::atomic::Ordering;

/// Accumulators of one image row.
#[derive(Clone)]
pub struct GdRow {
    pub primal: Vec<[f64; 3]>,
    pub dx: Vec<[f64; 3]>,
    pub dy: Vec<[f64; 3]>,
    pub direct: Vec<[f64; 3]>,
    pub albedo: Vec<[f64; 3]>,
    pub normal: Vec<[f64; 3]>,
    /// Sum of the base samples' film transparency.
    pub transparent: Vec<f64>,
    pub invalid: u64,
}

impl GdRow {
    fn new(w: usize) -> GdRow {
        let z = vec![[0.0; 3]; w];
        GdRow {
            primal: z.clone(),
            dx: z.clone(),
            dy: z.clone(),
            direct: z.clone(),
            albedo: z.clone(),
            normal: z,
            transparent: vec![0.0; w],
            invalid: 0,
        }
    }
}

#[inline]
fn acc(a: &mut [f64; 3], v: Spectrum, s: f64) {
    a[0] += v.x as f64 * s;
    a[1] += v.y as f64 * s;
    a[2] += v.z as f64 * s;
}

/// (dx, dy) of the four shifts.
pub const SHIFTS: [(i32, i32); 4] = [(1, 0), (-1, 0), (0, 1), (0, -1)];

/// Renders samples [from, to) of the base pixels of row `y`; `win` holds rows lo..lo+len.
#[allow(clippy::too_many_arguments)]
fn render_row(scene: &Scene, settings: &RenderSettings, y: usize, lo: usize, win: &mut [GdRow], from: u32, to: u32) {
    let (w, h) = (scene.camera.width as i32, scene.camera.height as i32);
    let mut path = Path::default();
    for x in 0..w as usize {
        for s in from..to {
            let mut sampler = super::pt::pixel_sampler(settings.seed, y * w as usize + x, s);
            let raster = scene.camera.pixel_raster(x as f32, y as f32, sampler.next_2d());
            // the base's camera ray and its four offsets' (neighbour pixels, same lens sample)
            // traced as one packet: ray 0 the base, ray 1 + i the offset of SHIFTS[i]
            let lens = sampler.next_2d();
            let mut rays = [CameraRay::default(); 1 + SHIFTS.len()];
            for (ray, (dx, dy)) in rays.iter_mut().zip(std::iter::once((0, 0)).chain(SHIFTS)) {
                *ray = scene.camera.generate_ray(raster + Vec2::new(dx as f32, dy as f32), lens);
            }
            let hits = scene.intersect_camera_rays(&rays);
            let (ray, hit) = (rays[0], hits[0]);
            let c = trace_path_from(scene, &settings.path, Primary { lens, ray, hit }, &mut sampler, Some(&mut path));
            let me = &mut win[y - lo];
            if !is_finite_spectrum(c.radiance) {
                me.invalid += 1;
                continue;
            }
            acc(&mut me.direct[x], c.very_direct, 1.0);
            acc(&mut me.albedo[x], c.albedo, 1.0);
            acc(&mut me.normal[x], c.normal, 1.0);
            me.transparent[x] += c.transparent as f64;
            for (i, (dx, dy)) in SHIFTS.into_iter().enumerate() {
                let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                let inside = nx >= 0 && ny >= 0 && nx < w && ny < h;
                let pc = shift_from(scene, &path, inside.then(|| (rays[1 + i], hits[1 + i])));
                if !is_finite_spectrum(pc.base) || !is_finite_spectrum(pc.offset) {
                    win[y - lo].invalid += 1;
                    continue;
                }
                acc(&mut win[y - lo].primal[x], pc.base, 0.25);
                if !inside {
                    continue;
                }
                let (nx, ny) = (nx as usize, ny as usize);
                acc(&mut win[ny - lo].primal[nx], pc.offset, 0.25);
                let g = pc.offset - pc.base;
                match (dx, dy) {
                    (1, 0) => acc(&mut win[y - lo].dx[x], g, 1.0),
                    (-1, 0) => acc(&mut win[ny - lo].dx[nx], g, -1.0),
                    (0, 1) => acc(&mut win[y - lo].dy[x], g, 1.0),
                    _ => acc(&mut win[ny - lo].dy[nx], g, -1.0),
                }
            }
        }
    }
}

/// Runs one phase: base rows y ≡ phase (mod 3), each with its window of rows y−1..=y+1.
fn run_phase(scene: &Scene, settings: &RenderSettings, rows: &mut [GdRow], phase: usize, from: u32, to: u32) {
    let h = rows.len();
    let mut windows = Vec::new();
    let mut rest: &mut [GdRow] = rows;
    let mut offset = 0;
    for y in (phase..h).step_by(3) {
        let lo = y.saturating_sub(1);
        let hi = (y + 1).min(h - 1);
        let (_, r) = std::mem::take(&mut rest).split_at_mut(lo - offset);
        let (win, r2) = r.split_at_mut(hi - lo + 1);
        windows.push((y, lo, win));
        rest = r2;
        offset = hi + 1;
    }
    windows.into_par_iter().for_each(|(y, lo, win)| render_row(scene, settings, y, lo, win, from, to));
}

fn to_image(rows: &[GdRow], pick: impl Fn(&GdRow) -> &Vec<[f64; 3]>, scale: f64) -> Vec<f64> {
    let mut out = Vec::new();
    for r in rows {
        for px in pick(r) {
            out.extend(px.iter().map(|v| v * scale));
        }
    }
    out
}

fn f32_image(w: usize, h: usize, data: &[f64]) -> Image {
    Image { width: w, height: h, channels: 3, data: data.iter().map(|&v| v as f32).collect() }
}

/// Normalises the accumulators of `spp` samples and reconstructs:
/// (combined, primal + very direct, dx, dy, very direct).
fn resolve(
    rows: &[GdRow],
    w: usize,
    h: usize,
    spp: u32,
    alpha: f64,
    norm: crate::reconstruct::Norm,
    stop: &(dyn Fn() -> bool + Sync),
) -> (Image, Image, Image, Image, Image) {
    let scale = 1.0 / spp.max(1) as f64;
    let primal = to_image(rows, |r| &r.primal, scale);
    let dx = to_image(rows, |r| &r.dx, scale);
    let dy = to_image(rows, |r| &r.dy, scale);
    let direct = to_image(rows, |r| &r.direct, scale);
    let (combined, primal_full) = gradient_domain_image(w, h, &primal, &dx, &dy, &direct, alpha, norm, stop);
    let im = |v: &[f64]| f32_image(w, h, v);
    (im(&combined), im(&primal_full), im(&dx), im(&dy), im(&direct))
}

pub fn render(scene: &Scene, settings: &RenderSettings, control: &RenderControl) -> RenderOutput {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let mut rows = vec![GdRow::new(w); h];
    control.work_total.store(w as u64 * h as u64 * settings.spp as u64, Ordering::Relaxed);
    let (mut done, mut batch) = (0u32, 1u32);
    // Whole passes only (a pass is short): every pixel always has the same sample count.
    while done < settings.spp && !control.should_stop() {
        let to = (done + batch).min(settings.spp);
        let t0 = std::time::Instant::now();
        for phase in 0..3 {
            run_phase(scene, settings, &mut rows, phase, done, to);
        }
        control.work_done.fetch_add(w as u64 * h as u64 * (to - done) as u64, Ordering::Relaxed);
        let dt = t0.elapsed().as_secs_f64();
        let per_sample = dt / (to - done) as f64;
        done = to;
        control.offer_preview(|| {
            resolve(&rows, w, h, done, settings.alpha_rec, crate::reconstruct::Norm::L2, &|| false).0
        });
        if dt < 0.1 {
            batch = (batch * 2).min(64);
        }
        batch = control.samples_fitting(batch, per_sample);
        if batch == 0 {
            break;
        }
    }
    let (combined, primal_full, dx, dy, direct) =
        resolve(&rows, w, h, done, settings.alpha_rec, control.final_norm(settings.reconstruction), &|| {
            control.is_cancelled()
        });
    let scale = 1.0 / done.max(1) as f64;
    let n = |v: &[f64]| f32_image(w, h, v);
    let albedo = to_image(&rows, |r| &r.albedo, scale);
    let normal = to_image(&rows, |r| &r.normal, scale);
    let mut layers = vec![
        ("Combined".into(), combined),
        ("GD Primal".into(), primal_full),
        ("GD Gradient X".into(), dx),
        ("GD Gradient Y".into(), dy),
        ("Very Direct".into(), direct),
        ("Denoising Albedo".into(), n(&albedo)),
        ("Denoising Normal".into(), n(&normal)),
    ];
    if scene.camera.film_transparent {
        let data = rows.iter().flat_map(|r| r.transparent.iter().map(|t| (1.0 - t * scale) as f32)).collect();
        let alpha = Image { width: w, height: h, channels: 1, data };
        layers[0].1.clear_uncovered(&alpha);
        layers.push(("Alpha".into(), alpha));
    }
    RenderOutput {
        layers,
        stats: RenderStats {
            method: "gdpt",
            elapsed: control.elapsed(),
            spp_min: done,
            spp_max: done,
            invalid_samples: rows.iter().map(|r| r.invalid).sum(),
            ..Default::default()
        },
    }
}
