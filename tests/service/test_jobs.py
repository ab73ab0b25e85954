"""The SQLite job store: life cycle, restart recovery, orphaned workers, settings validation."""
from __future__ import annotations

import pytest

from identify.errors import InputError
from service.jobs import RESTART_REASON, JobKind, JobState, JobStore
from service.settings import DEV_API_KEY, load_settings


def test_life_cycle_and_results_survive_reopening(tmp_path):
    store = JobStore(tmp_path / "jobs.sqlite")
    rec = store.create(JobKind.simulation, {"robot": "max100"}, boot="b1")
    assert rec.state is JobState.queued and rec.progress == 0.0 and rec.request == {"robot": "max100"}
    assert store.start(rec.id, "b1")
    assert not store.start(rec.id, "b1")  # only once
    assert store.report(rec.id, 0.4, "half way") is JobState.running
    assert store.finish(rec.id, "b1", JobState.succeeded, result={"ranking": [1, 2]})
    again = JobStore(tmp_path / "jobs.sqlite").get(rec.id)
    assert again.state is JobState.succeeded and again.progress == 1.0 and again.result == {"ranking": [1, 2]}
    assert again.finished >= again.started >= again.created


def test_recovery_fails_unfinished_jobs_of_earlier_boots_with_the_reason(tmp_path):
    store = JobStore(tmp_path / "jobs.sqlite")
    done = store.create(JobKind.simulation, {}, boot="old")
    store.start(done.id, "old")
    store.finish(done.id, "old", JobState.succeeded, result={"ok": True})
    running = store.create(JobKind.simulation, {}, boot="old")
    store.start(running.id, "old")
    store.report(running.id, 0.3, "pose 1")
    queued = store.create(JobKind.diagnose, {}, boot="old")
    mine = store.create(JobKind.simulation, {}, boot="new")

    assert store.recover("new") == 2
    r = store.get(running.id)
    assert r.state is JobState.failed and r.error == {"message": RESTART_REASON.format(state="running")}
    assert r.progress == pytest.approx(0.3)  # where it was cut off
    q = store.get(queued.id)
    assert q.state is JobState.failed and "queued" in q.error["message"]
    assert store.get(done.id).state is JobState.succeeded and store.get(done.id).result == {"ok": True}
    assert store.get(mine.id).state is JobState.queued
    # a worker orphaned by the killed server cannot overwrite the recorded failure
    assert not store.finish(running.id, "old", JobState.succeeded, result={"late": True})
    assert store.get(running.id).state is JobState.failed and store.get(running.id).result is None


def test_cancel_is_seen_by_the_worker_and_not_overwritten(tmp_path):
    store = JobStore(tmp_path / "jobs.sqlite")
    rec = store.create(JobKind.simulation, {}, boot="b")
    store.start(rec.id, "b")
    assert store.cancel(rec.id).state is JobState.cancelled
    assert store.report(rec.id, 0.5, "x") is JobState.cancelled
    assert not store.finish(rec.id, "b", JobState.succeeded, result={})
    assert store.get(rec.id).state is JobState.cancelled
    assert store.cancel("f" * 32) is None


def test_settings_need_a_key_outside_development_mode(monkeypatch, tmp_path):
    for k in ("GREYBENCH_API_KEYS", "GREYBENCH_DEV_MODE", "RAY_ADDRESS"):
        monkeypatch.delenv(k, raising=False)
    with pytest.raises(InputError, match="GREYBENCH_API_KEYS"):
        load_settings()
    monkeypatch.setenv("GREYBENCH_DEV_MODE", "1")
    assert load_settings().keys() == frozenset({DEV_API_KEY})
    monkeypatch.setenv("GREYBENCH_API_KEYS", "first-key-1, second-key-2")
    assert load_settings().keys() == frozenset({"first-key-1", "second-key-2"})  # dev key not added
    monkeypatch.setenv("GREYBENCH_API_KEYS", "short")
    with pytest.raises(InputError, match="8 characters"):
        load_settings()


@pytest.mark.parametrize("var,value", [("GREYBENCH_WORKERS", "0"), ("GREYBENCH_QUEUE_SIZE", "-1"),
                                       ("GREYBENCH_MAX_BODY_BYTES", "ten"), ("GREYBENCH_RETRY_AFTER", "0")])
def test_bad_settings_name_the_variable(monkeypatch, var, value):
    monkeypatch.setenv("GREYBENCH_API_KEYS", "a-good-key-1")
    monkeypatch.setenv(var, value)
    with pytest.raises(InputError) as exc:
        load_settings()
    assert exc.value.field == var and exc.value.source == "environment"


def test_serve_refuses_to_start_without_keys(monkeypatch, tmp_path):
    from typer.testing import CliRunner

    from greybench.cli import app
    for k in ("GREYBENCH_API_KEYS", "GREYBENCH_DEV_MODE"):
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("GREYBENCH_DATA_DIR", str(tmp_path / "d"))
    r = CliRunner().invoke(app, ["serve", "--port", "1"])
    assert r.exit_code == 2
    assert "GREYBENCH_API_KEYS" in r.output
    assert not (tmp_path / "d").exists()  # nothing created
    monkeypatch.setenv("GREYBENCH_API_KEYS", "a-good-key-1")
    monkeypatch.setenv("GREYBENCH_WORKERS", "many")
    r = CliRunner().invoke(app, ["serve"])
    assert r.exit_code == 2 and "GREYBENCH_WORKERS" in r.output
