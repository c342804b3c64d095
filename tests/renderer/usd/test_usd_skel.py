"""UsdSkel (renderer/usd/geometry/skel.py): skinned meshes and blend shapes match UsdSkel's own baked points at every
key inside the shutter, rigidly skinned primitives follow their joint, skinned motion blurs, and skinned meshes
inside native instances (crowd agents) are skinned by the Skeleton above each instance."""
from __future__ import annotations

import shutil

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdShade, UsdSkel, Vt

import stages
from renderer.motion.transform import matrix_at
from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, prepare, render_frame
from renderer.usd.importer import load_scene


def bar_points(n=4, length=2.0, half=0.1):
    """A bar along +x from the origin: n segments, 2 (n + 1) points in the z = 0 plane."""
    xs = np.linspace(0, length, n + 1)
    pts = [(x, y, 0.0) for x in xs for y in (-half, half)]
    idx = []
    for i in range(n):
        a = 2 * i
        idx += [a, a + 2, a + 3, a + 1]
    return pts, [4] * n, idx


def skel_stage(path, *, angles={0.0: 0.0, 1.0: 90.0}, blend=False, root_offset=(0.0, 0.0, 0.0), axis=(0, 0, 1),
               joints=None, normals=False):
    """A SkelRoot at /World/Char with a two-joint skeleton (root at the origin, 'root/tip' 1 unit along x), an
    animation that turns the tip joint about ``axis`` through ``angles`` {time: degrees}, and a bar mesh skinned to
    both joints (weights blending along x); with ``blend``, a blend shape lifting the bar's end, its weight animated
    0 -> 1; ``joints``: the mesh's own skel:joints (its joint indices refer to that order); ``normals``: authored
    vertex normals +z."""
    stage = stages.new_stage(path)
    skel_character(stage, "/World/Char", angles=angles, blend=blend, root_offset=root_offset, axis=axis,
                   joints=joints, normals=normals)
    return stage


def skel_character(stage, root_path, *, angles={0.0: 0.0, 1.0: 90.0}, blend=False, root_offset=(0.0, 0.0, 0.0),
                   axis=(0, 0, 1), joints=None, normals=False):
    """The character of ``skel_stage`` under ``root_path`` (the SkelRoot; children Skel, Anim, Bar)."""
    root = UsdSkel.Root.Define(stage, root_path)
    UsdGeom.Xformable(root).AddTranslateOp().Set(Gf.Vec3d(*root_offset))
    skel = UsdSkel.Skeleton.Define(stage, f"{root_path}/Skel")
    skel.CreateJointsAttr(["root", "root/tip"])
    rest = [Gf.Matrix4d(1), Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(1, 0, 0))]
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1), Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(1, 0, 0))]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray(rest))
    anim = UsdSkel.Animation.Define(stage, f"{root_path}/Anim")
    anim.CreateJointsAttr(["root", "root/tip"])
    anim.CreateTranslationsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0), Gf.Vec3f(1, 0, 0)]))
    anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1), Gf.Vec3h(1, 1, 1)]))
    rot = anim.CreateRotationsAttr()
    for t, deg in angles.items():
        q = Gf.Rotation(Gf.Vec3d(*axis), deg).GetQuat()
        rot.Set(Vt.QuatfArray([Gf.Quatf(1, 0, 0, 0), Gf.Quatf(q)]), t)
    binding = UsdSkel.BindingAPI.Apply(root.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    pts, counts, idx = bar_points()
    mesh = UsdGeom.Mesh.Define(stage, f"{root_path}/Bar")
    mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]))
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(idx)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if normals:
        mesh.CreateNormalsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 1)] * len(pts)))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mb = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    order = list(joints or ["root", "root/tip"])
    if joints is not None:
        mb.CreateJointsAttr(order)
    j_root, j_tip = order.index("root"), order.index("root/tip")
    w = np.clip(np.array([p[0] for p in pts]) - 0.5, 0.0, 1.0)  # 0 -> root joint, 1 -> tip joint
    mb.CreateJointIndicesPrimvar(False, 2).Set(Vt.IntArray([j for _ in pts for j in (j_root, j_tip)]))
    mb.CreateJointWeightsPrimvar(False, 2).Set(Vt.FloatArray([float(x) for wi in w for x in (1 - wi, wi)]))
    mb.CreateGeomBindTransformAttr(Gf.Matrix4d(1))
    if blend:
        shape = UsdSkel.BlendShape.Define(stage, f"{root_path}/Bar/Lift")
        shape.CreateOffsetsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0.5)] * 2))
        shape.CreatePointIndicesAttr(Vt.IntArray([len(pts) - 2, len(pts) - 1]))
        mb.CreateBlendShapesAttr(["lift"])
        mb.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
        anim.CreateBlendShapesAttr(["lift"])
        bw = anim.CreateBlendShapeWeightsAttr()
        bw.Set(Vt.FloatArray([0.0]), 0.0)
        bw.Set(Vt.FloatArray([1.0]), 1.0)
    return root


