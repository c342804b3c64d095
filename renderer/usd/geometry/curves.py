"""UsdGeomPoints (exact spheres), UsdGeomBasisCurves and UsdGeomHermiteCurves as triangle meshes (``CurveGeom``).

Tessellated at import (``renderer/scene/tessellate_curves``, ``tessellate_points``) so motion keys, materials,
instancing and shadows follow the mesh path unchanged. Density is chosen from each element's size on screen,
seen from the render camera at the frame (``View``): the RenderSettings resolution, else ``NOMINAL_WIDTH``
pixels across, since the scene is read before ``--width`` is known.

Curves (``widths`` are diameters; ``primvars:widths`` wins over ``widths``; unauthored: ``DEFAULT_WIDTH``):

* authored ``normals``: ribbons facing the (interpolated) normals, 2 triangles per sub-segment;
* thinner than ``RIBBON_PX`` pixels: **camera-facing ribbons**, exact width, 2 triangles per sub-segment
  (a hair under two pixels wide looks the same as a tube; its shadows are as wide as seen from the camera);
* wider: round tubes of 4..24 sides (the polygon within half a pixel of the circle, two vertices on the
  silhouette, so the seen width is exact), 2 sides triangles per sub-segment;
* cubic segments are cut into 1..16 sub-segments so the chord error stays under a quarter pixel (a hundredth
  of the segment when no camera is known).

Points (``widths`` are diameters, default ``DEFAULT_WIDTH``): a cloud of exact spheres, or of exact discs facing
authored ``normals`` (``_point_cloud``, ``scene.analytic``), whose triangles, made only if something needs them (an
emissive cloud, a CSG operand), are polygons facing the normals, or camera-facing hexagons (4 triangles) under
``DISC_PX`` pixels and icospheres of 20 / 80 / 320 triangles by size above. With no camera (automatic framing) or
inside PointInstancer prototypes the view is unknown: curves are 6-sided tubes, points 80-triangle spheres.

NurbsCurves are evaluated (rational, Cox-de Boor) at ``NURBS_SAMPLES`` points per knot span of their ``ranges``
and rendered as linear curves through those points; their vertex widths go through the same basis.

A ``displayColor`` that varies becomes per-corner ``CurveGeom.colors``: along BasisCurves through their basis
(like widths), and per point over each point's whole shape.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from pxr import UsdGeom

from renderer.scene import tessellate_curves as tc
from renderer.scene import tessellate_points as tp
from renderer.scene.model import AnalyticShape
from renderer.usd.geometry.mesh import GeomData
from renderer.motion.shutter import Shutter
from renderer.usd.motion import point_keys
from renderer.usd.geometry.primvars import varying_colors
from renderer.usd.reads import reads

DEFAULT_WIDTH = 1.0  # scene units; the schema has no fallback, Hydra and RenderMan use 1
NOMINAL_WIDTH = 1920  # pixels across assumed for density when the stage sets no resolution
RIBBON_PX = 2.0  # curves thinner than this on screen are camera-facing ribbons
DISC_PX = 3.0  # points smaller than this on screen are camera-facing discs
TOLERANCE_PX = 0.25  # chord error of cubic segments, pixels
NO_VIEW_SIDES = 6
NO_VIEW_SPHERE = 1
NURBS_SAMPLES = 8  # samples per non-empty knot span of a NurbsCurves curve

CURVE_TYPES = ("BasisCurves", "HermiteCurves")
HANDLED_TYPES = ("Points", "BasisCurves", "HermiteCurves", "NurbsCurves")


def handles(prim) -> bool:
    """Is this a prim this module reads (points or curves)?"""
    return prim.GetTypeName() in HANDLED_TYPES


@dataclass
class View:
    """The render camera at the frame, in a prim's object space: what one pixel measures at a point."""

    position: np.ndarray  # (3,) camera position (perspective)
    direction: np.ndarray  # (3,) unit view direction (orthographic)
    pixel: float  # perspective: pixel angle (radians per pixel); orthographic: pixel size in object units
    orthographic: bool = False

    def footprint(self, p: np.ndarray) -> np.ndarray:
        """Size of one pixel (object units) at points p (..., 3)."""
        if self.orthographic:
            return np.full(p.shape[:-1], self.pixel)
        return np.maximum(np.linalg.norm(p - self.position, axis=-1), 1e-9) * self.pixel

    def facing(self, p: np.ndarray) -> np.ndarray:
        """Unit vectors from p (N, 3) toward the camera."""
        if self.orthographic:
            return np.broadcast_to(-self.direction, p.shape).copy()
        d = self.position - p
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        return np.where(n > 1e-12, d / np.where(n > 1e-12, n, 1.0), np.array([0.0, 0.0, 1.0]))


