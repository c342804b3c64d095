"""Traversal of the time-keyed two-level BVH against brute force, at random ray times."""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from renderer.motion.shutter import Shutter
from renderer.accel.intersect import (Geometry, instance_object_to_world, instance_world_to_object, intersect_closest,
                                      leaf_closest, leaf_four, triangle_hit_edges)
from renderer.motion.kernels import find_segment, keys_matrix
from renderer.shading.materials import Materials
from renderer.shading.material_upload import upload_material_textures, upload_materials
from renderer.accel.occlusion import hit_uv, transmittance
from renderer.shading.textures import Textures
from renderer.accel.build import build_bvh
from renderer.accel.instance_bounds import instance_key_bounds
from renderer.accel.upload import upload_geometry
from renderer.motion.transform import MotionTransform, make_transform, matrix_at
from renderer.scene.model import Camera, Instance, Material, Mesh, Scene


@wp.kernel
def probe_kernel(geo: Geometry, mats: Materials, tex: Textures, ro: wp.array(dtype=wp.vec3),
                 rd: wp.array(dtype=wp.vec3), times: wp.array(dtype=wp.float32), t_out: wp.array(dtype=wp.float32),
                 inst_out: wp.array(dtype=wp.int32), tri_out: wp.array(dtype=wp.int32),
                 tr_out: wp.array(dtype=wp.float32)):
    i = wp.tid()
    h = intersect_closest(geo, ro[i], rd[i], 1.0e30, times[i])
    t_out[i] = h.t
    inst_out[i] = h.inst
    tri_out[i] = h.tri
    tr_out[i] = transmittance(geo, mats, tex, ro[i], rd[i], 1.0e30, times[i])


def rot_y(deg, t=(0, 0, 0)):
    a = np.radians(deg)
    m = np.eye(4)
    m[0, 0], m[0, 2], m[2, 0], m[2, 2] = np.cos(a), np.sin(a), -np.sin(a), np.cos(a)
    m[:3, 3] = t
    return m


def random_mesh(rng, n_tri, keys=1, name="m"):
    centres = rng.uniform(-1, 1, (n_tri, 1, 3))
    tri = (centres + rng.normal(0, 0.25, (n_tri, 3, 3))).reshape(-1, 3)
    pts = [tri]
    for _ in range(keys - 1):
        pts.append(tri + rng.normal(0, 0.3, (1, 3)) + rng.normal(0, 0.05, tri.shape))
    times = np.linspace(0, 1, keys) if keys > 1 else np.zeros(1)
    return Mesh(name, times.astype(np.float32), np.array(pts, np.float32),
                np.arange(n_tri * 3, dtype=np.int32).reshape(-1, 3), np.zeros(n_tri, np.int32))


def make_scene(rng):
    meshes = [random_mesh(rng, 400, 1, "still"), random_mesh(rng, 300, 3, "deforming")]
    instances = [
        Instance(0, MotionTransform.static(np.eye(4))),
        Instance(0, make_transform([0, 0.5, 1], [rot_y(0, (3, 0, 0)), rot_y(90, (3, 1, 0)), rot_y(180, (3, 1, 0))])),
        Instance(1, make_transform([0, 1], [rot_y(0, (-3, 0, 0)), rot_y(30, (-2, 0, 1))])),
        Instance(1, MotionTransform.static(rot_y(45, (0, 0, -3))), visible_from=0.25, visible_to=0.75),
        # only its translation moves: the matrices come from the still ones and the translation at s
        Instance(0, make_transform([0, 0.5, 1], [rot_y(30, (0, 2, 0)), rot_y(30, (0.5, 2.5, 0)),
                                                  rot_y(30, (1.5, 2, 0.5))])),
    ]
    cam = Camera("cam", MotionTransform.static(np.eye(4)))
    return Scene(meshes, instances, [Material("m", opacity=0.5)], [], cam, Shutter(0, 0, 1))


