//! Materials: the parameters of the Principled-like uber-material, turned into a BSDF at a
//! surface point: Lambertian or Oren–Nayar base (under a dielectric specular layer), GGX or mirror metal (metallic), smooth glass
//! or rough GGX glass (transmission), mixed by their Principled weights, and a pass-through
//! lobe (Transparent BSDF, alpha as coverage) that takes probability τ from all of them.

use super::desc::{MaterialDesc, RayFactor};
use crate::bsdf::{Bsdf, Coat, ColourPower, Conductor, Dielectric, Lambert, Layered, Translucent};
use crate::error::SceneError;
use crate::math::Spectrum;
use glam::Vec3;

#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    pub base_color: Spectrum,
    pub emission: Spectrum,
    pub roughness: f32,
    /// The diffuse base's roughness σ (0 = Lambertian, above it Oren–Nayar).
    pub diffuse_roughness: f32,
    /// How its Oren–Nayar multiple scattering takes the colour: the scene's
    /// `SceneDesc::oren_nayar_rho_cubed` (set for every material by `Shading::new`).
    pub rough_diffuse_power: ColourPower,
    /// Its normal map's frame is built on the interpolated normal as it is, not normalized:
    /// the scene's `SceneDesc::normal_map_unnormalized_base` (set by `Shading::new`).
    pub normal_map_unnormalized_base: bool,
    /// A Holdout shader (`MaterialDesc::holdout`).
    pub holdout: bool,
    pub metallic: f32,
    pub transmission: f32,
    pub ior: f32,
    /// Specular layer over the diffuse base: IOR (1 = none) and coverage.
    pub specular_ior: f32,
    pub specular: f32,
    pub base_color_texture: Option<u32>,
    pub roughness_texture: Option<u32>,
    pub metallic_texture: Option<u32>,
    pub alpha_texture: Option<u32>,
    pub normal_texture: Option<u32>,
    pub normal_strength: f32,
    pub bump_texture: Option<u32>,
    /// The base colour is multiplied by the vertex colour (`MaterialDesc::vertex_color`).
    pub vertex_color: bool,
    /// Bump-shadow the diffuse lobes under a mapped normal (`MaterialDesc::bump_map_correction`).
    pub bump_map_correction: bool,
    pub bump_distance: f32,
    pub bump_strength: f32,
    pub emission_texture: Option<u32>,
    pub metal_color: Option<Spectrum>,
    pub glass_color: Option<Spectrum>,
    /// The glass lobe's reflection colour, when not the glass colour (Principled: white).
    pub glass_reflection_tint: Option<Spectrum>,
    /// The glass lobe transmits √colour per interface (Principled).
    pub glass_sqrt_tint: bool,
    pub metal_roughness: Option<f32>,
    pub glass_roughness: Option<f32>,
    pub multiscatter: bool,
    /// The Principled coat over the other lobes (weight 0: none).
    pub coat: Coat,
    /// The metal lobe reflects its colour at every angle (Glossy BSDF), not Schlick's curve.
    pub metal_constant_fresnel: bool,
    /// Specular Tint of the dielectric layer over the base (white: untinted).
    pub specular_tint: Spectrum,
    /// The diffuse base's subsurface layer (`MaterialDesc::subsurface`; weight 0: none).
    pub subsurface: crate::medium::subsurface::Subsurface,
    /// Share of diffuse transmission among the lobes, and its colour (None: the base colour).
    pub translucency: f32,
    pub translucent_color: Option<Spectrum>,
    /// Pass-through probability τ and tint (Transparent BSDF, alpha as coverage).
    pub transparency: f32,
    pub transparent_color: Spectrum,
    /// Always the full Principled mixture, even for a single lobe (benchmarks of the
    /// shortcuts only; set by `Scene::build`).
    pub general: bool,
    /// The material this one blends into by the luminance of texture `blend_texture`
    /// (`MaterialDesc::blend`; `Scene::bsdf` mixes their BSDFs lobe by lobe).
    pub blend: Option<Box<Material>>,
    pub blend_texture: Option<u32>,
    pub blend_ray: Option<RayFactor>,
    /// `MaterialDesc::blend_ray_curve` (empty: none).
    pub blend_ray_curve: Vec<f32>,
}

