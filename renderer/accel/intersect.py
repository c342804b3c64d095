"""Ray intersection against moving geometry: a two-level BVH whose bounds depend on time.

Design (the paper asks that a moving object cost no more per ray than a still one):

* **Bottom level, per mesh.** One BVH per mesh in object space (``build.build_bvh``, binned SAH).
  A deforming mesh has P point keys; every node stores one box per key and a ray at time s tests the box
  interpolated between the two bracketing keys. Vertices are interpolated linearly between the same keys, so
  the interpolated box of a node always contains its triangles at time s: boxes stay tight at every instant
  instead of covering the whole shutter, and a ray's cost does not grow with the speed of the deformation.
* **Top level, per instance.** Rigid motion never touches the bottom level: the ray is carried into object
  space by the inverse of the instance's transform *at the ray's time* (translation lerp, rotation slerp). The
  top-level nodes store one box per key on a uniform grid of ``K`` shutter times, each box conservative for
  the instance's swept bounds on the adjacent segments (``instance_bounds.instance_key_bounds`` pads the keys with
  the measured deviation of curved motion from the linear blend). A still scene has ``K = 1``.

Both levels are binned-SAH trees (``build``) collapsed to four-wide nodes (``wide``): a node holds its four
children's boxes per key and their references (an inner node, or a leaf's range of primitives). Traversal is a
stack walk, nearest child first for closest hits.
"""
from __future__ import annotations

import warp as wp

from renderer.accel.analytic import SHAPE_DISCS, is_cloud, shape_hits, sphere_roots
from renderer.accel.embree import embree_closest
from renderer.accel.quads import embree_triangle
from renderer.accel.quantize import QNode, q_entries
from renderer.accel.wide import (WideBoxes, dist_stack_t, entries, far_to_near, leaf_range, root_entered,
                                 wide_stack_t)
from renderer.motion.kernels import MotionKeys, find_segment, keys_matrix
from renderer.kernels.struct_refs import by_reference
from renderer.kernels.vector_code import VECTOR_TYPES_CPP

BIG = 3.4e38


