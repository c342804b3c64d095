"""What the job monitor reads and does, over real HTTP: retry, server-sent events, tile maps, the farm, the static
shell and its headers, the token, and ``drt cancel/retry/delete``."""
from __future__ import annotations

import contextlib
import json
import re
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from urllib.parse import urljoin

import httpx
import pytest

from schemas import JobState
from service.queue import states as sm
from service.queue.store import Store

from live_server import LiveServer
from service_helpers import assert_same_exr, cli_env, cli_render, metric, submit, wait_job

SMALL = {"width": 24, "height": 16, "spp": 2, "tile": 8}
SLOW = {"width": 64, "height": 64, "spp": 1024, "tile": 8}  # 64 tiles, seconds on one thread


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    s = LiveServer(tmp_path_factory.mktemp("monitor-api") / "data", threads_per_worker=1)
    yield s
    s.stop()


@pytest.fixture(scope="module")
def token_server(tmp_path_factory):
    s = LiveServer(tmp_path_factory.mktemp("monitor-token") / "data", threads_per_worker=1, api_token="s3cret")
    yield s
    s.stop()


class EventReader:
    """Reads a text/event-stream in a thread; ``events`` is the list of (name, data) received so far."""

    def __init__(self, url: str, headers: dict | None = None):
        self.events: list[tuple[str, object]] = []
        self.status: int | None = None
        self.ended = threading.Event()
        self._client = httpx.Client(timeout=httpx.Timeout(60, read=None), headers=headers or {})
        self.thread = threading.Thread(target=self._run, args=(url,), daemon=True)
        self.thread.start()

    def _run(self, url: str) -> None:
        try:
            with self._client.stream("GET", url) as r:
                self.status = r.status_code
                self.content_type = r.headers.get("content-type")
                name, data = "message", []
                for line in r.iter_lines():
                    if line == "":
                        if data:
                            self.events.append((name, json.loads("\n".join(data))))
                        name, data = "message", []
                    elif line.startswith("event:"):
                        name = line[6:].strip()
                    elif line.startswith("data:"):
                        data.append(line[5:].strip())
        except httpx.HTTPError:
            pass
        finally:
            self.ended.set()

    def wait_for(self, pred, timeout: float = 60.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for e in list(self.events):
                if pred(e):
                    return e
            time.sleep(0.02)
        raise AssertionError(f"no such event within {timeout} s; got {[n for n, _ in self.events]}")

    def close(self) -> None:
        self._client.close()


# -- retry ------------------------------------------------------------------------------------------------------

def test_the_state_machine_allows_a_retry_of_failed_and_canceled_jobs_only(tmp_path):
    assert sm.TRANSITIONS[JobState.failed] == {JobState.queued} == sm.TRANSITIONS[JobState.canceled]
    assert sm.sources(JobState.queued) == {JobState.failed, JobState.canceled}
    assert sm.TERMINAL == {JobState.succeeded, JobState.failed, JobState.canceled}
    store = Store(tmp_path / "db.sqlite3")
    try:
        store.create_job(job_id="a", priority=0, settings_json="{}", scene_sha256="s" * 64, scene_name="x.usda",
                         scene_bytes=1, width=4, height=4, tile_size=2, tiles_per_frame=4, frame_times=[0.0],
                         exposure_scale=1.0, warnings=[])
        store.transition("a", JobState.running)
        assert store.tile_done("a", 0, 0, samples=16, seconds=0.1)
        assert store.tile_attempt("a", 0, 1, error="boom") == 1
        store.transition("a", JobState.failed, error="tile 1 failed")
        with pytest.raises(sm.IllegalTransition):
            store.transition("a", JobState.running)
        row = store.transition("a", JobState.queued)
        assert (row.state, row.error, row.started_at, row.finished_at, row.samples_done) == ("queued", None, None,
                                                                                             None, 0)
        assert row.tiles_done == 1 and store.done_tiles("a") == {0: {0}}  # the checkpointed tile is kept
        assert store.tile_attempt("a", 0, 1) == 1  # the failed attempt was forgotten: the tile has its retries
        store.transition("a", JobState.running)
        store.transition("a", JobState.succeeded)
        with pytest.raises(sm.IllegalTransition):
            store.transition("a", JobState.queued)
    finally:
        store.close()


def test_a_write_answers_with_the_row_it_wrote_not_a_later_one(tmp_path):
    """The coordinator (another process) may start a queued job the moment the submission or retry commits; the
    answer must still be the row as written (a retried job read back after the commit was seen "running", with a
    start time, in a retry's 200)."""
    store = Store(tmp_path / "db.sqlite3")
    other = sqlite3.connect(tmp_path / "db.sqlite3", isolation_level=None)
    tx = store._tx

    @contextlib.contextmanager
    def then_started(*a, **kw):  # another writer claims the job right after each commit
        with tx(*a, **kw) as c:
            yield c
        other.execute("UPDATE jobs SET state = 'running', started_at = 1.0 WHERE state = 'queued'")

    store._tx = then_started
    try:
        row = store.create_job(job_id="a", priority=0, settings_json="{}", scene_sha256="s" * 64,
                               scene_name="x.usda", scene_bytes=1, width=4, height=4, tile_size=2,
                               tiles_per_frame=4, frame_times=[0.0], exposure_scale=1.0, warnings=[])
        assert (row.state, row.started_at, len(row.frames)) == ("queued", None, 1)
        assert store.get_job("a").state == "running"  # the other writer did run
        store.transition("a", JobState.canceled)
        row = store.transition("a", JobState.queued)
        assert (row.state, row.started_at) == ("queued", None)
        assert store.get_job("a").state == "running"
    finally:
        other.close()
        store.close()


def test_a_canceled_job_retried_resumes_and_equals_drt_render(server, card, tmp_path):
    settings = {"width": 32, "height": 32, "spp": 1024, "tile": 8}  # 16 tiles
    job_id = submit(server.http, card, settings).json()["id"]
    deadline = time.monotonic() + 120
    while server.http.get(f"/v1/jobs/{job_id}").json()["tiles_done"] < 3:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    r = server.http.post(f"/v1/jobs/{job_id}/retry")
    assert (r.status_code, r.json()) == (409, {"detail": "cannot retry a running job; only failed or canceled jobs "
                                                         "can be retried"})
    canceled = server.http.post(f"/v1/jobs/{job_id}/cancel").json()
    assert canceled["state"] == "canceled" and canceled["tiles_done"] >= 3
    r = server.http.post(f"/v1/jobs/{job_id}/retry")
    assert r.status_code == 200, r.text
    job = r.json()
    assert (job["state"], job["error"], job["started_at"], job["finished_at"]) == ("queued", None, None, None)
    assert job["tiles_done"] >= canceled["tiles_done"]  # what was checkpointed stays done
    job = wait_job(server.http, job_id)
    assert job["state"] == "succeeded" and job["tiles_done"] == job["tiles_total"] == 16
    (tmp_path / "svc.exr").write_bytes(server.http.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "cli.exr", "--width", 32, "--height", 32, "--spp", 1024)
    assert_same_exr(tmp_path / "svc.exr", tmp_path / "cli.exr")
    r = server.http.post(f"/v1/jobs/{job_id}/retry")
    assert (r.status_code, r.json()["detail"]) == (409, "cannot retry a succeeded job; only failed or canceled jobs "
                                                        "can be retried")
    r = server.http.post("/v1/jobs/0123456789abcdef/retry")
    assert (r.status_code, r.json()) == (404, {"detail": "job not found"})


_failures = {"left": 0}


def failing_tile(task, scene):
    from service.farm import tasks

    if any(box[:2] == (0, 0) for box in task.tiles) and _failures["left"] > 0:
        _failures["left"] -= 1
        raise RuntimeError("worker fell over")
    return tasks.render_tile_task(task, scene)


def test_a_failed_job_retried_gets_fresh_attempts(server, card, monkeypatch):
    import service.farm.dispatcher

    monkeypatch.setattr(service.farm.dispatcher, "render_tile_task", failing_tile)
    _failures["left"] = 3  # the default 2 retries: 3 failures fail the job
    job = wait_job(server.http, submit(server.http, card, SMALL).json()["id"])
    assert (job["state"], job["error"]) == ("failed", "tile 0 of frame 0 failed after 3 attempts: RuntimeError: "
                                                      "worker fell over")
    _failures["left"] = 2  # fails twice more: with the old attempts counted, that would fail it again at once
    assert server.http.post(f"/v1/jobs/{job['id']}/retry").json()["state"] == "queued"
    job = wait_job(server.http, job["id"])
    assert (job["state"], job["error"], _failures["left"]) == ("succeeded", None, 0)


# -- server-sent events -----------------------------------------------------------------------------------------

def test_events_stream_a_job_from_queued_to_deleted(server, card):
    everything = EventReader(f"{server.url}/v1/events")
    everything.wait_for(lambda e: e[0] == "ready", timeout=10)
    assert everything.status == 200 and everything.content_type.startswith("text/event-stream")
    job_id = submit(server.http, card, {"width": 48, "height": 48, "spp": 512, "tile": 8}).json()["id"]
    one = EventReader(f"{server.url}/v1/jobs/{job_id}/events")
    first = one.wait_for(lambda e: True, timeout=10)
    assert first[0] == "job" and first[1]["id"] == job_id  # the one-job stream starts with the job as it is
    everything.wait_for(lambda e: e[0] == "job" and e[1]["id"] == job_id and e[1]["state"] == "succeeded")
    one.wait_for(lambda e: e[0] == "job" and e[1]["state"] == "succeeded")
    mine = [d for n, d in everything.events if n == "job" and d["id"] == job_id]
    states = [d["state"] for d in mine]
    assert states == sorted(states, key=["queued", "running", "succeeded"].index)  # never backwards
    assert "running" in states
    progress = [d["progress"] for d in mine]
    assert progress == sorted(progress) and any(0 < p < 1 for p in progress)  # moving, a tile burst at a time
    assert len(mine) < 36  # coalesced: fewer events than the job has tiles
    assert server.http.delete(f"/v1/jobs/{job_id}").status_code == 204
    assert everything.wait_for(lambda e: e[0] == "deleted")[1] == {"id": job_id}
    assert one.ended.wait(10)  # the one-job stream ends with the job
    assert one.events[-1] == ("deleted", {"id": job_id})
    everything.close()
    r = server.http.get("/v1/jobs/0123456789abcdef/events")
    assert (r.status_code, r.json()) == (404, {"detail": "job not found"})


def test_a_stopping_service_ends_its_event_streams(tmp_path):
    s = LiveServer(tmp_path / "data")
    reader = EventReader(f"{s.url}/v1/events")
    reader.wait_for(lambda e: e[0] == "ready", timeout=10)
    t0 = time.monotonic()
    s.stop()
    assert reader.ended.wait(10) and time.monotonic() - t0 < 4.0  # not the 5 s graceful-shutdown timeout
    reader.close()


# -- tiles and farm -----------------------------------------------------------------------------------------------

def test_tile_map_and_farm_show_the_tiles_workers_hold(server, card):
    check_tile_map_and_farm(server, card)


def test_tile_map_and_farm_from_a_coordinator_process(tmp_path, card):
    """The same answers when the job scheduler and the Dask client run in ``drt serve``'s child process."""
    s = LiveServer(tmp_path / "data", threads_per_worker=1, scheduler_process=True)
    try:
        assert s.http.get("/healthz").json() == {"status": "ok", "cluster": "reachable", "workers": 1, "threads": 1}
        check_tile_map_and_farm(s, card)
        deadline = time.monotonic() + 5  # the counters reach the API four times a second
        while metric(s.http, "drt_tiles_completed_total") < 6:  # the small job's tiles at least
            assert time.monotonic() < deadline
            time.sleep(0.05)
    finally:
        s.stop()


def check_tile_map_and_farm(server, card):
    job_id = submit(server.http, card, SLOW).json()["id"]
    deadline = time.monotonic() + 60
    while True:
        tiles = server.http.get(f"/v1/jobs/{job_id}/tiles").json()
        farm = server.http.get("/v1/farm").json()
        held = [t for w in farm["workers"] for t in w["tasks"] if t["job_id"] == job_id]
        if tiles["frames"][0]["rendering"] and held:
            break
        assert time.monotonic() < deadline, (tiles, farm)
        time.sleep(0.05)
    assert (tiles["width"], tiles["height"], tiles["tile_size"], tiles["columns"], tiles["rows"]) == (64, 64, 8, 8, 8)
    assert set(tiles["frames"][0]["rendering"]).isdisjoint(tiles["frames"][0]["done"])
    assert all(0 <= i < 64 for i in tiles["frames"][0]["rendering"])
    assert [w["nthreads"] for w in farm["workers"]] == [1]
    assert (held[0]["kind"], held[0]["frame_index"], held[0]["frame"]) == ("tile", 0, 0.0)
    assert 0 <= held[0]["tile"] < 64
    assert farm["tiles_in_flight"] >= 1 and farm["dashboard_url"] is None
    server.http.post(f"/v1/jobs/{job_id}/cancel")
    job_id = wait_job(server.http, submit(server.http, card, SMALL).json()["id"])["id"]
    tiles = server.http.get(f"/v1/jobs/{job_id}/tiles").json()
    assert tiles["frames"] == [{"frame": 0.0, "done": list(range(6)), "rendering": []}]
    r = server.http.get("/v1/jobs/0123456789abcdef/tiles")
    assert (r.status_code, r.json()) == (404, {"detail": "job not found"})


def test_farm_links_the_configured_dashboard(tmp_path):
    from service.settings import ServiceSettings

    assert ServiceSettings(dashboard_url="").dashboard_url is None  # `DRT_DASHBOARD_URL=` means unset
    s = LiveServer(tmp_path / "data", dashboard_url="https://dask.example/status")
    try:
        assert s.http.get("/v1/farm").json()["dashboard_url"] == "https://dask.example/status"
    finally:
        s.stop()


# -- the static shell and the token ------------------------------------------------------------------------------

def test_the_shell_is_static_with_a_strict_csp(server):
    from service.api import web

    for path in ("/", "/jobs/anything", "/farm"):
        r = server.http.get(path)
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
        csp = r.headers["content-security-policy"]
        assert "script-src 'self'" in csp and "default-src 'none'" in csp and "unsafe-inline" not in csp
        assert r.headers["x-content-type-options"] == "nosniff"
        assert '<script type="module" src="/ui/app.js"></script>' in r.text and "<script>" not in r.text
    for name in web.MODULES:
        js = server.http.get(f"/ui/{name}")
        assert js.status_code == 200 and js.headers["content-type"].startswith("text/javascript"), name
        assert ".innerHTML" not in js.text and "insertAdjacentHTML" not in js.text and "eval(" not in js.text, name
    assert server.http.get("/ui/style.css").headers["content-type"].startswith("text/css")
    for bad in ("/ui/index.html", "/ui/..%2Fapp.py", "/ui/nope.js"):
        assert server.http.get(bad).status_code == 404, bad


# An import or re-export of a module by its specifier: `import {a} from "./x.js"`, `export * from "./x.js"`,
# `import "./x.js"`, `import("./x.js")`.
IMPORTS = re.compile(r"""^\s*(?:import|export)\s[^;'"]*?\sfrom\s*["']([^"']+)["']"""
                     r"""|^\s*import\s*["']([^"']+)["']|\bimport\(\s*["']([^"']+)["']\s*\)""", re.M)
MAX_LINES = 450


def test_the_page_loads_modules_that_are_all_served_as_javascript_and_short(server):
    # The browser follows the entry point's imports from /ui/: each must be served, as JavaScript (a module of any
    # other type is refused), and every module served must be one the page loads.
    from service.api import web

    shell = server.http.get("/").text
    entries = re.findall(r'<script type="module" src="(/ui/[^"]+)"></script>', shell)
    assert entries == ["/ui/app.js"] and len(re.findall(r"<script", shell)) == 1
    loaded, todo = {}, list(entries)
    while todo:
        url = todo.pop()
        if url in loaded:
            continue
        r = server.http.get(url)
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/javascript"), (url, r.status_code)
        loaded[url] = r.text
        for specifier in (next(filter(None, m)) for m in IMPORTS.findall(r.text)):
            todo.append(urljoin(url, specifier))
    assert len(loaded) >= 6, sorted(loaded)  # the API client, the stream, the three views...
    served = {f"/ui/{name}" for name, kind in web.FILES.items() if kind.startswith("text/javascript")}
    assert set(loaded) == served, "a module is served but no page imports it"
    assert {f"/ui/{p.name}" for p in web.STATIC_DIR.glob("*.js")} == served, "a module in static/ is not served"
    for url, text in loaded.items():
        assert len(text.splitlines()) <= MAX_LINES, (url, len(text.splitlines()))
        assert text.startswith("// "), f"{url} does not start with a comment saying what it does"
    for name in ("index.html", "style.css"):
        assert len((web.STATIC_DIR / name).read_text().splitlines()) <= MAX_LINES, name


def test_with_a_token_only_the_shell_and_healthz_are_open(token_server):
    from service.api import web

    shell = [r.path for r in web.router.routes]
    api = [p for p, ops in token_server.app.openapi()["paths"].items() if "get" in ops]  # every documented GET
    anon = httpx.Client(base_url=token_server.url, timeout=30)
    try:
        checked = 0
        for template in shell + api + ["/docs", "/openapi.json"]:
            path = (template.replace("{job_id}", "0123456789abcdef").replace("{frame}", "0")
                    .replace("{name}", "app.js"))
            public = template in shell
            assert web.is_public(path) == public, path  # what an authentication layer in front consults
            r = anon.get(path)
            if public or path == "/healthz":
                assert r.status_code == 200, path
            else:
                assert (r.status_code, r.json()) == (401, {"detail": "missing or invalid bearer token"}), path
            checked += 1
        assert checked >= 12
        assert anon.post("/v1/jobs/x/retry").status_code == 401
    finally:
        anon.close()
    reader = EventReader(f"{token_server.url}/v1/events", headers={"Authorization": "Bearer s3cret"})
    reader.wait_for(lambda e: e[0] == "ready", timeout=10)
    assert reader.status == 200
    reader.close()


# -- the CLI ------------------------------------------------------------------------------------------------------

def drt(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "service.cli", *map(str, args)], capture_output=True, text=True,
                          env=cli_env(), timeout=120)


