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

The raw Combined layer is kept as "Noisy Image" (Cycles' pass of that name). Guides that a
render did not produce are not used. Inputs are never modified.

Parameters (defaults once, here): ``prefilter=True`` (step 1), ``threads=0`` (all cores;
the render's thread setting), ``quality="high"``.

The binding is the `pyoidn` package (it bundles the OIDN library). Without it, `available()`
is False and `denoise` raises `DenoiserUnavailable`; the CLI and Blender then write the raw
image with a warning.
"""

import numpy as np

NOISY = "Noisy Image"
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


def denoise(layers: dict, *, prefilter=True, threads=0, quality="high") -> dict:
    """A render's layers with Combined denoised and the raw Combined as "Noisy Image" (every
    other layer unchanged; the guides are the render's own, not their prefiltered copies)."""
    if "Combined" not in layers:
        raise ValueError("denoise: the layers have no 'Combined' image")
    out = dict(layers)
    out[NOISY] = layers["Combined"]
    out["Combined"] = denoise_image(layers["Combined"], layers.get(ALBEDO), layers.get(NORMAL),
                                    prefilter=prefilter, threads=threads, quality=quality)
    return out


def denoise_or_warn(layers: dict, warn, *, threads=0) -> dict:
    """`denoise(layers)`, or, when OIDN is not available, the layers unchanged and one call
    of `warn(message)` (the documented fallback: the raw image, never no image)."""
    try:
        return denoise(layers, threads=threads)
    except DenoiserUnavailable as e:
        warn(f"{e}; the image was written without denoising")
        return layers
