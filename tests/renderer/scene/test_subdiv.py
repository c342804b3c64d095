"""Subdivision surfaces (renderer/subdiv): convergence to the limit surface, B-spline limit masks, creases and
corners, boundaries, Loop, face-varying data and motion keys."""
from __future__ import annotations

import numpy as np
import pytest

from renderer.subdiv import SubdivOptions, subdivide, triangle_count

CUBE_P = np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)  # index 4x + 2y + z
CUBE_F = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]  # outward
CUBE_COUNTS, CUBE_IDX = [4] * 6, sum(CUBE_F, [])


def volume_area(tris_xyz: np.ndarray) -> tuple[float, float]:
    a, b, c = tris_xyz[:, 0], tris_xyz[:, 1], tris_xyz[:, 2]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    return float(vol), float(area)


def surface(counts, idx, pts, level, limit=True, **opts):
    ref = subdivide(counts, idx, len(pts), SubdivOptions(**opts), level)
    if limit:
        p = ref.points(pts)
    else:
        p = np.asarray(pts, float)
        for s in ref.stencils:
            p = s.apply(p)
    return ref, p


def cube_creases(sharpness):
    edges = {tuple(sorted((f[k], f[(k + 1) % 4]))) for f in CUBE_F for k in range(4)}
    idx = np.array(sorted(edges)).reshape(-1)
    return dict(crease_indices=idx, crease_lengths=np.full(12, 2), crease_sharpnesses=np.full(12, float(sharpness)))


def grid(n, z=None):
    """(n+1)^2 vertices over [0, n]^2, n^2 quads (counter-clockwise from +z)."""
    xs = np.arange(n + 1, dtype=float)
    gx, gy = np.meshgrid(xs, xs)
    pts = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size) if z is None else z(gx, gy).ravel()], 1)
    idx = []
    for r in range(n):
        for c in range(n):
            a = r * (n + 1) + c
            idx += [a, a + 1, a + n + 2, a + n + 1]
    return [4] * (n * n), idx, pts


# ---------------------------------------------------------------------------------------------------------------
# Catmull-Clark


def test_cube_cage_converges_to_its_limit_surface():
    """The limit projection puts every level on the same surface: volumes and areas of levels 2..6 converge
    towards one value (unit cube: volume 0.32747, area 2.2991), and plain refinement without the projection
    reaches the same value from outside - an independent check of the limit masks."""
    vols, areas = [], []
    for level in range(1, 7):
        ref, p = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, level)
        v, a = volume_area(p[ref.triangles])
        vols.append(v / 8)  # side 2 -> unit cube
        areas.append(a / 4)
    vols, areas = np.array(vols), np.array(areas)
    assert np.all(np.diff(vols) > 0) and np.all(np.diff(areas) > 0), "inscribed polyhedra grow towards the limit"
    err = np.abs(vols - vols[-1])
    assert np.all(err[1:-1] < err[:-2] / 3), "error falls by about 4x per level (second order)"
    assert vols[-1] == pytest.approx(0.32747, abs=2e-4) and areas[-1] == pytest.approx(2.2991, abs=5e-4)
    ref, p = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, 6, limit=False)
    v_plain, _ = volume_area(p[ref.triangles])
    assert v_plain / 8 == pytest.approx(vols[-1], rel=2e-3)
    assert v_plain / 8 > vols[-1], "refined control points lie outside the convex limit surface"
    # the limit surface of the cube cage is symmetric and strictly inside the cage
    _, p = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, 3)
    assert np.abs(p).max() < 1.0 and np.linalg.norm(p, axis=1).min() > 0.8


