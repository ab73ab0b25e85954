"""``trajectory``: apart from the friction commands, whose options import the models and plant (numba, scipy)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from greybench import options as o
from greybench.support import out, resolve_robot, show
from identify import workflows as wf
from identify.axis_limits import load_axis_limits


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
    from identify.records import write_table

    limits = load_axis_limits(resolve_robot(robot), axis)
    traj = wf.make_trajectory(kind, limits, duration, rate)
    write_table(traj.to_frame(), out_file)
    show(as_json, {"kind": kind, "axis": axis, "samples": int(traj.t.size), "duration": float(traj.t[-1]),
                   "peaks": traj.peaks(), "limits": limits.__dict__, "out": str(out_file)},
         lambda: out.print(f"{kind} trajectory, axis {axis}: {wf.trajectory_text(traj, limits, out_file)}"))


COMMANDS = {"trajectory": trajectory}
