"""The render cluster as the service holds it: a Dask client, on an embedded ``LocalCluster`` or an external
``dask scheduler``.

Embedded (no ``DRT_SCHEDULER_ADDRESS``): ``DRT_WORKERS`` worker processes (nanny-supervised: a worker that dies
is restarted and its tasks rescheduled), each with ``DRT_THREADS_PER_WORKER`` threads (default: all cores over the
workers). External: workers started by ``dask worker tcp://HOST:8786`` anywhere; they need only the scheduler's
address (scenes travel through Dask, tiles come back as results; see ``service.farm.tasks``).

**Outages.** A watcher thread keeps the client connected: the Dask client reconnects by itself for
``DRT_SCHEDULER_TIMEOUT`` seconds and then closes for good, so when it has closed (or never connected) the watcher
makes a new one, backing off from 0.5 s to 5 s between attempts (each first knocks on the scheduler's TCP port for
at most 2 s, so that an attempt never waits out a whole connection timeout). Every future of a lost connection is cancelled by
Dask with the reason ``scheduler-connection-lost``; the dispatcher resubmits those tiles without counting an
attempt. The watcher also caches the cluster's facts (reachable, workers, threads) once a second, so ``/healthz``
and the dispatcher never wait on a scheduler that does not answer. ``submit`` raises ``ClusterUnavailable`` while
there is no connection (the API answers 503).
"""
from __future__ import annotations

import logging
import os
import socket
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

from ..settings import ServiceSettings

log = logging.getLogger("drt.cluster")

BACKOFF_FIRST, BACKOFF_MAX = 0.5, 5.0  # seconds between attempts to make a new client
FACTS_EVERY = 1.0  # seconds between refreshes of the cached cluster facts


class ClusterUnavailable(Exception):
    """No connection to the Dask scheduler right now."""


@dataclass(frozen=True)
class ClusterFacts:
    reachable: bool
    workers: int
    threads: int
    nthreads: dict  # {worker address: threads}


UNREACHABLE = ClusterFacts(False, 0, 0, {})


