"""Limit surface: limit-position masks (points pushed onto the surface a refinement converges to), shading
normals per smooth sector, and triangles of the final level.

Limit masks (OpenSubdiv Sdc): Catmull-Clark on quads, smooth vertex of valence n: n/(n+5) v + 4/(n(n+5)) per
edge neighbour + 1/(n(n+5)) per diagonal neighbour (1/36, 1/9, 4/9 when regular: the bicubic B-spline at a knot);
Loop, valence n: (1 - n chi) v + chi per neighbour with chi = 1/(3/(8 beta) + n); crease vertices (both schemes):
2/3 v + 1/6 per crease neighbour; corners stay put. Remaining semi-sharpness counts as sharp.

Normals: at smooth interior vertices the exact limit normal, the cross product of the two limit tangents
(masks of Halstead et al. 1993 for Catmull-Clark, Loop's cosine/sine masks); at crease, corner and boundary
vertices the limit-point mesh's face normals averaged over each *smooth sector* (the faces around the vertex
between sharp edges), so creases keep a hard shading edge.
"""
from __future__ import annotations

import numpy as np

from renderer.subdiv.rules import CATMARK, CORNER, CREASE, LOOP, SMOOTH, Level, vertex_rules
from renderer.subdiv.stencil import Stencil
from renderer.subdiv.topology import Topology


def limit_stencil(lv: Level, scheme: str) -> Stencil | None:
    """Stencil from the level's vertices to their limit positions; None for the linear schemes."""
    if scheme not in (CATMARK, LOOP):
        return None
    topo = lv.topo
    nv = topo.num_vertices
    verts = np.arange(nv)
    rule = vertex_rules(topo, lv.vertex_sharpness, lv.edge_sharpness)
    iv, other, ie = topo.incidences()
    rows, cols, ws = [verts[rule == CORNER]], [verts[rule == CORNER]], [np.ones(int(np.sum(rule == CORNER)))]
    # crease
    cr = rule == CREASE
    rows.append(verts[cr]), cols.append(verts[cr]), ws.append(np.full(int(cr.sum()), 2.0 / 3.0))
    sel = cr[iv] & (lv.edge_sharpness[ie] > 0)
    rows.append(iv[sel]), cols.append(other[sel]), ws.append(np.full(int(sel.sum()), 1.0 / 6.0))
    # smooth
    sm = rule == SMOOTH
    n = topo.vertex_faces.astype(np.float64)
    if scheme == CATMARK:
        # valence-2 interior vertices have no smooth limit mask of their own: they stay (OpenSubdiv does the same)
        stay = sm & (n <= 2)
        rows.append(verts[stay]), cols.append(verts[stay]), ws.append(np.ones(int(stay.sum())))
        sm = sm & (n > 2)
        f = 1.0 / np.maximum(n * (n + 5.0), 1.0)
        rows.append(verts[sm]), cols.append(verts[sm]), ws.append((n / (n + 5.0))[sm])
        sel = sm[iv]
        rows.append(iv[sel]), cols.append(other[sel]), ws.append(4.0 * f[iv[sel]])
        cv = topo.indices
        sel = sm[cv]
        diag = topo.indices[topo.corner_next[topo.corner_next]]  # quads: the corner across the face
        rows.append(cv[sel]), cols.append(diag[sel]), ws.append(f[cv[sel]])
    else:
        ne = np.maximum(topo.vertex_edges, 1).astype(np.float64)
        beta = (0.625 - (0.375 + 0.25 * np.cos(2 * np.pi / ne)) ** 2) / ne
        chi = 1.0 / (3.0 / (8.0 * beta) + ne)
        rows.append(verts[sm]), cols.append(verts[sm]), ws.append((1.0 - ne * chi)[sm])
        sel = sm[iv]
        rows.append(iv[sel]), cols.append(other[sel]), ws.append(chi[iv[sel]])
    return Stencil(np.concatenate(rows), np.concatenate(cols), np.concatenate(ws), nv, nv)


def corner_sectors(topo: Topology, sharp_edge: np.ndarray) -> np.ndarray:
    """Label per corner: corners at one vertex joined across non-sharp manifold edges share a label."""
    nc = len(topo.indices)
    c = np.arange(nc)
    # each corner touches its outgoing edge and the edge coming in; across a manifold edge the corner of the
    # other face at the same vertex has the same (vertex, edge) key
    key = np.concatenate([topo.indices * topo.num_edges + topo.corner_edge,
                          topo.indices * topo.num_edges + topo.corner_edge[topo.corner_prev]])
    owner = np.concatenate([c, c])
    edge = np.concatenate([topo.corner_edge, topo.corner_edge[topo.corner_prev]])
    ok = ~sharp_edge[edge] & (topo.edge_faces[edge] == 2)
    key, owner = key[ok], owner[ok]
    order = np.argsort(key, kind="stable")
    key, owner = key[order], owner[order]
    pair = np.flatnonzero(key[1:] == key[:-1])
    a, b = owner[pair], owner[pair + 1]
    label = c.copy()
    for _ in range(int(topo.vertex_faces.max(initial=0)) + 1):  # propagate the smallest label around
        m = np.minimum(label[a], label[b])
        new = label.copy()
        np.minimum.at(new, a, m)
        np.minimum.at(new, b, m)
        if np.array_equal(new, label):
            break
        label = new
    return label


