"""Instances placed in batches (scenes of 10^4 prims): the importer's deferred transforms, ``matrices_at`` and the
upload's still boxes must equal what the one-at-a-time paths give, bit for bit (images must not change)."""
from __future__ import annotations

import numpy as np
from pxr import Usd, UsdGeom

from renderer.accel.build import build_bvh
from renderer.accel.instance_bounds import instance_key_bounds
from renderer.motion.transform import make_transform, matrices_at, matrix_at, place_boxes
from renderer.usd.importer import load_scene
from renderer.usd.motion import motion_transform


def _random_matrix(rng) -> np.ndarray:
    """A column-vector 4x4 matrix: rotation, non-uniform scale (sometimes mirrored), shear, translation."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    s = np.diag(rng.uniform(0.2, 3.0, 3) * rng.choice([-1.0, 1.0], 3))
    shear = np.eye(3)
    shear[0, 1] = rng.uniform(-0.5, 0.5)
    m = np.eye(4)
    m[:3, :3] = q @ s @ shear
    m[:3, 3] = rng.uniform(-100, 100, 3)
    return m


def test_matrices_at_is_matrix_at_bit_for_bit():
    rng = np.random.default_rng(7)
    xfs = [make_transform([0.0], [_random_matrix(rng)]) for _ in range(300)]
    xfs += [make_transform([0.0, 0.4, 1.0], [_random_matrix(rng) for _ in range(3)]) for _ in range(20)]
    rng.shuffle(xfs)
    for s in (0.0, 0.3, 1.0):
        batch = matrices_at(xfs, s)
        one = np.array([matrix_at(xf, s) for xf in xfs])
        assert np.array_equal(batch, one)
    assert matrices_at([], 0.0).shape == (0, 4, 4)


def test_still_boxes_in_one_batch_equal_instance_key_bounds():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(40, 3)).astype(np.float32)
    tri = rng.integers(0, 40, size=(30, 3))
    v = pts[tri]
    bvh = build_bvh(v.min(1), v.max(1))
    xfs = [make_transform([0.0], [_random_matrix(rng)]) for _ in range(100)]

    class Inst:
        def __init__(self, xf):
            self.transform = xf

    root = np.array([bvh.node_lower[0, 0], bvh.node_upper[0, 0]], np.float64)
    lo, hi = place_boxes(matrices_at(xfs, 0.0), *(np.repeat(root[None, k], len(xfs), 0) for k in (0, 1)))
    corners = np.array([[root[(i >> a) & 1, a] for a in range(3)] for i in range(8)])
    for i, xf in enumerate(xfs):
        m = matrix_at(xf, 0.0)
        w = corners @ m[:3, :3].T + m[:3, 3]  # one box, one matrix, as the upload placed them before batching
        assert np.array_equal(lo[i], w.min(0)) and np.array_equal(hi[i], w.max(0))
        klo, khi = instance_key_bounds(Inst(xf), bvh, np.zeros(1), 3)  # the same box at every key
        assert np.array_equal(klo, np.repeat(lo[i:i + 1], 3, 0)) and np.array_equal(khi, np.repeat(hi[i:i + 1], 3, 0))


def test_importer_places_every_prim_with_its_own_transform(tmp_path):
    """Many prims under transformed parents, some moving: each instance's transform is the one made from its own
    world matrices, whatever order the batches resolve in."""
    rng = np.random.default_rng(11)
    stage = Usd.Stage.CreateNew(str(tmp_path / "many.usda"))
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(2)
    paths = []
    for g in range(4):
        group = UsdGeom.Xform.Define(stage, f"/G{g}")
        group.AddRotateXYZOp().Set(tuple(rng.uniform(-90, 90, 3)))
        for i in range(25):
            kind = (UsdGeom.Sphere, UsdGeom.Cube, UsdGeom.Cylinder)[i % 3]
            prim = kind.Define(stage, f"/G{g}/P{i}")
            op = prim.AddTranslateOp()
            if i % 7 == 0:  # moving
                op.Set(tuple(rng.uniform(-5, 5, 3)), 1)
                op.Set(tuple(rng.uniform(-5, 5, 3)), 2)
            else:
                op.Set(tuple(rng.uniform(-5, 5, 3)))
            prim.AddScaleOp().Set(tuple(rng.uniform(0.5, 2.0, 3)))
            paths.append(f"/G{g}/P{i}")
    stage.GetRootLayer().Save()
    scene = load_scene(tmp_path / "many.usda", frame=1.0, shutter=(0.0, 0.5))
    by_name = {inst.name: inst for inst in scene.instances}
    assert sorted(by_name) == sorted(paths)
    for path in paths:
        xf = by_name[path].transform
        prim = stage.GetPrimAtPath(path)
        times = np.array([1.0, 1.5]) if int(path.rsplit("P", 1)[1]) % 7 == 0 else np.array([1.0])
        rows = np.array([np.array(UsdGeom.XformCache(Usd.TimeCode(t)).GetLocalToWorldTransform(prim))
                         for t in times])
        want = motion_transform((times - 1.0) / 0.5, rows)
        assert xf.num_keys == want.num_keys, path
        for a, b in ((xf.times, want.times), (xf.translation, want.translation), (xf.rotation, want.rotation),
                     (xf.scale, want.scale)):
            assert np.array_equal(a, b), path


def test_placed_extent_is_the_bounds_of_every_placed_box_bit_for_bit():
    """``placed_extent`` places only the boxes that can hold an extreme; its bounds must equal those of all the
    placed boxes exactly: random affine maps, many boxes tied at the extremes, huge coordinates, a NaN box."""
    from renderer.motion.transform import placed_extent

    rng = np.random.default_rng(21)
    for case in range(6):
        n = 3000
        ms = np.array([_random_matrix(rng) for _ in range(n)])
        lo = rng.uniform(-2, 0, (n, 3))
        hi = lo + rng.uniform(0, 3, (n, 3))
        if case == 1:  # every box the same and in the same place: all tie
            ms[:] = ms[0]
            lo[:], hi[:] = lo[0], hi[0]
        if case == 2:  # a few distinct places, many boxes on each
            ms = ms[rng.integers(0, 5, n)]
        if case == 3:
            ms[:, :3, 3] *= 1e7
        if case == 4:
            lo[17, 1] = np.nan
        if case == 5:
            n = 1
            ms, lo, hi = ms[:1], lo[:1], hi[:1]
        wlo, whi = place_boxes(ms, lo, hi)
        want = wlo.min(0), whi.max(0)
        got = placed_extent(ms, lo, hi)
        for g, w in zip(got, want):
            assert np.array_equal(g, w, equal_nan=True), case
