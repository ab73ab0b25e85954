"""Toolpath commands: ``testpiece``, ``interpolate`` (paper 3.1, 3.2, 3.7)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from greybench import options as o
from greybench.support import print_summary, progress, resolve_robot, show


def testpiece(
    out_file: Annotated[Path, typer.Option("--out", help="G-code output (.nc); the stock goes to "
                                                         "<stem>.stock.json.")],
    size: Annotated[int, typer.Option("--size", help="Test piece size [mm]: 160 or 320.")] = 320,
    tool_diameter: Annotated[float, typer.Option("--tool-diameter", help="Flat end mill diameter [mm].")] = 10.0,
    allowance: Annotated[float, typer.Option("--allowance", help="Finishing allowance on the stock walls "
                                                                 "[mm].")] = 0.5,
    feed: Annotated[float, typer.Option("--feed", help="Cutting feed [mm/min].")] = 2000.0,
    spindle: Annotated[float, typer.Option("--spindle", help="Spindle speed [rev/min].")] = 12000.0,
    as_json: o.Json = False,
) -> None:
    """Write the finishing program of the ISO 10791-7 style test piece and its semi-finished stock."""
    from simulate.run import test_piece

    info, rows = test_piece(out_file, size, tool_diameter, allowance, feed, spindle)
    show(as_json, info, lambda: print_summary(f"test piece {size}", rows))


def interpolate_cmd(
    program: Annotated[Path, typer.Option("--program", help="G-code program (lengths in mm or inch as "
                                                            "programmed).")],
    pose: o.Pose,
    out_file: Annotated[Path, typer.Option("--out", help="Output .csv or .parquet: t [s], line, x y z [m], q1..q6 "
                                                         "[rad], qd1..qd6 [rad/s], switch.")],
    robot: o.Robot = "max100",
    name: o.PoseName = None,
    acceleration: Annotated[float, typer.Option("--acceleration", help="Path acceleration limit A [m/s^2].")] = 2.0,
    jerk: Annotated[float, typer.Option("--jerk", help="Path jerk limit J [m/s^3].")] = 50.0,
    rapid_speed: Annotated[float, typer.Option("--rapid-speed", help="Speed of G0 moves [m/s].")] = 0.25,
    cycle: Annotated[float, typer.Option("--cycle", help="Interpolation cycle [ms].")] = 2.0,
    setup: o.Setup = None,
    as_json: o.Json = False,
) -> None:
    """Interpolate a program at the NC cycle (jerk-limited, look-ahead), transform to joint angles and
    velocities of the robot for one placement, and mark axis stops/reversals (paper 3.1, 3.2, 3.7)."""
    from simulate.run import interpolate_program
    from simulate.toolpath.interpolation import PathLimits

    limits = PathLimits(acceleration=acceleration, jerk=jerk, rapid_speed=rapid_speed, cycle=cycle / o.MM_PER_M)
    res = interpolate_program(program, resolve_robot(robot), pose, name, limits, out_file, progress=progress,
                              setup=setup)
    show(as_json, res.summary, lambda: print_summary(f"{program.name} on {res.robot}, pose {res.placement.name}",
                                                     res.summary))


COMMANDS = {"testpiece": testpiece, "interpolate": interpolate_cmd}