def ray_triangles(v, o, d):
    """Moller-Trumbore in float64 over triangles v (T, 3, 3): the ray parameter t of each and whether the ray hits
    it ahead of its origin."""
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    pv = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, pv)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1 / det
        tv = o - v[:, 0]
        b1 = np.einsum("ij,ij->i", tv, pv) * inv
        qv = np.cross(tv, e1)
        b2 = (qv @ d) * inv
        t = np.einsum("ij,ij->i", e2, qv) * inv
    return t, (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > 0)


def brute_force(scene, o, d, s):
    best = (np.inf, -1, -1)
    for ii, inst in enumerate(scene.instances):
        if not inst.visible_from <= s <= inst.visible_to:
            continue
        mesh = scene.meshes[inst.mesh]
        w2o = np.linalg.inv(matrix_at(inst.transform, s))
        oo = w2o[:3, :3] @ o + w2o[:3, 3]
        dd = w2o[:3, :3] @ d
        pt = mesh.point_times.astype(np.float64)
        if len(pt) > 1:
            j = int(np.clip(np.searchsorted(pt, s, side="right"), 1, len(pt) - 1))
            u = (s - pt[j - 1]) / (pt[j] - pt[j - 1])
            pts = mesh.points[j - 1] * (1 - u) + mesh.points[j] * u
        else:
            pts = mesh.points[0]
        t, ok = ray_triangles(pts[mesh.triangles].astype(np.float64), oo, dd)
        if ok.any():
            k = np.argmin(np.where(ok, t, np.inf))
            if t[k] < best[0]:
                best = (t[k], ii, k + sum(len(m.triangles) for m in scene.meshes[:inst.mesh]))
    return best


def test_closest_hit_matches_brute_force_at_random_times():
    rng = np.random.default_rng(7)
    scene = make_scene(rng)
    geo, stats = upload_geometry(scene)
    assert stats.tlas_keys > 1
    n = 600
    ro = np.tile([0.0, 0.3, 8.0], (n, 1)) + rng.normal(0, 0.5, (n, 3))
    target = rng.uniform([-4, -1.5, -4], [4, 1.5, 1], (n, 3))
    rd = target - ro
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    times = rng.uniform(0, 1, n)
    outs = [wp.zeros(n, dtype=wp.float32), wp.zeros(n, dtype=wp.int32), wp.zeros(n, dtype=wp.int32),
            wp.zeros(n, dtype=wp.float32)]
    mats = upload_materials(scene.materials)
    tex = upload_material_textures(scene.materials)
    wp.launch(probe_kernel, dim=n, inputs=[geo, mats, tex, wp.array(ro, dtype=wp.vec3), wp.array(rd, dtype=wp.vec3),
                                           wp.array(times, dtype=wp.float32)] + outs)
    t, inst, tri, tr = (o.numpy() for o in outs)
    hits = 0
    for i in range(n):
        bt, bi, btri = brute_force(scene, ro[i], rd[i], times[i])
        if bi < 0:
            assert inst[i] < 0, i
        else:
            hits += 1
            assert inst[i] == bi and tri[i] == btri, (i, inst[i], bi, tri[i], btri)
            np.testing.assert_allclose(t[i], bt, rtol=1e-4)
    assert hits > n // 4  # the test exercises real hits
    # transmittance: every crossed surface has opacity 0.5, a hit means at most 0.5 gets through
    assert np.all(tr[inst >= 0] <= 0.5 + 1e-6) and np.all(tr[inst < 0] == 1.0)


