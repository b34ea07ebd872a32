"""USD stage → the scene dict that gdmlt.Scene takes, with usd-core (no Blender needed).

Supported: UsdGeomMesh (points, faces triangulated as fans, left-handed orientation,
normals of any interpolation, the `st` texture coordinates, GeomSubset material bindings);
materials from their MaterialX network where the core renders it exactly (OpenPBR — what
Blender writes for Principled —, or one diffuse / conductor / dielectric BSDF and a uniform
EDF), else from UsdPreviewSurface (diffuseColor, metallic, roughness, ior — also of the
dielectric specular layer over the diffuse base —, emissiveColor, opacity); image textures
(UsdUVTexture, MaterialX image nodes) on base colour and roughness; UsdLux SphereLight (with
ShapingAPI cone → spot), RectLight, DiskLight, DistantLight and DomeLight (constant colour,
or an OpenEXR latlong texture in UsdLux's orientation — OpenEXR's latlong map, its pole
along the dome's +Y — under the dome's transform, as Blender 4.5 and 5.1 on write it; a
stage whose documentation names Blender 5.0 keeps what 5.0 wrote, Blender's Z-up
equirectangular mapping under the transform) with intensity × 2^exposure ×
colour × blackbody colour of the temperature and `normalize` as UsdLux defines them,
UsdGeomCamera (apertures and focal length in tenths of a scene unit, clipping, f-stop,
focus distance, aperture offsets), time samples (`frame`), instance proxies and
PointInstancers of meshes (as instances: each prototype mesh once, with its instances'
transforms). Everything else is reported in the returned warnings with the fallback used
(docs/features.md: "USD feature table").
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from . import scenedict
from .shading import specular_layer_ior

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


def temperature_rgb(kelvin: float) -> np.ndarray:
    """UsdLux's blackbody colour of `kelvin` (luminance 1; usd-core's
    BlackbodyTemperatureAsRgb, the same colour as Blender's Light.temperature_color)."""
    from pxr import UsdLux

    return np.array(UsdLux.BlackbodyTemperatureAsRgb(float(min(max(kelvin, 1000.0), 10000.0))))


def _light_color(light, time, warnings, name):
    color = np.array(light.GetColorAttr().Get(time) or (1.0, 1.0, 1.0), dtype=np.float64)
    # An unauthored temperature is white: Blender's exporter enables the temperature on every
    # light and writes one only when the light uses it (its lights are white otherwise).
    temp = light.GetColorTemperatureAttr()
    if light.GetEnableColorTemperatureAttr().Get(time) and temp.HasAuthoredValue():
        color = color * temperature_rgb(temp.Get(time))
    return color


class _PreviewInstead(Exception):
    """A MaterialX network the reader does not follow: use the UsdPreviewSurface."""


