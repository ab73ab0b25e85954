"""The CLI refuses before any work what the service refuses at submission, with the same shared checks
(:func:`simulate.run.check_program_text`, :func:`simulate.run.check_material`, :func:`simulate.run.check_reach`):
non-ASCII digits, a program without motion or spindle, an unknown material, a pose out of reach."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from identify.errors import InputError
from simulate.evaluation.ranking import RankSettings
from simulate.pipeline import Components
from simulate.run import check_material, check_program_text, rank_program

DATA = Path(__file__).resolve().parents[2] / "data"
ROBOT = DATA / "robots" / "max100.toml"


def _program(tmp: Path, text: str) -> Path:
    program = tmp / "p.nc"
    program.write_text(text)
    shutil.copyfile(DATA / "programs" / "iso160.stock.json", tmp / "p.stock.json")
    return program


def _rank(program: Path, poses: Path, **settings):
    return rank_program(program, ROBOT, poses, settings=RankSettings(spacing=2e-3, size=160, **settings),
                        components=Components(), workers=1)


GOOD = "G21 G90\nS12000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F600\nG1 X10\n"


@pytest.mark.parametrize(("text", "line", "what"), [
    ("G21 G90\nS12000 M3\nG0 X\u0661 Y0 Z5\n", 3, "non-ASCII digit"),
    ("(only a comment)\n", None, "no motion"),
    ("G21 G90\nG0 X0 Y0 Z5\nG1 Z-1 F600\n", None, "never switches the spindle on"),
])
def test_bad_programs_are_refused_naming_the_program(tmp_path, text, line, what):
    program = _program(tmp_path, text)
    with pytest.raises(InputError, match=what) as err:
        _rank(program, DATA / "poses" / "iso160.json")
    assert err.value.source == str(program) and err.value.field == "--program" and err.value.line == line
    # the very function the service calls at submission says the same
    with pytest.raises(InputError, match=what):
        check_program_text(text, "gcode", "gcode")


def test_a_spindle_default_makes_a_program_without_s_acceptable():
    check_program_text("G21 G90\nG0 X0 Y0 Z5\nG1 Z-1 F600\n", "p.nc", spindle_rpm=12000.0)


def test_an_unknown_material_is_refused_before_any_work(tmp_path):
    with pytest.raises(InputError) as err:
        _rank(_program(tmp_path, GOOD), DATA / "poses" / "iso160.json", material="unobtainium")
    assert err.value.field == "material"
    with pytest.raises(InputError) as err:
        check_material("unobtainium", "options.material")
    assert err.value.field == "options.material"


def test_a_pose_out_of_reach_is_refused_before_any_simulation(tmp_path):
    poses = tmp_path / "far.json"
    poses.write_text(json.dumps({"poses": [{"name": "moon", "xyz": [9.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}]}))
    out = tmp_path / "out"
    with pytest.raises(InputError) as err:
        rank_program(_program(tmp_path, GOOD), ROBOT, poses, settings=RankSettings(spacing=2e-3, size=160),
                     components=Components(), workers=1, out_dir=out)
    assert err.value.field == "--poses" and not out.exists()
