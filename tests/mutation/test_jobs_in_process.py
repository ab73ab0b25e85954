"""Job handling parts that normally run in a worker process or a supervisor thread, run in the test
process with stand-ins for the operating system calls (nothing is armed, signalled or killed).

The forked-child tests in test_jobs_store.py show the real effect (a worker armed with SIGKILL, a
group leader); these show each decision and argument in-process, where the mutation tool sees them.
"""
from __future__ import annotations

import signal

import pytest

from service import jobs
from service.jobs import JobKind, JobManager, JobState, JobStore


class Exit(BaseException):
    """Stand-in for os._exit: ends the code under test without ending the test process."""

    def __init__(self, code):
        super().__init__(code)
        self.code = code


@pytest.fixture
def os_calls(monkeypatch):
    """Record-only stand-ins for the process calls of service.jobs."""
    calls = []
    monkeypatch.setattr(jobs.os, "_exit", lambda code: (_ for _ in ()).throw(Exit(code)))
    monkeypatch.setattr(jobs.os, "killpg", lambda pid, sig: calls.append(("killpg", pid, sig)))
    monkeypatch.setattr(jobs.os, "register_at_fork", lambda **kw: calls.append(("register_at_fork", kw)))
    monkeypatch.setattr(jobs.os, "setpgid", lambda a, b: calls.append(("setpgid", a, b)))
    monkeypatch.setattr(jobs.time, "sleep", lambda s: calls.append(("sleep", s)))
    return calls


class FakeLibc:
    def __init__(self, ret=0):
        self.ret = ret
        self.calls = []

    def prctl(self, *args):
        self.calls.append(args)
        return self.ret


def test_parent_death_signal_asks_the_kernel_for_sigkill(monkeypatch):
    libc = FakeLibc(0)
    opened = []
    monkeypatch.setattr(jobs.sys, "platform", "linux")
    monkeypatch.setattr(jobs.ctypes, "CDLL", lambda name, use_errno=False: opened.append((name, use_errno)) or libc)
    monkeypatch.setattr(jobs.ctypes.util, "find_library", lambda name: "libc.so.test" if name == "c" else None)
    assert jobs._set_parent_death_signal() is True
    assert libc.calls == [(1, signal.SIGKILL, 0, 0, 0)] and jobs.PR_SET_PDEATHSIG == 1
    assert opened == [("libc.so.test", True)]
    libc.ret = -1                                   # the kernel refused
    assert jobs._set_parent_death_signal() is False
    monkeypatch.setattr(jobs.ctypes.util, "find_library", lambda name: None)
    jobs._set_parent_death_signal()
    assert opened[-1][0] == "libc.so.6"


@pytest.mark.parametrize("exc", [OSError, AttributeError])
def test_parent_death_signal_without_libc_or_prctl(monkeypatch, exc):
    monkeypatch.setattr(jobs.sys, "platform", "linux")

    def cdll(*a, **k):
        raise exc("no")

    monkeypatch.setattr(jobs.ctypes, "CDLL", cdll)
    assert jobs._set_parent_death_signal() is False


def test_parent_death_signal_is_linux_only(monkeypatch):
    libc = FakeLibc(0)
    monkeypatch.setattr(jobs.ctypes, "CDLL", lambda *a, **k: libc)
    monkeypatch.setattr(jobs.sys, "platform", "darwin")
    assert jobs._set_parent_death_signal() is False and libc.calls == []


def test_die_with_parent_on_linux_arms_every_later_fork(monkeypatch, os_calls):
    monkeypatch.setattr(jobs, "_set_parent_death_signal", lambda: True)
    monkeypatch.setattr(jobs.os, "getppid", lambda: 4242)
    started = []
    monkeypatch.setattr(jobs.threading, "Thread", lambda **kw: started.append(kw))
    assert jobs.die_with_parent(4242) is None
    assert os_calls == [("register_at_fork", {"after_in_child": jobs._set_parent_death_signal})]
    assert started == []                          # no watchdog where the kernel does it


