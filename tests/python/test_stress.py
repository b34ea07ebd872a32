"""Numerical stress suite: scenes that must render with every method without NaN/Inf, panics
or hangs, to a finite and plausible image, with a warning where the input was repaired
(issue 5's list). Each render is small and bounded in time."""

import numpy as np
import pytest

import gdmlt

METHODS = ["pt", "bdpt", "gdpt", "pssmlt", "gdpssmlt"]


def cornell(w=12, h=12):
    return gdmlt.builtin_scene("cornell", w, h)


def _quad(name, corners, mat):
    return {"name": name, "positions": np.array(corners, np.float32),
            "indices": np.array([[0, 1, 2], [0, 2, 3]], np.uint32), "material_ids": np.array([mat, mat], np.uint32)}


def _add_mesh(d, mesh):
    d["meshes"].append(mesh)
    return d


def degenerate_and_slivers():
    d = cornell()
    pos = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 0.5], [0.5, 1e-9, 0.5], [1, 0, 0.5]], np.float32)
    idx = np.array([[0, 1, 2], [0, 0, 3], [3, 4, 5], [1, 1, 1]], np.uint32)  # collinear, repeated, sliver
    return _add_mesh(d, {"name": "Broken", "positions": pos, "indices": idx})


def duplicate_vertices_and_flipped_normals():
    d = cornell()
    m = d["meshes"][0]
    pos = np.concatenate([m["positions"], m["positions"]])  # every vertex twice
    m["positions"] = pos
    n = np.repeat(np.array([[0, 0, -1]], np.float32), 3 * len(m["indices"]), axis=0)  # pointing away
    m["normals"] = n
    return d


def extreme_scales():
    d = cornell()
    _add_mesh(d, _quad("Tiny", [[0, 0, 0], [1e-4, 0, 0], [1e-4, 1e-4, 0], [0, 1e-4, 0]], 0))
    return _add_mesh(d, _quad("Huge", [[-1e5, -1e5, -50], [1e5, -1e5, -50], [1e5, 1e5, -50], [-1e5, 1e5, -50]], 0))


def tiny_bright_emitter():
    d = cornell()
    d["materials"].append({"name": "Hot", "base_color": (0, 0, 0), "emission": (1e7, 1e7, 1e7)})
    s = 1e-3
    return _add_mesh(d, _quad("Spark", [[0, 0, 0.5], [s, 0, 0.5], [s, s, 0.5], [0, s, 0.5]], len(d["materials"]) - 1))


def extreme_materials():
    d = cornell()
    d["materials"] += [{"name": "R0", "metallic": 1.0, "roughness": 0.0},
                       {"name": "R1", "metallic": 1.0, "roughness": 1.0},
                       {"name": "Ior1", "transmission": 1.0, "ior": 1.0, "roughness": 0.0},
                       {"name": "RoughGlass", "transmission": 1.0, "ior": 1.5, "roughness": 1.0}]
    n = len(d["materials"])
    for k, mesh in enumerate(d["meshes"][:4]):
        mesh["material_ids"] = np.full(len(mesh["indices"]), n - 4 + k, np.uint32)
    return d


def camera_inside_an_object():
    d = cornell()
    sphere = gdmlt.builtin_scene("spheres", 4, 4)["meshes"][-1]  # a closed UV sphere
    sphere["material_ids"] = np.zeros_like(sphere["material_ids"])
    d["meshes"].append(sphere)
    d["camera"]["matrix"] = np.array(d["camera"]["matrix"], np.float32)
    d["camera"]["matrix"][:3, 3] = sphere["positions"].mean(axis=0)  # at the sphere's centre
    return d


def camera_looking_at_nothing():
    d = cornell()
    m = np.array(d["camera"]["matrix"], np.float32)
    m[:3, 2] = -m[:3, 2]  # look away from the box
    m[:3, 0] = -m[:3, 0]
    d["camera"]["matrix"] = m
    return d


def one_pixel():
    return cornell(1, 1)


def very_wide():
    return cornell(96, 1)


def no_lights():
    d = cornell()
    for m in d["materials"]:
        m["emission"] = (0.0, 0.0, 0.0)
    d["lights"] = []
    d["world"] = (0.0, 0.0, 0.0)
    return d


def empty_scene():
    d = cornell()
    d["meshes"] = []
    return d


CASES = {f.__name__: f for f in [degenerate_and_slivers, duplicate_vertices_and_flipped_normals, extreme_scales,
                                 tiny_bright_emitter, extreme_materials, camera_inside_an_object,
                                 camera_looking_at_nothing, one_pixel, very_wide, no_lights, empty_scene]}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("method", METHODS)
def test_stress_scene_renders_finite(case, method):
    d = CASES[case]()
    scene = gdmlt.Scene(d)
    res = gdmlt.render(scene, method=method, spp=8, max_bounces=4, seed=7, time_limit=20.0)
    for name, img in res["layers"].items():
        assert np.isfinite(img).all(), f"{case}/{method}: {name} has NaN/Inf"
        assert img.min() >= -1e-6 or name.startswith("GD Gradient") or name == "Denoising Normal", (name, img.min())
    combined = res["layers"]["Combined"]
    st = res["stats"]
    if case in ("no_lights", "empty_scene"):
        assert combined.max() == 0.0
        assert any("no light" in w for w in st["warnings"]), st["warnings"]
    if case == "degenerate_and_slivers":
        assert any("degenerate" in w for w in st["warnings"]), st["warnings"]
    if case == "tiny_bright_emitter":
        assert combined.max() < 1e9  # a bright but finite spark


def test_fifty_renders_in_one_process_do_not_grow_memory():
    """Issue 5: repeated renders in one process (as in one Blender session) must not leak."""
    import resource

    d = cornell(16, 16)
    def rss_mb():
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    for i in range(5):  # warm up allocators and caches
        gdmlt.render(gdmlt.Scene(d), method=METHODS[i % 4], spp=4)
    before = rss_mb()
    for i in range(50):
        gdmlt.render(gdmlt.Scene(d), method=METHODS[i % 4], spp=4, seed=i)
    grown = rss_mb() - before
    assert grown < 30, f"RSS grew by {grown:.1f} MB over 50 renders"
