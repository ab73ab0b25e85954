"""Job handling: persistence across a restart, a recycled worker pid, cancelling a worker not started yet.

Complements tests/mutation/test_jobs_store.py and test_jobs_in_process.py; no worker process is
started by the job manager here (``workers=0``).
"""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from service.jobs import RESTART_REASON, JobKind, JobManager, JobState, JobStore, process_start


class _NotStarted:
    """Stands in for a worker process object whose ``start()`` has not given it a pid yet."""

    pid = None
    exitcode = None

    def is_alive(self):
        return True


@pytest.fixture
def sleeper():
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], start_new_session=True)
    yield proc
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def test_recover_leaves_a_live_process_alone_when_its_start_time_differs(tmp_path, sleeper):
    # the pid of an old boot's worker now belongs to another process (its start time differs): not ended
    store = JobStore(tmp_path / "jobs.sqlite")
    rec = store.create(JobKind.simulation, {}, "old")
    store.start(rec.id, "old")
    start = process_start(sleeper.pid)
    assert start is not None
    store.set_worker(rec.id, sleeper.pid, str(int(start) + 1))
    assert store.recover("new") == 1
    with pytest.raises(subprocess.TimeoutExpired):   # a SIGKILL would have ended it by now
        sleeper.wait(0.5)
    assert store.get(rec.id).state is JobState.failed
    # a job of this boot with the same pid is not an old boot's: not ended either
    mine = store.create(JobKind.simulation, {}, "new")
    store.start(mine.id, "new")
    store.set_worker(mine.id, sleeper.pid, start)
    assert store.recover("new") == 0
    with pytest.raises(subprocess.TimeoutExpired):
        sleeper.wait(0.5)
    assert store.get(mine.id).state is JobState.running
    store.close()


def test_cancel_of_a_worker_without_a_pid_yet_cancels_the_job(tmp_path):
    store = JobStore(tmp_path / "jobs.sqlite")
    m = JobManager(store, tmp_path / "jobs", workers=0, capacity=2, retry_after=1)
    try:
        rec = m.submit(JobKind.simulation, {"n": 1})
        store.start(rec.id, m.boot)
        with m._lock:
            m._pending.clear()
            m._running[rec.id] = _NotStarted()
        assert m.running_pids() == {}
        assert m.cancel(rec.id).state is JobState.cancelled
        with m._lock:
            m._running.clear()
    finally:
        m.shutdown()
        store.close()


def test_store_round_trip_across_a_restart(tmp_path):
    """Every state written by one server is read back by the next; unfinished jobs fail with the reason."""
    path = tmp_path / "data" / "jobs.sqlite"
    first = JobStore(path)
    boot = "boot-1"
    queued = first.create(JobKind.simulation, {"pose": "p1", "x": [1.5, 2]}, boot, owner="o1")
    running = first.create(JobKind.explain, {"pose": "p2"}, boot, owner="o2")
    first.start(running.id, boot)
    first.report(running.id, 0.375, "pose 3 of 8")
    done = first.create(JobKind.compensation, {"k": 2}, boot)
    first.start(done.id, boot)
    first.finish(done.id, boot, JobState.succeeded, result={"rms_um": 3.25}, files={"a.csv": "ab" * 32})
    bad = first.create(JobKind.diagnose, {}, boot)
    first.start(bad.id, boot)
    first.report(bad.id, 0.5, "half")
    first.finish(bad.id, boot, JobState.failed, error={"message": "line 3: bad", "line": 3}, message="line 3: bad")
    gone = first.create(JobKind.simulation, {}, boot)
    first.cancel(gone.id)
    first.close()

    second = JobStore(path, check=True)
    r = second.get(running.id)
    assert (r.state, r.progress, r.message, r.owner, r.request) == (JobState.running, 0.375, "pose 3 of 8", "o2",
                                                                     {"pose": "p2"})
    d = second.get(done.id)
    assert (d.state, d.progress, d.result, d.message) == (JobState.succeeded, 1.0, {"rms_um": 3.25}, "succeeded")
    assert second.files(done.id) == {"a.csv": "ab" * 32}
    b = second.get(bad.id)
    assert (b.state, b.progress, b.error) == (JobState.failed, 0.5, {"message": "line 3: bad", "line": 3})
    assert second.get(gone.id).state is JobState.cancelled
    assert second.count() == 2 and second.count(owner="o1") == 1

    m = JobManager(second, tmp_path / "data" / "jobs", workers=0, capacity=4, retry_after=1)
    try:
        assert m.recovered == 2 and m.boot != boot
        q, r = second.get(queued.id), second.get(running.id)
        assert q.state is JobState.failed and q.message == RESTART_REASON.format(state="queued")
        assert r.state is JobState.failed and r.error == {"message": RESTART_REASON.format(state="running")}
        assert q.finished is not None and r.progress == 0.375
        # finished jobs are kept as they were, and the late worker of the old boot cannot close its job
        assert second.get(done.id).state is JobState.succeeded and second.get(gone.id).state is JobState.cancelled
        assert not second.finish(running.id, boot, JobState.succeeded, result={"late": 1})
        assert second.get(running.id).result is None
        assert not second.start(queued.id, boot)
        assert second.count() == 0
        # the new boot admits again up to its capacity
        for _ in range(4):
            m.submit(JobKind.simulation, {})
        assert second.count() == 4 and second.count((JobState.queued,)) == 4
    finally:
        m.shutdown()
    assert second.count((JobState.failed,)) == 2 + 1 + 4
    second.close()


