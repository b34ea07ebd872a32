//! The only file that knows about Python: `gdmlt._core`. Scenes arrive as dicts of numpy
//! arrays (their layout: `scene/desc.rs`, whose types this file fills), renders release the GIL, report
//! progress to a callback that can cancel, and Rust panics become Python exceptions.

use crate::film::Image;
use crate::integrator::{self, Method, RenderControl, RenderSettings};
use crate::path::PathSettings;
use crate::scene::{
    self, AreaShape, CameraDesc, LightDesc, MaterialDesc, MeshDesc, Projection, SceneDesc, SensorFit, TextureDesc,
    TextureExtension,
};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::sync::Arc;
use std::time::Duration;

fn verr(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}

// The keys the parsers asked each dict for (by the dict's address), while a scene dict is
// parsed: a key a dict has and no parser asked for is almost always a misspelling ("lense"),
// reported as a warning naming the dict with the closest asked-for key. The parsers are the
// one list of the layout's keys.
thread_local! {
    static KEYS_ASKED: std::cell::RefCell<std::collections::HashMap<usize, Vec<&'static str>>> =
        std::cell::RefCell::new(std::collections::HashMap::new());
}

/// `d[key]` if present — the one way the parsers read a dict (it notes the key as known).
fn item<'py>(d: &Bound<'py, PyDict>, key: &'static str) -> PyResult<Option<Bound<'py, PyAny>>> {
    KEYS_ASKED.with(|m| m.borrow_mut().entry(d.as_ptr() as usize).or_default().push(key));
    d.get_item(key)
}

fn get<'py>(d: &Bound<'py, PyDict>, key: &'static str, ctx: &str) -> PyResult<Bound<'py, PyAny>> {
    item(d, key)?.ok_or_else(|| verr(format!("{ctx}: missing '{key}'")))
}

fn get_or<'py, T: FromPyObjectOwned<'py>>(
    d: &Bound<'py, PyDict>,
    key: &'static str,
    default: T,
    ctx: &str,
) -> PyResult<T> {
    match item(d, key)? {
        Some(v) if !v.is_none() => {
            v.extract::<T>().map_err(|e| verr(format!("{ctx}: '{key}': {}", Into::<PyErr>::into(e))))
        }
        _ => Ok(default),
    }
}

/// A numpy array of dtype T, shape (N, cols) or flat with a multiple of `cols` entries.
fn flat_array<T: numpy::Element + Copy>(
    obj: &Bound<'_, PyAny>,
    cols: usize,
    what: &str,
    dtype: &str,
) -> PyResult<Vec<T>> {
    let arr: PyReadonlyArrayDyn<T> =
        obj.extract().map_err(|_| verr(format!("{what}: expected a {dtype} numpy array")))?;
    let shape = arr.shape();
    let ok = (shape.len() == 2 && shape[1] == cols) || (shape.len() == 1 && shape[0] % cols == 0);
    if !ok {
        return Err(verr(format!("{what}: unexpected shape {shape:?} (need N×{cols})")));
    }
    Ok(arr.as_array().iter().copied().collect())
}

fn floats(obj: &Bound<'_, PyAny>, cols: usize, what: &str) -> PyResult<Vec<f32>> {
    flat_array(obj, cols, what, "float32")
}

fn uints(obj: &Bound<'_, PyAny>, cols: usize, what: &str) -> PyResult<Vec<u32>> {
    flat_array(obj, cols, what, "uint32")
}

fn vec3s(v: Vec<f32>) -> Vec<[f32; 3]> {
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn rgb(d: &Bound<'_, PyDict>, key: &'static str, default: [f32; 3], ctx: &str) -> PyResult<[f32; 3]> {
    get_or(d, key, default, ctx)
}

fn matrix(d: &Bound<'_, PyDict>, key: &'static str, ctx: &str) -> PyResult<[[f32; 4]; 4]> {
    let v = floats(&get(d, key, ctx)?, 4, &format!("{ctx}: {key}"))?;
    if v.len() != 16 {
        return Err(verr(format!("{ctx}: {key} must be 4×4")));
    }
    Ok([0, 1, 2, 3].map(|r| [v[4 * r], v[4 * r + 1], v[4 * r + 2], v[4 * r + 3]]))
}

fn parse_mesh(d: &Bound<'_, PyDict>) -> PyResult<MeshDesc> {
    let name: String = get_or(d, "name", "mesh".to_string(), "mesh")?;
    let ctx = format!("mesh '{name}'");
    let positions = vec3s(floats(&get(d, "positions", &ctx)?, 3, &format!("{ctx}: positions"))?);
    let idx = uints(&get(d, "indices", &ctx)?, 3, &format!("{ctx}: indices"))?;
    let indices = idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let corner_normals = match item(d, "normals")? {
        Some(n) if !n.is_none() => vec3s(floats(&n, 3, &format!("{ctx}: normals"))?),
        _ => vec![],
    };
    let material_ids = match item(d, "material_ids")? {
        Some(m) if !m.is_none() => uints(&m, 1, &format!("{ctx}: material_ids"))?,
        _ => vec![],
    };
    let corner_uvs = match item(d, "uvs")? {
        Some(u) if !u.is_none() => {
            floats(&u, 2, &format!("{ctx}: uvs"))?.chunks_exact(2).map(|c| [c[0], c[1]]).collect()
        }
        _ => vec![],
    };
    let corner_colors = match item(d, "colors")? {
        Some(c) if !c.is_none() => vec3s(floats(&c, 3, &format!("{ctx}: colors"))?),
        _ => vec![],
    };
    let corners = |key: &'static str| -> PyResult<Vec<[f32; 3]>> {
        Ok(match item(d, key)? {
            Some(c) if !c.is_none() => vec3s(floats(&c, 3, &format!("{ctx}: {key}"))?),
            _ => vec![],
        })
    };
    let (corner_generated, corner_object) = (corners("generated")?, corners("object")?);
    let transforms = match item(d, "transforms")? {
        Some(t) if !t.is_none() => {
            floats(&t, 12, &format!("{ctx}: transforms (row-major 3×4 object-to-world matrices)"))?
                .chunks_exact(12)
                .map(|c| std::array::from_fn(|k| c[k]))
                .collect()
        }
        _ => vec![],
    };
    let pass_index = get_or(d, "pass_index", 0, &ctx)?;
    let camera_invisible = !get_or(d, "visible_camera", true, &ctx)?;
    let shadow_invisible = !get_or(d, "visible_shadow", true, &ctx)?;
    let shadow_terminator_offset = match item(d, "shadow_terminator_offset")? {
        Some(v) if !v.is_none() => Some(
            get(d, "shadow_terminator_offset", &ctx)?
                .extract::<f32>()
                .map_err(|_| verr(format!("{ctx}: shadow_terminator_offset must be a number")))?,
        ),
        _ => None,
    };
    Ok(MeshDesc {
        name,
        positions,
        transforms,
        indices,
        corner_normals,
        material_ids,
        corner_uvs,
        corner_colors,
        corner_generated,
        corner_object,
        pass_index,
        camera_invisible,
        shadow_invisible,
        shadow_terminator_offset,
        holdout: get_or(d, "holdout", false, &ctx)?,
        light_set: get_or(d, "light_set", 0u8, &ctx)?,
        light_membership: get_or(d, "light_membership", None, &ctx)?,
    })
}

