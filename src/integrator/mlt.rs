//! Metropolis light transport in primary sample space (Kelemen et al. 2002), and its
//! gradient-domain variant (Lehtinen et al. 2013 with Kettunen's shift mapping, as in the
//! seed paper): one driver, two targets.
//!
//! * `pssmlt`: state u; target F = luminance of the path's radiance; splat L at its pixel.
//! * `gdpssmlt`: state (u, d), d ∈ {+x, −x, +y, −y}; target
//!   F = ℓ(|G_d|) + (α/4)·ℓ(|L|) (docs/algorithm.md §3, ℓ of per-channel absolute values);
//!   splats: primal C_x (base pixel) and C_y (neighbour), gradient ±4·G_d; then screened
//!   Poisson reconstruction.
//!
//! Direct light (camera-visible emission and light after one scattering) is not the chains'
//! work where plain Monte Carlo renders it well: a direct pass renders it and adds it on top
//! (`FirstHits`); where it is hard (its measured relative variance above
//! `DIRECT_APART_MAX_RELATIVE_VARIANCE`) the chains render all but camera-seen emission.
//!
//! Bootstrap: independent states estimate b = E[F] and give chain starts ∝ F; every large
//! step of every chain is one more independent state, so b is refined with them as the
//! render goes (Kelemen et al. 2002): its error shrinks with the mutations, not only with
//! the bootstrap's size. Expected-value splatting: proposed × a/F_p, current × (1−a)/F_c;
//! image × b/mpp.
//!
//! Parallelism and memory: chains run in rounds of `ROUND` mutations, in batches of
//! `CHAIN_BATCH` (or 4 per thread) chains in parallel (so every core is busy); each records
//! its splats in a log, sorted into `MERGE_BANDS` bands of the image as they are made, and
//! after the batch the logs are added to the one image, band by band in parallel, chain by
//! chain in order. The image therefore depends only on the seed (not on the thread count,
//! unless a time limit stops chains early), and memory is one f32 image plus logs bounded by
//! the batch × `ROUND`, whatever the image size or the number of chains.

use super::{ChainStart, RenderControl, RenderOutput, RenderSettings, RenderStats};
use crate::film::Image;
use crate::math::{abs_luminance, is_finite_spectrum, Spectrum};
use crate::path::{camera_transparency, first_hit, trace_path, trace_path_from, Path, PathSettings, Primary};
use crate::reconstruct::{
    chosen_alpha, gradient_domain_image, gradient_domain_layers, HalfDifference, IrlsParams, Norm, Problem, RowPlanar,
};
use crate::sampler::{mix64, IndependentSampler, PssSampler, Sampler};
use crate::scene::{CameraRay, Scene};
use crate::shift::{shift, shift_indirect};
use glam::Vec2;
use rayon::prelude::*;
use std::sync::atomic::Ordering;

/// Independent states drawn to estimate the normalisation and choose chain starts: 16 per
/// pixel, within these bounds (the large steps refine b afterwards, so a small image with
/// few mutations does not pay for a large bootstrap, and a large one gets enough starts).
pub const BOOTSTRAP_SAMPLES: (usize, usize) = (16_384, 1 << 20);

/// The bootstrap's size for a w × h image: 16 per pixel, within `BOOTSTRAP_SAMPLES`.
pub fn bootstrap_samples(w: usize, h: usize) -> usize {
    (16 * w * h).clamp(BOOTSTRAP_SAMPLES.0, BOOTSTRAP_SAMPLES.1)
}
/// The bootstrap's states, by F: chain starts are drawn ∝ F. 4 bytes a state (F, and f64
/// sums of blocks of `Bootstrap::BLOCK` states: an exact f64 CDF without storing one).
struct Bootstrap {
    f: Vec<f32>,
    /// Running sums of F up to the end of each block.
    block_ends: Vec<f64>,
    total: f64,
}

impl Bootstrap {
    const BLOCK: usize = 1024;

    /// F of each state (a non-finite or negative F counts as 0).
    fn new(mut f: Vec<f32>) -> Bootstrap {
        f.iter_mut().filter(|v| !(v.is_finite() && **v > 0.0)).for_each(|v| *v = 0.0);
        let mut acc = 0.0f64;
        let block_ends = f.chunks(Self::BLOCK).map(|b| {
            acc += b.iter().map(|&v| v as f64).sum::<f64>();
            acc
        });
        let block_ends: Vec<f64> = block_ends.collect();
        Bootstrap { total: block_ends.last().copied().unwrap_or(0.0), f, block_ends }
    }

    /// The state i with Σ_{j<i} F_j ≤ u·ΣF < Σ_{j≤i} F_j (a state of F > 0), None if all F are 0.
    fn sample(&self, u: f64) -> Option<usize> {
        if self.total <= 0.0 {
            return None;
        }
        let t = u.clamp(0.0, 1.0) * self.total;
        let b = self.block_ends.partition_point(|&e| e <= t).min(self.block_ends.len() - 1);
        let mut acc = if b == 0 { 0.0 } else { self.block_ends[b - 1] };
        let block = &self.f[b * Self::BLOCK..((b + 1) * Self::BLOCK).min(self.f.len())];
        let mut last = None;
        for (k, &v) in block.iter().enumerate() {
            if v > 0.0 {
                last = Some(b * Self::BLOCK + k);
                acc += v as f64;
                if t < acc {
                    return last;
                }
            }
        }
        // rounding at the block's end (t within an ulp of its sum): its last state of F > 0,
        // or, for an empty block there, the last state of F > 0 before it
        last.or_else(|| self.f[..b * Self::BLOCK].iter().rposition(|&v| v > 0.0))
    }
}

