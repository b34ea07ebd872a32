//! Metropolis light transport in primary sample space (Kelemen et al. 2002), and its
//! gradient-domain variant (Lehtinen et al. 2013 with Kettunen's shift mapping, as in the
//! seed paper): one driver, two targets.
//!
//! * `pssmlt`: state u; target F = luminance of the path's radiance; splat L at its pixel.
//! * `gdpssmlt`: state (u, d), d ∈ {+x, −x, +y, −y}; target
//!   F = ℓ(|G_d|) + (α/4)·ℓ(|L|) (docs/algorithm.md §3, ℓ of per-channel absolute values);
//!   splats: primal C_x (base pixel) and C_y (neighbour), gradient ±4·G_d; then screened
//!   Poisson reconstruction and the very-direct image (plain Monte Carlo) on top.
//!
//! Bootstrap: independent states estimate b = E[F] and give chain starts ∝ F; every large
//! step of every chain is one more independent state, so b is refined with them as the
//! render goes (Kelemen et al. 2002): its error shrinks with the mutations, not only with
//! the bootstrap's size. Expected-value splatting: proposed × a/F_p, current × (1−a)/F_c;
//! image × b/mpp.
//!
//! Parallelism and memory: chains run in rounds of `ROUND` mutations, all chains in parallel
//! (so every core is busy); each records its splats in its own log, sorted into
//! `MERGE_BANDS` bands of the image as they are made, and after the round the logs are added
//! to the one image, band by band in parallel, chain by chain in order. The image therefore
//! depends only on the seed (not on the thread count, unless a time limit stops chains
//! early), and memory is one image plus logs whose size is bounded by chains × `ROUND`,
//! whatever the image size or thread count.

use super::{ChainStart, RenderControl, RenderOutput, RenderSettings, RenderStats};
use crate::distribution::Distribution1D;
use crate::film::Image;
use crate::math::{abs_luminance, is_finite_spectrum, Spectrum};
use crate::path::{camera_transparency, first_hit, trace_path, Path};
use crate::reconstruct::{gradient_domain_image, Norm};
use crate::sampler::{mix64, IndependentSampler, PssSampler, Sampler};
use crate::scene::{CameraRay, Scene};
use crate::shift::shift;
use glam::Vec2;
use rayon::prelude::*;
use std::sync::atomic::Ordering;

/// Independent states drawn to estimate the normalisation and choose chain starts: 16 per
/// pixel, within these bounds (the large steps refine b afterwards, so a small image with
/// few mutations does not pay for a large bootstrap, and a large one gets enough starts).
pub const BOOTSTRAP_SAMPLES: (usize, usize) = (16_384, 1 << 20);

fn bootstrap_samples(w: usize, h: usize) -> usize {
    (16 * w * h).clamp(BOOTSTRAP_SAMPLES.0, BOOTSTRAP_SAMPLES.1)
}
/// Probability that a small step also redraws the shift direction d (its own symmetric
/// mutation: a Gaussian step of the other coordinates never changes d).
pub const DIRECTION_MUTATION_PROBABILITY: f32 = 0.1;
/// Bands a chain's splats are sorted into, for the parallel merge after each round.
const MERGE_BANDS: usize = 64;
/// Samples per pixel of the very-direct image of gdpssmlt (and of the denoising passes of
/// both Metropolis methods): 16 before the chains run, then topped up between rounds to a
/// quarter of the mutations per pixel done (whenever that doubles it), up to the maximum, so
/// that it converges with the budget like the rest of the image.
const VERY_DIRECT_SPP: (u32, u32) = (16, 4096);

const SHIFTS: [(i32, i32); 4] = [(1, 0), (-1, 0), (0, 1), (0, -1)];
const PRIMAL: usize = 0;
const DX: usize = 1;
const DY: usize = 2;
/// The log entry of a mutation's current state (the density image).
const DENSITY: usize = 3;

/// What one state contributes, before the 1/F weighting.
#[derive(Clone, Copy, Default)]
struct Splats {
    n: usize,
    items: [(usize, usize, Spectrum); 4], // (layer, pixel, value)
    pixel: usize,
}

impl Splats {
    fn push(&mut self, layer: usize, pixel: usize, v: Spectrum) {
        self.items[self.n] = (layer, pixel, v);
        self.n += 1;
    }
}

