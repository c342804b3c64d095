"""Primvars of a mesh as per-triangle-corner values: interpolation, indices, ``elementSize``, texture coordinates.

Every interpolation expands over the triangles' corners (``renderer.usd.geometry.triangulation``) the same way: constant ->
broadcast, uniform -> per face, vertex/varying -> per point, faceVarying -> per corner. Subdivision surfaces refine
their primvars with the surface's own rules (``renderer.usd.geometry.subdiv``).
"""
from __future__ import annotations

import numpy as np
from pxr import UsdGeom

from renderer.usd.geometry import subdiv as usd_subdiv
from renderer.usd.reads import reads
from renderer.usd.geometry.subdiv import SubdivisionDetail
from renderer.usd.geometry.triangulation import drop_holes, hole_indices, triangulate

# Hydra's mesh of a UsdGeomCube (GeomUtilCuboidMeshGenerator): the topology primvars authored on a Cube refer to.
# Points are for size 1; faces are right-handed quads.
CUBE_POINTS = np.array([(1, 1, 1), (-1, 1, 1), (-1, -1, 1), (1, -1, 1), (-1, -1, -1), (-1, 1, -1), (1, 1, -1),
                        (1, -1, -1)], np.float64) * 0.5
CUBE_COUNTS = np.full(6, 4, np.int64)
CUBE_INDICES = np.array([0, 1, 2, 3, 4, 5, 6, 7, 0, 6, 5, 1, 4, 7, 3, 2, 0, 3, 7, 6, 4, 2, 1, 5], np.int64)


def expand_primvar(values, interpolation: str, corners: np.ndarray, tri_faces: np.ndarray, fvi: np.ndarray,
                   num_faces: int, num_points: int) -> np.ndarray | None:
    """Expand a primvar of any interpolation to per-triangle-corner values (T, 3, C); None if sizes mismatch."""
    if values is None:
        return None
    v = np.asarray(values, np.float32)
    if v.ndim == 1:
        v = v[:, None]
    if len(v) == 0:
        return None
    t = len(corners)
    if interpolation == UsdGeom.Tokens.constant:
        return np.ascontiguousarray(np.broadcast_to(v[0], (t, 3, v.shape[1])))
    if interpolation == UsdGeom.Tokens.uniform:
        if len(v) < num_faces:
            return None
        return np.ascontiguousarray(np.repeat(v[tri_faces][:, None, :], 3, axis=1))
    if interpolation in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
        if len(v) < num_points:
            return None
        return v[fvi[corners]]
    if interpolation == UsdGeom.Tokens.faceVarying:
        if len(v) < len(fvi):
            return None
        return v[corners]
    return None


def _element_count(prim, interpolation: str, frame: float) -> int | None:
    """How many elements a primvar of this interpolation has on a Mesh or a Cube (None: unknown)."""
    if prim.GetTypeName() == "Cube":
        counts = {UsdGeom.Tokens.constant: 1, UsdGeom.Tokens.uniform: len(CUBE_COUNTS),
                  UsdGeom.Tokens.vertex: len(CUBE_POINTS), UsdGeom.Tokens.varying: len(CUBE_POINTS),
                  UsdGeom.Tokens.faceVarying: len(CUBE_INDICES)}
        return counts.get(interpolation)
    if not prim.IsA(UsdGeom.Mesh):
        return None
    mesh = UsdGeom.Mesh(prim)
    if interpolation == UsdGeom.Tokens.constant:
        return 1
    if interpolation == UsdGeom.Tokens.uniform:
        counts = mesh.GetFaceVertexCountsAttr().Get(frame)
        return None if counts is None else len(counts)
    if interpolation in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
        pts = mesh.GetPointsAttr().Get(frame)
        return None if pts is None else len(pts)
    if interpolation == UsdGeom.Tokens.faceVarying:
        fvi = mesh.GetFaceVertexIndicesAttr().Get(frame)
        return None if fvi is None else len(fvi)
    return None


