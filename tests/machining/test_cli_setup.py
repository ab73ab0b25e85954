"""``greybench machine --setup``: a program written in G55 coordinates with a G28 retract and G43 H
machines the same part as the placement-frame program (the fixture's), and without the setup file
it is refused naming the offset."""
from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from greybench.cli import app

runner = CliRunner()
# the fixture's slot program in G55 coordinates, G55 = (-5, 3, 0) mm: program x = x + 5, y = y - 3;
# G28 G91 Z0. goes to home z 5 mm, where the fixture's program starts its cut from
SHIFTED = """%
O0200 (G55 SLOT)
G21 G17 G40 G49 G80 G90
G28 G91 Z0.
T2 M6
G90 G55 G0 X-3. Y7. S12000 M3
G43 H2 Z5.
G0 Z-1.
G1 X33. F3000.
G1 Y-7.5
G1 X-3.
G0 Z5.
M5
M30
%
"""


def test_machine_with_setup_matches_the_placement_frame_program(small_job, tmp_path):
    prog, pose = small_job
    shifted = prog.with_name("shifted.nc")
    shifted.write_text(SHIFTED)
    shifted.with_name("shifted.stock.json").write_text(prog.with_name("small.stock.json").read_text())
    setup = tmp_path / "setup.json"
    setup.write_text(json.dumps({"units": "mm", "work_offsets": {"G55": [-5, 3, 0]}, "home": [-8, 10, 5],
                                 "tools": {"2": {"length": 60, "diameter": 10}}}))
    common = ["--pose", str(pose), "--spacing", "0.5", "--ideal", "--json"]
    r0 = runner.invoke(app, ["machine", "--program", str(prog), "--out", str(tmp_path / "a"), *common])
    assert r0.exit_code == 0, r0.output
    r1 = runner.invoke(app, ["machine", "--program", str(shifted), "--out", str(tmp_path / "b"), "--setup",
                             str(setup), *common])
    assert r1.exit_code == 0, r1.output
    a, b = json.loads(r0.stdout), json.loads(r1.stdout)
    # the same cuts (the shifted program's first rapid differs: rounding only)
    assert a["removed_volume"] > 1e-7 and b["removed_volume"] == pytest.approx(a["removed_volume"], rel=1e-9)
    assert b["peak_force"] == pytest.approx(a["peak_force"], rel=1e-9)
    r2 = runner.invoke(app, ["machine", "--program", str(shifted), "--out", str(tmp_path / "c"), *common])
    assert r2.exit_code == 2 and "shifted.nc" in r2.output and "G28" in r2.output
    assert not (tmp_path / "c").exists()
