"""Implicit prims intersected as their exact shapes (``scene.analytic``, ``accel.analytic``), not as triangles."""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from pxr import Sdf, Usd, UsdGeom, UsdShade

import stages
from renderer.motion.shutter import Shutter
from renderer.accel.analytic import BIG, shape_hits, shape_normal, sphere_roots
from renderer.accel.upload import upload_geometry
from renderer.motion.transform import MotionTransform, make_transform
from renderer.scene.analytic import SHAPE_CODES, analytic_shapes
from renderer.scene.flatten import flatten_still_instances
from renderer.scene.model import LIGHT_MESH, AnalyticShape, Camera, Instance, Light, Material, Mesh, Scene
from renderer.usd.geometry.primitives import _AXIS_PERM, _analytic_shape, _sphere, _tessellate, tessellate_primitive
from renderer.usd.importer import load_scene
from test_accel import _probe, random_mesh, ray_triangles


@wp.kernel
def _roots(ro: wp.array(dtype=wp.vec3), rd: wp.array(dtype=wp.vec3), r: wp.array(dtype=float),
           out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    t0, t1 = sphere_roots(ro[i], rd[i], r[i])
    out[i] = wp.vec2(t0, t1)


def _exact_roots(o, d, r):
    """Both roots in float64 (NaN on a miss) of |o + t d| = r."""
    a, b, c = d @ d, o @ d, o @ o - r * r
    disc = b * b - a * c
    if disc < 0:
        return np.nan, np.nan
    return (-b - np.sqrt(disc)) / a, (-b + np.sqrt(disc)) / a


def test_sphere_roots_match_float64_for_near_far_small_and_inside_rays():
    rng = np.random.default_rng(3)
    n = 4000
    r = 10.0 ** rng.uniform(-3, 1, n)  # 1 mm to 10 m
    dist = r * 10.0 ** rng.uniform(-0.5, 4, n)  # from inside the sphere to ten thousand radii away
    ro = rng.normal(size=(n, 3))
    ro *= (dist / np.linalg.norm(ro, axis=1))[:, None]
    aim = rng.normal(size=(n, 3)) * (r * rng.uniform(0, 1.5, n))[:, None]  # some graze, some miss
    rd = (aim - ro) * rng.uniform(0.1, 10, (n, 1))  # not unit length: rays come from scaled instances
    out = wp.zeros(n, dtype=wp.vec2)
    wp.launch(_roots, n, [wp.array(ro, dtype=wp.vec3), wp.array(rd, dtype=wp.vec3), wp.array(r, dtype=float), out])
    got = out.numpy()
    ro32, rd32, r32 = ro.astype(np.float32).astype(np.float64), rd.astype(np.float32), r.astype(np.float32)
    checked = 0
    for i in range(n):
        e0, e1 = _exact_roots(ro32[i], rd32[i].astype(np.float64), float(r32[i]))
        # the closest approach, relative to the radius: away from a tangent a hit and a miss cannot be confused
        closest = np.linalg.norm(np.cross(ro32[i], rd32[i])) / np.linalg.norm(rd32[i]) / r32[i]
        if abs(closest - 1.0) < 1e-3:
            continue
        if np.isnan(e0):
            assert got[i, 0] == BIG and got[i, 1] == BIG, i
            continue
        checked += 1
        # each root to within a float32 rounding of the distance covered (the origin is ~dist from the centre)
        scale = (np.linalg.norm(ro32[i]) + r32[i]) / np.linalg.norm(rd32[i])
        np.testing.assert_allclose(got[i], [e0, e1], rtol=0, atol=4e-7 * scale + 1e-6 * abs(e1 - e0))
    assert checked > n // 3


def _sphere_mesh(radius, name="ball"):
    p, t, n = _sphere(radius)
    return Mesh(name, np.zeros(1, np.float32), p[None].astype(np.float32), t.astype(np.int32),
                np.zeros(len(t), np.int32), normals=n[t].astype(np.float32), shape=AnalyticShape("sphere", radius))


def _scene(meshes, instances, opacity=1.0):
    cam = Camera("cam", MotionTransform.static(np.eye(4)))
    return Scene(meshes, instances, [Material("m", opacity=opacity)], [], cam, Shutter(0, 0, 1))


def _ellipsoid_hit(o, d, w2o, r):
    """Nearest positive root, exactly, of the ray under the inverse transform w2o, or inf."""
    oo = w2o[:3, :3] @ o + w2o[:3, 3]
    dd = w2o[:3, :3] @ d
    roots = [t for t in _exact_roots(oo, dd, r) if t > 0]
    return min(roots) if roots else np.inf


def test_walks_hit_a_scaled_sphere_and_a_moving_one_exactly_and_shadows_cross_each_twice():
    """A squashed, rotated sphere (an ellipsoid), a sphere moving over the shutter and a triangle mesh: closest
    hits at the exact distances of the quadric, at random times, the sphere's hit reporting its mesh's first
    triangle; a shadow ray through a sphere of opacity 0.5 crosses it twice (0.25 gets through)."""
    rng = np.random.default_rng(17)
    squash = np.diag([1.5, 0.5, 1.0, 1.0])
    c, s_ = np.cos(0.6), np.sin(0.6)
    squash = np.array([[c, -s_, 0, 0], [s_, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) @ squash
    squash[:3, 3] = (-1.5, 0.2, -1.0)
    move0, move1 = np.eye(4), np.eye(4)
    move0[:3, 3], move1[:3, 3] = (1.0, -0.5, 0.0), (2.5, 0.5, -1.0)
    clutter = np.eye(4)
    clutter[:3, 3] = (0.0, 0.0, -6.0)
    scene = _scene([_sphere_mesh(0.8), random_mesh(rng, 200, name="clutter")],
                   [Instance(0, MotionTransform.static(squash)), Instance(0, make_transform([0, 1], [move0, move1])),
                    Instance(1, MotionTransform.static(clutter))], opacity=0.5)
    geo, _ = upload_geometry(scene)
    assert geo.mesh_shape.numpy().tolist() == [1, 0] and geo.mesh_shape_param.numpy()[0, 0] == np.float32(0.8)
    n = 3000
    ro = np.tile([0.0, 0.0, 6.0], (n, 1)) + rng.normal(0, 0.3, (n, 3))
    rd = rng.uniform([-3.5, -1.5, -1.5], [3.5, 1.5, 0.0], (n, 3)) - ro
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    times = rng.uniform(0, 1, n).astype(np.float32)
    t, inst, tri, tr = _probe(geo, scene, ro, rd, times)
    sphere_hits = 0
    for i in range(n):
        x = [_ellipsoid_hit(ro[i], rd[i], np.linalg.inv(squash), 0.8)]
        m = move0.copy()
        m[:3, 3] = move0[:3, 3] + times[i] * (move1[:3, 3] - move0[:3, 3])
        x.append(_ellipsoid_hit(ro[i], rd[i], np.linalg.inv(m), 0.8))
        k = int(np.argmin(x))
        if inst[i] in (0, 1):
            sphere_hits += 1
            assert inst[i] == k and tri[i] == 0, i
            np.testing.assert_allclose(t[i], x[k], rtol=2e-6, atol=2e-6)
            # an opaque-half sphere in the way: both its crossings count
            assert tr[i] <= 0.25 + 1e-6, i
        elif np.isfinite(min(x)):  # the clutter is behind both spheres: only a graze may tell them apart
            assert inst[i] == 2 or abs(x[k] - t[i]) < 1e-3, i
    assert sphere_hits > n // 8


# Each implicit prim kind, with its USD parameters and spine axis (tapered cylinder and cone included)
SHAPE_CASES = [
    ("Sphere", (0.9,), "Z"),
    ("Cylinder", (0.6, 0.6, 1.8), "X"),
    ("Cylinder_1", (0.3, 0.8, 1.5), "Z"),
    ("Cone", (0.7, 0.0, 1.6), "Y"),
    ("Capsule", (0.45, 0.45, 1.2), "Y"),
]


def _cloud_mesh(centres, radii, normals=None, name="cloud"):
    """A point cloud as the importer makes it (``curves._point_cloud``): centres (P, N, 3), radii (N,), and for
    discs their unit normals (N, 3)."""
    n = centres.shape[1]
    corner = None if normals is None else np.repeat(normals[:, None, :], 3, 1).astype(np.float32)
    return Mesh(name, np.linspace(0, 1, len(centres)).astype(np.float32), centres.astype(np.float32),
                np.repeat(np.arange(n, dtype=np.int32)[:, None], 3, 1), np.zeros(n, np.int32), normals=corner,
                solid=np.full(n, normals is None), shape=AnalyticShape("points" if normals is None else "discs",
                                                                       float(radii.max())),
                point_radii=radii.astype(np.float32))


def _discs_hits(o, d, centres, radii, normals):
    """Brute force, float64: (nearest t > 0 or inf, its disc, crossings) of a ray and discs."""
    denom = normals @ d
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.sum((centres - o[None]) * normals, 1) / denom
    q = o[None] + t[:, None] * d[None] - centres
    ok = np.isfinite(t) & (t > 0) & (np.sum(q * q, 1) <= radii ** 2)
    t = np.where(ok, t, np.inf)
    k = int(np.argmin(t))
    return t[k], k, int(ok.sum())


def _spheres_hits(o, d, centres, radii):
    """Brute force, float64: (nearest t > 0 or inf, its sphere, crossings in (0, inf)) of a ray and spheres."""
    oc = o[None] - centres
    b = oc @ d
    disc = b * b - (np.sum(oc * oc, 1) - radii ** 2)
    root = np.sqrt(np.maximum(disc, 0.0))
    t0, t1 = np.where(disc >= 0, -b - root, np.inf), np.where(disc >= 0, -b + root, np.inf)
    crossings = int(np.sum(np.isfinite(t0) & (t0 > 0)) + np.sum(np.isfinite(t1) & (t1 > 0)))
    t = np.where(t0 > 0, t0, np.where(t1 > 0, t1, np.inf))
    k = int(np.argmin(t))
    return t[k], k, crossings


@pytest.mark.parametrize("moving", [False, True])
@pytest.mark.parametrize("kind", ["points", "discs"])
def test_point_clouds_are_exact_spheres_or_discs_to_the_walks(moving, kind):
    """A cloud of 400 spheres (or discs facing random normals) of different radii, scaled and placed by its
    instance, its points still or moving (two point keys): closest hits at the exact distance of the nearest one at
    the ray's time, reporting its point as the triangle; shadow rays multiply (1 - opacity) once per crossing."""
    rng = np.random.default_rng(5)
    n = 400
    c0 = rng.uniform(-1.5, 1.5, (n, 3))
    keys = np.stack([c0, c0 + rng.normal(0, 0.3, (n, 3))]) if moving else c0[None]
    radii = rng.uniform(0.03, 0.12, n) * (2.0 if kind == "discs" else 1.0)
    normals = None
    if kind == "discs":
        normals = rng.normal(size=(n, 3))
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    xf = np.diag([1.2, 1.2, 1.2, 1.0])
    xf[:3, 3] = (0.2, -0.1, 0.0)
    scene = _scene([_cloud_mesh(keys, radii, normals)], [Instance(0, MotionTransform.static(xf))], opacity=0.5)
    assert analytic_shapes(scene)[0].kind == kind
    geo, stats = upload_geometry(scene)
    assert geo.mesh_shape.numpy()[0] == SHAPE_CODES[kind] and stats.triangles == n
    m = 2000
    ro = np.tile([0.0, 0.0, 6.0], (m, 1)) + rng.normal(0, 0.2, (m, 3))
    rd = rng.uniform([-0.3, -0.3, -1], [0.3, 0.3, -1], (m, 3))
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    times = rng.uniform(0, 1, m).astype(np.float32)
    t, inst, tri, tr = _probe(geo, scene, ro, rd, times)
    hits = 0
    for i in range(m):
        centres = (keys[0] + (keys[-1] - keys[0]) * float(times[i])) * 1.2 + xf[:3, 3]
        if kind == "discs":  # a uniform scale keeps the normals
            tb, k, crossings = _discs_hits(ro[i], rd[i], centres, radii * 1.2, normals)
        else:
            tb, k, crossings = _spheres_hits(ro[i], rd[i], centres, radii * 1.2)
        if np.isfinite(tb):
            hits += 1
            assert inst[i] == 0 and tri[i] == k, i
            np.testing.assert_allclose(t[i], tb, rtol=1e-5, atol=1e-5)
        else:
            assert inst[i] == -1, i
        np.testing.assert_allclose(tr[i], 0.5 ** crossings, rtol=1e-5, atol=1e-30)
    assert hits > m // 4


@pytest.mark.parametrize("kind, params, axis", SHAPE_CASES)
def test_a_shapes_world_box_is_exact(kind, params, axis):
    """The top level's box of a transformed shape (rotated, sheared, scaled unevenly, mirrored) holds all of its
    fine tessellation, and that tessellation reaches it to within its facets' error (the box of the object
    box's corners is up to sqrt 3 times wider per axis)."""
    from renderer.scene.analytic import shape_world_boxes

    rng = np.random.default_rng(3)
    perm = _AXIS_PERM[axis]
    shape = _analytic_shape(kind, params, perm)
    p = _tessellate(kind, params)[0][:, perm]
    ms = np.tile(np.eye(4), (20, 1, 1))
    for m in ms:
        q, _r = np.linalg.qr(rng.normal(size=(3, 3)))
        m[:3, :3] = q @ np.diag(rng.uniform(0.3, 3.0, 3) * rng.choice([-1, 1], 3)) @ (np.eye(3) + np.triu(
            rng.uniform(-0.4, 0.4, (3, 3)), 1))
        m[:3, 3] = rng.uniform(-50, 50, 3)
    los, his = shape_world_boxes(shape, ms)  # all 20 in one batch
    for m, lo, hi in zip(ms, los, his):
        w = p @ m[:3, :3].T + m[:3, 3]
        assert np.all(w >= lo) and np.all(w <= hi)
        size = hi - lo
        assert np.all(w.min(0) - lo <= 2e-3 * size) and np.all(hi - w.max(0) <= 2e-3 * size)


def test_a_shadow_ray_leaving_a_sphere_crosses_it_once():
    scene = _scene([_sphere_mesh(1.0)], [Instance(0, MotionTransform.static(np.eye(4)))], opacity=0.5)
    geo, _ = upload_geometry(scene)
    ro = np.array([[0.0, 0.0, 0.0], [0.2, 0.3, -0.1], [0.0, 0.0, 3.0]])
    rd = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    t, inst, _, tr = _probe(geo, scene, ro, rd, np.zeros(3, np.float32))
    np.testing.assert_allclose(t, [1.0, np.sqrt(1 - 0.09 - 0.01) - 0.2, 2.0], rtol=1e-6)
    np.testing.assert_allclose(tr, [0.5, 0.5, 0.25], rtol=1e-6)


def test_which_spheres_are_analytic():
    """Static spheres are; deforming ones, emitters, CSG operands and spheres with uvs or colours keep their
    triangles; other meshes never are."""
    base = [_sphere_mesh(1.0, f"s{i}") for i in range(6)] + [random_mesh(np.random.default_rng(0), 4)]
    base[1].point_times = np.array([0.0, 1.0], np.float32)
    base[1].points = np.concatenate([base[1].points, base[1].points * 2])
    base[3].uvs = np.zeros((len(base[3].triangles), 3, 2), np.float32)
    base[4].colors = np.ones((len(base[4].triangles), 3, 3), np.float32)
    still = MotionTransform.static(np.eye(4))
    instances = [Instance(i, still) for i in range(7)] + [Instance(5, still, csg_group=0)]
    scene = _scene(base, instances)
    scene.csg_operations = ["union"]
    scene.lights = [Light(LIGHT_MESH, "glow", (1.0, 1.0, 1.0), still, instance=2)]
    assert [s is not None for s in analytic_shapes(scene)] == [True] + [False] * 6


def test_analytic_spheres_stay_instanced_when_still_geometry_is_merged():
    rng = np.random.default_rng(1)
    still = MotionTransform.static(np.eye(4))
    scene = _scene([random_mesh(rng, 10, name="a"), random_mesh(rng, 10, name="b"), _sphere_mesh(0.5)],
                   [Instance(0, still), Instance(1, still), Instance(2, still), Instance(2, still)])
    flat = flatten_still_instances(scene)
    assert len(flat.instances) == 3  # the merged mesh and both spheres
    assert [flat.meshes[i.mesh].shape.radius_bottom for i in flat.instances[1:]] == [0.5, 0.5]


def test_the_importer_marks_implicit_prims_whose_size_holds_over_the_shutter(tmp_path):
    """Spheres, cylinders (tapered too, along their authored axis), cones and capsules are marked with their exact
    shape; a sphere growing over the shutter deforms and keeps its triangles (with a closed shutter it is the sphere
    of its radius at the frame); cubes stay meshes, and so do tapered capsules (not a quadric)."""
    stage = stages.new_stage(tmp_path / "s.usda")
    stages.camera(stage, translate=(0, 0, 5), shutter=(-0.25, 0.25))
    stages.sphere(stage, "/World/Still", 0.7)
    grows = stages.sphere(stage, "/World/Grows", 0.5, center=(2, 0, 0))
    grows.GetRadiusAttr().Set(0.5, Usd.TimeCode(0))
    grows.GetRadiusAttr().Set(1.0, Usd.TimeCode(48))
    UsdGeom.Cube.Define(stage, "/World/Box")
    cyl = UsdGeom.Cylinder.Define(stage, "/World/Tube")
    cyl.CreateAxisAttr("X")
    cyl.CreateRadiusAttr(0.25)
    cyl.CreateHeightAttr(3.0)
    UsdGeom.Cone.Define(stage, "/World/Cone").CreateAxisAttr("Y")
    UsdGeom.Capsule.Define(stage, "/World/Pill")
    taper = stage.DefinePrim("/World/Taper", "Cylinder_1")
    taper.CreateAttribute("radiusTop", Sdf.ValueTypeNames.Double).Set(0.2)
    stage.DefinePrim("/World/Tapered", "Capsule_1").CreateAttribute("radiusTop", Sdf.ValueTypeNames.Double).Set(0.2)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(48)
    stage.Save()
    scene = load_scene(tmp_path / "s.usda", frame=24)
    shape = {m.name: m.shape for m in scene.meshes}
    assert shape == {"/World/Still": AnalyticShape("sphere", pytest.approx(0.7)), "/World/Grows": None,
                     "/World/Box": None, "/World/Tube": AnalyticShape("frustum", 0.25, 0.25, 3.0, 0),
                     "/World/Cone": AnalyticShape("frustum", 1.0, 0.0, 2.0, 1),
                     "/World/Pill": AnalyticShape("capsule", 0.5, 0.5, 1.0, 2),
                     "/World/Taper": AnalyticShape("frustum", 1.0, pytest.approx(0.2), 2.0, 2), "/World/Tapered": None}
    scene = load_scene(tmp_path / "s.usda", frame=24, motion_blur=False)
    assert {m.name: m.shape for m in scene.meshes}["/World/Grows"].radius_bottom == pytest.approx(0.75)


def test_stand_ins_get_their_triangles_where_the_shape_cannot_be_used(tmp_path):
    """A still implicit prim arrives as its shape and a one-triangle stand-in. An emissive one (a light samples its
    triangles) and the operands of a CSG group get exactly the tessellation the importer made before; a stand-in
    that stops being usable after import (a light made of it through the library) gets it when prepared."""
    from renderer.settings.options import RenderOptions
    from renderer.render import prepare

    stage = stages.new_stage(tmp_path / "s.usda")
    stages.camera(stage, translate=(0, 0, 8))
    stages.sphere(stage, "/World/Plain", 0.5, center=(-2, 0, 0))
    stages.sphere(stage, "/World/Glow", 0.6, center=(2, 0, 0), mat=stages.material(stage, "E", emissive=(1, 1, 1)))
    group = UsdGeom.Xform.Define(stage, "/World/Group").GetPrim()
    group.CreateAttribute("drt:csg:operation", Sdf.ValueTypeNames.Token, variability=Sdf.VariabilityUniform).Set(
        "union")
    stages.sphere(stage, "/World/Group/A", 0.7, center=(0, 2, 0))
    stages.sphere(stage, "/World/Group/B", 0.8, center=(0.5, 2, 0))
    stage.Save()
    scene = load_scene(tmp_path / "s.usda")
    mesh = {m.name: m for m in scene.meshes}
    assert len(mesh["/World/Plain"].triangles) == 1 and mesh["/World/Plain"].tessellate is not None
    assert scene.csg_operations == ["union"]
    for name, r in (("/World/Glow", 0.6), ("/World/Group/A", 0.7), ("/World/Group/B", 0.8)):
        m = mesh[name]
        p, tris, nrm, _, _ = tessellate_primitive("Sphere", (r,), tuple(_AXIS_PERM["Z"]))
        assert m.tessellate is None and m.solid is None, name
        assert np.array_equal(m.points, p) and np.array_equal(m.triangles, tris) and np.array_equal(m.normals, nrm)
        assert len(m.material_ids) == len(tris) and len(set(m.material_ids.tolist())) == 1
    assert [s is not None for s in analytic_shapes(scene)] == [m.name == "/World/Plain" for m in scene.meshes]
    assert not any("closed" in w for w in scene.warnings), scene.warnings
    plain = next(i for i, inst in enumerate(scene.instances) if scene.meshes[inst.mesh].name == "/World/Plain")
    scene.lights.append(Light(LIGHT_MESH, "late", (1.0, 1.0, 1.0), scene.instances[plain].transform, instance=plain))
    prep = prepare(scene, RenderOptions(width=16, height=16, spp=1))
    n = len(tessellate_primitive("Sphere", (0.5,), tuple(_AXIS_PERM["Z"]))[1])
    assert mesh["/World/Plain"].tessellate is None and len(mesh["/World/Plain"].triangles) == n
    assert prep.stats.triangles == 4 * n


def test_points_import_as_sphere_clouds(tmp_path):
    """Points without normals are a sphere cloud: radii from the widths (diameters), one colour per point where
    displayColor varies per point; with normals, a cloud of discs facing them (thin); an emissive cloud gets its
    triangles (a light samples them), each keeping its point's colour."""
    stage = stages.new_stage(tmp_path / "p.usda")
    stages.camera(stage, translate=(0, 0, 8))
    for name in ("Beads", "Discs", "Glow"):
        p = UsdGeom.Points.Define(stage, f"/World/{name}")
        p.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
        p.CreateWidthsAttr([0.2, 0.4, 0.6])
        p.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
        p.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex).Set([(1, 0, 0), (0, 1, 0), (0, 0, 1)])
    UsdGeom.Points.Get(stage, "/World/Discs").CreateNormalsAttr([(0, 0, 1)] * 3)
    glow = stages.material(stage, "E", emissive=(1, 1, 1))
    UsdShade.MaterialBindingAPI.Apply(stage.GetPrimAtPath("/World/Glow")).Bind(glow)
    stage.Save()
    scene = load_scene(tmp_path / "p.usda")
    mesh = {m.name: m for m in scene.meshes}
    beads = mesh["/World/Beads"]
    assert beads.shape.kind == "points" and len(beads.triangles) == 3 and beads.normals is None
    np.testing.assert_allclose(beads.point_radii, [0.1, 0.2, 0.3], rtol=1e-6)
    np.testing.assert_allclose(beads.colors[:, 0], [(1, 0, 0), (0, 1, 0), (0, 0, 1)])
    assert beads.solid.all() and beads.tessellate is not None
    discs = mesh["/World/Discs"]
    assert discs.shape.kind == "discs" and len(discs.triangles) == 3 and not discs.solid.any()
    np.testing.assert_allclose(discs.normals, np.broadcast_to([0, 0, 1], (3, 3, 3)))
    g = mesh["/World/Glow"]
    assert g.tessellate is None and g.point_radii is None and len(g.triangles) > 3
    assert any(lt.kind == LIGHT_MESH for lt in scene.lights)
    assert [s is not None for s in analytic_shapes(scene)] == [m.name != "/World/Glow" for m in scene.meshes]


def test_threads_realizing_one_cloud_get_one_whole_tessellation(tmp_path):
    """Workers sharing a scene may realize its meshes at once: each mesh is realized once, whole (its triangles'
    materials and colours from the right points)."""
    import threading

    stage = stages.new_stage(tmp_path / "c.usda")
    stages.camera(stage, translate=(0, 0, 8))
    p = UsdGeom.Points.Define(stage, "/World/Cloud")
    p.CreatePointsAttr([(x, 0, 0) for x in range(50)])
    p.CreateWidthsAttr([0.3])
    p.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex).Set([(x / 50, 1 - x / 50, 0.5) for x in range(50)])
    stage.Save()
    meshes = [load_scene(tmp_path / "c.usda").meshes[0] for _ in range(2)]
    want = meshes[0].realize()
    shared = meshes[1]
    threads = [threading.Thread(target=shared.realize) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for name in ("points", "triangles", "normals", "material_ids", "colors"):
        assert np.array_equal(getattr(shared, name), getattr(want, name)), name
    # each triangle's colour is its point's: the point nearest its centroid
    centroid = want.points[0][want.triangles].mean(1)
    np.testing.assert_allclose(want.colors[:, 0, 0], np.round(centroid[:, 0]) / 50, atol=1e-6)


def test_a_sphere_covers_exactly_its_disc_in_an_orthographic_view(tmp_path):
    """Coverage through the whole render path (camera, walk, film): the alpha of a unit sphere seen orthographically
    integrates to pi (seeds 0 and 1: +1.0e-4, +0.5e-4). Its 4032-triangle tessellation covered 0.165 % less (a
    64-gon silhouette), five times this tolerance."""
    from renderer.settings.options import RenderOptions
    from renderer.render import frame_channels, prepare, render_frame

    stage = stages.new_stage(tmp_path / "disc.usda")
    stages.camera(stage, translate=(0, 0, 5), ortho=True, h_ap_mm=24.0, v_ap_mm=24.0)  # 2.4 x 2.4 units
    stages.sphere(stage, "/World/Ball", 1.0, mat=stages.material(stage, "W", diffuse=(0.5, 0.5, 0.5)))
    stage.Save()
    prep = prepare(load_scene(tmp_path / "disc.usda"), RenderOptions(width=96, height=96, spp=64, max_depth=1))
    alpha = frame_channels(prep, render_frame(prep, tile_size=32, threads=2).sums)["A"]
    area = alpha.astype(np.float64).sum() * (2.4 / 96) ** 2
    assert abs(area / np.pi - 1.0) < 3e-4, area / np.pi


@wp.kernel
def _shape_probe(kind: int, axis: int, prm: wp.vec4, ro: wp.array(dtype=wp.vec3), rd: wp.array(dtype=wp.vec3),
                 t_out: wp.array(dtype=float), n_out: wp.array(dtype=int), nrm_out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    t, part, n = shape_hits(kind, axis, prm, ro[i], rd[i], 1.0e30)
    t_out[i] = t
    n_out[i] = n
    if t < BIG:
        nrm_out[i] = wp.normalize(shape_normal(kind, axis, prm, ro[i] + rd[i] * t, part))


def _tessellated_hits(p, tris, nrm, o, d):
    """Brute force over a tessellation: (nearest t or inf, its triangle's mean corner normal, crossings)."""
    t, ok = ray_triangles(p[tris], o, d)
    if not ok.any():
        return np.inf, None, 0
    k = int(np.argmin(np.where(ok, t, np.inf)))
    n = nrm[tris[k]].mean(0)
    return t[k], n / np.linalg.norm(n), int(ok.sum())


@pytest.mark.parametrize("kind, params, axis", SHAPE_CASES)
def test_each_shape_agrees_with_its_own_tessellation(kind, params, axis):
    """The exact shape against brute force over the 64-segment tessellation it replaces, on rays from all around:
    the same rays hit (bar a few grazing the silhouette), at the same distances and with the same outward normals up
    to the facets' error, and every hit crosses the closed surface twice."""

    perm = _AXIS_PERM[axis]
    p, tris, nrm = _tessellate(kind, params)
    p, nrm = p[:, perm], nrm[:, perm]
    shape = _analytic_shape(kind, params, perm)
    rng = np.random.default_rng(len(kind))
    n = 1500
    ro = rng.normal(size=(n, 3))
    ro *= (4.0 / np.linalg.norm(ro, axis=1))[:, None]
    rd = rng.uniform(-1.1, 1.1, (n, 3)) - ro
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    prm = wp.vec4(shape.radius_bottom, shape.radius_top, 0.5 * shape.height, 0.0)
    t, crossings, normal = wp.zeros(n, dtype=float), wp.zeros(n, dtype=int), wp.zeros(n, dtype=wp.vec3)
    wp.launch(_shape_probe, n, [SHAPE_CODES[shape.kind], shape.axis, prm, wp.array(ro, dtype=wp.vec3),
                                wp.array(rd, dtype=wp.vec3), t, crossings, normal])
    t, crossings, normal = t.numpy(), crossings.numpy(), normal.numpy()
    disagree = hits = 0
    size = max(params)
    for i in range(n):
        bt, bn, bcount = _tessellated_hits(p, tris, nrm, ro[i], rd[i])
        hit = t[i] < BIG
        if hit != np.isfinite(bt):
            disagree += 1
            continue
        if not hit:
            assert crossings[i] == 0
            continue
        hits += 1
        # apart along the normal by at most a facet's sagitta, r (1 - cos(pi / 64)) (along a grazing ray: more)
        assert abs(t[i] - bt) * abs(rd[i] @ bn) < 4e-3 * size, (i, t[i], bt)
        if normal[i] @ bn < np.cos(np.radians(6.0)):  # on a rim the exact cap and the facets' side may meet
            disagree += 1
        assert crossings[i] == 2 or bcount != 2, i
    assert hits > n // 4
    assert disagree <= n // 100, disagree  # grazing a silhouette or a rim
