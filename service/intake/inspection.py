"""Scene inspection before a job is queued, in a small pool of local processes (never on the render workers).

``inspect_task`` checks an upload: every asset path inside it (``scene_checks.check_asset_paths``), composition
errors, the first frame loaded with the renderer (camera path, settings bounds), the resolution, the products it
writes (``spec.frame_products``: the AOVs their vars need, warnings for those it leaves out). It answers
``{"error": message}`` for anything wrong with the scene (the API's 422) or the facts the job needs.

``InspectionPool`` runs it in ``size`` processes of its own (``python -m service.intake.inspection``, talking over
two pipes of their own, warmed up with pxr and the renderer imported; not ``multiprocessing``'s spawn, which would
run the embedding program's main script again in each child), so pxr never parses untrusted bytes in the API
process, the answer does not wait behind tiles on the cluster, and it works while the cluster is away. A scene that
loads for longer than ``timeout`` seconds is refused (422) and the process stuck on it is killed and replaced; a
process that dies loading a scene (a crash in pxr) is 422 too.

Answers are remembered (the last ``CACHE_SIZE``), keyed by the upload's content hash, its name, the frames and the
settings that reach the loader (not the seed): the same bytes give the same answer, so a pipeline that submits one
scene many times (seeds, priorities, tile sizes) pays for one inspection, and a burst of identical submissions
waits for the one inspection under way rather than queueing one each.
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import logging
import os
import queue
import subprocess
import sys
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path

from schemas import JobCreate

from ..errors import ApiError
from ..latency import freeze_heap
from ..queue.scenes import StoredScene, UploadError
from ..spec import RenderSpec, frame_products
from .scene_checks import check_asset_paths, hide_dir

log = logging.getLogger("drt.inspection")

CRASHED = "loading the scene crashed a worker"
CACHE_SIZE = 256


@dataclass(frozen=True)
class InspectTask:
    spec: RenderSpec
    frames: tuple[float, ...] | None  # None: the stage's start time code


def _one_line(e: BaseException, path: Path) -> str:
    return hide_dir(" ".join(str(e).split()) or type(e).__name__, path.parent)


def inspect_task(task: InspectTask) -> dict:
    """Check an upload before it is queued: asset paths, composition, the first frame, resolution.

    Returns ``{"error": message}`` for anything wrong with the scene or settings (the API answers 422), else
    ``{"frames", "width", "height", "exposure_scale", "warnings", "product_aovs"}``.
    """
    from renderer.errors import RenderError

    path = Path(task.spec.scene_path)
    try:
        check_asset_paths(path)  # before anything composes the stage
        problem = _composition_problem(path)
        if problem:
            return {"error": problem}
        from pxr import Usd

        from renderer.settings.options import MAX_PIXELS
        from renderer.prepared import resolve_resolution

        frames = task.frames
        stages = Usd.StageCache()  # the products are read from the stage the frame loaded from: opened once
        with Usd.StageCacheContext(stages):
            scene = task.spec.load(frames[0] if frames else None)
        options = task.spec.options().validate()
        width, height = resolve_resolution(scene, options)
        if width * height > MAX_PIXELS:
            return {"error": f"image of {width}x{height} pixels is too large"}
        first = frames[0] if frames else float(scene.frame)
        warnings = list(scene.warnings)
        with Usd.StageCacheContext(stages):
            product_aovs = _product_aovs(task.spec, first, warnings)
        return {"frames": list(frames) if frames else [first], "width": width, "height": height,
                "exposure_scale": float(2.0 ** scene.camera.exposure), "warnings": warnings,
                "product_aovs": product_aovs}
    except (UploadError, RenderError) as e:
        return {"error": _one_line(e, path)}
    except Exception as e:  # noqa: BLE001 - untrusted input: whatever fails is reported, never a 500
        return {"error": f"scene could not be loaded: {type(e).__name__}: {_one_line(e, path)}"}


def _product_aovs(spec: RenderSpec, frame: float, warnings: list[str]) -> list[str]:
    """What the RenderVars of the frame's products need rendered (``renderer.output.var_channels.needs``: AOVs, LPE,
    Cryptomatte and hit items; ``spec.frame_products``); what it leaves out joins ``warnings``."""
    from renderer.output.var_channels import needs
    from renderer.usd.stage import open_stage

    def warn(message: str) -> None:
        if message not in warnings:
            warnings.append(message)

    products = frame_products(open_stage(spec.scene_path), spec.request, frame, warn)
    return list(needs([v for p in products for v in p.vars]))


def _composition_problem(path: Path) -> str | None:
    """A reference or payload to a prim that does not exist (or any other composition error), as one line."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    errors = stage.GetCompositionErrors() if stage is not None else []
    if not errors:
        return None
    first = hide_dir(" ".join(str(errors[0]).split()), path.parent)
    return f"scene has {len(errors)} composition error(s): {first}"


