"""Viewport rendering (the 3D View's Rendered shading): a progressive path-traced preview.

The engine's `view_update` hands every re-exported scene to a `ViewportSession`, which
compares it with the one it renders and rebuilds only what differs (`scene_change`):

- the triangles (a mesh moved, was edited, added or deleted; a material reassigned):
  the core scene and its BVH are built again;
- materials, textures, lights or the world: the core swaps them in
  (`gdmlt.Scene.update_shading`), keeping the triangles and the BVH;
- nothing the image depends on (a selection, a frame of a static scene): the passes go on.

The view itself (`view_camera`: the region's view and projection matrices, so free
navigation, camera view with its zoom and offset, and orthographic views all work) changes
only the core camera (`gdmlt.Scene.set_camera`). After any change the image restarts: a
coarse pass first (at most 64, then 256 pixels across, shown at once), then full-resolution
passes of one path-traced sample per pixel, averaged, up to the Viewport samples limit.

The viewport always path-traces (`pt`, the method whose passes average progressively) with
the scene's light path settings; F12 renders with the chosen method. No depth of field
outside the camera view. No denoising in the viewport.
"""

import math

import numpy as np

# the coarse passes shown right after a change: at most this many pixels across
COARSE_SIZES = (64, 256)
# settings of gdmlt.render a viewport pass takes from the scene (the rest are F12's)
PASS_SETTINGS = ("max_bounces", "nee", "diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces",
                 "transparent_bounces", "clamp_direct", "clamp_indirect")


