"""The GDMLT RenderEngine: export the evaluated depsgraph, render in the Rust core with
progress and Esc, write the image into the render result."""

import time

import bpy
import numpy as np

from . import export

# Statistics of the last finished render in this process (the CLI prints them).
last_stats = {}


class GDMLTRenderEngine(bpy.types.RenderEngine):
    bl_idname = "GDMLT"
    bl_label = "GDMLT"
    bl_use_preview = False
    bl_use_postprocess = True

    def render(self, depsgraph):
        try:
            self._render(depsgraph)
        except export.ExportCancelled:
            return
        except Exception as e:  # noqa: BLE001 - every failure must reach the user, not a blank image
            self.report({"ERROR"}, f"GDMLT: {e}")

    def _render(self, depsgraph):
        import gdmlt

        scene = depsgraph.scene
        s = scene.gdmlt
        t0 = time.perf_counter()
        self.update_stats("GDMLT", "Exporting scene")
        desc, warnings = export.export_scene(depsgraph, self.test_break)
        ntri = sum(len(m["indices"]) for m in desc["meshes"])
        self.update_stats("GDMLT", f"Building BVH ({ntri:,} triangles)")
        core_scene = gdmlt.Scene(desc)
        for w in warnings + list(core_scene.warnings):
            self.report({"WARNING"}, f"GDMLT: {w}")
        export_time = time.perf_counter() - t0
        method = s.method.lower()

        def progress(fraction, elapsed):
            self.update_progress(fraction)
            self.update_stats("GDMLT", f"{s.method} | {fraction * 100:.0f}% | {elapsed:.1f} s")
            return self.test_break()

        res = gdmlt.render(core_scene, method=method, spp=s.samples, time_limit=s.time_limit,
                           max_bounces=s.max_bounces, nee=s.use_nee, seed=s.seed, threads=s.threads,
                           progress=progress)
        st = res["stats"]
        global last_stats
        last_stats = dict(st, export_time=export_time)
        for w in st["warnings"]:
            if w not in core_scene.warnings:
                self.report({"WARNING"}, f"GDMLT: {w}")
        if st["invalid_samples"]:
            self.report({"WARNING"}, f"GDMLT: {st['invalid_samples']} samples were NaN/Inf and were dropped")
        w, h = core_scene.size
        img = res["layers"]["Combined"]
        rgba = np.empty((h, w, 4), np.float32)
        rgba[:, :, :3] = img[::-1]  # Blender's row 0 is the bottom row
        rgba[:, :, 3] = 1.0
        result = self.begin_result(0, 0, w, h)
        r = scene.render
        if r.use_border:  # the result comes back clipped to the border rectangle
            x0, x1 = round(r.border_min_x * w), round(r.border_max_x * w)
            y0, y1 = round(r.border_min_y * h), round(r.border_max_y * h)
            rgba = rgba[y0:y1, x0:x1]
        result.layers[0].passes["Combined"].rect.foreach_set(np.ascontiguousarray(rgba).ravel())
        self.end_result(result)
        self.update_stats("GDMLT", f"{s.method} | {st['spp_max']} spp | render {st['elapsed']:.2f} s, export {export_time:.2f} s"
                          + (" | cancelled" if st["cancelled"] else ""))
