"""Adaptive sampling: a per-pixel error estimate from two half buffers, and when a pixel stops sampling.

Every *sample pixel* (a pixel whose area the samples are drawn in) keeps the sums of its own even- and
odd-indexed samples, unfiltered. After a wave, once it has at least ``min_spp`` samples, its error is Cycles'
estimate (after Dammertz et al. 2010, "A hierarchical automatic stopping condition for Monte Carlo global
illumination"): with A and B the means of the two halves and I = (A + B) / 2,

    error = sum_rgb |A - B| / 2  /  (1e-4 + sqrt(sum_rgb I))

and the pixel stops for good when error < ``noise_threshold``. The decision depends only on the pixel's own
samples (pure functions of seed, pixel and index) and on the wave schedule, never on the tile: a sample pixel in
the filter margin of two tiles stops after the same wave in both, so the filtered sums stay bit-identical
across tilings. The sums are float64 and added one sample index at a time, elementwise (no reductions whose
order could depend on array shapes).
"""
from __future__ import annotations

import numpy as np

ERROR_EPSILON = 1.0e-4  # keeps black pixels from dividing by zero (Cycles' value)


def pixel_error(even: np.ndarray, odd: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The error estimate of pixels with ``count`` samples (even count: both halves hold count/2)."""
    half = np.maximum(count, 2)[:, None] / 2.0
    a, b = even / half, odd / half
    diff = np.abs(a - b).sum(-1) / 2.0
    level = np.maximum((a + b).sum(-1) / 2.0, 0.0)
    return diff / (ERROR_EPSILON + np.sqrt(level))


class Convergence:
    """The adaptive state of a region's sample pixels (flat index = row * width + column)."""

    def __init__(self, n_pixels: int, threshold: float, min_spp: int):
        self.threshold = float(threshold)
        self.min_spp = int(min_spp)
        self.count = np.zeros(n_pixels, np.int32)
        self.even = np.zeros((n_pixels, 3), np.float64)
        self.odd = np.zeros((n_pixels, 3), np.float64)
        self.active = np.ones(n_pixels, bool)

    @property
    def enabled(self) -> bool:
        return self.threshold > 0.0

    def active_pixels(self) -> np.ndarray:
        """Region pixels that still sample, in increasing order (the wave's slots)."""
        return np.flatnonzero(self.active).astype(np.int32)

    def add_wave(self, pixels: np.ndarray, rgb: np.ndarray | None, start: int, wave: int) -> None:
        """Record a wave of ``wave`` samples (start, start + 1, ...) of ``pixels``: their radiance ``rgb``
        (len(pixels), wave, 3) when adaptive sampling is on (else None: only the counts are kept)."""
        self.count[pixels] += wave
        if not self.enabled:
            return
        even, odd = self.even[pixels], self.odd[pixels]
        for j in range(wave):
            (even if (start + j) % 2 == 0 else odd)[:] += rgb[:, j, :]
        self.even[pixels], self.odd[pixels] = even, odd

    def update(self) -> None:
        """Stop the pixels that have converged (checked only when both halves hold the same count)."""
        if not self.enabled:
            return
        check = self.active & (self.count >= self.min_spp) & (self.count % 2 == 0)
        idx = np.flatnonzero(check)
        if idx.size:
            err = pixel_error(self.even[idx], self.odd[idx], self.count[idx])
            self.active[idx[err < self.threshold]] = False

    @property
    def done(self) -> bool:
        return not self.active.any()