def test_die_with_parent_exits_when_the_parent_is_already_gone(monkeypatch, os_calls):
    monkeypatch.setattr(jobs, "_set_parent_death_signal", lambda: True)
    monkeypatch.setattr(jobs.os, "getppid", lambda: 1)
    with pytest.raises(Exit) as e:
        jobs.die_with_parent(4242)
    assert e.value.code == 3 and os_calls == []


class FakeThread:
    made = []

    def __init__(self, **kw):
        self.kw = kw
        self.started = False
        FakeThread.made.append(self)

    def start(self):
        self.started = True


def test_die_with_parent_elsewhere_polls_the_parent_and_ends_its_group(monkeypatch, os_calls):
    """Without the kernel's signal: a daemon watchdog thread polls the parent pid every interval and,
    once the parent is gone, SIGKILLs its own process group (0) and exits with code 3. The thread is
    not started here; its function is run in the test with the calls recorded."""
    monkeypatch.setattr(jobs, "_set_parent_death_signal", lambda: False)
    ppids = iter([4242, 4242, 4242, 1])          # checked at arming, then twice alive, then gone
    monkeypatch.setattr(jobs.os, "getppid", lambda: next(ppids))
    FakeThread.made = []
    monkeypatch.setattr(jobs.threading, "Thread", FakeThread)
    jobs.die_with_parent(4242, interval=0.25)
    (th,) = FakeThread.made
    assert th.started and th.kw["daemon"] is True and th.kw["name"] == "exit-with-parent"
    assert os_calls == []
    with pytest.raises(Exit) as e:
        th.kw["target"]()
    assert e.value.code == 3
    assert os_calls == [("sleep", 0.25), ("sleep", 0.25), ("killpg", 0, signal.SIGKILL)]


def test_watchdog_exits_even_when_the_group_kill_fails(monkeypatch, os_calls):
    monkeypatch.setattr(jobs, "_set_parent_death_signal", lambda: False)
    ppids = iter([7, 8])
    monkeypatch.setattr(jobs.os, "getppid", lambda: next(ppids))

    def killpg(pid, sig):
        raise PermissionError("no")

    monkeypatch.setattr(jobs.os, "killpg", killpg)
    FakeThread.made = []
    monkeypatch.setattr(jobs.threading, "Thread", FakeThread)
    jobs.die_with_parent(7)
    with pytest.raises(Exit) as e:
        FakeThread.made[0].kw["target"]()
    assert e.value.code == 3


def test_worker_main_in_process(monkeypatch, os_calls):
    seen = []
    monkeypatch.setattr(jobs, "die_with_parent", lambda pid: seen.append(("die_with_parent", pid)))
    monkeypatch.setattr("identify.resources.configure_threads", lambda n: seen.append(("threads", n)))
    monkeypatch.setattr(jobs, "run_in_worker", lambda *a: seen.append(("run", a)))
    jobs._worker_main(99, 3, "db", "boot", "jid", "simulation", {"r": 1}, "dir", "ray")
    assert os_calls == [("setpgid", 0, 0)]
    assert seen == [("die_with_parent", 99), ("threads", 3),
                    ("run", ("db", "boot", "jid", "simulation", {"r": 1}, "dir", "ray"))]

    def refuse(a, b):
        raise PermissionError("already a leader")

    monkeypatch.setattr(jobs.os, "setpgid", refuse)
    seen.clear()
    jobs._worker_main(98, 1, "db", "b", "j", "simulation", {}, "d", None)   # carries on
    assert [s[0] for s in seen] == ["die_with_parent", "threads", "run"]


# --------------------------------------------------------------------------- supervisor


class FakeEvent:
    def __init__(self):
        self.waits, self.cleared, self.flag = [], 0, False

    def wait(self, timeout=None):
        self.waits.append(timeout)
        return True

    def clear(self):
        self.cleared += 1

    def set(self):
        self.flag = True

    def is_set(self):
        return self.flag


