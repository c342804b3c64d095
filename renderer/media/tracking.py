"""Participating media in the kernels: where a ray's light is scattered, absorbed or emitted, and how much of it a
shadow ray's segment lets through.

Two kinds of medium:

* **grid volumes** (``Media``, one per UsdVol Volume): a density field (and temperature, emission and velocity
  fields) in NanoVDB grids, placed by a transform over the shutter. Each has a **majorant grid**: a coarse uniform
  grid over its object-space box whose cells bound the extinction anywhere in them (trilinear reach and velocity
  advection included, ``media.grids``). A ray walks those cells with a 3D DDA and samples tentative collisions
  at the cell's majorant rate, so empty space costs one cell step and thin regions few collisions: **delta
  tracking** for the path (a collision is real with probability sigma / majorant, else null and the walk goes on)
  and **ratio tracking** for shadow rays (the product of sigma_null / majorant over the collisions, an unbiased
  transmittance). Neither marches with a fixed step, so neither is biased.
* **homogeneous interiors**: a closed mesh whose material has a scattering coefficient (``Media.mat_scatter``)
  fills its inside with that medium (and the material's absorption); a path inside one samples its collisions
  exactly (constant majorant), and shadow rays count the distance they travel inside such meshes
  (``interior_transmittance``).

Colour: coefficients are RGB (chromatic extinction). Distances are sampled with one scalar majorant (the largest
channel's bound), and a collision is chosen real (absorbing or scattering) or null with probabilities from the
channel means; the path's weight takes the ratio of each channel's coefficient to that probability (spectral
tracking, Kutz et al. 2017), so grey media keep a weight of exactly 1. Emission (a source term, radiance per scene
unit) is gathered at every tentative collision, weighted by 1 / majorant.

Overlapping volumes are tracked one after the other, each up to the nearest real collision found so far: exact for
grey media; for chromatic media whose boxes overlap, the null-collision weights of the farther part of an
earlier volume's walk are kept (a small bias, only there).

Random numbers come from the sampler at dimensions of their own (``sampling.sobol``: ``DIM_MEDIUM`` and
``DIM_MEDIUM_SHADOW``), one per collision, so every sample stays replayable.
"""
from __future__ import annotations

import warp as wp

from renderer.accel.intersect import BIG, Geometry, intersect_closest
from renderer.motion.kernels import MotionKeys, keys_matrix
from renderer.sampling.sobol import sample_1d, sample_2d
from renderer.shading.materials import Materials
from renderer.kernels.struct_refs import by_reference

wp.set_module_options({"enable_backward": False})

# What ended a walk through media (``sample_media``): the path goes on to the surface, scatters, or is absorbed.
MEDIUM_NONE = wp.constant(0)
MEDIUM_SCATTER = wp.constant(1)  # a real scattering collision: the volume event (V) of light path expressions
MEDIUM_ABSORB = wp.constant(2)

EMIT_NONE = 0
EMIT_FIELD = 1  # emission x the emission field
EMIT_DENSITY = 2  # emission x the density field

MAX_STEPS = 1 << 16  # tentative collisions per walk; a majorant grid keeps real walks far below this
MAX_INTERFACES = 16  # medium boundaries a shadow ray crosses before the rest of it is taken as clear
STEP_DIMS = 2  # sampler dimensions per tentative collision of the path (distance, event)