def baked_world_points(path, tmp_path, times):
    """UsdSkel.BakeSkinning on a copy of the stage: world points of the bar at each time."""
    copy = tmp_path / "baked.usda"
    shutil.copy(path, copy)
    stage = Usd.Stage.Open(str(copy))
    assert UsdSkel.BakeSkinning(stage.Traverse())
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Char/Bar"))
    out = []
    for t in times:
        p = np.asarray(mesh.GetPointsAttr().Get(t), np.float64)
        m = np.asarray(mesh.ComputeLocalToWorldTransform(t), np.float64)
        out.append(p @ m[:3, :3] + m[3, :3])
    return np.stack(out)


@pytest.mark.parametrize("blend", [False, True])
def test_skinned_mesh_matches_usdskel_baked_points_inside_the_shutter(tmp_path, blend):
    path = tmp_path / "skel.usda"
    # animation samples every quarter: UsdSkel.BakeSkinning bakes points at the animation's samples (linear in
    # between), and our keys (the shutter's quarters) fall on them
    angles = {t: 90.0 * t for t in (0.0, 0.25, 0.5, 0.75, 1.0)}
    stage = skel_stage(path, angles=angles, blend=blend, root_offset=(0.5, -1.0, 2.0))
    stages.camera(stage, shutter=(0.0, 1.0), translate=(1, 0, 10))
    stage.Save()
    scene = load_scene(path, 0.0)
    bar = [m for m in scene.meshes if m.name.endswith("Bar")]
    assert len(bar) == 1 and bar[0].deforming
    mesh = bar[0]
    inst = [i for i in scene.instances if i.name.endswith("Bar")][0]
    s = mesh.point_times.astype(np.float64)
    assert len(s) >= 5, "curved keys inside the shutter"
    baked = baked_world_points(path, tmp_path, s)  # shutter [0, 1]: s is the time code
    for k, sk in enumerate(s):
        m = matrix_at(inst.transform, float(sk))
        ours = mesh.points[k].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        np.testing.assert_allclose(ours, baked[k], atol=1e-5)
    tip0, tip1 = mesh.points[0][-1], mesh.points[-1][-1]
    assert np.linalg.norm(tip1 - tip0) > 1.0, "the tip swings during the shutter"
    if blend:
        assert mesh.points[-1][-1][2] == pytest.approx(0.5, abs=1e-5) and mesh.points[0][-1][2] == 0.0


def test_static_frame_and_no_blur_give_one_key(tmp_path):
    path = tmp_path / "skel.usda"
    stage = skel_stage(path, angles={0.0: 0.0, 0.5: 45.0, 1.0: 90.0})
    stages.camera(stage, shutter=(0.0, 1.0), translate=(1, 0, 10))
    stage.Save()
    scene = load_scene(path, 0.5, motion_blur=False)
    bar = [m for m in scene.meshes if m.name.endswith("Bar")][0]
    assert not bar.deforming
    baked = baked_world_points(path, tmp_path, [0.5])[0]
    inst = [i for i in scene.instances if i.name.endswith("Bar")][0]
    m = matrix_at(inst.transform, 0.0)
    np.testing.assert_allclose(bar.points[0] @ m[:3, :3].T + m[:3, 3], baked, atol=1e-5)


def test_authored_normals_follow_the_skinning(tmp_path):
    """The tip joint turns the bar's end by 90 degrees about x: authored normals (+z) are carried with it and
    agree with the skinned faces' geometric normals where the bar is rigid, and stay +z at the root."""
    path = tmp_path / "normals.usda"
    stage = skel_stage(path, angles={0.0: 0.0, 1.0: 90.0}, axis=(1, 0, 0))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Char/Bar"))
    mesh.CreateNormalsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 1)] * 10))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    stage.Save()
    scene = load_scene(path, 1.0, motion_blur=False)
    bar = [m for m in scene.meshes if m.name.endswith("Bar")][0]
    p = bar.points[0][bar.triangles].astype(np.float64)
    geo = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    geo /= np.linalg.norm(geo, axis=1, keepdims=True)
    x = p.mean(1)[:, 0]
    tip, root = x > 1.5, x < 0.5  # weights 1 on the tip joint / the root joint
    np.testing.assert_allclose(bar.normals[tip], np.repeat(geo[tip][:, None], 3, axis=1), atol=1e-5)
    np.testing.assert_allclose(bar.normals[tip][0, 0], (0, -1, 0), atol=1e-5)
    np.testing.assert_allclose(bar.normals[root], np.tile((0, 0, 1), (root.sum(), 3, 1)), atol=1e-6)
    assert np.allclose(np.linalg.norm(bar.normals, axis=2), 1.0, atol=1e-5)


