"""The HTTP API through FastAPI's test client, on an in-process Dask cluster (one worker, threads)."""
from __future__ import annotations

import io
import threading
import time

import numpy as np
import pytest
from PIL import Image

from renderer.film.exr import read_exr
from renderer.film.tiles import Tile
from service.farm import tasks
from service.intake import inspection
from service.api.deps import get_settings, get_store
from service.queue.store import Store, StoreBusy

from service_helpers import (CONTRACT_LIMITS, assert_same_exr, cli_render, http_contract, service_settings, submit,
                             wait_job, write_card)

SMALL = {"width": 24, "height": 16, "spp": 2, "tile": 8}
SLOW = {"width": 64, "height": 64, "spp": 1024, "tile": 8}  # 64 tiles, a few seconds on one thread


def test_submit_poll_download_equals_drt_render(client, card, tmp_path):
    settings = {"width": 40, "height": 30, "spp": 4, "seed": 7, "tile": 16, "aovs": ["depth", "normal"],
                "filter": "box", "shutter": [-0.25, 0.25], "max_depth": 3, "clamp": 50.0}
    r = submit(client, card, settings)
    assert r.status_code == 202, r.text
    job = r.json()
    assert r.headers["location"] == f"/v1/jobs/{job['id']}" == job["url"]
    assert job["state"] in ("queued", "running", "succeeded") and job["settings"]["spp"] == 4
    job = wait_job(client, job["id"])
    assert job["state"] == "succeeded", job
    assert job["progress"] == 1.0 and job["tiles_done"] == job["tiles_total"] == 6
    assert job["samples_per_second"] > 0 and job["error"] is None
    assert job["scene"]["filename"] == "card.usda" and len(job["scene"]["sha256"]) == 64
    frame = job["frames"][0]
    assert (frame["frame"], frame["state"], frame["progress"]) == (0.0, "done", 1.0)
    r = client.get(frame["exr_url"])
    assert r.status_code == 200 and r.headers["content-type"] == "image/x-exr"
    (tmp_path / "service.exr").write_bytes(r.content)
    cli_render(card, tmp_path / "cli.exr", "--width", 40, "--height", 30, "--spp", 4, "--seed", 7, "--tile", 64,
               "--aov", "depth", "--aov", "normal", "--filter", "box", "--shutter", -0.25, 0.25, "--max-depth", 3,
               "--clamp", 50)
    assert_same_exr(tmp_path / "service.exr", tmp_path / "cli.exr")

    r = client.get(frame["preview_url"])
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    img = Image.open(io.BytesIO(r.content))
    assert img.size == (40, 30) and img.mode == "RGB"
    assert np.asarray(img)[15, 20].max() > 0 and np.asarray(img)[0, 0].max() == 0  # the card, the black sky


def test_frames_half_and_camera_overrides(client, card, tmp_path):
    from renderer.render import prepare, render_frame, write_frame
    from service.spec import RenderSpec
    from schemas import JobCreate

    settings = {**SMALL, "frames": {"start": 0, "end": 2, "step": 2}, "f_stop": 0, "focal_length": 0.7,
                "half": True}
    job = wait_job(client, submit(client, card, settings).json()["id"])
    assert job["state"] == "succeeded", job
    assert [f["frame"] for f in job["frames"]] == [0.0, 2.0]
    assert [f["exr_url"].rsplit("/", 1)[1] for f in job["frames"]] == ["0.exr", "2.exr"]
    spec = RenderSpec.from_settings(JobCreate(**settings), str(card), "-")
    for f in job["frames"]:
        (tmp_path / "got.exr").write_bytes(client.get(f["exr_url"]).content)
        prep = prepare(spec.load(f["frame"]), spec.options())  # the library path `drt render` takes
        write_frame(tmp_path / "want.exr", prep, render_frame(prep, tile_size=64, threads=1).sums, half=True)
        assert_same_exr(tmp_path / "got.exr", tmp_path / "want.exr")
        channels, header = read_exr(tmp_path / "got.exr")
        assert header["channels"]["R"] == "HALF" and header["drt/frame"] == f["frame"]
        assert header["drt/depthOfField"] == 0  # f_stop 0: a pinhole


