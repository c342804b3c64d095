"""UsdGeomMesh subdivision surfaces: the schema's attributes read into ``renderer.subdiv``, the refinement level
chosen from the camera, and the refined triangles, limit points (every motion key), normals and texture
coordinates that ``renderer.usd.geometry.mesh.read_mesh`` returns.

Level: with a camera, the smallest level whose edges project to at most ``EDGE_PIXELS`` (95th percentile of the
cage's edges, each at its own distance from the camera), between 1 and ``MAX_AUTO_LEVEL``; without one
``DEFAULT_LEVEL``; a fixed level when asked. Any level is lowered until the mesh stays under ``MAX_TRIANGLES``.
Authored normals are ignored on subdivision surfaces (the schema: the surface defines its own); shading normals
come from the key nearest the frame. ``vertex`` texture coordinates are refined with the surface's own rules,
``varying`` ones linearly, ``faceVarying`` ones by ``faceVaryingLinearInterpolation`` (with the surface's
authored creases and corners).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pxr import UsdGeom

from renderer.subdiv import FVAR_MODES, MAX_LEVEL, SubdivOptions, subdivide, topology, triangle_count
from renderer.usd.reads import reads

EDGE_PIXELS = 4.0  # target projected length of a refined edge, pixels
DEFAULT_LEVEL = 2  # no camera to measure from
MAX_AUTO_LEVEL = 4
MAX_TRIANGLES = 4_000_000  # per mesh, after refinement
SUBDIV_SCHEMES = ("catmullClark", "loop", "bilinear")


@dataclass(frozen=True)
class SubdivisionDetail:
    """How finely subdivision surfaces are refined: a fixed ``level``, or from the camera."""

    level: int | None = None
    camera_position: tuple[float, float, float] | None = None  # world, at the frame
    pixels_per_radian: float | None = None  # perspective: image width * focal length / horizontal aperture
    pixels_per_unit: float | None = None  # orthographic: image width / horizontal aperture
    edge_pixels: float = EDGE_PIXELS
    max_triangles: int = MAX_TRIANGLES

    def edge_length_px(self, world_points: np.ndarray, edges: np.ndarray) -> float | None:
        """95th percentile of the projected lengths of the cage's edges, pixels (None: no camera)."""
        if len(edges) == 0:
            return None
        a, b = world_points[edges[:, 0]], world_points[edges[:, 1]]
        length = np.linalg.norm(a - b, axis=1)
        if self.pixels_per_unit is not None:
            px = length * self.pixels_per_unit
        elif self.pixels_per_radian is not None and self.camera_position is not None:
            size = float(np.linalg.norm(np.ptp(world_points, axis=0))) or 1.0
            dist = np.linalg.norm(0.5 * (a + b) - np.asarray(self.camera_position), axis=1)
            px = length / np.maximum(dist, 1e-3 * size) * self.pixels_per_radian
        else:
            return None
        return float(np.percentile(px, 95))

    def choose(self, counts: np.ndarray, scheme: str, world_points: np.ndarray, edges: np.ndarray) -> int:
        if self.level is not None:
            level = int(self.level)
        else:
            px = self.edge_length_px(world_points, edges)
            if px is None:
                level = DEFAULT_LEVEL
            else:
                level = math.ceil(math.log2(max(px, 1e-9) / self.edge_pixels))
                level = min(max(level, 1), MAX_AUTO_LEVEL)
        return self.capped(counts, scheme, min(max(level, 0), MAX_LEVEL))

    def capped(self, counts: np.ndarray, scheme: str, level: int) -> int:
        """The highest level up to ``level`` that keeps the mesh under ``max_triangles``."""
        while level > 0 and triangle_count(counts, scheme, level) > self.max_triangles:
            level -= 1
        return level


@reads("Mesh", "interpolateBoundary", "faceVaryingLinearInterpolation", "triangleSubdivisionRule", "creaseIndices",
       "creaseLengths", "creaseSharpnesses", "cornerIndices", "cornerSharpnesses")
