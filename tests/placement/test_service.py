"""Placement-search jobs of the service (in process, TestClient with one worker): 4xx naming the field before
admission, a small search to the end with its files, and a cancel."""
from __future__ import annotations

import json
import time

import pytest

from .conftest import SMALL

KEY = "placement-key-0123456789"
HEADERS = {"X-API-Key": KEY}
GCODE = (SMALL / "small160.nc").read_text()
GIVEN = json.loads((SMALL / "small160.poses.json").read_text())["poses"]


@pytest.fixture
def client(tmp_path, monkeypatch):
    from fastapi.testclient import TestClient

    from service.app import create_app
    from service.settings import load_settings

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    settings = load_settings(api_keys=KEY, data_dir=tmp_path / "data", workers=1, queue_size=1, retry_after=7)
    with TestClient(create_app(settings)) as c:
        yield c


def _body(**options):
    return {"gcode": GCODE, "stock": "iso160", "poses": GIVEN, "options": {"spacing_mm": 1.0, **options}}


def _wait(client, job, timeout=300.0):
    deadline = time.time() + timeout
    while True:
        st = client.get(f"/placement-searches/{job}", headers=HEADERS).json()
        if st["state"] in ("succeeded", "failed", "cancelled"):
            return st
        assert time.time() < deadline, st
        time.sleep(0.5)


def test_bad_requests_are_4xx_naming_the_field(client):
    r = client.post("/placement-searches", headers=HEADERS, json=_body(budget_s=0.5))
    assert r.status_code == 422 and r.json()["detail"]["field"] == "options.budget_s", r.text
    assert "too short" in r.json()["detail"]["message"]
    r = client.post("/placement-searches", headers=HEADERS, json=_body(budget_s=0))
    assert r.status_code == 422 and "budget_s" in r.json()["detail"][0]["field"]
    far = {**_body(), "poses": [{"name": "moon", "xyz": [30.0, 0.0, 0.0], "rpy": [0, 0, 0]}]}
    r = client.post("/placement-searches", headers=HEADERS, json=far)
    # the given pose itself is out of reach: refused at submission naming it, before any planning
    assert r.status_code == 422 and r.json()["detail"]["field"] == "poses.0", r.text
    assert "moon" in r.json()["detail"]["message"] and "reachable" in r.json()["detail"]["message"]
    r = client.post("/placement-searches", headers=HEADERS, json={"program": "nope", "pose_set": "iso160"})
    assert r.status_code == 404
    r = client.post("/placement-searches", headers=HEADERS, json={"program": "iso160", "pose_set": "iso160",
                                                                  "poses": GIVEN})
    assert r.status_code == 422
    assert client.post("/placement-searches", json=_body()).status_code == 401
    assert client.get("/placement-searches/" + "0" * 32, headers=HEADERS).status_code == 404


def test_a_search_runs_to_the_end_and_serves_its_files(client):
    r = client.post("/placement-searches", headers=HEADERS, json=_body(budget_s=120, max_simulations=1, seed=2))
    assert r.status_code == 202, r.text
    job = r.json()["id"]
    assert r.headers["Location"] == f"/placement-searches/{job}"
    st = _wait(client, job)
    assert st["state"] == "succeeded", st
    res = st["result"]
    assert [g["name"] for g in res["given"]] == [p["name"] for p in GIVEN]
    assert res["best"]["score"] <= min(g["score"] for g in res["given"])
    best = client.get(f"/placement-searches/{job}/files/best.json", headers=HEADERS)
    assert best.status_code == 200
    assert [{k: p[k] for k in ("name", "xyz", "rpy")} for p in best.json()["poses"][:2]] == GIVEN
    png = client.get(f"/placement-searches/{job}/files/heatmap.png", headers=HEADERS)
    assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Search history" in client.get(f"/placement-searches/{job}/files/report.md", headers=HEADERS).text
    assert client.get(f"/placement-searches/{job}/files/secret.txt", headers=HEADERS).status_code == 404
    assert client.get(f"/jobs/{job}", headers=HEADERS).json()["kind"] == "placement_search"


def test_delete_cancels_a_running_search(client):
    r = client.post("/placement-searches", headers=HEADERS, json=_body(budget_s=3600))
    assert r.status_code == 202, r.text
    job = r.json()["id"]
    time.sleep(1.0)
    r = client.delete(f"/placement-searches/{job}", headers=HEADERS)
    assert r.status_code == 200 and r.json()["state"] == "cancelled"
    assert _wait(client, job, 30)["state"] == "cancelled"
    r = client.get(f"/placement-searches/{job}/files/best.json", headers=HEADERS)
    assert r.status_code == 409
