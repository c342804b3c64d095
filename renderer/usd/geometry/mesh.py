"""UsdGeomMesh to triangles: topology at the frame, point keys over the shutter, normals and texture coordinates.

``read_mesh`` returns a ``GeomData`` (NumPy only) in object space, the form every gprim reader returns (implicit
primitives: ``renderer.usd.geometry.primitives``; points and curves: ``renderer.usd.geometry.curves``). Subdivision surfaces are
refined in ``renderer.usd.geometry.subdiv``. ``orientation = leftHanded`` swaps two corners so the result is
counter-clockwise seen from the front; faces named in ``holeIndices`` are not drawn.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pxr import UsdGeom

from renderer.scene.model import AnalyticShape
from renderer.usd.geometry import subdiv as usd_subdiv
from renderer.motion.shutter import Shutter
from renderer.usd.motion import point_keys
from renderer.usd.geometry.primvars import expand_primvar, read_primvar, read_uv_primvar, read_uv_primvar_raw
from renderer.usd.reads import reads
from renderer.usd.geometry.subdiv import SubdivisionDetail
from renderer.usd.geometry.triangulation import drop_holes, hole_indices, triangulate


@dataclass
class GeomData:
    """A triangulated prim in object space; ``tri_faces`` maps triangles back to authored faces."""

    point_times: np.ndarray  # (P,) absolute time codes of the point keys
    points: np.ndarray  # (P, V, 3) float32
    triangles: np.ndarray  # (T, 3) int32
    tri_faces: np.ndarray  # (T,) int64 authored face index per triangle
    num_faces: int
    normals: np.ndarray | None = None  # (T, 3, 3) float32
    uvs: np.ndarray | None = None  # (T, 3, 2) float32
    double_sided: bool = False
    subdivision_level: int | None = None  # refinement level of a subdivision surface; None: not subdivided
    shape: AnalyticShape | None = None  # an implicit prim whose size does not vary (``Mesh.shape``)
    solid: np.ndarray | None = None  # (T,) bool, ``Mesh.solid``
    tessellate: object = None  # ``Mesh.tessellate``: the full triangles of a stand-in, deferred
    point_radii: np.ndarray | None = None  # ``Mesh.point_radii``: a cloud of exact spheres


@reads("Mesh", "faceVertexCounts", "faceVertexIndices", "subdivisionScheme")
@reads("PointBased", "points", "normals")
@reads("Gprim", "doubleSided", "orientation")
def read_mesh(prim, shutter: Shutter, warn, detail: SubdivisionDetail | None = None,
              world: np.ndarray | None = None, keys: tuple[np.ndarray, np.ndarray] | None = None) -> GeomData | None:
    """Triangulate a UsdGeomMesh at the frame (topology) with point keys over the shutter; subdivision surfaces
    (any ``subdivisionScheme`` but ``none``) are refined to ``detail``'s level (``world``: the prim's row-vector
    object-to-world matrix at the frame, for a level from the camera). ``keys`` (times, (P, V, 3) points)
    replaces the authored points, for skinned meshes (whose authored normals the caller then carries along)."""
    mesh = UsdGeom.Mesh(prim)
    path = str(prim.GetPath())
    frame = shutter.frame
    counts = mesh.GetFaceVertexCountsAttr().Get(frame)
    fvi = mesh.GetFaceVertexIndicesAttr().Get(frame)
    pts = mesh.GetPointsAttr().Get(frame)
    if counts is None or fvi is None or pts is None or len(counts) == 0 or len(pts) == 0:
        warn("meshes without faces or points skipped", path)
        return None
    counts = np.asarray(counts, np.int64)
    fvi = np.asarray(fvi, np.int64)
    base = np.asarray(pts, np.float32).reshape(-1, 3)
    if int(counts.sum()) != len(fvi) or np.any(counts < 0) or fvi.min() < 0 or fvi.max() >= len(base):
        warn("meshes with invalid topology (face counts/indices out of range) skipped", path)
        return None
    if not np.all(np.isfinite(base)):
        warn("meshes with NaN/infinite points skipped", path)
        return None
    if keys is not None and (keys[1].ndim != 3 or keys[1].shape[1] != len(base)):
        warn("deformed point keys whose size differs from the mesh ignored", path)
        keys = None
    if keys is None:
        keys = point_keys(mesh, shutter, len(base), warn)
    if keys is None:
        keys = (np.array([frame]), base[None])
    if not np.all(np.isfinite(keys[1])):
        warn("meshes with NaN/infinite points skipped", path)
        return None
    holes = hole_indices(mesh, frame, len(counts))
    left_handed = mesh.GetOrientationAttr().Get(frame) == UsdGeom.Tokens.leftHanded
    scheme = str(mesh.GetSubdivisionSchemeAttr().Get(frame) or "catmullClark")
    if scheme not in usd_subdiv.SUBDIV_SCHEMES and scheme != UsdGeom.Tokens.none:
        warn(f"unknown subdivisionScheme rendered as catmullClark ({scheme})", path)
        scheme = "catmullClark"
    if scheme != UsdGeom.Tokens.none:
        return _subdivided(mesh, frame, scheme, counts, fvi, keys, holes, left_handed, detail, world, warn)
    corners, tri_faces = triangulate(counts, fvi, base)
    corners, tri_faces = drop_holes(corners, tri_faces, holes)
    if len(corners) == 0:
        warn("meshes with zero triangles (or only holes) skipped", path)
        return None
    if left_handed:
        corners = corners[:, [0, 2, 1]]
    nf, npnt = len(counts), len(base)
    tris = fvi[corners]

    normals = None
    hit = read_primvar(prim, "normals", frame, warn)
    if hit is None:
        n_attr = mesh.GetNormalsAttr()
        n_val = n_attr.Get(frame) if n_attr.HasAuthoredValue() else None
        if n_val is not None and len(n_val):
            hit = (n_val, mesh.GetNormalsInterpolation())
    if hit is not None:
        normals = expand_primvar(hit[0], hit[1], corners, tri_faces, fvi, nf, npnt)
        if normals is None or normals.shape[-1] != 3:
            warn("normals with a size that does not match their interpolation ignored", path)
            normals = None

    uvs = None
    hit = read_uv_primvar(prim, frame, warn)
    if hit is not None:
        uvs = expand_primvar(hit[0], hit[1], corners, tri_faces, fvi, nf, npnt)
        if uvs is None or uvs.shape[-1] != 2:
            warn("texture coordinates with a size that does not match their interpolation ignored", path)
            uvs = None

    return GeomData(
        point_times=keys[0],
        points=np.ascontiguousarray(keys[1], np.float32),
        triangles=np.ascontiguousarray(tris, np.int32),
        tri_faces=tri_faces,
        num_faces=nf,
        normals=None if normals is None else np.ascontiguousarray(normals, np.float32),
        uvs=None if uvs is None else np.ascontiguousarray(uvs, np.float32),
        double_sided=bool(mesh.GetDoubleSidedAttr().Get(frame)),
    )


def _subdivided(mesh, frame, scheme, counts, fvi, keys, holes, left_handed, detail, world, warn):
    path = str(mesh.GetPath())
    uv = read_uv_primvar_raw(mesh.GetPrim(), frame, warn)
    frame_key = int(np.argmin(np.abs(np.asarray(keys[0], np.float64) - frame)))
    ref = usd_subdiv.refine(mesh, frame, scheme, counts, fvi, keys[1], holes, uv, detail, world, warn, frame_key)
    if ref is None:
        warn("meshes with zero triangles (or only holes) skipped", path)
        return None
    tris, normals, uvs = ref.triangles, ref.normals, ref.uvs
    if left_handed:  # the front is the clockwise side: flip the winding, and the normals with it
        tris, normals = tris[:, [0, 2, 1]], -normals[:, [0, 2, 1]]
        uvs = None if uvs is None else uvs[:, [0, 2, 1]]
    return GeomData(
        point_times=keys[0],
        points=np.ascontiguousarray(ref.points, np.float32),
        triangles=np.ascontiguousarray(tris, np.int32),
        tri_faces=ref.tri_faces,
        num_faces=len(counts),
        normals=np.ascontiguousarray(normals, np.float32),
        uvs=None if uvs is None else np.ascontiguousarray(uvs, np.float32),
        double_sided=bool(mesh.GetDoubleSidedAttr().Get(frame)),
        subdivision_level=ref.level,
    )
