"""Writes the equal-time benchmark scenes of docs/benchmarks.md as .blend files, built the way
an artist builds them: Blender lights, Principled and Diffuse materials, a world colour or an
HDRI. `make bench-lights` renders each with `python -m gdmlt_bench bench --peers cycles`.

    .venv/bin/python tools/make_bench_scenes.py OUT_DIR

Scenes (128², 4 bounces, saved with engine GDMLT):
- area, point, sun, world: a ground, a Principled ball and a cube, lit by that alone
- area_point_sun, area_world, area_point_sun_world: the same lit by those together
- hall: a hall of 64 point lamps of varied power and colour and a 320-triangle emissive
  sphere (the many-lights case)
- hdri_interior: a room with a window, lit only by an HDRI sky with a sun (an Environment
  Texture of a float image written next to the .blend and packed into it)
- door_ajar: a dark room lit only through the 10 cm gap of a door left ajar onto a room lit
  by an area light (the hard-light case; 8 bounces)
- glass_box: a Cornell-style box lit by an area light under its ceiling, with a glass ball and
  a mirror ball (caustics and specular paths; 8 bounces)
- attic: a closed room filled with fog around the camera, a spot's beam through it (media)
"""

import math
import sys
from pathlib import Path

import numpy as np

LIGHT_SETS = {
    "area": ("area",),
    "point": ("point",),
    "sun": ("sun",),
    "world": ("world",),
    "area_point_sun": ("area", "point", "sun"),
    "area_world": ("area", "world"),
    "area_point_sun_world": ("area", "point", "sun", "world"),
}


def _reset(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("World")
    scene.world = world
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    return scene


def _material(bpy, name, color, kind="PRINCIPLED", roughness=0.5, emission=None):
    from make_test_scenes import empty_material

    mat, nt, out = empty_material(bpy, name)
    if emission is not None:
        n = nt.nodes.new("ShaderNodeEmission")
        n.inputs["Color"].default_value = (*color, 1)
        n.inputs["Strength"].default_value = emission
    elif kind == "DIFFUSE":
        n = nt.nodes.new("ShaderNodeBsdfDiffuse")
        n.inputs["Color"].default_value = (*color, 1)
    else:
        n = nt.nodes.new("ShaderNodeBsdfPrincipled")
        n.inputs["Base Color"].default_value = (*color, 1)
        n.inputs["Roughness"].default_value = roughness
    nt.links.new(n.outputs[0], out.inputs["Surface"])
    return mat


def _add(bpy, scene, ob, mat=None):
    if mat is not None:
        ob.data.materials.append(mat)
    return ob


def _box(bpy, scene, name, loc, size, mat, rot_z=0.0):
    """A cube scaled to `size` (scale applied) at `loc`, turned by `rot_z` about Z."""
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=loc, rotation=(0, 0, rot_z))
    ob = bpy.context.object
    ob.name = name
    ob.scale = size
    bpy.ops.object.transform_apply(scale=True)
    _add(bpy, scene, ob, mat)


def _camera(bpy, scene, location, rotation_deg, lens=35):
    cam = bpy.data.cameras.new("Camera")
    cam.lens = lens
    ob = bpy.data.objects.new("Camera", cam)
    ob.location = location
    ob.rotation_euler = tuple(math.radians(a) for a in rotation_deg)
    scene.collection.objects.link(ob)
    scene.camera = ob


def _light(bpy, scene, kind, name, location, rotation_deg=(0, 0, 0), **attrs):
    data = bpy.data.lights.new(name, kind)
    for k, v in attrs.items():
        setattr(data, k, v)
    ob = bpy.data.objects.new(name, data)
    ob.location = location
    ob.rotation_euler = tuple(math.radians(a) for a in rotation_deg)
    scene.collection.objects.link(ob)
    return ob


def _settings(scene, size=128, bounces=4):
    from make_test_scenes import gdmlt_settings  # (this folder is on sys.path when run)

    gdmlt_settings(scene, size, bounces)


