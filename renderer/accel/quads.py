"""Triangles laid out in pairs, so that Embree can hold them as quads read in place from the mesh's own indices.

Embree stores a quad (v0, v1, v2, v3) as the two triangles (v0, v1, v3) and (v2, v3, v1), four quads to a leaf:
eight triangles in the memory and the box tests that four triangles of a triangle mesh take. Most meshes are
triangulated quads or close to it, so pairing each triangle with the neighbour across its longest edge (a quad's
diagonal) pairs nearly all of them: 98.7 % of the heavy bench scene's million triangles.

``order_for_quads`` (run on the flattened scene before anything is uploaded) puts each pair side by side in the
mesh, the first triangle as (v3, v0, v1) and the second as (v2, v3, v1): each is its own corners rotated, so the
surface is the same, and the pair's six indices hold the quad's four in a row, (v0, v1, v2, v3) from the second
index on. Embree then reads a run of pairs as a quad buffer with a stride of two triangles, straight from the
uploaded indices (``quad_runs`` finds the runs), and a hit's quad index and parameters give the triangle and
its barycentrics by arithmetic alone (``embree_triangle``). Triangles left alone follow the pairs and go to
Embree as quads too, (t0, t1, t2, t2), whose second half has no area (Embree walks a tree per primitive type). Pairs are made only across an edge that exactly two triangles of one emitting range share
(a mesh light's triangles stay where its range says), in opposite directions (consistently wound), and that is
the longest edge of both.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import warp as wp

from renderer.scene.model import LIGHT_MESH, Mesh, Scene

MAX_TRIANGLES = 1 << 30  # a run's first triangle, times 2 plus its kind, fits an int32
# Meshes with fewer triangles stay as they are, triangles to Embree: a quad leaf tests both halves of each quad,
# which costs more than it saves where leaves hold a few primitives (the Cornell box's 34 triangles: Embree's
# instructions +55 %, the frame's +8.9 %; gloss's 3984 and dof's 9922 triangles +0.7-0.8 %, callgrind), and the
# memory saved only matters for large meshes (heavy's million: 67.1 -> 43.4 bytes per triangle in Embree, its
# incoherent rays 10 % faster, its frame +0.75 % counted, 1.000x timed)
MIN_TRIANGLES = 1 << 16


def _norm2(v: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", v, v)


def pair_up(points: np.ndarray, triangles: np.ndarray, segment: np.ndarray | None = None):
    """Pairs of triangles sharing their longest edge: (first, second, k_first, k_second), where edge k runs from
    corner k to corner k + 1. Only an edge of exactly two proper triangles, wound in opposite directions along it,
    both in the same ``segment`` (T,) when given."""
    tris = np.asarray(triangles).reshape(-1, 3)
    n = len(tris)
    idx = np.arange(n)
    pts = np.asarray(points, np.float32)
    c0, c1, c2 = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    k = np.stack([_norm2(c1 - c0), _norm2(c2 - c1), _norm2(c0 - c2)], 1).argmax(1)
    a, b = tris[idx, k].astype(np.int64), tris[idx, (k + 1) % 3].astype(np.int64)
    proper = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])
    nv = max(int(tris.max(initial=0)) + 1, 1)
    key = np.where(proper, np.minimum(a, b) * nv + np.maximum(a, b), -1 - idx)  # a lone key for a degenerate one
    order = np.argsort(key)  # ties only within an edge's group, whose order does not matter
    sk = key[order]
    same = sk[1:] == sk[:-1]  # neighbours in sorted order that share their longest edge
    before = np.concatenate([[False], same[:-1]])
    after = np.concatenate([same[1:], [False]])
    two = same & ~before & ~after  # exactly two triangles on that edge
    i, j = order[:-1][two], order[1:][two]
    ok = a[i] == b[j]  # opposite directions along the edge
    if segment is not None:
        ok &= segment[i] == segment[j]
    i, j = i[ok], j[ok]
    first, second = np.minimum(i, j), np.maximum(i, j)
    return first, second, k[first], k[second]


def quad_order(points: np.ndarray, triangles: np.ndarray, cuts=()) -> tuple[np.ndarray, np.ndarray]:
    """The order and corner rotation that lay ``triangles`` out in pairs (module docstring): new triangle i is old
    triangle ``order[i]`` with corners ``(c + shift[i]) % 3`` for c = 0, 1, 2. Within each range between ``cuts``
    (triangle indices), its pairs come first, in the order of their first triangle, then its lone triangles in
    their order; no triangle leaves its range."""
    n = len(triangles)
    edges = np.array(sorted(set(int(c) for c in cuts if 0 < c < n)), np.int64)
    segment = np.searchsorted(edges, np.arange(n), side="right")  # the range each triangle is in
    first, second, ka, kb = pair_up(points, triangles, segment)
    # sort keys: (range, lone, position): a pair at 2 * its first triangle (+1 for the second), a lone one at its own
    lone = np.ones(n, np.int64)
    pos = np.arange(n, dtype=np.int64)
    shift = np.zeros(n, np.int64)
    lone[first] = lone[second] = 0
    pos[first], pos[second] = 2 * first, 2 * first + 1
    shift[first] = ka + 1  # (v3, v0, v1) = corners (k + 1, k + 2, k) of the first, whose edge k is the diagonal
    shift[second] = kb + 2  # (v2, v3, v1) = corners (k + 2, k, k + 1) of the second
    order = np.argsort(segment * (4 * n) + lone * (2 * n) + pos)  # the keys are distinct
    return order, shift[order] % 3


def reorder_mesh(mesh: Mesh, order: np.ndarray, shift: np.ndarray) -> Mesh:
    """``mesh`` with its triangles in ``order``, each one's corners rotated by ``shift`` (``quad_order``): the
    same surface, per-triangle and per-corner data carried along."""
    corner = (np.arange(3)[None, :] + shift[:, None]) % 3
    rows = order[:, None]

    def corners(a):
        return None if a is None else np.ascontiguousarray(a[rows, corner])

    def per_triangle(a):
        return None if a is None else np.ascontiguousarray(np.asarray(a)[order])

    return replace(mesh, triangles=corners(mesh.triangles), material_ids=per_triangle(mesh.material_ids),
                   normals=corners(mesh.normals), uvs=corners(mesh.uvs), colors=corners(mesh.colors),
                   solid=per_triangle(mesh.solid), tangents=per_triangle(mesh.tangents),
                   source_instance=per_triangle(mesh.source_instance),
                   primvars={k: v if v.ndim == 1 else corners(v) for k, v in mesh.primvars.items()})


def order_for_quads(scene: Scene, min_triangles: int | None = None) -> Scene:
    """``scene`` with each still triangle mesh of at least ``min_triangles`` (None: ``MIN_TRIANGLES``) laid out in
    pairs (``quad_order``), the ranges of mesh lights kept. The meshes Embree would not hold (deforming, exact
    shapes, point clouds) stay as they are."""
    if min_triangles is None:
        min_triangles = MIN_TRIANGLES
    cuts: dict[int, set] = {}
    for light in scene.lights:
        if light.kind == LIGHT_MESH and light.triangles is not None and 0 <= light.instance < len(scene.instances):
            cuts.setdefault(scene.instances[light.instance].mesh, set()).update(light.triangles)
    meshes = list(scene.meshes)
    for mi, mesh in enumerate(meshes):
        if (mesh.shape is not None or mesh.tessellate is not None or len(mesh.point_times) != 1
                or not max(2, min_triangles) <= len(mesh.triangles) < MAX_TRIANGLES):
            continue
        order, shift = quad_order(mesh.points[0], mesh.triangles, cuts.get(mi, ()))
        meshes[mi] = reorder_mesh(mesh, order, shift)
    return replace(scene, meshes=meshes)


def quad_runs(triangles: np.ndarray) -> list[tuple[int, int, bool]]:
    """The runs that cover ``triangles`` (T, 3) in order: (first triangle, count, True) for count pairs laid out
    as ``order_for_quads`` lays them, whose indices read from the first's second index on with a stride of six are
    quads (v0, v1, v2, v3); (first, count, False) for count triangles between them. Any two neighbours of that
    shape are a right quad, however they came to be; runs are found leftmost first."""
    tris = np.asarray(triangles).reshape(-1, 3)
    n = len(tris)
    if n < 2:
        return [(0, n, False)] if n else []
    a, b = tris[:-1], tris[1:]
    # a = (v3, v0, v1), b = (v2, v3, v1), the four corners distinct
    p = ((a[:, 0] == b[:, 1]) & (a[:, 2] == b[:, 2]) & (a[:, 0] != a[:, 1]) & (a[:, 1] != a[:, 2])
         & (a[:, 2] != a[:, 0]) & (b[:, 0] != a[:, 0]) & (b[:, 0] != a[:, 1]) & (b[:, 0] != a[:, 2]))
    idx = np.arange(n - 1)
    starts_run = p & ~np.concatenate([[False], p[:-1]])
    run_start = np.maximum.accumulate(np.where(starts_run, idx, 0))
    pair = p & ((idx - run_start) % 2 == 0)  # leftmost: a run of k shapes in a row holds ceil(k / 2) pairs
    starts = np.nonzero(pair)[0]
    if not len(starts):
        return [(0, n, False)]
    cut = np.nonzero(np.diff(starts) != 2)[0]  # pair starts two apart make one run of quads
    firsts = starts[np.concatenate([[0], cut + 1])]
    lasts = starts[np.concatenate([cut, [len(starts) - 1]])]
    runs: list[tuple[int, int, bool]] = []
    t = 0
    for f, last in zip(firsts.tolist(), lasts.tolist()):
        if f > t:
            runs.append((t, f - t, False))
        runs.append((f, (last - f) // 2 + 1, True))
        t = last + 2
    if t < n:
        runs.append((t, n - t, False))
    return runs


@wp.func
def embree_triangle(geoms: wp.array(dtype=wp.int32), off: int, geom: int, prim: int, u: float, v: float):
    """A hit on primitive ``prim`` of Embree geometry ``geom`` at Embree's (u, v): the mesh's triangle and its
    barycentrics (b1, b2) of corners 1 and 2. ``geoms[off + geom]`` is the run's first triangle * 2, plus 1 for a
    run of quads (``quad_runs``). A quad's first half (v0, v1, v3) is the triangle (v3, v0, v1) and covers
    u + v <= 1 with (u, v) its own barycentrics; the second (v2, v3, v1) is the triangle (v2, v3, v1), with
    barycentrics 1 - u and 1 - v."""
    code = geoms[off + geom]
    base = code >> 1
    if (code & 1) == 0:
        return base + prim, u, v
    if u + v <= 1.0:
        return base + 2 * prim, 1.0 - u - v, u
    return base + 2 * prim + 1, 1.0 - u, 1.0 - v
