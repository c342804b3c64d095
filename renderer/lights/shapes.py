"""The light shapes' samplers: a point on a rectangle, disk, sphere, cylinder or triangle seen from a reference
point, with its density in solid angle, built on the warps of ``renderer.sampling.warps``.

``sample_<shape>(p_ref, <geometry>, u)`` returns a ``LightSampleGeom`` (``dir`` unit vector from ``p_ref`` to
``point``, ``dist``, ``point``, unit geometric ``normal`` at the point, ``pdf`` with respect to SOLID ANGLE at
``p_ref``). ``pdf == 0`` marks an unusable sample (``p_ref`` in the light's plane, on the light, ...). The matching
``<shape>_pdf(p_ref, dir, <geometry>)`` gives the solid-angle pdf with which the sampler would produce the unit
direction ``dir`` (0 if the ray misses). Shapes are two-sided here; which side emits is the light's business.

=========================================================  =======================================================
sampler                                                    strategy
=========================================================  =======================================================
``sample_rect(p_ref, corner, edge_u, edge_v, u)``          spherical rectangle (Urena et al. 2013) while its solid
                                                           angle is in [3e-4, 6.22] sr (``SPH_RECT_*``), else by
                                                           area. ``edge_u`` must be orthogonal to ``edge_v``.
``sample_disk_light(p_ref, center, normal, radius, u)``    area (concentric map)
``sample_sphere_light(p_ref, center, radius, u)``          uniform in the cone the sphere subtends (pbrt-v4
                                                           ``Sphere::Sample(ctx)``); by area from inside
``sample_cylinder_light(p_ref, center, axis, length,       area of the lateral surface (no caps, like USD
radius, u)``                                               ``CylinderLight``); ``axis`` = unit local X in world
``sample_triangle_light(p_ref, p0, p1, p2, u)``            area (Heitz 2019 map)
=========================================================  =======================================================

For area sampling the pdf is ``dist^2 / (|cos_light| * area)``. A ray can cross a cylinder twice; like pbrt,
``cylinder_light_pdf`` uses the first hit only (the far point is shadowed by the near one), so on a cylinder the
pdf of a direction is that of the visible point, not the density of directions (the tests account for this).

Vectors named ``normal``, ``axis`` and ``dir`` must be unit length; shapes must not be degenerate.
"""
from __future__ import annotations

import warp as wp

from renderer.sampling.warps import (
    INV_TWO_PI,
    PI,
    TWO_PI,
    frame_from_normal,
    sin_cos,
    square_to_uniform_disk_concentric,
    square_to_uniform_sphere,
    square_to_uniform_triangle,
    to_world,
)
from renderer.kernels.vector_code import VECTOR_TYPES_CPP

XU_RADICAND_MIN = wp.constant(1.0e-30)  # sample_rect: fu^2 + b0^2 - 1 at least this (never a 0 / 0)

# Spherical-rectangle sampling is used only for solid angles in this range (pbrt-v4's thresholds for spherical
# triangles): below it float32 cancellation spoils the warp, above it p_ref is nearly on the light.
SPH_RECT_MIN_SOLID_ANGLE = 3e-4
SPH_RECT_MAX_SOLID_ANGLE = 6.22
W_SPH_MIN = wp.constant(SPH_RECT_MIN_SOLID_ANGLE)
W_SPH_MAX = wp.constant(SPH_RECT_MAX_SOLID_ANGLE)


@wp.struct
class LightSampleGeom:
    """A point sampled on a light's geometry, seen from a reference point."""

    dir: wp.vec3  # unit direction from p_ref to point
    dist: float  # distance from p_ref to point, scene units
    point: wp.vec3  # sampled point on the light, world space
    normal: wp.vec3  # unit geometric normal of the light at point
    pdf: float  # density of dir with respect to solid angle at p_ref, 1/sr; 0 = invalid sample


@wp.func
def _area_sample_geom(p_ref: wp.vec3, point: wp.vec3, normal: wp.vec3, area: float) -> LightSampleGeom:
    """Fill a sample chosen uniformly by area; convert the area density 1/area to solid angle."""
    g = LightSampleGeom()
    d = point - p_ref
    dist2 = wp.dot(d, d)
    g.point = point
    g.normal = normal
    g.dist = wp.sqrt(dist2)
    g.dir = wp.vec3(0.0, 0.0, 0.0)
    g.pdf = 0.0
    if dist2 > 0.0:
        g.dir = d / g.dist
        cos_l = wp.abs(wp.dot(normal, g.dir))
        if cos_l > 0.0 and area > 0.0:
            g.pdf = dist2 / (cos_l * area)
    return g


