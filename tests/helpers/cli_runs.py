"""``drt`` run as a user runs it: a real process (``python -m service.cli``) with this checkout's modules, and the
CLI's error contract checked (one line on stderr, no traceback, a non-zero exit)."""
from __future__ import annotations

import os
import subprocess
import sys


def drt(*args, cwd=None, env=None):
    """``drt ARGS...`` in a process of its own; ``env``: variables added to this one's."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path), **(env or {}))
    return subprocess.run([sys.executable, "-m", "service.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=env, timeout=300)


def assert_one_line_error(r, *needles):
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    for n in needles:
        assert n in lines[0], lines[0]
