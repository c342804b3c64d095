"""Bottom-level nodes in 8 bits per coordinate (``accel.quantize``): every decoded box holds the float box it
encodes, exactly as the walk decodes it, and is at most two steps looser per side."""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from renderer.motion.shutter import Shutter
from renderer.accel.build import build_bvh
from renderer.accel.quantize import LIMIT, STEPS, QNode, decode, q_entries, quantize
from renderer.accel.wide import WideBoxes, WideBvh, box_records, collapse, entries


def _random_tree(rng, nodes: int, keys: int, spread: tuple[int, int] = (-3, 3)):
    """Four-wide trees of random boxes: centres and sizes over many orders of magnitude, some slots unused, some
    boxes flat along an axis."""
    centre = rng.normal(size=(nodes, keys, 1, 3, 4)) * 10.0 ** rng.integers(*spread, size=(nodes, keys, 1, 3, 4))
    size = rng.random((nodes, keys, 1, 3, 4)) * 10.0 ** rng.integers(*spread, size=(nodes, keys, 1, 3, 4))
    size[rng.random(size.shape) < 0.1] = 0.0
    box = np.concatenate([centre, centre + size], 2).astype(np.float32).reshape(-1, 4)
    child = rng.integers(-9, 9, size=(nodes, 4)).astype(np.int32)
    child[:, 0] = np.where(child[:, 0] == 0, 1, child[:, 0])  # every node uses at least one slot
    return WideBvh(box=box, child=child, prim_order=np.zeros(1, np.int32), num_keys=keys)


def _check(tree: WideBvh):
    q = quantize(tree)
    k = tree.num_keys
    assert q.shape == (tree.num_nodes * k,) and q.dtype.itemsize == 64
    lo, hi = decode(q)
    b = tree.box.reshape(-1, 6, 4)
    used = np.repeat(tree.child != 0, k, 0)[:, None, :]
    assert np.all(~used | (lo <= b[:, :3])) and np.all(~used | (hi >= b[:, 3:])), "a decoded box clips its box"
    # the decode is exact: float64 arithmetic on the same records gives the same values
    o64 = q["origin"].astype(np.float64)[:, :, None]
    s64 = q["scale"].astype(np.float64)[:, :, None]
    for name, got in (("l", lo), ("h", hi)):
        want = np.stack([q[name + "x"], q[name + "y"], q[name + "z"]], 1).astype(np.float64) * s64 + o64
        np.testing.assert_array_equal(got.astype(np.float64), want)
    # scales are powers of two; each side at most two steps loose, a step at most twice what the node needs
    s = q["scale"].astype(np.float64)
    assert np.all(np.frexp(s)[0] == 0.5)
    plo = np.where(used, b[:, :3], np.inf).min(-1).astype(np.float64)
    phi = np.where(used, b[:, 3:], -np.inf).max(-1).astype(np.float64)
    need = np.maximum((phi - plo) / STEPS, np.maximum(np.abs(plo), np.abs(phi)) / LIMIT)
    assert np.all(s <= 2 * np.maximum(need, 2.0 ** -120))
    slack = np.maximum(b[:, :3] - lo, hi - b[:, 3:])
    assert np.all(~used | (slack <= 2 * s[:, :, None]))
    # unused slots hold zeros and the child references are copied into every key's record
    for name in ("lx", "ly", "lz", "hx", "hy", "hz"):
        assert np.all(q[name][~used[:, 0]] == 0)
    np.testing.assert_array_equal(q["child"], np.repeat(tree.child, k, 0))
    return q


@pytest.mark.parametrize("keys", [1, 3])
def test_decoded_boxes_hold_their_boxes(keys):
    _check(_random_tree(np.random.default_rng(keys), 4000, keys))


def test_extreme_magnitudes():
    """Tiny boxes far from the origin (the step follows the coordinates' magnitude, not the box) and huge ones."""
    _check(_random_tree(np.random.default_rng(5), 4000, 1, spread=(-30, 30)))
    rng = np.random.default_rng(6)
    t = _random_tree(rng, 64, 1)
    b = t.box.reshape(-1, 6, 4)
    b[:32, :3] = 1.0e6 + rng.random((32, 3, 4)).astype(np.float32)  # 1 ulp boxes at a million
    b[:32, 3:] = np.nextafter(b[:32, :3], np.float32(np.inf))
    b[32:, :3] = -3.0e37
    b[32:, 3:] = 3.0e37
    _check(t)


