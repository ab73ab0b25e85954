"""Placement command: ``optimize-pose`` (search the workpiece pose the machining simulation scores best)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from greybench import options as o
from greybench.support import out, print_summary, progress, resolve_robot, show
from simulate.run import optimize_placement


def optimize_pose_cmd(
    program: o.Program,
    poses: Annotated[Path, typer.Option("--poses", help="Pose file (JSON) [m, rad]: the baseline, and where the "
                                                        "search box lies.")],
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder: best.json, report.md, heatmap.png, "
                                                        "history.csv, summary.json.")],
    budget_s: Annotated[float, typer.Option("--budget-s", help="Wall time for all simulations [s], the given "
                                                               "poses' included.")],
    robot: o.Robot = "max100",
    workers: o.Workers = 2,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the sampler [-].")] = 0,
    spacing: o.Spacing = o.RANKING_SPACING_MM,
    size: o.Size = None,
    xy_margin: Annotated[float, typer.Option("--xy-margin-mm", help="Search box half-width around the given poses, "
                                                                    "x and y [mm].")] = 400.0,
    z_margin: Annotated[float, typer.Option("--z-margin-mm", help="Search box half-height around the given poses "
                                                                  "[mm].")] = 100.0,
    max_simulations: Annotated[int | None, typer.Option("--max-simulations", help="Stop after this many simulated "
                                                                                  "candidates [-].")] = None,
    setup: o.Setup = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object: best pose [m, rad], its score, every "
                                                         "given pose's score, the improvement [-].")] = False,
) -> None:
    """Search x, y, z and yaw of the workpiece for the lowest rank-poses score, within a time budget."""
    res = optimize_placement(program, resolve_robot(robot), poses, out_dir, budget_s=budget_s, workers=workers,
                             seed=seed, spacing_mm=spacing, size=size, xy_margin_mm=xy_margin, z_margin_mm=z_margin,
                             max_simulations=max_simulations, robot_name=robot, progress=progress,
                             setup=setup)
    show(as_json, res.info, lambda: print_summary("placement search", res.summary()), lambda: out.print(
              f"report: {out_dir / 'report.md'}; check: greybench rank-poses --program {program} --robot {robot} "
              f"--poses {out_dir / 'best.json'} --size {res.size} --spacing {spacing:g}"
              + (f" --setup {setup}" if setup is not None else "")))


COMMANDS = {"optimize-pose": optimize_pose_cmd}