/// A base path evaluated at one primary-sample vector; `f(d)` and `splats(d)` per direction.
struct Evaluated {
    splats: [Splats; 4],
    f: [f32; 4],
}

struct Target<'a> {
    scene: &'a Scene,
    settings: &'a RenderSettings,
    gradient: bool,
    w: usize,
    h: usize,
}

impl Target<'_> {
    /// Evaluates the state; for the gradient target only direction `only` (all four if None).
    fn evaluate<S: Sampler>(&self, sampler: &mut S, path: &mut Path, only: Option<usize>) -> Evaluated {
        // The primary sample is the raster position itself (a box pixel filter). The
        // Metropolis methods do not take the scene's pixel filter: mapping the fraction inside
        // the pixel through it (as pt does) measured gdpssmlt's naive image 3% ± 1.5% darker
        // on the smooth room (8 seeds), which is not understood yet (docs/limits.md).
        let u = sampler.next_2d();
        let raster = Vec2::new(u.x * self.w as f32, u.y * self.h as f32);
        let (px, py) = ((raster.x as usize).min(self.w - 1), (raster.y as usize).min(self.h - 1));
        let pixel = py * self.w + px;
        let c = trace_path(self.scene, &self.settings.path, raster, sampler, Some(path));
        let mut ev = Evaluated { splats: [Splats::default(); 4], f: [0.0; 4] };
        if !is_finite_spectrum(c.radiance) {
            return ev;
        }
        if !self.gradient {
            let f = abs_luminance(c.radiance);
            for k in 0..4 {
                ev.f[k] = f;
                ev.splats[k].pixel = pixel;
                ev.splats[k].push(PRIMAL, pixel, c.radiance);
            }
            return ev;
        }
        let l = c.radiance - c.very_direct;
        for (k, (dx, dy)) in SHIFTS.iter().enumerate() {
            if only.is_some_and(|o| o != k) {
                continue;
            }
            let (nx, ny) = (px as i32 + dx, py as i32 + dy);
            let inside = nx >= 0 && ny >= 0 && nx < self.w as i32 && ny < self.h as i32;
            let pc = shift(self.scene, path, inside.then(|| raster + Vec2::new(*dx as f32, *dy as f32)));
            if !is_finite_spectrum(pc.base) || !is_finite_spectrum(pc.offset) {
                continue;
            }
            let g = pc.offset - pc.base;
            ev.f[k] = abs_luminance(g) + 0.25 * self.settings.alpha_target * abs_luminance(l);
            let s = &mut ev.splats[k];
            s.pixel = pixel;
            s.push(PRIMAL, pixel, pc.base);
            if inside {
                let n = ny as usize * self.w + nx as usize;
                s.push(PRIMAL, n, pc.offset);
                // each direction has measure 1/4: gradients × 4 (docs/algorithm.md §4b)
                match (dx, dy) {
                    (1, 0) => s.push(DX, pixel, g * 4.0),
                    (-1, 0) => s.push(DX, n, g * -4.0),
                    (0, 1) => s.push(DY, pixel, g * 4.0),
                    _ => s.push(DY, n, g * -4.0),
                }
            }
        }
        ev
    }
}

/// Mutations a chain runs per round (between merges, previews and stop checks).
const ROUND: u64 = 256;

/// One splat as a chain records it: `at` = pixel · 4 + layer (`DENSITY` counts a visit).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Splat {
    at: u64,
    v: [f32; 3],
}

/// What a chain records in one round: its splats (sorted by merge band once the round is
/// over), and its tallies. Both buffers are reserved for a full round when the chain is made,
/// so recording allocates nothing.
struct Log {
    raw: Vec<Splat>,
    sorted: Vec<Splat>,
    /// `sorted[offsets[b]..offsets[b + 1]]` are band b's splats.
    offsets: [usize; MERGE_BANDS + 1],
    /// Pixels per merge band.
    band_pixels: u64,
    mutations: u64,
    accepted: u64,
    /// Sum of F over the large-step proposals, and their number.
    large_f: f64,
    large_steps: u64,
}

impl Log {
    /// Splats one mutation records at most: proposal and current state (three each for
    /// gdpssmlt: base, offset, gradient; one for pssmlt) and a visit.
    fn max_splats_per_mutation(gradient: bool) -> usize {
        if gradient {
            7
        } else {
            3
        }
    }

