"""Sampling lights (the paper's light-area dimension) and the pdfs multiple importance sampling needs.

``sample_light`` places light ``li`` at the sample's time and picks a point on it from two uniform numbers
(area, spherical-rectangle or cone sampling: ``lights.shapes``, ``sampling.warps``), returning the solid-angle
pdf. The same pdf is given by ``area_light_hit`` / ``infinite_light_eval`` / ``mesh_light_pdf`` for a direction
found by BSDF sampling, so both strategies can be weighted by the power heuristic. ``first_seen_light`` finds what
a camera ray sees of the area lights seen by the camera, with the same radiance.
"""
from __future__ import annotations

import warp as wp

from renderer.accel.intersect import (
    BIG,
    Geometry,
    instance_object_to_world,
    instance_visible,
    instance_world_to_object,
    mesh_keys_at,
    triangle_points,
)
from renderer.accel.occlusion import hit_uv
from renderer.lights.envmap import env_pdf, env_radiance, env_sample
from renderer.lights.linking import lit_by
from renderer.lights.shapes import (
    cylinder_light_pdf,
    disk_light_pdf,
    rect_pdf,
    sample_cylinder_light,
    sample_disk_light,
    sample_rect,
    sample_sphere_light,
    sample_triangle_light,
    sphere_light_pdf,
)
from renderer.lights.shaping import shaping_eval
from renderer.lights.table import Lights
from renderer.motion.kernels import keys_matrix
from renderer.sampling.warps import (square_to_cosine_hemisphere, square_to_uniform_cone, square_to_uniform_triangle,
                                     to_world)
from renderer.scene.model import (
    LIGHT_CYLINDER,
    LIGHT_DISK,
    LIGHT_DISTANT,
    LIGHT_DOME,
    LIGHT_RECT,
    LIGHT_SPHERE,
)
from renderer.shading.materials import Materials, eval_emission
from renderer.shading.textures import Textures

DISTANT_DIST = 1.0e30  # shadow-ray length toward lights at infinity (scene units)


@wp.func
def pick_triangle(lights: Lights, li: int, u: float):
    """A mesh light's triangle (index within its mesh) chosen by emitted power, and that probability."""
    off = lights.cdf_off[li]
    n = lights.tri_count[li]
    lo = int(0)
    hi = n - 1
    while lo < hi:
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
def triangle_probability(lights: Lights, li: int, tri_in_mesh: int):
    k = tri_in_mesh - lights.tri_base[li]
    if k < 0 or k >= lights.tri_count[li]:
        return 0.0
    off = lights.cdf_off[li]
    prev = float(0.0)
    if k > 0:
        prev = lights.cdf[off + k - 1]
    return lights.cdf[off + k] - prev


@wp.func
def light_matrix(lights: Lights, li: int, s: float):
    if lights.xf_count[li] > 1:
        return keys_matrix(lights.keys, lights.xf_off[li], lights.xf_count[li], s)
    return lights.xf_still[li]


@wp.func
def light_shaping(lights: Lights, li: int, emit_dir: wp.vec3, s: float):
    """ShapingAPI colour of light li for the unit world direction ``emit_dir`` leaving it, at time s."""
    sh0 = lights.shape0[li]
    if sh0[3] == 0.0:
        return wp.vec3(1.0)
    sh = sh0 * (1.0 - s) + lights.shape1[li] * s
    m = light_matrix(lights, li, s)
    ax = wp.normalize(wp.transform_vector(m, wp.vec3(1.0, 0.0, 0.0)))
    ay = wp.normalize(wp.transform_vector(m, wp.vec3(0.0, 1.0, 0.0)))
    az = wp.normalize(wp.transform_vector(m, wp.vec3(0.0, 0.0, 1.0)))
    dl = wp.normalize(wp.vec3(wp.dot(emit_dir, ax), wp.dot(emit_dir, ay), wp.dot(emit_dir, az)))
    return shaping_eval(sh, lights.focus_tint[li], lights.ies_table, lights.ies_off[li], lights.ies_param[li], dl)