/// The largest emission (and light power) accepted: beyond it a path's throughput × emission
/// can overflow f32 (Blender stores an infinite strength as f32::MAX, 3.4e38).
pub const MAX_RADIANCE: f32 = 1e20;

/// The warnings for a material's inputs that `Material::from_desc` clamps: each names the
/// material, the value given and the value used. Blender's own UI keeps these in range, but
/// the Python API and USD stages do not.
pub fn range_warnings(d: &MaterialDesc) -> Vec<String> {
    let mut out = Vec::new();
    let mut unit = |what: &str, x: f32| {
        if x.is_finite() && !(0.0..=1.0).contains(&x) {
            out.push(format!("material '{}': {what} {x} is outside 0…1; {} is used", d.name, x.clamp(0.0, 1.0)));
        }
    };
    for (what, x) in [
        ("roughness", d.roughness),
        ("diffuse roughness", d.diffuse_roughness),
        ("metallic", d.metallic),
        ("transmission", d.transmission),
        ("specular", d.specular),
        ("coat weight", d.coat),
        ("coat roughness", d.coat_roughness),
        ("translucency", d.translucency),
        ("transparency", d.transparency),
        ("subsurface weight", d.subsurface.as_ref().map_or(0.0, |s| s.weight)),
    ] {
        unit(what, x);
    }
    for (i, x) in d.base_color.iter().enumerate() {
        if x.is_finite() && !(0.0..=1.0).contains(x) {
            let used = Vec3::from_array(d.base_color).clamp(Vec3::ZERO, Vec3::ONE);
            out.push(format!(
                "material '{}': base colour {:?} has channel {i} outside 0…1 (an albedo); ({}, {}, {}) is used",
                d.name, d.base_color, used.x, used.y, used.z
            ));
            break;
        }
    }
    if d.ior.is_finite() && d.ior <= 0.0 {
        out.push(format!("material '{}': IOR {} is not above 0; 1.5 is used", d.name, d.ior));
    }
    out
}

/// The subsurface layer of a material (`Subsurface::NONE` without one, or with weight 0 or
/// every radius 0 — Cycles scatters a channel of radius below 1e-8 as a Lambertian), checked:
/// finite, radius not negative, a known method; the weight clamped to [0, 1].
pub fn subsurface_from_desc(d: &MaterialDesc) -> Result<crate::medium::subsurface::Subsurface, SceneError> {
    use crate::medium::subsurface::{Subsurface, SubsurfaceMethod};
    let Some(s) = &d.subsurface else { return Ok(Subsurface::NONE) };
    let bad = |what: &str| SceneError::Material { material: d.name.clone(), what: format!("its subsurface: {what}") };
    if s.radius.iter().chain([&s.weight, &s.anisotropy, &s.ior]).any(|x| !x.is_finite()) {
        return Err(bad("NaN or Inf parameter"));
    }
    if s.radius.iter().any(|&r| r < 0.0) {
        return Err(bad("negative radius"));
    }
    let method = match s.method.as_str() {
        "random_walk" => SubsurfaceMethod::RandomWalk,
        "legacy" => SubsurfaceMethod::Legacy,
        "skin" => SubsurfaceMethod::Skin,
        other => return Err(bad(&format!("unknown method '{other}' (random_walk, legacy or skin)"))),
    };
    let weight = s.weight.clamp(0.0, 1.0);
    if weight <= 0.0 || s.radius.iter().all(|&r| r < 1e-8) {
        return Ok(Subsurface::NONE);
    }
    Ok(Subsurface { weight, radius: Vec3::from_array(s.radius), anisotropy: s.anisotropy, ior: s.ior, method })
}

