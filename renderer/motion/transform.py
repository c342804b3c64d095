"""Motion over the shutter (the paper's time dimension), NumPy side.

Transforms are decomposed into translation, rotation and scale-shear keys (polar decomposition, as in pbrt's
AnimatedTransform) so that rotations interpolate along arcs (slerp) instead of shrinking through a matrix lerp.
The Warp twins of ``interpolate`` live in ``kernels.py``; tests compare the two.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(slots=True)  # no __dict__: a scene may hold a million of them
class MotionTransform:
    """Object-to-world transform over the shutter, as K decomposed keys.

    matrix(s) = T(s) * R(s) * S(s) in the column-vector convention (p_world = M @ p_object), where T is
    interpolated linearly, R (unit quaternion, x, y, z, w) by slerp and S (3x3 scale/shear, the symmetric
    polar factor) linearly. K == 1 means static.
    """

    times: np.ndarray  # (K,) float32, sorted, normalised shutter time in [0, 1]
    translation: np.ndarray  # (K, 3) float32
    rotation: np.ndarray  # (K, 4) float32 unit quaternions (x, y, z, w)
    scale: np.ndarray  # (K, 3, 3) float32

    @property
    def num_keys(self) -> int:
        return int(len(self.times))

    @staticmethod
    def static(matrix: np.ndarray) -> "MotionTransform":
        """A motionless transform from a 4x4 column-vector matrix (p_world = M @ p)."""
        t, q, s = decompose(np.asarray(matrix, dtype=np.float64))
        return MotionTransform(
            times=np.zeros(1, np.float32),
            translation=t[None].astype(np.float32),
            rotation=q[None].astype(np.float32),
            scale=s[None].astype(np.float32),
        )


def decompose(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split a 4x4 column-vector affine matrix into (translation (3,), quaternion xyzw (4,), scale-shear (3,3)).

    M[:3,:3] = R @ S with R a rotation and S symmetric (polar decomposition via SVD). Reflections (negative
    determinant) are folded into S so that R stays a proper rotation.
    """
    m = np.asarray(m, dtype=np.float64)
    t = m[:3, 3].copy()
    a = m[:3, :3]
    u, sig, vt = np.linalg.svd(a)
    r = u @ vt
    if np.linalg.det(r) < 0:  # mirror: keep R proper, put the flip into S
        u[:, -1] *= -1.0
        r = u @ vt
    s = r.T @ a
    return t, matrix_to_quat(r), s


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """Rotation matrix (3x3) to unit quaternion (x, y, z, w)."""
    r = np.asarray(r, dtype=np.float64)
    tr = np.trace(r)
    if tr > 0.0:
        k = np.sqrt(tr + 1.0) * 2.0
        q = [(r[2, 1] - r[1, 2]) / k, (r[0, 2] - r[2, 0]) / k, (r[1, 0] - r[0, 1]) / k, 0.25 * k]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        k = np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2.0
        q = [0.25 * k, (r[0, 1] + r[1, 0]) / k, (r[0, 2] + r[2, 0]) / k, (r[2, 1] - r[1, 2]) / k]
    elif r[1, 1] > r[2, 2]:
        k = np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2.0
        q = [(r[0, 1] + r[1, 0]) / k, 0.25 * k, (r[1, 2] + r[2, 1]) / k, (r[0, 2] - r[2, 0]) / k]
    else:
        k = np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2.0
        q = [(r[0, 2] + r[2, 0]) / k, (r[1, 2] + r[2, 1]) / k, 0.25 * k, (r[1, 0] - r[0, 1]) / k]
    q = np.array(q)
    return q / np.linalg.norm(q)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = np.asarray(q, dtype=np.float64)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def slerp(q0: np.ndarray, q1: np.ndarray, u: float) -> np.ndarray:
    q0 = np.asarray(q0, np.float64)
    q1 = np.asarray(q1, np.float64)
    d = float(np.dot(q0, q1))
    if d < 0.0:  # take the short way round
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + u * (q1 - q0)
        return q / np.linalg.norm(q)
    th = np.arccos(np.clip(d, -1.0, 1.0))
    return (np.sin((1 - u) * th) * q0 + np.sin(u * th) * q1) / np.sin(th)


def make_transform(times, matrices):
    """MotionTransform from K sorted times and K 4x4 column-vector matrices.

    Consecutive quaternions are made to lie in the same hemisphere so slerp takes the short arc.
    """
    times = np.asarray(times, np.float64)
    ts, qs, ss = [], [], []
    for m in matrices:
        t, q, s = decompose(m)
        if qs and np.dot(qs[-1], q) < 0:
            q = -q
        ts.append(t)
        qs.append(q)
        ss.append(s)
    if len(times) > 1 and all(
        np.allclose(ts[0], t) and np.allclose(qs[0], q) and np.allclose(ss[0], s) for t, q, s in zip(ts, qs, ss)
    ):
        times, ts, qs, ss = times[:1] * 0.0, ts[:1], qs[:1], ss[:1]
    return MotionTransform(
        times=times.astype(np.float32),
        translation=np.array(ts, np.float32),
        rotation=np.array(qs, np.float32),
        scale=np.array(ss, np.float32),
    )


