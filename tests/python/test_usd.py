"""USD stages rendered without Blender (usd-core): a stage written by hand with known light
units renders the analytic irradiance; broken input is a clear error; the CLI renders
.usda files. (The Blender → USD → GDMLT round trip is in test_blender.py.)"""

import math
import subprocess
import sys

import numpy as np
import pytest

import gdmlt
from gdmlt import usd
from conftest import read_exr

pxr = pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom, UsdLux, UsdShade, Sdf  # noqa: E402


def _stage(path, light="rect", ior=1.0):
    """A 40×40 grey (albedo 0.5) floor at z = 0 seen from above by a narrow camera, lit by
    one light: a 0.2×0.2 RectLight of intensity 100 (normalize off) 2 units above the
    centre, or a DistantLight of intensity 3 tilted by 30°. IOR 1: no specular lobe, a
    Lambertian floor; None: UsdPreviewSurface's default (1.5)."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    floor = UsdGeom.Mesh.Define(stage, "/World/Floor")
    floor.CreatePointsAttr([(-20, -20, 0), (20, -20, 0), (20, 20, 0), (-20, 20, 0)])
    floor.CreateFaceVertexCountsAttr([4])
    floor.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    floor.CreateSubdivisionSchemeAttr("none")
    mat = UsdShade.Material.Define(stage, "/World/Grey")
    shader = UsdShade.Shader.Define(stage, "/World/Grey/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.5, 0.5, 0.5))
    if ior is not None:
        shader.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(ior)
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(floor.GetPrim()).Bind(mat)
    if light == "rect":
        rect = UsdLux.RectLight.Define(stage, "/World/Light")
        rect.CreateWidthAttr(0.2)
        rect.CreateHeightAttr(0.2)
        rect.CreateIntensityAttr(100.0)
        rect.CreateNormalizeAttr(False)
        UsdGeom.Xformable(rect).AddTranslateOp().Set(Gf.Vec3d(0, 0, 2))  # emits along −Z: down
    else:
        sun = UsdLux.DistantLight.Define(stage, "/World/Light")
        sun.CreateIntensityAttr(3.0)
        sun.CreateAngleAttr(0.0)
        UsdGeom.Xformable(sun).AddRotateXOp().Set(30.0)
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.CreateFocalLengthAttr(50.0)
    cam.CreateHorizontalApertureAttr(2.0)
    cam.CreateVerticalApertureAttr(2.0)
    UsdGeom.Xformable(cam).AddTranslateOp().Set(Gf.Vec3d(0, 0, 5))  # looks down −Z
    stage.GetRootLayer().Save()
    return path


def _layered_brdf_at_normal_incidence(albedo, ior, roughness):
    """f(n, n) of UsdPreviewSurface's dielectric specular lobe over the diffuse base, as the
    core layers them: F·D·G2/(4 cos θo cos θi) + (1 − E)·ρ/π, with the layer's albedo E at
    normal incidence integrated here by quadrature over the half-vector angle (wi = 2θh)."""
    a2 = roughness ** 4
    th = np.linspace(0.0, math.pi / 4, 200001)[:-1] + math.pi / 4 / 400000

    def fresnel(c):
        g = np.sqrt(ior * ior - 1 + c * c)
        return 0.5 * ((g - c) / (g + c)) ** 2 * (1 + ((c * (g + c) - 1) / (c * (g - c) + 1)) ** 2)

    d = a2 / (math.pi * (np.cos(th) ** 2 * (a2 - 1) + 1) ** 2)
    lam_i = 0.5 * (-1 + np.sqrt(1 + a2 * np.tan(2 * th) ** 2))
    e = np.sum(fresnel(np.cos(th)) * d / (1 + lam_i) * np.cos(th) * 2 * math.pi * np.sin(th)) * (math.pi / 4 / 200000)
    return fresnel(1.0) / (math.pi * a2) / 4 + (1 - e) * albedo / math.pi


@pytest.mark.parametrize("light, ior, expected", [
    # small rectangle: E = L·A/h² (to 0.1% at this size) → radiance ρ/π·E
    ("rect", 1.0, 0.5 / math.pi * 100.0 * 0.04 / 4.0),
    # distant light tilted 30°: E = 4·intensity·cos 30° (a sun of strength 4·intensity, as
    # Blender's own USD importer reads a DistantLight)
    ("sun", 1.0, 0.5 / math.pi * 4.0 * 3.0 * math.cos(math.radians(30))),
    # the default IOR 1.5 and roughness 0.5: the specular lobe adds a highlight under the light
    ("rect", None, _layered_brdf_at_normal_incidence(0.5, 1.5, 0.5) * 100.0 * 0.04 / 4.0),
])
def test_light_units_of_a_hand_written_stage(tmp_path, light, ior, expected):
    desc, warnings = usd.load(_stage(tmp_path / "s.usda", light, ior), width=16, height=16)
    assert warnings == []
    img = gdmlt.render(gdmlt.Scene(desc), method="pt", spp=256, max_bounces=0, seed=1)["layers"]["Combined"]
    centre = img[7:9, 7:9].mean(axis=(0, 1))
    noise = img[7:9, 7:9].std() / 2 + 1e-6
    assert np.allclose(centre, expected, rtol=0.01, atol=4 * noise), (centre, expected)


def test_missing_and_broken_stages_are_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        usd.load(tmp_path / "none.usda")
    path = _stage(tmp_path / "b.usda")
    stage = Usd.Stage.Open(str(path))
    UsdGeom.Mesh(stage.GetPrimAtPath("/World/Floor")).GetFaceVertexCountsAttr().Set([5])
    stage.GetRootLayer().Save()
    with pytest.raises(ValueError, match="Floor"):
        usd.load(path)
    UsdGeom.Mesh(stage.GetPrimAtPath("/World/Floor")).GetFaceVertexCountsAttr().Set([4])
    stage.RemovePrim("/World/Cam")
    stage.GetRootLayer().Save()
    with pytest.raises(ValueError, match="no camera"):
        usd.load(path)


def test_cli_renders_a_usd_file(tmp_path):
    path = _stage(tmp_path / "s.usda")
    out = tmp_path / "o.exr"
    r = subprocess.run([sys.executable, "-m", "gdmlt.cli", "render", str(path), "-o", str(out), "--method", "pt",
                        "--spp", "16", "--width", "8"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    img = read_exr(out)
    assert img.shape == (8, 8, 3) and np.isfinite(img).all() and img.mean() > 0


def _winding_normals(mesh):
    """Per triangle: the geometric normal its winding gives, and the mean of its corner normals."""
    p = np.asarray(mesh["positions"], dtype=np.float64)[np.asarray(mesh["indices"]).reshape(-1, 3)]
    ng = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    ns = np.asarray(mesh["normals"], dtype=np.float64).reshape(-1, 3, 3).mean(axis=1)
    return ng, ns


@pytest.mark.parametrize("orientation", ["rightHanded", "leftHanded"])
def test_a_mirrored_mesh_keeps_its_outside(tmp_path, orientation):
    """A transform of negative determinant (a scale of −1, how artists mirror objects) turns
    a mesh's winding inside out; the core orients glass by the winding, so the loader flips
    it back, as Cycles does (its geometric normal is negated for such objects). Each
    triangle's winding normal then points to the side its normals do. Failed before:
    every triangle of the mirrored quad was wound against its normal."""
    path = _stage(tmp_path / "m.usda")
    stage = Usd.Stage.Open(str(path))
    quad = UsdGeom.Mesh.Define(stage, "/World/Mirrored")
    pts = [(-0.5, -0.5, 0), (0.5, -0.5, 0), (0.5, 0.5, 0), (-0.5, 0.5, 0)]
    quad.CreatePointsAttr(pts)
    quad.CreateFaceVertexCountsAttr([4])
    quad.CreateFaceVertexIndicesAttr([0, 1, 2, 3] if orientation == "rightHanded" else [3, 2, 1, 0])
    quad.CreateOrientationAttr(orientation)
    quad.CreateNormalsAttr([(0, 0, 1)] * 4)
    quad.SetNormalsInterpolation("vertex")
    quad.CreateSubdivisionSchemeAttr("none")
    UsdGeom.Xformable(quad).AddScaleOp().Set(Gf.Vec3f(-1, 1, 1))
    stage.GetRootLayer().Save()
    desc, _ = usd.load(path, width=8, height=8)
    mesh = next(m for m in desc["meshes"] if m["name"] == "/World/Mirrored")
    ng, ns = _winding_normals(mesh)
    assert np.allclose(ns / np.linalg.norm(ns, axis=1, keepdims=True), (0, 0, 1))  # the normals stay up
    assert (np.einsum("ij,ij->i", ng, ns) > 0).all(), ng


def test_point_instancer_places_every_instance(tmp_path):
    """A PointInstancer of a unit quad at three positions (one scaled by 2, one rotated) is
    one mesh with three transforms, the instancer's own transform applied, which the core
    stores once and places three times."""
    path = _stage(tmp_path / "i.usda")
    stage = Usd.Stage.Open(str(path))
    inst = UsdGeom.PointInstancer.Define(stage, "/World/Inst")
    UsdGeom.Xformable(inst).AddTranslateOp().Set(Gf.Vec3d(0, 0, 1))
    proto = UsdGeom.Mesh.Define(stage, "/World/Inst/Protos/Quad")
    proto.CreatePointsAttr([(-0.5, -0.5, 0), (0.5, -0.5, 0), (0.5, 0.5, 0), (-0.5, 0.5, 0)])
    proto.CreateFaceVertexCountsAttr([4])
    proto.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    proto.CreateSubdivisionSchemeAttr("none")
    inst.CreatePrototypesRel().SetTargets([proto.GetPath()])
    inst.CreateProtoIndicesAttr([0, 0, 0])
    inst.CreatePositionsAttr([(0, 0, 0), (3, 0, 0), (0, 3, 0)])
    inst.CreateScalesAttr([(1, 1, 1), (2, 2, 2), (1, 1, 1)])
    inst.CreateOrientationsAttr([Gf.Quath(1, 0, 0, 0), Gf.Quath(1, 0, 0, 0),
                                 Gf.Quath(0.7071068, 0.7071068, 0, 0)])  # 90° about x
    stage.GetRootLayer().Save()
    desc, warnings = usd.load(path, width=8, height=8)
    placed = [m for m in desc["meshes"] if "/World/Inst[" in m["name"]]
    assert len(placed) == 1 and placed[0]["transforms"].shape == (3, 12), [m["name"] for m in desc["meshes"]]
    xf = placed[0]["transforms"].astype(np.float64).reshape(-1, 3, 4)
    copies = [{"positions": placed[0]["positions"] @ t[:, :3].T + t[:, 3]} for t in xf]
    centres = sorted(tuple(np.round(m["positions"].mean(axis=0), 4)) for m in copies)
    assert centres == sorted([(0.0, 0.0, 1.0), (3.0, 0.0, 1.0), (0.0, 3.0, 1.0)])
    ext = {tuple(np.round(m["positions"].mean(axis=0), 4)): np.ptp(m["positions"], axis=0) for m in copies}
    assert np.allclose(ext[(3.0, 0.0, 1.0)], (2, 2, 0))  # scaled by 2
    assert np.allclose(ext[(0.0, 3.0, 1.0)], (1, 0, 1), atol=1e-3)  # stood up by the rotation (half floats)
    assert not any(m["name"] == "/World/Inst/Protos/Quad" for m in desc["meshes"])  # prototype not rendered alone
    assert gdmlt.Scene(desc).instances == 3


@pytest.mark.parametrize("opacity, threshold, seen", [(0.25, 0.0, 0.75), (0.25, 0.5, 1.0), (0.75, 0.5, 0.0)])
def test_opacity_is_coverage_and_threshold_cuts_out(tmp_path, opacity, threshold, seen):
    """UsdPreviewSurface opacity (what Blender writes for Principled alpha) becomes the
    material's transparency 1 − opacity (the core's pass-through lobe, tested there); with an
    opacityThreshold it is a cutout: fully transparent below the threshold, else opaque."""
    path = _stage(tmp_path / "veil.usda")
    stage = Usd.Stage.Open(str(path))
    sheet = UsdGeom.Mesh.Define(stage, "/World/Sheet")
    sheet.CreatePointsAttr([(-1, -1, 3), (1, -1, 3), (1, 1, 3), (-1, 1, 3)])
    sheet.CreateFaceVertexCountsAttr([4])
    sheet.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    mat = UsdShade.Material.Define(stage, "/World/Sheer")
    shader = UsdShade.Shader.Define(stage, "/World/Sheer/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0, 0, 0))
    shader.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(opacity)
    shader.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(threshold)
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(sheet.GetPrim()).Bind(mat)
    stage.GetRootLayer().Save()
    desc, warnings = usd.load(path, width=8, height=8)
    sheer = [m for m in desc["materials"] if m["name"] == "Sheer"][0]
    assert sheer.get("transparency", 0.0) == pytest.approx(seen)
    assert not any("opacity" in w for w in warnings)


def test_uv_texture_of_a_hand_written_stage(tmp_path):
    """A UsdUVTexture (an 8-bit PNG: left half red, right half blue, sRGB) read
    through the `st` primvar into diffuseColor: the left of the image shows the decoded red
    albedo and the right the blue one, at the analytic radiance ρ/π·E under the small light."""
    from PIL import Image

    px = np.zeros((2, 16, 3), np.uint8)
    px[:, :8] = (200, 60, 30)
    px[:, 8:] = (30, 60, 200)
    Image.fromarray(px).save(tmp_path / "halves.png")
    path = _stage(tmp_path / "t.usda")
    stage = Usd.Stage.Open(str(path))
    floor = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Floor"))
    # a floor as wide as the camera's view (0.2 at 5 units), st from 0 to 1 across it
    floor.GetPointsAttr().Set([(-0.1, -0.1, 0), (0.1, -0.1, 0), (0.1, 0.1, 0), (-0.1, 0.1, 0)])
    st = UsdGeom.PrimvarsAPI(floor).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    shader = UsdShade.Shader(stage.GetPrimAtPath("/World/Grey/Surface"))
    tex = UsdShade.Shader.Define(stage, "/World/Grey/Tex")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("halves.png")
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
    reader = UsdShade.Shader.Define(stage, "/World/Grey/St")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    shader.GetInput("diffuseColor").ConnectToSource(tex.ConnectableAPI(), "rgb")
    stage.GetRootLayer().Save()
    desc, warnings = usd.load(path, width=16, height=16)
    assert warnings == []
    img = gdmlt.render(gdmlt.Scene(desc), method="pt", spp=256, max_bounces=0, seed=1)["layers"]["Combined"]

    def decode(c):  # sRGB → linear
        c = c / 255.0
        return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)

    e = 100.0 * 0.04 / 4.0  # the small light's irradiance at the centre (see the light-units test)
    for cols, colour in ((slice(1, 6), (200, 60, 30)), (slice(10, 15), (30, 60, 200))):
        got = img[5:11, cols].mean(axis=(0, 1))
        assert np.allclose(got, decode(np.array(colour)) / math.pi * e, rtol=0.03), (got, colour)
    # a metallic map (here the image's red channel) is read as one, not warned and dropped
    stage = Usd.Stage.Open(str(path))
    shader = UsdShade.Shader(stage.GetPrimAtPath("/World/Grey/Surface"))
    tex = UsdShade.Shader(stage.GetPrimAtPath("/World/Grey/Tex"))
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).ConnectToSource(tex.ConnectableAPI(), "r")
    stage.GetRootLayer().Save()
    desc, warnings = usd.load(path, width=16, height=16)
    assert warnings == [] and "metallic_texture" in [m for m in desc["materials"] if m["name"] == "Grey"][0]


def test_colour_primvars_read_by_the_material_are_vertex_colours(tmp_path):
    """diffuseColor fed by a UsdPrimvarReader_float3 of a colour primvar (USD's vertex
    colours): the material multiplies its base colour by the mesh's colours, per corner as
    the primvar's interpolation says — a constant-coloured floor renders ρ/π·E with ρ that
    colour (before: a warning and the reader's fallback, grey); a mesh without the primvar is
    warned and reads black."""
    path = _stage(tmp_path / "c.usda")
    stage = Usd.Stage.Open(str(path))
    floor = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Floor"))
    floor.GetPointsAttr().Set([(-0.1, -0.1, 0), (0.1, -0.1, 0), (0.1, 0.1, 0), (-0.1, 0.1, 0)])
    paint = UsdGeom.PrimvarsAPI(floor).CreatePrimvar("paint", Sdf.ValueTypeNames.Color3fArray,
                                                     UsdGeom.Tokens.vertex)
    paint.Set([(0.2, 0.5, 0.8)] * 4)
    shader = UsdShade.Shader(stage.GetPrimAtPath("/World/Grey/Surface"))
    reader = UsdShade.Shader.Define(stage, "/World/Grey/Paint")
    reader.CreateIdAttr("UsdPrimvarReader_float3")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("paint")
    reader.CreateInput("fallback", Sdf.ValueTypeNames.Float3).Set((0.5, 0.5, 0.5))
    shader.GetInput("diffuseColor").ConnectToSource(reader.ConnectableAPI(), "result")
    stage.GetRootLayer().Save()
    desc, warnings = usd.load(path, width=16, height=16)
    assert warnings == []
    mat = [m for m in desc["materials"] if m["name"] == "Grey"][0]
    assert mat["vertex_color"] and "vertex_color_layer" not in mat
    mesh = next(m for m in desc["meshes"] if m["name"] == "/World/Floor")
    assert np.allclose(mesh["colors"], (0.2, 0.5, 0.8)) and len(mesh["colors"]) == 3 * len(mesh["indices"])
    img = gdmlt.render(gdmlt.Scene(desc), method="pt", spp=256, max_bounces=0, seed=1)["layers"]["Combined"]
    e = 100.0 * 0.04 / 4.0  # the small light's irradiance at the centre (see the light-units test)
    got = img[6:10, 6:10].mean(axis=(0, 1))
    assert np.allclose(got, np.array([0.2, 0.5, 0.8]) / math.pi * e, rtol=0.03), got
    paint.GetAttr().Clear()
    stage.GetRootLayer().Save()
    desc, warnings = usd.load(path, width=16, height=16)
    assert any("paint" in w and "black" in w for w in warnings), warnings


@pytest.mark.parametrize("writer", [None, "Blender v5.3.0", "Blender v5.0.1"])
def test_a_dome_texture_is_oriented_as_usdlux_says(tmp_path, writer):
    """A DomeLight's latlong texture follows UsdLux (OpenEXR's latlong map: latitude ±π/2 along
    the dome's ±Y, longitude 0 along +Z and π/2 along +X), as Blender writes it from 5.1 on (and
    4.5): read as Blender's own Z-up mapping before, Blender 5.3's HDRI world came back turned
    (block differences 170× the noise; failed before). Only a stage Blender 5.0 wrote, whose
    exporter wrote its own mapping unrotated, keeps that. Checked on the world rotation the
    reader hands the core: where the texture's pole, centre and quarter point lie."""
    path = _stage(tmp_path / "dome.usda")
    exr = tmp_path / "sky.exr"
    gdmlt.write_exr(str(exr), [("Combined", np.ones((4, 8, 3), np.float32))])
    stage = Usd.Stage.Open(str(path))
    if writer is not None:
        stage.GetRootLayer().documentation = writer
    dome = UsdLux.DomeLight.Define(stage, "/World/Sky")
    dome.CreateTextureFileAttr(str(exr))
    stage.GetRootLayer().Save()
    desc, warnings = usd.load(path, width=8, height=8)
    assert warnings == [] and desc["world_texture"] is not None
    r = np.asarray(desc["world_rotation"], np.float64)  # world → the core's equirectangular frame
    # the core's frame: pole +Z, the image's centre along +X, a quarter of its width along +Y
    expected = {(0, 1, 0): (0, 0, 1), (0, 0, 1): (1, 0, 0), (1, 0, 0): (0, 1, 0)}
    if writer == "Blender v5.0.1":
        expected = {d: d for d in expected}
    for world, frame in expected.items():
        assert np.allclose(r @ np.array(world, np.float64), frame, atol=1e-6), (world, r)
