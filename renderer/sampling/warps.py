"""Sampling routines: warps from uniform numbers to shapes and directions, each paired with its density.

After pbrt-v4 ``util/sampling.h`` and Mitsuba 3 ``warp.py``. Every routine takes its uniform numbers as arguments
(it never owns an RNG), so it can be tested alone and replayed. Every ``X`` has ``X_pdf`` (same name + ``_pdf``),
and both have NumPy twins named ``np_X`` / ``np_X_pdf`` (vectorised over a leading batch axis, float64) that the
tests compare against the Warp ``@wp.func``s and feed to the chi-square harness.

Conventions
-----------
* Local frames are z-up; ``frame_from_normal(n)`` returns the matrix whose columns are (s, t, n) (Duff et al. 2017,
  branchless), so ``to_world(v, n) = frame @ v`` and ``to_local(v, n) = frame^T @ v``.
* Densities are with respect to: area in the unit square / disk / barycentric triangle for 2D warps, solid angle
  for directions, length for ``sample_tent``.
* ``square_to_uniform_triangle(u)`` returns barycentrics ``(b0, b1)``, weights of ``p0`` and ``p1``; the weight of
  ``p2`` is ``1 - b0 - b1``. Its pdf is 2, the density over ``{b0, b1 >= 0, b0 + b1 <= 1}`` (area 1/2); on a real
  triangle that is ``1 / area``. Low-distortion map of Heitz 2019.
* ``square_to_uniform_cone(u, cos_theta_max)`` needs ``cos_theta_max < 1`` (a zero-angle cone is a delta and the
  caller handles it; the pdf then returns 0).

Light geometry samplers
-----------------------
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

NumPy twins return ``NpLightSample`` (same fields, arrays). Geometry arguments broadcast against the batch. Extra
NumPy helpers for tests: ``np_rect_solid_angle`` (the strategy switch) and ``np_cylinder_hits`` (both crossings).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import warp as wp

from renderer.vector_code import VECTOR_TYPES_CPP

PI = wp.constant(math.pi)
TWO_PI = wp.constant(2.0 * math.pi)
INV_PI = wp.constant(1.0 / math.pi)
INV_TWO_PI = wp.constant(0.5 / math.pi)
INV_FOUR_PI = wp.constant(0.25 / math.pi)
PI_OVER_2 = wp.constant(0.5 * math.pi)
PI_OVER_4 = wp.constant(0.25 * math.pi)
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


# ================================================================================================================
# Warp: frames and basic warps
# ================================================================================================================


@wp.func
def frame_from_normal(n: wp.vec3) -> wp.mat33:
    """Orthonormal frame with columns (s, t, n) for unit ``n`` (Duff et al. 2017, branchless ONB)."""
    sign = wp.where(n[2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = wp.vec3(1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    t = wp.vec3(b, sign + n[1] * n[1] * a, -n[1])
    return wp.matrix_from_cols(s, t, n)


@wp.func
def to_world(v: wp.vec3, n: wp.vec3) -> wp.vec3:
    """Local (z = n) to world."""
    return frame_from_normal(n) * v


@wp.func
def to_local(v: wp.vec3, n: wp.vec3) -> wp.vec3:
    """World to local (z = n)."""
    return wp.transpose(frame_from_normal(n)) * v


@wp.func
def square_to_uniform_disk_concentric(u: wp.vec2) -> wp.vec2:
    """Shirley-Chiu concentric map of [0,1)^2 onto the unit disk (area-preserving, low distortion)."""
    # Without branches: where |ox| > |oy| the angle is phi = pi/4 oy/ox, else pi/2 - phi with phi = pi/4 ox/oy, whose
    # cosine and sine are phi's sine and cosine. |phi| <= pi/4 either way: the polynomials need no range reduction.
    # (The branchy form was 2.9 % of a depth-of-field render in perf, this one 2.0 %; the lens, diffuse bounces and
    # disk lights all come through here.)
    ox = 2.0 * u[0] - 1.0
    oy = 2.0 * u[1] - 1.0
    wide = wp.abs(ox) > wp.abs(oy)
    r = wp.where(wide, ox, oy)
    phi = PI_OVER_4 * (wp.where(wide, oy, ox) / wp.where(r == 0.0, 1.0, r))  # 0 at the centre, where r = 0
    s, c = _sin_cos_quarter(phi)
    return wp.where(wide, wp.vec2(r * c, r * s), wp.vec2(r * s, r * c))


@wp.func
def square_to_uniform_disk_concentric_pdf(p: wp.vec2) -> float:
    return wp.where(wp.dot(p, p) <= 1.0, INV_PI, 0.0)


@wp.func
def square_to_cosine_hemisphere(u: wp.vec2) -> wp.vec3:
    """Malley's method: concentric disk lifted to the z-up hemisphere; density cos(theta)/pi."""
    d = square_to_uniform_disk_concentric(u)
    z = wp.sqrt(wp.max(0.0, 1.0 - wp.dot(d, d)))
    return wp.vec3(d[0], d[1], z)


