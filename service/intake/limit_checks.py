"""A job's cost against the farm's limits (``DRT_MAX_*`` settings), checked before the job is queued.

Every refusal is a 422 whose detail names the limit and what the job would cost, so that a client can shrink the
job; the upload size (413) is enforced while the body streams in (``service.app.BodyLimit``, ``SceneStore.receive``).
"""
from __future__ import annotations

from ..errors import ApiError
from ..queue.store import Store
from ..settings import ServiceSettings


def check_frames(s: ServiceSettings, frames: int) -> None:
    if frames > s.max_frames:
        raise ApiError(422, f"too many frames: {frames} (the limit is {s.max_frames})")


def check_cost(s: ServiceSettings, *, width: int, height: int, spp: int, frames: int) -> None:
    """Pixels per frame, frames, then samples (width x height x spp x frames) of one job."""
    pixels = width * height
    if pixels > s.max_pixels_per_frame:
        raise ApiError(422, f"a frame of {width}x{height} has {pixels} pixels; the limit is "
                            f"{s.max_pixels_per_frame} pixels per frame")
    check_frames(s, frames)
    samples = pixels * spp * frames
    if samples > s.max_samples_per_job:
        raise ApiError(422, f"the job needs {samples} samples ({width}x{height} pixels x {spp} spp x {frames} "
                            f"frame{'s' if frames != 1 else ''}); the limit is {s.max_samples_per_job} samples "
                            f"per job")


def check_tiles(s: ServiceSettings, tiles: int) -> None:
    if tiles > s.max_tiles:
        raise ApiError(422, f"the job has {tiles} tiles; the limit is {s.max_tiles} (use a larger tile size or "
                            f"fewer frames)")


def check_queue(s: ServiceSettings, store: Store, client: str | None) -> None:
    """Jobs queued or running, in total and of this client (None: not counted per client)."""
    total = store.count_active()
    if total >= s.max_queued_jobs:
        raise ApiError(422, f"the queue is full: {total} jobs queued or running; the limit is "
                            f"{s.max_queued_jobs} jobs")
    if client is not None:
        mine = store.count_active(client)
        if mine >= s.max_queued_jobs_per_client:
            raise ApiError(422, f"this client has {mine} jobs queued or running; the limit is "
                                f"{s.max_queued_jobs_per_client} jobs per client")
