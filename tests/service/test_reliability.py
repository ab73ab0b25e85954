"""Reliability against real ``greybench serve`` processes on 127.0.0.1: bad numbers and huge inputs,
HTTP manners, two servers on one folder, cancel, ``kill -9``, damaged results and stores, fairness.

Bounded: every loop has a deadline, every server is stopped with its process group. Each case takes
seconds (plus a server start); the soak with many jobs and a crash is marked slow.
"""
from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from service.jobs import RESTART_REASON, JobKind, JobState, JobStore, folder_digests, owner_of, process_start

from .conftest import (
    DATA,
    GREYBENCH,
    HEADERS,
    KEY,
    ROBOT_FRICTION,
    Server,
    free_port,
    server_env,
    short_program,
    wait_for,
)

OTHER_KEY = "other-key-9876543210"


def slow_program(factor: int = 10) -> str:
    """The 160 test piece with every feed divided by ``factor``: the same cut taking ``factor``
    times longer (more 2 ms samples), so a job runs for minutes with little memory."""
    import re

    text = (DATA / "programs" / "iso160.nc").read_text()
    return re.sub(r"F(\d+(?:\.\d*)?)", lambda m: f"F{float(m.group(1)) / factor:g}", text)


#: Runs for minutes: long enough to cancel it or crash its server while it runs.
LONG_JOB = {"gcode": slow_program(), "stock": "iso160", "pose_set": "iso160",
            "options": {"spacing_mm": 2.0, "shares": True}, "friction": ROBOT_FRICTION}


# ---- helpers --------------------------------------------------------------------------------
def _proc_table() -> dict[int, tuple[int, str]]:
    """pid -> (parent pid, command line) of every process we can see."""
    table = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        table[int(entry.name)] = (int(stat[stat.rindex(")") + 2:].split()[1]), cmd)
    return table


def job_workers(server_pid: int) -> dict[int, str]:
    """Job worker processes under a server (spawned ``spawn_main`` processes and their children),
    pid -> start time, found from /proc without help from the server."""
    table = _proc_table()
    found, frontier = {}, [server_pid]
    while frontier:
        parent = frontier.pop()
        for pid, (ppid, cmd) in table.items():
            if ppid == parent and "resource_tracker" not in cmd:
                frontier.append(pid)
                if pid != server_pid:
                    found[pid] = process_start(pid)
    return {p: s for p, s in found.items() if s is not None}


def alive(workers: dict[int, str]) -> list[int]:
    """Those of ``workers`` still running (same pid and start time: not a reused pid)."""
    left = []
    for pid, start in workers.items():
        if process_start(pid) == start:
            try:
                state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
            except OSError:
                continue
            if state != "Z":  # a zombie has ended; it only waits for its parent to reap it
                left.append(pid)
    return left


def wait_until(predicate, timeout: float, what: str, interval: float = 0.1):
    deadline = time.time() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.time() > deadline:
            raise AssertionError(f"not within {timeout} s: {what}")
        time.sleep(interval)


def fabricate_finished_job(data_dir: Path) -> tuple[str, dict[str, bytes]]:
    """A succeeded simulation job written into a server's store and jobs folder by an earlier boot,
    as the worker writes it (files, then the row with their digests); returns (id, files)."""
    store = JobStore(data_dir / "jobs.sqlite")
    rec = store.create(JobKind.simulation, {"robot": "max100"}, boot="earlier-boot", owner=owner_of(KEY))
    assert store.start(rec.id, "earlier-boot")
    ranking = [{"pose": "near", "score": 1.25, "rank": 1, "in_tolerance": 9, "worst_feature": "circle"}]
    glb_body = b"\x00" * 20
    glb = b"glTF" + (2).to_bytes(4, "little") + (12 + len(glb_body)).to_bytes(4, "little") + glb_body
    files = {"ranking.json": json.dumps({"ranking": ranking}).encode(),
             "report.json": json.dumps({"poses": [{"pose": "near", "steps": 10}],
                                        "features": [{"name": "circle", "nominal": 108.0, "tolerance": 0.02,
                                                      "deviation": {"near": 0.011}}]}).encode(),
             "report.csv": (b"feature,nominal_mm,nominal_deg,tolerance_mm,pose,deviation_mm,in_tolerance\n"
                            b"circle,108.0,,0.02,near,0.011,True\n"),
             "workpiece/near.glb": glb}
    d = data_dir / "jobs" / rec.id
    for name, data in files.items():
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_bytes(data)
    assert store.finish(rec.id, "earlier-boot", JobState.succeeded, result={"ranking": ranking, "poses": ["near"]},
                        files=folder_digests(d))
    store.close()
    return rec.id, files


