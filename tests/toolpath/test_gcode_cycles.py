"""Canned cycles G81, G82, G83, G73 with G98/G99: the expanded moves against move lists worked out by
hand from the RS-274/NGC rules (LinuxCNC's interpreter, docs/gcode.md)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.cycles import RAPID_DELTA, CycleLevels, DrillCycle, drill_moves
from simulate.toolpath.gcode import parse_program, read_program

PROGRAMS = Path(__file__).parent / "programs"
MM = 1e-3
D = 0.254  # mm, the 0.010 inch peck clearance


def _moves(segs):
    """(kind, end in mm) per segment: 'R' rapid, 'F' feed."""
    return [("R" if s.rapid else "F", tuple(np.round(s.end / MM, 9))) for s in segs]


def test_haas_drilling_program_move_by_move():
    f = PROGRAMS / "haas_drilling.nc"
    segs = read_program(f).segments
    R, F = "R", "F"
    g83_hole = lambda x, y: [  # noqa: E731  (pecks of 2.5 from R2 to Z-6, G99 back to R)
        (F, (x, y, -0.5)), (R, (x, y, 2)), (R, (x, y, -0.5 + D)),
        (F, (x, y, -3.0)), (R, (x, y, 2)), (R, (x, y, -3.0 + D)),
        (F, (x, y, -5.5)), (R, (x, y, 2)), (R, (x, y, -5.5 + D)),
        (F, (x, y, -6.0)), (R, (x, y, 2))]
    expected = [
        (R, (10, 10, 0)), (R, (10, 10, 15)), (R, (10, 10, 10)),
        # N50 G98 G81 at (10, 10): already there at the initial level 10; down to R2, feed to -5, back to 10
        (R, (10, 10, 2)), (F, (10, 10, -5)), (R, (10, 10, 10)),
        # N55 X20.: the same cycle at (20, 10)
        (R, (20, 10, 10)), (R, (20, 10, 2)), (F, (20, 10, -5)), (R, (20, 10, 10)),
        # N65 G99 G83 at (30, 10) from the initial level 10
        (R, (30, 10, 10)), (R, (30, 10, 2)), *g83_hole(30, 10),
        # N70 Y20.: at R (G99), so straight over to (30, 20) and no move down to R
        (R, (30, 20, 2)), *g83_hole(30, 20),
        # N80 G98 G82 from z 2 (the initial level of this series): R1, feed to -3 with 0.5 s dwell, back to 2
        (R, (40, 10, 2)), (R, (40, 10, 1)), (F, (40, 10, -3)), (R, (40, 10, 2)),
        # N90 G99 G73 Q1 from R1 to -2: chip-break pecks at 0 and -1 (retract 0.254), G99 back to R1
        (R, (50, 10, 2)), (R, (50, 10, 1)), (F, (50, 10, 0)), (R, (50, 10, D)), (F, (50, 10, -1)),
        (R, (50, 10, -1 + D)), (F, (50, 10, -2)), (R, (50, 10, 1)),
        (R, (50, 10, 15)),
    ]
    got = _moves(segs)
    assert len(got) == len(expected)
    for (k1, e1), (k2, e2) in zip(got, expected, strict=True):
        assert k1 == k2 and e1 == pytest.approx(e2, abs=1e-9), (got, expected)
    feeds = {s.line: round(s.feed * 60 / MM, 9) for s in segs if not s.rapid}
    assert sorted(set(feeds.values())) == [60, 80, 100]
    dwells = [(s.line, s.dwell) for s in segs if s.dwell]
    assert dwells == [(18, 0.5)]  # N80, at the bottom of the G82 hole only


def test_initial_level_below_r_and_incremental_cycle():
    # from z 0 with R2: first straight up to R, which is then also the G98 level
    p = parse_program("G21 G90\nG0 X0 Y0 Z0\nG81 X5 Y0 Z-1 R2 F100\n")
    assert _moves(p.segments) == [("R", (0, 0, 2)), ("R", (5, 0, 2)), ("F", (5, 0, -1)), ("R", (5, 0, 2))]
    # G91: X from the current point, R from the initial level (10 - 8 = 2), Z from R (2 - 4 = -2)
    p = parse_program("G21 G90\nG0 X0 Y0 Z10\nG91 G81 X5 Y0 Z-4 R-8 F100\nX5\n")
    assert _moves(p.segments[1:]) == [("R", (5, 0, 10)), ("R", (5, 0, 2)), ("F", (5, 0, -2)), ("R", (5, 0, 10)),
                                      ("R", (10, 0, 10)), ("R", (10, 0, 2)), ("F", (10, 0, -2)),
                                      ("R", (10, 0, 10))]
    # G99: the second hole starts at R, but R is still measured from the initial level 10
    p = parse_program("G21 G90\nG0 X0 Y0 Z10\nG91 G99 G81 X5 Y0 Z-4 R-8 F100\nX5\n")
    assert _moves(p.segments[1:]) == [("R", (5, 0, 10)), ("R", (5, 0, 2)), ("F", (5, 0, -2)), ("R", (5, 0, 2)),
                                      ("R", (10, 0, 2)), ("F", (10, 0, -2)), ("R", (10, 0, 2))]


def test_cycle_under_a_work_offset_and_g80_ends_the_series():
    t = {"G54": (0.1, 0.0, 0.05)}
    p = parse_program("G21 G90\nG0 X0 Y0 Z10\nG99 G81 X1 Y0 Z-1 R1 F100\nG80\nG0 Z5\n", work_offsets=t)
    # program z 10 -> frame 60; R1 -> 51; Z-1 -> 49; G99 back to 51; G80 then G0 Z5 -> 55
    assert _moves(p.segments) == [("R", (100, 0, 60)), ("R", (101, 0, 60)), ("R", (101, 0, 51)),
                                  ("F", (101, 0, 49)), ("R", (101, 0, 51)), ("R", (101, 0, 55))]
    with pytest.raises(InputError, match="without a motion mode"):
        parse_program("G21 G90\nG0 Z10\nG81 X1 Z-1 R1 F100\nG80\nX2\n")


def test_peck_at_an_exact_multiple_adds_no_empty_peck():
    lv = CycleLevels(initial=0.010, r=0.002, bottom=-0.002)
    mv = drill_moves(DrillCycle.G73, np.array([0.0, 0.0, 0.010]), (0.0, 0.0), lv, peck=0.001)
    feeds = [round(m.end[2] / MM, 9) for m in mv if not m.rapid]
    assert feeds == [1, 0, -1, -2]   # r - q, r - 2q, r - 3q, then the bottom; no second feed to -2
    assert [round(m.end[2] / MM, 6) for m in mv][-1] == 10.0   # G98
    assert abs(RAPID_DELTA - 0.254 * MM) < 1e-15


@pytest.mark.parametrize("text, line, column, words", [
    ("G21 G90 G0 Z5\nG81 X1 Z-1 F10\n", 2, 1, ["G81 needs R"]),
    ("G21 G90 G0 Z5\nG81 X1 R1 F10\n", 2, 1, ["G81 needs Z"]),
    ("G21 G90 G0 Z5\nG83 X1 Z-1 R1 F10\n", 2, 1, ["G83 needs the peck depth Q"]),
    ("G21 G90 G0 Z5\nG82 X1 Z-1 R1 F10\n", 2, 1, ["G82 needs the dwell P"]),
    ("G21 G90 G0 Z5\nG81 X1 Z2 R1 F10\n", 2, 11, ["R plane is below the hole bottom"]),
    ("G21 G90 G0 Z5\nG83 X1 Z-2 R1 Q0 F10\n", 2, 15, ["Q must be > 0"]),
    ("G21 G90 G0 Z5\nG18 G81 X1 Z-1 R1 F10\n", 2, 5, ["XY plane"]),
    ("G21 G90 G0 Z5\nG81 X1 Z-1 R1 F10\nX2 I1\n", 3, 4, ["'I'", "canned cycle"]),
    ("G21 G90 G0 Z5\nG81 X1 Z-1 R1\n", 2, 1, ["feed"]),
    ("G21 G90 G0 Z5\nG81 X1 Z-1 R1 F10\nR3\n", 3, 1, ["'R' without a hole position"]),
    ("G21 G90 G0 Z5\nG81 G1 X1 Z-1 R1 F10\n", 2, 5, ["modal group (motion)"]),
    ("G21 G90 G0 Z5\nG98 G99\n", 2, 5, ["modal group (return mode)"]),
])
def test_bad_cycle_lines(text, line, column, words):
    with pytest.raises(InputError) as ei:
        parse_program(text, source="c.nc")
    assert (ei.value.line, ei.value.column) == (line, column), str(ei.value)
    for w in words:
        assert w in str(ei.value)