def objects_scene(bpy, lights):
    """Ground, Principled ball, cube; `lights` ⊆ {area, point, sun, world}."""
    scene = _reset(bpy)
    bpy.ops.mesh.primitive_plane_add(size=20)
    _add(bpy, scene, bpy.context.object, _material(bpy, "Ground", (0.6, 0.6, 0.6), "DIFFUSE"))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(-0.7, 0.3, 0.8), segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()
    _add(bpy, scene, bpy.context.object, _material(bpy, "Ball", (0.8, 0.2, 0.15), roughness=0.35))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(1.0, -0.2, 0.5), rotation=(0, 0, math.radians(30)))
    _add(bpy, scene, bpy.context.object, _material(bpy, "Cube", (0.2, 0.4, 0.8), "DIFFUSE"))
    if "area" in lights:
        _light(bpy, scene, "AREA", "Area", (-2.0, -1.5, 3.0), (30, -25, 0), energy=300.0, size=1.0)
    if "point" in lights:
        _light(bpy, scene, "POINT", "Point", (2.0, -1.0, 2.0), energy=200.0, shadow_soft_size=0.1,
               color=(1.0, 0.85, 0.7))
    if "sun" in lights:
        _light(bpy, scene, "SUN", "Sun", (0, 0, 5), (40, 10, 60), energy=2.0, angle=math.radians(2))
    if "world" in lights:
        scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.3, 0.35, 0.45, 1)
    _camera(bpy, scene, (0.0, -6.0, 2.5), (70, 0, 0), lens=35)
    _settings(scene)
    return scene


def hall(bpy, lamps=64):
    """A hall 16 × 10 m: 64 point lamps of varied power and colour in a grid under the
    ceiling, and an emissive UV sphere of 320 triangles (16 segments × 11 rings)."""
    scene = _reset(bpy)
    rng = np.random.default_rng(7)
    grey = _material(bpy, "Walls", (0.65, 0.65, 0.65), "DIFFUSE")
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 2.5))
    ob = bpy.context.object
    ob.scale = (16, 10, 5)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.flip_normals()
    bpy.ops.object.mode_set(mode="OBJECT")
    _add(bpy, scene, ob, grey)
    for i, x in enumerate((-5.0, -1.5, 2.0, 5.5)):
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(x, 1.0 - (i % 2) * 2.0, 1.0))
        bpy.ops.object.transform_apply()
        _add(bpy, scene, bpy.context.object, _material(bpy, f"Block{i}", tuple(rng.uniform(0.2, 0.8, 3)), "DIFFUSE"))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0.0, 3.0, 1.2), segments=16, ring_count=11)
    emitter = bpy.context.object
    _add(bpy, scene, emitter, _material(bpy, "Glow", (1.0, 0.6, 0.3), emission=8.0))
    assert sum(len(p.vertices) - 2 for p in emitter.data.polygons) >= 300
    xs, ys = np.linspace(-7, 7, 8), np.linspace(-4, 4, 8)
    for i, (x, y) in enumerate((x, y) for x in xs for y in ys):
        power = float(rng.choice([0.5, 2.0, 8.0]) * rng.uniform(0.5, 1.5))
        _light(bpy, scene, "POINT", f"Lamp{i:02}", (float(x), float(y), 4.6), energy=power,
               shadow_soft_size=0.05, color=tuple(float(c) for c in rng.uniform(0.5, 1.0, 3)))
    _camera(bpy, scene, (0.0, -4.6, 2.0), (85, 0, 0), lens=20)
    _settings(scene)
    return scene


