"""Reconstruction time: `gdmlt.reconstruct` (L2, and L1 with gdpt's and gdpssmlt's IRLS
schedules) on a synthetic gradient-domain image at several sizes, best of a few runs, with
the error of each against the image the noisy inputs were made from (so that a faster solver
is seen to reach the same result). Threads: all of this machine's cores (rayon's default)."""

import os
import time

import numpy as np

import gdmlt


def synthetic(w, h, seed=1):
    """A smooth image with a hard edge, and its primal and forward differences with noise
    (primal σ 0.3, gradients σ 0.05, 1% of gradient samples ×20 as fireflies)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    truth = (0.5 + 0.3 * np.sin(xx / 40.0) + (xx > w // 2)).astype(np.float32)[..., None].repeat(3, 2)
    noise = lambda s: (rng.standard_normal((h, w, 3)) * s).astype(np.float32)  # noqa: E731
    dx = np.zeros_like(truth)
    dx[:, :-1] = truth[:, 1:] - truth[:, :-1]
    dy = np.zeros_like(truth)
    dy[:-1] = truth[1:] - truth[:-1]
    fire = lambda: (rng.random((h, w, 3)) < 0.01) * noise(1.0)  # noqa: E731
    return truth, truth + noise(0.3), dx + noise(0.05) + fire(), dy + noise(0.05) + fire()


def run(sizes, repeats=3):
    print(f"reconstruction of RGB images, {os.cpu_count()} cores: seconds (best of {repeats}) and MSE against the truth")
    print(f"{'size':>11} {'norm (schedule)':>15} {'seconds':>8} {'MSE':>10}")
    for w, h in sizes:
        truth, p, dx, dy = synthetic(w, h)
        zero = np.zeros_like(truth)
        for norm, method in (("l2", "gdpt"), ("l1", "gdpt"), ("l1", "gdpssmlt")):
            best = float("inf")
            for _ in range(repeats):
                t = time.perf_counter()
                out = gdmlt.reconstruct(p, dx, dy, zero, 0.2, norm, method=method)
                best = min(best, time.perf_counter() - t)
            mse = float(((out - truth) ** 2).mean())
            label = norm if norm == "l2" else f"{norm} ({method})"
            print(f"{w:>5}×{h:<5} {label:>15} {best:8.3f} {mse:10.3e}", flush=True)
