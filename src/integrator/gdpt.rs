//! Gradient-domain path tracing (Kettunen et al. 2015): every base path is shifted to its
//! four neighbours (shift.rs); the pair contributions give a primal image and forward-
//! difference gradients, reconstructed by screened Poisson (reconstruct/). Light seen
//! directly by the camera goes to a separate very-direct image, added afterwards.
//!
//! Splats reach the rows above and below, so rows are processed in three phases (y mod 3):
//! within a phase the 3-row windows are disjoint, which makes the accumulation lock-free and
//! the image identical for any thread count given the same passes. (Passes grow while they
//! take under 0.1 s, so where a pass crosses that line on one machine and not on another the
//! order of a pixel's additions differs: the images then differ by f32 rounding, ~1e-6.)

use super::{RenderControl, RenderOutput, RenderSettings, RenderStats};
use crate::film::Image;
use crate::math::{is_finite_spectrum, Spectrum};
use crate::path::{trace_path_from, Path, Primary};
use crate::reconstruct::{
    chosen_alpha, gradient_domain_image, gradient_domain_layers, HalfDifference, IrlsParams, Norm, Problem, RowPlanar,
};
use crate::sampler::{Sampler, SobolSampler};
use crate::scene::{CameraRay, Scene};
use crate::shift::shift_from;
use glam::Vec2;
use rayon::prelude::*;
use std::sync::atomic::Ordering;

/// The accumulators of a render, whole images in f32: primal and gradients row-planar (the
/// reconstruction's layout, so they become its problem without a copy), the first-hit sums
/// interleaved RGB (the output's layout), and the even − odd sample halves that measure the
/// reconstruction's α (reconstruct/alpha.rs). About 88 bytes per pixel.
struct GdFilm {
    primal: RowPlanar,
    dx: RowPlanar,
    dy: RowPlanar,
    halves: HalfDifference,
    direct: Vec<f32>,
    albedo: Vec<f32>,
    normal: Vec<f32>,
    /// Sum of the base samples' film transparency.
    transparent: Vec<f32>,
    /// Invalid (non-finite) samples, per base row.
    invalid: Vec<u64>,
}

/// One row's share of every accumulator (row-planar rows: R, G, B of the row in turn).
struct GdRow<'a> {
    primal: &'a mut [f32],
    dx: &'a mut [f32],
    dy: &'a mut [f32],
    /// The row of the half differences of primal, dx, dy (channel means).
    halves: [&'a mut [f32]; 3],
    direct: &'a mut [f32],
    albedo: &'a mut [f32],
    normal: &'a mut [f32],
    transparent: &'a mut [f32],
    invalid: &'a mut u64,
}

impl GdFilm {
    fn new(w: usize, h: usize) -> GdFilm {
        GdFilm {
            primal: RowPlanar::zeros(w, h),
            dx: RowPlanar::zeros(w, h),
            dy: RowPlanar::zeros(w, h),
            halves: HalfDifference::zeros(w, h),
            direct: vec![0.0; 3 * w * h],
            albedo: vec![0.0; 3 * w * h],
            normal: vec![0.0; 3 * w * h],
            transparent: vec![0.0; w * h],
            invalid: vec![0; h],
        }
    }

