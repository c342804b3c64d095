"""Uploading a Scene's meshes and instances into the two-level, time-keyed hierarchy of ``accel``.

Builds one bottom-level BVH per mesh (bounds per point key; binned SAH, then collapsed to four-wide nodes, stored
as ``quantize``'s 64-byte records), the instances' world bounds on a uniform grid of top-level time keys
(``instance_bounds``: placed from a cut of the mesh's hierarchy, padded so that the blend between two keys contains
the curved path in between), and the top-level BVH over them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from renderer.accel import embree
from renderer.accel.build import Bvh, build_bvh
from renderer.accel.csg import OPERATIONS as CSG_OPERATIONS
from renderer.accel.instance_bounds import box_cut, cut_size, instance_key_bounds, still_world_boxes
from renderer.accel.intersect import Geometry
from renderer.accel.quantize import QNODE_DTYPE, QNode, quantize
from renderer.accel.wide import WideBvh, box_records, collapse, root_boxes
from renderer.accel.triangle_kernels import leaf_triangles, triangle_boxes
from renderer.motion.kernels import upload_keys
from renderer.motion.transform import MotionTransform, matrices_at
from renderer.scene.analytic import (CLOUD_KINDS, SHAPE_BOX_PAD, analytic_shapes, realize_tessellations,
                                     shape_bounds, shape_table, shape_world_boxes)
from renderer.scene.mesh_facts import is_closed
from renderer.scene.model import Mesh, Scene
from renderer.shading.material_upload import opaque_for_shadows

MAX_TLAS_KEYS = 33  # top-level time keys for moving scenes (32 segments over the shutter)
# Bottom-level leaves of up to 4 triangles, SAH node cost 2 triangle tests: for the four-wide walk, 5-13 % faster
# than the 8 / 4 that suited the binary one (320x180, 16 spp, one thread, 2 runs each: heavy 2.10 vs 2.22 s,
# cornell 1.67 vs 1.91, gloss 2.08 vs 2.19, motion 1.75 vs 1.80), at 59 instead of 50 bytes per triangle on the
# heavy scene (8 / 2: 58, slower; 4 / 1: 69, no faster).
BLAS_MAX_LEAF = 4
BLAS_TRAVERSAL_COST = 2.0
# The collapse makes a subtree of up to 6 triangles one leaf: 44 % of the heavy scene's wide nodes had only two
# children (leaves at the bottom). Heavy hierarchy 51.0 -> 47.0 bytes per triangle (gloss 51.5 -> 48.2). Its cost
# is within the noise: four runs in one process against no merging (320x180, 16 spp, one thread, 3-8 rounds)
# gave heavy 1.09, 1.09, 0.98 and 0.95x the time, gloss 1.00; callgrind counts 0.8 % more instructions and L1
# misses. Up to 8 triangles: 45.3 bytes, heavy 1.08-1.26x in two runs.
BLAS_MERGE_LEAF = 6
# A still triangle mesh's leaves are tested four triangles at a time (``intersect.leaf_closest``, ``leaf_four``):
# a triangle costs a quarter of what the parameters above assume, so its leaves are larger, up to 12 triangles,
# with a node costing 12 triangle tests. `drt render` at 640x360, 2 threads, 32 spp, the two builds in turn, best
# of 7: cornell 4.33 -> 4.17 s, heavy 5.00 -> 4.89 s, gloss 5.23 -> 5.21 s (teapot shot, dof: within the noise);
# heavy's hierarchy 0.45 -> 0.38 s on one thread and 47.0 -> 43.7 bytes per triangle. (Up to 8 with cost 8, merged
# up to 12: the same within the noise; 15 with cost 10: cornell slower.) Deforming meshes and point clouds, tested
# one primitive at a time, keep the parameters above.
STILL_MAX_LEAF = 12
STILL_TRAVERSAL_COST = 12.0
STILL_MERGE_LEAF = 12


@dataclass
class GeometryStats:
    triangles: int
    blas_nodes: int
    tlas_nodes: int
    tlas_keys: int
    build_seconds: float
    nbytes: int  # everything the walks read beyond the meshes' own arrays, Embree's trees included
    embree_nbytes: int = 0  # of which Embree's (``accel.embree``)


def _mesh_prim_bounds(mesh: Mesh, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Per-key primitive boxes (P, T, 3) of a mesh: its triangles', or a sphere cloud's spheres'."""
    if mesh.point_radii is not None:  # a sphere reaches r along every axis, a disc r sqrt(1 - n_i^2) along axis i
        r = mesh.point_radii.astype(np.float64)[None, :, None]
        if mesh.shape is not None and mesh.shape.kind == "discs":
            n = mesh.normals[:, 0].astype(np.float64)
            r = r * np.sqrt(np.maximum(1.0 - n * n, 0.0))[None]
        c = mesh.points.astype(np.float64)
        # rounded outwards to float32: a box never clips its sphere, however far from the origin
        lo = np.nextafter((c - r).astype(np.float32), np.float32(-np.inf))
        hi = np.nextafter((c + r).astype(np.float32), np.float32(np.inf))
        return np.ascontiguousarray(lo), np.ascontiguousarray(hi)
    return triangle_boxes(mesh.points, mesh.triangles, device)


