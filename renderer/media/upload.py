"""Uploading a scene's media: each volume field as a sparse NanoVDB grid (Warp's ``wp.Volume``), the majorant
grids, the blackbody table, and the homogeneous media of materials, into one ``tracking.Media`` struct.

A field's active voxels go into 8^3 tiles (NanoVDB's leaves, as OpenVDB's): only tiles holding active voxels are
allocated, so a sparse grid stays sparse. ``MediaUpload.nbytes`` is the memory the grids take.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from renderer.media import grids
from renderer.media.phase import G_MAX
from renderer.media.tracking import EMIT_DENSITY, EMIT_FIELD, EMIT_NONE, Media
from renderer.motion.kernels import upload_keys
from renderer.motion.transform import matrix_at
from renderer.scene.model import Material, Scene, VolumeField

wp.set_module_options({"enable_backward": False})

TILE = 8  # voxels per tile side (NanoVDB leaf)


@wp.kernel
def store_scalars_kernel(vid: wp.uint64, coords: wp.array(dtype=wp.vec3i), values: wp.array(dtype=wp.float32)):
    i = wp.tid()
    c = coords[i]
    wp.volume_store_f(vid, c[0], c[1], c[2], values[i])


@wp.kernel
def store_vectors_kernel(vid: wp.uint64, coords: wp.array(dtype=wp.vec3i), values: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    c = coords[i]
    wp.volume_store_v(vid, c[0], c[1], c[2], values[i])


@dataclass
class MediaUpload:
    """The kernels' struct and the Warp grids it refers to (kept alive here)."""

    media: Media
    grids: list = field(default_factory=list)  # wp.Volume objects
    nbytes: int = 0  # NanoVDB grids and majorant grids
    count: int = 0


def nanovdb_grid(f: VolumeField, device: str) -> wp.Volume:
    """A NanoVDB grid of the field's active voxels (tiles of 8^3 where any voxel is active) and its transform."""
    coords = np.ascontiguousarray(f.coords, np.int32).reshape(-1, 3)
    m = np.asarray(f.index_to_object, np.float64)
    tiles = np.unique(np.floor_divide(coords, TILE), axis=0) * TILE if len(coords) else np.zeros((1, 3), np.int32)
    bg = (0.0, 0.0, 0.0) if f.vector else float(f.background)
    vol = wp.Volume.allocate_by_tiles(wp.array(tiles.astype(np.int32), dtype=wp.vec3i, device=device),
                                      bg_value=bg, translation=tuple(m[:3, 3]),
                                      transform=wp.mat33(*m[:3, :3].ravel()), device=device)
    if len(coords):
        c = wp.array(coords, dtype=wp.vec3i, device=device)
        if f.vector:
            wp.launch(store_vectors_kernel, dim=len(coords), device=device,
                      inputs=[vol.id, c, wp.array(np.asarray(f.values, np.float32).reshape(-1, 3), dtype=wp.vec3,
                                                  device=device)])
        else:
            wp.launch(store_scalars_kernel, dim=len(coords), device=device,
                      inputs=[vol.id, c, wp.array(np.asarray(f.values, np.float32), dtype=wp.float32, device=device)])
    return vol


def material_media(materials: list[Material]) -> np.ndarray:
    """(M, 4) float32: per material its interior scattering coefficient (rgb, per scene unit) and anisotropy."""
    out = np.zeros((max(1, len(materials)), 4), np.float32)
    for i, m in enumerate(materials):
        d = m.scatter_distance if np.isfinite(m.scatter_distance) and m.scatter_distance > 0 else 1.0
        out[i, :3] = np.maximum(np.asarray(m.scatter_color, np.float64), 0.0) / d
        out[i, 3] = np.clip(m.scatter_anisotropy, -G_MAX, G_MAX)
    return out


