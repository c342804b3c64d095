"""Helpers shared by the service tests: tiny scenes, job polling, reference renders, EXR comparison."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import stages
from renderer.film.exr import read_exr


def write_card(path: Path, *, fstop: float = 2.0, extra: str | None = None) -> Path:
    """A grey card 3 m in front of a camera with depth of field, lit by a distant light (renders in ms)."""
    stage = stages.new_stage(path)
    stages.camera(stage, fstop=fstop, focus=2.0, tenths_per_mm=0.01)
    stages.rect_xy(stage, "/World/Card", -0.5, 0.5, -0.4, 0.4, -3.0, stages.material(stage, "W", (0.8, 0.6, 0.4)))
    stages.distant_light(stage, rotate_x=-20.0)
    stage.Save()
    if extra:
        text = path.read_text()
        path.write_text(text + "\n" + extra + "\n")
    return path



def service_settings(data_dir: Path, **overrides):
    from service.settings import ServiceSettings

    # The coordinator as threads of the test's process: tests patch the worker functions it submits.
    base = dict(data_dir=data_dir, processes=False, scheduler_process=False, workers=1, threads_per_worker=2,
                poll_interval=0.05, inspect_timeout=60, inspect_processes=1)
    base.update(overrides)
    return ServiceSettings(**base)


def submit(client, scene: Path, settings: dict | None = None, headers: dict | None = None, name: str | None = None):
    with open(scene, "rb") as f:
        return client.post("/v1/jobs", files={"scene": (name or scene.name, f, "application/octet-stream")},
                           data={"settings": json.dumps(settings or {})}, headers=headers or {})


def wait_job(client, job_id: str, timeout: float = 300.0, until=("succeeded", "failed", "canceled")) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job["state"] in until:
            return job
        if time.monotonic() > deadline:
            raise AssertionError(f"job {job_id} still {job['state']} after {timeout} s: {job}")
        time.sleep(0.05)


def metric(http, name: str) -> float:
    """One value of the service's ``/metrics`` (Prometheus text), read through ``http`` (a client of the service)."""
    text = http.get("/metrics").text
    return float(re.search(rf"^{name} (\S+)$", text, re.M).group(1))


def cli_env() -> dict:
    """The environment for a subprocess that must import this checkout (and its renderer) first."""
    return dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))


def cli_render(scene: Path, out: Path, *flags) -> None:
    """``drt render`` in a subprocess: the reference every service result must equal."""
    r = subprocess.run([sys.executable, "-m", "service.cli", "render", str(scene), "-o", str(out), "--quiet",
                        *map(str, flags)], capture_output=True, text=True, env=cli_env(), timeout=300)
    assert r.returncode == 0, r.stderr


def assert_same_exr(a: Path, b: Path) -> None:
    ca, ha = read_exr(a)
    cb, hb = read_exr(b)
    assert set(ca) == set(cb)
    for k in ca:
        assert np.array_equal(ca[k], cb[k]), k
    assert {k: str(v) for k, v in ha.items()} == {k: str(v) for k, v in hb.items()}
    assert Path(a).read_bytes() == Path(b).read_bytes()


CONTRACT_LIMITS = {"threads_per_worker": 1, "max_in_flight": 1, "max_upload_bytes": 100_000}


def http_contract(client, card: Path, tmp_path: Path) -> None:
    """The API's contract in one scenario, run through FastAPI's test client and against a real `drt serve`
    (started with CONTRACT_LIMITS): priorities, cancel, idempotency, and 404/409/413/422 with their details."""
    small = {"width": 16, "height": 16, "spp": 2, "tile": 8}
    slow = {"width": 64, "height": 64, "spp": 512, "tile": 8}  # a few seconds: long enough to be overtaken
    first = submit(client, card, slow, headers={"Idempotency-Key": "contract-1"})
    assert first.status_code == 202, first.text
    first_id = first.json()["id"]
    again = submit(client, card, slow, headers={"Idempotency-Key": "contract-1"})
    assert (again.status_code, again.json()["id"]) == (202, first_id)
    r = submit(client, card, small, headers={"Idempotency-Key": "contract-1"})
    assert (r.status_code, r.json()) == (422, {"detail": "Idempotency-Key was already used with a different request"})
    wait_job(client, first_id, until=("running",))
    low = submit(client, card, small).json()["id"]
    doomed = submit(client, card, small).json()["id"]
    high = submit(client, card, {**small, "priority": 5}).json()["id"]
    r = client.post(f"/v1/jobs/{doomed}/cancel")
    assert (r.status_code, r.json()["state"]) == (200, "canceled")
    r = client.post(f"/v1/jobs/{doomed}/cancel")
    assert (r.status_code, r.json()) == (409, {"detail": "cannot cancel a canceled job"})
    assert client.get("/v1/limits").json()["max_upload_bytes"] == 100_000
    r = client.get(f"/v1/jobs/{first_id}/frames/0.exr")
    assert (r.status_code, r.json()) == (409, {"detail": "frame is not rendered yet"})
    jobs = {name: wait_job(client, i) for name, i in (("first", first_id), ("low", low), ("high", high))}
    assert {j["state"] for j in jobs.values()} == {"succeeded"}
    assert jobs["high"]["finished_at"] < jobs["first"]["finished_at"] <= jobs["low"]["started_at"]
    assert client.get(f"/v1/jobs/{doomed}").json()["started_at"] is None  # canceled while queued: never ran

    r = client.get("/v1/jobs/0123456789abcdef")
    assert (r.status_code, r.json()) == (404, {"detail": "job not found"})
    r = client.get(f"/v1/jobs/{first_id}/frames/3.5.exr")
    assert (r.status_code, r.json()) == (404, {"detail": "frame not found"})
    big = tmp_path / "big.usda"
    big.write_bytes(card.read_bytes() + b"\n#" + b"x" * 200_000 + b"\n")
    r = submit(client, big, small)
    assert (r.status_code, r.json()) == (413, {"detail": "upload exceeds the limit of 100000 bytes"})
    r = submit(client, card, {**small, "spp": 0})
    assert (r.status_code, r.json()) == (422, {"detail": "invalid settings: spp: Input should be greater than or "
                                                         "equal to 1"})
    r = submit(client, card, {**small, "camera": "/World/Nope"})
    assert (r.status_code, r.json()) == (422, {"detail": "camera prim not found: /World/Nope"})
    r = client.get(jobs["high"]["frames"][0]["exr_url"])
    assert r.status_code == 200 and r.content[:4] == b"\x76\x2f\x31\x01"  # the OpenEXR magic number