def _tlas_key_count(scene: Scene) -> int:
    if not scene.instances:
        return 1
    xf_keys = np.array([len(i.transform.times) for i in scene.instances], np.int64)
    mesh_of = np.array([i.mesh for i in scene.instances], np.int64)
    mesh_keys = np.array([len(m.point_times) for m in scene.meshes], np.int64)[mesh_of]
    deforming = np.array([m.deforming for m in scene.meshes], bool)[mesh_of]
    moving = (xf_keys > 1) | deforming
    if not moving.any():
        return 1
    return int(min(MAX_TLAS_KEYS, max(3, int(np.maximum(xf_keys, mesh_keys)[moving].max()))))


def _wp(a: np.ndarray, dtype, device):
    """A Warp array of ``a``: on the CPU the same memory (no copy; the Warp array keeps ``a`` alive), elsewhere a
    copy. Every array passed here is the upload's own (concatenated or computed), never the Scene's. At 10M
    triangles the copies cost 2 s and doubled the peak memory of the upload."""
    return wp.array(np.ascontiguousarray(a), dtype=dtype, device=device, copy=wp.get_device(device).is_cuda)


def _i32(a, device):
    return _wp(np.asarray(a, np.int32), wp.int32, device)


def _f32(a, device):
    return _wp(np.asarray(a, np.float32), wp.float32, device)


def _v3(a, device):
    a = np.asarray(a, np.float32).reshape(-1, 3)
    if len(a) == 0:
        a = np.zeros((1, 3), np.float32)
    return _wp(a, wp.vec3, device)


def _corner_table(per_mesh: list, width: int, dtype, device):
    """Per-corner values (3 per triangle) of the meshes that have them, concatenated, and per mesh the index of its
    first corner, -1 for a mesh without (``Geometry.normals`` / ``uvs``)."""
    off, parts, n = [], [], 0
    for values in per_mesh:
        off.append(n if values is not None else -1)
        if values is not None:
            parts.append(np.asarray(values, np.float32).reshape(-1, width))
            n += len(parts[-1])
    table = np.concatenate(parts) if parts else np.zeros((1, width), np.float32)
    return _wp(table, dtype, device), _i32(off or [-1], device)


def upload_csg(g: Geometry, scene: Scene, device: str = "cpu") -> None:
    """The CSG group tables of ``accel.csg``: per instance its group and operand, per group its members."""
    groups = [inst.csg_group for inst in scene.instances]
    g.inst_csg = _i32(groups or [-1], device)
    g.inst_csg_operand = _i32([inst.csg_operand for inst in scene.instances] or [0], device)
    ng = len(scene.csg_operations)
    members = [[i for i, grp in enumerate(groups) if grp == k] for k in range(ng)]
    g.csg_groups = ng
    g.csg_op = _i32([CSG_OPERATIONS[op] for op in scene.csg_operations] or [0], device)
    g.csg_operands = _i32([1 + max([scene.instances[i].csg_operand for i in m] or [0]) for m in members] or [0],
                          device)
    g.csg_count = _i32([len(m) for m in members] or [0], device)
    g.csg_first = _i32(np.cumsum([0] + [len(m) for m in members])[:-1] if ng else [0], device)
    g.csg_members = _i32([i for m in members for i in m] or [0], device)


def _translate_only(xf: MotionTransform) -> bool:
    """A moving transform whose keys share one rotation and one scale (only the translation moves)."""
    return xf.num_keys > 1 and bool(np.all(xf.rotation == xf.rotation[0]) and np.all(xf.scale == xf.scale[0]))


