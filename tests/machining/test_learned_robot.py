"""A robot file whose joints 1-3 reference a grey-box, a residual and an LSTM model machines a part
that differs from the inline-LuGre robot's, where a repeated job does not differ at all; bad model
references exit 2 naming the robot file key, writing nothing.

Fast version of the acceptance scenario: the square and circle contours of the 160 test piece
(tests/explain/data/small160.nc), models fitted with a few epochs on 4 s synthetic records.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from greybench.cli import app

ROOT = Path(__file__).resolve().parents[2]
SMALL = ROOT / "tests" / "explain" / "data"
KINDS = {1: "greybox", 2: "residual", 3: "lstm"}


def _robot_with_models(tmp_path: Path, refs: dict[int, str]) -> Path:
    """max100.toml with joints' [joint.friction] tables replaced by ``model = "<ref>"``."""
    parts = (ROOT / "data" / "robots" / "max100.toml").read_text().split("[[joint]]")
    for j, ref in refs.items():
        p = parts[j]
        # the table header at a line start (comments elsewhere also name [joint.friction])
        hdr = re.search(r"^\[joint\.friction\][^\n]*", p, re.M)
        i = hdr.start()
        rest = p[hdr.end():]
        m = re.search(r"\n\[", rest)
        parts[j] = p[:i] + f'[joint.friction]\nmodel = "{ref}"\n' + rest[m.start() if m else len(rest):]
    out = tmp_path / "robot.toml"
    out.write_text("[[joint]]".join(parts))
    return out


@pytest.fixture(scope="module")
def learned_robot(tmp_path_factory, few_epoch_models):
    d = tmp_path_factory.mktemp("learned")
    for j, kind in KINDS.items():
        few_epoch_models(kind, d / f"model{j}")   # tests/conftest.py: fitted once per session
    return _robot_with_models(d, {j: f"model{j}" for j in KINDS})   # relative to the robot file


def _part(robot):
    from simulate.pipeline import MachiningJob, MachiningSettings, run_job
    from simulate.toolpath.placement import load_poses

    pl = load_poses(SMALL / "small160.poses.json")[0]
    return run_job(MachiningJob(program=SMALL / "small160.nc", robot=robot, placement=pl,
                                settings=MachiningSettings(spacing=1e-3)))


def test_learned_models_machine_a_different_part(learned_robot):
    inline = _part(ROOT / "data" / "robots" / "max100.toml")
    again = _part(ROOT / "data" / "robots" / "max100.toml")
    learned = _part(learned_robot)
    assert [f["kind"] for f in learned.friction[:3]] == ["greybox", "residual", "lstm"]
    assert all(f["kind"] == "lugre" and f["source"] == "inline" for f in inline.friction)
    # the learned friction acted in the loop: each joint's torque is the model's (a few Nm), not the
    # robot file's LuGre (tens of Nm)
    jf_in, jf_le = np.abs(inline.result.joint_friction), np.abs(learned.result.joint_friction)
    assert np.all(jf_le[:, :3].max(axis=0) < 0.3 * jf_in[:, :3].max(axis=0))
    assert all(f["kind"] == "lugre" and f["source"] == "inline" for f in learned.friction[3:])
    def rms(a, b):
        return float(np.sqrt(np.mean((a - b) ** 2)))
    def pts(mo):
        return np.concatenate([mo.scan.points[k] for k in sorted(mo.scan.points)])
    assert rms(again.tracking_error, inline.tracking_error) == 0.0          # a repeated job: identical
    assert rms(pts(again), pts(inline)) == 0.0
    d_path = rms(learned.tracking_error, inline.tracking_error)
    d_part = rms(pts(learned), pts(inline))
    print(f"learned vs inline: tracking error {d_path * 1e6:.3g} um RMS, scan points {d_part * 1e6:.3g} um RMS")
    assert d_path > 1e-6 and d_part > 5e-8, (d_path, d_part)   # measured: 3.2 um and 0.6 um RMS


@pytest.mark.parametrize("case", ["missing", "not-a-model", "other-axis"])
def test_bad_model_reference_exits_2_naming_the_key(tmp_path, case):
    (tmp_path / "empty").mkdir()
    ref = {"missing": "nowhere", "not-a-model": "empty", "other-axis": "models:/max100-axis3-friction@champion"}[case]
    robot = _robot_with_models(tmp_path, {2: ref})
    out = tmp_path / "out"
    r = CliRunner().invoke(app, ["machine", "--program", str(SMALL / "small160.nc"), "--pose",
                                 str(SMALL / "small160.poses.json"), "--robot", str(robot), "--out", str(out),
                                 "--spacing", "2"])
    assert r.exit_code == 2, r.output
    # off a terminal the progress lines (ISO timestamps) come first; the error is one line of its own
    lines = [ln for ln in r.output.strip().splitlines() if not re.match(r"\d{4}-\d\d-\d\dT", ln)]
    msg = "\n".join(lines)
    assert len(lines) == 1 and "joint[2].friction.model" in msg and "robot.toml" in msg, msg
    assert not out.exists() or not any(out.iterdir())


def test_torch_is_imported_only_for_a_learned_model(tmp_path):
    """The inline-LuGre robot machines without torch; a saved LuGre model folder too (read from its
    params.json); torch comes in only with a learned model's network.pt."""
    import subprocess
    import sys

    code = f"""
import sys
from pathlib import Path
from simulate.pipeline import MachiningJob, MachiningSettings, run_job
from simulate.robot.friction import loop_friction
from simulate.robot.model import load_robot
from simulate.toolpath.placement import load_poses
pl = load_poses(Path({str(SMALL / "small160.poses.json")!r}))[0]
run_job(MachiningJob(program=Path({str(SMALL / "small160.nc")!r}),
                     robot=Path({str(ROOT / "data/robots/max100.toml")!r}), placement=pl,
                     settings=MachiningSettings(spacing=4e-3)))
print("torch" in sys.modules)
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "False"
