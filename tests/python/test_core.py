"""The Python surface of the core, without Blender."""

import subprocess
import sys
import time

import numpy as np
import pytest

import gdmlt
from conftest import ROOT, read_exr


def test_builtin_render_is_finite_and_lit():
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 32, 24))
    assert scene.size == (32, 24)
    res = gdmlt.render(scene, spp=4, seed=1)
    img = res["layers"]["Combined"]
    assert img.shape == (24, 32, 3) and img.dtype == np.float32
    assert np.isfinite(img).all()
    assert img.mean() > 0.05
    assert res["stats"]["spp_max"] == 4 and res["stats"]["invalid_samples"] == 0


def test_same_seed_same_image_any_thread_count():
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 16, 16))
    a = gdmlt.render(scene, spp=2, seed=3, threads=1)["layers"]["Combined"]
    b = gdmlt.render(scene, spp=2, seed=3, threads=2)["layers"]["Combined"]
    assert np.array_equal(a, b)


def test_exr_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.random((5, 7, 3), dtype=np.float32)
    b = rng.random((5, 7, 3), dtype=np.float32)
    p = tmp_path / "x.exr"
    gdmlt.write_exr(str(p), [("Combined", a), ("GD Primal", b)])
    assert np.array_equal(read_exr(p), a)
    assert np.array_equal(read_exr(p, "GD Primal"), b)


def _cornell_desc():
    return gdmlt.builtin_scene("cornell", 8, 8)


def test_nan_vertex_is_a_value_error_naming_the_mesh():
    d = _cornell_desc()
    mesh = next(m for m in d["meshes"] if m["name"] == "LeftWall")
    pos = mesh["positions"].copy()
    pos[2, 1] = np.nan
    mesh["positions"] = pos
    with pytest.raises(ValueError, match="LeftWall.*NaN"):
        gdmlt.Scene(d)


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d["meshes"][0].__setitem__("indices", np.array([[0, 1, 9]], np.uint32)), "Floor"),
    (lambda d: d["meshes"][0].__setitem__("positions", np.zeros((0, 3), np.float32)), "Floor"),
    (lambda d: d["meshes"][0].__setitem__("positions", [[0, 0, 0]]), "float32"),
    (lambda d: d["camera"].__setitem__("resolution_x", 0), "nothing to render"),
    (lambda d: d["materials"][0].__setitem__("base_color", (np.inf, 0, 0)), "White"),
    (lambda d: d.__setitem__("lights", [{"type": "BLOB", "name": "L"}]), "BLOB"),
    (lambda d: d["materials"][0].__setitem__("base_color_texture", 3), "White.*texture 3"),
    (lambda d: d.__setitem__("textures", [{"name": "Bricks", "width": 4, "height": 4,
                                           "pixels": np.zeros((15, 4), np.float32)}]), "Bricks"),
    (lambda d: d["meshes"][0].__setitem__("uvs", np.zeros((5, 2), np.float32)), "Floor.*UV"),
])
def test_bad_input_is_a_clear_value_error(mutate, match):
    d = _cornell_desc()
    mutate(d)
    with pytest.raises(ValueError, match=match):
        gdmlt.Scene(d)


def test_bad_render_settings():
    scene = gdmlt.Scene(_cornell_desc())
    with pytest.raises(ValueError, match="unknown method"):
        gdmlt.render(scene, method="vcm")
    with pytest.raises(ValueError, match="samples"):
        gdmlt.render(scene, spp=0)
    with pytest.raises(ValueError, match="time limit"):
        gdmlt.render(scene, time_limit=float("nan"))