def test_regular_limit_points_are_the_bicubic_bspline():
    """On a regular grid the limit of a vertex is the uniform bicubic B-spline at its knot:
    (16 v + 4 sum(edge neighbours) + sum(diagonal neighbours)) / 36."""
    rng = np.random.default_rng(3)
    counts, idx, pts = grid(6, z=lambda x, y: 0 * x)
    pts[:, 2] = rng.normal(size=len(pts))
    ref = subdivide(counts, idx, len(pts), SubdivOptions(), 1)
    limit = ref.points(pts)
    nf, ne = 36, ref.stencils[0].num_rows - 36 - len(pts)
    z = pts[:, 2].reshape(7, 7)
    for r, c in [(2, 2), (3, 4), (1, 5)]:
        expected = (16 * z[r, c] + 4 * (z[r - 1, c] + z[r + 1, c] + z[r, c - 1] + z[r, c + 1])
                    + z[r - 1, c - 1] + z[r - 1, c + 1] + z[r + 1, c - 1] + z[r + 1, c + 1]) / 36
        v = r * 7 + c
        assert limit[nf + ne + v, 2] == pytest.approx(expected, abs=1e-12)
        assert limit[nf + ne + v, :2] == pytest.approx(pts[v, :2], abs=1e-12)


def vertex_normals(ref, p, c):
    out = np.zeros((len(p), 3))
    out[ref.triangles.reshape(-1)] = ref.normals(p, c).reshape(-1, 3)
    return out


@pytest.mark.parametrize("scheme", ["catmullClark", "loop"])
def test_limit_normals_match_a_much_finer_surface(scheme):
    """Normals of level 2 from the limit tangent masks equal those of a level-6 refinement at the same limit
    points within 0.05 degrees (the sector average of face normals alone is off by about 2 degrees)."""
    from scipy.spatial import cKDTree

    if scheme == "loop":
        counts, idx, pts = octahedron()
    else:
        counts, idx, pts = CUBE_COUNTS, CUBE_IDX, CUBE_P
    fine = subdivide(counts, idx, len(pts), SubdivOptions(scheme=scheme), 6)
    cf = fine.control_points(pts)
    pf = fine.limit.apply(cf)
    nf = vertex_normals(fine, pf, cf)
    ref = subdivide(counts, idx, len(pts), SubdivOptions(scheme=scheme), 2)
    c = ref.control_points(pts)
    p = ref.limit.apply(c)
    dist, near = cKDTree(pf).query(p)
    assert dist.max() < 1e-12, "level-2 limit points are points of the finer limit mesh"
    ang = np.degrees(np.arccos(np.clip(np.sum(vertex_normals(ref, p, c) * nf[near], axis=1), -1, 1)))
    assert ang.max() < 0.05
    assert np.all(np.sum(vertex_normals(ref, p, c) * p, axis=1) > 0), "outward"


def test_infinitely_sharp_creases_keep_the_cube_a_cube():
    ref, p = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, 3, **cube_creases(10.0))
    assert np.abs(p).max(axis=1) == pytest.approx(np.ones(len(p)), abs=1e-12), "every point on a cube face"
    v, a = volume_area(p[ref.triangles])
    assert v == pytest.approx(8.0, abs=1e-9) and a == pytest.approx(24.0, abs=1e-9)
    n = ref.normals(p)
    assert np.allclose(np.abs(n).max(axis=2), 1.0, atol=1e-9), "hard shading edges: face normals throughout"


def test_semi_sharp_creases_interpolate_between_smooth_and_sharp():
    vols = []
    for s in (0.0, 0.5, 1.0, 2.0, 3.0):
        ref, p = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, 5, **cube_creases(s))
        vols.append(volume_area(p[ref.triangles])[0])
    assert vols[0] == pytest.approx(8 * 0.32747, abs=4e-3)
    assert np.all(np.diff(vols) > 0) and vols[-1] < 8.0


def test_infinitely_sharp_corner_stays_put():
    opts = dict(corner_indices=np.array([7]), corner_sharpnesses=np.array([10.0]))
    ref, p = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, 3, **opts)
    assert np.min(np.linalg.norm(p - CUBE_P[7], axis=1)) < 1e-12
    ref, p = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, 3)
    assert np.min(np.linalg.norm(p - CUBE_P[7], axis=1)) > 0.5


