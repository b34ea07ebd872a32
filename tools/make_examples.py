"""Writes examples/cornell.blend from the core's built-in Cornell box arrays, so that the
demo file and `gdmlt render cornell` are the same scene (one definition, in Rust).

Run with the project venv: .venv/bin/python tools/make_examples.py
"""

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def mesh_object(bpy, name, positions, indices, material_ids, materials):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, p)) for p in positions], [], [tuple(map(int, t)) for t in indices])
    used = sorted(set(int(m) for m in material_ids))
    for m in used:
        me.materials.append(materials[m])
    slot = {m: i for i, m in enumerate(used)}
    me.polygons.foreach_set("material_index", np.array([slot[int(m)] for m in material_ids], np.int32))
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def material(bpy, d):
    mat = bpy.data.materials.new(d["name"])
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    if max(d["emission"]) > 0:
        em = nt.nodes.new("ShaderNodeEmission")
        strength = max(d["emission"])
        em.inputs["Color"].default_value = (*[c / strength for c in d["emission"]], 1.0)
        em.inputs["Strength"].default_value = strength
        nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    else:
        df = nt.nodes.new("ShaderNodeBsdfDiffuse")
        df.inputs["Color"].default_value = (*d["base_color"], 1.0)
        nt.links.new(df.outputs["BSDF"], out.inputs["Surface"])
    return mat


def build_cornell(bpy, gdmlt, width=256, height=256):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    desc = gdmlt.builtin_scene("cornell", width, height)
    mats = [material(bpy, m) for m in desc["materials"]]
    for m in desc["meshes"]:
        mesh_object(bpy, m["name"], m["positions"], m["indices"], m["material_ids"], mats)
    c = desc["camera"]
    cam = bpy.data.cameras.new("Camera")
    cam.lens = c["lens"]
    cam.sensor_width = c["sensor_width"]
    cam.sensor_fit = "AUTO"
    cam.clip_start = c["clip_start"]
    cam.clip_end = c["clip_end"]
    cam_ob = bpy.data.objects.new("Camera", cam)
    import mathutils
    cam_ob.matrix_world = mathutils.Matrix([list(map(float, row)) for row in c["matrix"]])
    scene.collection.objects.link(cam_ob)
    scene.camera = cam_ob
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    scene.world = world
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
    scene.view_settings.view_transform = "Standard"
    return scene


def main():
    sys.path.insert(0, str(ROOT / "python"))
    from gdmlt.blend import import_bpy
    import gdmlt

    bpy = import_bpy()
    scene = build_cornell(bpy, gdmlt)
    gdmlt.enable_addon()
    scene.render.engine = "GDMLT"
    scene.gdmlt.method = "GDPSSMLT"
    scene.gdmlt.samples = 64
    scene.gdmlt.max_bounces = 8
    out = ROOT / "examples" / "cornell.blend"
    out.parent.mkdir(exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(out), compress=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
