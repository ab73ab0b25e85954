"""Keys are isolated: every job of every kind belongs to the key that submitted it. Another key gets 404
for its status, results, files, view page, view link and cancel, and does not see it listed; every kind
counts toward the key's limit; the admin key sees, lists and cancels every job. In process, with the job
supervisor stopped so the jobs stay queued (no simulation runs)."""
from __future__ import annotations

import numpy as np
import pytest

from .conftest import ROBOT_FRICTION

KEY_A = "key-a-0123456789"
KEY_B = "key-b-0123456789"
ADMIN = "admin-key-0123456789"
A, B, ROOT = ({"X-API-Key": k} for k in (KEY_A, KEY_B, ADMIN))


def _record_csv(seed: int, n: int = 400) -> str:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 2e-3
    qd = 0.5 * 2 * np.pi * 0.7 * np.cos(2 * np.pi * 0.7 * t)
    q = 0.5 * np.sin(2 * np.pi * 0.7 * t)
    tau = np.tanh(qd / 2e-3) + 0.6 * qd + rng.normal(0, 0.02, n)
    rows = zip(t, q, qd, tau, strict=True)
    return "t,q,qd,tau\n" + "".join(f"{a:.6f},{b:.9f},{c:.9f},{d:.9f}\n" for a, b, c, d in rows)


#: One valid submission of every job kind: (route, body, kind, the kind's own route prefix).
SUBMISSIONS = [
    ("/simulations", {"program": "iso160", "pose_set": "iso160", "select": ["near"], "friction": ROBOT_FRICTION},
     "simulation", "/simulations"),
    ("/compensations", {"program": "iso160", "pose_set": "iso160", "pose": "near", "friction": ROBOT_FRICTION},
     "compensation", "/compensations"),
    ("/circles", {"pose_set": "iso320", "pose": "pose1", "friction": ROBOT_FRICTION}, "circle", "/circles"),
    ("/placement-searches", {"program": "iso160", "pose_set": "iso160", "select": ["near"]},
     "placement_search", "/placement-searches"),
    ("/explain", {"scan_csv": "feature,x,y,z\ncircle,0,0,0\n", "program": "iso160", "pose_set": "iso160",
                  "pose": "near"}, "explain", "/jobs"),
    ("/diagnose", {"train_csv": _record_csv(1), "test_csv": _record_csv(2), "generations": 1}, "diagnose", "/jobs"),
]
#: Kinds with a planner's page (and a view link).
VIEWED = {"simulation": "/simulations", "compensation": "/compensations", "circle": "/circles",
          "placement_search": "/placement-searches"}
#: A result file name per kind with files (the route answers 409 to the owner while the job is queued).
FILE_ROUTES = {"simulation": "ranking", "compensation": "files/summary.json", "circle": "files/summary.json",
               "placement_search": "files/summary.json"}


def _app(tmp_path, monkeypatch, per_key: int):
    from fastapi.testclient import TestClient

    from service.app import create_app
    from service.jobs import JobManager
    from service.settings import load_settings

    monkeypatch.setattr(JobManager, "_pass", lambda self: None)  # nothing starts: the jobs stay queued
    settings = load_settings(api_keys=f"{KEY_A},{KEY_B}", admin_key=ADMIN, data_dir=tmp_path / "data", workers=1,
                             queue_size=40, jobs_per_key=per_key, max_body_bytes=1024 * 1024)
    return TestClient(create_app(settings))


@pytest.fixture(scope="module")
def jobs_of_a(tmp_path_factory):
    """A server whose key A holds one queued job of every kind: (client, {kind: (id, prefix)})."""
    mp = pytest.MonkeyPatch()
    with _app(tmp_path_factory.mktemp("own"), mp, per_key=20) as c:
        jobs = {}
        for route, body, kind, prefix in SUBMISSIONS:
            r = c.post(route, headers=A, json=body)
            assert r.status_code == 202, (route, r.text)
            assert r.json()["kind"] == kind
            jobs[kind] = (r.json()["id"], prefix)
        yield c, jobs
    mp.undo()


def test_every_kind_records_the_submitting_key(jobs_of_a):
    from service.jobs import owner_of

    c, jobs = jobs_of_a
    assert len(jobs) == 6
    store = c.app.state.store
    for kind, (job, _) in jobs.items():
        assert store.get(job).owner == owner_of(KEY_A) != owner_of(KEY_B), kind