    fn new(pixels: usize, gradient: bool) -> Log {
        let cap = ROUND as usize * Log::max_splats_per_mutation(gradient);
        Log {
            raw: Vec::with_capacity(cap),
            sorted: Vec::with_capacity(cap),
            offsets: [0; MERGE_BANDS + 1],
            band_pixels: (pixels as u64).div_ceil(MERGE_BANDS as u64).max(1),
            mutations: 0,
            accepted: 0,
            large_f: 0.0,
            large_steps: 0,
        }
    }

    fn clear(&mut self) {
        self.raw.clear();
        self.sorted.clear();
        self.offsets = [0; MERGE_BANDS + 1];
        (self.mutations, self.accepted, self.large_f, self.large_steps) = (0, 0, 0.0, 0);
    }

    fn band(&self, s: &Splat) -> usize {
        (s.at / 4 / self.band_pixels) as usize
    }

    #[inline]
    fn push(&mut self, layer: usize, pixel: usize, v: [f32; 3]) {
        self.raw.push(Splat { at: pixel as u64 * 4 + layer as u64, v });
    }

    /// Records the splats of a state with weight `weight` (skipped when not positive/finite).
    fn splat(&mut self, s: &Splats, weight: f64) {
        if weight <= 0.0 || !weight.is_finite() {
            return;
        }
        for &(layer, pixel, v) in &s.items[..s.n] {
            let v = [(v.x as f64 * weight) as f32, (v.y as f64 * weight) as f32, (v.z as f64 * weight) as f32];
            self.push(layer, pixel, v);
        }
    }

    /// Sorts the round's splats by band (a stable counting sort: each band keeps the order
    /// the splats were made in).
    fn sort_by_band(&mut self) {
        let mut counts = [0usize; MERGE_BANDS + 1];
        for s in &self.raw {
            counts[self.band(s) + 1] += 1;
        }
        for b in 0..MERGE_BANDS {
            counts[b + 1] += counts[b];
        }
        self.offsets = counts;
        self.sorted.clear();
        self.sorted.resize(self.raw.len(), Splat { at: 0, v: [0.0; 3] });
        for s in &self.raw {
            let b = self.band(s);
            self.sorted[counts[b]] = *s;
            counts[b] += 1;
        }
    }

    fn band_splats(&self, b: usize) -> &[Splat] {
        &self.sorted[self.offsets[b]..self.offsets[b + 1]]
    }
}

struct Chain {
    s: PssSampler,
    cur: Evaluated,
    d: usize,
    remaining: u64,
    path: Path,
    log: Log,
}

/// One Metropolis–Hastings step with expected-value splatting (docs/algorithm.md §2).
fn mutate(target: &Target, c: &mut Chain, gradient: bool) {
    c.s.start_iteration();
    let d_new = if !gradient {
        c.d
    } else if c.s.is_large_step() || c.s.rng().next_1d() < DIRECTION_MUTATION_PROBABILITY {
        ((c.s.rng().next_1d() * 4.0) as usize).min(3)
    } else {
        c.d
    };
    let prop = target.evaluate(&mut c.s, &mut c.path, Some(d_new));
    let (fc, fp) = (c.cur.f[c.d], prop.f[d_new]);
    let a = if fc > 0.0 { (fp / fc).min(1.0) } else { 1.0 };
    if fp > 0.0 {
        c.log.splat(&prop.splats[d_new], a as f64 / fp as f64);
    }
    if c.s.is_large_step() {
        // an independent uniform state (u, d): one more sample of b = E[F]
        c.log.large_f += fp as f64;
        c.log.large_steps += 1;
    }
    if fc > 0.0 {
        c.log.splat(&c.cur.splats[c.d], (1.0 - a) as f64 / fc as f64);
    }
    if c.s.rng().next_1d() < a {
        c.s.accept();
        c.cur = prop;
        c.d = d_new;
        c.log.accepted += 1;
    } else {
        c.s.reject();
    }
    c.log.push(DENSITY, c.cur.splats[c.d].pixel, [0.0; 3]);
    c.log.mutations += 1;
}

/// One merge band of the image: its slice of every layer and of the density.
type BandMut<'a> = (Vec<&'a mut [[f64; 3]]>, &'a mut [u32]);