def test_rigidly_skinned_primitive_follows_its_joint(tmp_path):
    """A Sphere bound to the tip joint alone (constant interpolation) is moved by the skinned transform."""
    path = tmp_path / "rigid.usda"
    stage = skel_stage(path, angles={0.0: 0.0, 1.0: 90.0})
    ball = UsdGeom.Sphere.Define(stage, "/World/Char/Ball")
    ball.CreateRadiusAttr(0.1)
    UsdGeom.Xformable(ball).AddTranslateOp().Set(Gf.Vec3d(2, 0, 0))
    b = UsdSkel.BindingAPI.Apply(ball.GetPrim())
    b.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([1]))
    b.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
    b.CreateGeomBindTransformAttr(Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(2, 0, 0)))
    stages.camera(stage, shutter=(0.0, 1.0), translate=(1, 0, 10))
    stage.Save()
    scene = load_scene(path, 0.0)
    inst = [i for i in scene.instances if i.name.endswith("Ball")][0]
    c0, c1 = matrix_at(inst.transform, 0.0)[:3, 3], matrix_at(inst.transform, 1.0)[:3, 3]
    np.testing.assert_allclose(c0, (2, 0, 0), atol=1e-6)
    np.testing.assert_allclose(c1, (1, 1, 0), atol=1e-6), "turned 90 degrees about the tip joint at x = 1"


def test_skinned_motion_blur_renders_a_streak(tmp_path):
    """Orthographic view down -z of the bar whose outer half swings by 90 degrees during the shutter: blurred,
    the swept area is covered partially (a streak much wider than the bar), while the total coverage stays the
    bar's area; with motion blur off the bar is sharp."""
    path = tmp_path / "streak.usda"
    stage = skel_stage(path, angles={0.0: -45.0, 1.0: 45.0})
    stages.camera(stage, ortho=True, h_ap_mm=60.0, v_ap_mm=60.0, translate=(1, 0, 5), shutter=(0.0, 1.0),
                  tenths_per_mm=1.0)
    emit = stages.material(stage, "E", emissive=(1, 1, 1))
    UsdShade.MaterialBindingAPI.Apply(stage.GetPrimAtPath("/World/Char/Bar")).Bind(emit)
    stage.Save()

    def alpha(blur):
        scene = load_scene(path, 0.0, motion_blur=blur)
        prep = prepare(scene, RenderOptions(width=64, height=64, spp=64, filter="box"))
        return frame_channels(prep, render_frame(prep, tile_size=32, threads=2).sums)["A"]

    px = (6.0 / 64) ** 2
    blurred, sharp = alpha(True), alpha(False)
    assert blurred.sum() * px == pytest.approx(sharp.sum() * px, rel=0.08), "coverage is conserved"
    partial_blur = np.count_nonzero((blurred > 0.02) & (blurred < 0.6))
    partial_sharp = np.count_nonzero((sharp > 0.02) & (sharp < 0.6))
    assert partial_blur > 3 * max(partial_sharp, 1)
    assert np.count_nonzero(blurred > 0.02) > 2 * np.count_nonzero(sharp > 0.02)


def bar_pose(angle_deg):
    """Points of the bar skinned with its tip joint turned by ``angle_deg`` about +x (linear blend skinning: the
    root joint stays, the tip joint turns about the x axis, which runs through it)."""
    p = np.array(bar_points()[0], np.float64)
    w = np.clip(p[:, 0] - 0.5, 0.0, 1.0)
    a = np.radians(angle_deg)
    return np.stack([p[:, 0], p[:, 1] * ((1 - w) + w * np.cos(a)), w * p[:, 1] * np.sin(a)], axis=1)


def world_points(scene, name, k=0, s=None):
    """World points of key k of the instance named ``name`` (its transform at normalised time s, default the key's)."""
    inst = [i for i in scene.instances if i.name == name]
    assert len(inst) == 1, f"{name} is in the scene once"
    mesh = scene.meshes[inst[0].mesh]
    s = float(mesh.point_times[k]) if mesh.deforming else (0.0 if s is None else s)
    m = matrix_at(inst[0].transform, s)
    return mesh, mesh.points[k].astype(np.float64) @ m[:3, :3].T + m[:3, 3]


