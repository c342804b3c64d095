"""A job's files under the data directory: tile checkpoints and the frames' products.

    <data>/jobs/<job id>/tiles/<frame index>/<tile index>.npz   filtered sums of one finished tile
    <data>/jobs/<job id>/frames/<frame index>/<product name>    a product of the frame (its EXR), written atomically
    <data>/jobs/<job id>/frames/<frame index>.exr               the frame, as services before products wrote it

A product's name is a relative path (``schemas.product_name``: ``renders/beauty.0001.exr``); ``product`` refuses
any that would leave the frame's folder, whoever asks.

Only the service reads and writes them (workers return tiles as task results and never see this directory). A
tile's index is its place in the frame's grid (``renderer.film.tiles.split_tiles``).

A checkpoint is written to a temporary file in its directory and renamed over its name (``renderer.output.checkpoint``), so a
file that exists is complete: a service killed at any moment resumes from the tiles on disk, and assembling them
gives the same bits as rendering the frame in one go (``render_tile`` is a pure function of scene, options and
tile).
"""
from __future__ import annotations

import shutil
from pathlib import Path

from renderer.output.checkpoint import load_tile, save_tile  # noqa: F401 - the tile files' format is the renderer's
from schemas import product_name


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

    def product(self, frame_idx: int, name: str, create: bool = False) -> Path:
        """A product's file; ``create``: make its folders (FileNotFoundError once the job's files are gone).
        ValueError for a name that is not a product's (``schemas.product_name``) or leaves the frame's folder."""
        base = self.root / "frames" / str(frame_idx)
        path = base / name
        if product_name(name) != name or not path.resolve().is_relative_to(base.resolve()):
            raise ValueError(f"not a product name: {name!r}")
        if create:
            if not (self.root / "frames").is_dir():
                raise FileNotFoundError(self.root / "frames")
            path.parent.mkdir(parents=True, exist_ok=True)
        return path

    def main_image(self, frame) -> Path:
        """The EXR of a frame row (``queue.store.FrameRow``) that ``exr_url`` and the preview serve: its first
        product, or the one image of a frame written before products."""
        products = frame.products
        return self.product(frame.idx, products[0]["name"]) if products else self.frame(frame.idx)

    def remove_tiles(self, frame_idx: int) -> None:
        shutil.rmtree(self.root / "tiles" / str(frame_idx), ignore_errors=True)

    def remove(self) -> None:
        shutil.rmtree(self.root, ignore_errors=True)

