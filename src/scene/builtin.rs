//! Scenes built in code: the Cornell box (also saved as `examples/cornell.blend` by
//! tools/make_examples.py from these very arrays) and a closed furnace sphere for tests.

use super::desc::*;

const WHITE: [f32; 3] = [0.725, 0.71, 0.68];
const RED: [f32; 3] = [0.63, 0.065, 0.05];
const GREEN: [f32; 3] = [0.14, 0.45, 0.091];
/// Emitted radiance of the Cornell box's ceiling light (Emission Color × Strength).
pub const CORNELL_LIGHT: [f32; 3] = [17.0, 12.0, 4.0];

fn quad(name: &str, p: [[f32; 3]; 4], mat: u32) -> MeshDesc {
    MeshDesc {
        name: name.into(),
        positions: p.to_vec(),
        transforms: vec![],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        corner_normals: vec![],
        material_ids: vec![mat, mat],
        corner_uvs: vec![],
        corner_colors: vec![],
        corner_generated: vec![],
        corner_object: vec![],
        camera_invisible: false,
        shadow_invisible: false,
        pass_index: 0,
        shadow_terminator_offset: None,
        holdout: false,
        light_set: 0,
        light_membership: None,
    }
}

/// An axis-aligned box rotated by `angle` about +Z around its centre.
fn block(name: &str, center: [f32; 3], half: [f32; 3], angle: f32, mat: u32) -> MeshDesc {
    let (s, c) = angle.sin_cos();
    let mut positions = Vec::new();
    for k in 0..8 {
        let l = [
            if k & 1 != 0 { half[0] } else { -half[0] },
            if k & 2 != 0 { half[1] } else { -half[1] },
            if k & 4 != 0 { half[2] } else { -half[2] },
        ];
        positions.push([center[0] + c * l[0] - s * l[1], center[1] + s * l[0] + c * l[1], center[2] + l[2]]);
    }
    // faces as quads (outward orientation is irrelevant: surfaces are two-sided)
    let faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    let mut indices = Vec::new();
    for f in faces {
        indices.push([f[0], f[1], f[2]]);
        indices.push([f[0], f[2], f[3]]);
    }
    flat_mesh(name, positions, indices, mat)
}

fn material(name: &str, base_color: [f32; 3], emission: [f32; 3]) -> MaterialDesc {
    MaterialDesc { name: name.into(), base_color, emission, roughness: 1.0, ..Default::default() }
}

/// White glass of IOR 1.5 ("Glass"), smooth at roughness 0.
fn clear_glass(roughness: f32) -> MaterialDesc {
    MaterialDesc {
        name: "Glass".into(),
        base_color: [1.0; 3],
        transmission: 1.0,
        ior: 1.5,
        roughness,
        ..Default::default()
    }
}

/// Camera at `position` looking along +Y with +Z up (Blender convention: looks down local −Z).
pub fn camera_looking_along_y(position: [f32; 3], lens: f32, width: u32, height: u32) -> CameraDesc {
    CameraDesc {
        to_world: [
            [1.0, 0.0, 0.0, position[0]],
            [0.0, 0.0, -1.0, position[1]],
            [0.0, 1.0, 0.0, position[2]],
            [0.0, 0.0, 0.0, 1.0],
        ],
        lens,
        sensor_width: 36.0,
        resolution_x: width,
        resolution_y: height,
        clip_start: 0.01,
        clip_end: 100.0,
        ..Default::default()
    }
}