/// The medium of a material's volume (None without one, or for a clear one), its
/// coefficients checked: finite and not negative, the anisotropy within (−1, 1).
pub fn medium_from_desc(
    d: &MaterialDesc,
    textures: &[super::texture::Texture],
) -> Result<Option<crate::medium::Medium>, SceneError> {
    let Some(v) = &d.volume else { return Ok(None) };
    let bad = |what: &str| SceneError::Material { material: d.name.clone(), what: format!("its volume: {what}") };
    let all = v.scattering.iter().chain(&v.absorption).chain(&v.emission).chain([&v.anisotropy]);
    if all.clone().any(|x| !x.is_finite()) {
        return Err(bad("NaN or Inf coefficient"));
    }
    if v.scattering.iter().chain(&v.absorption).chain(&v.emission).any(|&x| x < 0.0) {
        return Err(bad("negative coefficient"));
    }
    if v.emission.iter().chain(&v.scattering).chain(&v.absorption).any(|&x| x > MAX_RADIANCE) {
        return Err(bad(&format!("coefficient above {MAX_RADIANCE:e}")));
    }
    if !(v.anisotropy > -1.0 && v.anisotropy < 1.0) {
        return Err(bad(&format!("anisotropy {} is not inside (−1, 1)", v.anisotropy)));
    }
    let (sigma_s, sigma_a) = (Vec3::from_array(v.scattering), Vec3::from_array(v.absorption));
    use crate::medium::Phase;
    let phase = match v.phase.as_str() {
        "" | "hg" | "henyey_greenstein" => Phase::hg(v.anisotropy),
        "rayleigh" => Phase::Rayleigh,
        "draine" => Phase::draine(v.anisotropy, v.alpha),
        "mie" => Phase::mie(v.diameter),
        other => return Err(bad(&format!("unknown phase function '{other}' (hg, rayleigh, draine or mie)"))),
    };
    if !(v.alpha.is_finite() && v.diameter.is_finite()) {
        return Err(bad("NaN or Inf phase parameter"));
    }
    let field = match &v.density {
        None => None,
        Some(f) => {
            let Some(t) = textures.get(f.texture as usize) else {
                return Err(bad(&format!("density texture {} but the scene has {}", f.texture, textures.len())));
            };
            if f.world_to_object.iter().chain(&f.generated).any(|x| !x.is_finite()) {
                return Err(bad("NaN or Inf in its density's coordinates"));
            }
            let density = crate::medium::Density {
                texture: f.texture,
                world_to_object: f.world_to_object,
                generated: f.generated,
                max: t.max_value().max(0.0),
            };
            Some(crate::medium::Field { density, sigma_s, sigma_a })
        }
    };
    let m = match field {
        Some(_) => crate::medium::Medium {
            sigma_s: Vec3::ZERO,
            sigma_a: Vec3::ZERO,
            emission: Vec3::from_array(v.emission),
            phase,
            field,
        },
        None => crate::medium::Medium { sigma_s, sigma_a, emission: Vec3::from_array(v.emission), phase, field: None },
    };
    Ok((!m.is_vacuum()).then_some(m))
}

