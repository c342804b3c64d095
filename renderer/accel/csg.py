"""Constructive solid geometry by ray intervals (the paper's section 5: "the union, intersection, difference
problem is easily solved with ray tracing ... these calculations are also correctly motion blurred").

A CSG group is a set of closed meshes (instances, each moving as it likes) sorted into *operands*, and an
operation: ``union`` (inside any operand), ``intersection`` (inside every operand) or ``difference`` (inside
operand 0 and no other). Member instances are left out of the ordinary walks (``inst_csg >= 0``); every ray
then walks each group along its own length:

1. at the ray origin, each operand's inside/outside state is the parity of its crossings along the whole ray
   (a closed mesh is crossed an odd number of times from inside);
2. the crossings are visited in order of distance (the nearest crossing of any member beyond the last one),
   each toggling its operand's state; the first crossing that changes the group's state is the surface seen.

Everything is evaluated at the ray's time, with each member's own transform and point keys, so a moving
operand carves a moving hole: the result is motion-blurred like any surface. Shadow rays multiply by
``1 - opacity`` at every state-changing crossing before the light, so transparency and shadows follow the
carved surface. The walk costs a few bottom-level traversals per group per ray and nothing for scenes
without groups. Limits: a ray grazing an edge shared by two triangles can count a crossing twice (a speck),
the subtracted surfaces of a ``difference`` keep their winding (for glass, they refract as seen from inside
that operand), and an emissive operand is sampled as a light over its whole surface, carved parts included.
"""
from __future__ import annotations

import warp as wp

from renderer.accel.intersect import (
    BIG,
    Geometry,
    Hit,
    corner_index,
    found,
    instance_visible,
    instance_world_to_object,
    leaf_hit,
    mesh_keys_at,
    safe_inverse,
)
from renderer.accel.quantize import q_entries
from renderer.accel.wide import leaf_range, wide_stack_t
from renderer.shading.materials import Materials, eval_opacity
from renderer.shading.textures import Textures

CSG_UNION = 0
CSG_INTERSECTION = 1
CSG_DIFFERENCE = 2
OPERATIONS = {"union": CSG_UNION, "intersection": CSG_INTERSECTION, "difference": CSG_DIFFERENCE}
MAX_OPERANDS = 30  # operand states are bits of an int32
MAX_STEPS = 64  # crossings visited per group and ray


@wp.func
def csg_inside(op: int, mask: int, operands: int):
    """Is a point inside the group, given the inside bit of each operand?"""
    if op == CSG_UNION:
        return mask != 0
    if op == CSG_INTERSECTION:
        return mask == (1 << operands) - 1
    return mask == 1  # difference: inside operand 0 and no other


@wp.func(inline=True)
def mesh_next_hit(geo: Geometry, m: int, ro: wp.vec3, rd: wp.vec3, tmin: float, tmax: float, s: float):
    """Nearest crossing of mesh m (object-space ray) with tmin < t < tmax: (t or BIG, local triangle, b1, b2)."""
    k0, k1, u = mesh_keys_at(geo, m, s)
    nk = geo.mesh_nkeys[m]
    noff = geo.mesh_node_off[m]
    poff = geo.mesh_prim_off[m]
    inv_d = safe_inverse(rd)
    stack = wide_stack_t()  # scratch: not zeroed, read below sp only
    stack[0] = 0  # the root
    sp = int(1)
    t_best = tmax
    found = float(BIG)
    tri = int(-1)
    hb1 = float(0.0)
    hb2 = float(0.0)
    while sp > 0:
        sp -= 1
        ref = stack[sp]
        if ref < 0:
            first, count = leaf_range(ref)
            for i in range(count):
                t, b1, b2, lt = leaf_hit(geo, m, poff + first + i, nk, k0, k1, u, ro, rd, t_best)
                if t < t_best and t > tmin:
                    t_best = t
                    found = t
                    tri = lt
                    hb1 = b1
                    hb2 = b2
        else:
            d, c = q_entries(geo.blas_node, noff + ref * nk, k0, k1, u, ro, inv_d, t_best)
            for j in range(4):
                if d[j] < BIG:
                    stack[sp] = c[j]
                    sp += 1
    return found, tri, hb1, hb2


@wp.func(inline=True)
def mesh_crossings(geo: Geometry, m: int, ro: wp.vec3, rd: wp.vec3, s: float):
    """Number of triangles of mesh m the object-space ray crosses at t > 0 (parity: is the origin inside)."""
    k0, k1, u = mesh_keys_at(geo, m, s)
    nk = geo.mesh_nkeys[m]
    noff = geo.mesh_node_off[m]
    poff = geo.mesh_prim_off[m]
    inv_d = safe_inverse(rd)
    stack = wide_stack_t()  # scratch: not zeroed, read below sp only
    stack[0] = 0  # the root
    sp = int(1)
    crossed = int(0)
    while sp > 0:
        sp -= 1
        ref = stack[sp]
        if ref < 0:
            first, count = leaf_range(ref)
            for i in range(count):
                t, b1, b2, lt = leaf_hit(geo, m, poff + first + i, nk, k0, k1, u, ro, rd, float(BIG))
                if t < BIG:
                    crossed += 1
        else:
            d, c = q_entries(geo.blas_node, noff + ref * nk, k0, k1, u, ro, inv_d, float(BIG))
            for j in range(4):
                if d[j] < BIG:
                    stack[sp] = c[j]
                    sp += 1
    return crossed