@by_reference
@wp.struct
class Media:
    """Every grid volume of a scene, and the homogeneous media of materials (``media.upload.upload_media``)."""

    count: int  # grid volumes (0: the walk is skipped)
    mesh_media: int  # 1 when some material fills its closed meshes with a scattering medium
    frame_s: float  # the frame's instant in normalised shutter time (velocity advection is 0 there)
    keys: MotionKeys  # object-to-world keys of the volumes
    xf_off: wp.array(dtype=wp.int32)  # per volume: its keys
    xf_count: wp.array(dtype=wp.int32)
    w2o: wp.array(dtype=wp.mat44)  # per volume: world to object when it does not move
    density: wp.array(dtype=wp.uint64)  # per volume: NanoVDB grid ids (0: none)
    temperature: wp.array(dtype=wp.uint64)
    emission_grid: wp.array(dtype=wp.uint64)
    velocity: wp.array(dtype=wp.uint64)
    vel_dt: wp.array(dtype=wp.float32)  # per volume: seconds (x velocity scale) per unit of normalised time
    absorption: wp.array(dtype=wp.vec3)  # per volume: sigma_a per unit density, per scene unit
    scattering: wp.array(dtype=wp.vec3)  # per volume: sigma_s per unit density
    g: wp.array(dtype=wp.float32)  # per volume: Henyey-Greenstein anisotropy
    emission: wp.array(dtype=wp.vec3)  # per volume: radiance per scene unit per unit of the emission source
    emit_kind: wp.array(dtype=wp.int32)  # per volume: EMIT_*
    blackbody: wp.array(dtype=wp.vec2)  # per volume: (kelvin per unit temperature, intensity; 0 none)
    maj_lo: wp.array(dtype=wp.vec3)  # per volume: object-space corner of its majorant grid (= its box)
    maj_cell: wp.array(dtype=wp.vec3)  # per volume: cell size (object units)
    maj_dims: wp.array(dtype=wp.vec3i)  # per volume: cells per axis
    maj_off: wp.array(dtype=wp.int32)  # per volume: first cell in ``maj``
    maj: wp.array(dtype=wp.float32)  # extinction bounds per scene unit, x fastest
    bb_rgb: wp.array(dtype=wp.vec3)  # blackbody radiance table (``media.grids.blackbody_table``)
    bb_step: float  # kelvin per table entry
    mat_scatter: wp.array(dtype=wp.vec4)  # per material: interior sigma_s (rgb, per scene unit), HG g (w)


@wp.func
def volume_world_to_object(media: Media, v: int, s: float):
    if media.xf_count[v] == 1:
        return media.w2o[v]
    return wp.inverse(keys_matrix(media.keys, media.xf_off[v], media.xf_count[v], s))


@wp.func
def box_clip(lo: wp.vec3, hi: wp.vec3, ro: wp.vec3, rd: wp.vec3, t_lo: float, t_hi: float):
    """The part (t0, t1) of the ray's [t_lo, t_hi] inside the box; t0 >= t1 when it misses."""
    t0 = t_lo
    t1 = t_hi
    for a in range(3):
        if rd[a] != 0.0:
            inv = 1.0 / rd[a]
            ta = (lo[a] - ro[a]) * inv
            tb = (hi[a] - ro[a]) * inv
            t0 = wp.max(t0, wp.min(ta, tb))
            t1 = wp.min(t1, wp.max(ta, tb))
        elif ro[a] < lo[a] or ro[a] > hi[a]:
            t1 = -1.0
    return t0, t1


@wp.func
def grid_value(vid: wp.uint64, p: wp.vec3):
    """A scalar field's trilinear value at object-space point p (0 without a grid)."""
    if vid == wp.uint64(0):
        return float(0.0)
    return wp.volume_sample_f(vid, wp.volume_world_to_index(vid, p), wp.Volume.LINEAR)


@wp.func
def blackbody(media: Media, kelvin: float):
    """Blackbody radiance of a temperature (table, linear between entries; 0 below the first)."""
    x = kelvin / media.bb_step
    n = media.bb_rgb.shape[0]
    if x <= 0.0:
        return wp.vec3(0.0)
    if x >= float(n - 1):
        return media.bb_rgb[n - 1]
    i = int(x)
    f = x - float(i)
    return media.bb_rgb[i] * (1.0 - f) + media.bb_rgb[i + 1] * f


@wp.func
def medium_at(media: Media, v: int, p: wp.vec3, s: float):
    """(sigma_a, sigma_s, emitted radiance per scene unit) of volume v at object-space point p, time s."""
    q = p
    vel = media.velocity[v]
    if vel != wp.uint64(0):  # the fluid moved: what is at p now was at p - velocity dt (OpenVDB's convention)
        u = wp.volume_sample_v(vel, wp.volume_world_to_index(vel, p), wp.Volume.LINEAR)
        q = p - u * ((s - media.frame_s) * media.vel_dt[v])
    d = wp.max(grid_value(media.density[v], q), 0.0)
    Le = wp.vec3(0.0)
    kind = media.emit_kind[v]
    if kind == EMIT_FIELD:
        Le = media.emission[v] * wp.max(grid_value(media.emission_grid[v], q), 0.0)
    elif kind == EMIT_DENSITY:
        Le = media.emission[v] * d
    bb = media.blackbody[v]
    if bb[1] > 0.0:
        Le = Le + blackbody(media, grid_value(media.temperature[v], q) * bb[0]) * bb[1]
    return media.absorption[v] * d, media.scattering[v] * d, Le


