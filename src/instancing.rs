//! Instancing: a mesh stored once, in its object space, and placed any number of times by
//! affine transforms — the two-level acceleration structure of Embree, Cycles and pbrt-v4.
//!
//! The top level is obvhs' compressed wide BVH over the instances' world-space bounds; each
//! of its leaves names an instance, whose prototype has its own bottom-level `Accel` over the
//! prototype's triangles. A ray reaching a leaf is carried into the prototype's object space
//! (o' = M⁻¹o, d' = M⁻¹d, not renormalised, so that distances t stay those of the world-space
//! ray) and traced there; the closest hit so far bounds the rest of the traversal.
//!
//! Everything that reads a hit (`Scene::interaction`) takes the triangle's vertices, normals
//! and tangents back to world space with the instance's transform (`Instance::point`,
//! `Instance::normal`, `Instance::vector`), so that an instanced scene renders as its
//! flattened copy.

use crate::accel::{Accel, TriHit};
use crate::scene::MeshDesc;
use glam::{Affine3A, UVec2, Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;
use obvhs::BvhBuildParams;
use rayon::prelude::*;
use std::ops::Range;
use std::time::Duration;

/// One placement of a prototype.
#[derive(Clone, Copy, Debug)]
pub struct Instance {
    /// Object to world.
    pub to_world: Affine3A,
    /// World to object (its inverse).
    pub to_object: Affine3A,
    /// The prototype placed.
    pub proto: u32,
}

impl Instance {
    /// The instance of a row-major 3×4 object-to-world matrix; None where the matrix is
    /// singular (a zero scale: the instance has no surface to hit) or not finite.
    pub fn new(m: &[f32; 12], proto: u32) -> Option<Instance> {
        let to_world =
            Affine3A::from_cols_array(&[m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10], m[3], m[7], m[11]]);
        let det = to_world.matrix3.determinant();
        if !(det.abs() > 1e-30) || !to_world.is_finite() {
            return None;
        }
        let to_object = to_world.inverse();
        to_object.is_finite().then_some(Instance { to_world, to_object, proto })
    }

    /// A point of the prototype in world space.
    #[inline]
    pub fn point(&self, p: Vec3) -> Vec3 {
        self.to_world.transform_point3(p)
    }

    /// A direction (tangent) of the prototype in world space.
    #[inline]
    pub fn vector(&self, v: Vec3) -> Vec3 {
        self.to_world.transform_vector3(v)
    }

    /// A normal of the prototype in world space (by the inverse transpose: on the side the
    /// prototype's normal is, also for a mirroring transform), not normalised.
    #[inline]
    pub fn normal(&self, n: Vec3) -> Vec3 {
        Vec3::from(self.to_object.matrix3.transpose() * Vec3A::from(n))
    }

    /// The transform mirrors (negative determinant): the handedness of tangent frames flips.
    #[inline]
    pub fn mirrors(&self) -> bool {
        self.to_world.matrix3.determinant() < 0.0
    }

    /// World-space bounds of the object-space box [lo, hi] (its eight corners placed).
    fn bounds(&self, lo: Vec3, hi: Vec3) -> Aabb {
        let mut b = Aabb::INVALID;
        for k in 0..8 {
            let c = Vec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            b.extend(self.point(c).into());
        }
        b
    }
}

/// A mesh stored once: its bottom-level BVH and the scene index of its first triangle (its
/// triangles are the scene's `first..first + n`, in object space).
struct Prototype {
    accel: Option<Accel>,
    first: u32,
    /// Object-space bounds of its triangles.
    bounds: (Vec3, Vec3),
}

/// The instances of a scene and their two-level BVH.
pub struct Instances {
    protos: Vec<Prototype>,
    instances: Vec<Instance>,
    /// The top level over the instances' distinct world bounds; its primitive indices name
    /// groups of instances with the same bounds (almost always one each): group g is
    /// `by_group[group_start[g]..group_start[g + 1]]`.
    tlas: CwBvh,
    group_start: Vec<u32>,
    by_group: Vec<u32>,
    /// World bounds of all instances.
    pub bounds: (Vec3, Vec3),
}

impl Instances {
    /// Builds the bottom level of each prototype (`protos[k]`: the range of the scene's
    /// triangles `tris` that is prototype k) and the top level over `instances` (none of
    /// which places an empty prototype).
    pub fn build(tris: &[[Vec3; 3]], protos: &[Range<usize>], instances: Vec<Instance>) -> Instances {
        let protos: Vec<Prototype> = protos
            .iter()
            .map(|r| {
                let (mut a, mut b) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
                for v in tris[r.clone()].iter().flatten() {
                    (a, b) = (a.min(*v), b.max(*v));
                }
                Prototype {
                    accel: (!r.is_empty()).then(|| Accel::build(&tris[r.clone()])),
                    first: r.start as u32,
                    bounds: (a, b),
                }
            })
            .collect();
        let mut out = Instances {
            protos,
            instances: Vec::new(),
            tlas: CwBvh::default(),
            group_start: Vec::new(),
            by_group: Vec::new(),
            bounds: (Vec3::ZERO, Vec3::ZERO),
        };
        out.place(instances);
        out
    }