/// A material description as the dict `parse_material` reads.
fn material_dict<'py>(py: Python<'py>, m: &MaterialDesc) -> PyResult<Bound<'py, PyDict>> {
    let md = PyDict::new(py);
    md.set_item("name", &m.name)?;
    for (key, c) in [
        ("base_color", m.base_color),
        ("emission", m.emission),
        ("transparent_color", m.transparent_color),
        ("coat_tint", m.coat_tint),
        ("specular_tint", m.specular_tint),
    ] {
        md.set_item(key, c)?;
    }
    for (key, v) in [
        ("roughness", m.roughness),
        ("diffuse_roughness", m.diffuse_roughness),
        ("metallic", m.metallic),
        ("transmission", m.transmission),
        ("ior", m.ior),
        ("specular_ior", m.specular_ior),
        ("specular", m.specular),
        ("transparency", m.transparency),
        ("normal_strength", m.normal_strength),
        ("bump_distance", m.bump_distance),
        ("bump_strength", m.bump_strength),
        ("coat", m.coat),
        ("coat_roughness", m.coat_roughness),
        ("coat_ior", m.coat_ior),
        ("translucency", m.translucency),
    ] {
        md.set_item(key, v)?;
    }
    md.set_item("glass_sqrt_tint", m.glass_sqrt_tint)?;
    md.set_item("metal_constant_fresnel", m.metal_constant_fresnel)?;
    md.set_item("multiscatter", m.multiscatter)?;
    md.set_item("vertex_color", m.vertex_color)?;
    md.set_item("bump_map_correction", m.bump_map_correction)?;
    md.set_item("pass_index", m.pass_index)?;
    md.set_item("holdout", m.holdout)?;
    for (key, value) in [
        ("base_color_texture", m.base_color_texture),
        ("roughness_texture", m.roughness_texture),
        ("metallic_texture", m.metallic_texture),
        ("alpha_texture", m.alpha_texture),
        ("normal_texture", m.normal_texture),
        ("emission_texture", m.emission_texture),
        ("bump_texture", m.bump_texture),
    ] {
        if let Some(t) = value {
            md.set_item(key, t)?;
        }
    }
    for (key, value) in [
        ("metal_color", m.metal_color),
        ("glass_color", m.glass_color),
        ("glass_reflection_tint", m.glass_reflection_tint),
        ("translucent_color", m.translucent_color),
    ] {
        if let Some(c) = value {
            md.set_item(key, c)?;
        }
    }
    for (key, value) in [("metal_roughness", m.metal_roughness), ("glass_roughness", m.glass_roughness)] {
        if let Some(r) = value {
            md.set_item(key, r)?;
        }
    }
    if let Some(v) = &m.volume {
        let vd = PyDict::new(py);
        vd.set_item("scattering", v.scattering)?;
        vd.set_item("absorption", v.absorption)?;
        vd.set_item("emission", v.emission)?;
        vd.set_item("anisotropy", v.anisotropy)?;
        if !v.phase.is_empty() && v.phase != "hg" {
            vd.set_item("phase", &v.phase)?;
            vd.set_item("alpha", v.alpha)?;
            vd.set_item("diameter", v.diameter)?;
        }
        if let Some(f) = &v.density {
            let fd = PyDict::new(py);
            fd.set_item("texture", f.texture)?;
            fd.set_item("world_to_object", f.world_to_object.to_vec())?;
            fd.set_item("generated", f.generated.to_vec())?;
            vd.set_item("density", fd)?;
        }
        md.set_item("volume", vd)?;
    }
    if let Some(v) = &m.subsurface {
        let sd = PyDict::new(py);
        sd.set_item("weight", v.weight)?;
        sd.set_item("radius", v.radius)?;
        sd.set_item("anisotropy", v.anisotropy)?;
        sd.set_item("ior", v.ior)?;
        sd.set_item("method", &v.method)?;
        md.set_item("subsurface", sd)?;
    }
    if let Some(b) = &m.blend {
        md.set_item("blend", material_dict(py, b)?)?;
        if let Some(t) = m.blend_texture {
            md.set_item("blend_texture", t)?;
        }
        if let Some(v) = m.blend_ray {
            use scene::desc::RayFactor;
            let (kind, x) = match v {
                RayFactor::Fresnel(x) => ("FRESNEL", x),
                RayFactor::LayerFresnel(x) => ("LAYER_FRESNEL", x),
                RayFactor::LayerFacing(x) => ("LAYER_FACING", x),
                RayFactor::ShadowRay => ("SHADOW_RAY", 0.0),
                RayFactor::Backfacing => ("BACKFACING", 0.0),
                RayFactor::CameraRay => ("CAMERA_RAY", 0.0),
            };
            md.set_item("blend_ray", (kind, x))?;
        }
        if !m.blend_ray_curve.is_empty() {
            md.set_item("blend_ray_curve", m.blend_ray_curve.clone())?;
        }
    }
    Ok(md)
}

fn parse_material(d: &Bound<'_, PyDict>) -> PyResult<MaterialDesc> {
    let name: String = get_or(d, "name", "material".to_string(), "material")?;
    let ctx = format!("material '{name}'");
    let def = MaterialDesc::default();
    Ok(MaterialDesc {
        base_color: rgb(d, "base_color", def.base_color, &ctx)?,
        emission: rgb(d, "emission", def.emission, &ctx)?,
        roughness: get_or(d, "roughness", def.roughness, &ctx)?,
        diffuse_roughness: get_or(d, "diffuse_roughness", def.diffuse_roughness, &ctx)?,
        metallic: get_or(d, "metallic", def.metallic, &ctx)?,
        transmission: get_or(d, "transmission", def.transmission, &ctx)?,
        ior: get_or(d, "ior", def.ior, &ctx)?,
        base_color_texture: get_or(d, "base_color_texture", None, &ctx)?,
        roughness_texture: get_or(d, "roughness_texture", None, &ctx)?,
        metallic_texture: get_or(d, "metallic_texture", None, &ctx)?,
        alpha_texture: get_or(d, "alpha_texture", None, &ctx)?,
        normal_texture: get_or(d, "normal_texture", None, &ctx)?,
        normal_strength: get_or(d, "normal_strength", def.normal_strength, &ctx)?,
        bump_texture: get_or(d, "bump_texture", None, &ctx)?,
        bump_distance: get_or(d, "bump_distance", def.bump_distance, &ctx)?,
        bump_strength: get_or(d, "bump_strength", def.bump_strength, &ctx)?,
        vertex_color: get_or(d, "vertex_color", false, &ctx)?,
        bump_map_correction: get_or(d, "bump_map_correction", true, &ctx)?,
        emission_texture: get_or(d, "emission_texture", None, &ctx)?,
        metal_roughness: get_or(d, "metal_roughness", None, &ctx)?,
        glass_roughness: get_or(d, "glass_roughness", None, &ctx)?,
        multiscatter: get_or(d, "multiscatter", false, &ctx)?,
        metal_color: get_or(d, "metal_color", None, &ctx)?,
        glass_color: get_or(d, "glass_color", None, &ctx)?,
        glass_reflection_tint: get_or(d, "glass_reflection_tint", None, &ctx)?,
        glass_sqrt_tint: get_or(d, "glass_sqrt_tint", false, &ctx)?,
        specular_ior: get_or(d, "specular_ior", def.specular_ior, &ctx)?,
        specular: get_or(d, "specular", def.specular, &ctx)?,
        coat: get_or(d, "coat", def.coat, &ctx)?,
        coat_roughness: get_or(d, "coat_roughness", def.coat_roughness, &ctx)?,
        coat_ior: get_or(d, "coat_ior", def.coat_ior, &ctx)?,
        coat_tint: rgb(d, "coat_tint", def.coat_tint, &ctx)?,
        specular_tint: rgb(d, "specular_tint", def.specular_tint, &ctx)?,
        metal_constant_fresnel: get_or(d, "metal_constant_fresnel", false, &ctx)?,
        translucency: get_or(d, "translucency", def.translucency, &ctx)?,
        translucent_color: get_or(d, "translucent_color", None, &ctx)?,
        transparency: get_or(d, "transparency", def.transparency, &ctx)?,
        transparent_color: rgb(d, "transparent_color", def.transparent_color, &ctx)?,
        pass_index: get_or(d, "pass_index", 0, &ctx)?,
        holdout: get_or(d, "holdout", false, &ctx)?,
        blend: match item(d, "blend")? {
            Some(b) if !b.is_none() => Some(Box::new(parse_material(
                b.cast::<PyDict>().map_err(|_| verr(format!("{ctx}: blend must be a material dict")))?,
            )?)),
            _ => None,
        },
        blend_texture: get_or(d, "blend_texture", None, &ctx)?,
        blend_ray: match get_or::<Option<(String, f32)>>(d, "blend_ray", None, &ctx)? {
            None => None,
            Some((kind, x)) => Some(match kind.to_ascii_uppercase().as_str() {
                "FRESNEL" => scene::desc::RayFactor::Fresnel(x),
                "LAYER_FRESNEL" => scene::desc::RayFactor::LayerFresnel(x),
                "LAYER_FACING" => scene::desc::RayFactor::LayerFacing(x),
                "SHADOW_RAY" => scene::desc::RayFactor::ShadowRay,
                "BACKFACING" => scene::desc::RayFactor::Backfacing,
                "CAMERA_RAY" => scene::desc::RayFactor::CameraRay,
                other => {
                    return Err(verr(format!(
                        "{ctx}: unknown blend_ray '{other}' (FRESNEL, LAYER_FRESNEL, LAYER_FACING, SHADOW_RAY, CAMERA_RAY or BACKFACING)"
                    )))
                }
            }),
        },
        blend_ray_curve: get_or(d, "blend_ray_curve", Vec::new(), &ctx)?,
        volume: match item(d, "volume")? {
            Some(v) if !v.is_none() => Some(parse_volume(
                v.cast::<PyDict>().map_err(|_| verr(format!("{ctx}: volume must be a dict")))?,
                &ctx,
            )?),
            _ => None,
        },
        subsurface: match item(d, "subsurface")? {
            Some(v) if !v.is_none() => Some(parse_subsurface(
                v.cast::<PyDict>().map_err(|_| verr(format!("{ctx}: subsurface must be a dict")))?,
                &ctx,
            )?),
            _ => None,
        },
        name,
    })
}

/// A material's subsurface layer: {"weight": w, "radius": RGB (world units, Radius × Scale),
/// "anisotropy": g, "ior": Subsurface IOR, "method": "random_walk" | "legacy" | "skin"}.
fn parse_subsurface(d: &Bound<'_, PyDict>, ctx: &str) -> PyResult<scene::desc::SubsurfaceDesc> {
    let ctx = format!("{ctx}: subsurface");
    Ok(scene::desc::SubsurfaceDesc {
        weight: get_or(d, "weight", 1.0, &ctx)?,
        radius: rgb(d, "radius", [1.0, 0.2, 0.1], &ctx)?,
        anisotropy: get_or(d, "anisotropy", 0.0, &ctx)?,
        ior: get_or(d, "ior", 1.4, &ctx)?,
        method: get_or(d, "method", "random_walk".to_string(), &ctx)?,
    })
}

