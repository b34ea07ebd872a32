"""Time to render one frame split into partials on 1 and 2 local Dask workers (one thread
each), against one process rendering the same total budget with 1 and 2 threads — the
scaling figure of issue 6. Usage: python tools/bench_dask.py [--size 128] [--partials 8] [--spp 16]"""

import argparse
import time

import gdmlt
from gdmlt import distributed as dist


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--partials", type=int, default=8)
    ap.add_argument("--spp", type=int, default=16, help="mutations per pixel of each partial")
    ap.add_argument("--method", default="gdpssmlt")
    a = ap.parse_args()
    desc = gdmlt.builtin_scene("cornell", a.size, a.size)
    settings = {"method": a.method, "spp": a.spp, "max_bounces": 8, "seed": 1, "threads": 1}
    print(f"# {a.method}, cornell {a.size}², {a.partials} partials × {a.spp} per pixel "
          f"(= {a.partials * a.spp} per pixel in all)")
    for threads in (1, 2):
        t = time.perf_counter()
        gdmlt.render(gdmlt.Scene(desc), **dict(settings, spp=a.spp * a.partials, threads=threads))
        print(f"one process, {threads} thread(s): {time.perf_counter() - t:6.2f} s")
    for workers in (1, 2):
        t = time.perf_counter()
        _, dropped = dist.render_dask(desc, a.partials, settings, workers=workers)
        print(f"dask, {workers} local worker(s):  {time.perf_counter() - t:6.2f} s (dropped {dropped})")


if __name__ == "__main__":
    main()
