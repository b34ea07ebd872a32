"""Peer renderers driven from GDMLT's own scene dictionary, for benchmarks that compare like
with like: Mitsuba 3 (PyPI `mitsuba`, `llvm_ad_rgb`) and LuxCoreRender (PyPI `pyluxcore`).

Only what both peers can reproduce exactly is translated: triangle meshes with diffuse
(Lambert) materials, emissive meshes (two-sided, as Blender's), a constant-colour world and a
perspective camera with Blender's framing (no shift, no depth of field). Anything else raises
`Unsupported`, so that a benchmark never compares different scenes. Depth: GDMLT's
`max_bounces` B (Blender's convention: 0 = direct light only) is Mitsuba's `max_depth` B + 2
and LuxCore's `path.pathdepth.total` B + 1; the bench prints each peer's image mean next to
GDMLT's to show the translation renders the same scene.

LuxCore's bundled allocator crashes a process that imports numpy-heavy libraries after it, so
it always runs in a child process (`python -m gdmlt_bench.peers luxcore IN.npz OUT.npz`)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

LLVM_CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", "/usr/lib/x86_64-linux-gnu/libLLVM-19.so")


class Unsupported(Exception):
    """The scene uses something a peer translation does not reproduce exactly."""


def simple_scene(desc: dict) -> dict:
    """Triangle soups per material plus camera and world, or Unsupported naming the feature."""
    if desc.get("lights"):
        raise Unsupported("lamp objects (only emissive meshes are translated)")
    if desc.get("textures") or desc.get("world_texture") is not None:
        raise Unsupported("image textures")
    mats = desc["materials"]
    for m in mats:
        if m.get("metallic", 0) or m.get("transmission", 0):
            raise Unsupported(f"material {m['name']!r} is not diffuse")
        for key in ("base_color_texture", "roughness_texture", "glass_color", "metal_color"):
            if m.get(key) is not None:
                raise Unsupported(f"material {m['name']!r} has {key}")
    cam = desc["camera"]
    if cam.get("type", "PERSP") != "PERSP" or cam.get("shift_x", 0) or cam.get("shift_y", 0) \
            or cam.get("aperture_radius", 0) or cam.get("fstop", 0):
        raise Unsupported("camera other than a plain perspective one")
    w, h = int(cam["resolution_x"]), int(cam["resolution_y"])
    fit = cam.get("sensor_fit", "AUTO")
    horizontal = (fit == "HORIZONTAL") or (fit == "AUTO" and w >= h)
    sensor = cam["sensor_width"] if fit in ("AUTO", "HORIZONTAL") else cam["sensor_height"]
    fov_fit = 2 * math.degrees(math.atan(sensor / (2 * cam["lens"])))
    # vertical and horizontal fields of view
    aspect = w / h
    if horizontal:
        fov_x = fov_fit
        fov_y = 2 * math.degrees(math.atan(math.tan(math.radians(fov_fit) / 2) / aspect))
    else:
        fov_y = fov_fit
        fov_x = 2 * math.degrees(math.atan(math.tan(math.radians(fov_fit) / 2) * aspect))
    groups = {}
    for mesh in desc["meshes"]:
        p = np.asarray(mesh["positions"], np.float64)
        t = np.asarray(mesh["indices"], np.int64).reshape(-1, 3)
        ids = np.asarray(mesh.get("material_ids", np.zeros(len(t))), np.int64).reshape(-1)
        for mid in np.unique(ids):
            sel = t[ids == mid]
            used, inv = np.unique(sel, return_inverse=True)
            g = groups.setdefault(int(mid), ([], []))
            g[0].append(p[used])
            g[1].append(inv.reshape(-1, 3))
    shapes = []
    for mid, (ps, ts) in sorted(groups.items()):
        off, tris = 0, []
        for pp, tt in zip(ps, ts):
            tris.append(tt + off)
            off += len(pp)
        m = mats[mid]
        shapes.append(dict(name=f"m{mid}", positions=np.concatenate(ps).astype(np.float32),
                           indices=np.concatenate(tris).astype(np.int32),
                           base_color=[float(c) for c in m["base_color"]],
                           emission=[float(c) for c in m.get("emission", (0, 0, 0))]))
    return dict(shapes=shapes, matrix=np.asarray(cam["matrix"], np.float64), width=w, height=h,
                fov_x=fov_x, fov_y=fov_y, clip_start=float(cam.get("clip_start", 0.01)),
                clip_end=float(cam.get("clip_end", 1000.0)), world=[float(c) for c in desc.get("world", (0, 0, 0))])


def two_sided(simple: dict) -> list:
    """The shapes with every emissive one doubled: both peers' area lights emit from the front
    only, Blender's from both sides. The copy faces the other way and sits 1e-5 × the scene's
    size behind, so each side is seen (and sampled) from its own half-space and occludes the
    other (an exactly coincident copy would make the hit order a coin toss)."""
    allp = np.concatenate([s["positions"] for s in simple["shapes"]])
    eps = 1e-5 * float(np.max(allp.max(0) - allp.min(0)))
    out = []
    for s in simple["shapes"]:
        out.append(s)
        if any(s["emission"]):
            p, t = s["positions"].astype(np.float64), s["indices"]
            # vertex normals from the area-weighted face normals (flat emitters: all equal)
            fn = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
            vn = np.zeros_like(p)
            for k in range(3):
                np.add.at(vn, t[:, k], fn)
            vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)
            out.append(dict(s, name=s["name"] + "_back", positions=(p - eps * vn).astype(np.float32),
                            indices=np.ascontiguousarray(t[:, ::-1])))
    return out


# ---------------------------------------------------------------- Mitsuba 3


def import_mitsuba(threads: int = 0):
    """Mitsuba 3 with the LLVM variant (needs Debian's libllvm19: `apt-get install libllvm19`)."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        for c in LLVM_CANDIDATES:
            if Path(c).exists():
                os.environ["DRJIT_LIBLLVM_PATH"] = c
                break
        else:
            # Dr.Jit would load whatever libLLVM it finds; with Debian's LLVM 14/15 its code
            # generation aborts the process ("Cannot select"), which nothing can catch
            raise Unsupported("Mitsuba's LLVM backend needs libLLVM 19 (apt-get install libllvm19)")
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as e:
        raise Unsupported("mitsuba is not installed (pip install -r requirements-bench.txt)") from e
    mi.set_variant("llvm_ad_rgb")
    if threads:
        dr.set_thread_count(threads)
    return mi, dr


_BSDF_RR = "gdmlt_bsdf_sampling_rr"


def gdmlt_roulette(sampler, beta, depth, rr_depth):
    """GDMLT's Russian roulette (`src/path.rs`) on Mitsuba's lanes: from bounce `rr_depth` a
    path goes on with probability q = min((max β)^gdmlt.RR_EXPONENT, 1), its throughput divided
    by q. Returns (β, the lanes that go on). Used inside the integrators' `dr.syntax` loops."""
    import drjit as dr
    import gdmlt
    import mitsuba as mi

    beta_max = dr.max(mi.unpolarized_spectrum(beta))
    q = dr.minimum(dr.power(beta_max, gdmlt.RR_EXPONENT), 1.0)
    roulette = depth >= rr_depth
    survive = sampler.next_1d() < q
    beta = dr.select(roulette, beta * dr.rcp(q), beta)
    return beta, (~roulette | survive) & (beta_max > 0)


_PATH_RR = "gdmlt_path_rr"


def _register_rr_integrators(mi, dr):
    """Registers two Mitsuba integrators with GDMLT's Russian roulette (`gdmlt_roulette`):
    `_BSDF_RR` finds light by BSDF sampling only (as `prb_basic`, which has no roulette, so
    its paths run to `max_depth`); `_PATH_RR` is Mitsuba's own path tracer with emitter
    sampling and MIS (the primal part of its `prb`, `path`'s estimator), where `path` survives
    with min(max β·η², 0.95) and so ends paths sooner than GDMLT at the same rr_depth, its
    samples/s being of shorter paths (issue 51)."""
    if getattr(_register_rr_integrators, "done", False):
        return

    class RR(mi.SamplingIntegrator):
        def __init__(self, props):
            super().__init__(props)
            self.max_depth = props.get("max_depth", 10)
            self.rr_depth = props.get("rr_depth", 3)

    class BsdfSamplingRR(RR):
        @dr.syntax
        def sample(self, scene, sampler, ray, medium=None, active=True):
            # (dr.syntax recompiles this body without its closure: the modules come by import)
            import mitsuba as mi

            from gdmlt_bench.peers import gdmlt_roulette

            ctx = mi.BSDFContext()
            ray = mi.Ray3f(ray)
            radiance = mi.Spectrum(0.0)
            beta = mi.Spectrum(1.0)
            depth = mi.UInt32(0)
            active = mi.Bool(active)
            while active:
                si = scene.ray_intersect(ray, active)
                radiance += beta * si.emitter(scene).eval(si, active)
                active &= si.is_valid() & (depth + 1 < self.max_depth)
                bs, weight = si.bsdf(ray).sample(ctx, si, sampler.next_1d(), sampler.next_2d(), active)
                beta *= weight
                ray = si.spawn_ray(si.to_world(bs.wo))
                depth += 1
                beta, going_on = gdmlt_roulette(sampler, beta, depth, self.rr_depth)
                active &= going_on
            return radiance, mi.Bool(True), []


    class PathRR(RR):
        @dr.syntax
        def sample(self, scene, sampler, ray, medium=None, active=True):
            import drjit as dr
            import mitsuba as mi

            from gdmlt_bench.peers import gdmlt_roulette
            from mitsuba.ad.integrators.common import mis_weight

            ctx = mi.BSDFContext()
            ray = mi.Ray3f(ray)
            radiance = mi.Spectrum(0.0)
            beta = mi.Spectrum(1.0)
            depth = mi.UInt32(0)
            active = mi.Bool(active)
            si_prev = dr.zeros(mi.SurfaceInteraction3f)
            pdf_prev = mi.Float(1.0)
            delta_prev = mi.Bool(True)
            while active:
                si = scene.ray_intersect(ray, active)
                bsdf = si.bsdf(ray)
                # light found by the previous bounce's BSDF sample, MIS-weighted
                ds = mi.DirectionSample3f(scene, si=si, ref=si_prev)
                mis = mis_weight(pdf_prev, scene.pdf_emitter_direction(si_prev, ds, ~delta_prev))
                radiance += beta * mis * ds.emitter.eval(si, active)
                active &= si.is_valid() & (depth + 1 < self.max_depth)
                # a light sample, MIS-weighted
                active_em = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
                ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
                active_em &= ds.pdf != 0.0
                value, pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), active_em)
                mis_em = dr.select(ds.delta, 1.0, mis_weight(ds.pdf, pdf))
                radiance[active_em] += beta * mis_em * value * em_weight
                # the continuation, then GDMLT's roulette
                bs, weight = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), active)
                beta *= weight
                ray = si.spawn_ray(si.to_world(bs.wo))
                si_prev = dr.detach(si, True)
                pdf_prev = bs.pdf
                delta_prev = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
                depth += 1
                beta, going_on = gdmlt_roulette(sampler, beta, depth, self.rr_depth)
                active &= going_on
            return radiance, mi.Bool(True), []


    mi.register_integrator(_BSDF_RR, lambda props: BsdfSamplingRR(props))
    mi.register_integrator(_PATH_RR, lambda props: PathRR(props))
    _register_rr_integrators.done = True