def view_in_object_space(cam_row: np.ndarray, horizontal_aperture: float, focal_length: float, width_px: int,
                         orthographic: bool, obj_row: np.ndarray) -> View | None:
    """The camera (world matrix ``cam_row``, row-vector USD convention) seen from an object (world ``obj_row``).

    Apertures in the camera's USD units (tenths of a scene unit), like ``focal_length``.
    """
    try:
        inv = np.linalg.inv(np.asarray(obj_row, np.float64))
    except np.linalg.LinAlgError:
        return None
    pos = np.append(cam_row[3, :3], 1.0) @ inv
    d = np.array([0.0, 0.0, -1.0]) @ cam_row[:3, :3] @ inv[:3, :3]
    dn = np.linalg.norm(d)
    if not np.all(np.isfinite(pos)) or dn <= 0 or width_px <= 0:
        return None
    scale = abs(np.linalg.det(obj_row[:3, :3])) ** (1.0 / 3.0)
    if orthographic:
        pixel = horizontal_aperture / 10.0 / width_px / max(scale, 1e-30)
    else:
        if focal_length <= 0:
            return None
        pixel = horizontal_aperture / focal_length / width_px
    return View(position=pos[:3] / pos[3], direction=d / dn, pixel=float(pixel), orthographic=orthographic)


@dataclass
class CurveGeom(GeomData):
    """GeomData plus which triangles are thin (curves and tessellated points never refract as solids; a cloud of
    exact spheres does)."""

    solid: np.ndarray | None = None  # (T,) bool
    colors: np.ndarray | None = None  # (T, 3, 3) per-corner displayColor where it varies (points, BasisCurves)


# ---------------------------------------------------------------------------------------------------------------
# Attribute reading


def _interp_values(prim, name: str, attr, interp: str, frame: float):
    """(values, interpolation) of primvars:name if authored, else of the schema attribute; None if neither."""
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
    if pv and pv.HasAuthoredValue():
        v = pv.ComputeFlattened(frame)
        if v is not None and len(v):
            return np.asarray(v, np.float64), str(pv.GetInterpolation())
    if attr and attr.HasAuthoredValue():
        v = attr.Get(frame)
        if v is not None and len(v):
            return np.asarray(v, np.float64), str(interp)
    return None


def _varying_display_color(prim, frame: float):
    """(values (n, 3), interpolation) of a displayColor that is not constant over the prim, else None."""
    got = _interp_values(prim, "displayColor", None, "constant", frame)
    vals = None if got is None or got[1] == "constant" else varying_colors(got[0])
    return None if vals is None else (vals, got[1])


def _keys(prim, shutter: Shutter, warn, path: str):
    pb = UsdGeom.PointBased(prim)
    pts = pb.GetPointsAttr().Get(shutter.frame)
    if pts is None or len(pts) == 0:
        return None
    base = np.asarray(pts, np.float64).reshape(-1, 3)
    keys = point_keys(pb, shutter, len(base), warn)
    times, pts = keys if keys is not None else (np.array([shutter.frame]), base[None])
    pts = np.asarray(pts, np.float64)
    if not np.all(np.isfinite(pts)):
        warn("points or curves with NaN/infinite points skipped", path)
        return None
    return np.asarray(times), pts


