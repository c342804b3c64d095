"""The integrator's render loop over one tile: waves of samples launched through the path tracing kernel, filtered
into the tile's sums (``film``), with adaptive sampling, time budgets and the id tables of Cryptomatte.

``render_tile`` is a pure function of (prepared scene, tile): the same bits whoever renders it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import warp as wp

from renderer.errors import SettingsError
from renderer.film import borders, coverage, film, hit_vars, id_tables
from renderer.film.adaptive import Convergence
from renderer.film.tiles import Tile
from renderer.integrator.layers import trace_wave_layers_kernel
from renderer.integrator.path import PathSettings, Wave, trace_wave_kernel
from renderer.kernels.device import denormals_flushed
from renderer.prepared import COVERAGE_NAMES, PreparedScene, coverage_kinds
from renderer.settings.options import TIME_FILTERS, RenderOptions


@dataclass
class TileSums:
    """Filtered sums of one tile: arrays (h, w[, c]) float32."""

    tile: Tile
    arrays: dict[str, np.ndarray]
    rays: int = 0
    nonfinite: int = 0


def render_tile(prep: PreparedScene, tile: Tile,
                on_wave: Callable[[int, int], None] | None = None, *,
                time_budget: float | None = None, shared_borders: bool = False) -> TileSums:
    """Render one tile: its filtered sums and weights, a pure function of (scene, options, tile).

    By default the tile is final on its own: it also draws the samples of the ring of pixels its filter reaches
    (``filter_margin``), so its pixels equal the same pixels of a whole-frame render, bit for bit (a crop).
    With ``shared_borders`` (what ``render_frame`` and the service do) it draws its own pixels' samples only, so no
    sample is drawn by two tiles: its arrays then hold its pixels' sums (final except within the filter's reach of
    its edge, where they hold its own samples' share) and, under ``band.``, the partial sums that ``assemble``
    adds to the neighbouring tiles' into the exact border pixels (``film.borders``). Either way the sums are the
    same per-direction partials added in the same order, so both give the same bits.

    ``on_wave(samples_done_in_tile, samples_total_in_tile)`` is called after every wave; raising
    ``Cancelled`` from it stops the render. ``time_budget`` (seconds) stops sampling before the wave that would
    overrun it (progressive rendering; the result then depends on the machine's speed). Samples per pixel are
    ``options.spp`` at most, fewer where adaptive sampling found a pixel converged (``sums["spp"]``).

    The thread computes with denormals flushed to zero meanwhile (``device.denormals_flushed``).
    """
    with denormals_flushed():
        return _sampled_tile(prep, tile, on_wave, time_budget, shared_borders)


def _sampled_tile(prep: PreparedScene, tile: Tile, on_wave: Callable[[int, int], None] | None,
                  time_budget: float | None, shared_borders: bool) -> TileSums:
    """``render_tile``'s work."""
    opts = prep.options
    W, H = prep.width, prep.height
    if not (0 <= tile.x0 < tile.x1 <= W and 0 <= tile.y0 < tile.y1 <= H):
        raise SettingsError(f"tile {tile} is outside the {W}x{H} image")
    t_start = time.perf_counter()
    kind = film.FILTERS[opts.filter]
    margin = film.filter_margin(kind)
    ring = borders.extended_region(tile.x0, tile.y0, tile.x1, tile.y1, margin, W, H)
    own = (tile.x0, tile.y0, tile.x1, tile.y1)
    # sample pixels (sx0, sy0) .. (sx1, sy1) and target pixels (ex0, ey0) .. (ex1, ey1)
    sx0, sy0, sx1, sy1 = own if shared_borders else ring
    ex0, ey0, ex1, ey1 = ring if shared_borders else own
    sw, sh = sx1 - sx0, sy1 - sy0
    targets = (ex1 - ex0) * (ey1 - ey0)
    directions = borders.directions(margin)
    aov_sums = int(film.needs_aov_sums(opts.aovs, opts.denoise))
    conv = Convergence(sw * sh, opts.noise_threshold, opts.min_spp)
    # one launch per MAX_WAVE samples unless something decides between waves: launches and passes over the
    # tile's sums cost time of their own (the teapot shot at 16 spp: 300 waves of 1-8 samples, 2.10 s; 60, 1.91 s)
    waves = film.wave_schedule(opts.spp, progressive=conv.enabled or time_budget is not None)
    max_wave = max(e - s for s, e in waves)
    dev = prep.device
    n_lpe = prep.lpe_count
    extra = n_lpe  # RGB triples filtered as the colour: the LPE vars'
    plan = prep.hit_layout
    hit_triples = plan.triples if plan else 0  # ... and the vars of what each sample hit
    tables = coverage_kinds(opts)  # id tables: {kind: (ids, weights)} per (target, direction, slot)
    records = 2 if plan and plan.keys else int(bool(tables))
    buf = film.new_sample_buffer(sw * sh * max_wave, dev, extra=extra, hits=records > 0,
                                 hit_triples=hit_triples)
    tables = {k: (wp.full(targets * directions * coverage.SLOTS, -1, dtype=wp.int32, device=dev),
                  wp.zeros(targets * directions * coverage.SLOTS, dtype=wp.float32, device=dev)) for k in tables}
    sample_ids = wp.empty(sw * sh * max_wave if tables else 1, dtype=wp.vec2i, device=dev)
    none = (wp.empty(1, dtype=wp.int32, device=dev), wp.empty(1, dtype=wp.float32, device=dev))
    kinds_mask = sum(1 << k for k in tables)
    acc = film.new_tile_accum(directions * targets, dev, aovs=bool(aov_sums), extra=extra, hit_triples=hit_triples)

    counters = wp.zeros(2, dtype=wp.int64, device=dev)  # rays traced, non-finite samples zeroed
    settings = PathSettings()
    settings.max_depth = int(opts.max_depth)
    settings.clamp = float(opts.clamp)
    settings.indirect_clamp = opts.path_indirect_clamp
    settings.glossy_filter = opts.path_glossy_filter
    settings.time_filter = TIME_FILTERS[opts.time_filter]
    settings.frame_s = prep.scene.shutter.frame_s
    settings.seed = wp.uint32(opts.seed)
    settings.record_hits = records
    # the kernel without the LPE and record code when neither is asked for (``integrator.trace_wave_kernel_variant``)
    trace = trace_wave_layers_kernel if records or extra else trace_wave_kernel
    slot_of = np.full(sw * sh, -1, np.int32)
    # the tile's own pixels among the sample pixels (its samples-per-pixel count and progress)
    mine = np.zeros((sh, sw), bool)
    mine[tile.y0 - sy0:tile.y1 - sy0, tile.x0 - sx0:tile.x1 - sx0] = True
    mine = mine.ravel()
    total = tile.width * tile.height * opts.spp
    for start, end in waves:
        wave = end - start
        pixels = conv.active_pixels()
        if pixels.size == 0:
            break
        if time_budget is not None and start > 0:
            # stop before a wave that would overrun the budget, predicted from the rate so far
            elapsed = time.perf_counter() - t_start
            per_sample = elapsed / max(1, int(conv.count.sum()))
            if elapsed + per_sample * pixels.size * wave > time_budget:
                break
        slot_of[:] = -1
        slot_of[pixels] = np.arange(pixels.size, dtype=np.int32)
        launch = Wave()
        launch.active = wp.array(pixels, dtype=wp.int32, device=dev)
        launch.region_x0, launch.region_y0, launch.region_w = sx0, sy0, sw
        launch.start, launch.count = start, wave
        launch.counters = counters
        wp.launch(trace, dim=pixels.size * wave, device=dev,
                  inputs=[prep.geometry, prep.materials, prep.textures, prep.lights, prep.media.media,
                          prep.camera.params, buf,
                          settings, launch, prep.lpe_table])
        wp.launch(film.axis_weights_kernel, dim=pixels.size * wave, device=dev,
                  inputs=[buf, kind, float(film.FILTER_RADIUS[kind])])
        slot_array = wp.array(slot_of, dtype=wp.int32, device=dev)
        wp.launch(film.gather_kernel, dim=sw * sh, device=dev,
                  inputs=[buf, acc, wave, sx0, sy0, sw, slot_array, ex0, ey0, ex1 - ex0, ey1 - ey0, margin, aov_sums,
                          1])
        if plan and plan.keys:
            n = pixels.size * wave
            hit_vars.fill(plan, prep.flat or prep.scene, *prep.hit_index, buf.hit_inst.numpy()[:n],
                          buf.hit_tri.numpy()[:n], buf.hit_uv.numpy()[:n], buf.hit_p.numpy()[:n],
                          buf.hits.numpy()[:n * hit_triples].reshape(n, hit_triples, 3))
        if tables:
            wp.launch(coverage.sample_ids_kernel, dim=pixels.size * wave, device=dev,
                      inputs=[buf, *prep.objects, prep.geometry.tri_material, sample_ids])
            wp.launch(coverage.coverage_gather_kernel, dim=sw * sh, device=dev,
                      inputs=[buf, sample_ids, *tables.get(coverage.KIND_OBJECT, none),
                              *tables.get(coverage.KIND_MATERIAL, none), kinds_mask, wave, sx0, sy0, sw, slot_array,
                              ex0, ey0, ex1 - ex0, ey1 - ey0, margin])
        for src, dst, count in ((buf.extra, acc.extra, extra), (buf.hits, acc.hits, hit_triples)):
            if count:
                wp.launch(film.gather_extra_kernel, dim=sw * sh, device=dev,
                          inputs=[buf, src, dst, count, wave, sx0, sy0, sw, slot_array, ex0, ey0, ex1 - ex0, ey1 - ey0,
                                  margin])
        rgb = None
        if conv.enabled:
            rgb = buf.rgba.numpy()[:pixels.size * wave].reshape(pixels.size, wave, 4)[..., :3]
        conv.add_wave(pixels, rgb, start, wave)
        conv.update()
        if on_wave is not None:
            on_wave(min(total, int(conv.count[mine].sum())), total)
    partials = film.accum_partials(acc, directions, ey1 - ey0, ex1 - ex0, aovs=bool(aov_sums), extra=extra,
                                   hit_triples=hit_triples)
    if shared_borders:
        arrays = borders.split_tile(partials, own, margin, W, H)
    else:
        arrays = {name: borders.combine(p) if p is not None else borders.zero_sums(name, (ey1 - ey0, ex1 - ex0))
                  for name, p in partials.items()}
    band = borders.band_mask(tile.x0, tile.y0, tile.x1, tile.y1, margin, W, H) if shared_borders and margin else None
    for kind, (ids, weights) in tables.items():
        shape = (ey1 - ey0, ex1 - ex0, directions, coverage.SLOTS)
        per_direction = [np.moveaxis(a.numpy().reshape(shape), 2, 0) for a in (ids, weights)]
        mine, banded = id_tables.tile_tables(COVERAGE_NAMES[kind], *per_direction,
                                             own if shared_borders else (ex0, ey0, ex1, ey1), (ex0, ey0), band)
        arrays.update(mine)
        arrays.update((borders.BAND + k, a) for k, a in banded.items())
    arrays["spp"] = conv.count.reshape(sh, sw)[tile.y0 - sy0:tile.y1 - sy0, tile.x0 - sx0:tile.x1 - sx0] \
        .astype(np.float32)
    c = counters.numpy()
    return TileSums(tile=tile, arrays=arrays, rays=int(c[0]), nonfinite=int(c[1]))


def tile_time_budget(options: RenderOptions, tile: Tile, width: int, height: int, threads: int = 1) -> float | None:
    """A tile's fair share of the frame's time limit: its share of the frame's pixels, times the threads that
    render tiles at once (so the frame takes about the limit in wall-clock time). None without a limit."""
    if not options.time_limit:
        return None
    return float(options.time_limit) * threads * (tile.width * tile.height) / (width * height)


