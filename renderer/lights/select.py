"""Choosing the lights a shading point samples: every infinite light, and one finite light chosen by a light cut.

**Infinite lights** (dome, distant) are each sampled at every shading point, with their own shadow ray
(``infinite_light``; selection probability 1). Choosing between a sky and a lamp by a coin flip weighted by
their estimated irradiance made the flip itself the noise: on the demo scene (a rect light and a dome lighting
the same floor about equally) 64-spp relMSE was 8x that of either light alone.

**Finite lights**: a two-level light cut, spatially aware: they are grouped into at most ``MAX_CLUSTERS`` spatial
clusters (recursive median splits along the widest axis). At a shading point p a cluster is chosen in proportion
to its estimated irradiance at p,

    min(Phi_c / (4 pi max(|p - centre_c|^2, R_c^2)), pi * cap_c)    (Phi_c the cluster's power, R_c its radius,
                                                                     cap_c the brightest radiance in it)

then a light inside it in proportion to its power. Every finite light keeps a non-zero probability everywhere, so
the estimate stays unbiased; near lights are chosen far more often than far ones, which is what keeps a row of a
thousand lights quiet. ``select_pdf`` gives the same probability for a light found by BSDF sampling (MIS): 1 for
an infinite light. Cost per shading point: O(finite clusters). With ``clusters=False`` all finite lights form
one cluster (selection by power).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from renderer.kernels.struct_refs import by_reference

MAX_CLUSTERS = 64


@dataclass
class SelectEstimate:
    """One uploaded light, as selection sees it."""

    finite: bool
    power: float  # finite: radiant power Phi (pi L A; a point: 4 pi I); infinite: the irradiance it delivers
    cap: float  # finite: the brightest radiance (inf for point lights)
    pos: np.ndarray  # finite: centre
    extent: float  # finite: radius of the light's shape


@by_reference
@wp.struct
class Selection:
    count: int  # clusters: the finite ones first, then one per infinite light
    n_finite: int  # finite clusters
    kind: wp.array(dtype=wp.int32)  # 0 finite, 1 infinite
    centre: wp.array(dtype=wp.vec3)
    radius2: wp.array(dtype=wp.float32)  # squared radius (the distance below which the estimate stops rising)
    power: wp.array(dtype=wp.float32)  # finite: Phi / (4 pi); infinite: irradiance
    cap: wp.array(dtype=wp.float32)  # finite: pi * brightest radiance (or a huge number)
    first: wp.array(dtype=wp.int32)  # cluster's first entry in order / cdf
    n: wp.array(dtype=wp.int32)
    order: wp.array(dtype=wp.int32)  # light indices, cluster by cluster
    cdf: wp.array(dtype=wp.float32)  # within-cluster cumulative power, per entry of order
    light_cluster: wp.array(dtype=wp.int32)  # per light
    light_p: wp.array(dtype=wp.float32)  # per light: probability within its cluster


def _split(idx: np.ndarray, pos: np.ndarray, leaf: int) -> list[np.ndarray]:
    if len(idx) <= leaf:
        return [idx]
    p = pos[idx]
    axis = int(np.argmax(p.max(0) - p.min(0)))
    o = idx[np.argsort(p[:, axis], kind="stable")]
    h = len(o) // 2
    return _split(o[:h], pos, leaf) + _split(o[h:], pos, leaf)


def build_clusters(est: list[SelectEstimate], clusters: bool = True) -> list[np.ndarray]:
    """Light indices per cluster: finite lights split spatially, then each infinite light alone."""
    fin = np.array([i for i, e in enumerate(est) if e.finite], np.int64)
    groups: list[np.ndarray] = []
    if len(fin):
        if not clusters:
            groups.append(fin)
        else:
            pos = np.array([e.pos for e in est], np.float64)
            leaf = max(1, math.ceil(len(fin) / MAX_CLUSTERS))
            groups += _split(fin, pos, leaf)
    groups += [np.array([i]) for i, e in enumerate(est) if not e.finite]
    return groups


def upload_selection(est: list[SelectEstimate], device: str, clusters: bool = True) -> Selection:
    groups = build_clusters(est, clusters)
    kinds, centres, r2, power, cap, first, ns, order, cdf = ([] for _ in range(9))
    light_cluster = np.zeros(max(1, len(est)), np.int32)
    light_p = np.ones(max(1, len(est)), np.float32)
    at = 0
    for c, g in enumerate(groups):
        e = [est[i] for i in g]
        w = np.array([max(x.power, 0.0) for x in e], np.float64)
        if w.sum() <= 0:
            w = np.ones(len(e))
        p = w / w.sum()
        light_cluster[g] = c
        light_p[g] = p
        order += [int(i) for i in g]
        cum = np.cumsum(p)
        cum[-1] = 1.0
        cdf += list(cum)
        first.append(at)
        ns.append(len(g))
        at += len(g)
        if e[0].finite:
            pts = np.array([x.pos for x in e])
            ctr = 0.5 * (pts.min(0) + pts.max(0))
            rad = max(float(np.max(np.linalg.norm(pts - ctr, axis=1) + [x.extent for x in e])), 1e-4)
            kinds.append(0)
            centres.append(ctr)
            r2.append(rad * rad)
            power.append(w.sum() / (4.0 * math.pi))
            cap.append(min(math.pi * max(x.cap for x in e), 3.0e38))
        else:  # an infinite light: always sampled, never weighed (its estimate fields are placeholders)
            kinds.append(1)
            centres.append(np.zeros(3))
            r2.append(1.0)
            power.append(w.sum())
            cap.append(3.0e38)
    s = Selection()
    s.count = len(groups)
    s.n_finite = sum(1 for g in groups if est[g[0]].finite)
    i32 = lambda a: wp.array(np.array(a or [0], np.int32), dtype=wp.int32, device=device)  # noqa: E731
    f32 = lambda a: wp.array(np.array(a or [0.0], np.float32), dtype=wp.float32, device=device)  # noqa: E731
    s.kind, s.first, s.n, s.order = i32(kinds), i32(first), i32(ns), i32(order)
    s.centre = wp.array(np.array(centres or [np.zeros(3)], np.float32), dtype=wp.vec3, device=device)
    s.radius2, s.power, s.cap, s.cdf = f32(r2), f32(power), f32(cap), f32(cdf)
    s.light_cluster = wp.array(light_cluster, dtype=wp.int32, device=device)
    s.light_p = wp.array(light_p, dtype=wp.float32, device=device)
    return s


@wp.func
def cluster_weight(sel: Selection, c: int, p: wp.vec3):
    """A finite cluster's estimated irradiance at p (infinite lights are not chosen: each is always sampled)."""
    d = sel.centre[c] - p
    return wp.min(sel.power[c] / wp.max(wp.dot(d, d), sel.radius2[c]), sel.cap[c])


