"""Small tiles go to Dask in batches: the plan's choice of tiles, the task keys the farm reads, and jobs whose tiles
share a task (a frame that fits in one batch is one task, tiles and EXR channels; same EXR as ``drt render``; a failed
batch retried tile by tile, each charged one attempt)."""
from __future__ import annotations

import collections
from pathlib import Path

import pytest

from renderer.film.tiles import split_tiles
from service.farm import tasks
from service.farm.dispatcher import FINISH, MAX_BATCH, FramePlan, JobPlan
from service.farm.view import parse_key

from service_helpers import assert_same_exr, cli_render, submit, wait_job

SMALL = {"width": 24, "height": 16, "spp": 2, "tile": 8}  # 6 tiles of 128 samples


def plan(width: int, height: int, tile: int, spp: int) -> JobPlan:
    boxes = split_tiles(width, height, tile)
    frame = FramePlan(idx=0, time=0.0, queue=collections.deque(range(len(boxes))), done=set())
    return JobPlan(job_id="j", state=None, priority=0, spec=None, scene_file=Path("x"), width=width, height=height,
                   spp=spp, boxes=boxes, frames=[frame], files=None)


def drain(p: JobPlan, batch: int) -> list[tuple[int, ...]]:
    out = []
    while (work := p.next_work(batch)) is not None and work[1] != (FINISH,):
        out.append(work[1])
    return out


def test_batches_fill_up_to_the_sample_budget_in_tile_order():
    p = plan(40, 16, 8, 4)  # 10 tiles of 256 samples
    assert drain(p, 1024) == [(0, 1, 2, 3), (4, 5, 6, 7), (8, 9)]
    assert drain(plan(40, 16, 8, 4), 1000) == [(0, 1, 2), (3, 4, 5), (6, 7, 8), (9,)]
    assert drain(plan(40, 16, 8, 4), 0) == [(i,) for i in range(10)]  # 0: one tile per task
    assert drain(plan(40, 16, 8, 4), 100) == [(i,) for i in range(10)]  # a tile larger than the budget goes alone


def test_edge_tiles_count_their_own_samples():
    p = plan(20, 8, 8, 1)  # tiles of 64, 64 and 32 samples
    assert drain(p, 96) == [(0,), (1, 2)]


def test_batches_stop_at_max_batch_and_solo_tiles_go_alone():
    p = plan(8 * (MAX_BATCH + 6), 8, 8, 1)
    batches = drain(p, 10 ** 9)
    assert [len(b) for b in batches] == [MAX_BATCH, 6]
    p = plan(48, 8, 8, 1)
    p.frames[0].solo.update({2, 3})
    assert drain(p, 10 ** 9) == [(0, 1), (2,), (3,), (4, 5)]


def test_the_frame_is_assembled_once_every_tile_is_done():
    p = plan(16, 8, 8, 1)
    f, tiles = p.next_work(1000)
    assert tiles == (0, 1) and p.next_work(1000) is None  # rendering: nothing else to do yet
    f.done.update(tiles)
    assert p.next_work(1000) == (f, (FINISH,))


def test_farm_reads_batch_keys():
    t = parse_key("drt-tile-abc123-2-4.5.6-0a1b2c3d")
    assert (t.kind, t.job_id, t.frame_index, t.tile, t.tiles) == ("tile", "abc123", 2, 4, [4, 5, 6])
    t = parse_key("drt-tile-abc123-0-7-0a1b2c3d")
    assert (t.tile, t.tiles) == (7, [7])
    t = parse_key("drt-frame-abc123-1--1-0a1b2c3d")
    assert (t.kind, t.tile, t.tiles) == ("frame", None, [])
    assert parse_key("drt-tile-abc123-0-4..5-0a1b2c3d") is None


_tasks: list = []
_assemblies: list = []


def counting_tile(task, scene):
    _tasks.append(task.tiles)
    return tasks.render_tile_task(task, scene)


def counting_assembly(task, scene):
    _assemblies.append(task.frame)
    return tasks.frame_image_task(task, scene)


@pytest.fixture
def counted(monkeypatch):
    import service.farm.dispatcher

    monkeypatch.setattr(service.farm.dispatcher, "render_tile_task", counting_tile)
    monkeypatch.setattr(service.farm.dispatcher, "frame_image_task", counting_assembly)
    _tasks.clear()
    _assemblies.clear()


def test_a_tiny_job_is_one_task_and_equals_drt_render(make_client, card, counted, tmp_path):
    client = make_client()
    job = wait_job(client, submit(client, card, SMALL).json()["id"])
    assert job["state"] == "succeeded" and job["tiles_done"] == job["tiles_total"] == 6, job
    assert job["samples_per_second"] > 0, job  # the tiles' samples and seconds were recorded
    assert _tasks == [tuple(split_tiles(24, 16, 8))] and _assemblies == []  # the tiles and the EXR: one task
    (tmp_path / "got.exr").write_bytes(client.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "want.exr", "--width", 24, "--height", 16, "--spp", 2)
    assert_same_exr(tmp_path / "got.exr", tmp_path / "want.exr")


