"""Grids of a volume in NumPy: object-space bounds, the majorant grid the kernels walk, the blackbody table.

The **majorant grid** covers a volume's object-space box with at most ``MAJORANT_RES`` cells per axis, each at
least two voxels' reach wide, and holds per cell an upper bound of the extinction (largest RGB channel, per scene
unit) anywhere in the cell: every active voxel raises the cells its trilinear reach (one voxel each way) overlaps.
With a velocity field the density seen at a point was looked up up to |v| dt away, so cells are widened by that
reach too. Where the medium emits but does not extinguish, cells get a rate of one collision per voxel so that the
walk gathers the emission there (``tracking``).
"""
from __future__ import annotations

import numpy as np

from renderer.scene.model import Volume, VolumeField

MAJORANT_RES = 32  # cells per axis at most
BLACKBODY_MAX_K = 20000.0  # the table's last temperature (kelvin); hotter reads the last entry
BLACKBODY_STEP_K = 25.0
BLACKBODY_REFERENCE_K = 6500.0  # the temperature whose blackbody radiance has luminance 1


def voxel_centres(f: VolumeField) -> np.ndarray:
    """(N, 3) object-space centres of a field's active voxels."""
    m = np.asarray(f.index_to_object, np.float64)
    return f.coords.astype(np.float64) @ m[:3, :3].T + m[:3, 3]


def voxel_reach(f: VolumeField) -> np.ndarray:
    """Half-extent (3,) in object space of the box a voxel's trilinear reach (one voxel each way) covers."""
    m = np.asarray(f.index_to_object, np.float64)
    return np.abs(m[:3, :3]).sum(axis=1)


def field_bounds(f: VolumeField) -> tuple[np.ndarray, np.ndarray] | None:
    """Object-space box of where the field is non-zero (trilinear reach included), or None when empty."""
    if len(f.coords) == 0:
        return None
    nz = f.values != 0 if not f.vector else np.any(f.values != 0, axis=1)
    if not nz.any():
        return None
    c = voxel_centres(VolumeField(f.name, f.coords[nz], f.values[nz], f.index_to_object))
    r = voxel_reach(f)
    return c.min(axis=0) - r, c.max(axis=0) + r


def max_speed(vol: Volume) -> float:
    """Largest velocity magnitude of the volume (object units per second, times its velocity scale)."""
    if vol.velocity is None or len(vol.velocity.values) == 0:
        return 0.0
    v = np.asarray(vol.velocity.values, np.float64).reshape(-1, 3)
    return float(np.sqrt((v * v).sum(axis=1)).max()) * abs(vol.medium.velocity_scale)


def extinction_scale(vol: Volume) -> float:
    """Largest RGB extinction per unit density (per scene unit)."""
    med = vol.medium
    return float(max(np.asarray(med.absorption, np.float64) + np.asarray(med.scattering, np.float64))) \
        * med.density_scale


def emits(vol: Volume) -> list[VolumeField]:
    """The fields whose non-zero values make the volume emit."""
    med = vol.medium
    out = []
    if max(med.emission) > 0 and vol.emission is not None:
        out.append(vol.emission)
    elif max(med.emission) > 0 and med.emission_from_density and vol.density is not None:
        out.append(vol.density)
    if med.blackbody_intensity > 0 and vol.temperature is not None:
        out.append(vol.temperature)
    return out


