//! The renderable scene: triangles in a BVH, materials, lights (analytic and emissive
//! triangles), camera and world. `Scene::build` is the one place a scene is made.

mod build;
pub mod builtin;
pub mod camera;
pub mod desc;
pub mod emit;
pub mod environment;
pub mod light;
pub mod light_select;
pub mod light_tree;
pub mod material;
pub mod procedural;
mod tangent;
pub mod terminator;
pub mod texture;

pub use camera::{Camera, CameraRay};
pub use desc::*;
pub use light::{Light, LightSample, LightShape};
pub use material::Material;
pub use texture::Texture;

use crate::accel::{Accel, RayPacket, TriHit, NO_INSTANCE};
use crate::bsdf::Bsdf;
use crate::error::SceneError;
use crate::instancing::{Instance, Instances};
use crate::math::{ray_epsilon, square_to_triangle, Frame, Spectrum};
use crate::medium::{Crossings, Flight, FreeFlight, Medium, MediumStack};
use build::{Lighting, Shading, Triangles, RAY_CAMERA_INVISIBLE, RAY_HOLDOUT, RAY_SHADOW_INVISIBLE};
use environment::Environment;
use glam::{Vec2, Vec3, Vec4};
use material::RayKind;
use procedural::Space;
/// At most this many objects a ray does not see are skipped along one ray (camera rays past
/// camera-invisible objects, shadow rays past shadow-invisible ones).
const MAX_INVISIBLE_CROSSINGS: u32 = 64;
pub use texture::TexCoord;

/// A surface point found by a ray.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceInteraction {
    pub p: Vec3,
    /// Geometric normal, flipped to the side the ray came from.
    pub ng: Vec3,
    /// Shading frame (shading normal, also on the ray's side).
    pub frame: Frame,
    pub prim: u32,
    /// The instance that placed the triangle (`accel::NO_INSTANCE`: stored in world space).
    pub inst: u32,
    pub material: u32,
    pub t: f32,
    /// The ray arrived on the side the geometric normal points to (outside a closed mesh).
    pub front: bool,
    /// Texture coordinates: the UV map's, Generated and Object (zero where the mesh
    /// has none).
    pub tex: TexCoord,
    /// The mesh's interpolated corner colour (black when it has none).
    pub color: Spectrum,
    /// The shading normal before normal and bump mapping, in the shading frame (+Z where the
    /// material maps none): what bump-shadows its diffuse lobe.
    pub unmapped: Vec3,
    /// The direction back along the ray that arrived, in the shading frame.
    pub wo: Vec3,
    /// The ray that arrived is the camera's (or its continuation straight through
    /// transparent surfaces): what Light Path › Is Camera Ray reads. Set by the path builder.
    pub camera: bool,
    /// The hit's barycentric coordinates of the triangle's second and third vertices.
    pub bary: Vec2,
}

impl SurfaceInteraction {
    /// Origin for a ray leaving towards `dir`, offset off the surface on that side.
    #[inline]
    pub fn spawn_origin(&self, dir: Vec3) -> Vec3 {
        let eps = ray_epsilon(self.p);
        if dir.dot(self.ng) >= 0.0 {
            self.p + self.ng * eps
        } else {
            self.p - self.ng * eps
        }
    }
}

/// What the renderer learned while building the scene, for the user.
#[derive(Clone, Debug, Default)]
pub struct SceneReport {
    pub warnings: Vec<String>,
    /// Triangles stored (an instanced mesh's once).
    pub triangles: usize,
    /// Instances placing the meshes stored once.
    pub instances: usize,
    pub degenerate_triangles: usize,
    pub emissive_triangles: usize,
}

pub struct Scene {
    pub positions: Vec<[Vec3; 3]>,
    geo_normals: Vec<Vec3>,
    /// Per-triangle corner normals; `None` when the triangle is flat-shaded.
    normals: Vec<Option<[Vec3; 3]>>,
    /// Per-triangle corner texture coordinates; `None` without a UV map.
    uvs: Vec<Option<[Vec2; 3]>>,
    /// Per-triangle corner colours; empty when no mesh has them.
    colors: Vec<[Vec3; 3]>,
    /// Per-triangle corner Generated and Object coordinates (procedural textures); each empty
    /// when no mesh has them.
    generated: Vec<[Vec3; 3]>,
    object: Vec<[Vec3; 3]>,
    /// Per-triangle MikkTSpace corner tangents (xyz, bitangent sign) for normal maps; empty
    /// when no normal-mapped mesh has UVs, zero on the triangles of other meshes.
    tangents: Vec<[Vec4; 3]>,
    tri_material: Vec<u32>,
    /// Object Pass Index per triangle (empty: all 0) and material Pass Index per material
    /// (the IndexOB and IndexMA passes).
    tri_pass_index: Vec<u32>,
    /// Per triangle, its object's Shadow Terminator Geometry Offset (empty: all the default).
    tri_terminator: Vec<f32>,
    material_pass_index: Vec<u32>,
    /// Per triangle, the rays that pass through it (`build::RAY_CAMERA_INVISIBLE`,
    /// `RAY_SHADOW_INVISIBLE`); empty when every object is seen by every ray.
    ray_mask: Vec<u8>,
    /// Some object's shadow visibility is off (shadow rays then look for the first surface
    /// that casts one, instead of an any-hit test).
    has_shadow_invisible: bool,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub lights: Vec<Light>,
    /// Which light a shading point samples (light_select.rs).
    selector: light_select::LightSelector,
    /// Light index of each emissive triangle (u32::MAX if not emissive).
    tri_light: Vec<u32>,
    /// Non-triangle lights that a ray can hit (spheres, planes, suns with an angle).
    hittable_lights: Vec<u32>,
    pub camera: Camera,
    /// The world background, a light with index `env_light()` when it is not black.
    pub env: Environment,
    /// What the camera sees where its rays leave the scene when it is not the world: a
    /// textured backdrop (`CameraDesc::backdrop_texture`; a constant one is composited).
    pub backdrop: Option<Environment>,
    /// The BVH of the triangles stored in world space (`0..world_triangles`).
    accel: Option<Accel>,
    world_triangles: usize,
    /// Bounds of the triangles stored in world space.
    world_bounds: (Vec3, Vec3),
    /// How the description's meshes with transforms were placed (`update_transforms`).
    placement: Placement,
    /// The instanced meshes (triangles `world_triangles..`, in object space) and their
    /// two-level BVH.
    instances: Option<Instances>,
    /// Some material lets light through (pass-through lobe): shadow rays then cross such
    /// surfaces instead of stopping (decided once; without it shadow rays stay any-hit tests).
    has_transparency: bool,
    /// Some material has a normal map (decided once: without one, hits never look up
    /// their material to shade).
    has_perturbed_normals: bool,
    /// Some object or material is held out (`is_holdout`).
    has_holdout: bool,
    /// Light linking: each triangle's receiver set and emitter membership (empty: none set),
    /// and each light's membership (`lights_receiver`).
    tri_light_set: Vec<u8>,
    tri_membership: Vec<u64>,
    light_membership: Vec<u64>,
    /// Each material's medium (None: none; `crate::medium`), whether any material has one,
    /// and the media the camera stands in (`media_around`).
    media: Vec<Option<Medium>>,
    has_media: bool,
    /// The world's medium (`SceneDesc::world_volume`): its index in `media`, past the
    /// materials', at the bottom of every stack.
    world_medium: Option<u32>,
    camera_media: MediumStack,
    /// The media each light stands in (`light_media`; empty without media).
    light_media: Vec<MediumStack>,
    pub bounds_center: Vec3,
    pub bounds_radius: f32,
    pub report: SceneReport,
}

/// Peak bytes a stored triangle costs while the scene is built (its arrays, its share of
/// the BVH and the builder's working memory, the description's copy), and an instance
/// (its transforms and its share of the top-level BVH): measured as the peak resident
/// memory above the exported arrays of a 5.1M-triangle mesh with normals and UVs (442 B per
/// triangle, 2026-12-07, `gdmlt_bench instancebench`) and of 10^6 instances, rounded up.
const BUILD_BYTES_PER_TRIANGLE: u64 = 480;
const BUILD_BYTES_PER_INSTANCE: u64 = 400;

/// Refuses a scene whose build would need more memory than is `available` (None: unknown,
/// not refused), saying how much it needs and why, before anything is allocated — rather
/// than an allocation abort halfway through.
fn check_memory(triangles: u64, instances: u64, available: Option<u64>) -> Result<(), SceneError> {
    use crate::integrator::memory::human;
    let need = triangles * BUILD_BYTES_PER_TRIANGLE + instances * BUILD_BYTES_PER_INSTANCE;
    match available {
        Some(have) if need > have => Err(SceneError::Memory(format!(
            "{triangles} triangles to store and {instances} instances need about {} to build and {} is \
             available; keep repeated meshes as instances (Geometry Nodes, collection and particle \
             instances, USD PointInstancers are kept as instances; realized ones are copies), or \
             free memory",
            human(need),
            human(have)
        ))),
        _ => Ok(()),
    }
}

/// How the meshes with transforms are placed: stored once and instanced (two or more
/// transforms, no emitting material), or as world-space copies (`place_meshes`).
#[derive(Clone, Debug, Default)]
struct Placement {
    /// The mesh (index in the description) of each prototype.
    protos: Vec<usize>,
    /// The instances of the prototypes (singular transforms skipped; taken out once placed).
    placed: Vec<Instance>,
    /// The meshes placed as copies, and (kept by the scene) their transforms.
    copied: Vec<usize>,
    copied_transforms: Vec<Vec<[f32; 12]>>,
    /// Instances skipped for a singular transform.
    singular: usize,
}

impl Placement {
    fn of(meshes: &[MeshDesc], materials: &[Material]) -> Result<Placement, SceneError> {
        let emits = |m: &MeshDesc| {
            if m.material_ids.is_empty() {
                materials.first().is_some_and(|x| x.emits())
            } else {
                m.material_ids.iter().any(|&i| materials.get(i as usize).is_some_and(|x| x.emits()))
            }
        };
        let mut p = Placement::default();
        for (i, m) in meshes.iter().enumerate().filter(|(_, m)| !m.transforms.is_empty()) {
            if m.transforms.iter().flatten().any(|x| !x.is_finite()) {
                return Err(SceneError::Mesh {
                    mesh: m.name.clone(),
                    what: "has a NaN or Inf instance transform".into(),
                });
            }
            if m.transforms.len() == 1 || emits(m) {
                p.copied.push(i);
                p.copied_transforms.push(m.transforms.clone());
                p.singular += m.transforms.iter().filter(|xf| Instance::new(xf, 0).is_none()).count();
            } else {
                let k = p.protos.len() as u32;
                let before = p.placed.len();
                p.placed.extend(m.transforms.iter().filter_map(|xf| Instance::new(xf, k)));
                p.singular += m.transforms.len() - (p.placed.len() - before);
                if p.placed.len() > before {
                    p.protos.push(i);
                }
            }
        }
        Ok(p)
    }
}

impl Scene {
    /// Builds a scene from its description, in four steps: the camera; the shading inputs
    /// (textures, materials); the triangles (validated, degenerate ones skipped) and their
    /// BVH; the lighting (lights, emissive triangles, the world, light selection).
    pub fn build(desc: &SceneDesc) -> Result<Scene, SceneError> {
        Self::build_with(desc, desc.meshes.as_slice())
    }

    /// `build`, taking the description: its meshes are freed as soon as their triangles are
    /// laid out, before the BVH is built (80 bytes a triangle less at the build's peak, for
    /// a mesh with normals and UVs).
    pub fn build_from(mut desc: SceneDesc) -> Result<Scene, SceneError> {
        let meshes = std::mem::take(&mut desc.meshes);
        Self::build_with(&desc, meshes)
    }