@by_reference
@wp.struct
class Geometry:
    """Every mesh and instance of a scene, uploaded for traversal. Offsets index the concatenated arrays."""

    # --- bottom level: all meshes concatenated
    points: wp.array(dtype=wp.vec3)  # mesh m, key k, vertex v at mesh_vert_off[m] + k * mesh_nverts[m] + v
    point_times: wp.array(dtype=wp.float32)  # mesh m's key times at mesh_key_off[m] .. + mesh_nkeys[m]
    tri_vidx: wp.array(dtype=wp.vec3i)  # global triangle -> local vertex indices
    tri_material: wp.array(dtype=wp.int32)  # global triangle -> material index
    # per-corner normals (object space) and uvs of the meshes that have them: triangle t (local) of mesh m, corner c
    # at mesh_normal_off[m] + 3 t + c (mesh_uv_off); -1: the mesh has none (``corner_index``)
    normals: wp.array(dtype=wp.vec3)
    mesh_normal_off: wp.array(dtype=wp.int32)
    uvs: wp.array(dtype=wp.vec2)
    mesh_uv_off: wp.array(dtype=wp.int32)
    # four-wide nodes in 64-byte records (``quantize``): node n of mesh m at key k is record
    # mesh_node_off[m] + n * K + k
    blas_node: wp.array(dtype=QNode)
    blas_prim: wp.array(dtype=wp.int32)  # local triangle index per leaf slot
    # Still meshes (one point key): each leaf slot's triangle as a vertex and two edges, contiguous in leaf
    # order, so a leaf's triangle tests read consecutive memory instead of gathering indexed vertices. A point
    # cloud (SHAPE_POINTS, SHAPE_DISCS): the slot's centre in leaf_v0 (still clouds), its radius in leaf_e1.x and a
    # disc's unit normal in leaf_e2.
    leaf_v0: wp.array(dtype=wp.vec3)
    leaf_e1: wp.array(dtype=wp.vec3)
    leaf_e2: wp.array(dtype=wp.vec3)
    mesh_node_off: wp.array(dtype=wp.int32)
    mesh_prim_off: wp.array(dtype=wp.int32)
    mesh_tri_off: wp.array(dtype=wp.int32)
    mesh_vert_off: wp.array(dtype=wp.int32)
    mesh_nverts: wp.array(dtype=wp.int32)
    mesh_key_off: wp.array(dtype=wp.int32)
    mesh_nkeys: wp.array(dtype=wp.int32)
    # per-corner displayColor of the meshes whose displayColor varies, laid out as the normals; -1: the mesh has
    # none (its materials hold the colour)
    colors: wp.array(dtype=wp.vec3)
    mesh_color_off: wp.array(dtype=wp.int32)
    tri_solid: wp.array(dtype=wp.int32)  # per global triangle, 1: part of a closed surface (refracts, absorbs)
    # per mesh: the exact shape the walks test instead of the mesh's tree (``accel.analytic``: SHAPE_SPHERE, ...), or
    # 0; its spine axis and parameters (rb, rt, half height, 0). A hit on it reports the mesh's first triangle (for
    # its material) and the piece it crossed in b1.
    mesh_shape: wp.array(dtype=wp.int32)
    mesh_shape_axis: wp.array(dtype=wp.int32)
    mesh_shape_param: wp.array(dtype=wp.vec4)
    # per mesh: the Embree scene that answers its closest hits instead of our walk, or 0 (``accel.embree``: still
    # triangle meshes); 1 where that scene also answers its shadow rays (every material opaque for them); and
    # Embree's rtcIntersect1 and rtcOccluded1
    mesh_embree: wp.array(dtype=wp.uint64)
    mesh_embree_shadow: wp.array(dtype=wp.int32)
    # per mesh: where the codes of its Embree scene's geometries start in embree_geoms (``quads.embree_triangle``)
    mesh_embree_geom_off: wp.array(dtype=wp.int32)
    embree_geoms: wp.array(dtype=wp.int32)
    embree_closest_fn: wp.uint64
    embree_occluded_fn: wp.uint64
    # --- top level
    # four-wide nodes as the bottom level's, in float: node n, key k (uniform key times k / (K - 1)) at record
    # n * tlas_nkeys + k
    tlas_box: wp.array(dtype=WideBoxes)
    tlas_child: wp.array(dtype=wp.vec4i)
    # the root's own box (the union of the top level's instances) per segment between keys: lo, hi at 2 k, 2 k + 1
    # (``wide.root_boxes``)
    tlas_root: wp.array(dtype=wp.vec3)
    tlas_prim: wp.array(dtype=wp.int32)  # instance index per leaf slot
    tlas_nkeys: int
    # The instance walked outside the top level, or -1 (``upload.direct_instance``): a still one, outside CSG, whose
    # world box has at least the area of all the others' together: every still scene (one instance after
    # flattening), or its merged still geometry beside a few movers. Walks visit its mesh first, without the top
    # level's loop, root box test and instance checks (a traversal-only kernel: closest hits 30-40 % faster on
    # gloss), then the top level, which holds the other ``tlas_others`` instances (none: not walked).
    direct_inst: int
    direct_identity: int  # 1: the direct instance's matrix is the identity (``direct_ray``)
    tlas_others: int
    inst_mesh: wp.array(dtype=wp.int32)
    inst_xf_off: wp.array(dtype=wp.int32)
    inst_xf_count: wp.array(dtype=wp.int32)
    inst_w2o: wp.array(dtype=wp.mat44)  # world-to-object for still instances (xf_count == 1)
    inst_o2w: wp.array(dtype=wp.mat44)  # object-to-world for still instances
    # 1: a moving instance whose keys differ only in translation: its matrices are inst_o2w / inst_w2o with the
    # translation interpolated (no slerp, no 4x4 inverse per visit)
    inst_translate_only: wp.array(dtype=wp.int32)
    inst_vis_from: wp.array(dtype=wp.float32)
    inst_vis_to: wp.array(dtype=wp.float32)
    keys: MotionKeys
    # --- CSG groups (``accel.csg``): members are skipped by the ordinary walks and walked per group instead
    inst_csg: wp.array(dtype=wp.int32)  # per instance: its CSG group, or -1
    inst_csg_operand: wp.array(dtype=wp.int32)  # per instance: its operand within the group (0..29)
    csg_groups: int
    csg_op: wp.array(dtype=wp.int32)  # per group: CSG_UNION / CSG_INTERSECTION / CSG_DIFFERENCE
    csg_operands: wp.array(dtype=wp.int32)  # per group: number of operands
    csg_first: wp.array(dtype=wp.int32)  # per group: first member in csg_members
    csg_count: wp.array(dtype=wp.int32)  # per group: member instances
    csg_members: wp.array(dtype=wp.int32)  # instance indices, grouped


