"""The ``greybench`` console script: one typer app composing identify, simulate and service.

Each area registers its commands from its own module in :mod:`greybench.commands`;
``greybench bench ...`` holds the benchmarks.
"""
from __future__ import annotations

import importlib
import sys

# Before torch or numba load: their thread pools sized to the cores this process may use
# (affinity, cgroup quota, GREYBENCH_CORES), waiting threads sleeping, so a fit beside a busy
# neighbour is slowed by sharing the cores, not by oversubscribed pools.
from identify.resources import configure_process

configure_process()

import typer  # noqa: E402

app = typer.Typer(no_args_is_help=True, pretty_exceptions_enable=False, add_completion=False, rich_markup_mode=None,
                  help="greybench: friction identification and robot machining simulation (SI units).")
bench_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help="Benchmarks: tables with ratios measured in one run.")
app.add_typer(bench_app, name="bench")

# Areas, in the order of the workflow. Each module defines register(app, bench_app).
_AREAS = ["friction", "diagnose", "robot", "toolpath", "machining", "evaluation", "placement", "circle", "compensate",
          "explain", "serve"]
#: The area of each command (``bench <name>`` for the benchmarks): a console run of one command loads
#: only its own area, so ``greybench machine`` does not import torch, pandas or scipy.signal for the
#: friction commands (seconds of start-up). ``tests/cli/test_lazy_areas.py`` checks it against what
#: every area registers; a command missing here still works (every area is loaded).
COMMAND_AREAS = {
    "trajectory": "friction", "synth": "friction", "fit": "friction", "predict": "friction", "compare": "friction",
    "train-robot": "friction", "promote": "friction", "ui": "friction", "bench friction": "friction",
    "bench realdata": "friction", "diagnose": "diagnose", "bench diagnose": "diagnose", "robot": "robot",
    "prepare": "robot", "bench robot": "robot", "testpiece": "toolpath", "interpolate": "toolpath",
    "bench toolpath": "toolpath", "machine": "machining", "bench machining": "machining",
    "rank-poses": "evaluation", "trace": "evaluation", "bench ranking": "evaluation", "circle": "circle",
    "optimize-pose": "placement", "bench circle": "circle", "compensate": "compensate", "bench compensate": "compensate", "explain": "explain",
    "bench explain": "explain", "serve": "serve", "bench service": "serve",
}


def areas_for(argv: list[str]) -> list[str]:
    """The areas to load for a console run with ``argv`` (``sys.argv``): the one area of the
    command named, or every area (``--help``, an unknown command, an import as a library)."""
    from pathlib import Path

    if len(argv) < 2 or Path(argv[0]).name not in ("greybench", "cli.py"):
        return list(_AREAS)
    words = argv[1:3] if argv[1] == "bench" else argv[1:2]
    area = COMMAND_AREAS.get(" ".join(words))
    return [area] if area in _AREAS else list(_AREAS)


for _name in areas_for(sys.argv):
    try:
        _mod = importlib.import_module(f"greybench.commands.{_name}")
    except ModuleNotFoundError as exc:  # an area not built yet
        if exc.name != f"greybench.commands.{_name}":
            raise
        continue
    _mod.register(app, bench_app)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
