"""Next-event estimation, generated with or without the compositing layers' code: the area lights a ray reaches on
its way (``add_area_lights``, weighted against light sampling by MIS) and the direct light at a volume vertex
(``volume_direct``)."""
from __future__ import annotations

import warp as wp

from renderer.accel.intersect import BIG, Geometry, safe_inverse
from renderer.accel.wide import entries, leaf_range, wide_stack_t
from renderer.film.film import SampleBuffer
from renderer.lights.sample import area_light_hit, sample_light
from renderer.lights.linking import lit_by, shadow_factor
from renderer.lights.select import infinite_light, select_light, select_pdf
from renderer.lights.table import Lights
from renderer.lpe.kernel import LpeTable, light_symbol, lpe_light, lpe_light_after, volume_symbol
from renderer.media.phase import hg_pdf
from renderer.media.tracking import Media
from renderer.sampling.sobol import DIM_MEDIUM_SHADOW, MEDIUM_SHADOW_DIMS_PER_BOUNCE, MEDIUM_SHADOW_DIMS_PER_PICK
from renderer.lights.multipliers import sampled_weight
from renderer.shading.materials import Materials
from renderer.shading.textures import Textures
from renderer.integrator.vertex import clamp_contribution, media_shadow, power_heuristic


# Rendering needs no gradients: no adjoint code (half the compile time and code size).
wp.set_module_options({"enable_backward": False})


