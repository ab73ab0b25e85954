"""Cutter radius compensation G41/G42: tool centre paths against offsets worked out by hand on a
square and a circle (inside and outside corners), checked also by their distance from the contour."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import Arc, Linear, parse_program, read_program

PROGRAMS = Path(__file__).parent / "programs"
MM = 1e-3
TOOLS = {1: (0.050, 0.005)}   # T1: radius 5 mm


def _desc(segs):
    """Per segment: ('L', end) or ('A', end, centre, radius, sweep), mm and rad."""
    out = []
    for s in segs:
        e = tuple(np.round(s.end[:2] / MM, 6))
        if isinstance(s, Arc):
            out.append(("A", e, tuple(np.round(s.center[:2] / MM, 6)), round(s.radius / MM, 6), round(s.sweep, 6)))
        else:
            out.append(("L", e))
    return out


def _dist_to_square(p, lo, hi):
    """Distance (mm) of the XY point p (mm) from the boundary of the square [lo, hi]^2."""
    x, y = p
    corners = [(lo, lo), (hi, lo), (hi, hi), (lo, hi)]
    best = math.inf
    for (ax, ay), (bx, by) in zip(corners, corners[1:] + corners[:1], strict=True):
        dx, dy = bx - ax, by - ay
        t = min(max(((x - ax) * dx + (y - ay) * dy) / (dx * dx + dy * dy), 0.0), 1.0)
        best = min(best, math.hypot(x - ax - t * dx, y - ay - t * dy))
    return best


def _samples(seg, n=9):
    if isinstance(seg, Arc):
        pts = seg.point_at(np.linspace(0, 1, n))
    else:
        pts = seg.start[None, :] + np.linspace(0, 1, n)[:, None] * (seg.end - seg.start)[None, :]
    return pts[:, :2] / MM


def test_square_outside_g41_with_corner_arcs():
    segs = read_program(PROGRAMS / "linuxcnc_cutter_comp.ngc", tools=TOOLS).segments
    cut = segs[2:-1]   # after the rapid and the plunge, before the final rapid
    # by hand: entry along +y ends 5 mm left of (0, 0); every clockwise turn is an outside corner for a
    # tool on the left, so it is rounded by a quarter circle of radius 5 about the programmed corner
    half = round(-math.pi / 2, 6)
    assert _desc(cut) == [
        ("L", (-5, 0)), ("L", (-5, 20)), ("A", (0, 25), (0, 20), 5, half), ("L", (20, 25)),
        ("A", (25, 20), (20, 20), 5, half), ("L", (25, 0)), ("A", (20, -5), (20, 0), 5, half), ("L", (0, -5)),
        ("L", (-10, -10))]
    np.testing.assert_allclose(cut[0].start[:2], [0, -10 * MM], atol=1e-15)   # entry from the point reached
    for s in cut[1:-1]:   # the compensated contour: 5 mm from the square everywhere
        for p in _samples(s):
            assert _dist_to_square(p, 0, 20) == pytest.approx(5, abs=1e-9)
    assert all(abs(s.start[2] + MM) < 1e-15 and abs(s.end[2] + MM) < 1e-15 for s in cut)
    for a, b in zip(segs, segs[1:], strict=False):
        np.testing.assert_allclose(a.end, b.start, atol=1e-15)   # continuous


def test_square_pocket_g41_inside_corners_are_cut_back():
    text = ("G21 G90 G17\nT1 M6\nG0 X10 Y10 Z0\nG1 F100\nG41 D1 X10 Y0\nX20\nY20\nX0\nY0\nX10\n"
            "G40 X10 Y10\n")
    segs = [s for s in parse_program(text, tools=TOOLS).segments if not getattr(s, "rapid", False)]
    # by hand: entry (10,10)->(10,0) offset to x = 15 at its end, inside corner with y = 5: the entry is cut
    # back along itself to (12.5, 5); then the offsets y = 5, x = 15, y = 15, x = 5 meet at the inner square
    # (5..15)^2; the last side ends 5 mm above (10, 0); the exit goes back to (10, 10)
    assert _desc(segs) == [("L", (12.5, 5)), ("L", (15, 5)), ("L", (15, 15)), ("L", (5, 15)), ("L", (5, 5)),
                           ("L", (10, 5)), ("L", (10, 10))]
    for s in segs[1:-1]:
        for p in _samples(s):
            assert _dist_to_square(p, 0, 20) == pytest.approx(5, abs=1e-9)
    # a ramp on the first side: cut back in XY only, it still ends at its programmed z -2
    segs = [s for s in parse_program(text.replace("\nX20\n", "\nX20 Z-2\n"), tools=TOOLS).segments
            if not getattr(s, "rapid", False)]
    assert [round(s.end[2] / MM, 9) for s in segs] == [0, -2, -2, -2, -2, -2, -2]


def test_circle_outside_g42_and_inside_g41():
    # outside: ccw circle R10, tool on the right = outside: radius 15, tangent entry along +y
    text = "G21 G90 G17\nG0 X10 Y-10\nG1 F100\nG42 D1 X10 Y0\nG3 X10 Y0 I-10 J0\nG40 G1 X10 Y10\n"
    segs = [s for s in parse_program(text, tools=TOOLS).segments if not getattr(s, "rapid", False)]
    assert _desc(segs) == [("L", (15, 0)), ("A", (15, 0), (0, 0), 15, round(2 * math.pi, 6)), ("L", (10, 10))]
    # inside: ccw circle R10, tool on the left = inside: radius 5; the entry from the centre along +x meets
    # the offset circle at 5 (2, 1) / sqrt 5 (its line ends at (10, 5)), the arc runs from there round to (5, 0)
    text = "G21 G90 G17\nG0 X0 Y0\nG1 F100\nG41 D1 X10 Y0\nG3 X10 Y0 I-10 J0\nG40 G1 X0 Y0\n"
    segs = [s for s in parse_program(text, tools=TOOLS).segments if not getattr(s, "rapid", False)]
    p = (round(2 * math.sqrt(5), 6), round(math.sqrt(5), 6))
    assert _desc(segs) == [("L", p), ("A", (5, 0), (0, 0), 5, round(2 * math.pi - math.atan(0.5), 6)),
                           ("L", (0, 0))]
    np.testing.assert_allclose(segs[1].start[:2] / MM, p, atol=1e-9)


def test_line_to_arc_outside_corner_and_z_only_moves():
    # G42 along +x to (10, 0), then a ccw arc about (10, 10) (tangent +x: a tangent join) -> no corner arc;
    # then a line back -x from (20, 10): the arc ends with tangent +y, turning to -x is a left turn, outside
    # for a tool on the right: corner arc about (20, 10)
    text = ("G21 G90 G17\nG0 X0 Y0\nG1 F100\nG42 D1 X10 Y0\nG3 X20 Y10 I0 J10\nG1 Z-2\nX0\nG40 X0 Y20\n")
    segs = parse_program(text, tools=TOOLS).segments
    assert _desc(segs) == [("L", (10, -5)), ("A", (25, 10), (10, 10), 15, round(math.pi / 2, 6)),
                           ("L", (25, 10)), ("A", (20, 15), (20, 10), 5, round(math.pi / 2, 6)), ("L", (0, 15)),
                           ("L", (0, 20))]
    assert segs[2].end[2] == pytest.approx(-2 * MM) and isinstance(segs[2], Linear)


def test_reversal_goes_round_the_end_point():
    # G41 along +x with the tool at +y, then straight back: half a circle about (10, 0) through (15, 0)
    segs = parse_program("G21 G17\nG0 X0 Y-10\nG1 F100\nG41 D1 X0 Y0\nX10\nX0\nG40 X0 Y-10\n",
                         tools=TOOLS).segments
    arc = segs[4]   # after the rapid, the entry, the corner arc at (0, 0) and the line along +x
    assert isinstance(arc, Arc) and arc.sweep == pytest.approx(-math.pi)
    np.testing.assert_allclose(arc.point_at(np.array([0.5]))[0][:2], [15 * MM, 0], atol=1e-15)
    assert _desc(segs[5:6]) == [("L", (0, -5))]


@pytest.mark.parametrize("text, line, words", [
    ("G21 G17\nG0 X0 Y0\nG1 F100\nG41 D1 X5 Y0\nG3 X5 Y0 I-3 J0\nG40 G1 X0\n", 5, ["not smaller than the arc radius"]),
    ("G21 G17\nG0 X4 Y4\nG1 F100\nG41 D1 X4 Y0\nX8\nY8\nX0\nY0\nX4\nG40 X4 Y4\n", 5, ["gouge"]),
    ("G21 G17\nG0 X0 Y0\nG1 F100\nG41 D1\nG2 X10 Y0 R5\nG40 G1 X0\n", 5, ["entry move"]),
    ("G21 G17\nG0 X0 Y0\nG1 F100\nG41 D1 X10\nG3 X20 Y0 Z1 R5\nG40 G1 X0\n", 5, ["helix"]),
])
def test_compensation_refusals(text, line, words):
    with pytest.raises(InputError) as ei:
        parse_program(text, source="cc.nc", tools=TOOLS)
    assert ei.value.line == line, str(ei.value)
    for w in words:
        assert w in str(ei.value)


@pytest.mark.parametrize("text, column, words", [
    ("G21\nG41 D1\nG42 D1\n", 1, ["G40 first"]),
    ("G21\nG41 D1\nG28 Z0\n", 1, ["G28/G53 under cutter compensation"]),
    ("G21\nG41 D1\nG81 X1 Z-1 R1 F10\n", 1, ["canned cycle under cutter compensation"]),
    ("G21\nG18 G41 D1\n", 5, ["XY plane"]),
    ("G21\nG41 D2\n", 5, ["D2", "not in the tool table"]),
])
def test_compensation_bad_lines(text, column, words):
    with pytest.raises(InputError) as ei:
        parse_program(text, tools=TOOLS)
    assert (ei.value.line, ei.value.column) == (text.count("\n"), column), str(ei.value)
    for w in words:
        assert w in str(ei.value)