def options(mesh: UsdGeom.Mesh, frame: float, scheme: str) -> SubdivOptions:
    """The mesh's subdivision attributes (unknown tokens fall back to USD's defaults)."""
    def get(attr, default):
        v = attr.Get(frame) if attr else None
        return default if v is None else v

    boundary = str(get(mesh.GetInterpolateBoundaryAttr(), "edgeAndCorner"))
    fvar = str(get(mesh.GetFaceVaryingLinearInterpolationAttr(), "cornersPlus1"))
    arr = lambda attr, dt: np.asarray(get(attr, []), dt).reshape(-1)  # noqa: E731
    return SubdivOptions(
        scheme=scheme,
        interpolate_boundary=boundary if boundary in ("none", "edgeOnly", "edgeAndCorner") else "edgeAndCorner",
        fvar_linear=fvar if fvar in FVAR_MODES else "cornersPlus1",
        triangle_smooth=str(get(mesh.GetTriangleSubdivisionRuleAttr(), "catmullClark")) == "smooth",
        crease_indices=arr(mesh.GetCreaseIndicesAttr(), np.int64),
        crease_lengths=arr(mesh.GetCreaseLengthsAttr(), np.int64),
        crease_sharpnesses=arr(mesh.GetCreaseSharpnessesAttr(), np.float64),
        corner_indices=arr(mesh.GetCornerIndicesAttr(), np.int64),
        corner_sharpnesses=arr(mesh.GetCornerSharpnessesAttr(), np.float64),
    )


def crease_problem(opts: SubdivOptions) -> str | None:
    """What is inconsistent in the crease and corner attributes (renderer.subdiv then ignores them), or None."""
    lengths, idx, sharp = opts.crease_lengths, opts.crease_indices, opts.crease_sharpnesses
    if len(lengths) or len(idx) or len(sharp):
        if np.any(lengths < 2) or int(lengths.sum()) != len(idx) or \
                len(sharp) not in (len(lengths), int(np.sum(lengths - 1))):
            return "creases whose creaseLengths, creaseIndices and creaseSharpnesses do not agree"
    if len(opts.corner_indices) != len(opts.corner_sharpnesses):
        return "corners whose cornerIndices and cornerSharpnesses differ in length"
    return None


@dataclass
class Refined:
    points: np.ndarray  # (P, V, 3) float32 limit points per key
    triangles: np.ndarray  # (T, 3) int32
    tri_faces: np.ndarray  # (T,) int64 authored faces
    normals: np.ndarray  # (T, 3, 3) float32
    uvs: np.ndarray | None  # (T, 3, 2) float32
    level: int


def _face_varying_ids(values: np.ndarray, indices: np.ndarray | None, vertex_of_corner: np.ndarray):
    """(values, index per authored corner) with corners that share a vertex and a value sharing one index, so
    the refinement sees UV islands, not one island per face."""
    if indices is not None:
        return values, indices
    v = np.asarray(values, np.float64)
    key = np.concatenate([vertex_of_corner[:, None].astype(np.float64), v.reshape(len(v), -1)], axis=1)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return v[first], inv.reshape(-1)


def refine(mesh: UsdGeom.Mesh, frame: float, scheme: str, counts: np.ndarray, fvi: np.ndarray, keys: np.ndarray,
           holes: np.ndarray, uv, detail: SubdivisionDetail | None, world: np.ndarray | None, warn,
           frame_key: int = 0) -> Refined | None:
    """Refine a subdivision-surface mesh whose topology was checked by the caller (faces of < 3 vertices are
    left out). ``keys``: (P, V, 3) cage points per motion key. ``uv``: (values, indices or None,
    interpolation) of its texture coordinates, or None. ``world``: row-vector object-to-world matrix at the
    frame, for the level; None: no camera-based level. ``frame_key``: the key the shading normals come from."""
    path = str(mesh.GetPath())
    opts = options(mesh, frame, scheme)
    problem = crease_problem(opts)
    if problem:
        warn(f"subdivision {problem}: ignored", path)
    counts = np.asarray(counts, np.int64)
    fvi = np.asarray(fvi, np.int64)
    nf = len(counts)
    face_of_corner = np.repeat(np.arange(nf), counts)
    valid = counts >= 3
    corner_ok = valid[face_of_corner]
    corner_map = np.flatnonzero(corner_ok)  # authored corner of every corner given to the refinement
    sub_counts, base_face = counts[valid], np.flatnonzero(valid)
    if scheme == "loop" and np.any(sub_counts != 3):
        from_geometry = _fan(sub_counts)
        corner_map = corner_map[from_geometry]
        base_face = np.repeat(base_face, sub_counts - 2)
        sub_counts = np.full(len(base_face), 3, np.int64)
        warn("Loop subdivision of faces that are not triangles: fanned into triangles first", path)
    sub_idx = fvi[corner_map]
    if len(sub_counts) == 0:
        return None
    edges = topology.build(sub_counts, sub_idx, len(keys[0])).edge_vertices
    cage = keys[frame_key].astype(np.float64)
    world_pts = cage if world is None else cage @ world[:3, :3] + world[3, :3]
    detail = detail or SubdivisionDetail()
    if world is None and detail.level is None:
        detail = SubdivisionDetail(level=DEFAULT_LEVEL, max_triangles=detail.max_triangles)
    level = detail.choose(sub_counts, scheme, world_pts, edges)
    if detail.level is not None and level < detail.level:
        warn(f"subdivision level lowered to {level} to stay under {detail.max_triangles:,} triangles", path)
    ref = subdivide(sub_counts, sub_idx, len(cage), opts, level, base_face)
    keep = ~np.isin(ref.tri_faces, holes) if len(holes) else np.ones(len(ref.tri_faces), bool)
    if not np.any(keep):
        return None
    pts = np.stack([ref.points(k) for k in keys])
    normals = ref.normals(pts[frame_key], ref.control_points(keys[frame_key]))[keep]
    uvs = None
    if uv is not None:
        uvs = _refine_uv(ref, uv, opts.fvar_linear, corner_map, fvi, nf, len(cage), warn, path)
        uvs = None if uvs is None else uvs[keep]
    tris = ref.triangles[keep]
    normals = _fill_degenerate_normals(normals, pts[frame_key][tris])
    if not np.all(np.isfinite(pts)):
        warn("subdivision produced non-finite points; mesh skipped", path)
        return None
    return Refined(pts.astype(np.float32), tris.astype(np.int32), ref.tri_faces[keep],
                   normals.astype(np.float32), None if uvs is None else uvs.astype(np.float32), level)


