"""One level of uniform refinement: Catmull-Clark, Loop and bilinear masks with semi-sharp creases and corners.

The rules are those of OpenSubdiv's Sdc (DeRose, Kass, Truong 1998 for semi-sharp creases):

* sharpness s of an edge or vertex: 0 smooth, > 0 sharp at this level, >= ``INFINITE`` (10) sharp forever;
  children inherit s - 1 (the "uniform" crease method). Boundary and non-manifold edges are infinitely sharp.
* vertex rule from the sharpness around it: *corner* if the vertex is sharp or more than two incident edges
  are, *crease* with exactly two sharp edges, else *smooth* (a dart, one sharp edge, is smooth).
* an edge point is the smooth mask, the midpoint (crease) for s >= 1, and their blend by s for 0 < s < 1;
  a vertex point whose rule changes between parent and child levels is the blend of both rules' masks by the
  average sharpness of what stops being sharp (capped at 1).

Catmull-Clark and bilinear split every n-gon into n quads (child vertices: face points, edge points, vertex
points); Loop splits triangles into four (edge points, vertex points). ``triangle_smooth`` is USD's
``triangleSubdivisionRule = smooth`` (the 0.47 face weight of OpenSubdiv for edges of triangles).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from renderer.subdiv.stencil import Stencil
from renderer.subdiv.topology import Topology, build

INFINITE = 10.0  # OpenSubdiv's Crease::SHARPNESS_INFINITE: at or above it a crease never softens
SMOOTH, CREASE, CORNER = 0, 1, 2
CATMARK, LOOP, LINEAR_QUADS, LINEAR_TRIS = "catmark", "loop", "linear-quads", "linear-tris"


@dataclass
class Level:
    """A refinement level: topology, sharpness, and which authored face every face descends from."""

    topo: Topology
    edge_sharpness: np.ndarray  # (E,) float64
    vertex_sharpness: np.ndarray  # (V,) float64
    base_face: np.ndarray  # (F,) int64


def normalise_sharpness(s: np.ndarray) -> np.ndarray:
    s = np.maximum(np.asarray(s, np.float64), 0.0)
    return np.where(s >= INFINITE, np.inf, s)


def soften(s: np.ndarray) -> np.ndarray:
    """Children's sharpness: one less, never negative; infinite stays infinite."""
    return np.maximum(s - 1.0, 0.0)


def vertex_rules(topo: Topology, vs: np.ndarray, es: np.ndarray) -> np.ndarray:
    v, _, e = topo.incidences()
    n_sharp = np.bincount(v, (es[e] > 0).astype(np.float64), minlength=topo.num_vertices)
    return np.where((vs > 0) | (n_sharp > 2), CORNER, np.where(n_sharp == 2, CREASE, SMOOTH))


def _transition_weight(topo: Topology, vs, es, vs_c, es_c) -> np.ndarray:
    """Average sharpness of what goes from sharp to smooth between parent and child, capped at 1."""
    v, _, e = topo.incidences()
    goes = (es[e] > 0) & (es_c[e] == 0)
    total = np.bincount(v, np.where(goes, es[e], 0.0), minlength=topo.num_vertices)
    count = np.bincount(v, goes.astype(np.float64), minlength=topo.num_vertices)
    vgoes = (vs > 0) & (vs_c == 0)
    total += np.where(vgoes, vs, 0.0)
    count += vgoes
    return np.minimum(np.where(count > 0, total / np.maximum(count, 1), 0.0), 1.0)


class _Triples:
    """Accumulates (row, col, weight) triples."""

    def __init__(self):
        self.r: list[np.ndarray] = []
        self.c: list[np.ndarray] = []
        self.w: list[np.ndarray] = []

    def add(self, rows, cols, weights):
        rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
        self.r.append(rows)
        self.c.append(cols)
        self.w.append(np.broadcast_to(np.asarray(weights, np.float64), rows.shape))

    def stencil(self, num_rows: int, num_cols: int) -> Stencil:
        cat = lambda xs: np.concatenate(xs) if xs else np.zeros(0)  # noqa: E731
        return Stencil(cat(self.r), cat(self.c), cat(self.w), num_rows, num_cols)