@wp.func
def mean3(v: wp.vec3):
    return (v[0] + v[1] + v[2]) * (1.0 / 3.0)


@wp.func
def collide(sa: wp.vec3, ss: wp.vec3, m: float, w: wp.vec3, u: float):
    """A tentative collision at majorant m: (event, weight). Real with probability mean(sigma) / m, chosen by
    ``u``; the weight is sigma / (m p) per channel for the event chosen (1 for grey media)."""
    sn = wp.vec3(wp.max(m - sa[0] - ss[0], 0.0), wp.max(m - sa[1] - ss[1], 0.0), wp.max(m - sa[2] - ss[2], 0.0))
    pa = mean3(sa)
    ps = mean3(ss)
    pn = mean3(sn)
    total = pa + ps + pn
    x = u * total
    if x < pa:
        return MEDIUM_ABSORB, w
    if x < pa + ps:
        return MEDIUM_SCATTER, wp.cw_mul(w, ss) * (total / (m * ps))
    return MEDIUM_NONE, wp.cw_mul(w, sn) * (total / (m * pn))


@wp.struct
class Walk:
    """The state of a walk through media along one ray segment."""

    t_end: float  # the nearest real collision so far, else the segment's end
    event: int  # MEDIUM_*
    g: float  # anisotropy at the scattering collision
    weight: wp.vec3  # throughput factor up to the collision (null-collision weights; 1 for grey media)
    emitted: wp.vec3  # radiance gathered along the way, before the path's throughput
    step: int  # tentative collisions drawn (sampler dimensions used)


@wp.func
def walk_homogeneous(walk: Walk, sa: wp.vec3, ss: wp.vec3, g: float, seed: wp.uint32, pixel: wp.uint32,
                     index: wp.uint32, dim: wp.uint32):
    """Delta tracking through a constant medium over [0, walk.t_end): a closed mesh's interior."""
    m = wp.max(wp.max(sa[0] + ss[0], sa[1] + ss[1]), sa[2] + ss[2])
    t = float(0.0)
    w = walk.weight
    out = walk
    while m > 0.0 and out.step < MAX_STEPS:
        u = sample_2d(seed, pixel, index, dim + wp.uint32(STEP_DIMS * out.step))
        out.step += 1
        t = t - wp.log(1.0 - u[0]) / m
        if t >= out.t_end:
            break
        ev, w = collide(sa, ss, m, w, u[1])
        if ev != MEDIUM_NONE:
            out.t_end = t
            out.event = ev
            out.g = g
            break
    out.weight = w
    return out


@wp.func
def dda_setup(lo: wp.vec3, cell: wp.vec3, dims: wp.vec3i, ro: wp.vec3, rd: wp.vec3, t0: float):
    """The majorant cell at ray parameter t0, the parameter of the next cell boundary per axis and the parameter
    step between boundaries."""
    p = ro + rd * t0
    c = wp.vec3i(0, 0, 0)
    t_next = wp.vec3(BIG, BIG, BIG)
    dt = wp.vec3(BIG, BIG, BIG)
    for a in range(3):
        ca = wp.clamp(int(wp.floor((p[a] - lo[a]) / cell[a])), 0, dims[a] - 1)
        c[a] = ca
        if rd[a] > 0.0:
            t_next[a] = t0 + (lo[a] + float(ca + 1) * cell[a] - p[a]) / rd[a]
            dt[a] = cell[a] / rd[a]
        elif rd[a] < 0.0:
            t_next[a] = t0 + (lo[a] + float(ca) * cell[a] - p[a]) / rd[a]
            dt[a] = -cell[a] / rd[a]
    return c, t_next, dt


@wp.func
def dda_axis(t_next: wp.vec3):
    a = int(0)
    if t_next[1] < t_next[a]:
        a = 1
    if t_next[2] < t_next[a]:
        a = 2
    return a