/// A material's medium: {"scattering": RGB, "absorption": RGB, "emission": RGB (per unit
/// distance), "anisotropy": g} (each optional, default 0).
fn parse_volume(d: &Bound<'_, PyDict>, ctx: &str) -> PyResult<scene::desc::VolumeDesc> {
    let ctx = format!("{ctx}: volume");
    let zero = [0.0f32; 3];
    Ok(scene::desc::VolumeDesc {
        scattering: rgb(d, "scattering", zero, &ctx)?,
        absorption: rgb(d, "absorption", zero, &ctx)?,
        emission: rgb(d, "emission", zero, &ctx)?,
        anisotropy: get_or(d, "anisotropy", 0.0, &ctx)?,
        phase: get_or(d, "phase", "hg".to_string(), &ctx)?,
        alpha: get_or(d, "alpha", 0.5, &ctx)?,
        diameter: get_or(d, "diameter", 20.0, &ctx)?,
        density: match item(d, "density")? {
            Some(v) if !v.is_none() => {
                let f = v.cast::<PyDict>().map_err(|_| verr(format!("{ctx}: density must be a dict")))?;
                let dctx = format!("{ctx}: density");
                let w2o: Vec<f32> = get(f, "world_to_object", &dctx)?.extract()?;
                let gen: Vec<f32> = get_or(f, "generated", vec![1.0, 1.0, 1.0, 0.0, 0.0, 0.0], &dctx)?;
                Some(scene::desc::DensityDesc {
                    texture: get(f, "texture", &dctx)?.extract()?,
                    world_to_object: w2o
                        .try_into()
                        .map_err(|_| verr(format!("{dctx}: world_to_object takes 12 numbers (3×4, row-major)")))?,
                    generated: gen
                        .try_into()
                        .map_err(|_| verr(format!("{dctx}: generated takes 6 numbers (scale xyz, offset xyz)")))?,
                })
            }
            _ => None,
        },
    })
}

/// {"name", "width", "height", "pixels": float32 RGBA or RGB, row 0 at the bottom (as
/// Blender's Image.pixels), "interpolation": "Linear"|"Closest", "extension": "REPEAT"|
/// "EXTEND"|"CLIP", "srgb": the values are sRGB-encoded (decoded after interpolation)}
fn parse_texture(d: &Bound<'_, PyDict>) -> PyResult<TextureDesc> {
    let name: String = get_or(d, "name", "texture".to_string(), "texture")?;
    let ctx = format!("texture '{name}'");
    let width: usize = get_or(d, "width", 0, &ctx)?;
    let height: usize = get_or(d, "height", 0, &ctx)?;
    let channels: usize = get_or(d, "channels", 4, &ctx)?;
    if !(channels == 3 || channels == 4) {
        return Err(verr(format!("{ctx}: channels must be 3 or 4")));
    }
    let px = floats(&get(d, "pixels", &ctx)?, channels, &format!("{ctx}: pixels"))?;
    let pixels = px.chunks_exact(channels).map(|c| [c[0], c[1], c[2]]).collect();
    let interpolation: String = get_or(d, "interpolation", "Linear".to_string(), &ctx)?;
    let extension: String = get_or(d, "extension", "REPEAT".to_string(), &ctx)?;
    let extension = match extension.to_ascii_uppercase().as_str() {
        "REPEAT" => TextureExtension::Repeat,
        "EXTEND" => TextureExtension::Extend,
        "CLIP" => TextureExtension::Clip,
        "MIRROR" => TextureExtension::Mirror,
        other => return Err(verr(format!("{ctx}: unknown extension '{other}' (REPEAT, EXTEND, CLIP or MIRROR)"))),
    };
    let srgb: bool = get_or(d, "srgb", false, &ctx)?;
    let transform: Option<[f32; 6]> = get_or(d, "transform", None, &ctx)?;
    let procedural = match item(d, "procedural")? {
        Some(p) if !p.is_none() => Some(parse_procedural(p.cast::<PyDict>()?, &ctx)?),
        _ => None,
    };
    Ok(TextureDesc {
        name,
        width,
        height,
        pixels,
        closest: interpolation.eq_ignore_ascii_case("closest"),
        extension,
        srgb,
        transform,
        procedural,
    })
}

/// {"pattern": "NOISE"|"VORONOI"|"WAVE"|"BRICK"|"CHECKER"|"GRADIENT", "space": "GENERATED"|"OBJECT"|
/// "UV", "transform": 12 floats (row-major 3×4), "domain": (lo, hi); NOISE: "noise_type",
/// "detail", "roughness", "lacunarity", "offset", "gain", "distortion", "normalize", "color";
/// VORONOI: "f2", "metric", "exponent", "randomness", "detail", "roughness", "lacunarity",
/// "normalize", "color"; WAVE: "rings", "direction", "profile", "distortion", "detail",
/// "detail_scale", "detail_roughness", "phase"; BRICK: "mortar_size", "mortar_smooth", "bias",
/// "brick_width", "row_height", "offset", "offset_frequency", "squash", "squash_frequency",
/// "color1", "color2", "mortar", "color"; GRADIENT: "gradient_type" (Blender's
/// identifiers)}
fn parse_procedural(d: &Bound<'_, PyDict>, ctx: &str) -> PyResult<scene::procedural::Procedural> {
    use scene::procedural::{
        BrickParams, GradientKind, Metric, NoiseKind, NoiseParams, Pattern, Procedural, Space, VoronoiParams,
        WaveParams, WaveProfile,
    };
    let ctx = format!("{ctx}: procedural");
    let kind: String = get_or(d, "pattern", String::new(), &ctx)?;
    let pattern = match kind.to_ascii_uppercase().as_str() {
        "NOISE" => {
            let kind: String = get_or(d, "noise_type", "FBM".to_string(), &ctx)?;
            Pattern::Noise {
                noise: NoiseParams {
                    kind: NoiseKind::parse(&kind).ok_or_else(|| verr(format!("{ctx}: unknown noise_type '{kind}'")))?,
                    detail: get_or(d, "detail", 2.0, &ctx)?,
                    roughness: get_or(d, "roughness", 0.5, &ctx)?,
                    lacunarity: get_or(d, "lacunarity", 2.0, &ctx)?,
                    offset: get_or(d, "offset", 0.0, &ctx)?,
                    gain: get_or(d, "gain", 1.0, &ctx)?,
                    distortion: get_or(d, "distortion", 0.0, &ctx)?,
                    normalize: get_or(d, "normalize", true, &ctx)?,
                },
                color: get_or(d, "color", false, &ctx)?,
            }
        }
        "WAVE" => {
            let direction: String = get_or(d, "direction", "X".to_string(), &ctx)?;
            let profile: String = get_or(d, "profile", "SIN".to_string(), &ctx)?;
            Pattern::Wave(WaveParams {
                rings: get_or(d, "rings", false, &ctx)?,
                direction: match direction.to_ascii_uppercase().as_str() {
                    "X" => 0,
                    "Y" => 1,
                    "Z" => 2,
                    "DIAGONAL" | "SPHERICAL" => 3,
                    other => return Err(verr(format!("{ctx}: unknown wave direction '{other}'"))),
                },
                profile: match profile.to_ascii_uppercase().as_str() {
                    "SIN" => WaveProfile::Sine,
                    "SAW" => WaveProfile::Saw,
                    "TRI" => WaveProfile::Triangle,
                    other => return Err(verr(format!("{ctx}: unknown wave profile '{other}'"))),
                },
                distortion: get_or(d, "distortion", 0.0, &ctx)?,
                detail: get_or(d, "detail", 2.0, &ctx)?,
                detail_scale: get_or(d, "detail_scale", 1.0, &ctx)?,
                detail_roughness: get_or(d, "detail_roughness", 0.5, &ctx)?,
                phase: get_or(d, "phase", 0.0, &ctx)?,
            })
        }
        "VORONOI" => {
            let metric: String = get_or(d, "metric", "EUCLIDEAN".to_string(), &ctx)?;
            Pattern::Voronoi {
                voronoi: VoronoiParams {
                    f2: get_or(d, "f2", false, &ctx)?,
                    metric: Metric::parse(&metric).ok_or_else(|| verr(format!("{ctx}: unknown metric '{metric}'")))?,
                    exponent: get_or(d, "exponent", 0.5, &ctx)?,
                    randomness: get_or(d, "randomness", 1.0, &ctx)?,
                    detail: get_or(d, "detail", 0.0, &ctx)?,
                    roughness: get_or(d, "roughness", 0.5, &ctx)?,
                    lacunarity: get_or(d, "lacunarity", 2.0, &ctx)?,
                    normalize: get_or(d, "normalize", false, &ctx)?,
                },
                color: get_or(d, "color", false, &ctx)?,
            }
        }
        "BRICK" => {
            let colour = |key: &'static str, def| -> PyResult<glam::Vec3> {
                Ok(glam::Vec3::from_array(get_or(d, key, def, &ctx)?))
            };
            Pattern::Brick {
                brick: BrickParams {
                    mortar_size: get_or(d, "mortar_size", 0.02, &ctx)?,
                    mortar_smooth: get_or(d, "mortar_smooth", 0.1, &ctx)?,
                    bias: get_or(d, "bias", 0.0, &ctx)?,
                    brick_width: get_or(d, "brick_width", 0.5, &ctx)?,
                    row_height: get_or(d, "row_height", 0.25, &ctx)?,
                    offset: get_or(d, "offset", 0.5, &ctx)?,
                    offset_frequency: get_or(d, "offset_frequency", 2, &ctx)?,
                    squash: get_or(d, "squash", 1.0, &ctx)?,
                    squash_frequency: get_or(d, "squash_frequency", 2, &ctx)?,
                    color1: colour("color1", [0.8; 3])?,
                    color2: colour("color2", [0.2; 3])?,
                    mortar: colour("mortar", [0.0; 3])?,
                },
                color: get_or(d, "color", false, &ctx)?,
            }
        }
        "CHECKER" => Pattern::Checker,
        "GRADIENT" => {
            let g: String = get_or(d, "gradient_type", "LINEAR".to_string(), &ctx)?;
            Pattern::Gradient(
                GradientKind::parse(&g).ok_or_else(|| verr(format!("{ctx}: unknown gradient_type '{g}'")))?,
            )
        }
        other => {
            return Err(verr(format!(
                "{ctx}: unknown pattern '{other}' (NOISE, VORONOI, WAVE, BRICK, CHECKER or GRADIENT)"
            )))
        }
    };
    let space: String = get_or(d, "space", "GENERATED".to_string(), &ctx)?;
    let space = match space.to_ascii_uppercase().as_str() {
        "UV" => Space::Uv,
        "GENERATED" => Space::Generated,
        "OBJECT" => Space::Object,
        other => return Err(verr(format!("{ctx}: unknown space '{other}' (GENERATED, OBJECT or UV)"))),
    };
    let transform: [f32; 12] =
        get_or(d, "transform", [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0], &ctx)?;
    let domain: (f32, f32) = get_or(d, "domain", (0.0, 1.0), &ctx)?;
    Ok(Procedural { pattern, space, transform, domain })
}

