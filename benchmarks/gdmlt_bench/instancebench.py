"""`make bench-scale` (`python -m gdmlt_bench instancebench`): scatters as artists build
exteriors, against Cycles in the same run. A ground plane with a Geometry Nodes scatter
(Distribute Points on Faces → Instance on Points of a 5,120-triangle ico sphere, random
rotation and non-uniform scale), a sun and a sky colour, 128×96, 16 samples per pixel; the
same scene with the instances realized into one mesh. Each render runs in its own process
(F12 through bpy, as `blender -b file -f 1` does): its wall time, the time to the first
sample (GDMLT: export and scene build, from its log; Cycles: its own "Synchronizing" to
"Path Tracing" stages are not exposed, so the whole wall time is given) and its peak resident
memory (VmHWM). It measures; it does not pass or fail."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

from .membench import STATUS

_BUILD = r"""
import sys
from gdmlt.blend import import_bpy
bpy = import_bpy()
count, realize, path = int(sys.argv[1]), sys.argv[2] == "1", sys.argv[3]
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=5, radius=1.0, location=(0, 0, -50))
rock = bpy.context.active_object
rock.name, rock.hide_render = "Rock", True
bpy.ops.object.shade_smooth()
mat = bpy.data.materials.new("RockMat")
mat.use_nodes = True
mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.6, 0.45, 0.3, 1.0)
rock.data.materials.append(mat)
bpy.ops.mesh.primitive_plane_add(size=40.0)
ground = bpy.context.active_object
ng = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
n, links = ng.nodes, ng.links
gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
dist, inst, info = (n.new(t) for t in ("GeometryNodeDistributePointsOnFaces", "GeometryNodeInstanceOnPoints",
                                      "GeometryNodeObjectInfo"))
rot, scale, join = (n.new(t) for t in ("FunctionNodeRandomValue", "FunctionNodeRandomValue", "GeometryNodeJoinGeometry"))
dist.inputs["Density"].default_value = count / 1600.0
info.inputs["Object"].default_value = rock
for r, lo, hi, s in ((rot, (0, 0, 0), (6.3, 6.3, 6.3), 1), (scale, (0.1, 0.1, 0.07), (0.3, 0.25, 0.2), 2)):
    r.data_type = "FLOAT_VECTOR"
    r.inputs["Min"].default_value, r.inputs["Max"].default_value = lo, hi
    r.inputs["Seed"].default_value = s
links.new(gin.outputs[0], dist.inputs["Mesh"])
links.new(dist.outputs["Points"], inst.inputs["Points"])
links.new(info.outputs["Geometry"], inst.inputs["Instance"])
links.new(rot.outputs["Value"], inst.inputs["Rotation"])
links.new(scale.outputs["Value"], inst.inputs["Scale"])
last = inst.outputs["Instances"]
if realize:
    real = n.new("GeometryNodeRealizeInstances")
    links.new(last, real.inputs[0])
    last = real.outputs[0]
links.new(last, join.inputs[0])
links.new(gin.outputs[0], join.inputs[0])
links.new(join.outputs[0], gout.inputs[0])
ground.modifiers.new("Scatter", "NODES").node_group = ng
sun = bpy.data.lights.new("Sun", "SUN")
sun.energy, sun.angle = 3.0, 0.05
sob = bpy.data.objects.new("Sun", sun)
sob.rotation_euler = (0.6, 0.2, 0.5)
scene.collection.objects.link(sob)
world = bpy.data.worlds.new("Sky")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.3, 0.4, 0.6, 1.0)
scene.world = world
cam = bpy.data.cameras.new("Camera")
ob = bpy.data.objects.new("Camera", cam)
ob.location, ob.rotation_euler = (0.0, -24.0, 10.0), (1.2, 0.0, 0.0)
scene.collection.objects.link(ob)
scene.camera = ob
r = scene.render
r.resolution_x, r.resolution_y, r.resolution_percentage = 128, 96, 100
bpy.ops.wm.save_as_mainfile(filepath=path)
"""

_RENDER = r"""
import sys, time
t0 = time.perf_counter()
from gdmlt.blend import import_bpy
import gdmlt
bpy = import_bpy()
gdmlt.enable_addon()
engine, path, out = sys.argv[1], sys.argv[2], sys.argv[3]
bpy.ops.wm.open_mainfile(filepath=path)
scene = bpy.context.scene
scene.render.engine = engine
if engine == "CYCLES":
    c = scene.cycles
    c.device, c.samples, c.use_denoising, c.use_adaptive_sampling = "CPU", 16, False, False
else:
    g = scene.gdmlt
    g.method, g.samples, g.use_denoising, g.use_adaptive_sampling = "PT", 16, False, False
scene.render.filepath = out
t1 = time.perf_counter()
bpy.ops.render.render(write_still=True)
t2 = time.perf_counter()
""" + STATUS + r"""
print("RESULT", {"load": t1 - t0, "render": t2 - t1, "peak": status("VmHWM:")})
"""


def _child(args, timeout):
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", *args], capture_output=True, text=True, check=False, timeout=timeout)
    wall = time.perf_counter() - t
    line = next((x for x in r.stdout.splitlines() if x.startswith("RESULT")), None)
    if r.returncode != 0 or line is None:
        return {"error": (r.stderr.strip() or r.stdout.strip())[-300:], "wall": wall}
    import ast

    return dict(ast.literal_eval(line[len("RESULT "):]), wall=wall)


def run(counts=(1000, 10000, 100000), realized=(1000,), timeout=600, out=print, keep=None):
    """Renders each scatter with both renderers; `keep`: a folder to keep the images in."""
    out("# instancebench: a Geometry Nodes scatter of a 5,120-triangle ico sphere, 128x96, 16 spp, pt raw; "
        "each render in its own process (F12 through bpy); GDMLT on all cores, Cycles on all cores")
    out(f"{'scene':>26} {'renderer':>8} {'render s':>9} {'peak MB':>8}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cases = [(c, False) for c in counts] + [(c, True) for c in realized]
        for count, realize in cases:
            blend = os.path.join(tmp, f"scatter{count}{'r' if realize else ''}.blend")
            r = subprocess.run([sys.executable, "-c", _BUILD, str(count), "1" if realize else "0", blend],
                               capture_output=True, text=True)
            if r.returncode != 0:
                out(f"building the {count} scene failed: {r.stderr.strip()[-300:]}")
                continue
            name = f"{count:,} instances" + (" realized" if realize else "")
            for engine in ("CYCLES", "GDMLT"):
                image = os.path.join(keep or tmp, f"scatter{count}{'r' if realize else ''}-{engine}.png")
                res = _child([_RENDER, engine, blend, image], timeout)
                rows.append({"scene": name, "engine": engine, **res})
                if "error" in res:
                    out(f"{name:>26} {engine:>8} failed after {res['wall']:.1f} s: {res['error']}")
                else:
                    out(f"{name:>26} {engine:>8} {res['render']:9.2f} {res['peak'] / 2**20:8.0f}")
    return rows


if __name__ == "__main__":
    print(json.dumps(run()))
