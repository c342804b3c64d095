"""The farm as the monitor shows it: Dask's workers with the drt tasks each holds, and a job's tile map.

Which tile a worker renders is read from the Dask task keys the dispatcher gives its tasks,
``drt-<kind>-<job id>-<frame index>-<tile indices>-<nonce>`` (``kind`` is ``tile`` or ``frame``; the indices of a
batch of tiles joined by dots; a frame's assembly has tile index -1). Keys of other shapes are counted, not named.
"""
from __future__ import annotations

import importlib.util
import re
from collections import defaultdict

from schemas import Farm, FarmTask, FarmWorker, FrameTiles, TileMap

from ..queue.store import JobNotFound, JobRow, Store
from ..settings import ServiceSettings
from .coordinator import FarmView, DispatcherStats

_KEY = re.compile(r"^drt-(tile|frame)-([0-9A-Za-z]+)-(\d+)-(-?\d+(?:\.\d+)*)-[0-9A-Za-z]+$")


def parse_key(key) -> FarmTask | None:
    m = _KEY.match(key if isinstance(key, str) else str(key))
    if m is None:
        return None
    kind, job_id, frame_idx = m.group(1), m.group(2), int(m.group(3))
    tiles = [int(t) for t in m.group(4).split(".")] if kind == "tile" else []
    return FarmTask(kind=kind, job_id=job_id, frame_index=frame_idx, tile=tiles[0] if tiles else None, tiles=tiles)


def dashboard_url(settings: ServiceSettings, view: FarmView) -> str | None:
    """``DRT_DASHBOARD_URL`` if set; else the Dask dashboard's own link when one runs: an external scheduler's
    (``dask scheduler`` serves one on :8787), or the embedded cluster's when bokeh is installed (a loopback URL)."""
    if settings.dashboard_url:
        return settings.dashboard_url
    if "dashboard" not in (view.info.get("services") or {}):
        return None
    if settings.scheduler_address is None and importlib.util.find_spec("bokeh") is None:
        return None  # the embedded scheduler's HTTP server has no /status page without bokeh
    return view.dashboard_link


def _frame_times(store: Store, tasks: list[FarmTask]) -> None:
    """Name each task's frame by its time code (as the job's page does)."""
    times: dict[str, list[float]] = {}
    for t in tasks:
        if t.job_id not in times:
            try:
                times[t.job_id] = [f.time for f in store.get_job(t.job_id).frames]
            except JobNotFound:
                times[t.job_id] = []
        frames = times[t.job_id]
        t.frame = frames[t.frame_index] if t.frame_index < len(frames) else None


def farm(settings: ServiceSettings, view: FarmView, store: Store, stats: DispatcherStats) -> Farm:
    info, held = view.info, view.processing
    workers = []
    for address, w in sorted((info.get("workers") or {}).items()):
        tasks = [t for t in (parse_key(k) for k in held.get(address, ())) if t is not None]
        metrics = w.get("metrics") or {}
        workers.append(FarmWorker(
            address=address, name=str(w.get("name", address)), host=str(w.get("host", "")),
            nthreads=int(w.get("nthreads", 0)), memory_limit=w.get("memory_limit"),
            memory=metrics.get("memory"), cpu=metrics.get("cpu"), tasks=tasks,
            other_tasks=len(held.get(address, ())) - len(tasks)))
    _frame_times(store, [t for w in workers for t in w.tasks])
    return Farm(scheduler=info.get("address"), dashboard_url=dashboard_url(settings, view), workers=workers,
                tiles_in_flight=stats.in_flight, tiles_pending=stats.pending, tiles_per_second=stats.tiles_per_second)


def tile_map(row: JobRow, store: Store, view: FarmView) -> TileMap:
    """Which tiles of each frame are checkpointed and which a worker holds now."""
    done = store.done_tiles(row.id)
    rendering: dict[int, set[int]] = defaultdict(set)
    for keys in view.processing.values():
        for t in (parse_key(k) for k in keys):
            if t is not None and t.job_id == row.id:
                rendering[t.frame_index].update(t.tiles)
    per_frame = row.tiles_per_frame
    columns = -(-row.width // row.tile_size)
    frames = []
    for f in row.frames:
        finished = set(range(per_frame)) if f.done else done.get(f.idx, set())
        frames.append(FrameTiles(frame=f.time, done=sorted(finished),
                                 rendering=sorted(rendering.get(f.idx, set()) - finished)))
    return TileMap(width=row.width, height=row.height, tile_size=row.tile_size, columns=columns,
                   rows=-(-row.height // row.tile_size), frames=frames)
