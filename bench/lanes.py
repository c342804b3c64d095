#!/usr/bin/env python3
"""SIMD lanes inside Warp, proven or killed (issue 48): next-event estimation one record per thread against an
in-thread loop over 64 records, and Embree's ray packets against single rays.

    python bench/lanes.py [--scene cornell] [--width 320 --spp 16] [--repeats 5]
                          [--target v3,native] [--count] [--embree cornell,heavy]

1. **Capture.** A capture kernel here re-traces the scene's paths as ``integrator.trace_wave_kernel`` does (the same
   sample dimensions, surface and material code, glossy filter, BSDF sampling and Russian roulette; no light is
   gathered) and writes, at every vertex from bounce 1 on where the integrator samples a light, a shading record:
   point, geometric and shading normals, outgoing direction, the regularized ``SurfaceParams``, pixel, sample
   index and bounce. It also keeps every continuation ray. Nothing of ``renderer/`` is changed.
2. **Next-event estimation, timed** on one thread, best of ``--repeats``: the sampler's scramble of the light
   dimensions (bounce 1 with a pinhole: the camera's pair, as the integrator), the light choice, the rect light's
   spherical-rectangle sample, ``bsdf_setup`` + ``lobes_eval`` + ``lobes_pdf`` and the power heuristic; output the
   unshadowed contribution f Le cos w / pdf, the direction and the distance (the shadow ray is part 4).
   - *scalar*: one record per thread, the integrator's own ``@wp.func`` code (``sample_3d``, ``select_light``,
     ``sample_light``, ...), records read from plain float arrays;
   - *lanes-vec3*: one thread per 64 records in the layout a per-thread wavefront would keep (each field a
     ``vector(64, float)`` per batch, loaded into locals), looped over with the renderer's own vec3 code, except
     the sampler's and the rectangle's 4-lane natives (their scalar twins ``owen_scramble3_reference`` /
     ``_sph_rect_angles_reference``, bit-identical by the renderer's tests) and the light choice's loops (its
     one-light arithmetic: one cluster of one light, checked). LLVM does not vectorize it (see ``nee_soa``);
   - *soa*: the same loop over ``nee_soa``, the computation rewritten in plain floats, vectorized 8 wide (forced:
     ``FORCE``); *soa-w16* 16 wide; *soa-novec* the same source with ``-fno-vectorize``;
   - *soa-flat*: ``nee_soa`` reading plain float arrays (``array_t``): Warp's run-time byte strides make LLVM
     version the loop on a byte stride of 1, so the ymm code it emits is never reached by float arrays.
   Every variant's outputs are compared with the scalar ones (relative 1e-5 would do; they are bit-equal).
3. **Evidence**: per build target (``v3``: the shipped x86-64-v3/AVX2 flags; ``native``: Warp's ``-march=native``,
   AVX-512 where the host has it), ymm/zmm/xmm instruction counts, packed vs scalar float ops and gathers in
   each module's object (``objdump -d``), and with ``--count`` the instructions per record under callgrind
   (``perf stat -e instructions`` is not supported in this VM; valgrind runs no AVX-512, so v3 builds only).
4. **Embree packets**: the captured continuation rays (bounce 1 on) and the shadow rays of the computed samples,
   in wavefront order (by bounce, then path), traced through one Embree scene of the world-space triangles with
   ``rtcIntersect1`` / ``rtcOccluded1`` eight or sixteen times per thread against one ``rtcIntersect8``/``16``
   (``rtcOccluded8``/``16``) from the same Warp kernels (function pointers and native snippets, as
   ``accel.embree``). Hits are compared.

Run from the worktree root with ``PYTHONPATH=$PWD``; the first run compiles the capture kernel (~1 min) and the
NEE kernels per target. ``--count`` needs valgrind and a C compiler (as ``bench/instructions.py``).
"""
from __future__ import annotations

import argparse
import collections
import ctypes
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
import warp as wp

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
SCENES = next((p for p in (ROOT.parent / "shared" / "bench" / "scenes", pathlib.Path("/work/shared/bench/scenes"))
               if p.is_dir()), None)

from renderer.accel.csg import csg_closest  # noqa: E402
from renderer.accel.intersect import BIG, Geometry, intersect_closest  # noqa: E402
from renderer.camera import CameraParams, camera_ray  # noqa: E402
from renderer.integrator import (  # noqa: E402
    FLAG_DELTA,
    RR_START,
    display_diffuse,
    finite3,
    offset_origin,
    power_heuristic,
    regularized_params,
    roughness_of_pdf,
    shading_normal,
    surface_at,
)
from renderer.kernel_cache import PORTABLE_FLAGS  # noqa: E402
from renderer.lights.sample import sample_light  # noqa: E402
from renderer.lights.select import select_light  # noqa: E402
from renderer.lights.table import Lights  # noqa: E402
from renderer.sampling.sobol import (  # noqa: E402
    mix32,
    reverse_bits32,
    u32_to_unit_float,
    BOUNCE_LIGHT_CHOICE,
    BOUNCE_LOBE,
    BOUNCE_ROULETTE,
    CAMERA_BSDF_1,
    CAMERA_LENS,
    CAMERA_LIGHT_0,
    CAMERA_LIGHT_1,
    DIM_FILM,
    DIM_LIGHT_BASE,
    DIMS_PER_BOUNCE,
    W_SOBOL7_TABLE,
    W_SOBOL8_TABLE,
    _byte_product,
    owen_scramble,
    owen_scramble3_reference,
    pattern_hash,
    sample_1d,
    sample_3d,
    sample_camera_pair,
    sobol_dims12,
)
from renderer.sampling.warps import (  # noqa: E402
    INV_PI,
    TWO_PI,
    XU_RADICAND_MIN,
    LightSampleGeom,
    _area_sample_geom,
    _rect_local,
    _sph_rect_angles_reference,
    _use_sph_rect,
    sin_cos,
)
from renderer.shading.bsdf import SurfaceParams, bsdf_setup, lobes_eval, lobes_pdf, lobes_sample  # noqa: E402
from renderer.shading.materials import Materials, eval_material_cone  # noqa: E402
from renderer.shading.raycone import bounce_spread, camera_cone, uv_footprint  # noqa: E402
from renderer.shading.textures import Textures  # noqa: E402
from renderer.struct_refs import by_reference  # noqa: E402

wp.set_module_options({"enable_backward": False})

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

CAPTURE_MODULE = "lanes_capture"


# ================================================================================================================
# 1. Capture
# ================================================================================================================

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
            ms = eval_material_cone(mats, tex, sp.material, sp.uv, s,
                                    uv_footprint(cone_w, sp.uv_density, wp.dot(sp.ng, rd)))
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
            "i": np.ascontiguousarray(np.concatenate(is_, axis=1)), "rays": np.concatenate(rays, axis=1), "ray_bounce": np.concatenate(ray_bounce), "paths": paths}


# ================================================================================================================
# 2. Next-event estimation: one record per thread, and 64 per thread in a loop
# ================================================================================================================

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


@wp.func
def record_params(dr: float, dg: float, db: float, sr: float, sg: float, sb: float, use_spec: int, metallic: float,
                  roughness: float, clearcoat: float, cc_rough: float, opacity: float, ior: float, thin: int):
    p = SurfaceParams()
    p.diffuse_color = wp.vec3(dr, dg, db)
    p.specular_color = wp.vec3(sr, sg, sb)
    p.use_specular_workflow = use_spec
    p.metallic = metallic
    p.roughness = roughness
    p.clearcoat = clearcoat
    p.clearcoat_roughness = cc_rough
    p.opacity = opacity
    p.ior = ior
    p.thin = thin
    return p


