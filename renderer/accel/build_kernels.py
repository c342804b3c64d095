"""Warp kernels of the BVH builder (``build.py`` is the NumPy-facing side and documents the layout).

All four kernels are sequential and launched with ``dim=1``: a top-down build is a chain of dependent
decisions, and one native thread running an explicit work stack beats any amount of NumPy bookkeeping per node.
A CPU launch releases the GIL, so a build can overlap other Python work.

``scene_bounds`` and ``normalise_boxes`` prepare a normalised copy of the per-key boxes (the scene spans about
[-1, 1]^3) and the key-average centroids; ``build_topology`` chooses the splits on that copy, reordering it and
the primitive indices in place; ``refit_keys`` then computes the per-key node bounds bottom-up from the
caller's original boxes, so the output bounds are exact unions of the input, untouched by the normalisation.
"""
from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

BIG = wp.constant(3.4e38)  # the float32 range is +-3.4028235e38; an empty box is [+BIG, -BIG]
# Centroid extents at or below this (in normalised units, the scene is about 2 wide) are treated as zero: the
# axis cannot be binned. Keeps nbins / extent finite in float32.
MIN_EXTENT = wp.constant(1.0e-30)
STACK_CAPACITY = 64  # pending siblings; the smaller child is built first, so at most log2(N) + 1 are pending


@wp.struct
class BuildParams:
    """Scalars of one build."""

    n_prims: int
    num_keys: int  # K: boxes per primitive
    max_leaf: int  # a node with more primitives is always split
    max_depth: int  # deeper nodes would be reached only by equal-count splits (see build_topology)
    num_bins: int  # SAH bins per axis
    c_trav: float  # SAH cost of visiting an inner node (two child-box tests), in units of one primitive test
    c_isect: float  # SAH cost of one primitive test
    sample_target: int  # a node of n >= 2 * sample_target primitives bins every (n // sample_target)-th only


@wp.struct
class BinScratch:
    """Per-node SAH bins, bin b of axis a is bin j = a * num_bins + b. Reset for every node."""

    lo: wp.array(dtype=wp.vec3)  # (3 * num_bins * K,) per key, the union of the boxes whose centroid falls in
    hi: wp.array(dtype=wp.vec3)  # the bin: bin j key k at j * K + k
    count: wp.array(dtype=wp.int32)  # (3 * num_bins,)
    right_cost: wp.array(dtype=wp.float32)  # (num_bins,) area(union of bins >= b) * count(bins >= b), one axis
    right_count: wp.array(dtype=wp.int32)  # at a time
    acc_lo: wp.array(dtype=wp.vec3)  # (K,) a running union of bins, per key
    acc_hi: wp.array(dtype=wp.vec3)


@wp.struct
class WorkStack:
    """Pending right-hand work: a primitive range still to be built, the parent whose ``node_b`` it becomes,
    its depth and the bounds of its centroids (computed while partitioning the parent)."""

    start: wp.array(dtype=wp.int32)
    end: wp.array(dtype=wp.int32)
    parent: wp.array(dtype=wp.int32)
    depth: wp.array(dtype=wp.int32)
    clo: wp.array(dtype=wp.vec3)
    chi: wp.array(dtype=wp.vec3)


@wp.func
def half_area(lo: wp.vec3, hi: wp.vec3) -> float:
    """Half the surface area of a box; 0 for an empty box (lo > hi)."""
    d = wp.max(hi - lo, wp.vec3(0.0))
    return d[0] * d[1] + d[1] * d[2] + d[2] * d[0]


@wp.func
def bin_of(c: float, lo: float, scale: float, num_bins: int) -> int:
    """Bin of centroid coordinate c; the binning and the partition must use this same function so that the
    partition reproduces the bin counts exactly."""
    b = int((c - lo) * scale)
    return wp.clamp(b, 0, num_bins - 1)


@wp.func
def axis_scale(extent: float, num_bins: int) -> float:
    """Centroid-to-bin scale of an axis, 0 when the axis is too thin to bin."""
    s = float(0.0)
    if extent > MIN_EXTENT:
        s = float(num_bins) / extent
    return s


@wp.func
def ceil_log2(x: int) -> int:
    """Smallest d with 2^d >= x (0 for x <= 1)."""
    d = int(0)
    v = int(1)
    while v < x:
        v = v * 2
        d += 1
    return d


