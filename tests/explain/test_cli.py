"""CLI: ``greybench explain`` JSON contract, output folder, and bad files (exit 2 naming file and line)."""
from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from greybench.cli import app

runner = CliRunner()
DATA_ARGS = None


def _args(conftest_data, robot_file, scan, *extra):
    return ["explain", "--measured", str(scan), "--program", str(conftest_data / "small160.nc"), "--robot",
            str(robot_file), "--pose", str(conftest_data / "small160.poses.json"), "--name", "near", *extra]


@pytest.fixture(scope="module")
def data_dir():
    from pathlib import Path

    return Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def hidden_scan(helpers, robot, setup, tmp_path_factory):
    meas = helpers.measured_scan(helpers.hidden_robot(robot, "stiffness", 2, 0.5), setup, seed=5)
    return helpers.write_scan_csv(meas, tmp_path_factory.mktemp("scan") / "scan.csv")


def test_cli_json_and_outputs(data_dir, robot_file, hidden_scan, tmp_path):
    out_dir = tmp_path / "explained"
    # explained at the 1 mm grid the "measured" part was simulated at (the setup fixture): at the CLI's
    # default 0.25 mm the grids' own force differences score friction:2 beside stiffness:2 (823 / 786)
    res = runner.invoke(app, _args(data_dir, robot_file, hidden_scan, "--out", str(out_dir), "--json",
                                   "--max-sims", "2", "--spacing", "1"))
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert set(doc) >= {"cause", "ranking", "calibrated", "rms_before", "rms_after", "gain"}
    assert doc["cause"] == "stiffness:2"
    assert doc["ranking"][0]["cause"] == "stiffness:2" and "score" in doc["ranking"][0]
    assert set(doc["calibrated"]) >= {"param", "before", "after"}
    assert doc["calibrated"]["after"] == pytest.approx(doc["calibrated"]["before"] * 0.5, rel=0.2)
    assert doc["rms_after"] < doc["rms_before"]
    assert doc["gain"] == pytest.approx(1 - doc["rms_after"] / doc["rms_before"])
    for f in ("report.md", "robot_calibrated.toml", "explain.json", "images/roundness.png",
              "images/straightness.png"):
        assert (out_dir / f).exists(), f
    from simulate.robot.model import load_robot

    cal = load_robot(out_dir / "robot_calibrated.toml")
    assert cal.stiffness[1] == pytest.approx(doc["calibrated"]["after"])
    md = (out_dir / "report.md").read_text()
    assert "before" in md and "after" in md and "stiffness:2" in md


BAD = {
    "number": ("feature,x,y,z\ncircle_wall,0.0595,0.0,0.009\ncircle_wall,abc,0.0,0.009\n", "line 3"),
    "fields": ("feature,x,y,z\ncircle_wall,0.0595,0.0\n", "line 2"),
    "unknown": ("feature,x,y,z\ncircle_wall,0.055,0.0,0.009\nhexagon,0.01,0.0,0.009\n", "line 3"),
    "far": ("feature,x,y,z\ncircle_wall,0.055,0.0,0.009\ncircle_wall,55.0,0.0,9.0\n", "line 3"),
    "header": ("feat,x,y,z\ncircle_wall,0.055,0.0,0.009\n", "line 1"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_cli_bad_scan_exit_2_names_file_and_line(data_dir, robot_file, tmp_path, case):
    text, where = BAD[case]
    bad = tmp_path / f"bad_{case}.csv"
    bad.write_text(text)
    out_dir = tmp_path / "out"
    res = runner.invoke(app, _args(data_dir, robot_file, bad, "--out", str(out_dir)))
    assert res.exit_code == 2, res.output
    assert bad.name in res.output and where in res.output, res.output
    assert not out_dir.exists()


def test_cli_missing_scan_and_table_input(data_dir, robot_file, tmp_path):
    res = runner.invoke(app, _args(data_dir, robot_file, tmp_path / "nope.csv"))
    assert res.exit_code == 2 and "nope.csv" in res.output
    table = tmp_path / "table.json"
    table.write_text(json.dumps({"features": [{"name": "circle diameter", "deviation": {"near": 0.01}}]}))
    res = runner.invoke(app, _args(data_dir, robot_file, table))
    assert res.exit_code == 2 and "table.json" in res.output


def test_cli_bad_options_exit_2(data_dir, robot_file, hidden_scan):
    res = runner.invoke(app, _args(data_dir, robot_file, hidden_scan, "--max-sims", "0"))
    assert res.exit_code == 2 and "--max-sims" in res.output
    res = runner.invoke(app, _args(data_dir, robot_file, hidden_scan, "--spacing", "-1"))
    assert res.exit_code == 2 and "spacing" in res.output
