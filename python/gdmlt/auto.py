"""`method = "auto"`: a short pilot measures each method's error per second on the scene at
hand, and the render spends the rest of its budget on the best one.

Why: which method is best depends on the scene. On everyday scenes lit directly (a few lamps,
a sun, a sky) path tracing and GDPT are 5–10× ahead of GDPSSMLT at equal time; where light
arrives through a small gap GDPSSMLT is ahead of both (docs/benchmarks.md). No fixed default
is right for both, and users should not have to know.

The pilot (`choose`):
1. **A window of the image**: the central quarter of each side (at least 16 × 16 pixels, the
   whole image when it is smaller), so that each pilot render gets many samples per pixel
   in a short time on pixels that are typical of the frame — seen through the render's own
   scene (`Scene.set_camera`), not a second build of it.
2. **Two independent renders per candidate** (`pt`, `gdpt`, `gdpssmlt`, `bdpt`; seeds differ) of
   `t` seconds each, with the render's own bounce and NEE settings.
3. **Error per second**: half the mean relative squared difference of the two renders,
   (a − b)² / (((a + b)/2)² + 0.01), estimates one render's relative variance `v` after `t`
   seconds; a Monte Carlo error falls as 1/time, so `v·t` is the method's error for one second
   (its fixed costs — the Metropolis bootstrap — counted against it, as the real render pays
   them too). The smallest `v·t` wins.
4. **What camera paths miss**: a short render of a method that builds its paths from the
   camera (`CAMERA_PATHS`) shows the light those paths find often and not the light they
   find rarely — a sun through a glazed window, a lamp behind glass —, and so reports a small,
   confident variance where the real render gets fireflies or a dark, biased image (the
   window bench room: `pt` measured 6× ahead of `bdpt` in the pilot, 100× behind in the
   render). `bdpt`'s pilot renders therefore also estimate, from their own samples, what
   `pt` would make of each pixel (integrator/bdpt.rs, `predict_pt`: its second moment, and
   the light it cannot make at all — docs/bidirectional.md, "Predicting pt's noise"). When
   that predicts `TAILS_MIN` (4×) more error than `pt`'s own renders showed, the camera-path
   methods' `v·t` are multiplied by the ratio, `tails` (on the window room 5000–6000, caustics
   50–80, a lamp in a glass ball 300–600; on everyday scenes 0.1–2.9, where the prediction,
   which leaves out the correlations between one path's contributions, is the lower).

With the denoiser on (Blender's Denoise, the CLI's default), what the user gets is each
method's image *after* OIDN, and that ranks the methods differently: OIDN removes path
tracing's white noise but hardly touches the low-frequency error the gradient-domain
reconstruction leaves (docs/denoising.md). So when the raw ranking puts another method
first, `choose(..., denoise=True)` denoises both pilot renders of it and of `pt` (a central
crop of at most `DENOISE_CROP` pixels a side, one OIDN device for the four) and picks the
lower relative variance of the denoised pair × seconds — the other method only when it is
`DENOISED_MARGIN` (2×) ahead of `pt` there. `bdpt` is an exception both ways: its noise is
white, as `pt`'s, and OIDN takes it out as well, so when it is `BDPT_RAW_LEAD` (2×) ahead of
`pt` raw it joins the denoised comparison (whatever ranked first raw) and only has to stay
ahead there (and is kept while OIDN is still loading) — measured at 10 s, 128² (2026-12-07): bulb in a shade raw 25× ahead, denoised
3.3×; window 90× / 4.6×; caustics 18× / 1.3×; door ajar 2.3× / 1.1×; an HDRI-lit interior
0.67× / 0.75×, which the rule leaves to `pt`. (A margin of 1.25× on the denoised crops
alone took `bdpt` on that interior once in two seeds.) (`pt` ranked first raw stays first: OIDN lowers
its error at least as much as any other method's, on every scene measured.) The margin:
the denoised comparison rests on two small crops per method and is noisy — on the glass box
at 8 s its pt ÷ gdpt ratio ranged 1.2–1.5 over seeds while the whole images after OIDN were
1.45× apart in pt's favour, and one bench run picked `gdpt` there (1.13× Cycles + OIDN's
relMSE, 2026-12-05); no scene measured has had another method ahead of `pt` after OIDN.
Measured (`gdmlt bench --denoise`, 2026-12-02, 128², 1–8 s): `pt` + OIDN has the lowest
error on a door left ajar, a glass-and-mirror box, a multi-light scene, the gap and the
Cornell box (1.2–3.3× below `gdpt` + OIDN, equal on the box at 4 s), and the pilot's
denoised variance ranked `pt` first on each (3 seeds: `gdpt`'s 1.2–6× `pt`'s), where the
raw ranking had chosen `gdpt` on all but the multi-light scene.

Budget: the render ends at whichever of its limits comes first — the time limit, or the
samples per pixel (mutations per pixel for the Metropolis methods), whose time a probe of
`pt` render of `PROBE_SECONDS` on the window estimates. The pilot takes `PILOT_FRACTION` of that
estimate (each of its six renders at least `MIN_PILOT_RENDER`); a render too short for that
to stay under `MAX_PILOT_SHARE` of it (about 0.6 s) gets `pt` without a pilot. The chosen
method then renders the samples asked for, within what is left of the time limit: the frame
holds the samples the user set, and the pilot costs a small share of the render it plans. (A
time limit without samples, as the Python API may pass it, renders to the time limit.)

Parameters (defaults once, here): `DENOISE_CROP = 96`, `DENOISED_MARGIN = 2.0`, `PILOT_FRACTION = 0.05`,
`MAX_PILOT_SHARE = 0.1`, `PROBE_SECONDS = 0.02`, `MIN_PILOT_RENDER = 0.01` s (measured 2026-12-03, 128² cornell, veil and lights, 3 seeds: the pilot
4.4–5.0% of a 1 s budget, where 0.02 s made it 8.5–8.9%, and the same choice in all 9),
`BOOTSTRAP_MARGIN = 1.5` (gdpssmlt is not tried when its bootstrap, predicted from `gdpt`'s
pilot speed, would outlast a pilot render by this factor),
`CANDIDATES = ("pt", "gdpt", "gdpssmlt", "bdpt")` (`pssmlt` is left out: it measured behind
`gdpssmlt` on every benchmark scene; `bdpt`, last so that the others keep their pilot seeds,
wins where light comes through glass: on the window bench room, 2 and 10 s, its raw relMSE
was 0.5–1% of `pt`'s and after OIDN 18–22% — docs/bidirectional.md).
"""

