"""Process settings that keep the API's answers fast while the same process does other work.

* **Garbage collector.** The API process holds a large heap from startup (pxr, Warp, Dask, FastAPI) that lives
  as long as the process. CPython's full collections walk all of it: 50-150 ms each, measured with
  ``gc.callbacks`` during ``bench/load_test.py``, every one a stall of the event loop (and, in an inspection
  process, of a submission). Freezing the startup heap moves it out of the collector's sight (``gc.freeze``);
  collections then walk only what was allocated since: none over 3 ms in the API process during the load test
  afterwards. The frozen heap goes back to the collector at exit, so that the interpreter's last collections
  free it: a frozen module held in cycles (OpenImageIO's, imported before the freeze) would outlive the
  interpreter, and its bindings (nanobind) would print each of its objects as "leaked" on stderr.
* **GIL switch interval.** The event loop shares the interpreter with the dispatcher's thread (checkpoints,
  frame assembly, EXR writing), Dask's client thread and the submission threads. A thread that wants the GIL
  waits up to the switch interval for the holder to let go, at every step of a request. 1 ms instead of 5:
  status p99 16-20 ms (4 runs) against 22-28 ms (3 runs) in the 50-client load test, submission p50 140-167
  against 144-202 ms.
* **Submissions admitted a few at a time** (``SubmissionGate``). The event loop parses each submission's
  multipart body, synchronously, once its last byte has arrived. A burst of 50 submissions arriving together
  made 50 such tasks ready in one turn of the loop, and a status request waited for all of them: a 37 ms stall
  of the loop, measured by a 1 ms sleeper task during ``bench/load_test.py``. Submissions cannot go faster than
  their threads (``submit_limiter``) anyway, so only one more than those may be past their body at a time; the
  loop's stalls under the same burst then stay under 15 ms.
"""
from __future__ import annotations

import atexit
import gc
import sys

import anyio

SWITCH_INTERVAL = 0.001  # seconds


def freeze_heap() -> None:
    """Collect once, then exempt every surviving object from later collections (call when startup is done); they
    are handed back to the collector at exit."""
    gc.collect()
    gc.freeze()
    atexit.unregister(gc.unfreeze)  # once, however often a process freezes
    atexit.register(gc.unfreeze)


def tune_api_process() -> None:
    """The API process's settings (above), once its startup is done."""
    freeze_heap()
    sys.setswitchinterval(SWITCH_INTERVAL)


class SubmissionGate:
    """ASGI middleware: at most ``app.state.submission_gate``'s tokens of job submissions (``POST`` to ``path``)
    run past their request body at once; the others wait for a token with their body received.

    A token is taken when the body's last message arrives (or the client disconnects), not before: a slow upload
    holds none while its bytes trickle in, so slow clients cannot keep the others out. It is held until the
    submission is answered. Without a gate in the app's state (its lifespan not run), requests pass through."""

    def __init__(self, app, path: str):
        self.app = app
        self.path = path

    async def __call__(self, scope, receive, send):
        gate = getattr(getattr(scope.get("app"), "state", None), "submission_gate", None)
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"] != self.path or gate is None:
            return await self.app(scope, receive, send)
        held = False

        async def gated_receive():
            nonlocal held
            message = await receive()
            if not held and (message["type"] != "http.request" or not message.get("more_body", False)):
                await gate.acquire()
                held = True
            return message

        try:
            await self.app(scope, gated_receive, send)
        finally:
            if held:
                gate.release()


def new_submission_gate(submission_threads: int) -> anyio.Semaphore:
    """The gate's tokens: one per submission thread and one more, so the next body is parsed while they work."""
    return anyio.Semaphore(submission_threads + 1)