def test_top_level_key_bounds_contain_curved_motion():
    """The blend of two key boxes must contain the instance's true box at every time in between."""
    rng = np.random.default_rng(3)
    mesh = random_mesh(rng, 30, 1)
    lo, hi = mesh.points[:, mesh.triangles].min(2), mesh.points[:, mesh.triangles].max(2)
    bvh = build_bvh(lo, hi)
    # half a turn about an offset axis plus a climb: the path is an arc, far from linear
    xf = make_transform(np.linspace(0, 1, 9), [rot_y(180 * k / 8, (2 * np.cos(k / 2), k * 0.1, 0)) for k in range(9)])
    inst = Instance(0, xf)
    for nkeys in (3, 5, 9):
        klo, khi = instance_key_bounds(inst, bvh, mesh.point_times.astype(np.float64), nkeys)
        for s in np.linspace(0, 1, 401):
            m = matrix_at(xf, s)
            w = mesh.points[0] @ m[:3, :3].T + m[:3, 3]
            x = s * (nkeys - 1)
            k = min(int(x), nkeys - 2)
            u = x - k
            blo = klo[k] * (1 - u) + klo[k + 1] * u
            bhi = khi[k] * (1 - u) + khi[k + 1] * u
            assert np.all(w.min(0) >= blo - 1e-5) and np.all(w.max(0) <= bhi + 1e-5), (nkeys, s)


def test_cost_of_a_ray_does_not_depend_on_speed():
    """Key boxes of a fast mover are as tight at each key as those of a still object (not the swept box)."""
    rng = np.random.default_rng(5)
    mesh = random_mesh(rng, 30, 1)
    lo, hi = mesh.points[:, mesh.triangles].min(2), mesh.points[:, mesh.triangles].max(2)
    bvh = build_bvh(lo, hi)
    still_size = (hi[0].max(0) - lo[0].min(0))
    for speed in (1.0, 100.0):
        xf = make_transform([0, 1], [np.eye(4), rot_y(0, (speed, 0, 0))])
        klo, khi = instance_key_bounds(Instance(0, xf), bvh, mesh.point_times.astype(np.float64), 3)
        np.testing.assert_allclose(khi - klo, np.tile(still_size, (3, 1)), rtol=1e-4, atol=1e-4)


@wp.kernel
def _instance_matrices(geo: Geometry, inst: int, times: wp.array(dtype=float), w2o: wp.array(dtype=wp.mat44),
                       o2w: wp.array(dtype=wp.mat44), general: wp.array(dtype=wp.mat44)):
    i = wp.tid()
    w2o[i] = instance_world_to_object(geo, inst, times[i])
    o2w[i] = instance_object_to_world(geo, inst, times[i])
    general[i] = wp.inverse(keys_matrix(geo.keys, geo.inst_xf_off[inst], geo.inst_xf_count[inst], times[i]))


def test_translate_only_motion_takes_the_short_path_and_agrees_with_the_general_one():
    geo, _ = upload_geometry(make_scene(np.random.default_rng(3)))
    assert geo.inst_translate_only.numpy().tolist() == [0, 0, 0, 0, 1]  # still, rotating, rotating, still, moving
    s = np.linspace(0, 1, 41).astype(np.float32)
    out = [wp.zeros(len(s), dtype=wp.mat44) for _ in range(3)]
    wp.launch(_instance_matrices, len(s), [geo, 4, wp.array(s, dtype=float), *out])
    w2o, o2w, general = (a.numpy() for a in out)
    np.testing.assert_allclose(w2o, general, atol=1e-5)
    np.testing.assert_allclose(np.einsum("nij,njk->nik", o2w, w2o), np.broadcast_to(np.eye(4), w2o.shape), atol=1e-5)
    np.testing.assert_allclose(o2w[20][:3, 3], [0.5, 2.5, 0.0], atol=1e-6)  # the middle key, exactly at s = 0.5