@wp.struct
class Hit:
    """The closest intersection found along a ray (``inst < 0``: none)."""

    t: float
    inst: int
    tri: int  # global triangle index
    b1: float  # barycentric weight of vertex 1
    b2: float  # barycentric weight of vertex 2
    ng: wp.vec3  # object-space (p1 - p0) x (p2 - p0) where Embree found the hit (it has it at hand), else 0


@wp.func
def found(t: float, inst: int, tri: int, b1: float, b2: float, ng: wp.vec3):
    """The ``Hit`` a walk records: every field anew, so that no nearer hit keeps a farther one's normal."""
    h = Hit()
    h.t = t
    h.inst = inst
    h.tri = tri
    h.b1 = b1
    h.b2 = b2
    h.ng = ng
    return h


@wp.func
def safe_inverse(d: wp.vec3):
    e = float(1.0e-30)
    return wp.vec3(1.0 / wp.where(wp.abs(d[0]) < e, e, d[0]),
                   1.0 / wp.where(wp.abs(d[1]) < e, e, d[1]),
                   1.0 / wp.where(wp.abs(d[2]) < e, e, d[2]))


@wp.func
def triangle_hit_edges(p0: wp.vec3, e1: wp.vec3, e2: wp.vec3, ro: wp.vec3, rd: wp.vec3, tmax: float):
    """Moller-Trumbore on a vertex and its two edges (p1 - p0, p2 - p0). Returns (t, b1, b2); t = BIG on a
    miss. Both faces are hit (no culling)."""
    pv = wp.cross(rd, e2)
    det = wp.dot(e1, pv)
    if det == 0.0:
        return float(BIG), 0.0, 0.0
    inv = 1.0 / det
    tv = ro - p0
    b1 = wp.dot(tv, pv) * inv
    if b1 < 0.0 or b1 > 1.0:
        return float(BIG), 0.0, 0.0
    qv = wp.cross(tv, e1)
    b2 = wp.dot(rd, qv) * inv
    if b2 < 0.0 or b1 + b2 > 1.0:
        return float(BIG), 0.0, 0.0
    t = wp.dot(e2, qv) * inv
    if t <= 0.0 or t >= tmax:
        return float(BIG), 0.0, 0.0
    return t, b1, b2


