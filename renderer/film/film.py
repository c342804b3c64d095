"""The film: pixel reconstruction filters, sample waves, and the gather of samples into tile pixels.

Samples are taken uniformly over each pixel's area (the film dimensions of the sample) and every sample
contributes to all pixels whose filter covers it, weighted by the filter: pixel = sum(w L) / sum(w). A tile
therefore also renders the samples of a margin of ``ceil(radius - 0.5)`` pixels around it, so that its border
pixels receive exactly the contributions they would get in one whole-frame render: no seams, and the sums run
over the same samples in the same order whatever the tiling.

The sample budget is spent in *waves* of 1, 1, 2, 4, ... samples per pixel (capped), a schedule that depends on
the sample count only, never on tile size or threads: the floating-point sums are then bit-identical across
tilings. Progress and cancellation happen between waves.
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from renderer.struct_refs import by_reference

# Rendering needs no gradients: no adjoint code (half the compile time and code size).
wp.set_module_options({"enable_backward": False})

from renderer.options import FILTERS

FILTER_BOX = FILTERS["box"]
FILTER_TRIANGLE = FILTERS["triangle"]
FILTER_GAUSSIAN = FILTERS["gaussian"]
FILTER_BLACKMAN_HARRIS = FILTERS["blackman-harris"]
# Radii in pixels: box covers exactly one pixel; gaussian as pbrt-v4 (sigma 0.5); Blackman-Harris 1.5 px
# radius (Cycles' default filter width of 1.5 px is the *half* width of its window... we take the full 3 px
# support that Cycles uses).
FILTER_RADIUS = {FILTER_BOX: 0.5, FILTER_TRIANGLE: 1.0, FILTER_GAUSSIAN: 1.5, FILTER_BLACKMAN_HARRIS: 1.5}
GAUSSIAN_SIGMA = 0.5
MAX_WAVE = 32  # samples per pixel per wave (bounds the sample buffer of a tile)


def filter_margin(kind: int) -> int:
    """Pixels of margin a tile must render so that its own pixels see every sample their filter covers."""
    return int(math.ceil(FILTER_RADIUS[kind] - 0.5))


def wave_schedule(spp: int) -> list[tuple[int, int]]:
    """[start, end) sample-index ranges: 1, 1, 2, 4, ... capped at MAX_WAVE; depends on spp only."""
    waves, start, size = [], 0, 1
    while start < spp:
        end = min(spp, start + size)
        waves.append((start, end))
        if start > 0:
            size = min(size * 2, MAX_WAVE)
        start = end
    return waves


@wp.func
def filter_1d(kind: int, x: float, radius: float):
    ax = wp.abs(x)
    if ax >= radius:
        return 0.0
    if kind == FILTER_TRIANGLE:
        return 1.0 - ax / radius
    if kind == FILTER_GAUSSIAN:
        # Gaussian minus its value at the radius, so it falls to exactly 0 there (pbrt-v4)
        a = 1.0 / (2.0 * GAUSSIAN_SIGMA * GAUSSIAN_SIGMA)
        return wp.exp(-a * ax * ax) - wp.exp(-a * radius * radius)
    if kind == FILTER_BLACKMAN_HARRIS:
        # 4-term window over [-radius, radius]
        t = (x / radius + 1.0) * 0.5
        w = 2.0 * wp.pi * t
        return 0.35875 - 0.48829 * wp.cos(w) + 0.14128 * wp.cos(2.0 * w) - 0.01168 * wp.cos(3.0 * w)
    return 1.0


@wp.func
def filter_weight(kind: int, dx: float, dy: float, radius: float):
    """Weight of a sample at offset (dx, dy) pixels from a pixel centre."""
    if kind == FILTER_BOX:
        # half-open pixel square, so a sample on a pixel edge belongs to exactly one pixel
        if dx >= -0.5 and dx < 0.5 and dy >= -0.5 and dy < 0.5:
            return 1.0
        return 0.0
    return filter_1d(kind, dx, radius) * filter_1d(kind, dy, radius)


def filter_weight_np(kind: int, dx, dy) -> np.ndarray:
    """NumPy twin of ``filter_weight`` (tests)."""
    r = FILTER_RADIUS[kind]
    dx, dy = np.asarray(dx, np.float64), np.asarray(dy, np.float64)
    if kind == FILTER_BOX:
        return ((dx >= -0.5) & (dx < 0.5) & (dy >= -0.5) & (dy < 0.5)).astype(np.float64)

    def f1(x):
        ax = np.abs(x)
        if kind == FILTER_TRIANGLE:
            v = 1 - ax / r
        elif kind == FILTER_GAUSSIAN:
            a = 1 / (2 * GAUSSIAN_SIGMA**2)
            v = np.exp(-a * ax * ax) - np.exp(-a * r * r)
        else:
            w = 2 * np.pi * (x / r + 1) * 0.5
            v = 0.35875 - 0.48829 * np.cos(w) + 0.14128 * np.cos(2 * w) - 0.01168 * np.cos(3 * w)
        return np.where(ax < r, v, 0.0)

    return f1(dx) * f1(dy)


@by_reference
@wp.struct
class SampleBuffer:
    """One wave of samples of a tile's region (tile + margin): index (slot * wave + j), where slot is the
    pixel's position in the wave's list of pixels still sampling (every region pixel without adaptive sampling)."""

    film: wp.array(dtype=wp.vec2)  # sample position within its pixel, [0, 1)^2
    rgba: wp.array(dtype=wp.vec4)  # premultiplied radiance and coverage
    depth: wp.array(dtype=wp.float32)  # camera depth of the first hit (0 when nothing was hit)
    normal: wp.array(dtype=wp.vec3)  # world shading normal of the first hit
    albedo: wp.array(dtype=wp.vec3)


@by_reference
@wp.struct
class TileAccum:
    """Filtered sums of a tile's pixels: sum(w * value) and sum(w); AOVs average over covered samples."""

    rgba: wp.array(dtype=wp.vec4)
    weight: wp.array(dtype=wp.float32)
    depth: wp.array(dtype=wp.float32)  # sum(w * depth) over samples that hit
    hit_weight: wp.array(dtype=wp.float32)  # sum(w) over samples that hit
    normal: wp.array(dtype=wp.vec3)
    albedo: wp.array(dtype=wp.vec3)


