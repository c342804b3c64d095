"""Abuse: a job's cost against the farm's limits, the token checked before the body, delete means stop."""
from __future__ import annotations

import re
import sqlite3
import time

from fastapi.testclient import TestClient

from service.farm import tasks

from service_helpers import submit, wait_job

MAXIMAL = {"width": 16384, "height": 16384, "spp": 65536, "max_depth": 64}  # the schema's own maxima


def test_the_maximal_job_is_refused_naming_the_limit(client, card, tmp_path):
    limits = client.get("/v1/limits").json()
    assert limits == {"max_upload_bytes": 256 * 2**20, "max_samples_per_job": 2_000_000_000,
                      "max_pixels_per_frame": 4096 * 4096, "max_frames": 10_000, "max_tiles": 200_000,
                      "max_queued_jobs": 200, "max_queued_jobs_per_client": 50}
    t0 = time.monotonic()
    r = submit(client, card, MAXIMAL)
    assert (r.status_code, r.json()) == (422, {"detail": "a frame of 16384x16384 has 268435456 pixels; the limit is "
                                                         "16777216 pixels per frame"})
    r = submit(client, card, {**MAXIMAL, "width": 4096, "height": 4096})
    assert (r.status_code, r.json()) == (422, {"detail": "the job needs 1099511627776 samples (4096x4096 pixels x "
                                                         "65536 spp x 1 frame); the limit is 2000000000 samples per "
                                                         "job"})
    r = submit(client, card, {"width": 64, "height": 64, "spp": 4096, "frames": {"start": 1, "end": 200}})
    assert (r.status_code, r.json()) == (422, {"detail": "the job needs 3355443200 samples (64x64 pixels x 4096 spp x "
                                                         "200 frames); the limit is 2000000000 samples per job"})
    assert time.monotonic() - t0 < 5.0  # refused from the settings alone, no scene loaded
    assert client.get("/v1/jobs").json() == {"items": [], "next_cursor": None}
    assert list((tmp_path / "data" / "scenes").glob("*/*")) == []  # nothing of the refused uploads is kept


def test_limits_are_settings_and_a_job_within_them_renders(make_client, card):
    """Exactly at the limit is allowed, one sample more is not; the resolution the scene gives counts too."""
    client = make_client(max_samples_per_job=24 * 16 * 2 * 2, max_pixels_per_frame=24 * 16, max_frames=2)
    job = wait_job(client, submit(client, card, {"width": 24, "height": 16, "spp": 2, "tile": 8,
                                                 "frames": [0, 1]}).json()["id"])
    assert (job["state"], job["tiles_done"]) == ("succeeded", 12)
    r = submit(client, card, {"width": 24, "height": 16, "spp": 3, "frames": [0, 1]})
    assert (r.status_code, r.json()) == (422, {"detail": "the job needs 2304 samples (24x16 pixels x 3 spp x 2 "
                                                         "frames); the limit is 1536 samples per job"})
    r = submit(client, card, {"width": 24, "height": 16, "frames": [0, 1, 2]})
    assert (r.status_code, r.json()) == (422, {"detail": "too many frames: 3 (the limit is 2)"})
    r = submit(client, card, {"width": 40, "spp": 1})  # height from the camera's aspect: known after loading
    assert r.status_code == 422
    assert re.fullmatch(r"a frame of 40x\d+ has \d+ pixels; the limit is 384 pixels per frame", r.json()["detail"])
    assert client.get("/v1/limits").json()["max_samples_per_job"] == 1536


def test_queue_limits_per_client_and_in_total(make_client, card):
    client = make_client(threads_per_worker=1, max_in_flight=1, max_queued_jobs=2, max_queued_jobs_per_client=1)
    slow = {"width": 64, "height": 64, "spp": 1024, "tile": 8}
    first = submit(client, card, slow).json()["id"]
    r = submit(client, card, slow)
    assert (r.status_code, r.json()) == (422, {"detail": "this client has 1 jobs queued or running; the limit is 1 "
                                                         "jobs per client"})
    other = TestClient(client.app, client=("10.0.0.2", 50000))  # another address: another client
    second = submit(other, card, slow)
    assert second.status_code == 202, second.text
    third = TestClient(client.app, client=("10.0.0.3", 50000))
    r = submit(third, card, slow)
    assert (r.status_code, r.json()) == (422, {"detail": "the queue is full: 2 jobs queued or running; the limit is "
                                                         "2 jobs"})
    assert client.delete(f"/v1/jobs/{first}").status_code == 204  # a finished (here: deleted) job frees its place
    assert submit(third, card, {"width": 8, "height": 8, "spp": 1}).status_code == 202
    assert client.delete(f"/v1/jobs/{second.json()['id']}").status_code == 204


