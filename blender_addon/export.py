"""Evaluated depsgraph → scene arrays (the dict layout that gdmlt.Scene takes).

Geometry is read with foreach_get into numpy (no per-vertex Python objects). An object is
exported in world space; instances from `depsgraph.object_instances` (Geometry Nodes,
particle and collection instances) are exported as one mesh in object space with the
transforms of its instances, which the core stores once (src/instancing.rs). Lights follow
Cycles' conventions; the conversion to radiance happens in the core. Everything unsupported
is reported as a warning with a fallback.
"""

import hashlib
import math
import os
from dataclasses import dataclass, field

import numpy as np
from gdmlt import scenedict  # the scene dict's one builder (the add-on registers only once gdmlt imports)
from gdmlt.scenedict import DEFAULT_MATERIAL, DEFAULT_SURFACE

from .node_view import NodeView

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT", "CURVES", "POINTCLOUD", "VOLUME"}
# Object types GDMLT cannot render yet: left out of the scene with a warning naming the object.
NOT_RENDERED = {"CURVES": "hair curves", "POINTCLOUD": "point clouds", "VOLUME": "volumes"}
# Object › Visibility › Ray Visibility: every ray sees every object and light in GDMLT (a
# light's camera visibility excepted, which is rendered)
RAY_VISIBILITY = (("camera", "visible_camera"), ("diffuse", "visible_diffuse"), ("glossy", "visible_glossy"),
                  ("transmission", "visible_transmission"), ("shadow", "visible_shadow"))


def _visibility_warnings(ob, what, warnings, light=False):
    """Warnings for the ray visibility and shadow catcher settings of `ob`, which GDMLT does
    not render (each ray type sees it; it is rendered as an ordinary object), but for the
    camera and shadow visibility, which are (the mesh's `visible_camera` and
    `visible_shadow`; a light's camera visibility too, and its shadow visibility means
    nothing to Cycles), and holdout (`_holdout`). Blender keeps holdout and shadow-catcher
    flags on lights that Cycles ignores."""
    skip = ("camera", "shadow")
    off = [name for name, attr in RAY_VISIBILITY if name not in skip and not getattr(ob, attr, True)]
    if off:
        warnings.append(f"{what} '{ob.name}': ray visibility ({', '.join(off)} off) is not rendered; "
                        "every ray sees it")
    linking = getattr(ob, "light_linking", None)
    if linking is not None and linking.blocker_collection is not None:
        warnings.append(f"{what} '{ob.name}': shadow linking (its Blocker collection) is not rendered; every "
                        "object casts its shadows")
    if light:
        return
    if getattr(ob, "is_shadow_catcher", False):
        warnings.append(f"{what} '{ob.name}': shadow catcher is not rendered; it is rendered as an ordinary object")


class ExportCancelled(Exception):
    pass


def _input_value(node, name, warnings, what, default=None):
    """An input's value: unlinked, its own; linked from an RGB or Value node, that node's
    constant (converted as Cycles converts sockets: a colour into a value socket is its
    luminance, Rec.709 weights; a value into a colour socket is grey); linked to anything else
    (a texture, etc.), its unlinked value, with a warning."""
    return _socket_value(node.inputs.get(name), warnings, what, default)


def _socket_value(sock, warnings, what, default=None):
    """`_input_value` of an input socket."""
    if sock is None:
        return default
    v = getattr(sock, "default_value", default)
    if sock.is_linked:
        from . import texture_graph

        try:
            kind, c = texture_graph.evaluate(sock, None, None)  # (constant: no image under it)
        except texture_graph.Unsupported as e:
            warnings.append(f"{what}: input '{sock.name}' of node '{sock.node.name}' is linked through {e}, which "
                            f"GDMLT does not evaluate here; its unlinked value is used")
        else:
            try:
                n = len(v)
            except TypeError:
                return float(c)
            return (*c, 1.0)[:n]
    try:
        return tuple(v)
    except TypeError:
        return float(v)


LINEAR_COLORSPACES = {"Non-Color", "Linear Rec.709", "Linear", "Linear CIE-XYZ E", "Raw", "Linear Rec.2020"}


class Textures:
    """The scene's image textures, each Blender image (with its sampling settings) once."""

    def __init__(self):
        self.items = []
        self.index = {}
        self.pixels = {}  # image name → its RGBA pixels, for node graphs (read once per export)
        self.spaces = {}  # procedural texture index → the coordinates it reads ('GENERATED', 'OBJECT', 'UV')
        self.graphs = {}  # (material, node, socket) → add_graph's result: a graph is evaluated once

    def add(self, node, warnings, what, alpha=False):
        """Index of the texture of an Image (or Environment) Texture node, or None (with a
        warning) if it cannot be used: no image, a missing file, an empty image. With
        `alpha`, a grey texture of the image's alpha channel (linear, as Cycles reads it)."""
        img = node.image
        if img is None:
            warnings.append(f"{what}: texture node '{node.name}' has no image; its input uses the socket value")
            return None
        env = node.type == "TEX_ENVIRONMENT"
        ext = "REPEAT" if env else node.extension
        transform = None if env else _uv_transform(node, warnings, what)
        key = (img.name, node.interpolation, ext, alpha, transform)
        if key in self.index:
            return self.index[key]
        read = self.rgba(img)
        if read is None:
            warnings.append(f"{what}: image '{img.name}' has no pixels (missing file '{img.filepath}'?); "
                            f"its input uses the socket value")
            return None
        px, w, h, _ = read
        rgb = np.repeat(px[:, 3:4], 3, axis=1) if alpha else px[:, :3]
        cs = img.colorspace_settings.name
        # byte images hold sRGB-encoded values, decoded after interpolation as Cycles does;
        # float images are linear (and alpha always is)
        srgb = cs == "sRGB" and not img.is_float and not alpha
        if cs not in LINEAR_COLORSPACES and cs != "sRGB":
            warnings.append(f"{what}: image '{img.name}' colour space '{cs}' is treated as linear")
        if node.projection != ("EQUIRECTANGULAR" if env else "FLAT"):
            warnings.append(f"{what}: texture '{node.name}' projection {node.projection} is not supported "
                            f"(rendered as {'EQUIRECTANGULAR' if env else 'FLAT'})")
        if ext not in ("REPEAT", "EXTEND", "CLIP", "MIRROR"):
            warnings.append(f"{what}: Image Texture '{node.name}' extension {ext} is rendered as REPEAT")
            ext = "REPEAT"
        self.index[key] = len(self.items)
        self.items.append(scenedict.texture(img.name + (" (alpha)" if alpha else ""),
                                            np.ascontiguousarray(rgb, dtype=np.float32), w, h,
                                            interpolation="Closest" if node.interpolation == "Closest" else "Linear",
                                            extension=ext, srgb=srgb))
        if transform is not None:
            self.items[-1]["transform"] = transform
        return self.index[key]

    def rgba(self, img, keep=False):
        """An image's pixels as RGBA ((w·h, 4) float32, row 0 at the bottom; 8-bit sRGB values
        still encoded; grey images repeated, alpha 1 where there is none), its size and whether
        it is 8-bit sRGB; None when it has no pixels (a missing file). With `keep` (node graphs,
        which may read an image several times) they stay for the rest of the export."""
        if img.name in self.pixels:
            return self.pixels[img.name]
        w, h = img.size
        if w == 0 or h == 0 or not img.has_data and not _load(img):
            return None
        w, h = img.size
        buf = np.empty(w * h * img.channels, np.float32)
        img.pixels.foreach_get(buf)
        px = buf.reshape(-1, img.channels)
        rgba = np.ones((len(px), 4), np.float32)
        rgba[:, :3] = px[:, :3] if img.channels >= 3 else px[:, :1]
        if img.channels == 4:
            rgba[:, 3] = px[:, 3]
        read = (rgba, w, h, img.colorspace_settings.name == "sRGB" and not img.is_float)
        if keep:
            self.pixels[img.name] = read
        return read

    def add_graph(self, sock, warnings, what):
        """The linked input `sock` through a graph of colour and value nodes over image
        textures (texture_graph.py): ('texture', index) of the evaluated texture,
        ('constant', value) when no image feeds it, or None (warned) when the graph has a
        node the evaluator does not render. Evaluated once per material, node and socket."""
        from .texture_graph import current_object

        key = (what, sock.node.name, sock.identifier, current_object())
        if key not in self.graphs:
            self.graphs[key] = self._evaluate_graph(sock, warnings, what)
        return self.graphs[key]

    def _evaluate_graph(self, sock, warnings, what):
        """`add_graph`, evaluated."""
        from . import texture_graph

        uv_keys = {}

        def uv_key(node):
            if node.name not in uv_keys:
                closest = node.interpolation == "Closest"
                uv_keys[node.name] = (_uv_transform(node, warnings, what), node.extension, closest)
            return uv_keys[node.name]

        def image_identity(node):
            """The file and its time stamp for an image read from disk and not edited since;
            else a hash of its pixels."""
            import bpy

            img = node.image
            path = bpy.path.abspath(img.filepath) if img.source == "FILE" and img.packed_file is None else ""
            if path and not img.is_dirty and os.path.isfile(path):
                return (img.name, path, os.path.getmtime(path), tuple(img.size), img.colorspace_settings.name)
            px = image_pixels(node)[0]
            return (img.name, hashlib.blake2b(px.tobytes(), digest_size=16).digest(), tuple(img.size),
                    img.colorspace_settings.name)

        def image_pixels(node):
            read = self.rgba(node.image, keep=True)
            if read is None:
                raise texture_graph.Unsupported(f"image '{node.image.name}' has no pixels (missing file "
                                                f"'{node.image.filepath}'?)")
            return read

        node = sock.node
        try:
            r = texture_graph.evaluate(sock, image_pixels, uv_key, image_identity, _procedural_coordinates)
        except texture_graph.Unsupported as e:
            warnings.append(f"{what}: input '{sock.name}' of node '{node.name}' is linked through {e}, which "
                            f"GDMLT does not evaluate; its unlinked value is used")
            return None
        if r[0] == "constant":
            return r
        if r[0] == "procedural":
            _, table, spec = r
            self.items.append(scenedict.texture(f"{what}: {node.name} › {sock.name}", table, len(table), 1,
                                                extension="EXTEND", srgb=False))
            self.items[-1]["procedural"] = spec
            self.spaces[len(self.items) - 1] = spec["space"]
            return ("texture", len(self.items) - 1)
        _, rgb, w, h, transform, ext, closest = r
        if ext not in ("REPEAT", "EXTEND", "CLIP", "MIRROR"):
            ext = "REPEAT"
        self.items.append(scenedict.texture(f"{what}: {node.name} › {sock.name}", rgb, w, h,
                                            interpolation="Closest" if closest else "Linear",
                                            extension=ext, srgb=False))
        if transform is not None:
            self.items[-1]["transform"] = transform
        return ("texture", len(self.items) - 1)


def _mapping_on(link, is_source):
    """The Mapping node of a texture's Vector `link` when it is one GDMLT renders (Point,
    Texture or Vector type, its parameters unlinked) fed by `is_source` (the texture's own
    coordinates); else None."""
    m = link.from_node
    if m.type == "MAPPING" and m.vector_type in ("POINT", "TEXTURE", "VECTOR") and m.inputs["Vector"].is_linked \
            and is_source(m.inputs["Vector"].links[0]) \
            and not any(m.inputs[k].is_linked for k in ("Location", "Rotation", "Scale") if k in m.inputs):
        return m
    return None


def _mapping_matrix(m):
    """A Mapping node's (Point, Texture or Vector type; parameters unlinked) affine map of
    vectors as (3×3 linear part, translation)."""
    from mathutils import Euler, Matrix, Vector

    rot = Euler(tuple(m.inputs["Rotation"].default_value), "XYZ").to_matrix()
    scale = Vector(tuple(m.inputs["Scale"].default_value))
    loc = Vector(tuple(m.inputs["Location"].default_value)) if m.vector_type != "VECTOR" else Vector((0, 0, 0))
    if m.vector_type == "TEXTURE":  # the inverse of Point: (R⁻¹·(v − L)) / S
        inv_s = Matrix.Diagonal(tuple(1.0 / x if abs(x) > 1e-12 else 0.0 for x in scale))
        lin = inv_s @ rot.transposed()
        return lin, -(lin @ loc)
    return rot @ Matrix.Diagonal(tuple(scale)), loc  # Point (and Vector without location): R·(v ⊙ S) + L


def _procedural_coordinates(node):
    """What a procedural texture's Vector input reads, for the core: (space, row-major 3×4
    matrix): unlinked or a Texture Coordinate's Generated output: the mesh's
    Generated coordinates; its Object output (of the object itself): Object coordinates; its
    UV output or a UV Map node: the active render UV map (space 'UV'); a Mapping node on
    those maps them. Anything else raises texture_graph.Unsupported."""
    from . import texture_graph

    identity = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    sock = node.inputs["Vector"]
    if not sock.is_linked:
        return ("GENERATED", identity)

    def source(link):
        n, out = link.from_node, link.from_socket.name
        if n.type == "UVMAP" or n.type == "TEX_COORD" and out == "UV":
            return "UV"
        if n.type == "TEX_COORD" and out == "Generated":
            return "GENERATED"
        if n.type == "TEX_COORD" and out == "Object" and getattr(n, "object", None) is None:
            return "OBJECT"
        return None

    link = sock.links[0]
    found = source(link)
    if found is not None:
        return (found, identity)
    m = _mapping_on(link, lambda l: source(l) is not None)
    if m is None:
        raise texture_graph.Unsupported(f"the Vector input of '{node.name}' ({link.from_node.type}; supported: "
                                        f"Generated, Object, UV, and a Mapping node on those)")
    lin, t = _mapping_matrix(m)
    found = source(m.inputs["Vector"].links[0])
    return (found, tuple(float(x) for r in range(3) for x in (*lin[r], t[r])))


