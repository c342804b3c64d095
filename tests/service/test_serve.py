"""A real ``drt serve`` process on a loopback port, driven by ``drt submit``/``status``/``fetch`` and plain HTTP;
killed with SIGKILL mid-job and restarted; and a Dask worker process killed mid-tile."""
from __future__ import annotations

import ctypes
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import psutil
import pytest

from service_helpers import (CONTRACT_LIMITS, assert_same_exr, cli_env, cli_render, http_contract, metric,
                             service_settings, submit, wait_job)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """``python -m service.cli serve`` in its own process group (so that it and its workers can be killed)."""

    def __init__(self, data_dir: Path, log: Path, **settings):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = open(log, "ab")
        settings = {"workers": 1, "threads_per_worker": 2, "poll_interval": 0.05, **settings}
        env = dict(cli_env(), DRT_DATA_DIR=str(data_dir), **{f"DRT_{k.upper()}": str(v) for k, v in settings.items()})
        self.proc = subprocess.Popen([sys.executable, "-m", "service.cli", "serve", "--port", str(self.port),
                                      "--log-level", "warning"], env=env, stdout=self.log, stderr=self.log,
                                     start_new_session=True)
        deadline = time.monotonic() + 90
        while True:
            try:
                if httpx.get(f"{self.url}/healthz", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert self.proc.poll() is None, f"drt serve exited with {self.proc.returncode}: {log.read_text()}"
            assert time.monotonic() < deadline, "drt serve did not come up"
            time.sleep(0.2)
        self.http = httpx.Client(base_url=self.url, timeout=60)

    def family(self) -> list[psutil.Process]:
        p = psutil.Process(self.proc.pid)
        return [p, *p.children(recursive=True)]

    def kill(self) -> None:
        """SIGKILL the service and everything it started (as a crash of the machine's service would)."""
        self.http.close()
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait(timeout=30)
        self.log.close()

    def terminate(self) -> int:
        self.http.close()
        self.proc.send_signal(signal.SIGTERM)
        code = self.proc.wait(timeout=60)
        self.log.close()
        return code


def _become_subreaper() -> None:
    """Orphans of a killed server become our children (not PID 1's, which may never reap them)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER (Linux)
    except (OSError, AttributeError):
        pass


def _group(pgid: int) -> list[psutil.Process]:
    out = []
    for p in psutil.process_iter():
        try:
            if os.getpgid(p.pid) == pgid:
                out.append(p)
        except (ProcessLookupError, psutil.Error):
            pass
    return out


@pytest.fixture
def servers(tmp_path):
    _become_subreaper()
    started: list[Server] = []

    def start(**settings) -> Server:
        s = Server(tmp_path / "data", tmp_path / "serve.log", **settings)
        started.append(s)
        return s

    yield start
    for s in started:
        if s.proc.poll() is None:
            s.kill()
        deadline = time.monotonic() + 30
        while alive := [p for p in _group(s.proc.pid) if p.status() != psutil.STATUS_ZOMBIE]:
            assert time.monotonic() < deadline, f"left behind: {alive}"  # nothing of the server may survive it
            time.sleep(0.1)
        for p in _group(s.proc.pid):  # reap the dead
            try:
                os.waitpid(p.pid, 0)
            except ChildProcessError:
                pass


def drt(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "service.cli", *map(str, args)], capture_output=True, text=True,
                          env=cli_env(), timeout=300)


def test_drt_submit_status_fetch_against_drt_serve(servers, card, tmp_path):
    server = servers()
    flags = ["--width", 40, "--height", 30, "--spp", 4, "--seed", 5, "--aov", "depth", "--filter", "triangle"]
    r = drt("submit", card, *flags, "--tile", 16, "--server", server.url, "--wait", "-o", tmp_path / "svc.exr")
    assert r.returncode == 0, r.stderr
    job_id = r.stdout.splitlines()[0]
    assert r.stdout.splitlines()[1] == f"wrote {tmp_path / 'svc.exr'}"
    cli_render(card, tmp_path / "cli.exr", *flags)
    assert_same_exr(tmp_path / "svc.exr", tmp_path / "cli.exr")

    r = drt("status", job_id, "--server", server.url)
    assert r.returncode == 0 and r.stdout.startswith(f"{job_id} succeeded 100% frames 1/1 40x30 tiles 6/6"), r.stdout
    r = drt("fetch", job_id, "-o", tmp_path / "again.exr", "--server", server.url)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "again.exr").read_bytes() == (tmp_path / "svc.exr").read_bytes()

    r = drt("status", "nope", "--server", server.url)
    assert (r.returncode, r.stderr) == (1, "drt: error: 404: job not found\n")
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\ndef Xform "World"\n{\n    int x = [1,\n    what\n}\n')
    r = drt("submit", bad, "--server", server.url)
    assert r.returncode == 1
    assert r.stderr.startswith("drt: error: 422: malformed USD in bad.usda: syntax error at line 6"), r.stderr
    r = drt("submit", card, "--spp", 0, "--server", server.url)
    assert r.returncode == 2 and r.stderr.startswith("drt: error: argument --spp")

    workers = server.family()[1:]
    assert workers, "the LocalCluster runs worker processes"
    # SIGTERM: a clean shutdown (uvicorn re-raises the signal once the app has shut down)
    assert server.terminate() in (0, -signal.SIGTERM)
    gone, alive = psutil.wait_procs(workers, timeout=30)
    assert not alive


def test_http_contract_against_drt_serve(servers, card, tmp_path):
    http_contract(servers(**CONTRACT_LIMITS).http, card, tmp_path)


def test_a_killed_service_resumes_its_running_job(servers, card, tmp_path):
    server = servers()
    settings = {"width": 128, "height": 128, "spp": 256, "tile": 16}  # 64 tiles, a few seconds
    job_id = submit(server.http, card, settings).json()["id"]
    deadline = time.monotonic() + 120
    while (seen := server.http.get(f"/v1/jobs/{job_id}").json())["tiles_done"] < 8:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    assert seen["state"] == "running" and seen["tiles_done"] < seen["tiles_total"]
    server.kill()

    server = servers()  # the same data directory
    job = wait_job(server.http, job_id)
    assert job["state"] == "succeeded", job
    rendered_again = metric(server.http, "drt_tiles_completed_total")
    assert rendered_again <= job["tiles_total"] - seen["tiles_done"]  # checkpointed tiles were kept
    (tmp_path / "svc.exr").write_bytes(server.http.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "cli.exr", "--width", 128, "--height", 128, "--spp", 256)
    assert_same_exr(tmp_path / "svc.exr", tmp_path / "cli.exr")


def _coordinator(server: Server) -> psutil.Process:
    """The child process that runs the job scheduler and the Dask client (``service.farm.coordinator``)."""
    (proc,) = [p for p in psutil.Process(server.proc.pid).children()
               if any("spawn_main" in a for a in p.cmdline())]
    return proc


@pytest.mark.slow  # 15 s; the killed service, API process and worker process stay in the default run
def test_a_killed_coordinator_is_started_again_and_its_job_finishes_the_same(servers, card, tmp_path):
    """The scheduler's process dies mid-job: the API keeps answering, says the cluster is unreachable and refuses
    submissions with 503 until a new coordinator has resumed the job from its checkpoints; the old one's workers
    do not outlive it."""
    server = servers()
    settings = {"width": 128, "height": 128, "spp": 256, "tile": 16}  # 64 tiles, a few seconds
    job_id = submit(server.http, card, settings).json()["id"]
    deadline = time.monotonic() + 120
    while server.http.get(f"/v1/jobs/{job_id}").json()["tiles_done"] < 8:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    old = _coordinator(server)
    old_workers = old.children(recursive=True)
    old.kill()
    deadline = time.monotonic() + 10
    while (health := server.http.get("/healthz")).json()["cluster"] != "unreachable":
        assert time.monotonic() < deadline, "the API never noticed its coordinator died"
        time.sleep(0.02)
    assert health.status_code == 200 and health.elapsed.total_seconds() < 1
    r = submit(server.http, card, settings)
    assert (r.status_code, r.headers["retry-after"]) == (503, "5")
    job = wait_job(server.http, job_id)
    assert job["state"] == "succeeded", job
    assert _coordinator(server).pid != old.pid
    _, alive = psutil.wait_procs(old_workers, timeout=30)
    assert not alive, f"the dead coordinator's workers live on: {alive}"
    (tmp_path / "svc.exr").write_bytes(server.http.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "cli.exr", "--width", 128, "--height", 128, "--spp", 256)
    assert_same_exr(tmp_path / "svc.exr", tmp_path / "cli.exr")


def test_a_killed_api_process_takes_its_coordinator_and_workers_with_it(servers, card):
    """Never two schedulers on one database: the coordinator leaves when the API process dies, even by SIGKILL."""
    server = servers()
    job = wait_job(server.http, submit(server.http, card, {"width": 16, "height": 16, "spp": 1}).json()["id"])
    assert job["state"] == "succeeded"
    family = server.family()
    assert _coordinator(server) in family and len(_coordinator(server).children()) >= 1  # a LocalCluster worker
    server.http.close()
    os.kill(server.proc.pid, signal.SIGKILL)
    server.proc.wait(timeout=30)
    _, alive = psutil.wait_procs(family[1:], timeout=30)
    assert not alive, f"left behind by the killed API process: {alive}"


def test_a_killed_worker_process_still_yields_the_same_image(card, tmp_path):
    from fastapi.testclient import TestClient

    from service.app import create_app

    settings = service_settings(tmp_path / "data", processes=True, workers=1, threads_per_worker=2)
    with TestClient(create_app(settings)) as client:
        runtime = client.app.state.runtime
        job_id = submit(client, card, {"width": 64, "height": 64, "spp": 2048, "tile": 16}).json()["id"]
        deadline = time.monotonic() + 120
        while client.get(f"/v1/jobs/{job_id}").json()["tiles_done"] < 2:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        assert runtime.coordinator.dispatcher.in_flight() > 0  # tiles are running on the worker right now
        (pid,) = runtime.coordinator.cluster.worker_pids().values()
        os.kill(pid, signal.SIGKILL)
        job = wait_job(client, job_id, timeout=180)
        assert job["state"] == "succeeded", job
        (new_pid,) = runtime.coordinator.cluster.worker_pids().values()
        assert new_pid != pid  # the nanny started a new worker process
        (tmp_path / "svc.exr").write_bytes(client.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "cli.exr", "--width", 64, "--height", 64, "--spp", 2048)
    assert_same_exr(tmp_path / "svc.exr", tmp_path / "cli.exr")


def _cpu_seconds(procs: list[psutil.Process]) -> float:
    total = 0.0
    for p in procs:
        try:
            t = p.cpu_times()
            total += t.user + t.system
        except psutil.Error:
            pass
    return total


def test_abuse_against_drt_serve(servers, card, tmp_path):
    """With a token: a stranger's malformed body is 401, the maximal job is refused by `drt submit` naming the
    limit, and a running job deleted outright stops rendering in the worker processes (no shared flag file)."""
    server = servers(api_token="t0ken", threads_per_worker=2)
    r = httpx.post(f"{server.url}/v1/jobs", content=b"--x\r\nnot multipart",
                   headers={"content-type": "multipart/form-data"})
    assert (r.status_code, r.json(), r.headers["www-authenticate"]) == (
        401, {"detail": "missing or invalid bearer token"}, "Bearer")
    r = drt("submit", card, "--width", 16384, "--height", 16384, "--spp", 65536, "--max-depth", 64,
            "--server", server.url, "--token", "t0ken")
    assert (r.returncode, r.stderr) == (1, "drt: error: 422: a frame of 16384x16384 has 268435456 pixels; the limit "
                                           "is 16777216 pixels per frame\n")

    auth = {"Authorization": "Bearer t0ken"}
    settings = {"width": 64, "height": 64, "spp": 65536, "tile": 32}  # 67M samples a tile: minutes each
    with open(card, "rb") as f:
        job = server.http.post("/v1/jobs", files={"scene": ("card.usda", f)}, data={"settings": json.dumps(settings)},
                               headers=auth).json()
    workers = server.family()[1:]
    deadline = time.monotonic() + 120
    while server.http.get(job["url"], headers=auth).json()["state"] != "running":
        assert time.monotonic() < deadline
        time.sleep(0.1)
    while True:  # rendering (after loading the scene): the workers are busy, as busy as a shared machine lets them
        cpu0 = _cpu_seconds(workers)
        time.sleep(1.0)
        before = _cpu_seconds(workers) - cpu0
        if before > 0.3:
            break
        assert time.monotonic() < deadline, "the job never kept the workers busy"
    assert server.http.delete(job["url"], headers=auth).status_code == 204
    time.sleep(2.0)  # a tile asks whether to stop every 0.25 s, between sample waves of a fraction of a second
    cpu0, t0 = _cpu_seconds(workers), time.monotonic()
    time.sleep(2.0)
    busy = (_cpu_seconds(workers) - cpu0) / (time.monotonic() - t0)
    # idle workers still heartbeat and collect garbage: 0.155 cores once on the loaded 2-core machine; one tile
    # still rendering would be 0.5 or more
    assert busy < min(0.25, before / 3), f"{busy:.2f} cores busy in the workers after the delete, {before:.2f} before"
    assert server.http.get(job["url"], headers=auth).status_code == 404
    assert not (tmp_path / "data" / "jobs" / job["id"]).exists()
