"""Curves as triangles: UsdGeomBasisCurves evaluation (basis matrices, segment indexing, wrap) and sweeping.

Pure NumPy, vectorised over all curves of a prim. Conventions of the UsdGeom schema (``BasisCurves`` docs):

* A cubic segment is ``P(t) = [t^3 t^2 t 1] M [P0 P1 P2 P3]`` with the basis matrix ``M`` (``BASIS``) and vstep
  3 for bezier, 1 for bspline and catmullRom; linear segments are ``(1 - t) P0 + t P1``.
* ``periodic`` curves wrap their vertex indices; ``pinned`` bspline/catmullRom curves get the phantom points
  ``P[-1] = 2 P[0] - P[1]`` and ``P[n] = 2 P[n-1] - P[n-2]``.
* Primvars: ``constant``, ``uniform`` (per curve), ``varying`` (linear per segment, ``segments + 1`` values per
  nonperiodic curve), ``vertex`` (through the basis, like the points).

Tessellation density is the caller's choice, made per curve from its size on screen (``renderer/usd/curves``):
every segment is cut into ``m`` sub-segments (``flatness_steps``: the chord error of a cubic span stays under
a tolerance), and the polyline of samples is swept as

* a **ribbon**: two vertices per sample, ``width`` wide across ``side`` (camera-facing for thin hair, or facing
  the authored ``normals``): 2 triangles per sub-segment;
* a **tube**: ``sides`` (even) vertices per sample on a rotation-minimising frame (double reflection, Wang et al.
  2008) started across the view, so two vertices lie on the silhouette and the seen width is the authored one;
  with no view the radius is scaled by ``pi / (sides sin(pi / sides))`` so the polygon's mean projected width
  (Cauchy: perimeter / pi) is the authored width. 2 ``sides`` triangles per sub-segment.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Basis matrices of UsdGeomBasisCurves (RenderMan's), rows multiply [t^3, t^2, t, 1].
BASIS = {
    "bezier": np.array([[-1, 3, -3, 1], [3, -6, 3, 0], [-3, 3, 0, 0], [1, 0, 0, 0]], np.float64),
    "bspline": np.array([[-1, 3, -3, 1], [3, -6, 3, 0], [-3, 0, 3, 0], [1, 4, 1, 0]], np.float64) / 6.0,
    "catmullRom": np.array([[-1, 3, -3, 1], [2, -5, 4, -1], [-1, 0, 1, 0], [0, 2, 0, 0]], np.float64) / 2.0,
}
VSTEP = {"bezier": 3, "bspline": 1, "catmullRom": 1}
MAX_STEPS = 16  # sub-segments per cubic segment at most (memory per segment stays bounded)


@dataclass
class Topology:
    """How a batch of curves decomposes into segments (schema ``Segment Indexing``).

    Control points of the segments index an *extended* vertex array ``ext = P[ia] * wa + P[ib] * wb`` (the
    authored vertices, plus the phantom points of pinned curves).
    """

    ia: np.ndarray  # (E,) int64
    ib: np.ndarray  # (E,) int64
    wa: np.ndarray  # (E,) float64
    wb: np.ndarray  # (E,) float64
    seg_ctrl: np.ndarray  # (S, order) int64 indices into ext (order 2 for linear, 4 for cubic)
    seg_curve: np.ndarray  # (S,) int64 curve of each segment
    seg_index: np.ndarray  # (S,) int64 segment number within its curve
    seg_vary: np.ndarray  # (S, 2) int64 indices of the varying values at the segment's two ends
    curve_ok: np.ndarray  # (C,) bool: the curve's vertex count is valid for its type/basis/wrap
    periodic: bool
    num_varying: int  # expected length of varying primvars
    vertex_start: np.ndarray  # (C,) int64 first authored vertex of each curve

    def extend(self, values: np.ndarray) -> np.ndarray:
        """Authored per-vertex values (..., V, C) -> extended (..., E, C) (phantom points added)."""
        return values[..., self.ia, :] * self.wa[:, None] + values[..., self.ib, :] * self.wb[:, None]


def topology(counts: np.ndarray, kind: str, basis: str, wrap: str) -> Topology:
    """Segments of curves with vertex ``counts`` for ``kind`` 'linear'/'cubic', ``basis`` and ``wrap``."""
    counts = np.asarray(counts, np.int64)
    nc = len(counts)
    start = np.zeros(nc, np.int64)
    if nc:
        start[1:] = np.cumsum(counts)[:-1]
    periodic = wrap == "periodic"
    pinned = wrap == "pinned" and kind == "cubic" and basis in ("bspline", "catmullRom")
    if kind == "linear":
        order, vstep = 2, 1
        ok = counts >= (3 if periodic else 2)  # the schema's "> 2" would reject a 2-point line; accept it
        nseg = np.where(periodic, counts, counts - 1)
    else:
        order, vstep = 4, VSTEP[basis]
        if periodic:
            ok = (counts >= 4 - vstep + 1) & (counts % vstep == 0)
            nseg = counts // vstep
        elif pinned:
            ok = counts >= 2
            nseg = counts - 1
        else:
            ok = (counts >= 4) & ((counts - 4) % vstep == 0)
            nseg = (counts - 4) // vstep + 1
    nseg = np.where(ok, np.maximum(nseg, 0), 0)

    # extended vertex array: identity, or phantom points around each pinned curve
    if pinned:
        ext_count = counts + 2
        ext_start = np.zeros(nc, np.int64)
        if nc:
            ext_start[1:] = np.cumsum(ext_count)[:-1]
        e_curve = np.repeat(np.arange(nc), ext_count)
        local = np.arange(int(ext_count.sum())) - ext_start[e_curve] - 1  # -1 .. n
        n = counts[e_curve]
        first, last = local < 0, local >= n
        ia = start[e_curve] + np.clip(local, 0, np.maximum(n - 1, 0))
        ib = np.where(first, start[e_curve] + np.minimum(1, n - 1),
                      np.where(last, start[e_curve] + np.maximum(n - 2, 0), ia))
        wa = np.where(first | last, 2.0, 1.0)
        wb = np.where(first | last, -1.0, 0.0)
        base, ring = ext_start, ext_count
    else:
        ia = ib = np.arange(int(counts.sum()), dtype=np.int64)
        wa, wb = np.ones(len(ia)), np.zeros(len(ia))
        base, ring = start, counts

    seg_curve = np.repeat(np.arange(nc), nseg)
    seg_start = np.zeros(nc, np.int64)
    if nc:
        seg_start[1:] = np.cumsum(nseg)[:-1]
    j = np.arange(int(nseg.sum())) - seg_start[seg_curve]
    local = j[:, None] * vstep + np.arange(order)[None, :]
    local = local % ring[seg_curve][:, None]  # only periodic curves actually wrap
    seg_ctrl = base[seg_curve][:, None] + local

    nvary = np.where(periodic, nseg, nseg + 1) * ok
    vstart = np.zeros(nc, np.int64)
    if nc:
        vstart[1:] = np.cumsum(nvary)[:-1]
    v0 = vstart[seg_curve] + j
    v1 = np.where(periodic, vstart[seg_curve] + (j + 1) % np.maximum(nseg[seg_curve], 1), v0 + 1)
    return Topology(ia=ia, ib=ib, wa=wa, wb=wb, seg_ctrl=seg_ctrl, seg_curve=seg_curve, seg_index=j,
                    seg_vary=np.stack([v0, v1], 1), curve_ok=ok, periodic=periodic,
                    num_varying=int(nvary.sum()), vertex_start=start)


def basis_weights(kind: str, basis: str, t: np.ndarray) -> np.ndarray:
    """(N, order) weights of the control points at parameters t (N,)."""
    t = np.asarray(t, np.float64)
    if kind == "linear":
        return np.stack([1.0 - t, t], 1)
    tp = np.stack([t ** 3, t ** 2, t, np.ones_like(t)], 1)
    return tp @ BASIS[basis]


def evaluate(ctrl: np.ndarray, kind: str, basis: str, seg: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Positions (..., N, C) on segments ``seg`` (N,) at t (N,), from control values ctrl (..., S, order, C)."""
    w = basis_weights(kind, basis, t)  # (N, order)
    return np.einsum("...noc,no->...nc", ctrl[..., seg, :, :], w)


