"""A small contour program (a line, an arc, a line along two edges of a 20 x 20 mm block), its box
stock and a reachable pose."""
from __future__ import annotations

import json

import pytest

SMALL = """%
(small contour for the compensation tests)
G21 G90 G17 G94
T1 M6
S12000 M3
G0 X-8 Y24.5 Z5
G0 X-8 Y24.5 Z-2
G1 X20 Y24.5 Z-2 F1200
G2 X24.5 Y20 I0 J-4.5
G1 X24.5 Y-8 Z-2
G0 X24.5 Y-8 Z5
M5
M30
%
"""


@pytest.fixture
def small(tmp_path):
    prog = tmp_path / "small.nc"
    prog.write_text(SMALL)
    (tmp_path / "small.stock.json").write_text(json.dumps(
        {"units": "mm", "base": {"name": "block", "kind": "polygon", "vertices": [[0, 0], [20, 0], [20, 20], [0, 20]],
                                 "z_bottom": -6, "top": {"z0": 0}}, "blanks": []}))
    pose = tmp_path / "poses.json"
    pose.write_text(json.dumps({"poses": [{"name": "near", "xyz": [1.45, 0.0, -0.1], "rpy": [0.0, 0.0, 0.0]},
                                          {"name": "away", "xyz": [6.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}]}))
    return prog, pose


@pytest.fixture
def program(small):
    """``program(text, name) -> ProgramSetup``: a G-code text written beside the small contour and read
    with the small contour's stock."""
    from simulate.pipeline import load_program

    prog, _ = small

    def load(text: str, name: str):
        f = prog.with_name(f"{name}.nc")
        f.write_text(text)
        return load_program(f, stock=prog.with_name("small.stock.json"))

    return load
