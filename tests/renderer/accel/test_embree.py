"""Embree as the bottom level of still triangle meshes (``renderer.accel.embree``): which meshes it answers for,
that it finds what our walk and brute force find, that its answers do not depend on how it was built, and the
ray interval and bad rays."""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from renderer.motion.shutter import Shutter
from renderer.accel import embree
from renderer.accel.upload import upload_geometry
from renderer.motion.transform import MotionTransform
from renderer.scene.model import Camera, Instance, Material, Mesh, Scene
from test_accel import _probe, brute_force, random_mesh, rot_y
from test_quads import hits

pytestmark = pytest.mark.skipif(embree.library() is None, reason="Embree (embreex) is not available")


def _scene(meshes, materials):
    insts = [Instance(i, MotionTransform.static(np.eye(4))) for i in range(len(meshes))]
    return Scene(meshes, insts, materials, [], Camera("cam", MotionTransform.static(np.eye(4))), Shutter(0, 0, 1))


def _without_embree(monkeypatch, scene):
    with monkeypatch.context() as m:
        m.setattr(embree, "library", lambda: None)
        return upload_geometry(scene)[0]


def _rays(rng, n):
    ro = np.tile([0.0, 0.3, 6.0], (n, 1)) + rng.normal(0, 0.5, (n, 3))
    rd = rng.uniform([-2, -2, -2], [2, 2, 1], (n, 3)) - ro
    return ro, rd / np.linalg.norm(rd, axis=1, keepdims=True)


def test_still_triangle_meshes_go_to_embree_and_it_finds_what_our_walk_and_brute_force_find(monkeypatch):
    """A still mesh is Embree's (closest hits, and shadows: its material is opaque), a deforming one stays ours;
    every ray finds the triangle brute force finds (but for near-ties), at the same distance, and the shadow
    answers are our walk's."""
    rng = np.random.default_rng(3)
    scene = _scene([random_mesh(rng, 3000, 1, "still"), random_mesh(rng, 300, 3, "deforming")], [Material("m")])
    geo, stats = upload_geometry(scene)
    assert list(geo.mesh_embree.numpy() != 0) == [True, False]
    assert list(geo.mesh_embree_shadow.numpy()) == [1, 0]
    assert stats.embree_nbytes > 3000 * 8 and stats.nbytes > stats.embree_nbytes
    ours = _without_embree(monkeypatch, scene)
    assert not ours.mesh_embree.numpy().any()
    n = 800
    ro, rd = _rays(rng, n)
    times = rng.uniform(0, 1, n).astype(np.float32)
    t, inst, tri, tr = _probe(geo, scene, ro, rd, times)
    t0, inst0, tri0, tr0 = _probe(ours, scene, ro, rd, times)
    assert (inst >= 0).sum() > n // 2
    np.testing.assert_array_equal(tr, tr0)  # opaque: 0 where anything is crossed, else 1
    same = (inst == inst0) & (tri == tri0)
    assert same.mean() > 0.99
    np.testing.assert_allclose(t[same & (inst >= 0)], t0[same & (inst >= 0)], rtol=1e-5)
    for i in range(n):
        bt, bi, btri = brute_force(scene, ro[i], rd[i], float(times[i]))
        if bi < 0:
            assert inst[i] < 0, i
            continue
        assert inst[i] >= 0, i
        np.testing.assert_allclose(t[i], bt, rtol=1e-4)
        if (inst[i], tri[i]) != (bi, btri):  # another triangle at the same distance (they cross there)
            assert abs(t[i] - bt) <= 1e-4 * bt, i


