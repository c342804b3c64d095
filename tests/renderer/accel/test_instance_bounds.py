"""Top-level boxes placed from a cut of the mesh's hierarchy (``accel.instance_bounds``): every cut covers every
primitive, the placed boxes hold the placed mesh at every time (still and moving), are never looser than the
root box's corners placed, and are much tighter for a rotated elongated mesh."""
from __future__ import annotations

import numpy as np
import pytest

from renderer.accel.build import build_bvh
from renderer.accel.instance_bounds import (
    CUT_BOXES,
    box_cut,
    cut_size,
    instance_key_bounds,
    place_cut,
    still_world_boxes,
)
from renderer.motion.transform import make_transform, matrix_at, place_boxes
from renderer.scene.model import Instance


def _ellipsoid(n_u=24, n_v=12, axes=(3.0, 1.0, 0.5)):
    """Points and triangles of an elongated ellipsoid (a rock, a plank)."""
    th = np.linspace(0, np.pi, n_v + 1)
    ph = np.linspace(0, 2 * np.pi, n_u, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    pts = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], -1).reshape(-1, 3) * axes
    tris = []
    for j in range(n_v):
        for i in range(n_u):
            a, b = j * n_u + i, j * n_u + (i + 1) % n_u
            tris += [(a, b, b + n_u), (a, b + n_u, a + n_u)]
    return pts.astype(np.float32), np.array(tris, np.int64)


def _bvh(pts, tris):
    v = pts[tris]  # (T, 3, 3)
    return build_bvh(v.min(1)[None], v.max(1)[None], max_leaf=4)  # (keys, primitives, 3)


