"""Surface scattering: the UsdPreviewSurface (spec v2.5) as a physically based BSDF for a path tracer with MIS.

The lobes themselves (local frame) live in ``lobes.py``, the microfacet pieces in ``microfacet.py``; this
module mixes them. All vectors are world space and unit; ``wo`` and ``wi`` point AWAY from the surface.

Inputs: ``SurfaceParams`` (after textures). ``n`` is the shading normal and ``ng`` the geometric normal, both on the
side of ``wo`` (the integrator flips them to face the incoming ray). ``front`` is 1 when ``wo`` is outside the
solid (the ray hit the outward face) and 0 when it is inside; it only matters for refraction (``thin`` = 0).

The model (weights per lobe; ``A = (1 - cc Fcc(|cos_o|)) (1 - cc Fcc(|cos_i|))`` is the clearcoat's attenuation of
everything under it, ``Fcc`` = exact dielectric Fresnel of ior 1.5, ``cc`` = clearcoat; for the diffuse lobe A is
divided by ``1 - cc K`` (``COAT_DIFFUSE_K`` = 0.0795, its average over the diffuse lobe) so that the diffuse under the
coat reflects exactly ``(1 - cc Fcc(co))`` times its uncoated albedo: the light the coat reflects back down is not
lost. Other lobes keep the plain product, which never amplifies them):

=============  ====================================================================================================
lobe           f(wo, wi)
=============  ====================================================================================================
clearcoat      ``cc Fcc(wo.h) D G2 / (4 co ci)``, alpha = clearcoat_roughness^2, white
specular       ``A opacity F_schlick(wo.h; F0, 1) D G2 / (4 co ci)``, alpha = roughness^2.
               metallic workflow: ``F0 = lerp(((1-ior)/(1+ior))^2, diffuse_color, metallic)``;
               specular workflow: ``F0 = specular_color``. F90 = saturate(50 Y(F0)) in both: 1 for every real
               material, 0 for black specular, which authors use to mean "Lambertian" (``specular_f90``).
diffuse        ``A opacity wd diffuse_color (1 - F0) 21/(20 pi) (1-(1-co)^5) (1-(1-ci)^5)`` with
               ``wd = 1 - metallic`` (metallic workflow) or 1 (specular workflow), i.e.
               ``diffuse (1 - F(co)) (1 - F(ci)) / (pi (1 - F_avg))`` with F the specular layer's Schlick term: our
               "diffuse * (1 - F_spec)", made reciprocal and energy-aware (Kelemen & Szirmay-Kalos 2001). Its
               albedo is exactly diffuse (1 - F(co)), so with a smooth specular layer a white diffuse reflects
               exactly 1; a rough GGX layer loses its single-scattering energy (see the tests' figures). Weighting
               the diffuse by (1 - F(wo.h)) alone, as real-time UsdPreviewSurface renderers do, exceeds 1 at grazing
               angles.
transmission   ``(1 - opacity)`` times, for a solid (thin = 0, |ior - 1| >= 1e-3): the rough dielectric of Walter
               et al. 2007 with eta = ior entering (front = 1) or 1/ior leaving (front = 0), exact Fresnel between
               its reflection and refraction, alpha = roughness^2, refraction CLEAR (untinted: a glass of
               opacity 0 and the default diffuseColor 0.18 must not look smoked; colour inside a solid is
               Beer-Lambert absorption, ``usd.materials``' documented extension) and divided by eta^2 (radiance
               convention, pbrt-v4 TransportMode::Radiance). For a thin sheet (thin = 1) or ior = 1: straight
               pass-through (delta, wi = -wo), untinted (opacity is coverage, the paper's transparency: the
               holes in a leaf are not green).
=============  ====================================================================================================

The opaque lobes (diffuse, specular, clearcoat) are two-sided: they are the same whichever side ``wo`` is on.
Any lobe with alpha < ALPHA_DELTA (roughness < ~0.032) is a delta: exact mirror / Snell refraction.

Reciprocity: every reflection lobe is symmetric, f(wo, wi) = f(wi, wo). Transmission obeys
``f(wo, wi) / eta(wo)^2 = f(wi, wo) / eta(wi)^2`` with ``eta(w)`` the refractive index of the medium on w's side
(1 outside, ior inside): evaluate the swapped pair with the normals flipped and ``front`` toggled.

``bsdf_sample`` picks a lobe with ``u_lobe`` (in the order clearcoat, specular, transmission, diffuse) with
probability proportional to an estimate of the lobe's albedo at wo, with ``co = cos_o``, ``Ao = 1 - cc Fcc(co)``
and ``Y`` = Rec. 709 luminance:

    clearcoat     cc Fcc(co)
    specular      Ao opacity max(Y(F_schlick(co)), 0.02)                (never 0 while opacity > 0)
    diffuse       Ao Y(opacity wd diffuse_color (1 - F0)) (1 - (1 - co)^5)
    transmission  Ao (1 - opacity) (Fd(co, eta) + (1 - Fd(co, eta)) Y(tint))   rough or smooth dielectric
                  Ao^2 (1 - opacity) Y(tint)                                    pass-through

then reuses the remainder of ``u_lobe`` for the dielectric's reflect/refract choice. ``bsdf_pdf`` = sum over NON-delta lobes of p_select x pdf_lobe. For a delta
sample ``pdf`` is the discrete probability of that event (p_select x F or x (1 - F)), not a density: do not
use it in MIS. ``flags``: bit 0 (``BSDF_DELTA``) delta sample, bit 1 (``BSDF_TRANSMISSION``) wi is on the other side.
``pdf == 0`` means an invalid sample (weight zero): terminate the path.

The geometric normal guards against light leaks: reflection needs wi above ng, transmission below; otherwise f and
pdf are 0 and samples are invalid. If wo is below the shading normal, the geometric normal is used as shading
normal.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import warp as wp

from renderer.sampling.warps import frame_from_normal
from renderer.shading.lobes import (
    dielectric_eval,
    dielectric_sample,
    dielectric_sample_pdf,
    diffuse_eval,
    diffuse_sample,
    diffuse_sample_pdf,
    ggx_reflection_eval,
    ggx_reflection_sample,
    ggx_reflection_sample_pdf,
)
from renderer.shading.microfacet import (
    f0_from_ior,
    fresnel_dielectric,
    fresnel_schlick,
    is_delta,
    np_fresnel_dielectric,
    reflect,
    refract,
    roughness_to_alpha,
)

# No gradients are ever taken: no adjoint code (half the compile time and code size).
wp.set_module_options({"enable_backward": False})

BSDF_DELTA = 1
BSDF_TRANSMISSION = 2
W_BSDF_DELTA = wp.constant(BSDF_DELTA)
W_BSDF_TRANSMISSION = wp.constant(BSDF_TRANSMISSION)
CLEARCOAT_IOR = 1.5
W_CLEARCOAT_IOR = wp.constant(CLEARCOAT_IOR)


def _coat_diffuse_k() -> float:
    """K = int (1 - cc Fcc(ci)) weighted by the coupled diffuse's cos-weighted shape, per unit cc: the diffuse under
    a coat of weight cc reflects (1 - cc K) of what it would without, averaged over wi. Gauss-Legendre in cos."""
    x, w = np.polynomial.legendre.leggauss(64)
    c = 0.5 * (x + 1.0)
    shape = (1.0 - (1.0 - c) ** 5) * c * 2.0 * (21.0 / 20.0)  # integrates to 1 over [0, 1] (times 1/2 below)
    return float(0.5 * np.sum(w * shape * np_fresnel_dielectric(c, CLEARCOAT_IOR)))


COAT_DIFFUSE_K = _coat_diffuse_k()  # 0.0795
W_COAT_DIFFUSE_K = wp.constant(COAT_DIFFUSE_K)
PASS_THROUGH_IOR_EPS = 1.0e-3  # |ior - 1| below this: no refraction, straight pass-through
W_PASS_EPS = wp.constant(PASS_THROUGH_IOR_EPS)
SPEC_SELECT_FLOOR = wp.constant(0.02)  # least Fresnel estimate for picking the specular lobe (never 0)
TRANS_NONE = wp.constant(0)
TRANS_DIELECTRIC = wp.constant(1)
TRANS_PASS = wp.constant(2)
_LUM = wp.constant(wp.vec3(0.2126, 0.7152, 0.0722))  # Rec. 709 luminance


@wp.struct
class SurfaceParams:
    """UsdPreviewSurface inputs at a point, textures applied. Colours are linear RGB in [0, 1]; scalars in [0, 1]
    unless noted. Values outside the ranges are clamped."""

    diffuse_color: wp.vec3  # diffuseColor: diffuse albedo; metal F0 (metallic workflow)
    specular_color: wp.vec3  # specularColor: F0 of the specular layer (specular workflow only)
    use_specular_workflow: int  # useSpecularWorkflow: 0 metallic (metallic, ior), 1 specular (specular_color)
    metallic: float  # metallic workflow only
    roughness: float  # perceptual; GGX alpha = roughness^2 (specular layer and dielectric)
    clearcoat: float  # weight of a white dielectric (ior 1.5) coat
    clearcoat_roughness: float  # perceptual; alpha = clearcoat_roughness^2
    opacity: float  # 1 opaque; 1 - opacity is the transmitted (refracted / passed-through) fraction
    ior: float  # index of refraction of the solid relative to the outside (> 0); also F0 in the metallic workflow
    thin: int  # 1: a sheet bounding no solid (transmission passes straight through); 0: surface of a solid


@wp.struct
class BsdfLobes:
    """The BSDF set up for one surface point and outgoing direction (``bsdf_setup``); reuse it for several
    ``lobes_eval`` / ``lobes_pdf`` / ``lobes_sample`` calls at the same point (``bsdf_*`` set up every call)."""

    frame: wp.mat33  # columns (s, t, n) of the shading frame
    ng: wp.vec3  # geometric normal on wo's side
    wo_w: wp.vec3  # wo, world
    wo: wp.vec3  # wo, local (z > 0 when valid)
    valid: int
    kd: wp.vec3  # diffuse: opacity * wd * diffuse_color
    f0: wp.vec3  # Schlick F0 of the specular layer
    f90: wp.vec3  # Schlick F90: saturate(50 Y(F0)), so black specular is no specular at all
    w_spec: float  # specular weight (opacity)
    alpha: float  # GGX alpha of the specular layer and the dielectric
    cc: float  # clearcoat weight
    alpha_cc: float
    w_trans: float  # 1 - opacity
    tint: wp.vec3  # transmission tint
    eta: float  # far-side index / wo-side index (dielectric)
    trans: int  # TRANS_NONE / TRANS_DIELECTRIC / TRANS_PASS
    p_diffuse: float  # lobe selection probabilities (sum 1, or all 0 when nothing scatters)
    p_spec: float
    p_coat: float
    p_trans: float


@wp.func
def _lum(c: wp.vec3) -> float:
    return wp.dot(c, _LUM)


@wp.func
def _clamp01(c: wp.vec3) -> wp.vec3:
    return wp.vec3(wp.clamp(c[0], 0.0, 1.0), wp.clamp(c[1], 0.0, 1.0), wp.clamp(c[2], 0.0, 1.0))


@wp.func
def specular_f0(p: SurfaceParams) -> wp.vec3:
    """F0 of the specular layer (F90 = 1)."""
    if p.use_specular_workflow != 0:
        return _clamp01(p.specular_color)
    f0d = f0_from_ior(wp.max(p.ior, 1.0e-3))
    return wp.lerp(wp.vec3(f0d), _clamp01(p.diffuse_color), wp.clamp(p.metallic, 0.0, 1.0))


@wp.func
def specular_f90(f0: wp.vec3) -> wp.vec3:
    """Edge reflectance of the specular layer: 1 for every real material (F0 >= 0.02), fading to 0 with F0.

    UsdPreviewSurface says the edge is white; with black ``specularColor`` that still leaves a highlight at
    grazing angles, yet authors use black specular (``useSpecularWorkflow`` 1) to mean a purely Lambertian
    surface (so do our benchmark scenes). Scaling F90 by 50 F0 (as UE4 and Filament do: F0 below 2 % is
    taken as shadowing) honours that intent and leaves every physically plausible F0 untouched.
    """
    return wp.vec3(wp.clamp(50.0 * _lum(f0), 0.0, 1.0))


@wp.func
def _coat_att(cc: float, c: float) -> float:
    if cc <= 0.0:
        return 1.0
    return 1.0 - cc * fresnel_dielectric(wp.abs(c), W_CLEARCOAT_IOR)


@wp.func
def bsdf_setup(p: SurfaceParams, n: wp.vec3, ng: wp.vec3, wo: wp.vec3, front: int) -> BsdfLobes:
    b = BsdfLobes()
    ns = n
    if wp.dot(n, wo) <= 0.0:
        ns = ng
    b.frame = frame_from_normal(ns)
    b.ng = ng
    b.wo_w = wo
    b.wo = wp.transpose(b.frame) * wo
    b.valid = wp.where(b.wo[2] > 0.0 and wp.dot(ng, wo) > 0.0, 1, 0)
    opacity = wp.clamp(p.opacity, 0.0, 1.0)
    dc = _clamp01(p.diffuse_color)
    wd = float(1.0)
    if p.use_specular_workflow == 0:
        wd = 1.0 - wp.clamp(p.metallic, 0.0, 1.0)
    b.f0 = specular_f0(p)
    b.f90 = specular_f90(b.f0)
    b.kd = dc * (opacity * wd)
    b.w_spec = opacity
    b.alpha = roughness_to_alpha(p.roughness)
    b.cc = wp.clamp(p.clearcoat, 0.0, 1.0)
    b.alpha_cc = roughness_to_alpha(p.clearcoat_roughness)
    b.w_trans = 1.0 - opacity
    b.tint = wp.vec3(1.0)  # clear: colour inside solids is Beer-Lambert's (usd.materials' absorption extension)
    ior = wp.max(p.ior, 1.0e-3)
    b.eta = wp.where(front != 0, ior, 1.0 / ior)
    b.trans = TRANS_NONE
    if b.w_trans > 0.0:
        if p.thin != 0:
            b.trans = TRANS_PASS
        elif wp.abs(ior - 1.0) < W_PASS_EPS:
            b.trans = TRANS_PASS
        else:
            b.trans = TRANS_DIELECTRIC
    # lobe selection: estimated albedo of each lobe at wo
    co = wp.clamp(b.wo[2], 0.0, 1.0)
    att = float(1.0)  # what the coat lets through; the coat's own Fresnel only where there is a coat (2 % of a
    e_coat = float(0.0)  # Cornell box sample went to it): 1 - 0 * F and 0 * F are these same bits
    if b.cc > 0.0:
        fcc = fresnel_dielectric(co, W_CLEARCOAT_IOR)
        att = 1.0 - b.cc * fcc
        e_coat = b.cc * fcc
    e_spec = float(0.0)
    if b.w_spec > 0.0 and _lum(b.f90) > 0.0:  # a black specular layer (F0 = F90 = 0) reflects nothing
        e_spec = att * b.w_spec * wp.max(_lum(fresnel_schlick(b.f0, b.f90, co)), SPEC_SELECT_FLOOR)
    e_diff = att * _lum(wp.cw_mul(b.kd, wp.vec3(1.0) - fresnel_schlick(b.f0, b.f90, co)))  # albedo, exact
    e_trans = float(0.0)
    if b.trans == TRANS_DIELECTRIC:
        fr = fresnel_dielectric(co, b.eta)
        e_trans = att * b.w_trans * (fr + (1.0 - fr) * _lum(b.tint))
    elif b.trans == TRANS_PASS:
        e_trans = att * att * b.w_trans * _lum(b.tint)
    total = e_coat + e_spec + e_diff + e_trans
    if total > 0.0 and b.valid != 0:
        b.p_coat = e_coat / total
        b.p_spec = e_spec / total
        b.p_diffuse = e_diff / total
        b.p_trans = e_trans / total
    else:
        b.valid = 0
    return b


@wp.func
def _leaks(b: BsdfLobes, wi_local_z: float, wi: wp.vec3) -> bool:
    """True when wi's side of the shading surface disagrees with its side of the geometric surface."""
    cg = wp.dot(b.ng, wi)
    return wi_local_z == 0.0 or cg == 0.0 or (wi_local_z > 0.0) != (cg > 0.0)


