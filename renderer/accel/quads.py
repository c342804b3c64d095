"""Triangles paired into quads for Embree, and the way back from a quad's hit to the triangle of ours.

Embree stores a quad (v0, v1, v2, v3) as the two triangles (v0, v1, v3) and (v2, v3, v1), four quads to a leaf:
eight triangles in the memory and the box tests that four triangles of a triangle mesh take. Most meshes are
triangulated quads or close to it, so pairing each triangle with the neighbour across its longest edge (a quad's
diagonal) pairs nearly all of them: 98.7 % of the heavy bench scene's million triangles. A triangle left alone is
the quad (t0, t1, t2, t2), whose second half has no area and is never hit.

``pair_triangles`` returns the quads and, per quad, a code for each half: the triangle's index times 4 plus k, the
corner its shared edge starts from. The half's corners are the triangle's own, rotated to start at corner k + 2, so
``quad_triangle`` maps Embree's (u, v) back to the triangle's barycentrics without reading its corners. Pairs
are made only across an edge that exactly two triangles share, in opposite directions (consistently wound), and
that is the longest edge of both.
"""
from __future__ import annotations

import numpy as np
import warp as wp

MAX_TRIANGLES = 1 << 29  # a code (index * 4 + k) fits an int32


def pair_triangles(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quads (Q, 4) uint32 over ``triangles`` (T, 3) and their codes (Q, 2) int32: for the first half
    (v0, v1, v3) and the second (v2, v3, v1) the triangle index * 4 + k (see the module docstring); a lone
    triangle's second code repeats its first. Quads appear in the order of their first triangle."""
    tris = np.ascontiguousarray(triangles, np.int64).reshape(-1, 3)
    n = len(tris)
    if n >= MAX_TRIANGLES:
        raise ValueError(f"{n} triangles: at most {MAX_TRIANGLES - 1} can be paired")
    idx = np.arange(n)
    pts = np.asarray(points, np.float32)
    c0, c1, c2 = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    lengths = np.stack([_norm2(c1 - c0), _norm2(c2 - c1), _norm2(c0 - c2)], 1)  # edge k: corner k to k + 1
    k = lengths.argmax(1)
    a, b = tris[idx, k], tris[idx, (k + 1) % 3]
    proper = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])
    nv = max(int(tris.max(initial=0)) + 1, 1)
    key = np.where(proper, np.minimum(a, b) * nv + np.maximum(a, b), -1 - idx)  # a lone key for a degenerate one
    order = np.argsort(key, kind="stable")
    sk = key[order]
    same = sk[1:] == sk[:-1]  # neighbours in sorted order that share their longest edge
    before = np.concatenate([[False], same[:-1]])
    after = np.concatenate([same[1:], [False]])
    two = same & ~before & ~after  # exactly two triangles on that edge
    i, j = order[:-1][two], order[1:][two]
    wound = a[i] == b[j]  # opposite directions along the edge
    i, j = i[wound], j[wound]
    first, second = np.minimum(i, j), np.maximum(i, j)
    partner = np.full(n, -1, np.int64)
    partner[first] = second
    lead = np.ones(n, bool)
    lead[second] = False  # a pair's quad is listed at its first triangle
    t = idx[lead]
    u = partner[t]
    paired = u >= 0
    ka, kb = k[t], np.where(paired, k[np.maximum(u, 0)], 1)
    other = np.where(paired, u, t)
    quads = np.stack([tris[t, (ka + 2) % 3], tris[t, ka], tris[other, (kb + 2) % 3], tris[t, (ka + 1) % 3]], 1)
    lone = ~paired  # (t0, t1, t2, t2): the whole triangle is the first half, with k = 1
    quads[lone] = tris[t[lone]][:, [0, 1, 2, 2]]
    ka = np.where(paired, ka, 1)
    codes = np.stack([t * 4 + ka, np.where(paired, u * 4 + kb, t * 4 + ka)], 1)
    return quads.astype(np.uint32), codes.astype(np.int32)


def _norm2(v: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", v, v)


@wp.func
def quad_triangle(codes: wp.array(dtype=wp.int32), off: int, quad: int, u: float, v: float):
    """A hit on ``quad`` at Embree's quad parameters (u, v): the triangle of the mesh it lies on and that
    triangle's barycentrics (b1, b2) of its corners 1 and 2. ``codes`` holds two entries per quad from ``off``
    (``pair_triangles``). Embree's first half (v0, v1, v3) covers u + v <= 1, where (u, v) are its own
    barycentrics; on the second (v2, v3, v1) they are 1 - u and 1 - v."""
    second = u + v > 1.0
    code = codes[off + 2 * quad + wp.where(second, 1, 0)]
    s = wp.where(second, 1.0 - u, u)
    t = wp.where(second, 1.0 - v, v)
    k = code & 3
    w = wp.vec3(1.0 - s - t, s, t)  # weights of the half's corners: the triangle's corners k + 2, k, k + 1
    return code >> 2, w[(2 - k) % 3], w[(3 - k) % 3]