def test_cancel_during_the_l1_reconstruction_returns_within_a_second():
    """Esc after the samples are taken, while the L1 reconstruction of a 1280×720 image runs
    (2.2 s on 2 cores, stopped in 0.34 s; 1920×1080: 5.6 s, stopped in 0.81–0.87 s; measured): the solve
    stops at its next CG step and the render returns its current iterate within a second."""
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 1280, 720))
    asked = {}

    def progress(fraction, elapsed):
        if fraction >= 1.0 and "t" not in asked:  # all samples done: reconstructing
            asked["t"] = time.perf_counter()
        return "t" in asked

    res = gdmlt.render(scene, method="gdpt", spp=1, max_bounces=1, reconstruction="l1", progress=progress)
    stopped = time.perf_counter() - asked["t"]
    assert stopped < 1.0, f"took {stopped:.2f} s to stop"
    img = res["layers"]["Combined"]
    assert img.shape == (720, 1280, 3) and np.isfinite(img).all() and img.mean() > 0


def test_cancellation_returns_within_a_second():
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 128, 128))
    asked = {}

    def progress(fraction, elapsed):
        if elapsed > 0.3 and "t" not in asked:
            asked["t"] = time.perf_counter()
        return "t" in asked

    res = gdmlt.render(scene, spp=100000, progress=progress)
    stopped = time.perf_counter() - asked["t"]
    assert stopped < 1.0, f"took {stopped:.2f} s to stop"
    assert res["stats"]["cancelled"]
    img = res["layers"]["Combined"]
    assert np.isfinite(img).all() and img.mean() > 0  # keeps what it had


def test_progress_callback_exception_propagates():
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 64, 64))

    def progress(fraction, elapsed):
        raise KeyError("boom")

    with pytest.raises(KeyError):
        gdmlt.render(scene, spp=100000, progress=progress)


def test_gradient_domain_renders_measure_their_alpha():
    """alpha_rec 0 (the default): gdpt and gdpssmlt measure the reconstruction's α from
    their two sample (chain) halves, report it, and Combined is the reconstruction with it;
    an α given is used as given; one sample has no halves (α 0.2); pt has no α."""
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 24, 16))
    for method in ("gdpt", "gdpssmlt"):
        res = gdmlt.render(scene, method=method, spp=8, seed=2, reconstruction="l2", chains=4)
        a = res["stats"]["alpha_rec"]
        assert 0.02 <= a <= 5.0 and a != 0.2, (method, a)
        L = res["layers"]
        rec = gdmlt.reconstruct(np.ascontiguousarray(L["GD Primal"] - L["Very Direct"]), L["GD Gradient X"],
                                L["GD Gradient Y"], L["Very Direct"], alpha=a, norm="l2", method=method)
        np.testing.assert_allclose(rec, L["Combined"], rtol=1e-3, atol=1e-4)
        other = gdmlt.reconstruct(np.ascontiguousarray(L["GD Primal"] - L["Very Direct"]), L["GD Gradient X"],
                                  L["GD Gradient Y"], L["Very Direct"], alpha=2 * a, norm="l2", method=method)
        assert np.abs(other - L["Combined"]).max() > 1e-3  # (the comparison can tell α apart)
        fixed = gdmlt.render(scene, method=method, spp=8, seed=2, reconstruction="l2", alpha_rec=0.5, chains=4)
        assert fixed["stats"]["alpha_rec"] == 0.5
    assert gdmlt.render(scene, method="gdpt", spp=1)["stats"]["alpha_rec"] == 0.2
    assert gdmlt.render(scene, method="gdpssmlt", spp=4, chains=1)["stats"]["alpha_rec"] == 0.2
    assert gdmlt.render(scene, method="pt", spp=2)["stats"]["alpha_rec"] == 0.0


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "gdmlt.cli", *args], capture_output=True, text=True, cwd=ROOT)


def test_cli_renders_builtin(tmp_path):
    out = tmp_path / "c.exr"
    r = _cli("render", "cornell", "-o", str(out), "--spp", "2", "--width", "20", "--height", "10", "--no-nee", "--max-bounces", "3",
             "--method", "gdpt", "--recon", "l2", "--alpha-rec", "0.3")
    assert r.returncode == 0, r.stderr
    img = read_exr(out)
    assert img.shape == (10, 20, 3) and np.isfinite(img).all()
    assert (tmp_path / "c.png").stat().st_size > 0
    assert read_exr(out, "GD Gradient X").shape == (10, 20, 3)