    /// Places the prototypes by `instances` instead, keeping their bottom levels: the top
    /// level is built again (a moved instancer in the viewport).
    pub fn place(&mut self, mut instances: Vec<Instance>) {
        // (a prototype whose triangles are all degenerate places nothing)
        instances.retain(|i| self.protos[i.proto as usize].accel.is_some());
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let boxes: Vec<Aabb> = instances
            .iter()
            .map(|i| {
                let (a, b) = self.protos[i.proto as usize].bounds;
                let bx = i.bounds(a, b);
                (lo, hi) = (lo.min(bx.min.into()), hi.max(bx.max.into()));
                bx
            })
            .collect();
        // Instances with bit-identical bounds (a scatter onto coincident points) share one
        // primitive of the top level: PLOC pairs mutual nearest neighbours and merges one pair
        // of identical boxes per round, quadratic in them (as for copies of a triangle,
        // `accel::unique_triangles`).
        let key = |b: &Aabb| [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z].map(f32::to_bits);
        let mut by_group: Vec<u32> = (0..instances.len() as u32).collect();
        by_group.par_sort_unstable_by_key(|&i| (key(&boxes[i as usize]), i));
        let mut group_start = Vec::with_capacity(instances.len() + 1);
        let mut group_boxes = Vec::with_capacity(instances.len());
        for (k, &i) in by_group.iter().enumerate() {
            if k == 0 || key(&boxes[by_group[k - 1] as usize]) != key(&boxes[i as usize]) {
                group_start.push(k as u32);
                group_boxes.push(boxes[i as usize]);
            }
        }
        group_start.push(by_group.len() as u32);
        drop(boxes);
        self.tlas = build_cwbvh(&group_boxes, BvhBuildParams::medium_build(), &mut Duration::default());
        (self.instances, self.group_start, self.by_group, self.bounds) = (instances, group_start, by_group, (lo, hi));
    }

    /// The instances of top-level primitive `p` (a group of instances with equal bounds).
    #[inline]
    fn group(&self, p: u32) -> &[u32] {
        let g = self.tlas.primitive_indices[p as usize] as usize;
        &self.by_group[self.group_start[g] as usize..self.group_start[g + 1] as usize]
    }

    /// Instance `i`.
    #[inline]
    pub fn get(&self, i: u32) -> &Instance {
        &self.instances[i as usize]
    }

    pub fn len(&self) -> usize {
        self.instances.len()
    }

    pub fn is_empty(&self) -> bool {
        self.instances.is_empty()
    }

    /// The closest hit of an instanced triangle along the ray in (tmin, tmax): its scene
    /// triangle index, and the instance in `TriHit::inst`.
    #[inline]
    pub fn closest(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<TriHit> {
        let d = d + Vec3::ZERO; // (negative zeros made positive, as `Accel` does)
        let mut ray = Ray::new(o.into(), d.into(), tmin, tmax);
        let mut best = None;
        let mut state = self.tlas.new_traversal(ray.direction);
        let mut node;
        obvhs::traverse!(self.tlas, node, state, node.intersect_ray(&ray, state.oct_inv4), {
            for &i in self.group(state.primitive_id) {
                let inst = &self.instances[i as usize];
                let proto = &self.protos[inst.proto as usize];
                let (lo, ld) = (inst.to_object.transform_point3(o), inst.to_object.transform_vector3(d));
                if let Some(h) = proto.accel.as_ref().and_then(|a| a.closest(lo, ld, tmin, ray.tmax)) {
                    ray.tmax = h.t;
                    best = Some(TriHit { prim: h.prim + proto.first, inst: i, ..h });
                }
            }
        });
        best
    }

    /// Whether any instanced triangle lies along the ray in (tmin, tmax).
    #[inline]
    pub fn occluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        let d = d + Vec3::ZERO;
        let ray = Ray::new(o.into(), d.into(), tmin, tmax);
        let mut state = self.tlas.new_traversal(ray.direction);
        let mut node;
        'traversal: {
            obvhs::traverse!(self.tlas, node, state, node.intersect_ray(&ray, state.oct_inv4), {
                for &i in self.group(state.primitive_id) {
                    let inst = &self.instances[i as usize];
                    let proto = &self.protos[inst.proto as usize];
                    let (lo, ld) = (inst.to_object.transform_point3(o), inst.to_object.transform_vector3(d));
                    if proto.accel.as_ref().is_some_and(|a| a.occluded(lo, ld, tmin, tmax)) {
                        break 'traversal true;
                    }
                }
            });
            false
        }
    }
}

