"""``greybench circle``: the virtual circular test (ISO 230-4, ballbar) of the robot at a pose."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import typer

from greybench.support import emit_json, err, guarded, out, progress, print_summary, resolve_robot
from identify.errors import InputError


def _centre(text: Optional[str]):
    if text is None:
        return (0.0, 0.0, 0.0)
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise InputError(f"expected three numbers x,y,z in mm, got {text!r}", field="center-mm")
    return tuple(v * 1e-3 for v in vals)


def circle(
    robot: str = typer.Option("max100", "--robot", help="Robot name in data/robots or a robot TOML path."),
    pose: Path = typer.Option(..., "--pose", help="Pose file (JSON) [m, rad]."),
    name: Optional[str] = typer.Option(None, "--name", help="Pose name in the file (default: the first)."),
    radius_mm: float = typer.Option(50.0, "--radius-mm", help="Circle radius [mm]."),
    feed_mm_min: float = typer.Option(2000.0, "--feed-mm-min", help="Feed along the circle [mm/min]."),
    plane: str = typer.Option("xy", "--plane", help="Plane of the workpiece frame: xy, yz or zx."),
    center_mm: Optional[str] = typer.Option(None, "--center-mm",
                                            help="Centre x,y,z in the workpiece frame [mm] (default: its origin)."),
    cw: bool = typer.Option(False, "--cw", help="Clockwise about the plane normal (G2); default counter-clockwise."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder (circle.csv, circle.png, summary.json)."),
    no_friction: bool = typer.Option(False, "--no-friction", help="Switch off joint friction."),
    no_backlash: bool = typer.Option(False, "--no-backlash", help="Switch off the gear play."),
    friction_scale: float = typer.Option(1.0, "--friction-scale",
                                         help="Factor on every joint's Coulomb and static friction levels [-]."),
    ff_friction: bool = typer.Option(False, "--ff-friction", help="NC friction feed-forward on (off: the NC does not know the friction)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Simulate a circle through the machining pipeline (drives, friction models, no cutting) and
    evaluate it as a ballbar test.

    Writes circle.csv (angle_deg, radial_deviation_um, q1_rad..q6_rad), circle.png (polar plot,
    deviation magnified, reversal spikes marked with the joint) and summary.json, prints roundness_um,
    radius_error_um and reversal_spikes (angle [deg], joint, height [µm]).
    """
    from simulate.evaluation.circle import CircleSpec, evaluate_run, simulate_circle, write_outputs
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import load_poses, select_pose

    spec = CircleSpec(radius=radius_mm * 1e-3, feed=feed_mm_min / 6e4, plane=plane.lower(),
                      center=_centre(center_mm), ccw=not cw)
    placement = select_pose(load_poses(pose), name, source=str(pose))
    rob = load_robot(resolve_robot(robot))
    with progress("circle: simulating", total=None) as advance:
        run = simulate_circle(rob, placement, spec, friction=not no_friction, backlash=not no_backlash,
                              friction_scale=friction_scale, ff_friction=ff_friction, advance=advance)
        result = evaluate_run(run)
    # everything is computed: only now write
    title = (f"{rob.name}, pose {placement.name}" + (", no friction" if no_friction else "")
             + (", no backlash" if no_backlash else "") + (f", friction x{friction_scale:g}" if friction_scale != 1 else ""))
    summary = write_outputs(result, out_dir, title=title, info={
        "robot": rob.name, "pose": placement.name, "radius_mm": radius_mm, "feed_mm_min": feed_mm_min,
        "plane": spec.plane.value, "friction": not no_friction, "backlash": not no_backlash,
        "friction_scale": friction_scale, "friction_models": run.friction})
    csv, png = summary["csv"], summary["png"]
    if as_json:
        emit_json(summary)
        return
    print_summary("circle", {"roundness_um": result.roundness_um, "radius_error_um": result.radius_error_um,
                             "largest_spike_um": result.largest_spike_um, "csv": str(csv), "png": str(png)})
    from rich.table import Table

    table = Table(title="reversal spikes")
    for col in ("angle [deg]", "joint", "height [µm]"):
        table.add_column(col, justify="right")
    for s in result.spikes:
        table.add_row(f"{s.angle_deg:.1f}", s.name, f"{s.height_um:+.1f}")
    out.print(table)
    if not result.spikes:
        err.print("no joint reverses along this circle")


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


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    app.command("circle")(guarded(circle))
    bench_app.command("circle")(guarded(bench_circle))
