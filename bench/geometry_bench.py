#!/usr/bin/env python3
"""Geometry benchmark: memory and time for one million curve segments and one million points.

``python bench/geometry_bench.py [--spp N] [--width W] [--which curves,points,spheres,prims]``

Each case runs in a child process (so peak memory is its own) that authors a stage with usd-core, then loads it
(tessellation), prepares it (BVH build and upload) and renders it, printing the triangle count, the seconds of
each phase and the process's peak resident memory. Cases:

* curves: 100 000 hairs of 10 linear segments (1 M segments), 0.002 wide: sub-pixel, camera-facing ribbons;
* points: 1 M points 0.004 wide seen from 10 units away: tiny exact spheres (they were camera-facing hexagons);
* spheres: 1 M points 0.03 wide: a few pixels each, exact spheres (they were 20-triangle icospheres);
* prims: 10 000 gprims (spheres, cubes, cylinders, cones of 500 sizes), each under a transform of its own in
  100 groups, the set-dressing case: what costs here is the work per prim, not per triangle.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import resource
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def author(kind: str, path: pathlib.Path) -> int:
    import numpy as np
    from pxr import Gf, Usd, UsdGeom, Vt

    rng = np.random.default_rng(1)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0, 0, 10))
    cam.CreateFocalLengthAttr(50)
    cam.CreateHorizontalApertureAttr(36)
    cam.CreateVerticalApertureAttr(27)
    if kind == "curves":
        n, segs = 100_000, 10
        roots = np.stack([rng.uniform(-3, 3, n), rng.uniform(-2, 0, n), rng.uniform(-1, 1, n)], 1)
        s = np.linspace(0, 1, segs + 1)
        bend = rng.normal(0, 0.3, (n, 1))
        pts = roots[:, None, :] + np.stack([bend * s ** 2, 2.0 * np.broadcast_to(s, (n, segs + 1)),
                                            np.zeros((n, segs + 1))], -1)
        curves = UsdGeom.BasisCurves.Define(stage, "/Hair")
        curves.CreateTypeAttr("linear")
        curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts.reshape(-1, 3).astype(np.float32)))
        curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(n, segs + 1, np.int32)))
        curves.CreateWidthsAttr(Vt.FloatArray([0.002]))
        curves.SetWidthsInterpolation(UsdGeom.Tokens.constant)
        count = n * segs
    elif kind == "prims":
        count = 10_000
        kinds = (UsdGeom.Sphere, UsdGeom.Cube, UsdGeom.Cylinder, UsdGeom.Cone)
        for g in range(100):
            UsdGeom.Xform.Define(stage, f"/Set/G{g}").AddTranslateOp().Set(Gf.Vec3d(*rng.uniform(-2, 2, 3)))
            for i in range(count // 100):
                prim = kinds[i % 4].Define(stage, f"/Set/G{g}/P{i}")
                size = 0.01 * (1 + int(rng.integers(0, 500)) / 100)  # 500 distinct sizes
                if i % 4 == 1:
                    prim.CreateSizeAttr(2 * size)
                else:
                    prim.CreateRadiusAttr(size)
                prim.AddTranslateOp().Set(Gf.Vec3d(*rng.uniform(-1, 1, 3)))
                prim.AddRotateXYZOp().Set(Gf.Vec3f(*rng.uniform(-180, 180, 3)))
    else:
        n = 1_000_000
        pts = np.stack([rng.uniform(-3, 3, n), rng.uniform(-2, 2, n), rng.uniform(-1, 1, n)], 1)
        p = UsdGeom.Points.Define(stage, "/Dust")
        p.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)))
        p.CreateWidthsAttr(Vt.FloatArray([0.004 if kind == "points" else 0.03]))
        p.SetWidthsInterpolation(UsdGeom.Tokens.constant)
        count = n
    stage.GetRootLayer().Save()
    return count


def child(kind: str, spp: int, width: int) -> dict:
    from renderer.settings.options import RenderOptions
    from renderer.render import prepare, render_frame
    from renderer.usd.importer import load_scene

    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / f"{kind}.usdc"
        count = author(kind, path)
        t0 = time.perf_counter()
        scene = load_scene(path, 0.0)
        t1 = time.perf_counter()
        prep = prepare(scene, RenderOptions(width=width, height=width * 3 // 4, spp=spp))
        t2 = time.perf_counter()
        render_frame(prep, tile_size=64)
        t3 = time.perf_counter()
    tris = sum(len(m.triangles) for m in scene.meshes)
    return dict(kind=kind, elements=count, triangles=tris, load_s=t1 - t0, prepare_s=t2 - t1, render_s=t3 - t2,
                peak_gib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--which", default="curves,points,spheres,prims")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(a.child, a.spp, a.width)))
        return
    for kind in a.which.split(","):
        p = subprocess.run([sys.executable, __file__, "--child", kind, "--spp", str(a.spp), "--width", str(a.width)],
                           capture_output=True, text=True)
        if p.returncode != 0:
            print(f"{kind}: failed: {(p.stderr.strip().splitlines() or ['?'])[-1]}")
            continue
        r = json.loads(p.stdout.strip().splitlines()[-1])
        unit = {"curves": "M segments", "prims": "M gprims"}.get(kind, "M points")
        print(f"{kind:8s} {r['elements'] / 1e6:.2f} {unit}: {r['triangles'] / 1e6:.1f} M primitives, "
              f"load (tessellate) {r['load_s']:.1f} s, prepare (BVH) {r['prepare_s']:.1f} s, render "
              f"{a.width}x{a.width * 3 // 4} at {a.spp} spp {r['render_s']:.1f} s, peak memory {r['peak_gib']:.2f} GiB",
              flush=True)


if __name__ == "__main__":
    main()