def flatness_steps(ctrl: np.ndarray, kind: str, basis: str, tol: np.ndarray) -> np.ndarray:
    """Sub-segments per segment so a polyline stays within ``tol`` (S,) of each cubic segment (ctrl (S, 4, 3)).

    The chord error of n uniform steps of a cubic is at most max|P''| / (8 n^2), and max|P''| of the Bezier form
    B0..B3 is 6 max(|B0 - 2 B1 + B2|, |B1 - 2 B2 + B3|).
    """
    if kind == "linear":
        return np.ones(len(ctrl), np.int64)
    to_bezier = np.linalg.inv(BASIS["bezier"]) @ BASIS[basis]
    b = np.einsum("ij,sjc->sic", to_bezier, ctrl)
    d2 = 6.0 * np.maximum(np.linalg.norm(b[:, 0] - 2 * b[:, 1] + b[:, 2], axis=1),
                          np.linalg.norm(b[:, 1] - 2 * b[:, 2] + b[:, 3], axis=1))
    n = np.ceil(np.sqrt(d2 / (8.0 * np.maximum(tol, 1e-30))))
    return np.clip(np.nan_to_num(n, nan=1.0), 1, MAX_STEPS).astype(np.int64)


@dataclass
class Samples:
    """Sample points along the curves: polylines to sweep, in curve order."""

    seg: np.ndarray  # (N,) segment of each sample
    t: np.ndarray  # (N,) parameter within the segment
    curve: np.ndarray  # (N,) curve of each sample
    closed: np.ndarray  # (C',) bool per polyline (periodic)
    poly_start: np.ndarray  # (C',) first sample of each polyline
    poly_count: np.ndarray  # (C',) samples per polyline