@wp.func(inline=True)
def group_start(geo: Geometry, g: int, ro: wp.vec3, rd: wp.vec3, s: float):
    """Operand inside-bits at the ray origin (parity of each visible member's crossings along the ray)."""
    mask = int(0)
    first = geo.csg_first[g]
    for i in range(geo.csg_count[g]):
        inst = geo.csg_members[first + i]
        if instance_visible(geo, inst, s):
            w2o = instance_world_to_object(geo, inst, s)
            c = mesh_crossings(geo, geo.inst_mesh[inst], wp.transform_point(w2o, ro), wp.transform_vector(w2o, rd),
                               s)
            if c % 2 == 1:
                mask = mask ^ (1 << geo.inst_csg_operand[inst])
    return mask


@wp.func(inline=True)
def group_next(geo: Geometry, g: int, ro: wp.vec3, rd: wp.vec3, tmin: float, tmax: float, s: float):
    """Nearest crossing of any member in (tmin, tmax): (t or BIG, instance, global triangle, b1, b2)."""
    first = geo.csg_first[g]
    t_best = tmax
    found = float(BIG)
    h_inst = int(-1)
    h_tri = int(-1)
    hb1 = float(0.0)
    hb2 = float(0.0)
    for i in range(geo.csg_count[g]):
        inst = geo.csg_members[first + i]
        if instance_visible(geo, inst, s):
            w2o = instance_world_to_object(geo, inst, s)
            m = geo.inst_mesh[inst]
            t, lt, b1, b2 = mesh_next_hit(geo, m, wp.transform_point(w2o, ro), wp.transform_vector(w2o, rd), tmin,
                                          t_best, s)
            if t < t_best:
                t_best = t
                found = t
                h_inst = inst
                h_tri = geo.mesh_tri_off[m] + lt
                hb1 = b1
                hb2 = b2
    return found, h_inst, h_tri, hb1, hb2


@wp.func(inline=True)  # one call site: no copy of the Geometry struct
def csg_closest(geo: Geometry, ro: wp.vec3, rd: wp.vec3, s: float, best: Hit):
    """``best`` (the closest ordinary hit) replaced by a nearer surface of any CSG group."""
    for g in range(geo.csg_groups):
        op = geo.csg_op[g]
        nops = geo.csg_operands[g]
        mask = group_start(geo, g, ro, rd, s)
        inside = csg_inside(op, mask, nops)
        t_cur = float(0.0)
        for step in range(MAX_STEPS):
            t, inst, tri, b1, b2 = group_next(geo, g, ro, rd, t_cur, best.t, s)
            if t >= BIG:
                break
            mask = mask ^ (1 << geo.inst_csg_operand[inst])
            now = csg_inside(op, mask, nops)
            if now != inside:
                best = found(t, inst, tri, b1, b2, wp.vec3(0.0))
                break
            t_cur = t
    return best


@wp.func
def _hit_uv(geo: Geometry, inst: int, tri: int, b1: float, b2: float):
    c = corner_index(geo, geo.mesh_uv_off, geo.inst_mesh[inst], tri)
    if c < 0:
        return wp.vec2(wp.nan, wp.nan)
    return geo.uvs[c] * (1.0 - b1 - b2) + geo.uvs[c + 1] * b1 + geo.uvs[c + 2] * b2


@wp.func(inline=True)  # one call site: no copy of the Geometry struct
def csg_transmittance(geo: Geometry, mats: Materials, tex: Textures, ro: wp.vec3, rd: wp.vec3, tmax: float,
                      s: float, trans: float):
    """``trans`` times (1 - opacity) of every CSG surface crossed along ro + t rd, t in (0, tmax), at time s."""
    tr = trans
    for g in range(geo.csg_groups):
        if tr > 0.0:
            op = geo.csg_op[g]
            nops = geo.csg_operands[g]
            mask = group_start(geo, g, ro, rd, s)
            inside = csg_inside(op, mask, nops)
            t_cur = float(0.0)
            for step in range(MAX_STEPS):
                t, inst, tri, b1, b2 = group_next(geo, g, ro, rd, t_cur, tmax, s)
                if t >= BIG or tr <= 0.0:
                    break
                mask = mask ^ (1 << geo.inst_csg_operand[inst])
                now = csg_inside(op, mask, nops)
                if now != inside:
                    opacity = eval_opacity(mats, tex, geo.tri_material[tri], _hit_uv(geo, inst, tri, b1, b2), s)
                    tr = tr * (1.0 - opacity)
                    inside = now
                t_cur = t
    return tr
