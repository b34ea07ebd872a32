"""Hostile and careless input (issue 18): every case a clear message and a non-zero exit, or
a finite, correctly sized image — never a traceback, a panic or a silently wrong image. Each
case here failed before its fix (the issue's numbers in brackets)."""

import io
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import gdmlt

from conftest import ROOT, read_exr


def _cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "gdmlt.cli", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=300, **kw)


def test_a_time_limit_beyond_any_clock_renders_to_the_sample_count(tmp_path):
    """[1] --time 1e20 panicked outside the render's guard: a black frame and exit 0."""
    out = tmp_path / "t.exr"
    r = _cli("render", "cornell", "-o", str(out), "--time", "1e20", "--spp", "2", "--width", "16", "--height", "16",
             "--method", "pt", "--no-png", "--no-denoise")
    assert r.returncode == 0, r.stderr
    img = read_exr(out)
    assert img.shape == (16, 16, 3) and img.mean() > 0.01 and np.isfinite(img).all()


@pytest.mark.parametrize("args", [
    ["--width", "42949700", "--height", "16"],   # [2] wrapped to 27 pixels in u32
    ["--spp", "99999999999"],                    # [9] OverflowError traceback
    ["--seed", str(2 ** 64)],
    ["--max-bounces", str(10 ** 12)],
    ["--chains", str(10 ** 12)],
    ["--threads", "-1"],
    ["--noise-threshold", "2"],
    ["--noise-threshold", "-0.01"],
    ["--adaptive-min-samples", str(2 ** 40)],
    ["--dask-timeout", "0"],
    ["--dask-timeout", "nan"],
])
def test_out_of_range_numbers_are_usage_errors_not_tracebacks(tmp_path, args):
    r = _cli("render", "cornell", "-o", str(tmp_path / "x.exr"), *args)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and "must be" in r.stderr, r.stderr


def test_an_image_size_that_wraps_is_refused_from_the_scene_dict():
    """[2] through a stage's or a script's resolution: refused with the size asked for."""
    d = gdmlt.builtin_scene("cornell", 16, 16)
    d["camera"]["resolution_x"] = 42949700
    with pytest.raises(ValueError, match="42949700"):
        gdmlt.Scene(d)


def test_negative_light_power_is_refused_naming_the_light():
    """[5] negative pixels in pt/pssmlt and a false 'no light' warning."""
    d = gdmlt.builtin_scene("cornell", 16, 16)
    d["lights"] = [{"type": "point", "name": "Minus", "position": [0.0, 0.0, 1.0], "power": [-10.0, -10.0, -10.0]}]
    with pytest.raises(ValueError, match="Minus.*negative|negative.*Minus"):
        gdmlt.Scene(d)


@pytest.mark.parametrize("spread", [float("nan"), float("inf"), -0.1])
def test_a_broken_area_light_spread_is_refused_naming_the_light(spread):
    """A NaN, infinite or negative Spread is a ValueError naming the light (a spread of 0,
    Cycles' delta beam, is held at a hundredth of a degree; above π it is Lambertian)."""
    import numpy as np

    from gdmlt import scenedict

    d = gdmlt.builtin_scene("cornell", 16, 16)
    d["lights"] = [scenedict.area_light("Softbox", np.eye(4, dtype=np.float32), "SQUARE", 0.5, 0.5,
                                        (10.0, 10.0, 10.0), spread=spread)]
    with pytest.raises(ValueError, match="Softbox.*spread"):
        gdmlt.Scene(d)
    for fine in (0.0, 4.0):
        d["lights"][0]["spread"] = fine
        gdmlt.Scene(d)


def test_usd_stored_settings_go_through_the_cli_checks(tmp_path):
    """[9] customLayerData skipped the CLI's validation (spp 'abc', threads -1 → tracebacks)."""
    pxr = pytest.importorskip("pxr")
    from test_usd import _stage

    path = _stage(tmp_path / "s.usda")
    for bad in ({"spp": "abc"}, {"threads": -1}, {"width": "wide", "height": 8}):
        layer = pxr.Sdf.Layer.FindOrOpen(str(path))
        layer.customLayerData = {"gdmlt": bad}
        layer.Save()
        r = _cli("render", str(path), "-o", str(tmp_path / "o.exr"), "--method", "pt", "--spp", "2")
        if "spp" in bad:  # the CLI's own --spp wins, and the stored one is still checked
            pass
        assert r.returncode == 1, (bad, r.stderr)
        assert "Traceback" not in r.stderr and "customLayerData" in r.stderr, r.stderr


