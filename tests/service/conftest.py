"""Service test fixtures: a tiny scene, an app on an in-process Dask cluster (TestClient with its lifespan)."""
from __future__ import annotations

from pathlib import Path

import pytest

from service_helpers import service_settings, write_card


@pytest.fixture(scope="session")
def card(tmp_path_factory) -> Path:
    return write_card(tmp_path_factory.mktemp("scenes") / "card.usda")


@pytest.fixture
def make_client(tmp_path):
    """make_client(**settings) -> a started TestClient (lifespan entered); make_client.stop(c) stops one early;
    the rest are closed at teardown. All share one data directory, so a second client is a restarted service."""
    from fastapi.testclient import TestClient

    from service.app import create_app

    opened = []

    def make(**overrides):
        app = create_app(service_settings(tmp_path / "data", **overrides))
        c = TestClient(app)
        c.__enter__()
        opened.append(c)
        return c

    def stop(c):
        """Stop a service (its lifespan ends: scheduler, Dask and database closed); its data directory stays."""
        opened.remove(c)
        c.__exit__(None, None, None)

    make.stop = stop
    yield make
    for c in reversed(opened):
        c.__exit__(None, None, None)


@pytest.fixture
def client(make_client):
    return make_client()
