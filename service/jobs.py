"""Jobs: a SQLite job store that survives restarts, and supervised worker processes.

Design
------
- :class:`JobStore` keeps one row per job (kind, state, owner, progress, request, result summary,
  error, worker pid) in SQLite (WAL journal, so the worker processes can write progress while the
  server reads). Every server start has a *boot id*; on start, :meth:`JobStore.recover` marks the
  jobs another boot left ``queued`` or ``running`` as ``failed`` with the reason, and ends any
  process of theirs that is somehow still alive. A worker only finishes a job whose row is still
  ``running`` under its own boot id, so nothing late can overwrite what the new server recorded.
  A damaged database file is refused with :class:`identify.errors.InputError` naming the file.
- :class:`DataDirLock`: one server per data folder. The server holds an exclusive ``flock`` on
  ``<data_dir>/server.pid`` for its lifetime (the kernel drops it when the process dies, also on
  ``kill -9``); a second server on the same folder is refused naming the running server's pid,
  before it touches the job store.
- :class:`JobManager` admits at most ``capacity`` unfinished jobs (and ``per_key`` per API key;
  beyond either :class:`QueueFull`, the API answers 429 with ``Retry-After``) and runs each job in
  a fresh ``spawn`` process of its own, started by one supervisor thread, at most ``workers`` at
  once. Each worker process leads its own process group, so a cancel ends it and everything it
  started (``killpg`` with SIGKILL) within a supervisor tick. No worker outlives its server: on
  Linux the kernel sends SIGKILL to a worker when the server dies (``PR_SET_PDEATHSIG``, also set in
  every process the worker forks); elsewhere a watchdog thread polls the parent pid.
- Results live in ``<data_dir>/jobs/<id>/`` (files written by the job, renamed into place) and a
  small JSON summary in the row.
"""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import hashlib
import json
import multiprocessing
import os
import shutil
import signal
import sqlite3
import sys
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from identify.errors import InputError
from service.states import JobKind, JobState

#: Reason recorded for jobs cut off by a restart.
RESTART_REASON = "the service stopped while this job was {state} (server restart); submit it again"
#: Reason recorded for a job whose worker process ended without recording an end.
WORKER_DIED_REASON = "the worker process ended unexpectedly ({how}); submit it again"


class QueueFull(RuntimeError):
    """The bounded queue (or the caller's share of it) is full; retry after ``retry_after`` seconds."""

    def __init__(self, retry_after: int, message: str | None = None):
        super().__init__(message or f"the job queue is full; retry after {retry_after} s")
        self.retry_after = retry_after


class JobCancelled(RuntimeError):
    """Raised inside a worker when its job was cancelled."""


def owner_of(api_key: str | None) -> str:
    """The owner recorded with a job: a short digest of the API key (the key itself is never stored)."""
    return hashlib.sha256((api_key or "").encode()).hexdigest()[:16]


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
    boot : str
        Boot id of the server that admitted the job.
    owner : str
        Digest of the API key that submitted it (:func:`owner_of`).
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
    owner: str = ""


