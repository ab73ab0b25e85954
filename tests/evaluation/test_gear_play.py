"""Gears floating in their play: flank changes per program section and line (counted on hand-made
drive states), the physics behind them (a drive whose load cancels its friction floats, one loaded
40 Nm away from it does not) and the compensation report's list, original lines matched through the
corrected program's pieces."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from simulate.compensation.report import gears_rattling, report_text
from simulate.evaluation.gear_play import GearPlay, gear_play, program_sections, rattling_gears

#: joint-side friction, so the gear carries it (tests/data/max100_joint_friction.toml)
ROBOT = Path(__file__).resolve().parents[2] / "tests" / "data" / "max100_joint_friction.toml"
PROGRAM = """%
(test piece)
(tool T1)
G21 G90
(wall: contour at z = 0 mm)
G1 X10 Y0 F500 (first wall)
G1 X10 Y10
(circle)
G2 X10 Y10 I-5 J0
M30
"""


def test_sections_are_named_by_their_comment_lines():
    secs = program_sections(PROGRAM)
    assert [(s.name, s.first_line, s.last_line) for s in secs] == [
        ("start", 1, 1), ("tool T1", 2, 4), ("wall: contour at z = 0 mm", 5, 7), ("circle", 8, 10)]
    # a comment after a word on the same line starts nothing
    assert "first wall" not in [s.name for s in secs]


def test_flank_changes_and_play_share_per_section_and_per_line():
    # cycles on lines 6, 6, 6, 7, 7, 9, 9 and back to 6 (a section entered again)
    line = np.array([6, 6, 6, 7, 7, 9, 9, 6, 6])
    c1 = np.array([1, 0, -1, -1, 0, 1, 1, 1, 0])      # joint 1: two crossings on the wall
    c2 = np.ones(9, int)                               # joint 2: on its flank throughout
    contact = np.stack([c1, c2], axis=1)
    by_sec = {(p.section, p.joint): p for p in gear_play(PROGRAM, line, contact)}
    wall = by_sec["wall: contour at z = 0 mm", 1]
    # wall cycles 0-4 and 7-8: changes 1->0->-1 (2), -1->0 (1) and 1->0 (1); the jump from cycle 4 to 7
    # is not within one stretch
    assert (wall.flank_changes, wall.cycles, wall.line) == (4, 7, None)
    assert wall.in_play == pytest.approx(3 / 7)
    assert by_sec["wall: contour at z = 0 mm", 2].flank_changes == 0
    assert by_sec["circle", 1].flank_changes == 0 and by_sec["circle", 1].in_play == 0.0
    by_line = {(p.line, p.joint): p for p in gear_play(PROGRAM, line, contact, per_line=True)}
    assert by_line[6, 1].flank_changes == 3 and by_line[6, 1].section == "wall: contour at z = 0 mm"
    assert by_line[7, 1].flank_changes == 1 and by_line[9, 1].section == "circle"
    with pytest.raises(ValueError):
        gear_play(PROGRAM, line[:-1], contact)


def _play(line, joint, changes, cycles=300):
    return GearPlay("wall", line, joint, changes, 0.5, cycles)


def test_rattling_needs_enough_changes_and_a_rise():
    before = [_play(6, 1, 4), _play(6, 2, 9), _play(7, 1, 0)]
    after = [_play(6, 1, 12), _play(6, 2, 12), _play(7, 1, 9), _play(8, 1, 10)]
    got = rattling_gears(before, after)
    # 4 -> 12 rose 3x (20 per second); 9 -> 12 only 1.33x; 0 -> 9 below 10 changes; line 8 had no counterpart
    assert [(a.line, a.joint, None if b is None else b.flank_changes) for b, a in got] == [(6, 1, 4), (8, 1, None)]
    assert rattling_gears(before, after, factor=1.2, min_changes=9) == [
        (before[0], after[0]), (before[1], after[1]), (before[2], after[2]), (None, after[3])]
    # a slow drift: 15 changes over 1000 cycles of 2 ms (7.5 per second) is no rattle, 16 are; a contact
    # bouncing at a reversal (20 changes in 0.48 s) neither
    slow = [_play(6, 1, 15, cycles=1000), _play(7, 1, 16, cycles=1000), _play(8, 1, 20, cycles=240),
            _play(9, 1, 20, cycles=250)]
    assert [a.line for _, a in rattling_gears([], slow)] == [7, 9]
    # a step-over of 0.1 s the corrected program slows down to 0.6 s is still a reversal
    assert rattling_gears([_play(8, 1, 2, cycles=50)], [_play(8, 1, 20, cycles=300)]) == []


def _drive_floats(load_offset: float) -> tuple[int, float]:
    """A1 at a constant 0.011 rad/s with the robot file's friction on the joint side, loaded by
    -(friction at that speed + load_offset) [Nm]: its gear's flank changes and share in the play over
    2.5 s once settled."""
    from simulate.robot.drive import drive_friction, simulate_drive
    from simulate.robot.loop_friction import static_friction
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import HOME_Q

    robot = load_robot(ROBOT)
    v, tau, dt = 0.011, 0.3, 0.002
    t = np.arange(0.0, 4.0, dt)
    q = HOME_Q + (v * (t - tau * (1 - np.exp(-t / tau))))[:, None] * np.array([1.0, 0, 0, 0, 0, 0])
    load = np.zeros((t.size, 6))
    load[:, 0] = -(static_friction(drive_friction(robot), 0, v) + load_offset)
    jl = np.array([650.0, 480.0, 137.0, 1.25, 4.0, 0.065])   # kg m^2, link inertias at the home pose
    res = simulate_drive(robot, t, q, tau_load=load, link_inertia=jl)
    keep = t > 1.5
    (p,) = [g for g in gear_play("(wall)\nG1 X1\n", np.where(keep, 2, 0), res.contact) if g.joint == 1]
    return p.flank_changes, p.in_play


def test_a_gear_whose_load_cancels_its_friction_floats():
    """The transmitted torque is friction + load: where the load cancels the friction the link leaves its
    flank and drifts through the play; 40 Nm either way keeps it on one flank."""
    changes, play = _drive_floats(0.5)
    assert changes >= 4 and play > 0.5
    for off in (-40.0, 40.0):
        assert _drive_floats(off) == (0, 0.0)


def test_the_report_counts_the_corrected_pieces_on_their_original_line():
    # original: the wall on line 6 (segment 0), line 7 (segment 1); corrected: header comment added and
    # line 6 split into output lines 7 and 8, line 7 written as output line 9
    segs = [SimpleNamespace(line=6), SimpleNamespace(line=7)]
    pieces = {7: (0, 0.0, 0.5), 8: (0, 0.5, 1.0), 9: (1, 0.0, 1.0)}
    quiet = np.ones((600, 6), int)
    rattle = quiet.copy()
    rattle[:300, 0] = np.tile([1, 0], 150)                    # A1: 299 changes on the first wall (0.6 s)
    before = SimpleNamespace(trajectory=SimpleNamespace(line=np.repeat([6, 7], 300)), contact=quiet)
    after = SimpleNamespace(trajectory=SimpleNamespace(line=np.repeat([7, 8, 9, 9], 150)), contact=rattle)
    result = SimpleNamespace(before=before, after=after, path=SimpleNamespace(text=PROGRAM, segments=segs),
                             program=SimpleNamespace(pieces=pieces))
    got = gears_rattling(result)
    assert got == [{"section": "wall: contour at z = 0 mm", "line": 6, "text": "G1 X10 Y0 F500 (first wall)",
                    "joint": 1, "flank_changes_before": 0, "flank_changes_after": 299, "in_play_before": 0.0,
                    "in_play_after": 0.5}]
    info = {"evaluation": None, "checks": [], "best_iteration": 0, "iterations": [], "max_offset_mm": 0.0,
            "time_ratio": 1.0, "speed_ratio": 1.0, "gears_rattling": got}
    text = report_text(None, info, "small", 1.0)
    from simulate.run import RATTLE_LINES, compensation_summary

    _, lines = compensation_summary(info)
    assert any(line.endswith("line 6 A1 0 -> 299") for line in lines)
    # a long list is cut after RATTLE_LINES entries, naming how many more the report has
    _, lines = compensation_summary(dict(info, gears_rattling=got * (RATTLE_LINES + 3)))
    (line,) = [x for x in lines if x.startswith("gears left rattling")]
    assert line.count("line 6 A1") == RATTLE_LINES and line.endswith("; 3 more in report.md")
    assert "| wall: contour at z = 0 mm | 6: `G1 X10 Y0 F500 (first wall)` | A1 | 0 | 299 | 0 | 50 |" in text
    assert "rattling" not in report_text(None, dict(info, gears_rattling=[]), "small", 1.0)
    # runs without drive states: nothing to list
    assert gears_rattling(SimpleNamespace(before=SimpleNamespace(contact=None, trajectory=None), after=after)) == []
