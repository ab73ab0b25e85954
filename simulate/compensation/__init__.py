"""Pre-compensation of a program from the machining simulation (mirror compensation, iterated).

The tool tip the coupled loop predicts is the command plus the robot's deflection plus the servo
tracking error (friction, backlash), per 2 ms interpolation cycle in the workpiece frame
(:class:`simulate.pipeline.MachiningOutcome`). Mirror compensation moves the command against the
predicted deviation from the nominal path,

    x_cmd(k+1) = x_cmd(k) - (x_sim(k) - x_des),

and repeats until the ISO 10791-7 (Table-2) deviations stop improving (Reinl et al., IEEE/ASME AIM
2011; Carriere et al., Int. J. Adv. Manuf. Technol. 110:2361-2375, 2020; ``docs/compensation.md``).

One concept per module; where the method is vague, each module's docstring states the choice made
(so it can be replaced):

- :mod:`~simulate.compensation.settings`: the settings, the correction's grid and its contract;
- :mod:`~simulate.compensation.path`: the nominal path and the correction along it;
- :mod:`~simulate.compensation.program`: the corrected program written as G-code pieces;
- :mod:`~simulate.compensation.measure`: simulating a program, its normal deviation from the path;
- :mod:`~simulate.compensation.update`: the update rules (secant step, curvature limit, corners,
  ramp-in, keeping the feed);
- :mod:`~simulate.compensation.iterate`: the iteration and the choice of the best program;
- :mod:`~simulate.compensation.report`: the output files (program, stock, tables, report, figure);
- :mod:`~simulate.compensation.job`: a compensation as one job (``greybench compensate``'s work,
  the service's jobs), its progress.

The names below are imported from their modules when first asked for, so importing the package
alone loads no simulation.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from simulate.compensation.iterate import compensate
    from simulate.compensation.job import compensation_job, progress_total, run_compensation
    from simulate.compensation.measure import pipeline_simulator
    from simulate.compensation.settings import CompensationSettings

#: Public name -> module of this package that holds it.
_EXPORTS = {"CompensationSettings": "settings", "compensate": "iterate", "pipeline_simulator": "measure",
            "compensation_job": "job", "progress_total": "job", "run_compensation": "job"}

__all__ = ["CompensationSettings", "compensate", "compensation_job", "pipeline_simulator", "progress_total",
           "run_compensation"]


def __getattr__(name: str) -> Any:
    """The exported name from its module, looked up anew each time (not cached here), so that a name
    replaced in its module (a test's monkeypatch) is the one the package gives."""
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
