"""The integrator: one distributed-ray-tracing sample per thread.

A sample is a point in every dimension at once (the paper's central idea): its film position (antialiasing),
its time (motion blur: camera, geometry, lights and shadows are all evaluated at that one instant), its lens
position (depth of field) and its light positions (penumbras). All come from ``sampler`` as pure functions of
(seed, pixel, sample index, dimension), so the sample can be replayed exactly.

Shading here is what the spine needs: emission, Lambertian diffuse, direct lighting from every light with
shadow rays through partially opaque surfaces, and opacity layers along the camera ray. Path tracing,
gloss and translucency arrive with issue 3.
"""
from __future__ import annotations

import warp as wp

from .accel import Geometry, instance_world_to_object, intersect_closest, mesh_keys_at, transmittance, \
    triangle_points
from .bsdf import lambert_eval
from .camera import CameraParams, camera_ray
from .film import SampleBuffer
from .lights import Lights, sample_light, dome_radiance
from .materials import Materials
from .sampler import DIM_FILM, DIM_LENS, DIM_LIGHT_BASE, DIM_TIME, DIMS_PER_LIGHT, sample_1d, sample_2d
from .sampling import sample_tent

TIME_BOX = 0
TIME_TRIANGLE = 1
TIME_STROBE = 2
TIME_FILTERS = {"box": TIME_BOX, "triangle": TIME_TRIANGLE, "strobe": TIME_STROBE}

MAX_LAYERS = 8  # partially opaque surfaces a camera ray passes through before it stops
RAY_EPSILON = 2.0e-5  # relative offset of secondary ray origins (times 1 + |p|_inf, scene units)


@wp.func
def shutter_time(kind: int, u: float, frame_s: float):
    """Normalised shutter time of a sample from its time dimension, weighted by the temporal filter.

    ``frame_s`` is the frame's own time in normalised shutter time, the one instant a strobe shutter sees.
    """
    if kind == TIME_TRIANGLE:
        return sample_tent(u)
    if kind == TIME_STROBE:
        return frame_s
    return u


@wp.func
def offset_origin(p: wp.vec3, n: wp.vec3):
    scale = 1.0 + wp.max(wp.max(wp.abs(p[0]), wp.abs(p[1])), wp.abs(p[2]))
    return p + n * (RAY_EPSILON * scale)


@wp.func
def finite3(v: wp.vec3):
    return wp.isfinite(v[0]) and wp.isfinite(v[1]) and wp.isfinite(v[2])


@wp.struct
class SurfacePoint:
    p: wp.vec3  # world position
    ng: wp.vec3  # geometric normal, facing the incoming ray
    ns: wp.vec3  # shading normal, same hemisphere as ng
    material: int


@wp.func
def surface_at(geo: Geometry, inst: int, tri: int, b1: float, b2: float, ro: wp.vec3, rd: wp.vec3, t: float,
               s: float):
    """World position and normals of a hit at time s (vertices and transform evaluated at that instant)."""
    m = geo.inst_mesh[inst]
    w2o_t = wp.transpose(instance_world_to_object(geo, inst, s))  # normals transform by the inverse transpose
    k0, k1, u = mesh_keys_at(geo, m, s)
    p0, p1, p2 = triangle_points(geo, m, tri - geo.mesh_tri_off[m], k0, k1, u)
    ng = wp.normalize(wp.transform_vector(w2o_t, wp.cross(p1 - p0, p2 - p0)))
    ns = ng
    if geo.mesh_has_normals[m] != 0:
        b0 = 1.0 - b1 - b2
        n = geo.normals[3 * tri] * b0 + geo.normals[3 * tri + 1] * b1 + geo.normals[3 * tri + 2] * b2
        nw = wp.transform_vector(w2o_t, n)
        if wp.length(nw) > 0.0:
            ns = wp.normalize(nw)
    # two-sided: both normals face the viewer
    if wp.dot(ng, rd) > 0.0:
        ng = -ng
    if wp.dot(ns, ng) < 0.0:
        ns = -ns
    sp = SurfacePoint()
    sp.p = ro + rd * t
    sp.ng = ng
    sp.ns = ns
    sp.material = geo.tri_material[tri]
    return sp


