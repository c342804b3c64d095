"""Mesh features read from USD (renderer/usd/geometry/mesh.py, renderer/usd/geometry/primvars.py): holes, GeomSubsets through holes
and refinement, subdivision surfaces as imported and rendered."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt

import stages
from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, prepare, render_frame
from renderer.usd.importer import load_scene


def grid_mesh(stage, path, n=2, size=2.0, z=0.0, scheme=UsdGeom.Tokens.none):
    """An n x n grid of quads over [-size/2, size/2]^2 at height z, facing +z; face f = row * n + col."""
    xs = np.linspace(-size / 2, size / 2, n + 1)
    pts = [(x, y, z) for y in xs for x in xs]
    idx = []
    for r in range(n):
        for c in range(n):
            a = r * (n + 1) + c
            idx += [a, a + 1, a + n + 2, a + n + 1]
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]))
    m.CreateFaceVertexCountsAttr([4] * (n * n))
    m.CreateFaceVertexIndicesAttr(idx)
    m.CreateSubdivisionSchemeAttr(scheme)
    return m


def render(path, **opts):
    scene = load_scene(path, 0.0)
    prep = prepare(scene, RenderOptions(**opts))
    ch = frame_channels(prep, render_frame(prep, tile_size=32, threads=2).sums)
    return np.stack([ch["R"], ch["G"], ch["B"], ch["A"]], -1), scene


# ---------------------------------------------------------------------------------------------------------------
# holes


def test_hole_faces_are_dropped_and_subsets_stay_on_their_faces(tmp_path):
    stage = stages.new_stage(tmp_path / "holes.usda")
    red = stages.material(stage, "Red", diffuse=(0.8, 0.1, 0.1))
    blue = stages.material(stage, "Blue", diffuse=(0.1, 0.1, 0.8))
    m = grid_mesh(stage, "/World/Grid", n=2)
    m.CreateHoleIndicesAttr([1, 7, -2])  # out-of-range indices are ignored
    binding = UsdShade.MaterialBindingAPI.Apply(m.GetPrim())
    binding.Bind(red)
    sub = binding.CreateMaterialBindSubset("blue", Vt.IntArray([1, 2]))
    UsdShade.MaterialBindingAPI.Apply(sub.GetPrim()).Bind(blue)
    stage.Save()
    scene = load_scene(tmp_path / "holes.usda", 0.0)
    mesh = scene.meshes[0]
    assert len(mesh.triangles) == 6, "3 quads of 4 remain"
    names = [scene.materials[i].name for i in mesh.material_ids]
    # faces 0, 2, 3 in order; face 2 keeps the subset's blue although face 1 before it is gone
    assert names == ["/World/Looks/Red"] * 2 + ["/World/Looks/Blue"] * 2 + ["/World/Looks/Red"] * 2
    centres = mesh.points[0][mesh.triangles].mean(1)
    assert not np.any((centres[:, 0] > 0) & (centres[:, 1] < 0)), "nothing left in face 1's quadrant"


def test_a_hole_renders_as_a_hole(tmp_path):
    """Orthographic camera straight down on a 2 x 2 grid whose face 3 (x > 0, y > 0) is a hole: that quarter
    of the image shows the background (alpha 0), the other three quarters are covered."""
    stage = stages.new_stage(tmp_path / "hole.usda")
    stages.camera(stage, ortho=True, h_ap_mm=20.0, v_ap_mm=20.0, translate=(0, 0, 5), tenths_per_mm=1.0)
    emit = stages.material(stage, "E", emissive=(1, 1, 1))
    m = grid_mesh(stage, "/World/Grid", n=2)
    m.CreateHoleIndicesAttr([3])
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(emit)
    stage.Save()
    rgba, _ = render(tmp_path / "hole.usda", width=32, height=32, spp=4, filter="box")
    a = rgba[..., 3]
    # image row 0 is the top (+y); column 0 is the left (-x)
    assert np.all(a[2:14, 18:30] == 0.0), "the hole's quarter is empty"
    for q in (a[2:14, 2:14], a[18:30, 2:14], a[18:30, 18:30]):
        assert np.all(q == 1.0)


# ---------------------------------------------------------------------------------------------------------------
# subdivision surfaces

CUBE_P = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]  # index 4x + 2y + z
CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]  # outward


def cube_cage(stage, path, left_handed=False, creased=False):
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in CUBE_P]))
    m.CreateFaceVertexCountsAttr([4] * 6)
    faces = [f[::-1] for f in CUBE_F] if left_handed else CUBE_F
    m.CreateFaceVertexIndicesAttr(sum(faces, []))
    if left_handed:
        m.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    if creased:
        edges = sorted({tuple(sorted((f[k], f[(k + 1) % 4]))) for f in CUBE_F for k in range(4)})
        m.CreateCreaseIndicesAttr(Vt.IntArray([int(v) for e in edges for v in e]))
        m.CreateCreaseLengthsAttr([2] * 12)
        m.CreateCreaseSharpnessesAttr([10.0] * 12)
    return m  # subdivisionScheme not authored: catmullClark, USD's default


def mesh_volume(mesh):
    t = mesh.points[0][mesh.triangles].astype(np.float64)
    return np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0


def test_subdivided_cube_cage_imports_as_its_limit_surface(tmp_path):
    stage = stages.new_stage(tmp_path / "cc.usda")
    cube_cage(stage, "/World/Smooth")
    cube_cage(stage, "/World/Left", left_handed=True)
    cube_cage(stage, "/World/Creased", creased=True)
    stage.Save()
    scene = load_scene(tmp_path / "cc.usda", 0.0, subdivision_level=4)
    meshes = {m.name.rsplit("/", 1)[1]: m for m in scene.meshes}
    assert mesh_volume(meshes["Smooth"]) == pytest.approx(8 * 0.32747, rel=5e-3)
    assert mesh_volume(meshes["Left"]) == pytest.approx(8 * 0.32747, rel=5e-3), "leftHanded: still outward"
    assert mesh_volume(meshes["Creased"]) == pytest.approx(8.0, abs=1e-5)
    for m in meshes.values():
        centre = m.points[0][m.triangles].mean(1)
        assert np.all(np.einsum("tij,tj->ti", m.normals, centre) > 0), "normals point out of the solid"
        assert len(m.triangles) == 6 * 2 * 4 ** 4 and np.all(m.material_ids == m.material_ids[0])
    assert not any("subdivision" in w for w in scene.warnings)


def test_refinement_level_follows_the_camera(tmp_path):
    stage = stages.new_stage(tmp_path / "lvl.usda")
    stages.camera(stage, translate=(0, 0, 0), h_ap_mm=36.0, focal_mm=50.0)
    for name, z in (("Near", -6.0), ("Far", -600.0)):
        xf = UsdGeom.Xform.Define(stage, f"/World/{name}")
        xf.AddTranslateOp().Set(Gf.Vec3d(0, 0, z))
        cube_cage(stage, f"/World/{name}/Cage")
    stage.Save()
    scene = load_scene(tmp_path / "lvl.usda", 0.0, width=640)
    tris = {m.name.split("/")[2]: len(m.triangles) for m in scene.meshes}
    # near: a 2-unit edge at 6 units spans ~300 px -> level 4 (capped); far: ~3 px -> level 1
    assert tris["Near"] == 48 * 4 ** 3 and tris["Far"] == 48
    scene = load_scene(tmp_path / "lvl.usda", 0.0, subdivision_level=0)
    assert {len(m.triangles) for m in scene.meshes} == {12}, "level 0 is the cage"
    with pytest.raises(Exception, match="subdivision level"):
        load_scene(tmp_path / "lvl.usda", 0.0, subdivision_level=9)


def test_subdivided_silhouette_is_the_limit_surface(tmp_path):
    """Orthographic view along -z of the Catmull-Clark cube: covered pixels = the area of the limit surface's
    outline (from an independent level-6 refinement), clearly less than the cage's 2 x 2 square."""
    from scipy.spatial import ConvexHull

    from renderer.subdiv import SubdivOptions, subdivide

    stage = stages.new_stage(tmp_path / "sil.usda")
    stages.camera(stage, ortho=True, h_ap_mm=30.0, v_ap_mm=30.0, translate=(0, 0, 5), tenths_per_mm=1.0)
    emit = stages.material(stage, "E", emissive=(1, 1, 1))
    UsdShade.MaterialBindingAPI.Apply(cube_cage(stage, "/World/Cage").GetPrim()).Bind(emit)
    stage.Save()
    rgba, scene = render(tmp_path / "sil.usda", width=96, height=96, spp=16, filter="box")
    covered = rgba[..., 3].sum() * (3.0 / 96) ** 2
    ref = subdivide([4] * 6, sum(CUBE_F, []), 8, SubdivOptions(), 6)
    outline = ConvexHull(ref.points(np.array(CUBE_P, float))[:, :2]).volume
    assert covered == pytest.approx(outline, rel=0.015)
    assert outline < 0.8 * 4.0


