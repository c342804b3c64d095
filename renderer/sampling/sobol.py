"""The sample generator: Owen-scrambled Sobol points, stateless and decorrelated across dimensions.

Every value is a pure function of ``(seed, pixel, index, dim)``; nothing is stored between calls, so a sample can be
replayed alone ("pixel (x, y) sample n failed") and tiling cannot change the image. ``pixel`` is the flattened id
``y * width + x`` of the FULL image.

Construction (Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4); pbrt-v4's ``PaddedSobolSampler``):

1. ``h = pattern_hash(seed, pixel, dim)`` — a well-mixed 32-bit hash of the request.
2. The sample index is shuffled by a nested-uniform (Owen) scramble of its bits seeded by ``h``. The first ``2^m``
   indices map onto one aligned block of ``2^m`` Sobol indices, so they stay a (0, m, 2)-net; different ``dim``
   (and pixels, seeds) get unrelated shuffles, which is what decorrelates the strata of one dimension pair from
   those of another (Cook's "decorrelated strata", without storing a permutation).
3. The 2D Sobol point at the shuffled index is taken: coordinate 0 is van der Corput (bit reversal), coordinate 1
   is Sobol's second dimension (direction numbers ``v_1 = 2^31, v_k = v_{k-1} ^ (v_{k-1} >> 1)``).
4. Each coordinate is Owen-scrambled with its own seed derived from ``h``. The scramble is a Laine-Karras style
   hash applied to the reversed bits (the improved constants of Vegdahl, as used by pbrt-v4 ``FastOwenScrambler``):
   every output bit depends only on itself and more significant bits of the fraction, which is nested-uniform
   scrambling.
5. The top 24 bits become a float32: ``(x >> 8) * 2^-24``; exact, so every result is in ``[0, 0x1.fffffep-1]``.

Known property: the index shuffle is a nested permutation, not a uniformly random one, so within one pixel the
strata of two different dimension requests are tied hierarchically (over the first 2^k indices, k >= 1, the
quadrant counts of (dim a, dim b) satisfy N00 = N11). Every cell is still equally likely and the estimator is
unbiased; correlations are about 1.2x those of independent sequences, and integration error matches that of a
random per-wave permutation (measured while writing tests/renderer/sampling/test_sampler.py).

``sample_1d(.., dim)`` equals ``sample_2d(.., dim).x``, and ``sample_2d(.., dim)`` the first two coordinates of
``sample_3d(.., dim)``: a request uses one pattern with as many coordinates as it needs (Sobol's dimensions over
one shuffled index; in 3D the first 2^m samples form a (1, m, 3)-net). The camera's request goes on to eleven:
``sample_camera_pair`` gives Sobol's dimensions 3-4, 5-6, 7-8 or 9-10 at the same index, so the lens and the first
bounce's light point (with a pinhole: the first bounce's direction and light point, the second's light point and
direction) are stratified jointly with the pixel and the time: pbrt's global ``SobolSampler`` where it pays (a
moving or defocused edge, a penumbra that moves, a glossy reflection of a lit wall), padded 2D/3D requests after
that. A k-D request at ``dim`` consumes dims ``dim`` .. ``dim + k - 1`` (its shuffle is keyed by ``dim``, the
first); callers must not also request those on their own.

Dimension allocation (the integrator follows this table; ``b`` is the bounce, 0 for the camera ray's first hit):

=================================================  ===========  ==========================================
dims                                               request      use
=================================================  ===========  ==========================================
``DIM_FILM`` = 0 .. 10                             ``11d``      position on the film inside the pixel (0, 1),
                                                                time within the shutter (2; box, or
                                                                ``sample_tent``), position on the lens (3, 4;
                                                                with a pinhole, bounce 0's BSDF direction),
                                                                bounce 0's point on each light (5, 6); with a
                                                                pinhole, bounce 1's (7, 8) and its BSDF direction
                                                                (9, 10)
``DIM_LIGHT_BASE + b * DIMS_PER_BOUNCE`` + 0..2    ``3d``       bounce ``b``'s lights: a point on each (x, y; from
                                                                the camera's request as above), the finite light
                                                                the cut chooses (z)
``DIM_LIGHT_BASE + b * DIMS_PER_BOUNCE`` + 3..5    ``3d``       the BSDF: a direction (x, y; gloss, translucency;
                                                                from the camera's request as above), the lobe (z)
``DIM_LIGHT_BASE + b * DIMS_PER_BOUNCE`` + 6       ``1d``       Russian roulette
=================================================  ===========  ==========================================

Participating media draw one request per tentative collision, at dimensions far above these (``media.tracking``):
bounce ``b``'s walk along its ray uses ``DIM_MEDIUM + b * MEDIUM_DIMS_PER_BOUNCE + 2 k`` (a 2D request: the
distance to the k-th tentative collision and whether it is real), the ratio tracking of its shadow ray towards
light pick ``j`` ``DIM_MEDIUM_SHADOW + b * MEDIUM_SHADOW_DIMS_PER_BOUNCE + j * MEDIUM_SHADOW_DIMS_PER_PICK + k``.

The per-bounce offsets are the ``BOUNCE_*`` constants. Any dims work: the hash keys on the full 32-bit ``dim``.
Measured, 64 spp against 1024-spp references: the camera's request with the lens and bounce 0's light point
lowered relMSE by 23 % on the demo (a moving ball's soft shadow, depth of field), 7 % on the dof and 6 % on the
motion bench scenes, 1 % on the still ones; giving a pinhole's lens dims to bounce 0's BSDF direction, by 7 % more
on cornell and motion; then bounce 1's light point and direction, by 4-6 % more on cornell and motion and 2 % on
gloss, for 0.5-3 % more time (with a lens, whose dims keep bounce 0's direction out, they gained nothing: used with
a pinhole only). Bounce 2 as well (dimensions 11-14) gained 0-1.4 %: not used. Sobol's dimensions 7-8 for
bounce 0's BSDF direction next to its light point in 5-6 raised relMSE by 7-15 %: not used.

Warp side: ``sample_1d``, ``sample_2d``, ``sample_3d``, ``sample_camera_pair`` (``@wp.func``, arguments
``wp.uint32``). NumPy side: ``np_sample_1d``, ``np_sample_2d``, ``np_sample_3d``, ``np_sample_11d``
(vectorised, broadcasting, bit-identical float32 results; tests compare them).
"""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.kernels.vector_code import VECTOR_TYPES_CPP