def _uv_transform(node, warnings, what):
    """The affine map of UV coordinates an Image Texture's Vector input applies, as the core's
    texture transform (m0..m5: u' = m0·u + m1·v + m2, v' = m3·u + m4·v + m5): None for the
    active UV map (unlinked, a Texture Coordinate's UV, a UV Map node), the matrix of a Mapping
    node (Point, Texture or Vector type, unlinked parameters) on those. Anything else uses the
    active UV map, with a warning."""
    sock = node.inputs["Vector"]
    if not sock.is_linked:
        return None

    def uv_source(link):
        n = link.from_node
        if n.type == "TEX_COORD" and link.from_socket.name == "UV":
            return True
        if n.type == "UVMAP":
            if n.uv_map:
                warnings.append(f"{what}: UV Map node '{n.name}' ('{n.uv_map}') is read as the active render UV map")
            return True
        return False

    link = sock.links[0]
    if uv_source(link):
        return None
    m = _mapping_on(link, uv_source)
    if m is not None:
        lin, t = _mapping_matrix(m)
        return (lin[0][0], lin[0][1], t[0], lin[1][0], lin[1][1], t[1])
    warnings.append(f"{what}: the Vector input of texture '{node.name}' ({link.from_node.type}) is not supported; the active "
                    f"render UV map is used (supported: UV, UV Map, and a Mapping node on those)")
    return None


def _load(img):
    try:
        img.reload()
    except RuntimeError:
        return False
    return img.has_data and img.size[0] > 0


def _linked_texture(sock, textures, warnings, what, output="Color"):
    """If input socket `sock` is fed by an Image Texture's `output` (Color, or Alpha: then
    the texture of its alpha channel), its texture index."""
    if sock is None or not sock.is_linked or textures is None:
        return None
    link = sock.links[0]
    src = link.from_node
    if src.type != "TEX_IMAGE" or link.from_socket.name != output:
        return None
    return textures.add(src, warnings, what, alpha=output == "Alpha")


def _input_texture(node, name, textures, warnings, what, output="Color"):
    """Input `name` of `node` as a texture: an Image Texture's `output` linked straight in, or
    colour and value nodes over images (texture_graph.py) — its index; None when it is not
    linked that way (unlinked, a constant graph: `_input_value` reads those); False when the
    graph cannot be evaluated (warned: the input keeps its unlinked value)."""
    return _socket_texture(node.inputs.get(name), textures, warnings, what, output)


def _socket_texture(sock, textures, warnings, what, output="Color"):
    """`_input_texture` of an input socket."""
    tex = _linked_texture(sock, textures, warnings, what, output)
    if tex is not None:
        return tex
    if sock is None or not sock.is_linked or textures is None:
        return None
    r = textures.add_graph(sock, warnings, what)
    if r is None:
        return False
    return r[1] if r[0] == "texture" else None


def _color_or_texture(node, name, out, key, textures, warnings, what, default):
    """Sets out[key] from an unlinked colour or value input (or a constant graph), or
    out[key + '_texture'] from an image or a graph of nodes over images; a value texture
    (`key` other than base_color) also sets out[key] to its mean, which mixes of shaders use.
    A base colour from a colour attribute (alone, or multiplied with an image) sets
    out['vertex_color'] and the attribute's name as out['vertex_color_layer']."""
    if key == "base_color" and _vertex_colour(node.inputs[name], out, textures, warnings, what):
        return
    tex = _input_texture(node, name, textures, warnings, what)
    if tex is False:
        v = node.inputs[name].default_value
    elif tex is not None:
        out[key + "_texture"] = tex
        if key != "base_color":
            from .texture_graph import LUMA

            px = np.asarray(textures.items[tex]["pixels"]).reshape(-1, 3)[::7]  # (a sample is enough)
            out[key] = float(np.clip(px @ LUMA, 0.0, 1.0).mean())
        return
    else:
        v = _input_value(node, name, warnings, what, default)  # (warns if linked to something else)
    out[key] = tuple(v)[:3] if key == "base_color" else float(v)


def _output_node(tree, warnings=None, what=""):
    """The tree's Cycles output node as a view of the flattened tree (node groups inlined:
    node_view.py), or None. Links Blender marks invalid (a loop, or sockets that do not
    connect) carry nothing, as in Cycles: each is named in a warning."""
    node_out = tree.get_output_node("CYCLES") if tree is not None else None
    if node_out is None:
        return None
    if warnings is not None:
        _warn_invalid_links(tree, warnings, what, set())
    return NodeView(node_out)


def _warn_invalid_links(tree, warnings, what, seen):
    """A warning for every invalid link of `tree` and of the node groups it uses."""
    if tree.name in seen:
        return
    seen.add(tree.name)
    for link in tree.links:
        if not getattr(link, "is_valid", True):
            warnings.append(f"{what}: the link from '{link.from_node.name}' to '{link.to_node.name}' is invalid "
                            f"(a loop, or sockets that do not connect) and is left out, as Cycles leaves it")
    for node in tree.nodes:
        if node.type == "GROUP" and node.node_tree is not None:
            _warn_invalid_links(node.node_tree, warnings, what, seen)


def _colour_attribute(sock):
    """The name of the colour attribute feeding input socket `sock` ('' = the mesh's
    default one: a Color Attribute node without a name), or None."""
    if not sock.is_linked:
        return None
    link = sock.links[0]
    n, out = link.from_node, link.from_socket
    if n.type == "VERTEX_COLOR" and out.name == "Color":
        return n.layer_name
    if n.type == "ATTRIBUTE" and n.attribute_type == "GEOMETRY" and out.name == "Color" and n.attribute_name:
        return n.attribute_name
    return None


def _vertex_colour(sock, out, textures, warnings, what):
    """A base colour `sock` fed by a colour attribute, alone or as one factor of a Mix ›
    Multiply at factor 1 (the other an image, a graph over images or a constant): sets out's
    vertex colour keys and the other factor as the base colour (white when alone); False
    when `sock` is fed otherwise."""
    layer = _colour_attribute(sock)
    if layer is not None:
        out["base_color"], out["vertex_color"], out["vertex_color_layer"] = (1.0, 1.0, 1.0), True, layer
        return True
    if not sock.is_linked or textures is None:
        return False
    mix = sock.links[0].from_node
    if not (mix.type == "MIX" and mix.data_type == "RGBA" and mix.blend_type == "MULTIPLY"
            and sock.links[0].from_socket.identifier == "Result_Color"):
        return False
    ins = {s.identifier: s for s in mix.inputs}
    fac = ins["Factor_Float"]
    if fac.is_linked or abs(fac.default_value - 1.0) > 1e-6:
        return False
    a, b = ins["A_Color"], ins["B_Color"]
    layer, other = next(((_colour_attribute(s), o) for s, o in ((a, b), (b, a)) if _colour_attribute(s) is not None),
                        (None, None))
    if layer is None:
        return False
    out["vertex_color"], out["vertex_color_layer"] = True, layer
    tex = _socket_texture(other, textures, warnings, what)
    if tex is not None and tex is not False:
        out["base_color_texture"], out["base_color"] = tex, (1.0, 1.0, 1.0)
    else:
        v = other.default_value if tex is False else _socket_value(other, warnings, what, (0.8, 0.8, 0.8, 1.0))
        out["base_color"] = tuple(v)[:3]
    return True


def material_params(mat, warnings, textures=None):
    """Principled-like parameters of a Blender material (nodes followed from the Cycles output).
    `textures`: a Textures registry; image textures linked into Base Color / Color and
    Roughness are added to it. Mix Shader and Add Shader trees of supported nodes are
    flattened into one weighted set of lobes (see _combine)."""
    if mat is None:
        return dict(DEFAULT_SURFACE)
    what = f"material '{mat.name}'"
    out = dict(DEFAULT_MATERIAL, name=mat.name)
    if mat.pass_index:
        out["pass_index"] = mat.pass_index  # the IndexMA pass
    if not getattr(getattr(mat, "cycles", None), "use_bump_map_correction", True):
        out["bump_map_correction"] = False
    node_out = _output_node(mat.node_tree, warnings, what)
    if node_out is None:
        c = tuple(mat.diffuse_color)[:3]
        out["base_color"] = c
        return out
    surface = node_out.inputs.get("Surface")
    volume = node_out.inputs.get("Volume")
    if volume is not None and volume.is_linked:
        medium = _volume(volume.links[0].from_node, 1.0, warnings, what, textures)
        if medium is not None:
            out["volume"] = medium
    if (surface is None or not surface.is_linked) and volume is not None and volume.is_linked:
        # Cycles' rule: a material with a Volume output and no Surface is the boundary of a
        # medium, which every ray passes unchanged (camera, scattered and shadow rays, and in
        # alpha): a clear Transparent BSDF (one transparent bounce per crossing, where Cycles
        # counts crossings apart, up to 1024), the medium inside it.
        clear = dict(DEFAULT_MATERIAL, base_color=(0.0, 0.0, 0.0), **{"pass": (1.0, 1.0, 1.0)})
        return {**out, **_leaves_material([(1.0, clear)], False, warnings, what)}
    _warn_unrendered_outputs(node_out, warnings, what, skip=("Displacement", "Volume"))
    if surface is None or not surface.is_linked:
        out["base_color"] = (0.0, 0.0, 0.0)  # Cycles renders an unconnected surface black
        return out
    displaced = _displacement_bump(mat, node_out, textures, warnings, what)
    node = surface.links[0].from_node
    blend = _factored_mix(node, textures, warnings, what)
    if blend is None:
        leaves = []
        _shader_leaves(node, 1.0, leaves, textures, warnings, what)
        out.update(_leaves_material(leaves, node.type in ("MIX_SHADER", "ADD_SHADER"), warnings, what))
    else:
        out.update(_blend_material(node, blend, textures, warnings, what))
    if displaced and "bump_texture" in out:
        warnings.append(f"{what}: its displacement and a Bump node both bump the normal; only the Bump node's "
                        f"is rendered")
    elif displaced:
        out.update(displaced)
    return out


def _volume(node, weight, warnings, what, textures=None):
    """The homogeneous medium of a Volume output's shader tree — Principled Volume, Volume
    Scatter and Volume Absorption, summed through Add Shader and weighted through Mix Shader —
    as the core's volume dict (coefficients per unit distance, as Cycles' volume closures:
    Principled Volume's scattering Color × Density and absorption (1 − Color)(1 − √Absorption
    Color) × Density; Volume Scatter's Color × Density; Volume Absorption's (1 − Color) ×
    Density; emission Strength × Color). None when it holds nothing.

    A Density from a procedural texture graph (a Noise Texture, a Color Ramp or Math after it)
    makes a heterogeneous medium (smoke): its coefficients per unit density and
    "density": {"texture": index} — the object's coordinates are added per object
    (`_density_coordinates`). One such density per material; other volume shaders beside
    it, a second textured density and a colour from a texture are taken at their unlinked
    values, with a warning."""
    acc = {"scattering": [0.0] * 3, "absorption": [0.0] * 3, "emission": [0.0] * 3}
    g_weighted = [0.0]
    field = {}
    _volume_leaves(node, weight, acc, g_weighted, warnings, what, set(), textures, field)
    if "texture" in field:
        constant = [x for k in ("scattering", "absorption") for x in acc[k]]
        if any(x > 0.0 for x in constant):
            warnings.append(f"{what}: a volume beside a density from a texture is left out (one density field "
                            f"per material)")
        acc["scattering"], acc["absorption"] = field["scattering"], field["absorption"]
        acc["emission"] = [a + b for a, b in zip(acc["emission"], field["emission"])]
        g_weighted = field.get("g_weighted", [0.0])
    if not any(x > 0.0 for v in acc.values() for x in v):
        return None
    s = sum(acc["scattering"])
    g = min(max(g_weighted[0] / s, -0.999), 0.999) if s > 0.0 else 0.0
    out = {**{k: tuple(v) for k, v in acc.items()}, "anisotropy": g}
    # one scattering leaf of another phase function keeps it; mixed with others, the mixture is
    # Henyey-Greenstein of their mean cosine
    phased = g_weighted[1:]
    if len(phased) == 1 and abs(phased[0][0] - s) <= 1e-6 * max(s, 1e-12):
        out.update(phased[0][1])
    elif phased:
        warnings.append(f"{what}: volume scattering of several phase functions is rendered as Henyey-Greenstein "
                        f"of their mean cosine")
    if "texture" in field:
        out["density"] = {"texture": field["texture"]}
    return out


def _phase_mean_cosine(params):
    """The mean cosine of a Rayleigh, Draine or Mie phase function (the core's `Phase`; Mie
    by Cycles' fit in the diameter, for mixing)."""
    from gdmlt import _core

    return _core.phase_mean_cosine(params["phase"], params.get("anisotropy", 0.0), params.get("alpha", 0.0),
                                   params.get("diameter", 0.0))


def _density_coordinates(volume, ob, matrix_world):
    """A heterogeneous medium's coordinates for object `ob` placed by `matrix_world`: world →
    Object (the inverse transform, 3×4) and Object → Generated (its texture space, the bounding
    box by default, to [0, 1]³ — Cycles' generated transform for volumes)."""
    inv = np.linalg.inv(np.array(matrix_world, dtype=np.float64))[:3].reshape(12)
    me = getattr(ob, "data", None)
    loc = np.array(getattr(me, "texspace_location", (0.0, 0.0, 0.0))[:], np.float64)
    size = np.array(getattr(me, "texspace_size", (1.0, 1.0, 1.0))[:], np.float64)
    size = np.where(size != 0.0, size, 1.0)
    scale = 1.0 / (2.0 * size)
    volume["density"]["world_to_object"] = [float(x) for x in inv]
    volume["density"]["generated"] = [float(x) for x in np.concatenate([scale, 0.5 - loc * scale])]