_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY, kind TEXT NOT NULL, state TEXT NOT NULL, boot TEXT NOT NULL,
    created REAL NOT NULL, started REAL, finished REAL, progress REAL NOT NULL DEFAULT 0,
    message TEXT NOT NULL DEFAULT '', request TEXT NOT NULL, result TEXT, error TEXT
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state);
"""
#: Columns added after the first release (added to older stores on open).
_ADDED = {"owner": "TEXT NOT NULL DEFAULT ''", "pid": "INTEGER", "pid_start": "TEXT", "files": "TEXT"}


def file_digest(path: Path) -> str:
    """SHA-256 of a file (hex): recorded when a job succeeds, checked when a result is served."""
    h = hashlib.sha256()
    with Path(path).open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def folder_digests(folder: Path) -> dict[str, str]:
    """``relative/path -> sha256`` of every file under ``folder``."""
    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): file_digest(p) for p in sorted(folder.rglob("*")) if p.is_file()}


class JobStore:
    """Job records in SQLite at ``path``; usable from the server and from worker processes.

    Raises :class:`InputError` naming the file when it is not a readable job store; with
    ``check=True`` (the server at start) the whole file is verified (``PRAGMA quick_check``).
    """

    def __init__(self, path: str | Path, *, check: bool = False):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._local = threading.local()
        try:
            conn = self._conn()
            conn.executescript(_SCHEMA)
            have = {row[1] for row in conn.execute("PRAGMA table_info(jobs)")}
            for col, decl in _ADDED.items():
                if col not in have:
                    conn.execute(f"ALTER TABLE jobs ADD COLUMN {col} {decl}")
            if check:
                problems = [r[0] for r in conn.execute("PRAGMA quick_check(3)")]
                if problems != ["ok"]:
                    raise sqlite3.DatabaseError("; ".join(str(p) for p in problems))
                conn.execute("SELECT id, request, result, error FROM jobs").fetchall()
        except sqlite3.DatabaseError as exc:
            self.close()
            raise InputError(f"damaged job store ({str(exc)[:200]}); move the file away to start with an "
                             f"empty store", source=str(self.path)) from None

    def _conn(self) -> sqlite3.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(self.path, timeout=30.0, isolation_level=None, check_same_thread=False)
            self._local.conn = conn
            conn.execute("PRAGMA busy_timeout=30000")
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
        return conn

    def close(self) -> None:
        conn = getattr(self._local, "conn", None)
        if conn is not None:
            conn.close()
            self._local.conn = None

    # ---- writes ----------------------------------------------------------------------
    def create(self, kind: JobKind, request: dict, boot: str, owner: str = "") -> JobRecord:
        job_id = uuid.uuid4().hex
        now = time.time()
        self._conn().execute(
            "INSERT INTO jobs (id, kind, state, boot, created, progress, message, request, owner) "
            "VALUES (?,?,?,?,?,?,?,?,?)",
            (job_id, kind.value, JobState.queued.value, boot, now, 0.0, "queued", json.dumps(request), owner))
        rec = self.get(job_id)
        assert rec is not None  # inserted just above
        return rec

    def start(self, job_id: str, boot: str) -> bool:
        """queued -> running; False when the job is no longer queued (cancelled, recovered)."""
        cur = self._conn().execute(
            "UPDATE jobs SET state=?, started=?, message=? WHERE id=? AND state=? AND boot=?",
            (JobState.running.value, time.time(), "running", job_id, JobState.queued.value, boot))
        return cur.rowcount == 1

    def set_worker(self, job_id: str, pid: int, pid_start: str | None) -> None:
        """Record the worker process (pid and its start time, to recognise it after a crash)."""
        self._conn().execute("UPDATE jobs SET pid=?, pid_start=? WHERE id=?", (pid, pid_start, job_id))

    def report(self, job_id: str, progress: float, message: str) -> JobState | None:
        """Record progress of a running job; returns the job's state (to notice a cancel)."""
        conn = self._conn()
        conn.execute("UPDATE jobs SET progress=?, message=? WHERE id=? AND state=?",
                     (float(min(max(progress, 0.0), 1.0)), message[:500], job_id, JobState.running.value))
        row = conn.execute("SELECT state FROM jobs WHERE id=?", (job_id,)).fetchone()
        return None if row is None else JobState(row[0])

    def finish(self, job_id: str, boot: str, state: JobState, *, result: dict | None = None,
               error: dict | None = None, message: str = "", files: dict[str, str] | None = None) -> bool:
        """Close a job that is still queued/running under ``boot``; False if it was closed already.

        ``files`` maps the result files (relative paths) to their SHA-256, checked when served.
        """
        cur = self._conn().execute(
            "UPDATE jobs SET state=?, finished=?, progress=COALESCE(?, progress), message=?, result=?, error=?, "
            "files=? WHERE id=? AND boot=? AND state IN (?, ?)",
            (state.value, time.time(), 1.0 if state is JobState.succeeded else None, message or state.value,
             None if result is None else json.dumps(result), None if error is None else json.dumps(error),
             None if files is None else json.dumps(files), job_id, boot, JobState.queued.value,
             JobState.running.value))
        return cur.rowcount == 1

    def mark_damaged(self, job_id: str, reason: str) -> None:
        """A succeeded job whose result files are unreadable becomes failed with the reason."""
        self._conn().execute(
            "UPDATE jobs SET state=?, message=?, error=? WHERE id=? AND state=?",
            (JobState.failed.value, reason[:500], json.dumps({"message": reason}), job_id,
             JobState.succeeded.value))

    def cancel(self, job_id: str) -> JobRecord | None:
        """Mark a queued or running job cancelled; returns the record (None if unknown)."""
        self._conn().execute(
            "UPDATE jobs SET state=?, finished=?, message=?, error=? WHERE id=? AND state IN (?, ?)",
            (JobState.cancelled.value, time.time(), "cancelled by the client",
             json.dumps({"message": "cancelled by the client"}), job_id, JobState.queued.value,
             JobState.running.value))
        return self.get(job_id)

    def recover(self, boot: str) -> int:
        """Fail the jobs that earlier boots left unfinished (ending any worker of theirs still
        alive); returns how many."""
        conn = self._conn()
        for pid, pid_start in conn.execute(
                "SELECT pid, pid_start FROM jobs WHERE state=? AND boot<>? AND pid IS NOT NULL",
                (JobState.running.value, boot)).fetchall():
            if pid_start is not None and process_start(pid) == pid_start:
                kill_group(pid)
        n = 0
        for state in (JobState.queued, JobState.running):
            reason = RESTART_REASON.format(state=state.value)
            cur = conn.execute(
                "UPDATE jobs SET state=?, finished=?, message=?, error=? WHERE state=? AND boot<>?",
                (JobState.failed.value, time.time(), reason, json.dumps({"message": reason}), state.value, boot))
            n += cur.rowcount
        return n

    # ---- reads -----------------------------------------------------------------------
    _COLUMNS = ("id, kind, state, created, started, finished, progress, message, request, result, error, boot, "
                "owner")

    def get(self, job_id: str) -> JobRecord | None:
        row = self._conn().execute(f"SELECT {self._COLUMNS} FROM jobs WHERE id=?", (job_id,)).fetchone()
        return None if row is None else self._record(row)

    def find(self, *, owner: str | None = None, kind: JobKind | None = None, state: JobState | None = None,
             limit: int = 50, offset: int = 0) -> tuple[list[JobRecord], int]:
        """Jobs newest first (of one ``owner``, ``kind``, ``state`` when given): ``limit`` of them from
        ``offset``, and how many match in all."""
        where, args = [], []
        for column, value in (("owner", owner), ("kind", kind and kind.value), ("state", state and state.value)):
            if value is not None:
                where.append(f"{column}=?")
                args.append(value)
        cond = f" WHERE {' AND '.join(where)}" if where else ""
        conn = self._conn()
        total = int(conn.execute(f"SELECT COUNT(*) FROM jobs{cond}", args).fetchone()[0])
        rows = conn.execute(f"SELECT {self._COLUMNS} FROM jobs{cond} ORDER BY created DESC, id LIMIT ? OFFSET ?",
                            [*args, int(limit), int(offset)]).fetchall()
        return [self._record(r) for r in rows], total

    @staticmethod
    def _record(row) -> JobRecord:
        return JobRecord(id=row[0], kind=JobKind(row[1]), state=JobState(row[2]), created=row[3], started=row[4],
                         finished=row[5], progress=float(row[6] or 0.0), message=row[7], request=json.loads(row[8]),
                         result=None if row[9] is None else json.loads(row[9]),
                         error=None if row[10] is None else json.loads(row[10]), boot=row[11], owner=row[12] or "")

    def files(self, job_id: str) -> dict[str, str] | None:
        """The result files' SHA-256 recorded when the job succeeded (None for older jobs)."""
        row = self._conn().execute("SELECT files FROM jobs WHERE id=?", (job_id,)).fetchone()
        return None if row is None or row[0] is None else json.loads(row[0])

    def count(self, states: tuple[JobState, ...] = (JobState.queued, JobState.running),
              owner: str | None = None) -> int:
        """Jobs in ``states`` (of one ``owner`` when given)."""
        marks = ",".join("?" * len(states))
        sql = f"SELECT COUNT(*) FROM jobs WHERE state IN ({marks})"
        args: tuple = tuple(s.value for s in states)
        if owner is not None:
            sql += " AND owner=?"
            args += (owner,)
        return int(self._conn().execute(sql, args).fetchone()[0])


