"""What clients read back: the public job view, job lists, errors, health; the rule for a product's name."""
from __future__ import annotations

import re
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


_DRIVE = re.compile(r"^[A-Za-z]:")


def product_name(text: str) -> str | None:
    """A product's name inside a job's folder and under a client's output folder: a RenderProduct's
    ``productName`` at the frame as a relative POSIX path (``renders/beauty.0001.exr``); an absolute one, or one
    climbing out with ``..``, by its last part alone (``beauty.0001.exr``); None when nothing usable is left.
    ``name == product_name(name)`` holds exactly for the names a job can have."""
    if not text or "\0" in text:
        return None
    absolute = text.startswith(("/", "\\")) or bool(_DRIVE.match(text))
    parts = [p for p in _DRIVE.sub("", text).replace("\\", "/").split("/") if p not in ("", ".")]
    if parts and (absolute or ".." in parts):
        parts = parts[-1:]
    if not parts or parts[-1] == "..":
        return None
    return "/".join(parts)


class ProductPublic(BaseModel):
    name: str = Field(description="the RenderProduct's productName at this frame, as a relative path (an absolute "
                                  "productName by its file name): where `drt fetch` writes it")
    prim: str | None = Field(description="the RenderProduct prim; null for a stage without RenderProducts, whose "
                                         "one image is named after the scene file (`shot.0012.exr`)")
    url: str = Field(description="the product's EXR")


class FramePublic(BaseModel):
    frame: float = Field(description="time code")
    state: FrameState
    progress: float = Field(ge=0, le=1)
    exr_url: str | None = Field(description="the EXR, once the frame is done: its first product's")
    products: list[ProductPublic] = Field(
        default_factory=list, description="every EXR the frame wrote, once it is done: each RenderProduct of the "
        "render settings (`settings_prim`) with its RenderVars as layers, in the settings' order")
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