@wp.func
def mean_half_area(lo: wp.array(dtype=wp.vec3), hi: wp.array(dtype=wp.vec3), base: int, num_keys: int) -> float:
    """Half surface area averaged over the keys of the per-key boxes lo/hi[base : base + num_keys]."""
    s = float(0.0)
    for k in range(num_keys):
        s += half_area(lo[base + k], hi[base + k])
    return s / float(num_keys)


@wp.func
def reset_boxes(lo: wp.array(dtype=wp.vec3), hi: wp.array(dtype=wp.vec3), base: int, count: int):
    for j in range(base, base + count):
        lo[j] = wp.vec3(BIG)
        hi[j] = wp.vec3(-BIG)


@wp.func
def grow_boxes(
    lo: wp.array(dtype=wp.vec3),
    hi: wp.array(dtype=wp.vec3),
    base: int,
    src_lo: wp.array(dtype=wp.vec3),
    src_hi: wp.array(dtype=wp.vec3),
    src_base: int,
    count: int,
):
    """lo/hi[base + k] |= src_lo/src_hi[src_base + k] for k < count."""
    for k in range(count):
        lo[base + k] = wp.min(lo[base + k], src_lo[src_base + k])
        hi[base + k] = wp.max(hi[base + k], src_hi[src_base + k])


@wp.func
def slot_centroid(box_lo: wp.array(dtype=wp.vec3), box_hi: wp.array(dtype=wp.vec3), cen: wp.array(dtype=wp.vec3),
                  i: int, num_keys: int) -> wp.vec3:
    """The key-average centroid of slot i. With one key it is the box's centre, computed as ``normalise_boxes``
    does, bit for bit, so no copy is kept: the build streams 24 bytes per slot instead of 36 (simulated last-level
    misses -26 % on the 1M-triangle heavy scene)."""
    if num_keys == 1:
        return (box_lo[i] + box_hi[i]) * 0.5
    return cen[i]


@wp.func
def swap_slots(box_lo: wp.array(dtype=wp.vec3), box_hi: wp.array(dtype=wp.vec3), cen: wp.array(dtype=wp.vec3),
               prim: wp.array(dtype=wp.int32), i: int, j: int, num_keys: int):
    t = prim[i]
    prim[i] = prim[j]
    prim[j] = t
    if num_keys == 1:  # no centroid copy (slot_centroid)
        lo1 = box_lo[i]
        hi1 = box_hi[i]
        box_lo[i] = box_lo[j]
        box_hi[i] = box_hi[j]
        box_lo[j] = lo1
        box_hi[j] = hi1
        return
    c = cen[i]
    cen[i] = cen[j]
    cen[j] = c
    for k in range(num_keys):
        lo = box_lo[i * num_keys + k]
        hi = box_hi[i * num_keys + k]
        box_lo[i * num_keys + k] = box_lo[j * num_keys + k]
        box_hi[i * num_keys + k] = box_hi[j * num_keys + k]
        box_lo[j * num_keys + k] = lo
        box_hi[j * num_keys + k] = hi


@wp.func
def bins_area(bins: BinScratch, first: int, count: int, nk: int) -> float:
    """Key-averaged half area of the union of bins first .. first + count - 1."""
    if nk == 1:
        lo = wp.vec3(BIG)
        hi = wp.vec3(-BIG)
        for j in range(first, first + count):
            lo = wp.min(lo, bins.lo[j])
            hi = wp.max(hi, bins.hi[j])
        return half_area(lo, hi)
    reset_boxes(bins.acc_lo, bins.acc_hi, 0, nk)
    for j in range(first, first + count):
        grow_boxes(bins.acc_lo, bins.acc_hi, 0, bins.lo, bins.hi, j * nk, nk)
    return mean_half_area(bins.acc_lo, bins.acc_hi, 0, nk)


