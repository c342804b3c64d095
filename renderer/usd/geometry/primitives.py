"""Implicit primitives (Sphere, Cube, Cylinder, Cone, Capsule, Plane) as triangles, or as exact shapes.

Tessellated as surfaces of revolution about +Z, then turned to their axis. A still prim the renderer can intersect
exactly becomes its ``AnalyticShape`` and a one-triangle stand-in whose tessellation is made only on demand; a Cube
with authored texture coordinates is tessellated as Hydra's cube mesh, which those coordinates refer to.
"""
from __future__ import annotations

import functools

import numpy as np

from renderer.scene.analytic import shape_bounds
from renderer.scene.model import AnalyticShape
from renderer.usd.geometry.mesh import GeomData
from renderer.motion.shutter import Shutter
from renderer.usd.motion import collapse_keys, samples_in_shutter
from renderer.usd.geometry.primvars import CUBE_COUNTS, CUBE_INDICES, CUBE_POINTS, expand_primvar, read_uv_primvar
from renderer.usd.reads import reads
from renderer.usd.geometry.triangulation import triangulate

SPHERE_SEGMENTS = 64  # around the axis
SPHERE_RINGS = 32  # pole to pole
PRIMITIVE_TYPES = ("Sphere", "Cube", "Cylinder", "Cylinder_1", "Cone", "Capsule", "Capsule_1", "Plane")


def _lathe(polylines, segments: int):
    """Revolve profile polylines [(r, z, nr, nz), ...] about +Z. Returns (points, triangles, vertex normals)."""
    pts, nrm, tris = [], [], []
    th = 2.0 * np.pi * np.arange(segments) / segments
    c, s = np.cos(th), np.sin(th)
    base = 0
    for line in polylines:
        prof = np.asarray(line, np.float64)  # (m, 4)
        m = len(prof)
        r, z, nr, nz = prof[:, 0:1], prof[:, 1:2], prof[:, 2:3], prof[:, 3:4]
        p = np.stack([r * c, r * s, np.broadcast_to(z, (m, segments))], -1).reshape(-1, 3)
        n = np.stack([nr * c, nr * s, np.broadcast_to(nz, (m, segments))], -1).reshape(-1, 3)
        j, k = np.meshgrid(np.arange(m - 1), np.arange(segments), indexing="ij")
        a = base + j * segments + k
        b = base + j * segments + (k + 1) % segments
        cc = b + segments
        d = a + segments
        t = np.concatenate([np.stack([a, b, cc], -1).reshape(-1, 3), np.stack([a, cc, d], -1).reshape(-1, 3)])
        pts.append(p)
        nrm.append(n)
        tris.append(t)
        base += len(p)
    p = np.concatenate(pts)
    n = np.concatenate(nrm)
    t = np.concatenate(tris)
    area = np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)
    t = t[area > 1e-12 * max(1.0, float(np.abs(p).max()) ** 2)]  # drop the degenerate pole triangles
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = n / np.where(ln > 0, ln, 1.0)
    return p, t, n


def _arc(radius: float, z0: float, a0: float, a1: float, steps: int):
    """Profile of a circular arc (latitude a0 -> a1, radians) of a sphere centred at z0."""
    a = np.linspace(a0, a1, steps + 1)
    return [(radius * np.cos(x), z0 + radius * np.sin(x), np.cos(x), np.sin(x)) for x in a]


def _sphere(radius: float):
    return _lathe([_arc(radius, 0.0, -np.pi / 2, np.pi / 2, SPHERE_RINGS)], SPHERE_SEGMENTS)


def _frustum(r_bottom: float, r_top: float, height: float, bottom_cap: bool = True, top_cap: bool = True):
    h = 0.5 * height
    slope = np.array([height, r_bottom - r_top])
    slope = slope / (np.linalg.norm(slope) or 1.0)
    lines = [[(r_bottom, -h, slope[0], slope[1]), (r_top, h, slope[0], slope[1])]]
    if bottom_cap and r_bottom > 0:
        lines.append([(0.0, -h, 0.0, -1.0), (r_bottom, -h, 0.0, -1.0)])
    if top_cap and r_top > 0:
        lines.append([(r_top, h, 0.0, 1.0), (0.0, h, 0.0, 1.0)])
    return _lathe(lines, SPHERE_SEGMENTS)


