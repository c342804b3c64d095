"""USD import (renderer/usd/importer.py and the rest of renderer/usd): small stages authored with pxr, plus every
shipped asset."""
from __future__ import annotations

import json
import math
import pathlib
import time

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdRender, UsdShade, Vt

from renderer.scene import model as sc
from renderer.errors import SceneError
from renderer.motion.transform import make_transform, matrix_at, quat_to_matrix
from renderer.usd.geometry.triangulation import triangulate
from renderer.usd.motion import motion_transforms
from renderer.usd.importer import load_scene

ASSETS = pathlib.Path("/work/shared/usd-assets")
HEAVY = pathlib.Path("/work/shared/bench/scenes/heavy.usda")


# ---------------------------------------------------------------------------------------------------------------
# helpers


def new_stage(tmp_path, name="scene.usda", *, up="Y", mpu=0.01, tcps=24.0, start=None, end=None):
    path = str(tmp_path / name)
    stage = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up == "Z" else UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    stage.SetTimeCodesPerSecond(tcps)
    if start is not None:
        stage.SetStartTimeCode(start)
        stage.SetEndTimeCode(end if end is not None else start)
    return stage, path


def save_and_load(stage, path, **kw):
    stage.GetRootLayer().Save()
    return load_scene(path, **kw)


def add_mesh(stage, where, points, counts, indices, **attrs):
    m = UsdGeom.Mesh.Define(stage, where)
    m.CreatePointsAttr([Gf.Vec3f(*p) for p in points])
    m.CreateFaceVertexCountsAttr(list(counts))
    m.CreateFaceVertexIndicesAttr(list(indices))
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    for k, v in attrs.items():
        m.GetPrim().GetAttribute(k).Set(v) if m.GetPrim().HasAttribute(k) else None
    return m


def add_tri(stage, where="/World/Tri"):
    return add_mesh(stage, where, [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [3], [0, 1, 2])


def add_camera(stage, where="/World/Cam", shutter=(0.0, 0.0)):
    cam = UsdGeom.Camera.Define(stage, where)
    cam.CreateShutterOpenAttr(shutter[0])
    cam.CreateShutterCloseAttr(shutter[1])
    return cam


def tri_normals(mesh, key=0):
    p = mesh.points[key][mesh.triangles]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def world_points(scene, inst, s=0.0):
    mesh = scene.meshes[inst.mesh]
    m = matrix_at(inst.transform, s)
    return mesh.points[0] @ m[:3, :3].T + m[:3, 3]


def by_name(items, suffix):
    hits = [x for x in items if x.name.endswith(suffix)]
    assert len(hits) == 1, [x.name for x in items]
    return hits[0]


# ---------------------------------------------------------------------------------------------------------------
# geometry


def test_triangulation_counts_and_concave_polygon():
    # quad, convex pentagon, concave "L" hexagon, all in the z = 0 plane
    pts = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
                    (3, 0, 0), (4, 0, 0), (4.5, 1, 0), (3.5, 2, 0), (2.5, 1, 0),
                    (0, 3, 0), (2, 3, 0), (2, 4, 0), (1, 4, 0), (1, 5, 0), (0, 5, 0)], np.float32)
    counts = np.array([4, 5, 6])
    idx = np.arange(15)
    corners, faces = triangulate(counts, idx, pts)
    assert len(corners) == 2 + 3 + 4
    np.testing.assert_array_equal(np.bincount(faces), [2, 3, 4])
    tri = pts[idx[corners]]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(cross[:, 2] > 0), "every triangle keeps the polygons' counter-clockwise winding"
    area_l = 0.5 * cross[faces == 2, 2].sum()
    assert area_l == pytest.approx(3.0), "ear clipping covers the L exactly (a fan would overlap)"


def test_mesh_triangulation_and_left_handed_winding(tmp_path):
    stage, path = new_stage(tmp_path)
    quad = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    add_mesh(stage, "/World/Right", quad, [4], [0, 1, 2, 3])
    left = add_mesh(stage, "/World/Left", quad, [4], [0, 1, 2, 3])
    left.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    scene = save_and_load(stage, path)
    right_m, left_m = by_name(scene.meshes, "Right"), by_name(scene.meshes, "Left")
    assert right_m.triangles.shape == (2, 3) and right_m.triangles.dtype == np.int32
    assert np.all(tri_normals(right_m)[:, 2] > 0)
    assert np.all(tri_normals(left_m)[:, 2] < 0), "leftHanded: the front is -Z, so CCW-from-front flips"
    assert right_m.points.dtype == np.float32 and right_m.points.shape == (1, 4, 3)


