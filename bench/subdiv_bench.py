#!/usr/bin/env python3
"""Subdivision benchmark: prints figures, asserts nothing. ``python bench/subdiv_bench.py [--levels 1,2,3]``.

Refines every subdivision-surface mesh of a production asset from ../shared/usd-assets (the usd-wg teapot
layouts: ``DrawModes.usd``, 35 Catmull-Clark cages, 67,680 faces; ``Teapot.usd``, one cage of 1,236 faces) at
each level, with limit points and normals, and prints wall time, triangles per second and the peak memory the
refinement allocated (tracemalloc, which sees NumPy's buffers; the largest mesh's refinement sets it). Then the
whole ``load_scene`` with the level chosen from the camera. Noise on a shared 2-core machine is large.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time
import tracemalloc

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
ASSETS = ROOT.parent / "shared" / "usd-assets"
if not ASSETS.is_dir():
    ASSETS = pathlib.Path("/work/shared/usd-assets")

from pxr import Usd, UsdGeom  # noqa: E402

from renderer.subdiv import SubdivOptions, subdivide  # noqa: E402
from renderer.usd.importer import load_scene  # noqa: E402


def cages(path: pathlib.Path):
    stage = Usd.Stage.Open(str(path))
    out = []
    for prim in Usd.PrimRange.Stage(stage, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)):
        if not prim.IsA(UsdGeom.Mesh):
            continue
        mesh = UsdGeom.Mesh(prim)
        if mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none:
            continue
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(), np.int64)
        idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), np.int64)
        pts = np.asarray(mesh.GetPointsAttr().Get(), np.float64)
        out.append((counts, idx, pts))
    return out


def refine_all(meshes, level):
    tris = 0
    for counts, idx, pts in meshes:
        ref = subdivide(counts, idx, len(pts), SubdivOptions(), level)
        control = ref.control_points(pts)
        limit = ref.limit.apply(control) if ref.limit is not None else control
        ref.normals(limit, control)
        tris += len(ref.triangles)
    return tris


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="1,2,3")
    args = ap.parse_args()
    for name in ("usdwg_teapot_asset/DrawModes.usd", "usdwg_teapot_asset/Teapot.usd"):
        path = ASSETS / name
        if not path.exists():
            print(f"{name}: not present")
            continue
        meshes = cages(path)
        faces = sum(len(m[0]) for m in meshes)
        print(f"{name}: {len(meshes)} subdivision meshes, {faces} faces")
        for level in (int(x) for x in args.levels.split(",")):
            tracemalloc.start()
            t0 = time.perf_counter()
            tris = refine_all(meshes, level)
            took = time.perf_counter() - t0
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            print(f"  level {level}: {tris:>9,} triangles in {took:6.2f} s ({tris / took / 1e3:7.1f} k tri/s), "
                  f"peak {peak / 2**20:7.1f} MiB (meshes are refined one at a time)")
        t0 = time.perf_counter()
        scene = load_scene(path)
        took = time.perf_counter() - t0
        tris = sum(len(m.triangles) for m in scene.meshes)
        print(f"  load_scene (level from the camera or {2} without one): {tris:,} triangles in {took:.2f} s")


if __name__ == "__main__":
    main()