@wp.func
def _eval_local(b: BsdfLobes, wi: wp.vec3) -> wp.vec3:
    """Sum of the non-delta lobes at local wi (no leak check)."""
    wo = b.wo
    att = _coat_att(b.cc, wo[2]) * _coat_att(b.cc, wi[2])
    f = wp.vec3(0.0)
    if wi[2] > 0.0:
        f += diffuse_eval(b.kd, b.f0, b.f90, wo, wi) * (att / (1.0 - b.cc * W_COAT_DIFFUSE_K))
        if b.w_spec > 0.0 and not is_delta(b.alpha):
            v, c = ggx_reflection_eval(b.alpha, wo, wi)
            f += fresnel_schlick(b.f0, b.f90, c) * (att * b.w_spec * v)
        if b.cc > 0.0 and not is_delta(b.alpha_cc):
            v, c = ggx_reflection_eval(b.alpha_cc, wo, wi)
            f += wp.vec3(b.cc * fresnel_dielectric(c, W_CLEARCOAT_IOR) * v)
    if b.trans == TRANS_DIELECTRIC and not is_delta(b.alpha):
        fr, ft = dielectric_eval(b.alpha, b.eta, wo, wi)
        f += (wp.vec3(fr) + b.tint * ft) * (att * b.w_trans)
    return f


