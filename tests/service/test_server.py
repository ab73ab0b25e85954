"""A real uvicorn server on loopback: restart during a job, bounded load, property tests from the schema."""
from __future__ import annotations

import time

import httpx
import pytest

from service.jobs import RESTART_REASON

#: Placed 9 m from the robot: the job's inverse kinematics fails and names the program line.
UNREACHABLE = {"program": "iso160", "poses": [{"name": "far", "xyz": [9.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}]}
TWO_POSES = {"program": "iso160", "pose_set": "iso160", "options": {"spacing_mm": 2.0}}


def wait_for(client: httpx.Client, job: str, states: tuple[str, ...], timeout: float = 120.0) -> dict:
    deadline = time.time() + timeout
    while True:
        st = client.get(f"/jobs/{job}").json()
        if st["state"] in states:
            return st
        if time.time() > deadline:
            raise AssertionError(f"job {job} still {st['state']} after {timeout} s: {st}")
        time.sleep(0.1)


def test_a_job_that_fails_names_the_program_line(make_server):
    srv = make_server()
    with srv.client() as c:
        r = c.post("/simulations", json=UNREACHABLE)
        assert r.status_code == 202
        st = wait_for(c, r.json()["id"], ("failed", "succeeded"))
    assert st["state"] == "failed"
    assert st["error"]["source"] == "iso160.nc" and st["error"]["line"] >= 1
    assert "far" in st["error"]["message"]


def test_restart_during_a_job_keeps_the_records(make_server, tmp_path):
    srv = make_server()
    with srv.client() as c:
        failed = c.post("/simulations", json=UNREACHABLE).json()["id"]
        failed_before = wait_for(c, failed, ("failed",))
        cancelled = c.post("/simulations", json=UNREACHABLE).json()["id"]
        c.delete(f"/simulations/{cancelled}")
        wait_for(c, cancelled, ("cancelled",))
        job = c.post("/simulations", json=TWO_POSES).json()["id"]
        running = wait_for(c, job, ("running",), timeout=60)
    srv.kill()  # SIGKILL the server in the middle of the job

    srv2 = make_server(data_dir=srv.data_dir)
    with srv2.client() as c:
        st = c.get(f"/simulations/{job}").json()
        assert st["state"] == "failed"
        assert st["error"]["message"] == RESTART_REASON.format(state="running")
        assert st["created"] == running["created"] and st["started"] == running["started"]
        assert c.get(f"/simulations/{failed}").json() == failed_before
        assert c.get(f"/simulations/{cancelled}").json()["state"] == "cancelled"
        assert c.get(f"/simulations/{job}/ranking").status_code == 409
        # the orphaned worker of the killed server must not revive the job
        time.sleep(1.0)
        assert c.get(f"/simulations/{job}").json()["state"] == "failed"
        # and the restarted service takes new work
        again = c.post("/simulations", json=UNREACHABLE).json()["id"]
        assert wait_for(c, again, ("failed",))["error"]["line"] >= 1


def test_bounded_load_on_status_and_ranking_has_no_errors(shared_server):
    from service.loadtest import load

    with shared_server.client() as c:
        job = c.post("/simulations", json=UNREACHABLE).json()["id"]
        wait_for(c, job, ("failed",))
    paths = [f"/simulations/{job}", f"/simulations/{job}/ranking"]
    # the job failed, so its ranking is a 409 every time: anything else is an error
    res = load(shared_server.url, {"X-API-Key": "test-key-0123456789"}, paths, clients=50, duration=3.0,
               expect={paths[1]: 409})
    assert res["errors"] == 0, res
    assert res["requests"] >= 100
    assert all(row["requests"] > 0 for row in res["endpoints"])
