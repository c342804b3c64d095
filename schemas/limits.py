"""The farm's limits on one job and on the queue, as ``GET /v1/limits`` returns them."""
from __future__ import annotations

from pydantic import BaseModel, Field


class Limits(BaseModel):
    """A submission over any of these is refused before it is queued: 413 for the upload, 422 for the rest, with a
    detail naming the limit and the job's cost."""

    max_upload_bytes: int = Field(description="largest scene upload, bytes (413 above)")
    max_samples_per_job: int = Field(description="width x height x spp x frames of one job")
    max_pixels_per_frame: int = Field(description="width x height of one frame")
    max_frames: int = Field(description="frames of one job")
    max_tiles: int = Field(description="tiles of one job (frames x tiles per frame)")
    max_queued_jobs: int = Field(description="jobs queued or running, all clients together")
    max_queued_jobs_per_client: int = Field(
        description="jobs queued or running of one client (its bearer token, else its address)")