@wp.func
def _eval_local_split(b: BsdfLobes, wi: wp.vec3):
    """(diffuse lobe, every other non-delta lobe) at local wi: ``_eval_local`` in two parts, for per-light
    diffuse/specular multipliers. Kept apart from ``_eval_local`` so that its sums (and frames) stay as they are."""
    wo = b.wo
    att = _coat_att(b.cc, wo[2]) * _coat_att(b.cc, wi[2])
    fd = wp.vec3(0.0)
    fs = wp.vec3(0.0)
    if wi[2] > 0.0:
        fd = diffuse_eval(b.kd, b.f0, b.f90, wo, wi) * (att / (1.0 - b.cc * W_COAT_DIFFUSE_K))
        if b.w_spec > 0.0 and not is_delta(b.alpha):
            v, c = ggx_reflection_eval(b.alpha, wo, wi)
            fs += fresnel_schlick(b.f0, b.f90, c) * (att * b.w_spec * v)
        if b.cc > 0.0 and not is_delta(b.alpha_cc):
            v, c = ggx_reflection_eval(b.alpha_cc, wo, wi)
            fs += wp.vec3(b.cc * fresnel_dielectric(c, W_CLEARCOAT_IOR) * v)
    if b.trans == TRANS_DIELECTRIC and not is_delta(b.alpha):
        fr, ft = dielectric_eval(b.alpha, b.eta, wo, wi)
        fs += (wp.vec3(fr) + b.tint * ft) * (att * b.w_trans)
    return fd, fs


