"""Lights as the kernels see them, and how one is chosen per shading point.

Conventions (UsdLux): rect and disk lights emit from their front face towards local -Z; sphere and cylinder
lights from their outer surface; a distant light arrives along its local -Z within a cone of apex ``angle``;
a dome light from every direction (a constant colour or a lat-long texture, see ``envmap``); MeshLightAPI meshes
from their front faces unless ``doubleSided``, meshes of emissive materials from both faces (as Cycles does).

A shading point samples every infinite light and ONE finite light, chosen by ``select`` in proportion to the
irradiance each can deliver at that point (spatial clusters of finite lights; see ``select``). ``select_pdf``
keeps the scene-wide estimate (delivered at the scene's centre, capped at pi times the radiance). The sampling routines are in ``sample``.
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from renderer.lights.envmap import EnvMap, upload_envmap
from renderer.lights.linking import Links, upload_links
from renderer.lights.reach import AREA_KINDS, Reach, upload_reach
from renderer.lights.select import SelectEstimate, Selection, upload_selection
from renderer.lights.shaping import mean_face_shaping, mean_shaping
from renderer.motion.kernels import MotionKeys, upload_keys
from renderer.motion.transform import matrices_at, matrix_at, placed_extent
from renderer.scene.analytic import object_box
from renderer.scene.model import (
    LIGHT_CYLINDER,
    LIGHT_DISK,
    LIGHT_DISTANT,
    LIGHT_DOME,
    LIGHT_MESH,
    LIGHT_RECT,
    LIGHT_SPHERE,
    Scene,
    Shaping,
)
from renderer.kernels.struct_refs import by_reference


@by_reference
@wp.struct
class Lights:
    count: int
    kind: wp.array(dtype=wp.int32)
    radiance: wp.array(dtype=wp.vec3)  # emitted radiance, nits (distant of angle 0: irradiance; point: intensity)
    size: wp.array(dtype=wp.vec4)  # rect (width, height), disk/sphere (_, _, radius), cylinder (length, _,
    #                                radius), distant (cos of the half apex angle), dome (1 = textured)
    xf_off: wp.array(dtype=wp.int32)
    xf_count: wp.array(dtype=wp.int32)
    xf_still: wp.array(dtype=wp.mat44)  # light-to-world of lights that do not move (xf_count == 1)
    # rect lights that do not move: world corner, edge vectors and emitting normal at 4 li .. 4 li + 3, computed
    # once here (in float64) instead of from xf_still at every sample (``sample.rect_frame``)
    rect_still: wp.array(dtype=wp.vec3)
    # lights that do not move: their unit +z axis in the world, the direction toward a distant light
    # (``sample.distant_axis``: an escaped ray's and a sun sample's, 3 % of the teapot shot's kernel from xf_still)
    axis_still: wp.array(dtype=wp.vec3)
    # ... their origin in the world and size[2] (radius) times the length of their x axis: a sphere's or disk's
    # centre and world radius (``sample.sphere_frame``, ``disk_frame``: 2 % of the dof scene's kernel from xf_still)
    centre_still: wp.array(dtype=wp.vec4)
    disk_front_still: wp.array(dtype=wp.vec3)  # ... and a disk's emitting side (``emitting_sides``)
    keys: MotionKeys
    select_pdf: wp.array(dtype=wp.float32)  # (count,) probability of choosing each light
    instance: wp.array(dtype=wp.int32)  # mesh lights: the emissive instance
    inst_light: wp.array(dtype=wp.int32)  # per instance: its mesh light, or -1
    one_sided: wp.array(dtype=wp.int32)  # mesh lights: 1 = emits from its triangles' front faces only
    uniform: wp.array(dtype=wp.int32)  # mesh lights: 1 = MeshLightAPI (radiance[li] everywhere, light rays only)
    tri_base: wp.array(dtype=wp.int32)  # mesh lights: first emitting triangle of the instance's mesh
    tri_count: wp.array(dtype=wp.int32)  # mesh lights: number of emitting triangles
    cdf: wp.array(dtype=wp.float32)  # mesh lights: cumulative triangle power, concatenated
    cdf_off: wp.array(dtype=wp.int32)
    shape0: wp.array(dtype=wp.vec4)  # ShapingAPI at s = 0: (cone angle rad, softness, focus, 1 = shaped)
    shape1: wp.array(dtype=wp.vec4)  # ... at s = 1 (blended linearly by the sample's time)
    focus_tint: wp.array(dtype=wp.vec3)
    ies_off: wp.array(dtype=wp.int32)  # offset of the light's IES grid in ies_table, -1 none
    ies_param: wp.array(dtype=wp.vec2)  # (ies:angleScale, 1 / profile power or 1)
    ies_table: wp.array(dtype=wp.float32)  # IES grids (IES_THETA x IES_PHI candela each), concatenated
    img_off: wp.array(dtype=wp.int32)  # rect lights: first texel of its texture in img, -1 none
    img_w: wp.array(dtype=wp.int32)
    img_h: wp.array(dtype=wp.int32)
    img: wp.array(dtype=wp.vec3)  # rect light textures, rows top to bottom, concatenated
    links: Links  # light/shadow linking and shadow controls (``linking``)
    reach: Reach  # which lights a ray may reach: the area lights' tree, the infinite lights (``reach``)
    select: Selection  # which light a shading point samples (``select``)
    env: EnvMap  # the textured dome, if any (size[0] == 1 marks its light)
    dome_visible: int  # 1 when camera rays see a dome (alpha 1 there)
    lobe_mult: wp.array(dtype=wp.vec2)  # (inputs:diffuse, inputs:specular) per light
    rad_off: wp.array(dtype=wp.int32)  # first radiance key of a light animated within the shutter in rad_keys
    rad_count: wp.array(dtype=wp.int32)  # its number of keys (evenly spaced over the shutter), 0 = constant
    rad_keys: wp.array(dtype=wp.vec3)  # radiance keys, concatenated
    lobe_mults: int  # 1 when some light's multipliers are not (1, 1): the kernels split the BSDF by lobe


def _luminance(rgb) -> float:
    return float(0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2])


def scene_sphere(scene: Scene) -> tuple[np.ndarray, float]:
    """Centre and radius of a sphere around the scene's geometry at the shutter start (origin, 1 if empty)."""
    # each mesh's box once, then every instance's box corners placed in one batch
    boxes = np.array([np.stack(object_box(m, key=0)) if len(m.points[0]) else np.full((2, 3), np.nan)
                      for m in scene.meshes]).reshape(-1, 2, 3)
    insts = [i for i in scene.instances if len(scene.meshes[i.mesh].points[0])]
    if not insts:
        return np.zeros(3), 1.0
    b = boxes[[i.mesh for i in insts]]  # (N, 2, 3)
    lo, hi = placed_extent(matrices_at([i.transform for i in insts], 0.0), b[:, 0], b[:, 1])
    if not np.isfinite(lo).all():
        return np.zeros(3), 1.0
    return (lo + hi) / 2, float(max(0.5 * np.linalg.norm(hi - lo), 1e-6))