def _volume_leaves(node, weight, acc, g_weighted, warnings, what, seen, textures=None, field=None):
    while node is not None and node.type == "REROUTE":
        node = node.inputs[0].links[0].from_node if node.inputs[0].is_linked else None
    if node is None or weight <= 0.0 or node.name in seen:
        return
    seen = seen | {node.name}

    def value(name, default):
        return _input_value(node, name, warnings, what, default)

    def colour(name):
        c = value(name, (1.0, 1.0, 1.0, 1.0))
        return [max(float(x), 0.0) for x in tuple(c)[:3]]

    def add(key, c, scale):
        for i in range(3):
            acc[key][i] += weight * scale * c[i]

    if node.type == "ADD_SHADER":
        for sock in node.inputs:
            if sock.is_linked:
                _volume_leaves(sock.links[0].from_node, weight, acc, g_weighted, warnings, what, seen, textures, field)
        return
    if node.type == "MIX_SHADER":
        f = min(max(float(value("Fac", 0.5)), 0.0), 1.0)
        shaders = [sock for sock in node.inputs if sock.type == "SHADER"]
        for sock, w in zip(shaders, (1.0 - f, f)):
            if sock.is_linked:
                _volume_leaves(sock.links[0].from_node, weight * w, acc, g_weighted, warnings, what, seen, textures,
                               field)
        return
    if node.type not in ("PRINCIPLED_VOLUME", "VOLUME_SCATTER", "VOLUME_ABSORPTION"):
        warnings.append(f"{what}: volume shader node '{node.name}' ({node.type}) is not rendered (left out)")
        return
    density = _textured_density(node, weight, textures, field, warnings, what)
    if density is None:
        density = max(float(value("Density", 1.0)), 0.0)
    else:
        # (this leaf's coefficients are per unit of the field's density, and its phase
        # function's weight too)
        acc, g_weighted = field, field.setdefault("g_weighted", [0.0])
    color = colour("Color")
    if node.type in ("PRINCIPLED_VOLUME", "VOLUME_SCATTER"):
        g = min(max(float(value("Anisotropy", 0.0)), -0.999), 0.999)
        add("scattering", color, density)
        phase = getattr(node, "phase", "HENYEY_GREENSTEIN") if node.type == "VOLUME_SCATTER" else "HENYEY_GREENSTEIN"
        share = weight * density * sum(color)
        if phase in ("RAYLEIGH", "DRAINE", "MIE"):
            params = {"phase": phase.lower(), "anisotropy": g}
            if phase == "DRAINE":
                params["alpha"] = max(float(value("Alpha", 0.5)), 0.0)
            if phase == "MIE":
                params["diameter"] = max(float(value("Diameter", 20.0)), 0.0)
            g_weighted.append((share, params))
            g = _phase_mean_cosine(params)
        elif phase != "HENYEY_GREENSTEIN":
            warnings.append(f"{what}: the {phase.replace('_', '-').title()} phase function of '{node.name}' is "
                            f"rendered as Henyey-Greenstein with its anisotropy")
        g_weighted[0] += share * g
    if node.type == "VOLUME_ABSORPTION":
        add("absorption", [max(1.0 - c, 0.0) for c in color], density)
    if node.type == "PRINCIPLED_VOLUME":
        a = colour("Absorption Color")
        add("absorption", [max(1.0 - c, 0.0) * max(1.0 - x ** 0.5, 0.0) for c, x in zip(color, a)], density)
        strength = max(float(value("Emission Strength", 0.0)), 0.0)
        if strength > 0.0:
            add("emission", colour("Emission Color"), strength)
        blackbody = float(value("Blackbody Intensity", 0.0))
        if blackbody > 1e-3:
            # Cycles' blackbody emission: tint × σ·mix(1, T⁴, intensity) × the blackbody colour
            # of T (Stefan–Boltzmann's σ scaled by 10⁻⁶/π, as Cycles' closure)
            from .blackbody import colour as blackbody_colour

            t = max(float(value("Temperature", 1000.0)), 0.0)
            sigma = 5.670373e-8 * 1e-6 / math.pi
            rgb = blackbody_colour([t])[0]
            tint = colour("Blackbody Tint")
            add("emission", [a * float(c) for a, c in zip(tint, rgb)], sigma * (1.0 + (t ** 4 - 1.0) * blackbody))
        for attr in ("Density Attribute", "Color Attribute", "Temperature Attribute"):
            sock = node.inputs.get(attr)
            if sock is not None and sock.is_linked:
                warnings.append(f"{what}: '{node.name}' reads {attr} from a grid; grids are not rendered yet")


def _textured_density(node, weight, textures, field, warnings, what):
    """1.0 when the leaf's Density comes from a procedural texture graph that becomes the
    material's density field (`field["texture"]`; its coefficient sums start here), else
    None (the density is the socket's value)."""
    sock = node.inputs.get("Density")
    if field is None or textures is None or sock is None or not sock.is_linked:
        return None
    tex = _socket_texture(sock, textures, warnings, what)
    if not isinstance(tex, int) or isinstance(tex, bool):
        return None
    if "procedural" not in textures.items[tex]:
        warnings.append(f"{what}: the density of '{node.name}' comes from an image, which a volume cannot read "
                        f"(no UV map inside it); its mean is used")
        return None
    if "texture" in field and field["texture"] != tex:
        warnings.append(f"{what}: a second density texture ('{node.name}') is taken at its unlinked value (one "
                        f"density field per material)")
        return None
    if "texture" not in field:
        field.update({"texture": tex, "scattering": [0.0] * 3, "absorption": [0.0] * 3, "emission": [0.0] * 3})
    return 1.0


def _leaves_material(leaves, mixed, warnings, what):
    """The material parameters of weighted shader leaves: one opaque leaf's own, else their
    combination (`_combine`) — a Mix/Add Shader tree (`mixed`) or a leaf with pass-through.
    Holdout leaves: all of the material, a holdout; a share of it, left out (the rest keeps
    its weight, so to rays other than the camera's the held share is black, as in Cycles),
    with a warning."""
    held = sum(w for w, p in leaves if p.get("holdout"))
    if held >= 1.0 - 1e-6:
        return {"base_color": (0.0, 0.0, 0.0), "holdout": True}
    if held > 0.0:
        warnings.append(f"{what}: a Holdout mixed with other shaders is not held out (its share, {held:.2f}, "
                        f"renders black)")
        leaves = [(w, p) for w, p in leaves if not p.get("holdout")]
        if not leaves:
            return {"base_color": (0.0, 0.0, 0.0)}
    if not mixed and len(leaves) == 1 and leaves[0][0] == 1.0 and "pass" not in leaves[0][1]:
        p = dict(leaves[0][1])  # one shader node, opaque: its own parameters
        p.pop("bsdf", None)
        return p
    if any(p.get("vertex_color") for _, p in leaves):
        warnings.append(f"{what}: a colour attribute inside a Mix/Add Shader is not rendered (its factor "
                        f"is taken as white)")
    return _combine(leaves, warnings, what)


def _factored_mix(node, textures, warnings, what):
    """The first Mix Shader of the shader tree under `node` (depth first, first shaders
    first) whose Fac the core computes per point: (its name, the material keys of the
    factor) — `blend_texture` for an image or procedural texture (or colour and value nodes
    over one), `blend_ray` for a Fresnel or Layer Weight node (their Normal unlinked), a
    Light Path's Is Shadow Ray or Is Camera Ray, or Geometry › Backfacing; None without one."""
    stack, seen = [node], set()
    while stack:
        n = stack.pop()
        if n.name in seen:
            continue
        seen.add(n.name)
        if n.type == "MIX_SHADER" and n.inputs[0].is_linked:
            keys = _mix_factor(n.inputs[0], textures, warnings, what)
            if keys is not None:
                return n.name, keys
        if n.type in ("MIX_SHADER", "ADD_SHADER"):
            first = 1 if n.type == "MIX_SHADER" else 0
            shaders = (n.inputs[first + 1], n.inputs[first])  # (the first shader on top of the stack)
            stack.extend(s.links[0].from_node for s in shaders if s.is_linked)
    return None


def _mix_factor(fac, textures, warnings, what):
    """The material keys of a linked Mix Shader factor the core computes per point, or None
    (then the factor keeps its unlinked value, warned by `_shader_leaves`)."""
    link = fac.links[0]
    src, out = link.from_node, link.from_socket.identifier
    if (src.type, out) in _KIND_FACTORS:
        return {"blend_ray": (_KIND_FACTORS[(src.type, out)], 0.0)}
    view = _RAY_NODES.get((src.type, out))
    if view is not None:
        kind, name, default = view
        if src.inputs["Normal"].is_linked:
            warnings.append(f"{what}: the Normal input of '{src.name}' is not read (the surface normal is used)")
        value = src.inputs[name]
        if value.is_linked:
            return None
        return {"blend_ray": (kind, float(_socket_value(value, warnings, what, default)))}
    ray = _ray_curve(fac, warnings, what)
    if ray is not None:
        return ray
    if textures is None:
        return None
    tex = _socket_texture(fac, textures, [], what)
    return {"blend_texture": tex} if tex is not None and tex is not False else None


def _ray_curve(fac, warnings, what):
    """A Mix Shader factor of colour and value nodes over a Fresnel or Layer Weight node (a
    Color Ramp on Facing, say): that node's factor and the nodes after it tabulated over its
    output (`blend_ray_curve`); None for another graph."""
    from . import texture_graph

    try:
        r = texture_graph.evaluate_ray(fac)
    except texture_graph.Unsupported:
        return None
    if r is None:
        return None
    (src, out), table = r
    if (src.type, out) in _KIND_FACTORS:  # (a factor of 0 or 1: the curve's two ends)
        return {"blend_ray": (_KIND_FACTORS[(src.type, out)], 0.0), "blend_ray_curve": table.tolist()}
    kind, name, default = _RAY_NODES[(src.type, out)]
    if src.inputs["Normal"].is_linked:
        warnings.append(f"{what}: the Normal input of '{src.name}' is not read (the surface normal is used)")
    if src.inputs[name].is_linked:
        return None
    return {"blend_ray": (kind, float(_socket_value(src.inputs[name], warnings, what, default))),
            "blend_ray_curve": table.tolist()}


# Outputs that are 0 or 1 by the ray's kind or side, as the core's ray factors
_KIND_FACTORS = {("NEW_GEOMETRY", "Backfacing"): "BACKFACING", ("LIGHT_PATH", "Is Camera Ray"): "CAMERA_RAY",
                 ("LIGHT_PATH", "Is Shadow Ray"): "SHADOW_RAY"}
# Fresnel and Layer Weight outputs as the core's ray factors: (kind, the node's input, its default)
_RAY_NODES = {("FRESNEL", "Fac"): ("FRESNEL", "IOR", 1.45), ("LAYER_WEIGHT", "Fresnel"): ("LAYER_FRESNEL", "Blend", 0.5),
              ("LAYER_WEIGHT", "Facing"): ("LAYER_FACING", "Blend", 0.5)}


def _blend_material(node, blend, textures, warnings, what):
    """A shader tree whose Mix Shader `blend` = (name, factor keys) takes its factor f from a
    texture or the view (`_mix_factor`): the material at f = 0 blending into the one at
    f = 1 by that factor (the core's `MaterialDesc::blend`, mixed lobe by lobe per point). Every leaf's weight is
    affine in f, so the two ends' mixtures blended by f are the tree's mixture at f (their
    emission too). The shading normal is one per point: normal and bump maps come from the
    f = 0 end (warned where the ends differ)."""
    name, factor = blend
    ends = []
    for f in (0.0, 1.0):
        leaves, said = [], []
        _shader_leaves(node, 1.0, leaves, textures, said, what, fixed={name: f})
        warnings.extend(w for w in said if w not in warnings)
        ends.append(_leaves_material(leaves, False, warnings, what)
                    if leaves else {"base_color": (0.0, 0.0, 0.0)})
    a, b = ends
    if a.pop("holdout", False) | b.pop("holdout", False):
        warnings.append(f"{what}: a Holdout under Mix Shader '{name}' (its factor per point) is not held out "
                        f"(it renders black)")
    if any(a.get(k) != b.get(k) for k in NORMAL_KEYS):
        warnings.append(f"{what}: Mix Shader '{name}' mixes normal or bump maps by a texture; GDMLT renders "
                        f"those of its first shader's side only")
    if b.get("vertex_color") and not a.get("vertex_color"):
        warnings.append(f"{what}: a colour attribute under Mix Shader '{name}''s second shader is not rendered")
        b.pop("vertex_color", None)
    b.pop("vertex_color_layer", None)
    drop = ["pass_index", *NORMAL_KEYS]
    if "blend_ray" in factor and factor["blend_ray"][0] != "CAMERA_RAY":
        # (the core blends emission by a texture, or by Is Camera Ray: the camera sees the second's)
        drop += ["emission", "emission_texture"]
        if any(a.get(k) != b.get(k) for k in ("emission", "emission_texture")) and any(
                max(p.get("emission", (0, 0, 0))) > 0 for p in (a, b)):
            warnings.append(f"{what}: Mix Shader '{name}' mixes emission by the ray (its direction or kind); GDMLT renders its first "
                            f"shader's emission only")
    for k in drop:
        b.pop(k, None)
    return dict(a, blend=b, **factor)


def _displacement_bump(mat, node_out, textures, warnings, what):
    """Material Output › Displacement fed by a Displacement node whose Height is an image or a
    graph over images: as Cycles renders it with the material's default method, Bump Only —
    the normal of the surface displaced by (Height − Midlevel)·Scale along it, which to first
    order is a bump of distance Scale (object space taken as world space: the object's own
    scale is not applied). True displacement is rendered so too, with a warning. Returns the
    bump's material keys, or None."""
    sock = node_out.inputs.get("Displacement")
    if sock is None or not sock.is_linked:
        return None
    node = sock.links[0].from_node
    if node.type != "DISPLACEMENT" or textures is None:
        warnings.append(f"{what}: its Displacement output ({node.type}) is not rendered (supported: a "
                        f"Displacement node over images, rendered as bump)")
        return None
    method = getattr(mat, "displacement_method", "BUMP")
    if method != "BUMP":
        warnings.append(f"{what}: displacement method {method} is rendered as Bump Only (the mesh is not "
                        f"displaced)")
    if node.inputs["Normal"].is_linked:
        warnings.append(f"{what}: the Normal input of Displacement '{node.name}' is not read (the surface "
                        f"normal is used)")
    bump = {}
    _bump_height(node, bump, textures, warnings, what, float(_input_value(node, "Scale", warnings, what, 1.0)), 1.0)
    return bump or None