@wp.func
def rect_texel(lights: Lights, li: int, corner: wp.vec3, ex: wp.vec3, ey: wp.vec3, q: wp.vec3):
    """A rect light's texture at world point q on it (white without one), nearest texel: the image's top-left
    texel at the (-X, +Y) corner, its bottom-right at (+X, -Y), so the image reads unmirrored from behind the
    light, looking where it shines (as a projector's slide; husk, kick and other renderers agree on this)."""
    off = lights.img_off[li]
    if off < 0:
        return wp.vec3(1.0)
    a = wp.clamp(wp.dot(q - corner, ex) / wp.dot(ex, ex), 0.0, 1.0)  # 0 at -X, 1 at +X
    b = wp.clamp(wp.dot(q - corner, ey) / wp.dot(ey, ey), 0.0, 1.0)  # 0 at -Y, 1 at +Y
    w = lights.img_w[li]
    h = lights.img_h[li]
    col = wp.min(int(a * float(w)), w - 1)
    row = wp.min(int((1.0 - b) * float(h)), h - 1)
    return lights.img[off + row * w + col]


@wp.func
def rect_frame(lights: Lights, li: int, s: float):
    """World corner, edge vectors and emitting normal of a rect light at time s."""
    if lights.xf_count[li] == 1:
        return (lights.rect_still[4 * li], lights.rect_still[4 * li + 1], lights.rect_still[4 * li + 2],
                lights.rect_still[4 * li + 3])
    m = light_matrix(lights, li, s)
    size = lights.size[li]
    ex = wp.transform_vector(m, wp.vec3(size[0], 0.0, 0.0))
    ey = wp.transform_vector(m, wp.vec3(0.0, size[1], 0.0))
    corner = wp.transform_point(m, wp.vec3(-0.5 * size[0], -0.5 * size[1], 0.0))
    return corner, ex, ey, emitting_side(m)


@wp.func
def emitting_side(m: wp.mat44):
    """Unit normal of a rect or disk light's plane (the xy plane of its light-to-world m) on the side it emits
    from: "along the -Z axis" (usdLux), the side -m z points to. That is -(m x) x (m y), but under a mirroring m
    (negative determinant) whose (m x) x (m y) points away from m z (``table.emitting_sides``)."""
    n = wp.normalize(wp.cross(wp.transform_vector(m, wp.vec3(1.0, 0.0, 0.0)),
                              wp.transform_vector(m, wp.vec3(0.0, 1.0, 0.0))))
    if wp.dot(n, wp.transform_vector(m, wp.vec3(0.0, 0.0, 1.0))) < 0.0:
        return n
    return -n


@wp.func
def disk_frame(lights: Lights, li: int, s: float):
    """A disk light's world centre, emitting normal (its -z side) and radius at time s."""
    if lights.xf_count[li] == 1:
        c = lights.centre_still[li]
        return wp.vec3(c[0], c[1], c[2]), lights.disk_front_still[li], c[3]
    m = light_matrix(lights, li, s)
    return wp.transform_point(m, wp.vec3(0.0)), emitting_side(m), lights.size[li][2] * wp.length(
        wp.transform_vector(m, wp.vec3(1.0, 0.0, 0.0)))


@wp.func
def sphere_frame(lights: Lights, li: int, s: float):
    """A sphere light's world centre and radius at time s."""
    if lights.xf_count[li] == 1:
        c = lights.centre_still[li]
        return wp.vec3(c[0], c[1], c[2]), c[3]
    m = light_matrix(lights, li, s)
    return wp.transform_point(m, wp.vec3(0.0)), lights.size[li][2] * wp.length(
        wp.transform_vector(m, wp.vec3(1.0, 0.0, 0.0)))


@wp.func
def cylinder_frame(lights: Lights, li: int, s: float):
    m = light_matrix(lights, li, s)
    ax = wp.transform_vector(m, wp.vec3(1.0, 0.0, 0.0))
    ry = wp.length(wp.transform_vector(m, wp.vec3(0.0, 1.0, 0.0)))
    size = lights.size[li]
    return wp.transform_point(m, wp.vec3(0.0)), wp.normalize(ax), size[0] * wp.length(ax), size[2] * ry


@wp.func
def distant_axis(lights: Lights, li: int, s: float):
    """Unit direction toward a distant light."""
    if lights.xf_count[li] == 1:
        return lights.axis_still[li]
    return wp.normalize(wp.transform_vector(light_matrix(lights, li, s), wp.vec3(0.0, 0.0, 1.0)))


@wp.func
def light_radiance(lights: Lights, li: int, s: float) -> wp.vec3:
    """Radiance of light ``li`` at normalised shutter time ``s``: its keys linearly interpolated when its emission
    is animated within the shutter (``rad_count`` > 1), else the constant."""
    n = lights.rad_count[li]
    if n < 2:
        return lights.radiance[li]
    x = wp.clamp(s, 0.0, 1.0) * float(n - 1)
    k = wp.min(int(x), n - 2)
    off = lights.rad_off[li] + k
    return wp.lerp(lights.rad_keys[off], lights.rad_keys[off + 1], x - float(k))


