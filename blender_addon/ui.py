"""Render Properties panels for GDMLT, and the standard panels it shares with other engines."""

import bpy


class GDMLTRenderPanel:
    """What every GDMLT Render Properties panel shares."""
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {"GDMLT"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def split_layout(self):
        """The panel's layout as Cycles lays its panels out: labels on the left, no
        keyframe dots."""
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        return layout


class GDMLT_PT_sampling(GDMLTRenderPanel, bpy.types.Panel):
    bl_label = "Sampling"

    def draw(self, context):
        s = context.scene.gdmlt
        layout = self.split_layout()
        layout.prop(s, "method")
        row = layout.row(heading="Noise Threshold")  # as Cycles' Render panel
        row.prop(s, "use_adaptive_sampling", text="")
        sub = row.row()
        sub.active = s.use_adaptive_sampling and s.method in {"AUTO", "PT"}
        sub.prop(s, "adaptive_threshold", text="")
        col = layout.column(align=True)
        col.prop(s, "samples", text="Max Samples" if s.use_adaptive_sampling else "Render Samples")
        sub = col.column(align=True)
        sub.active = s.use_adaptive_sampling
        sub.prop(s, "adaptive_min_samples")
        col.prop(s, "time_limit")
        layout.prop(s, "preview_samples", text="Viewport Samples")
        layout.prop(s, "seed")
        layout.prop(s, "use_denoising")
        if s.method in {"AUTO", "GDPT", "GDPSSMLT"}:
            col = layout.column(align=True)
            col.prop(s, "reconstruction")
            col.prop(s, "alpha_reconstruction", text="Alpha (0 = Automatic)")
        if s.method in {"AUTO", "PSSMLT", "GDPSSMLT"}:
            col = layout.column(align=True)
            col.prop(s, "large_step_probability")
            col.prop(s, "chains")
            if s.method in {"AUTO", "GDPSSMLT"}:
                col.prop(s, "alpha_target")


class GDMLT_PT_light_paths(GDMLTRenderPanel, bpy.types.Panel):
    bl_label = "Light Paths"

    def draw(self, context):
        s = context.scene.gdmlt
        layout = self.split_layout()
        col = layout.column(align=True)
        col.prop(s, "max_bounces", text="Max Bounces Total")
        col.prop(s, "diffuse_bounces")
        col.prop(s, "glossy_bounces")
        col.prop(s, "transmission_bounces")
        col.prop(s, "volume_bounces")
        col.prop(s, "transparent_max_bounces")
        col = layout.column(align=True, heading="Clamping")
        col.prop(s, "clamp_direct")
        col.prop(s, "clamp_indirect")
        layout.prop(s, "use_nee")


class GDMLT_PT_performance(GDMLTRenderPanel, bpy.types.Panel):
    bl_label = "Performance"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        self.split_layout().prop(context.scene.gdmlt, "threads")


class GDMLT_PT_film(GDMLTRenderPanel, bpy.types.Panel):
    bl_label = "Film"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        s = context.scene.gdmlt
        layout = self.split_layout()
        col = layout.column(align=True)
        col.prop(s, "pixel_filter_type")
        if s.pixel_filter_type != "BOX":
            col.prop(s, "filter_width")
        # Blender's own setting, as Cycles' Film > Transparent: the world seen by the camera
        # becomes alpha
        layout.prop(context.scene.render, "film_transparent", text="Transparent")


def wrapped(text: str, width: int = 72) -> list:
    """`text` in lines of at most `width` characters, broken at spaces (a panel label does not
    wrap)."""
    lines, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    return lines + ([line] if line else [])


class GDMLT_PT_last_render(GDMLTRenderPanel, bpy.types.Panel):
    """The last render's warnings (material, node, object or light named), kept until the
    next render."""
    bl_label = "Last Render"

    def draw(self, context):
        from . import engine

        layout = self.layout
        if not engine.last_stats and not engine.last_warnings:
            layout.label(text="No render yet")
            return
        st = engine.last_stats
        if st:
            layout.label(text=f"{st.get('method', '?')}: {st.get('spp_max', 0)} per pixel, "
                              f"{st.get('elapsed', 0.0):.1f} s", icon="INFO")
        if not engine.last_warnings:
            layout.label(text="No warnings", icon="CHECKMARK")
        for w in engine.last_warnings:
            col = layout.column(align=True)
            for k, line in enumerate(wrapped(w)):
                col.label(text=line, icon="ERROR" if k == 0 else "BLANK1")


class GDMLT_PT_passes(GDMLTRenderPanel, bpy.types.Panel):
    """View Layer > Passes: the data passes GDMLT writes besides its method's own (Combined,
    the gradient-domain and Metropolis passes, the denoising guides, Noisy Image)."""
    bl_label = "Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = self.split_layout()
        from gdmlt.passes import DATA_PASSES

        col = layout.column(heading="Data", align=True)
        for _, toggle, *_ in DATA_PASSES:  # the passes the engine writes when they are on
            col.prop(context.view_layer, toggle)


CLASSES = (GDMLT_PT_sampling, GDMLT_PT_light_paths, GDMLT_PT_film, GDMLT_PT_performance, GDMLT_PT_last_render,
           GDMLT_PT_passes)

# Blender's own panels (dimensions, output, colour management, camera, light, world data,
# material slots and surface, world surface, spot shape, depth of field, object visibility)
# show for an engine only when it is in their COMPAT_ENGINES: those for settings GDMLT
# renders.
_SHARED_PANELS = (
    "RENDER_PT_color_management", "RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output",
    "DATA_PT_camera", "DATA_PT_lens", "DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture", "DATA_PT_light",
    "DATA_PT_EEVEE_light", "DATA_PT_spot", "DATA_PT_context_light", "WORLD_PT_context_world",
    "EEVEE_WORLD_PT_surface", "EEVEE_MATERIAL_PT_context_material", "EEVEE_MATERIAL_PT_surface",
    "OBJECT_PT_visibility",
)


def _shared_panels():
    for name in _SHARED_PANELS:
        panel = getattr(bpy.types, name, None)
        if panel is not None and hasattr(panel, "COMPAT_ENGINES"):
            yield panel


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for p in _shared_panels():
        p.COMPAT_ENGINES.add("GDMLT")


def unregister():
    for p in _shared_panels():
        p.COMPAT_ENGINES.discard("GDMLT")
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
