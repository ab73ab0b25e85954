"""Job handling: the store's life cycle and guards, admission limits, recovery, worker outcomes.

No worker process is started here (``workers=0``); worker exits are simulated with stand-in
process objects, so every test runs in milliseconds."""
from __future__ import annotations

import hashlib
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time

import pytest

from identify.errors import InputError
from service import jobs
from service.jobs import (
    RESTART_REASON,
    WORKER_DIED_REASON,
    DataDirLock,
    JobCancelled,
    JobKind,
    JobManager,
    JobState,
    JobStore,
    QueueFull,
    file_digest,
    folder_digests,
    kill_group,
    owner_of,
    process_start,
    run_in_worker,
)


@pytest.fixture
def store(tmp_path):
    s = JobStore(tmp_path / "db" / "jobs.sqlite")
    yield s
    s.close()


def test_states_kinds_and_errors():
    assert [s.value for s in JobState] == ["queued", "running", "succeeded", "failed", "cancelled"]
    assert [s.finished for s in JobState] == [False, False, True, True, True]
    assert JobKind("compensation") is JobKind.compensation
    q = QueueFull(7)
    assert q.retry_after == 7 and str(q) == "the job queue is full; retry after 7 s"
    assert str(QueueFull(3, "mine")) == "mine"
    assert owner_of("k") == hashlib.sha256(b"k").hexdigest()[:16]
    assert owner_of(None) == owner_of("") == hashlib.sha256(b"").hexdigest()[:16]
    assert owner_of("a") != owner_of("b")


