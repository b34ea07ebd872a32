"""`gdmlt scalebench --memory`: the memory a render needs per pixel, by method, image size and
thread count. Each cell runs in its own process (so one cell's freed pages do not hide the
next one's peak): it builds the built-in Cornell box at the size, reads its resident memory,
renders one sample (or one mutation) per pixel with the final L1 reconstruction, keeps the
returned layers as a caller does, and reads its peak resident memory (VmHWM). Bytes per pixel
= (peak − resident before the render) / pixels. It measures; it does not pass or fail."""

from __future__ import annotations

import json
import os
import subprocess
import sys

# `status(key)`: a byte figure of /proc/self/status (VmRSS:, VmHWM:) in a child script
STATUS = r"""
def status(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1]) * 1024
    return 0
"""

_CHILD = r"""
import json, sys
import gdmlt
method, w, h, threads = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
""" + STATUS + r"""
scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", w, h))
before = status("VmRSS:")
out = gdmlt.render(scene, method=method, spp=1, seed=1, threads=threads, reconstruction="l1")
peak = status("VmHWM:")
kept = sum(a.nbytes for a in out["layers"].values())
print(json.dumps({"peak": peak - before, "layers": kept}))
"""


def measure(method: str, w: int, h: int, threads: int) -> dict:
    """Peak bytes above the built scene, and the bytes of the returned layers, of one render."""
    r = subprocess.run([sys.executable, "-c", _CHILD, method, str(w), str(h), str(threads)],
                       capture_output=True, text=True, check=False)
    if r.returncode != 0:
        raise RuntimeError(f"{method} {w}x{h} on {threads} threads failed: {r.stderr.strip()[-400:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def run(sizes=((512, 512), (1024, 1024), (1920, 1080)), methods=("pt", "gdpt", "pssmlt", "gdpssmlt"),
        thread_counts=None, out=print):
    all_threads = os.cpu_count() or 1
    thread_counts = thread_counts or sorted({1, all_threads})
    out("# gdmlt scalebench --memory: peak resident bytes per pixel of a 1-sample render of the Cornell box "
        "(above the built scene), and of the layers it returns; each cell in its own process")
    out(f"{'method':>9} {'size':>10} {'threads':>7} {'peak MB':>8} {'B/px':>6} {'layers B/px':>11}")
    rows = []
    for method in methods:
        for w, h in sizes:
            for th in thread_counts:
                m = measure(method, w, h, th)
                px = w * h
                rows.append((method, w, h, th, m["peak"] / px, m["layers"] / px))
                out(f"{method:>9} {f'{w}x{h}':>10} {th:>7} {m['peak'] / 2**20:8.0f} {m['peak'] / px:6.0f} "
                    f"{m['layers'] / px:11.0f}")
    return rows
