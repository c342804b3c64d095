"""Output is bit-identical whatever the tiling and thread count; the tile grid; filters and waves behave."""
from __future__ import annotations

import pickle

import numpy as np
import pytest
import warp as wp

from renderer.errors import SettingsError
from renders import make_scene
from renderer.film import film
from renderer.film.exr import read_exr
from renderer.film.tiles import Tile, auto_tile_size, split_tiles, tile_count
from renderer.settings.options import RenderOptions
from renderer.render import (assemble, frame_image, prepare, render_frame, render_tile, with_options,
                             write_frame)


@pytest.fixture(scope="module")
def scene():
    return make_scene()


@pytest.mark.parametrize("filter_name", ["gaussian", "blackman-harris", "box", "triangle"])
def test_bit_identical_across_tilings_and_threads(scene, filter_name):
    prep = prepare(scene, RenderOptions(width=40, height=28, spp=7, filter=filter_name, aovs=("depth",)))
    ref = render_frame(prep, tile_size=64, threads=1).sums
    for tile_size, threads in ((8, 2), (13, 2), (5, 1)):
        other = render_frame(prep, tile_size=tile_size, threads=threads).sums
        for k in ref:
            assert np.array_equal(ref[k], other[k]), (filter_name, tile_size, threads, k)
    # tiles of any shape sharing their borders assemble the same frame; one of them alone has its pixels beyond
    # the filter's reach of its edge final
    parts = [Tile(0, 0, 40, 5), Tile(0, 5, 11, 17), Tile(11, 5, 30, 17), Tile(30, 5, 40, 17), Tile(0, 17, 40, 28)]
    rendered = [render_tile(prep, t, shared_borders=True) for t in parts]
    mosaic = assemble(rendered, 40, 28)
    for k in ref:
        assert np.array_equal(ref[k], mosaic[k]), (filter_name, k)
    m = film.filter_margin(film.FILTERS[filter_name])
    shared = rendered[2].arrays["rgba"]
    assert np.array_equal(shared[m:12 - m, m:19 - m], ref["rgba"][5 + m:17 - m, 11 + m:30 - m])
    # a tile rendered on its own (it draws its margin's samples too) equals its region of the frame everywhere
    alone = render_tile(prep, Tile(11, 5, 30, 17))
    for k in ref:
        assert np.array_equal(alone.arrays[k], ref[k][5:17, 11:30]), (filter_name, k)
    assert not any(k.startswith("band.") for k in alone.arrays)
    assert assemble([alone], 40, 28)["rgba"][5:17, 11:30].tobytes() == ref["rgba"][5:17, 11:30].tobytes()
    assert ref["rgba"][..., :3].max() > 0.05  # the scene is lit


def test_the_default_tile_size_keeps_every_thread_busy(scene):
    # production frames keep 64 px tiles; a small preview gets smaller ones (at least 4 per thread, not under 16)
    assert auto_tile_size(640, 360, 2) == 64 and auto_tile_size(1920, 1080, 8) == 64
    assert auto_tile_size(160, 90, 2) == 32 and len(split_tiles(160, 90, 32)) >= 8
    assert auto_tile_size(40, 28, 2) == 16 and auto_tile_size(8, 8, 64) == 16
    prep = prepare(scene, RenderOptions(width=40, height=28, spp=3))
    auto = render_frame(prep, threads=2).sums  # the default is only a schedule: same pixels
    assert np.array_equal(auto["rgba"], render_frame(prep, tile_size=64, threads=1).sums["rgba"])


@pytest.mark.parametrize("width, height, size", [(1, 1, 1), (24, 16, 8), (40, 28, 16), (37, 23, 8), (5, 70, 64),
                                                  (160, 90, 32), (64, 64, 64)])
def test_the_tile_grid_covers_the_frame_once_in_row_major_order(width, height, size):
    tiles = split_tiles(width, height, size)
    assert len(tiles) == tile_count(width, height, size)
    covered = np.zeros((height, width), np.int32)
    for x0, y0, x1, y1 in tiles:
        covered[y0:y1, x0:x1] += 1
    assert (covered == 1).all()
    assert tiles == sorted(tiles, key=lambda t: (t.y0, t.x0))  # row-major: checkpoints are named by the index
    assert all(t.width == min(size, width - t.x0) and t.height == min(size, height - t.y0) for t in tiles)
    # a Tile is the plain box too (task keys, the border code) and pickles (Dask tasks carry tiles)
    assert tiles[0] == (0, 0, min(size, width), min(size, height)) and pickle.loads(pickle.dumps(tiles)) == tiles
    with pytest.raises(SettingsError):
        split_tiles(width, height, 0)


