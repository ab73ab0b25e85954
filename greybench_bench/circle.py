"""``greybench bench circle``: the two-mass drives' speed on the ballbar circle, and where the circle
command's time goes."""
from __future__ import annotations

import typer

from greybench.support import print_summary
from identify.errors import InputError


def bench_circle(
    repeats: int = typer.Option(3, "--repeats", help="Timed runs of the drives (best is reported) [-]."),
) -> None:
    """Drive model speed on the 50 mm, 2000 mm/min circle at iso320 pose1: 2 ms cycles per CPU second
    of the six two-mass drives (one thread), substeps, and where the circle command's time goes."""
    import time

    import numpy as np

    from greybench.support import DATA_DIR
    from simulate.evaluation.circle import CircleSpec, circle_program, evaluate_run, simulate_circle
    from simulate.robot.drive import command_velocity, load_torques, simulate_drive
    from simulate.robot.model import load_robot
    from simulate.toolpath.interpolation import interpolate
    from simulate.toolpath.placement import joint_trajectory, load_poses, select_pose

    if repeats < 1:
        raise InputError(f"repeats must be >= 1, got {repeats}", field="repeats")
    rob = load_robot(DATA_DIR / "robots" / "max100.toml")
    placement = select_pose(load_poses(DATA_DIR / "poses" / "iso320.json"), "pose1")
    spec = CircleSpec(radius=0.05, feed=2000 / 6e4)
    simulate_circle(rob, placement, spec)      # compile or load the caches
    c0 = time.process_time()
    jt = joint_trajectory(rob, interpolate(circle_program(spec)), placement, source="<circle>")
    c1 = time.process_time()
    v = command_velocity(jt.t, jt.q)
    tl, jl = load_torques(rob, jt.q, v, command_velocity(jt.t, v))
    c2 = time.process_time()
    best = np.inf
    for _ in range(repeats):
        c = time.process_time()
        res = simulate_drive(rob, jt.t, jt.q, tau_load=tl, link_inertia=jl)
        best = min(best, time.process_time() - c)
    c3 = time.process_time()
    run = simulate_circle(rob, placement, spec)
    c4 = time.process_time()
    evaluate_run(run)
    c5 = time.process_time()
    from rich.markup import escape

    n = len(jt.t)
    print_summary("bench circle (CPU time, one thread)", {escape(k): v for k, v in {
        "cycles [-]": n, "substeps per 2 ms cycle, A1-A6 [-]": "/".join(str(k) for k in res.substeps),
        "drive cycles per CPU second [1/s]": n / best, "drive per cycle [µs]": best / n * 1e6,
        "interpolation + IK [s]": c1 - c0, "load torques (Newton-Euler) [s]": c2 - c1,
        "whole simulation [s]": c4 - c3, "evaluation [s]": c5 - c4}.items()})