# ---- one server per data folder -------------------------------------------------------------
class DataDirLock:
    """Exclusive lock on a data folder for one server process (``<folder>/server.pid``).

    ``acquire()`` raises :class:`InputError` naming the folder and the pid of the server holding it.
    The lock is an ``flock`` on an open file: the kernel releases it when the holder dies.
    """

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.path = self.folder / "server.pid"
        self._fd: int | None = None

    def acquire(self) -> DataDirLock:
        import fcntl

        self.folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.read(fd, 32).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise InputError(f"already served by another greybench serve (pid {holder}); stop it or set "
                             f"GREYBENCH_DATA_DIR to another folder", source=str(self.folder),
                             field="GREYBENCH_DATA_DIR") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing drops the flock
            self._fd = None


# ---- processes --------------------------------------------------------------------------
PR_SET_PDEATHSIG = 1


def process_start(pid: int) -> str | None:
    """Start time of a process (clock ticks since boot, from /proc), or None when unknown/gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat[stat.rindex(")") + 2:].split()[19]


def kill_group(pid: int) -> None:
    """SIGKILL the process group led by ``pid`` (falls back to the process alone)."""
    try:
        os.killpg(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signal.SIGKILL)


def _set_parent_death_signal() -> bool:
    """Ask the kernel to SIGKILL this process when its parent (thread) dies; Linux only."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def die_with_parent(parent_pid: int, interval: float = 0.5) -> None:
    """Make this process (and every process it forks later) end when ``parent_pid`` is gone."""
    linux = _set_parent_death_signal()
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(3)
    if linux:
        # forked children (e.g. a process pool of the pipeline) die with this process in turn
        os.register_at_fork(after_in_child=_set_parent_death_signal)
        return

    def watch() -> None:
        while True:
            if os.getppid() != parent_pid:
                try:
                    os.killpg(0, signal.SIGKILL)
                finally:
                    os._exit(3)
            time.sleep(interval)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def run_in_worker(db_path: str, boot: str, job_id: str, kind: str, request: dict, job_dir: str,
                  ray_address: str | None) -> str:
    """Run one job in this process and record its end in the store.

    Imports the pipeline lazily so the server process stays light.
    """
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
    except MemoryError:
        msg = "out of memory: the job needs more memory than this machine gives it"
        store.finish(job_id, boot, JobState.failed, error={"message": msg}, message=msg)
        return JobState.failed.value
    except Exception as exc:  # a bug or resource problem: recorded, never lost
        msg = f"internal error: {type(exc).__name__}: {exc}"
        store.finish(job_id, boot, JobState.failed, error={"message": msg}, message=msg[:500])
        return JobState.failed.value
    store.finish(job_id, boot, JobState.succeeded, result=result, message="done", files=folder_digests(Path(job_dir)))
    return JobState.succeeded.value


