"""Robot commands: ``robot fk``, ``robot ik``, ``prepare`` (paper 2.1, 3.2, 3.6)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from greybench import options as o
from greybench.support import guarded, out, print_summary, print_table, resolve_robot, show
from simulate.robot.model import load_robot

robot_app = typer.Typer(no_args_is_help=True, help="Robot kinematics: poses (m, unit quaternion) <-> joints (rad).")
#: The two table formats fk and ik read and write.
JOINT_TABLE = "Joint table (.csv/.parquet): q1..q6 (rad); ik adds ok, status."
POSE_TABLE = "Pose table (.csv/.parquet): x, y, z (m), qw, qx, qy, qz."


def fk_cmd(
    in_file: Annotated[Path, typer.Option("--in", help=JOINT_TABLE)],
    out_file: Annotated[Path, typer.Option("--out", help=POSE_TABLE)],
    robot: o.Robot = "max100",
    flange: Annotated[bool, typer.Option("--flange", help="Flange pose instead of the TCP pose (m).")] = False,
    as_json: o.Json = False,
) -> None:
    """Forward kinematics: joints (rad) -> TCP poses in the robot base frame (m, unit quaternion)."""
    from simulate.run import forward_table

    info = forward_table(load_robot(resolve_robot(robot)), in_file, out_file, flange=flange)
    show(as_json, info, lambda: print_summary(f"robot fk ({info['robot']})", info))


def ik_cmd(
    in_file: Annotated[Path, typer.Option("--in", help=POSE_TABLE)],
    out_file: Annotated[Path, typer.Option("--out", help=JOINT_TABLE)],
    robot: o.Robot = "max100",
    q_start: Annotated[str | None, typer.Option("--q-start", help="Start configuration 'q1,..,q6' (rad); default: "
                                                                  "mid of the limits for axes 2, 3, 5 (0 for 1, 4, "
                                                                  "6).")] = None,
    independent: Annotated[bool, typer.Option("--independent", help="Each pose nearest --q-start (rad) (default: a "
                                                                    "continuous path).")] = False,
    as_json: o.Json = False,
) -> None:
    """Inverse kinematics (analytic, paper 3.2): TCP poses -> joints; unreachable rows get ok=false and NaN."""
    from simulate.run import inverse_table

    q0 = o.numbers(q_start, 6, "q-start", "rad") if q_start is not None else None
    info = inverse_table(load_robot(resolve_robot(robot)), in_file, out_file, q_start=q0, independent=independent)
    show(as_json, info, lambda: print_summary(f"robot ik ({info['robot']}, {info['mode']}): poses per status",
                                              info["status"]), lambda: out.print(f"wrote {out_file}"))


def prepare(
    log: o.RobotLog,
    out_dir: Annotated[Path, typer.Option("--out-dir", help="Folder for axis1..axis6 records (format of the "
                                                            "log).")],
    robot: o.Robot = "max100",
    window: Annotated[float, typer.Option("--window", help="Savitzky-Golay window for qd, qdd (s).")] = 0.021,
    as_json: o.Json = False,
) -> None:
    """Split a six-axis log into axis records with tau_rb (RNEA) and tau_load (gravity/payload), in Nm."""
    from simulate.run import prepare_records

    info, table = prepare_records(load_robot(resolve_robot(robot)), log, out_dir, window)
    show(as_json, info, lambda: print_table(*table))


robot_app.command("fk")(guarded(fk_cmd))
robot_app.command("ik")(guarded(ik_cmd))
COMMANDS = {"robot": robot_app, "prepare": prepare}