@wp.func
def _area_pdf(t: float, dir: wp.vec3, normal: wp.vec3, area: float) -> float:
    """Solid-angle pdf of an area-sampled point hit at distance t along unit dir."""
    cos_l = wp.abs(wp.dot(normal, dir))
    if cos_l <= 0.0 or area <= 0.0:
        return 0.0
    return t * t / (cos_l * area)


@wp.func
def _safe_acos(x: float) -> float:
    """acos of x clamped to [-1, 1], within 5e-7 rad (float32 rounding of Abramowitz & Stegun 4.4.46, a degree-7
    polynomial in |x| times sqrt(1 - |x|), whose own error is 2e-8). Four of these are a spherical rectangle's
    angles; libm's acosf call was most of the rectangle-light sampling time (13 % of a Cornell-box sample)."""
    a = wp.min(wp.abs(x), 1.0)
    p = float(-0.0012624911)
    p = p * a + 0.0066700901
    p = p * a - 0.0170881256
    p = p * a + 0.0308918810
    p = p * a - 0.0501743046
    p = p * a + 0.0889789874
    p = p * a - 0.2145988016
    p = p * a + 1.5707963050
    r = wp.sqrt(1.0 - a) * p
    return wp.where(x < 0.0, PI - r, r)


@wp.func
def _rect_local(p_ref: wp.vec3, corner: wp.vec3, edge_u: wp.vec3, edge_v: wp.vec3):
    """Rectangle in a frame at p_ref with x, y along the edges and z pointing away from the rectangle.

    Returns (ex, ey, ez, x0, y0, z0, x1, y1); z0 <= 0.
    """
    exl = wp.length(edge_u)
    eyl = wp.length(edge_v)
    ex = edge_u / exl
    ey = edge_v / eyl
    ez = wp.cross(ex, ey)
    d = corner - p_ref
    x0 = wp.dot(d, ex)
    y0 = wp.dot(d, ey)
    z0 = wp.dot(d, ez)
    if z0 > 0.0:
        ez = -ez
        z0 = -z0
    return ex, ey, ez, x0, y0, z0, x0 + exl, y0 + eyl


# The four edge-plane normals' radii and the four internal angles of ``_sph_rect_angles`` side by side in vector
# lanes (``vector_code``): four square roots, four divisions and four ``_safe_acos`` polynomials at once, each
# lane operation for operation what the scalar code computes (constants rounded as Warp rounds them, double to
# float), so the same bits (tests/renderer/sampling/test_sampling.py holds them to the scalar code, bit for bit). The angles were a
# quarter of the rectangle light's sampling, itself 16 % of a gloss sample.
_SPH_RECT_CPP = VECTOR_TYPES_CPP + r"""
    const v4f zz = splat(z0 * z0);
    const v4f w = {y0, x1, y1, x0};  /* r0 .. r3 */
    const v4f ww = w * w;
    const v4f r = __builtin_elementwise_sqrt(zz + ww);
    const v4f r_next = __builtin_shufflevector(r, r, 1, 2, 3, 0);
    const v4f num_a = {y0, -x1, x0, -x0};
    const v4f num_b = {x1, y1, y1, y0};
    const v4f num = num_a * num_b;
    const v4f den = r * r_next;
    const v4f x = num / den;
    /* _safe_acos: Warp's min(|x|, 1) takes 1 for a NaN */
    const v4f one = splat(1.0f);
    const v4f ax = __builtin_elementwise_abs(x);
    const v4f a = ax <= one ? ax : one;
    auto c = [&](double v) { return splat((float)v); };  /* _safe_acos's coefficients (the test holds them equal) */
    v4f p = c(-0.0012624911);
    v4f m;
    m = p * a; p = m + c(0.0066700901);
    m = p * a; p = m - c(0.0170881256);
    m = p * a; p = m + c(0.0308918810);
    m = p * a; p = m - c(0.0501743046);
    m = p * a; p = m + c(0.0889789874);
    m = p * a; p = m - c(0.2145988016);
    m = p * a; p = m + c(1.5707963050);
    const v4f rr = __builtin_elementwise_sqrt(one - a) * p;
    const v4f g = x < splat(0.0f) ? c(3.141592653589793) - rr : rr;
    return wp::vec_t<4, wp::float32>(g[0] + g[1], g[2] + g[3], r[0], r[2]);
"""


