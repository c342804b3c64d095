"""Warp start-up for a CPU render: initialise once, without Warp's greeting or its CUDA-driver warning.

The CLI promises one-line errors on stderr; Warp's native library prints a warning about the missing CUDA
driver straight to file descriptor 2 when it initialises, so we point fd 2 at /dev/null for that moment.
"""
from __future__ import annotations

import os
import threading

import warp as wp

_lock = threading.Lock()
_done = False


def init_warp() -> None:
    global _done
    with _lock:
        if _done:
            return
        wp.config.log_level = wp.LOG_WARNING
        wp.config.quiet = True
        saved = os.dup(2)
        try:
            with open(os.devnull, "w") as null:
                os.dup2(null.fileno(), 2)
                wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        _done = True
