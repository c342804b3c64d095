"""What runs on the Dask workers: tile rendering and a frame's products; the per-process scene caches.

A worker needs nothing but the scheduler's address. It never sees the service's data directory: the uploaded
scene reaches it through Dask (a ``ScenePackage``, the upload's bytes, is the result of a ``scene_package`` task on
which every tile task depends, so Dask copies it to a worker once and recomputes it if the worker holding it dies),
tiles and the frames' products go back as task results (numpy arrays and plain values), and the service alone
writes checkpoints, products and the database.

Tasks are pure functions of their arguments (a ``RenderSpec``, the scene's bytes, a frame, a batch of tiles), so
Dask may run them anywhere and run them again after a worker dies: the result is the same bits.

**Caches, per worker process.** (1) A package is written once to a private temporary directory of the process
(``scene files``), keyed by its content hash, and its USD stage is opened once and kept in a ``Usd.StageCache``, so
the 24 frames of an animation load their stage once per worker, not once per frame. (2) The last few
``PreparedScene``s (a frame loaded and its BVH built), keyed by (content hash, frame, everything that affects
loading and preparing). Threads of one worker share them (Warp launches release the GIL), and a per-key lock makes
sure that a frame is prepared once per process even when its tiles arrive together.

**Stopping.** Dask cannot interrupt a running task. When the service cancels a tile's future (its job was canceled
or failed), the scheduler releases the task and the worker marks it ``cancelled``; ``render_tile`` looks at that
mark between sample waves and stops. No file, no round trip.

**Errors.** A ``RenderError`` (bad scene, bad settings: the user's to fix) is returned as ``{"error": message}``,
never retried. Anything else raises, so the dispatcher's bounded resubmission applies.
"""
from __future__ import annotations

import atexit
import dataclasses
import hashlib
import multiprocessing
import os
import shutil
import tempfile
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

from renderer.core.files import atomic_write
from renderer.film.tiles import Tile

from ..spec import FrameProduct, RenderSpec, frame_products

_cache: OrderedDict = OrderedDict()  # (sha, cache key) -> PreparedScene
_cache_lock = threading.Lock()
_key_locks: dict = {}
_stats = {"prepared": 0, "tiles": 0, "running": 0, "stopped": 0, "packages": 0, "stages": 0}
PACKAGES_KEPT = 4  # scene packages (files and open stages) kept per process


# -- scene packages ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ScenePackage:
    """An uploaded scene as bytes: one USD layer or a ``.usdz`` package (all its assets inside)."""

    sha256: str
    name: str  # the upload's file name (messages name it; the extension tells pxr the format)
    data: bytes

    def __repr__(self) -> str:  # never print megabytes into a log
        return f"ScenePackage({self.sha256[:12]}, {self.name!r}, {len(self.data)} bytes)"


def scene_package(sha256: str, name: str, data: bytes) -> ScenePackage:
    """The Dask task whose result is a scene (its bytes travel with the task; the hash is checked)."""
    if hashlib.sha256(data).hexdigest() != sha256:
        raise ValueError(f"scene package {sha256[:12]} arrived corrupted")
    return ScenePackage(sha256, name, data)


class _LocalScene:
    """A package written to this process's private directory, with its stage cache and a lock for loading."""

    def __init__(self, root: Path, pkg: ScenePackage):
        from pxr import Usd

        self.dir = root / pkg.sha256
        self.dir.mkdir(parents=True, exist_ok=True)
        self.path = self.dir / pkg.name
        with atomic_write(self.path, durable=False) as f:  # a private copy: it need not outlive a crash
            f.write(pkg.data)
        self.stages = Usd.StageCache()
        self.lock = threading.Lock()  # one frame loads at a time from the shared stage

    def load(self, spec: RenderSpec, frame: float | None):
        from pxr import Usd

        with self.lock, Usd.StageCacheContext(self.stages):
            before = self.stages.Size()
            scene = spec.load(frame, scene_path=str(self.path))
            if self.stages.Size() > before:
                with _cache_lock:
                    _stats["stages"] += 1
        return scene

    def products(self, spec: RenderSpec, frame: float) -> list[FrameProduct]:
        """The products a frame of the job writes (``spec.frame_products``), read from the cached stage."""
        from pxr import Usd

        from renderer.usd.stage import open_stage

        with self.lock, Usd.StageCacheContext(self.stages):
            stage = open_stage(self.path)
        return frame_products(stage, spec.request_at(frame), frame, lambda _message: None)

    def remove(self) -> None:
        self.stages.Clear()
        shutil.rmtree(self.dir, ignore_errors=True)


