"""Per-light ``inputs:diffuse`` / ``inputs:specular`` (UsdLux LightAPI): how much a light affects the diffuse and
the specular response of materials.

Light reaches a shading point in two ways, and both carry the multipliers:
* next-event estimation evaluates the BSDF toward a point on the light: the diffuse lobe is scaled by the
  light's diffuse multiplier, every other lobe (specular, coat, transmission) by its specular one;
* a BSDF-sampled direction that finds a light: the sampled direction's BSDF value is split the same way when it
  is drawn (``diffuse_fraction``, per colour channel; 0 for delta lobes), and the light found scales it with
  ``sampled_weight``.
Camera rays that see a light directly are not a material response and keep weight 1. When every light has
(1, 1) the kernels skip all of this (``Lights.lobe_mults``), so renders without multipliers are unchanged bit
for bit.
"""
from __future__ import annotations

import warp as wp

from renderer.lights.table import Lights
from renderer.shading.bsdf import BsdfLobes, lobes_eval_split


@wp.func
def nee_bsdf(lights: Lights, li: int, lobes: BsdfLobes, wi: wp.vec3, f: wp.vec3) -> wp.vec3:
    """The BSDF value ``f`` toward light ``li`` with its multipliers applied (``f`` itself when they are 1)."""
    m = lights.lobe_mult[li]
    if m[0] == 1.0 and m[1] == 1.0:
        return f
    fd, fs = lobes_eval_split(lobes, wi)
    return fd * m[0] + fs * m[1]


@wp.func
def diffuse_fraction(lobes: BsdfLobes, wi: wp.vec3, delta: int) -> wp.vec3:
    """Per channel, the share of the diffuse lobe in the BSDF value of a sampled direction (0 for delta lobes)."""
    if delta != 0:
        return wp.vec3(0.0)
    fd, fs = lobes_eval_split(lobes, wi)
    out = wp.vec3(0.0)
    for c in range(3):
        total = fd[c] + fs[c]
        if total > 0.0:
            out[c] = fd[c] / total
    return out


@wp.func
def sampled_weight(lights: Lights, li: int, frac: wp.vec3) -> wp.vec3:
    """The multiplier of light ``li`` found along a sampled direction whose diffuse share was ``frac``."""
    m = lights.lobe_mult[li]
    return frac * m[0] + (wp.vec3(1.0) - frac) * m[1]
