"""CLI: testpiece, interpolate (columns, formats), bad input -> one line, exit code 2, nothing written."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from greybench.cli import app

runner = CliRunner()
POSES = __import__("pathlib").Path(__file__).resolve().parents[2] / "data" / "poses"


def test_testpiece_and_interpolate_roundtrip(tmp_path):
    nc = tmp_path / "tp.nc"
    r = runner.invoke(app, ["testpiece", "--size", "160", "--out", str(nc), "--json"])
    assert r.exit_code == 0, r.output
    info = json.loads(r.stdout)
    assert info["program"] == str(nc) and (tmp_path / "tp.stock.json").exists()
    for ext in ("csv", "parquet"):
        out = tmp_path / f"traj.{ext}"
        r = runner.invoke(app, ["interpolate", "--program", str(nc), "--robot", "max100", "--pose",
                                str(POSES / "iso160.json"), "--name", "far_rotated", "--out", str(out), "--json"])
        assert r.exit_code == 0, r.output
        summary = json.loads(r.stdout)
        df = pd.read_csv(out) if ext == "csv" else pd.read_parquet(out)
        assert list(df.columns) == (["t", "line", "x", "y", "z"] + [f"q{i}" for i in range(1, 7)]
                                    + [f"qd{i}" for i in range(1, 7)] + ["switch"])
        assert len(df) == summary["samples"]
        np.testing.assert_allclose(np.diff(df["t"]), 0.002, atol=1e-9)
        assert summary["switching_steps"] == int((df["switch"] > 0).sum())


def test_human_output(tmp_path):
    r = runner.invoke(app, ["testpiece", "--out", str(tmp_path / "a.nc")])
    assert r.exit_code == 0 and "circle diameter" in r.stdout


@pytest.mark.parametrize("body, needle", [
    ("G21\nG1 X10 F100\nG41 X5\n", "line 3, column 1"),
    ("G21\nG0 X10\nG3 X0 Y10 I-10 J0.5 F100\n", "line 3, column 11"),
])
def test_interpolate_bad_program_exit_2_nothing_written(tmp_path, body, needle):
    nc = tmp_path / "bad.nc"
    nc.write_text(body)
    out = tmp_path / "o.csv"
    r = runner.invoke(app, ["interpolate", "--program", str(nc), "--pose", str(POSES / "iso320.json"),
                            "--out", str(out)])
    assert r.exit_code == 2
    assert needle in r.output and "bad.nc" in r.output
    assert not out.exists() and list(tmp_path.iterdir()) == [nc]


def test_interpolate_bad_pose_and_unreachable(tmp_path):
    nc = tmp_path / "p.nc"
    nc.write_text("G21 G90\nG1 X10 F600\nG1 X2500 F30000\n")
    pose = tmp_path / "poses.json"
    pose.write_text(json.dumps({"poses": [{"name": "a", "xyz": [1.5, 0, "z"], "rpy": [0, 0, 0]}]}))
    out = tmp_path / "o.parquet"
    r = runner.invoke(app, ["interpolate", "--program", str(nc), "--pose", str(pose), "--out", str(out)])
    assert r.exit_code == 2 and "poses[0].xyz" in r.output and not out.exists()
    r = runner.invoke(app, ["interpolate", "--program", str(nc), "--pose", str(POSES / "iso320.json"),
                            "--name", "nope", "--out", str(out)])
    assert r.exit_code == 2 and "no pose named" in r.output
    r = runner.invoke(app, ["interpolate", "--program", str(nc), "--pose", str(POSES / "iso320.json"),
                            "--out", str(out)])
    assert r.exit_code == 2 and "line 3" in r.output and "t=" in r.output and not out.exists()
    r = runner.invoke(app, ["interpolate", "--program", str(nc), "--pose", str(POSES / "iso320.json"),
                            "--out", str(tmp_path / "o.txt")])
    assert r.exit_code == 2 and ".csv or .parquet" in r.output


def test_testpiece_bad_options_exit_2(tmp_path):
    r = runner.invoke(app, ["testpiece", "--size", "200", "--out", str(tmp_path / "x.nc")])
    assert r.exit_code == 2 and "size" in r.output
    r = runner.invoke(app, ["testpiece", "--size", "160", "--tool-diameter", "20", "--out", str(tmp_path / "x.nc")])
    assert r.exit_code == 2 and "tool-diameter" in r.output
    r = runner.invoke(app, ["testpiece", "--allowance", "-1", "--out", str(tmp_path / "x.nc")])
    assert r.exit_code == 2 and "allowance" in r.output
    assert list(tmp_path.iterdir()) == []
