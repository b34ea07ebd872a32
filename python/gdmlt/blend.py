"""A .blend file through the GDMLT add-on in bpy: its scene exported as F12 would, its settings read
once (settings_of), and `gdmlt export` to USD."""

import os
import tempfile
from pathlib import Path

# keys of gdmlt.render's keyword arguments → scene.gdmlt property names
PROPERTY_OF = {"method": "method", "spp": "samples", "time_limit": "time_limit", "max_bounces": "max_bounces",
               "nee": "use_nee", "seed": "seed", "threads": "threads",
               "reconstruction": "reconstruction", "alpha_rec": "alpha_reconstruction",
               "alpha_target": "alpha_target", "large_step_probability": "large_step_probability",
               "chains": "chains", "denoise": "use_denoising", "diffuse_bounces": "diffuse_bounces",
               "glossy_bounces": "glossy_bounces", "transmission_bounces": "transmission_bounces",
               "volume_bounces": "volume_bounces",
               "transparent_bounces": "transparent_max_bounces", "clamp_direct": "clamp_direct",
               "clamp_indirect": "clamp_indirect", "adaptive_threshold": "adaptive_threshold",
               "adaptive_min_samples": "adaptive_min_samples"}


def settings_of(props) -> dict:
    """The render settings a scene's GDMLT properties (`scene.gdmlt`) hold, keyed as
    gdmlt.render and the CLI name them (PROPERTY_OF): the one reading of those properties for
    the engine and for `gdmlt export`."""
    out = {}
    for key, prop in PROPERTY_OF.items():
        value = getattr(props, prop)
        out[key] = value.lower() if key in ("method", "reconstruction") else value
    if not props.use_adaptive_sampling:  # Cycles' checkbox beside the threshold
        out["adaptive_threshold"] = 0.0
    return out


def import_bpy():
    """Import bpy with Blender's user config kept out of the home directory."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(Path(tempfile.gettempdir()) / "gdmlt-blender-user"))
    import bpy  # noqa: F401
    return bpy


def scene_desc(scene: str, size=None):
    """(scene dict, label, export warnings) of a built-in scene name (size = (w, h), default
    128²) or of a .blend file (its own resolution unless size is given), exported through the
    add-on as F12 would."""
    import gdmlt

    path = Path(scene)
    if path.suffix.lower() != ".blend":
        w, h = size or (128, 128)
        return gdmlt.builtin_scene(scene, w, h), scene, []
    loaded = load(path, width=size[0] if size else None, height=size[1] if size else None)
    return loaded["desc"], path.stem, loaded["warnings"]


def load(path: Path, frame=None, width=None, height=None) -> dict:
    """Opens a .blend and exports its active scene through the add-on, as F12 would: {"desc":
    scene dict, "warnings": export warnings, "settings": its GDMLT render settings
    (settings_of), "view": its colour management (gdmlt.colour), "passes": the data passes its
    view layer has on (gdmlt.passes)}. `frame`: the frame to export (default: the file's);
    `width`/`height`: override the resolution (at 100%)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    bpy = import_bpy()
    from .addon import enable_addon

    enable_addon()  # before loading, so the file's engine and settings resolve
    import gdmlt_blender.export as export

    from . import colour, passes

    bpy.ops.wm.open_mainfile(filepath=str(path.resolve()))
    sc = bpy.context.scene
    if frame is not None:
        sc.frame_set(int(frame))
    r = sc.render
    if width:
        r.resolution_x = width
    if height:
        r.resolution_y = height
    if width or height:
        r.resolution_percentage = 100
    desc, warnings = export.export_scene(bpy.context.evaluated_depsgraph_get())
    warnings = list(warnings)
    if r.use_compositing and _has_compositor(sc):
        warnings.append("the scene's compositing nodes are not applied by `gdmlt render` (render with "
                        "`blender -b file.blend -f N` to apply them)")
    return {"desc": desc, "warnings": warnings, "settings": settings_of(sc.gdmlt), "view": colour.view_of(sc),
            "passes": passes.of_view_layer(bpy.context.view_layer)}


def _has_compositor(scene) -> bool:
    """Whether the scene composites more than its render layer into its output."""
    tree = getattr(scene, "compositing_node_group", None) or getattr(scene, "node_tree", None)
    if tree is None:
        return False
    return any(n.type not in ("R_LAYERS", "COMPOSITE", "GROUP_OUTPUT", "VIEWER") for n in tree.nodes)


def export_usd(path: Path, out: Path, frame=None) -> dict:
    """Exports the .blend's active scene with Blender's own USD exporter (evaluated meshes,
    materials as UsdPreviewSurface and MaterialX networks, textures, lights, cameras, the
    world as a dome) and stores the
    GDMLT render settings and the image size in the stage's customLayerData under "gdmlt",
    so `gdmlt render out.usd` on a machine without Blender renders it the same way.
    Returns the stored settings."""
    bpy = import_bpy()
    from .addon import enable_addon

    enable_addon()
    bpy.ops.wm.open_mainfile(filepath=str(path))
    scene = bpy.context.scene
    if frame is not None:
        scene.frame_set(int(frame))
    _as_exportable_principled(bpy)
    _safe_packed_image_names(bpy)
    out.parent.mkdir(parents=True, exist_ok=True)
    result = bpy.ops.wm.usd_export(filepath=str(out.resolve()), selected_objects_only=False,
                                   export_animation=False, export_materials=True, export_lights=True,
                                   export_cameras=True, convert_world_material=True,
                                   # MaterialX keeps what UsdPreviewSurface cannot say (glass,
                                   # glossy, a Diffuse without specular layer); textures are
                                   # written next to the stage
                                   generate_materialx_network=True, export_textures_mode="NEW")
    if "FINISHED" not in result:
        raise RuntimeError(f"Blender's USD export of {path} failed")
    g = scene.gdmlt
    r = scene.render
    pct = r.resolution_percentage / 100.0
    settings = settings_of(g)
    del settings["threads"]  # a property of the machine that exports, not of the scene
    settings.update(width=max(1, int(r.resolution_x * pct)), height=max(1, int(r.resolution_y * pct)))
    if scene.camera is not None:
        settings["camera"] = scene.camera.name
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(out.resolve()))
    data = dict(layer.customLayerData)
    from . import colour, passes

    # the stage renders as the file does: its settings, its colour management (the PNG) and
    # its view layer's data passes (the EXR)
    settings["view"] = colour.view_of(scene)
    on = set(passes.of_view_layer(bpy.context.view_layer))
    settings["passes"] = ",".join(row[0] for row in passes.DATA_PASSES if row[2] in on)
    data["gdmlt"] = {k: v for k, v in settings.items() if k != "camera"}
    layer.customLayerData = data
    layer.Save()
    return settings


