"""Tools from the program: ``M6`` changes the cutter, ``S`` the spindle speed of the passes that follow.

A 20 x 20 mm block is slotted twice, first by T1 (10 mm, 3 flutes, S12000), then by T2 (4 mm,
2 flutes, S10000) from the setup file's tool table. Each slot runs across the whole block with its
ends outside it, and its edges lie on dexel grid lines (0.5 mm), so the material each tool removes
is the slot's box, width D x depth a x 20 mm, exactly; the slotting force in the middle of each
pass is the closed-form revolution-mean force (Altintas) of that tool's flutes and feed per tooth.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from greybench.cli import app

runner = CliRunner()

TWO_TOOLS = """%
O0300 (TWO TOOLS)
G21 G90 G17 G94
T1 M6
S12000 M3
G0 X-8. Y6. Z5.
G0 Z-1.
G1 X28. F1500.
G0 Z5.
T2 M6
S10000 M3
G0 X28. Y16.
G0 Z-2.
G1 X-8. F1000.
G0 Z5.
M5
M30
%
"""
# (tool, diameter [mm], flutes, rpm, feed [mm/min], depth [mm], line of the slot)
PASSES = ((1, 10.0, 3, 12000.0, 1500.0, 1.0, 8), (2, 4.0, 2, 10000.0, 1000.0, 2.0, 14))


def _setup(tmp_path):
    setup = tmp_path / "setup.json"
    setup.write_text(json.dumps({"units": "mm", "tools": {
        "1": {"length": 80, "diameter": 10, "flutes": 3},
        "2": {"length": 90, "diameter": 4, "type": "flat", "flutes": 2, "helix_deg": 30, "flute_length": 15}}}))
    return setup


@pytest.fixture
def two_tools(small_job, tmp_path):
    prog, pose = small_job
    two = prog.with_name("two.nc")
    two.write_text(TWO_TOOLS)
    two.with_name("two.stock.json").write_text(prog.with_name("small.stock.json").read_text())
    return two, pose, _setup(tmp_path)


def _job(two, pose, setup_file, **kw):
    from greybench.support import DATA_DIR
    from simulate.pipeline import Components, MachiningJob, MachiningSettings
    from simulate.toolpath.placement import load_poses
    from simulate.toolpath.setup import read_setup

    off = Components(deflection=False, friction=False, switching=False, servo=False)
    return MachiningJob(program=two, robot=DATA_DIR / "robots" / "max100.toml", placement=load_poses(pose)[0],
                        components=off, settings=MachiningSettings(spacing=0.5e-3, **kw),
                        setup=None if setup_file is None else read_setup(setup_file))


def test_each_pass_is_cut_with_its_tool(two_tools):
    from simulate.machining.closed_form import mean_force_local
    from simulate.machining.cutting import load_material
    from simulate.pipeline import run_job

    two, pose, setup = two_tools
    mo = run_job(_job(two, pose, setup))
    uses = {u.tool: u for u in mo.result.tools}
    assert set(uses) == {1, 2}
    mat = load_material(_job(two, pose, setup).settings.material)
    st = mo.steps
    for tool, d_mm, flutes, rpm, feed, depth_mm, line in PASSES:
        u = uses[tool]
        assert u.diameter == pytest.approx(d_mm * 1e-3) and u.flutes == flutes and u.spindle_rpm == (rpm,)
        # the slot's box, D x a x 20 mm (grid-aligned edges: exact up to rounding)
        assert u.removed_volume == pytest.approx(d_mm * depth_mm * 20.0 * 1e-9, rel=1e-9)
        # steady slotting in the middle of the block: the closed-form mean force of this tool
        x = mo.trajectory.xyz[:, 0]
        mid = (st.line == line) & (x > 8e-3) & (x < 12e-3)
        assert mid.sum() > 10
        fz = feed * 1e-3 / 60.0 / (flutes * rpm / 60.0)
        ref = mean_force_local(0.0, math.pi, depth_mm * 1e-3, fz, flutes, mat.kc, mat.ke)
        got = np.linalg.norm(st.force[mid][:, :2], axis=1).mean()
        assert got == pytest.approx(math.hypot(ref[0], ref[1]), rel=0.05)
    assert mo.result.removed_volume == pytest.approx(sum(u.removed_volume for u in uses.values()), rel=1e-12)


def test_machine_cli_reports_each_tool_and_refuses_without_the_table(two_tools, tmp_path):
    two, pose, setup = two_tools
    common = ["--pose", str(pose), "--spacing", "0.5", "--ideal", "--json"]
    r = runner.invoke(app, ["machine", "--program", str(two), "--out", str(tmp_path / "a"), "--setup", str(setup),
                            *common])
    assert r.exit_code == 0, r.output
    tools = {t["tool"]: t for t in json.loads(r.stdout)["tools"]}
    assert tools[1]["removed_volume"] == pytest.approx(200e-9, rel=1e-9)
    assert tools[2]["removed_volume"] == pytest.approx(160e-9, rel=1e-9)
    assert tools[2]["spindle_rpm"] == [10000.0] and tools[2]["diameter"] == pytest.approx(4e-3)
    # two tools and no table: refused naming the line T2 first cuts on
    r = runner.invoke(app, ["machine", "--program", str(two), "--out", str(tmp_path / "b"), *common])
    assert r.exit_code == 2 and "T1, T2" in r.output and "line 14" in r.output
    assert not (tmp_path / "b").exists()
    # a table without T2
    one = tmp_path / "one.json"
    one.write_text(json.dumps({"units": "mm", "tools": {"1": {"length": 80, "diameter": 10}}}))
    r = runner.invoke(app, ["machine", "--program", str(two), "--out", str(tmp_path / "c"), "--setup", str(one),
                            *common])
    assert r.exit_code == 2 and "T2" in r.output and "line 14" in r.output


def test_spindle_stopped_on_a_cut_is_refused_and_the_default_is_stated(small_job, tmp_path):
    from identify.errors import InputError
    from simulate.pipeline import load_program

    prog, _ = small_job
    text = prog.read_text()
    stopped = prog.with_name("stopped.nc")
    stopped.write_text(text.replace("G1 X28 Y-4.5 Z-1\n", "M5\nG1 X28 Y-4.5 Z-1\n"))
    stopped.with_name("stopped.stock.json").write_text(prog.with_name("small.stock.json").read_text())
    line = stopped.read_text().splitlines().index("G1 X28 Y-4.5 Z-1") + 1
    with pytest.raises(InputError, match="spindle stopped") as exc:
        load_program(stopped)
    assert exc.value.line == line
    assert load_program(stopped, spindle_rpm=9000.0).step_rpm.min() == 9000.0   # --spindle states it
    none = prog.with_name("nos.nc")
    none.write_text(text.replace("S12000 M3\n", "M3\n"))
    none.with_name("nos.stock.json").write_text(prog.with_name("small.stock.json").read_text())
    ps = load_program(none)
    assert (ps.step_rpm == 12000.0).all() and any("default 12000 rev/min" in w for w in ps.warnings)
    with pytest.raises(InputError, match="never switches the spindle on"):
        load_program(none, require_spindle=True)


def test_a_program_without_units_word_warns_and_can_be_refused(small_job, tmp_path):
    prog, pose = small_job
    bare = prog.with_name("bare.nc")
    bare.write_text(prog.read_text().replace("G21 G90 G17 G94\n", "G90 G17 G94\n"))
    bare.with_name("bare.stock.json").write_text(prog.with_name("small.stock.json").read_text())
    line = bare.read_text().splitlines().index("G0 X-8 Y10 Z5") + 1
    common = ["--program", str(bare), "--pose", str(pose), "--spacing", "1", "--ideal", "--json"]
    r = runner.invoke(app, ["machine", *common, "--out", str(tmp_path / "a")])
    assert r.exit_code == 0
    assert "no units word" in r.stderr and f"line {line}" in r.stderr and "read as mm" in r.stderr
    r = runner.invoke(app, ["machine", *common, "--out", str(tmp_path / "b"), "--require-units"])
    assert r.exit_code == 2 and "units word" in r.output and f"line {line}" in r.output
