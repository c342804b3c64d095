"""A range of frames on a farm slot: N frames in one ``drt render -f A -n N`` process, against N single-frame
processes (one per frame, as a farm without frame ranges runs them). Prints the wall-clock time per frame of each.

    python bench/farm_range.py [--scene examples/demo.usda] [--frames 8] [--res 320 180] [--spp 8]

The one process opens the stage once, loads the kernels once and reuses the hierarchy and textures of a frame
whose geometry and materials did not change; each single-frame process pays its start-up (interpreter, USD,
Warp), the stage and the hierarchy again. Both write the same EXRs (compared at the end).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).absolute().parents[1]


def drt(*args, cwd) -> float:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "service.cli", "render", *map(str, args), "--quiet"], cwd=cwd,
                       env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(r.stderr)
    return time.perf_counter() - t


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=str(REPO / "examples" / "demo.usda"))
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--first", type=float, default=1.0)
    p.add_argument("--res", type=int, nargs=2, default=(320, 180))
    p.add_argument("--spp", type=int, default=8)
    a = p.parse_args()
    common = [os.path.abspath(a.scene), "--res", *a.res, "--spp", a.spp, "-o", "f.$F4.exr"]
    with tempfile.TemporaryDirectory() as d:
        one, many = Path(d, "one"), Path(d, "many")
        one.mkdir()
        many.mkdir()
        drt(*common, "-f", a.first, cwd=many)  # warm the kernel cache and the file cache for both
        t_one = drt(*common, "-f", a.first, "-n", a.frames, cwd=one)
        t_many = sum(drt(*common, "-f", a.first + k, cwd=many) for k in range(a.frames))
        from renderer.film.exr import read_exr

        names = sorted(f.name for f in one.glob("*.exr"))
        assert names == sorted(f.name for f in many.glob("*.exr")) and len(names) == a.frames, names
        same = all(np.array_equal(read_exr(one / n)[0]["R"], read_exr(many / n)[0]["R"]) for n in names)
    print(f"{Path(a.scene).name}, {a.frames} frames of {a.res[0]}x{a.res[1]} at {a.spp} spp "
          f"({'identical' if same else 'DIFFERENT'} images)")
    print(f"  one process, -f {a.first:g} -n {a.frames}: {t_one:7.2f} s, {t_one / a.frames:6.3f} s per frame")
    print(f"  {a.frames} single-frame processes:  {t_many:7.2f} s, {t_many / a.frames:6.3f} s per frame")
    print(f"  saved per frame: {(t_many - t_one) / a.frames:.3f} s ({t_many / t_one:.2f}x)")


if __name__ == "__main__":
    main()
