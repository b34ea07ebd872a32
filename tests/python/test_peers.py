"""The peer translation used by the benchmarks (gdmlt_bench.peers): it must render the same scene
as GDMLT, or refuse. Cycles (bpy, always installed for the tests) checks the translation
end to end; Mitsuba and LuxCore are benchmark-only dependencies."""

import numpy as np
import pytest

import gdmlt
from gdmlt_bench import peers


def test_scenes_a_peer_cannot_reproduce_are_refused_by_name():
    with pytest.raises(peers.Unsupported, match="not diffuse"):
        peers.simple_scene(gdmlt.builtin_scene("spheres", 16, 16))
    desc = gdmlt.builtin_scene("cornell", 16, 16)
    desc["lights"] = [{"type": "POINT", "name": "L"}]
    with pytest.raises(peers.Unsupported, match="lamp"):
        peers.simple_scene(desc)


def test_emitters_are_doubled_back_to_back():
    simple = peers.simple_scene(gdmlt.builtin_scene("cornell", 16, 16))
    shapes = peers.two_sided(simple)
    emitters = [s for s in shapes if any(s["emission"])]
    assert len(shapes) == len(simple["shapes"]) + 1 and len(emitters) == 2
    front, back = emitters
    p, t = front["positions"], front["indices"]
    n = np.cross(p[t[0, 1]] - p[t[0, 0]], p[t[0, 2]] - p[t[0, 0]])
    q, u = back["positions"], back["indices"]
    m = np.cross(q[u[0, 1]] - q[u[0, 0]], q[u[0, 2]] - q[u[0, 0]])
    assert np.dot(n, m) < 0  # faces the other way
    gap = (p - q) @ (n / np.linalg.norm(n))
    assert np.all(gap > 0) and np.all(gap < 1e-3)  # just behind


def test_the_scene_rebuilt_in_cycles_renders_what_gdmlt_renders():
    desc = gdmlt.builtin_scene("cornell", 32, 32)
    ref = gdmlt.render(gdmlt.Scene(desc), method="pt", spp=1024, seed=3, max_bounces=4)["layers"]["Combined"]
    (img,), times, _ = peers.cycles_render([1.5], 4, True, desc=desc)
    assert img.shape == ref.shape
    # Same framing and light: means within 1%; 4×4-pixel blocks (clipped at 1 so the light's
    # anti-aliased edge does not dominate) within 2% of the mean in rms — measured 0.55%, while
    # two PT renders of 1024 spp differ by 0.8% and a one-pixel shift of the image gives 20–34%.
    b = lambda x: np.minimum(x, 1).reshape(8, 4, 8, 4, 3).mean(axis=(1, 3))  # noqa: E731
    assert abs(img.mean() - ref.mean()) < 0.01 * ref.mean()
    assert np.sqrt(np.mean((b(img) - b(ref)) ** 2)) < 0.02 * ref.mean()


@pytest.mark.parametrize("nee", [True, False])
def test_mitsuba_with_gdmlt_roulette_renders_what_gdmlt_renders(nee):
    """pathbench's Mitsuba settings (GDMLT's Russian roulette in integrators of our own:
    Mitsuba's emitter sampling + MIS with NEE, BSDF sampling without) render the same image
    as GDMLT: equal means (2%: 64k paths each,
    image-mean noise ≈ 0.4%) and equal pixels on average over 8×8 blocks. Benchmark-only
    dependency: skipped where Mitsuba or its LLVM library is missing."""
    pytest.importorskip("mitsuba")
    try:
        mi, dr = peers.import_mitsuba(2)
    except Exception as e:  # noqa: BLE001 — no libLLVM: nothing to compare
        pytest.skip(f"mitsuba llvm variant unavailable: {e}")
    desc = gdmlt.builtin_scene("cornell", 32, 32)
    ref = gdmlt.render(gdmlt.Scene(desc), method="pt", spp=1024, seed=3, nee=nee, max_bounces=4)["layers"]["Combined"][..., :3]
    msc = peers.mitsuba_scene(mi, peers.simple_scene(desc), 4, nee, rr_depth=gdmlt.RR_START_DEPTH)
    img = peers.mitsuba_render(mi, msc, 1024, seed=1)
    assert img.shape == ref.shape
    assert abs(img.mean() / ref.mean() - 1) < 0.02
    blocks = lambda a: a.reshape(4, 8, 4, 8, 3).mean(axis=(1, 3))  # noqa: E731
    b, r = blocks(img), blocks(ref)
    assert np.abs(b - r).mean() < 0.05 * r.mean()


def test_cycles_denoised_rows_are_cycles_own_oidn_of_the_same_render():
    """bench --denoise compares with Cycles as artists render (its OIDN on): the raw image is
    the Noisy Image pass of the render whose Combined is denoised — same light, less noise."""
    desc = gdmlt.builtin_scene("cornell", 32, 32)
    ref = gdmlt.render(gdmlt.Scene(desc), method="pt", spp=2048, seed=3, max_bounces=4)["layers"]["Combined"]
    (raw,), _, _, (den,) = peers.cycles_render([0.3], 4, True, desc=desc, denoise=True)
    assert raw.shape == den.shape == ref.shape
    assert not np.array_equal(raw, den)
    assert abs(den.mean() - raw.mean()) < 0.03 * raw.mean()
    rms = lambda x: float(np.sqrt(np.mean((np.minimum(x, 1) - np.minimum(ref, 1)) ** 2)))  # noqa: E731
    assert rms(den) < rms(raw)