@wp.func
def square_to_cosine_hemisphere_pdf(v: wp.vec3) -> float:
    return wp.max(v[2], 0.0) * INV_PI


@wp.func
def square_to_uniform_sphere(u: wp.vec2) -> wp.vec3:
    z = 1.0 - 2.0 * u[0]
    r = wp.sqrt(wp.max(0.0, 1.0 - z * z))
    sp, cp = sin_cos(TWO_PI * u[1])
    return wp.vec3(r * cp, r * sp, z)


@wp.func
def square_to_uniform_sphere_pdf(v: wp.vec3) -> float:
    return INV_FOUR_PI


@wp.func
def square_to_uniform_hemisphere(u: wp.vec2) -> wp.vec3:
    z = u[0]
    r = wp.sqrt(wp.max(0.0, 1.0 - z * z))
    sp, cp = sin_cos(TWO_PI * u[1])
    return wp.vec3(r * cp, r * sp, z)


@wp.func
def square_to_uniform_hemisphere_pdf(v: wp.vec3) -> float:
    return wp.where(v[2] >= 0.0, INV_TWO_PI, 0.0)


@wp.func
def square_to_uniform_cone(u: wp.vec2, cos_theta_max: float) -> wp.vec3:
    """Uniform over the directions within ``acos(cos_theta_max)`` of +z (stable for tiny cones)."""
    one_minus_cos = u[0] * (1.0 - cos_theta_max)
    cos_t = 1.0 - one_minus_cos
    sin_t = wp.sqrt(wp.max(0.0, one_minus_cos * (2.0 - one_minus_cos)))
    sp, cp = sin_cos(TWO_PI * u[1])
    return wp.vec3(sin_t * cp, sin_t * sp, cos_t)


@wp.func
def square_to_uniform_cone_pdf(v: wp.vec3, cos_theta_max: float) -> float:
    if cos_theta_max >= 1.0 or v[2] < cos_theta_max:
        return 0.0
    return INV_TWO_PI / (1.0 - cos_theta_max)


@wp.func
def square_to_uniform_triangle(u: wp.vec2) -> wp.vec2:
    """Area-uniform barycentrics (b0, b1) (Heitz 2019); b2 = 1 - b0 - b1."""
    b0 = 0.0
    b1 = 0.0
    if u[0] < u[1]:
        b0 = 0.5 * u[0]
        b1 = u[1] - b0
    else:
        b1 = 0.5 * u[1]
        b0 = u[0] - b1
    return wp.vec2(b0, b1)


@wp.func
def square_to_uniform_triangle_pdf(b: wp.vec2) -> float:
    if b[0] < 0.0 or b[1] < 0.0 or b[0] + b[1] > 1.0:
        return 0.0
    return 2.0


@wp.func
def sample_tent(u: float) -> float:
    """Tent on [0, 1] peaked at 0.5 (density 4x, then 4(1 - x)): the temporal 'triangle' shutter filter."""
    if u < 0.5:
        return wp.sqrt(0.5 * u)
    return 1.0 - wp.sqrt(0.5 * (1.0 - u))


@wp.func
def sample_tent_pdf(x: float) -> float:
    if x < 0.0 or x > 1.0:
        return 0.0
    return 4.0 * wp.min(x, 1.0 - x)


# ================================================================================================================
# Warp: light geometry
# ================================================================================================================


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
def _sin_cos_quarter(r: float):
    """(sin r, cos r) for |r| <= pi/4: Cephes' single-precision polynomials."""
    z = r * r
    sr = ((-1.9515295891e-4 * z + 8.3321608736e-3) * z - 1.6666654611e-1) * z * r + r
    cr = ((2.443315711809948e-5 * z - 1.388731625493765e-3) * z + 4.166664568298827e-2) * z * z - 0.5 * z + 1.0
    return sr, cr