@wp.func(inline=True)  # called once per path vertex: no copy of the big structs
def sample_light(lights: Lights, geo: Geometry, mats: Materials, tex: Textures, li: int, p: wp.vec3,
                 n: wp.vec3, s: float, u_pick: float, u: wp.vec2):
    """Sample light ``li`` from point p (shading normal n) at time s.

    Returns (wi, dist, Le, pdf, delta): unit direction to the light, distance for the shadow ray, emitted
    radiance along -wi, and the solid-angle pdf (not including the light's selection probability). For
    delta lights (point, distant of angle 0) pdf is 1 and Le already is the irradiance-like term
    (intensity / dist^2, or irradiance), and delta is True: no multiple importance weight applies.
    """
    kind = lights.kind[li]
    Le = light_radiance(lights, li, s)
    zero = wp.vec3(0.0)
    if kind == LIGHT_RECT:
        corner, ex, ey, front = rect_frame(lights, li, s)
        g = sample_rect(p, corner, ex, ey, u)
        if g.pdf > 0.0 and wp.dot(g.dir, front) < 0.0:
            Le = wp.cw_mul(Le, rect_texel(lights, li, corner, ex, ey, p + g.dir * g.dist))
            return g.dir, g.dist, wp.cw_mul(Le, light_shaping(lights, li, -g.dir, s)), g.pdf, False
        return zero, 0.0, zero, 0.0, False
    if kind == LIGHT_DISK:
        c, front, r = disk_frame(lights, li, s)
        g = sample_disk_light(p, c, front, r, u)
        if g.pdf > 0.0 and wp.dot(g.dir, front) < 0.0:
            return g.dir, g.dist, wp.cw_mul(Le, light_shaping(lights, li, -g.dir, s)), g.pdf, False
        return zero, 0.0, zero, 0.0, False
    if kind == LIGHT_SPHERE:
        c, r = sphere_frame(lights, li, s)
        if r <= 0.0:  # point light: radiance holds the intensity
            d = c - p
            dist = wp.length(d)
            if dist <= 0.0:
                return zero, 0.0, zero, 0.0, True
            return d / dist, dist, wp.cw_mul(Le, light_shaping(lights, li, -d / dist, s)) / (dist * dist), 1.0, True
        g = sample_sphere_light(p, c, r, u)
        if g.pdf > 0.0:
            return g.dir, g.dist, wp.cw_mul(Le, light_shaping(lights, li, -g.dir, s)), g.pdf, False
        return zero, 0.0, zero, 0.0, False
    if kind == LIGHT_CYLINDER:
        c, axis, length, r = cylinder_frame(lights, li, s)
        g = sample_cylinder_light(p, c, axis, length, r, u)
        if g.pdf > 0.0 and wp.dot(g.dir, g.normal) < 0.0:
            return g.dir, g.dist, wp.cw_mul(Le, light_shaping(lights, li, -g.dir, s)), g.pdf, False
        return zero, 0.0, zero, 0.0, False
    if kind == LIGHT_DISTANT:
        to_light = distant_axis(lights, li, s)
        cos_max = lights.size[li][0]
        if cos_max >= 1.0:
            return to_light, DISTANT_DIST, Le, 1.0, True
        wi = to_world(square_to_uniform_cone(u, cos_max), to_light)
        return wi, DISTANT_DIST, Le, 1.0 / (2.0 * wp.pi * (1.0 - cos_max)), False
    if kind == LIGHT_DOME:
        if lights.size[li][0] > 0.0:
            d, pdf, L = env_sample(lights.env, u)
            return d, DISTANT_DIST, wp.cw_mul(Le, L), pdf, False
        wi = to_world(square_to_cosine_hemisphere(u), n)
        cos_n = wp.dot(wi, n)
        if cos_n <= 0.0:
            return zero, 0.0, zero, 0.0, False
        return wi, DISTANT_DIST, Le, cos_n / wp.pi, False
    # emissive mesh: a triangle by power, a point on it by area
    inst = lights.instance[li]
    if not instance_visible(geo, inst, s):
        return zero, 0.0, zero, 0.0, False
    tri, p_tri = pick_triangle(lights, li, u_pick)
    mesh = geo.inst_mesh[inst]
    k0, k1, ku = mesh_keys_at(geo, mesh, s)
    p0, p1, p2 = triangle_points(geo, mesh, tri, k0, k1, ku)
    o2w = instance_object_to_world(geo, inst, s)
    g = sample_triangle_light(p, wp.transform_point(o2w, p0), wp.transform_point(o2w, p1),
                              wp.transform_point(o2w, p2), u)
    if lights.one_sided[li] != 0:  # a MeshLightAPI mesh emits from its front faces (normal as surface_at's)
        w2o_t = wp.transpose(instance_world_to_object(geo, inst, s))
        if wp.dot(wp.transform_vector(w2o_t, wp.cross(p1 - p0, p2 - p0)), g.dir) >= 0.0:
            return zero, 0.0, zero, 0.0, False
    if g.pdf > 0.0 and lights.uniform[li] != 0:  # MeshLightAPI: light rays only, so no MIS partner
        # ShapingAPI about the light's primary axis, the mesh prim's -Z (its transform is the light's), the same
        # for every triangle: each triangle's normal only decides which side emits (above)
        return g.dir, g.dist, wp.cw_mul(Le, light_shaping(lights, li, -g.dir, s)), g.pdf * p_tri, True
    if g.pdf > 0.0:
        # the emission where the point landed (emissive textures): its barycentrics are the warp's
        b = square_to_uniform_triangle(u)
        tg = geo.mesh_tri_off[mesh] + tri
        uv = hit_uv(geo, mesh, tg, b[1], 1.0 - b[0] - b[1])
        return g.dir, g.dist, eval_emission(mats, tex, geo.tri_material[tg], uv), g.pdf * p_tri, False
    return zero, 0.0, zero, 0.0, False


