"""Microfacet building blocks: the GGX (Trowbridge-Reitz) distribution, its visible-normal sampling, Smith masking
and Fresnel reflectance (exact dielectric and Schlick).

After pbrt-v4 ``TrowbridgeReitzDistribution`` / ``FrDielectric`` / ``Refract`` and Mitsuba 3 ``MicrofacetDistribution``.
Isotropic only (UsdPreviewSurface has no anisotropy).

Conventions
-----------
* Every function works in a LOCAL frame whose z axis is the macro-surface normal (use ``warps.to_local``).
* ``alpha`` is the GGX width. UsdPreviewSurface roughness r maps to ``alpha = max(r^2, ALPHA_MIN)``
  (``roughness_to_alpha``); below ``ALPHA_DELTA`` a lobe is a delta (perfect mirror / sharp refraction) and the
  callers branch on ``is_delta(alpha)`` instead of evaluating a 1e8-tall density in float32.
* ``eta`` is a RELATIVE index of refraction: eta_t / eta_i, the index on the far side of the surface over the
  index on the side the direction ``w`` (or ``cos_i``) lies on. Glass seen from air: 1.5; air seen from glass: 1/1.5.
* ``ggx_sample_visible(w, alpha, u)`` needs ``w.z > 0``. It draws a microfacet normal ``wm`` from the distribution
  of normals visible from ``w`` (Heitz 2018), by the spherical-cap method of Dupuy & Benyoub 2023. Its density with
  respect to solid angle of ``wm`` is ``ggx_sample_visible_pdf(w, wm, alpha) = G1(w) max(0, w.wm) D(wm) / w.z``.
* Smith masking is the height-correlated form: ``G2 = 1 / (1 + Lambda(wo) + Lambda(wi))`` (Heitz 2014).

NumPy twins ``np_*`` are float64 and vectorised over leading axes; the tests compare them against the Warp code.
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from renderer.sampling.warps import sin_cos

ALPHA_MIN = 1.0e-4  # smallest GGX alpha used (roughness 0.01)
ALPHA_DELTA = 1.0e-3  # alpha below this is a delta lobe (roughness < ~0.0316)
W_ALPHA_MIN = wp.constant(ALPHA_MIN)
W_ALPHA_DELTA = wp.constant(ALPHA_DELTA)
_INV_PI = wp.constant(1.0 / math.pi)
_TWO_PI = wp.constant(2.0 * math.pi)


# ================================================================================================================
# Warp
# ================================================================================================================


@wp.func
def roughness_to_alpha(roughness: float) -> float:
    """UsdPreviewSurface convention: alpha = roughness^2, clamped to >= ALPHA_MIN."""
    r = wp.clamp(roughness, 0.0, 1.0)
    return wp.max(r * r, W_ALPHA_MIN)


@wp.func
def is_delta(alpha: float) -> bool:
    return alpha < W_ALPHA_DELTA


@wp.func
def ggx_d(wm: wp.vec3, alpha: float) -> float:
    """GGX normal distribution D(wm) (1/sr), normalised so that the integral of D(wm) wm.z over wm is 1."""
    if wm[2] <= 0.0:
        return 0.0
    a2 = alpha * alpha
    sin2 = wm[0] * wm[0] + wm[1] * wm[1]  # accurate near the pole, unlike 1 - cos^2
    t = a2 * wm[2] * wm[2] + sin2
    if t <= 0.0:
        return 0.0
    return a2 * _INV_PI / (t * t)


@wp.func
def ggx_lambda(w: wp.vec3, alpha: float) -> float:
    """Smith Lambda(w) of GGX; depends on |cos theta| only (valid for both hemispheres)."""
    cos2 = w[2] * w[2]
    sin2 = w[0] * w[0] + w[1] * w[1]
    if cos2 <= 0.0:
        return 1.0e30
    a = alpha * alpha * sin2 / cos2  # alpha^2 tan^2 theta
    return a / (2.0 * (wp.sqrt(1.0 + a) + 1.0))  # = (sqrt(1 + a) - 1) / 2 without cancellation


@wp.func
def ggx_g1(w: wp.vec3, alpha: float) -> float:
    return 1.0 / (1.0 + ggx_lambda(w, alpha))


@wp.func
def ggx_g2(wo: wp.vec3, wi: wp.vec3, alpha: float) -> float:
    """Height-correlated Smith masking-shadowing."""
    return 1.0 / (1.0 + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha))


@wp.func
def ggx_sample_visible(w: wp.vec3, alpha: float, u: wp.vec2) -> wp.vec3:
    """Microfacet normal visible from ``w`` (w.z > 0), Dupuy & Benyoub 2023 (spherical caps)."""
    # warp to the hemisphere configuration (alpha = 1)
    wh = wp.normalize(wp.vec3(alpha * w[0], alpha * w[1], w[2]))
    # sample a spherical cap in (-wh.z, 1]
    sp, cp = sin_cos(_TWO_PI * u[0])
    z = (1.0 - u[1]) * (1.0 + wh[2]) - wh[2]
    sin_t = wp.sqrt(wp.clamp(1.0 - z * z, 0.0, 1.0))
    h = wp.vec3(sin_t * cp, sin_t * sp, z) + wh
    # warp back to the ellipsoid configuration
    m = wp.vec3(alpha * h[0], alpha * h[1], wp.max(h[2], 0.0))
    lm = wp.length(m)
    if lm <= 0.0:
        return wp.vec3(0.0, 0.0, 1.0)
    return m / lm


@wp.func
def ggx_sample_visible_pdf(w: wp.vec3, wm: wp.vec3, alpha: float) -> float:
    """Density (solid angle of wm) of ``ggx_sample_visible``: D_w(wm) = G1(w) max(0, w.wm) D(wm) / w.z."""
    if w[2] <= 0.0:
        return 0.0
    c = wp.dot(w, wm)
    if c <= 0.0:
        return 0.0
    return ggx_g1(w, alpha) * c * ggx_d(wm, alpha) / w[2]


@wp.func
def fresnel_dielectric(cos_i: float, eta: float) -> float:
    """Unpolarised Fresnel reflectance of a dielectric interface. ``cos_i`` < 0 means w is on the far side (the
    relative index is then 1/eta). Returns 1 under total internal reflection."""
    c = wp.clamp(cos_i, -1.0, 1.0)
    e = eta
    if c < 0.0:
        e = 1.0 / e
        c = -c
    sin2_t = (1.0 - c * c) / (e * e)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = wp.sqrt(wp.max(0.0, 1.0 - sin2_t))
    r_parl = (e * c - cos_t) / (e * c + cos_t)
    r_perp = (c - e * cos_t) / (c + e * cos_t)
    return 0.5 * (r_parl * r_parl + r_perp * r_perp)


@wp.func
def schlick_weight(cos_t: float) -> float:
    m = wp.clamp(1.0 - cos_t, 0.0, 1.0)
    m2 = m * m
    return m2 * m2 * m


@wp.func
def fresnel_schlick(f0: wp.vec3, f90: wp.vec3, cos_t: float) -> wp.vec3:
    """Schlick's approximation F0 + (F90 - F0) (1 - cos)^5, per channel."""
    return f0 + (f90 - f0) * schlick_weight(cos_t)


