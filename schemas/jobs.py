"""What clients read back: the public job view, job lists, errors, health."""
from __future__ import annotations

from datetime import datetime
from enum import Enum

from pydantic import BaseModel, Field

from .settings import JobCreate


class JobState(str, Enum):
    """``queued -> running -> succeeded | failed | canceled`` (queued jobs may also be canceled or fail)."""

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    canceled = "canceled"


class FrameState(str, Enum):
    pending = "pending"  # no tile finished yet
    rendering = "rendering"  # some tiles finished
    done = "done"  # the EXR is written


class FramePublic(BaseModel):
    frame: float = Field(description="time code")
    state: FrameState
    progress: float = Field(ge=0, le=1)
    exr_url: str | None = Field(description="the EXR, once the frame is done")
    preview_url: str = Field(description="a tone-mapped PNG of the tiles finished so far")


class SceneInfo(BaseModel):
    filename: str
    sha256: str
    bytes: int


class JobPublic(BaseModel):
    id: str
    url: str
    state: JobState
    priority: int
    progress: float = Field(ge=0, le=1, description="finished tiles / all tiles")
    width: int
    height: int
    tiles_done: int
    tiles_total: int
    samples_per_second: float | None = Field(description="samples rendered per second of wall time while running")
    frames: list[FramePublic]
    error: str | None = None
    warnings: list[str] = Field(default_factory=list, description="the renderer's warnings about the scene")
    scene: SceneInfo
    settings: JobCreate
    created_at: datetime
    updated_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None


class JobList(BaseModel):
    items: list[JobPublic]
    next_cursor: str | None = Field(description="pass as ?cursor= for the next page; null on the last page")


class ErrorBody(BaseModel):
    detail: str


class Health(BaseModel):
    status: str = Field(description='"ok", or "degraded" while the render cluster is unreachable')
    cluster: str = Field("reachable", description='"reachable" or "unreachable" (the Dask scheduler)')
    workers: int = Field(description="Dask workers connected now")
    threads: int = Field(description="their threads")