def test_meshes_embree_answers_upload_one_leaf_of_ours_and_rotated_instances_stay_tightly_placed():
    """Opaque still meshes: Embree answers every walk, so our uploaded tree of each is one leaf of one slot; the
    top level still places rotated instances from a cut of a full tree of ours (their boxes are no larger than
    with Embree off), and hits and shadows agree with brute force."""
    rng = np.random.default_rng(4)
    meshes = [random_mesh(rng, 500, 1, "a"), random_mesh(rng, 400, 1, "b")]
    insts = [Instance(0, MotionTransform.static(np.eye(4))),
             Instance(1, MotionTransform.static(rot_y(35, (3, 0, 0)))),
             Instance(1, MotionTransform.static(rot_y(-60, (-3, 0.5, 0))))]
    scene = _scene(meshes, [Material("m")])
    scene.instances = insts
    geo, stats = upload_geometry(scene)
    assert list(geo.mesh_embree_shadow.numpy()) == [1, 1]
    assert len(geo.blas_prim.numpy()) == 2 and len(geo.leaf_v0.numpy()) == 2
    from renderer.accel import upload
    with pytest.MonkeyPatch.context() as m:
        m.setattr(embree, "library", lambda: None)
        ours = upload.upload_geometry(scene)[0]
    np.testing.assert_array_equal(geo.tlas_box.numpy(), ours.tlas_box.numpy())  # the same instance boxes
    n = 400
    ro = np.tile([0.0, 0.3, 8.0], (n, 1)) + rng.normal(0, 0.5, (n, 3))
    rd = rng.uniform([-5, -1.5, -2], [5, 1.5, 1], (n, 3)) - ro
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    t, inst, tri, tr = _probe(geo, scene, ro, rd, np.zeros(n, np.float32))
    assert (inst >= 0).sum() > n // 4 and (inst >= 1).sum() > 20
    np.testing.assert_array_equal(tr, np.where(inst >= 0, 0.0, 1.0))
    for i in range(n):
        bt, bi, btri = brute_force(scene, ro[i], rd[i], 0.0)
        assert (inst[i] >= 0) == (bi >= 0), i
        if bi >= 0:
            np.testing.assert_allclose(t[i], bt, rtol=1e-4)


