"""``trajectory``: apart from the friction commands, whose options import the models and plant (numba, scipy)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from greybench import options as o
from greybench.support import out, show
from identify import workflows as wf


def trajectory(
    kind: Annotated[Literal["universal", "test", "stribeck", "presliding"], typer.Argument(
        help="universal | test (Universal Trajectory and its test variant), stribeck (constant-velocity steps) | "
             "presliding (slow motion).")],
    out_file: Annotated[Path, typer.Option("--out", help="Output table, .csv or .parquet: t [s], q [rad], qd [rad/s], "
                                                         "qdd [rad/s^2].")],
    axis: Annotated[int, typer.Option("--axis", help="Joint number 1..6 whose limits apply.")] = 1,
    robot: o.Robot = "max100",
    duration: Annotated[float, typer.Option("--duration", help="Duration [s] (universal, test, presliding).")] = 60.0,
    rate: Annotated[float, typer.Option("--rate", help="Sampling rate [Hz].")] = 1000.0,
    as_json: o.Json = False,
) -> None:
    """Generate an excitation trajectory within the axis's position, velocity [rad/s],
    acceleration [rad/s^2] and jerk [rad/s^3] limits from the robot file."""
    from greybench.api import trajectory as make_trajectory

    res = make_trajectory(kind, out_file, axis=axis, robot=robot, duration_s=duration, rate_hz=rate)
    text = wf.trajectory_text(res.trajectory, res.limits, out_file)
    show(as_json, res.to_dict(kind, axis), lambda: out.print(f"{kind} trajectory, axis {axis}: {text}"))


COMMANDS = {"trajectory": trajectory}