def test_a_frame_image_pickles_and_writes_what_write_frame_writes(scene, tmp_path):
    """The service's workers return a frame's image (channels, header, windows) and its coordinator writes it: plain
    values that pickle (an ``OpenEXR.TimeCode`` does not), written into the same file as ``write_frame``'s."""
    prep = prepare(scene, RenderOptions(width=24, height=16, spp=2))
    sums = render_frame(prep, tile_size=8, threads=1).sums
    write_frame(tmp_path / "direct.exr", prep, sums, half=True)
    pickle.loads(pickle.dumps(frame_image(prep, sums))).write(tmp_path / "shipped.exr", half=True)
    assert (tmp_path / "shipped.exr").read_bytes() == (tmp_path / "direct.exr").read_bytes()
    assert "timeCode" in read_exr(tmp_path / "shipped.exr")[1]


def test_seed_changes_the_noise_not_the_mean(scene):
    a = render_frame(prepare(scene, RenderOptions(width=24, height=16, spp=64, seed=1)), tile_size=16).sums
    b = render_frame(prepare(scene, RenderOptions(width=24, height=16, spp=64, seed=2)), tile_size=16).sums
    assert not np.array_equal(a["rgba"], b["rgba"])
    ma, mb = a["rgba"][..., 0].sum() / a["weight"].sum(), b["rgba"][..., 0].sum() / b["weight"].sum()
    assert abs(ma - mb) < 0.05 * max(ma, mb)


def test_a_prepared_scene_with_other_sampling_options_renders_as_if_prepared_with_them(scene):
    """What a service worker does for jobs of one scene that differ in seed, spp, filter, depth or AOVs."""
    base = prepare(scene, RenderOptions(width=24, height=16, spp=4, seed=1))
    other = RenderOptions(width=24, height=16, spp=8, seed=2, filter="box", max_depth=2, aovs=("depth",))
    a = render_frame(with_options(base, other), tile_size=16).sums
    b = render_frame(prepare(scene, other), tile_size=16).sums
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    for changed in (RenderOptions(width=32, height=16), RenderOptions(width=24, height=16, dof=False)):
        with pytest.raises(ValueError):
            with_options(base, changed)


def test_wave_schedule_depends_on_spp_and_progressive_only():
    assert film.wave_schedule(1) == [(0, 1)]
    assert film.wave_schedule(8) == [(0, 1), (1, 2), (2, 4), (4, 8)]
    assert film.wave_schedule(8, progressive=False) == [(0, 8)]
    assert film.wave_schedule(70, progressive=False) == [(0, 32), (32, 64), (64, 70)]
    for progressive in (True, False):
        waves = film.wave_schedule(1000, progressive)
        assert waves[0][0] == 0 and waves[-1][1] == 1000
        assert all(a[1] == b[0] for a, b in zip(waves, waves[1:]))
        assert max(e - s for s, e in waves) <= film.MAX_WAVE


def test_a_tile_is_the_same_bits_in_waves_of_any_size(scene):
    """A time budget (never reached here) makes the tile sample in doubling waves, 1, 1, 2, 4, ...; without, in
    waves of MAX_WAVE: the sums take each pixel's samples in the same order either way."""
    prep = prepare(scene, RenderOptions(width=16, height=12, spp=40, aovs=("depth", "normal", "albedo")))
    tile = Tile(0, 0, 16, 12)
    a = render_tile(prep, tile).arrays
    b = render_tile(prep, tile, time_budget=1.0e9).arrays
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    assert a["rgba"].any()


