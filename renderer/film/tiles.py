"""Tiles: the boxes of pixels a frame is rendered in, one ``render_tile`` each, and the grid that splits a frame.

A ``Tile`` is the pixels [x0, x1) x [y0, y1) of the full image, y down. It is a named tuple: it pickles and hashes
(Dask tasks carry tiles), and it unpacks and compares like the plain ``(x0, y0, x1, y1)`` that the film's border
code and the service's task keys use. ``split_tiles`` is the one grid of a frame, row-major, the same for ``drt
render`` (``render_frame``), the service's dispatcher and its checkpoints, which are named by a tile's index in it.
The image does not depend on the grid: tiles share their borders' partial sums (``borders``).
"""
from __future__ import annotations

from typing import NamedTuple

from renderer.errors import SettingsError

DEFAULT_TILE = 64  # pixels: large enough that per-tile overhead vanishes on production frames
MIN_AUTO_TILE = 16


class Tile(NamedTuple):
    """Pixels [x0, x1) x [y0, y1) of the full image (y down)."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def width(self) -> int:
        return self.x1 - self.x0

    @property
    def height(self) -> int:
        return self.y1 - self.y0


def split_tiles(width: int, height: int, tile_size: int) -> list[Tile]:
    """The frame's tiles in row-major order: ``tile_size`` pixels square, smaller at the right and bottom edges."""
    if tile_size < 1:
        raise SettingsError(f"tile size must be >= 1, got {tile_size}")
    return [Tile(x, y, min(x + tile_size, width), min(y + tile_size, height))
            for y in range(0, height, tile_size) for x in range(0, width, tile_size)]


def tile_count(width: int, height: int, tile_size: int) -> int:
    """``len(split_tiles(width, height, tile_size))`` without making them."""
    return -(-width // tile_size) * -(-height // tile_size)


def auto_tile_size(width: int, height: int, threads: int) -> int:
    """The tile size for a frame rendered on ``threads`` threads: DEFAULT_TILE, halved (down to MIN_AUTO_TILE)
    while the frame would have fewer than 4 tiles per thread, so that the last tiles do not leave threads idle
    (a 160x90 preview is 6 tiles of 64 px, of unequal sizes, on 2 threads). The image does not depend on it."""
    size = DEFAULT_TILE
    while size > MIN_AUTO_TILE and tile_count(width, height, size) < 4 * max(1, threads):
        size //= 2
    return size
