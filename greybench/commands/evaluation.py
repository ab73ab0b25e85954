"""Evaluation commands: ``rank-poses``, ``trace`` (paper 3.8, 4, Table 2)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from greybench import options as o
from greybench.support import emit_json, err, guarded, out, progress, resolve_robot
from simulate.evaluation.features import MM
from simulate.evaluation.ranking import COMPONENTS, Components, Ranking, RankSettings, ranking_json
from simulate.run import rank_program

_COLOURS = ["green", "chartreuse3", "yellow", "dark_orange", "red"]


def _colour(rank: int, n: int) -> str:
    if n <= 1:
        return _COLOURS[0]
    return _COLOURS[round(rank * (len(_COLOURS) - 1) / (n - 1))]


def print_ranking(r: Ranking) -> None:
    poses = [p.name for p in r.placements]
    n = len(poses)
    t = Table(title="Feature deviations \\[mm] (ISO 10791-7, paper Table 2); green best .. red worst per row, "
                    "bold: in tolerance")
    t.add_column("feature")
    t.add_column("nominal \\[mm]", justify="right")
    t.add_column("tolerance \\[mm]", justify="right")
    for p in poses:
        t.add_column(p, justify="right")
    for row in r.results[poses[0]].table.rows:
        devs = [r.results[p].table[row.name] for p in poses]
        order = sorted(range(n), key=lambda i: abs(devs[i].deviation))
        rank = {i: k for k, i in enumerate(order)}
        cells = []
        for i, d in enumerate(devs):
            style = _colour(rank[i], n) + (" bold" if d.in_tolerance else "")
            cells.append(f"[{style}]{d.deviation / MM:+.4f}[/]")
        t.add_row(row.name, row.nominal_text(), f"{row.tolerance / MM:.3f}", *cells)
    out.print(t)
    rt = Table(title="Pose ranking (score = sum |deviation|/tolerance, lower is better)")
    for c in ("rank", "pose", "score", "in tolerance"):
        rt.add_column(c, justify="right" if c != "pose" else "left")
    for e in r.entries:
        rt.add_row(str(e.rank), f"[{_colour(e.rank - 1, n)}]{e.pose}[/]", f"{e.score:.2f}", f"{e.in_tolerance}/10")
    out.print(rt)
    if r.variants:
        st = Table(title="Component share of the score (re-run with the component switched off)")
        st.add_column("pose")
        for c in COMPONENTS:
            st.add_column(c, justify="right")
        for p in poses:
            sh = r.shares(p).get("score", {})
            st.add_row(p, *[f"{100 * sh.get(c, 0.0):.0f}%" for c in COMPONENTS])
        out.print(st)


def rank_poses_cmd(
    program: o.Program = ...,
    robot: o.Robot = "max100",
    poses: o.Poses = ...,
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
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object: ranking (score [-]) and feature "
                                                         "rows (nominal_mm, tolerance_mm, deviation_mm per "
                                                         "pose).")] = False,
) -> None:
    """Simulate the program in every pose, measure the virtual parts (ISO 10791-7 features) and rank the poses."""
    settings = RankSettings(spacing=spacing * MM, probe_spacing=probe_spacing * MM, stiffness_scale=stiffness_scale,
                            size=size)
    comps = Components(deflection=False, servo=False) if ideal else Components()
    r = rank_program(program, resolve_robot(robot), poses, settings=settings, components=comps, shares=shares,
                     out_dir=out_dir, workers=workers, friction=o.friction_refs(friction), progress=progress)
    if as_json:
        emit_json(ranking_json(r))
        return
    print_ranking(r)
    if out_dir is not None:
        out.print(f"report: {out_dir / 'report.md'}")


def trace_cmd(
    workpiece: Annotated[Path, typer.Option("--workpiece", help="Pose folder written by rank-poses (workpiece.npz) "
                                                                "or the .npz itself.")],
    point: Annotated[str, typer.Option("--point", help="Point x,y,z [mm], workpiece frame.")],
    radius: Annotated[float, typer.Option("--radius", help="Search radius around the point [mm].")] = 1.5,
    program: Annotated[Path | None, typer.Option("--program", help="G-code program to show line texts (default: "
                                                                   "the one recorded in meta.json).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object with the lines and times.")] = False,
) -> None:
    """Time stamps and program lines that machined the surface near a point (paper 3.8)."""
    import numpy as np

    from simulate.evaluation.trace import resolve_workpiece, trace_point
    from simulate.machining.virtual_workpiece import VirtualWorkpiece
    from simulate.toolpath.switching import axes_of

    xyz = np.array(o.numbers(point, 3, "point", "mm"))
    f, meta = resolve_workpiece(workpiece)
    vw = VirtualWorkpiece.load(f)
    prog = str(program) if program is not None else meta.get("program")
    tr = trace_point(vw, xyz * MM, radius * MM, program=prog)
    if as_json:
        emit_json({"point_mm": xyz.tolist(), "radius_mm": radius, "n_ends": tr.n_ends,
                   "lines": [{"line": ln.line, "text": ln.text, "t_first_s": ln.t_first, "t_last_s": ln.t_last,
                              "n_ends": ln.n_ends, "max_deflection_m": ln.max_deflection,
                              "max_force_n": ln.max_force, "switching_axes": axes_of(ln.switching)}
                             for ln in tr.lines]})
        return
    t = Table(title=f"{tr.n_ends} machined dexel ends within {radius:g} mm of ({point}) mm")
    for c in ("line", "program", "t \\[s]", "ends", "max deflection \\[um]", "max force \\[N]", "switching"):
        t.add_column(c)
    for ln in tr.lines:
        t.add_row(str(ln.line), ln.text, f"{ln.t_first:.3f}..{ln.t_last:.3f}", str(ln.n_ends),
                  f"{ln.max_deflection / 1e-6:.1f}", f"{ln.max_force:.1f}",
                  ",".join(f"A{a}" for a in axes_of(ln.switching)) or "-")
    out.print(t)
    if not tr.lines:
        err.print("no machined surface near that point (stock surface or empty space)")


def register(app: typer.Typer) -> None:
    app.command("rank-poses")(guarded(rank_poses_cmd))
    app.command("trace")(guarded(trace_cmd))
