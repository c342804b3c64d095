"""What a path vertex computes beside its BSDF and lights: the sample's time in the shutter, ray origins offset off
surfaces, the power heuristic of multiple importance sampling, path regularization (roughness that only grows along
a path) and clamping, Russian roulette, and the media a path or shadow ray is in at a surface."""
from __future__ import annotations

import warp as wp

from renderer.accel.intersect import Geometry
from renderer.media.tracking import Media, grid_transmittance, interior_transmittance
from renderer.settings.options import TIME_FILTERS
from renderer.sampling.warps import sample_tent
from renderer.shading.bsdf import SurfaceParams
from renderer.shading.materials import Materials, MaterialSample


# Rendering needs no gradients: no adjoint code (half the compile time and code size).
wp.set_module_options({"enable_backward": False})


TIME_BOX = TIME_FILTERS["box"]
TIME_TRIANGLE = TIME_FILTERS["triangle"]
TIME_STROBE = TIME_FILTERS["strobe"]

RR_START = 5  # bounces before Russian roulette may end a path (equal-time efficiency: 3 -> 5 gained 3-15 %)
RAY_EPSILON = 2.0e-5  # relative offset of secondary ray origins (times 1 + |p|_inf, scene units)
FLAG_DELTA = 1
FLAG_TRANSMISSION = 2


@wp.func
def shutter_time(kind: int, u: float, frame_s: float):
    """Normalised shutter time of a sample from its time dimension, weighted by the temporal filter.

    ``frame_s`` is the frame's own time in normalised shutter time, the one instant a strobe shutter sees.
    """
    if kind == TIME_TRIANGLE:
        return sample_tent(u)
    if kind == TIME_STROBE:
        return frame_s
    return u


@wp.func
def offset_origin(p: wp.vec3, n: wp.vec3):
    scale = 1.0 + wp.max(wp.max(wp.abs(p[0]), wp.abs(p[1])), wp.abs(p[2]))
    return p + n * (RAY_EPSILON * scale)


@wp.func
def finite3(v: wp.vec3):
    return wp.isfinite(v[0]) and wp.isfinite(v[1]) and wp.isfinite(v[2])


@wp.func
def power_heuristic(pdf_a: float, pdf_b: float):
    a = pdf_a * pdf_a
    b = pdf_b * pdf_b
    if a + b <= 0.0:
        return 0.0
    return a / (a + b)


@wp.func
def surface_params(ms: MaterialSample, thin: int):
    p = SurfaceParams()
    p.diffuse_color = ms.diffuse_color
    p.specular_color = ms.specular_color
    p.use_specular_workflow = ms.use_specular_workflow
    p.metallic = ms.metallic
    p.roughness = ms.roughness
    p.clearcoat = ms.clearcoat
    p.clearcoat_roughness = ms.clearcoat_roughness
    p.opacity = ms.opacity
    p.ior = ms.ior
    p.thin = thin
    return p


@wp.func
def clamp_contribution(c: wp.vec3, limit: float):
    """c scaled so its largest channel is at most limit (limit 0 = off); the hue is kept."""
    m = wp.max(wp.max(c[0], c[1]), c[2])
    if limit > 0.0 and m > limit:
        return c * (limit / m)
    return c


@wp.func
def roughness_of_pdf(pdf: float):
    """The perceptual GGX roughness whose lobe peaks at this pdf (1/sr): alpha = 1/sqrt(4 pi pdf), clamped to 1.

    A GGX reflection lobe of alpha a has its peak pdf near 1/(4 pi a^2); a Lambertian direction (pdf <= 1/pi)
    maps to roughness >= 0.71.
    """
    if pdf <= 0.0:
        return 1.0
    a = wp.min(1.0, 1.0 / wp.sqrt(4.0 * wp.pi * pdf))
    return wp.sqrt(a)


@wp.func
def regularized_params(ms: MaterialSample, thin: int, k: float, path_roughness: float):
    """Surface parameters with lobes at least k x the path's roughness so far (the glossy filter; k 0 = off)."""
    p = surface_params(ms, thin)
    r = k * path_roughness
    if r > 0.0:
        p.roughness = wp.max(p.roughness, r)
        p.clearcoat_roughness = wp.max(p.clearcoat_roughness, r)
    return p


@wp.func(inline=True)  # no copy of the big structs
def media_shadow(geo: Geometry, mats: Materials, media: Media, ro: wp.vec3, rd: wp.vec3, tmax: float, s: float,
                 in_sa: wp.vec3, in_ss: wp.vec3, seed: wp.uint32, pixel: wp.uint32, index: wp.uint32,
                 dim: wp.uint32):
    """Transmittance of the media along a shadow ray that starts in the homogeneous medium (in_sa, in_ss)."""
    tr = grid_transmittance(media, ro, rd, tmax, s, seed, pixel, index, dim)
    if media.mesh_media != 0 and (tr[0] > 0.0 or tr[1] > 0.0 or tr[2] > 0.0):
        tr = wp.cw_mul(tr, interior_transmittance(geo, mats, media, ro, rd, tmax, s, in_sa, in_ss))
    return tr


@wp.func
def shadow_start_medium(media: Media, mats: Materials, mat: int, front: int, through: bool, sa: wp.vec3,
                        ss: wp.vec3):
    """The medium a surface's shadow ray starts in: the path's own on the side it came from; through the surface,
    the material's medium when entering its solid, none when leaving it."""
    if not through:
        return sa, ss
    m = media.mat_scatter[mat]
    if front != 0 and (m[0] > 0.0 or m[1] > 0.0 or m[2] > 0.0):
        return mats.absorption[mat], wp.vec3(m[0], m[1], m[2])
    return wp.vec3(0.0), wp.vec3(0.0)


@wp.func
def medium_boundary(media: Media, mat: int, flags: int):
    """Is this event a straight pass through the surface of a solid that holds a medium? Such a boundary is no
    vertex of the path for multiple importance sampling: shadow rays from inside pass it (with the medium's
    transmittance), so light found beyond it keeps the weights of the vertex before it."""
    if media.mesh_media == 0 or (flags & FLAG_DELTA) == 0 or (flags & FLAG_TRANSMISSION) == 0:
        return False
    m = media.mat_scatter[mat]
    return m[0] > 0.0 or m[1] > 0.0 or m[2] > 0.0


@wp.func
def roulette(beta: wp.vec3, u: float):
    """Russian roulette once the path has carried light a few bounces: (survives, reweighted throughput)."""
    q = wp.max(0.05, 1.0 - wp.max(wp.max(beta[0], beta[1]), beta[2]))
    if u < q:
        return 0, beta
    return 1, beta / (1.0 - q)