# ``triangle_hit_edges`` on four of a still leaf's triangles at once (``vector_code``; Warp's vec3 code compiles to
# scalar instructions), then the nearest taken in slot order: the triangle tests were 13 % of a Cornell-box
# sample, the hottest leaf of the profile. Every lane computes what the scalar test computes, expression for
# expression as Warp writes ``cross`` and ``dot`` (so that a compiler contracting products into fused multiply-adds
# would contract the same ones), and a lane stands for a hit where the scalar test would not have returned a miss.
# So a leaf gives the bits of the scalar loop: tested against it, and renders are unchanged.
LEAF_LANES_CPP = VECTOR_TYPES_CPP + r"""
    struct Lanes { v4f t, b1, b2; v4i miss; };
    /* triangle_hit_edges on the slots first + k .. first + k + 3 of arrays v0, e1, e2 (a lane past ``lanes``
       repeats the last); ``miss`` where the scalar test returns a miss */
    auto four_lanes = [&](int k, int lanes) {
        const v4f ox = splat(ro.c[0]), oy = splat(ro.c[1]), oz = splat(ro.c[2]);
        const v4f dx = splat(rd.c[0]), dy = splat(rd.c[1]), dz = splat(rd.c[2]);
        const v4f zero = splat(0.0f), one = splat(1.0f);
        v4f px, py, pz, ax, ay, az, bx, by, bz;  /* vertex 0, edge 1, edge 2 of each lane's triangle */
        for (int l = 0; l < 4; ++l) {
            const int slot = first + k + (l < lanes ? l : lanes - 1);
            const wp::vec_t<3, wp::float32> p = wp::index(v0, slot);
            const wp::vec_t<3, wp::float32> a = wp::index(e1, slot);
            const wp::vec_t<3, wp::float32> b = wp::index(e2, slot);
            px[l] = p.c[0]; py[l] = p.c[1]; pz[l] = p.c[2];
            ax[l] = a.c[0]; ay[l] = a.c[1]; az[l] = a.c[2];
            bx[l] = b.c[0]; by[l] = b.c[1]; bz[l] = b.c[2];
        }
        /* pv = cross(rd, e2); det = dot(e1, pv) */
        const v4f pvx = dy * bz - dz * by;
        const v4f pvy = dz * bx - dx * bz;
        const v4f pvz = dx * by - dy * bx;
        const v4f det = ax * pvx + ay * pvy + az * pvz;
        const v4f inv = one / det;
        /* tv = ro - p0; b1 = dot(tv, pv) * inv */
        const v4f tvx = ox - px;
        const v4f tvy = oy - py;
        const v4f tvz = oz - pz;
        const v4f dot_b1 = tvx * pvx + tvy * pvy + tvz * pvz;
        Lanes r;
        r.b1 = dot_b1 * inv;
        /* qv = cross(tv, e1); b2 = dot(rd, qv) * inv; t = dot(e2, qv) * inv */
        const v4f qvx = tvy * az - tvz * ay;
        const v4f qvy = tvz * ax - tvx * az;
        const v4f qvz = tvx * ay - tvy * ax;
        const v4f dot_b2 = dx * qvx + dy * qvy + dz * qvz;
        r.b2 = dot_b2 * inv;
        const v4f dot_t = bx * qvx + by * qvy + bz * qvz;
        r.t = dot_t * inv;
        const v4f b12 = r.b1 + r.b2;
        /* the scalar test's misses; a NaN passes them as it does there, and then loses every comparison */
        r.miss = (det == zero) | (r.b1 < zero) | (r.b1 > one) | (r.b2 < zero) | (b12 > one) | (r.t <= zero) |
                 (r.t >= splat(tmax));
        return r;
    };
"""
_LEAF_CLOSEST_CPP = LEAF_LANES_CPP + r"""
    float best_t = tmax, best_b1 = 0.0f, best_b2 = 0.0f;
    int best_i = -1;
    for (int k = 0; k < count; k += 4) {
        const int lanes = count - k < 4 ? count - k : 4;
        const Lanes r = four_lanes(k, lanes);
        for (int l = 0; l < lanes; ++l) {
            if (!r.miss[l] && r.t[l] < best_t) {
                best_t = r.t[l];
                best_b1 = r.b1[l];
                best_b2 = r.b2[l];
                best_i = k + l;
            }
        }
    }
    return wp::vec_t<4, wp::float32>(best_t, best_b1, best_b2, (float)best_i);
"""
_LEAF_FOUR_CPP = LEAF_LANES_CPP + r"""
    const int lanes = count < 4 ? count : 4;
    const Lanes r = four_lanes(0, lanes);
    const v4i past = (v4i){0, 1, 2, 3} >= (v4i){lanes, lanes, lanes, lanes};
    const v4f t = (r.miss | past) ? splat(3.4e38f) : r.t;
    return wp::vec_t<4, wp::float32>(t[0], t[1], t[2], t[3]);
"""


