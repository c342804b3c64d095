"""Motion over the shutter, Warp side: transforms and deforming points evaluated at a ray's time.

Every moving thing (instances, lights, the camera) stores its ``MotionTransform`` keys in one shared
``MotionKeys`` table; a thing refers to its keys by (offset, count). Between keys translation and scale-shear
are interpolated linearly and rotation by slerp, which is what ``transform.matrix_at`` does in NumPy.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.kernels.struct_refs import by_reference


@by_reference
@wp.struct
class MotionKeys:
    """All transform keys of a scene, concatenated. Times are normalised shutter time in [0, 1]."""

    times: wp.array(dtype=wp.float32)
    translation: wp.array(dtype=wp.vec3)
    rotation: wp.array(dtype=wp.quat)
    scale: wp.array(dtype=wp.mat33)


@wp.func
def find_segment(times: wp.array(dtype=wp.float32), offset: int, count: int, s: float):
    """Bracketing keys (i, j) of time s among times[offset : offset + count] and the blend u in [0, 1].

    Times outside the keys clamp to the first/last key. Linear search: key counts are small (a few to ~30).
    """
    if count <= 1 or s <= times[offset]:
        return offset, offset, float(0.0)
    last = offset + count - 1
    if s >= times[last]:
        return last, last, float(0.0)
    j = offset + 1
    while times[j] < s:
        j += 1
    i = j - 1
    span = times[j] - times[i]
    u = float(0.0)
    if span > 0.0:
        u = (s - times[i]) / span
    return i, j, u


@wp.func
def keys_matrix(keys: MotionKeys, offset: int, count: int, s: float):
    """Object-to-world matrix (column vectors) of the transform stored at keys[offset : offset + count]."""
    i, j, u = find_segment(keys.times, offset, count, s)
    t = wp.lerp(keys.translation[i], keys.translation[j], u)
    q = keys.rotation[i]
    if j != i:
        q = wp.quat_slerp(keys.rotation[i], keys.rotation[j], u)
    sc = keys.scale[i] * (1.0 - u) + keys.scale[j] * u
    r = wp.quat_to_matrix(q) * sc
    return wp.mat44(
        r[0, 0], r[0, 1], r[0, 2], t[0],
        r[1, 0], r[1, 1], r[1, 2], t[1],
        r[2, 0], r[2, 1], r[2, 2], t[2],
        0.0, 0.0, 0.0, 1.0,
    )


def upload_keys(transforms, device: str = "cpu"):
    """Concatenate MotionTransforms into a MotionKeys struct. Returns (keys, offsets, counts) as numpy ints."""
    # one list and one concatenation per field (a per-transform loop of appends took 2.7 s for 10^6 instances)
    transforms = list(transforms)
    counts = np.array([len(xf.times) for xf in transforms], np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if len(counts) else counts
    if counts.sum() == 0:  # Warp arrays may not be empty in a struct used by kernels: keep one identity key
        times, trans = np.zeros(1, np.float32), np.zeros((1, 3), np.float32)
        rots, scales = np.array([[0, 0, 0, 1]], np.float32), np.eye(3, dtype=np.float32)[None]
    else:
        times = np.concatenate([xf.times for xf in transforms]).astype(np.float32, copy=False)
        trans = np.concatenate([xf.translation for xf in transforms]).astype(np.float32, copy=False)
        rots = np.concatenate([xf.rotation for xf in transforms]).astype(np.float32, copy=False)
        scales = np.concatenate([xf.scale for xf in transforms]).astype(np.float32, copy=False)
    keys = MotionKeys()
    keys.times = wp.array(times, dtype=wp.float32, device=device)
    keys.translation = wp.array(np.ascontiguousarray(trans.reshape(-1, 3)), dtype=wp.vec3, device=device)
    keys.rotation = wp.array(np.ascontiguousarray(rots.reshape(-1, 4)), dtype=wp.quat, device=device)
    keys.scale = wp.array(np.ascontiguousarray(scales.reshape(-1, 3, 3)), dtype=wp.mat33, device=device)
    return keys, offsets.astype(np.int32), counts.astype(np.int32)