def test_digests(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.txt").write_bytes(b"abc")
    big = os.urandom((1 << 20) + 17)                 # more than one read chunk
    (tmp_path / "sub" / "b.bin").write_bytes(big)
    assert file_digest(tmp_path / "a.txt") == hashlib.sha256(b"abc").hexdigest()
    assert folder_digests(tmp_path) == {"a.txt": hashlib.sha256(b"abc").hexdigest(),
                                        "sub/b.bin": hashlib.sha256(big).hexdigest()}


def test_life_cycle(store):
    t0 = time.time()
    rec = store.create(JobKind.simulation, {"a": 1}, "boot1", owner="own")
    assert rec.state is JobState.queued and rec.kind is JobKind.simulation and rec.request == {"a": 1}
    assert rec.boot == "boot1" and rec.owner == "own" and rec.message == "queued" and rec.progress == 0.0
    assert rec.started is None and rec.finished is None and rec.result is None and rec.error is None
    assert t0 - 1 <= rec.created <= time.time() + 1
    assert not store.start(rec.id, "other-boot")               # only its own boot starts it
    assert store.start(rec.id, "boot1")
    assert not store.start(rec.id, "boot1")                    # not twice
    r = store.get(rec.id)
    assert r.state is JobState.running and r.message == "running" and r.started is not None
    assert store.report(rec.id, 0.25, "step 1") is JobState.running
    assert store.get(rec.id).progress == 0.25 and store.get(rec.id).message == "step 1"
    store.report(rec.id, 7.0, "x" * 900)
    r = store.get(rec.id)
    assert r.progress == 1.0 and len(r.message) == 500
    store.report(rec.id, -3.0, "back")
    assert store.get(rec.id).progress == 0.0
    assert store.report("nope", 0.5, "m") is None
    assert not store.finish(rec.id, "other-boot", JobState.succeeded)
    assert store.finish(rec.id, "boot1", JobState.succeeded, result={"ok": 1}, files={"f": "d"})
    r = store.get(rec.id)
    assert r.state is JobState.succeeded and r.progress == 1.0 and r.result == {"ok": 1} and r.message == "succeeded"
    assert r.finished is not None and r.error is None
    assert store.files(rec.id) == {"f": "d"}
    assert not store.finish(rec.id, "boot1", JobState.failed)  # closed already: nothing late overwrites it
    store.report(rec.id, 0.1, "late")
    assert store.get(rec.id).message == "succeeded"
    store.mark_damaged(rec.id, "file gone")
    r = store.get(rec.id)
    assert r.state is JobState.failed and r.message == "file gone" and r.error == {"message": "file gone"}
    assert store.get("nope") is None and store.files("nope") is None


def test_failed_finish_keeps_progress_and_message(store):
    rec = store.create(JobKind.diagnose, {}, "b")
    store.start(rec.id, "b")
    store.report(rec.id, 0.4, "half")
    assert store.finish(rec.id, "b", JobState.failed, error={"message": "bad"}, message="it broke")
    r = store.get(rec.id)
    assert r.progress == 0.4 and r.message == "it broke" and r.error == {"message": "bad"}
    assert store.files(rec.id) is None
    rec2 = store.create(JobKind.diagnose, {}, "b")          # a queued job may be closed too
    assert store.finish(rec2.id, "b", JobState.failed)
    assert store.get(rec2.id).message == "failed"


def test_cancel_and_count(store):
    a = store.create(JobKind.simulation, {}, "b", owner="x")
    b = store.create(JobKind.simulation, {}, "b", owner="y")
    c = store.create(JobKind.explain, {}, "b", owner="x")
    store.start(b.id, "b")
    assert store.count() == 3 and store.count(owner="x") == 2 and store.count(owner="z") == 0
    assert store.count((JobState.running,)) == 1 and store.count((JobState.queued,), owner="x") == 2
    r = store.cancel(a.id)
    assert r.state is JobState.cancelled and r.message == "cancelled by the client"
    assert r.error == {"message": "cancelled by the client"} and r.finished is not None
    assert store.report(b.id, 0.5, "m") is JobState.running
    assert store.cancel(b.id).state is JobState.cancelled
    assert store.report(b.id, 0.5, "m") is JobState.cancelled
    store.finish(c.id, "b", JobState.succeeded)
    assert store.cancel(c.id).state is JobState.succeeded      # a finished job stays as it is
    assert store.cancel("nope") is None
    assert store.count() == 0 and store.count((JobState.cancelled,)) == 2


def test_recover_fails_other_boots_jobs_with_the_reason(store):
    q = store.create(JobKind.simulation, {}, "old")
    r = store.create(JobKind.simulation, {}, "old")
    store.start(r.id, "old")
    mine = store.create(JobKind.simulation, {}, "new")
    done = store.create(JobKind.simulation, {}, "old")
    store.finish(done.id, "old", JobState.succeeded)
    assert store.recover("new") == 2
    rq, rr = store.get(q.id), store.get(r.id)
    assert rq.state is JobState.failed and rq.message == RESTART_REASON.format(state="queued")
    assert rr.state is JobState.failed and rr.error == {"message": RESTART_REASON.format(state="running")}
    assert "queued" in rq.message and "running" in rr.message and rr.finished is not None
    assert store.get(mine.id).state is JobState.queued and store.get(done.id).state is JobState.succeeded
    assert store.recover("new") == 0


def test_recover_ends_a_surviving_worker_of_an_old_boot(store):
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], start_new_session=True)
    try:
        rec = store.create(JobKind.simulation, {}, "old")
        store.start(rec.id, "old")
        store.set_worker(rec.id, proc.pid, process_start(proc.pid))
        stale = store.create(JobKind.simulation, {}, "old")
        store.start(stale.id, "old")
        store.set_worker(stale.id, proc.pid, "1")             # a recycled pid: left alone
        assert store.recover("new") == 2
        assert proc.wait(10) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_process_start_and_kill_group():
    me = process_start(os.getpid())
    assert me is not None and me.isdigit() and me == process_start(os.getpid())
    assert process_start(2 ** 30) is None
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])   # not a group leader
    kill_group(proc.pid)
    assert proc.wait(10) == -signal.SIGKILL
    kill_group(proc.pid)          # gone: no error