    fn build_with<M: std::borrow::Borrow<[MeshDesc]>>(desc: &SceneDesc, meshes: M) -> Result<Scene, SceneError> {
        let camera = Camera::new(&desc.camera)?;
        let mut report = SceneReport::default();
        report.warnings.extend(camera::range_warnings(&desc.camera));
        report.warnings.extend(desc.lights.iter().flat_map(light::range_warnings));
        let shading = Shading::new(desc)?;
        report.warnings.extend(shading.warnings.iter().cloned());
        let normal_mapped: Vec<bool> = shading.materials.iter().map(|m| m.normal_texture.is_some()).collect();
        let (tris, instances, placement) = Self::place_meshes(meshes.borrow(), &shading, &normal_mapped, &mut report)?;
        drop(meshes);
        let instances = instances.map(|(ranges, placed)| Instances::build(&tris.positions, &ranges, placed));
        report.instances = instances.as_ref().map_or(0, |i| i.len());
        // Bounds (geometry, lights and camera) for sun power estimates and epsilons.
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for v in tris.positions[..tris.world].iter().flatten() {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
        let world_bounds = (lo, hi);
        if let Some(i) = &instances {
            (lo, hi) = (lo.min(i.bounds.0), hi.max(i.bounds.1));
        }
        lo = lo.min(camera.position());
        hi = hi.max(camera.position());
        let bounds_center = (lo + hi) * 0.5;
        let bounds_radius = ((hi - lo).length() * 0.5).max(1e-3);
        let lighting = Lighting::new(desc, &shading, &tris, bounds_center)?;
        report.emissive_triangles = lighting.emissive_triangles;
        report.warnings.extend(lighting.warning.clone());
        let accel = if tris.world == 0 { None } else { Some(Accel::build(&tris.positions[..tris.world])) };
        let tris_world = tris.world;
        let mut scene = Scene {
            geo_normals: tris.positions.iter().map(|v| (v[1] - v[0]).cross(v[2] - v[0]).normalize()).collect(),
            positions: tris.positions,
            normals: tris.normals,
            uvs: tris.uvs,
            colors: tris.colors,
            generated: tris.generated,
            object: tris.object,
            tangents: tris.tangents,
            tri_material: tris.material,
            tri_pass_index: tris.pass_index,
            tri_terminator: tris.terminator,
            material_pass_index: Vec::new(),
            has_shadow_invisible: tris.ray_mask.iter().any(|m| m & RAY_SHADOW_INVISIBLE != 0),
            ray_mask: tris.ray_mask,
            materials: Vec::new(),
            textures: Vec::new(),
            has_transparency: false,
            has_perturbed_normals: false,
            has_holdout: false,
            tri_light_set: tris.light_set,
            tri_membership: tris.membership,
            light_membership: lighting.membership,
            lights: Vec::new(),
            selector: lighting.selector,
            tri_light: Vec::new(),
            hittable_lights: Vec::new(),
            camera,
            env: lighting.env,
            backdrop: lighting.backdrop,
            accel,
            world_triangles: tris_world,
            world_bounds,
            placement,
            instances,
            media: Vec::new(),
            has_media: false,
            world_medium: None,
            camera_media: MediumStack::default(),
            light_media: Vec::new(),
            bounds_center,
            bounds_radius,
            report,
        };
        scene.lights = lighting.lights;
        scene.tri_light = lighting.tri_light;
        scene.hittable_lights = lighting.hittable_lights;
        scene.set_shading(shading);
        Ok(scene)
    }

    /// The scene's triangles, with the instanced meshes' last (`Triangles::world` on), and
    /// the instances that place them: (each prototype's triangles, the instances), and how
    /// the meshes were placed (`Placement`, kept for `update_transforms`).
    #[allow(clippy::type_complexity)]
    fn place_meshes(
        meshes: &[MeshDesc],
        shading: &Shading,
        normal_mapped: &[bool],
        report: &mut SceneReport,
    ) -> Result<(Triangles, Option<(Vec<std::ops::Range<usize>>, Vec<Instance>)>, Placement), SceneError> {
        let mut placement = Placement::of(meshes, &shading.materials)?;
        let mut copies = Vec::new();
        for &i in &placement.copied {
            let m = &meshes[i];
            copies.extend(m.transforms.iter().filter_map(|xf| crate::instancing::flattened(m, xf)));
        }
        if placement.singular > 0 {
            report.warnings.push(format!(
                "{} instance(s) with a singular (zero-scale) transform were skipped: they have no surface",
                placement.singular
            ));
        }
        let mut order: Vec<&MeshDesc> = meshes.iter().filter(|m| m.transforms.is_empty()).collect();
        order.extend(copies.iter());
        let world_meshes = order.len();
        order.extend(placement.protos.iter().map(|&i| &meshes[i]));
        let stored = order.iter().map(|m| m.indices.len() as u64).sum();
        check_memory(stored, placement.placed.len() as u64, crate::integrator::memory::available())?;
        let mut tris = Triangles::from_meshes(&order, shading.materials.len(), normal_mapped, report)?;
        tris.world = tris.ranges.get(world_meshes).map_or(tris.positions.len(), |r| r.start);
        let mut placed = std::mem::take(&mut placement.placed);
        if placed.is_empty() {
            return Ok((tris, None, placement));
        }
        // (a prototype whose triangles are all degenerate places nothing)
        let ranges: Vec<_> = tris.ranges[world_meshes..].to_vec();
        placed.retain(|i| !ranges[i.proto as usize].is_empty());
        Ok((tris, (!placed.is_empty()).then_some((ranges, placed)), placement))
    }

    /// Places the instanced meshes by the transforms of `desc` (a scene dict of the same
    /// meshes, their transforms moved: a moved instancer in the viewport), keeping the
    /// triangles and the prototypes' BVHs; the top level, the scene's bounds and the lighting
    /// (which reads them) are built again. An error where it takes a full build: a mesh the
    /// core placed as copies (emitting, or placed once) moved, or which meshes are instanced
    /// changed.
    pub fn update_transforms(&mut self, desc: &SceneDesc) -> Result<(), SceneError> {
        let rebuild = |what: &str| SceneError::Mesh {
            mesh: "(viewport update)".into(),
            what: format!("{what}: the scene needs building again"),
        };
        let mut placement = Placement::of(&desc.meshes, &self.materials)?;
        if placement.protos != self.placement.protos {
            return Err(rebuild("other meshes are instanced now"));
        }
        if placement.copied != self.placement.copied
            || placement
                .copied
                .iter()
                .zip(&self.placement.copied_transforms)
                .any(|(&i, old)| &desc.meshes[i].transforms != old)
        {
            return Err(rebuild("a mesh placed as copies moved"));
        }
        let Some(instances) = self.instances.as_mut() else { return Err(rebuild("no instances")) };
        instances.place(std::mem::take(&mut placement.placed));
        self.report.instances = instances.len();
        let (mut lo, mut hi) = self.world_bounds;
        (lo, hi) = (lo.min(instances.bounds.0), hi.max(instances.bounds.1));
        (lo, hi) = (lo.min(self.camera.position()), hi.max(self.camera.position()));
        self.bounds_center = (lo + hi) * 0.5;
        self.bounds_radius = ((hi - lo).length() * 0.5).max(1e-3);
        self.placement = placement;
        self.update_shading(desc)
    }

    /// Replaces the materials, textures, lights and world of a built scene with those of
    /// `desc`, keeping its triangles, BVH and camera: for edits that do not move geometry
    /// (the viewport's material, light and world changes). `desc`'s meshes must be the
    /// ones the scene was built from (the caller checks); their material ids are checked
    /// against the new materials.
    pub fn update_shading(&mut self, desc: &SceneDesc) -> Result<(), SceneError> {
        let shading = Shading::new(desc)?;
        let tris = Triangles {
            ranges: Vec::new(),
            world: self.world_triangles,
            // (before the positions are taken)
            areas: self.positions.iter().map(|v| 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length()).collect(),
            positions: std::mem::take(&mut self.positions),
            material: std::mem::take(&mut self.tri_material),
            normals: Vec::new(),
            uvs: Vec::new(),
            colors: Vec::new(),
            generated: Vec::new(),
            object: Vec::new(),
            tangents: Vec::new(),
            pass_index: Vec::new(),
            ray_mask: Vec::new(),
            terminator: Vec::new(),
            light_set: Vec::new(),
            membership: std::mem::take(&mut self.tri_membership),
        };
        let lighting = match tris.material.iter().max() {
            Some(&m) if m as usize >= shading.materials.len() => Err(SceneError::Mesh {
                mesh: "(viewport update)".into(),
                what: format!("uses material {m} but there are {}", shading.materials.len()),
            }),
            // (an instanced mesh is placed as copies where it emits: `place_meshes`)
            _ if tris.material[tris.world..].iter().any(|&m| shading.materials[m as usize].emits()) => {
                Err(SceneError::Mesh {
                    mesh: "(viewport update)".into(),
                    what: "an instanced mesh's material emits now: the scene needs building again".into(),
                })
            }
            _ => Lighting::new(desc, &shading, &tris, self.bounds_center),
        };
        (self.positions, self.tri_material) = (tris.positions, tris.material);
        self.tri_membership = tris.membership;
        let lighting = lighting?;
        self.light_membership = lighting.membership.clone();
        self.report.emissive_triangles = lighting.emissive_triangles;
        (self.lights, self.selector, self.tri_light) = (lighting.lights, lighting.selector, lighting.tri_light);
        (self.hittable_lights, self.env, self.backdrop) = (lighting.hittable_lights, lighting.env, lighting.backdrop);
        self.set_shading(shading);
        Ok(())
    }

    fn set_shading(&mut self, shading: Shading) {
        (self.materials, self.textures) = (shading.materials, shading.textures);
        self.material_pass_index = shading.pass_index;
        (self.has_transparency, self.has_perturbed_normals) = (shading.has_transparency, shading.has_perturbed_normals);
        self.has_holdout =
            self.materials.iter().any(|m| m.holdout) || self.ray_mask.iter().any(|m| m & RAY_HOLDOUT != 0);
        self.media = shading.media;
        self.has_media = self.media.iter().any(Option::is_some);
        let n = self.materials.len();
        self.world_medium = self.media.get(n).is_some_and(Option::is_some).then_some(n as u32);
        self.camera_media = self.media_around(self.camera.position());
        self.light_media = if self.has_media {
            (0..self.lights.len())
                .map(|li| self.light_position(li).map_or_else(|| self.world_stack(), |p| self.media_around(p)))
                .collect()
        } else {
            Vec::new()
        };
    }

    /// Where light `li` stands (a point of it), None for lights at infinity.
    fn light_position(&self, li: usize) -> Option<Vec3> {
        match &self.lights[li].shape {
            LightShape::Sphere { center, .. } => Some(*center),
            LightShape::Planar { center, .. } => Some(*center),
            LightShape::Triangle { prim, .. } => Some(self.positions[*prim as usize].iter().sum::<Vec3>() / 3.0),
            LightShape::Distant { .. } => None,
        }
    }

    /// Triangle `prim` is held out where the camera sees it (its object's Holdout, or a
    /// Holdout shader): a camera ray, straight or through transparent surfaces, that meets
    /// it ends there, its throughput counted as the film's transparency (Cycles'
    /// `integrate_surface_holdout`; the transparency of an object held out is not kept).
    #[inline]
    pub fn is_holdout(&self, prim: u32) -> bool {
        self.has_holdout
            && (self.masked(prim, RAY_HOLDOUT) || self.materials[self.tri_material[prim as usize] as usize].holdout)
    }

    /// Light linking: whether light `li` lights the object of triangle `receiver` (the
    /// vertex a light sample is taken at, or the one a ray that meets the light left;
    /// u32::MAX: none — a camera ray, which sees every emitter —, as Cycles'
    /// `light_link_object_match`). The world lights everything.
    #[inline]
    pub fn lights_receiver(&self, li: u32, receiver: u32) -> bool {
        if self.light_membership.is_empty() || receiver == u32::MAX {
            return true;
        }
        let set = self.tri_light_set.get(receiver as usize).copied().unwrap_or(0);
        self.light_membership.get(li as usize).is_none_or(|m| m >> set & 1 == 1)
    }

    /// The render has an alpha: a transparent film, or holdouts (which make the film
    /// transparent where the camera sees them, also under an opaque film, as in Cycles).
    pub fn has_alpha(&self) -> bool {
        self.camera.film_transparent || self.has_holdout
    }

    /// The density field of medium `m` at world point `p` (1 for a homogeneous one).
    #[inline]
    pub fn density_at(&self, m: &Medium, p: Vec3) -> f32 {
        match &m.field {
            Some(f) => {
                let (object, generated) = f.density.coordinates(p);
                self.textures[f.density.texture as usize].at_point(object, generated).x
            }
            None => 1.0,
        }
    }

    /// The transmittance of medium `m` along o + t·d over [0, len]: in closed form, or (a
    /// heterogeneous one) by ratio tracking, its numbers drawn from a generator seeded by the
    /// segment itself.
    pub fn medium_transmittance(&self, m: &Medium, o: Vec3, d: Vec3, len: f32) -> Spectrum {
        if !m.is_heterogeneous() {
            return m.transmittance(len);
        }
        let seed = crate::sampler::mix64(
            (o.x.to_bits() as u64) << 32
                ^ (o.y.to_bits() as u64) << 16
                ^ o.z.to_bits() as u64
                ^ (d.x.to_bits() as u64) << 7,
        ) ^ (d.y.to_bits() as u64) << 24
            ^ (d.z.to_bits() as u64);
        let mut rng = crate::sampler::IndependentSampler::new(seed, 0x7a7a);
        m.ratio_tracking(|p| self.density_at(m, p), o, d, len, &mut rng)
    }

    /// A free flight through medium `m` along o + t·d, t ∈ [0, t_max), from primary sample
    /// `u` (`Medium::sample_distance`; a heterogeneous medium tracks with a generator seeded
    /// by it, `medium::heterogeneous`), and the flight's weight at the lights it crosses
    /// (`crossings`: T/P where the flight passed them, 0 past its end).
    pub fn fly(&self, m: &Medium, o: Vec3, d: Vec3, t_max: f32, u: f32, crossings: &mut Crossings) -> Flight {
        let n = crossings.n;
        if m.is_heterogeneous() {
            let mut rng = crate::medium::heterogeneous::rng_from(u, 0xf1e);
            let at = crossings.t;
            let tr = m.track(|p| self.density_at(m, p), (o, d), t_max, &mut rng, &at[..n], &mut crossings.weight[..n]);
            let free = match tr.scatter {
                Some(t) => FreeFlight::Scatter { t, weight: tr.weight },
                None => FreeFlight::Pass { weight: tr.weight },
            };
            return Flight { free, emitted: tr.emitted };
        }
        let free = m.sample_distance(u, t_max);
        let end = match free {
            FreeFlight::Scatter { t, .. } => t,
            FreeFlight::Pass { .. } => f32::INFINITY,
        };
        for i in 0..n {
            let t = crossings.t[i];
            crossings.weight[i] =
                if t < end { m.transmittance(t) / m.pass_probability(t).max(1e-30) } else { Spectrum::ZERO };
        }
        Flight { free, emitted: m.emitted(t_max) }
    }

    /// The material of triangle `prim`.
    #[inline]
    pub fn triangle_material(&self, prim: u32) -> u32 {
        self.tri_material[prim as usize]
    }

    /// The Pass Indices (object, material) of a triangle: Blender's IndexOB and IndexMA.
    pub fn pass_indices(&self, prim: u32) -> (u32, u32) {
        let material = self.tri_material[prim as usize] as usize;
        (
            self.tri_pass_index.get(prim as usize).copied().unwrap_or(0),
            self.material_pass_index.get(material).copied().unwrap_or(0),
        )
    }

    pub fn num_triangles(&self) -> usize {
        self.positions.len()
    }

    /// Closest surface hit along the ray in (tmin, tmax).
    #[inline]
    pub fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<TriHit> {
        let hit = self.accel.as_ref().and_then(|a| a.closest(o, d, tmin, tmax));
        match &self.instances {
            None => hit,
            Some(i) => i.closest(o, d, tmin, hit.map_or(tmax, |h| h.t)).or(hit),
        }
    }

    /// The closest surface hit of each ray of a packet (coherent rays: see `RayPacket`).
    #[inline]
    pub fn intersect_packet(&self, rays: &RayPacket) -> [Option<TriHit>; 8] {
        let mut hits = self.accel.as_ref().map_or([None; 8], |a| a.closest_packet(rays));
        if let Some(inst) = &self.instances {
            for (k, h) in hits.iter_mut().enumerate().take(rays.count.min(8)) {
                let tmax = h.map_or(rays.tmax[k], |h| h.t);
                if let Some(nearer) = inst.closest(rays.o[k], rays.d[k], rays.tmin[k], tmax) {
                    *h = Some(nearer);
                }
            }
        }
        hits
    }

    /// The first hits of up to eight camera rays (of neighbouring samples), traced together
    /// (past objects the camera does not see, as `intersect_camera`).
    pub fn intersect_camera_rays(&self, rays: &[CameraRay]) -> [Option<TriHit>; 8] {
        let mut p = RayPacket { count: rays.len().min(8), ..Default::default() };
        for (k, r) in rays.iter().take(8).enumerate() {
            (p.o[k], p.d[k], p.tmin[k], p.tmax[k]) = (r.origin, r.dir, r.tmin, r.tmax);
        }
        let mut hits = self.intersect_packet(&p);
        if !self.ray_mask.is_empty() {
            for (k, h) in hits.iter_mut().enumerate().take(p.count) {
                if h.is_some_and(|h| self.masked(h.prim, RAY_CAMERA_INVISIBLE)) {
                    *h = self.intersect_camera(p.o[k], p.d[k], p.tmin[k], p.tmax[k]);
                }
            }
        }
        hits
    }

    /// The closest hit of a ray the camera sees along (a camera ray, and its continuation
    /// through transparent surfaces before any scattering): objects whose camera visibility
    /// is off let it pass, as Cycles' visibility flags do.
    pub fn intersect_camera(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<TriHit> {
        let mut hit = self.intersect(o, d, tmin, tmax);
        if self.ray_mask.is_empty() {
            return hit;
        }
        for _ in 0..MAX_INVISIBLE_CROSSINGS {
            match hit {
                Some(h) if self.masked(h.prim, RAY_CAMERA_INVISIBLE) => {
                    hit = self.intersect(o, d, h.t + ray_epsilon(o + d * h.t), tmax);
                }
                _ => return hit,
            }
        }
        None
    }

    /// Triangle `prim` lets the rays of `bit` (a `RAY_*_INVISIBLE`) through.
    #[inline]
    fn masked(&self, prim: u32, bit: u8) -> bool {
        self.ray_mask.get(prim as usize).is_some_and(|m| m & bit != 0)
    }

    /// True when any surface lies along the ray in (tmin, tmax). Lights never occlude.
    #[inline]
    pub fn occluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        self.accel.as_ref().is_some_and(|a| a.occluded(o, d, tmin, tmax))
            || self.instances.as_ref().is_some_and(|i| i.occluded(o, d, tmin, tmax))
    }

    /// The shadow ray from a surface point towards `target` (a point, or for lights at
    /// infinity a unit direction): (origin, direction, tmax). The origin is offset off the
    /// surface and the direction re-aimed from it, so the segment ends just short of the
    /// target. (Aimed from the unoffset point, a grazing ray met the emitter's own plane
    /// before its end and NEE went dark beside lights: measured on the gap scene, where the
    /// plate under the light lost 99% of its direct light.) None when there is no segment.
    pub fn shadow_ray(&self, si: &SurfaceInteraction, target: Vec3, at_infinity: bool) -> Option<(Vec3, Vec3, f32)> {
        self.shadow_ray_from(si, target, at_infinity, false)
    }

    /// `shadow_ray`, its start lifted off a smooth-shaded triangle by the object's shadow
    /// terminator offset where `lift` (a light sample's shadow ray, not a path segment).
    fn shadow_ray_from(
        &self,
        si: &SurfaceInteraction,
        target: Vec3,
        at_infinity: bool,
        lift: bool,
    ) -> Option<(Vec3, Vec3, f32)> {
        let dir = if at_infinity { target } else { target - si.p };
        let mut o = si.spawn_origin(dir);
        if lift {
            o += self.terminator_lift(si, dir);
        }
        if at_infinity {
            return Some((o, target, f32::INFINITY));
        }
        let to = target - o;
        let len = to.length();
        if !(len > 0.0) {
            return None;
        }
        Some((o, to / len, len * (1.0 - 1e-4) - ray_epsilon(target)))
    }

    /// The shadow-terminator lift (terminator.rs) of a light sample's shadow ray towards
    /// `dir` (any length) from `si`: zero unless its triangle is smooth-shaded and lit at a
    /// grazing angle. (Flat triangles return before any arithmetic: most shadow rays.)
    fn terminator_lift(&self, si: &SurfaceInteraction, dir: Vec3) -> Vec3 {
        let t = si.prim as usize;
        // (flat, or no triangle at all: a point in a medium)
        if self.normals.get(t).is_none_or(Option::is_none) {
            return Vec3::ZERO;
        }
        let l = dir.normalize_or_zero();
        let cutoff = self.tri_terminator.get(t).copied().unwrap_or(terminator::DEFAULT_GEOMETRY_OFFSET);
        // (Cycles' sd->N: the interpolated normal before normal and bump maps)
        let (amount, ng) = terminator::lift_amount(si.frame.to_world(si.unmapped), si.ng, l, cutoff);
        if amount <= 0.0 {
            return Vec3::ZERO;
        }
        let b = [1.0 - si.bary.x - si.bary.y, si.bary.x, si.bary.y];
        let (v, n, _) = self.world_triangle(t, self.placed(si.inst));
        let Some(n) = n else { return Vec3::ZERO };
        terminator::smooth_surface_lift(&v, &n, b, ng) * amount
    }

    /// Nothing blocks the shadow segment from a surface point to `target` (a point, or at
    /// infinity a direction); transparent surfaces block it too.
    pub fn segment_clear(&self, si: &SurfaceInteraction, target: Vec3, at_infinity: bool) -> bool {
        self.segment_clear_from(si, target, at_infinity, false)
    }

    fn segment_clear_from(&self, si: &SurfaceInteraction, target: Vec3, at_infinity: bool, lift: bool) -> bool {
        match self.shadow_ray_from(si, target, at_infinity, lift) {
            Some((o, d, tmax)) => tmax <= 0.0 || !self.occluded(o, d, 0.0, tmax),
            None => false,
        }
    }

    /// A shadow ray from a surface point to `target` (as `segment_clear`) meets no surface
    /// that casts shadows: objects whose shadow visibility is off let it pass.
    pub fn shadow_clear(&self, si: &SurfaceInteraction, target: Vec3, at_infinity: bool) -> bool {
        if !self.has_shadow_invisible {
            return self.segment_clear_from(si, target, at_infinity, true);
        }
        let mut from = *si;
        for crossing in 0..MAX_INVISIBLE_CROSSINGS {
            let Some((o, d, tmax)) = self.shadow_ray_from(&from, target, at_infinity, crossing == 0) else {
                return false;
            };
            if tmax <= 0.0 {
                return true;
            }
            match self.intersect(o, d, 0.0, tmax) {
                None => return true,
                Some(hit) if self.masked(hit.prim, RAY_SHADOW_INVISIBLE) => from = self.interaction(&hit, d),
                Some(_) => return false,
            }
        }
        false
    }

    /// Visibility between a surface point and a light sample.
    pub fn visible(&self, si: &SurfaceInteraction, ls: &LightSample) -> bool {
        let at_infinity = !ls.dist.is_finite();
        self.shadow_clear(si, if at_infinity { ls.wi } else { ls.p }, at_infinity)
    }

    /// Transmittance from a surface point to a light sample (transparent shadows, as Cycles):
    /// the product of τ·tint of the transparent surfaces crossed (at most
    /// `MAX_TRANSPARENT_BOUNCES`), and whether any was crossed; None when an opaque surface
    /// blocks the way.
    pub fn transmittance(&self, si: &SurfaceInteraction, ls: &LightSample) -> Option<(Spectrum, bool)> {
        if !self.has_transparency {
            return self.visible(si, ls).then_some((Spectrum::ONE, false));
        }
        let at_infinity = !ls.dist.is_finite();
        let target = if at_infinity { ls.wi } else { ls.p };
        self.transmittance_along(si, target, at_infinity, RAY_SHADOW_INVISIBLE, true, None).map(|(t, c, _)| (t, c))
    }

    /// `transmittance` for a shadow ray that starts in the media `media` (the path's, on the
    /// side of `si` the ray leaves to: `media_towards`), through the media it crosses
    /// (`crate::medium`: their transmittance, the boundaries it passes entering and leaving
    /// them); also whether any medium touched it (the shift fails on such light).
    pub fn transmittance_in(
        &self,
        si: &SurfaceInteraction,
        ls: &LightSample,
        media: MediumStack,
    ) -> Option<(Spectrum, bool, bool)> {
        if !self.has_media {
            return self.transmittance(si, ls).map(|(t, c)| (t, c, false));
        }
        let at_infinity = !ls.dist.is_finite();
        let target = if at_infinity { ls.wi } else { ls.p };
        self.transmittance_along(si, target, at_infinity, RAY_SHADOW_INVISIBLE, true, Some(media))
    }

    /// Replaces the camera (the viewport's view, the pilot's window), keeping everything
    /// else; the media it stands in are found again from its position.
    pub fn set_camera(&mut self, camera: Camera) {
        self.camera = camera;
        self.camera_media = self.media_around(self.camera.position());
    }

    /// Whether some material has a medium (`crate::medium`).
    #[inline]
    pub fn has_media(&self) -> bool {
        self.has_media
    }

    /// The media the camera stands in.
    #[inline]
    pub fn camera_media(&self) -> MediumStack {
        self.camera_media
    }

    /// Material `m` has a medium inside its surfaces.
    #[inline]
    pub fn has_medium(&self, m: u32) -> bool {
        self.media.get(m as usize).is_some_and(Option::is_some)
    }

    /// The medium a ray in `stack` runs through (None: none, or a clear one).
    #[inline]
    pub fn medium(&self, stack: &MediumStack) -> Option<Medium> {
        if stack.is_empty() {
            return None;
        }
        crate::medium::combined(stack, &self.media)
    }

    /// The media on the side of surface `si` that direction `dir` leaves to, for a ray that
    /// arrived in `stack`: crossing the surface of a material with a medium enters it (from
    /// the front) or leaves it.
    #[inline]
    pub fn media_towards(&self, stack: MediumStack, si: &SurfaceInteraction, dir: Vec3) -> MediumStack {
        let mut s = stack;
        if dir.dot(si.ng) < 0.0 && self.has_medium(si.material) {
            s.cross(si.material, si.front);
        }
        s
    }

    /// The media enclosing point `p` (the camera's position): along a ray from `p` to
    /// infinity, a medium boundary left (met from its back) that the ray did not enter
    /// first holds `p`. (Cycles finds the camera's volume stack the same way.)
    fn media_around(&self, p: Vec3) -> MediumStack {
        let mut inside = self.world_stack();
        if !self.has_media {
            return inside;
        }
        // an oblique direction, away from the axis-aligned edges of modelled boxes
        let d = Vec3::new(0.377_964_5, 0.267_261_24, 0.886_405_9).normalize();
        let mut entered = MediumStack::default();
        let mut tmin = 0.0;
        for _ in 0..256 {
            let Some(hit) = self.intersect(p, d, tmin, f32::INFINITY) else { break };
            let m = self.tri_material[hit.prim as usize];
            if self.has_medium(m) {
                let front = self.interaction(&hit, d).front;
                if front {
                    entered.enter(m);
                } else if entered.ids().contains(&m) {
                    entered.leave(m);
                } else {
                    inside.enter(m);
                }
            }
            tmin = hit.t + ray_epsilon(p + d * hit.t).max(hit.t * 1e-6);
        }
        inside
    }

    /// The stack of a point outside every mesh's medium: the world's medium, if any.
    #[inline]
    fn world_stack(&self) -> MediumStack {
        let mut s = MediumStack::default();
        if let Some(w) = self.world_medium {
            s.enter(w);
        }
        s
    }

    /// Light from infinitely far (the sun, the world) is extinguished before it arrives: the
    /// world's medium absorbs or scatters in some channel (its transmittance over an infinite
    /// distance is 0). Light subpaths from such lights are then not traced (they carry nothing).
    #[inline]
    pub fn world_medium_extinguishes(&self) -> bool {
        self.world_medium.and_then(|w| self.media[w as usize]).is_some_and(|m| m.sigma_t().min_element() > 0.0)
    }

    /// Some object casts no shadow (its shadow ray visibility is off).
    #[inline]
    pub fn has_shadow_invisible(&self) -> bool {
        self.has_shadow_invisible
    }

    /// Transmittance of the segment from a surface point to the point `target` for a ray of
    /// another kind than a shadow ray (bidirectional joins): as a camera ray (`camera`:
    /// objects hidden from the camera let it pass) or as a ray scattered between surfaces
    /// (every object blocks it, also one whose shadow visibility is off); transparent surfaces
    /// pass it with τ·tint, as for `transmittance`. No shadow-terminator lift (not a light
    /// sample). None when blocked.
    pub fn segment_transmittance(&self, si: &SurfaceInteraction, target: Vec3, camera: bool) -> Option<Spectrum> {
        let skip = if camera { RAY_CAMERA_INVISIBLE } else { 0 };
        if !self.has_transparency && (skip == 0 || self.ray_mask.is_empty()) {
            return self.segment_clear(si, target, false).then_some(Spectrum::ONE);
        }
        self.transmittance_along(si, target, false, skip, false, None).map(|(t, _, _)| t)
    }

    /// `segment_transmittance` for a segment that starts in the media `media` (on the side
    /// of `si` towards `target`: `media_towards`): also through the media it crosses.
    pub fn segment_transmittance_in(
        &self,
        si: &SurfaceInteraction,
        target: Vec3,
        camera: bool,
        media: MediumStack,
    ) -> Option<Spectrum> {
        if !self.has_media {
            return self.segment_transmittance(si, target, camera);
        }
        let skip = if camera { RAY_CAMERA_INVISIBLE } else { 0 };
        self.transmittance_along(si, target, false, skip, false, Some(media)).map(|(t, _, _)| t)
    }

    /// Light `li` is a sphere light with Soft Falloff, which a point in a medium sees as a
    /// disk facing it (`light::FacingDisk`).
    #[inline]
    pub fn sees_facing_disk(&self, li: u32) -> bool {
        self.lights.get(li as usize).is_some_and(|l| l.facing_disk().is_some())
    }

    /// The media a light's subpaths start in (found from its position at build time; none
    /// for lights at infinity, whose rays come from outside every mesh).
    #[inline]
    pub fn light_media(&self, li: u32) -> MediumStack {
        self.light_media.get(li as usize).copied().unwrap_or_default()
    }

    /// A point `p` in a medium as a surface interaction with no surface (no normal to offset
    /// rays along, no triangle): what shadow rays and joins start from there.
    pub fn medium_point(p: Vec3, wo: Vec3) -> SurfaceInteraction {
        SurfaceInteraction {
            p,
            ng: Vec3::ZERO,
            frame: Frame::from_normal(wo),
            prim: u32::MAX,
            inst: NO_INSTANCE,
            material: u32::MAX,
            t: 0.0,
            front: true,
            tex: TexCoord::default(),
            color: Spectrum::ZERO,
            unmapped: Vec3::Z,
            wo: Vec3::Z,
            camera: false,
            bary: Vec2::ZERO,
        }
    }

    /// The walk of `transmittance` and `segment_transmittance` from `si` to `target` (a point,
    /// or at infinity a direction): surfaces whose ray mask has a bit of `skip` let the ray
    /// pass untouched (a camera's segment, skipping RAY_CAMERA_INVISIBLE, ends at a holdout),
    /// transparent ones multiply it by τ·tint (at most
    /// `MAX_TRANSPARENT_BOUNCES`), any other blocks it (None); `lift`: the first segment
    /// starts lifted off a smooth triangle (a light sample's). Also whether any transparent
    /// surface was crossed.
    fn transmittance_along(
        &self,
        si: &SurfaceInteraction,
        target: Vec3,
        at_infinity: bool,
        skip: u8,
        lift: bool,
        mut media: Option<MediumStack>,
    ) -> Option<(Spectrum, bool, bool)> {
        let mut t = Spectrum::ONE;
        let mut from = *si;
        let (mut crossed, mut invisible) = (0, 0);
        let mut in_medium = false;
        while crossed <= crate::path::MAX_TRANSPARENT_BOUNCES && invisible < MAX_INVISIBLE_CROSSINGS {
            let first = lift && crossed == 0 && invisible == 0;
            let Some((o, d, tmax)) = self.shadow_ray_from(&from, target, at_infinity, first) else {
                return Some((t, crossed > 0, in_medium));
            };
            let hit = if tmax <= 0.0 { None } else { self.intersect(o, d, 0.0, tmax) };
            if let Some(m) = media.as_ref().and_then(|s| self.medium(s)) {
                // (the medium's transmittance over the segment to the next surface or the end)
                in_medium = true;
                t *= self.medium_transmittance(&m, o, d, hit.map_or(tmax.max(0.0), |h| h.t));
            }
            let Some(hit) = hit else {
                return Some((t, crossed > 0, in_medium));
            };
            from = self.interaction(&hit, d);
            if skip != 0 && self.masked(hit.prim, skip) {
                invisible += 1; // (not a crossing of a transparent surface)
                if let Some(s) = media.as_mut() {
                    *s = self.media_towards(*s, &from, d); // (a hidden medium's boundary is still crossed)
                }
                continue;
            }
            crossed += 1;
            let m = &self.materials[self.tri_material[hit.prim as usize] as usize];
            // (a camera's segment ends at a holdout, transparent or not, as its rays do)
            if !m.is_transparent() || skip & RAY_CAMERA_INVISIBLE != 0 && self.is_holdout(hit.prim) {
                return None;
            }
            let pass = self.pass_through(m, &from);
            if pass.max_element() <= 0.0 {
                return None;
            }
            t *= pass;
            if let Some(s) = media.as_mut() {
                *s = self.media_towards(*s, &from, d);
            }
        }
        None
    }

    /// Surface data at a hit, with normals facing the incoming ray direction `d`.
    pub fn interaction(&self, hit: &TriHit, d: Vec3) -> SurfaceInteraction {
        let t = hit.prim as usize;
        let inst = self.placed(hit.inst);
        let placed;
        let (v, normals, mut ng) = match inst {
            None => (&self.positions[t], self.normals[t].as_ref(), self.geo_normals[t]),
            Some(_) => {
                placed = self.world_triangle(t, inst);
                (&placed.0, placed.1.as_ref(), placed.2)
            }
        };
        let (b1, b2) = (hit.b1, hit.b2);
        let b0 = 1.0 - b1 - b2;
        let p = v[0] * b0 + v[1] * b1 + v[2] * b2;
        let mut ns = match normals {
            Some(n) => (n[0] * b0 + n[1] * b1 + n[2] * b2).normalize_or(ng),
            None => ng,
        };
        let tex = self.tex_coord(t, b0, b1, b2);
        let color = self.colors.get(t).map_or(Spectrum::ZERO, |c| c[0] * b0 + c[1] * b1 + c[2] * b2);
        let mut unmapped = ns;
        if self.has_perturbed_normals {
            ns = self.normal_mapped(t, inst, ns, tex, [b0, b1, b2]);
        }
        let front = ng.dot(d) <= 0.0;
        if !front {
            ng = -ng;
        }
        if ns.dot(ng) < 0.0 {
            ns = -ns;
        }
        if unmapped.dot(ng) < 0.0 {
            unmapped = -unmapped;
        }
        let frame = Frame::from_normal(ns);
        let unmapped = if unmapped == ns { Vec3::Z } else { frame.to_local(unmapped) };
        SurfaceInteraction {
            p,
            ng,
            frame,
            prim: hit.prim,
            inst: hit.inst,
            material: self.tri_material[t],
            t: hit.t,
            front,
            tex,
            color,
            unmapped,
            wo: frame.to_local(-d),
            camera: false,
            bary: Vec2::new(b1, b2),
        }
    }

    /// Triangle `t`'s unit geometric normal (its winding's; in object space for an instanced
    /// mesh's). Stored: computing it at each hit cost 1–2% of `pt`'s samples per second.
    #[inline(always)]
    fn geo_normal(&self, t: usize) -> Vec3 {
        self.geo_normals[t]
    }

    /// The area of triangle light `li` (0 for another kind of light).
    #[inline]
    fn light_area(&self, li: u32) -> f32 {
        match self.lights[li as usize].shape {
            LightShape::Triangle { area, .. } => area,
            _ => 0.0,
        }
    }

    /// The instance `inst` names (None: `NO_INSTANCE`, a triangle in world space).
    #[inline]
    fn placed(&self, inst: u32) -> Option<&Instance> {
        if inst == NO_INSTANCE {
            return None;
        }
        self.instances.as_ref().map(|i| i.get(inst))
    }

    /// Triangle `t`'s vertices, corner normals (unit) and geometric normal (unit, on its
    /// outside) in world space, placed by instance `inst` where it is instanced.
    #[inline(always)]
    fn world_triangle(&self, t: usize, inst: Option<&Instance>) -> ([Vec3; 3], Option<[Vec3; 3]>, Vec3) {
        let (v, n, ng) = (self.positions[t], self.normals[t], self.geo_normal(t));
        match inst {
            None => (v, n, ng),
            Some(x) => (
                v.map(|p| x.point(p)),
                n.map(|n| n.map(|n| x.normal(n).normalize_or(n))),
                x.normal(ng).normalize_or(ng),
            ),
        }
    }

    /// The texture coordinates of triangle `t` at barycentrics (b0, b1, b2).
    #[inline]
    fn tex_coord(&self, t: usize, b0: f32, b1: f32, b2: f32) -> TexCoord {
        TexCoord {
            uv: self.uvs[t].map_or(Vec2::ZERO, |u| u[0] * b0 + u[1] * b1 + u[2] * b2),
            generated: self.generated.get(t).map_or(Vec3::ZERO, |c| c[0] * b0 + c[1] * b1 + c[2] * b2),
            object: self.object.get(t).map_or(Vec3::ZERO, |c| c[0] * b0 + c[1] * b1 + c[2] * b2),
        }
    }

    /// Emitted radiance of emissive triangle `t` (factor `emission`) at texture coordinates
    /// `tc`: the factor, times the material's emission texture where it has one. A material
    /// that blends into another by a texture emits the blend of the two sides' own emission
    /// (the light's factor is then only its selection estimate, `Lighting::build`).
    /// A blend by Is Camera Ray emits the blend of the sides' own emission by its factor for
    /// the `camera`'s rays or for every other ray (the light's factor is the latter's estimate).
    #[inline]
    fn emission_at(&self, t: usize, emission: Spectrum, tc: TexCoord, camera: bool) -> Spectrum {
        let m = &self.materials[self.tri_material[t] as usize];
        match (&m.blend, m.blend_texture, m.blend_ray) {
            (Some(b), Some(tex), _) => {
                let f = self.blend_factor(tex, tc);
                self.own_emission(m, m.emission, tc) * (1.0 - f) + self.own_emission(b, b.emission, tc) * f
            }
            (Some(b), None, Some(RayFactor::CameraRay)) => {
                let f = material::ray_curve(&m.blend_ray_curve, f32::from(u8::from(camera))).clamp(0.0, 1.0);
                let a = if f < 1.0 { self.own_emission(m, m.emission, tc) * (1.0 - f) } else { Spectrum::ZERO };
                a + if f > 0.0 { self.own_emission(b, b.emission, tc) * f } else { Spectrum::ZERO }
            }
            // (another blend by the ray emits this material's emission alone)
            _ => self.own_emission(m, emission, tc),
        }
    }

    /// `emission` times material `m`'s emission texture at `tc` (if it has one).
    #[inline]
    fn own_emission(&self, m: &Material, emission: Spectrum, tc: TexCoord) -> Spectrum {
        match m.emission_texture {
            Some(tex) => emission * self.textures[tex as usize].at(tc),
            None => emission,
        }
    }

    /// The same at barycentric coordinates (b1, b2) of the triangle.
    #[inline]
    fn triangle_radiance(&self, t: usize, emission: Spectrum, b1: f32, b2: f32) -> Spectrum {
        let m = &self.materials[self.tri_material[t] as usize];
        if m.emission_texture.is_none() && m.blend.is_none() {
            return emission;
        }
        self.emission_at(t, emission, self.tex_coord(t, 1.0 - b1 - b2, b1, b2), false)
    }

    /// Barycentric coordinates (b1, b2) of point `p` (on the plane of) triangle `t`.
    fn barycentrics(&self, t: usize, p: Vec3) -> (f32, f32) {
        let v = &self.positions[t];
        let (e1, e2, d) = (v[1] - v[0], v[2] - v[0], p - v[0]);
        let n = e1.cross(e2);
        let n2 = n.length_squared();
        if n2 <= 0.0 {
            return (0.0, 0.0);
        }
        (d.cross(e2).dot(n) / n2, e1.cross(d).dot(n) / n2)
    }

    /// The shading normal `ns` of triangle `t` perturbed by its material's tangent-space
    /// normal map and then its bump map at `tc`, in the frame of the triangle's UV mapping
    /// (∂p/∂u, ∂p/∂v; none without UVs or with degenerate ones) — or, for a procedural
    /// height on Generated or Object coordinates, of its edges e₁, e₂ with the height's
    /// derivatives along them (∇_c h·(c₁ − c₀), ∇_c h·(c₂ − c₀) from its corner coordinates c).
    ///
    /// Normal map, as Cycles' Normal Map node: n' = normalize(T·c.x + B·c.y + N·c.z) with
    /// c = 2·rgb − 1, T and its sign s the MikkTSpace corner tangents interpolated at the
    /// barycentrics `b`, N the interpolated corner normal (the geometric one on flat
    /// triangles) normalized as Cycles 5.3 takes it, or as it is as earlier Cycles took it
    /// (the material's `normal_map_unnormalized_base`: on a coarse ball up to 0.15 apart in
    /// the mapped normal), B = s·N × T; then normalize(ns + strength·(n' − ns)). A mesh without
    /// those tangents takes T = ∂p/∂u made orthogonal to ns and B = ±ns × T (the UV mapping's
    /// handedness).
    ///
    /// Bump, as Cycles' Bump node in the limit of its small filter width: the surface
    /// gradient of the height h perpendicular to N, ∇h = (h_u·R_u + h_v·R_v)/det with
    /// R_u = ∂p/∂v × N, R_v = N × ∂p/∂u, det = ∂p/∂u · R_u (the basis dual to the tangents,
    /// so that ∇h·∂p/∂u = h_u), then N' = normalize(N − distance·∇h), mixed with N by the
    /// strength.
    fn normal_mapped(&self, t: usize, inst: Option<&Instance>, ns: Vec3, tc: TexCoord, b: [f32; 3]) -> Vec3 {
        let m = &self.materials[self.tri_material[t] as usize];
        let (p, normals, geo_normal) = self.world_triangle(t, inst);
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        // the UV mapping's tangents ∂p/∂u, ∂p/∂v (none without UVs or with degenerate ones)
        let uv_tangents = self.uvs[t].and_then(|uvs| {
            let (d1, d2) = (uvs[1] - uvs[0], uvs[2] - uvs[0]);
            let det = d1.x * d2.y - d1.y * d2.x;
            (det.abs() >= 1e-20).then(|| ((e1 * d2.y - e2 * d1.y) / det, (e2 * d1.x - e1 * d2.x) / det))
        });
        let mut n = ns;
        if let (Some(tex), Some((dpdu, dpdv))) = (m.normal_texture, uv_tangents) {
            let mut mikk = self.tangents.get(t).map_or(Vec4::ZERO, |c| c[0] * b[0] + c[1] * b[1] + c[2] * b[2]);
            if let Some(x) = inst.filter(|_| mikk.truncate() != Vec3::ZERO) {
                // (a mirroring placement flips the frame's handedness)
                let sign = if x.mirrors() { -mikk.w } else { mikk.w };
                mikk = x.vector(mikk.truncate()).normalize_or_zero().extend(sign);
            }
            let (tangent, sign, normal) = if mikk.truncate() != Vec3::ZERO {
                let normal = match &normals {
                    Some(c) if m.normal_map_unnormalized_base => c[0] * b[0] + c[1] * b[1] + c[2] * b[2],
                    Some(c) => (c[0] * b[0] + c[1] * b[1] + c[2] * b[2]).normalize_or(geo_normal),
                    None => geo_normal,
                };
                (mikk.truncate(), mikk.w, normal)
            } else {
                let sign = if ns.cross(dpdu).dot(dpdv) < 0.0 { -1.0 } else { 1.0 };
                ((dpdu - ns * ns.dot(dpdu)).normalize_or_zero(), sign, ns)
            };
            if tangent != Vec3::ZERO {
                let bitangent = normal.cross(tangent) * sign;
                let c = self.textures[tex as usize].eval(tc.uv) * 2.0 - Vec3::ONE;
                let mapped = (tangent * c.x + bitangent * c.y + normal * c.z).normalize_or(ns);
                n = (ns + (mapped - ns) * m.normal_strength).normalize_or(ns);
            }
        }
        if let Some(tex) = m.bump_texture {
            let texture = &self.textures[tex as usize];
            // the height's derivatives along two tangents of the surface
            let along = match texture.procedural_space() {
                None => uv_tangents.map(|(dpdu, dpdv)| (dpdu, dpdv, texture.luminance_gradient(tc.uv))),
                Some(Space::Uv) => {
                    let g = texture.procedural_luminance_gradient(tc);
                    uv_tangents.map(|(dpdu, dpdv)| (dpdu, dpdv, Vec2::new(g.x, g.y)))
                }
                Some(space @ (Space::Generated | Space::Object)) => {
                    let corners = if space == Space::Generated { &self.generated } else { &self.object };
                    corners.get(t).map(|c| {
                        let g = texture.procedural_luminance_gradient(tc);
                        (e1, e2, Vec2::new(g.dot(c[1] - c[0]), g.dot(c[2] - c[0])))
                    })
                }
            };
            if let Some((ta, tb, h)) = along {
                let (ra, rb) = (tb.cross(n), n.cross(ta));
                let det = ta.dot(ra);
                if det.abs() > 1e-30 {
                    let grad = (ra * h.x + rb * h.y) / det;
                    let bumped = (n - grad * m.bump_distance).normalize_or(n);
                    n = (bumped * m.bump_strength + n * (1.0 - m.bump_strength)).normalize_or(n);
                }
            }
        }
        n
    }

    /// The BSDF of `material` at texture coordinates `tc` and vertex colour `color` (textures
    /// replace the base colour and the roughness where the material links them; the vertex
    /// colour multiplies the base colour where the material reads it), its diffuse lobe
    /// bump-shadowed where the surface's own normal is `unmapped` (shading frame; +Z: none),
    /// seen from direction `wo` (shading frame: what a blend by the view reads).
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn bsdf(
        &self,
        material: u32,
        front: bool,
        tc: TexCoord,
        color: Spectrum,
        unmapped: Vec3,
        wo: Vec3,
        camera: bool,
    ) -> Bsdf {
        let ray = if camera { RayKind::Camera } else { RayKind::Scattered };
        let bsdf = self.unbumped_bsdf(material, front, tc, color, wo.dot(unmapped), ray);
        if unmapped == Vec3::Z || !self.materials[material as usize].bump_map_correction {
            bsdf
        } else {
            bsdf.bumped(unmapped)
        }
    }

    /// `bsdf` before the bump shadowing of its diffuse lobe: a material that blends into
    /// another by a texture or by the view (a Mix Shader's factor) mixes the two BSDFs lobe by
    /// lobe; `cos`: the view's cosine with the unmapped shading normal.
    #[inline]
    fn unbumped_bsdf(&self, material: u32, front: bool, tc: TexCoord, color: Spectrum, cos: f32, ray: RayKind) -> Bsdf {
        let m = &self.materials[material as usize];
        let Some(b) = &m.blend else {
            return self.material_bsdf(m, front, tc, color, m.general);
        };
        match self.blend_at(m, tc, cos, front, ray) {
            f if f <= 0.0 => self.material_bsdf(m, front, tc, color, m.general),
            f if f >= 1.0 => self.material_bsdf(b, front, tc, color, b.general),
            f => Bsdf::blend(
                &self.material_bsdf(m, front, tc, color, true),
                &self.material_bsdf(b, front, tc, color, true),
                f,
            ),
        }
    }

    /// The factor of a blend at `tc`: its texture's luminance in [0, 1] (Cycles clamps a Mix
    /// Shader's factor so).
    #[inline]
    fn blend_factor(&self, texture: u32, tc: TexCoord) -> f32 {
        crate::math::luminance(self.textures[texture as usize].at(tc)).clamp(0.0, 1.0)
    }

    /// The factor of material `m`'s blend at `tc`, seen at cosine `cos` with the unmapped
    /// shading normal from the `front` or back, by a `ray` of that kind.
    #[inline]
    fn blend_at(&self, m: &Material, tc: TexCoord, cos: f32, front: bool, ray: RayKind) -> f32 {
        match (m.blend_texture, m.blend_ray) {
            (Some(t), _) => self.blend_factor(t, tc),
            (None, Some(v)) => {
                let x = v.at(cos, front, ray);
                material::ray_curve(&m.blend_ray_curve, x).clamp(0.0, 1.0)
            }
            (None, None) => 0.0,
        }
    }

    /// The BSDF of one material (no blend) at `tc`, the full Principled mixture when `general`.
    #[inline]
    fn material_bsdf(&self, m: &Material, front: bool, tc: TexCoord, color: Spectrum, general: bool) -> Bsdf {
        if m.base_color_texture.is_none()
            && m.roughness_texture.is_none()
            && m.metallic_texture.is_none()
            && m.alpha_texture.is_none()
            && !m.vertex_color
        {
            return m.lobes(front, m.base_color, m.roughness, m.metallic, m.transparency, general);
        }
        let mut base = m.base_color_texture.map_or(m.base_color, |t| self.textures[t as usize].at(tc));
        if m.vertex_color {
            base *= color;
        }
        let base = base.clamp(Spectrum::ZERO, Spectrum::ONE);
        let grey = |t: Option<u32>, constant: f32| {
            t.map_or(constant, |t| crate::math::luminance(self.textures[t as usize].at(tc)).clamp(0.0, 1.0))
        };
        let (rough, metallic) = (grey(m.roughness_texture, m.roughness), grey(m.metallic_texture, m.metallic));
        m.lobes(front, base, rough, metallic, self.transparency(m, tc), general)
    }

    /// Transparency τ of a material at `tc`: 1 − alpha from its alpha texture, else its constant.
    #[inline]
    fn transparency(&self, m: &Material, tc: TexCoord) -> f32 {
        m.alpha_texture
            .map_or(m.transparency, |t| 1.0 - crate::math::luminance(self.textures[t as usize].at(tc)).clamp(0.0, 1.0))
    }

    /// What a shadow ray carries on through surface `si` of material `m`: τ × the
    /// transparent tint (of each side of a blend, mixed by its factor).
    #[inline]
    fn pass_through(&self, m: &Material, si: &SurfaceInteraction) -> Spectrum {
        let own = |m: &Material| m.transparent_color * self.transparency(m, si.tex);
        match &m.blend {
            Some(b) => {
                let f = self.blend_at(m, si.tex, si.wo.dot(si.unmapped), si.front, RayKind::Shadow);
                own(m) * (1.0 - f) + own(b) * f
            }
            None => own(m),
        }
    }

    /// The BSDF at a surface point.
    #[inline]
    pub fn bsdf_at(&self, si: &SurfaceInteraction) -> Bsdf {
        self.bsdf(si.material, si.front, si.tex, si.color, si.unmapped, si.wo, si.camera)
    }

    #[inline]
    pub fn material(&self, si: &SurfaceInteraction) -> &Material {
        &self.materials[si.material as usize]
    }

    pub fn has_lights(&self) -> bool {
        !self.selector.is_empty()
    }

    /// Chooses a light for shading point `p` (light_select.rs) and samples a point on it
    /// (NEE). `pdf` of the result includes the selection probability.
    pub fn sample_light(&self, p: Vec3, u_select: f32, u: Vec2) -> Option<(u32, LightSample)> {
        self.sample_light_in(p, u_select, u, false)
    }

    /// `sample_light` from `p`, a point in a medium where `in_medium` (soft-falloff sphere
    /// lights are then the disk facing it: `light::FacingDisk`).
    pub fn sample_light_in(&self, p: Vec3, u_select: f32, u: Vec2, in_medium: bool) -> Option<(u32, LightSample)> {
        let (li, pmf) = self.selector.sample(p, u_select)?;
        if li == self.lights.len() {
            let (wi, radiance, pdf) = self.env.sample(&self.textures, u)?;
            let pdf = pdf * pmf;
            let ls = LightSample { p: p + wi * 1e30, n: -wi, wi, dist: f32::INFINITY, radiance, pdf, is_delta: false };
            return (pdf > 0.0 && pdf.is_finite()).then_some((li as u32, ls));
        }
        let light = &self.lights[li];
        let mut ls = match light.shape {
            LightShape::Triangle { prim, area } => {
                let v = &self.positions[prim as usize];
                let (b1, b2) = square_to_triangle(u);
                let lp = v[0] * (1.0 - b1 - b2) + v[1] * b1 + v[2] * b2;
                let radiance = self.triangle_radiance(prim as usize, light.emission, b1, b2);
                let to = lp - p;
                let d2 = to.length_squared();
                if d2 == 0.0 {
                    return None;
                }
                let dist = d2.sqrt();
                let wi = to / dist;
                let n = self.geo_normal(prim as usize);
                // |cos| at the light (two-sided emission) = |to·n|/dist; the pdf d²/(|cos|·A)
                // is formed from to·n, not from wi, so that it waits for one division, not two
                let to_n = to.dot(n);
                if to_n.abs() <= 1e-7 * dist {
                    return None;
                }
                LightSample {
                    p: lp,
                    n: if to_n < 0.0 { n } else { -n },
                    wi,
                    dist,
                    radiance,
                    pdf: d2 * dist / (to_n.abs() * area),
                    is_delta: false,
                }
            }
            _ if in_medium => light.sample_from_medium(p, u)?,
            _ => light.sample(p, u)?,
        };
        ls.pdf *= pmf;
        if !(ls.pdf > 0.0) || !ls.pdf.is_finite() {
            return None;
        }
        Some((li as u32, ls))
    }

    /// Emitted radiance of the surface at `si` towards the ray origin, and the NEE pdf
    /// (selection included) with which a light sample from `from` would have chosen it.
    /// A surface only the camera sees glowing (the second side of a blend by Is Camera Ray,
    /// whose first side does not emit) is no light: the camera sees its emission, pdf 0.
    pub fn surface_emission(&self, si: &SurfaceInteraction, from: Vec3, dir: Vec3) -> Option<(Spectrum, f32)> {
        let li = self.tri_light.get(si.prim as usize).copied().unwrap_or(u32::MAX);
        if li == u32::MAX {
            let m = &self.materials[si.material as usize];
            return match (&m.blend, m.blend_ray) {
                (Some(b), Some(RayFactor::CameraRay)) if si.camera && (m.is_emissive() || b.is_emissive()) => {
                    let le = self.emission_at(si.prim as usize, m.emission, si.tex, true);
                    (le.max_element() > 0.0).then_some((le, 0.0))
                }
                _ => None,
            };
        }
        let le = self.emission_at(si.prim as usize, self.lights[li as usize].emission, si.tex, si.camera);
        let cos_l = dir.dot(si.ng).abs();
        let d2 = (si.p - from).length_squared();
        let pdf =
            if cos_l > 0.0 { self.selector.pmf(li as usize, from) * d2 / (cos_l * self.light_area(li)) } else { 0.0 };
        Some((le, pdf))
    }

    /// Calls `f(radiance, nee_pdf)` for every analytic light the ray (o, d) crosses before
    /// `tmax` (lights are transparent); the pdf is NEE's from shading point `from` (the
    /// vertex the ray left). `camera_ray` skips lights not visible to the camera.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn for_each_light_crossed(
        &self,
        from: Vec3,
        o: Vec3,
        d: Vec3,
        tmax: f32,
        camera_ray: bool,
        f: impl FnMut(u32, f32, Spectrum, f32),
    ) {
        self.for_each_light_crossed_in(from, false, o, d, tmax, camera_ray, f)
    }

