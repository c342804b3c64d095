"""The job store: SQLite through SQLAlchemy 2 (WAL mode), the only place job state lives.

Tables: ``jobs`` (one row per job), ``frames`` (one per frame of a job), ``tiles`` (one per tile that was
attempted: attempts, done, seconds: the checkpoint record), ``idempotency`` (Idempotency-Key -> job).

Reads of one job (``get_job``: the status request, the API's hot path) skip the ORM: one plain ``sqlite3``
connection per thread reads the job and its frames in one snapshot and fills detached ``JobRow``/``FrameRow``
objects, about 0.2 ms instead of 1.5-2 ms of SQLAlchemy session and query overhead under the GIL. So does the
bookkeeping every job goes through (submission: the Idempotency-Key claim, the queue counts, the insert; the
scheduler: active jobs, transitions, each finished tile and frame): plain SQL on one writer connection, about 4x
less CPU than building and running the same statements through SQLAlchemy, CPU that status requests waited for
(the GIL). SQLAlchemy keeps the schema, migrations and the rarer operations.

Concurrency: the API's threads and the scheduler's thread share one engine. Every state change is a single
conditional ``UPDATE`` (``WHERE state IN (...)``) so a claim or a transition is atomic, and write transactions
start with ``BEGIN IMMEDIATE`` so that two writers never deadlock upgrading a read lock; writers of this process
queue on a lock (``_write``), and ``busy_timeout`` covers any other process.
"""
from __future__ import annotations

import base64
import contextlib
import json
import sqlite3
import threading
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import (BigInteger, Boolean, Float, ForeignKey, Integer, String, Text, create_engine, delete, event,
                        func, select, update)
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column, relationship

from schemas import JobState

from . import states as sm


class Base(DeclarativeBase):
    pass


class JobRow(Base):
    __tablename__ = "jobs"

    seq: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)  # FIFO order and list cursor
    id: Mapped[str] = mapped_column(String(32), unique=True, index=True)
    state: Mapped[str] = mapped_column(String(16), index=True)
    priority: Mapped[int] = mapped_column(Integer)
    settings_json: Mapped[str] = mapped_column(Text)
    scene_sha256: Mapped[str] = mapped_column(String(64), index=True)
    scene_name: Mapped[str] = mapped_column(String(255))
    scene_bytes: Mapped[int] = mapped_column(BigInteger)
    width: Mapped[int] = mapped_column(Integer)
    height: Mapped[int] = mapped_column(Integer)
    tile_size: Mapped[int] = mapped_column(Integer)
    tiles_per_frame: Mapped[int] = mapped_column(Integer)
    tiles_total: Mapped[int] = mapped_column(Integer)
    tiles_done: Mapped[int] = mapped_column(Integer, default=0)
    samples_done: Mapped[int] = mapped_column(BigInteger, default=0)
    exposure_scale: Mapped[float] = mapped_column(Float, default=1.0)
    warnings_json: Mapped[str] = mapped_column(Text, default="[]")
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    created_at: Mapped[float] = mapped_column(Float)
    updated_at: Mapped[float] = mapped_column(Float)
    started_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    finished_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    client: Mapped[str | None] = mapped_column(String(80), nullable=True)  # who submitted it (queue limits)
    # AOVs rendered for the RenderVars of its products only, beyond the ones the settings ask for (inspection)
    product_aovs_json: Mapped[str] = mapped_column(Text, default="[]")

    frames: Mapped[list["FrameRow"]] = relationship(back_populates="job", cascade="all, delete-orphan",
                                                    order_by="FrameRow.idx", lazy="selectin",
                                                    passive_deletes=True)

    @property
    def job_state(self) -> JobState:
        return JobState(self.state)

    @property
    def warnings(self) -> list[str]:
        return json.loads(self.warnings_json)

    @property
    def product_aovs(self) -> list[str]:
        return json.loads(self.product_aovs_json or "[]")


class FrameRow(Base):
    __tablename__ = "frames"

    job_id: Mapped[str] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"), primary_key=True)
    idx: Mapped[int] = mapped_column(Integer, primary_key=True)
    time: Mapped[float] = mapped_column(Float)
    tiles_done: Mapped[int] = mapped_column(Integer, default=0)
    done: Mapped[bool] = mapped_column(Boolean, default=False)
    # the EXRs the frame wrote, once done: [{"name", "prim"}] in the settings' order; NULL for frames written by
    # a service before products (their one EXR is ``JobFiles.frame``)
    products_json: Mapped[str | None] = mapped_column(Text, nullable=True)

    job: Mapped[JobRow] = relationship(back_populates="frames")

    @property
    def products(self) -> list[dict] | None:
        return None if self.products_json is None else json.loads(self.products_json)


