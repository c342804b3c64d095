"""What runs on the Dask workers: scene inspection, tile rendering, frame assembly; and the per-process scene cache.

Tasks are pure functions of their arguments (a ``RenderSpec``, a frame, a tile), so Dask may run them anywhere
and run them again after a worker dies: the result is the same bits.

**Scene cache.** Loading a USD frame and building its BVH costs far more than a small tile, so each worker
process keeps the last few ``PreparedScene``s, keyed by (scene content hash, frame, everything that affects
loading and preparing). Threads of one worker share them (Warp launches release the GIL), and a per-key lock
makes sure that a frame is prepared once per process even when its tiles arrive together.

**Errors.** A ``RenderError`` (bad scene, bad settings: the user's to fix) is returned as ``{"error": message}``,
never retried. Anything else raises, so Dask's ``retries`` and the scheduler's bounded resubmission apply.
"""
from __future__ import annotations

import os
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

from .checkpoints import TileBox, load_tile
from .spec import RenderSpec

_cache: OrderedDict = OrderedDict()
_cache_lock = threading.Lock()
_key_locks: dict = {}
_stats = {"prepared": 0, "tiles": 0}


def _one_line(e: BaseException, spec: RenderSpec | None = None) -> str:
    text = " ".join(str(e).split()) or type(e).__name__
    if spec is not None:  # never show clients where the server keeps their files
        from .uploads import hide_dir

        text = hide_dir(text, Path(spec.scene_path).parent)
    return text


def prepared(spec: RenderSpec, frame: float, capacity: int = 2):
    """The PreparedScene of one frame of a job, from this process's cache or freshly loaded and prepared."""
    key = (spec.scene_sha256, spec.cache_key(frame))
    with _cache_lock:
        if key in _cache:
            _cache.move_to_end(key)
            return _cache[key]
        lock = _key_locks.setdefault(key, threading.Lock())
    with lock:
        with _cache_lock:
            if key in _cache:
                return _cache[key]
        from renderer.device import init_warp
        from renderer.render import prepare

        init_warp()
        prep = prepare(spec.load(frame), spec.options())
        with _cache_lock:
            _cache[key] = prep
            _stats["prepared"] += 1
            while len(_cache) > max(1, capacity):
                _cache.popitem(last=False)
            _key_locks.pop(key, None)
    return prep


def stats() -> dict:
    """Counters of this process (tests read them through ``client.run``)."""
    with _cache_lock:
        return dict(_stats, cached=len(_cache), pid=os.getpid())


def clear_cache() -> None:
    with _cache_lock:
        _cache.clear()


@dataclass(frozen=True)
class TileTask:
    spec: RenderSpec
    frame: float
    tile: TileBox
    width: int  # the resolution the job was planned at
    height: int
    cache_size: int = 2
    stop_flag: str | None = None  # a file whose existence means "stop": the job was canceled or failed


def _stop_check(flag: str | None, every: float = 0.1):
    """``render_tile``'s wave callback: raise Cancelled once ``flag`` exists (looked at most every ``every`` s;
    Dask cannot interrupt a running task, so a long tile of a canceled job would otherwise run to its end)."""
    if flag is None:
        return None
    from renderer.errors import Cancelled

    last = time.monotonic()

    def on_wave(_done: int, _total: int) -> None:
        nonlocal last
        now = time.monotonic()
        if now - last >= every:
            last = now
            if os.path.exists(flag):
                raise Cancelled("job stopped")

    return on_wave


def _worker_threads() -> int:
    """Threads of the Dask worker running this task (tiles rendering at once), 1 outside a worker."""
    try:
        from distributed import get_worker

        w = get_worker()
        return max(1, int(getattr(getattr(w, "state", w), "nthreads", 1)))
    except (ImportError, ValueError):
        return 1