DIM_FILM = 0  # the camera's 11D request
DIM_LIGHT_BASE = 11  # first dimension of bounce 0
# the camera request's pairs after film and time (``sample_camera_pair``): Sobol's dimensions 3-4, 5-6, 7-8, 9-10
CAMERA_LENS = wp.constant(0)  # the lens; with a pinhole, bounce 0's BSDF direction
CAMERA_LIGHT_0 = wp.constant(1)  # bounce 0's point on each light
CAMERA_LIGHT_1 = wp.constant(2)  # bounce 1's point on each light
CAMERA_BSDF_1 = wp.constant(3)  # bounce 1's BSDF direction
DIMS_PER_BOUNCE = 7
BOUNCE_LIGHT_CHOICE = 0  # a 3D request: the point on the light and the choice of light together
BOUNCE_LOBE = 3  # a 3D request: the BSDF direction and the choice of lobe together
BOUNCE_ROULETTE = 6
DIM_MEDIUM = 1 << 24  # walks through media (``media.tracking``): tentative collisions, 2 dims each
MEDIUM_DIMS_PER_BOUNCE = 1 << 17
DIM_MEDIUM_SHADOW = 1 << 28  # ratio tracking of shadow rays, 1 dim per tentative collision
MEDIUM_SHADOW_DIMS_PER_BOUNCE = 1 << 20
MEDIUM_SHADOW_DIMS_PER_PICK = 1 << 16

# Largest float32 below 1 (0x1.fffffep-1); every sample is <= this.
ONE_MINUS_EPSILON = float(np.float32(1.0) - np.float32(2.0**-24))

# 32-bit constants: wrapped in wp.uint32 so the generated C++ uses unsigned literals.
_M1, _M2 = 0x7FEB352D, 0x846CA68B  # lowbias32 (C. Wellons) finaliser
_GOLDEN = 0x9E3779B9
_O1, _O2, _O3 = 0x3D20ADEA, 0x05526C56, 0x53A22864  # Owen scrambler (Vegdahl / pbrt-v4)

W_M1 = wp.constant(wp.uint32(_M1))
W_M2 = wp.constant(wp.uint32(_M2))
W_GOLDEN = wp.constant(wp.uint32(_GOLDEN))
W_O1 = wp.constant(wp.uint32(_O1))
W_O2 = wp.constant(wp.uint32(_O2))
W_O3 = wp.constant(wp.uint32(_O3))
W_MASK1 = wp.constant(wp.uint32(0x55555555))
W_MASK2 = wp.constant(wp.uint32(0x33333333))
W_MASK4 = wp.constant(wp.uint32(0x0F0F0F0F))
W_MASK8 = wp.constant(wp.uint32(0x00FF00FF))
W_TO_UNIT = wp.constant(2.0**-24)


