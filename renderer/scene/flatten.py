"""Merging still instances into one world-space mesh before the hierarchy is built.

A ray pays for every instance it visits: a top-level leaf, a transform into object space, a separate
bottom-level walk. Geometry that does not move gains nothing from that, so still instances whose mesh is not
shared are transformed into world space once and merged into a single mesh with one BVH. Moving and deforming
instances, and every mesh used by more than one instance, stay instanced.

Shared meshes were copied too, up to 1024 triangles each and 8 M in all. Measured (``drt`` kernels, 640x360,
16 spp, 2 threads, merged against instanced in one process): a PointInstancer of 100 000 rocks of 192 triangles
prepared in 17.8 s instead of 2.3 s (an 8.4 M-triangle merged mesh and its hierarchy, 3 GB) and rendered in
10.3 s instead of 8.5 s; 10 000 rocks 3.6 s / 4.4 s against 0.5 s / 4.1 s; 100 000 eight-triangle pieces 11.0
s / 8.1 s against 2.1 s / 6.7 s; 30 rocks on a ground and 10 000 pieces within the noise; 10 000 spheres, cubes,
cylinders and cones of 500 sizes (``bench/geometry_bench.py``'s prims, whose cubes were copied) 3-4 % faster to
render (320x180, 16 spp, one thread), 0.5 s slower to prepare (2500 more instances, 480 more small hierarchies). A
small shared mesh's hierarchy stays in cache, the merged one's does not: copies never rendered faster.
Emissive instances keep lighting: their light is redirected to the range of merged triangles they became (one of
them at most: the others stay instanced).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from renderer.motion.transform import MotionTransform, matrix_at
from renderer.scene.analytic import analytic_shapes, realize_tessellations
from renderer.scene.mesh_facts import is_closed
from renderer.scene.model import LIGHT_MESH, Instance, Mesh, Scene


def _is_still(scene: Scene, inst: Instance, analytic: list) -> bool:
    """Still and plain: meshes with per-corner colours stay instanced (the merged mesh carries none), and so do
    analytic shapes (``scene.analytic``: a transformed sphere or cylinder is intersected in its own object space)."""
    mesh = scene.meshes[inst.mesh]
    return (inst.transform.num_keys == 1 and not mesh.deforming and mesh.colors is None
            and inst.visible_from <= 0.0 and inst.visible_to >= 1.0 and inst.csg_group < 0
            and analytic[inst.mesh] is None)


def flatten_still_instances(scene: Scene) -> Scene:
    """An equivalent scene in which mergeable still instances form one world-space mesh (instance 0)."""
    if any(lt.illuminates is not None or lt.casts_shadow is not None for lt in scene.lights):
        return scene  # light linking is per instance: merging would lose which instance is which
    one_sided = {lt.instance for lt in scene.lights if lt.kind == LIGHT_MESH and lt.uniform}  # MeshLightAPI
    users = np.bincount([i.mesh for i in scene.instances], minlength=len(scene.meshes))
    analytic = analytic_shapes(realize_tessellations(scene))  # a stand-in that cannot be its shape is merged as
    # the triangles it stands for
    # an instance has one mesh light (``Lights.inst_light``: the light whose pdf weights a hit's emission and whose
    # group labels it), so one emissive instance at most joins the merged mesh: a second would be taken for the first
    emissive = {lt.instance for lt in scene.lights if lt.kind == LIGHT_MESH}
    merge, keep = [], []
    merged_emitter = False
    for idx, inst in enumerate(scene.instances):
        ok = idx not in one_sided and users[inst.mesh] == 1 and _is_still(scene, inst, analytic)
        if ok and idx in emissive:
            ok, merged_emitter = not merged_emitter, True
        (merge if ok else keep).append(idx)
    if len(merge) <= 1:
        return scene

    points, tris, mats, normals, uvs, solid = [], [], [], [], [], []
    ranges = {}  # old instance -> (first, end) triangle of the merged mesh
    has_normals = any(scene.meshes[scene.instances[i].mesh].normals is not None for i in merge)
    has_uvs = any(scene.meshes[scene.instances[i].mesh].uvs is not None for i in merge)
    nvert = ntri = 0
    for idx in merge:
        inst = scene.instances[idx]
        mesh = scene.meshes[inst.mesh]
        m = matrix_at(inst.transform, 0.0)
        p = mesh.points[0].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        points.append(p.astype(np.float32))
        tris.append(mesh.triangles + nvert)
        mats.append(mesh.material_ids)
        t = len(mesh.triangles)
        closed = mesh.solid is None and is_closed(mesh.triangles, mesh.points[0])
        solid.append(mesh.solid if mesh.solid is not None else np.full(t, closed))
        if has_normals:
            if mesh.normals is not None:
                nm = np.linalg.inv(m[:3, :3]).T  # normals transform by the inverse transpose
                normals.append((mesh.normals.reshape(-1, 3) @ nm.T).reshape(t, 3, 3).astype(np.float32))
            else:  # flat: the geometric normal at every corner
                v = p[mesh.triangles]
                n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
                normals.append(np.repeat(n[:, None, :], 3, 1).astype(np.float32))
        if has_uvs:
            uvs.append(mesh.uvs if mesh.uvs is not None else np.zeros((t, 3, 2), np.float32))
        ranges[idx] = (ntri, ntri + t)
        nvert += len(p)
        ntri += t
    merged = Mesh(
        name="<merged still geometry>",
        point_times=np.zeros(1, np.float32),
        points=np.concatenate(points)[None],
        triangles=np.concatenate(tris).astype(np.int32),
        material_ids=np.concatenate(mats).astype(np.int32),
        normals=np.concatenate(normals) if has_normals else None,
        uvs=np.concatenate(uvs) if has_uvs else None,
        solid=np.concatenate(solid).astype(bool),
        # which instance each triangle was (Cryptomatte and ids name the instances merged here)
        source_instance=np.concatenate([np.full(b - a, idx, np.int32) for idx, (a, b) in ranges.items()]),
    )
    meshes = list(scene.meshes) + [merged]
    instances = [Instance(len(meshes) - 1, MotionTransform.static(np.eye(4)), name="<merged>")]
    new_index = {}
    for idx in keep:
        new_index[idx] = len(instances)
        instances.append(scene.instances[idx])
    lights = []
    for light in scene.lights:
        if light.kind == LIGHT_MESH and light.instance in ranges:
            light = replace(light, instance=0, triangles=ranges[light.instance])
        elif light.kind == LIGHT_MESH:
            light = replace(light, instance=new_index[light.instance])
        lights.append(light)
    # meshes no instance uses any more are dropped by reindexing
    used = sorted({i.mesh for i in instances})
    remap = {old: new for new, old in enumerate(used)}
    instances = [replace(i, mesh=remap[i.mesh]) for i in instances]
    return replace(scene, meshes=[meshes[i] for i in used], instances=instances, lights=lights,
                   instance_sources=tuple([-1] + keep))
