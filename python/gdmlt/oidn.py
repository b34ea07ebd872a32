"""Denoising a render's layers with Intel Open Image Denoise (OIDN), as Cycles does.

    import gdmlt
    res = gdmlt.render(scene, method="gdpt", time_limit=4)
    layers = gdmlt.denoise(res["layers"])   # "Combined" denoised, "Noisy Image" the raw one

What it does, for every method:

1. **Prefilter the guides** (Cycles' "Accurate" prefilter): the "Denoising Albedo" and
   "Denoising Normal" layers are themselves Monte Carlo estimates (depth of field, glass,
   anti-aliasing), so each is first denoised on its own with OIDN's RT filter; the colour
   filter is then told its guides are clean (`cleanAux`).
2. **Denoise the image**: OIDN's RT filter, HDR, quality "high", on the Combined layer.
   For the gradient-domain methods (`gdpt`, `gdpssmlt`) the image handed to OIDN is their
   reconstruction (the Combined layer), which docs/denoising.md measured against the other
   ways of combining the gradients with the denoiser.

3. **Give back what the raw image already knows** (`restore_detail`; renders with a
   "Variance" layer — `pt`, and `auto` when it picks `pt`): OIDN also smooths away detail
   that the raw image has resolved (at high sample counts its output is further from the
   converged image than the raw one). Over each (2r+1)² window, with D the denoised and X
   the raw image, V the variance of a raw pixel's brightness (R + G + B)/3 (the layer: its
   samples' variance over their count) and E the mean of the squared difference of X's and
   D's brightness, the output is D + k·(X − D), k = max(0, 1 − c·V/E):
   the share of the difference that is not noise (a Wiener weight; c > 1 because a
   heavy-tailed pixel's variance estimated from its own samples is too often too small).
   Where the raw image is noisy, E ≈ V and the denoised image stays; where OIDN removed
   more than noise, the raw image's detail comes back. A pixel of fewer than
   ``gdmlt.VARIANCE_MIN_SAMPLES`` (64) samples has an unknown variance in the layer and
   keeps D: so few samples miss a hard-lit room's rare bright paths (restoring them took
   the door-ajar room to 1.6× OIDN's error at 16 spp); so does every window that holds such
   a pixel.

4. **Keep the raw image's mean** (`keep_mean`, every method): OIDN and step 3 move the
   image's mean (a room through a glazed window −3.6%, a door-ajar room +5%, a 16² frame with
   one lit pixel −40%), where the raw image is unbiased. Per channel, over (2r+1)² windows
   (r = ``MEAN_RADIUS``) the denoised image is scaled towards the raw window's mean by the
   share of their difference that is not the raw mean's noise (step 3's Wiener weight and
   caution; the noise from the Variance layer where known, else from the squared raw −
   denoised difference, which overstates it), then over the whole image to the raw mean
   exactly. Multiplicative, so black stays black (a raw image of 0 gives 0); where OIDN left
   no light that the raw image has, the raw mean is added evenly.
5. **Stay premultiplied** (`keep_premultiplied`, renders with an "Alpha" layer: Film ›
   Transparent): colour 0 where alpha is 0, as in the raw image, and at most alpha × the
   largest unpremultiplied raw colour in its 5×5 window where alpha is partial — OIDN
   otherwise spreads light into the transparent pixels, a glow around every object once
   composited over a plate.

The raw Combined layer is kept as "Noisy Image" (Cycles' pass of that name). Guides that a
render did not produce are not used. Inputs are never modified.

Parameters (defaults once, here): ``prefilter=True`` (step 1), ``threads=0`` (all cores;
the render's thread setting), ``quality="high"``, ``restore=True`` (step 3) with
``RESTORE_RADIUS = 2`` and ``RESTORE_CAUTION = 4`` (c), ``MEAN_RADIUS = 8`` and
``MEAN_CAUTION = 4`` (step 4; 1 and 4 measured alike, 4 a little ahead on the bulb). Measured with `pt`'s layer
(2026-12-05, 128², 8 bounces, 2 seeds, relMSE less the reference's noise, against OIDN
alone): world colour at 512 spp −30%, area + point + sun + world at 256 spp −6%, the
built-in lights scene at 256 spp −24%; door ajar at 128 spp, gap at 256, glass box at
128, the 64-lamp hall at 64: equal. c = 1 was 2.5–7× worse on the door (too little
caution), c = 2 equal but for the door (+1–4%); docs/denoising.md.

The binding is the `pyoidn` package (it bundles the OIDN library). Without it, `available()`
is False and `denoise` raises `DenoiserUnavailable`; the CLI and Blender then write the raw
image with a warning.
"""

