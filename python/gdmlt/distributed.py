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

from . import VARIANCE_UNKNOWN

GD_METHODS = ("gdpt", "gdpssmlt")
# 2: partials carry what identifies them (scene and settings hashes, seed, K/N), checked by merge
FORMAT = 2
MAX_LAYERS = 32


def scene_hash(desc: dict) -> str:
    """A stable hash of a scene dict (keys sorted; arrays by dtype, shape and bytes)."""
    import hashlib

    h = hashlib.sha256()

    def feed(v):
        if isinstance(v, dict):
            h.update(b"{")
            for k in sorted(v, key=str):
                h.update(str(k).encode() + b":")
                feed(v[k])
            h.update(b"}")
        elif isinstance(v, (list, tuple)):
            h.update(b"[")
            for x in v:
                feed(x)
            h.update(b"]")
        elif isinstance(v, np.ndarray):
            a = np.ascontiguousarray(v)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        else:
            h.update(repr(v).encode())

    feed(desc)
    return h.hexdigest()[:32]


def settings_hash(settings: dict) -> str:
    """The render settings that must agree between partials (all but the seed and threads)."""
    import hashlib

    keep = {k: settings[k] for k in sorted(settings) if k not in ("seed", "threads", "progress", "preview")}
    return hashlib.sha256(repr(keep).encode()).hexdigest()[:32]


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
                "alpha_rec": float(st.get("alpha_rec") or opts.get("alpha_rec") or 0.2), "reconstruction": opts.get("reconstruction", "l1"),
                "scene_hash": scene_hash(desc), "settings_hash": settings_hash(settings), "seed": opts["seed"]})
    return out


def save_partial(path, partial: dict):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **{k: np.asarray(v) for k, v in partial.items()})
    tmp.replace(path)  # a partial file is either complete or absent


def _check_sizes(path, max_pixels=65536 * 65536):
    """Refuses an .npz whose members would inflate beyond what a partial of its own image
    size holds (a zip bomb), before anything is decompressed."""
    import zipfile

    with zipfile.ZipFile(path) as z:
        infos = z.infolist()
        if len(infos) > MAX_LAYERS + 16:
            raise ValueError(f"{path}: {len(infos)} entries; not a GDMLT partial")
        combined = next((i for i in infos if i.filename == "layer:Combined.npy"), None)
        if combined is None:
            raise ValueError(f"{path}: no Combined layer; not a GDMLT partial")
        with z.open(combined) as f:
            version = np.lib.format.read_magic(f)
            read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, _, dtype = read(f)
        if len(shape) != 3 or shape[2] != 3 or shape[0] * shape[1] > max_pixels or dtype != np.float32:
            raise ValueError(f"{path}: Combined layer of shape {shape} and type {dtype} is not an RGB float32 image")
        layer_bytes = shape[0] * shape[1] * 3 * 4 + 4096
        for i in infos:
            limit = layer_bytes if i.filename.startswith("layer:") else 4096
            if i.file_size > limit:
                raise ValueError(f"{path}: entry {i.filename} inflates to {i.file_size:,} bytes, more than a "
                                 f"{shape[1]}×{shape[0]} partial holds ({limit:,})")


def load_partial(path) -> dict:
    """A partial written by `save_partial`, checked: its size bound before decompressing, its
    format, every layer an RGB float32 image of the Combined layer's size."""
    import zipfile

    try:
        _check_sizes(path)
        with np.load(Path(path), allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, EOFError) as e:
        raise ValueError(f"{path}: not a GDMLT partial render ({e})") from None
    if int(d.get("format", 0)) != FORMAT:
        raise ValueError(f"{path}: not a GDMLT partial render of this version (format {d.get('format')}, "
                         f"expected {FORMAT}); render the partials again")
    try:
        for k in ("method", "reconstruction", "scene_hash", "settings_hash"):
            d[k] = str(d[k])
        for k in ("work", "alpha_rec"):
            d[k] = float(d[k])
        for k in ("k", "n", "seed"):
            d[k] = int(d[k])
    except KeyError as e:
        raise ValueError(f"{path}: a GDMLT partial without its {e} field") from None
    if not (d["n"] >= 1 and 0 <= d["k"] < d["n"]):
        raise ValueError(f"{path}: its header says partial {d['k']} of {d['n']}, and a partial K/N needs "
                         "0 ≤ K < N: not a partial GDMLT wrote (damaged or edited)")
    shape = d["layer:Combined"].shape
    for name, a in d.items():
        if name.startswith("layer:") and (a.dtype != np.float32 or a.shape[:2] != shape[:2] or a.ndim != 3):
            raise ValueError(f"{path}: layer '{name[6:]}' is {a.dtype} {a.shape}, not float32 {shape}")
    d["path"] = str(path)
    return d


