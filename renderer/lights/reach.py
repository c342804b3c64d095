"""Which UsdLux lights a ray may reach: a four-wide tree over the area lights, and the lists of the others.

UsdLux area lights (rect, disk, sphere, cylinder) are not in the scene's hierarchy: a ray scattered by a surface
tests them on its own, so that mirrors and glass show them and multiple importance sampling can weight the two
ways of finding them (``sample.area_light_hit``). Testing every light at every bounce, and every light again for a
ray that leaves the scene, would make a Cornell box lit by 1024 small rect lights render 8-9x slower than by one
(``bench/many_lights.py``), 85 % of it in those loops (``bench/kernel_profile.py``).

With ``TREE_MIN`` area lights or more, the still ones get a tree of their own: the top level's four-wide nodes
(``accel.wide``) over each light's world box, walked to the surface the ray hit, so a bounce tests the lights
whose boxes it enters. Lights that move within the shutter are tested one by one (``loose``): their boxes would
have to bound a sweep, and they are rare. Fewer area lights are all ``loose``, tested one by one as before. The
infinite lights (distant, dome) are listed in ``infinite``, and the area lights camera rays see in ``seen`` (most
scenes have none: then a camera ray tests no light at all; ``sample.first_seen_light``). The lists are in light
order, the order the old loops added their light in; a tree walk adds them in its own order, which changes a
pixel's last bits only where one ray reaches two lights (tested).

Boxes are grown by ``PAD`` of their size and position: the kernels intersect the lights in float32, from frames
computed in float64, so a box exactly on a light's edge could miss a ray the light itself takes.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.accel.build import build_bvh
from renderer.accel.wide import WideBoxes, box_records, collapse
from renderer.motion.transform import matrices_at
from renderer.scene.model import LIGHT_CYLINDER, LIGHT_DISK, LIGHT_DISTANT, LIGHT_DOME, LIGHT_RECT, LIGHT_SPHERE
from renderer.kernels.struct_refs import by_reference

TREE_MIN = 8  # area lights from which the still ones are walked in a tree (fewer: one by one is as fast)
PAD = 1.0e-4  # relative growth of each light's box
AREA_KINDS = (LIGHT_RECT, LIGHT_DISK, LIGHT_SPHERE, LIGHT_CYLINDER)


@by_reference
@wp.struct
class Reach:
    tree: int  # 1: the still area lights are walked in the tree below, the others in ``loose``
    box: wp.array(dtype=WideBoxes)  # the tree's nodes (one time key), ``accel.wide`` layout
    child: wp.array(dtype=wp.vec4i)
    light: wp.array(dtype=wp.int32)  # leaf slot -> light
    n_loose: int
    loose: wp.array(dtype=wp.int32)  # area lights tested one by one, in light order: the moving ones (and any
    #                                  without a finite box), or all
    n_infinite: int
    infinite: wp.array(dtype=wp.int32)  # distant and dome lights, in light order
    n_seen: int  # 0 in most scenes: then camera rays test no light
    seen: wp.array(dtype=wp.int32)  # area lights camera rays see (``usd.lights.seen_by_camera``), in light order


def world_boxes(kinds, sizes, matrices) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (N, 3): the world boxes of lights (``table.Lights.size``) under their 4x4 column-vector
    matrices, as ``sample``'s frames place them, grown by PAD. A rect is its four corners; a disk and a sphere are
    a ball of radius r |M x| about the centre (the kernels make them round whatever the matrix's scales); a
    cylinder is its axis, M x times its length, grown by its radius r |M y| every way. One NumPy pass for all."""
    kinds = np.asarray(kinds).reshape(-1)
    sizes = np.asarray(sizes, np.float64).reshape(-1, 4)
    m = np.asarray(matrices, np.float64).reshape(-1, 4, 4)
    c, ax, ay = m[:, :3, 3], m[:, :3, 0], m[:, :3, 1]
    w, h, r = sizes[:, 0:1], sizes[:, 1:2], np.abs(sizes[:, 2:3])
    # a ball (disk, sphere) by default
    half = r * np.linalg.norm(ax, axis=1, keepdims=True) * np.ones((1, 3))
    rect = kinds == LIGHT_RECT  # the four corners' spread about the centre
    half[rect] = (np.abs(0.5 * w * ax) + np.abs(0.5 * h * ay))[rect]
    cyl = kinds == LIGHT_CYLINDER  # size: (length, _, radius)
    half[cyl] = (np.abs(0.5 * w * ax) + r * np.linalg.norm(ay, axis=1, keepdims=True))[cyl]
    lo, hi = c - half, c + half
    grow = PAD * (np.abs(hi - lo).max(1, keepdims=True) + np.abs(c).max(1, keepdims=True)) + 1e-30
    return lo - grow, hi + grow


def upload_reach(kinds, sizes, transforms, matrices, device: str, tree_min: int | None = None,
                 seen=None) -> Reach:
    """The lists and the tree for lights of ``kinds`` (``table.Lights.kind`` order), their ``sizes``,
    MotionTransforms and matrices at the shutter's start (``table.Lights.xf_still``); a tree from ``tree_min`` area
    lights (default ``TREE_MIN``). ``seen``: per light, do camera rays see it (area lights only; None: none)."""
    tree_min = TREE_MIN if tree_min is None else tree_min
    kinds = np.asarray([int(k) for k in kinds], np.int32)
    area = np.flatnonzero(np.isin(kinds, AREA_KINDS))
    infinite = np.flatnonzero(np.isin(kinds, (LIGHT_DISTANT, LIGHT_DOME)))
    still = np.array([i for i in area if len(transforms[i].times) == 1], np.int64)
    lo, hi = world_boxes(kinds[still], np.asarray(sizes, np.float64).reshape(-1, 4)[still],
                         np.asarray(matrices, np.float64).reshape(-1, 4, 4)[still])
    # a light whose box is not finite (a degenerate transform) is tested in turn, never lost
    ok = (np.abs(lo) < 1e37).all(1) & (np.abs(hi) < 1e37).all(1)  # also False for NaN
    still, lo, hi = still[ok], lo[ok], hi[ok]
    r = Reach()

    def ints(a):
        return wp.array(np.array(a if len(a) else [0], np.int32), dtype=wp.int32, device=device)

    r.n_infinite = len(infinite)
    r.infinite = ints(infinite)
    seen_area = [int(i) for i in area if seen is not None and seen[i]]
    r.n_seen = len(seen_area)
    r.seen = ints(seen_area)
    r.tree = int(len(area) >= tree_min and len(still) > 0)
    box = np.full((6, 4), 3.0e38, np.float32)
    child = np.zeros((1, 4), np.int32)
    light = [0]
    loose = area  # without a tree, every area light in turn
    if r.tree:
        wide = collapse(build_bvh(lo.astype(np.float32), hi.astype(np.float32), max_leaf=1, device=device),
                        device)
        box, child, light = wide.box, wide.child, still.astype(np.int32)[wide.prim_order]
        loose = np.setdiff1d(area, still)  # sorted: light order
    r.box = box_records(box, device)
    r.child = wp.array(np.asarray(child, np.int32), dtype=wp.vec4i, device=device)
    r.light = ints(light)
    r.n_loose = len(loose)
    r.loose = ints(loose)
    return r