/// The image so far: the splat sums of each layer (primal; and dx, dy for gdpssmlt), the
/// chains' visits per pixel, and the tallies.
struct Accum {
    layers: Vec<Vec<[f64; 3]>>,
    density: Vec<u32>,
    mutations: u64,
    accepted: u64,
    large_f: f64,
    large_steps: u64,
}

impl Accum {
    fn new(pixels: usize, gradient: bool) -> Accum {
        let n_layers = if gradient { 3 } else { 1 };
        Accum {
            layers: (0..n_layers).map(|_| vec![[0.0; 3]; pixels]).collect(),
            density: vec![0; pixels],
            mutations: 0,
            accepted: 0,
            large_f: 0.0,
            large_steps: 0,
        }
    }

    /// Adds the chains' logs of a round: band by band in parallel, chain by chain in order
    /// within a band (so every pixel sums its splats in the same order on any thread count).
    fn merge(&mut self, chains: &[Chain]) {
        let Some(first) = chains.first() else { return };
        let bp = first.log.band_pixels as usize;
        let mut layer_bands: Vec<std::slice::ChunksMut<'_, [f64; 3]>> =
            self.layers.iter_mut().map(|l| l.chunks_mut(bp)).collect();
        let bands: Vec<BandMut> = self
            .density
            .chunks_mut(bp)
            .map(|d| (layer_bands.iter_mut().map(|it| it.next().expect("same band count")).collect(), d))
            .collect();
        bands.into_par_iter().enumerate().for_each(|(b, (mut layers, density))| {
            let base = b * bp;
            for c in chains {
                for s in c.log.band_splats(b) {
                    let (pixel, layer) = ((s.at / 4) as usize - base, (s.at % 4) as usize);
                    if layer == DENSITY {
                        density[pixel] += 1;
                    } else {
                        let a = &mut layers[layer][pixel];
                        a[0] += s.v[0] as f64;
                        a[1] += s.v[1] as f64;
                        a[2] += s.v[2] as f64;
                    }
                }
            }
        });
        for c in chains {
            self.mutations += c.log.mutations;
            self.accepted += c.log.accepted;
            self.large_f += c.log.large_f;
            self.large_steps += c.log.large_steps;
        }
    }

    /// b = E[F] from the bootstrap's F sum and every large step so far.
    fn normalisation(&self, boot_sum: f64, n_boot: usize) -> f64 {
        (boot_sum + self.large_f) / (n_boot as u64 + self.large_steps) as f64
    }
}

