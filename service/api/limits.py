"""``/v1/limits``: what one job may cost on this farm (a submission over any limit is refused before queuing)."""
from __future__ import annotations

from fastapi import APIRouter

from schemas import Limits

from .deps import Authorized, SettingsDep
from .docs import UNAUTHORIZED_ANSWER

router = APIRouter(tags=["limits"], dependencies=[Authorized], responses=UNAUTHORIZED_ANSWER)


@router.get("/limits", response_model=Limits)
def get_limits(settings: SettingsDep):
    """The farm's limits (``DRT_MAX_*``): upload bytes, samples per job, pixels per frame, frames and tiles per
    job, jobs queued in total and per client."""
    s = settings
    return Limits(max_upload_bytes=s.max_upload_bytes, max_samples_per_job=s.max_samples_per_job,
                  max_pixels_per_frame=s.max_pixels_per_frame, max_frames=s.max_frames, max_tiles=s.max_tiles,
                  max_queued_jobs=s.max_queued_jobs, max_queued_jobs_per_client=s.max_queued_jobs_per_client)
