"""Toolpath commands: ``testpiece``, ``interpolate`` (paper 3.1, 3.2, 3.7)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import typer
from rich.table import Table

from greybench.support import emit_json, guarded, out, print_summary, progress, resolve_robot
from identify.errors import InputError
from identify.records import write_table
from simulate.toolpath.gcode import read_program
from simulate.toolpath.interpolation import PathLimits, interpolate
from simulate.toolpath.placement import JointTrajectory, joint_trajectory, load_poses, select_pose
from simulate.toolpath.testpiece import Technology, iso_test_piece, write_test_piece


def trajectory_frame(jt: JointTrajectory) -> pd.DataFrame:
    """Columns t, line, x, y, z (workpiece, m), q1..q6 (rad), qd1..qd6 (rad/s), switch."""
    cols = {"t": jt.t, "line": jt.line, "x": jt.xyz[:, 0], "y": jt.xyz[:, 1], "z": jt.xyz[:, 2]}
    for i in range(6):
        cols[f"q{i + 1}"] = jt.q[:, i]
    for i in range(6):
        cols[f"qd{i + 1}"] = jt.qd[:, i]
    cols["switch"] = jt.switch
    return pd.DataFrame(cols)


def testpiece(
    size: int = typer.Option(320, "--size", help="Test piece size [mm]: 160 or 320."),
    out_file: Path = typer.Option(..., "--out", help="G-code output (.nc); the stock goes to <stem>.stock.json."),
    tool_diameter: float = typer.Option(10.0, "--tool-diameter", help="Flat end mill diameter [mm]."),
    allowance: float = typer.Option(0.5, "--allowance", help="Finishing allowance on the stock walls [mm]."),
    feed: float = typer.Option(2000.0, "--feed", help="Cutting feed [mm/min]."),
    spindle: float = typer.Option(12000.0, "--spindle", help="Spindle speed [rev/min]."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object with the written files."),
) -> None:
    """Write the finishing program of the ISO 10791-7 style test piece and its semi-finished stock."""
    tech = Technology(tool_diameter=tool_diameter * 1e-3, allowance=allowance * 1e-3, feed=feed, spindle=spindle)
    prog, stock = write_test_piece(out_file, size=size, tech=tech)
    piece = iso_test_piece(size)
    info = {"program": str(prog), "stock": str(stock), "size_mm": size, "tool_diameter_mm": tool_diameter,
            "allowance_mm": allowance, "lines": len(prog.read_text().splitlines())}
    if as_json:
        emit_json(info)
        return
    table = Table(title=f"test piece {size}")
    table.add_column("item")
    table.add_column("value", justify="right")
    table.add_row("program", str(prog))
    table.add_row("stock", str(stock))
    table.add_row("circle diameter [mm]", f"{piece.circle_diameter * 1e3:g}")
    table.add_row("square side [mm]", f"{piece.square_side * 1e3:g}")
    table.add_row("slope [deg]", f"{np.degrees(piece.slope_angle):g}")
    out.print(table)


def interpolate_cmd(
    program: Path = typer.Option(..., "--program", help="G-code program (lengths in mm or inch as programmed)."),
    robot: str = typer.Option("max100", "--robot", help="Robot name in data/robots or a robot TOML path."),
    pose: Path = typer.Option(..., "--pose", help="Pose file (JSON): workpiece frame in the robot base frame [m, "
                                                  "rad]."),
    name: str | None = typer.Option(None, "--name", help="Pose name in the file (default: the first)."),
    out_file: Path = typer.Option(..., "--out", help="Output .csv or .parquet: t [s], line, x y z [m], q1..q6 [rad], "
                                                     "qd1..qd6 [rad/s], switch."),
    acceleration: float = typer.Option(2.0, "--acceleration", help="Path acceleration limit A [m/s^2]."),
    jerk: float = typer.Option(50.0, "--jerk", help="Path jerk limit J [m/s^3]."),
    rapid_speed: float = typer.Option(0.25, "--rapid-speed", help="Speed of G0 moves [m/s]."),
    cycle: float = typer.Option(2.0, "--cycle", help="Interpolation cycle [ms]."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object with the summary."),
) -> None:
    """Interpolate a program at the NC cycle (jerk-limited, look-ahead), transform to joint angles and
    velocities of the robot for one placement, and mark axis stops/reversals (paper 3.1, 3.2, 3.7)."""
    from simulate.robot.model import load_robot

    if out_file.suffix.lower() not in (".csv", ".parquet"):
        raise InputError("output must end in .csv or .parquet", source=str(out_file))
    limits = PathLimits(acceleration=acceleration, jerk=jerk, rapid_speed=rapid_speed, cycle=cycle * 1e-3)
    limits.validate()
    with progress("interpolate", total=4) as advance:
        advance.describe("reading the program")
        prog = read_program(program)
        placements = load_poses(pose)
        placement = select_pose(placements, name, source=str(pose))
        rob = load_robot(resolve_robot(robot))
        advance(1)
        advance.describe("interpolating")
        ip = interpolate(prog, limits)
        advance(1)
        advance.describe("inverse kinematics")
        jt = joint_trajectory(rob, ip, placement, source=str(program))
        advance(1)
        advance.describe(f"writing {out_file}")
        write_table(trajectory_frame(jt), out_file)
        advance(1)
    summary = {"out": str(out_file), "pose": placement.name, "samples": len(ip), "duration_s": ip.duration,
               "path_length_m": prog.length, "max_speed_m_s": float(ip.v.max()),
               "switching_steps": int((jt.switch > 0).sum()),
               "switching_per_axis": [int(((jt.switch >> i) & 1).sum()) for i in range(6)]}
    if as_json:
        emit_json(summary)
        return
    print_summary(f"{program.name} on {rob.name}, pose {placement.name}", summary)


def register(app: typer.Typer) -> None:
    app.command("testpiece")(guarded(testpiece))
    app.command("interpolate")(guarded(interpolate_cmd))
