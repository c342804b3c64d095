"""A sparse linear map from parent values to child values (one subdivision level, or the limit projection).

Built once per mesh topology from (row, column, weight) triples, applied to any number of value arrays (every
motion key of the points, face-varying texture coordinates): child[r] = sum_k w_k * parent[col_k].
"""
from __future__ import annotations

import numpy as np


class Stencil:
    def __init__(self, rows: np.ndarray, cols: np.ndarray, weights: np.ndarray, num_rows: int, num_cols: int):
        rows = np.asarray(rows, np.int64)
        cols = np.asarray(cols, np.int64)
        weights = np.asarray(weights, np.float64)
        keep = weights != 0.0
        rows, cols, weights = rows[keep], cols[keep], weights[keep]
        # merge duplicate (row, col) pairs and sort by row: compact, and rows become contiguous runs
        key = rows * max(num_cols, 1) + cols
        uniq, inv = np.unique(key, return_inverse=True)
        self.weights = np.bincount(inv.reshape(-1), weights, minlength=len(uniq))
        self.rows = uniq // max(num_cols, 1)
        self.cols = uniq % max(num_cols, 1)
        self.num_rows = int(num_rows)
        self.num_cols = int(num_cols)
        if len(self.rows) and (np.unique(self.rows).size != self.num_rows):
            raise ValueError("subdivision stencil leaves child values undefined")
        self._starts = np.flatnonzero(np.r_[True, self.rows[1:] != self.rows[:-1]]) if len(self.rows) else \
            np.zeros(0, np.int64)

    @property
    def nnz(self) -> int:
        return len(self.weights)

    def apply(self, values: np.ndarray) -> np.ndarray:
        """(num_cols, ...) -> (num_rows, ...) in float64."""
        v = np.asarray(values, np.float64)
        if len(v) != self.num_cols:
            raise ValueError(f"stencil expects {self.num_cols} values, got {len(v)}")
        if self.num_rows == 0:
            return np.zeros((0,) + v.shape[1:])
        terms = v[self.cols] * self.weights.reshape((-1,) + (1,) * (v.ndim - 1))
        return np.add.reduceat(terms, self._starts, axis=0)

    def row_sums(self) -> np.ndarray:
        return np.bincount(self.rows, self.weights, minlength=self.num_rows)
