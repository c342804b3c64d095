"""Triangles laid out in pairs for Embree's quads (``renderer.accel.quads``): which triangles pair, that the layout
keeps the surface, its per-corner data and the mesh lights' ranges, that the runs found read as quads made of the
mesh's own triangles, that a hit's quad parameters map back to the right triangle and barycentrics, and that
Embree holding quads finds what our walk finds on a real (connected, curved) mesh, in less memory."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import warp as wp

from renderer.motion.shutter import Shutter
from renderer.accel import embree
from renderer.accel.intersect import Geometry, intersect_closest
from renderer.accel.quads import embree_triangle, order_for_quads, quad_order, quad_runs, reorder_mesh
from renderer.accel.surface import surface_at
from renderer.accel.upload import upload_geometry
from renderer.motion.transform import MotionTransform
from renderer.scene.model import LIGHT_MESH, Camera, Instance, Light, Material, Mesh, Scene
from test_accel import rot_y


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


def _canonical(tris):
    """Each triangle as the rotation of its corners that starts at its smallest index: equal rows are the same
    triangle, wound the same way."""
    tris = np.asarray(tris)
    r = tris.argmin(1)[:, None]
    return tris[np.arange(len(tris))[:, None], (r + np.arange(3)) % 3]


def _same_triangles(a, b):
    np.testing.assert_array_equal(np.unique(_canonical(a), axis=0), np.unique(_canonical(b), axis=0))


def _check_runs(tris, runs):
    """The runs cover the triangles in order, and each quad read as Embree reads it, (v0, v1, v2, v3) from the
    pair's second index, has halves (v0, v1, v3) and (v2, v3, v1) that are the pair's triangles as stored, up to
    rotation."""
    t = 0
    flat = np.asarray(tris).reshape(-1)
    for first, count, is_quad in runs:
        assert first == t and count > 0
        if is_quad:
            for q in range(count):
                v = flat[3 * (first + 2 * q) + 1:3 * (first + 2 * q) + 5]
                np.testing.assert_array_equal(_canonical(v[[0, 1, 3]][None]), _canonical(tris[first + 2 * q][None]))
                np.testing.assert_array_equal(_canonical(v[[2, 3, 1]][None]),
                                              _canonical(tris[first + 2 * q + 1][None]))
            t += 2 * count
        else:
            t += count
    assert t == len(tris)


def test_a_triangulated_grid_is_laid_out_as_one_run_of_quads_with_its_corner_data():
    rng = np.random.default_rng(1)
    pts, tris = bumpy_grid(rng)
    order, shift = quad_order(pts, tris)
    np.testing.assert_array_equal(np.sort(order), np.arange(len(tris)))
    uvs = pts[tris][:, :, :2].copy()  # per-corner data: the corner's own x, y
    mesh = Mesh("grid", np.zeros(1, np.float32), pts[None], tris, np.arange(len(tris), dtype=np.int32), uvs=uvs,
                solid=np.arange(len(tris)) % 2 == 0)
    out = reorder_mesh(mesh, order, shift)
    _same_triangles(out.triangles, tris)
    np.testing.assert_array_equal(out.uvs, pts[out.triangles][:, :, :2])  # each corner kept its data
    np.testing.assert_array_equal(_canonical(out.triangles), _canonical(tris[out.material_ids]))
    np.testing.assert_array_equal(out.solid, mesh.solid[out.material_ids])
    runs = quad_runs(out.triangles)
    assert runs == [(0, len(tris) // 2, True)]  # every cell's diagonal is both its triangles' longest edge
    _check_runs(out.triangles, runs)
    again = quad_order(pts, tris)
    np.testing.assert_array_equal(again[0], order)
    np.testing.assert_array_equal(again[1], shift)


def test_only_consistently_wound_edges_of_exactly_two_triangles_in_one_range_pair():
    """A neighbour wound the other way, a third triangle on the edge, a degenerate triangle and a soup stay alone;
    no pair reaches across a cut, and every triangle stays in its range."""
    rng = np.random.default_rng(2)
    flip = np.zeros(240, bool)
    flip[np.arange(0, 240, 7)] = True
    pts, tris = bumpy_grid(rng, 12, 10, flip=np.nonzero(flip)[0])
    cuts = (50, 131)
    order, shift = quad_order(pts, tris, cuts)
    out = tris[order[:, None], (np.arange(3)[None] + shift[:, None]) % 3]
    for lo, hi in ((0, 50), (50, 131), (131, 240)):
        assert ((order[lo:hi] >= lo) & (order[lo:hi] < hi)).all()
    runs = quad_runs(out)
    _check_runs(out, runs)
    pairs = [(order[f + 2 * q], order[f + 2 * q + 1]) for f, c, quad in runs if quad for q in range(c)]
    assert len(pairs) > 20  # the grid is shuffled: many partners lie in another range
    for i, j in pairs:
        assert flip[i] == flip[j]  # never one of each winding
        assert np.searchsorted(cuts, i, "right") == np.searchsorted(cuts, j, "right")
    assert not all(flip[i] for i, _ in pairs)
    # a fin: three triangles on the edge 0-1; a degenerate triangle
    p = np.array([[0, 0, 0], [2, 0, 0], [1, 1, 0], [1, -1, 0], [1, 0, 1], [5, 5, 5]], np.float32)
    fin = np.array([[0, 1, 2], [1, 0, 3], [1, 0, 4], [0, 5, 5]])
    order, shift = quad_order(p, fin)
    np.testing.assert_array_equal(order, np.arange(4))
    np.testing.assert_array_equal(shift, 0)
    assert quad_runs(fin) == [(0, 4, False)]
    soup = np.arange(30).reshape(10, 3)
    assert quad_runs(soup[quad_order(rng.normal(size=(30, 3)), soup)[0]]) == [(0, 10, False)]
    assert quad_runs(np.zeros((0, 3), np.int32)) == []


def test_runs_are_found_leftmost_wherever_pairs_stand():
    """Pairs of the layout's shape between lone triangles, and three shapes in a row (two overlapping pairs):
    the runs are right quads, found leftmost first."""
    a = [[13, 10, 11], [12, 13, 11]]  # the quad (10, 11, 12, 13)
    b = [[23, 20, 21], [22, 23, 21]]
    lone = [[0, 1, 2]]
    tris = np.array(lone + a + b + lone + lone + a, np.int32)
    runs = quad_runs(tris)
    assert runs == [(0, 1, False), (1, 2, True), (5, 2, False), (7, 1, True)]
    _check_runs(tris, runs)
    near = np.array([[3, 0, 1], [2, 3, 5], [3, 0, 1], [3, 2, 1]], np.int32)  # one shared corner, or reversed
    assert quad_runs(near) == [(0, 4, False)]
    # a fan around corner 1: every neighbour has the shape, so the pairs are (0, 1) and (2, 3), not (1, 2)
    chain = np.array([[3, 0, 1], [2, 3, 1], [4, 2, 1], [5, 4, 1]], np.int32)
    runs = quad_runs(chain)
    assert runs == [(0, 2, True)]
    _check_runs(chain, runs)


def test_mesh_lights_keep_their_triangles():
    """A mesh light's range holds the same triangles after the layout (the light samples them by index); the
    layout changes no other mesh (a deforming one) and not the scene it was given."""
    rng = np.random.default_rng(6)
    pts, tris = bumpy_grid(rng, 10, 10)
    still = Mesh("grid", np.zeros(1, np.float32), pts[None], tris, np.zeros(len(tris), np.int32))
    moving = Mesh("moving", np.array([0, 1], np.float32), np.stack([pts, pts + 0.1]), tris,
                  np.zeros(len(tris), np.int32))
    lights = [Light(LIGHT_MESH, "glow", (1, 1, 1), MotionTransform.static(np.eye(4)), instance=0,
                    triangles=(37, 121))]
    scene = Scene([still, moving], [Instance(0, MotionTransform.static(np.eye(4))),
                                    Instance(1, MotionTransform.static(np.eye(4)))],
                  [Material("m")], lights, Camera("cam", MotionTransform.static(np.eye(4))), Shutter(0, 0, 1))
    out = order_for_quads(scene, min_triangles=2)
    assert scene.meshes[0] is still and out.meshes[1] is moving
    assert order_for_quads(scene).meshes[0] is still  # below the size where quads pay
    for lo, hi in ((0, 37), (37, 121), (121, len(tris))):
        _same_triangles(out.meshes[0].triangles[lo:hi], tris[lo:hi])
    assert sum(c for _, c, q in quad_runs(out.meshes[0].triangles) if q) > 0.2 * len(tris)  # pairs (shuffled)


@wp.kernel
def _map_kernel(geoms: wp.array(dtype=wp.int32), geom: wp.array(dtype=int), prim: wp.array(dtype=int),
                uv: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    tri, b1, b2 = embree_triangle(geoms, 0, geom[i], prim[i], uv[i][0], uv[i][1])
    out[i] = wp.vec3(float(tri), b1, b2)


def test_a_quads_parameters_map_to_the_point_on_the_right_triangle():
    """Points on either half of every quad and on every lone triangle, given as Embree reports them (a quad's
    (u, v): the first half's barycentrics, or one minus the second's): the triangle found and its barycentrics
    give the same point, and the point is on that triangle."""
    rng = np.random.default_rng(3)
    pts, tris = bumpy_grid(rng, 10, 8, flip=np.arange(0, 160, 9))
    order, shift = quad_order(pts, tris)
    tris = tris[order[:, None], (np.arange(3)[None] + shift[:, None]) % 3]
    runs = quad_runs(tris)
    assert any(q for *_, q in runs) and not all(q for *_, q in runs)
    codes = np.array([2 * f + int(q) for f, _, q in runs], np.int32)
    flat = tris.reshape(-1)
    geom, prim, uv, point, want = [], [], [], [], []
    for g, (first, count, is_quad) in enumerate(runs):
        for p in range(count):
            for _ in range(8):
                s, t = rng.random(2)
                s, t = (1 - s, 1 - t) if s + t > 1 else (s, t)
                if is_quad:
                    v = pts[flat[3 * (first + 2 * p) + 1:3 * (first + 2 * p) + 5]]
                    second = rng.random() < 0.5
                    c = v[[2, 3, 1]] if second else v[[0, 1, 3]]
                    uv.append((1 - s, 1 - t) if second else (s, t))
                    want.append(first + 2 * p + int(second))
                else:
                    c = pts[tris[first + p]]
                    uv.append((s, t))
                    want.append(first + p)
                geom.append(g)
                prim.append(p)
                point.append((1 - s - t) * c[0] + s * c[1] + t * c[2])
    n = len(geom)
    out = wp.zeros(n, dtype=wp.vec3)
    wp.launch(_map_kernel, dim=n, inputs=[wp.array(codes, dtype=wp.int32), wp.array(geom, dtype=int),
                                          wp.array(prim, dtype=int), wp.array(np.array(uv, np.float32),
                                                                              dtype=wp.vec2), out])
    out = out.numpy()
    tri, b1, b2 = out[:, 0].astype(int), out[:, 1], out[:, 2]
    np.testing.assert_array_equal(tri, want)
    c = pts[tris[tri]]
    mapped = (1 - b1 - b2)[:, None] * c[:, 0] + b1[:, None] * c[:, 1] + b2[:, None] * c[:, 2]
    np.testing.assert_allclose(mapped, np.array(point), atol=1e-6)
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
        normals[3 * i] = a.ng
        normals[3 * i + 1] = b.ng
        normals[3 * i + 2] = hit.ng
        fronts[i] = wp.vec2i(a.front, b.front)


def hits(geo, ro, rd):
    """Per ray: (t, b1, b2), (instance, triangle), the facing normals ``surface_at`` gives with the hit's normal
    (Embree's) and from the corners, and the hit's normal (zero from our walks), and the two sides (front or
    back) they give."""
    n = len(ro)
    outs = [wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec2i), wp.zeros(3 * n, dtype=wp.vec3),
            wp.zeros(n, dtype=wp.vec2i)]
    wp.launch(_hit_kernel, dim=n, inputs=[geo, wp.array(ro, dtype=wp.vec3), wp.array(rd, dtype=wp.vec3)] + outs)
    tbb, ids, normals, fronts = (o.numpy() for o in outs)
    return tbb, ids, normals.reshape(n, 3, 3), fronts


@pytest.mark.skipif(embree.library() is None, reason="Embree (embreex) is not available")
def test_embree_holding_quads_finds_the_triangle_point_and_side_our_walk_finds(monkeypatch):
    """A curved grid laid out in pairs, some triangles wound the other way (left alone), through a rotated, scaled
    instance and a plain one: the same triangle as our walk (but for ties on shared edges, at the same distance),
    the same barycentrics, the same facing normal from Embree's hit as from the corners and the same side, the
    same shadow answers; and Embree's share of the memory below what it takes for the triangles unpaired."""
    from test_accel import _probe

    rng = np.random.default_rng(4)
    pts, tris = bumpy_grid(rng, 30, 24, flip=np.arange(5, 1440, 11))
    mesh = Mesh("grid", np.zeros(1, np.float32), pts[None], tris, np.zeros(len(tris), np.int32))
    place = np.diag([1.5, 0.7, 1.0, 1.0]) @ rot_y(35, (0.2, 0, 0))
    unordered = Scene([mesh], [Instance(0, MotionTransform.static(place)),
                               Instance(0, MotionTransform.static(rot_y(0, (0.5, 0.3, -1.0))))],
                      [Material("m")], [], Camera("cam", MotionTransform.static(np.eye(4))), Shutter(0, 0, 1))
    scene = order_for_quads(unordered, min_triangles=2)
    geo, stats = upload_geometry(scene)
    assert geo.mesh_embree.numpy()[0] != 0
    codes = geo.embree_geoms.numpy()
    assert 1 < len(codes) <= 2 and codes[0] == 1  # a run of quads from triangle 0, then the lone triangles
    # a sixth of the triangles left alone (the flipped ones and their neighbours): less memory all the same, and
    # the unordered mesh, whose neighbours have the pair's shape here and there by chance, stays triangles
    plain_geo, plain = upload_geometry(unordered)
    assert list(plain_geo.embree_geoms.numpy()) == [0] and stats.embree_nbytes < plain.embree_nbytes
    clean = replace(mesh, triangles=bumpy_grid(np.random.default_rng(4), 30, 24)[1])
    clean_scene = replace(unordered, meshes=[clean])
    assert (upload_geometry(order_for_quads(clean_scene, min_triangles=2))[1].embree_nbytes
            < 0.8 * upload_geometry(clean_scene)[1].embree_nbytes)  # every triangle paired
    with monkeypatch.context() as m:
        m.setattr(embree, "library", lambda: None)
        ours = upload_geometry(scene)[0]
    n = 4000
    ro = np.tile([0.0, 0.0, 4.0], (n, 1)) + rng.normal(0, 0.3, (n, 3))
    rd = rng.uniform([-1.5, -1.2, -1.5], [1.5, 1.2, 0.5], (n, 3)) - ro
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    tbb, ids, normals, fronts = hits(geo, ro, rd)
    tbb0, ids0, normals0, fronts0 = hits(ours, ro, rd)
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


def _grid_mesh(stage, path, n, half, y, mat, down, lone=False):
    """An n x n grid of quads over [-half, half]^2 at height y, its front facing down (-Y) or up; ``lone``: and
    a triangle beside it, which pairs with nothing."""
    from pxr import Gf, UsdGeom, UsdShade, Vt

    xs = np.linspace(-half, half, n + 1)
    pts = [Gf.Vec3f(float(x), y, float(z)) for x in xs for z in xs]
    faces = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1
            faces += [a, b, c, d] if down else [a, d, c, b]
    counts = [4] * (n * n)
    if lone:
        pts += [Gf.Vec3f(half + 0.1, y, 0.0), Gf.Vec3f(half + 1.1, y, 0.0), Gf.Vec3f(half + 0.1, y, 1.0)]
        v = len(pts) - 3
        faces += [v, v + 1, v + 2] if down else [v, v + 2, v + 1]
        counts.append(3)
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray(pts))
    m.CreateFaceVertexCountsAttr(counts)
    m.CreateFaceVertexIndicesAttr(faces)
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(mat)