def served_files(c: httpx.Client, job: str) -> dict[str, bytes]:
    out = {}
    for name, url in [("ranking.json", f"/simulations/{job}/ranking"),
                      ("report.csv", f"/simulations/{job}/report?format=csv"),
                      ("workpiece/near.glb", f"/simulations/{job}/workpiece/near.glb")]:
        r = c.get(url)
        assert r.status_code == 200, (url, r.status_code, r.text[:300])
        out[name] = r.json()["ranking"] if name == "ranking.json" else r.content
    return out


def as_stored(files: dict[str, bytes]) -> dict:
    """What :func:`served_files` gives for unchanged files: the ranking's entries, the other bytes."""
    return {"ranking.json": json.loads(files["ranking.json"])["ranking"], "report.csv": files["report.csv"],
            "workpiece/near.glb": files["workpiece/near.glb"]}


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    """One server for the cases that do not stop it: one worker, one unfinished job per key."""
    d = tmp_path_factory.mktemp("reliable") / "data"
    s = Server(data_dir=d, env=server_env(d, GREYBENCH_API_KEYS=f"{KEY},{OTHER_KEY}", GREYBENCH_JOBS_PER_KEY=1,
                                          GREYBENCH_QUEUE_SIZE=4))
    s.start()
    yield s
    s.stop()


# ---- 1. finite numbers, short answers -------------------------------------------------------
@pytest.mark.parametrize("path,body,field", [
    ("/simulations", '{"program": "iso160", "pose_set": "iso160", "options": {"spacing_mm": NaN}}',
     "options.spacing_mm"),
    ("/simulations", '{"program": "iso160", "poses": [{"name": "a", "xyz": [Infinity, 0, 0], "rpy": [0, 0, 0]}]}',
     "poses.0.xyz.0"),
    ("/simulations", '{"program": "iso160", "poses": [{"name": "a", "xyz": [0, 0, 0], "rpy": [0, -Infinity, 0]}]}',
     "poses.0.rpy.1"),
    ("/friction/predict", '{"model": {"axis": 1}, "t": [0, 0.001], "q": [0, NaN]}', "q.1"),
    ("/explain", '{"scan_csv": "feature,x,y,z", "program": "iso160", "pose": "near", "pose_set": "iso160", '
                 '"spacing_mm": Infinity}', "spacing_mm"),
    ("/diagnose", '{"train_csv": "t", "test_csv": "t", "seed": NaN}', "seed"),
])
def test_non_finite_numbers_are_422_naming_the_field_without_the_value(srv, path, body, field):
    with srv.client() as c:
        r = c.post(path, content=body, headers={"Content-Type": "application/json"})
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert field in [d["field"] for d in detail], detail
    assert "nan" not in r.text.lower() and "infinity" not in r.text.lower()


def test_huge_strings_and_csv_headers_get_a_short_answer(srv):
    with srv.client() as c:
        long_name = "a" * 1_000_000
        r = c.post("/simulations", json={"program": long_name, "pose_set": "iso160"})
        assert r.status_code == 422 and len(r.content) < 2000
        assert r.json()["detail"][0]["field"] == "program"
        header = ",".join(f"c{i}" for i in range(150_000))
        r = c.post("/diagnose", json={"train_csv": header + "\n1\n", "test_csv": "t,q,tau\n0,0,0\n"})
        assert r.status_code == 422 and len(r.content) < 2000
        assert r.json()["detail"]["source"] == "train.csv" and r.json()["detail"]["line"] == 1
        # an InputError message quoting a huge value is cut short as well
        r = c.post("/diagnose", json={"train_csv": "t,q,tau\n0," + "9" * 500_000 + ",x\n",
                                      "test_csv": "t,q,tau\n0,0,0\n"})
        assert 400 <= r.status_code < 500 and len(r.content) < 2000