@pytest.mark.parametrize("name", list(film.FILTERS))
def test_filters_are_nonnegative_and_vanish_at_their_radius(name):
    kind = film.FILTERS[name]
    r = film.FILTER_RADIUS[kind]
    x = np.linspace(-r - 0.5, r + 0.5, 501)
    w = film.filter_weight_np(kind, x, 0.0 * x)
    assert np.all(w >= 0) and w.max() > 0
    assert np.all(w[(x >= r) | (x < -r)] == 0)  # box is half-open: [-r, r)
    assert film.filter_margin(kind) == int(np.ceil(r - 0.5))


def test_no_nan_reaches_the_image(scene):
    prep = prepare(scene, RenderOptions(width=16, height=12, spp=4, aovs=("depth", "normal", "albedo")))
    r = render_frame(prep, tile_size=8)
    for v in r.sums.values():
        assert np.isfinite(v).all()
    assert r.nonfinite == 0


def test_progress_reaches_the_total_and_cancellation_stops_between_waves(scene):
    from renderer.errors import Cancelled

    prep = prepare(scene, RenderOptions(width=16, height=16, spp=80))  # waves of 32, 32 and 16 samples
    seen = []
    render_frame(prep, tile_size=8, threads=2, progress=lambda done, total: seen.append((done, total)))
    assert seen[-1] == (16 * 16 * 80, 16 * 16 * 80)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)

    waves = []

    def stop_after_two(done, total):
        waves.append(done)
        if len(waves) == 2:
            raise Cancelled()

    with pytest.raises(Cancelled):
        render_tile(prep, Tile(0, 0, 16, 16), stop_after_two)
    assert waves == [16 * 16 * 32, 16 * 16 * 64]  # stopped after the second wave, before the third


@pytest.mark.parametrize("name", list(film.FILTERS))
def test_the_kernels_axis_weights_make_the_filter(name):
    kind = film.FILTERS[name]
    rng = np.random.default_rng(3)
    u = rng.random((500, 2)).astype(np.float32)
    u[:4] = [[0.0, 0.0], [0.5, 0.5], [0.999, 0.25], [0.25, 0.0]]  # pixel edges and centre
    buf = film.new_sample_buffer(len(u), "cpu")
    buf.film = wp.array(u, dtype=wp.vec2, device="cpu")
    wp.launch(film.axis_weights_kernel, dim=len(u), inputs=[buf, kind, float(film.FILTER_RADIUS[kind])], device="cpu")
    wx, wy = buf.wx.numpy(), buf.wy.numpy()
    for o in (-1, 0, 1):  # toward the pixel at offset o (the sample sits at u - 0.5 - o from its centre)
        for p in (-1, 0, 1):
            want = film.filter_weight_np(kind, u[:, 0] - 0.5 - o, u[:, 1] - 0.5 - p)
            np.testing.assert_allclose(wx[:, o + 1] * wy[:, p + 1], want, rtol=1e-5, atol=1e-6)


def test_the_gaussian_weights_exp_is_within_two_ulp():
    """``gaussian_axis`` (vector code, exp as a polynomial) against the exact exp of the same float32 argument, at
    200001 positions over a pixel: within 2 ulp, 0 at the radius, and the same weights as the formula."""
    k = film.FILTER_GAUSSIAN
    u = np.linspace(0, 1, 200001, endpoint=False).astype(np.float32)
    buf = film.new_sample_buffer(len(u), "cpu")
    buf.film = wp.array(np.stack([u, u], 1), dtype=wp.vec2, device="cpu")
    wp.launch(film.axis_weights_kernel, dim=len(u), inputs=[buf, k, 1.5], device="cpu")
    wx = buf.wx.numpy()
    x = np.stack([u + np.float32(0.5), u - np.float32(0.5), u - np.float32(1.5)], 1)
    arg = (np.abs(x) * np.abs(x)) * np.float32(-1.0 / (2.0 * film.GAUSSIAN_SIGMA ** 2))
    exact = np.exp(arg.astype(np.float64))
    edge = np.exp(-2.0 * 1.5 ** 2)  # gaussian_edge: libm's expf of the same argument, within 0.1 ulp of exp here
    inside = np.abs(x) < 1.5
    got = wx.astype(np.float64) + edge  # the weight is exp - edge, rounded once
    ulps = np.abs(got - exact) / np.spacing(exact.astype(np.float32)).astype(np.float64)
    assert ulps[inside].max() <= 2.0
    assert np.all(wx[~inside] == 0.0) and (~inside).any()  # u = 0: the far neighbour at exactly the radius