def test_subdivided_texture_coordinates_and_named_uv_sets(tmp_path):
    """st (faceVarying, linear 'all') on a flat subdivided grid is the bilinear map of the cage: every refined
    corner keeps uv = xy of the cage; a second set read by name for materials lines up with the same
    triangles; varying uvs refine linearly too."""
    from renderer.usd.geometry.primvars import read_named_uvs
    from renderer.usd.stage import WarningLog

    stage = stages.new_stage(tmp_path / "uv.usda")
    m = grid_mesh(stage, "/World/Grid", n=2, size=2.0, scheme=UsdGeom.Tokens.catmullClark)
    m.CreateFaceVaryingLinearInterpolationAttr("all")
    xy = [(x, y) for y in (-1.0, 0.0, 1.0) for x in (-1.0, 0.0, 1.0)]
    idx = list(m.GetFaceVertexIndicesAttr().Get())
    api = UsdGeom.PrimvarsAPI(m)
    st = api.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set(Vt.Vec2fArray([Gf.Vec2f(*xy[i]) for i in idx]))
    uv2 = api.CreatePrimvar("uv2", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.varying)
    uv2.Set(Vt.Vec2fArray([Gf.Vec2f(*p) for p in xy]))
    stage.Save()
    scene = load_scene(tmp_path / "uv.usda", 0.0, subdivision_level=2)
    mesh = scene.meshes[0]
    assert mesh.uvs.shape == (len(mesh.triangles), 3, 2)
    # the smooth surface pulls the boundary in, but the bilinear uvs sit on the dyadic grid of the cage
    assert set(np.round(mesh.uvs.reshape(-1), 6)) <= {round(k / 4 - 1, 6) for k in range(9)}
    prim = stage.GetPrimAtPath("/World/Grid")
    named = read_named_uvs(prim, "uv2", 0.0, WarningLog(), level=2)
    np.testing.assert_allclose(named, mesh.uvs, atol=1e-6)