pub fn render(scene: &Scene, settings: &RenderSettings, control: &RenderControl, gradient: bool) -> RenderOutput {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let target = Target { scene, settings, gradient, w, h };
    let p_large = settings.large_step_probability;
    let boot_seed = mix64(settings.seed ^ 0xB007);

    // Bootstrap (parallel, deterministic): F averaged over the four directions.
    let n_boot = bootstrap_samples(w, h);
    let boot: Vec<(f32, [f32; 4])> = (0..n_boot)
        .into_par_iter()
        .map_init(
            || (Path::default(), PssSampler::new(boot_seed, 0, p_large)),
            |(path, s), i| {
                if control.is_cancelled() {
                    return (0.0, [0.0; 4]); // Esc during the bootstrap: finish at once
                }
                s.restart(boot_seed, i as u64);
                s.start_iteration();
                let ev = target.evaluate(s, path, None);
                (ev.f.iter().sum::<f32>() * 0.25, ev.f)
            },
        )
        .collect();
    let boot_sum: f64 = boot.iter().map(|(f, _)| *f as f64).sum::<f64>();
    let starts = Distribution1D::new(&boot.iter().map(|(f, _)| *f).collect::<Vec<_>>());

    let total = settings.spp as u64 * (w * h) as u64;
    let n_chains = match settings.chains {
        0 => (total / 2000).clamp(1, 1024) as usize,
        n => (n as u64).min(total.max(1)) as usize,
    };
    let dimmest =
        boot.iter().enumerate().filter(|(_, (f, _))| *f > 0.0).min_by(|a, b| a.1 .0.total_cmp(&b.1 .0)).map(|(i, _)| i);
    control.work_total.store(total, Ordering::Relaxed);
    let chain_seed = mix64(settings.seed ^ 0xC4A1);

    // Very-direct light of gdpssmlt by plain Monte Carlo (first, so previews include it; then
    // topped up as the chains advance), and the denoising albedo and normal of every
    // Metropolis render.
    let mut first = FirstHits::new(w, h, settings.path.transparent_bounces);
    first.add(scene, settings.seed, VERY_DIRECT_SPP.0, control);
    let mut direct = first.very_direct(gradient);

    // Every chain starts from a bootstrap state (replayed; direction ∝ F) ...
    let mut chains: Vec<Chain> = (0..n_chains)
        .into_par_iter()
        .filter_map(|chain| {
            let mutations = total / n_chains as u64 + u64::from((chain as u64) < total % n_chains as u64);
            let mut pick = IndependentSampler::new(chain_seed, chain as u64);
            let (start, _) = starts.sample(pick.next_1d())?;
            let start = match settings.chain_start {
                ChainStart::Proportional => start,
                ChainStart::Dimmest => dimmest?,
            };
            let mut s = PssSampler::new(boot_seed, start as u64, p_large);
            let mut path = Path::default();
            s.start_iteration();
            let cur = target.evaluate(&mut s, &mut path, None);
            s.accept();
            // its own proposal stream (two chains may start from the same bootstrap state)
            s.reseed(chain_seed ^ 0x5EED, chain as u64);
            let fsum: f32 = cur.f.iter().sum();
            let (mut d, mut acc) = (0, pick.next_1d() * fsum);
            while d < 3 && acc >= cur.f[d] {
                acc -= cur.f[d];
                d += 1;
            }
            Some(Chain { s, cur, d, remaining: mutations, path, log: Log::new(w * h, gradient) })
        })
        .collect();
    let mut image = Accum::new(w * h, gradient);
    // ... and all chains advance in rounds of ROUND mutations, so that a time limit or Esc
    // stops them at about the same length, and intermediate images can be taken in between.
    while !control.should_stop() && chains.iter().any(|c| c.remaining > 0) {
        chains.par_iter_mut().with_max_len(1).for_each(|c| {
            c.log.clear();
            if control.should_stop() {
                return;
            }
            let n = c.remaining.min(ROUND);
            for _ in 0..n {
                mutate(&target, c, gradient);
            }
            c.log.sort_by_band();
            c.remaining -= n;
            control.work_done.fetch_add(n, Ordering::Relaxed);
        });
        image.merge(&chains);
        let target = very_direct_target(image.mutations, w * h);
        if target >= 2 * first.spp {
            first.add(scene, settings.seed, target, control);
            direct = first.very_direct(gradient);
        }
        control.offer_preview(|| {
            let b = image.normalisation(boot_sum, n_boot);
            resolve(&image, b, w, h, gradient, &direct, settings.alpha_rec, Norm::L2, &|| false).remove(0).1
        });
    }
    drop(chains);
    let (mutations, accepted) = (image.mutations, image.accepted);
    let mpp = mutations as f64 / (w * h) as f64;
    let mut stats = RenderStats {
        method: if gradient { "gdpssmlt" } else { "pssmlt" },
        spp_min: mpp as u32,
        spp_max: mpp.ceil() as u32,
        ..Default::default()
    };
    stats.acceptance = accepted as f64 / mutations.max(1) as f64;
    let b = image.normalisation(boot_sum, n_boot);
    stats.normalization = b;
    stats.chains = n_chains;
    if starts.is_empty() {
        stats.warnings.push("no light reaches the camera in the bootstrap: the image is black".into());
    }
    first.add(scene, settings.seed, very_direct_target(mutations, w * h), control);
    let direct = first.very_direct(gradient);
    let [albedo, normal] = [1, 2].map(|k| first.mean(k));
    let norm = control.final_norm(settings.reconstruction);
    let mut layers = resolve(&image, b, w, h, gradient, &direct, settings.alpha_rec, norm, &|| control.is_cancelled());
    let img = |v: Vec<f64>| Image { width: w, height: h, channels: 3, data: v.into_iter().map(|x| x as f32).collect() };
    layers.push(("Denoising Albedo".into(), img(albedo)));
    layers.push(("Denoising Normal".into(), img(normal)));
    if let Some(alpha) = first.alpha() {
        // alpha comes from the first-hit pass, the colour from the chains: where the pass saw
        // only the world, the colour is made 0 too (a sliver of geometry the chains found in
        // such a pixel is lost: a bias confined to silhouettes, shrinking as the pass's
        // samples grow with the mutations)
        layers[0].1.clear_uncovered(&alpha);
        layers.push(("Alpha".into(), alpha));
    }
    stats.elapsed = control.elapsed();
    RenderOutput { layers, stats }
}

