"""Circle (ballbar) jobs: bad input answers 4xx naming the field (in process); a real server runs the
circle at iso320 pose1 and serves the trace, the plot and the summary, which agree with the CLI."""
from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pytest

from .conftest import HEADERS, ROBOT_FRICTION, wait_for

ROOT = Path(__file__).resolve().parents[2]


def test_bad_circle_input_is_4xx_naming_the_field(client):
    base = {"pose_set": "iso320", "pose": "pose1", "friction": ROBOT_FRICTION}
    r = client.post("/circles", headers=HEADERS, json={**base, "pose": "nowhere"})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "pose"
    r = client.post("/circles", headers=HEADERS, json={**base, "options": {"radius_mm": 3000}})
    assert r.status_code == 422   # beyond the schema's bound
    r = client.post("/circles", headers=HEADERS, json={**base, "options": {"radius_mm": 1500}})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "options.radius_mm", r.json()
    r = client.post("/circles", headers=HEADERS, json={**base, "options": {"feed_mm_min": 0}})
    assert r.status_code == 422
    r = client.post("/circles", headers=HEADERS, json={**base, "options": {"radius_mm": 1000, "feed_mm_min": 10}})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "options.feed_mm_min"
    r = client.post("/circles", headers=HEADERS, json={**base, "options": {"plane": "xz"}})
    assert r.status_code == 422
    r = client.post("/circles", headers=HEADERS, json={"pose": "pose1"})
    assert r.status_code == 422   # a pose name needs a pose set
    twice = [{"axis": 1, "model": "robot"}, {"axis": 1, "model": "robot"}]
    r = client.post("/circles", headers=HEADERS, json={**base, "friction": twice})
    assert r.status_code == 422 and "at most once" in r.text
    r = client.post("/circles", headers=HEADERS, json={**base, "robot": "nope"})
    assert r.status_code == 404
    assert client.post("/circles", headers={}, json=base).status_code == 401
    assert client.get("/circles/" + "0" * 32, headers=HEADERS).status_code == 404


@pytest.mark.slow
def test_circle_job_end_to_end(make_server, tmp_path):
    """Submit, poll, download: the served summary is the CLI's for the same circle."""
    from typer.testing import CliRunner

    from greybench.cli import app

    srv = make_server(GREYBENCH_WORKERS="1")
    with srv.client() as c:
        r = c.post("/circles", json={"pose_set": "iso320", "pose": "pose1", "friction": ROBOT_FRICTION})
        assert r.status_code == 202, r.text
        job = r.json()["id"]
        assert r.headers["Location"] == f"/circles/{job}"
        st = wait_for(c, job, prefix="/circles", timeout=900, interval=1.0)
        assert st["state"] == "succeeded", st
        res = st["result"]
        summary = json.loads(c.get(f"/circles/{job}/files/summary.json").text)
        trace = c.get(f"/circles/{job}/files/circle.csv")
        assert next(csv.reader(io.StringIO(trace.text)))[:2] == ["angle_deg", "radial_deviation_um"]
        png = c.get(f"/circles/{job}/files/circle.png")
        assert png.status_code == 200 and png.content[:4] == b"\x89PNG"
        assert c.get(f"/circles/{job}/files/secret.txt").status_code == 404
    r = CliRunner().invoke(app, ["circle", "--pose", str(ROOT / "data" / "poses" / "iso320.json"), "--name", "pose1",
                                 "--out", str(tmp_path / "cli"), "--json"])
    assert r.exit_code == 0, r.output
    cli = json.loads(r.stdout)
    for key in ("roundness_um", "radius_error_um", "largest_excursion_um", "largest_spike_um"):
        assert res[key] == summary[key] == cli[key], key
    assert res["largest_spike_um"] == res["largest_excursion_um"]   # the deprecated alias
    assert [f["kind"] for f in res["friction_models"]] == ["lugre"] * 6