def _usable_element_size(pv, prim, frame: float, warn) -> bool:
    """Whether the primvar can be read one value per element.

    An ``elementSize`` above 1 means several values per element (UsdGeomPrimvar). DCC exporters (Maya's among
    them) write counts there that are not meant that way: when the primvar holds exactly one value (or index)
    per element of its interpolation, that is how it is read, as Hydra and the other renderers read it.
    """
    size = pv.GetElementSize()
    if size == 1:
        return True
    path, name = str(prim.GetPath()), pv.GetPrimvarName()
    expected = _element_count(prim, pv.GetInterpolation(), frame)
    indices = pv.GetIndices(frame) if pv.IsIndexed() else None
    values = pv.Get(frame)
    have = len(indices) if indices is not None else (0 if values is None else len(values))
    if expected is not None and have == expected:
        warn(f"primvar elementSize read as 1: one value per {pv.GetInterpolation()} element ({name})", path)
        return True
    warn(f"primvars with elementSize != 1 ignored ({name})", path)
    return False


def _flattened(pv, frame: float):
    """The primvar's values at the frame, expanded through its indices one value per element (None if it has no
    value or an index is out of range). ``ComputeFlattened`` would group values by ``elementSize``."""
    vals = pv.Get(frame)
    if vals is None or len(vals) == 0:
        return None
    if not pv.IsIndexed():
        return vals
    idx = np.asarray(pv.GetIndices(frame), np.int64)
    if len(idx) and (idx.min() < 0 or idx.max() >= len(vals)):
        return None
    return np.asarray(vals)[idx]


def read_primvar(prim, name: str, frame: float, warn):
    """(flattened values, interpolation) of primvars:name, or None if absent/empty."""
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
    if not pv or not pv.HasAuthoredValue():
        return None
    if not _usable_element_size(pv, prim, frame, warn):
        return None
    vals = _flattened(pv, frame)
    if vals is None or len(vals) == 0:
        return None
    return vals, pv.GetInterpolation()


def _uv_primvar_object(prim, frame: float, warn):
    """The texture-coordinate primvar of a mesh: ``st``, else the first float2 texCoord primvar; or None."""
    api = UsdGeom.PrimvarsAPI(prim)
    pv = api.GetPrimvar("st")
    if pv and pv.HasAuthoredValue():
        return pv if _usable_element_size(pv, prim, frame, warn) else None
    for pv in api.GetPrimvarsWithAuthoredValues():  # any texture-coordinate primvar
        if str(pv.GetTypeName().role) == "TextureCoordinate" or pv.GetPrimvarName() in ("uv", "UVMap", "st0"):
            if pv.GetElementSize() != 1 and not _usable_element_size(pv, prim, frame, warn):
                continue
            v = pv.Get(frame)
            if v is not None and len(v) and np.asarray(v).ndim == 2 and np.asarray(v).shape[1] == 2:
                return pv
    return None


def default_uv_name(prim, frame: float) -> str | None:
    """The primvar ``read_mesh`` takes as texture coordinates (``st``, else the first texCoord2f one), or None."""
    pv = _uv_primvar_object(prim, frame, lambda *a: None)
    return None if pv is None else pv.GetPrimvarName()


def read_uv_primvar(prim, frame: float, warn):
    """(flattened values, interpolation) of the texture coordinates ``default_uv_name`` names, or None."""
    pv = _uv_primvar_object(prim, frame, warn)
    if pv is None:
        return None
    vals = _flattened(pv, frame)
    if vals is None or len(vals) == 0:
        return None
    return vals, pv.GetInterpolation()


def read_uv_primvar_raw(prim, frame: float, warn):
    """(values, indices or None, interpolation) of the texture coordinates, for refinement; or None."""
    pv = _uv_primvar_object(prim, frame, warn)
    if pv is None:
        return None
    vals = pv.Get(frame)
    if vals is None or len(vals) == 0:
        return None
    idx = pv.GetIndices(frame) if pv.IsIndexed() else None
    return np.asarray(vals), (None if idx is None else np.asarray(idx, np.int64)), pv.GetInterpolation()


def read_named_uvs(prim, name: str, frame: float, warn, level: int | None = None) -> np.ndarray | None:
    """Per-corner values (T, 3, 2) float32 of the float2 primvar ``name`` of a Mesh (``read_corner_primvar``).

    For materials whose UsdPrimvarReader_float2 names a primvar other than the one ``read_mesh`` picks (``st``,
    else the first texCoord2f primvar).
    """
    return read_corner_primvar(prim, name, frame, warn, level, 2)


