"""Robot commands: ``robot fk``, ``robot ik``, ``prepare`` (paper 2.1, 3.2, 3.6)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import typer
from rich.table import Table

from greybench.support import emit_json, guarded, out, print_summary, resolve_robot
from identify.errors import InputError
from simulate.robot.kinematics import IKStatus, fk, ik_nearest, ik_path
from simulate.robot.model import load_robot
from simulate.robot.prepare import prepare_log
from simulate.robot.tables import (
    JOINT_COLUMNS,
    frame_from_poses,
    numeric_columns,
    poses_from_frame,
    read_table,
    write_table,
)

robot_app = typer.Typer(no_args_is_help=True, help="Robot kinematics: poses (m, unit quaternion) <-> joints (rad).")

_EXTS = (".csv", ".parquet", ".pq")


def _check_out(path: Path) -> None:
    if path.suffix.lower() not in _EXTS:
        raise InputError("output must end in .csv or .parquet", source=str(path))
    if not path.parent.exists():
        raise InputError("output folder does not exist", source=str(path.parent))


def _parse_q(text: str, name: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise InputError(f"expected 6 comma-separated numbers [rad], got {text!r}", field=name) from None
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise InputError(f"expected 6 finite comma-separated numbers [rad], got {text!r}", field=name)
    return v


def fk_cmd(
    robot: str = typer.Option("max100", "--robot", help="Robot name (data/robots) or robot file (.toml)."),
    in_file: Path = typer.Option(..., "--in", help="Joint table (.csv/.parquet), columns q1..q6 (rad)."),
    out_file: Path = typer.Option(..., "--out", help="Pose table (.csv/.parquet): x, y, z (m), qw, qx, qy, qz."),
    flange: bool = typer.Option(False, "--flange", help="Flange pose instead of the TCP pose (m)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object summarising the run."),
) -> None:
    """Forward kinematics: joints (rad) -> TCP poses in the robot base frame (m, unit quaternion)."""
    r = load_robot(resolve_robot(robot))
    _check_out(out_file)
    df = read_table(in_file)
    q = numeric_columns(df, JOINT_COLUMNS, str(in_file))
    T = fk(r, q, tool=not flange)
    write_table(frame_from_poses(T), out_file)
    info = {"robot": r.name, "in": str(in_file), "out": str(out_file), "poses": int(len(q)),
            "frame": "flange" if flange else "tcp"}
    if as_json:
        emit_json(info)
        return
    print_summary(f"robot fk ({r.name})", info)


def ik_cmd(
    robot: str = typer.Option("max100", "--robot", help="Robot name (data/robots) or robot file (.toml)."),
    in_file: Path = typer.Option(..., "--in", help="Pose table (.csv/.parquet): x, y, z (m), qw, qx, qy, qz."),
    out_file: Path = typer.Option(..., "--out", help="Joint table (.csv/.parquet): q1..q6 (rad), ok, status."),
    q_start: str | None = typer.Option(None, "--q-start",
                                          help="Start configuration 'q1,..,q6' (rad); default: mid of the limits "
                                               "for axes 2, 3, 5 (0 for 1, 4, 6)."),
    independent: bool = typer.Option(False, "--independent",
                                     help="Each pose nearest --q-start (rad) (default: a continuous path)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object summarising the run."),
) -> None:
    """Inverse kinematics (analytic, paper 3.2): TCP poses -> joints; unreachable rows get ok=false and NaN."""
    r = load_robot(resolve_robot(robot))
    _check_out(out_file)
    df = read_table(in_file)
    T = poses_from_frame(df, str(in_file))
    if q_start is not None:
        q0 = _parse_q(q_start, "q-start")
    else:
        q0 = np.where([False, True, True, False, True, False], 0.5 * (r.lower + r.upper), 0.0)
    res = ik_nearest(r, T, q0) if independent else ik_path(r, T, q0)
    cols: dict[str, Any] = {c: res.q[:, i] for i, c in enumerate(JOINT_COLUMNS)}
    cols["ok"] = res.ok
    cols["status"] = [IKStatus(s).name for s in res.status]
    write_table(pd.DataFrame(cols), out_file)
    counts = {s.name: int(np.sum(res.status == s)) for s in IKStatus}
    info = {"robot": r.name, "in": str(in_file), "out": str(out_file), "poses": int(len(T)),
            "ok": int(res.ok.sum()), "mode": "independent" if independent else "path", "status": counts}
    if as_json:
        emit_json(info)
        return
    table = Table(title=f"robot ik ({r.name}, {info['mode']})")
    table.add_column("status")
    table.add_column("poses", justify="right")
    for k, v in counts.items():
        table.add_row(k, str(v))
    out.print(table)
    out.print(f"wrote {out_file}")


def prepare(
    robot: str = typer.Option("max100", "--robot", help="Robot name (data/robots) or robot file (.toml)."),
    log: Path = typer.Option(..., "--log", help="Six-axis log: t (s), q1..q6 (rad), tau1..tau6 (Nm), temp1..6 (degC)."),
    out_dir: Path = typer.Option(..., "--out-dir", help="Folder for axis1..axis6 records (format of the log)."),
    window: float = typer.Option(0.021, "--window", help="Savitzky-Golay window for qd, qdd (s)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object with the written files."),
) -> None:
    """Split a six-axis log into axis records with tau_rb (RNEA) and tau_load (gravity/payload), in Nm."""
    r = load_robot(resolve_robot(robot))
    if not window > 0:
        raise InputError("must be > 0 [s]", field="window")
    res = prepare_log(r, log, out_dir, window_s=window)
    info = {"robot": r.name, "log": str(log), "records": [str(p) for p in res.paths], "samples": res.n_samples,
            "dt_s": res.dt, "savgol_window_samples": res.window}
    if as_json:
        emit_json(info)
        return
    table = Table(title=f"prepare ({r.name}): {res.n_samples} samples at {res.dt * 1e3:.3g} ms")
    table.add_column("axis")
    table.add_column("record")
    for i, p in enumerate(res.paths):
        table.add_row(f"A{i + 1}", str(p))
    out.print(table)


def register(app: typer.Typer) -> None:
    robot_app.command("fk")(guarded(fk_cmd))
    robot_app.command("ik")(guarded(ik_cmd))
    app.add_typer(robot_app, name="robot")
    app.command("prepare")(guarded(prepare))
