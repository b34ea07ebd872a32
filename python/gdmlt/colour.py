"""The one colour pipeline of the PNGs GDMLT writes beside its EXRs: the rendered image
(scene-linear Rec.709, premultiplied alpha) shown through the scene's view — Blender's
colour management: display device, view transform, look, exposure and gamma — as Blender
shows it, whatever the scene came from:

- a .blend file: its scene's view (`view_of`);
- a USD stage written by `gdmlt export`: the view it stored (customLayerData gdmlt "view");
- a built-in scene or any other stage: Standard (plain sRGB), what an unmanaged viewer shows.

Standard on an sRGB display, with any exposure and gamma, is computed here: the linear
colour × 2^exposure, un-premultiplied, the sRGB transfer function, then the display value
to the power 1/gamma (Blender's order). Other views (AgX, Filmic, Khronos PBR Neutral,
looks) need Blender's OpenColorIO configuration: they go through bpy's own colour
management when bpy is installed; without it the PNG is written with Standard and a
warning says so. No dither (Blender's render dither is left out: the PNG is a function of
the EXR alone).
"""

import sys
from pathlib import Path

import numpy as np

STANDARD = {"display_device": "sRGB", "view_transform": "Standard", "look": "None", "exposure": 0.0, "gamma": 1.0}


def view_of(scene) -> dict:
    """A Blender scene's view (its Color Management panel)."""
    v = scene.view_settings
    return {"display_device": scene.display_settings.display_device, "view_transform": v.view_transform,
            "look": v.look, "exposure": float(v.exposure), "gamma": float(v.gamma)}


def checked_view(stored, where: str) -> dict:
    """A stored view (e.g. a USD stage's) with its keys checked; ValueError naming `where`."""
    if not isinstance(stored, dict):
        raise ValueError(f"{where}: view must be a dictionary, got {stored!r}")
    view = dict(STANDARD)
    for key, value in stored.items():
        if key not in STANDARD:
            continue
        kind = type(STANDARD[key])
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) if kind is float else isinstance(value, str)
        if not ok or (kind is float and not np.isfinite(value)):
            raise ValueError(f"{where}: view '{key}' must be a {'number' if kind is float else 'name'}, got {value!r}")
        view[key] = kind(value)
    if view["gamma"] <= 0:
        raise ValueError(f"{where}: view 'gamma' must be positive, got {view['gamma']}")
    return view


def is_standard(view: dict) -> bool:
    return (view["display_device"] == "sRGB" and view["view_transform"] == "Standard"
            and view["look"] in ("None", ""))


def srgb_encode(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_decode(v):
    v = np.clip(v, 0.0, 1.0)
    return np.where(v <= 0.04045, v / 12.92, np.power((v + 0.055) / 1.055, 2.4))


def standard_linear(image: np.ndarray, view: dict) -> np.ndarray:
    """The image, premultiplied as rendered, with exposure and gamma folded in so that the
    core's sRGB PNG writer (un-premultiply, sRGB, 8 bits) writes Standard with them."""
    img = np.array(image, dtype=np.float32, copy=True)
    img[..., :3] *= np.float32(2.0 ** view["exposure"])
    if view["gamma"] != 1.0:
        a = img[..., 3:4] if img.shape[2] >= 4 else np.ones_like(img[..., :1])
        straight = np.divide(img[..., :3], a, out=np.zeros_like(img[..., :3]), where=a > 0)
        display = np.power(srgb_encode(straight), 1.0 / view["gamma"])
        img[..., :3] = srgb_decode(display) * a
    return img


def write_png(path, image: np.ndarray, view: dict | None = None, warn=None):
    """Writes `image` (H, W, 3 or 4; top row first) as an 8-bit PNG through `view` (default
    Standard), marked as GDMLT's (gdmlt.outputs)."""
    import gdmlt

    view = dict(STANDARD, **(view or {}))
    if not is_standard(view):
        say = warn or (lambda m: print(f"gdmlt: warning: {m}", file=sys.stderr))
        try:
            _blender_png(Path(path), image, view)
            return
        except ImportError:
            say(f"the view transform '{view['view_transform']}' needs Blender's colour management (bpy), which "
                f"is not installed: {path} is written with Standard")
        except TypeError as e:  # a name this Blender does not know (bpy's enum error)
            say(f"{e}: {path} is written with Standard")
    gdmlt.write_png(str(path), standard_linear(image, view))


def _blender_png(path: Path, image: np.ndarray, view: dict):
    """The PNG through bpy's colour management (Image.save_render with a scene holding `view`)."""
    from .blend import import_bpy

    bpy = import_bpy()
    from .outputs import mark_png

    h, w = image.shape[:2]
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., : min(4, image.shape[2])] = image[..., :4]
    scene = bpy.data.scenes.new("gdmlt-png")
    img = bpy.data.images.new("gdmlt-png", w, h, alpha=True, float_buffer=True)
    try:
        scene.display_settings.display_device = view["display_device"]
        scene.view_settings.view_transform = view["view_transform"]
        scene.view_settings.look = view["look"]
        scene.view_settings.exposure, scene.view_settings.gamma = view["exposure"], view["gamma"]
        scene.render.dither_intensity = 0.0
        s = scene.render.image_settings
        s.file_format, s.color_mode, s.color_depth = "PNG", "RGBA" if image.shape[2] >= 4 else "RGB", "8"
        img.pixels.foreach_set(np.ascontiguousarray(rgba[::-1]).ravel())  # Blender's rows: bottom first
        img.save_render(str(path), scene=scene)
    finally:
        bpy.data.images.remove(img)
        bpy.data.scenes.remove(scene)
    mark_png(path)
