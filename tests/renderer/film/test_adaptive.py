"""Adaptive sampling (per-pixel stop from two half buffers), the spp AOV, and the time budget."""
from __future__ import annotations

import time

import numpy as np
import pytest

from renderer.film.adaptive import Convergence, pixel_error
from renderer.settings.options import RenderOptions
from renderer.render import Tile, frame_channels, prepare, render_frame, render_tile
from renders import make_scene


@pytest.fixture(scope="module")
def scene():
    return make_scene()


def test_pixel_error_is_zero_for_equal_halves_and_scales_with_their_difference():
    even = np.array([[1.0, 1.0, 1.0], [1.2, 1.2, 1.2], [0.0, 0.0, 0.0]])
    odd = np.array([[1.0, 1.0, 1.0], [0.8, 0.8, 0.8], [0.0, 0.0, 0.0]])
    e = pixel_error(even, odd, np.array([2, 2, 2]))
    assert e[0] == 0.0 and e[2] == 0.0
    # halves 1.2 and 0.8 (2 samples: each half is one sample): sum|A-B|/2 = 0.6, sqrt(sum I) = sqrt(3)
    np.testing.assert_allclose(e[1], 0.6 / (1e-4 + np.sqrt(3.0)))


def test_convergence_stops_only_after_min_spp_and_below_threshold():
    c = Convergence(2, threshold=0.1, min_spp=4)
    flat = np.ones((2, 1, 3), np.float32)
    flat[1, 0] = (5.0, 0.0, 0.0)
    for start in range(4):
        if start == 3:
            flat[1, 0] = (0.0, 0.0, 0.0)  # pixel 1 is noisy: 5 then 0 in its odd half
        c.add_wave(c.active_pixels(), flat[c.active_pixels()], start, 1)
        c.update()
        if start < 3:
            assert c.active.all()  # fewer than min_spp samples: nobody stops
    assert list(c.active) == [False, True]
    assert list(c.count) == [4, 4]


def test_more_samples_where_it_is_noisy_than_where_it_is_flat(scene):
    opts = RenderOptions(width=40, height=28, spp=128, noise_threshold=0.02, min_spp=8, aovs=("spp",))
    prep = prepare(scene, opts)
    r = render_frame(prep, tile_size=16, threads=2)
    spp = r.sums["spp"]
    ch = frame_channels(prep, r.sums)
    assert np.array_equal(ch["spp.Y"], spp)
    # sky: nothing is hit, every sample is black, the estimate is 0 at once; the lit floor with its penumbrae
    # and the blurred moving card are noisy
    alpha = r.sums["rgba"][..., 3] / r.sums["weight"]
    sky, lit = alpha == 0.0, alpha > 0.5
    assert sky.sum() > 50 and lit.sum() > 50
    assert np.all(spp[sky] == 8)
    assert spp[lit].mean() > 3 * 8
    assert spp.max() == 128
    assert r.samples == int(spp.sum()) < 40 * 28 * 128


def test_adaptive_frames_are_bit_identical_across_tilings(scene):
    prep = prepare(scene, RenderOptions(width=40, height=28, spp=48, noise_threshold=0.1, min_spp=4,
                                        aovs=("depth", "spp")))
    ref = render_frame(prep, tile_size=64, threads=1).sums
    assert 4 * 40 * 28 < ref["spp"].sum() < 48 * 40 * 28  # adaptive did stop some pixels, not all
    for tile_size, threads in ((8, 2), (13, 2), (5, 1)):
        other = render_frame(prep, tile_size=tile_size, threads=threads).sums
        for k in ref:
            assert np.array_equal(ref[k], other[k]), (tile_size, threads, k)
    t = render_tile(prep, Tile(11, 5, 30, 17))  # on its own: its margin's samples drawn too, every pixel final
    assert np.array_equal(t.arrays["rgba"], ref["rgba"][5:17, 11:30])
    assert np.array_equal(t.arrays["spp"], ref["spp"][5:17, 11:30])
    shared = render_tile(prep, Tile(11, 5, 30, 17), shared_borders=True)  # final one pixel inside its edge
    assert np.array_equal(shared.arrays["rgba"][1:-1, 1:-1], ref["rgba"][6:16, 12:29])
    assert np.array_equal(shared.arrays["spp"], ref["spp"][5:17, 11:30])


@pytest.mark.parametrize("limit", [1.0, 3.0])
def test_time_limit_is_respected_within_ten_percent(scene, limit):
    prep = prepare(scene, RenderOptions(width=64, height=48, spp=1 << 16, time_limit=limit))
    t0 = time.perf_counter()
    r = render_frame(prep, tile_size=32, threads=2)
    wall = time.perf_counter() - t0
    assert 0.5 * limit < wall < 1.1 * limit, wall
    assert r.sums["spp"].min() >= 1 and np.isfinite(r.sums["rgba"]).all()


def test_tile_budgets_share_the_frame_limit_by_area():
    from renderer.film.tiles import split_tiles
    from renderer.render import tile_time_budget

    o = RenderOptions(time_limit=10.0)
    tiles = split_tiles(100, 70, 32)
    assert sum(tile_time_budget(o, t, 100, 70, threads=2) for t in tiles) == pytest.approx(20.0)
    assert tile_time_budget(RenderOptions(), tiles[0], 100, 70) is None