_scene_root: Path | None = None
_scenes: OrderedDict = OrderedDict()  # sha -> _LocalScene
_scenes_lock = threading.Lock()
ROOT_PREFIX = "drt-worker-"  # + pid + "-" + random: the scene files of one worker process
ROOT_LOCK = ".owner"  # a file in it, locked (flock) by the process for as long as it lives
_root_lock = None  # that file, open: the kernel releases the lock when the process ends, however it ends

try:
    import fcntl
except ImportError:  # not POSIX: no sweeping, the atexit clean-up only
    fcntl = None


def _owner_gone(d: Path) -> bool:
    """Whether the process that made worker directory ``d`` has ended: its lock file can be locked. A lock, unlike
    a pid, holds across PID namespaces sharing one temporary directory and cannot be confused by a reused pid."""
    try:
        fd = os.open(d / ROOT_LOCK, os.O_RDWR)
    except FileNotFoundError:  # made by a process that died before locking it, or never will: leave it
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError:
        return False
    finally:
        os.close(fd)


def remove_orphaned_roots(tmp: Path) -> int:
    """Remove the scene directories of worker processes that no longer run; returns how many. A worker stopped by a
    signal (as Dask's nanny and a farm's scheduler stop them) never runs its atexit clean-up, so each new worker
    process sweeps what ended ones left: only this user's directories, only those whose owner's lock is free."""
    if fcntl is None:
        return 0
    removed = 0
    for d in tmp.glob(ROOT_PREFIX + "*"):
        try:
            if d.stat().st_uid != os.getuid() or not _owner_gone(d):
                continue
        except OSError:  # gone meanwhile, or not ours to read
            continue
        shutil.rmtree(d, ignore_errors=True)
        removed += 1
    return removed


def _root() -> Path:
    global _scene_root, _root_lock
    if _scene_root is None:
        root = Path(tempfile.mkdtemp(prefix=f"{ROOT_PREFIX}{os.getpid()}-"))
        if fcntl is not None:
            _root_lock = open(root / ROOT_LOCK, "w")
            fcntl.flock(_root_lock.fileno(), fcntl.LOCK_EX)
            remove_orphaned_roots(root.parent)  # after locking its own, so it never takes itself for dead
        _scene_root = root
        atexit.register(shutil.rmtree, _scene_root, True)
    return _scene_root


def local_scene(pkg: ScenePackage) -> _LocalScene:
    """This process's copy of a package (written on first use; the oldest beyond PACKAGES_KEPT removed)."""
    with _scenes_lock:
        local = _scenes.get(pkg.sha256)
        if local is None:
            local = _scenes[pkg.sha256] = _LocalScene(_root(), pkg)
            _stats["packages"] += 1
            while len(_scenes) > PACKAGES_KEPT:
                _scenes.popitem(last=False)[1].remove()
        else:
            _scenes.move_to_end(pkg.sha256)
        return local


def _one_line(e: BaseException) -> str:
    """One line, without this process's private directory (clients see their own file names only)."""
    text = " ".join(str(e).split()) or type(e).__name__
    if _scene_root is not None:
        for d in sorted({str(s.dir) for s in _scenes.values()}, key=len, reverse=True):
            text = text.replace(d + os.sep, "").replace(d, ".")
    return text