impl Material {
    pub fn from_desc(d: &MaterialDesc, textures: usize) -> Result<Material, SceneError> {
        let bad = |what: &str| SceneError::Material { material: d.name.clone(), what: what.to_string() };
        let used = [
            d.base_color_texture,
            d.roughness_texture,
            d.metallic_texture,
            d.alpha_texture,
            d.normal_texture,
            d.emission_texture,
            d.bump_texture,
        ];
        let factors = d.blend_texture.is_some() as u32 + d.blend_ray.is_some() as u32;
        let blend = match &d.blend {
            None if factors == 0 => None,
            Some(_) if factors != 1 => {
                return Err(bad("a blend takes one factor: blend_texture or blend_ray"));
            }
            Some(b) if b.blend.is_some() => return Err(bad("its blend material blends again (one level)")),
            Some(b) => Some(Box::new(Material::from_desc(b, textures).map_err(|e| match e {
                SceneError::Material { what, .. } => bad(&format!("its blend material: {what}")),
                other => other,
            })?)),
            None => return Err(bad("blend_texture or blend_ray without a blend material")),
        };
        if let Some(RayFactor::Fresnel(x) | RayFactor::LayerFresnel(x) | RayFactor::LayerFacing(x)) = d.blend_ray {
            if !x.is_finite() {
                return Err(bad("NaN or Inf blend_ray"));
            }
        }
        if !d.blend_ray_curve.is_empty() && (d.blend_ray.is_none() || d.blend_ray_curve.len() < 2) {
            return Err(bad("blend_ray_curve needs a blend_ray and at least 2 values"));
        }
        if d.blend_ray_curve.iter().any(|x| !x.is_finite()) {
            return Err(bad("NaN or Inf in blend_ray_curve"));
        }
        for t in used.into_iter().chain([d.blend_texture]).flatten() {
            if t as usize >= textures {
                return Err(bad(&format!("uses texture {t} but the scene has {textures}")));
            }
        }
        let scalars = [
            d.roughness,
            d.diffuse_roughness,
            d.metallic,
            d.transmission,
            d.ior,
            d.transparency,
            d.specular_ior,
            d.specular,
            d.normal_strength,
            d.bump_distance,
            d.bump_strength,
            d.coat,
            d.coat_roughness,
            d.coat_ior,
            d.translucency,
        ];
        let lobe_colors = d
            .metal_color
            .iter()
            .chain(d.glass_color.iter())
            .chain(d.glass_reflection_tint.iter())
            .flatten()
            .chain(d.transparent_color.iter())
            .chain(d.coat_tint.iter())
            .chain(d.specular_tint.iter())
            .chain(d.translucent_color.iter().flatten())
            .chain(d.metal_roughness.iter())
            .chain(d.glass_roughness.iter());
        if d.base_color.iter().chain(d.emission.iter()).chain(scalars.iter()).chain(lobe_colors).any(|x| !x.is_finite())
        {
            return Err(bad("NaN or Inf parameter"));
        }
        if d.emission.iter().any(|&x| x < 0.0) {
            return Err(bad("negative emission"));
        }
        // Blender stores an infinite strength as f32::MAX: finite, but every path that
        // meets it overflows to Inf and is dropped (a black image and a "no light" warning)
        if d.emission.iter().any(|&x| x > MAX_RADIANCE) {
            return Err(bad(&format!(
                "emission {:.3e} is too large for single precision (at most {MAX_RADIANCE:e})",
                d.emission.iter().fold(0.0f32, |a, &x| a.max(x))
            )));
        }
        let subsurface = subsurface_from_desc(d)?;
        Ok(Material {
            subsurface,
            name: d.name.clone(),
            // Albedo above 1 would add energy; Cycles clamps the base colour the same way.
            base_color: Vec3::from_array(d.base_color).clamp(Vec3::ZERO, Vec3::ONE),
            emission: Vec3::from_array(d.emission),
            roughness: d.roughness.clamp(0.0, 1.0),
            diffuse_roughness: d.diffuse_roughness.clamp(0.0, 1.0),
            rough_diffuse_power: ColourPower::Squared,
            normal_map_unnormalized_base: false,
            holdout: d.holdout,
            metallic: d.metallic.clamp(0.0, 1.0),
            transmission: d.transmission.clamp(0.0, 1.0),
            // η = 1 exactly would make refraction a pass-through; keep it just off 1.
            ior: if d.ior > 0.0 && (d.ior - 1.0).abs() > 1e-4 {
                d.ior
            } else if d.ior > 0.0 {
                1.0 + 1e-4
            } else {
                1.5
            },
            // the layer's table covers η ≤ 3; below 1 (or exactly 1) there is no layer
            specular_ior: if d.specular_ior > 1.0 + 1e-4 { d.specular_ior.min(3.0) } else { 1.0 },
            specular: d.specular.clamp(0.0, 1.0),
            base_color_texture: d.base_color_texture,
            roughness_texture: d.roughness_texture,
            metallic_texture: d.metallic_texture,
            alpha_texture: d.alpha_texture,
            normal_texture: d.normal_texture,
            normal_strength: d.normal_strength.max(0.0),
            bump_texture: d.bump_texture,
            vertex_color: d.vertex_color,
            bump_map_correction: d.bump_map_correction,
            bump_distance: d.bump_distance,
            bump_strength: d.bump_strength.clamp(0.0, 1.0),
            emission_texture: d.emission_texture,
            metal_color: d.metal_color.map(|c| Vec3::from_array(c).clamp(Vec3::ZERO, Vec3::ONE)),
            glass_color: d.glass_color.map(|c| Vec3::from_array(c).clamp(Vec3::ZERO, Vec3::ONE)),
            glass_reflection_tint: d.glass_reflection_tint.map(|c| Vec3::from_array(c).clamp(Vec3::ZERO, Vec3::ONE)),
            glass_sqrt_tint: d.glass_sqrt_tint,
            metal_roughness: d.metal_roughness.map(|r| r.clamp(0.0, 1.0)),
            glass_roughness: d.glass_roughness.map(|r| r.clamp(0.0, 1.0)),
            multiscatter: d.multiscatter,
            coat: Coat {
                weight: d.coat.clamp(0.0, 1.0),
                // (Cycles clamps the IOR at 1; the albedo table covers η ≤ 3)
                eta: d.coat_ior.clamp(1.0, 3.0),
                roughness: d.coat_roughness.clamp(0.0, 1.0),
                // (a tint above 1 would add energy at every crossing, as a base colour above 1)
                tint: Vec3::from_array(d.coat_tint).clamp(Vec3::ZERO, Vec3::ONE),
            },
            specular_tint: Vec3::from_array(d.specular_tint).clamp(Vec3::ZERO, Vec3::ONE),
            metal_constant_fresnel: d.metal_constant_fresnel,
            translucency: d.translucency.clamp(0.0, 1.0),
            translucent_color: d.translucent_color.map(|c| Vec3::from_array(c).clamp(Vec3::ZERO, Vec3::ONE)),
            transparency: d.transparency.clamp(0.0, 1.0),
            transparent_color: Vec3::from_array(d.transparent_color).clamp(Vec3::ZERO, Vec3::ONE),
            general: false,
            blend,
            blend_texture: d.blend_texture,
            blend_ray: d.blend_ray,
            blend_ray_curve: d.blend_ray_curve.iter().map(|x| x.clamp(0.0, 1.0)).collect(),
        })
    }

    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// Does the surface emit: this material, or the one it blends into by a texture (a
    /// blend by the view emits this material's emission only)?
    pub fn emits(&self) -> bool {
        let blend_emits = self.blend.as_ref().is_some_and(|b| b.is_emissive());
        match self.unseen_blend() {
            // (what every ray but the camera's sees of a blend by Is Camera Ray)
            Some(f) => (self.is_emissive() && f < 1.0) || (blend_emits && f > 0.0),
            None => self.is_emissive() || (self.blend_texture.is_some() && blend_emits),
        }
    }