    /// `for_each_light_crossed` for a segment whose light pdfs are taken at `from`, a point
    /// in a medium where `in_medium` (`sample_light_in`).
    #[allow(clippy::too_many_arguments)]
    pub fn for_each_light_crossed_in(
        &self,
        from: Vec3,
        in_medium: bool,
        o: Vec3,
        d: Vec3,
        tmax: f32,
        camera_ray: bool,
        mut f: impl FnMut(u32, f32, Spectrum, f32),
    ) {
        for &li in &self.hittable_lights {
            let light = &self.lights[li as usize];
            if camera_ray && !light.visible_camera {
                continue;
            }
            let crossed =
                if in_medium { light.intersect_from_medium(from, o, d, tmax) } else { light.intersect(o, d, tmax) };
            if let Some((t, le, pdf)) = crossed {
                f(li, t, le, pdf * self.selector.pmf(li as usize, from));
            }
        }
    }

    /// Where the ray (o, d) crosses analytic light `li` before `tmax`: (t, radiance, NEE pdf
    /// from shading point `from`, selection included). None for emissive triangles (they are
    /// surfaces) and for a miss.
    #[inline]
    pub fn light_crossed(&self, li: u32, from: Vec3, o: Vec3, d: Vec3, tmax: f32) -> Option<(f32, Spectrum, f32)> {
        let light = self.lights.get(li as usize)?;
        let (t, le, pdf) = light.intersect(o, d, tmax)?;
        Some((t, le, pdf * self.selector.pmf(li as usize, from)))
    }

