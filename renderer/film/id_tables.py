"""Per-pixel id tables (Cryptomatte's coverage), in numpy: merging per-direction tables, tile arrays and the
frame's band (``renderer.film.coverage`` fills the tables in its kernels; this module needs no Warp).

A pixel's tables are merged in direction order, weights summed per id in float64 and the entries sorted by weight
(then id), and the first ``KEEP`` kept: a pure function of the tables, so the frame's bits do not depend on the
tiling (``borders``).
"""
from __future__ import annotations

import numpy as np

KEEP = 16  # entries a pixel keeps after merging (Cryptomatte writes at most 16 ranks)
PREFIX = "cov."  # tile array names: cov.<kind>.ids / cov.<kind>.weights


def merge(ids: np.ndarray, weights: np.ndarray, keep: int = KEEP) -> tuple[np.ndarray, np.ndarray]:
    """Tables (P, N) of ids and weights (entries in direction order; -1 empty) merged per pixel: (P, keep) with each
    id once, its weights summed in float64, sorted by weight descending then id ascending; -1 / 0 padding."""
    P, N = ids.shape
    out_ids = np.full((P, keep), -1, np.int32)
    out_w = np.zeros((P, keep), np.float32)
    if P == 0 or N == 0:
        return out_ids, out_w
    rows = np.repeat(np.arange(P), N)
    flat_ids = ids.reshape(-1).astype(np.int64)
    flat_w = weights.reshape(-1).astype(np.float64)
    used = flat_ids >= 0
    rows, flat_ids, flat_w = rows[used], flat_ids[used], flat_w[used]
    if rows.size == 0:
        return out_ids, out_w
    order = np.lexsort((flat_ids, rows))  # stable: equal ids keep their direction order
    rows, flat_ids, flat_w = rows[order], flat_ids[order], flat_w[order]
    starts = np.flatnonzero(np.r_[True, (rows[1:] != rows[:-1]) | (flat_ids[1:] != flat_ids[:-1])])
    sums = np.add.reduceat(flat_w, starts)
    r, i = rows[starts], flat_ids[starts]
    w32 = sums.astype(np.float32)
    order = np.lexsort((i, -w32.astype(np.float64), r))
    r, i, w32 = r[order], i[order], w32[order]
    first = np.flatnonzero(np.r_[True, r[1:] != r[:-1]])
    rank = np.arange(r.size) - np.repeat(first, np.diff(np.r_[first, r.size]))
    ok = rank < keep
    out_ids[r[ok], rank[ok]] = i[ok]
    out_w[r[ok], rank[ok]] = w32[ok]
    return out_ids, out_w


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