def _node_params(node, textures, warnings, what):
    """Parameters of one shader node (a leaf of the shader tree)."""
    out = dict(DEFAULT_MATERIAL)
    del out["name"]
    t = node.type
    if t == "BSDF_PRINCIPLED":
        _color_or_texture(node, "Base Color", out, "base_color", textures, warnings, what, (0.8, 0.8, 0.8, 1))
        _color_or_texture(node, "Metallic", out, "metallic", textures, warnings, what, 0.0)
        _color_or_texture(node, "Roughness", out, "roughness", textures, warnings, what, 0.5)
        out["diffuse_roughness"] = _unit(_input_value(node, "Diffuse Roughness", warnings, what, 0.0))
        out["ior"] = _input_value(node, "IOR", warnings, what, 1.5)
        out["specular_ior"] = _specular_layer_ior(out["ior"], _input_value(node, "Specular IOR Level", warnings,
                                                                           what, 0.5))
        out["transmission"] = _input_value(node, "Transmission Weight", warnings, what, 0.0)
        if out["transmission"] > 0:
            # as Cycles: its glass reflects with the Specular Tint (white; warned when set) and
            # transmits √(base colour) at each interface, so that light entering and leaving
            # takes the base colour once — a Glass BSDF tints both by its colour
            out["glass_reflection_tint"] = (1.0, 1.0, 1.0)
            out["glass_sqrt_tint"] = True
        _warn_unsupported_layers(node, warnings, what)
        _subsurface(node, out, warnings, what)
        _specular_tint(node, out, warnings, what)
        _emission(node, "Emission Color", "Emission Strength", out, textures, warnings, what, (0, 0, 0, 1), 0.0)
        _coat(node, out, warnings, what)
        # (the image's alpha channel, or nodes over images: a Math on the alpha, a Color Ramp)
        alpha_tex = _input_texture(node, "Alpha", textures, warnings, what, output="Alpha")
        if alpha_tex is False:
            out["alpha"] = _unit(node.inputs["Alpha"].default_value)
        elif alpha_tex is not None:  # coverage from the image's alpha channel, per shading point
            out["alpha_texture"], out["alpha"] = alpha_tex, 1.0
        else:
            out["alpha"] = min(max(_input_value(node, "Alpha", warnings, what, 1.0), 0.0), 1.0)
    elif t == "SUBSURFACE_SCATTERING":
        # a subsurface closure alone: Color the albedo, entering through an interface of the
        # node's IOR and roughness (Cycles takes its Roughness as α, unsquared) without a
        # specular layer reflecting
        _color_or_texture(node, "Color", out, "base_color", textures, warnings, what, (0.8, 0.8, 0.8, 1))
        out["specular_ior"] = max(float(_input_value(node, "IOR", warnings, what, 1.4)), 1.0)
        out["specular"] = 0.0
        out["roughness"] = math.sqrt(_unit(_input_value(node, "Roughness", warnings, what, 1.0)))
        _subsurface(node, out, warnings, what, weight=1.0)
    elif t == "BSDF_TRANSLUCENT":
        # diffuse transmission towards the far side (its colour a constant)
        out["base_color"] = (0.0, 0.0, 0.0)
        out["translucency"] = 1.0
        out["translucent_color"] = tuple(_input_value(node, "Color", warnings, what, (0.8, 0.8, 0.8, 1))[:3])
    elif t == "BSDF_TRANSPARENT":
        out["base_color"] = (0.0, 0.0, 0.0)
        out["pass"] = tuple(_input_value(node, "Color", warnings, what, (1, 1, 1, 1))[:3])
    elif t == "BSDF_DIFFUSE":
        _color_or_texture(node, "Color", out, "base_color", textures, warnings, what, (0.8, 0.8, 0.8, 1))
        out["roughness"] = 1.0
        # (Cycles: Oren–Nayar above 0, its Lambertian at 0)
        out["diffuse_roughness"] = _unit(_input_value(node, "Roughness", warnings, what, 0.0))
    elif t == "BSDF_GLOSSY" or t == "BSDF_ANISOTROPIC":
        _color_or_texture(node, "Color", out, "base_color", textures, warnings, what, (0.8, 0.8, 0.8, 1))
        _color_or_texture(node, "Roughness", out, "roughness", textures, warnings, what, 0.5)
        out["metallic"] = 1.0
        out["metal_constant_fresnel"] = True  # (Cycles' Glossy BSDF reflects its colour at every angle)
        if t == "BSDF_ANISOTROPIC":
            warnings.append(f"{what}: anisotropy is ignored (rendered as isotropic glossy)")
    elif t == "BSDF_GLASS" or t == "BSDF_REFRACTION":
        _color_or_texture(node, "Color", out, "base_color", textures, warnings, what, (1, 1, 1, 1))
        out["ior"] = _input_value(node, "IOR", warnings, what, 1.5)
        _color_or_texture(node, "Roughness", out, "roughness", textures, warnings, what, 0.0)
        out["transmission"] = 1.0
        if t == "BSDF_REFRACTION":
            warnings.append(f"{what}: Refraction BSDF is rendered as Glass (with Fresnel reflection)")
    elif t == "EMISSION":
        _emission(node, "Color", "Strength", out, textures, warnings, what, (1, 1, 1, 1), 1.0)
        out["base_color"] = (0.0, 0.0, 0.0)
        out["bsdf"] = False  # no scattering lobe (matters inside Mix/Add Shaders)
    elif t == "HOLDOUT":
        # transparent black where the camera sees it; to other rays no lobe: black
        out["base_color"] = (0.0, 0.0, 0.0)
        out["bsdf"] = False
        out["holdout"] = True
    else:
        warnings.append(f"{what}: shader node '{node.name}' ({t}) is not supported; rendered as grey diffuse")
    _normal_map(node, out, textures, warnings, what)
    if out.get("coat", 0.0) > 0.0 and ("normal_texture" in out or "bump_texture" in out):
        kind = "normal map" if "normal_texture" in out else "bump map"
        warnings.append(f"{what}: the coat of '{node.name}' follows its {kind} (Cycles' coat keeps the "
                        f"unmapped normal unless its Coat Normal is linked)")
    if t in ("BSDF_PRINCIPLED", "BSDF_GLOSSY", "BSDF_ANISOTROPIC", "BSDF_GLASS", "BSDF_REFRACTION"):
        # Multiscatter GGX (Blender's default) compensates the energy the metal and glass lobes
        # lose to single scattering (the Refraction BSDF has no such option)
        distribution = getattr(node, "distribution", "GGX")
        out["multiscatter"] = distribution == "MULTI_GGX"
        if distribution not in ("GGX", "MULTI_GGX"):
            # (measured: a Beckmann glossy ball of roughness 0.5 renders about 2% dark as GGX)
            warnings.append(f"{what}: the {distribution.replace('_', '-').title()} distribution of "
                            f"'{node.name}' is rendered as GGX")
    return out


def _normal_map(node, out, textures, warnings, what):
    """A Normal input fed by a Bump node (its Height an image, or a graph of colour and value
    nodes over images: out['bump_texture'], bump_distance and bump_strength) and/or a Normal
    Map node (Tangent Space, the active UV map) whose Color comes from an Image Texture
    (out['normal_texture'] and out['normal_strength']); a Bump node's own Normal input may be
    such a Normal Map (the core applies the normal map, then the bump around it, as Cycles).
    Anything else linked there is ignored, with a warning."""
    sock = node.inputs.get("Normal")
    if sock is None or not sock.is_linked:
        return
    nm = sock.links[0].from_node
    if nm.type == "BUMP" and textures is not None:
        _bump(nm, out, textures, warnings, what)
        sock = nm.inputs["Normal"]
        if not sock.is_linked:
            return
        node, nm = nm, sock.links[0].from_node
    if nm.type == "NORMAL_MAP" and nm.space == "TANGENT" and textures is not None:
        if nm.uv_map:
            warnings.append(f"{what}: Normal Map '{nm.name}' UV map '{nm.uv_map}' is not read; the active "
                            f"render UV map is used")
        tex = _linked_texture(nm.inputs["Color"], textures, warnings, what)
        if tex is not None:
            out["normal_texture"] = tex
            out["normal_strength"] = max(float(_input_value(nm, "Strength", warnings, what, 1.0)), 0.0)
            return
    warnings.append(f"{what}: the Normal input of '{node.name}' ({nm.type}"
                    f"{' ' + nm.space if nm.type == 'NORMAL_MAP' else ''}) is not supported; the mesh normal is used "
                    f"(supported: a Bump node over images, a tangent-space Normal Map fed by an Image Texture)")


def _bump(node, out, textures, warnings, what):
    """A Bump node whose Height is an image's luminance or a graph over images: the height
    map, Distance (negated by Invert) and Strength, as Cycles bumps the normal (its Filter
    Width, a finite-difference step of a tenth of a pixel, is the limit the core computes
    exactly). A constant height bumps nothing."""
    distance = float(_input_value(node, "Distance", warnings, what, 1.0))
    _bump_height(node, out, textures, warnings, what, -distance if node.invert else distance,
                 _unit(_input_value(node, "Strength", warnings, what, 1.0)))


def _bump_height(node, out, textures, warnings, what, distance, strength):
    """out's bump keys from the Height input of `node` (an image's luminance, or a graph of
    colour and value nodes over images), unless that height is constant."""
    tex = _input_texture(node, "Height", textures, warnings, what)
    if tex is not None and tex is not False:
        out.update(bump_texture=tex, bump_distance=distance, bump_strength=strength)


def _emission(node, color, strength, out, textures, warnings, what, default_color, default_strength):
    """Emission colour × strength; with an Image Texture in the colour, the image per point
    (out['emission_texture']) times the strength."""
    s = _input_value(node, strength, warnings, what, default_strength)
    tex = _input_texture(node, color, textures, warnings, what)
    if tex is False:
        out["emission"] = tuple(c * s for c in node.inputs[color].default_value[:3])
    elif tex is not None:
        out["emission_texture"], out["emission"] = tex, (s, s, s)
    else:
        out["emission"] = tuple(c * s for c in _input_value(node, color, warnings, what, default_color)[:3])


def _specular_layer_ior(ior, level):
    from gdmlt.shading import specular_layer_ior  # (the core's package: the engine needs it anyway)

    return specular_layer_ior(ior, level)


# Principled inputs whose layers the core does not render: (input, value that means "off").
_UNSUPPORTED_LAYERS = (("Sheen Weight", 0.0), ("Anisotropic", 0.0), ("Thin Film Thickness", 0.0))


COAT_KEYS = ("coat", "coat_roughness", "coat_ior", "coat_tint")
NORMAL_KEYS = ("normal_texture", "normal_strength", "bump_texture", "bump_distance", "bump_strength")


def _coat(node, out, warnings, what):
    """The Principled BSDF's coat (weight, roughness, IOR, tint), as Cycles layers it over the
    other lobes (src/bsdf/coat.rs). Its own normal input is not read."""
    weight = _unit(_input_value(node, "Coat Weight", warnings, what, 0.0))
    if weight <= 0.0:
        return
    out["coat"] = weight
    out["coat_roughness"] = _unit(_input_value(node, "Coat Roughness", warnings, what, 0.03))
    out["coat_ior"] = max(float(_input_value(node, "Coat IOR", warnings, what, 1.5)), 1.0)
    out["coat_tint"] = tuple(max(float(c), 0.0) for c in _input_value(node, "Coat Tint", warnings, what,
                                                                      (1.0, 1.0, 1.0, 1.0))[:3])
    sock = node.inputs.get("Coat Normal")
    if sock is not None and sock.is_linked:
        warnings.append(f"{what}: the Coat Normal input of '{node.name}' is not read; the coat follows "
                        f"the surface's normal")
    if max(out.get("emission", (0.0,))) > 0.0 or "emission_texture" in out:
        warnings.append(f"{what}: emission under the coat of '{node.name}' is not dimmed by the coat")


def _subsurface_method(node, warnings, what):
    """The core's walk for the node's Subsurface Method (its `falloff` on the Subsurface
    Scattering node): Blender 5.2 renamed 4.x–5.1's Random Walk to Random Walk (Legacy) and
    gave Random Walk a new model (`src/medium/subsurface.rs`) — told apart by the Legacy
    choice being offered; Christensen-Burley is rendered as Random Walk (Legacy), with a
    warning."""
    prop = "subsurface_method" if node.type == "BSDF_PRINCIPLED" else "falloff"
    method = getattr(node, prop, "RANDOM_WALK")
    if method == "RANDOM_WALK":
        return "random_walk" if _has_legacy_random_walk(node, prop) else "legacy"
    if method == "RANDOM_WALK_SKIN":
        return "skin"
    if method == "BURLEY":
        warnings.append(f"{what}: subsurface method Christensen-Burley of '{node.name}' is rendered as a random "
                        f"walk (Random Walk (Legacy))")
    return "legacy"


def _has_legacy_random_walk(node, prop):
    """Whether this Blender offers Random Walk (Legacy) (5.2 and later): its Random Walk is then
    the new model."""
    try:
        return "RANDOM_WALK_LEGACY" in {e.identifier for e in node.bl_rna.properties[prop].enum_items}
    except (KeyError, AttributeError):
        return False