    /// The light index of the world background (one past the light objects).
    #[inline]
    pub fn env_light(&self) -> u32 {
        self.lights.len() as u32
    }

    /// Light `li`'s shadow rays are blocked by surfaces (its Cast Shadow; the world's always).
    #[inline]
    pub fn casts_shadow(&self, li: u32) -> bool {
        self.lights.get(li as usize).is_none_or(|l| l.cast_shadow)
    }

    /// What a camera ray leaving the scene in direction `d` sees: the textured backdrop, or
    /// the world.
    #[inline]
    pub fn camera_background(&self, d: Vec3) -> Spectrum {
        match &self.backdrop {
            Some(b) => b.eval(&self.textures, d),
            None => self.world_eval(self.camera.position(), d).0,
        }
    }

    /// Background radiance arriving from direction `d` and the NEE pdf from shading point
    /// `from` (solid angle, selection included; 0 when the world is not sampled).
    #[inline]
    pub fn world_eval(&self, from: Vec3, d: Vec3) -> (Spectrum, f32) {
        if self.env.is_black() {
            return (Spectrum::ZERO, 0.0);
        }
        let pmf = self.selector.pmf(self.lights.len(), from);
        (self.env.eval(&self.textures, d), pmf * self.env.pdf(d))
    }

    /// True when light `li` is an emissive triangle.
    #[inline]
    pub fn is_triangle_light(&self, li: u32) -> bool {
        matches!(self.lights.get(li as usize).map(|l| &l.shape), Some(LightShape::Triangle { .. }))
    }