@wp.func
def f0_from_ior(ior: float) -> float:
    """Normal-incidence reflectance ((1 - ior) / (1 + ior))^2."""
    r = (1.0 - ior) / (1.0 + ior)
    return r * r


@wp.func
def reflect(w: wp.vec3, n: wp.vec3) -> wp.vec3:
    """Mirror ``w`` (pointing away from the surface) about ``n``."""
    return 2.0 * wp.dot(w, n) * n - w


@wp.func
def refract(w: wp.vec3, n: wp.vec3, eta: float):
    """Snell refraction of ``w`` (pointing away from the surface) through the interface with normal ``n``.

    ``eta`` = index on the far side / index on w's side when dot(w, n) > 0 (pbrt-v4 ``Refract``; for
    dot(w, n) < 0 the roles swap). Returns (wt, ok); ok = 0 under total internal reflection.
    """
    c = wp.dot(n, w)
    e = eta
    nn = n
    if c < 0.0:
        e = 1.0 / e
        c = -c
        nn = -n
    sin2_t = wp.max(0.0, 1.0 - c * c) / (e * e)
    if sin2_t >= 1.0:
        return wp.vec3(0.0), 0
    cos_t = wp.sqrt(wp.max(0.0, 1.0 - sin2_t))
    return -w / e + (c / e - cos_t) * nn, 1


# ================================================================================================================
# NumPy twins (float64, vectorised; vectors are (..., 3))
# ================================================================================================================