# ---- 7. HTTP manners and the documented job union ----------------------------------------
def test_options_answers_with_allow_and_the_job_union_is_one_of_with_a_discriminator(srv):
    with srv.client() as c:
        r = c.options("/simulations")
        assert r.status_code == 204 and set(r.headers["Allow"].split(", ")) == {"POST", "OPTIONS"}
        r = c.options("/jobs/" + "0" * 32)
        assert r.status_code == 204 and {"GET", "DELETE", "OPTIONS"} <= set(r.headers["Allow"].split(", "))
        assert c.options("/no/such/route").status_code == 404
        r = c.put("/simulations", json={})
        assert r.status_code == 405 and "POST" in r.headers["Allow"]
        doc = c.get("/openapi.json").json()
    schema = doc["paths"]["/jobs/{job_id}"]["get"]["responses"]["200"]["content"]["application/json"]["schema"]
    assert {s["$ref"].rsplit("/", 1)[1] for s in schema["oneOf"]} == {"SimulationJobStatus", "DiagnoseJobStatus",
                                                                      "ExplainJobStatus", "CompensationJobStatus",
                                                                      "PlacementSearchJobStatus", "CircleJobStatus"}
    assert schema["discriminator"]["propertyName"] == "kind"
    assert set(schema["discriminator"]["mapping"]) == {"simulation", "diagnose", "explain", "compensation",
                                                        "placement_search", "circle"}


def test_schemathesis_default_checks_over_the_served_schema_find_nothing(srv, tmp_path):
    config = Path(__file__).with_name("schemathesis.toml")
    st = str(Path(sys.executable).parent / "st")
    r = subprocess.run([st, "--config-file", str(config), "run", f"{srv.url}/openapi.json", "-H", f"X-API-Key: {KEY}",
                        "--max-examples", "3", "--workers", "1", "--seed", "7", "--no-color",
                        "--request-timeout", "60"],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path)  # its cache stays there
    tail = r.stdout[-3000:]
    assert r.returncode == 0, tail
    assert "generated" in tail and "failure" not in tail.split("Test cases:")[-1]


# ---- 2. one server per data folder -----------------------------------------------------------
def test_a_second_server_on_the_folder_exits_naming_it_and_the_first_keeps_its_job(srv):
    with srv.client() as c:
        job = c.post("/simulations", json=LONG_JOB).json()["id"]
        try:
            before = wait_for(c, job, ("running",), timeout=120)
            t0 = time.time()
            second = subprocess.run([GREYBENCH, "serve", "--port", str(free_port())], env=srv.env,
                                    capture_output=True, text=True, timeout=120)
            took = time.time() - t0
            assert second.returncode == 2, second.stderr
            lines = [x for x in second.stderr.splitlines() if x.strip()]
            assert len(lines) == 1, second.stderr
            assert str(srv.data_dir) in lines[0] and f"pid {srv.proc.pid}" in lines[0]
            assert took < 60  # at once: the imports, no waiting
            after = c.get(f"/jobs/{job}").json()
            assert after["state"] == "running" and after["started"] == before["started"]
            assert c.get("/health").status_code == 200
        finally:
            c.delete(f"/jobs/{job}")