def nee_scalar_kernel(module: str):
    @wp.kernel(module=module)
    def nee_scalar(rec: FlatRecords, geo: Geometry, mats: Materials, tex: Textures, lights: Lights, seed: wp.uint32,
                   pinhole: int):
        """The integrator's next-event estimation at one record (one finite light, no infinite ones, no links)."""
        i = wp.tid()
        pixel = wp.uint32(rec.i[I_PIXEL, i])
        index = wp.uint32(rec.i[I_INDEX, i])
        bounce = rec.i[I_BOUNCE, i]
        p = wp.vec3(rec.f[F_PX, i], rec.f[F_PY, i], rec.f[F_PZ, i])
        ng = wp.vec3(rec.f[F_NGX, i], rec.f[F_NGY, i], rec.f[F_NGZ, i])
        ns = wp.vec3(rec.f[F_NSX, i], rec.f[F_NSY, i], rec.f[F_NSZ, i])
        wo = wp.vec3(rec.f[F_WOX, i], rec.f[F_WOY, i], rec.f[F_WOZ, i])
        params = record_params(rec.f[F_DR, i], rec.f[F_DG, i], rec.f[F_DB, i], rec.f[F_SR, i], rec.f[F_SG, i],
                               rec.f[F_SB, i], rec.i[I_USE_SPEC, i], rec.f[F_METALLIC, i], rec.f[F_ROUGHNESS, i],
                               rec.f[F_CLEARCOAT, i], rec.f[F_CC_ROUGH, i], rec.f[F_OPACITY, i], rec.f[F_IOR, i],
                               rec.i[I_THIN, i])
        lobes = bsdf_setup(params, ns, ng, wo, rec.i[I_FRONT, i])
        dim = wp.uint32(DIM_LIGHT_BASE + bounce * DIMS_PER_BOUNCE)
        u_light = sample_3d(seed, pixel, index, dim + wp.uint32(BOUNCE_LIGHT_CHOICE))
        if bounce == 0 or (bounce == 1 and pinhole != 0):
            on_light = sample_camera_pair(seed, pixel, index, wp.uint32(DIM_FILM), CAMERA_LIGHT_0 + bounce)
            u_light = wp.vec3(on_light[0], on_light[1], u_light[2])
        origin_l = offset_origin(p, ng)
        li, p_sel, u_tri = select_light(lights.select, p, u_light[2])
        wi = wp.vec3(0.0)
        dist = float(0.0)
        Le_l = wp.vec3(0.0)
        pdf_l = float(0.0)
        delta = False
        if li >= 0:
            wi, dist, Le_l, pdf_l, delta = sample_light(lights, geo, mats, tex, li, origin_l, ns, 0.0, u_tri,
                                                        wp.vec2(u_light[0], u_light[1]))
        c = wp.vec3(0.0)
        if pdf_l > 0.0 and (Le_l[0] > 0.0 or Le_l[1] > 0.0 or Le_l[2] > 0.0):
            f = lobes_eval(lobes, wi)
            if f[0] > 0.0 or f[1] > 0.0 or f[2] > 0.0:
                w = float(1.0)
                if not delta:
                    w = power_heuristic(p_sel * pdf_l, lobes_pdf(lobes, wi))
                cos_i = wp.abs(wp.dot(ns, wi))
                c = wp.cw_mul(f, Le_l) * (cos_i * w / (p_sel * pdf_l))
        rec.out[O_CR, i] = c[0]
        rec.out[O_CG, i] = c[1]
        rec.out[O_CB, i] = c[2]
        rec.out[O_WIX, i] = wi[0]
        rec.out[O_WIY, i] = wi[1]
        rec.out[O_WIZ, i] = wi[2]
        rec.out[O_DIST, i] = dist
    return nee_scalar


@wp.func
def sample_3d_lane(seed: wp.uint32, pixel: wp.uint32, index: wp.uint32, dim: wp.uint32) -> wp.vec3:
    """``sobol.sample_3d`` with the scalar twin of its 4-lane native scramble."""
    h = pattern_hash(seed, pixel, dim)
    i = owen_scramble(index, h)
    d1, d2 = sobol_dims12(i)
    return owen_scramble3_reference(i, d1, d2, h, wp.uint32(1), 1)


@wp.func
def light_pair_1_lane(seed: wp.uint32, pixel: wp.uint32, index: wp.uint32) -> wp.vec2:
    """``sobol.sample_camera_pair(.., DIM_FILM, CAMERA_LIGHT_1)`` (bounce 1's point on a light) in scalar code."""
    h = pattern_hash(seed, pixel, wp.uint32(DIM_FILM))
    i = owen_scramble(index, h)
    u = owen_scramble3_reference(_byte_product(W_SOBOL7_TABLE, i), _byte_product(W_SOBOL8_TABLE, i), wp.uint32(0),
                                 h, wp.uint32(4 + 2 * CAMERA_LIGHT_1), 0)
    return wp.vec2(u[0], u[1])


@wp.func
def sample_rect_lane(p_ref: wp.vec3, corner: wp.vec3, edge_u: wp.vec3, edge_v: wp.vec3, u: wp.vec2) -> LightSampleGeom:
    """``warps.sample_rect`` with the scalar twin of its 4-lane angles."""
    n = wp.cross(edge_u, edge_v)
    area = wp.length(n)
    normal = n / area
    ex, ey, ez, x0, y0, z0, x1, y1 = _rect_local(p_ref, corner, edge_u, edge_v)
    g01, g23, b0, b1, solid_angle = _sph_rect_angles_reference(x0, y0, z0, x1, y1)
    if not _use_sph_rect(solid_angle):
        return _area_sample_geom(p_ref, corner + u[0] * edge_u + u[1] * edge_v, normal, area)
    au = u[0] * (g01 - TWO_PI) + (u[0] - 1.0) * g23
    sau, cau = sin_cos(au)
    fu = (cau * b0 - b1) / sau
    e = fu * fu + b0 * b0 - 1.0
    xu = wp.clamp(wp.where(fu < 0.0, z0, -z0) / wp.sqrt(wp.max(e, XU_RADICAND_MIN)), x0, x1)
    dd2 = xu * xu + z0 * z0
    h0 = y0 / wp.sqrt(dd2 + y0 * y0)
    h1 = y1 / wp.sqrt(dd2 + y1 * y1)
    dd = wp.sqrt(dd2)
    hv = h0 + u[1] * (h1 - h0)
    hv2 = hv * hv
    yv = y1
    if hv2 < 1.0 - 1e-6:
        yv = hv * dd / wp.sqrt(1.0 - hv2)
    yv = wp.clamp(yv, y0, y1)
    d = xu * ex + yv * ey + z0 * ez
    g = LightSampleGeom()
    g.point = p_ref + d
    g.normal = normal
    g.dist = wp.length(d)
    g.dir = d / g.dist
    g.pdf = 1.0 / solid_angle
    return g


@wp.struct
class OneRect:
    """The one light of the batch, read once per thread: its selection cluster and its (still) rectangle."""

    centre: wp.vec3
    power: float
    radius2: float
    cap: float
    p_in: float
    Le: wp.vec3
    corner: wp.vec3
    ex: wp.vec3
    ey: wp.vec3
    front: wp.vec3
    normal: wp.vec3  # unit normal of the rectangle's plane and its area (sample_rect)
    area: float
    exu: wp.vec3  # unit edges and their lengths, and exu x eyu (_rect_local)
    eyu: wp.vec3
    ezu: wp.vec3
    exl: float
    eyl: float


@wp.func
def one_rect(lights: Lights) -> OneRect:
    r = OneRect()
    sel = lights.select
    r.centre = sel.centre[0]
    r.power = sel.power[0]
    r.radius2 = sel.radius2[0]
    r.cap = sel.cap[0]
    li = sel.order[sel.first[0]]
    r.p_in = sel.light_p[li]
    r.Le = lights.radiance[li]
    r.corner = lights.rect_still[4 * li]
    r.ex = lights.rect_still[4 * li + 1]
    r.ey = lights.rect_still[4 * li + 2]
    r.front = lights.rect_still[4 * li + 3]
    n = wp.cross(r.ex, r.ey)
    r.area = wp.length(n)
    r.normal = n / r.area
    r.exl = wp.length(r.ex)
    r.eyl = wp.length(r.ey)
    r.exu = r.ex / r.exl
    r.eyu = r.ey / r.eyl
    r.ezu = wp.cross(r.exu, r.eyu)
    return r