def test_normals_and_uv_interpolations(tmp_path):
    stage, path = new_stage(tmp_path)
    quad = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]

    fv = add_mesh(stage, "/World/FaceVarying", quad, [4], [0, 1, 2, 3])
    fv.CreateNormalsAttr([Gf.Vec3f(0, 0, 1), Gf.Vec3f(1, 0, 0), Gf.Vec3f(0, 1, 0), Gf.Vec3f(0, 0, -1)])
    fv.SetNormalsInterpolation(UsdGeom.Tokens.faceVarying)

    un = add_mesh(stage, "/World/Uniform", quad + [(2, 0, 0), (2, 1, 0)], [4, 4], [0, 1, 2, 3, 1, 4, 5, 2])
    un.CreateNormalsAttr([Gf.Vec3f(0, 0, 1), Gf.Vec3f(0, 1, 0)])
    un.SetNormalsInterpolation(UsdGeom.Tokens.uniform)

    vx = add_mesh(stage, "/World/Vertex", quad, [4], [0, 1, 2, 3])
    vx.CreateNormalsAttr([Gf.Vec3f(0, 0, 1)] * 4)  # loses against primvars:normals below
    pv = UsdGeom.PrimvarsAPI(vx).CreatePrimvar("normals", Sdf.ValueTypeNames.Normal3fArray, UsdGeom.Tokens.vertex)
    pv.Set([Gf.Vec3f(1, 0, 0), Gf.Vec3f(0, 1, 0), Gf.Vec3f(0, 0, 1), Gf.Vec3f(-1, 0, 0)])
    st = UsdGeom.PrimvarsAPI(vx).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                               UsdGeom.Tokens.faceVarying)
    st.Set([Gf.Vec2f(0, 0), Gf.Vec2f(1, 1)])
    st.SetIndices(Vt.IntArray([0, 1, 1, 0]))  # indexed primvar

    scene = save_and_load(stage, path)
    m = by_name(scene.meshes, "FaceVarying")
    assert m.normals.shape == (2, 3, 3) and m.normals.dtype == np.float32
    by_corner = {tuple(m.points[0][v]): tuple(n) for t, tn in zip(m.triangles, m.normals) for v, n in zip(t, tn)}
    assert by_corner[(1.0, 0.0, 0.0)] == (1.0, 0.0, 0.0) and by_corner[(0.0, 1.0, 0.0)] == (0.0, 0.0, -1.0)

    m = by_name(scene.meshes, "Uniform")
    assert m.normals.shape == (4, 3, 3)
    np.testing.assert_array_equal(m.normals[:2], np.broadcast_to([0, 0, 1], (2, 3, 3)))
    np.testing.assert_array_equal(m.normals[2:], np.broadcast_to([0, 1, 0], (2, 3, 3)))

    m = by_name(scene.meshes, "Vertex")
    want = {0: (1, 0, 0), 1: (0, 1, 0), 2: (0, 0, 1), 3: (-1, 0, 0)}
    for t, tn in zip(m.triangles, m.normals):
        for v, n in zip(t, tn):
            assert tuple(n) == want[int(v)], "primvars:normals (vertex) wins over the normals attribute"
    assert m.uvs.shape == (2, 3, 2)
    uv_of = {int(v): tuple(uv) for t, tu in zip(m.triangles, m.uvs) for v, uv in zip(t, tu)}
    assert uv_of == {0: (0, 0), 1: (1, 1), 2: (1, 1), 3: (0, 0)}


def test_primitives_are_tessellated_to_size(tmp_path):
    stage, path = new_stage(tmp_path)
    UsdGeom.Sphere.Define(stage, "/World/Sphere").CreateRadiusAttr(2.5)
    UsdGeom.Cube.Define(stage, "/World/Cube").CreateSizeAttr(3.0)
    cyl = UsdGeom.Cylinder.Define(stage, "/World/Cyl")
    cyl.CreateRadiusAttr(0.5)
    cyl.CreateHeightAttr(4.0)
    cyl.CreateAxisAttr(UsdGeom.Tokens.x)
    cone = UsdGeom.Cone.Define(stage, "/World/Cone")
    cone.CreateHeightAttr(2.0)
    cap = UsdGeom.Capsule.Define(stage, "/World/Capsule")
    cap.CreateRadiusAttr(1.0)
    cap.CreateHeightAttr(2.0)
    cap.CreateAxisAttr(UsdGeom.Tokens.y)
    scene = save_and_load(stage, path)
    # still implicit prims arrive as their exact shape with a one-triangle stand-in spanning the shape's box;
    # their tessellation is made on demand (scene.analytic.realize_tessellations)
    for name in ("Sphere", "Cyl", "Cone", "Capsule"):
        m = by_name(scene.meshes, name)
        assert m.shape is not None and m.tessellate is not None and len(m.triangles) == 1 and m.solid.all()
        box = m.points[0].min(0), m.points[0].max(0)
        m.realize()
        assert m.tessellate is None and m.solid is None and len(m.material_ids) == len(m.triangles) > 100
        np.testing.assert_allclose(m.points[0].min(0), box[0], atol=1e-6)
        np.testing.assert_allclose(m.points[0].max(0), box[1], atol=1e-6)

    s = by_name(scene.meshes, "Sphere")
    r = np.linalg.norm(s.points[0], axis=1)
    np.testing.assert_allclose(r, 2.5, rtol=1e-5)
    assert len(s.triangles) >= 64 * 30, "a fine tessellation (64 x 32)"
    np.testing.assert_allclose(np.linalg.norm(s.normals, axis=-1), 1.0, rtol=1e-5)
    centroid = s.points[0][s.triangles].mean(axis=1)
    assert np.all(np.sum(tri_normals(s) * centroid, axis=1) > 0), "outward-facing, counter-clockwise"
    # the flat facets of a 64 x 32 sphere stay within 0.5 % of the radius
    assert np.linalg.norm(centroid, axis=1).min() > 2.5 * 0.995

    c = by_name(scene.meshes, "Cube")
    np.testing.assert_allclose(np.abs(c.points[0]), 1.5)
    assert len(c.triangles) == 12
    centroid = c.points[0][c.triangles].mean(axis=1)
    assert np.all(np.sum(tri_normals(c) * centroid, axis=1) > 0)

    y = by_name(scene.meshes, "Cyl")
    np.testing.assert_allclose(y.points[0][:, 0].min(), -2.0)
    np.testing.assert_allclose(y.points[0][:, 0].max(), 2.0)
    np.testing.assert_allclose(np.linalg.norm(y.points[0][:, 1:], axis=1).max(), 0.5, rtol=1e-5)

    k = by_name(scene.meshes, "Cone")
    top = k.points[0][np.argmax(k.points[0][:, 2])]
    np.testing.assert_allclose(top, [0, 0, 1], atol=1e-6)

    p = by_name(scene.meshes, "Capsule")
    np.testing.assert_allclose([p.points[0][:, 1].min(), p.points[0][:, 1].max()], [-2.0, 2.0], rtol=1e-5)