fn parse_light(d: &Bound<'_, PyDict>) -> PyResult<LightDesc> {
    let name: String = get_or(d, "name", "light".to_string(), "light")?;
    let ctx = format!("light '{name}'");
    let kind: String = get_or(d, "type", String::new(), &ctx)?;
    let visible_camera: bool = get_or(d, "visible_camera", false, &ctx)?;
    let cast_shadow: bool = get_or(d, "cast_shadow", true, &ctx)?;
    let power = rgb(d, "power", [0.0; 3], &ctx)?;
    Ok(match kind.to_ascii_uppercase().as_str() {
        "POINT" => LightDesc::Point {
            position: rgb(d, "position", [0.0; 3], &ctx)?,
            radius: get_or(d, "radius", 0.0, &ctx)?,
            soft_falloff: get_or(d, "soft_falloff", true, &ctx)?,
            power,
            visible_camera,
            cast_shadow,
            name,
        },
        "SPOT" => LightDesc::Spot {
            position: rgb(d, "position", [0.0; 3], &ctx)?,
            direction: rgb(d, "direction", [0.0, 0.0, -1.0], &ctx)?,
            radius: get_or(d, "radius", 0.0, &ctx)?,
            spot_size: get_or(d, "spot_size", std::f32::consts::FRAC_PI_4, &ctx)?,
            spot_blend: get_or(d, "spot_blend", 0.15, &ctx)?,
            soft_falloff: get_or(d, "soft_falloff", true, &ctx)?,
            matrix: match item(d, "matrix")? {
                Some(m) if !m.is_none() => Some(matrix(d, "matrix", &ctx)?),
                _ => None,
            },
            power,
            visible_camera,
            cast_shadow,
            name,
        },
        "AREA" => {
            let shape: String = get_or(d, "shape", "SQUARE".to_string(), &ctx)?;
            let shape = match shape.to_ascii_uppercase().as_str() {
                "SQUARE" => AreaShape::Square,
                "RECTANGLE" => AreaShape::Rectangle,
                "DISK" => AreaShape::Disk,
                "ELLIPSE" => AreaShape::Ellipse,
                s => return Err(verr(format!("{ctx}: unknown area shape '{s}'"))),
            };
            let size_x: f32 = get_or(d, "size", 1.0, &ctx)?;
            LightDesc::Area {
                to_world: matrix(d, "matrix", &ctx)?,
                shape,
                size_x,
                size_y: get_or(d, "size_y", size_x, &ctx)?,
                power,
                normalize: get_or(d, "normalize", true, &ctx)?,
                spread: get_or(d, "spread", std::f32::consts::PI, &ctx)?,
                visible_camera,
                cast_shadow,
                name,
            }
        }
        "SUN" => LightDesc::Sun {
            direction: rgb(d, "direction", [0.0, 0.0, 1.0], &ctx)?,
            irradiance: rgb(d, "irradiance", [1.0; 3], &ctx)?,
            angle: get_or(d, "angle", 0.0, &ctx)?,
            visible_camera,
            cast_shadow,
            name,
        },
        other => return Err(verr(format!("{ctx}: unknown light type '{other}' (POINT, SPOT, AREA or SUN)"))),
    })
}

/// Optional 3×3 matrix `key` of `d` (rows; None when absent or None).
fn rotation3(d: &Bound<'_, PyDict>, key: &'static str, ctx: &str) -> PyResult<Option<[[f32; 3]; 3]>> {
    match item(d, key)? {
        Some(r) if !r.is_none() => {
            let v = floats(&r, 3, &format!("{ctx}: {key}"))?;
            if v.len() != 9 {
                return Err(verr(format!("{ctx}: {key} must be 3×3")));
            }
            Ok(Some([0, 1, 2].map(|i| [v[3 * i], v[3 * i + 1], v[3 * i + 2]])))
        }
        _ => Ok(None),
    }
}

fn parse_camera(d: &Bound<'_, PyDict>) -> PyResult<CameraDesc> {
    let ctx = "camera";
    let def = CameraDesc::default();
    let projection: String = get_or(d, "type", "PERSP".to_string(), ctx)?;
    let fit: String = get_or(d, "sensor_fit", "AUTO".to_string(), ctx)?;
    Ok(CameraDesc {
        to_world: matrix(d, "matrix", ctx)?,
        projection: match projection.to_ascii_uppercase().as_str() {
            "PERSP" => Projection::Perspective,
            "ORTHO" => Projection::Orthographic,
            "EQUIRECTANGULAR" => Projection::Equirectangular,
            "FISHEYE_EQUIDISTANT" => Projection::FisheyeEquidistant,
            "FISHEYE_EQUISOLID" => Projection::FisheyeEquisolid,
            p => {
                return Err(verr(format!(
                    "camera: unsupported type '{p}' (PERSP, ORTHO, EQUIRECTANGULAR, FISHEYE_EQUIDISTANT or FISHEYE_EQUISOLID)"
                )))
            }
        },
        sensor_fit: match fit.to_ascii_uppercase().as_str() {
            "AUTO" => SensorFit::Auto,
            "HORIZONTAL" => SensorFit::Horizontal,
            "VERTICAL" => SensorFit::Vertical,
            f => return Err(verr(format!("camera: unknown sensor fit '{f}'"))),
        },
        lens: get_or(d, "lens", def.lens, ctx)?,
        sensor_width: get_or(d, "sensor_width", def.sensor_width, ctx)?,
        sensor_height: get_or(d, "sensor_height", def.sensor_height, ctx)?,
        ortho_scale: get_or(d, "ortho_scale", def.ortho_scale, ctx)?,
        shift_x: get_or(d, "shift_x", 0.0, ctx)?,
        shift_y: get_or(d, "shift_y", 0.0, ctx)?,
        clip_start: get_or(d, "clip_start", def.clip_start, ctx)?,
        clip_end: get_or(d, "clip_end", def.clip_end, ctx)?,
        resolution_x: get_or(d, "resolution_x", def.resolution_x, ctx)?,
        resolution_y: get_or(d, "resolution_y", def.resolution_y, ctx)?,
        resolution_percentage: get_or(d, "resolution_percentage", 100, ctx)?,
        window: get_or(d, "window", None, ctx)?,
        pixel_aspect_x: get_or(d, "pixel_aspect_x", 1.0, ctx)?,
        pixel_aspect_y: get_or(d, "pixel_aspect_y", 1.0, ctx)?,
        fstop: get_or(d, "fstop", 0.0, ctx)?,
        focus_distance: get_or(d, "focus_distance", def.focus_distance, ctx)?,
        aperture_blades: get_or(d, "aperture_blades", def.aperture_blades, ctx)?,
        aperture_rotation: get_or(d, "aperture_rotation", def.aperture_rotation, ctx)?,
        aperture_ratio: get_or(d, "aperture_ratio", def.aperture_ratio, ctx)?,
        pixel_filter: get_or(d, "pixel_filter", def.pixel_filter.clone(), ctx)?,
        filter_width: get_or(d, "filter_width", def.filter_width, ctx)?,
        film_transparent: get_or(d, "film_transparent", false, ctx)?,
        backdrop: get_or(d, "backdrop", None, ctx)?,
        backdrop_texture: get_or(d, "backdrop_texture", None, ctx)?,
        backdrop_rotation: rotation3(d, "backdrop_rotation", ctx)?,
        panorama: [
            get_or(d, "latitude_min", def.panorama[0], ctx)?,
            get_or(d, "latitude_max", def.panorama[1], ctx)?,
            get_or(d, "longitude_min", def.panorama[2], ctx)?,
            get_or(d, "longitude_max", def.panorama[3], ctx)?,
        ],
        fisheye_fov: get_or(d, "fisheye_fov", def.fisheye_fov, ctx)?,
        fisheye_lens: get_or(d, "fisheye_lens", def.fisheye_lens, ctx)?,
    })
}