def _add_face_centres(out: _Triples, topo: Topology, row_of_corner: np.ndarray, weight_of_corner: np.ndarray):
    """For every corner c, add weight_of_corner[c] x (centroid of c's face) to row row_of_corner[c]."""
    c, c2 = topo.face_corner_pairs()
    n = topo.counts[topo.corner_face[c]]
    sel = weight_of_corner[c] != 0
    out.add(row_of_corner[c][sel], topo.indices[c2][sel], (weight_of_corner[c] / n)[sel])


def _vertex_points(out: _Triples, lv: Level, scheme: str, row0: int, face_row0: int | None):
    """Vertex-point masks into rows row0 + v. face_row0: rows of the face points (Catmull-Clark) or None."""
    topo, vs, es = lv.topo, lv.vertex_sharpness, lv.edge_sharpness
    nv = topo.num_vertices
    verts = np.arange(nv)
    if scheme in (LINEAR_QUADS, LINEAR_TRIS):
        out.add(row0 + verts, verts, 1.0)
        return
    vs_c, es_c = soften(vs), soften(es)
    parent, child = vertex_rules(topo, vs, es), vertex_rules(topo, vs_c, es_c)
    w = _transition_weight(topo, vs, es, vs_c, es_c)
    same = parent == child
    # weights of the four masks: smooth, crease (parent's sharp edges), crease (child's), corner
    a_smooth = np.where(same, parent == SMOOTH, np.where(child == SMOOTH, 1 - w, 0.0)).astype(np.float64)
    a_crease_p = np.where(same, parent == CREASE, np.where(parent == CREASE, w, 0.0)).astype(np.float64)
    a_crease_c = np.where(same, 0.0, np.where(child == CREASE, 1 - w, 0.0))
    a_corner = np.where(parent == CORNER, np.where(same, 1.0, w), 0.0)
    out.add(row0 + verts, verts, a_corner)
    iv, other, ie = topo.incidences()
    for a, sharp in ((a_crease_p, es > 0), (a_crease_c, es_c > 0)):
        out.add(row0 + verts, verts, 0.75 * a)
        sel = sharp[ie] & (a[iv] != 0)
        out.add(row0 + iv[sel], other[sel], 0.125 * a[iv[sel]])
    # smooth masks, written so that they sum to 1 whatever the counts
    nf = np.maximum(topo.vertex_faces, 1).astype(np.float64)
    ne = np.maximum(topo.vertex_edges, 1).astype(np.float64)
    if scheme == CATMARK:
        we = wf = 1.0 / (nf * nf)
        out.add(row0 + verts, verts, a_smooth * (1.0 - (topo.vertex_edges + topo.vertex_faces) * we))
        out.add(row0 + iv, other, (a_smooth * we)[iv])
        cv = topo.indices
        _add_face_centres(out, topo, row0 + cv, (a_smooth * wf)[cv])
    else:  # Loop
        beta = (0.625 - (0.375 + 0.25 * np.cos(2 * np.pi / ne)) ** 2) / ne
        beta = np.where(ne == 3, 3.0 / 16.0, beta)
        out.add(row0 + verts, verts, a_smooth * (1.0 - ne * beta))
        out.add(row0 + iv, other, (a_smooth * beta)[iv])


