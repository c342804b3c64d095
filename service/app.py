"""``create_app(settings)``: the FastAPI application, its lifespan (database, coordinator, inspection) and error format.

Every error answers ``{"detail": "<one line>"}``: ``ApiError`` from the service, FastAPI's own validation errors
flattened to ``"<field>: <message>"``, a malformed body (e.g. multipart without a boundary) 400, and an oversized
body cut off early with 413 (the ``Content-Length`` is checked before anything is read, the bytes are counted as
they arrive). The bearer token is checked before all of that (``api.auth.TokenFirst``), and every answer carries the
service's own time for it (``api.timing.ServerTiming``, the outermost middleware).
"""
from __future__ import annotations

import json
import logging
from contextlib import asynccontextmanager

import anyio
from fastapi import Depends, FastAPI, HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from .api import events, health, jobs, limits, monitor, web
from .api.auth import TokenFirst
from .api.deps import require_token
from .api.presenters import job_public
from .api.timing import ServerTiming
from .errors import ApiError
from .latency import SubmissionGate, new_submission_gate, tune_api_process
from .queue.changes import ChangeFeed
from .queue.scenes import UploadTooLarge
from .runtime import Runtime
from .settings import ServiceSettings

log = logging.getLogger("drt.service")

MULTIPART_OVERHEAD = 1 << 20  # room for the settings field and part headers next to the largest scene


class _BodyTooLarge(HTTPException):
    pass


class BodyLimit:
    """ASGI middleware: refuse request bodies over ``limit`` bytes with 413 before they fill the disk."""

    def __init__(self, app, limit: int, detail: str):
        self.app = app
        self.limit = limit
        self.detail = detail

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        length = dict(scope.get("headers") or []).get(b"content-length")
        if length is not None and length.isdigit() and int(length) > self.limit:
            return await self._reject(send)
        seen = 0

        async def counted():
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    # An HTTPException passes through FastAPI's body parsing to the exception handlers.
                    raise _BodyTooLarge(413, self.detail)
            return message

        await self.app(scope, counted, send)

    async def _reject(self, send):
        body = json.dumps({"detail": self.detail}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})


def _validation_detail(exc: RequestValidationError) -> str:
    parts = []
    for err in exc.errors():
        loc = [str(x) for x in err.get("loc", ()) if x not in ("body", "query", "path", "header")]
        parts.append(f"{'.'.join(loc)}: {err.get('msg', 'invalid')}" if loc else str(err.get("msg", "invalid")))
    return "; ".join(parts) or "invalid request"


def create_app(settings: ServiceSettings | None = None) -> FastAPI:
    settings = settings or ServiceSettings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        # Starting Dask blocks (worker processes start): keep it off the event loop.
        app.state.runtime = await run_in_threadpool(Runtime.start, settings)
        # Submissions wait for an inspection process to load their scene; they get threads of their own, so that
        # a burst of them never holds every thread of the pool that status requests need. One per inspection
        # process and one more to read the next upload meanwhile: more threads inspect no faster, they only
        # contend for the GIL with the event loop (50 clients at once, bench/load_test.py: status p99 15-21 ms
        # with 3 threads, 25-53 ms with 8).
        submission_threads = settings.inspect_processes + 1
        app.state.submit_limiter = anyio.CapacityLimiter(submission_threads)
        app.state.submission_gate = new_submission_gate(submission_threads)
        # the monitor's server-sent events
        app.state.feed = ChangeFeed(app.state.runtime.store, present=lambda row: job_public(row).model_dump_json())
        tune_api_process()  # startup is done: freeze its heap, shorten the GIL switch interval
        try:
            yield
        finally:
            app.state.feed.close()
            await run_in_threadpool(app.state.runtime.close)

    protected_docs = settings.api_token is not None
    app = FastAPI(
        title="drt render service",
        version="1",
        summary="Distributed ray tracing (Cook, Porter, Carpenter 1984): USD in, OpenEXR out.",
        lifespan=lifespan,
        docs_url=None if protected_docs else "/docs",
        openapi_url=None if protected_docs else "/openapi.json",
        redoc_url=None,
    )
    app.state.settings = settings

    if protected_docs:  # "every endpoint but /healthz" needs the token, the API description included
        @app.get("/openapi.json", include_in_schema=False, dependencies=[Depends(require_token)])
        def openapi_json():
            return JSONResponse(app.openapi())

        @app.get("/docs", include_in_schema=False, dependencies=[Depends(require_token)])
        def docs():
            return get_swagger_ui_html(openapi_url="/openapi.json", title=app.title)

    @app.exception_handler(ApiError)
    async def _api_error(_request: Request, exc: ApiError):
        return JSONResponse({"detail": exc.detail}, status_code=exc.status, headers=exc.headers)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(_request: Request, exc: StarletteHTTPException):
        # FastAPI's body parsing (400), unknown routes (404), wrong methods (405): the same one-line shape.
        detail = exc.detail if isinstance(exc.detail, str) else str(exc.detail)
        if exc.status_code == 400:
            detail = f"malformed request body: {detail}"
        return JSONResponse({"detail": detail}, status_code=exc.status_code, headers=exc.headers)

    @app.exception_handler(RequestValidationError)
    async def _invalid(_request: Request, exc: RequestValidationError):
        return JSONResponse({"detail": _validation_detail(exc)}, status_code=422)

    app.add_middleware(SubmissionGate, path="/v1/jobs")  # inside the body limit: an oversized body never waits
    app.add_middleware(BodyLimit, limit=settings.max_upload_bytes + MULTIPART_OVERHEAD,
                       detail=str(UploadTooLarge(settings.max_upload_bytes)))
    # Outside the body limit: an unauthenticated request is answered 401 before its body is read or measured.
    app.add_middleware(TokenFirst, token=settings.api_token.get_secret_value() if protected_docs else None)
    # Outermost of all: the service's own time for every answer, 401s included (``Server-Timing``).
    app.add_middleware(ServerTiming)
    app.include_router(health.router)
    app.include_router(jobs.router, prefix="/v1")
    app.include_router(limits.router, prefix="/v1")
    app.include_router(events.router, prefix="/v1")
    app.include_router(monitor.router, prefix="/v1")
    app.include_router(web.router)  # the job monitor's static shell (no data, no token)
    return app
