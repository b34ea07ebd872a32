"""The scene dict, the layout `gdmlt.Scene` reads, built in one place for both exporters
(the Blender add-on's `export.py` and the USD reader `usd.py`): one constructor per kind of
entry, each with the layout's keys and defaults. What each key means and which values are
valid is said once, by the core's parsers (`src/python.rs`, filling `src/scene/desc.rs`),
which also warn about any key they do not read.
"""

import math

# The material of triangles without one (and every material's starting point): a grey
# diffuse-ish Principled BSDF, as Blender's default surface.
DEFAULT_MATERIAL = {"name": "(default)", "base_color": (0.8, 0.8, 0.8), "emission": (0.0, 0.0, 0.0),
                    "roughness": 0.5, "metallic": 0.0, "transmission": 0.0, "ior": 1.5}

# What Blender gives an object without a material (or an empty slot), and Cycles renders:
# its default surface, a default Principled BSDF (base 0.8 under the specular layer of IOR
# 1.5 at Specular IOR Level 0.5) — not Cycles' own diffuse default.
DEFAULT_SURFACE = dict(DEFAULT_MATERIAL, name="(default surface)", specular_ior=1.5, multiscatter=True)


def material(name: str, **params) -> dict:
    """A material: DEFAULT_MATERIAL with `params` (base_color, emission, roughness, metallic,
    transmission, ior, specular, specular_ior, diffuse_roughness (0 = Lambertian, up to 1:
    Oren–Nayar), *_texture indices, …) over it."""
    return dict(DEFAULT_MATERIAL, name=name, **params)


def point_light(name, position, power, radius, soft_falloff=True, visible_camera=False) -> dict:
    """A point light: power in W per RGB channel (Blender's), a sphere of `radius`."""
    return {"type": "POINT", "name": name, "position": tuple(position), "radius": float(radius),
            "soft_falloff": bool(soft_falloff), "power": tuple(power), "visible_camera": bool(visible_camera)}


def spot_light(name, position, direction, power, radius, spot_size, spot_blend, soft_falloff=True,
               visible_camera=False, matrix=None) -> dict:
    """A spot light: a point light limited to a cone of full angle `spot_size` (radians)
    around `direction`, softened by `spot_blend`. `matrix`: the light object's 4×4 matrix (float32),
    whose uneven scale makes the cone elliptical as in Cycles (round in the object's scaled
    frame); None: a round cone."""
    d = dict(point_light(name, position, power, radius, soft_falloff, visible_camera), type="SPOT",
             direction=tuple(direction), spot_size=float(spot_size), spot_blend=float(spot_blend))
    if matrix is not None:
        d["matrix"] = matrix
    return d


def area_light(name, matrix, shape, size, size_y, power, normalize=True, visible_camera=False,
               spread=math.pi) -> dict:
    """An area light emitting along its local −Z: `shape` SQUARE, RECTANGLE, DISK or ELLIPSE,
    `matrix` its object matrix (4×4 float32, scale included); `spread` Blender's Spread, the
    full angle of its emission cone in radians (π: Lambertian; narrower keeps the power, as
    Cycles' soft-box model)."""
    return {"type": "AREA", "name": name, "matrix": matrix, "shape": shape, "size": float(size),
            "size_y": float(size_y), "power": tuple(power), "normalize": bool(normalize),
            "visible_camera": bool(visible_camera), "spread": float(spread)}


def sun_light(name, direction, irradiance, angle, visible_camera=False) -> dict:
    """A sun: light arriving from `direction` (towards the sun), `irradiance` in W/m² per
    channel, a disc of angular diameter `angle` (radians)."""
    return {"type": "SUN", "name": name, "direction": tuple(direction), "irradiance": tuple(irradiance),
            "angle": float(angle), "visible_camera": bool(visible_camera)}


def mesh(name, positions, indices, normals=None, material_ids=None, uvs=None, pass_index=0, colors=None) -> dict:
    """A triangle mesh in world space: positions (N×3 float32), indices (T×3 uint32), per-corner
    normals (3T×3), UVs (3T×2) and colours (3T×3, linear RGB: what a material with
    `vertex_color` multiplies its base colour by), per-triangle material ids (uint32);
    `pass_index` is its object's Pass Index."""
    out = {"name": name, "positions": positions, "indices": indices}
    for key, value in (("normals", normals), ("material_ids", material_ids), ("uvs", uvs), ("colors", colors)):
        if value is not None:
            out[key] = value
    if pass_index:
        out["pass_index"] = int(pass_index)
    return out


def texture(name, pixels, width, height, channels=3, **params) -> dict:
    """An image texture: pixels (height × width × channels float32, row 0 at the bottom);
    `params`: srgb, extension, interpolation, transform."""
    return {"name": name, "width": int(width), "height": int(height), "channels": int(channels), "pixels": pixels,
            **params}
