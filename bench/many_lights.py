"""Render time against the number of area lights: the bench's Cornell box with its ceiling light replaced by an
N x N grid of rect lights (the same total area, spread over the same patch), N^2 = 1, 64, 256, 1024.

    python bench/many_lights.py [--width 320 --height 180 --spp 16] [--counts 1 64 256 1024]

Prints each count's render time (``drt render``'s own figure, best of ``--repeats``) and its ratio to the first
count's (one light by default).
A scattered ray tests the area lights whose boxes it enters (``renderer.lights.reach``): with a tree over them the
time should barely grow with the count; testing every light in turn, it grew 7.8x from 1 to 1024 lights.
"""
from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
import tempfile
from pathlib import Path

CORNELL = Path(__file__).resolve().parents[2] / "shared" / "bench" / "scenes" / "cornell.usda"
if not CORNELL.is_file():  # a clone elsewhere on the development machine
    CORNELL = Path("/work/shared/bench/scenes/cornell.usda")


def grid_scene(src: str, n: int) -> str:
    """The Cornell box with its one rect light (24 x 19 at y = 99.9) replaced by n x n lights of 90 % of a cell:
    the text from ``def RectLight "CeilingLight"`` to ``def Camera "Camera"`` is replaced."""
    start, end = src.index('    def RectLight "CeilingLight"'), src.index('    def Camera "Camera"')
    lights = []
    for i in range(n):
        for j in range(n):
            x, z = 38.0 + 24.0 * (i + 0.5) / n, -59.5 + 19.0 * (j + 0.5) / n
            lights.append(f"""    def RectLight "L_{i}_{j}"
    {{
        float inputs:height = {19.0 / n * 0.9}
        float inputs:intensity = 40
        bool inputs:normalize = 0
        float inputs:width = {24.0 / n * 0.9}
        float xformOp:rotateX = -90
        double3 xformOp:translate = ({x}, 99.9, {z})
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateX"]
    }}
""")
    return src[:start] + "".join(lights) + src[end:]


def render_seconds(scene: Path, args) -> float:
    out = subprocess.run([sys.executable, "-m", "service.cli", "render", str(scene), "-o", str(scene.with_suffix(".exr")),
                          "--width", str(args.width), "--height", str(args.height), "--spp", str(args.spp)],
                         capture_output=True, text=True, check=True)
    return float(re.search(r"([0-9.]+) s render", out.stdout + out.stderr).group(1))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=180)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--counts", type=int, nargs="+", default=[1, 64, 256, 1024])
    p.add_argument("--scene", type=Path, default=CORNELL, help="the Cornell box (../shared/bench/scenes)")
    args = p.parse_args(argv)
    if not args.scene.is_file():
        p.error(f"scene not found: {args.scene} (pass --scene: a scene with a RectLight \"CeilingLight\" defined "
                f"just before its Camera \"Camera\", as the bench's Cornell box)")
    src = args.scene.read_text()
    base = None
    with tempfile.TemporaryDirectory() as tmp:
        for count in args.counts:
            n = max(1, round(math.sqrt(count)))
            scene = Path(tmp) / f"cornell_{n * n}.usda"
            scene.write_text(grid_scene(src, n))
            t = min(render_seconds(scene, args) for _ in range(args.repeats))
            base = t if base is None else base
            ratio = f"{t / base:.2f}x" if base > 0 else "-"
            print(f"{n * n:5d} rect lights: {t:.2f} s render ({ratio} the first count), "
                  f"{args.width}x{args.height}, {args.spp} spp", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