# ----------------------------------------------------------------------------------------------------------------
# Warp
# ----------------------------------------------------------------------------------------------------------------

_ByteTable = wp.types.vector(length=1024, dtype=wp.uint32)


def _byte_table(directions: list[int]) -> _ByteTable:
    """[k * 256 + b]: XOR of the direction numbers of the set bits of byte value b in byte k of the index."""
    t = []
    for k in range(4):
        for b in range(256):
            r = 0
            for j in range(8):
                if (b >> j) & 1:
                    r ^= directions[8 * k + j]
            t.append(r)
    return _ByteTable(*[wp.uint32(x) for x in t])


def _joe_kuo(s: int, a: int, m: list[int]) -> list[int]:
    """32-bit direction numbers of a Sobol dimension: primitive polynomial of degree ``s`` with inner coefficients
    ``a``, initial numbers ``m`` (a row of Joe & Kuo's table, new-joe-kuo-6.21201)."""
    v = [m[k] << (31 - k) for k in range(s)]
    while len(v) < 32:
        k = len(v)
        x = v[k - s] ^ (v[k - s] >> s)
        for j in range(1, s):
            if (a >> (s - 1 - j)) & 1:
                x ^= v[k - j]
        v.append(x)
    return v


# Sobol's dimensions 1..10 (dimension 0 is the bit reversal of the index): (s, a, m) rows of Joe & Kuo's table.
JOE_KUO = ((1, 0, [1]), (2, 1, [1, 3]), (3, 1, [1, 3, 1]), (3, 2, [1, 1, 1]), (4, 1, [1, 1, 3, 3]),
           (4, 4, [1, 3, 5, 13]), (5, 2, [1, 1, 5, 5, 17]), (5, 4, [1, 1, 5, 5, 5]), (5, 7, [1, 1, 7, 11, 19]),
           (5, 11, [1, 1, 5, 1, 1]))
SOBOL_DIRECTIONS = [_joe_kuo(*row) for row in JOE_KUO]  # [d - 1]: dimension d's 32 direction numbers

W_SOBOL1_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[0]))
W_SOBOL2_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[1]))
W_SOBOL3_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[2]))
W_SOBOL4_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[3]))
W_SOBOL5_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[4]))
W_SOBOL6_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[5]))
W_SOBOL7_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[6]))
W_SOBOL8_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[7]))
W_SOBOL9_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[8]))
W_SOBOL10_TABLE = wp.constant(_byte_table(SOBOL_DIRECTIONS[9]))


@wp.func
def reverse_bits32(v: wp.uint32) -> wp.uint32:
    """Reverse the 32 bits of ``v`` (Warp has no builtin)."""
    v = ((v >> wp.uint32(1)) & W_MASK1) | ((v & W_MASK1) << wp.uint32(1))
    v = ((v >> wp.uint32(2)) & W_MASK2) | ((v & W_MASK2) << wp.uint32(2))
    v = ((v >> wp.uint32(4)) & W_MASK4) | ((v & W_MASK4) << wp.uint32(4))
    v = ((v >> wp.uint32(8)) & W_MASK8) | ((v & W_MASK8) << wp.uint32(8))
    return (v >> wp.uint32(16)) | (v << wp.uint32(16))


@wp.func
def mix32(x: wp.uint32) -> wp.uint32:
    """A bijective 32-bit integer hash with good avalanche (lowbias32)."""
    x = x ^ (x >> wp.uint32(16))
    x = x * W_M1
    x = x ^ (x >> wp.uint32(15))
    x = x * W_M2
    return x ^ (x >> wp.uint32(16))


@wp.func
def hash_combine(seed: wp.uint32, v: wp.uint32) -> wp.uint32:
    """Boost-style combine, as in Burley 2020."""
    return seed ^ (v + W_GOLDEN + (seed << wp.uint32(6)) + (seed >> wp.uint32(2)))


@wp.func
def pattern_hash(seed: wp.uint32, pixel: wp.uint32, dim: wp.uint32) -> wp.uint32:
    """The per-(seed, pixel, dim) key from which the index shuffle and the coordinate scrambles derive."""
    return mix32(hash_combine(hash_combine(mix32(seed), mix32(pixel)), mix32(dim)))