import numpy as np

# the Variance layer's value where a pixel has too few samples: the core's own (film.rs)
from . import VARIANCE_UNKNOWN

NOISY = "Noisy Image"
VARIANCE = "Variance"
RESTORE_RADIUS = 2
RESTORE_CAUTION = 4.0
MEAN_RADIUS = 8
MEAN_CAUTION = RESTORE_CAUTION
ALPHA = "Alpha"
ALBEDO = "Denoising Albedo"
NORMAL = "Denoising Normal"


class DenoiserUnavailable(RuntimeError):
    """OIDN's binding (the `pyoidn` package) is not installed or its library did not load."""


def _pyoidn():
    try:
        import pyoidn
    except Exception as e:  # noqa: BLE001 — ImportError, or OSError from a library that does not load
        raise DenoiserUnavailable(f"the denoiser needs the pyoidn package (Intel Open Image Denoise): {e}") from e
    return pyoidn


def available() -> bool:
    """Whether OIDN can be loaded in this process."""
    try:
        _pyoidn()
    except DenoiserUnavailable:
        return False
    return True


def _finite_rgb(img, name):
    a = np.asarray(img, dtype=np.float32)
    if a.ndim != 3 or a.shape[2] < 3 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"denoise: layer '{name}' must be an (H, W, 3) image, got shape {a.shape}")
    a = np.ascontiguousarray(a[..., :3])
    if not np.isfinite(a).all():
        a = np.where(np.isfinite(a), a, 0.0).astype(np.float32)
    return a


class _Device:
    """One committed OIDN CPU device for the filter runs of one denoise (the guides'
    prefilters and the image): created once, released on exit."""

    def __init__(self, pyoidn, threads):
        self.pyoidn = pyoidn
        self.dev = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
        if threads:
            self.dev.set_int("numThreads", int(threads))
        self.dev.commit()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.dev.release()

    def run(self, images, *, hdr, clean_aux, quality):
        """One RT filter execution; `images` maps OIDN slot → array ('output' is written)."""
        pyoidn = self.pyoidn
        flt = pyoidn.Filter(self.dev, pyoidn.OIDN_FILTER_TYPE_RT)
        try:
            for slot, arr in images.items():
                flt.set_image(slot, arr, pyoidn.OIDN_FORMAT_FLOAT3)
            flt.set_bool("hdr", hdr)
            flt.set_bool("cleanAux", clean_aux)
            flt.set_quality(quality)
            flt.commit()
            flt.execute()
            err = self.dev.get_error()
            if err:
                raise RuntimeError(f"denoise: OIDN failed: {err}")
        finally:
            flt.release()


def session(threads=0):
    """One OIDN device for several `denoise_image(..., device=)` calls (`with session() as d:`),
    so that many small images (the automatic method's pilot) pay for it once."""
    return _Device(_pyoidn(), threads)


def denoise_image(color, albedo=None, normal=None, *, prefilter=True, threads=0, quality="high", device=None):
    """OIDN on one linear HDR image (H, W, 3) with optional albedo and normal guides; returns
    a new float32 image. Negative and non-finite values are not valid OIDN input: they are
    clamped to 0 in the copy that is denoised. `device`: a `session()` to run on (else one
    is created for this call)."""
    pyoidn = _pyoidn()
    q = {"high": pyoidn.OIDN_QUALITY_HIGH, "balanced": pyoidn.OIDN_QUALITY_BALANCED,
         "fast": pyoidn.OIDN_QUALITY_FAST}[quality]
    c = np.maximum(_finite_rgb(color, "Combined"), 0.0)
    images = {"color": c}
    guides = {}
    if albedo is not None:
        guides["albedo"] = np.clip(_finite_rgb(albedo, ALBEDO), 0.0, 1.0)
    if normal is not None:
        guides["normal"] = np.clip(_finite_rgb(normal, NORMAL), -1.0, 1.0)
    if "normal" in guides and "albedo" not in guides:
        guides.pop("normal")  # OIDN takes a normal guide only together with an albedo
    for slot, g in guides.items():
        if g.shape != c.shape:
            raise ValueError(f"denoise: the {slot} guide is {g.shape[1]}×{g.shape[0]}, the image {c.shape[1]}×{c.shape[0]}")
    out = np.empty_like(c)
    if device is None:
        with _Device(pyoidn, threads) as dev:
            return denoise_image(c, guides.get("albedo"), guides.get("normal"), prefilter=prefilter,
                                 quality=quality, device=dev)
    for slot, g in guides.items():
        if prefilter:
            clean = np.empty_like(g)
            device.run({slot: g, "output": clean}, hdr=False, clean_aux=False, quality=q)
            g = clean
        images[slot] = g
    images["output"] = out
    device.run(images, hdr=True, clean_aux=prefilter and bool(guides), quality=q)
    return out


