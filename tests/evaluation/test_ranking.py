"""Ranking end to end (full machining simulations, a few seconds each with the compiled coupled loop): ideal robot,
stiff vs soft robot, the report for the four poses of iso320.json; the cutter comes from the robot file's ``[tool]``."""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

from simulate.evaluation.ranking import Components, RankSettings, rank_poses
from simulate.toolpath.placement import load_poses

PROGRAM = "data/programs/iso160.nc"
ROBOT = "data/robots/max100.toml"
SMALL = Path("tests/explain/data")  # square and circle finishing contours of the 160 piece


def test_cutter_comes_from_the_robot_tool(tmp_path):
    """A robot file whose tool is 0.2 mm larger (and 2-fluted) cuts the square and circle 0.2 mm smaller, although
    the stock file still says D10: the cutter is the robot's ``[tool]``, not the stock's."""
    from simulate.robot.model import load_robot, save_robot

    assert json.loads((SMALL / "small160.stock.json").read_text())["tool"]["diameter"] == 0.01
    rob = load_robot(ROBOT)
    big = save_robot(rob.with_changes(tool=dataclasses.replace(rob.tool, diameter=rob.tool.diameter + 0.2e-3,
                                                               flutes=2)), tmp_path / "big_tool.toml")
    pl = load_poses(SMALL / "small160.poses.json")[:1]
    ideal = Components(deflection=False, servo=False)
    dev = {}
    for f in (ROBOT, big):
        r = rank_poses(SMALL / "small160.nc", f, pl, settings=RankSettings(spacing=2e-3, size=160), components=ideal,
                       workers=1)
        dev[f] = r.results[pl[0].name].table
    for row in ("circle diameter", "square side length (2x)"):
        assert abs(dev[ROBOT][row].deviation) < 1e-6, row
        assert dev[big][row].deviation == pytest.approx(-0.2e-3, abs=1e-6), row


def test_ideal_robot_gives_near_zero_deviations(piece160):
    pl = load_poses("data/poses/iso160.json")[:1]
    r = rank_poses(PROGRAM, ROBOT, pl, settings=RankSettings(spacing=2e-3, size=160),
                   components=Components(deflection=False, servo=False), workers=1)
    table = r.results[pl[0].name].table
    for row in table.rows:
        if row.name == "slope height zMZ":
            # The zig-zag finishing of the slope with a flat end mill leaves ridges between its passes
            # (the tool bottom follows the plane only on each pass centre line): at most
            # tan(3 deg) * (R - sqrt(R^2 - dy^2)) with dy up to the stepover / 2.
            R = 5e-3
            assert 0 <= row.deviation <= math.tan(piece160.slope_angle) * R
        else:
            assert abs(row.deviation) < 1e-6, row.name


def test_stiffer_robot_scores_better():
    pl = load_poses("data/poses/iso160.json")[:1]
    soft = rank_poses(PROGRAM, ROBOT, pl, settings=RankSettings(spacing=2e-3, size=160, stiffness_scale=0.2))
    stiff = rank_poses(PROGRAM, ROBOT, pl, settings=RankSettings(spacing=2e-3, size=160, stiffness_scale=20.0))
    name = pl[0].name
    assert stiff.results[name].score < soft.results[name].score


@pytest.mark.parametrize("size", [160, pytest.param(320, marks=pytest.mark.slow)])
def test_report_for_the_four_poses(tmp_path, size):
    """The four placements of iso320.json; the 160 piece fits each of them and takes less than half the
    simulation time, the 320 piece they were chosen for runs with the slow tests."""
    from simulate.evaluation.report import write_report

    program = f"data/programs/iso{size}.nc"
    pl = load_poses("data/poses/iso320.json")
    r = rank_poses(program, ROBOT, pl, settings=RankSettings(spacing=2e-3, size=size), out_dir=tmp_path,
                   shares=True)
    assert [e.rank for e in r.entries] == [1, 2, 3, 4]
    path = write_report(r, tmp_path, program=program, trajectories=r.trajectories)
    text = path.read_text()
    for p in pl:
        assert (tmp_path / p.name / "scan.csv").exists()
        assert (tmp_path / "images" / f"{p.name}_deviation.png").exists()
        assert (tmp_path / "images" / f"{p.name}_process.png").exists()
        assert (tmp_path / "images" / f"{p.name}_switching.png").exists()
        assert f"### {p.name}" in text
    assert "greybench trace --workpiece" in text and "Why the best pose wins" in text
    why = text[text.index("## Why the best pose wins"):text.index("## Component shares")]
    assert why.count(" vs ") >= 3 and f"Component shares of {r.best}'s score" in why
    # every one of the best pose's three largest gains per rival is attributed (or said to be an interaction)
    assert why.count("; mostly ") + why.count("; no single component") == 3 * (len(pl) - 1)
    for pose in (p.name for p in pl):  # every pose has a score share per component
        sh = r.shares(pose)["score"]
        assert set(sh) == {"deflection", "friction", "switching"}