def test_moving_transforms_agree_with_numpy_slerp_and_inverse():
    """The Warp side's transforms at a ray's time (slerp, rotation matrix, inverse) against motion.transform's
    NumPy matrix_at: a quarter turn per key, a 30-degree key pair, a sub-degree one, a half turn and a shear."""
    scene = make_scene(np.random.default_rng(3))
    shear = np.eye(4)
    shear[0, 1] = 0.4
    scene.instances += [
        Instance(0, make_transform([0, 1], [rot_y(10, (0, 0, 0)), rot_y(10.5, (0, 1e-3, 0))])),
        Instance(0, make_transform([0, 1], [rot_y(0, (1, 2, 3)), rot_y(179, (1, 2, 3)) @ shear])),
    ]
    geo, _ = upload_geometry(scene)
    s = np.linspace(0, 1, 101).astype(np.float32)
    for inst in (1, 2, 4, 5, 6):
        out = [wp.zeros(len(s), dtype=wp.mat44) for _ in range(3)]
        wp.launch(_instance_matrices, len(s), [geo, inst, wp.array(s, dtype=float), *out])
        w2o, o2w, _ = (a.numpy() for a in out)
        want = np.array([matrix_at(scene.instances[inst].transform, float(x)) for x in s])
        np.testing.assert_allclose(o2w, want, atol=2e-5, err_msg=f"instance {inst}")
        np.testing.assert_allclose(w2o, np.linalg.inv(want), atol=2e-5, err_msg=f"instance {inst}")


