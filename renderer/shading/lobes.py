"""The BSDF lobes of the UsdPreviewSurface, each with eval / sample / pdf, in a LOCAL frame (z = the normal on the
side of ``wo``; ``wo.z > 0``). ``bsdf.py`` mixes them; the tests check each one alone.

=========================================  ==========================================================================
lobe                                        f(wo, wi) (not times cos)
=========================================  ==========================================================================
``diffuse_*``                               Fresnel-coupled diffuse (Kelemen & Szirmay-Kalos 2001, with the Schlick
                                            Fresnel of the specular layer as its albedo): ``21/(20 pi) rd (1 - rs)
                                            (1 - (1 - co)^5) (1 - (1 - ci)^5)`` = ``rd (1 - F(co)) (1 - F(ci)) /
                                            (pi (1 - F_avg))``. Reciprocal; its directional albedo is exactly
                                            ``rd (1 - F_schlick(co))``, so under a smooth Schlick layer of F0 = rs
                                            the pair reflects F + rd (1 - F) <= 1 (= 1 for white). Cosine sampled.
``ggx_reflection_*``                        ``D(h) G2(wo, wi) / (4 co ci)``, WITHOUT Fresnel (the caller multiplies:
                                            Schlick for the specular layer, exact dielectric for the clearcoat).
                                            Sampled by visible normals: weight = G2 / G1(wo) (times Fresnel).
``dielectric_*``                            Walter et al. 2007 rough dielectric, reflection + transmission chosen
                                            per microfacet by the exact Fresnel term (pbrt-v4 ``DielectricBxDF``).
                                            ``eta`` = index on the far side / index on wo's side. Transmission is in
                                            the RADIANCE convention: divided by eta^2 (see ``bsdf.py``).
=========================================  ==========================================================================

Every ``*_sample`` takes its uniform numbers as arguments. Delta (alpha < ALPHA_DELTA) configurations are the
caller's business: these functions assume a rough lobe.
"""
from __future__ import annotations

import math

import warp as wp

from renderer.sampling.warps import square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf, to_world
from renderer.shading.microfacet import (
    fresnel_dielectric,
    ggx_d,
    ggx_g2,
    ggx_sample_visible,
    ggx_sample_visible_pdf,
    reflect,
    refract,
)

_Z = wp.constant(wp.vec3(0.0, 0.0, 1.0))


# ---- diffuse ------------------------------------------------------------------------------------------------


@wp.func
def diffuse_fresnel_factor(c: float) -> float:
    """1 - (1 - c)^5 = (1 - F_schlick(c)) / (1 - F0): the Fresnel transmission of the coupled diffuse lobe."""
    m = wp.clamp(1.0 - c, 0.0, 1.0)
    m2 = m * m
    return 1.0 - m2 * m2 * m


