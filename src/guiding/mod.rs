//! Path guiding for `pt` (Müller, Gross & Novák 2017, "Practical Path Guiding for Efficient
//! Light-Transport Simulation"): the render learns, as it goes, where light arrives from at
//! each region of the scene (an SD-tree: `spatial.rs` over `quadtree.rs`), and samples the
//! continuation of a path from that distribution beside the BSDF.
//!
//! Parameters (fixed; the paper's unless said):
//! - training in iterations of 1, 2, 4, … samples per pixel; the guide learned in one is
//!   used, unchanged, through the next, so every sample is an unbiased estimate and all of
//!   them are kept (the paper discards the earlier iterations; at 128² and a few seconds they
//!   are a third of the samples);
//! - a spatial leaf splits above [`SPLIT_C`]·√(2^k) records in iteration k;
//! - a directional quadrant splits above [`RHO`] = 1% of its leaf's energy;
//! - at a guidable vertex (`Bsdf::guidable`) among a path's first [`MAX_GUIDED_DEPTH`]
//!   scattering vertices, with a learned distribution of at least
//!   [`MIN_RECORDS`] records, one-sample MIS of the guide (probability
//!   [`GUIDE_PROBABILITY`]) and the BSDF; the density of the mixture is what MIS with
//!   next-event estimation sees;
//! - records: at each guidable vertex, the luminance of the radiance the path brought back
//!   along the sampled direction (light samples and emission found after it, divided by the
//!   throughput up to it) over the mixture's density. Sums are fixed-point, so the guide,
//!   and the image, do not depend on the thread count.

mod quadtree;
mod spatial;

pub use quadtree::DTree;
use spatial::STree;

use crate::bsdf::{Bsdf, BsdfSample, LobeKind, Scatter};
use crate::math::{luminance, Frame, Spectrum};
use crate::scene::Scene;
use glam::{Vec2, Vec3};

/// Records per spatial leaf, times √(samples per pixel of the iteration), above which it
/// splits (the paper's 12000; 3000 gave a lower median error on the door-ajar room at 128²,
/// where 12000 leaves a few dozen leaves for the whole room).
pub const SPLIT_C: f64 = 3000.0;
/// Energy share above which a directional quadrant splits.
pub const RHO: f32 = 0.01;
/// Scattering vertices guided (and recorded) per path: the first two. Deeper vertices carry
/// less of the image and cost as much: on the door-ajar room, guiding every vertex cost 26%
/// more time per sample for −9% relMSE (−21% block error after OIDN) at equal samples; the
/// first two, 11% for −7% (−17%); the first alone 5% for −3% (−14%).
pub const MAX_GUIDED_DEPTH: u32 = 2;
/// Records a distribution needs before it is sampled.
pub const MIN_RECORDS: u64 = 128;
/// Probability of sampling the guide rather than the BSDF at a guided vertex (the paper's ½
/// gave the door-ajar room 1.5× its relMSE at equal samples, from fireflies where the guide
/// was wrong; ¼ lowered it by 9%).
pub const GUIDE_PROBABILITY: f32 = 0.25;

/// The guide of a render: what has been learned, and the iteration being recorded.
#[derive(Clone, Debug)]
pub struct GuideField {
    tree: STree,
    /// Training iterations completed.
    pub iterations: u32,
}

impl GuideField {
    /// An empty guide over the scene's bounds (nothing learned: every vertex samples its BSDF).
    pub fn new(scene: &Scene) -> GuideField {
        GuideField { tree: STree::new(scene.bounds_center, scene.bounds_radius), iterations: 0 }
    }

    /// The samples per pixel that end training iteration `k` (0, 1, …): 1, 3, 7, 15, …
    pub fn iteration_end(k: u32) -> u32 {
        ((1u64 << (k + 1).min(31)) - 1) as u32
    }

    /// Ends the current iteration: what it recorded becomes the guide, and the tree refines.
    pub fn refine(&mut self) {
        let k = self.iterations.min(40);
        self.tree.refine(SPLIT_C * 2f64.powf(k as f64 * 0.5), RHO);
        self.iterations += 1;
    }

    /// Spatial leaves (for tests and the log).
    pub fn leaves(&self) -> usize {
        self.tree.leaves.len()
    }

    /// The guide at `p`: its leaf, and the distribution to sample there if one has been
    /// learned.
    #[inline]
    pub fn at(&self, p: Vec3) -> GuideAt<'_> {
        let leaf = self.tree.leaf_at(p);
        let d = &self.tree.leaves[leaf as usize].sampling;
        GuideAt { leaf, dist: (d.records >= MIN_RECORDS && d.total() > 0.0).then_some(d) }
    }

    /// Records `value` (radiance over the density it was sampled with) arriving at leaf
    /// `leaf` from direction `d`.
    #[inline]
    pub fn record(&self, leaf: u32, d: Vec3, value: f32) {
        self.tree.leaves[leaf as usize].recorder.record(d, value);
    }
}

/// The guide at one vertex.
#[derive(Clone, Copy, Debug)]
pub struct GuideAt<'a> {
    pub leaf: u32,
    pub dist: Option<&'a DTree>,
}

