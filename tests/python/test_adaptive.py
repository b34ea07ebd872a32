"""Adaptive sampling (Blender's Noise Threshold; src/integrator/adaptive.rs) from the Python
API, the command line and F12. The estimator itself is tested in Rust (tests/render.rs:
the image converges to the uniformly sampled one, whatever the thread count); how much it
helps at equal time is measured by `gdmlt bench` (docs/benchmarks.md), not by a timed test."""

import numpy as np

import gdmlt
from gdmlt import cli

from conftest import ROOT


def test_settled_pixels_stop_and_the_image_keeps_its_mean():
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 32, 32))
    uniform = gdmlt.render(scene, method="pt", spp=256, seed=1)
    adaptive = gdmlt.render(scene, method="pt", spp=256, seed=1, adaptive_threshold=0.05, adaptive_min_samples=16)
    st = adaptive["stats"]
    assert (st["spp_min"], st["spp_max"]) == (16, 256), st
    assert (uniform["stats"]["spp_min"], uniform["stats"]["spp_max"]) == (256, 256)
    a, u = adaptive["layers"]["Combined"], uniform["layers"]["Combined"]
    assert np.isfinite(a).all()
    # the mean over the image: the stopped pixels are each their own samples' mean
    assert abs(a.mean() / u.mean() - 1) < 0.02, (a.mean(), u.mean())
    # at the threshold's upper end every pixel stops at the minimum
    loose = gdmlt.render(scene, method="pt", spp=256, seed=1, adaptive_threshold=1.0, adaptive_min_samples=16)
    assert loose["stats"]["spp_max"] <= 32, loose["stats"]


def test_the_command_line_takes_a_noise_threshold_and_reports_the_samples_range(tmp_path, capsys):
    out = tmp_path / "a.exr"
    code = cli.main(["render", "cornell", "-o", str(out), "--method", "pt", "--spp", "256", "--noise-threshold",
                     "0.05", "--adaptive-min-samples", "16", "--width", "32", "--height", "32", "--no-png",
                     "--no-denoise"])
    assert code == 0
    assert "16–256 samples per pixel" in capsys.readouterr().out
    args = cli.build_parser().parse_args(["render", "cornell", "-o", "x.exr", "--noise-threshold", "0"])
    opts, _ = cli.render_settings(args, {})
    assert opts["adaptive_threshold"] == 0.0  # 0 turns it off, as in Cycles


def test_blender_noise_threshold_checkbox_turns_adaptive_sampling_on_and_off(bpy_mod):
    bpy = bpy_mod
    from gdmlt.blend import settings_of
    import gdmlt_blender.engine as engine

    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 32
    g = scene.gdmlt
    g.method, g.samples, g.time_limit, g.use_denoising = "PT", 256, 0.0, False
    assert g.use_adaptive_sampling and settings_of(g)["adaptive_threshold"] > 0  # on by default, as Cycles
    g.adaptive_threshold, g.adaptive_min_samples = 0.05, 16
    bpy.ops.render.render()
    assert (engine.last_stats["spp_min"], engine.last_stats["spp_max"]) == (16, 256), engine.last_stats
    g.use_adaptive_sampling = False
    assert settings_of(g)["adaptive_threshold"] == 0.0
    bpy.ops.render.render()
    assert engine.last_stats["spp_min"] == engine.last_stats["spp_max"] == 256
