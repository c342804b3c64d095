"""The integrator: one distributed-ray-tracing sample per thread, a path of up to ``max_depth`` bounces.

A sample is a point in every dimension at once (the paper's central idea): its film position (antialiasing),
its time (motion blur: camera, geometry, lights and shadows are all evaluated at that one instant), its lens
position (depth of field), and at every bounce a light position (penumbrae) and a BSDF direction (gloss,
translucency). All come from ``sampling.sobol`` as pure functions of (seed, pixel, sample index, dimension), so the
sample can be replayed exactly.

At every surface, light is gathered twice and the two estimates combined by the power heuristic (Veach's
multiple importance sampling): a light chosen by power and a point on it (a shadow ray), and the direction
the BSDF samples, which may hit an emitter by itself. Paths end by Russian roulette after a few bounces.
UsdLux area lights are not in the scene's hierarchy: scattered rays test them on their way (``lights.reach``) and
go on; a camera ray (and its straight passes through sheets) sees only those the scene has the camera see, and
ends at the first of them with the radiance a scattered ray would find there.
Inside a closed solid entered through its surface, light is absorbed along the distance travelled
(Beer-Lambert). Participating media (``renderer.media``: grid volumes, and solids whose material holds a scattering
medium) are walked by delta tracking along every ray before its surface: a real collision makes a volume vertex
lit like a surface vertex by light sampling and phase sampling combined with MIS; shadow rays
take the media's transmittance (ratio tracking). Samples with NaN/Inf radiance are counted and zeroed; ``clamp``
(off by default) limits a sample's radiance to cut fireflies, never silently. When a render asks for them (and
then in a kernel variant of its own, ``renderer.integrator.layers``), each contribution is also handed to the LPE
vars whose automata accept its path (``renderer.lpe.kernel``), and the first surface a sample sees is recorded
for Cryptomatte and the vars of what it hit. Next-event estimation is ``integrator.direct``'s; the smaller terms
of a vertex (MIS weights, regularization, roulette, media at boundaries, the shutter time) ``integrator.vertex``'s.

Path regularization (the production default, off with ``unbiased``; see README "Noise defaults"):
- *indirect clamp*: each contribution that reached the camera after more than one surface bounce is scaled
  down so that its largest channel is at most ``indirect_clamp`` (hue kept), as Cycles' indirect clamp;
- *glossy filter*: after a rough bounce, later lobes are roughened to at least ``glossy_filter`` times the
  roughness the path has had so far (estimated from the pdf of each sampled direction), as Cycles' "filter
  glossy": caustic-like paths (diffuse -> sharp gloss -> small light) become low-variance blurred ones.
"""
from __future__ import annotations

import warp as wp

from renderer.accel.csg import csg_closest
from renderer.accel.intersect import BIG, Geometry, intersect_closest
from renderer.accel.occlusion import transmittance
from renderer.accel.surface import display_diffuse, hit_geometry, shading_normal, surface_at
from renderer.camera.lens import CameraParams, camera_ray
from renderer.film.film import SampleBuffer
from renderer.lights.sample import (
    emission_mis_light,
    first_seen_light,
    infinite_light_eval,
    mesh_light_pdf,
    sample_light,
)
from renderer.lights.linking import lit_by, shadow_factor
from renderer.lights.select import infinite_light, select_light, select_pdf
from renderer.lights.table import Lights
from renderer.lpe.kernel import (
    LpeTable,
    clamp_factor,
    emission_symbol,
    light_symbol,
    lpe_begin,
    lpe_event,
    lpe_finish,
    lpe_light,
    lpe_light_after,
    sampled_scatter,
    surface_symbol,
    volume_symbol,
    SCATTER_D,
    SCATTER_G,
)
from renderer.media.phase import hg_sample
from renderer.media.tracking import MEDIUM_ABSORB, MEDIUM_NONE, Media, sample_media
from renderer.sampling.sobol import (
    BOUNCE_LIGHT_CHOICE,
    BOUNCE_LOBE,
    BOUNCE_ROULETTE,
    CAMERA_BSDF_1,
    CAMERA_LENS,
    CAMERA_LIGHT_0,
    DIM_FILM,
    DIM_LIGHT_BASE,
    DIM_MEDIUM,
    DIM_MEDIUM_SHADOW,
    DIMS_PER_BOUNCE,
    MEDIUM_DIMS_PER_BOUNCE,
    MEDIUM_SHADOW_DIMS_PER_BOUNCE,
    MEDIUM_SHADOW_DIMS_PER_PICK,
    sample_1d,
    sample_3d,
    sample_camera_pair,
)
from renderer.scene.model import LIGHT_DOME
from renderer.lights.multipliers import diffuse_fraction, nee_bsdf, sampled_weight
from renderer.shading.bsdf import (
    bsdf_albedo_hint,
    bsdf_setup,
    lobes_eval,
    lobes_eval_diffuse,
    lobes_eval_split,
    lobes_pdf,
    lobes_sample,
)
from renderer.shading.materials import HitGeometry, Materials, beer_lambert, eval_material_cone
from renderer.shading.raycone import bounce_spread, camera_cone, uv_footprint
from renderer.shading.textures import Textures
from renderer.kernels.struct_refs import by_reference
from renderer.integrator.direct import light_gathering
from renderer.integrator.vertex import (FLAG_DELTA, FLAG_TRANSMISSION, RR_START, clamp_contribution, finite3,
                                        media_shadow, medium_boundary, offset_origin, power_heuristic,
                                        regularized_params, roughness_of_pdf, roulette, shadow_start_medium,
                                        shutter_time)

