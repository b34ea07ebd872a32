"""Blender's data passes that GDMLT writes — one table for the render engine (the View
Layer's toggles) and the command line (`gdmlt render --passes`).

Depth, Position, Object Index and Material Index come from the core's first-hit pass
(`gdmlt.render(..., data_passes=True)`: the first camera sample of each pixel, as Cycles);
Normal is the averaged shading normal every render has ("Denoising Normal").
"""

# (CLI name, View Layer toggle, pass name, channels, channel ids, type): the names and
# channels Cycles registers in Blender 5.
DATA_PASSES = (
    ("depth", "use_pass_z", "Depth", 1, "Z", "VALUE"),
    ("normal", "use_pass_normal", "Normal", 3, "XYZ", "VECTOR"),
    ("position", "use_pass_position", "Position", 3, "XYZ", "VECTOR"),
    ("object-index", "use_pass_object_index", "Object Index", 1, "X", "VALUE"),
    ("material-index", "use_pass_material_index", "Material Index", 1, "X", "VALUE"),
)
# the passes the core's first-hit pass writes
CORE_DATA_PASSES = frozenset({"Depth", "Position", "Object Index", "Material Index"})
CLI_NAMES = tuple(row[0] for row in DATA_PASSES)


def parse_cli(text: str) -> tuple:
    """`--passes depth,normal` → the pass names ("Depth", "Normal"); "all" for every one.
    ValueError naming an unknown one."""
    names = [t.strip().lower() for t in text.split(",") if t.strip()]
    if names == ["all"]:
        names = list(CLI_NAMES)
    by_cli = {row[0]: row[2] for row in DATA_PASSES}
    unknown = [n for n in names if n not in by_cli]
    if unknown:
        raise ValueError(f"unknown pass '{unknown[0]}' (known: {', '.join(CLI_NAMES)}, or all)")
    return tuple(dict.fromkeys(by_cli[n] for n in names))


def of_view_layer(view_layer) -> tuple:
    """The pass names a Blender view layer has switched on."""
    return tuple(row[2] for row in DATA_PASSES if getattr(view_layer, row[1], False))


def needs_core_pass(wanted) -> bool:
    """Whether the render must run the core's first-hit pass for `wanted` pass names."""
    return any(name in CORE_DATA_PASSES for name in wanted)


def select(layers: dict, wanted) -> dict:
    """The render's layers with the data passes limited to `wanted` (Normal: the denoising
    normal under Blender's name)."""
    out = {k: v for k, v in layers.items() if k not in CORE_DATA_PASSES or k in wanted}
    if "Normal" in wanted and "Denoising Normal" in layers:
        out["Normal"] = layers["Denoising Normal"]
    return out