def direct_instance(scene: Scene, lo: np.ndarray, hi: np.ndarray) -> int:
    """The instance the walks visit outside the top level (``Geometry.direct_inst``), or -1: the still one, outside
    CSG and visible all the shutter, with the largest world box, if that box has at least the surface area of all
    the others' together (``lo, hi``: (N, 3) world boxes at the shutter's start). None in a scene with light
    linking, whose shadow walk goes through the top level alone (``lights.linking``)."""
    if any(lt.illuminates is not None or lt.casts_shadow is not None for lt in scene.lights):
        return -1
    d = np.maximum(hi.astype(np.float64) - lo, 0.0)
    area = d[:, 0] * d[:, 1] + d[:, 1] * d[:, 2] + d[:, 2] * d[:, 0]
    ok = np.array([len(i.transform.times) == 1 and i.csg_group < 0 and i.visible_from <= 0.0 and i.visible_to >= 1.0
                   for i in scene.instances], bool)
    if not ok.any():
        return -1
    best = int(np.argmax(np.where(ok, area, -1.0)))  # the first of the largest, as the loop this replaces
    best_area = area[best]
    if best_area < area.sum() - best_area:
        return -1
    return best


@dataclass
class EmbreeMeshes:
    """What ``embree_meshes`` built: per mesh, the Embree scene (0: none) and whether it answers shadow rays too."""

    owner: object  # the ``embree.EmbreeScenes`` the handles point into, or None
    handles: np.ndarray  # (M,) uint64
    shadow: np.ndarray  # (M,) int32
    geoms: list  # per mesh: its Embree geometries' codes (``quads.embree_triangle``), or None

    @property
    def nbytes(self) -> int:
        return self.owner.nbytes if self.owner is not None else 0


def embree_meshes(scene: Scene, shapes: list, device: str = "cpu", points: np.ndarray | None = None,
                  vert_off: np.ndarray | None = None, triangles: np.ndarray | None = None,
                  tri_off: np.ndarray | None = None) -> EmbreeMeshes:
    """Embree scenes for the still triangle meshes (``accel.embree``); with opaque materials only, their shadow
    rays too. Without Embree every handle is 0 and the walks are all ours. ``points`` and ``triangles``: every
    mesh's points and triangles concatenated (mesh i's from ``vert_off[i]`` and ``tri_off[i]``), the points with a
    row of padding after the last, which Embree then reads in place (the upload's own arrays, kept alive by the
    handles' owner too)."""
    lib = embree.library() if device == "cpu" else None
    handles = np.zeros(max(1, len(scene.meshes)), np.uint64)
    shadow = np.zeros(max(1, len(scene.meshes)), np.int32)
    owner = None
    geoms = [None] * len(scene.meshes)
    if lib is not None:
        opaque = np.array([opaque_for_shadows(m) for m in scene.materials] or [True], bool)
        for mi, (mesh, shape) in enumerate(zip(scene.meshes, shapes)):
            if shape is not None or len(mesh.point_times) != 1 or not len(mesh.triangles):
                continue
            if owner is None:
                owner = embree.EmbreeScenes(lib)
            if points is not None:
                handles[mi], geoms[mi] = owner.add_mesh(
                    points[vert_off[mi]:vert_off[mi] + mesh.points.shape[1]],
                    triangles[tri_off[mi]:tri_off[mi] + len(mesh.triangles)], shared=True)
            else:
                handles[mi], geoms[mi] = owner.add_mesh(mesh.points[0], mesh.triangles)
            ids = np.asarray(mesh.material_ids)
            known = bool(((ids >= 0) & (ids < len(scene.materials))).all())
            shadow[mi] = int(handles[mi] != 0 and known and bool(opaque[ids].all()))
    return EmbreeMeshes(owner, handles, shadow, geoms)