# ---- 6. fairness -------------------------------------------------------------------------------
def test_a_key_beyond_its_job_limit_gets_429_while_another_key_is_served(srv):
    other = {"X-API-Key": OTHER_KEY}
    with srv.client() as c:
        first = c.post("/simulations", json=LONG_JOB)
        assert first.status_code == 202
        try:
            r = c.post("/simulations", json=LONG_JOB)
            assert r.status_code == 429 and int(r.headers["Retry-After"]) >= 1
            assert "GREYBENCH_JOBS_PER_KEY" in r.json()["detail"]
            theirs = c.post("/simulations", json=LONG_JOB, headers=other)
            assert theirs.status_code == 202, theirs.text
            c.delete(f"/jobs/{theirs.json()['id']}", headers=other)
        finally:
            c.delete(f"/jobs/{first.json()['id']}")
        # the share is free again once the job is finished (cancelled)
        again = c.post("/simulations", json=LONG_JOB)
        assert again.status_code == 202
        c.delete(f"/jobs/{again.json()['id']}")


# ---- 4. costs refused before work ---------------------------------------------------------------
def test_costly_requests_are_refused_at_once_naming_the_field_and_the_same_within_limits_accepted(srv):
    body = {"program": "iso320", "pose_set": "iso320", "select": ["pose1"], "friction": ROBOT_FRICTION}
    slow = (DATA / "programs" / "iso320.nc").read_text().replace("F2000", "F0.0001")
    with srv.client() as c:
        # earlier cases' cancelled workers reaped first, so the count below is this case's own
        wait_until(lambda: c.get("/health").json()["queue"]["active"] == 0, 10, "an idle server")
        r = c.post("/simulations", json={**body, "options": {"spacing_mm": 0.051}})
        assert r.status_code == 422 and r.json()["detail"]["field"] == "options.spacing_mm", r.text
        r = c.post("/simulations", json={**body, "program": None, "gcode": slow, "stock": "iso320"})
        assert r.status_code == 422, r.text
        assert r.json()["detail"]["field"] == "gcode" and "F0.0001" in slow.splitlines()[r.json()["detail"]["line"] - 1]
        assert c.get("/health").json()["queue"]["active"] == 0  # nothing was queued
        r = c.post("/simulations", json={**body, "options": {"spacing_mm": 2.0}})
        assert r.status_code == 202, r.text
        c.delete(f"/jobs/{r.json()['id']}")


# ---- 3. cancel means gone ----------------------------------------------------------------------
def test_cancel_of_a_running_job_ends_its_worker_processes_within_seconds(srv):
    with srv.client() as c:
        job = c.post("/simulations", json=LONG_JOB).json()["id"]
        wait_for(c, job, ("running",), timeout=120)
        workers = wait_until(lambda: job_workers(srv.proc.pid), 30, "a worker process under the server")
        t0 = time.time()
        r = c.delete(f"/simulations/{job}")
        assert r.status_code == 200 and r.json()["state"] == "cancelled"
        wait_until(lambda: not alive(workers), 5, f"workers {workers} ended after the cancel")
        took = time.time() - t0
        assert took < 5
        assert c.get(f"/jobs/{job}").json()["state"] == "cancelled"
        # the slot is free for new work once the supervisor has reaped the process
        wait_until(lambda: c.get("/health").json()["queue"]["active"] == 0, 5, "the worker slot freed")


# ---- 5. damaged results ----------------------------------------------------------------------
def test_a_damaged_result_is_named_and_marks_its_job_failed(srv):
    job, files = fabricate_finished_job(srv.data_dir)
    with srv.client() as c:
        assert served_files(c, job) == as_stored(files)
        # altered but still valid JSON: caught by the digest recorded when the job finished
        path = srv.data_dir / "jobs" / job / "ranking.json"
        path.write_text(path.read_text().replace("1.25", "0.25"))
        r = c.get(f"/simulations/{job}/ranking")
        assert r.status_code == 409 and r.headers["content-type"].startswith("application/json")
        assert job in r.json()["detail"] and "ranking.json" in r.json()["detail"]
        st = c.get(f"/jobs/{job}").json()
        assert st["state"] == "failed" and "ranking.json" in st["error"]["message"]
        assert c.get(f"/simulations/{job}/report").status_code == 409
    job2, _ = fabricate_finished_job(srv.data_dir)
    with srv.client() as c:
        (srv.data_dir / "jobs" / job2 / "report.json").write_bytes(b"\x00{garbage")
        r = c.get(f"/simulations/{job2}/report")
        assert r.status_code == 409 and job2 in r.json()["detail"]
        (srv.data_dir / "jobs" / job2 / "workpiece" / "near.glb").unlink()
        assert c.get(f"/simulations/{job2}/workpiece/near.glb").status_code == 409