def varying_colors(values) -> np.ndarray | None:
    """The colours (n, 3) float64 when they are finite and not all equal (worth per-corner data), else None."""
    v = np.asarray(values, np.float64)
    if v.size < 6 or v.size % 3:
        return None
    v = v.reshape(-1, 3)
    return v if np.all(np.isfinite(v)) and not np.all(v == v[0]) else None


@reads("Gprim", "primvars:displayColor")
def read_display_colors(prim, frame: float, warn, level: int | None = None) -> np.ndarray | None:
    """Per-corner displayColor (T, 3, 3) float32 of a Mesh whose displayColor varies over it (uniform, vertex,
    varying or faceVarying with unequal values); None when it is constant, absent, mis-sized or not finite."""
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
    if not pv or not pv.HasAuthoredValue() or pv.GetInterpolation() == UsdGeom.Tokens.constant:
        return None
    vals = _flattened(pv, frame)
    if vals is None or varying_colors(vals) is None:
        return None
    colors = read_corner_primvar(prim, "displayColor", frame, warn, level, 3)
    if colors is None:
        warn("displayColor with a size that does not match its interpolation: its mean used", str(prim.GetPath()))
    return colors


def read_corner_primvar(prim, name: str, frame: float, warn, level: int | None, width: int) -> np.ndarray | None:
    """Per-corner values (T, 3, width) float32 of the primvar ``name`` of a Mesh, on the triangles ``read_mesh``
    makes (same triangulation, holes and winding; for a subdivision surface pass ``level``, the
    ``GeomData.subdivision_level`` it was refined to, and the values are refined with the surface's rules); None
    if the prim is not a Mesh or the primvar is absent or mis-sized."""
    if not prim.IsA(UsdGeom.Mesh):
        return None
    mesh = UsdGeom.Mesh(prim)
    counts = mesh.GetFaceVertexCountsAttr().Get(frame)
    fvi = mesh.GetFaceVertexIndicesAttr().Get(frame)
    pts = mesh.GetPointsAttr().Get(frame)
    hit = read_primvar(prim, name, frame, warn)
    if hit is None or counts is None or fvi is None or pts is None or len(counts) == 0:
        return None
    counts, fvi = np.asarray(counts, np.int64), np.asarray(fvi, np.int64)
    base = np.asarray(pts, np.float32).reshape(-1, 3)
    if int(counts.sum()) != len(fvi) or fvi.min() < 0 or fvi.max() >= len(base):
        return None
    holes = hole_indices(mesh, frame, len(counts))
    left_handed = mesh.GetOrientationAttr().Get(frame) == UsdGeom.Tokens.leftHanded
    scheme = str(mesh.GetSubdivisionSchemeAttr().Get(frame) or "catmullClark")
    if scheme != UsdGeom.Tokens.none:
        scheme = scheme if scheme in usd_subdiv.SUBDIV_SCHEMES else "catmullClark"
        pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
        idx = pv.GetIndices(frame) if pv.IsIndexed() else None
        uv = (np.asarray(pv.Get(frame)), None if idx is None else np.asarray(idx, np.int64), pv.GetInterpolation())
        detail = SubdivisionDetail(level=usd_subdiv.DEFAULT_LEVEL if level is None else level)
        ref = usd_subdiv.refine(mesh, frame, scheme, counts, fvi, base[None], holes, uv, detail, None, warn)
        if ref is None or ref.uvs is None or ref.uvs.shape[-1] != width:
            return None
        return np.ascontiguousarray(ref.uvs[:, [0, 2, 1]] if left_handed else ref.uvs, np.float32)
    corners, tri_faces = triangulate(counts, fvi, base)
    corners, tri_faces = drop_holes(corners, tri_faces, holes)
    if left_handed:
        corners = corners[:, [0, 2, 1]]
    values = expand_primvar(hit[0], hit[1], corners, tri_faces, fvi, len(counts), len(base))
    if values is None or values.shape[-1] != width:
        return None
    return np.ascontiguousarray(values, np.float32)
