"""Motion over the shutter, USD side: which time codes to sample, how to turn USD matrices and points into keys.

Conventions used by every module of ``renderer/usd``:

* Times handed around are **absolute time codes**; only the final keys are normalised to ``s`` in [0, 1] over
  ``[shutter.open, shutter.close]`` (``Shutter.normalise``).
* Matrices are kept in USD's **row-vector** convention (``p' = p @ M``, translation in the last row) while they
  are composed, and transposed to the scene's column-vector convention only in ``motion_transforms``.

Key selection (``Shutter.keys``): the shutter ends plus every authored time sample strictly inside the shutter,
so that a ball keyed at 0, 0.5 and 1 (stopping halfway) keeps its key at 0.5. ``refine_keys`` then bisects any
segment that rotates by more than ``MAX_SEGMENT_DEGREES`` or whose USD-evaluated midpoint differs from what
lerp/slerp between the keys would give (curved or long-way-round motion).
"""
from __future__ import annotations

import numpy as np
from pxr import Gf, Usd, UsdGeom

from renderer.motion.shutter import Shutter
from renderer.motion.transform import MotionTransform
from renderer.usd.reads import reads

MAX_SEGMENT_DEGREES = 10.0  # largest rotation between two consecutive keys
_MAX_REFINE_ROUNDS = 6  # at most 2^6 sub-segments per authored segment


def shutter_interval(shutter: Shutter) -> Gf.Interval:
    return Gf.Interval(shutter.open, shutter.close)


def samples_in_shutter(shutter: Shutter, attr) -> list[float]:
    """Authored time samples of an attribute strictly inside the shutter."""
    if shutter.static or not attr or not attr.HasAuthoredValue():
        return []
    return shutter.inner(attr.GetTimeSamplesInInterval(shutter_interval(shutter)))


class TransformSampler:
    """World transforms of prims at time codes, with per-time ``UsdGeom.XformCache`` s and memoised key times."""

    def __init__(self, shutter: Shutter):
        self.shutter = shutter
        self._caches: dict[float, UsdGeom.XformCache] = {}
        self._chain: dict[str, tuple[bool, tuple[float, ...]]] = {}

    def _cache(self, t: float) -> UsdGeom.XformCache:
        c = self._caches.get(t)
        if c is None:
            if len(self._caches) > 256:  # a long refinement: do not hold hundreds of caches
                self._caches.clear()
            c = self._caches[t] = UsdGeom.XformCache(Usd.TimeCode(t))
        return c

    def world(self, prim, times) -> np.ndarray:
        """(K, 4, 4) float64 local-to-world matrices, USD row-vector convention, at absolute times."""
        return np.array([np.array(self._cache(float(t)).GetLocalToWorldTransform(prim)) for t in times])

    def chain(self, prim) -> tuple[bool, tuple[float, ...]]:
        """(might move, samples inside the shutter) of the prim's transform and all its ancestors'."""
        if not prim or prim.IsPseudoRoot():
            return False, ()
        key = str(prim.GetPath())
        hit = self._chain.get(key)
        if hit is not None:
            return hit
        moving, samples = False, ()
        xf = UsdGeom.Xformable(prim)
        reset = False
        if xf:
            if xf.TransformMightBeTimeVarying():
                moving = True
                samples = tuple(self.shutter.inner(xf.GetTimeSamplesInInterval(shutter_interval(self.shutter))))
            reset = xf.GetResetXformStack()
        if not reset:
            p_moving, p_samples = self.chain(prim.GetParent())
            moving = moving or p_moving
            samples = tuple(sorted(set(samples) | set(p_samples)))
        self._chain[key] = (moving, samples)
        return moving, samples

    def key_times(self, prim) -> np.ndarray:
        moving, samples = self.chain(prim)
        if not moving or self.shutter.static:
            return np.array([self.shutter.frame], np.float64)
        return self.shutter.keys(samples)

    @reads("Xformable", "xformOpOrder")  # with the xformOp:* it orders, through UsdGeom.XformCache
    def motion(self, prim) -> tuple[np.ndarray, np.ndarray]:
        """(times (K,), row-vector world matrices (K, 4, 4)) with keys refined for curved motion."""
        times = self.key_times(prim)
        if len(times) == 1:
            return times, self.world(prim, times)
        times, mats = refine_keys(lambda ts: self.world(prim, ts)[None], times)
        return times, mats[0]


