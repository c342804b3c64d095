"""Tile checkpoints: a finished tile's filtered sums on disk, written atomically, so a render killed at any moment
resumes from the tiles it finished, with the same bits as a render in one go (``render_tile`` is a pure function
of scene, options and tile, and ``assemble`` adds the same partials in the same order).

``save_tile`` / ``load_tile`` are the file format (the service keeps its jobs' tiles with them);
``FrameCheckpoints`` keeps one frame's tiles beside its output, for ``drt render --checkpoint``.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np

from renderer.core.files import atomic_write


def save_tile(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write a tile checkpoint atomically (``renderer.core.files``: a file that exists is complete).
    FileNotFoundError if its directory is gone."""
    with atomic_write(path) as f:
        np.savez(f, **arrays)


def load_tile(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


class FrameCheckpoints:
    """The finished tiles of one frame's render, in ``<output>.drt-tiles/`` beside its output:
    ``<index>.npz`` per tile and ``render.json``, the fingerprint of what they are tiles of (the request, the frame,
    the tiling and the scene file's size and time). Tiles of another fingerprint are discarded, not reused."""

    def __init__(self, output: str | os.PathLike, what: dict):
        self.root = Path(f"{os.fspath(output)}.drt-tiles")
        self.key = hashlib.sha256(json.dumps(what, sort_keys=True, default=repr).encode()).hexdigest()

    def load(self) -> dict[int, tuple[dict[str, np.ndarray], int, int]]:
        """The tiles saved by an earlier run of the same render: index -> (arrays, rays, non-finite samples)."""
        stamp = self.root / "render.json"
        if not stamp.is_file() or json.loads(stamp.read_text()).get("key") != self.key:
            self.remove()
            return {}
        out = {}
        for p in self.root.glob("*.npz"):
            if p.stem.isdigit():
                a = load_tile(p)
                rays, nonfinite = int(a.pop("_rays")), int(a.pop("_nonfinite"))
                out[int(p.stem)] = (a, rays, nonfinite)
        return out

    def save(self, index: int, arrays: dict[str, np.ndarray], rays: int, nonfinite: int) -> None:
        if not (self.root / "render.json").is_file():
            self.root.mkdir(parents=True, exist_ok=True)
            (self.root / "render.json").write_text(json.dumps({"key": self.key}))
        save_tile(self.root / f"{index}.npz", {**arrays, "_rays": np.int64(rays), "_nonfinite": np.int64(nonfinite)})

    def remove(self) -> None:
        shutil.rmtree(self.root, ignore_errors=True)