def test_nan_and_overflow_are_conservative():
    """A NaN side decodes to the node's whole extent on that side, never a box that could miss."""
    t = _random_tree(np.random.default_rng(7), 16, 1)
    b = t.box.reshape(-1, 6, 4)
    b[0, 0, 1] = np.nan  # node 0, child 1: lower x unknown
    b[1, 5, 0] = np.nan
    t.child[0, 1] = t.child[1, 0] = 3
    q = quantize(t)
    lo, hi = decode(q)
    assert lo[0, 0, 1] <= -2.0 ** 126 and hi[1, 2, 0] >= 2.0 ** 126


def test_empty_mesh_root():
    """The single leaf of an empty mesh (an inverted box) encodes without error, as a point box."""
    tree = collapse(build_bvh(np.zeros((1, 0, 3), np.float32), np.zeros((1, 0, 3), np.float32)))
    q = quantize(tree)
    lo, hi = decode(q)
    assert np.all(np.isfinite(lo)) and np.all(lo <= hi)


@wp.kernel
def _both_entries(q: wp.array(dtype=QNode), box: wp.array(dtype=WideBoxes), keys: int, u: float,
                  ro: wp.array(dtype=wp.vec3), rd: wp.array(dtype=wp.vec3), out_q: wp.array(dtype=wp.vec4),
                  out_f: wp.array(dtype=wp.vec4), child: wp.array(dtype=wp.vec4i)):
    i = wp.tid()
    node = i % (q.shape[0] // keys)
    inv = wp.vec3(1.0 / rd[i][0], 1.0 / rd[i][1], 1.0 / rd[i][2])
    k1 = wp.min(1, keys - 1)
    d, c = q_entries(q, node * keys, 0, k1, u, ro[i], inv, 1.0e30)
    out_q[i] = d
    child[i] = c
    out_f[i] = entries(box, node * keys, c, 0, k1, u, ro[i], inv, 1.0e30)


@pytest.mark.parametrize("keys", [1, 2])
def test_walk_decodes_as_numpy(keys):
    """``q_entries`` tests exactly the boxes ``decode`` gives: the same entry distances as the float walk's
    ``entries`` on the decoded boxes (bit for bit), blended between keys too."""
    rng = np.random.default_rng(11 + keys)
    tree = _random_tree(rng, 500, keys, spread=(0, 1))
    q = quantize(tree)
    lo, hi = decode(q)
    fbox = np.concatenate([lo, hi], 1).reshape(-1, 4)  # (W * K * 6, 4) in the float layout
    n = 20000
    ro = rng.normal(size=(n, 3)).astype(np.float32) * 30
    rd = rng.normal(size=(n, 3)).astype(np.float32)
    outs = [wp.zeros(n, dtype=wp.vec4) for _ in range(2)]
    child = wp.zeros(n, dtype=wp.vec4i)
    wp.launch(_both_entries, dim=n, inputs=[wp.array(q, dtype=QNode), box_records(fbox), keys, 0.375,
                                            wp.array(ro, dtype=wp.vec3), wp.array(rd, dtype=wp.vec3), outs[0],
                                            outs[1], child])
    dq, df = outs[0].numpy(), outs[1].numpy()
    np.testing.assert_array_equal(dq, df)
    np.testing.assert_array_equal(child.numpy(), tree.child[np.arange(n) % tree.num_nodes])
    assert (dq < 1e30).any() and (dq > 1e30).any()  # rays both enter and miss boxes


def test_uploaded_records_are_cache_lines():
    """The uploaded records start on a 64-byte boundary, so each is one cache line (a wrapped NumPy buffer is
    only 16-byte aligned: every record would straddle two)."""
    from renderer.accel.upload import upload_geometry
    from renderer.motion.transform import MotionTransform
    from renderer.scene.model import Camera, Instance, Material, Mesh, Scene

    rng = np.random.default_rng(3)
    pts = rng.random((1, 3000, 3)).astype(np.float32)
    tris = rng.integers(0, 3000, size=(5000, 3)).astype(np.int32)
    mesh = Mesh(name="/m", point_times=np.zeros(1, np.float32), points=pts, triangles=tris,
                material_ids=np.zeros(5000, np.int32))
    still = MotionTransform.static(np.eye(4))
    scene = Scene([mesh], [Instance(0, still)], [Material("m")], [], Camera("cam", still), Shutter(0, 0, 1))
    g, _ = upload_geometry(scene)
    assert g.blas_node.ptr % 64 == 0 and g.blas_node.strides == (64,)