def test_store_schema_upgrade_and_damaged_file(tmp_path):
    old = tmp_path / "old.sqlite"
    conn = sqlite3.connect(old)
    conn.executescript(jobs._SCHEMA)
    conn.execute("INSERT INTO jobs (id, kind, state, boot, created, request) VALUES ('j', 'simulation', 'queued', "
                 "'b', 1.0, '{}')")
    conn.commit()
    conn.close()
    s = JobStore(old, check=True)
    assert s.get("j").owner == "" and s.files("j") is None
    cols = {r[1] for r in s._conn().execute("PRAGMA table_info(jobs)")}
    assert {"owner", "pid", "pid_start", "files"} <= cols
    s.close()
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(b"not a database at all" * 100)
    with pytest.raises(InputError) as e:
        JobStore(bad)
    assert e.value.source == str(bad) and "damaged job store" in e.value.message


def test_data_dir_lock(tmp_path):
    a = DataDirLock(tmp_path / "d").acquire()
    assert (tmp_path / "d" / "server.pid").read_text() == f"{os.getpid()}\n"
    with pytest.raises(InputError) as e:
        DataDirLock(tmp_path / "d").acquire()
    assert e.value.field == "GREYBENCH_DATA_DIR" and e.value.source == str(tmp_path / "d")
    assert f"pid {os.getpid()}" in e.value.message
    a.release()
    a.release()
    b = DataDirLock(tmp_path / "d").acquire()
    b.release()


class _Dead:
    """Stands in for a finished worker process."""

    def __init__(self, exitcode, pid=None):
        self.exitcode = exitcode
        self.pid = pid

    def is_alive(self):
        return False

    def join(self, timeout=None):
        pass


@pytest.fixture
def manager(tmp_path, store):
    m = JobManager(store, tmp_path / "jobs", workers=0, capacity=3, retry_after=9, per_key=2)
    yield m
    m.shutdown()


def test_manager_admission_limits(manager, store):
    assert manager.per_key == 2 and manager.threads == 1 and manager.recovered == 0
    a = manager.submit(JobKind.simulation, {"n": 1}, owner="k1")
    manager.submit(JobKind.simulation, {"n": 2}, owner="k1")
    with pytest.raises(QueueFull) as e:
        manager.submit(JobKind.simulation, {}, owner="k1")
    assert e.value.retry_after == 9
    assert "2 unfinished jobs" in str(e.value) and "GREYBENCH_JOBS_PER_KEY" in str(e.value) and "is 2" in str(e.value)
    manager.submit(JobKind.simulation, {}, owner="k2")
    with pytest.raises(QueueFull) as e:
        manager.submit(JobKind.simulation, {}, owner="k3")
    assert str(e.value) == "the job queue is full; retry after 9 s"
    assert manager.active() == 3 and store.count() == 3
    assert manager.job_dir(a.id) == manager.jobs_dir / a.id and manager.job_dir(a.id).is_dir()
    assert manager.cancel(a.id).state is JobState.cancelled
    assert manager.active() == 2
    manager.submit(JobKind.simulation, {}, owner="k1")       # a freed slot, also for its owner


def test_manager_defaults(tmp_path, store):
    m = JobManager(store, tmp_path / "j", workers=0, capacity=2, retry_after=1, threads=0)
    try:
        assert m.per_key == 2 and m.threads == 1 and m.TICK == 0.2
    finally:
        m.shutdown()


def test_submit_runs_prepare_and_fails_the_job_when_it_raises(manager, store):
    seen = []
    rec = manager.submit(JobKind.simulation, {}, prepare=lambda d: seen.append(d))
    assert seen == [manager.job_dir(rec.id)]

    def broken(_d):
        raise OSError("disk full")

    with pytest.raises(OSError):
        manager.submit(JobKind.simulation, {}, prepare=broken)
    failed = store.count((JobState.failed,))
    assert failed == 1 and manager.active() == 1


