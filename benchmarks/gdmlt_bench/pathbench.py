"""`gdmlt pathbench`: path-tracing throughput (camera samples per second) of GDMLT's `pt`
against Mitsuba 3 (`path` with emitter sampling; without it, BSDF sampling as `prb_basic`;
`llvm_ad_rgb`) and LuxCore PATHCPU (Sobol, light sampling on or off), on the same scene arrays,
same resolution, same bounce limit, same thread count, in one run. Scenes: the built-in Cornell
box and the Cornell box with a ~1M-triangle bumpy sphere inside. Each renderer's image mean is
printed as a ratio to GDMLT's to show that all three render the same scene. It measures; it does
not pass or fail.

Same path length: samples/s only compare when every renderer ends its paths alike, so Mitsuba
runs with GDMLT's Russian roulette (from bounce `gdmlt.RR_START_DEPTH`, q = min((max
throughput)^RR_EXPONENT, 1); see `peers.mitsuba_integrator`). Mitsuba's defaults (roulette from depth 5 with
`path`, none with `prb_basic`) trace longer paths per sample; the column `mi default` gives
that rate for reference. LuxCore keeps its own roulette (from depth 3 on the local BSDF weight,
survival at least 0.5), so its paths run longer than GDMLT's.

Timing: GDMLT and Mitsuba are timed around one render call after a warm-up render (Mitsuba's
first call compiles its kernels); scene loading/BVH building is not counted for anyone.
LuxCore runs one session in a child process; its rate is the sample count between two reads of
its film (after 1 s and after the run), so start-up is not counted either."""

from __future__ import annotations

import os
import time

import numpy as np

from . import peers


def cornell_with_sphere(size: int, triangles: int) -> dict:
    import gdmlt

    from .raybench import bumpy_sphere

    desc = gdmlt.builtin_scene("cornell", size, size)
    pos, tris = bumpy_sphere(triangles)
    # the Cornell box spans [-1, 1]^3 (z up); the sphere (radius ≈ 0.32) sits on the floor, front left
    desc["meshes"].append({"name": "BumpySphere", "positions": (pos * 0.3 + np.array([-0.5, -0.55, -0.68])).astype(np.float32),
                           "indices": tris, "material_ids": np.zeros(len(tris), np.uint32)})
    return desc


def rate_gdmlt(sc, w, h, nee, bounces, threads, seconds, method="pt"):
    """Samples/s of one render of `method` long enough to measure (over seconds/4, after a
    warm-up): (rate, image, samples per pixel of that render, mean segments per path — `pt`'s
    `mean_path_segments`, 0 for the other methods)."""
    import gdmlt

    gdmlt.render(sc, method=method, spp=1, nee=nee, seed=7, threads=threads, max_bounces=bounces)
    spp = 1
    while True:
        t = time.perf_counter()
        res = gdmlt.render(sc, method=method, spp=spp, nee=nee, seed=1, threads=threads, max_bounces=bounces)
        dt = time.perf_counter() - t
        if dt > seconds / 4 or spp >= 1 << 16:
            break
        spp = max(spp * 2, int(spp * seconds / max(dt, 1e-3)))
    return w * h * spp / dt, res["layers"]["Combined"], spp, res["stats"].get("mean_path_segments", 0.0)


def _rate_mitsuba(mi, scene, w, h, seconds, rate_hint):
    peers.mitsuba_render(mi, scene, 4)  # compile
    spp = max(4, int(rate_hint * seconds / 4 / (w * h)))
    t = time.perf_counter()
    img = peers.mitsuba_render(mi, scene, spp, seed=1)
    dt = time.perf_counter() - t
    return w * h * spp / dt, img


def run(size=128, triangles=1_000_000, bounces=8, seconds=8.0, thread_counts=None, out=print):
    import gdmlt

    all_threads = os.cpu_count() or 1
    thread_counts = thread_counts or sorted({1, all_threads})
    scenes = [("cornell", gdmlt.builtin_scene("cornell", size, size)),
              (f"cornell+{triangles // 1000}k", cornell_with_sphere(size, triangles))]
    out(f"# gdmlt pathbench: camera samples/s, {size}x{size}, max bounces {bounces} "
        f"(Mitsuba max_depth {bounces + 2}, LuxCore pathdepth {bounces + 1}), ~{seconds:g} s per cell, "
        f"{all_threads} hardware threads")
    out(f"{'scene':16} {'nee':5} {'threads':>7} {'gdmlt Ms/s':>11} {'segments':>8} {'mitsuba Ms/s':>13} "
        f"{'luxcore Ms/s':>13} {'gdmlt/mi':>9} {'gdmlt/lux':>9} {'mean mi/g':>9} {'mean lux/g':>10} {'mi default':>10}")
    try:
        mi, dr = peers.import_mitsuba()
    except Exception as e:  # noqa: BLE001 — a missing peer is reported, not fatal
        out(f"# mitsuba unavailable: {e}")
        mi = dr = None
    rows = []
    for label, desc in scenes:
        simple = peers.simple_scene(desc)
        sc = gdmlt.Scene(desc)
        for nee in (True, False):
            msc = msc_default = None
            if mi is not None:
                msc = peers.mitsuba_scene(mi, simple, bounces, nee, rr_depth=gdmlt.RR_START_DEPTH)
                msc_default = peers.mitsuba_scene(mi, simple, bounces, nee)
            for th in thread_counts:
                rg, img, _, segments = rate_gdmlt(sc, size, size, nee, bounces, th, seconds)
                ref_mean = float(img.mean())
                rm = mm = rmd = float("nan")
                if msc is not None:
                    dr.set_thread_count(th)
                    rm, mimg = _rate_mitsuba(mi, msc, size, size, seconds, rg)
                    mm = float(mimg.mean()) / ref_mean
                    rmd, _ = _rate_mitsuba(mi, msc_default, size, size, seconds / 2, rg)
                try:
                    imgs, times, samples = peers.luxcore_render(simple, [1.0, seconds / 2 + 1.0], bounces, nee, threads=th)
                    rl = (samples[1] - samples[0]) / (times[1] - times[0])
                    ml = float(imgs[-1].mean()) / ref_mean
                except RuntimeError as e:
                    out(f"# luxcore failed: {e}")
                    rl = ml = float("nan")
                rows.append((label, nee, th, rg, rm, rl))
                out(f"{label:16} {str(nee):5} {th:>7} {rg / 1e6:11.3f} {segments:8.3f} {rm / 1e6:13.3f} {rl / 1e6:13.3f} "
                    f"{rg / rm:9.2f} {rg / rl:9.2f} {mm:9.3f} {ml:10.3f} {rmd / 1e6:10.3f}")
    out("# Ms/s = million camera samples (paths) per second; segments = GDMLT's mean closest-hit rays per "
        "path (camera ray included), the path length its samples/s are paid for; mean x/g = that renderer's "
        "image mean / GDMLT's;")
    out(f"# mitsuba with GDMLT's Russian roulette (from bounce {gdmlt.RR_START_DEPTH}); "
        "mi default = Mitsuba's own (path: from depth 5; prb_basic: none), Ms/s")
    return rows
