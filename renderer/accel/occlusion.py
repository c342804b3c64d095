"""Shadow rays: how much light gets through a segment at the sample's time.

Every surface crossed multiplies the light by (1 - opacity) at the crossing point (textured opacity and
opacityThreshold cut-outs included), the paper's transparency (section 5). The order of crossings does not
matter for a product, so this is an any-hit walk of the same time-keyed hierarchy as ``accel``'s closest-hit
walk, stopping as soon as the segment is fully blocked.
"""
from __future__ import annotations

import warp as wp

from renderer.accel.csg import csg_transmittance
from renderer.accel.embree import embree_occluded
from renderer.accel.intersect import (
    BIG,
    Geometry,
    corner_index,
    direct_ray,
    instance_visible,
    instance_world_to_object,
    leaf_four,
    leaf_hit,
    mesh_keys_at,
    point_hit,
    safe_inverse,
    tlas_keys_at,
)
from renderer.accel.analytic import is_cloud, shape_hits
from renderer.accel.quantize import q_entries
from renderer.accel.wide import entries, leaf_range, root_entered, wide_stack_t
from renderer.shading.materials import Materials, eval_opacity
from renderer.shading.textures import Textures


@wp.func
def hit_uv(geo: Geometry, m: int, tri: int, b1: float, b2: float):
    """Interpolated st of a hit, or NaN where the mesh has none (primvar readers then use their fallback)."""
    c = corner_index(geo, geo.mesh_uv_off, m, tri)
    if c < 0:
        return wp.vec2(wp.nan, wp.nan)
    return geo.uvs[c] * (1.0 - b1 - b2) + geo.uvs[c + 1] * b1 + geo.uvs[c + 2] * b2


@wp.func
def crossing_opacity(geo: Geometry, mats: Materials, tex: Textures, m: int, lt: int, b1: float, b2: float, s: float):
    """Opacity of local triangle lt of mesh m where a ray crosses it at (b1, b2), at time s."""
    tri = geo.mesh_tri_off[m] + lt
    return eval_opacity(mats, tex, geo.tri_material[tri], hit_uv(geo, m, tri, b1, b2), s)


@wp.func(inline=True)  # one call site: no copy of the Geometry struct
def blas_transmittance(geo: Geometry, mats: Materials, tex: Textures, m: int, ro: wp.vec3, rd: wp.vec3,
                       inv_d: wp.vec3, tmax: float, s: float, trans: float):
    """Multiply ``trans`` by (1 - opacity) of every triangle of mesh m crossed before tmax (object-space ray,
    ``inv_d`` = ``safe_inverse(rd)``); stops at 0."""
    k0, k1, u = mesh_keys_at(geo, m, s)
    nk = geo.mesh_nkeys[m]
    noff = geo.mesh_node_off[m]
    poff = geo.mesh_prim_off[m]
    stack = wide_stack_t()  # scratch: not zeroed, read below sp only
    stack[0] = 0  # the root
    sp = int(1)
    tr = trans
    kind = geo.mesh_shape[m]
    if kind > 0 and not is_cloud(kind):  # an exact shape: each crossing at the opacity of its material, no walk
        sp = 0
        t, part, n = shape_hits(kind, geo.mesh_shape_axis[m], geo.mesh_shape_param[m], ro, rd, tmax)
        if n > 0 and tr > 0.0:
            opacity = crossing_opacity(geo, mats, tex, m, 0, 0.0, 0.0, s)
            tr = tr * (1.0 - opacity)
            if n == 2:
                tr = tr * (1.0 - opacity)
    while sp > 0 and tr > 0.0:
        sp -= 1
        ref = stack[sp]
        if ref < 0:
            first, count = leaf_range(ref)
            if nk == 1 and not is_cloud(kind):  # a still leaf: which triangles are crossed, four at a time
                for g in range(0, count, 4):
                    ts = leaf_four(geo.leaf_v0, geo.leaf_e1, geo.leaf_e2, poff + first + g, count - g, ro, rd, tmax)
                    for j in range(4):
                        if ts[j] < BIG and tr > 0.0:  # the scalar test's own t: its b1, b2 and triangle
                            t, b1, b2, lt = leaf_hit(geo, m, poff + first + g + j, nk, k0, k1, u, ro, rd, tmax)
                            tr = tr * (1.0 - crossing_opacity(geo, mats, tex, m, lt, b1, b2, s))
            else:
                for i in range(count):
                    if is_cloud(kind):  # a sphere or disc of a point cloud: each crossing at its point's opacity
                        tp, nq, lp = point_hit(geo, m, kind, poff + first + i, nk, k0, k1, u, ro, rd, tmax)
                        if nq > 0 and tr > 0.0:
                            op = crossing_opacity(geo, mats, tex, m, lp, 0.0, 0.0, s)
                            tr = tr * (1.0 - op)
                            if nq == 2:
                                tr = tr * (1.0 - op)
                    else:
                        t, b1, b2, lt = leaf_hit(geo, m, poff + first + i, nk, k0, k1, u, ro, rd, tmax)
                        if t < BIG and tr > 0.0:
                            tr = tr * (1.0 - crossing_opacity(geo, mats, tex, m, lt, b1, b2, s))
        else:
            d, c = q_entries(geo.blas_node, noff + ref * nk, k0, k1, u, ro, inv_d, tmax)
            for j in range(4):
                if d[j] < BIG:
                    stack[sp] = c[j]
                    sp += 1
    return tr


