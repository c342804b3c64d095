"""The four-wide bottom level: a collapse that keeps every primitive and box, and a four-box slab test that
agrees with the binary one."""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from renderer.accel import wide
from renderer.accel.build import build_bvh
from renderer.accel.intersect import safe_inverse


def random_boxes(n, keys, seed=0):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-10, 10, (1, n, 3)) + rng.normal(0, 0.5, (keys, n, 3))  # a little motion between keys
    h = rng.uniform(0.01, 0.5, (keys, n, 3))
    return (c - h).astype(np.float32), (c + h).astype(np.float32)


def walk(w: wide.WideBvh):
    """Every node reached from the root, and the leaves as (first, count)."""
    seen, leaves, todo = [], [], [0]
    while todo:
        n = todo.pop()
        seen.append(n)
        for ref in w.child[n]:
            if ref > 0:
                todo.append(int(ref))
            elif ref < 0:
                v = -(int(ref) + 1)
                leaves.append((v >> 4, v & 15))
    return seen, leaves


@pytest.mark.parametrize("n,keys,merge", [(1, 1, 0), (5, 1, 0), (3000, 1, 0), (2000, 3, 0), (5, 1, 6),
                                          (3000, 1, 6), (2000, 3, 15)])
def test_the_collapse_keeps_every_primitive_once_and_every_box(n, keys, merge):
    lo, hi = random_boxes(n, keys)
    binary = build_bvh(lo, hi, max_leaf=4 if merge else 8, c_trav=2.0 if merge else 4.0)
    w = wide.collapse(binary, merge_leaf=merge)
    nodes, leaves = walk(w)
    assert sorted(nodes) == list(range(w.num_nodes))  # every node reached exactly once
    prims = np.concatenate([binary.prim_order[f:f + c] for f, c in leaves])
    assert sorted(prims) == list(range(n))  # every primitive in exactly one leaf
    assert max(c for _, c in leaves) <= max(8 if not merge else 4, merge)
    if merge and n >= 100:  # merging makes fewer, fuller nodes than the plain collapse of the same tree
        plain = wide.collapse(binary)
        assert w.num_nodes < plain.num_nodes and max(c for _, c in leaves) > 4
    inner = int((binary.node_a >= 0).sum())
    assert w.num_nodes <= max(1, inner)
    if n >= 100:  # wide nodes are mostly full: only leaves stop a node from opening children
        assert (w.child != 0).sum(1).mean() > 2.5
    box = w.box.reshape(w.num_nodes, keys, 6, 4)
    for node in range(w.num_nodes):
        for j, ref in enumerate(w.child[node]):
            if ref == 0:
                continue
            # the child box at every key contains the boxes of every primitive below it
            below = []
            todo = [int(ref)]
            while todo:
                r = todo.pop()
                if r < 0:
                    v = -(r + 1)
                    below.extend(binary.prim_order[(v >> 4):(v >> 4) + (v & 15)])
                else:
                    todo.extend(int(x) for x in w.child[r] if x != 0)
            below = np.array(below)
            for k in range(keys):
                assert np.all(box[node, k, 0:3, j] <= lo[k, below].min(0) + 1e-6)
                assert np.all(box[node, k, 3:6, j] >= hi[k, below].max(0) - 1e-6)


def test_an_empty_mesh_has_one_node_that_nothing_hits():
    w = wide.collapse(build_bvh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)))
    assert w.num_nodes == 1 and w.prim_order.size == 0


@wp.func
def box_entry(lo: wp.vec3, hi: wp.vec3, ro: wp.vec3, inv_d: wp.vec3, tmax: float):
    """The binary walk's slab test (before the four-wide one): entry distance into [lo, hi], or 3.4e38."""
    t0 = wp.cw_mul(lo - ro, inv_d)
    t1 = wp.cw_mul(hi - ro, inv_d)
    tn = wp.min(t0, t1)
    tf = wp.max(t0, t1)
    tnear = wp.max(wp.max(tn[0], tn[1]), wp.max(tn[2], 0.0))
    tfar = wp.min(wp.min(tf[0], tf[1]), wp.min(tf[2], tmax))
    if tnear <= tfar * 1.00000024:  # robust for flat boxes (Ize 2013: 2 ulp slack)
        return tnear
    return float(3.4e38)



