"""A Blender scene from GDMLT's scene dictionary (triangle meshes with Diffuse / Emission
materials, a perspective camera, a world colour): the one builder behind
`tools/make_examples.py` (the demo .blend) and the Cycles side of the benchmarks
(gdmlt.peers). Needs bpy; materials other than diffuse-with-emission are not translated."""

import numpy as np


def material(bpy, d):
    """Diffuse of the base colour; with emission, Emission (black base) or Add(Diffuse,
    Emission) — Blender's emission is two-sided, as the core's."""
    mat = bpy.data.materials.new(d["name"])
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    emission, base = list(d.get("emission", (0, 0, 0)))[:3], list(d["base_color"])[:3]
    shader = None
    if max(base) > 0 or max(emission) <= 0:
        df = nt.nodes.new("ShaderNodeBsdfDiffuse")
        df.inputs["Color"].default_value = (*base, 1.0)
        shader = df.outputs["BSDF"]
    if max(emission) > 0:
        em = nt.nodes.new("ShaderNodeEmission")
        strength = max(emission)
        em.inputs["Color"].default_value = (*[c / strength for c in emission], 1.0)
        em.inputs["Strength"].default_value = strength
        if shader is None:
            shader = em.outputs["Emission"]
        else:
            add = nt.nodes.new("ShaderNodeAddShader")
            nt.links.new(shader, add.inputs[0])
            nt.links.new(em.outputs["Emission"], add.inputs[1])
            shader = add.outputs["Shader"]
    nt.links.new(shader, out.inputs["Surface"])
    return mat


def mesh_object(bpy, scene, name, positions, indices, material_ids, materials):
    me = bpy.data.meshes.new(name)
    me.from_pydata(np.asarray(positions, np.float64).tolist(), [], np.asarray(indices, np.int64).tolist())
    material_ids = np.asarray(material_ids, np.int64).reshape(-1)
    used = sorted(set(material_ids.tolist()))
    for m in used:
        me.materials.append(materials[m])
    slot = {m: i for i, m in enumerate(used)}
    me.polygons.foreach_set("material_index", np.array([slot[int(m)] for m in material_ids], np.int32))
    me.update()
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    return ob


def build(bpy, desc):
    """A new Blender scene (factory settings, nothing else) holding `desc`."""
    import mathutils

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    mats = [material(bpy, m) for m in desc["materials"]]
    for m in desc["meshes"]:
        ids = m.get("material_ids")
        mesh_object(bpy, scene, m["name"], m["positions"], m["indices"],
                    np.zeros(len(m["indices"]), np.int64) if ids is None else ids, mats)
    c = desc["camera"]
    cam = bpy.data.cameras.new("Camera")
    cam.lens = c["lens"]
    cam.sensor_width = c["sensor_width"]
    cam.sensor_height = c.get("sensor_height", 24.0)
    cam.sensor_fit = c.get("sensor_fit", "AUTO")
    cam.clip_start, cam.clip_end = c["clip_start"], c["clip_end"]
    cam_ob = bpy.data.objects.new("Camera", cam)
    cam_ob.matrix_world = mathutils.Matrix(np.asarray(c["matrix"], np.float64).tolist())
    scene.collection.objects.link(cam_ob)
    scene.camera = cam_ob
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (*list(desc.get("world", (0, 0, 0)))[:3], 1)
    scene.world = world
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = c["resolution_x"], c["resolution_y"], 100
    scene.view_settings.view_transform = "Standard"
    return scene