def test_shutdown_fails_queued_jobs_with_the_restart_reason(tmp_path, store):
    m = JobManager(store, tmp_path / "j", workers=0, capacity=5, retry_after=1)
    rec = m.submit(JobKind.simulation, {})
    m.shutdown()
    r = store.get(rec.id)
    assert r.state is JobState.failed and r.message == RESTART_REASON.format(state="queued")
    assert m.active() == 0


def test_supervisor_records_a_dead_worker_and_cleans_a_cancelled_job(manager, store):
    a = store.create(JobKind.simulation, {}, manager.boot)
    store.start(a.id, manager.boot)
    b = store.create(JobKind.simulation, {}, manager.boot)
    store.start(b.id, manager.boot)
    store.cancel(b.id)
    manager.job_dir(b.id).mkdir()
    (manager.job_dir(b.id) / "partial.csv").write_text("x")
    c = store.create(JobKind.simulation, {}, manager.boot)
    store.start(c.id, manager.boot)
    store.finish(c.id, manager.boot, JobState.succeeded)
    manager.job_dir(c.id).mkdir()
    d = store.create(JobKind.simulation, {}, manager.boot)
    store.start(d.id, manager.boot)
    with manager._lock:
        manager._running.update({a.id: _Dead(-9), b.id: _Dead(0), c.id: _Dead(0), d.id: _Dead(3)})
    manager._pass()
    assert manager.running_pids() == {} and manager.active() == 0
    ra = store.get(a.id)
    assert ra.state is JobState.failed and ra.message == WORKER_DIED_REASON.format(how="signal 9")
    assert store.get(d.id).error == {"message": WORKER_DIED_REASON.format(how="exit code 3")}
    assert not manager.job_dir(b.id).exists()                  # partial files of a cancel removed
    assert manager.job_dir(c.id).exists() and store.get(c.id).state is JobState.succeeded


def test_running_pids_and_cancel_ends_the_worker_group(manager, store):
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], start_new_session=True)
    try:
        rec = store.create(JobKind.simulation, {}, manager.boot)
        store.start(rec.id, manager.boot)
        with manager._lock:
            manager._running[rec.id] = _Dead(None, pid=proc.pid)
            manager._running["nopid"] = _Dead(None, pid=None)
        assert manager.running_pids() == {rec.id: proc.pid}
        manager.cancel(rec.id)
        assert proc.wait(10) == -signal.SIGKILL
        with manager._lock:
            manager._running.clear()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _run(store, tmp_path, monkeypatch, outcome):
    from service import pipeline

    def fake(kind, request, job_dir, progress, ray_address=None):
        assert kind is JobKind.simulation and request == {"r": 1} and ray_address == "ray://x"
        progress(0.5, "half")
        if isinstance(outcome, BaseException):
            raise outcome
        (job_dir / "out.txt").write_text("result")
        return outcome

    monkeypatch.setattr(pipeline, "run_job", fake)
    rec = store.create(JobKind.simulation, {"r": 1}, "b")
    job_dir = tmp_path / rec.id
    job_dir.mkdir()
    status = run_in_worker(str(store.path), "b", rec.id, "simulation", {"r": 1}, str(job_dir), "ray://x")
    return status, store.get(rec.id)


def test_worker_success_records_result_and_file_digests(store, tmp_path, monkeypatch):
    status, r = _run(store, tmp_path, monkeypatch, {"rms": 1.5})
    assert status == "succeeded" and r.state is JobState.succeeded and r.result == {"rms": 1.5}
    assert r.message == "done"
    assert store.files(r.id) == {"out.txt": hashlib.sha256(b"result").hexdigest()}


@pytest.mark.parametrize("exc, words", [(InputError("bad line", line=3), "bad line"),
                                        (MemoryError(), "out of memory"),
                                        (ZeroDivisionError("boom"), "internal error: ZeroDivisionError: boom")])