@wp.func
def emission_mis_light(lights: Lights, inst: int):
    """The mesh light whose sampling also finds the emission seen on instance ``inst`` (for the MIS weight), or
    -1: none, or a MeshLightAPI light (its L reaches surfaces by light sampling only; hits see the glow)."""
    li = lights.inst_light[inst]
    if li >= 0 and lights.uniform[li] != 0:
        return -1
    return li


@wp.func
def plane_hit(ro: wp.vec3, rd: wp.vec3, point: wp.vec3, normal: wp.vec3):
    denom = wp.dot(rd, normal)
    if denom == 0.0:
        return float(BIG)
    return wp.dot(point - ro, normal) / denom


@wp.func(inline=True)  # called once per path vertex: no copy of the big structs
def area_light_hit(lights: Lights, li: int, ro: wp.vec3, rd: wp.vec3, tmax: float, s: float):
    """Does the ray (ro, rd) reach UsdLux area light li before tmax? Returns (t, Le, pdf of sampling rd).

    UsdLux lights are not in the BVH: BSDF-sampled rays test them here, so mirrors and glass show them and
    multiple importance sampling can weight the two ways of finding them. t = BIG when missed.
    """
    kind = lights.kind[li]
    zero = wp.vec3(0.0)
    if kind == LIGHT_RECT:
        corner, ex, ey, front = rect_frame(lights, li, s)
        t = plane_hit(ro, rd, corner, front)
        if t > 0.0 and t < tmax and wp.dot(rd, front) < 0.0:
            pdf = rect_pdf(ro, rd, corner, ex, ey)
            if pdf > 0.0:
                Le = wp.cw_mul(light_radiance(lights, li, s), rect_texel(lights, li, corner, ex, ey, ro + rd * t))
                return t, wp.cw_mul(Le, light_shaping(lights, li, -rd, s)), pdf
    elif kind == LIGHT_DISK:
        c, front, r = disk_frame(lights, li, s)
        t = plane_hit(ro, rd, c, front)
        if t > 0.0 and t < tmax and wp.dot(rd, front) < 0.0:
            pdf = disk_light_pdf(ro, rd, c, front, r)
            if pdf > 0.0:
                return t, wp.cw_mul(light_radiance(lights, li, s), light_shaping(lights, li, -rd, s)), pdf
    elif kind == LIGHT_SPHERE:
        c, r = sphere_frame(lights, li, s)
        if r > 0.0:
            oc = ro - c
            b = wp.dot(oc, rd)
            disc = b * b - (wp.dot(oc, oc) - r * r)
            if disc > 0.0:
                t = -b - wp.sqrt(disc)
                if t <= 0.0:
                    t = -b + wp.sqrt(disc)
                if t > 0.0 and t < tmax:
                    pdf = sphere_light_pdf(ro, rd, c, r)
                    if pdf > 0.0:
                        return t, wp.cw_mul(light_radiance(lights, li, s), light_shaping(lights, li, -rd, s)), pdf
    elif kind == LIGHT_CYLINDER:
        c, axis, length, r = cylinder_frame(lights, li, s)
        o = ro - c
        o_perp = o - wp.dot(o, axis) * axis
        d_perp = rd - wp.dot(rd, axis) * axis
        a = wp.dot(d_perp, d_perp)
        if a > 0.0:
            t_mid = -wp.dot(o_perp, d_perp) / a
            q = o_perp + t_mid * d_perp
            disc = a * (r * r - wp.dot(q, q))
            if disc > 0.0:
                t = t_mid - wp.sqrt(disc) / a  # only the outside emits: the near wall, seen from outside
                if t > 0.0 and t < tmax and wp.abs(wp.dot(o + t * rd, axis)) <= 0.5 * length:
                    pdf = cylinder_light_pdf(ro, rd, c, axis, length, r)
                    if pdf > 0.0:
                        return t, wp.cw_mul(light_radiance(lights, li, s), light_shaping(lights, li, -rd, s)), pdf
    return float(BIG), zero, 0.0


