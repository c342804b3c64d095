"""Building a BVH whose node bounds depend on time (binned SAH, one box per node per time key).

Input: every primitive's box at K time keys, ``lower, upper (K, N, 3)``. Between two keys a primitive's box at
time t is (at most) the linear blend of its boxes at the bracketing keys, which holds for linearly interpolated
vertices. A node stores the union of its children's boxes *per key*; blending two such unions with the same
weights still contains the blended children, so node boxes stay conservative at every time in between.

Layout (``Bvh``; root is node 0; nodes numbered depth-first in pre-order)::

    node_lower, node_upper: (M, K, 3) float32   node box per key
    node_a: (M,) int32     inner: first child (always node + 1, the child with fewer primitives)
                           leaf:  -(first + 1)
    node_b: (M,) int32     inner: second child (after the first child's whole subtree)
                           leaf:  primitive count, >= 1 (0 only for the single leaf of an empty input)
    prim_order: (N,) int32 a leaf's primitives are prim_order[first : first + count]

The topology is chosen by binned SAH with **time-averaged areas**: primitives are binned by their key-average
centroid, but every bin keeps the union of its boxes *per key*, and the area of a candidate child is the mean
over the keys of its per-key union's half area, which is the area the traversal will actually meet, averaged
over the shutter (exact at the keys; between keys the blended box is what the mean approximates). One
representative box per primitive does worse over the shutter (measured in ``tests/renderer/accel/test_accel_build.py``, SAH
cost averaged over 3 keys, 3000 boxes): the union over keys stretches fast movers along their path so SAH
groups them by sweep (+10..20%), and the key-average box puts a mover among still primitives near its mid
position, whose nodes then stretch with it at the other keys (+5..10% against the union when a fifth of the
scene moves). For K = 1 all of this is plain binned SAH. (Key times are not passed in; for unevenly spaced
keys the plain mean weights the keys equally, which only affects quality, never correctness.)

SAH constants: ``C_TRAV = 1`` for visiting an inner node (two lerped child-box slab tests, about the cost of one
moving-triangle test) and ``C_ISECT = 1`` per primitive; a node with ``n <= max_leaf`` primitives stays a leaf
when ``C_ISECT * n <= C_TRAV + C_ISECT * (A_l n_l + A_r n_r) / A`` (key-averaged half surface areas); larger
nodes are always split. ``NUM_BINS = 16`` per axis (``min(16, n // 2)``, at least 2, for a node of n
primitives), all three axes. A node of n >= 2 ``SAMPLE_TARGET`` primitives chooses its split from every
(n // SAMPLE_TARGET)-th of them (the partition still moves all): binning is half of a build, and the top levels
bin every primitive once per level. At 4096 the 1M-triangle heavy scene builds 17 % faster (0.66 -> 0.55 s,
``build_topology`` alone) with its SAH cost unchanged (4.28 -> 4.29); over the 25 meshes of at least 2048
triangles in the shared assets, peer references and bench scenes the SAH cost moved +0.03 % on average, +0.5 %
at most. (1024 was faster still, 0.52 s, but cost a 540k-triangle layout 3.4 %; 512 cost the gloss scene's 4k
triangles 12 %: a few large triangles a sparse sample misses weigh on the top split.)

Degenerate inputs terminate: coincident centroids split by equal counts, zero-area nodes (points) split at the
most balanced bin boundary, and the tree depth (nodes on the longest root-to-leaf path) is kept
``<= max_depth`` (default 48) by switching to equal-count splits when a subtree would otherwise run out of
depth, so a traversal stack of 64 entries never overflows. (A max_depth below ``1 + ceil(log2(ceil(N /
max_leaf)))`` cannot be met; the tree is then all equal-count splits, as shallow as possible.) Coordinates are
normalised in float64 before binning, so huge (finite) coordinates are fine; NaN or infinite bounds are rejected.

Empty input (N == 0): one leaf with count 0 whose boxes are ``lower = +3.4e38, upper = -3.4e38`` at every key
(an empty box: no ray hits it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from renderer.accel import build_kernels as K_

NUM_BINS = 16
C_TRAV = 1.0
C_ISECT = 1.0
MAX_DEPTH = 48
SAMPLE_TARGET = 4096
EMPTY = 3.4e38  # empty box: lower = +EMPTY, upper = -EMPTY


@dataclass
class Bvh:
    """A BVH with K boxes per node (see the module docstring for the layout). All arrays C-contiguous."""

    node_lower: np.ndarray  # (M, K, 3) float32
    node_upper: np.ndarray  # (M, K, 3) float32
    node_a: np.ndarray  # (M,) int32
    node_b: np.ndarray  # (M,) int32
    prim_order: np.ndarray  # (N,) int32

    @property
    def num_nodes(self) -> int:
        return int(self.node_a.shape[0])

    @property
    def num_keys(self) -> int:
        return int(self.node_lower.shape[1])

    @property
    def num_prims(self) -> int:
        return int(self.prim_order.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes of all arrays (node boxes + child/leaf words + primitive order)."""
        return sum(a.nbytes for a in (self.node_lower, self.node_upper, self.node_a, self.node_b, self.prim_order))

    @property
    def bytes_per_node(self) -> int:
        """24 * K + 8: two float32 corners per key and two int32 words."""
        return 24 * self.num_keys + 8

    def depth(self) -> int:
        """Number of nodes on the longest root-to-leaf path (1 for a single leaf)."""
        parent = np.zeros(self.num_nodes, np.int64)
        inner = np.nonzero(self.node_a >= 0)[0]
        parent[self.node_a[inner]] = inner
        parent[self.node_b[inner]] = inner
        d = np.ones(self.num_nodes, np.int64)
        d[0] = 0
        while True:  # one pass per level: depth(i) = depth(parent) + 1
            nd = d[parent] + 1
            nd[0] = 1
            if np.array_equal(nd, d):
                return int(d.max())
            d = nd


