"""A worker's private scene files: what a worker stopped by a signal leaves behind is removed by the next one."""
from __future__ import annotations

import os
import subprocess
import sys

from service import worker


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_the_scene_directories_of_dead_workers_are_removed_and_live_ones_kept(tmp_path):
    dead = tmp_path / f"drt-worker-{_dead_pid()}-abc123"
    (dead / ("f" * 64)).mkdir(parents=True)
    (dead / ("f" * 64) / "scene.usda").write_text("#usda 1.0\n")
    live = tmp_path / f"drt-worker-{os.getpid()}-def456"  # this process: alive
    live.mkdir()
    other = tmp_path / "drt-worker-notapid-x"
    other.mkdir()
    unrelated = tmp_path / "something-else"
    unrelated.mkdir()

    assert worker.remove_orphaned_roots(tmp_path) == 1
    assert not dead.exists()
    assert live.exists() and other.exists() and unrelated.exists()
    assert worker.remove_orphaned_roots(tmp_path) == 0
