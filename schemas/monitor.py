"""What the job monitor reads besides jobs: a job's tile map and the farm (Dask workers and their tasks)."""
from __future__ import annotations

from pydantic import BaseModel, Field


class FrameTiles(BaseModel):
    frame: float = Field(description="time code")
    done: list[int] = Field(description="indices of the checkpointed tiles (all of them once the frame is done)")
    rendering: list[int] = Field(description="indices of the tiles a worker holds right now")


class TileMap(BaseModel):
    """Tiles are numbered row-major from the top left: tile ``i`` is column ``i % columns``, row ``i // columns``."""

    width: int
    height: int
    tile_size: int
    columns: int
    rows: int
    frames: list[FrameTiles]


class FarmTask(BaseModel):
    kind: str = Field(description="`tile` (rendering a tile) or `frame` (assembling a frame's EXR)")
    job_id: str
    frame_index: int = Field(description="position of the frame in the job's `frames`")
    frame: float | None = Field(None, description="the frame's time code (null if the job is gone)")
    tile: int | None = Field(description="tile index (null for a frame's assembly); a batch's first tile")
    tiles: list[int] = Field(default_factory=list, description="every tile the task renders, one after the other "
                                                                "(small tiles go in batches); empty for an assembly")


class FarmWorker(BaseModel):
    address: str
    name: str
    host: str
    nthreads: int
    memory_limit: int | None = Field(description="bytes")
    memory: int | None = Field(description="bytes in use")
    cpu: float | None = Field(description="percent of one core")
    tasks: list[FarmTask] = Field(description="drt tasks the worker holds (running or next in its queue)")
    other_tasks: int = Field(description="tasks that are not drt tiles or frames (scene inspection, ...)")


class Farm(BaseModel):
    scheduler: str | None = Field(description="the Dask scheduler's address")
    dashboard_url: str | None = Field(description="the Dask dashboard, when one runs and is reachable")
    workers: list[FarmWorker]
    tiles_in_flight: int = Field(description="tasks submitted to the cluster and not finished")
    tiles_pending: int = Field(description="tiles of active jobs not yet submitted")
    tiles_per_second: float = Field(description="over the last minute")
