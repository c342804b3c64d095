"""The film: pixel reconstruction filters, sample waves, and the gather of samples into tile pixels.

Samples are taken uniformly over each pixel's area (the film dimensions of the sample) and every sample
contributes to all pixels whose filter covers it, weighted by the filter: pixel = sum(w L) / sum(w). The
gather keeps one partial sum per target pixel and source direction (``borders``): a tile of a frame draws its
own pixels' samples only and hands the partials of its border over for assembly (no sample drawn twice), a tile
rendered on its own also draws the ring of ``ceil(radius - 0.5)`` pixels around it; either way the sums run over
the same samples in the same order whatever the tiling: no seams.

The sample budget is spent in *waves*, a schedule that depends on the sample count and the render's options only,
never on tile size or threads: of 1, 1, 2, 4, ... samples per pixel (capped) where adaptive sampling or a time
limit decides between waves, else of the cap at a time. Either way a pixel's sums take its samples in sample
order, so the floating-point sums are bit-identical across tilings and schedules. Progress and cancellation
happen between waves.
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from renderer.sampling.warps import sin_cos
from renderer.kernels.struct_refs import by_reference
from renderer.kernels.vector_code import VECTOR_TYPES_CPP

# Rendering needs no gradients: no adjoint code (half the compile time and code size).
wp.set_module_options({"enable_backward": False})

from renderer.settings.options import FILTERS

FILTER_BOX = FILTERS["box"]
FILTER_TRIANGLE = FILTERS["triangle"]
FILTER_GAUSSIAN = FILTERS["gaussian"]
FILTER_BLACKMAN_HARRIS = FILTERS["blackman-harris"]
# Radii in pixels: box covers exactly one pixel; gaussian as pbrt-v4 (sigma 0.5); Blackman-Harris 1.5 px
# radius (Cycles' default filter width of 1.5 px is the *half* width of its window... we take the full 3 px
# support that Cycles uses).
FILTER_RADIUS = {FILTER_BOX: 0.5, FILTER_TRIANGLE: 1.0, FILTER_GAUSSIAN: 1.5, FILTER_BLACKMAN_HARRIS: 1.5}
GAUSSIAN_SIGMA = 0.5
assert max(FILTER_RADIUS.values()) <= 1.5  # a sample reaches one pixel beyond its own at most (``axis_weights``)
MAX_WAVE = 32  # samples per pixel per wave (bounds the sample buffer of a tile)


def filter_margin(kind: int) -> int:
    """How many pixels a sample's filter reaches beyond its own pixel (the ring of ``borders``): 0 or 1."""
    return int(math.ceil(FILTER_RADIUS[kind] - 0.5))


def wave_schedule(spp: int, progressive: bool = True) -> list[tuple[int, int]]:
    """[start, end) sample-index ranges: 1, 1, 2, 4, ... capped at MAX_WAVE when ``progressive`` (adaptive
    sampling and time limits decide between waves), else MAX_WAVE at a time; depends on these two only."""
    if not progressive:
        return [(s, min(spp, s + MAX_WAVE)) for s in range(0, spp, MAX_WAVE)]
    waves, start, size = [], 0, 1
    while start < spp:
        end = min(spp, start + size)
        waves.append((start, end))
        if start > 0:
            size = min(size * 2, MAX_WAVE)
        start = end
    return waves


@wp.func
def gaussian_edge(radius: float):
    """The Gaussian's value at the radius, which ``filter_1d`` subtracts so that the filter falls to exactly 0
    there (pbrt-v4): computed once per sample, not once per weight (it was 6 of a sample's 12 calls of exp)."""
    a = 1.0 / (2.0 * GAUSSIAN_SIGMA * GAUSSIAN_SIGMA)
    return wp.exp(-a * radius * radius)