def sample_params(topo: Topology, steps: np.ndarray) -> Samples:
    """Samples t = k / m (k = 0..m-1) of every segment, plus t = 1 on the last segment of an open curve."""
    steps = np.asarray(steps, np.int64)
    s_of = np.repeat(np.arange(len(steps)), steps)
    first = np.zeros(len(steps), np.int64)
    if len(steps):
        first[1:] = np.cumsum(steps)[:-1]
    k = np.arange(int(steps.sum())) - first[s_of]
    t = k / steps[s_of]
    seg, tt = s_of, t.astype(np.float64)
    if not topo.periodic and len(steps):
        last = np.ones(len(steps), bool)
        last[:-1] = topo.seg_curve[1:] != topo.seg_curve[:-1]
        ends = np.nonzero(last)[0]
        # insert t = 1 after the last sample of each curve's last segment
        pos = first[ends] + steps[ends]
        seg = np.insert(seg, pos, ends)
        tt = np.insert(tt, pos, 1.0)
    curve = topo.seg_curve[seg] if len(seg) else np.zeros(0, np.int64)
    polys, starts, cnts = np.unique(curve, return_index=True, return_counts=True)
    return Samples(seg=seg, t=tt, curve=curve, closed=np.full(len(polys), topo.periodic),
                   poly_start=starts.astype(np.int64), poly_count=cnts.astype(np.int64))


