"""`gdmlt bench`: error against a converged reference at equal wall-clock budgets, per
method and light mode. Prints a table (relMSE and SMAPE as defined in ALGORITHM.md §5b).
It measures; it does not pass or fail."""

import time

import numpy as np

EPS = 1e-2


def rel_mse(img, ref):
    return float(np.mean((img - ref) ** 2 / (ref ** 2 + EPS)))


def smape(img, ref):
    return float(np.mean(2 * np.abs(img - ref) / (np.abs(img) + np.abs(ref) + EPS)))


def run(scene_name="cornell", size=128, budgets=(1.0, 2.0, 4.0), methods=("pt", "gdpt", "pssmlt", "gdpssmlt"),
        modes=(True, False), reference_spp=8192, threads=0, out=print):
    import gdmlt

    scene = gdmlt.Scene(gdmlt.builtin_scene(scene_name, size, size))
    out(f"# {scene_name} {size}x{size}, threads={threads or 'all'}, reference: pt with NEE at {reference_spp} spp")
    t0 = time.perf_counter()
    ref = gdmlt.render(scene, method="pt", spp=reference_spp, nee=True, seed=12345, threads=threads)["layers"]["Combined"]
    out(f"# reference took {time.perf_counter() - t0:.1f} s")
    out(f"{'method':10} {'nee':5} " + " ".join(f"{'relMSE@' + str(b) + 's':>14} {'SMAPE':>7}" for b in budgets))
    rows = []
    for nee in modes:
        for m in methods:
            cells = []
            for b in budgets:
                res = gdmlt.render(scene, method=m, spp=10 ** 7, time_limit=b, nee=nee, seed=1, threads=threads)
                img = res["layers"]["Combined"]
                cells.append((rel_mse(img, ref), smape(img, ref)))
            rows.append((m, nee, cells))
            out(f"{m:10} {str(nee):5} " + " ".join(f"{r:14.4g} {s:7.4f}" for r, s in cells))
    return rows
