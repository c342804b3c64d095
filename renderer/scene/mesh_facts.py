"""Plain NumPy facts about meshes that several modules need."""
from __future__ import annotations

import numpy as np


def _edge_keys(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.minimum(a, b) << 32 | np.maximum(a, b)


def _mix(z: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser, in place on a uint64 array: a bijection that scatters nearby keys."""
    z ^= z >> np.uint64(30)
    z *= np.uint64(0xBF58476D1CE4E5B9)
    z ^= z >> np.uint64(27)
    z *= np.uint64(0x94D049BB133111EB)
    z ^= z >> np.uint64(31)
    return z


def _odd_edge_hash(vertex_keys: np.ndarray, t: np.ndarray) -> int:
    """XOR over the undirected edges of triangles t (T, 3) of a 64-bit hash of each, an edge being the unordered
    pair of its vertices' keys (so vertices with equal keys are one vertex): 0 when every edge occurs an even
    number of times, non-zero but with probability ~2^-64 when one occurs an odd number of times. Symmetric in the
    two ends by hashing the sum of their own hashes."""
    h = _mix(vertex_keys.astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15))
    out = 0
    for a, b in ((0, 1), (1, 2), (2, 0)):
        out ^= int(np.bitwise_xor.reduce(_mix(h[t[:, a]] + h[t[:, b]])))
    return out


def is_closed(triangles: np.ndarray, points: np.ndarray | None = None) -> bool:
    """Does a triangle mesh bound a solid? Every undirected edge is shared by exactly two triangles.

    Vertices at the same position are welded first (meshes split at UV seams are still solids). Closed meshes
    refract and absorb (a glass ball); open ones are thin (a window pane, a leaf).
    """
    if len(triangles) == 0:
        return False
    t = np.asarray(triangles, np.int64)
    if points is not None:  # weld on a grid of 1e-5 of the extent: seam copies differ by rounding
        pts = np.asarray(points, np.float64).reshape(-1, 3)
        cell = max(float(np.ptp(pts, axis=0).max()), 1e-30) * 1e-5
        q = np.round((pts - pts.min(axis=0)) / cell).astype(np.int64)  # each in [0, 1e5]: 17 bits, one int64 key
        vertex_keys = q[:, 0] << 34 | q[:, 1] << 17 | q[:, 2]
    else:
        vertex_keys = np.arange(int(t.max()) + 1, dtype=np.int64)
    # An open mesh has border edges, which occur once: rejected in one pass over the welded edges, without
    # welding's sort or the edges' (a 10M-triangle terrain: 1.4 s instead of 4.7 s). A mesh that passes is checked exactly.
    if _odd_edge_hash(vertex_keys, t) != 0:
        return False
    if points is not None:
        _, weld = np.unique(vertex_keys, return_inverse=True)
        t = weld.reshape(-1)[t]
    # one key per undirected edge (smaller vertex in the high half); every edge exactly twice: in sorted order the
    # keys come in equal pairs, each pair unlike the next
    k = np.sort(np.concatenate([_edge_keys(t[:, 0], t[:, 1]), _edge_keys(t[:, 1], t[:, 2]),
                                _edge_keys(t[:, 2], t[:, 0])]))
    return bool(len(k) % 2 == 0 and np.array_equal(k[0::2], k[1::2]) and np.all(k[1:-1:2] != k[2::2]))