/// The Cornell box: walls at x, z = ±1, back wall at y = 1, open towards the camera at −y,
/// lit by an emissive quad set into the ceiling.
pub fn cornell_box(width: u32, height: u32) -> SceneDesc {
    let materials = vec![
        material("White", WHITE, [0.0; 3]),
        material("Red", RED, [0.0; 3]),
        material("Green", GREEN, [0.0; 3]),
        material("Light", [0.0; 3], CORNELL_LIGHT),
    ];
    let l = 0.25;
    let lz = 1.0;
    let meshes = vec![
        quad("Floor", [[-1.0, -1.0, -1.0], [1.0, -1.0, -1.0], [1.0, 1.0, -1.0], [-1.0, 1.0, -1.0]], 0),
        // The ceiling has a hole that the light fills, so the light's back (mesh emission is
        // two-sided) faces outside instead of into a thin gap above it.
        quad("Ceiling", [[-1.0, -1.0, 1.0], [-1.0, -l, 1.0], [1.0, -l, 1.0], [1.0, -1.0, 1.0]], 0),
        quad("Ceiling.001", [[-1.0, l, 1.0], [-1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, l, 1.0]], 0),
        quad("Ceiling.002", [[-1.0, -l, 1.0], [-1.0, l, 1.0], [-l, l, 1.0], [-l, -l, 1.0]], 0),
        quad("Ceiling.003", [[l, -l, 1.0], [l, l, 1.0], [1.0, l, 1.0], [1.0, -l, 1.0]], 0),
        quad("BackWall", [[-1.0, 1.0, -1.0], [1.0, 1.0, -1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]], 0),
        quad("LeftWall", [[-1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, 1.0, 1.0], [-1.0, -1.0, 1.0]], 1),
        quad("RightWall", [[1.0, -1.0, -1.0], [1.0, -1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, -1.0]], 2),
        quad("Light", [[-l, -l, lz], [l, -l, lz], [l, l, lz], [-l, l, lz]], 3),
        block("ShortBlock", [0.33, -0.3, -0.7], [0.3, 0.3, 0.3], -0.3, 0),
        block("TallBlock", [-0.35, 0.3, -0.4], [0.3, 0.3, 0.6], 0.3, 0),
    ];
    SceneDesc {
        meshes,
        materials,
        lights: vec![],
        textures: vec![],
        world_texture: None,
        world_volume: None,
        world_rotation: None,
        camera: camera_looking_along_y([0.0, -3.4, 0.0], 35.0, width, height),
        world: [0.0; 3],
        general_paths: false,
        oren_nayar_rho_cubed: false,
        normal_map_unnormalized_base: false,
        light_membership: Vec::new(),
    }
}

/// A closed UV sphere mesh (flat-shaded facets).
fn uv_sphere(name: &str, center: [f32; 3], radius: f32, nu: u32, nv: u32, mat: u32) -> MeshDesc {
    let mut positions = Vec::new();
    for j in 0..=nv {
        let theta = std::f32::consts::PI * j as f32 / nv as f32;
        for i in 0..nu {
            let phi = 2.0 * std::f32::consts::PI * i as f32 / nu as f32;
            positions.push([
                center[0] + radius * theta.sin() * phi.cos(),
                center[1] + radius * theta.sin() * phi.sin(),
                center[2] + radius * theta.cos(),
            ]);
        }
    }
    let mut indices = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let a = j * nu + i;
            let b = j * nu + (i + 1) % nu;
            let c = (j + 1) * nu + i;
            let d = (j + 1) * nu + (i + 1) % nu;
            if j > 0 {
                indices.push([a, b, d]);
            }
            if j + 1 < nv {
                indices.push([a, d, c]);
            }
        }
    }
    flat_mesh(name, positions, indices, mat)
}