def test_inconsistent_creases_are_ignored_with_a_warning(tmp_path):
    stage = stages.new_stage(tmp_path / "bad.usda")
    m = cube_cage(stage, "/World/Cage")
    m.CreateCreaseIndicesAttr(Vt.IntArray([0, 1, 3]))
    m.CreateCreaseLengthsAttr(Vt.IntArray([2]))
    m.CreateCreaseSharpnessesAttr(Vt.FloatArray([10.0]))
    stage.Save()
    scene = load_scene(tmp_path / "bad.usda", 0.0, subdivision_level=3)
    assert mesh_volume(scene.meshes[0]) == pytest.approx(2.5770, rel=1e-3), "level 3, smooth: creases ignored"
    assert any("creases" in w and "/World/Cage" in w for w in scene.warnings)


def test_level_choice_from_projected_edges_and_the_triangle_cap():
    from renderer.usd.geometry.subdiv import SubdivisionDetail

    counts = np.full(6, 4)
    edges = np.array([[0, 1]])
    pts = np.array([[0.0, 0.0, -10.0], [1.0, 0.0, -10.0]])
    near = SubdivisionDetail(camera_position=(0, 0, 0), pixels_per_radian=640.0)  # the edge spans 64 px
    assert near.edge_length_px(pts, edges) == pytest.approx(640.0 / np.hypot(10.0, 0.5))  # from its midpoint
    assert near.choose(counts, "catmullClark", pts, edges) == 4  # 64 / 2^4 = 4 px
    assert SubdivisionDetail(camera_position=(0, 0, 0), pixels_per_radian=64.0).choose(
        counts, "catmullClark", pts, edges) == 1  # 6.4 px: one level (never the cage)
    assert SubdivisionDetail(pixels_per_unit=32.0).choose(counts, "catmullClark", pts, edges) == 3
    capped = SubdivisionDetail(level=6, max_triangles=1000)
    assert capped.choose(counts, "catmullClark", pts, edges) == 3  # 768 triangles; level 4 would make 3072


def test_geom_subsets_follow_refinement_and_holes(tmp_path):
    stage = stages.new_stage(tmp_path / "subsets.usda")
    red = stages.material(stage, "Red", diffuse=(0.8, 0.1, 0.1))
    blue = stages.material(stage, "Blue", diffuse=(0.1, 0.1, 0.8))
    m = grid_mesh(stage, "/World/Grid", n=2, scheme=UsdGeom.Tokens.catmullClark)
    m.CreateHoleIndicesAttr([0])
    binding = UsdShade.MaterialBindingAPI.Apply(m.GetPrim())
    binding.Bind(red)
    sub = binding.CreateMaterialBindSubset("blue", Vt.IntArray([3]))
    UsdShade.MaterialBindingAPI.Apply(sub.GetPrim()).Bind(blue)
    stage.Save()
    scene = load_scene(tmp_path / "subsets.usda", 0.0, subdivision_level=2)
    mesh = scene.meshes[0]
    names = np.array([scene.materials[i].name for i in mesh.material_ids])
    assert len(mesh.triangles) == 3 * 4 * 2 * 4, "3 faces of 4 remain, each 16 quads"
    centre = mesh.points[0][mesh.triangles].mean(1)
    is_blue = names == "/World/Looks/Blue"
    assert is_blue.sum() == 32 and np.all(centre[is_blue, 0] > 0) and np.all(centre[is_blue, 1] > 0)
    assert not np.any((centre[:, 0] < 0) & (centre[:, 1] < 0)), "face 0 (x < 0, y < 0) is a hole"
