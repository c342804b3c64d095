"""Plain NumPy facts about meshes that several modules need."""
from __future__ import annotations

import numpy as np


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
        _, weld = np.unique(np.round(pts / cell), axis=0, return_inverse=True)
        triangles = weld.reshape(-1)[triangles]
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    e = np.sort(e, axis=1)
    _, counts = np.unique(e[:, 0].astype(np.int64) << 32 | e[:, 1].astype(np.int64), return_counts=True)
    return bool(np.all(counts == 2))