# ---------------------------------------------------------------------------------------------------------------
# Batched decomposition (vectorised twin of motion.decompose / motion.make_transform)


def _quat_from_rot(r: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices to (N, 4) unit quaternions (x, y, z, w); same branches as motion.matrix_to_quat."""
    n = len(r)
    q = np.empty((n, 4))
    tr = np.trace(r, axis1=1, axis2=2)
    c0 = tr > 0
    c1 = ~c0 & (r[:, 0, 0] > r[:, 1, 1]) & (r[:, 0, 0] > r[:, 2, 2])
    c2 = ~c0 & ~c1 & (r[:, 1, 1] > r[:, 2, 2])
    c3 = ~c0 & ~c1 & ~c2
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.sqrt(np.maximum(tr + 1.0, 0.0)) * 2.0
        q0 = np.stack([(r[:, 2, 1] - r[:, 1, 2]) / k, (r[:, 0, 2] - r[:, 2, 0]) / k,
                       (r[:, 1, 0] - r[:, 0, 1]) / k, 0.25 * k], -1)
        k = np.sqrt(np.maximum(1.0 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2], 0.0)) * 2.0
        q1 = np.stack([0.25 * k, (r[:, 0, 1] + r[:, 1, 0]) / k, (r[:, 0, 2] + r[:, 2, 0]) / k,
                       (r[:, 2, 1] - r[:, 1, 2]) / k], -1)
        k = np.sqrt(np.maximum(1.0 + r[:, 1, 1] - r[:, 0, 0] - r[:, 2, 2], 0.0)) * 2.0
        q2 = np.stack([(r[:, 0, 1] + r[:, 1, 0]) / k, 0.25 * k, (r[:, 1, 2] + r[:, 2, 1]) / k,
                       (r[:, 0, 2] - r[:, 2, 0]) / k], -1)
        k = np.sqrt(np.maximum(1.0 + r[:, 2, 2] - r[:, 0, 0] - r[:, 1, 1], 0.0)) * 2.0
        q3 = np.stack([(r[:, 0, 2] + r[:, 2, 0]) / k, (r[:, 1, 2] + r[:, 2, 1]) / k, 0.25 * k,
                       (r[:, 1, 0] - r[:, 0, 1]) / k], -1)
    for cond, qq in ((c0, q0), (c1, q1), (c2, q2), (c3, q3)):
        q[cond] = qq[cond]
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(np.isfinite(norm) & (norm > 0), q / np.where(norm > 0, norm, 1.0), [0.0, 0.0, 0.0, 1.0])
    return q


def decompose_batch(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 4, 4) column-vector matrices to translation (N, 3), quaternion (N, 4) and scale-shear (N, 3, 3)."""
    m = np.asarray(m, np.float64)
    a = m[:, :3, :3]
    t = m[:, :3, 3].copy()
    u, _, vt = np.linalg.svd(a)
    r = u @ vt
    flip = np.linalg.det(r) < 0
    if np.any(flip):
        u[flip, :, -1] *= -1.0
        r = u @ vt
    s = np.swapaxes(r, 1, 2) @ a
    return t, _quat_from_rot(r), s


def to_column(rows: np.ndarray) -> np.ndarray:
    """USD row-vector matrices (..., 4, 4) to column-vector ones."""
    return np.swapaxes(np.asarray(rows, np.float64), -1, -2)


def motion_transforms(times, rows: np.ndarray) -> list[MotionTransform]:
    """One MotionTransform per instance from row-vector world matrices (N, K, 4, 4) at normalised times (K,).

    Equivalent to ``renderer.motion.transform.make_transform`` per instance (hemisphere-aligned quaternions,
    collapsed to one key when nothing moves), vectorised over the N instances.
    """
    rows = np.asarray(rows, np.float64)
    n, k = rows.shape[:2]
    times = np.asarray(times, np.float32)
    if n == 0:
        return []
    t, q, s = decompose_batch(to_column(rows).reshape(n * k, 4, 4))
    t, q, s = t.reshape(n, k, 3), q.reshape(n, k, 4), s.reshape(n, k, 3, 3)
    for j in range(1, k):
        neg = np.sum(q[:, j - 1] * q[:, j], axis=1) < 0
        q[neg, j] *= -1.0
    if k > 1:
        same = (
            np.all(np.abs(t - t[:, :1]) <= 1e-8 + 1e-5 * np.abs(t), axis=(1, 2))
            & np.all(np.abs(q - q[:, :1]) <= 1e-8 + 1e-5 * np.abs(q), axis=(1, 2))
            & np.all(np.abs(s - s[:, :1]) <= 1e-8 + 1e-5 * np.abs(s), axis=(1, 2, 3))
        )
    else:
        same = np.ones(n, bool)
    # One buffer per field for the batch; each transform holds disjoint views of it, read-only (a transform is
    # never changed in place; a new one is made). Four copies per instance took 1.4 s of a million-instance import.
    t32, q32, s32 = t.astype(np.float32), q.astype(np.float32), s.astype(np.float32)
    key_times = np.where(same[:, None], np.float32(0.0), times[None]).astype(np.float32)  # (n, k): [0] when still
    for a in (key_times, t32, q32, s32):
        a.flags.writeable = False
    if same.all():  # all still: the row views made by NumPy's iterator, faster than slicing one by one
        return [MotionTransform(*f) for f in zip(*(list(a[:, :1]) for a in (key_times, t32, q32, s32)))]
    nkeys = np.where(same, 1, k).tolist()
    return [MotionTransform(key_times[i, :kk], t32[i, :kk], q32[i, :kk], s32[i, :kk]) for i, kk in enumerate(nkeys)]


def motion_transform(times, rows: np.ndarray) -> MotionTransform:
    """A single MotionTransform from row-vector matrices (K, 4, 4) at normalised times (K,)."""
    return motion_transforms(times, np.asarray(rows)[None])[0]


# ---------------------------------------------------------------------------------------------------------------
# Key refinement for curved motion


def _angle(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    d = np.abs(np.sum(qa * qb, axis=-1))
    return np.degrees(2.0 * np.arccos(np.clip(d, 0.0, 1.0)))


def _slerp_batch(qa: np.ndarray, qb: np.ndarray, u: float) -> np.ndarray:
    d = np.sum(qa * qb, axis=-1, keepdims=True)
    qb = np.where(d < 0, -qb, qb)
    d = np.abs(d)
    th = np.arccos(np.clip(d, -1.0, 1.0))
    sin_th = np.sin(th)
    small = sin_th < 1e-6
    w0 = np.where(small, 1 - u, np.sin((1 - u) * th) / np.where(small, 1.0, sin_th))
    w1 = np.where(small, u, np.sin(u * th) / np.where(small, 1.0, sin_th))
    q = w0 * qa + w1 * qb
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _needs_split(a, b, mid) -> np.ndarray:
    """Per segment (S,) whether keys a, b (each (N, S, 4, 4) row matrices) miss the USD midpoint ``mid``."""
    n, s = a.shape[:2]

    def dec(x):
        t, q, sc = decompose_batch(to_column(x).reshape(n * s, 4, 4))
        return t.reshape(n, s, 3), q.reshape(n, s, 4), sc.reshape(n, s, 3, 3)

    ta, qa, sa = dec(a)
    tb, qb, sb = dec(b)
    tm, qm, sm = dec(mid)
    too_far = _angle(qa, qb) > MAX_SEGMENT_DEGREES
    off_arc = _angle(qm, _slerp_batch(qa, qb, 0.5)) > 1.0
    dt = np.linalg.norm(tb - ta, axis=-1)
    size = np.linalg.norm(ta, axis=-1) + np.linalg.norm(tb, axis=-1)
    off_t = np.linalg.norm(tm - 0.5 * (ta + tb), axis=-1) > 0.05 * dt + 1e-5 * (1.0 + size)
    ds = np.linalg.norm((sb - sa).reshape(n, s, 9), axis=-1)
    s_size = np.linalg.norm(sa.reshape(n, s, 9), axis=-1)  # quaternions stored as half floats wobble ~1e-4
    off_s = np.linalg.norm((sm - 0.5 * (sa + sb)).reshape(n, s, 9), axis=-1) > 0.05 * ds + 1e-3 * s_size
    return np.any(too_far | off_arc | off_t | off_s, axis=0)


def refine_keys(evaluate, times) -> tuple[np.ndarray, np.ndarray]:
    """Bisect key segments until motion between keys is well described by lerp/slerp.

    ``evaluate(times) -> (N, K, 4, 4)`` row-vector matrices of N things moving together (one segment is split when
    any of them needs it). Returns (times (K',), matrices (N, K', 4, 4)).
    """
    times = np.asarray(times, np.float64)
    mats = np.asarray(evaluate(times), np.float64)
    if len(times) < 2 or mats.shape[0] == 0:
        return times, mats
    open_seg = np.ones(len(times) - 1, bool)
    for _ in range(_MAX_REFINE_ROUNDS):
        idx = np.nonzero(open_seg)[0]
        if len(idx) == 0:
            break
        mids = 0.5 * (times[idx] + times[idx + 1])
        mid_mats = np.asarray(evaluate(mids), np.float64)
        split = _needs_split(mats[:, idx], mats[:, idx + 1], mid_mats)
        if not np.any(split):
            break
        times = np.concatenate([times, mids[split]])
        mats = np.concatenate([mats, mid_mats[:, split]], axis=1)
        order = np.argsort(times, kind="stable")
        # Re-check only the two halves of each split segment: those starting at its left key or at its new midpoint.
        starts_half = np.zeros(len(times), bool)
        starts_half[idx[split]] = True
        starts_half[len(times) - int(split.sum()):] = True
        times, mats = times[order], mats[:, order]
        open_seg = starts_half[order][:-1]
    return times, mats


@reads("PointBased", "points", "velocities", "accelerations")
def point_keys(pb: UsdGeom.PointBased, shutter: Shutter, count: int, warn) -> tuple[np.ndarray, np.ndarray] | None:
    """(times (P,), points (P, V, 3) float32) over the shutter, or None if the frame has no usable points.

    With ``velocities`` authored, ``UsdGeomPointBased.ComputePointsAtTimes`` applies the USD formula
    p(t) = p(tS) + v (t - tS)/tcps + a/2 ((t - tS)/tcps)^2 from the sample tS at or before the frame (five keys
    when ``accelerations`` make the path curved). Otherwise every authored points sample inside the shutter is a
    key, evaluated with USD's own interpolation; samples whose point count differs from the frame's are dropped.
    """
    attr = pb.GetPointsAttr()
    frame = shutter.frame
    base = attr.Get(frame)
    if base is None:
        return None
    base = np.asarray(base, np.float32).reshape(-1, 3)
    if len(base) != count:
        return None
    single = (np.array([frame]), base[None])
    if shutter.static:
        return single
    path = str(pb.GetPath())
    vel = pb.GetVelocitiesAttr()
    if vel and vel.HasAuthoredValue():
        v = vel.Get(frame)
        if v is not None and len(v) == len(base):
            acc = pb.GetAccelerationsAttr()
            curved = bool(acc and acc.HasAuthoredValue())
            times = shutter.uniform(5) if curved else shutter.keys()
            arrays = pb.ComputePointsAtTimes([Usd.TimeCode(float(t)) for t in times], Usd.TimeCode(frame))
            if arrays and all(len(a) == len(base) for a in arrays):
                keys = np.stack([np.asarray(a, np.float32).reshape(-1, 3) for a in arrays])
                return collapse_keys(times, keys)
            warn("velocities could not be applied (point counts differ); those prims are not deformation-blurred",
                 path)
    if not attr.ValueMightBeTimeVarying():
        return single
    times = shutter.keys(attr.GetTimeSamplesInInterval(shutter_interval(shutter)))
    keys, kept = [], []
    for t in times:
        a = attr.Get(float(t))
        a = None if a is None else np.asarray(a, np.float32).reshape(-1, 3)
        if a is None or len(a) != len(base):
            continue
        keys.append(a)
        kept.append(t)
    if len(kept) < len(times):
        warn("point count changes within the shutter; deformation blur dropped for", path)
        return single
    return collapse_keys(np.array(kept), np.stack(keys))


def collapse_keys(times: np.ndarray, keys: np.ndarray):
    """(times, keys) as one key when every key equals the first (nothing moves), else unchanged."""
    if len(keys) > 1 and all(np.array_equal(keys[0], k) for k in keys[1:]):
        return times[:1], keys[:1]
    return times, keys