def test_bad_meshes_are_skipped_with_one_warning(tmp_path):
    stage, path = new_stage(tmp_path)
    for i in range(3):
        add_mesh(stage, f"/World/NaN{i}", [(0, 0, 0), (1, float("nan"), 0), (0, 1, 0)], [3], [0, 1, 2])
    add_mesh(stage, "/World/Lines", [(0, 0, 0), (1, 0, 0)], [2], [0, 1])
    add_tri(stage)
    scene = save_and_load(stage, path)
    assert [m.name for m in scene.meshes] == ["/World/Tri"]
    nan_lines = [w for w in scene.warnings if "NaN" in w]
    assert len(nan_lines) == 1 and "(3)" in nan_lines[0]
    assert any("zero triangles" in w for w in scene.warnings)


def test_unreadable_prims_are_skipped_not_raised(tmp_path):
    path = tmp_path / "weird.usda"
    path.write_text('#usda 1.0\ndef Sphere "S"\n{\n    string radius = "big"\n}\n'
                    'def Mesh "M"\n{\n    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0, 1, 7]\n'
                    '    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]\n}\n'
                    'def SphereLight "L"\n{\n    string inputs:intensity = "x"\n}\ndef Cube "C"\n{\n}\n')
    scene = load_scene(path)
    assert [i.name for i in scene.instances] == ["/C"]
    assert any("unreadable" in w and "/S" in w and "/L" in w for w in scene.warnings)
    assert any("invalid topology" in w and "/M" in w for w in scene.warnings)


def test_prims_of_unknown_types_are_named_in_a_warning(tmp_path):
    # A renderer's own procedural (no schema in usd-core) draws nothing here and says so; typeless prims and the
    # meshes under an unknown prim are not its concern.
    path = tmp_path / "proc.usda"
    path.write_text('#usda 1.0\ndef ArnoldUsd "Proc"\n{\n    string arnold:filename = "other.usd"\n'
                    '    def Cube "Inside"\n    {\n    }\n}\ndef "Group"\n{\n    def Cube "C"\n    {\n    }\n}\n')
    scene = load_scene(path)
    assert sorted(i.name for i in scene.instances) == ["/Group/C", "/Proc/Inside"]
    unknown = [w for w in scene.warnings if "no schema defines" in w]
    assert len(unknown) == 1 and "/Proc (ArnoldUsd)" in unknown[0] and "/Group" not in unknown[0], scene.warnings


def test_light_filters_are_named_in_a_warning(tmp_path):
    path = tmp_path / "filters.usda"
    path.write_text('#usda 1.0\ndef Cube "C"\n{\n}\ndef LightFilter "Gobo"\n{\n}\n'
                    'def SphereLight "Key"\n{\n    rel light:filters = </Gobo>\n}\n')
    scene = load_scene(path)
    assert len(scene.lights) == 1
    assert any("light filters ignored" in w and "/Gobo (LightFilter)" in w for w in scene.warnings), scene.warnings


def test_subdivision_surfaces_are_refined_without_warnings(tmp_path):
    stage, path = new_stage(tmp_path)
    for i in range(5):
        m = add_tri(stage, f"/World/Sub{i}")
        m.GetSubdivisionSchemeAttr().Set(UsdGeom.Tokens.catmullClark)
    scene = save_and_load(stage, path)
    assert len(scene.meshes) == 5
    assert all(len(m.triangles) > 1 and m.normals is not None for m in scene.meshes)
    assert not any("subdivision" in w for w in scene.warnings), scene.warnings


def test_purpose_visibility_and_proxies(tmp_path):
    stage, path = new_stage(tmp_path)
    add_tri(stage, "/World/Default")
    add_tri(stage, "/World/Guide").CreatePurposeAttr(UsdGeom.Tokens.guide)
    add_tri(stage, "/World/Proxy").CreatePurposeAttr(UsdGeom.Tokens.proxy)
    hidden = UsdGeom.Xform.Define(stage, "/World/Hidden")
    hidden.CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    add_tri(stage, "/World/Hidden/Child")
    scene = save_and_load(stage, path)
    names = sorted(i.name for i in scene.instances)
    assert names == ["/World/Default", "/World/Proxy"], "no render prim: the proxy is drawn"

    add_tri(stage, "/World/Render").CreatePurposeAttr(UsdGeom.Tokens.render)
    scene = save_and_load(stage, path)
    assert sorted(i.name for i in scene.instances) == ["/World/Default", "/World/Render"]


def test_native_instances_share_one_mesh(tmp_path):
    stage, path = new_stage(tmp_path)
    proto = UsdGeom.Xform.Define(stage, "/Proto")
    proto.GetPrim().SetSpecifier(Sdf.SpecifierClass)
    add_tri(stage, "/Proto/Tri")
    for i in range(3):
        x = UsdGeom.Xform.Define(stage, f"/World/I{i}")
        x.AddTranslateOp().Set(Gf.Vec3d(10 * i, 0, 0))
        x.GetPrim().GetReferences().AddInternalReference("/Proto")
        x.GetPrim().SetInstanceable(True)
    scene = save_and_load(stage, path)
    assert len(scene.instances) == 3 and len(scene.meshes) == 1
    xs = sorted(float(world_points(scene, i)[0, 0]) for i in scene.instances)
    assert xs == [0.0, 10.0, 20.0]


