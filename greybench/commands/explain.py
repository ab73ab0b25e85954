"""``greybench explain``: name what the simulation gets wrong
about a measured part, calibrate it, and measure the gain."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from greybench import options as o
from greybench.support import out, print_table, progress, show
from simulate.run import explanation_tables

if TYPE_CHECKING:
    from simulate.explain.pipeline import Explanation


def explain(
    measured: Annotated[Path, typer.Option("--measured", help="CMM scan CSV 'feature,x,y,z' [m, workpiece frame], or "
                                                              "the feature deviation table JSON of rank-poses --json "
                                                              "[mm].")],
    program: o.Program,
    pose: o.Pose,
    robot: Annotated[str, typer.Option("--robot", help="Nominal robot: name in data/robots or a TOML path "
                                                       "[SI].")] = "max100",
    name: o.PoseName = None,
    out_dir: Annotated[Path | None, typer.Option("--out", help="Output folder: report.md with PNGs, the calibrated "
                                                               "robot file robot_calibrated.toml, explain.json.")]
    = None,
    spacing: Annotated[float, typer.Option("--spacing", help="Dexel spacing of the simulation [mm]; use the spacing "
                                           "the scan was simulated at (greybench machine: the same default): a coarser "
                                           "grid alone differs by some micrometres, which explain would try to "
                                           "attribute to a cause.")] = o.PART_SPACING_MM,
    size: o.Size = None,
    max_sims: Annotated[int, typer.Option("--max-sims", help="Re-simulations for the calibration [-] (>= 1).")] = 3,
    as_json: Annotated[bool, typer.Option("--json", help='Print {"cause", "ranking", "calibrated", "rms_before", '
                                                         '"rms_after", "gain"} (SI: m, rad, Nm/rad) as one JSON '
                                                         'object.')] = False,
) -> None:
    """Compare the measured part with the simulation point by point and feature by feature, name the cause
    (stiffness:<axis>, backlash:<axis>, friction:<axis>, tool_radius, thermal or none), calibrate it by
    re-simulating and report the RMS before and after [m]."""
    from greybench.api import ExplainOptions, explain_part

    res = explain_part(measured, program, pose, out_dir, progress=progress, options=ExplainOptions(
        robot=robot, name=name, spacing_mm=spacing, size=size, max_sims=max_sims))
    show(as_json, res.to_dict(), lambda: print_explanation(res.explanation, out_dir))


def print_explanation(ex: Explanation, out_dir: Path | None = None) -> None:
    for table in explanation_tables(ex):
        print_table(*table)
    if ex.calibration is not None:
        cal = ex.calibration
        out.print(f"calibrated {cal.before.param}: {cal.before.value:.6g} -> {cal.after.value:.6g} {cal.before.unit}")
    out.print(f"gain (1 - rms_after/rms_before): {ex.gain * 100:.1f} %" +
              (f"; report {out_dir / 'report.md'}" if out_dir is not None else ""))


COMMANDS = {"explain": explain}
