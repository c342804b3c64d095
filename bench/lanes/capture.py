"""The capture: the scene's paths re-traced as ``integrator.trace_wave_kernel`` traces them, without gathering light,
keeping a shading record at every vertex where the integrator samples a light (bounce 1 on) and every
continuation ray."""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.accel.csg import csg_closest
from renderer.accel.intersect import BIG, Geometry, intersect_closest
from renderer.accel.surface import display_diffuse, hit_geometry, shading_normal, surface_at
from renderer.camera import CameraParams, camera_ray
from renderer.integrator import FLAG_DELTA, RR_START, finite3, offset_origin, regularized_params, roughness_of_pdf
from renderer.sampling.sobol import (
    BOUNCE_LOBE,
    BOUNCE_ROULETTE,
    CAMERA_BSDF_1,
    CAMERA_LENS,
    DIM_FILM,
    DIM_LIGHT_BASE,
    DIMS_PER_BOUNCE,
    sample_1d,
    sample_3d,
    sample_camera_pair,
)
from renderer.shading.bsdf import bsdf_setup, lobes_sample
from renderer.shading.materials import HitGeometry, Materials, eval_material_cone
from renderer.shading.raycone import bounce_spread, camera_cone, uv_footprint
from renderer.shading.textures import Textures
from renderer.struct_refs import by_reference

from .records import (
    F_CC_ROUGH, F_CLEARCOAT, F_DB, F_DG, F_DR, F_IOR, F_METALLIC, F_NGX, F_NGY, F_NGZ, F_NSX, F_NSY, F_NSZ, F_OPACITY,
    F_PX, F_PY, F_PZ, F_ROUGHNESS, F_SB, F_SG, F_SR, F_WOX, F_WOY, F_WOZ, I_BOUNCE, I_FRONT, I_INDEX, I_PIXEL, I_THIN,
    I_USE_SPEC, I_VALID, NF, NI,
)

wp.set_module_options({"enable_backward": False})

CAPTURE_MODULE = "lanes_capture"


@by_reference
@wp.struct
class Capture:
    f: wp.array2d(dtype=wp.float32)  # (NF, paths * max_depth): slot = path * max_depth + bounce
    i: wp.array2d(dtype=wp.int32)  # (NI, ...)
    ray: wp.array2d(dtype=wp.float32)  # (6, ...) the continuation ray leaving the vertex: origin, direction
    ray_ok: wp.array(dtype=wp.int32)
    first: int  # the launch's first path
    width: int
    spp: int
    max_depth: int
    glossy_filter: float
    seed: wp.uint32


