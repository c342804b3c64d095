"""Tile borders: each sample pixel rendered once, border pixels assembled exactly from per-direction partials."""
from __future__ import annotations

import numpy as np
import pytest

from renderer.film import borders


def fake_partials(tile, margin, width, height, rng_seed=0):
    """Per-direction partials of a tile over its extended region, as ``render_tile`` lays them out: direction d
    of target t is non-zero only where its source pixel t + offset(d) is the tile's and inside the frame."""
    x0, y0, x1, y1 = tile
    ex0, ey0, ex1, ey1 = borders.extended_region(x0, y0, x1, y1, margin, width, height)
    D = borders.directions(margin)
    out = {}
    for name, c in borders.CHANNELS.items():
        shape = (D, ey1 - ey0, ex1 - ex0) + ((c,) if c > 1 else ())
        p = np.zeros(shape, np.float32)
        d = 0
        for oy in range(-margin, margin + 1):
            for ox in range(-margin, margin + 1):
                for ty in range(ey0, ey1):
                    for tx in range(ex0, ex1):
                        sx, sy = tx + ox, ty + oy
                        if x0 <= sx < x1 and y0 <= sy < y1:
                            # a value that depends on (direction, target) only, never on the tile
                            g = np.random.default_rng([d, ty, tx, len(name)])
                            p[d, ty - ey0, tx - ex0] = g.random(c if c > 1 else None, dtype=np.float32)
                d += 1
        out[name] = p
    return out


def render(tiles, margin, width, height):
    return borders.assemble([(t, borders.split_tile(fake_partials(t, margin, width, height), t, margin, width,
                                                    height)) for t in tiles], width, height)


@pytest.mark.parametrize("margin", [0, 1, 2])
def test_every_tiling_assembles_the_same_bits(margin):
    W, H = 11, 9
    whole = render([(0, 0, W, H)], margin, W, H)
    grids = [[(x, y, min(x + s, W), min(y + s, H)) for y in range(0, H, s) for x in range(0, W, s)] for s in (1, 3, 4)]
    odd = [(0, 0, 11, 2), (0, 2, 5, 9), (5, 2, 6, 9), (6, 2, 11, 9)]  # a one-pixel column between two tiles
    for tiles in grids + [odd]:
        got = render(tiles, margin, W, H)
        for k in borders.CHANNELS:
            assert np.array_equal(got[k], whole[k]), (margin, tiles, k)
    # and the sum is over every direction (the reference: plain ordered sums per pixel)
    ref = borders.combine(fake_partials((0, 0, W, H), margin, W, H)["rgba"])
    assert np.array_equal(whole["rgba"], ref)


def test_the_band_is_the_ring_and_the_pixels_within_reach_of_the_edge():
    mask = borders.band_mask(4, 4, 10, 9, 1, 20, 20)
    assert mask.shape == (7, 8)
    assert mask[0].all() and mask[-1].all() and mask[:, 0].all() and mask[:, -1].all()
    assert mask[1].all() and mask[:, 1].all()  # the tile's own edge pixels
    assert not mask[2:-2, 2:-2].any()
    # at the frame's corner the ring is cut off
    assert borders.band_mask(0, 0, 3, 3, 1, 3, 3).shape == (3, 3)


def test_checkpoints_of_another_layout_are_refused():
    tile = (0, 0, 4, 3)
    arrays = borders.split_tile(fake_partials(tile, 1, 8, 8), tile, 1, 8, 8)
    borders.check_tile(arrays, tile, 1, 8, 8)
    with pytest.raises(ValueError, match="band of normal"):
        borders.check_tile({k: v for k, v in arrays.items() if k != "band.normal"}, tile, 1, 8, 8)
    with pytest.raises(ValueError, match="weight missing"):
        borders.check_tile({k: v for k, v in arrays.items() if k != "weight"}, tile, 1, 8, 8)
    with pytest.raises(ValueError, match="band"):
        borders.check_tile(arrays, (0, 0, 4, 3), 1, 4, 3)  # a different frame: a different band
    with pytest.raises(ValueError, match="band"):
        borders.check_tile(arrays, tile, 2, 8, 8)  # a wider filter
    old = {k: v for k, v in arrays.items() if not k.startswith("band.")}
    with pytest.raises(ValueError, match="band of rgba"):
        borders.check_tile(old, tile, 1, 8, 8)  # the layout that rendered its margin instead
    borders.check_tile(old, tile, 0, 8, 8)  # a box filter needs no band
    other = (4, 0, 8, 8)
    with pytest.raises(ValueError, match="some tiles"):
        borders.assemble([(tile, old), (other, borders.split_tile(fake_partials(other, 1, 8, 8), other, 1, 8, 8))],
                         8, 8)