@wp.func
def first_seen_light(lights: Lights, ro: wp.vec3, rd: wp.vec3, tmax: float, s: float, prev_inst: int):
    """The nearest area light camera rays see (``reach.seen``) that the ray (ro, rd) reaches before tmax, at time s:
    (light or -1, t, Le), Le what ``area_light_hit`` gives a BSDF-sampled ray (texture, shaping, one-sidedness)."""
    best = int(-1)
    t_best = tmax
    Le_best = wp.vec3(0.0)
    for k in range(lights.reach.n_seen):
        li = lights.reach.seen[k]
        t, Le, pdf = area_light_hit(lights, li, ro, rd, t_best, s)
        if t < t_best and lit_by(lights.links, li, prev_inst):
            best = li
            t_best = t
            Le_best = Le
    return best, t_best, Le_best


@wp.func(inline=True)  # called once per path vertex: no copy of the big structs
def infinite_light_eval(lights: Lights, li: int, d: wp.vec3, n_prev: wp.vec3, s: float):
    """Radiance from infinite light li along a ray leaving the scene in direction d, and the pdf of sampling d.

    ``n_prev`` is the shading normal at the ray's origin (constant domes are sampled about it).
    """
    kind = lights.kind[li]
    if kind == LIGHT_DOME:
        if lights.size[li][0] > 0.0:
            return wp.cw_mul(light_radiance(lights, li, s), env_radiance(lights.env, d)), env_pdf(lights.env, d)
        return light_radiance(lights, li, s), wp.max(wp.dot(d, n_prev), 0.0) / wp.pi
    if kind == LIGHT_DISTANT:
        cos_max = lights.size[li][0]
        if cos_max < 1.0 and wp.dot(d, distant_axis(lights, li, s)) >= cos_max:
            return light_radiance(lights, li, s), 1.0 / (2.0 * wp.pi * (1.0 - cos_max))
    return wp.vec3(0.0), 0.0


@wp.func(inline=True)  # called once per path vertex: no copy of the big structs
def mesh_light_pdf(lights: Lights, geo: Geometry, li: int, inst: int, tri_global: int, ref: wp.vec3,
                   hit: wp.vec3, s: float):
    """Solid-angle pdf with which ``sample_light`` would have chosen point ``hit`` on an emissive triangle."""
    mesh = geo.inst_mesh[inst]
    tri = tri_global - geo.mesh_tri_off[mesh]
    p_tri = triangle_probability(lights, li, tri)
    if p_tri <= 0.0:
        return 0.0
    k0, k1, ku = mesh_keys_at(geo, mesh, s)
    p0, p1, p2 = triangle_points(geo, mesh, tri, k0, k1, ku)
    o2w = instance_object_to_world(geo, inst, s)
    w0 = wp.transform_point(o2w, p0)
    nrm = wp.cross(wp.transform_point(o2w, p1) - w0, wp.transform_point(o2w, p2) - w0)
    area2 = wp.length(nrm)
    d = hit - ref
    dist2 = wp.dot(d, d)
    if area2 <= 0.0 or dist2 <= 0.0:
        return 0.0
    cos_l = wp.abs(wp.dot(nrm, d)) / (area2 * wp.sqrt(dist2))
    if cos_l <= 0.0:
        return 0.0
    return p_tri * dist2 / (cos_l * 0.5 * area2)