/// Samples per pixel of the first-hit images after `mutations` mutations over `pixels`.
fn very_direct_target(mutations: u64, pixels: usize) -> u32 {
    (mutations / (4 * pixels.max(1) as u64)).clamp(VERY_DIRECT_SPP.0 as u64, VERY_DIRECT_SPP.1 as u64) as u32
}

/// Camera-visible emission, first-surface albedo and normal by plain Monte Carlo, jittered
/// samples per pixel accumulated progressively: sums of [very direct, albedo, normal], RGB;
/// and, with a transparent film, of the camera rays' transparency (alpha = 1 − its mean).
struct FirstHits {
    sums: [Vec<f64>; 3],
    transparent: Vec<f64>,
    /// Transparent surfaces a camera ray may cross (PathSettings::transparent_bounces).
    crossings: u32,
    spp: u32,
    w: usize,
    h: usize,
}

impl FirstHits {
    fn new(w: usize, h: usize, crossings: u32) -> FirstHits {
        FirstHits {
            sums: std::array::from_fn(|_| vec![0.0; w * h * 3]),
            transparent: Vec::new(),
            crossings,
            spp: 0,
            w,
            h,
        }
    }

    /// Adds samples up to `target` per pixel, eight at a time (each pixel's eight traced as
    /// one packet); stops early when the render must stop, once it has the minimum.
    fn add(&mut self, scene: &Scene, seed: u64, target: u32, control: &RenderControl) {
        let (w, h) = (self.w, self.h);
        while self.spp < target {
            if self.spp >= VERY_DIRECT_SPP.0 && control.should_stop() {
                break;
            }
            let (from, n) = (self.spp, (target - self.spp).min(8));
            let (film_transparent, crossings) = (scene.camera.film_transparent, self.crossings);
            let per_pixel: Vec<([Spectrum; 3], f32)> = (0..h)
                .into_par_iter()
                .flat_map_iter(|y| {
                    (0..w).map(move |x| {
                        let mut acc = [Spectrum::ZERO; 3];
                        let mut transparent = 0.0f32;
                        let mut rays = [CameraRay::default(); 8];
                        for (k, ray) in rays.iter_mut().enumerate().take(n as usize) {
                            let mut smp = super::pt::pixel_sampler(seed ^ 0xD1, y * w + x, from + k as u32);
                            let raster = Vec2::new(x as f32, y as f32) + smp.next_2d(); // box, as the chains
                            *ray = scene.camera.generate_ray(raster, smp.next_2d());
                        }
                        let hits = scene.intersect_camera_rays(&rays[..n as usize]);
                        for (ray, hit) in rays.iter().zip(hits).take(n as usize) {
                            let f = first_hit(scene, ray, hit);
                            acc[0] += f.very_direct;
                            acc[1] += f.albedo;
                            acc[2] += f.normal;
                            if film_transparent {
                                transparent += camera_transparency(scene, ray, hit, crossings);
                            }
                        }
                        (acc, transparent)
                    })
                })
                .collect();
            for (k, sum) in self.sums.iter_mut().enumerate() {
                for (i, (p, _)) in per_pixel.iter().enumerate() {
                    sum[3 * i] += p[k].x as f64;
                    sum[3 * i + 1] += p[k].y as f64;
                    sum[3 * i + 2] += p[k].z as f64;
                }
            }
            if film_transparent {
                self.transparent.resize(w * h, 0.0);
                for (t, (_, v)) in self.transparent.iter_mut().zip(&per_pixel) {
                    *t += *v as f64;
                }
            }
            self.spp += n;
        }
    }

    /// The mean of image `k` (0 very direct, 1 albedo, 2 normal).
    fn mean(&self, k: usize) -> Vec<f64> {
        let n = self.spp.max(1) as f64;
        self.sums[k].iter().map(|v| v / n).collect()
    }

    /// The alpha layer of a transparent film (one channel), None otherwise.
    fn alpha(&self) -> Option<Image> {
        let n = self.spp.max(1) as f64;
        let data = self.transparent.iter().map(|t| (1.0 - t / n) as f32).collect::<Vec<_>>();
        (!data.is_empty()).then_some(Image { width: self.w, height: self.h, channels: 1, data })
    }

