"""Writing .vdb files for tests with OpenVDB's own Python module (``pyopenvdb``, Debian's ``python3-openvdb``).

The module is built for the system's Python and its NumPy 1.x, not this environment's, so the grids are written
by a child process of ``/usr/bin/python3``; tests skip, saying why, where it is absent (``.ci/run`` installs it
where apt-get can).
"""
from __future__ import annotations

import json
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

SYSTEM_PYTHON = "/usr/bin/python3"

WRITER = r"""
import json, sys
import numpy as np
import pyopenvdb as vdb
spec = json.load(open(sys.argv[1]))
grids = []
for g in spec["grids"]:
    data = np.load(g["npy"])
    grid = vdb.Vec3SGrid() if data.ndim == 4 else vdb.FloatGrid()
    grid.name = g["name"]
    grid.copyFromArray(data, ijk=tuple(g["ijk"]))
    t = vdb.createLinearTransform(voxelSize=g["voxel_size"])
    t.translate(tuple(g["translation"]))
    grid.transform = t
    if g.get("fog", True):
        grid.gridClass = vdb.GridClass.FOG_VOLUME
    grids.append(grid)
vdb.write(spec["path"], grids=grids)
"""


def have_openvdb() -> bool:
    if not shutil.which(SYSTEM_PYTHON):
        return False
    return subprocess.run([SYSTEM_PYTHON, "-c", "import pyopenvdb"], capture_output=True).returncode == 0


needs_openvdb = pytest.mark.skipif(not have_openvdb(), reason="writing .vdb test files needs OpenVDB's Python "
                                   "module for /usr/bin/python3 (Debian: apt install python3-openvdb)")


def write_vdb(path, grids: list[dict]) -> pathlib.Path:
    """Write grids {name, data (nx, ny, nz[, 3]) indexed x, y, z, ijk of data[0, 0, 0], voxel_size} to ``path``."""
    path = pathlib.Path(path)
    spec = {"path": str(path), "grids": []}
    for k, g in enumerate(grids):
        npy = path.with_name(f"{path.stem}_{k}.npy")
        np.save(npy, np.asarray(g["data"], np.float32))
        spec["grids"].append({"name": g["name"], "npy": str(npy), "ijk": list(g.get("ijk", (0, 0, 0))),
                              "voxel_size": float(g.get("voxel_size", 1.0)),
                              "translation": list(g.get("translation", (0.0, 0.0, 0.0)))})
    js = path.with_suffix(".json")
    js.write_text(json.dumps(spec))
    run = subprocess.run([SYSTEM_PYTHON, "-c", WRITER, str(js)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return path