def test_the_colour_does_not_depend_on_which_aovs_are_asked_for(scene):
    """The gather adds depth, normal and albedo only for a render that asks for one of them (or denoises): the
    colour and weight sums are the same bits either way, and each AOV's sums are the same whichever set asks."""
    plain = render_frame(prepare(scene, RenderOptions(width=24, height=16, spp=4)), tile_size=8).sums
    every = render_frame(prepare(scene, RenderOptions(width=24, height=16, spp=4,
                                                      aovs=("depth", "normal", "albedo"))), tile_size=8).sums
    normal = render_frame(prepare(scene, RenderOptions(width=24, height=16, spp=4, aovs=("normal",))),
                          tile_size=8).sums
    for k in ("rgba", "weight"):
        assert np.array_equal(plain[k], every[k]) and np.array_equal(plain[k], normal[k]), k
    assert np.abs(every["normal"]).sum() > 0 and np.array_equal(every["normal"], normal["normal"])
    assert np.array_equal(every["depth"], normal["depth"])  # any one of them gathers all three
    assert not plain["depth"].any() and not plain["normal"].any()  # the work that is skipped
    assert film.needs_aov_sums((), True) and film.needs_aov_sums(("albedo",), False)
    assert not film.needs_aov_sums(("spp",), False)


@pytest.mark.parametrize("region", [(0, 0, 12, 9, 0, 0, 13, 10), (5, 4, 12, 9, 4, 3, 14, 11)])
def test_the_vector_gather_gives_the_bits_of_the_loop(region):
    """``gather_nine`` (a source pixel's nine colour partials as vector code) against ``gather_kernel``'s loop, bit
    for bit: random samples and partials (negative zeros among them), weights of 0 (a sample a partial skips),
    stopped pixels, targets beyond the extended region on every side; two waves in a row."""
    x0, y0, w, h, ex0, ey0, ex1, ey1 = region
    wave = 7
    rng = np.random.default_rng(5)
    targets = (ex1 - ex0) * (ey1 - ey0)
    slot_of = np.arange(w * h, dtype=np.int32)
    slot_of[rng.random(w * h) < 0.2] = -1
    rgba0 = rng.normal(size=(targets * 9, 4)).astype(np.float32)
    rgba0[rng.random(rgba0.shape) < 0.3] = -0.0
    weight0 = rng.random(targets * 9).astype(np.float32)
    weight0[::3] = -0.0
    results = []
    for native in (0, 1):
        acc = film.new_tile_accum(targets * 9, "cpu")
        acc.rgba = wp.array(rgba0, dtype=wp.vec4)
        acc.weight = wp.array(weight0, dtype=wp.float32)
        for k in range(2):
            r = np.random.default_rng(k)
            buf = film.new_sample_buffer(w * h * wave, "cpu")
            buf.rgba = wp.array(r.normal(size=(w * h * wave, 4)).astype(np.float32), dtype=wp.vec4)
            wx, wy = r.random((2, w * h * wave, 3)).astype(np.float32)
            wx[r.random(wx.shape) < 0.2] = 0.0
            wy[r.random(wy.shape) < 0.2] = 0.0
            # some pixels give one direction no weight at all: their partial there must keep its bits (-0.0)
            wx.reshape(w * h, wave, 3)[r.random(w * h) < 0.3, :, 0] = 0.0
            buf.wx, buf.wy = wp.array(wx, dtype=wp.vec3), wp.array(wy, dtype=wp.vec3)
            wp.launch(film.gather_kernel, dim=w * h, inputs=[buf, acc, wave, x0, y0, w, wp.array(slot_of), ex0, ey0,
                                                              ex1 - ex0, ey1 - ey0, 1, 0, native])
        results.append((acc.rgba.numpy(), acc.weight.numpy()))
    (a_rgba, a_w), (b_rgba, b_w) = results
    assert not np.array_equal(a_rgba, rgba0)  # the samples were added
    np.testing.assert_array_equal(a_rgba.view(np.uint32), b_rgba.view(np.uint32))
    np.testing.assert_array_equal(a_w.view(np.uint32), b_w.view(np.uint32))