@wp.func
def _pdf_local(b: BsdfLobes, wi: wp.vec3) -> float:
    wo = b.wo
    pdf = float(0.0)
    if wi[2] > 0.0:
        pdf += b.p_diffuse * diffuse_sample_pdf(wi)
        if b.p_spec > 0.0 and not is_delta(b.alpha):
            pdf += b.p_spec * ggx_reflection_sample_pdf(b.alpha, wo, wi)
        if b.p_coat > 0.0 and not is_delta(b.alpha_cc):
            pdf += b.p_coat * ggx_reflection_sample_pdf(b.alpha_cc, wo, wi)
    if b.trans == TRANS_DIELECTRIC and b.p_trans > 0.0 and not is_delta(b.alpha):
        pdf += b.p_trans * dielectric_sample_pdf(b.alpha, b.eta, wo, wi)
    return pdf


@wp.func
def lobes_eval(b: BsdfLobes, wi: wp.vec3) -> wp.vec3:
    """f(wo, wi) of the non-delta lobes (not times cos)."""
    if b.valid == 0:
        return wp.vec3(0.0)
    wl = wp.transpose(b.frame) * wi
    if _leaks(b, wl[2], wi):
        return wp.vec3(0.0)
    return _eval_local(b, wl)


@wp.func
def lobes_eval_split(b: BsdfLobes, wi: wp.vec3):
    """(diffuse, the other lobes) of ``lobes_eval``: f = diffuse + other."""
    if b.valid == 0:
        return wp.vec3(0.0), wp.vec3(0.0)
    wl = wp.transpose(b.frame) * wi
    if _leaks(b, wl[2], wi):
        return wp.vec3(0.0), wp.vec3(0.0)
    return _eval_local_split(b, wl)


