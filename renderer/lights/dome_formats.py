"""DomeLight ``texture:format``: mirroredBall, angular and cubeMapVerticalCross images resampled to lat-long.

The renderer samples lat-long domes only (``envmap``), so other layouts are converted once, when the scene is
loaded. UsdLux names the formats without fixing their axes; ours agree with the lat-long layout on the image's
centre being the dome's local +Z, with +Y up:

- mirroredBall: a mirror ball photographed from +Z; the ball's centre reflects +Z, its rim -Z; the texel for a
  direction d is at the ball normal n = normalize(d + Z): (u, v) = (0.5 + 0.5 n.x, 0.5 - 0.5 n.y) (v down).
- angular: the light-probe angular map; the centre is +Z, the rim -Z, the distance from the centre is
  proportional to the angle from +Z: (u, v) = 0.5 + 0.5 (d.x, -d.y) acos(d.z) / (pi sqrt(d.x^2 + d.y^2)).
- cubeMapVerticalCross: a 3 x 4 cross; row 1 holds +X, +Z, -X (left to right, as seen from inside facing
  +Z), +Y is above +Z, -Y below it and -Z below -Y (upside down, continuing the strip).
"""
from __future__ import annotations

import numpy as np

from renderer.lights.envmap import latlong_to_dir_np

FORMATS = ("mirroredBall", "angular", "cubeMapVerticalCross")

# cross faces: (column, row, forward, right, up) in the 3 x 4 grid
_FACES = (
    (1, 1, (0, 0, 1), (-1, 0, 0), (0, 1, 0)),
    (2, 1, (-1, 0, 0), (0, 0, -1), (0, 1, 0)),
    (0, 1, (1, 0, 0), (0, 0, 1), (0, 1, 0)),
    (1, 0, (0, 1, 0), (-1, 0, 0), (0, 0, -1)),
    (1, 2, (0, -1, 0), (-1, 0, 0), (0, 0, 1)),
    (1, 3, (0, 0, -1), (-1, 0, 0), (0, -1, 0)),
)


def _bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Image (rows top to bottom) at (u, v) in [0, 1]^2, v down, clamped at the edges."""
    h, w = img.shape[:2]
    x = np.clip(u * w - 0.5, 0, w - 1)
    y = np.clip(v * h - 0.5, 0, h - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    top = img[y0, x0] * (1 - fx) + img[y0, x1] * fx
    bot = img[y1, x0] * (1 - fx) + img[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def lookup(img: np.ndarray, fmt: str, d: np.ndarray) -> np.ndarray:
    """The image of layout ``fmt`` in unit dome-local directions d (..., 3)."""
    d = np.asarray(d, np.float64)
    if fmt == "mirroredBall":
        n = d + np.array([0.0, 0.0, 1.0])
        n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
        return _bilinear(img, 0.5 + 0.5 * n[..., 0], 0.5 - 0.5 * n[..., 1])
    if fmt == "angular":
        s = np.hypot(d[..., 0], d[..., 1])
        r = np.where(s > 1e-12, np.arccos(np.clip(d[..., 2], -1, 1)) / (np.pi * np.maximum(s, 1e-12)), 0.0)
        return _bilinear(img, 0.5 + 0.5 * d[..., 0] * r, 0.5 - 0.5 * d[..., 1] * r)
    if fmt == "cubeMapVerticalCross":
        out = np.zeros(d.shape[:-1] + (img.shape[-1],), np.float64)
        best = np.full(d.shape[:-1], -np.inf)
        fw, fh = img.shape[1] / 3.0, img.shape[0] / 4.0
        for col, row, f, r, up in _FACES:
            f, r, up = (np.asarray(x, np.float64) for x in (f, r, up))
            df = d @ f
            sel = df > best
            best = np.where(sel, df, best)
            a = (d @ r) / np.maximum(df, 1e-12)
            b = (d @ up) / np.maximum(df, 1e-12)
            # sample inside the face (half a texel in) so neighbouring faces do not bleed
            x = np.clip((col + 0.5 + 0.5 * a) * fw, col * fw + 0.5, (col + 1) * fw - 0.5) / img.shape[1]
            y = np.clip((row + 0.5 - 0.5 * b) * fh, row * fh + 0.5, (row + 1) * fh - 0.5) / img.shape[0]
            val = _bilinear(img, x, y)
            out = np.where(sel[..., None], val, out)
        return out
    raise ValueError(f"unknown dome texture format {fmt!r}")


def to_latlong(img: np.ndarray, fmt: str, height: int | None = None) -> np.ndarray:
    """A lat-long image (2H x H, rows top to bottom) of an image in layout ``fmt``."""
    h = int(height or max(16, min(1024, img.shape[0])))
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(2 * h) + 0.5) / (2 * h), indexing="ij")
    return lookup(np.asarray(img, np.float64), fmt, latlong_to_dir_np(u, v)).astype(np.float32)
