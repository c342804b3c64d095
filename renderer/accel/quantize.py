"""Bottom-level nodes in one cache line: the four children's boxes stored in 8 bits per coordinate.

A ray walking a large mesh waits on memory more than it computes: on the 1M-triangle heavy scene the loads of
node boxes, child references and leaf triangles were the three hottest lines of the render. A float four-wide
node (``wide``) is 96 bytes of boxes per time key plus 16 bytes of child references in a second array: three
cache lines per visit. ``QNode`` is 64 bytes, one line (in an array Warp allocates, 64-byte aligned), with the
child references inside: the nodes take 11.0 instead of 19.3 bytes per heavy triangle. The walk is no faster for
it (callgrind on heavy: 24 % fewer last-level misses, 3.2 % more instructions for the decode); the gain is memory.

Encoding of node w at key k (record w * K + k; each record repeats the child references, so a walk reads one
record per key it blends)::

    origin  (x, y, z)   the corner of the union of the used children's boxes, rounded down to a multiple of scale
    scale   (x, y, z)   per axis a power of two 2^e: the smallest with 254 * 2^e >= the union's extent, and large
                        enough that |origin| / 2^e <= 2^24 - 256
    lx .. hz            per coordinate the four children's offsets in units of scale: child j's lower x is
                        origin.x + lx[j] * scale.x (rounded down), its upper x origin.x + hx[j] * scale.x (up)
    child               ``wide``'s child references (0: an unused slot, whose bytes are 0)

Every decoded coordinate (m + q) * 2^e has |m + q| < 2^24, so it is exactly a float32 and the decode is exact
however the compiler contracts it; each decoded box therefore contains the float box it encodes, and a walk
misses nothing. A decoded box is larger by less than one step (1/254 of the node's extent) per side, so a walk
enters a few more nodes: the triangle tests, and with them the hits, are unchanged.

Coordinates beyond +-2^126 (~8.5e37) are clamped there, and a NaN box becomes the whole node's (never looser than
the float test, which would miss it): finite scenes never meet either (``renderer.usd.geometry.mesh`` rejects non-finite
points).
"""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.accel.wide import SLAB_TEST_CPP, WideBvh, box_entries

wp.set_module_options({"enable_backward": False})

STEPS = 254  # the node's extent spans at most 254 steps, so origin (rounded down by < 1 step) + 255 steps covers it
LIMIT = 2.0 ** 24 - 256.0  # |origin| <= LIMIT steps, so every origin + q steps (q <= 255) is an integer < 2^24 steps
CLAMP = 2.0 ** 126
E_MIN = -120  # smallest exponent (2^-120 is a normal float32; q * 2^-120 too)


@wp.struct
class QNode:
    """One node (at one time key) of a bottom-level four-wide tree; see the module docstring."""

    origin: wp.vec3
    scale: wp.vec3
    lx: wp.vec4ub
    ly: wp.vec4ub
    lz: wp.vec4ub
    hx: wp.vec4ub
    hy: wp.vec4ub
    hz: wp.vec4ub
    child: wp.vec4i


QNODE_DTYPE = np.dtype(QNode.numpy_dtype())
assert QNODE_DTYPE.itemsize == 64


@wp.func
def _pow2(e: int):
    """2^e as a float64, built from its bits (exact; no libm call)."""
    return wp.cast(wp.int64(e + 1023) << wp.int64(52), wp.float64)


@wp.func
def _ilogb(x: wp.float64):
    """floor(log2 x) of a normal x > 0, from its exponent bits."""
    return int((wp.cast(x, wp.int64) >> wp.int64(52)) & wp.int64(2047)) - 1023


@wp.func
def _exponent(extent: wp.float64, magnitude: wp.float64):
    """The smallest e >= E_MIN with STEPS * 2^e >= extent and magnitude <= LIMIT * 2^e."""
    e = int(E_MIN)
    if extent > wp.float64(0.0):
        e = wp.max(e, _ilogb(extent / wp.float64(STEPS)))
    if magnitude > wp.float64(0.0):
        e = wp.max(e, _ilogb(magnitude / wp.float64(LIMIT)))
    # each floor(log2) is the exponent needed or one less
    if wp.float64(STEPS) * _pow2(e) < extent or magnitude > wp.float64(LIMIT) * _pow2(e):
        e += 1
    return e


