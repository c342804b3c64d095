"""What keeps the API's answers fast (``service.latency``): once started, the API process freezes its startup heap
and shortens the GIL switch interval; submissions pass the ``SubmissionGate`` a few at a time. And every answer
carries the service's own time for it (``service.api.timing``)."""
from __future__ import annotations

import gc
import pathlib
import sys

import pytest

from service import latency


def test_the_service_freezes_its_startup_heap_and_shortens_the_switch_interval_once_started(make_client):
    gc.unfreeze()  # whatever an earlier test (or service) did to this process
    sys.setswitchinterval(0.005)
    assert gc.get_freeze_count() == 0
    client = make_client()
    assert client.get("/healthz").status_code == 200
    assert gc.get_freeze_count() > 10_000  # the imports and the started runtime, not a handful of objects
    assert sys.getswitchinterval() == latency.SWITCH_INTERVAL


def test_a_frozen_heap_is_freed_at_exit_so_no_binding_reports_leaked_objects():
    """OpenImageIO imported before the freeze (a texture read in the service's process) and frozen with it: at exit
    its nanobind bindings find every object of the module still alive unless the heap is handed back to the
    collector first, and print a hundred lines of "leaked instance" warnings."""
    import subprocess

    code = "import OpenImageIO\nfrom service.latency import freeze_heap\nfreeze_heap()\nprint('frozen')"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       cwd=pathlib.Path(__file__).resolve().parents[2])
    assert r.returncode == 0 and r.stdout.strip() == "frozen", r.stderr
    assert "leaked" not in r.stderr, r.stderr[:2000]


def test_every_answer_carries_the_services_own_time_within_what_the_client_waited(make_client, card):
    """``Server-Timing: app;dur=<ms>`` on answers of every kind (401 before the body is read, 404, 202 and the
    health check): positive, and never more than the client itself waited (a wrong unit would exceed it)."""
    import time

    from service.api.timing import app_duration
    from service_helpers import submit

    client = make_client(api_token="s3cret")
    auth = {"Authorization": "Bearer s3cret"}
    calls = [lambda: client.get("/healthz"), lambda: client.get("/v1/jobs/nope"),
             lambda: client.get("/v1/jobs/nope", headers=auth),
             lambda: submit(client, card, {"width": 8, "height": 8, "spp": 1}, headers=auth)]
    for call, status in zip(calls, (200, 401, 404, 202)):
        t0 = time.perf_counter()
        r = call()
        waited = time.perf_counter() - t0
        assert r.status_code == status, r.text
        dur = app_duration(r.headers.get("server-timing"))
        assert dur is not None and 0 < dur <= waited, (r.headers.get("server-timing"), waited)


def test_the_server_timing_parser_reads_the_app_entry_only():
    from service.api.timing import app_duration

    assert app_duration("app;dur=1.5") == 0.0015
    assert app_duration("db;dur=3, app;desc=\"api\";dur=2") == 0.002
    assert app_duration("db;dur=3") is None and app_duration(None) is None and app_duration("app") is None
    assert app_duration("app;dur=x") is None


def _gated(tokens: int):
    """A SubmissionGate around an app that reads its whole body, then counts itself inside for 10 ms."""
    import types

    import anyio

    from service.latency import SubmissionGate

    seen = {"inside": 0, "peak": 0, "done": 0}

    async def app(scope, receive, send):
        while (await receive()).get("more_body"):
            pass
        seen["inside"] += 1
        seen["peak"] = max(seen["peak"], seen["inside"])
        await anyio.sleep(0.01)
        seen["inside"] -= 1
        if scope["path"] == "/boom":
            raise RuntimeError("boom")
        await send({"type": "http.response.start", "status": 202, "headers": []})
        await send({"type": "http.response.body", "body": b""})
        seen["done"] += 1

    holder = types.SimpleNamespace(state=types.SimpleNamespace(submission_gate=anyio.Semaphore(tokens)))
    return SubmissionGate(app, path="/v1/jobs"), holder, seen


async def _request(gate, holder, method="POST", path="/v1/jobs", chunks=(b"body",), stall: "anyio.Event" = None):
    # With a stall, even the last chunk says more is coming, and then nothing does.
    messages = [{"type": "http.request", "body": c, "more_body": stall is not None or i < len(chunks) - 1}
                for i, c in enumerate(chunks)]

    async def receive():
        if not messages:
            await stall.wait()  # a client whose next bytes never come
        return messages.pop(0)

    async def send(_message):
        pass

    await gate({"type": "http", "method": method, "path": path, "app": holder}, receive, send)


def test_the_submission_gate_admits_its_tokens_at_once_and_only_submissions():
    import anyio

    async def main():
        gate, holder, seen = _gated(2)
        async with anyio.create_task_group() as tg:
            for _ in range(8):
                tg.start_soon(_request, gate, holder)
        assert seen["done"] == 8 and seen["peak"] == 2
        assert holder.state.submission_gate.value == 2  # every token given back
        gate, holder, seen = _gated(2)
        async with anyio.create_task_group() as tg:
            for _ in range(8):
                tg.start_soon(_request, gate, holder, "GET")  # a status read or a job list: never gated
        assert seen["done"] == 8 and seen["peak"] == 8

    anyio.run(main)


def test_a_slow_upload_holds_no_token_and_a_failed_submission_gives_its_token_back():
    import anyio

    async def main():
        gate, holder, seen = _gated(1)
        stall = anyio.Event()
        async with anyio.create_task_group() as tg:
            # Two chunks arrived, the rest never does: it must not keep the one token.
            tg.start_soon(_request, gate, holder, "POST", "/v1/jobs", (b"a", b"b"), stall)
            await anyio.sleep(0.05)
            with anyio.fail_after(5):
                await _request(gate, holder)
                await _request(gate, holder)
            assert seen["done"] == 2
            tg.cancel_scope.cancel()
        assert holder.state.submission_gate.value == 1

        gate, holder, seen = _gated(1)
        gate.path = "/boom"
        for _ in range(2):  # the second would wait forever had the first kept the token
            with anyio.fail_after(5), pytest.raises(RuntimeError, match="boom"):
                await _request(gate, holder, path="/boom")
        assert holder.state.submission_gate.value == 1

    anyio.run(main)
