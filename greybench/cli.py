"""The ``greybench`` console script: one typer app composing identify, simulate and service.

Each area registers its commands from its own module in :mod:`greybench.commands`;
``greybench bench ...`` holds the benchmarks, loaded from :mod:`greybench_bench` only when asked for.
"""
from __future__ import annotations

import importlib

# Before torch or numba load: their thread pools sized to the cores this process may use
# (affinity, cgroup quota, GREYBENCH_CORES), waiting threads sleeping, so a fit beside a busy
# neighbour is slowed by sharing the cores, not by oversubscribed pools.
from identify.resources import configure_process

configure_process()

from typing import Any  # noqa: E402

import typer  # noqa: E402
from typer.core import TyperGroup  # noqa: E402


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

# Areas, in the order of the workflow. Each module defines register(app).
_AREAS = ["friction", "diagnose", "robot", "toolpath", "machining", "evaluation", "circle", "compensate",
          "explain", "serve"]
#: Areas whose module still registers a benchmark too, ``register(app, bench_app)``; greybench_bench takes it.
_WITH_BENCH = {"machining", "circle", "compensate"}
for _name in _AREAS:
    _mod = importlib.import_module(f"greybench.commands.{_name}")
    if _name in _WITH_BENCH:
        _mod.register(app, typer.Typer())
    else:
        _mod.register(app)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