@pytest.mark.skipif(embree.library() is None, reason="Embree (embreex) is not available")
def test_a_merged_mesh_light_in_quads_lights_the_floor_as_in_triangles(tmp_path, monkeypatch):
    """An emissive panel and a floor, merged into one mesh by the flattening with the panel's light on the first
    range of it: laid out in pairs and held by Embree as quads (every mesh, the size floor lowered), the floor's
    irradiance is what the plain layout gives, within the noise (the light samples its triangles in another
    order). The panel's lone triangle stays in its range, not after the floor's pairs."""
    import stages
    from renderer.accel import quads
    from renders import render_rgb

    stage = stages.new_stage(tmp_path / "panel.usda")
    stages.camera(stage, ortho=True, h_ap_mm=0.4, v_ap_mm=0.4, translate=(0, 0.5, 0), rotate_x=-90.0,
                  tenths_per_mm=1.0)
    _grid_mesh(stage, "/World/Panel", 8, 0.5, 1.0, stages.material(stage, "Glow", emissive=(4, 4, 4)), down=True,
               lone=True)
    _grid_mesh(stage, "/World/Floor", 24, 10.0, 0.0, stages.material(stage, "White", (1, 1, 1)), down=False)
    stage.Save()
    plain, prep = render_rgb(tmp_path / "panel.usda", width=8, height=8, spp=256, max_depth=1)
    assert not (prep.geometry.embree_geoms.numpy() & 1).any()
    monkeypatch.setattr(quads, "MIN_TRIANGLES", 2)
    paired, prep = render_rgb(tmp_path / "panel.usda", width=8, height=8, spp=256, max_depth=1)
    assert (prep.geometry.embree_geoms.numpy() & 1).any() and prep.light_count == 1
    from renderer.scene.flatten import flatten_still_instances
    from renderer.usd.importer import load_scene

    flat = order_for_quads(flatten_still_instances(load_scene(tmp_path / "panel.usda")))
    (light,) = flat.lights
    lo, hi = light.triangles
    mats = flat.meshes[flat.instances[light.instance].mesh].material_ids
    assert hi - lo == 129 and len(set(mats[lo:hi])) == 1 and mats[lo] not in set(mats[hi:]) | set(mats[:lo])
    a, b = plain.mean(), paired.mean()
    assert a > 0.05
    assert abs(a - b) < 0.02 * a


@pytest.mark.skipif(embree.library() is None, reason="Embree (embreex) is not available")
def test_embree_takes_quads_only_from_a_mesh_laid_out_in_pairs():
    """A mesh at least half in pairs goes in as quads (a run of pairs, then the lone triangles); one whose
    neighbours have the pair's shape only here and there goes in as plain triangles, one geometry."""
    pts = np.random.default_rng(7).normal(size=(40, 3)).astype(np.float32)
    pair = [[13, 10, 11], [12, 13, 11]]
    lone = [[0, 1, 2], [3, 4, 5], [6, 7, 8]]
    scenes = embree.EmbreeScenes(embree.library())
    handle, codes = scenes.add_mesh(pts, np.array(pair + pair + lone[:1], np.int32))
    assert handle != 0 and list(codes) == [1, 2 * 4]
    handle, codes = scenes.add_mesh(pts, np.array(lone * 3 + pair, np.int32))
    assert handle != 0 and list(codes) == [0]
    scenes.close()
