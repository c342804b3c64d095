"""Polygon-mesh topology as flat NumPy arrays: corners, edges, incidences (no pxr, no Python loops per element).

A mesh is ``counts`` (F,) vertices per face and ``indices`` (C,) vertex per face-corner, C = sum(counts), as in
UsdGeomMesh. A *corner* c lies in face ``corner_face[c]`` at vertex ``indices[c]``; its outgoing edge (to the
next corner of the face) is ``corner_edge[c]``. Edges are undirected, numbered by their sorted vertex pair.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Topology:
    counts: np.ndarray  # (F,) int64
    indices: np.ndarray  # (C,) int64
    num_vertices: int
    face_start: np.ndarray  # (F,) int64 first corner of each face
    corner_face: np.ndarray  # (C,) int64
    corner_next: np.ndarray  # (C,) int64 next corner in the same face
    corner_prev: np.ndarray  # (C,) int64
    corner_edge: np.ndarray  # (C,) int64 edge from this corner to the next
    edge_keys: np.ndarray  # (E,) int64 lo * V + hi, sorted
    edge_vertices: np.ndarray  # (E, 2) int64 (lo, hi)
    edge_faces: np.ndarray  # (E,) int64 number of incident faces (1 boundary, 2 manifold, >2 non-manifold)
    vertex_faces: np.ndarray  # (V,) int64 number of incident face-corners
    vertex_edges: np.ndarray  # (V,) int64 number of incident edges

    @property
    def num_faces(self) -> int:
        return len(self.counts)

    @property
    def num_edges(self) -> int:
        return len(self.edge_keys)

    def incidences(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(vertex, other end, edge) for both ends of every edge: (2E,) each."""
        e = np.arange(self.num_edges)
        v0, v1 = self.edge_vertices[:, 0], self.edge_vertices[:, 1]
        return np.concatenate([v0, v1]), np.concatenate([v1, v0]), np.concatenate([e, e])

    def edge_ids(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Edge numbers of vertex pairs (a, b); -1 where no such edge exists."""
        a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
        key = np.minimum(a, b) * self.num_vertices + np.maximum(a, b)
        pos = np.searchsorted(self.edge_keys, key)
        pos = np.minimum(pos, max(self.num_edges - 1, 0))
        hit = (self.num_edges > 0) & (self.edge_keys[pos] == key) if self.num_edges else np.zeros(len(key), bool)
        return np.where(hit, pos, -1)

    def face_corner_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """Every (corner c, corner c2 of the same face) pair: sum(counts^2) pairs, for face-centre stencils."""
        n = self.counts[self.corner_face]  # (C,) size of each corner's face
        c = np.repeat(np.arange(len(self.indices)), n)
        first = np.repeat(self.face_start[self.corner_face], n)
        run_start = np.repeat(np.cumsum(n) - n, n)
        c2 = first + (np.arange(len(c)) - run_start)
        return c, c2


def build(counts: np.ndarray, indices: np.ndarray, num_vertices: int) -> Topology:
    counts = np.asarray(counts, np.int64)
    indices = np.asarray(indices, np.int64)
    nc = len(indices)
    face_start = np.cumsum(counts) - counts
    corner_face = np.repeat(np.arange(len(counts)), counts)
    local = np.arange(nc) - face_start[corner_face]
    last = local == counts[corner_face] - 1
    corner_next = np.where(last, face_start[corner_face], np.arange(nc) + 1)
    corner_prev = np.where(local == 0, face_start[corner_face] + counts[corner_face] - 1, np.arange(nc) - 1)
    a, b = indices, indices[corner_next]
    key = np.minimum(a, b) * num_vertices + np.maximum(a, b)
    edge_keys, corner_edge = np.unique(key, return_inverse=True)
    edge_vertices = np.stack([edge_keys // max(num_vertices, 1), edge_keys % max(num_vertices, 1)], axis=1)
    ne = len(edge_keys)
    edge_faces = np.bincount(corner_edge, minlength=ne)
    vertex_faces = np.bincount(indices, minlength=num_vertices)
    vertex_edges = np.bincount(edge_vertices.reshape(-1), minlength=num_vertices)
    return Topology(counts, indices, int(num_vertices), face_start, corner_face, corner_next, corner_prev,
                    corner_edge.reshape(-1).astype(np.int64), edge_keys, edge_vertices, edge_faces, vertex_faces,
                    vertex_edges)
