"""G-code reader: exact arcs, units, modes, and line/column-numbered errors."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from identify.errors import InputError
from simulate.toolpath.gcode import Arc, Linear, parse_program, read_program


def test_segments_units_and_modal_state(rect_program):
    segs = rect_program.segments
    assert [type(s).__name__ for s in segs] == ["Linear", "Linear", "Linear", "Arc", "Linear", "Arc", "Linear",
                                               "Arc", "Linear", "Linear"]
    assert segs[0].rapid and not segs[1].rapid
    assert segs[1].feed == pytest.approx(0.6 / 60)  # F600 mm/min -> m/s
    assert segs[2].feed == pytest.approx(3.0 / 60)
    assert segs[2].spindle == pytest.approx(200.0)  # 12000 rpm -> rev/s
    assert segs[2].tool == 1
    assert segs[3].line == 9  # 1-based file line of N70
    np.testing.assert_allclose(segs[2].end, [0.150, -0.020, 0.0])


def test_arc_geometry_ijk_and_r(rect_program):
    a = rect_program.segments[3]
    assert isinstance(a, Arc)
    np.testing.assert_allclose(a.center, [0.150, -0.010, 0.0], atol=1e-15)
    assert a.radius == pytest.approx(0.010)
    assert a.sweep == pytest.approx(math.pi / 2)
    b = rect_program.segments[5]  # R form, G3
    np.testing.assert_allclose(b.center, [0.150, 0.080, 0.0], atol=1e-12)
    assert b.sweep == pytest.approx(math.pi / 2)
    c = rect_program.segments[7]  # G2 clockwise
    assert c.sweep == pytest.approx(-math.pi / 2)
    assert c.length == pytest.approx(0.010 * math.pi / 2)


def test_r_negative_gives_long_arc_and_full_circle_ijk():
    p = parse_program("G17 G21 G90\nG0 X10 Y0\nG3 X0 Y10 R-10 F100\nG2 X0 Y10 I0 J-10\n")
    long_arc, full = p.segments[1], p.segments[2]
    assert long_arc.sweep == pytest.approx(1.5 * math.pi)
    np.testing.assert_allclose(long_arc.center, [0.010, 0.010, 0.0], atol=1e-12)
    assert full.sweep == pytest.approx(-2 * math.pi)


def test_planes_follow_right_hand_rule():
    # G18: normal +y, G3 positive about +y turns z into x.
    p = parse_program("G18 G21 G90\nG0 X0 Z10\nG3 X10 Z0 I0 K-10 F100\n")
    a = p.segments[1]
    np.testing.assert_allclose(a.normal, [0, 1, 0])
    assert a.sweep == pytest.approx(math.pi / 2)
    mid = a.point_at(np.array([0.5]))[0]
    np.testing.assert_allclose(mid, [0.01 * math.sqrt(0.5), 0, 0.01 * math.sqrt(0.5)], atol=1e-15)
    p = parse_program("G19 G21 G90\nG0 Y10 Z0\nG3 Y0 Z10 J-10 K0 F100\n")
    a = p.segments[1]
    np.testing.assert_allclose(a.normal, [1, 0, 0])
    assert a.sweep == pytest.approx(math.pi / 2)


def test_inch_incremental_and_helix():
    p = parse_program("G20 G91\nG1 X1 Y2 F10\nG21\nG1 X-25.4\n")
    np.testing.assert_allclose(p.segments[0].end, [0.0254, 0.0508, 0])
    np.testing.assert_allclose(p.segments[1].end, [0.0, 0.0508, 0], atol=1e-15)
    assert p.segments[0].feed == pytest.approx(10 * 0.0254 / 60)
    h = parse_program("G21 G90\nG0 X10\nG3 X10 Y0 Z6 I-10 F100\n").segments[1]
    assert h.sweep == pytest.approx(2 * math.pi) and h.rise == pytest.approx(0.006)
    assert h.length == pytest.approx(math.hypot(2 * math.pi * 0.01, 0.006))


def test_radius_mismatch_within_tolerance_is_made_exact():
    # end radius off by 0.001 mm (CAM rounding): accepted, both ends exactly on one circle
    a = parse_program("G21 G90\nG0 X10 Y0\nG3 X0 Y10.001 I-10 J0 F100\n").segments[1]
    assert np.linalg.norm(a.start - a.center) == pytest.approx(a.radius, abs=1e-15)
    assert np.linalg.norm(a.end - a.center) == pytest.approx(a.radius, abs=1e-15)


@settings(max_examples=60, deadline=None)
@given(cx=st.floats(-200, 200), cy=st.floats(-200, 200), r=st.floats(0.5, 300),
       a0=st.floats(-math.pi, math.pi), a1=st.floats(-math.pi, math.pi), cw=st.booleans())
def test_random_arcs_have_exact_endpoints(cx, cy, r, a0, a1, cw):
    x0, y0 = cx + r * math.cos(a0), cy + r * math.sin(a0)
    x1, y1 = cx + r * math.cos(a1), cy + r * math.sin(a1)
    text = (f"G21 G90\nG0 X{x0:.6f} Y{y0:.6f}\n"
            f"G{2 if cw else 3} X{x1:.6f} Y{y1:.6f} I{cx - x0:.6f} J{cy - y0:.6f} F500\n")
    segs = parse_program(text).segments
    arc = [s for s in segs if isinstance(s, Arc)][0]
    assert (arc.sweep < 0) == cw
    ends = arc.point_at(np.array([0.0, 1.0]))
    np.testing.assert_allclose(ends[0], arc.start, atol=1e-12)
    np.testing.assert_allclose(ends[1], arc.end, atol=1e-12)


@pytest.mark.parametrize("text, line, column, words", [
    ("G21\nG1 X10 F100\nG41.1 X5\n", 3, 1, ["unsupported", "G41.1"]),
    ("G21\nG1 X10 F100\nG41 X5\n", 3, 1, ["G41 D0", "not in the tool table"]),
    ("G21\nG1 X10 F100 M98\n", 2, 13, ["unsupported", "M98", "subprogram call is not supported"]),
    ("G21\nG1 X10 A5 F100\n", 2, 8, ["unsupported", "A5"]),
    ("G21\nG1 X10\n", 2, 4, ["feed"]),
    ("G21\nX10\n", 2, 1, ["motion mode"]),
    ("G21\nG1 X10 F100 (open comment\n", 2, 13, ["not closed"]),
    ("G21 G1 X1 F10\nG1 X10 Y\n", 2, 8, ["has no number"]),
    ("G21 G1 X1 F10\nG1 X10 X5\n", 2, 8, ["twice"]),
    ("G21\nG0 X10\nG3 X0 Y10 I-10 J0.5 F100\n", 3, 11, ["not on the circle"]),
    ("G21\nG0 X10\nG2 X0 Y0 R2 F100\n", 3, 10, ["smaller than half the chord"]),
    ("G21\nG0 X10\nG2 X0 Y0 F100\n", 3, 4, ["centre"]),
    ("G21\nG0 X10\nG1 X0 I4 F100\n", 3, 7, ["only allowed with G2/G3"]),
    ("G21 G0 X1\nM30\nG1 X5 F1\n", 3, 1, ["after its end"]),
    ("G21\nG0 G1 X10 F10\n", 2, 4, ["modal group"]),
    ("G21\nG1 X10 F-5\n", 2, 8, ["F must be > 0"]),
    ("G21\nG1 X10 F10 #5\n", 2, 12, ["parameter '#5'", "not supported"]),
    ("G21\nG1 X10 F10 $5\n", 2, 12, ["word letter", "'$'"]),
    ("G21\nG17\nG2 X10 Y0 K3 F10\n", 3, 11, ["not an arc centre"]),
    ("G21\nG1 X1 F1\nG1 X2 N20\n", 3, 7, ["first word"]),
])
def test_malformed_programs_name_line_and_column(text, line, column, words):
    with pytest.raises(InputError) as ei:
        parse_program(text, source="bad.nc")
    e = ei.value
    assert (e.source, e.line, e.column) == ("bad.nc", line, column), str(e)
    for w in words:
        assert w in str(e)
    assert f"bad.nc, line {line}, column {column}" in str(e)


def test_read_program_missing_and_binary(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_program(tmp_path / "nope.nc")
    f = tmp_path / "bin.nc"
    f.write_bytes(b"\xff\xfe\x00G1")
    with pytest.raises(InputError, match="not a text file") as ei:
        read_program(f)
    assert ei.value.source == str(f)


def test_comments_and_zero_length_moves_are_dropped():
    p = parse_program("(hello) ; world\nN1 G21 G90 (a) G1 X0 Y0 F100 ; zero move\nG1 X1 ;(x\n")
    assert len(p.segments) == 1 and isinstance(p.segments[0], Linear)