class _Reader:
    def __init__(self, stage, time, warnings):
        pxr = _pxr()
        self.pxr = pxr
        self.stage = stage
        self.time = time
        self.warnings = warnings
        self.mpu = pxr.UsdGeom.GetStageMetersPerUnit(stage) or 0.01
        self.xcache = pxr.UsdGeom.XformCache(time)
        self.materials = [dict(scenedict.DEFAULT_SURFACE)]  # (unbound meshes: as Blender renders them)
        self.material_index = {}
        self.colour_layers = {}  # material index → the colour primvar its diffuseColor reads
        self.textures = []  # scene textures: material images and the dome's
        self.texture_index = {}

    def warn(self, msg):
        if msg not in self.warnings:
            self.warnings.append(msg)

    # ---- materials -------------------------------------------------------------------
    def material(self, usd_material) -> int:
        """Index of a bound material in the scene's table. The MaterialX network (the
        `mtlx` render context Blender writes with generate_materialx_network) is read when
        the core can render it exactly; else the UsdPreviewSurface."""
        if not usd_material:
            return 0
        path = str(usd_material.GetPath())
        if path in self.material_index:
            return self.material_index[path]
        name = usd_material.GetPrim().GetName()
        out = scenedict.material(name)
        what = f"material '{name}'"
        mtlx = usd_material.ComputeSurfaceSource("mtlx")[0]
        done = False
        if mtlx and (mtlx.GetIdAttr().Get() or "").startswith("ND_"):
            work, kept = dict(out), (len(self.textures), dict(self.texture_index))
            try:
                done = self._materialx(mtlx, work, what)
            except _PreviewInstead as e:
                # a MaterialX graph the reader does not follow (math on texture coordinates):
                # Blender's UsdPreviewSurface beside it says the same for a Principled BSDF
                if mtlx.GetIdAttr().Get() != "ND_open_pbr_surface_surfaceshader":
                    self.warn(f"{what}: MaterialX {e} is not read; the UsdPreviewSurface is used")
            if done:
                out = work
            else:  # textures read for the abandoned attempt are dropped again
                del self.textures[kept[0]:]
                self.texture_index = kept[1]
        if not done:
            shader = usd_material.ComputeSurfaceSource()[0]
            if shader and shader.GetIdAttr().Get() == "UsdPreviewSurface":
                self._preview_surface(shader, out, what)
            else:
                self.warn(f"{what}: no UsdPreviewSurface or supported MaterialX surface; rendered grey diffuse")
        self.material_index[path] = len(self.materials)
        self.colour_layers[len(self.materials)] = out.pop("vertex_color_layer", None)
        self.materials.append(out)
        return self.material_index[path]

    def _source(self, inp):
        """(shader, output name) that produces a connected input's value, through node graphs."""
        if not inp or not inp.HasConnectedSource():
            return None
        attrs = inp.GetValueProducingAttributes(shaderOutputsOnly=True)
        if not attrs:
            return None
        return self.pxr.UsdShade.Shader(attrs[0].GetPrim()), attrs[0].GetName().split(":")[-1]

    def _param(self, shader, name, default, what, out=None, texture_key=None):
        """An input's constant (default when unauthored). Connected: an image texture becomes
        out[texture_key] where the core takes one; anything else warns and uses the texture
        node's fallback or the default."""
        inp = shader.GetInput(name)
        if not inp:
            return default
        if inp.HasConnectedSource():
            src = self._source(inp)
            if src is not None and texture_key == "base_color_texture" \
                    and src[0].GetIdAttr().Get() in ("UsdPrimvarReader_float3", "UsdPrimvarReader_float4"):
                # a colour primvar (vertex colours): the base colour is the mesh's colours
                var = src[0].GetInput("varname")
                out["vertex_color"], out["vertex_color_layer"] = True, str(var.Get() if var else "") or "displayColor"
                return (1.0, 1.0, 1.0)
            if src is not None and texture_key is not None:
                # coverage from an image's alpha: UsdUVTexture's `a` output, MaterialX's channel 3
                alpha = texture_key == "alpha_texture"
                index = self._texture(src[0], what, alpha) if not alpha or src[1] in ("a", "out") else None
                if index is not None:
                    out[texture_key] = index
                    return (1.0, 1.0, 1.0) if isinstance(default, tuple) else default
            fb = src[0].GetInput("fallback") if src is not None else None
            fallback = fb.Get() if fb else None
            self.warn(f"{what}: input '{name}' is connected to what the core does not render here; "
                      f"{'its fallback' if fallback is not None else 'the default'} is used")
            v = fallback if fallback is not None else default
        else:
            v = inp.Get(self.time)
            if v is None:
                return default
        if isinstance(default, str):
            return str(v)
        if isinstance(default, tuple):
            return tuple(float(x) for x in tuple(v)[:3]) if hasattr(v, "__len__") else (float(v),) * 3
        return float(v[0] if hasattr(v, "__len__") else v)

    def _preview_surface(self, shader, out, what):
        p = lambda name, default, key=None: self._param(shader, name, default, what, out, key)  # noqa: E731
        out["base_color"] = p("diffuseColor", (0.18, 0.18, 0.18), "base_color_texture")
        out["metallic"] = p("metallic", 0.0, "metallic_texture")
        out["multiscatter"] = True  # as Blender's default (Multiscatter GGX), which writes this shader
        out["roughness"] = p("roughness", 0.5, "roughness_texture")
        out["ior"] = p("ior", 1.5)
        # the specular lobe: a dielectric layer of that IOR over the diffuse base (Principled's,
        # which Blender writes as this shader, with its Specular IOR Level as `specular`)
        out["specular_ior"] = specular_layer_ior(out["ior"], p("specular", 0.5))
        out["emission"] = p("emissiveColor", (0.0, 0.0, 0.0))
        # opacity as coverage (what Blender writes for Principled alpha); with an
        # opacityThreshold, a cutout: below it fully transparent, else opaque
        opacity = min(max(p("opacity", 1.0, "alpha_texture"), 0.0), 1.0)
        threshold = p("opacityThreshold", 0.0)
        if threshold > 0.0 and "alpha_texture" in out:
            self.warn(f"{what}: opacityThreshold with an opacity texture is rendered as coverage (no cutout)")
            threshold = 0.0
        if threshold > 0.0:
            opacity = 0.0 if opacity < threshold else 1.0
        if opacity < 1.0:
            out["transparency"] = 1.0 - opacity
        if p("useSpecularWorkflow", 0.0):
            self.warn(f"{what}: the specular workflow is rendered as the metallic one")
        clearcoat = min(max(float(p("clearcoat", 0.0)), 0.0), 1.0)
        if clearcoat > 0.0:  # (the schema's coat: IOR 1.5, untinted; Blender reads it as Coat Weight)
            out["coat"], out["coat_roughness"] = clearcoat, min(max(float(p("clearcoatRoughness", 0.01)), 0.0), 1.0)
        self._normal_input(shader, "normal", out, what)

    # MaterialX / OpenPBR inputs the core leaves out, with their "off" value
    _OPEN_PBR_UNSUPPORTED = (("fuzz_weight", 0.0), ("subsurface_weight", 0.0),
                             ("thin_film_weight", 0.0), ("specular_roughness_anisotropy", 0.0))

    def _materialx(self, surface, out, what) -> bool:
        """OpenPBR (Blender's Principled) or a MaterialX `surface` of one diffuse, conductor or
        dielectric BSDF plus a uniform EDF (Diffuse, Glossy, Glass, Emission). False: not
        renderable exactly (the UsdPreviewSurface is used instead, with a warning)."""
        kind = surface.GetIdAttr().Get()
        p = lambda sh, name, default, key=None: self._param(sh, name, default, what, out, key)  # noqa: E731
        if kind == "ND_open_pbr_surface_surfaceshader":
            weight = p(surface, "base_weight", 1.0)
            color = p(surface, "base_color", (0.8, 0.8, 0.8), "base_color_texture")
            out["base_color"] = tuple(c * weight for c in color)
            out["metallic"] = p(surface, "base_metalness", 0.0, "metallic_texture")
            out["diffuse_roughness"] = min(max(float(p(surface, "base_diffuse_roughness", 0.0)), 0.0), 1.0)
            coat = min(max(float(p(surface, "coat_weight", 0.0)), 0.0), 1.0)
            if coat > 0.0:  # (Blender writes its Principled coat here: weight, roughness, IOR, tint)
                out["coat"] = coat
                out["coat_roughness"] = min(max(float(p(surface, "coat_roughness", 0.0)), 0.0), 1.0)
                out["coat_ior"] = max(float(p(surface, "coat_ior", 1.6)), 1.0)
                out["coat_tint"] = tuple(max(float(c), 0.0) for c in p(surface, "coat_color", (1.0, 1.0, 1.0)))
            out["multiscatter"] = True  # OpenPBR's metal conserves energy (Blender's default, too)
            out["roughness"] = p(surface, "specular_roughness", 0.3, "roughness_texture")
            out["ior"] = p(surface, "specular_ior", 1.5)
            # OpenPBR's specular_weight is twice Principled's Specular IOR Level
            out["specular_ior"] = specular_layer_ior(out["ior"], 0.5 * p(surface, "specular_weight", 1.0))
            out["transmission"] = p(surface, "transmission_weight", 0.0)
            if out["transmission"] > 0:
                # as the Principled BSDF it comes from: untinted reflection, √colour transmitted
                out["glass_reflection_tint"], out["glass_sqrt_tint"] = (1.0, 1.0, 1.0), True
            lum = p(surface, "emission_luminance", 0.0)  # Blender writes its Emission Strength here
            out["emission"] = tuple(c * lum for c in p(surface, "emission_color", (1.0, 1.0, 1.0)))
            opacity = min(max(p(surface, "geometry_opacity", 1.0, "alpha_texture"), 0.0), 1.0)
            if opacity < 1.0:
                out["transparency"] = 1.0 - opacity
            for name, off in self._OPEN_PBR_UNSUPPORTED:
                if abs(p(surface, name, off) - off) > 1e-6:
                    self.warn(f"{what}: OpenPBR '{name}' is not rendered (the layer is left out)")
            tint = tuple(min(max(float(c), 0.0), 1.0) for c in p(surface, "specular_color", (1.0, 1.0, 1.0)))
            if any(abs(c - 1.0) > 1e-6 for c in tint):  # (Blender writes its Specular Tint here)
                out["specular_tint"] = tint
                if out["transmission"] > 0.0:
                    self.warn(f"{what}: OpenPBR 'specular_color' is not applied to the transmissive part")
            self._normal_input(surface, "geometry_normal", out, what)
            return True
        if kind != "ND_surface":
            self.warn(f"{what}: MaterialX surface {kind} is not supported; the UsdPreviewSurface is used")
            return False
        bsdf = self._source(surface.GetInput("bsdf"))
        edf = self._source(surface.GetInput("edf"))
        if edf is not None:
            if edf[0].GetIdAttr().Get() != "ND_uniform_edf":
                self.warn(f"{what}: MaterialX EDF {edf[0].GetIdAttr().Get()} is not supported; the "
                          f"UsdPreviewSurface is used")
                return False
            out["emission"] = self._emission_color(edf[0], out, what)
        out["specular_ior"] = 1.0
        if bsdf is None:
            out["base_color"] = (0.0, 0.0, 0.0)
        else:
            sh, bkind = bsdf[0], bsdf[0].GetIdAttr().Get()
            weight = p(sh, "weight", 1.0)
            rough = lambda: float(np.mean(p(sh, "roughness", (0.0, 0.0, 0.0))[:2]))  # noqa: E731 (float2)
            if bkind == "ND_oren_nayar_diffuse_bsdf":
                out["base_color"] = tuple(c * weight for c in p(sh, "color", (0.8, 0.8, 0.8), "base_color_texture"))
                out["roughness"] = 1.0
                # (Oren–Nayar above 0, compensated for multiple scattering as Cycles renders it)
                out["diffuse_roughness"] = min(max(float(p(sh, "roughness", 0.0)), 0.0), 1.0)
            elif bkind == "ND_translucent_bsdf":  # (Blender's Translucent BSDF: diffuse transmission)
                out["base_color"], out["translucency"] = (0.0, 0.0, 0.0), 1.0
                out["translucent_color"] = tuple(c * weight for c in p(sh, "color", (1.0, 1.0, 1.0)))
            elif bkind == "ND_conductor_bsdf":
                ior = self._source(sh.GetInput("ior"))
                if ior is None or ior[0].GetIdAttr().Get() != "ND_artistic_ior":
                    self.warn(f"{what}: MaterialX conductor without artistic IOR; the UsdPreviewSurface is used")
                    return False
                out["base_color"] = tuple(c * weight for c in p(ior[0], "reflectivity", (0.8, 0.8, 0.8)))
                out["metallic"], out["roughness"], out["multiscatter"] = 1.0, rough(), True
                out["metal_constant_fresnel"] = True  # (Blender writes its Glossy BSDF so: its colour at every angle)
            elif bkind == "ND_dielectric_bsdf" and p(sh, "scatter_mode", "R") in ("RT", "T"):
                out["base_color"] = tuple(c * weight for c in p(sh, "tint", (1.0, 1.0, 1.0)))
                out["transmission"], out["ior"], out["roughness"] = 1.0, p(sh, "ior", 1.5), rough()
                out["multiscatter"] = True  # Blender's Glass BSDF default (Multiscatter GGX)
            else:
                self.warn(f"{what}: MaterialX BSDF {bkind} is not supported; the UsdPreviewSurface is used")
                return False
            self._normal_input(sh, "normal", out, what)
        opacity = surface.GetInput("opacity")
        value = opacity.Get(self.time) if opacity and not opacity.HasConnectedSource() else None
        if value is not None and value < 1.0:
            out["transparency"] = 1.0 - min(max(float(value), 0.0), 1.0)
        return True

    # ---- textures --------------------------------------------------------------------
    _WRAP = {"repeat": "REPEAT", "periodic": "REPEAT", "clamp": "EXTEND", "black": "CLIP", "constant": "CLIP",
             "useMetadata": "REPEAT", "mirror": "REPEAT"}

    def _emission_color(self, edf, out, what):
        """A uniform EDF's colour: a constant, or an image (× a constant colour, the way Blender
        writes Emission Color × Strength) → out['emission_texture'] and the factor."""
        inp = edf.GetInput("color")
        src = self._source(inp) if inp else None
        factor = (1.0, 1.0, 1.0)
        if src is not None and src[0].GetIdAttr().Get() == "ND_multiply_color3" and \
                not src[0].GetInput("in2").HasConnectedSource():
            factor = self._param(src[0], "in2", factor, what)
            src = self._source(src[0].GetInput("in1"))
        if src is not None:
            index = self._texture(src[0], what)
            if index is not None:
                out["emission_texture"] = index
                return factor
        return self._param(edf, "color", (1.0, 1.0, 1.0), what)

    def _normal_input(self, shader, name, out, what):
        """A connected normal input: a tangent-space normal map (MaterialX `normalmap` of an
        image, or a UsdUVTexture read with scale 2 and bias −1) → out['normal_texture'] and
        out['normal_strength']; anything else is ignored with a warning."""
        inp = shader.GetInput(name)
        if not inp or not inp.HasConnectedSource():
            return
        src = self._source(inp)
        kind = src[0].GetIdAttr().Get() if src is not None else None
        index, strength = None, 1.0
        if kind is not None and kind.startswith("ND_normalmap"):
            space = self._param(src[0], "space", "tangent", what)
            image = self._source(src[0].GetInput("in"))
            if space == "tangent" and image is not None:
                index = self._texture(image[0], what, normal=True)
                strength = self._param(src[0], "scale", 1.0, what)
        elif kind == "UsdUVTexture" and src[1] == "rgb":
            index = self._texture(src[0], what, normal=True)
        if index is None:
            self.warn(f"{what}: the '{name}' input ({kind}) is not a tangent-space normal map of an image; "
                      f"the mesh normal is used")
            return
        out["normal_texture"], out["normal_strength"] = index, max(float(strength), 0.0)

    def _texture(self, shader, what, alpha=False, normal=False):
        """Texture index of a UsdUVTexture or a MaterialX image node (through a colour
        conversion, or channel 3 extracted: `alpha`), read from its file; None (with a
        warning) when it cannot be. With `alpha`: a grey texture of the alpha channel."""
        kind = shader.GetIdAttr().Get() or ""
        if kind.startswith("ND_convert_") or (kind == "ND_extract_color4" and alpha):
            if kind == "ND_extract_color4" and self._param(shader, "index", 0.0, what) != 3:
                return None
            src = self._source(shader.GetInput("in"))
            return self._texture(src[0], what, alpha) if src is not None else None
        if alpha and kind.startswith("ND_") and not kind.endswith("color4"):
            return None  # a MaterialX image without alpha
        p = lambda name, default: self._param(shader, name, default, what)  # noqa: E731
        p_of = lambda sh, name, default: self._param(sh, name, default, what)  # noqa: E731
        if kind == "UsdUVTexture":
            wraps = {shader.GetInput(w).Get() if shader.GetInput(w) else "useMetadata" for w in ("wrapS", "wrapT")}
            space = shader.GetInput("sourceColorSpace").Get() if shader.GetInput("sourceColorSpace") else "auto"
            closest = False
            transform = None
            st = self._source(shader.GetInput("st"))
            if st is not None and st[0].GetIdAttr().Get() == "UsdTransform2d":
                # in·scale, turned by `rotation` degrees, + translation (as Blender's Mapping)
                tr = st[0]
                sx, sy = (tuple(p_of(tr, "scale", (1.0, 1.0, 1.0)))[:2])
                a = math.radians(p_of(tr, "rotation", 0.0))
                tx, ty = (tuple(p_of(tr, "translation", (0.0, 0.0, 0.0)))[:2])
                c, s_ = math.cos(a), math.sin(a)
                transform = (c * sx, -s_ * sy, tx, s_ * sx, c * sy, ty)
                st = self._source(tr.GetInput("in"))
            if st is not None:
                reader = st[0]
                var = reader.GetInput("varname").Get() if reader.GetInput("varname") else None
                if reader.GetIdAttr().Get() != "UsdPrimvarReader_float2" or str(var) != "st":
                    self.warn(f"{what}: texture '{shader.GetPath().name}' reads other coordinates than primvar "
                              f"'st' (other UV sets, other transforms); 'st' is used")
            # a normal map is read as 2·rgb − 1: the scale and bias UsdPreviewSurface asks for
            scale, bias = ((2.0,) * 3, (-1.0,) * 3) if normal else ((1.0,) * 3, (0.0,) * 3)
            if tuple(p("scale", (1.0,) * 3)) != scale or tuple(p("bias", (0.0,) * 3)) != bias:
                self.warn(f"{what}: texture '{shader.GetPath().name}' scale and bias other than {scale[0]:g} and "
                          f"{bias[0]:g} are ignored")
            if normal:
                space = "raw"
        elif kind.startswith("ND_image_") or kind.startswith("ND_tiledimage_"):
            wraps = {shader.GetInput(w).Get() if shader.GetInput(w) else "periodic"
                     for w in ("uaddressmode", "vaddressmode")}
            attr = shader.GetInput("file").GetAttr() if shader.GetInput("file") else None
            cs = (attr.GetColorSpace() if attr and attr.HasColorSpace() else "") or ""
            # MaterialX files are in the document's (linear) space unless tagged: Blender tags
            # sRGB images "srgb_texture" and writes Non-Color ones as vector images
            space = "sRGB" if "srgb" in cs.lower() else "raw"
            closest = p("filtertype", "linear") == "closest"
            transform = None
            coords = self._source(shader.GetInput("texcoord"))
            while coords is not None and (coords[0].GetIdAttr().Get() or "").startswith("ND_convert_"):
                coords = self._source(coords[0].GetInput("in"))
            if coords is not None and coords[0].GetIdAttr().Get() != "ND_texcoord_vector2":
                raise _PreviewInstead(f"texture coordinates from {coords[0].GetIdAttr().Get()}")
            if kind.startswith("ND_tiledimage_"):
                self.warn(f"{what}: tiling of texture '{shader.GetPath().name}' is ignored")
        else:
            return None
        inp = shader.GetInput("file")
        asset = inp.Get(self.time) if inp else None
        if not asset or not asset.path:
            self.warn(f"{what}: texture '{shader.GetPath().name}' has no file")
            return None
        file = Path(asset.resolvedPath) if asset.resolvedPath else \
            Path(self.stage.GetRootLayer().realPath).parent / asset.path
        if "mirror" in wraps or len(wraps) > 1:
            self.warn(f"{what}: texture '{file.name}' wrap modes {sorted(map(str, wraps))}: one mode for both "
                      f"axes, and mirror as repeat")
        key = (str(file), space, closest, min(wraps, key=str), alpha, transform)
        if key in self.texture_index:
            return self.texture_index[key]
        image = _read_image(file)
        if image is None:
            self.warn(f"{what}: texture '{asset.path}' could not be read; the input's value is used")
            return None
        pixels, coverage, eight_bit = image
        if alpha:  # alpha is linear, whatever the colour space
            pixels, space = np.repeat((coverage if coverage is not None else np.ones(pixels.shape[:2]))[..., None], 3, -1), "raw"
        h, w, _ = pixels.shape
        self.textures.append(scenedict.texture(file.name + (" (alpha)" if alpha else ""),
                                               np.ascontiguousarray(pixels[::-1].reshape(-1, 3)), w, h,  # row 0 at the bottom
                                               interpolation="Closest" if closest else "Linear",
                                               extension=self._WRAP.get(str(min(wraps, key=str)), "REPEAT"),
                                               srgb=space == "sRGB" or (space == "auto" and eight_bit)))
        if transform is not None:
            self.textures[-1]["transform"] = transform
        self.texture_index[key] = len(self.textures) - 1
        return self.texture_index[key]

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
        if (counts < 0).any():
            raise ValueError(f"mesh '{name}': negative faceVertexCounts ({int(counts.min())})")
        if counts.sum() != len(idx):
            raise ValueError(f"mesh '{name}': faceVertexCounts add up to {counts.sum()} but there are "
                             f"{len(idx)} faceVertexIndices")
        if len(idx) and (idx.min() < 0 or idx.max() >= len(pts)):
            raise ValueError(f"mesh '{name}': faceVertexIndices reach {int(idx.min())}…{int(idx.max())} "
                             f"but there are {len(pts)} points")
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
        m = _mat(self.xcache.GetLocalToWorldTransform(prim)) if to_world is None else to_world
        det = np.linalg.det(m[:3, :3])
        # the outside (how glass refracts) is taken from the world-space winding: a left-handed
        # mesh, or a mirroring transform (negative determinant), winds it the other way
        if (mesh.GetOrientationAttr().Get() == "leftHanded") != (det < 0):
            corners = corners[:, [0, 2, 1]]
        tris = idx[corners]
        if len(tris) == 0:
            self.warn(f"mesh '{name}': no face with three or more corners; skipped")
            return None
        pos = pts @ m[:3, :3].T + m[:3, 3]
        nmat = np.linalg.inv(m[:3, :3]).T if abs(det) > 1e-30 else m[:3, :3]

        def corner_values(values, interp, what):
            """Per-corner values of a primvar, or None (with a warning) when it holds fewer
            values than its interpolation needs."""
            values = np.asarray(values, dtype=np.float64)
            need = {"vertex": len(pts), "varying": len(pts), "faceVarying": len(idx),
                    "uniform": len(counts)}.get(interp, 1)
            if values.ndim != 2 or len(values) < need:
                self.warn(f"mesh '{name}': {what} has {len(values)} values, {interp} needs {need}; ignored")
                return None
            if interp in ("vertex", "varying"):
                return values[tris]
            if interp == "faceVarying":
                return values[corners]
            if interp == "uniform":
                return np.repeat(values[face_of_tri][:, None, :], 3, axis=1)
            return np.broadcast_to(values[0], (len(tris), 3, values.shape[-1]))

        out = scenedict.mesh(name, np.ascontiguousarray(pos, dtype=np.float32), np.ascontiguousarray(tris, dtype=np.uint32))
        pv_api = UsdGeom.PrimvarsAPI(prim)
        nrm_pv = pv_api.GetPrimvar("normals")
        if nrm_pv and nrm_pv.HasValue():
            normals, interp = nrm_pv.ComputeFlattened(t), nrm_pv.GetInterpolation()
        else:
            normals, interp = mesh.GetNormalsAttr().Get(t), mesh.GetNormalsInterpolation()
        if normals is not None and len(normals):
            cn = corner_values(normals, interp, "normals")
            if cn is not None:
                out["normals"] = np.ascontiguousarray(cn.reshape(-1, 3) @ nmat.T, dtype=np.float32)
        st = pv_api.GetPrimvar("st")
        if st and st.HasValue():
            uv = corner_values(st.ComputeFlattened(t), st.GetInterpolation(), "primvar st")
            if uv is not None:
                out["uvs"] = np.ascontiguousarray(uv.reshape(-1, 2), dtype=np.float32)
        # materials: the prim's binding, overridden per face by GeomSubsets
        binding = UsdShade.MaterialBindingAPI(prim)
        face_mat = np.full(len(counts), self.material(binding.ComputeBoundMaterial()[0]), dtype=np.uint32)
        for subset in binding.GetMaterialBindSubsets():
            faces = np.array(subset.GetIndicesAttr().Get(t) or [], dtype=np.int64)
            mat = UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial()[0]
            face_mat[faces[(faces >= 0) & (faces < len(counts))]] = self.material(mat)
        out["material_ids"] = np.ascontiguousarray(face_mat[face_of_tri])
        layers = [x for x in dict.fromkeys(self.colour_layers.get(int(i)) for i in np.unique(face_mat)) if x]
        if len(layers) > 1:
            self.warn(f"mesh '{name}': its materials read different colour primvars ({', '.join(layers)}); all get "
                      f"'{layers[0]}'")
        if layers:
            pv = pv_api.GetPrimvar(layers[0])
            colours = corner_values(pv.ComputeFlattened(t), pv.GetInterpolation(), f"primvar {layers[0]}") \
                if pv and pv.HasValue() else None
            if colours is None:
                self.warn(f"mesh '{name}': its material reads the colour primvar '{layers[0]}', which it does not "
                          f"have: black")
            else:
                out["colors"] = np.ascontiguousarray(colours[..., :3].reshape(-1, 3), dtype=np.float32)
        return out

    def point_instancer(self, prim):
        """The meshes of a UsdGeomPointInstancer's prototypes, each once in its prototype's
        space, with the transforms of every instance that uses it (the core stores a mesh
        once and places it; src/instancing.rs). Vectorized: no Python work per instance."""
        UsdGeom, Usd = self.pxr.UsdGeom, self.pxr.Usd
        inst = UsdGeom.PointInstancer(prim)
        xforms = inst.ComputeInstanceTransformsAtTime(self.time, self.time)
        indices = np.asarray(inst.GetProtoIndicesAttr().Get(self.time) or [], dtype=np.int64)
        targets = inst.GetPrototypesRel().GetTargets()
        # row-vector matrices (USD's p' = p·M), one per instance
        x = np.array(xforms, dtype=np.float64).reshape(-1, 4, 4) if len(xforms) else np.zeros((0, 4, 4))
        world = np.array(self.xcache.GetLocalToWorldTransform(prim), dtype=np.float64)
        n = min(len(indices), len(x))
        bad = (indices[:n] < 0) | (indices[:n] >= len(targets))
        if bad.any():
            i = int(np.argmax(bad))
            self.warn(f"'{prim.GetPath()}': {int(bad.sum())} instance(s) use a prototype out of range (instance {i} "
                      f"uses prototype {int(indices[i])} of {len(targets)}); skipped")
        out = []
        for k, path in enumerate(targets):
            root = self.stage.GetPrimAtPath(path)
            inv = self.xcache.GetLocalToWorldTransform(root).GetInverse()
            parts = [(p, self.xcache.GetLocalToWorldTransform(p) * inv)
                     for p in Usd.PrimRange(root, Usd.TraverseInstanceProxies()) if p.IsA(UsdGeom.Mesh)]
            if not parts and root.IsA(UsdGeom.Gprim):
                self.warn(f"'{path}': {root.GetTypeName()} prototypes are not supported (only Mesh); skipped")
            mine = x[:n][(indices[:n] == k) & ~bad]
            if len(mine) == 0:
                continue
            for part, rel in parts:
                m = self.mesh(part, to_world=np.eye(4))
                if m is None:
                    continue
                full = np.array(rel, dtype=np.float64) @ mine @ world  # (row-vector) part → world
                cols = np.transpose(full, (0, 2, 1))[:, :3, :]  # column-vector rows 0..2
                m["name"] = f"{prim.GetPath()}[{k}]{part.GetPath()}"
                m["transforms"] = np.ascontiguousarray(cols.reshape(-1, 12), dtype=np.float32)
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
                return scenedict.spot_light(name, pos, minus_z.tolist(), power.tolist(), r, 2 * math.radians(angle),
                                            float(shaping.GetShapingConeSoftnessAttr().Get(t) or 0.0),
                                            visible_camera=visible, matrix=m.astype(np.float32))
            return scenedict.point_light(name, pos, power.tolist(), r, visible_camera=visible)
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
            return scenedict.area_light(name, m.astype(np.float32), "RECTANGLE" if rect else "DISK", w, h,
                                        power.tolist(), visible_camera=visible)
        if prim.IsA(UsdLux.DistantLight):
            light = UsdLux.DistantLight(prim)
            color = _light_color(light, t, self.warnings, name)
            plus_z = m[:3, 2] / np.linalg.norm(m[:3, 2])
            # As Blender's own USD importer reads a DistantLight back (checked with bpy 5.0.1:
            # its exporter writes a sun of strength S and angle θ as intensity S/4, angle θ/2,
            # and its importer returns S and θ): irradiance = 4·intensity·2^exposure·colour,
            # angular diameter = 2·angle.
            return scenedict.sun_light(name, plus_z.tolist(), (color * 4.0 * _light_scale(light, t)).tolist(),
                                       2.0 * math.radians(float(light.GetAngleAttr().Get(t) or 0.0)), visible)
        self.warn(f"light '{name}': {prim.GetTypeName()} is not supported; skipped")
        return None

    def dome(self, prim):
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
        textures = self.textures
        textures.append(scenedict.texture(file.name, np.ascontiguousarray(pixels[::-1].reshape(-1, 3)), w, h,
                                          interpolation="Linear", extension="REPEAT"))  # row 0 at the bottom
        m = _mat(self.xcache.GetLocalToWorldTransform(prim))[:3, :3]
        m = m / np.linalg.norm(m, axis=0)
        to_texture = m.T if _blender_5_0(self.stage) else DOME_TO_EQUIRECT @ m.T
        return scale, len(textures) - 1, np.ascontiguousarray(to_texture, dtype=np.float32)

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