def test_ctrl_c_exits_130_and_keeps_the_work_under_another_name(tmp_path):
    """[8] Ctrl-C wrote the unfinished image as the requested file and exited 0 ('wrote …')."""
    out = tmp_path / "c.exr"
    p = subprocess.Popen([sys.executable, "-m", "gdmlt.cli", "render", "cornell", "-o", str(out), "--method", "pt",
                          "--spp", "1000000", "--width", "32", "--height", "32", "--no-denoise"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    time.sleep(3.0)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err, err
    assert not out.exists()
    partial = tmp_path / "c.interrupted.exr"
    assert partial.exists() and np.isfinite(read_exr(partial)).all()
    import OpenEXR

    header = OpenEXR.File(str(partial), header_only=True).header()  # its header says so too
    assert header.get("gdmlt/interrupted") == "yes" and header.get("gdmlt/method") == "pt", header


def test_an_output_folder_that_cannot_be_made_is_an_error(tmp_path):
    """[9] a read-only output parent gave a PermissionError traceback."""
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    r = _cli("render", "cornell", "-o", str(blocker / "sub" / "x.exr"), "--spp", "1")
    assert r.returncode == 1 and "Traceback" not in r.stderr and "error" in r.stderr, r.stderr


def test_an_image_larger_than_memory_is_refused_before_allocating(tmp_path):
    """[3] `ulimit -v 4000000; gdmlt render cornell --width 65536 --height 65536` aborted
    (SIGABRT); now exit 1 saying how much it needs and how much there is."""
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (4_000_000 * 1024, resource.RLIM_INFINITY))

    r = subprocess.run([sys.executable, "-m", "gdmlt.cli", "render", "cornell", "-o", str(tmp_path / "a.exr"),
                        "--width", "65536", "--height", "65536", "--spp", "1"],
                       capture_output=True, text=True, cwd=ROOT, timeout=300, preexec_fn=limit)
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    assert "memory" in r.stderr and "65536×65536" in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_export_writes_packed_textures_only_under_the_output_folder(bpy_mod, tmp_path):
    """[4] a packed image named '../../../evil.png' in an untrusted .blend was written that
    many folders above the stage by Blender's USD exporter (textures mode NEW)."""
    bpy = bpy_mod
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    img = bpy.data.images.new("../../../evil.png", 4, 4)
    img.pixels.foreach_set(np.ones(4 * 4 * 4, np.float32))
    img.pack()
    img.name = "../../../evil.png"
    mat = bpy.data.materials[0]
    nt = mat.node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    bsdf = next(n for n in nt.nodes if n.type in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE"))
    colour = bsdf.inputs.get("Base Color") or bsdf.inputs["Color"]
    nt.links.new(tex.outputs["Color"], colour)
    blend = tmp_path / "untrusted.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    stage_dir = tmp_path / "a" / "b" / "c"
    r = _cli("export", str(blend), "-o", str(stage_dir / "stage.usda"))
    assert r.returncode == 0, r.stderr[-2000:]
    escaped = [p for p in tmp_path.rglob("evil*") if stage_dir not in p.parents]
    assert not escaped, escaped
    assert list(stage_dir.rglob("evil*")), sorted(stage_dir.rglob("*"))  # the texture is still exported


def test_a_file_beside_the_output_that_gdmlt_did_not_write_is_kept(tmp_path):
    """[7] `gdmlt render scene.usda -o wood.exr` overwrote the scene's texture wood.png."""
    wood = tmp_path / "wood.png"
    from PIL import Image

    Image.new("RGB", (3, 3), (10, 20, 30)).save(wood)
    before = wood.read_bytes()
    r = _cli("render", "cornell", "-o", str(tmp_path / "wood.exr"), "--spp", "1", "--width", "8", "--height", "8")
    assert r.returncode == 0, r.stderr
    assert wood.read_bytes() == before and "not replacing" in r.stderr
    assert (tmp_path / "wood.exr").exists()
    # its own PNG it replaces: render twice into one name, the second image is written
    out = tmp_path / "mine.exr"
    for spp in ("1", "4"):
        r = _cli("render", "cornell", "-o", str(out), "--spp", spp, "--width", "8", "--height", "8",
                 "--method", "pt", "--no-denoise")
        assert r.returncode == 0 and "not replacing" not in r.stderr, r.stderr
        from gdmlt.outputs import written_by_gdmlt

        assert written_by_gdmlt(out.with_suffix(".png"))


def test_blenders_png_is_marked_as_gdmlts(tmp_path):
    from PIL import Image

    from gdmlt.outputs import mark_png, written_by_gdmlt

    p = tmp_path / "b.png"
    Image.new("RGB", (5, 4), (200, 100, 50)).save(p)
    assert not written_by_gdmlt(p)
    mark_png(p)
    assert written_by_gdmlt(p)
    im = Image.open(p)
    im.load()  # still a valid PNG (chunk CRCs checked)
    assert im.size == (5, 4) and im.getpixel((0, 0)) == (200, 100, 50) and im.info.get("Software") == "GDMLT"


def test_version_is_printed():
    r = _cli("--version")
    assert r.returncode == 0 and r.stdout.startswith("gdmlt ") and gdmlt.__version__ in r.stdout, r.stdout


def test_a_misspelt_scene_key_is_reported_not_ignored_silently():
    """[10] 'lense' in the camera dict was ignored without a word."""
    d = gdmlt.builtin_scene("cornell", 16, 16)
    assert not [w for w in gdmlt.Scene(d).warnings if "unknown key" in w]
    d["camera"]["lense"] = 85.0
    d["materials"][0]["roughnes"] = 0.2
    warnings = gdmlt.Scene(d).warnings
    assert any("camera: unknown key 'lense'" in w and "'lens'" in w for w in warnings), warnings
    assert any("unknown key 'roughnes'" in w and "'roughness'" in w for w in warnings), warnings


def test_the_known_keys_are_the_ones_the_parsers_read():
    """Issue 19.4: the keys a scene dict may have were listed by hand beside the parsers (and
    the list missed `general_paths`, which the scene parser reads: it was reported as
    unknown). The known keys are now those the parsers read — for a light, those of its type:
    a spot's cone on a point light is ignored, and said so."""
    d = gdmlt.builtin_scene("cornell", 16, 16)
    d["general_paths"] = True
    d["lights"] = [{"type": "POINT", "name": "Lamp", "position": (0.0, 0.0, 0.5), "power": (10.0, 10.0, 10.0),
                    "spot_size": 0.5}]
    warnings = [w for w in gdmlt.Scene(d).warnings if "unknown key" in w]
    assert warnings == ["light 'Lamp': unknown key 'spot_size' ignored"], warnings


def test_the_exporters_write_only_keys_the_core_reads(bpy_mod):
    """Blender's export and the USD reader produce no unknown-key warnings (the check would
    otherwise cry wolf on every render)."""
    from gdmlt.blend import scene_desc

    for name in ("lights", "textures", "mix", "specular"):
        desc, _, _ = scene_desc(str(ROOT / "tests" / "scenes" / f"{name}.blend"), (8, 8))
        assert not [w for w in gdmlt.Scene(desc).warnings if "unknown key" in w], name


def test_usd_meshes_with_short_primvars_or_bad_counts_are_messages(tmp_path):
    """[9] short normals/st arrays or negative face counts raised IndexError in usd.py."""
    pxr = pytest.importorskip("pxr")
    from test_usd import _stage

    from gdmlt import usd

    path = _stage(tmp_path / "s.usda")
    stage = pxr.Usd.Stage.Open(str(path))
    floor = pxr.UsdGeom.Mesh(stage.GetPrimAtPath("/World/Floor"))
    floor.CreateNormalsAttr([(0, 0, 1)])  # one normal for four vertices
    floor.SetNormalsInterpolation("vertex")
    pv = pxr.UsdGeom.PrimvarsAPI(floor.GetPrim()).CreatePrimvar(
        "st", pxr.Sdf.ValueTypeNames.TexCoord2fArray, pxr.UsdGeom.Tokens.faceVarying)
    pv.Set([(0, 0), (1, 0)])  # two of four corners
    stage.GetRootLayer().Save()
    desc, warnings = usd.load(path)
    assert any("normals has 1 values" in w for w in warnings), warnings
    assert any("primvar st has 2 values" in w for w in warnings), warnings
    assert gdmlt.Scene(desc) is not None
    floor.GetFaceVertexCountsAttr().Set([-4, 8])
    stage.GetRootLayer().Save()
    with pytest.raises(ValueError, match="negative faceVertexCounts"):
        usd.load(path)


def test_reconstruct_of_an_empty_image_and_a_huge_scale_are_messages():
    """[9] gdmlt.reconstruct on a 0×N array; [10] a 1e30 scale reported as 'zero-area
    triangles' (the triangles' area overflowed)."""
    z = np.zeros((0, 4, 3), np.float32)
    with pytest.raises(ValueError, match="empty"):
        gdmlt.reconstruct(z, z, z, z, 0.2, "l2")
    d = gdmlt.builtin_scene("cornell", 8, 8)
    d["meshes"][0]["positions"] = (np.asarray(d["meshes"][0]["positions"]) * 1e30).astype(np.float32)
    with pytest.raises(ValueError, match="too large for single precision"):
        gdmlt.Scene(d)


def test_a_shader_node_loop_names_the_material(bpy_mod):
    """[10] a node loop failed with 'maximum recursion depth' without the material's name.
    Blender marks a loop's closing link invalid, and Cycles renders the tree without it:
    so does GDMLT, with a warning naming the material and the link. A loop of links that
    still claim to be valid (a script can make one) is an error naming the material."""
    from gdmlt_blender import export

    bpy = bpy_mod
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    mat = bpy.data.materials[0]
    nt = mat.node_tree
    a, b = nt.nodes.new("ShaderNodeMixShader"), nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(b.outputs[0], a.inputs[1])
    nt.links.new(a.outputs[0], b.inputs[1])
    nt.links.new(a.outputs[0], nt.get_output_node("CYCLES").inputs["Surface"])
    desc, warnings = export.export_scene(bpy.context.evaluated_depsgraph_get())
    assert any(mat.name in w and "invalid" in w and "loop" in w for w in warnings), warnings
    for link in nt.links:
        link.is_valid = True
    with pytest.raises(ValueError, match=f"{mat.name}.*loop"):
        export.material_params(mat, [])


def test_the_command_line_reports_progress_with_the_time_left():
    """Issue 17: `gdmlt render` printed nothing until it ended (no progress, no ETA)."""
    from gdmlt.cli import ProgressLine

    out = io.StringIO()
    line = ProgressLine("pt", out)
    for i in range(1, 201):  # 20 s of polls every 0.1 s, progress linear in time
        assert line(i / 200, i * 0.1) is False
    lines = out.getvalue().splitlines()
    assert 9 <= len(lines) <= 12, lines  # one per 10%, not one per poll
    assert "pt 50% after 10.0 s, 10.0 s left" in out.getvalue(), lines


def test_an_unreachable_dask_scheduler_is_a_message():
    """[9] an unreachable scheduler ended in a traceback."""
    r = subprocess.run([sys.executable, "-m", "gdmlt.cli", "render", "cornell", "-o", "/tmp/gdmlt-unreachable.exr",
                        "--method", "pt", "--dask", "tcp://127.0.0.1:9", "--partials", "2", "--dask-timeout", "1"],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 1, r.stderr[-2000:]
    assert "cannot reach the Dask scheduler" in r.stderr and "within 1.0 s" in r.stderr, r.stderr[-2000:]
    assert "Traceback" not in r.stderr, r.stderr[-2000:]


def test_an_infinite_emission_strength_is_refused_naming_the_material():
    """[10] Emission Strength inf (Blender stores f32::MAX) rendered a black room with a
    'no light' warning: every path that met it overflowed and was dropped."""
    d = gdmlt.builtin_scene("cornell", 8, 8)
    light = next(m for m in d["materials"] if max(m.get("emission", (0, 0, 0))) > 0)
    light["emission"] = [3.4028234663852886e38] * 3
    with pytest.raises(ValueError, match=f"{light['name']}.*too large"):
        gdmlt.Scene(d)


def test_reconstruct_takes_an_irls_schedule_and_refuses_a_bad_one():
    """`irls` = (reweightings, CG steps, decay) replaces a method's L1 schedule (to measure
    schedules, docs/benchmarks.md): gdpssmlt's own is (10, 6, 0.5); no reweighting is the
    exact L2 solution; nonsense is a ValueError, not a hang or a panic."""
    rng = np.random.default_rng(3)
    p, dx, dy = (rng.random((12, 16, 3), dtype=np.float32) for _ in range(3))
    d = np.zeros_like(p)
    own = gdmlt.reconstruct(p, dx, dy, d, 0.2, "l1", method="gdpssmlt")
    assert np.array_equal(gdmlt.reconstruct(p, dx, dy, d, 0.2, "l1", irls=(10, 6, 0.5)), own)
    assert not np.array_equal(gdmlt.reconstruct(p, dx, dy, d, 0.2, "l1", irls=(10, 10, 0.5)), own)
    l2 = gdmlt.reconstruct(p, dx, dy, d, 0.2, "l2")
    assert np.allclose(gdmlt.reconstruct(p, dx, dy, d, 0.2, "l1", irls=(0, 6, 0.5)), l2, atol=1e-6)
    for bad in ((10, 6, 0.0), (10, 6, float("nan")), (10, 10 ** 6, 0.5)):
        with pytest.raises(ValueError, match="irls"):
            gdmlt.reconstruct(p, dx, dy, d, 0.2, "l1", irls=bad)


def test_bad_procedural_textures_are_refused_naming_them():
    """A procedural texture of an unknown pattern, a NaN in its transform, a table of one
    entry, or Object coordinates of the wrong count or with a NaN are messages naming the
    texture or the mesh, not a panic or NaN pixels; a good one renders finite pixels."""
    import numpy as np

    d = gdmlt.builtin_scene("cornell", 8, 8)
    table = np.linspace(0.0, 1.0, 6, dtype=np.float32).repeat(3).reshape(-1, 3)
    noise = {"pattern": "NOISE", "space": "OBJECT", "detail": 3.0, "domain": (-0.02, 1.02),
             "transform": (4.0, 0, 0, 0, 0, 4.0, 0, 0, 0, 0, 4.0, 0)}
    d["textures"] = [{"name": "Marble", "width": 6, "height": 1, "channels": 3, "pixels": table,
                      "procedural": dict(noise)}]
    d["materials"][0]["base_color_texture"] = 0
    mesh = d["meshes"][0]
    corners = 3 * len(np.asarray(mesh["indices"]).reshape(-1, 3))
    mesh["object"] = np.random.default_rng(1).uniform(-1, 1, (corners, 3)).astype(np.float32)
    res = gdmlt.render(gdmlt.Scene(d), spp=2, seed=1)
    assert np.isfinite(res["layers"]["Combined"]).all()
    for bad, message in [({"pattern": "MARBLE"}, "Marble.*unknown pattern 'MARBLE'"),
                         ({"transform": (np.nan,) + (0.0,) * 11}, "Marble.*NaN or Inf"),
                         ({"gradient_type": "WAVY", "pattern": "GRADIENT"}, "Marble.*unknown gradient_type 'WAVY'")]:
        d["textures"][0]["procedural"] = {**noise, **bad}
        with pytest.raises(ValueError, match=message):
            gdmlt.Scene(d)
    d["textures"][0].update(procedural=dict(noise), width=1, pixels=table[:1])
    with pytest.raises(ValueError, match="Marble.*procedural table of 1×1"):
        gdmlt.Scene(d)
    d["textures"][0].update(width=6, pixels=table)
    mesh["object"] = mesh["object"][:-1]
    with pytest.raises(ValueError, match=f"{mesh['name']}.*Object coordinates for"):
        gdmlt.Scene(d)
    mesh["object"] = np.zeros((corners, 3), np.float32)
    mesh["object"][2, 0] = np.inf
    with pytest.raises(ValueError, match=f"{mesh['name']}.*NaN or Inf Object coordinate"):
        gdmlt.Scene(d)


def test_bad_material_blends_are_refused_naming_the_material():
    """A material blend (a Mix Shader whose factor is a texture or the view) that is not a
    material dict, has no factor or two, an unknown or NaN view factor, or a factor texture
    the scene lacks is a message naming the material; a good one renders finite pixels."""
    import numpy as np

    d = gdmlt.builtin_scene("cornell", 8, 8)
    mat = d["materials"][0]
    name = mat["name"]
    gold = {"name": "Gold", "base_color": (1.0, 0.7, 0.25), "metallic": 1.0, "roughness": 0.3}
    d["textures"] = [{"name": "Mask", "width": 2, "height": 1, "channels": 3,
                      "pixels": np.array([[1, 1, 1], [0, 0, 0]], np.float32)}]
    for good in ({"blend": gold, "blend_texture": 0}, {"blend": gold, "blend_ray": ("LAYER_FACING", 0.3)}):
        mat.update(good)
        res = gdmlt.render(gdmlt.Scene(d), spp=2, seed=1)
        assert np.isfinite(res["layers"]["Combined"]).all()
        for k in good:
            del mat[k]
    for bad, message in [({"blend": "gold", "blend_texture": 0}, "blend must be a material dict"),
                         ({"blend": gold}, "one factor"),
                         ({"blend": gold, "blend_texture": 0, "blend_ray": ("FRESNEL", 1.5)}, "one factor"),
                         ({"blend": gold, "blend_ray": ("MOOD", 0.5)}, "unknown blend_ray 'MOOD'"),
                         ({"blend": gold, "blend_ray": ("FRESNEL", float("nan"))}, "NaN or Inf blend_ray"),
                         ({"blend": gold, "blend_texture": 4}, "uses texture 4"),
                         ({"blend": gold, "blend_ray": ("FRESNEL", 1.5), "blend_ray_curve": [0.5]}, "at least 2"),
                         ({"blend": gold, "blend_ray": ("FRESNEL", 1.5), "blend_ray_curve": [0.0, float("nan")]},
                          "NaN or Inf in blend_ray_curve"),
                         ({"blend": {**gold, "roughness": float("inf")}, "blend_texture": 0},
                          "its blend material: NaN or Inf")]:
        with pytest.raises(ValueError, match=f"{name}.*{message}"):
            gdmlt.Scene(dict(d, materials=[{**mat, **bad}, *d["materials"][1:]]))


def test_a_bad_camera_backdrop_is_refused():
    """A camera backdrop (what the camera sees instead of the world) with a NaN or negative
    component is a message naming the camera's backdrop; a good one fills the image where
    the camera sees the world."""
    import numpy as np

    d = gdmlt.builtin_scene("cornell", 8, 8)
    for bad in [(float("nan"), 0.0, 0.0), (-1.0, 0.0, 0.0)]:
        d["camera"]["backdrop"] = bad
        with pytest.raises(ValueError, match="camera.*backdrop must be finite"):
            gdmlt.Scene(d)
    d["camera"]["backdrop"] = (0.2, 0.4, 0.6)
    res = gdmlt.render(gdmlt.Scene(d), spp=2, seed=1)
    assert np.isfinite(res["layers"]["Combined"]).all() and "Alpha" not in res["layers"]
    # a textured backdrop: a texture that does not exist, a rotation that is none, no strength
    d["camera"]["backdrop_texture"] = 7
    with pytest.raises(ValueError, match="camera.*backdrop: uses texture 7"):
        gdmlt.Scene(d)
    from gdmlt import scenedict

    d["textures"] = [scenedict.texture("sky", np.full((2, 3), 0.5, np.float32), 2, 1)]
    d["camera"].update(backdrop_texture=0, backdrop_rotation=np.eye(3, dtype=np.float32) * 2)
    with pytest.raises(ValueError, match="camera.*backdrop: rotation must be a rotation matrix"):
        gdmlt.Scene(d)
    del d["camera"]["backdrop_rotation"], d["camera"]["backdrop"]
    with pytest.raises(ValueError, match="camera.*backdrop_texture needs a backdrop strength"):
        gdmlt.Scene(d)
    d["camera"]["backdrop"] = (1.0, 1.0, 1.0)
    res = gdmlt.render(gdmlt.Scene(d), spp=2, seed=1)
    assert np.isfinite(res["layers"]["Combined"]).all() and "Alpha" not in res["layers"]


def test_bad_panorama_ranges_are_refused():
    """An equirectangular camera whose latitude or longitude range is empty, reversed or NaN,
    a fisheye of no field of view or lens, is a message naming the camera, not a black frame;
    good ones render finite."""
    import numpy as np

    d = gdmlt.builtin_scene("cornell", 16, 8)
    d["camera"]["type"] = "EQUIRECTANGULAR"
    for key, bad in [("latitude_min", 2.0), ("longitude_max", float("nan")), ("longitude_min", 3.2)]:
        with pytest.raises(ValueError, match="camera.*panorama latitude and longitude ranges"):
            gdmlt.Scene(dict(d, camera=dict(d["camera"], **{key: bad})))
    res = gdmlt.render(gdmlt.Scene(d), spp=2, seed=1)
    img = res["layers"]["Combined"]
    assert np.isfinite(img).all() and img.mean() > 0
    d["camera"]["type"] = "FISHEYE_EQUISOLID"
    for key, bad in [("fisheye_fov", 0.0), ("fisheye_lens", -1.0), ("fisheye_fov", float("nan"))]:
        with pytest.raises(ValueError, match="camera.*fisheye field of view, lens and sensor size must be positive"):
            gdmlt.Scene(dict(d, camera=dict(d["camera"], **{key: bad})))
    img = gdmlt.render(gdmlt.Scene(d), spp=2, seed=1)["layers"]["Combined"]
    assert np.isfinite(img).all() and img.mean() > 0 and img[0, 0].max() == 0.0  # (a corner: no light)


def test_bad_corner_colours_are_refused_naming_the_mesh():
    """Corner colours (vertex colours) of the wrong count or with a NaN are a message naming
    the mesh, not a panic or NaN pixels."""
    import numpy as np

    d = gdmlt.builtin_scene("cornell", 8, 8)
    mesh = d["meshes"][0]
    corners = 3 * len(np.asarray(mesh["indices"]).reshape(-1, 3))
    mesh["colors"] = np.full((corners - 1, 3), 0.5, np.float32)
    with pytest.raises(ValueError, match=f"{mesh['name']}.*corner colours for"):
        gdmlt.Scene(d)
    mesh["colors"] = np.full((corners, 3), 0.5, np.float32)
    mesh["colors"][4, 1] = np.nan
    with pytest.raises(ValueError, match=f"{mesh['name']}.*NaN or Inf corner colour"):
        gdmlt.Scene(d)
    mesh["colors"][4, 1] = 0.25
    assert not [w for w in gdmlt.Scene(d).warnings if "unknown key" in w]


# --- issue 50: the second probe (each failed before its fix) ---------------------------------

def test_a_nan_light_power_is_reported_as_nan_not_as_too_large():
    """[5] a NaN power was reported as "too large for single precision"."""
    d = gdmlt.builtin_scene("cornell", 8, 8)
    d["lights"] = [{"type": "point", "name": "Lamp", "position": [0.0, 0.0, 1.0], "power": [float("nan"), 1.0, 1.0]}]
    with pytest.raises(ValueError, match="Lamp.*NaN power") as e:
        gdmlt.Scene(d)
    assert "too large" not in str(e.value)


def test_a_usd_syntax_error_is_one_line_naming_file_line_and_column(tmp_path):
    """[5] a USD syntax error printed an empty `gdmlt: error:` line and then pxr's C++ call
    stack (namespaces, the C++ file and line of the parser)."""
    pytest.importorskip("pxr")
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\ndef Xform "a" {\n  double3 xformOp:translate = (1, 2\n}\n')
    r = _cli("render", str(bad), "-o", str(tmp_path / "o.exr"))
    assert r.returncode != 0 and "Traceback" not in r.stderr
    errors = [line for line in r.stderr.splitlines() if "error" in line]
    assert len(errors) == 1, r.stderr
    assert f"{bad}:4:1:" in errors[0] and "parse error" in errors[0], r.stderr
    assert "pxrInternal" not in r.stderr and ".cpp" not in r.stderr and ".h :" not in r.stderr, r.stderr


def test_the_explanation_never_says_a_method_is_ahead_of_itself():
    """[5] auto once printed "pt is 1.0× ahead of pt": pt kept (the lead after denoising
    under the margin) while second in the denoised ranking."""
    from gdmlt.auto import _explain

    why = _explain("pt", {"pt": 2.0, "gdpt": 1.0}, {"pt": 1.2, "gdpt": 1.0}, "pilot")
    assert "ahead of pt" not in why and "pt kept though gdpt measured 1.2× ahead" in why, why
    why = _explain("pt", {"pt": 1.0, "gdpt": 3.0}, {}, "pilot")
    assert "pt is 3× ahead of gdpt" in why, why


def _warnings(desc):
    return gdmlt.Scene(desc).warnings


@pytest.mark.parametrize("key, value, words", [
    ("roughness", -1.0, "roughness -1 is outside 0…1; 0 is used"),
    ("roughness", 5.0, "roughness 5 is outside 0…1; 1 is used"),
    ("metallic", 2.0, "metallic 2 is outside 0…1; 1 is used"),
    ("ior", 0.0, "IOR 0 is not above 0; 1.5 is used"),
    ("ior", -1.5, "IOR -1.5 is not above 0; 1.5 is used"),
    ("base_color", [5.0, 0.5, 0.5], "(1, 0.5, 0.5) is used"),
    ("base_color", [-1.0, 0.5, 0.5], "(0, 0.5, 0.5) is used"),
])
def test_out_of_range_material_inputs_are_clamped_with_a_warning_naming_the_material(key, value, words):
    """[6] through the Python API (and USD, which reaches the core the same way) these were
    clamped in silence."""
    d = gdmlt.builtin_scene("cornell", 8, 8)
    m = d["materials"][0]
    m[key] = value
    warnings = _warnings(d)
    assert any(m["name"] in w and words in w for w in warnings), warnings
    ok = gdmlt.builtin_scene("cornell", 8, 8)
    assert not any("is used" in w for w in _warnings(ok))


def test_a_negative_area_light_size_and_a_crossed_clip_range_are_warned_and_rendered():
    """[6] an area light of size −1 was read as 1 in silence; clip start beyond clip end
    rendered a black image in silence. Now each is a warning naming the value used, and the
    crossed clip range is read swapped (the image is the one with the range put right)."""
    d = gdmlt.builtin_scene("cornell", 16, 16)
    d["lights"] = [{"type": "area", "name": "Panel", "matrix": np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.9], [0, 0, 0, 1]], np.float32),
                    "size": -1.0, "power": [50.0, 50.0, 50.0]}]
    assert any("Panel" in w and "size -1 is negative; 1 is used" in w for w in _warnings(d)), _warnings(d)
    crossed = dict(d, camera=dict(d["camera"], clip_start=100.0, clip_end=0.01))
    warnings = _warnings(crossed)
    assert any("clip start 100 is not before clip end 0.01" in w and "0.01 to 100 is used" in w for w in warnings), warnings
    img = gdmlt.render(gdmlt.Scene(crossed), method="pt", spp=4, seed=1)["layers"]["Combined"]
    right = dict(d, camera=dict(d["camera"], clip_start=0.01, clip_end=100.0))
    ref = gdmlt.render(gdmlt.Scene(right), method="pt", spp=4, seed=1)["layers"]["Combined"]
    assert img.mean() > 0.01 and np.array_equal(img, ref)


def test_usd_out_of_range_inputs_reach_the_user_as_warnings(tmp_path):
    """[6] the same through a USD stage and the command line: roughness 5 on a
    UsdPreviewSurface is a warning naming the material."""
    pxr = pytest.importorskip("pxr")
    from test_usd import _stage

    path = _stage(tmp_path / "s.usda")
    stage = pxr.Usd.Stage.Open(str(path))
    shader = pxr.UsdShade.Shader(stage.GetPrimAtPath("/World/Grey/Surface"))
    shader.CreateInput("roughness", pxr.Sdf.ValueTypeNames.Float).Set(5.0)
    stage.GetRootLayer().Save()
    r = _cli("render", str(path), "-o", str(tmp_path / "o.exr"), "--method", "pt", "--spp", "1", "--width", "8",
             "--height", "8", "--no-png", "--no-denoise")
    assert r.returncode == 0, r.stderr
    assert "roughness 5 is outside 0…1; 1 is used" in r.stderr and "Grey" in r.stderr, r.stderr


def test_a_scene_larger_than_memory_is_refused_before_building(tmp_path):
    """Issue 49: a mesh too large for the memory there (12M triangles under a 4 GB address
    space) aborted the process in an allocation while the scene was built; now gdmlt.Scene
    raises ValueError saying how much it needs and how much there is."""
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (4_000_000 * 1024, resource.RLIM_INFINITY))

    code = """
import numpy as np, gdmlt
k = 2450  # a k×k grid of quads: 12M triangles
x, y = np.meshgrid(np.arange(k + 1, dtype=np.float32), np.arange(k + 1, dtype=np.float32))
pos = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
v = (np.arange(k)[:, None] * (k + 1) + np.arange(k)[None, :]).reshape(-1).astype(np.uint32)
tris = np.concatenate([np.stack([v, v + 1, v + k + 2], -1), np.stack([v, v + k + 2, v + k + 1], -1)])
desc = gdmlt.builtin_scene("cornell", 8, 8)
desc["meshes"].append({"name": "Grid", "positions": pos, "indices": tris})
try:
    gdmlt.Scene(desc)
except ValueError as e:
    print("refused:", e)
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300,
                       preexec_fn=limit)
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
    assert "refused: not enough memory to build the scene" in r.stdout and "GiB" in r.stdout, r.stdout
