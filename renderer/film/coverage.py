"""Per-pixel coverage of ids (Cryptomatte): which object or material each sample saw first, filtered as the beauty.

Each sample that saw a surface carries an id (its object, or its material: ``sample_ids_kernel``). A pixel's
coverage of an id is the filter-weighted sum of its samples with that id over the sum of all its samples' weights,
so with the beauty's filter, over the same samples (motion blur and depth of field included); the coverages of a
pixel sum to its alpha.

The sums follow ``borders``' scheme so that the frame's bits do not depend on the tiling: one small table of
(id, weight) slots per target pixel and source direction (``SLOTS`` ids, in the order the samples first brought
them; an id beyond those in one direction of one pixel is dropped), filled in sample order by the one tile that owns the
source pixel. A pixel's tables are merged (``id_tables.merge``) in direction order, weights summed per id in float64 and
the entries sorted by weight (then id), and the first ``KEEP`` kept (``id_tables``).
"""
from __future__ import annotations

import warp as wp

from renderer.film.film import SampleBuffer

wp.set_module_options({"enable_backward": False})

SLOTS = 8  # ids per (target pixel, direction) table
KIND_OBJECT = 0
KIND_MATERIAL = 1


@wp.kernel
def sample_ids_kernel(buf: SampleBuffer, tri_material: wp.array(dtype=wp.int32), kind: int,
                      out: wp.array(dtype=wp.int32)):
    """Each sample's id: the instance (a render with coverage keeps every instance its own: ``render.prepare``
    does not merge still ones) or the material of the surface it saw first; -1 where it saw none."""
    i = wp.tid()
    inst = buf.hit_inst[i]
    found = int(-1)
    if inst >= 0:
        found = inst
        if kind == KIND_MATERIAL:
            found = tri_material[buf.hit_tri[i]]
    out[i] = found


@wp.kernel
def coverage_gather_kernel(
    buf: SampleBuffer,
    sample_id: wp.array(dtype=wp.int32),
    ids: wp.array(dtype=wp.int32),  # (target pixel, direction, slot), -1: empty
    weights: wp.array(dtype=wp.float32),
    wave: int,
    tile_x0: int,
    tile_y0: int,
    tile_w: int,
    slot_of: wp.array(dtype=wp.int32),
    ext_x0: int,
    ext_y0: int,
    ext_w: int,
    ext_h: int,
    margin: int,
):
    """``film.gather_kernel``'s loops for the id tables: one source pixel per thread, its samples in order."""
    tid = wp.tid()
    slot = slot_of[tid]
    if slot < 0:
        return
    sx = tile_x0 + tid % tile_w
    sy = tile_y0 + tid // tile_w
    side = 2 * margin + 1
    base = slot * wave
    for oy in range(-margin, margin + 1):
        ty = sy - oy - ext_y0
        for ox in range(-margin, margin + 1):
            tx = sx - ox - ext_x0
            if ty >= 0 and ty < ext_h and tx >= 0 and tx < ext_w:
                k = ((ty * ext_w + tx) * side * side + (oy + margin) * side + ox + margin) * SLOTS
                for j in range(wave):
                    w = buf.wx[base + j][1 - ox] * buf.wy[base + j][1 - oy]
                    sid = sample_id[base + j]
                    if w != 0.0 and sid >= 0:
                        at = int(-1)
                        for q in range(SLOTS):
                            if at < 0:
                                e = ids[k + q]
                                if e == sid or e < 0:
                                    at = q
                        if at >= 0:
                            ids[k + at] = sid
                            weights[k + at] = weights[k + at] + w
