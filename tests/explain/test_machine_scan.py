"""A part made by `greybench machine` stands in for a measured one: explained against the same
robot file it must give `none` (the simulation reproduces itself)."""
import json

import pytest
from typer.testing import CliRunner

from greybench.cli import app
from greybench.support import DATA_DIR

runner = CliRunner()


@pytest.mark.slow
def test_machine_scan_explained_by_the_same_robot_is_none(tmp_path):
    program = DATA_DIR / "programs" / "iso160.nc"
    poses = DATA_DIR / "poses" / "iso160.json"
    name = json.loads(poses.read_text())["poses"][0]["name"]
    res = runner.invoke(app, ["machine", "--program", str(program), "--robot", "max100", "--pose", str(poses),
                              "--name", name, "--out", str(tmp_path / "part"), "--json"])
    assert res.exit_code == 0, res.output
    scan = tmp_path / "part" / "scan.csv"
    assert scan.exists()
    res = runner.invoke(app, ["explain", "--measured", str(scan), "--program", str(program), "--robot", "max100",
                              "--pose", str(poses), "--name", name, "--out", str(tmp_path / "explained"), "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["cause"] == "none", doc["ranking"][:3]
    assert doc["rms_before"] < 1e-6
