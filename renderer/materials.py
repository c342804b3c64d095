"""Materials as the kernels see them: one row per material, indexed by the triangle's material id."""
from __future__ import annotations

import numpy as np
import warp as wp

from .scene import Material


@wp.struct
class Materials:
    diffuse: wp.array(dtype=wp.vec3)  # albedo, linear RGB in [0, 1]
    emission: wp.array(dtype=wp.vec3)  # emitted radiance (both faces)
    opacity: wp.array(dtype=wp.float32)  # 1 = opaque; light passes through with weight 1 - opacity


def upload_materials(materials: list[Material], device: str = "cpu") -> Materials:
    mats = materials or [Material(name="default")]
    m = Materials()
    diffuse = np.clip(np.array([x.diffuse_color for x in mats], np.float32), 0.0, 1.0)
    emission = np.maximum(np.array([x.emissive_color for x in mats], np.float32), 0.0)
    opacity = np.clip(np.array([x.opacity for x in mats], np.float32), 0.0, 1.0)
    m.diffuse = wp.array(np.nan_to_num(diffuse), dtype=wp.vec3, device=device)
    m.emission = wp.array(np.nan_to_num(emission), dtype=wp.vec3, device=device)
    m.opacity = wp.array(np.nan_to_num(opacity, nan=1.0), dtype=wp.float32, device=device)
    return m