def hdri_interior(bpy, out_dir: Path):
    """A 6 × 6 × 3 m room with a 2 × 1.5 m window in one wall, lit only by an HDRI of a sky
    gradient and a small bright sun (a float image written and packed)."""
    scene = _reset(bpy)
    w, h = 256, 128
    v = (np.arange(h) + 0.5) / h          # 0 at the bottom row (Blender's pixel order)
    u = (np.arange(w) + 0.5) / w
    elev = (v - 0.5) * math.pi
    sky = np.where(elev[:, None] > 0, 4.0, 0.6) * np.ones((h, w))
    img = np.zeros((h, w, 4), np.float32)
    for c, (a, b) in enumerate([(0.35, 0.9), (0.5, 0.95), (0.8, 1.0)]):
        img[..., c] = sky * (a + (b - a) * np.clip(1 - np.sin(np.maximum(elev, 0))[:, None], 0, 1))
    # the sun: a few pixels 2000× brighter, 30° up, towards the window
    su, sv = 0.25, 0.5 + 30 / 180
    d2 = ((u[None, :] - su) * w) ** 2 + ((v[:, None] - sv) * h) ** 2
    img[..., :3] += (d2 < 4.0)[..., None] * np.array([2000.0, 1800.0, 1500.0], np.float32)
    img[..., 3] = 1
    image = bpy.data.images.new("Sky", w, h, float_buffer=True, alpha=False)
    image.pixels.foreach_set(img.ravel())
    path = out_dir / "hdri_interior_sky.exr"
    image.filepath_raw = str(path)
    image.file_format = "OPEN_EXR"
    image.save()
    image.pack()
    nt = scene.world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    walls = _material(bpy, "Plaster", (0.75, 0.72, 0.68), "DIFFUSE")
    floor = _material(bpy, "Floor", (0.45, 0.3, 0.2), roughness=0.4)

    def box(name, loc, size, mat, rot_z=0.0):
        _box(bpy, scene, name, loc, size, mat, rot_z)

    box("Floor", (0, 0, -0.05), (6, 6, 0.1), floor)
    box("Ceiling", (0, 0, 3.05), (6, 6, 0.1), walls)
    box("Back", (0, 3.05, 1.5), (6, 0.1, 3), walls)
    box("Left", (-3.05, 0, 1.5), (0.1, 6, 3), walls)
    box("Right", (3.05, 0, 1.5), (0.1, 6, 3), walls)
    # the front wall (−y) with a window 2 × 1.5 m: four pieces around the hole
    box("FrontL", (-2.0, -3.05, 1.5), (2.0, 0.1, 3), walls)
    box("FrontR", (2.0, -3.05, 1.5), (2.0, 0.1, 3), walls)
    box("FrontB", (0, -3.05, 0.375), (2.0, 0.1, 0.75), walls)
    box("FrontT", (0, -3.05, 2.625), (2.0, 0.1, 0.75), walls)
    box("Table", (0.5, 0.8, 0.4), (1.2, 0.8, 0.8), _material(bpy, "Wood", (0.5, 0.35, 0.2), roughness=0.3))
    _camera(bpy, scene, (-2.4, -2.6, 1.6), (80, 0, -40), lens=18)
    _settings(scene)
    return scene


def door_ajar(bpy):
    """Two rooms of 5 × 5 × 2.8 m and 5 × 3 m sharing a wall with a 0.9 × 2.1 m doorway. The door,
    hinged at one jamb, is turned 6.4° into the far room, which an area light under its ceiling
    lights: the camera's room gets light only through the 10 cm gap at the door's free edge.
    Diffuse plaster, a Principled floor, a table and a ball; no world light."""
    scene = _reset(bpy)
    plaster = _material(bpy, "Plaster", (0.75, 0.72, 0.68), "DIFFUSE")
    floor = _material(bpy, "Floor", (0.5, 0.35, 0.22), roughness=0.35)

    def box(name, loc, size, mat, rot_z=0.0):
        _box(bpy, scene, name, loc, size, mat, rot_z)

    # shell: x ∈ [-2.5, 2.5], y ∈ [-2.5, 5.5] (the far room beyond y = 2.5), z ∈ [0, 2.8]
    box("Floor", (0, 1.5, -0.05), (5.2, 8.2, 0.1), floor)
    box("Ceiling", (0, 1.5, 2.85), (5.2, 8.2, 0.1), plaster)
    box("WallL", (-2.55, 1.5, 1.4), (0.1, 8.2, 2.8), plaster)
    box("WallR", (2.55, 1.5, 1.4), (0.1, 8.2, 2.8), plaster)
    box("WallNear", (0, -2.55, 1.4), (5.2, 0.1, 2.8), plaster)
    box("WallFar", (0, 5.55, 1.4), (5.2, 0.1, 2.8), plaster)
    # the shared wall at y = 2.5 (10 cm thick) with the doorway x ∈ [0.5, 1.4], z ∈ [0, 2.1]
    box("WallDoorL", (-1.0, 2.55, 1.4), (3.0, 0.1, 2.8), plaster)
    box("WallDoorR", (1.95, 2.55, 1.4), (1.1, 0.1, 2.8), plaster)
    box("Lintel", (0.95, 2.55, 2.45), (0.9, 0.1, 0.7), plaster)
    # the door: 0.9 × 0.04 × 2.1, hinged at (0.5, 2.6), turned by θ with 0.9·sin θ = 0.1
    theta = math.asin(0.1 / 0.9)
    hinge = np.array([0.5, 2.6])
    centre = hinge + 0.45 * np.array([math.cos(theta), math.sin(theta)]) + 0.02 * np.array([-math.sin(theta),
                                                                                              math.cos(theta)])
    box("Door", (float(centre[0]), float(centre[1]), 1.05), (0.9, 0.04, 2.1),
        _material(bpy, "DoorPaint", (0.6, 0.55, 0.5), roughness=0.4), rot_z=theta)
    box("Table", (-0.6, 0.6, 0.375), (1.4, 0.8, 0.75), _material(bpy, "Wood", (0.45, 0.3, 0.18), roughness=0.3))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.35, location=(1.2, -0.3, 0.35), segments=32, ring_count=16)
    bpy.ops.object.shade_smooth()
    _add(bpy, scene, bpy.context.object, _material(bpy, "Ball", (0.8, 0.25, 0.15), roughness=0.4))
    _light(bpy, scene, "AREA", "Lamp", (0.5, 4.2, 2.7), energy=2000.0, size=1.2)
    _camera(bpy, scene, (-2.1, -2.2, 1.6), (82, 0, -28), lens=20)
    _settings(scene, bounces=8)
    return scene