/// Probability that a small step also redraws the shift direction d (its own symmetric
/// mutation: a Gaussian step of the other coordinates never changes d). 0.5, measured
/// against 0.1 and 0.3 (gdpssmlt, 16 mutations per pixel, 128², 6 seeds, ÷ 0.1, relMSE /
/// block error): gap 0.86 / 0.89, door ajar 0.88 / 0.95, glass box 0.85 / 0.78, multi-light
/// 0.95 / 0.99, Cornell box 1.00 / 1.02 (0.3: 0.91 / 0.96, 0.88 / 1.00, 0.95 / 0.68, 1.00 /
/// 0.94, 0.99 / 0.93). A chain that can turn to the neighbour whose difference is large
/// leaves a flat region sooner. The small steps' σ stayed 0.01 (0.005, 0.02 and 0.04
/// measured worse on the door and the gap).
pub const DIRECTION_MUTATION_PROBABILITY: f32 = 0.5;
/// Bands a chain's splats are sorted into, for the parallel merge after each round.
const MERGE_BANDS: usize = 64;
/// Samples per pixel of the direct pass (direct light and the denoising guides): 16 before
/// the chains run, then topped up between rounds to `DIRECT_SPP_PER_MUTATION` of the
/// mutations per pixel done (whenever that doubles it), up to the maximum, so that it
/// converges with the budget like the rest of the image.
const DIRECT_SPP: (u32, u32) = (16, 4096);
/// Direct-pass samples per mutation (per pixel). A direct sample costs about a tenth of a
/// gdpssmlt mutation. Measured (gdpssmlt, 4 s, 128², relMSE; ratio 0.25 / 1 / 4 / 8): area
/// light 3.3e-4 / 1.5e-4 / 1.3e-4 / 1.7e-4, area + point + sun + world 3.8e-4 / 2.1e-4 /
/// 1.5e-4 / 1.4e-4, door ajar 0.017 / 0.012 / 0.013 / 0.015, glass box 0.0068 / 0.0067 /
/// 0.0083 / 0.0099: 2 between them.
const DIRECT_SPP_PER_MUTATION: f64 = 2.0;
/// Direct light is rendered apart only where one direct sample's relative variance (pooled
/// over the image, `relative_variance`) is at most this; above it (light through a window or a
/// door left ajar) the chains render all light but camera-seen emission, as they find the
/// rare paths that carry it. Measured (gdpssmlt, 128², 4 bounces, 2 s, relMSE apart / chains;
/// relative variance, camera-seen emission aside, 3 seeds): area + point + sun + world
/// 3.9e-4 / 7.3e-4 (0.04), hall 9.0e-3 / 7.8e-3 (1.8–1.9), glass box 1.0e-2 / 1.0e-2
/// (4.3–4.9), HDRI interior 3.1e-2 / 3.5e-3 (32–33), door ajar 1.6e-2 / 1.8e-2 (196–214);
/// area alone 0.01, world alone 0.06. On tiny images (16², 4k samples) the estimate is
/// heavy-tailed where light comes through glass (q 0.1–900 over seeds): runs may then
/// differ in their choice, each converging to the same image.
const DIRECT_APART_MAX_RELATIVE_VARIANCE: f64 = 10.0;

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

/// A base path evaluated at one primary-sample vector; `f(d)` and `splats(d)` per direction;
/// with bidirectional states, light tracing's splats besides (primal, any pixel).
struct Evaluated {
    splats: [Splats; 4],
    f: [f32; 4],
    light_tracing: Vec<(usize, Spectrum)>,
}

/// What a state's evaluation reuses: the recorded camera path, and bdpt's subpaths.
#[derive(Default)]
struct Workspace {
    path: Path,
    bd: super::bdpt::Scratch,
}

struct Target<'a> {
    scene: &'a Scene,
    settings: &'a RenderSettings,
    gradient: bool,
    /// The chains render indirect light only (direct light is the direct pass's).
    direct_apart: bool,
    w: usize,
    h: usize,
    /// `pssmlt` over bidirectional paths: each state is a whole bdpt sample (every strategy,
    /// light tracing's splats included; Veach 1997 §11.3, as Mitsuba 0.6 and LuxCore).
    bidirectional: Option<super::bdpt::Context<'a>>,
}

