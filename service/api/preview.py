"""Preview PNGs: the frame so far (finished tiles; the rest black), tone-mapped for a screen.

Tone mapping is deliberately plain: the EXR's linear, premultiplied colour (over black), clamped to [0, 1] and
encoded with the sRGB transfer curve; large frames are shrunk to ``MAX_SIDE`` pixels on their long side.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from renderer.film.tiles import Tile

from ..farm.job_files import load_tile

MAX_SIDE = 1024


def srgb8(rgb: np.ndarray) -> np.ndarray:
    x = np.clip(np.nan_to_num(rgb, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.round(x * 255.0).astype(np.uint8)


def png(rgb: np.ndarray) -> bytes:
    from PIL import Image

    img = Image.fromarray(srgb8(rgb))  # (H, W, 3) uint8: RGB
    if max(img.size) > MAX_SIDE:
        img.thumbnail((MAX_SIDE, MAX_SIDE))
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def from_exr(path: Path) -> bytes:
    from renderer.film.exr import read_exr

    channels, _ = read_exr(path)
    return png(np.stack([channels["R"], channels["G"], channels["B"]], axis=-1))


def from_tiles(tiles: list[tuple[Path, Tile]], width: int, height: int, exposure_scale: float) -> bytes:
    """Assemble the checkpoints that exist (a tile may vanish while we read: the frame was just finished)."""
    rgb = np.zeros((height, width, 3), np.float32)
    for path, (x0, y0, x1, y1) in tiles:
        try:
            a = load_tile(path)
        except (FileNotFoundError, OSError, ValueError, KeyError):
            continue
        w = a["weight"][..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            rgb[y0:y1, x0:x1] = np.where(w > 0, a["rgba"][..., :3] / w, 0.0) * exposure_scale
    return png(rgb)
