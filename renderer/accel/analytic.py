"""Ray intersection with the exact implicit prims (``scene.analytic``), centred at the object-space origin.

The walks call ``shape_hits`` in place of a bottom-level tree for a mesh with ``Geometry.mesh_shape[m] > 0``: the
ray is already in the instance's object space, so a scaled, sheared or moving shape is exact too. Shapes (the
spine along object axis ``axis``, z below its coordinate on it; parameters ``(rb, rt, hh, 0)``):

* SHAPE_SPHERE: |p| = rb;
* SHAPE_FRUSTUM (Cylinder, Cylinder_1, Cone): the side r(z) = rb + (rt - rb) (z + hh) / (2 hh) for |z| <= hh, closed
  by flat caps at z = -hh (radius rb) and z = hh (radius rt); a cone has rt = 0;
* SHAPE_CAPSULE: a cylinder of radius rb over |z| <= hh, closed by hemispheres centred at z = -hh and z = hh.

A point cloud (SHAPE_POINTS, SHAPE_DISCS) is not one shape but a tree of spheres or discs, walked like a mesh
(``intersect.point_hit``).

Every shape is convex: a ray crosses it at most twice. A hit reports which piece it crossed (``part``), from which
``shape_normal`` takes the normal.
"""
from __future__ import annotations

import warp as wp

from renderer.scene.analytic import SHAPE_CODES

BIG = 3.4e38
SHAPE_SPHERE = wp.constant(SHAPE_CODES["sphere"])
SHAPE_FRUSTUM = wp.constant(SHAPE_CODES["frustum"])
SHAPE_CAPSULE = wp.constant(SHAPE_CODES["capsule"])
SHAPE_POINTS = wp.constant(SHAPE_CODES["points"])  # a cloud of spheres: a leaf primitive each (``intersect.point_hit``)
SHAPE_DISCS = wp.constant(SHAPE_CODES["discs"])  # a cloud of discs facing their normals, the same way


@wp.func
def is_cloud(kind: int) -> bool:
    """A mesh of one small shape per point (spheres or discs), walked like a triangle mesh."""
    return kind == SHAPE_POINTS or kind == SHAPE_DISCS
PART_SIDE = wp.constant(0)  # a sphere, a frustum's or a capsule's side
PART_BOTTOM = wp.constant(1)  # the cap (flat or round) at z = -hh
PART_TOP = wp.constant(2)  # the cap at z = +hh


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
def quadratic_roots(a: float, b: float, c: float):
    """Roots (t0, t1), t0 <= t1, of a t^2 + 2 b t + c = 0, BIG for a missing one (a = 0: the one root of the linear
    equation, as when a ray runs parallel to a cone's slant), in the form that does not subtract nearly equal
    numbers."""
    if a == 0.0:
        if b == 0.0:
            return float(BIG), float(BIG)
        return -c / (2.0 * b), float(BIG)
    disc = b * b - a * c
    if disc < 0.0:
        return float(BIG), float(BIG)
    root = wp.sqrt(disc)
    q = wp.where(b >= 0.0, -b - root, -b + root)
    if q == 0.0:
        return float(0.0), float(0.0)
    t0 = c / q
    t1 = q / a
    return wp.min(t0, t1), wp.max(t0, t1)


@wp.func
def _take(t: float, ok: bool, part: int, tmax: float, best: float, best_part: int, n: int):
    """Count a candidate crossing at t in (0, tmax) that lies on its piece (``ok``), and keep the nearest."""
    if ok and t > 0.0 and t < tmax:
        if t < best:
            return t, part, n + 1
        return best, best_part, n + 1
    return best, best_part, n


@wp.func
def _axis_vector(axis: int):
    return wp.vec3(wp.where(axis == 0, 1.0, 0.0), wp.where(axis == 1, 1.0, 0.0), wp.where(axis == 2, 1.0, 0.0))


