"""The ``greybench`` console script: one typer app composing identify, simulate and service.

Each area registers its commands from its own module in :mod:`greybench.commands`;
``greybench bench ...`` holds the benchmarks, loaded from :mod:`greybench_bench` only when asked for.
"""
from __future__ import annotations

import importlib
import sys

# Before torch or numba load: their thread pools sized to the cores this process may use
# (affinity, cgroup quota, GREYBENCH_CORES), waiting threads sleeping, so a fit beside a busy
# neighbour is slowed by sharing the cores, not by oversubscribed pools.
from identify.resources import configure_process

configure_process()

from typing import Any  # noqa: E402

import typer  # noqa: E402
from typer.core import TyperGroup  # noqa: E402

from greybench.support import guarded  # noqa: E402


class _LazyBench(TyperGroup):
    """``greybench bench``: the benchmark package is imported when a benchmark (or its list) is asked for."""

    _loaded: TyperGroup | None = None

    def _group(self) -> TyperGroup:
        if self._loaded is None:
            from greybench_bench import build_app

            group = typer.main.get_command(build_app())
            assert isinstance(group, TyperGroup)
            self._loaded = group
        return self._loaded

    def list_commands(self, ctx: Any) -> list[str]:
        return self._group().list_commands(ctx)

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        return self._group().get_command(ctx, cmd_name)


app = typer.Typer(no_args_is_help=True, pretty_exceptions_enable=False, add_completion=False, rich_markup_mode=None,
                  help="greybench: friction identification and robot machining simulation (SI units).")
app.add_typer(typer.Typer(cls=_LazyBench, no_args_is_help=True, rich_markup_mode=None,
                          help="Benchmarks: tables with ratios measured in one run."), name="bench")

# Areas, in the order of the workflow, with their commands. Each module defines COMMANDS: name ->
# command function or sub-app.
_AREA_COMMANDS = {
    "trajectory": "trajectory", "friction": "synth fit predict compare train-robot promote", "diagnose": "diagnose",
    "robot": "robot prepare", "toolpath": "testpiece interpolate", "machining": "machine",
    "evaluation": "rank-poses trace", "placement": "optimize-pose", "circle": "circle", "compensate": "compensate",
    "explain": "explain", "serve": "serve ui"}
_AREAS = list(_AREA_COMMANDS)
#: The area of each command: a console run of one command loads only its own area, so ``greybench
#: machine`` does not import torch, pandas or scipy.signal for the friction commands (seconds of
#: start-up); ``bench`` loads none (greybench_bench is imported when a benchmark is asked for).
#: ``tests/cli/test_lazy_areas.py`` checks it against what every area registers; a command missing
#: here still works (every area is loaded).
COMMAND_AREAS = {name: area for area, names in _AREA_COMMANDS.items() for name in names.split()}


def areas_for(argv: list[str]) -> list[str]:
    """The areas to load for a console run with ``argv`` (``sys.argv``): the one area of the
    command named, none for ``bench``, or every area (``--help``, an unknown command, an import as
    a library)."""
    from pathlib import Path

    if len(argv) < 2 or Path(argv[0]).name not in ("greybench", "cli.py"):
        return list(_AREAS)
    if argv[1] == "bench":
        return []
    area = COMMAND_AREAS.get(argv[1])
    return [area] if area in _AREAS else list(_AREAS)


def register_area(group: typer.Typer, area: str) -> None:
    """Add the commands of ``greybench.commands.<area>`` to ``group``; bad input exits 2 (``guarded``)."""
    for name, command in importlib.import_module(f"greybench.commands.{area}").COMMANDS.items():
        if isinstance(command, typer.Typer):
            group.add_typer(command, name=name)
        else:
            group.command(name)(guarded(command))


for _name in areas_for(sys.argv):
    register_area(app, _name)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
