"""Work offsets G54-G59 / G54.1 P, G53 machine-coordinate moves and G28 returns: paths against a hand
reading with a given work-offset table (m, placement frame)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import Arc, parse_program, read_program

PROGRAMS = Path(__file__).parent / "programs"
MM = 1e-3
TABLE = {"G54": (0.300, 0.100, 0.050), "G55": (0.400, 0.100, 0.050), "G28": (0.0, 0.0, 0.400)}


def _mm(segs):
    return [tuple(np.round(s.end / MM, 9)) for s in segs]


def test_haas_program_with_two_fixtures_and_returns():
    segs = read_program(PROGRAMS / "haas_offsets.nc", work_offsets=TABLE).segments
    # by hand (mm, placement frame): G28 G91 Z0. from the origin goes straight up to home z 400;
    # G54 = (300, 100, 50): X-6 Y0 -> (294, 100) at z 400, Z5 -> 55, Z-1 -> 49, X26 -> 326, Z5 -> 55;
    # G55 = (400, 100, 50): X0 Y0 -> (400, 100), Z-1 -> 49, G2 to X10 (410) about I5 (405);
    # Z5 -> 55, G28 G91 Z0. -> z 400, G53 G0 X0 Y0 -> machine (0, 0) at z 400
    assert _mm(segs) == [(0, 0, 400), (294, 100, 400), (294, 100, 55), (294, 100, 49), (326, 100, 49),
                         (326, 100, 55), (400, 100, 55), (400, 100, 49), (410, 100, 49), (410, 100, 55),
                         (410, 100, 400), (0, 0, 400)]
    arc = segs[8]
    assert isinstance(arc, Arc)
    np.testing.assert_allclose(arc.center, [0.405, 0.100, 0.049], atol=1e-15)
    assert arc.sweep == pytest.approx(-math.pi)
    np.testing.assert_allclose(arc.point_at(np.array([0.5]))[0], [0.405, 0.105, 0.049], atol=1e-15)
    assert [i for i, s in enumerate(segs) if getattr(s, "retract", False)] == [0, 10, 11]
    assert all(s.rapid for i, s in enumerate(segs) if i in (0, 10, 11))


def test_empty_table_g54_is_the_frame_and_others_are_refused():
    p = parse_program("G21 G90 G54\nG0 X1 Y2 Z3\n")
    assert _mm(p.segments) == [(1, 2, 3)]
    with pytest.raises(InputError) as ei:
        parse_program("G21 G90\nG0 X1\nN30 G56 G0 X2\n", source="f.nc")
    e = ei.value
    assert (e.line, e.column) == (3, 5)
    assert "G56" in str(e) and "not in the work-offset table" in str(e) and "block N30" in str(e)
    with pytest.raises(InputError, match=r"G55 is not in the work-offset table \(given: G54\)"):
        parse_program("G55\n", work_offsets={"G54": (0, 0, 0)})


def test_g54_entry_applies_from_the_start_and_g54_1_p():
    t = {"G54": (0.01, 0, 0), "G54.1 P2": (0.0, 0.02, 0.0)}
    p = parse_program("G21 G90\nG0 X1\nG54.1 P2\nG0 X1\nG0 Y1\nG54\nG1 X0 F10\n", work_offsets=t)
    # X1 in G54 -> 11; in P2 -> 1 (y stays 0 until Y1 -> 21); G54 X0 -> 10, y stays 21
    assert _mm(p.segments) == [(11, 0, 0), (1, 0, 0), (1, 21, 0), (10, 21, 0)]
    assert _mm(parse_program("G54.1P2 G0 Y0\n", work_offsets={"G54.1P2": (0, 0.005, 0)}).segments) == \
        [(0, 5, 0)]
    with pytest.raises(InputError, match="G54.1 needs P"):
        parse_program("G54.1\n", work_offsets=t)
    with pytest.raises(InputError, match=r"G54.1 P3 is not in the work-offset table"):
        parse_program("G54.1 P3\n", work_offsets=t)


def test_incremental_moves_and_absolute_centres_under_an_offset():
    t = {"G54": (0.1, 0.2, 0.0)}
    p = parse_program("G21 G90\nG0 X0 Y0\nG91 G1 X5 F10\nG90 G90.1\nG3 X15 Y0 I10 J0\n", work_offsets=t)
    assert _mm(p.segments) == [(100, 200, 0), (105, 200, 0), (115, 200, 0)]
    # G90.1 I10 J0 is the program point (10, 0): frame (110, 200)
    np.testing.assert_allclose(p.segments[2].center, [0.110, 0.200, 0.0], atol=1e-15)


def test_g28_forms_and_g53_feed():
    t = {"G54": (0.1, 0.0, 0.0), "G28": (0.0, 0.05, 0.3)}
    # no axis words: straight to home; with X10 (G90): via program X10 (frame 110), then x home only
    p = parse_program("G21 G90\nG0 X1 Y2 Z3\nG28\nG0 X0\nG28 X10\n", work_offsets=t)
    assert _mm(p.segments) == [(101, 2, 3), (0, 50, 300), (100, 50, 300), (110, 50, 300), (0, 50, 300)]
    p = parse_program("G21 G90\nG1 X1 F60\nG53 Z0.2\nG1 X2\n", work_offsets=t)
    assert _mm(p.segments) == [(101, 0, 0), (101, 0, 0.2), (102, 0, 0.2)]
    assert p.segments[1].retract and not p.segments[1].rapid and p.segments[1].feed == pytest.approx(1e-3)


@pytest.mark.parametrize("text, line, column, words", [
    ("G21\nG28 Z0\n", 2, 1, ["G28 needs the home position"]),
    ("G21 G91\nG53 G0 Z0\n", 2, 1, ["G53", "incremental"]),
    ("G21\nG53 G2 X1 Y0 I1\n", 2, 5, ["G53", "G2", "axis words"]),
    ("G21\nG28 G53 Z0\n", 2, 5, ["modal group (non-modal)"]),
    ("G21\nG2 X2 F10 I1\nG53 X0\n", 3, 1, ["G53 needs G0 or G1"]),
    ("G21\nG54 G55\n", 2, 5, ["modal group (coordinate system)"]),
    ("G21\nG64 G54.1 P2\n", 2, 11, ["both G54.1 and G64"]),
])
def test_bad_offset_lines(text, line, column, words):
    with pytest.raises(InputError) as ei:
        parse_program(text, source="o.nc", work_offsets={"G54.1 P2": (0, 0, 0)})
    assert (ei.value.line, ei.value.column) == (line, column), str(ei.value)
    for w in words:
        assert w in str(ei.value)


@pytest.mark.parametrize("table, field", [
    ({"G60": (0, 0, 0)}, "work_offsets.G60"),
    ({"G55": (0, 0)}, "work_offsets.G55"),
    ({"G55": (0, float("nan"), 0)}, "work_offsets.G55"),
])
def test_bad_tables_name_the_entry(table, field):
    with pytest.raises(InputError) as ei:
        parse_program("G0 X0\n", work_offsets=table)
    assert ei.value.field == field
