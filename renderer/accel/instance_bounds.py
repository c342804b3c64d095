"""World boxes of instances for the top level: each instance's box at the top level's time keys.

An instance's box is placed from a **cut** of its mesh's hierarchy: up to ``cut_size`` node boxes that together
hold every primitive (the root, then repeatedly the inner node of largest half area replaced by its two
children). The eight corners of the root box alone, placed under a rotation, give a box up to sqrt 3 wider per
axis than the placed mesh: the usd-wg teapot layout's 1000 teapots, turned about their vertical axis, had top-level
boxes of 1.56x the surface area of their exact ones, and a ray entered (transformed into, tested against the
root of) an instance it could not hit that much more often. A cut of 64 boxes brings that to 1.08x. Every box of
a cut lies in the root box, so the placed cut lies in the placed root box: never looser, and conservative by
construction (each primitive lies in one of the cut's boxes).

Moving instances are placed the same way at each time they are measured at (``instance_key_bounds``). A scene
places at most ``CUT_BUDGET`` boxes in all: a PointInstancer of 100 000 instances spent 0.5 s of its 2 s
preparation placing 10 boxes each at a budget of 2^20; at 2^18 it places 2 each in 0.1 s.
"""
from __future__ import annotations

import heapq

import numpy as np

from renderer.accel.build import Bvh
from renderer.motion.transform import MotionTransform, matrix_at, place_boxes

SUBSTEPS = 8  # samples per top-level segment when measuring how far curved motion leaves the linear blend
CUT_BOXES = 64  # node boxes per instance at most
CUT_BUDGET = 1 << 18  # node boxes placed per scene at most (0.1 s of NumPy): from 2^18 instances on, root boxes only


