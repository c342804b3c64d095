"""Creating a job from an upload: settings, size, Idempotency-Key, scene safety and inspection, then the queue.

Order matters, cheapest and most certain first: settings JSON (422) and the file's extension (422); while the
render cluster is unreachable, 503 (with ``Retry-After``); the upload is streamed to disk with a byte limit (413)
and hashed; the Idempotency-Key is claimed (a replay returns the first job; the same key with a different request
is 422; while the first request is still running, 409); a ``.usdz``'s entries are checked; a local inspection
process checks every asset path, composes the stage and loads the first frame (422 with the renderer's message;
``intake.inspection``); the job's cost against the farm's limits (``intake.limit_checks``: 422) is checked once from
the settings alone (before the upload is looked at, when they give the resolution) and again with the scene's real
resolution and frames, the queue's length too; only then is the job queued.

Idempotency: the request's identity is the scene's content hash, its file name and the canonical settings JSON. A
key is remembered with its job until the job is deleted.
"""
from __future__ import annotations

import hashlib
import logging
import uuid
from pathlib import Path
from typing import BinaryIO, Protocol

from pydantic import ValidationError

from renderer.film.tiles import tile_count
from schemas import JobCreate
from schemas.settings import FRAMES_TAGS

from .. import errors
from ..errors import ApiError
from ..queue.scenes import SceneStore, StoredScene, UploadError
from ..queue.store import JobRow, Store
from ..settings import ServiceSettings
from . import limit_checks
from .scene_checks import check_usdz, safe_name, scene_extension

log = logging.getLogger("drt.submission")


def settings_error(e: ValidationError) -> str:
    """pydantic's errors as one line naming each field: ``invalid settings: spp: Input should be ...``."""
    parts = []
    for err in e.errors(include_url=False):
        loc = ".".join(str(x) for i, x in enumerate(err["loc"])  # the union's tags are not field names
                       if not (i == 1 and err["loc"][0] == "frames" and x in FRAMES_TAGS))
        msg = err["msg"].removeprefix("Value error, ")
        parts.append(f"{loc}: {msg}" if loc else msg)
    return "invalid settings: " + "; ".join(parts)


def parse_settings(text: str) -> JobCreate:
    try:
        return JobCreate.model_validate_json(text or "{}")
    except ValidationError as e:
        raise ApiError(422, settings_error(e)) from None


class Inspector(Protocol):
    def __call__(self, stored: StoredScene, settings: JobCreate) -> dict: ...


RETRY_AFTER = "5"  # seconds a client is asked to wait after a 503


def new_job_id() -> str:
    return uuid.uuid4().hex


class Submitter:
    def __init__(self, settings: ServiceSettings, store: Store, scenes: SceneStore, on_created=lambda: None,
                 cluster_available=lambda: True):
        self.settings = settings
        self.store = store
        self.scenes = scenes
        self.on_created = on_created
        self.cluster_available = cluster_available

    def submit(self, upload: BinaryIO, filename: str | None, settings_text: str, idempotency_key: str | None,
               inspector: Inspector, client: str | None = None) -> tuple[JobRow, bool]:
        """Returns (job, created): created is False when an Idempotency-Key replays an earlier request.
        ``client`` identifies the submitter for the per-client queue limit."""
        settings = parse_settings(settings_text)
        try:
            ext = scene_extension(filename)
        except UploadError as e:
            raise ApiError(e.status, str(e)) from None
        frames = settings.frame_times()
        if frames is not None:
            limit_checks.check_frames(self.settings, len(frames))
        if settings.width is not None and settings.height is not None:
            limit_checks.check_cost(self.settings, width=settings.width, height=settings.height, spp=settings.spp,
                                    frames=len(frames) if frames is not None else 1)
        if not self.cluster_available():
            raise ApiError(503, errors.CLUSTER_UNAVAILABLE, headers={"Retry-After": RETRY_AFTER})
        try:
            tmp, sha, size = self.scenes.receive(upload)
        except UploadError as e:
            raise ApiError(e.status, str(e)) from None
        name = safe_name(filename or "", ext)
        try:
            claimed = False
            if idempotency_key is not None:
                request_hash = hashlib.sha256(f"{sha}\n{name}\n{settings.model_dump_json()}".encode()).hexdigest()
                claim = self.store.claim_key(idempotency_key, request_hash)
                if claim.outcome == "existing":
                    return self.store.get_job(claim.job_id), False
                if claim.outcome == "conflict":
                    raise ApiError(422, errors.IDEMPOTENCY_MISMATCH)
                if claim.outcome == "busy":
                    raise ApiError(409, errors.IDEMPOTENCY_BUSY)
                claimed = True
            try:
                job = self._create(tmp, sha, name, size, ext, settings, idempotency_key, inspector, client)
            except BaseException:
                if claimed:
                    self.store.release_key(idempotency_key)
                raise
        finally:
            tmp.unlink(missing_ok=True)
        self.on_created()
        return job, True

    def _create(self, tmp: Path, sha: str, name: str, size: int, ext: str, settings: JobCreate,
                idempotency_key: str | None, inspector: Inspector, client: str | None) -> JobRow:
        s = self.settings
        created = False
        try:
            with self.scenes.pinned(tmp, sha, name, size) as stored:
                try:
                    if ext == ".usdz":
                        check_usdz(stored.path, s.max_usdz_unpacked_bytes, s.max_usdz_entries)
                except UploadError as e:
                    raise ApiError(e.status, str(e)) from None
                limit_checks.check_queue(s, self.store, client)  # before the inspection: it costs a worker's time
                info = inspector(stored, settings)
                if "error" in info:
                    raise ApiError(422, info["error"])
                width, height, frames = int(info["width"]), int(info["height"]), list(info["frames"])
                limit_checks.check_cost(s, width=width, height=height, spp=settings.spp, frames=len(frames))
                per_frame = tile_count(width, height, settings.tile)
                limit_checks.check_tiles(s, per_frame * len(frames))
                limit_checks.check_queue(s, self.store, client)  # again: other jobs may have been queued meanwhile
                job_id = new_job_id()  # (its files' directories are made when the dispatcher first plans it)
                job = self.store.create_job(
                    job_id=job_id, priority=settings.priority, settings_json=settings.model_dump_json(),
                    scene_sha256=sha, scene_name=name, scene_bytes=size, width=width, height=height,
                    tile_size=settings.tile, tiles_per_frame=per_frame, frame_times=frames,
                    exposure_scale=float(info.get("exposure_scale", 1.0)), warnings=list(info.get("warnings", [])),
                    idempotency_key=idempotency_key, client=client,
                    product_aovs=list(info.get("product_aovs", [])))
                created = True
                return job
        finally:
            if not created:  # a rejected upload leaves nothing behind unless a job uses the same content
                self.scenes.collect(sha, self.store.scene_in_use)