def test_point_instancer(tmp_path):
    stage, path = new_stage(tmp_path)
    pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
    add_tri(stage, "/World/PI/Protos/A")
    UsdGeom.Sphere.Define(stage, "/World/PI/Protos/B").CreateRadiusAttr(0.5)
    pi.CreatePrototypesRel().SetTargets(["/World/PI/Protos/A", "/World/PI/Protos/B"])
    pi.CreatePositionsAttr([Gf.Vec3f(0, 0, 0), Gf.Vec3f(5, 0, 0), Gf.Vec3f(0, 5, 0), Gf.Vec3f(0, 0, 5)])
    pi.CreateProtoIndicesAttr([0, 0, 1, 0])
    pi.CreateScalesAttr([Gf.Vec3f(1), Gf.Vec3f(2), Gf.Vec3f(1), Gf.Vec3f(1)])
    q = Gf.Quath(math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4))  # 90 degrees about Z
    pi.CreateOrientationsAttr([Gf.Quath(1), q, Gf.Quath(1), Gf.Quath(1)])
    pi.CreateInvisibleIdsAttr([3])
    UsdGeom.Xformable(pi).AddTranslateOp().Set(Gf.Vec3d(0, 0, 100))
    scene = save_and_load(stage, path)
    assert len(scene.instances) == 3, "invisibleIds hides one; prototypes are not drawn on their own"
    assert len(scene.meshes) == 2
    inst1 = by_name(scene.instances, "PI[1]/A")
    p = world_points(scene, inst1)
    # (1, 0, 0) scaled by 2, turned 90 degrees about Z, then at (5, 0, 100)
    np.testing.assert_allclose(p[1], [5, 2, 100], atol=2e-3)
    sph = by_name(scene.instances, "PI[2]/B")
    c = world_points(scene, sph).mean(axis=0)
    np.testing.assert_allclose(c, [0, 5, 100], atol=1e-3)


# ---------------------------------------------------------------------------------------------------------------
# materials


def preview_material(stage, where, **inputs):
    mat = UsdShade.Material.Define(stage, where)
    sh = UsdShade.Shader.Define(stage, where + "/PS")
    sh.CreateIdAttr("UsdPreviewSurface")
    types = {"diffuseColor": Sdf.ValueTypeNames.Color3f, "emissiveColor": Sdf.ValueTypeNames.Color3f,
             "specularColor": Sdf.ValueTypeNames.Color3f, "useSpecularWorkflow": Sdf.ValueTypeNames.Int}
    for k, v in inputs.items():
        sh.CreateInput(k, types.get(k, Sdf.ValueTypeNames.Float)).Set(v)
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    return mat, sh


def bind(prim, mat):
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim() if hasattr(prim, "GetPrim") else prim).Bind(mat)


def test_materials_preview_surface_subsets_fallbacks_and_dedupe(tmp_path):
    stage, path = new_stage(tmp_path)
    red, _ = preview_material(stage, "/Looks/Red", diffuseColor=Gf.Vec3f(0.8, 0.1, 0.1), roughness=0.3,
                              metallic=1.0, ior=1.33, opacity=0.5)
    glow, _ = preview_material(stage, "/Looks/Glow", emissiveColor=Gf.Vec3f(4, 3, 2))
    # a texture-driven diffuse falls back to the input's own value
    tex_mat, tex_ps = preview_material(stage, "/Looks/Tex")
    tex = UsdShade.Shader.Define(stage, "/Looks/Tex/Img")
    tex.CreateIdAttr("UsdUVTexture")
    out = tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    tex_ps.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.2, 0.4, 0.6))
    tex_ps.GetInput("diffuseColor").ConnectToSource(out)
    # an interface input on the material drives roughness
    iface = tex_mat.CreateInput("rough", Sdf.ValueTypeNames.Float)
    iface.Set(0.9)
    tex_ps.CreateInput("roughness", Sdf.ValueTypeNames.Float).ConnectToSource(iface)
    # a RenderMan-only material
    pxr_mat = UsdShade.Material.Define(stage, "/Looks/Pxr")
    pxr_sh = UsdShade.Shader.Define(stage, "/Looks/Pxr/S")
    pxr_sh.CreateIdAttr("PxrSurface")
    pxr_mat.CreateSurfaceOutput("ri").ConnectToSource(pxr_sh.ConnectableAPI(), "out")

    two = add_mesh(stage, "/World/Two", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0)],
                   [4, 4], [0, 1, 2, 3, 1, 4, 5, 2])
    bind(two, red)
    sub = UsdShade.MaterialBindingAPI(two.GetPrim()).CreateMaterialBindSubset("glowing", Vt.IntArray([1]))
    bind(sub, glow)
    for i in range(2):
        m = add_tri(stage, f"/World/Red{i}")
        bind(m, red)
    bind(add_tri(stage, "/World/Tex"), tex_mat)
    for i in range(3):
        m = add_tri(stage, f"/World/Pxr{i}")
        m.CreateDisplayColorAttr([Gf.Vec3f(0.0, 0.5, 1.0)])
        bind(m, pxr_mat)
    add_tri(stage, "/World/Plain").CreateDisplayColorAttr([Gf.Vec3f(1, 0, 0), Gf.Vec3f(0, 0, 1)])
    add_tri(stage, "/World/Grey")
    scene = save_and_load(stage, path)

    mats = scene.materials
    two_m = by_name(scene.meshes, "Two")
    np.testing.assert_array_equal(two_m.material_ids[:2], [two_m.material_ids[0]] * 2)
    r, g = mats[two_m.material_ids[0]], mats[two_m.material_ids[2]]
    assert r.diffuse_color == pytest.approx((0.8, 0.1, 0.1)) and r.roughness == pytest.approx(0.3)
    assert r.metallic == 1.0 and r.ior == pytest.approx(1.33) and r.opacity == 0.5
    assert g.emissive_color == (4.0, 3.0, 2.0)
    assert {mats[by_name(scene.meshes, f"Red{i}").material_ids[0]].name for i in range(2)} == {"/Looks/Red"}
    assert sum(m.name == "/Looks/Red" for m in mats) == 1, "deduplicated"
    t = mats[by_name(scene.meshes, "/Tex").material_ids[0]]
    assert t.diffuse_color == pytest.approx((0.2, 0.4, 0.6)) and t.roughness == pytest.approx(0.9)
    p = mats[by_name(scene.meshes, "Pxr0").material_ids[0]]
    assert p.diffuse_color == (0.0, 0.5, 1.0)
    assert sum("PxrSurface" in w for w in scene.warnings) == 1
    assert any("texture" in w and "/Looks/Tex" in w for w in scene.warnings)
    assert mats[by_name(scene.meshes, "Plain").material_ids[0]].diffuse_color == (0.5, 0.0, 0.5)
    assert mats[by_name(scene.meshes, "Grey").material_ids[0]].diffuse_color == (0.18, 0.18, 0.18)
    # the emissive subset makes the mesh a light, so no default light is added
    mesh_lights = [l for l in scene.lights if l.kind == sc.LIGHT_MESH]
    assert len(mesh_lights) == 1 and mesh_lights[0].radiance == (4.0, 3.0, 2.0)
    assert scene.instances[mesh_lights[0].instance].name == "/World/Two"
    assert not any("no lights" in w for w in scene.warnings)