/// The Cornell box with a glass sphere and a mirror sphere instead of the blocks, a lacquered
/// floor (a smooth dielectric layer of IOR 2.2 over dark grey: Principled's opaque
/// dielectric, roughness 0) and a back wall of rough white plastic (IOR 1.5, roughness 0.3):
/// the specular test scene of the gradient-domain methods.
pub fn cornell_spheres(width: u32, height: u32) -> SceneDesc {
    let mut d = cornell_box(width, height);
    d.meshes.retain(|m| !m.name.ends_with("Block"));
    for (name, roughness, ior, base_color) in [("Floor", 0.0f32, 2.2, [0.25; 3]), ("BackWall", 0.3, 1.5, WHITE)] {
        d.materials.push(MaterialDesc {
            name: format!("{name}Plastic"),
            base_color,
            roughness,
            specular_ior: ior,
            ..Default::default()
        });
        let m = d.materials.len() as u32 - 1;
        d.meshes
            .iter_mut()
            .filter(|mesh| mesh.name == name)
            .for_each(|mesh| mesh.material_ids = vec![m; mesh.indices.len()]);
    }
    d.materials.push(clear_glass(0.0));
    d.materials.push(MaterialDesc {
        name: "Mirror".into(),
        base_color: [0.95; 3],
        metallic: 1.0,
        roughness: 0.0,
        ..Default::default()
    });
    let (glass, mirror) = (d.materials.len() as u32 - 2, d.materials.len() as u32 - 1);
    d.meshes.push(uv_sphere("GlassSphere", [0.4, -0.3, -0.6], 0.4, 32, 16, glass));
    d.meshes.push(uv_sphere("MirrorSphere", [-0.4, 0.35, -0.6], 0.4, 32, 16, mirror));
    d
}

/// The Cornell box lit only by a bulb: an emitting sphere (the filament) inside a solid
/// sphere of rough glass (roughness 0.35, IOR 1.5) hanging in the middle of the room, the
/// ceiling light switched off and the blocks removed. Every light path crosses the glass,
/// and the camera sees the filament through it (the transmission test scene).
pub fn cornell_bulb(width: u32, height: u32) -> SceneDesc {
    let mut d = cornell_box(width, height);
    d.meshes.retain(|m| !m.name.ends_with("Block"));
    let light = d.materials.iter().position(|m| m.name == "Light").expect("the box has a light");
    d.materials[light].emission = [0.0; 3];
    d.materials.push(clear_glass(0.35));
    d.materials.push(material("Filament", [0.0; 3], [60.0, 45.0, 25.0]));
    let (glass, filament) = (d.materials.len() as u32 - 2, d.materials.len() as u32 - 1);
    d.meshes.push(uv_sphere("Bulb", [0.0, 0.0, 0.1], 0.35, 32, 16, glass));
    d.meshes.push(uv_sphere("Filament", [0.0, 0.0, 0.1], 0.1, 16, 8, filament));
    d
}

/// The Cornell box lit by every kind of light at once, as artists mix them: the ceiling
/// quad (an emissive mesh), a rectangular area light under the ceiling, a sphere lamp and a
/// spot near the floor, a sun with a 5° disc through the open front, and a grey-blue world
/// (the light-selection test scene).
pub fn cornell_mixed_lights(width: u32, height: u32) -> SceneDesc {
    let mut d = cornell_box(width, height);
    let light = d.materials.iter().position(|m| m.name == "Light").expect("the box has a light");
    d.materials[light].emission = [4.0, 3.0, 1.0];
    let down = [[1.0, 0.0, 0.0, -0.5], [0.0, 1.0, 0.0, 0.4], [0.0, 0.0, 1.0, 0.9], [0.0, 0.0, 0.0, 1.0]];
    d.lights = vec![
        LightDesc::Area {
            name: "Area".into(),
            to_world: down, // emits along local −Z: down
            shape: AreaShape::Rectangle,
            size_x: 0.4,
            size_y: 0.2,
            power: [20.0, 20.0, 25.0],
            normalize: true,
            spread: std::f32::consts::PI,
            visible_camera: false,
            cast_shadow: true,
        },
        LightDesc::Point {
            name: "Lamp".into(),
            position: [-0.6, 0.6, -0.7],
            radius: 0.05,
            power: [15.0, 10.0, 5.0],
            soft_falloff: true,
            visible_camera: false,
            cast_shadow: true,
        },
        LightDesc::Spot {
            name: "Spot".into(),
            position: [0.6, 0.0, 0.6],
            direction: [0.0, 0.0, -1.0],
            radius: 0.02,
            power: [30.0, 30.0, 30.0],
            spot_size: 0.8,
            spot_blend: 0.2,
            soft_falloff: true,
            visible_camera: false,
            cast_shadow: true,
            matrix: None,
        },
        LightDesc::Sun {
            name: "Sun".into(),
            direction: [0.2, -0.8, 0.4],
            irradiance: [2.0, 1.8, 1.5],
            angle: 5f32.to_radians(),
            visible_camera: false,
            cast_shadow: true,
        },
    ];
    d.world = [0.1, 0.12, 0.15];
    d
}

