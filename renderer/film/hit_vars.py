"""Vars of what each sample saw first: its point ``P``, a primvar interpolated there, and the ids of what it hit.

``P`` and primvars are filtered as the beauty over the samples that hit something (as depth is): each sample's
value goes into the sample buffer's hit triples (``SampleBuffer.hits``, one per var), with one more triple holding
1 for a sample that hit; the pixel's value is the filtered sum over the filtered hit
fraction. The values come from the hit records the kernel keeps (instance, global triangle, barycentrics,
world point): a primvar is interpolated from its per-corner values on the mesh (``Mesh.primvars``: what the
importer read for the names asked), a constant primvar is its value, and a hit on a prim without the primvar
reads 0.

``primId`` and ``instanceId`` are not filtered (an average of ids means nothing): they are the id that covers
most of the pixel in the Cryptomatte object table (``film.coverage``): ``primId`` the index of the instance (each
prim and each PointInstancer placement), ``instanceId`` the placement's index in its PointInstancer (-1 for a
prim that is not a PointInstancer's instance); -1 where nothing was hit.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

P = "P"
PRIMVAR = "primvar:"  # key prefix: primvar:<name>
ID_SOURCES = ("primId", "instanceId")
_PLACEMENT = re.compile(r"\[(\d+)\]")


@dataclass(frozen=True)
class HitLayout:
    """The hit vars of a render: triple i holds var i, the triple after them the hit flag."""

    keys: tuple[str, ...]  # "P" or "primvar:<name>"
    widths: tuple[int, ...]  # components of each (1-3)

    @property
    def triples(self) -> int:
        """Triples used, the hit flag's included."""
        return len(self.keys) + 1 if self.keys else 0

    @property
    def coverage(self) -> int:
        return len(self.keys)


def layout(keys: tuple[str, ...], widths: dict[str, int]) -> HitLayout:
    return HitLayout(tuple(keys), tuple(min(3, max(1, widths.get(k, 3))) for k in keys))


def primvar_names(keys) -> tuple[str, ...]:
    return tuple(k[len(PRIMVAR):] for k in keys if k.startswith(PRIMVAR))


def fill(plan: HitLayout, scene, inst_mesh: np.ndarray, mesh_tri_off: np.ndarray, hit_inst: np.ndarray,
         hit_tri: np.ndarray, hit_uv: np.ndarray, hit_p: np.ndarray, out: np.ndarray) -> None:
    """Write the hit vars of n samples into ``out`` (n, triples, 3), from their hit records."""
    if not plan.keys:
        return
    hit = hit_inst >= 0
    out[:] = 0.0
    out[hit, plan.coverage, 0] = 1.0
    if not hit.any():
        return
    idx = np.flatnonzero(hit)
    meshes = inst_mesh[hit_inst[idx]]
    local = hit_tri[idx] - mesh_tri_off[meshes]
    b1, b2 = hit_uv[idx, 0], hit_uv[idx, 1]
    for slot, key in enumerate(plan.keys):
        if key == P:
            out[idx, slot] = hit_p[idx]
            continue
        name = key[len(PRIMVAR):]
        for m in np.unique(meshes):
            values = scene.meshes[m].primvars.get(name)
            if values is None:
                continue
            sel = meshes == m
            rows = idx[sel]
            v = np.asarray(values, np.float32)
            if v.ndim == 1:  # constant over the prim
                at = np.broadcast_to(v[:3], (len(rows), min(3, v.size)))
            else:
                t = np.clip(local[sel], 0, len(v) - 1)
                w1, w2 = b1[sel, None], b2[sel, None]
                at = (v[t, 0] * (1.0 - w1 - w2) + v[t, 1] * w1 + v[t, 2] * w2)[:, :3]
            out[rows, slot, :at.shape[1]] = at


def resolve(plan: HitLayout, hits: np.ndarray) -> dict[str, np.ndarray]:
    """(H, W, width) values of each hit var from the resolved hit triples (H, W, 3 x triples)."""
    if not plan.keys:
        return {}
    cov = hits[..., 3 * plan.coverage]
    out = {}
    with np.errstate(divide="ignore", invalid="ignore"):
        for i, (key, width) in enumerate(zip(plan.keys, plan.widths)):
            v = hits[..., 3 * i:3 * i + width]
            out[key] = np.where(cov[..., None] > 0, v / cov[..., None], 0.0).astype(np.float32)
    return out


def placement_index(name: str) -> int:
    """A PointInstancer placement's index from its name (``/path/instancer[i]/proto``), else -1."""
    found = _PLACEMENT.findall(name)
    return int(found[-1]) if found else -1


def id_values(source: str, ids: np.ndarray, scene) -> np.ndarray:
    """(H, W) float32 of ``primId`` / ``instanceId`` from the object table's most covering ids (H, W; -1: none)."""
    if source == "primId":
        return ids.astype(np.float32)
    placements = np.array([placement_index(i.name) for i in scene.instances] + [-1], np.int64)
    return placements[np.where(ids >= 0, ids, len(placements) - 1)].astype(np.float32)
