"""`gdmlt raybench`: ray throughput of the core's BVH (obvhs CWBVH, as the renderer uses it)
against Intel Embree (PyPI `embreex`) on the same triangles and the same rays, in one run.
Closest-hit and occlusion; coherent (camera) and incoherent (random origins in the scene
bounds, random directions) rays; 1 thread and all threads (Embree: the batch split over as
many forked processes, since embreex traces a call on one thread). Both sides are timed from
Python around one batch call (array conversion included for both). Prints Mrays/s and the
ratio core/Embree, and checks that both find the same hits. It measures; it does not pass
or fail."""

from __future__ import annotations

import os
import time

import numpy as np


def bumpy_sphere(target_triangles: int):
    """A closed UV sphere with radial bumps: about `target_triangles` triangles."""
    n = max(8, int(np.sqrt(target_triangles / 2)))
    th = np.linspace(0, np.pi, n + 1)
    ph = np.linspace(0, 2 * np.pi, n + 1)[:-1]
    T, P = np.meshgrid(th, ph, indexing="ij")
    r = 1.0 + 0.05 * np.sin(7 * T) * np.cos(11 * P) + 0.02 * np.sin(23 * T + 5 * P)
    pos = np.stack([r * np.sin(T) * np.cos(P), r * np.sin(T) * np.sin(P), r * np.cos(T)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = i * n + j
    b = i * n + (j + 1) % n
    c = (i + 1) * n + j
    d = (i + 1) * n + (j + 1) % n
    tris = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])
    return pos.astype(np.float32), tris.astype(np.uint32)


def rays(kind: str, n: int, lo, hi, rng):
    if kind == "coherent":
        side = int(np.sqrt(n))
        u, v = np.meshgrid(np.linspace(-0.5, 0.5, side), np.linspace(-0.5, 0.5, side), indexing="ij")
        centre, size = (lo + hi) / 2, float(np.max(hi - lo))
        origin = centre + np.array([0, -2.5 * size, 0])
        target = centre + np.stack([u.ravel() * size, np.zeros(side * side), v.ravel() * size], -1)
        d = target - origin
        o = np.repeat(origin[None], side * side, axis=0)
    else:
        o = lo + rng.random((n, 3)) * (hi - lo)
        d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)


_SHARED = {}  # what forked Embree workers trace (set before the pool is made)


def _embree_chunk(span):
    """One worker's share of an Embree batch (a forked process: the scene and the rays are
    inherited); returns the number of hits only, so that no arrays travel back."""
    es, o, d, occl = _SHARED["batch"]
    a, b = span
    if occl:
        return int(np.count_nonzero(np.asarray(es.run(o[a:b], d[a:b], query="OCCLUDED")) != -1))
    return int(np.count_nonzero(es.run(o[a:b], d[a:b], output=1)["primID"] != -1))


def _embree_parallel(es, o, d, occl, threads, repeat=3):
    """Best wall time of Embree tracing the batch on `threads` cores for real: embreex traces
    a call on one thread, so the batch is split over as many forked processes (the pool made
    and warmed up outside the timing)."""
    import multiprocessing as mp

    _SHARED["batch"] = (es, o, d, occl)
    edges = np.linspace(0, len(o), threads + 1).astype(int)
    spans = [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
    with mp.get_context("fork").Pool(threads) as pool:
        pool.map(_embree_chunk, [(0, 1)] * threads)
        best = float("inf")
        for _ in range(repeat):
            t = time.perf_counter()
            pool.map(_embree_chunk, spans, chunksize=1)
            best = min(best, time.perf_counter() - t)
    return best


def _time(f, repeat=3):
    best = float("inf")
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t)
    return best, out


def run(triangles=1_000_000, n_rays=1_000_000, out=print):
    import gdmlt

    try:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh
    except ImportError as e:
        raise RuntimeError("raybench needs embreex (pip install embreex)") from e
    rng = np.random.default_rng(1)
    cams = gdmlt.builtin_scene("cornell", 8, 8)
    pos, tris = bumpy_sphere(triangles)
    cornell = [(np.asarray(m["positions"], np.float32), np.asarray(m["indices"], np.uint32)) for m in cams["meshes"]]
    off = np.cumsum([0] + [len(p) for p, _ in cornell])
    cornell_mesh = (np.concatenate([p for p, _ in cornell]),
                    np.concatenate([t + o for (_, t), o in zip(cornell, off)]).astype(np.uint32))
    threads = os.cpu_count() or 1
    out(f"# gdmlt raybench: core BVH (obvhs CWBVH) vs Embree (embreex), {n_rays:,} rays per batch, "
        f"best of 3, {threads} hardware threads")
    out(f"{'scene':14} {'rays':11} {'query':8} {'threads':>7} {'core Mrays/s':>13} {'embree Mrays/s':>15} {'ratio':>6}"
        f" {'agree':>6}")
    rows = []
    for label, (p, t) in (("bumpy sphere", (pos, tris)), ("cornell", cornell_mesh)):
        desc = {"meshes": [{"name": "m", "positions": p, "indices": t}], "materials": [], "lights": [],
                "camera": cams["camera"]}
        t0 = time.perf_counter()
        scene = gdmlt.Scene(desc)
        t_core_build = time.perf_counter() - t0
        t0 = time.perf_counter()
        es = rtcs.EmbreeScene()
        TriangleMesh(es, p, t.astype(np.int32))
        es.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32) / np.sqrt(3))  # commit
        t_embree_build = time.perf_counter() - t0
        out(f"# {label}: {len(t):,} triangles; build core {t_core_build:.2f} s, embree {t_embree_build:.2f} s")
        lo, hi = p.min(0), p.max(0)
        for kind in ("coherent", "incoherent"):
            o, d = rays(kind, n_rays, lo, hi, rng)
            for query in ("closest", "closest8", "occluded"):
                occl = query == "occluded"
                packets = query == "closest8"
                if query != "closest8":  # the same Embree figure serves both closest rows
                    te, eh = _time(lambda: es.run(o, d, query="OCCLUDED") if occl else es.run(o, d, output=1))
                if query != "closest8" and threads > 1:
                    te_all = _embree_parallel(es, o, d, occl, threads)
                for th in sorted({1, threads}):
                    tc, (tt, prim) = _time(lambda: scene.trace_rays(o, d, threads=th, occlusion=occl, packets=packets))
                    if occl:
                        agree = np.mean((np.asarray(eh) != -1) == (prim != -1))
                    else:
                        e_hit = eh["primID"] != -1
                        agree = np.mean((e_hit == (prim != -1)) &
                                        (~e_hit | (np.abs(eh["tfar"] - tt) <= 1e-3 * np.maximum(1, np.abs(tt)))))
                    # (all threads: Embree over as many processes, each a share of the batch)
                    mc, me = len(o) / tc / 1e6, len(o) / (te if th == 1 else te_all) / 1e6
                    ratio = mc / me
                    rows.append((label, kind, query, th, mc, me, ratio, agree))
                    out(f"{label:14} {kind:11} {query:8} {th:>7} {mc:13.2f} {me:15.2f} {ratio:6.2f} {agree:6.4f}")
    out("# ratio = core Mrays/s ÷ Embree Mrays/s; with all threads Embree traces the batch split over as many "
        "forked processes (embreex traces a call on one thread), timed around the whole split batch")
    out("# closest8 = the core's packet traversal, eight consecutive rays at a time (as pt's camera rays), "
        "against Embree's single-ray closest hits (embreex has no packet call)")
    return rows
