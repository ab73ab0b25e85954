"""Fixtures for the toolpath tests: small programs with known geometry."""
from __future__ import annotations

import pytest

from simulate.toolpath.gcode import parse_program

RECT_WITH_ARCS = """%
(rectangle with tangent corner arcs, climb milling)
N10 G21 G90 G17
N20 T1 M6
N30 S12000 M3
N40 G0 X0 Y-20 Z5
N50 G1 Z0 F600
N60 G1 X150 F3000
N70 G3 X160 Y-10 I0 J10
N80 G1 Y80
N90 G3 X150 Y90 R10
N100 G1 X0
N110 G2 X-10 Y100 I0 J10 ; convex turn the other way
N120 G1 Y120
N130 G0 Z20
N140 M5
N150 M30
%
"""


@pytest.fixture
def rect_program():
    return parse_program(RECT_WITH_ARCS, source="rect.nc")