def _random_matrix(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    s = np.diag(rng.uniform(0.3, 2.0, 3) * rng.choice([-1.0, 1.0], 3))
    m = np.eye(4)
    m[:3, :3] = q @ s
    m[:3, 3] = rng.uniform(-50, 50, 3)
    return m


def _subtree_prims(bvh, n):
    out, todo = [], [n]
    while todo:
        k = todo.pop()
        if bvh.node_a[k] < 0:
            first = -bvh.node_a[k] - 1
            out += list(bvh.prim_order[first:first + bvh.node_b[k]])
        else:
            todo += [int(bvh.node_a[k]), int(bvh.node_b[k])]
    return out


@pytest.mark.parametrize("count", [1, 2, 7, 64, 10_000])
def test_cut_covers_every_primitive_once(count):
    pts, tris = _ellipsoid()
    bvh = _bvh(pts, tris)
    nodes = box_cut(bvh, count)
    assert 1 <= len(nodes) <= max(count, 1)
    prims = sorted(p for n in nodes for p in _subtree_prims(bvh, int(n)))
    assert prims == list(range(len(tris)))  # a partition: each primitive under exactly one cut node
    if count >= len(tris):  # nothing left to open: every cut node is a leaf
        assert np.all(bvh.node_a[nodes] < 0)


def test_cut_size_budget():
    assert cut_size(1) == CUT_BOXES and cut_size(1000) == CUT_BOXES
    assert cut_size(10 ** 6) == 1 and 1 <= cut_size(100_000) < CUT_BOXES


def test_still_boxes_hold_the_mesh_and_are_tighter():
    rng = np.random.default_rng(5)
    pts, tris = _ellipsoid()
    bvh = _bvh(pts, tris)
    nodes = box_cut(bvh, 64)
    ms = np.array([_random_matrix(rng) for _ in range(50)])
    lo, hi = still_world_boxes(ms, bvh, nodes)
    root = np.array([bvh.node_lower[0, 0], bvh.node_upper[0, 0]], np.float64)
    rlo, rhi = place_boxes(ms, *(np.repeat(root[None, k], len(ms), 0) for k in (0, 1)))
    p = pts.astype(np.float64)

    def half_area(a, b):
        d = b - a
        return d[0] * d[1] + d[1] * d[2] + d[2] * d[0]

    cut_excess, root_excess = [], []  # placed box's half area over the exact box's
    for i, m in enumerate(ms):
        w = p @ m[:3, :3].T + m[:3, 3]
        tol = 1e-5 * (1 + np.abs(w).max())
        assert np.all(w.min(0) >= lo[i] - tol) and np.all(w.max(0) <= hi[i] + tol)  # conservative
        assert np.all(lo[i] >= rlo[i] - tol) and np.all(hi[i] <= rhi[i] + tol)  # never looser than the root
        exact = half_area(w.min(0), w.max(0))
        cut_excess.append(half_area(lo[i], hi[i]) / exact)
        root_excess.append(half_area(rlo[i], rhi[i]) / exact)
    cut_excess, root_excess = np.mean(cut_excess), np.mean(root_excess)
    assert cut_excess < 1.4 and root_excess > 1.6  # measured: 1.33 against 1.85 (a coarse, flat ellipsoid)


def test_one_root_box_is_the_old_placement_bit_for_bit():
    rng = np.random.default_rng(8)
    pts, tris = _ellipsoid()
    bvh = _bvh(pts, tris)
    ms = np.array([_random_matrix(rng) for _ in range(20)])
    root = np.array([bvh.node_lower[0, 0], bvh.node_upper[0, 0]], np.float64)
    rlo, rhi = place_boxes(ms, *(np.repeat(root[None, k], len(ms), 0) for k in (0, 1)))
    lo, hi = still_world_boxes(ms, bvh, box_cut(bvh, 1))
    assert np.array_equal(lo, rlo) and np.array_equal(hi, rhi)
    # shared boxes (1, C, 3) and per-instance boxes (n, C, 3) place alike
    blo = np.repeat(root[None, None, 0], len(ms), 0)
    bhi = np.repeat(root[None, None, 1], len(ms), 0)
    assert np.array_equal(place_cut(ms, blo, bhi)[0], rlo)


@pytest.mark.parametrize("deforming", [False, True])
def test_moving_instance_boxes_hold_the_mesh_at_every_time(deforming):
    """A tumbling, travelling instance (and its mesh deforming between two point keys): the blend of the key
    boxes at any time holds the mesh placed at that time."""
    rng = np.random.default_rng(2)
    pts, tris = _ellipsoid()
    keys = [pts, pts * np.float32(1.3) + np.float32(0.2)] if deforming else [pts]
    mesh_times = np.array([0.0, 1.0]) if deforming else np.zeros(1)
    v = np.stack([k[tris] for k in keys])  # (K, T, 3, 3)
    bvh = build_bvh(v.min(2), v.max(2), max_leaf=4)
    mats = [_random_matrix(rng) for _ in range(3)]
    xf = make_transform([0.0, 0.5, 1.0], mats)
    nkeys = 5
    klo, khi = instance_key_bounds(Instance(0, xf), bvh, mesh_times, nkeys, box_cut(bvh, 64))
    rlo, rhi = instance_key_bounds(Instance(0, xf), bvh, mesh_times, nkeys)
    for s in np.linspace(0, 1, 61):
        x = s * (nkeys - 1)
        k0 = min(int(x), nkeys - 2)
        u = x - k0
        lo, hi = klo[k0] * (1 - u) + klo[k0 + 1] * u, khi[k0] * (1 - u) + khi[k0 + 1] * u
        p = keys[0].astype(np.float64) if not deforming else (keys[0] * (1 - s) + keys[1] * s).astype(np.float64)
        m = matrix_at(xf, float(s))
        w = p @ m[:3, :3].T + m[:3, 3]
        tol = 1e-5 * (1 + np.abs(w).max())
        assert np.all(w.min(0) >= lo - tol) and np.all(w.max(0) <= hi + tol), s
    assert np.sum(khi - klo) < np.sum(rhi - rlo)  # and tighter than the root's corners