def test_block_error_sees_low_frequencies_that_relmse_weighs_like_noise():
    from gdmlt_bench.bench import block_error, flip_error, rel_mse

    rng = np.random.default_rng(1)
    ref = np.full((64, 64, 3), 0.5, np.float32)
    # ±10% noise, zero mean in every 8×8 block, against a 2% offset of whole blocks
    noise = np.tile(np.where((np.indices((8, 8)).sum(0) % 2) == 0, 0.05, -0.05)[..., None], (8, 8, 3))
    blotch = np.kron(rng.choice([-0.01, 0.01], (8, 8)), np.ones((8, 8)))[..., None] * np.ones(3)
    assert rel_mse(ref + noise, ref) > 10 * rel_mse(ref + blotch, ref)
    assert block_error(ref + noise, ref) < 1e-6
    assert abs(block_error(ref + blotch, ref) - 0.01 / 0.51) < 1e-4
    f = flip_error(ref + noise, ref)
    assert np.isnan(f) or f > flip_error(ref, ref)


def test_reference_noise_is_what_a_noisy_reference_adds_to_relmse():
    """A reference averaged from two noisy halves adds its own variance to every image's
    relMSE; `reference_noise` measures it from the halves, so that relMSE less it is the
    error against the true image (within the estimate's spread over 64² pixels), for an image
    noisier than the reference and for one cleaner than it."""
    from gdmlt_bench.bench import block_error, reference_noise, rel_mse

    rng = np.random.default_rng(7)
    truth = rng.uniform(0.2, 2.0, (64, 64, 3)).astype(np.float32)
    sd = 0.05 * truth
    a, b = truth + sd * rng.standard_normal(truth.shape), truth + sd * rng.standard_normal(truth.shape)
    ref, (noise, block_noise) = reference_noise(a, b)
    assert np.allclose(ref, 0.5 * (a + b))
    expected = float(np.mean((0.5 * sd) ** 2 * 2 / (truth ** 2 + 0.01)))  # Var of the mean of two
    assert abs(noise / expected - 1) < 0.05
    for scale in (3.0, 0.3):
        x = truth + scale * sd * rng.standard_normal(truth.shape)
        against_truth = rel_mse(x, truth)
        assert abs((rel_mse(x, ref) - noise) / against_truth - 1) < 0.1, scale
        # uncorrected, the cleaner image's error would be overstated several times
        if scale < 1:
            assert rel_mse(x, ref) > 2 * against_truth
    assert abs(block_noise / block_error(ref, truth) - 1) < 0.15


def test_bench_runs_average_each_cell_over_seeds_for_gdmlt_and_cycles(monkeypatch):
    """`bench --runs N`: every cell is the mean over seeds 1…N of the metrics of N renders,
    GDMLT's and Cycles' alike (one run's ratio moves by up to ±30%). The renderers are
    replaced by images whose error is known per seed, so the mean is checked exactly."""
    from gdmlt_bench import bench

    desc = gdmlt.builtin_scene("cornell", 16, 16)
    truth = gdmlt.render(gdmlt.Scene(desc), method="pt", spp=4, seed=9, max_bounces=2)["layers"]["Combined"]
    seen = {"gdmlt": [], "cycles": []}

    def fake_render(scene, method="pt", seed=1, **kw):
        if kw.get("spp", 0) < 10 ** 6:  # the reference halves: the truth itself
            return {"layers": {"Combined": truth.copy()}, "stats": {}}
        seen["gdmlt"].append(seed)
        return {"layers": {"Combined": truth * (1 + 0.1 * seed)}, "stats": {}}

    def fake_cycles(budgets, max_bounces, nee, threads=0, seed=1, **kw):
        seen["cycles"].append(seed)
        return [truth * (1 - 0.05 * seed) for _ in budgets], [0.1 for _ in budgets], [1 for _ in budgets]

    monkeypatch.setattr(gdmlt, "render", fake_render)
    monkeypatch.setattr(peers, "cycles_render", fake_cycles)
    monkeypatch.setattr(peers, "simple_scene", lambda d: d)
    lines = []
    rows = bench.run("cornell", (16, 16), budgets=(0.5, 1.0), methods=("pt",), modes=(True,), reference_spp=4,
                     max_bounces=2, peers=("cycles",), out=lines.append, runs=3)
    assert seen["gdmlt"] == [1, 2, 3, 1, 2, 3] and seen["cycles"] == [1, 2, 3]
    cells = {name: c for name, _, c in rows}
    for name, images in (("pt", [truth * (1 + 0.1 * s) for s in (1, 2, 3)]),
                         ("cycles", [truth * (1 - 0.05 * s) for s in (1, 2, 3)])):
        want = np.mean([bench.rel_mse(i, truth) for i in images])
        for cell in cells[name]:
            assert abs(cell[0] / want - 1) < 1e-5, name
            assert cell[0] != bench.rel_mse(images[0], truth)
    assert any("mean of 3 runs" in ln for ln in lines)