@wp.func
def sin_cos(x: float):
    """(sin x, cos x) for |x| up to 100, within 1e-7: Cody-Waite reduction by pi/2 (three-part constant)
    and Cephes' single-precision polynomials on [-pi/4, pi/4]. The sampling routines' angles are all of this kind;
    glibc's sincosf call was 4.5 % of a Cornell-box sample."""
    k = wp.floor(x * 0.63661977236758134 + 0.5)  # nearest multiple of pi/2
    r = ((x - k * 1.5703125) - k * 4.837512969970703125e-4) - k * 7.54978995489188216e-8
    sr, cr = _sin_cos_quarter(r)
    q = int(k) & 3
    s = wp.where(q == 0, sr, wp.where(q == 1, cr, wp.where(q == 2, -sr, -cr)))
    c = wp.where(q == 0, cr, wp.where(q == 1, -sr, wp.where(q == 2, -cr, sr)))
    return s, c


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
# float), so the same bits (tested against ``_sph_rect_angles_reference``). The angles were a quarter of the
# rectangle light's sampling, itself 16 % of a gloss sample.
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
    The four lanes in vector code (``_sph_rect_lanes``), the same bits as ``_sph_rect_angles_reference``.
    """
    lanes = _sph_rect_lanes(x0, y0, z0, x1, y1)
    g01 = lanes[0]
    g23 = lanes[1]
    solid_angle = g01 + g23 - TWO_PI
    if z0 == 0.0:
        solid_angle = 0.0
    return g01, g23, -y0 / lanes[2], y1 / lanes[3], solid_angle


@wp.func
def _sph_rect_angles_reference(x0: float, y0: float, z0: float, x1: float, y1: float):
    """``_sph_rect_angles`` in Warp's scalar code."""
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


# ================================================================================================================
# NumPy twins (float64, vectorised over the leading axes; geometry broadcasts)
# ================================================================================================================


class NpLightSample(NamedTuple):
    """NumPy twin of ``LightSampleGeom`` (arrays of shape (..., 3) or (...))."""

    dir: np.ndarray
    dist: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    pdf: np.ndarray


def _f(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _dot(a, b) -> np.ndarray:
    return np.sum(a * b, axis=-1)


def _norm(a) -> np.ndarray:
    return np.sqrt(_dot(a, a))


def _normalize(a) -> np.ndarray:
    n = _norm(a)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, a / np.where(n > 0, n, 1.0), 0.0)


def np_frame_from_normal(n) -> np.ndarray:
    """(..., 3, 3) frames with columns (s, t, n)."""
    n = _f(n)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    s = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    t = np.stack([b, sign + y * y * a, -y], axis=-1)
    return np.stack([s, t, n], axis=-1)


def np_to_world(v, n) -> np.ndarray:
    return np.einsum("...ij,...j->...i", np_frame_from_normal(n), _f(v))


def np_square_to_uniform_disk_concentric(u) -> np.ndarray:
    u = _f(u)
    ox, oy = 2.0 * u[..., 0] - 1.0, 2.0 * u[..., 1] - 1.0
    big = np.abs(ox) > np.abs(oy)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(big, ox, oy)
        theta = np.where(big, np.pi / 4 * (oy / ox), np.pi / 2 - np.pi / 4 * (ox / oy))
    theta = np.where((ox == 0) & (oy == 0), 0.0, theta)
    r = np.where((ox == 0) & (oy == 0), 0.0, r)
    return np.stack([r * np.cos(theta), r * np.sin(theta)], axis=-1)


def np_square_to_uniform_disk_concentric_pdf(p) -> np.ndarray:
    p = _f(p)
    return np.where(_dot(p, p) <= 1.0, 1.0 / np.pi, 0.0)


def np_square_to_cosine_hemisphere(u) -> np.ndarray:
    d = np_square_to_uniform_disk_concentric(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - _dot(d, d)))
    return np.concatenate([d, z[..., None]], axis=-1)


def np_square_to_cosine_hemisphere_pdf(v) -> np.ndarray:
    return np.maximum(_f(v)[..., 2], 0.0) / np.pi


def _np_spherical(sin_t, cos_t, phi) -> np.ndarray:
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)


def np_square_to_uniform_sphere(u) -> np.ndarray:
    u = _f(u)
    z = 1.0 - 2.0 * u[..., 0]
    return _np_spherical(np.sqrt(np.maximum(0.0, 1.0 - z * z)), z, 2 * np.pi * u[..., 1])


