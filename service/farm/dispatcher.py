"""The dispatcher: one thread that turns queued jobs into tile tasks on Dask and finished tiles into frames.

Each turn it reads the active jobs from the database (priority, then first-in first-out), keeps at most
``max_in_flight`` tasks submitted (default: twice the cluster's worker threads), so that a new high-priority job
or a cancellation takes effect within about one tile's time, and waits for a task to finish or a wake-up.

* Workers see no file of the service: a job's scene goes to the cluster once per connection as a ``scene_package``
  task carrying the upload's bytes, and every tile task depends on it (Dask copies it to each worker that needs it).
* Small tiles share a task: a frame's next tiles up to ``task_samples`` samples together (``JobPlan.next_work``).
* Finished tiles come back as the task's result; this thread checkpoints each (atomically) on disk, then records
  them in the database. When all tiles of a frame are recorded, they are assembled here, a worker turns the sums
  into the frame's products (each one's channels and header as plain values, ``tasks.ProductImage``: it holds the
  prepared frame and the stage's RenderProducts), and this thread writes each atomically with the renderer's
  writer under its name (as ``drt render`` does), inside the job's folder whatever the productName says; the
  frame is marked done with its products' names and its tile checkpoints are removed. A frame that fits in one
  batch is rendered and made its products in one task (``tasks.whole_frame_task``: no checkpoint). The job
  succeeds when every frame is done.
* A job that left the active states (canceled, failed, deleted) has its tasks cancelled (running tiles stop at
  their next sample wave) and late results dropped.
* A task that raises (including a worker that died three times running it, Dask's ``KilledWorker``) is submitted
  again up to ``tile_retries`` times, one database record per attempt and tile, then the job fails with the
  message; the tiles of a failed batch are tried again one per task, so the tile that keeps failing is named.
  A renderer error (bad scene or settings) fails the job at once: trying again would give the same answer.
  A task lost with the connection to the scheduler (Dask cancels every future then) is not a failure: it is
  submitted again, without counting an attempt, once the cluster has reconnected.
* On start, jobs found ``running`` resume: tiles whose checkpoints are on disk are not rendered again.

All job state lives in the database; the plans held here are a cache of it, rebuilt after a restart.
"""
from __future__ import annotations

import collections
import logging
import queue
import threading
import time
import uuid
from dataclasses import dataclass, field

from pathlib import Path

from sqlalchemy.exc import IntegrityError

from renderer.film import film
from renderer.film.borders import check_tile
from renderer.film.tiles import Tile, split_tiles
from renderer.integrator.frame import assemble
from renderer.integrator.tile import TileSums
from schemas import JobCreate, JobState, product_name

from ..queue import states as sm
from ..queue.scenes import SceneStore
from ..queue.store import JobNotFound, Store
from ..settings import ServiceSettings
from ..spec import RenderSpec
from .cluster import Cluster, ClusterUnavailable
from .job_files import JobFiles, load_tile, save_tile
from .tasks import FrameTask, TileTask, frame_image_task, render_tile_task, scene_package, whole_frame_task

log = logging.getLogger("drt.dispatcher")

FINISH = -1  # the "tile index" of a frame's assembly task in attempt records
MAX_BATCH = 64  # tiles in one task at most (their indices name the task's Dask key)


class UnreadableCheckpoints(Exception):
    """Checkpoints of a frame that exist but cannot be read (a disk fault, a crash mid-write by another tool)."""

    def __init__(self, tiles: set[int]):
        super().__init__(f"unreadable tile checkpoints: {sorted(tiles)}")
        self.tiles = tiles


@dataclass
class FramePlan:
    idx: int
    time: float
    queue: collections.deque  # tile indices still to submit
    done: set[int]
    inflight: set[int] = field(default_factory=set)
    solo: set[int] = field(default_factory=set)  # tiles of a batch that failed: retried one per task
    finishing: bool = False
    finished: bool = False