@reads("Points", "widths")
@reads("Curves", "curveVertexCounts", "widths")
@reads("BasisCurves", "type", "basis", "wrap")
@reads("PointBased", "points", "normals")
def read_points_or_curves(prim, shutter: Shutter, warn, view: View | None) -> CurveGeom | None:
    """Tessellate a Points/BasisCurves/HermiteCurves prim; None (with a warning) when it cannot be rendered."""
    kind = prim.GetTypeName()
    path = str(prim.GetPath())
    keys = _keys(prim, shutter, warn, path)
    if keys is None:
        warn("points or curves without points skipped", path)
        return None
    if kind == "Points":
        return _points(prim, keys, shutter.frame, warn, view, path)
    return _curves(prim, keys, shutter.frame, warn, view, path)


# ---------------------------------------------------------------------------------------------------------------
# Points


def _points(prim, keys, frame: float, warn, view: View | None, path: str) -> CurveGeom | None:
    times, pts = keys
    n = pts.shape[1]
    geom = UsdGeom.Points(prim)
    w = _interp_values(prim, "widths", geom.GetWidthsAttr(), geom.GetWidthsInterpolation(), frame)
    width = np.full(n, DEFAULT_WIDTH)
    if w is not None:
        vals, interp = w[0].reshape(-1), w[1]
        if interp == "constant" or len(vals) == 1:
            width[:] = vals[0]
        elif len(vals) >= n:
            width = vals[:n].copy()
        else:
            warn("point widths with a size that does not match their interpolation ignored", path)
    nrm = _interp_values(prim, "normals", geom.GetNormalsAttr(), geom.GetNormalsInterpolation(), frame)
    normals = None
    if nrm is not None:
        vals = nrm[0].reshape(-1, 3)
        if nrm[1] == "constant" or len(vals) == 1:
            normals = np.broadcast_to(vals[0], (n, 3)).copy()
        elif len(vals) >= n:
            normals = vals[:n].copy()
        else:
            warn("point normals with a size that does not match their interpolation ignored", path)
    keep = np.isfinite(width) & (width > 0)
    if normals is not None:
        ln = np.linalg.norm(normals, axis=1)
        keep &= np.isfinite(ln) & (ln > 0)
        normals = normals / np.where(ln > 0, ln, 1.0)[:, None]
    if not np.all(keep):
        warn("points of zero or invalid width (or normal) dropped", path)
    idx = np.nonzero(keep)[0]
    if len(idx) == 0:
        warn("points or curves with nothing to render skipped", path)
        return None

    centres = pts[:, idx]
    wd = width[idx]
    colors = None  # one colour per kept point, or None
    dc = _varying_display_color(prim, frame)
    if dc is not None:
        if dc[1] in ("vertex", "varying") and len(dc[0]) >= n:
            colors = np.asarray(dc[0], np.float64)[idx]
        else:
            warn("point displayColor that is not per point: its mean used", path)
    # exact spheres, or discs facing the normals: one leaf primitive each; triangles only if something needs them
    return _point_cloud(times, centres, wd, idx, n, colors, view, None if normals is None else normals[idx])


def _point_cloud(times, centres, wd, idx, n: int, colors, view, normals) -> CurveGeom:
    """Points as exact spheres (``scene.analytic``, kind "points"), or as exact discs facing ``normals`` (kind
    "discs"): point j is "triangle" (j, j, j) of the stand-in, which carries its material, colour and a disc's
    normal; ``tessellate`` gives the icospheres and polygons of ``_tessellated_points``, should something need
    triangles (an emissive cloud, a CSG operand)."""
    k = len(idx)
    tris = np.repeat(np.arange(k, dtype=np.int32)[:, None], 3, axis=1)
    corner = None if normals is None else np.ascontiguousarray(np.repeat(normals[:, None, :], 3, axis=1), np.float32)
    return CurveGeom(
        point_times=np.asarray(times),
        points=np.ascontiguousarray(centres, np.float32),
        triangles=tris,
        tri_faces=idx.astype(np.int64),
        num_faces=int(n),
        normals=corner,
        uvs=None,
        double_sided=True,
        shape=AnalyticShape("points" if normals is None else "discs", float(wd.max()) / 2),
        point_radii=np.ascontiguousarray(wd / 2, np.float32),
        solid=np.full(k, normals is None),  # a sphere is closed (a glass bead refracts), a disc is thin
        colors=None if colors is None else np.ascontiguousarray(np.repeat(colors[:, None, :], 3, axis=1), np.float32),
        tessellate=functools.partial(_points_as_triangles, times, centres, wd, idx, n, view, normals),
    )