    /// For a blend by Is Camera Ray: its factor for every ray but the camera's (the curve
    /// after the node at 0), which light sampling and scattered rays see.
    #[inline]
    pub fn unseen_blend(&self) -> Option<f32> {
        (self.blend.is_some() && self.blend_texture.is_none() && self.blend_ray == Some(RayFactor::CameraRay))
            .then(|| ray_curve(&self.blend_ray_curve, 0.0).clamp(0.0, 1.0))
    }

    /// The BSDF at a surface point; `front` is true when the ray arrives on the side the
    /// geometric normal points to (outside of a closed mesh), which orients refraction.
    #[inline]
    pub fn bsdf(&self, front: bool) -> Bsdf {
        self.bsdf_with(front, self.base_color, self.roughness, self.metallic, self.transparency)
    }

    /// The parameters its surface walks beneath with: its own subsurface's, or (a blend into
    /// a material that has one) the blended material's.
    #[inline]
    pub fn walk(&self) -> crate::medium::subsurface::Subsurface {
        match &self.blend {
            Some(b) if !self.subsurface.is_some() => b.subsurface,
            _ => self.subsurface,
        }
    }

    /// May the surface let light straight through (a transparency, constant or textured)?
    #[inline]
    pub fn is_transparent(&self) -> bool {
        self.transparency > 0.0
            || self.alpha_texture.is_some()
            || self.blend.as_ref().is_some_and(|b| b.is_transparent())
    }

    /// The BSDF with base colour, roughness, metallic and transparency τ given (where
    /// textures replace them).
    #[inline]
    pub fn bsdf_with(&self, front: bool, base_color: Spectrum, roughness: f32, metallic: f32, tau: f32) -> Bsdf {
        self.lobes(front, base_color, roughness, metallic, tau, self.general)
    }