def bytes_per_primitive(bvh: Bvh) -> float:
    """Total BVH bytes divided by the number of primitives (``nbytes`` for an empty one)."""
    return bvh.nbytes / max(bvh.num_prims, 1)


def _check_boxes(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lower = np.asarray(lower, dtype=np.float32)
    upper = np.asarray(upper, dtype=np.float32)
    if lower.ndim == 2:  # (N, 3): one key
        lower, upper = lower[None], upper[None]
    if lower.ndim != 3 or lower.shape[-1] != 3 or lower.shape != upper.shape or lower.shape[0] < 1:
        raise ValueError(f"lower/upper must both be (K, N, 3) with K >= 1, got {lower.shape} and {upper.shape}")
    if not (np.isfinite(lower).all() and np.isfinite(upper).all()):
        raise ValueError("primitive bounds contain NaN or infinity")
    if lower.shape[0] * lower.shape[1] >= 2**30:
        raise ValueError(f"too many primitive boxes for int32 indices: {lower.shape[0]} keys x {lower.shape[1]}")
    return np.ascontiguousarray(lower), np.ascontiguousarray(upper)


def _empty_bvh(k: int) -> Bvh:
    return Bvh(
        node_lower=np.full((1, k, 3), EMPTY, np.float32),
        node_upper=np.full((1, k, 3), -EMPTY, np.float32),
        node_a=np.array([-1], np.int32),
        node_b=np.array([0], np.int32),
        prim_order=np.zeros(0, np.int32),
    )


def build_bvh(
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    max_leaf: int = 4,
    device: str = "cpu",
    num_bins: int = NUM_BINS,
    max_depth: int = MAX_DEPTH,
    c_trav: float = C_TRAV,
    c_isect: float = C_ISECT,
    sample_target: int = SAMPLE_TARGET,
) -> Bvh:
    """Binned-SAH BVH over primitives with boxes ``lower, upper (K, N, 3)`` at K time keys (``(N, 3)`` means
    K = 1). Returns NumPy arrays in the layout of ``Bvh``; runs as four single-thread Warp launches on ``device``
    (CPU is the intended one: the build is sequential; each launch releases the GIL).

    ``num_bins``, ``max_depth``, ``c_trav`` and ``c_isect`` default to the module constants documented above."""
    lower, upper = _check_boxes(lower, upper)
    if max_leaf < 1:
        raise ValueError(f"max_leaf must be >= 1, got {max_leaf}")
    if num_bins < 2:
        raise ValueError(f"num_bins must be >= 2, got {num_bins}")
    nkeys, n, _ = lower.shape
    if n == 0:
        return _empty_bvh(nkeys)
    if n == 1:  # one leaf, what the kernels give, without their launches (a scene's many one-shape meshes)
        return Bvh(node_lower=lower.transpose(1, 0, 2).copy(), node_upper=upper.transpose(1, 0, 2).copy(),
                   node_a=np.array([-1], np.int32), node_b=np.array([1], np.int32),
                   prim_order=np.zeros(1, np.int32))

    with wp.ScopedDevice(device):
        on_cpu = wp.get_device().is_cpu
        # (K * N,) views of the caller's arrays on the CPU (flattened in NumPy: a (1, N, 3) array may carry a
        # zero stride that Warp would call non-contiguous), then (K, N) views of those
        flat_lo = wp.array(lower.reshape(-1, 3), dtype=wp.vec3, copy=not on_cpu)
        flat_hi = wp.array(upper.reshape(-1, 3), dtype=wp.vec3, copy=not on_cpu)
        key_lo = flat_lo.reshape((nkeys, n))
        key_hi = flat_hi.reshape((nkeys, n))
        bounds = wp.empty(2, dtype=wp.vec3)
        wp.launch(K_.scene_bounds, dim=1, inputs=[flat_lo, flat_hi, bounds])

        # normalise the representative boxes to about [-1, 1]^3 (SAH does not care about translation and scale)
        glo, ghi = bounds.numpy().astype(np.float64)
        center = 0.5 * (glo + ghi)
        half = 0.5 * float(np.max(ghi - glo))
        inv_half = 1.0 / half if half > 0.0 else 1.0
        box_lo = wp.empty(n * nkeys, dtype=wp.vec3)
        box_hi = wp.empty(n * nkeys, dtype=wp.vec3)
        cen = wp.empty(n if nkeys > 1 else 1, dtype=wp.vec3)  # one key: the box centres (slot_centroid)
        prim = wp.empty(n, dtype=wp.int32)
        centroid_bounds = wp.empty(2, dtype=wp.vec3)
        wp.launch(
            K_.normalise_boxes,
            dim=1,
            inputs=[nkeys, key_lo, key_hi, wp.vec3d(*center), wp.float64(inv_half), box_lo, box_hi, cen, prim,
                    centroid_bounds],
        )
        cen_lo, cen_hi = centroid_bounds.numpy()

        params = K_.BuildParams()
        params.n_prims = n
        params.num_keys = nkeys
        params.max_leaf = int(max_leaf)
        params.max_depth = int(max_depth)
        params.num_bins = int(num_bins)
        params.c_trav = float(c_trav)
        params.c_isect = float(c_isect)
        params.sample_target = int(sample_target)

        bins = K_.BinScratch()
        bins.lo = wp.empty(3 * num_bins * nkeys, dtype=wp.vec3)
        bins.hi = wp.empty(3 * num_bins * nkeys, dtype=wp.vec3)
        bins.count = wp.empty(3 * num_bins, dtype=wp.int32)
        bins.right_cost = wp.empty(num_bins, dtype=wp.float32)
        bins.right_count = wp.empty(num_bins, dtype=wp.int32)
        bins.acc_lo = wp.empty(nkeys, dtype=wp.vec3)
        bins.acc_hi = wp.empty(nkeys, dtype=wp.vec3)

        stack = K_.WorkStack()
        stack.start = wp.empty(K_.STACK_CAPACITY, dtype=wp.int32)
        stack.end = wp.empty(K_.STACK_CAPACITY, dtype=wp.int32)
        stack.parent = wp.empty(K_.STACK_CAPACITY, dtype=wp.int32)
        stack.depth = wp.empty(K_.STACK_CAPACITY, dtype=wp.int32)
        stack.clo = wp.empty(K_.STACK_CAPACITY, dtype=wp.vec3)
        stack.chi = wp.empty(K_.STACK_CAPACITY, dtype=wp.vec3)

        max_nodes = 2 * n - 1
        node_a = wp.empty(max_nodes, dtype=wp.int32)
        node_b = wp.empty(max_nodes, dtype=wp.int32)
        node_count = wp.zeros(1, dtype=wp.int32)
        wp.launch(
            K_.build_topology,
            dim=1,
            inputs=[params, wp.vec3(*cen_lo), wp.vec3(*cen_hi), box_lo, box_hi, cen, prim, bins, stack, node_a, node_b,
                    node_count],
        )
        m = int(node_count.numpy()[0])

        out_lo = wp.empty((m, nkeys), dtype=wp.vec3)
        out_hi = wp.empty((m, nkeys), dtype=wp.vec3)
        wp.launch(K_.refit_keys, dim=1, inputs=[m, nkeys, key_lo, key_hi, prim, node_a, node_b, out_lo, out_hi])

        return Bvh(
            node_lower=np.ascontiguousarray(out_lo.numpy().reshape(m, nkeys, 3)),
            node_upper=np.ascontiguousarray(out_hi.numpy().reshape(m, nkeys, 3)),
            node_a=node_a.numpy()[:m].copy(),
            node_b=node_b.numpy()[:m].copy(),
            prim_order=prim.numpy(),  # a view that keeps the Warp array alive
        )