def _read_image(path):
    """(float32 H×W×3 with row 0 at the top, its alpha channel H×W or None, whether it was
    8-bit) of an OpenEXR file or of any image Pillow reads (PNG, JPEG, TIFF, …); None when it
    cannot be read."""
    path = Path(path)
    if not path.is_file():
        return None
    if path.suffix.lower() == ".exr":
        px = _read_exr(path)
        return None if px is None else (px, None, False)
    try:
        from PIL import Image
    except ImportError:
        return None
    try:
        with Image.open(path) as im:
            if im.mode in ("I;16", "I;16B", "I"):
                px = np.asarray(im, dtype=np.float32) / 65535.0
                return np.repeat(px[..., None], 3, axis=-1), None, False
            rgba = np.asarray(im.convert("RGBA"), dtype=np.float32) / 255.0
            has_alpha = "A" in im.getbands() or "transparency" in im.info
            return rgba[..., :3], (rgba[..., 3] if has_alpha else None), True
    except Exception:  # a broken file is reported by the caller as unreadable
        return None


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
    try:
        layer = pxr.Sdf.Layer.FindOrOpen(str(path))
    except pxr.Tf.ErrorException as e:
        raise ValueError(f"'{path}' is not a valid USD stage: {parse_error(e)}") from None
    if layer is None:
        return {}
    data = layer.customLayerData.get("gdmlt", {})
    return {str(k): (v if not isinstance(v, str) else str(v)) for k, v in dict(data).items()}