def delivered_irradiance(power: float, lum: float, light_pos: np.ndarray, centre: np.ndarray, radius: float):
    """Irradiance a finite light of ``power`` can deliver at the scene: power / (4 pi d^2), d at least the scene
    radius, capped at pi times its radiance ``lum``."""
    d2 = max(float(np.sum((light_pos - centre) ** 2)), radius * radius)
    return min(power / (4.0 * math.pi * d2), math.pi * lum)


def _axis_scales(xf) -> np.ndarray:
    m = matrix_at(xf, 0.0)
    return np.linalg.norm(m[:3, :3], axis=0)


def _shape_keys(sh: Shaping) -> tuple[tuple[float, ...], tuple[float, ...]]:
    return tuple((math.radians(sh.cone_angle[k]), sh.cone_softness[k], sh.focus[k], 1.0) for k in (0, 1))


def _shaped_fraction(sh: Shaping, one_sided: bool, faces=None) -> float:
    """Share of a light's power its shaping lets out (at the shutter's open), for light selection. ``faces``: a
    mesh light's (unit normals in its light frame, their power), which emit about their own normals."""
    k0, _ = _shape_keys(sh)
    ies = (sh.ies_angle_scale, sh.ies_scale)
    if faces is not None:
        return max(mean_face_shaping(k0, sh.focus_tint, sh.ies_grid, ies, *faces, two_sided=not one_sided), 1e-6)
    return max(mean_shaping(k0, sh.focus_tint, sh.ies_grid, ies, cosine_weighted=one_sided), 1e-6)


