"""``greybench circle``: the virtual circular test (ISO 230-4, ballbar) of the robot at a pose."""
from __future__ import annotations

from pathlib import Path

import typer

from greybench import options as o
from greybench.support import emit_json, err, print_summary, print_table, progress


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
    from greybench.api import CircleOptions, circle_test
    from simulate.run import circle_rows, spike_table

    centre = o.numbers(center_mm, 3, "center-mm", "mm") if center_mm is not None else (0.0, 0.0, 0.0)
    res = circle_test(pose, out_dir, progress=progress, options=CircleOptions(
        robot=robot, name=name, radius_mm=radius_mm, feed_mm_min=feed_mm_min, plane=plane, center_mm=centre, cw=cw,
        friction=not no_friction, backlash=not no_backlash, friction_scale=friction_scale, ff_friction=ff_friction))
    result, summary = res.result, res.summary
    if as_json:
        emit_json(summary)
        return
    print_summary("circle", circle_rows(result, summary))
    print_table(*spike_table(result))
    if not result.spikes:
        err.print("no joint reverses along this circle")


COMMANDS = {"circle": circle}