@wp.func
def walk_grid(media: Media, v: int, walk: Walk, ro: wp.vec3, rd: wp.vec3, t0: float, t1: float, s: float,
              seed: wp.uint32, pixel: wp.uint32, index: wp.uint32, dim: wp.uint32):
    """Delta tracking through volume v over [t0, t1) of the object-space ray (ro, rd): cell by cell of its
    majorant grid, emission gathered on the way, stopping at the first real collision."""
    dims = media.maj_dims[v]
    off = media.maj_off[v]
    c, t_next, dt = dda_setup(media.maj_lo[v], media.maj_cell[v], dims, ro, rd, t0)
    out = walk
    w = walk.weight
    E = walk.emitted
    t = t0
    going = int(1)
    while going != 0:
        a = dda_axis(t_next)
        seg_end = wp.min(t_next[a], t1)
        m = media.maj[off + (c[2] * dims[1] + c[1]) * dims[0] + c[0]]
        while m > 0.0 and out.step < MAX_STEPS:
            u = sample_2d(seed, pixel, index, dim + wp.uint32(STEP_DIMS * out.step))
            out.step += 1
            tc = t - wp.log(1.0 - u[0]) / m
            if tc >= seg_end:
                break
            t = tc
            sa, ss, Le = medium_at(media, v, ro + rd * t, s)
            E = E + wp.cw_mul(w, Le) * (1.0 / m)
            ev, w = collide(sa, ss, m, w, u[1])
            if ev != MEDIUM_NONE:
                out.t_end = t
                out.event = ev
                out.g = media.g[v]
                going = 0
                break
        if going != 0:
            t = seg_end
            if seg_end >= t1:
                going = 0
            else:
                c[a] = c[a] + wp.where(rd[a] > 0.0, 1, -1)
                if c[a] < 0 or c[a] >= dims[a]:
                    going = 0
                t_next[a] = t_next[a] + dt[a]
    out.weight = w
    out.emitted = E
    return out


@wp.func
def ratio_grid(media: Media, v: int, tr: wp.vec3, ro: wp.vec3, rd: wp.vec3, t0: float, t1: float, s: float,
               seed: wp.uint32, pixel: wp.uint32, index: wp.uint32, dim: wp.uint32, step: int):
    """Ratio tracking through volume v over [t0, t1): ``tr`` times the segment's transmittance (unbiased)."""
    dims = media.maj_dims[v]
    off = media.maj_off[v]
    c, t_next, dt = dda_setup(media.maj_lo[v], media.maj_cell[v], dims, ro, rd, t0)
    out = tr
    n = step
    t = t0
    going = int(1)
    while going != 0:
        a = dda_axis(t_next)
        seg_end = wp.min(t_next[a], t1)
        m = media.maj[off + (c[2] * dims[1] + c[1]) * dims[0] + c[0]]
        while m > 0.0 and n < MAX_STEPS:
            u = sample_1d(seed, pixel, index, dim + wp.uint32(n))
            n += 1
            tc = t - wp.log(1.0 - u) / m
            if tc >= seg_end:
                break
            t = tc
            sa, ss, Le = medium_at(media, v, ro + rd * t, s)
            out = wp.vec3(out[0] * wp.max(1.0 - (sa[0] + ss[0]) / m, 0.0),
                          out[1] * wp.max(1.0 - (sa[1] + ss[1]) / m, 0.0),
                          out[2] * wp.max(1.0 - (sa[2] + ss[2]) / m, 0.0))
            if out[0] <= 0.0 and out[1] <= 0.0 and out[2] <= 0.0:
                going = 0
                break
        if going != 0:
            t = seg_end
            if seg_end >= t1:
                going = 0
            else:
                c[a] = c[a] + wp.where(rd[a] > 0.0, 1, -1)
                if c[a] < 0 or c[a] >= dims[a]:
                    going = 0
                t_next[a] = t_next[a] + dt[a]
    return out, n


