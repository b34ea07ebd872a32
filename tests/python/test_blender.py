"""GDMLT inside Blender (bpy from PyPI, headless): the addon renders like an engine, its
export matches the core's built-in scene, its camera matches Blender's, its lights match
Cycles, and bad input reaches the user as an error instead of a crash."""

import math
import time
import sys
from pathlib import Path

import numpy as np
import pytest

import gdmlt
from conftest import ROOT, block_means, read_exr


def render_to_exr(bpy, scene, path):
    img = scene.render.image_settings
    img.file_format = "OPEN_EXR"
    img.color_depth = "32"
    img.color_mode = "RGB"
    scene.render.filepath = str(path)
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    return read_exr(path)


def test_demo_blend_matches_builtin_scene(bpy_mod, tmp_out):
    bpy = bpy_mod
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    scene = bpy.context.scene
    assert scene.render.engine == "GDMLT"
    scene.render.resolution_x = scene.render.resolution_y = 48
    s = scene.gdmlt
    assert s.method == "GDPSSMLT"  # the demo shows the product's method
    s.method, s.samples, s.seed, s.max_bounces, s.use_nee = "PT", 64, 1, 6, True
    blend = render_to_exr(bpy, scene, tmp_out / "blend.exr")
    assert blend.shape == (48, 48, 3) and np.isfinite(blend).all()
    core = gdmlt.Scene(gdmlt.builtin_scene("cornell", 48, 48))
    ref = [gdmlt.render(core, spp=64, seed=k, max_bounces=6)["layers"]["Combined"] for k in (1, 2)]
    # Blender writes its EXR top row first, like the core.
    b, r1, r2 = (block_means(x, 6) for x in (blend, ref[0], ref[1]))
    noise = np.sqrt(np.mean((r1 - r2) ** 2))  # rms block difference of two independent renders
    diff = np.sqrt(np.mean((b - r1) ** 2))
    # The same scene and seed: the export must not add a difference larger than the noise.
    assert diff < 1.5 * noise, (diff, noise)
    assert abs(b.mean() / r1.mean() - 1) < 0.01


def test_nan_vertex_reports_an_error_naming_the_object(bpy_mod, tmp_out):
    bpy = bpy_mod
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 16
    ob = bpy.data.objects["TallBlock"]
    ob.data.vertices[0].co = (math.nan, 0.0, 0.0)
    with pytest.raises(RuntimeError, match="TallBlock.*NaN"):  # and Blender survives writing the frame
        render_to_exr(bpy, scene, tmp_out / "nan.exr")


def test_unsupported_node_warns_and_falls_back(bpy_mod, tmp_out, capfd):
    bpy = bpy_mod
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 16
    scene.gdmlt.samples = 1
    mat = bpy.data.materials["Red"]
    nt = mat.node_tree
    toon = nt.nodes.new("ShaderNodeBsdfToon")
    nt.links.new(toon.outputs[0], nt.get_output_node("CYCLES").inputs["Surface"])
    img = render_to_exr(bpy, scene, tmp_out / "x.exr")
    assert np.isfinite(img).all()
    err = capfd.readouterr()
    assert "not supported" in err.out + err.err


