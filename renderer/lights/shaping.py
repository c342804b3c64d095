"""usdLux ShapingAPI: how a light's emission varies with direction (cone, focus, focus tint, IES profile).

All by the formulas of usdLux's schema.usda, in the light's frame at the sample's time; the light's primary
axis is its local -Z and the emission direction points from the light towards the lit point:

    theta_off = acos(axis . dir)
    cone:   0 beyond theta_cutoff = radians(cone:angle); else 1 - smoothstep(theta_smoothStart, theta_cutoff,
            theta_off) with theta_smoothStart = lerp(softness, theta_cutoff, 0) = theta_cutoff (1 - softness)
    focus:  focusFactor = |axis . dir|^focus (focus > 0), colour lerp(focusFactor, focusTint, white)
    IES:    the profile at (theta_ies, phi), theta_ies from ``ies:angleScale`` (see ``ies``), divided by the
            profile's power with ``ies:normalize``.

Shaping parameters are keyed at the shutter's open and close (``shape0`` / ``shape1``) and blended linearly by
the sample's time, so an animated cone blurs. ``shaping_np`` is the NumPy twin the tests and the light
selection use.
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from renderer.lights.ies import IES_PHI, IES_THETA


@wp.func
def _smoothstep(e0: float, e1: float, x: float):
    if x <= e0:
        return 0.0
    if x >= e1:
        return 1.0
    t = (x - e0) / (e1 - e0)
    return t * t * (3.0 - 2.0 * t)


@wp.func
def ies_lookup(table: wp.array(dtype=wp.float32), off: int, theta: float, phi: float):
    """Bilinear candela of the IES grid at ``off`` at theta in [0, pi], phi in radians."""
    if theta < 0.0 or theta > wp.pi:
        return 0.0
    x = theta / wp.pi * float(IES_THETA - 1)
    p = phi / (2.0 * wp.pi)
    p = p - wp.floor(p)
    y = p * float(IES_PHI - 1)
    i = wp.min(int(x), IES_THETA - 2)
    j = wp.min(int(y), IES_PHI - 2)
    fx = x - float(i)
    fy = y - float(j)
    base = off + i * IES_PHI + j
    a = table[base] * (1.0 - fy) + table[base + 1] * fy
    b = table[base + IES_PHI] * (1.0 - fy) + table[base + IES_PHI + 1] * fy
    return a * (1.0 - fx) + b * fx


@wp.func
def shaping_eval(shape: wp.vec4, tint: wp.vec3, ies_table: wp.array(dtype=wp.float32), ies_off: int,
                 ies: wp.vec2, dl: wp.vec3):
    """The shaping colour for a unit emission direction ``dl`` in the light's frame.

    shape = (cone angle in radians, cone softness, focus, unused); ies = (angleScale, 1 / power or 1).
    """
    cos_off = wp.clamp(-dl[2], -1.0, 1.0)
    theta = wp.acos(cos_off)
    cutoff = wp.clamp(shape[0], 0.0, wp.pi)
    if theta > cutoff:
        return wp.vec3(0.0)
    f = float(1.0)
    soft = wp.clamp(shape[1], 0.0, 1.0)
    if soft > 0.0:
        f = 1.0 - _smoothstep(cutoff * (1.0 - soft), cutoff, theta)
    c = wp.vec3(f)
    if shape[2] > 0.0:
        ff = wp.pow(wp.abs(cos_off), shape[2])
        c = wp.cw_mul(c, tint + (wp.vec3(1.0) - tint) * ff)
    if ies_off >= 0:
        t = theta
        if ies[0] > 0.0:
            t = theta / ies[0]
        elif ies[0] < 0.0:
            t = (theta - wp.pi) / -ies[0] + wp.pi
        c = c * (ies_lookup(ies_table, ies_off, t, wp.atan2(dl[1], dl[0])) * ies[1])
    return c


def shaping_np(shape, tint, ies_grid, ies, dl: np.ndarray) -> np.ndarray:
    """NumPy twin of ``shaping_eval`` for directions ``dl`` (N, 3) in the light's frame: (N, 3) colours."""
    dl = np.asarray(dl, np.float64)
    cos_off = np.clip(-dl[:, 2], -1.0, 1.0)
    theta = np.arccos(cos_off)
    cutoff = min(max(shape[0], 0.0), math.pi)
    soft = min(max(shape[1], 0.0), 1.0)
    f = np.ones_like(theta)
    if soft > 0:
        e0 = cutoff * (1 - soft)
        t = np.clip((theta - e0) / max(cutoff - e0, 1e-30), 0.0, 1.0)
        f = 1.0 - t * t * (3 - 2 * t)
    f = np.where(theta > cutoff, 0.0, f)
    c = np.repeat(f[:, None], 3, 1)
    if shape[2] > 0:
        ff = np.abs(cos_off) ** shape[2]
        tint = np.asarray(tint, np.float64)
        c = c * (tint[None] + (1 - tint[None]) * ff[:, None])
    if ies_grid is not None:
        t = theta
        if ies[0] > 0:
            t = theta / ies[0]
        elif ies[0] < 0:
            t = (theta - math.pi) / -ies[0] + math.pi
        phi = np.mod(np.arctan2(dl[:, 1], dl[:, 0]), 2 * math.pi)
        x = t / math.pi * (IES_THETA - 1)
        y = phi / (2 * math.pi) * (IES_PHI - 1)
        i = np.clip(x.astype(int), 0, IES_THETA - 2)
        j = np.clip(y.astype(int), 0, IES_PHI - 2)
        fx, fy = x - i, y - j
        g = np.asarray(ies_grid, np.float64)
        a = g[i, j] * (1 - fy) + g[i, j + 1] * fy
        b = g[i + 1, j] * (1 - fy) + g[i + 1, j + 1] * fy
        v = np.where((t < 0) | (t > math.pi), 0.0, a * (1 - fx) + b * fx) * ies[1]
        c = c * v[:, None]
    return c