class Cluster:
    def __init__(self, settings: ServiceSettings):
        self.settings = settings
        self.local = None
        self.client = None
        self.generation = 0  # +1 for every new client: futures of an older one are gone
        self._facts = UNREACHABLE
        self._stop = threading.Event()
        self._watcher: threading.Thread | None = None
        self._lock = threading.Lock()

    def start(self, connect_wait: float = 10.0) -> "Cluster":
        """Start (or connect to) the cluster. An external scheduler that does not answer within ``connect_wait``
        seconds does not stop the service from starting: it reports the cluster unreachable meanwhile."""
        import dask
        from distributed import LocalCluster

        s = self.settings
        if not s.scheduler_address:
            # A worker killed while running a tile counts against the task; three deaths in a row mean the task
            # itself kills workers. Dask's default, kept explicit since the dispatcher's retry logic relies on it.
            with dask.config.set({"distributed.scheduler.allowed-failures": 3}):
                # No dashboard, and the scheduler's own HTTP endpoint on an ephemeral loopback port rather than
                # 8787, so that several services (and test runs) on one machine never collide.
                self.local = LocalCluster(n_workers=s.workers, threads_per_worker=s.local_threads(),
                                            processes=s.processes, dashboard_address=None,
                                            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                            silence_logs=logging.WARNING)
            log.info("started a LocalCluster: %d worker(s) x %d thread(s) (%s)", s.workers, s.local_threads(),
                     "processes" if s.processes else "threads")
            self._connect(timeout=30)
        else:
            log.info("connecting to the Dask scheduler at %s", s.scheduler_address)
        self._watcher = threading.Thread(target=self._watch, name="drt-cluster", daemon=True)
        self._watcher.start()
        deadline = time.monotonic() + connect_wait
        while s.scheduler_address and not self.available() and time.monotonic() < deadline:
            time.sleep(0.05)
        return self

    # -- connection ---------------------------------------------------------------------------------------------
    def _knock(self) -> None:
        """OSError unless the external scheduler's TCP port accepts a connection (cheap, at most 2 s)."""
        address = self.settings.scheduler_address or ""
        if self.local is not None or not address.startswith("tcp://"):
            return
        host, _, port = address[len("tcp://"):].rpartition(":")
        with socket.create_connection((host.strip("[]"), int(port)), timeout=2):
            pass

    def _connect(self, timeout: float) -> None:
        from distributed import Client

        self._knock()
        target = self.local if self.local is not None else self.settings.scheduler_address
        client = Client(target, set_as_default=False, timeout=timeout if self.local is not None
                        else self.settings.scheduler_timeout)
        with self._lock:
            old, self.client = self.client, client
            self.generation += 1
        self._refresh()
        log.info("connected to the Dask scheduler (client %d)", self.generation)
        if old is not None:
            self._close_client(old)

    def _watch(self) -> None:
        backoff = BACKOFF_FIRST
        while not self._stop.is_set():
            client = self.client
            if client is None or client.status in ("closed", "closing"):
                self._facts = UNREACHABLE
                try:
                    self._connect(timeout=5)
                    backoff = BACKOFF_FIRST
                except Exception as e:  # noqa: BLE001 - the scheduler is away; try again later
                    log.warning("the Dask scheduler is unreachable (%s: %s); retrying in %.1f s", type(e).__name__,
                                " ".join(str(e).split())[:200], backoff)
                    self._stop.wait(backoff)
                    backoff = min(2 * backoff, BACKOFF_MAX)
                continue
            self._refresh()
            self._stop.wait(FACTS_EVERY)

    def _refresh(self) -> None:
        client = self.client
        if client is None or client.status != "running":
            if self._facts.reachable:
                log.warning("lost the connection to the Dask scheduler; reconnecting")
            self._facts = UNREACHABLE
            return
        try:
            nthreads = dict(client.nthreads())
        except Exception:  # noqa: BLE001 - the connection broke under us; the next turn sees it
            self._facts = UNREACHABLE
            return
        if client.status == "running":
            self._facts = ClusterFacts(True, len(nthreads), int(sum(nthreads.values())), nthreads)

    def _close_client(self, client) -> None:
        try:
            client.close(timeout=5)
        except Exception:  # noqa: BLE001 - it is gone anyway
            log.debug("closing an old Dask client failed", exc_info=True)

    # -- what the service asks ----------------------------------------------------------------------------------
    def available(self) -> bool:
        client = self.client
        return client is not None and client.status == "running"

    def facts(self) -> ClusterFacts:
        """Reachable, workers and threads as of the last refresh (at most about a second old); never blocks."""
        return self._facts if self.available() else UNREACHABLE

    def submit(self, fn: Callable, *args: Any, key: str, priority: int = 0, retries: int = 0):
        client = self.client
        if client is None or client.status != "running":
            raise ClusterUnavailable("no connection to the Dask scheduler")
        try:
            return client.submit(fn, *args, key=key, priority=priority, retries=retries, pure=False)
        except Exception as e:  # noqa: BLE001 - the client closed between our look and the call
            raise ClusterUnavailable(f"{type(e).__name__}: {e}") from e

    def cancel(self, futures: list) -> None:
        """Release futures (their running tasks stop at the next sample wave); best effort."""
        by_client: dict = {}
        for f in futures:
            by_client.setdefault(id(f.client), (f.client, []))[1].append(f)
        for client, fs in by_client.values():
            if client.status != "running":
                continue  # a lost connection already cancelled them
            try:
                client.cancel(fs)
            except Exception:  # noqa: BLE001 - their results are ignored anyway
                log.debug("cancelling futures failed", exc_info=True)

    def threads(self) -> int:
        """Worker threads in the cluster now (workers come and go on an external cluster)."""
        return self.facts().threads

    def workers(self) -> int:
        return self.facts().workers

    def restartable(self) -> bool:
        """Workers are processes under a nanny (not threads of this process), so they can be restarted."""
        return self.local is None or self.settings.processes

    def worker_pids(self) -> dict[str, int]:
        return self.client.run(os.getpid)

    def close(self) -> None:
        self._stop.set()
        if self._watcher is not None:
            self._watcher.join(timeout=15)
        if self.client is not None:
            try:
                self.client.close(timeout=10)
            except Exception:  # noqa: BLE001 - shutting down anyway
                log.debug("closing the Dask client failed", exc_info=True)
        if self.local is not None:
            try:
                self.local.close(timeout=20)
            except Exception:  # noqa: BLE001
                log.debug("closing the LocalCluster failed", exc_info=True)
        self.client = self.local = None
