//! Ray–triangle acceleration: obvhs' compressed wide BVH (CWBVH, Ylitie et al. 2017) behind
//! two calls, closest hit and occlusion. The triangles of each node's leaf children are
//! stored in blocks of eight in structure-of-arrays layout, aligned to the node, and tested
//! eight at a time (Möller–Trumbore in SIMD lanes, as Embree's Triangle8 leaves) the moment
//! the node is entered, instead of one by one.

use glam::{UVec2, Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;
use obvhs::BvhBuildParams;
use std::time::Duration;

/// A hit: triangle index (scene order), distance and barycentrics of v1 and v2, and the
/// instance that placed the triangle (`NO_INSTANCE` for a triangle stored in world space).
#[derive(Clone, Copy, Debug)]
pub struct TriHit {
    pub prim: u32,
    pub t: f32,
    pub b1: f32,
    pub b2: f32,
    pub inst: u32,
}

/// `TriHit::inst` of a triangle stored in world space (not instanced).
pub const NO_INSTANCE: u32 = u32::MAX;

/// Lanes of a triangle block.
const LANES: usize = 8;

/// Eight triangles as vertex v0 and edges e1 = v1 − v0, e2 = v2 − v0, one array per
/// coordinate (x, y, z), so that one SIMD load fetches a coordinate of all eight. 288 bytes.
#[derive(Clone, Copy, Default)]
#[repr(C, align(32))]
struct TriBlock {
    v0: [[f32; LANES]; 3],
    e1: [[f32; LANES]; 3],
    e2: [[f32; LANES]; 3],
}

/// The ray segment a block is tested against: origin, direction and the open interval
/// (tmin, tmax) of distances.
#[derive(Clone, Copy)]
struct Segment {
    o: Vec3A,
    d: Vec3A,
    tmin: f32,
    tmax: f32,
}

/// A block test's answer: per lane (det, U, V, T), and the mask of the lanes hit.
type BlockHits = ([[f32; LANES]; 4], u32);

/// Möller–Trumbore (1997) on the eight triangles of a block, without its division: with
/// det = e1·(d × e2), the scaled barycentrics U = s·(d × e2), V = d·(s × e1) and distance
/// T = e2·(s × e1) are compared against det-scaled bounds (b1 = U/det, b2 = V/det, t = T/det),
/// so that only a hit pays for a division. Returns per lane (det, U, V, T) and the mask of
/// lanes in `lanes` hit inside (tmin, tmax). Written lane by lane over fixed-size arrays so
/// that the compiler vectorises it (AVX2 in the x86-64-v3 build, SSE2 pairs in the portable
/// one).
#[cfg_attr(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma"), allow(dead_code))]
#[inline(always)]
fn intersect_block_lanes(b: &TriBlock, lanes: u32, seg: &Segment) -> BlockHits {
    let Segment { o, d, tmin, tmax } = *seg;
    let mut out = [[0.0f32; LANES]; 4];
    let mut ok = [false; LANES];
    for i in 0..LANES {
        let (e1, e2) = ([b.e1[0][i], b.e1[1][i], b.e1[2][i]], [b.e2[0][i], b.e2[1][i], b.e2[2][i]]);
        // p = d × e2, det = e1 · p
        let p = [d.y * e2[2] - d.z * e2[1], d.z * e2[0] - d.x * e2[2], d.x * e2[1] - d.y * e2[0]];
        let det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
        let s = [o.x - b.v0[0][i], o.y - b.v0[1][i], o.z - b.v0[2][i]];
        let u = s[0] * p[0] + s[1] * p[1] + s[2] * p[2];
        // q = s × e1
        let q = [s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0]];
        let v = d.x * q[0] + d.y * q[1] + d.z * q[2];
        let t = e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2];
        // the bounds 0 ≤ b1, 0 ≤ b2, b1 + b2 ≤ 1, tmin < t < tmax, multiplied by |det|
        let (adet, sign) = (det.abs(), if det < 0.0 { -1.0 } else { 1.0 });
        let (us, vs, ts) = (u * sign, v * sign, t * sign);
        // |det| > 0 and finite; every comparison with NaN fails
        ok[i] = adet > 0.0
            && adet < f32::INFINITY
            && us >= 0.0
            && vs >= 0.0
            && us + vs <= adet
            && ts > tmin * adet
            && ts < tmax * adet;
        (out[0][i], out[1][i], out[2][i], out[3][i]) = (det, u, v, t);
    }
    let mut mask = 0u32;
    for (i, &hit) in ok.iter().enumerate() {
        mask |= (hit as u32) << i;
    }
    (out, mask & lanes)
}