def tip_normals(mesh):
    """Authored normals at the corners of the triangles skinned to the tip joint alone (x > 1.5)."""
    x = mesh.points[0][mesh.triangles].mean(1)[:, 0]
    return mesh.normals[x > 1.5].reshape(-1, 3)


JOINT_ORDERS = {"skeleton order": ["root", "root/tip"], "reordered": ["root/tip", "root"]}


@pytest.mark.parametrize("order", JOINT_ORDERS.values(), ids=JOINT_ORDERS.keys())
def test_own_joint_order_with_authored_normals(tmp_path, order):
    """A mesh authoring its own skel:joints (Maya USD and Houdini crowds write it, often in the skeleton's order)
    and normals is skinned like UsdSkel bakes it, its normals carried along, without a warning about skinning."""
    path = tmp_path / "joints.usda"
    angles = {t: 90.0 * t for t in (0.0, 0.25, 0.5, 0.75, 1.0)}
    stage = skel_stage(path, angles=angles, axis=(1, 0, 0), joints=order, normals=True, root_offset=(0.5, -1, 2))
    stages.camera(stage, shutter=(0.0, 1.0), translate=(1, 0, 10))
    stage.Save()
    scene = load_scene(path, 0.0)
    assert not [w for w in scene.warnings if "skin" in w or "unreadable" in w], scene.warnings
    bar = [m for m in scene.meshes if m.name.endswith("Bar")]
    assert len(bar) == 1 and bar[0].deforming
    baked = baked_world_points(path, tmp_path, bar[0].point_times.astype(np.float64))
    for k in range(len(bar[0].point_times)):
        np.testing.assert_allclose(world_points(scene, "/World/Char/Bar", k)[1], baked[k], atol=1e-5)
    still = load_scene(path, 1.0, motion_blur=False)
    mesh, pts = world_points(still, "/World/Char/Bar")
    np.testing.assert_allclose(pts, bar_pose(90.0) + (0.5, -1, 2), atol=1e-5)
    np.testing.assert_allclose(tip_normals(mesh), np.tile((0, -1, 0), (len(tip_normals(mesh)), 1)), atol=1e-5)


def test_instanceable_skel_roots_with_collection_bound_material(tmp_path):
    """Crowd members referencing one instanceable SkelRoot (its mesh with its own, reordered skel:joints and
    normals), a material bound through a collection on an ancestor: each member is skinned, placed and shaded."""
    path = tmp_path / "crowd.usda"
    stage = stages.new_stage(path)
    stage.CreateClassPrim("/Lib")
    skel_character(stage, "/Lib/Char", axis=(1, 0, 0), joints=["root/tip", "root"], normals=True)
    red = stages.material(stage, "Red", diffuse=(1, 0, 0))
    offsets = [(0.0, 2.0 * i, 0.0) for i in range(3)]
    for i, off in enumerate(offsets):
        member = stage.DefinePrim(f"/World/Crowd/C{i}")
        member.GetReferences().AddInternalReference("/Lib/Char")
        member.SetInstanceable(True)
        member.GetAttribute("xformOp:translate").Set(Gf.Vec3d(*off))  # the SkelRoot's own op, referenced
    world = stage.GetPrimAtPath("/World")
    skins = Usd.CollectionAPI.Apply(world, "skins")
    skins.CreateIncludesRel().AddTarget("/World/Crowd")
    UsdShade.MaterialBindingAPI.Apply(world).Bind(skins, red, "skins")
    stage.Save()
    scene = load_scene(path, 1.0, motion_blur=False)
    red_id = [i for i, m in enumerate(scene.materials) if m.name == "/World/Looks/Red"]
    for i, off in enumerate(offsets):
        mesh, pts = world_points(scene, f"/World/Crowd/C{i}/Bar")
        np.testing.assert_allclose(pts, bar_pose(90.0) + off, atol=1e-5)
        np.testing.assert_allclose(tip_normals(mesh), np.tile((0, -1, 0), (len(tip_normals(mesh)), 1)), atol=1e-5)
        assert red_id and set(np.unique(mesh.material_ids)) == set(red_id)


def test_skinned_motion_blur_under_an_animated_parent(tmp_path):
    """A character (own skel:joints, normals) under a parent moving 3 units along z during the shutter: at every
    key, the skinned pose of that time placed where the parent is then."""
    path = tmp_path / "moving.usda"
    stage = stages.new_stage(path)
    mover = UsdGeom.Xform.Define(stage, "/World/Mover")
    op = mover.AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 0.0)
    op.Set(Gf.Vec3d(0, 0, 3), 1.0)
    skel_character(stage, "/World/Mover/Char", axis=(1, 0, 0), joints=["root", "root/tip"], normals=True)
    stages.camera(stage, shutter=(0.0, 1.0), translate=(1, 0, 10))
    stage.Save()
    scene = load_scene(path, 0.0)
    mesh, _ = world_points(scene, "/World/Mover/Char/Bar")
    assert mesh.deforming and len(mesh.point_times) >= 5
    for k, s in enumerate(mesh.point_times.astype(np.float64)):
        _, pts = world_points(scene, "/World/Mover/Char/Bar", k)
        np.testing.assert_allclose(pts, bar_pose(90.0 * s) + (0, 0, 3 * s), atol=1e-4)


