"""Compensation jobs: bad input answers 4xx naming the place (in process), and, marked slow, a
real server compensates iso160 for one pose: poll, download the program and the tables."""
from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pytest

from .conftest import HEADERS, ROBOT_FRICTION, wait_for

BAD_GCODE = "G21 G90 G17\nG0 X0 Y0 Z5\nG1 X10 Y0 Z0 F300\nG1 X10 Y10 Q\n"


def test_bad_gcode_unknown_pose_and_names_are_4xx(client):
    r = client.post("/compensations", headers=HEADERS, json={"gcode": BAD_GCODE, "stock": "iso160",
                                                            "pose_set": "iso160", "pose": "near"})
    assert r.status_code == 422 and r.json()["detail"]["source"] == "gcode" and r.json()["detail"]["line"] == 4
    r = client.post("/compensations", headers=HEADERS, json={"program": "iso160", "pose_set": "iso160", "pose": "far",
                                                            "friction": ROBOT_FRICTION})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "pose" and "far" in r.json()["detail"]["message"]
    r = client.post("/compensations", headers=HEADERS, json={"program": "nope", "pose_set": "iso160", "pose": "near"})
    assert r.status_code == 404
    r = client.post("/compensations", headers=HEADERS, json={"program": "iso160", "pose": "near"})
    assert r.status_code == 422   # a pose name needs a pose set
    for key in ("ff_friction", "backlash_comp"):   # the NC options are switches
        r = client.post("/compensations", headers=HEADERS, json={"program": "iso160", "pose_set": "iso160",
                                                                "pose": "near", "options": {key: "sometimes"}})
        assert r.status_code == 422 and key in str(r.json()["detail"]), r.text
    r = client.post("/compensations", headers={}, json={})
    assert r.status_code == 401
    assert client.get("/compensations/" + "0" * 32, headers=HEADERS).status_code == 404


@pytest.mark.slow
def test_compensation_job_end_to_end(make_server):
    srv = make_server(GREYBENCH_WORKERS="1")
    with srv.client() as c:
        r = c.post("/compensations", json={"program": "iso160", "pose_set": "iso160", "pose": "near",
                                           "friction": ROBOT_FRICTION,
                                           "options": {"spacing_mm": 1.0, "iterations": 1}})
        assert r.status_code == 202, r.text
        job = r.json()["id"]
        assert r.headers["Location"] == f"/compensations/{job}"
        st = wait_for(c, job, prefix="/compensations", timeout=1800, interval=1.0)
        assert st["state"] == "succeeded", st
        ev = st["result"]["evaluation"]
        assert ev["ratio"] < 0.6 and len(ev["rows_mm"]) == 10
        prog = c.get(f"/compensations/{job}/files/compensated.nc")
        assert prog.status_code == 200 and "F2000" in prog.text and "S12000" in prog.text
        off = c.get(f"/compensations/{job}/files/offsets.csv")
        header = next(csv.reader(io.StringIO(off.text)))
        assert header[:5] == ["t_s", "line", "dx_mm", "dy_mm", "dz_mm"]
        ff = c.get(f"/compensations/{job}/files/feedforward.csv")
        assert next(csv.reader(io.StringIO(ff.text)))[2] == "tau_f1_Nm"
        assert c.get(f"/compensations/{job}/files/secret.txt").status_code == 404


def test_accepted_job_reports_its_status(client):
    """An accepted compensation job answers 202 and its status validates (kind 'compensation')."""
    r = client.post("/compensations", headers=HEADERS, json={"program": "iso160", "pose_set": "iso160",
                                                            "pose": "near", "friction": ROBOT_FRICTION,
                                                            "options": {"spacing_mm": 2.0, "iterations": 1}})
    assert r.status_code == 202, r.text
    st = client.get(r.headers["Location"], headers=HEADERS)
    assert st.status_code == 200, st.text
    assert st.json()["kind"] == "compensation"
    client.delete(r.headers["Location"], headers=HEADERS)


def test_job_body_passes_robot_file_and_models(tmp_path, monkeypatch):
    """The job body hands run_compensation the shipped robot file and the fetched model folders per axis."""
    from service import compensation
    from service.paths import DATA_DIR
    from simulate.compensation import job as compensation_job

    seen = {}

    def fake(program, robot, poses, name, out, **kw):
        seen.update(robot=robot, friction=kw["friction"], program=program.read_text(),
                    nc=(kw["ff_friction"], kw["backlash_comp"]))
        return {"evaluation": {}}

    monkeypatch.setattr(compensation_job, "run_compensation", fake)
    gcode = (DATA_DIR / "programs" / "iso160.nc").read_text()
    (tmp_path / "program.nc").write_text(gcode)
    (tmp_path / "stock.json").write_text((DATA_DIR / "programs" / "iso160.stock.json").read_text())
    req = {"program_source": "gcode", "stock_source": "stock", "robot": "max100",
           "pose": json.loads((DATA_DIR / "poses" / "iso160.json").read_text())["poses"][0],
           "friction": [], "options": {"iterations": 1}}
    info = compensation.run(req, tmp_path, lambda *a: None)
    assert Path(seen["robot"]).is_file() and Path(seen["robot"]).suffix == ".toml"
    assert seen["friction"] == {} and seen["program"] == gcode
    assert seen["nc"] == (False, False)     # the NC options are off unless asked for
    assert "compensated.nc" in info["files"]
    compensation.run({**req, "options": {"iterations": 1, "ff_friction": True, "backlash_comp": True}}, tmp_path,
                     lambda *a: None)
    assert seen["nc"] == (True, True)


def test_job_progress_ends_where_run_compensation_counts_to(tmp_path, monkeypatch):
    """The job's progress total is run_compensation's own (progress_total of the program's steps): counting
    it all brings the job to 95 % (the rest is writing the files), never past."""
    from service import compensation
    from service.paths import DATA_DIR
    from simulate.compensation import job as compensation_job
    from simulate.pipeline import load_program

    gcode = (DATA_DIR / "programs" / "iso160.nc").read_text()
    (tmp_path / "program.nc").write_text(gcode)
    (tmp_path / "stock.json").write_text((DATA_DIR / "programs" / "iso160.stock.json").read_text())
    shipped = DATA_DIR / "programs" / "iso160.nc"
    total = compensation_job.progress_total(len(load_program(shipped, require_spindle=True).interp), 2, 1.0, [0.8])

    def fake(program, robot, poses, name, out, advance, **kw):
        for _ in range(total // 1000):
            advance(1000)
        advance(total % 1000)
        return {}

    monkeypatch.setattr(compensation_job, "run_compensation", fake)
    seen = []
    req = {"program_source": "gcode", "stock_source": "stock", "robot": "max100",
           "pose": json.loads((DATA_DIR / "poses" / "iso160.json").read_text())["poses"][0],
           "friction": [], "options": {"iterations": 2, "check_scales": [0.8]}}
    compensation.run(req, tmp_path, lambda frac, *a: seen.append(frac))
    fracs = [f for f in seen if f is not None]
    assert fracs[-1] == pytest.approx(0.95) and max(fracs) <= 0.95 + 1e-12
    assert fracs[-2] < 0.95
