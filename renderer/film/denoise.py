"""Denoising an assembled frame with Intel Open Image Denoise (OIDN), guided by the albedo and normal AOVs.

OIDN comes from the ``pyoidn`` package, an optional install (``pip install 'drt[denoise]'``, about 90 MB): the
renderer works without it, and asking for ``denoise`` without it is a clear settings error before rendering.
The denoised image is an extra layer; the beauty stays the raw Monte Carlo estimate.
"""
from __future__ import annotations

import importlib.util

import numpy as np

from renderer.errors import SettingsError

MISSING = "denoising needs Intel Open Image Denoise: install it with pip install 'drt[denoise]' (the pyoidn package)"


def available() -> bool:
    return importlib.util.find_spec("pyoidn") is not None


def require() -> None:
    if not available():
        raise SettingsError(MISSING)


def denoise_rgb(rgb: np.ndarray, albedo: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Denoise linear HDR colour (H, W, 3) with its first-hit albedo ([0, 1]) and world normals ([-1, 1])."""
    require()
    # imported here, not at the top: the package is optional and loading its native library costs 0.2 s
    import pyoidn

    f32 = lambda a: np.ascontiguousarray(np.nan_to_num(a, nan=0.0, posinf=0.0, neginf=0.0), np.float32)  # noqa: E731
    out = pyoidn.denoise(np.maximum(f32(rgb), 0.0), np.clip(f32(albedo), 0.0, 1.0), np.clip(f32(normal), -1.0, 1.0),
                         hdr=True, quality="high")
    return np.nan_to_num(np.asarray(out, np.float32), nan=0.0, posinf=0.0, neginf=0.0)