# ---- 3 and 5: crash, restart, damaged store --------------------------------------------------
def test_kill_9_leaves_no_worker_and_a_restart_serves_finished_results_unchanged(make_server, tmp_path):
    data = tmp_path / "svc"
    data.mkdir()
    done, files = fabricate_finished_job(data)
    a = make_server(data_dir=data)
    with a.client() as c:
        before = served_files(c, done)
        assert before == as_stored(files)
        job = c.post("/simulations", json=LONG_JOB).json()["id"]
        wait_for(c, job, ("running",), timeout=120)
        workers = wait_until(lambda: job_workers(a.proc.pid), 30, "a worker process under the server")
    a.kill()  # SIGKILL the server alone: its workers are orphaned, the kernel must end them
    wait_until(lambda: not alive(workers), 5, f"workers {workers} ended with their server")
    b = make_server(data_dir=data)
    with b.client() as c:
        assert served_files(c, done) == before
        st = c.get(f"/jobs/{job}").json()
        assert st["state"] == "failed" and st["error"]["message"] == RESTART_REASON.format(state="running")
        assert c.get(f"/jobs/{done}").json()["state"] == "succeeded"


def test_a_damaged_job_store_makes_serve_exit_2_with_one_line_naming_the_file(tmp_path):
    from identify.errors import InputError

    garbage = tmp_path / "garbage" / "jobs.sqlite"
    garbage.parent.mkdir()
    garbage.write_bytes(b"this is not a database" * 100)
    r = subprocess.run([GREYBENCH, "serve", "--port", "1"], env=server_env(garbage.parent), capture_output=True,
                       text=True, timeout=120)
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert r.returncode == 2, r.stderr[-2000:]
    assert len(lines) == 1 and str(garbage) in lines[0] and "damaged" in lines[0], r.stderr[-2000:]
    # a real store with a page in the middle overwritten: found by the check the server runs at start
    torn = tmp_path / "torn" / "jobs.sqlite"
    store = JobStore(torn)
    for i in range(300):
        store.create(JobKind.simulation, {"pad": "x" * 400, "i": i}, boot="b")
    store._conn().execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.close()
    with torn.open("r+b") as f:
        f.seek(4096 * 5)
        f.write(os.urandom(4096))
    with pytest.raises(InputError, match="damaged job store") as exc:
        JobStore(torn, check=True)
    assert exc.value.source == str(torn)


