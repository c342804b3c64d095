"""``/v1/jobs``: submit, read, list, cancel, retry, delete; frames' products (EXRs) and previews.

Status codes: 202 + ``Location`` on create (also when an Idempotency-Key replays it), 400 malformed multipart, 401
no or a wrong token, 404 unknown job or frame, 409 illegal state change or frame not ready, 413 upload too large,
422 invalid input or a job over the limits, 503 cluster unavailable; each operation documents the ones it can
answer. Detail strings are in ``service.errors`` and ``service.intake.limit_checks``. DELETE cancels an active job
first.
"""
from __future__ import annotations

import functools
from typing import Annotated

import anyio
from fastapi import APIRouter, File, Form, Header, Query, Request, Response, UploadFile
from fastapi.responses import FileResponse, JSONResponse

from renderer.film.tiles import split_tiles
from schemas import JobList, JobPublic, JobState, product_name

from .. import errors
from ..errors import ApiError
from ..farm.job_files import JobFiles
from ..queue import states as sm
from ..queue.store import JobActive, JobNotFound, JobRow, StoreBusy, decode_cursor, encode_cursor
from . import preview
from .deps import Authorized, ClientIdDep, InspectorDep, RuntimeDep, SettingsDep, StoreDep, SubmitterDep
from .docs import UNAUTHORIZED_ANSWER, errors as answers
from .presenters import find_frame, job_public, job_url

router = APIRouter(prefix="/jobs", tags=["jobs"], dependencies=[Authorized], responses=UNAUTHORIZED_ANSWER)


def _job(store, job_id: str) -> JobRow:
    try:
        return store.get_job(job_id)
    except JobNotFound:
        raise ApiError(404, errors.JOB_NOT_FOUND) from None


@router.post("", status_code=202, response_model=JobPublic, responses=answers(400, 409, 413, 422, 503))
async def create_job(
    request: Request,
    submitter: SubmitterDep,
    inspector: InspectorDep,
    client_id: ClientIdDep,
    scene: Annotated[UploadFile, File(description="a .usda, .usdc, .usd or .usdz file")],
    settings: Annotated[str, Form(description="JSON: schemas.JobCreate")] = "{}",
    idempotency_key: Annotated[str | None, Header(alias="Idempotency-Key", min_length=1, max_length=255)] = None,
):
    """Queue a render of an uploaded USD scene. Retrying with the same ``Idempotency-Key`` returns the same job.

    A job over the farm's limits (``GET /v1/limits``: samples, pixels, frames, tiles, jobs queued) is refused with
    422 naming the limit and the job's cost; an upload over ``max_upload_bytes`` with 413."""
    row, _created = await anyio.to_thread.run_sync(
        functools.partial(submitter.submit, scene.file, scene.filename, settings, idempotency_key, inspector,
                          client_id),
        limiter=request.app.state.submit_limiter)
    body = job_public(row).model_dump(mode="json")
    return JSONResponse(body, status_code=202, headers={"Location": job_url(row.id)})


@router.get("", response_model=JobList, responses=answers(422))
def list_jobs(
    store: StoreDep,
    state: JobState | None = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    cursor: Annotated[str | None, Query(max_length=64, description="next_cursor of the previous page")] = None,
):
    """Jobs, newest first, optionally of one state; follow ``next_cursor`` for more."""
    before = None
    if cursor:
        try:
            before = decode_cursor(cursor)
        except ValueError:
            raise ApiError(422, errors.BAD_CURSOR) from None
    rows, next_seq = store.list_jobs(state, limit, before)
    return JobList(items=[job_public(r) for r in rows],
                   next_cursor=encode_cursor(next_seq) if next_seq is not None else None)


@router.get("/{job_id}", response_model=JobPublic, responses=answers(404, 422))
async def get_job(store: StoreDep, job_id: str):
    # The API's hot path, answered on the event loop: two indexed reads of a WAL database (~0.2 ms; readers never
    # wait for writers) cost less than the hop to the thread pool and back, which under load meant waiting twice for
    # the GIL. The loop must never wait for a lock, so the read does not wait: in the rare moment the database
    # refuses a reader (another process holding it exclusively), it is done on the thread pool, where it may wait.
    try:
        row = store.get_job(job_id, wait=False)
    except StoreBusy:
        row = await anyio.to_thread.run_sync(_job, store, job_id)
    except JobNotFound:
        raise ApiError(404, errors.JOB_NOT_FOUND) from None
    # The body is serialized once here, not validated again against the response model.
    return Response(job_public(row).model_dump_json(), media_type="application/json")


@router.post("/{job_id}/cancel", response_model=JobPublic, responses=answers(404, 409, 422))
def cancel_job(runtime: RuntimeDep, job_id: str):
    """Cancel a queued or running job: no new tiles start, queued ones are dropped, running ones stop."""
    try:
        row = runtime.store.transition(job_id, sm.CANCELED)
    except JobNotFound:
        raise ApiError(404, errors.JOB_NOT_FOUND) from None
    except sm.IllegalTransition as e:
        raise ApiError(409, errors.cannot_cancel(e.current.value)) from None
    runtime.coordinator.wake()  # it cancels the job's tasks: running tiles stop at their next sample wave
    return job_public(row)