@wp.kernel
def _corner_lookups(geo: Geometry, mesh: wp.array(dtype=int), tri: wp.array(dtype=int), uv: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    uv[i] = hit_uv(geo, mesh[i], tri[i], 0.25, 0.5)


def test_only_meshes_with_uvs_or_normals_hold_them_and_each_finds_its_own():
    rng = np.random.default_rng(11)
    meshes = [random_mesh(rng, 5, 1, "bare"), random_mesh(rng, 4, 1, "uv"), random_mesh(rng, 3, 1, "both")]
    meshes[1].uvs = rng.random((4, 3, 2)).astype(np.float32)
    meshes[2].uvs = rng.random((3, 3, 2)).astype(np.float32)
    meshes[2].normals = rng.normal(size=(3, 3, 3)).astype(np.float32)
    scene = Scene(meshes, [Instance(i, MotionTransform.static(np.eye(4))) for i in range(3)], [Material("m")], [],
                  Camera("cam", MotionTransform.static(np.eye(4))), Shutter(0, 0, 1))
    geo, _ = upload_geometry(scene)
    assert geo.mesh_uv_off.numpy().tolist() == [-1, 0, 12] and geo.uvs.shape[0] == 21
    assert geo.mesh_normal_off.numpy().tolist() == [-1, -1, 0] and geo.normals.shape[0] == 9
    np.testing.assert_array_equal(geo.normals.numpy(), meshes[2].normals.reshape(-1, 3))
    mesh = np.array([0, 1, 1, 2, 2], np.int32)
    tri = np.array([2, 5, 8, 9, 11], np.int32)  # global triangle indices (mesh offsets 0, 5, 9)
    uv = wp.zeros(len(mesh), dtype=wp.vec2)
    wp.launch(_corner_lookups, len(mesh), [geo, wp.array(mesh, dtype=int), wp.array(tri, dtype=int), uv])
    uv = uv.numpy()
    assert np.isnan(uv[0]).all()
    w = np.array([0.25, 0.25, 0.5])  # barycentrics (1 - b1 - b2, b1, b2)
    for i, (m, local) in enumerate([(1, 0), (1, 3), (2, 0), (2, 2)], start=1):
        np.testing.assert_allclose(uv[i], w @ meshes[m].uvs[local], rtol=1e-6)


def _probe(geo, scene, ro, rd, times):
    n = len(ro)
    outs = [wp.zeros(n, dtype=wp.float32), wp.zeros(n, dtype=wp.int32), wp.zeros(n, dtype=wp.int32),
            wp.zeros(n, dtype=wp.float32)]
    wp.launch(probe_kernel, dim=n, inputs=[geo, upload_materials(scene.materials),
                                           upload_material_textures(scene.materials), wp.array(ro, dtype=wp.vec3),
                                           wp.array(rd, dtype=wp.vec3), wp.array(times, dtype=wp.float32)] + outs)
    return [o.numpy() for o in outs]


def _rays(rng, n):
    ro = np.tile([0.0, 0.3, 8.0], (n, 1)) + rng.normal(0, 0.5, (n, 3))
    rd = rng.uniform([-4, -1.5, -4], [4, 1.5, 1], (n, 3)) - ro
    return ro, rd / np.linalg.norm(rd, axis=1, keepdims=True)


def _equals_top_level_walk_and_brute_force(scene, ro, rd, times):
    """Probe with the direct instance the upload chose, then with every instance in the top level: the same hits,
    triangles, distances and transmittance, bit for bit, and brute force's hits."""
    geo, _ = upload_geometry(scene)
    direct = _probe(geo, scene, ro, rd, times)
    from renderer.accel import upload
    chooser = upload.direct_instance
    upload.direct_instance = lambda *a: -1
    try:
        through_top = _probe(upload_geometry(scene)[0], scene, ro, rd, times)
    finally:
        upload.direct_instance = chooser
    for a, b in zip(direct, through_top):
        np.testing.assert_array_equal(a, b)
    t, inst, tri, tr = direct
    assert (inst >= 0).sum() > len(ro) // 4
    for i in range(0, len(ro), 5):
        bt, bi, btri = brute_force(scene, ro[i], rd[i], float(times[i]))
        assert inst[i] == bi and (bi < 0 or tri[i] == btri), i
    return geo, direct


@pytest.mark.parametrize("identity", [False, True])
def test_a_lone_still_instance_is_walked_without_the_top_level_and_finds_what_the_top_level_walk_finds(identity):
    """One still instance (every still scene, flattened): closest hits and shadows go straight to its mesh and the
    top level is not walked. A flattened scene's merged mesh is in world space: its rays skip the matrix."""
    rng = np.random.default_rng(11)
    scene = make_scene(rng)
    scene.instances = [Instance(0, MotionTransform.static(np.eye(4) if identity else rot_y(30, (0.5, 0, -1))))]
    ro, rd = _rays(rng, 400)
    geo, _ = _equals_top_level_walk_and_brute_force(scene, ro, rd, np.full(400, 0.3, np.float32))
    assert (geo.direct_inst, geo.tlas_others, geo.direct_identity) == (0, 0, int(identity))


def test_a_dominant_still_instance_is_walked_first_and_the_movers_through_the_top_level():
    """A large still instance (a floor and walls, merged) beside moving and time-limited ones: it is walked
    directly and left out of the top level, which holds the others; the same hits and shadows as with all of
    them in the top level, and as brute force, at random times."""
    rng = np.random.default_rng(5)
    scene = make_scene(rng)
    big = rot_y(0, (0, 0, -2))
    big[:3, :3] *= 6.0  # six times the others' size: its box outweighs all of theirs
    scene.instances = [scene.instances[1], scene.instances[3], Instance(0, MotionTransform.static(big)),
                       scene.instances[2]]
    ro, rd = _rays(rng, 600)
    geo, (_, inst, _, _) = _equals_top_level_walk_and_brute_force(scene, ro, rd,
                                                                  rng.uniform(0, 1, 600).astype(np.float32))
    assert (geo.direct_inst, geo.tlas_others) == (2, 3)
    assert sorted(set(geo.tlas_prim.numpy().tolist())) == [0, 1, 3]
    assert {0, 2, 3} <= set(inst.tolist())  # movers in front of it are found too


def test_no_instance_is_walked_directly_when_none_dominates_the_only_one_moves_or_lights_are_linked():
    rng = np.random.default_rng(3)
    scene = make_scene(rng)
    assert upload_geometry(scene)[0].direct_inst == -1  # five of similar size
    alone = Scene(scene.meshes, [scene.instances[0]], scene.materials, [], scene.camera, Shutter(0, 0, 1))
    assert upload_geometry(alone)[0].direct_inst == 0
    from renderer.scene.model import LIGHT_SPHERE, Light
    linked = Light(LIGHT_SPHERE, "key", (1.0, 1.0, 1.0), MotionTransform.static(np.eye(4)),
                   illuminates=np.array([True]))
    alone.lights = [linked]
    assert upload_geometry(alone)[0].direct_inst == -1  # the linked shadow walk goes through the top level only
    scene.instances = [scene.instances[1]]  # one, moving
    assert upload_geometry(scene)[0].direct_inst == -1


@wp.kernel
def _leaf_tests_kernel(v0: wp.array(dtype=wp.vec3), e1: wp.array(dtype=wp.vec3), e2: wp.array(dtype=wp.vec3),
                       first: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32),
                       ro: wp.array(dtype=wp.vec3), rd: wp.array(dtype=wp.vec3), tmax: wp.array(dtype=wp.float32),
                       native: wp.array(dtype=wp.vec4), scalar: wp.array(dtype=wp.vec4),
                       four_wrong: wp.array(dtype=wp.int32)):
    i = wp.tid()
    native[i] = leaf_closest(v0, e1, e2, first[i], count[i], ro[i], rd[i], tmax[i])
    best = wp.vec4(tmax[i], 0.0, 0.0, -1.0)  # the walk's loop before the leaf was vector code
    for k in range(count[i]):
        s = first[i] + k
        t, b1, b2 = triangle_hit_edges(v0[s], e1[s], e2[s], ro[i], rd[i], best[0])
        if t < best[0]:
            best = wp.vec4(t, b1, b2, float(k))
    scalar[i] = best
    # the any-hit walk's four at a time: each lane the scalar test's t at the same tmax (BIG past the count)
    four = leaf_four(v0, e1, e2, first[i], count[i], ro[i], rd[i], tmax[i])
    for k in range(4):
        want = float(3.4e38)
        if k < count[i]:
            s = first[i] + k
            want, b1, b2 = triangle_hit_edges(v0[s], e1[s], e2[s], ro[i], rd[i], tmax[i])
        if not (four[k] == want or (four[k] != four[k] and want != want)):  # NaN for NaN
            wp.atomic_add(four_wrong, 0, 1)