# ---------------------------------------------------------------------------------------------------------------
# camera, render settings, stage metrics


def test_camera_units_and_stage_metrics(tmp_path):
    stage, path = new_stage(tmp_path, mpu=0.01, up="Z", tcps=30.0, start=12, end=20)
    add_tri(stage)
    cam = add_camera(stage, shutter=(-0.25, 0.25))
    cam.CreateFocalLengthAttr(50.0)
    cam.CreateHorizontalApertureAttr(36.0)
    cam.CreateVerticalApertureAttr(24.0)
    cam.CreateHorizontalApertureOffsetAttr(2.0)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.5, 5000))
    cam.CreateFStopAttr(2.8)
    cam.CreateFocusDistanceAttr(250.0)
    cam.GetExposureAttr().Set(1.5)
    UsdGeom.Xformable(cam).AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
    scene = save_and_load(stage, path)
    c = scene.camera
    assert c.name == "/World/Cam"
    assert c.focal_length == pytest.approx(5.0), "focalLength 50 (tenths of a cm) is 5 cm"
    assert (c.horizontal_aperture, c.vertical_aperture) == pytest.approx((3.6, 2.4))
    assert c.horizontal_aperture_offset == pytest.approx(0.2)
    assert c.clipping_range == pytest.approx((0.5, 5000))
    assert (c.f_stop, c.focus_distance, c.exposure) == pytest.approx((2.8, 250.0, 1.5))
    np.testing.assert_allclose(matrix_at(c.transform, 0.5)[:3, 3], [1, 2, 3])
    assert scene.frame == 12.0, "frame defaults to startTimeCode"
    assert (scene.shutter.open, scene.shutter.close) == (11.75, 12.25)
    assert (scene.meters_per_unit, scene.up_axis, scene.time_codes_per_second) == (0.01, "Z", 30.0)

    scene = load_scene(path, frame=3, shutter=(0.0, 0.5))
    assert (scene.frame, scene.shutter.open, scene.shutter.close) == (3.0, 3.0, 3.5)
    scene = load_scene(path, frame=3, motion_blur=False)
    assert scene.shutter.open == scene.shutter.close == 3.0


def test_orthographic_camera(tmp_path):
    stage, path = new_stage(tmp_path)
    add_tri(stage)
    cam = add_camera(stage)
    cam.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
    cam.CreateHorizontalApertureAttr(200.0)
    scene = save_and_load(stage, path)
    assert scene.camera.projection == "orthographic" and scene.camera.horizontal_aperture == pytest.approx(20.0)


def test_render_settings_pick_camera_resolution_and_disable_blur(tmp_path):
    stage, path = new_stage(tmp_path)
    add_tri(stage)
    add_camera(stage, "/World/First", shutter=(0, 1))
    add_camera(stage, "/World/Second", shutter=(0, 1))
    rs = UsdRender.Settings.Define(stage, "/Render/Settings")
    rs.CreateResolutionAttr(Gf.Vec2i(640, 360))
    rs.CreateCameraRel().SetTargets(["/World/Second"])
    rs.CreatePixelAspectRatioAttr(2.0)
    rs.CreateDisableMotionBlurAttr(True)
    rs.CreateDisableDepthOfFieldAttr(True)
    scene = save_and_load(stage, path)
    info = scene.render_settings
    assert info.resolution == (640, 360) and info.camera_path == "/World/Second"
    assert info.pixel_aspect_ratio == 2.0 and info.disable_motion_blur and info.disable_depth_of_field
    assert scene.camera.name == "/World/Second"
    assert scene.shutter.open == scene.shutter.close == scene.frame
    # an explicit camera wins over the settings
    assert load_scene(path, camera="/World/First").camera.name == "/World/First"


def test_a_camera_placed_only_by_arnold_look_at_primvars(tmp_path):
    # 3ds Max exports leave the camera's USD transform empty and place it with Arnold's position / look_at / up;
    # a camera that USD places keeps its own transform whatever those say.
    stage, path = new_stage(tmp_path, up="Z")
    add_tri(stage)
    for name, own in (("Max", None), ("Placed", (1.0, 2.0, 3.0))):
        cam = UsdGeom.Camera.Define(stage, f"/World/{name}")
        if own is not None:
            cam.AddTranslateOp().Set(Gf.Vec3d(*own))
        p = cam.GetPrim()
        for key, v in (("position", (-6.0, -3.0, 30.0)), ("look_at", (-6.0, -3.0, 7.0)), ("up", (0.0, 1.0, 0.0))):
            p.CreateAttribute(f"primvars:arnold:{key}", Sdf.ValueTypeNames.Float3Array).Set([Gf.Vec3f(*v)])
    stage.GetRootLayer().Save()
    m = matrix_at(load_scene(path, camera="/World/Max").camera.transform, 0.0)
    np.testing.assert_allclose(m[:3, 3], [-6, -3, 30], atol=1e-5)  # eye
    np.testing.assert_allclose(-m[:3, 2], [0, 0, -1], atol=1e-6)  # looks at look_at
    np.testing.assert_allclose(m[:3, 1], [0, 1, 0], atol=1e-6)  # up
    m = matrix_at(load_scene(path, camera="/World/Placed").camera.transform, 0.0)
    np.testing.assert_allclose(m[:3, 3], [1, 2, 3], atol=1e-6)
    np.testing.assert_allclose(m[:3, :3], np.eye(3), atol=1e-6)


