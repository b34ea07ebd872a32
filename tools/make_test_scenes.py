"""Writes the small .blend files in tests/scenes/, one per feature group, that the tests
render through Blender's F12 path (bpy.ops.render.render with engine GDMLT), with Cycles for
comparison, and through `gdmlt render file.blend`. The files are data; this tool is their
source: change a scene here and run it again.

    .venv/bin/python tools/make_test_scenes.py

Each scene is saved with engine GDMLT (method PT, 64 samples, the bounce limit its test uses)
and its images packed into the file.
"""

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "tests" / "scenes"


def lights(bpy, size=48, bounces=4):
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
    gdmlt_settings(scene, size, bounces)
    return scene


def gdmlt_settings(scene, size, bounces):
    """What every saved test and benchmark scene renders with: GDMLT, PT, 64 samples, seed 1,
    NEE, `bounces`, a square image of `size` at 100%, the Standard view transform."""
    r = scene.render
    r.resolution_x = r.resolution_y = size
    r.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    r.engine = "GDMLT"
    s = scene.gdmlt
    s.method, s.samples, s.seed, s.max_bounces, s.use_nee = "PT", 64, 1, bounces, True


def specular(bpy, size=40, bounces=6):
    """A mirror (Glossy, roughness 0, white) and a glass sphere (IOR 1.5) on a floor of
    default Principled (IOR 1.5, roughness 0.5: a dielectric specular layer over grey) in front
    of a wall, with two Principled plastic spheres behind (smooth: IOR 1.5, roughness 0; rough:
    IOR 1.45, roughness 0.35, Specular IOR Level 0.7), lit by an area light."""
    scene = lights(bpy, size=size, bounces=bounces)
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
    floor = bpy.data.objects["Floor"]
    nt, out = fresh_material(bpy, floor, "FloorPrincipled")
    p = nt.nodes.new("ShaderNodeBsdfPrincipled")  # Blender's defaults: IOR 1.5, roughness 0.5
    p.inputs["Base Color"].default_value = (0.6, 0.6, 0.6, 1)
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    for name, color, rough, ior, level, loc in (
            ("SmoothPlastic", (0.7, 0.1, 0.1, 1), 0.0, 1.5, 0.5, (-0.5, 1.3, 0.45)),
            ("RoughPlastic", (0.1, 0.2, 0.7, 1), 0.35, 1.45, 0.7, (1.4, 1.1, 0.45))):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.45, location=loc, segments=32, ring_count=16)
        ob = bpy.context.active_object
        ob.name = name
        bpy.ops.object.shade_smooth()
        nt, out = fresh_material(bpy, ob, name)
        p = nt.nodes.new("ShaderNodeBsdfPrincipled")
        p.inputs["Base Color"].default_value = color
        p.inputs["Roughness"].default_value = rough
        p.inputs["IOR"].default_value = ior
        p.inputs["Specular IOR Level"].default_value = level
        nt.links.new(p.outputs[0], out.inputs["Surface"])
    return scene


def all_lights(bpy):
    """The lights scene with every kind of light at once: the area and point lights, a spot,
    a sun and a coloured world. Tests pick the ones they check with keep_lights()."""
    scene = lights(bpy, size=40, bounces=2)
    spot = bpy.data.lights.new("Spot", "SPOT")
    spot.energy, spot.spot_size, spot.spot_blend, spot.shadow_soft_size = 300.0, math.radians(50), 0.3, 0.1
    ob = bpy.data.objects.new("Spot", spot)
    ob.location, ob.rotation_euler = (0.3, -1.5, 2.5), (math.radians(20), 0, 0)
    scene.collection.objects.link(ob)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, math.radians(5)
    ob = bpy.data.objects.new("Sun", sun)
    ob.rotation_euler = (math.radians(40), math.radians(20), 0)
    scene.collection.objects.link(ob)
    bg = scene.world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.3, 0.5, 0.8, 1)
    bg.inputs["Strength"].default_value = 1.5
    return scene


def keep_lights(bpy, scene, keep):
    """Turns off every light of the scene not named in `keep` ("World" for the background)."""
    for ob in scene.objects:
        if ob.type == "LIGHT" and ob.name not in keep:
            ob.data.energy = 0.0
    if "World" not in keep:  # black, not strength 0: Blender's USD exporter ignores the strength
        scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    return scene


