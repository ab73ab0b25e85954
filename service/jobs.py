"""Jobs: a SQLite job store that survives restarts, and a bounded pool of worker processes.

Design
------
- :class:`JobStore` keeps one row per job (kind, state, progress, request, result summary, error)
  in SQLite (WAL journal, so the worker processes can write progress while the server reads).
  Every server start has a *boot id*; on start, :meth:`JobStore.recover` marks the jobs another boot
  left ``queued`` or ``running`` as ``failed`` with the reason (the process that ran them is gone).
  Workers end themselves when the server process disappears; and a worker only finishes a job
  whose row is still ``running`` under its own boot id, so a worker orphaned by a killed server
  cannot overwrite what the new server recorded.
- :class:`JobManager` runs jobs in a :class:`concurrent.futures.ProcessPoolExecutor` (``spawn``
  start method: safe next to the server's threads) and admits at most ``workers + queue_size``
  unfinished jobs; beyond that :class:`QueueFull` (the API answers 429 with ``Retry-After``).
- Cancelling: a queued job is cancelled at once; a running one is marked ``cancelled`` and the
  worker stops at its next progress report (cooperative: processes are never killed mid-write).
- Results live in ``<data_dir>/jobs/<id>/`` (files written by the job, renamed into place) and a
  small JSON summary in the row.
"""
from __future__ import annotations

import json
import multiprocessing
import sqlite3
import threading
import time
import uuid
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Callable

#: Reason recorded for jobs cut off by a restart.
RESTART_REASON = "the service stopped while this job was {state} (server restart); submit it again"


class JobState(str, Enum):
    """Life cycle of a job: queued -> running -> succeeded | failed | cancelled."""

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    cancelled = "cancelled"

    @property
    def finished(self) -> bool:
        return self in (JobState.succeeded, JobState.failed, JobState.cancelled)


class JobKind(str, Enum):
    """What a job computes."""

    simulation = "simulation"
    diagnose = "diagnose"
    explain = "explain"
    compensation = "compensation"


class QueueFull(RuntimeError):
    """The bounded queue is full; retry after ``retry_after`` seconds."""

    def __init__(self, retry_after: int):
        super().__init__(f"the job queue is full; retry after {retry_after} s")
        self.retry_after = retry_after


class JobCancelled(RuntimeError):
    """Raised inside a worker when its job was cancelled."""


@dataclass(frozen=True)
class JobRecord:
    """One row of the job store.

    Attributes
    ----------
    id, kind, state : job identity and life-cycle state
    created, started, finished : float or None
        Unix time [s].
    progress : float
        Fraction done, 0..1.
    message : str
        What the job is doing now (or did last).
    request : dict
        The validated request (as submitted).
    result : dict or None
        Summary of the result (files are in the job folder).
    error : dict or None
        ``{"message": ..., "source"/"line"/...}`` when failed or cancelled.
    """

    id: str
    kind: JobKind
    state: JobState
    created: float
    started: float | None
    finished: float | None
    progress: float
    message: str
    request: dict
    result: dict | None
    error: dict | None
    boot: str