def test_partly_opaque_meshes_keep_our_shadow_walk():
    """Embree finds a sheet of opacity 0.5 for closest hits, but its shadow rays are ours: they pass half the
    light; an opaque sheet beside it blocks all."""
    quad = np.array([[[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]], np.float32)
    tris = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    half = Mesh("half", np.zeros(1, np.float32), quad, tris, np.zeros(2, np.int32))
    full = Mesh("full", np.zeros(1, np.float32), quad + np.float32([3, 0, 0]), tris, np.ones(2, np.int32))
    scene = _scene([half, full], [Material("half", opacity=0.5), Material("full")])
    geo, _ = upload_geometry(scene)
    assert (geo.mesh_embree.numpy() != 0).all()
    assert list(geo.mesh_embree_shadow.numpy()) == [0, 1]
    ro = np.array([[0.2, 0.1, 2.0], [3.2, 0.1, 2.0], [6.0, 0.0, 2.0]])
    rd = np.tile([0.0, 0.0, -1.0], (3, 1))
    t, inst, tri, tr = _probe(geo, scene, ro, rd, np.zeros(3, np.float32))
    assert list(inst) == [0, 1, -1]
    np.testing.assert_allclose(t[:2], 2.0)
    np.testing.assert_allclose(tr, [0.5, 0.0, 1.0])


@wp.kernel
def _closest_kernel(fn: wp.uint64, scene: wp.uint64, ro: wp.array(dtype=wp.vec3), rd: wp.array(dtype=wp.vec3),
                    tmax: wp.array(dtype=float), out: wp.array(dtype=embree.embree_hit_t), occluded: wp.array(dtype=int),
                    occluded_fn: wp.uint64):
    i = wp.tid()
    out[i] = embree.embree_closest(fn, scene, ro[i], rd[i], tmax[i])
    occluded[i] = embree.embree_occluded(occluded_fn, scene, ro[i], rd[i], tmax[i])


def _trace(scenes, handle, ro, rd, tmax):
    n = len(ro)
    out, occ = wp.zeros(n, dtype=embree.embree_hit_t), wp.zeros(n, dtype=int)
    wp.launch(_closest_kernel, dim=n, inputs=[wp.uint64(scenes.closest_fn), wp.uint64(handle),
                                              wp.array(ro, dtype=wp.vec3), wp.array(rd, dtype=wp.vec3),
                                              wp.array(tmax, dtype=float), out, occ, wp.uint64(scenes.occluded_fn)])
    return out.numpy(), occ.numpy()


def test_hits_do_not_depend_on_the_builders_threads():
    """Every process builds its own trees (the service's workers, a resumed job): one thread and two give the same
    bits, so tiles traced in different processes fit together."""
    rng = np.random.default_rng(9)
    mesh = random_mesh(rng, 20000)
    ro, rd = _rays(rng, 20000)
    tmax = np.full(len(ro), 1e30, np.float32)
    results = []
    for threads in (1, 2, 1):
        scenes = embree.EmbreeScenes(embree.library(), threads=threads)
        handle, _ = scenes.add_mesh(mesh.points[0], mesh.triangles)
        assert handle != 0
        results.append(_trace(scenes, handle, ro, rd, tmax))
        scenes.close()
    assert (results[0][0][:, 3] >= 0).sum() > len(ro) // 2
    for r in results[1:]:
        np.testing.assert_array_equal(r[0], results[0][0])
        np.testing.assert_array_equal(r[1], results[0][1])


def test_the_interval_is_open_and_bad_rays_miss():
    """(0, tmax) as our triangle test has it: a hit exactly at tmax or at the origin is not one; a ray with a NaN
    or infinite coordinate, or an empty interval, misses instead of reaching Embree."""
    quad = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    scenes = embree.EmbreeScenes(embree.library())
    handle, codes = scenes.add_mesh(quad, np.array([[0, 1, 2], [0, 2, 3]]))  # int64 indices: converted
    assert handle != 0 and list(codes) == [0]  # one run of two triangles (not laid out in pairs)
    assert scenes.add_mesh(quad, np.array([[0, 1, 4]])) == (0, None)  # an index past the vertices: refused
    down = [0.0, 0.0, -1.0]
    ro = np.array([[0.3, 0.2, 1.0], [0.3, 0.2, 1.0], [0.3, 0.2, 0.0], [np.nan, 0, 1], [0.3, 0.2, np.inf],
                   [0.3, 0.2, 1.0], [0.3, 0.2, 1.0]])
    rd = np.array([down] * 7)
    tmax = np.array([1.0, np.nextafter(np.float32(1), np.float32(2)), 5.0, 5.0, 5.0, 0.0, np.inf], np.float32)
    hits, occ = _trace(scenes, handle, ro, rd, tmax)
    assert list(hits[:, 3] >= 0) == [False, True, False, False, False, False, True]  # an endless ray hits too
    assert list(occ) == [0, 1, 0, 0, 0, 0, 1]
    assert hits[1, 0] == 1.0 and hits[1, 3] in (0, 1) and hits[1, 7] == 0
    np.testing.assert_allclose(hits[1, 1] + hits[1, 2] <= 1.0, True)
    scenes.close()


def test_drt_embree_0_turns_it_off(monkeypatch):
    monkeypatch.setattr(embree, "_lib", False)
    monkeypatch.setenv("DRT_EMBREE", "0")
    assert embree.library() is None
    rng = np.random.default_rng(1)
    geo, stats = upload_geometry(_scene([random_mesh(rng, 50)], [Material("m")]))
    assert not geo.mesh_embree.numpy().any() and stats.embree_nbytes == 0
    monkeypatch.setattr(embree, "_lib", False)
    monkeypatch.delenv("DRT_EMBREE")
    assert embree.library() is not None


def test_embrees_normal_of_the_hit_is_the_one_from_the_corners(monkeypatch):
    """Embree hands back the hit triangle's (p1 - p0) x (p2 - p0), which ``surface_at`` uses for a mesh without
    uvs instead of reading the corners: the same facing normal (up to rounding) and the same side (front or back,
    what a solid's inside depends on) as from the corners, through a rotated, scaled instance too; our own walk
    leaves no stale normal of an Embree hit it overrides."""
    rng = np.random.default_rng(5)
    still = random_mesh(rng, 2000, 1, "still")
    deforming = random_mesh(rng, 200, 3, "deforming")  # walked by us, beside Embree's
    scale = np.diag([1.5, 0.7, 1.0, 1.0]) @ rot_y(35, (0.2, 0, 0))
    scene = Scene([still, deforming], [Instance(0, MotionTransform.static(scale)),
                                       Instance(1, MotionTransform.static(np.eye(4)))],
                  [Material("m")], [], Camera("cam", MotionTransform.static(np.eye(4))), Shutter(0, 0, 1))
    geo, _ = upload_geometry(scene)
    assert list(geo.mesh_embree.numpy() != 0) == [True, False]
    n = 3000
    ro, rd = _rays(rng, n)
    _, _, normals, fronts = hits(geo, ro, rd)
    a, b, hit_ng = normals[:, 0], normals[:, 1], normals[:, 2]
    hit = np.linalg.norm(b, axis=1) > 0
    by_embree = np.linalg.norm(hit_ng, axis=1) > 0
    assert hit.sum() > n // 2 and by_embree.sum() > n // 4 and (hit & ~by_embree).sum() > 50  # both walks hit
    np.testing.assert_allclose(a[hit], b[hit], atol=2e-5)
    np.testing.assert_array_equal(fronts[hit, 0], fronts[hit, 1])
    assert 0.2 < fronts[hit, 0].mean() < 0.8  # both sides seen