def parse_error(e) -> str:
    """The line of a USD error a user needs (file:line:col: the parser's message) out of the
    C++ call stack pxr reports, its internal namespace removed; else the last message."""
    import re

    text = re.sub(r"pxrInternal_\w+?__pxrReserved__::", "", str(e))
    found = re.search(r"'([^'\n]+:\d+:\d+: [^\n]*?)'?\s*$", text, re.MULTILINE)
    if found:
        return found.group(1).strip().rstrip("'")
    quoted = re.findall(r" : '([^']*)'", text)
    return quoted[-1].strip() if quoted else text.strip() or type(e).__name__


# A UsdLux DomeLight's frame (OpenEXR's latlong map: latitude ±π/2 along ±Y, longitude 0
# along +Z and π/2 along +X) in the frame of Blender's equirectangular mapping, which the
# core's world texture takes (pole +Z, the image's centre along +X, a quarter along +Y):
# the columns are where the dome's +X, +Y, +Z go. (Blender's exporter from 5.1 on rotates
# its dome by (90°, 0, 90°) about X then Z, this matrix; 4.5's does too, 5.0's did not.)
DOME_TO_EQUIRECT = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _blender_5_0(stage):
    """Whether the stage was written by Blender 5.0's exporter (its layer's documentation
    reads "Blender v5.0..."), whose DomeLights hold Blender's own mapping, unrotated."""
    return re.match(r"Blender v5\.0\b", stage.GetRootLayer().documentation or "") is not None