def test_another_key_cannot_read_link_open_or_cancel(jobs_of_a):
    c, jobs = jobs_of_a
    for kind, (job, prefix) in jobs.items():
        # the owner reads its status on the kind's route and on /jobs; B gets 404, as for an unknown id
        for route in {prefix, "/jobs"}:
            assert c.get(f"{route}/{job}", headers=A).status_code == 200, (kind, route)
            r = c.get(f"{route}/{job}", headers=B)
            assert r.status_code == 404 and job in r.json()["detail"], (kind, route, r.text)
            assert r.json()["detail"] == c.get(f"{route}/{'f' * 32}", headers=B).json()["detail"].replace(
                "f" * 32, job)
        assert c.delete(f"/jobs/{job}", headers=B).status_code == 404, kind
        if kind in FILE_ROUTES:
            url = f"{prefix}/{job}/{FILE_ROUTES[kind]}"
            assert c.get(url, headers=A).status_code == 409, (kind, url)   # the owner: not finished yet
            assert c.get(url, headers=B).status_code == 404, (kind, url)
        if kind in VIEWED:
            assert c.post(f"{prefix}/{job}/view-link", headers=B, json={}).status_code == 404, kind
            assert c.get(f"{prefix}/{job}/view", headers=B).status_code == 404, kind
            assert c.get(f"{prefix}/{job}/view/data", headers=B).status_code == 404, kind
            assert c.get(f"{prefix}/{job}/view", headers=A).status_code == 409, kind
            link = c.post(f"{prefix}/{job}/view-link", headers=A, json={})
            assert link.status_code == 200, kind
            # the owner's signed link opens the job for whoever holds it, and that job only
            assert c.get(link.json()["url"]).status_code == 409, kind
            other = next(j for k, (j, _) in jobs.items() if k != kind and k in VIEWED)
            token = link.json()["token"]
            assert c.get(f"{VIEWED[kind]}/{other}/view/data", params={"token": token}).status_code in (401, 404)
        assert c.get(f"/jobs/{job}", headers=A).json()["state"] == "queued", kind   # B's cancels did nothing


def test_another_key_does_not_see_them_listed_and_the_admin_sees_all(jobs_of_a):
    c, jobs = jobs_of_a
    mine = c.get("/jobs", headers=A).json()
    assert mine["total"] == 6 and {j["id"] for j in mine["jobs"]} == {j for j, _ in jobs.values()}
    assert {j["kind"] for j in mine["jobs"]} == set(jobs) and mine["next_offset"] is None
    assert c.get("/jobs", headers=B).json() == {"jobs": [], "total": 0, "limit": 50, "offset": 0, "next_offset": None}
    assert c.get("/jobs", headers=B, params={"kind": "circle"}).json()["total"] == 0
    everyone = c.get("/jobs", headers=ROOT).json()
    assert {j["id"] for j in everyone["jobs"]} >= {j for j, _ in jobs.values()}


def test_the_list_pages_newest_first_and_filters(jobs_of_a):
    c, jobs = jobs_of_a
    first = c.get("/jobs", headers=A, params={"limit": 4}).json()
    assert len(first["jobs"]) == 4 and first["total"] == 6 and first["next_offset"] == 4
    rest = c.get("/jobs", headers=A, params={"limit": 4, "offset": first["next_offset"]}).json()
    assert len(rest["jobs"]) == 2 and rest["next_offset"] is None and rest["offset"] == 4
    listed = [j["id"] for j in first["jobs"] + rest["jobs"]]
    store = c.app.state.store
    created = [store.get(j).created for j in listed]
    assert sorted(listed) == sorted(j for j, _ in jobs.values()) and created == sorted(created, reverse=True)
    one = c.get("/jobs", headers=A, params={"kind": "circle"}).json()
    assert [j["id"] for j in one["jobs"]] == [jobs["circle"][0]] and one["total"] == 1
    assert c.get("/jobs", headers=A, params={"state": "queued"}).json()["total"] == 6
    assert c.get("/jobs", headers=A, params={"state": "cancelled"}).json()["total"] == 0
    assert c.get("/jobs", headers=A, params={"kind": "circle", "state": "succeeded"}).json()["total"] == 0
    for params, field in [({"kind": "nope"}, "kind"), ({"state": "done"}, "state"), ({"limit": 0}, "limit"),
                          ({"limit": 201}, "limit"), ({"offset": -1}, "offset")]:
        r = c.get("/jobs", headers=A, params=params)
        assert r.status_code == 422 and r.json()["detail"][0]["field"] == field, (params, r.text)
    assert c.get("/jobs").status_code == 401