def glass_box(bpy):
    """A 2 m box open towards the camera (white walls, red left, green right), a 0.5 m square
    area light just under the ceiling, a glass ball (Glass BSDF, IOR 1.5) and a mirror ball
    (Principled, metallic, roughness 0)."""
    scene = _reset(bpy)
    white = _material(bpy, "White", (0.73, 0.73, 0.73), "DIFFUSE")

    def box(name, loc, size, mat, rot_z=0.0):
        _box(bpy, scene, name, loc, size, mat, rot_z)

    box("Floor", (0, 0, -0.05), (2.2, 2.2, 0.1), white)
    box("Ceiling", (0, 0, 2.05), (2.2, 2.2, 0.1), white)
    box("Back", (0, 1.05, 1.0), (2.2, 0.1, 2.2), white)
    box("Left", (-1.05, 0, 1.0), (0.1, 2.2, 2.2), _material(bpy, "Red", (0.63, 0.065, 0.05), "DIFFUSE"))
    box("Right", (1.05, 0, 1.0), (0.1, 2.2, 2.2), _material(bpy, "Green", (0.14, 0.45, 0.09), "DIFFUSE"))
    from make_test_scenes import empty_material

    glass, nt, out = empty_material(bpy, "Glass")
    g = nt.nodes.new("ShaderNodeBsdfGlass")
    g.inputs["IOR"].default_value = 1.5
    g.inputs["Roughness"].default_value = 0.0
    nt.links.new(g.outputs[0], out.inputs["Surface"])
    mirror = _material(bpy, "Mirror", (0.95, 0.95, 0.95), roughness=0.0)
    mirror.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    for name, loc, mat in (("GlassBall", (0.4, -0.2, 0.35), glass), ("MirrorBall", (-0.45, 0.35, 0.35), mirror)):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.35, location=loc, segments=48, ring_count=24)
        bpy.ops.object.shade_smooth()
        bpy.context.object.name = name
        _add(bpy, scene, bpy.context.object, mat)
    _light(bpy, scene, "AREA", "Lamp", (0, 0, 1.98), energy=20.0, size=0.5)
    _camera(bpy, scene, (0, -3.4, 1.0), (90, 0, 0), lens=35)
    _settings(scene, bounces=8)
    return scene


def _glass(bpy, name, roughness=0.0, ior=1.5):
    from make_test_scenes import empty_material

    glass, nt, out = empty_material(bpy, name)
    g = nt.nodes.new("ShaderNodeBsdfGlass")
    g.inputs["IOR"].default_value = ior
    g.inputs["Roughness"].default_value = roughness
    nt.links.new(g.outputs[0], out.inputs["Surface"])
    return glass


def _room(bpy, scene, walls, floor, back=True):
    """A closed 4 × 4 × 2.6 m room around the origin (its back wall at y = 2 left to the
    caller when `back` is False): floor, ceiling and walls of 10 cm boxes."""
    for name, loc, size, mat in (("Floor", (0, 0, -0.05), (4.2, 4.2, 0.1), floor),
                                 ("Ceiling", (0, 0, 2.65), (4.2, 4.2, 0.1), walls),
                                 ("WallFront", (0, -2.05, 1.3), (4.2, 0.1, 2.6), walls),
                                 ("WallL", (-2.05, 0, 1.3), (0.1, 4.2, 2.6), walls),
                                 ("WallR", (2.05, 0, 1.3), (0.1, 4.2, 2.6), walls)):
        _box(bpy, scene, name, loc, size, mat)
    if back:
        _box(bpy, scene, "WallBack", (0, 2.05, 1.3), (4.2, 0.1, 2.6), walls)