def np_square_to_uniform_sphere_pdf(v) -> np.ndarray:
    return np.full(_f(v).shape[:-1], 1.0 / (4 * np.pi))


def np_square_to_uniform_hemisphere(u) -> np.ndarray:
    u = _f(u)
    z = u[..., 0]
    return _np_spherical(np.sqrt(np.maximum(0.0, 1.0 - z * z)), z, 2 * np.pi * u[..., 1])


def np_square_to_uniform_hemisphere_pdf(v) -> np.ndarray:
    return np.where(_f(v)[..., 2] >= 0.0, 1.0 / (2 * np.pi), 0.0)


def np_square_to_uniform_cone(u, cos_theta_max) -> np.ndarray:
    u = _f(u)
    omc = u[..., 0] * (1.0 - _f(cos_theta_max))
    sin_t = np.sqrt(np.maximum(0.0, omc * (2.0 - omc)))
    return _np_spherical(sin_t, 1.0 - omc, 2 * np.pi * u[..., 1])


def np_square_to_uniform_cone_pdf(v, cos_theta_max) -> np.ndarray:
    c = _f(cos_theta_max)
    with np.errstate(divide="ignore"):
        val = 1.0 / (2 * np.pi * (1.0 - c))
    return np.where((c < 1.0) & (_f(v)[..., 2] >= c), val, 0.0)


def np_square_to_uniform_triangle(u) -> np.ndarray:
    u = _f(u)
    lo = u[..., 0] < u[..., 1]
    b0 = np.where(lo, 0.5 * u[..., 0], u[..., 0] - 0.5 * u[..., 1])
    b1 = np.where(lo, u[..., 1] - 0.5 * u[..., 0], 0.5 * u[..., 1])
    return np.stack([b0, b1], axis=-1)


def np_square_to_uniform_triangle_pdf(b) -> np.ndarray:
    b = _f(b)
    inside = (b[..., 0] >= 0) & (b[..., 1] >= 0) & (b[..., 0] + b[..., 1] <= 1.0)
    return np.where(inside, 2.0, 0.0)


def np_sample_tent(u) -> np.ndarray:
    u = _f(u)
    return np.where(u < 0.5, np.sqrt(0.5 * u), 1.0 - np.sqrt(0.5 * np.maximum(0.0, 1.0 - u)))


def np_sample_tent_pdf(x) -> np.ndarray:
    x = _f(x)
    return np.where((x >= 0) & (x <= 1), 4.0 * np.minimum(x, 1.0 - x), 0.0)


# ---- light geometry ---------------------------------------------------------------------------------------------


def _np_area_sample(p_ref, point, normal, area) -> NpLightSample:
    d = point - p_ref
    dist2 = _dot(d, d)
    dist = np.sqrt(dist2)
    with np.errstate(invalid="ignore", divide="ignore"):
        dirn = np.where(dist[..., None] > 0, d / np.where(dist > 0, dist, 1.0)[..., None], 0.0)
        cos_l = np.abs(_dot(normal, dirn))
        pdf = np.where((cos_l > 0) & (dist2 > 0), dist2 / (cos_l * area), 0.0)
    normal = np.broadcast_to(normal, point.shape)
    return NpLightSample(dirn, dist, point, normal, pdf)


def _np_area_pdf(t, dirn, normal, area) -> np.ndarray:
    cos_l = np.abs(_dot(normal, dirn))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cos_l > 0, t * t / (cos_l * area), 0.0)


def _np_angle_between(a, b) -> np.ndarray:
    return np.where(
        _dot(a, b) < 0,
        np.pi - 2.0 * np.arcsin(np.clip(0.5 * _norm(a + b), -1, 1)),
        2.0 * np.arcsin(np.clip(0.5 * _norm(b - a), -1, 1)),
    )


def _np_rect_local(p_ref, corner, edge_u, edge_v):
    exl, eyl = _norm(edge_u), _norm(edge_v)
    ex, ey = edge_u / exl[..., None], edge_v / eyl[..., None]
    ez = np.cross(ex, ey)
    d = corner - p_ref
    x0, y0, z0 = _dot(d, ex), _dot(d, ey), _dot(d, ez)
    flip = z0 > 0
    ez = np.where(flip[..., None], -ez, ez)
    z0 = np.where(flip, -z0, z0)
    return ex, ey, ez, x0, y0, z0, x0 + exl, y0 + eyl