# ---- 3: the kernel ends workers and their children with the parent ---------------------------
_ORPHAN_SCRIPT = r"""
import multiprocessing, os, sys, time
from service.jobs import die_with_parent

def worker(parent, out):
    die_with_parent(parent)
    child = os.fork()  # a process the job starts (e.g. a process pool of the pipeline)
    if child == 0:
        time.sleep(300)
        os._exit(0)
    with open(out, "w") as f:
        f.write(f"{os.getpid()} {child}")
    time.sleep(300)

if __name__ == "__main__":
    p = multiprocessing.get_context("spawn").Process(target=worker, args=(os.getpid(), sys.argv[1]))
    p.start()
    time.sleep(300)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signal: Linux")
def test_workers_and_the_processes_they_fork_die_with_their_parent(tmp_path):
    script = tmp_path / "orphan.py"
    script.write_text(_ORPHAN_SCRIPT)
    out = tmp_path / "pids"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    parent = subprocess.Popen([sys.executable, str(script), str(out)], env=env, start_new_session=True)
    try:
        wait_until(lambda: out.exists() and out.read_text().count(" ") == 1, 60, "the worker's pids")
        pids = {int(p): process_start(int(p)) for p in out.read_text().split()}
        assert not any(s is None for s in pids.values())
        parent.kill()  # kill -9: no cleanup code of the parent runs
        parent.wait(10)
        wait_until(lambda: not alive(pids), 5, f"worker and its child {pids} ended")
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(parent.pid, signal.SIGKILL)


# ---- soak: many clients, jobs, cancels and a crash; nothing lost ------------------------------
SHORT_CUT = {"stock": "iso160", "pose_set": "iso160", "select": ["near"], "options": {"spacing_mm": 2.0},
             "friction": ROBOT_FRICTION}
UNREACHABLE = {"program": "iso160", "poses": [{"name": "far", "xyz": [9.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}],
               "friction": ROBOT_FRICTION}


@pytest.mark.slow  # about two minutes: dozens of jobs on a 2-core machine, a crash and a restart
def test_soak_with_three_keys_cancels_and_a_crash_loses_nothing(make_server, tmp_path):
    import random

    from service.loadtest import load

    rng = random.Random(21)
    keys = [KEY, OTHER_KEY, "third-key-000111222"]
    data = tmp_path / "soak"
    env = dict(GREYBENCH_API_KEYS=",".join(keys), GREYBENCH_WORKERS=2, GREYBENCH_QUEUE_SIZE=6,
               GREYBENCH_JOBS_PER_KEY=3)
    a = make_server(data_dir=data, **env)
    submitted: dict[str, str] = {}  # job -> key
    statuses: dict[int, int] = {}
    good = {"gcode": short_program(), **SHORT_CUT}
    deadline = time.time() + 60
    with httpx.Client(base_url=a.url, timeout=60) as c:
        while time.time() < deadline and len(submitted) < 40:
            key = rng.choice(keys)
            h = {"X-API-Key": key}
            action = rng.random()
            if action < 0.5:
                body = good if rng.random() < 0.5 else UNREACHABLE
                r = c.post("/simulations", json=body, headers=h)
                if r.status_code == 202:
                    assert body is good, r.text
                    submitted[r.json()["id"]] = key
                elif body is UNREACHABLE:   # refused at submission, never queued
                    assert r.status_code == 422 and r.json()["detail"]["field"] == "poses.0", r.text
                else:
                    assert r.status_code == 429 and "Retry-After" in r.headers, r.text
            elif action < 0.65 and submitted:
                r = c.delete(f"/jobs/{rng.choice(list(submitted))}", headers=h)
            else:
                r = c.get(f"/jobs/{rng.choice(list(submitted))}" if submitted else "/health", headers=h)
            statuses[r.status_code] = statuses.get(r.status_code, 0) + 1
            time.sleep(0.2)
        done = [j for j in submitted if c.get(f"/jobs/{j}", headers=HEADERS).json()["state"] == "succeeded"]
        rankings = {j: c.get(f"/simulations/{j}/ranking", headers=HEADERS).json() for j in done}
        busy = load(a.url, HEADERS, [f"/jobs/{j}" for j in list(submitted)[:5]] or ["/health"], clients=50,
                    duration=5.0)
        workers = job_workers(a.proc.pid)
    a.kill()
    wait_until(lambda: not alive(workers), 5, "workers ended with the killed server")
    b = make_server(data_dir=data, **env)
    with httpx.Client(base_url=b.url, headers=HEADERS, timeout=60) as c:
        final = {j: c.get(f"/jobs/{j}").json() for j in submitted}
        assert all(st["state"] in ("succeeded", "failed", "cancelled") for st in final.values())  # none lost
        for j, ranking in rankings.items():
            assert c.get(f"/simulations/{j}/ranking").json() == ranking
    assert not any(code >= 500 for code in statuses) and busy["errors"] == 0, (statuses, busy)
    print(f"soak: {sum(statuses.values())} requests {statuses}, {len(submitted)} jobs, {len(done)} succeeded, "
          f"load p50 {busy['p50_ms']:.1f} ms p95 {busy['p95_ms']:.1f} ms, workers left 0")