def test_list_jobs_by_state_with_cursor(client, card):
    ids = [submit(client, card, {**SMALL, "seed": i}).json()["id"] for i in range(3)]
    for i in ids:
        wait_job(client, i)
    page = client.get("/v1/jobs", params={"limit": 2}).json()
    assert [j["id"] for j in page["items"]] == ids[::-1][:2] and page["next_cursor"]
    page2 = client.get("/v1/jobs", params={"limit": 2, "cursor": page["next_cursor"]}).json()
    assert [j["id"] for j in page2["items"]] == [ids[0]] and page2["next_cursor"] is None
    assert len(client.get("/v1/jobs", params={"state": "succeeded"}).json()["items"]) == 3
    assert client.get("/v1/jobs", params={"state": "running"}).json() == {"items": [], "next_cursor": None}
    r = client.get("/v1/jobs", params={"cursor": "garbage"})
    assert (r.status_code, r.json()) == (422, {"detail": "invalid cursor"})
    r = client.get("/v1/jobs", params={"state": "lost"})
    assert r.status_code == 422
    assert r.json()["detail"] == "state: Input should be 'queued', 'running', 'succeeded', 'failed' or 'canceled'"
    r = client.get("/v1/jobs", params={"limit": 0})
    assert r.json()["detail"] == "limit: Input should be greater than or equal to 1"


def test_cancel_delete_and_their_conflicts(make_client, card, tmp_path):
    client = make_client(threads_per_worker=1, max_in_flight=1)
    slow = submit(client, card, SLOW).json()["id"]
    wait_job(client, slow, until=("running",))
    queued = submit(client, card, {**SMALL, "seed": 1}).json()["id"]
    assert client.get(f"/v1/jobs/{queued}").json()["state"] == "queued"

    r = client.get(f"/v1/jobs/{slow}/frames/0.exr")
    assert (r.status_code, r.json()) == (409, {"detail": "frame is not rendered yet"})
    assert client.get(f"/v1/jobs/{slow}/frames/0/preview.png").status_code == 200  # while rendering, too
    r = client.get(f"/v1/jobs/{slow}/frames/7.exr")
    assert (r.status_code, r.json()) == (404, {"detail": "frame not found"})

    r = client.post(f"/v1/jobs/{queued}/cancel")
    assert r.status_code == 200 and r.json()["state"] == "canceled" and r.json()["started_at"] is None
    r = client.post(f"/v1/jobs/{slow}/cancel")
    assert r.status_code == 200 and r.json()["state"] == "canceled"
    time.sleep(0.5)  # the tile that was running may still land; nothing after it
    done = client.get(f"/v1/jobs/{slow}").json()["tiles_done"]
    time.sleep(0.5)
    job = client.get(f"/v1/jobs/{slow}").json()
    assert job["tiles_done"] == done < job["tiles_total"]
    r = client.post(f"/v1/jobs/{slow}/cancel")
    assert (r.status_code, r.json()) == (409, {"detail": "cannot cancel a canceled job"})

    assert client.delete(f"/v1/jobs/{slow}").status_code == 204
    assert not (tmp_path / "data" / "jobs" / slow).exists()
    for method, url in [("GET", f"/v1/jobs/{slow}"), ("POST", f"/v1/jobs/{slow}/cancel"),
                        ("DELETE", f"/v1/jobs/{slow}"), ("GET", f"/v1/jobs/{slow}/frames/0.exr"),
                        ("GET", f"/v1/jobs/{slow}/frames/0/preview.png")]:
        r = client.request(method, url)
        assert (r.status_code, r.json()) == (404, {"detail": "job not found"}), url
    assert client.delete(f"/v1/jobs/{queued}").status_code == 204
    assert list((tmp_path / "data" / "scenes").glob("*/card.usda")) == []  # no job uses the scene any more

    done = wait_job(client, submit(client, card, SMALL).json()["id"])
    r = client.post(f"/v1/jobs/{done['id']}/cancel")
    assert (r.status_code, r.json()) == (409, {"detail": "cannot cancel a succeeded job"})