def face_triangles(topo: Topology) -> tuple[np.ndarray, np.ndarray]:
    """(corners (T, 3) of a fan of every face, face of each triangle). The final levels are quads or triangles."""
    out_c, out_f = [], []
    for n in np.unique(topo.counts):
        faces = np.flatnonzero(topo.counts == n)
        start = topo.face_start[faces]
        for k in range(1, int(n) - 1):
            out_c.append(np.stack([start, start + k, start + k + 1], axis=1))
            out_f.append(faces)
    corners = np.concatenate(out_c)
    faces = np.concatenate(out_f)
    order = np.argsort(faces, kind="stable")
    return corners[order], faces[order]


def _scatter_add(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """out[i] = sum of values[k] with index[k] == i, for (K, 3) values (bincount per column: no sorting)."""
    return np.stack([np.bincount(index, values[:, k], minlength=n) for k in range(values.shape[1])], axis=1)


def sector_normals(topo: Topology, sectors: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(C, 3) unit normal per corner: area-weighted face normals summed over the corner's sector."""
    p = points[topo.indices]  # (C, 3)
    q = points[topo.indices[topo.corner_next]]
    # Newell: the face's area vector is half the sum over its corners of p x q
    fn = _scatter_add(topo.corner_face, np.cross(p, q), topo.num_faces)
    acc = _scatter_add(sectors, fn[topo.corner_face], len(topo.indices))
    n = acc[sectors]
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    fallback = fn[topo.corner_face]
    lf = np.linalg.norm(fallback, axis=1, keepdims=True)
    n = np.where(ln > 0, n / np.where(ln > 0, ln, 1.0), fallback / np.where(lf > 0, lf, 1.0))
    return n


def _ring_positions(topo: Topology) -> tuple[np.ndarray, np.ndarray]:
    """(position of every corner in the counter-clockwise ring of faces around its vertex, closed-ring flag
    per vertex). Around vertex v the next corner after c is the one whose outgoing edge is c's incoming edge."""
    nc = len(topo.indices)
    v = topo.indices
    out_key = v * topo.num_vertices + topo.indices[topo.corner_next]
    in_key = v * topo.num_vertices + topo.indices[topo.corner_prev]
    order = np.argsort(out_key, kind="stable")
    pos = np.searchsorted(out_key[order], in_key)
    pos = np.minimum(pos, nc - 1)
    found = out_key[order][pos] == in_key
    succ = np.where(found, order[pos], -1)
    closed = np.ones(topo.num_vertices, bool)
    closed[v[~found]] = False
    # duplicate (v, w) keys mean a non-manifold or inconsistently wound ring: no closed ring there
    dup = np.flatnonzero(out_key[order][1:] == out_key[order][:-1])
    closed[v[order[dup]]] = False
    start = np.full(topo.num_vertices, nc, np.int64)
    np.minimum.at(start, v, np.arange(nc))
    ring = np.full(nc, -1, np.int64)
    cur = start[closed]
    cur = cur[cur < nc]
    for i in range(int(topo.vertex_faces.max(initial=0))):
        ring[cur] = i
        cur = succ[cur]
        cur = cur[(cur >= 0) & (ring[np.maximum(cur, 0)] < 0)]
        if len(cur) == 0:
            break
    closed &= np.bincount(v, ring >= 0, minlength=topo.num_vertices) == topo.vertex_faces
    return ring, closed


def smooth_limit_normals(lv: Level, scheme: str, control: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit limit normals (V, 3), valid (V,)) at smooth interior vertices from the limit tangent masks
    (Catmull-Clark on quads: t = sum A_n cos(2 pi i/n) e_i + (cos(2 pi i/n) + cos(2 pi (i+1)/n)) f_i, with
    A_n = 1 + cos(2 pi/n) + cos(pi/n) sqrt(2 (9 + cos(2 pi/n))); Loop: t = sum cos(2 pi i/n) e_i), the second
    tangent with sines; normal = t1 x t2. Elsewhere ``valid`` is False."""
    topo = lv.topo
    rule = vertex_rules(topo, lv.vertex_sharpness, lv.edge_sharpness)
    ring, closed = _ring_positions(topo)
    n = topo.vertex_faces.astype(np.float64)
    valid = closed & (rule == SMOOTH) & (topo.vertex_faces >= 3) & (topo.vertex_faces == topo.vertex_edges)
    v = topo.indices
    use = valid[v] & (ring >= 0)
    c = np.flatnonzero(use)
    vv = v[c]
    nn = n[vv]
    th = 2 * np.pi * ring[c] / nn
    th1 = 2 * np.pi * (ring[c] + 1) / nn
    e = control[topo.indices[topo.corner_next[c]]]
    if scheme == CATMARK:
        a = 1 + np.cos(2 * np.pi / nn) + np.cos(np.pi / nn) * np.sqrt(2 * (9 + np.cos(2 * np.pi / nn)))
        f = control[topo.indices[topo.corner_next[topo.corner_next[c]]]]
        t1 = (a * np.cos(th))[:, None] * e + (np.cos(th) + np.cos(th1))[:, None] * f
        t2 = (a * np.sin(th))[:, None] * e + (np.sin(th) + np.sin(th1))[:, None] * f
    else:
        t1 = np.cos(th)[:, None] * e
        t2 = np.sin(th)[:, None] * e
    T1 = _scatter_add(vv, t1, topo.num_vertices)
    T2 = _scatter_add(vv, t2, topo.num_vertices)
    nrm = np.cross(T1, T2)
    ln = np.linalg.norm(nrm, axis=1)
    valid &= ln > 1e-300
    return nrm / np.where(ln > 0, ln, 1.0)[:, None], valid