@wp.func
def owen_scramble(v: wp.uint32, seed: wp.uint32) -> wp.uint32:
    """Nested-uniform scramble of the bits of ``v`` read as a binary fraction (MSB first)."""
    v = reverse_bits32(v)
    v = v ^ (v * W_O1)
    v = v + seed
    v = v * ((seed >> wp.uint32(16)) | wp.uint32(1))
    v = v ^ (v * W_O2)
    v = v ^ (v * W_O3)
    return reverse_bits32(v)


@wp.func
def _byte_product(tab: _ByteTable, index: wp.uint32) -> wp.uint32:
    """The GF(2) product of a Sobol generator matrix with the index's bits, one table row per byte of the index
    (``_byte_table``): four look-ups instead of a 32-round loop (the scrambled index has random high bits)."""
    return (tab[int(index & wp.uint32(255))] ^ tab[256 + int((index >> wp.uint32(8)) & wp.uint32(255))]
            ^ tab[512 + int((index >> wp.uint32(16)) & wp.uint32(255))] ^ tab[768 + int(index >> wp.uint32(24))])


@wp.func
def sobol_dim1(index: wp.uint32) -> wp.uint32:
    """Sobol's second dimension (32-bit fraction); dimension 0 is ``reverse_bits32(index)``."""
    return _byte_product(W_SOBOL1_TABLE, index)


@wp.func
def sobol_dims12(index: wp.uint32):
    """Sobol's second and third dimensions (32-bit fractions). The third: primitive polynomial x^2 + x + 1,
    m = (1, 3) (Joe & Kuo's direction numbers; ``np_sobol``)."""
    return _byte_product(W_SOBOL1_TABLE, index), _byte_product(W_SOBOL2_TABLE, index)


@wp.func
def u32_to_unit_float(x: wp.uint32) -> float:
    """Top 24 bits as a float32 in [0, 1 - 2^-24], exact."""
    return wp.float32(x >> wp.uint32(8)) * W_TO_UNIT


_OWEN3_CPP = VECTOR_TYPES_CPP + r"""
    typedef unsigned v4u __attribute__((vector_size(16)));
    auto rev = [](v4u v) {  /* reverse_bits32 */
        v = ((v >> 1) & 0x55555555u) | ((v & 0x55555555u) << 1);
        v = ((v >> 2) & 0x33333333u) | ((v & 0x33333333u) << 2);
        v = ((v >> 4) & 0x0F0F0F0Fu) | ((v & 0x0F0F0F0Fu) << 4);
        v = ((v >> 8) & 0x00FF00FFu) | ((v & 0x00FF00FFu) << 8);
        return (v >> 16) | (v << 16);
    };
    v4u m = (v4u){h, h, h, h} + (v4u){k, k + 1u, k + 2u, 0u};  /* mix32(h + k + j) */
    m ^= m >> 16; m *= %(M1)du; m ^= m >> 15; m *= %(M2)du; m ^= m >> 16;
    v4u v = rev((v4u){v0, v1, v2, 0u});
    if (first_reversed) v[0] = v0;  /* reverse_bits32 of reverse_bits32(v0) */
    v ^= v * %(O1)du;  /* owen_scramble */
    v += m;
    v *= (m >> 16) | 1u;
    v ^= v * %(O2)du;
    v ^= v * %(O3)du;
    v = rev(v);
    const v4f f = __builtin_convertvector((v4i)(v >> 8), v4f) * splat(0x1p-24f);  /* u32_to_unit_float */
    return wp::vec3(f[0], f[1], f[2]);
""" % {"M1": _M1, "M2": _M2, "O1": _O1, "O2": _O2, "O3": _O3}


@wp.func_native(_OWEN3_CPP)
def owen_scramble3(v0: wp.uint32, v1: wp.uint32, v2: wp.uint32, h: wp.uint32, k: wp.uint32,
                   first_reversed: int) -> wp.vec3:
    """``u32_to_unit_float(owen_scramble(v_j, mix32(h + k + j)))`` for j = 0, 1, 2, the three lanes at once in
    vector code, the same bits as ``owen_scramble3_reference``. ``first_reversed`` 1: the first lane scrambles
    ``reverse_bits32(v0)`` instead (a sample's first coordinate is the van der Corput value of the shuffled index;
    the scramble's first step reverses the bits back, so that lane skips both reversals). The samplers took 6-12 %
    of the path tracing kernel (``bench/kernel_profile.py``), most of it in these scrambles, one coordinate at a
    time."""
    ...


