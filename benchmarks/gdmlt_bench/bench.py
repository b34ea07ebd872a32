"""`gdmlt bench`: error against a converged reference at equal wall-clock budgets, per
method and light mode, on a built-in scene or a .blend file. Prints a table (relMSE and
SMAPE as defined in docs/algorithm.md §5b) — also, with --peers, for Cycles, LuxCore (path and
Metropolis samplers) and Mitsuba 3 at the same budgets against the same reference — and, with --plot, draws error against time (PNG,
needs matplotlib). With --denoise, every render is also passed through Intel Open Image
Denoise (GDMLT's own denoiser, gdmlt/oidn.py: OIDN with the prefiltered albedo and normal passes) and reported as its own row — the
question the paper leaves open (is GD-MLT better than MLT + a denoiser?); the denoiser's own
time is printed, not charged to the budget. It measures; it does not pass or fail."""

import time
from pathlib import Path

import numpy as np

EPS = 1e-2


def rel_mse(img, ref):
    return float(np.mean((img - ref) ** 2 / (ref ** 2 + EPS)))


def smape(img, ref):
    return float(np.mean(2 * np.abs(img - ref) / (np.abs(img) + np.abs(ref) + EPS)))


def block_error(img, ref, b=8):
    """Mean relative difference of b×b block averages (of the channel mean): the blotches
    and low-frequency error that relMSE, a per-pixel measure, hides."""
    h, w = ref.shape[0] // b * b, ref.shape[1] // b * b

    def blocks(a):
        return a[:h, :w].mean(2).reshape(h // b, b, w // b, b).mean((1, 3))

    bi, br = blocks(img), blocks(ref)
    return float(np.mean(np.abs(bi - br) / (br + EPS)))


def flip_error(img, ref):
    """Mean HDR-FLIP (NVIDIA's perceptual difference, PyPI `flip-evaluator`; linear inputs,
    its default 67 pixels per degree and exposure range), or NaN without the package."""
    try:
        import flip_evaluator
    except ImportError:
        return float("nan")
    pos = lambda a: np.ascontiguousarray(np.maximum(np.nan_to_num(a), 0), np.float32)  # noqa: E731
    return float(flip_evaluator.evaluate(pos(ref), pos(img), "HDR", inputsRGB=False, applyMagma=False)[1])


METRICS = ("relMSE", "SMAPE", "block", "FLIP")


def metrics(img, ref):
    """(relMSE, SMAPE, block error, FLIP) of `img` against `ref`."""
    return rel_mse(img, ref), smape(img, ref), block_error(img, ref), flip_error(img, ref)


def scene_desc(scene: str, size):
    """(scene dict, label) of a built-in name or a .blend file (gdmlt.blend.scene_desc), its
    export warnings printed as comments of the table."""
    from gdmlt.blend import scene_desc as desc_of

    desc, label, warnings = desc_of(scene, size)
    for w in warnings:
        print(f"# warning: {w}")
    return desc, label


PEERS = ("cycles", "cycles-guiding", "luxcore", "luxcore-mlt", "mitsuba")


def peer_rows(peer, scene, desc, budgets, nee, max_bounces, threads, size, denoise=False, adaptive=0.0, runs=1):
    """(images at each budget, denoised images or None, note), or (None, None, the reason it
    was skipped); each budget's entry a list of `runs` images (Cycles: seeds 1…runs; the
    other peers render once). Cycles renders the .blend itself (or the built-in scene rebuilt in Blender);
    LuxCore and Mitsuba render the translation of the scene arrays (gdmlt.peers), when the
    scene is simple enough. With `denoise`, Cycles also returns its own denoised images of the
    same renders; the other peers never do. `adaptive`: Cycles' noise threshold (0 = off)."""
    from . import peers

    try:
        simple = peers.simple_scene(desc)
    except peers.Unsupported as e:
        simple, why = None, str(e)
    if peer in ("cycles", "cycles-guiding"):
        blend = scene if str(scene).lower().endswith(".blend") else None
        if blend is None and simple is None:
            return None, None, f"skipped: {why}"
        imgs, dens, times = [[] for _ in budgets], [[] for _ in budgets], []
        for seed in range(1, runs + 1):
            raw, t, _, *den = peers.cycles_render(budgets, max_bounces, nee, threads, desc=None if blend else desc,
                                                  blend=blend, size=size, seed=seed, denoise=denoise, adaptive=adaptive,
                                                  guiding=peer == "cycles-guiding")
            for i in range(len(budgets)):
                imgs[i].append(raw[i])
                if denoise:
                    dens[i].append(den[0][i])
            times.append(t)
        note = ("cycles wall time per budget (sync included): "
                f"{', '.join(f'{t:.2f}' for t in np.mean(times, axis=0))} s" + (f" (mean of {runs} runs)" if runs > 1 else ""))
        return imgs, (dens if denoise else None), note
    if simple is None:
        return None, None, f"skipped: {why}"
    if peer.startswith("luxcore"):
        imgs, times, samples = peers.luxcore_render(simple, budgets, max_bounces, nee,
                                                    sampler="METROPOLIS" if peer == "luxcore-mlt" else "SOBOL",
                                                    threads=threads)
        return [[i] for i in imgs], None, None
    mi, dr = peers.import_mitsuba(threads)
    msc = peers.mitsuba_scene(mi, simple, max_bounces, nee)
    peers.mitsuba_render(mi, msc, 2)  # compile the kernels
    spp, dt = 4, 0.0
    while dt < 0.3 and spp < 1 << 20:  # time a run long enough to set spp from
        spp *= 4
        t = time.perf_counter()
        peers.mitsuba_render(mi, msc, spp)
        dt = time.perf_counter() - t
    per_spp = dt / spp
    imgs, used = [], []
    for b in budgets:
        spp = max(1, int(b / per_spp))
        t = time.perf_counter()
        imgs.append(peers.mitsuba_render(mi, msc, spp, seed=1))
        used.append(time.perf_counter() - t)
        per_spp = used[-1] / spp  # Mitsuba has no time limit: refine the rate as it goes
    return [[i] for i in imgs], None, f"mitsuba time used per budget: {', '.join(f'{u:.2f}' for u in used)} s (spp set from a timed run)"


def run(scene="cornell", size=None, budgets=(1.0, 2.0, 4.0), methods=("pt", "gdpt", "pssmlt", "gdpssmlt"),
        modes=(True, False), reference_spp=8192, max_bounces=8, threads=0, plot=None, extra=None, denoise=False,
        peers=(), out=print, reference="pt", reference_seconds=60.0, runs=1):
    """extra: more render settings for every run (alpha_target, reconstruction, ...).
    peers: any of PEERS, rendered at the same budgets and compared with the same reference.
    runs: renders per cell (seeds 1…runs, GDMLT and Cycles alike), each metric their mean —
    one run's ratio to Cycles moves by up to ±30% between runs on this machine."""
    import gdmlt

    desc, label = scene_desc(scene, size)
    if {"luxcore", "luxcore-mlt", "mitsuba"} & set(peers):
        # those peers render with a one-pixel box filter: everything here does, for this run
        desc["camera"] = dict(desc["camera"], pixel_filter="BOX", filter_width=1.0)
    sc = gdmlt.Scene(desc)
    extra = dict(extra or {})
    cam = desc["camera"]
    what = (f"Cycles for {reference_seconds:g} s (another seed)" if reference == "cycles"
            else f"{reference} with NEE at {reference_spp} spp")
    out(f"# {label} {cam['resolution_x']}x{cam['resolution_y']}, max bounces {max_bounces}, threads={threads or 'all'}, "
        f"reference: {what}, core {gdmlt.BUILD_TARGET}" + (f", settings {extra}" if extra else ""))
    t0 = time.perf_counter()
    # The reference is the mean of two independent halves: their difference measures its own
    # noise, which every error below contains (reference_noise).
    if reference == "cycles":
        # GDMLT's own error then includes any difference from Cycles' answer, not only noise
        from . import peers as _peers

        blend = scene if str(scene).lower().endswith(".blend") else None
        halves = [_peers.cycles_render([reference_seconds / 2], max_bounces, True, threads,
                                       desc=None if blend else desc, blend=blend, size=size, seed=s)[0][0]
                  for s in (977, 978)]
    else:
        # (bdpt for hard light: caustics and sunlight through glass, which pt barely finds)
        halves = [gdmlt.render(sc, method=reference, spp=max(1, reference_spp // 2), nee=True, seed=s, threads=threads,
                               max_bounces=max_bounces)["layers"]["Combined"] for s in (12345, 12346)]
    ref, noise = reference_noise(*halves)
    out(f"# reference took {time.perf_counter() - t0:.1f} s; its own noise: relMSE {noise[0]:.3g}, block error "
        f"{noise[1]:.3g} (in every figure below; the tables 'less the reference's noise' take its relMSE out)")
    if runs > 1:
        out(f"# every cell is the mean of {runs} runs (seeds 1…{runs}; LuxCore and Mitsuba render once)")
    out(f"{'method':14} {'nee':5} " + " ".join(f"{'relMSE@' + f'{b:g}' + 's':>14} {'SMAPE':>7}" for b in budgets))
    if denoise:
        from gdmlt.oidn import available, denoise as denoise_layers

        if not available():
            raise RuntimeError("--denoise needs pyoidn (pip install pyoidn)")
    rows = []  # (name, nee, [metrics(img, ref) per budget])
    denoise_time = []
    notes = []

    def add_row(name, nee, cells):
        rows.append((name, nee, cells))
        out(f"{name:14} {str(nee):5} " + " ".join(f"{c[0]:14.4g} {c[1]:7.4f}" for c in cells))

    for nee in modes:
        for m in methods:
            cells, dcells = [], []
            for b in budgets:
                imgs, dimgs = [], []
                for seed in range(1, runs + 1):
                    opts = dict(spp=10 ** 7, time_limit=b, nee=nee, seed=seed, threads=threads,
                                max_bounces=max_bounces, **extra)
                    if m == "auto":  # the pilot's time is part of the budget
                        from gdmlt.auto import render as auto_render

                        res = auto_render(desc, opts)
                        notes.append(f"auto at {b:g} s (seed {seed}) chose {res['stats']['auto']['method']}")
                    elif m.endswith("-bd"):  # a Metropolis method over bidirectional states
                        res = gdmlt.render(sc, method=m[:-3], bidirectional=True, **opts)
                    else:
                        res = gdmlt.render(sc, method=m, **opts)
                    layers = res["layers"]
                    imgs.append(layers["Combined"])
                    if denoise and m == "auto":
                        # as the product renders with its denoiser on: the pilot chooses for that
                        res = auto_render(desc, opts, denoise=True)
                        notes.append(f"auto for denoising at {b:g} s (seed {seed}) chose {res['stats']['auto']['method']}")
                        layers = res["layers"]
                    if denoise:
                        t1 = time.perf_counter()
                        dimgs.append(denoise_layers(layers)["Combined"])  # as the product denoises
                        denoise_time.append(time.perf_counter() - t1)
                cells.append(mean_metrics(imgs, ref))
                if denoise:
                    dcells.append(mean_metrics(dimgs, ref))
            add_row(m, nee, cells)
            if denoise:
                add_row(m + "+oidn", nee, dcells)
        for peer in peers:
            try:
                raw, den, note = peer_rows(peer, scene, desc, budgets, nee, max_bounces, threads, size,
                                           denoise=denoise and peer == "cycles",
                                           adaptive=extra.get("adaptive_threshold", 0.0), runs=runs)
            except Exception as e:  # noqa: BLE001 — a peer that fails is reported, the bench goes on
                raw, den, note = None, None, f"failed: {e}"
            if raw is None:
                out(f"# {peer} ({'NEE' if nee else 'naive'}): {note}")
                continue
            add_row(peer, nee, [mean_metrics(i, ref) for i in raw])
            if den is not None:  # Cycles' own denoiser on the same renders
                add_row(peer + "+oidn", nee, [mean_metrics(i, ref) for i in den])
            if note:
                out(f"# {note}")
    for n in notes:
        out(f"# {n}")
    if denoise_time:
        out(f"# denoiser time per image: {np.median(denoise_time):.2f} s (median, not charged to the budget)")
    summary(rows, budgets, out, noise)
    if plot:
        draw(rows, budgets, f"{label}: relMSE against time", plot)
        out(f"# plot: {plot}")
    return rows


def mean_metrics(images, ref):
    """`metrics` of each image (runs of one cell), averaged metric by metric."""
    return tuple(float(v) for v in np.mean([metrics(i, ref) for i in images], axis=0))


def reference_noise(a, b):
    """The reference made of two independent half renders `a` and `b` of the same image, and
    its own noise: (relMSE, block error) of the mean against the image it estimates, from the
    halves' difference. Any image x independent of the reference has E[relMSE(x, ref)] =
    relMSE(x, truth) + the first (the weights 1/(ref² + ε) held fixed); the block error of
    the mean is about half the halves' against each other (noise of ¼ the variance)."""
    from gdmlt.auto import relative_variance  # one half's relative variance; the mean's is half

    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return (0.5 * (a + b)).astype(np.float32), (0.5 * relative_variance(a, b), 0.5 * block_error(a, b))


def summary(rows, budgets, out=print, noise=None):
    """Every metric as its own table, then each row's relMSE and block error as ratios to
    the Cycles row of the same light mode (Cycles+OIDN for denoised rows), when there is one;
    with `noise` (reference_noise's), also the relMSE ratios less the reference's own noise,
    which otherwise draws every ratio towards 1 where errors come near it."""
    head = f"{'':14} {'nee':5} " + " ".join(f"{f'{b:g} s':>10}" for b in budgets)
    for k, metric in enumerate(METRICS):
        out(f"## {metric}")
        out(head)
        for name, nee, cells in rows:
            out(f"{name:14} {str(nee):5} " + " ".join(f"{c[k]:10.4g}" for c in cells))
    peer = {(name, nee): cells for name, nee, cells in rows if name.startswith("cycles")}
    if not peer:
        return
    floor = noise[0] if noise else 0.0
    tables = [(0, "relMSE", 0.0), (2, "block", 0.0)] + ([(0, "relMSE less the reference's noise", floor)] if noise else [])
    for k, metric, sub in tables:
        out(f"## {metric} ÷ Cycles' (÷ Cycles+OIDN's for denoised rows)")
        out(head)
        for name, nee, cells in rows:
            ref = peer.get(("cycles+oidn" if name.endswith("+oidn") else "cycles", nee))
            if ref is None or name.startswith("cycles"):
                continue
            out(f"{name:14} {str(nee):5} " + " ".join(_ratio(c[k] - sub, r[k] - sub) for c, r in zip(cells, ref)))


def _ratio(a, b):
    """a ÷ b, or why not: an error at or under the reference's noise is not measured."""
    if b <= 0:
        return f"{'(floor)':>10}"
    return f"{max(a, 0.0) / b:10.3g}"


def draw(rows, budgets, title, path):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:
        raise RuntimeError("--plot needs matplotlib (pip install matplotlib)") from e
    fig, ax = plt.subplots(figsize=(6, 4.2), dpi=110)
    for m, nee, cells in rows:
        ax.loglog(budgets, [c[0] for c in cells], marker="o", linestyle="-" if nee else "--",
                  label=f"{m} ({'NEE' if nee else 'naive'})")
    ax.set_xlabel("render time (s)")
    ax.set_ylabel("relMSE")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
