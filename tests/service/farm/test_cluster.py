"""Scale-out with real processes: ``dask scheduler``, two ``dask worker``s that cannot see the service's data
directory, and ``drt serve --scheduler``. Jobs render identical to ``drt render``; a worker SIGKILLed mid-job; the
scheduler killed and restarted mid-job (for 60 s, then three times in a row) with no restart of ``drt serve``.
"""
from __future__ import annotations

import re
import time
from pathlib import Path

import pytest
from distributed import Client

from service.farm import tasks

from cluster_helpers import CAN_HIDE, Scheduler, Server, SupervisedWorker, free_port, service_files
from service_helpers import assert_same_exr, cli_render, metric, submit, wait_job


class Cluster:
    def __init__(self, tmp: Path):
        self.tmp = tmp
        self.data = tmp / "data"
        self.data.mkdir()
        self.scheduler = Scheduler(free_port(), tmp / "scheduler.log")
        self.scheduler.wait_up()
        self.workers = [SupervisedWorker(self.scheduler.address, tmp / f"w{i}", self.data, tmp / f"worker{i}.log")
                        for i in range(2)]
        self.server: Server | None = None

    def serve(self, **settings) -> Server:
        self.server = Server(self.data, self.tmp / "serve.log", self.scheduler.address, **settings)
        self.server.wait_health("reachable", workers=len(self.workers))
        return self.server

    def restart_scheduler(self) -> None:
        self.scheduler = Scheduler(self.scheduler.port, self.tmp / "scheduler.log")
        self.scheduler.wait_up()

    def worker_stats(self) -> list[dict]:
        with Client(self.scheduler.address, timeout=30, set_as_default=False) as c:
            return list(c.run(tasks.stats).values())

    def close(self) -> None:
        if self.server is not None:
            self.server.http.close()
            self.server.terminate()
        for w in self.workers:
            w.stop()
        self.scheduler.kill()


@pytest.fixture
def cluster(tmp_path):
    c = Cluster(tmp_path)
    yield c
    c.close()


def check_isolation(cluster: Cluster, job_ids: list[str]) -> None:
    """The workers got the scene through Dask and wrote only into their own directories; the data directory holds
    nothing but what the service writes (database, scenes, frames' products)."""
    views = [w.hidden_view() for w in cluster.workers]
    if CAN_HIDE:  # what the workers see at the data directory's path: the empty tmpfs of their own namespace
        assert views == [[]] * len(cluster.workers), f"a worker saw or wrote something there: {views}"
    stats = cluster.worker_stats()
    assert stats and all(Path(s["cwd"]) in [w.workdir for w in cluster.workers] for s in stats)
    for s in stats:
        if s["scene_dir"]:  # the scene arrived as bytes and went to the worker's own temporary directory
            assert Path(s["scene_dir"]).parent in [w.workdir for w in cluster.workers]
            assert not Path(s["scene_dir"]).is_relative_to(cluster.data)
    allowed = re.compile(r"(drt\.sqlite3(-wal|-shm)?|scenes/[0-9a-f]{64}/[\w.-]+|jobs/(" + "|".join(job_ids)
                         + r")/frames/\d+/[\w.-]+\.exr)$")  # a frame's products
    stray = [f for f in service_files(cluster.data) if not allowed.match(f)]
    assert not stray, f"files in the data directory the service did not write: {stray}"