def _points_as_triangles(times, centres, wd, idx, n: int, view, normals):
    """``Mesh.tessellate`` of a point cloud: its icospheres and camera-facing discs, or its polygons facing the
    normals (thin, as before)."""
    full = None
    if normals is not None:  # _tessellated_points indexes normals by point
        full = np.zeros((n, 3))
        full[idx] = normals
    out = _tessellated_points(times, centres, wd, idx, n, None, view, full)
    origin = np.searchsorted(idx, out.tri_faces)  # each triangle's point, as an index into the kept points
    return out.points, out.triangles, out.normals, origin, out.solid


def _tessellated_points(times, centres, wd, idx, n: int, colors, view, normals) -> CurveGeom | None:
    """Points as triangles: discs facing their ``normals`` when given, else camera-facing discs under ``DISC_PX``
    pixels and icospheres by size on screen (the density needs the view: 80-triangle spheres without one)."""
    parts = []
    if normals is not None:
        d_px = wd / view.footprint(centres[0]) if view is not None else np.full(len(idx), 1e3)
        sides = np.maximum(tc.tube_sides(0.5 * d_px), 6)
        for s in np.unique(sides):
            sel = np.nonzero(sides == s)[0]
            parts.append((*tp.discs(centres[:, sel], wd[sel], normals[idx[sel]], int(s)), idx[sel]))
    else:
        if view is not None:
            d_px = wd / view.footprint(centres[0])
            bucket = np.where(d_px < DISC_PX, -1, tp.sphere_level(d_px))
        else:
            bucket = np.full(len(idx), NO_VIEW_SPHERE)
        for b in np.unique(bucket):
            sel = np.nonzero(bucket == b)[0]
            if b < 0:
                facing = view.facing(centres[0, sel])
                parts.append((*tp.discs(centres[:, sel], wd[sel], facing, 6), idx[sel]))
            else:
                parts.append((*tp.spheres(centres[:, sel], wd[sel], int(b)), idx[sel]))
    out = _assemble(parts, times, n)
    if out is not None and colors is not None:  # one colour per point, over its whole shape
        full = np.zeros((n, 3))
        full[idx] = colors
        out.colors = np.ascontiguousarray(np.repeat(full[out.tri_faces][:, None, :], 3, axis=1), np.float32)
    return out


# ---------------------------------------------------------------------------------------------------------------
# Curves