def test_no_camera_no_lights_defaults_follow_up_axis(tmp_path):
    stage, path = new_stage(tmp_path, up="Z")
    UsdGeom.Cube.Define(stage, "/World/Box").AddTranslateOp().Set(Gf.Vec3d(10, 20, 30))
    scene = save_and_load(stage, path)
    assert "no camera in stage: framing the scene bounds automatically" in scene.warnings
    assert any(w.startswith("no lights in stage: using the default distant light") for w in scene.warnings)
    m = matrix_at(scene.camera.transform, 0.0)
    eye, forward, up = m[:3, 3], -m[:3, 2], m[:3, 1]
    to_box = np.array([10.0, 20, 30]) - eye
    assert np.dot(forward, to_box / np.linalg.norm(to_box)) > 0.999, "looks at the bounds' centre"
    assert up[2] > 0.5 and forward[2] < 0, "Z-up stage: camera upright, looking down a little"
    assert scene.camera.clipping_range[0] < np.linalg.norm(to_box) < scene.camera.clipping_range[1]
    (light,) = scene.lights
    # radiance of a 0.53 degree disk delivering the irradiance pi (a white Lambert surface facing it: 1)
    half = math.radians(light.angle / 2)
    assert light.kind == sc.LIGHT_DISTANT and light.angle == 0.53
    assert np.multiply(light.radiance, math.pi * math.sin(half) ** 2) == pytest.approx((math.pi,) * 3)
    travel = -matrix_at(light.transform, 0.0)[:3, 2]
    assert travel[2] < 0 and np.dot(travel, forward) > 0, "from above, behind the camera"


# ---------------------------------------------------------------------------------------------------------------
# lights


def test_light_radiance_exposure_normalize_temperature(tmp_path):
    stage, path = new_stage(tmp_path)
    add_tri(stage)
    rect = UsdLux.RectLight.Define(stage, "/World/Rect")
    rect.CreateIntensityAttr(2.0)
    rect.CreateExposureAttr(1.0)
    rect.CreateColorAttr(Gf.Vec3f(1, 0.5, 0.25))
    rect.CreateWidthAttr(2.0)
    rect.CreateHeightAttr(3.0)
    rect.CreateNormalizeAttr(True)
    UsdGeom.Xformable(rect).AddScaleOp().Set(Gf.Vec3f(2, 2, 1))
    warm = UsdLux.SphereLight.Define(stage, "/World/Warm")
    warm.CreateEnableColorTemperatureAttr(True)
    warm.CreateColorTemperatureAttr(3000.0)
    warm.CreateTreatAsPointAttr(True)
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(3.0)
    sun.CreateAngleAttr(1.0)
    UsdLux.DiskLight.Define(stage, "/World/Disk").CreateRadiusAttr(0.25)
    cyl = UsdLux.CylinderLight.Define(stage, "/World/Cyl")
    cyl.CreateLengthAttr(4.0)
    cyl.CreateTreatAsLineAttr(True)
    UsdLux.DomeLight.Define(stage, "/World/Dome").CreateColorAttr(Gf.Vec3f(0.1, 0.2, 0.3))
    legacy = stage.DefinePrim("/World/Legacy", "SphereLight")  # pre-"inputs:" attribute names
    legacy.CreateAttribute("intensity", Sdf.ValueTypeNames.Float).Set(7.0)
    legacy.CreateAttribute("radius", Sdf.ValueTypeNames.Float).Set(0.1)
    scene = save_and_load(stage, path)

    r = by_name(scene.lights, "Rect")
    assert r.kind == sc.LIGHT_RECT and (r.width, r.height) == (2.0, 3.0)
    area = 2 * 3 * 2 * 2  # width * height * scale_x * scale_y
    assert r.radiance == pytest.approx(tuple(2 * 2 * c / area for c in (1, 0.5, 0.25)))
    w = by_name(scene.lights, "Warm")
    assert w.radius == 0.0
    # treatAsPoint: the intensity (cd) of the default radius-0.5 sphere seen from afar, L pi r^2
    assert w.radiance == pytest.approx(tuple(c * math.pi * 0.25 for c in UsdLux.BlackbodyTemperatureAsRgb(3000.0)),
                                       rel=1e-5)
    assert w.radiance[0] > w.radiance[2]
    s = by_name(scene.lights, "Sun")
    assert s.kind == sc.LIGHT_DISTANT and s.radiance == (3.0, 3.0, 3.0) and s.angle == 1.0
    assert by_name(scene.lights, "Disk").radius == 0.25
    c = by_name(scene.lights, "Cyl")
    assert c.kind == sc.LIGHT_CYLINDER and c.length == 4.0 and c.radius == 0.5  # treatAsLine: a hint, disregarded
    d = by_name(scene.lights, "Dome")
    assert d.kind == sc.LIGHT_DOME and d.radiance == pytest.approx((0.1, 0.2, 0.3))
    g = by_name(scene.lights, "Legacy")
    assert g.radiance == (7.0, 7.0, 7.0) and g.radius == pytest.approx(0.1)
    assert not any("no lights" in w for w in scene.warnings)


# ---------------------------------------------------------------------------------------------------------------
# motion


def test_translate_that_stops_halfway(tmp_path):
    stage, path = new_stage(tmp_path)
    add_camera(stage, shutter=(0.0, 1.0))
    ball = UsdGeom.Xform.Define(stage, "/World/Ball")
    op = ball.AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 0.0)
    op.Set(Gf.Vec3d(4, 0, 0), 0.5)
    op.Set(Gf.Vec3d(4, 0, 0), 1.0)
    add_tri(stage, "/World/Ball/Tri")
    scene = save_and_load(stage, path, frame=0)
    xf = scene.instances[0].transform
    np.testing.assert_allclose(xf.times, [0, 0.5, 1])
    np.testing.assert_allclose(matrix_at(xf, 0.75), matrix_at(xf, 1.0), atol=1e-6)
    np.testing.assert_allclose(matrix_at(xf, 0.25)[:3, 3], [2, 0, 0], atol=1e-6)
    # a parent's samples count too, and the shutter may straddle the frame
    scene = load_scene(path, frame=0.5, shutter=(-0.25, 0.25))
    xf = scene.instances[0].transform
    np.testing.assert_allclose(xf.times, [0, 0.5, 1])
    np.testing.assert_allclose(matrix_at(xf, 0.0)[:3, 3], [2, 0, 0], atol=1e-6)
    np.testing.assert_allclose(matrix_at(xf, 1.0)[:3, 3], [4, 0, 0], atol=1e-6)