@wp.func
def lobes_eval_diffuse(b: BsdfLobes, wi: wp.vec3) -> wp.vec3:
    """The diffuse lobe's term of ``lobes_eval``, computed as it computes it (its first term: ``lobes_eval`` minus
    this is the other lobes' share, never negative), without evaluating the others."""
    if b.valid == 0:
        return wp.vec3(0.0)
    wl = wp.transpose(b.frame) * wi
    if _leaks(b, wl[2], wi) or wl[2] <= 0.0:
        return wp.vec3(0.0)
    att = _coat_att(b.cc, b.wo[2]) * _coat_att(b.cc, wl[2])
    return diffuse_eval(b.kd, b.f0, b.f90, b.wo, wl) * (att / (1.0 - b.cc * W_COAT_DIFFUSE_K))


@wp.func
def lobes_pdf(b: BsdfLobes, wi: wp.vec3) -> float:
    """Solid-angle density with which ``lobes_sample`` returns a non-delta sample in direction wi."""
    if b.valid == 0:
        return 0.0
    wl = wp.transpose(b.frame) * wi
    if _leaks(b, wl[2], wi):
        return 0.0
    return _pdf_local(b, wl)


@wp.func
def _invalid():
    return wp.vec3(0.0), wp.vec3(0.0), 0.0, 0


