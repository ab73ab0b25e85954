"""A console run of one command loads only that command's area (start-up time): the command -> area
map of ``greybench.cli`` must name every command each area registers, and nothing else."""
from __future__ import annotations

import importlib
import subprocess
import sys

import typer

from greybench import cli


def _registered(area: str) -> set[str]:
    app, bench = typer.Typer(), typer.Typer()
    importlib.import_module(f"greybench.commands.{area}").register(app, bench)
    names = {c.name for c in app.registered_commands} | {g.name for g in app.registered_groups}
    return names | {f"bench {c.name}" for c in bench.registered_commands}


def test_every_registered_command_maps_to_its_area():
    seen = {}
    for area in cli._AREAS:
        for name in _registered(area):
            seen[name] = area
    assert seen == cli.COMMAND_AREAS


def test_areas_for_picks_one_area_only_for_a_console_run():
    assert cli.areas_for(["/x/bin/greybench", "machine", "--json"]) == ["machining"]
    assert cli.areas_for(["/x/greybench/cli.py", "bench", "machining"]) == ["machining"]
    assert cli.areas_for(["/x/bin/greybench", "bench"]) == cli._AREAS
    assert cli.areas_for(["/x/bin/greybench", "--help"]) == cli._AREAS
    assert cli.areas_for(["/x/bin/greybench", "no-such-command"]) == cli._AREAS
    assert cli.areas_for(["/x/bin/pytest", "machine"]) == cli._AREAS   # imported as a library: all


def test_machine_help_does_not_import_torch_or_mlflow():
    code = ("import sys; sys.argv = ['greybench', 'machine', '--help']; import runpy\n"
            "try:\n    runpy.run_module('greybench.cli', run_name='__main__')\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('torch', 'mlflow', 'pandas') if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip().splitlines()[-1] == "[]"