def check_partials(partials):
    """Refuses partials that are not independent estimates of one image: other scenes or
    settings, other sizes, the same partial twice, two with one seed, work that is not a
    finite positive number, non-finite pixels."""
    first = partials[0]
    name = lambda p: p.get("path", f"partial {p.get('k')}/{p.get('n')}")  # noqa: E731
    size = lambda p: "{1}×{0}".format(*p["layer:Combined"].shape[:2])  # noqa: E731
    split = "partials must be one render split K/N"
    for p in partials:
        if "k" in p and "n" in p and not (p["n"] >= 1 and 0 <= p["k"] < p["n"]):
            raise ValueError(f"{name(p)} says it is partial {p['k']} of {p['n']}: a partial K/N needs 0 ≤ K < N")
        # what differs, most telling first: the image size and the method before the hashes
        # (a resolution or a method is also in the scene's or the settings' hash)
        if p["layer:Combined"].shape != first["layer:Combined"].shape:
            raise ValueError(f"{name(p)} is {size(p)} pixels, {name(first)} {size(first)}: {split}")
        for key, what in (("method", "rendered with method {} where {} used {}"),
                          ("n", "is one of {} partials where {} is one of {}"),
                          ("scene_hash", "is of another scene (hash {}) than {} (hash {})"),
                          ("settings_hash", "was rendered with other settings (hash {}) than {} (hash {})")):
            if key in first and p.get(key) != first.get(key):
                raise ValueError(f"{name(p)} " + what.format(p.get(key), name(first), first.get(key)) + f": {split}")
        w = p["work"]
        if not (np.isfinite(w) and w > 0):
            raise ValueError(f"{name(p)}: its work ({w}) must be a finite number > 0")
        for layer, a in p.items():
            if layer.startswith("layer:"):
                bad = int(np.size(a) - np.count_nonzero(np.isfinite(a)))
                if bad:
                    raise ValueError(f"{name(p)}: layer '{layer[6:]}' has {bad} NaN/Inf values")
    for key, what in (("k", "the same partial"), ("seed", "two partials with one seed")):
        seen = {}
        for p in partials:
            if key in p:
                if p[key] in seen:
                    raise ValueError(f"{name(p)} and {seen[p[key]]}: {what} ({key} = {p[key]}); "
                                     "merging it twice would count its noise twice")
                seen[p[key]] = name(p)


def merge(partials, alpha_rec=None, reconstruction=None) -> dict:
    """Merged layers of partial renders of the same scene, method and size (dict name → array)."""
    import gdmlt

    partials = list(partials)
    if not partials:
        raise ValueError("nothing to merge")
    check_partials(partials)
    method = partials[0]["method"]
    work = np.array([p["work"] for p in partials], dtype=np.float64)
    weights = work / work.sum()
    names = [k for k in partials[0] if k.startswith("layer:")]
    merged = {}
    for name in names:
        if all(name in p for p in partials):
            # a weighted mean of independent estimates: its variance is Σ w² · each variance
            power = 2 if name == "layer:Variance" else 1
            merged[name[6:]] = sum(w ** power * p[name].astype(np.float64)
                                   for w, p in zip(weights, partials)).astype(np.float32)
            if name == "layer:Variance":  # unknown in any partial (too few samples): unknown
                unknown = np.any([p[name] >= 0.5 * VARIANCE_UNKNOWN for p in partials], axis=0)
                merged["Variance"][unknown] = VARIANCE_UNKNOWN
    if method in GD_METHODS:
        direct = merged["Very Direct"]
        merged["Combined"] = gdmlt.reconstruct(
            np.ascontiguousarray(merged["GD Primal"] - direct), merged["GD Gradient X"], merged["GD Gradient Y"],
            # α: as asked, else the work-weighted mean of what each partial used (each measured
            # its own from its sample halves where it was automatic: the same quantity)
            direct, alpha=alpha_rec or float(np.dot(weights, [p["alpha_rec"] for p in partials])), norm=reconstruction or partials[0]["reconstruction"],
            method=method)
    if "Alpha" in merged:
        # as the core does for one render: where every camera sample saw the (transparent)
        # world, the colour is 0 — the reconstruction must not spread light there
        merged["Combined"][merged["Alpha"][..., 0] <= 0.0] = 0.0
    return merged


def render_dask(desc: dict, n: int, settings: dict, address=None, workers=2, retries=2, log=print,
                connect_timeout=10):
    """Renders n partials on a Dask cluster and merges them. Returns (layers, dropped k's)."""
    from distributed import Client, LocalCluster

    cluster = None
    if address is None:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, worker_dashboard_address=None)
        address = cluster.scheduler_address
    try:
        try:
            client = Client(address, timeout=connect_timeout)
        except (OSError, TimeoutError) as e:
            raise RuntimeError(f"cannot reach the Dask scheduler at {address} within {connect_timeout} s: {e}") from None
        with client:
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