    fn rows(&mut self) -> Vec<GdRow<'_>> {
        let w = self.primal.width;
        let mut primal = self.primal.data.chunks_mut(3 * w);
        let mut dx = self.dx.data.chunks_mut(3 * w);
        let mut dy = self.dy.data.chunks_mut(3 * w);
        let mut half_p = self.halves.primal.chunks_mut(w);
        let mut half_x = self.halves.dx.chunks_mut(w);
        let mut half_y = self.halves.dy.chunks_mut(w);
        let mut direct = self.direct.chunks_mut(3 * w);
        let mut albedo = self.albedo.chunks_mut(3 * w);
        let mut normal = self.normal.chunks_mut(3 * w);
        let mut transparent = self.transparent.chunks_mut(w);
        self.invalid
            .iter_mut()
            .map(|invalid| GdRow {
                primal: primal.next().expect("one row each"),
                dx: dx.next().expect("one row each"),
                dy: dy.next().expect("one row each"),
                halves: [&mut half_p, &mut half_x, &mut half_y].map(|it| it.next().expect("one row each")),
                direct: direct.next().expect("one row each"),
                albedo: albedo.next().expect("one row each"),
                normal: normal.next().expect("one row each"),
                transparent: transparent.next().expect("one row each"),
                invalid,
            })
            .collect()
    }

    /// The reconstruction's α: the setting, or where it is 0 (automatic) the one the two
    /// sample halves measure.
    fn alpha(&self, setting: f64) -> f64 {
        chosen_alpha(setting, || self.halves.alpha([&self.primal, &self.dx, &self.dy]))
    }

    /// The gradient-domain problem of `spp` samples per pixel, and the very-direct image,
    /// copied (the render goes on).
    fn problem(&self, spp: u32, alpha: f64) -> (Problem, Vec<f32>) {
        let s = 1.0 / spp.max(1) as f32;
        let p = Problem::new(self.alpha(alpha), self.primal.scaled(s), self.dx.scaled(s), self.dy.scaled(s));
        (p, self.direct.par_iter().map(|v| v * s).collect())
    }
}

/// Adds v·s to pixel x of a row-planar row.
#[inline]
fn acc_planar(row: &mut [f32], x: usize, v: Spectrum, s: f32) {
    let w = row.len() / 3;
    row[x] += v.x * s;
    row[w + x] += v.y * s;
    row[2 * w + x] += v.z * s;
}

/// Adds v·s to pixel x of a row-planar row, and its channel mean times `sign` to pixel x of
/// the row's half difference.
#[inline]
fn acc_split(row: &mut [f32], half: &mut [f32], x: usize, v: Spectrum, s: f32, sign: f32) {
    acc_planar(row, x, v, s);
    half[x] += sign * s * (v.x + v.y + v.z) * (1.0 / 3.0);
}

/// Adds v to pixel x of an interleaved RGB row.
#[inline]
fn acc_rgb(row: &mut [f32], x: usize, v: Spectrum) {
    row[3 * x] += v.x;
    row[3 * x + 1] += v.y;
    row[3 * x + 2] += v.z;
}

/// (dx, dy) of the four shifts.
pub const SHIFTS: [(i32, i32); 4] = [(1, 0), (-1, 0), (0, 1), (0, -1)];

/// Camera rays of this many samples of a pixel are traced together, one packet per shift
/// (the base's rays, then each neighbour's): a packet of the eight rays of one direction
/// costs about what one of a sample's five rays did, and five packets serve eight samples.
const PACKET: usize = 8;