/// Edit distance (for the "did you mean" of an unknown key).
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            cur[j + 1] = (prev[j] + usize::from(ca != *cb)).min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

/// Warnings for the keys of `d` no parser asked for (KEYS_ASKED).
fn unknown_keys(d: &Bound<'_, PyDict>, ctx: &str, out: &mut Vec<String>) {
    let known = KEYS_ASKED.with(|m| m.borrow().get(&(d.as_ptr() as usize)).cloned().unwrap_or_default());
    for k in d.keys() {
        let Ok(k) = k.extract::<String>() else { continue };
        if known.contains(&k.as_str()) {
            continue;
        }
        let near = known.iter().min_by_key(|c| edit_distance(&k, c)).filter(|c| edit_distance(&k, c) <= 2);
        out.push(match near {
            Some(c) => format!("{ctx}: unknown key '{k}' ignored (did you mean '{c}'?)"),
            None => format!("{ctx}: unknown key '{k}' ignored"),
        });
    }
}

/// Every key of a scene dict that its parse (`parse_scene`, just before) did not read, as
/// warnings naming where it is.
fn scene_key_warnings(d: &Bound<'_, PyDict>) -> Vec<String> {
    let mut out = Vec::new();
    unknown_keys(d, "scene", &mut out);
    for (list, what) in [("meshes", "mesh"), ("materials", "material"), ("textures", "texture"), ("lights", "light")] {
        if let Ok(Some(items)) = d.get_item(list) {
            for item in items.try_iter().into_iter().flatten().flatten() {
                if let Ok(item) = item.cast_into::<PyDict>() {
                    let name: String = item
                        .get_item("name")
                        .ok()
                        .flatten()
                        .and_then(|n| n.extract().ok())
                        .unwrap_or_else(|| "?".to_string());
                    unknown_keys(&item, &format!("{what} '{name}'"), &mut out);
                }
            }
        }
    }
    if let Ok(Some(cam)) = d.get_item("camera") {
        if let Ok(cam) = cam.cast_into::<PyDict>() {
            unknown_keys(&cam, "camera", &mut out);
        }
    }
    KEYS_ASKED.with(|m| m.borrow_mut().clear());
    out
}

fn parse_scene(d: &Bound<'_, PyDict>) -> PyResult<SceneDesc> {
    KEYS_ASKED.with(|m| m.borrow_mut().clear()); // (addresses of dicts parsed before may be reused)
    let list = |key: &'static str| -> PyResult<Vec<Bound<'_, PyDict>>> {
        match item(d, key)? {
            Some(l) if !l.is_none() => l
                .cast::<PyList>()
                .map_err(|_| verr(format!("scene: '{key}' must be a list")))?
                .iter()
                .map(|x| x.cast_into::<PyDict>().map_err(|_| verr(format!("scene: '{key}' entries must be dicts"))))
                .collect(),
            _ => Ok(vec![]),
        }
    };
    Ok(SceneDesc {
        meshes: list("meshes")?.iter().map(parse_mesh).collect::<PyResult<_>>()?,
        materials: list("materials")?.iter().map(parse_material).collect::<PyResult<_>>()?,
        textures: list("textures")?.iter().map(parse_texture).collect::<PyResult<_>>()?,
        lights: list("lights")?.iter().map(parse_light).collect::<PyResult<_>>()?,
        camera: parse_camera(
            &get(d, "camera", "scene")?.cast_into::<PyDict>().map_err(|_| verr("scene: camera must be a dict"))?,
        )?,
        world: get_or(d, "world", [0.0; 3], "scene")?,
        world_texture: get_or(d, "world_texture", None, "scene")?,
        world_volume: match item(d, "world_volume")? {
            Some(v) if !v.is_none() => Some(parse_volume(
                v.cast::<PyDict>().map_err(|_| verr("scene: world_volume must be a dict"))?,
                "world",
            )?),
            _ => None,
        },
        general_paths: get_or(d, "general_paths", false, "scene")?,
        oren_nayar_rho_cubed: get_or(d, "oren_nayar_rho_cubed", false, "scene")?,
        normal_map_unnormalized_base: get_or(d, "normal_map_unnormalized_base", false, "scene")?,
        light_membership: list("lights")?
            .iter()
            .map(|l| get_or(l, "light_membership", u64::MAX, "light"))
            .collect::<PyResult<_>>()?,
        world_rotation: rotation3(d, "world_rotation", "scene")?,
    })
}

/// `Scene.trace_rays`' answer: (t as float32, triangle as int64).
type Hits<'py> = (Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<i64>>);

/// A scene ready to render (BVH built). Construct from the dict layout of gdmlt.scene.
#[pyclass(module = "gdmlt._core")]
struct Scene {
    inner: Arc<scene::Scene>,
}

impl Scene {
    /// The scene to change in place: not while a render still holds it.
    fn exclusive(&mut self) -> PyResult<&mut scene::Scene> {
        Arc::get_mut(&mut self.inner).ok_or_else(|| PyRuntimeError::new_err("the scene is in use by a render"))
    }
}

#[pymethods]
impl Scene {
    #[new]
    fn new(py: Python<'_>, desc: &Bound<'_, PyDict>) -> PyResult<Self> {
        let d = parse_scene(desc)?;
        let unknown = scene_key_warnings(desc);
        let built = py.detach(|| std::panic::catch_unwind(move || scene::Scene::build_from(d)));
        match built {
            Ok(Ok(mut s)) => {
                s.report.warnings.extend(unknown);
                Ok(Scene { inner: Arc::new(s) })
            }
            Ok(Err(e)) => Err(verr(e.to_string())),
            Err(_) => Err(PyRuntimeError::new_err("internal error while building the scene (a bug: please report it)")),
        }
    }
    /// Closest hits of a batch of rays (origins and directions float32 N×3) with the core's
    /// BVH: (t, triangle) as float32 and int64 arrays, t = inf and triangle = −1 for a miss.
    /// For benchmarks (gdmlt_bench raybench) and tests; `threads` 0 = all cores. `packets`: closest
    /// hits of each run of eight consecutive rays traced as one packet (as the path tracer's
    /// camera rays; for coherent rays).
    #[pyo3(signature = (origins, directions, threads=0, occlusion=false, packets=false))]
    #[allow(clippy::too_many_arguments)]
    fn trace_rays<'py>(
        &self,
        py: Python<'py>,
        origins: &Bound<'py, PyAny>,
        directions: &Bound<'py, PyAny>,
        threads: usize,
        occlusion: bool,
        packets: bool,
    ) -> PyResult<Hits<'py>> {
        let o = floats(origins, 3, "origins")?;
        let d = floats(directions, 3, "directions")?;
        if o.len() != d.len() {
            return Err(verr("origins and directions must have the same number of rays"));
        }
        let n = o.len() / 3;
        let scene = &self.inner;
        let miss = (f32::INFINITY, -1i64);
        let run = || -> Vec<(f32, i64)> {
            use rayon::prelude::*;
            if packets && !occlusion {
                return (0..n.div_ceil(8))
                    .into_par_iter()
                    .with_min_len(128)
                    .flat_map_iter(|c| {
                        let mut p = crate::accel::RayPacket { count: (n - 8 * c).min(8), ..Default::default() };
                        for k in 0..p.count {
                            let i = 8 * c + k;
                            p.o[k] = glam::Vec3::new(o[3 * i], o[3 * i + 1], o[3 * i + 2]);
                            p.d[k] = glam::Vec3::new(d[3 * i], d[3 * i + 1], d[3 * i + 2]);
                            (p.tmin[k], p.tmax[k]) = (0.0, f32::INFINITY);
                        }
                        let hits = scene.intersect_packet(&p);
                        (0..p.count).map(move |k| hits[k].map_or(miss, |h| (h.t, h.prim as i64)))
                    })
                    .collect();
            }
            (0..n)
                .into_par_iter()
                .with_min_len(1024)
                .map(|i| {
                    let oi = glam::Vec3::new(o[3 * i], o[3 * i + 1], o[3 * i + 2]);
                    let di = glam::Vec3::new(d[3 * i], d[3 * i + 1], d[3 * i + 2]);
                    if occlusion {
                        if scene.occluded(oi, di, 0.0, f32::INFINITY) {
                            (0.0, 0)
                        } else {
                            (f32::INFINITY, -1)
                        }
                    } else {
                        scene
                            .intersect(oi, di, 0.0, f32::INFINITY)
                            .map_or((f32::INFINITY, -1), |h| (h.t, h.prim as i64))
                    }
                })
                .collect()
        };
        let res = py.detach(|| -> PyResult<Vec<(f32, i64)>> {
            if threads == 0 {
                Ok(run())
            } else {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
                Ok(pool.install(run))
            }
        })?;
        let (t, p): (Vec<f32>, Vec<i64>) = res.into_iter().unzip();
        Ok((PyArray1::from_vec(py, t), PyArray1::from_vec(py, p)))
    }

    /// Looks through another camera (a camera dict of the scene layout), nothing else
    /// rebuilt: for the viewport, whose view moves while the scene stays.
    fn set_camera(&mut self, camera: &Bound<'_, PyDict>) -> PyResult<()> {
        let camera = scene::Camera::new(&parse_camera(camera)?).map_err(|e| verr(e.to_string()))?;
        self.exclusive()?.set_camera(camera);
        Ok(())
    }
    /// Places the instanced meshes by the transforms of `desc` (a scene dict of the same
    /// meshes, instancers moved), keeping the triangles and the meshes' BVHs, and takes its
    /// materials, lights and world: for the viewport. ValueError where it needs a full build.
    fn update_transforms(&mut self, py: Python<'_>, desc: &Bound<'_, PyDict>) -> PyResult<()> {
        let d = parse_scene(desc)?;
        let scene = self.exclusive()?;
        py.detach(|| scene.update_transforms(&d)).map_err(|e| verr(e.to_string()))
    }
    /// Takes the materials, textures, lights and world of `desc` (a scene dict; its meshes
    /// are not read) and keeps the triangles, BVH and camera: for edits that move no
    /// geometry. The meshes the scene was built from must still be the scene's, with the
    /// same material ids (the caller's check); an id past the new materials is an error.
    fn update_shading(&mut self, py: Python<'_>, desc: &Bound<'_, PyDict>) -> PyResult<()> {
        let d = parse_scene(desc)?;
        let scene = self.exclusive()?;
        py.detach(|| scene.update_shading(&d)).map_err(|e| verr(e.to_string()))
    }

    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.inner.report.warnings.clone()
    }
    /// Triangles stored (an instanced mesh's once).
    #[getter]
    fn triangles(&self) -> usize {
        self.inner.num_triangles()
    }
    /// Instances placing the meshes stored once.
    #[getter]
    fn instances(&self) -> usize {
        self.inner.report.instances
    }
    /// Some material has a medium (a Volume output): light subpaths do not enter media yet.
    #[getter]
    fn has_media(&self) -> bool {
        self.inner.has_media()
    }
    #[getter]
    fn size(&self) -> (u32, u32) {
        (self.inner.camera.width, self.inner.camera.height)
    }
    /// Raster position (x, y from the top, in pixels) of a world point, or None behind the camera.
    fn project(&self, p: [f32; 3]) -> Option<(f32, f32)> {
        self.inner.camera.project(glam::Vec3::from_array(p)).map(|v| (v.x, v.y))
    }
}