def load(path, frame=None, width=None, height=None, camera=None):
    """Reads a USD stage into a scene dict. Returns (dict, warnings). Raises
    FileNotFoundError for a missing file and ValueError for a stage that cannot be rendered
    (no camera, broken meshes). `camera`: path of the camera prim (default: the first)."""
    pxr = _pxr()
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    try:
        stage = pxr.Usd.Stage.Open(str(path))
    except pxr.Tf.ErrorException as e:
        raise ValueError(f"'{path}' is not a valid USD stage: {parse_error(e)}") from None
    if stage is None:
        raise ValueError(f"'{path}' could not be opened as a USD stage")
    time = pxr.Usd.TimeCode(frame) if frame is not None else pxr.Usd.TimeCode.Default()
    warnings = []
    stored = stored_settings(path)
    if width is None and height is None and "width" in stored:
        try:
            width, height = (int(stored[k]) for k in ("width", "height"))
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"'{path}': customLayerData gdmlt width and height must both be integers, got "
                             f"{stored.get('width')!r} and {stored.get('height')!r}") from None
        if not (1 <= width <= 65536 and 1 <= height <= 65536):
            raise ValueError(f"'{path}': customLayerData gdmlt image size {width}×{height} is not 1…65536 pixels a side")
    r = _Reader(stage, time, warnings)
    meshes, lights, world, cams = [], [], (0.0, 0.0, 0.0), []
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
            world, world_texture, world_rotation = r.dome(prim)
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
            "textures": r.textures, "world_texture": world_texture, "world_rotation": world_rotation,
            "camera": r.camera(cams[0], width, height)}
    return desc, warnings