def _camera_scene(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    cam = bpy.data.cameras.new("Cam")
    ob = bpy.data.objects.new("Cam", cam)
    scene.collection.objects.link(ob)
    scene.camera = ob
    ob.location = (1.0, -7.0, 2.5)
    ob.rotation_euler = (math.radians(75), math.radians(4), math.radians(8))
    ob.scale = (1.3, 0.7, 2.0)  # scale must not change the framing
    return scene, ob


@pytest.mark.parametrize("case", [
    dict(type="PERSP", sensor_fit="AUTO", res=(160, 90), pct=100),
    dict(type="PERSP", sensor_fit="VERTICAL", res=(90, 160), pct=50, shift=(0.2, -0.1)),
    dict(type="PERSP", sensor_fit="HORIZONTAL", res=(120, 120), pct=75, aspect=(1.0, 2.0)),
    dict(type="PERSP", sensor_fit="AUTO", res=(100, 140), pct=100, aspect=(2.0, 1.0), shift=(-0.3, 0.25)),
    dict(type="ORTHO", sensor_fit="AUTO", res=(160, 90), pct=100, shift=(0.1, 0.1)),
])
def test_camera_projection_matches_blender(bpy_mod, case):
    bpy = bpy_mod
    from gdmlt_blender import export

    scene, ob = _camera_scene(bpy)
    cam = ob.data
    cam.type = case["type"]
    cam.sensor_fit = case["sensor_fit"]
    cam.lens, cam.sensor_width, cam.sensor_height, cam.ortho_scale = 42.0, 36.0, 20.0, 6.0
    cam.shift_x, cam.shift_y = case.get("shift", (0.0, 0.0))
    r = scene.render
    r.resolution_x, r.resolution_y = case["res"]
    r.resolution_percentage = case["pct"]
    r.pixel_aspect_x, r.pixel_aspect_y = case.get("aspect", (1.0, 1.0))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    core = gdmlt.Scene({"camera": export.camera_dict(scene, ob.evaluated_get(depsgraph))})
    W = r.resolution_x * r.resolution_percentage // 100
    H = r.resolution_y * r.resolution_percentage // 100
    assert core.size == (W, H)
    P = np.array(ob.calc_matrix_camera(depsgraph, x=W, y=H, scale_x=r.pixel_aspect_x, scale_y=r.pixel_aspect_y))
    m = np.array(ob.matrix_world.normalized())
    V = np.linalg.inv(m)
    rng = np.random.default_rng(1)
    for _ in range(50):
        p = np.array([rng.uniform(-3, 5), rng.uniform(-3, 4), rng.uniform(-2, 4), 1.0])
        clip = P @ V @ p
        if clip[3] <= 0:
            continue
        ndc = clip[:3] / clip[3]
        expect = ((ndc[0] * 0.5 + 0.5) * W, (1.0 - (ndc[1] * 0.5 + 0.5)) * H)
        got = core.project(tuple(p[:3]))
        assert got is not None
        assert abs(got[0] - expect[0]) < 1e-2 and abs(got[1] - expect[1]) < 1e-2, (got, expect)


def assert_agrees_with_cycles(bpy, build, tmp_out, tag, spp=(256, 512), block=6, slack=0.005):
    """Renders `build(bpy, engine, spp, seed)` twice per renderer (seeds 1, 2). The rms block
    difference of the two-seed means must be within 2× the noise measured from the seed
    differences of both renderers, and the image means within 4σ of that noise plus `slack`
    (relative, for modelling differences). Returns the Cycles and GDMLT block means."""
    imgs = {}
    for engine, n in zip(("CYCLES", "GDMLT"), spp):
        for seed in (1, 2):
            scene = build(bpy, engine, n, seed)
            imgs[engine, seed] = block_means(render_to_exr(bpy, scene, tmp_out / f"{tag}{engine}{seed}.exr"), block)
    c = (imgs["CYCLES", 1] + imgs["CYCLES", 2]) / 2
    g = (imgs["GDMLT", 1] + imgs["GDMLT", 2]) / 2
    var = (np.mean((imgs["CYCLES", 1] - imgs["CYCLES", 2]) ** 2) + np.mean((imgs["GDMLT", 1] - imgs["GDMLT", 2]) ** 2)) / 4
    rms_diff = np.sqrt(np.mean((c - g) ** 2))
    print(f"{tag}: rms block difference {rms_diff:.4g}, noise {np.sqrt(var):.4g}, means {c.mean():.4g} vs {g.mean():.4g}")
    assert c.mean() > 1e-3
    assert rms_diff < 2.0 * np.sqrt(var) + 1e-3 * c.mean()
    assert abs(g.mean() - c.mean()) < 4 * np.sqrt(var / c.size) + slack * c.mean()
    return c, g


def _lights_scene(bpy, engine, spp, seed, size=48, bounces=4):
    """Diffuse floor, wall and block lit by an area light and a point light with radius."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene

    def diffuse(name, color):
        mat = bpy.data.materials.new(name)
        nt = mat.node_tree if mat.node_tree else None
        if nt is None:
            mat.use_nodes = True
            nt = mat.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        d = nt.nodes.new("ShaderNodeBsdfDiffuse")
        d.inputs["Color"].default_value = (*color, 1)
        nt.links.new(d.outputs[0], out.inputs["Surface"])
        return mat

    def quad(name, verts, mat):
        me = bpy.data.meshes.new(name)
        me.from_pydata(verts, [], [(0, 1, 2, 3)])
        me.materials.append(mat)
        ob = bpy.data.objects.new(name, me)
        scene.collection.objects.link(ob)

    grey, orange = diffuse("Grey", (0.7, 0.7, 0.7)), diffuse("Orange", (0.8, 0.4, 0.1))
    quad("Floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], grey)
    quad("Wall", [(-3, 2, 0), (3, 2, 0), (3, 2, 3), (-3, 2, 3)], orange)
    quad("Card", [(-0.5, 0, 0), (0.5, 0.3, 0), (0.5, 0.3, 1.2), (-0.5, 0, 1.2)], grey)

    area = bpy.data.lights.new("Area", "AREA")
    area.size, area.energy, area.shape, area.size_y = 1.0, 150.0, "RECTANGLE", 0.5
    ob = bpy.data.objects.new("Area", area)
    ob.location = (-1.0, -0.5, 2.2)
    ob.rotation_euler = (math.radians(-20), 0, 0)
    scene.collection.objects.link(ob)
    point = bpy.data.lights.new("Point", "POINT")
    point.energy, point.shadow_soft_size, point.color = 250.0, 0.2, (1.0, 0.9, 0.8)
    ob = bpy.data.objects.new("Point", point)
    ob.location = (1.3, -1.0, 1.4)
    scene.collection.objects.link(ob)

    cam = bpy.data.cameras.new("Cam")
    cam.lens = 30
    ob = bpy.data.objects.new("Cam", cam)
    ob.location = (0, -6.5, 2.2)
    ob.rotation_euler = (math.radians(75), 0, 0)
    scene.collection.objects.link(ob)
    scene.camera = ob
    world = bpy.data.worlds.new("W")
    scene.world = world
    world.color = (0, 0, 0)
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    r = scene.render
    r.resolution_x = r.resolution_y = size
    r.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    r.engine = engine
    if engine == "CYCLES":
        from gdmlt.peers import cycles_unbiased

        cycles_unbiased(scene, spp, seed, bounces)
    else:
        s = scene.gdmlt
        s.method, s.samples, s.seed, s.max_bounces, s.use_nee = "PT", spp, seed, bounces, True
    return scene


def test_area_and_point_light_agree_with_cycles(bpy_mod, tmp_out):
    """Same scene in Cycles and GDMLT, tolerance from the noise measured here."""
    assert_agrees_with_cycles(bpy_mod, _lights_scene, tmp_out, "lights")


def test_gdpt_through_blender_writes_its_passes(bpy_mod, tmp_out):
    import OpenEXR

    bpy = bpy_mod
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 24
    s = scene.gdmlt
    s.method, s.samples, s.seed, s.reconstruction = "GDPT", 16, 3, "L2"
    im = scene.render.image_settings
    im.media_type = "MULTI_LAYER_IMAGE"
    im.file_format = "OPEN_EXR_MULTILAYER"
    im.color_depth = "32"
    path = tmp_out / "ml.exr"
    scene.render.filepath = str(path)
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    with OpenEXR.File(str(path)) as f:
        parts = {p.name().split(".", 1)[1]: p for p in f.parts}
        assert {"Combined", "GD Primal", "GD Gradient X", "GD Gradient Y", "Denoising Albedo"} <= set(parts)
        primal = next(iter(parts["GD Primal"].channels.values())).pixels
        combined = next(iter(parts["Combined"].channels.values())).pixels
    core = gdmlt.Scene(gdmlt.builtin_scene("cornell", 24, 24))
    ref = gdmlt.render(core, method="gdpt", spp=16, seed=3, reconstruction="l2")["layers"]
    assert np.isfinite(primal).all() and np.isfinite(combined).all()
    # the same scene, seed and method: the passes match the core's own output
    assert abs(primal[..., :3].mean() / ref["GD Primal"].mean() - 1) < 0.01
    assert abs(combined[..., :3].mean() / ref["Combined"].mean() - 1) < 0.01


def _specular_scene(bpy, engine, spp, seed, size=40, bounces=6):
    """A mirror (Glossy, roughness 0, white) and a glass sphere (IOR 1.5) on a diffuse floor
    in front of a wall, lit by an area light."""
    scene = _lights_scene(bpy, engine, spp, seed, size=size, bounces=bounces)
    bpy.data.objects.remove(bpy.data.objects["Card"])
    bpy.data.objects["Point"].data.energy = 0.0

    def node_material(name, node_type, **inputs):
        mat = bpy.data.materials.new(name)
        nt = mat.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        n = nt.nodes.new(node_type)
        for k, v in inputs.items():
            n.inputs[k].default_value = v
        nt.links.new(n.outputs[0], out.inputs["Surface"])
        return mat

    mirror = node_material("Mirror", "ShaderNodeBsdfGlossy", Color=(1, 1, 1, 1), Roughness=0.0)
    glass = node_material("Glass", "ShaderNodeBsdfGlass", Color=(1, 1, 1, 1), Roughness=0.0, IOR=1.5)
    for name, mat, loc in (("MirrorBall", mirror, (-0.8, 0.3, 0.6)), ("GlassBall", glass, (0.8, -0.2, 0.6))):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.6, location=loc, segments=32, ring_count=16)
        ob = bpy.context.active_object
        ob.name = name
        ob.data.materials.append(mat)
    return scene


def test_mirror_and_glass_agree_with_cycles(bpy_mod, tmp_out):
    """Sharp mirror and glass against Cycles."""
    assert_agrees_with_cycles(bpy_mod, _specular_scene, tmp_out, "specular", block=5)


@pytest.mark.parametrize("method", ["PT", "GDPSSMLT"])
def test_long_render_shows_intermediate_images(bpy_mod, tmp_out, method):
    """A render that runs for a while updates the result before it ends (the first
    intermediate image comes after 1 s), then writes the final image."""
    bpy = bpy_mod
    from gdmlt_blender import engine

    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 64
    s = scene.gdmlt
    s.method, s.samples, s.time_limit = method, 100000, 2.5
    img = render_to_exr(bpy, scene, tmp_out / "long.exr")
    assert engine.last_stats["previews"] >= 1, engine.last_stats
    assert np.isfinite(img).all() and img.mean() > 0.05


def _single_light_scene(bpy, engine, spp, seed, kind):
    """The lights scene with only a spot light, a sun, or a coloured world."""
    scene = _lights_scene(bpy, engine, spp, seed, size=40, bounces=2)
    bpy.data.objects["Point"].data.energy = 0.0
    bpy.data.objects["Area"].data.energy = 0.0
    ob = None
    if kind == "spot":
        light = bpy.data.lights.new("Spot", "SPOT")
        light.energy, light.spot_size, light.spot_blend, light.shadow_soft_size = 300.0, math.radians(50), 0.3, 0.1
        ob = bpy.data.objects.new("Spot", light)
        ob.location, ob.rotation_euler = (0.3, -1.5, 2.5), (math.radians(20), 0, 0)
    elif kind == "sun":
        light = bpy.data.lights.new("Sun", "SUN")
        light.energy, light.angle = 3.0, math.radians(5)
        ob = bpy.data.objects.new("Sun", light)
        ob.rotation_euler = (math.radians(40), math.radians(20), 0)
    else:
        bg = scene.world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (0.3, 0.5, 0.8, 1)
        bg.inputs["Strength"].default_value = 1.5
    if ob is not None:
        scene.collection.objects.link(ob)
    return scene


@pytest.mark.parametrize("kind", ["spot", "sun", "world"])
def test_spot_sun_and_world_agree_with_cycles(bpy_mod, tmp_out, kind):
    def build(bpy, engine, spp, seed):
        return _single_light_scene(bpy, engine, spp // 2, seed, kind)

    assert_agrees_with_cycles(bpy_mod, build, tmp_out, kind, block=5)


def _fresh_material(bpy, ob, name):
    """A new node material with only an output node, made the object's only material:
    (node tree, output node)."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    ob.data.materials.clear()
    ob.data.materials.append(mat)
    return nt, out


def _textured_scene(bpy, engine, spp, seed):
    """The lights scene with image textures: an sRGB checker (8-bit, bilinear, repeated twice)
    into the floor's Diffuse colour and a linear (Non-Color) gradient into the wall's
    Principled Base Color, both through UV maps."""
    scene = _lights_scene(bpy, engine, spp, seed, size=40, bounces=3)

    def image(name, pixels, colorspace):
        h, w, _ = pixels.shape
        img = bpy.data.images.new(name, w, h, alpha=True)
        img.colorspace_settings.name = colorspace
        img.pixels.foreach_set(np.ascontiguousarray(pixels, dtype=np.float32).ravel())
        return img

    yy, xx = np.mgrid[0:8, 0:8]
    checker = np.where(((xx + yy) % 2 == 0)[..., None], [0.9, 0.8, 0.2, 1.0], [0.1, 0.3, 0.7, 1.0])
    ramp = np.zeros((4, 16, 4))
    ramp[..., 0] = np.linspace(0.05, 0.9, 16)
    ramp[..., 1] = 0.3
    ramp[..., 2] = np.linspace(0.9, 0.05, 16)
    ramp[..., 3] = 1
    for ob_name, img, shader, socket, scale in (
            ("Floor", image("Checker", checker, "sRGB"), "ShaderNodeBsdfDiffuse", "Color", 2.0),
            ("Wall", image("Ramp", ramp, "Non-Color"), "ShaderNodeBsdfPrincipled", "Base Color", 1.0)):
        ob = bpy.data.objects[ob_name]
        nt, out = _fresh_material(bpy, ob, ob_name + "Tex")
        bsdf = nt.nodes.new(shader)
        if shader == "ShaderNodeBsdfPrincipled":
            bsdf.inputs["Roughness"].default_value = 1.0
            bsdf.inputs["IOR"].default_value = 1.0  # no specular layer: GDMLT's Principled has none yet
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = img
        nt.links.new(tex.outputs["Color"], bsdf.inputs[socket])
        nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
        uv = ob.data.uv_layers.new(name="UVMap")
        for loop, (u, v) in zip(uv.uv, [(0, 0), (1, 0), (1, 1), (0, 1)]):
            loop.vector = (u * scale, v * scale)
    return scene


def test_image_textures_agree_with_cycles(bpy_mod, tmp_out):
    """sRGB decoding (after interpolation, as Cycles does for 8-bit images: decoding first
    renders this checker 40% brighter), Non-Color data, bilinear lookup, Repeat and UV maps."""
    c, g = assert_agrees_with_cycles(bpy_mod, _textured_scene, tmp_out, "textures", block=5)
    # the checker must actually show: block means vary strongly across the floor
    assert c[-2:].std() > 0.1 * c[-2:].mean()


def _hdri_scene(bpy, engine, spp, seed):
    """The lights scene lit only by an HDRI world (one of the CC0 studio lights bpy ships,
    1024×512 EXR) through an Environment Texture node, strength 0.8."""
    scene = _lights_scene(bpy, engine, spp, seed, size=40, bounces=2)
    bpy.data.objects["Point"].data.energy = 0.0
    bpy.data.objects["Area"].data.energy = 0.0
    hdri = Path(bpy.utils.system_resource("DATAFILES")) / "studiolights" / "world" / "forest.exr"
    nt = scene.world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(hdri))
    bg = nt.nodes["Background"]
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 0.8
    return scene


