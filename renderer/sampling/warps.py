"""Warps from uniform numbers to shapes and directions, each paired with its density (``square_to_X``,
``square_to_X_pdf``), and the fast ``sin_cos`` their angles go through.

After pbrt-v4 ``util/sampling.h`` and Mitsuba 3 ``warp.py``. Every routine takes its uniform numbers as arguments
(it never owns an RNG), so it can be tested alone and replayed. Every ``X`` has ``X_pdf`` (same name + ``_pdf``);
the tests keep NumPy twins of both (``tests/helpers/sampling_twins.py``) to compare against and to feed the chi-square
harness. The light shapes' samplers, built on these, are in ``renderer.lights.shapes``.

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
"""
from __future__ import annotations

import math

import warp as wp

PI = wp.constant(math.pi)
TWO_PI = wp.constant(2.0 * math.pi)
INV_PI = wp.constant(1.0 / math.pi)
INV_TWO_PI = wp.constant(0.5 / math.pi)
INV_FOUR_PI = wp.constant(0.25 / math.pi)
PI_OVER_4 = wp.constant(0.25 * math.pi)


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
