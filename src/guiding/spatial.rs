//! The spatial half of the SD-tree (Müller et al. 2017, §4.1): a binary tree over the scene's
//! bounding cube, each node halving its box along x, y, z in turn; each leaf holds the
//! directional distribution learned there ([`DTree`]) and the recorder of the current
//! iteration. A leaf whose records in an iteration exceed c·√(2^k) (k: the iteration, whose
//! sample count is 2^k per pixel) is split, its halves starting from copies of its
//! distribution.

use super::quadtree::{DTree, DTreeRecorder};
use glam::Vec3;

/// Deepest spatial subdivision (each level halves one axis).
const MAX_SPATIAL_DEPTH: u32 = 30;
/// Most leaves (memory bound: a leaf's trees take a few KB).
const MAX_LEAVES: usize = 1 << 14;

#[derive(Clone, Copy, Debug)]
enum SNode {
    /// Children of the lower and upper half along `axis`.
    Inner { axis: u8, child: [u32; 2] },
    /// Index into the leaves.
    Leaf(u32),
}

/// One region's guide: the distribution to sample and the recorder being filled.
#[derive(Clone, Debug, Default)]
pub struct SLeaf {
    pub sampling: DTree,
    pub recorder: DTreeRecorder,
}

/// The spatial tree over the cube [lo, lo + size]³.
#[derive(Clone, Debug)]
pub struct STree {
    lo: Vec3,
    size: f32,
    nodes: Vec<SNode>,
    pub leaves: Vec<SLeaf>,
}

impl STree {
    /// One leaf covering the cube around `center` of half-size `radius` (a little larger, so
    /// that points on the scene's bounds fall inside).
    pub fn new(center: Vec3, radius: f32) -> STree {
        let r = radius.max(1e-3) * 1.01;
        STree {
            lo: center - Vec3::splat(r),
            size: 2.0 * r,
            nodes: vec![SNode::Leaf(0)],
            leaves: vec![SLeaf::default()],
        }
    }

    /// The leaf whose box holds `p` (points outside the cube go to the nearest leaf).
    #[inline]
    pub fn leaf_at(&self, p: Vec3) -> u32 {
        self.descend(p).0
    }

    /// The leaf holding `p` and its depth in the tree.
    #[inline]
    fn descend(&self, p: Vec3) -> (u32, u32) {
        let mut x = ((p - self.lo) / self.size).clamp(Vec3::ZERO, Vec3::splat(1.0 - f32::EPSILON));
        let (mut node, mut depth) = (0usize, 0);
        loop {
            match self.nodes[node] {
                SNode::Leaf(l) => return (l, depth),
                SNode::Inner { axis, child } => {
                    let a = axis as usize;
                    let upper = x[a] >= 0.5;
                    x[a] = if upper { x[a] * 2.0 - 1.0 } else { x[a] * 2.0 };
                    node = child[upper as usize] as usize;
                    depth += 1;
                }
            }
        }
    }

    /// Ends a training iteration: each leaf's recorder becomes its distribution; leaves with
    /// more than `max_records` records are split (each half taken to hold half of them) until
    /// none has; then every leaf lays out its next recorder by `rho`.
    pub fn refine(&mut self, max_records: f64, rho: f32) {
        for leaf in &mut self.leaves {
            leaf.sampling = leaf.recorder.collect();
        }
        // split, depth first from the root: (node, depth, records ascribed to the node)
        let mut stack: Vec<(usize, u32, f64)> = vec![(0, 0, f64::NAN)];
        while let Some((node, depth, ascribed)) = stack.pop() {
            match self.nodes[node] {
                SNode::Inner { child, .. } => {
                    stack.push((child[0] as usize, depth + 1, f64::NAN));
                    stack.push((child[1] as usize, depth + 1, f64::NAN));
                }
                SNode::Leaf(l) => {
                    let records =
                        if ascribed.is_nan() { self.leaves[l as usize].sampling.records as f64 } else { ascribed };
                    if records <= max_records || depth >= MAX_SPATIAL_DEPTH || self.leaves.len() >= MAX_LEAVES {
                        continue;
                    }
                    let copy = self.leaves[l as usize].clone();
                    let l2 = self.leaves.len() as u32;
                    self.leaves.push(copy);
                    let n = self.nodes.len() as u32;
                    self.nodes.push(SNode::Leaf(l));
                    self.nodes.push(SNode::Leaf(l2));
                    self.nodes[node] = SNode::Inner { axis: (depth % 3) as u8, child: [n, n + 1] };
                    stack.push((n as usize, depth + 1, records * 0.5));
                    stack.push((n as usize + 1, depth + 1, records * 0.5));
                }
            }
        }
        for leaf in &mut self.leaves {
            leaf.recorder = leaf.sampling.refined(rho);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Leaves split where the records are: many records near one corner deepen the tree
    /// there more than at the far corner; a point finds the leaf that holds it.
    #[test]
    fn splits_follow_the_records() {
        let mut t = STree::new(Vec3::ZERO, 1.0);
        let near = Vec3::new(-0.9, -0.9, -0.9);
        let far = Vec3::new(0.9, 0.9, 0.9);
        for _ in 0..3 {
            for i in 0..4000 {
                let p = near + Vec3::new((i % 10) as f32, ((i / 10) % 10) as f32, (i / 100) as f32) * 0.002;
                let l = t.leaf_at(p);
                t.leaves[l as usize].recorder.record(Vec3::Z, 1.0);
            }
            let l = t.leaf_at(far);
            t.leaves[l as usize].recorder.record(Vec3::Z, 1.0);
            t.refine(500.0, 0.01);
        }
        // (the first split ascribes half the records to each half, as the paper does, so the
        // far corner is split too in the first refinement, and only then left alone)
        let (dn, df) = (t.descend(near).1, t.descend(far).1);
        assert!(dn >= df + 3, "depth near the records {dn}, far from them {df}");
        assert!(t.leaves.len() > 4);
        // every leaf is reached by some point in its box: leaf_at is consistent with the splits
        let l = t.leaf_at(near);
        assert!(t.leaves[l as usize].sampling.total() > 0.0);
    }
}