def _worker_main(parent_pid: int, threads: int, db_path: str, boot: str, job_id: str, kind: str, request: dict,
                 job_dir: str, ray_address: str | None) -> None:
    """Entry point of a worker process: own process group, dies with the server, sized thread pools."""
    with contextlib.suppress(OSError):
        os.setpgid(0, 0)
    die_with_parent(parent_pid)
    from identify.resources import configure_threads

    configure_threads(threads)
    run_in_worker(db_path, boot, job_id, kind, request, job_dir, ray_address)


class JobManager:
    """Admission, submission and cancellation of jobs over supervised worker processes.

    Parameters
    ----------
    store : JobStore
    jobs_dir : Path
        Parent of the per-job result folders.
    workers : int
        Jobs running at once (one process each).
    capacity : int
        Unfinished jobs admitted at once (running + waiting).
    retry_after : int
        Seconds suggested to a client refused with :class:`QueueFull`.
    per_key : int, optional
        Unfinished jobs admitted at once per owner (API key); default: ``capacity``.
    threads : int
        Threads each worker's torch/numba pools may use (see :mod:`identify.resources`).
    ray_address : str, optional
        Passed to the jobs: pose simulations as Ray tasks.
    """

    #: Seconds between supervisor passes (reaping, starting) when nothing wakes it earlier.
    TICK = 0.2

    def __init__(self, store: JobStore, jobs_dir: Path, *, workers: int, capacity: int, retry_after: int,
                 per_key: int | None = None, threads: int = 1, ray_address: str | None = None):
        self.store = store
        self.jobs_dir = Path(jobs_dir)
        self.jobs_dir.mkdir(parents=True, exist_ok=True)
        self.workers = workers
        self.capacity = capacity
        self.per_key = per_key or capacity
        self.retry_after = retry_after
        self.threads = max(1, int(threads))
        self.ray_address = ray_address
        self.boot = uuid.uuid4().hex
        self.recovered = store.recover(self.boot)
        self._ctx = multiprocessing.get_context("spawn")
        self._pending: deque[tuple[str, JobKind, dict]] = deque()
        self._running: dict[str, multiprocessing.process.BaseProcess] = {}
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        # One long-lived thread starts every worker: the kernel's parent-death signal follows the
        # creating *thread*, so workers must not be started from short-lived request threads.
        self._thread = threading.Thread(target=self._supervise, name="job-supervisor", daemon=True)
        self._thread.start()

    def job_dir(self, job_id: str) -> Path:
        return self.jobs_dir / job_id

    def check_admission(self, owner: str = "") -> None:
        """Raise :class:`QueueFull` when a job of ``owner`` would be refused now: a route whose checks are
        expensive (a placement search's planning) asks first, so a refused request costs nothing.
        :meth:`submit` checks again (another job may be admitted in between)."""
        with self._lock:
            self._admissible(owner)

    def _admissible(self, owner: str) -> None:
        # under self._lock
        if self.store.count() >= self.capacity:
            raise QueueFull(self.retry_after)
        mine = self.store.count(owner=owner)
        if mine >= self.per_key:
            raise QueueFull(self.retry_after, f"this API key has {mine} unfinished jobs, the limit per key "
                                              f"(GREYBENCH_JOBS_PER_KEY) is {self.per_key}; retry after "
                                              f"{self.retry_after} s")

    def submit(self, kind: JobKind, request: dict, prepare: Callable[[Path], None] | None = None,
               owner: str = "") -> JobRecord:
        """Admit and queue a job; raises :class:`QueueFull` when the queue or the owner's share is full.

        ``prepare(job_dir)`` may write inputs (e.g. the program text) before the job is queued.
        """
        with self._lock:
            self._admissible(owner)
            rec = self.store.create(kind, request, self.boot, owner)
            d = self.job_dir(rec.id)
            try:
                d.mkdir(parents=True, exist_ok=True)
                if prepare is not None:
                    prepare(d)
            except BaseException:
                self.store.finish(rec.id, self.boot, JobState.failed, error={"message": "could not store the inputs"})
                raise
            self._pending.append((rec.id, kind, request))
        self._wake.set()
        return rec

    def cancel(self, job_id: str) -> JobRecord | None:
        """Cancel a queued job, or end the worker process group of a running one at once."""
        with self._lock:
            rec = self.store.cancel(job_id)
            self._pending = deque(p for p in self._pending if p[0] != job_id)
            proc = self._running.get(job_id)
            if proc is not None and proc.pid is not None:
                kill_group(proc.pid)
        self._wake.set()
        return rec

    def active(self) -> int:
        with self._lock:
            return len(self._pending) + len(self._running)

    def running_pids(self) -> dict[str, int]:
        """Worker pid per running job (what a cancel or shutdown ends)."""
        with self._lock:
            return {k: p.pid for k, p in self._running.items() if p.pid is not None}

    # ---- supervisor ----------------------------------------------------------------------
    def _supervise(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(self.TICK)
            self._wake.clear()
            try:
                self._pass()
            except Exception as exc:  # never let the supervisor die silently: jobs would stall
                print(f"job supervisor: {type(exc).__name__}: {exc}", file=sys.stderr)

    def _pass(self) -> None:
        with self._lock:
            if self._stop.is_set():
                return
            for job_id, proc in list(self._running.items()):
                if proc.is_alive():
                    continue
                proc.join()
                del self._running[job_id]
                code = proc.exitcode
                if code:
                    how = f"signal {-code}" if code < 0 else f"exit code {code}"
                    msg = WORKER_DIED_REASON.format(how=how)
                    self.store.finish(job_id, self.boot, JobState.failed, error={"message": msg}, message=msg)
                rec = self.store.get(job_id)
                if rec is not None and rec.state is JobState.cancelled:
                    shutil.rmtree(self.job_dir(job_id), ignore_errors=True)  # partial files of a cancel
            while self._pending and len(self._running) < self.workers:
                job_id, kind, request = self._pending.popleft()
                rec = self.store.get(job_id)
                if rec is None or rec.state is not JobState.queued:
                    continue
                proc = self._ctx.Process(
                    target=_worker_main, name=f"greybench-job-{job_id[:8]}",
                    args=(os.getpid(), self.threads, str(self.store.path), self.boot, job_id, kind.value, request,
                          str(self.job_dir(job_id)), self.ray_address))
                proc.start()
                self._running[job_id] = proc
                assert proc.pid is not None  # set by start()
                self.store.set_worker(job_id, proc.pid, process_start(proc.pid))

    def shutdown(self) -> None:
        """End every worker process group; their jobs are recorded failed with the restart reason."""
        self._stop.set()
        self._wake.set()
        with self._lock:
            for proc in self._running.values():
                if proc.pid is not None:
                    kill_group(proc.pid)
            for job_id, proc in self._running.items():
                proc.join(5)
                reason = RESTART_REASON.format(state="running")
                self.store.finish(job_id, self.boot, JobState.failed, error={"message": reason}, message=reason)
            for job_id, _, _ in self._pending:
                reason = RESTART_REASON.format(state="queued")
                self.store.finish(job_id, self.boot, JobState.failed, error={"message": reason}, message=reason)
            self._running.clear()
            self._pending.clear()
        if self._thread is not threading.current_thread():
            self._thread.join(5)
