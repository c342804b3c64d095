"""Render work computes with denormals flushed to zero (FTZ and DAZ, as Embree asks), and only render work."""
from __future__ import annotations

import threading

import numpy as np
import pytest
import warp as wp

import renderer.integrator.tile as tile_module
from renderer.kernels.device import FTZ_DAZ, denormals_flushed, init_warp, thread_mxcsr
from renderer.film.tiles import Tile
from renderer.settings.options import RenderOptions
from renderer.render import prepare, render_frame, render_tile

from renders import make_scene

pytestmark = pytest.mark.skipif(thread_mxcsr() is None, reason="MXCSR is read on Linux x86-64 only")

TINY = 1.0e-20  # its square, 1e-40, is a denormal float32 (the smallest normal is 1.18e-38)


def control() -> int:
    """The MXCSR's control bits (modes and masks), without its sticky exception flags (bits 0-5)."""
    return thread_mxcsr() & ~0x3F


@wp.kernel(module="unique")
def products(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    out[0] = a[0] * a[0]  # a denormal result: 0 under FTZ
    out[1] = a[1] * 1.0  # a denormal input: 0 under DAZ


def run_products() -> np.ndarray:
    a = wp.array(np.array([TINY, 1.0e-40], np.float32), dtype=float, device="cpu")
    out = wp.zeros(2, dtype=float, device="cpu")
    wp.launch(products, dim=1, inputs=[a, out], device="cpu")
    return out.numpy()


def test_a_warp_kernel_flushes_denormals_inside_and_not_outside():
    init_warp()
    before = control()
    plain = run_products()
    assert plain[0] > 0.0 and plain[1] > 0.0  # IEEE gradual underflow outside
    with denormals_flushed():
        assert thread_mxcsr() & FTZ_DAZ == FTZ_DAZ
        assert list(run_products()) == [0.0, 0.0]
    assert control() == before
    assert list(run_products()) == list(plain)


def test_the_mode_is_restored_when_the_work_raises():
    before = control()
    with pytest.raises(RuntimeError):
        with denormals_flushed():
            raise RuntimeError("a tile failed")
    assert control() == before


def test_render_tiles_run_flushed_on_every_thread_and_leave_the_caller_as_it_was(monkeypatch):
    """The mode is set where the tile is rendered (render_frame's threads, a farm worker's render_tile call), not
    inherited from whoever made the threads."""
    seen = []
    inner = tile_module._sampled_tile

    def spy(*args):
        seen.append((threading.get_ident(), thread_mxcsr()))
        return inner(*args)

    monkeypatch.setattr(tile_module, "_sampled_tile", spy)
    prep = prepare(make_scene(), RenderOptions(width=24, height=16, spp=2))
    before = control()
    render_frame(prep, tile_size=8, threads=2)
    render_tile(prep, Tile(0, 0, 8, 8))
    assert len(seen) == 6 + 1
    assert all(mode & FTZ_DAZ == FTZ_DAZ for _, mode in seen)
    assert len({ident for ident, _ in seen}) >= 2  # the frame's own threads, and this one
    assert control() == before
