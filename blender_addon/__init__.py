"""GDMLT render engine for Blender.

Modules: properties (scene.gdmlt settings), engine (the RenderEngine), export (evaluated
depsgraph → scene arrays for the core), ui (panels). The Rust core is the `gdmlt` Python
package: bundled as a wheel inside the extension zip (`make addon`), or installed next to
bpy. The engine registers only if the core imports; otherwise the add-on's preferences say
why, and nothing else is registered (no engine that would fail on F12).
"""

import bpy

# properties, engine, ui (and export, which builds scene dicts with gdmlt.scenedict) are
# imported once the core is known to load: the add-on depends on the gdmlt package, one way

_registered = False
core_error = None  # why the core could not be imported, shown in the preferences


def _core_import_error():
    try:
        from gdmlt import _core  # noqa: F401
    except Exception as e:  # ImportError, or an OSError from a wheel built for another CPU/OS
        return f"{type(e).__name__}: {e}"
    return None


class GDMLTPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    def draw(self, context):
        layout = self.layout
        if core_error:
            col = layout.column()
            col.alert = True
            col.label(text="The GDMLT core could not be loaded, so the render engine is not registered:", icon="ERROR")
            col.label(text=core_error)
            layout.label(text="Install the extension zip built for this platform (make addon), or pip install gdmlt "
                              "into Blender's Python.")
        else:
            import gdmlt

            layout.label(text=f"GDMLT core loaded from {gdmlt.__file__}", icon="CHECKMARK")


def register():
    global _registered, core_error
    bpy.utils.register_class(GDMLTPreferences)
    core_error = _core_import_error()
    if core_error is None:
        from . import engine, properties, ui

        properties.register()
        bpy.utils.register_class(engine.GDMLTRenderEngine)
        ui.register()
    else:
        print(f"GDMLT: render engine not registered: {core_error}")
    _registered = True


def unregister():
    global _registered
    if core_error is None:
        from . import engine, properties, ui

        ui.unregister()
        bpy.utils.unregister_class(engine.GDMLTRenderEngine)
        properties.unregister()
    bpy.utils.unregister_class(GDMLTPreferences)
    _registered = False
