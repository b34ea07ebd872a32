"""The viewport's Rendered shading, headless: the camera it derives from the 3D View's
matrices, which edits rebuild what, and the progressive passes. (The drawing through
Blender's gpu module needs a window; what was checked by hand is in docs/testing.md.)"""

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import gdmlt
from gdmlt.blend import settings_of
from gdmlt.outputs import with_alpha

SCENES = Path(__file__).resolve().parents[1] / "scenes"


def frustum(left, right, bottom, top, near, far, ortho=False):
    """An OpenGL projection matrix (as Blender's region window_matrix)."""
    p = np.zeros((4, 4))
    if ortho:
        p[0, 0], p[1, 1], p[2, 2] = 2 / (right - left), 2 / (top - bottom), -2 / (far - near)
        p[0, 3], p[1, 3] = -(right + left) / (right - left), -(top + bottom) / (top - bottom)
        p[2, 3], p[3, 3] = -(far + near) / (far - near), 1.0
    else:
        p[0, 0], p[1, 1] = 2 * near / (right - left), 2 * near / (top - bottom)
        p[0, 2], p[1, 2] = (right + left) / (right - left), (top + bottom) / (top - bottom)
        p[2, 2], p[2, 3], p[3, 2] = -(far + near) / (far - near), -2 * far * near / (far - near), -1.0
    return p


def _empty_scene(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "GDMLT"
    return scene


def _view_matrix():
    from mathutils import Euler, Matrix, Vector

    to_world = Matrix.Translation(Vector((1.0, -7.0, 2.5))) @ Euler(
        (math.radians(75), math.radians(4), math.radians(8))).to_matrix().to_4x4()
    return np.array(to_world.inverted())


@pytest.mark.parametrize("case", ["camera view", "free perspective", "orthographic", "orthographic behind origin"])
def test_view_camera_projects_as_the_view_matrices(bpy_mod, case):
    """Every world point lands on the pixel the region's projection × view matrix puts it on
    (what Blender draws there), for the camera view (with shift and sensor fit), a free
    off-centre perspective, and orthographic views — also for points behind the view's origin,
    which Blender's orthographic views show."""
    bpy = bpy_mod
    from gdmlt_blender import viewport

    scene = _empty_scene(bpy)
    W, H = 150, 90
    V = _view_matrix()
    if case == "camera view":
        cam = bpy.data.cameras.new("Cam")
        ob = bpy.data.objects.new("Cam", cam)
        scene.collection.objects.link(ob)
        cam.lens, cam.sensor_fit, cam.shift_x, cam.shift_y = 35.0, "VERTICAL", 0.15, -0.2
        ob.matrix_world = __import__("mathutils").Matrix(np.linalg.inv(V).tolist())
        P = np.array(ob.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=W, y=H))
    elif case == "free perspective":
        P = frustum(-0.3, 0.5, -0.2, 0.28, 0.1, 100.0)  # the region's aspect, as Blender's
    elif case == "orthographic":
        P = frustum(-3.0, 4.0, -1.5, 2.7, 0.5, 50.0, ortho=True)
    else:
        P = frustum(-3.0, 4.0, -1.5, 2.7, -20.0, 20.0, ortho=True)
    rd = SimpleNamespace(view_matrix=V.tolist(), window_matrix=P.tolist(), view_perspective="PERSP")
    core = gdmlt.Scene({"camera": viewport.view_camera(rd, W, H, scene)})
    assert core.size == (W, H)
    rng = np.random.default_rng(2)
    checked = 0
    for _ in range(60):
        p = np.array([rng.uniform(-3, 5), rng.uniform(-3, 4), rng.uniform(-2, 4), 1.0])
        if case == "orthographic behind origin":
            p[:3] = np.linalg.inv(V)[:3, 3] + rng.uniform(-1, 1, 3) - 5 * np.linalg.inv(V)[:3, 2] * rng.uniform(-1, 1)
        clip = P @ V @ p
        if clip[3] <= 0 or np.any(np.abs(clip[:3] / clip[3]) > 1):
            continue  # outside what the view shows
        ndc = clip[:3] / clip[3]
        expect = ((ndc[0] * 0.5 + 0.5) * W, (1.0 - (ndc[1] * 0.5 + 0.5)) * H)
        got = core.project(tuple(p[:3]))
        assert got is not None, (case, p)
        assert abs(got[0] - expect[0]) < 2e-2 and abs(got[1] - expect[1]) < 2e-2, (case, got, expect)
        checked += 1
    assert checked >= 10