@pytest.mark.parametrize("args", [
    ["render", "cornell", "-o", "x.exr", "--method", "magic"],
    ["render", "cornell", "-o", "x.exr", "--spp", "-3"],
    ["render", "cornell", "-o", "x.exr", "--time", "soon"],
    ["render", "nowhere.obj", "-o", "x.exr"],
    ["render", "cornell", "-o", "x.png"],
])
def test_cli_bad_values_exit_2(args):
    r = _cli(*args)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "error" in r.stderr


def test_cli_missing_blend_file_is_an_error():
    r = _cli("render", "missing.blend", "-o", "x.exr")
    assert r.returncode == 1 and "not found" in r.stderr


@pytest.mark.parametrize("method", ["gdpt", "pssmlt", "gdpssmlt"])
def test_every_method_writes_denoising_passes(method):
    """Blender's compositor Denoise node needs albedo and normal from every method: each
    method's passes estimate the same first-hit albedo and normal as path tracing's (pixel
    by pixel, within the jitter noise of a few samples per pixel), albedo in [0, 1], normals
    at most unit length (shorter where a pixel straddles an edge)."""
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 24, 24))
    ref = gdmlt.render(scene, method="pt", spp=64, seed=3)["layers"]
    layers = gdmlt.render(scene, method=method, spp=4, seed=3)["layers"]
    for name in ("Denoising Albedo", "Denoising Normal"):
        got, want = layers[name], ref[name]
        assert got.shape == want.shape == (24, 24, 3)
        assert np.abs(got - want).mean() < 0.03, (name, np.abs(got - want).mean())
    assert 0.0 <= layers["Denoising Albedo"].min() and layers["Denoising Albedo"].max() <= 1.0 + 1e-6
    assert np.linalg.norm(layers["Denoising Normal"], axis=2).max() <= 1.0 + 1e-4


