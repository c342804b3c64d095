"""Server-sent events: ``GET /v1/events`` (every job) and ``GET /v1/jobs/{id}/events`` (one job).

Events (``text/event-stream``): ``job`` with the job's public view (the body of ``GET /v1/jobs/{id}``) whenever it
changes (state, progress: at most one per job and feed interval), ``deleted`` with ``{"id": ...}``, ``ready`` once
the subscription is in place (the all-jobs stream: load the list after it and nothing is missed), ``resync`` when
the reader fell behind (load the jobs again). The one-job stream starts with the job as it is and ends after
``deleted``. A comment line every ``KEEPALIVE`` seconds keeps proxies from closing an idle stream.

Authentication is the ``Authorization`` header like every other endpoint. Browsers read the stream with
``fetch`` (a readable body) rather than ``EventSource``, which cannot send headers: that keeps the token out of
URLs (server logs, browser history, proxies) and needs no second way to authenticate.
"""
from __future__ import annotations

import asyncio
import json

import anyio
from fastapi import APIRouter, Request
from fastapi.responses import StreamingResponse

from schemas import ErrorBody

from .. import errors
from ..errors import ApiError
from ..queue.changes import ChangeFeed, Subscription
from ..queue.store import JobNotFound
from .deps import Authorized, StoreDep
from .presenters import job_public

router = APIRouter(tags=["events"], dependencies=[Authorized], responses={401: {"model": ErrorBody}})

KEEPALIVE = 15.0  # seconds
STREAM_HEADERS = {"Cache-Control": "no-store", "X-Accel-Buffering": "no"}  # no buffering in nginx-like proxies
EVENT_STREAM = {200: {"content": {"text/event-stream": {}}, "description": "a stream of server-sent events"}}


def get_feed(request: Request) -> ChangeFeed:
    return request.app.state.feed


def _event(name: str, data: str) -> str:
    return f"event: {name}\ndata: {data}\n\n"


async def _relay(sub: Subscription, until_deleted: bool):
    while True:
        try:
            item = await asyncio.wait_for(sub.queue.get(), KEEPALIVE)
        except TimeoutError:
            yield ": keepalive\n\n"
            continue
        if item is None:
            return
        if sub.overflowed:  # what is queued is stale: drop it and let the reader start over
            while not sub.queue.empty():
                sub.queue.get_nowait()
            sub.overflowed = False
            yield _event("resync", "{}")
            continue
        name, data = item
        yield _event(name, data)
        if until_deleted and name == "deleted":
            return


@router.get("/events", response_class=StreamingResponse, responses=EVENT_STREAM)
async def all_events(request: Request):
    """Changes of every job, as server-sent events."""
    feed = get_feed(request)

    async def stream():
        async with feed.subscribe(None) as sub:
            yield "retry: 2000\n\n" + _event("ready", "{}")
            async for chunk in _relay(sub, until_deleted=False):
                yield chunk

    return StreamingResponse(stream(), media_type="text/event-stream", headers=STREAM_HEADERS)


@router.get("/jobs/{job_id}/events", response_class=StreamingResponse,
            responses={**EVENT_STREAM, 404: {"model": ErrorBody}})
async def job_events(request: Request, store: StoreDep, job_id: str):
    """Changes of one job, as server-sent events, starting with the job as it is now."""
    feed = get_feed(request)
    try:
        await anyio.to_thread.run_sync(store.get_job, job_id)
    except JobNotFound:
        raise ApiError(404, errors.JOB_NOT_FOUND) from None

    async def stream():
        async with feed.subscribe(job_id) as sub:
            try:  # the first event is read after subscribing: a change in between is sent again, never lost
                row = await anyio.to_thread.run_sync(store.get_job, job_id)
            except JobNotFound:
                yield _event("deleted", json.dumps({"id": job_id}))
                return
            yield "retry: 2000\n\n" + _event("job", job_public(row).model_dump_json())
            async for chunk in _relay(sub, until_deleted=True):
                yield chunk

    return StreamingResponse(stream(), media_type="text/event-stream", headers=STREAM_HEADERS)
