"""Property-based fuzzing of each input surface (issue 18): the command line, USD stages and
merge partials. Whatever the input: a clear message and a non-zero exit (or a ValueError), or
a finite, non-negative, correctly sized image — never a traceback, a panic or an abort. (The
scene dict has its own in test_properties.py.) Few examples each, to keep `make test` short;
hypothesis shrinks any failure to a minimal case."""

import contextlib
import io

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import gdmlt
from gdmlt import cli, distributed as dist

from conftest import read_exr

NUMBERS = st.sampled_from(["0", "1", "-1", "3", "0.5", "1e20", "-1e-9", "nan", "inf", "abc", "", "2" * 25,
                           str(2 ** 64), str(2 ** 32), "65537"])
OPTIONS = st.sampled_from(["--spp", "--time", "--max-bounces", "--seed", "--threads", "--chains", "--alpha-rec",
                           "--alpha-target", "--large-step", "--width", "--height", "--recon", "--method",
                           "--noise-threshold", "--adaptive-min-samples"])


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(args=st.lists(st.tuples(OPTIONS, NUMBERS | st.sampled_from(["pt", "gdpt", "l1", "l2", "auto"])), max_size=4),
       flags=st.lists(st.sampled_from(["--nee", "--no-nee", "--denoise", "--no-denoise"]), max_size=2))
def test_any_command_line_exits_cleanly(tmp_path, args, flags):
    out = tmp_path / "f.exr"
    argv = ["render", "cornell", "-o", str(out), *[x for pair in args for x in pair], *flags,
            # small and quick whatever was fuzzed (argparse keeps the last of a repeated option)
            "--width", "6", "--height", "5", "--spp", "2", "--time", "2", "--no-png"]
    if "auto" in argv:
        argv += ["--method", "pt"]
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli.main(argv)
    except SystemExit as e:  # argparse: a bad value
        code = e.code
    assert code in (0, 1, 2), (argv, code, err.getvalue())
    assert "Traceback" not in err.getvalue()
    if code == 0:
        img = read_exr(out)
        assert img.shape == (5, 6, 3) and np.isfinite(img).all() and (img >= 0).all()
    else:
        assert "error" in err.getvalue() or "usage" in err.getvalue(), (argv, err.getvalue())


@pytest.fixture(scope="module")
def partials():
    d = gdmlt.builtin_scene("cornell", 8, 8)
    return [dist.render_partial(d, k, 3, {"method": "gdpt", "spp": 2}) for k in range(3)]


FIELD_VALUES = {"work": st.sampled_from([0.0, -1.0, float("nan"), float("inf"), 1e300, 5.0]),
                "k": st.integers(-2, 5), "n": st.integers(0, 5), "seed": st.integers(0, 3),
                "method": st.sampled_from(["pt", "gdpt", "gdpssmlt", "x"]),
                "scene_hash": st.sampled_from(["", "abc"])}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_tampered_set_of_partials_merges_finite_or_is_refused(partials, data):
    chosen = data.draw(st.lists(st.integers(0, 2), min_size=1, max_size=4))
    ps = [dict(partials[i]) for i in chosen]
    for p in ps:
        for field in data.draw(st.lists(st.sampled_from(sorted(FIELD_VALUES)), max_size=2)):
            p[field] = data.draw(FIELD_VALUES[field])
        if data.draw(st.booleans()):
            layer = data.draw(st.sampled_from([k for k in p if k.startswith("layer:")]))
            a = p[layer].copy()
            a.flat[data.draw(st.integers(0, a.size - 1))] = data.draw(
                st.sampled_from([np.nan, np.inf, -1e30, 1e30, -0.5]))
            p[layer] = a
    try:
        layers = dist.merge(ps)
    except ValueError as e:
        assert str(e)
        return
    img = layers["Combined"]
    assert img.shape == (8, 8, 3) and np.isfinite(img).all() and (img >= 0).all()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(counts=st.lists(st.integers(-3, 6), min_size=1, max_size=3),
       indices=st.lists(st.integers(-2, 8), max_size=10),
       normals=st.integers(0, 6), intensity=st.sampled_from([1.0, -10.0, float("nan"), float("inf"), 0.0]))
def test_any_broken_usd_mesh_or_light_loads_or_is_a_value_error(tmp_path, counts, indices, normals, intensity):
    pxr = pytest.importorskip("pxr")
    from test_usd import _stage

    from gdmlt import usd

    path = _stage(tmp_path / "s.usda")
    stage = pxr.Usd.Stage.Open(str(path))
    floor = pxr.UsdGeom.Mesh(stage.GetPrimAtPath("/World/Floor"))
    floor.GetFaceVertexCountsAttr().Set(counts)
    floor.GetFaceVertexIndicesAttr().Set(indices)
    floor.CreateNormalsAttr([(0, 0, 1)] * normals)
    for prim in stage.Traverse():
        if prim.HasAPI(pxr.UsdLux.LightAPI):
            pxr.UsdLux.LightAPI(prim).GetIntensityAttr().Set(intensity)
    stage.GetRootLayer().Save()
    try:
        desc, _ = usd.load(path, width=6, height=4)
        scene = gdmlt.Scene(desc)
    except ValueError as e:
        assert str(e)
        return
    img = gdmlt.render(scene, method="pt", spp=1, max_bounces=2)["layers"]["Combined"]
    assert img.shape == (4, 6, 3) and np.isfinite(img).all() and (img >= 0).all()