def new_sample_buffer(n: int, device: str) -> SampleBuffer:
    b = SampleBuffer()
    b.film = wp.zeros(n, dtype=wp.vec2, device=device)
    b.rgba = wp.zeros(n, dtype=wp.vec4, device=device)
    b.depth = wp.zeros(n, dtype=wp.float32, device=device)
    b.normal = wp.zeros(n, dtype=wp.vec3, device=device)
    b.albedo = wp.zeros(n, dtype=wp.vec3, device=device)
    return b


def new_tile_accum(n: int, device: str) -> TileAccum:
    a = TileAccum()
    a.rgba = wp.zeros(n, dtype=wp.vec4, device=device)
    a.weight = wp.zeros(n, dtype=wp.float32, device=device)
    a.depth = wp.zeros(n, dtype=wp.float32, device=device)
    a.hit_weight = wp.zeros(n, dtype=wp.float32, device=device)
    a.normal = wp.zeros(n, dtype=wp.vec3, device=device)
    a.albedo = wp.zeros(n, dtype=wp.vec3, device=device)
    return a


@wp.kernel
def gather_kernel(
    buf: SampleBuffer,
    acc: TileAccum,
    wave: int,  # samples per pixel in this wave
    region_x0: int,  # region origin and size (pixels, full-image coordinates)
    region_y0: int,
    region_w: int,
    region_h: int,
    slot_of: wp.array(dtype=wp.int32),  # a region pixel's slot in this wave's buffer, -1: it has stopped
    tile_x0: int,
    tile_y0: int,
    tile_w: int,
    filter_kind: int,
    radius: float,
    margin: int,
):
    """Add one wave's samples to each tile pixel, in a fixed order (neighbour rows, columns, samples)."""
    tid = wp.tid()
    px = tile_x0 + tid % tile_w
    py = tile_y0 + tid // tile_w
    cx = float(px) + 0.5
    cy = float(py) + 0.5
    rgba = acc.rgba[tid]
    wsum = acc.weight[tid]
    dsum = acc.depth[tid]
    hsum = acc.hit_weight[tid]
    nsum = acc.normal[tid]
    asum = acc.albedo[tid]
    for oy in range(-margin, margin + 1):
        qy = py + oy
        ry = qy - region_y0
        if ry >= 0 and ry < region_h:
            for ox in range(-margin, margin + 1):
                qx = px + ox
                rx = qx - region_x0
                slot = int(-1)
                if rx >= 0 and rx < region_w:
                    slot = slot_of[ry * region_w + rx]
                if slot >= 0:
                    base = slot * wave
                    for j in range(wave):
                        f = buf.film[base + j]
                        w = filter_weight(filter_kind, float(qx) + f[0] - cx, float(qy) + f[1] - cy, radius)
                        if w != 0.0:
                            c = buf.rgba[base + j]
                            rgba = rgba + c * w
                            wsum = wsum + w
                            if c[3] > 0.0:
                                hw = w * c[3]
                                dsum = dsum + buf.depth[base + j] * hw
                                hsum = hsum + hw
                                nsum = nsum + buf.normal[base + j] * hw
                                asum = asum + buf.albedo[base + j] * hw
    acc.rgba[tid] = rgba
    acc.weight[tid] = wsum
    acc.depth[tid] = dsum
    acc.hit_weight[tid] = hsum
    acc.normal[tid] = nsum
    acc.albedo[tid] = asum


def resolve(sums: dict[str, np.ndarray], exposure_scale: float = 1.0) -> dict[str, np.ndarray]:
    """Divide filtered sums by their weights: final premultiplied RGBA and AOVs, finite everywhere."""
    w = sums["weight"]
    hw = sums["hit_weight"]
    with np.errstate(divide="ignore", invalid="ignore"):
        rgba = np.where(w[..., None] > 0, sums["rgba"] / w[..., None], 0.0)
        depth = np.where(hw > 0, sums["depth"] / hw, 0.0)
        albedo = np.where(hw[..., None] > 0, sums["albedo"] / hw[..., None], 0.0)
        n = sums["normal"]
        nlen = np.linalg.norm(n, axis=-1, keepdims=True)
        normal = np.where(nlen > 0, n / nlen, 0.0)
    rgba[..., :3] *= exposure_scale
    out = {"rgba": rgba, "depth": depth, "normal": normal, "albedo": albedo}
    return {k: np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32) for k, v in out.items()}