def test_boundaries():
    """An open grid: edgeAndCorner keeps its corners and makes its edges cubic B-splines of the boundary
    ((a + 4 v + b) / 6 at a boundary vertex); edgeOnly rounds the corners; none drops the boundary faces."""
    counts, idx, pts = grid(4, z=lambda x, y: 0.1 * (x - 2) ** 2 + 0.05 * x * y)
    ref, p = surface(counts, idx, pts, 2)
    nearest = lambda q: np.min(np.linalg.norm(p - q, axis=1))  # noqa: E731
    assert nearest(pts[0]) < 1e-12 and nearest(pts[24]) < 1e-12
    v, a, b = pts[2], pts[1], pts[3]  # on the bottom boundary
    assert nearest((a + 4 * v + b) / 6) < 1e-12
    ref, p = surface(counts, idx, pts, 2, interpolate_boundary="edgeOnly")
    assert np.min(np.linalg.norm(p - pts[0], axis=1)) > 0.1
    ref = subdivide(counts, idx, len(pts), SubdivOptions(interpolate_boundary="none"), 2)
    assert set(np.unique(ref.tri_faces)) == {5, 6, 9, 10}, "only faces away from the boundary"


def test_triangle_smooth_rule_changes_only_triangle_meshes():
    tet = np.array([(1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)], float)
    faces = [0, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2]
    r1, p1 = surface([3] * 4, faces, tet, 3)
    r2, p2 = surface([3] * 4, faces, tet, 3, triangle_smooth=True)
    assert not np.allclose(p1, p2)
    _, q1 = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, 2)
    _, q2 = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, 2, triangle_smooth=True)
    assert np.array_equal(q1, q2)


# ---------------------------------------------------------------------------------------------------------------
# Loop, bilinear


def octahedron():
    p = np.array([(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)], float)
    f = [0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5]
    return [3] * 8, f, p


def test_loop_converges_and_reproduces_planes():
    counts, idx, pts = octahedron()
    vols = []
    for level in (2, 3, 4, 5):
        ref, p = surface(counts, idx, pts, level, scheme="loop")
        assert np.all(ref.final.topo.counts == 3)
        vols.append(volume_area(p[ref.triangles])[0])
    d = np.diff(vols)
    assert np.all(d > 0) and np.all(d[1:] < d[:-1] / 3.5), "second-order convergence"
    # the valence-4 vertices' limit: (1 - 4 chi) v with chi = 1 / (3 / (8 beta) + 4), beta(4) = 31/256
    chi = 1 / (3 / (8 * 31 / 256) + 4)
    assert np.abs(p).max() == pytest.approx(1 - 4 * chi, abs=1e-12)
    ref, p = surface(counts, idx, pts, 5, scheme="loop", limit=False)
    assert volume_area(p[ref.triangles])[0] == pytest.approx(vols[-1], rel=5e-3)
    # a triangulated plane z = 0.3 x - 0.2 y stays on it (affine invariance, boundary included)
    c, i, g = grid(3, z=lambda x, y: 0.3 * x - 0.2 * y)
    tris = np.array(i).reshape(-1, 4)[:, [0, 1, 2, 0, 2, 3]].reshape(-1)
    ref, p = surface([3] * (2 * 9), tris, g, 3, scheme="loop")
    assert np.allclose(p[:, 2], 0.3 * p[:, 0] - 0.2 * p[:, 1], atol=1e-12)


def test_bilinear_keeps_flat_quads_flat_and_the_cage_corners():
    ref, p = surface(CUBE_COUNTS, CUBE_IDX, CUBE_P, 2, scheme="bilinear")
    assert np.abs(p).max(axis=1) == pytest.approx(np.ones(len(p)))
    assert volume_area(p[ref.triangles]) == pytest.approx((8.0, 24.0))


def test_triangle_count_matches_the_refinement():
    for scheme, counts, idx, n in [("catmullClark", CUBE_COUNTS, CUBE_IDX, 8), ("loop", *octahedron()[:2], 6),
                                   ("catmullClark", [3, 5], [0, 1, 2, 0, 2, 3, 4, 5], 6)]:
        for level in range(4):
            ref = subdivide(counts, idx, n, SubdivOptions(scheme=scheme), level)
            assert len(ref.triangles) == triangle_count(counts, scheme, level)


