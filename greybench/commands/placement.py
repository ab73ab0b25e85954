"""Placement command: ``optimize-pose`` (search the workpiece pose the machining simulation scores best)."""
from __future__ import annotations

import json
import os
from pathlib import Path

import typer

from greybench.support import check_cost, emit_json, guarded, out, print_summary, progress, resolve_robot
from identify.errors import InputError
from simulate import defaults as DEFAULTS

MM = 1e-3


def optimize_pose_cmd(
    program: Path = typer.Option(..., "--program", help="G-code program; its stock <stem>.stock.json must sit next "
                                                        "to it."),
    robot: str = typer.Option("max100", "--robot", help="Robot name in data/robots or a robot TOML path."),
    poses: Path = typer.Option(..., "--poses", help="Pose file (JSON) [m, rad]: the baseline, and where the search "
                                                    "box lies."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder: best.json, report.md, heatmap.png, history.csv, "
                                                    "summary.json."),
    budget_s: float = typer.Option(..., "--budget-s", help="Wall time for all simulations [s], the given poses' "
                                                           "included."),
    workers: int = typer.Option(2, "--workers", help="Simulations at once [-] (processes; Ray tasks when "
                                                     "RAY_ADDRESS is set)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the sampler [-]."),
    spacing: float = typer.Option(DEFAULTS.RANKING_DEXEL_SPACING / MM, "--spacing", help="Dexel spacing [mm] (the "
                                                                                          "ranking's)."),
    size: int | None = typer.Option(None, "--size", help="Test piece size [mm]: 160 or 320 (default: the stock's "
                                                            "size_mm)."),
    xy_margin: float = typer.Option(400.0, "--xy-margin-mm", help="Search box half-width around the given poses, "
                                                                  "x and y [mm]."),
    z_margin: float = typer.Option(100.0, "--z-margin-mm", help="Search box half-height around the given poses [mm]."),
    max_simulations: int | None = typer.Option(None, "--max-simulations", help="Stop after this many simulated "
                                                                                  "candidates [-]."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object: best pose [m, rad], its score, every "
                                                       "given pose's score, the improvement [-]."),
) -> None:
    """Search x, y, z and yaw of the workpiece for the lowest rank-poses score, within a time budget."""
    from identify.errors import read_json
    from simulate.evaluation.ranking import RankSettings
    from simulate.placement.report import write_outputs
    from simulate.placement.search import SearchSettings, plan_search, run_search
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import parse_poses

    if not program.exists():
        raise InputError("program not found", source=str(program))
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("output must be a folder", source=str(out_dir), field="out")
    robot_path = resolve_robot(robot)
    load_robot(robot_path)
    doc = read_json(poses, missing="pose file not found")
    placements = parse_poses(doc, source=str(poses))
    if size is None:
        stock = read_json(program.with_name(program.stem + ".stock.json"),
                          missing="stock description not found next to the program")
        size = stock.get("size_mm") if isinstance(stock, dict) else None
        if size not in (160, 320):
            raise InputError("the stock names no test-piece size_mm: give --size 160 or 320", field="size")
    settings = SearchSettings(budget_s=budget_s, workers=workers, seed=seed,
                              rank=RankSettings(spacing=spacing * MM, size=int(size)), max_simulations=max_simulations,
                              xy_margin=xy_margin * MM, z_margin=z_margin * MM)
    check_cost(program, None, spacing, simulations=1)
    plan = plan_search(program, robot_path, placements, settings, poses_source=str(poses))  # every check first
    with progress("placement search", total=round(budget_s), enabled=True) as advance:
        done = [0]

        def report(elapsed: float, text: str) -> None:
            step = int(min(elapsed, budget_s)) - done[0]   # whole seconds of the budget
            if step > 0:
                advance(step)
                done[0] += step
            advance.describe(text)

        result = run_search(plan, progress=report, ray_address=os.environ.get("RAY_ADDRESS") or None)
        advance.describe("writing the report and the heat map")
        info = write_outputs(result, out_dir, given_doc=doc, robot=plan.robot, interp=plan.program.interp,
                             program=str(program), robot_name=robot, poses=str(poses), size=int(size))
    if as_json:
        from simulate.placement.report import finite

        emit_json(finite(info))
        return
    b = info["best"]
    print_summary("placement search", {
        "best pose": f"{b['name']} ({b['origin']})",
        "best xyz \\[mm]": ", ".join(f"{v / MM:.1f}" for v in b["xyz_m"]),
        "best yaw \\[deg]": f"{b['rpy_rad'][2] * 180 / 3.141592653589793:.1f}",
        "best score \\[-]": b["score"],
        **{f"given {g['name']} score \\[-]": g["score"] for g in info["given"]},
        "improvement \\[%]": 100 * info["improvement"],
        "candidates": json.dumps(info["candidates"]),
        "stopped": info["stop_reason"],
        "wall time \\[s]": info["wall_time_s"],
    })
    out.print(f"report: {out_dir / 'report.md'}; check: greybench rank-poses --program {program} --robot {robot} "
              f"--poses {out_dir / 'best.json'} --size {size} --spacing {spacing:g}")


def register(app: typer.Typer) -> None:
    app.command("optimize-pose")(guarded(optimize_pose_cmd))