@wp.func
def sweep_axis(bins: BinScratch, base: int, nb: int, nk: int):
    """Cheapest split between the bins base .. base + nb - 1 of one axis: (A_l n_l + A_r n_r, first bin of the
    right side), or (BIG, 0) when every split leaves a side empty. Areas are key-averaged half areas."""
    best = float(BIG)
    best_bin = int(0)
    cnt = int(0)
    if nk == 1:  # the still case in registers
        lo = wp.vec3(BIG)
        hi = wp.vec3(-BIG)
        for r in range(nb - 1):
            b = nb - 1 - r
            lo = wp.min(lo, bins.lo[base + b])
            hi = wp.max(hi, bins.hi[base + b])
            cnt += bins.count[base + b]
            bins.right_cost[b] = half_area(lo, hi) * float(cnt)
            bins.right_count[b] = cnt
        lo = wp.vec3(BIG)
        hi = wp.vec3(-BIG)
        cnt = int(0)
        for b in range(1, nb):
            lo = wp.min(lo, bins.lo[base + b - 1])
            hi = wp.max(hi, bins.hi[base + b - 1])
            cnt += bins.count[base + b - 1]
            if cnt > 0 and bins.right_count[b] > 0:
                cost = half_area(lo, hi) * float(cnt) + bins.right_cost[b]
                if cost < best:
                    best = cost
                    best_bin = b
        return best, best_bin
    reset_boxes(bins.acc_lo, bins.acc_hi, 0, nk)
    for r in range(nb - 1):
        b = nb - 1 - r
        grow_boxes(bins.acc_lo, bins.acc_hi, 0, bins.lo, bins.hi, (base + b) * nk, nk)
        cnt += bins.count[base + b]
        bins.right_cost[b] = mean_half_area(bins.acc_lo, bins.acc_hi, 0, nk) * float(cnt)
        bins.right_count[b] = cnt
    reset_boxes(bins.acc_lo, bins.acc_hi, 0, nk)
    cnt = int(0)
    for b in range(1, nb):
        grow_boxes(bins.acc_lo, bins.acc_hi, 0, bins.lo, bins.hi, (base + b - 1) * nk, nk)
        cnt += bins.count[base + b - 1]
        if cnt > 0 and bins.right_count[b] > 0:
            cost = mean_half_area(bins.acc_lo, bins.acc_hi, 0, nk) * float(cnt) + bins.right_cost[b]
            if cost < best:
                best = cost
                best_bin = b
    return best, best_bin


@wp.func
def partition(box_lo: wp.array(dtype=wp.vec3), box_hi: wp.array(dtype=wp.vec3), cen: wp.array(dtype=wp.vec3),
              prim: wp.array(dtype=wp.int32), start: int, end: int, nk: int, axis: int, cmin: float, scale: float,
              nb: int, split_bin: int):
    """Hoare partition of the slots start .. end - 1: those whose centroid falls in a bin below ``split_bin`` of
    ``axis`` first. Swaps only misplaced pairs (half the swaps of moving every right-hand slot to the end: heavy's
    topology -5 % instructions). Returns the first right-hand slot and the centroid bounds of both sides."""
    lclo = wp.vec3(BIG)
    lchi = wp.vec3(-BIG)
    rclo = wp.vec3(BIG)
    rchi = wp.vec3(-BIG)
    ci = wp.vec3(0.0)
    cj = wp.vec3(0.0)
    i = start
    j = end - 1
    while i <= j:
        while i <= j:  # i up to the first slot that belongs right
            ci = slot_centroid(box_lo, box_hi, cen, i, nk)
            if bin_of(ci[axis], cmin, scale, nb) >= split_bin:
                break
            lclo = wp.min(lclo, ci)
            lchi = wp.max(lchi, ci)
            i += 1
        while i <= j:  # j down to the last slot that belongs left
            cj = slot_centroid(box_lo, box_hi, cen, j, nk)
            if bin_of(cj[axis], cmin, scale, nb) < split_bin:
                break
            rclo = wp.min(rclo, cj)
            rchi = wp.max(rchi, cj)
            j -= 1
        if i < j:
            swap_slots(box_lo, box_hi, cen, prim, i, j, nk)
            lclo = wp.min(lclo, cj)
            lchi = wp.max(lchi, cj)
            rclo = wp.min(rclo, ci)
            rchi = wp.max(rchi, ci)
            i += 1
            j -= 1
    return i, lclo, lchi, rclo, rchi


