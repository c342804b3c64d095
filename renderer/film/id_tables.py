"""Per-pixel id tables (Cryptomatte's coverage): merging per-direction tables, tile arrays and the
frame's band (``renderer.film.coverage`` fills the tables in its kernels, and merges them).

A pixel's tables are merged in direction order, weights summed per id in float64 and the entries sorted by weight
(then id), and the first ``KEEP`` kept: a pure function of the tables, so the frame's bits do not depend on the
tiling (``borders``).
"""
from __future__ import annotations

import numpy as np
import warp as wp

KEEP = 16  # entries a pixel keeps after merging (Cryptomatte writes at most 16 ranks)
PREFIX = "cov."  # tile array names: cov.<kind>.ids / cov.<kind>.weights


def merge(ids: np.ndarray, weights: np.ndarray, keep: int = KEEP) -> tuple[np.ndarray, np.ndarray]:
    """Tables (P, N) of ids and weights (entries in direction order; -1 empty) merged per pixel: (P, keep) with each
    id once, its weights summed in float64 in entry order, sorted by weight descending then id ascending; -1 / 0
    padding. A Warp kernel, one pixel per thread (``coverage.merge_kernel``): in numpy, sorts of the whole frame
    took 0.45 s of a 640x360 frame's asset layer and 1.2 s of its tiles' tables."""
    P, N = ids.shape
    if P == 0 or N == 0:
        return np.full((P, keep), -1, np.int32), np.zeros((P, keep), np.float32)
    from renderer.kernels import cache as kernel_cache
    from renderer.kernels.device import init_warp
    from renderer.film import coverage
    init_warp()
    kernel_cache.load_modules((coverage,))  # the shipped build when no other is cached (a no-op once loaded)
    ids_out = wp.full((P, keep), -1, dtype=wp.int32, device="cpu")
    w_out = wp.zeros((P, keep), dtype=wp.float32, device="cpu")
    wp.launch(coverage.merge_kernel, dim=P, device="cpu",
              inputs=[wp.array(np.ascontiguousarray(ids, np.int32), dtype=wp.int32, device="cpu"),
                      wp.array(np.ascontiguousarray(weights, np.float32), dtype=wp.float32, device="cpu"), keep,
                      wp.empty((P, N), dtype=wp.int32, device="cpu"), wp.empty((P, N), dtype=wp.float64, device="cpu"),
                      ids_out, w_out])
    return ids_out.numpy(), w_out.numpy()


def merge_directions(ids: np.ndarray, weights: np.ndarray, keep: int = KEEP) -> tuple[np.ndarray, np.ndarray]:
    """Per-direction tables (D, ..., SLOTS) of the same pixels merged: (..., keep)."""
    D = ids.shape[0]
    shape = ids.shape[1:-1]
    flat_i = np.moveaxis(ids, 0, -2).reshape(-1, D * ids.shape[-1])
    flat_w = np.moveaxis(weights, 0, -2).reshape(-1, D * ids.shape[-1])
    mi, mw = merge(flat_i, flat_w, keep)
    return mi.reshape(shape + (keep,)), mw.reshape(shape + (keep,))


def remap(ids: np.ndarray, weights: np.ndarray, to: np.ndarray, keep: int = KEEP) -> tuple[np.ndarray, np.ndarray]:
    """Tables (..., N) with every id replaced by ``to[id]`` (objects to their assets) and merged again."""
    shape = ids.shape[:-1]
    mapped = np.where(ids >= 0, to[np.maximum(ids, 0)], -1).astype(np.int32)
    mi, mw = merge(mapped.reshape(-1, ids.shape[-1]), weights.reshape(-1, ids.shape[-1]), keep)
    return mi.reshape(shape + (keep,)), mw.reshape(shape + (keep,))


def names(name: str) -> tuple[str, str]:
    """The tile array names of a kind's id and weight tables."""
    return f"{PREFIX}{name}.ids", f"{PREFIX}{name}.weights"


def is_table(name: str) -> bool:
    return name.startswith(PREFIX)


def assemble_band(band_ids: list[np.ndarray], band_weights: list[np.ndarray], where: list[np.ndarray],
                  n_pixels: int) -> tuple[np.ndarray, np.ndarray]:
    """The merged tables of the band pixels from every tile's (D, band pixels, SLOTS) partial tables: per pixel, its
    directions in order, each from the one tile that owns that direction's samples (the others hold empty tables
    there, which are skipped)."""
    D, _, S = band_ids[0].shape
    ids = np.full((n_pixels, D, S), -1, np.int32)
    w = np.zeros((n_pixels, D, S), np.float32)
    for bi, bw, at in zip(band_ids, band_weights, where):
        bi, bw = np.moveaxis(bi, 0, 1), np.moveaxis(bw, 0, 1)  # (band pixels, D, S)
        owned = bi[..., 0] >= 0  # a table's first slot fills first
        rows, dirs = np.nonzero(owned)
        ids[at[rows], dirs] = bi[rows, dirs]
        w[at[rows], dirs] = bw[rows, dirs]
    return merge(ids.reshape(n_pixels, -1), w.reshape(n_pixels, -1))


def tile_tables(name: str, ids: np.ndarray, weights: np.ndarray, own: tuple[int, int, int, int],
                region: tuple[int, int], band: np.ndarray | None) -> tuple[dict, dict]:
    """A tile's arrays of one kind from its per-direction tables (D, rows, columns, SLOTS) over the region whose
    top-left pixel is ``region``: its own pixels' merged tables, and the band's per-direction tables when ``band``
    (the band mask of the region) is given (``borders`` files them under its band prefix)."""
    x0, y0, x1, y1 = own
    ex0, ey0 = region
    ni, nw = names(name)
    rows, columns = slice(y0 - ey0, y1 - ey0), slice(x0 - ex0, x1 - ex0)
    mi, mw = merge_directions(ids[:, rows, columns], weights[:, rows, columns])
    banded = {}
    if band is not None:
        banded = {ni: np.ascontiguousarray(ids[:, band]), nw: np.ascontiguousarray(weights[:, band])}
    return {ni: mi, nw: mw}, banded