def _subsurface(node, out, warnings, what, weight=None):
    """Principled Subsurface (or the Subsurface Scattering node, `weight` 1): the share of the
    diffuse base that walks beneath the surface, its mean free path Radius × Scale per channel,
    Anisotropy and (Skin) IOR, as Cycles' `bssrdf_setup` takes them."""
    if weight is None:
        weight = _unit(_input_value(node, "Subsurface Weight", warnings, what, 0.0))
    if weight <= 0.0:
        return
    prefix = "Subsurface " if node.type == "BSDF_PRINCIPLED" else ""
    radius = _input_value(node, prefix + "Radius", warnings, what, (1.0, 0.2, 0.1))
    scale = float(_input_value(node, prefix + "Scale", warnings, what, 0.05))
    g = float(_input_value(node, prefix + "Anisotropy", warnings, what, 0.0))
    method = _subsurface_method(node, warnings, what)
    if not _has_legacy_random_walk(node, "subsurface_method" if node.type == "BSDF_PRINCIPLED" else "falloff"):
        g = max(g, 0.0)  # (before 5.2 Cycles clamps the anisotropy to [0, 0.9])
    ior_input = "Subsurface IOR" if node.type == "BSDF_PRINCIPLED" else "IOR"
    out["subsurface"] = {
        "weight": weight,
        "radius": tuple(max(float(r) * scale, 0.0) for r in tuple(radius)[:3]),
        "anisotropy": g,
        "ior": float(_input_value(node, ior_input, warnings, what, 1.4)),
        "method": method,
    }


def _unit(x):
    """x clamped to [0, 1] (as Cycles clamps a roughness)."""
    return min(max(float(x), 0.0), 1.0)


def _warn_unsupported_layers(node, warnings, what):
    for name, off in _UNSUPPORTED_LAYERS:
        sock = node.inputs.get(name)
        if sock is not None and (sock.is_linked or abs(float(sock.default_value) - off) > 1e-6):
            warnings.append(f"{what}: Principled '{name}' is not rendered (the layer is left out)")


def _specular_tint(node, out, warnings, what):
    """Specular Tint: it colours the dielectric specular layer over the base (F0·tint) and the
    metal's edge (its F82 tint), as Cycles; the transmissive part is rendered untinted, with a
    warning."""
    tint = tuple(_unit(c) for c in _input_value(node, "Specular Tint", warnings, what, (1.0, 1.0, 1.0, 1.0))[:3])
    if all(abs(c - 1.0) <= 1e-6 for c in tint):
        return
    out["specular_tint"] = tint
    if out.get("transmission", 0.0) > 0.0:
        warnings.append(f"{what}: Principled 'Specular Tint' is not applied to the transmissive part (its "
                        f"glass reflects untinted)")


def _shader_leaves(node, weight, leaves, textures, warnings, what, branch=(), fixed=None):
    """Walks a Mix/Add Shader tree: appends (weight, leaf parameters) for every shader node.
    `branch`: the Mix/Add nodes above this one; a node met again on its own branch is a loop
    (Blender's editor refuses those, a script need not), refused naming material and node.
    `fixed`: Mix Shader name → the factor taken for it (`_blend_material`'s two ends)."""
    if weight <= 0.0:
        return
    if node.name in branch:
        raise ValueError(f"{what}: its shader nodes form a loop through '{node.name}'")
    if node.type == "MIX_SHADER":
        fac = fixed[node.name] if fixed and node.name in fixed else _input_value(node, "Fac", warnings, what, 0.5)
        fac = min(max(fac, 0.0), 1.0)
        pairs = ((node.inputs[1], weight * (1.0 - fac)), (node.inputs[2], weight * fac))
    elif node.type == "ADD_SHADER":
        pairs = ((node.inputs[0], weight), (node.inputs[1], weight))
    else:
        p = _node_params(node, textures, warnings, what)
        alpha = p.pop("alpha", 1.0)
        if alpha < 1.0:  # alpha as coverage: Mix(Transparent(white), shader, alpha), as in Cycles
            leaves.append((weight * (1.0 - alpha), {"emission": (0.0, 0.0, 0.0), "pass": (1.0, 1.0, 1.0)}))
        leaves.append((weight * alpha, p))
        return
    for sock, w in pairs:
        if sock.is_linked:  # an unconnected shader socket adds nothing, as in Cycles
            _shader_leaves(sock.links[0].from_node, w, leaves, textures, warnings, what, branch + (node.name,), fixed)


@dataclass
class _LobeSum:
    """The summed weight and weight × colour of the lobes of one kind."""
    weight: float = 0.0
    colour: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def add(self, w, colour):
        self.weight += w
        self.colour += w * colour

    def mean(self, scale):
        return tuple((self.colour / self.weight * scale).tolist()) if self.weight > 0 else (0.0, 0.0, 0.0)


@dataclass
class _Mixture:
    """What the weighted leaves of a Mix/Add Shader tree add up to (`_gather`), before it is
    turned into one material (`_combine`)."""
    lobes: dict = field(default_factory=lambda: {"d": _LobeSum(), "m": _LobeSum(), "g": _LobeSum(), "t": _LobeSum()})
    glass_reflection: _LobeSum = field(default_factory=_LobeSum)  # the glass lobes' reflection colours
    passing: _LobeSum = field(default_factory=_LobeSum)  # Transparent BSDF leaves (and 1 − alpha)
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    glowing: list = field(default_factory=list)  # the leaves that emit
    rough: list = field(default_factory=list)  # (lobe kind: layer, d, m or g; weight; roughness)
    iors: list = field(default_factory=list)  # the glass lobes' IOR
    layer_weight: float = 0.0  # diffuse-lobe weight under a specular layer
    layer_iors: list = field(default_factory=list)
    textures: list = field(default_factory=list)  # (base colour texture, on a diffuse-only leaf)
    rough_textures: list = field(default_factory=list)
    normals: list = field(default_factory=list)  # the leaves' normal and bump maps (NORMAL_KEYS)
    multiscatter: list = field(default_factory=list)  # the metal and glass leaves' distributions
    constant_fresnel: list = field(default_factory=list)  # the metal leaves': Glossy (True) or Principled
    subsurface: list = field(default_factory=list)  # (diffuse weight, the leaf's subsurface)
    bsdf_leaves: int = 0

    @property
    def bsdf_weight(self):
        return sum(v.weight for v in self.lobes.values())


def _gather(leaves, warnings, what) -> _Mixture:
    """Sums the leaves' lobes (Principled weights (1−m)(1−t), m, (1−m)t), emission and
    pass-through, and lists what each leaf asks of the shared parameters."""
    mix = _Mixture(glowing=[p for w, p in leaves if w > 0 and max(p["emission"][:3]) > 0])
    for w, p in leaves:
        mix.emission += w * np.array(p["emission"][:3], dtype=np.float64)
        if "pass" in p:
            mix.passing.add(w, np.array(p["pass"][:3], dtype=np.float64))
            continue
        if not p.get("bsdf", True):
            continue
        mix.bsdf_leaves += 1
        m, t, tl = p["metallic"], p["transmission"], p.get("translucency", 0.0)
        colour = np.array(p["base_color"][:3], dtype=np.float64)
        if w * tl > 0:
            mix.lobes["t"].add(w * tl, np.array(p.get("translucent_color", colour), dtype=np.float64))
        w = w * (1 - tl)  # (the other lobes share the rest)
        for k, wk in (("d", (1 - m) * (1 - t)), ("m", m), ("g", (1 - m) * t)):
            if w * wk > 0:
                # (a Principled leaf's glass transmits √colour per interface)
                mix.lobes[k].add(w * wk, np.sqrt(colour) if k == "g" and p.get("glass_sqrt_tint") else colour)
        if w * (1 - m) * t > 0:
            mix.glass_reflection.add(w * (1 - m) * t, np.array(p.get("glass_reflection_tint", colour), dtype=np.float64))
        has_layer = p.get("specular_ior", 1.0) > 1.0 and w * (1 - m) * (1 - t) > 0
        if has_layer:
            mix.layer_weight += w * (1 - m) * (1 - t)
            mix.layer_iors.append(p["specular_ior"])
        for kind, wk in (("layer", w * (1 - m) * (1 - t) if has_layer else 0.0), ("m", w * m), ("g", w * (1 - m) * t)):
            if wk > 0:
                mix.rough.append((kind, wk, p["roughness"]))
        if w * (1 - m) * (1 - t) > 0:
            mix.rough.append(("d", w * (1 - m) * (1 - t), p.get("diffuse_roughness", 0.0)))
            mix.subsurface.append((w * (1 - m) * (1 - t), p.get("subsurface")))
        if w * (1 - m) * t > 0:
            mix.iors.append(p["ior"])
        if "base_color_texture" in p:
            mix.textures.append((p["base_color_texture"], (1 - m) * (1 - t) > 0.999))
        if "roughness_texture" in p:
            mix.rough_textures.append(p["roughness_texture"])
        if "metallic_texture" in p:
            warnings.append(f"{what}: a metallic map inside a Mix/Add Shader is not supported; its mean "
                            f"{m:.3f} is used")
        if "alpha_texture" in p:
            warnings.append(f"{what}: an image's alpha inside a Mix/Add Shader is not supported; that shader is "
                            f"rendered opaque")
        if "normal_texture" in p or "bump_texture" in p:
            mix.normals.append(tuple(p.get(k) for k in NORMAL_KEYS))
        if w * m > 0 or w * (1 - m) * t > 0:
            mix.multiscatter.append(p.get("multiscatter", False))
        if w * m > 0:
            mix.constant_fresnel.append(p.get("metal_constant_fresnel", False))
    return mix


def _combine(leaves, warnings, what):
    """One material from weighted leaves: the diffuse, metal and glass lobes of every leaf
    are summed per kind — exact, since lobes of one kind differ only in colour — and
    emission adds up. The specular layer, the metal and the glass lobes keep their own
    roughness; lobes of one kind with different roughness, or glass lobes with different
    IOR, are averaged (with a warning). A total BSDF weight above 1 (Add Shader of two BSDFs)
    is normalized, with a warning. Steps: gather the leaves (`_gather`); emission; the
    pass-through lobe; the lobe weights and colours; the specular layer; roughness; IOR;
    textures; the metal distribution; the normal map."""
    mix = _gather(leaves, warnings, what)
    total = mix.bsdf_weight
    total_all = total + mix.passing.weight
    out = {"emission": tuple(mix.emission.tolist()), "metallic": 0.0, "transmission": 0.0, "roughness": 0.5,
           "ior": mix.iors[0] if mix.iors else 1.5}
    _combined_emission_texture(mix, out, warnings, what)
    scale = min(total_all, 1.0)
    if total_all > 1.0 + 1e-6:
        warnings.append(f"{what}: Add Shader of BSDFs with total weight {total_all:.2f} is normalized to 1")
    if mix.passing.weight > 0:
        # the core's pass-through lobe takes probability τ; the other lobes share 1 − τ
        out["transparency"] = mix.passing.weight / total_all
        out["transparent_color"] = mix.passing.mean(scale)
    if total <= 0:
        out["base_color"] = (0.0, 0.0, 0.0)
        return out
    colour = {k: v.mean(scale) for k, v in mix.lobes.items()}
    translucent = mix.lobes["t"].weight
    if translucent > 0:
        out["translucency"] = translucent / total
        out["translucent_color"] = colour["t"]
    out["metallic"] = mix.lobes["m"].weight / (total - translucent) if total > translucent else 0.0
    dg = mix.lobes["d"].weight + mix.lobes["g"].weight
    out["transmission"] = mix.lobes["g"].weight / dg if dg > 0 else 0.0
    out["base_color"], out["metal_color"], out["glass_color"] = colour["d"], colour["m"], colour["g"]
    reflection = mix.glass_reflection.mean(scale)
    if mix.glass_reflection.weight > 0 and max(abs(a - b) for a, b in zip(reflection, colour["g"])) > 1e-6:
        out["glass_reflection_tint"] = reflection
    if mix.layer_weight > 0:
        out["specular_ior"] = mix.layer_iors[0]
        out["specular"] = mix.layer_weight / mix.lobes["d"].weight
        if max(mix.layer_iors) - min(mix.layer_iors) > 1e-4:
            warnings.append(f"{what}: the mixed Principled specular layers have different IOR; "
                            f"{mix.layer_iors[0]:.3f} is used")
    _combined_roughness(mix, out, warnings, what)
    _combined_subsurface(mix, out, warnings, what)
    if len(set(mix.iors)) > 1:
        warnings.append(f"{what}: the mixed glass lobes have different IOR; {mix.iors[0]} is used")
    _combined_textures(mix, out, colour, warnings, what)
    # a coat or Specular Tint is kept for one Principled beside pass-through only
    for keys, name, fallback in ((COAT_KEYS, "coat", "the coat is left out"),
                                 (("specular_tint",), "Specular Tint", "white is used")):
        having = [p for _, p in leaves if keys[0] in p]
        if having and mix.bsdf_leaves == 1:
            out.update({k: having[0][k] for k in keys})
        elif having:
            warnings.append(f"{what}: a Principled {name} inside a Mix/Add Shader is not rendered ({fallback})")
    return out


def _combined_subsurface(mix, out, warnings, what):
    """The diffuse lobes' subsurface shares add up (weight: their share of all diffuse weight);
    they walk with the parameters of the heaviest."""
    having = [(w, s) for w, s in mix.subsurface if s]
    if not having:
        return
    total = sum(w for w, _ in mix.subsurface)
    heaviest = max(having, key=lambda ws: ws[0] * ws[1]["weight"])[1]
    out["subsurface"] = dict(heaviest, weight=min(sum(w * s["weight"] for w, s in having) / total, 1.0))
    keys = ("radius", "anisotropy", "ior", "method")
    if any(tuple(s[k] for k in keys) != tuple(heaviest[k] for k in keys) for _, s in having):
        warnings.append(f"{what}: the mixed subsurface shaders differ; they walk with the radius, anisotropy "
                        f"and method of the heaviest")