@wp.func
def filter_1d(kind: int, x: float, radius: float, edge: float):
    """The 1D filter at offset x pixels; ``edge`` is ``gaussian_edge(radius)`` for the Gaussian (else unused)."""
    ax = wp.abs(x)
    if ax >= radius:
        return 0.0
    if kind == FILTER_TRIANGLE:
        return 1.0 - ax / radius
    if kind == FILTER_GAUSSIAN:
        a = 1.0 / (2.0 * GAUSSIAN_SIGMA * GAUSSIAN_SIGMA)
        return wp.exp(-a * ax * ax) - edge
    if kind == FILTER_BLACKMAN_HARRIS:
        # 4-term window over [-radius, radius]; cos 2w and cos 3w from cos w (double- and triple-angle formulas)
        # and cos w from ``sin_cos``'s polynomials: three libm cosf calls per weight, 18 per sample, were 18 % of a
        # teapot-shot render with this filter
        t = (x / radius + 1.0) * 0.5
        w = 2.0 * wp.pi * t
        sw, c1 = sin_cos(w)
        c2 = 2.0 * c1 * c1 - 1.0
        c3 = c1 * (2.0 * c2 - 1.0)
        return 0.35875 - 0.48829 * c1 + 0.14128 * c2 - 0.01168 * c3
    return 1.0


def filter_weight_np(kind: int, dx, dy) -> np.ndarray:
    """Weight of a sample at offset (dx, dy) pixels from a pixel centre (tests; the kernels multiply
    ``axis_weights``)."""
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
    """One wave of samples of a tile's pixels: index (slot * wave + j), where slot is the pixel's position in
    the wave's list of pixels still sampling (every tile pixel without adaptive sampling)."""

    film: wp.array(dtype=wp.vec2)  # sample position within its pixel, [0, 1)^2
    rgba: wp.array(dtype=wp.vec4)  # premultiplied radiance and coverage
    depth: wp.array(dtype=wp.float32)  # camera depth of the first hit (0 when nothing was hit)
    normal: wp.array(dtype=wp.vec3)  # world shading normal of the first hit
    albedo: wp.array(dtype=wp.vec3)
    # per sample, ``extra`` RGB triples of further channels filtered as the colour is (the LPE vars' sums,
    # ``renderer.lpe.kernel``; one element when there are none)
    extra: wp.array(dtype=wp.vec3)
    hits: wp.array(dtype=wp.vec3)  # per sample, the RGB triples of the vars of what it hit (``film.hit_vars``)
    # the instance, global triangle, barycentrics (b1, b2) and world point each sample saw first (instance -1:
    # none), when a render records them (Cryptomatte, primvar and id vars)
    hit_inst: wp.array(dtype=wp.int32)
    hit_tri: wp.array(dtype=wp.int32)
    hit_uv: wp.array(dtype=wp.vec2)
    hit_p: wp.array(dtype=wp.vec3)
    wx: wp.array(dtype=wp.vec3)  # filter weights along x toward the pixels at offsets -1, 0, +1 (``axis_weights``)
    wy: wp.array(dtype=wp.vec3)


@by_reference
@wp.struct
class TileAccum:
    """Filtered sums of a tile's target pixels, one set per source direction (``borders``): sum(w * value) and
    sum(w); AOVs average over covered samples."""

    rgba: wp.array(dtype=wp.vec4)
    weight: wp.array(dtype=wp.float32)
    depth: wp.array(dtype=wp.float32)  # sum(w * depth) over samples that hit
    hit_weight: wp.array(dtype=wp.float32)  # sum(w) over samples that hit
    normal: wp.array(dtype=wp.vec3)
    albedo: wp.array(dtype=wp.vec3)
    extra: wp.array(dtype=wp.vec3)  # sum(w * value) of each further RGB triple: (partial, triple), flat
    hits: wp.array(dtype=wp.vec3)  # ... of each hit var's triple


def new_sample_buffer(n: int, device: str, extra: int = 0, hits: bool = False,
                      hit_triples: int = 0) -> SampleBuffer:
    """Room for n samples with ``extra`` further RGB triples, ``hit_triples`` of hit vars and hit records
    (``hits``) each, not cleared: a wave writes every sample it later reads (the path tracing kernel its values,
    ``axis_weights_kernel`` its weights) before the gather reads them."""
    b = SampleBuffer()
    b.extra = wp.empty(max(1, n * extra), dtype=wp.vec3, device=device)
    b.hits = wp.empty(max(1, n * hit_triples), dtype=wp.vec3, device=device)
    b.hit_inst = wp.empty(n if hits else 1, dtype=wp.int32, device=device)
    b.hit_tri = wp.empty(n if hits else 1, dtype=wp.int32, device=device)
    b.hit_uv = wp.empty(n if hits else 1, dtype=wp.vec2, device=device)
    b.hit_p = wp.empty(n if hits else 1, dtype=wp.vec3, device=device)
    b.film = wp.empty(n, dtype=wp.vec2, device=device)
    b.rgba = wp.empty(n, dtype=wp.vec4, device=device)
    b.depth = wp.empty(n, dtype=wp.float32, device=device)
    b.normal = wp.empty(n, dtype=wp.vec3, device=device)
    b.albedo = wp.empty(n, dtype=wp.vec3, device=device)
    b.wx = wp.empty(n, dtype=wp.vec3, device=device)
    b.wy = wp.empty(n, dtype=wp.vec3, device=device)
    return b