def safe_file_name(name: str, fallback: str = "texture") -> str:
    """`name` as a plain file name: no folders, no '..', no leading dots or separators."""
    import re

    base = re.split(r"[\\/]", name)[-1]
    base = re.sub(r"[^A-Za-z0-9._ -]", "_", base).lstrip(". ")
    return base or fallback


def _safe_packed_image_names(bpy):
    """Blender's USD exporter writes each packed image (export_textures_mode NEW) to the
    stage's textures folder under the image's file name or, without one, its datablock name —
    a name like '../../../x.png' in an untrusted .blend wrote outside the output folder. Every
    packed image gets a plain file name first (in memory; the .blend is not saved)."""
    for img in bpy.data.images:
        if img.packed_file is None:
            continue
        base = safe_file_name(img.filepath or img.name, f"image{img.session_uid}")
        img.name = safe_file_name(img.name, base)
        img.filepath = "//" + base


def _as_exportable_principled(bpy):
    """Blender's USD exporter writes UsdPreviewSurface from Principled (and Diffuse) shaders;
    an Emission-only surface would be exported as grey diffuse, and a Diffuse one gets
    UsdPreviewSurface's default IOR 1.5, i.e. a specular layer the Diffuse BSDF does not
    have. Rewire such materials (in memory; the .blend is not saved) to a Principled BSDF of
    IOR 1 (no specular layer) with the emission colour and strength (on black), or with the
    Diffuse colour (its link, if an image texture feeds it)."""
    for mat in bpy.data.materials:
        tree = mat.node_tree
        out = tree.get_output_node("CYCLES") if tree is not None else None
        surface = out.inputs.get("Surface") if out is not None else None
        if surface is None or not surface.is_linked or surface.links[0].from_node.type not in ("EMISSION",
                                                                                               "BSDF_DIFFUSE"):
            continue
        src = surface.links[0].from_node
        p = tree.nodes.new("ShaderNodeBsdfPrincipled")
        p.inputs["IOR"].default_value = 1.0
        p.inputs["Roughness"].default_value = 1.0
        if src.type == "EMISSION":
            p.inputs["Base Color"].default_value = (0, 0, 0, 1)
            p.inputs["Emission Color"].default_value = src.inputs["Color"].default_value
            p.inputs["Emission Strength"].default_value = src.inputs["Strength"].default_value
        elif src.inputs["Color"].is_linked:
            tree.links.new(src.inputs["Color"].links[0].from_socket, p.inputs["Base Color"])
        else:
            p.inputs["Base Color"].default_value = src.inputs["Color"].default_value
        tree.links.new(p.outputs[0], surface)