@wp.func
def lobes_sample(b: BsdfLobes, u_lobe: float, u: wp.vec2):
    """(wi, weight = f |cos| / pdf, pdf, flags); see the module docstring."""
    if b.valid == 0:
        return _invalid()
    n = wp.vec3(b.frame[0, 2], b.frame[1, 2], b.frame[2, 2])
    co = b.wo[2]
    att_o = _coat_att(b.cc, co)
    ul = wp.clamp(u_lobe, 0.0, 0.99999994)
    wl = wp.vec3(0.0)
    down = int(0)  # the sampled lobe meant wi below the surface (a refraction)
    # --- choose the lobe; the delta branches return directly
    c1 = b.p_coat
    c2 = c1 + b.p_spec
    c3 = c2 + b.p_trans
    if ul < c1:
        if is_delta(b.alpha_cc):
            wi = reflect(b.wo_w, n)
            if _leaks(b, co, wi):
                return _invalid()
            w_cc = b.cc * fresnel_dielectric(co, W_CLEARCOAT_IOR) / b.p_coat
            return wi, wp.vec3(w_cc), b.p_coat, W_BSDF_DELTA
        wl = ggx_reflection_sample(b.alpha_cc, b.wo, u)
    elif ul < c2:
        if is_delta(b.alpha):
            wi = reflect(b.wo_w, n)
            if _leaks(b, co, wi):
                return _invalid()
            w = fresnel_schlick(b.f0, b.f90, co) * (att_o * att_o * b.w_spec / b.p_spec)
            return wi, w, b.p_spec, W_BSDF_DELTA
        wl = ggx_reflection_sample(b.alpha, b.wo, u)
    elif ul < c3:
        uc = wp.clamp((ul - c2) / b.p_trans, 0.0, 0.99999994)
        if b.trans == TRANS_PASS:
            w = b.tint * (att_o * att_o * b.w_trans / b.p_trans)
            return -b.wo_w, w, b.p_trans, W_BSDF_DELTA | W_BSDF_TRANSMISSION
        if is_delta(b.alpha):
            fr = fresnel_dielectric(co, b.eta)
            if uc < fr:
                wi = reflect(b.wo_w, n)
                if _leaks(b, co, wi):
                    return _invalid()
                return wi, wp.vec3(att_o * att_o * b.w_trans / b.p_trans), b.p_trans * fr, W_BSDF_DELTA
            wt, ok = refract(b.wo_w, n, b.eta)
            ct = wp.dot(wt, n)
            if ok == 0 or _leaks(b, ct, wt):
                return _invalid()
            w = b.tint * (att_o * _coat_att(b.cc, ct) * b.w_trans / (b.eta * b.eta * b.p_trans))
            return wt, w, b.p_trans * (1.0 - fr), W_BSDF_DELTA | W_BSDF_TRANSMISSION
        wl, down = dielectric_sample(b.alpha, b.eta, b.wo, u, uc)
    else:
        wl = diffuse_sample(u)
    # --- a non-delta sample: the whole non-delta mixture at wi. A reflection that went below the surface (or a
    # refraction above it) is invalid: the mixture pdf there describes other lobes, not this path.
    if (down != 0) != (wl[2] < 0.0):
        return _invalid()
    wi = b.frame * wl
    if _leaks(b, wl[2], wi):
        return _invalid()
    pdf = _pdf_local(b, wl)
    if pdf <= 0.0:
        return _invalid()
    f = _eval_local(b, wl)
    flags = wp.where(wl[2] < 0.0, W_BSDF_TRANSMISSION, 0)
    return wi, f * (wp.abs(wl[2]) / pdf), pdf, flags


