"""Centre-format arc tolerance as LinuxCNC's (docs/gcode.md): both sides of the absolute and the
relative bound, and a Fusion-style program whose rounding the older 2 um + 1e-5 r bound refused."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import Arc, parse_program, read_program

PROGRAMS = Path(__file__).parent / "programs"
MM = 1e-3


def _quarter(r: float, delta: float, units: str = "G21", **kw):
    """G3 quarter circle from (r, 0) about (0, 0) to (0, r + delta): radius mismatch exactly delta."""
    return parse_program(f"{units} G90\nG0 X{r} Y0\nG3 X0 Y{r + delta} I{-r} J0 F100\n", **kw)


@pytest.mark.parametrize("units, r, inside, outside", [
    ("G21", 100.0, 0.027, 0.029),     # 0.1 % of 100 mm = 0.1 mm: the absolute 0.028284 mm bound acts
    ("G21", 10.0, 0.0099, 0.0101),    # 0.1 % of 10 mm = 0.01 mm < 0.028 mm: the relative bound acts
    ("G20", 10.0, 0.0028, 0.0029),    # inch: 2 * 0.001 * sqrt(2) = 0.0028284 in
])
def test_linuxcnc_bounds_both_sides(units, r, inside, outside):
    arc = _quarter(r, inside, units).segments[1]
    assert isinstance(arc, Arc)
    with pytest.raises(InputError, match="not on the circle") as ei:
        _quarter(r, outside, units)
    assert (ei.value.line, ei.value.column) == (3, len(f"G3 X0 Y{r + outside} ") + 1)  # the I word


def test_explicit_tolerance_replaces_the_default():
    _quarter(100.0, 0.004, arc_tolerance=0.005 * MM)
    with pytest.raises(InputError, match="not on the circle"):
        _quarter(100.0, 0.006, arc_tolerance=0.005 * MM)


def test_fusion_rounded_arcs_are_accepted_and_made_exact():
    segs = read_program(PROGRAMS / "fusion_generic_arcs.nc").segments
    a, b = segs[4], segs[5]
    assert isinstance(a, Arc) and isinstance(b, Arc)
    # G3 from (50, 0) about (0, 0) to (0, 50.004): 4 um mismatch, over the old 2 um + 0.5 um bound;
    # G2 from (0, 50.004) about (0.001, 55.006) to (-5.001, 55.002): 1.5 um
    for arc, centre, r in ((a, (0, 0), 50.0), (b, (0.001, 55.006), 5.002)):
        assert np.linalg.norm(arc.start - arc.center) == pytest.approx(arc.radius, abs=1e-15)
        assert np.linalg.norm(arc.end - arc.center) == pytest.approx(arc.radius, abs=1e-15)
        # the centre moved by no more than the rounding (a few um) from the programmed one
        assert np.linalg.norm(arc.center[:2] - np.array(centre) * MM) < 0.005 * MM
        assert arc.radius == pytest.approx(r * MM, abs=0.005 * MM)
    assert a.sweep == pytest.approx(math.pi / 2, abs=1e-4)
    # the G2 runs from the bottom of its circle (-90 deg) to its left point (180 deg): a clockwise quarter
    assert b.sweep == pytest.approx(-math.pi / 2, abs=1e-3)
    assert a.feed == pytest.approx(0.8 / 60)


def test_zero_radius_and_short_r_radius():
    # LinuxCNC: a radius under 0.00005 inch (1.27 um) at either end is a zero-radius arc
    with pytest.raises(InputError, match="coincides with the start point"):
        parse_program("G21 G90\nG0 X1 Y1\nG3 X2 Y1 I0.0012 J0 F10\n")
    with pytest.raises(InputError, match="coincides with the end point"):
        parse_program("G21 G90\nG0 X1 Y1\nG3 X2.0012 Y1 I1.0002 J0 F10\n")
    # R may fall short of half the chord by 0.00005 inch (1.27 um), no more
    parse_program("G21 G90\nG0 X0 Y0\nG3 X10 Y0 R4.9988 F10\n")
    with pytest.raises(InputError, match="smaller than half the chord"):
        parse_program("G21 G90\nG0 X0 Y0\nG3 X10 Y0 R4.9985 F10\n")
