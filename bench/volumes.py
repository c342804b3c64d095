#!/usr/bin/env python3
"""A volume's cost: the example smoke (``examples/volumes.vdb``, its ``density`` grid) lit by a rect light and a dome,
against the same frame with the volume replaced by an opaque box of its bounds; and the memory its grids take.

    python bench/volumes.py [--width 640 --height 360 --spp 64] [--repeats 2]

Prints the best render time of each (2 threads), their ratio (the goal: a volume costs at most 3x its opaque
bounds), the active voxels, the field's bytes as read and the uploaded NanoVDB and majorant grids' bytes (sparse
grids stay sparse: only the tiles that hold voxels are allocated).
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile
import time

import numpy as np
from pxr import Gf, Sdf, UsdGeom, UsdLux, UsdVol

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "examples"))

import make_examples as m  # noqa: E402

from renderer.media.grids import field_bounds  # noqa: E402
from renderer.media.openvdb import read_field  # noqa: E402
from renderer.settings.options import RenderOptions  # noqa: E402
from renderer.render import prepare, render_frame  # noqa: E402
from renderer.usd.importer import load_scene  # noqa: E402

VDB = ROOT / "examples" / "volumes.vdb"
LIFT = np.array([0.0, 0.75, 0.0])  # the smoke sits above the floor


def stage(path: pathlib.Path, kind: str, bounds) -> pathlib.Path:
    st = m.new_stage(path)
    m.box(st, "/World/Floor", (8.0, 0.1, 6.0), (0, -0.05, 0), m.surface(st, "Floor", diffuseColor=(0.5, 0.5, 0.5)))
    if kind == "volume":
        vol = UsdVol.Volume.Define(st, "/World/Smoke")
        field = UsdVol.OpenVDBAsset.Define(st, "/World/Smoke/density")
        field.CreateFilePathAttr(Sdf.AssetPath(str(VDB)))
        field.CreateFieldNameAttr("density")
        vol.CreateFieldRelationship("density", field.GetPath())
        UsdGeom.Xformable(vol).AddTranslateOp().Set(Gf.Vec3d(*LIFT))
    else:
        lo, hi = bounds
        m.box(st, "/World/Smoke", tuple(float(x) for x in hi - lo), tuple(float(x) for x in (lo + hi) / 2 + LIFT),
              m.surface(st, "Grey", diffuseColor=(0.7, 0.7, 0.7)))
    m.rect_light(st, "/World/Key", 1.5, 1.0, 14.0, (-1.5, 3.0, 2.0), (-55.0, -30.0, 0.0))
    UsdLux.DomeLight.Define(st, "/World/Sky").CreateIntensityAttr(0.25)
    m.look_at_camera(st, (0.0, 1.4, 4.6), (0.0, 0.6, 0.0))
    st.GetRootLayer().Save()
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    field = read_field(str(VDB), "density", 0)
    bounds = field_bounds(field)
    best = {}
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("bounds", "volume"):
            scene = load_scene(stage(pathlib.Path(tmp) / f"{kind}.usda", kind, bounds))
            prep = prepare(scene, RenderOptions(width=args.width, height=args.height, spp=args.spp))
            times = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                render_frame(prep, threads=2)
                times.append(time.perf_counter() - t)
            best[kind] = min(times)
            print(f"{kind:7s} {args.width}x{args.height}, {args.spp} spp: {best[kind]:.2f} s")
            if kind == "volume":
                print(f"volume: {len(field.coords)} active voxels, {field.nbytes / 1e6:.2f} MB as read, "
                      f"{prep.media.nbytes / 1e6:.2f} MB uploaded (NanoVDB and majorant grids)")
    print(f"volume / opaque bounds: {best['volume'] / best['bounds']:.2f}x (goal <= 3x)")


if __name__ == "__main__":
    main()