def light_frame_normals(points, triangles, inst_matrix, light_matrix) -> np.ndarray:
    """(n, 3) unit front-face normals of triangles (object-space ``points``) placed by ``inst_matrix``, in the
    frame of ``light_matrix`` (its unit axes, as ``sample.light_shaping`` measures directions): the side each
    emits from, by the inverse transpose as the kernels take it (a mirroring matrix does not flip it)."""
    p = np.asarray(points, np.float64)[triangles]
    a = np.asarray(inst_matrix, np.float64)[:3, :3]
    # det(a) a^-T by its cofactors: defined for a flattening (singular) matrix too, whose faces still emit
    cof = np.stack([np.cross(a[:, 1], a[:, 2]), np.cross(a[:, 2], a[:, 0]), np.cross(a[:, 0], a[:, 1])], 1)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) @ cof.T * (-1.0 if np.linalg.det(a) < 0 else 1.0)
    axes = np.asarray(light_matrix, np.float64)[:3, :3]
    return _unit(n @ (axes / np.maximum(np.linalg.norm(axes, axis=0), 1e-300)))


def _upload_shaping(lt: Lights, shapes: list, device: str) -> None:
    no = (math.pi, 0.0, 0.0, 0.0)
    s0, s1, tint, offs, params, grids = [], [], [], [], [], []
    at = 0
    for sh in shapes:
        if sh is None:
            s0.append(no), s1.append(no), tint.append((0.0, 0.0, 0.0)), offs.append(-1), params.append((0.0, 1.0))
            continue
        k0, k1 = _shape_keys(sh)
        s0.append(k0), s1.append(k1), tint.append(sh.focus_tint)
        params.append((sh.ies_angle_scale, sh.ies_scale))
        if sh.ies_grid is None:
            offs.append(-1)
        else:
            offs.append(at)
            grids.append(np.asarray(sh.ies_grid, np.float32).ravel())
            at += grids[-1].size
    v4 = lambda a: wp.array(np.array(a or [no], np.float32), dtype=wp.vec4, device=device)  # noqa: E731
    lt.shape0, lt.shape1 = v4(s0), v4(s1)
    lt.focus_tint = wp.array(np.array(tint or [(0, 0, 0)], np.float32), dtype=wp.vec3, device=device)
    lt.ies_off = wp.array(np.array(offs or [-1], np.int32), dtype=wp.int32, device=device)
    lt.ies_param = wp.array(np.array(params or [(0, 1)], np.float32), dtype=wp.vec2, device=device)
    lt.ies_table = wp.array(np.concatenate(grids) if grids else np.zeros(1, np.float32), dtype=wp.float32,
                            device=device)


def _upload_images(lt: Lights, images: list, device: str) -> None:
    offs, ws, hs, data = [], [], [], []
    at = 0
    for im in images:
        if im is None:
            offs.append(-1), ws.append(0), hs.append(0)
            continue
        im = np.asarray(im, np.float32)
        offs.append(at), ws.append(im.shape[1]), hs.append(im.shape[0])
        data.append(im.reshape(-1, 3))
        at += len(data[-1])
    i32 = lambda a, d: wp.array(np.array(a or [d], np.int32), dtype=wp.int32, device=device)  # noqa: E731
    lt.img_off, lt.img_w, lt.img_h = i32(offs, -1), i32(ws, 0), i32(hs, 0)
    lt.img = wp.array(np.concatenate(data) if data else np.zeros((1, 3), np.float32), dtype=wp.vec3, device=device)


def rect_frames(matrices, sizes) -> np.ndarray:
    """(n, 4, 3) float32: each light's rect (size width x height, centred, in its z = 0 plane, facing -z) in the
    world under its matrix: corner, edge along x, edge along y, emitting normal (``sample.rect_frame``)."""
    m = np.asarray(matrices, np.float64)
    wh = np.asarray(sizes, np.float64)[:, :2]
    ex = m[:, :3, 0] * wh[:, :1]
    ey = m[:, :3, 1] * wh[:, 1:2]
    corner = m[:, :3, 3] - 0.5 * ex - 0.5 * ey
    return np.stack([corner, ex, ey, emitting_sides(m)], 1).astype(np.float32)