def test_each_kinds_route_cancels_its_own_and_refuses_another_key(tmp_path, monkeypatch):
    from service.jobs import owner_of
    from service.states import JobKind

    routes = {JobKind.simulation: "/simulations", JobKind.compensation: "/compensations",
              JobKind.circle: "/circles", JobKind.placement_search: "/placement-searches",
              JobKind.explain: "/jobs", JobKind.diagnose: "/jobs"}
    with _app(tmp_path, monkeypatch, per_key=4) as c:
        store, boot = c.app.state.store, c.app.state.manager.boot
        for kind, prefix in routes.items():
            job = store.create(kind, {}, boot, owner_of(KEY_A)).id
            assert c.delete(f"{prefix}/{job}", headers=B).status_code == 404, kind
            assert store.get(job).state.value == "queued"
            r = c.delete(f"{prefix}/{job}", headers=A)
            assert r.status_code == 200 and r.json()["state"] == "cancelled" and r.json()["kind"] == kind.value, kind
            if prefix != "/jobs":   # a kind's route knows its own kind only
                other = store.create(JobKind.diagnose, {}, boot, owner_of(KEY_A)).id
                assert c.delete(f"{prefix}/{other}", headers=A).status_code == 404, kind
                assert store.get(other).state.value == "queued"


def test_cancel_refuses_another_key(tmp_path, monkeypatch):
    with _app(tmp_path, monkeypatch, per_key=4) as c:
        route, body, _, prefix = SUBMISSIONS[2]   # a circle: the quickest submission
        job = c.post(route, headers=A, json=body).json()["id"]
        assert c.delete(f"/jobs/{job}", headers=B).status_code == 404
        assert c.get(f"/jobs/{job}", headers=A).json()["state"] == "queued"
        r = c.delete(f"/jobs/{job}", headers=A)
        assert r.status_code == 200 and r.json()["state"] == "cancelled"


@pytest.mark.parametrize("first", range(len(SUBMISSIONS)), ids=[s[2] for s in SUBMISSIONS])
def test_every_kind_counts_toward_the_key_limit(tmp_path, monkeypatch, first):
    """With one job per key, key A's job of any kind makes A's next submission 429 while B is still served."""
    circle = SUBMISSIONS[2]
    with _app(tmp_path, monkeypatch, per_key=1) as c:
        route, body, _, _ = SUBMISSIONS[first]
        assert c.post(route, headers=A, json=body).status_code == 202
        r = c.post(circle[0], headers=A, json=circle[1])
        assert r.status_code == 429 and "GREYBENCH_JOBS_PER_KEY" in r.json()["detail"], r.text
        assert r.headers["Retry-After"]
        assert c.post(circle[0], headers=B, json=circle[1]).status_code == 202


def test_the_admin_key_reads_and_cancels_every_job(tmp_path, monkeypatch):
    with _app(tmp_path, monkeypatch, per_key=4) as c:
        route, body, _, prefix = SUBMISSIONS[2]
        job_a = c.post(route, headers=A, json=body).json()["id"]
        job_b = c.post(route, headers=B, json=body).json()["id"]
        for job in (job_a, job_b):
            assert c.get(f"{prefix}/{job}", headers=ROOT).status_code == 200
            assert c.post(f"{prefix}/{job}/view-link", headers=ROOT, json={}).status_code == 200
        assert c.delete(f"/jobs/{job_a}", headers=ROOT).json()["state"] == "cancelled"
        assert c.get(f"{prefix}/{job_a}", headers=A).json()["state"] == "cancelled"
        assert c.get(f"{prefix}/{job_b}", headers=A).status_code == 404   # A is still no admin


def test_the_admin_key_setting_is_checked():
    from identify.errors import InputError
    from service.settings import load_settings

    with pytest.raises(InputError) as info:
        load_settings(api_keys=KEY_A, admin_key="short")
    assert info.value.field == "GREYBENCH_ADMIN_KEY"
    s = load_settings(api_keys=KEY_A, admin_key=ADMIN)
    assert s.keys() == {KEY_A, ADMIN}
