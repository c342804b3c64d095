"""Lights: the paper's light-area dimension (penumbrae). One sample per light per shading point.

Each light is placed at the sample's time (lights may move over the shutter like anything else) and a point
on it is chosen from the sample's two light dimensions by the geometric samplers of ``sampling``
(area, spherical-rectangle or cone sampling, each with its solid-angle pdf). A shadow ray toward that point
decides visibility, so a partly hidden light gives the soft shadow edge of its visible fraction.

Conventions (UsdLux): rect and disk lights emit from their front face towards local -Z; sphere and cylinder
lights from their outer surface; a distant light arrives along its local -Z within a cone of apex ``angle``;
a dome light from every direction; emissive meshes from both faces (as Cycles does).
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from .accel import Geometry, instance_object_to_world, instance_visible, mesh_keys_at, triangle_points
from .motion import matrix_at
from .motion_kernels import MotionKeys, keys_matrix, upload_keys
from .sampling import (sample_cylinder_light, sample_disk_light, sample_rect, sample_sphere_light,
                       sample_triangle_light, square_to_cosine_hemisphere, square_to_uniform_cone, to_world)
from .scene import (LIGHT_CYLINDER, LIGHT_DISK, LIGHT_DISTANT, LIGHT_DOME, LIGHT_MESH, LIGHT_RECT,
                    LIGHT_SPHERE, Scene)

DISTANT_DIST = 1.0e30  # shadow-ray length toward lights at infinity (scene units)


@wp.struct
class Lights:
    kind: wp.array(dtype=wp.int32)
    radiance: wp.array(dtype=wp.vec3)  # emitted radiance (distant of angle 0: irradiance; point: intensity)
    size: wp.array(dtype=wp.vec4)  # rect (width, height), disk/sphere (_, _, radius), cylinder (length, _,
    #                                radius), distant (cos of the half apex angle), in the light's local units
    xf_off: wp.array(dtype=wp.int32)
    xf_count: wp.array(dtype=wp.int32)
    xf_still: wp.array(dtype=wp.mat44)  # light-to-world of lights that do not move (xf_count == 1)
    keys: MotionKeys
    instance: wp.array(dtype=wp.int32)  # mesh lights: the emissive instance
    tri_base: wp.array(dtype=wp.int32)  # mesh lights: first emitting triangle of the instance's mesh
    cdf: wp.array(dtype=wp.float32)  # mesh lights: cumulative triangle power, concatenated
    cdf_off: wp.array(dtype=wp.int32)
    cdf_count: wp.array(dtype=wp.int32)
    dome: wp.vec3  # summed radiance of the dome lights (seen by rays that leave the scene)
    dome_visible: int  # 1 when camera rays see the dome (alpha 1 there)


@wp.func
def dome_radiance(lights: Lights, d: wp.vec3):
    return lights.dome


@wp.func
def pick_triangle(lights: Lights, li: int, u: float):
    """Triangle (local index) chosen with probability proportional to its emitted power, and that probability."""
    off = lights.cdf_off[li]
    n = lights.cdf_count[li]
    lo = int(0)
    hi = n - 1
    while lo < hi:  # first entry with cdf > u
        mid = (lo + hi) // 2
        if lights.cdf[off + mid] > u:
            hi = mid
        else:
            lo = mid + 1
    prev = float(0.0)
    if lo > 0:
        prev = lights.cdf[off + lo - 1]
    return lights.tri_base[li] + lo, lights.cdf[off + lo] - prev


@wp.func
def sample_light(lights: Lights, geo: Geometry, emission: wp.array(dtype=wp.vec3), li: int, p: wp.vec3,
                 n: wp.vec3, s: float, u_pick: float, u: wp.vec2):
    """Sample light ``li`` from point p (normal n) at time s.

    Returns (wi, dist, weight, ok): unit direction to the light, distance for the shadow ray, and
    radiance / pdf (solid angle) so that the estimate is f * weight * cos. Delta lights return their
    irradiance (distant) or intensity / dist^2 (point) as the weight.
    """
    kind = lights.kind[li]
    Le = lights.radiance[li]
    size = lights.size[li]
    zero = wp.vec3(0.0)
    m = lights.xf_still[li]
    if lights.xf_count[li] > 1 and kind != LIGHT_MESH and kind != LIGHT_DOME:
        m = keys_matrix(lights.keys, lights.xf_off[li], lights.xf_count[li], s)
    if kind == LIGHT_RECT or kind == LIGHT_DISK:
        ex = wp.transform_vector(m, wp.vec3(1.0, 0.0, 0.0))
        ey = wp.transform_vector(m, wp.vec3(0.0, 1.0, 0.0))
        front = -wp.normalize(wp.cross(ex, ey))  # emits towards local -Z
        if kind == LIGHT_RECT:
            corner = wp.transform_point(m, wp.vec3(-0.5 * size[0], -0.5 * size[1], 0.0))
            g = sample_rect(p, corner, ex * size[0], ey * size[1], u)
        else:
            g = sample_disk_light(p, wp.transform_point(m, wp.vec3(0.0)), front, size[2] * wp.length(ex), u)
        if g.pdf > 0.0 and wp.dot(g.dir, front) < 0.0:
            return g.dir, g.dist, Le / g.pdf, True
        return zero, 0.0, zero, False
    if kind == LIGHT_SPHERE:
        c = wp.transform_point(m, wp.vec3(0.0))
        r = size[2] * wp.length(wp.transform_vector(m, wp.vec3(1.0, 0.0, 0.0)))
        if r <= 0.0:  # point light: radiance holds the intensity (W/sr-like)
            d = c - p
            dist = wp.length(d)
            if dist <= 0.0:
                return zero, 0.0, zero, False
            return d / dist, dist, Le / (dist * dist), True
        g = sample_sphere_light(p, c, r, u)
        if g.pdf > 0.0:
            return g.dir, g.dist, Le / g.pdf, True
        return zero, 0.0, zero, False
    if kind == LIGHT_CYLINDER:
        ax = wp.transform_vector(m, wp.vec3(1.0, 0.0, 0.0))
        ry = wp.length(wp.transform_vector(m, wp.vec3(0.0, 1.0, 0.0)))
        g = sample_cylinder_light(p, wp.transform_point(m, wp.vec3(0.0)), wp.normalize(ax),
                                  size[0] * wp.length(ax), size[2] * ry, u)
        if g.pdf > 0.0 and wp.dot(g.dir, g.normal) < 0.0:
            return g.dir, g.dist, Le / g.pdf, True
        return zero, 0.0, zero, False
    if kind == LIGHT_DISTANT:
        to_light = wp.normalize(wp.transform_vector(m, wp.vec3(0.0, 0.0, 1.0)))
        cos_max = size[0]
        if cos_max >= 1.0:
            return to_light, DISTANT_DIST, Le, True
        wi = to_world(square_to_uniform_cone(u, cos_max), to_light)
        pdf = 1.0 / (2.0 * wp.pi * (1.0 - cos_max))
        return wi, DISTANT_DIST, Le * (1.0 / pdf), True
    if kind == LIGHT_DOME:
        wi = to_world(square_to_cosine_hemisphere(u), n)
        cos_n = wp.dot(wi, n)
        if cos_n <= 0.0:
            return zero, 0.0, zero, False
        return wi, DISTANT_DIST, Le * (wp.pi / cos_n), True
    # emissive mesh: a triangle by power, a point on it by area
    inst = lights.instance[li]
    if not instance_visible(geo, inst, s):
        return zero, 0.0, zero, False
    tri, p_tri = pick_triangle(lights, li, u_pick)
    mesh = geo.inst_mesh[inst]
    k0, k1, ku = mesh_keys_at(geo, mesh, s)
    p0, p1, p2 = triangle_points(geo, mesh, tri, k0, k1, ku)
    o2w = instance_object_to_world(geo, inst, s)
    g = sample_triangle_light(p, wp.transform_point(o2w, p0), wp.transform_point(o2w, p1),
                              wp.transform_point(o2w, p2), u)
    pdf = g.pdf * p_tri
    if pdf > 0.0:
        Le_tri = emission[geo.tri_material[geo.mesh_tri_off[mesh] + tri]]
        return g.dir, g.dist, Le_tri / pdf, True
    return zero, 0.0, zero, False


def _luminance(rgb) -> float:
    return float(0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2])


def upload_lights(scene: Scene, device: str = "cpu") -> tuple[Lights, int]:
    """Lights of a scene for the kernels; returns the struct and the number of lights."""
    kinds, radiance, size, insts, cdfs, bases = [], [], [], [], [], []
    transforms = []
    dome = np.zeros(3)
    dome_visible = 0
    for light in scene.lights:
        rad = np.asarray(light.radiance, np.float64)
        cdf = np.zeros(1, np.float32)
        first = 0
        if light.kind == LIGHT_MESH:
            inst = scene.instances[light.instance]
            mesh = scene.meshes[inst.mesh]
            first, end = light.triangles or (0, len(mesh.triangles))
            pts = mesh.points[0].astype(np.float64)
            tri = pts[mesh.triangles[first:end]]
            area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
            emis = np.array([_luminance(scene.materials[m].emissive_color) for m in mesh.material_ids[first:end]])
            power = area * np.maximum(emis, 0.0)
            if not np.isfinite(power).all() or power.sum() <= 0:
                continue
            cdf = (np.cumsum(power) / power.sum()).astype(np.float32)
            cdf[-1] = 1.0
            sz = (0.0, 0.0, 0.0, 0.0)
        elif light.kind == LIGHT_DISTANT:
            half = math.radians(max(0.0, light.angle) * 0.5)
            cos_max = math.cos(half) if half > 1e-6 else 1.0
            sz = (cos_max, 0.0, 0.0, 0.0)
            if cos_max < 1.0:  # the disk of directions' radiance that gives the irradiance at normal incidence
                rad = rad / (math.pi * math.sin(half) ** 2)
        elif light.kind == LIGHT_DOME:
            dome += rad
            dome_visible |= int(light.visible_to_camera)
            sz = (0.0, 0.0, 0.0, 0.0)
        else:
            sz = (light.width, light.height, light.radius, light.length)
            if light.kind == LIGHT_CYLINDER:
                sz = (light.length, 0.0, light.radius, 0.0)
        if not np.isfinite(rad).all() or (rad <= 0).all():
            continue
        kinds.append(light.kind)
        radiance.append(rad)
        size.append(sz)
        insts.append(light.instance)
        bases.append(first)
        cdfs.append(cdf)
        transforms.append(light.transform)
    n = len(kinds)
    lt = Lights()
    lt.kind = wp.array(np.array(kinds or [LIGHT_DOME], np.int32), dtype=wp.int32, device=device)
    lt.radiance = wp.array(np.array(radiance or [[0, 0, 0]], np.float32), dtype=wp.vec3, device=device)
    lt.size = wp.array(np.array(size or [[0, 0, 0, 0]], np.float32), dtype=wp.vec4, device=device)
    keys, offs, counts = upload_keys(transforms, device)
    lt.keys = keys
    lt.xf_off = wp.array(offs if n else np.zeros(1, np.int32), dtype=wp.int32, device=device)
    lt.xf_count = wp.array(counts if n else np.ones(1, np.int32), dtype=wp.int32, device=device)
    still = [matrix_at(xf, 0.0) for xf in transforms] or [np.eye(4)]
    lt.xf_still = wp.array(np.array(still, np.float32), dtype=wp.mat44, device=device)
    lt.instance = wp.array(np.array(insts or [-1], np.int32), dtype=wp.int32, device=device)
    lt.tri_base = wp.array(np.array(bases or [0], np.int32), dtype=wp.int32, device=device)
    lens = [len(c) for c in cdfs] or [1]
    lt.cdf = wp.array(np.concatenate(cdfs) if cdfs else np.zeros(1, np.float32), dtype=wp.float32,
                      device=device)
    lt.cdf_off = wp.array(np.cumsum([0] + lens[:-1]).astype(np.int32), dtype=wp.int32, device=device)
    lt.cdf_count = wp.array(np.array(lens, np.int32), dtype=wp.int32, device=device)
    lt.dome = wp.vec3(*np.nan_to_num(dome).astype(np.float32))
    lt.dome_visible = int(dome_visible)
    return lt, n