@wp.func
def volume_ray(media: Media, v: int, ro: wp.vec3, rd: wp.vec3, tmax: float, s: float):
    """Volume v's object-space ray at time s and the part (t0, t1) of [0, tmax) inside its box (t in world
    units: the object-space direction is not normalised, so coefficients stay per world scene unit)."""
    w2o = volume_world_to_object(media, v, s)
    ro_o = wp.transform_point(w2o, ro)
    rd_o = wp.transform_vector(w2o, rd)
    dims = media.maj_dims[v]
    lo = media.maj_lo[v]
    cell = media.maj_cell[v]
    hi = lo + wp.vec3(cell[0] * float(dims[0]), cell[1] * float(dims[1]), cell[2] * float(dims[2]))
    t0, t1 = box_clip(lo, hi, ro_o, rd_o, 0.0, tmax)
    return ro_o, rd_o, t0, t1


@wp.func
def sample_media(media: Media, ro: wp.vec3, rd: wp.vec3, tmax: float, s: float, in_sa: wp.vec3, in_ss: wp.vec3,
                 in_g: float, seed: wp.uint32, pixel: wp.uint32, index: wp.uint32, dim: wp.uint32):
    """Delta tracking along the path's ray up to the surface at tmax: the homogeneous interior the path is in
    (``in_sa``, ``in_ss``: zero outside), then each grid volume. Returns a ``Walk``."""
    walk = Walk()
    walk.t_end = tmax
    walk.event = MEDIUM_NONE
    walk.g = float(0.0)
    walk.weight = wp.vec3(1.0)
    walk.emitted = wp.vec3(0.0)
    walk.step = 0
    if in_ss[0] > 0.0 or in_ss[1] > 0.0 or in_ss[2] > 0.0:
        walk = walk_homogeneous(walk, in_sa, in_ss, in_g, seed, pixel, index, dim)
    for v in range(media.count):
        ro_o, rd_o, t0, t1 = volume_ray(media, v, ro, rd, walk.t_end, s)
        if t0 < t1:
            walk = walk_grid(media, v, walk, ro_o, rd_o, t0, t1, s, seed, pixel, index, dim)
    return walk


@wp.func
def grid_transmittance(media: Media, ro: wp.vec3, rd: wp.vec3, tmax: float, s: float, seed: wp.uint32,
                       pixel: wp.uint32, index: wp.uint32, dim: wp.uint32):
    """Transmittance of the grid volumes along a shadow ray's segment (ratio tracking)."""
    tr = wp.vec3(1.0)
    n = int(0)
    for v in range(media.count):
        ro_o, rd_o, t0, t1 = volume_ray(media, v, ro, rd, tmax, s)
        if t0 < t1 and (tr[0] > 0.0 or tr[1] > 0.0 or tr[2] > 0.0):
            tr, n = ratio_grid(media, v, tr, ro_o, rd_o, t0, t1, s, seed, pixel, index, dim, n)
    return tr


@wp.func
def interior_transmittance(geo: Geometry, mats: Materials, media: Media, ro: wp.vec3, rd: wp.vec3, tmax: float,
                           s: float, in_sa: wp.vec3, in_ss: wp.vec3):
    """exp(-sigma_t d) of the homogeneous interiors a shadow ray's segment runs through: from the medium it
    starts in (``in_sa``, ``in_ss``), each surface of a material with a medium toggles in and out of it."""
    tr = wp.vec3(1.0)
    sa = in_sa
    ss = in_ss
    o = ro
    left = tmax
    for k in range(MAX_INTERFACES):
        if left > 0.0:
            hit = intersect_closest(geo, o, rd, left, s)
            seg = wp.min(hit.t, left)
            st = sa + ss
            if st[0] > 0.0 or st[1] > 0.0 or st[2] > 0.0:
                tr = wp.cw_mul(tr, wp.vec3(wp.exp(-st[0] * seg), wp.exp(-st[1] * seg), wp.exp(-st[2] * seg)))
            if hit.inst < 0:
                left = 0.0
            else:
                mat = geo.tri_material[hit.tri]
                ms = media.mat_scatter[mat]
                if ms[0] > 0.0 or ms[1] > 0.0 or ms[2] > 0.0:
                    if ss[0] > 0.0 or ss[1] > 0.0 or ss[2] > 0.0:
                        sa = wp.vec3(0.0)
                        ss = wp.vec3(0.0)
                    else:
                        sa = mats.absorption[mat]
                        ss = wp.vec3(ms[0], ms[1], ms[2])
                step = hit.t * (1.0 + 1.0e-5) + 1.0e-6
                o = o + rd * step
                left = left - step
    return tr