@wp.func
def infinite_light(sel: Selection, k: int) -> int:
    """The k-th infinite light (0 <= k < ``sel.count - sel.n_finite``), sampled at every shading point."""
    return sel.order[sel.first[sel.n_finite + k]]


@wp.func
def select_light(sel: Selection, p: wp.vec3, u: float):
    """A finite light chosen at p from one uniform number: (index, its probability, u rescaled to [0, 1) again);
    index -1 when no finite light can deliver anything."""
    total = float(0.0)
    acc = float(0.0)
    chosen = int(0)
    w_c = float(0.0)
    if sel.n_finite == 1:
        # one cluster (one finite light, or selection by power alone): its weight once, not in three loops (2 % of
        # a Cornell box sample); the loops below give this cluster, acc = 0 and these same bits
        total = cluster_weight(sel, 0, p)
        w_c = total
    else:
        for c in range(sel.n_finite):
            total += cluster_weight(sel, c, p)
    if not (total > 0.0):
        return int(-1), 0.0, u
    target = u * total
    if sel.n_finite != 1:
        chosen = sel.n_finite - 1
        for c in range(sel.n_finite):
            w = cluster_weight(sel, c, p)
            if acc + w > target and w > 0.0:
                chosen = c
                w_c = w
                break
            acc += w
        if w_c <= 0.0:  # rounding at the top end: the last cluster with weight
            for c in range(sel.n_finite):
                w = cluster_weight(sel, c, p)
                if w > 0.0:
                    chosen = c
                    w_c = w
            acc = total - w_c
    v = wp.clamp((target - acc) / w_c, 0.0, 0.99999994)
    first = sel.first[chosen]
    lo = int(0)
    hi = sel.n[chosen] - 1
    while lo < hi:  # first entry with cdf > v
        mid = (lo + hi) // 2
        if sel.cdf[first + mid] > v:
            hi = mid
        else:
            lo = mid + 1
    li = sel.order[first + lo]
    p_in = sel.light_p[li]
    start = sel.cdf[first + lo] - p_in
    u_rest = wp.clamp((v - start) / wp.max(p_in, 1.0e-30), 0.0, 0.99999994)
    return li, (w_c / total) * p_in, u_rest


@wp.func
def select_pdf(sel: Selection, li: int, p: wp.vec3):
    """Probability that light li is sampled at p: 1 for an infinite light, ``select_light``'s for a finite one."""
    c = sel.light_cluster[li]
    if sel.kind[c] == 1:
        return 1.0
    if sel.n_finite == 1:  # its weight over itself: 1 exactly where positive
        if not (cluster_weight(sel, 0, p) > 0.0):
            return 0.0
        return sel.light_p[li]
    total = float(0.0)
    for k in range(sel.n_finite):
        total += cluster_weight(sel, k, p)
    if not (total > 0.0):
        return 0.0
    return cluster_weight(sel, c, p) / total * sel.light_p[li]
