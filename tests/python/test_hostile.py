"""Hostile and careless input (issue 18): every case a clear message and a non-zero exit, or
a finite, correctly sized image — never a traceback, a panic or a silently wrong image. Each
case here failed before its fix (the issue's numbers in brackets)."""

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