    /// `bsdf_with`, always as the full Principled mixture when `general` (what a blend of
    /// two materials mixes: `Bsdf::blend`).
    #[inline]
    pub fn lobes(
        &self,
        front: bool,
        base_color: Spectrum,
        roughness: f32,
        metallic: f32,
        tau: f32,
        general: bool,
    ) -> Bsdf {
        let (m, t, tl) = (metallic, self.transmission, self.translucency);
        let rest = (1.0 - tau) * (1.0 - tl);
        let w = [(1.0 - m) * (1.0 - t) * rest, m * rest, (1.0 - m) * t * rest];
        let translucent = Translucent {
            weight: (1.0 - tau) * tl,
            albedo: self.translucent_color.unwrap_or(base_color),
            ..Translucent::NONE
        };
        // the specular layer has the same IOR seen from either side (Cycles inverts it on
        // back faces; opaque surfaces are rarely seen from behind)
        let diffuse = Layered {
            base: Lambert { power: self.rough_diffuse_power, ..Lambert::rough(base_color, self.diffuse_roughness) },
            eta: self.specular_ior,
            roughness,
            coverage: self.specular,
            tint: self.specular_tint,
            subsurface: self.subsurface.weight,
            subsurface_ior: self.subsurface.skin_ior().map_or(0.0, |i| {
                if i.is_finite() {
                    i.clamp(1.01, 3.8)
                } else {
                    1.4
                }
            }),
        };
        // a roughness texture drives every lobe; else each lobe may have its own
        let (rm, rg) = if self.roughness_texture.is_some() {
            (roughness, roughness)
        } else {
            (self.metal_roughness.unwrap_or(roughness), self.glass_roughness.unwrap_or(roughness))
        };
        let metal =
            // (the Principled metal's edge takes the Specular Tint as its F82 tint)
            Conductor {
                f0: self.metal_color.unwrap_or(base_color),
                roughness: rm,
                multiscatter: self.multiscatter,
                f82: self.specular_tint,
                constant: self.metal_constant_fresnel,
            };
        let eta = if front { self.ior } else { 1.0 / self.ior };
        let colour = self.glass_color.unwrap_or(base_color);
        let tint = if self.glass_sqrt_tint { colour.max(Vec3::ZERO).powf(0.5) } else { colour };
        let glass = Dielectric {
            eta,
            tint,
            reflection_tint: self.glass_reflection_tint.unwrap_or(tint),
            roughness: rg,
            multiscatter: self.multiscatter,
        };
        let coat = self.coat;
        if tau > 0.0 || general || coat.is_some() || translucent.is_some() {
            Bsdf::Principled {
                diffuse,
                metal,
                glass,
                w,
                pass: tau,
                pass_tint: self.transparent_color,
                coat,
                translucent,
            }
        } else if w[1] <= 0.0 && w[2] <= 0.0 && !diffuse.has_layer() && diffuse.subsurface <= 0.0 {
            Bsdf::Lambert(diffuse.base)
        } else if w[1] <= 0.0 && w[2] <= 0.0 {
            Bsdf::Layered(diffuse)
        } else if w[0] <= 0.0 && w[2] <= 0.0 {
            Bsdf::Conductor(metal)
        } else if w[0] <= 0.0 && w[1] <= 0.0 {
            Bsdf::Dielectric(glass)
        } else {
            Bsdf::Principled {
                diffuse,
                metal,
                glass,
                w,
                pass: 0.0,
                pass_tint: Spectrum::ZERO,
                coat,
                translucent: Translucent::NONE,
            }
        }
    }
}

/// `curve` (values at evenly spaced points of [0, 1]) at `x`, interpolated linearly; `x`
/// itself when the curve is empty.
#[inline]
pub fn ray_curve(curve: &[f32], x: f32) -> f32 {
    if curve.len() < 2 {
        return x;
    }
    let t = x.clamp(0.0, 1.0) * (curve.len() - 1) as f32;
    let i = (t as usize).min(curve.len() - 2);
    let f = t - i as f32;
    curve[i] * (1.0 - f) + curve[i + 1] * f
}

/// The kind of ray a surface is seen by, as Light Path's outputs read it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RayKind {
    /// A camera ray, or its continuation straight through transparent surfaces.
    Camera,
    /// A ray a path scattered into (after its first bounce).
    Scattered,
    /// The shadow ray of light sampling.
    Shadow,
}