impl Target<'_> {
    /// Evaluates the state; for the gradient target only direction `only` (all four if None).
    fn evaluate<S: Sampler>(&self, sampler: &mut S, ws: &mut Workspace, only: Option<usize>) -> Evaluated {
        // The primary sample picks the pixel (its integer part) and, as pt's samples do, the
        // offset from the pixel's centre through the scene's pixel filter (its fraction): the
        // splats go to that pixel, which so estimates the image convolved with the filter.
        let u = sampler.next_2d();
        let (fx, fy) = (u.x * self.w as f32, u.y * self.h as f32);
        let (px, py) = ((fx as usize).min(self.w - 1), (fy as usize).min(self.h - 1));
        let frac = Vec2::new(fx - px as f32, fy - py as f32);
        let raster = self.scene.camera.pixel_raster(px as f32, py as f32, frac);
        let pixel = py * self.w + px;
        let mut ev = Evaluated { splats: [Splats::default(); 4], f: [0.0; 4], light_tracing: Vec::new() };
        if let Some(ctx) = &self.bidirectional {
            // the image is b/mpp × the splats: light tracing's per light path ÷ the pixels
            let (w, scale) = (self.w, 1.0 / (self.w * self.h) as f32);
            let mut lt = Vec::new();
            let mut streams = super::bdpt::Streams { cam: sampler, light: None };
            let c = super::bdpt::sample(ctx, &mut ws.bd, &mut streams, px, py, frac, |x, y, v| {
                if is_finite_spectrum(v) {
                    lt.push((y * w + x, v * scale))
                }
            });
            if !is_finite_spectrum(c.radiance) {
                return ev;
            }
            // (camera-seen emission is the direct pass's)
            let l = c.radiance - c.very_direct;
            let f = abs_luminance(l) + lt.iter().map(|(_, v)| abs_luminance(*v)).sum::<f32>();
            for k in 0..4 {
                ev.f[k] = f;
                ev.splats[k].pixel = pixel;
                ev.splats[k].push(PRIMAL, pixel, l);
            }
            ev.light_tracing = lt;
            return ev;
        }
        let path = &mut ws.path;
        let c = trace_path(self.scene, &self.settings.path, raster, sampler, Some(path));
        if !is_finite_spectrum(c.radiance) {
            return ev;
        }
        // the chains render indirect light (direct light is the direct pass's, FirstHits) or,
        // where direct light is hard, all but the emission the camera sees
        let l = c.radiance - if self.direct_apart { c.direct } else { c.very_direct };
        if !self.gradient {
            let f = abs_luminance(l);
            for k in 0..4 {
                ev.f[k] = f;
                ev.splats[k].pixel = pixel;
                ev.splats[k].push(PRIMAL, pixel, l);
            }
            return ev;
        }
        for (k, (dx, dy)) in SHIFTS.iter().enumerate() {
            if only.is_some_and(|o| o != k) {
                continue;
            }
            let (nx, ny) = (px as i32 + dx, py as i32 + dy);
            let inside = nx >= 0 && ny >= 0 && nx < self.w as i32 && ny < self.h as i32;
            let offset = inside.then(|| raster + Vec2::new(*dx as f32, *dy as f32));
            let pc = if self.direct_apart {
                shift_indirect(self.scene, path, offset)
            } else {
                shift(self.scene, path, offset)
            };
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
/// Chains run (and logged) at once at least; more on machines of more than 16 threads
/// (4 per thread). Bounds the logs' memory: ≈ 86 KB a chain for gdpssmlt.
const CHAIN_BATCH: usize = 64;

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
    /// Pixels per merge band (whole rows).
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

    fn new(w: usize, h: usize, gradient: bool) -> Log {
        let cap = ROUND as usize * Log::max_splats_per_mutation(gradient);
        Log {
            raw: Vec::with_capacity(cap),
            sorted: Vec::with_capacity(cap),
            offsets: [0; MERGE_BANDS + 1],
            band_pixels: (h.div_ceil(MERGE_BANDS).max(1) * w) as u64,
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

    /// `splat` for the state's direction `d` and its light-tracing splats.
    fn splat_state(&mut self, ev: &Evaluated, d: usize, weight: f64) {
        self.splat(&ev.splats[d], weight);
        if weight <= 0.0 || !weight.is_finite() {
            return;
        }
        for &(pixel, v) in &ev.light_tracing {
            let v = [(v.x as f64 * weight) as f32, (v.y as f64 * weight) as f32, (v.z as f64 * weight) as f32];
            self.push(PRIMAL, pixel, v);
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
    ws: Workspace,
}

/// One Metropolis–Hastings step with expected-value splatting (docs/algorithm.md §2).
fn mutate(target: &Target, c: &mut Chain, log: &mut Log, gradient: bool) {
    c.s.start_iteration();
    let d_new = if !gradient {
        c.d
    } else if c.s.is_large_step() || c.s.rng().next_1d() < DIRECTION_MUTATION_PROBABILITY {
        ((c.s.rng().next_1d() * 4.0) as usize).min(3)
    } else {
        c.d
    };
    let prop = target.evaluate(&mut c.s, &mut c.ws, Some(d_new));
    let (fc, fp) = (c.cur.f[c.d], prop.f[d_new]);
    let a = if fc > 0.0 { (fp / fc).min(1.0) } else { 1.0 };
    if fp > 0.0 {
        log.splat_state(&prop, d_new, a as f64 / fp as f64);
    }
    if c.s.is_large_step() {
        // an independent uniform state (u, d): one more sample of b = E[F]
        log.large_f += fp as f64;
        log.large_steps += 1;
    }
    if fc > 0.0 {
        log.splat_state(&c.cur, c.d, (1.0 - a) as f64 / fc as f64);
    }
    if c.s.rng().next_1d() < a {
        c.s.accept();
        c.cur = prop;
        c.d = d_new;
        log.accepted += 1;
    } else {
        c.s.reject();
    }
    log.push(DENSITY, c.cur.splats[c.d].pixel, [0.0; 3]);
    log.mutations += 1;
}

/// One merge band of the image (whole rows): its rows of every layer, of the density and of
/// the half differences (gdpssmlt).
type BandMut<'a> = (Vec<&'a mut [f32]>, &'a mut [u32], Vec<&'a mut [f32]>);

/// The image so far: the splat sums of each layer (primal; and dx, dy for gdpssmlt),
/// row-planar f32 as the reconstruction takes them, the chains' visits per pixel, for
/// gdpssmlt the even − odd chain halves that measure the reconstruction's α
/// (reconstruct/alpha.rs), and the tallies.
struct Accum {
    layers: Vec<RowPlanar>,
    density: Vec<u32>,
    halves: Option<HalfDifference>,
    mutations: u64,
    accepted: u64,
    large_f: f64,
    large_steps: u64,
}

impl Accum {
    fn new(w: usize, h: usize, gradient: bool) -> Accum {
        let n_layers = if gradient { 3 } else { 1 };
        Accum {
            layers: (0..n_layers).map(|_| RowPlanar::zeros(w, h)).collect(),
            density: vec![0; w * h],
            halves: gradient.then(|| HalfDifference::zeros(w, h)),
            mutations: 0,
            accepted: 0,
            large_f: 0.0,
            large_steps: 0,
        }
    }

    /// Adds the chains' logs of a round (or of a batch of its chains, the first of them chain
    /// `first_chain`): band by band in parallel, chain by chain in order within a band (so
    /// every pixel sums its splats in the same order on any thread count).
    fn merge(&mut self, logs: &[Log], first_chain: usize) {
        let Some(first) = logs.first() else { return };
        let bp = first.band_pixels as usize;
        let w = self.layers[0].width;
        let mut layer_bands: Vec<std::slice::ChunksMut<'_, f32>> =
            self.layers.iter_mut().map(|l| l.data.chunks_mut(3 * bp)).collect();
        let mut half_bands: Vec<std::slice::ChunksMut<'_, f32>> = match &mut self.halves {
            Some(d) => [&mut d.primal, &mut d.dx, &mut d.dy].map(|v| v.chunks_mut(bp)).into(),
            None => Vec::new(),
        };
        let bands: Vec<BandMut> = self
            .density
            .chunks_mut(bp)
            .map(|d| {
                let layers = layer_bands.iter_mut().map(|it| it.next().expect("same band count")).collect();
                (layers, d, half_bands.iter_mut().map(|it| it.next().expect("same band count")).collect())
            })
            .collect();
        bands.into_par_iter().enumerate().for_each(|(b, (mut layers, density, mut halves))| {
            let base = b * bp;
            for (i, log) in logs.iter().enumerate() {
                let sign = HalfDifference::sign((first_chain + i) as u64);
                for s in log.band_splats(b) {
                    let (pixel, layer) = ((s.at / 4) as usize - base, (s.at % 4) as usize);
                    if layer == DENSITY {
                        density[pixel] += 1;
                    } else {
                        // row-planar: the band's row r holds R, G, B rows of w values
                        let (r, x) = (pixel / w, pixel % w);
                        let l = &mut layers[layer];
                        for (k, v) in s.v.iter().enumerate() {
                            l[(3 * r + k) * w + x] += v;
                        }
                        if let Some(half) = halves.get_mut(layer) {
                            half[pixel] += sign * (s.v[0] + s.v[1] + s.v[2]) * (1.0 / 3.0);
                        }
                    }
                }
            }
        });
        for log in logs {
            self.mutations += log.mutations;
            self.accepted += log.accepted;
            self.large_f += log.large_f;
            self.large_steps += log.large_steps;
        }
    }

    /// The reconstruction's α: the setting, or where it is 0 (automatic) the one the even and
    /// odd chains measure.
    fn alpha(&self, setting: f64) -> f64 {
        chosen_alpha(setting, || match (&self.halves, self.layers.as_slice()) {
            (Some(d), [p, dx, dy]) => d.alpha([p, dx, dy]),
            _ => None,
        })
    }

    /// b = E[F] from the bootstrap's F sum and every large step so far.
    fn normalisation(&self, boot_sum: f64, n_boot: usize) -> f64 {
        (boot_sum + self.large_f) / (n_boot as u64 + self.large_steps) as f64
    }
}

pub fn render(scene: &Scene, settings: &RenderSettings, control: &RenderControl, gradient: bool) -> RenderOutput {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    // The direct pass (first, so previews include it; then topped up as the chains advance),
    // and the denoising albedo and normal. Its first samples, in two halves, measure how
    // hard direct light is for plain Monte Carlo; where it is too hard, the chains take it.
    // (The camera-seen emission is left out of that measure: the pass renders it either way.)
    let mut first = FirstHits::new(w, h, &settings.path, true);
    first.emitted = Some(vec![0.0; w * h * 3]);
    first.add(scene, settings.seed, DIRECT_SPP.0 / 2, control);
    let half = first.sums_apart();
    first.add(scene, settings.seed, DIRECT_SPP.0, control);
    let q = relative_variance(&half, &first.sums_apart(), DIRECT_SPP.0 / 2);
    // (bidirectional states render all but camera-seen emission: their strategies do not
    // split by the direct pass's terms)
    let bidirectional = settings.bidirectional && !gradient;
    let direct_apart = !bidirectional && q.is_some_and(|q| q <= DIRECT_APART_MAX_RELATIVE_VARIANCE);
    drop(half);
    first.settle(direct_apart);
    let target = Target {
        scene,
        settings,
        gradient,
        direct_apart,
        w,
        h,
        bidirectional: bidirectional.then(|| super::bdpt::Context::new(scene, &settings.path, None)),
    };
    let p_large = settings.large_step_probability;
    let boot_seed = mix64(settings.seed ^ 0xB007);

    // Bootstrap (parallel, deterministic): F averaged over the four directions.
    let n_boot = bootstrap_samples(w, h);
    let boot: Vec<f32> = (0..n_boot)
        .into_par_iter()
        .map_init(
            || (Workspace::default(), PssSampler::new(boot_seed, 0, p_large)),
            |(ws, s), i| {
                if control.is_cancelled() {
                    return 0.0; // Esc during the bootstrap: finish at once
                }
                s.restart(boot_seed, i as u64);
                s.start_iteration();
                let ev = target.evaluate(s, ws, None);
                ev.f.iter().sum::<f32>() * 0.25
            },
        )
        .collect();
    let starts = Bootstrap::new(boot);
    let boot_sum = starts.total;

    let total = settings.spp as u64 * (w * h) as u64;
    let n_chains = match settings.chains {
        0 => (total / 2000).clamp(1, 1024) as usize,
        n => (n as u64).min(total.max(1)) as usize,
    };
    let dimmest =
        starts.f.iter().enumerate().filter(|(_, f)| **f > 0.0).min_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i);
    control.work_total.store(total, Ordering::Relaxed);
    let chain_seed = mix64(settings.seed ^ 0xC4A1);

    // Every chain starts from a bootstrap state (replayed; direction ∝ F) ...
    let mut chains: Vec<Chain> = (0..n_chains)
        .into_par_iter()
        .filter_map(|chain| {
            let mutations = total / n_chains as u64 + u64::from((chain as u64) < total % n_chains as u64);
            let mut pick = IndependentSampler::new(chain_seed, chain as u64);
            let start = starts.sample(pick.next_1d() as f64)?;
            let start = match settings.chain_start {
                ChainStart::Proportional => start,
                ChainStart::Dimmest => dimmest?,
            };
            let mut s = PssSampler::new(boot_seed, start as u64, p_large);
            let mut ws = Workspace::default();
            s.start_iteration();
            let cur = target.evaluate(&mut s, &mut ws, None);
            s.accept();
            // its own proposal stream (two chains may start from the same bootstrap state)
            s.reseed(chain_seed ^ 0x5EED, chain as u64);
            let fsum: f32 = cur.f.iter().sum();
            let (mut d, mut acc) = (0, pick.next_1d() * fsum);
            while d < 3 && acc >= cur.f[d] {
                acc -= cur.f[d];
                d += 1;
            }
            Some(Chain { s, cur, d, remaining: mutations, ws })
        })
        .collect();
    let no_light = starts.total <= 0.0;
    drop(starts); // the bootstrap is not needed once the chains have started
    let mut image = Accum::new(w, h, gradient);
    if let Some(d) = &mut image.halves {
        d.counts = [chains.len().div_ceil(2) as u64, (chains.len() / 2) as u64];
    }
    // ... and all chains advance in rounds of ROUND mutations, so that a time limit or Esc
    // stops them at about the same length, and intermediate images can be taken in between.
    // A round runs the chains batch by batch (a batch in parallel, each chain into its own
    // log), each batch merged before the next: the same additions in the same order as one
    // merge of all chains, with logs for one batch only.
    let batch = (4 * rayon::current_num_threads()).max(CHAIN_BATCH).min(chains.len().max(1));
    let mut logs: Vec<Log> = (0..batch).map(|_| Log::new(w, h, gradient)).collect();
    while !control.should_stop() && chains.iter().any(|c| c.remaining > 0) {
        for (g, group) in chains.chunks_mut(batch).enumerate() {
            group.par_iter_mut().zip(logs.par_iter_mut()).with_max_len(1).for_each(|(c, log)| {
                log.clear();
                if control.should_stop() {
                    return;
                }
                let n = c.remaining.min(ROUND);
                for _ in 0..n {
                    mutate(&target, c, log, gradient);
                }
                log.sort_by_band();
                c.remaining -= n;
                control.work_done.fetch_add(n, Ordering::Relaxed);
            });
            image.merge(&logs[..group.len()], g * batch);
        }
        let target = direct_target(image.mutations, w * h);
        if direct_apart && target >= 2 * first.spp {
            first.add(scene, settings.seed, target, control);
        }
        control.offer_preview(|| {
            preview(&image, image.normalisation(boot_sum, n_boot), &first, image.alpha(settings.alpha_rec))
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
    stats.direct_pass = direct_apart;
    stats.direct_relative_variance = q.unwrap_or(0.0);
    // without indirect light (no chain ran) the budget is the direct pass's
    let direct_spp = match (direct_apart, no_light) {
        (_, true) => settings.spp.min(DIRECT_SPP.1),
        (false, false) => DIRECT_SPP.0,
        (true, false) => direct_target(mutations, w * h),
    };
    first.add(scene, settings.seed, direct_spp, control);
    let ([direct, albedo, normal], alpha) = first.into_means();
    // (the pass's image: direct light, or with the chains taking all, the camera-seen emission)
    if no_light && !direct.iter().any(|&v| v > 0.0) {
        stats.warnings.push("no light reaches the camera: the image is black".into());
    }
    let norm = control.final_norm(settings.reconstruction);
    if gradient {
        stats.alpha_rec = image.alpha(settings.alpha_rec);
    }
    let mut layers = resolve(image, b, direct, stats.alpha_rec, norm, &|| control.is_cancelled());
    let img = |data: Vec<f32>| Image { width: w, height: h, channels: 3, data };
    layers.push(("Denoising Albedo".into(), img(albedo)));
    layers.push(("Denoising Normal".into(), img(normal)));
    if let Some(alpha) = alpha {
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

/// The relative variance of one direct-light sample, pooled over the image: from two
/// independent halves of `n` samples each (sums of RGB `a`, and of both halves `ab`), the
/// mean over pixels of the luminance's sample variance, over the squared mean luminance.
/// None where no direct light was seen.
fn relative_variance(a: &[f32], ab: &[f32], n: u32) -> Option<f64> {
    let lum = |v: &[f32]| 0.2126 * v[0] as f64 + 0.7152 * v[1] as f64 + 0.0722 * v[2] as f64;
    let n = n as f64;
    let (mut var, mut mean) = (0.0, 0.0);
    for (a, ab) in a.chunks_exact(3).zip(ab.chunks_exact(3)) {
        let (la, lab) = (lum(a) / n, lum(ab) / n);
        let lb = lab - la;
        // Var(mean of n) = σ²/n and E[(A − B)²] = 2σ²/n
        var += 0.5 * n * (la - lb) * (la - lb);
        mean += 0.5 * (la + lb);
    }
    let pixels = (a.len() / 3).max(1) as f64;
    let (var, mean) = (var / pixels, mean / pixels);
    (mean > 0.0 && var.is_finite()).then(|| var / (mean * mean))
}

/// Samples per pixel of the direct pass after `mutations` mutations over `pixels`.
fn direct_target(mutations: u64, pixels: usize) -> u32 {
    let spp = DIRECT_SPP_PER_MUTATION * mutations as f64 / pixels.max(1) as f64;
    (spp as u64).clamp(DIRECT_SPP.0 as u64, DIRECT_SPP.1 as u64) as u32
}

/// The direct pass: direct light (`PathContribution::direct`: the render's own paths cut at
/// `max_bounces` 0, Cycles' direct lighting), first-surface albedo and normal, by plain
/// Monte Carlo (Owen-scrambled Sobol samples through the pixel filter, as pt's), accumulated
/// progressively: sums of [direct, albedo, normal], RGB; and, with a transparent film, of
/// the camera rays' transparency (alpha = 1 − its mean). The chains render the rest of the
/// light (Veach 1997 §11.3.2 and Mitsuba's "direct sampling" do the same): direct light is
/// what plain Monte Carlo renders best, and a chain that need not find it spends its
/// mutations on the indirect light.
struct FirstHits {
    sums: [Vec<f32>; 3],
    transparent: Vec<f32>,
    /// While the pass probes how hard direct light is (light mode): the sums of the
    /// camera-seen emission, which its direct light includes but the decision leaves out
    /// (the pass renders it either way).
    emitted: Option<Vec<f32>>,
    /// The render's path settings with `max_bounces` 0.
    direct: PathSettings,
    /// Transparent surfaces a camera ray may cross (PathSettings::transparent_bounces).
    crossings: u32,
    spp: u32,
    /// Whether it renders direct light (else only the guides and alpha; the chains render
    /// all light).
    light: bool,
    w: usize,
    h: usize,
}

impl FirstHits {
    fn new(w: usize, h: usize, path: &PathSettings, light: bool) -> FirstHits {
        FirstHits {
            light,
            sums: std::array::from_fn(|_| vec![0.0; w * h * 3]),
            transparent: Vec::new(),
            emitted: None,
            direct: PathSettings { max_bounces: 0, ..*path },
            crossings: path.transparent_bounces,
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
            if self.spp >= DIRECT_SPP.0 && control.should_stop() {
                break;
            }
            let (from, n) = (self.spp, (target - self.spp).min(8));
            let (has_alpha, crossings, cfg) = (scene.has_alpha(), self.crossings, &self.direct);
            let light = self.light;
            if has_alpha {
                self.transparent.resize(w * h, 0.0);
            }
            // each row's samples are added to its sums in place (no image-sized temporary)
            let [direct, albedo, normal] = &mut self.sums;
            let mut transparent: Vec<&mut [f32]> = self.transparent.chunks_mut(w).collect();
            transparent.resize_with(h, || &mut []);
            let mut emitted: Vec<&mut [f32]> = self.emitted.iter_mut().flat_map(|e| e.chunks_mut(3 * w)).collect();
            emitted.resize_with(h, || &mut []);
            direct
                .par_chunks_mut(3 * w)
                .zip(albedo.par_chunks_mut(3 * w))
                .zip(normal.par_chunks_mut(3 * w))
                .zip(transparent.into_par_iter())
                .zip(emitted.into_par_iter())
                .enumerate()
                .for_each(|(y, ((((direct, albedo), normal), transparent), emitted))| {
                    for x in 0..w {
                        let mut rays = [CameraRay::default(); 8];
                        let mut samplers: [_; 8] =
                            std::array::from_fn(|k| super::pt::pixel_sampler(seed ^ 0xD1, y * w + x, from + k as u32));
                        let mut lens = [Vec2::ZERO; 8];
                        for k in 0..n as usize {
                            let smp = &mut samplers[k];
                            let raster = scene.camera.pixel_raster(x as f32, y as f32, smp.next_2d());
                            lens[k] = smp.next_2d();
                            rays[k] = scene.camera.generate_ray(raster, lens[k]);
                        }
                        let hits = scene.intersect_camera_rays(&rays[..n as usize]);
                        let mut acc = [Spectrum::ZERO; 3];
                        let (mut t, mut e) = (0.0f32, Spectrum::ZERO);
                        for (k, (ray, hit)) in rays.iter().zip(hits).take(n as usize).enumerate() {
                            let primary = Primary { lens: lens[k], ray: *ray, hit };
                            let f = first_hit(scene, ray, hit);
                            if light {
                                let c = trace_path_from(scene, cfg, primary, &mut samplers[k], None);
                                if is_finite_spectrum(c.radiance) {
                                    acc[0] += c.radiance;
                                    e += f.very_direct;
                                }
                            } else {
                                acc[0] += f.very_direct;
                            }
                            acc[1] += f.albedo;
                            acc[2] += f.normal;
                            if has_alpha {
                                t += camera_transparency(scene, ray, hit, crossings);
                            }
                        }
                        for (sum, a) in [&mut *direct, &mut *albedo, &mut *normal].into_iter().zip(acc) {
                            sum[3 * x] += a.x;
                            sum[3 * x + 1] += a.y;
                            sum[3 * x + 2] += a.z;
                        }
                        if has_alpha {
                            transparent[x] += t;
                        }
                        if !emitted.is_empty() {
                            emitted[3 * x] += e.x;
                            emitted[3 * x + 1] += e.y;
                            emitted[3 * x + 2] += e.z;
                        }
                    }
                });
            self.spp += n;
        }
    }

    /// Ends the probe: keeps the direct light (`apart`), or else only the camera-seen emission
    /// summed while probing (the same samples' first hits), and renders that from then on.
    fn settle(&mut self, apart: bool) {
        let emitted = self.emitted.take();
        if !apart {
            self.sums[0] = emitted.expect("settle ends a probe");
            self.light = false;
        }
    }

    /// The sums of the direct light the chains would otherwise render: direct light but the
    /// camera-seen emission (while probing; else all of it).
    fn sums_apart(&self) -> Vec<f32> {
        match &self.emitted {
            Some(e) => self.sums[0].iter().zip(e).map(|(d, e)| d - e).collect(),
            None => self.sums[0].clone(),
        }
    }

    /// The mean of image `k` (0 direct, 1 albedo, 2 normal).
    fn mean(&self, k: usize) -> Vec<f32> {
        let n = self.spp.max(1) as f32;
        self.sums[k].par_iter().map(|v| v / n).collect()
    }

    /// The means of [direct, albedo, normal], made in place, and the alpha layer of a
    /// transparent film (one channel; None otherwise).
    fn into_means(self) -> ([Vec<f32>; 3], Option<Image>) {
        let n = self.spp.max(1) as f32;
        let mut sums = self.sums;
        for v in &mut sums {
            v.par_iter_mut().for_each(|x| *x /= n);
        }
        let data: Vec<f32> = self.transparent.iter().map(|t| 1.0 - t / n).collect();
        let alpha = (!data.is_empty()).then_some(Image { width: self.w, height: self.h, channels: 1, data });
        (sums, alpha)
    }
}

/// The factor of the splat sums: b / (mutations per pixel).
fn splat_scale(image: &Accum, b: f64) -> f32 {
    let pixels = image.density.len().max(1);
    let mpp = image.mutations as f64 / pixels as f64;
    if mpp > 0.0 {
        (b / mpp) as f32
    } else {
        0.0
    }
}

/// The image so far (a preview): the splats × b/mpp (for gdpssmlt their L2 screened Poisson
/// reconstruction) plus the direct light.
fn preview(image: &Accum, b: f64, first: &FirstHits, alpha_rec: f64) -> Image {
    let s = splat_scale(image, b);
    let (w, h) = (first.w, first.h);
    if image.layers.len() == 1 {
        let data = image.layers[PRIMAL].scaled(s).to_interleaved(Some(&first.mean(0)), f32::NEG_INFINITY);
        return Image { width: w, height: h, channels: 3, data };
    }
    let [p, dx, dy] = [PRIMAL, DX, DY].map(|l| image.layers[l].scaled(s));
    let p = Problem::new(alpha_rec, p, dx, dy);
    gradient_domain_image(&p, &first.mean(0), Norm::L2, &IrlsParams::default(), &|| false)
}

/// The output layers, from the image (consumed: its buffers become the problem and the
/// layers) and the direct pass's image: splats × b/mpp (for gdpssmlt their screened Poisson
/// reconstruction) plus the direct light; and the chains' density.
fn resolve(
    image: Accum,
    b: f64,
    direct: Vec<f32>,
    alpha_rec: f64,
    norm: Norm,
    stop: &(dyn Fn() -> bool + Sync),
) -> Vec<(String, Image)> {
    let s = splat_scale(&image, b);
    let Accum { mut layers, density, .. } = image;
    let (w, h) = (layers[0].width, layers[0].height);
    let img = |data: Vec<f32>| Image { width: w, height: h, channels: 3, data };
    for l in &mut layers {
        l.scale(s);
    }
    let mut out = match <[RowPlanar; 3]>::try_from(layers) {
        Ok([primal, dx, dy]) => {
            let p = Problem::new(alpha_rec, primal, dx, dy);
            gradient_domain_layers(p, direct, norm, &IrlsParams::default(), stop)
        }
        Err(primal) => vec![("Combined".into(), img(primal[PRIMAL].to_interleaved(Some(&direct), f32::NEG_INFINITY)))],
    };
    let dmean = density.iter().map(|&d| d as f64).sum::<f64>() / (w * h) as f64;
    let density: Vec<f32> = density.iter().flat_map(|&v| [(v as f64 / dmean.max(1e-300)) as f32; 3]).collect();
    out.push(("MLT Density".into(), img(density)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::path::first_hit;

    /// Chain starts are drawn exactly ∝ F: the state sampled for u is the one whose slice of
    /// the f64 running sum holds u·ΣF (checked against a direct running sum), across block
    /// boundaries, skipping states of F = 0, and never a state of F = 0.
    /// The pooled relative variance from two halves matches the one of the distribution the
    /// samples come from: per pixel, a light found with probability p carrying 1/p (mean 1,
    /// variance (1 − p)/p), p varying over the image; and it is None for a black image.
    /// The chain halves: a chain's splats to the primal and gradients enter the half
    /// differences with the sign of its index's parity (the index in the whole render, not in
    /// its batch), channel-averaged; visits do not; merging in batches gives the same halves.
    #[test]
    fn chain_halves_are_even_minus_odd_chains() {
        let (w, h) = (7, 20);
        let logs: Vec<Log> = (0..5)
            .map(|c| {
                let mut log = Log::new(w, h, true);
                for (layer, pixel) in [(PRIMAL, 3), (DX, 3), (DY, 130), (PRIMAL, 130), (DENSITY, 3)] {
                    log.push(layer, pixel, [c as f32 + 1.0, 2.0 * layer as f32, 0.5]);
                }
                log.sort_by_band();
                log
            })
            .collect();
        let mut whole = Accum::new(w, h, true);
        whole.merge(&logs, 0);
        let mut batched = Accum::new(w, h, true);
        batched.merge(&logs[..2], 0);
        batched.merge(&logs[2..], 2);
        let mean = |c: f32, layer: usize| (c + 1.0 + 2.0 * layer as f32 + 0.5) / 3.0;
        let expect =
            |layer: usize| (0..5).map(|c| if c % 2 == 0 { 1.0 } else { -1.0 } * mean(c as f32, layer)).sum::<f32>();
        for a in [&whole, &batched] {
            let d = a.halves.as_ref().unwrap();
            for (got, layer) in [(d.primal[3], PRIMAL), (d.dx[3], DX), (d.dy[130], DY), (d.primal[130], PRIMAL)] {
                assert!((got - expect(layer)).abs() < 1e-5, "layer {layer}: {got} vs {}", expect(layer));
            }
            assert_eq!(d.primal.iter().chain(&d.dx).chain(&d.dy).filter(|v| **v != 0.0).count(), 4);
        }
        assert!(Accum::new(w, h, false).halves.is_none(), "pssmlt keeps no halves");
    }

    #[test]
    fn relative_variance_of_direct_samples_matches_their_distribution() {
        let n = 8u32;
        let pixels = 20_000;
        let mut s = IndependentSampler::new(3, 0);
        let (mut a, mut ab) = (vec![0.0f32; 3 * pixels], vec![0.0f32; 3 * pixels]);
        let mut expected = 0.0;
        for i in 0..pixels {
            let p = [0.05f32, 0.2, 0.5, 0.9][i % 4];
            expected += (1.0 - p as f64) / p as f64 / pixels as f64;
            for k in 0..2 * n {
                let v = if s.next_1d() < p { 1.0 / p } else { 0.0 };
                for c in 0..3 {
                    ab[3 * i + c] += v;
                    if k < n {
                        a[3 * i + c] += v;
                    }
                }
            }
        }
        let q = relative_variance(&a, &ab, n).unwrap();
        // the estimate's own standard error here is ≈ 2% of its value
        assert!((q / expected - 1.0).abs() < 0.08, "estimated {q}, expected {expected}");
        assert_eq!(relative_variance(&[0.0; 6], &[0.0; 6], n), None);
    }

    #[test]
    fn bootstrap_starts_follow_the_running_sum_of_f() {
        let mut s = IndependentSampler::new(11, 0);
        let f: Vec<f32> =
            (0..5000).map(|i| if i % 7 == 0 || (1024..2048).contains(&i) { 0.0 } else { s.next_1d() * 3.0 }).collect();
        let boot = Bootstrap::new(f.clone());
        let total: f64 = f.iter().map(|&v| v as f64).sum();
        assert!((boot.total - total).abs() < 1e-9 * total);
        for k in 0..20_000 {
            let u = (k as f64 + 0.5) / 20_000.0;
            let i = boot.sample(u).expect("F > 0 somewhere");
            let before: f64 = f[..i].iter().map(|&v| v as f64).sum();
            assert!(f[i] > 0.0, "u = {u}: state {i} has F = 0");
            let t = u * total;
            assert!(before <= t * (1.0 + 1e-12) && t < (before + f[i] as f64) * (1.0 + 1e-12), "u = {u}: state {i}");
        }
        assert_eq!(boot.sample(1.0), f.iter().rposition(|&v| v > 0.0));
        assert_eq!(Bootstrap::new(vec![0.0; 10]).sample(0.5), None);
    }

    /// The direct pass, tracing each pixel's camera rays in packets of eight and topped up in
    /// two passes, gives every pixel the mean of the samples that single paths (cut at
    /// `max_bounces` 0) and single first-hit rays give it.
    #[test]
    fn packet_first_hit_pass_matches_single_rays() {
        let scene = Scene::build(&crate::scene::builtin::cornell_spheres(9, 7)).unwrap();
        let settings = RenderSettings { seed: 3, ..Default::default() };
        let (w, h) = (9, 7);
        let mut first = FirstHits::new(w, h, &settings.path, true);
        let cut = PathSettings { max_bounces: 0, ..settings.path };
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
                    let raster = scene.camera.pixel_raster(x as f32, y as f32, smp.next_2d());
                    let lens = smp.next_2d();
                    let ray = scene.camera.generate_ray(raster, lens);
                    let f = first_hit(&scene, &ray, scene.intersect_camera(ray.origin, ray.dir, ray.tmin, ray.tmax));
                    let mut smp2 = super::super::pt::pixel_sampler(settings.seed ^ 0xD1, y * w + x, s);
                    smp2.next_2d(); // the raster sample
                    acc[0] += trace_path(&scene, &cut, raster, &mut smp2, None).radiance;
                    acc[1] += f.albedo;
                    acc[2] += f.normal;
                }
                let i = 3 * (y * w + x);
                for (img, a) in [&direct, &albedo, &normal].iter().zip(acc) {
                    let a = a / spp as f32;
                    for c in 0..3 {
                        let v = img[i + c];
                        assert!((v - a[c]).abs() <= 1e-6 * v.abs().max(1.0), "pixel ({x}, {y})");
                    }
                }
            }
        }
        assert!(albedo.iter().any(|&v| v > 0.0) && direct.iter().any(|&v| v > 0.0));
    }
}
