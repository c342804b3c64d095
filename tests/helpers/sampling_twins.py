"""NumPy twins of the warps (``renderer.sampling.warps``) and the light shapes' samplers
(``renderer.lights.shapes``), for the tests: float64, vectorised over a leading batch axis, named ``np_X`` /
``np_X_pdf`` after the Warp ``X`` / ``X_pdf``. The tests compare them against the Warp ``@wp.func``s and feed them
to the chi-square harness.

The light samplers' twins return ``NpLightSample`` (the fields of ``LightSampleGeom``, as arrays); geometry
arguments broadcast against the batch. Extra helpers: ``np_rect_solid_angle`` (the strategy switch of
``sample_rect``) and ``np_cylinder_hits`` (both crossings of a ray with a cylinder).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from renderer.lights.shapes import SPH_RECT_MAX_SOLID_ANGLE, SPH_RECT_MIN_SOLID_ANGLE


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