def test_priority_then_fifo(make_client, card):
    client = make_client(threads_per_worker=1, max_in_flight=1)
    first = submit(client, card, {**SLOW, "spp": 512}).json()["id"]  # long enough to be overtaken
    wait_job(client, first, until=("running",))
    low = submit(client, card, {**SMALL, "priority": 0}).json()["id"]
    high = submit(client, card, {**SMALL, "priority": 10}).json()["id"]
    jobs = {k: wait_job(client, i) for k, i in (("first", first), ("low", low), ("high", high))}
    assert all(j["state"] == "succeeded" for j in jobs.values())
    # The high-priority job overtook the running one at the next tile and the queued one entirely.
    assert jobs["high"]["finished_at"] < jobs["first"]["finished_at"]
    assert jobs["high"]["finished_at"] <= jobs["low"]["started_at"]
    assert jobs["first"]["finished_at"] <= jobs["low"]["started_at"]  # equal priorities: first in, first out


def test_idempotency_key(client, card):
    h = {"Idempotency-Key": "build-1234"}
    a = submit(client, card, SMALL, headers=h)
    b = submit(client, card, SMALL, headers=h)
    assert a.status_code == b.status_code == 202
    assert a.json()["id"] == b.json()["id"] and b.headers["location"] == a.headers["location"]
    assert len(client.get("/v1/jobs").json()["items"]) == 1
    r = submit(client, card, {**SMALL, "spp": 3}, headers=h)
    assert (r.status_code, r.json()) == (422, {"detail": "Idempotency-Key was already used with a different request"})
    c = submit(client, card, SMALL, headers={"Idempotency-Key": "build-1235"})
    assert c.json()["id"] != a.json()["id"]
    bad = submit(client, card, {"spp": 0}, headers={"Idempotency-Key": "k2"})
    assert bad.status_code == 422
    # a failed try is forgotten: the key is free again
    assert submit(client, card, SMALL, headers={"Idempotency-Key": "k2"}).status_code == 202
    wait_job(client, a.json()["id"])
    assert client.delete(a.json()["url"]).status_code == 204
    again = submit(client, card, SMALL, headers=h)
    assert again.status_code == 202 and again.json()["id"] != a.json()["id"]  # the key went with its job


def test_upload_too_large(make_client, card, tmp_path):
    client = make_client(max_upload_bytes=1000)
    big = write_card(tmp_path / "big.usda", extra="#" + "x" * 2000)
    r = submit(client, big, SMALL)
    assert (r.status_code, r.json()) == (413, {"detail": "upload exceeds the limit of 1000 bytes"})
    huge = tmp_path / "huge.usda"
    huge.write_bytes(b"#usda 1.0\n" + b"#" * (2 << 20))  # over the limit plus the multipart allowance
    r = submit(client, huge, SMALL)
    assert (r.status_code, r.json()) == (413, {"detail": "upload exceeds the limit of 1000 bytes"})
    assert list((tmp_path / "data" / "scenes" / ".incoming").iterdir()) == []
    assert client.get("/healthz").status_code == 200


BAD_USDA = '#usda 1.0\ndef Xform "World"\n{\n    int x = [1,\n    what\n}\n'