@wp.func
def _frustum_hits(ro: wp.vec3, rd: wp.vec3, axis: int, rb: float, rt: float, hh: float, tmax: float):
    oz = ro[axis]
    dz = rd[axis]
    orr = wp.dot(ro, ro) - oz * oz  # squared distance from the spine, and its expansion along the ray
    odr = wp.dot(ro, rd) - oz * dz
    drr = wp.dot(rd, rd) - dz * dz
    alpha = 0.5 * (rb + rt)  # the radius at z = 0
    beta = (rt - rb) / (2.0 * hh)  # its change per unit of z
    r_o = alpha + beta * oz
    t0, t1 = quadratic_roots(drr - beta * beta * dz * dz, odr - beta * dz * r_o, orr - r_o * r_o)
    best = float(BIG)
    part = int(PART_SIDE)
    n = int(0)
    z0 = oz + t0 * dz
    z1 = oz + t1 * dz
    # on the side: within the height, and on the shape's nappe of the double cone (r(z) >= 0)
    best, part, n = _take(t0, wp.abs(z0) <= hh and alpha + beta * z0 >= 0.0, PART_SIDE, tmax, best, part, n)
    best, part, n = _take(t1, wp.abs(z1) <= hh and alpha + beta * z1 >= 0.0, PART_SIDE, tmax, best, part, n)
    if dz != 0.0:
        tb = (-hh - oz) / dz
        best, part, n = _take(tb, orr + tb * (2.0 * odr + tb * drr) <= rb * rb and rb > 0.0, PART_BOTTOM, tmax,
                              best, part, n)
        tt = (hh - oz) / dz
        best, part, n = _take(tt, orr + tt * (2.0 * odr + tt * drr) <= rt * rt and rt > 0.0, PART_TOP, tmax,
                              best, part, n)
    return best, part, n


@wp.func
def _capsule_hits(ro: wp.vec3, rd: wp.vec3, axis: int, r: float, hh: float, tmax: float):
    oz = ro[axis]
    dz = rd[axis]
    t0, t1 = quadratic_roots(wp.dot(rd, rd) - dz * dz, wp.dot(ro, rd) - oz * dz, wp.dot(ro, ro) - oz * oz - r * r)
    best = float(BIG)
    part = int(PART_SIDE)
    n = int(0)
    best, part, n = _take(t0, wp.abs(oz + t0 * dz) <= hh, PART_SIDE, tmax, best, part, n)
    best, part, n = _take(t1, wp.abs(oz + t1 * dz) <= hh, PART_SIDE, tmax, best, part, n)
    e = _axis_vector(axis) * hh
    b0, b1 = sphere_roots(ro + e, rd, r)  # the hemisphere centred at z = -hh: its half below
    best, part, n = _take(b0, oz + b0 * dz < -hh, PART_BOTTOM, tmax, best, part, n)
    best, part, n = _take(b1, oz + b1 * dz < -hh, PART_BOTTOM, tmax, best, part, n)
    u0, u1 = sphere_roots(ro - e, rd, r)  # the one centred at z = hh: its half above
    best, part, n = _take(u0, oz + u0 * dz > hh, PART_TOP, tmax, best, part, n)
    best, part, n = _take(u1, oz + u1 * dz > hh, PART_TOP, tmax, best, part, n)
    return best, part, n


@wp.func
def shape_hits(kind: int, axis: int, prm: wp.vec4, ro: wp.vec3, rd: wp.vec3, tmax: float):
    """(t, part, n) of the object-space ray against a shape over (0, tmax): the nearest crossing (BIG if none), the
    piece it lies on, and how many crossings there are (0, 1 or 2)."""
    if kind == SHAPE_SPHERE:
        t0, t1 = sphere_roots(ro, rd, prm[0])
        best, part, n = _take(t0, True, PART_SIDE, tmax, float(BIG), int(PART_SIDE), int(0))
        return _take(t1, True, PART_SIDE, tmax, best, part, n)
    if kind == SHAPE_FRUSTUM:
        return _frustum_hits(ro, rd, axis, prm[0], prm[1], prm[2], tmax)
    return _capsule_hits(ro, rd, axis, prm[0], prm[2], tmax)


@wp.func
def shape_normal(kind: int, axis: int, prm: wp.vec4, p: wp.vec3, part: int):
    """Outward normal (not unit) of a shape at the object-space point p on piece ``part``."""
    e = _axis_vector(axis)
    z = p[axis]
    if kind == SHAPE_SPHERE:
        return p
    if kind == SHAPE_FRUSTUM:
        if part == PART_BOTTOM:
            return -e
        if part == PART_TOP:
            return e
        beta = (prm[1] - prm[0]) / (2.0 * prm[2])
        # the gradient of |p - z e|^2 - r(z)^2, halved
        return p - e * z - e * (beta * (0.5 * (prm[0] + prm[1]) + beta * z))
    if part == PART_BOTTOM:
        return p + e * prm[2]
    if part == PART_TOP:
        return p - e * prm[2]
    return p - e * z
