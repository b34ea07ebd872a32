"""One frame across processes or machines: independent partial renders merged into one image.

A partial render is the same scene and settings with its own seed (so Metropolis chains,
bootstrap and path samples are independent between partials), saved as a `.npz` file with
its layers and the work it did (samples or mutations). `merge` averages the partials
weighted by that work — each partial is an estimate of the same image, so the weighted mean
is too, and equals one render of the summed budget in expectation — and, for the
gradient-domain methods, reconstructs once from the merged primal and gradients (the
reconstruction is not linear under L1, so averaging reconstructed images would not be the
same). `render_dask` farms the partials out to a Dask cluster (an address, or a
LocalCluster on this machine) with retries, so a worker that dies has its partial rerun
elsewhere; a partial that still fails is dropped and reported, never merged half-written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

GD_METHODS = ("gdpt", "gdpssmlt")
FORMAT = 1


def partial_seed(seed: int, k: int) -> int:
    """Seed of partial k: distinct for every k, the render's own seed for k = 0."""
    return (int(seed) + 1_000_003 * int(k)) % (2 ** 63)


def render_partial(desc: dict, k: int, n: int, settings: dict) -> dict:
    """Renders partial k of n of scene dict `desc`; returns a picklable dict of arrays."""
    import gdmlt

    if not (0 <= k < n):
        raise ValueError(f"partial {k}/{n}: need 0 ≤ K < N")
    opts = dict(settings)
    opts["seed"] = partial_seed(opts.get("seed", 0), k)
    res = gdmlt.render(gdmlt.Scene(desc), **opts)
    st = res["stats"]
    h, w, _ = res["layers"]["Combined"].shape
    # samples (or mutations) per pixel; any fixed weights of unbiased partials are unbiased,
    # work-proportional ones give the lowest variance
    work = 0.5 * (float(st.get("spp_min", 0)) + float(st.get("spp_max", 0)))
    out = {f"layer:{name}": np.asarray(img, np.float32) for name, img in res["layers"].items()}
    out.update({"format": FORMAT, "method": opts.get("method", "pt"), "k": k, "n": n, "work": work * w * h,
                "alpha_rec": float(opts.get("alpha_rec", 0.2)), "reconstruction": opts.get("reconstruction", "l1")})
    return out


def save_partial(path, partial: dict):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **{k: np.asarray(v) for k, v in partial.items()})
    tmp.replace(path)  # a partial file is either complete or absent


def load_partial(path) -> dict:
    with np.load(Path(path), allow_pickle=False) as z:
        d = {k: z[k] for k in z.files}
    for k in ("method", "reconstruction"):
        d[k] = str(d[k])
    for k in ("work", "alpha_rec"):
        d[k] = float(d[k])
    if int(d.get("format", 0)) != FORMAT:
        raise ValueError(f"{path}: not a GDMLT partial render (format {d.get('format')})")
    return d


def merge(partials, alpha_rec=None, reconstruction=None) -> dict:
    """Merged layers of partial renders of the same scene, method and size (dict name → array)."""
    import gdmlt

    partials = list(partials)
    if not partials:
        raise ValueError("nothing to merge")
    method = partials[0]["method"]
    shape = partials[0]["layer:Combined"].shape
    for p in partials:
        if p["method"] != method or p["layer:Combined"].shape != shape:
            raise ValueError(f"partials differ: {p['method']} {p['layer:Combined'].shape} vs {method} {shape}")
    work = np.array([p["work"] for p in partials], dtype=np.float64)
    if not (work > 0).any():
        raise ValueError("the partials did no work")
    weights = work / work.sum()
    names = [k for k in partials[0] if k.startswith("layer:")]
    merged = {}
    for name in names:
        if all(name in p for p in partials):
            merged[name[6:]] = sum(w * p[name].astype(np.float64) for w, p in zip(weights, partials)).astype(np.float32)
    if method in GD_METHODS:
        direct = merged["Very Direct"]
        merged["Combined"] = gdmlt.reconstruct(
            np.ascontiguousarray(merged["GD Primal"] - direct), merged["GD Gradient X"], merged["GD Gradient Y"],
            direct, alpha=alpha_rec or partials[0]["alpha_rec"], norm=reconstruction or partials[0]["reconstruction"])
    return merged


def render_dask(desc: dict, n: int, settings: dict, address=None, workers=2, retries=2, log=print):
    """Renders n partials on a Dask cluster and merges them. Returns (layers, dropped k's)."""
    from distributed import Client, LocalCluster

    cluster = None
    if address is None:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, worker_dashboard_address=None)
        address = cluster.scheduler_address
    try:
        with Client(address) as client:
            # every worker renders with all of its machine's cores unless told otherwise
            futures = [client.submit(render_partial, desc, k, n, settings, key=f"gdmlt-partial-{k}-{n}",
                                     retries=retries, pure=False) for k in range(n)]
            partials, dropped = [], []
            for k, f in enumerate(futures):
                try:
                    partials.append(f.result())
                except Exception as e:  # a partial that failed after its retries is dropped
                    log(f"gdmlt: warning: partial {k}/{n} failed ({type(e).__name__}: {e}); dropped")
                    dropped.append(k)
        if not partials:
            raise RuntimeError("every partial render failed")
        return merge(partials), dropped
    finally:
        if cluster is not None:
            cluster.close()