def _unit(v: np.ndarray) -> np.ndarray:
    """(n, 3) float32: the rows of v at unit length (0 where a row is 0)."""
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0).astype(np.float32)


def z_axes(matrices) -> np.ndarray:
    """(n, 3) float32: each matrix's +z axis in the world, of unit length (0 where it has none)."""
    return _unit(np.asarray(matrices, np.float64)[:, :3, 2])


def emitting_sides(matrices) -> np.ndarray:
    """(n, 3) float32: the unit normal of each matrix's xy plane on the side its -z axis points to: the side a
    rect or disk light emits from ("along the -Z axis", usdLux). That is -(x axis x y axis), but for a mirroring
    matrix (negative determinant), whose x x y points away from its z (``sample.emitting_side``)."""
    m = np.asarray(matrices, np.float64)
    n = np.cross(m[:, :3, 0], m[:, :3, 1])
    side = np.where(np.einsum("ij,ij->i", n, m[:, :3, 2]) < 0.0, 1.0, -1.0)
    return _unit(n * side[:, None])


def centres(matrices, sizes) -> np.ndarray:
    """(n, 4) float32: each matrix's origin in the world and size[2] times the length of its x axis (the world
    radius of a sphere or disk light of that radius)."""
    m = np.asarray(matrices, np.float64)
    radius = np.asarray(sizes, np.float64)[:, 2] * np.linalg.norm(m[:, :3, 0], axis=1)
    return np.concatenate([m[:, :3, 3], radius[:, None]], 1).astype(np.float32)


