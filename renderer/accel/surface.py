"""The surface at a hit: position, normals, uv, tangent and material of the triangle or shape a ray found, at the
sample's time (``SurfacePoint``); the hit's geometry in object and world space for inputs driven by it; the
per-corner displayColor; the shading normal with the material's normal map applied.
"""
from __future__ import annotations

import warp as wp

from renderer.accel.analytic import SHAPE_DISCS, SHAPE_POINTS, shape_normal
from renderer.accel.intersect import (
    Geometry,
    corner_index,
    instance_object_to_world,
    instance_world_to_object,
    mesh_keys_at,
    mesh_vertex,
    triangle_points,
)
from renderer.accel.occlusion import hit_uv
from renderer.shading.materials import HitGeometry, Materials, MaterialSample, apply_normal_map, triangle_tangent
from renderer.shading.raycone import uv_density

# Rendering needs no gradients: no adjoint code.
wp.set_module_options({"enable_backward": False})


@wp.struct
class SurfacePoint:
    p: wp.vec3  # world position
    ng: wp.vec3  # geometric normal, facing the incoming ray
    ns: wp.vec3  # shading normal, same hemisphere as ng
    tangent: wp.vec4  # world dP/du and uv handedness (w = 0: no usable uvs), for normal maps
    uv: wp.vec2  # st at the hit, NaN where the mesh has none
    uv_density: float  # sqrt(uv area / world area) of the triangle (ray cones: raycone.uv_footprint)
    front: int  # 1 when the ray hit the side the triangle's winding faces (entering a closed solid)
    material: int


@wp.func
def surface_at(geo: Geometry, inst: int, tri: int, b1: float, b2: float, ng_hit: wp.vec3, ro: wp.vec3, rd: wp.vec3,
               t: float, s: float):
    """Position, normals, uv and tangent of a hit at time s (vertices and transform at that instant). ``ng_hit``
    is the hit's object-space (p1 - p0) x (p2 - p0) where the walk had it (``Hit.ng``), else 0."""
    m = geo.inst_mesh[inst]
    w2o = instance_world_to_object(geo, inst, s)
    w2o_t = wp.transpose(w2o)  # normals transform by the inverse transpose
    kind = geo.mesh_shape[m]
    analytic = kind > 0
    p0 = wp.vec3(0.0)
    p1 = wp.vec3(0.0)
    p2 = wp.vec3(0.0)
    ng = wp.vec3(0.0)
    if kind == SHAPE_DISCS:  # a disc of a point cloud: its normal (the point's, in the per-corner table)
        ng = wp.normalize(wp.transform_vector(w2o_t, geo.normals[corner_index(geo, geo.mesh_normal_off, m, tri)]))
    elif kind == SHAPE_POINTS:  # a sphere of a point cloud: outward from its centre at the hit's time
        pk0, pk1, pu = mesh_keys_at(geo, m, s)
        centre = mesh_vertex(geo, m, pk0, pk1, pu, geo.tri_vidx[tri][0])
        ng = wp.normalize(wp.transform_vector(w2o_t, wp.transform_point(w2o, ro + rd * t) - centre))
    elif analytic:  # an exact shape: the normal of the piece crossed (b1) at the object-space hit point
        po = wp.transform_point(w2o, ro + rd * t)
        no = shape_normal(kind, geo.mesh_shape_axis[m], geo.mesh_shape_param[m], po, int(b1))
        ng = wp.normalize(wp.transform_vector(w2o_t, no))
    elif geo.mesh_uv_off[m] < 0 and (ng_hit[0] != 0.0 or ng_hit[1] != 0.0 or ng_hit[2] != 0.0):
        # Embree's normal of the triangle it hit: without uvs (no tangent, no ray-cone density) nothing else needs
        # the corners, whose index and three vertex reads missed the cache on most hits of a large mesh (the
        # heavy scene renders about 6 % faster)
        ng = wp.normalize(wp.transform_vector(w2o_t, ng_hit))
    else:
        k0, k1, u = mesh_keys_at(geo, m, s)
        p0, p1, p2 = triangle_points(geo, m, tri - geo.mesh_tri_off[m], k0, k1, u)
        ng = wp.normalize(wp.transform_vector(w2o_t, wp.cross(p1 - p0, p2 - p0)))
    b0 = 1.0 - b1 - b2
    ns = ng
    nc = corner_index(geo, geo.mesh_normal_off, m, tri)
    if nc >= 0 and not analytic:
        n = geo.normals[nc] * b0 + geo.normals[nc + 1] * b1 + geo.normals[nc + 2] * b2
        nw = wp.transform_vector(w2o_t, n)
        if wp.length(nw) > 0.0:
            ns = wp.normalize(nw)
    if wp.dot(ns, ng) < 0.0:  # keep the shading normal on the geometric normal's side
        ns = -ns
    sp = SurfacePoint()
    sp.uv = hit_uv(geo, m, tri, b1, b2)
    sp.tangent = wp.vec4(0.0)
    sp.uv_density = 0.0
    uc = corner_index(geo, geo.mesh_uv_off, m, tri)
    if uc >= 0:
        # from world-space corners, so a mirroring transform is accounted for in the handedness
        o2w = instance_object_to_world(geo, inst, s)  # (only here: a moving instance's keys are looked up again)
        w0 = wp.transform_point(o2w, p0)
        w1 = wp.transform_point(o2w, p1)
        w2 = wp.transform_point(o2w, p2)
        sp.tangent = triangle_tangent(w0, w1, w2, geo.uvs[uc], geo.uvs[uc + 1], geo.uvs[uc + 2])
        sp.uv_density = uv_density(w0, w1, w2, geo.uvs[uc], geo.uvs[uc + 1], geo.uvs[uc + 2])
    sp.front = 1
    if wp.dot(ng, rd) > 0.0:  # hit from behind: both normals face the viewer, and we are leaving
        ng = -ng
        ns = -ns
        sp.front = 0
    sp.p = ro + rd * t
    sp.ng = ng
    sp.ns = ns
    sp.material = geo.tri_material[tri]
    return sp