def prepared(spec: RenderSpec, frame: float, scene: ScenePackage, capacity: int = 2):
    """The PreparedScene of one frame of a job, from this process's cache or freshly loaded and prepared; a
    cached one prepared for a job that sampled differently (seed, spp, ...) takes this job's options."""
    from renderer.prepared import with_options

    key = (spec.scene_sha256, spec.cache_key(frame))
    options = spec.options()
    with _cache_lock:
        prep = _cache.get(key)
        if prep is not None:
            _cache.move_to_end(key)
        else:
            lock = _key_locks.setdefault(key, threading.Lock())
    if prep is None:
        with lock:
            with _cache_lock:
                prep = _cache.get(key)
            if prep is None:
                from renderer.kernels.device import init_warp
                from renderer.prepared import prepare

                init_warp()
                prep = prepare(local_scene(scene).load(spec, frame), options)
                with _cache_lock:
                    _cache[key] = prep
                    _stats["prepared"] += 1
                    while len(_cache) > max(1, capacity):
                        _cache.popitem(last=False)
                    _key_locks.pop(key, None)
    return prep if prep.options == options else with_options(prep, options)


def stats() -> dict:
    """Counters of this process (tests read them through ``client.run``)."""
    with _cache_lock:
        return dict(_stats, cached=len(_cache), pid=os.getpid(), cwd=os.getcwd(),
                    scene_dir=str(_scene_root) if _scene_root else None)


def clear_cache() -> None:
    with _cache_lock:
        _cache.clear()
    with _scenes_lock:
        while _scenes:
            _scenes.popitem()[1].remove()


# -- tiles ------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TileTask:
    """Tiles of one frame rendered one after the other in one task (a batch: tiny tiles cost one task together)."""

    spec: RenderSpec
    frame: float
    tiles: tuple[Tile, ...]
    width: int  # the resolution the job was planned at
    height: int
    cache_size: int = 2


def _stop_check(every: float = 0.1):
    """``render_tile``'s wave callback: raise Cancelled once Dask has released this task (looked at most every
    ``every`` s). Outside a Dask worker (tests calling the task directly) there is nothing to look at."""
    try:
        from distributed import get_worker

        w = get_worker()
        key = w.get_current_task()
    except (ImportError, ValueError):
        return None
    from renderer.errors import Cancelled

    last = time.monotonic()

    def on_wave(_done: int, _total: int) -> None:
        nonlocal last
        now = time.monotonic()
        if now - last >= every:
            last = now
            ts = w.state.tasks.get(key)
            if ts is None or ts.state in ("cancelled", "released", "forgotten"):
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


# Render work yields the CPU to whatever shares the machine with it: on the embedded LocalCluster that is the API
# answering status requests and inspecting uploads, which must stay fast while tiles render. A niceness, raised
# once per rendering thread (never lowered: that needs privileges); DRT_RENDER_NICENESS=0 leaves it alone. Per
# thread, because on Linux a niceness belongs to the thread that set it: a worker's other task threads (and the
# worker's own event loop) would otherwise render, or answer the scheduler, at the old one.
RENDER_NICENESS = 10
_niced = threading.local()


def background_priority() -> None:
    """Raise the calling thread's niceness to DRT_RENDER_NICENESS (default RENDER_NICENESS), once per thread, in a
    worker process of its own (a nanny's child): workers running as threads of the service (or of a test) leave it
    alone."""
    if getattr(_niced, "done", False):
        return
    _niced.done = True
    if multiprocessing.parent_process() is None:
        return
    try:
        want = int(os.environ.get("DRT_RENDER_NICENESS", RENDER_NICENESS))
        if want > os.getpriority(os.PRIO_PROCESS, 0):  # 0: the calling thread on Linux, the process elsewhere
            os.setpriority(os.PRIO_PROCESS, 0, min(want, 19))
    except (ValueError, OSError, AttributeError):  # not a number, not permitted, or not a POSIX system
        pass