AOV_SUMS = ("depth", "normal", "albedo")  # what the gather's depth, hit-weight, normal and albedo sums serve


def needs_aov_sums(aovs, denoise: bool) -> bool:
    """Whether a render must gather the depth, normal and albedo sums: an AOV of them, or the denoiser (which
    takes albedo and normal). Without, the gather adds colour and weight only (a cornell render's gather 2.7 ->
    2.3 % of its time)."""
    return denoise or any(a in AOV_SUMS for a in aovs)


def new_tile_accum(n: int, device: str, aovs: bool = True, extra: int = 0, hit_triples: int = 0) -> TileAccum:
    """n partial sums of each channel, and of ``extra`` further RGB triples, zeroed; without ``aovs`` the depth, normal
    and albedo sums (which the gather then leaves alone) are one each."""
    m = n if aovs else 1
    a = TileAccum()
    a.extra = wp.zeros(max(1, n * extra), dtype=wp.vec3, device=device)
    a.hits = wp.zeros(max(1, n * hit_triples), dtype=wp.vec3, device=device)
    a.rgba = wp.zeros(n, dtype=wp.vec4, device=device)
    a.weight = wp.zeros(n, dtype=wp.float32, device=device)
    a.depth = wp.zeros(m, dtype=wp.float32, device=device)
    a.hit_weight = wp.zeros(m, dtype=wp.float32, device=device)
    a.normal = wp.zeros(m, dtype=wp.vec3, device=device)
    a.albedo = wp.zeros(m, dtype=wp.vec3, device=device)
    return a


# ``filter_1d``'s Gaussian at a sample's three offsets in one piece of vector code, with exp as a polynomial (Cephes'
# expf: Cody-Waite reduction by ln 2, a degree-7 polynomial, the power of two put into the exponent bits; within
# 2 ulp of the exact value here, tested) instead of three calls of libm's expf: the six calls per sample were
# most of the weights pass (0.079 -> 0.060 s of the teapot shot's 1.7 s on one thread). Each operation is a
# statement of its own, so no compiler fuses a multiply and an add: the same bits on every CPU and build.
_GAUSSIAN_AXIS_CPP = VECTOR_TYPES_CPP + r"""
    typedef int v4i_ __attribute__((vector_size(16)));
    const v4f x = {u + 0.5f, u - 0.5f, u - 1.5f, 0.0f};  /* offsets from the centres of the pixels -1, 0, +1 */
    const v4f ax = __builtin_elementwise_abs(x);
    const v4f ax2 = ax * ax;
    const v4f e = ax2 * splat(-a);  /* in [-2.25 a, 0] */
    const v4f scaled = e * splat(1.44269504088896341f);
    const v4f n = __builtin_elementwise_floor(scaled + splat(0.5f));
    const v4f hi = n * splat(0.693359375f);
    const v4f lo = n * splat(-2.12194440e-4f);
    v4f r = e - hi;
    r = r - lo;
    v4f p = splat(1.9875691500e-4f);
    v4f m;
    m = p * r; p = m + splat(1.3981999507e-3f);
    m = p * r; p = m + splat(8.3334519073e-3f);
    m = p * r; p = m + splat(4.1665795894e-2f);
    m = p * r; p = m + splat(1.6666665459e-1f);
    m = p * r; p = m + splat(5.0000001201e-1f);
    const v4f r2 = r * r;
    m = p * r2;
    v4f y = m + r;
    y = y + splat(1.0f);
    const v4i_ bits = (__builtin_convertvector(n, v4i_) + 127) << 23;  /* 2^n, n in [-7, 0] */
    y = y * (v4f)bits;
    const v4f w = y - splat(edge);
    const v4f out = ax >= splat(radius) ? splat(0.0f) : w;
    return wp::vec_t<3, wp::float32>(out[0], out[1], out[2]);
"""


