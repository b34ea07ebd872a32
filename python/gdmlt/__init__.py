"""GDMLT: a physically based render engine for Blender with a Rust core.

    import gdmlt
    scene = gdmlt.Scene(gdmlt.builtin_scene("cornell", 128, 128))
    result = gdmlt.render(scene, method="pt", spp=64)
    result["layers"]["Combined"]        # float32 (H, W, 3), linear, top row first
    layers = gdmlt.denoise(result["layers"])   # Intel Open Image Denoise; raw kept as "Noisy Image"

Blender: ``gdmlt.enable_addon()`` registers the render engine in the running bpy.
"""

import os as _os

from . import _core


def _pick_core():
    """The x86-64-v3 build of the core when this CPU runs it and it was built from the same
    sources (the Makefile builds both; GDMLT_CPU=portable forces the portable one), else the
    portable build."""
    if _os.environ.get("GDMLT_CPU", "").lower() != "portable" and _core.cpu_supports_x86_64_v3():
        try:
            from . import _core_v3
        except ImportError:
            return _core
        if _core_v3.SOURCE_HASH == _core.SOURCE_HASH:
            return _core_v3
        import warnings

        warnings.warn("gdmlt: _core_v3 was built from other sources than _core (run `make build`); "
                      "using the portable core", RuntimeWarning, stacklevel=2)
    return _core


_impl = _pick_core()
Scene, render, builtin_scene = _impl.Scene, _impl.render, _impl.builtin_scene
write_exr, write_png, reconstruct = _impl.write_exr, _impl.write_png, _impl.reconstruct
METHODS, __version__, BUILD_TARGET = _impl.METHODS, _impl.__version__, _impl.BUILD_TARGET
RR_START_DEPTH, RR_EXPONENT = _impl.RR_START_DEPTH, _impl.RR_EXPONENT
# samples a pixel needs before pt's Variance layer (and so the denoiser's restore step) trusts it
VARIANCE_MIN_SAMPLES, VARIANCE_UNKNOWN = _impl.VARIANCE_MIN_SAMPLES, _impl.VARIANCE_UNKNOWN
check_memory, bootstrap_paths = _impl.check_memory, _impl.bootstrap_paths
procedural_range = _impl.procedural_range
from .addon import enable_addon, addon_dir
from .oidn import denoise

__all__ = ["Scene", "render", "builtin_scene", "denoise", "write_exr", "write_png", "reconstruct", "METHODS", "enable_addon", "addon_dir",
           "__version__", "BUILD_TARGET", "RR_START_DEPTH", "RR_EXPONENT",
           "VARIANCE_MIN_SAMPLES", "VARIANCE_UNKNOWN"]