@dataclass
class JobPlan:
    job_id: str
    state: JobState
    priority: int
    spec: RenderSpec  # its scene_path is the upload's file name: workers get the bytes, never a path of ours
    scene_file: Path  # the stored upload, in the data directory
    width: int
    height: int
    spp: int
    boxes: list[Tile]  # the frame's grid (split_tiles): a tile's index in it names its checkpoint
    frames: list[FramePlan]
    files: JobFiles

    def tile_samples(self, tile_idx: int) -> int:
        x0, y0, x1, y1 = self.boxes[tile_idx]
        return (x1 - x0) * (y1 - y0) * self.spp

    def next_work(self, batch_samples: int = 0) -> tuple[FramePlan, tuple[int, ...]] | None:
        """(frame, tile indices) to submit next as one task, or (frame, (FINISH,)) to assemble a frame, or None.

        Tiles go in batches of the frame's next tiles up to ``batch_samples`` samples together (always at least
        one; 0: one tile per task), so that a tiny job costs one task rather than one per tile. A tile that was
        in a failed batch goes alone, so that a failure is charged to the tile that fails."""
        for f in self.frames:
            if f.finished or f.finishing:
                continue
            if f.queue:
                first = f.queue.popleft()
                batch, samples = [first], self.tile_samples(first)
                while (first not in f.solo and f.queue and f.queue[0] not in f.solo and len(batch) < MAX_BATCH
                       and samples + self.tile_samples(f.queue[0]) <= batch_samples):
                    samples += self.tile_samples(f.queue[0])
                    batch.append(f.queue.popleft())
                return f, tuple(batch)
            if len(f.done) == len(self.boxes) and not f.inflight:
                return f, (FINISH,)
        return None


@dataclass
class InFlight:
    job_id: str
    frame_idx: int
    tiles: tuple[int, ...]  # the tiles the task renders, or (FINISH,)
    future: object
    submitted: float
    generation: int  # the cluster's client the future belongs to
    whole: bool = False  # every tile of the frame and its EXR channels in one task (no checkpoints)