    /// The very-direct image gdpssmlt adds after reconstruction; zero for pssmlt, whose
    /// chains carry that light themselves.
    fn very_direct(&self, gradient: bool) -> Vec<f64> {
        if gradient {
            self.mean(0)
        } else {
            vec![0.0; self.w * self.h * 3]
        }
    }
}

/// The output layers from the image so far: splats × b/mpp; for gdpssmlt the screened
/// Poisson reconstruction plus the very-direct image.
#[allow(clippy::too_many_arguments)]
fn resolve(
    image: &Accum,
    b: f64,
    w: usize,
    h: usize,
    gradient: bool,
    direct: &[f64],
    alpha_rec: f64,
    norm: Norm,
    stop: &(dyn Fn() -> bool + Sync),
) -> Vec<(String, Image)> {
    let mpp = image.mutations as f64 / (w * h) as f64;
    let scale = if mpp > 0.0 { b / mpp } else { 0.0 };
    let sum_layer =
        |l: usize| -> Vec<f64> { image.layers[l].par_iter().flat_map_iter(|v| v.map(|x| x * scale)).collect() };
    let primal = sum_layer(PRIMAL);
    let dmean = image.density.iter().map(|&d| d as f64).sum::<f64>() / (w * h) as f64;
    let density_img: Vec<f64> = image.density.iter().flat_map(|&v| [v as f64 / dmean.max(1e-300); 3]).collect();
    let img = |v: &[f64]| Image { width: w, height: h, channels: 3, data: v.iter().map(|&x| x as f32).collect() };
    if !gradient {
        return vec![("Combined".into(), img(&primal)), ("MLT Density".into(), img(&density_img))];
    }
    let dx = sum_layer(DX);
    let dy = sum_layer(DY);
    let (combined, primal_full) = gradient_domain_image(w, h, &primal, &dx, &dy, direct, alpha_rec, norm, stop);
    vec![
        ("Combined".into(), img(&combined)),
        ("GD Primal".into(), img(&primal_full)),
        ("GD Gradient X".into(), img(&dx)),
        ("GD Gradient Y".into(), img(&dy)),
        ("Very Direct".into(), img(direct)),
        ("MLT Density".into(), img(&density_img)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::path::first_hit;

    /// The first-hit pass, tracing each pixel's camera rays in packets of eight and topped up
    /// in two passes, gives every pixel the mean of the samples that single rays give it.
    #[test]
    fn packet_first_hit_pass_matches_single_rays() {
        let scene = Scene::build(&crate::scene::builtin::cornell_spheres(9, 7)).unwrap();
        let settings = RenderSettings { seed: 3, ..Default::default() };
        let (w, h) = (9, 7);
        let mut first = FirstHits::new(w, h, settings.path.transparent_bounces);
        first.add(&scene, settings.seed, 5, &RenderControl::new(0.0)); // a first pass of 5,
        first.add(&scene, settings.seed, 21, &RenderControl::new(0.0)); // topped up to 21
        let spp = first.spp;
        assert_eq!(spp, 21);
        let [direct, albedo, normal] = [0, 1, 2].map(|k| first.mean(k));
        for y in 0..h {
            for x in 0..w {
                let mut acc = [Spectrum::ZERO; 3];
                for s in 0..spp {
                    let mut smp = super::super::pt::pixel_sampler(settings.seed ^ 0xD1, y * w + x, s);
                    let raster = Vec2::new(x as f32, y as f32) + smp.next_2d(); // box, as the chains
                    let ray = scene.camera.generate_ray(raster, smp.next_2d());
                    let f = first_hit(&scene, &ray, scene.intersect(ray.origin, ray.dir, ray.tmin, ray.tmax));
                    acc[0] += f.very_direct;
                    acc[1] += f.albedo;
                    acc[2] += f.normal;
                }
                let i = 3 * (y * w + x);
                for (img, a) in [&direct, &albedo, &normal].iter().zip(acc) {
                    let a = a / spp as f32;
                    for c in 0..3 {
                        let v = img[i + c];
                        assert!((v - a[c] as f64).abs() <= 1e-6 * v.abs().max(1.0), "pixel ({x}, {y})");
                    }
                }
            }
        }
        assert!(albedo.iter().any(|&v| v > 0.0) && direct.iter().any(|&v| v > 0.0));
    }
}