@wp.func_native(_LEAF_FOUR_CPP)
def leaf_four(v0: wp.array(dtype=wp.vec3), e1: wp.array(dtype=wp.vec3), e2: wp.array(dtype=wp.vec3), first: int,
              count: int, ro: wp.vec3, rd: wp.vec3, tmax: float) -> wp.vec4:
    """``triangle_hit_edges``' t for the still leaf triangles in slots first .. first + 3 (the first ``count`` of
    them; BIG for the others), as vector code: the any-hit walks find which triangles a shadow ray crosses."""
    ...


@wp.func_native(_LEAF_CLOSEST_CPP)
def leaf_closest(v0: wp.array(dtype=wp.vec3), e1: wp.array(dtype=wp.vec3), e2: wp.array(dtype=wp.vec3), first: int,
                 count: int, ro: wp.vec3, rd: wp.vec3, tmax: float) -> wp.vec4:
    """The nearest of the still leaf triangles in slots first .. first + count - 1 hit in (0, tmax): (t, b1, b2, its
    place in the leaf), or (tmax, 0, 0, -1) when none is. The bits of ``triangle_hit_edges`` in slot order."""
    ...


@wp.func
def mesh_vertex(geo: Geometry, m: int, k0: int, k1: int, u: float, v: int):
    """Object-space position of vertex v of mesh m between point keys k0 and k1 (local key indices)."""
    base = geo.mesh_vert_off[m]
    nv = geo.mesh_nverts[m]
    p = geo.points[base + k0 * nv + v]
    if k1 != k0:
        p = wp.lerp(p, geo.points[base + k1 * nv + v], u)
    return p


@wp.func
def triangle_points(geo: Geometry, m: int, local_tri: int, k0: int, k1: int, u: float):
    idx = geo.tri_vidx[geo.mesh_tri_off[m] + local_tri]
    return (mesh_vertex(geo, m, k0, k1, u, idx[0]), mesh_vertex(geo, m, k0, k1, u, idx[1]),
            mesh_vertex(geo, m, k0, k1, u, idx[2]))


@wp.func
def leaf_triangle(geo: Geometry, m: int, slot: int, lt: int, nkeys: int, k0: int, k1: int, u: float):
    """Vertex and edges of the triangle in leaf slot ``slot`` (local triangle ``lt``) at the walk's time."""
    if nkeys == 1:
        return geo.leaf_v0[slot], geo.leaf_e1[slot], geo.leaf_e2[slot]
    p0, p1, p2 = triangle_points(geo, m, lt, k0, k1, u)
    return p0, p1 - p0, p2 - p0


@wp.func
def leaf_hit(geo: Geometry, m: int, slot: int, nkeys: int, k0: int, k1: int, u: float, ro: wp.vec3, rd: wp.vec3,
             tmax: float):
    """The triangle in leaf slot ``slot`` of mesh m against the object-space ray at the walk's time: (t, or BIG on a
    miss, b1, b2, its local triangle index, -1 on a miss). Every bottom-level walk tests its leaves with this."""
    if nkeys == 1:  # a still mesh: the leaf copy alone; its triangle index is read on a hit only (most tests
        # miss, and the index is a separate stream: 4 % of the heavy scene's time went to that load)
        t, b1, b2 = triangle_hit_edges(geo.leaf_v0[slot], geo.leaf_e1[slot], geo.leaf_e2[slot], ro, rd, tmax)
        lt = int(-1)
        if t < BIG:
            lt = geo.blas_prim[slot]
        return t, b1, b2, lt
    lt = geo.blas_prim[slot]
    v0, e1, e2 = leaf_triangle(geo, m, slot, lt, nkeys, k0, k1, u)
    t, b1, b2 = triangle_hit_edges(v0, e1, e2, ro, rd, tmax)
    return t, b1, b2, lt


