"""Subdivision surfaces in NumPy: Catmull-Clark, Loop and bilinear uniform refinement with semi-sharp creases and
corners, boundary interpolation, limit positions and normals, and face-varying data refined alongside.

``Refinement`` is computed once per mesh topology: a short chain of sparse stencils (one per level, then the
limit projection) applied to every motion key of the points and to every primvar, so deforming meshes stay
consistent between keys. No pxr here: ``renderer/usd/geometry/subdiv.py`` reads the USD attributes into
``SubdivOptions``. No library on the package registry offers OpenSubdiv to Python on CPU in a maintained form
(``pyopensubdiv`` 0.0.3 wraps plain Catmull-Clark without creases or face-varying data), hence this module.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from renderer.subdiv import limit as _limit
from renderer.subdiv.rules import (CATMARK, INFINITE, LINEAR_QUADS, LINEAR_TRIS, LOOP, Level, normalise_sharpness,
                                   refine)
from renderer.subdiv.stencil import Stencil
from renderer.subdiv.topology import Topology, build

SCHEMES = ("catmullClark", "loop", "bilinear")
BOUNDARY_MODES = ("none", "edgeOnly", "edgeAndCorner")
FVAR_MODES = ("none", "cornersOnly", "cornersPlus1", "cornersPlus2", "boundaries", "all")
MAX_LEVEL = 6


@dataclass(frozen=True)
class SubdivOptions:
    """The UsdGeomMesh subdivision attributes (USD token values; defaults are USD's)."""

    scheme: str = "catmullClark"
    interpolate_boundary: str = "edgeAndCorner"
    fvar_linear: str = "cornersPlus1"
    triangle_smooth: bool = False  # triangleSubdivisionRule == "smooth"
    crease_indices: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    crease_lengths: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    crease_sharpnesses: np.ndarray = field(default_factory=lambda: np.zeros(0))
    corner_indices: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    corner_sharpnesses: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _kind(scheme: str) -> str:
    return {"catmullClark": CATMARK, "loop": LOOP}.get(scheme, LINEAR_QUADS)


def _linear_of(kind: str) -> str:
    return LINEAR_TRIS if kind in (LOOP, LINEAR_TRIS) else LINEAR_QUADS


def triangle_count(counts: np.ndarray, scheme: str, levels: int) -> int:
    """Triangles after ``levels`` levels (before holes are dropped)."""
    counts = np.asarray(counts, np.int64)
    if levels == 0:
        return int(np.sum(counts - 2))
    if _kind(scheme) == LOOP:
        return int(np.sum(counts - 2)) * 4 ** levels
    return 2 * int(np.sum(counts)) * 4 ** (levels - 1)


def _crease_edges(topo: Topology, opts: SubdivOptions) -> tuple[np.ndarray, np.ndarray]:
    """(edge ids, sharpness) of the authored creases; either one sharpness per crease or one per crease edge."""
    idx = np.asarray(opts.crease_indices, np.int64)
    lengths = np.asarray(opts.crease_lengths, np.int64)
    sharp = np.asarray(opts.crease_sharpnesses, np.float64)
    if len(lengths) == 0 or np.any(lengths < 2) or int(lengths.sum()) != len(idx):
        return np.zeros(0, np.int64), np.zeros(0)
    start = np.cumsum(lengths) - lengths
    crease = np.repeat(np.arange(len(lengths)), lengths - 1)
    local = np.arange(len(crease)) - np.repeat(np.cumsum(lengths - 1) - (lengths - 1), lengths - 1)
    a = idx[start[crease] + local]
    b = idx[start[crease] + local + 1]
    if len(sharp) == len(lengths):
        s = sharp[crease]
    elif len(sharp) == len(crease):
        s = sharp
    else:
        return np.zeros(0, np.int64), np.zeros(0)
    ok = (a >= 0) & (b >= 0) & (a < topo.num_vertices) & (b < topo.num_vertices)
    ids = topo.edge_ids(a[ok], b[ok])
    return ids[ids >= 0], s[ok][ids >= 0]


def _base_level(counts, indices, num_vertices: int, opts: SubdivOptions, base_face: np.ndarray):
    """(level 0 with authored and boundary sharpness, the faces that interpolateBoundary=none hides, the authored
    (edge, vertex) sharpness alone)."""
    topo = build(counts, indices, num_vertices)
    es = np.zeros(topo.num_edges)
    vs = np.zeros(topo.num_vertices)
    ids, s = _crease_edges(topo, opts)
    np.maximum.at(es, ids, s)
    ci = np.asarray(opts.corner_indices, np.int64)
    cs = np.asarray(opts.corner_sharpnesses, np.float64)
    if len(ci) == len(cs) and len(ci):
        ok = (ci >= 0) & (ci < topo.num_vertices)
        np.maximum.at(vs, ci[ok], cs[ok])
    authored = (normalise_sharpness(es), normalise_sharpness(vs))
    boundary_edge = topo.edge_faces != 2
    es[boundary_edge] = INFINITE  # boundary and non-manifold edges are always sharp
    on_boundary = np.zeros(topo.num_vertices, bool)
    on_boundary[topo.edge_vertices[topo.edge_faces == 1].reshape(-1)] = True
    hidden = np.zeros(topo.num_faces, bool)
    if opts.interpolate_boundary == "edgeAndCorner":
        vs[on_boundary & (topo.vertex_faces == 1)] = INFINITE
    elif opts.interpolate_boundary == "none":
        # the boundary faces only support their neighbours: no surface is made for them
        hidden = np.bincount(topo.corner_face, on_boundary[topo.indices], minlength=topo.num_faces) > 0
    return Level(topo, normalise_sharpness(es), normalise_sharpness(vs), base_face), hidden, authored


@dataclass
class Refinement:
    """A mesh refined ``levels`` times: the stencils, the final level and its triangles."""

    scheme: str  # catmullClark, loop or bilinear
    levels: int
    stencils: list[Stencil]
    limit: Stencil | None
    final: Level
    tri_corners: np.ndarray  # (T, 3) corners of the final level
    tri_faces: np.ndarray  # (T,) authored face each triangle descends from
    base_counts: np.ndarray
    hidden_faces: np.ndarray  # (F0,) bool: faces with no surface (interpolateBoundary none)
    base: Level | None = None  # level 0 with its authored sharpness only, for face-varying data

    @property
    def triangles(self) -> np.ndarray:
        return self.final.topo.indices[self.tri_corners]

    @property
    def num_points(self) -> int:
        return self.final.topo.num_vertices

    def control_points(self, base_points: np.ndarray) -> np.ndarray:
        """The final level's control points (V, 3) float64 (before the limit projection)."""
        x = np.asarray(base_points, np.float64)
        for s in self.stencils:
            x = s.apply(x)
        return x

    def points(self, base_points: np.ndarray) -> np.ndarray:
        """Limit positions (V, 3) float64 of the final level's vertices for one key of the cage points."""
        x = self.control_points(base_points)
        return self.limit.apply(x) if self.limit is not None else x

    def normals(self, limit_points: np.ndarray, control_points: np.ndarray | None = None) -> np.ndarray:
        """Per-triangle-corner unit normals (T, 3, 3): exact limit normals at smooth interior vertices (from the
        final level's ``control_points``, when given), elsewhere the limit points' face normals averaged over each
        smooth sector, so sharp edges, corners and boundaries keep a hard shading edge."""
        sharp = self.final.edge_sharpness > 0
        if self.limit is None:  # bilinear: every edge is a facet edge
            sharp = np.ones_like(sharp)
        topo = self.final.topo
        sectors = _limit.corner_sectors(topo, sharp)
        n = _limit.sector_normals(topo, sectors, np.asarray(limit_points, np.float64))
        if control_points is not None and self.limit is not None:
            exact, valid = _limit.smooth_limit_normals(self.final, _kind(self.scheme),
                                                       np.asarray(control_points, np.float64))
            use = valid[topo.indices]
            # keep the orientation of the faces (an inconsistently wound cage has no outside)
            flip = np.einsum("ij,ij->i", exact[topo.indices], n) < 0
            n = np.where(use[:, None], np.where(flip[:, None], -1.0, 1.0) * exact[topo.indices], n)
        return n[self.tri_corners]

    def face_varying(self, values: np.ndarray, fv_indices: np.ndarray, mode: str) -> np.ndarray:
        """Refine face-varying data (one value index per authored face-corner, in ``base`` corner order) on the
        same topology, with the surface's creases and corners. Returns per-triangle-corner values (T, 3, C)."""
        values = np.asarray(values, np.float64)
        if values.ndim == 1:
            values = values[:, None]
        kind = _kind(self.scheme)
        linear = mode == "all" or kind not in (CATMARK, LOOP)
        fv_opts = SubdivOptions(interpolate_boundary="edgeOnly" if mode == "none" else "edgeAndCorner")
        lv, _, _ = _base_level(self.base_counts, fv_indices, len(values), fv_opts, np.arange(len(self.base_counts)))
        if mode == "boundaries":
            on_boundary = np.zeros(lv.topo.num_vertices, bool)
            on_boundary[lv.topo.edge_vertices[lv.topo.edge_faces == 1].reshape(-1)] = True
            lv.vertex_sharpness[on_boundary] = np.inf
        if self.base is not None and not linear:  # the surface's creases and corners crease its data too
            np.maximum.at(lv.edge_sharpness, lv.topo.corner_edge, self.base.edge_sharpness[self.base.topo.corner_edge])
            np.maximum.at(lv.vertex_sharpness, lv.topo.indices, self.base.vertex_sharpness[self.base.topo.indices])
        scheme = _linear_of(kind) if linear else kind
        x = values
        for _ in range(self.levels):
            lv, st = refine(lv, scheme)
            x = st.apply(x)
        lim = None if linear else _limit.limit_stencil(lv, kind)
        if lim is not None:
            x = lim.apply(x)
        return x[lv.topo.indices[self.tri_corners]]

    def vertex_values(self, values: np.ndarray) -> np.ndarray:
        """Refine per-cage-vertex data (vertex interpolation) with the surface's own stencils: (T, 3, C)."""
        v = np.asarray(values, np.float64)
        if v.ndim == 1:
            v = v[:, None]
        return self.points(v)[self.triangles]

    def varying_values(self, values: np.ndarray, base_indices: np.ndarray) -> np.ndarray:
        """Refine per-cage-vertex data linearly (varying interpolation): (T, 3, C). ``base_indices``: the
        face-vertex indices the refinement was built from."""
        v = np.asarray(values, np.float64)
        if v.ndim == 1:
            v = v[:, None]
        lv, _, _ = _base_level(self.base_counts, base_indices, len(v), SubdivOptions(),
                            np.arange(len(self.base_counts)))
        scheme = _linear_of(_kind(self.scheme))
        for _ in range(self.levels):
            lv, st = refine(lv, scheme)
            v = st.apply(v)
        return v[lv.topo.indices[self.tri_corners]]


def subdivide(counts: np.ndarray, indices: np.ndarray, num_vertices: int, opts: SubdivOptions, levels: int,
              base_face: np.ndarray | None = None) -> Refinement:
    """Refine a polygon mesh ``levels`` times (0..MAX_LEVEL). ``base_face`` maps faces to authored face numbers
    (default: themselves); Loop needs triangles (the caller triangulates other polygons first)."""
    counts = np.asarray(counts, np.int64)
    indices = np.asarray(indices, np.int64)
    if not 0 <= levels <= MAX_LEVEL:
        raise ValueError(f"subdivision level must be 0..{MAX_LEVEL}, got {levels}")
    if opts.scheme not in SCHEMES:
        raise ValueError(f"unknown subdivision scheme {opts.scheme!r}")
    kind = _kind(opts.scheme)
    if base_face is None:
        base_face = np.arange(len(counts), dtype=np.int64)
    lv, hidden, authored = _base_level(counts, indices, num_vertices, opts, np.asarray(base_face, np.int64))
    local = Level(lv.topo, lv.edge_sharpness, lv.vertex_sharpness, np.arange(len(counts), dtype=np.int64))
    stencils = []
    for _ in range(levels):
        local, st = refine(local, kind, opts.triangle_smooth)
        stencils.append(st)
    lim = _limit.limit_stencil(local, kind) if levels > 0 else None
    tri_corners, tri_local = _limit.face_triangles(local.topo)
    base_of_tri = local.base_face[tri_local]  # faces of the input arrays
    keep = ~hidden[base_of_tri]
    tri_corners, base_of_tri = tri_corners[keep], base_of_tri[keep]
    final = Level(local.topo, local.edge_sharpness, local.vertex_sharpness, local.base_face)
    return Refinement(opts.scheme, levels, stencils, lim, final, tri_corners, lv.base_face[base_of_tri], counts,
                      hidden, Level(lv.topo, authored[0], authored[1], lv.base_face))


__all__ = ["SubdivOptions", "Refinement", "subdivide", "triangle_count", "SCHEMES", "BOUNDARY_MODES",
           "FVAR_MODES", "MAX_LEVEL"]
