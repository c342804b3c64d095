"""The job change feed behind the server-sent events: one watcher per service notices changed and deleted jobs
and hands every subscriber the job's public view (``present``, given by the API: the queue knows no wire format).

Why a watcher over the database rather than callbacks from the writers: every state change and every finished tile
already stamps the job's ``updated_at`` in one committed ``UPDATE``, whoever wrote it (an API thread, the dispatcher
thread or, with a shared database, another process). One query per ``interval`` finds them, and a
burst of tiles of one job becomes one event per interval. A write that commits later than the time it stamped is
still seen: the watcher looks back ``LOOKBACK`` seconds and remembers which version of each job it already sent.
A deletion shows as a job count lower than the ids known; the ids are then compared.

The watcher runs only while someone subscribes. A subscriber that reads too slowly (its queue is full) is told to
``resync`` (fetch the jobs again) instead of holding an ever-growing backlog.
"""
from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import anyio

from .store import JobNotFound, JobRow, Store

log = logging.getLogger("drt.events")

LOOKBACK = 10.0  # seconds: longer than any commit takes after stamping updated_at
QUEUE_SIZE = 256


@dataclass(eq=False)
class Subscription:
    job_id: str | None  # None: every job
    queue: asyncio.Queue = field(default_factory=lambda: asyncio.Queue(QUEUE_SIZE))
    overflowed: bool = False

    def offer(self, item) -> None:
        try:
            self.queue.put_nowait(item)
        except asyncio.QueueFull:
            self.overflowed = True


class ChangeFeed:
    """``async with feed.subscribe(job_id) as sub``: ``await sub.queue.get()`` gives ``(event, data)`` pairs,
    ``("job", present(job))`` or ``("deleted", '{"id": ...}')``, and ``None`` when the feed closes."""

    def __init__(self, store: Store, present: Callable[[JobRow], str], interval: float = 0.25):
        self.store = store
        self.present = present  # a job's row -> its public view as JSON
        self.interval = interval
        self._subs: set[Subscription] = set()
        self._task: asyncio.Task | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._closed = False

    @asynccontextmanager
    async def subscribe(self, job_id: str | None = None):
        sub = Subscription(job_id)
        if self._closed:
            sub.offer(None)
        self._subs.add(sub)
        self._loop = asyncio.get_running_loop()
        if not self._closed and (self._task is None or self._task.done()):
            self._task = asyncio.create_task(self._watch(), name="drt-change-feed")
        try:
            yield sub
        finally:
            self._subs.discard(sub)

    def close(self) -> None:
        """End every stream (the service is stopping: open streams must not hold up its shutdown)."""
        self._closed = True
        for sub in list(self._subs):
            sub.offer(None)

    def close_threadsafe(self) -> None:
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self.close)
        else:
            self._closed = True

    def _view(self, job_id: str) -> str | None:
        try:
            return self.present(self.store.get_job(job_id))
        except JobNotFound:
            return None

    async def _watch(self) -> None:
        known: set[str] | None = None  # ids of the jobs that exist
        sent: dict[str, float] = {}  # job id -> updated_at of the version last sent
        while self._subs and not self._closed:
            try:
                if known is None:
                    known = await anyio.to_thread.run_sync(self.store.job_ids)
                known, sent = await self._tick(known, sent)
            except Exception:  # noqa: BLE001 - a busy database must not end the feed; the next turn retries
                log.warning("change feed turn failed", exc_info=True)
            await asyncio.sleep(self.interval)

    async def _tick(self, known: set[str], sent: dict[str, float]) -> tuple[set[str], dict[str, float]]:
        rows = await anyio.to_thread.run_sync(self.store.changed_since, time.time() - LOOKBACK)
        changed = [job_id for job_id, updated, _ in rows if sent.get(job_id) != updated]
        sent = {job_id: updated for job_id, updated, _ in rows}
        known |= sent.keys()
        gone: set[str] = set()
        if await anyio.to_thread.run_sync(self.store.job_count) != len(known):
            ids = await anyio.to_thread.run_sync(self.store.job_ids)
            gone, known = known - ids, ids
        for job_id in changed:
            if job_id in gone or not self._wanted(job_id):
                continue
            data = await anyio.to_thread.run_sync(self._view, job_id)
            if data is None:
                gone.add(job_id)
            else:
                self._publish(job_id, ("job", data))
        for job_id in gone:
            known.discard(job_id)
            self._publish(job_id, ("deleted", json.dumps({"id": job_id})))
        return known, sent

    def _wanted(self, job_id: str) -> bool:
        return any(s.job_id is None or s.job_id == job_id for s in self._subs)

    def _publish(self, job_id: str, item: tuple[str, str]) -> None:
        for sub in list(self._subs):
            if sub.job_id is None or sub.job_id == job_id:
                sub.offer(item)