@pytest.mark.parametrize("name, text, settings, limits, detail", [
    ("card.usda", None, {"spp": 0}, {}, "invalid settings: spp: Input should be greater than or equal to 1"),
    ("card.usda", None, {"tile": 8, "seed": "x"}, {}, "invalid settings: seed: Input should be a valid integer, "
                                                      "unable to parse string as an integer"),
    ("card.txt", None, {}, {}, "scene must be a .usda, .usdc, .usd or .usdz file"),
    ("bad.usda", BAD_USDA, {}, {}, "malformed USD in bad.usda: syntax error at line 6 (column 1): "
                                   "parse error matching ListValueClose at '}' in </World.x>"),
    ("empty.usda", "", {}, {}, "malformed USD in empty.usda: <empty.usda> is not a valid usda layer"),
    ("card.usda", None, {"camera": "/World/NoSuchCam"}, {}, "camera prim not found: /World/NoSuchCam"),
    ("card.usda", None, {"camera": "/World/Card"}, {}, "prim is not a Camera: /World/Card (type Mesh)"),
    ("abs.usda", '#usda 1.0\ndef Xform "W" (\n    references = @/etc/hosts@\n)\n{\n}\n', {}, {},
     "asset path is absolute: /etc/hosts"),
    ("up.usda", '#usda 1.0\n(\n    subLayers = [@../../drt.sqlite3@]\n)\n', {}, {},
     "asset path escapes the upload: ../../drt.sqlite3"),
    ("tex.usda", '#usda 1.0\ndef Shader "T"\n{\n    asset inputs:file = @wood.png@\n}\n', {}, {},
     "asset not found in the upload: wood.png"),
    ("ref.usda", '#usda 1.0\ndef Xform "W" (\n    references = </Nope>\n)\n{\n}\n', {}, {},
     "scene has 1 composition error(s): Unresolved reference prim path @ref.usda@</Nope> introduced by "
     "@ref.usda@</W>"),
    ("card.usda", None, {"width": 64, "height": 64, "tile": 1}, {"max_tiles": 1000},
     "the job has 4096 tiles; the limit is 1000 (use a larger tile size or fewer frames)"),
    ("card.usda", None, {"frames": [1, 2, 3]}, {"max_frames": 2}, "too many frames: 3 (the limit is 2)"),
])
def test_invalid_input_is_422_naming_the_problem(make_client, card, tmp_path, name, text, settings, limits, detail):
    client = make_client(**limits)
    path = card if text is None else tmp_path / name
    if text is not None:
        path.write_text(text)
    r = submit(client, path, settings, name=name)
    assert (r.status_code, r.json()) == (422, {"detail": detail})
    assert client.get("/v1/jobs").json()["items"] == []
    ok = wait_job(client, submit(client, card, SMALL).json()["id"])  # and the service carries on
    assert ok["state"] == "succeeded"


def test_usdz_upload_renders_and_bad_usdz_is_422(client, card, tmp_path):
    import zipfile

    from pxr import Sdf

    w = Sdf.ZipFileWriter.CreateNew(str(tmp_path / "card.usdz"))
    w.AddFile(str(card), "card.usda")
    w.Save()
    job = wait_job(client, submit(client, tmp_path / "card.usdz", SMALL).json()["id"])
    assert job["state"] == "succeeded" and job["scene"]["filename"] == "card.usdz"
    with zipfile.ZipFile(tmp_path / "evil.usdz", "w") as z:
        z.writestr(zipfile.ZipInfo("../evil.usda"), "#usda 1.0\n")
    r = submit(client, tmp_path / "evil.usdz", SMALL)
    assert (r.status_code, r.json()) == (422, {"detail": ".usdz entry escapes the package: ../evil.usda"})


def test_missing_form_fields(client):
    r = client.post("/v1/jobs", data={"settings": "{}"})
    assert (r.status_code, r.json()) == (422, {"detail": "scene: Field required"})


def test_bearer_token(make_client, card):
    client = make_client(api_token="s3cret")
    assert client.get("/healthz").status_code == 200
    for url in ["/v1/jobs", "/metrics", "/docs", "/openapi.json", "/v1/jobs/x"]:
        r = client.get(url)
        assert (r.status_code, r.json()) == (401, {"detail": "missing or invalid bearer token"}), url
        assert r.headers["www-authenticate"] == "Bearer"
        assert client.get(url, headers={"Authorization": "Bearer wrong"}).status_code == 401
    auth = {"Authorization": "Bearer s3cret"}
    assert client.get("/v1/jobs", headers=auth).status_code == 200
    assert client.get("/openapi.json", headers=auth).json()["paths"]["/v1/jobs"]
    assert submit(client, card, SMALL, headers=auth).status_code == 202


def test_token_through_dependency_override(client, tmp_path):
    """Tests swap parts of the app with dependency_overrides: here the settings the auth check reads."""
    client.app.dependency_overrides[get_settings] = lambda: service_settings(tmp_path, api_token="t")
    try:
        assert client.get("/v1/jobs").status_code == 401
        assert client.get("/v1/jobs", headers={"Authorization": "Bearer t"}).status_code == 200
    finally:
        client.app.dependency_overrides.clear()
    assert client.get("/v1/jobs").status_code == 200