@pytest.mark.parametrize("step, warning", [("normal_matrices", "authored normals of skinned meshes"),
                                           ("_blend", "blend shapes that UsdSkel could not apply")])
def test_a_failing_optional_step_degrades_with_one_warning(tmp_path, monkeypatch, step, warning):
    """Skinning the normals or applying blend shapes fails: the mesh is still skinned and drawn, one warning says
    which step was left out."""
    from renderer.usd.geometry.skel import Skinning

    def fail(*args, **kwargs):
        raise TypeError("not this time")

    monkeypatch.setattr(Skinning, step, fail)
    path = tmp_path / "degrade.usda"
    stage = skel_stage(path, axis=(1, 0, 0), joints=["root", "root/tip"], normals=True, blend=step == "_blend")
    stage.Save()
    scene = load_scene(path, 1.0, motion_blur=False)
    _, pts = world_points(scene, "/World/Char/Bar")
    np.testing.assert_allclose(pts, bar_pose(90.0), atol=1e-5)
    assert len([w for w in scene.warnings if w.startswith(warning)]) == 1, scene.warnings
    assert not [w for w in scene.warnings if "skipped" in w or "unskinned" in w], scene.warnings


# ---------------------------------------------------------------------------------------------------------------
# Skinned geometry inside native instances: a character asset (its own layer, whose root prim is a SkelRoot, as
# character assets are) referenced by instanceable prims below the SkelRoots that animate it


def bar_skinned(angle_deg, axis="x", lift=0.0, bind=np.eye(4)):
    """The bar's points in skeleton space, computed from UsdSkel's definition: the blend shape lifting the two
    end points by ``lift`` along z, the geomBindTransform ``bind`` (row-vector), then linear blend skinning with
    the tip joint (pivot (1, 0, 0)) turned by ``angle_deg`` about ``axis``."""
    p = np.array(bar_points()[0], np.float64)
    w = np.clip(p[:, 0] - 0.5, 0.0, 1.0)[:, None]  # the authored tip-joint weights
    p[-2:, 2] += lift
    p = p @ bind[:3, :3] + bind[3, :3]
    r = np.array(Gf.Matrix3d(Gf.Rotation(Gf.Vec3d(*np.eye(3)["xyz".index(axis)]), angle_deg)))  # row-vector
    j = np.array([1.0, 0.0, 0.0])
    return (1 - w) * p + w * ((p - j) @ r + j)


def agent_asset(path, *, blend=True, bind=None, skeleton=False):
    """A character asset in its own layer: defaultPrim /Agent, a SkelRoot holding the bar mesh (joint influences
    on 'root' and 'root/tip', a blend shape 'lift' raising its end by 0.5 along z) and, with ``skeleton``, the
    Skeleton /Agent/Skel and a rest-pose animation, bound on /Agent."""
    stage = Usd.Stage.CreateNew(str(path))
    root = UsdSkel.Root.Define(stage, "/Agent")
    stage.SetDefaultPrim(root.GetPrim())
    pts, counts, idx = bar_points()
    mesh = UsdGeom.Mesh.Define(stage, "/Agent/Bar")
    mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]))
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(idx)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mb = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    w = np.clip(np.array([p[0] for p in pts]) - 0.5, 0.0, 1.0)
    mb.CreateJointIndicesPrimvar(False, 2).Set(Vt.IntArray([j for _ in pts for j in (0, 1)]))
    mb.CreateJointWeightsPrimvar(False, 2).Set(Vt.FloatArray([float(x) for wi in w for x in (1 - wi, wi)]))
    mb.CreateGeomBindTransformAttr(Gf.Matrix4d(1) if bind is None else Gf.Matrix4d(*bind.ravel().tolist()))
    if blend:
        shape = UsdSkel.BlendShape.Define(stage, "/Agent/Bar/Lift")
        shape.CreateOffsetsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0.5)] * 2))
        shape.CreatePointIndicesAttr(Vt.IntArray([len(pts) - 2, len(pts) - 1]))
        mb.CreateBlendShapesAttr(["lift"])
        mb.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    if skeleton:
        skel = two_joint_skeleton(stage, "/Agent/Skel")
        anim = tip_animation(stage, "/Agent/Skel/Anim", {0.0: 0.0}, "z", {})
        binding = UsdSkel.BindingAPI.Apply(root.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
        binding.CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    stage.Save()


def two_joint_skeleton(stage, path):
    """The Skeleton of ``skel_stage``: 'root' at the origin, 'root/tip' 1 unit along x (bind = rest pose)."""
    skel = UsdSkel.Skeleton.Define(stage, path)
    skel.CreateJointsAttr(["root", "root/tip"])
    rest = Vt.Matrix4dArray([Gf.Matrix4d(1), Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(1, 0, 0))])
    skel.CreateBindTransformsAttr(rest)
    skel.CreateRestTransformsAttr(rest)
    return skel