@wp.func_native(_GAUSSIAN_AXIS_CPP)
def gaussian_axis(u: float, a: float, radius: float, edge: float) -> wp.vec3:
    """``axis_weights`` of the Gaussian filter (``a`` = 1 / (2 sigma^2)), as vector code."""
    ...


@wp.func
def axis_weights(kind: int, u: float, radius: float, edge: float):
    """Filter weights of a sample at position u in [0, 1) of its pixel, along one axis, for the pixels at
    offsets -1, 0, +1 from its own (``filter_margin`` is at most 1; ``edge`` as in ``filter_1d``). The box
    filter's pixel is half-open, so its own pixel always takes the whole sample."""
    if kind == FILTER_BOX:
        return wp.vec3(0.0, 1.0, 0.0)
    if kind == FILTER_GAUSSIAN:
        return gaussian_axis(u, 1.0 / (2.0 * GAUSSIAN_SIGMA * GAUSSIAN_SIGMA), radius, edge)
    # the sample's offset from the centre of the pixel at offset o is u - 0.5 - o
    return wp.vec3(filter_1d(kind, u + 0.5, radius, edge), filter_1d(kind, u - 0.5, radius, edge),
                   filter_1d(kind, u - 1.5, radius, edge))


@wp.kernel
def axis_weights_kernel(buf: SampleBuffer, filter_kind: int, radius: float):
    """Each sample's weights toward its own and neighbouring pixels along x and y (the weight toward a pixel is
    their product)."""
    i = wp.tid()
    f = buf.film[i]
    edge = float(0.0)
    if filter_kind == FILTER_GAUSSIAN:
        edge = gaussian_edge(radius)
    buf.wx[i] = axis_weights(filter_kind, f[0], radius, edge)
    buf.wy[i] = axis_weights(filter_kind, f[1], radius, edge)


# A source pixel's nine partials of colour and weight (``margin`` 1, no AOV sums: every filter but the box, most
# renders) in one piece of vector code: each sample is read once and added to nine independent sums, where the
# loop over one partial at a time waited on its own additions, one after the other. Each sum takes the same
# operations in the same order as ``gather_kernel``'s loop (products and sums as separate statements, so never
# contracted), so the bits are the same (tested, and renders are unchanged).
_GATHER_NINE_CPP = VECTOR_TYPES_CPP + r"""
    v4f sum[9];
    float wsum[9];
    int key[9];
    for (int d = 0; d < 9; ++d) {
        const int oy = d / 3 - 1, ox = d % 3 - 1;
        const int ty = sy - oy - ext_y0, tx = sx - ox - ext_x0;  /* the target: at (-ox, -oy) from the source */
        key[d] = (ty >= 0 && ty < ext_h && tx >= 0 && tx < ext_w) ? (ty * ext_w + tx) * 9 + d : -1;
        sum[d] = splat(0.0f);
        wsum[d] = 0.0f;
        if (key[d] >= 0) {
            const wp::vec_t<4, wp::float32> a = wp::index(acc_rgba, key[d]);
            sum[d] = (v4f){a.c[0], a.c[1], a.c[2], a.c[3]};
            wsum[d] = wp::index(acc_weight, key[d]);
        }
    }
    for (int j = 0; j < wave; ++j) {
        const wp::vec_t<3, wp::float32> wx = wp::index(buf_wx, base + j);
        const wp::vec_t<3, wp::float32> wy = wp::index(buf_wy, base + j);
        const wp::vec_t<4, wp::float32> c = wp::index(buf_rgba, base + j);
        const v4f cv = {c.c[0], c.c[1], c.c[2], c.c[3]};
        for (int d = 0; d < 9; ++d) {
            const int oy = d / 3 - 1, ox = d % 3 - 1;
            const float w = wx.c[1 - ox] * wy.c[1 - oy];
            if (w != 0.0f) {
                const v4f cw = cv * splat(w);
                sum[d] = sum[d] + cw;
                wsum[d] = wsum[d] + w;
            }
        }
    }
    for (int d = 0; d < 9; ++d) {
        if (key[d] >= 0) {
            wp::index(acc_rgba, key[d]) = wp::vec_t<4, wp::float32>(sum[d][0], sum[d][1], sum[d][2], sum[d][3]);
            wp::index(acc_weight, key[d]) = wsum[d];
        }
    }
"""