@reads("HermiteCurves", "tangents")
def _hermite_to_bezier(prim, counts, pts, frame: float, warn, path):
    """HermiteCurves (points + tangents per vertex) as nonperiodic cubic Bezier control points (K, V', 3)."""
    tan = UsdGeom.HermiteCurves(prim).GetTangentsAttr().Get(frame)
    if tan is None or len(tan) != pts.shape[1]:
        warn("HermiteCurves without one tangent per point skipped", path)
        return None
    tan = np.asarray(tan, np.float64).reshape(-1, 3)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    out_counts, seg_p0 = [], []
    for s, c in zip(start, counts):
        c = int(c)
        out_counts.append(3 * (c - 1) + 1 if c >= 2 else 0)
        seg_p0.append(np.arange(s, s + c - 1))
    p0 = np.concatenate(seg_p0).astype(np.int64) if seg_p0 else np.zeros(0, np.int64)
    p1 = p0 + 1
    # per curve: P0, P0 + T0/3, P1 - T1/3, P1, P1 + T1/3, ...
    ctrl = np.stack([pts[:, p0], pts[:, p0] + tan[p0] / 3.0, pts[:, p1] - tan[p1] / 3.0], axis=2)  # (K, S, 3, 3)
    segs_per = np.maximum(np.asarray(counts) - 1, 0)
    out = []
    k = 0
    for c in segs_per:
        if c == 0:
            continue
        block = ctrl[:, k:k + c].reshape(pts.shape[0], -1, 3)
        out.append(np.concatenate([block, pts[:, p1[k + c - 1]][:, None]], axis=1))
        k += c
    if not out:
        return None
    return np.asarray([c for c in out_counts if c > 0], np.int64), np.concatenate(out, axis=1)


def nurbs_basis(knots: np.ndarray, order: int, u: np.ndarray) -> np.ndarray:
    """(len(u), n) B-spline basis functions of the given order (degree + 1) at u (Cox-de Boor), n = len(knots) -
    order; u in [knots[order - 1], knots[n]] (the last span closed at its end)."""
    knots = np.asarray(knots, np.float64)
    n = len(knots) - order
    u = np.asarray(u, np.float64)
    last = np.nonzero(knots[1:] > knots[:-1])[0]
    end_span = last[last < n][-1] if np.any(last < n) else order - 1
    span = np.clip(np.searchsorted(knots, u, side="right") - 1, order - 1, end_span)
    b = np.zeros((len(u), len(knots) - 1))
    b[np.arange(len(u)), span] = 1.0
    for k in range(2, order + 1):
        nb = np.zeros((len(u), len(knots) - k))
        for i in range(len(knots) - k):
            d1 = knots[i + k - 1] - knots[i]
            d2 = knots[i + k] - knots[i + 1]
            if d1 > 0:
                nb[:, i] += (u - knots[i]) / d1 * b[:, i]
            if d2 > 0:
                nb[:, i] += (knots[i + k] - u) / d2 * b[:, i + 1]
        b = nb
    return b[:, :n]


@reads("NurbsCurves", "order", "knots", "pointWeights", "ranges")
def _nurbs_polylines(prim, counts, pts, frame: float, warn, path):
    """NurbsCurves sampled into polylines: (counts, points (K, N, 3), vertex widths (values, "vertex") or None)."""
    nc = UsdGeom.NurbsCurves(prim)
    order = nc.GetOrderAttr().Get(frame)
    knots = nc.GetKnotsAttr().Get(frame)
    if order is None or knots is None or len(order) != len(counts):
        warn("NurbsCurves without one order per curve skipped", path)
        return None
    order = np.asarray(order, np.int64)
    knots = np.asarray(knots, np.float64)
    if len(knots) != int(np.sum(counts + order)):
        warn("NurbsCurves whose knots do not number points + order per curve skipped", path)
        return None
    weights = nc.GetPointWeightsAttr().Get(frame)
    weights = np.asarray(weights, np.float64) if weights is not None and len(weights) == pts.shape[1] else None
    ranges = nc.GetRangesAttr().Get(frame)
    ranges = np.asarray(ranges, np.float64).reshape(-1, 2) if ranges is not None and len(ranges) == len(counts) \
        else None
    w = _interp_values(prim, "widths", nc.GetWidthsAttr(), nc.GetWidthsInterpolation(), frame)
    out_counts, out_pts, out_w = [], [], []
    v0 = k0 = 0
    for i, (c, o) in enumerate(zip(counts, order)):
        c, o = int(c), int(o)
        kn = knots[k0:k0 + c + o]
        cps = pts[:, v0:v0 + c]
        wt = weights[v0:v0 + c] if weights is not None else np.ones(c)
        if c >= o >= 2 and np.all(np.diff(kn) >= 0):
            lo, hi = (kn[o - 1], kn[c]) if ranges is None else ranges[i]
            lo, hi = max(lo, kn[o - 1]), min(hi, kn[c])
            breaks = np.unique(np.clip(kn, lo, hi))
            if len(breaks) >= 2:
                u = np.concatenate([np.linspace(a, b, NURBS_SAMPLES, endpoint=False)
                                    for a, b in zip(breaks[:-1], breaks[1:])] + [breaks[-1:]])
                basis = nurbs_basis(kn, o, u) * wt[None, :]
                basis /= np.where(basis.sum(1, keepdims=True) != 0, basis.sum(1, keepdims=True), 1.0)
                out_counts.append(len(u))
                out_pts.append(np.einsum("nv,kvc->knc", basis, cps))
                if w is not None and w[1] == "vertex" and len(w[0]) >= v0 + c:
                    out_w.append(basis @ w[0].reshape(-1)[v0:v0 + c])
        v0 += c
        k0 += c + o
    if len(out_counts) < len(counts):
        warn("NurbsCurves with invalid order, knots or ranges skipped", path)
    if not out_counts:
        return None
    widths = None
    if w is not None:
        if w[1] == "vertex":
            widths = (np.concatenate(out_w), "vertex") if len(out_w) == len(out_counts) else None
        elif w[1] in ("constant", "uniform"):
            widths = w if w[1] == "constant" or len(out_counts) == len(counts) else None
        if widths is None:
            warn("NurbsCurves widths not per point, per curve or constant use their mean", path)
            widths = (np.array([float(np.mean(w[0]))]), "constant")
    return np.asarray(out_counts, np.int64), np.concatenate(out_pts, axis=1), widths


