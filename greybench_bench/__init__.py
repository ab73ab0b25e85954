"""The benchmarks behind ``greybench bench <name>``: tables with figures and ratios measured in one run.

A package of its own beside the CLI: :func:`build_app` is called only when a benchmark is asked for
(``greybench bench ...``), so the everyday commands never import the benchmark code.
"""
from __future__ import annotations

import typer

from greybench.support import guarded

HELP = "Benchmarks: tables with ratios measured in one run."


def build_app() -> typer.Typer:
    """The ``bench`` sub-app with every benchmark, in the order of the workflow."""
    from greybench_bench import (
        circle,
        compensate,
        diagnose,
        explain,
        friction,
        machining,
        ranking,
        realdata,
        robot,
        service,
        toolpath,
    )

    app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help=HELP)
    for name, fn in (("friction", friction.bench_friction), ("realdata", realdata.bench_realdata),
                     ("diagnose", diagnose.bench_diagnose), ("robot", robot.bench_robot),
                     ("toolpath", toolpath.bench_toolpath), ("machining", machining.bench_machining),
                     ("ranking", ranking.bench_ranking), ("circle", circle.bench_circle),
                     ("compensate", compensate.bench_compensate), ("explain", explain.bench_explain),
                     ("service", service.bench_service)):
        app.command(name)(guarded(fn))
    return app