/// The Cornell box with a plate under the light that has one narrow gap: the room is lit
/// only through it (a hard case for path tracing, the kind MLT is for).
pub fn cornell_gap(width: u32, height: u32) -> SceneDesc {
    let mut d = cornell_box(width, height);
    let (z, g0, g1) = (0.8f32, 0.05f32, 0.15f32);
    d.meshes.push(quad("PlateFront", [[-1.0, -1.0, z], [1.0, -1.0, z], [1.0, g0, z], [-1.0, g0, z]], 0));
    d.meshes.push(quad("PlateBack", [[-1.0, g1, z], [1.0, g1, z], [1.0, 1.0, z], [-1.0, 1.0, z]], 0));
    d
}

/// The Cornell box with a veil: a card between the blocks and the camera that lets 60% of
/// the light through, tinted orange (Transparent BSDF / alpha), and reflects the rest
/// diffusely, and a canopy of lace under the light whose coverage is an alpha texture, which
/// most direct light crosses (half-shadows: the transparency test scene).
pub fn cornell_veil(width: u32, height: u32) -> SceneDesc {
    let mut d = cornell_box(width, height);
    d.materials.push(MaterialDesc {
        name: "Veil".into(),
        base_color: [0.8; 3],
        roughness: 1.0,
        transparency: 0.6,
        transparent_color: [1.0, 0.7, 0.4],
        ..Default::default()
    });
    let m = d.materials.len() as u32 - 1;
    let (y, z0, z1) = (-0.75f32, -1.0f32, 0.3f32);
    d.meshes.push(quad("Veil", [[-0.7, y, z0], [0.7, y, z0], [0.7, y, z1], [-0.7, y, z1]], m));
    // and a canopy of lace under the light, which most direct light crosses: its coverage
    // (alpha) comes from a texture, a 4×4 checker of alpha 1, 0, 0.5 and 0.25
    let alpha = [1.0f32, 0.0, 0.5, 0.25];
    d.textures.push(TextureDesc {
        name: "LaceAlpha".into(),
        width: 4,
        height: 4,
        pixels: (0..16).map(|i| [alpha[(i % 4 + i / 4) % 4]; 3]).collect(),
        closest: true,
        ..Default::default()
    });
    d.materials.push(MaterialDesc {
        name: "Lace".into(),
        base_color: [0.8; 3],
        roughness: 1.0,
        alpha_texture: Some(d.textures.len() as u32 - 1),
        ..Default::default()
    });
    let lace = d.materials.len() as u32 - 1;
    let z = 0.7f32;
    let mut canopy = quad("Canopy", [[-0.6, -0.6, z], [0.6, -0.6, z], [0.6, 0.6, z], [-0.6, 0.6, z]], lace);
    // the quad's triangles are (0, 1, 2) and (0, 2, 3)
    let uv = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    canopy.corner_uvs = [0, 1, 2, 0, 2, 3].iter().map(|&k| uv[k]).collect();
    d.meshes.push(canopy);
    d
}