@pytest.fixture
def manager(tmp_path):
    store = JobStore(tmp_path / "jobs.sqlite")
    m = JobManager(store, tmp_path / "jobs", workers=0, capacity=4, retry_after=3)
    yield m
    m.shutdown()
    store.close()


def test_supervisor_waits_a_tick_and_survives_a_failing_pass(manager, capsys):
    """Each pass waits for a wake-up at most TICK seconds, clears it, and an error of a pass is
    printed and the loop goes on."""
    manager._stop.set()
    manager._thread.join(5)                      # the real supervisor has ended
    manager._stop = FakeEvent()
    manager._wake = FakeEvent()
    passes = []

    def one_pass():
        passes.append(1)
        if len(passes) == 1:
            raise RuntimeError("boom")
        manager._stop.flag = True

    manager._pass = one_pass
    manager._supervise()
    assert passes == [1, 1]
    assert manager._wake.waits == [0.2, 0.2] and manager._wake.cleared == 2
    assert "job supervisor: RuntimeError: boom" in capsys.readouterr().err


class Proc:
    def __init__(self, pid=None, exitcode=None, alive=False):
        self.pid, self.exitcode, self.alive, self.joined = pid, exitcode, alive, []

    def is_alive(self):
        return self.alive

    def join(self, timeout=None):
        self.joined.append(timeout)


def test_pass_starts_queued_jobs_up_to_the_worker_count(manager, monkeypatch):
    """Two worker slots, three queued jobs (one cancelled before its turn): the two live ones start
    with the worker entry point and their arguments, their pid is recorded; a busy slot waits."""
    manager._stop.set()
    manager._thread.join(5)
    manager._stop.clear()
    manager.workers = 2
    started = []

    class Ctx:
        @staticmethod
        def Process(target, name, args):
            p = Proc(pid=50000 + len(started))
            p.start = lambda: started.append((target, name, args))
            return p

    manager._ctx = Ctx
    monkeypatch.setattr(jobs, "process_start", lambda pid: f"t{pid}")
    a = manager.submit(JobKind.simulation, {"a": 1})
    b = manager.submit(JobKind.simulation, {"b": 2})
    c = manager.submit(JobKind.simulation, {"c": 3})
    manager.store.cancel(a.id)
    manager._pass()
    assert [s[2][4] for s in started] == [b.id, c.id]
    target, name, args = started[0]
    assert target is jobs._worker_main and name == f"greybench-job-{b.id[:8]}"
    assert args[1:] == (1, str(manager.store.path), manager.boot, b.id, "simulation", {"b": 2},
                        str(manager.job_dir(b.id)), None)
    assert manager.running_pids() == {b.id: 50000, c.id: 50001}
    row = manager.store._conn().execute("SELECT pid, pid_start FROM jobs WHERE id=?", (b.id,)).fetchone()
    assert tuple(row) == (50000, "t50000")
    for p in manager._running.values():
        p.alive = True
    d = manager.submit(JobKind.simulation, {"d": 4})
    manager._pass()                                  # both slots busy: d waits
    assert len(started) == 2 and manager.active() == 3
    # shutdown: every running group killed, joined for at most 5 s, recorded failed; the queued one too
    killed = []
    monkeypatch.setattr(jobs, "kill_group", lambda pid: killed.append(pid))
    procs = list(manager._running.values())
    manager.shutdown()
    assert sorted(killed) == [50000, 50001] and all(p.joined == [5] for p in procs)
    for jid, state in ((b.id, "running"), (c.id, "running"), (d.id, "queued")):
        rec = manager.store.get(jid)
        assert rec.state is JobState.failed and rec.message == jobs.RESTART_REASON.format(state=state)
        assert rec.error == {"message": jobs.RESTART_REASON.format(state=state)}
    assert manager.active() == 0


