"""The Warp kernels that replace NumPy gathers in the bottom-level upload give the NumPy results bit for bit."""
from __future__ import annotations

import numpy as np

from renderer.accel.triangle_kernels import leaf_triangles, triangle_boxes
from renderer.kernels.device import init_warp


def test_triangle_boxes_equal_numpy_min_max_at_every_key():
    init_warp()
    rng = np.random.default_rng(3)
    points = (rng.normal(size=(3, 200, 3)) * 1e3).astype(np.float32)  # 3 point keys (a deforming mesh)
    tris = rng.integers(0, 200, size=(500, 3)).astype(np.int32)
    lo, hi = triangle_boxes(points, tris)
    corners = points[:, tris]  # (K, T, 3, 3)
    assert lo.shape == hi.shape == (3, 500, 3)
    np.testing.assert_array_equal(lo, corners.min(axis=2))
    np.testing.assert_array_equal(hi, corners.max(axis=2))


def test_triangle_boxes_of_no_triangles_are_empty():
    init_warp()
    lo, hi = triangle_boxes(np.zeros((1, 4, 3), np.float32), np.zeros((0, 3), np.int32))
    assert lo.shape == hi.shape == (1, 0, 3)


def test_leaf_triangles_follow_the_slot_order():
    init_warp()
    rng = np.random.default_rng(4)
    points = rng.normal(size=(100, 3)).astype(np.float32)
    tris = rng.integers(0, 100, size=(300, 3)).astype(np.int32)
    order = rng.permutation(300).astype(np.int32)
    v0, e1, e2 = leaf_triangles(points, tris, order)
    tri = points[tris[order]]
    np.testing.assert_array_equal(v0, tri[:, 0])
    np.testing.assert_array_equal(e1, tri[:, 1] - tri[:, 0])
    np.testing.assert_array_equal(e2, tri[:, 2] - tri[:, 0])