def test_task_samples_zero_sends_one_tile_per_task(make_client, card, counted, tmp_path):
    client = make_client(task_samples=0)
    job = wait_job(client, submit(client, card, SMALL).json()["id"])
    assert job["state"] == "succeeded", job
    assert sorted(_tasks) == sorted((box,) for box in split_tiles(24, 16, 8)) and _assemblies == [0.0]
    (tmp_path / "got.exr").write_bytes(client.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "want.exr", "--width", 24, "--height", 16, "--spp", 2)
    assert_same_exr(tmp_path / "got.exr", tmp_path / "want.exr")


def test_frames_larger_than_a_batch_are_checkpointed_and_assembled(make_client, card, counted):
    client = make_client(task_samples=3 * 128)  # 6 tiles of 128 samples: two batches of three
    job = wait_job(client, submit(client, card, SMALL).json()["id"])
    assert job["state"] == "succeeded", job
    boxes = split_tiles(24, 16, 8)
    assert sorted(_tasks) == [tuple(boxes[:3]), tuple(boxes[3:])] and _assemblies == [0.0]


def test_a_one_tile_frame_larger_than_a_batch_keeps_its_checkpoint_and_assembly(make_client, card, counted):
    client = make_client(task_samples=100)  # the 24x16 frame in one tile of 768 samples
    job = wait_job(client, submit(client, card, {**SMALL, "tile": 32}).json()["id"])
    assert job["state"] == "succeeded", job
    assert _tasks == [((0, 0, 24, 16),)] and _assemblies == [0.0]


def test_a_time_limit_keeps_one_tile_per_task(make_client, card, counted):
    """A time limit is shared out per tile over the threads: a batch would render its tiles' shares in a row."""
    client = make_client()
    job = wait_job(client, submit(client, card, {**SMALL, "time_limit": 0.5}).json()["id"])
    assert job["state"] == "succeeded", job
    assert len(_tasks) == 6 and all(len(t) == 1 for t in _tasks)


def fails_once_with_tile_zero(task, scene):
    _tasks.append(task.tiles)
    if len(_tasks) == 1:
        assert (0, 0, 8, 8) in task.tiles
        raise RuntimeError("worker fell over")
    return tasks.render_tile_task(task, scene)


def test_a_failed_batch_is_retried_tile_by_tile(make_client, card, monkeypatch, tmp_path):
    import service.farm.dispatcher

    monkeypatch.setattr(service.farm.dispatcher, "render_tile_task", fails_once_with_tile_zero)
    _tasks.clear()
    client = make_client()
    job = wait_job(client, submit(client, card, SMALL).json()["id"])
    assert job["state"] == "succeeded", job
    boxes = split_tiles(24, 16, 8)
    assert _tasks[0] == tuple(boxes) and sorted(_tasks[1:]) == sorted((b,) for b in boxes)
    assert "drt_task_failures_total 1" in client.get("/metrics").text
    store = client.app.state.runtime.store
    attempts = store._query("SELECT tile_idx, attempts FROM tiles WHERE job_id = ?", (job["id"],))
    assert sorted(attempts) == [(t, 1) for t in range(6)]  # the batch's failure: one attempt charged to each
    (tmp_path / "got.exr").write_bytes(client.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "want.exr", "--width", 24, "--height", 16, "--spp", 2)
    assert_same_exr(tmp_path / "got.exr", tmp_path / "want.exr")


_race: dict = {}


def cancel_and_retry_meanwhile(task, scene):
    """The first task's job is canceled and retried while it renders (both before the scheduler's next look at the
    database): its result arrives for a job that is queued again, not running."""
    from service.queue import states as sm

    _tasks.append(task.tiles)
    result = tasks.render_tile_task(task, scene)
    if len(_tasks) == 1:
        store = _race["store"]
        (job_id,) = [row.id for row in store.active_jobs()]
        store.transition(job_id, sm.CANCELED)
        store.transition(job_id, sm.QUEUED)
    return result


@pytest.mark.parametrize("task_samples", [65536, 0], ids=["whole-frame", "tile-by-tile"])
def test_a_result_for_a_job_canceled_and_retried_meanwhile_is_rendered_again(make_client, card, monkeypatch,
                                                                            tmp_path, task_samples):
    """Its tiles cannot be recorded (the job is not running), so they go back to the queue: lost, the job would wait
    for them for ever (a CI run hung at 15 of 16 tiles after a quick cancel and retry; without the fix the
    whole-frame case here hangs every time, the tile-by-tile one when the result beats the job's new claim)."""
    import service.farm.dispatcher

    monkeypatch.setattr(service.farm.dispatcher, "render_tile_task", cancel_and_retry_meanwhile)
    _tasks.clear()
    client = make_client(task_samples=task_samples)
    _race["store"] = client.app.state.runtime.store
    # the job passes through "canceled" on its way back to the queue (the task's two transitions): a poll may see it
    # there, so wait for the end the test is about, and fail on "failed" or the timeout
    job = wait_job(client, submit(client, card, SMALL).json()["id"], timeout=60, until=("succeeded", "failed"))
    assert job["state"] == "succeeded" and job["tiles_done"] == job["tiles_total"] == 6, job
    (tmp_path / "got.exr").write_bytes(client.get(job["frames"][0]["exr_url"]).content)
    cli_render(card, tmp_path / "want.exr", "--width", 24, "--height", 16, "--spp", 2)
    assert_same_exr(tmp_path / "got.exr", tmp_path / "want.exr")