@wp.func
def _sanitized(lo: wp.vec4, hi: wp.vec4):
    """Box coordinates clamped to +-CLAMP, a NaN replaced by the conservative side (-CLAMP low, +CLAMP high)."""
    a = lo
    b = hi
    for j in range(4):
        if not (a[j] >= -CLAMP):  # also NaN
            a[j] = -CLAMP
        if a[j] > CLAMP:
            a[j] = CLAMP
        if not (b[j] <= CLAMP):
            b[j] = CLAMP
        if b[j] < -CLAMP:
            b[j] = -CLAMP
    return a, b


@wp.func
def _axis_code(lo_in: wp.vec4, hi_in: wp.vec4, c: wp.vec4i):
    """(origin, scale, lower offsets, upper offsets) of one axis of a node's four children (``c``: used slots)."""
    lo, hi = _sanitized(lo_in, hi_in)
    plo = float(CLAMP)
    phi = float(-CLAMP)
    any_used = bool(False)
    for j in range(4):
        if c[j] != 0:
            any_used = True
            plo = wp.min(plo, lo[j])
            phi = wp.max(phi, hi[j])
    if not any_used:
        plo = 0.0
        phi = 0.0
    phi = wp.max(phi, plo)  # the empty mesh's root: its one leaf holds an inverted box
    plo64 = wp.float64(plo)
    e = _exponent(wp.float64(phi) - plo64, wp.float64(wp.max(wp.abs(plo), wp.abs(phi))))
    ql = wp.vec4ub()
    qh = wp.vec4ub()
    origin = wp.float64(0.0)
    step = wp.float64(1.0)
    done = bool(False)
    while not done:  # once, unless rounding in the extent asked for a larger step (then twice)
        done = True
        step = _pow2(e)
        inv = _pow2(-e)  # dividing by a power of two is multiplying by its exact inverse
        origin = wp.floor(plo64 * inv) * step
        for j in range(4):
            if c[j] != 0:
                a = wp.float64(lo[j])
                b = wp.float64(hi[j])
                # offsets rounded outwards, then checked exactly: a decoded (m + q) * step is exact in float64
                ia = int(wp.floor((a - origin) * inv))
                if origin + wp.float64(ia) * step > a:
                    ia -= 1
                ib = int(wp.ceil((b - origin) * inv))
                if origin + wp.float64(ib) * step < b:
                    ib += 1
                if ia < 0 or ib > 255:
                    done = False
                ql[j] = wp.uint8(wp.clamp(ia, 0, 255))
                qh[j] = wp.uint8(wp.clamp(ib, 0, 255))
        e += 1
    return wp.float32(origin), wp.float32(step), ql, qh


@wp.kernel
def quantize_kernel(num_keys: int, box: wp.array(dtype=wp.vec4), child: wp.array(dtype=wp.vec4i),
                    out: wp.array(dtype=QNode)):
    """Record r = node * K + key of a four-wide tree (``wide`` layout in ``box`` and ``child``)."""
    r = wp.tid()
    c = child[r / num_keys]
    b = r * 6
    ox, sx, lx, hx = _axis_code(box[b + 0], box[b + 3], c)
    oy, sy, ly, hy = _axis_code(box[b + 1], box[b + 4], c)
    oz, sz, lz, hz = _axis_code(box[b + 2], box[b + 5], c)
    n = QNode()
    n.origin = wp.vec3(ox, oy, oz)
    n.scale = wp.vec3(sx, sy, sz)
    n.lx = lx
    n.ly = ly
    n.lz = lz
    n.hx = hx
    n.hy = hy
    n.hz = hz
    n.child = c
    out[r] = n


def quantize(wide: WideBvh, device: str = "cpu") -> np.ndarray:
    """The ``QNode`` records (W * K,) of a four-wide tree, as a structured NumPy array."""
    n = wide.num_nodes * wide.num_keys
    with wp.ScopedDevice(device):
        out = wp.empty(n, dtype=QNode)
        wp.launch(quantize_kernel, dim=n, inputs=[wide.num_keys, wp.array(wide.box, dtype=wp.vec4),
                                                  wp.array(wide.child, dtype=wp.vec4i), out])
        return out.numpy()