impl RayFactor {
    /// The factor for a `ray` whose direction makes cosine `cos` with the shading normal
    /// (before normal and bump maps, on the viewer's side), arriving on the front (`front`) or
    /// the back of the surface — Cycles' Fresnel, Layer Weight, Geometry and Light Path nodes.
    #[inline]
    pub fn at(&self, cos: f32, front: bool, ray: RayKind) -> f32 {
        use crate::bsdf::microfacet::fresnel_dielectric;
        match *self {
            RayFactor::Fresnel(ior) => {
                let eta = ior.max(1e-5);
                fresnel_dielectric(cos, if front { eta } else { 1.0 / eta })
            }
            RayFactor::LayerFresnel(blend) => {
                let eta = (1.0 - blend).max(1e-5);
                fresnel_dielectric(cos, if front { 1.0 / eta } else { eta })
            }
            RayFactor::LayerFacing(blend) => {
                let mut f = cos.abs();
                if blend != 0.5 {
                    let b = blend.clamp(0.0, 1.0 - 1e-5);
                    f = f.powf(if b < 0.5 { 2.0 * b } else { 0.5 / (1.0 - b) });
                }
                1.0 - f
            }
            RayFactor::ShadowRay => f32::from(u8::from(ray == RayKind::Shadow)),
            RayFactor::CameraRay => f32::from(u8::from(ray == RayKind::Camera)),
            RayFactor::Backfacing => f32::from(u8::from(!front)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glass_of(d: &MaterialDesc, front: bool) -> Dielectric {
        match Material::from_desc(d, 0).unwrap().bsdf(front) {
            Bsdf::Dielectric(g) => g,
            other => panic!("not glass: {other:?}"),
        }
    }

    /// Blender's Glass BSDF tints reflection and transmission by its colour; the Principled
    /// BSDF reflects untinted and transmits √(base colour) at each interface, so that light
    /// entering and leaving takes the base colour once (as Cycles sets its closures up) —
    /// from either side.
    #[test]
    fn principled_and_glass_bsdf_tint_their_glass_as_cycles() {
        let c = [0.81f32, 0.49, 0.25];
        let glass_node = MaterialDesc { base_color: c, transmission: 1.0, ior: 1.5, ..Default::default() };
        let principled =
            MaterialDesc { glass_reflection_tint: Some([1.0; 3]), glass_sqrt_tint: true, ..glass_node.clone() };
        for front in [true, false] {
            let g = glass_of(&glass_node, front);
            assert_eq!((g.tint, g.reflection_tint), (Vec3::from_array(c), Vec3::from_array(c)));
            let p = glass_of(&principled, front);
            assert!((p.tint - Vec3::new(0.9, 0.7, 0.5)).abs().max_element() < 1e-6, "{}", p.tint);
            assert_eq!(p.reflection_tint, Vec3::ONE);
        }
    }

    /// Out-of-range layer inputs cannot add energy: a coat tint above 1 (a linked colour can
    /// be), a coat weight, translucency or diffuse roughness outside [0, 1] are clamped, so
    /// a white furnace of the material stays at most 1. A tint of 5 made a Cornell box's
    /// image mean 4·10³³ before.
    #[test]
    fn out_of_range_layer_inputs_are_clamped() {
        let d = MaterialDesc {
            coat: 5.0,
            coat_tint: [-1.0, 5.0, 0.5],
            coat_ior: 0.0,
            translucency: 2.0,
            translucent_color: Some([9.0, -1.0, 0.5]),
            diffuse_roughness: 7.0,
            base_color: [1.0; 3],
            ..MaterialDesc::default()
        };
        let m = Material::from_desc(&d, 0).unwrap();
        assert_eq!(m.coat.weight, 1.0);
        assert_eq!(m.coat.tint, Vec3::new(0.0, 1.0, 0.5));
        assert!(m.coat.eta >= 1.0 && m.translucency == 1.0 && m.diffuse_roughness == 1.0);
        let b = m.bsdf(true);
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8)] {
            let (albedo, _) = crate::bsdf::testing::white_furnace(&b, wo, 50_000, 3);
            assert!(albedo <= 1.0 + 0.01, "{albedo}");
        }
    }

    /// A blend needs its factor texture, that texture must exist, and the blended material
    /// may not blend again; each refusal names the material.
    #[test]
    fn bad_blends_are_refused_naming_the_material() {
        let other = MaterialDesc { name: "rust".into(), ..Default::default() };
        let with = |blend: Option<MaterialDesc>, tex: Option<u32>| MaterialDesc {
            name: "paint".into(),
            blend: blend.map(Box::new),
            blend_texture: tex,
            ..Default::default()
        };
        let nested = with(Some(with(Some(other.clone()), Some(0))), Some(0));
        let bad_inner = with(Some(MaterialDesc { roughness: f32::NAN, ..other.clone() }), Some(0));
        let two = MaterialDesc { blend_ray: Some(RayFactor::Fresnel(1.45)), ..with(Some(other.clone()), Some(0)) };
        let nan_view =
            MaterialDesc { blend_ray: Some(RayFactor::LayerFacing(f32::NAN)), ..with(Some(other.clone()), None) };
        for (d, what) in [
            (with(Some(other.clone()), None), "one factor"),
            (two, "one factor"),
            (nan_view, "NaN or Inf blend_ray"),
            (with(None, Some(0)), "without a blend material"),
            (with(Some(other.clone()), Some(3)), "uses texture 3"),
            (nested, "blends again"),
            (bad_inner, "its blend material: NaN"),
        ] {
            let e = Material::from_desc(&d, 1).unwrap_err().to_string();
            assert!(e.contains("paint") && e.contains(what), "{e}");
        }
        assert!(Material::from_desc(&with(Some(other), Some(0)), 1).unwrap().blend.is_some());
    }

    /// The view factors against their definitions: Fresnel at normal incidence is F0 of the
    /// IOR (inverted from the back), reaching 1 at grazing; Layer Weight's Fresnel is the
    /// Fresnel of IOR 1/(1 − blend); Facing at blend 0.5 is 1 − |cos|, and its exponent
    /// follows the blend (0.25 → |cos|^0.5, 0.75 → |cos|^2).
    #[test]
    fn ray_factors_follow_cycles_nodes() {
        use RayKind::*;
        let f0 = |eta: f32| ((eta - 1.0) / (eta + 1.0)).powi(2);
        let near = |a: f32, b: f32| (a - b).abs() < 1e-5;
        assert!(near(RayFactor::Fresnel(1.5).at(1.0, true, Scattered), f0(1.5)));
        assert!(near(RayFactor::Fresnel(1.5).at(1.0, false, Scattered), f0(1.0 / 1.5)));
        assert!(RayFactor::Fresnel(1.5).at(1e-4, true, Scattered) > 0.99);
        assert!(near(RayFactor::LayerFresnel(0.2).at(1.0, true, Scattered), f0(1.0 / 0.8)));
        assert!(near(
            RayFactor::LayerFresnel(0.2).at(0.6, true, Scattered),
            RayFactor::Fresnel(1.25).at(0.6, true, Scattered)
        ));
        let kinds = |f: RayFactor| [Camera, Scattered, Shadow].map(|k| f.at(0.3, true, k));
        assert_eq!(kinds(RayFactor::ShadowRay), [0.0, 0.0, 1.0]);
        assert_eq!(kinds(RayFactor::CameraRay), [1.0, 0.0, 0.0]);
        assert_eq!(kinds(RayFactor::Fresnel(1.5)), [RayFactor::Fresnel(1.5).at(0.3, true, Scattered); 3]);
        assert_eq!(
            (RayFactor::Backfacing.at(0.3, true, Camera), RayFactor::Backfacing.at(0.3, false, Camera)),
            (0.0, 1.0)
        );
        assert_eq!(RayFactor::Backfacing.at(0.7, false, Shadow), 1.0); // (shadow rays see the side they cross)

        // a curve after the factor: its table interpolated, the identity without one
        let ramp = [0.0, 0.0, 1.0, 1.0];
        assert!(
            near(ray_curve(&ramp, 0.5), 0.5) && near(ray_curve(&ramp, 0.2), 0.0) && near(ray_curve(&ramp, 1.0), 1.0)
        );
        assert!(near(ray_curve(&ramp, 0.45), 0.35) && near(ray_curve(&[], 0.3), 0.3));
        for (blend, k) in [(0.5f32, 1.0f32), (0.25, 0.5), (0.75, 2.0)] {
            for cos in [0.1f32, 0.5, 0.9] {
                assert!(
                    near(RayFactor::LayerFacing(blend).at(cos, true, Scattered), 1.0 - cos.powf(k)),
                    "{blend} {cos}"
                );
            }
        }
    }
}
