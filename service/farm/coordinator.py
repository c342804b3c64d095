"""The coordinator: the dispatcher and its Dask cluster, which turn queued jobs into tile tasks and tile results
into frames. It runs in a child process of its own (``CoordinatorProcess``, the default) or as threads of the API's
process (``Coordinator``, ``DRT_SCHEDULER_PROCESS=false``: the in-process tests patch worker functions).

Why a process of its own: the Dask client's IO loop, the embedded Dask scheduler and the job scheduler's
bookkeeping (results, checkpoints, EXR writes) were three quarters of the API process's GIL time per job; status
requests and submissions queued behind them. A submission alone now costs the API process 3.3 ms of CPU instead of
7.3; with 50 clients submitting tiny jobs at once (``bench/load_test.py``, three alternating runs on this 2-core
machine): 40 jobs/s instead of 30-38 as threads, submit p50 97-143 ms instead of 116-149 ms.

The two processes share only the database (all job state; both open it, WAL mode) and one pipe:
- API -> child: ``b"wake"`` (a job was created, canceled, retried or deleted), ``b"farm"`` (the monitor wants the
  workers and their tasks), ``b"stop"``; plain bytes, since a wake-up per submission must cost next to nothing.
- child -> API: ``("ready",)`` once the cluster is up, then ``("state", facts, stats, farm)`` every
  ``PUBLISH_EVERY`` seconds (``farm`` only for a while after it was asked for: it costs the Dask scheduler a look
  at every worker). The API answers ``/healthz``, ``/metrics`` and 503s from the last state: never waits on it.
- The child exits when the pipe closes, so a dead API (even SIGKILLed) never leaves a second dispatcher on its
  database. A child that dies is started again (backing off 1 s to 30 s); meanwhile the cluster counts as
  unreachable (submissions get 503) and the new child resumes the running jobs from their checkpoints, as after a
  restart of the service.
"""
from __future__ import annotations

import logging
import multiprocessing
import signal
import threading
import time
from dataclasses import dataclass, field

from ..settings import ServiceSettings
from .cluster import UNREACHABLE, Cluster, ClusterFacts

log = logging.getLogger("drt.coordinator")

PUBLISH_EVERY = 0.25  # seconds between the child's state messages
FARM_INTEREST = 10.0  # seconds the child keeps sending the farm after the API asked for it
FARM_WAIT = 2.0  # seconds the API waits for a fresh farm
STALE_AFTER = 10.0  # seconds without a state message after which the cluster counts as unreachable
RESTART_FIRST, RESTART_MAX = 1.0, 30.0  # seconds before starting a dead child again


@dataclass(frozen=True)
class DispatcherStats:
    """The dispatcher's counters, as ``/metrics`` and the monitor show them."""
    tiles_completed: int = 0
    tiles_failed: int = 0
    tiles_lost: int = 0
    in_flight: int = 0
    pending: int = 0
    tiles_per_second: float = 0.0


@dataclass(frozen=True)
class FarmView:
    """What the Dask scheduler says of its workers: ``scheduler_info`` (empty while unreachable), the task keys
    each worker holds, and the dashboard's link."""
    info: dict = field(default_factory=dict)
    processing: dict = field(default_factory=dict)  # {worker address: [task keys]}
    dashboard_link: str | None = None


class Coordinator:
    """The dispatcher and its cluster as threads of this process."""

    def __init__(self, settings: ServiceSettings, store, scenes):
        self.settings = settings
        self.store = store
        self.scenes = scenes
        self.cluster = Cluster(settings)
        self.dispatcher = None

    def start(self) -> "Coordinator":
        from .dispatcher import Dispatcher  # the renderer's film code comes with it: only where tiles are handled

        self.cluster.start()
        self.dispatcher = Dispatcher(self.settings, self.store, self.cluster, self.scenes)
        self.dispatcher.start()
        return self

    def wake(self) -> None:
        self.dispatcher.wake()

    def facts(self) -> ClusterFacts:
        return self.cluster.facts()

    def available(self) -> bool:
        return self.cluster.available()

    def stats(self) -> DispatcherStats:
        s = self.dispatcher
        return DispatcherStats(tiles_completed=s.tiles_completed, tiles_failed=s.tiles_failed,
                              tiles_lost=s.tiles_lost, in_flight=s.in_flight(), pending=s.pending_tiles(),
                              tiles_per_second=s.tiles_per_second())

    def farm(self) -> FarmView:
        """Asks the Dask scheduler (a round trip or two); an empty view while it cannot be reached."""
        client = self.cluster.client
        if client is None or not self.cluster.available():
            return FarmView()
        try:
            info = client.scheduler_info(n_workers=-1)
            processing = {w: [str(k) for k in keys] for w, keys in client.processing().items()}
        except Exception:  # noqa: BLE001 - the cluster is away for the moment: the monitor shows no workers
            return FarmView()
        try:
            link = client.dashboard_link
        except Exception:  # noqa: BLE001
            link = None
        return FarmView(info=info, processing=processing, dashboard_link=link)

    def close(self) -> None:
        if self.dispatcher is not None:
            self.dispatcher.stop()
        self.cluster.close()


