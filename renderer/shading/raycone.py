"""Ray cones: the footprint a path's ray covers at a hit, for choosing texture mip levels.

After Akenine-Moeller et al., "Texture Level of Detail Strategies for Real-Time Ray Tracing" (Ray Tracing Gems,
2019), kept simple. A path carries a cone: its width ``w`` (scene units) at the current ray origin and its
spread angle ``gamma`` (radians). The camera ray starts with w = 0 and gamma = the angle one pixel subtends
(film height / (focal length x image height)); an orthographic camera starts with w = one pixel and gamma = 0.
At a hit at distance t the width is w + gamma t, and its footprint in texture space is

    footprint (uv units) = width * sqrt(uv area / world area of the triangle) / |cos(theta)|

(theta between the ray and the geometric normal, |cos| at least ``MIN_COS`` so grazing hits do not blur
without bound). Textures pick their level from it (``textures.image_trilinear``). At a bounce the cone keeps its
width and widens its spread by the lobe's width: 0 for mirrors and clear glass, 2 alpha (alpha = roughness^2,
the GGX width) for glossy and diffuse lobes. Surface curvature is not followed (flat-surface cones), which
keeps textures in mirror reflections of curved objects somewhat sharper than a full ray-cone tracer would.
Distributed ray tracing's many samples per pixel filter what the cone leaves; the cone only removes the
aliasing that no affordable sample count would (a checkerboard at grazing angles).
"""
from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

MIN_COS = 0.05  # grazing hits: the footprint grows at most 20x beyond the cone's width


@wp.func
def camera_cone(film_height: float, focal_length: float, height: int, orthographic: int):
    """(width at the camera, spread angle) of a camera ray's cone, in scene units and radians."""
    pixel = film_height / float(wp.max(height, 1))
    if orthographic != 0:
        return pixel, 0.0
    return 0.0, pixel / wp.max(focal_length, 1.0e-12)


@wp.func
def uv_density(p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, uv0: wp.vec2, uv1: wp.vec2, uv2: wp.vec2):
    """sqrt(uv area / world area) of a triangle: uv units per scene unit (0 if degenerate)."""
    pa = wp.length(wp.cross(p1 - p0, p2 - p0))
    d1 = uv1 - uv0
    d2 = uv2 - uv0
    ta = wp.abs(d1[0] * d2[1] - d2[0] * d1[1])
    if pa <= 0.0 or not wp.isfinite(ta) or not wp.isfinite(pa):
        return 0.0
    return wp.sqrt(ta / pa)


@wp.func
def uv_footprint(width: float, density: float, cos_theta: float):
    """Footprint in uv units of a cone ``width`` wide meeting a surface at cos_theta."""
    return wp.abs(width) * density / wp.max(wp.abs(cos_theta), MIN_COS)


@wp.func
def bounce_spread(spread: float, roughness: float, delta: int):
    """The cone's spread angle after a bounce: unchanged by a delta lobe, widened by 2 alpha otherwise."""
    if delta != 0:
        return spread
    return spread + 2.0 * roughness * roughness
