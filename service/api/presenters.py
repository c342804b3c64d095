"""Database rows -> the public job view (``schemas.JobPublic``), and frame names in URLs.

URLs are relative to the server (``/v1/jobs/<id>/...``) so they stay right behind a proxy. A frame's name in a URL
is its time code: ``12`` for 12.0, ``12.5`` for 12.5; a product's, its name (a relative path, slashes kept, each
part percent-encoded).
"""
from __future__ import annotations

import functools
import time
from datetime import datetime, timezone
from urllib.parse import quote

from schemas import FramePublic, FrameState, JobCreate, JobPublic, JobState, ProductPublic, SceneInfo

from ..queue.store import FrameRow, JobRow


def frame_name(t: float) -> str:
    t = float(t)
    return str(int(t)) if t.is_integer() else repr(t)


def find_frame(row: JobRow, name: str) -> FrameRow | None:
    try:
        t = float(name)
    except ValueError:
        return None
    return next((f for f in row.frames if f.time == t), None)


def job_url(job_id: str) -> str:
    return f"/v1/jobs/{job_id}"


def _dt(t: float | None) -> datetime | None:
    return None if t is None else datetime.fromtimestamp(t, tz=timezone.utc)


@functools.lru_cache(maxsize=4096)
def _settings(settings_json: str) -> JobCreate:
    """A job's settings never change: parse each once (status requests are the API's hot path)."""
    return JobCreate.model_validate_json(settings_json)


def job_public(row: JobRow) -> JobPublic:
    base = job_url(row.id)
    frames = []
    for f in row.frames:
        name = frame_name(f.time)
        if f.done:
            state, progress = FrameState.done, 1.0
        else:
            state = FrameState.rendering if f.tiles_done else FrameState.pending
            progress = f.tiles_done / (row.tiles_per_frame + 1)  # +1: writing the EXR is the last step
        products = [ProductPublic(name=p["name"], prim=p["prim"],
                                  url=f"{base}/frames/{name}/products/{quote(p['name'])}")
                    for p in (f.products or ()) if f.done]
        frames.append(FramePublic(frame=f.time, state=state, progress=progress,
                                  exr_url=f"{base}/frames/{name}.exr" if f.done else None, products=products,
                                  preview_url=f"{base}/frames/{name}/preview.png"))
    steps = row.tiles_total + len(row.frames)
    progress = (row.tiles_done + sum(f.done for f in row.frames)) / steps if steps else 0.0
    sps = None
    if row.started_at is not None and row.samples_done:
        end = row.finished_at if row.finished_at is not None else time.time()
        if end > row.started_at:
            sps = row.samples_done / (end - row.started_at)
    return JobPublic(
        id=row.id, url=base, state=JobState(row.state), priority=row.priority, progress=min(1.0, progress),
        width=row.width, height=row.height, tiles_done=row.tiles_done, tiles_total=row.tiles_total,
        samples_per_second=sps, frames=frames, error=row.error, warnings=row.warnings,
        scene=SceneInfo(filename=row.scene_name, sha256=row.scene_sha256, bytes=row.scene_bytes),
        settings=_settings(row.settings_json), created_at=_dt(row.created_at),
        updated_at=_dt(row.updated_at), started_at=_dt(row.started_at), finished_at=_dt(row.finished_at))