/// Möller–Trumbore (as `intersect_block_lanes`) in eight AVX2 + FMA lanes, on whatever the
/// lanes hold: eight triangles against one ray (the ray broadcast: the block test) or one
/// triangle against eight rays (the triangle broadcast: the packet test). Returns per lane
/// (det, U, V, T) and the mask of lanes hit inside (tmin, tmax), as all-ones lanes.
#[cfg(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma"))]
#[inline(always)]
fn moller_trumbore_avx2(
    [ox, oy, oz]: [std::arch::x86_64::__m256; 3],
    [dx, dy, dz]: [std::arch::x86_64::__m256; 3],
    [v0x, v0y, v0z]: [std::arch::x86_64::__m256; 3],
    [e1x, e1y, e1z]: [std::arch::x86_64::__m256; 3],
    [e2x, e2y, e2z]: [std::arch::x86_64::__m256; 3],
    tmin: std::arch::x86_64::__m256,
    tmax: std::arch::x86_64::__m256,
) -> ([std::arch::x86_64::__m256; 4], std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    // SAFETY: compiled only for targets with AVX2 and FMA (the v3 module, loaded only on CPUs
    // that report them); register arithmetic only.
    unsafe {
        // a·b − c·e
        let cross = |a: __m256, b: __m256, c: __m256, e: __m256| _mm256_fmsub_ps(a, b, _mm256_mul_ps(c, e));
        let dot = |ax: __m256, ay: __m256, az: __m256, bx: __m256, by: __m256, bz: __m256| {
            _mm256_fmadd_ps(ax, bx, _mm256_fmadd_ps(ay, by, _mm256_mul_ps(az, bz)))
        };
        let (px, py, pz) = (cross(dy, e2z, dz, e2y), cross(dz, e2x, dx, e2z), cross(dx, e2y, dy, e2x));
        let det = dot(e1x, e1y, e1z, px, py, pz);
        let (sx, sy, sz) = (_mm256_sub_ps(ox, v0x), _mm256_sub_ps(oy, v0y), _mm256_sub_ps(oz, v0z));
        let u = dot(sx, sy, sz, px, py, pz);
        let (qx, qy, qz) = (cross(sy, e1z, sz, e1y), cross(sz, e1x, sx, e1z), cross(sx, e1y, sy, e1x));
        let v = dot(dx, dy, dz, qx, qy, qz);
        let t = dot(e2x, e2y, e2z, qx, qy, qz);
        // |det| and the sign of det applied to U, V, T (xor of the sign bit)
        let sign_bit = _mm256_set1_ps(-0.0);
        let sign = _mm256_and_ps(det, sign_bit);
        let adet = _mm256_andnot_ps(sign_bit, det);
        let (us, vs, ts) = (_mm256_xor_ps(u, sign), _mm256_xor_ps(v, sign), _mm256_xor_ps(t, sign));
        let zero = _mm256_setzero_ps();
        let mut ok = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GT_OQ>(adet, zero),
            _mm256_cmp_ps::<_CMP_LT_OQ>(adet, _mm256_set1_ps(f32::INFINITY)),
        );
        ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_GE_OQ>(us, zero));
        ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_GE_OQ>(vs, zero));
        ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_add_ps(us, vs), adet));
        ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_GT_OQ>(ts, _mm256_mul_ps(tmin, adet)));
        ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_LT_OQ>(ts, _mm256_mul_ps(tmax, adet)));
        ([det, u, v, t], ok)
    }
}

/// The block test in AVX2 + FMA intrinsics (the x86-64-v3 core): half the instructions of
/// the compiler's vectorisation of the lane loop (fused multiply-adds, one movemask).
/// Products are fused, so results may differ from the portable test in the last bits.
#[cfg(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma"))]
#[inline(always)]
fn intersect_block_avx2(b: &TriBlock, lanes: u32, seg: &Segment) -> BlockHits {
    let Segment { o, d, tmin, tmax } = *seg;
    use std::arch::x86_64::*;
    // SAFETY: compiled only for targets with AVX2 and FMA (the v3 module, loaded only on CPUs
    // that report them); TriBlock is 32-byte aligned, so each row is an aligned load.
    unsafe {
        let rows = |r: &[[f32; LANES]; 3]| r.each_ref().map(|x| _mm256_load_ps(x.as_ptr()));
        let splat = |v: Vec3A| [_mm256_set1_ps(v.x), _mm256_set1_ps(v.y), _mm256_set1_ps(v.z)];
        let (res, ok) = moller_trumbore_avx2(
            splat(o),
            splat(d),
            rows(&b.v0),
            rows(&b.e1),
            rows(&b.e2),
            _mm256_set1_ps(tmin),
            _mm256_set1_ps(tmax),
        );
        let mut out = [[0.0f32; LANES]; 4];
        for (row, x) in out.iter_mut().zip(res) {
            _mm256_storeu_ps(row.as_mut_ptr(), x);
        }
        (out, _mm256_movemask_ps(ok) as u32 & lanes)
    }
}