def decode(nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The boxes the records encode, as a walk decodes them: (lo, hi), each (R, 3, 4) float32 (NumPy twin of
    ``q_boxes``)."""
    o = nodes["origin"].astype(np.float32)[:, :, None]
    s = nodes["scale"].astype(np.float32)[:, :, None]
    lo = np.stack([nodes["lx"], nodes["ly"], nodes["lz"]], 1).astype(np.float32) * s + o
    hi = np.stack([nodes["hx"], nodes["hy"], nodes["hz"]], 1).astype(np.float32) * s + o
    return lo, hi


@wp.func
def _axis(q: wp.vec4ub, origin: float, scale: float):
    return wp.vec4(wp.float32(q[0]), wp.float32(q[1]), wp.float32(q[2]), wp.float32(q[3])) * scale + wp.vec4(origin)


@wp.func
def q_boxes(n: QNode):
    """The four children's boxes of a record as (lo x, lo y, lo z, hi x, hi y, hi z), one lane per child."""
    o = n.origin
    s = n.scale
    return (_axis(n.lx, o[0], s[0]), _axis(n.ly, o[1], s[1]), _axis(n.lz, o[2], s[2]),
            _axis(n.hx, o[0], s[0]), _axis(n.hy, o[1], s[1]), _axis(n.hz, o[2], s[2]))


# ``q_boxes`` and ``box_entries`` of a record in one piece of vector code (``wide.SLAB_TEST_CPP``): the bytes widened
# and scaled four lanes at a time, straight into the slab test, instead of 24 scalar conversions packed into
# vectors. The decode is exact (module docstring), so these are the bits of the Warp functions (tested).
_Q_BOX_ENTRIES_CPP = SLAB_TEST_CPP + r"""
    typedef unsigned char v4b __attribute__((vector_size(4)));
    auto axis = [&](wp::vec_t<4, wp::uint8> q, float origin, float scale) {
        const v4f steps = __builtin_convertvector((v4b){q.c[0], q.c[1], q.c[2], q.c[3]}, v4f);
        const v4f scaled = steps * splat(scale);
        return scaled + splat(origin);
    };
    const wp::vec_t<3, wp::float32> o = n.origin;
    const wp::vec_t<3, wp::float32> s = n.scale;
    return slab_test(axis(n.lx, o.c[0], s.c[0]), axis(n.ly, o.c[1], s.c[1]), axis(n.lz, o.c[2], s.c[2]),
                     axis(n.hx, o.c[0], s.c[0]), axis(n.hy, o.c[1], s.c[1]), axis(n.hz, o.c[2], s.c[2]),
                     (v4i){n.child.c[0], n.child.c[1], n.child.c[2], n.child.c[3]});
"""


@wp.func_native(_Q_BOX_ENTRIES_CPP)
def q_box_entries(n: QNode, ro: wp.vec3, inv_d: wp.vec3, tmax: float) -> wp.vec4:
    """``box_entries`` of the boxes ``q_boxes`` decodes from record n (native vector code, the same bits)."""
    ...


@wp.func
def q_entries(nodes: wp.array(dtype=QNode), rec: int, k0: int, k1: int, u: float, ro: wp.vec3, inv_d: wp.vec3,
              tmax: float):
    """``wide.entries`` of the node whose key-0 record is ``rec``, blended between keys k0 and k1: (entry distances,
    BIG where missed or unused; the child references)."""
    n = nodes[rec + k0]
    if k1 == k0:
        return q_box_entries(n, ro, inv_d, tmax), n.child
    lx, ly, lz, hx, hy, hz = q_boxes(n)
    lx1, ly1, lz1, hx1, hy1, hz1 = q_boxes(nodes[rec + k1])
    lx = wp.lerp(lx, lx1, u)
    ly = wp.lerp(ly, ly1, u)
    lz = wp.lerp(lz, lz1, u)
    hx = wp.lerp(hx, hx1, u)
    hy = wp.lerp(hy, hy1, u)
    hz = wp.lerp(hz, hz1, u)
    c = n.child
    return box_entries(lx, ly, lz, hx, hy, hz, c, ro, inv_d, tmax), c