def mitsuba_integrator(mi, max_bounces: int, nee: bool, rr_depth: int | None = None) -> dict:
    """Emitter sampling + MIS or BSDF sampling only. rr_depth None: Mitsuba's own integrators
    and defaults (`path`: roulette from depth 5, q = min(max β·η², 0.95); `prb_basic`: no
    roulette). rr_depth k: Mitsuba's estimators with GDMLT's roulette from bounce k (our
    `_PATH_RR` and `_BSDF_RR` integrators), so that both renderers trace paths of the same
    length."""
    depth = max_bounces + 2
    if rr_depth is None:
        return {"type": "path" if nee else "prb_basic", "max_depth": depth}
    import drjit as dr

    _register_rr_integrators(mi, dr)
    return {"type": _PATH_RR if nee else _BSDF_RR, "max_depth": depth, "rr_depth": rr_depth}


def mitsuba_scene(mi, simple: dict, max_bounces: int, nee: bool, seed_spp: int = 1, rr_depth: int | None = None):
    # Blender's camera looks down −Z with +Y up; Mitsuba's down +Z with +Y up and +X to the left.
    to_world = simple["matrix"] @ np.diag([-1.0, 1.0, -1.0, 1.0])
    scene = {
        "type": "scene",
        "integrator": mitsuba_integrator(mi, max_bounces, nee, rr_depth),
        "sensor": {
            "type": "perspective", "fov": simple["fov_x"], "fov_axis": "x",
            "near_clip": simple["clip_start"], "far_clip": simple["clip_end"],
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "film": {"type": "hdrfilm", "width": simple["width"], "height": simple["height"],
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": seed_spp},
        },
    }
    if any(simple["world"]):
        scene["world"] = {"type": "constant", "radiance": {"type": "rgb", "value": simple["world"]}}
    for s in two_sided(simple):
        props = mi.Properties()
        # two-sided, as Blender's BSDFs (a Mitsuba BSDF is black from the back)
        props["bsdf"] = mi.load_dict({"type": "twosided", "bsdf": {
            "type": "diffuse", "reflectance": {"type": "rgb", "value": s["base_color"]}}})
        if any(s["emission"]):
            props["emitter"] = mi.load_dict({"type": "area", "radiance": {"type": "rgb", "value": s["emission"]}})
        mesh = mi.Mesh(s["name"], len(s["positions"]), len(s["indices"]), props=props, has_vertex_normals=False)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(np.ascontiguousarray(s["positions"], np.float32).ravel())
        params["faces"] = mi.UInt32(np.ascontiguousarray(s["indices"], np.uint32).ravel())
        params.update()
        scene[s["name"]] = mesh
    return mi.load_dict(scene)


def mitsuba_render(mi, scene, spp: int, seed: int = 0) -> np.ndarray:
    img = mi.render(scene, spp=spp, seed=seed)
    return np.array(img, dtype=np.float32)[:, :, :3]


# ---------------------------------------------------------------- LuxCore (child process)


def _luxcore_child(inp: str, outp: str):
    import pyluxcore

    data = np.load(inp, allow_pickle=False)
    cfg = json.loads(str(data["config"]))
    pyluxcore.Init(lambda msg: None)
    scn = pyluxcore.Scene()
    props = pyluxcore.Properties()
    w, h = cfg["width"], cfg["height"]
    m = data["matrix"]
    eye = m[:3, 3]
    fwd = -m[:3, 2]
    up = m[:3, 1]
    props.Set(pyluxcore.Property("scene.camera.type", "perspective"))
    props.Set(pyluxcore.Property("scene.camera.lookat.orig", [float(x) for x in eye]))
    props.Set(pyluxcore.Property("scene.camera.lookat.target", [float(x) for x in eye + fwd]))
    props.Set(pyluxcore.Property("scene.camera.up", [float(x) for x in up]))
    # LuxCore's field of view is along the shorter image side.
    props.Set(pyluxcore.Property("scene.camera.fieldofview", float(min(cfg["fov_x"], cfg["fov_y"]))))
    # Its image sits one pixel row low; shift the screen window back (docs/benchmarks.md,
    # "The peers' framing"; checked by the bench against GDMLT's framing).
    ax, ay = (w / h, 1.0) if w >= h else (1.0, h / w)
    dy = 2.0 * ay / h
    props.Set(pyluxcore.Property("scene.camera.screenwindow", [-ax, ax, -ay - dy, ay - dy]))
    props.Set(pyluxcore.Property("scene.camera.cliphither", cfg["clip_start"]))
    props.Set(pyluxcore.Property("scene.camera.clipyon", cfg["clip_end"]))
    if any(cfg["world"]):
        props.Set(pyluxcore.Property("scene.lights.world.type", "constantinfinite"))
        props.Set(pyluxcore.Property("scene.lights.world.color", cfg["world"]))
        props.Set(pyluxcore.Property("scene.lights.world.gain", [1.0, 1.0, 1.0]))
    for i, s in enumerate(cfg["shapes"]):
        pos = data[f"p{i}"]
        tri = data[f"t{i}"]
        name = s["name"]
        mat = name.removesuffix("_back")
        mp = f"scene.materials.{mat}"
        props.Set(pyluxcore.Property(f"{mp}.type", "matte"))
        props.Set(pyluxcore.Property(f"{mp}.kd", s["base_color"]))
        if any(s["emission"]):
            props.Set(pyluxcore.Property(f"{mp}.emission", s["emission"]))
            props.Set(pyluxcore.Property(f"{mp}.emission.gain", [1.0, 1.0, 1.0]))
            props.Set(pyluxcore.Property(f"{mp}.emission.power", 0.0))
            props.Set(pyluxcore.Property(f"{mp}.emission.efficency", 0.0))
            if not cfg["nee"]:
                props.Set(pyluxcore.Property(f"{mp}.emission.directlightsampling.type", "DISABLED"))
        scn.DefineMesh(name, [tuple(map(float, p)) for p in pos], [tuple(map(int, x)) for x in tri],
                       None, None, None, None)
        props.Set(pyluxcore.Property(f"scene.objects.{name}.shape", name))
        props.Set(pyluxcore.Property(f"scene.objects.{name}.material", mat))
    scn.Parse(props)
    c = pyluxcore.Properties()
    depth = cfg["max_bounces"] + 1
    for k, v in [("renderengine.type", "PATHCPU"), ("sampler.type", cfg["sampler"]),
                 ("sampler.sobol.adaptive.strength", 0.0), ("film.filter.type", "NONE"),
                 ("film.width", w), ("film.height", h), ("path.pathdepth.total", depth),
                 ("path.pathdepth.diffuse", depth), ("path.pathdepth.glossy", depth),
                 ("path.pathdepth.specular", depth), ("path.clamping.variance.maxvalue", 0.0),
                 ("native.threads.count", cfg["threads"] or os.cpu_count()),
                 ("batch.halttime", 0), ("batch.haltspp", 0)]:
        c.Set(pyluxcore.Property(k, v))
    session = pyluxcore.RenderSession(pyluxcore.RenderConfig(c, scn))
    buf = np.zeros(w * h * 3, np.float32)
    images, times, samples = [], [], []
    t0 = time.perf_counter()
    session.Start()
    for budget in cfg["budgets"]:
        while time.perf_counter() - t0 < budget:
            time.sleep(min(0.02, max(0.0, budget - (time.perf_counter() - t0))))
        session.UpdateStats()
        stats = session.GetStats()
        session.GetFilm().GetOutputFloat(pyluxcore.FilmOutputType.RGB, buf)
        times.append(time.perf_counter() - t0)
        samples.append(stats.Get("stats.renderengine.pass").GetFloat() * w * h)
        images.append(buf.reshape(h, w, 3)[::-1].copy())
    session.Stop()
    pyluxcore.SetLogHandler(None)
    np.savez(outp, images=np.stack(images), times=np.array(times), samples=np.array(samples))


def luxcore_render(simple: dict, budgets, max_bounces: int, nee: bool, sampler="SOBOL", threads=0):
    """Images after each wall-clock budget (seconds from the session's start, one session),
    with the sample counts reached then. Runs in a child process."""
    cfg = dict(width=simple["width"], height=simple["height"], fov_x=simple["fov_x"], fov_y=simple["fov_y"],
               clip_start=simple["clip_start"], clip_end=simple["clip_end"], world=simple["world"],
               max_bounces=max_bounces, nee=nee, sampler=sampler, threads=threads, budgets=list(budgets),
               shapes=[{k: s[k] for k in ("name", "base_color", "emission")} for s in two_sided(simple)])
    arrays = {"matrix": simple["matrix"]}
    for i, s in enumerate(two_sided(simple)):
        arrays[f"p{i}"] = s["positions"]
        arrays[f"t{i}"] = s["indices"]
    return _run_child("luxcore", cfg, arrays)


# ---------------------------------------------------------------- Cycles (bpy, child process)


def cycles_unbiased(scene, samples: int, seed: int, bounces: int, threads: int = 0, kinds=None):
    """Cycles as an unbiased reference (docs/blender.md, "Cycles as a reference renderer"): no clamping, no glossy filter, no
    denoiser, no adaptive sampling, no light threshold, the default 1.5-pixel Blackman-Harris filter, caustics on,
    the same bounce limit for every kind — or, with `kinds` ({"diffuse", "glossy",
    "transmission", "volume", "transparent"} → limit), those limits (GDMLT's Light Paths)."""
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = samples
    c.seed = seed
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.light_sampling_threshold = 0.0  # the default 0.01 drops faint light contributions (biased)
    # Cycles' default pixel filter, which GDMLT's default now is too (pixel_filter.rs)
    c.pixel_filter_type = "BLACKMAN_HARRIS"
    c.filter_width = 1.5
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = c.volume_bounces = bounces
    c.transparent_max_bounces = 16  # as the core (path.rs MAX_TRANSPARENT_BOUNCES): crossings are not bounces
    for kind, limit in (kinds or {}).items():
        setattr(c, "transparent_max_bounces" if kind == "transparent" else f"{kind}_bounces", min(limit, 1024))
    c.caustics_reflective = c.caustics_refractive = True
    scene.render.threads_mode = "FIXED" if threads else "AUTO"
    if threads:
        scene.render.threads = threads
    scene.view_settings.view_transform = "Standard"


def _cycles_child(inp: str, outp: str):
    from gdmlt.blend import import_bpy

    data = np.load(inp, allow_pickle=False)
    cfg = json.loads(str(data["config"]))
    bpy = import_bpy()
    if cfg.get("blend"):
        bpy.ops.wm.open_mainfile(filepath=cfg["blend"])
        scene = bpy.context.scene
        if cfg.get("size"):
            scene.render.resolution_x, scene.render.resolution_y = cfg["size"]
            scene.render.resolution_percentage = 100
    else:
        from gdmlt.blendscene import build

        desc = dict(cfg["desc"], camera=dict(cfg["desc"]["camera"], matrix=data["matrix"]),
                    meshes=[dict(m, positions=data[f"p{i}"], indices=data[f"t{i}"], material_ids=data[f"m{i}"])
                            for i, m in enumerate(cfg["desc"]["meshes"])])
        scene = build(bpy, desc)
    cycles_unbiased(scene, 1 << 24, seed=cfg.get("seed", 1), bounces=cfg["max_bounces"], threads=cfg["threads"])
    if not cfg["nee"]:
        # the paper's naive mode: emissive surfaces and the world only found by hitting them
        # (lamp objects, if any, are still sampled: Cycles cannot turn that off)
        for mat in bpy.data.materials:
            mat.cycles.emission_sampling = "NONE"
        if scene.world is not None:
            scene.world.cycles.sampling_method = "NONE"
    if cfg.get("guiding"):
        # Cycles as an artist renders hard light: path guiding (Intel Open PGL, CPU) on
        # surfaces, its defaults otherwise (training throughout the render's first 128 samples)
        scene.cycles.use_guiding = True
        scene.cycles.use_surface_guiding = True
    if cfg.get("adaptive"):
        # as artists render: Cycles' adaptive sampling (automatic minimum samples)
        scene.cycles.use_adaptive_sampling = True
        scene.cycles.adaptive_threshold = cfg["adaptive"]
        scene.cycles.adaptive_min_samples = 0
    if cfg.get("denoise"):
        # Cycles as artists render: its default denoiser (OIDN, albedo + normal guides,
        # "Accurate" prefilter); the raw image of the same samples is the Noisy Image pass
        scene.cycles.use_denoising = True
        scene.cycles.denoiser = "OPENIMAGEDENOISE"
        scene.cycles.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        scene.cycles.denoising_prefilter = "ACCURATE"
        bpy.context.view_layer.cycles.denoising_store_passes = True
    img = scene.render.image_settings
    img.media_type = "MULTI_LAYER_IMAGE"  # Blender 5: a multi-layer EXR
    img.file_format, img.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.use_file_extension = False
    images, denoised, times = [], [], []
    for k, budget in enumerate(cfg["budgets"]):
        scene.cycles.time_limit = budget
        path = str(Path(outp).with_suffix(f".{k}.exr"))
        scene.render.filepath = path
        t = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        times.append(time.perf_counter() - t)
        layers = exr_layers(path)
        if cfg.get("denoise"):
            images.append(layers["Noisy Image"])
            denoised.append(layers["Combined"])
        else:
            images.append(layers["Combined"])
    np.savez(outp, images=np.stack(images), times=np.array(times), samples=np.zeros(len(times)),
             **({"denoised": np.stack(denoised)} if denoised else {}))


def exr_layers(path, rgb_only=True) -> dict:
    """{pass name: H×W×C, top row first} of a multi-layer EXR that Blender wrote (one part
    per pass in Blender 5, one part for all of them in 4.5; "ViewLayer.Noisy Image" → "Noisy
    Image"): its colour passes as RGB, or with `rgb_only=False` every pass with all its
    channels (Depth as H×W×1; the X, Y, Z channels of Normal and Position, which OpenEXR
    leaves apart, stacked in that order)."""
    import OpenEXR

    passes = {}  # name: [channel arrays]
    with OpenEXR.File(str(path)) as f:
        for part in f.parts:
            for key, ch in part.channels.items():
                name = key.split(".", 1)[1] if "." in key else key
                head, _, last = name.rpartition(".")
                if head and len(last) == 1:  # a lone channel of a pass ("Normal.X")
                    name = head
                passes.setdefault(name, []).append(np.asarray(ch.pixels, np.float32))
    out = {}
    for name, chans in passes.items():
        a = np.stack(chans, axis=-1) if len(chans) > 1 and all(c.ndim == 2 for c in chans) else chans[0]
        if not rgb_only:
            out[name] = a[..., None] if a.ndim == 2 else a
        elif a.ndim == 3 and a.shape[2] >= 3:
            out[name] = a[..., :3].copy()
    return out


def cycles_render(budgets, max_bounces: int, nee: bool, threads=0, desc=None, blend=None, size=None, seed=1,
                  denoise=False, adaptive=0.0, guiding=False):
    """Cycles images after each time limit (one render per budget, Cycles' own time limit),
    of a .blend file or of a scene dict that `simple_scene` accepts (rebuilt in Blender by
    gdmlt.blendscene). Runs in a child process (bpy). Returns (images, times, samples), and
    with `denoise` also Cycles' own denoised images of the same renders (the raw ones are
    then its Noisy Image pass). `adaptive`: adaptive sampling at that noise threshold, as
    artists render (0 = off: every pixel sampled alike)."""
    cfg = dict(budgets=list(budgets), max_bounces=max_bounces, nee=nee, threads=threads, seed=seed,
               blend=str(Path(blend).resolve()) if blend else None, size=list(size) if size else None,
               denoise=bool(denoise), adaptive=float(adaptive), guiding=bool(guiding))
    arrays = {}
    if desc is not None:
        simple_scene(desc)  # refuses what the rebuilt scene would not reproduce
        cam = desc["camera"]
        cfg["desc"] = dict(
            materials=[{k: [float(x) for x in m[k]] if k != "name" else m[k] for k in ("name", "base_color", "emission")}
                       for m in desc["materials"]],
            world=[float(x) for x in desc.get("world", (0, 0, 0))],
            camera={k: v for k, v in cam.items() if k != "matrix"},
            meshes=[{"name": m["name"]} for m in desc["meshes"]])
        arrays["matrix"] = np.asarray(cam["matrix"], np.float64)
        for i, m in enumerate(desc["meshes"]):
            arrays[f"p{i}"] = np.asarray(m["positions"], np.float32)
            arrays[f"t{i}"] = np.asarray(m["indices"], np.int64).reshape(-1, 3)
            arrays[f"m{i}"] = np.asarray(m.get("material_ids", np.zeros(len(arrays[f"t{i}"]))), np.int64).reshape(-1)
    out = _run_child("cycles", cfg, arrays, keys=("images", "times", "samples") + (("denoised",) if denoise else ()))
    return out


def _run_child(kind: str, cfg: dict, arrays: dict, keys=("images", "times", "samples")):
    with tempfile.TemporaryDirectory() as tmp:
        inp, outp = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(inp, config=json.dumps(cfg, default=lambda o: o.item() if hasattr(o, "item") else str(o)), **arrays)
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [str(Path(__file__).resolve().parent.parent)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
        r = subprocess.run([sys.executable, "-m", "gdmlt_bench.peers", kind, str(inp), str(outp)],
                           capture_output=True, text=True, env=env)
        if r.returncode != 0 or not outp.exists():
            raise RuntimeError(f"{kind} child failed ({r.returncode}): {r.stderr.strip()[-600:]}")
        out = np.load(outp)
        return tuple(out[k] for k in keys)


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] in ("luxcore", "cycles"):
        {"luxcore": _luxcore_child, "cycles": _cycles_child}[sys.argv[1]](sys.argv[2], sys.argv[3])
    else:
        sys.exit("usage: python -m gdmlt_bench.peers luxcore|cycles IN.npz OUT.npz")