_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY, kind TEXT NOT NULL, state TEXT NOT NULL, boot TEXT NOT NULL,
    created REAL NOT NULL, started REAL, finished REAL, progress REAL NOT NULL DEFAULT 0,
    message TEXT NOT NULL DEFAULT '', request TEXT NOT NULL, result TEXT, error TEXT
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state);
"""


class JobStore:
    """Job records in SQLite at ``path``; usable from the server and from worker processes."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._local = threading.local()
        with self._conn() as c:
            c.executescript(_SCHEMA)

    def _conn(self) -> sqlite3.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(self.path, timeout=30.0, isolation_level=None, check_same_thread=False)
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
            conn.execute("PRAGMA busy_timeout=30000")
            self._local.conn = conn
        return conn

    # ---- writes ----------------------------------------------------------------------
    def create(self, kind: JobKind, request: dict, boot: str) -> JobRecord:
        job_id = uuid.uuid4().hex
        now = time.time()
        self._conn().execute(
            "INSERT INTO jobs (id, kind, state, boot, created, progress, message, request) VALUES (?,?,?,?,?,?,?,?)",
            (job_id, kind.value, JobState.queued.value, boot, now, 0.0, "queued", json.dumps(request)))
        return self.get(job_id)

    def start(self, job_id: str, boot: str) -> bool:
        """queued -> running; False when the job is no longer queued (cancelled, recovered)."""
        cur = self._conn().execute(
            "UPDATE jobs SET state=?, started=?, message=? WHERE id=? AND state=? AND boot=?",
            (JobState.running.value, time.time(), "running", job_id, JobState.queued.value, boot))
        return cur.rowcount == 1

    def report(self, job_id: str, progress: float, message: str) -> JobState | None:
        """Record progress of a running job; returns the job's state (to notice a cancel)."""
        conn = self._conn()
        conn.execute("UPDATE jobs SET progress=?, message=? WHERE id=? AND state=?",
                     (float(min(max(progress, 0.0), 1.0)), message[:500], job_id, JobState.running.value))
        row = conn.execute("SELECT state FROM jobs WHERE id=?", (job_id,)).fetchone()
        return None if row is None else JobState(row[0])

    def finish(self, job_id: str, boot: str, state: JobState, *, result: dict | None = None,
               error: dict | None = None, message: str = "") -> bool:
        """Close a job that is still queued/running under ``boot``; False if it was closed already."""
        cur = self._conn().execute(
            "UPDATE jobs SET state=?, finished=?, progress=COALESCE(?, progress), message=?, result=?, error=? "
            "WHERE id=? AND boot=? AND state IN (?, ?)",
            (state.value, time.time(), 1.0 if state is JobState.succeeded else None, message or state.value,
             None if result is None else json.dumps(result), None if error is None else json.dumps(error),
             job_id, boot, JobState.queued.value, JobState.running.value))
        return cur.rowcount == 1

    def cancel(self, job_id: str) -> JobRecord | None:
        """Mark a queued or running job cancelled; returns the record (None if unknown)."""
        self._conn().execute(
            "UPDATE jobs SET state=?, finished=?, message=?, error=? WHERE id=? AND state IN (?, ?)",
            (JobState.cancelled.value, time.time(), "cancelled by the client",
             json.dumps({"message": "cancelled by the client"}), job_id, JobState.queued.value,
             JobState.running.value))
        return self.get(job_id)

    def recover(self, boot: str) -> int:
        """Fail the jobs that earlier boots left unfinished; returns how many."""
        conn = self._conn()
        n = 0
        for state in (JobState.queued, JobState.running):
            reason = RESTART_REASON.format(state=state.value)
            cur = conn.execute(
                "UPDATE jobs SET state=?, finished=?, message=?, error=? WHERE state=? AND boot<>?",
                (JobState.failed.value, time.time(), reason, json.dumps({"message": reason}), state.value, boot))
            n += cur.rowcount
        return n

    # ---- reads -----------------------------------------------------------------------
    def get(self, job_id: str) -> JobRecord | None:
        row = self._conn().execute(
            "SELECT id, kind, state, created, started, finished, progress, message, request, result, error, boot "
            "FROM jobs WHERE id=?", (job_id,)).fetchone()
        if row is None:
            return None
        return JobRecord(id=row[0], kind=JobKind(row[1]), state=JobState(row[2]), created=row[3], started=row[4],
                         finished=row[5], progress=float(row[6] or 0.0), message=row[7], request=json.loads(row[8]),
                         result=None if row[9] is None else json.loads(row[9]),
                         error=None if row[10] is None else json.loads(row[10]), boot=row[11])

    def count(self, states: tuple[JobState, ...] = (JobState.queued, JobState.running)) -> int:
        marks = ",".join("?" * len(states))
        return int(self._conn().execute(f"SELECT COUNT(*) FROM jobs WHERE state IN ({marks})",
                                        tuple(s.value for s in states)).fetchone()[0])