/// Renders samples [from, to) of the base pixels of row `y`; `win` holds rows lo..lo+len.
#[allow(clippy::too_many_arguments)]
fn render_row(
    scene: &Scene,
    settings: &RenderSettings,
    y: usize,
    lo: usize,
    win: &mut [GdRow<'_>],
    from: u32,
    to: u32,
) {
    let (w, h) = (scene.camera.width as i32, scene.camera.height as i32);
    let mut path = Path::default();
    let mut samplers: Vec<SobolSampler> = Vec::with_capacity(PACKET);
    let mut lenses = [Vec2::ZERO; PACKET];
    // rays[0] the bases' camera rays, rays[1 + i] their offsets' of SHIFTS[i] (neighbour
    // pixels, the same sub-pixel position and lens sample)
    let mut rays = [[CameraRay::default(); PACKET]; 1 + SHIFTS.len()];
    for x in 0..w as usize {
        for first in (from..to).step_by(PACKET) {
            // 1. the camera rays of up to PACKET samples, and what they hit
            let n = (to - first).min(PACKET as u32) as usize;
            samplers.clear();
            for (k, s) in (first..first + n as u32).enumerate() {
                let mut sampler = super::pt::pixel_sampler(settings.seed, y * w as usize + x, s);
                let raster = scene.camera.pixel_raster(x as f32, y as f32, sampler.next_2d());
                lenses[k] = sampler.next_2d();
                for (shift, (dx, dy)) in rays.iter_mut().zip(std::iter::once((0, 0)).chain(SHIFTS)) {
                    shift[k] = scene.camera.generate_ray(raster + Vec2::new(dx as f32, dy as f32), lenses[k]);
                }
                samplers.push(sampler);
            }
            let hits = rays.map(|r| scene.intersect_camera_rays(&r[..n]));
            // 2. each sample's base path and its four shifts
            for (k, sampler) in samplers.iter_mut().enumerate() {
                let sign = HalfDifference::sign((first + k as u32).into());
                let primary = Primary { lens: lenses[k], ray: rays[0][k], hit: hits[0][k] };
                let c = trace_path_from(scene, &settings.path, primary, sampler, Some(&mut path));
                let me = &mut win[y - lo];
                if !is_finite_spectrum(c.radiance) {
                    *me.invalid += 1;
                    continue;
                }
                acc_rgb(me.direct, x, c.very_direct);
                acc_rgb(me.albedo, x, c.albedo);
                acc_rgb(me.normal, x, c.normal);
                me.transparent[x] += c.transparent;
                for (i, (dx, dy)) in SHIFTS.into_iter().enumerate() {
                    let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                    let inside = nx >= 0 && ny >= 0 && nx < w && ny < h;
                    let pc = shift_from(scene, &path, inside.then(|| (rays[1 + i][k], hits[1 + i][k])));
                    if !is_finite_spectrum(pc.base) || !is_finite_spectrum(pc.offset) {
                        *win[y - lo].invalid += 1;
                        continue;
                    }
                    let me = &mut win[y - lo];
                    acc_split(me.primal, me.halves[0], x, pc.base, 0.25, sign);
                    if !inside {
                        continue;
                    }
                    let (nx, ny) = (nx as usize, ny as usize);
                    // the forward difference at the left or upper pixel of the pair
                    let g = pc.offset - pc.base;
                    let (at, row, side) = if dx + dy > 0 { (x, y, 1.0) } else { (nx, ny, -1.0) };
                    let to = &mut win[row - lo];
                    if dx != 0 {
                        acc_split(to.dx, to.halves[1], at, g, side, sign);
                    } else {
                        acc_split(to.dy, to.halves[2], at, g, side, sign);
                    }
                    let n = &mut win[ny - lo];
                    acc_split(n.primal, n.halves[0], nx, pc.offset, 0.25, sign);
                }
            }
        }
    }
}

/// Runs one phase: base rows y ≡ phase (mod 3), each with its window of rows y−1..=y+1.
fn run_phase(scene: &Scene, settings: &RenderSettings, rows: &mut [GdRow<'_>], phase: usize, from: u32, to: u32) {
    let h = rows.len();
    let mut windows = Vec::new();
    let mut rest: &mut [GdRow<'_>] = rows;
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

pub fn render(scene: &Scene, settings: &RenderSettings, control: &RenderControl) -> RenderOutput {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let mut film = GdFilm::new(w, h);
    control.work_total.store(w as u64 * h as u64 * settings.spp as u64, Ordering::Relaxed);
    let (mut done, mut batch) = (0u32, 1u32);
    // Whole passes only (a pass is short): every pixel always has the same sample count.
    while done < settings.spp && !control.should_stop() {
        let to = (done + batch).min(settings.spp);
        let t0 = std::time::Instant::now();
        let mut rows = film.rows();
        for phase in 0..3 {
            run_phase(scene, settings, &mut rows, phase, done, to);
        }
        drop(rows);
        film.halves.count(done.into(), to.into());
        control.work_done.fetch_add(w as u64 * h as u64 * (to - done) as u64, Ordering::Relaxed);
        let dt = t0.elapsed().as_secs_f64();
        let per_sample = dt / (to - done) as f64;
        done = to;
        control.offer_preview(|| {
            let (p, direct) = film.problem(done, settings.alpha_rec);
            gradient_domain_image(&p, &direct, Norm::L2, &IrlsParams::short(), &|| false)
        });
        if dt < 0.1 {
            batch = (batch * 2).min(64);
        }
        batch = control.samples_fitting(batch, per_sample);
        if batch == 0 {
            break;
        }
    }
    // the accumulators become the layers: scaled in place, the primal and gradients handed to
    // the reconstruction as its problem (nothing is held twice)
    let s = 1.0 / done.max(1) as f32;
    let alpha = film.alpha(settings.alpha_rec);
    let GdFilm { mut primal, mut dx, mut dy, halves, mut direct, mut albedo, mut normal, transparent, invalid } = film;
    drop(halves);
    for v in [&mut primal, &mut dx, &mut dy] {
        v.scale(s);
    }
    for v in [&mut direct, &mut albedo, &mut normal] {
        v.par_iter_mut().for_each(|x| *x *= s);
    }
    let problem = Problem::new(alpha, primal, dx, dy);
    let norm = control.final_norm(settings.reconstruction);
    let mut layers = gradient_domain_layers(problem, direct, norm, &IrlsParams::short(), &|| control.is_cancelled());
    let img = |data: Vec<f32>| Image { width: w, height: h, channels: 3, data };
    layers.push(("Denoising Albedo".into(), img(albedo)));
    layers.push(("Denoising Normal".into(), img(normal)));
    if scene.has_alpha() {
        let data = transparent.iter().map(|t| 1.0 - t * s).collect();
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
            invalid_samples: invalid.iter().sum(),
            alpha_rec: alpha,
            ..Default::default()
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin::cornell_box;

    fn film_of(scene: &Scene, settings: &RenderSettings, passes: &[(u32, u32)]) -> GdFilm {
        let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
        let mut film = GdFilm::new(w, h);
        for &(from, to) in passes {
            let mut rows = film.rows();
            for phase in 0..3 {
                run_phase(scene, settings, &mut rows, phase, from, to);
            }
            drop(rows);
            film.halves.count(from.into(), to.into());
        }
        film
    }

    /// The half differences are the channel means of (even samples − odd samples) of the
    /// primal and both gradients, every splat included (the offsets' to the neighbours too):
    /// four samples taken in passes of 1, 2 and 1 against the four one-sample films.
    #[test]
    fn halves_are_the_even_minus_odd_samples() {
        let scene = Scene::build(&cornell_box(12, 10)).unwrap();
        let settings = RenderSettings { method: super::super::Method::Gdpt, seed: 3, ..Default::default() };
        let film = film_of(&scene, &settings, &[(0, 1), (1, 3), (3, 4)]);
        assert_eq!(film.halves.counts, [2, 2]);
        let one: Vec<GdFilm> = (0..4).map(|s| film_of(&scene, &settings, &[(s, s + 1)])).collect();
        let planes = |f: &GdFilm| [f.primal.data.clone(), f.dx.data.clone(), f.dy.data.clone()];
        let (w, h) = (12, 10);
        let mut nonzero = 0;
        for (k, half) in [&film.halves.primal, &film.halves.dx, &film.halves.dy].into_iter().enumerate() {
            for y in 0..h {
                for x in 0..w {
                    let mean = |f: &GdFilm| (0..3).map(|c| planes(f)[k][(3 * y + c) * w + x]).sum::<f32>() / 3.0;
                    let expected = mean(&one[0]) - mean(&one[1]) + mean(&one[2]) - mean(&one[3]);
                    let got = half[y * w + x];
                    let scale = one.iter().map(|f| mean(f).abs()).sum::<f32>();
                    assert!((got - expected).abs() <= 1e-5 * scale + 1e-7, "layer {k} ({x}, {y}): {got} vs {expected}");
                    nonzero += usize::from(expected.abs() > 1e-4);
                }
            }
        }
        assert!(nonzero > w * h, "the test sees noise in the halves ({nonzero} pixels)");
        // and the α they give is used where the setting is automatic, the setting otherwise
        let measured = film.halves.alpha([&film.primal, &film.dx, &film.dy]).unwrap();
        assert_eq!(film.alpha(0.0), measured);
        assert_eq!(film.alpha(0.7), 0.7);
    }
}
