"""One frame across processes: partial renders merged (gdmlt merge) and the Dask driver.
Merging N partials must equal, statistically, one render of N× the budget; one partial
merged alone must equal the plain render; a worker killed mid-render must not corrupt the
merge."""

import os
import threading
import time

import numpy as np
import pytest

import gdmlt
from gdmlt import distributed as dist
from conftest import block_means

SIZE = 24


@pytest.fixture(scope="module")
def cornell():
    return gdmlt.builtin_scene("cornell", SIZE, SIZE)


@pytest.fixture(scope="module")
def reference(cornell):
    return block_means(gdmlt.render(gdmlt.Scene(cornell), method="pt", spp=4096, max_bounces=4, seed=99)
                       ["layers"]["Combined"], 4)


@pytest.mark.parametrize("method", ["pt", "gdpt", "gdpssmlt"])
def test_one_partial_merged_alone_is_the_plain_render(cornell, method, tmp_path):
    settings = {"method": method, "spp": 8, "max_bounces": 4, "seed": 5, "reconstruction": "l1"}
    p = dist.render_partial(cornell, 0, 1, settings)
    dist.save_partial(tmp_path / "p.npz", p)
    merged = dist.merge([dist.load_partial(tmp_path / "p.npz")])
    plain = gdmlt.render(gdmlt.Scene(cornell), **settings)["layers"]["Combined"]
    assert np.allclose(merged["Combined"], plain, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("method", ["pt", "gdpt", "gdpssmlt"])
def test_partials_of_a_transparent_film_merge_to_the_plain_render_with_its_alpha(cornell, method, tmp_path):
    """A transparent film's Alpha layer is carried by partials and merged; one partial merged
    alone is the plain render, alpha and colour (the reconstruction of the merged gradients
    leaves the world's pixels at 0, as the core does)."""
    desc = dict(cornell, meshes=[m for m in cornell["meshes"] if m["name"] != "BackWall"], world=(0.3, 0.5, 0.9),
                camera=dict(cornell["camera"], film_transparent=True))
    settings = {"method": method, "spp": 8, "max_bounces": 4, "seed": 5, "reconstruction": "l1"}
    dist.save_partial(tmp_path / "p.npz", dist.render_partial(desc, 0, 1, settings))
    merged = dist.merge([dist.load_partial(tmp_path / "p.npz")])
    plain = gdmlt.render(gdmlt.Scene(desc), **settings)["layers"]
    np.testing.assert_array_equal(merged["Alpha"], plain["Alpha"])
    assert (plain["Alpha"] <= 0).sum() > 20
    assert np.allclose(merged["Combined"], plain["Combined"], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("method, spp", [("pt", 16), ("gdpt", 16), ("gdpssmlt", 32)])
def test_merged_partials_converge_like_one_render_of_the_summed_budget(cornell, reference, method, spp):
    """4 partials merged: the error of the merged image against a PT reference (4×4 blocks)
    is what averaging 4 independent renders gives — within 2.5× the noise measured from the
    partials' own spread (÷√4, plus the reference's noise) — and its mean within the 1e-3
    Student-t bound of the partials' spread. A
    merge that dropped or double-counted a partial, or mixed seeds, fails this."""
    settings = {"method": method, "spp": spp, "max_bounces": 4, "seed": 11}
    partials = [dist.render_partial(cornell, k, 4, settings) for k in range(4)]
    merged = block_means(dist.merge(partials)["Combined"], 4)
    each = np.stack([block_means(p["layer:Combined"], 4) for p in partials])
    var = each.var(axis=0, ddof=1).mean()  # per-block variance of one partial
    expected = np.sqrt(var * (1 / 4 + 4 * spp / 4096))
    err = np.sqrt(np.mean((merged - reference) ** 2))
    assert err < 2.5 * expected + 1e-4, (err, expected)
    sd_mean = each.mean(axis=(1, 2, 3)).std(ddof=1) / 2
    # σ from 4 partials has 3 degrees of freedom: the two-sided 1e-3 Student-t quantile is
    # 12.92, not 4 (a normal quantile made this fail by chance: gdpssmlt's mean is spread
    # mostly by each partial's own normalisation estimate)
    assert abs(merged.mean() - reference.mean()) < 12.92 * sd_mean + 1e-3 * reference.mean()


def test_partials_have_distinct_seeds_and_refuse_mismatched_merges(cornell):
    a = dist.render_partial(cornell, 0, 2, {"method": "pt", "spp": 4})
    b = dist.render_partial(cornell, 1, 2, {"method": "pt", "spp": 4})
    assert not np.array_equal(a["layer:Combined"], b["layer:Combined"])
    c = dist.render_partial(cornell, 1, 2, {"method": "gdpt", "spp": 4})
    with pytest.raises(ValueError, match="rendered with method gdpt where .* used pt"):
        dist.merge([a, c])
    with pytest.raises(ValueError):
        dist.render_partial(cornell, 2, 2, {"method": "pt", "spp": 4})


def test_dask_local_cluster_survives_a_killed_worker(cornell, reference):
    """Two worker processes on loopback; one is killed while rendering. Its partial is rerun
    (Dask's retries and the nanny's restart) and every partial is merged into a valid image."""
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None, worker_dashboard_address=None)
    try:
        killed = []

        def kill_one():
            time.sleep(1.0)
            with Client(cluster.scheduler_address) as c:
                victim = sorted(c.scheduler_info()["workers"])[0]
                try:
                    c.run(os._exit, 1, workers=[victim])
                except Exception:
                    pass  # the connection to the dying worker breaks, as it should
                killed.append(victim)

        t = threading.Thread(target=kill_one)
        t.start()
        settings = {"method": "gdpt", "spp": 10 ** 6, "time_limit": 2.0, "max_bounces": 4, "seed": 1, "threads": 1}
        layers, dropped = dist.render_dask(cornell, 4, settings, address=cluster.scheduler_address, retries=3)
        t.join()
    finally:
        cluster.close()
    assert killed, "the fault was not injected"
    assert dropped == []
    img = layers["Combined"]
    assert np.isfinite(img).all()
    assert abs(block_means(img, 4).mean() / reference.mean() - 1) < 0.03


def _saved(tmp_path, name, p):
    path = tmp_path / f"{name}.npz"
    dist.save_partial(path, p)
    return path


def test_merge_refuses_what_is_not_one_render_split_k_of_n(cornell, tmp_path):
    """Issue 18 [6]: each of these merged with exit 0 before (other scenes, a partial twice,
    one seed twice, bad work, a NaN pixel that made the whole EXR NaN, int64 layers)."""
    a = dist.render_partial(cornell, 0, 2, {"method": "pt", "spp": 2})
    b = dist.render_partial(cornell, 1, 2, {"method": "pt", "spp": 2})
    assert dist.merge([a, b])["Combined"].shape == (SIZE, SIZE, 3)
    other = gdmlt.builtin_scene("spheres", SIZE, SIZE)
    cases = {
        "another scene": dist.render_partial(other, 1, 2, {"method": "pt", "spp": 2}),
        "same partial": dict(a),
        "one seed": dict(b, seed=a["seed"]),
        "nan work": dict(b, work=float("nan")),
        "negative work": dict(b, work=-1.0),
        "nan pixel": dict(b, **{"layer:Combined": np.where(np.arange(SIZE * SIZE * 3).reshape(SIZE, SIZE, 3) == 7,
                                                             np.nan, b["layer:Combined"]).astype(np.float32)}),
    }
    match = {"another scene": "another scene", "same partial": "same partial", "one seed": "one seed",
             "nan work": "work", "negative work": "work", "nan pixel": "NaN"}
    for what, bad in cases.items():
        with pytest.raises(ValueError, match=match[what]):
            dist.merge([a, bad])
    # on disk: int64 layers and a zip bomb are refused before they are used or inflated
    ints = dict(b, **{"layer:Combined": b["layer:Combined"].astype(np.int64)})
    with pytest.raises(ValueError, match="float32|int64"):
        dist.load_partial(_saved(tmp_path, "ints", ints))
    bomb = dict(b, **{"layer:Huge": np.zeros((4000, 4000, 3), np.float32)})
    path = _saved(tmp_path, "bomb", bomb)
    assert path.stat().st_size < 1_000_000
    with pytest.raises(ValueError, match="inflates"):
        dist.load_partial(path)
    ok = [dist.load_partial(_saved(tmp_path, n, p)) for n, p in (("a", a), ("b", b))]
    assert np.isfinite(dist.merge(ok)["Combined"]).all()


def test_merge_command_exits_1_on_a_bad_partial(cornell, tmp_path):
    import subprocess
    import sys

    from conftest import ROOT

    a = _saved(tmp_path, "a", dist.render_partial(cornell, 0, 2, {"method": "pt", "spp": 2}))
    r = subprocess.run([sys.executable, "-m", "gdmlt.cli", "merge", str(a), str(a), "-o", str(tmp_path / "m.exr")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 1 and "same partial" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "m.exr").exists()


def test_merged_variance_layer_is_the_variance_of_the_weighted_mean(cornell):
    """`pt`'s "Variance" layer (what the denoiser's restore step trusts) merges as the
    variance of a work-weighted mean of independent partials, Σ w²·v (a plain weighted mean
    would overstate it by 1/w), while the colour merges as the weighted mean. A pixel that
    is unknown in any partial (too few samples there) stays unknown."""
    n = gdmlt.VARIANCE_MIN_SAMPLES
    a = dist.render_partial(cornell, 0, 2, {"method": "pt", "spp": n})
    b = dist.render_partial(cornell, 1, 2, {"method": "pt", "spp": n})
    assert a["layer:Variance"].max() < 1e29 and b["layer:Variance"].max() < 1e29
    wa, wb = a["work"] / (a["work"] + b["work"]), b["work"] / (a["work"] + b["work"])
    va, vb = a["layer:Variance"].astype(np.float64), b["layer:Variance"].astype(np.float64)
    merged = dist.merge([a, b])
    assert np.allclose(merged["Variance"], wa ** 2 * va + wb ** 2 * vb, rtol=1e-5)
    assert np.allclose(merged["Combined"], wa * a["layer:Combined"] + wb * b["layer:Combined"], rtol=1e-5, atol=1e-7)
    few = dict(b, **{"layer:Variance": b["layer:Variance"].copy()})
    few["layer:Variance"][::3, ::2] = gdmlt.VARIANCE_UNKNOWN  # as where b had too few samples
    v = dist.merge([a, few])["Variance"]
    lattice = np.zeros(v.shape, bool)
    lattice[::3, ::2] = True
    assert np.all(v[lattice] == np.float32(gdmlt.VARIANCE_UNKNOWN))
    assert np.allclose(v[~lattice], (wa ** 2 * va + wb ** 2 * vb)[~lattice], rtol=1e-5)


def test_merge_says_what_differs_and_refuses_a_tampered_index(cornell, tmp_path):
    """Issue 50 [4, 5]: a partial whose header says k = 5 of n = 2 was merged (failed before);
    partials of another resolution were refused as "of another scene" with two hashes, and of
    other settings as "of another settings" (failed before: the size and the words)."""
    a = dist.render_partial(cornell, 0, 2, {"method": "pt", "spp": 2})
    b = dist.render_partial(cornell, 1, 2, {"method": "pt", "spp": 2})
    tampered = dict(b, k=np.int64(5))
    with pytest.raises(ValueError, match="partial 5 of 2"):
        dist.load_partial(_saved(tmp_path, "tampered", tampered))
    with pytest.raises(ValueError, match="0 ≤ K < N"):
        dist.merge([a, dict(b, k=5)])
    small = gdmlt.builtin_scene("cornell", SIZE // 2, SIZE // 2)
    c = dist.render_partial(small, 1, 2, {"method": "pt", "spp": 2})
    with pytest.raises(ValueError, match=f"is {SIZE // 2}×{SIZE // 2} pixels, .* {SIZE}×{SIZE}"):
        dist.merge([a, c])
    d = dist.render_partial(cornell, 1, 2, {"method": "pt", "spp": 3})
    with pytest.raises(ValueError, match="rendered with other settings"):
        dist.merge([a, d])