@wp.func_native(_GATHER_NINE_CPP)
def gather_nine(buf_wx: wp.array(dtype=wp.vec3), buf_wy: wp.array(dtype=wp.vec3), buf_rgba: wp.array(dtype=wp.vec4),
                base: int, wave: int, acc_rgba: wp.array(dtype=wp.vec4), acc_weight: wp.array(dtype=wp.float32),
                sx: int, sy: int, ext_x0: int, ext_y0: int, ext_w: int, ext_h: int):
    """``gather_kernel``'s loop for one source pixel with ``margin`` 1 and no AOV sums, as vector code."""
    ...


@wp.kernel
def gather_kernel(
    buf: SampleBuffer,
    acc: TileAccum,  # per-direction partial sums: direction d of target pixel t at t * directions + d
    wave: int,  # samples per pixel in this wave
    tile_x0: int,  # the sample pixels (full-image coordinates; one thread each, row by row)
    tile_y0: int,
    tile_w: int,
    slot_of: wp.array(dtype=wp.int32),  # a sample pixel's slot in this wave's buffer, -1: it has stopped
    ext_x0: int,  # the target pixels: the tile and its ring of ``margin`` pixels (``borders.extended_region``)
    ext_y0: int,
    ext_w: int,
    ext_h: int,
    margin: int,
    aovs: int,  # 0: the depth, normal and albedo sums stay 0 (no AOV asks for them)
    native: int,  # 0: never ``gather_nine`` (its test's reference)
):
    """Add one wave's samples of one tile pixel (the source) to the partial sums of the target pixels its filter
    reaches, one partial per direction (``borders``), each in sample order.

    A (target, direction) partial has exactly one source pixel, so the threads of this launch never write the
    same sum. Source by source, the nine sums of the common case are one piece of vector code (``gather_nine``):
    the teapot shot's gather 0.082 -> 0.031 s per 640x360 frame at 16 spp."""
    tid = wp.tid()
    slot = slot_of[tid]
    if slot < 0:
        return
    sx = tile_x0 + tid % tile_w
    sy = tile_y0 + tid // tile_w
    side = 2 * margin + 1
    base = slot * wave
    if margin == 1 and aovs == 0 and native != 0:
        gather_nine(buf.wx, buf.wy, buf.rgba, base, wave, acc.rgba, acc.weight, sx, sy, ext_x0, ext_y0, ext_w, ext_h)
        return
    for oy in range(-margin, margin + 1):
        ty = sy - oy - ext_y0  # the target lies at offset (-ox, -oy) from the sample's pixel
        for ox in range(-margin, margin + 1):
            tx = sx - ox - ext_x0
            if ty >= 0 and ty < ext_h and tx >= 0 and tx < ext_w:
                k = (ty * ext_w + tx) * side * side + (oy + margin) * side + ox + margin
                rgba = acc.rgba[k]
                wsum = acc.weight[k]
                dsum = float(0.0)
                hsum = float(0.0)
                nsum = wp.vec3(0.0)
                asum = wp.vec3(0.0)
                if aovs != 0:
                    dsum = acc.depth[k]
                    hsum = acc.hit_weight[k]
                    nsum = acc.normal[k]
                    asum = acc.albedo[k]
                for j in range(wave):
                    w = buf.wx[base + j][1 - ox] * buf.wy[base + j][1 - oy]
                    if w != 0.0:
                        c = buf.rgba[base + j]
                        rgba = rgba + c * w
                        wsum = wsum + w
                        if aovs != 0 and c[3] > 0.0:
                            hw = w * c[3]
                            dsum = dsum + buf.depth[base + j] * hw
                            hsum = hsum + hw
                            nsum = nsum + buf.normal[base + j] * hw
                            asum = asum + buf.albedo[base + j] * hw
                acc.rgba[k] = rgba
                acc.weight[k] = wsum
                if aovs != 0:
                    acc.depth[k] = dsum
                    acc.hit_weight[k] = hsum
                    acc.normal[k] = nsum
                    acc.albedo[k] = asum


# acc[k .. k + n) += w * src[at .. at + n) over RGB triples, as one loop over floats that the compiler vectorizes
# (element by element in Warp's code it was 14 % of a render with eight LPE layers); the product and the sum are
# statements of their own, so never fused: the same bits on every CPU.
_ADD_SCALED_CPP = r"""
    float* a = reinterpret_cast<float*>(acc.data) + 3 * k;
    const float* x = reinterpret_cast<const float*>(src.data) + 3 * at;
    for (int i = 0; i < 3 * n; ++i) {
        const float p = x[i] * w;
        a[i] = a[i] + p;
    }
"""


