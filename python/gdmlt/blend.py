"""Rendering a .blend file through the GDMLT addon in bpy, as `blender -b file -f` would."""

import os
import tempfile
from pathlib import Path

# keys of gdmlt.render's keyword arguments → scene.gdmlt property names
PROPERTY_OF = {"method": "method", "spp": "samples", "time_limit": "time_limit", "max_bounces": "max_bounces",
               "nee": "use_nee", "seed": "seed", "threads": "threads",
               "reconstruction": "reconstruction", "alpha_rec": "alpha_reconstruction",
               "alpha_target": "alpha_target", "large_step_probability": "large_step_probability",
               "chains": "chains"}


def import_bpy():
    """Import bpy with Blender's user config kept out of the home directory."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(Path(tempfile.gettempdir()) / "gdmlt-blender-user"))
    import bpy  # noqa: F401
    return bpy


def apply_settings(scene, settings: dict):
    for k, v in settings.items():
        setattr(scene.gdmlt, PROPERTY_OF[k], v.upper() if k in ("method", "reconstruction") else v)


def render_blend(path: Path, out: Path, settings: dict, width=None, height=None, png=True) -> dict:
    """Opens `path`, renders its active scene with GDMLT into `out` (EXR, 32-bit float) and
    `out.png`. Raises RuntimeError with Blender's report if the render fails."""
    bpy = import_bpy()
    from .addon import enable_addon

    mod = enable_addon()  # before loading, so the file's engine and settings resolve
    bpy.ops.wm.open_mainfile(filepath=str(path))
    scene = bpy.context.scene
    scene.render.engine = "GDMLT"
    apply_settings(scene, settings)
    if width:
        scene.render.resolution_x = width
    if height:
        scene.render.resolution_y = height
    if width or height:
        scene.render.resolution_percentage = 100
    img = scene.render.image_settings
    img.file_format = "OPEN_EXR"
    img.color_depth = "32"
    img.color_mode = "RGB"
    scene.render.filepath = str(out.resolve())
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    if png:
        img.file_format = "PNG"
        img.color_depth = "8"
        bpy.data.images["Render Result"].save_render(str(out.with_suffix(".png").resolve()), scene=scene)
    return dict(getattr(mod.engine, "last_stats", {}) or {})
