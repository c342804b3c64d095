"""Next-event estimation over LANES records per thread in the renderer's vec3 code: each field of a batch a
``vector(LANES, float)`` loaded into locals, one loop over the batch. The sampler's and the rectangle's 4-lane
natives are replaced by their scalar twins, the light choice by its one-light arithmetic (``one_rect``, whose
assumptions ``check_one_rect`` verifies on the host)."""
from __future__ import annotations

import warp as wp

from renderer.integrator import offset_origin, power_heuristic
from renderer.lights.shapes import (
    XU_RADICAND_MIN,
    LightSampleGeom,
    _area_sample_geom,
    _rect_local,
    _safe_acos,
    _use_sph_rect,
)
from renderer.lights.table import Lights
from renderer.sampling.sobol import (
    BOUNCE_LIGHT_CHOICE,
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
    sobol_dims12,
)
from renderer.sampling.warps import TWO_PI, sin_cos
from renderer.shading.bsdf import SurfaceParams, bsdf_setup, lobes_eval, lobes_pdf

from .nee_scalar import record_params
from .records import (
    F_CC_ROUGH, F_CLEARCOAT, F_DB, F_DG, F_DR, F_IOR, F_METALLIC, F_NGX, F_NGY, F_NGZ, F_NSX, F_NSY, F_NSZ, F_OPACITY,
    F_PX, F_PY, F_PZ, F_ROUGHNESS, F_SB, F_SG, F_SR, F_WOX, F_WOY, F_WOZ, I_BOUNCE, I_FRONT, I_INDEX, I_PIXEL, I_THIN,
    I_USE_SPEC, LANES, O_CB, O_CG, O_CR, O_DIST, O_WIX, O_WIY, O_WIZ, LaneRecords, vecL,
)

wp.set_module_options({"enable_backward": False})


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
def _sph_rect_angles_reference(x0: float, y0: float, z0: float, x1: float, y1: float):
    """``shapes._sph_rect_angles`` in Warp's scalar code (its vector lanes equal it bit for bit, by the renderer's
    tests)."""
    r0 = wp.sqrt(z0 * z0 + y0 * y0)
    r1 = wp.sqrt(z0 * z0 + x1 * x1)
    r2 = wp.sqrt(z0 * z0 + y1 * y1)
    r3 = wp.sqrt(z0 * z0 + x0 * x0)
    g01 = _safe_acos(y0 * x1 / (r0 * r1)) + _safe_acos(-x1 * y1 / (r1 * r2))
    g23 = _safe_acos(x0 * y1 / (r2 * r3)) + _safe_acos(-x0 * y0 / (r3 * r0))
    solid_angle = g01 + g23 - TWO_PI
    if z0 == 0.0:
        solid_angle = 0.0
    return g01, g23, -y0 / r0, y1 / r2, solid_angle


@wp.func
def sample_rect_lane(p_ref: wp.vec3, corner: wp.vec3, edge_u: wp.vec3, edge_v: wp.vec3, u: wp.vec2) -> LightSampleGeom:
    """``shapes.sample_rect`` with the scalar twin of its 4-lane angles."""
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