# ---- worker side ---------------------------------------------------------------------
def _exit_with_parent(parent_pid: int, interval: float = 0.5) -> None:
    """Pool initializer: end this worker when the server process is gone.

    A killed server leaves its workers orphaned (re-parented); without this they would run their
    job to the end and burn the shared cores. The job's row stays ``running`` and the next start
    marks it failed with the reason.
    """
    import os

    def watch() -> None:
        while True:
            if os.getppid() != parent_pid:
                os._exit(3)
            time.sleep(interval)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def run_in_worker(db_path: str, boot: str, job_id: str, kind: str, request: dict, job_dir: str,
                  ray_address: str | None) -> str:
    """Entry point of a worker process: run one job and record its end in the store.

    Imports the pipeline lazily so the server process stays light.
    """
    from identify.errors import InputError
    from service import pipeline

    store = JobStore(db_path)
    if not store.start(job_id, boot):
        return "skipped"

    def progress(fraction: float, message: str) -> None:
        state = store.report(job_id, fraction, message)
        if state is JobState.cancelled:
            raise JobCancelled(job_id)

    try:
        result = pipeline.run_job(JobKind(kind), request, Path(job_dir), progress, ray_address=ray_address)
    except JobCancelled:
        return JobState.cancelled.value
    except InputError as exc:
        store.finish(job_id, boot, JobState.failed, error=exc.to_dict(), message=str(exc))
        return JobState.failed.value
    except pipeline.StageUnavailable as exc:
        store.finish(job_id, boot, JobState.failed, error={"message": str(exc), "missing": exc.missing},
                     message=str(exc))
        return JobState.failed.value
    except Exception as exc:  # a bug or resource problem: recorded, never lost
        msg = f"internal error: {type(exc).__name__}: {exc}"
        store.finish(job_id, boot, JobState.failed, error={"message": msg}, message=msg[:500])
        return JobState.failed.value
    store.finish(job_id, boot, JobState.succeeded, result=result, message="done")
    return JobState.succeeded.value


class JobManager:
    """Admission, submission and cancellation of jobs over a bounded process pool.

    Parameters
    ----------
    store : JobStore
    jobs_dir : Path
        Parent of the per-job result folders.
    workers : int
        Worker processes.
    capacity : int
        Unfinished jobs admitted at once (running + waiting).
    retry_after : int
        Seconds suggested to a client refused with :class:`QueueFull`.
    ray_address : str, optional
        Passed to the jobs: pose simulations as Ray tasks.
    """

    def __init__(self, store: JobStore, jobs_dir: Path, *, workers: int, capacity: int, retry_after: int,
                 ray_address: str | None = None):
        self.store = store
        self.jobs_dir = Path(jobs_dir)
        self.jobs_dir.mkdir(parents=True, exist_ok=True)
        self.capacity = capacity
        self.retry_after = retry_after
        self.ray_address = ray_address
        self.boot = uuid.uuid4().hex
        self.recovered = store.recover(self.boot)
        import os

        self._pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                         initializer=_exit_with_parent, initargs=(os.getpid(),))
        self._futures: dict[str, Future] = {}
        self._lock = threading.Lock()

    def job_dir(self, job_id: str) -> Path:
        return self.jobs_dir / job_id

    def submit(self, kind: JobKind, request: dict, prepare: Callable[[Path], None] | None = None) -> JobRecord:
        """Admit and start a job; raises :class:`QueueFull` when the bounded queue is full.

        ``prepare(job_dir)`` may write inputs (e.g. the program text) before the job is queued.
        """
        with self._lock:
            self._futures = {k: f for k, f in self._futures.items() if not f.done()}
            if len(self._futures) >= self.capacity:
                raise QueueFull(self.retry_after)
            rec = self.store.create(kind, request, self.boot)
            d = self.job_dir(rec.id)
            d.mkdir(parents=True, exist_ok=True)
            if prepare is not None:
                prepare(d)
            fut = self._pool.submit(run_in_worker, str(self.store.path), self.boot, rec.id, kind.value, request,
                                    str(d), self.ray_address)
            fut.add_done_callback(lambda f, job_id=rec.id: self._on_done(job_id, f))
            self._futures[rec.id] = fut
        return rec

    def _on_done(self, job_id: str, fut: Future) -> None:
        # The worker records its own end; this catches a worker that died (BrokenProcessPool) or a
        # job cancelled before it started.
        if fut.cancelled():
            return
        exc = fut.exception()
        if exc is not None:
            msg = f"worker process failed: {type(exc).__name__}: {exc}"
            self.store.finish(job_id, self.boot, JobState.failed, error={"message": msg}, message=msg[:500])

    def cancel(self, job_id: str) -> JobRecord | None:
        with self._lock:
            fut = self._futures.get(job_id)
            if fut is not None:
                fut.cancel()  # succeeds only while queued in the pool
        return self.store.cancel(job_id)

    def active(self) -> int:
        with self._lock:
            return sum(1 for f in self._futures.values() if not f.done())

    def shutdown(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
