"""The Henyey-Greenstein phase function: how a scattering medium turns light, with its sampling routine and pdf.

p(cos theta) = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos theta)^(3/2)), per steradian, where theta is the angle between
the direction light travelled before the scattering event (``d``) and the one it leaves in (``wi``): anisotropy
``g`` in (-1, 1), 0 isotropic, > 0 forward (smoke, clouds), < 0 backward. ``hg_sample`` inverts its cumulative
distribution exactly, so a sampled direction's weight p / pdf is 1. NumPy twins (``np_hg_*``) are for tests.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.sampling.warps import INV_FOUR_PI, TWO_PI, sin_cos, to_world

G_ISOTROPIC = 1.0e-3  # |g| below this samples the sphere uniformly (the inversion divides by g)
G_MAX = 0.99  # anisotropy is clamped to [-G_MAX, G_MAX]: |g| = 1 is a delta


@wp.func
def hg_pdf(g: float, cos_theta: float):
    """Density (per steradian) of scattering by angle theta from the direction of travel."""
    g2 = g * g
    denom = 1.0 + g2 - 2.0 * g * cos_theta
    return INV_FOUR_PI * (1.0 - g2) / (denom * wp.sqrt(denom))


@wp.func
def hg_sample(g: float, d: wp.vec3, u: wp.vec2):
    """A direction scattered from travel direction ``d`` (unit), and its pdf. ``u`` uniform in [0, 1)^2."""
    cos_t = 1.0 - 2.0 * u[0]
    if wp.abs(g) >= G_ISOTROPIC:
        q = (1.0 - g * g) / (1.0 - g + 2.0 * g * u[0])
        cos_t = wp.clamp((1.0 + g * g - q * q) / (2.0 * g), -1.0, 1.0)
    sin_t = wp.sqrt(wp.max(0.0, 1.0 - cos_t * cos_t))
    sp, cp = sin_cos(TWO_PI * u[1])
    wi = to_world(wp.vec3(sin_t * cp, sin_t * sp, cos_t), d)
    return wi, hg_pdf(g, cos_t)


def np_hg_pdf(g: float, cos_theta) -> np.ndarray:
    g2 = g * g
    denom = 1.0 + g2 - 2.0 * g * np.asarray(cos_theta, np.float64)
    return (1.0 - g2) / (4.0 * np.pi * denom ** 1.5)


def np_hg_sample_cos(g: float, u0) -> np.ndarray:
    """cos theta of ``hg_sample`` for uniform u0 (the inversion, NumPy)."""
    u0 = np.asarray(u0, np.float64)
    if abs(g) < G_ISOTROPIC:
        return 1.0 - 2.0 * u0
    q = (1.0 - g * g) / (1.0 - g + 2.0 * g * u0)
    return np.clip((1.0 + g * g - q * q) / (2.0 * g), -1.0, 1.0)