def test_pass_does_nothing_once_stopped(manager):
    manager._stop.set()
    manager._thread.join(5)
    manager._running["x"] = Proc(pid=1, exitcode=1)
    manager._pass()
    assert "x" in manager._running
    manager._running.clear()


def test_pass_records_how_a_worker_died(manager):
    manager._stop.set()
    manager._thread.join(5)
    manager._stop.clear()
    recs = [manager.submit(JobKind.simulation, {}) for _ in range(3)]
    for r in recs:
        manager.store.start(r.id, manager.boot)
    manager._pending.clear()
    manager._running.update({recs[0].id: Proc(1, -9), recs[1].id: Proc(2, 2), recs[2].id: Proc(3, 0)})
    manager._pass()
    assert manager._running == {}
    assert manager.store.get(recs[0].id).message == jobs.WORKER_DIED_REASON.format(how="signal 9")
    assert manager.store.get(recs[1].id).message == jobs.WORKER_DIED_REASON.format(how="exit code 2")
    assert manager.store.get(recs[1].id).error == {"message": jobs.WORKER_DIED_REASON.format(how="exit code 2")}
    assert manager.store.get(recs[2].id).state is JobState.running     # exit 0: the worker recorded its end


def test_data_dir_lock_creates_its_folder_and_a_private_pid_file(tmp_path):
    """The lock creates a nested data folder and its pid file with mode 0644 (umask 022)."""
    import os

    old = os.umask(0o022)
    try:
        lock = jobs.DataDirLock(tmp_path / "a" / "b").acquire()
        try:
            assert (lock.path.stat().st_mode & 0o777) == 0o644
            assert lock.path.read_text() == f"{os.getpid()}\n"
        finally:
            lock.release()
    finally:
        os.umask(old)


def test_a_long_internal_error_is_cut_to_500_characters_in_the_message(tmp_path, monkeypatch):
    from service import pipeline

    def fake(kind, request, job_dir, progress, ray_address=None):
        raise RuntimeError("x" * 1000)

    monkeypatch.setattr(pipeline, "run_job", fake)
    store = JobStore(tmp_path / "s.sqlite")
    rec = store.create(JobKind.simulation, {}, "b")
    assert jobs.run_in_worker(str(store.path), "b", rec.id, "simulation", {}, str(tmp_path / "d"), None) == "failed"
    r = store.get(rec.id)
    assert len(r.message) == 500 and r.message.startswith("internal error: RuntimeError: xxx")
    assert r.error["message"] == "internal error: RuntimeError: " + "x" * 1000       # the whole text kept
    store.close()


def test_a_new_manager_recovers_the_jobs_of_an_earlier_boot(tmp_path):
    store = JobStore(tmp_path / "s.sqlite")
    old = store.create(JobKind.simulation, {}, "earlier-boot")
    m = JobManager(store, tmp_path / "jobs", workers=0, capacity=2, retry_after=1)
    try:
        assert m.recovered == 1
        r = store.get(old.id)
        assert r.state is JobState.failed and r.message == jobs.RESTART_REASON.format(state="queued")
    finally:
        m.shutdown()
        store.close()


def test_inputs_that_cannot_be_stored_fail_the_job_with_the_reason(manager):
    def broken(_d):
        raise OSError("disk full")

    with pytest.raises(OSError):
        manager.submit(JobKind.simulation, {}, prepare=broken)
    (row,) = manager.store._conn().execute("SELECT id FROM jobs").fetchall()
    r = manager.store.get(row[0])
    assert r.state is JobState.failed and r.error == {"message": "could not store the inputs"}


def test_close_drops_the_thread_connection_and_the_default_owner_is_empty(manager):
    rec = manager.submit(JobKind.simulation, {})
    assert rec.owner == "" and manager.store.get(rec.id).owner == ""
    conn = manager.store._conn()
    manager.store.close()
    assert manager.store._local.conn is None
    with pytest.raises(Exception, match="closed"):
        conn.execute("SELECT 1")