def caustics(bpy):
    """Hard light, the caustic kind: a glass ball (IOR 1.5) and a polished metal ring on a
    wooden table in a dim 4 × 4 × 2.6 m room, lit by one small lamp (a point lamp of radius
    2 cm) 1.2 m above the table: the ball focuses the lamp into a bright spot on the table
    and the ring throws a cardioid; every caustic path runs lamp → glass or metal → table."""
    scene = _reset(bpy)
    plaster = _material(bpy, "Plaster", (0.7, 0.68, 0.65), "DIFFUSE")

    def box(name, loc, size, mat):
        _box(bpy, scene, name, loc, size, mat)

    _room(bpy, scene, plaster, plaster)
    box("Table", (0, 0.2, 0.35), (1.6, 1.0, 0.7), _material(bpy, "Wood", (0.55, 0.38, 0.22), "DIFFUSE"))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.15, location=(-0.25, 0.25, 0.85), segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()
    bpy.context.object.name = "GlassBall"
    _add(bpy, scene, bpy.context.object, _glass(bpy, "Glass"))
    metal = _material(bpy, "Polished", (0.95, 0.8, 0.5), roughness=0.02)
    metal.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    # a ring: an open cylinder (inner face seen by the lamp) 0.25 m across, 6 cm tall
    bpy.ops.mesh.primitive_cylinder_add(radius=0.125, depth=0.06, location=(0.35, 0.2, 0.73), vertices=64,
                                        end_fill_type="NOTHING")
    bpy.ops.object.shade_smooth()
    bpy.context.object.name = "Ring"
    _add(bpy, scene, bpy.context.object, metal)
    _light(bpy, scene, "POINT", "Lamp", (0.3, 1.0, 1.6), energy=60.0, shadow_soft_size=0.02)
    _camera(bpy, scene, (0.0, -1.75, 1.55), (66, 0, 0), lens=35)
    _settings(scene, size=128, bounces=12)
    return scene


def window(bpy):
    """Hard light, the window kind: a 4 × 4 × 2.6 m room whose only opening, a 1.2 × 1 m
    window, is glazed with a 6 mm pane of clear glass (IOR 1.5, a closed box); a soft sun
    (4° disc) shines through it onto the floor and a sky-blue world lights the room through
    the same pane — every path of light from outside crosses two smooth faces."""
    scene = _reset(bpy)
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.35, 0.5, 0.8, 1)
    plaster = _material(bpy, "Plaster", (0.75, 0.72, 0.68), "DIFFUSE")
    floor = _material(bpy, "Floor", (0.5, 0.35, 0.22), roughness=0.4)

    def box(name, loc, size, mat):
        _box(bpy, scene, name, loc, size, mat)

    _room(bpy, scene, plaster, floor, back=False)
    # the back wall (y = 2, 10 cm thick) with the window x ∈ [-0.6, 0.6], z ∈ [1.0, 2.0]
    box("WallBackL", (-1.35, 2.05, 1.3), (1.5, 0.1, 2.6), plaster)
    box("WallBackR", (1.35, 2.05, 1.3), (1.5, 0.1, 2.6), plaster)
    box("WallBackLow", (0, 2.05, 0.5), (1.2, 0.1, 1.0), plaster)
    box("WallBackHigh", (0, 2.05, 2.3), (1.2, 0.1, 0.6), plaster)
    box("Pane", (0, 2.05, 1.5), (1.2, 0.006, 1.0), _glass(bpy, "WindowGlass"))
    box("Table", (-0.5, 0.4, 0.375), (1.2, 0.7, 0.75), _material(bpy, "Wood", (0.45, 0.3, 0.18), roughness=0.3))
    sun = _light(bpy, scene, "SUN", "Sun", (0, 5, 5), (-50, 0, 0), energy=4.0)
    sun.data.angle = math.radians(4.0)
    _camera(bpy, scene, (1.4, -1.8, 1.5), (80, 0, 30), lens=20)
    _settings(scene, size=128, bounces=12)
    return scene


