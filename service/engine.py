"""The execution engine: a Dask client, on an embedded ``LocalCluster`` or an external ``dask scheduler``.

Embedded (no ``DRT_SCHEDULER_ADDRESS``): ``DRT_WORKERS`` worker processes (nanny-supervised: a worker that dies
is restarted and its tasks rescheduled), each with ``DRT_THREADS_PER_WORKER`` threads (default: all cores over the
workers). External: the same code, with workers started by ``dask worker`` elsewhere; they must see the data
directory at the same path (a shared volume), since tasks read scenes and write checkpoints and frames there.
"""
from __future__ import annotations

import logging
import os
import time
from typing import Any, Callable

from .settings import ServiceSettings

log = logging.getLogger("drt.engine")


class Engine:
    def __init__(self, settings: ServiceSettings):
        self.settings = settings
        self.cluster = None
        self.client = None
        self._nthreads_cache: dict = {}
        self._nthreads_at = -1e9

    def start(self) -> "Engine":
        import dask
        from distributed import Client, LocalCluster

        s = self.settings
        if s.scheduler_address:
            log.info("connecting to the Dask scheduler at %s", s.scheduler_address)
            self.client = Client(s.scheduler_address, set_as_default=False, timeout="30s")
        else:
            # A worker killed while running a tile counts against the task; three deaths in a row mean the task
            # itself kills workers. Dask's default, kept explicit since the scheduler's retry logic relies on it.
            with dask.config.set({"distributed.scheduler.allowed-failures": 3}):
                # No dashboard, and the scheduler's own HTTP endpoint on an ephemeral loopback port rather than
                # 8787, so that several services (and test runs) on one machine never collide.
                self.cluster = LocalCluster(n_workers=s.workers, threads_per_worker=s.local_threads(),
                                            processes=s.processes, dashboard_address=None,
                                            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                            silence_logs=logging.WARNING)
            self.client = Client(self.cluster, set_as_default=False)
            log.info("started a LocalCluster: %d worker(s) x %d thread(s) (%s)", s.workers, s.local_threads(),
                     "processes" if s.processes else "threads")
        return self

    def submit(self, fn: Callable, *args: Any, key: str, priority: int = 0, retries: int = 0):
        return self.client.submit(fn, *args, key=key, priority=priority, retries=retries, pure=False)

    def _nthreads(self) -> dict:
        """{worker: threads}, asked of the scheduler at most once a second (the scheduler loop asks often)."""
        now = time.monotonic()
        if now - self._nthreads_at > 1.0:
            try:
                self._nthreads_cache = dict(self.client.nthreads())
            except Exception:  # noqa: BLE001 - the scheduler is unreachable for the moment
                self._nthreads_cache = {}
            self._nthreads_at = now
        return self._nthreads_cache

    def threads(self) -> int:
        """Worker threads in the cluster now (workers come and go on an external cluster)."""
        return int(sum(self._nthreads().values()))

    def workers(self) -> int:
        return len(self._nthreads())

    def restartable(self) -> bool:
        """Workers are processes under a nanny (not threads of this process), so they can be restarted."""
        return self.cluster is None or self.settings.processes

    def worker_pids(self) -> dict[str, int]:
        return self.client.run(os.getpid)

    def close(self) -> None:
        if self.client is not None:
            try:
                self.client.close(timeout=10)
            except Exception:  # noqa: BLE001 - shutting down anyway
                log.debug("closing the Dask client failed", exc_info=True)
        if self.cluster is not None:
            try:
                self.cluster.close(timeout=20)
            except Exception:  # noqa: BLE001
                log.debug("closing the LocalCluster failed", exc_info=True)
        self.client = self.cluster = None
