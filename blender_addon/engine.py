"""The GDMLT RenderEngine: export the evaluated depsgraph, render in the Rust core with
progress and Esc, write the image into the render result (F12, and the small previews of
materials, lights and worlds); draw progressive path-traced passes in the 3D View's
Rendered shading (viewport.py)."""

import time

import bpy
import numpy as np

from . import export, viewport

# Statistics of the last finished render in this process (the Last Render panel shows them).
last_stats = {}
# The last render's warnings (export, scene, render), kept for the Render Properties'
# "Last Render" panel: the status bar shows a warning only for a moment.
last_warnings = []

# The one table of extra passes: (name, channels, chan_id, type). Written when the core
# returns a layer of that name (gradient-domain methods write the GD passes).
PASSES = (
    ("GD Primal", 3, "RGB", "COLOR"),
    ("GD Gradient X", 3, "RGB", "COLOR"),
    ("GD Gradient Y", 3, "RGB", "COLOR"),
    ("Denoising Albedo", 3, "RGB", "COLOR"),
    ("Denoising Normal", 3, "XYZ", "VECTOR"),
    ("MLT Density", 3, "RGB", "COLOR"),
    ("Noisy Image", 3, "RGB", "COLOR"),
)


# Passes each method writes (besides Combined).
METHOD_PASSES = {
    "PT": {"Denoising Albedo", "Denoising Normal"},
    "BDPT": {"Denoising Albedo", "Denoising Normal"},
    "GDPT": {"GD Primal", "GD Gradient X", "GD Gradient Y", "Denoising Albedo", "Denoising Normal"},
    "PSSMLT": {"MLT Density", "Denoising Albedo", "Denoising Normal"},
    "GDPSSMLT": {"GD Primal", "GD Gradient X", "GD Gradient Y", "MLT Density", "Denoising Albedo", "Denoising Normal"},
}


def data_passes_of(view_layer) -> list:
    """(name, channels, channel ids, type) of each data pass the view layer has switched on
    (gdmlt.passes: the one table of them)."""
    from gdmlt.passes import DATA_PASSES

    return [row[2:] for row in DATA_PASSES if getattr(view_layer, row[1], False)]


def _to_blender_rows(img, channels):
    """Core image (H, W, C), top row first → flat float32 buffer, bottom row first."""
    h, w = img.shape[:2]
    out = np.empty((h, w, channels), np.float32)
    if channels == 1:
        out[..., 0] = img[::-1, :, 0]
        return out
    out[..., :3] = img[::-1, :, :3]
    if channels == 4:
        out[..., 3] = img[::-1, :, 3] if img.shape[2] >= 4 else 1.0
    return out


def render_threads(scene) -> int:
    """GDMLT's own Threads setting when set; else Blender's fixed thread count (what
    `blender -t N` sets, which farm managers use); else 0 = all cores."""
    own = scene.gdmlt.threads
    if own:
        return own
    r = scene.render
    return r.threads if r.threads_mode == "FIXED" else 0


def remaining_time(fraction: float, elapsed: float) -> str:
    """' | 12.3 s left' for the stats line (gdmlt.progress.seconds_left), or ''."""
    from gdmlt.progress import seconds_left

    left = seconds_left(fraction, elapsed)
    return "" if left is None else f" | {left:.1f} s left"


# Material, light and world preview thumbnails: path-traced, this many samples per pixel.
PREVIEW_SAMPLES = 16


