"""Light linking, shadow linking and the ShadowAPI controls, as the kernels test them.

Lights whose link collections differ from "everything" get a bit (lights with the same membership share one: a
link group); each instance carries two bit masks, the groups that light it and the groups it casts shadows
for (``upload_links``). ``lit_by`` says whether light li may light a point of instance ``inst``;
``shadow_factor`` is what reaches a point from light li along a shadow ray: the transmittance T through the
occluders that cast shadows for li (only those nearer than ``shadow:distance``), as L (T + (1 - T)
shadow:color), and 1 with ``shadow:enable`` off. ``shadow:falloff`` F fades the last F of ``shadow:distance`` D:
occluders nearer than D - F shadow fully, those in the zone with strength (1 - x)^``shadow:falloffGamma`` (x the
fraction through the zone), taken per slice of the zone (FALLOFF_STEPS), those beyond D not at all.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.accel.intersect import Geometry
from renderer.accel.occlusion import linked_transmittance
from renderer.shading.materials import Materials
from renderer.shading.textures import Textures
from renderer.kernels.struct_refs import by_reference

MAX_GROUPS = 31  # link groups per mask (bits of an int32)
FALLOFF_STEPS = 8  # slices of a shadow:falloff zone, each with the fade strength at its middle


@by_reference
@wp.struct
class Links:
    light_bit: wp.array(dtype=wp.int32)  # per light: its light-link group bit, -1 unlinked (lights everything)
    shadow_bit: wp.array(dtype=wp.int32)  # per light: its shadow-link group bit, -1 (everything casts)
    inst_lit: wp.array(dtype=wp.int32)  # per instance: bits of the groups that light it
    inst_caster: wp.array(dtype=wp.int32)  # per instance: bits of the groups it casts shadows for
    shadow_color: wp.array(dtype=wp.vec3)  # per light
    shadow_param: wp.array(dtype=wp.vec2)  # per light: (enable 0/1, max occluder distance or -1)
    shadow_falloff: wp.array(dtype=wp.vec2)  # per light: (falloff zone size or -1, falloff gamma)
    falloff_steps: int  # FALLOFF_STEPS (a struct field, not a constant, so the loop over slices is not unrolled)


def _groups(masks: list, n_inst: int, what: str, names: list[str], warn) -> tuple[list[int], np.ndarray]:
    """A bit per distinct membership array, and per instance the bits of the groups containing it."""
    bits, keys = [], {}
    inst = np.zeros(max(1, n_inst), np.int64)
    for m, name in zip(masks, names):
        if m is None:
            bits.append(-1)
            continue
        key = np.asarray(m, bool).tobytes()
        if key not in keys:
            if len(keys) >= MAX_GROUPS:
                warn(f"more than {MAX_GROUPS} distinct {what} collections: the rest are ignored", name)
                bits.append(-1)
                continue
            keys[key] = len(keys)
            inst[:n_inst] |= np.asarray(m, bool).astype(np.int64) << keys[key]
        bits.append(keys[key])
    return bits, inst.astype(np.int32)


def upload_links(lights, n_inst: int, device: str, warn=lambda *a: None) -> Links:
    """Link groups and shadow controls of the uploaded ``lights`` (scene.Light, in table order)."""
    names = [lt.name for lt in lights]
    lb, lit = _groups([lt.illuminates for lt in lights], n_inst, "light-link", names, warn)
    sb, cast = _groups([lt.casts_shadow for lt in lights], n_inst, "shadow-link", names, warn)
    k = Links()
    i32 = lambda a: wp.array(np.asarray(a if len(a) else [-1], np.int32), dtype=wp.int32, device=device)  # noqa
    k.light_bit, k.shadow_bit = i32(lb), i32(sb)
    k.inst_lit = wp.array(lit, dtype=wp.int32, device=device)
    k.inst_caster = wp.array(cast, dtype=wp.int32, device=device)
    k.shadow_color = wp.array(np.array([lt.shadow_color for lt in lights] or [(0, 0, 0)], np.float32),
                              dtype=wp.vec3, device=device)
    k.shadow_param = wp.array(np.array([(float(lt.shadow_enable), lt.shadow_distance) for lt in lights]
                                       or [(1.0, -1.0)], np.float32), dtype=wp.vec2, device=device)
    k.shadow_falloff = wp.array(np.array([(lt.shadow_falloff, lt.shadow_falloff_gamma) for lt in lights]
                                         or [(-1.0, 1.0)], np.float32), dtype=wp.vec2, device=device)
    k.falloff_steps = FALLOFF_STEPS
    return k


@wp.func
def lit_by(links: Links, li: int, inst: int):
    """May light li light a point of instance ``inst`` (-1: not on an instance)?"""
    b = links.light_bit[li]
    if b < 0 or inst < 0:
        return True
    return ((links.inst_lit[inst] >> b) & 1) != 0


@wp.func(inline=True)  # one call site: no copy of the Geometry struct
def shadow_factor(geo: Geometry, mats: Materials, tex: Textures, links: Links, li: int, ro: wp.vec3,
                  rd: wp.vec3, tmax: float, s: float):
    """What fraction (per channel) of light li's emission arrives along the shadow ray (ro, rd, tmax)."""
    sp = links.shadow_param[li]
    if sp[0] == 0.0:
        return wp.vec3(1.0)
    t = tmax
    if sp[1] > 0.0:
        t = wp.min(tmax, sp[1])
    bit = links.shadow_bit[li]
    tr = float(1.0)
    fo = links.shadow_falloff[li]
    # segments of the shadow ray, each with its shadow strength: the whole ray at strength 1, or, with a falloff
    # zone, the part before it (strength 1) and FALLOFF_STEPS slices of the zone with the strength at their middle,
    # (1 - x)^gamma, x the fraction through the zone. One traversal call site in a loop of runtime length, so the
    # kernel holds one copy of the traversal (a loop of constant length would be unrolled).
    z0 = t
    segments = int(1)
    if sp[1] > 0.0 and fo[0] > 0.0 and tmax > sp[1] - fo[0]:
        z0 = wp.max(sp[1] - fo[0], 0.0)
        segments = 1 + links.falloff_steps
    step = fo[0] / float(wp.max(links.falloff_steps, 1))
    for k in range(segments):
        a = float(0.0)
        b = z0
        strength = float(1.0)
        if k > 0:
            a = z0 + step * float(k - 1)
            b = wp.min(a + step, t)
            strength = wp.pow(1.0 - (float(k) - 0.5) / float(links.falloff_steps), fo[1])
        if b > a and tr > 0.0:
            tk = linked_transmittance(geo, mats, tex, ro + rd * a, rd, b - a, s, links.inst_caster, bit)
            if strength == 1.0:
                tr = tr * tk
            else:
                tr = tr * (1.0 - strength * (1.0 - tk))
    return wp.vec3(tr) + links.shadow_color[li] * (1.0 - tr)