import copy
import threading
import time

import numpy as np

CANDIDATES = ("pt", "gdpt", "gdpssmlt", "bdpt")
CAMERA_PATHS = ("pt", "gdpt", "gdpssmlt")
TAILS_MIN = 4.0
PILOT_FRACTION = 0.05
MIN_PILOT_RENDER = 0.01
MAX_PILOT_SHARE = 0.1
UNLIMITED_SPP = 10 ** 7
PROBE_SECONDS = 0.02
BOOTSTRAP_MARGIN = 1.5
DENOISE_CROP = 96
DENOISED_MARGIN = 2.0
BDPT_RAW_LEAD = 2.0
EPS = 1e-2


def _window(w, h):
    """[x, y, width, height] of the central quarter of each side (≥ 16 px, ≤ the image)."""
    ww, wh = min(w, max(16, w // 4)), min(h, max(16, h // 4))
    return [(w - ww) // 2, (h - wh) // 2, ww, wh]


def _image_size(cam):
    pct = cam.get("resolution_percentage", 100)
    return int(cam["resolution_x"]) * pct // 100, int(cam["resolution_y"]) * pct // 100


def relative_variance(a, b):
    """One render's relative variance from two independent renders a, b of the same pixels."""
    m = 0.5 * (a + b)
    return float(np.mean((a - b) ** 2 / (m ** 2 + EPS)) / 2.0)


def _crop(img, n):
    """The central n × n (at most) pixels of an (H, W, C) image."""
    h, w = img.shape[:2]
    y, x = max(0, (h - n) // 2), max(0, (w - n) // 2)
    return np.ascontiguousarray(img[y:y + n, x:x + n])


def _denoised_pair(layers_pair, device):
    """The central crops of two renders' Combined layers after OIDN with each render's own
    guides (not prefiltered: a third of the time, and the ranking measured the same)."""
    from .oidn import ALBEDO, NORMAL, denoise_image

    out = []
    for layers in layers_pair:
        guide = {k: _crop(layers[k], DENOISE_CROP) if k in layers else None for k in (ALBEDO, NORMAL)}
        out.append(denoise_image(_crop(layers["Combined"], DENOISE_CROP), guide[ALBEDO], guide[NORMAL],
                                 prefilter=False, device=device))
    return out


def choose(desc: dict, settings: dict, cancelled=lambda: False, denoise=False, scene=None) -> dict:
    """Runs the pilot. Returns {"method", "budget" (seconds for the whole render, pilot
    included), "pilot_seconds", "efficiency": {method: v·t}, "denoised": {method: v·t after
    OIDN} (empty unless compared), "tails" (the factor on the camera-path methods' v·t, 1
    when none), "why"}. `denoise`: the final image will be denoised, so
    the raw winner and pt are compared after OIDN (without OIDN installed: the raw ranking).
    `scene`: the render's own `gdmlt.Scene` of `desc`, if built already: the pilot looks
    through it at its window and gives the camera back (a second build, BVH included, can
    cost as much as the pilot on a heavy scene)."""
    import gdmlt

    # 1. the candidates whose render of the whole frame fits in memory
    w, h = _image_size(desc["camera"])
    base = desc["camera"].get("window")
    candidates, refusal = [], None
    for m in CANDIDATES:  # the frame itself must fit, not only the pilot's window
        try:
            gdmlt.check_memory(m, *(base[2:] if base else (w, h)))
            candidates.append(m)
        except ValueError as e:
            refusal = refusal or e
    if not candidates:
        raise refusal
    # 2. the pilot's window, its scene and settings
    pilot_desc = copy.copy(desc)
    pilot_desc["camera"] = dict(desc["camera"])
    region = tuple(base[2:]) if base else (w, h)  # what the render renders
    x, y, ww, wh = _window(*region)
    if base:
        x, y = x + base[0], y + base[1]
    pilot_desc["camera"]["window"] = [x, y, ww, wh]
    if scene is None:
        return _choose_in(gdmlt.Scene(pilot_desc), desc, settings, cancelled, denoise, candidates, (*region, ww, wh))
    scene.set_camera(pilot_desc["camera"])
    try:
        return _choose_in(scene, desc, settings, cancelled, denoise, candidates, (*region, ww, wh))
    finally:
        scene.set_camera(desc["camera"])


def _choose_in(scene, desc, settings, cancelled, denoise, candidates, sizes):
    """`choose`'s steps 3–5 on `scene`, which looks at the pilot's window."""
    import gdmlt
    from . import oidn

    w, h, ww, wh = sizes  # (w, h: the frame, or its render region)
    frame_pixels = w * h
    limit = float(settings.get("time_limit") or 0.0)
    from .settings import CORE

    # (a time limit without samples — the Python API's `{"time_limit": 10}` — renders to the
    # time limit; neither: the core's default samples)
    spp = settings.get("spp") or (None if limit else CORE["spp"])
    common = {k: settings[k] for k in ("max_bounces", "nee", "threads", "reconstruction", "alpha_rec",
                                       "large_step_probability", "alpha_target", "diffuse_bounces", "glossy_bounces",
                                       "transmission_bounces", "volume_bounces", "transparent_bounces", "clamp_direct",
                                       "clamp_indirect") if k in settings}
    seed = int(settings.get("seed", 0))
    t0 = time.perf_counter()
    # 3a. the render's length: its time limit, or what pt takes for its samples (a probe of
    # PROBE_SECONDS on the window), whichever ends it first
    rate = {}
    estimate = limit or float("inf")
    if spp:
        probe = gdmlt.render(scene, method="pt", spp=10 ** 7, time_limit=PROBE_SECONDS, seed=seed, **common)
        st = probe["stats"]
        # (a time-limited render stops between rows: its pixels are a pass apart)
        rate["pt"] = max(st["elapsed"], 1e-6) / (max(0.5 * (st["spp_min"] + st["spp_max"]), 1.0) * ww * wh)
        estimate = min(estimate, float(spp) * rate["pt"] * frame_pixels)
    t_each = PILOT_FRACTION * estimate / (2 * len(candidates))
    if t_each < MIN_PILOT_RENDER * PILOT_FRACTION / MAX_PILOT_SHARE:
        # even its shortest renders would cost more than MAX_PILOT_SHARE of the render: pt,
        # the method with the least fixed cost, without a pilot
        pilot = time.perf_counter() - t0
        return {"method": "pt", "budget": estimate, "pilot_seconds": pilot, "efficiency": {}, "denoised": {},
                "tails": 1.0, "why": f"the render (≈{estimate:.2g} s) is too short to pay for a pilot: pt"}
    t_each = max(MIN_PILOT_RENDER, t_each)
    if denoise:  # loading OIDN's library takes ~0.25 s: during the pilot renders, not after them
        loader = threading.Thread(target=oidn.available, daemon=True)
        loader.start()
    # 3b. two renders per candidate: relative variance × seconds
    eff, pairs, skipped = {}, {}, ""
    for m in candidates:
        if m == "gdpssmlt" and "gdpt" in rate:
            # its bootstrap traces bootstrap_paths gradient-domain paths before the first
            # mutation, each about a gdpt sample: when that alone outlasts a pilot render by
            # half again, the render would end with no mutation (measured: 0.06 s of a 0.15 s
            # pilot for nothing), so it is not run
            boot = gdmlt.bootstrap_paths(ww, wh) * rate["gdpt"]  # rate: seconds per path
            if boot > BOOTSTRAP_MARGIN * t_each:
                eff[m] = float("inf")
                skipped = f"; gdpssmlt not tried: its bootstrap (≈{boot:.2f} s) outlasts a pilot render"
                continue
        layers, elapsed, samples = [], 0.0, 0
        for s in (1, 2):
            if cancelled():
                break
            res = gdmlt.render(scene, method=m, spp=10 ** 7, time_limit=t_each,
                               seed=(seed * 7919 + s * 104729 + 31 * CANDIDATES.index(m)) % 2 ** 63,
                               **({"predict_pt": True} if m == "bdpt" else {}), **common)
            layers.append(res["layers"])
            elapsed += res["stats"]["elapsed"]
            samples += res["stats"]["spp_min"]
            if samples == 0:
                break  # its fixed cost outlasts t_each (a Metropolis bootstrap): a second would too
        if samples == 0 and layers:
            eff[m] = float("inf")
            continue
        if len(layers) < 2:
            break
        v = relative_variance(layers[0]["Combined"], layers[1]["Combined"])
        # two identical images say nothing about the error: unknown, never "perfect"
        eff[m] = v * elapsed / 2 if v > 0 else float("inf")
        pairs[m] = (layers, elapsed)
        rate[m] = elapsed / max(samples, 1) / (ww * wh)  # seconds per sample per pixel
    if not eff:
        return {"method": "pt", "budget": estimate, "pilot_seconds": time.perf_counter() - t0, "efficiency": {},
                "denoised": {}, "tails": 1.0, "why": "cancelled"}
    # 3c. camera paths' rare bright light, which their short renders do not see: bdpt's
    # prediction of pt's noise from its own samples
    tails = 1.0
    if "bdpt" in pairs and 0 < eff.get("pt", float("inf")) < float("inf"):
        predicted = _pt_predicted(pairs["bdpt"][0], rate["pt"] * ww * wh, limit or estimate)
        ratio = predicted / eff["pt"]
        tails = ratio if ratio > TAILS_MIN else 1.0
        for m in CAMERA_PATHS:
            if m in eff:
                eff[m] *= tails
    best = min(eff, key=eff.get)
    if eff[best] == float("inf"):
        best = "pt"  # nothing measured: the method with the least fixed cost
    # 4. for an image that will be denoised: the raw winner against pt after OIDN, and bdpt
    # too where it is well ahead of pt raw (its noise is white, as pt's, and OIDN takes it
    # out; the gradient-domain methods' low-frequency error it hardly touches)
    denoised, note = {}, ""
    finite_bdpt = "bdpt" in pairs and 0 < eff.get("bdpt", 0) < float("inf")
    lead = eff.get("pt", float("inf")) / eff["bdpt"] if finite_bdpt else 0.0
    bdpt_clear = lead >= BDPT_RAW_LEAD
    if denoise:
        # with a time limit, OIDN's loading (cold: up to a second) is waited for at most as
        # long as the pilot renders took, so that it cannot eat a short budget
        loader.join(timeout=max(0.05, time.perf_counter() - t0) if limit else None)
        # pt first already stays first: OIDN lowers its error at least as much as any other's
        if best != "pt" and eff.get("pt", float("inf")) < float("inf") and not cancelled():
            if loader.is_alive():
                if best == "bdpt" and bdpt_clear:
                    note = "; OIDN still loading: bdpt, well ahead of pt raw"
                else:
                    best, note = "pt", "; OIDN still loading: pt, first after denoising on every scene measured"
            elif oidn.available():
                contenders = {"pt", best} | ({"bdpt"} if bdpt_clear else set())
                denoised = _after_denoising({m: pairs[m] for m in contenders}, common.get("threads", 0))
                for m in denoised:  # (OIDN leaves a firefly's energy in the image)
                    if m in CAMERA_PATHS:
                        denoised[m] *= tails
                # each other method must lead pt by its margin: bdpt, clear of pt raw, only
                # has to stay ahead; the others DENOISED_MARGIN
                def margin(m):
                    return 1.0 if m == "bdpt" and bdpt_clear else DENOISED_MARGIN

                pt_den = denoised.get("pt", float("inf"))
                others = [m for m in contenders - {"pt"} if m in denoised]
                passing = [m for m in others if margin(m) * denoised[m] < pt_den]
                if passing:
                    best = min(passing, key=denoised.get)
                else:
                    ahead = [m for m in others if denoised[m] < pt_den]
                    if ahead:
                        m = min(ahead, key=denoised.get)
                        note = f"; {m}'s lead after denoising is under {margin(m):g}×: pt"
                    best = "pt"
    # 5. why
    pilot = time.perf_counter() - t0
    why = _explain(best, eff, denoised, f"pilot {pilot:.2f} s on a {ww}×{wh} window") + note + skipped
    if tails > 1.0:
        why += f"; camera paths' error × {tails:.3g} for the rare light bdpt's samples show they miss"
    return {"method": best, "budget": estimate, "pilot_seconds": pilot, "efficiency": eff, "denoised": denoised,
            "tails": tails, "why": why}


def _pt_predicted(layers_pair, seconds_per_sample: float, budget: float) -> float:
    """`pt`'s relative error × seconds on the pilot's window as bdpt's two pilot renders
    predict it ("PT Second Moment", "PT Unsampled": integrator/bdpt.rs): the variance of one
    sample, M₂ − mean², relative as `relative_variance` takes it, × the seconds a sample of
    the window takes; plus the light `pt` cannot make at all, a squared relative bias that no
    render time lowers (× the render's `budget`; the product of the two renders' estimates,
    which is unbiased for its square)."""
    a, b = layers_pair
    if any(k not in a or k not in b for k in ("PT Second Moment", "PT Unsampled")):
        return 0.0  # (a bdpt without the prediction: nothing known)
    mean = 0.5 * (a["Combined"] + b["Combined"])
    m2 = 0.5 * (a["PT Second Moment"] + b["PT Second Moment"])
    pt_mean = mean - 0.5 * (a["PT Unsampled"] + b["PT Unsampled"])  # (what pt itself makes)
    denom = mean ** 2 + EPS
    var = np.maximum(m2 - pt_mean ** 2, 0.0)
    bias2 = np.maximum(a["PT Unsampled"] * b["PT Unsampled"], 0.0)
    predicted = float(np.mean(var / denom)) * seconds_per_sample + float(np.mean(bias2 / denom)) * budget
    return predicted if np.isfinite(predicted) else 0.0  # (nothing known)


def _after_denoising(pairs: dict, threads: int) -> dict:
    """{method: relative variance × seconds of its two pilot renders after OIDN} for
    `pairs` = {method: (the two renders' layers, their seconds)}, on one OIDN device."""
    from . import oidn

    out = {}
    with oidn.session(threads) as device:
        for m, (layers, elapsed) in pairs.items():
            v = relative_variance(*_denoised_pair(layers, device))
            out[m] = v * elapsed / 2 if v > 0 else float("inf")
    return out


def _explain(best: str, eff: dict, denoised: dict, head: str) -> str:
    """The pilot's findings in one line, for the log and Blender's status bar."""
    def ranking(e):
        r = sorted(e, key=e.get)
        return ", ".join(f"{m} {e[m]:.3g}" for m in r), r

    text, ranked = ranking(eff)
    why = f"{head}: relative error × seconds {text}"
    if denoised:
        text, ranked = ranking(denoised)
        why += f"; after denoising {text}"
    final = denoised or eff
    others = [m for m in ranked if m != best]
    if others and 0 < final[best] < float("inf"):
        # the best of the others: ahead of it, or (pt kept within the margin) behind it
        ratio = final[others[0]] / final[best]
        if ratio >= 1.0:
            why += f"; {best} is {ratio:.2g}× ahead of {others[0]}"
        else:
            why += f"; {best} kept though {others[0]} measured {1 / ratio:.2g}× ahead"
    return why


def plan(desc: dict, settings: dict, cancelled=lambda: False, denoise=False, scene=None):
    """Runs the pilot; returns (the gdmlt.render settings for the rest of the render, the
    pilot's findings as `choose` returns them). `denoise`: the image will be denoised;
    `scene`: the render's own scene of `desc`, if built (see `choose`)."""
    settings = dict(settings)
    settings.pop("method", None)
    pick = choose(desc, settings, cancelled, denoise, scene)
    # the frame holds the samples asked for, within what is left of the time limit (a time
    # limit alone: as many samples as fit)
    opts = dict(settings, method=pick["method"])
    if settings.get("time_limit"):
        opts["time_limit"] = max(float(settings["time_limit"]) - pick["pilot_seconds"], MIN_PILOT_RENDER)
        if not opts.get("spp"):
            opts["spp"] = UNLIMITED_SPP
    return opts, pick


def render(desc: dict, settings: dict, progress=None, preview=None, cancelled=lambda: False, denoise=False):
    """gdmlt.render with method "auto": the pilot, then the chosen method for the rest of the
    budget. Returns the render's (raw) result with stats["auto"] = what `choose` found.
    `denoise`: choose for an image that will be denoised."""
    import gdmlt

    scene = gdmlt.Scene(desc)
    opts, pick = plan(desc, settings, cancelled, denoise, scene)
    extra = {k: v for k, v in (("progress", progress), ("preview", preview)) if v is not None}
    res = gdmlt.render(scene, **opts, **extra)
    res["stats"]["auto"] = pick
    return res
