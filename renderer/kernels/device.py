"""The CPU device: Warp's start-up for a render, and the floating-point mode render threads compute in.

The CLI promises one-line errors on stderr; Warp's native library prints a warning about the missing CUDA
driver straight to file descriptor 2 when it initialises, so we point fd 2 at /dev/null for that moment.
Render work runs with denormals flushed to zero (``denormals_flushed``), as Embree asks.
"""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools
import os
import platform
import sys
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


# ---------------------------------------------------------------------------------------------------------------
# The render threads' floating-point mode

# MXCSR bits: flush-to-zero (15: a denormal result becomes 0) and denormals-are-zero (6: a denormal input is read
# as 0). Embree asks for both ("for best performance set FTZ and DAZ"): its traversal makes denormals, each one a
# slow microcode assist on x86 cores without them. Here they cost cornell and heavy 8 % of a frame (320x180, 32 spp,
# 2 threads; none with our own traversal, DRT_EMBREE=0), and their pixels are the same bits with and without.
FTZ_DAZ = 0x8040
MXCSR_MASKS = 0x1F80  # every exception masked: what a process starts with, and how we recognise the field


class _FEnv(ctypes.Structure):
    """``fenv_t`` of glibc and musl on x86-64: the x87 environment (28 bytes), then MXCSR."""

    _fields_ = [("x87", ctypes.c_ubyte * 28), ("mxcsr", ctypes.c_uint32)]


@functools.cache
def _fenv_functions():
    """libm's ``fegetenv`` and ``fesetenv`` where ``fenv_t`` is known to end in MXCSR (Linux x86-64), else None."""
    if sys.platform != "linux" or platform.machine() not in ("x86_64", "AMD64"):
        return None
    try:
        libm = ctypes.CDLL(ctypes.util.find_library("m") or "libm.so.6")
        get, put = libm.fegetenv, libm.fesetenv
    except (OSError, AttributeError):
        return None
    get.argtypes = put.argtypes = [ctypes.POINTER(_FEnv)]
    env = _FEnv()
    if get(ctypes.byref(env)) != 0 or env.mxcsr & MXCSR_MASKS != MXCSR_MASKS:
        return None  # not the layout above
    return get, put


def thread_mxcsr() -> int | None:
    """This thread's MXCSR, or None where it cannot be read (not Linux x86-64)."""
    fns = _fenv_functions()
    if fns is None:
        return None
    env = _FEnv()
    fns[0](ctypes.byref(env))
    return int(env.mxcsr)


@contextlib.contextmanager
def denormals_flushed():
    """Within: this thread computes with FTZ and DAZ (Warp's CPU kernels run in the thread that launches them,
    and Embree in the kernel). On exit the thread's previous floating-point environment is back, so the mode
    stays with render work. Elsewhere than Linux x86-64: nothing changes."""
    fns = _fenv_functions()
    if fns is None:
        yield
        return
    get, put = fns
    saved = _FEnv()
    get(ctypes.byref(saved))
    env = _FEnv.from_buffer_copy(saved)
    env.mxcsr |= FTZ_DAZ
    put(ctypes.byref(env))
    try:
        yield
    finally:
        put(ctypes.byref(saved))