/// The image as a (H, W, C) float32 array that takes over its buffer (no copy: a render's
/// layers are not held twice).
fn image_to_numpy(py: Python<'_>, img: Image) -> PyResult<Bound<'_, PyAny>> {
    let shape = [img.height, img.width, img.channels];
    Ok(PyArray1::from_vec(py, img.data).reshape(shape)?.into_any())
}

fn numpy_to_image(obj: &Bound<'_, PyAny>) -> PyResult<Image> {
    let arr: PyReadonlyArrayDyn<f32> =
        obj.extract().map_err(|_| verr("expected a float32 numpy array of shape (H, W, C)"))?;
    let s = arr.shape();
    if s.len() != 3 || s[2] == 0 {
        return Err(verr(format!("expected an image of shape (H, W, C), got {s:?}")));
    }
    Ok(Image { height: s[0], width: s[1], channels: s[2], data: arr.as_array().iter().copied().collect() })
}

/// Renders a scene. `progress(fraction, elapsed_seconds)` is called about every 50 ms from
/// the calling thread; if it returns True the render stops and keeps what it has. Every
/// setting left out (or None) takes `RenderSettings::default()`'s value (`DEFAULT_SETTINGS`).
#[pyfunction]
#[pyo3(signature = (scene, method=None, spp=None, time_limit=None, max_bounces=None, nee=None, seed=None, threads=None, reconstruction=None, alpha_rec=None, large_step_probability=None, alpha_target=None, chains=None, progress=None, preview=None, diffuse_bounces=None, glossy_bounces=None, transmission_bounces=None, volume_bounces=None, transparent_bounces=None, clamp_direct=None, clamp_indirect=None, data_passes=None, adaptive_threshold=None, adaptive_min_samples=None, guiding=None, bidirectional=None, predict_pt=None))]
#[allow(clippy::too_many_arguments)]
fn render<'py>(
    py: Python<'py>,
    scene: &Scene,
    method: Option<&str>,
    spp: Option<u32>,
    time_limit: Option<f64>,
    max_bounces: Option<u32>,
    nee: Option<bool>,
    seed: Option<u64>,
    threads: Option<usize>,
    reconstruction: Option<&str>,
    alpha_rec: Option<f64>,
    large_step_probability: Option<f32>,
    alpha_target: Option<f32>,
    chains: Option<u32>,
    progress: Option<Bound<'py, PyAny>>,
    preview: Option<Bound<'py, PyAny>>,
    diffuse_bounces: Option<u32>,
    glossy_bounces: Option<u32>,
    transmission_bounces: Option<u32>,
    volume_bounces: Option<u32>,
    transparent_bounces: Option<u32>,
    clamp_direct: Option<f32>,
    clamp_indirect: Option<f32>,
    data_passes: Option<bool>,
    adaptive_threshold: Option<f32>,
    adaptive_min_samples: Option<u32>,
    guiding: Option<bool>,
    bidirectional: Option<bool>,
    predict_pt: Option<bool>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = RenderSettings::default();
    let method = match method {
        Some(m) => Method::parse(m).map_err(|e| verr(e.to_string()))?,
        None => d.method,
    };
    let reconstruction = match reconstruction {
        Some(r) => crate::reconstruct::Norm::parse(r)
            .ok_or_else(|| verr(format!("unknown reconstruction '{r}' (expected l1 or l2)")))?,
        None => d.reconstruction,
    };
    let settings = RenderSettings {
        method,
        spp: spp.unwrap_or(d.spp),
        time_limit: time_limit.unwrap_or(d.time_limit),
        path: PathSettings {
            max_bounces: max_bounces.unwrap_or(d.path.max_bounces),
            nee: nee.unwrap_or(d.path.nee),
            diffuse_bounces: diffuse_bounces.unwrap_or(d.path.diffuse_bounces),
            glossy_bounces: glossy_bounces.unwrap_or(d.path.glossy_bounces),
            transmission_bounces: transmission_bounces.unwrap_or(d.path.transmission_bounces),
            volume_bounces: volume_bounces.unwrap_or(d.path.volume_bounces),
            transparent_bounces: transparent_bounces.unwrap_or(d.path.transparent_bounces),
            clamp_direct: clamp_direct.unwrap_or(d.path.clamp_direct),
            clamp_indirect: clamp_indirect.unwrap_or(d.path.clamp_indirect),
            strict_glass_nee: d.path.strict_glass_nee,
        },
        seed: seed.unwrap_or(d.seed),
        threads: threads.unwrap_or(d.threads),
        reconstruction,
        alpha_rec: alpha_rec.unwrap_or(d.alpha_rec),
        large_step_probability: large_step_probability.unwrap_or(d.large_step_probability),
        alpha_target: alpha_target.unwrap_or(d.alpha_target),
        chains: chains.unwrap_or(d.chains),
        data_passes: data_passes.unwrap_or(d.data_passes),
        adaptive_threshold: adaptive_threshold.unwrap_or(d.adaptive_threshold),
        adaptive_min_samples: adaptive_min_samples.unwrap_or(d.adaptive_min_samples),
        guiding: guiding.unwrap_or(d.guiding),
        bidirectional: bidirectional.unwrap_or(d.bidirectional),
        predict_pt: predict_pt.unwrap_or(d.predict_pt),
        ..d
    };
    settings.validate().map_err(|e| verr(e.to_string()))?;
    let control = RenderControl::new(settings.time_limit);
    let sc = self::Scene { inner: scene.inner.clone() };
    let progress = progress.map(|p| p.unbind());
    let preview = preview.map(|p| p.unbind());
    // First intermediate image after 1 s, then at intervals that grow with the render time
    // (a quarter of the time so far, 1 to 10 s), so that previews never slow a long render.
    let mut next_preview = 1.0f64;
    let mut callback_error: Option<PyErr> = None;
    let result = py.detach(|| {
        std::thread::scope(|s| {
            let worker = s.spawn(|| {
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    integrator::render(&sc.inner, &settings, &control)
                }))
            });
            // the worker is polled every millisecond (a viewport pass may take a few), the
            // callbacks every 50 ms
            let mut last_call = std::time::Instant::now();
            while !worker.is_finished() {
                std::thread::sleep(Duration::from_millis(1));
                if last_call.elapsed() < Duration::from_millis(50) {
                    continue;
                }
                last_call = std::time::Instant::now();
                if let Some(cb) = &preview {
                    let t = control.elapsed();
                    if t >= next_preview {
                        control.request_preview();
                        next_preview = t + (0.25 * t).clamp(1.0, 10.0);
                    }
                    if let Some(img) = control.take_preview() {
                        Python::attach(|py| {
                            let r = image_to_numpy(py, img).and_then(|a| cb.call1(py, (a,)));
                            if let Err(e) = r {
                                control.cancel();
                                callback_error.get_or_insert(e);
                            }
                        });
                    }
                }
                if let Some(cb) = &progress {
                    Python::attach(|py| match cb.call1(py, (control.progress(), control.elapsed())) {
                        Ok(r) => {
                            if r.is_truthy(py).unwrap_or(false) {
                                control.cancel();
                            }
                        }
                        Err(e) => {
                            control.cancel();
                            callback_error.get_or_insert(e);
                        }
                    });
                } else if Python::attach(|py| py.check_signals()).is_err() {
                    control.cancel(); // Ctrl-C in a plain Python session
                }
            }
            worker.join()
        })
    });
    if let Some(e) = callback_error {
        return Err(e);
    }
    let out = match result {
        Ok(Ok(Ok(out))) => out,
        Ok(Ok(Err(e))) => return Err(verr(e.to_string())),
        _ => return Err(PyRuntimeError::new_err("internal error during the render (a bug: please report it)")),
    };
    let dict = PyDict::new(py);
    let layers = PyDict::new(py);
    for (name, img) in out.layers {
        layers.set_item(name, image_to_numpy(py, img)?)?;
    }
    dict.set_item("layers", layers)?;
    let st = &out.stats;
    let stats = PyDict::new(py);
    stats.set_item("method", st.method)?;
    stats.set_item("elapsed", st.elapsed)?;
    stats.set_item("spp_min", st.spp_min)?;
    stats.set_item("spp_max", st.spp_max)?;
    stats.set_item("invalid_samples", st.invalid_samples)?;
    stats.set_item("cancelled", st.cancelled)?;
    stats.set_item("warnings", st.warnings.clone())?;
    stats.set_item("acceptance", st.acceptance)?;
    stats.set_item("normalization", st.normalization)?;
    stats.set_item("chains", st.chains)?;
    stats.set_item("direct_pass", st.direct_pass)?;
    stats.set_item("direct_relative_variance", st.direct_relative_variance)?;
    stats.set_item("guide_iterations", st.guide_iterations)?;
    stats.set_item("guide_regions", st.guide_regions)?;
    stats.set_item("mean_path_segments", st.mean_path_segments)?;
    stats.set_item("alpha_rec", st.alpha_rec)?;
    dict.set_item("stats", stats)?;
    Ok(dict)
}

