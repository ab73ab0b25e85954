"""G-code reader on programs in the style real posts write: every feature compared with a path worked
out by hand (end points, arc centres, feeds, spindle) from the program text."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import Arc, parse_program, read_program

PROGRAMS = Path(__file__).parent / "programs"
MM = 1e-3


def _line_of(path: Path, block: str) -> int:
    """1-based file line of the block starting with ``block`` (e.g. 'N80')."""
    for i, raw in enumerate(path.read_text(encoding="latin-1").splitlines(), start=1):
        if raw.split() and raw.split()[0] == block:
            return i
    raise AssertionError(block)


def test_linuxcnc_modes_program_against_a_hand_reading():
    f = PROGRAMS / "linuxcnc_modes.ngc"
    segs = read_program(f).segments
    kinds = [("arc" if isinstance(s, Arc) else "rapid" if s.rapid else "feed") for s in segs]
    assert kinds == ["rapid", "feed", "arc", "arc", "feed", "feed", "arc", "rapid"]
    ends = [tuple(np.round(s.end / MM, 9)) for s in segs]
    assert ends == [(0, 0, 5), (0, 0, -1), (20, 0, -1), (40, 0, -1), (40, 10, -1), (50, 10, -1),
                    (60, 10, -1), (60, 10, 5)]
    # N80 G3, I10 J0 incremental (G91.1): centre (10, 0), half circle counter-clockwise through (10, -10)
    a = segs[2]
    np.testing.assert_allclose(a.center, [10 * MM, 0, -MM], atol=1e-15)
    assert a.sweep == pytest.approx(math.pi) and a.radius == pytest.approx(10 * MM)
    np.testing.assert_allclose(a.point_at(np.array([0.5]))[0], [10 * MM, -10 * MM, -MM], atol=1e-15)
    # N100 G2 under G90.1: I30 J0 is the absolute centre (30, 0), clockwise through (30, 10)
    b = segs[3]
    np.testing.assert_allclose(b.center, [30 * MM, 0, -MM], atol=1e-15)
    assert b.sweep == pytest.approx(-math.pi)
    np.testing.assert_allclose(b.point_at(np.array([0.5]))[0], [30 * MM, 10 * MM, -MM], atol=1e-15)
    # N160 back to G91.1: I5 from the start (50, 10) -> centre (55, 10)
    np.testing.assert_allclose(segs[6].center, [55 * MM, 10 * MM, -MM], atol=1e-15)
    assert [s.line for s in segs] == [_line_of(f, n) for n in
                                      ("N60", "N70", "N80", "N100", "N130", "N150", "N160", "N190")]
    # F300 mm/min on every feed move; spindle 8000 rpm clockwise, then M4 S6000 counter-clockwise, M5 off
    assert all(s.feed == pytest.approx(0.3 / 60) for s in segs[1:7])
    assert [round(s.spindle * 60) for s in segs] == [8000, 8000, 8000, 8000, 6000, 6000, 6000, 0]
    assert [s.spindle_ccw for s in segs] == [False] * 4 + [True] * 3 + [False]
    # G64 P0.01 (mm) until G61 on N140
    assert [s.blend for s in segs] == [True] * 5 + [False] * 3
    assert [s.blend_tolerance for s in segs] == [pytest.approx(0.01 * MM)] * 5 + [0.0] * 3


def test_g90_1_centre_read_as_incremental_would_be_refused():
    # the same arc with G91.1: centre (50, 0) is 30 from the start but 10 from the end
    with pytest.raises(InputError, match="not on the circle"):
        parse_program("G21 G90 G91.1\nG0 X20 Y0\nG2 X40 Y0 I30 J0 F100\n")


def test_g64_without_p_and_p_elsewhere():
    s = parse_program("G21 G64\nG1 X1 F10\n").segments[0]
    assert s.blend and s.blend_tolerance == 0.0
    s = parse_program("G20 G64 P0.001\nG1 X1 F10\n").segments[0]
    assert s.blend_tolerance == pytest.approx(0.001 * 0.0254)


@pytest.mark.parametrize("text, line, column, words", [
    ("O100\nO200 G0 X1\n", 2, 6, ["'O'", "alone"]),
    ("G21 G90\nN5 G1 X1 A5. F10\n", 2, 10, ["A5.", "rotary", "only", "0", "block N5"]),
    ("G21 G90\nG1 X1 B-0.001 F10\n", 2, 7, ["B-0.001", "rotary"]),
    ("G21\nG41 D1 X5\n", 2, 5, ["G41 D1", "not in the tool table"]),
    ("G21\nG1 X1 F10 D1\n", 2, 11, ["'D'", "only allowed with G41/G42"]),
    ("G21\nG42.1 D1 X5\n", 2, 1, ["G42.1", "not supported"]),
    ("G21\nG16\n", 2, 1, ["G16", "polar coordinates is not supported"]),
    ("G21\nG15\n", 2, 1, ["G15", "polar coordinates is not supported"]),
    ("G21\nG65 P9010 A1\n", 2, 1, ["G65", "macro call is not supported"]),
    ("G21\nM98 P1000\n", 2, 1, ["M98", "subprogram call is not supported"]),
    ("G21\no100 if [#1 GT 0]\n", 2, 1, ["o-word control flow", "o100 if", "not supported"]),
    ("G21\nO<pocket> call\n", 2, 1, ["o-word control flow", "o<pocket> call", "not supported"]),
    ("G21\n#1 = 5\n", 2, 1, ["parameter '#1'", "not supported"]),
    ("G21\nG1 X[1+2] F10\n", 2, 5, ["expression", "not supported"]),
    ("G21\nG1 X1 F10 P2\n", 2, 11, ["'P'", "only allowed"]),
    ("G21\nG84 X1 Z-1 R1 F10\n", 2, 1, ["G84", "not supported"]),
    ("G21\nG92 X0\n", 2, 1, ["G92", "not supported"]),
    ("G21\nG61.1\n", 2, 1, ["G61.1", "not supported"]),
    ("G21\nM3 M5\n", 2, 4, ["spindle"]),
    ("G21\nG90 G91.1 G90.1\n", 2, 11, ["modal group (arc centre)"]),
    ("G21\nG1 X1 F10 U3\n", 2, 11, ["U3", "not supported"]),
])
def test_unsupported_words_refused_in_one_line(text, line, column, words):
    with pytest.raises(InputError) as ei:
        parse_program(text, source="post.nc")
    e = ei.value
    assert (e.source, e.line, e.column) == ("post.nc", line, column), str(e)
    assert "\n" not in str(e)
    for w in words:
        assert w in str(e), str(e)


def test_g80_cancels_the_motion_mode_and_m_words_do_not_move():
    with pytest.raises(InputError, match="without a motion mode"):
        parse_program("G21 G90\nG1 X1 F10\nG80\nX2\n")
    p = parse_program("G21 G90\nG0 X1\nM0\nM1\nM7\nM8\nM9\nM6 T2\nG1 X2 F10\nM2\n")
    assert [tuple(np.round(s.end / MM, 9)) for s in p.segments] == [(1, 0, 0), (2, 0, 0)]
    assert p.segments[1].tool == 2


def test_g4_dwell_is_recorded_on_the_move_before():
    p = parse_program("G21 G90\nG4 P1\nG1 X1 F10\nG4 P0.5\nG3 X3 Y0 R1\nG4 P2\nG4 P1\n")
    assert [s.dwell for s in p.segments] == [0.5, 3.0]   # nothing moved before the first G4
    with pytest.raises(InputError, match="G4 needs the dwell time P"):
        parse_program("G21\nG4\n")
    with pytest.raises(InputError, match="both G4 and path mode"):
        parse_program("G21\nG64 G4 P1\n")