/// The block test of this build: AVX2 + FMA intrinsics where the target has them, else the
/// portable lane loop.
#[inline(always)]
fn intersect_block(b: &TriBlock, lanes: u32, seg: &Segment) -> BlockHits {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma"))]
    {
        intersect_block_avx2(b, lanes, seg)
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma")))]
    {
        intersect_block_lanes(b, lanes, seg)
    }
}

/// The nearest hit among the `lanes` of a block: (lane, t, b1, b2).
#[inline(always)]
fn closest_in_block(b: &TriBlock, lanes: u32, seg: &Segment) -> Option<(u32, f32, f32, f32)> {
    let ([det, u, v, t], mut mask) = intersect_block(b, lanes, seg);
    let (tmin, tmax) = (seg.tmin, seg.tmax);
    let mut best: Option<(u32, f32, f32, f32)> = None;
    while mask != 0 {
        let i = mask.trailing_zeros();
        mask &= mask - 1;
        let k = i as usize;
        let inv = 1.0 / det[k];
        let tk = t[k] * inv;
        // (the quotient is rounded: keep it inside the interval the scaled test accepted)
        if tk > tmin && tk < tmax && best.is_none_or(|h| tk < h.1) {
            best = Some((i, tk, u[k] * inv, v[k] * inv));
        }
    }
    best
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

/// Asks the memory system early for the inner children a ray entered (incoherent rays on
/// large meshes spend half their time waiting for node loads: perf, 1M triangles).
#[inline(always)]
fn prefetch_children(bvh: &CwBvh, node: &CwBvhNode, hits: u32) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        if hits >> 24 != 0 {
            let base = node.child_base_idx as usize;
            let nodes = &bvh.nodes[base.min(bvh.nodes.len())..(base + 8).min(bvh.nodes.len())];
            for n in nodes.iter().take(node.imask.count_ones() as usize) {
                // SAFETY: prefetching a valid reference has no effect on memory.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(n as *const CwBvhNode as *const i8) };
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (bvh, node, hits);
}

/// A scene triangle as obvhs' builder sees it: its bounds.
#[repr(transparent)]
struct BuildTri([Vec3; 3]);

impl obvhs::Boundable for BuildTri {
    #[inline]
    fn aabb(&self) -> Aabb {
        let [a, b, c] = self.0;
        Aabb::new(a.min(b).min(c).into(), a.max(b).max(c).into())
    }
}

/// A scene triangle by reference, for a build over some of them (`unique_triangles`).
struct TriRef<'a>(&'a [Vec3; 3]);

impl obvhs::Boundable for TriRef<'_> {
    #[inline]
    fn aabb(&self) -> Aabb {
        BuildTri(*self.0).aabb()
    }
}

/// The indices of the triangles that are not exact copies of an earlier one (the same three
/// vertices, bit for bit, in any order), or None when none is a copy (the usual case: one
/// hash and a parallel sort, 16 bytes a triangle for the moment).
fn unique_triangles(tris: &[[Vec3; 3]]) -> Option<Vec<u32>> {
    use rayon::prelude::*;
    let key = |t: &[Vec3; 3]| {
        let mut v = t.map(|p| p.to_array().map(f32::to_bits));
        v.sort_unstable();
        v
    };
    let hash = |t: &[Vec3; 3]| {
        key(t).iter().flatten().fold(0xcbf2_9ce4_8422_2325u64, |h, &x| (h ^ x as u64).wrapping_mul(0x0100_0000_01b3))
    };
    let mut order: Vec<(u64, u32)> = tris.par_iter().enumerate().map(|(i, t)| (hash(t), i as u32)).collect();
    order.par_sort_unstable();
    let mut copy: Vec<u32> = Vec::new();
    let mut run = 0;
    while run < order.len() {
        let mut end = run + 1;
        while end < order.len() && order[end].0 == order[run].0 {
            end += 1;
        }
        if end - run > 1 {
            // equal hashes: sorted by vertices, then index, the first of equal triangles is kept
            let mut r: Vec<_> = order[run..end].iter().map(|&(_, i)| (key(&tris[i as usize]), i)).collect();
            r.sort_unstable();
            copy.extend(r.windows(2).filter(|w| w[0].0 == w[1].0).map(|w| w[1].1));
        }
        run = end;
    }
    if copy.is_empty() {
        return None;
    }
    copy.sort_unstable();
    let mut kept = Vec::with_capacity(tris.len() - copy.len());
    let mut c = copy.iter().peekable();
    for i in 0..tris.len() as u32 {
        if c.peek() == Some(&&i) {
            c.next();
        } else {
            kept.push(i);
        }
    }
    Some(kept)
}

pub struct Accel {
    bvh: CwBvh,
    /// Leaf triangles: node n's leaf triangles k = 0..24 (its hit-mask bits) are slot
    /// `n.primitive_base_idx + k`, i.e. lane k % 8 of block `n.primitive_base_idx / 8 + k / 8`
    /// (each node's base is rewritten to a multiple of 8 at build).
    blocks: Vec<TriBlock>,
    /// Scene triangle index of each slot (u32::MAX for padding lanes).
    slot_prim: Vec<u32>,
    /// Whether the traversal prefetches (only when the BVH outgrows the caches: on small
    /// scenes everything is cached and the prefetches are pure overhead, −7% on the Cornell box).
    prefetch: bool,
}

/// BVH sizes (nodes + leaf triangles) above this are prefetched during traversal.
const PREFETCH_ABOVE_BYTES: usize = 1 << 20;

/// Number of leaf triangles a node references (offsets 0..24 from its primitive base):
/// the end of its furthest leaf child (child_meta: low 5 bits the offset, high 3 the count
/// in unary; inner children have offsets 24..32, empty slots are 0).
fn node_leaf_triangles(node: &CwBvhNode) -> usize {
    node.child_meta
        .iter()
        .filter(|&&m| m != 0 && (m & 0x1f) < 24)
        .map(|&m| (m & 0x1f) as usize + (m >> 5).count_ones() as usize)
        .max()
        .unwrap_or(0)
}

impl Accel {
    /// Builds the BVH in parallel (rayon) over the triangles.
    pub fn build(tris: &[[Vec3; 3]]) -> Accel {
        // obvhs' medium preset: on the 1M-triangle raybench mesh it builds as fast as the fast
        // preset here (0.6 s) and traces a few per cent faster; the slow preset costs 45% more
        // build time for no measurable gain (2026-11-25, `make raybench`). Built over the
        // scene's own triangles (`BuildTri`), not a copy of them in obvhs' layout (48 bytes a
        // triangle more at the build's peak).
        let params = BvhBuildParams::medium_build();
        // Exact copies of a triangle are left out of the BVH but the first: a ray meets them
        // all at one distance, and every walk along a ray steps past that distance at once,
        // so only one of them is ever seen either way — while PLOC, which pairs mutual
        // nearest neighbours, merges only one pair of identical boxes per round (32,000
        // copies of one triangle took 18 s, quadratic).
        let kept = unique_triangles(tris);
        let mut bvh = match &kept {
            None => {
                // SAFETY: `BuildTri` is `repr(transparent)` over `[Vec3; 3]`: the same layout.
                let view: &[BuildTri] =
                    unsafe { std::slice::from_raw_parts(tris.as_ptr() as *const BuildTri, tris.len()) };
                build_cwbvh(view, params, &mut Duration::default())
            }
            Some(kept) => {
                let refs: Vec<TriRef> = kept.iter().map(|&i| TriRef(&tris[i as usize])).collect();
                let mut bvh = build_cwbvh(&refs, params, &mut Duration::default());
                bvh.primitive_indices.iter_mut().for_each(|p| *p = kept[*p as usize]);
                bvh
            }
        };
        // Lay each node's leaf triangles out as whole blocks of eight starting at a block
        // boundary, in the order of its hit-mask bits.
        // (sized exactly first: growing by doubling would hold up to twice the blocks at once)
        let count: usize = bvh.nodes.iter().map(|n| node_leaf_triangles(n).div_ceil(LANES)).sum();
        let mut blocks: Vec<TriBlock> = Vec::with_capacity(count);
        let mut slot_prim: Vec<u32> = Vec::with_capacity(count * LANES);
        for node in bvh.nodes.iter_mut() {
            let n = node_leaf_triangles(node);
            if n == 0 {
                continue;
            }
            let old = node.primitive_base_idx as usize;
            node.primitive_base_idx = (blocks.len() * LANES) as u32;
            for g in 0..n.div_ceil(LANES) {
                let mut b = TriBlock::default();
                for lane in 0..LANES {
                    let k = g * LANES + lane;
                    let prim = if k < n { bvh.primitive_indices.get(old + k).copied() } else { None };
                    slot_prim.push(prim.unwrap_or(u32::MAX));
                    let Some(t) = prim.and_then(|p| tris.get(p as usize)) else { continue };
                    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
                    for c in 0..3 {
                        b.v0[c][lane] = t[0][c];
                        b.e1[c][lane] = e1[c];
                        b.e2[c][lane] = e2[c];
                    }
                }
                blocks.push(b);
            }
        }
        bvh.primitive_indices = Vec::new(); // replaced by slot_prim
        let mut accel = Accel { bvh, blocks, slot_prim, prefetch: false };
        accel.prefetch = accel.bytes() > PREFETCH_ABOVE_BYTES;
        accel
    }

    /// Bytes held by the BVH nodes and the triangle blocks.
    pub fn bytes(&self) -> usize {
        self.bvh.nodes.len() * std::mem::size_of::<CwBvhNode>()
            + self.blocks.len() * std::mem::size_of::<TriBlock>()
            + self.slot_prim.len() * 4
    }

    /// The node's child hit mask; with prefetching of the entered inner children on large BVHs.
    #[inline(always)]
    fn visit(&self, node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
        let hits = node_hits(node, ray, oct_inv4);
        if self.prefetch {
            prefetch_children(&self.bvh, node, hits);
        }
        hits
    }

    /// Calls `f(slot, block, lanes)` for each block of the node's leaf triangles that the
    /// hit mask `hits` entered (lanes: the entered triangles of that block).
    #[inline(always)]
    fn for_each_block(&self, node: &CwBvhNode, hits: u32, mut f: impl FnMut(usize, &TriBlock, u32) -> bool) -> bool {
        let mut tri = hits & 0x00ff_ffff;
        let base = node.primitive_base_idx as usize;
        while tri != 0 {
            let g = tri.trailing_zeros() as usize / LANES;
            let lanes = (tri >> (g * LANES)) & 0xff;
            tri &= !(0xff << (g * LANES));
            let slot = base + g * LANES;
            if let Some(b) = self.blocks.get(slot / LANES) {
                if f(slot, b, lanes) {
                    return true;
                }
            }
        }
        false
    }

    #[inline]
    pub fn closest(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<TriHit> {
        let (oa, da) = (Vec3A::from(o), Vec3A::from(positive_zeros(d)));
        let mut ray = Ray::new(oa, da, tmin, tmax);
        let (mut slot, mut b1, mut b2) = (usize::MAX, 0.0, 0.0);
        let mut state = self.bvh.new_traversal(da);
        let mut node;
        // Leaf triangles are tested inside the node step (the macro's per-primitive block
        // stays empty): the node's hit mask goes back with its triangle bits cleared.
        obvhs::traverse!(
            self.bvh,
            node,
            state,
            {
                let hits = self.visit(node, &ray, state.oct_inv4);
                self.for_each_block(node, hits, |s, b, lanes| {
                    let seg = Segment { o: oa, d: da, tmin, tmax: ray.tmax };
                    if let Some((lane, t, u, v)) = closest_in_block(b, lanes, &seg) {
                        ray.tmax = t;
                        (slot, b1, b2) = (s + lane as usize, u, v);
                    }
                    false
                });
                hits & 0xff00_0000
            },
            {}
        );
        let prim = *self.slot_prim.get(slot)?;
        Some(TriHit { prim, t: ray.tmax, b1, b2, inst: NO_INSTANCE })
    }

    #[inline]
    pub fn occluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        let (oa, da) = (Vec3A::from(o), Vec3A::from(positive_zeros(d)));
        let ray = Ray::new(oa, da, tmin, tmax);
        let seg = Segment { o: oa, d: da, tmin, tmax };
        let mut state = self.bvh.new_traversal(da);
        let mut node;
        // (a plain `break` would only leave the macro's inner loop)
        'traversal: {
            obvhs::traverse!(
                self.bvh,
                node,
                state,
                {
                    let hits = self.visit(node, &ray, state.oct_inv4);
                    if self.for_each_block(node, hits, |_, b, lanes| intersect_block(b, lanes, &seg).1 != 0) {
                        break 'traversal true;
                    }
                    hits & 0xff00_0000
                },
                {}
            );
            false
        }
    }
}