@wp.func
def diffuse_eval(rd: wp.vec3, rs: wp.vec3, r90: wp.vec3, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """Coupled diffuse under a Schlick specular layer F(c) = rs + (r90 - rs)(1 - c)^5 (Kelemen & Szirmay-Kalos
    2001): ``rd (1 - F(co)) (1 - F(ci)) / (pi (1 - F_avg))`` with F_avg = rs + (r90 - rs) / 21. Its directional
    albedo is rd (1 - F(co)) exactly; with rs = r90 = 0 it is Lambert's rd / pi."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return wp.vec3(0.0)
    wo5 = 1.0 - diffuse_fresnel_factor(wo[2])
    wi5 = 1.0 - diffuse_fresnel_factor(wi[2])
    one = wp.vec3(1.0)
    t_o = one - rs - (r90 - rs) * wo5
    t_i = one - rs - (r90 - rs) * wi5
    avg = one - rs - (r90 - rs) * (1.0 / 21.0)
    k = wp.vec3(t_o[0] * t_i[0] / wp.max(avg[0], 1.0e-6), t_o[1] * t_i[1] / wp.max(avg[1], 1.0e-6),
                t_o[2] * t_i[2] / wp.max(avg[2], 1.0e-6))
    return wp.cw_mul(rd, k) * (1.0 / wp.pi)


@wp.func
def diffuse_sample(u: wp.vec2) -> wp.vec3:
    return square_to_cosine_hemisphere(u)


@wp.func
def diffuse_sample_pdf(wi: wp.vec3) -> float:
    return square_to_cosine_hemisphere_pdf(wi)


# ---- GGX reflection -----------------------------------------------------------------------------------------


@wp.func
def ggx_reflection_eval(alpha: float, wo: wp.vec3, wi: wp.vec3):
    """(D G2 / (4 co ci), wo . h): the Fresnel-free microfacet reflection and the cosine for the Fresnel term."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0, 0.0
    h = wo + wi
    lh = wp.length(h)
    if lh <= 0.0:
        return 0.0, 0.0
    h = h / lh
    return ggx_d(h, alpha) * ggx_g2(wo, wi, alpha) / (4.0 * wo[2] * wi[2]), wp.max(wp.dot(wo, h), 0.0)


@wp.func
def ggx_reflection_sample(alpha: float, wo: wp.vec3, u: wp.vec2) -> wp.vec3:
    """Reflect wo about a visible microfacet normal. The result may point below the surface (wi.z <= 0): invalid."""
    return reflect(wo, ggx_sample_visible(wo, alpha, u))


@wp.func
def ggx_reflection_sample_pdf(alpha: float, wo: wp.vec3, wi: wp.vec3) -> float:
    """D_wo(h) / (4 wo.h) = G1(wo) D(h) / (4 wo.z) for wi above the surface."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0
    h = wo + wi
    lh = wp.length(h)
    if lh <= 0.0:
        return 0.0
    h = h / lh
    c = wp.dot(wo, h)
    if c <= 0.0:
        return 0.0
    return ggx_sample_visible_pdf(wo, h, alpha) / (4.0 * c)


# ---- rough dielectric ---------------------------------------------------------------------------------------


@wp.func
def _dielectric_half(eta: float, wo: wp.vec3, wi: wp.vec3):
    """Generalised half vector (facing +z) and validity; (h, ok)."""
    h = wo + wi
    if wi[2] < 0.0:
        h = wo + eta * wi
    lh = wp.length(h)
    if lh <= 0.0 or wi[2] == 0.0 or wo[2] <= 0.0:
        return _Z, 0
    h = h / lh
    if h[2] < 0.0:
        h = -h
    # discard back-facing microfacets
    if wp.dot(h, wo) <= 0.0 or wp.dot(h, wi) * wi[2] <= 0.0:
        return _Z, 0
    return h, 1


@wp.func
def _dielectric_fresnel(eta: float, ho: float, hi: float, transmit: bool) -> float:
    """F at the microfacet. For a refraction pair F(wo.h, eta) = F(|wi.h|, 1 / eta); evaluate it from the less dense
    side, where it is well conditioned (from the dense side it is steep near the critical angle)."""
    if transmit and eta < 1.0:
        return fresnel_dielectric(wp.abs(hi), 1.0 / eta)
    return fresnel_dielectric(ho, eta)


@wp.func
def dielectric_eval(alpha: float, eta: float, wo: wp.vec3, wi: wp.vec3):
    """(f_reflection, f_transmission) of the rough dielectric; one of them is 0. Transmission is divided by eta^2
    (radiance) and untinted."""
    h, ok = _dielectric_half(eta, wo, wi)
    if ok == 0:
        return 0.0, 0.0
    ho = wp.dot(h, wo)
    hi = wp.dot(h, wi)
    f = _dielectric_fresnel(eta, ho, hi, wi[2] < 0.0)
    dg = ggx_d(h, alpha) * ggx_g2(wo, wi, alpha)
    if wi[2] > 0.0:
        return dg * f / (4.0 * wo[2] * wi[2]), 0.0
    s = hi + ho / eta
    ft = dg * (1.0 - f) * wp.abs(hi * ho) / (s * s * wp.abs(wi[2]) * wo[2])
    return 0.0, ft / (eta * eta)


@wp.func
def dielectric_sample_pdf(alpha: float, eta: float, wo: wp.vec3, wi: wp.vec3) -> float:
    """Density of ``dielectric_sample``: D_wo(h) times the Jacobian of reflection or refraction, times F or 1-F."""
    h, ok = _dielectric_half(eta, wo, wi)
    if ok == 0:
        return 0.0
    ho = wp.dot(h, wo)
    hi = wp.dot(h, wi)
    f = _dielectric_fresnel(eta, ho, hi, wi[2] < 0.0)
    pdf_h = ggx_sample_visible_pdf(wo, h, alpha)
    if wi[2] > 0.0:
        return pdf_h * f / (4.0 * ho)
    s = hi + ho / eta
    return pdf_h * (1.0 - f) * wp.abs(hi) / (s * s)


@wp.func
def dielectric_sample(alpha: float, eta: float, wo: wp.vec3, u: wp.vec2, uc: float):
    """(wi, kind): kind 0 reflection, 1 transmission. Reflection with probability F(wo.h) per sampled microfacet.
    Check the hemisphere of wi (reflection below / refraction above the surface is an invalid sample)."""
    h = ggx_sample_visible(wo, alpha, u)
    f = fresnel_dielectric(wp.dot(wo, h), eta)
    if uc < f:
        return reflect(wo, h), 0
    wt, ok = refract(wo, h, eta)
    if ok == 0:  # cannot happen for f < 1 except by rounding; report as a (downward-invalid) reflection
        return reflect(wo, h), 0
    return wt, 1


# ---- plain Lambert ---------------------------------------------------------------------------------------------


@wp.func
def lambert_eval(albedo: wp.vec3, n: wp.vec3, wi: wp.vec3):
    """f(wo, wi) of a diffuse surface: albedo / pi above the surface, 0 below."""
    if wp.dot(n, wi) <= 0.0:
        return wp.vec3(0.0)
    return albedo * (1.0 / wp.pi)


@wp.func
def lambert_sample(n: wp.vec3, u: wp.vec2):
    """Cosine-weighted direction about n."""
    return to_world(square_to_cosine_hemisphere(u), n)


@wp.func
def lambert_pdf(n: wp.vec3, wi: wp.vec3):
    c = wp.dot(n, wi)
    if c <= 0.0:
        return 0.0
    return square_to_cosine_hemisphere_pdf(wp.vec3(0.0, 0.0, c))
