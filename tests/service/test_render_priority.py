"""Render work yields the CPU to the API: a worker process of its own lowers its priority, a worker running as
threads of the service's (or the tests') process leaves it alone."""
from __future__ import annotations

import multiprocessing
import os

from service import worker


def _child(q):
    worker.background_priority()
    q.put(os.getpriority(os.PRIO_PROCESS, 0))


def test_a_worker_process_lowers_its_priority_and_the_service_keeps_its_own(monkeypatch):
    before = os.getpriority(os.PRIO_PROCESS, 0)
    monkeypatch.setattr(worker, "_niced", False)
    worker.background_priority()  # this process has no parent process: a threads-mode "worker"
    assert os.getpriority(os.PRIO_PROCESS, 0) == before
    ctx = multiprocessing.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_child, args=(q,))
    p.start()
    got = q.get(timeout=60)
    p.join(timeout=60)
    assert got == max(before, worker.RENDER_NICENESS)