@wp.func
def point_hit(geo: Geometry, m: int, kind: int, slot: int, nkeys: int, k0: int, k1: int, u: float, ro: wp.vec3,
              rd: wp.vec3, tmax: float):
    """The sphere (or disc, ``kind``) in leaf slot ``slot`` of point cloud m against the object-space ray at the
    walk's time: (t of its nearest crossing in (0, tmax), BIG if none; crossings in (0, tmax), 0..2; its point, the
    local "triangle")."""
    lt = geo.blas_prim[slot]
    c = geo.leaf_v0[slot]
    if nkeys > 1:  # moving points: the centre between the point keys
        c = mesh_vertex(geo, m, k0, k1, u, lt)
    r = geo.leaf_e1[slot][0]
    if kind == SHAPE_DISCS:  # the plane through c facing the slot's normal, within r of c
        nrm = geo.leaf_e2[slot]
        denom = wp.dot(rd, nrm)
        td = float(BIG)
        if denom != 0.0:
            td = wp.dot(c - ro, nrm) / denom
        if td > 0.0 and td < tmax:
            q = ro + rd * td - c
            if wp.dot(q, q) <= r * r:
                return td, 1, lt
        return float(BIG), 0, lt
    t0, t1 = sphere_roots(ro - c, rd, r)
    t = float(BIG)
    n = int(0)
    if t1 > 0.0 and t1 < tmax:
        t = t1
        n = 1
    if t0 > 0.0 and t0 < tmax:
        t = t0
        n += 1
    return t, n, lt


@wp.func
def corner_index(geo: Geometry, first_corner: wp.array(dtype=wp.int32), m: int, tri: int):
    """Index of global triangle tri's first corner in a per-corner table (normals, uvs, colours) where mesh m's
    corners start at first_corner[m]; -1 when mesh m has none there."""
    off = first_corner[m]
    if off < 0:
        return -1
    return off + 3 * (tri - geo.mesh_tri_off[m])


@wp.func
def mesh_keys_at(geo: Geometry, m: int, s: float):
    """Local point-key indices (k0, k1) bracketing time s for mesh m, and the blend u."""
    off = geo.mesh_key_off[m]
    i, j, u = find_segment(geo.point_times, off, geo.mesh_nkeys[m], s)
    return i - off, j - off, u


@wp.func
def instance_translation(geo: Geometry, inst: int, s: float):
    """The translation of a moving instance's transform at time s (its keys' translations interpolated)."""
    i, j, u = find_segment(geo.keys.times, geo.inst_xf_off[inst], geo.inst_xf_count[inst], s)
    return wp.lerp(geo.keys.translation[i], geo.keys.translation[j], u)


@wp.func
def instance_world_to_object(geo: Geometry, inst: int, s: float):
    if geo.inst_xf_count[inst] == 1:
        return geo.inst_w2o[inst]
    if geo.inst_translate_only[inst] != 0:  # [A | -A t(s)], A the constant inverse of the linear part
        m = geo.inst_w2o[inst]
        t = instance_translation(geo, inst, s)
        return wp.mat44(
            m[0, 0], m[0, 1], m[0, 2], -(m[0, 0] * t[0] + m[0, 1] * t[1] + m[0, 2] * t[2]),
            m[1, 0], m[1, 1], m[1, 2], -(m[1, 0] * t[0] + m[1, 1] * t[1] + m[1, 2] * t[2]),
            m[2, 0], m[2, 1], m[2, 2], -(m[2, 0] * t[0] + m[2, 1] * t[1] + m[2, 2] * t[2]),
            0.0, 0.0, 0.0, 1.0)
    return wp.inverse(keys_matrix(geo.keys, geo.inst_xf_off[inst], geo.inst_xf_count[inst], s))


@wp.func
def instance_object_to_world(geo: Geometry, inst: int, s: float):
    if geo.inst_xf_count[inst] == 1:
        return geo.inst_o2w[inst]
    if geo.inst_translate_only[inst] != 0:
        m = geo.inst_o2w[inst]
        t = instance_translation(geo, inst, s)
        return wp.mat44(m[0, 0], m[0, 1], m[0, 2], t[0], m[1, 0], m[1, 1], m[1, 2], t[1],
                        m[2, 0], m[2, 1], m[2, 2], t[2], 0.0, 0.0, 0.0, 1.0)
    return keys_matrix(geo.keys, geo.inst_xf_off[inst], geo.inst_xf_count[inst], s)


