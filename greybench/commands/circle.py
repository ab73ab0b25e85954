"""``greybench circle``: the virtual circular test (ISO 230-4, ballbar) of the robot at a pose."""
from __future__ import annotations

import math
from pathlib import Path

import typer

from greybench.support import emit_json, err, guarded, out, print_summary, progress, resolve_robot
from identify.errors import InputError


def _centre(text: str | None):
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
    name: str | None = typer.Option(None, "--name", help="Pose name in the file (default: the first)."),
    radius_mm: float = typer.Option(50.0, "--radius-mm", help="Circle radius [mm]."),
    feed_mm_min: float = typer.Option(2000.0, "--feed-mm-min", help="Feed along the circle [mm/min]."),
    plane: str = typer.Option("xy", "--plane", help="Plane of the workpiece frame: xy, yz or zx."),
    center_mm: str | None = typer.Option(None, "--center-mm",
                                            help="Centre x,y,z in the workpiece frame [mm] (default: its origin)."),
    cw: bool = typer.Option(False, "--cw", help="Clockwise about the plane normal (G2); default counter-clockwise."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder (circle.csv, circle.png, summary.json)."),
    no_friction: bool = typer.Option(False, "--no-friction", help="Switch off joint friction."),
    no_backlash: bool = typer.Option(False, "--no-backlash", help="Switch off the gear play."),
    friction_scale: float = typer.Option(1.0, "--friction-scale",
                                         help="Factor on every joint's Coulomb and static friction levels [-]."),
    ff_friction: bool = typer.Option(False, "--ff-friction",
                                     help="NC friction feed-forward on (off: the NC does not know the friction)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Simulate a circle through the machining pipeline (drives, friction models, no cutting) and
    evaluate it as a ballbar test.

    Writes circle.csv (angle_deg, radial_deviation_um, q1_rad..q6_rad), circle.png (polar plot,
    deviation magnified, reversal spikes marked with the joint) and summary.json, prints roundness_um,
    radius_error_um and reversal_spikes (angle [deg], joint, excursion height [µm], and as a ballbar
    analysis splits it: spike beyond the settled trace [µm], lost motion step [µm]).
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
             + (", no backlash" if no_backlash else "")
             + (f", friction x{friction_scale:g}" if friction_scale != 1 else ""))
    summary = write_outputs(result, out_dir, title=title, info={
        "robot": rob.name, "pose": placement.name, "radius_mm": radius_mm, "feed_mm_min": feed_mm_min,
        "plane": spec.plane.value, "friction": not no_friction, "backlash": not no_backlash,
        "friction_scale": friction_scale, "friction_models": run.friction})
    csv, png = summary["csv"], summary["png"]
    if as_json:
        emit_json(summary)
        return
    print_summary("circle", {"roundness_um": result.roundness_um, "radius_error_um": result.radius_error_um,
                             "largest_spike_um": result.largest_spike_um,
                             "largest_reversal_spike_um": result.largest_reversal_spike_um,
                             "largest_lost_motion_um": result.largest_lost_motion_um, "csv": str(csv), "png": str(png)})
    from rich.table import Table

    table = Table(title="reversal spikes")
    for col in ("angle [deg]", "joint", "excursion [µm]", "spike [µm]", "lost motion [µm]"):
        table.add_column(col, justify="right")
    for s in result.spikes:
        table.add_row(f"{s.angle_deg:.1f}", s.name, f"{s.height_um:+.1f}", f"{s.spike_um:+.1f}",
                      f"{s.lost_motion_um:+.1f}")
    out.print(table)
    if not result.spikes:
        err.print("no joint reverses along this circle")


def register(app: typer.Typer) -> None:
    app.command("circle")(guarded(circle))