class CoordinatorProcess:
    """The same questions, answered by a child process that runs a ``Coordinator``."""

    def __init__(self, settings: ServiceSettings):
        self.settings = settings
        self._ctx = multiprocessing.get_context("spawn")  # no fork of a process with threads
        self._proc = None
        self._conn = None
        self._send_lock = threading.Lock()
        self._changed = threading.Condition()
        self._facts = UNREACHABLE
        self._stats = DispatcherStats()
        self._farm = FarmView()
        self._farm_at = 0.0  # monotonic time of the last farm received
        self._state_at = 0.0  # ... of the last state received
        self._ready = threading.Event()
        self._stopping = threading.Event()
        self._reader: threading.Thread | None = None

    # -- lifecycle -------------------------------------------------------------------------------------------
    def start(self, timeout: float = 300.0) -> "CoordinatorProcess":
        """Start the child and wait until its cluster is up (RuntimeError if it dies or takes too long)."""
        self._spawn()
        self._reader = threading.Thread(target=self._read, name="drt-coordinator", daemon=True)
        self._reader.start()
        deadline = time.monotonic() + timeout
        while not self._ready.wait(0.1):
            if not self._proc.is_alive() and not self._ready.is_set():
                self._stopping.set()  # no restarts of a child that cannot start
                raise RuntimeError(f"the coordinator process exited with code {self._proc.exitcode} while "
                                   "starting (its log lines above say why)")
            if time.monotonic() > deadline:
                self.close()
                raise RuntimeError(f"the coordinator process did not start within {timeout:.0f} s")
        return self

    def _spawn(self) -> None:
        parent, child = self._ctx.Pipe()
        level = logging.getLogger().getEffectiveLevel()
        # Not a daemon: a daemonic process may not start the LocalCluster's worker processes.
        proc = self._ctx.Process(target=child_main, args=(self.settings, child, level), name="drt-coordinator")
        proc.start()
        child.close()  # the child holds the only other end: when it dies, our reads end
        self._proc, self._conn = proc, parent
        self._ready.clear()

    def _read(self) -> None:
        backoff = RESTART_FIRST
        while True:
            try:
                message = self._conn.recv()
            except (EOFError, OSError):
                self._proc.join(timeout=30)
                with self._changed:
                    self._facts, self._state_at = UNREACHABLE, 0.0
                    self._changed.notify_all()
                if self._stopping.is_set():
                    return
                log.error("the coordinator process exited (code %s); starting a new one in %.0f s",
                          self._proc.exitcode, backoff)
                if self._stopping.wait(backoff):
                    return
                backoff = min(2 * backoff, RESTART_MAX)
                self._spawn()
                continue
            kind = message[0]
            if kind == "ready":
                self._ready.set()
                backoff = RESTART_FIRST
            elif kind == "state":
                _, facts, stats, farm = message
                with self._changed:
                    self._facts, self._stats, self._state_at = facts, stats, time.monotonic()
                    if farm is not None:
                        self._farm, self._farm_at = farm, self._state_at
                    self._changed.notify_all()

    def close(self) -> None:
        self._stopping.set()
        self._send(b"stop")
        if self._proc is not None:
            self._proc.join(timeout=60)
            if self._proc.is_alive():
                log.warning("the coordinator process did not stop within 60 s; killing it")
                self._proc.kill()
                self._proc.join(timeout=10)
        if self._reader is not None:
            self._reader.join(timeout=10)
        if self._conn is not None:
            self._conn.close()

    def _send(self, message: bytes) -> None:
        with self._send_lock:
            try:
                self._conn.send_bytes(message)
            except (OSError, ValueError, AttributeError):
                pass  # the child is gone: the next one reads the database afresh anyway

    # -- what the API asks ---------------------------------------------------------------------------------------
    def wake(self) -> None:
        self._send(b"wake")

    def facts(self) -> ClusterFacts:
        """The child's last word on the cluster; unreachable when the child is silent or gone."""
        if time.monotonic() - self._state_at > STALE_AFTER:
            return UNREACHABLE
        return self._facts

    def available(self) -> bool:
        return self.facts().reachable

    def stats(self) -> DispatcherStats:
        return self._stats

    def farm(self) -> FarmView:
        asked = time.monotonic()
        self._send(b"farm")
        with self._changed:
            self._changed.wait_for(lambda: self._farm_at >= asked or self._state_at == 0.0, timeout=FARM_WAIT)
            return self._farm if self._state_at else FarmView()


def child_main(settings: ServiceSettings, conn, log_level: int) -> None:
    """The coordinator process: its own database connection and cluster, steered through ``conn``."""
    from ..queue.scenes import SceneStore
    from ..queue.store import Store

    logging.basicConfig(level=log_level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    # Ctrl-C in a terminal reaches the whole process group: the API shuts down and tells this process to stop.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stopping = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stopping.set())
    store = Store(settings.db_path, clear_claims=False)  # the API's requests in flight hold theirs
    scenes = SceneStore(settings.data_dir / "scenes", settings.max_upload_bytes)
    coordinator = Coordinator(settings, store, scenes)
    try:
        coordinator.start()
        conn.send(("ready",))
        farm_until = [0.0]
        farm_now = threading.Event()

        def publish() -> None:
            while not stopping.is_set():
                farm = coordinator.farm() if time.monotonic() < farm_until[0] else None
                try:
                    conn.send(("state", coordinator.facts(), coordinator.stats(), farm))
                except (OSError, ValueError):
                    stopping.set()
                    return
                farm_now.wait(PUBLISH_EVERY)
                farm_now.clear()

        publisher = threading.Thread(target=publish, name="drt-publish", daemon=True)
        publisher.start()
        while not stopping.is_set():
            if not conn.poll(0.5):
                continue
            try:
                message = conn.recv_bytes()
            except (EOFError, OSError):
                break  # the API process is gone
            if message == b"wake":
                coordinator.wake()
            elif message == b"farm":
                farm_until[0] = time.monotonic() + FARM_INTEREST
                farm_now.set()
            elif message == b"stop":
                break
    finally:
        stopping.set()
        coordinator.close()
        store.close()
        conn.close()
