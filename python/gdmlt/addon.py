"""Finding and enabling the Blender addon from Python (tests, the CLI, scripts)."""

import atexit
import importlib.util
import os
import sys
from pathlib import Path

MODULE_NAME = "gdmlt_blender"


def addon_dir() -> Path:
    """The addon's source folder: $GDMLT_ADDON_DIR, else blender_addon/ of this checkout."""
    env = os.environ.get("GDMLT_ADDON_DIR")
    if env:
        return Path(env)
    here = Path(__file__).resolve().parent
    for cand in (here.parent.parent / "blender_addon", here / "blender_addon"):
        if (cand / "__init__.py").exists():
            return cand
    raise FileNotFoundError(
        "the GDMLT Blender addon was not found next to the gdmlt package; set GDMLT_ADDON_DIR"
    )


def enable_addon():
    """Import the addon into the running bpy and register it (idempotent). Returns the module."""
    import bpy  # noqa: F401  (the addon needs bpy loaded first)

    mod = sys.modules.get(MODULE_NAME)
    if mod is None:
        path = addon_dir()
        spec = importlib.util.spec_from_file_location(
            MODULE_NAME, path / "__init__.py", submodule_search_locations=[str(path)]
        )
        mod = importlib.util.module_from_spec(spec)
        sys.modules[MODULE_NAME] = mod
        spec.loader.exec_module(mod)
    if not getattr(mod, "_registered", False):
        mod.register()
        # Blender 4.5's bpy module does not exit while an add-on's classes are still
        # registered (the process hangs after Python has finished); 5.x does. Unregister
        # first (Python's exit handlers run before bpy's own teardown).
        atexit.register(_unregister, mod)
    return mod


def _unregister(mod):
    if getattr(mod, "_registered", False):
        try:
            mod.unregister()
        except Exception:  # noqa: BLE001  (at exit: nothing left to tell)
            pass