def _serve(requests: Connection, answers: Connection) -> None:
    """A pool process: import what inspections need once, then answer (fn, task) requests until the pipe closes."""
    import renderer.render  # noqa: F401 - warm-up: pxr, Warp and the importer, before the first request
    import renderer.usd.importer  # noqa: F401

    freeze_heap()
    answers.send("ready")
    while True:
        try:
            fn, task = requests.recv()
        except (EOFError, OSError):
            return
        try:
            result = fn(task)
        except Exception as e:  # noqa: BLE001 - reported as the scene's problem, never a dead pool process
            result = {"error": f"scene could not be loaded: {type(e).__name__}: {' '.join(str(e).split())}"}
        answers.send(result)


class _Proc:
    """One inspection process and the two pipes to it (stdout stays free for whatever pxr or Warp print)."""

    def __init__(self):
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        self.process = subprocess.Popen([sys.executable, "-m", "service.intake.inspection", str(to_child_r),
                                         str(from_child_w)], pass_fds=(to_child_r, from_child_w), env=env,
                                        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self.requests = Connection(to_child_w, readable=False)
        self.answers = Connection(from_child_r, writable=False)
        self.ready = False

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            pass
        self.requests.close()
        self.answers.close()


class InspectionPool:
    """``size`` inspection processes; ``__call__(stored, settings)`` is the submission's inspector."""

    def __init__(self, size: int, timeout: float, fn=None):
        self.timeout = timeout
        self.fn = fn  # None: this module's inspect_task, looked up at each call
        self._idle: queue.Queue = queue.Queue()
        self._closed = False
        self._lock = threading.Lock()
        self._all: set[_Proc] = set()
        self._answers: OrderedDict = OrderedDict()
        self._pending: dict = {}  # key -> Future of the inspection under way
        for _ in range(max(1, size)):
            self._idle.put(self._spawn())

    def _spawn(self) -> _Proc:
        p = _Proc()
        with self._lock:
            self._all.add(p)
        return p

    def _retire(self, p: _Proc) -> None:
        with self._lock:
            self._all.discard(p)
        p.kill()
        if not self._closed:
            self._idle.put(self._spawn())

    def __call__(self, stored: StoredScene, settings: JobCreate) -> dict:
        frames = settings.frame_times()
        task = InspectTask(spec=RenderSpec.from_settings(settings, str(stored.path), stored.sha256),
                           frames=tuple(frames) if frames else None)
        return self.run(task)

    def run(self, task: InspectTask) -> dict:
        # The stored path is content-addressed (<sha>/<name>); the request says which settings the answer reads.
        key = (task.frames, task.spec.scene_path, task.spec.request.check_key())
        with self._lock:
            if key in self._answers:
                self._answers.move_to_end(key)
                return self._answers[key]
            pending = self._pending.get(key)
            if pending is None:
                pending = self._pending[key] = concurrent.futures.Future()
                mine = True
            else:
                mine = False
        if not mine:
            return pending.result()  # raises the same ApiError (timeout, crash) as the inspection it waited for
        try:
            result = self._run(task)
        except BaseException as e:
            with self._lock:
                del self._pending[key]
            pending.set_exception(e)
            raise
        with self._lock:
            del self._pending[key]
            self._answers[key] = result
            while len(self._answers) > CACHE_SIZE:
                self._answers.popitem(last=False)
        pending.set_result(result)
        return result

    def _run(self, task: InspectTask) -> dict:
        p = self._idle.get()
        try:
            if not p.ready:  # first use: wait for its imports (not counted against the scene's time)
                if not p.answers.poll(120) or p.answers.recv() != "ready":
                    raise EOFError
                p.ready = True
            p.requests.send((self.fn or inspect_task, task))
            t0 = time.monotonic()
            if not p.answers.poll(self.timeout):
                log.warning("a scene took longer than %g s to load; restarting its inspection process",
                            self.timeout)
                self._retire(p)
                raise ApiError(422, f"the scene took longer than {self.timeout:g} s to load")
            result = p.answers.recv()
            log.debug("inspected in %.1f ms", 1e3 * (time.monotonic() - t0))
        except (EOFError, OSError, BrokenPipeError):
            log.warning("an inspection process died loading a scene; starting another")
            self._retire(p)
            raise ApiError(422, CRASHED) from None
        self._idle.put(p)
        return result

    def wait_ready(self, timeout: float) -> None:
        """Wait (at most ``timeout`` seconds) until the idle processes have imported what inspections need (~2 s,
        done while the cluster starts), so that the first submissions to a new service do not wait for it."""
        deadline = time.monotonic() + timeout
        procs = []
        while True:
            try:
                procs.append(self._idle.get_nowait())
            except queue.Empty:
                break
        try:
            for p in procs:
                if not p.ready and p.answers.poll(max(0.0, deadline - time.monotonic())):
                    try:
                        p.ready = p.answers.recv() == "ready"
                    except (EOFError, OSError):
                        pass  # dead: its first use replaces it, as for any process that dies
        finally:
            for p in procs:
                self._idle.put(p)

    def close(self) -> None:
        self._closed = True
        with self._lock:
            procs = list(self._all)
            self._all.clear()
        for p in procs:
            p.kill()


if __name__ == "__main__":  # a pool process: python -m service.intake.inspection REQUESTS_FD ANSWERS_FD
    _serve(Connection(int(sys.argv[1]), writable=False), Connection(int(sys.argv[2]), readable=False))