    /// Radiance that light `li` sends from its point `z` (or, for distant lights, from
    /// direction `z`) towards `from`, and the NEE pdf (solid angle at `from`, selection
    /// included; 1·selection for delta lights) of choosing that point. None if `z` does not
    /// face `from`. Used by the shift mapping to re-evaluate a light point from an offset path.
    pub fn light_eval(&self, li: u32, from: Vec3, z: Vec3) -> Option<(Spectrum, f32)> {
        self.light_eval_in(li, from, z, false)
    }

    /// `light_eval` from `from`, a point in a medium where `in_medium` (`sample_light_in`).
    pub fn light_eval_in(&self, li: u32, from: Vec3, z: Vec3, in_medium: bool) -> Option<(Spectrum, f32)> {
        if li == self.env_light() {
            return Some(self.world_eval(from, z));
        }
        let light = self.lights.get(li as usize)?;
        let pmf = self.selector.pmf(li as usize, from);
        if let Some(disk) = light.facing_disk().filter(|_| in_medium) {
            let (pdf, att) = disk.eval(from, z)?;
            return (att > 0.0).then(|| (light.emission * att, pmf * pdf));
        }
        match &light.shape {
            LightShape::Triangle { prim, area } => {
                let n = self.geo_normal(*prim as usize);
                let to = from - z;
                let d2 = to.length_squared();
                let cos = (to.dot(n) / d2.sqrt()).abs();
                let (b1, b2) = self.barycentrics(*prim as usize, z);
                let le = self.triangle_radiance(*prim as usize, light.emission, b1, b2);
                (cos > 1e-7).then(|| (le, pmf * d2 / (cos * area)))
            }
            LightShape::Planar { normal, area, spread, .. } => {
                let to = from - z;
                let d2 = to.length_squared();
                let cos = to.dot(*normal) / d2.sqrt();
                let att = spread.map_or(1.0, |s| s.attenuation(cos));
                (cos > 1e-7 && att > 0.0).then(|| (light.emission * att, pmf * d2 / (cos * area)))
            }
            LightShape::Sphere { center, radius, spot, soft_falloff } => {
                let att = spot.map_or(1.0, |s| s.along(*center, radius * radius, from, (from - z).normalize_or_zero()));
                if att <= 0.0 {
                    return None;
                }
                if *radius > 0.0 {
                    if (from - z).dot(z - *center) <= 0.0 {
                        return None; // the point is on the far side of the sphere
                    }
                    let soft = light::soft_falloff_factor(*soft_falloff, from, *center, *radius);
                    Some((light.emission * (att * soft), pmf * light::sphere_cone_pdf(from, *center, *radius)))
                } else {
                    let d2 = (from - *center).length_squared();
                    Some((light.emission * (att / d2), pmf))
                }
            }
            LightShape::Distant { cos_half, .. } => {
                if *cos_half >= 1.0 {
                    Some((light.emission, pmf))
                } else {
                    Some((light.emission, pmf / (2.0 * std::f32::consts::PI * (1.0 - cos_half))))
                }
            }
        }
    }

