//! The scene as flat arrays: what the Blender addon, the USD reader and the built-in scenes
//! hand to the core. `Scene::build` (scene/mod.rs) is the one place that turns it into a
//! renderable scene, validating everything on the way in.

/// One triangle mesh: in world space, or in its object space placed by `transforms`.
#[derive(Clone, Debug, Default)]
pub struct MeshDesc {
    pub name: String,
    /// Vertex positions, xyz (in object space when the mesh has `transforms`).
    pub positions: Vec<[f32; 3]>,
    /// Instances: the object-to-world transforms (row-major 3×4) the mesh is placed by, the
    /// mesh stored once for all of them (`instancing.rs`); empty: the mesh is in world
    /// space, once. Every instance shares the mesh's other fields (materials, visibility,
    /// pass index, light linking). An instanced mesh whose materials emit is placed as that
    /// many world-space copies instead (each copy is a light of its own).
    pub transforms: Vec<[f32; 12]>,
    /// Triangle vertex indices.
    pub indices: Vec<[u32; 3]>,
    /// Optional per-corner shading normals (3 per triangle, in triangle order); empty = flat.
    /// A triangle whose three are zero (or broken) is flat-shaded.
    pub corner_normals: Vec<[f32; 3]>,
    /// Per-triangle index into the scene material table (empty = all 0).
    pub material_ids: Vec<u32>,
    /// Optional per-corner texture coordinates (3 per triangle, in triangle order; Blender's
    /// active render UV map); empty = all (0, 0).
    pub corner_uvs: Vec<[f32; 2]>,
    /// Optional per-corner colours (3 per triangle, in triangle order; linear RGB: the
    /// colour attribute its materials read); empty = none, which reads as black.
    pub corner_colors: Vec<[f32; 3]>,
    /// Optional per-corner Generated and Object coordinates (3 per triangle, in triangle
    /// order), where its materials' procedural textures read them; empty = none, which reads
    /// as the origin.
    pub corner_generated: Vec<[f32; 3]>,
    pub corner_object: Vec<[f32; 3]>,
    /// The object's Pass Index (Blender's IndexOB pass).
    pub pass_index: u32,
    /// Ray visibility off (Blender's Object › Visibility › Ray Visibility): camera rays pass
    /// through the object; shadow rays pass through it (it casts no shadow).
    pub camera_invisible: bool,
    pub shadow_invisible: bool,
    /// The object's Shadow Terminator › Geometry Offset (0…1; `None`: Cycles' default 0.1),
    /// which lifts the start of light samples' shadow rays on its smooth-shaded triangles
    /// (scene/terminator.rs).
    pub shadow_terminator_offset: Option<f32>,
    /// Object › Visibility › Holdout: where the camera sees the object (straight, or through
    /// transparent surfaces) the film is transparent and black, as Cycles' holdout; every
    /// other ray sees it as its material.
    pub holdout: bool,
    /// Light linking (Blender's Light Linking, as Cycles' light sets): the receiver set the
    /// object belongs to (0…63; 0, the default, for objects no emitter links explicitly),
    /// and, for an emissive object, the receiver sets it lights (bit k: set k; None: all).
    pub light_set: u8,
    pub light_membership: Option<u64>,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TextureExtension {
    #[default]
    Repeat,
    Extend,
    Clip,
    /// Repeated with every other copy mirrored (Blender's Mirror), so edges meet seamlessly.
    Mirror,
}

/// An image texture, row 0 at the bottom: linear values, or sRGB-encoded values (8-bit sRGB
/// images) that are decoded after interpolation, as Cycles does.
#[derive(Clone, Debug, Default)]
pub struct TextureDesc {
    pub name: String,
    pub width: usize,
    pub height: usize,
    /// width × height RGB values, row-major from the bottom row.
    pub pixels: Vec<[f32; 3]>,
    /// Blender's "Closest" interpolation (else "Linear", bilinear).
    pub closest: bool,
    pub extension: TextureExtension,
    /// The pixels are sRGB-encoded: decode after interpolating.
    pub srgb: bool,
    /// Affine map of the texture coordinates before the lookup (Blender's Mapping node on a
    /// UV input): (u, v) → (m0·u + m1·v + m2, m3·u + m4·v + m5). None = identity. Surface
    /// textures only (the world's importance sampling assumes none).
    pub transform: Option<[f32; 6]>,
    /// A procedural texture (scene/procedural.rs): its pattern, and `pixels` (width × 1) the
    /// table of what the graph after the pattern makes of each output value in its domain.
    pub procedural: Option<super::procedural::Procedural>,
}

/// A material, as the parameters of one uber-material close to Blender's Principled BSDF.
/// Plain "Diffuse" and "Emission" shaders are special cases of it.
#[derive(Clone, Debug)]
pub struct MaterialDesc {
    pub name: String,
    pub base_color: [f32; 3],
    /// Emitted radiance: Emission Color × Emission Strength (two-sided, as in Cycles).
    pub emission: [f32; 3],
    pub roughness: f32,
    /// Roughness σ of the diffuse base (Blender's Diffuse BSDF Roughness, Principled Diffuse
    /// Roughness): 0 = Lambertian, above it Oren–Nayar as Cycles renders it.
    pub diffuse_roughness: f32,
    pub metallic: f32,
    pub transmission: f32,
    pub ior: f32,
    /// IOR of the dielectric specular layer over the diffuse base (Principled's opaque
    /// dielectric, UsdPreviewSurface's specular lobe); 1 = none (a plain Diffuse BSDF).
    pub specular_ior: f32,
    /// Coverage of that layer over the diffuse base (1 for Principled; less where a Mix
    /// Shader blends a Principled with a plain Diffuse).
    pub specular: f32,
    /// Image textures (indices into `SceneDesc::textures`) that replace the base colour, and
    /// the roughness (the texture's luminance), where the material links them.
    pub base_color_texture: Option<u32>,
    pub roughness_texture: Option<u32>,
    /// A texture whose luminance replaces `metallic` (a metallic map).
    pub metallic_texture: Option<u32>,
    /// A texture whose luminance is the alpha (coverage) of the surface: transparency
    /// 1 − alpha(uv) replaces `transparency` (an image's alpha channel into Principled Alpha).
    pub alpha_texture: Option<u32>,
    /// A tangent-space normal map (linear RGB, 0.5 = no tilt; Blender's Normal Map node in
    /// Tangent space) and its strength, perturbing the shading normal.
    pub normal_texture: Option<u32>,
    pub normal_strength: f32,
    /// A height map (its luminance, in scene units × `bump_distance`) that bumps the shading
    /// normal as Blender's Bump node: N' = normalize(N − distance·∇h), mixed with N by
    /// `bump_strength`; a negative distance inverts it.
    pub bump_texture: Option<u32>,
    pub bump_distance: f32,
    pub bump_strength: f32,
    /// The base colour (constant or texture) is multiplied by the mesh's corner colours,
    /// interpolated across each triangle (Blender's Color Attribute node into Base Color,
    /// alone or through Mix › Multiply with an image); a mesh without them reads black, as
    /// Cycles reads a missing attribute.
    pub vertex_color: bool,
    /// Diffuse lobes under a normal or bump map are shadowed (Cycles' Bump Map Correction,
    /// on by default: `bsdf/bump_shadowing.rs`).
    pub bump_map_correction: bool,
    /// An image that multiplies `emission` per point (an Image Texture into Emission Color:
    /// `emission` is then the strength, and the image the colour).
    pub emission_texture: Option<u32>,
    /// Colours of the metal and glass lobes when they differ from the base colour (a Mix
    /// Shader of Diffuse and Glossy, say); None = the base colour (Principled).
    pub metal_color: Option<[f32; 3]>,
    pub glass_color: Option<[f32; 3]>,
    /// Colour of the glass lobe's reflection when it differs from the glass colour: Blender's
    /// Glass BSDF tints both, the Principled BSDF only its transmission (its reflection takes
    /// the Specular Tint, white by default: the exporter writes (1, 1, 1)). None = the glass
    /// colour.
    pub glass_reflection_tint: Option<[f32; 3]>,
    /// The glass lobe transmits the square root of its colour at each interface, so that
    /// light entering and leaving takes the colour once (the Principled BSDF); false: the
    /// colour itself (the Glass BSDF).
    pub glass_sqrt_tint: bool,
    /// Roughness of the metal and glass lobes when it differs from `roughness` (which then is
    /// the specular layer's): a Mix Shader of a rough Glossy and a smooth Glass, say.
    pub metal_roughness: Option<f32>,
    pub glass_roughness: Option<f32>,
    /// The metal and glass lobes compensate the energy single scattering loses (Blender's
    /// Multiscatter GGX, its default distribution).
    pub multiscatter: bool,
    /// The Principled BSDF's coat: weight (0 = none), roughness, IOR and tint (Cycles'
    /// layering: `bsdf/coat.rs`).
    pub coat: f32,
    pub coat_roughness: f32,
    pub coat_ior: f32,
    pub coat_tint: [f32; 3],
    /// Specular Tint of the dielectric layer over the diffuse base (Principled; white:
    /// untinted): its F0 becomes F0·tint, as in Cycles.
    pub specular_tint: [f32; 3],
    /// The metal lobe's reflectance is its colour at every angle, as Blender's Glossy BSDF
    /// (false: Schlick's Fresnel from it, as the Principled BSDF's metal).
    pub metal_constant_fresnel: bool,
    /// Share of diffuse transmission (Translucent BSDF) among the BSDF's lobes, and its colour
    /// when not the base colour.
    pub translucency: f32,
    pub translucent_color: Option<[f32; 3]>,
    /// Probability τ of passing straight through the surface (Blender's Transparent BSDF, or
    /// Principled alpha = 1 − τ as coverage); the other lobes share 1 − τ.
    pub transparency: f32,
    /// Tint of the light that passes through (white for alpha).
    pub transparent_color: [f32; 3],
    /// The material's Pass Index (Blender's IndexMA pass).
    pub pass_index: u32,
    /// A Holdout shader: where the camera sees the surface the film is transparent and
    /// black (as `MeshDesc::holdout`); to every other ray it is black, as its parameters
    /// should say (the exporter writes a black surface).
    pub holdout: bool,
    /// A second material this one blends into by the luminance f of `blend_texture` at each
    /// point (a Mix Shader whose factor is a texture): the BSDF there is (1 − f)·this + f·that,
    /// lobe by lobe (`bsdf/blend.rs`), and the emission is (1 − f)·this + f·that. The blend's
    /// own normal and bump maps and pass index are not read (this material's are); it may not
    /// blend further.
    pub blend: Option<Box<MaterialDesc>>,
    pub blend_texture: Option<u32>,
    /// The blend's factor from the ray that arrives instead (a Fresnel, Layer Weight or
    /// Light Path › Is Shadow Ray node into the Mix Shader's factor: `RayFactor`); one of it
    /// and `blend_texture` goes with `blend`. Such a blend's emission is this material's alone.
    pub blend_ray: Option<RayFactor>,
    /// The colour and value nodes between that ray factor and the Mix Shader (a Color Ramp
    /// on Layer Weight › Facing, say) as a table of the factor over the node's output at
    /// evenly spaced values on [0, 1], interpolated linearly; empty: the output itself.
    pub blend_ray_curve: Vec<f32>,
    /// The medium inside the mesh (its Volume output; `None`: none). A material with a
    /// volume and a clear Transparent surface is a bare boundary (Cycles' rule for a Volume
    /// output without Surface); with another surface (glass), the medium fills what it holds.
    pub volume: Option<VolumeDesc>,
    /// Subsurface scattering of the diffuse base (Principled Subsurface; `None`: none).
    pub subsurface: Option<SubsurfaceDesc>,
}

/// Principled BSDF's subsurface layer (`crate::medium::subsurface`): the share of the diffuse
/// base that scatters beneath the surface, walking through an interior whose mean free path
/// per channel is `radius` (Subsurface Radius × Subsurface Scale, world units) and whose
/// albedo is the base colour.
#[derive(Clone, Debug, PartialEq)]
pub struct SubsurfaceDesc {
    /// Subsurface Weight in [0, 1].
    pub weight: f32,
    pub radius: [f32; 3],
    /// Subsurface Anisotropy g.
    pub anisotropy: f32,
    /// Subsurface IOR (the Skin method's).
    pub ior: f32,
    /// "random_walk" (Blender 5.3's Random Walk), "legacy" (Blender 4.x–5.2's Random Walk,
    /// 5.3's Random Walk (Legacy)) or "skin" (Random Walk (Skin)).
    pub method: String,
}

/// A homogeneous medium (`crate::medium`): coefficients per unit world distance, as
/// Cycles' volume closures take them (Principled Volume: scattering = Color × Density,
/// absorption = (1 − Color)(1 − √Absorption Color) × Density; Volume Scatter: Color ×
/// Density; Volume Absorption: (1 − Color) × Density).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VolumeDesc {
    pub scattering: [f32; 3],
    pub absorption: [f32; 3],
    /// Radiance emitted per unit distance (Emission Strength × Emission Color).
    pub emission: [f32; 3],
    /// The Henyey–Greenstein mean cosine g, in (−1, 1) (also Draine's g).
    pub anisotropy: f32,
    /// The phase function (`crate::medium::Phase`): "hg" (empty: the same), "rayleigh",
    /// "draine" (`anisotropy`, `alpha`) or "mie" (`diameter`, micrometres).
    pub phase: String,
    pub alpha: f32,
    pub diameter: f32,
    /// A density field scaling `scattering` and `absorption` (then given per unit density)
    /// point by point — smoke (`crate::medium::Density`); None: homogeneous.
    pub density: Option<DensityDesc>,
}