/// A path's use of the guide: sample from it, and (in a training iteration) record into it.
#[derive(Clone, Copy, Debug)]
pub struct Guiding<'a> {
    pub field: &'a GuideField,
    pub record: bool,
}

/// Samples the continuation at a guided vertex from the mixture of `dist` (probability
/// [`GUIDE_PROBABILITY`]) and the BSDF: `u_lobe` chooses between them (and, rescaled, the
/// BSDF's lobe or the guided direction's label), `u` the direction. The sample's pdf and
/// weight are the mixture's; a delta lobe the BSDF samples keeps its own (only the BSDF
/// has it).
#[inline]
pub fn sample_mixture(bsdf: &Bsdf, frame: &Frame, dist: &DTree, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
    let a = GUIDE_PROBABILITY;
    if u_lobe < a {
        let (d, pdf_g) = dist.sample(u);
        if !(pdf_g > 0.0) {
            return None;
        }
        let wi = frame.to_local(d);
        let (f, pdf_b) = bsdf.eval_pdf(wo, wi);
        let pdf = a * pdf_g + (1.0 - a) * pdf_b;
        if !(f.max_element() > 0.0) || !(pdf > 0.0) {
            return None;
        }
        // (the rest of u_lobe labels it, as the BSDF's lobes would have)
        let diffuse = u_lobe / a < bsdf.diffuse_share(wo, wi, pdf_b);
        let scatter = if diffuse { Scatter::Diffuse } else { Scatter::Glossy };
        return Some(BsdfSample { wi, weight: f / pdf, pdf, lobe: LobeKind::Diffuse, eta: 1.0, scatter });
    }
    let mut bs = bsdf.sample(wo, ((u_lobe - a) / (1.0 - a)).min(1.0 - f32::EPSILON), u)?;
    if bs.lobe != LobeKind::Specular {
        let pdf = a * dist.pdf(frame.to_world(bs.wi)) + (1.0 - a) * bs.pdf;
        bs.weight *= bs.pdf / pdf;
        bs.pdf = pdf;
    } else {
        // a discrete lobe (beneath the surface) is chosen only when the guide is not
        bs.weight /= 1.0 - a;
        bs.pdf *= 1.0 - a;
    }
    Some(bs)
}

/// The mixture's density towards a direction whose BSDF density is `pdf_b` (for MIS).
#[inline]
pub fn mixture_pdf(dist: &DTree, wi_world: Vec3, pdf_b: f32) -> f32 {
    GUIDE_PROBABILITY * dist.pdf(wi_world) + (1.0 - GUIDE_PROBABILITY) * pdf_b
}

/// Most vertices a path records: its guided ones.
const MAX_RECORDED: usize = MAX_GUIDED_DEPTH as usize;

/// The vertices of one path that will record what it brings back.
#[derive(Clone, Copy, Debug)]
pub struct PathRecords {
    n: usize,
    leaf: [u32; MAX_RECORDED],
    dir: [Vec3; MAX_RECORDED],
    /// 1 / the throughput after the vertex's scattering (0 where it is 0), and the density
    /// of its sampled direction.
    inv_beta: [Spectrum; MAX_RECORDED],
    pdf: [f32; MAX_RECORDED],
    radiance: [Spectrum; MAX_RECORDED],
}

impl Default for PathRecords {
    fn default() -> Self {
        PathRecords {
            n: 0,
            leaf: [0; MAX_RECORDED],
            dir: [Vec3::ZERO; MAX_RECORDED],
            inv_beta: [Spectrum::ZERO; MAX_RECORDED],
            pdf: [0.0; MAX_RECORDED],
            radiance: [Spectrum::ZERO; MAX_RECORDED],
        }
    }
}

impl PathRecords {
    /// A vertex at `leaf` continued in `dir` with density `pdf`, its throughput now `beta`.
    #[inline]
    pub fn push(&mut self, leaf: u32, dir: Vec3, pdf: f32, beta: Spectrum) {
        if self.n < MAX_RECORDED && pdf > 0.0 {
            let i = self.n;
            let inv = |b: f32| if b > 0.0 { 1.0 / b } else { 0.0 };
            (self.leaf[i], self.dir[i], self.pdf[i], self.radiance[i]) = (leaf, dir, pdf, Spectrum::ZERO);
            self.inv_beta[i] = Spectrum::new(inv(beta.x), inv(beta.y), inv(beta.z));
            self.n += 1;
        }
    }

    /// Light `c` (as added to the pixel) reached the camera through every vertex so far.
    #[inline]
    pub fn add(&mut self, c: Spectrum) {
        for i in 0..self.n {
            self.radiance[i] += c * self.inv_beta[i];
        }
    }

    /// Writes the records into the guide.
    pub fn flush(&self, field: &GuideField) {
        for i in 0..self.n {
            let v = luminance(self.radiance[i]) / self.pdf[i];
            if v.is_finite() {
                field.record(self.leaf[i], self.dir[i], v.max(0.0));
            }
        }
    }
}