/// A closed UV sphere of radius 1 with uniform albedo and emission, seen from its centre.
/// Radiance inside is constant: L = Le·Σ_{k=0}^{B+1} ρ^k for B bounces (ρ = albedo).
pub fn furnace_sphere(albedo: f32, emission: f32, width: u32, height: u32) -> SceneDesc {
    SceneDesc {
        meshes: vec![uv_sphere("Sphere", [0.0; 3], 1.0, 48, 24, 0)],
        materials: vec![material("Furnace", [albedo; 3], [emission; 3])],
        lights: vec![],
        textures: vec![],
        world_texture: None,
        world_volume: None,
        world_rotation: None,
        camera: camera_looking_along_y([0.0, 0.0, 0.0], 20.0, width, height),
        world: [0.0; 3],
        general_paths: false,
        oren_nayar_rho_cubed: false,
        normal_map_unnormalized_base: false,
        light_membership: Vec::new(),
    }
}

/// The Cornell box filled with a faint bluish haze (a homogeneous medium: scattering
/// (0.35, 0.4, 0.45), absorption 0.05, Henyey–Greenstein g = 0.3 per unit length) in a box
/// that reaches out of its open side towards the camera (which stays outside).
pub fn cornell_fog(width: u32, height: u32) -> SceneDesc {
    let mut d = cornell_box(width, height);
    let m = d.materials.len() as u32;
    d.materials.push(MaterialDesc {
        name: "Haze".into(),
        base_color: [0.0; 3],
        transparency: 1.0,
        transparent_color: [1.0; 3],
        volume: Some(super::desc::VolumeDesc {
            scattering: [0.35, 0.4, 0.45],
            absorption: [0.05; 3],
            emission: [0.0; 3],
            anisotropy: 0.3,
            density: None,
            ..Default::default()
        }),
        ..Default::default()
    });
    d.meshes.push(closed_box("Haze", [-0.98, -1.6, -0.98], [0.98, 0.98, 0.98], m));
    d
}

/// A closed axis-aligned box, its faces wound outwards (what a medium's boundary needs).
pub fn closed_box(name: &str, lo: [f32; 3], hi: [f32; 3], mat: u32) -> MeshDesc {
    let p = |k: usize| [[lo[0], hi[0]][k & 1], [lo[1], hi[1]][(k >> 1) & 1], [lo[2], hi[2]][(k >> 2) & 1]];
    let faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let mut indices = Vec::new();
    for f in faces {
        indices.push([f[0], f[1], f[2]]);
        indices.push([f[0], f[2], f[3]]);
    }
    flat_mesh(name, (0..8).map(p).collect(), indices, mat)
}

/// Names accepted by `builtin`.
pub const BUILTIN_SCENES: &[&str] = &["cornell", "spheres", "gap", "veil", "bulb", "lights", "furnace", "fog"];

pub fn builtin(name: &str, width: u32, height: u32) -> Option<SceneDesc> {
    match name {
        "cornell" => Some(cornell_box(width, height)),
        "spheres" => Some(cornell_spheres(width, height)),
        "gap" => Some(cornell_gap(width, height)),
        "veil" => Some(cornell_veil(width, height)),
        "bulb" => Some(cornell_bulb(width, height)),
        "lights" => Some(cornell_mixed_lights(width, height)),
        "furnace" => Some(furnace_sphere(0.8, 1.0, width, height)),
        "fog" => Some(cornell_fog(width, height)),
        _ => None,
    }
}

/// A flat-shaded mesh of one material, without UVs.
fn flat_mesh(name: &str, positions: Vec<[f32; 3]>, indices: Vec<[u32; 3]>, mat: u32) -> MeshDesc {
    let n = indices.len();
    MeshDesc {
        name: name.into(),
        positions,
        transforms: vec![],
        indices,
        corner_normals: vec![],
        material_ids: vec![mat; n],
        corner_uvs: vec![],
        corner_colors: vec![],
        corner_generated: vec![],
        corner_object: vec![],
        camera_invisible: false,
        shadow_invisible: false,
        pass_index: 0,
        shadow_terminator_offset: None,
        holdout: false,
        light_set: 0,
        light_membership: None,
    }
}