class TileRow(Base):
    __tablename__ = "tiles"

    job_id: Mapped[str] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"), primary_key=True)
    frame_idx: Mapped[int] = mapped_column(Integer, primary_key=True)
    tile_idx: Mapped[int] = mapped_column(Integer, primary_key=True)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    done: Mapped[bool] = mapped_column(Boolean, default=False)
    seconds: Mapped[float | None] = mapped_column(Float, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)


class IdempotencyRow(Base):
    __tablename__ = "idempotency"

    key: Mapped[str] = mapped_column(String(255), primary_key=True)
    request_hash: Mapped[str] = mapped_column(String(64))
    job_id: Mapped[str | None] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"), nullable=True)
    created_at: Mapped[float] = mapped_column(Float)


_JOB_COLUMNS = tuple(c.name for c in JobRow.__table__.columns)
_SELECT_JOB = f"SELECT {', '.join(_JOB_COLUMNS)} FROM jobs WHERE id = ?"
_SELECT_FRAMES = "SELECT idx, time, tiles_done, done, products_json FROM frames WHERE job_id = ? ORDER BY idx"
_INSERT_JOB = (f"INSERT INTO jobs ({', '.join(c for c in _JOB_COLUMNS if c != 'seq')}) "
               f"VALUES ({', '.join(':' + c for c in _JOB_COLUMNS if c != 'seq')})")
_ACTIVE = f"({', '.join(repr(x.value) for x in sorted(sm.ACTIVE))})"  # ('queued', 'running')


class JobNotFound(Exception):
    pass


class StoreBusy(Exception):
    """The database is locked and the caller asked not to wait."""


def _read_job(conn: sqlite3.Connection, job_id: str) -> JobRow:
    """The job with its frames, detached, read on ``conn`` inside the caller's transaction."""
    job = conn.execute(_SELECT_JOB, (job_id,)).fetchone()
    if job is None:
        raise JobNotFound(job_id)
    row = JobRow(**dict(zip(_JOB_COLUMNS, job)))
    row.frames = [FrameRow(job_id=job_id, idx=i, time=t, tiles_done=n, done=bool(d), products_json=p)
                  for i, t, n, d, p in conn.execute(_SELECT_FRAMES, (job_id,))]
    return row


class JobActive(Exception):
    """The job is queued or running (it must be canceled before it can be deleted)."""

    def __init__(self, state: JobState):
        super().__init__(state.value)
        self.state = state


@dataclass(frozen=True)
class JobHead:
    id: str
    state: JobState
    priority: int


@dataclass(frozen=True)
class Claim:
    """Outcome of claiming an Idempotency-Key: ``new`` (go ahead), ``existing`` (replay ``job_id``),
    ``conflict`` (same key, different request) or ``busy`` (the first request is still being processed)."""

    outcome: str
    job_id: str | None = None


def encode_cursor(seq: int) -> str:
    return base64.urlsafe_b64encode(f"seq:{seq}".encode()).decode().rstrip("=")


def decode_cursor(cursor: str) -> int:
    """The job sequence number in a cursor; ValueError if it is not one of ours."""
    try:
        text = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)).decode()
    except Exception:  # noqa: BLE001 - any garbage is the same client error
        raise ValueError("invalid cursor") from None
    digits = text[4:]
    # ASCII digits only (str.isdigit also accepts superscripts), and within SQLite's signed 64-bit integers.
    if not text.startswith("seq:") or not digits.isascii() or not digits.isdigit() or len(digits) > 19:
        raise ValueError("invalid cursor")
    seq = int(digits)
    if seq > 2**63 - 1:
        raise ValueError("invalid cursor")
    return seq