@router.post("/{job_id}/retry", response_model=JobPublic, responses=answers(404, 409))
def retry_job(runtime: RuntimeDep, job_id: str):
    """Queue a failed or canceled job again: it resumes from its checkpointed tiles and finished frames."""
    row = _job(runtime.store, job_id)
    if not sm.can_move(row.job_state, sm.QUEUED):
        raise ApiError(409, errors.cannot_retry(row.state))
    # Nothing to clear: a stopped run's tiles were cancelled on Dask; the new run submits new tasks.
    try:
        row = runtime.store.transition(job_id, sm.QUEUED)
    except JobNotFound:
        raise ApiError(404, errors.JOB_NOT_FOUND) from None
    except sm.IllegalTransition as e:
        raise ApiError(409, errors.cannot_retry(e.current.value)) from None
    runtime.coordinator.wake()
    return job_public(row)


@router.delete("/{job_id}", status_code=204, responses=answers(404, 409, 422))
def delete_job(runtime: RuntimeDep, job_id: str):
    """Delete a job with its files (and its scene, if no other job uses it); a queued or running job is canceled
    first, and its running tiles stop within about a second wherever they run."""
    try:
        runtime.store.transition(job_id, sm.CANCELED)
    except JobNotFound:
        raise ApiError(404, errors.JOB_NOT_FOUND) from None
    except sm.IllegalTransition:
        pass  # already finished
    try:
        row = runtime.store.delete_job(job_id)
    except JobNotFound:  # deleted by a concurrent request
        raise ApiError(404, errors.JOB_NOT_FOUND) from None
    except JobActive as e:  # cannot happen after the cancel above, unless a future state allows it
        raise ApiError(409, errors.cannot_delete(e.state.value)) from None
    runtime.coordinator.wake()
    JobFiles(runtime.settings.data_dir, job_id).remove()
    runtime.scenes.collect(row.scene_sha256, runtime.store.scene_in_use)
    return Response(status_code=204)


_EXR = {200: {"content": {"image/x-exr": {"schema": {"type": "string", "format": "binary"}}},
              "description": "an OpenEXR file"}}


@router.get("/{job_id}/frames/{frame}.exr", response_class=FileResponse, responses={**_EXR, **answers(404, 409, 422)})
def get_frame(store: StoreDep, settings: SettingsDep, job_id: str, frame: str):
    """The frame's EXR, once it is rendered (409 before): its first product (``products[0]``)."""
    f = find_frame(_job(store, job_id), frame)
    if f is None:
        raise ApiError(404, errors.FRAME_NOT_FOUND)
    path = JobFiles(settings.data_dir, job_id).main_image(f) if f.done else None
    if path is None or not path.is_file():
        raise ApiError(409, errors.FRAME_NOT_READY)
    return FileResponse(path, media_type="image/x-exr", filename=f"{job_id}_{frame}.exr")


@router.get("/{job_id}/frames/{frame}/products/{name:path}", response_class=FileResponse,
            responses={**_EXR, **answers(404, 409, 422)})
def get_product(store: StoreDep, settings: SettingsDep, job_id: str, frame: str, name: str):
    """One product of a frame, by its name in the frame's ``products`` (a relative path: slashes allowed), once the
    frame is rendered (409 before). 404 names the frame's products when it has none of this name; 422 for a name
    that could not be a product's (absolute, or with ``..``)."""
    f = find_frame(_job(store, job_id), frame)
    if f is None:
        raise ApiError(404, errors.FRAME_NOT_FOUND)
    if product_name(name) != name:
        raise ApiError(422, errors.bad_product_name(name))
    if not f.done:
        raise ApiError(409, errors.FRAME_NOT_READY)
    names = [p["name"] for p in f.products or ()]
    if name not in names:
        raise ApiError(404, errors.product_not_found(frame, name, names))
    path = JobFiles(settings.data_dir, job_id).product(f.idx, name)  # a safe name, checked above
    if not path.is_file():
        raise ApiError(404, errors.product_not_found(frame, name, names))
    return FileResponse(path, media_type="image/x-exr", filename=name.rsplit("/", 1)[-1])


@router.get("/{job_id}/frames/{frame}/preview.png", response_class=Response,
            responses={200: {"content": {"image/png": {"schema": {"type": "string", "format": "binary"}}},
                             "description": "a tone-mapped PNG"}, **answers(404, 422)})
def get_preview(store: StoreDep, settings: SettingsDep, job_id: str, frame: str):
    """A tone-mapped PNG of the frame: the finished tiles while it renders, the EXR once it is done."""
    row = _job(store, job_id)
    f = find_frame(row, frame)
    if f is None:
        raise ApiError(404, errors.FRAME_NOT_FOUND)
    files = JobFiles(settings.data_dir, job_id)
    exr = files.main_image(f)
    if f.done and exr.is_file():
        data = preview.from_exr(exr)
    else:
        boxes = split_tiles(row.width, row.height, row.tile_size)
        data = preview.from_tiles([(files.tile(f.idx, i), b) for i, b in enumerate(boxes)], row.width, row.height,
                                  row.exposure_scale)
    return Response(data, media_type="image/png", headers={"Cache-Control": "no-store"})