/// A medium's density field: texture `texture` (a procedural pattern, the graph after it
/// tabulated) read at the point's Object coordinates (`world_to_object`, row-major 3×4) or
/// Generated ones (those scaled and offset per axis: `generated` = scale xyz, offset xyz).
#[derive(Clone, Debug, PartialEq)]
pub struct DensityDesc {
    pub texture: u32,
    pub world_to_object: [f32; 12],
    pub generated: [f32; 6],
}

/// A Mix Shader factor computed from the ray arriving at the shading point, as Cycles' nodes
/// compute it: from its direction (`RayFactor::at`) or its kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RayFactor {
    /// Fresnel node: the dielectric Fresnel reflectance of this IOR.
    Fresnel(f32),
    /// Layer Weight's Fresnel output: the Fresnel reflectance of IOR 1/(1 − blend).
    LayerFresnel(f32),
    /// Layer Weight's Facing output: 1 − |cos θ|^k, k remapped from the blend (0.5: k = 1).
    LayerFacing(f32),
    /// Light Path › Is Shadow Ray: 1 for the shadow rays of light sampling (what they pass
    /// through), 0 for every ray a path scatters from or is seen by.
    ShadowRay,
    /// Geometry › Backfacing: 1 where the ray arrives on the back of the surface (against its
    /// geometric normal, as Cycles' flag), 0 on its front — a two-sided card, a lamp shade.
    Backfacing,
    /// Light Path › Is Camera Ray: 1 for the camera's rays (and their continuation straight
    /// through transparent surfaces, as Cycles keeps the flag), 0 for every other ray — an
    /// emitter the camera does not see, a different look for reflections. The emission too:
    /// the camera sees the second shader's, light sampling and scattered rays the first's.
    CameraRay,
}