def _curves(prim, keys, frame: float, warn, view: View | None, path: str) -> CurveGeom | None:
    times, pts = keys
    curves = UsdGeom.Curves(prim)
    counts = curves.GetCurveVertexCountsAttr().Get(frame)
    if counts is None or len(counts) == 0:
        warn("curves without curveVertexCounts skipped", path)
        return None
    counts = np.asarray(counts, np.int64)
    if np.any(counts < 0) or int(counts.sum()) != pts.shape[1]:
        warn("curves whose curveVertexCounts do not add up to their points skipped", path)
        return None
    nurbs_widths = None
    if prim.GetTypeName() == "NurbsCurves":
        hit = _nurbs_polylines(prim, counts, pts, frame, warn, path)
        if hit is None:
            return None
        counts, pts, nurbs_widths = hit
        ctype, basis, wrap = "linear", "bezier", "nonperiodic"
        widths_ok_for = "basis"
    elif prim.GetTypeName() == "HermiteCurves":
        hit = _hermite_to_bezier(prim, counts, pts, frame, warn, path)
        if hit is None:
            return None
        counts, pts = hit
        ctype, basis, wrap = "cubic", "bezier", "nonperiodic"
        widths_ok_for = "hermite"
    else:
        bc = UsdGeom.BasisCurves(prim)
        ctype = str(bc.GetTypeAttr().Get(frame) or "cubic")
        basis = str(bc.GetBasisAttr().Get(frame) or "bezier")
        wrap = str(bc.GetWrapAttr().Get(frame) or "nonperiodic")
        widths_ok_for = "basis"
        if ctype not in ("linear", "cubic"):
            warn(f"curves of unknown type '{ctype}' rendered as linear", path)
            ctype = "linear"
        if ctype == "cubic" and basis not in tc.BASIS:
            warn(f"curves of unknown basis '{basis}' rendered as bezier", path)
            basis = "bezier"
        if wrap not in ("nonperiodic", "periodic", "pinned"):
            warn(f"curves of unknown wrap '{wrap}' rendered nonperiodic", path)
            wrap = "nonperiodic"
    topo = tc.topology(counts, ctype, basis, wrap)
    if not np.all(topo.curve_ok):
        warn("curves with a vertex count invalid for their type/basis/wrap skipped", path)
    if len(topo.seg_ctrl) == 0:
        warn("points or curves with nothing to render skipped", path)
        return None

    ext = topo.extend(pts)  # (K, E, 3)
    ctrl0 = ext[0][topo.seg_ctrl]  # (S, order, 3)
    centre = ctrl0.mean(axis=1)
    if view is not None:
        tol = TOLERANCE_PX * view.footprint(centre)
    else:
        tol = 0.01 * np.linalg.norm(ctrl0[:, -1] - ctrl0[:, 0], axis=1) + 1e-9
    steps = tc.flatness_steps(ctrl0, ctype, basis, tol)
    smp = tc.sample_params(topo, steps)
    ctrl = ext[:, topo.seg_ctrl]  # (K, S, order, 3)
    p = tc.evaluate(ctrl, ctype, basis, smp.seg, smp.t)  # (K, N, 3)

    width = np.full(len(smp.seg), DEFAULT_WIDTH)
    w = _interp_values(prim, "widths", curves.GetWidthsAttr(), curves.GetWidthsInterpolation(), frame)
    if nurbs_widths is not None:
        w = nurbs_widths
    if w is not None:
        vals, interp = w
        if widths_ok_for == "hermite" and interp == "vertex":
            interp = "varying"  # a Hermite vertex is a segment end: per-vertex widths vary linearly
        got = tc.primvar_at(vals.reshape(-1, 1), interp, topo, ctype, basis, smp)
        if got is None:
            warn("curve widths with a size that does not match their interpolation ignored", path)
        else:
            width = got[:, 0]
    width = np.where(np.isfinite(width), np.maximum(width, 0.0), 0.0)

    normals = None
    nrm = _interp_values(prim, "normals", curves.GetNormalsAttr(), curves.GetNormalsInterpolation(), frame)
    if nrm is not None and prim.GetTypeName() == "NurbsCurves":
        warn("normals of NurbsCurves ignored (rendered as tubes)", path)
        nrm = None
    if nrm is not None:
        interp = nrm[1]
        if widths_ok_for == "hermite" and interp == "vertex":
            interp = "varying"
        normals = tc.primvar_at(nrm[0].reshape(-1, 3), interp, topo, ctype, basis, smp)
        if normals is None:
            warn("curve normals with a size that does not match their interpolation ignored", path)

    colors = None  # displayColor at the samples (N, 3), through the basis like widths (BasisCurves only)
    dc = _varying_display_color(prim, frame)
    if dc is not None:
        if prim.GetTypeName() == "BasisCurves":
            colors = tc.primvar_at(dc[0], dc[1], topo, ctype, basis, smp)
        if colors is None:
            warn("curve displayColor that does not match its interpolation (or of Hermite/NURBS curves): its mean "
                 "used", path)

    tan = tc.polyline_tangents(p, smp)  # (K, N, 3)
    ncurves = len(smp.poly_start)
    poly_of = np.repeat(np.arange(ncurves), smp.poly_count)
    if normals is not None:
        mode = np.full(ncurves, -2)  # oriented ribbons
    elif view is not None:
        w_px = width / view.footprint(p[0])
        per_curve = np.zeros(ncurves)
        np.maximum.at(per_curve, poly_of, w_px)
        mode = np.where(per_curve < RIBBON_PX, -1, tc.tube_sides(0.5 * per_curve))
    else:
        mode = np.full(ncurves, NO_VIEW_SIDES)

    parts = []
    for m in np.unique(mode):
        sub, sel = _subset(smp, mode == m)
        ps, ts, ws = p[:, sel], tan[:, sel], width[sel]
        if m == -2:
            nn = tc._unit(normals[sel])
            side = tc._unit(np.cross(ts, nn), tc._any_perpendicular(ts))
            pts_, tris, nr, pair = tc.ribbon(ps, side, nn, ws, sub)
            per_sample = 2
        elif m == -1:
            facing = view.facing(ps[0])
            side = tc._unit(np.cross(ts, facing), tc._any_perpendicular(ts))
            shade = tc._unit(facing - np.sum(facing * ts[0], axis=-1, keepdims=True) * ts[0], facing)
            pts_, tris, nr, pair = tc.ribbon(ps, side, shade, ws, sub)
            per_sample = 2
        else:
            start = None
            if view is not None:  # start across the view so two vertices sit on the silhouette
                st = sub.poly_start
                start = np.cross(ts[0, st], view.facing(ps[0, st]))
            u = np.stack([tc.rotation_minimising_frames(ps[k], ts[k], sub, start) for k in range(len(ps))])
            pts_, tris, nr, pair = tc.tube(ps, u, ts, ws, int(m), sub, mean_width=view is None)
            per_sample = int(m)
        corner = None
        if colors is not None:  # ribbons have 2 vertices per sample, tubes ``sides``, in sample order
            corner = colors[sel][np.arange(pts_.shape[-2]) // per_sample][tris]
        parts.append((pts_, tris, nr, sub.curve[pair], None, corner))
    return _assemble(parts, times, len(counts))


def _subset(smp: tc.Samples, keep: np.ndarray) -> tuple[tc.Samples, np.ndarray]:
    """The polylines ``keep`` (C',) of ``smp`` as their own Samples, and the selected sample indices."""
    poly_of = np.repeat(np.arange(len(smp.poly_start)), smp.poly_count)
    sel = np.nonzero(keep[poly_of])[0]
    cnt = smp.poly_count[keep]
    start = np.zeros(len(cnt), np.int64)
    if len(cnt):
        start[1:] = np.cumsum(cnt)[:-1]
    return tc.Samples(seg=smp.seg[sel], t=smp.t[sel], curve=smp.curve[sel], closed=smp.closed[keep],
                      poly_start=start, poly_count=cnt), sel


def _assemble(parts, times, num_faces: int) -> CurveGeom | None:
    """Concatenate tessellated parts [(points (K, V, 3), tris, normals, owner, owner index map or None[, per-corner
    colours (T, 3, 3) or None])]; the colours are kept when every part has them."""
    pts, tris, nrms, faces = [], [], [], []
    corner = [part[5] if len(part) > 5 else None for part in parts]
    base = 0
    for p, t, n, owner, remap, *_ in parts:
        pts.append(p)
        tris.append(t + base)
        nrms.append(n)
        faces.append(owner if remap is None else remap[owner])
        base += p.shape[-2]
    tris = np.concatenate(tris)
    if len(tris) == 0:
        return None
    points = np.concatenate(pts, axis=-2).astype(np.float32)
    return CurveGeom(
        point_times=np.asarray(times),
        points=np.ascontiguousarray(points),
        triangles=np.ascontiguousarray(tris, np.int32),
        tri_faces=np.concatenate(faces).astype(np.int64),
        num_faces=int(num_faces),
        normals=np.ascontiguousarray(np.concatenate(nrms), np.float32),
        uvs=None,
        double_sided=True,
        solid=np.zeros(len(tris), bool),
        colors=np.ascontiguousarray(np.concatenate(corner), np.float32) if corner and all(
            c is not None for c in corner) else None,
    )


def density_camera(cam_prim, cam_row: np.ndarray, resolution, frame: float):
    """What ``view_in_object_space`` needs of the render camera (all but the object's matrix), or None."""
    cam = UsdGeom.Camera(cam_prim)
    ha = cam.GetHorizontalApertureAttr().Get(frame)
    fl = cam.GetFocalLengthAttr().Get(frame)
    ortho = cam.GetProjectionAttr().Get(frame) == UsdGeom.Tokens.orthographic
    if ha is None or fl is None or not np.isfinite(ha) or not np.isfinite(fl) or ha <= 0:
        return None
    width = int(resolution[0]) if resolution else NOMINAL_WIDTH
    return np.asarray(cam_row, np.float64), float(ha), float(fl), width, bool(ortho)
