"""`gdmlt skipbench`: what "skip what the scene does not need" saves. `Scene::build` decides
once per scene which general code paths a render can leave out — shadow rays become any-hit
occlusion tests when no material is transparent, and single-lobe materials use their own BSDF
rather than the Principled mixture. The scene setting `general_paths` makes it take the general paths
anyway; this benchmark renders the same scenes both ways in one run and prints samples per
second and their ratio. It measures; it does not pass or fail.

Each cell is the best of three timed renders (after a warm-up), alternating the two builds so
that a machine's slow moments hit both."""

from __future__ import annotations

import time

from .pathbench import rate_gdmlt


def _timed(sc, method, size, spp, threads):
    import gdmlt

    t = time.perf_counter()
    res = gdmlt.render(sc, method=method, spp=spp, seed=1, threads=threads)
    return size * size * spp / (time.perf_counter() - t), float(res["layers"]["Combined"].mean())


def _scene(desc, shortcuts):
    import gdmlt

    return gdmlt.Scene(dict(desc, general_paths=not shortcuts))


def run(size=96, seconds=2.0, threads=0, out=print):
    import gdmlt

    out(f"# gdmlt skipbench: samples/s with the scene's shortcuts and with the general paths "
        f"(scene setting general_paths), {size}x{size}, best of 3 runs of ~{seconds:g} s, threads={threads or 'all'}")
    out(f"{'scene':10} {'method':6} {'shortcuts Ms/s':>15} {'general Ms/s':>13} {'speed-up':>9} {'mean ratio':>11}")
    rows = []
    for name in ("cornell", "spheres", "veil"):
        desc = gdmlt.builtin_scene(name, size, size)
        fast, general = _scene(desc, True), _scene(desc, False)
        for method in ("pt", "gdpt"):
            # the sample count of a ~`seconds` render (pathbench's calibration: over seconds/4)
            spp = rate_gdmlt(fast, size, size, True, 8, threads, 4 * seconds, method)[2]
            best = {True: (0.0, 0.0), False: (0.0, 0.0)}
            for _ in range(3):
                for shortcuts, sc in ((True, fast), (False, general)):
                    r = _timed(sc, method, size, spp, threads)
                    best[shortcuts] = max(best[shortcuts], r)
            (rf, mf), (rg, mg) = best[True], best[False]
            rows.append((name, method, rf, rg))
            out(f"{name:10} {method:6} {rf / 1e6:15.3f} {rg / 1e6:13.3f} {rf / rg:9.2f} {mf / mg:11.4f}")
    out("# speed-up = shortcuts / general; mean ratio = image means (same seed: the same image up to "
        "rounding, since both paths compute the same thing)")
    return rows
