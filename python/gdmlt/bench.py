"""`gdmlt bench`: error against a converged reference at equal wall-clock budgets, per
method and light mode, on a built-in scene or a .blend file. Prints a table (relMSE and
SMAPE as defined in ALGORITHM.md §5b) and, with --plot, draws error against time (PNG,
needs matplotlib). With --denoise, every render is also passed through Intel Open Image
Denoise (pyoidn, with the albedo and normal passes) and reported as its own row — the
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


def scene_desc(scene: str, size):
    """The scene dictionary of a built-in scene (size = (w, h)) or of a .blend file (its own
    resolution unless size is given), exported through the addon as F12 would."""
    import gdmlt

    path = Path(scene)
    if path.suffix.lower() != ".blend":
        w, h = size or (128, 128)
        return gdmlt.builtin_scene(scene, w, h), scene
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    from .blend import import_bpy

    bpy = import_bpy()
    from .addon import enable_addon

    enable_addon()
    import gdmlt_blender.export as export

    bpy.ops.wm.open_mainfile(filepath=str(path.resolve()))
    sc = bpy.context.scene
    if size:
        sc.render.resolution_x, sc.render.resolution_y = size
        sc.render.resolution_percentage = 100
    desc, warnings = export.export_scene(bpy.context.evaluated_depsgraph_get())
    for w in warnings:
        print(f"# warning: {w}")
    return desc, path.stem


def run(scene="cornell", size=None, budgets=(1.0, 2.0, 4.0), methods=("pt", "gdpt", "pssmlt", "gdpssmlt"),
        modes=(True, False), reference_spp=8192, max_bounces=8, threads=0, plot=None, extra=None, denoise=False,
        out=print):
    """extra: more render settings for every run (alpha_target, reconstruction, ...)."""
    import gdmlt

    desc, label = scene_desc(scene, size)
    sc = gdmlt.Scene(desc)
    extra = dict(extra or {})
    cam = desc["camera"]
    out(f"# {label} {cam['resolution_x']}x{cam['resolution_y']}, max bounces {max_bounces}, threads={threads or 'all'}, "
        f"reference: pt with NEE at {reference_spp} spp" + (f", settings {extra}" if extra else ""))
    t0 = time.perf_counter()
    ref = gdmlt.render(sc, method="pt", spp=reference_spp, nee=True, seed=12345, threads=threads,
                       max_bounces=max_bounces)["layers"]["Combined"]
    out(f"# reference took {time.perf_counter() - t0:.1f} s")
    out(f"{'method':14} {'nee':5} " + " ".join(f"{'relMSE@' + f'{b:g}' + 's':>14} {'SMAPE':>7}" for b in budgets))
    if denoise:
        try:
            import pyoidn
        except ImportError as e:
            raise RuntimeError("--denoise needs pyoidn (pip install pyoidn)") from e
    rows = []
    denoise_time = []
    for nee in modes:
        for m in methods:
            cells, dcells = [], []
            for b in budgets:
                res = gdmlt.render(sc, method=m, spp=10 ** 7, time_limit=b, nee=nee, seed=1, threads=threads,
                                   max_bounces=max_bounces, **extra)
                layers = res["layers"]
                img = layers["Combined"]
                cells.append((rel_mse(img, ref), smape(img, ref)))
                if denoise:
                    t1 = time.perf_counter()
                    d = pyoidn.denoise(np.ascontiguousarray(img, dtype=np.float32),
                                       albedo=layers.get("Denoising Albedo"), normal=layers.get("Denoising Normal"),
                                       hdr=True, quality="high")
                    denoise_time.append(time.perf_counter() - t1)
                    dcells.append((rel_mse(d, ref), smape(d, ref)))
            for name, cs in [(m, cells)] + ([(m + "+oidn", dcells)] if denoise else []):
                rows.append((name, nee, cs))
                out(f"{name:14} {str(nee):5} " + " ".join(f"{r:14.4g} {s:7.4f}" for r, s in cs))
    if denoise_time:
        out(f"# denoiser time per image: {np.median(denoise_time):.2f} s (median, not charged to the budget)")
    if plot:
        draw(rows, budgets, f"{label}: relMSE against time", plot)
        out(f"# plot: {plot}")
    return rows


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
