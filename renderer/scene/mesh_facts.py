"""Plain NumPy facts about meshes that several modules need."""
from __future__ import annotations

import numpy as np


def _edge_keys(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.minimum(a, b) << 32 | np.maximum(a, b)


def is_closed(triangles: np.ndarray, points: np.ndarray | None = None) -> bool:
    """Does a triangle mesh bound a solid? Every undirected edge is shared by exactly two triangles.

    Vertices at the same position are welded first (meshes split at UV seams are still solids). Closed meshes
    refract and absorb (a glass ball); open ones are thin (a window pane, a leaf).
    """
    if len(triangles) == 0:
        return False
    if points is not None:  # weld on a grid of 1e-5 of the extent: seam copies differ by rounding
        pts = np.asarray(points, np.float64).reshape(-1, 3)
        cell = max(float(np.ptp(pts, axis=0).max()), 1e-30) * 1e-5
        q = np.round((pts - pts.min(axis=0)) / cell).astype(np.int64)  # each in [0, 1e5]: 17 bits, one int64 key
        _, weld = np.unique(q[:, 0] << 34 | q[:, 1] << 17 | q[:, 2], return_inverse=True)
        triangles = weld.reshape(-1)[triangles]
    t = np.asarray(triangles, np.int64)
    # one key per undirected edge (smaller vertex in the high half); every edge exactly twice: in sorted order the
    # keys come in equal pairs, each pair unlike the next
    k = np.sort(np.concatenate([_edge_keys(t[:, 0], t[:, 1]), _edge_keys(t[:, 1], t[:, 2]),
                                _edge_keys(t[:, 2], t[:, 0])]))
    return bool(len(k) % 2 == 0 and np.array_equal(k[0::2], k[1::2]) and np.all(k[1:-1:2] != k[2::2]))
