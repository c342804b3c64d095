"""Process settings that keep the API's answers fast while the same process does other work.

* **Garbage collector.** The API process holds a large heap from startup (pxr, Warp, Dask, FastAPI) that lives
  as long as the process. CPython's full collections walk all of it: 50-150 ms each, measured with
  ``gc.callbacks`` during ``bench/load_test.py``, every one a stall of the event loop (and, in an inspection
  process, of a submission). Freezing the startup heap moves it out of the collector's sight (``gc.freeze``);
  collections then walk only what was allocated since: none over 3 ms in the API process during the load test
  afterwards.
* **GIL switch interval.** The event loop shares the interpreter with the job scheduler's thread (checkpoints,
  frame assembly, EXR writing), Dask's client thread and the submission threads. A thread that wants the GIL
  waits up to the switch interval for the holder to let go, at every step of a request. 1 ms instead of 5:
  status p99 16-20 ms (4 runs) against 22-28 ms (3 runs) in the 50-client load test, submission p50 140-167
  against 144-202 ms.
"""
from __future__ import annotations

import gc
import sys

SWITCH_INTERVAL = 0.001  # seconds


def freeze_heap() -> None:
    """Collect once, then exempt every surviving object from later collections (call when startup is done)."""
    gc.collect()
    gc.freeze()


def tune_api_process() -> None:
    """The API process's settings (above), once its startup is done."""
    freeze_heap()
    sys.setswitchinterval(SWITCH_INTERVAL)
