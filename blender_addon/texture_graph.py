"""Texture node graphs evaluated at export: the colour and value nodes artists put between an
Image Texture and a shader input (Color Ramp or RGB Curves on a roughness map, Separate Color on a packed
AO/roughness/metallic map, Mix › Multiply of a colour map and a tint, Math, Invert, Hue/
Saturation, Brightness/Contrast, Gamma, Map Range, Clamp, RGB to BW) are pointwise: the
value at a shading point is a function of the images' values there. So the graph is
evaluated once per point of a grid over its largest image and handed to the core as one
linear float texture, looked up with the images' own UV transform and extension.

Exact at the grid's points: each image is looked up there as the core looks it up
(bilinear or closest, 8-bit sRGB decoded after interpolation, as Cycles), and the nodes
compute what Cycles' do. Between them the core interpolates the result where Cycles runs
the graph on interpolated inputs, so a graph over interpolated images is evaluated on a
grid up to 16× finer than the image (at most 1024 texels across, 4M in all): a Color Ramp
step on a magnified 8×8 image is then sharp to 1/128 of the image, where at the image's own
resolution it rendered 5% off Cycles. Over Closest images the grid is the image's own.

A graph over one procedural texture instead of images (Noise, Voronoi, Wave, Brick, Checker, Gradient) is a
function of that texture's output alone: it is evaluated on a table of the output's values
over its range (`_PROCEDURAL_TABLES`), which the core looks up after computing the pattern
per shading point (src/scene/procedural.rs). A Noise's, Voronoi's or Brick's Color output
(three values) only when it feeds the input straight, a Checker's or Brick's colours only
from constants.

A graph with no image in it is a constant (a Math node on two values, a Mix of two colours):
its value. An Object Info node is a constant of the object being exported (`object_info`:
the exporter evaluates such a material once per object). A graph with a node outside this set, images under different UV transforms or
extensions, or a loop is not evaluated: `evaluate` raises Unsupported naming it, the
exporter warns, and the input keeps its unlinked value.

Each node's arithmetic follows Blender's documented node behaviour (the Cycles manual's
node pages); colour into value is Rec.709 luminance, value into colour is grey.
"""

import contextlib
import math

import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
# Cycles tabulates a Color Ramp at 256 positions over [0, 1] and interpolates that table
RAMP_TABLE = 256
CHUNK = 1 << 20


class Unsupported(Exception):
    """A node (or a combination of them) the evaluator does not render."""


class _Colour:
    """A colour: (N, 3) float32 (N = 1 for a constant)."""

    def __init__(self, a):
        self.a = a


class _Value:
    """A value: (N,) float32."""

    def __init__(self, a):
        self.a = a


def _as_colour(v):
    return v if isinstance(v, _Colour) else _Colour(np.repeat(v.a[:, None], 3, axis=1))


def _as_value(v):
    return v if isinstance(v, _Value) else _Value(v.a @ LUMA)


_SRGB_TABLE = np.arange(256, dtype=np.float64) / 255.0
_SRGB_TABLE = np.where(_SRGB_TABLE <= 0.04045, _SRGB_TABLE / 12.92,
                       ((_SRGB_TABLE + 0.055) / 1.055) ** 2.4).astype(np.float32)


