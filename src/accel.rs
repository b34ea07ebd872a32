//! Ray–triangle acceleration: obvhs' compressed wide BVH (CWBVH, Ylitie et al. 2017) behind
//! two calls, closest hit and occlusion. Triangles are stored in BVH leaf order for locality.

use glam::{UVec2, Vec3, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use std::time::Duration;

/// A hit: triangle index (scene order), distance and barycentrics of v1 and v2.
#[derive(Clone, Copy, Debug)]
pub struct TriHit {
    pub prim: u32,
    pub t: f32,
    pub b1: f32,
    pub b2: f32,
}

#[derive(Clone, Copy)]
struct LeafTri {
    v0: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
}

pub struct Accel {
    bvh: CwBvh,
    leaf_tris: Vec<LeafTri>,
    leaf_prim: Vec<u32>,
    /// Whether the traversal prefetches (only when the BVH outgrows the caches: on small
    /// scenes everything is cached and the prefetches are pure overhead, −7% on the Cornell box).
    prefetch: bool,
}

/// BVH sizes (nodes + leaf triangles) above this are prefetched during traversal.
const PREFETCH_ABOVE_BYTES: usize = 1 << 20;

/// Möller–Trumbore (1997). Returns (t, b1, b2) inside (tmin, tmax).
#[inline(always)]
fn intersect(tri: &LeafTri, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let p = d.cross(tri.e2);
    let det = tri.e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - tri.v0;
    let b1 = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&b1) {
        return None;
    }
    let q = s.cross(tri.e1);
    let b2 = d.dot(q) * inv;
    if b2 < 0.0 || b1 + b2 > 1.0 {
        return None;
    }
    let t = tri.e2.dot(q) * inv;
    if t > tmin && t < tmax {
        Some((t, b1, b2))
    } else {
        None
    }
}

/// Which children of a CWBVH node the ray's segment meets, as the traversal's hit mask
/// (Ylitie et al. 2017, §3.2): the quantized child boxes are slab-tested in the node's frame.
/// The x86-64-v3 build tests all eight children in one AVX2 pass (the byte bounds widened
/// to floats by one instruction per axis); elsewhere obvhs' SSE test (two passes of four).
#[inline(always)]
fn node_hits(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        // SAFETY: compiled only when the target has AVX2 (the v3 module, loaded only on CPUs
        // that report it); loads read exactly the node's eight-byte arrays.
        unsafe { node_hits_avx2(node, ray, oct_inv4) }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        node.intersect_ray(ray, oct_inv4)
    }
}

#[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
#[inline(always)]
unsafe fn node_hits_avx2(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
    use std::arch::x86_64::*;
    #[inline(always)]
    unsafe fn widen(v: &[u8; 8]) -> __m256 {
        _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(v.as_ptr() as *const __m128i)))
    }
    // The same arithmetic as obvhs' test, in the same order (identical hit masks).
    let dir_inv = node.compute_extent() * ray.inv_direction;
    let orig = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    let slab = |lo: &[u8; 8], hi: &[u8; 8], neg: bool, s: f32, o: f32| {
        let (near, far) = if neg { (hi, lo) } else { (lo, hi) };
        let (s, o) = (_mm256_set1_ps(s), _mm256_set1_ps(o));
        (_mm256_add_ps(_mm256_mul_ps(widen(near), s), o), _mm256_add_ps(_mm256_mul_ps(widen(far), s), o))
    };
    let (tnx, tfx) = slab(&node.child_min_x, &node.child_max_x, ray.direction.x < 0.0, dir_inv.x, orig.x);
    let (tny, tfy) = slab(&node.child_min_y, &node.child_max_y, ray.direction.y < 0.0, dir_inv.y, orig.y);
    let (tnz, tfz) = slab(&node.child_min_z, &node.child_max_z, ray.direction.z < 0.0, dir_inv.z, orig.z);
    let tmin = _mm256_max_ps(_mm256_max_ps(tnx, _mm256_max_ps(tny, tnz)), _mm256_set1_ps(1e-4));
    let tmax = _mm256_min_ps(_mm256_min_ps(tfx, _mm256_min_ps(tfy, tfz)), _mm256_set1_ps(ray.tmax));
    let mut mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tmin, tmax)) as u32;
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let mut hits = 0u32;
    while mask != 0 {
        let c = mask.trailing_zeros() * 8;
        mask &= mask - 1;
        hits |= ((child_bits8 >> c) as u32 & 0xff) << ((bit_index8 >> c) as u32 & 0xff);
    }
    hits
}

