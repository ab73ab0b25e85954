"""A console run of one command loads only that command's area (start-up time): the command -> area
map of ``greybench.cli`` must name every command each area registers, and nothing else."""
from __future__ import annotations

import subprocess
import sys

import typer

from greybench import cli


def _registered(area: str) -> set[str]:
    app = typer.Typer()
    cli.register_area(app, area)
    return {c.name for c in app.registered_commands} | {g.name for g in app.registered_groups}


def test_every_registered_command_maps_to_its_area():
    seen = {}
    for area in cli._AREAS:
        for name in _registered(area):
            seen[name] = area
    assert seen == cli.COMMAND_AREAS


def test_areas_for_picks_one_area_only_for_a_console_run():
    assert cli.areas_for(["/x/bin/greybench", "machine", "--json"]) == ["machining"]
    assert cli.areas_for(["/x/greybench/cli.py", "bench", "machining"]) == []   # greybench_bench, lazily
    assert cli.areas_for(["/x/bin/greybench", "bench"]) == []
    assert cli.areas_for(["/x/bin/greybench", "--help"]) == cli._AREAS
    assert cli.areas_for(["/x/bin/greybench", "no-such-command"]) == cli._AREAS
    assert cli.areas_for(["/x/bin/pytest", "machine"]) == cli._AREAS   # imported as a library: all


def test_machine_help_does_not_import_torch_or_mlflow():
    code = ("import sys; sys.argv = ['greybench', 'machine', '--help']; import runpy\n"
            "try:\n    runpy.run_module('greybench.cli', run_name='__main__')\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('torch', 'mlflow', 'pandas') if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip().splitlines()[-1] == "[]"


SLOT = "%\nG21 G90 G17\nT1 M6\nS12000 M3\nG0 X-8 Y10 Z5\nG1 Z-1 F600\nG1 X28 F1200\nG0 Z5\nM30\n%\n"


def test_machine_with_a_lugre_robot_imports_no_torch_mlflow_or_pyplot(tmp_path):
    import json

    prog = tmp_path / "slot.nc"
    prog.write_text(SLOT)
    stock = {"units": "mm", "box": {"min": [0, 0, -6], "max": [20, 20, 0]}}
    (tmp_path / "slot.stock.json").write_text(json.dumps(stock))
    pose = tmp_path / "poses.json"
    pose.write_text(json.dumps({"poses": [{"name": "near", "xyz": [1.45, 0.0, -0.1], "rpy": [0.0, 0.0, 0.0]}]}))
    seen = tmp_path / "modules.json"
    code = ("import sys, json, runpy, atexit\n"
            f"atexit.register(lambda: open({str(seen)!r}, 'w').write(json.dumps(sorted(m for m in "
            "('torch', 'mlflow', 'matplotlib.pyplot', 'pandas') if m in sys.modules))))\n"
            f"sys.argv = ['greybench', 'machine', '--program', {str(prog)!r}, '--pose', {str(pose)!r}, '--out', "
            f"{str(tmp_path / 'out')!r}, '--spacing', '1', '--json']\n"
            "runpy.run_module('greybench.cli', run_name='__main__')\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert json.loads(seen.read_text()) == []
    assert (tmp_path / "out" / "surface_deflection.glb").exists()
