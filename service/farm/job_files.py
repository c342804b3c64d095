"""A job's files under the data directory: tile checkpoints, frame EXRs; the tile grid of a frame.

    <data>/jobs/<job id>/tiles/<frame index>/<tile index>.npz   filtered sums of one finished tile
    <data>/jobs/<job id>/frames/<frame index>.exr               the frame, written atomically

Only the service reads and writes them (workers return tiles as task results and never see this directory).

A checkpoint is written to a temporary file in its directory and renamed over its name, so a file that exists is
complete: a service killed at any moment resumes from the tiles on disk, and assembling them gives the same bits
as rendering the frame in one go (``render_tile`` is a pure function of scene, options and tile).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

TileBox = tuple[int, int, int, int]  # x0, y0, x1, y1: pixels [x0, x1) x [y0, y1), y down


def tile_grid(width: int, height: int, size: int) -> list[TileBox]:
    """Tiles in row-major order (the order of ``renderer.render.split_tiles``)."""
    return [(x, y, min(x + size, width), min(y + size, height))
            for y in range(0, height, size) for x in range(0, width, size)]


def tile_count(width: int, height: int, size: int) -> int:
    return -(-width // size) * -(-height // size)


class JobFiles:
    def __init__(self, data_dir: Path, job_id: str):
        self.root = Path(data_dir) / "jobs" / job_id

    def create(self, frames: int) -> None:
        (self.root / "frames").mkdir(parents=True, exist_ok=True)
        for i in range(frames):
            (self.root / "tiles" / str(i)).mkdir(parents=True, exist_ok=True)

    def tile(self, frame_idx: int, tile_idx: int) -> Path:
        return self.root / "tiles" / str(frame_idx) / f"{tile_idx}.npz"

    def frame(self, frame_idx: int) -> Path:
        return self.root / "frames" / f"{frame_idx}.exr"

    def remove_tiles(self, frame_idx: int) -> None:
        shutil.rmtree(self.root / "tiles" / str(frame_idx), ignore_errors=True)

    def remove(self) -> None:
        shutil.rmtree(self.root, ignore_errors=True)


def save_tile(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write a tile checkpoint atomically. FileNotFoundError if the job's directory is gone (job deleted)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".npz.tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def load_tile(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}