def test_status_of_a_locked_database_is_read_on_the_thread_pool(client, card):
    """The status route reads on the event loop without waiting; when the database refuses that read (locked by
    another process), the same answer comes from a read on the thread pool, which may wait."""
    job = wait_job(client, submit(client, card, SMALL).json()["id"])
    store = client.app.state.runtime.store
    reads = []

    class Locked:
        def get_job(self, job_id, wait=True):
            reads.append((wait, threading.get_ident()))
            if not wait:
                raise StoreBusy(job_id)
            return store.get_job(job_id)

    client.app.dependency_overrides[get_store] = lambda: Locked()
    try:
        r = client.get(f"/v1/jobs/{job['id']}")
        missing = client.get("/v1/jobs/nope")
    finally:
        client.app.dependency_overrides.clear()
    assert r.status_code == 200 and r.json() == job
    assert missing.status_code == 404 and missing.json() == {"detail": "job not found"}
    assert [w for w, _ in reads] == [False, True, False, True]
    assert reads[0][1] != reads[1][1]  # the waiting read ran on another thread than the one that refused


def test_the_inspection_processes_are_ready_when_the_service_starts(client):
    """Every submission of a burst at a new service waited for the processes' imports (~2 s) before; they are
    done while the cluster starts."""
    pool = client.app.state.runtime.inspector
    assert pool._all and all(p.ready for p in pool._all)


def test_health_metrics_and_docs(client, card):
    assert client.get("/healthz").json() == {"status": "ok", "cluster": "reachable", "workers": 1, "threads": 2}
    job = wait_job(client, submit(client, card, SMALL).json()["id"])
    r = client.get("/metrics")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
    text = r.text
    assert 'drt_jobs{state="succeeded"} 1' in text and 'drt_jobs{state="queued"} 0' in text
    assert f"drt_tiles_completed_total {job['tiles_total']}" in text
    assert "drt_queue_depth 0" in text and "drt_tiles_per_second" in text
    assert client.get("/docs").status_code == 200
    paths = client.get("/openapi.json").json()["paths"]
    assert {"/v1/jobs", "/v1/jobs/{job_id}", "/v1/jobs/{job_id}/cancel", "/v1/jobs/{job_id}/frames/{frame}.exr",
            "/v1/jobs/{job_id}/frames/{frame}/preview.png", "/healthz", "/metrics"} <= set(paths)
    product = paths["/v1/jobs/{job_id}/frames/{frame}/products/{name}"]["get"]
    assert "relative path" in product["description"] and {"200", "404", "409", "422"} <= set(product["responses"])


def test_each_frame_is_prepared_once_per_worker(client, card):
    tasks.clear_cache()
    before = tasks.stats()["prepared"]
    settings = {"width": 32, "height": 32, "spp": 2, "tile": 8, "frames": [0, 1]}  # 16 tiles per frame
    job = wait_job(client, submit(client, card, settings).json()["id"])
    assert job["state"] == "succeeded" and job["tiles_total"] == 32
    assert tasks.stats()["prepared"] - before == 2


def test_jobs_that_sample_differently_share_a_prepared_scene_and_each_equals_drt_render(client, card, tmp_path):
    """The worker's cache is keyed by what shapes the prepared scene, not by seed, spp, filters or AOVs (the load
    test's jobs differ only in seed: each was loaded and prepared anew). Each job still renders as its own."""
    tasks.clear_cache()
    before = tasks.stats()["prepared"]
    first = {"width": 24, "height": 16, "spp": 4, "seed": 1}
    second = {"width": 24, "height": 16, "spp": 8, "seed": 2, "filter": "box", "aovs": ["depth"], "max_depth": 2}
    for i, settings in enumerate((first, second)):
        job = wait_job(client, submit(client, card, settings).json()["id"])
        assert job["state"] == "succeeded", job
        (tmp_path / f"svc{i}.exr").write_bytes(client.get(job["frames"][0]["exr_url"]).content)
    assert tasks.stats()["prepared"] - before == 1
    cli_render(card, tmp_path / "cli0.exr", "--width", 24, "--height", 16, "--spp", 4, "--seed", 1)
    cli_render(card, tmp_path / "cli1.exr", "--width", 24, "--height", 16, "--spp", 8, "--seed", 2, "--filter", "box",
               "--aov", "depth", "--max-depth", 2)
    assert_same_exr(tmp_path / "svc0.exr", tmp_path / "cli0.exr")
    assert_same_exr(tmp_path / "svc1.exr", tmp_path / "cli1.exr")
    job = wait_job(client, submit(client, card, {**first, "width": 16}).json()["id"])  # a new resolution
    assert job["state"] == "succeeded" and tasks.stats()["prepared"] - before == 2


