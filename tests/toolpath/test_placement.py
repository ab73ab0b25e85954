"""Placement: pose-file validation, TCP frames, IK along the path reproduced by FK, limits reported."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import parse_program
from simulate.toolpath.interpolation import interpolate
from simulate.toolpath.placement import (
    R_WCS_TCP,
    Placement,
    joint_trajectory,
    load_poses,
    rpy_matrix,
    select_pose,
    tcp_poses,
)
from simulate.toolpath.switching import switching_points
from simulate.toolpath.testpiece import finishing_program, iso_test_piece

DATA = __import__("pathlib").Path(__file__).resolve().parents[2] / "data"


@pytest.fixture(scope="module")
def robot():
    from simulate.robot.model import load_robot
    return load_robot(DATA / "robots" / "max100.toml")


def test_rpy_and_tool_down():
    R = rpy_matrix([0.1, -0.2, 0.3])
    c, s = math.cos, math.sin
    Rx = np.array([[1, 0, 0], [0, c(.1), -s(.1)], [0, s(.1), c(.1)]])
    Ry = np.array([[c(-.2), 0, s(-.2)], [0, 1, 0], [-s(-.2), 0, c(-.2)]])
    Rz = np.array([[c(.3), -s(.3), 0], [s(.3), c(.3), 0], [0, 0, 1]])
    np.testing.assert_allclose(R, Rz @ Ry @ Rx, atol=1e-15)
    assert np.linalg.det(R_WCS_TCP) == pytest.approx(1.0)
    pl = Placement("p", np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, math.pi / 2]))
    T = tcp_poses(np.array([[0.1, 0.0, 0.0]]), pl)[0]
    np.testing.assert_allclose(T[:3, 3], [1.0, 2.1, 3.0], atol=1e-15)
    np.testing.assert_allclose(T[:3, 2], [0, 0, -1], atol=1e-15)  # tool axis down


@pytest.mark.parametrize("doc, field", [
    ({}, "poses"),
    ({"poses": []}, "poses"),
    ({"poses": [{"name": "a", "xyz": [1, 2], "rpy": [0, 0, 0]}]}, "poses[0].xyz"),
    ({"poses": [{"name": "a", "xyz": [1, 2, 3], "rpy": [0, 0, 0]},
                {"name": "b", "xyz": [1, 2, 3], "rpy": [0, "x", 0]}]}, "poses[1].rpy"),
    ({"poses": [{"name": "a", "xyz": [1, 2, 3]}]}, "poses[0].rpy"),
    ({"poses": [{"name": "", "xyz": [1, 2, 3], "rpy": [0, 0, 0]}]}, "poses[0].name"),
    ({"poses": [{"name": "a", "xyz": [1, 2, 3], "rpy": [0, 0, 0]},
                {"name": "a", "xyz": [1, 2, 3], "rpy": [0, 0, 0]}]}, "poses[1].name"),
    ({"poses": [{"name": "a", "xyz": [1, 2, 3], "rpy": [0, 0, 0], "rpz": 1}]}, "poses[0].rpz"),
])
def test_pose_file_errors_name_the_field(tmp_path, doc, field):
    f = tmp_path / "p.json"
    f.write_text(json.dumps(doc))
    with pytest.raises(InputError) as ei:
        load_poses(f)
    assert ei.value.field == field and ei.value.source == str(f)
    assert field in str(ei.value)


def test_pose_file_json_syntax_and_selection(tmp_path):
    f = tmp_path / "p.json"
    f.write_text('{"poses": [\n  {"name": "a",, }]}')
    with pytest.raises(InputError) as ei:
        load_poses(f)
    assert ei.value.line == 2 and ei.value.column is not None
    poses = load_poses(DATA / "poses" / "iso320.json")
    assert [p.name for p in poses] == ["pose1", "pose2", "pose3", "pose4"]
    assert select_pose(poses, None).name == "pose1"
    with pytest.raises(InputError, match="no pose named") as ei:
        select_pose(poses, "pose9")
    assert ei.value.field == "name"


@pytest.fixture(scope="module")
def interp320():
    return interpolate(parse_program(finishing_program(iso_test_piece(320)), source="tp320.nc"))


def test_all_iso320_poses_reachable_and_fk_reproduces_path(robot, interp320):
    from simulate.robot.kinematics import fk
    for pl in load_poses(DATA / "poses" / "iso320.json"):
        jt = joint_trajectory(robot, interp320, pl)
        T = fk(robot, jt.q)
        # back into the workpiece frame
        Tzp = pl.T
        p_wcs = (T[:, :3, 3] - Tzp[:3, 3]) @ Tzp[:3, :3]
        assert np.abs(p_wcs - interp320.xyz).max() < 1e-9
        R_wcs = np.einsum("ji,njk->nik", Tzp[:3, :3], T[:, :3, :3])
        assert np.abs(R_wcs - R_WCS_TCP).max() < 1e-9
        assert np.all(jt.q >= robot.lower - 1e-9) and np.all(jt.q <= robot.upper + 1e-9)
        np.testing.assert_allclose(jt.qd[1:], np.diff(jt.q, axis=0) / 0.002)
        np.testing.assert_array_equal(jt.switch, switching_points(jt.qd))
        assert np.abs(jt.qd).max() < 1.0  # no configuration jumps


def test_iso160_poses_reachable(robot):
    ip = interpolate(parse_program(finishing_program(iso_test_piece(160))))
    for pl in load_poses(DATA / "poses" / "iso160.json"):
        joint_trajectory(robot, ip, pl)


def test_unreachable_reported_with_line_and_time(robot, interp320):
    far = Placement("far", np.array([3.5, 0.0, 0.0]), np.zeros(3))
    with pytest.raises(InputError) as ei:
        joint_trajectory(robot, interp320, far, source="tp320.nc")
    assert ei.value.source == "tp320.nc" and ei.value.line is not None
    assert "t=0.000 s" in str(ei.value) and "far" in str(ei.value)
    # reachable at the start, out of reach later: the first failing line and time are named
    prog = parse_program("G21 G90\nG1 X10 F3000\nG1 X1500 F30000\n", source="long.nc")
    ip = interpolate(prog)
    pl = Placement("edge", np.array([1.6, 0.0, -0.1]), np.zeros(3))
    with pytest.raises(InputError) as ei:
        joint_trajectory(robot, ip, pl, source="long.nc")
    e = ei.value
    assert e.line == 3 and ("UNREACHABLE" in str(e) or "JOINT_LIMIT" in str(e))
    assert "t=" in str(e) and "t=0.000" not in str(e)
