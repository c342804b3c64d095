"""displayColor that varies over a mesh (Houdini's Cd, Maya's colour sets): per-vertex, per-face-vertex and per-face
colours are interpolated across each triangle, on polygon meshes and subdivision surfaces alike, for the fallback
material and for a UsdPreviewSurface whose diffuseColor reads displayColor through a UsdPrimvarReader_float3; along
BasisCurves and per point of a Points prim too.

Seen from above under a white dome of radiance 1, a diffuse surface's colour shows its albedo's hue: the left edge
of a quad coloured red on the left and blue on the right is red, the right edge blue, the middle purple; with the
colours averaged (what a constant-only renderer does) all three would be the same purple."""
from __future__ import annotations

import pytest
from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt

import stages
from renders import render_rgb

RED, BLUE, GREEN = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)


def grid_stage(tmp_path, *, subdivision="none", name="colors.usda"):
    """A 2x1 grid of quads over x in [-1, 1], z in [-0.5, 0.5] (y = 0, facing up), an orthographic camera above
    it seeing exactly that rectangle, and a white dome."""
    stage = stages.new_stage(tmp_path / name)
    stages.camera(stage, ortho=True, h_ap_mm=20.0, v_ap_mm=10.0, translate=(0, 5, 0), rotate_x=-90.0,
                  tenths_per_mm=1.0)
    stages.dome_light(stage)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Grid")
    pts = [(-1, 0, 0.5), (0, 0, 0.5), (1, 0, 0.5), (-1, 0, -0.5), (0, 0, -0.5), (1, 0, -0.5)]
    mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]))
    mesh.CreateFaceVertexCountsAttr([4, 4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 4, 3, 1, 2, 5, 4])
    mesh.CreateSubdivisionSchemeAttr(subdivision)
    return stage, mesh


def set_colors(gprim, interpolation, colors) -> None:
    UsdGeom.PrimvarsAPI(gprim).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                             interpolation).Set(Vt.Vec3fArray([Gf.Vec3f(*c) for c in colors]))


RED_TO_BLUE = (RED, (0.5, 0, 0.5), BLUE)  # the grid's three vertex columns, left to right


def columns(rgb):
    """Mean colour of the left, middle and right columns of pixels."""
    w = rgb.shape[1]
    return rgb[:, :2].reshape(-1, 3).mean(0), rgb[:, w // 2 - 1: w // 2 + 1].reshape(-1, 3).mean(0), \
        rgb[:, -2:].reshape(-1, 3).mean(0)


def render(stage):
    stage.GetRootLayer().Save()
    rgb, _ = render_rgb(stage.GetRootLayer().realPath, width=20, height=10, spp=16, max_depth=1)
    return rgb


def red_to_blue(left, mid, right):
    assert left[0] > 4 * left[2], left  # red
    assert right[2] > 4 * right[0], right  # blue
    assert 0.6 < mid[0] / mid[2] < 1.6, mid  # purple halfway


@pytest.mark.parametrize("subdivision", ["none", "catmullClark"])
def test_vertex_colours_are_interpolated(tmp_path, subdivision):
    stage, mesh = grid_stage(tmp_path, subdivision=subdivision)
    set_colors(mesh, UsdGeom.Tokens.vertex, RED_TO_BLUE * 2)
    red_to_blue(*columns(render(stage)))


def test_face_varying_and_uniform_colours(tmp_path):
    stage, mesh = grid_stage(tmp_path)
    # face 0 (left) red at its left corners and purple at its right ones; face 1 purple then blue
    purple = (0.5, 0, 0.5)
    set_colors(mesh, UsdGeom.Tokens.faceVarying, (RED, purple, purple, RED, purple, BLUE, BLUE, purple))
    red_to_blue(*columns(render(stage)))

    stage, mesh = grid_stage(tmp_path, name="uniform.usda")
    set_colors(mesh, UsdGeom.Tokens.uniform, (GREEN, RED))
    left, _, right = columns(render(stage))
    assert left[1] > 4 * max(left[0], left[2]) and right[0] > 4 * max(right[1], right[2]), (left, right)


def test_a_primvar_reader_of_display_color_feeds_diffuse(tmp_path):
    stage, mesh = grid_stage(tmp_path)
    mat = UsdShade.Material.Define(stage, "/World/Looks/Cd")
    surf = UsdShade.Shader.Define(stage, "/World/Looks/Cd/Surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    reader = UsdShade.Shader.Define(stage, "/World/Looks/Cd/Reader")
    reader.CreateIdAttr("UsdPrimvarReader_float3")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("displayColor")
    out = reader.CreateOutput("result", Sdf.ValueTypeNames.Float3)
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(out)
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(1.0)
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)
    set_colors(mesh, UsdGeom.Tokens.vertex, RED_TO_BLUE * 2)
    red_to_blue(*columns(render(stage)))


def test_a_constant_display_color_is_unchanged(tmp_path):
    stage, mesh = grid_stage(tmp_path)
    set_colors(mesh, UsdGeom.Tokens.constant, (GREEN,))
    left, mid, right = columns(render(stage))
    for c in (left, mid, right):
        assert c[1] > 4 * max(c[0], c[2]), c


def test_curve_and_point_colours(tmp_path):
    # a wide linear curve along x, red at its left end and blue at its right; then two points, green and red
    stage, mesh = grid_stage(tmp_path, name="curve.usda")
    stage.RemovePrim(mesh.GetPath())
    curve = UsdGeom.BasisCurves.Define(stage, "/World/Curve")
    curve.CreateTypeAttr("linear")
    curve.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(-1.2, 0, 0), Gf.Vec3f(0, 0, 0), Gf.Vec3f(1.2, 0, 0)]))
    curve.CreateCurveVertexCountsAttr([3])
    curve.CreateWidthsAttr([1.2])
    set_colors(curve, UsdGeom.Tokens.vertex, RED_TO_BLUE)
    red_to_blue(*columns(render(stage)))

    stage, mesh = grid_stage(tmp_path, name="points.usda")
    stage.RemovePrim(mesh.GetPath())
    points = UsdGeom.Points.Define(stage, "/World/Points")
    points.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(-0.5, 0, 0), Gf.Vec3f(0.5, 0, 0)]))
    points.CreateWidthsAttr([0.9, 0.9])
    set_colors(points, UsdGeom.Tokens.vertex, (GREEN, RED))
    rgb = render(stage)
    left, right = rgb[3:7, 3:7].reshape(-1, 3).mean(0), rgb[3:7, 13:17].reshape(-1, 3).mean(0)
    assert left[1] > 4 * max(left[0], left[2]) and right[0] > 4 * max(right[1], right[2]), (left, right)