def denoise(layers: dict, *, prefilter=True, threads=0, quality="high", restore=True) -> dict:
    """A render's layers with Combined denoised and the raw Combined as "Noisy Image" (every
    other layer unchanged; the guides are the render's own, not their prefiltered copies).
    `restore`: with a "Variance" layer, step 3 (`restore_detail`)."""
    if "Combined" not in layers:
        raise ValueError("denoise: the layers have no 'Combined' image")
    out = dict(layers)
    out[NOISY] = layers["Combined"]
    raw = layers["Combined"]
    out["Combined"] = denoise_image(raw, layers.get(ALBEDO), layers.get(NORMAL),
                                    prefilter=prefilter, threads=threads, quality=quality)
    variance = layers.get(VARIANCE)
    if restore and variance is not None:
        out["Combined"] = restore_detail(raw, out["Combined"], variance)
    out["Combined"] = keep_mean(raw, out["Combined"], variance)
    if layers.get(ALPHA) is not None:
        out["Combined"] = keep_premultiplied(raw, out["Combined"], layers[ALPHA])
    return out


def _shifted_max(a, r):
    """Maximum over the (2r+1)² window around each pixel of an (H, W, C) array (edges
    repeated), by shifts: memory of two images, whatever the size."""
    h, w = a.shape[:2]
    p = np.pad(a, ((r, r), (r, r), (0, 0)), mode="edge")
    out = np.full_like(a, -np.inf)
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            np.maximum(out, p[dy:dy + h, dx:dx + w], out=out)
    return out


def keep_premultiplied(noisy, denoised, alpha, radius=RESTORE_RADIUS):
    """Step 5: the denoised colour made premultiplied by the film's alpha again. OIDN spreads
    light into pixels the camera saw only the (transparent) world through; composited
    "over" a plate that adds a glow around every object. So: colour 0 where alpha is 0 (as
    the raw image has it), and where alpha is partial at most alpha × the largest
    unpremultiplied raw colour in the pixel's (2r+1)² window (per channel)."""
    d = np.asarray(denoised, np.float32)[..., :3].copy()
    a = np.nan_to_num(np.asarray(alpha, np.float32).reshape(d.shape[:2]), nan=0.0, posinf=1.0, neginf=0.0)
    x = np.nan_to_num(np.asarray(noisy, np.float32)[..., :3], nan=0.0, posinf=0.0, neginf=0.0)
    seen = a > 0.0
    colour = np.where(seen[..., None], x / np.where(seen, a, 1.0)[..., None], -np.inf).astype(np.float32)
    bound = a[..., None] * np.maximum(_shifted_max(colour, radius), 0.0)
    partial = (seen & (a < 1.0))[..., None]
    d = np.where(partial, np.minimum(d, bound), d)
    d[~seen] = 0.0
    return d