def _session_on(bpy, name):
    from gdmlt_blender import export, viewport

    bpy.ops.wm.open_mainfile(filepath=str(SCENES / f"{name}.blend"))
    scene = bpy.context.scene
    session = viewport.ViewportSession()

    def export_now():
        return export.export_scene(bpy.context.evaluated_depsgraph_get(), need_camera=False)[0]

    cam = scene.camera
    W, H = 48, 36
    depsgraph = bpy.context.evaluated_depsgraph_get()
    P = np.array(cam.calc_matrix_camera(depsgraph, x=W, y=H))
    rd = SimpleNamespace(view_matrix=np.linalg.inv(np.array(cam.matrix_world.normalized())).tolist(),
                         window_matrix=P.tolist(), view_perspective="CAMERA")
    return scene, session, export_now, lambda: viewport.view_camera(rd, W, H, scene)


def test_each_edit_rebuilds_only_what_it_changed(bpy_mod):
    """The update logic: the first export builds everything; a selection or a camera move
    rebuilds nothing; material, light and world edits swap the shading in (and render what a
    session built afresh from the edited scene renders); moving or editing a mesh rebuilds the
    triangles."""
    bpy = bpy_mod
    from gdmlt_blender import viewport

    scene, session, export_now, camera = _session_on(bpy, "lights")
    settings = viewport.pass_settings(settings_of(scene.gdmlt), threads=2)
    assert session.update(export_now()) == "geometry"
    session.look_through(camera())
    session.step(settings)
    assert session.update(export_now()) == "none"

    mesh_ob = next(o for o in scene.objects if o.type == "MESH" and o.active_material is not None)
    mesh_ob.select_set(not mesh_ob.select_get())
    assert session.update(export_now()) == "none", "a selection must not restart the viewport"
    scene.camera.location.x += 0.1
    assert session.update(export_now()) == "none", "the camera is the view's, not the scene's"

    def node(tree, kind):
        return next(n for n in tree.nodes if n.type == kind)

    edits = [
        lambda: setattr(node(mesh_ob.active_material.node_tree, "BSDF_DIFFUSE").inputs["Color"],
                        "default_value", (0.1, 0.6, 0.2, 1.0)),
        lambda: setattr(next(o for o in scene.objects if o.type == "LIGHT").data, "energy", 321.0),
        lambda: setattr(node(scene.world.node_tree, "BACKGROUND").inputs["Strength"], "default_value", 0.37),
    ]
    for edit in edits:
        edit()
        assert session.update(export_now()) == "shading"
    # the updated core renders what a fresh one renders
    session.look_through(camera())
    while session._coarse:
        session.step(settings)
    updated = session.step(settings)
    fresh = viewport.ViewportSession()
    fresh.update(export_now())
    fresh.look_through(camera())
    fresh._coarse = []
    np.testing.assert_array_equal(updated, fresh.step(settings))

    # a normal map added to a material: its meshes' tangents are built with the triangles
    mat_tree = mesh_ob.active_material.node_tree
    normal_map, tex = mat_tree.nodes.new("ShaderNodeNormalMap"), mat_tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.new("Flat", 2, 2)
    mat_tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    mat_tree.links.new(normal_map.outputs["Normal"], node(mat_tree, "BSDF_DIFFUSE").inputs["Normal"])
    assert session.update(export_now()) == "geometry"
    mesh_ob.location.z += 0.05
    assert session.update(export_now()) == "geometry"
    mesh_ob.data.vertices[0].co.x += 0.01
    mesh_ob.data.update()
    assert session.update(export_now()) == "geometry"