@wp.func
def nee_lane(L: OneRect, seed: wp.uint32, pinhole: int, pixel: wp.uint32, index: wp.uint32, bounce: int,
             p: wp.vec3, ng: wp.vec3, ns: wp.vec3, wo: wp.vec3, front: int, params: SurfaceParams):
    """The scalar kernel's computation for one record of a batch, in code the loop vectorizer accepts (no loops, no
    vector-typed natives): (contribution, wi, dist)."""
    lobes = bsdf_setup(params, ns, ng, wo, front)
    dim = wp.uint32(DIM_LIGHT_BASE + bounce * DIMS_PER_BOUNCE)
    u_light = sample_3d_lane(seed, pixel, index, dim + wp.uint32(BOUNCE_LIGHT_CHOICE))
    if bounce == 1 and pinhole != 0:
        on_light = light_pair_1_lane(seed, pixel, index)
        u_light = wp.vec3(on_light[0], on_light[1], u_light[2])
    origin_l = offset_origin(p, ng)
    # select_light with one cluster of one light: its weight, and 1 x the light's share where positive
    d = L.centre - p
    total = wp.min(L.power / wp.max(wp.dot(d, d), L.radius2), L.cap)
    p_sel = (total / total) * L.p_in
    wi = wp.vec3(0.0)
    dist = float(0.0)
    pdf_l = float(0.0)
    if total > 0.0:
        g = sample_rect_lane(origin_l, L.corner, L.ex, L.ey, wp.vec2(u_light[0], u_light[1]))
        if g.pdf > 0.0 and wp.dot(g.dir, L.front) < 0.0:
            wi = g.dir
            dist = g.dist
            pdf_l = g.pdf
    c = wp.vec3(0.0)
    if pdf_l > 0.0 and (L.Le[0] > 0.0 or L.Le[1] > 0.0 or L.Le[2] > 0.0):
        f = lobes_eval(lobes, wi)
        if f[0] > 0.0 or f[1] > 0.0 or f[2] > 0.0:
            w = power_heuristic(p_sel * pdf_l, lobes_pdf(lobes, wi))
            cos_i = wp.abs(wp.dot(ns, wi))
            c = wp.cw_mul(f, L.Le) * (cos_i * w / (p_sel * pdf_l))
    return c, wi, dist


def nee_lanes_kernel(module: str):
    @wp.kernel(module=module)
    def nee_lanes(rec: LaneRecords, lights: Lights, seed: wp.uint32, pinhole: int):
        """LANES records per thread: the batch's fields loaded into local vectors, then one loop over them."""
        b = wp.tid()
        L = one_rect(lights)
        px = rec.f[F_PX, b]
        py = rec.f[F_PY, b]
        pz = rec.f[F_PZ, b]
        ngx = rec.f[F_NGX, b]
        ngy = rec.f[F_NGY, b]
        ngz = rec.f[F_NGZ, b]
        nsx = rec.f[F_NSX, b]
        nsy = rec.f[F_NSY, b]
        nsz = rec.f[F_NSZ, b]
        wox = rec.f[F_WOX, b]
        woy = rec.f[F_WOY, b]
        woz = rec.f[F_WOZ, b]
        dr = rec.f[F_DR, b]
        dg = rec.f[F_DG, b]
        db = rec.f[F_DB, b]
        sr = rec.f[F_SR, b]
        sg = rec.f[F_SG, b]
        sb = rec.f[F_SB, b]
        metallic = rec.f[F_METALLIC, b]
        roughness = rec.f[F_ROUGHNESS, b]
        clearcoat = rec.f[F_CLEARCOAT, b]
        cc_rough = rec.f[F_CC_ROUGH, b]
        opacity = rec.f[F_OPACITY, b]
        ior = rec.f[F_IOR, b]
        pixel = rec.i[I_PIXEL, b]
        index = rec.i[I_INDEX, b]
        bounce = rec.i[I_BOUNCE, b]
        front = rec.i[I_FRONT, b]
        thin = rec.i[I_THIN, b]
        use_spec = rec.i[I_USE_SPEC, b]
        cr = vecL()
        cg = vecL()
        cb = vecL()
        wix = vecL()
        wiy = vecL()
        wiz = vecL()
        dist = vecL()
        for k in range(LANES):
            params = record_params(dr[k], dg[k], db[k], sr[k], sg[k], sb[k], use_spec[k], metallic[k],
                                   roughness[k], clearcoat[k], cc_rough[k], opacity[k], ior[k], thin[k])
            c, wi, d = nee_lane(L, seed, pinhole, wp.uint32(pixel[k]), wp.uint32(index[k]), bounce[k],
                                wp.vec3(px[k], py[k], pz[k]), wp.vec3(ngx[k], ngy[k], ngz[k]),
                                wp.vec3(nsx[k], nsy[k], nsz[k]), wp.vec3(wox[k], woy[k], woz[k]), front[k], params)
            cr[k] = c[0]
            cg[k] = c[1]
            cb[k] = c[2]
            wix[k] = wi[0]
            wiy[k] = wi[1]
            wiz[k] = wi[2]
            dist[k] = d
        rec.out[O_CR, b] = cr
        rec.out[O_CG, b] = cg
        rec.out[O_CB, b] = cb
        rec.out[O_WIX, b] = wix
        rec.out[O_WIY, b] = wiy
        rec.out[O_WIZ, b] = wiz
        rec.out[O_DIST, b] = dist
    return nee_lanes


# ---- the same computation in scalar floats only (the loop vectorizer's terms) --------------------------------
# Every ``@wp.func`` above that takes or returns a ``wp.vec3`` is a C++ function whose vec3 travels, by the x86-64
# calling convention, as {<2 x float>, float}; inlined, those <2 x float> values stay in the loop body, and LLVM's
# loop vectorizer refuses any loop holding a vector-typed instruction ("instruction return type cannot be
# vectorized", its remark; ``-opt-record-file``). So the vectorized stage is written anew below in plain floats
# (tuples of floats are returned through references, which inlining removes), lobe by lobe as ``bsdf``, ``lobes``,
# ``microfacet`` and ``warps`` compute them, for the records of the bench scenes: diffuse and GGX specular lobes,
# no clearcoat, opaque (checked on the host).

