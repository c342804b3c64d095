"""Triangles paired into quads for Embree (``renderer.accel.quads``): which triangles pair, that each quad's halves
are its triangles' own corners, that a hit's quad parameters map back to the right triangle and barycentrics, and
that Embree holding quads finds what our walk finds on a real (connected, curved) mesh."""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from renderer.accel import embree
from renderer.accel.intersect import Geometry, intersect_closest
from renderer.accel.quads import pair_triangles, quad_triangle
from renderer.accel.upload import upload_geometry
from renderer.integrator import surface_at
from renderer.scene.model import Camera, Instance, Material, Mesh, MotionTransform, Scene
from tests.test_accel import rot_y


def bumpy_grid(rng, nx=40, ny=30, flip=None):
    """A height field over [-1, 1]^2, each cell split along a random diagonal, wound counter-clockwise seen
    from +z. ``flip``: indices of triangles whose winding is reversed."""
    x, y = np.meshgrid(np.linspace(-1, 1, nx + 1), np.linspace(-1, 1, ny + 1), indexing="ij")
    z = 0.15 * np.sin(3 * x) * np.cos(2 * y) + rng.normal(0, 0.002, x.shape)
    pts = np.stack([x, y, z], -1).reshape(-1, 3).astype(np.float32)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b, c, d = a + (ny + 1), a + (ny + 1) + 1, a + 1  # a=(i,j) b=(i+1,j) c=(i+1,j+1) d=(i,j+1)
    diag = rng.random(len(a)) < 0.5
    t1 = np.where(diag[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    t2 = np.where(diag[:, None], np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    tris = np.concatenate([t1, t2]).astype(np.int32)
    tris = tris[rng.permutation(len(tris))]  # a pair's triangles far apart in the list
    if flip is not None:
        tris[flip] = tris[flip][:, ::-1]
    return pts, tris


def _check_halves(tris, quads, codes):
    """Each quad's first half (v0, v1, v3) and second (v2, v3, v1) are the coded triangle's corners k + 2, k, k + 1
    (a lone triangle's second half degenerate: v3 == v2); every triangle is in exactly one half."""
    for half, cols in ((0, [0, 1, 3]), (1, [2, 3, 1])):
        t, k = codes[:, half] >> 2, codes[:, half] & 3
        lone = codes[:, 0] == codes[:, 1]
        rot = tris[t[:, None], (k[:, None] + np.array([2, 0, 1])) % 3]
        want = quads[:, cols]
        if half == 1:
            np.testing.assert_array_equal(quads[lone, 2], quads[lone, 3])
            rot, want = rot[~lone], want[~lone]
        np.testing.assert_array_equal(rot, want)
    lone = codes[:, 0] == codes[:, 1]
    listed = np.concatenate([codes[:, 0] >> 2, codes[~lone, 1] >> 2])
    np.testing.assert_array_equal(np.sort(listed), np.arange(len(tris)))


def test_a_triangulated_grid_pairs_every_triangle_with_its_cells_other_half():
    rng = np.random.default_rng(1)
    pts, tris = bumpy_grid(rng)
    quads, codes = pair_triangles(pts, tris)
    assert quads.dtype == np.uint32 and codes.dtype == np.int32
    assert len(quads) == len(tris) // 2  # every cell's diagonal is both its triangles' longest edge
    _check_halves(tris, quads, codes)
    # each quad is a grid cell: four distinct corners
    assert all(len(set(q)) == 4 for q in quads.tolist())
    again = pair_triangles(pts, tris)
    np.testing.assert_array_equal(again[0], quads)
    np.testing.assert_array_equal(again[1], codes)


def test_only_consistently_wound_edges_of_exactly_two_triangles_pair():
    """A neighbour wound the other way, a third triangle on the edge, a degenerate triangle and a soup stay
    alone, as quads (t0, t1, t2, t2)."""
    rng = np.random.default_rng(2)
    pts, tris = bumpy_grid(rng, 12, 10, flip=np.arange(0, 240, 7))
    quads, codes = pair_triangles(pts, tris)
    _check_halves(tris, quads, codes)
    lone = codes[:, 0] == codes[:, 1]
    flipped = np.zeros(len(tris), bool)
    flipped[np.arange(0, 240, 7)] = True
    pairs = codes[~lone] >> 2
    assert len(pairs) > 80
    np.testing.assert_array_equal(flipped[pairs[:, 0]], flipped[pairs[:, 1]])  # never one of each
    assert not flipped[pairs[:, 0]].all()
    # a fin: three triangles on the edge 0-1; a degenerate triangle; a soup of separate triangles
    p = np.array([[0, 0, 0], [2, 0, 0], [1, 1, 0], [1, -1, 0], [1, 0, 1], [5, 5, 5]], np.float32)
    fin = np.array([[0, 1, 2], [1, 0, 3], [1, 0, 4], [0, 5, 5]])
    quads, codes = pair_triangles(p, fin)
    assert len(quads) == 4 and (codes[:, 0] == codes[:, 1]).all()
    np.testing.assert_array_equal(quads, fin[:, [0, 1, 2, 2]])
    np.testing.assert_array_equal(codes[:, 0], np.arange(4) * 4 + 1)
    soup = np.arange(30).reshape(10, 3)
    quads, codes = pair_triangles(rng.normal(size=(30, 3)), soup)
    assert len(quads) == 10
    assert pair_triangles(np.zeros((0, 3)), np.zeros((0, 3), np.int32))[0].shape == (0, 4)


@wp.kernel
def _map_kernel(codes: wp.array(dtype=wp.int32), quad: wp.array(dtype=int), uv: wp.array(dtype=wp.vec2),
                out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    tri, b1, b2 = quad_triangle(codes, 0, quad[i], uv[i][0], uv[i][1])
    out[i] = wp.vec3(float(tri), b1, b2)


def test_a_quads_parameters_map_to_the_point_on_the_right_triangle():
    """Points on either half of every quad, given as Embree reports them (the quad's (u, v): the first half's
    barycentrics, or one minus the second's): the triangle found and its barycentrics give the same point, and the
    point is on that triangle."""
    rng = np.random.default_rng(3)
    pts, tris = bumpy_grid(rng, 10, 8)
    quads, codes = pair_triangles(pts, tris)
    n = 4000
    q = rng.integers(0, len(quads), n)
    s, t = rng.random(n), rng.random(n)
    s, t = np.where(s + t > 1, 1 - s, s), np.where(s + t > 1, 1 - t, t)  # uniform on a triangle
    second = rng.random(n) < 0.5
    corners = np.where(second[:, None, None], pts[quads[q][:, [2, 3, 1]]], pts[quads[q][:, [0, 1, 3]]])
    point = (1 - s - t)[:, None] * corners[:, 0] + s[:, None] * corners[:, 1] + t[:, None] * corners[:, 2]
    uv = np.where(second[:, None], np.stack([1 - s, 1 - t], 1), np.stack([s, t], 1)).astype(np.float32)
    out = wp.zeros(n, dtype=wp.vec3)
    wp.launch(_map_kernel, dim=n, inputs=[wp.array(codes.ravel(), dtype=wp.int32), wp.array(q, dtype=int),
                                          wp.array(uv, dtype=wp.vec2), out])
    out = out.numpy()
    tri, b1, b2 = out[:, 0].astype(int), out[:, 1], out[:, 2]
    want = np.where(second, codes[q, 1] >> 2, codes[q, 0] >> 2)
    np.testing.assert_array_equal(tri, want)
    c = pts[tris[tri]]
    mapped = (1 - b1 - b2)[:, None] * c[:, 0] + b1[:, None] * c[:, 1] + b2[:, None] * c[:, 2]
    np.testing.assert_allclose(mapped, point, atol=1e-6)
    assert (b1 >= -1e-6).all() and (b2 >= -1e-6).all() and (b1 + b2 <= 1 + 1e-6).all()


@wp.kernel
def _hit_kernel(geo: Geometry, ro: wp.array(dtype=wp.vec3), rd: wp.array(dtype=wp.vec3),
                tbb: wp.array(dtype=wp.vec3), ids: wp.array(dtype=wp.vec2i), normals: wp.array(dtype=wp.vec3),
                fronts: wp.array(dtype=wp.vec2i)):
    i = wp.tid()
    hit = intersect_closest(geo, ro[i], rd[i], 1.0e30, 0.5)
    tbb[i] = wp.vec3(hit.t, hit.b1, hit.b2)
    ids[i] = wp.vec2i(hit.inst, hit.tri)
    if hit.inst >= 0:
        a = surface_at(geo, hit.inst, hit.tri, hit.b1, hit.b2, hit.ng, ro[i], rd[i], hit.t, 0.5)
        b = surface_at(geo, hit.inst, hit.tri, hit.b1, hit.b2, wp.vec3(0.0), ro[i], rd[i], hit.t, 0.5)
        normals[2 * i] = a.ng
        normals[2 * i + 1] = b.ng
        fronts[i] = wp.vec2i(a.front, b.front)


def _hits(geo, ro, rd):
    n = len(ro)
    outs = [wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec2i), wp.zeros(2 * n, dtype=wp.vec3),
            wp.zeros(n, dtype=wp.vec2i)]
    wp.launch(_hit_kernel, dim=n, inputs=[geo, wp.array(ro, dtype=wp.vec3), wp.array(rd, dtype=wp.vec3)] + outs)
    tbb, ids, normals, fronts = (o.numpy() for o in outs)
    return tbb, ids, normals.reshape(n, 2, 3), fronts


@pytest.mark.skipif(embree.library() is None, reason="Embree (embreex) is not available")
def test_embree_holding_quads_finds_the_triangle_point_and_side_our_walk_finds(monkeypatch):
    """A curved grid, some triangles wound the other way, through a rotated, scaled instance and a plain one: the
    same triangle as our walk (but for ties on shared edges, at the same distance), the same barycentrics, the
    same facing normal from Embree's hit as from the corners and the same side, and the same shadow answers."""
    from tests.test_accel import _probe

    rng = np.random.default_rng(4)
    pts, tris = bumpy_grid(rng, 30, 24, flip=np.arange(5, 1440, 11))
    mesh = Mesh("grid", np.zeros(1, np.float32), pts[None], tris, np.zeros(len(tris), np.int32))
    place = np.diag([1.5, 0.7, 1.0, 1.0]) @ rot_y(35, (0.2, 0, 0))
    scene = Scene([mesh], [Instance(0, MotionTransform.static(place)),
                           Instance(0, MotionTransform.static(rot_y(0, (0.5, 0.3, -1.0))))],
                  [Material("m")], [], Camera("cam", MotionTransform.static(np.eye(4))), 0, 0, 1)
    geo, stats = upload_geometry(scene)
    assert geo.mesh_embree.numpy()[0] != 0 and geo.mesh_embree_quad_off.numpy()[0] == 0
    assert len(geo.embree_quad_codes.numpy()) < 1.2 * len(tris)  # two codes per quad: most are pairs
    with monkeypatch.context() as m:
        m.setattr(embree, "library", lambda: None)
        ours = upload_geometry(scene)[0]
    n = 4000
    ro = np.tile([0.0, 0.0, 4.0], (n, 1)) + rng.normal(0, 0.3, (n, 3))
    rd = rng.uniform([-1.5, -1.2, -1.5], [1.5, 1.2, 0.5], (n, 3)) - ro
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    tbb, ids, normals, fronts = _hits(geo, ro, rd)
    tbb0, ids0, normals0, fronts0 = _hits(ours, ro, rd)
    hit = ids[:, 0] >= 0
    np.testing.assert_array_equal(hit, ids0[:, 0] >= 0)
    assert hit.sum() > n // 2
    np.testing.assert_allclose(tbb[hit, 0], tbb0[hit, 0], rtol=1e-5)
    same = hit & (ids == ids0).all(1)
    assert same.sum() > 0.99 * hit.sum()
    np.testing.assert_allclose(tbb[same, 1:], tbb0[same, 1:], atol=2e-5)
    np.testing.assert_allclose(normals[hit, 0], normals[hit, 1], atol=2e-5)  # Embree's normal, the corners'
    np.testing.assert_allclose(normals[same, 1], normals0[same, 1], atol=2e-5)
    np.testing.assert_array_equal(fronts[hit, 0], fronts[hit, 1])
    np.testing.assert_array_equal(fronts[same], fronts0[same])
    assert 0.02 < fronts[hit, 0].mean() < 0.98  # both sides seen: the flipped triangles face away
    times = np.full(n, 0.5, np.float32)
    np.testing.assert_array_equal(_probe(geo, scene, ro, rd, times)[3], _probe(ours, scene, ro, rd, times)[3])
