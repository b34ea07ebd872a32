//! The directional half of Müller et al.'s SD-tree ("Practical Path Guiding for Efficient
//! Light-Transport Simulation", 2017, §3–4): a quadtree over the unit square, which the
//! cylindrical map (`square_to_dir`, area-preserving) wraps onto the sphere of directions.
//! Each node splits its square into four quadrants (q = x + 2y) and holds the energy of each;
//! a quadrant without a child is a leaf, its energy spread evenly over it.
//!
//! Two forms of the same structure: [`DTree`], read-only, which a pass samples and evaluates;
//! [`DTreeRecorder`], which the pass fills with the radiance its paths bring back (fixed-point
//! atomic sums: the totals are the same in any order, so the guide does not depend on the
//! thread count). At the end of a training iteration the recorder becomes the next `DTree`
//! (`DTreeRecorder::collect`), and `DTree::refined` lays out the next recorder: a quadrant
//! holding more than `rho` of the energy is subdivided, one holding less is merged (§4.2).

use crate::math::{atan2, sin_cos_turns};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};

/// Deepest level of subdivision (the paper's 20).
pub const MAX_DEPTH: u32 = 20;

/// Fixed-point scale of recorded energy: a record of value v adds round(v·SCALE).
const SCALE: f64 = (1u64 << 24) as f64;
/// Largest single record (in energy units): a firefly cannot overflow the sums.
const MAX_RECORD: f64 = 1e6;

/// The unit square's point (u, v) as a direction: cos θ = 2u − 1, φ = 2πv (equal-area).
#[inline]
pub fn square_to_dir(p: Vec2) -> Vec3 {
    let cos_t = 2.0 * p.x - 1.0;
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let (s, c) = sin_cos_turns(p.y);
    Vec3::new(sin_t * c, sin_t * s, cos_t)
}

