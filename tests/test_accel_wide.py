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
    assert np.all(np.diff(od, axis=1) <= 0)
    for i in range(200):  # the same pairs, reordered
        assert sorted(zip(od[i], oc[i])) == sorted(zip(d[i], c[i]))


def test_merging_is_bounded_by_the_leaf_reference():
    lo, hi = random_boxes(50, 1)
    with pytest.raises(ValueError):
        wide.collapse(build_bvh(lo, hi), merge_leaf=16)
