"""The job state machine and the store's atomic transitions, claims and idempotency records."""
from __future__ import annotations

import sqlite3
import threading
import time

import pytest

from schemas import JobState
from service.queue import states as sm
from service.queue.store import JobActive, JobNotFound, Store, StoreBusy, decode_cursor, encode_cursor


def test_transition_table():
    assert sm.TRANSITIONS[JobState.queued] == {JobState.running, JobState.canceled, JobState.failed}
    assert sm.TRANSITIONS[JobState.running] == {JobState.succeeded, JobState.failed, JobState.canceled}
    assert sm.TERMINAL == {JobState.succeeded, JobState.failed, JobState.canceled}
    assert sm.sources(JobState.canceled) == {JobState.queued, JobState.running}
    with pytest.raises(sm.IllegalTransition):
        sm.check("j", JobState.succeeded, JobState.running)


def _job(store, job_id="a", priority=0, frames=(0.0,)):
    return store.create_job(job_id=job_id, priority=priority, settings_json="{}", scene_sha256="s" * 64,
                            scene_name="x.usda", scene_bytes=1, width=4, height=4, tile_size=2, tiles_per_frame=4,
                            frame_times=list(frames), exposure_scale=1.0, warnings=[])


@pytest.fixture
def store(tmp_path):
    s = Store(tmp_path / "db.sqlite3")
    yield s
    s.close()


def test_store_moves_jobs_through_the_table(store):
    row = _job(store)
    assert row.state == "queued" and [f.time for f in row.frames] == [0.0]
    row = store.transition("a", JobState.running)
    assert row.started_at is not None and row.finished_at is None
    with pytest.raises(sm.IllegalTransition) as e:
        store.transition("a", JobState.queued)
    assert e.value.current == JobState.running
    row = store.transition("a", JobState.succeeded)
    assert row.finished_at is not None
    with pytest.raises(sm.IllegalTransition):
        store.transition("a", JobState.canceled)
    with pytest.raises(JobNotFound):
        store.transition("nope", JobState.canceled)


def test_racing_transitions_have_one_winner(store):
    _job(store)
    store.transition("a", JobState.running)
    wins, losses = [], []

    def go(target):
        try:
            store.transition("a", target)
            wins.append(target)
        except sm.IllegalTransition:
            losses.append(target)

    threads = [threading.Thread(target=go, args=(t,)) for t in [JobState.succeeded, JobState.canceled] * 4]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(wins) == 1 and len(losses) == 7
    assert store.get_job("a").state == wins[0].value


def test_scheduling_order_priority_then_fifo(store):
    _job(store, "low1", 0)
    _job(store, "high", 5)
    _job(store, "low2", 0)
    assert [h.id for h in store.active_jobs()] == ["high", "low1", "low2"]


def test_tiles_are_recorded_once_and_only_while_running(store):
    _job(store)
    assert not store.tile_done("a", 0, 1, samples=10, seconds=0.1)  # queued: not running yet
    store.transition("a", JobState.running)
    assert store.tile_done("a", 0, 1, samples=10, seconds=0.1)
    assert not store.tile_done("a", 0, 1, samples=10, seconds=0.1)
    assert store.done_tiles("a") == {0: {1}}
    row = store.get_job("a")
    assert (row.tiles_done, row.samples_done, row.frames[0].tiles_done) == (1, 10, 1)
    store.forget_tiles("a", 0, {1})
    assert store.get_job("a").tiles_done == 0 and store.done_tiles("a") == {}
    assert store.tile_attempt("a", 0, 2, "boom") == 1
    assert store.tile_attempt("a", 0, 2, "boom") == 2


def test_delete_only_finished_jobs(store):
    _job(store)
    with pytest.raises(JobActive):
        store.delete_job("a")
    store.transition("a", JobState.canceled)
    assert store.delete_job("a").id == "a"
    with pytest.raises(JobNotFound):
        store.get_job("a")


def test_idempotency_claims(store):
    assert store.claim_key("k", "h1").outcome == "new"
    assert store.claim_key("k", "h1").outcome == "busy"
    assert store.claim_key("k", "h2").outcome == "conflict"
    _job(store, "a")
    store.create_job  # noqa: B018 - (the key is attached when a job is created with it)
    store.release_key("k")
    assert store.claim_key("k", "h1").outcome == "new"


def test_cursor_round_trip():
    assert decode_cursor(encode_cursor(42)) == 42
    for bad in ["", "xyz", encode_cursor(1)[:-2] + "!!"]:
        with pytest.raises(ValueError):
            decode_cursor(bad)


def test_active_jobs_are_counted_per_client_and_old_databases_gain_the_column(tmp_path):
    import sqlite3

    path = tmp_path / "db.sqlite3"
    Store(path).close()
    with sqlite3.connect(path) as db:  # a data directory from before the column existed
        db.execute("ALTER TABLE jobs DROP COLUMN client")
    store = Store(path)
    try:
        for job_id, client in (("a", "addr:1"), ("b", "addr:1"), ("c", "addr:2"), ("d", None)):
            store.create_job(job_id=job_id, priority=0, settings_json="{}", scene_sha256="s" * 64,
                             scene_name="x.usda", scene_bytes=1, width=4, height=4, tile_size=2, tiles_per_frame=4,
                             frame_times=[0.0], exposure_scale=1.0, warnings=[], client=client)
        store.transition("b", JobState.running)
        assert (store.count_active(), store.count_active("addr:1"), store.count_active("addr:2")) == (4, 2, 1)
        store.transition("a", JobState.canceled)
        store.transition("b", JobState.succeeded)
        assert (store.count_active(), store.count_active("addr:1")) == (2, 0)
    finally:
        store.close()


def test_cursor_sequence_numbers_stay_within_sqlite_integers():
    assert decode_cursor(encode_cursor(2**63 - 1)) == 2**63 - 1
    for seq in (2**63, 10**30):
        with pytest.raises(ValueError):
            decode_cursor(encode_cursor(seq))


def test_a_read_that_must_not_wait_is_refused_at_once_while_the_database_is_locked(tmp_path):
    """The status route reads on the event loop with ``wait=False``: a locked database must answer StoreBusy at once
    (the route then reads on the thread pool), never hold the loop for the 60 s busy timeout."""
    store = Store(tmp_path / "db.sqlite3")
    _job(store)
    store.close()  # another process can lock a WAL database exclusively only while no connection has it open
    locker = sqlite3.connect(tmp_path / "db.sqlite3", isolation_level=None)
    locker.execute("PRAGMA locking_mode=EXCLUSIVE")
    locker.execute("BEGIN EXCLUSIVE")
    seen = []

    def read():  # a thread of its own: the closed store's connections stay with the thread that opened them
        t0 = time.monotonic()
        try:
            store.get_job("a", wait=False)
            seen.append("read")
        except StoreBusy:
            seen.append(("busy", time.monotonic() - t0))
        released.wait(10)
        seen.append(store.get_job("a", wait=False).id)  # the same connection reads again once the lock is gone

    released = threading.Event()
    t = threading.Thread(target=read)
    t.start()
    while not seen and t.is_alive():
        time.sleep(0.01)
    locker.execute("COMMIT")
    locker.close()
    released.set()
    t.join(10)
    assert seen[0][0] == "busy" and seen[0][1] < 1.0, seen
    assert seen[1] == "a"
    store.close()