@wp.func
def owen_scramble3_reference(v0: wp.uint32, v1: wp.uint32, v2: wp.uint32, h: wp.uint32, k: wp.uint32,
                             first_reversed: int) -> wp.vec3:
    """``owen_scramble3`` in Warp's scalar code."""
    x0 = v0
    if first_reversed != 0:
        x0 = reverse_bits32(v0)
    return wp.vec3(u32_to_unit_float(owen_scramble(x0, mix32(h + k))),
                   u32_to_unit_float(owen_scramble(v1, mix32(h + k + wp.uint32(1)))),
                   u32_to_unit_float(owen_scramble(v2, mix32(h + k + wp.uint32(2)))))


@wp.func
def sample_1d(seed: wp.uint32, pixel: wp.uint32, index: wp.uint32, dim: wp.uint32) -> float:
    """One value in [0, 1) for dimension ``dim``; equals ``sample_2d(seed, pixel, index, dim)[0]``."""
    h = pattern_hash(seed, pixel, dim)
    i = owen_scramble(index, h)
    x = owen_scramble(reverse_bits32(i), mix32(h + wp.uint32(1)))
    return u32_to_unit_float(x)


@wp.func
def sample_2d(seed: wp.uint32, pixel: wp.uint32, index: wp.uint32, dim: wp.uint32) -> wp.vec2:
    """A point in [0, 1)^2 for dimensions (``dim``, ``dim + 1``): stratified as a (0, 2)-sequence over ``index``."""
    h = pattern_hash(seed, pixel, dim)
    i = owen_scramble(index, h)
    u = owen_scramble3(i, sobol_dim1(i), wp.uint32(0), h, wp.uint32(1), 1)
    return wp.vec2(u[0], u[1])


@wp.func
def sample_3d(seed: wp.uint32, pixel: wp.uint32, index: wp.uint32, dim: wp.uint32) -> wp.vec3:
    """A point in [0, 1)^3 for dimensions ``dim`` .. ``dim + 2``, stratified jointly (Sobol's first three dimensions
    over one shuffled index): its first two coordinates are ``sample_2d(.., dim)``. For a discrete choice and a
    2D point that depend on each other (a light and a point on it): the samples that make one choice keep
    well-spread 2D points, which two independent requests would not."""
    h = pattern_hash(seed, pixel, dim)
    i = owen_scramble(index, h)
    d1, d2 = sobol_dims12(i)
    return owen_scramble3(i, d1, d2, h, wp.uint32(1), 1)


@wp.func
def sample_camera_pair(seed: wp.uint32, pixel: wp.uint32, index: wp.uint32, dim: wp.uint32, pair: int) -> wp.vec2:
    """Coordinates ``3 + 2 pair`` and ``4 + 2 pair`` (``pair`` 0-3) of the 11D request at ``dim``
    (``np_sample_11d``), whose first three are ``sample_3d(.., dim)``: Sobol's dimensions 3-10 at the same shuffled
    index, so stratified jointly with the film position and the time."""
    h = pattern_hash(seed, pixel, dim)
    i = owen_scramble(index, h)
    a = wp.uint32(0)
    b = wp.uint32(0)
    if pair == CAMERA_LENS:
        a, b = _byte_product(W_SOBOL3_TABLE, i), _byte_product(W_SOBOL4_TABLE, i)
    elif pair == CAMERA_LIGHT_0:
        a, b = _byte_product(W_SOBOL5_TABLE, i), _byte_product(W_SOBOL6_TABLE, i)
    elif pair == CAMERA_LIGHT_1:
        a, b = _byte_product(W_SOBOL7_TABLE, i), _byte_product(W_SOBOL8_TABLE, i)
    else:
        a, b = _byte_product(W_SOBOL9_TABLE, i), _byte_product(W_SOBOL10_TABLE, i)
    u = owen_scramble3(a, b, wp.uint32(0), h, wp.uint32(4 + 2 * pair), 0)
    return wp.vec2(u[0], u[1])


# ----------------------------------------------------------------------------------------------------------------
# NumPy twins (vectorised over broadcast arguments; uint32 arithmetic wraps exactly as in Warp)
# ----------------------------------------------------------------------------------------------------------------

_U = np.uint32


def _u32(x) -> np.ndarray:
    a = np.asarray(x)
    if a.dtype.kind == "f":
        raise TypeError("sampler arguments are integers")
    return a.astype(np.uint64).astype(np.uint32) if a.dtype != np.uint32 else a