def empty_material(bpy, name):
    """A new node material holding only its output node: (material, node tree, output)."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    return mat, nt, nt.nodes.new("ShaderNodeOutputMaterial")


def fresh_material(bpy, ob, name):
    """A new node material with only an output node, made the object's only material:
    (node tree, output node)."""
    mat, nt, out = empty_material(bpy, name)
    ob.data.materials.clear()
    ob.data.materials.append(mat)
    return nt, out


def textures(bpy):
    """The lights scene with image textures: an sRGB checker (8-bit, bilinear, repeated twice)
    into the floor's Diffuse colour, a linear (Non-Color) gradient into the wall's
    Principled Base Color (tiled twice and turned 20° by a Mapping node), both through UV
    maps, a leaf card whose Principled Alpha is the image's alpha channel, a floor tile with a
    tangent-space normal map of ridges and a screen whose emission colour is an image."""
    scene = lights(bpy, size=40, bounces=3)

    def image(name, pixels, colorspace):
        h, w, _ = pixels.shape
        img = bpy.data.images.new(name, w, h, alpha=True)
        img.colorspace_settings.name = colorspace
        img.pixels.foreach_set(np.ascontiguousarray(pixels, dtype=np.float32).ravel())
        return img

    def image_node(nt, name, pixels, colorspace):
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = image(name, pixels, colorspace)
        return tex

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
        nt, out = fresh_material(bpy, ob, ob_name + "Tex")
        bsdf = nt.nodes.new(shader)
        if shader == "ShaderNodeBsdfPrincipled":
            bsdf.inputs["Roughness"].default_value = 1.0  # (and the default IOR 1.5 specular layer)
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = img
        nt.links.new(tex.outputs["Color"], bsdf.inputs[socket])
        if ob_name == "Wall":  # tiled and turned by a Mapping node on the UVs
            coords = nt.nodes.new("ShaderNodeTexCoord")
            mapping = nt.nodes.new("ShaderNodeMapping")
            mapping.inputs["Scale"].default_value = (2.0, 1.0, 1.0)
            mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(20))
            mapping.inputs["Location"].default_value = (0.1, 0.0, 0.0)
            nt.links.new(coords.outputs["UV"], mapping.inputs["Vector"])
            nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
        uv = ob.data.uv_layers.new(name="UVMap")
        for loop, (u, v) in zip(uv.uv, [(0, 0), (1, 0), (1, 1), (0, 1)]):
            loop.vector = (u * scale, v * scale)
    # a leaf card: Principled whose Alpha comes from the image's alpha channel (a disc,
    # opaque inside, half transparent on a ring, clear outside), in front of the wall and in
    # the area light's way (transparent shadows through the texture)
    yy, xx = (np.mgrid[0:32, 0:32] + 0.5) / 16.0 - 1.0
    r = np.hypot(xx, yy)
    leaf = np.zeros((32, 32, 4))
    leaf[..., :3] = [0.2, 0.7, 0.15]
    leaf[..., 3] = np.where(r < 0.6, 1.0, np.where(r < 0.9, 0.5, 0.0))
    nt, out = uv_card(bpy, scene, "Leaf", [(-1.4, -0.6, 0.1), (-0.2, -0.6, 0.1), (-0.2, -0.6, 1.3), (-1.4, -0.6, 1.3)],
                      "LeafAlpha")
    bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Roughness"].default_value = 1.0
    tex = image_node(nt, "LeafRGBA", leaf, "sRGB")
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    nt.links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    # a ridged tile on the floor: a tangent-space normal map (Non-Color) of ridges across u
    # (tilts up to ±35°), strength 1, under a Principled of roughness 0.4
    u = (np.arange(64) + 0.5) / 64.0
    tilt = 0.7 * np.sin(2 * np.pi * 4 * u)
    ridges = np.zeros((4, 64, 4))
    ridges[..., 0] = 0.5 + 0.5 * tilt / np.sqrt(1 + tilt ** 2)
    ridges[..., 1] = 0.5
    ridges[..., 2] = 0.5 + 0.5 / np.sqrt(1 + tilt ** 2)
    ridges[..., 3] = 1
    nt, out = uv_card(bpy, scene, "Tile", [(0.3, -1.6, 0.01), (1.8, -1.6, 0.01), (1.8, -0.4, 0.01), (0.3, -0.4, 0.01)],
                      "TileRidges")
    bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (0.7, 0.6, 0.5, 1)
    bsdf.inputs["Roughness"].default_value = 0.4
    nm = nt.nodes.new("ShaderNodeNormalMap")
    nm.inputs["Strength"].default_value = 1.0  # (UsdPreviewSurface cannot carry another strength)
    tex = image_node(nt, "Ridges", ridges, "Non-Color")
    nt.links.new(tex.outputs["Color"], nm.inputs["Color"])
    nt.links.new(nm.outputs["Normal"], bsdf.inputs["Normal"])
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    # a glowing screen in front of the wall: an Emission shader whose Color is an image
    # (8-bit sRGB, four coloured bars), Strength 3 — it lights the floor in its colours
    bars = np.zeros((4, 8, 4))
    bars[..., 3] = 1
    for i, c in enumerate([(1.0, 0.2, 0.1), (0.2, 1.0, 0.2), (0.1, 0.3, 1.0), (1.0, 1.0, 0.9)]):
        bars[:, 2 * i:2 * i + 2, :3] = c
    nt, out = uv_card(bpy, scene, "Screen", [(0.6, 1.9, 0.3), (1.6, 1.9, 0.3), (1.6, 1.9, 0.9), (0.6, 1.9, 0.9)],
                      "ScreenGlow")
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 3.0
    tex = image_node(nt, "ScreenBars", bars, "sRGB")
    nt.links.new(tex.outputs["Color"], em.inputs["Color"])
    nt.links.new(em.outputs[0], out.inputs["Surface"])
    return scene


def uv_card(bpy, scene, name, corners, material):
    """A quad object with a UV map from (0, 0) to (1, 1) and a new node material: (tree, output)."""
    me = bpy.data.meshes.new(name)
    me.from_pydata(corners, [], [(0, 1, 2, 3)])
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    uv = me.uv_layers.new(name="UVMap")
    for loop, (u, v) in zip(uv.uv, [(0, 0), (1, 0), (1, 1), (0, 1)]):
        loop.vector = (u, v)
    return fresh_material(bpy, ob, material)


def mix(bpy):
    """The lights scene with shader trees: the card is Mix(Diffuse, Glossy) (a "plastic"), the
    wall Mix(Principled metal, Principled paint) of different roughness, the floor Add(Diffuse,
    Emission); in front, a veil
    Mix(Transparent (orange), Diffuse) and a curtain of Principled with alpha 0.35 (coverage).
    GGX distributions set to single scattering, as GDMLT's."""
    scene = lights(bpy, size=40, bounces=3)

    def tree(ob_name, build):
        nt, out = fresh_material(bpy, bpy.data.objects[ob_name], ob_name + "Mix")
        nt.links.new(build(nt).outputs[0], out.inputs["Surface"])

    def diffuse(nt, color):
        n = nt.nodes.new("ShaderNodeBsdfDiffuse")
        n.inputs["Color"].default_value = (*color, 1)
        return n

    def mix_node(nt, fac, a, b, kind="ShaderNodeMixShader"):
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
        return mix_node(nt, 0.4, diffuse(nt, (0.8, 0.4, 0.1)), g)

    def metal_and_paint(nt):
        # rough gold (Multiscatter GGX, Blender's default) over glossy blue paint (GGX): each
        # lobe keeps its own roughness (0.6 and 0.1)
        p = nt.nodes.new("ShaderNodeBsdfPrincipled")
        p.distribution = "MULTI_GGX"
        p.inputs["Base Color"].default_value = (0.9, 0.7, 0.3, 1)
        p.inputs["Metallic"].default_value = 1.0
        p.inputs["Roughness"].default_value = 0.6
        paint = nt.nodes.new("ShaderNodeBsdfPrincipled")
        paint.distribution = "GGX"
        paint.inputs["Base Color"].default_value = (0.2, 0.5, 0.7, 1)
        paint.inputs["Roughness"].default_value = 0.1
        return mix_node(nt, 0.5, p, paint)

    def glowing_floor(nt):
        e = nt.nodes.new("ShaderNodeEmission")
        e.inputs["Color"].default_value = (0.2, 0.4, 1.0, 1)
        e.inputs["Strength"].default_value = 0.3
        return mix_node(nt, 0, diffuse(nt, (0.6, 0.6, 0.6)), e, kind="ShaderNodeAddShader")

    def veil(nt):
        t = nt.nodes.new("ShaderNodeBsdfTransparent")
        t.inputs["Color"].default_value = (1.0, 0.7, 0.4, 1)
        return mix_node(nt, 0.4, t, diffuse(nt, (0.6, 0.6, 0.6)))

    def curtain(nt):
        p = nt.nodes.new("ShaderNodeBsdfPrincipled")
        p.inputs["Base Color"].default_value = (0.2, 0.6, 0.3, 1)
        p.inputs["Roughness"].default_value = 1.0
        p.inputs["Alpha"].default_value = 0.35
        return p

    for name, x0, x1, y in (("Veil", -1.5, -0.2, -2.0), ("Curtain", 0.2, 1.5, -2.5)):
        me = bpy.data.meshes.new(name)
        me.from_pydata([(x0, y, 0), (x1, y, 0), (x1, y, 1.6), (x0, y, 1.6)], [], [(0, 1, 2, 3)])
        ob = bpy.data.objects.new(name, me)
        scene.collection.objects.link(ob)
        me.materials.append(bpy.data.materials.new(name))
    tree("Card", plastic)
    tree("Wall", metal_and_paint)
    tree("Floor", glowing_floor)
    tree("Veil", veil)
    tree("Curtain", curtain)
    return scene


SCENES = {"lights": all_lights, "specular": specular, "textures": textures, "mix": mix}


def main():
    sys.path.insert(0, str(ROOT / "python"))
    from gdmlt.blend import import_bpy
    import gdmlt

    bpy = import_bpy()
    gdmlt.enable_addon()
    OUT.mkdir(parents=True, exist_ok=True)
    for name, build in SCENES.items():
        build(bpy)
        for img in bpy.data.images:
            if img.source == "GENERATED" or not img.filepath:
                img.pack()
        path = OUT / f"{name}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True, copy=True)
        print(f"wrote {path.relative_to(ROOT)} ({path.stat().st_size // 1024} KB)")


if __name__ == "__main__":
    main()
