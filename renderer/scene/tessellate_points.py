"""Points as triangles: low-poly spheres, and discs (camera-facing for tiny points, or facing authored normals).

Pure NumPy, vectorised over every point of a batch. Sizes are chosen so that *coverage* is right, which is what
a particle render is judged on:

* a sphere of diameter ``w`` is an icosphere (20, 80 or 320 triangles) scaled so that its surface area is
  ``pi w^2`` (a convex body's mean projected area is a quarter of its surface area, Cauchy), so on average over
  orientations it covers the disc of the true sphere;
* a disc is a regular n-gon scaled to the area ``pi w^2 / 4`` (hexagon: 4 triangles, octagon: 6).
"""
from __future__ import annotations

import numpy as np


def _icosahedron() -> tuple[np.ndarray, np.ndarray]:
    g = (1.0 + 5.0 ** 0.5) / 2.0
    v = np.array([(-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g), (0, -1, -g), (0, 1, -g),
                  (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1)], np.float64)
    f = np.array([(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
                  (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
                  (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)], np.int64)
    return v / np.linalg.norm(v, axis=1, keepdims=True), f


def icosphere(level: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere subdivided ``level`` times: (vertices (V, 3) on the unit sphere, triangles (20 4^level, 3))."""
    v, f = _icosahedron()
    for _ in range(level):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = v[uniq[:, 0]] + v[uniq[:, 1]]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = len(v) + inv.reshape(3, -1).T  # (F, 3): midpoints of edges 01, 12, 20
        v = np.concatenate([v, mid])
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        f = np.concatenate([np.stack([a, m[:, 0], m[:, 2]], 1), np.stack([b, m[:, 1], m[:, 0]], 1),
                            np.stack([c, m[:, 2], m[:, 1]], 1), m])
    return v, f


def area_scale(v: np.ndarray, f: np.ndarray) -> float:
    """Factor making a polyhedron inscribed in the unit sphere have the unit sphere's surface area 4 pi."""
    a = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum()
    return float(np.sqrt(4.0 * np.pi / a))


SPHERES = {level: icosphere(level) for level in (0, 1, 2)}
SPHERE_SCALE = {level: area_scale(*SPHERES[level]) for level in SPHERES}


def sphere_level(diameter_px: np.ndarray) -> np.ndarray:
    """Icosphere level for a sphere this many pixels across: 20 triangles under 12 px, 80 under 48, else 320."""
    d = np.asarray(diameter_px, np.float64)
    return np.where(d < 12.0, 0, np.where(d < 48.0, 1, 2)).astype(np.int64)


def spheres(centres: np.ndarray, diameter: np.ndarray, level: int):
    """Icospheres at centres (K, N, 3) of ``diameter`` (N,).

    Returns (points (K, N Vs, 3), triangles (N Fs, 3), per-corner normals (N Fs, 3, 3), triangle -> point (N Fs,)).
    """
    v, f = SPHERES[level]
    r = 0.5 * np.asarray(diameter, np.float64) * SPHERE_SCALE[level]
    n = centres.shape[-2]
    pts = (centres[..., :, None, :] + r[:, None, None] * v[None]).reshape(*centres.shape[:-2], -1, 3)
    tris = (np.arange(n)[:, None, None] * len(v) + f[None]).reshape(-1, 3)
    nrm = np.broadcast_to(v[f].astype(np.float32)[None], (n, len(f), 3, 3)).reshape(-1, 3, 3)
    owner = np.repeat(np.arange(n), len(f))
    return pts, tris, nrm, owner


def disc_polygon(sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A regular polygon of unit *area-equivalent* radius (area pi) in the XY plane: (vertices (n, 2), fan)."""
    th = 2.0 * np.pi * np.arange(sides) / sides
    circum = np.sqrt(2.0 * np.pi / (sides * np.sin(2.0 * np.pi / sides)))  # polygon area = pi
    v = circum * np.stack([np.cos(th), np.sin(th)], 1)
    fan = np.stack([np.zeros(sides - 2, np.int64), np.arange(1, sides - 1), np.arange(2, sides)], 1)
    return v, fan


def discs(centres: np.ndarray, diameter: np.ndarray, normal: np.ndarray, sides: int = 6):
    """Discs at centres (K, N, 3) of ``diameter`` (N,) facing unit ``normal`` (N, 3).

    Returns (points (K, N sides, 3), triangles, per-corner normals, triangle -> point), like ``spheres``.
    """
    v2, fan = disc_polygon(sides)
    nrm = np.asarray(normal, np.float64)
    a = np.where(np.abs(nrm[:, :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    u = np.cross(nrm, a)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(nrm, u)
    r = 0.5 * np.asarray(diameter, np.float64)
    off = r[:, None, None] * (v2[None, :, :1] * u[:, None, :] + v2[None, :, 1:] * w[:, None, :])  # (N, sides, 3)
    n = centres.shape[-2]
    pts = (centres[..., :, None, :] + off).reshape(*centres.shape[:-2], -1, 3)
    tris = (np.arange(n)[:, None, None] * sides + fan[None]).reshape(-1, 3)
    nf = np.repeat(nrm.astype(np.float32), len(fan), axis=0)
    corner_n = np.repeat(nf[:, None, :], 3, axis=1)
    owner = np.repeat(np.arange(n), len(fan))
    return pts, tris, corner_n, owner