def _np_sph_rect_angles(x0, y0, z0, x1, y1):
    def v(a, b):
        return np.stack(np.broadcast_arrays(a, b, z0), axis=-1)

    v00, v01, v10, v11 = v(x0, y0), v(x0, y1), v(x1, y0), v(x1, y1)
    n0 = _normalize(np.cross(v00, v10))
    n1 = _normalize(np.cross(v10, v11))
    n2 = _normalize(np.cross(v11, v01))
    n3 = _normalize(np.cross(v01, v00))
    g01 = _np_angle_between(-n0, n1) + _np_angle_between(-n1, n2)
    g23 = _np_angle_between(-n2, n3) + _np_angle_between(-n3, n0)
    solid_angle = np.where(z0 == 0, 0.0, g01 + g23 - 2 * np.pi)
    return g01, g23, n0[..., 2], n2[..., 2], solid_angle


def _np_use_sph(solid_angle) -> np.ndarray:
    return (solid_angle >= SPH_RECT_MIN_SOLID_ANGLE) & (solid_angle <= SPH_RECT_MAX_SOLID_ANGLE)


def np_rect_solid_angle(p_ref, corner, edge_u, edge_v) -> np.ndarray:
    """Solid angle (sr) of the rectangle seen from p_ref, as computed for spherical-rectangle sampling."""
    _, _, _, x0, y0, z0, x1, y1 = _np_rect_local(_f(p_ref), _f(corner), _f(edge_u), _f(edge_v))
    return _np_sph_rect_angles(x0, y0, z0, x1, y1)[4]


def np_sample_rect(p_ref, corner, edge_u, edge_v, u) -> NpLightSample:
    p_ref, corner, edge_u, edge_v, u = map(_f, (p_ref, corner, edge_u, edge_v, u))
    n = np.cross(edge_u, edge_v)
    area = _norm(n)
    normal = n / area[..., None]
    ex, ey, ez, x0, y0, z0, x1, y1 = _np_rect_local(p_ref, corner, edge_u, edge_v)
    g01, g23, b0, b1, solid_angle = _np_sph_rect_angles(x0, y0, z0, x1, y1)
    u0, u1 = u[..., 0], u[..., 1]
    by_area = _np_area_sample(p_ref, corner + u0[..., None] * edge_u + u1[..., None] * edge_v, normal, area)
    with np.errstate(invalid="ignore", divide="ignore"):
        au = u0 * (g01 - 2 * np.pi) + (u0 - 1.0) * g23
        fu = (np.cos(au) * b0 - b1) / np.sin(au)
        e = np.maximum(fu * fu + b0 * b0 - 1.0, 1e-30)  # pbrt's cu and xu in one step, as sample_rect
        xu = np.clip(np.where(fu < 0, z0, -z0) / np.sqrt(e), x0, x1)
        dd2 = xu * xu + z0 * z0
        dd = np.sqrt(dd2)
        h0 = y0 / np.sqrt(dd2 + y0 * y0)
        h1 = y1 / np.sqrt(dd2 + y1 * y1)
        hv = h0 + u1 * (h1 - h0)
        hv2 = hv * hv
        yv = np.where(hv2 < 1.0 - 1e-6, hv * dd / np.sqrt(np.maximum(1e-300, 1.0 - hv2)), y1)
        yv = np.clip(yv, y0, y1)
        d = xu[..., None] * ex + yv[..., None] * ey + z0[..., None] * ez
        dist = _norm(d)
        sph = NpLightSample(d / dist[..., None], dist, p_ref + d, np.broadcast_to(normal, d.shape),
                            np.broadcast_to(1.0 / solid_angle, dist.shape))
    use = _np_use_sph(solid_angle)
    return NpLightSample(*(np.where(use[..., None] if a.ndim > use.ndim else use, a, b)
                           for a, b in zip(sph, by_area)))


def _np_plane_hit(p_ref, dirn, origin, normal):
    denom = _dot(dirn, normal)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = _dot(origin - p_ref, normal) / denom
    ok = (denom != 0) & (t > 0)
    t = np.where(ok, t, 0.0)
    return ok, t, p_ref + t[..., None] * dirn - origin


