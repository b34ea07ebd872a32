"""GDMLT render engine for Blender.

Modules: properties (scene.gdmlt settings), engine (the RenderEngine), export (evaluated
depsgraph → scene arrays for the core), ui (panels). The Rust core is the `gdmlt` Python
package (import gdmlt), installed next to bpy.
"""

import bpy

from . import properties, engine, ui

_registered = False


def register():
    global _registered
    properties.register()
    bpy.utils.register_class(engine.GDMLTRenderEngine)
    ui.register()
    _registered = True


def unregister():
    global _registered
    ui.unregister()
    bpy.utils.unregister_class(engine.GDMLTRenderEngine)
    properties.unregister()
    _registered = False
