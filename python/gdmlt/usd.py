"""USD stage → the scene dict that gdmlt.Scene takes, with usd-core (no Blender needed).

Supported: UsdGeomMesh (points, faces triangulated as fans, left-handed orientation,
normals of any interpolation, the `st` texture coordinates, GeomSubset material bindings),
UsdPreviewSurface materials (diffuseColor, metallic, roughness, ior — also of the
dielectric specular layer over the diffuse base —, emissiveColor as constants), UsdLux SphereLight (with ShapingAPI cone → spot), RectLight, DiskLight,
DistantLight and DomeLight (constant colour, or an OpenEXR latlong texture oriented as
Blender's exporter writes it: the dome's transform applied to Blender's Z-up
equirectangular mapping) with intensity × 2^exposure × colour and
`normalize` as UsdLux defines them, UsdGeomCamera (apertures and focal length in tenths of
a scene unit, clipping, f-stop, focus distance, aperture offsets), time samples (`frame`),
instance proxies and PointInstancers of meshes (flattened: copies per instance). Everything else is reported in the returned warnings:
textures in USD materials (their fallback or the constant value is used), colour
temperature other than 6500 K, non-EXR DomeLight textures, non-mesh prototypes, other prim types.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")


def _pxr():
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade  # noqa: F401
    except ImportError as e:  # pragma: no cover - usd-core is a dependency of the tools
        raise RuntimeError("reading USD needs usd-core (pip install usd-core)") from e
    import pxr

    return pxr


def _mat(gf_matrix) -> np.ndarray:
    """Gf.Matrix4d (row vectors, translation in the last row) → column-vector 4×4."""
    return np.array(gf_matrix, dtype=np.float64).T


def _light_scale(light, time) -> float:
    exposure = light.GetExposureAttr().Get(time) or 0.0
    return float(light.GetIntensityAttr().Get(time) or 0.0) * 2.0 ** float(exposure)


def _light_color(light, time, warnings, name):
    color = np.array(light.GetColorAttr().Get(time) or (1.0, 1.0, 1.0), dtype=np.float64)
    if light.GetEnableColorTemperatureAttr().Get(time):
        temp = light.GetColorTemperatureAttr().Get(time) or 6500.0
        if abs(temp - 6500.0) > 1.0:
            warnings.append(f"light '{name}': colour temperature {temp:g} K is ignored (6500 K = white is assumed)")
    return color


class _Reader:
    def __init__(self, stage, time, warnings):
        pxr = _pxr()
        self.pxr = pxr
        self.stage = stage
        self.time = time
        self.warnings = warnings
        self.mpu = pxr.UsdGeom.GetStageMetersPerUnit(stage) or 0.01
        self.xcache = pxr.UsdGeom.XformCache(time)
        self.materials = [{"name": "(default)", "base_color": (0.8, 0.8, 0.8)}]
        self.material_index = {}

    def warn(self, msg):
        if msg not in self.warnings:
            self.warnings.append(msg)

    # ---- materials -------------------------------------------------------------------
    def material(self, usd_material) -> int:
        if not usd_material:
            return 0
        path = str(usd_material.GetPath())
        if path in self.material_index:
            return self.material_index[path]
        UsdShade = self.pxr.UsdShade
        out = {"name": usd_material.GetPrim().GetName(), "base_color": (0.8, 0.8, 0.8), "roughness": 0.5,
               "metallic": 0.0, "ior": 1.5, "emission": (0.0, 0.0, 0.0)}
        shader = usd_material.ComputeSurfaceSource()[0]
        if not shader or shader.GetIdAttr().Get() != "UsdPreviewSurface":
            self.warn(f"material '{out['name']}': no UsdPreviewSurface surface; rendered grey diffuse")
        else:
            def value(name, default):
                inp = shader.GetInput(name)
                if not inp:
                    return default
                if inp.HasConnectedSource():
                    src = inp.GetConnectedSource()[0]
                    fb = UsdShade.Shader(src.GetPrim()).GetInput("fallback") if src else None
                    fallback = fb.Get() if fb else None
                    self.warn(f"material '{out['name']}': input '{name}' is connected (texture); "
                              f"{'its fallback' if fallback is not None else 'the default'} is used")
                    v = fallback if fallback is not None else default
                    return tuple(v)[:3] if isinstance(default, tuple) else float(v if not hasattr(v, '__len__') else v[0])
                v = inp.Get(self.time)
                if v is None:
                    return default
                return tuple(float(x) for x in v)[:3] if isinstance(default, tuple) else float(v)

            out["base_color"] = value("diffuseColor", (0.18, 0.18, 0.18))
            out["metallic"] = value("metallic", 0.0)
            out["roughness"] = value("roughness", 0.5)
            out["ior"] = value("ior", 1.5)
            # UsdPreviewSurface's specular lobe: a dielectric layer of that IOR over the
            # diffuse base (as Principled's, which Blender writes as this shader)
            out["specular_ior"] = out["ior"]
            out["emission"] = value("emissiveColor", (0.0, 0.0, 0.0))
            # opacity as coverage (what Blender writes for Principled alpha); with an
            # opacityThreshold, a cutout: below it fully transparent, else opaque
            opacity = min(max(value("opacity", 1.0), 0.0), 1.0)
            threshold = value("opacityThreshold", 0.0)
            if threshold > 0.0:
                opacity = 0.0 if opacity < threshold else 1.0
            if opacity < 1.0:
                out["transparency"] = 1.0 - opacity
            if value("useSpecularWorkflow", 0.0):
                self.warn(f"material '{out['name']}': the specular workflow is rendered as the metallic one")
        self.material_index[path] = len(self.materials)
        self.materials.append(out)
        return self.material_index[path]

    # ---- meshes ----------------------------------------------------------------------
    def mesh(self, prim, to_world=None):
        """The mesh in world space (`to_world`: a column-vector 4×4 instead of the prim's own
        transform, for point-instanced copies)."""
        UsdGeom, UsdShade = self.pxr.UsdGeom, self.pxr.UsdShade
        mesh = UsdGeom.Mesh(prim)
        t = self.time
        pts = mesh.GetPointsAttr().Get(t)
        counts = mesh.GetFaceVertexCountsAttr().Get(t)
        idx = mesh.GetFaceVertexIndicesAttr().Get(t)
        name = str(prim.GetPath())
        if pts is None or counts is None or idx is None or len(pts) == 0 or len(counts) == 0:
            self.warn(f"mesh '{name}': no points or faces; skipped")
            return None
        pts = np.array(pts, dtype=np.float64)
        counts = np.array(counts, dtype=np.int64)
        idx = np.array(idx, dtype=np.int64)
        if counts.sum() != len(idx):
            raise ValueError(f"mesh '{name}': faceVertexCounts add up to {counts.sum()} but there are "
                             f"{len(idx)} faceVertexIndices")
        if mesh.GetSubdivisionSchemeAttr().Get() not in (None, "none"):
            self.warn(f"mesh '{name}': subdivision is not applied (the control mesh is rendered)")
        # fan triangulation: face f with n corners → (c0, c_k, c_k+1), k = 1..n−2 (corner indices)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        keep = counts >= 3
        ntri_face = np.where(keep, counts - 2, 0)
        face_of_tri = np.repeat(np.arange(len(counts)), ntri_face)
        k = np.arange(len(face_of_tri)) - np.repeat(np.cumsum(ntri_face) - ntri_face, ntri_face)
        c0 = starts[face_of_tri]
        corners = np.stack([c0, c0 + k + 1, c0 + k + 2], axis=1)
        if mesh.GetOrientationAttr().Get() == "leftHanded":
            corners = corners[:, [0, 2, 1]]
        tris = idx[corners]
        if len(tris) == 0:
            self.warn(f"mesh '{name}': no face with three or more corners; skipped")
            return None
        m = _mat(self.xcache.GetLocalToWorldTransform(prim)) if to_world is None else to_world
        pos = pts @ m[:3, :3].T + m[:3, 3]
        det = np.linalg.det(m[:3, :3])
        nmat = np.linalg.inv(m[:3, :3]).T if abs(det) > 1e-30 else m[:3, :3]

        def corner_values(values, interp):
            values = np.asarray(values, dtype=np.float64)
            if interp in ("vertex", "varying"):
                return values[tris]
            if interp == "faceVarying":
                return values[corners]
            if interp == "uniform":
                return np.repeat(values[face_of_tri][:, None, :], 3, axis=1)
            return np.broadcast_to(values[0], (len(tris), 3, values.shape[-1]))

        out = {"name": name, "positions": np.ascontiguousarray(pos, dtype=np.float32),
               "indices": np.ascontiguousarray(tris, dtype=np.uint32)}
        pv_api = UsdGeom.PrimvarsAPI(prim)
        nrm_pv = pv_api.GetPrimvar("normals")
        if nrm_pv and nrm_pv.HasValue():
            normals, interp = nrm_pv.ComputeFlattened(t), nrm_pv.GetInterpolation()
        else:
            normals, interp = mesh.GetNormalsAttr().Get(t), mesh.GetNormalsInterpolation()
        if normals is not None and len(normals):
            cn = corner_values(normals, interp).reshape(-1, 3) @ nmat.T
            out["normals"] = np.ascontiguousarray(cn, dtype=np.float32)
        st = pv_api.GetPrimvar("st")
        if st and st.HasValue():
            uv = corner_values(st.ComputeFlattened(t), st.GetInterpolation()).reshape(-1, 2)
            out["uvs"] = np.ascontiguousarray(uv, dtype=np.float32)
        # materials: the prim's binding, overridden per face by GeomSubsets
        binding = UsdShade.MaterialBindingAPI(prim)
        face_mat = np.full(len(counts), self.material(binding.ComputeBoundMaterial()[0]), dtype=np.uint32)
        for subset in binding.GetMaterialBindSubsets():
            faces = np.array(subset.GetIndicesAttr().Get(t) or [], dtype=np.int64)
            mat = UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial()[0]
            face_mat[faces[(faces >= 0) & (faces < len(counts))]] = self.material(mat)
        out["material_ids"] = np.ascontiguousarray(face_mat[face_of_tri])
        return out

    def point_instancer(self, prim):
        """Meshes of every instance of a UsdGeomPointInstancer (flattened: each instance's
        triangles are copied, memory grows with the instance count)."""
        UsdGeom, Usd = self.pxr.UsdGeom, self.pxr.Usd
        inst = UsdGeom.PointInstancer(prim)
        xforms = inst.ComputeInstanceTransformsAtTime(self.time, self.time)
        indices = inst.GetProtoIndicesAttr().Get(self.time) or []
        targets = inst.GetPrototypesRel().GetTargets()
        world = self.xcache.GetLocalToWorldTransform(prim)
        protos = []
        for path in targets:
            root = self.stage.GetPrimAtPath(path)
            inv = self.xcache.GetLocalToWorldTransform(root).GetInverse()
            parts = [(p, self.xcache.GetLocalToWorldTransform(p) * inv)
                     for p in Usd.PrimRange(root, Usd.TraverseInstanceProxies()) if p.IsA(UsdGeom.Mesh)]
            if not parts and root.IsA(UsdGeom.Gprim):
                self.warn(f"'{path}': {root.GetTypeName()} prototypes are not supported (only Mesh); skipped")
            protos.append(parts)
        out = []
        for i, (k, x) in enumerate(zip(indices, xforms)):
            if not 0 <= k < len(protos):
                self.warn(f"'{prim.GetPath()}': instance {i} uses prototype {k} of {len(protos)}; skipped")
                continue
            for part, rel in protos[k]:
                m = self.mesh(part, to_world=_mat(rel * x * world))
                if m is not None:
                    m["name"] = f"{prim.GetPath()}[{i}]{part.GetPath()}"
                    out.append(m)
        return out

    # ---- lights ----------------------------------------------------------------------
    def light(self, prim):
        UsdLux = self.pxr.UsdLux
        t = self.time
        name = prim.GetName()
        m = _mat(self.xcache.GetLocalToWorldTransform(prim))
        visible = False
        if prim.IsA(UsdLux.SphereLight):
            light = UsdLux.SphereLight(prim)
            r = float(light.GetRadiusAttr().Get(t) or 0.0) * float(np.linalg.norm(m[:3, 0]))
            if light.GetTreatAsPointAttr().Get(t):
                r = 0.0
            scale = _light_scale(light, t)
            color = _light_color(light, t, self.warnings, name)
            # radiance L = intensity·2^exposure·colour (÷ area 4πr² when normalized); a
            # Blender point light of power P has L = P/(4π²r²), i.e. P = π·L·4πr²
            normalize = light.GetNormalizeAttr().Get(t)
            power = color * scale * math.pi * (1.0 if normalize or r == 0 else 4 * math.pi * r * r)
            pos = tuple(m[:3, 3].tolist())
            shaping = UsdLux.ShapingAPI(prim)
            angle = shaping.GetShapingConeAngleAttr().Get(t) if shaping else None
            if angle is not None and angle < 180:
                minus_z = -m[:3, 2] / np.linalg.norm(m[:3, 2])
                return {"type": "SPOT", "name": name, "position": pos, "direction": tuple(minus_z.tolist()),
                        "radius": r, "spot_size": 2 * math.radians(angle),
                        "spot_blend": float(shaping.GetShapingConeSoftnessAttr().Get(t) or 0.0),
                        "soft_falloff": True, "power": tuple(power.tolist()), "visible_camera": visible}
            return {"type": "POINT", "name": name, "position": pos, "radius": r, "soft_falloff": True,
                    "power": tuple(power.tolist()), "visible_camera": visible}
        if prim.IsA(UsdLux.RectLight) or prim.IsA(UsdLux.DiskLight):
            rect = prim.IsA(UsdLux.RectLight)
            light = UsdLux.RectLight(prim) if rect else UsdLux.DiskLight(prim)
            if rect:
                w, h = float(light.GetWidthAttr().Get(t) or 1.0), float(light.GetHeightAttr().Get(t) or 1.0)
                if light.GetTextureFileAttr().Get(t):
                    self.warn(f"light '{name}': RectLight texture is ignored")
                area = w * h
            else:
                w = h = 2.0 * float(light.GetRadiusAttr().Get(t) or 0.5)
                area = math.pi * w * h / 4
            area *= float(np.linalg.norm(m[:3, 0]) * np.linalg.norm(m[:3, 1]))
            scale = _light_scale(light, t)
            color = _light_color(light, t, self.warnings, name)
            # L = intensity·2^exposure·colour (÷ area when normalized); Blender's power P = π·L·A
            normalize = light.GetNormalizeAttr().Get(t)
            power = color * scale * math.pi * (1.0 if normalize else area)
            return {"type": "AREA", "name": name, "matrix": m.astype(np.float32),
                    "shape": "RECTANGLE" if rect else "DISK", "size": w, "size_y": h,
                    "power": tuple(power.tolist()), "normalize": True, "visible_camera": visible}
        if prim.IsA(UsdLux.DistantLight):
            light = UsdLux.DistantLight(prim)
            color = _light_color(light, t, self.warnings, name)
            plus_z = m[:3, 2] / np.linalg.norm(m[:3, 2])
            return {"type": "SUN", "name": name, "direction": tuple(plus_z.tolist()),
                    "irradiance": tuple((color * _light_scale(light, t)).tolist()),
                    "angle": math.radians(float(light.GetAngleAttr().Get(t) or 0.0)), "visible_camera": visible}
        self.warn(f"light '{name}': {prim.GetTypeName()} is not supported; skipped")
        return None

    def dome(self, prim, textures):
        """(colour × intensity, texture index or None, world → texture rotation or None)."""
        UsdLux = self.pxr.UsdLux
        light = UsdLux.DomeLight(prim)
        name = prim.GetName()
        color = _light_color(light, self.time, self.warnings, name)
        scale = tuple((color * _light_scale(light, self.time)).tolist())
        asset = light.GetTextureFileAttr().Get(self.time)
        if not asset or not asset.path:
            return scale, None, None
        file = Path(asset.resolvedPath) if asset.resolvedPath else \
            Path(self.stage.GetRootLayer().realPath).parent / asset.path
        pixels = _read_exr(file) if file.suffix.lower() == ".exr" and file.is_file() else None
        if pixels is None:
            self.warn(f"light '{name}': dome texture '{asset.path}' could not be read (only OpenEXR files are); "
                      f"its colour × intensity is used")
            return scale, None, None
        h, w, _ = pixels.shape
        textures.append({"name": file.name, "width": w, "height": h, "channels": 3,
                         "pixels": np.ascontiguousarray(pixels[::-1].reshape(-1, 3)),  # row 0 at the bottom
                         "interpolation": "Linear", "extension": "REPEAT"})
        m = _mat(self.xcache.GetLocalToWorldTransform(prim))[:3, :3]
        m = m / np.linalg.norm(m, axis=0)
        return scale, len(textures) - 1, np.ascontiguousarray(m.T, dtype=np.float32)

    # ---- camera ----------------------------------------------------------------------
    def camera(self, prim, width, height):
        UsdGeom = self.pxr.UsdGeom
        cam = UsdGeom.Camera(prim).GetCamera(self.time)
        m = _mat(self.xcache.GetLocalToWorldTransform(prim))
        for axis in range(3):  # the camera's scale is not part of its projection
            n = np.linalg.norm(m[:3, axis])
            if n > 0:
                m[:3, axis] /= n
        # apertures and focal length are in tenths of a scene unit: in mm, × 100·metersPerUnit
        mm = 100.0 * self.mpu
        h_ap, v_ap = cam.horizontalAperture, cam.verticalAperture
        if width is None and height is None:
            width = 640
        if height is None:
            height = max(1, round(width * v_ap / h_ap)) if h_ap > 0 else width
        if width is None:
            width = max(1, round(height * h_ap / v_ap)) if v_ap > 0 else height
        ortho = cam.projection == cam.Orthographic
        clip = cam.clippingRange
        d = {"matrix": m.astype(np.float32), "type": "ORTHO" if ortho else "PERSP",
             "lens": cam.focalLength * mm, "sensor_width": h_ap * mm, "sensor_height": v_ap * mm,
             "sensor_fit": "HORIZONTAL", "ortho_scale": h_ap * 0.1,
             "shift_x": cam.horizontalApertureOffset / h_ap if h_ap else 0.0,
             "shift_y": cam.verticalApertureOffset / h_ap if h_ap else 0.0,
             "clip_start": clip.min, "clip_end": clip.max, "resolution_x": int(width), "resolution_y": int(height)}
        if cam.fStop > 0:
            d["fstop"] = cam.fStop
            d["focus_distance"] = cam.focusDistance
        return d


def _read_exr(path):
    """An OpenEXR image as float32 H×W×3 (row 0 at the top), or None."""
    try:
        import OpenEXR
    except ImportError:
        return None
    try:
        with OpenEXR.File(str(path)) as f:
            ch = f.channels()
            for key in ("RGB", "RGBA"):
                if key in ch:
                    px = np.asarray(ch[key].pixels, dtype=np.float32)
                    return np.ascontiguousarray(px[..., :3])
            if all(c in ch for c in "RGB"):
                return np.stack([np.asarray(ch[c].pixels, dtype=np.float32) for c in "RGB"], axis=-1)
    except Exception:  # a broken file is reported by the caller as unreadable
        return None
    return None


def stored_settings(path) -> dict:
    """The GDMLT render settings that `gdmlt export` stored in the stage (customLayerData
    "gdmlt"), or {}."""
    pxr = _pxr()
    layer = pxr.Sdf.Layer.FindOrOpen(str(path))
    if layer is None:
        return {}
    data = layer.customLayerData.get("gdmlt", {})
    return {str(k): (v if not isinstance(v, str) else str(v)) for k, v in dict(data).items()}


def load(path, frame=None, width=None, height=None, camera=None):
    """Reads a USD stage into a scene dict. Returns (dict, warnings). Raises
    FileNotFoundError for a missing file and ValueError for a stage that cannot be rendered
    (no camera, broken meshes). `camera`: path of the camera prim (default: the first)."""
    pxr = _pxr()
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    stage = pxr.Usd.Stage.Open(str(path))
    if stage is None:
        raise ValueError(f"'{path}' could not be opened as a USD stage")
    time = pxr.Usd.TimeCode(frame) if frame is not None else pxr.Usd.TimeCode.Default()
    warnings = []
    stored = stored_settings(path)
    if width is None and height is None and "width" in stored:
        width, height = int(stored["width"]), int(stored["height"])
    r = _Reader(stage, time, warnings)
    meshes, lights, world, cams, textures = [], [], (0.0, 0.0, 0.0), [], []
    world_texture = world_rotation = None
    UsdGeom, UsdLux = pxr.UsdGeom, pxr.UsdLux
    it = iter(pxr.Usd.PrimRange.Stage(stage, pxr.Usd.TraverseInstanceProxies()))
    for prim in it:
        if not prim.IsActive():
            it.PruneChildren()
            continue
        img = UsdGeom.Imageable(prim)
        if img and img.ComputeVisibility(time) == UsdGeom.Tokens.invisible:
            it.PruneChildren()
            continue
        if prim.IsA(UsdGeom.Mesh):
            purpose = img.ComputePurpose() if img else UsdGeom.Tokens.default_
            if purpose in (UsdGeom.Tokens.proxy, UsdGeom.Tokens.guide):
                continue
            m = r.mesh(prim)
            if m is not None:
                meshes.append(m)
        elif prim.IsA(UsdGeom.Camera):
            cams.append(prim)
        elif prim.IsA(UsdLux.DomeLight):
            if world != (0.0, 0.0, 0.0) or world_texture is not None:
                r.warn(f"light '{prim.GetName()}': only one DomeLight is rendered")
                continue
            world, world_texture, world_rotation = r.dome(prim, textures)
        elif prim.HasAPI(UsdLux.LightAPI) or prim.IsA(UsdLux.BoundableLightBase) or \
                prim.IsA(UsdLux.NonboundableLightBase):
            light = r.light(prim)
            if light is not None:
                lights.append(light)
        elif prim.IsA(UsdGeom.PointInstancer):
            meshes.extend(r.point_instancer(prim))
            it.PruneChildren()  # the prototypes render only through their instances
        elif prim.IsA(UsdGeom.Gprim):
            r.warn(f"'{prim.GetPath()}': {prim.GetTypeName()} prims are not supported (only Mesh); skipped")
    if camera is not None:
        cams = [c for c in cams if str(c.GetPath()) == camera]
        if not cams:
            raise ValueError(f"no camera prim at '{camera}'")
    if not cams:
        raise ValueError(f"'{path}' has no camera")
    desc = {"meshes": meshes, "materials": r.materials, "lights": lights, "world": world,
            "textures": textures, "world_texture": world_texture, "world_rotation": world_rotation,
            "camera": r.camera(cams[0], width, height)}
    return desc, warnings