def _capsule(r_bottom: float, r_top: float, height: float):
    h = 0.5 * height
    q = SPHERE_RINGS // 2
    line = _arc(r_bottom, -h, -np.pi / 2, 0.0, q) + _arc(r_top, h, 0.0, np.pi / 2, q)
    return _lathe([line], SPHERE_SEGMENTS)


def _cube(size: float):
    h = 0.5 * size
    pts, nrm, tris = [], [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            u, v = (axis + 1) % 3, (axis + 2) % 3
            n = np.zeros(3)
            n[axis] = sign
            quad = []
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = np.zeros(3)
                p[axis], p[u], p[v] = sign * h, a * h, b * h
                quad.append(p)
            base = len(pts)
            pts += quad
            nrm += [n] * 4
            t = [(0, 1, 2), (0, 2, 3)] if sign > 0 else [(0, 2, 1), (0, 3, 2)]
            tris += [(base + i, base + j, base + k) for i, j, k in t]
    return np.array(pts), np.array(tris, np.int64), np.array(nrm)


def _cube_with_uvs(prim, frame: float, keys: list[np.ndarray], perm, warn):
    """(triangles, corner normals, corner uvs, per-key points) of a Cube whose texture coordinates are authored,
    tessellated as Hydra's cube mesh so the primvar lines up; None when it has none that fit."""
    hit = read_uv_primvar(prim, frame, warn)
    if hit is None:
        return None
    corners, tri_faces = triangulate(CUBE_COUNTS, CUBE_INDICES, CUBE_POINTS)
    uvs = expand_primvar(hit[0], hit[1], corners, tri_faces, CUBE_INDICES, len(CUBE_COUNTS), len(CUBE_POINTS))
    if uvs is None or uvs.shape[-1] != 2:
        warn("texture coordinates with a size that does not match their interpolation ignored", str(prim.GetPath()))
        return None
    tris = CUBE_INDICES[corners]
    sizes = [float(np.abs(k).max()) * 2.0 for k in keys]  # the size at each key (the generic cube spans +-size/2)
    points = [(CUBE_POINTS * size)[:, perm] for size in sizes]
    p = points[0][tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    return tris, np.repeat(n[:, None, :], 3, axis=1), uvs, points, tri_faces


def _plane(width: float, length: float):
    w, l = 0.5 * width, 0.5 * length
    p = np.array([(-w, -l, 0), (w, -l, 0), (w, l, 0), (-w, l, 0)], np.float64)
    return p, np.array([(0, 1, 2), (0, 2, 3)], np.int64), np.tile([0.0, 0.0, 1.0], (4, 1))


_AXIS_PERM = {"Z": [0, 1, 2], "X": [2, 0, 1], "Y": [1, 2, 0]}  # cyclic permutations are rotations: +Z -> axis


def _get(prim, name: str, t: float, default):
    a = prim.GetAttribute(name)
    v = a.Get(t) if a else None
    return default if v is None else v


@reads("Sphere", "radius")
@reads("Cube", "size")
@reads("Cylinder", "radius", "height", "axis")
@reads("Cylinder_1", "radiusBottom", "radiusTop", "height", "axis")
@reads("Cone", "radius", "height", "axis")
@reads("Capsule", "radius", "height", "axis")
@reads("Capsule_1", "radiusBottom", "radiusTop", "height", "axis")
@reads("Plane", "width", "length", "axis")
@reads("Gprim", "doubleSided")
def _primitive_params(prim, t: float) -> tuple:
    kind = prim.GetTypeName()
    g = lambda n, d: float(_get(prim, n, t, d))  # noqa: E731
    if kind == "Sphere":
        return (g("radius", 1.0),)
    if kind == "Cube":
        return (g("size", 2.0),)
    if kind in ("Cylinder", "Capsule"):
        r = g("radius", 0.5 if kind == "Capsule" else 1.0)
        return (r, r, g("height", 1.0 if kind == "Capsule" else 2.0))
    if kind in ("Cylinder_1", "Capsule_1"):
        return (g("radiusBottom", 1.0 if kind == "Cylinder_1" else 0.5),
                g("radiusTop", 1.0 if kind == "Cylinder_1" else 0.5),
                g("height", 2.0 if kind == "Cylinder_1" else 1.0))
    if kind == "Cone":
        return (g("radius", 1.0), 0.0, g("height", 2.0))
    if kind == "Plane":
        return (g("width", 2.0), g("length", 2.0))
    raise ValueError(kind)


def _analytic_shape(kind: str, params: tuple, perm: list[int]) -> AnalyticShape | None:
    """The exact shape of a still implicit prim (``Mesh.shape``), or None for those drawn only as triangles: planes
    and cubes (flat already), tapered capsules (``Capsule_1`` with two radii), degenerate sizes."""
    axis = perm.index(2)  # the tessellation's Z spine lands on this object axis
    if kind == "Sphere":
        return AnalyticShape("sphere", float(params[0])) if params[0] > 0 else None
    if kind in ("Cylinder", "Cylinder_1", "Cone"):
        rb, rt, h = (float(x) for x in params)
        return AnalyticShape("frustum", rb, rt, h, axis) if h > 0 and max(rb, rt) > 0 else None
    if kind in ("Capsule", "Capsule_1"):
        rb, rt, h = (float(x) for x in params)
        return AnalyticShape("capsule", rb, rb, h, axis) if rb == rt and rb > 0 and h >= 0 else None
    return None


def _tessellate(kind: str, params: tuple):
    if kind == "Sphere":
        return _sphere(*params)
    if kind == "Cube":
        return _cube(*params)
    if kind in ("Cylinder", "Cylinder_1", "Cone"):
        return _frustum(*params)
    if kind in ("Capsule", "Capsule_1"):
        return _capsule(*params)
    return _plane(*params)


_PRIMITIVE_ATTRS = ("radius", "size", "height", "radiusTop", "radiusBottom", "width", "length")


def primitive_signature(prim, frame: float) -> tuple | None:
    """A hashable description of a static implicit primitive (equal signatures tessellate identically), or None
    for meshes and animated primitives."""
    kind = prim.GetTypeName()
    if kind not in PRIMITIVE_TYPES:
        return None
    for name in _PRIMITIVE_ATTRS:
        a = prim.GetAttribute(name)
        if a and a.ValueMightBeTimeVarying():
            return None
    try:
        params = _primitive_params(prim, frame)
    except (TypeError, ValueError):
        return None
    return (kind, params, str(_get(prim, "axis", frame, "Z")), bool(_get(prim, "doubleSided", frame, False)))


def read_primitive(prim, shutter: Shutter, warn) -> GeomData | None:
    """Tessellate a Sphere/Cube/Cylinder/Cone/Capsule/Plane (attribute-animated sizes become point keys)."""
    kind = prim.GetTypeName()
    frame = shutter.frame
    samples: list[float] = []
    for name in _PRIMITIVE_ATTRS:
        a = prim.GetAttribute(name)
        if a and a.ValueMightBeTimeVarying():
            samples += samples_in_shutter(shutter, a) + [shutter.open, shutter.close]
    times = shutter.keys(samples) if samples else np.array([frame])
    perm = _AXIS_PERM.get(str(_get(prim, "axis", frame, "Z")), _AXIS_PERM["Z"])
    if len(times) == 1 and kind != "Cube":
        params = _primitive_params(prim, frame)
        shape = _analytic_shape(kind, params, perm) if all(np.isfinite(params)) and min(params) >= 0 else None
        if shape is not None:  # the renderer will most likely intersect the shape itself: triangles on demand
            return _stand_in(kind, params, perm, shape, bool(_get(prim, "doubleSided", frame, False)), frame)
    keys = []
    tris = nrm = None
    for t in times:
        params = _primitive_params(prim, float(t))
        if not all(np.isfinite(params)) or min(params) < 0:
            warn("primitives with invalid sizes skipped", str(prim.GetPath()))
            return None
        p, tris, nrm = _tessellate(kind, params)
        keys.append(p[:, perm])
    nrm = nrm[:, perm]
    if len(tris) == 0:
        warn("primitives of zero size skipped", str(prim.GetPath()))
        return None
    ds = _get(prim, "doubleSided", frame, kind == "Plane")
    textured = _cube_with_uvs(prim, frame, keys, perm, warn) if kind == "Cube" else None
    if textured is not None:  # Hydra's cube mesh, which the authored texture coordinates refer to
        tris, corner_normals, uvs, keys, tri_faces = textured
        times, pts = collapse_keys(np.asarray(times), np.stack(keys).astype(np.float32))
        return GeomData(point_times=times, points=np.ascontiguousarray(pts),
                        triangles=np.ascontiguousarray(tris, np.int32), tri_faces=tri_faces,
                        num_faces=len(CUBE_COUNTS), normals=np.ascontiguousarray(corner_normals, np.float32),
                        uvs=np.ascontiguousarray(uvs, np.float32), double_sided=bool(ds))
    times, pts = collapse_keys(np.asarray(times), np.stack(keys).astype(np.float32))
    return GeomData(
        point_times=times,
        points=np.ascontiguousarray(pts),
        triangles=np.ascontiguousarray(tris, np.int32),
        tri_faces=np.zeros(len(tris), np.int64),
        num_faces=1,
        normals=np.ascontiguousarray(nrm[tris], np.float32),
        uvs=None,
        double_sided=bool(ds),
        shape=_analytic_shape(kind, _primitive_params(prim, frame), perm) if len(times) == 1 else None,
    )


def tessellate_primitive(kind: str, params: tuple, perm: tuple):
    """The triangles ``read_primitive`` makes of a still implicit prim, as ``Mesh.tessellate`` returns them: points
    (1, V, 3) float32, triangles (T, 3) int32, per-corner normals (T, 3, 3) float32, origin (T,) (all from the
    stand-in's one triangle), solid None (derived from the triangles)."""
    p, tris, nrm = _tessellate(kind, params)
    points = p[:, list(perm)][None].astype(np.float32)
    return (np.ascontiguousarray(points), np.ascontiguousarray(tris, np.int32),
            np.ascontiguousarray(nrm[:, list(perm)][tris], np.float32), np.zeros(len(tris), np.int64), None)


def _stand_in(kind: str, params: tuple, perm: list[int], shape: AnalyticShape, double_sided: bool,
              frame: float) -> GeomData:
    """A still implicit prim as its exact shape and a one-triangle stand-in: the corners of the shape's box as
    points (so bounds are right), one triangle that carries the material, solid (the shape is closed). Its
    tessellation (``tessellate_primitive``, 1-2 ms and ~0.4 MB for 4032 triangles) is made only if something
    needs triangles (``Mesh.realize``): 10^4 spheres of distinct radii were 40 M triangles before."""
    lo, hi = shape_bounds(shape)
    corners = np.array([[(hi if (i >> a) & 1 else lo)[a] for a in range(3)] for i in range(8)], np.float32)
    return GeomData(
        point_times=np.array([frame]),
        points=corners[None],
        triangles=np.array([[0, 1, 3]], np.int32),
        tri_faces=np.zeros(1, np.int64),
        num_faces=1,
        double_sided=double_sided,
        shape=shape,
        solid=np.ones(1, bool),
        tessellate=functools.partial(tessellate_primitive, kind, tuple(params), tuple(perm)),
    )