@wp.kernel(module=CAPTURE_MODULE)
def capture_kernel(geo: Geometry, mats: Materials, tex: Textures, cam: CameraParams, cap: Capture):
    """``trace_wave_kernel``'s path without light gathering: the vertices where it samples lights, and its rays."""
    tid = wp.tid()
    path = cap.first + tid
    j = path % cap.spp
    pr = path // cap.spp
    px = pr % cap.width
    py = pr // cap.width
    pixel = wp.uint32(py * cam.width + px)
    index = wp.uint32(j)
    seed = cap.seed
    film_t = sample_3d(seed, pixel, index, wp.uint32(DIM_FILM))
    s = film_t[2]  # box shutter filter (the bench scenes' shutters are closed: s changes nothing)
    lens_u = sample_camera_pair(seed, pixel, index, wp.uint32(DIM_FILM), CAMERA_LENS)
    pinhole = cam.lens_radius <= 0.0
    ro, rd, tmin, tmax, fwd = camera_ray(cam, wp.vec2(float(px) + film_t[0], float(py) + film_t[1]), lens_u, s)
    cone_w, cone_spread = camera_cone(cam.film_size[1], cam.focal_length, cam.height, cam.orthographic)
    beta = wp.vec3(1.0)
    origin = ro + rd * tmin
    t_far = tmax - tmin
    bounce = int(0)
    alive = int(1)
    path_roughness = float(0.0)
    while alive != 0:
        hit = intersect_closest(geo, origin, rd, t_far, s)
        if geo.csg_groups > 0:
            hit = csg_closest(geo, origin, rd, s, hit)
        if hit.inst < 0:
            alive = 0
        else:
            sp = surface_at(geo, hit.inst, hit.tri, hit.b1, hit.b2, hit.ng, origin, rd, hit.t, s)
            cone_w = cone_w + cone_spread * hit.t
            hg = HitGeometry()
            if mats.geo_driven[sp.material] != 0:
                hg = hit_geometry(geo, hit.inst, sp, s, cone_w)
            ms = eval_material_cone(mats, tex, sp.material, sp.uv, s,
                                    uv_footprint(cone_w, sp.uv_density, wp.dot(sp.ng, rd)), hg)
            ms.diffuse_color = display_diffuse(geo, mats, sp.material, hit.inst, hit.tri, hit.b1, hit.b2,
                                               ms.diffuse_color)
            ns = shading_normal(sp, ms)
            thin = 1 - geo.tri_solid[hit.tri]
            params = regularized_params(ms, thin, cap.glossy_filter, path_roughness)
            wo = -rd
            lobes = bsdf_setup(params, ns, sp.ng, wo, sp.front)
            if bounce >= cap.max_depth:
                alive = 0
            else:
                slot = tid * cap.max_depth + bounce
                if bounce >= 1:  # a shading record: the integrator samples a light here
                    cap.f[F_PX, slot] = sp.p[0]
                    cap.f[F_PY, slot] = sp.p[1]
                    cap.f[F_PZ, slot] = sp.p[2]
                    cap.f[F_NGX, slot] = sp.ng[0]
                    cap.f[F_NGY, slot] = sp.ng[1]
                    cap.f[F_NGZ, slot] = sp.ng[2]
                    cap.f[F_NSX, slot] = ns[0]
                    cap.f[F_NSY, slot] = ns[1]
                    cap.f[F_NSZ, slot] = ns[2]
                    cap.f[F_WOX, slot] = wo[0]
                    cap.f[F_WOY, slot] = wo[1]
                    cap.f[F_WOZ, slot] = wo[2]
                    cap.f[F_DR, slot] = params.diffuse_color[0]
                    cap.f[F_DG, slot] = params.diffuse_color[1]
                    cap.f[F_DB, slot] = params.diffuse_color[2]
                    cap.f[F_SR, slot] = params.specular_color[0]
                    cap.f[F_SG, slot] = params.specular_color[1]
                    cap.f[F_SB, slot] = params.specular_color[2]
                    cap.f[F_METALLIC, slot] = params.metallic
                    cap.f[F_ROUGHNESS, slot] = params.roughness
                    cap.f[F_CLEARCOAT, slot] = params.clearcoat
                    cap.f[F_CC_ROUGH, slot] = params.clearcoat_roughness
                    cap.f[F_OPACITY, slot] = params.opacity
                    cap.f[F_IOR, slot] = params.ior
                    cap.i[I_PIXEL, slot] = int(pixel)
                    cap.i[I_INDEX, slot] = int(index)
                    cap.i[I_BOUNCE, slot] = bounce
                    cap.i[I_FRONT, slot] = sp.front
                    cap.i[I_THIN, slot] = params.thin
                    cap.i[I_USE_SPEC, slot] = params.use_specular_workflow
                    cap.i[I_VALID, slot] = 1
                dim = wp.uint32(DIM_LIGHT_BASE + bounce * DIMS_PER_BOUNCE)
                u_bsdf = sample_3d(seed, pixel, index, dim + wp.uint32(BOUNCE_LOBE))
                if pinhole and bounce < 2:
                    pair = int(CAMERA_BSDF_1)
                    if bounce == 0:
                        pair = int(CAMERA_LENS)
                    direction = sample_camera_pair(seed, pixel, index, wp.uint32(DIM_FILM), pair)
                    u_bsdf = wp.vec3(direction[0], direction[1], u_bsdf[2])
                wi, weight, pdf, flags = lobes_sample(lobes, u_bsdf[2], wp.vec2(u_bsdf[0], u_bsdf[1]))
                if pdf <= 0.0 or not finite3(weight) or (weight[0] <= 0.0 and weight[1] <= 0.0 and weight[2] <= 0.0):
                    alive = 0
                else:
                    beta = wp.cw_mul(beta, weight)
                    cone_spread = bounce_spread(cone_spread, ms.roughness, flags & FLAG_DELTA)
                    if (flags & FLAG_DELTA) == 0:
                        path_roughness = wp.max(path_roughness, roughness_of_pdf(pdf))
                    if (flags & 2) != 0:
                        origin = offset_origin(sp.p, -sp.ng)
                    else:
                        origin = offset_origin(sp.p, sp.ng)
                    rd = wi
                    t_far = float(BIG)
                    cap.ray[0, slot] = origin[0]
                    cap.ray[1, slot] = origin[1]
                    cap.ray[2, slot] = origin[2]
                    cap.ray[3, slot] = rd[0]
                    cap.ray[4, slot] = rd[1]
                    cap.ray[5, slot] = rd[2]
                    cap.ray_ok[slot] = 1
                    bounce += 1
                    if bounce >= RR_START:
                        q = wp.max(0.05, 1.0 - wp.max(wp.max(beta[0], beta[1]), beta[2]))
                        if sample_1d(seed, pixel, index, dim + wp.uint32(BOUNCE_ROULETTE)) < q:
                            alive = 0
                        else:
                            beta = beta / (1.0 - q)


