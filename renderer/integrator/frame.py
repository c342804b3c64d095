"""A whole frame: every tile rendered on threads (Warp launches release the GIL) and assembled, bit-identical in
any tiling and on any number of threads."""
from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np

from renderer.errors import SettingsError
from renderer.film import borders
from renderer.film.tiles import auto_tile_size, split_tiles
from renderer.integrator.tile import TileSums, render_tile, tile_time_budget
from renderer.prepared import PreparedScene


def assemble(tiles: list[TileSums], width: int, height: int) -> dict[str, np.ndarray]:
    """The frame's sums from tiles that cover it without overlapping (``borders.assemble``)."""
    return borders.assemble([((t.tile.x0, t.tile.y0, t.tile.x1, t.tile.y1), t.arrays) for t in tiles], width,
                            height)


@dataclass
class FrameResult:
    sums: dict[str, np.ndarray]
    seconds: float
    samples: int
    rays: int
    nonfinite: int


def render_frame(prep: PreparedScene, *, tile_size: int | None = None, threads: int = 2,
                 progress: Callable[[int, int], None] | None = None,
                 finished: dict[int, TileSums] | None = None,
                 on_tile: Callable[[int, TileSums], None] | None = None) -> FrameResult:
    """Render every tile of the frame on ``threads`` threads (Warp launches release the GIL); the tile size
    defaults to ``auto_tile_size``.

    ``finished``: tiles already rendered, by index in ``split_tiles`` order (a resumed render's checkpoints):
    they are not rendered again, and each tile rendered is added to it as it finishes (so the frame so far can
    be assembled at any moment), after ``on_tile(index, tile)``."""
    if threads < 1:
        raise SettingsError(f"threads must be >= 1, got {threads}")
    if tile_size is None:
        tile_size = auto_tile_size(prep.width, prep.height, threads)
    tiles = split_tiles(prep.width, prep.height, tile_size)
    finished = {} if finished is None else finished
    total = prep.width * prep.height * prep.options.spp
    done = {tiles[i]: t.tile.width * t.tile.height * prep.options.spp for i, t in finished.items()}
    lock = threading.Lock()

    def work(index: int) -> TileSums:
        tile = tiles[index]

        def on_wave(n: int, _: int) -> None:
            with lock:
                done[tile] = n
                if progress is not None:
                    progress(sum(done.values()), total)
        budget = tile_time_budget(prep.options, tile, prep.width, prep.height, min(threads, len(tiles)))
        result = render_tile(prep, tile, on_wave, time_budget=budget, shared_borders=True)
        if on_tile is not None:
            on_tile(index, result)
        with lock:
            finished[index] = result
        return result

    t0 = time.perf_counter()
    todo = [i for i in range(len(tiles)) if i not in finished]
    if threads == 1:
        for i in todo:
            work(i)
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            list(pool.map(work, todo))
    results = [finished[i] for i in range(len(tiles))]
    seconds = time.perf_counter() - t0
    sums = assemble(results, prep.width, prep.height)
    return FrameResult(sums=sums, seconds=seconds, samples=int(sums["spp"].sum()),
                       rays=sum(r.rays for r in results), nonfinite=sum(r.nonfinite for r in results))


def default_threads() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


