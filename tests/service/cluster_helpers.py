"""Real processes for the scale-out tests: ``dask scheduler``, ``dask worker``s that cannot see the service's data
directory, and ``drt serve --scheduler``.

Isolation: each worker runs with its own working directory and ``TMPDIR``, an environment with no ``DRT_*``
variable, and (where the machine allows it: ``unshare`` with a user and mount namespace) in a mount namespace in
which an empty tmpfs covers the service's data directory, so that it could not read a byte of it even by accident.
A worker that dies with its scheduler (``dask worker`` exits when the scheduler goes away) is started again by a
supervisor thread, as compose's ``restart: unless-stopped`` or Kubernetes would.
"""
from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx

from service_helpers import cli_env

BIN = Path(sys.executable).parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _can_unshare() -> bool:
    if shutil.which("unshare") is None:
        return False
    r = subprocess.run(["unshare", "-Urm", "sh", "-c", "mount -t tmpfs none /mnt && true"], capture_output=True,
                       timeout=30)
    return r.returncode == 0


CAN_HIDE = _can_unshare()


class Proc:
    """A process in its own session (killed with its children), its output in a log file."""

    def __init__(self, args: list[str], log: Path, env: dict, cwd: Path | None = None):
        self.args, self.logpath, self.env, self.cwd = args, log, env, cwd
        self.start()

    def start(self) -> None:
        self.log = open(self.logpath, "ab")
        self.proc = subprocess.Popen(self.args, env=self.env, cwd=self.cwd, stdout=self.log, stderr=self.log,
                                     start_new_session=True)

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def kill(self) -> None:
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self.proc.wait(timeout=30)
        self.log.close()

    def terminate(self, timeout: float = 30) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                pass
        self.kill()


class Scheduler(Proc):
    def __init__(self, port: int, log: Path):
        self.port = port
        self.address = f"tcp://127.0.0.1:{port}"
        super().__init__([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                          "--no-dashboard"], log, cli_env())

    def wait_up(self, timeout: float = 60) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=1):
                    return
            except OSError:
                assert self.alive(), self.logpath.read_text()[-3000:]
                assert time.monotonic() < deadline, "dask scheduler did not come up"
                time.sleep(0.1)


def worker_env(home: Path) -> dict:
    """Code (PYTHONPATH), the Warp kernel cache (HOME) and nothing of the service (no DRT_* variables)."""
    env = {k: v for k, v in cli_env().items() if not k.startswith("DRT_")}
    env.update(TMPDIR=str(home), PWD=str(home))
    return env


class SupervisedWorker:
    """``dask worker SCHEDULER --nthreads 1``, restarted whenever it exits until ``stop()``."""

    def __init__(self, address: str, workdir: Path, hidden: Path, log: Path, nthreads: int = 1):
        workdir.mkdir(parents=True, exist_ok=True)
        self.workdir, self.hidden = workdir, hidden
        cmd = [str(BIN / "dask"), "worker", address, "--nthreads", str(nthreads), "--no-dashboard"]
        if CAN_HIDE:  # an empty tmpfs over the service's data directory, in the worker's own mount namespace
            cmd = ["unshare", "-Urm", "sh", "-c", 'mount -t tmpfs -o size=1m drt-hidden "$0" && exec "$@"',
                   str(hidden), *cmd]
        self._stopped = threading.Event()
        self.starts = 0
        self.proc = Proc(cmd, log, worker_env(workdir), cwd=workdir)
        self.starts = 1
        self._thread = threading.Thread(target=self._supervise, daemon=True)
        self._thread.start()

    def _supervise(self) -> None:
        while not self._stopped.is_set():
            if not self.proc.alive() and not self._stopped.is_set():
                self.proc.log.close()
                time.sleep(0.5)
                if not self._stopped.is_set():
                    self.proc.start()
                    self.starts += 1
            time.sleep(0.2)

    def kill(self) -> None:
        """SIGKILL the worker (nanny and worker process) for good: a machine that died."""
        self._stopped.set()
        self._thread.join(timeout=10)
        self.proc.kill()

    def stop(self) -> None:
        self._stopped.set()
        self._thread.join(timeout=10)
        self.proc.terminate(timeout=10)

    def hidden_view(self) -> list[str] | None:
        """What the worker sees at the service's data directory (None if it cannot be looked at)."""
        if not CAN_HIDE or not self.proc.alive():
            return None
        try:
            return os.listdir(f"/proc/{self.proc.pid}/root{self.hidden}")
        except OSError:
            return None


class Server(Proc):
    """``drt serve --scheduler ADDRESS`` on a free loopback port."""

    def __init__(self, data_dir: Path, log: Path, scheduler: str, **settings):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        env = dict(cli_env(), DRT_DATA_DIR=str(data_dir), DRT_POLL_INTERVAL="0.05",
                   **{f"DRT_{k.upper()}": str(v) for k, v in settings.items()})
        super().__init__([str(BIN / "drt"), "serve", "--port", str(self.port), "--scheduler", scheduler,
                          "--log-level", "warning"], log, env)
        deadline = time.monotonic() + 120
        while True:
            try:
                if httpx.get(f"{self.url}/healthz", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert self.alive(), f"drt serve exited: {log.read_text()[-3000:]}"
            assert time.monotonic() < deadline, "drt serve did not come up"
            time.sleep(0.2)
        self.http = httpx.Client(base_url=self.url, timeout=60)

    def health(self) -> tuple[dict, float]:
        t0 = time.perf_counter()
        r = self.http.get("/healthz", timeout=5)
        return r.json(), time.perf_counter() - t0

    def wait_health(self, cluster: str, workers: int = 0, timeout: float = 120) -> dict:
        deadline = time.monotonic() + timeout
        while True:
            h, _ = self.health()
            if h["cluster"] == cluster and h["workers"] >= workers:
                return h
            assert time.monotonic() < deadline, f"/healthz still says {h}"
            time.sleep(0.1)


def service_files(data_dir: Path) -> list[str]:
    """Every file under the data directory, relative (what the service wrote)."""
    return sorted(str(p.relative_to(data_dir)) for p in data_dir.rglob("*") if p.is_file())