def render_tile_task(task: TileTask) -> dict:
    from renderer.errors import Cancelled, RenderError
    from renderer.render import Tile, render_tile, tile_time_budget

    try:
        prep = prepared(task.spec, task.frame, task.cache_size)
        if (prep.width, prep.height) != (task.width, task.height):
            return {"error": f"frame {task.frame:g} renders at {prep.width}x{prep.height}, "
                             f"not at the job's {task.width}x{task.height}"}
        t0 = time.perf_counter()
        tile = Tile(*task.tile)
        budget = tile_time_budget(prep.options, tile, prep.width, prep.height, _worker_threads())
        sums = render_tile(prep, tile, on_wave=_stop_check(task.stop_flag), time_budget=budget)
        seconds = time.perf_counter() - t0
    except Cancelled:
        return {"stopped": True}
    except RenderError as e:
        return {"error": _one_line(e, task.spec)}
    with _cache_lock:
        _stats["tiles"] += 1
    return {"arrays": sums.arrays, "rays": sums.rays, "nonfinite": sums.nonfinite, "seconds": seconds,
            "pid": os.getpid()}


@dataclass(frozen=True)
class FrameTask:
    spec: RenderSpec
    frame: float
    tiles: tuple[tuple[str, TileBox], ...]  # (checkpoint path, tile box)
    output: str
    cache_size: int = 2


def finish_frame_task(task: FrameTask) -> dict:
    """Assemble a frame's checkpointed tiles and write its EXR atomically (the same bits as ``drt render``)."""
    from renderer.errors import RenderError
    from renderer.render import Tile, TileSums, assemble, write_frame

    try:
        prep = prepared(task.spec, task.frame, task.cache_size)
        parts = [TileSums(tile=Tile(*box), arrays=load_tile(Path(p))) for p, box in task.tiles]
        sums = assemble(parts, prep.width, prep.height)
        zeroed = write_frame(task.output, prep, sums, half=task.spec.half)
    except RenderError as e:
        return {"error": _one_line(e, task.spec)}
    return {"zeroed": zeroed}


@dataclass(frozen=True)
class InspectTask:
    spec: RenderSpec
    frames: tuple[float, ...] | None  # None: the stage's start time code


def inspect_task(task: InspectTask) -> dict:
    """Check an upload before it is queued: asset paths, composition, the first frame, resolution.

    Returns ``{"error": message}`` for anything wrong with the scene or settings (the API answers 422), else
    ``{"frames", "width", "height", "exposure_scale", "warnings"}``.
    """
    from .uploads import UploadError, check_asset_paths

    path = Path(task.spec.scene_path)
    try:
        check_asset_paths(path)  # before anything composes the stage
        problem = _composition_problem(path)
        if problem:
            return {"error": problem}
        from renderer.render import MAX_PIXELS, resolve_resolution

        frames = task.frames
        scene = task.spec.load(frames[0] if frames else None)
        options = task.spec.options().validate()
        width, height = resolve_resolution(scene, options)
        if width * height > MAX_PIXELS:
            return {"error": f"image of {width}x{height} pixels is too large"}
        return {"frames": list(frames) if frames else [float(scene.frame)], "width": width, "height": height,
                "exposure_scale": float(2.0 ** scene.camera.exposure), "warnings": list(scene.warnings)}
    except UploadError as e:
        return {"error": _one_line(e, task.spec)}
    except Exception as e:  # noqa: BLE001 - untrusted input: whatever fails is reported, never a 500
        from renderer.errors import RenderError

        if isinstance(e, RenderError):
            return {"error": _one_line(e, task.spec)}
        return {"error": f"scene could not be loaded: {type(e).__name__}: {_one_line(e, task.spec)}"}


def _composition_problem(path: Path) -> str | None:
    """A reference or payload to a prim that does not exist (or any other composition error), as one line."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    errors = stage.GetCompositionErrors() if stage is not None else []
    if not errors:
        return None
    from .uploads import hide_dir

    first = hide_dir(" ".join(str(errors[0]).split()), path.parent)
    return f"scene has {len(errors)} composition error(s): {first}"
