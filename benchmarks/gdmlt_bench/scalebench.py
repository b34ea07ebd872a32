"""`gdmlt scalebench`: how the cost of a mutation (GDPSSMLT) and of a path (PT) grows with
scene size (the Cornell box with a bumpy sphere of 10k → 10M triangles) and with threads
(1 → all). Per-unit times are differences of two renders (N and 2N per pixel), so the fixed
costs (Metropolis bootstrap, first-hit pass, reconstruction) cancel; scene build time and the
memory the built scene holds (RSS growth) are printed per size. It measures; it does not pass
or fail."""

from __future__ import annotations

import gc
import os
import time



def _rss_mb() -> float:
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        return float("nan")


def _per_unit(render, units_per_n: int) -> float:
    """Seconds per unit: renders with n and 2n per pixel (n grown until a render takes 0.4 s)
    and divides the time difference (best of two) by the n·units_per_n units it added."""
    n = 4
    while True:
        t = time.perf_counter()
        render(n)
        a = time.perf_counter() - t
        if a >= 0.4 or n >= 1 << 14:
            break
        n *= 2
    best = float("inf")
    for _ in range(2):  # best of two differences: the machine is shared
        t = time.perf_counter()
        render(n)
        a = time.perf_counter() - t
        t = time.perf_counter()
        render(2 * n)
        best = min(best, time.perf_counter() - t - a)
    return max(best, 1e-9) / (n * units_per_n)


def run(sizes=(10_000, 100_000, 1_000_000, 10_000_000), size=64, thread_counts=None, out=print):
    import gdmlt

    from .pathbench import cornell_with_sphere

    all_threads = os.cpu_count() or 1
    thread_counts = thread_counts or sorted({1, all_threads})
    px = size * size
    out(f"# gdmlt scalebench: {size}x{size}, max bounces 8, NEE; µs per mutation (gdpssmlt) and per path (pt), "
        f"from the difference of two renders; {all_threads} hardware threads; core {gdmlt.BUILD_TARGET}")
    out(f"{'triangles':>10} {'build s':>8} {'MB held':>8} {'threads':>7} {'pt µs/path':>11} {'gdpssmlt µs/mut':>16} "
        f"{'pt speedup':>10} {'mlt speedup':>11}")
    rows = []
    for n in sizes:
        gc.collect()
        rss0 = _rss_mb()
        desc = cornell_with_sphere(size, n)
        t = time.perf_counter()
        sc = gdmlt.Scene(desc)
        build = time.perf_counter() - t
        del desc
        gc.collect()
        held = _rss_mb() - rss0
        base = {}
        for th in thread_counts:
            pt = _per_unit(lambda k: gdmlt.render(sc, method="pt", spp=k, seed=1, threads=th), px)
            mlt = _per_unit(lambda k: gdmlt.render(sc, method="gdpssmlt", spp=k, seed=1, threads=th,
                                                  reconstruction="l2"), px)
            base.setdefault("pt", pt)
            base.setdefault("mlt", mlt)
            rows.append((n, build, held, th, pt, mlt))
            out(f"{n:>10,} {build:8.2f} {held:8.0f} {th:>7} {pt * 1e6:11.3f} {mlt * 1e6:16.3f} "
                f"{base['pt'] / pt:10.2f} {base['mlt'] / mlt:11.2f}")
        sc = None  # the scene is freed before the next size is built
    out("# speedup = one-thread time / this time; MB held = resident memory the built scene added")
    return rows
