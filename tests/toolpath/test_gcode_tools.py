"""Tool length offset G43 H / G49 from a tool table (m): where the tool tip goes, against a hand
reading of a Fanuc-style two-tool program."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import parse_program, read_program

PROGRAMS = Path(__file__).parent / "programs"
MM = 1e-3
TOOLS = {1: (0.100, 0.005), 2: (0.080, 0.003)}   # T1 100 mm long, T2 80 mm
HOME = {"G28": (0.0, 0.0, 0.400)}


def _mm(segs):
    return [tuple(np.round(s.end / MM, 9)) for s in segs]


def test_fanuc_two_tools_tip_follows_the_program():
    segs = read_program(PROGRAMS / "fanuc_two_tools.nc", work_offsets=HOME, tools=TOOLS).segments
    # by hand: H names the tool in the spindle at each G43 (H1 with T1, the preselected T2 does not
    # count; H2 with T2), so the tip is where the program says; the G28 G91 Z0. lines go to home z 400
    assert _mm(segs) == [(0, 0, 400), (0, 0, 15), (0, 0, 5), (0, 0, -2), (20, 0, -2), (20, 0, 15),
                         (20, 0, 400), (30, 0, 400), (30, 0, 15), (30, 0, -2), (30, 0, 15), (30, 0, 400)]
    # the cut of line N70 is made by T1 although T2 was named on N35; N130 by T2
    assert [s.tool for s in segs] == [0, 1, 1, 1, 1, 1, 1, 2, 2, 2, 2, 2]
    assert segs[3].feed == pytest.approx(0.4 / 60) and segs[9].feed == pytest.approx(0.3 / 60)


def test_g43_naming_another_tool_shifts_the_tip_by_the_length_difference():
    # T1 (100 mm) in the spindle, G43 H2 (80 mm): the gauge line goes to z + 80, the tip to z - 20
    p = parse_program("G21 G90\nT1 M6\nG43 H2 G0 Z10\nG1 X5 F100\nG49\nG0 Z10\n", tools=TOOLS)
    assert _mm(p.segments) == [(0, 0, -10), (5, 0, -10), (5, 0, 10)]


def test_h_offset_stays_in_force_across_a_tool_change():
    # G43 H1 (100 mm) kept, T2 (80 mm) loaded: tip 20 mm above the programmed z
    p = parse_program("G21 G90\nT1 M6\nG43 H1\nG0 Z10\nT2 M6\nG0 Z10\nG43 H2\nG0 Z10\n", tools=TOOLS)
    assert _mm(p.segments) == [(0, 0, 10), (0, 0, 30), (0, 0, 10)]


def test_without_a_table_only_the_loaded_tool_is_accepted():
    p = parse_program("G21 G90 G0\nT3 M6\nG43 Z5 H3\nG0 Z1\nG43\nG0 Z2\n")
    assert _mm(p.segments) == [(0, 0, 5), (0, 0, 1), (0, 0, 2)]
    with pytest.raises(InputError) as ei:
        parse_program("G21 G90\nN10 T3 M6\nN20 G43 Z5 H4\n", source="t.nc")
    e = ei.value
    assert (e.line, e.column) == (3, 12)
    assert "H4" in str(e) and "not in the tool table" in str(e) and "block N20" in str(e)
    with pytest.raises(InputError, match="tool T3 in the spindle: tool 3 is not in the tool table"):
        parse_program("G21 G90\nT3 M6\nG43 H1\n", tools=TOOLS)


@pytest.mark.parametrize("text, column, words", [
    ("G0 Z5 H1\n", 7, ["'H'", "G43"]),
    ("G43 H1.5\n", 5, ["H must be a non-negative integer"]),
    ("G43 G49\n", 5, ["modal group (tool length)"]),
    ("G43.1 Z1\n", 1, ["G43.1", "not supported"]),
])
def test_bad_length_offset_lines(text, column, words):
    with pytest.raises(InputError) as ei:
        parse_program(text, tools=TOOLS)
    assert (ei.value.line, ei.value.column) == (1, column), str(ei.value)
    for w in words:
        assert w in str(ei.value)


@pytest.mark.parametrize("table, field", [
    ({-1: (0.1, 0.0)}, "tools.-1"),
    ({"x": (0.1, 0.0)}, "tools.x"),
    ({1: (0.0, 0.0)}, "tools.1"),
    ({1: (0.1,)}, "tools.1"),
    ({1: (0.1, -0.001)}, "tools.1"),
])
def test_bad_tool_tables_name_the_entry(table, field):
    with pytest.raises(InputError) as ei:
        parse_program("G0 X0\n", tools=table)
    assert ei.value.field == field
