"""The ``greybench`` console script: one typer app composing identify, simulate and service.

Each area registers its commands from its own module in :mod:`greybench.commands`;
``greybench bench ...`` holds the benchmarks.
"""
from __future__ import annotations

import importlib

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
for _name in _AREAS:
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
