"""A sparse linear map from parent values to child values (one subdivision level, or the limit projection).

Built once per mesh topology from (row, column, weight) triples, applied to any number of value arrays (every
motion key of the points, face-varying texture coordinates): child[r] = sum_k w_k * parent[col_k].
"""
from __future__ import annotations

import numpy as np


class Stencil:
    """Kept as plain triples (duplicates allowed): applying is a weighted histogram per channel, O(nnz), with
    no sorting at build time."""

    def __init__(self, rows: np.ndarray, cols: np.ndarray, weights: np.ndarray, num_rows: int, num_cols: int):
        rows = np.asarray(rows, np.int64)
        weights = np.asarray(weights, np.float64)
        keep = weights != 0.0
        self.rows = rows[keep]
        self.cols = np.asarray(cols, np.int64)[keep]
        self.weights = weights[keep]
        self.num_rows = int(num_rows)
        self.num_cols = int(num_cols)
        if np.count_nonzero(np.bincount(self.rows, minlength=self.num_rows)) != self.num_rows:
            raise ValueError("subdivision stencil leaves child values undefined")

    @property
    def nnz(self) -> int:
        return len(self.weights)

    def apply(self, values: np.ndarray) -> np.ndarray:
        """(num_cols, ...) -> (num_rows, ...) in float64."""
        v = np.asarray(values, np.float64)
        if len(v) != self.num_cols:
            raise ValueError(f"stencil expects {self.num_cols} values, got {len(v)}")
        flat = v.reshape(len(v), -1)
        out = np.empty((self.num_rows, flat.shape[1]))
        for k in range(flat.shape[1]):
            out[:, k] = np.bincount(self.rows, self.weights * flat[self.cols, k], minlength=self.num_rows)
        return out.reshape((self.num_rows,) + v.shape[1:])

    def row_sums(self) -> np.ndarray:
        return np.bincount(self.rows, self.weights, minlength=self.num_rows)