# Rendering needs no gradients: no adjoint code (half the compile time and code size).
wp.set_module_options({"enable_backward": False})


@wp.struct
class PathSettings:
    max_depth: int  # bounces after the camera ray (0: emission and direct light only... see README)
    clamp: float  # maximum sample radiance per channel, 0 = off
    indirect_clamp: float  # maximum contribution after more than one bounce (largest channel), 0 = off
    glossy_filter: float  # k: later lobes at least k x the path's roughness so far, 0 = off
    time_filter: int
    frame_s: float  # the frame time in normalised shutter time (strobe)
    seed: wp.uint32
    record_hits: int  # each sample's first surface (``SampleBuffer.hit_*``): 1 instance and triangle (Cryptomatte,
    # ids), 2 also its barycentrics and point (P and primvar vars); 0 none


@by_reference
@wp.struct
class Wave:
    """The samples one launch draws: ``count`` consecutive sample indices from ``start`` for each active pixel of
    a tile's region. (A struct rather than separate arguments: a kernel with array arguments of its own gets a
    Warp CPU variant that copies all its arguments, the scene structs included, once per thread.)"""

    active: wp.array(dtype=wp.int32)  # region pixels still sampling (adaptive sampling); slot = position here
    region_x0: int
    region_y0: int
    region_w: int
    start: int  # sample index of this wave's first sample
    count: int  # samples per pixel in this wave
    counters: wp.array(dtype=wp.int64)  # [rays traced, non-finite samples zeroed]