# -- failures inside the cluster -----------------------------------------------------------------------------------

_calls: dict = {}


def flaky_tile(task, scene):
    """Tile 0 fails on its first attempt (a transient fault), the rest render normally."""
    if any(box[:2] == (0, 0) for box in task.tiles) and not _calls.get("failed"):
        _calls["failed"] = True
        raise RuntimeError("transient")
    return tasks.render_tile_task(task, scene)


def broken_tile(task, scene):
    if any(box[:2] == (0, 0) for box in task.tiles):
        raise RuntimeError("boom")
    return tasks.render_tile_task(task, scene)


def renderer_says_no(task, scene):
    return {"error": "frame 0 has no light"}


def test_a_failed_tile_is_retried(make_client, card, monkeypatch, tmp_path):
    import service.farm.dispatcher

    _calls.clear()
    monkeypatch.setattr(service.farm.dispatcher, "render_tile_task", flaky_tile)
    client = make_client()
    job = wait_job(client, submit(client, card, SMALL).json()["id"])
    assert job["state"] == "succeeded", job
    assert "drt_task_failures_total 1" in client.get("/metrics").text
    (tmp_path / "got.exr").write_bytes(client.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "want.exr", "--width", 24, "--height", 16, "--spp", 2)
    assert_same_exr(tmp_path / "got.exr", tmp_path / "want.exr")


def test_a_tile_that_keeps_failing_fails_the_job(make_client, card, monkeypatch):
    import service.farm.dispatcher

    monkeypatch.setattr(service.farm.dispatcher, "render_tile_task", broken_tile)
    client = make_client(tile_retries=2)
    job = wait_job(client, submit(client, card, SMALL).json()["id"])
    assert job["state"] == "failed"
    assert job["error"] == "tile 0 of frame 0 failed after 3 attempts: RuntimeError: boom"
    assert job["finished_at"] is not None
    r = client.post(f"/v1/jobs/{job['id']}/cancel")
    assert (r.status_code, r.json()) == (409, {"detail": "cannot cancel a failed job"})


def test_a_renderer_error_fails_the_job_at_once(make_client, card, monkeypatch):
    import service.farm.dispatcher

    monkeypatch.setattr(service.farm.dispatcher, "render_tile_task", renderer_says_no)
    client = make_client()
    job = wait_job(client, submit(client, card, SMALL).json()["id"])
    assert (job["state"], job["error"]) == ("failed", "frame 0 has no light")
    assert "drt_task_failures_total 0" in client.get("/metrics").text  # not retried: it would say the same


def stopped_job(tmp_path, job_id: str):
    """The job as a stopped service left it in the database (a restarted one resumes it before any request)."""
    store = Store(tmp_path / "data" / "drt.sqlite3")
    try:
        return store.get_job(job_id)
    finally:
        store.close()


def test_a_stopped_service_resumes_from_its_checkpoints(make_client, card, tmp_path):
    client = make_client(threads_per_worker=1, max_in_flight=1)
    settings = {**SLOW, "spp": 128}
    job_id = submit(client, card, settings).json()["id"]
    deadline = time.monotonic() + 60
    while client.get(f"/v1/jobs/{job_id}").json()["tiles_done"] < 10:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    make_client.stop(client)  # the service stops mid-job
    stopped = stopped_job(tmp_path, job_id)
    assert stopped.state == "running" and 10 <= stopped.tiles_done < stopped.tiles_total
    done_before = stopped.tiles_done
    client2 = make_client(threads_per_worker=2)  # it resumes the job at once, maybe before its first request
    job = wait_job(client2, job_id)
    assert job["state"] == "succeeded"
    rendered_after = client2.app.state.runtime.coordinator.dispatcher.tiles_completed
    assert rendered_after == job["tiles_total"] - done_before  # checkpointed tiles were not rendered again
    (tmp_path / "got.exr").write_bytes(client2.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "want.exr", "--width", 64, "--height", 64, "--spp", 128)
    assert_same_exr(tmp_path / "got.exr", tmp_path / "want.exr")


