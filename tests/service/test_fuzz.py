"""Property-based fuzzing of the API from its own OpenAPI description (schemathesis, positive and negative data):
no 5xx, every status and content type documented, every body matching its schema; with and without a token.

The fast runs use a fixed seed (Hypothesis ``derandomize``) and a few examples per operation; the long ones are
``@pytest.mark.slow``.
"""
from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import (content_type_conformance, not_a_server_error, response_schema_conformance,
                                 status_code_conformance)
from schemathesis.python import asgi

from service.app import create_app

from service_helpers import service_settings

TOKEN = "fuzz-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance]
FAST = settings(max_examples=12, derandomize=True, deadline=None, database=None,
                suppress_health_check=list(HealthCheck))
LONG = settings(max_examples=300, derandomize=False, deadline=None, database=None,
                suppress_health_check=list(HealthCheck))


# The apps are built at import (schemathesis parametrizes tests at collection) but start on first use: schemathesis
# runs an ASGI app's lifespan once and keeps it until ``shutdown_lifespans``.
_DATA = Path(tempfile.mkdtemp(prefix="drt-fuzz-"))
_APPS = {name: create_app(service_settings(_DATA / name, api_token=token, max_upload_bytes=200_000))
         for name, token in (("open", None), ("token", TOKEN))}


def _schema(app):
    # The event streams (server-sent events) never end by design, so an in-process client that reads a whole
    # response would wait forever; real clients test them (tests/service/test_monitor_api.py).
    schema = schemathesis.openapi.from_dict(app.openapi()).exclude(path_regex=r"/events$")
    schema.app = app  # requests go to the app in process (as ``schemathesis.openapi.from_asgi`` does)
    return schema


open_api = _schema(_APPS["open"])
token_api = _schema(_APPS["token"])


@pytest.fixture(scope="module", autouse=True)
def _services(card):
    """Both services started, each with one finished job (so that lists and job views have something to show)."""
    try:
        for name, app in _APPS.items():
            headers = AUTH if name == "token" else {}
            with asgi.get_client(app) as client, open(card, "rb") as f:
                client.headers.update(headers)
                r = client.post("/v1/jobs", files={"scene": ("card.usda", f)},
                                data={"settings": json.dumps({"width": 16, "height": 16, "spp": 1, "tile": 8})})
                assert r.status_code == 202, r.text
                deadline = time.monotonic() + 120
                while client.get(r.json()["url"]).json()["state"] != "succeeded":
                    assert time.monotonic() < deadline
                    time.sleep(0.05)
        yield
    finally:
        asgi.shutdown_lifespans()
        shutil.rmtree(_DATA, ignore_errors=True)


def _with_token(case) -> None:
    case.call_and_validate(headers=AUTH, checks=CHECKS)
    # The same request without credentials (or with a wrong token) is a documented 401, whatever its body.
    for headers in ({}, {"Authorization": "Bearer not-the-token"}):
        case.headers = {k: v for k, v in (case.headers or {}).items() if k.lower() != "authorization"}
        r = case.call(headers=headers)
        if case.operation.path != "/healthz":  # the one public path
            assert r.status_code == 401, (case.operation.label, r.status_code, r.text)
        case.validate_response(r, checks=CHECKS)


@open_api.parametrize()
@FAST
def test_fuzz_without_token(case):
    case.call_and_validate(checks=CHECKS)


@token_api.parametrize()
@FAST
def test_fuzz_with_token(case):
    _with_token(case)


@pytest.mark.slow
@open_api.parametrize()
@LONG
def test_fuzz_without_token_long(case):
    case.call_and_validate(checks=CHECKS)


@pytest.mark.slow
@token_api.parametrize()
@LONG
def test_fuzz_with_token_long(case):
    _with_token(case)