@wp.func_native(_SPH_RECT_CPP)
def _sph_rect_lanes(x0: float, y0: float, z0: float, x1: float, y1: float) -> wp.vec4:
    """(g0 + g1, g2 + g3, r0, r2) of ``_sph_rect_angles`` as vector code."""
    ...


@wp.func
def _sph_rect_angles(x0: float, y0: float, z0: float, x1: float, y1: float):
    """Internal angles of the spherical rectangle and the z of two edge-plane normals (Urena et al. 2013).

    Returns (g0 + g1, g2 + g3, b0, b1, solid_angle). solid_angle is 0 when p_ref lies in the plane.
    The edge planes' unit normals are n0 = (0, z0, -y0) / r0, n1 = (-z0, 0, x1) / r1, n2 = (0, -z0, y1) / r2,
    n3 = (z0, 0, -x0) / r3 (the normalised cross products of consecutive corners, written out as pbrt-v4 does),
    so the cosines of the internal angles, -n_i . n_(i+1), are products of corner coordinates (as in Cycles).
    The four lanes in vector code (``_sph_rect_lanes``), the same bits as the scalar code in tests/renderer/sampling/test_sampling.py.
    """
    lanes = _sph_rect_lanes(x0, y0, z0, x1, y1)
    g01 = lanes[0]
    g23 = lanes[1]
    solid_angle = g01 + g23 - TWO_PI
    if z0 == 0.0:
        solid_angle = 0.0
    return g01, g23, -y0 / lanes[2], y1 / lanes[3], solid_angle


@wp.func
def _use_sph_rect(solid_angle: float) -> bool:
    return solid_angle >= W_SPH_MIN and solid_angle <= W_SPH_MAX


@wp.func
def sample_rect(p_ref: wp.vec3, corner: wp.vec3, edge_u: wp.vec3, edge_v: wp.vec3, u: wp.vec2) -> LightSampleGeom:
    """Point on the rectangle ``corner + a * edge_u + b * edge_v`` (a, b in [0, 1]) seen from ``p_ref``."""
    n = wp.cross(edge_u, edge_v)
    area = wp.length(n)
    normal = n / area
    ex, ey, ez, x0, y0, z0, x1, y1 = _rect_local(p_ref, corner, edge_u, edge_v)
    g01, g23, b0, b1, solid_angle = _sph_rect_angles(x0, y0, z0, x1, y1)
    if not _use_sph_rect(solid_angle):
        return _area_sample_geom(p_ref, corner + u[0] * edge_u + u[1] * edge_v, normal, area)
    # Urena et al. 2013, as in pbrt-v4 SampleSphericalRectangle: first the x of the sample (u[0] sweeps the
    # spherical area), then y along the vertical arc at that x (u[1] uniform in h = sin(elevation)).
    au = u[0] * (g01 - TWO_PI) + (u[0] - 1.0) * g23
    sau, cau = sin_cos(au)
    fu = (cau * b0 - b1) / sau
    # pbrt's cu = sign(fu) / sqrt(fu^2 + b0^2) and xu = -cu z0 / sqrt(1 - cu^2) in one step: 1 - cu^2 is
    # (fu^2 + b0^2 - 1) / (fu^2 + b0^2), so xu = -sign(fu) z0 / sqrt(fu^2 + b0^2 - 1), one square root and one
    # division on the sample's chain of dependent ones where there were two of each (the floor stands for pbrt's
    # clamp of cu below 1: xu then lies past the rectangle's edge and is clamped to it)
    e = fu * fu + b0 * b0 - 1.0
    xu = wp.clamp(wp.where(fu < 0.0, z0, -z0) / wp.sqrt(wp.max(e, XU_RADICAND_MIN)), x0, x1)
    dd2 = xu * xu + z0 * z0  # squared distance to the vertical arc's line: its root is off the chain
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


