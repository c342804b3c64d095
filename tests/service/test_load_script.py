"""bench/load_test.py stays runnable: a few clients against the `drt serve` it starts itself."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from service_helpers import cli_env

SCRIPT = Path(__file__).resolve().parents[2] / "bench" / "load_test.py"


@pytest.mark.slow  # 9 s: a benchmark script's smoke test
def test_load_test_script_small():
    r = subprocess.run([sys.executable, str(SCRIPT), "--clients", "4", "--timeout", "300"], capture_output=True,
                       text=True, env=cli_env(), timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "4 submitted, 4 returned, 4 succeeded, 0 lost, 0 duplicated; 0 errors" in r.stdout
    assert "status latency over" in r.stdout and r.stdout.strip().endswith("OK")
    probe = next(line for line in r.stdout.splitlines() if line.startswith("probe ("))
    assert "status requests: p50" in probe and " over 0 " not in probe


def test_load_test_refuses_other_hosts():
    r = subprocess.run([sys.executable, str(SCRIPT), "--server", "http://192.0.2.1:8000"], capture_output=True,
                       text=True, env=cli_env(), timeout=60)
    assert r.returncode != 0 and "only loopback servers may be load-tested" in r.stderr
