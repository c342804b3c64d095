"""Stopping a job's running tiles through Dask itself (no shared disk needed between service and workers).

Dask cannot interrupt a running task, so a tile polls between its sample waves. Each plan of a job (one per time
the scheduler takes the job up) gets a fresh key; when the job leaves the active states (canceled, failed,
deleted) the scheduler sets a ``distributed.Event`` of that name on the Dask scheduler, which every worker can see.
Keys are never reused, so a job run again (after a restart or a retry) is never stopped by an old signal; set
events are cleared after a grace period, once no tile that could have seen them is still running.
"""
from __future__ import annotations

import logging
import time
import uuid
from typing import Callable

log = logging.getLogger("drt.stopping")

GRACE = 300.0  # seconds an event stays set: far longer than one sample wave of any tile


def new_key(job_id: str) -> str:
    return f"drt-stop-{job_id}-{uuid.uuid4().hex[:8]}"


class StopSignals:
    """The service side: set a plan's event, clear it after ``grace`` seconds (call ``sweep`` now and then)."""

    def __init__(self, client, grace: float = GRACE):
        self.client = client
        self.grace = grace
        self._set: dict[str, float] = {}

    def stop(self, key: str) -> None:
        from distributed import Event

        try:
            Event(key, client=self.client).set()
        except Exception:  # noqa: BLE001 - the cluster is unreachable: its tiles are lost with it anyway
            log.warning("could not signal %s to stop", key, exc_info=True)
            return
        self._set[key] = time.monotonic()

    def sweep(self) -> None:
        from distributed import Event

        now = time.monotonic()
        for key in [k for k, t in self._set.items() if now - t > self.grace]:
            try:
                Event(key, client=self.client).clear()  # a cleared event without waiters is deleted
            except Exception:  # noqa: BLE001 - try again next sweep
                continue
            del self._set[key]


def dask_should_stop(key: str, every: float = 0.25) -> Callable[[], bool]:
    """The worker side: a ``should_stop()`` that asks the Dask scheduler whether ``key`` is set, at most every
    ``every`` seconds (an RPC per call). Outside a Dask worker, or if the scheduler cannot be asked, it says no:
    finishing a tile is always safe, only wasteful."""
    from distributed import Event

    event = Event(key)
    last = time.monotonic()
    stopped = False

    def should_stop() -> bool:
        nonlocal last, stopped
        now = time.monotonic()
        if not stopped and now - last >= every:
            last = now
            try:
                stopped = event.is_set()
            except Exception:  # noqa: BLE001 - see above
                log.debug("cannot ask whether %s is set", key, exc_info=True)
        return stopped

    return should_stop