@wp.func
def direct_lighting(geo: Geometry, mats: Materials, lights: Lights, light_count: int, sp: SurfacePoint,
                    albedo: wp.vec3, s: float, seed: wp.uint32, pixel: wp.uint32, index: wp.uint32):
    """Light reaching the point from every light, one shadow ray each. Returns (radiance, rays traced)."""
    L = wp.vec3(0.0)
    rays = int(0)
    origin = offset_origin(sp.p, sp.ng)
    for li in range(light_count):
        dim = wp.uint32(DIM_LIGHT_BASE + DIMS_PER_LIGHT * li)
        u_pick = sample_1d(seed, pixel, index, dim)
        u_pos = sample_2d(seed, pixel, index, dim + wp.uint32(1))
        wi, dist, weight, ok = sample_light(lights, geo, mats.emission, li, origin, sp.ns, s, u_pick, u_pos)
        if ok:
            cos_s = wp.dot(sp.ns, wi)
            if cos_s > 0.0 and wp.dot(sp.ng, wi) > 0.0:
                rays += 1
                tr = transmittance(geo, mats.opacity, origin, wi, dist * (1.0 - 1.0e-4), s)
                if tr > 0.0:
                    L += wp.cw_mul(lambert_eval(albedo, sp.ns, wi), weight) * (cos_s * tr)
    return L, rays


@wp.kernel
def trace_wave_kernel(
    geo: Geometry,
    mats: Materials,
    lights: Lights,
    light_count: int,
    cam: CameraParams,
    buf: SampleBuffer,
    counters: wp.array(dtype=wp.int64),  # [rays traced, non-finite samples zeroed]
    seed: wp.uint32,
    region_x0: int,
    region_y0: int,
    region_w: int,
    wave_start: int,  # sample index of this wave's first sample
    wave: int,  # samples per pixel in this wave
    time_filter: int,
    frame_s: float,  # the frame time in normalised shutter time (strobe)
):
    tid = wp.tid()
    j = tid % wave
    pr = tid // wave
    px = region_x0 + pr % region_w
    py = region_y0 + pr // region_w
    pixel = wp.uint32(py * cam.width + px)
    index = wp.uint32(wave_start + j)

    film_u = sample_2d(seed, pixel, index, wp.uint32(DIM_FILM))
    s = shutter_time(time_filter, sample_1d(seed, pixel, index, wp.uint32(DIM_TIME)), frame_s)
    lens_u = sample_2d(seed, pixel, index, wp.uint32(DIM_LENS))
    ro, rd, tmin, tmax, fwd = camera_ray(cam, wp.vec2(float(px) + film_u[0], float(py) + film_u[1]), lens_u, s)
    cam_origin = ro

    L = wp.vec3(0.0)
    alpha = float(0.0)
    throughput = float(1.0)
    depth = float(0.0)
    normal = wp.vec3(0.0)
    albedo_aov = wp.vec3(0.0)
    rays = int(0)
    origin = ro + rd * tmin
    remaining = tmax - tmin
    layer = int(0)
    while layer < MAX_LAYERS and throughput > 0.0:
        rays += 1
        hit = intersect_closest(geo, origin, rd, remaining, s)
        if hit.inst < 0:
            L += dome_radiance(lights, rd) * throughput
            if lights.dome_visible != 0:
                alpha += throughput
            throughput = 0.0
        else:
            sp = surface_at(geo, hit.inst, hit.tri, hit.b1, hit.b2, origin, rd, hit.t, s)
            opacity = mats.opacity[sp.material]
            albedo = mats.diffuse[sp.material]
            if layer == 0:
                depth = wp.dot(sp.p - cam_origin, fwd)
                normal = sp.ns
                albedo_aov = albedo
            Ls = mats.emission[sp.material]
            if opacity > 0.0:
                direct, n = direct_lighting(geo, mats, lights, light_count, sp, albedo, s, seed, pixel, index)
                Ls += direct
                rays += n
            L += Ls * (throughput * opacity)
            alpha += throughput * opacity
            throughput *= 1.0 - opacity
            # continue behind a partially opaque surface
            origin = offset_origin(sp.p, rd)
            remaining = remaining - hit.t
        layer += 1

    sample = wp.vec4(L[0], L[1], L[2], wp.min(alpha, 1.0))
    if not (finite3(L)):
        sample = wp.vec4(0.0, 0.0, 0.0, wp.min(alpha, 1.0))
        wp.atomic_add(counters, 1, wp.int64(1))
    buf.film[tid] = film_u
    buf.rgba[tid] = sample
    buf.depth[tid] = depth
    buf.normal[tid] = normal
    buf.albedo[tid] = albedo_aov
    wp.atomic_add(counters, 0, wp.int64(rays))
