"""Reading OpenVDB files into ``VolumeField`` s, with the ``tinyvdb`` package (a maintained OpenVDB/NanoVDB reader
on PyPI, file versions 220-225: OpenVDB 3 to 10+; no OpenVDB library needed).

A grid is chosen as UsdVol's ``OpenVDBAsset`` does: by ``fieldName`` (the grid's name in the file) and, when
several grids share the name, by ``fieldIndex`` among them (in file order). Its active voxels and values become
the field (sparse: only active voxels), its linear transform the field's index-to-object matrix.

Limits of the reader (each a warning where it applies, never a wrong image): tinyvdb 0.9 returns the voxels of
scalar grids (float and double) only, so vector grids (a velocity ``vel``, a colour ``Cd``) cannot be read;
three scalar grids ``<name>.x``, ``<name>.y``, ``<name>.z`` (Houdini's split vector fields) are read as one
vector field instead. Level sets (``fieldClass = levelSet``) are not fog and are skipped by the importer.
"""
from __future__ import annotations

import threading

import numpy as np

from renderer.scene.model import VolumeField

MISSING_READER = "reading .vdb files needs the tinyvdb package: install it with pip install tinyvdb"


class VdbError(Exception):
    """A grid that cannot be read: the message says why."""


def _tinyvdb():
    try:
        import tinyvdb
    except ImportError:
        raise VdbError(MISSING_READER) from None
    return tinyvdb


_LOCK = threading.Lock()
_FILES: dict[str, object] = {}  # path -> opened tinyvdb file with its grids read (per process)


def _open(path: str):
    tv = _tinyvdb()
    with _LOCK:
        f = _FILES.get(path)
        if f is None:
            try:
                f = tv.open(path)
                f.read_grids()
            except (OSError, RuntimeError) as e:
                raise VdbError(f"cannot read {path}: {' '.join(str(e).split())}") from None
            _FILES[path] = f
        return f


def index_to_object(transform: dict) -> np.ndarray:
    """The 4x4 column-vector matrix of an OpenVDB linear transform as tinyvdb describes it."""
    kind = str(transform.get("type", ""))
    m = np.eye(4)
    if "scale" in kind or "translate" in kind:
        m[:3, :3] = np.diag(np.asarray(transform.get("scale", transform.get("voxel_size", (1, 1, 1))), np.float64))
        m[:3, 3] = np.asarray(transform.get("translation", (0, 0, 0)), np.float64)
        return m
    rows = np.asarray(transform.get("matrix", np.eye(4)), np.float64)  # OpenVDB: row vectors, translation last row
    return rows.T.copy()


def _scalar_grid(f, i: int, label: str) -> VolumeField:
    g = f.grid(i)
    try:
        sp = g.to_sparse()
    except RuntimeError as e:
        raise VdbError(f"grid {label} ({g.type_name}) cannot be read by tinyvdb: only scalar grids are "
                       f"({' '.join(str(e).split())})") from None
    coords = np.frombuffer(sp["coords"], np.int32).reshape(-1, 3).copy()
    values = np.frombuffer(sp["values"], np.float32).copy()
    return VolumeField(g.name, coords, values, index_to_object(g.transform), float(g.float_background()))


def read_field(path: str, name: str, index: int = 0) -> VolumeField:
    """The ``index``-th grid named ``name`` in the file (``name`` empty: the ``index``-th grid of the file)."""
    f = _open(path)
    names = [f.grid_name(i) for i in range(f.grid_count)]
    matches = [i for i, n in enumerate(names) if n == name] if name else list(range(len(names)))
    if index < len(matches):
        return _scalar_grid(f, matches[index], f"'{names[matches[index]]}' of {path}")
    parts = [[i for i, n in enumerate(names) if n == f"{name}.{c}"] for c in "xyz"]
    if name and all(len(p) > index for p in parts):  # a vector field split into three scalar grids
        comps = [_scalar_grid(f, p[index], f"'{name}' of {path}") for p in parts]
        coords = np.unique(np.concatenate([c.coords for c in comps]), axis=0)
        values = np.zeros((len(coords), 3), np.float32)
        for k, c in enumerate(comps):
            lut = {tuple(x): v for x, v in zip(c.coords.tolist(), c.values.tolist())}
            values[:, k] = [lut.get(tuple(x), c.background) for x in coords.tolist()]
        return VolumeField(name, coords.astype(np.int32), values, comps[0].index_to_object)
    what = f"grid '{name}'" if name else "grid"
    raise VdbError(f"{path} has no {what} of index {index} (grids: {', '.join(names) or 'none'})")