@wp.func(inline=True)  # no copy of the Geometry struct
def mesh_transmittance(geo: Geometry, mats: Materials, tex: Textures, m: int, ro: wp.vec3, rd: wp.vec3,
                       tmax: float, s: float, trans: float):
    """``trans`` times what passes mesh m before tmax (object-space ray). Where Embree answers the mesh's shadow
    rays (opaque still triangles) any crossing it finds blocks the light; else our walk. Every shadow walk of a
    mesh goes through here: our uploaded tree of a mesh Embree answers for may be a single leaf."""
    if geo.mesh_embree_shadow[m] != 0:
        if trans > 0.0 and embree_occluded(geo.embree_occluded_fn, geo.mesh_embree[m], ro, rd, tmax) != 0:
            return 0.0
        return trans
    return blas_transmittance(geo, mats, tex, m, ro, rd, safe_inverse(rd), tmax, s, trans)


@wp.func
def casts_shadow(casters: wp.array(dtype=wp.int32), bit: int, inst: int) -> bool:
    """Does instance ``inst`` block light for shadow-link group ``bit`` (its bit set in ``casters[inst]``; -1: every
    instance blocks)?"""
    if bit < 0:
        return True
    return ((casters[inst] >> bit) & 1) != 0


@wp.func(inline=True)  # no copy of the Geometry struct
def linked_transmittance(geo: Geometry, mats: Materials, tex: Textures, ro: wp.vec3, rd: wp.vec3, tmax: float,
                         s: float, casters: wp.array(dtype=wp.int32), bit: int):
    """Fraction of light passing along the segment ro + t rd, t in (0, tmax), at time s, through the instances that
    cast shadows for shadow-link group ``bit`` (``lights.linking``: their bit set in ``casters``, per instance);
    with a group, the operands of CSG groups block as plain meshes (the CSG walk does not know the groups'
    casters). ``bit`` -1: every instance blocks (``transmittance``)."""
    tr = float(1.0)
    direct = geo.direct_inst  # walked first, outside the top level (``Geometry.direct_inst``)
    if direct >= 0:
        if instance_visible(geo, direct, s) and casts_shadow(casters, bit, direct):
            ro_o, rd_o = direct_ray(geo, ro, rd)
            tr = mesh_transmittance(geo, mats, tex, geo.inst_mesh[direct], ro_o, rd_o, tmax, s, tr)
        if geo.tlas_others == 0 or tr <= 0.0:  # blocked by the still prims: no top-level walk, no CSG
            return tr
    inv_d = safe_inverse(rd)
    k0, k1, u = tlas_keys_at(geo, s)
    nk = geo.tlas_nkeys
    stack = wide_stack_t()  # scratch: not zeroed, read below sp only
    stack[0] = 0  # the root
    sp = int(1)
    if not root_entered(geo.tlas_root, k0, ro, inv_d, tmax):
        sp = 0  # the ray passes by every instance of the top level
    while sp > 0 and tr > 0.0:
        sp -= 1
        ref = stack[sp]
        if ref < 0:
            first, count = leaf_range(ref)
            for i in range(count):
                inst = geo.tlas_prim[first + i]
                csg_member = geo.inst_csg[inst] >= 0 and bit < 0  # walked by ``csg_transmittance`` below
                if instance_visible(geo, inst, s) and tr > 0.0 and not csg_member and casts_shadow(casters, bit, inst):
                    w2o = instance_world_to_object(geo, inst, s)
                    rd_o = wp.transform_vector(w2o, rd)
                    tr = mesh_transmittance(geo, mats, tex, geo.inst_mesh[inst], wp.transform_point(w2o, ro), rd_o,
                                            tmax, s, tr)
        else:
            c = geo.tlas_child[ref]
            d = entries(geo.tlas_box, ref * nk, c, k0, k1, u, ro, inv_d, tmax)
            for j in range(4):
                if d[j] < BIG:
                    stack[sp] = c[j]
                    sp += 1
    if tr > 0.0 and geo.csg_groups > 0 and bit < 0:
        tr = csg_transmittance(geo, mats, tex, ro, rd, tmax, s, tr)
    return tr


@wp.func(inline=True)  # no copy of the Geometry struct
def transmittance(geo: Geometry, mats: Materials, tex: Textures, ro: wp.vec3, rd: wp.vec3, tmax: float,
                  s: float):
    """Fraction of light passing along the segment ro + t rd, t in (0, tmax), at time s: every instance blocks
    (``linked_transmittance`` without a group, which then reads no caster mask: ``inst_mesh`` stands in)."""
    return linked_transmittance(geo, mats, tex, ro, rd, tmax, s, geo.inst_mesh, -1)
