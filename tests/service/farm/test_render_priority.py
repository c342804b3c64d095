"""Render work yields the CPU to the API: every rendering thread of a worker process of its own lowers its
priority, a worker running as threads of the service's (or the tests') process leaves it alone."""
from __future__ import annotations

import multiprocessing
import os
import threading

from service.farm import tasks


def _child(q):
    # two task threads one after the other, as a worker with two threads runs tiles; each reads its own niceness
    rendering = []

    def task():
        tasks.background_priority()
        tasks.background_priority()  # a second tile on the same thread: nothing more to do
        rendering.append(os.getpriority(os.PRIO_PROCESS, 0))  # 0: the calling thread on Linux

    for _ in range(2):
        t = threading.Thread(target=task)
        t.start()
        t.join()
    q.put((rendering, os.getpriority(os.PRIO_PROCESS, 0)))


def test_every_rendering_thread_of_a_worker_process_yields_and_the_service_keeps_its_priority(monkeypatch):
    before = os.getpriority(os.PRIO_PROCESS, 0)
    monkeypatch.setattr(tasks, "_niced", threading.local())
    tasks.background_priority()  # this process has no parent process: a threads-mode "worker"
    assert os.getpriority(os.PRIO_PROCESS, 0) == before
    ctx = multiprocessing.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_child, args=(q,))
    p.start()
    rendering, main_thread = q.get(timeout=60)
    p.join(timeout=60)
    want = max(before, tasks.RENDER_NICENESS)
    assert rendering == [want, want]
    assert main_thread == before  # the worker's event loop keeps answering the scheduler at its own