def test_a_still_leaf_tested_four_triangles_at_a_time_gives_the_scalar_loops_bits():
    """``leaf_closest`` and ``leaf_four`` (native vector code) against ``triangle_hit_edges`` in slot order, bit
    for bit (``leaf_four``: the same t as a number, BIG for a miss): leaves of
    1 to 15 triangles, rays through shared edges and vertices of a fan (ties between triangles), triangles seen
    edge-on and degenerate ones (det 0), parallel rays, hits at tmax and behind the origin, NaN rays."""
    rng = np.random.default_rng(21)
    tris = 6000
    v0 = rng.uniform(-1, 1, (tris, 3)).astype(np.float32)
    e1 = rng.uniform(-1, 1, (tris, 3)).astype(np.float32)
    e2 = rng.uniform(-1, 1, (tris, 3)).astype(np.float32)
    fan = np.arange(0, tris, 7)  # triangles sharing vertex 0 and an edge with the next slot: ties
    v0[fan[:-1] + 1] = v0[fan[:-1]]
    e1[fan[:-1] + 1] = e2[fan[:-1]]
    degenerate = rng.random(tris) < 0.05
    e2[degenerate] = 2.0 * e1[degenerate]
    n = 40000
    count = rng.integers(1, 16, n).astype(np.int32)
    first = rng.integers(0, tris - 15, n).astype(np.int32)
    ro = rng.uniform(-2, 2, (n, 3)).astype(np.float32)
    # aim at a point of the leaf's first triangle: at a vertex, on an edge or inside
    pick = rng.choice([0.0, 0.5, 1.0], size=(n, 2)) * (rng.random((n, 1)) < 0.3) + rng.random((n, 2)) * 0.5
    target = v0[first] + pick[:, :1] * e1[first] + pick[:, 1:] * e2[first]
    rd = (target - ro).astype(np.float32)
    rd[::13] = rng.normal(size=(len(rd[::13]), 3))  # random directions too
    rd[::29, 1:] = 0.0  # parallel to an axis
    ro[::501] = np.nan
    tmax = rng.choice(np.array([0.5, 1.0, 3.4e38], np.float32), size=n)
    a = [wp.array(x, dtype=wp.vec3) for x in (v0, e1, e2)]
    native, scalar = wp.zeros(n, dtype=wp.vec4), wp.zeros(n, dtype=wp.vec4)
    four_wrong = wp.zeros(1, dtype=wp.int32)
    wp.launch(_leaf_tests_kernel, dim=n, inputs=a + [wp.array(first, dtype=wp.int32), wp.array(count, dtype=wp.int32),
                                                   wp.array(ro, dtype=wp.vec3), wp.array(rd, dtype=wp.vec3),
                                                   wp.array(tmax, dtype=wp.float32), native, scalar, four_wrong])
    got, want = native.numpy(), scalar.numpy()
    hits = want[:, 3] >= 0
    assert 0.2 < hits.mean() < 0.9 and (want[hits, 3] > 0).sum() > 1000  # hits beyond the first lane too
    np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
    assert four_wrong.numpy()[0] == 0