# ---- the API --------------------------------------------------------------------------------------------------


@wp.func
def bsdf_eval(p: SurfaceParams, n: wp.vec3, ng: wp.vec3, wo: wp.vec3, wi: wp.vec3, front: int) -> wp.vec3:
    """f(wo, wi) of the non-delta lobes (not times cos), 1/sr."""
    return lobes_eval(bsdf_setup(p, n, ng, wo, front), wi)


@wp.func
def bsdf_pdf(p: SurfaceParams, n: wp.vec3, ng: wp.vec3, wo: wp.vec3, wi: wp.vec3, front: int) -> float:
    """Solid-angle density of ``bsdf_sample`` producing a non-delta sample in direction wi."""
    return lobes_pdf(bsdf_setup(p, n, ng, wo, front), wi)


@wp.func
def bsdf_sample(p: SurfaceParams, n: wp.vec3, ng: wp.vec3, wo: wp.vec3, front: int, u_lobe: float, u: wp.vec2):
    """(wi, weight = f |cos| / pdf, pdf, flags); pdf 0 = invalid."""
    return lobes_sample(bsdf_setup(p, n, ng, wo, front), u_lobe, u)


@wp.func
def bsdf_albedo_hint(p: SurfaceParams) -> wp.vec3:
    """A [0, 1] colour for the albedo AOV: the normal-incidence albedo of the opaque part (diffuse under the
    specular layer plus F0) and the transmission tint of the transparent part, under the coat's F0 = 0.04."""
    opacity = wp.clamp(p.opacity, 0.0, 1.0)
    dc = _clamp01(p.diffuse_color)
    f0 = specular_f0(p)
    wd = float(1.0)
    if p.use_specular_workflow == 0:
        wd = 1.0 - wp.clamp(p.metallic, 0.0, 1.0)
    base = (wp.cw_mul(dc * wd, wp.vec3(1.0) - f0) + f0) * opacity + wp.vec3(1.0 - opacity)
    cc = wp.clamp(p.clearcoat, 0.0, 1.0) * 0.04
    return _clamp01(base * (1.0 - cc) + wp.vec3(cc))


# ---- host helpers ----------------------------------------------------------------------------------------------

USD_DEFAULTS = dict(diffuse_color=(0.18, 0.18, 0.18), specular_color=(0.0, 0.0, 0.0), use_specular_workflow=0,
                    metallic=0.0, roughness=0.5, clearcoat=0.0, clearcoat_roughness=0.01, opacity=1.0, ior=1.5,
                    thin=0)