def test_hdri_world_agrees_with_cycles(bpy_mod, tmp_out):
    """Equirectangular mapping (axes as Cycles), linear EXR data, importance sampling + MIS."""
    assert_agrees_with_cycles(bpy_mod, _hdri_scene, tmp_out, "hdri", block=5)


def test_animation_renders_every_frame(bpy_mod, tmp_out):
    """`blender -b file -a` (here bpy.ops.render.render(animation=True)): every frame is
    rendered with the scene of that frame — an animated light moves the lit spot."""
    bpy = bpy_mod
    scene = _lights_scene(bpy, "GDMLT", 8, 1, size=24, bounces=1)
    bpy.data.objects["Area"].data.energy = 0.0
    point = bpy.data.objects["Point"]
    for frame, x in ((1, -2.0), (3, 2.0)):
        point.location.x = x
        point.keyframe_insert("location", index=0, frame=frame)
    scene.frame_start, scene.frame_end = 1, 3
    img = scene.render.image_settings
    img.file_format, img.color_depth, img.color_mode = "OPEN_EXR", "32", "RGB"
    scene.render.filepath = str(tmp_out / "anim_")
    scene.render.use_file_extension = True
    bpy.ops.render.render(animation=True)
    frames = [read_exr(tmp_out / f"anim_{f:04d}.exr") for f in (1, 2, 3)]
    # the light sweeps left to right: the brighter half of the image moves with it
    balance = [f[:, : f.shape[1] // 2].mean() - f[:, f.shape[1] // 2:].mean() for f in frames]
    assert balance[0] > 0.01 and balance[2] < -0.01 and abs(balance[1]) < abs(balance[0]), balance


@pytest.mark.parametrize("kind", ["lights", "hdri"])
def test_blender_usd_export_renders_the_same_outside_blender(bpy_mod, tmp_out, kind):
    """F12 in Blender and `gdmlt render` of the same scene exported with Blender's USD exporter
    (read by usd-core, no Blender) agree: area and point lights with Blender's power
    conventions, cameras, meshes, materials, and an HDRI dome. Tolerance from the spread of
    two seeds, as in the Cycles comparisons."""
    from gdmlt import usd

    bpy = bpy_mod
    imgs = {}
    for seed in (1, 2):
        if kind == "lights":
            scene = _lights_scene(bpy, "GDMLT", 64, seed, size=32)
        else:
            scene = _hdri_scene(bpy, "GDMLT", 64, seed)
            # (Blender 5.0's exporter writes the dome's intensity as 1 whatever the strength)
            scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
        imgs["blender", seed] = block_means(render_to_exr(bpy, scene, tmp_out / f"usd{kind}{seed}.exr"), 4)
        path = tmp_out / f"{kind}{seed}" / "scene.usdc"
        bpy.ops.wm.usd_export(filepath=str(path))
        r = scene.render
        desc, warnings = usd.load(path, width=r.resolution_x, height=r.resolution_y)
        assert warnings == [], warnings
        s = scene.gdmlt
        res = gdmlt.render(gdmlt.Scene(desc), method="pt", spp=64, seed=seed + 10, max_bounces=s.max_bounces)
        imgs["usd", seed] = block_means(res["layers"]["Combined"], 4)
    b = (imgs["blender", 1] + imgs["blender", 2]) / 2
    u = (imgs["usd", 1] + imgs["usd", 2]) / 2
    var = (np.mean((imgs["blender", 1] - imgs["blender", 2]) ** 2) + np.mean((imgs["usd", 1] - imgs["usd", 2]) ** 2)) / 4
    rms = np.sqrt(np.mean((b - u) ** 2))
    assert b.mean() > 1e-3 and rms < 2.0 * np.sqrt(var) + 1e-3 * b.mean(), (rms, np.sqrt(var))
    assert abs(b.mean() - u.mean()) < 4 * np.sqrt(var / b.size) + 0.002 * b.mean()


def _mixed_scene(bpy, engine, spp, seed):
    """The lights scene with shader trees: the card is Mix(Diffuse, Glossy) (a "plastic"), the
    wall Mix(Principled metal, Diffuse), the floor Add(Diffuse, Emission). GGX distributions
    set to single scattering, as GDMLT's."""
    scene = _lights_scene(bpy, engine, spp, seed, size=40, bounces=3)

    def tree(ob_name, build):
        nt, out = _fresh_material(bpy, bpy.data.objects[ob_name], ob_name + "Mix")
        nt.links.new(build(nt).outputs[0], out.inputs["Surface"])

    def diffuse(nt, color):
        n = nt.nodes.new("ShaderNodeBsdfDiffuse")
        n.inputs["Color"].default_value = (*color, 1)
        return n

    def mix(nt, fac, a, b, kind="ShaderNodeMixShader"):
        m = nt.nodes.new(kind)
        if kind == "ShaderNodeMixShader":
            m.inputs["Fac"].default_value = fac
            nt.links.new(a.outputs[0], m.inputs[1])
            nt.links.new(b.outputs[0], m.inputs[2])
        else:
            nt.links.new(a.outputs[0], m.inputs[0])
            nt.links.new(b.outputs[0], m.inputs[1])
        return m

    def plastic(nt):
        g = nt.nodes.new("ShaderNodeBsdfGlossy")
        g.distribution = "GGX"
        g.inputs["Color"].default_value = (1, 1, 1, 1)
        g.inputs["Roughness"].default_value = 0.3
        return mix(nt, 0.4, diffuse(nt, (0.8, 0.4, 0.1)), g)

    def metal_and_paint(nt):
        p = nt.nodes.new("ShaderNodeBsdfPrincipled")
        p.distribution = "GGX"
        p.inputs["Base Color"].default_value = (0.9, 0.7, 0.3, 1)
        p.inputs["Metallic"].default_value = 1.0
        p.inputs["Roughness"].default_value = 0.4
        return mix(nt, 0.5, p, diffuse(nt, (0.2, 0.5, 0.7)))

    def glowing_floor(nt):
        e = nt.nodes.new("ShaderNodeEmission")
        e.inputs["Color"].default_value = (0.2, 0.4, 1.0, 1)
        e.inputs["Strength"].default_value = 0.3
        return mix(nt, 0, diffuse(nt, (0.6, 0.6, 0.6)), e, kind="ShaderNodeAddShader")

    tree("Card", plastic)
    tree("Wall", metal_and_paint)
    tree("Floor", glowing_floor)
    return scene


def test_mix_and_add_shaders_agree_with_cycles(bpy_mod, tmp_out):
    """Mix Shader of Diffuse and Glossy, of a metallic Principled and Diffuse, and Add Shader
    of Diffuse and Emission, flattened into one weighted set of lobes."""
    assert_agrees_with_cycles(bpy_mod, _mixed_scene, tmp_out, "mix", block=5)


def test_gdmlt_export_carries_the_scene_and_its_settings_to_usd(bpy_mod, tmp_out):
    """`gdmlt export demo.blend -o x.usdc` (Blender's USD exporter, Emission materials made
    exportable, GDMLT settings and image size stored in the stage) and then `gdmlt render
    x.usdc` with no options renders what `gdmlt render demo.blend` renders."""
    import subprocess

    def cli(*args):
        r = subprocess.run([sys.executable, "-m", "gdmlt.cli", *args], capture_output=True, text=True, cwd=ROOT)
        assert r.returncode == 0, r.stdout + r.stderr
        return r.stdout

    bpy = bpy_mod
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    s = bpy.context.scene
    s.gdmlt.method, s.gdmlt.samples, s.gdmlt.seed = "PT", 16, 3
    s.render.resolution_x = s.render.resolution_y = 48
    blend = tmp_out / "demo.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    cli("export", str(blend), "-o", str(tmp_out / "demo.usdc"))
    from gdmlt.usd import stored_settings
    stored = stored_settings(tmp_out / "demo.usdc")
    assert stored["method"] == "pt" and stored["spp"] == 16 and stored["width"] == 48
    cli("render", str(tmp_out / "demo.usdc"), "-o", str(tmp_out / "from_usd.exr"))
    cli("render", str(blend), "-o", str(tmp_out / "from_blend.exr"))
    a, b = read_exr(tmp_out / "from_usd.exr"), read_exr(tmp_out / "from_blend.exr")
    assert a.shape == b.shape == (48, 48, 3)
    ba, bb = block_means(a, 8), block_means(b, 8)
    assert abs(a.mean() / b.mean() - 1) < 0.02
    assert np.sqrt(np.mean((ba - bb) ** 2)) < 0.05 * bb.mean()


def _rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def test_fifty_f12_renders_in_one_blender_do_not_grow_memory(bpy_mod, tmp_out):
    """Issue 5: an artist renders again and again in one Blender session: every method, through
    the engine (export, core, passes into the render result), must not leak."""
    bpy = bpy_mod
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 24
    scene.gdmlt.samples, scene.gdmlt.max_bounces = 4, 3
    methods = ["PT", "GDPT", "PSSMLT", "GDPSSMLT"]
    for i in range(8):  # warm up allocators and Blender's own caches
        scene.gdmlt.method = methods[i % 4]
        bpy.ops.render.render()
    before = _rss_mb()
    for i in range(50):
        scene.gdmlt.method, scene.gdmlt.seed = methods[i % 4], i
        bpy.ops.render.render()
    grown = _rss_mb() - before
    print(f"RSS {before:.0f} MB, grew {grown:.1f} MB over 50 renders")
    assert grown < 40, f"RSS grew by {grown:.1f} MB over 50 renders"


@pytest.mark.parametrize("method", ["PT", "GDPSSMLT"])
def test_esc_at_any_moment_stops_the_render_cleanly(bpy_mod, tmp_out, monkeypatch, method):
    """Esc in Blender turns RenderEngine.test_break() true; the engine polls it through
    esc_pressed() (test_break itself is Blender's C method and cannot be replaced from Python).
    Esc after k polls — k = 0: during export; later: during rendering — must end the render
    quickly, without an error, and leave finite pixels that Blender can write (an Esc during
    export used to crash Blender when it wrote the frame)."""
    bpy = bpy_mod
    from gdmlt_blender.engine import GDMLTRenderEngine

    polls = {"n": 0, "after": 0}

    def esc_pressed(self):
        polls["n"] += 1
        return polls["n"] > polls["after"]

    monkeypatch.setattr(GDMLTRenderEngine, "esc_pressed", esc_pressed)
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 32
    s = scene.gdmlt
    s.method, s.samples, s.time_limit = method, 100000, 0.0  # a minute of work if never stopped
    for after in (0, 1, 3, 20):
        polls.update(n=0, after=after)
        t = time.perf_counter()
        img = render_to_exr(bpy, scene, tmp_out / f"break{after}.exr")
        took = time.perf_counter() - t
        assert polls["n"] > after, polls  # it polled until Esc, and stopped then
        assert took < 5 + 0.06 * after, f"{method}: Esc after {after} polls took {took:.1f} s to stop"
        assert np.isfinite(img).all()
