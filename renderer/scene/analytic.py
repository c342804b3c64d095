"""Which meshes the renderer intersects as the exact implicit prims they tessellate.

A UsdGeomSphere, Cylinder, Cone or Capsule is a quadric (pieces of quadrics and planes): RenderMan, Karma and
Arnold intersect them exactly, so silhouettes and shading are smooth at any distance, and a ray pays a quadratic or
two instead of a walk over thousands of triangles (the README demo's three spheres were 4032 triangles each). The
tessellation stays in the scene for everything that needs triangles, so a prim is analytic only where nothing reads
those triangles at a hit:

* its size holds over the shutter (``Mesh.shape`` is set; transforms may move it);
* it carries no per-corner data a hit would interpolate: texture coordinates or a varying displayColor;
* it is not an emitter (mesh lights sample its triangles, whose pdf must match what rays hit);
* it is not a CSG operand (the CSG walks classify crossings triangle by triangle).

A ``Points`` prim is a cloud of exact spheres (kind "points", ``Mesh.point_radii``), or of exact discs facing its
authored normals (kind "discs", the normals in ``Mesh.normals``): each point is a leaf primitive of its mesh's tree,
moving with its point keys, with a colour of its own.

A still implicit prim is imported as its shape and a one-triangle stand-in; its tessellation is made only for the
meshes the rules above keep as triangles (``realize_tessellations``).
"""
from __future__ import annotations

import numpy as np

from renderer.scene.model import LIGHT_MESH, AnalyticShape, Scene

SHAPE_BOX_PAD = 1.0 + 1e-5  # a shape's box, relative to its size: float32 rounding never clips it
# Shape codes of the kernels (``accel.analytic``); 0: a triangle mesh
SHAPE_CODES = {"sphere": 1, "frustum": 2, "capsule": 3, "points": 4, "discs": 5}
CLOUD_KINDS = ("points", "discs")  # a mesh of many small shapes, one per point (``Mesh.point_radii``)


def analytic_shapes(scene: Scene) -> list[AnalyticShape | None]:
    """Per mesh, the shape the renderer intersects in place of its triangles, or None."""
    shapes = [m.shape if _usable(m) else None for m in scene.meshes]
    for light in scene.lights:
        if light.kind == LIGHT_MESH and 0 <= light.instance < len(scene.instances):
            shapes[scene.instances[light.instance].mesh] = None
    for inst in scene.instances:
        if inst.csg_group >= 0:
            shapes[inst.mesh] = None
    return shapes


def _usable(m) -> bool:
    """The mesh's own conditions (the scene's are in ``analytic_shapes``). A point cloud's spheres may move point
    by point and carry a colour each (a hit reads its point's); it must still be the spheres, not realized."""
    if m.shape is None or m.uvs is not None:
        return False
    if m.shape.kind in CLOUD_KINDS:
        return m.point_radii is not None
    return not m.deforming and m.colors is None


def object_box(mesh, key: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Object-space box (lo, hi) float64 of a mesh over its point keys (or at one ``key``), a point cloud's
    spheres included."""
    flat = (mesh.points if key is None else mesh.points[key]).reshape(-1, 3)
    pad = float(mesh.point_radii.max()) if mesh.point_radii is not None and len(mesh.point_radii) else 0.0
    return flat.min(axis=0).astype(np.float64) - pad, flat.max(axis=0).astype(np.float64) + pad


def realize_tessellations(scene: Scene) -> Scene:
    """Give every mesh the renderer will not intersect as its shape its real triangles (``Mesh.realize``): a
    stand-in's shape can stop being usable after import (a light or a CSG group made of it). Idempotent."""
    for mesh, shape in zip(scene.meshes, analytic_shapes(scene)):
        if shape is None and mesh.tessellate is not None:
            mesh.realize()
    return scene


def shape_bounds(shape: AnalyticShape) -> tuple[np.ndarray, np.ndarray]:
    """Object-space box (lo, hi) of a shape, float64."""
    if shape.kind == "sphere":
        half = np.full(3, shape.radius_bottom)
    else:
        half = np.full(3, max(shape.radius_bottom, shape.radius_top))
        half[shape.axis] = 0.5 * shape.height + (shape.radius_bottom if shape.kind == "capsule" else 0.0)
    return -half, half


def shape_world_boxes(shape: AnalyticShape, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exact world boxes (lo, hi), (N, 3) float64, of a shape under column-vector matrices m (N, 4, 4), padded by
    1e-5 of their size for float32 rounding. The box of the shape's object box's corners is up to sqrt 3 times wider
    per axis for a rotated sphere; these are what the shape reaches: a sphere's support along world axis i is
    r |A_i| (A the linear part, A_i its row i), a disc's of radius r around spine e is r |A_i with its e part
    removed|, and a capsule is its spine swept by a sphere."""
    m = np.asarray(m, np.float64).reshape(-1, 4, 4)
    a = m[:, :3, :3]
    centre = m[:, :3, 3]
    row = np.linalg.norm(a, axis=2)  # |A_i|, (N, 3)
    if shape.kind == "sphere":
        half = shape.radius_bottom * row
        lo, hi = centre - half, centre + half
    else:
        spine = a[:, :, shape.axis] * (0.5 * shape.height)  # the world offset of the spine's top end
        if shape.kind == "capsule":
            half = np.abs(spine) + shape.radius_bottom * row
            lo, hi = centre - half, centre + half
        else:  # a frustum: the hull of its two end discs
            across = np.sqrt(np.maximum(row ** 2 - a[:, :, shape.axis] ** 2, 0.0))
            bottom, top = centre - spine, centre + spine
            lo = np.minimum(bottom - shape.radius_bottom * across, top - shape.radius_top * across)
            hi = np.maximum(bottom + shape.radius_bottom * across, top + shape.radius_top * across)
    pad = (SHAPE_BOX_PAD - 1.0) * (np.abs(centre) + (hi - lo))
    return lo - pad, hi + pad


def shape_table(shapes: list[AnalyticShape | None]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per mesh the kernels' shape code (0: triangles), axis, and (radius_bottom, radius_top, height / 2, 0)."""
    codes = np.array([SHAPE_CODES[s.kind] if s is not None else 0 for s in shapes], np.int32)
    axes = np.array([s.axis if s is not None else 0 for s in shapes], np.int32)
    params = np.array([(s.radius_bottom, s.radius_top, 0.5 * s.height, 0.0) if s is not None else (0, 0, 0, 0)
                       for s in shapes], np.float32).reshape(-1, 4)
    return codes, axes, params