@wp.func(inline=True)  # one call site: no copy of the Geometry struct
def blas_closest(geo: Geometry, m: int, ro: wp.vec3, rd: wp.vec3, inv_d: wp.vec3, tmax: float, s: float, best: Hit,
                 inst: int):
    """Closest triangle of mesh m (object-space ray, ``inv_d`` = ``safe_inverse(rd)``) nearer than tmax; updates and
    returns ``best``. A walk of the four-wide tree, nearest child first, skipping what lies beyond the best hit."""
    k0, k1, u = mesh_keys_at(geo, m, s)
    nk = geo.mesh_nkeys[m]
    noff = geo.mesh_node_off[m]
    poff = geo.mesh_prim_off[m]
    stack = wide_stack_t()  # scratch: not zeroed, read below sp only
    dist = dist_stack_t()
    stack[0] = 0  # the root, entered at distance 0
    dist[0] = 0.0
    sp = int(1)
    t_best = tmax
    kind = geo.mesh_shape[m]
    if kind > 0 and not is_cloud(kind):  # an exact shape: a quadratic or two, no walk
        sp = 0
        t, part, n = shape_hits(kind, geo.mesh_shape_axis[m], geo.mesh_shape_param[m], ro, rd, t_best)
        if t < t_best:
            best = found(t, inst, geo.mesh_tri_off[m], float(part), 0.0, wp.vec3(0.0))
    while sp > 0:
        sp -= 1
        if dist[sp] < t_best:
            ref = stack[sp]
            if ref < 0:
                first, count = leaf_range(ref)
                if nk == 1 and not is_cloud(kind):  # a still leaf: four triangles at a time
                    r = leaf_closest(geo.leaf_v0, geo.leaf_e1, geo.leaf_e2, poff + first, count, ro, rd, t_best)
                    if r[3] >= 0.0:
                        t_best = r[0]
                        best = found(r[0], inst, geo.mesh_tri_off[m] + geo.blas_prim[poff + first + int(r[3])],
                                     r[1], r[2], wp.vec3(0.0))
                else:
                    for i in range(count):
                        if is_cloud(kind):  # a sphere or disc of a point cloud
                            tp, np_, lp = point_hit(geo, m, kind, poff + first + i, nk, k0, k1, u, ro, rd, t_best)
                            if tp < t_best:
                                t_best = tp
                                best = found(tp, inst, geo.mesh_tri_off[m] + lp, 0.0, 0.0, wp.vec3(0.0))
                        else:
                            t, b1, b2, lt = leaf_hit(geo, m, poff + first + i, nk, k0, k1, u, ro, rd, t_best)
                            if t < t_best:
                                t_best = t
                                best = found(t, inst, geo.mesh_tri_off[m] + lt, b1, b2, wp.vec3(0.0))
            else:
                d, c = q_entries(geo.blas_node, noff + ref * nk, k0, k1, u, ro, inv_d, t_best)
                d, c = far_to_near(d, c)
                for j in range(4):
                    if d[j] < BIG:
                        stack[sp] = c[j]
                        dist[sp] = d[j]
                        sp += 1
    return best


@wp.func
def embree_mesh_closest(geo: Geometry, m: int, ro: wp.vec3, rd: wp.vec3, tmax: float, best: Hit, inst: int):
    """``blas_closest`` of a mesh Embree holds (``geo.mesh_embree[m]`` != 0): its walk instead of ours."""
    eh = embree_closest(geo.embree_closest_fn, geo.mesh_embree[m], ro, rd, tmax)
    if eh[3] < wp.float64(0.0):
        return best
    tri, b1, b2 = embree_triangle(geo.embree_geoms, geo.mesh_embree_geom_off[m], int(eh[7]), int(eh[3]),
                                  float(eh[1]), float(eh[2]))
    ng = wp.vec3(float(eh[4]), float(eh[5]), float(eh[6]))
    return found(float(eh[0]), inst, geo.mesh_tri_off[m] + tri, b1, b2, ng)