@wp.kernel
def _entries_kernel(box: wp.array(dtype=wp.vec4), rec: wp.array(dtype=wide.WideBoxes),
                    child: wp.array(dtype=wp.vec4i), nodes: int,
                    ro: wp.array(dtype=wp.vec3), rd: wp.array(dtype=wp.vec3), tmax: float,
                    wide_out: wp.array(dtype=wp.vec4), binary_out: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    node = i % nodes
    r = i // nodes
    inv = safe_inverse(rd[r])
    base = node * 6
    wide_out[i] = wide.entries(rec, node, child[node], 0, 0, 0.0, ro[r], inv, tmax)
    out = wp.vec4(0.0)
    for j in range(4):
        lo = wp.vec3(box[base + 0][j], box[base + 1][j], box[base + 2][j])
        hi = wp.vec3(box[base + 3][j], box[base + 4][j], box[base + 5][j])
        out[j] = wp.where(child[node][j] != 0, box_entry(lo, hi, ro[r], inv, tmax), 3.4e38)
    binary_out[i] = out


@pytest.mark.parametrize("scale", [1.0, 0.25, 40.0])  # object-space rays of scaled instances are not unit
def test_the_four_box_slab_test_is_the_binary_one(scale):
    lo, hi = random_boxes(400, 1, seed=2)
    w = wide.collapse(build_bvh(lo, hi, max_leaf=8, c_trav=4.0))
    rng = np.random.default_rng(5)
    ro = rng.uniform(-12, 12, (300, 3)).astype(np.float32)
    rd = rng.normal(size=(300, 3))
    rd = (scale * rd / np.linalg.norm(rd, axis=1, keepdims=True)).astype(np.float32)
    rd[:10, 1:] = 0.0  # axis-parallel rays
    n = w.num_nodes * len(ro)
    got, want = wp.zeros(n, dtype=wp.vec4), wp.zeros(n, dtype=wp.vec4)
    wp.launch(_entries_kernel, dim=n, inputs=[wp.array(w.box, dtype=wp.vec4), wide.box_records(w.box),
                                              wp.array(w.child, dtype=wp.vec4i),
                                              w.num_nodes, wp.array(ro, dtype=wp.vec3), wp.array(rd, dtype=wp.vec3),
                                              3.4e38, got, want])
    got, want = got.numpy(), want.numpy()
    np.testing.assert_array_equal(got >= 3.4e38, want >= 3.4e38)  # the same children hit
    hit = want < 3.4e38
    assert hit.mean() > 0.01
    np.testing.assert_allclose(got[hit], want[hit], rtol=1e-6, atol=1e-6)
    unused = w.child.reshape(-1) == 0  # (node, slot), as the rows of got for one ray
    assert unused.any() and np.all(got.reshape(len(ro), -1)[:, unused] >= 3.4e38)  # never entered


@wp.kernel
def _native_and_reference_kernel(lo: wp.array(dtype=wp.vec4), hi: wp.array(dtype=wp.vec4),
                                 c: wp.array(dtype=wp.vec4i), ro: wp.array(dtype=wp.vec3),
                                 inv: wp.array(dtype=wp.vec3), tmax: wp.array(dtype=wp.float32),
                                 native: wp.array(dtype=wp.vec4), reference: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    native[i] = wide.box_entries(lo[3 * i], lo[3 * i + 1], lo[3 * i + 2], hi[3 * i], hi[3 * i + 1], hi[3 * i + 2],
                                 c[i], ro[i], inv[i], tmax[i])
    reference[i] = wide.box_entries_reference(lo[3 * i], lo[3 * i + 1], lo[3 * i + 2], hi[3 * i], hi[3 * i + 1],
                                              hi[3 * i + 2], c[i], ro[i], inv[i], tmax[i])


def test_the_native_slab_test_gives_the_bits_of_the_warp_one():
    """``box_entries`` (native vector code) against ``box_entries_reference`` (Warp's scalar arithmetic), bit for
    bit: flat boxes, rays starting inside and on faces, axis-parallel rays (safe_inverse's 1e30), unused slots,
    negative zeros, tmax at 0, short and unbounded; NaN origins give numbers."""
    rng = np.random.default_rng(11)
    n = 60000
    a = rng.uniform(-1, 1, (n, 3, 4)).astype(np.float32)
    b = rng.uniform(-1, 1, (n, 3, 4)).astype(np.float32)
    b = np.where(rng.random((n, 3, 4)) < 0.2, a, b)  # flat on an axis
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    ro = rng.uniform(-2, 2, (n, 3)).astype(np.float32)
    on_face = rng.random(n) < 0.1
    ro[on_face] = lo[on_face, :, 0]  # the origin on a corner of lane 0's box
    ro[rng.random((n, 3)) < 0.005] = np.nan  # a broken path's ray
    d = rng.normal(size=(n, 3))
    d[rng.random((n, 3)) < 0.15] = 0.0
    d[rng.random((n, 3)) < 0.05] = -0.0
    scale = rng.choice([1e-3, 1.0, 1e3], size=(n, 1))
    inv = np.ones((n, 3), np.float32)
    for i in range(0, n, 5000):  # the walks' own reciprocal
        inv[i:i + 5000] = _inverse((d * scale)[i:i + 5000].astype(np.float32))
    c = rng.integers(-3, 3, (n, 4)).astype(np.int32)  # 0: an unused slot
    tmax = rng.choice(np.array([0.0, 0.5, 3.0, 3.4e38], np.float32), size=n)
    native, reference = wp.zeros(n, dtype=wp.vec4), wp.zeros(n, dtype=wp.vec4)
    wp.launch(_native_and_reference_kernel, dim=n,
              inputs=[wp.array(lo.reshape(-1, 4), dtype=wp.vec4),
                      wp.array(hi.reshape(-1, 4), dtype=wp.vec4), wp.array(c, dtype=wp.vec4i),
                      wp.array(ro, dtype=wp.vec3), wp.array(inv, dtype=wp.vec3), wp.array(tmax, dtype=wp.float32),
                      native, reference])
    got, want = native.numpy(), reference.numpy()
    entered = want < 3.4e38
    assert 0.01 < entered.mean() < 0.95 and (got[c == 0] >= 3.4e38).all()  # thousands of lanes entered
    numbers = np.isfinite(ro).all(1)
    assert (~numbers).sum() > 500 and not np.isnan(got).any()  # broken rays: numbers still (may differ)
    np.testing.assert_array_equal(got[numbers].view(np.uint32), want[numbers].view(np.uint32))


@wp.kernel
def _one_box_kernel(lo: wp.array(dtype=wp.vec3), hi: wp.array(dtype=wp.vec3), ro: wp.array(dtype=wp.vec3),
                    inv: wp.array(dtype=wp.vec3), tmax: wp.array(dtype=wp.float32), native: wp.array(dtype=int),
                    reference: wp.array(dtype=int)):
    i = wp.tid()
    native[i] = int(wide.box_entered(lo[i], hi[i], ro[i], inv[i], tmax[i]))
    reference[i] = int(wide.box_entered_reference(lo[i], hi[i], ro[i], inv[i], tmax[i]))


def test_the_native_one_box_test_answers_as_the_warp_one():
    """``box_entered`` (native vector code, the root test) against ``box_entered_reference`` on every kind of ray
    of numbers: flat boxes, origins inside, on corners and on faces, axis-parallel rays (safe_inverse's 1e30),
    negative zeros, tmax at 0, at a face and unbounded."""
    rng = np.random.default_rng(12)
    n = 60000
    a = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    b = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    b = np.where(rng.random((n, 3)) < 0.2, a, b)  # flat on an axis
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    ro = rng.uniform(-2, 2, (n, 3)).astype(np.float32)
    corner = rng.random(n) < 0.1
    ro[corner] = lo[corner]
    face = rng.random(n) < 0.1
    ro[face, 0] = hi[face, 0]
    d = rng.normal(size=(n, 3))
    d[rng.random((n, 3)) < 0.15] = 0.0
    d[rng.random((n, 3)) < 0.05] = -0.0
    grazing = rng.random(n) < 0.2  # aimed at a corner from outside: entered and left at one distance, rounded
    d[grazing] = hi[grazing] - (ro[grazing] + 3.0)
    ro[grazing] += 3.0
    inv = np.ones((n, 3), np.float32)
    for i in range(0, n, 5000):
        inv[i:i + 5000] = _inverse(d[i:i + 5000].astype(np.float32))
    tmax = rng.choice(np.array([0.0, 0.5, 3.0, 3.4e38, np.inf], np.float32), size=n)
    exact = rng.random(n) < 0.1  # tmax where the ray leaves the box's x slab: on the slack's edge
    with np.errstate(all="ignore"):
        tx = np.maximum((lo[:, 0] - ro[:, 0]) * inv[:, 0], (hi[:, 0] - ro[:, 0]) * inv[:, 0])
    tmax[exact & np.isfinite(tx) & (tx >= 0)] = tx[exact & np.isfinite(tx) & (tx >= 0)]
    native, reference = wp.zeros(n, dtype=int), wp.zeros(n, dtype=int)
    wp.launch(_one_box_kernel, dim=n, inputs=[wp.array(lo, dtype=wp.vec3), wp.array(hi, dtype=wp.vec3),
                                              wp.array(ro, dtype=wp.vec3), wp.array(inv, dtype=wp.vec3),
                                              wp.array(tmax, dtype=wp.float32), native, reference])
    got, want = native.numpy(), reference.numpy()
    assert 0.05 < want.mean() < 0.95  # thousands of rays each way
    np.testing.assert_array_equal(got, want)


@wp.kernel
def _inverse_kernel(d: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = safe_inverse(d[i])


def _inverse(d: np.ndarray) -> np.ndarray:
    out = wp.zeros(len(d), dtype=wp.vec3)
    wp.launch(_inverse_kernel, dim=len(d), inputs=[wp.array(d, dtype=wp.vec3), out])
    return out.numpy()


def test_far_to_near_sorts_four_children():
    @wp.kernel
    def k(d: wp.array(dtype=wp.vec4), c: wp.array(dtype=wp.vec4i), od: wp.array(dtype=wp.vec4),
          oc: wp.array(dtype=wp.vec4i)):
        i = wp.tid()
        x, y = wide.far_to_near(d[i], c[i])
        od[i] = x
        oc[i] = y

    rng = np.random.default_rng(1)
    d = rng.choice([0.5, 1.0, 2.0, 3.4e38, 7.0], size=(200, 4)).astype(np.float32)
    c = np.tile(np.arange(1, 5, dtype=np.int32), (200, 1))
    od, oc = wp.zeros(200, dtype=wp.vec4), wp.zeros(200, dtype=wp.vec4i)
    wp.launch(k, dim=200, inputs=[wp.array(d, dtype=wp.vec4), wp.array(c, dtype=wp.vec4i), od, oc])
    od, oc = od.numpy(), oc.numpy()
    several = (d < 3.4e38).sum(1) >= 2
    assert several.any() and (~several).any()
    assert np.all(np.diff(od[several], axis=1) <= 0)  # sorted when two or more children are entered
    np.testing.assert_array_equal(od[~several], d[~several])  # else as they were: one is pushed, if any
    np.testing.assert_array_equal(oc[~several], c[~several])
    for i in range(200):  # the same pairs, reordered
        assert sorted(zip(od[i], oc[i])) == sorted(zip(d[i], c[i]))


def test_merging_is_bounded_by_the_leaf_reference():
    lo, hi = random_boxes(50, 1)
    with pytest.raises(ValueError):
        wide.collapse(build_bvh(lo, hi), merge_leaf=16)


@wp.kernel
def _root_kernel(root: wp.array(dtype=wp.vec3), rec: wp.array(dtype=wide.WideBoxes),
                 child: wp.array(dtype=wp.vec4i), nodes: int, nkeys: int,
                 ro: wp.array(dtype=wp.vec3), rd: wp.array(dtype=wp.vec3), s: wp.array(dtype=float),
                 tmax: wp.array(dtype=float), root_out: wp.array(dtype=int), child_out: wp.array(dtype=int)):
    r = wp.tid()
    k0 = int(0)
    k1 = int(0)
    u = float(0.0)
    if nkeys > 1:  # as the walks choose their keys (intersect.tlas_keys_at)
        x = s[r] * float(nkeys - 1)
        k0 = wp.min(int(x), nkeys - 2)
        k1 = k0 + 1
        u = x - float(k0)
    inv = safe_inverse(rd[r])
    root_out[r] = int(wide.root_entered(root, k0, ro[r], inv, tmax[r]))
    entered = int(0)
    for node in range(nodes):
        e = wide.entries(rec, node * nkeys, child[node], k0, k1, u, ro[r], inv, tmax[r])
        for j in range(4):
            if e[j] < wide.BIG:
                entered = 1
    child_out[r] = entered


def _blended(lo, hi, s):
    """Each box of (K, N, 3) blended at normalised times s (one per ray): (R, N, 3) lo and hi, in float64."""
    k = lo.shape[0]
    if k == 1:
        return np.broadcast_to(lo[0], (len(s),) + lo.shape[1:]), np.broadcast_to(hi[0], (len(s),) + hi.shape[1:])
    x = s * (k - 1)
    k0 = np.minimum(x.astype(int), k - 2)
    u = (x - k0)[:, None, None]
    return (lo[k0] * (1 - u) + lo[k0 + 1] * u), (hi[k0] * (1 - u) + hi[k0 + 1] * u)


@pytest.mark.parametrize("keys,scale,count", [(1, 1.0, 60), (3, 1.0, 60), (9, 1.0, 60), (3, 1e-3, 60), (3, 1e4, 60),
                                              (1, 1.0, 1), (3, 1.0, 1)])
def test_the_root_box_holds_every_child_at_every_time(keys, scale, count):
    """A ray that enters any box of the top level at its time enters the root box there (the root's slab test
    never drops a hit), while rays that pass by every instance are spared; aimed at points on the instances' blended faces and
    corners, so that many graze them."""
    rng = np.random.default_rng(keys)
    lo, hi = random_boxes(count, keys, seed=keys)
    flat = rng.integers(0, 3, count // 3 + 1)
    hi[:, np.arange(len(flat)), flat] = lo[:, np.arange(len(flat)), flat]  # a third flat on an axis (a ground quad)
    lo, hi = lo * np.float32(scale), hi * np.float32(scale)
    w = wide.collapse(build_bvh(lo, hi, max_leaf=1))
    root = wide.root_boxes(lo, hi)
    assert len(root) == 2 * max(keys - 1, 1)
    for seg in range(max(keys - 1, 1)):  # each segment's box holds every box at both of its keys
        for k in {seg, min(seg + 1, keys - 1)}:
            assert np.all(root[2 * seg] <= lo[k].min(0)) and np.all(root[2 * seg + 1] >= hi[k].max(0))
    n = 6000
    s = rng.uniform(0, 1, n)
    s[:200] = np.linspace(0, 1, 200)  # key times themselves included
    blo, bhi = _blended(lo.astype(np.float64), hi.astype(np.float64), s)
    pick = rng.integers(0, lo.shape[1], n)
    tlo, thi = blo[np.arange(n), pick], bhi[np.arange(n), pick]
    f = rng.uniform(0, 1, (n, 3))
    f[: n // 3] = np.round(f[: n // 3])  # corners
    face = rng.integers(0, 3, n)
    f[np.arange(n // 3, 2 * n // 3), face[n // 3: 2 * n // 3]] = rng.integers(0, 2, n // 3)  # faces
    target = tlo + f * (thi - tlo)
    ro = rng.uniform(-14, 14, (n, 3)) * scale
    rd = target - ro
    rd[-n // 6:] = rng.normal(size=(n // 6, 3))  # random directions: most pass by every box
    axis = rng.integers(0, 3, 300)
    rd[:300] = 0.0
    rd[np.arange(300), axis] = 1.0  # axis-parallel rays through a box face's plane
    ro[:300] = target[:300]
    ro[np.arange(300), axis] -= 20 * scale
    rd /= np.linalg.norm(rd, axis=1, keepdims=True)
    tmax = np.where(rng.uniform(0, 1, n) < 0.2, rng.uniform(0, 20, n) * scale, 3.4e38)
    got_root, got_child = wp.zeros(n, dtype=int), wp.zeros(n, dtype=int)
    wp.launch(_root_kernel, dim=n, inputs=[
        wp.array(root, dtype=wp.vec3), wide.box_records(w.box), wp.array(w.child, dtype=wp.vec4i), w.num_nodes,
        keys, wp.array(ro.astype(np.float32), dtype=wp.vec3), wp.array(rd.astype(np.float32), dtype=wp.vec3),
        wp.array(s.astype(np.float32), dtype=float), wp.array(tmax.astype(np.float32), dtype=float),
        got_root, got_child])
    got_root, got_child = got_root.numpy().astype(bool), got_child.numpy().astype(bool)
    assert got_child.mean() > 0.5  # most rays do enter a box
    assert not np.any(got_child & ~got_root), np.nonzero(got_child & ~got_root)[0][:10]
    assert (~got_root[-n // 6:]).mean() > 0.3  # and the random ones are mostly spared the walk


def test_an_empty_root_is_never_entered():
    """A top level without instances: no ray of unit direction enters its root."""
    root = wide.root_boxes(np.zeros((2, 0, 3), np.float32), np.zeros((2, 0, 3), np.float32))
    rng = np.random.default_rng(3)
    n = 500
    ro = rng.uniform(-1e3, 1e3, (n, 3)).astype(np.float32)
    rd = rng.normal(size=(n, 3))
    rd[:20] = 1.0  # diagonal, toward the far point
    rd[20:40] = np.eye(3)[rng.integers(0, 3, 20)]  # axis-parallel
    rd = (rd / np.linalg.norm(rd, axis=1, keepdims=True)).astype(np.float32)
    lo, hi = random_boxes(1, 2)
    w = wide.collapse(build_bvh(lo, hi, max_leaf=1))
    got_root, got_child = wp.zeros(n, dtype=int), wp.zeros(n, dtype=int)
    wp.launch(_root_kernel, dim=n, inputs=[
        wp.array(root, dtype=wp.vec3), wide.box_records(w.box), wp.array(w.child, dtype=wp.vec4i), w.num_nodes,
        2, wp.array(ro, dtype=wp.vec3), wp.array(rd, dtype=wp.vec3), wp.array(rng.uniform(0, 1, n).astype(np.float32),
                                                                             dtype=float),
        wp.array(np.full(n, 3.4e38, np.float32), dtype=float), got_root, got_child])
    assert not got_root.numpy().any()


@wp.kernel
def _blend_kernel(rec: wp.array(dtype=wide.WideBoxes), child: wp.array(dtype=wp.vec4i), nodes: int, keys: int,
                  ro: wp.array(dtype=wp.vec3), inv: wp.array(dtype=wp.vec3), s: wp.array(dtype=wp.float32),
                  native: wp.array(dtype=wp.vec4), reference: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    node = i % nodes
    x = wp.clamp(s[i], 0.0, 1.0) * float(keys - 1)
    k0 = wp.min(int(x), keys - 2)
    u = x - float(k0)
    native[i] = wide.entries(rec, node * keys, child[node], k0, k0 + 1, u, ro[i], inv[i], 1.0e30)
    reference[i] = wide.entries_reference(rec, node * keys, child[node], k0, k0 + 1, u, ro[i], inv[i], 1.0e30)


@pytest.mark.parametrize("keys", [2, 5])
def test_blended_top_level_boxes_give_the_bits_of_the_warp_blend(keys):
    """``entries`` between two keys (the blend and the slab test in native vector code) against
    ``entries_reference`` (``wp.lerp`` and Warp's slab test), bit for bit, at random shutter times and at the keys."""
    lo, hi = random_boxes(300, keys, seed=4)
    w = wide.collapse(build_bvh(lo, hi, max_leaf=4, c_trav=2.0))
    rng = np.random.default_rng(9)
    n = 40000
    ro = rng.uniform(-12, 12, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d[::17, :2] = 0.0
    s = rng.random(n).astype(np.float32)
    s[::5] = np.round(s[::5] * (keys - 1)) / (keys - 1)  # at a key
    out = [wp.zeros(n, dtype=wp.vec4), wp.zeros(n, dtype=wp.vec4)]
    wp.launch(_blend_kernel, dim=n, inputs=[wide.box_records(w.box), wp.array(w.child, dtype=wp.vec4i), w.num_nodes,
                                            keys, wp.array(ro, dtype=wp.vec3),
                                            wp.array(_inverse(d.astype(np.float32)), dtype=wp.vec3),
                                            wp.array(s, dtype=wp.float32)] + out)
    got, want = out[0].numpy(), out[1].numpy()
    assert 0.001 < (want < 3.4e38).mean() < 0.9
    np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