def _combined_emission_texture(mix, out, warnings, what):
    """An emission image multiplies all emission: right when it is the only emitter."""
    textured = [p["emission_texture"] for p in mix.glowing if "emission_texture" in p]
    if textured:
        if len(mix.glowing) == 1:
            out["emission_texture"] = textured[0]
        else:
            warnings.append(f"{what}: an emission image mixed with other emission is not supported; its "
                            f"strength is used as white light")


def _combined_roughness(mix, out, warnings, what):
    """Each lobe kind keeps its own roughness (the specular layer's is `roughness`, the diffuse
    base's `diffuse_roughness`); lobes of one kind with different roughness share their
    weighted mean."""
    means = {}
    for kind in ("layer", "d", "m", "g"):
        rs = [(w, r) for k, w, r in mix.rough if k == kind]
        if rs:
            means[kind] = sum(w * r for w, r in rs) / sum(w for w, _ in rs)
            if max(r for _, r in rs) - min(r for _, r in rs) > 1e-3:
                name = {"layer": "specular layers", "d": "diffuse lobes", "m": "glossy/metal lobes",
                        "g": "glass lobes"}[kind]
                warnings.append(f"{what}: the mixed {name} have different roughness; their weighted mean "
                                f"{means[kind]:.3f} is used")
    if means.get("d", 0.0) > 0.0:
        out["diffuse_roughness"] = means["d"]
    means.pop("d", None)
    if means:
        out["roughness"] = means.get("layer", means.get("m", means.get("g")))
        for kind, key in (("m", "metal_roughness"), ("g", "glass_roughness")):
            if kind in means and abs(means[kind] - out["roughness"]) > 1e-6:
                out[key] = means[kind]


def _combined_textures(mix, out, colour, warnings, what):
    """Image textures (one base colour image on a diffuse-only leaf, the first roughness
    image), the metal lobes' distribution and the normal map — each shared by the mixture."""
    if mix.textures:
        index, diffuse_only = mix.textures[0]
        if len(mix.textures) == 1 and diffuse_only:
            out["base_color_texture"] = index  # scales with the diffuse lobe's weight
            out["base_color"] = colour["d"]
        else:
            warnings.append(f"{what}: image textures inside a Mix/Add Shader are supported on one Diffuse "
                            f"(or diffuse-only Principled) input only; their socket values are used elsewhere")
    if mix.rough_textures:
        out["roughness_texture"] = mix.rough_textures[0]
    if mix.multiscatter:
        out["multiscatter"] = mix.multiscatter[0]
        if len(set(mix.multiscatter)) > 1:
            warnings.append(f"{what}: the mixed glossy/metal/glass lobes use different distributions; "
                            f"{'Multiscatter GGX' if mix.multiscatter[0] else 'GGX'} is used for all")
    if mix.constant_fresnel:
        out["metal_constant_fresnel"] = mix.constant_fresnel[0]
        if len(set(mix.constant_fresnel)) > 1:
            warnings.append(f"{what}: a Glossy BSDF mixed with a metallic Principled: their metal lobes share "
                            f"{'the Glossy' if mix.constant_fresnel[0] else 'the Principled'} Fresnel term")
    if mix.normals:
        # one shading normal per point in the core: a normal map shared by every BSDF leaf
        out.update({k: v for k, v in zip(NORMAL_KEYS, mix.normals[0]) if v is not None})
        if len(set(mix.normals)) > 1 or len(mix.normals) < mix.bsdf_leaves:
            warnings.append(f"{what}: the mixed shaders have different normals; the first normal map is used for all")


def _matrix(m):
    return np.array([list(row) for row in m], dtype=np.float64)


def _read(attributes, name, prop, n, dtype):
    """Attribute `name`'s values (its `prop`, `n` numbers) as a numpy array, or None when the
    mesh has no such attribute of that size."""
    attr = attributes.get(name)
    if attr is None:
        return None
    out = np.empty(n, dtype)
    try:
        attr.data.foreach_get(prop, out)
    except (RuntimeError, TypeError, AttributeError):
        return None
    return out


def _mesh_local_arrays(ob, colour_layer=None, spaces=()):
    """Triangulated mesh of an evaluated object, in object space, or None if it has no faces:
    (positions, triangles, corner normals, material slots, corner UVs or None, corner colours
    or None, {space: corner coordinates} of `spaces`). `colour_layer`: the colour attribute
    to read ('' = the default one), or None; `spaces`: the coordinates its procedural
    textures read ('GENERATED', 'OBJECT')."""
    try:
        me = ob.to_mesh()
    except RuntimeError:
        return None
    if me is None:
        return None
    try:
        me.calc_loop_triangles()
        nt = len(me.loop_triangles)
        if nt == 0:
            return None
        # (attribute arrays where Blender has them: foreach_get reads those as one block,
        # where the older collections go element by element — 0.4–0.7 s per array on a 5M-
        # triangle mesh against a few ms)
        co = _read(me.attributes, "position", "vector", len(me.vertices) * 3, np.float32)
        if co is None:
            co = np.empty(len(me.vertices) * 3, np.float32)
            me.vertices.foreach_get("co", co)
        tl = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("loops", tl)
        corner_vert = _read(me.attributes, ".corner_vert", "value", len(me.loops), np.int32)
        if corner_vert is not None:
            tv = corner_vert[tl]
        else:
            tv = np.empty(nt * 3, np.int32)
            me.loop_triangles.foreach_get("vertices", tv)
        mi = None
        face_mat = _read(me.attributes, "material_index", "value", len(me.polygons), np.int32)
        if face_mat is not None and hasattr(me, "loop_triangle_polygons"):
            pi = np.empty(nt, np.int32)
            me.loop_triangle_polygons.foreach_get("value", pi)
            mi = face_mat[pi]
        elif "material_index" not in me.attributes:
            mi = np.zeros(nt, np.int32)  # (no attribute: every face uses the first slot)
        if mi is None:
            mi = np.empty(nt, np.int32)
            me.loop_triangles.foreach_get("material_index", mi)
        normals = _cycles_normals(me, co.reshape(-1, 3), tv.reshape(-1, 3), tl)
        uvs = None
        uv_layer = next((l for l in me.uv_layers if l.active_render), None) or me.uv_layers.active
        if uv_layer is not None:
            uv = np.empty(len(me.loops) * 2, np.float32)
            uv_layer.uv.foreach_get("vector", uv)
            uvs = np.ascontiguousarray(uv.reshape(-1, 2)[tl])
        colours = None
        if colour_layer is not None:
            attrs = me.color_attributes
            name = colour_layer or getattr(me.attributes, "default_color_name", "") or ""
            attr = attrs.get(name) if name else None
            if attr is None and not colour_layer and len(attrs):
                attr = attrs[min(max(attrs.render_color_index, 0), len(attrs) - 1)]
            if attr is not None:
                rgba = np.empty(len(attr.data) * 4, np.float32)
                attr.data.foreach_get("color", rgba)  # (scene linear, byte colours too)
                rgba = rgba.reshape(-1, 4)
                colours = np.ascontiguousarray(rgba[tv if attr.domain == "POINT" else tl, :3])
        points = {}
        for space in spaces:
            p = co.reshape(-1, 3)[tv].astype(np.float64)
            if space == "GENERATED":  # the auto (bounding box) or the mesh's own texture space → [0, 1]³
                loc = np.array(me.texspace_location[:], np.float64)
                size = np.array(me.texspace_size[:], np.float64)
                p = (p - loc) / (2.0 * np.where(size != 0.0, size, 1.0)) + 0.5
            points[space] = np.ascontiguousarray(p, dtype=np.float32)
        return co.reshape(-1, 3), tv.reshape(-1, 3), normals, mi, uvs, colours, points
    finally:
        ob.to_mesh_clear()


def _cycles_normals(me, co, tv, tl):
    """The shading normals of mesh `me`'s triangles (vertex indices `tv`, corner indices `tl`)
    per corner as Cycles takes them, or None where every triangle is flat (Cycles' mesh sync,
    which reads the normals domain as `Mesh::normals_domain(support_sharp_face=true)`):
    - all faces flat (domain FACE): each triangle its own normal — on a non-planar quad not
      its polygon's (13° apart on a rough ground, +1.8%): None;
    - smooth and flat faces mixed, with no sharp edge and no custom normals (Python reports
      CORNER; Cycles up to Blender 5.0 reads POINT): a smooth triangle interpolates Blender's
      vertex normals, which average every face around a vertex, the flat ones too — not the
      corner normals, which leave the flat faces out (a smooth floor beside a flat skirt,
      pybullet's monastery: corner and vertex normals up to 40° apart, the image −3%) —,
      and a flat one takes its own normal. Measured against Cycles' Normal pass in 4.5.15
      and 5.0.1 (5.1.0 too); 5.2.0's and 5.3.0's Cycles take the corner normals here (as
      below), a flat face's its polygon's normal, and so does the export from 5.2 on;
    - otherwise (domain CORNER: sharp edges or custom normals, which Cycles splits the mesh
      along) every triangle interpolates its corner normals, a flat face's corners holding its
      polygon's normal, and Cycles counts every triangle as smooth (for its shadow
      terminator offset too)."""
    domain = getattr(me, "normals_domain", "CORNER")
    if domain == "FACE":
        return None
    attrs = me.attributes
    sharp_edge = attrs.get("sharp_edge")
    sharp_face = attrs.get("sharp_face")
    if (domain == "CORNER" and "custom_normal" not in attrs and sharp_face is not None
            and _cycles_reads_point_normals() and not _any_true(sharp_edge, len(me.edges))):
        vn = np.empty(len(me.vertices) * 3, np.float32)
        (me.vertex_normals if hasattr(me, "vertex_normals") else me.vertices).foreach_get(
            "vector" if hasattr(me, "vertex_normals") else "normal", vn)
        normals = vn.reshape(-1, 3)[tv]  # (triangles, 3 corners, 3)
        flat = np.empty(len(me.polygons), bool)
        sharp_face.data.foreach_get("value", flat)
        pi = np.empty(len(tv), np.int32)
        if hasattr(me, "loop_triangle_polygons"):
            me.loop_triangle_polygons.foreach_get("value", pi)
        else:
            me.loop_triangles.foreach_get("polygon_index", pi)
        tri_flat = flat[pi]
        if tri_flat.any():
            p = co[tv[tri_flat]].astype(np.float64)
            n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
            normals[tri_flat] = n[:, None, :].astype(np.float32)
        return normals.reshape(-1, 3)
    cn = np.empty(len(me.loops) * 3, np.float32)
    me.corner_normals.foreach_get("vector", cn)
    return cn.reshape(-1, 3)[tl]  # smooth, flat and custom split normals per corner


def _cycles_reads_point_normals():
    """Whether this Blender's Cycles shades a mesh of mixed smooth and flat faces (no sharp
    edges, no custom normals) with vertex normals (up to 5.1) rather than corner normals
    (5.2 and 5.3: tests/python/test_blender.py's Normal-pass comparison on each)."""
    import bpy

    return bpy.app.version < (5, 2, 0)


def _cycles_release_choices():
    """Where Cycles releases render differently, whether this Blender's Cycles does what the
    older ones do (read in each release's kernel; the scene description's switches of those
    names, src/scene/desc.rs): rough diffuse with its multiple scattering cubed in the colour
    rather than squared as OpenPBR's EON (bsdf_oren_nayar.h, up to 5.2), tangent-space
    normal maps on the interpolated normal as it is rather than normalized (triangle.h's
    triangle_smooth_normal_unnormalized*, up to 5.0)."""
    import bpy

    v = bpy.app.version
    return {"oren_nayar_rho_cubed": v < (5, 3, 0), "normal_map_unnormalized_base": v < (5, 1, 0)}


def _link_states(collection):
    """{object name: 'INCLUDE' or 'EXCLUDE'} of a light-linking collection: its objects' own
    states, then its child collections' states for the objects in them (depth first; an
    object's nearest entry decides)."""
    states = {}

    def walk(c, inherited):
        for ob, entry in zip(c.objects, c.collection_objects):
            states.setdefault(ob.name, inherited or entry.light_linking.link_state)
        for child, entry in zip(c.children, c.collection_children):
            walk(child, inherited or entry.light_linking.link_state)

    walk(collection, None)
    return states


def _light_linking(meshes, lights, sources, desc, warnings):
    """Blender's light linking (Object › Light Linking › Receiver Collection on lights and
    emitting objects) as Cycles' light sets: an emitter lights the objects its collection
    includes — or, when it includes none, every object it does not exclude. Objects lit by
    the same emitters share a receiver set (mesh `light_set`; 0 for those no collection
    names), and each emitter says which sets it lights (`light_membership`: a mesh's, or
    the scene's per light), as src/scene/desc.rs reads them."""
    emitters = []  # (kind, index, {object: state}, includes any)
    for kind in ("lights", "meshes"):
        for k, ob in enumerate(sources[kind]):
            linking = getattr(ob.original, "light_linking", None)
            collection = linking.receiver_collection if linking is not None else None
            if collection is not None:
                states = _link_states(collection)
                emitters.append((kind, k, states, "INCLUDE" in states.values()))
    if not emitters:
        return

    def lit(e, name):
        state = e[2].get(name)
        return state == "INCLUDE" or (not e[3] and state != "EXCLUDE")

    default = tuple(not e[3] for e in emitters)  # what an object no collection names receives
    sets = {default: 0}
    for mesh, ob in zip(meshes, sources["meshes"]):
        signature = tuple(lit(e, ob.original.name) for e in emitters)
        if signature not in sets:
            if len(sets) == 64:
                warnings.append(f"object '{ob.name}': more than 63 combinations of light links; it is lit as the "
                                f"objects no collection names")
                continue
            sets[signature] = len(sets)
        if sets[signature]:
            mesh["light_set"] = sets[signature]
    for i, (kind, k, _, _) in enumerate(emitters):
        bits = sum(1 << s for signature, s in sets.items() if signature[i])
        if kind == "meshes":
            meshes[k]["light_membership"] = bits
        else:
            lights[k]["light_membership"] = bits