# ---------------------------------------------------------------------------------------------------------------
# primvars and motion keys


def test_motion_keys_refine_linearly():
    """One set of stencils for every key: refining is linear, so a moved and scaled key refines to the
    moved and scaled surface, consistently with key 0."""
    ref = subdivide(CUBE_COUNTS, CUBE_IDX, 8, SubdivOptions(), 3)
    rng = np.random.default_rng(0)
    k0, k1 = CUBE_P + rng.normal(0, 0.1, (8, 3)), CUBE_P * 2 + (1, 2, 3)
    a, b = ref.points(k0), ref.points(k1)
    assert np.allclose(ref.points(0.25 * k0 + 0.75 * k1), 0.25 * a + 0.75 * b, atol=1e-12)
    assert np.allclose(b, ref.points(CUBE_P) * 2 + (1, 2, 3), atol=1e-12)


def test_face_varying_linear_modes():
    """uv = xy on a flat 2 x 2 grid. 'all' interpolates uvs linearly inside every face (so each refined corner
    keeps the bilinear uv of its place in the face) while the smooth modes round them; the corners of the
    uv island stay pinned in the corner modes."""
    counts, idx, pts = grid(2)
    uv = pts[:, :2] / 2
    fv_idx = np.array(idx)  # uvs indexed like the vertices: one island
    ref = subdivide(counts, idx, len(pts), SubdivOptions(), 2)
    lin = ref.face_varying(uv, fv_idx, "all")
    assert set(np.round(lin.reshape(-1), 9)) <= {k / 8 for k in range(9)}, "dyadic grid of the bilinear map"
    smooth = ref.face_varying(uv, fv_idx, "none")
    assert not np.allclose(smooth, lin)
    corners = ref.face_varying(uv, fv_idx, "cornersPlus1").reshape(-1, 2)
    for c in [(0, 0), (1, 0), (0, 1), (1, 1)]:
        assert np.min(np.linalg.norm(corners - c, axis=1)) < 1e-12
    assert np.min(np.linalg.norm(smooth.reshape(-1, 2) - (0, 0), axis=1)) > 1e-3


def test_holes_do_not_change_their_neighbours():
    counts, idx, pts = grid(3, z=lambda x, y: np.sin(x) * np.cos(y))
    ref = subdivide(counts, idx, len(pts), SubdivOptions(), 2)
    p = ref.points(pts)
    keep = ref.tri_faces != 4
    assert 4 in ref.tri_faces and keep.sum() == len(keep) - 32
    # the hole is applied after refinement (usd/subdiv.py): the surface around it is the same surface
    assert np.all(np.isfinite(p))


def test_creases_crease_face_varying_data_too():
    """A flat 4 x 4 grid with an infinitely sharp crease along the row y = 2 and a smooth ('none') uv set whose v
    is 0.3 on that row and random elsewhere: along the crease v stays 0.3 (the crease rule sees only the crease);
    without the crease it is smoothed with the rows beside it."""
    counts, idx, pts = grid(4)
    rng = np.random.default_rng(5)
    uv = np.stack([pts[:, 0], rng.uniform(0, 1, len(pts))], 1)
    row = np.flatnonzero(pts[:, 1] == 2)
    uv[row, 1] = 0.3
    crease = dict(crease_indices=row, crease_lengths=np.array([len(row)]), crease_sharpnesses=np.array([10.0]))
    for opts, stays in ((crease, True), ({}, False)):
        ref = subdivide(counts, idx, len(pts), SubdivOptions(**opts), 2)
        p = ref.points(pts)
        fv = ref.face_varying(uv, np.array(idx), "none").reshape(-1, 2)
        on = np.abs(p[ref.triangles].reshape(-1, 3)[:, 1] - 2) < 1e-12
        if stays:
            assert on.sum() > 20
            np.testing.assert_allclose(fv[on, 1], 0.3, atol=1e-12)
        else:  # without the crease the limit surface still has y = 2 there by symmetry, but v is smoothed
            assert on.sum() > 20 and np.abs(fv[on, 1] - 0.3).max() > 0.01