def tip_animation(stage, path, angles, axis, lifts):
    """A SkelAnimation turning the tip joint about ``axis`` by {time: degrees}, the 'lift' weight {time: w}."""
    anim = UsdSkel.Animation.Define(stage, path)
    anim.CreateJointsAttr(["root", "root/tip"])
    anim.CreateTranslationsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0), Gf.Vec3f(1, 0, 0)]))
    anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)] * 2))
    rot = anim.CreateRotationsAttr()
    for t, deg in angles.items():
        q = Gf.Rotation(Gf.Vec3d(*np.eye(3)["xyz".index(axis)]), deg).GetQuat()
        rot.Set(Vt.QuatfArray([Gf.Quatf(1, 0, 0, 0), Gf.Quatf(q)]), t)
    if lifts:
        anim.CreateBlendShapesAttr(["lift"])
        weights = anim.CreateBlendShapeWeightsAttr()
        for t, w in lifts.items():
            weights.Set(Vt.FloatArray([w]), t)
    return anim


# agent i: (tip angle about z at times 0 and 1 in degrees, lift weight at times 0 and 1), placed at y = 3 i
AGENTS = [((0.0, 90.0), (0.0, 1.0)), ((0.0, 45.0), (0.5, 0.5))]


def crowd_stage(path):
    """Houdini's crowd layout: SkelRoots /World/Mover/Crowd/agent_i, each with its own Skeleton and SkelAnimation
    (AGENTS) bound on it, and a child 'geometry' that is an instanceable reference to the agent asset (so a nested
    SkelRoot inheriting the binding); /World/Mover moves 3 units along z from time 0 to 1."""
    agent_asset(path.parent / "agent.usda")
    stage = stages.new_stage(path)
    mover = UsdGeom.Xform.Define(stage, "/World/Mover")
    op = mover.AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 0.0)
    op.Set(Gf.Vec3d(0, 0, 3), 1.0)
    for i, (angles, lifts) in enumerate(AGENTS):
        root = UsdSkel.Root.Define(stage, f"/World/Mover/Crowd/agent_{i}")
        UsdGeom.Xformable(root).AddTranslateOp().Set(Gf.Vec3d(0, 3 * i, 0))
        skel = two_joint_skeleton(stage, f"{root.GetPath()}/skel")
        anim = tip_animation(stage, f"{root.GetPath()}/skel/anim", dict(zip((0.0, 1.0), angles)), "z",
                             dict(zip((0.0, 1.0), lifts)))
        binding = UsdSkel.BindingAPI.Apply(root.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
        binding.CreateAnimationSourceRel().SetTargets([anim.GetPath()])
        geometry = stage.DefinePrim(f"{root.GetPath()}/geometry")
        geometry.GetReferences().AddReference("./agent.usda")
        geometry.SetInstanceable(True)
    return stage


def test_skinned_meshes_inside_instances_below_skel_roots(tmp_path):
    """Each agent's instanced bar is skinned by its own animation (tip angle and blend-shape weight) and moves
    with the animated parent: at every key of the shutter [0, 1] (its ends included) the skinned pose of that time
    is where the analytic skinning puts it; the instances share no mesh and no skinning is left out."""
    path = tmp_path / "crowd.usda"
    stage = crowd_stage(path)
    stages.camera(stage, shutter=(-0.5, 0.5), translate=(1, 1.5, 20))
    stage.Save()
    scene = load_scene(path, 0.5)
    assert not [w for w in scene.warnings if "skin" in w or "skipped" in w], scene.warnings
    meshes = set()
    for i, ((a0, a1), (l0, l1)) in enumerate(AGENTS):
        name = f"/World/Mover/Crowd/agent_{i}/geometry/Bar"
        mesh, _ = world_points(scene, name)
        meshes.add(id(mesh))
        s = mesh.point_times.astype(np.float64)
        assert mesh.deforming and s[0] == 0.0 and s[-1] == 1.0, "keys at the shutter ends"
        for k, t in enumerate(s):  # the shutter [0, 1] in time codes: t = s
            expected = bar_skinned(a0 + (a1 - a0) * t, "z", 0.5 * (l0 + (l1 - l0) * t)) + (0, 3 * i, 3 * t)
            np.testing.assert_allclose(world_points(scene, name, k)[1], expected, atol=1e-4, err_msg=f"{name} t={t}")
    assert len(meshes) == len(AGENTS)


def test_instanced_skinned_agents_render_where_their_skeletons_put_them(tmp_path):
    """Looking down -z at the crowd at time 1 (no blur): each agent's tip is drawn where its own animation turned
    it, and nothing is drawn where the tip would lie unskinned."""
    path = tmp_path / "crowd.usda"
    stage = crowd_stage(path)
    stages.camera(stage, ortho=True, h_ap_mm=60.0, v_ap_mm=60.0, translate=(1, 2, 10), tenths_per_mm=1.0)
    emit = stages.material(stage, "E", emissive=(1, 1, 1))
    UsdShade.MaterialBindingAPI.Apply(stage.GetPrimAtPath("/World/Mover")).Bind(emit)
    stage.Save()
    scene = load_scene(path, 1.0, motion_blur=False)
    prep = prepare(scene, RenderOptions(width=64, height=64, spp=16, filter="box"))
    alpha = frame_channels(prep, render_frame(prep, tile_size=32, threads=2).sums)["A"]

    def at(x, y):  # the pixel seeing world (x, y): the view spans x in [-2, 4], y in [-1, 5]
        return alpha[int((5.0 - y) / 6.0 * 64), int((x + 2.0) / 6.0 * 64)]

    for i, ((_, angle), _) in enumerate(AGENTS):
        tip = bar_skinned(angle, "z")[-2:].mean(axis=0) * 0.9 + bar_skinned(angle, "z")[-4:-2].mean(axis=0) * 0.1
        assert at(tip[0], tip[1] + 3 * i) > 0.9, f"agent {i}'s tip is drawn where its skeleton turned it"
        assert at(1.9, 3 * i) < 0.1, f"agent {i}'s bar is not drawn unskinned"
        assert at(0.25, 3 * i) > 0.9, "the root half stays"


def agent_definition(path, *, nested, bind, skel_xform):
    """An agent definition layer, defaultPrim /AgentDef: a SkelRoot with its Skeleton (placed by ``skel_xform``,
    row-vector), a rest animation bound on it, and the bar with geomBindTransform ``bind``: authored in it, or
    (``nested``) from the character asset referenced by /AgentDef/geometry (a nested SkelRoot)."""
    if nested:
        agent_asset(path.parent / "agent.usda", bind=bind)
    else:
        agent_asset(path.parent / "agent.usda", bind=bind, skeleton=True)
    stage = Usd.Stage.CreateNew(str(path))
    root = UsdSkel.Root.Define(stage, "/AgentDef")
    stage.SetDefaultPrim(root.GetPrim())
    if nested:
        skel = two_joint_skeleton(stage, "/AgentDef/Skel")
        anim = tip_animation(stage, "/AgentDef/Skel/Anim", {0.0: 0.0}, "z", {})
        binding = UsdSkel.BindingAPI.Apply(root.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
        binding.CreateAnimationSourceRel().SetTargets([anim.GetPath()])
        stage.DefinePrim("/AgentDef/geometry").GetReferences().AddReference("./agent.usda")
    else:
        root.GetPrim().GetReferences().AddReference("./agent.usda")
    skel_prim = stage.OverridePrim("/AgentDef/Skel")
    UsdGeom.Xformable(skel_prim).AddTransformOp().Set(Gf.Matrix4d(*skel_xform.ravel().tolist()))
    stage.Save()


@pytest.mark.parametrize("nested", [False, True], ids=["shapes in the agent", "shapes in a nested SkelRoot"])
def test_instanced_skel_roots_match_usdskel_on_a_deinstanced_copy(tmp_path, nested):
    """Instanceable SkelRoots sharing one prototype (Skeleton with its own transform, a non-identity
    geomBindTransform), each moved, turned and scaled by its own animated transform and animated by its own
    SkelAnimation (skel:animationSource on the instance): at the frame and the shutter ends, world points equal
    UsdSkel.BakeSkinning's on a de-instanced copy, the instance's transform applied after the Skeleton's."""
    bind = np.array(Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0.3, 0.2, 0.1)))
    skel_xform = np.array(Gf.Matrix4d(1).SetRotate(Gf.Rotation(Gf.Vec3d(1, 0, 0), 40))
                          * Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 0.5, 0.2)))
    agent_definition(tmp_path / "agent_def.usda", nested=nested, bind=bind, skel_xform=skel_xform)
    path = tmp_path / "crowd.usda"
    stage = stages.new_stage(path)
    names = []
    for i in range(3):
        anim = tip_animation(stage, f"/World/Anims/a{i}", {0.0: 0.0, 0.5: 20.0 * (i + 1), 1.0: 40.0 * (i + 1)}, "z",
                             {0.0: 0.0, 0.5: 0.5, 1.0: 1.0})
        agent = stage.DefinePrim(f"/World/Crowd/agent_{i}")
        agent.GetReferences().AddReference("./agent_def.usda")
        agent.SetInstanceable(True)
        UsdSkel.BindingAPI.Apply(agent).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
        xf = UsdGeom.Xformable(agent)
        move, turn = xf.AddTranslateOp(opSuffix="place"), xf.AddRotateZOp(opSuffix="place")
        move.Set(Gf.Vec3d(2 * i, 1, 0), 0.0)
        move.Set(Gf.Vec3d(2 * i + 1, 1.5, 0), 1.0)
        turn.Set(10.0 * i, 0.0)
        turn.Set(10.0 * i + 40.0, 1.0)
        xf.AddScaleOp(opSuffix="place").Set(Gf.Vec3f(1, 1.5, 1))
        names.append(f"/World/Crowd/agent_{i}/geometry/Bar" if nested else f"/World/Crowd/agent_{i}/Bar")
    stages.camera(stage, shutter=(-0.5, 0.5), translate=(3, 1.5, 20))
    stage.Save()
    scene = load_scene(path, 0.5)
    assert not [w for w in scene.warnings if "skin" in w or "skipped" in w], scene.warnings
    baked = Usd.Stage.Open(stage.Flatten())  # the prototypes kept as plain prims: BakeSkinning skips instances
    for prim in baked.Traverse():
        prim.SetInstanceable(False)
    assert UsdSkel.BakeSkinning(baked.Traverse())
    for name in names:
        mesh, _ = world_points(scene, name)
        ref = UsdGeom.Mesh(baked.GetPrimAtPath(name))
        s = [float(x) for x in mesh.point_times]
        for t in (0.0, 0.5, 1.0):  # the shutter ends and the frame (time code = s)
            assert t in s, f"a key at {t}"
            m = np.array(ref.ComputeLocalToWorldTransform(t))
            expected = np.array(ref.GetPointsAttr().Get(t), np.float64) @ m[:3, :3] + m[3, :3]
            np.testing.assert_allclose(world_points(scene, name, s.index(t))[1], expected, atol=1e-4,
                                       err_msg=f"{name} at {t}")
        i = names.index(name)  # and analytically: skinned in skeleton space, the Skeleton's, then the instance's
        agent = UsdGeom.Xformable(stage.GetPrimAtPath(f"/World/Crowd/agent_{i}"))
        place = np.array(agent.ComputeLocalToWorldTransform(1.0))
        analytic = bar_skinned(40.0 * (i + 1), "z", 0.5, bind) @ skel_xform[:3, :3] + skel_xform[3, :3]
        np.testing.assert_allclose(world_points(scene, name, s.index(1.0))[1], analytic @ place[:3, :3] + place[3, :3],
                                   atol=1e-4)


