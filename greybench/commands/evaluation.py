"""Evaluation commands: ``rank-poses``, ``trace`` (paper 3.8, 4, Table 2); the simulation is imported when run."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from greybench import options as o
from greybench.support import emit_json, err, out, print_table, progress, show

if TYPE_CHECKING:
    from simulate.evaluation.ranking import Ranking


def print_ranking(r: Ranking, out_dir: Path | None = None) -> None:
    from simulate.run import ranking_tables
    for table in ranking_tables(r):
        print_table(*table)
    if out_dir is not None:
        out.print(f"report: {out_dir / 'report.md'}")


def rank_poses_cmd(
    program: o.Program,
    poses: o.Poses,
    robot: o.Robot = "max100",
    out_dir: Annotated[Path | None, typer.Option("--out", help="Output folder: report.md, images/, per pose scan.csv "
                                                               "[m] and workpiece.npz.")] = None,
    spacing: Annotated[float, typer.Option("--spacing", help="Dexel spacing [mm] (coarser grids make the cutting "
                                                             "force, hence the deflection, jumpy).")]
    = o.RANKING_SPACING_MM,
    probe_spacing: o.ProbeSpacing = o.PROBE_SPACING_MM,
    stiffness_scale: o.StiffnessScale = 1.0,
    shares: Annotated[bool, typer.Option("--shares/--no-shares", help="Re-run each pose with deflection, friction "
                                                                      "and switching off in turn (4x the time).")]
    = False,
    ideal: Annotated[bool, typer.Option("--ideal", help="Ideal robot: no deflection and no tracking error.")] = False,
    size: Annotated[int, typer.Option("--size", help="Test piece size [mm]: 160 or 320.")] = 320,
    workers: o.Workers = 2,
    friction: o.Friction = None,
    ff_friction: o.FfFriction = False,
    backlash_comp: o.BacklashComp = False,
    setup: o.Setup = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object: ranking (score [-]) and feature "
                                                         "rows (nominal_mm, tolerance_mm, deviation_mm per "
                                                         "pose).")] = False,
) -> None:
    """Simulate the program in every pose, measure the virtual parts (ISO 10791-7 features) and rank the poses."""
    from greybench.api import RankOptions, rank_placements

    res = rank_placements(program, poses, out_dir, progress=progress, options=RankOptions(
        robot=robot, spacing_mm=spacing, probe_spacing_mm=probe_spacing, stiffness_scale=stiffness_scale, shares=shares,
        ideal=ideal, size=size, workers=workers, friction=o.friction_refs(friction), ff_friction=ff_friction,
        backlash_comp=backlash_comp, setup=setup))
    show(as_json, res.to_dict(), lambda: print_ranking(res.ranking, out_dir))


def trace_cmd(
    workpiece: Annotated[Path, typer.Option("--workpiece", help="Pose folder written by rank-poses (workpiece.npz) "
                                                                "or the .npz itself.")],
    point: Annotated[str, typer.Option("--point", help="Point x,y,z [mm], workpiece frame.")],
    radius: Annotated[float, typer.Option("--radius", help="Search radius around the point [mm].")] = 1.5,
    program: Annotated[Path | None, typer.Option("--program", help="G-code program to show line texts (default: "
                                                                   "the one recorded in meta.json).")] = None,
    as_json: o.Json = False,
) -> None:
    """Time stamps and program lines that machined the surface near a point (paper 3.8)."""
    from simulate.run import MM, trace_json, trace_table, trace_workpiece

    xyz = o.numbers(point, 3, "point", "mm")
    tr = trace_workpiece(workpiece, [v * MM for v in xyz], radius * MM, program)
    if as_json:
        emit_json(trace_json(tr, xyz, radius))
        return
    print_table(*trace_table(tr, point, radius))
    if not tr.lines:
        err.print("no machined surface near that point (stock surface or empty space)")


COMMANDS = {"rank-poses": rank_poses_cmd, "trace": trace_cmd}