def trace_wave_kernel_variant(name: str, layers: bool, module: str | None = None):
    """The path tracing kernel ``name`` of Warp module ``module`` (None: this one), with (``layers``) or without
    the LPE vars and first-hit records.

    Without, Warp generates none of their code (``wp.static``, and flags that are constants): a render that asks
    for neither runs the kernel it ran before they existed. (Their branches, never taken, cost it 3-5 % of its
    time even where the compiler could fold them away, and a variant with them in the same Warp module 2-4 %.)"""
    add_area_lights, volume_direct = light_gathering(layers)

    @wp.kernel(name=name, module=module)
    def kernel(
        geo: Geometry,
        mats: Materials,
        tex: Textures,
        lights: Lights,
        media: Media,
        cam: CameraParams,
        buf: SampleBuffer,
        settings: PathSettings,
        wave: Wave,
        lpe: LpeTable,
    ):
        tid = wp.tid()
        j = tid % wave.count
        pr = wave.active[tid // wave.count]
        px = wave.region_x0 + pr % wave.region_w
        py = wave.region_y0 + pr // wave.region_w
        pixel = wp.uint32(py * cam.width + px)
        index = wp.uint32(wave.start + j)
        seed = settings.seed

        # the film position and the time from one 3D sample: what a pixel sees of a moving object is one integral
        # over (x, y, t), which jointly stratified points resolve faster (64-spp relMSE: demo -13 %, motion -4 %)
        film_t = sample_3d(seed, pixel, index, wp.uint32(DIM_FILM))
        film_u = wp.vec2(film_t[0], film_t[1])
        s = shutter_time(settings.time_filter, film_t[2], settings.frame_s)
        lens_u = sample_camera_pair(seed, pixel, index, wp.uint32(DIM_FILM), CAMERA_LENS)
        pinhole = cam.lens_radius <= 0.0  # its lens dims are free for the first bounce's direction
        ro, rd, tmin, tmax, fwd = camera_ray(cam, wp.vec2(float(px) + film_u[0], float(py) + film_u[1]), lens_u, s)
        cam_origin = ro
        # ray cone (texture filtering, raycone): width at the current origin (scene units), spread (radians)
        cone_w, cone_spread = camera_cone(cam.film_size[1], cam.focal_length, cam.height, cam.orthographic)

        L = wp.vec3(0.0)
        beta = wp.vec3(1.0)  # path throughput
        alpha = float(0.0)
        depth_aov = float(0.0)
        normal_aov = wp.vec3(0.0)
        albedo_aov = wp.vec3(0.0)
        rays = int(0)
        origin = ro + rd * tmin
        t_far = tmax - tmin
        prev_delta = int(1)  # the camera ray: what it sees directly gets no MIS weight
        prev_pdf = float(0.0)
        prev_n = wp.vec3(0.0)
        prev_inst = int(-1)  # instance the path last left (light linking of what it finds)
        prev_p = wp.vec3(0.0)  # where the path last chose a light (the selection pdf of what it finds)
        sigma = wp.vec3(0.0)  # absorption coefficient of the solid the path is inside (1/scene unit)
        in_ss = wp.vec3(0.0)  # scattering coefficient of the solid's medium, if it holds one (1/scene unit)
        in_g = float(0.0)  # and the anisotropy of its phase function
        see_through = int(1)  # so far only straight pass-through events: domes hidden from the camera stay hidden
        bounce = int(0)
        alive = int(1)
        path_roughness = float(0.0)  # the roughest direction sampled so far (glossy filter)
        lobe_frac = wp.vec3(0.0)  # diffuse share of the last sampled direction (per-light diffuse/specular multipliers)
        lpe_s = int(0)  # the state of the LPE vars' automaton (``renderer.lpe.kernel``)
        # constants in the plain variant, so Warp generates none of what they guard
        lpe_on = False
        record = False  # each sample's first hit (PathSettings.record_hits)
        record_uv = False  # and its barycentrics and point
        if wp.static(layers):
            lpe_on = lpe.count > 0
            record = settings.record_hits != 0
            record_uv = settings.record_hits > 1
        if lpe_on:
            lpe_s = lpe_begin(lpe, buf.extra, tid)
        if record:
            buf.hit_inst[tid] = -1  # until a surface is seen
        while alive != 0:
            rays += 1
            # light reached along this ray has been scattered `bounce` times; direct light is 0 or 1 bounce
            hit_clamp = float(0.0)
            if bounce >= 2:
                hit_clamp = settings.indirect_clamp
            nee_clamp = float(0.0)
            if bounce >= 1:
                nee_clamp = settings.indirect_clamp
            hit = intersect_closest(geo, origin, rd, t_far, s)
            if geo.csg_groups > 0:
                hit = csg_closest(geo, origin, rd, s, hit)
            # a camera ray (and its straight passes through sheets) ends at the first area light the camera sees
            seen_li = int(-1)
            t_ray = hit.t
            Le_seen = wp.vec3(0.0)
            if see_through != 0 and lights.reach.n_seen > 0:
                seen_li, t_ray, Le_seen = first_seen_light(lights, origin, rd, hit.t, s, prev_inst)
            # participating media before the surface: emission gathered, and a real collision ends the ray there
            event = int(MEDIUM_NONE)
            t_seg = t_ray
            in_medium = in_ss[0] > 0.0 or in_ss[1] > 0.0 or in_ss[2] > 0.0
            g_event = float(0.0)
            if media.count > 0 or in_medium:
                walk = sample_media(media, origin, rd, t_ray, s, sigma, in_ss, in_g, seed, pixel, index,
                                    wp.uint32(DIM_MEDIUM + bounce * MEDIUM_DIMS_PER_BOUNCE))
                c_walk = clamp_contribution(wp.cw_mul(beta, walk.emitted), hit_clamp)
                if lpe_on:
                    lpe_light(lpe, lpe_s, buf.extra, tid, emission_symbol(lpe), c_walk)
                L += c_walk
                beta = wp.cw_mul(beta, walk.weight)
                event = walk.event
                t_seg = walk.t_end
                g_event = walk.g
            # UsdLux area lights are not in the scene's hierarchy: rays scattered by a surface or a medium may reach
            # them directly (the camera's, above, only those it sees)
            if see_through == 0:
                L = add_area_lights(L, lights, origin, rd, t_seg, s, prev_inst, prev_delta, prev_pdf, prev_p, lobe_frac,
                                    beta, hit_clamp, lpe, lpe_s, buf, tid)
            if event != MEDIUM_NONE:  # a volume vertex: absorbed, or scattered by the phase function
                p = origin + rd * t_seg
                cone_w = cone_w + cone_spread * t_seg
                if bounce == 0:
                    depth_aov = wp.dot(p - cam_origin, fwd)
                    alpha = 1.0  # the medium covers the pixel as far as it stops camera rays
                if event == MEDIUM_ABSORB or bounce >= settings.max_depth:
                    alive = 0
                else:
                    dim = wp.uint32(DIM_LIGHT_BASE + bounce * DIMS_PER_BOUNCE)
                    u_light = sample_3d(seed, pixel, index, dim + wp.uint32(BOUNCE_LIGHT_CHOICE))
                    L, nee_rays = volume_direct(L, geo, mats, tex, lights, media, p, rd, g_event, s, sigma, in_ss, beta,
                                                u_light, nee_clamp, seed, pixel, index, bounce, lpe, lpe_s,
                                                buf, tid)
                    rays += nee_rays
                    u_phase = sample_3d(seed, pixel, index, dim + wp.uint32(BOUNCE_LOBE))
                    wi, pdf = hg_sample(g_event, rd, wp.vec2(u_phase[0], u_phase[1]))
                    # the phase function is sampled exactly: the throughput keeps its value
                    lobe_frac = wp.vec3(1.0)
                    path_roughness = wp.max(path_roughness, roughness_of_pdf(pdf))
                    cone_spread = bounce_spread(cone_spread, 1.0, 0)
                    prev_delta = 0
                    prev_pdf = pdf
                    prev_n = rd
                    prev_inst = -1
                    prev_p = p
                    see_through = 0
                    if lpe_on:
                        lpe_s = lpe_event(lpe, lpe_s, volume_symbol(lpe))
                    origin = p
                    rd = wi
                    t_far = float(BIG)
                    bounce += 1
                    if bounce >= RR_START:
                        alive, beta = roulette(beta, sample_1d(seed, pixel, index, dim + wp.uint32(BOUNCE_ROULETTE)))
            elif seen_li >= 0:  # the light's emission towards the camera, as a scattered ray would find it
                c_seen = clamp_contribution(wp.cw_mul(beta, Le_seen), hit_clamp)
                if lpe_on:
                    lpe_light(lpe, lpe_s, buf.extra, tid, light_symbol(lpe, seen_li), c_seen)
                L += c_seen
                if bounce == 0:
                    alpha = 1.0
                    depth_aov = wp.dot(origin + rd * t_ray - cam_origin, fwd)
                alive = 0
            elif hit.inst < 0:
                for k in range(lights.reach.n_infinite):  # the distant and dome lights, in light order
                    li = lights.reach.infinite[k]
                    kind = lights.kind[li]
                    # domes hidden from the camera stay hidden behind pass-through surfaces too
                    if lit_by(lights.links, li, prev_inst) and not (
                            see_through != 0 and kind == LIGHT_DOME and lights.dome_visible == 0):
                        Le, pdf_l = infinite_light_eval(lights, li, rd, prev_n, s)
                        w = float(1.0)
                        if prev_delta == 0:
                            w = power_heuristic(prev_pdf, select_pdf(lights.select, li, prev_p) * pdf_l)
                        if lights.lobe_mults != 0 and bounce > 0:
                            Le = wp.cw_mul(Le, sampled_weight(lights, li, lobe_frac))
                        c_inf = clamp_contribution(wp.cw_mul(beta, Le) * w, hit_clamp)
                        if lpe_on:
                            lpe_light(lpe, lpe_s, buf.extra, tid, light_symbol(lpe, li), c_inf)
                        L += c_inf
                if bounce == 0 and lights.dome_visible != 0:
                    alpha = 1.0
                alive = 0
            else:
                # Beer-Lambert: absorbed along the way through a solid
                if (sigma[0] > 0.0 or sigma[1] > 0.0 or sigma[2] > 0.0) and not in_medium:  # (a medium's: tracked)
                    beta = wp.cw_mul(beta, beer_lambert(sigma, hit.t))
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
                thin = 1 - geo.tri_solid[hit.tri]  # open surfaces are thin sheets, closed ones bound solids
                params = regularized_params(ms, thin, settings.glossy_filter, path_roughness)
                wo = -rd
                lobes = bsdf_setup(params, ns, sp.ng, wo, sp.front)  # once per hit: eval, pdf and sample share it
                if bounce == 0:
                    if record:
                        buf.hit_inst[tid] = hit.inst
                        buf.hit_tri[tid] = hit.tri
                        if record_uv:
                            buf.hit_uv[tid] = wp.vec2(hit.b1, hit.b2)
                            buf.hit_p[tid] = sp.p
                    depth_aov = wp.dot(sp.p - cam_origin, fwd)
                    normal_aov = ns
                    albedo_aov = bsdf_albedo_hint(params)
                    # alpha is coverage: opaque surfaces and solids cover the pixel; partly opaque sheets cover
                    # it as much as light does not get through them along the camera ray (whatever the BSDF samples),
                    # all of it in front of a seen dome or of a light the camera sees (an opaque emitter to it)
                    alpha = 1.0
                    if lights.dome_visible == 0 and thin != 0 and ms.opacity < 1.0:
                        seen_behind = int(-1)
                        if lights.reach.n_seen > 0:
                            seen_behind, t_behind, Le_behind = first_seen_light(lights, origin, rd, t_far, s, -1)
                        if seen_behind < 0:
                            rays += 1
                            alpha = 1.0 - transmittance(geo, mats, tex, origin, rd, t_far, s)
                # emission seen along the path
                Le = ms.emissive_color
                if Le[0] > 0.0 or Le[1] > 0.0 or Le[2] > 0.0:
                    w = float(1.0)
                    li = emission_mis_light(lights, hit.inst)
                    if prev_delta == 0 and li >= 0:
                        pdf_l = select_pdf(lights.select, li, prev_p) * mesh_light_pdf(
                            lights, geo, li, hit.inst, hit.tri, origin, sp.p, s)
                        w = power_heuristic(prev_pdf, pdf_l)
                    if lights.lobe_mults != 0 and bounce > 0 and li >= 0:
                        Le = wp.cw_mul(Le, sampled_weight(lights, li, lobe_frac))
                    # emission covers what the surface covers
                    c_em = clamp_contribution(wp.cw_mul(beta, Le) * (w * ms.opacity), hit_clamp)
                    if lpe_on:
                        sym = emission_symbol(lpe)
                        if li >= 0:  # emission sampled as a light: its event and group
                            sym = light_symbol(lpe, li)
                        lpe_light(lpe, lpe_s, buf.extra, tid, sym, c_em)
                    L += c_em
                if bounce >= settings.max_depth:
                    alive = 0
                else:
                    dim = wp.uint32(DIM_LIGHT_BASE + bounce * DIMS_PER_BOUNCE)
                    # --- next-event estimation: each infinite light, and one finite light chosen by the light cut;
                    # a point on each and one shadow ray each
                    n_infinite = lights.select.count - lights.select.n_finite
                    n_picks = n_infinite + wp.min(lights.select.n_finite, 1)
                    # the light and the point on it from one 3D sample, so that each light's share of the pixel's
                    # samples still spreads its points well (as Cycles' 3D light pattern)
                    u_light = sample_3d(seed, pixel, index, dim + wp.uint32(BOUNCE_LIGHT_CHOICE))
                    # the first bounce's point on a light with the camera's sample (sampling.sobol); with a pinhole the
                    # second's too, which pays along with the first bounce's direction
                    if bounce == 0 or (bounce == 1 and pinhole):
                        on_light = sample_camera_pair(seed, pixel, index, wp.uint32(DIM_FILM), CAMERA_LIGHT_0 + bounce)
                        u_light = wp.vec3(on_light[0], on_light[1], u_light[2])
                    origin_l = offset_origin(sp.p, sp.ng)
                    for pick in range(n_picks):
                        li = int(-1)
                        p_sel = float(1.0)
                        u_tri = u_light[2]
                        if pick < n_infinite:
                            li = infinite_light(lights.select, pick)
                        else:
                            li, p_sel, u_tri = select_light(lights.select, sp.p, u_light[2])
                        wi = wp.vec3(0.0)
                        dist = float(0.0)
                        Le_l = wp.vec3(0.0)
                        pdf_l = float(0.0)
                        delta = False
                        if li >= 0:
                            wi, dist, Le_l, pdf_l, delta = sample_light(
                                lights, geo, mats, tex, li, origin_l, ns, s, u_tri, wp.vec2(u_light[0], u_light[1]))
                        if pdf_l > 0.0 and (Le_l[0] > 0.0 or Le_l[1] > 0.0 or Le_l[2] > 0.0) and lit_by(
                                lights.links, li, hit.inst):
                            f = lobes_eval(lobes, wi)
                            if lights.lobe_mults != 0:
                                f = nee_bsdf(lights, li, lobes, wi, f)
                            if f[0] > 0.0 or f[1] > 0.0 or f[2] > 0.0:
                                # shadow rays start on the side of the surface the light is on
                                o_sh = origin_l
                                if wp.dot(wi, sp.ng) < 0.0:
                                    o_sh = offset_origin(sp.p, -sp.ng)
                                rays += 1
                                # light/shadow linking and shadow controls (lights.linking)
                                tr = shadow_factor(geo, mats, tex, lights.links, li, o_sh, wi, dist * (1.0 - 1.0e-4),
                                                   s)
                                if (media.count > 0 or media.mesh_media != 0) and (tr[0] > 0.0 or tr[1] > 0.0 or
                                                                                   tr[2] > 0.0):
                                    sh_sa, sh_ss = shadow_start_medium(media, mats, sp.material, sp.front,
                                                                       wp.dot(wi, sp.ng) < 0.0, sigma, in_ss)
                                    tr = wp.cw_mul(tr, media_shadow(
                                        geo, mats, media, o_sh, wi, dist * (1.0 - 1.0e-4), s, sh_sa, sh_ss, seed, pixel,
                                        index, wp.uint32(DIM_MEDIUM_SHADOW + bounce * MEDIUM_SHADOW_DIMS_PER_BOUNCE
                                                         + pick * MEDIUM_SHADOW_DIMS_PER_PICK)))
                                if tr[0] > 0.0 or tr[1] > 0.0 or tr[2] > 0.0:
                                    w = float(1.0)
                                    if not delta:
                                        w = power_heuristic(p_sel * pdf_l, lobes_pdf(lobes, wi))
                                    cos_i = wp.abs(wp.dot(ns, wi))
                                    raw = wp.cw_mul(wp.cw_mul(wp.cw_mul(beta, f), Le_l), tr) * (
                                        cos_i * w / (p_sel * pdf_l))
                                    L += clamp_contribution(raw, nee_clamp)
                                    if lpe_on:
                                        # the diffuse and glossy lobes' shares, scaled as the sum was
                                        scale = clamp_factor(raw, nee_clamp) * (cos_i * w / (p_sel * pdf_l))
                                        fd = lobes_eval_diffuse(lobes, wi)  # f's first term: one lobe more
                                        fs = f - fd
                                        if lights.lobe_mults != 0:  # f is the lobes times their multipliers
                                            fd, fs = lobes_eval_split(lobes, wi)
                                            mult = lights.lobe_mult[li]
                                            fd = fd * mult[0]
                                            fs = fs * mult[1]
                                        through = wp.dot(wi, sp.ng) * wp.dot(wo, sp.ng) < 0.0
                                        light_sym = light_symbol(lpe, li)
                                        lit = wp.cw_mul(wp.cw_mul(beta, Le_l), tr) * scale
                                        if fd[0] > 0.0 or fd[1] > 0.0 or fd[2] > 0.0:
                                            lpe_light_after(lpe, lpe_s, buf.extra, tid,
                                                            surface_symbol(lpe, through, SCATTER_D), light_sym,
                                                            wp.cw_mul(lit, fd))
                                        if fs[0] > 0.0 or fs[1] > 0.0 or fs[2] > 0.0:
                                            lpe_light_after(lpe, lpe_s, buf.extra, tid,
                                                            surface_symbol(lpe, through, SCATTER_G), light_sym,
                                                            wp.cw_mul(lit, fs))
                    # --- the BSDF's own direction continues the path
                    # the lobe and the direction from one 3D sample, so that each lobe's share keeps spread directions
                    u_bsdf = sample_3d(seed, pixel, index, dim + wp.uint32(BOUNCE_LOBE))
                    # with a pinhole, the lens dims of the camera's sample give the first bounce's direction, and two
                    # more the second's
                    if pinhole and bounce < 2:
                        pair = int(CAMERA_BSDF_1)
                        if bounce == 0:
                            pair = int(CAMERA_LENS)
                        direction = sample_camera_pair(seed, pixel, index, wp.uint32(DIM_FILM), pair)
                        u_bsdf = wp.vec3(direction[0], direction[1], u_bsdf[2])
                    wi, weight, pdf, flags = lobes_sample(lobes, u_bsdf[2], wp.vec2(u_bsdf[0], u_bsdf[1]))
                    if pdf <= 0.0 or not finite3(weight) or (
                            weight[0] <= 0.0 and weight[1] <= 0.0 and weight[2] <= 0.0):
                        alive = 0
                    else:
                        beta = wp.cw_mul(beta, weight)
                        if lights.lobe_mults != 0:
                            lobe_frac = diffuse_fraction(lobes, wi, flags & FLAG_DELTA)
                        cone_spread = bounce_spread(cone_spread, ms.roughness, flags & FLAG_DELTA)
                        if (flags & FLAG_DELTA) == 0:
                            path_roughness = wp.max(path_roughness, roughness_of_pdf(pdf))
                        if not medium_boundary(media, sp.material, flags):
                            prev_delta = flags & FLAG_DELTA
                            prev_pdf = pdf
                            prev_n = ns
                            prev_inst = hit.inst
                            prev_p = sp.p
                        passthrough = (flags & FLAG_TRANSMISSION) != 0 and thin != 0 and (flags & FLAG_DELTA) != 0
                        if not passthrough:
                            see_through = 0
                        # a light path event, unless a straight pass through a sheet or into a medium
                        if lpe_on:
                            if not passthrough and not medium_boundary(media, sp.material, flags):
                                lobe_diffuse = wp.clamp(u_bsdf[2], 0.0, 0.99999994) >= (lobes.p_coat + lobes.p_spec
                                                                                         + lobes.p_trans)
                                lpe_s = lpe_event(lpe, lpe_s, surface_symbol(
                                    lpe, (flags & FLAG_TRANSMISSION) != 0,
                                    sampled_scatter(flags & FLAG_DELTA, lobe_diffuse)))
                        if (flags & FLAG_TRANSMISSION) != 0:
                            origin = offset_origin(sp.p, -sp.ng)
                            if thin == 0:  # into or out of a solid
                                if sp.front != 0:
                                    sigma = ms.absorption
                                    if media.mesh_media != 0:
                                        m = media.mat_scatter[sp.material]
                                        in_ss = wp.vec3(m[0], m[1], m[2])
                                        in_g = m[3]
                                else:
                                    sigma = wp.vec3(0.0)
                                    in_ss = wp.vec3(0.0)
                        else:
                            origin = offset_origin(sp.p, sp.ng)
                        rd = wi
                        t_far = float(BIG)
                        bounce += 1
                        if bounce >= RR_START:
                            alive, beta = roulette(beta, sample_1d(seed, pixel, index,
                                                                   dim + wp.uint32(BOUNCE_ROULETTE)))
        L_sum = L
        if settings.clamp > 0.0:
            L = wp.vec3(wp.min(L[0], settings.clamp), wp.min(L[1], settings.clamp), wp.min(L[2], settings.clamp))
        sample = wp.vec4(L[0], L[1], L[2], alpha)
        if not finite3(L):
            sample = wp.vec4(0.0, 0.0, 0.0, alpha)
            wp.atomic_add(wave.counters, 1, wp.int64(1))
        if lpe_on:  # the vars take what the beauty took: the sample clamp's share, nothing of a non-finite sample
            keep = wp.vec3(0.0)
            if finite3(L_sum):
                for i in range(3):
                    keep[i] = 1.0
                    if L_sum[i] > L[i]:
                        keep[i] = L[i] / L_sum[i]
            lpe_finish(lpe, buf.extra, tid, keep)
        buf.film[tid] = film_u
        buf.rgba[tid] = sample
        buf.depth[tid] = depth_aov
        buf.normal[tid] = normal_aov
        buf.albedo[tid] = albedo_aov
        wp.atomic_add(wave.counters, 0, wp.int64(rays))
    return kernel


# the kernel of every render that asks for no LPE var and no first-hit record (renderer.integrator.layers: of those
# that do)
trace_wave_kernel = trace_wave_kernel_variant("trace_wave_kernel", False)