/// Mesh `m` placed in world space by the row-major 3×4 matrix `xf`, as one mesh of its own
/// (no `transforms`): positions by the matrix, normals by its inverse transpose, and, for a
/// mirroring matrix, each triangle's corners reversed, so that its winding still gives the
/// outside (what an exporter flattening the instance does, and how Cycles treats negatively
/// scaled objects). None where the matrix is singular or not finite.
pub fn flattened(m: &MeshDesc, xf: &[f32; 12]) -> Option<MeshDesc> {
    let inst = Instance::new(xf, 0)?;
    let mirror = inst.mirrors();
    let corners = |c: &[[f32; 3]], f: &dyn Fn(Vec3) -> Vec3| -> Vec<[f32; 3]> {
        let mut out: Vec<[f32; 3]> = c.iter().map(|v| f(Vec3::from_array(*v)).to_array()).collect();
        if mirror {
            out.chunks_exact_mut(3).for_each(|t| t.reverse());
        }
        out
    };
    let mut uvs = m.corner_uvs.clone();
    if mirror {
        uvs.chunks_exact_mut(3).for_each(|t| t.reverse());
    }
    let same = |v: Vec3| v;
    Some(MeshDesc {
        name: m.name.clone(),
        positions: m.positions.iter().map(|p| inst.point(Vec3::from_array(*p)).to_array()).collect(),
        transforms: Vec::new(),
        indices: if mirror { m.indices.iter().map(|&[a, b, c]| [c, b, a]).collect() } else { m.indices.clone() },
        corner_normals: corners(&m.corner_normals, &|n| inst.normal(n)),
        corner_uvs: uvs,
        corner_colors: corners(&m.corner_colors, &same),
        corner_generated: corners(&m.corner_generated, &same),
        corner_object: corners(&m.corner_object, &same),
        ..m.clone_without_geometry()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};

    /// Issue 49: 20,000 instances placed by one transform (a scatter onto coincident points)
    /// are one primitive of the top level, as PLOC would merge their identical boxes one pair
    /// per round; rays meet what they meet in the placed triangles, tested one by one.
    #[test]
    fn instances_with_equal_bounds_share_a_top_level_primitive() {
        let tet = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let tris: Vec<[Vec3; 3]> = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]].map(|f| f.map(|i| tet[i])).to_vec();
        let mut s = IndependentSampler::new(5, 0);
        let mut r = |k: f32| (s.next_1d() - 0.5) * k;
        let same = [0.5, 0.1, 0.0, 1.0, 0.0, 0.6, 0.0, -2.0, 0.0, 0.0, 0.4, 0.5];
        let mut xfs = vec![same; 20_000];
        for _ in 0..30 {
            xfs.push([0.4, 0.0, 0.0, r(8.0), 0.0, 0.4, 0.0, r(8.0), 0.0, 0.0, -0.4, r(8.0)]);
        }
        let placed: Vec<Instance> = xfs.iter().map(|m| Instance::new(m, 0).unwrap()).collect();
        let protos = vec![std::ops::Range { start: 0, end: 4 }];
        let inst = Instances::build(&tris, &protos, placed.clone());
        assert_eq!(inst.group_start.len() - 1, 31);
        // every placed triangle, for brute force
        let world: Vec<[Vec3; 3]> = placed
            .iter()
            .take(1)
            .chain(&placed[20_000..])
            .flat_map(|i| tris.iter().map(move |t| t.map(|p| i.point(p))))
            .collect();
        for _ in 0..400 {
            let o = Vec3::new(r(12.0), r(12.0), r(12.0));
            let d = (Vec3::new(r(4.0), r(4.0), r(4.0)) - o).normalize();
            let want = world
                .iter()
                .filter_map(|t| {
                    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
                    let p = d.cross(e2);
                    let det = e1.dot(p);
                    let s = o - t[0];
                    let (u, q) = (s.dot(p) / det, s.cross(e1));
                    let (v, tt) = (d.dot(q) / det, e2.dot(q) / det);
                    (det != 0.0 && u >= 0.0 && v >= 0.0 && u + v <= 1.0 && tt > 0.0).then_some(tt)
                })
                .fold(f32::INFINITY, f32::min);
            let got = inst.closest(o, d, 0.0, f32::INFINITY).map_or(f32::INFINITY, |h| h.t);
            assert!(got == want || (got - want).abs() <= 1e-4 * (1.0 + want), "{got} against {want}");
            assert_eq!(inst.occluded(o, d, 0.0, f32::INFINITY), want.is_finite());
        }
    }
}