def _fill_degenerate_normals(normals: np.ndarray, tri_xyz: np.ndarray) -> np.ndarray:
    """Zero-length normals (collapsed cage faces) replaced by the triangle's own normal, else +z: never NaN."""
    ln = np.linalg.norm(normals, axis=2)
    if np.all(ln > 1e-12):
        return normals
    g = np.cross(tri_xyz[:, 1] - tri_xyz[:, 0], tri_xyz[:, 2] - tri_xyz[:, 0])
    lg = np.linalg.norm(g, axis=1, keepdims=True)
    g = np.where(lg > 1e-30, g / np.where(lg > 1e-30, lg, 1.0), np.array([0.0, 0.0, 1.0]))
    return np.where((ln > 1e-12)[..., None], normals, g[:, None, :])


def _fan(counts: np.ndarray) -> np.ndarray:
    """Corner positions (into the faces' corner list) of a fan triangulation of every face."""
    start = np.cumsum(counts) - counts
    face = np.repeat(np.arange(len(counts)), counts - 2)
    k = np.arange(len(face)) - np.repeat(np.cumsum(counts - 2) - (counts - 2), counts - 2)
    out = np.stack([start[face], start[face] + k + 1, start[face] + k + 2], axis=1)
    return out.reshape(-1)


def _refine_uv(ref, uv, fvar_mode: str, corner_map, fvi, num_faces: int, num_points: int, warn, path):
    values, indices, interp = uv
    values = np.asarray(values, np.float64).reshape(len(values), -1)
    if interp == UsdGeom.Tokens.faceVarying:
        if indices is None:
            if len(values) < len(fvi):
                warn("texture coordinates with a size that does not match their interpolation ignored", path)
                return None
            vals, ids = _face_varying_ids(values[: len(fvi)], None, fvi)
        else:
            ids = np.asarray(indices, np.int64)
            if len(ids) < len(fvi) or ids.min(initial=0) < 0 or ids.max(initial=0) >= len(values):
                warn("texture coordinates with a size that does not match their interpolation ignored", path)
                return None
            vals = values
        return ref.face_varying(vals, ids[corner_map], fvar_mode)
    if indices is not None:  # other interpolations: flatten the indexed values
        ids = np.asarray(indices, np.int64)
        if ids.min(initial=0) < 0 or ids.max(initial=0) >= len(values):
            return None
        values = values[ids]
    if interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
        if len(values) < num_points:
            warn("texture coordinates with a size that does not match their interpolation ignored", path)
            return None
        if interp == UsdGeom.Tokens.varying:
            return ref.varying_values(values[:num_points], fvi[corner_map])
        return ref.vertex_values(values[:num_points])
    if interp == UsdGeom.Tokens.uniform:
        if len(values) < num_faces:
            return None
        return np.repeat(values[ref.tri_faces][:, None], 3, axis=1)
    if interp == UsdGeom.Tokens.constant:
        return np.broadcast_to(values[0], (len(ref.tri_faces), 3, values.shape[1])).copy()
    return None
