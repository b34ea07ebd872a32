"""Property-based tests (hypothesis) of the Python API's input boundary: any scene arrays,
however broken, either build or raise ValueError naming what is wrong — never a crash or a
panic across the FFI — and whatever builds renders finite pixels."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import gdmlt

floats = st.floats(allow_nan=True, allow_infinity=True, width=32)
finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, width=32)


@st.composite
def meshes(draw):
    nv = draw(st.integers(0, 6))
    nt = draw(st.integers(0, 5))
    coord = floats if draw(st.booleans()) else finite
    pos = np.array(draw(st.lists(st.tuples(coord, coord, coord), min_size=nv, max_size=nv)) or np.zeros((0, 3)),
                   np.float32).reshape(-1, 3)
    idx = np.array(draw(st.lists(st.tuples(*[st.integers(0, 8)] * 3), min_size=nt, max_size=nt)) or
                   np.zeros((0, 3)), np.uint32).reshape(-1, 3)
    mesh = {"name": "M", "positions": pos, "indices": idx}
    if draw(st.booleans()):
        mesh["material_ids"] = np.array(draw(st.lists(st.integers(0, 3), min_size=nt, max_size=nt)), np.uint32)
    if draw(st.booleans()):
        n = draw(st.integers(0, 3 * nt + 1))
        mesh["normals"] = np.array(draw(st.lists(st.tuples(coord, coord, coord), min_size=n, max_size=n))
                                   or np.zeros((0, 3)), np.float32).reshape(-1, 3)
    return mesh


@st.composite
def materials(draw):
    return {"name": "Mat", "base_color": draw(st.tuples(floats, floats, floats)),
            "emission": draw(st.tuples(finite, finite, finite)), "roughness": draw(floats),
            "metallic": draw(floats), "transmission": draw(floats), "ior": draw(floats)}


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mesh=meshes(), mats=st.lists(materials(), max_size=3), world=st.tuples(finite, finite, finite))
def test_any_scene_input_builds_or_is_a_value_error(mesh, mats, world):
    d = gdmlt.builtin_scene("cornell", 6, 6)
    d["meshes"].append(mesh)
    d["materials"] = d["materials"] + mats
    d["world"] = world
    try:
        scene = gdmlt.Scene(d)
    except ValueError as e:
        assert str(e)  # a message naming the cause
        return
    res = gdmlt.render(scene, method="gdpt", spp=2, max_bounces=2, seed=1)
    for name, img in res["layers"].items():
        assert np.isfinite(img).all(), name


@settings(max_examples=60, deadline=None)
@given(method=st.sampled_from(["pt", "bdpt", "gdpt", "pssmlt", "gdpssmlt"]), spp=st.integers(1, 3),
       bounces=st.integers(0, 3), nee=st.booleans(), seed=st.integers(0, 2 ** 63 - 1),
       alpha=st.one_of(st.just(0.0), st.floats(min_value=1e-3, max_value=10)), large=st.floats(0, 1))
def test_any_valid_settings_render_finite(method, spp, bounces, nee, seed, alpha, large):
    scene = gdmlt.Scene(gdmlt.builtin_scene("spheres", 5, 4))
    res = gdmlt.render(scene, method=method, spp=spp, max_bounces=bounces, nee=nee, seed=seed, alpha_rec=alpha,
                       large_step_probability=large)
    assert all(np.isfinite(img).all() for img in res["layers"].values())


def test_every_layer_takes_its_defaults_from_one_place(bpy_mod):
    """Issue 19.4: render defaults were written four times (the core, its Python signature,
    the add-on's properties, the CLI). Now the core's live in RenderSettings::default()
    (gdmlt.settings.CORE) and the product's (gdmlt.settings.PRODUCT) are built on them: a
    fresh scene's GDMLT properties, the CLI with no options and gdmlt.render without
    arguments all give them."""
    import argparse

    from gdmlt import cli
    from gdmlt.blend import PROPERTY_OF, settings_of
    from gdmlt.settings import CORE, PRODUCT

    bpy = bpy_mod
    scene = bpy.data.scenes.new("defaults")
    try:
        blender = settings_of(scene.gdmlt)
    finally:
        bpy.data.scenes.remove(scene)
    # (Blender stores a FloatProperty in single precision)
    for k in PROPERTY_OF:
        want = PRODUCT[k]
        assert blender[k] == (pytest.approx(want, rel=1e-6) if isinstance(want, float) else want), (k, blender[k])
    args = cli.build_parser().parse_args(["render", "cornell", "-o", "x.exr"])
    opts, denoise = cli.render_settings(args, {})
    assert denoise == PRODUCT["denoise"] and opts == {k: v for k, v in PRODUCT.items() if k not in ("denoise", "data_passes")}
    assert isinstance(args, argparse.Namespace)
    core = gdmlt.Scene(gdmlt.builtin_scene("cornell", 8, 8))
    st = gdmlt.render(core)["stats"]
    assert (st["method"], st["spp_max"]) == (CORE["method"], CORE["spp"])
    # a setting given as None is the default too (what callers passing settings through get)
    assert gdmlt.render(core, spp=None, method=None)["stats"]["spp_max"] == CORE["spp"]