@wp.func_native(_ADD_SCALED_CPP)
def add_scaled(acc: wp.array(dtype=wp.vec3), k: int, src: wp.array(dtype=wp.vec3), at: int, n: int, w: float):
    """``gather_extra_kernel``'s inner loop: n triples of src from ``at``, times w, added to acc from ``k``."""
    ...


@wp.kernel
def gather_extra_kernel(
    buf: SampleBuffer,
    src: wp.array(dtype=wp.vec3),  # per sample, ``extra`` triples (``SampleBuffer.extra`` or ``hits``)
    dst: wp.array(dtype=wp.vec3),  # per (target, direction), ``extra`` triples (``TileAccum.extra`` or ``hits``)
    extra: int,  # RGB triples per sample
    wave: int,
    tile_x0: int,
    tile_y0: int,
    tile_w: int,
    slot_of: wp.array(dtype=wp.int32),
    ext_x0: int,
    ext_y0: int,
    ext_w: int,
    ext_h: int,
    margin: int,
):
    """``gather_kernel`` for the further channels (``SampleBuffer.extra``, ``hits``): the same weights, targets, partials
    and order, so that they are filtered exactly as the colour is. A launch of its own, made only when there are
    such channels: the colour's gather stays as it is."""
    tid = wp.tid()
    slot = slot_of[tid]
    if slot < 0:
        return
    sx = tile_x0 + tid % tile_w
    sy = tile_y0 + tid // tile_w
    side = 2 * margin + 1
    base = slot * wave
    for oy in range(-margin, margin + 1):
        ty = sy - oy - ext_y0
        for ox in range(-margin, margin + 1):
            tx = sx - ox - ext_x0
            if ty >= 0 and ty < ext_h and tx >= 0 and tx < ext_w:
                k = ((ty * ext_w + tx) * side * side + (oy + margin) * side + ox + margin) * extra
                for j in range(wave):
                    w = buf.wx[base + j][1 - ox] * buf.wy[base + j][1 - oy]
                    if w != 0.0:
                        add_scaled(dst, k, src, (base + j) * extra, extra, w)


def accum_partials(acc: TileAccum, directions: int, rows: int, columns: int,
                   aovs: bool = True, extra: int = 0, hit_triples: int = 0) -> dict[str, np.ndarray | None]:
    """The partial sums as (directions, rows, columns[, c]) arrays (``borders.split_tile``'s input); without
    ``aovs`` the depth, normal and albedo sums are None (all zero); ``extra`` further RGB triples under "extra"
    (3 x extra channels)."""
    shape = (rows, columns, directions)
    arrays = {"rgba": acc.rgba.numpy().reshape(shape + (4,)), "weight": acc.weight.numpy().reshape(shape)}
    if extra:
        arrays["extra"] = acc.extra.numpy()[:rows * columns * directions * extra].reshape(shape + (3 * extra,))
    if hit_triples:
        arrays["hits"] = acc.hits.numpy()[:rows * columns * directions * hit_triples].reshape(
            shape + (3 * hit_triples,))
    if aovs:
        arrays.update({"depth": acc.depth.numpy().reshape(shape), "hit_weight": acc.hit_weight.numpy().reshape(shape),
                       "normal": acc.normal.numpy().reshape(shape + (3,)),
                       "albedo": acc.albedo.numpy().reshape(shape + (3,))})
    out = {k: np.moveaxis(a, 2, 0) for k, a in arrays.items()}
    names = ("rgba", "weight", "depth", "hit_weight", "normal", "albedo") + (("extra",) if extra else ()) + (
        ("hits",) if hit_triples else ())
    return {k: out.get(k) for k in names}


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
    if sums.get("extra") is not None:  # filtered as the colour: divided by the same weights, exposed alike
        with np.errstate(divide="ignore", invalid="ignore"):
            out["extra"] = np.where(w[..., None] > 0, sums["extra"] / w[..., None], 0.0) * exposure_scale
    if sums.get("hits") is not None:  # the hit vars: weighted means, not light (no exposure)
        with np.errstate(divide="ignore", invalid="ignore"):
            out["hits"] = np.where(w[..., None] > 0, sums["hits"] / w[..., None], 0.0)
    return {k: np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32) for k, v in out.items()}