@wp.func(inline=True)  # no copy of the Geometry struct
def mesh_closest(geo: Geometry, m: int, ro: wp.vec3, rd: wp.vec3, tmax: float, s: float, best: Hit, inst: int):
    """Closest triangle of mesh m nearer than tmax (object-space ray): Embree's walk where it holds the mesh, else
    ours. Every walk of a mesh goes through here: our uploaded tree of a mesh Embree answers for may be a
    single leaf (``upload._walked_by_embree``)."""
    if geo.mesh_embree[m] != wp.uint64(0):
        return embree_mesh_closest(geo, m, ro, rd, tmax, best, inst)
    return blas_closest(geo, m, ro, rd, safe_inverse(rd), tmax, s, best, inst)


@wp.func
def tlas_keys_at(geo: Geometry, s: float):
    nk = geo.tlas_nkeys
    if nk == 1:
        return 0, 0, float(0.0)
    x = wp.clamp(s, 0.0, 1.0) * float(nk - 1)
    k0 = wp.min(int(x), nk - 2)
    return k0, k0 + 1, x - float(k0)


@wp.func
def instance_visible(geo: Geometry, inst: int, s: float):
    return s >= geo.inst_vis_from[inst] and s <= geo.inst_vis_to[inst]


@wp.func
def direct_ray(geo: Geometry, ro: wp.vec3, rd: wp.vec3):
    """The ray in the direct instance's object space. A flattened still scene's merged mesh is in world space,
    its matrix the identity: the ray is then used as it is, without a 64-byte matrix read and two products per
    walk (every closest-hit and shadow ray of a still scene)."""
    if geo.direct_identity != 0:
        return ro, rd
    w2o = geo.inst_w2o[geo.direct_inst]
    return wp.transform_point(w2o, ro), wp.transform_vector(w2o, rd)


@wp.func(inline=True)  # one call site: no copy of the Geometry struct
def intersect_closest(geo: Geometry, ro: wp.vec3, rd: wp.vec3, tmax: float, s: float):
    """Closest hit of a world-space ray at normalised shutter time s, nearer than tmax."""
    best = Hit()
    best.t = tmax
    best.inst = -1
    best.tri = -1
    direct = geo.direct_inst
    if direct >= 0:
        if instance_visible(geo, direct, s):
            ro_o, rd_o = direct_ray(geo, ro, rd)
            best = mesh_closest(geo, geo.inst_mesh[direct], ro_o, rd_o, tmax, s, best, direct)
        if geo.tlas_others == 0:
            return best
    inv_d = safe_inverse(rd)
    k0, k1, u = tlas_keys_at(geo, s)
    nk = geo.tlas_nkeys
    if not root_entered(geo.tlas_root, k0, ro, inv_d, best.t):
        return best
    stack = wide_stack_t()  # scratch: not zeroed, read below sp only
    dist = dist_stack_t()
    stack[0] = 0  # the root, entered at distance 0
    dist[0] = 0.0
    sp = int(1)
    while sp > 0:
        sp -= 1
        if dist[sp] < best.t:
            ref = stack[sp]
            if ref < 0:
                first, count = leaf_range(ref)
                for i in range(count):
                    inst = geo.tlas_prim[first + i]
                    if instance_visible(geo, inst, s) and geo.inst_csg[inst] < 0:
                        w2o = instance_world_to_object(geo, inst, s)
                        ro_o = wp.transform_point(w2o, ro)
                        rd_o = wp.transform_vector(w2o, rd)
                        best = mesh_closest(geo, geo.inst_mesh[inst], ro_o, rd_o, best.t, s, best, inst)
            else:
                c = geo.tlas_child[ref]
                d, c = far_to_near(entries(geo.tlas_box, ref * nk, c, k0, k1, u, ro, inv_d, best.t), c)
                for j in range(4):
                    if d[j] < BIG:
                        stack[sp] = c[j]
                        dist[sp] = d[j]
                        sp += 1
    return best