def render_tile_task(task: TileTask, scene: ScenePackage) -> dict:
    """The task's tiles' sums, in its order: ``{"arrays": [per tile], "seconds": [per tile], "rays",
    "nonfinite", "pid"}``, or ``{"stopped": True}``, or ``{"error"}``."""
    from renderer.errors import Cancelled, RenderError
    from renderer.integrator.tile import render_tile, tile_time_budget

    background_priority()
    arrays, seconds, rays, nonfinite = [], [], 0, 0
    try:
        prep = prepared(task.spec, task.frame, scene, task.cache_size)
        if (prep.width, prep.height) != (task.width, task.height):
            return {"error": f"frame {task.frame:g} renders at {prep.width}x{prep.height}, "
                             f"not at the job's {task.width}x{task.height}"}
        stop_check = _stop_check()
        with _cache_lock:
            _stats["running"] += 1  # tasks rendering now (tests watch a deleted job's tiles stop)
        try:
            for tile in task.tiles:
                t0 = time.perf_counter()
                budget = tile_time_budget(prep.options, tile, prep.width, prep.height, _worker_threads())
                sums = render_tile(prep, tile, on_wave=stop_check, time_budget=budget, shared_borders=True)
                arrays.append(sums.arrays)
                seconds.append(time.perf_counter() - t0)
                rays += sums.rays
                nonfinite += sums.nonfinite
        finally:
            with _cache_lock:
                _stats["running"] -= 1
    except Cancelled:
        with _cache_lock:
            _stats["stopped"] += 1
        return {"stopped": True}
    except RenderError as e:
        return {"error": _one_line(e)}
    with _cache_lock:
        _stats["tiles"] += len(task.tiles)
    return {"arrays": arrays, "rays": rays, "nonfinite": nonfinite, "seconds": seconds, "pid": os.getpid()}


# -- frames -----------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FrameTask:
    spec: RenderSpec
    frame: float
    sums: dict  # the frame's assembled filtered sums (renderer.render.assemble of its checkpointed tiles)
    cache_size: int = 2


@dataclass
class ProductImage:
    """One product of a frame as plain values: its name and prim (``spec.FrameProduct``), its EXR
    (``renderer.render.FrameImage``) and the channels stored as HALF."""

    name: str
    prim: str | None
    image: object  # renderer.render.FrameImage
    halves: frozenset


def frame_image_task(task: FrameTask, scene: ScenePackage) -> dict:
    """The frame's products from its sums (``renderer.output.var_channels.product_image``: each one's EXR channels, header
    attributes and windows as plain values): ``{"products": [ProductImage]}`` or ``{"error"}``. The service writes
    them with the renderer's writer, so each EXR has the same bits as ``drt render``'s."""
    from renderer.errors import RenderError
    from renderer.output.frame import ResolvedFrame
    from renderer.output.var_channels import product_image

    try:
        prep = prepared(task.spec, task.frame, scene, task.cache_size)
        resolved = ResolvedFrame(prep, task.sums)  # once for every product of the frame
        out = []
        for p in local_scene(scene).products(task.spec, task.frame):
            image, halves = product_image(prep, task.sums, p.vars, user_aovs=task.spec.user_aovs,
                                          user_cryptomatte=task.spec.user_cryptomatte, half=task.spec.request.half,
                                          resolved=resolved)
            out.append(ProductImage(p.name, p.prim, image, halves))
        return {"products": out}
    except RenderError as e:
        return {"error": _one_line(e)}


def whole_frame_task(render_tiles, task: TileTask, scene: ScenePackage) -> dict:
    """Every tile of a frame and then its image, in one task (a frame small enough for one batch): the tiles
    as ``render_tiles`` (the tile task) renders them, assembled, and ``frame_image_task``'s result from the sums,
    plus the tiles' ``seconds``. The same bits as tile tasks, checkpoints and an assembly task give."""
    from renderer.integrator.frame import assemble
    from renderer.integrator.tile import TileSums

    tiles = render_tiles(task, scene)
    if "arrays" not in tiles:
        return tiles  # stopped, or the renderer's error
    parts = [TileSums(tile=tile, arrays=arrays) for tile, arrays in zip(task.tiles, tiles["arrays"], strict=True)]
    image = frame_image_task(FrameTask(spec=task.spec, frame=task.frame, sums=assemble(parts, task.width, task.height),
                                       cache_size=task.cache_size), scene)
    if "error" in image:
        return image
    return {**image, "seconds": tiles["seconds"], "rays": tiles["rays"], "nonfinite": tiles["nonfinite"],
            "pid": tiles["pid"]}