/// Up to eight rays traced together: coherent rays (the camera rays of neighbouring samples)
/// share the nodes and triangle tests of one traversal. Lanes `count..8` are unused.
#[derive(Clone, Copy, Debug, Default)]
pub struct RayPacket {
    pub o: [Vec3; LANES],
    pub d: [Vec3; LANES],
    pub tmin: [f32; LANES],
    pub tmax: [f32; LANES],
    pub count: usize,
}

impl Accel {
    /// The closest hit of each ray of the packet, as `closest` would find it for that ray
    /// alone (the same triangle tests, so the same distances and barycentrics; a ray that
    /// meets two triangles at exactly the same distance may be given the other one).
    pub fn closest_packet(&self, rays: &RayPacket) -> [Option<TriHit>; LANES] {
        #[cfg(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma"))]
        {
            self.closest_packet_avx2(rays)
        }
        #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma")))]
        {
            let mut out = [None; LANES];
            for (i, h) in out.iter_mut().enumerate().take(rays.count.min(LANES)) {
                *h = self.closest(rays.o[i], rays.d[i], rays.tmin[i], rays.tmax[i]);
            }
            out
        }
    }

    /// Packet traversal in AVX2 lanes, one ray a lane (Wald et al. 2001; Embree's packet
    /// kernels): each entered node's eight child boxes are slab-tested against all the rays
    /// still in it, leaf children's triangles are tested one at a time against those rays
    /// (the Möller–Trumbore arithmetic of `intersect_block_avx2`, operands swapped: a
    /// triangle broadcast, a ray a lane), and inner children are visited nearest first.
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma"))]
    fn closest_packet_avx2(&self, rays: &RayPacket) -> [Option<TriHit>; LANES] {
        use std::arch::x86_64::*;
        let n = rays.count.min(LANES);
        let mut out = [None; LANES];
        if n == 0 || self.bvh.nodes.is_empty() {
            return out;
        }
        // the rays as rows of lanes: origin x y z, direction x y z, inverse direction x y z,
        // tmin, tmax; unused lanes repeat ray 0 (finite numbers) and stay out of every mask
        let mut soa = [[0.0f32; LANES]; 11];
        for i in 0..LANES {
            let j = if i < n { i } else { 0 };
            let (o, d) = (rays.o[j], positive_zeros(rays.d[j]));
            for c in 0..3 {
                (soa[c][i], soa[3 + c][i], soa[6 + c][i]) = (o[c], d[c], obvhs::ray::safe_inverse(d[c]));
            }
            (soa[9][i], soa[10][i]) = (rays.tmin[j], rays.tmax[j]);
        }
        let all: u32 = (1u32 << n) - 1;
        // SAFETY: compiled only for targets with AVX2 and FMA (the v3 module, loaded only on
        // CPUs that report them); every load and store is of a local array of eight floats.
        unsafe {
            let [ox, oy, oz, dx, dy, dz, ix, iy, iz, tmin, mut tmax] = soa.map(|r| _mm256_loadu_ps(r.as_ptr()));
            let mut best_slot = _mm256_set1_epi32(-1);
            let (mut bu, mut bv) = (_mm256_setzero_ps(), _mm256_setzero_ps());
            // stack of (node, lanes that entered it); a node pushes at most 8 children, so this
            // holds a nearest-first descent 70 levels deep (far beyond any BVH built here; were
            // it full, the rays are traced one by one instead); left uninitialised, as only
            // stack[..top] is ever read (zeroing its 4 KB was 3% of a gdpt render)
            let mut stack = [const { std::mem::MaybeUninit::<(u32, u32)>::uninit() }; 8 * 64];
            let mut top = 1usize;
            let mut overflow = false;
            stack[0].write((0, all));
            while top > 0 {
                top -= 1;
                // SAFETY: every slot below `top` was written before `top` passed it
                let (ni, entered) = stack[top].assume_init();
                let Some(node) = self.bvh.nodes.get(ni as usize) else { continue };
                let e = node.compute_extent();
                let (sx, sy, sz) = (
                    _mm256_mul_ps(_mm256_set1_ps(e.x), ix),
                    _mm256_mul_ps(_mm256_set1_ps(e.y), iy),
                    _mm256_mul_ps(_mm256_set1_ps(e.z), iz),
                );
                let (px, py, pz) = (
                    _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(node.p.x), ox), ix),
                    _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(node.p.y), oy), iy),
                    _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(node.p.z), oz), iz),
                );
                // children entered by some ray: (key = entry distance of the first, slot, lanes)
                let mut kids = [(0.0f32, 0usize, 0u32); 8];
                let mut nk = 0;
                for c in 0..8 {
                    if node.child_meta[c] == 0 {
                        continue;
                    }
                    let slab = |lo: u8, hi: u8, s: __m256, p: __m256| {
                        let a = _mm256_fmadd_ps(_mm256_set1_ps(lo as f32), s, p);
                        let b = _mm256_fmadd_ps(_mm256_set1_ps(hi as f32), s, p);
                        (_mm256_min_ps(a, b), _mm256_max_ps(a, b))
                    };
                    let (nx, fx) = slab(node.child_min_x[c], node.child_max_x[c], sx, px);
                    let (ny, fy) = slab(node.child_min_y[c], node.child_max_y[c], sy, py);
                    let (nz, fz) = slab(node.child_min_z[c], node.child_max_z[c], sz, pz);
                    let near = _mm256_max_ps(_mm256_max_ps(nx, ny), _mm256_max_ps(nz, tmin));
                    let far = _mm256_min_ps(_mm256_min_ps(fx, fy), _mm256_min_ps(fz, tmax));
                    let hit = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(near, far)) as u32 & entered;
                    if hit != 0 {
                        let mut nv = [0.0f32; LANES];
                        _mm256_storeu_ps(nv.as_mut_ptr(), near);
                        kids[nk] = (nv[hit.trailing_zeros() as usize], c, hit);
                        nk += 1;
                    }
                }
                // nearest first (insertion sort of at most eight)
                for i in 1..nk {
                    let mut j = i;
                    while j > 0 && kids[j - 1].0 > kids[j].0 {
                        kids.swap(j - 1, j);
                        j -= 1;
                    }
                }
                // leaves now, nearest first: their hits shorten the rays before the inner
                // children are entered
                for &(_, c, lanes) in &kids[..nk] {
                    let meta = node.child_meta[c];
                    if meta & 0x1f >= 24 {
                        continue;
                    }
                    let lanes_m = {
                        let bits = _mm256_set_epi32(128, 64, 32, 16, 8, 4, 2, 1);
                        _mm256_castsi256_ps(_mm256_cmpeq_epi32(
                            _mm256_and_si256(_mm256_set1_epi32(lanes as i32), bits),
                            bits,
                        ))
                    };
                    let first = node.primitive_base_idx as usize + (meta & 0x1f) as usize;
                    for slot in first..first + (meta >> 5).count_ones() as usize {
                        let Some(b) = self.blocks.get(slot / LANES) else { continue };
                        let k = slot % LANES;
                        let splat = |r: &[[f32; LANES]; 3]| r.each_ref().map(|x| _mm256_set1_ps(x[k]));
                        let ([det, u, v, t], mut ok) = moller_trumbore_avx2(
                            [ox, oy, oz],
                            [dx, dy, dz],
                            splat(&b.v0),
                            splat(&b.e1),
                            splat(&b.e2),
                            tmin,
                            tmax,
                        );
                        ok = _mm256_and_ps(ok, lanes_m);
                        if _mm256_movemask_ps(ok) == 0 {
                            continue;
                        }
                        // the division only for a hit, as `closest_in_block`: t, b1, b2 = (T, U, V)/det
                        let inv_det = _mm256_div_ps(_mm256_set1_ps(1.0), det);
                        let tk = _mm256_mul_ps(t, inv_det);
                        ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_GT_OQ>(tk, tmin));
                        ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_LT_OQ>(tk, tmax));
                        tmax = _mm256_blendv_ps(tmax, tk, ok);
                        bu = _mm256_blendv_ps(bu, _mm256_mul_ps(u, inv_det), ok);
                        bv = _mm256_blendv_ps(bv, _mm256_mul_ps(v, inv_det), ok);
                        best_slot = _mm256_castps_si256(_mm256_blendv_ps(
                            _mm256_castsi256_ps(best_slot),
                            _mm256_castsi256_ps(_mm256_set1_epi32(slot as i32)),
                            ok,
                        ));
                    }
                }
                // inner children, farthest pushed first so that the nearest is popped next
                for &(_, c, lanes) in kids[..nk].iter().rev() {
                    if node.child_meta[c] & 0x1f >= 24 {
                        if top == stack.len() {
                            overflow = true;
                            break;
                        }
                        stack[top].write((node.child_node_index(c), lanes));
                        top += 1;
                    }
                }
            }
            if overflow {
                for (i, h) in out.iter_mut().enumerate().take(n) {
                    *h = self.closest(rays.o[i], rays.d[i], rays.tmin[i], rays.tmax[i]);
                }
                return out;
            }
            let (mut ta, mut ua, mut va, mut sa) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES], [0i32; LANES]);
            _mm256_storeu_ps(ta.as_mut_ptr(), tmax);
            _mm256_storeu_ps(ua.as_mut_ptr(), bu);
            _mm256_storeu_ps(va.as_mut_ptr(), bv);
            _mm256_storeu_si256(sa.as_mut_ptr() as *mut __m256i, best_slot);
            for i in 0..n {
                if let Some(&prim) = self.slot_prim.get(sa[i] as u32 as usize) {
                    if prim != u32::MAX {
                        out[i] = Some(TriHit { prim, t: ta[i], b1: ua[i], b2: va[i], inst: NO_INSTANCE });
                    }
                }
            }
        }
        out
    }
}