def test_workers_without_the_data_directory_render_identical_and_outages_answer_fast(cluster, card, tmp_path):
    """The default run's representative: isolated workers, a multi-tile job equal to `drt render`, the 24-frame
    rule (one stage per worker), then the scheduler killed: /healthz answers at once and says so, a submission
    is 503; the scheduler back (workers restarted by their supervisor): the next job renders identical too."""
    server = cluster.serve()
    flags = ["--width", 64, "--height", 48, "--spp", 16, "--seed", 3]
    settings = {"width": 64, "height": 48, "spp": 16, "seed": 3, "tile": 16, "frames": [0, 1, 2]}  # 12 tiles/frame
    r = submit(server.http, card, settings)
    assert r.status_code == 202, r.text
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\ndef Xform "World"\n{\n    int x = [1,\n    what\n}\n')
    t0 = time.perf_counter()  # while the tiles run: a bad scene is refused by a local process, not a worker
    refused = submit(server.http, bad, settings)
    assert time.perf_counter() - t0 < 3.0
    assert refused.status_code == 422 and refused.json()["detail"].startswith(
        "malformed USD in bad.usda: syntax error at line 6"), refused.text
    job = wait_job(server.http, r.json()["id"], timeout=180)
    assert job["state"] == "succeeded", job
    (tmp_path / "svc.exr").write_bytes(server.http.get(job["frames"][1]["exr_url"]).content)
    cli_render(card, tmp_path / "cli.exr", *flags, "--frame", 1)
    assert_same_exr(tmp_path / "svc.exr", tmp_path / "cli.exr")
    stats = cluster.worker_stats()
    assert sum(s["tiles"] for s in stats) == 36
    assert all(s["stages"] <= 1 and s["packages"] <= 1 for s in stats), stats  # once per worker, not per frame
    check_isolation(cluster, [job["id"]])

    cluster.scheduler.kill()
    deadline = time.monotonic() + 30
    while (h := server.health())[0]["cluster"] != "unreachable":
        assert h[1] < 0.5 and time.monotonic() < deadline
        time.sleep(0.1)
    assert h[0] == {"status": "degraded", "cluster": "unreachable", "workers": 0, "threads": 0}
    for _ in range(5):
        h, seconds = server.health()
        assert seconds < 0.5 and h["cluster"] == "unreachable"
    r = submit(server.http, card, settings)
    assert (r.status_code, r.json(), r.headers.get("retry-after")) == (
        503, {"detail": "the render cluster is unavailable"}, "5")

    cluster.restart_scheduler()
    server.wait_health("reachable", workers=2)
    job2 = wait_job(server.http, submit(server.http, card, {**settings, "frames": [1]}).json()["id"], timeout=180)
    assert job2["state"] == "succeeded", job2
    (tmp_path / "svc2.exr").write_bytes(server.http.get(job2["frames"][0]["exr_url"]).content)
    assert_same_exr(tmp_path / "svc2.exr", tmp_path / "cli.exr")
    assert metric(server.http, "drt_task_failures_total") == 0
    check_isolation(cluster, [job["id"], job2["id"]])


SLOW_JOB = {"width": 160, "height": 120, "spp": 1024, "tile": 16}  # 80 tiles, tens of seconds on two threads
SLOW_FLAGS = ["--width", 160, "--height", 120, "--spp", 1024]


def wait_tiles(server: Server, job_id: str, at_least: int, timeout: float = 300) -> dict:
    deadline = time.monotonic() + timeout
    while (job := server.http.get(f"/v1/jobs/{job_id}").json())["tiles_done"] < at_least:
        assert job["state"] in ("queued", "running"), job
        assert time.monotonic() < deadline, job
        time.sleep(0.05)
    return job


@pytest.mark.slow
def test_a_worker_sigkilled_mid_job_still_gives_the_same_image(cluster, card, tmp_path):
    server = cluster.serve()
    job_id = submit(server.http, card, SLOW_JOB).json()["id"]
    seen = wait_tiles(server, job_id, 6)
    assert seen["state"] == "running" and seen["tiles_done"] < seen["tiles_total"]
    cluster.workers[0].kill()  # the worker and its nanny: a machine lost for good
    job = wait_job(server.http, job_id, timeout=600)
    assert job["state"] == "succeeded", job
    (tmp_path / "svc.exr").write_bytes(server.http.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "cli.exr", *SLOW_FLAGS)
    assert_same_exr(tmp_path / "svc.exr", tmp_path / "cli.exr")
    cluster.workers = cluster.workers[1:]
    check_isolation(cluster, [job_id])


@pytest.mark.slow
def test_the_scheduler_down_for_a_minute_then_restarted_three_times_mid_job(cluster, card, tmp_path):
    server = cluster.serve(scheduler_timeout=10)  # the client gives up after 10 s: a new one must be made
    serve_pid = server.pid
    job_id = submit(server.http, card, SLOW_JOB).json()["id"]
    done = wait_tiles(server, job_id, 4)["tiles_done"]

    cluster.scheduler.kill()
    t_down = time.monotonic()
    server.wait_health("unreachable", timeout=30)
    while time.monotonic() - t_down < 60:  # a minute without a scheduler
        h, seconds = server.health()
        assert seconds < 0.5 and h["cluster"] == "unreachable", (h, seconds)
        r = submit(server.http, card, SLOW_JOB)
        assert (r.status_code, r.json()) == (503, {"detail": "the render cluster is unavailable"})
        assert server.http.get(f"/v1/jobs/{job_id}").json()["state"] == "running"
        time.sleep(5)
    cluster.restart_scheduler()
    server.wait_health("reachable", workers=2)

    for _ in range(3):  # and again, three times in a row, each as soon as the job has moved on
        done = wait_tiles(server, job_id, done + 3)["tiles_done"]
        cluster.scheduler.kill()
        server.wait_health("unreachable", timeout=30)
        time.sleep(2)
        cluster.restart_scheduler()
        server.wait_health("reachable", workers=1)

    job = wait_job(server.http, job_id, timeout=600)
    assert job["state"] == "succeeded" and job["error"] is None, job
    assert server.alive() and server.pid == serve_pid  # never restarted
    assert metric(server.http, "drt_task_failures_total") == 0  # lost tasks were resubmitted, not charged
    assert metric(server.http, "drt_tasks_lost_total") > 0
    (tmp_path / "svc.exr").write_bytes(server.http.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "cli.exr", *SLOW_FLAGS)
    assert_same_exr(tmp_path / "svc.exr", tmp_path / "cli.exr")
    check_isolation(cluster, [job_id])
