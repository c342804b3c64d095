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
vec9i = wp.types.vector(length=9, dtype=wp.int32)  # one entry per direction (``film.filter_margin`` is at most 1)
KIND_OBJECT = 0
KIND_MATERIAL = 1


@wp.kernel
def sample_ids_kernel(buf: SampleBuffer, inst_object: wp.array(dtype=wp.int32),
                      tri_object: wp.array(dtype=wp.int32), tri_material: wp.array(dtype=wp.int32),
                      out: wp.array(dtype=wp.vec2i)):
    """Each sample's ids: the object (the loaded scene's instance: its own, or for merged still geometry its
    triangle's, ``render.object_tables``) and the material of the surface it saw first; -1 where it saw none."""
    i = wp.tid()
    inst = buf.hit_inst[i]
    obj = int(-1)
    mat = int(-1)
    if inst >= 0:
        tri = buf.hit_tri[i]
        mat = tri_material[tri]
        obj = inst_object[inst]
        if obj < 0:
            obj = tri_object[tri]
    out[i] = wp.vec2i(obj, mat)


@wp.func
def table_add(ids: wp.array(dtype=wp.int32), weights: wp.array(dtype=wp.float32), k: int, sid: int, w: float,
              last_id: int, last_at: int):
    """w added to id ``sid`` in the table at k (the slot holding it, else the first empty one: slots fill in order;
    dropped when all are taken). ``last_id``/``last_at``: the previous sample's id and slot, which neighbouring
    samples mostly share; returns them for the next."""
    at = int(last_at)
    if sid != last_id:
        found = int(-1)
        q = int(0)
        while q < SLOTS:
            e = ids[k + q]
            if e == sid or e < 0:
                found = q
                break
            q += 1
        if found >= 0:
            ids[k + found] = sid
        at = found
    if at >= 0:
        weights[k + at] = weights[k + at] + w
    return sid, at


@wp.kernel
def coverage_gather_kernel(
    buf: SampleBuffer,
    sample_id: wp.array(dtype=wp.vec2i),  # per sample: object, material (``sample_ids_kernel``)
    object_ids: wp.array(dtype=wp.int32),  # (target pixel, direction, slot), -1: empty
    object_weights: wp.array(dtype=wp.float32),
    material_ids: wp.array(dtype=wp.int32),
    material_weights: wp.array(dtype=wp.float32),
    kinds: int,  # bit KIND_OBJECT, bit KIND_MATERIAL: the tables kept
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
    """``film.gather_kernel``'s loops for the id tables: one source pixel per thread, its samples in order, both
    tables at once (one pass over the weights)."""
    tid = wp.tid()
    slot = slot_of[tid]
    if slot < 0:
        return
    sx = tile_x0 + tid % tile_w
    sy = tile_y0 + tid // tile_w
    side = 2 * margin + 1
    base = slot * wave
    objects = (kinds & (1 << KIND_OBJECT)) != 0
    materials = (kinds & (1 << KIND_MATERIAL)) != 0
    # the table of each direction's target (-1: outside the region), and per table the id and slot of the sample
    # before: one pass over the samples, each read once
    table = vec9i()
    last_o = vec9i()
    at_o = vec9i()
    last_m = vec9i()
    at_m = vec9i()
    for d in range(side * side):
        oy = d // side - margin
        ox = d % side - margin
        ty = sy - oy - ext_y0
        tx = sx - ox - ext_x0
        table[d] = -1
        if ty >= 0 and ty < ext_h and tx >= 0 and tx < ext_w:
            table[d] = ((ty * ext_w + tx) * side * side + d) * SLOTS
        last_o[d] = -1
        at_o[d] = -1
        last_m[d] = -1
        at_m[d] = -1
    for j in range(wave):
        sid = sample_id[base + j]
        if sid[0] >= 0:
            wx = buf.wx[base + j]
            wy = buf.wy[base + j]
            for d in range(side * side):
                w = wx[1 - (d % side - margin)] * wy[1 - (d // side - margin)]
                k = table[d]
                if w != 0.0 and k >= 0:
                    if objects:
                        lo, ao = table_add(object_ids, object_weights, k, sid[0], w, last_o[d], at_o[d])
                        last_o[d] = lo
                        at_o[d] = ao
                    if materials:
                        lm, am = table_add(material_ids, material_weights, k, sid[1], w, last_m[d], at_m[d])
                        last_m[d] = lm
                        at_m[d] = am


@wp.kernel
def merge_kernel(ids: wp.array2d(dtype=wp.int32), weights: wp.array2d(dtype=wp.float32), keep: int,
                 run_ids: wp.array2d(dtype=wp.int32), run_sums: wp.array2d(dtype=wp.float64),
                 out_ids: wp.array2d(dtype=wp.int32), out_weights: wp.array2d(dtype=wp.float32)):
    """One pixel's entries (-1: empty) merged (``id_tables.merge``): each id's weights summed in float64 in entry
    order (``run_*``: scratch, a row per pixel), then the ``keep`` heaviest ids (ties: smaller id first) written
    in order into ``out_*`` (filled with -1 / 0 beforehand)."""
    p = wp.tid()
    n = ids.shape[1]
    runs = int(0)
    for j in range(n):
        i = ids[p, j]
        if i >= 0:
            k = int(0)
            while k < runs and run_ids[p, k] != i:  # a pixel sees a few ids: a linear search
                k += 1
            if k == runs:
                run_ids[p, k] = i
                run_sums[p, k] = wp.float64(0.0)
                runs += 1
            run_sums[p, k] = run_sums[p, k] + wp.float64(weights[p, j])
    for r in range(wp.min(keep, runs)):  # selection: the heaviest of the runs not yet written
        best = r
        best_w = wp.float32(run_sums[p, r])
        for k in range(r + 1, runs):
            w = wp.float32(run_sums[p, k])
            if w > best_w or (w == best_w and run_ids[p, k] < run_ids[p, best]):
                best = k
                best_w = w
        best_id = run_ids[p, best]
        run_ids[p, best] = run_ids[p, r]
        run_sums[p, best] = run_sums[p, r]
        run_ids[p, r] = best_id
        out_ids[p, r] = best_id
        out_weights[p, r] = best_w