def srgb_to_linear(c, exact_bytes=False):
    """The sRGB transfer function inverted; `exact_bytes`: every value is k/255 (an 8-bit
    image's own texels), looked up in a table."""
    if exact_bytes:
        return _SRGB_TABLE[(c * np.float32(255.0) + np.float32(0.5)).astype(np.uint8)]
    c = c.astype(np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _resample(px, w, h, gw, gh, extension, closest):
    """The image `px` ((h·w, k), row 0 at the bottom) looked up at the texel centres of a
    gw × gh grid over the same UV square, as the core looks it up (bilinear or closest)."""
    if (w, h) == (gw, gh):
        return px
    u = (np.arange(gw) + 0.5) / gw * w - 0.5
    v = (np.arange(gh) + 0.5) / gh * h - 0.5
    img = px.reshape(h, w, -1)

    def wrap(i, n):
        return np.mod(i, n) if extension == "REPEAT" else np.clip(i, 0, n - 1)

    if closest:
        xi, yi = wrap(np.floor(u + 0.5).astype(int), w), wrap(np.floor(v + 0.5).astype(int), h)
        return img[yi][:, xi].reshape(gw * gh, -1)
    x0, y0 = np.floor(u).astype(int), np.floor(v).astype(int)
    fx, fy = (u - x0)[None, :, None], (v - y0)[:, None, None]
    xa, xb, ya, yb = wrap(x0, w), wrap(x0 + 1, w), wrap(y0, h), wrap(y0 + 1, h)
    top = img[ya][:, xa] * (1 - fx) + img[ya][:, xb] * fx
    bottom = img[yb][:, xa] * (1 - fx) + img[yb][:, xb] * fx
    return (top * (1 - fy) + bottom * fy).reshape(gw * gh, -1)


def _supersampling(w, h):
    """Texels per image texel (per axis) of the grid a graph over interpolated images is
    evaluated on: up to 1024 texels across (at most 16 per image texel, 4M texels in all), so
    that the core's interpolation of the result departs from the graph run on interpolated
    inputs (Cycles) only within a fraction of an image texel where the image is magnified."""
    k = max(1, min(16, 1024 // max(w, h)))
    while k > 1 and w * h * k * k > 1 << 22:
        k -= 1
    return k


# evaluated graphs, by what they depend on: a render or viewport update that exports the
# same material again reuses them (least recently used dropped beyond 16 or 512 MB)
_CACHE = {}
CACHE_BYTES = 512 << 20
_SETTINGS = ("blend_type", "data_type", "clamp_factor", "clamp_result", "factor_mode", "use_clamp", "operation",
             "mode", "clamp_type", "interpolation_type", "clamp", "interpolation", "extension")


def _settings(node):
    """A node's settings that its result depends on (besides its inputs)."""
    out = [node.bl_idname, node.name] + [(k, getattr(node, k)) for k in _SETTINGS if hasattr(node, k)]
    ramp = getattr(node, "color_ramp", None)
    if ramp is not None:
        out += [ramp.interpolation, ramp.color_mode, ramp.hue_interpolation,
                tuple((e.position, tuple(e.color)) for e in ramp.elements)]
    mapping = getattr(node, "mapping", None)
    if mapping is not None and hasattr(mapping, "curves"):  # (RGB Curves: every point of every curve)
        out += [mapping.extend, tuple(tuple((tuple(q.location), q.handle_type) for q in c.points)
                                      for c in mapping.curves)]
    return tuple(out)


# The outputs of an Object Info node while a material is evaluated for one object
# (`object_info`); None outside (the node is then not evaluated).
_OBJECT = None
OBJECT_INFO_OUTPUTS = ("Random", "Color", "Alpha", "Object Index", "Material Index")


@contextlib.contextmanager
def object_info(values):
    """Within: Object Info nodes output `values` (a tuple in the order of
    OBJECT_INFO_OUTPUTS: Random, Color (r, g, b), Alpha, Object Index, Material Index)."""
    global _OBJECT
    old, _OBJECT = _OBJECT, values
    try:
        yield
    finally:
        _OBJECT = old


def current_object():
    """The Object Info values in force (None outside `object_info`)."""
    return _OBJECT


def _input(node, identifier):
    for s in node.inputs:
        if s.identifier == identifier:
            return s
    raise Unsupported(f"node '{node.name}' has no input '{identifier}'")


class _Graph:
    """One evaluation: the image leaves found (first pass) and their texels on one grid."""

    def __init__(self, image_pixels, uv_key, image_identity, coords=None):
        self.image_pixels = image_pixels  # node → (pixels (h·w, 4), w, h, srgb)
        self.coords = coords  # node → (space, 3×4 matrix): the coordinates a procedural reads
        self.procedural = None  # (node, output name) of the procedural texture leaf
        self.ray = None  # (node, output identifier) of a Fresnel or Layer Weight leaf (`ray_leaf`)
        self.samples = None  # the table's values of that leaf's output
        self.domain = None  # (their first and last)
        self.image_identity = image_identity  # node → what identifies its pixels
        self.uv_key = uv_key  # node → (transform, extension, closest)
        self.images = {}  # node name → node
        self.grid = None  # (w, h), None until the leaves are read
        self.texels = {}
        self.visiting = set()
        self.signature = []  # what the result depends on besides the pixels (the cache's key)

    # --- the two passes -------------------------------------------------------------------

    def collect(self, sock):
        """Finds the image leaves under `sock` (and refuses unsupported nodes early)."""
        self._walk(sock, collect=True)

    def run(self, sock):
        """Loads the leaves' texels on the grid (or takes the cached result), then evaluates
        `sock` in slices of 1M texels (a 4K map's temporaries stay at tens of MB)."""
        if self.procedural is not None:
            if self.images:
                raise Unsupported(f"procedural texture '{self.procedural[0].name}' together with images")
            node, out_name = self.procedural
            self.domain = _procedural_domain(node, _pattern(node, out_name))
            self.samples = np.linspace(*self.domain, _PROCEDURAL_TABLES[node.type], dtype=np.float32)
        if not self.images:
            return self._walk(sock, collect=False)
        keys = {name: self.uv_key(n) for name, n in self.images.items()}
        if len({(k[0], k[1]) for k in keys.values()}) > 1:
            raise Unsupported("its images use different UV transforms or extensions")
        key = (tuple(self.signature), tuple(sorted(keys.items())),
               tuple((name, self.image_identity(n)) for name, n in sorted(self.images.items())))
        hit = _CACHE.get(key)
        if hit is not None:
            self.grid = hit[0]
            _CACHE[key] = _CACHE.pop(key)  # (most recently used last)
            return hit[1]
        loaded, full = {name: self.image_pixels(n) for name, n in self.images.items()}, {}
        _, w, h, _ = max(loaded.values(), key=lambda t: t[1] * t[2])
        k = 1 if all(uv[2] for uv in keys.values()) else _supersampling(w, h)
        self.grid = (w * k, h * k)
        for name, (px, w, h, srgb) in loaded.items():
            _, ext, closest = keys[name]
            same = (w, h) == self.grid
            px = _resample(px, w, h, *self.grid, ext, closest).astype(np.float32, copy=False)
            if srgb:  # (decoded after interpolation, as Cycles decodes 8-bit images)
                px = np.concatenate([srgb_to_linear(px[:, :3], exact_bytes=same), px[:, 3:]], axis=1)
            full[name] = px
        n, parts = self.grid[0] * self.grid[1], []
        for a in range(0, n, CHUNK):
            self.texels = {name: px[a:a + CHUNK] for name, px in full.items()}
            v = self._walk(sock, collect=False)
            m = min(CHUNK, n - a)
            parts.append(v.a if len(v.a) == m else np.broadcast_to(v.a, (m,) + v.a.shape[1:]))
        result = type(v)(np.concatenate(parts))
        _CACHE[key] = (self.grid, result)
        while len(_CACHE) > 1 and (len(_CACHE) > 16 or sum(r.a.nbytes for _, r in _CACHE.values()) > CACHE_BYTES):
            _CACHE.pop(next(iter(_CACHE)))
        return result

    # --- sockets and nodes ----------------------------------------------------------------

    def _walk(self, sock, collect):
        """The value at input socket `sock` (a node_view.SocketView: groups, reroutes, muted
        nodes and links already followed): its link's source output, else its own value."""
        if not sock.is_linked:
            return self._unlinked(sock, collect)
        link = sock.links[0]
        node, out = link.from_node, link.from_socket
        if collect:
            self.signature.append((sock.identifier, node.name, out.identifier))
        if node.name in self.visiting:
            raise Unsupported(f"its nodes form a loop through '{node.name}'")
        self.visiting.add(node.name)
        try:
            v = self._node(node, out, collect)
        finally:
            self.visiting.discard(node.name)
        # the destination's type decides the conversion (colour into value: luminance)
        if collect:
            return None
        return _as_value(v) if sock.type == "VALUE" else _as_colour(v) if sock.type == "RGBA" else v

    def _unlinked(self, sock, collect):
        v = sock.default_value
        if collect and sock.type in ("RGBA", "VALUE"):
            self.signature.append((sock.identifier, tuple(v) if sock.type == "RGBA" else float(v)))
        if sock.type == "RGBA":
            return _Colour(np.array([tuple(v)[:3]], np.float32))
        if sock.type == "VALUE":
            return _Value(np.array([float(v)], np.float32))
        raise Unsupported(f"an unlinked {sock.type.lower()} input '{sock.name}'")

    def _node(self, node, out, collect):
        t = node.type
        walk = (lambda ident: self._walk(_input(node, ident), collect))
        if collect:
            self.signature.append(_settings(node))
        if t == "RGB":
            return _Colour(np.array([tuple(node.outputs[0].default_value)[:3]], np.float32))
        if t == "VALUE":
            return _Value(np.array([float(node.outputs[0].default_value)], np.float32))
        if t == "TEX_IMAGE":
            if out.name not in ("Color", "Alpha"):
                raise Unsupported(f"output '{out.name}' of '{node.name}'")
            if node.image is None:
                raise Unsupported(f"Image Texture '{node.name}' has no image")
            if collect:
                self.images[node.name] = node
                return None
            px = self.texels[node.name]
            return _Value(px[:, 3]) if out.name == "Alpha" else _Colour(px[:, :3])
        if t in _PROCEDURAL_TABLES:
            return self._procedural(node, out, walk, collect)
        if (t, out.identifier) in RAY_LEAVES:
            return self._ray(node, out, collect)
        if t == "OBJECT_INFO":
            return self._object_info(node, out, collect)
        op = _NODES.get(t)
        if op is None:
            raise Unsupported(f"node '{node.name}' ({t})")
        return op(node, out, walk, collect)

    def _ray(self, node, out, collect):
        """A Fresnel or Layer Weight leaf (a factor the core computes from the ray, in
        [0, 1]): its output at the table's values."""
        if collect:
            if self.ray is not None and self.ray[0].name != node.name:
                raise Unsupported(f"two view factors ('{self.ray[0].name}', '{node.name}')")
            if self.coords is not None or self.images or self.procedural is not None:
                raise Unsupported(f"'{node.name}' ({node.type}) here (only into a Mix Shader's factor, alone)")
            self.ray = (node, out.identifier)
            return None
        return _Value(self.samples)

    def _object_info(self, node, out, collect):
        """An Object Info output: the object's constant (`object_info`)."""
        v = _OBJECT[OBJECT_INFO_OUTPUTS.index(out.identifier)] if (
            _OBJECT is not None and out.identifier in OBJECT_INFO_OUTPUTS) else None
        if v is None:
            raise Unsupported(f"output '{out.name}' of '{node.name}' (Object Info)")
        if collect:
            self.signature.append(("object", out.identifier, v))
            return None
        if out.identifier == "Color":
            return _Colour(np.array([v[:3]], np.float32))
        return _Value(np.array([v], np.float32))

    def _procedural(self, node, out, walk, collect):
        """A procedural texture leaf: its output at the table's values."""
        if collect:
            if self.procedural is not None and self.procedural[0].name != node.name:
                raise Unsupported(f"two procedural textures ('{self.procedural[0].name}', '{node.name}')")
            if self.coords is None:
                raise Unsupported(f"procedural texture '{node.name}' (into a constant input)")
            _check_procedural(node, out)
            self.procedural = (node, out.identifier)
            if node.type == "TEX_CHECKER":
                _all(walk, collect, "Color1", "Color2")
            return None
        s = self.samples
        if node.type == "TEX_CHECKER" and out.identifier == "Color":
            c1, c2 = (_as_colour(c).a for c in _all(walk, collect, "Color1", "Color2"))
            return _Colour(np.where(s[:, None] == 1.0, c1, c2))
        if out.identifier == "Color":  # (a Gradient's or Wave's grey, or three channels the core computes)
            return _Colour(np.repeat(s[:, None], 3, axis=1))
        return _Value(s)


# --- the nodes' arithmetic (each: (node, output, walk, collect) → _Colour | _Value) -------------


def _all(walk, collect, *idents):
    vals = [walk(i) for i in idents]
    return None if collect else vals


def _lerp(a, b, t):
    return a + (b - a) * t


def _rgb_to_hsv(c):
    r, g, b = c[:, 0], c[:, 1], c[:, 2]
    mx, mn = c.max(axis=1), c.min(axis=1)
    d = mx - mn
    s = np.where(mx > 0, d / np.where(mx > 0, mx, 1), 0.0)
    dd = np.where(d > 0, d, 1)
    h = np.where(mx == r, (g - b) / dd, np.where(mx == g, 2 + (b - r) / dd, 4 + (r - g) / dd)) / 6.0
    h = np.where(d > 0, np.mod(h, 1.0), 0.0)
    return np.stack([h, s, mx], axis=1)


def _hsv_to_rgb(hsv):
    h, s, v = hsv[:, 0:1], hsv[:, 1:2], hsv[:, 2:3]
    # each channel n ∈ {5, 3, 1}: v − v·s·clamp(min(k, 4 − k), 0, 1), k = (n + 6h) mod 6
    k = np.mod(np.array([5.0, 3.0, 1.0], np.float32) + 6.0 * np.mod(h, 1.0), 6.0)
    return v - v * s * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)


def _blend(mode, t, a, b):
    """Blender's colour blend modes (Mix node, Color type): a = A, b = B, t = factor (N, 1)."""
    if mode == "MIX":
        return _lerp(a, b, t)
    if mode == "ADD":
        return a + t * b
    if mode == "MULTIPLY":
        return a * (1 - t + t * b)
    if mode == "SUBTRACT":
        return a - t * b
    if mode == "SCREEN":
        return 1 - (1 - t + t * (1 - b)) * (1 - a)
    if mode == "DIVIDE":
        return np.where(b != 0, (1 - t) * a + t * a / np.where(b != 0, b, 1), a)
    if mode == "DIFFERENCE":
        return _lerp(a, np.abs(a - b), t)
    if mode == "EXCLUSION":
        return np.maximum(_lerp(a, a + b - 2 * a * b, t), 0.0)
    if mode == "DARKEN":
        return _lerp(a, np.minimum(a, b), t)
    if mode == "LIGHTEN":
        return _lerp(a, np.maximum(a, b), t)
    if mode == "OVERLAY":
        return np.where(a < 0.5, a * (1 - t + 2 * t * b), 1 - (1 - t + 2 * t * (1 - b)) * (1 - a))
    if mode == "SOFT_LIGHT":
        screen = 1 - (1 - b) * (1 - a)
        return (1 - t) * a + t * ((1 - a) * b * a + a * screen)
    if mode == "LINEAR_LIGHT":
        return a + t * (2 * b - 1)
    if mode == "DODGE":
        d = 1 - t * b
        return np.where(a == 0, a, np.where(d <= 0, 1.0, np.minimum(a / np.where(d > 0, d, 1), 1.0)))
    if mode == "BURN":
        d = (1 - t) + t * b
        return np.where(d <= 0, 0.0, np.clip(1 - (1 - a) / np.where(d > 0, d, 1), 0.0, 1.0))
    if mode in ("HUE", "SATURATION", "VALUE", "COLOR"):
        ha, hb = _rgb_to_hsv(a), _rgb_to_hsv(b)
        new = ha.copy()
        if mode == "VALUE":
            new[:, 2] = hb[:, 2]
        elif mode == "SATURATION":
            new[:, 1] = np.where(ha[:, 1] != 0, hb[:, 1], ha[:, 1])
        elif mode == "HUE":
            new[:, 0] = np.where(hb[:, 1] != 0, hb[:, 0], ha[:, 0])
        else:
            has = hb[:, 1] != 0
            new[:, 0] = np.where(has, hb[:, 0], ha[:, 0])
            new[:, 1] = np.where(has, hb[:, 1], ha[:, 1])
        return _lerp(a, _hsv_to_rgb(new), t)
    raise Unsupported(f"blend mode {mode}")


def _broadcast(*arrays):
    n = max(len(x) for x in arrays)
    return [np.broadcast_to(x, (n,) + x.shape[1:]) if len(x) != n else x for x in arrays]


def _mix(node, out, walk, collect):
    if node.type == "MIX_RGB":
        idents, mode, clamp_t, clamp_out, kind = ("Fac", "Color1", "Color2"), node.blend_type, True, node.use_clamp, "RGBA"
    else:
        kind = node.data_type
        if kind not in ("RGBA", "FLOAT") or getattr(node, "factor_mode", "UNIFORM") != "UNIFORM":
            raise Unsupported(f"Mix node '{node.name}' of type {kind}")
        suffix = "Color" if kind == "RGBA" else "Float"
        idents = ("Factor_Float", f"A_{suffix}", f"B_{suffix}")
        mode, clamp_t, clamp_out = node.blend_type, node.clamp_factor, kind == "RGBA" and node.clamp_result
    vals = _all(walk, collect, *idents)
    if collect:
        return None
    t, a, b = _as_value(vals[0]).a, vals[1], vals[2]
    if clamp_t:
        t = np.clip(t, 0.0, 1.0)
    if kind == "FLOAT":
        t, a, b = _broadcast(t, _as_value(a).a, _as_value(b).a)
        return _Value(_lerp(a, b, t))
    t, a, b = _broadcast(t[:, None], _as_colour(a).a, _as_colour(b).a)
    r = _blend(mode, t, a, b)
    return _Colour(np.clip(r, 0.0, 1.0) if clamp_out else r)


def _safe(fn, ok, a, *rest):
    """fn where `ok`, else 0 (Cycles' safe_ math functions)."""
    with np.errstate(all="ignore"):
        r = fn(a, *rest)
    return np.where(ok, r, 0.0)


def _math_op(op, a, b, c):
    with np.errstate(all="ignore"):
        table = {
            "ADD": lambda: a + b,
            "SUBTRACT": lambda: a - b,
            "MULTIPLY": lambda: a * b,
            "DIVIDE": lambda: _safe(lambda x, y: x / y, b != 0, a, b),
            "MULTIPLY_ADD": lambda: a * b + c,
            "POWER": lambda: _safe(np.power, ~((a < 0) & (b != np.floor(b))), a, b),
            "LOGARITHM": lambda: _safe(lambda x, y: np.log(x) / np.log(y), (a > 0) & (b > 0), a, b),
            "SQRT": lambda: _safe(np.sqrt, a > 0, a),
            "INVERSE_SQRT": lambda: _safe(lambda x: 1 / np.sqrt(x), a > 0, a),
            "ABSOLUTE": lambda: np.abs(a),
            "EXPONENT": lambda: np.exp(a),
            "MINIMUM": lambda: np.minimum(a, b),
            "MAXIMUM": lambda: np.maximum(a, b),
            "LESS_THAN": lambda: (a < b).astype(np.float32),
            "GREATER_THAN": lambda: (a > b).astype(np.float32),
            "SIGN": lambda: np.sign(a),
            "COMPARE": lambda: (np.abs(a - b) <= np.maximum(c, 1e-5)).astype(np.float32),
            "ROUND": lambda: np.floor(a + 0.5),
            "FLOOR": lambda: np.floor(a),
            "CEIL": lambda: np.ceil(a),
            "TRUNC": lambda: np.trunc(a),
            "FRACT": lambda: a - np.floor(a),
            "MODULO": lambda: _safe(np.fmod, b != 0, a, b),
            "FLOORED_MODULO": lambda: _safe(lambda x, y: x - np.floor(x / y) * y, b != 0, a, b),
            "SNAP": lambda: _safe(lambda x, y: np.floor(x / y) * y, b != 0, a, b),
            "SINE": lambda: np.sin(a),
            "COSINE": lambda: np.cos(a),
            "TANGENT": lambda: np.tan(a),
            "ARCSINE": lambda: np.arcsin(np.clip(a, -1, 1)),
            "ARCCOSINE": lambda: np.arccos(np.clip(a, -1, 1)),
            "ARCTANGENT": lambda: np.arctan(a),
            "ARCTAN2": lambda: np.arctan2(a, b),
            "RADIANS": lambda: a * (math.pi / 180),
            "DEGREES": lambda: a * (180 / math.pi),
        }
        if op not in table:
            raise Unsupported(f"Math operation {op}")
        return table[op]()


def _math(node, out, walk, collect):
    vals = _all(walk, collect, "Value", "Value_001", "Value_002")
    if collect:
        return None
    a, b, c = _broadcast(*(_as_value(v).a for v in vals))
    r = _math_op(node.operation, a, b, c)
    return _Value(np.clip(r, 0.0, 1.0) if node.use_clamp else r)


def _ramp(node, out, walk, collect):
    vals = _all(walk, collect, "Fac")
    if collect:
        return None
    ramp = node.color_ramp
    table = np.array([tuple(ramp.evaluate(i / (RAMP_TABLE - 1))) for i in range(RAMP_TABLE)], np.float32)
    f = np.clip(_as_value(vals[0]).a, 0.0, 1.0) * (RAMP_TABLE - 1)
    i = np.clip(f.astype(int), 0, RAMP_TABLE - 1)
    rgba = table[i]
    if ramp.interpolation != "CONSTANT":
        j = np.minimum(i + 1, RAMP_TABLE - 1)
        rgba = rgba + (table[j] - rgba) * (f - i)[:, None]
    return _Value(rgba[:, 3]) if out.name == "Alpha" else _Colour(rgba[:, :3])


def _invert(node, out, walk, collect):
    vals = _all(walk, collect, "Fac", "Color")
    if collect:
        return None
    t, c = _broadcast(_as_value(vals[0]).a[:, None], _as_colour(vals[1]).a)
    return _Colour(_lerp(c, 1 - c, t))


def _blackbody(node, out, walk, collect):
    """Blackbody: Blender's colour of the temperature (blackbody.py: Rec.709, luminance 1)."""
    from .blackbody import colour

    vals = _all(walk, collect, "Temperature")
    if collect:
        return None
    return _Colour(colour(_as_value(vals[0]).a))


def _curves(node, out, walk, collect):
    """RGB Curves: each channel through the combined curve, then its own (R(C(r)), …), mixed
    with the input by the factor; the curves tabulated at 1024 points over the inputs' range
    (Blender's own evaluation at each)."""
    vals = _all(walk, collect, "Fac", "Color")
    if collect:
        return None
    mapping = node.mapping
    if tuple(mapping.black_level) != (0.0, 0.0, 0.0) or tuple(mapping.white_level) != (1.0, 1.0, 1.0):
        raise Unsupported(f"RGB Curves '{node.name}' with black or white levels")
    mapping.initialize()
    t, c = _broadcast(_as_value(vals[0]).a[:, None], _as_colour(vals[1]).a)
    lo, hi = min(0.0, float(c.min())), max(1.0, float(c.max()))
    xs = np.linspace(lo, hi, 1024)
    combined = np.array([mapping.evaluate(mapping.curves[3], float(x)) for x in xs])
    lo2, hi2 = min(lo, float(combined.min())), max(hi, float(combined.max()))
    xs2 = np.linspace(lo2, hi2, 1024)
    out_c = np.empty_like(c)
    for k in range(3):
        own = np.array([mapping.evaluate(mapping.curves[k], float(x)) for x in xs2])
        out_c[:, k] = np.interp(np.interp(c[:, k], xs, combined), xs2, own)
    return _Colour(_lerp(c, out_c, t))


def _gamma(node, out, walk, collect):
    vals = _all(walk, collect, "Color", "Gamma")
    if collect:
        return None
    c, g = _broadcast(_as_colour(vals[0]).a, _as_value(vals[1]).a[:, None])
    with np.errstate(all="ignore"):
        return _Colour(np.where(c > 0, np.power(np.maximum(c, 1e-30), g), c))


def _bright_contrast(node, out, walk, collect):
    vals = _all(walk, collect, "Color", "Bright", "Contrast")
    if collect:
        return None
    c, br, co = _broadcast(_as_colour(vals[0]).a, _as_value(vals[1]).a[:, None], _as_value(vals[2]).a[:, None])
    return _Colour(np.maximum((1 + co) * c + (br - co * 0.5), 0.0))


def _hue_sat(node, out, walk, collect):
    vals = _all(walk, collect, "Hue", "Saturation", "Value", "Fac", "Color")
    if collect:
        return None
    hue, sat, val, fac = (_as_value(v).a for v in vals[:4])
    c = _as_colour(vals[4]).a
    hue, sat, val, fac, c = _broadcast(hue, sat, val, fac, c)
    hsv = _rgb_to_hsv(c)
    hsv[:, 0] = np.mod(hsv[:, 0] + hue + 0.5, 1.0)
    hsv[:, 1] = np.clip(hsv[:, 1] * sat, 0.0, 1.0)
    hsv[:, 2] = hsv[:, 2] * val
    return _Colour(np.maximum(_lerp(c, _hsv_to_rgb(hsv), fac[:, None]), 0.0))


def _separate(node, out, walk, collect):
    if getattr(node, "mode", "RGB") != "RGB":
        raise Unsupported(f"Separate Color '{node.name}' in {node.mode} mode")
    vals = _all(walk, collect, "Color" if node.type == "SEPARATE_COLOR" else "Image")
    if collect:
        return None
    k = {"Red": 0, "Green": 1, "Blue": 2, "R": 0, "G": 1, "B": 2}[out.name]
    return _Value(_as_colour(vals[0]).a[:, k])


def _combine(node, out, walk, collect):
    if getattr(node, "mode", "RGB") != "RGB":
        raise Unsupported(f"Combine Color '{node.name}' in {node.mode} mode")
    idents = ("Red", "Green", "Blue") if node.type == "COMBINE_COLOR" else ("R", "G", "B")
    vals = _all(walk, collect, *idents)
    if collect:
        return None
    return _Colour(np.stack(_broadcast(*(_as_value(v).a for v in vals)), axis=1))


def _to_bw(node, out, walk, collect):
    vals = _all(walk, collect, "Color")
    return None if collect else _as_value(vals[0])


def _clamp(node, out, walk, collect):
    vals = _all(walk, collect, "Value", "Min", "Max")
    if collect:
        return None
    v, lo, hi = _broadcast(*(_as_value(x).a for x in vals))
    if node.clamp_type == "RANGE":
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
    return _Value(np.minimum(np.maximum(v, lo), hi))


def _map_range(node, out, walk, collect):
    if node.data_type != "FLOAT":
        raise Unsupported(f"Map Range '{node.name}' of type {node.data_type}")
    vals = _all(walk, collect, "Value", "From Min", "From Max", "To Min", "To Max", "Steps")
    if collect:
        return None
    v, fmin, fmax, tmin, tmax, steps = _broadcast(*(_as_value(x).a for x in vals))
    with np.errstate(all="ignore"):
        span = fmax - fmin
        f = np.where(span != 0, (v - fmin) / np.where(span != 0, span, 1), 0.0)
        kind = node.interpolation_type
        if kind == "STEPPED":
            f = np.where(steps > 0, np.floor(f * (steps + 1)) / np.where(steps > 0, steps, 1), 0.0)
        elif kind in ("SMOOTHSTEP", "SMOOTHERSTEP"):
            lo, hi = np.minimum(fmin, fmax), np.maximum(fmin, fmax)
            s = np.clip(np.where(hi > lo, (v - lo) / np.where(hi > lo, hi - lo, 1), 0.0), 0.0, 1.0)
            s = s * s * (3 - 2 * s) if kind == "SMOOTHSTEP" else s ** 3 * (s * (s * 6 - 15) + 10)
            f = np.where(fmin > fmax, 1 - s, s)
        elif kind != "LINEAR":
            raise Unsupported(f"Map Range interpolation {kind}")
    r = tmin + f * (tmax - tmin)
    if node.clamp and kind in ("LINEAR", "STEPPED"):
        r = np.clip(r, np.minimum(tmin, tmax), np.maximum(tmin, tmax))
    return _Value(r)


# --- procedural textures (evaluated per point by the core; the graph after them tabulated) ----

# table entries over the output's range, per node type
_PROCEDURAL_TABLES = {"TEX_NOISE": 2048, "TEX_VORONOI": 4096, "TEX_WAVE": 2048, "TEX_BRICK": 1024,
                      "TEX_CHECKER": 2, "TEX_GRADIENT": 1024}
_NOISE_INPUTS = ("Scale", "Detail", "Roughness", "Lacunarity", "Offset", "Gain", "Distortion")
_WAVE_INPUTS = ("Scale", "Distortion", "Detail", "Detail Scale", "Detail Roughness", "Phase Offset")
_BRICK_INPUTS = ("Color1", "Color2", "Mortar", "Scale", "Mortar Size", "Mortar Smooth", "Bias", "Brick Width",
                 "Row Height")
_VORONOI_INPUTS = ("Scale", "Detail", "Roughness", "Lacunarity", "Randomness", "Exponent")
# outputs whose value (not colour) is the pattern, and colour outputs of three values
_SCALAR_OUTPUTS = {"TEX_NOISE": "Fac", "TEX_VORONOI": "Distance", "TEX_WAVE": "Fac", "TEX_BRICK": "Fac",
                   "TEX_CHECKER": "Fac", "TEX_GRADIENT": "Fac"}
# the colour outputs the core computes itself (three values, or the Brick's colours): only
# straight into a shader input, through an identity table
_COLOUR_OUTPUTS = ("TEX_NOISE", "TEX_VORONOI", "TEX_BRICK")


def _check_procedural(node, out):
    """Refuses what the core does not compute: a linked parameter, a Noise or Voronoi that is
    not 3D, Voronoi features other than F1 and F2, an output it does not compute (a colour
    output through other nodes is checked by the caller)."""
    params = {"TEX_NOISE": _NOISE_INPUTS, "TEX_VORONOI": _VORONOI_INPUTS, "TEX_WAVE": _WAVE_INPUTS,
              "TEX_BRICK": _BRICK_INPUTS, "TEX_CHECKER": ("Scale",), "TEX_GRADIENT": ()}[node.type]
    for name in params:
        if name in node.inputs and node.inputs[name].is_linked:
            raise Unsupported(f"the linked input '{name}' of procedural texture '{node.name}'")
    if node.type == "TEX_NOISE":
        if node.noise_dimensions != "3D":
            raise Unsupported(f"Noise Texture '{node.name}' in {node.noise_dimensions} (3D is rendered)")
    if node.type == "TEX_VORONOI":
        if node.voronoi_dimensions != "3D":
            raise Unsupported(f"Voronoi Texture '{node.name}' in {node.voronoi_dimensions} (3D is rendered)")
        if node.feature not in ("F1", "F2"):
            raise Unsupported(f"Voronoi Texture '{node.name}' feature {node.feature} (F1 and F2 are rendered)")
    if out.identifier not in (_SCALAR_OUTPUTS[node.type], "Color"):
        raise Unsupported(f"output '{out.name}' of '{node.name}'")


def _procedural_domain(node, params):
    """The range of a procedural texture's output (`params`: its pattern's description) that
    its table covers: [0, 1] for Checker, Gradient and Wave (within it); a Noise's fBm
    within ±1.02 per octave's amplitude, mapped to [0, 1] when normalised; Voronoi distances
    within 3 (twice for F2) per octave's amplitude, about 2 normalised; the multifractal
    Noise types over the range the core samples (`gdmlt.procedural_range`)."""
    if node.type == "TEX_VORONOI":
        if node.normalize:
            return 0.0, 2.5
        detail = min(max(float(node.inputs["Detail"].default_value), 0.0), 15.0)
        rough = min(max(float(node.inputs["Roughness"].default_value), 0.0), 1.0)
        amp = sum(rough ** k for k in range(int(detail) + 2))
        return 0.0, 3.0 * (2.0 if node.feature == "F2" else 1.0) * amp
    if node.type == "TEX_BRICK" and params["color"]:  # (an identity table over its colours)
        return 0.0, max(1.0, *params["color1"], *params["color2"], *params["mortar"])
    if node.type != "TEX_NOISE":
        return 0.0, 1.0
    if params.get("noise_type", "FBM") != "FBM":
        import gdmlt

        return gdmlt.procedural_range(params)
    if getattr(node, "normalize", True):
        return -0.02, 1.02
    detail = min(max(float(node.inputs["Detail"].default_value), 0.0), 15.0)
    rough = max(float(node.inputs["Roughness"].default_value), 0.0)
    amp = sum(rough ** k for k in range(int(detail) + 2))
    return -1.02 * amp, 1.02 * amp


def _value(node, name, default=0.0):
    return float(node.inputs[name].default_value) if name in node.inputs else default


def _pattern(node, out_name):
    """The core's description of procedural texture `node`'s pattern (its output
    `out_name`), without its coordinates."""
    spec = {"pattern": node.type[4:]}
    if node.type == "TEX_NOISE":
        spec.update(noise_type=getattr(node, "noise_type", "FBM"), detail=_value(node, "Detail"),
                    roughness=_value(node, "Roughness"), lacunarity=_value(node, "Lacunarity"),
                    offset=_value(node, "Offset"), gain=_value(node, "Gain", 1.0),
                    distortion=_value(node, "Distortion"), normalize=bool(getattr(node, "normalize", True)),
                    color=out_name == "Color")
    if node.type == "TEX_VORONOI":
        spec.update(f2=node.feature == "F2", metric=node.distance, exponent=_value(node, "Exponent", 0.5),
                    randomness=_value(node, "Randomness"), detail=_value(node, "Detail"),
                    roughness=_value(node, "Roughness"), lacunarity=_value(node, "Lacunarity"),
                    normalize=bool(node.normalize), color=out_name == "Color")
    if node.type == "TEX_WAVE":
        rings = node.wave_type == "RINGS"
        spec.update(rings=rings, direction=node.rings_direction if rings else node.bands_direction,
                    profile=node.wave_profile, distortion=_value(node, "Distortion"), detail=_value(node, "Detail"),
                    detail_scale=_value(node, "Detail Scale"), detail_roughness=_value(node, "Detail Roughness"),
                    phase=_value(node, "Phase Offset"))
    if node.type == "TEX_BRICK":
        spec.update(mortar_size=_value(node, "Mortar Size"), mortar_smooth=_value(node, "Mortar Smooth"),
                    bias=_value(node, "Bias"), brick_width=_value(node, "Brick Width"),
                    row_height=_value(node, "Row Height"), offset=float(node.offset),
                    offset_frequency=int(node.offset_frequency), squash=float(node.squash),
                    squash_frequency=int(node.squash_frequency),
                    **{k: tuple(float(x) for x in tuple(node.inputs[n].default_value)[:3])
                       for k, n in (("color1", "Color1"), ("color2", "Color2"), ("mortar", "Mortar"))},
                    color=out_name == "Color")
    if node.type == "TEX_GRADIENT":
        spec["gradient_type"] = node.gradient_type
    return spec


def procedural_spec(node, out_name, coords, domain):
    """The core's description of procedural texture `node` (its output `out_name`) read at
    `coords` = (space: 'GENERATED', 'OBJECT' or 'UV'; row-major 3×4 matrix of the Vector
    input's mapping), its table over `domain`."""
    space, m = coords
    m = np.asarray(m, np.float64).reshape(3, 4)
    if node.type != "TEX_GRADIENT":
        m = m * float(node.inputs["Scale"].default_value)  # (the node scales its vector)
    return {**_pattern(node, out_name), "space": space, "domain": tuple(domain),
            "transform": tuple(float(x) for x in m.reshape(-1))}


_NODES = {
    "MIX": _mix,
    "MIX_RGB": _mix,
    "MATH": _math,
    "VALTORGB": _ramp,
    "INVERT": _invert,
    "BLACKBODY": _blackbody,
    "CURVE_RGB": _curves,
    "GAMMA": _gamma,
    "BRIGHTCONTRAST": _bright_contrast,
    "HUE_SAT": _hue_sat,
    "SEPARATE_COLOR": _separate,
    "SEPRGB": _separate,
    "COMBINE_COLOR": _combine,
    "COMBRGB": _combine,
    "RGBTOBW": _to_bw,
    "CLAMP": _clamp,
    "MAP_RANGE": _map_range,
}


# Fresnel and Layer Weight outputs: factors the core computes per point from the ray
# (`RayFactor`); a graph over one of them is tabulated over [0, 1] (`evaluate_ray`).
RAY_LEAVES = {("FRESNEL", "Fac"), ("LAYER_WEIGHT", "Fresnel"), ("LAYER_WEIGHT", "Facing"), ("NEW_GEOMETRY", "Backfacing"),
              ("LIGHT_PATH", "Is Camera Ray"), ("LIGHT_PATH", "Is Shadow Ray")}
RAY_TABLE = 1024


def evaluate_ray(sock):
    """A linked Mix Shader factor over a Fresnel or Layer Weight node (and colour and value
    nodes after it): ((node, output identifier), the factor's luminance at RAY_TABLE values
    of the node's output over [0, 1]) — or None when no such node feeds it. Raises
    Unsupported for what it cannot evaluate."""
    g = _Graph(None, None, None)
    g.collect(sock)
    if g.ray is None or g.images or g.procedural is not None:
        return None
    g.samples = np.linspace(0.0, 1.0, RAY_TABLE, dtype=np.float32)
    v = _as_value(g._walk(sock, collect=False)).a
    table = np.nan_to_num(np.broadcast_to(v, (RAY_TABLE,)), nan=0.0, posinf=0.0, neginf=0.0)
    return g.ray, np.clip(table, 0.0, 1.0).astype(np.float32)


def evaluate(sock, image_pixels, uv_key, image_identity=None, coords=None):
    """The value of the linked input `sock`: ('constant', a tuple of 3 or a float) when no
    image feeds it, else ('texture', rgb (h·w, 3) float32, w, h, transform, extension,
    closest): the images' shared UV transform and extension, closest if every image is.
    `image_pixels(node)` → (RGBA (h·w, 4), w, h, srgb: 8-bit sRGB values still encoded),
    None for a constant input;
    `uv_key(node)` → (transform, extension, closest); `image_identity(node)` → a hashable
    value that changes whenever the image's pixels do (the cache's key). Raises Unsupported,
    naming what it cannot evaluate."""
    g = _Graph(image_pixels, uv_key, image_identity, coords)
    g.collect(sock)
    if g.ray is not None:
        raise Unsupported(f"'{g.ray[0].name}' ({g.ray[0].type}: a factor from the view, evaluated only into a Mix "
                          f"Shader's factor)")
    if g.procedural is not None:
        return _tabulated(g, sock)
    if g.images and image_pixels is None:
        raise Unsupported(f"Image Texture '{next(iter(g.images))}' (an image into a constant input)")
    v = g.run(sock)
    v = _as_value(v) if sock.type == "VALUE" else _as_colour(v)
    v.a = np.nan_to_num(v.a, nan=0.0, posinf=0.0, neginf=0.0)
    if not g.images:
        return ("constant", float(v.a[0]) if isinstance(v, _Value) else tuple(float(x) for x in v.a[0]))
    gw, gh = g.grid
    rgb = _as_colour(v).a
    if len(rgb) != gw * gh:
        rgb = np.broadcast_to(rgb, (gw * gh, 3))
    keys = [uv_key(n) for n in g.images.values()]
    transform, extension, _ = keys[0]
    closest = all(k[2] for k in keys)
    return ("texture", np.ascontiguousarray(rgb, dtype=np.float32), gw, gh, transform, extension, closest)


def _tabulated(g, sock):
    """`evaluate` of a graph over a procedural texture: ('procedural', table (n, 3) float32,
    the core's description of the pattern)."""
    node, out_name = g.procedural
    if out_name == "Color" and node.type in _COLOUR_OUTPUTS and not (
            sock.is_linked and sock.links[0].from_node.name == node.name):
        raise Unsupported(f"the Color output of '{node.name}' through other nodes (its "
                          f"{_SCALAR_OUTPUTS[node.type]} is rendered through them)")
    coords = g.coords(node)
    v = g.run(sock)
    v = _as_value(v) if sock.type == "VALUE" else _as_colour(v)
    rgb = np.nan_to_num(_as_colour(v).a, nan=0.0, posinf=0.0, neginf=0.0)
    rgb = np.ascontiguousarray(np.broadcast_to(rgb, (len(g.samples), 3)), dtype=np.float32)
    return ("procedural", rgb, procedural_spec(node, out_name, coords, g.domain))