def keep_mean(noisy, denoised, variance=None, radius=MEAN_RADIUS, caution=MEAN_CAUTION):
    """Step 4: the raw image's mean kept, at the scale of (2r+1)² windows and over the whole
    image. OIDN (and the restore step) move the image's mean — a room lit through a glazed
    window by −3.6%, a door-ajar room by +5% — and a 16² frame with one lit pixel by −40%,
    where the raw image is unbiased. At each scale, per channel, the denoised image is scaled
    towards the raw one's local mean by the ratio of the two means, weighted by the share of
    their difference that is not the raw mean's own noise (the restore step's Wiener weight,
    with the same caution). The raw pixels' noise: pt's Variance layer where known, else
    their squared difference from the denoised image (larger: it also holds what OIDN
    removed, so it corrects less). Multiplicative where the denoised window has light, so a
    black frame stays black; where OIDN left a window or the image with none that the raw
    image has, the raw mean is added evenly."""
    x = np.asarray(noisy, np.float64)[..., :3]
    d = np.asarray(denoised, np.float64)[..., :3]
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(d))):
        return np.asarray(denoised, np.float32)
    noise = (x - d).mean(-1) ** 2
    if variance is not None:
        v = np.asarray(variance, np.float64).reshape(x.shape[:2])
        noise = np.where(np.isfinite(v) & (v < 0.5 * VARIANCE_UNKNOWN), np.maximum(v, 0.0), noise)
    h, w = x.shape[:2]
    n_local = min((2 * radius + 1) ** 2, h * w)
    box = lambda a: np.stack([_box(a[..., c], radius) for c in range(a.shape[2])], -1)  # noqa: E731
    for scale in ("window", "image"):
        if scale == "image":
            mx, md, k = x.mean((0, 1)), d.mean((0, 1)), 1.0  # the raw mean, whose noise is its own
        else:
            mx, md, var = box(x), box(d), _box(noise, radius) / n_local
            delta2 = (mx - md).mean(-1) ** 2
            k = np.clip(1.0 - caution * var / np.maximum(delta2, 1e-300), 0.0, 1.0)
            # a window the raw image has no light in at all says little at few samples (the
            # light may just not have been found yet): left as OIDN has it
            k = np.where((delta2 > 0.0) & (mx.max(-1) > 0.0), k, 0.0)[..., None]
        # towards the raw mean by the share k: scaled where the denoised mean is positive
        # (black stays black), the missing mean added evenly where OIDN left nothing
        lost = md <= 0.0
        ratio = np.where(lost, 1.0, mx / np.where(lost, 1.0, md))
        d = d * (1.0 + k * (ratio - 1.0)) + np.where(lost, k * np.maximum(mx, 0.0), 0.0)
    return np.maximum(d, 0.0).astype(np.float32)


def _box(a, r):
    """Mean over the (2r+1)² window around each pixel of a 2-D array (edges repeated), f64."""
    n = 2 * r + 1
    c = np.pad(np.pad(a.astype(np.float64), r, mode="edge").cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    h, w = a.shape
    return (c[n:n + h, n:n + w] - c[:h, n:n + w] - c[n:n + h, :w] + c[:h, :w]) / (n * n)


def restore_detail(noisy, denoised, variance, radius=RESTORE_RADIUS, caution=RESTORE_CAUTION):
    """Step 3 of the module's recipe: `denoised` + k·(`noisy` − `denoised`), k per pixel from
    the raw pixels' `variance` (H, W) or (H, W, 1) and the local mean squared difference."""
    x = np.asarray(noisy, np.float64)[..., :3]
    d = np.asarray(denoised, np.float64)[..., :3]
    v = np.asarray(variance, np.float64).reshape(x.shape[:2])
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
        return np.asarray(denoised, np.float32)  # nothing to trust: the denoised image as it is
    diff2 = _box((x - d).mean(-1) ** 2, radius)
    # unknown pixels (VARIANCE_UNKNOWN: too few samples) keep D wherever a window holds one;
    # they are left out of the box sums, whose running differences would lose the small
    # variances beside them
    unknown = v >= 0.5 * VARIANCE_UNKNOWN
    var = _box(np.where(unknown, 0.0, np.maximum(v, 0.0)), radius)
    k = np.clip(1.0 - caution * var / np.maximum(diff2, 1e-30), 0.0, 1.0)
    k[_box(unknown.astype(np.float64), radius) > 0.0] = 0.0
    out = d + k[..., None] * (x - d)
    return np.maximum(out, 0.0).astype(np.float32)


def denoise_or_warn(layers: dict, warn, *, threads=0) -> dict:
    """`denoise(layers)`, or, when OIDN is not available, the layers unchanged and one call
    of `warn(message)` (the documented fallback: the raw image, never no image)."""
    try:
        return denoise(layers, threads=threads)
    except DenoiserUnavailable as e:
        warn(f"{e}; the image was written without denoising")
        return layers