def np_reverse_bits32(v: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        v = _u32(v)
        v = ((v >> _U(1)) & _U(0x55555555)) | ((v & _U(0x55555555)) << _U(1))
        v = ((v >> _U(2)) & _U(0x33333333)) | ((v & _U(0x33333333)) << _U(2))
        v = ((v >> _U(4)) & _U(0x0F0F0F0F)) | ((v & _U(0x0F0F0F0F)) << _U(4))
        v = ((v >> _U(8)) & _U(0x00FF00FF)) | ((v & _U(0x00FF00FF)) << _U(8))
        return (v >> _U(16)) | (v << _U(16))


def np_mix32(x: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        x = _u32(x)
        x = x ^ (x >> _U(16))
        x = x * _U(_M1)
        x = x ^ (x >> _U(15))
        x = x * _U(_M2)
        return x ^ (x >> _U(16))


def np_hash_combine(seed: np.ndarray, v: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        seed, v = _u32(seed), _u32(v)
        return seed ^ (v + _U(_GOLDEN) + (seed << _U(6)) + (seed >> _U(2)))


def np_pattern_hash(seed, pixel, dim) -> np.ndarray:
    """NumPy twin of ``pattern_hash``. (Every ``np_`` helper wraps uint32 silently, as Warp does.)"""
    return np_mix32(np_hash_combine(np_hash_combine(np_mix32(seed), np_mix32(pixel)), np_mix32(dim)))


def np_owen_scramble(v, seed) -> np.ndarray:
    with np.errstate(over="ignore"):
        v, seed = _u32(v), _u32(seed)
        v = np_reverse_bits32(v)
        v = v ^ (v * _U(_O1))
        v = v + seed
        v = v * ((seed >> _U(16)) | _U(1))
        v = v ^ (v * _U(_O2))
        v = v ^ (v * _U(_O3))
        return np_reverse_bits32(v)


def np_sobol(index, d: int) -> np.ndarray:
    """Sobol's dimension ``d`` (1-10) as 32-bit fractions, bit by bit from ``SOBOL_DIRECTIONS``."""
    i = _u32(index)
    r = np.zeros_like(i)
    for b, v in enumerate(SOBOL_DIRECTIONS[d - 1]):
        r = r ^ np.where(((i >> _U(b)) & _U(1)) != 0, _U(v), _U(0)).astype(np.uint32)
    return r


def np_u32_to_unit_float(x) -> np.ndarray:
    return (_u32(x) >> _U(8)).astype(np.float32) * np.float32(2.0**-24)


def _np_sample(seed, pixel, index, dim, n: int) -> np.ndarray:
    """The first ``n`` (1-11) coordinates of the pattern at ``dim``: float32, the broadcast shape + (n,)."""
    with np.errstate(over="ignore"):
        seed, pixel, index, dim = np.broadcast_arrays(_u32(seed), _u32(pixel), _u32(index), _u32(dim))
        h = np_pattern_hash(seed, pixel, dim)
        i = np_owen_scramble(index, h)
        gen = (np_reverse_bits32, *(lambda x, d=d: np_sobol(x, d) for d in range(1, 11)))[:n]
        return np.stack([np_u32_to_unit_float(np_owen_scramble(g(i), np_mix32(h + _U(k + 1))))
                         for k, g in enumerate(gen)], axis=-1)


def np_sample_1d(seed, pixel, index, dim) -> np.ndarray:
    """NumPy twin of ``sample_1d``: float32 array of the broadcast shape, bit-identical to Warp."""
    return _np_sample(seed, pixel, index, dim, 1)[..., 0]


def np_sample_2d(seed, pixel, index, dim) -> np.ndarray:
    """NumPy twin of ``sample_2d``: float32 array of the broadcast shape + (2,), bit-identical to Warp."""
    return _np_sample(seed, pixel, index, dim, 2)


def np_sample_3d(seed, pixel, index, dim) -> np.ndarray:
    """NumPy twin of ``sample_3d``: float32 array of the broadcast shape + (3,), bit-identical to Warp."""
    return _np_sample(seed, pixel, index, dim, 3)


def np_sample_11d(seed, pixel, index, dim) -> np.ndarray:
    """The 11D request at ``dim``: ``sample_3d`` and ``sample_camera_pair`` 0-3 side by side, bit-identical."""
    return _np_sample(seed, pixel, index, dim, 11)
