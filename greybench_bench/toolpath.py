"""``greybench bench toolpath``: interpolation and inverse kinematics throughput on the test-piece program."""
from __future__ import annotations

import time
from typing import Any

import numpy as np
import typer
from rich.table import Table

from greybench.support import DATA_DIR, emit_json, out, resolve_robot
from identify.errors import InputError
from simulate.toolpath.interpolation import interpolate
from simulate.toolpath.placement import joint_trajectory, load_poses
from simulate.toolpath.testpiece import finishing_program, iso_test_piece


def bench_toolpath(
    size: int = typer.Option(320, "--size", help="Test piece size [mm] whose finishing program is timed."),
    repeat: int = typer.Option(3, "--repeat", help="Timed runs; the best is reported."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Interpolation and inverse kinematics throughput [points/s] on the test-piece program (target >= 1e6)."""
    from simulate.robot.model import load_robot
    from simulate.toolpath.gcode import parse_program

    if repeat < 1:
        raise InputError("must be >= 1", field="repeat")
    prog = parse_program(finishing_program(iso_test_piece(size)), source=f"testpiece{size}.nc")
    rob = load_robot(resolve_robot("max100"))
    placement = load_poses(DATA_DIR / "poses" / f"iso{size}.json")[0]
    ip = interpolate(prog)
    joint_trajectory(rob, ip, placement)  # warm-up: numba compile / cache load
    t_int, t_ik = np.inf, np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        ip = interpolate(prog)
        t1 = time.perf_counter()
        joint_trajectory(rob, ip, placement)
        t2 = time.perf_counter()
        t_int, t_ik = min(t_int, t1 - t0), min(t_ik, t2 - t1)
    n = len(ip)
    rows = {"interpolation": t_int, "inverse kinematics + qd + switching": t_ik, "together": t_int + t_ik}
    res: dict[str, Any] = {name: {"seconds": s, "points_per_s": n / s, "us_per_point": s / n * 1e6}
                           for name, s in rows.items()}
    res["points"] = n
    res["segments"] = len(prog.segments)
    res["target_points_per_s"] = 1e6
    res["ratio_together_to_target"] = n / (t_int + t_ik) / 1e6
    if as_json:
        emit_json(res)
        return
    table = Table(title=f"toolpath bench: test piece {size}, {n} points at 2 ms, {len(prog.segments)} segments "
                        f"(best of {repeat})")
    for col in ("part", "time \\[s]", "points/s", "us/point", "x target 1e6/s"):
        table.add_column(col, justify="left" if col == "part" else "right")
    for name, s in rows.items():
        table.add_row(name, f"{s:.4f}", f"{n / s:,.0f}", f"{s / n * 1e6:.3f}", f"{n / s / 1e6:.2f}")
    out.print(table)
