"""Surface scattering (BSDFs). The spine has the Lambertian lobe; gloss and translucency come with issue 3.

Each lobe has ``*_eval`` (BSDF value times nothing: f(wo, wi)), ``*_sample`` (direction from two uniform numbers)
and ``*_pdf`` (solid angle), all in world space about the shading normal ``n`` (facing the viewer).
"""
from __future__ import annotations

import warp as wp

from .sampling import square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf, to_world


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