def _f(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def np_roughness_to_alpha(roughness) -> np.ndarray:
    r = np.clip(_f(roughness), 0.0, 1.0)
    return np.maximum(r * r, ALPHA_MIN)


def np_ggx_d(wm, alpha) -> np.ndarray:
    wm, a2 = _f(wm), _f(alpha) ** 2
    t = a2 * wm[..., 2] ** 2 + wm[..., 0] ** 2 + wm[..., 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        d = a2 / (np.pi * t * t)
    return np.where((wm[..., 2] > 0) & (t > 0), d, 0.0)


def np_ggx_lambda(w, alpha) -> np.ndarray:
    w = _f(w)
    cos2, sin2 = w[..., 2] ** 2, w[..., 0] ** 2 + w[..., 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        a = _f(alpha) ** 2 * sin2 / cos2
        lam = a / (2.0 * (np.sqrt(1.0 + a) + 1.0))
    return np.where(cos2 > 0, lam, 1e30)


def np_ggx_g1(w, alpha) -> np.ndarray:
    return 1.0 / (1.0 + np_ggx_lambda(w, alpha))


def np_ggx_g2(wo, wi, alpha) -> np.ndarray:
    return 1.0 / (1.0 + np_ggx_lambda(wo, alpha) + np_ggx_lambda(wi, alpha))


def np_ggx_sample_visible(w, alpha, u) -> np.ndarray:
    w, u, alpha = _f(w), _f(u), _f(alpha)
    wh = np.stack(np.broadcast_arrays(alpha * w[..., 0], alpha * w[..., 1], w[..., 2]), axis=-1)
    wh = wh / np.linalg.norm(wh, axis=-1, keepdims=True)
    phi = 2.0 * np.pi * u[..., 0]
    z = (1.0 - u[..., 1]) * (1.0 + wh[..., 2]) - wh[..., 2]
    sin_t = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    h = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), z], axis=-1) + wh
    m = np.stack([alpha * h[..., 0], alpha * h[..., 1], np.maximum(h[..., 2], 0.0)], axis=-1)
    lm = np.linalg.norm(m, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(lm > 0, m / np.where(lm > 0, lm, 1.0), np.array([0.0, 0.0, 1.0]))


def np_ggx_sample_visible_pdf(w, wm, alpha) -> np.ndarray:
    w, wm = _f(w), _f(wm)
    c = np.sum(w * wm, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np_ggx_g1(w, alpha) * c * np_ggx_d(wm, alpha) / w[..., 2]
    return np.where((w[..., 2] > 0) & (c > 0), p, 0.0)


def np_fresnel_dielectric(cos_i, eta) -> np.ndarray:
    c = np.clip(_f(cos_i), -1.0, 1.0)
    e = np.where(c < 0, 1.0 / _f(eta), _f(eta))
    c = np.abs(c)
    sin2_t = (1.0 - c * c) / (e * e)
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    with np.errstate(divide="ignore", invalid="ignore"):
        r_parl = (e * c - cos_t) / (e * c + cos_t)
        r_perp = (c - e * cos_t) / (c + e * cos_t)
        f = 0.5 * (r_parl ** 2 + r_perp ** 2)
    return np.where(sin2_t >= 1.0, 1.0, f)


def np_schlick_weight(cos_t) -> np.ndarray:
    return np.clip(1.0 - _f(cos_t), 0.0, 1.0) ** 5


def np_fresnel_schlick(f0, f90, cos_t) -> np.ndarray:
    return _f(f0) + (_f(f90) - _f(f0)) * np_schlick_weight(cos_t)[..., None]


def np_f0_from_ior(ior) -> np.ndarray:
    return ((1.0 - _f(ior)) / (1.0 + _f(ior))) ** 2


def np_reflect(w, n) -> np.ndarray:
    w, n = _f(w), _f(n)
    return 2.0 * np.sum(w * n, axis=-1, keepdims=True) * n - w


def np_refract(w, n, eta):
    """(wt, ok) as ``refract``."""
    w, n = _f(w), _f(n)
    c = np.sum(w * n, axis=-1)
    e = np.where(c < 0, 1.0 / _f(eta), _f(eta))
    nn = np.where((c < 0)[..., None], -n, n)
    c = np.abs(c)
    sin2_t = np.maximum(0.0, 1.0 - c * c) / (e * e)
    ok = sin2_t < 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    wt = -w / e[..., None] + (c / e - cos_t)[..., None] * nn
    return np.where(ok[..., None], wt, 0.0), ok