/// `d` with its negative zeros made positive (−0 + 0 = +0, the same direction): with −0
/// components (1/−0 = −∞) the traversal missed every triangle of an axis-aligned ray — a
/// flat floor seen straight down through `-Vec3::Z`, say (tested).
#[inline]
fn positive_zeros(d: Vec3) -> Vec3 {
    d + Vec3::ZERO
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};

    /// Scalar Möller–Trumbore in f64, independent of the block test: (t) of the hit, if any.
    fn reference_hit(t: &[Vec3; 3], o: Vec3, d: Vec3) -> Option<f64> {
        let f = |v: Vec3| glam::DVec3::new(v.x as f64, v.y as f64, v.z as f64);
        let (v0, e1, e2, o, d) = (f(t[0]), f(t[1] - t[0]), f(t[2] - t[0]), f(o), f(d));
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det == 0.0 {
            return None;
        }
        let s = o - v0;
        let b1 = s.dot(p) / det;
        let q = s.cross(e1);
        let b2 = d.dot(q) / det;
        let tt = e2.dot(q) / det;
        (b1 >= 0.0 && b2 >= 0.0 && b1 + b2 <= 1.0 && tt > 0.0).then_some(tt)
    }

    fn brute_force(tris: &[[Vec3; 3]], o: Vec3, d: Vec3) -> Option<(u32, f32)> {
        let mut best: Option<(u32, f32)> = None;
        for (i, t) in tris.iter().enumerate() {
            if let Some(tt) = reference_hit(t, o, d) {
                if best.is_none_or(|b| (tt as f32) < b.1) {
                    best = Some((i as u32, tt as f32));
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

    /// Issue 49: exact copies of triangles (20,000 of one, copies of soup triangles with their
    /// vertices rotated, among distinct ones) are left out of the build (32,000 copies of one
    /// took 18 s, quadratic in obvhs' PLOC; 200,000 now 0.05 s, `make bench-scale`'s
    /// neighbour) and every ray finds what brute force finds: the distance, on a kept triangle;
    /// occlusion too.
    #[test]
    fn exact_copies_of_triangles_build_fast_and_are_found_as_brute_force_finds_them() {
        let mut s = IndependentSampler::new(11, 0);
        let mut r = |k: f32| (s.next_1d() - 0.5) * k;
        let mut tris = triangle_soup(&mut r, 2000);
        let one = [Vec3::new(-1.0, -1.0, 0.5), Vec3::new(1.0, -1.0, 0.3), Vec3::new(0.0, 1.5, 0.4)];
        tris.extend(std::iter::repeat_n(one, 20_000));
        for k in 0..500 {
            let t = tris[k * 3];
            tris.push([t[1], t[2], t[0]]); // (the same triangle, its corners rotated)
        }
        let kept = unique_triangles(&tris).expect("copies found");
        assert_eq!(kept.len(), 2001);
        let accel = Accel::build(&tris); // (over the 2001 kept: the builder never sees the copies)
        for _ in 0..500 {
            let o = Vec3::new(r(14.0), r(14.0), r(14.0));
            let d = (Vec3::new(r(2.0), r(2.0), r(2.0)) - o * 0.1).normalize();
            let want = brute_force(&tris, o, d);
            let got = accel.closest(o, d, 0.0, f32::INFINITY);
            match (want, got) {
                (Some((p, t)), Some(h)) => {
                    assert!((h.t - t).abs() <= 1e-4 * (1.0 + t), "t {} against {t}", h.t);
                    assert!(kept.binary_search(&h.prim).is_ok(), "prim {} (against {p}) is a copy", h.prim);
                }
                (None, None) => {}
                (w, g) => panic!("{w:?} against {g:?}"),
            }
            assert_eq!(accel.occluded(o, d, 0.0, f32::INFINITY), want.is_some());
        }
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

    /// Axis-aligned rays whose zero components are negative zeros (−Y = (−0, −1, −0), as
    /// `-Vec3::Y` and many products give) find what the same rays with +0 find, single and
    /// in packets, closest and any hit: a flat quad seen straight on from either side.
    #[test]
    fn negative_zero_direction_components_find_their_hits() {
        let quad = [
            [Vec3::new(-1.0, 2.0, -1.0), Vec3::new(1.0, 2.0, -1.0), Vec3::new(1.0, 2.0, 1.0)],
            [Vec3::new(-1.0, 2.0, -1.0), Vec3::new(1.0, 2.0, 1.0), Vec3::new(-1.0, 2.0, 1.0)],
        ];
        let accel = Accel::build(&quad);
        for (o, d) in [
            (Vec3::new(0.1, 3.0, 0.05), Vec3::new(-0.0, -1.0, -0.0)),
            (Vec3::new(0.1, 1.0, 0.05), Vec3::new(-0.0, 1.0, -0.0)),
            (Vec3::new(0.3, 2.0, 3.0), Vec3::new(-0.0, -0.0, -1.0)),
            (Vec3::new(-3.0, 2.0, 0.2), Vec3::new(1.0, -0.0, -0.0)),
        ] {
            let hit = accel.closest(o, d, 0.0, f32::INFINITY);
            assert!(hit.is_some_and(|h| (o + d * h.t).y == 2.0) || d.y == 0.0 && hit.is_none(), "{o} {d}: {hit:?}");
            if d.y != 0.0 {
                assert!(accel.occluded(o, d, 0.0, f32::INFINITY), "{o} {d}");
                let mut p = RayPacket { count: 3, ..Default::default() };
                for k in 0..3 {
                    (p.o[k], p.d[k], p.tmin[k], p.tmax[k]) = (o, d, 0.0, f32::INFINITY);
                }
                assert!(accel.closest_packet(&p)[..3].iter().all(|h| h.is_some()), "{o} {d}");
            }
        }
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
                    // the barycentrics name the hit point on that triangle
                    let v = &tris[a.prim as usize];
                    let p = v[0] * (1.0 - a.b1 - a.b2) + v[1] * a.b1 + v[2] * a.b2;
                    assert!((p - (o + d * a.t)).length() < 1e-4, "barycentrics {a:?}");
                    assert!(accel.occluded(o, d, 0.0, b.1 * 1.001));
                    assert!(!accel.occluded(o, d, 0.0, b.1 * 0.999));
                }
                (None, None) => assert!(!accel.occluded(o, d, 0.0, f32::INFINITY)),
                (a, b) => panic!("bvh {a:?} vs brute force {b:?}"),
            }
        }
        assert!(hits > 300, "too few hits to be a test: {hits}");
    }

    /// Every triangle lands in a block lane: a ray at each triangle's centroid, along its
    /// normal, finds it (a small mesh with many triangles per leaf, and a large one).
    #[test]
    fn every_triangle_is_found_at_its_centroid() {
        let mut s = IndependentSampler::new(5, 1);
        let mut r = |k: f32| (s.next_1d() - 0.5) * k;
        for n in [1, 7, 9, 30, 5000] {
            let tris = triangle_soup(&mut r, n);
            let accel = Accel::build(&tris);
            assert_eq!(accel.slot_prim.len() % LANES, 0);
            for (i, t) in tris.iter().enumerate() {
                let c = (t[0] + t[1] + t[2]) / 3.0;
                let nrm = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
                let o = c + nrm * 1e-3;
                let h = accel.closest(o, -nrm, 0.0, 2e-3);
                let h = h.unwrap_or_else(|| panic!("triangle {i} of {n} not found"));
                // another triangle may lie in front at this spot only in the soup; then it is nearer
                assert!(h.prim == i as u32 || h.t < 1e-3, "triangle {i}: hit {h:?}");
                assert!(accel.occluded(o, -nrm, 0.0, 2e-3));
            }
        }
    }

    /// The AVX2 + FMA block test (x86-64-v3 core) and the portable lane loop agree: the same
    /// lanes hit (but for rays grazing an edge, where fused rounding may decide otherwise) at
    /// the same distances and barycentrics.
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2", target_feature = "fma"))]
    #[test]
    fn avx2_block_test_matches_the_portable_one() {
        let mut s = IndependentSampler::new(11, 0);
        let mut r = |k: f32| (s.next_1d() - 0.5) * k;
        let (mut hits, mut differ) = (0, 0);
        for _ in 0..20_000 {
            let tris = triangle_soup(&mut r, LANES);
            let mut b = TriBlock::default();
            for (lane, t) in tris.iter().enumerate() {
                let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
                for c in 0..3 {
                    (b.v0[c][lane], b.e1[c][lane], b.e2[c][lane]) = (t[0][c], e1[c], e2[c]);
                }
            }
            // aimed near one of the triangles, so that most rays hit something
            let o = Vec3A::new(r(14.0), r(14.0), r(14.0));
            let aim = tris[((r(1.0) + 0.5) * 7.99) as usize];
            let at = (aim[0] + aim[1] + aim[2]) / 3.0 + Vec3::new(r(0.6), r(0.6), r(0.6));
            let d = (Vec3A::from(at) - o).normalize();
            let tmax = if r(1.0) < 0.0 { f32::INFINITY } else { r(30.0).abs() };
            let seg = Segment { o, d, tmin: 0.0, tmax };
            let (a, ma) = intersect_block_avx2(&b, 0xff, &seg);
            let (p, mp) = intersect_block_lanes(&b, 0xff, &seg);
            differ += (ma ^ mp).count_ones();
            for k in 0..LANES {
                if ma & mp & (1 << k) != 0 {
                    hits += 1;
                    for q in 1..4 {
                        let (x, y) = (a[q][k] / a[0][k], p[q][k] / p[0][k]);
                        assert!((x - y).abs() <= 1e-4 * y.abs().max(1.0), "lane {k}: {x} vs {y}");
                    }
                }
            }
        }
        assert!(hits > 500, "too few hits to be a test: {hits}");
        assert!(differ * 1000 < hits, "{differ} lanes decided differently of {hits} hits");
    }

    /// A packet finds what each of its rays finds alone: the same triangle at the same
    /// distance and barycentrics (bit for bit: the same arithmetic), for coherent packets (the
    /// rays of one small cone, as a pixel's camera rays) and incoherent ones, 1 to 8 rays,
    /// with finite and infinite tmax.
    #[test]
    fn packets_find_what_single_rays_find() {
        let mut s = IndependentSampler::new(21, 0);
        let mut r = |k: f32| (s.next_1d() - 0.5) * k;
        let mut tris = Vec::new();
        let mut accel = Accel::build(&[]);
        let (mut hits, mut ties) = ([0usize; 3], 0);
        for case in 0..3600 {
            // a one-triangle BVH, a one-node one, and a deep one
            let size = [1, 9, 3000][case / 1200];
            if case % 1200 == 0 {
                tris = triangle_soup(&mut r, size);
                accel = Accel::build(&tris);
            }
            let coherent = case % 2 == 0;
            let mut p = RayPacket { count: 1 + case % LANES, ..Default::default() };
            let o = Vec3::new(r(14.0), r(14.0), r(14.0));
            // at a triangle (small meshes are hit only when aimed at)
            let t = tris[((r(1.0) + 0.5) * (tris.len() as f32 - 0.01)) as usize];
            let aim = (t[0] + t[1] + t[2]) / 3.0;
            for i in 0..p.count {
                (p.o[i], p.d[i]) = if coherent {
                    (o, (aim + Vec3::new(r(0.2), r(0.2), r(0.2)) - o).normalize())
                } else {
                    (Vec3::new(r(14.0), r(14.0), r(14.0)), Vec3::new(r(1.0), r(1.0), r(1.0)).normalize())
                };
                p.tmin[i] = if i % 3 == 0 { 0.0 } else { r(2.0).abs() };
                p.tmax[i] = if i % 2 == 0 { f32::INFINITY } else { r(40.0).abs() };
            }
            let got = accel.closest_packet(&p);
            for (i, &got_i) in got.iter().enumerate().take(LANES) {
                let want = if i < p.count { accel.closest(p.o[i], p.d[i], p.tmin[i], p.tmax[i]) } else { None };
                match (got_i, want) {
                    (Some(a), Some(b)) => {
                        hits[case / 1200] += 1;
                        assert_eq!(a.t, b.t, "case {case} ray {i}");
                        if a.prim == b.prim {
                            assert_eq!((a.b1, a.b2), (b.b1, b.b2), "case {case} ray {i}");
                        } else {
                            ties += 1;
                        }
                    }
                    (None, None) => {}
                    (a, b) => panic!("case {case} ray {i}: packet {a:?} vs single {b:?}"),
                }
            }
        }
        assert!(hits.iter().all(|&h| h > 300), "too few hits to be a test: {hits:?}");
        assert!(ties * 1000 <= hits.iter().sum::<usize>(), "{ties} ties of {hits:?}");
    }

    /// The node-aligned blocks waste little to padding: on a mesh with small leaves (a
    /// triangle soup) the BVH holds at most 80 bytes per triangle (nodes, blocks, slot map;
    /// a triangle alone is 40 bytes in a block).
    #[test]
    fn leaf_blocks_stay_compact() {
        let mut s = IndependentSampler::new(8, 2);
        let mut r = |k: f32| (s.next_1d() - 0.5) * k;
        let tris = triangle_soup(&mut r, 20_000);
        let accel = Accel::build(&tris);
        let per_tri = accel.bytes() as f64 / tris.len() as f64;
        let used = tris.len() as f64 / accel.slot_prim.len() as f64;
        assert!(per_tri < 80.0 && used > 0.5, "{per_tri} bytes per triangle, {used} of the lanes used");
    }
}
