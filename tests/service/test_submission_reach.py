"""Reach is checked at submission: a pose that puts a point of the program out of the robot's reach (or
beyond a joint limit) answers 422 naming the pose's field and the program line, and no job is queued; a
reachable pose is accepted. A placement search refused by the per-key limit does no planning. In process,
with the job supervisor stopped so accepted jobs stay queued (no simulation runs)."""
from __future__ import annotations

import pytest

from .conftest import ROBOT_FRICTION

KEY_A = "key-a-0123456789"
KEY_B = "key-b-0123456789"
A, B = ({"X-API-Key": k} for k in (KEY_A, KEY_B))
#: The iso160 pose set's "near" pose, and one 9 m in front of the robot's base (max100 spans about 3 m).
NEAR = {"name": "near", "xyz": [1.5, 0.0, -0.1], "rpy": [0.0, 0.0, 0.0]}
FAR = {"name": "far", "xyz": [9.0, 0.0, -0.1], "rpy": [0.0, 0.0, 0.0]}
SCAN = "feature,x,y,z\ncircle,0,0,0\n"


def _app(tmp_path, monkeypatch, per_key: int = 20):
    from fastapi.testclient import TestClient

    from service.app import create_app
    from service.jobs import JobManager
    from service.settings import load_settings

    monkeypatch.setattr(JobManager, "_pass", lambda self: None)  # nothing starts: the jobs stay queued
    settings = load_settings(api_keys=f"{KEY_A},{KEY_B}", data_dir=tmp_path / "data", workers=1,
                             queue_size=40, jobs_per_key=per_key, max_body_bytes=1024 * 1024)
    return TestClient(create_app(settings))


def _bodies(poses: list[dict]) -> list[tuple[str, dict]]:
    """(route, body) of every kind that machines the program, with ``poses`` inline (the single-pose kinds
    take the last one)."""
    return [("/simulations", {"program": "iso160", "poses": poses, "friction": ROBOT_FRICTION}),
            ("/compensations", {"program": "iso160", "pose": poses[-1], "friction": ROBOT_FRICTION}),
            ("/placement-searches", {"program": "iso160", "poses": poses}),
            ("/explain", {"scan_csv": SCAN, "program": "iso160", "pose": poses[-1]})]


#: The field each route names for the 9 m pose of [NEAR, FAR].
FAR_FIELD = {"/simulations": "poses.1", "/compensations": "pose", "/placement-searches": "poses.1",
             "/explain": "pose"}


def test_a_pose_out_of_reach_is_refused_naming_its_field(tmp_path, monkeypatch):
    with _app(tmp_path, monkeypatch) as c:
        for route, body in _bodies([NEAR, FAR]):
            r = c.post(route, headers=A, json=body)
            assert r.status_code == 422, (route, r.text)
            d = r.json()["detail"]
            assert d["field"] == FAR_FIELD[route], (route, d)
            assert "pose 'far'" in d["message"] and d["source"] == "iso160.nc" and d["line"] >= 1, (route, d)
        assert c.get("/jobs", headers=A).json()["jobs"] == []   # nothing was queued


def test_a_reachable_pose_is_accepted(tmp_path, monkeypatch):
    with _app(tmp_path, monkeypatch) as c:
        for route, body in _bodies([NEAR]):
            r = c.post(route, headers=A, json=body)
            assert r.status_code == 202, (route, r.text)


def test_the_check_is_the_pipelines(tmp_path, monkeypatch):
    """The submission check is the pipeline's joint_trajectory: the far pose fails it in the pipeline's
    own terms, at the line the service names."""
    from identify.errors import InputError
    from service.paths import DATA_DIR
    from simulate.pipeline import load_program
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import joint_trajectory, parse_poses

    prog = load_program(DATA_DIR / "programs" / "iso160.nc")
    robot = load_robot(DATA_DIR / "robots" / "max100.toml")
    near, far = parse_poses({"poses": [NEAR, FAR]})
    joint_trajectory(robot, prog.interp, near)
    with pytest.raises(InputError) as exc:
        joint_trajectory(robot, prog.interp, far)
    with _app(tmp_path, monkeypatch) as c:
        d = c.post("/simulations", headers=A, json=_bodies([FAR])[0][1]).json()["detail"]
    assert (d["message"], d["line"], d["field"]) == (exc.value.message, exc.value.line, "poses.0")


def test_a_refused_placement_search_does_no_planning(tmp_path, monkeypatch):
    import service.placement as placement

    planned: list[int] = []
    real = placement._plan

    def counting(*args, **kw):
        planned.append(1)
        return real(*args, **kw)

    monkeypatch.setattr(placement, "_plan", counting)
    search = {"program": "iso160", "pose_set": "iso160", "select": ["near"]}
    circle = {"pose_set": "iso320", "pose": "pose1", "friction": ROBOT_FRICTION}
    with _app(tmp_path, monkeypatch, per_key=1) as c:
        assert c.post("/circles", headers=A, json=circle).status_code == 202
        r = c.post("/placement-searches", headers=A, json=search)
        assert r.status_code == 429 and "GREYBENCH_JOBS_PER_KEY" in r.json()["detail"], r.text
        assert planned == []
        assert c.post("/placement-searches", headers=B, json=search).status_code == 202   # B is planned
        assert planned == [1]