def upload_lights(scene: Scene, device: str = "cpu", warn=lambda *a: None,
                  clusters: bool = True) -> tuple[Lights, int]:
    """Lights of a scene for the kernels; returns the struct and the number of lights."""
    (kinds, radiance, size, insts, cdfs, bases, counts, powers, transforms, shapes, sided, images, uniform, kept,
     estimates, mults, rad_keys) = ([] for _ in range(17))
    centre, radius = scene_sphere(scene)
    env_image, env_xf = None, np.eye(4)
    dome_visible = 0
    for light in scene.lights:
        rad = np.asarray(light.radiance, np.float64)
        if light.radiance_keys is not None:  # animated in the shutter: power and culling by its average
            rad = np.asarray(light.radiance_keys, np.float64).mean(0)
        phi = cap = ext = 0.0
        pos = np.zeros(3)
        lum = _luminance(rad)
        cdf = np.zeros(1, np.float32)
        first, count = 0, 0
        sz = (light.width, light.height, light.radius, light.length)
        sx, sy, _ = _axis_scales(light.transform)
        if light.kind == LIGHT_MESH:
            inst = scene.instances[light.instance]
            mesh = scene.meshes[inst.mesh]
            first, end = light.triangles or (0, len(mesh.triangles))
            count = end - first
            m = matrix_at(inst.transform, 0.0)
            pts = mesh.points[0].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
            tri = pts[mesh.triangles[first:end]]
            area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
            if light.uniform:  # MeshLightAPI: its own radiance, the same everywhere
                emis = np.full(count, lum)
            else:
                emis = np.array([_luminance(scene.materials[k].emissive_color)
                                 for k in mesh.material_ids[first:end]])
            tri_power = area * np.maximum(emis, 0.0)
            if count == 0 or not np.isfinite(tri_power).all() or tri_power.sum() <= 0:
                continue
            if light.shaping is not None:
                face_frames = (light_frame_normals(mesh.points[0], mesh.triangles[first:end], m,
                                                   matrix_at(light.transform, 0.0)), tri_power)
            cdf = (np.cumsum(tri_power) / tri_power.sum()).astype(np.float32)
            cdf[-1] = 1.0
            faces = 1.0 if light.one_sided else 2.0
            phi = faces * math.pi * tri_power.sum()  # pi L A per emitting face
            cap, pos = float(emis.max()), tri.mean((0, 1))
            ext = 0.5 * float(np.linalg.norm(tri.reshape(-1, 3).max(0) - tri.reshape(-1, 3).min(0)))
            power = delivered_irradiance(phi, cap, pos, centre, radius)
        elif light.kind == LIGHT_DISTANT:
            half = math.radians(max(0.0, light.angle) * 0.5)
            cos_max = math.cos(half) if half > 1e-6 else 1.0
            sz = (cos_max, 0.0, 0.0, 0.0)
            # the irradiance it delivers at normal incidence: radiance times the disk's pi sin^2 (delta: held)
            power = lum * (math.pi * (1.0 - cos_max * cos_max) if cos_max < 1.0 else 1.0)
        elif light.kind == LIGHT_DOME:
            dome_visible |= int(light.seen_by_camera())
            texture = getattr(light, "texture", None)
            sz = (0.0, 0.0, 0.0, 0.0)
            mean = lum
            if texture is not None and env_image is None:
                env_image, env_xf = np.asarray(texture, np.float32), matrix_at(light.transform, 0.0)
                sz = (1.0, 0.0, 0.0, 0.0)
                h = env_image.shape[0]
                cos_lat = np.cos(0.5 * np.pi - np.pi * (np.arange(h) + 0.5) / h)
                lum_img = env_image @ np.array([0.2126, 0.7152, 0.0722], np.float32)
                mean = float((lum_img * cos_lat[:, None]).sum() / (cos_lat.sum() * env_image.shape[1]))
                rad = np.ones(3)
            elif texture is not None:  # a second textured dome: its average colour
                rad = rad * np.asarray(texture, np.float64).reshape(-1, 3).mean(0)
                mean = _luminance(rad)
            power = math.pi * mean  # irradiance of a uniform dome of the mean radiance
        else:
            if light.kind == LIGHT_RECT:
                if light.texture is not None:  # the texture's mean scales the power
                    lum *= _luminance(np.asarray(light.texture, np.float64).reshape(-1, 3).mean(0))
                phi = lum * light.width * light.height * sx * sy * math.pi
            elif light.kind == LIGHT_DISK:
                phi = lum * math.pi * (light.radius * sx) ** 2 * math.pi
            elif light.kind == LIGHT_SPHERE:
                r = light.radius * sx
                phi = lum * 4.0 * math.pi * r * r * math.pi if r > 0 else lum * 4.0 * math.pi
            else:  # cylinder: length along local X, radius in Y/Z
                sz = (light.length, 0.0, light.radius, 0.0)
                phi = lum * 2.0 * math.pi * light.radius * sy * light.length * sx * math.pi
            point = light.kind == LIGHT_SPHERE and light.radius <= 0  # radiance holds an intensity: no cap
            cap, pos = (math.inf if point else lum), matrix_at(light.transform, 0.0)[:3, 3]
            ext = max(light.width * sx, light.height * sy) * 0.5 if light.kind == LIGHT_RECT else \
                light.length * sx * 0.5 if light.kind == LIGHT_CYLINDER else light.radius * sx
            power = delivered_irradiance(phi, cap, pos, centre, radius)
        if light.shaping is not None:
            one_sided = light.kind in (LIGHT_RECT, LIGHT_DISK) or (light.kind == LIGHT_MESH and light.one_sided)
            frac = _shaped_fraction(light.shaping, one_sided, face_frames if light.kind == LIGHT_MESH else None)
            power *= frac
            phi *= frac
        if not np.isfinite(rad).all() or (rad <= 0).all() or not power > 0:
            continue
        shapes.append(light.shaping)
        images.append(light.texture if light.kind == LIGHT_RECT else None)
        sided.append(int(light.one_sided))
        kept.append(light)
        uniform.append(int(light.kind == LIGHT_MESH and light.uniform))
        finite = light.kind not in (LIGHT_DISTANT, LIGHT_DOME)
        estimates.append(SelectEstimate(finite, phi if finite else power, cap if finite else math.inf,
                                        np.asarray(pos if finite else np.zeros(3), np.float64),
                                        float(ext) if finite else 0.0))
        kinds.append(light.kind)
        radiance.append(rad)
        size.append(sz)
        insts.append(light.instance)
        bases.append(first)
        counts.append(count)
        cdfs.append(cdf)
        powers.append(power)
        transforms.append(light.transform)
        mults.append((light.diffuse, light.specular))
        rad_keys.append(np.asarray(light.radiance_keys, np.float32).reshape(-1, 3)
                        if light.radiance_keys is not None else np.zeros((0, 3), np.float32))
    n = len(kinds)
    lt = Lights()
    lt.count = n
    i32 = lambda a, default: wp.array(np.array(a if len(a) else default, np.int32), dtype=wp.int32,  # noqa: E731
                                      device=device)
    lt.kind = i32(kinds, [LIGHT_DOME])
    lt.radiance = wp.array(np.array(radiance or [[0, 0, 0]], np.float32), dtype=wp.vec3, device=device)
    lt.size = wp.array(np.array(size or [[0, 0, 0, 0]], np.float32), dtype=wp.vec4, device=device)
    keys, offs, kcounts = upload_keys(transforms, device)
    lt.keys = keys
    lt.xf_off = i32(offs, [0])
    lt.xf_count = i32(kcounts, [1])
    still = matrices_at(transforms, 0.0) if transforms else np.eye(4)[None]
    lt.xf_still = wp.array(np.array(still, np.float32), dtype=wp.mat44, device=device)
    lt.rect_still = wp.array(rect_frames(still, size or [[0, 0, 0, 0]]).reshape(-1, 3), dtype=wp.vec3, device=device)
    lt.axis_still = wp.array(z_axes(still), dtype=wp.vec3, device=device)
    lt.centre_still = wp.array(centres(still, size or [[0, 0, 0, 0]]), dtype=wp.vec4, device=device)
    lt.disk_front_still = wp.array(emitting_sides(still), dtype=wp.vec3, device=device)
    p = np.array(powers or [1.0], np.float64)
    p = p / p.sum()
    counts_k = [len(k) for k in rad_keys]
    lt.rad_count = i32(counts_k, [0])
    lt.rad_off = i32(np.concatenate([[0], np.cumsum(counts_k)[:-1]]).astype(np.int32) if counts_k else [], [0])
    all_keys = np.concatenate(rad_keys) if counts_k and sum(counts_k) else np.zeros((1, 3), np.float32)
    lt.rad_keys = wp.array(all_keys.astype(np.float32), dtype=wp.vec3, device=device)
    lt.lobe_mult = wp.array(np.array(mults or [(1.0, 1.0)], np.float32), dtype=wp.vec2, device=device)
    lt.lobe_mults = int(any(m != (1.0, 1.0) for m in mults))
    lt.select_pdf = wp.array(p.astype(np.float32), dtype=wp.float32, device=device)
    lt.instance = i32(insts, [-1])
    inst_light = np.full(max(1, len(scene.instances)), -1, np.int32)
    for li, (k, inst) in enumerate(zip(kinds, insts)):
        if k == LIGHT_MESH:
            inst_light[inst] = li
    lt.inst_light = wp.array(inst_light, dtype=wp.int32, device=device)
    lt.one_sided = i32(sided, [0])
    lt.uniform = i32(uniform, [0])
    lt.tri_base = i32(bases, [0])
    lt.tri_count = i32(counts, [0])
    lens = [len(c) for c in cdfs] or [1]
    lt.cdf = wp.array(np.concatenate(cdfs) if cdfs else np.zeros(1, np.float32), dtype=wp.float32,
                      device=device)
    lt.cdf_off = i32(np.cumsum([0] + lens[:-1]), [0])
    _upload_shaping(lt, shapes, device)
    _upload_images(lt, images, device)
    lt.links = upload_links(kept, len(scene.instances), device, warn)
    lt.select = upload_selection(estimates, device, clusters=clusters)
    seen = [k in AREA_KINDS and light.seen_by_camera() and not (k == LIGHT_SPHERE and sz[2] <= 0.0)
            for k, light, sz in zip(kinds, kept, size)]
    lt.reach = upload_reach(kinds, size, transforms, still, device, seen=seen)
    lt.env = upload_envmap(env_image, env_xf, device)
    lt.dome_visible = int(dome_visible)
    return lt, n
