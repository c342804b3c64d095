"""Four-wide hierarchies (both levels): the binary SAH tree of ``build`` collapsed to nodes of up to four children.

A walk of a binary tree pops a node, loads two child boxes and pushes what it hit; a four-wide tree halves the
levels, the pops and the pushes, and its node keeps the four children's boxes side by side (one ``vec4`` per
box coordinate), so the four slab tests are straight-line vector arithmetic.

Layout (``WideBvh``; node 0 is the root; K time keys as in ``build``)::

    box:   (W * K * 6,) vec4   node w, key k at (w * K + k) * 6 + c, c = lo x, lo y, lo z, hi x, hi y, hi z:
                               component j of each is child j's box at that key (an unused slot's is a point
                               far away; ``entries`` skips it by its child reference).
    child: (W,) vec4i          child j: an inner node's index (> 0), a leaf ``leaf_ref(first, count)`` (< 0), or
                               0 for an unused slot (the root is nobody's child)
    prim_order                 as in ``build``: a leaf's primitives are prim_order[first : first + count]

The top level is walked in this form; the bottom level is uploaded as ``quantize``'s 64-byte records of the same
nodes (boxes in 8 bits per coordinate, child references inside).

Collapse (top-down, one thread): a wide node starts from a binary node's two children and repeatedly opens the
inner child of largest key-averaged surface area (the child a ray is most likely to enter) until it has four
children or only leaves; with ``merge_leaf``, a subtree of that many primitives or fewer counts as one leaf.
Boxes stay the binary tree's per-key boxes, so they are as tight at every time.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from renderer.accel.build import Bvh
from renderer.kernels.struct_refs import scratch
from renderer.kernels.vector_code import VECTOR_TYPES_CPP

wp.set_module_options({"enable_backward": False})

EMPTY = wp.constant(3.0e38)  # the coordinate of an unused child slot's point box
LEAF_BITS = wp.constant(4)  # a leaf reference packs its count in the low bits: at most 15 primitives per leaf
MAX_FIRST = (1 << (31 - LEAF_BITS)) - 1
# A walk pops one node and pushes at most four children: with a wide depth of at most the binary depth
# (build.MAX_DEPTH = 48), 3 * 48 + 4 entries never overflow. Each walk pushes inline (four lines): a @wp.func
# would receive the stack by value, a copy of 640 bytes per node visited.
STACK_SIZE = 160
wide_stack_t = scratch(wp.types.vector(length=STACK_SIZE, dtype=wp.int32))  # read below the top only
dist_stack_t = scratch(wp.types.vector(length=STACK_SIZE, dtype=wp.float32))
BIG = 3.4e38
# A slab test compares its entry with its exit grown by 2 ulp, so that a flat box (lo == hi on an axis) and a ray
# grazing a face are still entered despite the rounding of (bound - origin) * inv_d (Ize 2013)
SLAB_SLACK = wp.constant(1.00000024)


@wp.struct
class WideBoxes:
    """A wide node's four child boxes at one key, one lane per child: the six ``vec4`` of ``WideBvh.box`` at
    (w * K + k) * 6 as one 96-byte record, so that a walk computes one array index per key instead of six (each
    Warp index wraps negative values and multiplies by a stride: 6 integer instructions, 40 % of the top level's
    box test on the motion scene by callgrind)."""

    lx: wp.vec4
    ly: wp.vec4
    lz: wp.vec4
    hx: wp.vec4
    hy: wp.vec4
    hz: wp.vec4


WIDE_BOXES_DTYPE = np.dtype(WideBoxes.numpy_dtype())
assert WIDE_BOXES_DTYPE.itemsize == 96


def box_records(box: np.ndarray, device: str = "cpu") -> wp.array:
    """``WideBvh.box`` (W * K * 6, 4) as a Warp array of ``WideBoxes``, record w * K + k."""
    rec = np.ascontiguousarray(box, dtype=np.float32).reshape(-1, 24).view(WIDE_BOXES_DTYPE).reshape(-1)
    return wp.array(rec, dtype=WideBoxes, device=device, copy=True)


@dataclass
class WideBvh:
    box: np.ndarray  # (W * K * 6, 4) float32
    child: np.ndarray  # (W, 4) int32
    prim_order: np.ndarray  # (N,) int32
    num_keys: int

    @property
    def num_nodes(self) -> int:
        return int(self.child.shape[0])

    @property
    def nbytes(self) -> int:
        return self.box.nbytes + self.child.nbytes + self.prim_order.nbytes


def leaf_ref(first: int, count: int) -> int:
    return -((first << LEAF_BITS) | count) - 1


@wp.func
def leaf_range(ref: int):
    """(first, count) of a leaf reference."""
    v = -(ref + 1)
    return v >> LEAF_BITS, v & ((1 << LEAF_BITS) - 1)


@wp.func
def half_area(lo: wp.vec3, hi: wp.vec3):
    d = hi - lo
    return d[0] * d[1] + d[1] * d[2] + d[2] * d[0]


@wp.kernel
def subtree_ranges_kernel(node_a: wp.array(dtype=wp.int32), node_b: wp.array(dtype=wp.int32),
                          first: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32)):
    """Per binary node the slot range of its subtree's primitives (contiguous: a node's children split its
    range), one thread, children before parents (they follow them in pre-order)."""
    n = node_a.shape[0] - 1
    while n >= 0:
        a = node_a[n]
        if a < 0:
            first[n] = -(a + 1)
            count[n] = node_b[n]
        else:
            b = node_b[n]
            first[n] = wp.min(first[a], first[b])
            count[n] = count[a] + count[b]
        n -= 1


@wp.func
def is_leaf(node_a: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32), n: int, merge_leaf: int):
    """A binary node the wide tree keeps as one leaf: a leaf, or a subtree of at most ``merge_leaf`` primitives."""
    return node_a[n] < 0 or count[n] <= merge_leaf


@wp.kernel
def collapse_kernel(
    num_keys: int,
    merge_leaf: int,
    node_a: wp.array(dtype=wp.int32),
    node_b: wp.array(dtype=wp.int32),
    sub_first: wp.array(dtype=wp.int32),  # per binary node its subtree's first slot and primitive count
    sub_count: wp.array(dtype=wp.int32),
    node_lo: wp.array(dtype=wp.vec3),  # binary node n, key k at n * K + k
    node_hi: wp.array(dtype=wp.vec3),
    pending: wp.array(dtype=wp.int32),  # scratch: binary nodes waiting to become wide nodes (one per wide node)
    box: wp.array(dtype=wp.vec4),
    child: wp.array(dtype=wp.vec4i),
    count: wp.array(dtype=wp.int32),  # out: wide nodes
):
    """The whole collapse, one thread: wide node w is made from binary inner node pending[w]; new wide nodes are
    numbered in the order they are found, so pending doubles as the work queue."""
    nw = int(1)
    w = int(0)
    while w < nw:
        n = pending[w]
        c = wp.vec4i(node_a[n], node_b[n], -1, -1)
        nc = int(2)
        while nc < 4:
            best = int(-1)
            best_area = float(-1.0)
            for j in range(nc):
                cj = c[j]
                if not is_leaf(node_a, sub_count, cj, merge_leaf):
                    area = float(0.0)
                    for k in range(num_keys):
                        area += half_area(node_lo[cj * num_keys + k], node_hi[cj * num_keys + k])
                    if area > best_area:
                        best_area = area
                        best = j
            if best < 0:
                break
            opened = c[best]
            c[best] = node_a[opened]
            c[nc] = node_b[opened]
            nc += 1
        refs = wp.vec4i(0, 0, 0, 0)
        for j in range(4):
            if j < nc:
                cj = c[j]
                if is_leaf(node_a, sub_count, cj, merge_leaf):
                    refs[j] = -((sub_first[cj] << LEAF_BITS) | sub_count[cj]) - 1
                else:
                    pending[nw] = cj
                    refs[j] = nw
                    nw += 1
        child[w] = refs
        for k in range(num_keys):
            lx = wp.vec4(EMPTY)
            ly = wp.vec4(EMPTY)
            lz = wp.vec4(EMPTY)
            hx = wp.vec4(EMPTY)
            hy = wp.vec4(EMPTY)
            hz = wp.vec4(EMPTY)
            for j in range(nc):
                lo = node_lo[c[j] * num_keys + k]
                hi = node_hi[c[j] * num_keys + k]
                lx[j] = lo[0]
                ly[j] = lo[1]
                lz[j] = lo[2]
                hx[j] = hi[0]
                hy[j] = hi[1]
                hz[j] = hi[2]
            base = (w * num_keys + k) * 6
            box[base + 0] = lx
            box[base + 1] = ly
            box[base + 2] = lz
            box[base + 3] = hx
            box[base + 4] = hy
            box[base + 5] = hz
        w += 1
    count[0] = nw


def collapse(bvh: Bvh, device: str = "cpu", merge_leaf: int = 0) -> WideBvh:
    """The four-wide form of a binary ``Bvh`` (same primitive order, same per-key boxes). A subtree of at most
    ``merge_leaf`` primitives becomes one leaf (its primitives are contiguous in the order; its box is its root's)."""
    m, k = bvh.num_nodes, bvh.num_keys
    if bvh.num_prims > MAX_FIRST:
        raise ValueError(f"{bvh.num_prims} primitives in one mesh: at most {MAX_FIRST}")
    counts = bvh.node_b[bvh.node_a < 0]
    if counts.size and counts.max() >= 1 << LEAF_BITS:
        raise ValueError(f"leaves of up to {(1 << LEAF_BITS) - 1} primitives, got {counts.max()}")
    if bvh.node_a[0] < 0:  # the root is a leaf: one wide node holding it
        box = np.full((k, 6, 4), 3.0e38, np.float32)
        box[:, 0:3, 0] = bvh.node_lower[0]
        box[:, 3:6, 0] = bvh.node_upper[0]
        if bvh.num_prims == 0:
            box[:, :, 0] = 3.0e38
        child = np.array([[leaf_ref(-(int(bvh.node_a[0]) + 1), int(bvh.node_b[0])), 0, 0, 0]], np.int32)
        return WideBvh(box=box.reshape(-1, 4), child=child, prim_order=bvh.prim_order, num_keys=k)
    if merge_leaf >= 1 << LEAF_BITS:
        raise ValueError(f"leaves of up to {(1 << LEAF_BITS) - 1} primitives, asked to merge {merge_leaf}")
    with wp.ScopedDevice(device):
        inner = int((bvh.node_a >= 0).sum())
        node_a = wp.array(bvh.node_a, dtype=wp.int32)
        node_b = wp.array(bvh.node_b, dtype=wp.int32)
        sub_first = wp.empty(m, dtype=wp.int32)
        sub_count = wp.empty(m, dtype=wp.int32)
        wp.launch(subtree_ranges_kernel, dim=1, inputs=[node_a, node_b, sub_first, sub_count])
        pending = wp.zeros(max(1, inner), dtype=wp.int32)
        box = wp.empty(max(1, inner) * k * 6, dtype=wp.vec4)
        child = wp.empty(max(1, inner), dtype=wp.vec4i)
        count = wp.zeros(1, dtype=wp.int32)
        wp.launch(collapse_kernel, dim=1,
                  inputs=[k, int(merge_leaf), node_a, node_b, sub_first, sub_count,
                          wp.array(bvh.node_lower.reshape(-1, 3), dtype=wp.vec3),
                          wp.array(bvh.node_upper.reshape(-1, 3), dtype=wp.vec3), pending, box, child, count])
        nw = int(count.numpy()[0])
        return WideBvh(box=box.numpy()[:nw * k * 6].copy(), child=child.numpy()[:nw].copy(),
                       prim_order=bvh.prim_order, num_keys=k)


# The four slab tests as one vector computation. Warp's vec4 arithmetic compiles to scalar instructions (the
# kernel's code had 7 vminps against 175 vminss), so the box test is written in vector types (``vector_code``),
# lane for lane the operations of the Warp code it replaced: (bound - origin) * inv per axis, min and max as Warp
# defines them for numbers (-0 and +0 included), the same order of reductions. Its results are the same bits as
# ``box_entries_reference`` for every ray of numbers (tested); the production shot's walks spent 28 % of the kernel
# in this test, scalar. For a broken ray with a NaN coordinate the two may differ (Warp's min and max skip a NaN
# operand, these keep their first): neither is meaningful, and both return numbers.
SLAB_TEST_CPP = VECTOR_TYPES_CPP + r"""
    /* Warp's float min and max (builtin.h) for numbers, a <= b ? a : b and a >= b ? a : b (also which zero they
       pick), written so that each is one minps / maxps; with a NaN they give their first operand */
    auto vmin = [](v4f a, v4f b) { return b < a ? b : a; };
    auto vmax = [](v4f a, v4f b) { return b > a ? b : a; };
    /* the four boxes' lanes lx_, ly_, lz_, hx_, hy_, hz_ (v4f), the children c_ (v4i), the ray ro, inv_d, tmax */
    auto slab_test = [&](v4f lx_, v4f ly_, v4f lz_, v4f hx_, v4f hy_, v4f hz_, v4i c_) {
        const v4f ox = splat(ro.c[0]), oy = splat(ro.c[1]), oz = splat(ro.c[2]);
        const v4f ix = splat(inv_d.c[0]), iy = splat(inv_d.c[1]), iz = splat(inv_d.c[2]);
        const v4f ax = (lx_ - ox) * ix;
        const v4f bx = (hx_ - ox) * ix;
        const v4f ay = (ly_ - oy) * iy;
        const v4f by = (hy_ - oy) * iy;
        const v4f az = (lz_ - oz) * iz;
        const v4f bz = (hz_ - oz) * iz;
        const v4f tn = vmax(vmax(vmin(ax, bx), vmin(ay, by)), vmax(vmin(az, bz), splat(0.0f)));
        const v4f f_xyz = vmin(vmin(vmax(ax, bx), vmax(ay, by)), vmin(vmax(az, bz), splat(tmax)));
        const v4f tf = f_xyz * splat(1.00000024f);  /* SLAB_SLACK */
        const v4i used = c_ != (v4i){0, 0, 0, 0};
        const v4f d = ((tn <= tf) & used) ? tn : splat(3.4e38f);
        return wp::vec_t<4, wp::float32>(d[0], d[1], d[2], d[3]);
    };
"""
_BOX_ENTRIES_CPP = SLAB_TEST_CPP + r"""
    auto lanes = [](wp::vec_t<4, wp::float32> v) { return (v4f){v.c[0], v.c[1], v.c[2], v.c[3]}; };
    return slab_test(lanes(lx), lanes(ly), lanes(lz), lanes(hx), lanes(hy), lanes(hz),
                     (v4i){c.c[0], c.c[1], c.c[2], c.c[3]});
"""


@wp.func_native(_BOX_ENTRIES_CPP)
def box_entries(lx: wp.vec4, ly: wp.vec4, lz: wp.vec4, hx: wp.vec4, hy: wp.vec4, hz: wp.vec4, c: wp.vec4i,
                ro: wp.vec3, inv_d: wp.vec3, tmax: float) -> wp.vec4:
    """Entry distances of the ray into four boxes (one per lane; ``c`` their child references), BIG for a box it
    misses before tmax or an unused slot. A slab test made robust for flat boxes by 2 ulp of slack (Ize 2013).
    Native vector code, the same bits as ``box_entries_reference``."""
    ...


@wp.func
def _slabs(lo: wp.vec4, hi: wp.vec4, o: float, inv: float):
    t0 = (lo - wp.vec4(o)) * inv
    t1 = (hi - wp.vec4(o)) * inv
    return wp.min(t0, t1), wp.max(t0, t1)


@wp.func
def box_entries_reference(lx: wp.vec4, ly: wp.vec4, lz: wp.vec4, hx: wp.vec4, hy: wp.vec4, hz: wp.vec4,
                          c: wp.vec4i, ro: wp.vec3, inv_d: wp.vec3, tmax: float):
    """``box_entries`` in Warp's own arithmetic (scalar code): the definition the native version must equal."""
    nx, fx = _slabs(lx, hx, ro[0], inv_d[0])
    ny, fy = _slabs(ly, hy, ro[1], inv_d[1])
    nz, fz = _slabs(lz, hz, ro[2], inv_d[2])
    tn = wp.max(wp.max(nx, ny), wp.max(nz, wp.vec4(0.0)))
    tf = wp.min(wp.min(fx, fy), wp.min(fz, wp.vec4(tmax))) * SLAB_SLACK
    return wp.vec4(wp.where(tn[0] <= tf[0] and c[0] != 0, tn[0], BIG),
                   wp.where(tn[1] <= tf[1] and c[1] != 0, tn[1], BIG),
                   wp.where(tn[2] <= tf[2] and c[2] != 0, tn[2], BIG),
                   wp.where(tn[3] <= tf[3] and c[3] != 0, tn[3], BIG))


# Two keys' boxes of a top-level node blended to the ray's time (``wp.lerp``: a (1 - u) + b u per lane) and tested,
# in vector code: the blend was 24 scalar lerps per node visit of a blurred walk.
_BLEND_ENTRIES_CPP = SLAB_TEST_CPP + r"""
    const v4f wa = splat(1.0f - u), wb = splat(u);
    auto blend = [&](wp::vec_t<4, wp::float32> va, wp::vec_t<4, wp::float32> vb) {
        const v4f pa = (v4f){va.c[0], va.c[1], va.c[2], va.c[3]} * wa;
        const v4f pb = (v4f){vb.c[0], vb.c[1], vb.c[2], vb.c[3]} * wb;
        return pa + pb;
    };
    return slab_test(blend(a.lx, b.lx), blend(a.ly, b.ly), blend(a.lz, b.lz), blend(a.hx, b.hx),
                     blend(a.hy, b.hy), blend(a.hz, b.hz), (v4i){c.c[0], c.c[1], c.c[2], c.c[3]});
"""


@wp.func_native(_BLEND_ENTRIES_CPP)
def blended_box_entries(a: WideBoxes, b: WideBoxes, u: float, c: wp.vec4i, ro: wp.vec3, inv_d: wp.vec3,
                        tmax: float) -> wp.vec4:
    """``box_entries`` of the boxes ``wp.lerp(a, b, u)`` (native vector code, the same bits)."""
    ...


@wp.func
def entries(box: wp.array(dtype=WideBoxes), rec: int, c: wp.vec4i, k0: int, k1: int, u: float, ro: wp.vec3,
            inv_d: wp.vec3, tmax: float):
    """Entry distances of the ray into the four child boxes of a node (its key-0 record ``rec``, blended
    between keys k0 and k1; ``c`` its child references): ``box_entries``."""
    b = box[rec + k0]
    if k1 != k0:
        return blended_box_entries(b, box[rec + k1], u, c, ro, inv_d, tmax)
    return box_entries(b.lx, b.ly, b.lz, b.hx, b.hy, b.hz, c, ro, inv_d, tmax)


@wp.func
def entries_reference(box: wp.array(dtype=WideBoxes), rec: int, c: wp.vec4i, k0: int, k1: int, u: float,
                      ro: wp.vec3, inv_d: wp.vec3, tmax: float):
    """``entries`` with the blend in Warp's own code."""
    b = box[rec + k0]
    lx = b.lx
    ly = b.ly
    lz = b.lz
    hx = b.hx
    hy = b.hy
    hz = b.hz
    if k1 != k0:
        b1 = box[rec + k1]
        lx = wp.lerp(lx, b1.lx, u)
        ly = wp.lerp(ly, b1.ly, u)
        lz = wp.lerp(lz, b1.lz, u)
        hx = wp.lerp(hx, b1.hx, u)
        hy = wp.lerp(hy, b1.hy, u)
        hz = wp.lerp(hz, b1.hz, u)
    return box_entries_reference(lx, ly, lz, hx, hy, hz, c, ro, inv_d, tmax)


def root_boxes(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The top level's root box per segment between time keys, for ``root_entered``: the union of the (K, N, 3)
    instance boxes at keys k and k + 1 (at key 0 alone when K = 1), as (max(K - 1, 1) * 2, 3) float32 rows lo, hi.
    An instance's box blended at any time between two keys lies in the union of its two key boxes, so a walk tests
    the root without blending it. Grown by 2^-20 of its largest coordinate, since a float lerp between keys may
    round an ulp outside them. Without instances it is a point far away (as an unused child slot's box): its slab
    distances overflow, so no ray of unit direction from within the scene enters it before a finite tmax (an
    inverted box would not do: the slab test orders each axis's two distances, so lo > hi is entered everywhere)."""
    k = lo.shape[0]
    segments = max(k - 1, 1)
    root = np.empty((segments, 2, 3), np.float64)
    if lo.shape[1]:
        rlo, rhi = lo.min(1).astype(np.float64), hi.max(1).astype(np.float64)  # (K, 3) per key
        if k > 1:
            rlo, rhi = np.minimum(rlo[:-1], rlo[1:]), np.maximum(rhi[:-1], rhi[1:])
        pad = np.maximum(np.abs(rlo), np.abs(rhi)).max(1, keepdims=True) * 2.0**-20
        root[:, 0], root[:, 1] = rlo - pad, rhi + pad
    else:
        root[:] = EMPTY
    return np.clip(root, -BIG, BIG).astype(np.float32).reshape(-1, 3)


# One box's slab test in vector code: Warp's vec3 min and max skip NaN operands, which compiled the test to about
# 80 instructions with six branches; the root test of a blurred scene's top level, on every ray, took 5 % of the
# motion scene's kernel time (perf), half of what blur costs there. The lanes are the three axes, the fourth the
# ray's own interval [0, tmax]; each reduction is two shuffles and two minps / maxps. Which box it enters is the same
# as ``box_entered_reference`` for every ray of numbers (the order of a min or max changes only the sign of a zero
# result, which no comparison sees; tested).
_BOX_ENTERED_CPP = VECTOR_TYPES_CPP + r"""
    auto vmin = [](v4f a, v4f b) { return b < a ? b : a; };
    auto vmax = [](v4f a, v4f b) { return b > a ? b : a; };
    const v4f o = (v4f){ro.c[0], ro.c[1], ro.c[2], 0.0f};
    const v4f i = (v4f){inv_d.c[0], inv_d.c[1], inv_d.c[2], 0.0f};
    const v4f a = ((v4f){lo.c[0], lo.c[1], lo.c[2], 0.0f} - o) * i;
    const v4f b = ((v4f){hi.c[0], hi.c[1], hi.c[2], 0.0f} - o) * i;
    v4f n = vmin(a, b);
    v4f f = vmax(a, b);
    n[3] = 0.0f;  /* the ray starts at 0 and ends at tmax */
    f[3] = tmax;
    n = vmax(n, __builtin_shufflevector(n, n, 1, 0, 3, 2));
    n = vmax(n, __builtin_shufflevector(n, n, 2, 3, 0, 1));
    f = vmin(f, __builtin_shufflevector(f, f, 1, 0, 3, 2));
    f = vmin(f, __builtin_shufflevector(f, f, 2, 3, 0, 1));
    return n[0] <= f[0] * 1.00000024f;  /* SLAB_SLACK */
"""


@wp.func_native(_BOX_ENTERED_CPP)
def box_entered(lo: wp.vec3, hi: wp.vec3, ro: wp.vec3, inv_d: wp.vec3, tmax: float) -> bool:
    """Whether the ray enters the box [lo, hi] before tmax: the slab test of ``box_entries`` for one box (native
    vector code; the same answers as ``box_entered_reference``)."""
    ...


@wp.func
def box_entered_reference(lo: wp.vec3, hi: wp.vec3, ro: wp.vec3, inv_d: wp.vec3, tmax: float):
    """``box_entered`` in Warp's own arithmetic: the definition the native version must agree with."""
    t0 = wp.cw_mul(lo - ro, inv_d)
    t1 = wp.cw_mul(hi - ro, inv_d)
    near = wp.min(t0, t1)
    far = wp.max(t0, t1)
    tn = wp.max(wp.max(near[0], near[1]), wp.max(near[2], 0.0))
    tf = wp.min(wp.min(far[0], far[1]), wp.min(far[2], tmax)) * SLAB_SLACK
    return tn <= tf


@wp.func
def root_entered(root: wp.array(dtype=wp.vec3), k0: int, ro: wp.vec3, inv_d: wp.vec3, tmax: float):
    """Whether the ray enters the root box of the segment from key k0 (``root_boxes``) before tmax: one slab test
    that spares a ray passing by every instance the root's four-lane test. A blurred scene's still prims are one
    mesh walked directly, its movers instances under a top level: the test took the motion scene's integrator from
    206.6 to 197.4 M instructions (callgrind, 64x64, 4 spp; the still scene 187.1 M), and reading the segment's
    box rather than blending the keys' took its path tracing kernel from 199.5 to 198.1 M."""
    return box_entered(root[2 * k0], root[2 * k0 + 1], ro, inv_d, tmax)


@wp.func
def _order(da: float, ca: int, db: float, cb: int):
    """The pair with the larger distance first."""
    if da < db:
        return db, cb, da, ca
    return da, ca, db, cb


@wp.func
def far_to_near(d: wp.vec4, c: wp.vec4i):
    """The four (distance, child) pairs sorted by decreasing distance (five compare-exchanges). With one child
    entered or none, as deep in a walk most often, the order is left: only that child is pushed."""
    entered = wp.where(d[0] < BIG, 1, 0) + wp.where(d[1] < BIG, 1, 0) + wp.where(d[2] < BIG, 1, 0) + wp.where(
        d[3] < BIG, 1, 0)
    if entered < 2:
        return d, c
    d0, c0, d1, c1 = _order(d[0], c[0], d[1], c[1])
    d2, c2, d3, c3 = _order(d[2], c[2], d[3], c[3])
    d0, c0, d2, c2 = _order(d0, c0, d2, c2)
    d1, c1, d3, c3 = _order(d1, c1, d3, c3)
    d1, c1, d2, c2 = _order(d1, c1, d2, c2)
    return wp.vec4(d0, d1, d2, d3), wp.vec4i(c0, c1, c2, c3)