@wp.func
def perpendicular(n: wp.vec3):
    """A unit vector perpendicular to unit n (the tangent of a hit without uvs)."""
    a = wp.vec3(1.0, 0.0, 0.0)
    if wp.abs(n[0]) > 0.9:
        a = wp.vec3(0.0, 1.0, 0.0)
    return wp.normalize(wp.cross(n, a))


@wp.func
def hit_geometry(geo: Geometry, inst: int, sp: SurfacePoint, s: float, width: float):
    """The hit's position, front-side shading normal and tangent in object and world space (``HitGeometry``,
    for inputs driven by them), ``width`` the ray cone's width there."""
    hg = HitGeometry()
    hg.valid = 1
    hg.width = width
    w2o = instance_world_to_object(geo, inst, s)
    o2w = instance_object_to_world(geo, inst, s)
    n = sp.ns
    if sp.front == 0:
        n = -n
    t = wp.vec3(sp.tangent[0], sp.tangent[1], sp.tangent[2])
    t = t - n * wp.dot(n, t)
    if sp.tangent[3] == 0.0 or wp.length(t) < 1.0e-8:
        t = perpendicular(n)
    hg.p_world = sp.p
    hg.n_world = n
    hg.t_world = wp.normalize(t)
    hg.p_object = wp.transform_point(w2o, sp.p)
    hg.n_object = wp.normalize(wp.transform_vector(wp.transpose(o2w), n))
    hg.t_object = wp.normalize(wp.transform_vector(w2o, hg.t_world))
    return hg


@wp.func(inline=True)  # once per hit: no copy of the big structs
def display_diffuse(geo: Geometry, mats: Materials, mat_id: int, inst: int, tri: int, b1: float, b2: float,
                    diffuse: wp.vec3):
    """The diffuse colour at a hit: the mesh's per-corner displayColor (times the material's scale) where the
    material's diffuse is the displayColor and the mesh has one that varies, else ``diffuse``."""
    ds = mats.display_scale[mat_id]
    if ds[3] == 0.0:
        return diffuse
    m = geo.inst_mesh[inst]
    c = corner_index(geo, geo.mesh_color_off, m, tri)
    if c < 0:
        return diffuse
    col = geo.colors[c] * (1.0 - b1 - b2) + geo.colors[c + 1] * b1 + geo.colors[c + 2] * b2
    out = wp.cw_mul(col, wp.vec3(ds[0], ds[1], ds[2]))
    return wp.vec3(wp.clamp(out[0], 0.0, 1.0), wp.clamp(out[1], 0.0, 1.0), wp.clamp(out[2], 0.0, 1.0))


@wp.func
def shading_normal(sp: SurfacePoint, ms: MaterialSample):
    """The shading normal facing the viewer, with the material's normal map applied."""
    if ms.has_normal_map == 0 or sp.tangent[3] == 0.0:
        return sp.ns
    # the normal map is defined on the front (winding) side
    nf = sp.ns
    if sp.front == 0:
        nf = -sp.ns
    n = apply_normal_map(nf, sp.tangent, ms.normal_ts)
    if sp.front == 0:
        n = -n
    if wp.dot(n, sp.ng) <= 0.0:  # a map tilting the normal below the surface: keep the interpolated one
        return sp.ns
    return n
