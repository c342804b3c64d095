"""The frame's shutter: one type owns every form a shutter time takes.

USD authors the shutter relative to the frame (the camera's ``shutter:open`` / ``shutter:close``, and our
``shutter`` setting); the importer samples motion at absolute time codes; the kernels see normalised shutter time
``s`` in [0, 1] over ``[open, close]``. ``Shutter`` holds the absolute interval and converts between the three, so
no other module does that arithmetic. ``open == close`` means no motion blur (a still frame).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Shutter:
    """The shutter interval of the frame ``frame``, in absolute time codes."""

    frame: float  # time code of the frame
    open: float  # absolute time code of s = 0
    close: float  # absolute time code of s = 1
    time_codes_per_second: float = 24.0

    @classmethod
    def around(cls, frame: float, offsets: tuple[float, float] | None = None,
               time_codes_per_second: float = 24.0) -> "Shutter":
        """The shutter ``frame + offsets`` (offsets relative to the frame, as USD authors them); None: still."""
        o, c = offsets if offsets is not None else (0.0, 0.0)
        return cls(float(frame), float(frame) + float(o), float(frame) + float(c), float(time_codes_per_second))

    @property
    def static(self) -> bool:
        return not self.close > self.open

    @property
    def offsets(self) -> tuple[float, float]:
        """(open, close) relative to the frame, as USD's ``shutter:open/close`` (and the EXR's ``drt/shutter``)."""
        return (float(self.open - self.frame), float(self.close - self.frame))

    @property
    def frame_s(self) -> float:
        """The frame's own instant in normalised shutter time, clamped to the shutter (what a strobe sees)."""
        if self.static:
            return 0.0
        return min(1.0, max(0.0, (self.frame - self.open) / (self.close - self.open)))

    def time_code(self, s: float) -> float:
        """Absolute time code of normalised shutter time s."""
        return self.open + s * (self.close - self.open)

    def normalise(self, times) -> np.ndarray:
        """Absolute time codes to normalised shutter time s in [0, 1] (float32)."""
        times = np.asarray(times, np.float64)
        if self.static:
            return np.zeros(times.shape, np.float32)
        return np.clip((times - self.open) / (self.close - self.open), 0.0, 1.0).astype(np.float32)

    def inner(self, samples) -> list[float]:
        """The samples strictly inside the shutter."""
        if self.static:
            return []
        return [float(t) for t in samples if self.open < t < self.close]

    def keys(self, samples=()) -> np.ndarray:
        """Key times: the shutter ends plus the given samples that fall strictly inside (or the frame if static)."""
        if self.static:
            return np.array([self.frame], np.float64)
        return np.unique(np.array([self.open, self.close, *self.inner(samples)], np.float64))

    def uniform(self, n: int) -> np.ndarray:
        """n evenly spaced key times over the shutter (curved motion such as accelerations)."""
        if self.static:
            return np.array([self.frame], np.float64)
        return np.linspace(self.open, self.close, max(int(n), 2))
