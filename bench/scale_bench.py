#!/usr/bin/env python3
"""Scenes ten times larger (issue 13): memory and time for a 10M-triangle mesh and a 100M-triangle instanced set.

    python bench/scale_bench.py [--triangles 10e6] [--instanced 100e6] [--scatter 1e6] [--spp 4] [--keep DIR]

Each case runs in its own process (so its peak memory is its own) and prints: USD authoring size, scene load
(USD read and triangulation), hierarchy build, render time at 320x180 and the process's peak resident memory,
against this machine's 24 GiB. The scenes are generated:
- ``mesh``: one displaced grid of ``--triangles`` triangles (a rough terrain) under a distant light and a dome;
- ``instanced``: a PointInstancer placing copies of a 100k-triangle displaced sphere until ``--instanced``
  triangles are in view (1000 copies for 100M): the prototype is stored once and the instances share its BVH;
- ``scatter``: a PointInstancer of ``--scatter`` small rocks (three prototypes of 200 triangles, each instance
  turned and scaled its own way) on a ground plane, the set dressing of a production shot: what it measures is
  the cost per instance.
Prints figures, asserts nothing.
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
MACHINE_GIB = 24.0


def _grid(n: int, amplitude: float = 0.05):
    """(points (n+1)^2 x 3, quad indices n^2 x 4): a unit grid in x/z with a deterministic rough height."""
    import numpy as np

    u = np.linspace(-1.0, 1.0, n + 1, dtype=np.float32)
    x, z = np.meshgrid(u, u)
    y = amplitude * (np.sin(17.0 * x) * np.cos(13.0 * z) + 0.5 * np.sin(53.0 * x + 31.0 * z))
    pts = np.stack([x, y.astype(np.float32), z], -1).reshape(-1, 3)
    i = np.arange(n, dtype=np.int32)
    a = (i[:, None] * (n + 1) + i[None, :]).reshape(-1)
    quads = np.stack([a, a + 1, a + n + 2, a + n + 1], -1)
    return pts, quads


def _sphere(n: int):
    """A displaced UV sphere of 2 n^2 triangles (n x n quads), radius about 1."""
    import numpy as np

    pts, quads = _grid(n, 0.0)
    theta = (pts[:, 0] + 1.0) * np.pi  # 0 .. 2 pi
    phi = (pts[:, 2] + 1.0) * 0.5 * np.pi  # 0 .. pi
    r = 1.0 + 0.03 * np.sin(9.0 * theta) * np.sin(7.0 * phi)
    sph = np.stack([r * np.sin(phi) * np.cos(theta), r * np.cos(phi), r * np.sin(phi) * np.sin(theta)], -1)
    return sph.astype(np.float32), quads


def _write_mesh(stage, path, pts, quads):
    import numpy as np
    from pxr import UsdGeom, Vt

    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    m.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(quads), 4, np.int32)))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(quads.reshape(-1).astype(np.int32)))
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    return m


def _lights_and_camera(stage, eye, target):
    from pxr import Gf, UsdGeom, UsdLux

    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr(3.0)
    sun.CreateNormalizeAttr(True)
    UsdGeom.Xformable(sun).AddRotateXOp().Set(-60.0)
    UsdLux.DomeLight.Define(stage, "/World/Sky").CreateIntensityAttr(0.3)
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    m = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye), Gf.Vec3d(*target), Gf.Vec3d(0, 1, 0)).GetInverse()
    UsdGeom.Xformable(cam).AddTransformOp().Set(m)
    cam.CreateFocalLengthAttr(35.0)
    stage.SetMetadata("upAxis", "Y")


def make_mesh_scene(path: pathlib.Path, triangles: float) -> int:
    from pxr import Usd, UsdGeom

    n = int((triangles / 2) ** 0.5)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Xform.Define(stage, "/World")
    pts, quads = _grid(n)
    _write_mesh(stage, "/World/Terrain", pts * [10.0, 10.0, 10.0], quads)
    _lights_and_camera(stage, (0.0, 6.0, 14.0), (0.0, 0.0, 0.0))
    stage.Save()
    return 2 * n * n


def make_instanced_scene(path: pathlib.Path, triangles: float, per_prototype: int = 100_000) -> int:
    import numpy as np
    from pxr import Usd, UsdGeom, Vt

    n = int((per_prototype / 2) ** 0.5)
    count = max(1, int(round(triangles / (2 * n * n))))
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Xform.Define(stage, "/World")
    pi = UsdGeom.PointInstancer.Define(stage, "/World/Forest")
    UsdGeom.Scope.Define(stage, "/World/Forest/Prototypes")
    pts, quads = _sphere(n)
    _write_mesh(stage, "/World/Forest/Prototypes/Ball", pts, quads)
    pi.CreatePrototypesRel().SetTargets(["/World/Forest/Prototypes/Ball"])
    side = int(np.ceil(count ** 0.5))
    k = np.arange(count)
    pos = np.stack([(k % side - side / 2) * 2.5, np.zeros(count), (k // side - side / 2) * 2.5], -1)
    pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(pos.astype(np.float32)))
    pi.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.zeros(count, np.int32)))
    _lights_and_camera(stage, (0.0, side * 1.2, side * 2.2), (0.0, 0.0, 0.0))
    stage.Save()
    return count * 2 * n * n


def make_scatter_scene(path: pathlib.Path, count: float) -> int:
    import numpy as np
    from pxr import Usd, UsdGeom, Vt

    count = int(count)
    rng = np.random.default_rng(1)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Xform.Define(stage, "/World")
    pi = UsdGeom.PointInstancer.Define(stage, "/World/Rocks")
    UsdGeom.Scope.Define(stage, "/World/Rocks/Prototypes")
    pts, quads = _sphere(10)  # 200 triangles
    protos = []
    for k, squash in enumerate((0.5, 0.7, 0.9)):
        protos.append(f"/World/Rocks/Prototypes/Rock{k}")
        _write_mesh(stage, protos[-1], (pts * [0.3, 0.3 * squash, 0.25]).astype(np.float32), quads)
    pi.CreatePrototypesRel().SetTargets(protos)
    side = 2.0 * count ** 0.5  # a square of side x side, four rocks per square unit
    pos = rng.uniform(-0.5, 0.5, (count, 3)) * [side, 0.0, side]
    q = rng.normal(size=(count, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(pos.astype(np.float32)))
    pi.CreateOrientationsAttr(Vt.QuathArray.FromNumpy(q.astype(np.float16)))
    pi.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(rng.uniform(0.5, 1.5, (count, 3)).astype(np.float32)))
    pi.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(rng.integers(0, 3, count).astype(np.int32)))
    ground = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float32) * [side, 0.0, side]
    _write_mesh(stage, "/World/Ground", (ground - [0.0, 0.1, 0.0]).astype(np.float32), np.array([[0, 3, 2, 1]]))
    _lights_and_camera(stage, (0.0, 6.0, side * 0.5 + 12.0), (0.0, 0.0, side * 0.5 - 10.0))
    stage.Save()
    return count * len(quads) * 2


def run_case(path: str, spp: int) -> dict:
    """Load, build and render one scene in this process; the figures as a dict."""
    from renderer.settings.options import RenderOptions
    from renderer.render import load_kernels, prepare, render_frame
    from renderer.usd.importer import load_scene

    load_kernels()
    t0 = time.perf_counter()
    scene = load_scene(path)
    t1 = time.perf_counter()
    prep = prepare(scene, RenderOptions(width=320, height=180, spp=spp))
    t2 = time.perf_counter()
    r = render_frame(prep, tile_size=64, threads=2)
    peak_gib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # ru_maxrss is KiB on Linux
    return {"load": t1 - t0, "prepare": t2 - t1, "build": prep.stats.build_seconds, "render": r.seconds,
            "bvh_bytes": prep.stats.nbytes, "stored_triangles": prep.stats.triangles, "peak_gib": peak_gib}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=float, default=10e6)
    ap.add_argument("--instanced", type=float, default=100e6)
    ap.add_argument("--scatter", type=float, default=1e6, help="instances of the scatter case")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--keep", help="write the scenes here and keep them")
    ap.add_argument("--case", nargs=2, metavar=("SCENE", "SPP"), help=argparse.SUPPRESS)  # child process
    args = ap.parse_args()
    if args.case:
        print(json.dumps(run_case(args.case[0], int(args.case[1]))))
        return
    out = pathlib.Path(args.keep or tempfile.mkdtemp(prefix="drt-scale-"))
    out.mkdir(parents=True, exist_ok=True)
    print(f"# scale benchmark: 320x180, {args.spp} spp, 2 threads; each case in its own process; scenes in {out}")
    print(f"{'case':10} {'triangles':>11} {'stored':>10} {'usd MB':>7} {'make s':>7} {'load s':>7} {'build s':>7} "
          f"{'render s':>8} {'BVH B/tri':>9} {'peak GiB':>8}")
    for name, make, target in (("mesh", make_mesh_scene, args.triangles),
                               ("instanced", make_instanced_scene, args.instanced),
                               ("scatter", make_scatter_scene, args.scatter)):
        path = out / f"{name}.usdc"
        t = time.perf_counter()
        tris = make(path, target)
        made = time.perf_counter() - t
        p = subprocess.run([sys.executable, __file__, "--case", str(path), str(args.spp)], capture_output=True,
                           text=True)
        if p.returncode != 0:
            print(f"{name:10} {tris:11.3g} FAILED: {(p.stderr.strip().splitlines() or ['?'])[-1][:100]}")
            continue
        r = json.loads(p.stdout.strip().splitlines()[-1])
        # bytes per stored triangle; for the scatter the top level over its instances is nearly all of it
        per_tri = "-" if name == "scatter" else f"{r['bvh_bytes'] / max(r['stored_triangles'], 1):.1f}"
        print(f"{name:10} {tris:11.3g} {r['stored_triangles']:10.3g} {path.stat().st_size / 1e6:7.0f} {made:7.1f} "
              f"{r['load']:7.1f} {r['build']:7.1f} {r['render']:8.1f} "
              f"{per_tri:>9} {r['peak_gib']:8.2f}"
              f"{'' if r['peak_gib'] < MACHINE_GIB else '  OVER the machine'}")


if __name__ == "__main__":
    main()