def _holdout(ob, inst, depsgraph):
    """Whether the camera sees `ob` held out: its Object › Visibility › Holdout, or a
    collection of it set to Holdout in the view layer (as Cycles asks `holdout_get`), or
    its instancer's."""
    for o in (ob, inst.parent if inst.is_instance else None):
        if o is None:
            continue
        get = getattr(o.original, "holdout_get", None)
        try:
            if get(view_layer=depsgraph.view_layer) if get is not None else o.is_holdout:
                return True
        except (TypeError, RuntimeError):
            if getattr(o, "is_holdout", False):
                return True
    return False


def _any_true(attr, n):
    """Whether boolean attribute `attr` (of `n` elements, or None) is set anywhere."""
    if attr is None or n == 0:
        return False
    v = np.empty(n, bool)
    attr.data.foreach_get("value", v)
    return bool(v.any())


def _colour_layer(ob, layers, warnings):
    """The colour attribute the materials of `ob` read (`layers`: per slot, a name, '' for the
    default attribute, or None): one per mesh; where its materials ask for different ones,
    the first, with a warning."""
    wanted = list(dict.fromkeys(x for x in layers if x is not None))
    if len(wanted) > 1:
        warnings.append(f"object '{ob.name}': its materials read different colour attributes "
                        f"({', '.join(repr(x) for x in wanted)}); all of them get {wanted[0]!r}")
    return wanted[0] if wanted else None


def _mesh_coordinates(params, textures):
    """The mesh coordinates (Generated, Object) the procedural textures of a material's
    `params` read."""
    spaces = {textures.spaces[v] for k, v in params.items()
              if k.endswith("_texture") and textures.spaces.get(v) in ("GENERATED", "OBJECT")}
    return spaces | (_mesh_coordinates(params["blend"], textures) if "blend" in params else set())


# A material that reads Object Info is exported once per object it is on; beyond this many
# variants its Random output is rounded to 1/1023 (warned), which bounds the variants.
MAX_OBJECT_VARIANTS = 4096


def _object_info(inst, ob, mat, variants, warnings):
    """What an Object Info node outputs in material `mat` on object instance `inst` (values
    in the order of texture_graph.OBJECT_INFO_OUTPUTS; None for those the material does not
    read, so that objects differing only there share a variant), or None when the material
    reads no Object Info. Random as Cycles computes it: an instance's random id over
    2³² − 1, else Jenkins' lookup3 mix of a hash of the object's name (measured against
    Cycles). `variants`: material name → (the outputs it reads, its variants so far)."""
    from .texture_graph import OBJECT_INFO_OUTPUTS

    if mat.name not in variants:
        read = _object_info_read(mat.node_tree, set())
        variants[mat.name] = (read, set()) if read else None
    if variants[mat.name] is None:
        return None
    read, seen = variants[mat.name]
    if inst.is_instance:
        random = (inst.random_id & 0xFFFFFFFF) / 0xFFFFFFFF
    else:
        random = _hash_uint2(_hash_string(ob.name), 0) / 0xFFFFFFFF
    colour = tuple(float(c) for c in ob.color)
    values = (random, colour[:3], colour[3], float(ob.pass_index), float(mat.pass_index))
    info = tuple(v if name in read else None for name, v in zip(OBJECT_INFO_OUTPUTS, values))
    if len(seen) >= MAX_OBJECT_VARIANTS and info not in seen and info[0] is not None:
        warnings.append(f"material '{mat.name}': on more than {MAX_OBJECT_VARIANTS} objects its Object Info "
                        f"Random is rounded to 1/1023")
        info = (round(random * 1023) / 1023,) + info[1:]
    seen.add(info)
    return info


def _object_info_read(tree, seen):
    """The Object Info outputs (identifiers) node tree `tree` and the groups in it read."""
    if tree is None or tree.name in seen:
        return set()
    seen.add(tree.name)
    read = set()
    for node in tree.nodes:
        if node.type == "OBJECT_INFO":
            read |= {o.identifier for o in node.outputs if o.is_linked}
        elif node.type == "GROUP":
            read |= _object_info_read(node.node_tree, seen)
    return read


def _hash_string(name):
    """Cycles' hash of a C string (x86's signed char)."""
    h = 0
    for b in name.encode():
        h = (h * 37 + (b if b < 128 else b - 256)) & 0xFFFFFFFF
    return h


def _hash_uint2(kx, ky):
    """Jenkins' lookup3 hash of two words (its `final` mix), as Cycles hashes."""
    m = 0xFFFFFFFF
    v = {"a": (0xDEADBEEF + (2 << 2) + 13 + kx) & m, "b": (0xDEADBEEF + (2 << 2) + 13 + ky) & m,
         "c": (0xDEADBEEF + (2 << 2) + 13) & m}
    for x, y, k in (("c", "b", 14), ("a", "c", 11), ("b", "a", 25), ("c", "b", 16), ("a", "c", 4), ("b", "a", 14),
                    ("c", "b", 24)):
        v[x] = ((v[x] ^ v[y]) - (((v[y] << k) | (v[y] >> (32 - k))) & m)) & m
    return v["c"]


def _light(ob, matrix, warnings):
    """The scene dict entry of a light object, or None when it sends no light: a Cycles
    portal (an area light marking a window, which only guides Cycles' sampling of the world)."""
    light = ob.data
    name = ob.name
    if light.type == "AREA" and getattr(getattr(light, "cycles", None), "is_portal", False):
        return None
    scale = 2.0 ** float(getattr(light, "exposure", 0.0))
    color = np.array(light.color[:3], dtype=np.float64)
    if getattr(light, "use_temperature", False):  # Blender's blackbody colour (luminance 1)
        color = color * np.array(light.temperature_color[:3], dtype=np.float64)
    power = tuple((color * light.energy * scale).tolist())
    visible = bool(getattr(ob, "visible_camera", False))
    m = matrix
    pos = tuple(m[:3, 3].tolist())
    minus_z = -m[:3, 2]
    n = np.linalg.norm(minus_z)
    minus_z = tuple((minus_z / n if n > 0 else np.array([0, 0, -1.0])).tolist())
    power = tuple(p * e for p, e in zip(power, _light_emission(light, warnings, f"light '{name}'")))
    soft = bool(getattr(light, "use_soft_falloff", True))
    if light.type == "POINT":
        return scenedict.point_light(name, pos, power, light.shadow_soft_size, soft, visible)
    if light.type == "SPOT":
        return scenedict.spot_light(name, pos, minus_z, power, light.shadow_soft_size, light.spot_size,
                                    light.spot_blend, soft, visible, matrix=m.astype(np.float32))
    if light.type == "AREA":
        return scenedict.area_light(name, m.astype(np.float32), light.shape, light.size, light.size_y, power,
                                    getattr(light, "normalize", True), visible,
                                    float(getattr(light, "spread", math.pi)))
    if light.type == "SUN":
        plus_z = tuple((-np.array(minus_z)).tolist())
        return scenedict.sun_light(name, plus_z, power, light.angle, visible)
    warnings.append(f"light '{name}': type {light.type} is not supported and was skipped")
    return None


def _light_uses_nodes(light):
    """Light › Use Nodes. Blender 5.3 deprecates the property (a light's node tree, when it
    has one, is always used there, and the property reads True): read without its warning."""
    import warnings as _w

    with _w.catch_warnings():
        _w.simplefilter("ignore", DeprecationWarning)
        return bool(getattr(light, "use_nodes", False))


def _light_emission(light, warnings, what):
    """The factor a light's node tree puts on its colour × power, as Cycles applies it: the
    Emission node's Color × Strength into the Light Output (constant, or colour and value
    nodes without a texture under them: a Blackbody node, say); white without a tree. Anything
    else (a texture, an IES profile, Light Falloff) is left out with a warning: factor 1."""
    tree = light.node_tree if _light_uses_nodes(light) else None
    out = _output_node(tree, warnings, what) if tree is not None else None
    if out is None:
        return (1.0, 1.0, 1.0)
    sock = out.inputs.get("Surface")
    node = sock.links[0].from_node if sock is not None and sock.is_linked else None
    if node is None:
        return (0.0, 0.0, 0.0)  # (an unconnected output: the light emits nothing, as in Cycles)
    if node.type != "EMISSION":
        warnings.append(f"{what}: node '{node.name}' ({node.type}) into the light output is not rendered; "
                        f"colour × power is used")
        return (1.0, 1.0, 1.0)
    colour = _input_value(node, "Color", warnings, what, (1.0, 1.0, 1.0, 1.0))[:3]
    strength = float(_input_value(node, "Strength", warnings, what, 1.0))
    return tuple(max(float(c), 0.0) * strength for c in colour)


def _world_rotation(node, warnings, what):
    """The rotation (row-major 3×3, world direction → the texture's frame) that an Environment
    Texture's Vector input applies: None when unlinked or fed the Generated direction itself;
    a Mapping node of Point or Vector type on the Generated direction looks the texture up at
    R·d (R its Euler XYZ rotation), of Texture type at R⁻¹·d. Its Scale counts only when
    uniform and positive (the lookup normalises the direction) and its Location not at all
    for a Vector mapping; anything else: the world direction, with a warning."""
    sock = node.inputs["Vector"]
    if not sock.is_linked:
        return None

    def generated(link):
        return link.from_node.type == "TEX_COORD" and link.from_socket.name == "Generated"

    link = sock.links[0]
    if generated(link):
        return None
    m = _mapping_on(link, generated)
    if m is not None:
        from mathutils import Euler

        scale = tuple(m.inputs["Scale"].default_value)
        loc = tuple(m.inputs["Location"].default_value) if m.vector_type != "VECTOR" else (0.0, 0.0, 0.0)
        if max(scale) - min(scale) > 1e-6 * max(abs(s) for s in scale) or min(scale) <= 0.0 or any(loc):
            warnings.append(f"{what}: Mapping '{m.name}' on the environment: only its rotation is rendered "
                            f"(a location or a non-uniform or negative scale is left out)")
        rot = Euler(tuple(m.inputs["Rotation"].default_value), "XYZ").to_matrix()
        if m.vector_type == "TEXTURE":
            rot = rot.transposed()
        return np.array([list(row) for row in rot], dtype=np.float32)
    warnings.append(f"{what}: the Vector input of texture '{node.name}' ({link.from_node.type}) is not supported; the world "
                    f"direction is used (supported: Generated, and a Mapping node on it)")
    return None


def _world(scene, warnings, textures):
    """(colour × strength, or strength alone with an environment texture; texture index or
    None; the texture's rotation or None; the camera's backdrop keys or None). A Mix
    Shader by Light Path › Is Camera Ray (lighting by one background, the camera seeing
    another) gives the lighting world and the camera's: a colour (`backdrop`), or an
    environment texture's strength, index and rotation (`backdrop_texture`, `_rotation`)."""
    world = scene.world
    black = ((0.0, 0.0, 0.0), None, None)
    if world is None:
        return (*black, None)
    what = f"world '{world.name}'"
    node_out = _output_node(world.node_tree, warnings, what)
    if node_out is None:
        return tuple(world.color[:3]), None, None, None
    _warn_unrendered_outputs(node_out, warnings, what, skip=("Volume",))
    surface = node_out.inputs.get("Surface")
    if surface is None or not surface.is_linked:
        return (*black, None)
    node = surface.links[0].from_node
    backdrop = None
    if node.type == "MIX_SHADER" and _light_path_output(node.inputs[0]) == "Is Camera Ray":
        lighting, camera = (s.links[0].from_node if s.is_linked else None for s in (node.inputs[1], node.inputs[2]))
        strength, tex, rotation = _background(camera, warnings, what, textures)
        backdrop = {"backdrop": strength}
        if tex is not None:  # (an environment texture only the camera sees)
            backdrop["backdrop_texture"] = tex
            if rotation is not None:
                backdrop["backdrop_rotation"] = rotation
        node = lighting
    return (*_background(node, warnings, what, textures), backdrop)


def _light_path_output(sock):
    """The Light Path output (its identifier) linked into `sock`, or None."""
    if not sock.is_linked:
        return None
    link = sock.links[0]
    return link.from_socket.identifier if link.from_node.type == "LIGHT_PATH" else None


def _background(node, warnings, what, textures):
    """(colour × strength or the strength of a texture; texture index or None; rotation or
    None) of a world shader node: a Background, or Mix (constant factor) and Add Shaders of
    Backgrounds of constant colour; None (an unconnected socket) is black. A mix with an
    environment texture keeps the texture side, weighted (warned)."""
    black = ((0.0, 0.0, 0.0), None, None)
    if node is None:
        return black
    if node.type == "BACKGROUND":
        strength = _input_value(node, "Strength", warnings, what, 1.0)
        color_in = node.inputs["Color"]
        if color_in.is_linked and color_in.links[0].from_node.type == "TEX_ENVIRONMENT" \
                and color_in.links[0].from_socket.name == "Color":
            env = color_in.links[0].from_node
            tex = textures.add(env, warnings, what)
            if tex is not None:
                return (strength, strength, strength), tex, _world_rotation(env, warnings, what)
        col = _input_value(node, "Color", warnings, what, (0.05, 0.05, 0.05, 1))[:3]
        return tuple(c * strength for c in col), None, None
    if node.type in ("MIX_SHADER", "ADD_SHADER"):
        if node.type == "MIX_SHADER":
            fac = min(max(float(_input_value(node, "Fac", warnings, what, 0.5)), 0.0), 1.0)
            parts = ((node.inputs[1], 1.0 - fac), (node.inputs[2], fac))
        else:
            parts = ((node.inputs[0], 1.0), (node.inputs[1], 1.0))
        sides = [(_background(s.links[0].from_node if s.is_linked else None, warnings, what, textures), w)
                 for s, w in parts]
        textured = [(b, w) for b, w in sides if b[1] is not None and w > 0]
        if textured:
            (strength, tex, rot), w = max(textured, key=lambda t: t[1])
            if len(textured) > 1 or any(b[1] is None and w > 0 and max(b[0]) > 0 for b, w in sides):
                warnings.append(f"{what}: Shader '{node.name}' mixes an environment texture with another "
                                f"background; only the texture is rendered (weighted {w:.2f})")
            return tuple(c * w for c in strength), tex, rot
        return tuple(sum(b[0][k] * w for b, w in sides) for k in range(3)), None, None
    warnings.append(f"{what}: node '{node.name}' ({node.type}) is not supported; world is black")
    return black