def np_rect_pdf(p_ref, dirn, corner, edge_u, edge_v) -> np.ndarray:
    p_ref, dirn, corner, edge_u, edge_v = map(_f, (p_ref, dirn, corner, edge_u, edge_v))
    n = np.cross(edge_u, edge_v)
    area = _norm(n)
    normal = n / area[..., None]
    ok, t, q = _np_plane_hit(p_ref, dirn, corner, normal)
    a, b = _dot(q, edge_u) / _dot(edge_u, edge_u), _dot(q, edge_v) / _dot(edge_v, edge_v)
    ok &= (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
    solid_angle = np_rect_solid_angle(p_ref, corner, edge_u, edge_v)
    with np.errstate(divide="ignore"):
        pdf = np.where(_np_use_sph(solid_angle), 1.0 / solid_angle, _np_area_pdf(t, dirn, normal, area))
    return np.where(ok, pdf, 0.0)


def np_sample_disk_light(p_ref, center, normal, radius, u) -> NpLightSample:
    p_ref, center, normal, radius = map(_f, (p_ref, center, normal, radius))
    d = radius[..., None] * np_square_to_uniform_disk_concentric(u)
    local = np.concatenate([d, np.zeros(d.shape[:-1] + (1,))], axis=-1)
    point = center + np_to_world(local, np.broadcast_to(normal, local.shape))
    return _np_area_sample(p_ref, point, normal, np.pi * radius * radius)


def np_disk_light_pdf(p_ref, dirn, center, normal, radius) -> np.ndarray:
    p_ref, dirn, center, normal, radius = map(_f, (p_ref, dirn, center, normal, radius))
    ok, t, q = _np_plane_hit(p_ref, dirn, center, normal)
    ok &= _dot(q, q) <= radius * radius
    return np.where(ok, _np_area_pdf(t, dirn, normal, np.pi * radius * radius), 0.0)


def _np_sphere_cone(p_ref, center, radius):
    dc = center - p_ref
    dist_c = _norm(dc)
    sin2_max = (radius / dist_c) ** 2
    cos_max = np.sqrt(np.maximum(0.0, 1.0 - sin2_max))
    return dc / dist_c[..., None], dist_c, cos_max, sin2_max / (1.0 + cos_max)


def np_sample_sphere_light(p_ref, center, radius, u) -> NpLightSample:
    p_ref, center, radius, u = map(_f, (p_ref, center, radius, u))
    dc = center - p_ref
    inside = _dot(dc, dc) <= radius * radius
    n_area = np_square_to_uniform_sphere(u)
    by_area = _np_area_sample(p_ref, center + radius[..., None] * n_area, n_area, 4 * np.pi * radius * radius)
    with np.errstate(invalid="ignore", divide="ignore"):
        wc, dist_c, cos_max, omc_max = _np_sphere_cone(p_ref, center, radius)
        sin_max = radius / dist_c
        omc = u[..., 0] * omc_max
        cos_t = 1.0 - omc
        sin2_t = omc * (2.0 - omc)
        cos_alpha = sin2_t / sin_max + cos_t * np.sqrt(np.maximum(0.0, 1.0 - sin2_t / (sin_max * sin_max)))
        sin_alpha = np.sqrt(np.maximum(0.0, 1.0 - cos_alpha * cos_alpha))
        w = _np_spherical(sin_alpha, cos_alpha, 2 * np.pi * u[..., 1])
        n = -np_to_world(w, np.broadcast_to(wc, w.shape))
        point = center + radius[..., None] * n
        d = point - p_ref
        dist = _norm(d)
        cone = NpLightSample(d / dist[..., None], dist, point, n,
                             np.broadcast_to(1.0 / (2 * np.pi * omc_max), dist.shape))
    return NpLightSample(*(np.where(inside[..., None] if a.ndim > np.ndim(inside) else inside, a, b)
                           for a, b in zip(by_area, cone)))


def np_sphere_light_pdf(p_ref, dirn, center, radius) -> np.ndarray:
    p_ref, dirn, center, radius = map(_f, (p_ref, dirn, center, radius))
    dc = center - p_ref
    r2 = radius * radius
    inside = _dot(dc, dc) <= r2
    b = _dot(dirn, dc)
    t = b + np.sqrt(np.maximum(0.0, b * b - (_dot(dc, dc) - r2)))
    n = _normalize(p_ref + t[..., None] * dirn - center)
    pdf_in = _np_area_pdf(t, dirn, n, 4 * np.pi * r2)
    with np.errstate(invalid="ignore", divide="ignore"):
        wc, dist_c, cos_max, omc_max = _np_sphere_cone(p_ref, center, radius)
        c = np.cross(dirn, wc)
        in_cone = (_dot(dirn, wc) > 0) & (_dot(c, c) <= (radius / dist_c) ** 2)
        pdf_out = np.where(in_cone, 1.0 / (2 * np.pi * omc_max), 0.0)
    return np.where(inside, pdf_in, pdf_out)


def np_sample_cylinder_light(p_ref, center, axis, length, radius, u) -> NpLightSample:
    p_ref, center, axis, length, radius, u = map(_f, (p_ref, center, axis, length, radius, u))
    f = np_frame_from_normal(axis)
    phi = 2 * np.pi * u[..., 1]
    n = np.cos(phi)[..., None] * f[..., :, 0] + np.sin(phi)[..., None] * f[..., :, 1]
    point = center + ((u[..., 0] - 0.5) * length)[..., None] * axis + radius[..., None] * n
    return _np_area_sample(p_ref, point, n, 2 * np.pi * radius * length)


def np_cylinder_hits(p_ref, dirn, center, axis, length, radius):
    """Both crossings of the ray with the lateral surface: (t0, ok0, t1, ok1, |cos_light|), t0 <= t1.

    ``|cos_light|`` (the same at both crossings) is ``sqrt(disc) / radius``; ``dirn`` must be unit.
    """
    p_ref, dirn, center, axis, length, radius = map(_f, (p_ref, dirn, center, axis, length, radius))
    o = p_ref - center
    o_perp = o - _dot(o, axis)[..., None] * axis
    d_perp = dirn - _dot(dirn, axis)[..., None] * axis
    a = _dot(d_perp, d_perp)
    with np.errstate(invalid="ignore", divide="ignore"):
        t_mid = -_dot(o_perp, d_perp) / a
        c = o_perp + t_mid[..., None] * d_perp
        disc = a * (radius * radius - _dot(c, c))
        valid = (a > 0) & (disc > 0)
        half_chord = np.sqrt(np.maximum(disc, 0.0)) / a
        cos_l = np.sqrt(np.maximum(disc, 0.0)) / radius
    out = []
    for t in (t_mid - half_chord, t_mid + half_chord):
        ok = valid & (t > 0) & (np.abs(_dot(o + t[..., None] * dirn, axis)) <= 0.5 * length)
        out += [np.where(ok, t, 0.0), ok]
    return (*out, np.where(valid, cos_l, 0.0))


def np_cylinder_light_pdf(p_ref, dirn, center, axis, length, radius) -> np.ndarray:
    t0, ok0, t1, ok1, cos_l = np_cylinder_hits(p_ref, dirn, center, axis, length, radius)
    area = 2 * np.pi * _f(radius) * _f(length)
    t = np.where(ok0, t0, t1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok0 | ok1, t * t / (cos_l * area), 0.0)


def np_sample_triangle_light(p_ref, p0, p1, p2, u) -> NpLightSample:
    p_ref, p0, p1, p2 = map(_f, (p_ref, p0, p1, p2))
    b = np_square_to_uniform_triangle(u)
    point = b[..., 0:1] * p0 + b[..., 1:2] * p1 + (1.0 - b[..., 0:1] - b[..., 1:2]) * p2
    n = np.cross(p1 - p0, p2 - p0)
    len_n = _norm(n)
    return _np_area_sample(p_ref, point, n / len_n[..., None], 0.5 * len_n)


def np_triangle_light_pdf(p_ref, dirn, p0, p1, p2) -> np.ndarray:
    p_ref, dirn, p0, p1, p2 = map(_f, (p_ref, dirn, p0, p1, p2))
    e1, e2 = p1 - p0, p2 - p0
    pv = np.cross(dirn, e2)
    det = _dot(e1, pv)
    with np.errstate(invalid="ignore", divide="ignore"):
        inv_det = 1.0 / det
        tv = p_ref - p0
        bu = _dot(tv, pv) * inv_det
        qv = np.cross(tv, e1)
        bv = _dot(dirn, qv) * inv_det
        t = _dot(e2, qv) * inv_det
    ok = (det != 0) & (bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (t > 0)
    n = np.cross(e1, e2)
    len_n = _norm(n)
    return np.where(ok, _np_area_pdf(np.where(ok, t, 0.0), dirn, n / len_n[..., None], 0.5 * len_n), 0.0)