impl Default for MaterialDesc {
    fn default() -> Self {
        MaterialDesc {
            name: "default".into(),
            base_color: [0.8, 0.8, 0.8],
            emission: [0.0; 3],
            roughness: 0.5,
            diffuse_roughness: 0.0,
            metallic: 0.0,
            transmission: 0.0,
            ior: 1.5,
            specular_ior: 1.0,
            specular: 1.0,
            base_color_texture: None,
            roughness_texture: None,
            metallic_texture: None,
            alpha_texture: None,
            normal_texture: None,
            normal_strength: 1.0,
            bump_texture: None,
            bump_distance: 1.0,
            bump_strength: 1.0,
            vertex_color: false,
            bump_map_correction: true,
            emission_texture: None,
            metal_color: None,
            glass_color: None,
            glass_reflection_tint: None,
            glass_sqrt_tint: false,
            metal_roughness: None,
            glass_roughness: None,
            multiscatter: false,
            coat: 0.0,
            coat_roughness: 0.03,
            coat_ior: 1.5,
            coat_tint: [1.0; 3],
            specular_tint: [1.0; 3],
            metal_constant_fresnel: false,
            blend: None,
            blend_texture: None,
            blend_ray: None,
            blend_ray_curve: Vec::new(),
            volume: None,
            subsurface: None,
            translucency: 0.0,
            translucent_color: None,
            transparency: 0.0,
            transparent_color: [1.0; 3],
            pass_index: 0,
            holdout: false,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AreaShape {
    Square,
    Rectangle,
    Disk,
    Ellipse,
}

/// Lights in Blender's terms; radiometric conversion to Cycles' conventions happens in
/// scene/light.rs.
#[derive(Clone, Debug)]
pub enum LightDesc {
    /// Point light: `power` = Power [W] × colour; soft sphere of `radius` (0 = delta).
    /// `soft_falloff` is Blender's "Soft Falloff" (on by default, see scene/light.rs).
    Point {
        name: String,
        position: [f32; 3],
        radius: f32,
        power: [f32; 3],
        soft_falloff: bool,
        visible_camera: bool,
        cast_shadow: bool,
    },
    /// Spot light: a point light with a cone around `direction` (Blender: local −Z).
    Spot {
        name: String,
        position: [f32; 3],
        direction: [f32; 3],
        radius: f32,
        power: [f32; 3],
        spot_size: f32,
        spot_blend: f32,
        soft_falloff: bool,
        visible_camera: bool,
        cast_shadow: bool,
        /// The light object's matrix (row-major 4×4), when its scale is to shape the cone:
        /// as in Cycles, the cone is evaluated in the object's scaled frame, so a scale of
        /// (2, 1, 1) widens it along the object's x (an elliptical spot). None: a round cone
        /// around `direction`.
        matrix: Option<[[f32; 4]; 4]>,
    },
    /// Area light: `to_world` (row-major 4×4, may carry scale) maps the local light whose
    /// extent is size_x × size_y in the xy plane and which emits towards local −Z.
    /// `spread`: Blender's Spread, the full angle of the emission cone [rad] (π: Lambertian).
    Area {
        name: String,
        to_world: [[f32; 4]; 4],
        shape: AreaShape,
        size_x: f32,
        size_y: f32,
        power: [f32; 3],
        normalize: bool,
        spread: f32,
        visible_camera: bool,
        cast_shadow: bool,
    },
    /// Sun: `direction` points from the scene towards the sun; `irradiance` = Strength × colour
    /// [W/m²]; `angle` = angular diameter [rad] (0 = delta).
    Sun { name: String, direction: [f32; 3], irradiance: [f32; 3], angle: f32, visible_camera: bool, cast_shadow: bool },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Projection {
    Perspective,
    Orthographic,
    /// Blender's Panoramic › Equirectangular camera: longitude across the image, latitude up
    /// it, over `CameraDesc::panorama` (a 360° × 180° image by default), as Cycles maps it.
    Equirectangular,
    /// Panoramic › Fisheye Equidistant: the angle from the view axis grows with the distance
    /// from the image's centre, `CameraDesc::fisheye_fov` across the frame's width and height.
    FisheyeEquidistant,
    /// Panoramic › Fisheye Equisolid: a fisheye lens of `fisheye_lens` mm on the sensor,
    /// r = 2f·sin(θ/2), cut at `fisheye_fov`.
    FisheyeEquisolid,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SensorFit {
    Auto,
    Horizontal,
    Vertical,
}

/// Blender's camera parameters (mm for lens and sensor, scene units elsewhere).
#[derive(Clone, Debug)]
pub struct CameraDesc {
    /// Object matrix_world, row-major; scale is removed.
    pub to_world: [[f32; 4]; 4],
    pub projection: Projection,
    pub lens: f32,
    pub sensor_width: f32,
    pub sensor_height: f32,
    pub sensor_fit: SensorFit,
    pub ortho_scale: f32,
    pub shift_x: f32,
    pub shift_y: f32,
    pub clip_start: f32,
    pub clip_end: f32,
    pub resolution_x: u32,
    pub resolution_y: u32,
    pub resolution_percentage: u32,
    pub pixel_aspect_x: f32,
    pub pixel_aspect_y: f32,
    /// Depth of field: f-stop (0 = pinhole) and focus distance along the view axis.
    pub fstop: f32,
    pub focus_distance: f32,
    /// The aperture's shape, as Blender's: blades (a regular polygon of that many corners
    /// inscribed in the round aperture; below 3, round), their rotation [rad], and the
    /// anamorphic ratio (the bokeh's width divided by it).
    pub aperture_blades: u32,
    pub aperture_rotation: f32,
    pub aperture_ratio: f32,
    /// Render region (Blender's border): [x, y, width, height] in pixels of the final image,
    /// y from the top. Only that window is rendered; the image is the window's size.
    pub window: Option<[u32; 4]>,
    /// Pixel filter (pixel_filter.rs): "BLACKMAN_HARRIS" (Cycles' default) or "BOX", and its
    /// width in pixels (Cycles' default 1.5).
    pub pixel_filter: String,
    pub filter_width: f32,
    /// Film transparent (Blender's Film > Transparent): the world seen by camera rays —
    /// directly or through transparent surfaces — is left out of the image and the render
    /// has an "Alpha" layer (1 − the share of such rays, as Cycles); the world still lights
    /// the scene.
    pub film_transparent: bool,
    /// What camera rays see where they leave the scene — directly or through transparent
    /// surfaces — instead of the world (radiance; a world Mix Shader by Light Path › Is Camera
    /// Ray): composited behind the image by the share of such rays (the transparent film's
    /// alpha); the world still lights the scene. Ignored when the film is transparent.
    pub backdrop: Option<[f32; 3]>,
    /// A textured backdrop: the camera sees this environment texture (times `backdrop`, its
    /// strength, required with it) where its rays leave the scene, turned by
    /// `backdrop_rotation` (rows: world direction → the texture's frame), as the world's.
    pub backdrop_texture: Option<u32>,
    pub backdrop_rotation: Option<[[f32; 3]; 3]>,
    /// An equirectangular camera's ranges (radians): latitude min, max, longitude min, max.
    pub panorama: [f32; 4],
    /// A fisheye camera's field of view (radians) and, for the equisolid one, its lens (mm).
    pub fisheye_fov: f32,
    pub fisheye_lens: f32,
}

impl Default for CameraDesc {
    fn default() -> Self {
        CameraDesc {
            to_world: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
            projection: Projection::Perspective,
            lens: 50.0,
            sensor_width: 36.0,
            sensor_height: 24.0,
            sensor_fit: SensorFit::Auto,
            ortho_scale: 7.314,
            shift_x: 0.0,
            shift_y: 0.0,
            clip_start: 0.1,
            clip_end: 1000.0,
            resolution_x: 64,
            resolution_y: 64,
            resolution_percentage: 100,
            pixel_aspect_x: 1.0,
            pixel_aspect_y: 1.0,
            fstop: 0.0,
            focus_distance: 10.0,
            aperture_blades: 0,
            aperture_rotation: 0.0,
            aperture_ratio: 1.0,
            window: None,
            pixel_filter: "BLACKMAN_HARRIS".into(),
            filter_width: 1.5,
            film_transparent: false,
            backdrop: None,
            backdrop_texture: None,
            backdrop_rotation: None,
            panorama: [
                -std::f32::consts::FRAC_PI_2,
                std::f32::consts::FRAC_PI_2,
                -std::f32::consts::PI,
                std::f32::consts::PI,
            ],
            fisheye_fov: std::f32::consts::PI,
            fisheye_lens: 10.5,
        }
    }
}

#[derive(Clone, Debug, Default)]
pub struct SceneDesc {
    pub meshes: Vec<MeshDesc>,
    pub materials: Vec<MaterialDesc>,
    pub textures: Vec<TextureDesc>,
    pub lights: Vec<LightDesc>,
    pub camera: CameraDesc,
    /// World background radiance: Color × Strength (with `world_texture`: the factor that
    /// multiplies the texture, i.e. Strength).
    pub world: [f32; 3],
    /// Equirectangular environment texture (index into `textures`) for the background.
    pub world_texture: Option<u32>,
    /// The World's Volume output: a homogeneous medium filling all space, beneath the media
    /// of meshes (Cycles' world volume; its `density` must be None). Light from lights at
    /// infinity — the sun, the world — does not cross an infinite extinguishing medium.
    pub world_volume: Option<VolumeDesc>,
    /// Rotation (row-major 3×3) from world directions to the texture's frame (Blender's
    /// Z-up equirectangular mapping); None = identity.
    pub world_rotation: Option<[[f32; 3]; 3]>,
    /// Take the general code paths even where the scene allows a shortcut (no transparency:
    /// any-hit shadow rays; single-lobe materials: that lobe alone). Off by default; the
    /// benchmark `skipbench` turns it on to measure what the shortcuts save.
    pub general_paths: bool,
    /// Rough diffuse (Oren–Nayar) as Cycles 4.5–5.2 renders it, its multiple scattering ρ³
    /// in the colour; off (the default): ρ² as OpenPBR's EON and Cycles 5.3
    /// (`bsdf/oren_nayar.rs`). The Blender add-on sets it from the Blender it runs in.
    pub oren_nayar_rho_cubed: bool,
    /// Tangent-space normal maps built on the interpolated corner normal as it is, shorter
    /// than unit inside a triangle, as Cycles up to 5.0 builds them; off (the default): on
    /// that normal normalized, as Cycles from 5.1 (`Scene::normal_mapped`). The Blender add-on
    /// sets it from the Blender it runs in.
    pub normal_map_unnormalized_base: bool,
    /// Per light of `lights`, the receiver sets it lights (`MeshDesc::light_set`; bit k: set
    /// k); empty, or missing at the end: every set.
    pub light_membership: Vec<u64>,
}

impl MeshDesc {
    /// A copy of the mesh's per-object fields (name, materials, visibility, pass index,
    /// light linking) without its vertex and corner arrays.
    pub fn clone_without_geometry(&self) -> MeshDesc {
        MeshDesc {
            name: self.name.clone(),
            material_ids: self.material_ids.clone(),
            pass_index: self.pass_index,
            camera_invisible: self.camera_invisible,
            shadow_invisible: self.shadow_invisible,
            shadow_terminator_offset: self.shadow_terminator_offset,
            holdout: self.holdout,
            light_set: self.light_set,
            light_membership: self.light_membership,
            ..Default::default()
        }
    }
}

impl LightDesc {
    /// The light's Cast Shadow (Blender's Light › Cast Shadow): off, its shadow rays reach it
    /// through every surface.
    pub fn cast_shadow(&self) -> bool {
        match self {
            LightDesc::Point { cast_shadow, .. }
            | LightDesc::Spot { cast_shadow, .. }
            | LightDesc::Area { cast_shadow, .. }
            | LightDesc::Sun { cast_shadow, .. } => *cast_shadow,
        }
    }
}