def mean_shaping(shape, tint, ies_grid, ies, cosine_weighted: bool, n: int = 4096) -> float:
    """Average shaping luminance over the directions a light emits into (uniform sphere, or the cosine-weighted
    front hemisphere of a one-sided light): the fraction of its power shaping lets out, for light selection."""
    rng = np.random.default_rng(7)
    u = rng.random((n, 2))
    if cosine_weighted:
        r, phi = np.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
        z = -np.sqrt(np.maximum(0.0, 1 - u[:, 0]))
    else:
        z = 1 - 2 * u[:, 0]
        r, phi = np.sqrt(np.maximum(0.0, 1 - z * z)), 2 * math.pi * u[:, 1]
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    c = shaping_np(shape, tint, ies_grid, ies, d)
    return float((c @ np.array([0.2126, 0.7152, 0.0722])).mean())


def mean_face_shaping(shape, tint, ies_grid, ies, normals, weights, two_sided: bool, n: int = 4096) -> float:
    """``mean_shaping`` of an emitting mesh: its faces (unit ``normals`` (N, 3) in the light's frame) drawn by
    ``weights`` (their power), directions cosine-weighted about each face's normal (either side of a two-sided
    mesh): the share of its power the shaping about the light's -Z lets out, whichever way its faces look."""
    rng = np.random.default_rng(7)
    u = rng.random((n, 4))
    w = np.cumsum(np.asarray(weights, np.float64))
    k = np.minimum(np.searchsorted(w / w[-1], u[:, 0], side="right"), len(w) - 1)
    nrm = np.asarray(normals, np.float64)[k]
    if two_sided:
        nrm = np.where(u[:, 3:] < 0.5, nrm, -nrm)
    helper = np.where(np.abs(nrm[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(helper, nrm)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)  # a degenerate face: no direction
    b = np.cross(nrm, t)
    r, phi = np.sqrt(u[:, 1:2]), 2 * math.pi * u[:, 2:3]
    d = r * np.cos(phi) * t + r * np.sin(phi) * b + np.sqrt(np.maximum(0.0, 1 - r * r)) * nrm
    c = shaping_np(shape, tint, ies_grid, ies, d)
    return float((c @ np.array([0.2126, 0.7152, 0.0722])).mean())