def upload_media(scene: Scene, materials: list[Material], device: str = "cpu", warn=lambda *a: None) -> MediaUpload:
    """The ``Media`` struct of the scene's volumes and of ``materials`` (the uploaded list, in material order)."""
    sh = scene.shutter
    seconds = (sh.close - sh.open) / max(sh.time_codes_per_second, 1e-9)  # the shutter's length in seconds
    up = MediaUpload(media=Media())
    placed = []
    for vol in scene.volumes:
        speed = grids.max_speed(vol)
        # normalised time runs 0..1 over the shutter: a lookup moves by v * (s - frame_s) * seconds
        reach = speed * seconds * max(sh.frame_s, 1.0 - sh.frame_s)
        maj = grids.majorant_grid(vol, reach)
        if maj is None:
            warn("volume has no density or emission to render", vol.name)
            continue
        placed.append((vol, maj))
    n = len(placed)
    k = Media()
    k.count = n
    k.frame_s = float(sh.frame_s)
    keys, offs, counts = upload_keys([v.transform for v, _ in placed], device)
    k.keys = keys
    k.xf_off = _arr(offs if n else [0], np.int32, wp.int32, device)
    k.xf_count = _arr(counts if n else [1], np.int32, wp.int32, device)
    k.w2o = _arr([np.linalg.inv(matrix_at(v.transform, 0.0)) for v, _ in placed] or [np.eye(4)], np.float32,
                 wp.mat44, device)
    ids = {name: [] for name in ("density", "temperature", "emission", "velocity")}
    for vol, _ in placed:
        for name in ids:
            f = getattr(vol, name)
            if f is None or (name == "temperature" and vol.medium.blackbody_intensity <= 0):
                ids[name].append(0)
                continue
            g = nanovdb_grid(f, device)
            up.grids.append(g)
            up.nbytes += int(g.array().capacity)
            ids[name].append(g.id)
    k.density = _ids(ids["density"], device)
    k.temperature = _ids(ids["temperature"], device)
    k.emission_grid = _ids(ids["emission"], device)
    k.velocity = _ids(ids["velocity"], device)
    k.vel_dt = _arr([seconds * v.medium.velocity_scale for v, _ in placed] or [0.0], np.float32, wp.float32, device)
    meds = [v.medium for v, _ in placed]
    k.absorption = _arr([np.asarray(m.absorption) * m.density_scale for m in meds] or [(0, 0, 0)], np.float32,
                        wp.vec3, device)
    k.scattering = _arr([np.asarray(m.scattering) * m.density_scale for m in meds] or [(0, 0, 0)], np.float32,
                        wp.vec3, device)
    k.g = _arr([np.clip(m.anisotropy, -G_MAX, G_MAX) for m in meds] or [0.0], np.float32, wp.float32, device)
    k.emission = _arr([m.emission for m in meds] or [(0, 0, 0)], np.float32, wp.vec3, device)
    kinds = []
    for vol, _ in placed:
        med = vol.medium
        if max(med.emission) <= 0:
            kinds.append(EMIT_NONE)
        elif vol.emission is not None:
            kinds.append(EMIT_FIELD)
        elif med.emission_from_density:
            kinds.append(EMIT_DENSITY)
        else:
            kinds.append(EMIT_NONE)
    k.emit_kind = _arr(kinds or [EMIT_NONE], np.int32, wp.int32, device)
    k.blackbody = _arr([(m.temperature_scale, m.blackbody_intensity if v.temperature is not None else 0.0)
                        for v, _ in placed for m in [v.medium]] or [(0.0, 0.0)], np.float32, wp.vec2, device)
    los, cells, dims, offs_m, cells_all = [], [], [], [], []
    total = 0
    for _, (lo, cell, grid) in placed:
        los.append(lo)
        cells.append(cell)
        dims.append(grid.shape[::-1])
        offs_m.append(total)
        total += grid.size
        cells_all.append(grid.ravel())
    k.maj_lo = _arr(los or [(0, 0, 0)], np.float32, wp.vec3, device)
    k.maj_cell = _arr(cells or [(1, 1, 1)], np.float32, wp.vec3, device)
    k.maj_dims = _arr(dims or [(1, 1, 1)], np.int32, wp.vec3i, device)
    k.maj_off = _arr(offs_m or [0], np.int32, wp.int32, device)
    k.maj = _arr(np.concatenate(cells_all) if cells_all else [0.0], np.float32, wp.float32, device)
    up.nbytes += int(total * 4)
    table, step = grids.blackbody_table()
    k.bb_rgb = wp.array(table, dtype=wp.vec3, device=device)
    k.bb_step = float(step)
    mm = material_media(materials)
    k.mat_scatter = wp.array(mm, dtype=wp.vec4, device=device)
    k.mesh_media = int(bool((mm[:, :3] > 0).any()))
    up.media = k
    up.count = n
    return up


def _arr(values, np_dtype, wp_dtype, device):
    return wp.array(np.ascontiguousarray(np.asarray(values, np_dtype)), dtype=wp_dtype, device=device)


def _ids(ids: list[int], device) -> wp.array:
    return wp.array(np.asarray(ids or [0], np.uint64), dtype=wp.uint64, device=device)
