"""The denoising study of docs/denoising.md: each method's image after ways of combining it
with Intel Open Image Denoise, by relMSE and 8×8 block error against a `pt` reference.

Usage: .venv/bin/python tools/denoise_study.py SCENE [BUDGET_S] [REFERENCE_SPP]
SCENE: a built-in name (cornell, gap, …) or a .blend file; 128² images."""

import sys as _sys
from pathlib import Path as _Path

_sys.path.insert(0, str(_Path(__file__).resolve().parent.parent / "benchmarks"))  # gdmlt_bench

import sys
import time

import numpy as np

import gdmlt
from gdmlt_bench.bench import block_error, rel_mse, scene_desc
from gdmlt.oidn import denoise_image


def variants(layers):
    """name → image: the raw render, OIDN with and without prefiltered guides and, for the
    gradient-domain methods, OIDN on the primal followed by the screened Poisson solve."""
    a, n = layers["Denoising Albedo"], layers["Denoising Normal"]
    out = {"raw": layers["Combined"],
           "oidn": denoise_image(layers["Combined"], a, n, prefilter=False),
           "oidn+prefilter": denoise_image(layers["Combined"], a, n, prefilter=True)}
    if "GD Primal" in layers:
        d = layers["Very Direct"]
        dx, dy = layers["GD Gradient X"], layers["GD Gradient Y"]
        primal = denoise_image(layers["GD Primal"], a, n, prefilter=False)
        out["oidn(primal)"] = primal
        for norm in ("l2", "l1"):
            for alpha in (0.2, 1.0, 4.0):
                out[f"{norm}(oidn(primal), a={alpha})"] = gdmlt.reconstruct(
                    np.ascontiguousarray(primal - d), dx, dy, d, alpha, norm)
        l2 = gdmlt.reconstruct(np.ascontiguousarray(layers["GD Primal"] - d), dx, dy, d, 0.2, "l2")
        out["oidn(l2)"] = denoise_image(l2, a, n, prefilter=False)
    return out


def main(argv):
    scene = argv[0]
    budget = float(argv[1]) if len(argv) > 1 else 2.0
    ref_spp = int(argv[2]) if len(argv) > 2 else 4096
    desc, label = scene_desc(scene, (128, 128))
    sc = gdmlt.Scene(desc)
    t0 = time.perf_counter()
    ref = gdmlt.render(sc, method="pt", spp=ref_spp, seed=999)["layers"]["Combined"]
    print(f"# {label}: reference pt {ref_spp} spp ({time.perf_counter() - t0:.0f} s), budget {budget:g} s")
    for m in ("pt", "gdpt", "gdpssmlt"):
        layers = gdmlt.render(sc, method=m, spp=10 ** 7, time_limit=budget, seed=1)["layers"]
        for name, img in variants(layers).items():
            print(f"{label:10} {m:9} {name:26} relMSE {rel_mse(img, ref):9.3g}  block {block_error(img, ref) * 100:6.2f}%",
                  flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