def light_gathering(layers: bool):
    """``add_area_lights`` and ``volume_direct``, with (``layers``) or without (not generated at all) the share of
    what they add that goes to the LPE vars."""

    @wp.func(inline=True)  # no copy of the big structs
    def add_area_light(L: wp.vec3, lights: Lights, li: int, origin: wp.vec3, rd: wp.vec3, t_hit: float, s: float,
                       prev_inst: int, prev_delta: int, prev_pdf: float, prev_p: wp.vec3, lobe_frac: wp.vec3,
                       beta: wp.vec3, hit_clamp: float, lpe: LpeTable, lpe_s: int, buf: SampleBuffer,
                       sample: int):
        """L plus what area light li sends along the scattered ray (origin, rd) before the surface at t_hit, with its
        multiple importance weight against sampling the light."""
        t_l, Le, pdf_l = area_light_hit(lights, li, origin, rd, t_hit, s)
        if t_l < BIG and lit_by(lights.links, li, prev_inst):
            w = float(1.0)
            if prev_delta == 0:
                w = power_heuristic(prev_pdf, select_pdf(lights.select, li, prev_p) * pdf_l)
            if lights.lobe_mults != 0:
                Le = wp.cw_mul(Le, sampled_weight(lights, li, lobe_frac))
            c = clamp_contribution(wp.cw_mul(beta, Le) * w, hit_clamp)
            if wp.static(layers):
                if lpe.count > 0:
                    lpe_light(lpe, lpe_s, buf.extra, sample, light_symbol(lpe, li), c)
            return L + c
        return L

    @wp.func(inline=True)  # one call site: no copy of the big structs
    def add_area_lights(L: wp.vec3, lights: Lights, origin: wp.vec3, rd: wp.vec3, t_hit: float, s: float,
                        prev_inst: int, prev_delta: int, prev_pdf: float, prev_p: wp.vec3, lobe_frac: wp.vec3,
                        beta: wp.vec3, hit_clamp: float, lpe: LpeTable, lpe_s: int, buf: SampleBuffer,
                        sample: int):
        """L plus every area light the scattered ray reaches before t_hit (``lights.reach``): the still ones of a tree
        found by walking it, then the others (all of them without a tree) in light order. One loop, so that the light
        test is inlined once: a second copy cost a Cornell box 1.5-2.5 %."""
        inv_d = wp.vec3(0.0)
        if lights.reach.tree != 0:  # three divisions a bounce of a scene with a few lights need not pay
            inv_d = safe_inverse(rd)
        stack = wide_stack_t()  # scratch: not zeroed, read below sp only
        stack[0] = 0  # the root
        sp = lights.reach.tree
        leaf_at = int(0)  # the slots of the leaf being read, leaf_at .. leaf_end - 1
        leaf_end = int(0)
        k = int(0)
        while leaf_at < leaf_end or sp > 0 or k < lights.reach.n_loose:
            li = int(-1)
            if leaf_at < leaf_end:
                li = lights.reach.light[leaf_at]
                leaf_at += 1
            elif sp > 0:
                sp -= 1
                ref = stack[sp]
                if ref < 0:
                    first, count = leaf_range(ref)
                    leaf_at = first
                    leaf_end = first + count
                else:
                    c = lights.reach.child[ref]
                    d = entries(lights.reach.box, ref, c, 0, 0, 0.0, origin, inv_d, t_hit)
                    for j in range(4):
                        if d[j] < BIG:
                            stack[sp] = c[j]
                            sp += 1
            else:
                li = lights.reach.loose[k]
                k += 1
            if li >= 0:
                L = add_area_light(L, lights, li, origin, rd, t_hit, s, prev_inst, prev_delta, prev_pdf, prev_p,
                                   lobe_frac, beta, hit_clamp, lpe, lpe_s, buf, sample)
        return L

    @wp.func(inline=True)  # one call site: no copy of the big structs
    def volume_direct(L: wp.vec3, geo: Geometry, mats: Materials, tex: Textures, lights: Lights, media: Media,
                      p: wp.vec3, rd: wp.vec3, g: float, s: float, in_sa: wp.vec3, in_ss: wp.vec3, beta: wp.vec3,
                      u_light: wp.vec3, nee_clamp: float, seed: wp.uint32, pixel: wp.uint32, index: wp.uint32,
                      bounce: int, lpe: LpeTable, lpe_s: int, buf: SampleBuffer, sample: int):
        """L plus the light sampled at a scattering point p of a medium (each infinite light and one finite light,
        as at a surface), weighted against phase sampling by the power heuristic; and the shadow rays traced. The
        phase function takes the place of BSDF x cosine; ``rd`` (the direction of travel) is the axis constant domes
        are sampled about."""
        n_infinite = lights.select.count - lights.select.n_finite
        n_picks = n_infinite + wp.min(lights.select.n_finite, 1)
        rays = int(0)
        for pick in range(n_picks):
            li = int(-1)
            p_sel = float(1.0)
            u_tri = u_light[2]
            if pick < n_infinite:
                li = infinite_light(lights.select, pick)
            else:
                li, p_sel, u_tri = select_light(lights.select, p, u_light[2])
            wi = wp.vec3(0.0)
            dist = float(0.0)
            Le_l = wp.vec3(0.0)
            pdf_l = float(0.0)
            delta = False
            if li >= 0:
                wi, dist, Le_l, pdf_l, delta = sample_light(lights, geo, mats, tex, li, p, rd, s, u_tri,
                                                            wp.vec2(u_light[0], u_light[1]))
            if pdf_l > 0.0 and (Le_l[0] > 0.0 or Le_l[1] > 0.0 or Le_l[2] > 0.0) and lit_by(lights.links, li, -1):
                ph = hg_pdf(g, wp.dot(rd, wi))
                rays += 1
                tmax = dist * (1.0 - 1.0e-4)
                tr = shadow_factor(geo, mats, tex, lights.links, li, p, wi, tmax, s)
                if tr[0] > 0.0 or tr[1] > 0.0 or tr[2] > 0.0:
                    dim = wp.uint32(DIM_MEDIUM_SHADOW + bounce * MEDIUM_SHADOW_DIMS_PER_BOUNCE
                                    + pick * MEDIUM_SHADOW_DIMS_PER_PICK)
                    tr = wp.cw_mul(tr, media_shadow(geo, mats, media, p, wi, tmax, s, in_sa, in_ss, seed, pixel,
                                                    index, dim))
                    w = float(1.0)
                    if not delta:
                        w = power_heuristic(p_sel * pdf_l, ph)
                    if lights.lobe_mults != 0:  # a medium responds as a diffuse surface does
                        Le_l = wp.cw_mul(Le_l, sampled_weight(lights, li, wp.vec3(1.0)))
                    c = clamp_contribution(wp.cw_mul(wp.cw_mul(beta, Le_l), tr) * (ph * w / (p_sel * pdf_l)),
                                           nee_clamp)
                    if wp.static(layers):
                        if lpe.count > 0:
                            lpe_light_after(lpe, lpe_s, buf.extra, sample, volume_symbol(lpe),
                                            light_symbol(lpe, li), c)
                    L += c
        return L, rays

    return add_area_lights, volume_direct