def test_skinning_data_nothing_skins_is_named_in_one_warning(tmp_path):
    """Bars with joint influences and blend shapes that no Skeleton skins (the instanced asset, a nested SkelRoot,
    below a SkelRoot that binds none; the asset referenced onto an Xform, outside any SkelRoot) are drawn as
    authored, named in one warning with why."""
    agent_asset(tmp_path / "agent.usda")
    path = tmp_path / "unbound.usda"
    stage = stages.new_stage(path)
    UsdSkel.Root.Define(stage, "/World/Unbound")
    for parent, type_name in (("/World/Unbound", ""), ("/World/Loose", "Xform")):
        geometry = stage.DefinePrim(f"{parent}/geometry", type_name)
        geometry.GetReferences().AddReference("./agent.usda")
        geometry.SetInstanceable(True)
    stage.Save()
    scene = load_scene(path, 0.0)
    for parent in ("/World/Unbound", "/World/Loose"):
        _, pts = world_points(scene, f"{parent}/geometry/Bar")
        np.testing.assert_allclose(pts, bar_points()[0], atol=1e-6)
    lines = [w for w in scene.warnings if "no Skeleton skins" in w]
    assert len(lines) == 1, scene.warnings
    assert "/World/Unbound/geometry/Bar (no Skeleton bound)" in lines[0]
    assert "/World/Loose/geometry/Bar (no SkelRoot above it)" in lines[0]