def quat_to_matrices(q: np.ndarray) -> np.ndarray:
    """``quat_to_matrix`` of (N, 4) quaternions: (N, 3, 3), the same arithmetic elementwise."""
    x, y, z, w = np.asarray(q, dtype=np.float64).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def place_boxes(m: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World boxes (lo, hi), (N, 3) each, of object boxes lo/hi (N, 3) under column-vector matrices m (N, 4, 4):
    the bounds of their eight corners placed (``np.matmul`` sums as ``@`` does per box)."""
    sel = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], bool)
    corners = np.where(sel, np.asarray(hi)[:, None, :], np.asarray(lo)[:, None, :])  # (N, 8, 3)
    w = np.matmul(corners, np.swapaxes(m[:, :3, :3], 1, 2)) + m[:, None, :3, 3]
    return w.min(1), w.max(1)


def placed_extent(m: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bounds (lo, hi), (3,) each, of all the world boxes ``place_boxes(m, lo, hi)`` gives, with the same bits,
    placing the corners only of the boxes that can reach an extreme. Each box's exact world extent is its placed
    centre +- |A| half-extent; only boxes within a generous rounding margin of the best bound on an axis are
    placed corner by corner (a scatter of 10^6 instances: a handful instead of 1.3 s of corners)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    a = m[:, :3, :3]
    wc = np.einsum("nij,nj->ni", a, 0.5 * (lo + hi)) + m[:, :3, 3]
    wh = np.einsum("nij,nj->ni", np.abs(a), 0.5 * (hi - lo))
    slack = 1e-7 * (np.abs(wc) + wh + np.abs(m[:, :3, 3])) + 1e-300
    low, high = wc - wh, wc + wh
    if not (np.isfinite(low).all() and np.isfinite(high).all()):
        pick = np.arange(len(m))  # a NaN or infinite box: place them all, as place_boxes would
    else:
        near_lo = low - slack <= (low + slack).min(0)  # (N, 3): could hold the minimum on that axis
        near_hi = high + slack >= (high - slack).max(0)
        pick = np.nonzero(near_lo.any(1) | near_hi.any(1))[0]
    wlo, whi = place_boxes(m[pick], lo[pick], hi[pick])
    return wlo.min(0), whi.max(0)


def matrices_at(xfs, s: float) -> np.ndarray:
    """``matrix_at(xf, s)`` of many MotionTransforms: (N, 4, 4). The still ones (one key) in one vectorised
    pass, bit-identical to ``matrix_at``; the moving ones through it. Scenes of 10^4 instances spent seconds of
    their preparation calling ``matrix_at`` one instance at a time."""
    n = len(xfs)
    out = np.zeros((n, 4, 4))
    out[:, 3, 3] = 1.0
    still = np.array([len(xf.times) == 1 for xf in xfs], bool)
    idx = np.nonzero(still)[0]
    if len(idx):
        # matrix_at with one key: slerp(q, q, 0) normalises q; the blends of translation and scale are exact
        # one key each: concatenating the (1, ...) key arrays stacks them, 4x faster than np.stack of their rows
        # (a million instances: 0.17 s against 0.66 s per field)
        one = [xfs[i] for i in idx]
        t = np.concatenate([xf.translation for xf in one]).astype(np.float64)
        q = np.concatenate([xf.rotation for xf in one]).astype(np.float64)
        sc = np.concatenate([xf.scale for xf in one]).astype(np.float64)
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        r = quat_to_matrices(q)
        out[idx, :3, :3] = np.matmul(r, sc)  # as `@` per matrix (einsum sums in another order)
        out[idx, :3, 3] = t
    for i in np.nonzero(~still)[0]:
        out[i] = matrix_at(xfs[i], s)
    return out


def matrix_at(xf, s: float) -> np.ndarray:
    """The 4x4 column-vector matrix of a MotionTransform at normalised time s (clamped to its keys)."""
    times = np.asarray(xf.times, np.float64)
    k = len(times)
    if k == 1 or s <= times[0]:
        i, u = 0, 0.0
        j = 0
    elif s >= times[-1]:
        i = j = k - 1
        u = 0.0
    else:
        j = int(np.searchsorted(times, s, side="right"))
        i = j - 1
        span = times[j] - times[i]
        u = (s - times[i]) / span if span > 0 else 0.0
    t = (1 - u) * xf.translation[i].astype(np.float64) + u * xf.translation[j]
    q = slerp(xf.rotation[i], xf.rotation[j], u)
    sc = (1 - u) * xf.scale[i].astype(np.float64) + u * xf.scale[j]
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(q) @ sc
    m[:3, 3] = t
    return m