    /// Surface normal of light `li` at its point `z` (zero for points and distant lights).
    pub fn light_normal(&self, li: u32, z: Vec3) -> Vec3 {
        match self.lights.get(li as usize).map(|l| &l.shape) {
            Some(LightShape::Triangle { prim, .. }) => self.geo_normal(*prim as usize),
            Some(LightShape::Planar { normal, .. }) => *normal,
            Some(LightShape::Sphere { center, radius, .. }) if *radius > 0.0 => (z - *center).normalize_or_zero(),
            _ => Vec3::ZERO,
        }
    }

    /// Light index of an emissive triangle (None if it does not emit).
    pub fn triangle_light(&self, prim: u32) -> Option<u32> {
        self.tri_light.get(prim as usize).copied().filter(|&li| li != u32::MAX)
    }

    /// True when some light is a delta light (point without radius, sun without angle),
    /// which naive path tracing cannot find.
    pub fn delta_lights(&self) -> Vec<&str> {
        self.lights.iter().filter(|l| l.is_delta()).map(|l| l.name.as_str()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin::camera_looking_along_y;

    /// The shift mapping's re-evaluation of a light point (`light_eval`) gives what NEE's
    /// sample of that point carried: the radiance and the pdf, selection included, for every
    /// light of the mixed-lights box with its area light narrowed by a 50° spread. Failed
    /// before light_eval applied the spread (gdpt and gdpssmlt 16% dark against Cycles on the
    /// convergence test's softbox).
    #[test]
    fn light_eval_gives_what_light_samples_carry() {
        use crate::sampler::{IndependentSampler, Sampler};
        let mut desc = crate::scene::builtin::cornell_mixed_lights(8, 8);
        for l in &mut desc.lights {
            if let LightDesc::Area { spread, .. } = l {
                *spread = 50f32.to_radians();
            }
        }
        let scene = Scene::build(&desc).unwrap();
        let mut s = IndependentSampler::new(9, 1);
        let mut planar = 0;
        for k in 0..4000 {
            let p = Vec3::new(s.next_1d() * 1.8 - 0.9, s.next_1d() * 1.8 - 0.9, -0.95 + 0.1 * (k % 3) as f32);
            let Some((li, ls)) = scene.sample_light(p, s.next_1d(), s.next_2d()) else { continue };
            if li == scene.env_light() || ls.is_delta {
                continue;
            }
            let z = if ls.dist.is_finite() { ls.p } else { ls.wi };
            let Some((le, pdf)) = scene.light_eval(li, p, z) else {
                panic!("light {li} at {p}: sampled, not evaluated")
            };
            let want = ls.pdf; // selection included
            assert!(
                (le - ls.radiance).abs().max_element() <= 1e-3 * ls.radiance.max_element(),
                "light {li}: {le} vs {}",
                ls.radiance
            );
            assert!((pdf - want).abs() <= 1e-3 * want, "light {li}: pdf {pdf} vs {want}");
            planar +=
                usize::from(matches!(scene.lights[li as usize].shape, LightShape::Planar { spread: Some(_), .. }));
        }
        assert!(planar > 100, "{planar} samples of the spread light");
    }

    /// The shading normal where a ray from above hits a 2 m quad at z = 0 (facing +z) with
    /// UVs `uv` at its corners, of `material` with the one texture `texture`.
    fn quad_normal(uv: [[f32; 2]; 4], texture: TextureDesc, material: MaterialDesc) -> Vec3 {
        let quad = MeshDesc {
            name: "Quad".into(),
            positions: vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            corner_uvs: [0, 1, 2, 0, 2, 3].iter().map(|&k| uv[k]).collect(),
            material_ids: vec![0, 0],
            ..Default::default()
        };
        let desc = SceneDesc {
            meshes: vec![quad],
            materials: vec![material],
            textures: vec![texture],
            camera: camera_looking_along_y([0.0, -3.0, 0.0], 35.0, 4, 4),
            ..Default::default()
        };
        let scene = Scene::build(&desc).unwrap();
        let (o, d) = (Vec3::new(0.2, 0.1, 2.0), Vec3::new(0.0, 0.0, -1.0));
        let hit = scene.intersect(o, d, 0.0, f32::INFINITY).unwrap();
        scene.interaction(&hit, d).frame.n
    }

    /// `quad_normal` under a constant normal-map texture `rgb`.
    fn mapped_normal(rgb: [f32; 3], uv: [[f32; 2]; 4], strength: f32) -> Vec3 {
        let texture = TextureDesc { name: "n".into(), width: 1, height: 1, pixels: vec![rgb], ..Default::default() };
        let material = MaterialDesc { normal_texture: Some(0), normal_strength: strength, ..Default::default() };
        quad_normal(uv, texture, material)
    }

    /// Under a normal map the diffuse lobe is bump-shadowed towards light near the unmapped
    /// normal's horizon (`bsdf/bump_shadowing.rs`), and not with the material's Bump Map
    /// Correction off; without a map nothing changes.
    #[test]
    fn bump_map_correction_shadows_the_diffuse_lobe_of_mapped_normals() {
        let eval_towards = |normal_texture: Option<u32>, correction: bool| {
            let quad = MeshDesc {
                name: "Quad".into(),
                positions: vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]],
                indices: vec![[0, 1, 2], [0, 2, 3]],
                corner_uvs: [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0], [1.0, 1.0], [0.0, 1.0]].to_vec(),
                material_ids: vec![0, 0],
                ..Default::default()
            };
            let lean = TextureDesc {
                name: "n".into(),
                width: 1,
                height: 1,
                pixels: vec![[0.8, 0.5, 0.9]],
                ..Default::default()
            };
            let material = MaterialDesc { normal_texture, bump_map_correction: correction, ..Default::default() };
            let desc = SceneDesc {
                meshes: vec![quad],
                materials: vec![material],
                textures: vec![lean],
                camera: camera_looking_along_y([0.0, -3.0, 0.0], 35.0, 4, 4),
                ..Default::default()
            };
            let scene = Scene::build(&desc).unwrap();
            let d = Vec3::new(0.0, 0.0, -1.0);
            let si = scene.interaction(&scene.intersect(Vec3::new(0.2, 0.1, 2.0), d, 0.0, f32::INFINITY).unwrap(), d);
            // light 80° from the surface's own normal, on the side the map leans to
            let wi = si.frame.to_local(Vec3::new(80f32.to_radians().sin(), 0.0, 80f32.to_radians().cos()));
            scene.bsdf_at(&si).eval(si.frame.to_local(-d), wi).x
        };
        let (bumped, uncorrected, plain) =
            (eval_towards(Some(0), true), eval_towards(Some(0), false), eval_towards(None, true));
        assert!(bumped < 0.9 * uncorrected, "{bumped} vs {uncorrected}");
        assert!(uncorrected > plain, "the lean faces the light: {uncorrected} vs {plain}");
    }

    /// Corner colours are interpolated barycentrically and multiply the base colour (constant
    /// or texture) of a material that reads them; a mesh without them reads black, and a
    /// material that does not read them ignores them.
    #[test]
    fn vertex_colours_interpolate_and_tint_the_base_colour() {
        let corners = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.5, 0.5, 0.5]];
        let quad = |x: f32, coloured: bool, mat: u32| MeshDesc {
            name: format!("Quad{x}"),
            positions: vec![[x - 1.0, -1.0, 0.0], [x + 1.0, -1.0, 0.0], [x + 1.0, 1.0, 0.0], [x - 1.0, 1.0, 0.0]],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            corner_colors: if coloured { [0, 1, 2, 0, 2, 3].iter().map(|&k| corners[k]).collect() } else { vec![] },
            material_ids: vec![mat, mat],
            ..Default::default()
        };
        let tinted = MaterialDesc { base_color: [0.5, 0.8, 1.0], vertex_color: true, ..Default::default() };
        let plain = MaterialDesc { base_color: [0.5, 0.8, 1.0], ..Default::default() };
        let textured = MaterialDesc { base_color_texture: Some(0), vertex_color: true, ..Default::default() };
        let grey = TextureDesc { name: "g".into(), width: 1, height: 1, pixels: vec![[0.5; 3]], ..Default::default() };
        let desc = SceneDesc {
            meshes: vec![quad(0.0, true, 0), quad(3.0, true, 1), quad(6.0, false, 0), quad(9.0, true, 2)],
            materials: vec![tinted, plain, textured],
            textures: vec![grey],
            camera: camera_looking_along_y([0.0, -3.0, 0.0], 35.0, 4, 4),
            ..Default::default()
        };
        let scene = Scene::build(&desc).unwrap();
        let at = |x: f32| {
            let d = Vec3::new(0.0, 0.0, -1.0);
            let hit = scene.intersect(Vec3::new(x + 0.2, -0.5, 1.0), d, 0.0, f32::INFINITY).unwrap();
            let si = scene.interaction(&hit, d);
            (si.color, scene.bsdf_at(&si).albedo())
        };
        // (0.2, −0.5) in the first triangle: barycentrics (0.4, 0.35, 0.25)
        let want = Vec3::new(0.4, 0.35, 0.25);
        let close = |a: Vec3, b: Vec3| (a - b).abs().max_element() < 1e-5;
        let (c, albedo) = at(0.0);
        assert!(close(c, want) && close(albedo, want * Vec3::new(0.5, 0.8, 1.0)), "{c} {albedo}");
        let (c, albedo) = at(3.0);
        assert!(close(c, want) && close(albedo, Vec3::new(0.5, 0.8, 1.0)), "{c} {albedo}");
        let (c, albedo) = at(6.0);
        assert!(close(c, Vec3::ZERO) && close(albedo, Vec3::ZERO), "{c} {albedo}");
        let (_, albedo) = at(9.0);
        assert!(close(albedo, want * 0.5), "{albedo}");
    }

    /// Barycentric coordinates invert the triangle's parametrisation (what the shift uses to
    /// find an emission image's value at a reconnected light point).
    #[test]
    fn barycentrics_invert_the_parametrisation() {
        let quad = MeshDesc {
            name: "Tri".into(),
            positions: vec![[0.3, -1.0, 0.2], [1.5, 0.4, -0.3], [-0.7, 0.9, 1.1]],
            indices: vec![[0, 1, 2]],
            material_ids: vec![0],
            ..Default::default()
        };
        let desc = SceneDesc {
            meshes: vec![quad],
            materials: vec![MaterialDesc::default()],
            camera: camera_looking_along_y([0.0, -3.0, 0.0], 35.0, 4, 4),
            ..Default::default()
        };
        let scene = Scene::build(&desc).unwrap();
        let v = scene.positions[0];
        for (b1, b2) in [(0.2f32, 0.3f32), (0.0, 1.0), (0.7, 0.1)] {
            let p = v[0] * (1.0 - b1 - b2) + v[1] * b1 + v[2] * b2;
            let (c1, c2) = scene.barycentrics(0, p);
            assert!((c1 - b1).abs() < 1e-5 && (c2 - b2).abs() < 1e-5, "({b1}, {b2}) → ({c1}, {c2})");
        }
    }

    /// Tangent-space normal maps tilt the shading normal along the texture's u (red) and v
    /// (green) directions on the surface, follow a mirrored UV mapping, leave it unchanged
    /// for the flat colour (0.5, 0.5, 1) and scale the tilt with the strength.
    #[test]
    fn normal_maps_tilt_along_the_uv_directions() {
        let plain = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let mirrored_v = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
        let rotated = [[0.0, 1.0], [0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]; // u along +y, v along −x
        let tilt_u = [0.8, 0.5, 0.9]; // c = (0.6, 0, 0.8)
        let tilt_v = [0.5, 0.8, 0.9]; // c = (0, 0.6, 0.8)
        let close = |a: Vec3, b: Vec3| (a - b).length() < 1e-4;
        assert!(close(mapped_normal([0.5, 0.5, 1.0], plain, 1.0), Vec3::Z));
        assert!(close(mapped_normal(tilt_u, plain, 1.0), Vec3::new(0.6, 0.0, 0.8)));
        assert!(close(mapped_normal(tilt_v, plain, 1.0), Vec3::new(0.0, 0.6, 0.8)));
        assert!(close(mapped_normal(tilt_v, mirrored_v, 1.0), Vec3::new(0.0, -0.6, 0.8)));
        assert!(close(mapped_normal(tilt_u, rotated, 1.0), Vec3::new(0.0, 0.6, 0.8)));
        assert!(close(mapped_normal(tilt_v, rotated, 1.0), Vec3::new(-0.6, 0.0, 0.8)));
        // strength 0.5: halfway between N and the mapped normal, normalized
        assert!(close(mapped_normal(tilt_u, plain, 0.5), Vec3::new(0.3, 0.0, 0.9).normalize()));
        assert!(close(mapped_normal(tilt_u, plain, 0.0), Vec3::Z));
    }

    /// `quad_normal` (u = (x + 1)/2 under the plain UVs) bumped by a 2×1 height map of 0 and
    /// 1 (Extend: h = 2u − 0.5 between the texel centres, so ∂h/∂x = 1 under the plain UVs).
    fn bumped_normal(uv: [[f32; 2]; 4], distance: f32, strength: f32) -> Vec3 {
        let texture = TextureDesc {
            name: "h".into(),
            width: 2,
            height: 1,
            pixels: vec![[0.0; 3], [1.0; 3]],
            extension: crate::scene::desc::TextureExtension::Extend,
            ..Default::default()
        };
        let material = MaterialDesc {
            bump_texture: Some(0),
            bump_distance: distance,
            bump_strength: strength,
            ..Default::default()
        };
        quad_normal(uv, texture, material)
    }

    /// A bump map tilts the normal against the height's surface gradient, N' = N − d·∇h
    /// normalized, along whichever surface direction the UVs put u; a negative distance
    /// (Invert) tilts the other way, the strength mixes with the unbumped normal.
    #[test]
    fn bump_maps_tilt_against_the_height_gradient() {
        let plain = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let rotated = [[0.0, 1.0], [0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]; // u along +y
        let close = |a: Vec3, b: Vec3| (a - b).length() < 1e-4;
        let n = bumped_normal(plain, 0.5, 1.0);
        assert!(close(n, Vec3::new(-0.5, 0.0, 1.0).normalize()), "{n}");
        assert!(close(bumped_normal(plain, -0.5, 1.0), Vec3::new(0.5, 0.0, 1.0).normalize()));
        let n = bumped_normal(rotated, 0.5, 1.0);
        assert!(close(n, Vec3::new(0.0, -0.5, 1.0).normalize()), "{n}");
        let half = (Vec3::new(-0.5, 0.0, 1.0).normalize() * 0.5 + Vec3::Z * 0.5).normalize();
        assert!(close(bumped_normal(plain, 0.5, 0.5), half));
        assert!(close(bumped_normal(plain, 0.5, 0.0), Vec3::Z));
    }

    /// A procedural height bumps along its own coordinates: a gradient (h = x of the pattern
    /// space) read on Generated coordinates that turn and scale the quad (c = (2y, −x, z)), or on
    /// UVs, tilts the normal against ∇h carried back to the surface; a Noise height tilts it
    /// as its finite differences say.
    #[test]
    fn procedural_bump_maps_tilt_against_the_gradient_of_their_coordinates() {
        use super::procedural::{GradientKind, Pattern, Procedural, Space};
        let ramp = |space, pattern| TextureDesc {
            name: "h".into(),
            width: 2,
            height: 1,
            pixels: vec![[0.0; 3], [1.0; 3]],
            procedural: Some(Procedural {
                pattern,
                space,
                transform: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
                domain: (0.0, 1.0),
            }),
            ..Default::default()
        };
        let linear = Pattern::Gradient(GradientKind::Linear);
        let normal = |space, pattern, texspace: bool| {
            let quad = MeshDesc {
                name: "Quad".into(),
                positions: vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]],
                indices: vec![[0, 1, 2], [0, 2, 3]],
                corner_uvs: [0, 1, 2, 0, 2, 3]
                    .iter()
                    .map(|&k| [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]][k])
                    .collect(),
                corner_generated: if texspace {
                    // c = (2y, −x, z) + (0.5, 0.5, 0): h = 2y (+0.5), ∂h/∂y = 2
                    let c = |p: [f32; 3]| [2.0 * p[1] + 0.5, -p[0] + 0.5, p[2]];
                    [0, 1, 2, 0, 2, 3]
                        .iter()
                        .map(|&k| c([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]][k]))
                        .collect()
                } else {
                    vec![]
                },
                material_ids: vec![0, 0],
                ..Default::default()
            };
            let material =
                MaterialDesc { bump_texture: Some(0), bump_distance: 0.1, bump_strength: 1.0, ..Default::default() };
            let desc = SceneDesc {
                meshes: vec![quad],
                materials: vec![material],
                textures: vec![ramp(space, pattern)],
                camera: camera_looking_along_y([0.0, -3.0, 0.0], 35.0, 4, 4),
                ..Default::default()
            };
            let scene = Scene::build(&desc).unwrap();
            let (o, d) = (Vec3::new(0.05, -0.1, 2.0), Vec3::new(0.0, 0.0, -1.0));
            let hit = scene.intersect(o, d, 0.0, f32::INFINITY).unwrap();
            scene.interaction(&hit, d).frame.n
        };
        let close = |a: Vec3, b: Vec3| (a - b).length() < 1e-3;
        let n = normal(Space::Generated, linear, true);
        assert!(close(n, Vec3::new(0.0, -0.2, 1.0).normalize()), "{n}");
        // on UVs: u = (x + 1)/2, so ∂h/∂x = ½
        let n = normal(Space::Uv, linear, false);
        assert!(close(n, Vec3::new(-0.05, 0.0, 1.0).normalize()), "{n}");
        // a mesh without Generated coordinates reads the origin everywhere: a constant, no bump
        assert!(close(normal(Space::Generated, linear, false), Vec3::Z));
        // noise: the tilt is the one of its central differences
        let noise =
            Pattern::Noise { noise: super::procedural::NoiseParams::fbm(2.0, 0.5, 2.0, 0.0, true), color: false };
        let n = normal(Space::Generated, noise, true);
        let p = Vec3::new(0.05, -0.1, 0.0);
        let c = |p: Vec3| Vec3::new(2.0 * p.y + 0.5, -p.x + 0.5, p.z);
        let e = 1e-3;
        let h = |p: Vec3| {
            super::procedural::noise_texture(
                c(p),
                &super::procedural::NoiseParams::fbm(2.0, 0.5, 2.0, 0.0, true),
                false,
            )
            .0
        };
        let g = Vec3::new(h(p + Vec3::X * e) - h(p - Vec3::X * e), h(p + Vec3::Y * e) - h(p - Vec3::Y * e), 0.0)
            / (2.0 * e);
        let want = (Vec3::Z - g * 0.1).normalize();
        assert!((n - want).length() < 0.02 * (1.0 + g.length()), "{n} vs {want}");
        assert!(g.length() > 0.1);
    }

    /// Ray visibility: camera rays pass an object the camera does not see (and the path's
    /// continuation from the camera through it too), other rays hit it; shadow rays pass an
    /// object that casts no shadow, while a path segment is blocked by it.
    #[test]
    fn camera_and_shadow_rays_pass_objects_they_do_not_see() {
        let quad = |name: &str, y: f32, camera_invisible, shadow_invisible| MeshDesc {
            name: name.into(),
            positions: vec![[-1.0, y, -1.0], [1.0, y, -1.0], [1.0, y, 1.0], [-1.0, y, 1.0]],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            camera_invisible,
            shadow_invisible,
            ..Default::default()
        };
        let desc = SceneDesc {
            meshes: vec![
                quad("Front", 0.0, true, false),
                quad("Middle", 1.0, false, true),
                quad("Back", 2.0, false, false),
            ],
            materials: vec![MaterialDesc::default()],
            camera: camera_looking_along_y([0.0, -3.0, 0.0], 35.0, 4, 4),
            ..Default::default()
        };
        let scene = Scene::build(&desc).unwrap();
        let (o, d) = (Vec3::new(0.1, -3.0, 0.05), Vec3::Y);
        let y = |h: Option<TriHit>| h.map(|h| (o + d * h.t).y);
        assert_eq!(y(scene.intersect(o, d, 0.0, f32::INFINITY)), Some(0.0));
        assert_eq!(y(scene.intersect_camera(o, d, 0.0, f32::INFINITY)), Some(1.0));
        let rays = [scene.camera.generate_ray(Vec2::new(2.0, 2.0), Vec2::splat(0.5)); 3];
        let hits = scene.intersect_camera_rays(&rays);
        let first = |r: &CameraRay, h: Option<TriHit>| h.map(|h| (r.origin + r.dir * h.t).y);
        assert!(hits[..3].iter().all(|&h| (first(&rays[0], h).unwrap() - 1.0).abs() < 1e-4), "{hits:?}");
        // from the back quad towards a light behind the front one: the middle quad casts no
        // shadow, the front one does
        let si = scene
            .interaction(&scene.intersect(Vec3::new(0.1, 3.0, 0.05), -Vec3::Y, 0.0, f32::INFINITY).unwrap(), -Vec3::Y);
        let light = |y: f32| LightSample {
            p: Vec3::new(0.1, y, 0.05),
            n: Vec3::Y,
            wi: -Vec3::Y,
            dist: 2.0 - y,
            radiance: Vec3::ONE,
            pdf: 1.0,
            is_delta: true,
        };
        assert!(scene.visible(&si, &light(0.5)));
        assert_eq!(scene.transmittance(&si, &light(0.5)), Some((Spectrum::ONE, false)));
        assert!(!scene.visible(&si, &light(-0.5)));
        assert!(scene.transmittance(&si, &light(-0.5)).is_none());
        assert!(!scene.segment_clear(&si, Vec3::new(0.1, 0.5, 0.05), false)); // a path segment is blocked
    }

    /// A light's Cast Shadow reaches the scene; the world (index past the lights) always
    /// casts shadows.
    #[test]
    fn lights_say_whether_they_cast_shadows() {
        let mut desc = crate::scene::builtin::cornell_box(8, 8);
        desc.lights.push(LightDesc::Point {
            name: "Fill".into(),
            position: [0.0, 0.5, 0.5],
            radius: 0.0,
            power: [1.0; 3],
            soft_falloff: true,
            visible_camera: false,
            cast_shadow: false,
        });
        let scene = Scene::build(&desc).unwrap();
        let fill = scene.lights.iter().position(|l| l.name == "Fill").unwrap() as u32;
        assert!(!scene.casts_shadow(fill));
        assert!((0..scene.lights.len() as u32).filter(|&i| i != fill).all(|i| scene.casts_shadow(i)));
        assert!(scene.casts_shadow(scene.env_light()));
    }

    /// Issue 49: a scene too large for the memory there aborted in an allocation halfway
    /// through its build; it is refused first, with what it needs and what is available.
    #[test]
    fn a_scene_larger_than_memory_is_refused_with_what_it_needs() {
        let e = check_memory(50_000_000, 10, Some(8 << 30)).expect_err("refused").to_string();
        assert!(e.contains("50000000 triangles") && e.contains("GiB") && e.contains("available"), "{e}");
        assert!(check_memory(1_000_000, 1_000_000, Some(8 << 30)).is_ok());
        assert!(check_memory(u32::MAX as u64, 0, None).is_ok()); // unknown: not refused
    }
}
