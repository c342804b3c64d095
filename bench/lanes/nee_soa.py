"""Next-event estimation in scalar floats only, the loop vectorizer's terms (``nee_soa``), over batches of LANES
records in local vectors (``nee_soa_kernel``) or read from plain float arrays (``nee_soa_flat_kernel``).

Every ``@wp.func`` of ``nee_lanes`` that takes or returns a ``wp.vec3`` is a C++ function whose vec3 travels, by the
x86-64 calling convention, as {<2 x float>, float}; inlined, those <2 x float> values stay in the loop body, and
LLVM's loop vectorizer refuses any loop holding a vector-typed instruction ("instruction return type cannot be
vectorized", its remark; ``-opt-record-file``). So the vectorized stage is written anew here in plain floats (tuples
of floats are returned through references, which inlining removes), lobe by lobe as ``bsdf``, ``lobes``,
``microfacet``, ``warps`` and ``shapes`` compute them, for the records of the bench scenes: diffuse and GGX specular
lobes, no clearcoat, opaque (checked on the host).
"""
from __future__ import annotations

import warp as wp

from renderer.lights.shapes import XU_RADICAND_MIN, _use_sph_rect
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
    mix32,
    owen_scramble,
    pattern_hash,
    reverse_bits32,
    sobol_dims12,
    u32_to_unit_float,
)
from renderer.sampling.warps import INV_PI, TWO_PI, sin_cos

from .nee_lanes import OneRect, _sph_rect_angles_reference, one_rect
from .records import (
    F_DB, F_DG, F_DR, F_IOR, F_METALLIC, F_NGX, F_NGY, F_NGZ, F_NSX, F_NSY, F_NSZ, F_OPACITY, F_PX, F_PY, F_PZ,
    F_ROUGHNESS, F_SB, F_SG, F_SR, F_WOX, F_WOY, F_WOZ, I_BOUNCE, I_INDEX, I_PIXEL, I_USE_SPEC, LANES, O_CB, O_CG, O_CR,
    O_DIST, O_WIX, O_WIY, O_WIZ, FlatRecords, LaneRecords, vecL,
)

wp.set_module_options({"enable_backward": False})


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