class Store:
    def __init__(self, path: Path, clear_claims: bool = True):
        """``clear_claims``: drop Idempotency-Key claims left by requests in flight when the service stopped; only
        the API process may, at its start (the coordinator's process opens the store while requests run)."""
        path.parent.mkdir(parents=True, exist_ok=True)
        # One connection per busy thread: status requests run on up to 40 threads at once, and SQLAlchemy's default
        # pool of 5 (+10) made them queue for a connection rather than for the database (WAL: readers never wait).
        self.engine = create_engine(f"sqlite:///{path}", connect_args={"check_same_thread": False, "timeout": 60},
                                    pool_size=16, max_overflow=48, pool_timeout=60)

        @event.listens_for(self.engine, "connect")
        def _connect(dbapi_conn, _record):
            dbapi_conn.isolation_level = None  # SQLAlchemy emits BEGIN itself (below), pysqlite must not
            cur = dbapi_conn.cursor()
            for pragma in ("journal_mode=WAL", "synchronous=NORMAL", "foreign_keys=ON", "busy_timeout=60000"):
                cur.execute(f"PRAGMA {pragma}")
            cur.close()

        @event.listens_for(self.engine, "begin")
        def _begin(conn):
            conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.get_execution_options().get("drt_write") else "BEGIN")

        self._writer = self.engine.execution_options(drt_write=True)
        self._path = path
        self._raw = None  # the plain writer connection, opened after the schema exists
        self._local = threading.local()
        self._readers: list[sqlite3.Connection] = []
        self._readers_lock = threading.Lock()
        self._write_lock = threading.Lock()
        Base.metadata.create_all(self.engine)
        self._migrate()
        self._raw = sqlite3.connect(path, check_same_thread=False, isolation_level=None, timeout=60)
        for pragma in ("synchronous=NORMAL", "foreign_keys=ON", "busy_timeout=60000"):
            self._raw.execute(f"PRAGMA {pragma}")
        if clear_claims:  # claims left by requests in flight when the service stopped can never complete
            with self._write() as s:
                s.execute(delete(IdempotencyRow).where(IdempotencyRow.job_id.is_(None)))

    def _migrate(self) -> None:
        """Columns added since a data directory was created (create_all only makes missing tables)."""
        with self._write() as s, s.begin():
            columns = {r[1] for r in s.connection().exec_driver_sql("PRAGMA table_info(jobs)")}
            if "client" not in columns:
                s.connection().exec_driver_sql("ALTER TABLE jobs ADD COLUMN client VARCHAR(80)")
            if "product_aovs_json" not in columns:
                s.connection().exec_driver_sql("ALTER TABLE jobs ADD COLUMN product_aovs_json TEXT DEFAULT '[]'")
            if "products_json" not in {r[1] for r in s.connection().exec_driver_sql("PRAGMA table_info(frames)")}:
                s.connection().exec_driver_sql("ALTER TABLE frames ADD COLUMN products_json TEXT")

    def close(self) -> None:
        with self._write_lock:
            if self._raw is not None:
                self._raw.close()
                self._raw = None
        with self._readers_lock:
            for conn in self._readers:
                conn.close()
            self._readers.clear()
        self.engine.dispose()

    def _reader(self, wait: bool = True) -> sqlite3.Connection:
        """This thread's read-only connection: one that waits up to 60 s for a lock, or (``wait=False``) one that
        never waits (SQLITE_BUSY at once)."""
        attr = "conn" if wait else "conn_nowait"
        conn = getattr(self._local, attr, None)
        if conn is None:
            conn = sqlite3.connect(self._path, check_same_thread=False, isolation_level=None,
                                   timeout=60 if wait else 0)
            conn.execute(f"PRAGMA busy_timeout={60000 if wait else 0}")
            conn.execute("PRAGMA query_only=ON")
            setattr(self._local, attr, conn)
            with self._readers_lock:
                self._readers.append(conn)
        return conn

    def _read(self) -> Session:
        return Session(self.engine, expire_on_commit=False)

    @contextlib.contextmanager
    def _write(self):
        """A session for one write transaction. This process is the database's only writer, so writers queue on a
        lock here: SQLite's own busy handler would make a waiting writer sleep in steps of up to 100 ms."""
        with self._write_lock, Session(self._writer, expire_on_commit=False) as s:
            yield s

    @contextlib.contextmanager
    def _tx(self):
        """One write transaction on the plain writer connection (queued on the same lock as ``_write``)."""
        with self._write_lock:
            conn = self._raw
            conn.execute("BEGIN IMMEDIATE")
            try:
                yield conn
            except BaseException:
                conn.execute("ROLLBACK")
                raise
            conn.execute("COMMIT")

    def _query(self, sql: str, params: tuple = ()) -> list[tuple]:
        """One read statement on this thread's plain connection (a statement is its own snapshot)."""
        return self._reader().execute(sql, params).fetchall()

    # -- jobs ---------------------------------------------------------------------------------------------------
    def create_job(self, *, job_id: str, priority: int, settings_json: str, scene_sha256: str, scene_name: str,
                   scene_bytes: int, width: int, height: int, tile_size: int, tiles_per_frame: int,
                   frame_times: list[float], exposure_scale: float, warnings: list[str],
                   idempotency_key: str | None = None, client: str | None = None,
                   product_aovs: list[str] = ()) -> JobRow:
        now = time.time()
        job = dict(id=job_id, state=sm.QUEUED.value, priority=priority, settings_json=settings_json,
                   scene_sha256=scene_sha256, scene_name=scene_name, scene_bytes=scene_bytes, width=width,
                   height=height, tile_size=tile_size, tiles_per_frame=tiles_per_frame,
                   tiles_total=tiles_per_frame * len(frame_times), tiles_done=0, samples_done=0,
                   exposure_scale=exposure_scale, warnings_json=json.dumps(warnings), error=None, created_at=now,
                   updated_at=now, started_at=None, finished_at=None, client=client,
                   product_aovs_json=json.dumps(list(product_aovs)))
        with self._tx() as c:
            c.execute(_INSERT_JOB, job)
            c.executemany("INSERT INTO frames (job_id, idx, time, tiles_done, done) VALUES (?, ?, ?, 0, 0)",
                          [(job_id, i, float(t)) for i, t in enumerate(frame_times)])
            if idempotency_key is not None:
                c.execute("UPDATE idempotency SET job_id = ? WHERE key = ?", (job_id, idempotency_key))
            return _read_job(c, job_id)  # as written: the coordinator may start it the moment this commits

    def get_job(self, job_id: str, *, wait: bool = True) -> JobRow:
        """The job with its frames, detached (a snapshot: both read in one transaction).

        ``wait=False`` never waits for a lock: it raises ``StoreBusy`` instead (for callers on the event loop, which
        must not block; in WAL mode a reader is refused only in rare moments, e.g. another process holding the
        database in exclusive mode or recovering it after a crash)."""
        conn = self._reader(wait)
        try:
            conn.execute("BEGIN")
            try:
                return _read_job(conn, job_id)
            finally:
                conn.execute("COMMIT")
        except sqlite3.OperationalError as e:
            if wait or (e.sqlite_errorcode & 0xFF) not in (sqlite3.SQLITE_BUSY, sqlite3.SQLITE_LOCKED):
                raise
            raise StoreBusy(job_id) from e

    def list_jobs(self, state: JobState | None, limit: int, before_seq: int | None) -> tuple[list[JobRow], int | None]:
        """Newest first. Returns (rows, seq to continue before, or None on the last page)."""
        q = select(JobRow).order_by(JobRow.seq.desc()).limit(limit + 1)
        if state is not None:
            q = q.where(JobRow.state == state.value)
        if before_seq is not None:
            q = q.where(JobRow.seq < before_seq)
        with self._read() as s:
            rows = list(s.scalars(q))
        more = len(rows) > limit
        rows = rows[:limit]
        return rows, (rows[-1].seq if more and rows else None)

    def transition(self, job_id: str, target: JobState, *, error: str | None = None) -> JobRow:
        """Move a job to ``target`` atomically; IllegalTransition if its current state does not allow it."""
        now = time.time()
        values: dict = {"state": ("?", target.value), "updated_at": ("?", now)}  # column -> (SQL, parameter)
        if target == sm.RUNNING:
            values["started_at"] = ("COALESCE(started_at, ?)", now)
        if target in sm.TERMINAL:
            values["finished_at"] = ("?", now)
        if error is not None:
            values["error"] = ("?", error)
        if target == sm.QUEUED:  # a retry: a fresh run (its own start time and speed) over the same checkpoints
            values.update(error=("?", None), started_at=("?", None), finished_at=("?", None),
                          samples_done=("?", 0))
        sources = sorted(x.value for x in sm.sources(target))
        sql = (f"UPDATE jobs SET {', '.join(f'{k} = {v}' for k, (v, _) in values.items())} "
               f"WHERE id = ? AND state IN ({', '.join('?' * len(sources))})")
        with self._tx() as c:
            if c.execute(sql, (*(p for _, p in values.values()), job_id, *sources)).rowcount == 0:
                current = c.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
                if current is None:
                    raise JobNotFound(job_id)
                raise sm.IllegalTransition(job_id, JobState(current[0]), target)
            if target == sm.QUEUED:  # failed attempts are forgotten, so that each tile has its retries again
                c.execute("DELETE FROM tiles WHERE job_id = ? AND done = 0", (job_id,))
            # the row as this transition left it: read after the commit, a retried job could already be running
            return _read_job(c, job_id)

    def delete_job(self, job_id: str) -> JobRow:
        """Delete a finished job (cascading to frames, tiles and idempotency keys); JobActive if it is not."""
        with self._write() as s, s.begin():
            row = s.scalar(select(JobRow).where(JobRow.id == job_id))
            if row is None:
                raise JobNotFound(job_id)
            if row.job_state not in sm.TERMINAL:
                raise JobActive(row.job_state)
            s.execute(delete(JobRow).where(JobRow.id == job_id))
        return row

    def scene_in_use(self, sha256: str) -> bool:
        return bool(self._query("SELECT EXISTS (SELECT 1 FROM jobs WHERE scene_sha256 = ?)", (sha256,))[0][0])

    def active_jobs(self) -> list[JobHead]:
        """Queued and running jobs in scheduling order: priority (high first), then first-in first-out."""
        rows = self._query(f"SELECT id, state, priority FROM jobs WHERE state IN {_ACTIVE} ORDER BY priority DESC, seq")
        return [JobHead(i, JobState(st), p) for i, st, p in rows]

    def count_active(self, client: str | None = None) -> int:
        """Jobs queued or running, of one client or (None) of all."""
        if client is None:
            return self._query(f"SELECT count(*) FROM jobs WHERE state IN {_ACTIVE}")[0][0]
        return self._query(f"SELECT count(*) FROM jobs WHERE state IN {_ACTIVE} AND client = ?", (client,))[0][0]

    def counts_by_state(self) -> dict[JobState, int]:
        counts = {st: 0 for st in JobState}
        with self._read() as s:
            for st, n in s.execute(select(JobRow.state, func.count()).group_by(JobRow.state)):
                counts[JobState(st)] = n
        return counts

    # -- change feed (server-sent events) -------------------------------------------------------------------------
    def changed_since(self, since: float) -> list[tuple[str, float, str]]:
        """(id, updated_at, state) of the jobs written at or after ``since`` (every write sets ``updated_at``)."""
        with self._read() as s:
            return [tuple(r) for r in s.execute(select(JobRow.id, JobRow.updated_at, JobRow.state)
                                                .where(JobRow.updated_at >= since))]

    def job_count(self) -> int:
        with self._read() as s:
            return s.scalar(select(func.count()).select_from(JobRow))

    def job_ids(self) -> set[str]:
        with self._read() as s:
            return set(s.scalars(select(JobRow.id)))

    # -- tiles and frames (the scheduler's records) ---------------------------------------------------------------
    def tile_attempt(self, job_id: str, frame_idx: int, tile_idx: int, error: str | None = None) -> int:
        """Count one more attempt at a tile; returns the number of attempts so far."""
        stmt = sqlite_insert(TileRow).values(job_id=job_id, frame_idx=frame_idx, tile_idx=tile_idx, attempts=1,
                                             done=False, error=error)
        stmt = stmt.on_conflict_do_update(index_elements=["job_id", "frame_idx", "tile_idx"],
                                          set_={"attempts": TileRow.attempts + 1, "error": error})
        with self._write() as s, s.begin():
            s.execute(stmt)
            return s.scalar(select(TileRow.attempts).where(TileRow.job_id == job_id, TileRow.frame_idx == frame_idx,
                                                           TileRow.tile_idx == tile_idx))

    def tile_done(self, job_id: str, frame_idx: int, tile_idx: int, samples: int, seconds: float) -> bool:
        """Record a checkpointed tile of a running job. False (nothing recorded) if the job is no longer running
        or the tile was already recorded."""
        return bool(self.tiles_done(job_id, frame_idx, [(tile_idx, samples, seconds)]))

    def tiles_done(self, job_id: str, frame_idx: int, tiles: list[tuple[int, int, float]]) -> list[int]:
        """Record checkpointed tiles (index, samples, seconds) of a running job in one transaction; returns the
        indices recorded (none if the job is no longer running; not those already recorded)."""
        recorded = []
        with self._tx() as c:
            for tile_idx, samples, seconds in tiles:
                tile = (job_id, frame_idx, tile_idx)
                already = c.execute("SELECT done FROM tiles WHERE job_id = ? AND frame_idx = ? AND tile_idx = ?",
                                    tile).fetchone()
                if already is not None and already[0]:
                    continue
                if c.execute("UPDATE jobs SET tiles_done = tiles_done + 1, samples_done = samples_done + ?, "
                             "updated_at = ? WHERE id = ? AND state = ?",
                             (samples, time.time(), job_id, sm.RUNNING.value)).rowcount == 0:
                    return recorded  # the job is no longer running
                c.execute("INSERT INTO tiles (job_id, frame_idx, tile_idx, attempts, done, seconds) "
                          "VALUES (?, ?, ?, 1, 1, ?) ON CONFLICT (job_id, frame_idx, tile_idx) "
                          "DO UPDATE SET done = 1, seconds = excluded.seconds, error = NULL", (*tile, seconds))
                c.execute("UPDATE frames SET tiles_done = tiles_done + 1 WHERE job_id = ? AND idx = ?",
                          (job_id, frame_idx))
                recorded.append(tile_idx)
        return recorded

    def done_tiles(self, job_id: str) -> dict[int, set[int]]:
        out: dict[int, set[int]] = defaultdict(set)
        for f, t in self._query("SELECT frame_idx, tile_idx FROM tiles WHERE job_id = ? AND done = 1", (job_id,)):
            out[f].add(t)
        return out

    def forget_tiles(self, job_id: str, frame_idx: int, tile_idxs: set[int]) -> None:
        """Un-record tiles whose checkpoint files are missing (they will be rendered again)."""
        if not tile_idxs:
            return
        with self._write() as s, s.begin():
            res = s.execute(update(TileRow).where(TileRow.job_id == job_id, TileRow.frame_idx == frame_idx,
                                                  TileRow.tile_idx.in_(tile_idxs), TileRow.done.is_(True))
                            .values(done=False))
            n = res.rowcount
            s.execute(update(FrameRow).where(FrameRow.job_id == job_id, FrameRow.idx == frame_idx)
                      .values(tiles_done=FrameRow.tiles_done - n))
            s.execute(update(JobRow).where(JobRow.id == job_id).values(tiles_done=JobRow.tiles_done - n))

    def frame_done(self, job_id: str, frame_idx: int, products: list[dict] | None = None) -> None:
        """The frame is written: its EXRs, ``[{"name", "prim"}]``, are what the API serves."""
        with self._tx() as c:
            c.execute("UPDATE frames SET done = 1, products_json = ? WHERE job_id = ? AND idx = ?",
                      (None if products is None else json.dumps(products), job_id, frame_idx))
            c.execute("UPDATE jobs SET updated_at = ? WHERE id = ?", (time.time(), job_id))

    # -- idempotency -------------------------------------------------------------------------------------------
    def claim_key(self, key: str, request_hash: str) -> Claim:
        for _ in range(3):  # the holder of the key may release it between our insert and our read
            try:
                with self._tx() as c:
                    c.execute("INSERT INTO idempotency (key, request_hash, job_id, created_at) VALUES (?, ?, NULL, ?)",
                              (key, request_hash, time.time()))
                return Claim("new")
            except sqlite3.IntegrityError:
                pass
            row = self._query("SELECT request_hash, job_id FROM idempotency WHERE key = ?", (key,))
            if not row:
                continue
            held_hash, job_id = row[0]
            if held_hash != request_hash:
                return Claim("conflict", job_id)
            if job_id is None:
                return Claim("busy")
            return Claim("existing", job_id)
        return Claim("busy")

    def release_key(self, key: str) -> None:
        """Forget a claim whose request failed (so that a corrected retry may use the key)."""
        with self._tx() as c:
            c.execute("DELETE FROM idempotency WHERE key = ? AND job_id IS NULL", (key,))
