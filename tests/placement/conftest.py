"""Fixtures of the placement-search tests: a 10 mm line program, and the small 160 programme (square and circle
contours, about a second per simulation at 1 mm dexels)."""
from __future__ import annotations

from pathlib import Path

import pytest

ROBOT = "data/robots/max100.toml"
SMALL = Path("tests/explain/data")
#: The line program: the tool moves 10 mm along the workpiece x axis through the workpiece origin.
LINE = "G21 G90 G17 G94\nG0 X-5 Y0 Z0\nG1 X5 Y0 Z0 F1000\nM30\n"


@pytest.fixture(scope="session")
def robot():
    from simulate.robot.model import load_robot

    return load_robot(ROBOT)


@pytest.fixture(scope="session")
def line_interp():
    from simulate.toolpath.gcode import parse_program
    from simulate.toolpath.interpolation import PathLimits, interpolate

    return interpolate(parse_program(LINE, source="line"), PathLimits())