def test_drt_cancel_retry_delete(server, card):
    job_id = submit(server.http, card, SLOW).json()["id"]
    r = drt("cancel", job_id, "--server", server.url)
    assert r.returncode == 0 and r.stdout.startswith(f"{job_id} canceled "), (r.stdout, r.stderr)
    r = drt("cancel", job_id, "--server", server.url)
    assert (r.returncode, r.stderr) == (1, "drt: error: 409: cannot cancel a canceled job\n")
    r = drt("delete", job_id, "--server", server.url)
    assert (r.returncode, r.stdout) == (0, f"deleted {job_id}\n"), r.stderr
    r = drt("retry", job_id, "--server", server.url)
    assert (r.returncode, r.stderr) == (1, "drt: error: 404: job not found\n")

    job_id = submit(server.http, card, SLOW).json()["id"]  # delete means stop: an active job is canceled first
    r = drt("delete", job_id, "--server", server.url)
    assert (r.returncode, r.stdout) == (0, f"deleted {job_id}\n"), r.stderr
    assert server.http.get(f"/v1/jobs/{job_id}").status_code == 404

    job_id = submit(server.http, card, SLOW).json()["id"]
    assert drt("cancel", job_id, "--server", server.url).returncode == 0
    r = drt("retry", job_id, "--server", server.url)
    assert r.returncode == 0 and r.stdout.startswith(f"{job_id} queued "), (r.stdout, r.stderr)
    server.http.post(f"/v1/jobs/{job_id}/cancel")


def test_drt_serve_stops_promptly_with_a_monitor_open(tmp_path):
    """SIGTERM with an event stream open: ``drt serve`` ends the stream instead of waiting out uvicorn's 10 s
    graceful-shutdown timeout for it."""
    from test_serve import Server

    s = Server(tmp_path / "data", tmp_path / "serve.log", processes="false")
    reader = EventReader(f"{s.url}/v1/events")
    try:
        reader.wait_for(lambda e: e[0] == "ready", timeout=20)
        t0 = time.monotonic()
        assert s.terminate() in (0, -signal.SIGTERM)  # uvicorn re-raises the signal once it has stopped
        assert time.monotonic() - t0 < 6.0, (tmp_path / "serve.log").read_text()
        assert reader.ended.wait(5)
    finally:
        reader.close()
        if s.proc.poll() is None:
            s.kill()