def majorant_grid(vol: Volume, advect: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(lo (3,), cell (3,), grid (nz, ny, nx) float32) of the volume, or None when it holds nothing.

    ``advect`` is the longest distance (object units) a velocity moves a lookup over the shutter.
    """
    boxes = [b for b in (field_bounds(f) for f in [vol.density, *emits(vol)] if f is not None) if b is not None]
    if not boxes:
        return None
    lo = np.min([b[0] for b in boxes], axis=0) - advect
    hi = np.max([b[1] for b in boxes], axis=0) + advect
    reach = max((voxel_reach(f) for f in [vol.density, *emits(vol)] if f is not None), key=lambda r: r.max())
    extent = np.maximum(hi - lo, 1e-6)
    dims = np.clip(np.floor(extent / (2.0 * np.maximum(reach, 1e-9))), 1, MAJORANT_RES).astype(np.int64)
    cell = extent / dims
    grid = np.zeros(dims[::-1], np.float64)
    sigma = extinction_scale(vol)
    if vol.density is not None and sigma > 0:
        _raise_cells(grid, lo, cell, dims, vol.density, np.maximum(_scalar(vol.density), 0.0) * sigma)
    for f in emits(vol):  # a collision per voxel (at least) where it emits
        rate = np.where(_scalar(f) > 0, 1.0 / float(np.min(np.linalg.norm(
            np.asarray(f.index_to_object, np.float64)[:3, :3], axis=0))), 0.0)
        _raise_cells(grid, lo, cell, dims, f, rate)
    if advect > 0:  # a lookup moved by the velocity reaches up to `advect` away: widen each cell's bound
        k = np.ceil(advect / cell).astype(np.int64)
        grid = _max_filter(grid, k[::-1])
    return lo, cell, grid.astype(np.float32)


def _scalar(f: VolumeField) -> np.ndarray:
    v = np.asarray(f.values, np.float64)
    return np.sqrt((v * v).sum(axis=1)) if v.ndim == 2 else v


def _raise_cells(grid, lo, cell, dims, f: VolumeField, value: np.ndarray) -> None:
    keep = value > 0
    if not keep.any():
        return
    c = voxel_centres(VolumeField(f.name, f.coords[keep], f.values[keep], f.index_to_object))
    value = value[keep]
    r = voxel_reach(f)
    a = np.clip(np.floor((c - r - lo) / cell).astype(np.int64), 0, dims - 1)
    b = np.clip(np.floor((c + r - lo) / cell).astype(np.int64), 0, dims - 1)
    # a cell is at least two reaches wide, so a voxel's reach spans at most two cells per axis
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                idx = np.minimum(a + (dx, dy, dz), b)
                np.maximum.at(grid, (idx[:, 2], idx[:, 1], idx[:, 0]), value)


def _max_filter(grid: np.ndarray, k) -> np.ndarray:
    out = grid
    for axis, r in enumerate(k):
        r = int(min(r, grid.shape[axis]))
        cur = out.copy()
        for d in range(1, r + 1):
            fwd = np.roll(out, d, axis=axis)
            bwd = np.roll(out, -d, axis=axis)
            sl = [slice(None)] * 3
            sl[axis] = slice(0, d)
            fwd[tuple(sl)] = 0
            sl[axis] = slice(grid.shape[axis] - d, None)
            bwd[tuple(sl)] = 0
            cur = np.maximum(cur, np.maximum(fwd, bwd))
        out = cur
    return out


# --- blackbody -------------------------------------------------------------------------------------------------

def _cie_xyz(lam_nm: np.ndarray) -> np.ndarray:
    """CIE 1931 2-degree colour matching functions, the multi-lobe fit of Wyman, Sloan and Shirley (2013)."""
    def g(x, mu, s1, s2):
        return np.exp(-0.5 * ((x - mu) / np.where(x < mu, s1, s2)) ** 2)
    x = 1.056 * g(lam_nm, 599.8, 37.9, 31.0) + 0.362 * g(lam_nm, 442.0, 16.0, 26.7) \
        - 0.065 * g(lam_nm, 501.1, 20.4, 26.2)
    y = 0.821 * g(lam_nm, 568.8, 46.9, 40.5) + 0.286 * g(lam_nm, 530.9, 16.3, 31.1)
    z = 1.217 * g(lam_nm, 437.0, 11.8, 36.0) + 0.681 * g(lam_nm, 459.0, 26.0, 13.8)
    return np.stack([x, y, z], axis=-1)


XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])


def blackbody_rgb(kelvin) -> np.ndarray:
    """Linear Rec.709 radiance of blackbodies (Planck's law through the CIE observer), relative: the luminance is 1
    at ``BLACKBODY_REFERENCE_K`` and follows Planck's law elsewhere (a 1500 K flame is about 1/200 of it)."""
    kelvin = np.atleast_1d(np.asarray(kelvin, np.float64))
    lam = np.arange(380.0, 781.0, 5.0)
    cmf = _cie_xyz(lam)

    def planck(t):
        lm = lam[None, :] * 1e-9
        with np.errstate(over="ignore", divide="ignore"):
            return 1.0 / (lm ** 5 * (np.exp(1.438777e-2 / (lm * np.maximum(t[:, None], 1e-3))) - 1.0))

    xyz = planck(kelvin) @ cmf
    ref = (planck(np.array([BLACKBODY_REFERENCE_K])) @ cmf)[0, 1]
    rgb = (xyz / ref) @ XYZ_TO_REC709.T
    return np.maximum(rgb, 0.0)


def blackbody_table() -> tuple[np.ndarray, float]:
    """(entries (n, 3) float32, kelvin per entry) for the kernels' ``blackbody`` lookup."""
    k = np.arange(0.0, BLACKBODY_MAX_K + BLACKBODY_STEP_K, BLACKBODY_STEP_K)
    rgb = np.zeros((len(k), 3))
    rgb[1:] = blackbody_rgb(k[1:])
    return rgb.astype(np.float32), BLACKBODY_STEP_K


def field_from_dense(name: str, values: np.ndarray, voxel_size=1.0, origin=(0.0, 0.0, 0.0),
                     keep_zeros: bool = False) -> VolumeField:
    """A sparse field of a dense array indexed [i, j, k] (x, y, z; (..., 3) for vectors): voxel (i, j, k) centred
    at origin + (i, j, k) * voxel_size. Zero voxels are left inactive unless ``keep_zeros``."""
    values = np.asarray(values, np.float32)
    vector = values.ndim == 4
    mask = np.ones(values.shape[:3], bool) if keep_zeros else (
        np.any(values != 0, axis=-1) if vector else values != 0)
    coords = np.argwhere(mask).astype(np.int32)
    vs = np.broadcast_to(np.asarray(voxel_size, np.float64), (3,))
    m = np.eye(4)
    m[:3, :3] = np.diag(vs)
    m[:3, 3] = origin
    return VolumeField(name, coords, values[mask], m)
