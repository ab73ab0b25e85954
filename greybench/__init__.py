"""greybench: friction identification and robot machining simulation (SI units).

The Python API (:mod:`greybench.api`), importable from here; the names load when first used, so
``import greybench`` (and the ``greybench`` command's start-up) imports no simulation or model:

- :func:`fit_friction`, :func:`compare_friction`: identify a joint's friction model (MLflow runs);
- :func:`rank_placements`: rank workpiece placements by the simulated ISO 10791-7 features;
- :func:`compensate_program`: pre-compensate a program from the simulation;
- :func:`circle_test`: the virtual ballbar test at a pose;
- :func:`explain_part`: name and calibrate what the simulation gets wrong about a measured part;
- :func:`trajectory`, :func:`synthesize`: excitation trajectories and synthetic axis records;

each with its options dataclass (``FitOptions``, ``RankOptions``, ...) and result dataclass.
The command-line interface is :mod:`greybench.cli`.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from greybench.api import (
        CircleOptions,
        CircleTestResult,
        CompareOptions,
        ComparisonResult,
        CompensationOptions,
        CompensationResult,
        ExplainOptions,
        ExplanationResult,
        FitOptions,
        FitResult,
        RankingResult,
        RankOptions,
        TrajectoryResult,
        circle_test,
        compare_friction,
        compensate_program,
        explain_part,
        fit_friction,
        rank_placements,
        synthesize,
        trajectory,
    )

__all__ = ["CircleOptions", "CircleTestResult", "CompareOptions", "ComparisonResult", "CompensationOptions",
           "CompensationResult", "ExplainOptions", "ExplanationResult", "FitOptions", "FitResult", "RankOptions",
           "RankingResult", "TrajectoryResult", "circle_test", "compare_friction", "compensate_program", "explain_part",
           "fit_friction", "rank_placements", "synthesize", "trajectory"]


def __getattr__(name: str) -> Any:
    """An API name from :mod:`greybench.api`, imported on first use."""
    if name in __all__:
        import importlib

        return getattr(importlib.import_module("greybench.api"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