def test_a_material_edit_that_makes_an_instanced_mesh_emit_rebuilds_the_scene(bpy_mod):
    """An instanced mesh whose material starts to emit cannot be swapped in as shading (the
    core places an emitting mesh as copies, each a light): the session builds the scene
    again and renders what a fresh session renders. Before, the update raised."""
    from gdmlt_blender import viewport

    desc = gdmlt.builtin_scene("cornell", 24, 24)
    camera = desc.pop("camera")
    block = next(m for m in desc["meshes"] if m["material_ids"][0] == 0 and len(m["indices"]) > 2)
    block["transforms"] = np.array([[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0],
                                    [0.5, 0, 0, 0.3, 0, 0.5, 0, 0.2, 0, 0, 0.5, 0.4]], np.float32)
    block["material_ids"] = np.full(len(block["indices"]), len(desc["materials"]), np.uint32)
    desc["materials"].append(dict(desc["materials"][0], name="Glow"))
    settings = {"max_bounces": 4, "threads": 1}
    session = viewport.ViewportSession()
    session.update(desc)
    session.look_through(camera)
    session._coarse = []
    session.step(settings)
    edited = dict(desc, materials=[*desc["materials"][:-1], dict(desc["materials"][-1], emission=[2.0, 1.0, 0.5])])
    assert session.update(edited) == "shading"
    updated = session.step(settings)
    fresh = viewport.ViewportSession()
    fresh.update(edited)
    fresh.look_through(camera)
    fresh._coarse = []
    np.testing.assert_array_equal(updated, fresh.step(settings))


def test_a_moved_instancer_places_the_instances_again_without_rebuilding_the_meshes(bpy_mod):
    """Instances moved (an instanced mesh's transforms changed, as many) are an "instances"
    change: the core places them again, keeping the meshes' BVHs, and renders what a fresh
    session renders; a moved emitting mesh (placed as copies by the core) falls back to a
    full build, and a changed instance count is a geometry change."""
    from gdmlt_blender import viewport

    desc = gdmlt.builtin_scene("cornell", 24, 24)
    camera = desc.pop("camera")
    block = next(m for m in desc["meshes"] if m["material_ids"][0] == 0 and len(m["indices"]) > 2)
    block["transforms"] = np.array([[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0],
                                    [0.5, 0, 0, 0.3, 0, 0.5, 0, 0.2, 0, 0, 0.5, 0.4]], np.float32)
    settings = {"max_bounces": 4, "threads": 1}
    session = viewport.ViewportSession()
    session.update(desc)
    session.look_through(camera)
    session._coarse = []
    before = session.step(settings)
    core = session.core

    def fresh(d):
        f = viewport.ViewportSession()
        f.update(d)
        f.look_through(camera)
        f._coarse = []
        return f.step(settings)

    moved = dict(desc, meshes=[dict(m) for m in desc["meshes"]])
    mb = next(m for m in moved["meshes"] if "transforms" in m)
    mb["transforms"] = mb["transforms"].copy()
    mb["transforms"][1, [3, 7]] = (-0.4, -0.3)
    assert session.update(moved) == "instances"
    updated = session.step(settings)
    assert session.core is core, "the core scene was updated in place, not built again"
    assert not np.array_equal(updated, before)
    np.testing.assert_array_equal(updated, fresh(moved))

    # the light placed twice (emitting: copies in the core) and moved: a full build
    lit = dict(moved, meshes=[dict(m) for m in moved["meshes"]])
    light = next(m for m in lit["meshes"] if m["name"] == "Light")
    light["transforms"] = np.array([[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]] * 2, np.float32)
    assert session.update(lit) == "geometry"
    session.step(settings)
    lit2 = dict(lit, meshes=[dict(m) for m in lit["meshes"]])
    l2 = next(m for m in lit2["meshes"] if m["name"] == "Light")
    l2["transforms"] = l2["transforms"].copy()
    l2["transforms"][1, 7] = -0.3
    core = session.core
    assert session.update(lit2) == "instances"
    np.testing.assert_array_equal(session.step(settings), fresh(lit2))
    assert session.core is not core  # (built again: the core refused the in-place update)
    one_more = dict(lit2, meshes=[dict(m) for m in lit2["meshes"]])
    ob = next(m for m in one_more["meshes"] if "transforms" in m and m["name"] != "Light")
    ob["transforms"] = np.concatenate([ob["transforms"], ob["transforms"][:1]])
    assert session.update(one_more) == "geometry"


