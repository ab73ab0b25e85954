"""CLI: greybench robot fk/ik, prepare; bad files exit with code 2 naming the file and column/key."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from greybench.cli import app
from simulate.robot.kinematics import fk

runner = CliRunner()


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture
def joints(robot, tmp_path):
    rng = np.random.default_rng(11)
    q = rng.uniform(robot.lower, robot.upper, size=(200, 6))
    q[:, [3, 5]] = np.clip(q[:, [3, 5]], -3.0, 3.0)
    path = tmp_path / "joints.csv"
    pd.DataFrame({f"q{i + 1}": q[:, i] for i in range(6)}).to_csv(path, index=False, float_format="%.17g")
    return path, q


def test_fk_then_ik_round_trip(robot, joints, tmp_path):
    path, q = joints
    poses = tmp_path / "poses.csv"
    r = _run("robot", "fk", "--robot", "max100", "--in", path, "--out", poses, "--json")
    assert r.exit_code == 0, r.output
    info = json.loads(r.stdout)
    assert info["poses"] == 200
    df = pd.read_csv(poses)
    assert list(df.columns) == ["x", "y", "z", "qw", "qx", "qy", "qz"]
    assert np.allclose(df[["x", "y", "z"]].to_numpy(), fk(robot, q)[:, :3, 3], atol=1e-12)
    back = tmp_path / "back.parquet"
    r = _run("robot", "ik", "--robot", "max100", "--in", poses, "--out", back, "--independent", "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["ok"] == 200
    res = pd.read_parquet(back)
    assert list(res.columns)[:7] == ["q1", "q2", "q3", "q4", "q5", "q6", "ok"]
    qb = res[[f"q{i}" for i in range(1, 7)]].to_numpy()
    assert np.max(np.abs(fk(robot, qb)[:, :3, 3] - fk(robot, q)[:, :3, 3])) < 1e-9


def test_ik_unreachable_rows_are_ok_false_nan(tmp_path):
    p = tmp_path / "poses.csv"
    pd.DataFrame({"x": [1.5, 9.0], "y": [0.2, 0.0], "z": [1.2, 0.0], "qw": [0.0, 1.0], "qx": [1.0, 0.0],
                  "qy": [0.0, 0.0], "qz": [0.0, 0.0]}).to_csv(p, index=False)
    outp = tmp_path / "q.csv"
    r = _run("robot", "ik", "--in", p, "--out", outp)
    assert r.exit_code == 0, r.output
    res = pd.read_csv(outp)
    assert list(res["ok"]) == [True, False]
    assert res.loc[1, [f"q{i}" for i in range(1, 7)]].isna().all()
    assert res.loc[1, "status"] == "UNREACHABLE"


@pytest.mark.parametrize("frame,field,row", [
    ({"x": [1.0], "y": [0.0], "z": [1.0], "qw": [1.0], "qx": [0.0], "qy": [0.0]}, "qz", None),
    ({"x": [1.0, 1.0], "y": [0.0, "abc"], "z": [1.0, 1.0], "qw": [1.0, 1.0], "qx": [0.0, 0.0], "qy": [0.0, 0.0],
      "qz": [0.0, 0.0]}, "y", 1),
    ({"x": [1.0, 1.0], "y": [0.0, 0.0], "z": [1.0, 1.0], "qw": [1.0, 0.9], "qx": [0.0, 0.0], "qy": [0.0, 0.0],
      "qz": [0.0, 0.0]}, "qw", 1),
])
def test_malformed_pose_files_exit_2_naming_column(tmp_path, frame, field, row):
    p = tmp_path / "bad_poses.csv"
    pd.DataFrame(frame).to_csv(p, index=False)
    outp = tmp_path / "q.csv"
    r = _run("robot", "ik", "--in", p, "--out", outp)
    assert r.exit_code == 2
    assert str(p) in r.stderr and f"'{field}'" in r.stderr
    if row is not None:
        assert f"row {row}" in r.stderr
    assert not outp.exists()


def test_bad_joint_file_and_bad_robot_exit_2(robot_path, joints, tmp_path):
    p = tmp_path / "bad_joints.csv"
    pd.DataFrame({"q1": [0.0], "q2": [0.0], "q3": [0.0], "q4": [0.0], "q5": [0.0]}).to_csv(p, index=False)
    r = _run("robot", "fk", "--in", p, "--out", tmp_path / "o.csv")
    assert r.exit_code == 2 and "'q6'" in r.stderr
    bad_robot = tmp_path / "bad_robot.toml"
    bad_robot.write_text(robot_path.read_text().replace("backlash = 1.0e-4       # rad,",
                                                        "backlash = -1.0 #", 1))
    r = _run("robot", "fk", "--robot", bad_robot, "--in", joints[0], "--out", tmp_path / "o.csv")
    assert r.exit_code == 2 and str(bad_robot) in r.stderr and "joint[1].backlash" in r.stderr
    r = _run("robot", "fk", "--robot", "nosuchrobot", "--in", joints[0], "--out", tmp_path / "o.csv")
    assert r.exit_code == 2 and "unknown robot" in r.stderr
    r = _run("robot", "ik", "--in", joints[0], "--out", tmp_path / "o.csv", "--q-start", "1,2,3")
    assert r.exit_code == 2


def test_prepare_cli(robot, tmp_path):
    t = np.arange(0.0, 1.0, 1e-3)
    q = 0.3 * np.sin(2 * np.pi * 0.5 * t)[:, None] * np.ones(6) + np.array([0, 0.5, 0.3, 0, 0.5, 0])
    cols = {"t": t}
    cols.update({f"q{i + 1}": q[:, i] for i in range(6)})
    cols.update({f"tau{i + 1}": np.zeros_like(t) for i in range(6)})
    log = tmp_path / "log.csv"
    pd.DataFrame(cols).to_csv(log, index=False)
    r = _run("prepare", "--robot", "max100", "--log", log, "--out-dir", tmp_path / "axes", "--json")
    assert r.exit_code == 0, r.output
    info = json.loads(r.stdout)
    assert len(info["records"]) == 6 and info["samples"] == 1000
    df = pd.read_csv(tmp_path / "axes" / "axis2.csv")
    assert list(df.columns) == ["t", "q", "qd", "qdd", "tau", "tau_rb", "tau_load"]
    # missing tau column: exit 2, names it, writes nothing
    pd.DataFrame(cols).drop(columns=["tau6"]).to_csv(log, index=False)
    r = _run("prepare", "--log", log, "--out-dir", tmp_path / "axes2")
    assert r.exit_code == 2 and "'tau6'" in r.stderr and str(log) in r.stderr
    assert not (tmp_path / "axes2" / "axis1.csv").exists()


def test_bad_output_and_options_exit_2(joints, tmp_path):
    r = _run("robot", "fk", "--in", joints[0], "--out", tmp_path / "poses.txt")
    assert r.exit_code == 2 and "poses.txt" in r.stderr and ".csv or .parquet" in r.stderr
    r = _run("robot", "fk", "--in", joints[0], "--out", tmp_path / "nodir" / "poses.csv")
    assert r.exit_code == 2 and "does not exist" in r.stderr
    r = _run("robot", "fk", "--in", tmp_path / "missing.csv", "--out", tmp_path / "p.csv")
    assert r.exit_code == 2 and "missing.csv" in r.stderr and "not found" in r.stderr
    r = _run("prepare", "--log", joints[0], "--out-dir", tmp_path / "a", "--window", "0")
    assert r.exit_code == 2 and "'window'" in r.stderr
