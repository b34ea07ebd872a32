"""Builds the benchmark scene of the seed paper's setting — a large architectural scene lit by
one small, bright light — from the monastery courtyard that PyPI's `pybullet` ships
(`pybullet_data/samurai_monastry.obj`, 125k triangles, 81 colour materials), and saves it as
a .blend with GDMLT as its engine. Needs bpy and pybullet (`make bench-monastery` installs
both). Usage: python tools/make_monastery.py OUT.blend [--size W H]"""

import argparse
import os
import sys
import tempfile
from pathlib import Path

# camera in the courtyard looking at the north hall, lit from inside by one small sphere light
CAMERA = (12.0, -5.0, 6.0)
TARGET = (0.0, 25.0, 3.0)
LIGHT = (0.0, 25.0, 4.0)
LIGHT_RADIUS = 1.5
LIGHT_POWER_W = 20000.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--size", type=int, nargs=2, default=(320, 180), metavar=("W", "H"))
    args = ap.parse_args(argv)
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(Path(tempfile.gettempdir()) / "gdmlt-blender-user"))
    try:
        import pybullet_data
    except ImportError:
        print("make_monastery: pybullet is not installed (pip install pybullet)", file=sys.stderr)
        return 2
    import bpy
    from mathutils import Vector

    obj = Path(pybullet_data.getDataPath()) / "samurai_monastry.obj"
    if not obj.is_file():
        print(f"make_monastery: {obj} not found in the pybullet package", file=sys.stderr)
        return 2
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.obj_import(filepath=str(obj))
    scene = bpy.context.scene

    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens = 20.0
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = CAMERA
    direction = Vector(TARGET) - Vector(CAMERA)
    cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam

    light_data = bpy.data.lights.new("SmallLight", type="POINT")
    light_data.energy = LIGHT_POWER_W
    light_data.shadow_soft_size = LIGHT_RADIUS
    light = bpy.data.objects.new("SmallLight", light_data)
    light.location = LIGHT
    scene.collection.objects.link(light)

    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    scene.world = world

    scene.render.resolution_x, scene.render.resolution_y = args.size
    scene.render.resolution_percentage = 100
    args.out.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(args.out.resolve()))
    print(f"wrote {args.out} ({len(scene.objects)} objects)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