@wp.kernel
def build_topology(
    p: BuildParams,
    root_clo: wp.vec3,
    root_chi: wp.vec3,
    box_lo: wp.array(dtype=wp.vec3),  # (N * K,) per-key boxes, normalised, slot i key k at i * K + k; reordered
    box_hi: wp.array(dtype=wp.vec3),
    cen: wp.array(dtype=wp.vec3),  # (N,) key-average centroid per slot, normalised (K > 1 only); reordered
    prim: wp.array(dtype=wp.int32),  # (N,) primitive index per slot, 0..N-1 on entry; reordered in place
    bins: BinScratch,
    stack: WorkStack,
    node_a: wp.array(dtype=wp.int32),  # (2N - 1,) outputs, see build.Bvh
    node_b: wp.array(dtype=wp.int32),
    node_count: wp.array(dtype=wp.int32),  # (1,) output: number of nodes written
):
    """Top-down binned-SAH build, one thread. Nodes are numbered in depth-first pre-order; the first child of
    node i is node i + 1 and is the child with fewer primitives (so the pending stack stays shallow), the other
    child comes after the first child's whole subtree.

    Per node: bin the key-average centroids on all three axes (num_bins bins each; per bin a count and the union
    of the boxes at every key), sweep the bins for the cheapest split ``c_trav + c_isect * (A_l n_l + A_r n_r) /
    A`` where A is the half area averaged over the keys, keep a leaf when ``n <= max_leaf`` and the leaf cost
    ``c_isect * n`` is no higher, else partition the slots in place. Fallbacks that always terminate: if every
    axis is too thin to bin (coincident centroids) or the depth budget is spent, split the slot range in the
    middle (equal counts); if the node's box has no area (points), take the most balanced bin boundary of the
    widest axis instead of the SAH one.
    """
    nk = p.num_keys
    counter = int(0)
    sp = int(0)
    start = int(0)
    end = p.n_prims
    depth = int(0)
    clo = root_clo
    chi = root_chi
    running = int(1)
    while running == 1:
        node = counter
        counter += 1
        n = end - start
        # a bin per two primitives in small nodes: resetting and sweeping 3 * nb bins weighs as much as binning
        # the node (heavy's topology -15 % instructions; SAH cost +0.06 % on average over 20 meshes, at most +0.5 %)
        nb = wp.min(p.num_bins, wp.max(n // 2, 2))

        # ---- choose a split: split_axis >= 0 with split_bin (bins < split_bin go first), -1 equal counts,
        # -2 none (leaf)
        split_axis = int(-2)
        split_bin = int(0)
        ext = chi - clo
        s0 = axis_scale(ext[0], nb)
        s1 = axis_scale(ext[1], nb)
        s2 = axis_scale(ext[2], nb)
        leaves_needed = (n + p.max_leaf - 1) // p.max_leaf
        force_equal = depth + 1 + ceil_log2(leaves_needed) >= p.max_depth  # root depth 0, paths count nodes
        if n > 1:
            if force_equal or (s0 == 0.0 and s1 == 0.0 and s2 == 0.0):
                if n > p.max_leaf:
                    split_axis = -1
            elif n == 2:
                # two primitives (a third of all inner nodes): SAH on the pair directly, no bins
                if n > p.max_leaf:
                    split_axis = -1
                else:
                    a0 = mean_half_area(box_lo, box_hi, start * nk, nk)
                    a1 = mean_half_area(box_lo, box_hi, (start + 1) * nk, nk)
                    reset_boxes(bins.acc_lo, bins.acc_hi, 0, nk)
                    grow_boxes(bins.acc_lo, bins.acc_hi, 0, box_lo, box_hi, start * nk, nk)
                    grow_boxes(bins.acc_lo, bins.acc_hi, 0, box_lo, box_hi, (start + 1) * nk, nk)
                    pair_area = mean_half_area(bins.acc_lo, bins.acc_hi, 0, nk)
                    if pair_area > 0.0:
                        if p.c_trav + p.c_isect * (a0 + a1) / pair_area < 2.0 * p.c_isect:
                            split_axis = -1
            else:
                reset_boxes(bins.lo, bins.hi, 0, 3 * nb * nk)
                for j in range(3 * nb):
                    bins.count[j] = 0
                # a large node's split from a strided sample of its primitives (the partition below still moves
                # every one; a sweep only takes bins with samples on both sides, so neither child is empty)
                step = int(1)
                if p.sample_target > 0:
                    step = wp.max(1, n // p.sample_target)
                binned = (n + step - 1) // step
                if nk == 1:  # the still case, without the per-key loops
                    for i in range(start, end, step):
                        lo = box_lo[i]
                        hi = box_hi[i]
                        c = (lo + hi) * 0.5  # slot_centroid
                        if s0 > 0.0:
                            j0 = bin_of(c[0], clo[0], s0, nb)
                            bins.count[j0] += 1
                            bins.lo[j0] = wp.min(bins.lo[j0], lo)
                            bins.hi[j0] = wp.max(bins.hi[j0], hi)
                        if s1 > 0.0:
                            j1 = nb + bin_of(c[1], clo[1], s1, nb)
                            bins.count[j1] += 1
                            bins.lo[j1] = wp.min(bins.lo[j1], lo)
                            bins.hi[j1] = wp.max(bins.hi[j1], hi)
                        if s2 > 0.0:
                            j2 = 2 * nb + bin_of(c[2], clo[2], s2, nb)
                            bins.count[j2] += 1
                            bins.lo[j2] = wp.min(bins.lo[j2], lo)
                            bins.hi[j2] = wp.max(bins.hi[j2], hi)
                else:
                    for i in range(start, end, step):
                        c = cen[i]
                        if s0 > 0.0:
                            j0 = bin_of(c[0], clo[0], s0, nb)
                            bins.count[j0] += 1
                            grow_boxes(bins.lo, bins.hi, j0 * nk, box_lo, box_hi, i * nk, nk)
                        if s1 > 0.0:
                            j1 = nb + bin_of(c[1], clo[1], s1, nb)
                            bins.count[j1] += 1
                            grow_boxes(bins.lo, bins.hi, j1 * nk, box_lo, box_hi, i * nk, nk)
                        if s2 > 0.0:
                            j2 = 2 * nb + bin_of(c[2], clo[2], s2, nb)
                            bins.count[j2] += 1
                            grow_boxes(bins.lo, bins.hi, j2 * nk, box_lo, box_hi, i * nk, nk)

                # the node's own boxes: the union of the bins of any binned axis
                first_axis = int(0)
                if s0 == 0.0:
                    first_axis = 1
                    if s1 == 0.0:
                        first_axis = 2
                node_area = bins_area(bins, first_axis * nb, nb, nk)

                best = float(BIG)
                best_axis = int(-1)
                best_bin = int(0)
                if node_area > 0.0:
                    for a in range(3):
                        sa = s0
                        if a == 1:
                            sa = s1
                        if a == 2:
                            sa = s2
                        if sa > 0.0:
                            cost, b = sweep_axis(bins, a * nb, nb, nk)
                            if cost < best:
                                best = cost
                                best_axis = a
                                best_bin = b
                elif n > p.max_leaf:
                    # no area to weigh (points or lines): most balanced bin boundary on the widest axis
                    wa = int(0)
                    ws = s0
                    if ext[1] > ext[wa]:
                        wa = 1
                        ws = s1
                    if ext[2] > ext[wa]:
                        wa = 2
                        ws = s2
                    if ws > 0.0:
                        wcnt = int(0)
                        best_imbalance = int(binned + 1)
                        for b in range(1, nb):
                            wcnt += bins.count[wa * nb + b - 1]
                            if wcnt > 0 and wcnt < binned:
                                imbalance = wp.abs(2 * wcnt - binned)
                                if imbalance < best_imbalance:
                                    best_imbalance = imbalance
                                    best_axis = wa
                                    best_bin = b
                    best = float(0.0)

                if best_axis >= 0:
                    split_axis = best_axis
                    split_bin = best_bin
                    if n <= p.max_leaf:
                        leaf_cost = p.c_isect * float(n)
                        split_cost = p.c_trav + p.c_isect * best / wp.max(node_area, 1.0e-30)
                        if leaf_cost <= split_cost:
                            split_axis = -2
                elif n > p.max_leaf:
                    split_axis = -1

        # ---- emit the node
        if split_axis == -2:
            node_a[node] = -(start + 1)
            node_b[node] = n
            if sp == 0:
                running = 0
            else:
                sp -= 1
                start = stack.start[sp]
                end = stack.end[sp]
                depth = stack.depth[sp]
                clo = stack.clo[sp]
                chi = stack.chi[sp]
                node_b[stack.parent[sp]] = counter
        else:
            mid = start + n // 2
            lclo = clo
            lchi = chi
            rclo = clo
            rchi = chi
            if split_axis >= 0:
                sa = s0
                if split_axis == 1:
                    sa = s1
                if split_axis == 2:
                    sa = s2
                mid, lclo, lchi, rclo, rchi = partition(box_lo, box_hi, cen, prim, start, end, nk, split_axis,
                                                        clo[split_axis], sa, nb, split_bin)
            # the smaller child becomes node + 1, the other waits on the stack
            node_a[node] = node + 1
            stack.parent[sp] = node
            stack.depth[sp] = depth + 1
            depth += 1
            if mid - start <= end - mid:
                stack.start[sp] = mid
                stack.end[sp] = end
                stack.clo[sp] = rclo
                stack.chi[sp] = rchi
                end = mid
                clo = lclo
                chi = lchi
            else:
                stack.start[sp] = start
                stack.end[sp] = mid
                stack.clo[sp] = lclo
                stack.chi[sp] = lchi
                start = mid
                clo = rclo
                chi = rchi
            sp += 1
    node_count[0] = counter


@wp.kernel
def refit_keys(
    num_nodes: int,
    num_keys: int,
    key_lo: wp.array2d(dtype=wp.vec3),  # (K, N) the caller's primitive boxes per key
    key_hi: wp.array2d(dtype=wp.vec3),
    prim: wp.array(dtype=wp.int32),
    node_a: wp.array(dtype=wp.int32),
    node_b: wp.array(dtype=wp.int32),
    out_lo: wp.array2d(dtype=wp.vec3),  # (M, K) node boxes per key
    out_hi: wp.array2d(dtype=wp.vec3),
):
    """Per-key node bounds, bottom-up, one thread. Children come after their parent in the pre-order numbering,
    so walking the nodes from last to first sees every child before its parent."""
    for r in range(num_nodes):
        i = num_nodes - 1 - r
        a = node_a[i]
        b = node_b[i]
        if a < 0:
            first = -(a + 1)
            for k in range(num_keys):
                lo = wp.vec3(BIG)
                hi = wp.vec3(-BIG)
                for s in range(first, first + b):
                    q = prim[s]
                    lo = wp.min(lo, key_lo[k, q])
                    hi = wp.max(hi, key_hi[k, q])
                out_lo[i, k] = lo
                out_hi[i, k] = hi
        else:
            for k in range(num_keys):
                out_lo[i, k] = wp.min(out_lo[a, k], out_lo[b, k])
                out_hi[i, k] = wp.max(out_hi[a, k], out_hi[b, k])


@wp.kernel
def scene_bounds(
    key_lo: wp.array(dtype=wp.vec3),  # (K * N,) the caller's boxes, keys concatenated
    key_hi: wp.array(dtype=wp.vec3),
    out: wp.array(dtype=wp.vec3),  # (2,) lower and upper corner of everything
):
    """Bounds of all boxes at all keys, one thread (NumPy's strided min over axis 0 is ~10x slower)."""
    lo = wp.vec3(BIG)
    hi = wp.vec3(-BIG)
    for i in range(key_lo.shape[0]):
        lo = wp.min(lo, key_lo[i])
        hi = wp.max(hi, key_hi[i])
    out[0] = lo
    out[1] = hi


@wp.kernel
def normalise_boxes(
    num_keys: int,
    key_lo: wp.array2d(dtype=wp.vec3),  # (K, N)
    key_hi: wp.array2d(dtype=wp.vec3),
    center: wp.vec3d,  # normalisation: (x - center) * inv_half, in float64 so huge coordinates cannot overflow
    inv_half: wp.float64,
    out_lo: wp.array(dtype=wp.vec3),  # (N * K,) normalised boxes, primitive i key k at i * K + k
    out_hi: wp.array(dtype=wp.vec3),
    cen: wp.array(dtype=wp.vec3),  # (N,) key-average centroid, normalised (written for K > 1 only)
    prim: wp.array(dtype=wp.int32),  # (N,) set to 0..N-1
    centroid_bounds: wp.array(dtype=wp.vec3),  # (2,) output: bounds of cen
):
    """Every primitive's boxes moved and scaled so that the scene spans about [-1, 1]^3, and the average of its
    key centroids, one thread."""
    scale = wp.vec3d(inv_half, inv_half, inv_half)
    clo = wp.vec3(BIG)
    chi = wp.vec3(-BIG)
    for i in range(key_lo.shape[1]):
        csum = wp.vec3(0.0)
        for k in range(num_keys):
            nlo = wp.vec3(wp.cw_mul(wp.vec3d(key_lo[k, i]) - center, scale))
            nhi = wp.vec3(wp.cw_mul(wp.vec3d(key_hi[k, i]) - center, scale))
            out_lo[i * num_keys + k] = nlo
            out_hi[i * num_keys + k] = nhi
            csum += (nlo + nhi) * 0.5
        c = csum / float(num_keys)
        if num_keys > 1:  # one key: slot_centroid computes it from the box
            cen[i] = c
        prim[i] = i
        clo = wp.min(clo, c)
        chi = wp.max(chi, c)
    centroid_bounds[0] = clo
    centroid_bounds[1] = chi