def _edge_points(out: _Triples, lv: Level, scheme: str, row0: int, triangle_smooth: bool):
    topo, es = lv.topo, lv.edge_sharpness
    ne = topo.num_edges
    edges = np.arange(ne)
    v0, v1 = topo.edge_vertices[:, 0], topo.edge_vertices[:, 1]
    crease = np.ones(ne) if scheme in (LINEAR_QUADS, LINEAR_TRIS) else np.minimum(es, 1.0)
    smooth = 1.0 - crease
    out.add(row0 + edges, v0, 0.5 * crease)
    out.add(row0 + edges, v1, 0.5 * crease)
    ce = topo.corner_edge
    if scheme == CATMARK:
        fw = np.full(ne, 0.25)
        if triangle_smooth:
            tri = np.bincount(ce, (topo.counts[topo.corner_face] == 3).astype(np.float64), minlength=ne)
            fw = np.where(topo.edge_faces == 2, 0.5 * (0.47 * tri + 0.25 * (2 - tri)), fw)
        vw = 0.5 * (1.0 - 2.0 * fw)
        out.add(row0 + edges, v0, smooth * vw)
        out.add(row0 + edges, v1, smooth * vw)
        _add_face_centres(out, topo, row0 + ce, (smooth * fw)[ce])
    elif scheme == LOOP:
        out.add(row0 + edges, v0, 0.375 * smooth)
        out.add(row0 + edges, v1, 0.375 * smooth)
        opposite = topo.indices[topo.corner_prev]  # triangles: the corner before c faces c's edge
        out.add(row0 + ce, opposite, 0.125 * smooth[ce])


def _child_sharpness(child: Topology, lv: Level, vrow0: int, erow0: int):
    topo = lv.topo
    es = np.zeros(child.num_edges)
    e = np.arange(topo.num_edges)
    s = soften(lv.edge_sharpness)
    for end in (0, 1):
        ids = child.edge_ids(vrow0 + topo.edge_vertices[:, end], erow0 + e)
        es[ids[ids >= 0]] = s[ids >= 0]
    vs = np.zeros(child.num_vertices)
    vs[vrow0: vrow0 + topo.num_vertices] = soften(lv.vertex_sharpness)
    return es, vs


def refine(lv: Level, scheme: str, triangle_smooth: bool = False) -> tuple[Level, Stencil]:
    """One level: the child level and the stencil from parent vertices to child vertices."""
    topo = lv.topo
    nf, ne, nv = topo.num_faces, topo.num_edges, topo.num_vertices
    out = _Triples()
    c = np.arange(len(topo.indices))
    if scheme in (CATMARK, LINEAR_QUADS):
        f_row0, e_row0, v_row0 = 0, nf, nf + ne
        n_child = nf + ne + nv
        _add_face_centres(out, topo, topo.corner_face, 1.0 / topo.counts[topo.corner_face])
        _edge_points(out, lv, scheme, e_row0, triangle_smooth and scheme == CATMARK)
        _vertex_points(out, lv, scheme, v_row0, f_row0)
        quads = np.stack([v_row0 + topo.indices, e_row0 + topo.corner_edge, topo.corner_face,
                          e_row0 + topo.corner_edge[topo.corner_prev]], axis=1)
        child_faces, child_parent = quads.reshape(-1), topo.corner_face
        child_counts = np.full(len(c), 4, np.int64)
    else:  # Loop or linear triangles: faces must be triangles
        if np.any(topo.counts != 3):
            raise ValueError("Loop subdivision needs a triangle mesh")
        e_row0, v_row0 = 0, ne
        n_child = ne + nv
        _edge_points(out, lv, scheme, e_row0, False)
        _vertex_points(out, lv, scheme, v_row0, None)
        tri = topo.indices.reshape(-1, 3)
        ed = topo.corner_edge.reshape(-1, 3)  # edge k runs from corner k to corner k + 1
        va, vb, vc = (v_row0 + tri[:, k] for k in range(3))
        e0, e1, e2 = (e_row0 + ed[:, k] for k in range(3))
        child_faces = np.stack([np.stack([va, e0, e2], 1), np.stack([e0, vb, e1], 1), np.stack([e2, e1, vc], 1),
                                np.stack([e0, e1, e2], 1)], axis=1).reshape(-1)
        child_parent = np.repeat(np.arange(nf), 4)
        child_counts = np.full(4 * nf, 3, np.int64)
    stencil = out.stencil(n_child, nv)
    child = build(child_counts, child_faces, n_child)
    es, vs = _child_sharpness(child, lv, v_row0, e_row0)
    return Level(child, es, vs, lv.base_face[child_parent]), stencil