def _world_volume(scene, warnings):
    """The World's Volume output as a homogeneous medium filling all space (`_volume`), or
    None. Cycles' world volume: beneath every mesh's medium, and light from the sun and the
    world does not get through an infinite extent of it."""
    world = scene.world
    if world is None:
        return None
    what = f"world '{world.name}'"
    node_out = _output_node(world.node_tree, None, what)
    sock = node_out.inputs.get("Volume") if node_out is not None else None
    if sock is None or not sock.is_linked:
        return None
    return _volume(sock.links[0].from_node, 1.0, warnings, what)


def _warn_unrendered_outputs(node_out, warnings, what, skip=()):
    """A warning for each linked output socket GDMLT does not render (volumes, displacement)."""
    for socket in ("Volume", "Displacement"):
        if socket in skip:
            continue
        s = node_out.inputs.get(socket)
        if s is not None and s.is_linked:
            warnings.append(f"{what}: its {socket} output is not rendered yet (left out)")


def camera_dict(scene, cam_ob, warnings=None):
    """The scene dict's camera: Perspective, Orthographic, or Panoramic › Equirectangular (its
    latitude and longitude ranges) or Fisheye Equidistant / Equisolid (field of view, lens);
    depth of field is not rendered for a panoramic camera, warned."""
    cam = cam_ob.data
    r = scene.render
    kind = cam.type
    if kind == "PANO":
        pano = getattr(cam, "panorama_type", "")
        if pano not in ("EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT", "FISHEYE_EQUISOLID"):
            raise ValueError(f"camera '{cam_ob.name}': panoramic type {pano} is not supported (use Equirectangular, "
                             f"Fisheye Equidistant or Equisolid, Perspective or Orthographic)")
        kind = pano
    elif kind not in ("PERSP", "ORTHO"):
        raise ValueError(f"camera '{cam_ob.name}': {cam.type} cameras are not supported (use Perspective, "
                         f"Orthographic or Panoramic › Equirectangular)")
    d = {
        "matrix": _matrix(cam_ob.matrix_world).astype(np.float32), "type": kind, "lens": cam.lens,
        "sensor_width": cam.sensor_width, "sensor_height": cam.sensor_height, "sensor_fit": cam.sensor_fit,
        "ortho_scale": cam.ortho_scale, "shift_x": cam.shift_x, "shift_y": cam.shift_y,
        "clip_start": cam.clip_start, "clip_end": cam.clip_end,
        "resolution_x": r.resolution_x, "resolution_y": r.resolution_y,
        "resolution_percentage": r.resolution_percentage,
        "pixel_aspect_x": r.pixel_aspect_x, "pixel_aspect_y": r.pixel_aspect_y,
    }
    g = getattr(scene, "gdmlt", None)
    if g is not None:
        d["pixel_filter"], d["filter_width"] = g.pixel_filter_type, g.filter_width
    if r.film_transparent:
        d["film_transparent"] = True
    if kind in ("EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT", "FISHEYE_EQUISOLID"):
        for key in ("latitude_min", "latitude_max", "longitude_min", "longitude_max", "fisheye_fov", "fisheye_lens"):
            d[key] = float(getattr(cam, key))
        if cam.dof.use_dof and warnings is not None:
            warnings.append(f"camera '{cam_ob.name}': depth of field is not rendered for a panoramic camera")
    elif cam.dof.use_dof:
        d["fstop"] = cam.dof.aperture_fstop
        # the aperture's shape: blades (a polygon; fewer than 3 is round), their rotation and
        # the anamorphic ratio, as Cycles reads them
        d["aperture_blades"] = int(cam.dof.aperture_blades)
        d["aperture_rotation"] = float(cam.dof.aperture_rotation)
        d["aperture_ratio"] = float(cam.dof.aperture_ratio)
        focus = cam.dof.focus_distance
        if cam.dof.focus_object is not None:
            m = _matrix(cam_ob.matrix_world)
            axis = -m[:3, 2] / np.linalg.norm(m[:3, 2])
            target = np.array(cam.dof.focus_object.matrix_world.translation)
            focus = float(np.dot(target - m[:3, 3], axis))
        d["focus_distance"] = focus
    window = render_region(scene)
    if window is not None:
        x, y_bottom, w, h = window
        d["window"] = (x, _final_height(r) - y_bottom - h, w, h)  # the core counts rows from the top
    return d


def _final_height(r):
    return max(1, r.resolution_y * r.resolution_percentage // 100)


def render_region(scene):
    """The render region (Blender's border) in final pixels: (x, y from the bottom, width,
    height), as Blender's render result places it; None without one (or when it covers
    nothing)."""
    r = scene.render
    if not r.use_border:
        return None
    w, h = max(1, r.resolution_x * r.resolution_percentage // 100), _final_height(r)
    x0, x1 = round(r.border_min_x * w), round(r.border_max_x * w)
    y0, y1 = round(r.border_min_y * h), round(r.border_max_y * h)
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1 - x0, y1 - y0


def export_scene(depsgraph, test_break=lambda: False, need_camera=True):
    """Returns (scene dict, warnings). Raises ExportCancelled if test_break() turns true,
    ValueError for a scene that cannot be rendered (no camera, unsupported camera). Without
    `need_camera` (the viewport, which looks through its own) the dict has no camera."""
    from . import texture_graph

    scene = depsgraph.scene
    warnings = []
    if scene.camera is None and need_camera:
        raise ValueError("the scene has no active camera")
    materials = [dict(DEFAULT_SURFACE)]  # (objects without a material, empty slots)
    textures = Textures()
    mat_index = {}
    colour_layers = {}  # material index → the colour attribute it reads
    coordinates = {}  # material index → the mesh coordinates its procedural textures read
    meshes, lights = [], []
    sources = {"meshes": [], "lights": []}  # the object each came from (light linking)
    cache = {}
    groups = {}  # an instanced mesh's arrays and object settings → its instances' transforms
    same_group = {}  # (object, mesh, instancer) names → its group, where no material reads the instance
    instanced = []  # (mesh dict, its group)
    variants = {}  # material name → (the Object Info outputs it reads, its variants) or None
    for k, inst in enumerate(depsgraph.object_instances):
        if k % 64 == 0 and test_break():
            raise ExportCancelled()
        ob = inst.object
        if ob.type == "LIGHT":
            _visibility_warnings(ob, "light", warnings, light=True)
            l = _light(ob, _matrix(inst.matrix_world), warnings)
            if l is not None:
                if not getattr(ob.data, "use_shadow", True):  # (Light › Cast Shadow off)
                    l["cast_shadow"] = False
                lights.append(l)
                sources["lights"].append(ob)
            continue
        if ob.type not in GEOMETRY_TYPES:
            continue
        if ob.type in NOT_RENDERED:
            warnings.append(f"object '{ob.name}': {NOT_RENDERED[ob.type]} are not rendered yet; it is left out")
            continue
        if inst.is_instance:
            # another instance of an object whose materials read nothing of the instance
            # (no Object Info): only its transform is new
            fast = (ob.name, ob.data.name if ob.data is not None else "", inst.parent.name if inst.parent else "")
            group = same_group.get(fast)
            if group is not None:
                groups[group].append(np.array(inst.matrix_world, dtype=np.float32)[:3].reshape(12))
                continue
        _visibility_warnings(ob, "object", warnings)
        slot_to_global = []
        per_instance = False  # a material reads Object Info
        for slot in ob.material_slots:
            mat = slot.material
            if mat is None:
                slot_to_global.append(0)
                continue
            info = _object_info(inst, ob, mat, variants, warnings)
            per_instance |= info is not None
            key = mat.name if info is None else (mat.name, info)
            if key not in mat_index:
                mat_index[key] = len(materials)
                with texture_graph.object_info(info):
                    params = material_params(mat, warnings, textures)
                if "density" in params.get("volume", {}):
                    # (a density field reads this object's coordinates; other objects with the
                    # material share them)
                    _density_coordinates(params["volume"], ob, inst.matrix_world)
                colour_layers[len(materials)] = params.pop("vertex_color_layer", None)
                coordinates[len(materials)] = _mesh_coordinates(params, textures)
                materials.append(params)
            slot_to_global.append(mat_index[key])
        layer = _colour_layer(ob, [colour_layers.get(i) for i in slot_to_global], warnings)
        spaces = tuple(sorted(set().union(*(coordinates.get(i, ()) for i in slot_to_global))))
        key = (ob.name, ob.data.name if ob.data is not None else "", layer, spaces) if inst.is_instance else None
        arrays = cache.get(key) if key else None
        if arrays is None:
            arrays = _mesh_local_arrays(ob, layer, spaces)
            if key:
                cache[key] = arrays
        if arrays is None:
            continue
        co, tris, normals, mat_local, uvs, colours, points = arrays
        if layer is not None and colours is None:
            warnings.append(f"object '{ob.name}': its material reads the colour attribute "
                            f"{repr(layer) if layer else '(the default one)'}, which its mesh does not have: black, "
                            f"as in Cycles")
        table = np.array(slot_to_global or [0], dtype=np.uint32)
        mat_ids = table[np.clip(mat_local, 0, len(table) - 1)]
        m = _matrix(inst.matrix_world)
        visibility = tuple(key for key in ("visible_camera", "visible_shadow")  # (Object › Visibility › Ray Visibility)
                           if not getattr(ob, key, True))
        holdout = _holdout(ob, inst, depsgraph)
        # Object › Shading › Shadow Terminator (src/scene/terminator.rs)
        offset = float(getattr(ob, "shadow_terminator_geometry_offset", 0.1))
        if getattr(ob, "shadow_terminator_shading_offset", 0.0) > 0.0:
            warnings.append(f"object '{ob.name}': Shadow Terminator › Shading Offset is not rendered (0 is used)")
        if inst.is_instance:
            # an instance: its mesh is stored once, in object space, with the transforms of
            # every instance that shares its materials and object settings (the core places
            # them; src/instancing.rs)
            group = (key, tuple(slot_to_global), visibility, holdout, ob.pass_index, offset)
            if not per_instance:
                same_group[fast] = group
            if group in groups:
                groups[group].append(m[:3, :].reshape(12))
                continue
            groups[group] = [m[:3, :].reshape(12)]
            pos, nrm = co, normals
            name = f"{inst.parent.name if inst.parent else ''}/{ob.name}"
        else:
            pos = (co.astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
            det = np.linalg.det(m[:3, :3])
            nmat = np.linalg.inv(m[:3, :3]).T if abs(det) > 1e-30 else m[:3, :3]
            nrm = None if normals is None else (normals.astype(np.float64) @ nmat.T).astype(np.float32)
            if det < 0:
                # a mirroring transform winds the faces inside out; the core takes the outside
                # (how glass refracts) from the winding, so wind them back, as Cycles negates
                # the geometric normal of negatively scaled objects
                tris = tris[:, ::-1]
                nrm = None if nrm is None else nrm.reshape(-1, 3, 3)[:, ::-1].reshape(-1, 3)
                uvs = None if uvs is None else uvs.reshape(-1, 3, 2)[:, ::-1].reshape(-1, 2)
                colours = None if colours is None else colours.reshape(-1, 3, 3)[:, ::-1].reshape(-1, 3)
                points = {k: p.reshape(-1, 3, 3)[:, ::-1].reshape(-1, 3) for k, p in points.items()}
            name = ob.name
        sources["meshes"].append(ob)
        meshes.append(scenedict.mesh(name, np.ascontiguousarray(pos), np.ascontiguousarray(tris, dtype=np.uint32),
                                     None if nrm is None else np.ascontiguousarray(nrm), mat_ids, uvs, ob.pass_index,
                                     None if colours is None else np.ascontiguousarray(colours)))
        if inst.is_instance:
            instanced.append((meshes[-1], group))
        for space, p in points.items():
            meshes[-1][space.lower()] = np.ascontiguousarray(p)
        for flag in visibility:
            meshes[-1][flag] = False
        if holdout:
            meshes[-1]["holdout"] = True
        if abs(offset - 0.1) > 1e-6:
            meshes[-1]["shadow_terminator_offset"] = min(max(offset, 0.0), 1.0)
    for mesh, group in instanced:
        mesh["transforms"] = np.ascontiguousarray(groups[group], dtype=np.float32)
    world, world_texture, world_rotation, backdrop = _world(scene, warnings, textures)
    if scene.render.use_motion_blur:
        warnings.append("motion blur is not rendered yet: the frame is rendered at its shutter's start")
    desc = {"meshes": meshes, "materials": materials, "textures": textures.items, "lights": lights,
            "world": world, "world_texture": world_texture}
    if world_rotation is not None:
        desc["world_rotation"] = world_rotation
    world_volume = _world_volume(scene, warnings)
    if world_volume is not None:
        desc["world_volume"] = world_volume
    desc.update({k: True for k, older in _cycles_release_choices().items() if older})
    _light_linking(meshes, lights, sources, desc, warnings)
    if need_camera:
        desc["camera"] = camera_dict(scene, scene.camera.evaluated_get(depsgraph), warnings)
        if backdrop is not None:
            desc["camera"].update(backdrop)
    # the same warning once
    seen = set()
    warnings = [w for w in warnings if not (w in seen or seen.add(w))]
    return desc, warnings