@wp.func
def dot3(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> float:
    return ax * bx + ay * by + az * bz


@wp.func
def owen3_soa(v0: wp.uint32, v1: wp.uint32, v2: wp.uint32, h: wp.uint32, k: wp.uint32, first_reversed: int):
    """``owen_scramble3_reference`` as three floats."""
    x0 = v0
    if first_reversed != 0:
        x0 = reverse_bits32(v0)
    return (u32_to_unit_float(owen_scramble(x0, mix32(h + k))),
            u32_to_unit_float(owen_scramble(v1, mix32(h + k + wp.uint32(1)))),
            u32_to_unit_float(owen_scramble(v2, mix32(h + k + wp.uint32(2)))))


@wp.func
def schlick_w(c: float) -> float:
    m = wp.clamp(1.0 - c, 0.0, 1.0)
    m2 = m * m
    return m2 * m2 * m


@wp.func
def ggx_d_soa(hx: float, hy: float, hz: float, alpha: float) -> float:
    if hz <= 0.0:
        return 0.0
    a2 = alpha * alpha
    sin2 = hx * hx + hy * hy
    t = a2 * hz * hz + sin2
    if t <= 0.0:
        return 0.0
    return a2 * INV_PI / (t * t)


@wp.func
def ggx_lambda_soa(x: float, y: float, z: float, alpha: float) -> float:
    cos2 = z * z
    sin2 = x * x + y * y
    if cos2 <= 0.0:
        return 1.0e30
    a = alpha * alpha * sin2 / cos2
    return a / (2.0 * (wp.sqrt(1.0 + a) + 1.0))


@wp.func
def nee_soa(seed: wp.uint32, pinhole: int, pixel: wp.uint32, index: wp.uint32, bounce: int,
            px: float, py: float, pz: float, ngx: float, ngy: float, ngz: float, nx: float, ny: float, nz: float,
            wox: float, woy: float, woz: float, dr: float, dg: float, db: float, sr: float, sg: float, sb: float,
            use_spec: int, metallic: float, roughness: float, opacity: float, ior: float, L: OneRect):
    """``nee_lane`` for a diffuse + GGX specular opaque surface and one rect light, in floats: (cr, cg, cb, wix,
    wiy, wiz, dist)."""
    # ---- bsdf_setup (its frame's normal: the geometric one where wo is below the shading normal; the cosine of
    # the contribution keeps the shading normal)
    fnx = nx
    fny = ny
    fnz = nz
    if dot3(nx, ny, nz, wox, woy, woz) <= 0.0:
        fnx = ngx
        fny = ngy
        fnz = ngz
    sign = wp.where(fnz >= 0.0, 1.0, -1.0)
    oa = -1.0 / (sign + fnz)  # frame_from_normal's a and b
    ob = fnx * fny * oa
    sx = 1.0 + sign * fnx * fnx * oa
    sy = sign * ob
    sz = -sign * fnx
    tx = ob
    ty = sign + fny * fny * oa
    tz = -fny
    wlx = dot3(sx, sy, sz, wox, woy, woz)
    wly = dot3(tx, ty, tz, wox, woy, woz)
    wlz = dot3(fnx, fny, fnz, wox, woy, woz)
    valid = wlz > 0.0 and dot3(ngx, ngy, ngz, wox, woy, woz) > 0.0
    op = wp.clamp(opacity, 0.0, 1.0)
    dcr = wp.clamp(dr, 0.0, 1.0)
    dcg = wp.clamp(dg, 0.0, 1.0)
    dcb = wp.clamp(db, 0.0, 1.0)
    wd = float(1.0)
    f0r = wp.clamp(sr, 0.0, 1.0)
    f0g = wp.clamp(sg, 0.0, 1.0)
    f0b = wp.clamp(sb, 0.0, 1.0)
    if use_spec == 0:
        mt = wp.clamp(metallic, 0.0, 1.0)
        wd = 1.0 - mt
        ri = wp.max(ior, 1.0e-3)
        r = (1.0 - ri) / (1.0 + ri)
        f0d = r * r
        f0r = f0d * (1.0 - mt) + dcr * mt
        f0g = f0d * (1.0 - mt) + dcg * mt
        f0b = f0d * (1.0 - mt) + dcb * mt
    f90 = wp.clamp(50.0 * dot3(f0r, f0g, f0b, 0.2126, 0.7152, 0.0722), 0.0, 1.0)
    kw = op * wd
    kdr = dcr * kw
    kdg = dcg * kw
    kdb = dcb * kw
    alpha = wp.max(wp.clamp(roughness, 0.0, 1.0) * wp.clamp(roughness, 0.0, 1.0), 1.0e-4)
    co = wp.clamp(wlz, 0.0, 1.0)
    swo = schlick_w(co)
    e_spec = float(0.0)
    if op > 0.0 and f90 > 0.0:
        e_spec = op * wp.max(dot3(f0r + (f90 - f0r) * swo, f0g + (f90 - f0g) * swo, f0b + (f90 - f0b) * swo,
                                  0.2126, 0.7152, 0.0722), 0.02)
    e_diff = dot3(kdr * (1.0 - (f0r + (f90 - f0r) * swo)), kdg * (1.0 - (f0g + (f90 - f0g) * swo)),
                  kdb * (1.0 - (f0b + (f90 - f0b) * swo)), 0.2126, 0.7152, 0.0722)
    total_b = e_spec + e_diff
    p_spec = float(0.0)
    p_diff = float(0.0)
    if total_b > 0.0 and valid:
        p_spec = e_spec / total_b
        p_diff = e_diff / total_b
    else:
        valid = False
    # ---- the light dimensions (the scalar twin of the sampler's vector scramble)
    dim = wp.uint32(DIM_LIGHT_BASE + bounce * DIMS_PER_BOUNCE) + wp.uint32(BOUNCE_LIGHT_CHOICE)
    h = pattern_hash(seed, pixel, dim)
    si = owen_scramble(index, h)
    d1, d2 = sobol_dims12(si)
    u0, u1, u2 = owen3_soa(si, d1, d2, h, wp.uint32(1), 1)
    if bounce == 1 and pinhole != 0:
        hc = pattern_hash(seed, pixel, wp.uint32(DIM_FILM))
        ic = owen_scramble(index, hc)
        c0, c1, c2 = owen3_soa(_byte_product(W_SOBOL7_TABLE, ic), _byte_product(W_SOBOL8_TABLE, ic), wp.uint32(0),
                               hc, wp.uint32(4 + 2 * CAMERA_LIGHT_1), 0)
        u0 = c0
        u1 = c1
    # ---- offset_origin, the light choice, the rectangle's spherical sample (sample_rect)
    sc = 1.0 + wp.max(wp.max(wp.abs(px), wp.abs(py)), wp.abs(pz))
    ox = px + ngx * (2.0e-5 * sc)
    oy = py + ngy * (2.0e-5 * sc)
    oz = pz + ngz * (2.0e-5 * sc)
    cdx = L.centre[0] - px
    cdy = L.centre[1] - py
    cdz = L.centre[2] - pz
    total = wp.min(L.power / wp.max(dot3(cdx, cdy, cdz, cdx, cdy, cdz), L.radius2), L.cap)
    p_sel = (total / total) * L.p_in
    dx = L.corner[0] - ox
    dy = L.corner[1] - oy
    dz = L.corner[2] - oz
    x0 = dot3(dx, dy, dz, L.exu[0], L.exu[1], L.exu[2])
    y0 = dot3(dx, dy, dz, L.eyu[0], L.eyu[1], L.eyu[2])
    z0 = dot3(dx, dy, dz, L.ezu[0], L.ezu[1], L.ezu[2])
    ezs = float(1.0)
    if z0 > 0.0:
        ezs = -1.0
        z0 = -z0
    x1 = x0 + L.exl
    y1 = y0 + L.eyl
    g01, g23, b0, b1, solid_angle = _sph_rect_angles_reference(x0, y0, z0, x1, y1)
    gx = float(0.0)
    gy = float(0.0)
    gz = float(0.0)
    gdist = float(0.0)
    gpdf = float(0.0)
    if not _use_sph_rect(solid_angle):  # area sampling (_area_sample_geom)
        qx = L.corner[0] + u0 * L.ex[0] + u1 * L.ey[0] - ox
        qy = L.corner[1] + u0 * L.ex[1] + u1 * L.ey[1] - oy
        qz = L.corner[2] + u0 * L.ex[2] + u1 * L.ey[2] - oz
        dist2 = dot3(qx, qy, qz, qx, qy, qz)
        gdist = wp.sqrt(dist2)
        if dist2 > 0.0:
            gx = qx / gdist
            gy = qy / gdist
            gz = qz / gdist
            cos_l = wp.abs(dot3(L.normal[0], L.normal[1], L.normal[2], gx, gy, gz))
            if cos_l > 0.0 and L.area > 0.0:
                gpdf = dist2 / (cos_l * L.area)
    else:
        au = u0 * (g01 - TWO_PI) + (u0 - 1.0) * g23
        sau, cau = sin_cos(au)
        fu = (cau * b0 - b1) / sau
        e = fu * fu + b0 * b0 - 1.0
        xu = wp.clamp(wp.where(fu < 0.0, z0, -z0) / wp.sqrt(wp.max(e, XU_RADICAND_MIN)), x0, x1)
        dd2 = xu * xu + z0 * z0
        h0 = y0 / wp.sqrt(dd2 + y0 * y0)
        h1 = y1 / wp.sqrt(dd2 + y1 * y1)
        dd = wp.sqrt(dd2)
        hv = h0 + u1 * (h1 - h0)
        hv2 = hv * hv
        yv = y1
        if hv2 < 1.0 - 1e-6:
            yv = hv * dd / wp.sqrt(1.0 - hv2)
        yv = wp.clamp(yv, y0, y1)
        zs = z0 * ezs
        qx = xu * L.exu[0] + yv * L.eyu[0] + zs * L.ezu[0]
        qy = xu * L.exu[1] + yv * L.eyu[1] + zs * L.ezu[1]
        qz = xu * L.exu[2] + yv * L.eyu[2] + zs * L.ezu[2]
        gdist = wp.sqrt(dot3(qx, qy, qz, qx, qy, qz))
        gx = qx / gdist
        gy = qy / gdist
        gz = qz / gdist
        gpdf = 1.0 / solid_angle
    wix = float(0.0)
    wiy = float(0.0)
    wiz = float(0.0)
    dist = float(0.0)
    pdf_l = float(0.0)
    if total > 0.0 and gpdf > 0.0 and dot3(gx, gy, gz, L.front[0], L.front[1], L.front[2]) < 0.0:
        wix = gx
        wiy = gy
        wiz = gz
        dist = gdist
        pdf_l = gpdf
    # ---- lobes_eval, lobes_pdf at wi, the power heuristic
    cr = float(0.0)
    cg = float(0.0)
    cb = float(0.0)
    ilx = dot3(sx, sy, sz, wix, wiy, wiz)
    ily = dot3(tx, ty, tz, wix, wiy, wiz)
    ilz = dot3(fnx, fny, fnz, wix, wiy, wiz)
    cgn = dot3(ngx, ngy, ngz, wix, wiy, wiz)
    leaks = ilz == 0.0 or cgn == 0.0 or (ilz > 0.0) != (cgn > 0.0)
    if pdf_l > 0.0 and valid and not leaks and ilz > 0.0 and wlz > 0.0:
        # diffuse_eval
        wo5 = 1.0 - (1.0 - schlick_w(wlz))  # diffuse_eval's 1 - diffuse_fresnel_factor
        wi5 = 1.0 - (1.0 - schlick_w(ilz))
        fr = kdr * ((1.0 - f0r - (f90 - f0r) * wo5) * (1.0 - f0r - (f90 - f0r) * wi5)
                    / wp.max(1.0 - f0r - (f90 - f0r) * (1.0 / 21.0), 1.0e-6)) * INV_PI
        fg = kdg * ((1.0 - f0g - (f90 - f0g) * wo5) * (1.0 - f0g - (f90 - f0g) * wi5)
                    / wp.max(1.0 - f0g - (f90 - f0g) * (1.0 / 21.0), 1.0e-6)) * INV_PI
        fb = kdb * ((1.0 - f0b - (f90 - f0b) * wo5) * (1.0 - f0b - (f90 - f0b) * wi5)
                    / wp.max(1.0 - f0b - (f90 - f0b) * (1.0 / 21.0), 1.0e-6)) * INV_PI
        pdf_b = p_diff * (ilz * INV_PI)
        if op > 0.0 and alpha >= 1.0e-3:  # ggx_reflection_eval and its sampling pdf
            hx = wlx + ilx
            hy = wly + ily
            hz = wlz + ilz
            lh = wp.sqrt(dot3(hx, hy, hz, hx, hy, hz))
            if lh > 0.0:
                hx = hx / lh
                hy = hy / lh
                hz = hz / lh
                dd_h = ggx_d_soa(hx, hy, hz, alpha)
                lam_o = ggx_lambda_soa(wlx, wly, wlz, alpha)
                v = dd_h * (1.0 / (1.0 + lam_o + ggx_lambda_soa(ilx, ily, ilz, alpha))) / (4.0 * wlz * ilz)
                c = wp.max(dot3(wlx, wly, wlz, hx, hy, hz), 0.0)
                sw = schlick_w(c)
                fr = fr + (f0r + (f90 - f0r) * sw) * (op * v)
                fg = fg + (f0g + (f90 - f0g) * sw) * (op * v)
                fb = fb + (f0b + (f90 - f0b) * sw) * (op * v)
                if p_spec > 0.0 and c > 0.0:
                    pdf_b = pdf_b + p_spec * ((1.0 / (1.0 + lam_o)) * c * dd_h / wlz) / (4.0 * c)
        if fr > 0.0 or fg > 0.0 or fb > 0.0:
            a = p_sel * pdf_l
            a2 = a * a
            b2 = pdf_b * pdf_b
            w = float(0.0)
            if a2 + b2 > 0.0:
                w = a2 / (a2 + b2)
            k = wp.abs(dot3(nx, ny, nz, wix, wiy, wiz)) * w / a
            cr = fr * L.Le[0] * k
            cg = fg * L.Le[1] * k
            cb = fb * L.Le[2] * k
    return cr, cg, cb, wix, wiy, wiz, dist


def nee_soa_kernel(module: str):
    @wp.kernel(module=module)
    def nee_soa_batch(rec: LaneRecords, lights: Lights, seed: wp.uint32, pinhole: int):
        """``nee_soa`` over a batch of LANES records in local vectors."""
        b = wp.tid()
        L = one_rect(lights)
        px = rec.f[F_PX, b]
        py = rec.f[F_PY, b]
        pz = rec.f[F_PZ, b]
        ngx = rec.f[F_NGX, b]
        ngy = rec.f[F_NGY, b]
        ngz = rec.f[F_NGZ, b]
        nsx = rec.f[F_NSX, b]
        nsy = rec.f[F_NSY, b]
        nsz = rec.f[F_NSZ, b]
        wox = rec.f[F_WOX, b]
        woy = rec.f[F_WOY, b]
        woz = rec.f[F_WOZ, b]
        dr = rec.f[F_DR, b]
        dg = rec.f[F_DG, b]
        db = rec.f[F_DB, b]
        sr = rec.f[F_SR, b]
        sg = rec.f[F_SG, b]
        sb = rec.f[F_SB, b]
        metallic = rec.f[F_METALLIC, b]
        roughness = rec.f[F_ROUGHNESS, b]
        opacity = rec.f[F_OPACITY, b]
        ior = rec.f[F_IOR, b]
        pixel = rec.i[I_PIXEL, b]
        index = rec.i[I_INDEX, b]
        bounce = rec.i[I_BOUNCE, b]
        use_spec = rec.i[I_USE_SPEC, b]
        cr = vecL()
        cg = vecL()
        cb = vecL()
        wix = vecL()
        wiy = vecL()
        wiz = vecL()
        dist = vecL()
        for k in range(LANES):
            r0, r1, r2, r3, r4, r5, r6 = nee_soa(
                seed, pinhole, wp.uint32(pixel[k]), wp.uint32(index[k]), bounce[k], px[k], py[k], pz[k], ngx[k],
                ngy[k], ngz[k], nsx[k], nsy[k], nsz[k], wox[k], woy[k], woz[k], dr[k], dg[k], db[k], sr[k], sg[k],
                sb[k], use_spec[k], metallic[k], roughness[k], opacity[k], ior[k], L)
            cr[k] = r0
            cg[k] = r1
            cb[k] = r2
            wix[k] = r3
            wiy[k] = r4
            wiz[k] = r5
            dist[k] = r6
        rec.out[O_CR, b] = cr
        rec.out[O_CG, b] = cg
        rec.out[O_CB, b] = cb
        rec.out[O_WIX, b] = wix
        rec.out[O_WIY, b] = wiy
        rec.out[O_WIZ, b] = wiz
        rec.out[O_DIST, b] = dist
    return nee_soa_batch


def nee_soa_flat_kernel(module: str):
    @wp.kernel(module=module)
    def nee_soa_flat(rec: FlatRecords, lights: Lights, seed: wp.uint32, pinhole: int):
        """``nee_soa`` over LANES records read from and written to plain float arrays (run-time strides)."""
        b = wp.tid()
        L = one_rect(lights)
        for k in range(LANES):
            i = b * LANES + k
            r0, r1, r2, r3, r4, r5, r6 = nee_soa(
                seed, pinhole, wp.uint32(rec.i[I_PIXEL, i]), wp.uint32(rec.i[I_INDEX, i]), rec.i[I_BOUNCE, i],
                rec.f[F_PX, i], rec.f[F_PY, i], rec.f[F_PZ, i], rec.f[F_NGX, i], rec.f[F_NGY, i], rec.f[F_NGZ, i],
                rec.f[F_NSX, i], rec.f[F_NSY, i], rec.f[F_NSZ, i], rec.f[F_WOX, i], rec.f[F_WOY, i],
                rec.f[F_WOZ, i], rec.f[F_DR, i], rec.f[F_DG, i], rec.f[F_DB, i], rec.f[F_SR, i], rec.f[F_SG, i],
                rec.f[F_SB, i], rec.i[I_USE_SPEC, i], rec.f[F_METALLIC, i], rec.f[F_ROUGHNESS, i],
                rec.f[F_OPACITY, i], rec.f[F_IOR, i], L)
            rec.out[O_CR, i] = r0
            rec.out[O_CG, i] = r1
            rec.out[O_CB, i] = r2
            rec.out[O_WIX, i] = r3
            rec.out[O_WIY, i] = r4
            rec.out[O_WIZ, i] = r5
            rec.out[O_DIST, i] = r6
    return nee_soa_flat


TARGET_FLAGS = {
    "v3": PORTABLE_FLAGS,  # the shipped kernels' target: x86-64-v3 (AVX2, FMA), Warp's inlining flags
    "native": wp.config.cpu_compiler_flags,  # Warp's default: -march=native (AVX-512 on an AVX-512 host)
}
# LLVM's cost model finds the SoA loop "not beneficial" on its own (its remark): the loop variants force the
# vectorization factor, as ``#pragma clang loop vectorize_width`` would in hand-written C++
FORCE = " -mllvm=-force-vector-width={}"
# variant: (kernel factory, extra flags)
VARIANT_BUILD = {
    "scalar": ("nee_scalar_kernel", ""),
    "lanes-vec3": ("nee_lanes_kernel", FORCE.format(8)),
    "soa": ("nee_soa_kernel", FORCE.format(8)),
    "soa-w16": ("nee_soa_kernel", FORCE.format(16)),
    "soa-novec": ("nee_soa_kernel", " -fno-vectorize"),
    "soa-flat": ("nee_soa_flat_kernel", FORCE.format(8)),
}
VARIANTS = tuple(VARIANT_BUILD)


def module_name(variant: str, target: str) -> str:
    return f"lanes_nee_{variant.replace('-', '_')}_{target}"


_KERNELS: dict[str, dict] = {}


def nee_kernels(target: str) -> dict:
    """The NEE kernels of one build target, each in a module of its own (its own flags and object)."""
    if target in _KERNELS:
        return _KERNELS[target]
    out = _KERNELS[target] = {}
    for variant, (make, extra) in VARIANT_BUILD.items():
        name = module_name(variant, target)
        out[variant] = globals()[make](name)
        wp.set_module_options({"cpu_compiler_flags": TARGET_FLAGS[target] + extra, "enable_backward": False},
                              module=wp.get_module(name))
    return out


def compile_apart(target: str, kernels: dict) -> None:
    """Compile each NEE module not yet in Warp's cache in a process of its own: LLVM's ``-mllvm`` options are
    process-wide, so a forced vector width would leak into the modules compiled after it."""
    for variant, k in kernels.items():
        obj = module_object(k.module.name)
        if obj is None or not obj.exists():
            subprocess.run([sys.executable, __file__, "--compile", variant, target], check=True)


def check_one_rect(lights) -> None:
    """The lanes' assumptions (``one_rect``): one finite cluster of one still, untextured, unshaped rect light."""
    from renderer.scene.model import LIGHT_RECT

    sel = lights.select
    kind = lights.kind.numpy()
    if not (sel.count == 1 and sel.n_finite == 1 and sel.n.numpy()[0] == 1 and lights.count == 1
            and kind[0] == LIGHT_RECT and lights.xf_count.numpy()[0] == 1 and lights.img_off.numpy()[0] < 0
            and lights.shape0.numpy()[0][3] == 0.0 and lights.rad_count.numpy()[0] < 2
            and lights.links.light_bit.numpy()[0] < 0 and lights.lobe_mults == 0):
        raise SystemExit("the NEE lanes are written for one still rect light without texture, shaping or links")


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


def launch_nee(variant: str, kernel, flat, lanes, prep, seed: int, pinhole: int) -> None:
    n = flat.f.shape[1]
    if variant == "scalar":
        wp.launch(kernel, dim=n, inputs=[flat, prep.geometry, prep.materials, prep.textures, prep.lights,
                                         wp.uint32(seed), pinhole])
    elif variant in ("soa-flat",):
        wp.launch(kernel, dim=n // LANES, inputs=[flat, prep.lights, wp.uint32(seed), pinhole])
    else:
        wp.launch(kernel, dim=n // LANES, inputs=[lanes, prep.lights, wp.uint32(seed), pinhole])
    wp.synchronize()


def module_object(name: str) -> pathlib.Path | None:
    from renderer.kernel_cache import _cpu_object

    return _cpu_object(wp.get_module(name))


def isa_profile(obj: pathlib.Path) -> dict:
    """Instruction mix of a module's object: vector registers used, packed and scalar float ops, gathers."""
    text = subprocess.run(["objdump", "-d", "--no-show-raw-insn", str(obj)], capture_output=True, text=True).stdout
    c = collections.Counter()
    for line in text.splitlines():
        parts = line.split("\t")
        if len(parts) < 2 or not parts[1].strip():
            continue
        ins = parts[1].split()
        op = ins[0]
        c["total"] += 1
        args = " ".join(ins[1:])
        for reg in ("zmm", "ymm", "xmm"):
            if reg in args:
                c[reg] += 1
                break
        if re.fullmatch(r"v?(add|sub|mul|div|sqrt|min|max|fmadd\d*|fmsub\d*|fnmadd\d*|fnmsub\d*)ps", op) or \
                re.fullmatch(r"v(fmadd|fmsub|fnmadd|fnmsub)\d+ps", op):
            c["packed_ps_" + ("zmm" if "zmm" in args else "ymm" if "ymm" in args else "xmm")] += 1
        elif re.fullmatch(r"v?(add|sub|mul|div|sqrt|min|max)ss|v(fmadd|fmsub|fnmadd|fnmsub)\d+ss", op):
            c["scalar_ss"] += 1
        if "gather" in op:
            c["gather"] += 1
    return dict(c)


# ================================================================================================================
# 3. Instruction counts under callgrind (a child process per run)
# ================================================================================================================

def count_child(lib: str, data: str, scene: str, width: int, spp: int, target: str) -> None:
    toggle = ctypes.CDLL(lib)
    prep, _ = prepared(scene, width, spp)
    z = np.load(data)
    flat, lanes, _keep = lane_views(z["f"], z["i"], NO)
    kernels = nee_kernels(target)
    pinhole = int(prep.camera.params.lens_radius <= 0.0)
    for variant in VARIANTS:
        launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)  # load, warm
    for variant in VARIANTS:
        toggle.drt_cg_zero()
        toggle.drt_cg_on()
        launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)
        toggle.drt_cg_off()
        toggle.drt_cg_dump()


def callgrind_counts(scene: str, width: int, spp: int, target: str, f: np.ndarray, i: np.ndarray) -> dict:
    from instructions import TOGGLE_C

    cc = shutil.which("cc") or shutil.which("gcc")
    if not shutil.which("valgrind") or not cc:
        raise SystemExit("--count needs valgrind and a C compiler")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        (tmp / "toggle.c").write_text(TOGGLE_C)
        lib = tmp / "libtoggle.so"
        subprocess.run([cc, "-O1", "-shared", "-fPIC", "-o", str(lib), str(tmp / "toggle.c")], check=True)
        np.savez(tmp / "rec.npz", f=f, i=i)
        out = tmp / "cg.out"
        cmd = ["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={out}", sys.executable,
               __file__, "--child", str(lib), str(tmp / "rec.npz"), scene, str(width), str(spp), target]
        run = subprocess.run(cmd, capture_output=True, text=True)
        dumps = sorted(out.parent.glob(out.name + "*"), key=lambda p: int(p.name.rsplit(".", 1)[-1])
                       if p.name.rsplit(".", 1)[-1].isdigit() else 0)
        totals = [int(m) for d in dumps for m in re.findall(r"^totals: (\d+)", d.read_text(), re.M)]
        totals = [t for t in totals if t > 0]
        if run.returncode != 0 or len(totals) != len(VARIANTS):
            raise SystemExit(f"callgrind failed (exit {run.returncode}, {len(totals)} dumps):\n{run.stderr[-3000:]}")
        return dict(zip(VARIANTS, totals))


# ================================================================================================================
# 4. Embree: rtcIntersect8/16 and rtcOccluded8/16 against as many single-ray calls
# ================================================================================================================

def _packet_cpp(width: int, occluded: bool) -> str:
    """A native snippet tracing rays first .. first + count - 1 (count <= width) as one packet of ``width``."""
    w = width
    ray = (f"struct alignas({4 * w}) RayN {{ float ox[{w}], oy[{w}], oz[{w}], tnear[{w}], dx[{w}], dy[{w}], "
           f"dz[{w}], time[{w}], tfar[{w}]; unsigned mask[{w}], id[{w}], flags[{w}]; }};\n"
           f"    struct alignas({4 * w}) HitN {{ float ngx[{w}], ngy[{w}], ngz[{w}], u[{w}], v[{w}]; "
           f"unsigned prim[{w}], geom[{w}], inst[{w}], instprim[{w}]; }};\n"
           f"    struct alignas({4 * w}) RayHitN {{ RayN ray; HitN hit; }};\n")
    body = f"""
    {ray}
    const float* o = (const float*)ro;
    const float* d = (const float*)rd;
    const float* tm = (const float*)tmax;
    alignas({4 * w}) int valid[{w}];
    {"RayN r;" if occluded else "RayHitN rh; RayN& r = rh.ray;"}
    for (int k = 0; k < {w}; ++k) {{
        const int i = first + (k < count ? k : 0);
        valid[k] = k < count ? -1 : 0;
        r.ox[k] = o[3 * i]; r.oy[k] = o[3 * i + 1]; r.oz[k] = o[3 * i + 2]; r.tnear[k] = 0.0f;
        r.dx[k] = d[3 * i]; r.dy[k] = d[3 * i + 1]; r.dz[k] = d[3 * i + 2]; r.time[k] = 0.0f;
        r.tfar[k] = tm[i]; r.mask[k] = 0xffffffffu; r.id[k] = 0; r.flags[k] = 0;
        {"" if occluded else "rh.hit.geom[k] = 0xffffffffu; rh.hit.inst[k] = 0xffffffffu;"}
    }}
    typedef void (*fn_t)(const int*, void*, void*, void*);
    ((fn_t)fn)(valid, (void*)scene, (void*)&{"r" if occluded else "rh"}, nullptr);
    int* res = (int*)out;
    float* t = (float*)tout;
    for (int k = 0; k < count; ++k) {{
        {"res[first + k] = r.tfar[k] < 0.0f ? 1 : 0;" if occluded else
         "res[first + k] = rh.hit.geom[k] == 0xffffffffu ? -1 : (int)rh.hit.prim[k]; t[first + k] = r.tfar[k];"}
    }}
"""
    return body


def _single_cpp(occluded: bool) -> str:
    return f"""
    struct alignas(16) Ray {{ float ox, oy, oz, tnear, dx, dy, dz, time, tfar; unsigned mask, id, flags; }};
    struct alignas(16) Hit {{ float ngx, ngy, ngz, u, v; unsigned prim, geom, inst[2], pad[3]; }};
    struct alignas(16) RayHit {{ Ray ray; Hit hit; }};
    const float* o = (const float*)ro;
    const float* d = (const float*)rd;
    const float* tm = (const float*)tmax;
    int* res = (int*)out;
    float* t = (float*)tout;
    typedef void (*fn_t)(void*, void*, void*);
    for (int k = 0; k < count; ++k) {{
        const int i = first + k;
        RayHit rh;
        Ray& r = rh.ray;
        r.ox = o[3 * i]; r.oy = o[3 * i + 1]; r.oz = o[3 * i + 2]; r.tnear = 0.0f;
        r.dx = d[3 * i]; r.dy = d[3 * i + 1]; r.dz = d[3 * i + 2]; r.time = 0.0f;
        r.tfar = tm[i]; r.mask = 0xffffffffu; r.id = 0; r.flags = 0;
        rh.hit.geom = 0xffffffffu; rh.hit.inst[0] = 0xffffffffu;
        ((fn_t)fn)((void*)scene, (void*){"&r" if occluded else "&rh"}, nullptr);
        {"res[i] = r.tfar < 0.0f ? 1 : 0;" if occluded else
         "res[i] = rh.hit.geom == 0xffffffffu ? -1 : (int)rh.hit.prim; t[i] = r.tfar;"}
    }}
"""


def _native(snippet: str, name: str):
    def trace(fn: wp.uint64, scene: wp.uint64, ro: wp.uint64, rd: wp.uint64, tmax: wp.uint64, out: wp.uint64,
              tout: wp.uint64, first: int, count: int):
        ...
    trace.__name__ = trace.__qualname__ = name  # one Warp function per snippet
    trace.__annotations__ = {"fn": wp.uint64, "scene": wp.uint64, "ro": wp.uint64, "rd": wp.uint64,
                             "tmax": wp.uint64, "out": wp.uint64, "tout": wp.uint64, "first": int,
                             "count": int}  # types, not the strings of postponed annotations
    return wp.func_native(snippet)(trace)


EMBREE_MODULE = "lanes_embree"
_TRACERS = {}
for _occ in (False, True):
    _TRACERS[("single", _occ)] = _native(_single_cpp(_occ), f"trace_single_{int(_occ)}")
    for _w in (8, 16):
        _TRACERS[(_w, _occ)] = _native(_packet_cpp(_w, _occ), f"trace_packet{_w}_{int(_occ)}")


def _rays_kernel(tracer, name: str):
    @wp.kernel(module=f"{EMBREE_MODULE}_{name}")
    def rays(fn: wp.uint64, scene: wp.uint64, ro: wp.uint64, rd: wp.uint64, tmax: wp.uint64, out: wp.uint64,
             tout: wp.uint64, n: int, width: int):
        tid = wp.tid()
        first = tid * width
        tracer(fn, scene, ro, rd, tmax, out, tout, first, wp.min(width, n - first))
    wp.set_module_options({"enable_backward": False}, module=wp.get_module(f"{EMBREE_MODULE}_{name}"))
    return rays


_RAY_KERNELS = {key: _rays_kernel(tr, f"{key[0]}_{int(key[1])}") for key, tr in _TRACERS.items()}


def world_triangles(scene) -> tuple[np.ndarray, np.ndarray]:
    """Every instance's triangles in world space at shutter time 0, one mesh."""
    from renderer.motion.transform import matrix_at

    pts, tris, base = [], [], 0
    for inst in scene.instances:
        mesh = scene.meshes[inst.mesh]
        m = matrix_at(inst.transform, 0.0)
        pts.append((mesh.points[0].astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32))
        tris.append(mesh.triangles.astype(np.int32) + base)
        base += len(mesh.points[0])
    return np.concatenate(pts), np.concatenate(tris)


def embree_packets(scene, rays: dict, repeats: int) -> list[tuple]:
    """Rows (ray set, rays, call, M rays/s, agreement with single rays)."""
    from renderer.accel import embree

    lib = embree.library()
    if lib is None:
        raise SystemExit("Embree is not available (embreex)")
    dev = embree.EmbreeScenes(lib, threads=1)
    pts, tris = world_triangles(scene)
    handle, _ = dev.add_mesh(pts, tris)
    fns = {("single", False): lib.rtcIntersect1, ("single", True): lib.rtcOccluded1,
           (8, False): lib.rtcIntersect8, (8, True): lib.rtcOccluded8,
           (16, False): lib.rtcIntersect16, (16, True): lib.rtcOccluded16}
    rows = []
    calls = (("1 x8", 8), ("8", 8), ("1 x16", 16), ("16", 16))
    for set_name, (o, d, tmax, occluded) in rays.items():
        n = len(o)
        ro = wp.array(np.ascontiguousarray(o, np.float32).ravel(), dtype=wp.float32)
        rd = wp.array(np.ascontiguousarray(d, np.float32).ravel(), dtype=wp.float32)
        tm = wp.array(np.ascontiguousarray(tmax, np.float32), dtype=wp.float32)
        runs = {}
        for call, width in calls:
            key = ("single" if call.startswith("1") else width, occluded)
            fn = ctypes.cast(fns[key], ctypes.c_void_p).value
            res = wp.zeros(n, dtype=wp.int32)
            t = wp.zeros(n, dtype=wp.float32)
            args = [wp.uint64(fn), wp.uint64(handle), wp.uint64(ro.ptr), wp.uint64(rd.ptr), wp.uint64(tm.ptr),
                    wp.uint64(res.ptr), wp.uint64(t.ptr), n, width]
            runs[call] = (_RAY_KERNELS[key], (n + width - 1) // width, args, res, t)  # t: alive while traced
            wp.launch(runs[call][0], dim=runs[call][1], inputs=args)  # load, warm
        wp.synchronize()
        best = dict.fromkeys(runs, float("inf"))
        for _ in range(repeats):  # interleaved, as the NEE timings
            for call, (kernel, threads, args, *_out) in runs.items():
                c = time.perf_counter()
                wp.launch(kernel, dim=threads, inputs=args)
                wp.synchronize()
                best[call] = min(best[call], time.perf_counter() - c)
        ref = runs["1 x8"][3].numpy()
        for call, (*_, res, _t) in runs.items():
            rows.append((set_name, n, ("rtcOccluded" if occluded else "rtcIntersect") + call, n / best[call] / 1e6,
                         float(np.mean(res.numpy() == ref))))
    dev.close()
    return rows


# ================================================================================================================
# Driver
# ================================================================================================================

def prepared(scene: str, width: int, spp: int):
    from renderer.render import RenderOptions, prepare
    from renderer.usd.importer import load_scene
    from renderer.device import init_warp

    init_warp()
    path = pathlib.Path(scene)
    if not path.exists():
        path = SCENES / f"{scene}.usda"
    sc = load_scene(path)
    probe = prepare(sc, RenderOptions(width=width, spp=spp))  # the height from the camera's aspect
    return probe, sc


def shadow_rays(f: np.ndarray, out: np.ndarray):
    """The shadow rays of the samples with a contribution, as the integrator starts them (``offset_origin``)."""
    c = out[O_CR] + out[O_CG] + out[O_CB]
    keep = c > 0.0
    p = f[[F_PX, F_PY, F_PZ]].T[keep].astype(np.float32)
    ng = f[[F_NGX, F_NGY, F_NGZ]].T[keep].astype(np.float32)
    wi = out[[O_WIX, O_WIY, O_WIZ]].T[keep].astype(np.float32)
    ng = np.where(((wi * ng).sum(1) < 0.0)[:, None], -ng, ng)
    scale = np.float32(1.0) + np.abs(p).max(1)
    o = p + ng * (np.float32(2.0e-5) * scale)[:, None]
    return o, wi, (out[O_DIST][keep] * np.float32(1.0 - 1.0e-4)).astype(np.float32)


def time_nee(kernels: dict, flat, lanes, prep, pinhole: int, repeats: int) -> dict:
    best = {}
    for variant in VARIANTS:
        launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)  # compile / load
    for _ in range(repeats):  # interleaved: a burst of load from other processes hits every variant alike
        for variant in VARIANTS:
            c = time.perf_counter()
            launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)
            best[variant] = min(best.get(variant, float("inf")), time.perf_counter() - c)
    return best


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--compile":
        from renderer.device import init_warp

        init_warp()
        variant, target = sys.argv[2:4]
        wp.load_module(nee_kernels(target)[variant].module, device="cpu")
        return
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        lib, data, scene, width, spp, target = sys.argv[2:8]
        count_child(lib, data, scene, int(width), int(spp), target)
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="cornell", help="bench scene name or USD path (NEE part)")
    ap.add_argument("--width", type=int, default=320, help="capture width in pixels (height from the camera)")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--target", default="v3,native", help="comma-separated build targets: v3, native")
    ap.add_argument("--count", action="store_true", help="instructions per record under callgrind (v3 only)")
    ap.add_argument("--count-records", type=int, default=1 << 17, help="records counted under callgrind")
    ap.add_argument("--embree", default="cornell,heavy", help="scenes of the packet part ('' to skip)")
    ap.add_argument("--embree-spp", type=int, default=8, help="capture spp of the packet part")
    args = ap.parse_args()

    prep, _ = prepared(args.scene, args.width, args.spp)
    check_one_rect(prep.lights)
    t = time.perf_counter()
    cap = capture(prep, args.spp)
    n = cap["f"].shape[1] // LANES * LANES
    f, i = np.ascontiguousarray(cap["f"][:, :n]), np.ascontiguousarray(cap["i"][:, :n])
    bounces = np.bincount(i[I_BOUNCE])
    print(f"# {args.scene}: {prep.width}x{prep.height} pixels x {args.spp} spp = {cap['paths']} paths -> {n} shading "
          f"records (bounce 1..: {', '.join(str(x) for x in bounces[1:])}), "
          f"captured in {time.perf_counter() - t:.1f} s")
    spec = np.mean(f[F_SR] + f[F_SG] + f[F_SB] > 0) if n else 0
    print(f"# records with a specular colour: {spec * 100:.1f} %; mean roughness {f[F_ROUGHNESS].mean():.2f}")
    if np.any(f[F_CLEARCOAT] != 0.0) or np.any(f[F_OPACITY] < 1.0):
        raise SystemExit("nee_soa is written for opaque surfaces without clearcoat")
    pinhole = int(prep.camera.params.lens_radius <= 0.0)
    flat, lanes, _keep = lane_views(f, i, NO)
    for target in [x for x in args.target.split(",") if x]:
        kernels = nee_kernels(target)
        compile_apart(target, kernels)
        best = time_nee(kernels, flat, lanes, prep, pinhole, args.repeats)
        outs = {}
        for variant in VARIANTS:
            flat.out.fill_(float("nan"))  # nothing carried over from the variant before
            launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)
            outs[variant] = flat.out.numpy().copy()
        lit = np.mean((outs["scalar"][O_CR] + outs["scalar"][O_CG] + outs["scalar"][O_CB]) > 0)
        print(f"\n## target {target}: {TARGET_FLAGS[target]}  ({lit * 100:.1f} % of the records get light)")
        print(f"{'variant':12} {'ns/record':>10} {'speed-up':>9} {'max rel diff':>13} {'bit-equal':>10}  object: "
              f"{'insns':>7} {'ymm':>6} {'zmm':>6} {'xmm':>6} {'ps ymm':>7} {'ps zmm':>7} {'ss':>6} {'gather':>6}")
        for variant in VARIANTS:
            o = outs[variant]
            scale = np.maximum(np.abs(outs["scalar"]), 1e-6)
            rel = float(np.max(np.abs(o - outs["scalar"]) / scale))
            eq = float(np.mean(np.all(o == outs["scalar"], axis=0)))
            obj = module_object(kernels[variant].module.name)
            prof = isa_profile(obj) if obj and obj.exists() else {}
            print(f"{variant:12} {best[variant] / n * 1e9:10.1f} {best['scalar'] / best[variant]:8.2f}x "
                  f"{rel:13.2e} {eq * 100:9.3f}%          {prof.get('total', 0):7d} {prof.get('ymm', 0):6d} "
                  f"{prof.get('zmm', 0):6d} {prof.get('xmm', 0):6d} {prof.get('packed_ps_ymm', 0):7d} "
                  f"{prof.get('packed_ps_zmm', 0):7d} {prof.get('scalar_ss', 0):6d} {prof.get('gather', 0):6d}")
        for variant in VARIANTS:
            obj = module_object(kernels[variant].module.name)
            print(f"#   {variant}: {obj}")
        if args.count and target == "v3":
            m = min(n, args.count_records // LANES * LANES)
            counts = callgrind_counts(args.scene, args.width, args.spp, target, f[:, :m], i[:, :m])
            print(f"callgrind, instructions per record (first {m} records): " + ", ".join(
                f"{v} {c / m:.0f} ({counts['scalar'] / c:.2f}x)" for v, c in counts.items()))
    if args.embree:
        print("\n## Embree packets (one thread, best of %d)" % args.repeats)
        print(f"{'scene':8} {'rays':10} {'count':>8} {'call':18} {'M rays/s':>9} {'same hit':>9}")
        for name in [x for x in args.embree.split(",") if x]:
            eprep, esc = prepared(name, args.width, args.embree_spp)
            ecap = capture(eprep, args.embree_spp)
            order = np.argsort(ecap["ray_bounce"], kind="stable")  # wavefront order: bounce, then path
            r = ecap["rays"][:, order]
            rays = {"bounce": (r[:3].T, r[3:].T, np.full(r.shape[1], 1.0e30, np.float32), False)}
            en = ecap["f"].shape[1] // LANES * LANES
            if True:  # shadow rays: the scalar NEE's samples with a contribution
                sf, si = ecap["f"][:, :en], ecap["i"][:, :en]
                eflat, elanes, _k2 = lane_views(np.ascontiguousarray(sf), np.ascontiguousarray(si), NO)
                kern = nee_kernels("v3")["scalar"]
                compile_apart("v3", {"scalar": kern})
                launch_nee("scalar", kern, eflat, elanes, eprep, eprep.options.seed,
                           int(eprep.camera.params.lens_radius <= 0.0))
                o, d, tm = shadow_rays(sf, eflat.out.numpy())
                b = si[I_BOUNCE][(eflat.out.numpy()[O_CR] + eflat.out.numpy()[O_CG] + eflat.out.numpy()[O_CB]) > 0]
                so = np.argsort(b, kind="stable")
                rays["shadow"] = (o[so], d[so], tm[so], True)
            for row in embree_packets(esc, rays, args.repeats):
                print(f"{name:8} {row[0]:10} {row[1]:8d} {row[2]:18} {row[3]:9.2f} {row[4] * 100:8.2f}%")


if __name__ == "__main__":
    main()