def test_passes_average_progressively_up_to_the_viewport_samples(bpy_mod):
    """After a change: coarse passes first (at most 64, then 256 pixels across), then
    one-sample passes at the region's size whose running mean is exactly the mean of those
    renders; the limit stops them; a view change restarts from a coarse pass."""
    bpy = bpy_mod
    from gdmlt_blender import viewport

    scene, session, export_now, camera = _session_on(bpy, "lights")
    settings = viewport.pass_settings(settings_of(scene.gdmlt), threads=2)
    session.update(export_now())
    view = camera()
    view = dict(view, resolution_x=300, resolution_y=150)  # wider than 256: two coarse passes
    assert session.look_through(view) and not session.look_through(dict(view))
    shapes = [session.step(settings, seed=5).shape for _ in range(2)]
    assert shapes == [(30, 60, 4), (75, 150, 4)]  # whole divisions of 300 × 150, ≤ 64 and ≤ 256 across
    assert session.samples == 0
    view = dict(view, resolution_x=40, resolution_y=30)  # smaller than 64: no coarse pass
    session.look_through(view)
    passes = [session.step(settings, seed=5) for _ in range(4)]
    assert session.samples == 4 and session.finished(4) and not session.finished(5) and not session.finished(0)
    singles = []
    for k in range(4):
        core = gdmlt.Scene(dict(export_now(), camera=view))
        singles.append(with_alpha(gdmlt.render(core, method="pt", spp=1, seed=5 + k,
                                                             **settings)["layers"]))
    np.testing.assert_allclose(passes[-1][..., :3], np.mean(singles, axis=0)[..., :3], rtol=1e-5, atol=1e-6)
    assert np.all(passes[-1][..., 3] == 1.0)
    assert np.isfinite(passes[-1]).all() and passes[-1][..., :3].mean() > 0.0


def test_engine_draws_each_pass_through_blenders_display_shader(bpy_mod, monkeypatch):
    """The engine's glue, run with stand-ins for what needs a window (Blender's `gpu`
    module and the engine instance Blender makes): view_update exports and view_draw
    renders a pass and draws it as an RGBA float texture over the whole region, inside
    bind/unbind_display_space_shader, asking for another draw until Viewport Samples."""
    import sys

    bpy = bpy_mod
    from gdmlt_blender.engine import GDMLTRenderEngine as E

    bpy.ops.wm.open_mainfile(filepath=str(SCENES / "lights.blend"))
    scene = bpy.context.scene
    scene.gdmlt.preview_samples = 2
    drawn, calls = [], []

    class Texture:
        def __init__(self, size, format, data):
            self.size, self.format, self.data = size, format, np.asarray(data, np.float32)

    gpu = SimpleNamespace(types=SimpleNamespace(Buffer=lambda fmt, n, data: np.array(data, np.float32).ravel()[:n],
                                                GPUTexture=Texture),
                          state=SimpleNamespace(blend_set=lambda mode: calls.append(("blend", mode))))
    presets = SimpleNamespace(draw_texture_2d=lambda tex, pos, w, h: drawn.append((tex, pos, w, h)))
    monkeypatch.setitem(sys.modules, "gpu", gpu)
    monkeypatch.setitem(sys.modules, "gpu_extras.presets", presets)

    class Engine:  # Blender makes the real instance; these are the methods it calls
        view_update, view_draw, _report_viewport_error = E.view_update, E.view_draw, E._report_viewport_error
        viewport, _viewport_error, is_preview = None, None, False

        def report(self, kind, message):
            raise AssertionError(message)

        def get_preview_pixel_size(self, scene):
            return 2

        def bind_display_space_shader(self, scene):
            calls.append("bind")

        def unbind_display_space_shader(self):
            calls.append("unbind")

        def tag_redraw(self):
            calls.append("redraw")

        def update_stats(self, *a):
            pass

    cam = scene.camera
    W, H = 80, 60
    P = np.array(cam.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=W, y=H))
    context = SimpleNamespace(region=SimpleNamespace(width=W, height=H),
                              region_data=SimpleNamespace(view_matrix=np.linalg.inv(np.array(cam.matrix_world)),
                                                          window_matrix=P, view_perspective="CAMERA"))
    engine = Engine()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    engine.view_update(context, depsgraph)
    for _ in range(4):
        engine.view_draw(context, depsgraph)
    sizes = [d[0].size for d in drawn]
    assert sizes == [(40, 30), (40, 30), (40, 30), (40, 30)], sizes  # the region at Pixel Size 2 (no coarse pass)
    assert all(d[1:] == ((0, 0), W, H) for d in drawn) and all(d[0].format == "RGBA16F" for d in drawn)
    assert engine.viewport.samples == 2 and calls.count("redraw") == 1  # stops asking at Viewport Samples
    assert calls.count("bind") == calls.count("unbind") == 4
    assert drawn[-1][0].data.reshape(30, 40, 4)[..., :3].mean() > 0.0