/// The inverse of [`square_to_dir`], clamped into [0, 1).
#[inline]
pub fn dir_to_square(d: Vec3) -> Vec2 {
    let u = (d.z.clamp(-1.0, 1.0) + 1.0) * 0.5;
    let mut phi = atan2(d.y, d.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let v = phi / (2.0 * PI);
    let below_one = 1.0 - f32::EPSILON;
    Vec2::new(u.min(below_one), v.min(below_one))
}

/// The quadrant of `p` (in a node's unit square) and `p` in the quadrant's own unit square.
#[inline]
fn quadrant(p: Vec2) -> (usize, Vec2) {
    let (qx, qy) = ((p.x >= 0.5) as usize, (p.y >= 0.5) as usize);
    let local = Vec2::new(p.x * 2.0 - qx as f32, p.y * 2.0 - qy as f32);
    (qx + 2 * qy, local.min(Vec2::splat(1.0 - f32::EPSILON)))
}

#[derive(Clone, Copy, Debug, Default)]
struct Node {
    /// Child node of each quadrant (0: the quadrant is a leaf; the root is node 0).
    child: [u32; 4],
    /// 4 × each quadrant's share of the node's energy: the density factor of choosing it
    /// (they sum to 4; all 0 in a node without energy). 32 bytes a node: two to a cache line.
    density: [f32; 4],
}

/// A directional distribution to sample and evaluate (solid-angle densities over the sphere).
#[derive(Clone, Debug)]
pub struct DTree {
    nodes: Vec<Node>,
    /// Total energy recorded.
    total: f32,
    /// The number of records it was learned from.
    pub records: u64,
}

impl Default for DTree {
    /// The root alone, with no energy: nothing to sample.
    fn default() -> Self {
        DTree { nodes: vec![Node::default()], total: 0.0, records: 0 }
    }
}

impl DTree {
    /// Total energy recorded.
    #[inline]
    pub fn total(&self) -> f32 {
        self.total
    }

    /// A direction drawn ∝ the recorded energy, and its solid-angle density. `u` in [0, 1)².
    /// Only for a tree whose total is positive.
    #[inline]
    pub fn sample(&self, mut u: Vec2) -> (Vec3, f32) {
        let (mut node, mut origin, mut size, mut pdf) = (0usize, Vec2::ZERO, 1.0f32, 1.0f32);
        loop {
            let n = &self.nodes[node];
            let s = n.density;
            // the column ∝ its two quadrants' energy, then the row within it
            let left = (s[0] + s[2]) * 0.25;
            let qx = (u.x >= left) as usize;
            u.x = if qx == 0 { u.x / left } else { (u.x - left) / (1.0 - left) };
            let (a, b) = (s[qx], s[qx + 2]);
            let lower = a / (a + b);
            let qy = (u.y >= lower) as usize;
            u.y = if qy == 0 { u.y / lower } else { (u.y - lower) / (1.0 - lower) };
            u = u.clamp(Vec2::ZERO, Vec2::splat(1.0 - f32::EPSILON));
            let q = qx + 2 * qy;
            pdf *= n.density[q];
            size *= 0.5;
            origin += Vec2::new(qx as f32, qy as f32) * size;
            if n.child[q] == 0 {
                let p = origin + u * size;
                return (square_to_dir(p), pdf / (4.0 * PI));
            }
            node = n.child[q] as usize;
        }
    }

    /// The solid-angle density with which `sample` returns `d` (0 for a tree with no energy).
    #[inline]
    pub fn pdf(&self, d: Vec3) -> f32 {
        if !(self.total > 0.0) {
            return 0.0;
        }
        let (mut p, mut node, mut pdf) = (dir_to_square(d), 0usize, 1.0f32);
        loop {
            let n = &self.nodes[node];
            let (q, local) = quadrant(p);
            pdf *= n.density[q];
            if !(pdf > 0.0) {
                return 0.0;
            }
            if n.child[q] == 0 {
                return pdf / (4.0 * PI);
            }
            node = n.child[q] as usize;
            p = local;
        }
    }

    /// The layout of the next recorder (§4.2): from the root, a quadrant whose share of the
    /// total energy exceeds `rho` gets (or keeps) a child, down to [`MAX_DEPTH`]; a newly
    /// made child's quadrants are taken to hold a quarter each. Quadrants at or below `rho`
    /// become leaves. A tree with no energy keeps its layout.
    pub fn refined(&self, rho: f32) -> DTreeRecorder {
        let total = self.total();
        let mut layout: Vec<[u32; 4]> = vec![[0; 4]];
        if !(total > 0.0) {
            // no energy: the old layout, to record into again
            layout = self.nodes.iter().map(|n| n.child).collect();
            return DTreeRecorder::with_layout(layout);
        }
        // (node in self, or None for a new child; the node's share of the total energy; its
        // index in the new layout; its depth)
        let mut stack: Vec<(Option<usize>, f32, usize, u32)> = vec![(Some(0), 1.0, 0, 1)];
        while let Some((old, share, new, depth)) = stack.pop() {
            for q in 0..4 {
                let (child_old, e) = match old {
                    Some(o) => {
                        let c = self.nodes[o].child[q];
                        ((c != 0).then_some(c as usize), share * self.nodes[o].density[q] * 0.25)
                    }
                    None => (None, share * 0.25),
                };
                if depth < MAX_DEPTH && e > rho {
                    let idx = layout.len();
                    layout.push([0; 4]);
                    layout[new][q] = idx as u32;
                    stack.push((child_old, e, idx, depth + 1));
                }
            }
        }
        DTreeRecorder::with_layout(layout)
    }
}

/// A quadtree's layout with atomic energy sums: what a training pass records into.
#[derive(Debug)]
pub struct DTreeRecorder {
    child: Vec<[u32; 4]>,
    sum: Vec<[AtomicU64; 4]>,
    records: AtomicU64,
}

impl Clone for DTreeRecorder {
    fn clone(&self) -> Self {
        let sum =
            self.sum.iter().map(|s| std::array::from_fn(|q| AtomicU64::new(s[q].load(Ordering::Relaxed)))).collect();
        DTreeRecorder { child: self.child.clone(), sum, records: AtomicU64::new(self.records.load(Ordering::Relaxed)) }
    }
}

impl Default for DTreeRecorder {
    /// The root's four quadrants as leaves.
    fn default() -> Self {
        DTreeRecorder::with_layout(vec![[0; 4]])
    }
}

impl DTreeRecorder {
    fn with_layout(child: Vec<[u32; 4]>) -> DTreeRecorder {
        let sum = child.iter().map(|_| std::array::from_fn(|_| AtomicU64::new(0))).collect();
        DTreeRecorder { child, sum, records: AtomicU64::new(0) }
    }

    /// Nodes in the layout.
    pub fn nodes(&self) -> usize {
        self.child.len()
    }

    /// Records `value` (radiance over the sampling density) arriving from direction `d`.
    #[inline]
    pub fn record(&self, d: Vec3, value: f32) {
        let v = (value as f64).min(MAX_RECORD);
        self.records.fetch_add(1, Ordering::Relaxed);
        if !(v > 0.0) {
            return;
        }
        let fixed = (v * SCALE).round() as u64;
        let (mut p, mut node) = (dir_to_square(d), 0usize);
        loop {
            let (q, local) = quadrant(p);
            let c = self.child[node][q];
            if c == 0 {
                self.sum[node][q].fetch_add(fixed, Ordering::Relaxed);
                return;
            }
            node = c as usize;
            p = local;
        }
    }

    /// Records so far.
    pub fn records(&self) -> u64 {
        self.records.load(Ordering::Relaxed)
    }

    /// The recorded distribution: each quadrant's energy, summed up from its descendants.
    pub fn collect(&self) -> DTree {
        let n = self.child.len();
        let mut sums: Vec<[f64; 4]> =
            self.sum.iter().map(|s| std::array::from_fn(|q| s[q].load(Ordering::Relaxed) as f64 / SCALE)).collect();
        let mut nodes = vec![Node::default(); n];
        // children come after their parents in the layout: sum from the back
        for i in (0..n).rev() {
            for q in 0..4 {
                let c = self.child[i][q] as usize;
                if c != 0 {
                    sums[i][q] = sums[c].iter().sum();
                }
            }
            let t: f64 = sums[i].iter().sum();
            nodes[i].child = self.child[i];
            if t > 0.0 {
                nodes[i].density = sums[i].map(|s| (4.0 * s / t) as f32);
            }
        }
        let total = sums[0].iter().sum::<f64>() as f32;
        DTree { nodes, total, records: self.records() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{Sampler, SobolSampler};

    #[test]
    fn cylindrical_map_round_trips() {
        for i in 0..64 {
            for j in 0..64 {
                let p = Vec2::new((i as f32 + 0.37) / 64.0, (j as f32 + 0.61) / 64.0);
                let q = dir_to_square(square_to_dir(p));
                assert!((p - q).length() < 1e-4, "{p} → {q}");
            }
        }
    }

    /// A learned tree: records from a sharp lobe around `peak` and a dim uniform rest.
    fn learned(peak: Vec3, passes: u32) -> DTree {
        let mut tree = DTree::default();
        for pass in 0..passes {
            let rec = tree.refined(0.01);
            for k in 0..20000 {
                let mut s = SobolSampler::new(3, pass as u64, k);
                let d = square_to_dir(s.next_2d());
                let v = if d.dot(peak) > 0.95 { 50.0 } else { 1.0 };
                rec.record(d, v);
            }
            tree = rec.collect();
        }
        tree
    }

    /// The density integrates to one over the sphere and matches the histogram of the
    /// directions `sample` draws (χ² over 16 × 32 equal-area bins), and `sample` reports the
    /// density `pdf` gives its direction.
    #[test]
    fn sampling_matches_its_density() {
        let peak = Vec3::new(0.3, -0.5, 0.8).normalize();
        let tree = learned(peak, 4);
        assert!(tree.nodes.len() > 20, "the tree subdivided: {} nodes", tree.nodes.len());
        let (nu, nv) = (16usize, 32usize);
        // expected mass per bin by midpoint quadrature of the density (8² points per bin)
        let mut expected = vec![0.0f64; nu * nv];
        let k = 8;
        for (b, e) in expected.iter_mut().enumerate() {
            let (bu, bv) = (b % nu, b / nu);
            for i in 0..k * k {
                let p = Vec2::new(
                    (bu as f32 + ((i % k) as f32 + 0.5) / k as f32) / nu as f32,
                    (bv as f32 + ((i / k) as f32 + 0.5) / k as f32) / nv as f32,
                );
                *e += tree.pdf(square_to_dir(p)) as f64 * 4.0 * std::f64::consts::PI / (nu * nv * k * k) as f64;
            }
        }
        let mass: f64 = expected.iter().sum();
        assert!((mass - 1.0).abs() < 1e-3, "the density integrates to {mass}");
        let n = 200_000;
        let mut hist = vec![0.0f64; nu * nv];
        for i in 0..n {
            let mut s = SobolSampler::new(11, 7, i);
            let (d, pdf) = tree.sample(s.next_2d());
            let rel = (pdf - tree.pdf(d)).abs() / pdf;
            assert!(rel < 1e-3, "sample reports {pdf}, pdf gives {}", tree.pdf(d));
            let p = dir_to_square(d);
            let b = ((p.x * nu as f32) as usize).min(nu - 1) + nu * ((p.y * nv as f32) as usize).min(nv - 1);
            hist[b] += 1.0;
        }
        let (mut chi2, mut dof) = (0.0, 0);
        for (o, e) in hist.iter().zip(&expected) {
            let e = e * n as f64;
            if e > 5.0 {
                chi2 += (o - e) * (o - e) / e;
                dof += 1;
            }
        }
        // χ² with `dof` degrees of freedom: mean dof, sd √(2 dof); 5 sd above the mean
        let limit = dof as f64 + 5.0 * (2.0 * dof as f64).sqrt();
        assert!(chi2 < limit, "χ² = {chi2} over {dof} bins (limit {limit})");
        // and the lobe is where the density is: ≫ uniform at the peak
        assert!(tree.pdf(peak) > 10.0 / (4.0 * PI), "pdf at the peak {}", tree.pdf(peak));
    }

    /// Refinement follows the energy: a quadrant above rho is split, the rest merged; the
    /// recorded totals are the records' sum whatever their order.
    #[test]
    fn refinement_follows_the_energy_and_sums_are_order_free() {
        let peak = Vec3::new(0.0, 0.0, 1.0);
        let tree = learned(peak, 3);
        let rec = tree.refined(0.01);
        assert!(rec.nodes() > 8);
        // no energy: the layout is kept
        let empty = DTree::default().refined(0.01);
        assert_eq!(empty.nodes(), 1);
        // order-free sums
        let dirs: Vec<Vec3> =
            (0..500).map(|i| square_to_dir(Vec2::new((i as f32 * 0.618) % 1.0, (i as f32 * 0.271) % 1.0))).collect();
        let a = tree.refined(0.01);
        let b = tree.refined(0.01);
        for (i, d) in dirs.iter().enumerate() {
            a.record(*d, 0.1 + i as f32 * 0.37);
        }
        for (i, d) in dirs.iter().enumerate().rev() {
            b.record(*d, 0.1 + i as f32 * 0.37);
        }
        let (ta, tb) = (a.collect(), b.collect());
        assert_eq!(ta.total().to_bits(), tb.total().to_bits());
        let expect: f32 = (0..500).map(|i| 0.1 + i as f32 * 0.37).sum();
        assert!((ta.total() - expect).abs() < 1e-3 * expect);
    }
}
