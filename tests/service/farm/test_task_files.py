"""A worker's private scene files: what a worker stopped by a signal leaves behind is removed by the next one."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from service.farm import tasks

ROOT = Path(__file__).resolve().parents[3]

# A worker process: makes its scene directory (locked for as long as it lives), prints it, and waits.
WORKER = """
import sys, time, tempfile
tempfile.tempdir = sys.argv[1]
from service.farm import tasks
print(tasks._root(), flush=True)
time.sleep(60)
"""


def _start_worker(tmp_path) -> tuple[subprocess.Popen, str]:
    p = subprocess.Popen([sys.executable, "-c", WORKER, str(tmp_path)], stdout=subprocess.PIPE, text=True,
                         cwd=ROOT)
    return p, p.stdout.readline().strip()


def test_a_killed_workers_directory_is_removed_by_the_next_worker_and_a_live_ones_kept(tmp_path):
    killed, killed_dir = _start_worker(tmp_path)
    live, live_dir = _start_worker(tmp_path)  # its start sweeps too: the first one still runs, so it stays
    try:
        assert os.path.isdir(killed_dir) and os.path.isdir(live_dir)
        (tmp_path / "something-else").mkdir()
        old_style = tmp_path / "drt-worker-123-abc"  # no lock file: left alone
        old_style.mkdir()
        os.kill(killed.pid, signal.SIGKILL)  # no atexit clean-up
        killed.wait()
        assert os.path.isdir(killed_dir)

        assert tasks.remove_orphaned_roots(tmp_path) == 1
        assert not os.path.exists(killed_dir)
        assert os.path.isdir(live_dir) and old_style.exists() and (tmp_path / "something-else").exists()
        assert tasks.remove_orphaned_roots(tmp_path) == 0
    finally:
        live.kill()
        live.wait()
    time.sleep(0.1)
    assert tasks.remove_orphaned_roots(tmp_path) == 1  # the second, now ended too