@wp.kernel
def _segments(times: wp.array(dtype=wp.float32), offset: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32),
              s: wp.array(dtype=wp.float32), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    a, b, u = find_segment(times, offset[i], count[i], s[i])
    out[i] = wp.vec3(float(a), float(b), u)


def test_find_segment_brackets_the_time_by_the_first_key_at_or_after_it():
    """Keys and blend of a time among a thing's keys: uniform, uneven and repeated key times, one key, times at,
    between and outside the keys (outside: the end key, blend 0)."""
    rng = np.random.default_rng(3)
    spans = [np.linspace(0, 1, 9), np.linspace(-0.25, 1.25, 5), np.array([0.5]), np.array([0.0, 1.0]),
             np.array([0.0, 0.01, 0.02, 0.9, 1.0]), np.array([0.0, 0.5, 0.5, 0.5, 1.0]),
             np.sort(rng.uniform(0, 1, 30)), np.array([0.2, 0.3, 0.95])]
    times = np.concatenate(spans).astype(np.float32)
    offs = np.cumsum([0] + [len(k) for k in spans])[:-1]
    cases = []
    for off, k in zip(offs, spans):
        kt = times[off:off + len(k)]
        for s in np.concatenate([kt, (kt[:-1] + kt[1:]) / 2, rng.uniform(-0.5, 1.5, 40), [0.0, 1.0]]):
            cases.append((off, len(k), np.float32(s)))
    off, cnt, s = (np.array(c) for c in zip(*cases))
    out = wp.zeros(len(s), dtype=wp.vec3)
    wp.launch(_segments, dim=len(s), inputs=[wp.array(times), wp.array(off.astype(np.int32)),
                                             wp.array(cnt.astype(np.int32)), wp.array(s.astype(np.float32)), out])
    for (o, n, t), (a, b, u) in zip(cases, out.numpy()):
        kt = times[o:o + n]
        if n == 1 or t <= kt[0]:
            want = (o, o, 0.0)
        elif t >= kt[-1]:
            want = (o + n - 1, o + n - 1, 0.0)
        else:
            j = o + int(np.argmax(kt >= t))  # the first key at or after t
            span = np.float32(times[j] - times[j - 1])
            want = (j - 1, j, float(np.float32(t - times[j - 1]) / span) if span > 0 else 0.0)
        assert (int(a), int(b)) == want[:2], (o, n, t)
        assert u == pytest.approx(want[2], abs=1e-6)