def test_an_unreadable_checkpoint_is_rendered_again(make_client, card, tmp_path):
    client = make_client(threads_per_worker=1, max_in_flight=1)
    settings = {**SLOW, "spp": 64}
    job_id = submit(client, card, settings).json()["id"]
    deadline = time.monotonic() + 60
    while client.get(f"/v1/jobs/{job_id}").json()["tiles_done"] < 6:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    make_client.stop(client)
    tiles = sorted((tmp_path / "data" / "jobs" / job_id / "tiles" / "0").glob("*.npz"))
    assert tiles
    tiles[0].write_bytes(b"not a checkpoint")  # exists, so the resumed plan trusts it until it is read
    with np.load(tiles[1]) as z:  # the layout before border partials: readable, but cannot be assembled
        np.savez(tiles[1], **{k: z[k] for k in z.files if not k.startswith("band.")})
    done_before = stopped_job(tmp_path, job_id).tiles_done
    client2 = make_client(threads_per_worker=2)
    job = wait_job(client2, job_id)
    assert job["state"] == "succeeded" and job["error"] is None, job
    assert client2.app.state.runtime.coordinator.dispatcher.tiles_completed == job["tiles_total"] - done_before + 2
    assert "drt_task_failures_total 0" in client2.get("/metrics").text
    (tmp_path / "got.exr").write_bytes(client2.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "want.exr", "--width", 64, "--height", 64, "--spp", 64)
    assert_same_exr(tmp_path / "got.exr", tmp_path / "want.exr")


def slow_inspection(task):
    time.sleep(3)
    return inspection.inspect_task(task)


def test_a_scene_that_loads_too_long_is_422_and_the_service_carries_on(make_client, card, monkeypatch):
    monkeypatch.setattr(inspection, "inspect_task", slow_inspection)  # the pool's processes run this one
    client = make_client(inspect_timeout=0.5)
    r = submit(client, card, SMALL)
    assert (r.status_code, r.json()) == (422, {"detail": "the scene took longer than 0.5 s to load"})
    monkeypatch.undo()
    assert wait_job(client, submit(client, card, SMALL).json()["id"])["state"] == "succeeded"


def test_http_contract(make_client, card, tmp_path):
    http_contract(make_client(**CONTRACT_LIMITS), card, tmp_path)


def test_a_running_tile_stops_when_its_future_is_cancelled(card):
    """Dask cannot interrupt a task: the tile looks between sample waves whether Dask released it (no file)."""
    import hashlib

    from distributed import Client, LocalCluster

    from schemas import JobCreate
    from service.spec import RenderSpec

    data = card.read_bytes()
    sha = hashlib.sha256(data).hexdigest()
    spec = RenderSpec.from_settings(JobCreate(width=64, height=64, spp=4096), card.name, sha)
    task = tasks.TileTask(spec=spec, frame=0.0, tiles=(Tile(0, 0, 64, 64),), width=64, height=64)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster, set_as_default=False) as client:
        scene = client.submit(tasks.scene_package, sha, card.name, data, pure=False)
        small = tasks.TileTask(spec=spec, frame=0.0, tiles=(Tile(0, 0, 1, 1),), width=64, height=64)
        assert "arrays" in client.submit(tasks.render_tile_task, small, scene, pure=False).result()  # prepared
        before = tasks.stats()["stopped"]
        fut = client.submit(tasks.render_tile_task, task, scene, pure=False)
        deadline = time.monotonic() + 30
        while not any(fut.key in keys for keys in client.processing().values()):
            assert time.monotonic() < deadline
            time.sleep(0.02)
        time.sleep(0.3)
        t0 = time.perf_counter()
        fut.cancel()
        while tasks.stats()["stopped"] == before:
            assert time.perf_counter() - t0 < 3.0, "16M samples would take well over 10 s"
            time.sleep(0.02)