/// Asks the memory system early for what the traversal will read next: the node's inner
/// children the ray entered and the triangles of the leaves it entered. Incoherent rays on
/// large meshes spend half their time waiting for those loads (perf, 1M triangles).
#[inline(always)]
fn prefetch_children(bvh: &CwBvh, leaf_tris: &[LeafTri], node: &CwBvhNode, hits: u32) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let inner = (hits >> 24).count_ones() as usize;
        if inner > 0 {
            let base = node.child_base_idx as usize;
            let nodes = &bvh.nodes[base.min(bvh.nodes.len())..(base + 8).min(bvh.nodes.len())];
            for n in nodes.iter().take(node.imask.count_ones() as usize) {
                // SAFETY: prefetching a valid reference has no effect on memory.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(n as *const CwBvhNode as *const i8) };
            }
        }
        let mut tri = hits & 0x00ff_ffff;
        while tri != 0 {
            let i = node.primitive_base_idx as usize + tri.trailing_zeros() as usize;
            tri &= tri - 1;
            if let Some(t) = leaf_tris.get(i) {
                // SAFETY: as above.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(t as *const LeafTri as *const i8) };
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (bvh, leaf_tris, node, hits);
}

impl Accel {
    /// Builds the BVH in parallel (rayon) over the triangles.
    pub fn build(tris: &[[Vec3; 3]]) -> Accel {
        let obvhs_tris: Vec<Triangle> =
            tris.iter().map(|t| Triangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() }).collect();
        // obvhs' medium preset: on the 1M-triangle raybench mesh it builds as fast as the fast
        // preset here (0.6 s) and traces a few per cent faster; the slow preset costs 45% more
        // build time for no measurable gain (2026-11-25, `make raybench`).
        let params = BvhBuildParams::medium_build();
        let bvh = build_cwbvh_from_tris(&obvhs_tris, params, &mut Duration::default());
        let leaf_prim: Vec<u32> = bvh.primitive_indices.clone();
        let leaf_tris = leaf_prim
            .iter()
            .map(|&i| {
                let t = &tris[i as usize];
                LeafTri { v0: t[0].into(), e1: (t[1] - t[0]).into(), e2: (t[2] - t[0]).into() }
            })
            .collect();
        let bytes = bvh.nodes.len() * std::mem::size_of::<CwBvhNode>() + tris.len() * std::mem::size_of::<LeafTri>();
        Accel { bvh, leaf_tris, leaf_prim, prefetch: bytes > PREFETCH_ABOVE_BYTES }
    }

    #[inline(always)]
    fn visit(&self, node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
        let hits = node_hits(node, ray, oct_inv4);
        if self.prefetch {
            prefetch_children(&self.bvh, &self.leaf_tris, node, hits);
        }
        hits
    }

    #[inline]
    pub fn closest(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<TriHit> {
        let (oa, da) = (Vec3A::from(o), Vec3A::from(d));
        let mut ray = Ray::new(oa, da, tmin, tmax);
        let (mut prim, mut b1, mut b2) = (u32::MAX, 0.0, 0.0);
        let mut state = self.bvh.new_traversal(da);
        let mut node;
        obvhs::traverse!(self.bvh, node, state, self.visit(node, &ray, state.oct_inv4), {
            let id = state.primitive_id as usize;
            if let Some((t, u, v)) = intersect(&self.leaf_tris[id], oa, da, tmin, ray.tmax) {
                ray.tmax = t;
                (prim, b1, b2) = (id as u32, u, v);
            }
        });
        (prim != u32::MAX).then(|| TriHit { prim: self.leaf_prim[prim as usize], t: ray.tmax, b1, b2 })
    }

    #[inline]
    pub fn occluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        let (oa, da) = (Vec3A::from(o), Vec3A::from(d));
        let ray = Ray::new(oa, da, tmin, tmax);
        let mut state = self.bvh.new_traversal(da);
        let mut node;
        let mut hit = false;
        // (a plain `break` would only leave the macro's inner loop over a leaf's triangles)
        'traversal: {
            obvhs::traverse!(self.bvh, node, state, self.visit(node, &ray, state.oct_inv4), {
                if intersect(&self.leaf_tris[state.primitive_id as usize], oa, da, tmin, tmax).is_some() {
                    hit = true;
                    break 'traversal;
                }
            });
        }
        hit
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};

    fn brute_force(tris: &[[Vec3; 3]], o: Vec3, d: Vec3) -> Option<(u32, f32)> {
        let mut best: Option<(u32, f32)> = None;
        for (i, t) in tris.iter().enumerate() {
            let lt = LeafTri { v0: t[0].into(), e1: (t[1] - t[0]).into(), e2: (t[2] - t[0]).into() };
            if let Some((tt, _, _)) = intersect(&lt, o.into(), d.into(), 0.0, f32::INFINITY) {
                if best.is_none_or(|b| tt < b.1) {
                    best = Some((i as u32, tt));
                }
            }
        }
        best
    }

    /// `n` random small triangles in a 10-unit cube (`r(k)`: uniform in ±k/2).
    fn triangle_soup(r: &mut impl FnMut(f32) -> f32, n: usize) -> Vec<[Vec3; 3]> {
        (0..n)
            .map(|_| {
                let c = Vec3::new(r(10.0), r(10.0), r(10.0));
                [c, c + Vec3::new(r(1.0), r(1.0), r(1.0)), c + Vec3::new(r(1.0), r(1.0), r(1.0))]
            })
            .collect()
    }

    /// The AVX2 node test (x86-64-v3 build) returns exactly obvhs' hit masks, for every node
    /// of a BVH and random rays, including axis-parallel ones (infinite inverse directions).
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    #[test]
    fn avx2_node_test_matches_obvhs() {
        let mut s = IndependentSampler::new(3, 0);
        let mut r = |k: f32| (s.next_1d() - 0.5) * k;
        let tris = triangle_soup(&mut r, 3000);
        let accel = Accel::build(&tris);
        let mut checked = 0;
        for i in 0..400 {
            let o = Vec3::new(r(14.0), r(14.0), r(14.0));
            let mut d = Vec3::new(r(1.0), r(1.0), r(1.0));
            if i % 4 == 0 {
                d[i % 3] = 0.0;
            }
            let ray =
                Ray::new(o.into(), d.normalize().into(), 0.0, if i % 2 == 0 { f32::INFINITY } else { r(20.0).abs() });
            let oct = accel.bvh.new_traversal(ray.direction).oct_inv4;
            for node in &accel.bvh.nodes {
                assert_eq!(node_hits(node, &ray, oct), node.intersect_ray(&ray, oct));
                checked += 1;
            }
        }
        assert!(checked > 10_000);
    }

    #[test]
    fn bvh_agrees_with_brute_force() {
        let mut s = IndependentSampler::new(42, 0);
        let mut r = |k: f32| (s.next_1d() - 0.5) * k;
        let tris = triangle_soup(&mut r, 2000);
        let mut accel = Accel::build(&tris);
        let mut hits = 0;
        for i in 0..3000 {
            accel.prefetch = i % 2 == 0; // both traversal variants
            let o = Vec3::new(r(14.0), r(14.0), r(14.0));
            let d = Vec3::new(r(1.0), r(1.0), r(1.0)).normalize();
            let a = accel.closest(o, d, 0.0, f32::INFINITY);
            let b = brute_force(&tris, o, d);
            match (a, b) {
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert!((a.t - b.1).abs() <= 1e-4 * b.1.max(1.0), "t {} vs {}", a.t, b.1);
                    // the same triangle, unless two triangles are hit at the same distance
                    if a.prim != b.0 {
                        assert!((a.t - b.1).abs() < 1e-5);
                    }
                    assert!(accel.occluded(o, d, 0.0, b.1 * 1.001));
                    assert!(!accel.occluded(o, d, 0.0, b.1 * 0.999));
                }
                (None, None) => assert!(!accel.occluded(o, d, 0.0, f32::INFINITY)),
                (a, b) => panic!("bvh {a:?} vs brute force {b:?}"),
            }
        }
        assert!(hits > 300, "too few hits to be a test: {hits}");
    }
}