def _walked_by_embree(scene: Scene, em: EmbreeMeshes, o2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two (M,) bool arrays over the meshes: ``by_embree``, Embree answers every walk of the mesh (closest hits and
    shadows) and no CSG group holds it (CSG walks are ours), so the tree of ours we upload for it is one leaf, never
    walked; and ``identity_placed``, of those the ones whose instances are all still at the identity (``o2w``:
    each instance's matrix at time 0), whose root box is their world box, so no full tree of ours is built for
    them at all (for the others one is built only to place their instances from a cut of it)."""
    m = len(scene.meshes)
    by_embree = (em.handles[:m] != 0) & (em.shadow[:m] != 0)
    if not scene.instances:
        return by_embree, by_embree.copy()
    mesh_of = np.array([i.mesh for i in scene.instances], np.int64)
    csg = np.array([i.csg_group >= 0 for i in scene.instances], bool)
    placed = np.array([i.transform.num_keys == 1 for i in scene.instances], bool) & \
        np.all(o2w == np.eye(4), axis=(1, 2))
    by_embree[np.unique(mesh_of[csg])] = False
    identity_placed = by_embree.copy()
    identity_placed[np.unique(mesh_of[~placed])] = False
    return by_embree, identity_placed


def upload_geometry(scene: Scene, device: str = "cpu") -> tuple[Geometry, GeometryStats]:
    """Build both BVH levels of a scene and upload everything a ray needs."""
    import time

    t_start = time.perf_counter()
    blas: list[Bvh] = []
    wide: list[WideBvh] = []
    shapes = analytic_shapes(realize_tessellations(scene))  # a stand-in that cannot be its shape gets triangles
    n_verts = np.cumsum([0] + [m.points.shape[0] * m.points.shape[1] for m in scene.meshes])
    # every mesh's points, and a row of padding that lets Embree read the last vertex 16 bytes at a time
    points = np.concatenate([m.points.reshape(-1, 3) for m in scene.meshes]
                            + [np.zeros((1, 3), np.float32)]).astype(np.float32, copy=False)
    n_tris = np.cumsum([0] + [len(m.triangles) for m in scene.meshes])
    triangles = np.concatenate([m.triangles for m in scene.meshes] or [np.zeros((1, 3), np.int32)]).astype(
        np.int32, copy=False)
    em = embree_meshes(scene, shapes, device, points, n_verts, triangles, n_tris)
    o2w = matrices_at([inst.transform for inst in scene.instances], 0.0) if scene.instances else np.eye(4)[None]
    by_embree, identity_placed = _walked_by_embree(scene, em, o2w)
    walked: list[Bvh] = []  # the trees uploaded, walked by our kernels (``blas`` is for placing instances)
    for mi, (mesh, shape) in enumerate(zip(scene.meshes, shapes)):
        if by_embree[mi]:  # uploaded: one leaf over the mesh's box (never walked)
            pts = mesh.points[0]
            walked.append(build_bvh(pts.min(axis=0)[None], pts.max(axis=0)[None], max_leaf=1))
            wide.append(collapse(walked[-1], device))
            if identity_placed[mi]:  # the root box places its instances exactly
                blas.append(walked[-1])
                continue
        if shape is not None and shape.kind not in CLOUD_KINDS:  # one leaf holding the shape's box (walks test
            # the shape, never this leaf's triangle)
            lo, hi = (np.asarray(b * SHAPE_BOX_PAD, np.float32)[None, None] for b in shape_bounds(shape))
        else:
            lo, hi = _mesh_prim_bounds(mesh, device)
        if shape is None and len(mesh.point_times) == 1:  # still triangles: leaves tested four at a time
            max_leaf, c_trav, merge_leaf = STILL_MAX_LEAF, STILL_TRAVERSAL_COST, STILL_MERGE_LEAF
        else:
            max_leaf, c_trav, merge_leaf = BLAS_MAX_LEAF, BLAS_TRAVERSAL_COST, BLAS_MERGE_LEAF
        blas.append(build_bvh(lo, hi, max_leaf=max_leaf, c_trav=c_trav))
        if not by_embree[mi]:
            walked.append(blas[-1])
            wide.append(collapse(blas[-1], device, merge_leaf=merge_leaf))

    g = Geometry()
    nodes = [quantize(w, device) for w in wide]
    n_nodes = np.cumsum([0] + [w.num_nodes for w in wide])
    n_records = np.cumsum([0] + [len(q) for q in nodes])
    n_keys = np.cumsum([0] + [len(m.point_times) for m in scene.meshes])

    def cat(xs, shape, dt):
        return np.concatenate(xs).astype(dt, copy=False) if xs else np.zeros(shape, dt)

    g.points = _v3(points, device)  # the same memory on the CPU, where Embree reads it too
    g.point_times = _f32(cat([m.point_times for m in scene.meshes], (1,), np.float32), device)
    g.tri_vidx = _wp(triangles, wp.vec3i, device)  # the same memory on the CPU, where Embree reads it too
    g.tri_material = _i32(cat([m.material_ids for m in scene.meshes], (1,), np.int32), device)
    # per-corner normals and uvs of the meshes that have them (others take no memory: 60 bytes per triangle), and
    # the colours of the meshes whose displayColor varies
    g.normals, g.mesh_normal_off = _corner_table([m.normals for m in scene.meshes], 3, wp.vec3, device)
    g.uvs, g.mesh_uv_off = _corner_table([m.uvs for m in scene.meshes], 2, wp.vec2, device)
    g.colors, g.mesh_color_off = _corner_table([m.colors for m in scene.meshes], 3, wp.vec3, device)
    # Warp's own allocation, 64-byte aligned, so that each record is one cache line (a NumPy buffer, which ``_wp``
    # would wrap, is only 16-byte aligned)
    g.blas_node = wp.array(np.concatenate(nodes) if nodes else np.zeros(1, QNODE_DTYPE), dtype=QNode, device=device,
                           copy=True)
    g.blas_prim = _i32(cat([b.prim_order for b in walked], (1,), np.int32), device)
    v0, e1, e2 = [], [], []
    for mesh, b, shape in zip(scene.meshes, walked, shapes):
        if shape is not None and shape.kind in CLOUD_KINDS:  # per slot: centre (still clouds), radius, disc normal
            z = np.zeros((len(b.prim_order), 3), np.float32)
            radius = z.copy()
            radius[:, 0] = mesh.point_radii[b.prim_order]
            v0.append(mesh.points[0][b.prim_order] if len(mesh.point_times) == 1 else z), e1.append(radius)
            e2.append(np.ascontiguousarray(mesh.normals[b.prim_order, 0], np.float32) if shape.kind == "discs" else z)
        elif len(mesh.point_times) == 1 and len(b.prim_order):
            p0, d1, d2 = leaf_triangles(mesh.points[0], mesh.triangles, b.prim_order, device)  # leaf order
            v0.append(p0), e1.append(d1), e2.append(d2)
        else:  # deforming: interpolated at the ray's time instead
            z = np.zeros((len(b.prim_order), 3), np.float32)
            v0.append(z), e1.append(z), e2.append(z)
    g.leaf_v0 = _v3(cat(v0, (1, 3), np.float32), device)
    g.leaf_e1 = _v3(cat(e1, (1, 3), np.float32), device)
    g.leaf_e2 = _v3(cat(e2, (1, 3), np.float32), device)
    prim_off = np.cumsum([0] + [len(b.prim_order) for b in walked])
    g.mesh_node_off = _i32(n_records[:-1], device)
    g.mesh_prim_off = _i32(prim_off[:-1], device)
    g.mesh_tri_off = _i32(n_tris[:-1], device)
    g.mesh_vert_off = _i32(n_verts[:-1], device)
    g.mesh_nverts = _i32([m.points.shape[1] for m in scene.meshes] or [0], device)
    g.mesh_key_off = _i32(n_keys[:-1], device)
    g.mesh_nkeys = _i32([len(m.point_times) for m in scene.meshes] or [1], device)
    solid = [m.solid if m.solid is not None else np.full(len(m.triangles), is_closed(m.triangles, m.points[0]))
             for m in scene.meshes]
    g.tri_solid = _i32(cat(solid, (1,), np.int32), device)
    codes, axes, params = shape_table(shapes)
    g.mesh_shape = _i32(codes if len(codes) else [0], device)
    g.mesh_shape_axis = _i32(axes if len(axes) else [0], device)
    g.mesh_shape_param = _wp(params if len(params) else np.zeros((1, 4), np.float32), wp.vec4, device)
    g.mesh_embree = wp.array(em.handles, dtype=wp.uint64, device=device)
    g.mesh_embree_shadow = _i32(em.shadow, device)
    g.embree_geoms = _i32(cat([c for c in em.geoms if c is not None], (1,), np.int32), device)
    n_geoms = np.cumsum([0] + [0 if c is None else len(c) for c in em.geoms])
    g.mesh_embree_geom_off = _i32(n_geoms[:-1] if len(em.geoms) else [0], device)
    g.embree_closest_fn = wp.uint64(em.owner.closest_fn if em.owner else 0)
    g.embree_occluded_fn = wp.uint64(em.owner.occluded_fn if em.owner else 0)
    object.__setattr__(g, "embree_owner", em.owner)  # the handles above point into it: it lives as long as g

    # --- top level over instances, boxes on a uniform grid of time keys
    nk = _tlas_key_count(scene)
    ninst = len(scene.instances)
    lo = np.empty((nk, ninst, 3), np.float32)
    hi = np.empty((nk, ninst, 3), np.float32)
    still = np.array([nk == 1 or (inst.transform.num_keys == 1 and len(scene.meshes[inst.mesh].point_times) == 1)
                      for inst in scene.instances], bool)
    cuts = {}  # mesh -> the node boxes its instances are placed from (instance_bounds)

    def cut(mi: int) -> np.ndarray:
        if mi not in cuts:
            cuts[mi] = box_cut(blas[mi], cut_size(ninst))
        return cuts[mi]

    if still.any():  # instance_key_bounds of the still instances in batches: their box at time 0 at every key
        idx = np.nonzero(still)[0]
        mesh_of = np.array([scene.instances[i].mesh for i in idx], np.int64)
        wlo, whi = np.empty((len(idx), 3)), np.empty((len(idx), 3))
        for mi in np.unique(mesh_of):
            j = np.nonzero(mesh_of == mi)[0]
            wlo[j], whi[j] = still_world_boxes(o2w[idx[j]], blas[mi], cut(mi))
            shape = shapes[mi]
            if shape is not None and shape.kind not in CLOUD_KINDS:  # an exact shape: the box of the shape itself
                elo, ehi = shape_world_boxes(shape, o2w[idx[j]])
                wlo[j], whi[j] = np.maximum(wlo[j], elo), np.minimum(whi[j], ehi)
        lo[:, idx], hi[:, idx] = wlo[None], whi[None]
    for i in np.nonzero(~still)[0]:
        inst = scene.instances[i]
        mesh = scene.meshes[inst.mesh]
        klo, khi = instance_key_bounds(inst, blas[inst.mesh], mesh.point_times.astype(np.float64), nk,
                                       cut(inst.mesh))
        lo[:, i], hi[:, i] = klo, khi
    direct = direct_instance(scene, lo[0], hi[0])  # walked outside the top level
    others = np.array([i for i in range(ninst) if i != direct], np.int64)
    # one instance per leaf: visiting an instance (its transform, its mesh's root) costs far more than a box test,
    # so each gets its own box in its parent (demo scene 4 % faster, production and motion within noise)
    olo, ohi = lo[:, others], hi[:, others]  # (K, len(others), 3)
    tlas = collapse(build_bvh(olo, ohi, max_leaf=1), device)
    g.tlas_box = box_records(tlas.box, device)
    g.tlas_child = wp.array(tlas.child, dtype=wp.vec4i, device=device)
    g.tlas_root = _v3(root_boxes(olo, ohi), device)  # its slab test spares a ray that passes by every instance
    g.tlas_prim = _i32(others[tlas.prim_order] if len(tlas.prim_order) else [0], device)  # instance indices
    g.tlas_nkeys = nk
    g.direct_inst = direct
    g.tlas_others = len(others)

    keys, offs, counts = upload_keys([inst.transform for inst in scene.instances], device)
    g.keys = keys
    g.inst_mesh = _i32([inst.mesh for inst in scene.instances] or [0], device)
    g.inst_xf_off = _i32(offs if ninst else [0], device)
    g.inst_xf_count = _i32(counts if ninst else [1], device)
    w2o = np.linalg.inv(o2w).astype(np.float32)
    g.inst_o2w = wp.array(o2w.astype(np.float32), dtype=wp.mat44, device=device)
    g.inst_w2o = wp.array(w2o, dtype=wp.mat44, device=device)
    g.direct_identity = int(direct >= 0 and np.array_equal(w2o[direct], np.eye(4)))
    g.inst_translate_only = _i32([int(_translate_only(inst.transform)) for inst in scene.instances] or [0], device)
    g.inst_vis_from = _f32([inst.visible_from for inst in scene.instances] or [0.0], device)
    g.inst_vis_to = _f32([inst.visible_to for inst in scene.instances] or [1.0], device)
    upload_csg(g, scene, device)

    leaf_bytes = 3 * 12 * sum(len(x) for x in v0)  # the leaf-ordered still triangles
    nbytes = (sum(q.nbytes for q in nodes) + sum(b.prim_order.nbytes for b in walked) + tlas.nbytes + leaf_bytes
              + em.nbytes + 4 * int(n_geoms[-1]))
    stats = GeometryStats(
        triangles=int(n_tris[-1]),
        blas_nodes=int(n_nodes[-1]),
        tlas_nodes=tlas.num_nodes,
        tlas_keys=nk,
        build_seconds=time.perf_counter() - t_start,
        nbytes=int(nbytes),
        embree_nbytes=int(em.nbytes),
    )
    return g, stats
