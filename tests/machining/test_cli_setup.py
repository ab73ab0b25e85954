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


def test_rank_poses_reads_the_program_with_the_setup(tmp_path):
    """``rank-poses --setup``: the program is read with the file's tables before any simulation (a
    G55 the file lacks is refused naming it, after the G28 the file does give); without the file the
    G28 is refused; a bad file is refused naming its field. Nothing is written."""
    from greybench.support import DATA_DIR

    prog = tmp_path / "iso160_g55.nc"
    text = (DATA_DIR / "programs" / "iso160.nc").read_text()
    prog.write_text(text.replace("G21 G90 G17 G94\n", "G21 G90 G17 G94\nG28 G91 Z0.\nG90 G55\n", 1))
    line = prog.read_text().splitlines().index("G90 G55") + 1
    prog.with_name("iso160_g55.stock.json").write_text((DATA_DIR / "programs" / "iso160.stock.json").read_text())
    args = ["rank-poses", "--program", str(prog), "--poses", str(DATA_DIR / "poses" / "iso160.json"), "--size", "160",
            "--out", str(tmp_path / "out")]
    r = runner.invoke(app, args)
    assert r.exit_code == 2 and "G28" in r.output and f"line {line - 1}" in r.output
    home = tmp_path / "home.json"
    home.write_text(json.dumps({"units": "mm", "home": [0, 0, 100]}))
    r = runner.invoke(app, args + ["--setup", str(home)])
    assert r.exit_code == 2 and "G55" in r.output and f"line {line}" in r.output
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"units": "mm", "tools": {"1": {"length": 0, "diameter": 10}}}))
    r = runner.invoke(app, args + ["--setup", str(bad)])
    assert r.exit_code == 2 and "bad.json" in r.output and "tools.1" in r.output
    assert not (tmp_path / "out").exists()


def test_rank_poses_passes_the_setup_to_the_reader(tmp_path):
    """:func:`simulate.evaluation.ranking.rank_poses` reads the program with ``setup`` (no poses: the
    reading alone) and refuses the G28 without it."""
    from greybench.support import DATA_DIR
    from identify.errors import InputError
    from simulate.evaluation.ranking import rank_poses
    from simulate.toolpath.setup import MachineSetup

    prog = tmp_path / "iso160_g55.nc"
    prog.write_text((DATA_DIR / "programs" / "iso160.nc").read_text().replace(
        "G21 G90 G17 G94\n", "G21 G90 G17 G94\nG28 G91 Z0.\nG90 G55\n", 1))
    prog.with_name("iso160_g55.stock.json").write_text((DATA_DIR / "programs" / "iso160.stock.json").read_text())
    robot = DATA_DIR / "robots" / "max100.toml"
    with pytest.raises(InputError, match="G28"):
        rank_poses(prog, robot, [])
    setup = MachineSetup(work_offsets={"G28": (0.0, 0.0, 0.1), "G55": (0.0, 0.0, 0.0)})
    assert rank_poses(prog, robot, [], setup=setup).entries == []


def _iso160_g55(tmp_path):
    from greybench.support import DATA_DIR

    prog = tmp_path / "iso160_g55.nc"
    prog.write_text((DATA_DIR / "programs" / "iso160.nc").read_text().replace(
        "G21 G90 G17 G94\n", "G21 G90 G17 G94\nG28 G91 Z0.\nG90 G55\n", 1))
    prog.with_name("iso160_g55.stock.json").write_text((DATA_DIR / "programs" / "iso160.stock.json").read_text())
    return prog


def test_optimize_pose_reads_the_program_with_the_setup(tmp_path):
    """``optimize-pose --setup``: refusals before any simulation name G28 (no file) and G55 (a file
    with only the home); :func:`simulate.placement.search.plan_search` reads the program with the
    tables (its path then starts at home, 100 mm up)."""
    from greybench.support import DATA_DIR
    from identify.errors import InputError
    from simulate.evaluation.ranking import RankSettings
    from simulate.placement.search import SearchSettings, plan_search
    from simulate.toolpath.placement import load_poses
    from simulate.toolpath.setup import MachineSetup

    prog = _iso160_g55(tmp_path)
    poses = DATA_DIR / "poses" / "iso160.json"
    args = ["optimize-pose", "--program", str(prog), "--poses", str(poses), "--out", str(tmp_path / "out"),
            "--budget-s", "600"]
    r = runner.invoke(app, args)
    assert r.exit_code == 2 and "G28" in r.output
    home = tmp_path / "home.json"
    home.write_text(json.dumps({"units": "mm", "home": [0, 0, 100]}))
    r = runner.invoke(app, args + ["--setup", str(home)])
    assert r.exit_code == 2 and "G55" in r.output and not (tmp_path / "out").exists()
    settings = SearchSettings(budget_s=3600.0, rank=RankSettings(size=160))
    placements = load_poses(poses)[:1]
    with pytest.raises(InputError, match="G28"):
        plan_search(prog, DATA_DIR / "robots" / "max100.toml", placements, settings)
    setup = MachineSetup(work_offsets={"G28": (0.0, 0.0, 0.1), "G55": (0.0, 0.0, 0.0)})
    plan = plan_search(prog, DATA_DIR / "robots" / "max100.toml", placements, settings, setup=setup)
    assert plan.program.parsed.segments[0].end[2] == pytest.approx(0.1)