def test_worker_failures_are_recorded(store, tmp_path, monkeypatch, exc, words):
    status, r = _run(store, tmp_path, monkeypatch, exc)
    assert status == "failed" and r.state is JobState.failed
    assert words in r.message and words in r.error["message"]
    if isinstance(exc, InputError):
        assert r.error == {"message": "bad line", "line": 3}


def test_worker_stage_unavailable(store, tmp_path, monkeypatch):
    from service import pipeline
    status, r = _run(store, tmp_path, monkeypatch, pipeline.StageUnavailable("simulate.x", "the x stage"))
    assert status == "failed" and r.error["missing"] == "simulate.x" and r.error["message"] == r.message


def test_worker_sees_a_cancel_and_skips_a_job_not_queued(store, tmp_path, monkeypatch):
    from service import pipeline

    def fake(kind, request, job_dir, progress, ray_address=None):
        store.cancel(rec.id)
        progress(0.5, "half")
        raise AssertionError("a cancelled job must stop at its next progress report")

    monkeypatch.setattr(pipeline, "run_job", fake)
    rec = store.create(JobKind.simulation, {}, "b")
    assert run_in_worker(str(store.path), "b", rec.id, "simulation", {}, str(tmp_path), None) == "cancelled"
    r = store.get(rec.id)
    assert r.state is JobState.cancelled and r.message == "cancelled by the client"
    assert run_in_worker(str(store.path), "b", rec.id, "simulation", {}, str(tmp_path), None) == "skipped"
    with pytest.raises(JobCancelled):
        raise JobCancelled("x")


def _in_fork(fn):
    """Run fn() in a forked child (it sees this process's modules); returns (exit code, its JSON)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - child
        os.close(r)
        code = 0
        try:
            out = fn()
        except SystemExit as e:
            out, code = None, int(e.code or 0)
        except BaseException as e:
            out, code = repr(e), 1
        os.write(w, json.dumps(out).encode())
        os._exit(code)
    os.close(w)
    data = b""
    while chunk := os.read(r, 65536):
        data += chunk
    os.close(r)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), (json.loads(data) if data else None)


def _pdeathsig():
    import ctypes
    import ctypes.util

    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    v = ctypes.c_int(-1)
    libc.prctl(2, ctypes.byref(v), 0, 0, 0)     # PR_GET_PDEATHSIG
    return v.value


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signal is Linux only")
def test_parent_death_signal_is_sigkill():
    code, out = _in_fork(lambda: [jobs._set_parent_death_signal(), _pdeathsig()])
    assert code == 0 and out == [True, int(signal.SIGKILL)]
    # armed with the right parent: returns, and forked grandchildren inherit the arming
    code, out = _in_fork(lambda: [jobs.die_with_parent(os.getppid()), _pdeathsig(),
                                  _in_fork(_pdeathsig)])
    assert code == 0 and out == [None, int(signal.SIGKILL), [0, int(signal.SIGKILL)]]
    # the parent is already gone (another pid): exit code 3 at once
    code, _ = _in_fork(lambda: jobs.die_with_parent(os.getppid() + 100000))
    assert code == 3


def test_worker_main_leads_its_group_and_runs_the_job(monkeypatch):
    seen = {}

    def fake(*args):
        seen["args"] = args
        return "succeeded"

    monkeypatch.setattr(jobs, "run_in_worker", fake)
    monkeypatch.setattr("identify.resources.configure_threads", lambda n: seen.setdefault("threads", n))

    def child():
        jobs._worker_main(os.getppid(), 3, "db", "boot", "jid", "simulation", {"r": 1}, "dir", "ray")
        return [seen["args"], seen["threads"], os.getpgid(0) == os.getpid(), _pdeathsig()]

    code, out = _in_fork(child)
    assert code == 0
    args, threads, leader, sig = out
    assert args == ["db", "boot", "jid", "simulation", {"r": 1}, "dir", "ray"]
    assert threads == 3 and leader is True
    if sys.platform.startswith("linux"):
        assert sig == int(signal.SIGKILL)