class Dispatcher:
    def __init__(self, settings: ServiceSettings, store: Store, cluster: Cluster, scenes: SceneStore):
        self.settings = settings
        self.store = store
        self.cluster = cluster
        self.scenes = scenes
        self._events: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._plans: dict[str, JobPlan] = {}
        self._order: list[JobPlan] = []
        self._inflight: dict[str, InFlight] = {}
        self._scene_futures: dict[str, tuple[int, object]] = {}  # sha -> (client generation, scene_package future)
        self._generation = 0
        self._tile_times: collections.deque = collections.deque(maxlen=4096)
        self.tiles_completed = 0
        self.tiles_failed = 0
        self.tiles_lost = 0  # tasks lost with the scheduler connection and resubmitted (not failures)

    # -- lifecycle -------------------------------------------------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="drt-dispatcher", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._events.put(("wake", None))
        if self._thread is not None:
            self._thread.join(timeout=30)

    def wake(self) -> None:
        """Look at the database now (a job was created or canceled)."""
        self._events.put(("wake", None))

    # -- numbers for /metrics --------------------------------------------------------------------------------
    def in_flight(self) -> int:
        return len(self._inflight)

    def tiles_per_second(self, window: float = 60.0) -> float:
        now = time.monotonic()
        recent = [t for t in list(self._tile_times) if now - t <= window]
        if not recent:
            return 0.0
        return len(recent) / max(min(window, now - recent[0]), 1.0)

    def pending_tiles(self) -> int:
        return sum(len(f.queue) for p in list(self._plans.values()) for f in p.frames)

    # -- the loop ----------------------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._sync()
                self._fill()
                self._wait_and_handle()
            except Exception:  # noqa: BLE001 - the loop must outlive any one bad turn (database busy, etc.)
                log.exception("dispatcher turn failed; retrying")
                self._stop.wait(1.0)

    def _wait_and_handle(self) -> None:
        try:
            event = self._events.get(timeout=self.settings.poll_interval)
        except queue.Empty:
            return
        while True:
            kind, key = event
            if kind == "done":
                self._on_done(key)
            if self._stop.is_set():
                return
            try:
                event = self._events.get_nowait()
            except queue.Empty:
                return

    def _sync(self) -> None:
        if self._generation != self.cluster.generation:
            self._generation = self.cluster.generation
            self._scene_futures.clear()
            # The futures of an older client are gone (Dask cancelled them with the connection); their done
            # callbacks normally brought them back already, this catches any that did not.
            for key in [k for k, rec in self._inflight.items() if rec.generation != self._generation]:
                self._on_done(key)
        heads = self.store.active_jobs()
        active = {row.id for row in heads}
        for job_id in [j for j in self._plans if j not in active]:
            self._drop(job_id)
        order = []
        for row in heads:
            plan = self._plans.get(row.id)
            if plan is None:
                try:
                    plan = self._load(self.store.get_job(row.id))
                except JobNotFound:
                    continue
                except Exception as e:  # noqa: BLE001 - one unplannable job must not stall the others
                    log.exception("cannot plan job %s", row.id)
                    self._fail(row.id, f"the job cannot be planned: {type(e).__name__}: {e}")
                    continue
                if plan is None:
                    continue
                self._plans[row.id] = plan
            plan.state = row.state
            plan.priority = row.priority
            order.append(plan)
        self._order = order

    def _capacity(self) -> int:
        return self.settings.max_in_flight or 2 * max(1, self.cluster.threads())

    def _fill(self) -> None:
        if not self.cluster.available():
            return  # the cluster is reconnecting; queued work waits (nothing is charged)
        cap = self._capacity()
        for plan in list(self._order):
            if all(f.finished for f in plan.frames):  # e.g. stopped between its last frame and its success
                self._succeed(plan)
                continue
            # a time limit is shared out tile by tile over the threads: its tiles go one per task
            batch = 0 if plan.spec.request.options.time_limit else self.settings.task_samples
            while len(self._inflight) < cap:
                work = plan.next_work(batch)
                if work is None:
                    break
                frame, tiles = work
                if plan.state == sm.QUEUED and not self._claim(plan):
                    break  # canceled meanwhile: the plan is dropped
                # a frame that fits in one batch: its tiles and its EXR channels in one task, no checkpoints
                whole = (tiles != (FINISH,) and len(tiles) == len(plan.boxes)
                         and sum(map(plan.tile_samples, tiles)) <= batch)
                try:
                    self._submit(plan, frame, tiles, whole)
                except ClusterUnavailable as e:
                    log.info("cluster unavailable, holding work: %s", e)
                    return
                except UnreadableCheckpoints as e:
                    self._redo(plan, frame, e.tiles)
            if len(self._inflight) >= cap:
                return

    def _claim(self, plan: JobPlan) -> bool:
        try:
            self.store.transition(plan.job_id, sm.RUNNING)
        except (sm.IllegalTransition, JobNotFound):
            self._drop(plan.job_id)
            return False
        plan.state = sm.RUNNING
        return True

    def _scene(self, plan: JobPlan):
        """The future of the job's scene package on the current client (submitted once per scene and client)."""
        generation = self.cluster.generation
        held = self._scene_futures.get(plan.spec.scene_sha256)
        if held is not None and held[0] == generation and held[1].status in ("pending", "finished"):
            return held[1]
        data = plan.scene_file.read_bytes()
        key = f"drt-scene-{plan.spec.scene_sha256[:16]}-{uuid.uuid4().hex[:8]}"
        fut = self.cluster.submit(scene_package, plan.spec.scene_sha256, plan.spec.scene_path, data, key=key,
                                 priority=plan.priority + 2)
        self._scene_futures[plan.spec.scene_sha256] = (generation, fut)
        return fut

    def _frame_task(self, plan: JobPlan, frame: FramePlan) -> FrameTask:
        """The frame's checkpointed tiles, assembled (the sums ``render_frame`` would give: tiles are pure)."""
        parts, bad = [], set()
        margin = film.filter_margin(film.FILTERS[plan.spec.request.options.filter])
        for t, box in enumerate(plan.boxes):
            try:
                arrays = load_tile(plan.files.tile(frame.idx, t))
                check_tile(arrays, box, margin, plan.width, plan.height)  # e.g. an older layout: rendered again
                parts.append(TileSums(tile=box, arrays=arrays))
            except Exception:  # noqa: BLE001 - missing, truncated or garbage: np.load raises several kinds
                bad.add(t)
        if bad:
            raise UnreadableCheckpoints(bad)
        return FrameTask(spec=plan.spec, frame=frame.time, sums=assemble(parts, plan.width, plan.height),
                         cache_size=self.settings.scene_cache_size)

    def _submit(self, plan: JobPlan, frame: FramePlan, tiles: tuple[int, ...], whole: bool = False) -> None:
        s = self.settings
        finish = tiles == (FINISH,)
        try:
            scene = self._scene(plan)
            if finish:
                args = (frame_image_task, self._frame_task(plan, frame))
                kind, priority = "frame", plan.priority + 1
            else:
                task = TileTask(spec=plan.spec, frame=frame.time, tiles=tuple(plan.boxes[t] for t in tiles),
                                width=plan.width, height=plan.height, cache_size=s.scene_cache_size)
                args = (whole_frame_task, render_tile_task, task) if whole else (render_tile_task, task)
                kind, priority = "tile", plan.priority
            key = f"drt-{kind}-{plan.job_id}-{frame.idx}-{'.'.join(map(str, tiles))}-{uuid.uuid4().hex[:8]}"
            generation = self.cluster.generation
            future = self.cluster.submit(*args, scene, key=key, priority=priority)
        except BaseException:
            if not finish:
                frame.queue.extendleft(reversed(tiles))  # not submitted: they stay to do (the cluster may be back)
            raise
        if finish:
            frame.finishing = True
        else:
            frame.inflight.update(tiles)
        self._inflight[key] = InFlight(plan.job_id, frame.idx, tiles, future, time.monotonic(), generation, whole)
        future.add_done_callback(lambda fut, key=key: self._events.put(("done", key)))

    # -- results -----------------------------------------------------------------------------------------------
    def _on_done(self, key: str) -> None:
        rec = self._inflight.pop(key, None)
        plan = self._plans.get(rec.job_id) if rec is not None else None
        if rec is None or plan is None:
            return  # the job was dropped (canceled, failed) while this task ran
        try:
            self._handle(plan, rec)
        except IntegrityError:  # the job's rows vanished under us: it was canceled and deleted meanwhile
            self._drop(plan.job_id)

    def _handle(self, plan: JobPlan, rec: InFlight) -> None:
        frame = plan.frames[rec.frame_idx]
        fut = rec.future
        if fut.status == "finished":
            try:
                result = fut.result()
            except Exception as e:  # noqa: BLE001 - fetching the result can fail if its worker just died
                if not self.cluster.available() or rec.generation != self.cluster.generation:
                    self._lost(plan, frame, rec.tiles, f"{type(e).__name__}: {e}")
                else:
                    self._failed_attempt(plan, frame, rec.tiles, f"{type(e).__name__}: {e}")
                return
            if result.get("stopped"):
                return  # the job was canceled or failed while this tile ran; the plan is being dropped
            if "error" in result:
                self._fail(plan.job_id, result["error"])
            elif rec.tiles == (FINISH,):
                self._frame_image(plan, frame, result)
            elif rec.whole:
                self._whole_frame(plan, frame, rec.tiles, result)
            else:
                self._tiles_rendered(plan, frame, rec.tiles, result)
        elif fut.status == "error":
            exc = fut.exception()
            self._failed_attempt(plan, frame, rec.tiles, f"{type(exc).__name__}: {exc}")
        else:
            # Cancelled without our asking (we forget a future before we cancel it): Dask cancels every future
            # when the connection to the scheduler is lost. Not the tile's fault: it is submitted again.
            reason = getattr(getattr(fut, "_state", None), "exception", None)
            self._lost(plan, frame, rec.tiles, str(reason) if reason else f"task {fut.status}")

    @staticmethod
    def _what(frame: FramePlan, tiles: tuple[int, ...]) -> str:
        if tiles == (FINISH,):
            return f"frame {frame.time:g} assembly"
        if len(tiles) == 1:
            return f"tile {tiles[0]} of frame {frame.time:g}"
        return f"tiles {', '.join(map(str, tiles))} of frame {frame.time:g}"

    def _lost(self, plan: JobPlan, frame: FramePlan, tiles: tuple[int, ...], why: str) -> None:
        """A task the cluster lost: do it again, without counting an attempt."""
        self.tiles_lost += 1
        log.info("job %s: %s lost (%s); resubmitting", plan.job_id, self._what(frame, tiles),
                 " ".join(why.split())[:200])
        self._requeue(frame, tiles)

    @staticmethod
    def _requeue(frame: FramePlan, tiles: tuple[int, ...]) -> None:
        """The task's work is to do again, first in its frame's queue."""
        if tiles == (FINISH,):
            frame.finishing = False
        else:
            frame.inflight.difference_update(tiles)
            frame.queue.extendleft(reversed(tiles))

    def _redo(self, plan: JobPlan, frame: FramePlan, tiles: set[int]) -> None:
        """Render tiles again whose checkpoints cannot be read (not the tiles' fault: no attempt is counted)."""
        log.warning("job %s frame %g: %d tile checkpoint(s) unreadable, rendering them again", plan.job_id,
                    frame.time, len(tiles))
        for t in tiles:
            plan.files.tile(frame.idx, t).unlink(missing_ok=True)
        self.store.forget_tiles(plan.job_id, frame.idx, tiles)
        frame.done -= tiles
        frame.queue.extend(sorted(tiles))

    def _frame_image(self, plan: JobPlan, frame: FramePlan, result: dict) -> None:
        """Write the frame's products, each atomically, under their names made safe (``schemas.product_name``)."""
        written = []
        try:
            for p in result["products"]:
                name = product_name(p.name)
                if name is None or any(w["name"] == name for w in written):
                    log.warning("job %s frame %g: product %s (%r) not written: %s", plan.job_id, frame.time,
                                p.prim, p.name, "no usable name" if name is None else "its name is taken")
                    continue
                p.image.write(plan.files.product(frame.idx, name, create=True), half=p.halves)
                written.append({"name": name, "prim": p.prim})
        except FileNotFoundError:  # the job's files are gone: it was deleted
            self._drop(plan.job_id)
            return
        self._frame_written(plan, frame, written)

    def _tiles_rendered(self, plan: JobPlan, frame: FramePlan, tiles: tuple[int, ...], result: dict) -> None:
        frame.inflight.difference_update(tiles)
        try:
            for t, arrays in zip(tiles, result["arrays"], strict=True):
                save_tile(plan.files.tile(frame.idx, t), arrays)
        except FileNotFoundError:  # the job's files are gone: it was deleted
            self._drop(plan.job_id)
            return
        self._record_tiles(plan, frame, tiles, result["seconds"])

    def _record_tiles(self, plan: JobPlan, frame: FramePlan, tiles: tuple[int, ...], seconds: list[float]) -> None:
        """Record finished tiles (progress, samples, seconds) in one transaction and in the plan.

        The database records them only while the job is running. A job canceled and at once retried (before this
        thread looked at the database again) keeps its plan, and a result that arrives meanwhile cannot be recorded:
        its tiles go back to the frame's queue to be rendered again (a dropped plan never runs them)."""
        recorded = self.store.tiles_done(plan.job_id, frame.idx, [
            (t, plan.tile_samples(t), float(sec)) for t, sec in zip(tiles, seconds, strict=True)])
        now = time.monotonic()
        for t in recorded:
            frame.done.add(t)
            self.tiles_completed += 1
            self._tile_times.append(now)
        left = [t for t in tiles if t not in frame.done]
        if left:
            done = self.store.done_tiles(plan.job_id).get(frame.idx, set())  # e.g. a result that came twice
            frame.done.update(t for t in left if t in done)
            self._requeue(frame, tuple(t for t in left if t not in done))

    def _whole_frame(self, plan: JobPlan, frame: FramePlan, tiles: tuple[int, ...], result: dict) -> None:
        """A frame rendered in one task: its tiles are recorded (progress, samples, seconds) and its EXR written."""
        frame.inflight.difference_update(tiles)
        self._record_tiles(plan, frame, tiles, result["seconds"])
        if len(frame.done) != len(plan.boxes):
            return  # the job stopped running meanwhile (nothing recorded): dropped, or its tiles queued again
        self._frame_image(plan, frame, result)

    def _frame_written(self, plan: JobPlan, frame: FramePlan, products: list[dict]) -> None:
        frame.finishing = False
        frame.finished = True
        self.store.frame_done(plan.job_id, frame.idx, products)
        plan.files.remove_tiles(frame.idx)
        if all(f.finished for f in plan.frames):
            self._succeed(plan)

    def _succeed(self, plan: JobPlan) -> None:
        try:
            if plan.state == sm.QUEUED:
                self.store.transition(plan.job_id, sm.RUNNING)
            self.store.transition(plan.job_id, sm.SUCCEEDED)
        except (sm.IllegalTransition, JobNotFound):
            pass  # canceled at the last moment: the user's word stands
        self._drop(plan.job_id)

    def _failed_attempt(self, plan: JobPlan, frame: FramePlan, tiles: tuple[int, ...], message: str) -> None:
        """A task failed: an attempt is charged to each tile it carried (which one failed is not known), and the
        tiles of a batch are tried again one per task, so that a tile that keeps failing is named alone."""
        self.tiles_failed += 1
        message = " ".join(message.split())
        attempts = {t: self.store.tile_attempt(plan.job_id, frame.idx, t, error=message) for t in tiles}
        worst = max(attempts, key=attempts.get)
        if attempts[worst] <= self.settings.tile_retries:
            log.warning("%s of job %s failed (attempt %d), retrying%s: %s", self._what(frame, tiles), plan.job_id,
                        attempts[worst], " one by one" if len(tiles) > 1 else "", message)
            if len(tiles) > 1:
                frame.solo.update(tiles)
            self._requeue(frame, tiles)
            return
        self._fail(plan.job_id, f"{self._what(frame, (worst,))} failed after {attempts[worst]} attempts: {message}")

    def _fail(self, job_id: str, message: str) -> None:
        log.warning("job %s failed: %s", job_id, message)
        try:
            self.store.transition(job_id, sm.FAILED, error=message)
        except (sm.IllegalTransition, JobNotFound):
            pass
        self._drop(job_id)  # its other running tiles stop at their next sample wave

    def _drop(self, job_id: str) -> None:
        """Forget a job that is no longer active: cancel its tasks (queued ones never run, running ones stop)."""
        plan = self._plans.pop(job_id, None)
        self._order = [p for p in self._order if p.job_id != job_id]
        doomed = [k for k, rec in self._inflight.items() if rec.job_id == job_id]
        futures = [self._inflight.pop(k).future for k in doomed]
        if plan is not None and not any(p.spec.scene_sha256 == plan.spec.scene_sha256 for p in self._plans.values()):
            held = self._scene_futures.pop(plan.spec.scene_sha256, None)
            if held is not None:
                futures.append(held[1])  # no other job needs the scene: workers may forget its bytes
        if futures:
            self.cluster.cancel(futures)

    # -- plans ---------------------------------------------------------------------------------------------------
    def _load(self, row) -> JobPlan | None:
        """Build a job's plan from the database and its checkpoints (the resume path after a restart)."""
        settings = JobCreate.model_validate_json(row.settings_json)
        path = self.scenes.path(row.scene_sha256, row.scene_name)
        if not path.is_file():
            self._fail(row.id, "the job's scene is missing from the data directory")
            return None
        files = JobFiles(self.settings.data_dir, row.id)
        files.create(len(row.frames))
        boxes = split_tiles(row.width, row.height, row.tile_size)
        recorded = self.store.done_tiles(row.id)
        frames = []
        for fr in row.frames:
            done = set() if fr.done else {t for t in recorded.get(fr.idx, set()) if files.tile(fr.idx, t).is_file()}
            if not fr.done:
                self.store.forget_tiles(row.id, fr.idx, recorded.get(fr.idx, set()) - done)
            todo = collections.deque(t for t in range(len(boxes)) if t not in done and not fr.done)
            frames.append(FramePlan(idx=fr.idx, time=fr.time, queue=todo, done=done, finished=fr.done))
        if row.job_state == sm.RUNNING:
            log.info("resuming job %s: %d of %d tiles checkpointed", row.id, row.tiles_done, row.tiles_total)
        return JobPlan(job_id=row.id, state=row.job_state, priority=row.priority,
                       spec=RenderSpec.from_settings(settings, row.scene_name, row.scene_sha256,
                                                     tuple(row.product_aovs)), scene_file=path,
                       width=row.width, height=row.height, spp=settings.spp, boxes=boxes, frames=frames,
                       files=files)
