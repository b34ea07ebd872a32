"""The built-in denoiser (gdmlt.denoise, in gdmlt/oidn.py: Intel Open Image Denoise through pyoidn) from the
Python API, the CLI and Blender: it lowers the error of every method against a converged
render, keeps the raw image as "Noisy Image", never writes NaN, and falls back to the raw
image with a warning when OIDN is missing."""

import subprocess
import sys

import numpy as np
import pytest

import gdmlt
from gdmlt import oidn as dn

from conftest import ROOT, read_exr


def rel_mse(img, ref):
    return float(np.mean((img - ref) ** 2 / (ref ** 2 + 1e-2)))


@pytest.fixture(scope="module")
def cornell():
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 48, 48))
    ref = gdmlt.render(scene, method="pt", spp=2048, seed=77)["layers"]["Combined"]
    return scene, ref


@pytest.mark.parametrize("method", ["pt", "gdpt", "pssmlt", "gdpssmlt"])
def test_denoising_lowers_the_error_of_every_method(cornell, method):
    """At 16 samples (mutations) per pixel each method's denoised image is closer to a 2048-spp
    render than its raw one; the reference's own noise (about 16/2048 of the raw error) is far
    below the margins asked for. Measured (raw/denoised relMSE): pt 4.2×, pssmlt 3.3×, gdpt
    1.1×, gdpssmlt 1.2× — the gradient-domain methods' remaining error is low-frequency,
    which a denoiser does not see (docs/denoising.md)."""
    scene, ref = cornell
    layers = gdmlt.render(scene, method=method, spp=16, seed=3)["layers"]
    out = dn.denoise(layers)
    raw, den = rel_mse(layers["Combined"], ref), rel_mse(out["Combined"], ref)
    print(f"{method}: raw {raw:.3g}, denoised {den:.3g} ({raw / den:.1f}x)")
    assert den < raw / {"pt": 2.5, "pssmlt": 2.0}.get(method, 1.05), (raw, den)
    # the denoiser keeps the image's brightness: it removes noise, it does not shift the mean
    assert abs(out["Combined"].mean() / layers["Combined"].mean() - 1) < 0.02


def test_layers_keep_the_raw_image_and_are_not_modified():
    rng = np.random.default_rng(1)
    img = (0.5 + 0.1 * rng.standard_normal((24, 20, 3))).astype(np.float32)
    albedo = np.full_like(img, 0.5)
    normal = np.zeros_like(img)
    normal[..., 2] = 1
    layers = {"Combined": img.copy(), "Denoising Albedo": albedo, "Denoising Normal": normal, "Other": img[..., :1]}
    out = dn.denoise(layers)
    assert np.array_equal(layers["Combined"], img)  # input untouched
    assert out["Noisy Image"] is layers["Combined"] and out["Other"] is layers["Other"]
    assert out["Combined"].shape == img.shape and out["Combined"].dtype == np.float32
    # a flat grey surface with white noise comes out flat, at the same mean
    assert out["Combined"].std() < 0.2 * img.std()
    assert abs(out["Combined"].mean() - img.mean()) < 0.01


def test_non_finite_and_negative_pixels_never_reach_the_output():
    img = np.full((16, 16, 3), 0.3, np.float32)
    img[3, 4] = np.nan
    img[5, 6] = np.inf
    img[7, 8] = -5.0
    out = dn.denoise_image(img)
    assert np.isfinite(out).all() and (out >= 0).all()


def test_guides_of_another_size_are_refused():
    img = np.zeros((8, 8, 3), np.float32)
    with pytest.raises(ValueError, match="albedo guide"):
        dn.denoise_image(img, albedo=np.zeros((8, 9, 3), np.float32))


def test_without_oidn_the_raw_image_is_kept_with_a_warning(monkeypatch):
    def missing():
        raise dn.DenoiserUnavailable("the denoiser needs the pyoidn package: not installed")

    monkeypatch.setattr(dn, "_pyoidn", missing)
    assert dn.available() is False
    layers = {"Combined": np.ones((4, 4, 3), np.float32)}
    said = []
    assert dn.denoise_or_warn(layers, said.append) is layers
    assert len(said) == 1 and "without denoising" in said[0]


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "gdmlt.cli", *args], capture_output=True, text=True, cwd=ROOT)


def test_cli_denoises_by_default_and_keeps_the_noisy_layer(tmp_path):
    import OpenEXR

    common = ["render", "cornell", "--method", "pt", "--spp", "4", "--width", "24", "--height", "24", "--no-png"]
    r = _cli(*common, "-o", str(tmp_path / "d.exr"))
    assert r.returncode == 0, r.stderr
    r = _cli(*common, "-o", str(tmp_path / "n.exr"), "--no-denoise")
    assert r.returncode == 0, r.stderr
    with OpenEXR.File(str(tmp_path / "d.exr")) as f:
        names = set(f.channels())
    with OpenEXR.File(str(tmp_path / "n.exr")) as f:
        raw_names = set(f.channels())
    assert any(n.startswith("Noisy Image") for n in names), names
    assert not any(n.startswith("Noisy Image") for n in raw_names), raw_names
    den, raw = read_exr(tmp_path / "d.exr"), read_exr(tmp_path / "n.exr")
    assert np.array_equal(read_exr(tmp_path / "d.exr", "Noisy Image"), raw)  # the same render, kept raw
    assert np.isfinite(den).all() and not np.array_equal(den, raw)
    # Combined is OIDN of that raw image with the render's own albedo and normal guides
    guides = [read_exr(tmp_path / "n.exr", n) for n in ("Denoising Albedo", "Denoising Normal")]
    assert np.allclose(den, dn.denoise_image(raw, *guides), atol=1e-4)


def test_blender_denoise_checkbox_writes_noisy_image_pass(bpy_mod, tmp_path):
    bpy = bpy_mod
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples" / "cornell.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 24
    scene.gdmlt.method, scene.gdmlt.samples = "PT", 4
    import gdmlt_blender.engine as engine

    for on in (True, False):
        scene.gdmlt.use_denoising = on
        bpy.ops.render.render()
        assert engine.last_stats["denoised"] is on
    # the pass is declared to Blender's compositor and View Layer when the checkbox is on
    assert any(p[0] == "Noisy Image" for p in engine.PASSES)