def primvar_at(values: np.ndarray, interpolation: str, topo: Topology, kind: str, basis: str,
               smp: Samples) -> np.ndarray | None:
    """A primvar (n, C) of any curve interpolation at the samples (N, C); None when its size does not fit."""
    v = np.asarray(values, np.float64)
    if v.ndim == 1:
        v = v[:, None]
    if len(v) == 0:
        return None
    if interpolation == "constant":
        return np.broadcast_to(v[0], (len(smp.seg), v.shape[1])).copy()
    if interpolation == "uniform":
        if len(v) < len(topo.curve_ok):
            return None
        return v[smp.curve]
    if interpolation == "varying":
        if len(v) < topo.num_varying:
            return None
        a, b = v[topo.seg_vary[smp.seg, 0]], v[topo.seg_vary[smp.seg, 1]]
        return a + (b - a) * smp.t[:, None]
    if interpolation == "vertex":
        if len(v) < int(max(topo.ia.max(initial=-1), topo.ib.max(initial=-1))) + 1:
            return None
        return evaluate(topo.extend(v)[topo.seg_ctrl], kind, basis, smp.seg, smp.t)
    return None


# ---------------------------------------------------------------------------------------------------------------
# Sweeping polylines


def _unit(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    out = v / np.where(n > 1e-30, n, 1.0)
    if fallback is not None:
        out = np.where(n > 1e-30, out, fallback)
    return out


def polyline_tangents(p: np.ndarray, smp: Samples) -> np.ndarray:
    """Unit tangents (..., N, 3) by central differences within each polyline (one-sided at open ends)."""
    n = p.shape[-2]
    idx = np.arange(n)
    poly = np.repeat(np.arange(len(smp.poly_start)), smp.poly_count)
    st, cnt = smp.poly_start[poly], smp.poly_count[poly]
    loc = idx - st
    closed = smp.closed[poly]
    nxt = np.where(closed, st + (loc + 1) % cnt, np.minimum(idx + 1, st + cnt - 1))
    prv = np.where(closed, st + (loc - 1) % cnt, np.maximum(idx - 1, st))
    return _unit(p[..., nxt, :] - p[..., prv, :], np.array([0.0, 0.0, 1.0]))


def _any_perpendicular(t: np.ndarray) -> np.ndarray:
    a = np.where(np.abs(t[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    return _unit(np.cross(t, a))


def rotation_minimising_frames(p: np.ndarray, tan: np.ndarray, smp: Samples,
                                start: np.ndarray | None = None) -> np.ndarray:
    """Unit normals u (N, 3) perpendicular to the tangents, transported along each polyline (double reflection)
    from ``start`` (C', 3) at each polyline's first sample (any perpendicular when None)."""
    u = np.empty_like(p)
    st, cnt = smp.poly_start, smp.poly_count
    first = _any_perpendicular(tan[st])
    if start is not None:
        s0 = start - np.sum(start * tan[st], axis=1, keepdims=True) * tan[st]
        first = _unit(s0, first)
    u[st] = first
    for k in range(1, int(cnt.max(initial=0))):
        live = cnt > k
        i = st[live] + k
        j = i - 1
        v1 = p[i] - p[j]
        c1 = np.sum(v1 * v1, axis=1, keepdims=True)
        c1 = np.where(c1 > 1e-30, c1, 1.0)
        r_l = u[j] - (2.0 / c1) * np.sum(v1 * u[j], axis=1, keepdims=True) * v1
        t_l = tan[j] - (2.0 / c1) * np.sum(v1 * tan[j], axis=1, keepdims=True) * v1
        v2 = tan[i] - t_l
        c2 = np.sum(v2 * v2, axis=1, keepdims=True)
        c2 = np.where(c2 > 1e-30, c2, 1.0)
        r = r_l - (2.0 / c2) * np.sum(v2 * r_l, axis=1, keepdims=True) * v2
        r = r - np.sum(r * tan[i], axis=1, keepdims=True) * tan[i]  # re-orthogonalise against rounding
        u[i] = _unit(r, _any_perpendicular(tan[i]))
    return u


def _strip_pairs(smp: Samples) -> tuple[np.ndarray, np.ndarray]:
    """(i, i + 1) sample pairs joined by a sub-segment, within polylines (closing the closed ones)."""
    n = int(smp.poly_count.sum())
    idx = np.arange(n)
    poly = np.repeat(np.arange(len(smp.poly_start)), smp.poly_count)
    st, cnt = smp.poly_start[poly], smp.poly_count[poly]
    loc = idx - st
    has_next = (loc + 1 < cnt) | (smp.closed[poly] & (cnt > 2))
    a = idx[has_next]
    b = st[has_next] + (loc[has_next] + 1) % cnt[has_next]
    return a, b


def ribbon(p: np.ndarray, side: np.ndarray, facing: np.ndarray, width: np.ndarray, smp: Samples):
    """Ribbon of ``width`` (N,) across unit ``side`` (N, 3) through p (K, N, 3).

    Returns (points (K, 2N, 3), triangles (2M, 3), per-corner normals (2M, 3, 3) = ``facing``, triangle -> sample
    pair (2M,)). Vertex 2i is p_i - side w/2, 2i + 1 is p_i + side w/2.
    """
    half = (0.5 * width)[:, None] * side
    pts = np.stack([p - half, p + half], axis=-2).reshape(*p.shape[:-2], -1, 3)
    a, b = _strip_pairs(smp)
    l0, r0, l1, r1 = 2 * a, 2 * a + 1, 2 * b, 2 * b + 1
    tris = np.concatenate([np.stack([l0, r0, r1], 1), np.stack([l0, r1, l1], 1)])
    f = facing.astype(np.float32)
    nrm = np.concatenate([np.stack([f[a], f[a], f[b]], 1), np.stack([f[a], f[b], f[b]], 1)])
    pair = np.concatenate([a, a])
    return pts, tris, nrm, pair


def tube(p: np.ndarray, u: np.ndarray, tan: np.ndarray, width: np.ndarray, sides: int, smp: Samples,
         mean_width: bool = True):
    """Tube of diameter ``width`` (N,) with ``sides`` sides around p (K, N, 3) on frames u (K, N, 3), tan (K, N, 3).

    ``mean_width``: scale the polygon to the circle's mean projected width (orientation unknown); otherwise its
    vertices lie on the circle, which with u across the view puts two of them exactly on the silhouette.
    Returns (points (K, N sides, 3), triangles, per-corner radial normals (from key 0), triangle -> sample pair).
    """
    th = 2.0 * np.pi * np.arange(sides) / sides
    c, s = np.cos(th), np.sin(th)
    v = np.cross(tan, u)
    radial = c[:, None] * u[..., None, :] + s[:, None] * v[..., None, :]  # (K, N, sides, 3)
    r = 0.5 * width * ((np.pi / (sides * np.sin(np.pi / sides))) if mean_width else 1.0)
    pts = (p[..., None, :] + r[:, None, None] * radial).reshape(*p.shape[:-2], -1, 3)
    a, b = _strip_pairs(smp)
    j = np.arange(sides)
    jn = (j + 1) % sides
    va = a[:, None] * sides
    vb = b[:, None] * sides
    q0, q1, q2, q3 = va + j, va + jn, vb + jn, vb + j  # (M, sides)
    tris = np.concatenate([np.stack([q0, q1, q2], -1).reshape(-1, 3), np.stack([q0, q2, q3], -1).reshape(-1, 3)])
    rad0 = radial[0] if radial.ndim == 4 else radial
    n_flat = rad0.reshape(-1, 3).astype(np.float32)
    nrm = n_flat[tris]
    pair = np.concatenate([np.repeat(a, sides), np.repeat(a, sides)])
    return pts, tris, nrm, pair


def tube_sides(radius_px: np.ndarray, max_sides: int = 24) -> np.ndarray:
    """Sides of a tube whose silhouette polygon stays within half a pixel of the circle of radius_px pixels."""
    r = np.maximum(np.asarray(radius_px, np.float64), 1e-9)
    n = np.pi / np.arccos(np.clip(1.0 - 0.5 / r, -1.0, 1.0))
    n = 2 * np.ceil(n / 2)  # even, so a vertex pair can sit on both sides of the silhouette
    return np.clip(n, 4, max_sides).astype(np.int64)
