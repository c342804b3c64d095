"""A job's files under the data directory: tile checkpoints and frame EXRs.

    <data>/jobs/<job id>/tiles/<frame index>/<tile index>.npz   filtered sums of one finished tile
    <data>/jobs/<job id>/frames/<frame index>.exr               the frame, written atomically

Only the service reads and writes them (workers return tiles as task results and never see this directory). A
tile's index is its place in the frame's grid (``renderer.film.tiles.split_tiles``).

A checkpoint is written to a temporary file in its directory and renamed over its name (``renderer.checkpoint``), so a
file that exists is complete: a service killed at any moment resumes from the tiles on disk, and assembling them
gives the same bits as rendering the frame in one go (``render_tile`` is a pure function of scene, options and
tile).
"""
from __future__ import annotations

import shutil
from pathlib import Path

from renderer.checkpoint import load_tile, save_tile  # noqa: F401 - the tile files' format is the renderer's


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

