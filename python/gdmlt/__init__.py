"""GDMLT: a physically based render engine for Blender with a Rust core.

    import gdmlt
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 128, 128))
    result = gdmlt.render(scene, method="pt", spp=64)
    result["layers"]["Combined"]        # float32 (H, W, 3), linear, top row first

Blender: ``gdmlt.enable_addon()`` registers the render engine in the running bpy.
"""

from ._core import Scene, render, builtin_scene, write_exr, write_png, reconstruct, METHODS, __version__
from .addon import enable_addon, addon_dir

__all__ = ["Scene", "render", "builtin_scene", "write_exr", "write_png", "reconstruct", "METHODS", "enable_addon", "addon_dir", "__version__"]