def same(a, b) -> bool:
    """Exact equality of two scene-dict values (dicts, lists, numpy arrays, numbers)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def _normal_mapped(desc):
    return [m.get("normal_texture") is not None for m in desc.get("materials", [])]


def _moved_instances(old, new) -> bool:
    """The two mesh lists differ only in the transforms of instanced meshes, each still
    placed as many times (a moved instancer)."""
    if len(old) != len(new):
        return False
    for a, b in zip(old, new):
        if a.keys() != b.keys() or any(not same(a[k], b[k]) for k in a if k != "transforms"):
            return False
        if "transforms" in a and np.shape(a["transforms"]) != np.shape(b["transforms"]):
            return False
    return True


# what each change rebuilds, least first (a pending change keeps the larger)
CHANGES = ("none", "shading", "instances", "geometry")


def scene_change(old, new) -> str:
    """What differs between two exported scene dicts, for the viewport: "geometry" (the
    meshes, material ids included: rebuild everything — so too when a material gains or
    loses a normal map, whose meshes' tangents are computed with the triangles),
    "instances" (only instanced meshes' transforms: place them again, the meshes' BVHs
    kept; the shading is taken too), "shading" (materials, textures, lights, world: swap
    them in), or "none". The camera is not compared (the viewport looks through its own)."""
    if old is None:
        return "geometry"
    if not same(old.get("meshes", []), new.get("meshes", [])):
        if _normal_mapped(old) != _normal_mapped(new) or not _moved_instances(old.get("meshes", []),
                                                                             new.get("meshes", [])):
            return "geometry"
        return "instances"
    if _normal_mapped(old) != _normal_mapped(new):
        return "geometry"
    rest = {k for k in old.keys() | new.keys() if k not in ("meshes", "camera")}
    return "none" if all(same(old.get(k), new.get(k)) for k in rest) else "shading"


def view_camera(region_data, width: int, height: int, scene, pixel_size: int = 1) -> dict:
    """The core camera dict that sees what the 3D View shows: from the region's view matrix
    (world → view) and projection (window) matrix, for a width × height region rendered at
    1/pixel_size resolution. Film settings (pixel filter, transparent film) are the scene's;
    depth of field only in camera view, as the scene camera's."""
    p = np.array(region_data.window_matrix, dtype=np.float64)
    to_world = np.linalg.inv(np.array(region_data.view_matrix, dtype=np.float64))
    d = {"resolution_x": max(1, width // pixel_size), "resolution_y": max(1, height // pixel_size),
         "resolution_percentage": 100, "sensor_fit": "HORIZONTAL", "sensor_width": 36.0}
    if abs(p[3, 3]) < 0.5:  # perspective: x' = (2n/(r−l)) x + ((r+l)/(r−l)) z
        d.update(type="PERSP", lens=18.0 * p[0, 0], shift_x=0.5 * p[0, 2], shift_y=0.5 * p[1, 2] * p[0, 0] / p[1, 1])
        near, far = p[2, 3] / (p[2, 2] - 1.0), p[2, 3] / (p[2, 2] + 1.0)
    else:  # orthographic: x' = (2/(r−l)) x − (r+l)/(r−l)
        d.update(type="ORTHO", ortho_scale=2.0 / p[0, 0], shift_x=-0.5 * p[0, 3],
                 shift_y=-0.5 * p[1, 3] * p[0, 0] / p[1, 1])
        near, far = (p[2, 3] + 1.0) / p[2, 2], (p[2, 3] - 1.0) / p[2, 2]
        if near < 0.0:  # Blender's orthographic views see behind their origin: start the rays there
            to_world[:3, 3] += near * -to_world[:3, 2] / np.linalg.norm(to_world[:3, 2])
            near, far = 0.0, far - near
    d.update(matrix=to_world.astype(np.float32), clip_start=max(0.0, near), clip_end=far)
    g = scene.gdmlt
    d.update(pixel_filter=g.pixel_filter_type, filter_width=g.filter_width * 1.0)
    if scene.render.film_transparent:
        d["film_transparent"] = True
    cam = scene.camera
    if (getattr(region_data, "view_perspective", "") == "CAMERA" and d["type"] == "PERSP" and cam is not None
            and cam.type == "CAMERA" and cam.data.dof.use_dof):
        dof = cam.data.dof
        # the aperture is the camera's lens over its f-stop; the view's lens differs by the zoom
        d["fstop"] = dof.aperture_fstop * d["lens"] / cam.data.lens
        focus = dof.focus_distance
        if dof.focus_object is not None:
            axis = -to_world[:3, 2] / np.linalg.norm(to_world[:3, 2])
            focus = float(np.dot(np.array(dof.focus_object.matrix_world.translation) - to_world[:3, 3], axis))
        d["focus_distance"] = focus
    return d


def coarse(camera: dict, size: int) -> dict:
    """The camera rendered at most `size` pixels across (same view)."""
    w, h = camera["resolution_x"], camera["resolution_y"]
    div = max(1, math.ceil(max(w, h) / size))
    return dict(camera, resolution_x=max(1, w // div), resolution_y=max(1, h // div))


class ViewportSession:
    """The viewport's render state: the core scene, the camera, the passes averaged so far."""

    def __init__(self):
        self.desc = None  # the last exported scene dict
        self.core = None  # gdmlt.Scene
        self.camera = None  # the view's camera dict
        self._core_camera = None  # the camera the core scene has now (coarse or full)
        self.total = None  # sum of the full-resolution passes, RGBA
        self.samples = 0
        self._coarse = []  # coarse sizes still to show after the last change
        self._pending = "none"  # what the core scene has not taken from `desc` yet
        self.last = None  # the image shown last (RGBA, top row first)

    def update(self, desc) -> str:
        """Takes a freshly exported scene dict; returns what differs from the one being
        rendered (scene_change). The core scene is rebuilt or updated at the next pass (when
        the view's camera is known)."""
        change = scene_change(self.desc, desc)
        if change != "none":
            self.desc = desc
            self._pending = max(self._pending, change, key=CHANGES.index)
            self.restart()
        return change

    def _apply(self, camera: dict):
        """Brings the core scene up to date with the last update and looks through `camera`."""
        import gdmlt

        if self._pending == "geometry" or self.core is None:
            self.core = gdmlt.Scene(dict(self.desc, camera=camera))
        else:
            if self._pending == "instances":
                try:
                    self.core.update_transforms(dict(self.desc, camera=camera))
                except ValueError:
                    # (a mesh the core placed as copies moved, or other meshes are instanced)
                    self.core = gdmlt.Scene(dict(self.desc, camera=camera))
            if self._pending == "shading":
                try:
                    self.core.update_shading(dict(self.desc, meshes=[], camera=camera))
                except ValueError:
                    # an edit the triangles cannot take as they are (an instanced mesh's
                    # material emits now: the core places it as copies): build again
                    self.core = gdmlt.Scene(dict(self.desc, camera=camera))
            if self._core_camera is not camera:
                self.core.set_camera(camera)
        self._pending, self._core_camera = "none", camera

    def look_through(self, camera: dict) -> bool:
        """Sets the view's camera; True (and the image restarts) when it moved."""
        if self.camera is not None and same(self.camera, camera):
            return False
        self.camera = camera
        self.restart()
        return True

    def restart(self):
        self.total, self.samples = None, 0
        self._coarse = [s for s in COARSE_SIZES if self.camera is None
                        or max(self.camera["resolution_x"], self.camera["resolution_y"]) > s]

    def finished(self, limit: int) -> bool:
        """Whether the passes have reached the sample limit (0: never)."""
        return limit > 0 and self.samples >= limit

    def step(self, settings: dict, seed: int = 0) -> np.ndarray:
        """Renders the next pass and returns the image to show (RGBA, top row first): a
        coarse one right after a change, else the average of the full passes so far."""
        import gdmlt
        from gdmlt.outputs import with_alpha

        camera = coarse(self.camera, self._coarse.pop(0)) if self._coarse else self.camera
        self._apply(camera)
        res = gdmlt.render(self.core, method="pt", spp=1, seed=seed + self.samples, **settings)
        img = with_alpha(res["layers"]).astype(np.float32)
        if img.shape[2] == 3:  # opaque film
            img = np.concatenate([img, np.ones_like(img[..., :1])], axis=2)
        if camera is self.camera:
            self.total = img if self.total is None else self.total + img
            self.samples += 1
            img = self.total / self.samples
        self.last = img
        return img


def pass_settings(render_settings: dict, threads: int) -> dict:
    """gdmlt.render's settings for a viewport pass, from the scene's (gdmlt.blend.settings_of)."""
    return dict({k: render_settings[k] for k in PASS_SETTINGS}, threads=threads)