fn mat_to_numpy<'py>(py: Python<'py>, m: &[[f32; 4]; 4]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f32> = m.iter().flatten().copied().collect();
    Ok(PyArray1::from_vec(py, flat).reshape([4, 4])?.into_any())
}

/// An f32 setting as the f64 its shortest decimal reads as (0.3, not 0.30000001192…).
fn shortest(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(x as f64)
}

/// `render`'s settings as RenderSettings::default() has them, keyed as its arguments: the one
/// place the core's defaults live (gdmlt.settings builds the product's on them).
fn default_settings(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = RenderSettings::default();
    let out = PyDict::new(py);
    out.set_item("method", d.method.name())?;
    out.set_item("spp", d.spp)?;
    out.set_item("time_limit", d.time_limit)?;
    out.set_item("max_bounces", d.path.max_bounces)?;
    out.set_item("nee", d.path.nee)?;
    out.set_item("seed", d.seed)?;
    out.set_item("threads", d.threads)?;
    out.set_item("reconstruction", if d.reconstruction == crate::reconstruct::Norm::L1 { "l1" } else { "l2" })?;
    out.set_item("alpha_rec", d.alpha_rec)?;
    out.set_item("large_step_probability", shortest(d.large_step_probability))?;
    out.set_item("alpha_target", shortest(d.alpha_target))?;
    out.set_item("chains", d.chains)?;
    out.set_item("diffuse_bounces", d.path.diffuse_bounces)?;
    out.set_item("glossy_bounces", d.path.glossy_bounces)?;
    out.set_item("transmission_bounces", d.path.transmission_bounces)?;
    out.set_item("volume_bounces", d.path.volume_bounces)?;
    out.set_item("transparent_bounces", d.path.transparent_bounces)?;
    out.set_item("clamp_direct", shortest(d.path.clamp_direct))?;
    out.set_item("clamp_indirect", shortest(d.path.clamp_indirect))?;
    out.set_item("data_passes", d.data_passes)?;
    out.set_item("adaptive_threshold", shortest(d.adaptive_threshold))?;
    out.set_item("adaptive_min_samples", d.adaptive_min_samples)?;
    out.set_item("guiding", d.guiding)?;
    out.set_item("bidirectional", d.bidirectional)?;
    Ok(out)
}

/// The mean cosine of a phase function (`medium::Phase`): "hg", "rayleigh", "draine", "mie".
#[pyfunction]
fn phase_mean_cosine(kind: &str, anisotropy: f32, alpha: f32, diameter: f32) -> PyResult<f32> {
    use crate::medium::Phase;
    let p = match kind {
        "hg" => Phase::hg(anisotropy),
        "rayleigh" => Phase::Rayleigh,
        "draine" => Phase::draine(anisotropy, alpha),
        "mie" => Phase::mie(diameter),
        other => return Err(verr(format!("unknown phase function '{other}' (hg, rayleigh, draine or mie)"))),
    };
    Ok(p.mean_cosine())
}

/// The range of a procedural texture's output (a texture dict's "procedural" entry, its
/// domain ignored) over many points: the domain of the table the add-on builds for a pattern
/// without closed-form bounds.
#[pyfunction]
fn procedural_range(spec: &Bound<'_, PyDict>) -> PyResult<(f32, f32)> {
    Ok(parse_procedural(spec, "procedural_range")?.sampled_range())
}

/// The scene dict of a built-in scene (the names in `scene::builtin::BUILTIN_SCENES`).
#[pyfunction]
#[pyo3(signature = (name, width=256, height=256))]
fn builtin_scene<'py>(py: Python<'py>, name: &str, width: u32, height: u32) -> PyResult<Bound<'py, PyDict>> {
    let d = scene::builtin::builtin(name, width, height).ok_or_else(|| {
        verr(format!("unknown built-in scene '{name}' (known: {})", scene::builtin::BUILTIN_SCENES.join(", ")))
    })?;
    let out = PyDict::new(py);
    let meshes = PyList::empty(py);
    for m in &d.meshes {
        let md = PyDict::new(py);
        md.set_item("name", &m.name)?;
        let pos: Vec<f32> = m.positions.iter().flatten().copied().collect();
        md.set_item("positions", PyArray1::from_vec(py, pos).reshape([m.positions.len(), 3])?)?;
        let idx: Vec<u32> = m.indices.iter().flatten().copied().collect();
        md.set_item("indices", PyArray1::from_vec(py, idx).reshape([m.indices.len(), 3])?)?;
        md.set_item("material_ids", PyArray1::from_slice(py, &m.material_ids))?;
        md.set_item("pass_index", m.pass_index)?;
        if !m.transforms.is_empty() {
            let xf: Vec<f32> = m.transforms.iter().flatten().copied().collect();
            md.set_item("transforms", PyArray1::from_vec(py, xf).reshape([m.transforms.len(), 12])?)?;
        }
        if let Some(offset) = m.shadow_terminator_offset {
            md.set_item("shadow_terminator_offset", offset)?;
        }
        if !m.corner_normals.is_empty() {
            let n: Vec<f32> = m.corner_normals.iter().flatten().copied().collect();
            md.set_item("normals", PyArray1::from_vec(py, n).reshape([m.corner_normals.len(), 3])?)?;
        }
        if !m.corner_uvs.is_empty() {
            let uv: Vec<f32> = m.corner_uvs.iter().flatten().copied().collect();
            md.set_item("uvs", PyArray1::from_vec(py, uv).reshape([m.corner_uvs.len(), 2])?)?;
        }
        if !m.corner_colors.is_empty() {
            let c: Vec<f32> = m.corner_colors.iter().flatten().copied().collect();
            md.set_item("colors", PyArray1::from_vec(py, c).reshape([m.corner_colors.len(), 3])?)?;
        }
        meshes.append(md)?;
    }
    out.set_item("meshes", meshes)?;
    let mats = PyList::empty(py);
    for m in &d.materials {
        mats.append(material_dict(py, m)?)?;
    }
    out.set_item("materials", mats)?;
    let textures = PyList::empty(py);
    for t in &d.textures {
        let td = PyDict::new(py);
        td.set_item("name", &t.name)?;
        td.set_item("width", t.width)?;
        td.set_item("height", t.height)?;
        td.set_item("channels", 3)?;
        let px: Vec<f32> = t.pixels.iter().flatten().copied().collect();
        td.set_item("pixels", PyArray1::from_vec(py, px))?;
        td.set_item("interpolation", if t.closest { "Closest" } else { "Linear" })?;
        let ext = match t.extension {
            TextureExtension::Repeat => "REPEAT",
            TextureExtension::Extend => "EXTEND",
            TextureExtension::Clip => "CLIP",
            TextureExtension::Mirror => "MIRROR",
        };
        td.set_item("extension", ext)?;
        td.set_item("srgb", t.srgb)?;
        if let Some(m) = t.transform {
            td.set_item("transform", m.to_vec())?;
        }
        textures.append(td)?;
    }
    out.set_item("textures", textures)?;
    out.set_item("lights", PyList::empty(py))?;
    let c = &d.camera;
    let cd = PyDict::new(py);
    cd.set_item("matrix", mat_to_numpy(py, &c.to_world)?)?;
    cd.set_item(
        "type",
        match c.projection {
            Projection::Perspective => "PERSP",
            Projection::Orthographic => "ORTHO",
            Projection::Equirectangular => "EQUIRECTANGULAR",
            Projection::FisheyeEquidistant => "FISHEYE_EQUIDISTANT",
            Projection::FisheyeEquisolid => "FISHEYE_EQUISOLID",
        },
    )?;
    cd.set_item("fisheye_fov", c.fisheye_fov)?;
    cd.set_item("fisheye_lens", c.fisheye_lens)?;
    for (k, v) in ["latitude_min", "latitude_max", "longitude_min", "longitude_max"].iter().zip(c.panorama) {
        cd.set_item(*k, v)?;
    }
    cd.set_item("lens", c.lens)?;
    cd.set_item("sensor_width", c.sensor_width)?;
    cd.set_item("sensor_height", c.sensor_height)?;
    cd.set_item("sensor_fit", "AUTO")?;
    cd.set_item("clip_start", c.clip_start)?;
    cd.set_item("clip_end", c.clip_end)?;
    cd.set_item("resolution_x", c.resolution_x)?;
    cd.set_item("resolution_y", c.resolution_y)?;
    cd.set_item("pixel_filter", c.pixel_filter.clone())?;
    cd.set_item("filter_width", c.filter_width)?;
    cd.set_item("film_transparent", c.film_transparent)?;
    if let Some(b) = c.backdrop {
        cd.set_item("backdrop", b)?;
    }
    out.set_item("camera", cd)?;
    out.set_item("world", d.world)?;
    Ok(out)
}