def test_rotation_gets_curved_keys_and_static_when_blur_off(tmp_path):
    stage, path = new_stage(tmp_path)
    add_camera(stage, shutter=(0.0, 1.0))
    spin = UsdGeom.Xform.Define(stage, "/World/Spin")
    op = spin.AddRotateYOp()
    op.Set(0.0, 0.0)
    op.Set(90.0, 1.0)
    add_tri(stage, "/World/Spin/Tri")
    scene = save_and_load(stage, path, frame=0)
    xf = scene.instances[0].transform
    assert xf.num_keys >= 10, "90 degrees in <= 10 degree segments"
    angle = lambda m: math.degrees(math.atan2(m[0, 2], m[0, 0]))  # noqa: E731
    assert angle(matrix_at(xf, 0.5)) == pytest.approx(45.0, abs=1e-3)
    assert angle(matrix_at(xf, 1.0)) == pytest.approx(90.0, abs=1e-3)
    scene = load_scene(path, frame=0, motion_blur=False)
    assert scene.instances[0].transform.num_keys == 1


def test_velocities_and_accelerations_follow_the_usd_formula(tmp_path):
    tcps = 48.0
    stage, path = new_stage(tmp_path, tcps=tcps)
    add_camera(stage, shutter=(0.0, 1.0))
    m = add_tri(stage)
    p0 = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0)], np.float32)
    v = np.array([(48, 0, 0), (0, 24, 0), (0, 0, 0)], np.float32)
    a = np.array([(0, 0, 96), (0, 0, 0), (-96, 0, 0)], np.float32)
    m.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(p0), 1.0)  # authored at tS = 1 (the frame is 1.5)
    m.CreateVelocitiesAttr().Set(Vt.Vec3fArray.FromNumpy(v), 1.0)
    m.CreateAccelerationsAttr().Set(Vt.Vec3fArray.FromNumpy(a), 1.0)
    scene = save_and_load(stage, path, frame=1.5)
    mesh = scene.meshes[0]
    assert len(mesh.point_times) >= 5, "accelerations make the path curved"
    for s, pts in zip(mesh.point_times, mesh.points):
        dt = (scene.time_code(float(s)) - 1.0) / tcps
        np.testing.assert_allclose(pts, p0 + v * dt + 0.5 * a * dt * dt, atol=1e-5)

    # velocities only: two keys, straight line
    m.GetAccelerationsAttr().Block()
    scene = save_and_load(stage, path, frame=1.5)
    mesh = scene.meshes[0]
    np.testing.assert_allclose(mesh.point_times, [0, 1])
    np.testing.assert_allclose(mesh.points[1] - mesh.points[0], v * 1.0 / tcps, atol=1e-5)


def test_point_instancer_velocities(tmp_path):
    stage, path = new_stage(tmp_path)
    add_camera(stage, shutter=(-0.5, 0.5))
    pi = UsdGeom.PointInstancer.Define(stage, "/World/PI")
    add_tri(stage, "/World/PI/Protos/A")
    pi.CreatePrototypesRel().SetTargets(["/World/PI/Protos/A"])
    pi.CreatePositionsAttr().Set([Gf.Vec3f(0, 0, 0), Gf.Vec3f(0, 3, 0)], 2.0)
    pi.CreateVelocitiesAttr().Set([Gf.Vec3f(24, 0, 0), Gf.Vec3f(0, 0, -48)], 2.0)
    pi.CreateProtoIndicesAttr([0, 0])
    scene = save_and_load(stage, path, frame=2.0)
    a, b = by_name(scene.instances, "PI[0]/A"), by_name(scene.instances, "PI[1]/A")
    np.testing.assert_allclose(matrix_at(a.transform, 0.0)[:3, 3], [-0.5, 0, 0], atol=1e-6)
    np.testing.assert_allclose(matrix_at(a.transform, 1.0)[:3, 3], [0.5, 0, 0], atol=1e-6)
    np.testing.assert_allclose(matrix_at(b.transform, 1.0)[:3, 3], [0, 3, -1], atol=1e-6)
    assert len(scene.meshes) == 1


def test_deforming_points_keys(tmp_path):
    stage, path = new_stage(tmp_path)
    add_camera(stage, shutter=(0.0, 1.0))
    m = add_tri(stage)
    base = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0)], np.float32)
    for t, dz in ((0.0, 0.0), (0.5, 1.0), (1.0, 1.0)):
        m.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(base + [0, 0, dz]), t)
    scene = save_and_load(stage, path, frame=0)
    mesh = scene.meshes[0]
    np.testing.assert_allclose(mesh.point_times, [0, 0.5, 1])
    np.testing.assert_allclose(mesh.points[:, 0, 2], [0, 1, 1])
    assert mesh.deforming and mesh.points.dtype == np.float32