def capture(prep, spp: int, chunk: int = 1 << 17) -> dict:
    """Shading records (columns, in path order) and continuation rays of the prepared image at ``spp``, captured
    ``chunk`` paths at a time (a slot per bounce and path)."""
    opts = prep.options
    paths = prep.width * prep.height * spp
    depth = int(opts.max_depth)
    cap = Capture()
    cap.width, cap.spp, cap.max_depth = prep.width, spp, depth
    cap.glossy_filter = float(opts.path_glossy_filter)
    cap.seed = wp.uint32(opts.seed)
    cap.f = wp.zeros((NF, chunk * depth), dtype=wp.float32)
    cap.i = wp.zeros((NI, chunk * depth), dtype=wp.int32)
    cap.ray = wp.zeros((6, chunk * depth), dtype=wp.float32)
    cap.ray_ok = wp.zeros(chunk * depth, dtype=wp.int32)
    fs, is_, rays, ray_bounce = [], [], [], []
    for first in range(0, paths, chunk):
        count = min(chunk, paths - first)
        cap.first = first
        cap.i.zero_()
        cap.ray_ok.zero_()
        wp.launch(capture_kernel, dim=count, inputs=[prep.geometry, prep.materials, prep.textures,
                                                     prep.camera.params, cap])
        ii = cap.i.numpy()[:, :count * depth]
        keep = ii[I_VALID] != 0
        fs.append(cap.f.numpy()[:, :count * depth][:, keep])
        is_.append(ii[:, keep])
        bounce_of_slot = np.tile(np.arange(depth), count)
        later = (cap.ray_ok.numpy()[:count * depth] != 0) & (bounce_of_slot >= 1)  # rays leaving bounce 1 on
        rays.append(cap.ray.numpy()[:, :count * depth][:, later])
        ray_bounce.append(bounce_of_slot[later])
    return {"f": np.ascontiguousarray(np.concatenate(fs, axis=1)),
            "i": np.ascontiguousarray(np.concatenate(is_, axis=1)), "rays": np.concatenate(rays, axis=1),
            "ray_bounce": np.concatenate(ray_bounce), "paths": paths}
