"""Preview PNGs: the frame so far (finished tiles; the rest black), tone-mapped for a screen.

Tone mapping is deliberately plain: the EXR's linear, premultiplied colour (over black), from its rendering colour
space through OpenColorIO's sRGB display with its un-tone-mapped view (``renderer.core.color.to_display``: Rec.709
primaries, the sRGB transfer curve), clamped to [0, 1]; large frames are shrunk to ``MAX_SIDE`` pixels on their
long side. A frame still rendering (its tiles) is shown as linear Rec.709: the rendering space is in the EXR's
header, written when the frame is done.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from renderer.errors import SettingsError
from renderer.film.tiles import Tile

from ..farm.job_files import load_tile

MAX_SIDE = 1024


def srgb8(rgb: np.ndarray, rendering: str | None = None, config: str | None = None) -> np.ndarray:
    """Linear ``rgb`` in the rendering colour space ``rendering`` (default linear Rec.709) as 8-bit sRGB."""
    from renderer.core.color import to_display

    x = np.nan_to_num(np.asarray(rgb, np.float32), nan=0.0, posinf=1.0, neginf=0.0)
    x = np.clip(to_display(x, rendering, config), 0.0, 1.0)
    return np.round(x * 255.0).astype(np.uint8)


def png(rgb: np.ndarray, rendering: str | None = None, config: str | None = None) -> bytes:
    from PIL import Image

    img = Image.fromarray(srgb8(rgb, rendering, config))  # (H, W, 3) uint8: RGB
    if max(img.size) > MAX_SIDE:
        img.thumbnail((MAX_SIDE, MAX_SIDE))
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def from_exr(path: Path) -> bytes:
    from renderer.film.exr import read_exr

    channels, header = read_exr(path)
    rgb = np.stack([channels["R"], channels["G"], channels["B"]], axis=-1)
    try:
        return png(rgb, header.get("drt/renderingColorSpace"), header.get("drt/ocioConfig"))
    except SettingsError:  # a config only the render host has: shown as linear Rec.709
        return png(rgb)


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