def make_surface_params(**kw) -> SurfaceParams:
    """A ``SurfaceParams`` from keyword arguments, UsdPreviewSurface defaults for the rest (``USD_DEFAULTS``)."""
    unknown = set(kw) - set(USD_DEFAULTS)
    if unknown:
        raise TypeError(f"unknown SurfaceParams fields: {sorted(unknown)}")
    v = {**USD_DEFAULTS, **kw}
    p = SurfaceParams()
    p.diffuse_color = wp.vec3(*map(float, v["diffuse_color"]))
    p.specular_color = wp.vec3(*map(float, v["specular_color"]))
    p.use_specular_workflow = int(v["use_specular_workflow"])
    p.thin = int(v["thin"])
    for k in ("metallic", "roughness", "clearcoat", "clearcoat_roughness", "opacity", "ior"):
        setattr(p, k, float(v[k]))
    return p


@wp.kernel
def _albedo_kernel(p: SurfaceParams, wo: wp.vec3, front: int, u: wp.array(dtype=wp.vec3),
                   weight: wp.array(dtype=wp.vec3), flags: wp.array(dtype=int)):
    i = wp.tid()
    n = wp.vec3(0.0, 0.0, 1.0)
    x = u[i]
    wi, w, pdf, fl = bsdf_sample(p, n, n, wo, front, x[0], wp.vec2(x[1], x[2]))
    weight[i] = w
    flags[i] = wp.where(pdf > 0.0, fl, -1)


class Albedo(NamedTuple):
    """Directional albedo estimate (RGB arrays of shape (3,)); ``*_err`` are one standard error."""

    reflect: np.ndarray  # mean sample weight of reflected samples (delta ones included)
    transmit: np.ndarray  # mean weight of transmitted samples, radiance convention (includes 1 / eta^2)
    transmit_energy: np.ndarray  # the same with the eta^2 undone: the transmitted fraction of energy
    total_energy: np.ndarray  # reflect + transmit_energy (<= 1 for an energy-conserving BSDF)
    total_energy_err: np.ndarray


def directional_albedo(params: SurfaceParams | dict, cos_theta_o: float, front: int = 1,
                       n_samples: int = 1 << 18, seed: int = 0, device: str = "cpu") -> Albedo:
    """Monte-Carlo directional albedo of the BSDF for wo at polar angle acos(cos_theta_o) (mean of the sample
    weight over ``n_samples`` of ``bsdf_sample``), with n = ng = +z. ``params`` is a SurfaceParams or a dict of
    ``make_surface_params`` keywords."""
    p = make_surface_params(**params) if isinstance(params, dict) else params
    c = float(np.clip(cos_theta_o, 0.0, 1.0))
    wo = wp.vec3(math.sqrt(max(0.0, 1.0 - c * c)), 0.0, c)
    u = np.random.default_rng(seed).random((n_samples, 3)).astype(np.float32)
    weight = wp.zeros(n_samples, dtype=wp.vec3, device=device)
    flags = wp.zeros(n_samples, dtype=int, device=device)
    wp.launch(_albedo_kernel, dim=n_samples, inputs=[p, wo, int(front), wp.array(u, dtype=wp.vec3, device=device)],
              outputs=[weight, flags], device=device)
    w = weight.numpy().astype(np.float64)
    fl = flags.numpy()
    trans = (fl >= 0) & ((fl & BSDF_TRANSMISSION) != 0)
    refl = (fl >= 0) & ~trans
    eta = p.ior if front else 1.0 / p.ior
    eta2 = eta * eta if (not p.thin and abs(p.ior - 1.0) >= PASS_THROUGH_IOR_EPS) else 1.0
    wr = np.where(refl[:, None], w, 0.0)
    wt = np.where(trans[:, None], w, 0.0)
    tot = wr + wt * eta2
    return Albedo(wr.mean(0), wt.mean(0), (wt * eta2).mean(0), tot.mean(0), tot.std(0) / math.sqrt(n_samples))
