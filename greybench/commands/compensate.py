"""``greybench compensate``: pre-compensate a program from the
machining simulation (:mod:`simulate.compensation`, the job :mod:`simulate.compensation.job`, outputs
:mod:`simulate.compensation.report`)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from greybench import options as o
from greybench.support import out, print_table, progress, show
from simulate.compensation.settings import CompensationSettings
from simulate.run import compensation_summary


def print_info(info: dict[str, Any]) -> None:
    tables, lines = compensation_summary(info)
    for t in tables:
        print_table(*t)
    for line in lines:
        out.print(line)


def compensate_cmd(
    program: o.Program,
    pose: o.Pose,
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder: compensated.nc, compensated.stock.json, "
                                                        "offsets.csv [mm, rad], feedforward.csv [Nm], report.md, "
                                                        "deviation.png.")],
    robot: o.Robot = "max100",
    name: o.PoseName = None,
    iterations: Annotated[int, typer.Option("--iterations", help="Largest number of corrected programs simulated "
                                                                 "[-].")] = CompensationSettings.iterations,
    stiffness_scale: Annotated[float, typer.Option("--stiffness-scale", help="Joint stiffness multiplier [-] of the "
                                                   "robot the before/after evaluation simulates (both programs); the "
                                                   "compensation itself iterates with the robot file's model (1).")]
    = 1.0,
    check_scale: Annotated[list[float] | None, typer.Option("--check-scale", help="Also evaluate both programs with "
                                                            "this stiffness multiplier [-] (repeatable, e.g. 0.8 and "
                                                            "1.2).")] = None,
    gain: Annotated[float, typer.Option("--gain", help="Damping of the update [-] (0 < gain <= 1.5).")] = 1.0,
    spacing: o.Spacing = o.RANKING_SPACING_MM,
    probe_spacing: o.ProbeSpacing = o.PROBE_SPACING_MM,
    size: o.Size = None,
    friction: o.Friction = None,
    ff_friction: o.FfFriction = False,
    backlash_comp: o.BacklashComp = False,
    as_json: o.Json = False,
) -> None:
    """Pre-compensate a program from the simulation: correct the commanded path against the predicted
    tool deviation (deflection, tracking error with friction and backlash) and iterate."""
    from greybench.api import CompensationOptions, compensate_program

    res = compensate_program(program, pose, out_dir, progress=progress, options=CompensationOptions(
        robot=robot, name=name, iterations=iterations, stiffness_scale=stiffness_scale,
        check_scales=tuple(check_scale or ()), gain=gain, spacing_mm=spacing, probe_spacing_mm=probe_spacing, size=size,
        friction=o.friction_refs(friction), ff_friction=ff_friction, backlash_comp=backlash_comp))
    show(as_json, res.info, lambda: print_info(res.info))


COMMANDS = {"compensate": compensate_cmd}