@wp.func
def rect_pdf(p_ref: wp.vec3, dir: wp.vec3, corner: wp.vec3, edge_u: wp.vec3, edge_v: wp.vec3) -> float:
    """Solid-angle pdf of ``sample_rect`` producing the unit direction ``dir`` from ``p_ref`` (0 on a miss)."""
    n = wp.cross(edge_u, edge_v)
    area = wp.length(n)
    normal = n / area
    denom = wp.dot(dir, normal)
    if denom == 0.0:
        return 0.0
    t = wp.dot(corner - p_ref, normal) / denom
    if t <= 0.0:
        return 0.0
    q = p_ref + t * dir - corner
    a = wp.dot(q, edge_u) / wp.dot(edge_u, edge_u)
    b = wp.dot(q, edge_v) / wp.dot(edge_v, edge_v)
    if a < 0.0 or a > 1.0 or b < 0.0 or b > 1.0:
        return 0.0
    ex, ey, ez, x0, y0, z0, x1, y1 = _rect_local(p_ref, corner, edge_u, edge_v)
    g01, g23, b0, b1, solid_angle = _sph_rect_angles(x0, y0, z0, x1, y1)
    if _use_sph_rect(solid_angle):
        return 1.0 / solid_angle
    return _area_pdf(t, dir, normal, area)


@wp.func
def sample_disk_light(p_ref: wp.vec3, center: wp.vec3, normal: wp.vec3, radius: float, u: wp.vec2) -> LightSampleGeom:
    """Point uniform by area on the disk (``center``, unit ``normal``, ``radius``)."""
    d = radius * square_to_uniform_disk_concentric(u)
    point = center + to_world(wp.vec3(d[0], d[1], 0.0), normal)
    return _area_sample_geom(p_ref, point, normal, PI * radius * radius)


@wp.func
def disk_light_pdf(p_ref: wp.vec3, dir: wp.vec3, center: wp.vec3, normal: wp.vec3, radius: float) -> float:
    denom = wp.dot(dir, normal)
    if denom == 0.0:
        return 0.0
    t = wp.dot(center - p_ref, normal) / denom
    if t <= 0.0:
        return 0.0
    q = p_ref + t * dir - center
    if wp.dot(q, q) > radius * radius:
        return 0.0
    return _area_pdf(t, dir, normal, PI * radius * radius)


@wp.func
def _sphere_cone(p_ref: wp.vec3, center: wp.vec3, radius: float):
    """(unit axis to center, distance to center, cos_theta_max, 1 - cos_theta_max) of the subtended cone."""
    dc = center - p_ref
    dist_c = wp.length(dc)
    sin2_max = (radius / dist_c) * (radius / dist_c)
    cos_max = wp.sqrt(wp.max(0.0, 1.0 - sin2_max))
    one_minus_cos = sin2_max / (1.0 + cos_max)  # = 1 - cos_max without cancellation
    return dc / dist_c, dist_c, cos_max, one_minus_cos


@wp.func
def sample_sphere_light(p_ref: wp.vec3, center: wp.vec3, radius: float, u: wp.vec2) -> LightSampleGeom:
    """Point on the sphere's visible cap, direction uniform in the subtended cone; by area from inside."""
    dc = center - p_ref
    if wp.dot(dc, dc) <= radius * radius:
        n = square_to_uniform_sphere(u)
        return _area_sample_geom(p_ref, center + radius * n, n, 4.0 * PI * radius * radius)
    wc, dist_c, cos_max, one_minus_cos_max = _sphere_cone(p_ref, center, radius)
    sin_max = radius / dist_c
    # Direction in the cone (pbrt-v4 Sphere::Sample), then the angle alpha at the center to the first hit.
    omc = u[0] * one_minus_cos_max
    cos_t = 1.0 - omc
    sin2_t = omc * (2.0 - omc)
    cos_alpha = sin2_t / sin_max + cos_t * wp.sqrt(wp.max(0.0, 1.0 - sin2_t / (sin_max * sin_max)))
    sin_alpha = wp.sqrt(wp.max(0.0, 1.0 - cos_alpha * cos_alpha))
    sp, cp = sin_cos(TWO_PI * u[1])
    w = wp.vec3(sin_alpha * cp, sin_alpha * sp, cos_alpha)
    n = -to_world(w, wc)
    g = LightSampleGeom()
    g.point = center + radius * n
    g.normal = n
    d = g.point - p_ref
    g.dist = wp.length(d)
    g.dir = d / g.dist
    g.pdf = INV_TWO_PI / one_minus_cos_max
    return g


