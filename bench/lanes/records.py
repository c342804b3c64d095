"""The shading records' layout: their float, integer and output rows, and the two views of one set of records,
one record per thread (``FlatRecords``) and batches of LANES per thread (``LaneRecords``)."""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.struct_refs import by_reference

LANES = 64  # records per thread in the in-thread loop (more than Warp's max_unroll: a real loop)
vecL = wp.types.vector(length=LANES, dtype=wp.float32)
ivecL = wp.types.vector(length=LANES, dtype=wp.int32)

# record fields: floats (rows of Records.f) and integers (rows of Records.i)
F_NAMES = ("px", "py", "pz", "ngx", "ngy", "ngz", "nsx", "nsy", "nsz", "wox", "woy", "woz", "dr", "dg", "db",
           "sr", "sg", "sb", "metallic", "roughness", "clearcoat", "cc_rough", "opacity", "ior")
I_NAMES = ("pixel", "index", "bounce", "front", "thin", "use_spec", "valid")
O_NAMES = ("cr", "cg", "cb", "wix", "wiy", "wiz", "dist")
(F_PX, F_PY, F_PZ, F_NGX, F_NGY, F_NGZ, F_NSX, F_NSY, F_NSZ, F_WOX, F_WOY, F_WOZ, F_DR, F_DG, F_DB, F_SR, F_SG, F_SB,
 F_METALLIC, F_ROUGHNESS, F_CLEARCOAT, F_CC_ROUGH, F_OPACITY, F_IOR) = range(len(F_NAMES))
I_PIXEL, I_INDEX, I_BOUNCE, I_FRONT, I_THIN, I_USE_SPEC, I_VALID = range(len(I_NAMES))
O_CR, O_CG, O_CB, O_WIX, O_WIY, O_WIZ, O_DIST = range(len(O_NAMES))
NF, NI, NO = len(F_NAMES), len(I_NAMES), len(O_NAMES)


@by_reference
@wp.struct
class FlatRecords:
    f: wp.array2d(dtype=wp.float32)  # (NF, n)
    i: wp.array2d(dtype=wp.int32)  # (NI, n)
    out: wp.array2d(dtype=wp.float32)  # (NO, n)


@by_reference
@wp.struct
class LaneRecords:
    """The same memory as ``FlatRecords``, each row cut into batches of LANES (a per-thread wavefront's SoA)."""

    f: wp.array2d(dtype=vecL)  # (NF, n / LANES)
    i: wp.array2d(dtype=ivecL)
    out: wp.array2d(dtype=vecL)


def lane_views(f: np.ndarray, i: np.ndarray, out_rows: int):
    """FlatRecords and LaneRecords over the same buffers (n a multiple of LANES)."""
    n = f.shape[1]
    fa = wp.array(f, dtype=wp.float32)
    ia = wp.array(i, dtype=wp.int32)
    oa = wp.zeros((out_rows, n), dtype=wp.float32)
    flat = FlatRecords()
    flat.f, flat.i, flat.out = fa, ia, oa
    lanes = LaneRecords()
    lanes.f = wp.array(ptr=fa.ptr, dtype=vecL, shape=(NF, n // LANES), device="cpu")
    lanes.i = wp.array(ptr=ia.ptr, dtype=ivecL, shape=(NI, n // LANES), device="cpu")
    lanes.out = wp.array(ptr=oa.ptr, dtype=vecL, shape=(out_rows, n // LANES), device="cpu")
    return flat, lanes, (fa, ia, oa)
