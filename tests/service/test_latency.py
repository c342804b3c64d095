"""Once started, the API process freezes its startup heap and shortens the GIL switch interval
(``service.latency``)."""
from __future__ import annotations

import gc
import sys

from service import latency


def test_the_service_freezes_its_startup_heap_and_shortens_the_switch_interval_once_started(make_client):
    gc.unfreeze()  # whatever an earlier test (or service) did to this process
    sys.setswitchinterval(0.005)
    assert gc.get_freeze_count() == 0
    client = make_client()
    assert client.get("/healthz").status_code == 200
    assert gc.get_freeze_count() > 10_000  # the imports and the started runtime, not a handful of objects
    assert sys.getswitchinterval() == latency.SWITCH_INTERVAL