def test_trace_rays_batch_api():
    """Scene.trace_rays (used by gdmlt raybench): hits where a ray must hit, misses where it
    cannot, occlusion consistent with closest hits, same answer on 1 and all threads."""
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 8, 8))
    rng = np.random.default_rng(0)
    o = (rng.random((5000, 3)) * 1.6 - 0.8).astype(np.float32)  # inside the box
    d = rng.normal(size=(5000, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t, prim = scene.trace_rays(o, d)
    t1, prim1 = scene.trace_rays(o, d, threads=1)
    assert np.array_equal(prim, prim1) and np.array_equal(t, t1)
    # the box is closed except the light opening and the camera side: most rays hit
    assert (prim >= 0).mean() > 0.7 and np.all(t[prim >= 0] > 0) and np.all(np.isinf(t[prim < 0]))
    _, occ = scene.trace_rays(o, d, occlusion=True)
    assert np.array_equal(occ >= 0, prim >= 0)
    # packets of eight (4999 rays: the last packet is partial) find what single rays find
    tp, primp = scene.trace_rays(o[:4999], d[:4999], packets=True)
    assert np.array_equal(tp, t[:4999]) and np.array_equal(primp, prim[:4999])
    far = np.full((3, 3), 100.0, np.float32)
    _, miss = scene.trace_rays(far, np.tile(np.array([[0.0, 0.0, 1.0]], np.float32), (3, 1)))
    assert np.all(miss == -1)
    with pytest.raises(ValueError, match="same number"):
        scene.trace_rays(o, d[:10])


def test_the_cpu_specific_core_is_loaded_where_the_cpu_runs_it_and_can_be_refused():
    from gdmlt import _core

    expected = "x86-64-v3" if _core.cpu_supports_x86_64_v3() else "portable"
    assert gdmlt.BUILD_TARGET == expected  # `make build` builds both on x86-64
    out = subprocess.run([sys.executable, "-c", "import gdmlt; print(gdmlt.BUILD_TARGET)"],
                         env={**__import__("os").environ, "GDMLT_CPU": "portable"},
                         capture_output=True, text=True, check=True).stdout.strip()
    assert out == "portable"


@pytest.mark.parametrize("method", ["pt", "gdpt"])
def test_portable_and_v3_cores_render_the_same_image(method):
    """The two builds differ only in instruction selection (FMA changes rounding): with the
    same seed their images agree to float precision almost everywhere, and their means to
    well inside the Monte Carlo noise. pt traces its camera rays as packets; gdpt's shift
    starts from them."""
    from gdmlt import _core

    if not _core.cpu_supports_x86_64_v3():
        pytest.skip("this CPU does not run the x86-64-v3 build")
    from gdmlt import _core_v3

    imgs = []
    for mod in (_core, _core_v3):
        sc = mod.Scene(mod.builtin_scene("cornell", 24, 24))
        imgs.append(mod.render(sc, method=method, spp=64, seed=5, threads=1)["layers"]["Combined"])
    a, b = imgs
    assert abs(a.mean() - b.mean()) < 2e-3 * a.mean()
    close = np.abs(a - b) <= 1e-4 * np.maximum(1, np.abs(a))
    assert close.mean() > 0.5, f"only {close.mean():.2f} of the pixels agree"


def _brute_force_hits(pos, tris, o, d):
    """Closest hits by testing every triangle (Möller–Trumbore in float64): the reference
    the BVH must reproduce. (t, triangle), inf and −1 for a miss."""
    v0, v1, v2 = (pos[tris[:, k]].astype(np.float64) for k in range(3))
    e1, e2 = v1 - v0, v2 - v0
    best_t = np.full(len(o), np.inf)
    best = np.full(len(o), -1, np.int64)
    for s in range(0, len(o), 256):
        oo, dd = o[s:s + 256, None].astype(np.float64), d[s:s + 256, None].astype(np.float64)
        p = np.cross(dd, e2)
        det = np.einsum("rtk,tk->rt", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = oo - v0
            u = np.einsum("rtk,rtk->rt", tv, p) * inv
            q = np.cross(tv, e1)
            v = np.einsum("rtk,rtk->rt", np.broadcast_to(dd, q.shape), q) * inv
            t = np.einsum("rtk,tk->rt", q, e2) * inv
        ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        t = np.where(ok, t, np.inf)
        best[s:s + 256] = np.where(np.isfinite(t.min(1)), t.argmin(1), -1)
        best_t[s:s + 256] = t.min(1)
    return best_t, best


def test_v3_core_traces_the_rays_the_portable_core_traces():
    """The x86-64-v3 build's BVH (its AVX2 node and leaf tests) against the portable build's
    and against testing every triangle: closest hits (single rays and packets of eight),
    occlusion, coherent camera rays and incoherent rays, on a bumpy sphere inside the Cornell
    box. FMA moves t by rounding and may flip a ray that grazes an edge to the neighbour (or
    through the crack); nothing else may differ."""
    from gdmlt import _core

    if not _core.cpu_supports_x86_64_v3():
        pytest.skip("this CPU does not run the x86-64-v3 build")
    from gdmlt import _core_v3
    from gdmlt_bench.raybench import bumpy_sphere, rays

    cams = gdmlt.builtin_scene("cornell", 8, 8)
    sphere, sphere_tris = bumpy_sphere(3000)
    meshes = [(np.asarray(m["positions"], np.float32), np.asarray(m["indices"], np.uint32)) for m in cams["meshes"]]
    meshes.append((0.5 * sphere, sphere_tris))
    offsets = np.cumsum([0] + [len(p) for p, _ in meshes])
    pos = np.concatenate([p for p, _ in meshes])
    tris = np.concatenate([t + o for (_, t), o in zip(meshes, offsets)]).astype(np.uint32)
    desc = {"meshes": [{"name": "m", "positions": pos, "indices": tris}], "materials": [], "lights": [],
            "camera": cams["camera"]}
    rng = np.random.default_rng(7)
    lo, hi = pos.min(0), pos.max(0)
    for kind in ("coherent", "incoherent"):
        o, d = rays(kind, 4096 - 3, lo, hi, rng)  # the last packet of eight is partial
        ref_t, _ = _brute_force_hits(pos, tris, o, d)
        found = {}
        for mod in (_core, _core_v3):
            scene = mod.Scene(desc)
            t, prim = scene.trace_rays(o, d, threads=1)
            tp, primp = scene.trace_rays(o, d, threads=1, packets=True)
            _, occ = scene.trace_rays(o, d, threads=1, occlusion=True)
            name = mod.__name__
            assert np.array_equal(tp, t) and np.array_equal(primp, prim), f"{name} {kind}: packets differ"
            assert np.array_equal(occ >= 0, prim >= 0), f"{name} {kind}: occlusion differs"
            # (the core drops degenerate triangles, so its ids are not the input's: t decides)
            assert (np.isfinite(t) != np.isfinite(ref_t)).mean() < 1e-3, f"{name} {kind}: hits and misses differ"
            hit = np.isfinite(ref_t) & np.isfinite(t)
            close = np.isclose(t[hit], ref_t[hit], rtol=1e-4, atol=1e-5)
            assert hit.mean() > 0.3 and close.mean() > 0.998, f"{name} {kind}: t differs ({1 - close.mean():.4f})"
            found[name] = (t, prim)
        (ta, pa), (tb, pb) = found.values()
        # The builds agree on t but where a ray grazes an edge: the coherent grid runs along
        # the sphere's meridians and across the walls' diagonals, where the (not watertight)
        # triangle test of either build may let 1 ray in 1000 through to the next surface
        # (measured: 5 of 3969 each, different rays) or name either triangle (0.7% of them).
        assert np.isclose(ta, tb, rtol=1e-5, atol=1e-6).mean() > 0.995, f"{kind}: the builds' t differ"
        assert (pa == pb).mean() > 0.99, f"{kind}: {(pa != pb).mean():.4f} of the rays hit other triangles"


def test_builtin_scene_dicts_carry_every_material_feature():
    """The built-in scenes reach Python whole (the CLI and the benchmarks build them from
    these dicts): transparency, alpha textures with the meshes' UVs, specular layers."""
    veil = gdmlt.builtin_scene("veil", 8, 8)
    mats = {m["name"]: m for m in veil["materials"]}
    assert mats["Veil"]["transparency"] == pytest.approx(0.6)
    assert np.allclose(mats["Veil"]["transparent_color"], (1.0, 0.7, 0.4))
    lace = veil["textures"][mats["Lace"]["alpha_texture"]]
    assert (lace["width"], lace["height"]) == (4, 4) and sorted(set(lace["pixels"][::3])) == [0.0, 0.25, 0.5, 1.0]
    canopy = [m for m in veil["meshes"] if m["name"] == "Canopy"][0]
    assert canopy["uvs"].shape == (6, 2)
    spheres = {m["name"]: m for m in gdmlt.builtin_scene("spheres", 8, 8)["materials"]}
    assert spheres["FloorPlastic"]["specular_ior"] == pytest.approx(2.2)
    # and the dicts build: the same scene as the core's own (the image of a lit, finite render)
    img = gdmlt.render(gdmlt.Scene(veil), spp=4, seed=1)["layers"]["Combined"]
    assert np.isfinite(img).all() and img.mean() > 0


@pytest.mark.parametrize("method", gdmlt.METHODS)
def test_transparent_film_writes_rgba_exr_and_straight_alpha_png(tmp_path, method):
    """Issue 17: a render with a transparent film has an "Alpha" layer; the CLI's writer puts
    it into Combined's A channel (EXR, colour premultiplied) and the PNG stores straight alpha
    (colour divided by alpha, as Blender saves it). The Cornell box without its back wall:
    the world behind the opening is transparent, the walls opaque."""
    from PIL import Image

    from gdmlt.cli import write_layers

    desc = gdmlt.builtin_scene("cornell", 24, 24)
    desc["meshes"] = [m for m in desc["meshes"] if m["name"] != "BackWall"]
    desc["world"] = (0.3, 0.5, 0.9)
    desc["camera"]["film_transparent"] = True
    layers = gdmlt.render(gdmlt.Scene(desc), method=method, spp=16, seed=1)["layers"]
    alpha = layers["Alpha"]
    assert alpha.shape == (24, 24, 1) and alpha.min() < 0.01 and alpha.max() > 0.99
    write_layers(tmp_path / "t.exr", layers, png=True)
    rgba = read_exr(tmp_path / "t.exr", "RGBA")
    assert rgba.shape == (24, 24, 4)
    np.testing.assert_array_equal(rgba[..., 3], alpha[..., 0])
    png = np.asarray(Image.open(tmp_path / "t.png"))
    assert png.shape == (24, 24, 4)
    np.testing.assert_array_equal(png[..., 3], np.round(np.clip(alpha[..., 0], 0, 1) * 255).astype(np.uint8))
    # where the camera sees the world only, the colour is transparent black, not the sky
    sky = alpha[..., 0] < 1e-6
    if method == "bdpt":
        # (light tracing adds a wall's light to every pixel whose filter reaches it — within
        # 1.5 pixels, Blackman–Harris — where 16 camera samples may all have missed the wall:
        # the sky whose neighbours are sky too)
        k = 1
        padded = np.pad(sky, k, constant_values=True)
        sky = np.all([padded[k + dy:k + dy + sky.shape[0], k + dx:k + dx + sky.shape[1]]
                      for dy in range(-k, k + 1) for dx in range(-k, k + 1)], axis=0)
    assert sky.sum() > 20 and np.abs(rgba[sky][:, :3]).max() < 1e-6
    opaque = desc.copy()
    opaque["camera"] = dict(desc["camera"], film_transparent=False)
    assert "Alpha" not in gdmlt.render(gdmlt.Scene(opaque), method="pt", spp=1)["layers"]


@pytest.mark.parametrize("method", gdmlt.METHODS)
def test_data_passes_are_the_same_for_every_method(method):
    """`data_passes=True` adds Depth (1 channel, 1e10 where nothing is hit) and Position: the
    first camera sample's, so the same whatever the method; without it they are absent."""
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 12, 12))
    layers = gdmlt.render(scene, method=method, spp=4, seed=2, data_passes=True)["layers"]
    ref = gdmlt.render(scene, method="pt", spp=1, seed=2, data_passes=True)["layers"]
    assert layers["Depth"].shape == (12, 12, 1) and layers["Position"].shape == (12, 12, 3)
    np.testing.assert_array_equal(layers["Depth"], ref["Depth"])
    np.testing.assert_array_equal(layers["Position"], ref["Position"])
    assert (layers["Depth"] == 1e10).any() and (layers["Depth"] < 10).any()
    assert "Depth" not in gdmlt.render(scene, method=method, spp=1)["layers"]


def test_path_guiding_from_the_api_and_the_cli(tmp_path):
    """Path guiding (opt-in) learns during a pt render: iterations ending at 1, 3, 7, 15 spp,
    several regions, a finite image that differs from the unguided one; another method says
    it renders without it; the CLI takes --guiding."""
    scene = gdmlt.Scene(gdmlt.builtin_scene("gap", 48, 40))
    guided = gdmlt.render(scene, method="pt", spp=15, guiding=True, seed=2)
    plain = gdmlt.render(scene, method="pt", spp=15, seed=2)
    st = guided["stats"]
    assert st["guide_iterations"] == 4 and st["guide_regions"] > 1, st
    assert plain["stats"]["guide_iterations"] == 0
    img = guided["layers"]["Combined"]
    assert np.isfinite(img).all() and not np.array_equal(img, plain["layers"]["Combined"])
    other = gdmlt.render(scene, method="gdpt", spp=2, guiding=True)["stats"]
    assert any("guiding applies to pt only" in w for w in other["warnings"]), other["warnings"]
    out = tmp_path / "g.exr"
    r = _cli("render", "gap", "-o", str(out), "--spp", "7", "--width", "24", "--height", "20", "--method", "pt",
             "--guiding")
    assert r.returncode == 0, r.stderr
    assert np.isfinite(read_exr(out)).all()


def test_bidirectional_methods_from_the_api_and_the_cli(tmp_path):
    """`bdpt` and `pssmlt` over bidirectional states render from the API and the CLI: finite
    images whose mean agrees with `pt`'s (the spheres: mirror and glass caustics, 3 seeds,
    within 4 standard errors of the seeds' spread plus 2%), a method that has no bidirectional
    states says so, and `--method bdpt` / `--bidirectional` are taken by the CLI."""
    scene = gdmlt.Scene(gdmlt.builtin_scene("spheres", 32, 32))

    def means(**kw):
        return np.array([gdmlt.render(scene, spp=kw.pop("spp_", 64), seed=s, max_bounces=6, **kw)["layers"]
                         ["Combined"].mean() for s in (1, 2, 3)])

    ref = means(method="pt", spp_=256)
    for kw in (dict(method="bdpt", spp_=32), dict(method="pssmlt", bidirectional=True, spp_=64)):
        m = means(**kw)
        assert np.isfinite(m).all()
        tol = 4 * np.sqrt(m.var(ddof=1) / 3 + ref.var(ddof=1) / 3) + 0.02 * ref.mean()
        assert abs(m.mean() - ref.mean()) <= tol, (kw, m, ref)
    other = gdmlt.render(scene, method="gdpt", spp=2, bidirectional=True)["stats"]
    assert any("bidirectional Markov states apply to pssmlt only" in w for w in other["warnings"]), other["warnings"]
    for args in (["--method", "bdpt"], ["--method", "pssmlt", "--bidirectional"]):
        out = tmp_path / "b.exr"
        r = _cli("render", "spheres", "-o", str(out), "--spp", "4", "--width", "24", "--height", "20", *args)
        assert r.returncode == 0, r.stderr
        assert np.isfinite(read_exr(out)).all() and read_exr(out).mean() > 0


def test_pt_reports_its_mean_path_length():
    """Issue 51: samples per second only compare at matched path lengths, so `pt` reports
    its mean segments (closest-hit rays) per path. Each path traces its camera ray and at most
    one segment per bounce plus the last light-finding one (≤ max bounces + 2); more bounces
    allowed never shorten paths; Russian roulette keeps them finite (64 allowed bounces add
    little over 8 in the Cornell box); next-event estimation changes none of it (shadow rays
    are not segments), and the other methods report 0."""
    sc = gdmlt.Scene(gdmlt.builtin_scene("cornell", 24, 24))
    means = {}
    for b in (0, 1, 2, 8, 64):
        for nee in (True, False):
            means[b, nee] = gdmlt.render(sc, method="pt", spp=32, max_bounces=b, nee=nee, seed=3)["stats"][
                "mean_path_segments"]
        assert means[b, True] == means[b, False]
        assert 1.0 <= means[b, True] <= b + 2, (b, means[b, True])
    ordered = [means[b, True] for b in (0, 1, 2, 8, 64)]
    assert ordered == sorted(ordered) and ordered[0] < ordered[2]
    assert means[64, True] < 1.1 * means[8, True]
    assert gdmlt.render(sc, method="gdpt", spp=2)["stats"]["mean_path_segments"] == 0.0