class GDMLTRenderEngine(bpy.types.RenderEngine):
    bl_idname = "GDMLT"
    bl_label = "GDMLT"
    bl_use_preview = True  # material/light/world thumbnails
    bl_use_eevee_viewport = True  # Material Preview shading uses EEVEE, as for Cycles
    bl_use_postprocess = True
    # Blender's own shader nodes (the Shader Editor, the Material tab's slot list and Surface
    # panel, the World's Surface panel) show only for engines without custom nodes: GDMLT
    # reads the Cycles/EEVEE node trees, so it has none of its own.
    bl_use_shading_nodes_custom = False

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.viewport = None  # the viewport's ViewportSession (Rendered shading only)
        self._viewport_error = None

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for name, channels, chan_id, kind in PASSES:
            self.register_pass(scene, renderlayer, name, channels, chan_id, kind)
        for name, channels, chan_id, kind in data_passes_of(renderlayer):
            self.register_pass(scene, renderlayer, name, channels, chan_id, kind)

    def esc_pressed(self) -> bool:
        """Whether the user cancelled (Esc): the one place the engine polls test_break(),
        during export and from the core's progress callback every 50 ms."""
        return self.test_break()

    def render(self, depsgraph):
        try:
            self._render(depsgraph)
        except export.ExportCancelled:
            # Hand Blender an empty (black) result: returning without one makes Blender 5.0.1
            # crash when it writes the frame (`-f`, write_still) after an Esc during export.
            result = self.begin_result(0, 0, self.resolution_x, self.resolution_y)
            self.end_result(result)
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as e:  # noqa: BLE001 - every failure must reach the user, not a blank image
            # (BaseException: a panic in the core arrives as PyO3's PanicException, which is
            # not an Exception, and was saved as a black frame)
            self.report({"ERROR"}, f"GDMLT: {e}")

    def _render(self, depsgraph):
        import gdmlt

        scene = depsgraph.scene
        s = scene.gdmlt
        t0 = time.perf_counter()
        self.update_stats("GDMLT", "Exporting scene")
        desc, warnings = export.export_scene(depsgraph, self.esc_pressed)
        ntri = sum(len(m["indices"]) for m in desc["meshes"])
        self.update_stats("GDMLT", f"Building BVH ({ntri:,} triangles)")
        core_scene = gdmlt.Scene(desc)
        shown = []

        def warn(w):
            if w not in shown:
                shown.append(w)
                if not self.is_preview:
                    self.report({"WARNING"}, f"GDMLT: {w}")

        global last_warnings
        if not self.is_preview:  # thumbnails keep the Last Render panel's warnings
            last_warnings = shown  # filled as the render goes on
        for w in warnings + list(core_scene.warnings):
            warn(w)
        export_time = time.perf_counter() - t0
        from gdmlt.blend import settings_of

        settings = settings_of(s)  # gdmlt.render's keyword arguments, but for these three:
        del settings["method"], settings["denoise"]  # chosen below / applied after the render
        settings["threads"] = render_threads(scene)
        chosen = None
        denoise = s.use_denoising
        if self.is_preview:  # a material, light or world thumbnail: quick and plain
            settings.update(method="pt", spp=PREVIEW_SAMPLES, time_limit=0.0)
            denoise = False
        elif s.method == "AUTO":
            from gdmlt.auto import plan

            self.update_stats("GDMLT", "Automatic method: measuring each method on this scene")
            settings, chosen = plan(desc, settings, self.esc_pressed, denoise=denoise, scene=core_scene)
            self.report({"INFO"}, f"GDMLT: automatic method chose {chosen['method']} ({chosen['why']})")
        method = settings.pop("method", s.method.lower())
        label = method.upper() + (" (auto)" if chosen else "")

        from gdmlt.progress import ProgressThrottle

        # a background render's every stats line is a log line: once per 10% or 10 s there
        throttle = ProgressThrottle(every_poll=not bpy.app.background)

        def progress(fraction, elapsed):
            if throttle(fraction, elapsed):
                self.update_progress(fraction)
                self.update_stats("GDMLT", f"{label} | {fraction * 100:.0f}% | {elapsed:.1f} s"
                                  + remaining_time(fraction, elapsed))
            return self.esc_pressed()

        w, h = core_scene.size
        layer_name = depsgraph.view_layer.name
        wanted = METHOD_PASSES.get(method.upper(), set()) | ({"Noisy Image"} if denoise else set())
        for name, channels, chan_id, _ in PASSES:
            if name in wanted:
                self.add_pass(name, channels, chan_id, layer=layer_name)
        data = data_passes_of(depsgraph.view_layer)
        for name, channels, chan_id, _ in data:
            self.add_pass(name, channels, chan_id, layer=layer_name)
        from gdmlt.passes import needs_core_pass, select

        settings["data_passes"] = needs_core_pass(row[0] for row in data)
        # with a render region the core renders only that window (w × h): Blender's render
        # result is then that region, with its origin at the region's corner
        result = self.begin_result(0, 0, w, h, layer=layer_name)
        try:
            passes = result.layers[0].passes
            channels_of = dict([("Combined", 4)] + [(p[0], p[1]) for p in PASSES] + [(p[0], p[1]) for p in data])
            previews = 0

            def write(name, img):
                if passes.get(name) is not None:
                    buf = _to_blender_rows(img, channels_of[name])
                    passes[name].rect.foreach_set(np.ascontiguousarray(buf).ravel())

            def preview(img):  # intermediate image: shown while the render goes on
                nonlocal previews
                write("Combined", img)
                self.update_result(result)
                previews += 1

            res = gdmlt.render(core_scene, method=method, **settings, progress=progress, preview=preview)
            layers = res["layers"]
            denoised = False
            if denoise and not res["stats"]["cancelled"]:
                from gdmlt.oidn import denoise_or_warn

                self.update_stats("GDMLT", "Denoising")
                layers = denoise_or_warn(layers, warn,
                                         threads=settings["threads"])
                denoised = "Noisy Image" in layers
            from gdmlt.outputs import with_alpha

            layers = select(layers, [row[0] for row in data])
            for name, img in layers.items():
                if name in channels_of:
                    # Combined carries the transparent film's alpha in its A channel
                    write(name, with_alpha(layers) if name == "Combined" else img)
        finally:
            self.end_result(result)
        st = res["stats"]
        global last_stats
        if not self.is_preview:
            last_stats = dict(st, export_time=export_time, previews=previews, denoised=denoised, auto=chosen)
        for w_ in st["warnings"]:
            warn(w_)
        if st["invalid_samples"]:
            warn(f"{st['invalid_samples']} samples were NaN/Inf and were dropped")
        extra = f" | acceptance {st['acceptance'] * 100:.0f}%" if st.get("chains") else ""
        extra += f" | α {st['alpha_rec']:.2g}" if st.get("alpha_rec") else ""
        from gdmlt.progress import samples_per_pixel

        self.update_stats("GDMLT", f"{label} | {samples_per_pixel(st)} per pixel | render {st['elapsed']:.2f} s, "
                          f"export {export_time:.2f} s{extra}" + (" | denoised" if denoised else "") + (" | cancelled" if st["cancelled"] else ""))

    # ---- viewport (Rendered shading) ----

    def view_update(self, context, depsgraph):
        """Blender calls this on the viewport's first draw and after every depsgraph change:
        re-export and let the session rebuild what differs (viewport.scene_change)."""
        if self.viewport is None:
            self.viewport = viewport.ViewportSession()
        try:
            desc, _ = export.export_scene(depsgraph, need_camera=False)
            self.viewport.update(desc)
            self._viewport_error = None
        except Exception as e:  # noqa: BLE001 - shown in the status bar; the viewport stays up
            self._report_viewport_error(e)

    def _report_viewport_error(self, e):
        if str(e) != self._viewport_error:
            self._viewport_error = str(e)
            self.report({"ERROR"}, f"GDMLT viewport: {e}")

    def view_draw(self, context, depsgraph):
        """Renders the next pass (viewport.ViewportSession.step) and draws the image so far
        through Blender's display transform; asks for another draw until the Viewport
        samples are reached."""
        import gpu
        from gpu_extras.presets import draw_texture_2d

        session, region, scene = self.viewport, context.region, depsgraph.scene
        if session is None or session.desc is None:
            return
        s = scene.gdmlt
        pixel_size = max(1, int(self.get_preview_pixel_size(scene)))  # Blender's Pixel Size ("Automatic": DPI)
        try:
            session.look_through(viewport.view_camera(context.region_data, region.width, region.height,
                                                      scene, pixel_size))
            if not session.finished(s.preview_samples):
                from gdmlt.blend import settings_of

                session.step(viewport.pass_settings(settings_of(s), render_threads(scene)), seed=s.seed)
        except Exception as e:  # noqa: BLE001
            self._report_viewport_error(e)
            return
        img = session.last
        if img is None:
            return
        h, w = img.shape[:2]
        pixels = gpu.types.Buffer("FLOAT", w * h * 4, _to_blender_rows(img, 4).ravel())
        texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=pixels)
        gpu.state.blend_set("ALPHA_PREMULT")
        self.bind_display_space_shader(scene)
        draw_texture_2d(texture, (0, 0), region.width, region.height)
        self.unbind_display_space_shader()
        gpu.state.blend_set("NONE")
        if not session.finished(s.preview_samples):
            self.tag_redraw()
        self.update_stats("GDMLT", f"Viewport | {session.samples} samples")

