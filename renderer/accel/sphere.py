"""Ray intersection with an analytic sphere centred at the object-space origin (``scene.analytic``).

The walks call these in place of a bottom-level tree for a mesh with ``Geometry.mesh_sphere[m] > 0``: the ray is
already in the instance's object space, so a scaled, sheared or moving sphere is exact too.
"""
from __future__ import annotations

import warp as wp

BIG = 3.4e38


@wp.func
def sphere_roots(ro: wp.vec3, rd: wp.vec3, r: float):
    """Parameters (t0, t1), t0 <= t1, at which the ray ro + t rd meets the sphere |p| = r, or (BIG, BIG) when it
    misses; rd need not be unit length. The discriminant comes from the ray's closest approach to the centre
    instead of b^2 - a c, whose cancellation loses small spheres far from the origin of the ray, and the roots from
    the form that does not subtract nearly equal numbers (Haines et al., Ray Tracing Gems, ch. 7)."""
    a = wp.dot(rd, rd)
    if a == 0.0:
        return float(BIG), float(BIG)
    b = wp.dot(ro, rd)  # half the linear coefficient: a t^2 + 2 b t + c = 0
    f = ro - rd * (b / a)  # the ray's point closest to the centre
    disc = r * r - wp.dot(f, f)  # (b^2 - a c) / a
    if disc < 0.0:
        return float(BIG), float(BIG)
    root = wp.sqrt(a * disc)
    q = wp.where(b >= 0.0, -b - root, -b + root)
    if q == 0.0:  # b = 0 and a tangent: the ray starts on the sphere, tangent to it
        return float(0.0), float(0.0)
    c = wp.dot(ro, ro) - r * r
    t0 = c / q
    t1 = q / a
    return wp.min(t0, t1), wp.max(t0, t1)


@wp.func
def sphere_closest(ro: wp.vec3, rd: wp.vec3, r: float, tmax: float):
    """The nearest crossing of the sphere in (0, tmax), or BIG."""
    t0, t1 = sphere_roots(ro, rd, r)
    t = wp.where(t0 > 0.0, t0, t1)
    if t <= 0.0 or t >= tmax:
        return float(BIG)
    return t


@wp.func
def sphere_crossings(ro: wp.vec3, rd: wp.vec3, r: float, tmax: float):
    """How many times the segment (0, tmax) of the ray crosses the sphere: 0, 1 or 2."""
    t0, t1 = sphere_roots(ro, rd, r)
    n = int(0)
    if t0 > 0.0 and t0 < tmax:
        n += 1
    if t1 > 0.0 and t1 < tmax:
        n += 1
    return n
