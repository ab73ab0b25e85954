"""A real uvicorn server on loopback: restart during a job, bounded load, property tests from the schema."""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

from service.jobs import RESTART_REASON

from .conftest import DATA, ROBOT_FRICTION, short_program, wait_for

#: Placed 9 m from the robot: refused at submission, naming the pose and the program line.
UNREACHABLE = {"program": "iso160", "poses": [{"name": "far", "xyz": [9.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}],
               "friction": ROBOT_FRICTION}
TWO_POSES = {"program": "iso160", "pose_set": "iso160", "options": {"spacing_mm": 2.0}, "friction": ROBOT_FRICTION}


def test_restart_during_a_job_keeps_the_records(make_server, tmp_path):
    srv = make_server()
    with srv.client() as c:
        # a pose out of reach is refused before a job exists, naming the program line and the pose
        r = c.post("/simulations", json=UNREACHABLE)
        d = r.json()["detail"]
        assert r.status_code == 422 and d["source"] == "iso160.nc" and d["line"] >= 1 and "far" in d["message"]
        cancelled = c.post("/simulations", json=TWO_POSES).json()["id"]
        c.delete(f"/simulations/{cancelled}")
        cancelled_before = wait_for(c, cancelled, ("cancelled",))
        job = c.post("/simulations", json=TWO_POSES).json()["id"]
        running = wait_for(c, job, ("running",), timeout=60)
    srv.kill()  # SIGKILL the server in the middle of the job

    srv2 = make_server(data_dir=srv.data_dir)
    with srv2.client() as c:
        st = c.get(f"/simulations/{job}").json()
        assert st["state"] == "failed"
        assert st["error"]["message"] == RESTART_REASON.format(state="running")
        assert st["created"] == running["created"] and st["started"] == running["started"]
        assert c.get(f"/simulations/{cancelled}").json() == cancelled_before
        assert c.get(f"/simulations/{job}/ranking").status_code == 409
        # the worker of the killed server ended with it and did not revive the job
        time.sleep(2.0)
        assert c.get(f"/simulations/{job}").json()["state"] == "failed"
        with pytest.raises(ProcessLookupError):  # nothing of the killed server's process group is left
            os.killpg(srv.proc.pid, 0)
        # and the restarted service takes new work
        again = c.post("/simulations", json=TWO_POSES).json()["id"]
        assert wait_for(c, again, ("running",), timeout=60)["started"]
        c.delete(f"/simulations/{again}")
        wait_for(c, again, ("cancelled",))


def test_bounded_load_on_status_and_ranking_has_no_errors(shared_server):
    from service.loadtest import load

    with shared_server.client() as c:
        job = c.post("/simulations", json=TWO_POSES).json()["id"]
        c.delete(f"/simulations/{job}")
        wait_for(c, job, ("cancelled",))
    paths = [f"/simulations/{job}", f"/simulations/{job}/ranking"]
    # the job was cancelled, so its ranking is a 409 every time: anything else is an error
    res = load(shared_server.url, {"X-API-Key": "test-key-0123456789"}, paths, clients=50, duration=2.0,
               expect={paths[1]: 409})
    assert res["errors"] == 0, res
    assert res["requests"] >= 100 and all(row["requests"] > 0 for row in res["endpoints"])


def test_short_job_results_and_bounded_load_without_errors(shared_server):
    from service.loadtest import load

    with shared_server.client() as c:
        r = c.post("/simulations", json={"gcode": short_program(), "stock": "iso160", "pose_set": "iso160",
                                         "options": {"spacing_mm": 2.0}, "friction": ROBOT_FRICTION})
        assert r.status_code == 202, r.text
        job = r.json()["id"]
        st = wait_for(c, job, ("succeeded", "failed"), timeout=600)
        assert st["state"] == "succeeded", st
        ranking = c.get(f"/simulations/{job}/ranking").json()["ranking"]
        assert sorted(e["pose"] for e in ranking) == ["far_rotated", "near"] and ranking[0]["rank"] == 1
        report = c.get(f"/simulations/{job}/report").json()
        assert len(report["features"]) == 10
        for e in ranking:  # the score is the sum of |deviation| / tolerance
            assert e["score"] == pytest.approx(sum(abs(f["deviation_mm"][e["pose"]]) / f["tolerance_mm"]
                                                   for f in report["features"]), rel=1e-9)
        assert len(c.get(f"/simulations/{job}/report?format=csv").text.strip().splitlines()) == 1 + 20
        glb = c.get(f"/simulations/{job}/workpiece/near.glb")
        assert glb.status_code == 200 and glb.content[:4] == b"glTF"
    paths = [f"/simulations/{job}", f"/simulations/{job}/ranking"]
    res = load(shared_server.url, {"X-API-Key": "test-key-0123456789"}, paths, clients=50, duration=2.0)
    assert res["errors"] == 0, res
    assert res["requests"] >= 100 and all(row["requests"] > 0 for row in res["endpoints"])


def _record_csv(seed: int, n: int = 2000) -> str:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 2e-3
    q = 0.5 * np.sin(2 * np.pi * 0.7 * t)
    qd = 0.5 * 2 * np.pi * 0.7 * np.cos(2 * np.pi * 0.7 * t)
    tau = 1.0 * np.tanh(qd / 2e-3) + 0.6 * qd + rng.normal(0, 0.02, n)
    lines = ["t,q,qd,tau"] + [f"{a:.6f},{b:.9f},{c:.9f},{d:.9f}" for a, b, c, d in zip(t, q, qd, tau, strict=True)]
    return "\n".join(lines) + "\n"


def test_diagnose_runs_as_a_job(shared_server):
    with shared_server.client() as c:
        r = c.post("/diagnose", json={"train_csv": _record_csv(1), "test_csv": _record_csv(2), "generations": 3})
        assert r.status_code == 202 and r.headers["Location"] == f"/jobs/{r.json()['id']}"
        assert r.json()["kind"] == "diagnose"
        st = wait_for(c, r.json()["id"], ("succeeded", "failed"), timeout=300)
    assert st["state"] == "succeeded", st
    res = st["result"]
    assert set(res) >= {"cause", "ranking", "baseline", "extended", "gain"}
    assert res["baseline"]["test_rmse"] > 0 and np.isfinite(res["gain"])


def test_friction_models_are_pinned_and_loaded_into_the_simulation(shared_server, registered_model):
    """Axis 1 takes the registered champion (a Coulomb-viscous model, version 1, no LuGre form): the
    job fetches it, the coupled loop runs it as axis 1's friction and the report names the version;
    an unknown version is 404. (Grey-box, residual and LSTM champions: test_learned_champions.py.)"""
    body = {"gcode": short_program(), "stock": "iso160", "pose_set": "iso160", "select": ["near"],
            "friction": [{"axis": 1}] + ROBOT_FRICTION[1:]}
    with shared_server.client() as c:
        r = c.post("/simulations", json=body)
        assert r.status_code == 202, r.text
        st = wait_for(c, r.json()["id"], ("succeeded", "failed"), timeout=300)
        assert st["state"] == "succeeded", st
        report = c.get(f"/simulations/{r.json()['id']}/report").json()
        used = report["poses"][0]["friction"][0]
        assert used["kind"] == "coulomb-viscous" and used["model"]["version"] == 1
        assert used["model"]["name"] == "max100-axis1-friction" and used["model"]["ref"] == "champion"
        r = c.post("/simulations", json={**body, "friction": [{"axis": 1, "model": "9"}]})
        assert r.status_code == 404 and "max100-axis1-friction" in r.json()["detail"]


@pytest.mark.slow  # a simulation, its sensitivities and a calibration: minutes on 2 shared cores
def test_explain_runs_as_a_job_and_names_no_cause_for_the_nominal_robot(shared_server, tmp_path):
    from simulate.evaluation.ranking import RankSettings, rank_poses
    from simulate.toolpath.placement import load_poses

    program = tmp_path / "short.nc"
    program.write_text(short_program())
    (tmp_path / "short.stock.json").write_text((DATA / "programs" / "iso160.stock.json").read_text())
    near = [p for p in load_poses(DATA / "poses" / "iso160.json") if p.name == "near"]
    rank_poses(program, DATA / "robots" / "max100.toml", near, settings=RankSettings(spacing=2e-3, size=160),
               out_dir=tmp_path / "measured", workers=1)
    scan = (tmp_path / "measured" / "near" / "scan.csv").read_text()
    body = {"scan_csv": scan, "gcode": short_program(), "stock": "iso160", "pose_set": "iso160", "pose": "near",
            "spacing_mm": 2.0, "max_sims": 1}
    with shared_server.client() as c:
        r = c.post("/explain", json=body)
        assert r.status_code == 202, r.text
        st = wait_for(c, r.json()["id"], ("succeeded", "failed"), timeout=1800)
    assert st["state"] == "succeeded", st
    res = st["result"]
    assert set(res) >= {"cause", "ranking", "calibrated", "rms_before", "rms_after", "gain"}
    assert res["cause"] == "none"