def test_time_sampled_visibility_interval(tmp_path):
    stage, path = new_stage(tmp_path)
    add_camera(stage, shutter=(0.0, 1.0))
    gone = add_tri(stage, "/World/Gone")
    gone.CreateVisibilityAttr().Set(UsdGeom.Tokens.inherited, 0.0)
    gone.GetVisibilityAttr().Set(UsdGeom.Tokens.invisible, 0.5)
    grp = UsdGeom.Xform.Define(stage, "/World/Late")  # inherited from a parent
    grp.CreateVisibilityAttr().Set(UsdGeom.Tokens.invisible, 0.0)
    grp.GetVisibilityAttr().Set(UsdGeom.Tokens.inherited, 0.25)
    add_tri(stage, "/World/Late/Tri")
    blink = add_tri(stage, "/World/Blink")
    for t, v in ((0.0, "inherited"), (0.25, "invisible"), (0.5, "inherited"), (0.75, "invisible")):
        blink.CreateVisibilityAttr().Set(v, t)
    never = add_tri(stage, "/World/Never")
    never.CreateVisibilityAttr().Set(UsdGeom.Tokens.invisible, 0.0)
    never.GetVisibilityAttr().Set(UsdGeom.Tokens.invisible, 1.0)
    scene = save_and_load(stage, path, frame=0)
    assert (by_name(scene.instances, "Gone").visible_from, by_name(scene.instances, "Gone").visible_to) == (0, 0.5)
    late = by_name(scene.instances, "Late/Tri")
    assert (late.visible_from, late.visible_to) == (0.25, 1.0)
    b = by_name(scene.instances, "Blink")
    assert (b.visible_from, b.visible_to) == (0.0, 0.75)
    assert any("visibility toggles" in w for w in scene.warnings)
    assert not any(i.name.endswith("Never") for i in scene.instances)


def test_batched_transforms_match_make_transform():
    rng = np.random.default_rng(7)
    times = np.array([0.0, 0.3, 1.0])
    rows = []
    for _ in range(20):
        keys = []
        for _ in times:
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            m = np.eye(4)
            m[:3, :3] = quat_to_matrix(q) @ np.diag(rng.uniform(0.5, 2, 3)) * rng.choice([-1, 1])
            m[:3, 3] = rng.normal(size=3)
            keys.append(m)
        rows.append(np.array(keys).transpose(0, 2, 1))
    rows = np.array(rows)
    for got, r in zip(motion_transforms(times, rows), rows):
        want = make_transform(times, r.transpose(0, 2, 1))
        for s in (0.0, 0.2, 0.65, 1.0):
            np.testing.assert_allclose(matrix_at(got, s), matrix_at(want, s), atol=1e-5)


# ---------------------------------------------------------------------------------------------------------------
# errors


def test_missing_file(tmp_path):
    with pytest.raises(SceneError) as e:
        load_scene(tmp_path / "nope.usda")
    assert str(e.value) == f"scene file not found: {tmp_path / 'nope.usda'}"


def test_malformed_usda_names_the_line(tmp_path):
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\n(\n    upAxis = "Y"\n)\n\ndef Xform "World"\n{\n'
                   '    def Mesh "m"\n    {\n        int[] faceVertexCounts = [3,\n        oops here\n    }\n}\n')
    with pytest.raises(SceneError) as e:
        load_scene(bad)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("malformed USD in bad.usda") and "line 11" in msg, msg
    junk = tmp_path / "junk.usdc"
    junk.write_bytes(b"PXR-USDC" + bytes(20))
    with pytest.raises(SceneError) as e:
        load_scene(junk)
    assert "\n" not in str(e.value) and "junk.usdc" in str(e.value)


def test_bad_camera_paths(tmp_path):
    stage, path = new_stage(tmp_path)
    add_tri(stage)
    stage.GetRootLayer().Save()
    with pytest.raises(SceneError) as e:
        load_scene(path, camera="/World/Cam")
    assert str(e.value) == "camera prim not found: /World/Cam"
    with pytest.raises(SceneError) as e:
        load_scene(path, camera="/World/Tri")
    assert "not a Camera" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(SceneError):
        load_scene(path, camera="not a path")


# ---------------------------------------------------------------------------------------------------------------
# every shipped asset


def _asset_roots():
    manifest = json.loads((ASSETS / "MANIFEST.json").read_text())
    out = []
    for name, entry in manifest.items():
        for root in entry["roots"]:
            m = entry["measured"][root]
            expect_geometry = (m["tris_rendered"] or 0) + (m["implicit_rendered"] or 0) > 0
            out.append(pytest.param(ASSETS / name / root, expect_geometry, id=f"{name}/{root}"))
    return out


@pytest.mark.skipif(not (ASSETS / "MANIFEST.json").exists(), reason="shared assets not present")
@pytest.mark.parametrize("path, expect_geometry", _asset_roots() if (ASSETS / "MANIFEST.json").exists() else [])
def test_shipped_assets_load(path, expect_geometry):
    scene = load_scene(path)
    print(f"\n{path.relative_to(ASSETS)}: {len(scene.instances)} instances, {len(scene.meshes)} meshes")
    for w in scene.warnings:
        print("  warning:", w)
    tris = sum(len(scene.meshes[i.mesh].triangles) for i in scene.instances)
    if expect_geometry:
        assert tris >= 1
    for m in scene.meshes:
        for arr in (m.points, m.normals, m.uvs, m.point_times):
            if arr is not None:
                assert np.all(np.isfinite(arr)) and arr.dtype == np.float32 and arr.flags.c_contiguous
        assert m.triangles.dtype == np.int32 and m.material_ids.dtype == np.int32
        assert m.triangles.min() >= 0 and m.triangles.max() < m.points.shape[1]
        assert m.material_ids.max() < len(scene.materials)
    for xf in [i.transform for i in scene.instances] + [l.transform for l in scene.lights] + [scene.camera.transform]:
        assert np.all(np.isfinite(xf.translation)) and np.all(np.isfinite(xf.scale))
        assert xf.times[0] >= 0 and xf.times[-1] <= 1 and np.all(np.diff(xf.times) > 0)
    assert scene.lights and scene.camera.focal_length > 0


@pytest.mark.skipif(not HEAVY.exists(), reason="bench scene not present")
def test_heavy_scene_loads_fast():
    t0 = time.perf_counter()
    scene = load_scene(HEAVY)
    took = time.perf_counter() - t0
    tris = sum(len(scene.meshes[i.mesh].triangles) for i in scene.instances)
    print(f"\nheavy.usda: {tris} triangles in {took:.2f} s")
    assert tris >= 1_000_000
    assert took < 10.0