def test_process_start_is_the_start_time_in_clock_ticks_since_boot(sleeper):
    # field 22 of /proc/<pid>/stat: a process started just now started about `uptime` seconds after boot
    ticks = process_start(sleeper.pid)
    with open("/proc/uptime") as f:
        uptime_s = float(f.read().split()[0])
    assert ticks is not None
    started_s = int(ticks) / os.sysconf("SC_CLK_TCK")
    assert uptime_s - 30.0 <= started_s <= uptime_s + 1.0
    assert process_start(os.getpid()) != ticks or os.getpid() == sleeper.pid


def test_the_empty_owner_counts_only_its_own_jobs(tmp_path):
    # a key-less caller (owner "") has a share of its own, not the sum over all owners
    store = JobStore(tmp_path / "jobs.sqlite")
    m = JobManager(store, tmp_path / "jobs", workers=0, capacity=5, retry_after=1, per_key=2)
    try:
        m.submit(JobKind.simulation, {}, owner="a")
        m.submit(JobKind.simulation, {}, owner="a")
        assert store.count(owner="") == 0 and store.count(owner="a") == 2
        m.submit(JobKind.simulation, {}, owner="")
        m.submit(JobKind.simulation, {})
        assert store.count(owner="") == 2 and store.count() == 4
    finally:
        m.shutdown()
        store.close()


def test_one_connection_per_thread_and_close_from_any_thread(tmp_path):
    import threading

    store = JobStore(tmp_path / "jobs.sqlite")
    assert store._conn() is store._conn()                 # reused, not reopened per statement
    errors = []

    def other():
        try:
            store.close()                                 # this thread never opened one: nothing to close
            store.get("nope")
            store.close()
        except Exception as exc:                          # pragma: no cover - reported below
            errors.append(exc)

    t = threading.Thread(target=other)
    t.start()
    t.join()
    assert errors == []
    store.close()


def test_lock_release_without_acquire_and_a_second_manager_on_the_same_folders(tmp_path):
    from service.jobs import DataDirLock

    DataDirLock(tmp_path / "d").release()                 # never acquired: nothing to release
    store = JobStore(tmp_path / "jobs.sqlite")
    for _ in range(2):                                    # the jobs folder exists the second time
        m = JobManager(store, tmp_path / "jobs", workers=0, capacity=2, retry_after=1)
        rec = m.submit(JobKind.simulation, {"pose": "p1", "n": 3})
        assert store.get(rec.id).request == {"pose": "p1", "n": 3} and rec.request == {"pose": "p1", "n": 3}
        m.shutdown()
    store.close()


class _Alive(_NotStarted):
    pid = 12345


class _Ended:
    pid = 12346
    exitcode = 7

    def is_alive(self):
        return False

    def join(self, timeout=None):
        pass


def test_a_pass_reaps_every_ended_worker_behind_a_running_one(tmp_path):
    from service.jobs import WORKER_DIED_REASON

    store = JobStore(tmp_path / "jobs.sqlite")
    m = JobManager(store, tmp_path / "jobs", workers=0, capacity=3, retry_after=1)
    try:
        a = store.create(JobKind.simulation, {}, m.boot)
        b = store.create(JobKind.simulation, {}, m.boot)
        for rec in (a, b):
            store.start(rec.id, m.boot)
        with m._lock:
            m._running.update({a.id: _Alive(), b.id: _Ended()})     # the running one comes first
        m._pass()
        assert m.running_pids() == {a.id: 12345}
        assert store.get(b.id).message == WORKER_DIED_REASON.format(how="exit code 7")
        assert store.get(a.id).state is JobState.running
        with m._lock:
            m._running.clear()
    finally:
        m.shutdown()
        store.close()