/// Writes images into one EXR: `layers` is a list of (name, float32 array (H, W, C)); the
/// first is the main RGB.
#[pyfunction]
#[pyo3(signature = (path, layers, metadata=None))]
fn write_exr(
    py: Python<'_>,
    path: std::path::PathBuf,
    layers: Vec<(String, Bound<'_, PyAny>)>,
    metadata: Option<std::collections::BTreeMap<String, String>>,
) -> PyResult<()> {
    let imgs: Vec<(String, Image)> =
        layers.iter().map(|(n, a)| Ok((n.clone(), numpy_to_image(a)?))).collect::<PyResult<_>>()?;
    let refs: Vec<(&str, &Image)> = imgs.iter().map(|(n, i)| (n.as_str(), i)).collect();
    let meta = metadata.unwrap_or_default();
    let meta: Vec<(&str, &str)> = meta.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    py.detach(|| crate::output::write_exr_with(&path, &refs, &meta)).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

/// The gradient-domain image from (primal without very-direct light, dx, dy, very direct),
/// each float32 (H, W, 3): screened Poisson reconstruction (`norm` "l1" or "l2", weight
/// `alpha`) plus the very-direct light, clipped at 0 — what gdpt/gdpssmlt write as Combined.
/// Used to merge partial renders (gdmlt merge). `method` ("gdpt" or "gdpssmlt") picks the L1
/// schedule that method's renders use; `irls` = (reweightings, CG steps each, regulariser
/// decay) replaces it (for measuring schedules).
#[pyfunction]
#[pyo3(signature = (primal, dx, dy, direct, alpha=0.2, norm="l1", method="gdpssmlt", irls=None))]
#[allow(clippy::too_many_arguments)] // Python's keyword arguments
fn reconstruct<'py>(
    py: Python<'py>,
    primal: &Bound<'py, PyAny>,
    dx: &Bound<'py, PyAny>,
    dy: &Bound<'py, PyAny>,
    direct: &Bound<'py, PyAny>,
    alpha: f64,
    norm: &str,
    method: &str,
    irls: Option<(usize, usize, f64)>,
) -> PyResult<Bound<'py, PyAny>> {
    let norm = crate::reconstruct::Norm::parse(norm)
        .ok_or_else(|| verr(format!("unknown reconstruction '{norm}' (expected l1 or l2)")))?;
    let mut schedule = match method {
        "gdpt" => crate::reconstruct::IrlsParams::short(),
        "gdpssmlt" => crate::reconstruct::IrlsParams::default(),
        _ => return Err(verr(format!("unknown method '{method}' (expected gdpt or gdpssmlt)"))),
    };
    if let Some((outer, cg, decay)) = irls {
        if outer > 1000 || cg > 10_000 || !(decay.is_finite() && decay > 0.0 && decay <= 1.0) {
            return Err(verr("irls must be (reweightings ≤ 1000, CG steps ≤ 10000, 0 < decay ≤ 1)"));
        }
        (schedule.outer_iterations, schedule.cg_iterations, schedule.decay) = (outer, cg, decay);
    }
    let irls = schedule;
    if !(alpha.is_finite() && alpha > 0.0) {
        return Err(verr("alpha must be a finite number > 0"));
    }
    let imgs = [primal, dx, dy, direct].map(numpy_to_image);
    let [p, gx, gy, d] = imgs;
    let (p, gx, gy, d) = (p?, gx?, gy?, d?);
    if p.width == 0 || p.height == 0 {
        return Err(verr("reconstruct: the images are empty (0 pixels)"));
    }
    if p.channels != 3 || [&gx, &gy, &d].iter().any(|i| (i.width, i.height, i.channels) != (p.width, p.height, 3)) {
        return Err(verr("primal, dx, dy and direct must all be float32 arrays of the same shape (H, W, 3)"));
    }
    let out = py.detach(|| {
        use crate::reconstruct::{gradient_domain_image, Problem, RowPlanar};
        let planar = |i: &Image| RowPlanar::from_interleaved(&i.data, i.width, i.height, 1.0);
        let problem = Problem::new(alpha, planar(&p), planar(&gx), planar(&gy));
        gradient_domain_image(&problem, &d.data, norm, &irls, &|| false)
    });
    image_to_numpy(py, out)
}

/// Writes an RGB float32 (H, W, 3) linear image as an 8-bit sRGB PNG.
#[pyfunction]
fn write_png(path: std::path::PathBuf, image: &Bound<'_, PyAny>) -> PyResult<()> {
    let img = numpy_to_image(image)?;
    crate::output::write_png(&path, &img).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

/// How many paths the Metropolis methods' bootstrap traces before their first mutation on a
/// `width × height` image (their fixed cost; `gdmlt.auto` weighs it before a pilot render).
#[pyfunction]
fn bootstrap_paths(width: u32, height: u32) -> usize {
    integrator::mlt::bootstrap_samples(width as usize, height as usize)
}

/// Raises ValueError when a `width × height` render with `method` would need more memory
/// than this process may allocate (what `render` checks first; `gdmlt.auto` asks before its
/// pilot, which renders only a window of the frame).
#[pyfunction]
fn check_memory(method: &str, width: u32, height: u32) -> PyResult<()> {
    let method = Method::parse(method).map_err(|e| verr(e.to_string()))?;
    let available = integrator::memory::available();
    integrator::memory::check(method, width, height, available).map_err(|e| verr(e.to_string()))
}

/// Whether this CPU runs the x86-64-v3 build (AVX2, FMA, BMI1/2, LZCNT, MOVBE, F16C), so
/// that `gdmlt/__init__.py` can load it instead of the portable one.
#[pyfunction]
fn cpu_supports_x86_64_v3() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("lzcnt")
            && std::arch::is_x86_feature_detected!("movbe")
            && std::arch::is_x86_feature_detected!("f16c")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

fn init_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Scene>()?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(builtin_scene, m)?)?;
    m.add_function(wrap_pyfunction!(procedural_range, m)?)?;
    m.add_function(wrap_pyfunction!(phase_mean_cosine, m)?)?;
    m.add_function(wrap_pyfunction!(write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(write_png, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(cpu_supports_x86_64_v3, m)?)?;
    m.add_function(wrap_pyfunction!(check_memory, m)?)?;
    m.add_function(wrap_pyfunction!(bootstrap_paths, m)?)?;
    m.add("METHODS", vec!["pt", "bdpt", "gdpt", "pssmlt", "gdpssmlt"])?;
    m.add("DEFAULT_SETTINGS", default_settings(m.py())?)?;
    // The path builder's Russian roulette starts after this many bounces (benchmarks set
    // their peers' roulette to it, so that every renderer traces paths of the same length).
    m.add("RR_START_DEPTH", crate::path::RR_START_DEPTH)?;
    m.add("RR_EXPONENT", crate::path::RR_EXPONENT)?;
    m.add("VARIANCE_MIN_SAMPLES", crate::film::VARIANCE_MIN_SAMPLES)?;
    m.add("VARIANCE_UNKNOWN", crate::film::VARIANCE_UNKNOWN)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("BUILD_TARGET", if cfg!(target_feature = "avx2") { "x86-64-v3" } else { "portable" })?;
    m.add("SOURCE_HASH", env!("GDMLT_SOURCE_HASH"))?;
    Ok(())
}

/// The portable module (baseline x86-64 / any target).
#[cfg(not(feature = "v3-module"))]
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    init_module(m)
}

/// The same core compiled with `-C target-cpu=x86-64-v3` (Makefile `build`), loaded at
/// import time only on CPUs that have those instructions: a wheel never crashes an older CPU.
#[cfg(feature = "v3-module")]
#[pymodule]
fn _core_v3(m: &Bound<'_, PyModule>) -> PyResult<()> {
    init_module(m)
}