@wp.func
def sphere_light_pdf(p_ref: wp.vec3, dir: wp.vec3, center: wp.vec3, radius: float) -> float:
    dc = center - p_ref
    r2 = radius * radius
    if wp.dot(dc, dc) <= r2:
        # Inside: exactly one hit, at the far root of |p_ref + t dir - center|^2 = r^2.
        b = wp.dot(dir, dc)
        t = b + wp.sqrt(wp.max(0.0, b * b - (wp.dot(dc, dc) - r2)))
        n = wp.normalize(p_ref + t * dir - center)
        return _area_pdf(t, dir, n, 4.0 * PI * r2)
    wc, dist_c, cos_max, one_minus_cos_max = _sphere_cone(p_ref, center, radius)
    # Inside the cone <=> sin^2 of the angle to the axis <= (r / d)^2; the cross product keeps this exact in
    # float32 for tiny cones, where comparing cosines near 1 would not.
    c = wp.cross(dir, wc)
    if wp.dot(dir, wc) <= 0.0 or wp.dot(c, c) > (radius / dist_c) * (radius / dist_c):
        return 0.0
    return INV_TWO_PI / one_minus_cos_max


@wp.func
def sample_cylinder_light(
    p_ref: wp.vec3, center: wp.vec3, axis: wp.vec3, length: float, radius: float, u: wp.vec2
) -> LightSampleGeom:
    """Point uniform by area on the lateral surface of the cylinder centred at ``center`` along unit ``axis``."""
    f = frame_from_normal(axis)
    sp, cp = sin_cos(TWO_PI * u[1])
    n = cp * wp.vec3(f[0, 0], f[1, 0], f[2, 0]) + sp * wp.vec3(f[0, 1], f[1, 1], f[2, 1])
    point = center + (u[0] - 0.5) * length * axis + radius * n
    return _area_sample_geom(p_ref, point, n, TWO_PI * radius * length)


@wp.func
def cylinder_light_pdf(
    p_ref: wp.vec3, dir: wp.vec3, center: wp.vec3, axis: wp.vec3, length: float, radius: float
) -> float:
    """Solid-angle pdf of the FIRST hit of the ray (p_ref, dir) on the cylinder's lateral surface."""
    o = p_ref - center
    o_perp = o - wp.dot(o, axis) * axis
    d_perp = dir - wp.dot(dir, axis) * axis
    a = wp.dot(d_perp, d_perp)
    if a == 0.0:
        return 0.0
    # Roots of |o_perp + t d_perp| = radius via the closest-approach vector (pbrt-v4's accurate discriminant):
    # t = t_mid -+ sqrt(disc) / a with disc = a (r^2 - |c|^2); at either root |cos_light| = sqrt(disc) / r.
    t_mid = -wp.dot(o_perp, d_perp) / a
    c = o_perp + t_mid * d_perp
    disc = a * (radius * radius - wp.dot(c, c))
    if disc <= 0.0:
        return 0.0
    half_chord = wp.sqrt(disc) / a
    cos_l = wp.sqrt(disc) / radius
    area = TWO_PI * radius * length
    half = 0.5 * length
    t0 = t_mid - half_chord
    t1 = t_mid + half_chord
    if t0 > 0.0 and wp.abs(wp.dot(o + t0 * dir, axis)) <= half:
        return t0 * t0 / (cos_l * area)
    if t1 > 0.0 and wp.abs(wp.dot(o + t1 * dir, axis)) <= half:
        return t1 * t1 / (cos_l * area)
    return 0.0


@wp.func
def sample_triangle_light(p_ref: wp.vec3, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, u: wp.vec2) -> LightSampleGeom:
    """Point uniform by area on the triangle; normal = normalize((p1 - p0) x (p2 - p0))."""
    b = square_to_uniform_triangle(u)
    point = b[0] * p0 + b[1] * p1 + (1.0 - b[0] - b[1]) * p2
    n = wp.cross(p1 - p0, p2 - p0)
    len_n = wp.length(n)
    return _area_sample_geom(p_ref, point, n / len_n, 0.5 * len_n)


@wp.func
def triangle_light_pdf(p_ref: wp.vec3, dir: wp.vec3, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3) -> float:
    e1 = p1 - p0
    e2 = p2 - p0
    pv = wp.cross(dir, e2)
    det = wp.dot(e1, pv)
    if det == 0.0:
        return 0.0
    inv_det = 1.0 / det
    tv = p_ref - p0
    bu = wp.dot(tv, pv) * inv_det
    qv = wp.cross(tv, e1)
    bv = wp.dot(dir, qv) * inv_det
    if bu < 0.0 or bv < 0.0 or bu + bv > 1.0:
        return 0.0
    t = wp.dot(e2, qv) * inv_det
    if t <= 0.0:
        return 0.0
    n = wp.cross(e1, e2)
    len_n = wp.length(n)
    return _area_pdf(t, dir, n / len_n, 0.5 * len_n)