def lampshade(bpy):
    """Hard light, the shaded-bulb kind: an evening room (4 × 4 × 2.6 m, no world light) lit
    only by a bulb (a point lamp of radius 3 cm) inside an opaque cylindrical shade open at
    top and bottom on a floor lamp: the light leaves through the two openings onto the
    ceiling and the floor and reaches the rest of the room after bouncing."""
    scene = _reset(bpy)
    plaster = _material(bpy, "Plaster", (0.75, 0.72, 0.68), "DIFFUSE")
    floor = _material(bpy, "Floor", (0.5, 0.35, 0.22), roughness=0.4)

    def box(name, loc, size, mat):
        _box(bpy, scene, name, loc, size, mat)

    _room(bpy, scene, plaster, floor)
    box("Sofa", (-0.6, 1.3, 0.25), (1.8, 0.8, 0.5), _material(bpy, "Fabric", (0.3, 0.35, 0.5), "DIFFUSE"))
    box("Pole", (1.2, 1.4, 0.7), (0.03, 0.03, 1.4), _material(bpy, "Metal", (0.2, 0.2, 0.2), roughness=0.3))
    # the shade: an open cylinder (both sides opaque cloth), 40 cm across, 35 cm tall
    bpy.ops.mesh.primitive_cylinder_add(radius=0.2, depth=0.35, location=(1.2, 1.4, 1.55), vertices=48,
                                        end_fill_type="NOTHING")
    bpy.ops.object.shade_smooth()
    bpy.context.object.name = "Shade"
    _add(bpy, scene, bpy.context.object, _material(bpy, "Cloth", (0.8, 0.7, 0.55), "DIFFUSE"))
    _light(bpy, scene, "POINT", "Bulb", (1.2, 1.4, 1.55), energy=40.0, shadow_soft_size=0.03)
    _camera(bpy, scene, (-1.5, -1.8, 1.4), (85, 0, -35), lens=20)
    _settings(scene, size=128, bounces=12)
    return scene


def attic(bpy):
    """Media, the fog kind: a dusty attic (a closed 4 × 4 × 2.6 m room, no world light) filled
    with fog — a box just inside the walls whose material has only a Principled Volume
    (density 0.12, colour 0.8, anisotropy 0.3) — around the camera, lit by a spot (radius
    5 cm, 35°, soft falloff on) whose beam crosses the room onto the floor by a crate."""
    scene = _reset(bpy)
    plaster = _material(bpy, "Plaster", (0.7, 0.66, 0.6), "DIFFUSE")
    floor = _material(bpy, "Boards", (0.45, 0.32, 0.2), roughness=0.6)
    _room(bpy, scene, plaster, floor)
    _box(bpy, scene, "Crate", (0.6, 0.5, 0.3), (0.6, 0.6, 0.6), _material(bpy, "Wood", (0.5, 0.36, 0.2), "DIFFUSE"),
         rot_z=0.4)
    _box(bpy, scene, "Fog", (0, 0, 1.3), (3.96, 3.96, 2.56), _fog(bpy, "Fog", 0.12, 0.3))
    _light(bpy, scene, "SPOT", "Spot", (-1.5, 1.5, 2.4), (-40, 0, -135), energy=600.0, shadow_soft_size=0.05,
           spot_size=math.radians(35), spot_blend=0.2)
    _camera(bpy, scene, (1.2, -1.8, 1.3), (88, 0, 25), lens=20)
    _settings(scene, size=128, bounces=12)
    return scene


def _fog(bpy, name, density, anisotropy, color=(0.8, 0.8, 0.8)):
    """A material with only a Principled Volume: the mesh is the boundary of a medium."""
    from make_test_scenes import empty_material

    mat, nt, out = empty_material(bpy, name)
    vol = nt.nodes.new("ShaderNodeVolumePrincipled")
    vol.inputs["Color"].default_value = (*color, 1)
    vol.inputs["Density"].default_value = density
    vol.inputs["Anisotropy"].default_value = anisotropy
    nt.links.new(vol.outputs[0], out.inputs["Volume"])
    return mat


def main(argv):
    out = Path(argv[0] if argv else "out/bench").resolve()
    out.mkdir(parents=True, exist_ok=True)
    from gdmlt.blend import import_bpy
    import gdmlt

    bpy = import_bpy()
    gdmlt.enable_addon()
    for name, lights in LIGHT_SETS.items():
        objects_scene(bpy, lights)
        bpy.ops.wm.save_as_mainfile(filepath=str(out / f"{name}.blend"))
    hall(bpy)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "hall.blend"))
    hdri_interior(bpy, out)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "hdri_interior.blend"))
    door_ajar(bpy)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "door_ajar.blend"))
    glass_box(bpy)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "glass_box.blend"))
    attic(bpy)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "attic.blend"))
    caustics(bpy)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "caustics.blend"))
    window(bpy)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "window.blend"))
    lampshade(bpy)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "lampshade.blend"))
    print(f"wrote {len(LIGHT_SETS) + 7} scenes to {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
