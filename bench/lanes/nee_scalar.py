"""Next-event estimation one record per thread: the integrator's own ``@wp.func`` code (the sampler's light
dimensions, ``select_light``, ``sample_light``, the BSDF's lobes, the power heuristic), records read from plain float
arrays. The reference every other variant is compared with."""
from __future__ import annotations

import warp as wp

from renderer.accel.intersect import Geometry
from renderer.integrator import offset_origin, power_heuristic
from renderer.lights.sample import sample_light
from renderer.lights.select import select_light
from renderer.lights.table import Lights
from renderer.sampling.sobol import (
    BOUNCE_LIGHT_CHOICE,
    CAMERA_LIGHT_0,
    DIM_FILM,
    DIM_LIGHT_BASE,
    DIMS_PER_BOUNCE,
    sample_3d,
    sample_camera_pair,
)
from renderer.shading.bsdf import SurfaceParams, bsdf_setup, lobes_eval, lobes_pdf
from renderer.shading.materials import Materials
from renderer.shading.textures import Textures

from .records import (
    F_CC_ROUGH, F_CLEARCOAT, F_DB, F_DG, F_DR, F_IOR, F_METALLIC, F_NGX, F_NGY, F_NGZ, F_NSX, F_NSY, F_NSZ, F_OPACITY,
    F_PX, F_PY, F_PZ, F_ROUGHNESS, F_SB, F_SG, F_SR, F_WOX, F_WOY, F_WOZ, I_BOUNCE, I_FRONT, I_INDEX, I_PIXEL, I_THIN,
    I_USE_SPEC, O_CB, O_CG, O_CR, O_DIST, O_WIX, O_WIY, O_WIZ, FlatRecords,
)

wp.set_module_options({"enable_backward": False})


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
