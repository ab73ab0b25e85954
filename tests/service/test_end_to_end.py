"""End to end on loopback: submit the 160 test piece with two poses, poll, fetch ranking, report (JSON
and CSV) and the virtual workpieces (GLB); the results stay readable after a restart.

2 mm dexels: what is asserted (the ranking's sum, the report's rows and units, the files, the restart) does not
depend on the spacing; the 1 mm view of the same piece is tests/service/test_view.py's. The first run after a
kernel change compiles the numba kernels in the worker process and takes longer.
"""
from __future__ import annotations

import csv
import io
import time
from datetime import datetime, timedelta

import pytest

from service.loadtest import load

from .conftest import KEY, ROBOT_FRICTION


def poll(c, job: str, timeout: float) -> dict:
    deadline = time.time() + timeout
    seen = []
    while True:
        st = c.get(f"/simulations/{job}").json()
        seen.append(st["progress"])
        if st["state"] in ("succeeded", "failed", "cancelled"):
            return st, seen
        assert time.time() < deadline, f"job still {st['state']} after {timeout} s: {st}"
        time.sleep(1.0)


def check_results(c, job: str, poses: list[str]) -> dict:
    ranking = c.get(f"/simulations/{job}/ranking")
    assert ranking.status_code == 200, ranking.text
    entries = ranking.json()["ranking"]
    assert sorted(e["pose"] for e in entries) == sorted(poses)
    assert [e["rank"] for e in entries] == [1, 2]
    assert entries[0]["score"] <= entries[1]["score"]

    report = c.get(f"/simulations/{job}/report").json()
    names = [f["name"] for f in report["features"]]
    assert len(names) == 10 and names[0] == "circle height zMZ" and names[-1] == "slope angle"
    for f in report["features"]:
        assert set(f["deviation_mm"]) == set(poses) and f["tolerance_mm"] > 0
    # the ranking score is the sum of |deviation| / tolerance over the rows
    for e in entries:
        total = sum(abs(f["deviation_mm"][e["pose"]]) / f["tolerance_mm"] for f in report["features"])
        assert total == pytest.approx(e["score"], rel=1e-9)
    assert {p["pose"] for p in report["poses"]} == set(poses)
    # units in the field names; form rows (roundness, straightness) have no nominal size
    by_name = {f["name"]: f for f in report["features"]}
    for form in ("circle roundness", "square straightness (4x)", "slope straightness"):
        assert by_name[form]["nominal_mm"] is None and by_name[form]["nominal_text"] == "-"
    assert by_name["circle diameter"]["nominal_mm"] > 0 and by_name["circle diameter"]["nominal_deg"] is None
    assert by_name["slope angle"]["nominal_deg"] > 0 and by_name["slope angle"]["nominal_mm"] is None

    text = c.get(f"/simulations/{job}/report", params={"format": "csv"})
    assert text.status_code == 200 and text.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(text.text)))
    assert len(rows) == 10 * len(poses)
    first = next(r for r in rows if r["feature"] == "circle diameter" and r["pose"] == poses[0])
    dev = next(f for f in report["features"] if f["name"] == "circle diameter")["deviation_mm"][poses[0]]
    assert float(first["deviation_mm"]) == pytest.approx(dev)

    for pose in poses:
        glb = c.get(f"/simulations/{job}/workpiece/{pose}.glb")
        assert glb.status_code == 200 and glb.headers["content-type"] == "model/gltf-binary"
        assert glb.content[:4] == b"glTF" and len(glb.content) > 1000
    assert c.get(f"/simulations/{job}/workpiece/nope.glb").status_code == 404
    return report


def test_submit_poll_rank_report_glb_and_restart(make_server):
    srv = make_server(GREYBENCH_WORKERS="1")
    poses = ["near", "far_rotated"]
    with srv.client() as c:
        r = c.post("/simulations", json={"program": "iso160", "pose_set": "iso160", "select": poses,
                                         "options": {"spacing_mm": 2.0},
                                         # the robot file's friction: independent of the session's registry
                                         "friction": ROBOT_FRICTION})
        assert r.status_code == 202
        job = r.json()["id"]
        st, seen = poll(c, job, timeout=3600)
        assert st["state"] == "succeeded", st
        assert st["progress"] == 1.0 and seen == sorted(seen)  # progress never goes back
        # ISO 8601 UTC timestamps, in order
        created, started, finished = (datetime.fromisoformat(st[k]) for k in ("created", "started", "finished"))
        assert created.utcoffset() == timedelta(0) and created <= started <= finished
        report = check_results(c, job, poses)
    # a short load on the finished job's status and ranking
    res = load(srv.url, {"X-API-Key": KEY}, [f"/simulations/{job}", f"/simulations/{job}/ranking"],
               clients=20, duration=3.0)
    assert res["errors"] == 0, res
    srv.stop()
    srv2 = make_server(data_dir=srv.data_dir)
    with srv2.client() as c:
        assert c.get(f"/simulations/{job}").json()["state"] == "succeeded"
        assert check_results(c, job, poses) == report