def cut_size(num_instances: int) -> int:
    """Boxes per instance's cut in a scene of ``num_instances`` instances."""
    return int(np.clip(CUT_BUDGET // max(num_instances, 1), 1, CUT_BOXES))


def box_cut(bvh: Bvh, count: int) -> np.ndarray:
    """Up to ``count`` node indices of ``bvh`` whose boxes together hold every primitive: from the root, the inner
    node of largest key-averaged half area is replaced by its two children until there are ``count`` nodes or
    only leaves."""
    def area(n: int) -> float:
        d = np.maximum(bvh.node_upper[n].astype(np.float64) - bvh.node_lower[n], 0.0)  # (K, 3)
        return float((d[:, 0] * d[:, 1] + d[:, 1] * d[:, 2] + d[:, 2] * d[:, 0]).mean())

    leaves: list[int] = []
    inner = [(-area(0), 0)]
    if bvh.node_a[0] < 0:
        return np.zeros(1, np.int64)
    while inner and len(inner) + len(leaves) < count:
        _, n = heapq.heappop(inner)
        for c in (int(bvh.node_a[n]), int(bvh.node_b[n])):
            if bvh.node_a[c] < 0:
                leaves.append(c)
            else:
                heapq.heappush(inner, (-area(c), c))
    return np.array(sorted(leaves + [n for _, n in inner]), np.int64)


def cut_boxes_at(bvh: Bvh, nodes: np.ndarray, times: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (n, C, 3) of the cut ``nodes`` at times s (n,), interpolated between the mesh's point keys
    ``times``."""
    lo = bvh.node_lower[nodes].astype(np.float64).transpose(1, 0, 2)  # (K, C, 3)
    hi = bvh.node_upper[nodes].astype(np.float64).transpose(1, 0, 2)
    if len(times) == 1:
        return np.repeat(lo, len(s), 0), np.repeat(hi, len(s), 0)
    idx = np.clip(np.searchsorted(times, s, side="right"), 1, len(times) - 1)
    t0, t1 = times[idx - 1], times[idx]
    u = np.clip((s - t0) / np.maximum(t1 - t0, 1e-30), 0.0, 1.0)[:, None, None]
    return lo[idx - 1] * (1 - u) + lo[idx] * u, hi[idx - 1] * (1 - u) + hi[idx] * u


def place_cut(m: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World boxes (n, 3) of the unions of boxes lo/hi (n, C, 3) (or (1, C, 3), shared) under column-vector
    matrices m (n, 4, 4): the bounds of all their corners placed (``place_boxes``, each box under its matrix)."""
    n, c = len(m), lo.shape[1]
    wlo, whi = place_boxes(np.repeat(m, c, axis=0), np.broadcast_to(lo, (n, c, 3)).reshape(-1, 3),
                           np.broadcast_to(hi, (n, c, 3)).reshape(-1, 3))
    return wlo.reshape(n, c, 3).min(1), whi.reshape(n, c, 3).max(1)


def still_world_boxes(m: np.ndarray, bvh: Bvh, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World boxes (n, 3) of one still mesh (hierarchy ``bvh``, cut ``nodes``) under matrices m (n, 4, 4)."""
    lo, hi = cut_boxes_at(bvh, nodes, np.zeros(1), np.zeros(1))
    return place_cut(m, lo, hi)


def _world_box(xf: MotionTransform, lo: np.ndarray, hi: np.ndarray, s: np.ndarray):
    """World boxes (n, 3) of the box unions lo/hi (n, C, 3) under xf at times s (n,)."""
    return place_cut(np.array([matrix_at(xf, float(si)) for si in s]), lo, hi)


def instance_key_bounds(inst, mesh_bvh: Bvh, mesh_times: np.ndarray, nkeys: int, nodes: np.ndarray | None = None):
    """World boxes of an instance at ``nkeys`` uniform shutter times, padded for curved motion (``nodes``: the cut
    of ``mesh_bvh`` to place, the root if None).

    Between two keys the traversal blends the key boxes linearly; the true box at an intermediate time (a
    rotation, an arc) may poke out of that blend. We measure the excess at SUBSTEPS times per segment and grow
    both keys of the segment by it, plus a curvature bound for the motion between measured times.
    """
    nodes = np.zeros(1, np.int64) if nodes is None else nodes
    if nkeys == 1 or (inst.transform.num_keys == 1 and len(mesh_times) == 1):
        lo, hi = cut_boxes_at(mesh_bvh, nodes, mesh_times, np.zeros(1))
        wlo, whi = _world_box(inst.transform, lo, hi, np.zeros(1))
        return np.repeat(wlo, nkeys, 0), np.repeat(whi, nkeys, 0)
    key_t = np.linspace(0.0, 1.0, nkeys)
    lo, hi = cut_boxes_at(mesh_bvh, nodes, mesh_times, key_t)
    klo, khi = _world_box(inst.transform, lo, hi, key_t)
    nseg = nkeys - 1
    frac = (np.arange(1, SUBSTEPS) / SUBSTEPS)
    sub_t = (key_t[:-1, None] + frac[None, :] / nseg).reshape(-1)
    slo, shi = cut_boxes_at(mesh_bvh, nodes, mesh_times, sub_t)
    wlo, whi = _world_box(inst.transform, slo, shi, sub_t)
    wlo = wlo.reshape(nseg, SUBSTEPS - 1, 3)
    whi = whi.reshape(nseg, SUBSTEPS - 1, 3)
    f = frac[None, :, None]
    blend_lo = klo[:-1, None] * (1 - f) + klo[1:, None] * f
    blend_hi = khi[:-1, None] * (1 - f) + khi[1:, None] * f
    # all measured boxes of a segment, its two ends included: their second differences bound how far the
    # path can bulge between measured times (a chord of a curve with |f''| h^2 = D2 deviates by <= D2 / 8;
    # we take D2 / 2). Straight-line motion has none, so a fast linear mover stays exactly as tight.
    seq_lo = np.concatenate([klo[:-1, None], wlo, klo[1:, None]], 1)
    seq_hi = np.concatenate([khi[:-1, None], whi, khi[1:, None]], 1)
    d2 = np.maximum(np.abs(np.diff(seq_lo, 2, axis=1)).max(1), np.abs(np.diff(seq_hi, 2, axis=1)).max(1))
    pad_seg = np.maximum((blend_lo - wlo).max(1), (whi - blend_hi).max(1))
    pad_seg = np.maximum(pad_seg, 0.0) + 0.5 * d2  # (nseg, 3)
    pad = np.zeros((nkeys, 3))
    pad[:-1] = np.maximum(pad[:-1], pad_seg)
    pad[1:] = np.maximum(pad[1:], pad_seg)
    return klo - pad, khi + pad