def test_an_unauthenticated_request_is_refused_before_its_body_is_read(make_client):
    client = make_client(api_token="s3cret", max_upload_bytes=1000)
    for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": "Basic s3cret"}):
        r = client.post("/v1/jobs", content=b"--x\r\nnot multipart", headers={**headers,
                                                                              "content-type": "multipart/form-data"})
        assert (r.status_code, r.json()) == (401, {"detail": "missing or invalid bearer token"})
        assert r.headers["www-authenticate"] == "Bearer"
        # an oversized body: 401, not 413 (the size is not looked at for a stranger either)
        r = client.post("/v1/jobs", content=b"x" * (2 << 20), headers=headers)
        assert (r.status_code, r.headers["www-authenticate"]) == (401, "Bearer")
    auth = {"Authorization": "Bearer s3cret"}
    r = client.post("/v1/jobs", content=b"--x\r\nnot multipart",
                    headers={**auth, "content-type": "multipart/form-data"})
    assert (r.status_code, r.json()) == (400, {"detail": "malformed request body: Missing boundary in multipart."})
    r = client.post("/v1/jobs", content=b"x" * (2 << 20), headers=auth)
    assert (r.status_code, r.json()) == (413, {"detail": "upload exceeds the limit of 1000 bytes"})
    assert client.get("/healthz").status_code == 200
    for url in ("/v1/limits", "/metrics", "/v1/nowhere"):
        assert client.get(url).status_code == 401, url


def test_cursors_out_of_range_are_422(client):
    import base64

    for text in (f"seq:{2**63}", f"seq:{2**64 + 5}", "seq:" + "9" * 40, "seq:\u00b2", "seq:-1", "seq:"):
        cursor = base64.urlsafe_b64encode(text.encode()).decode().rstrip("=")
        r = client.get("/v1/jobs", params={"cursor": cursor})
        assert (r.status_code, r.json()) == (422, {"detail": "invalid cursor"}), text
    cursor = base64.urlsafe_b64encode(f"seq:{2**63 - 1}".encode()).decode().rstrip("=")
    assert client.get("/v1/jobs", params={"cursor": cursor}).json() == {"items": [], "next_cursor": None}
    r = client.get("/v1/jobs", params={"cursor": "A" * 65})
    assert (r.status_code, r.json()) == (422, {"detail": "cursor: String should have at most 64 characters"})


def _running_tiles(client) -> int:
    return sum(s["running"] for s in client.app.state.runtime.coordinator.cluster.client.run(tasks.stats).values())


def _nothing_left(data, job_id: str) -> None:
    assert not (data / "jobs" / job_id).exists()
    with sqlite3.connect(data / "drt.sqlite3") as db:
        for table, column in (("jobs", "id"), ("frames", "job_id"), ("tiles", "job_id"), ("idempotency", "job_id")):
            assert db.execute(f"SELECT COUNT(*) FROM {table} WHERE {column} = ?", (job_id,)).fetchone() == (0,)


def test_deleting_a_job_stops_its_running_tiles(make_client, card, tmp_path):
    """Canceled then deleted, or deleted while running: within seconds no tile of it renders, nothing is left."""
    client = make_client(threads_per_worker=2)
    long_tiles = {"width": 64, "height": 64, "spp": 65536, "tile": 32}  # 67M samples a tile: minutes each
    for cancel_first in (True, False):
        job_id = submit(client, card, long_tiles, headers={"Idempotency-Key": f"k{cancel_first}"}).json()["id"]
        wait_job(client, job_id, until=("running",))
        deadline = time.monotonic() + 30
        while _running_tiles(client) < 2:  # both threads busy rendering its tiles
            assert time.monotonic() < deadline
            time.sleep(0.05)
        if cancel_first:
            assert client.post(f"/v1/jobs/{job_id}/cancel").json()["state"] == "canceled"
        t0 = time.monotonic()
        assert client.delete(f"/v1/jobs/{job_id}").status_code == 204
        while _running_tiles(client):
            assert time.monotonic() - t0 < 3.0, "tiles of a deleted job still render"
            time.sleep(0.05)
        time.sleep(0.5)
        cpu0, wall0 = time.process_time(), time.monotonic()  # the workers are threads of this process
        time.sleep(1.5)
        busy = (time.process_time() - cpu0) / (time.monotonic() - wall0)
        assert busy < 0.3, f"{busy:.2f} cores still busy after the delete"
        _nothing_left(tmp_path / "data", job_id)
        assert client.get(f"/v1/jobs/{job_id}").status_code == 404
