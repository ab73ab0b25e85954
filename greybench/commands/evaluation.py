"""Evaluation commands: ``rank-poses``, ``trace`` (paper 3.8, 4, Table 2)."""
from __future__ import annotations

import os
from pathlib import Path

import typer
from rich.table import Table

from greybench.support import check_cost, emit_json, err, guarded, out, progress, resolve_robot
from identify.errors import InputError
from simulate import defaults as DEFAULTS
from simulate.evaluation.features import MM
from simulate.evaluation.ranking import COMPONENTS, Components, Ranking, RankSettings, rank_poses, ranking_json

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
    program: Path = typer.Option(..., "--program", help="G-code program (mm or inch as programmed); its stock "
                                                        "<stem>.stock.json must sit next to it."),
    robot: str = typer.Option("max100", "--robot", help="Robot name in data/robots or a robot TOML path."),
    poses: Path = typer.Option(..., "--poses", help="Pose file (JSON): workpiece frame in the robot base frame "
                                                    "[m, rad]."),
    out_dir: Path | None = typer.Option(None, "--out", help="Output folder: report.md, images/, per pose "
                                                               "scan.csv [m] and workpiece.npz."),
    spacing: float = typer.Option(DEFAULTS.RANKING_DEXEL_SPACING * 1e3, "--spacing",
                                  help="Dexel spacing [mm] (coarser grids make the cutting force, hence the "
                                       "deflection, jumpy)."),
    probe_spacing: float = typer.Option(DEFAULTS.PROBE_SPACING * 1e3, "--probe-spacing",
                                        help="Virtual CMM point distance [mm]."),
    stiffness_scale: float = typer.Option(1.0, "--stiffness-scale", help="Joint stiffness multiplier [-]."),
    shares: bool = typer.Option(False, "--shares/--no-shares", help="Re-run each pose with deflection, friction "
                                                                     "and switching off in turn (4x the time)."),
    ideal: bool = typer.Option(False, "--ideal", help="Ideal robot: no deflection and no tracking error."),
    size: int = typer.Option(320, "--size", help="Test piece size [mm]: 160 or 320."),
    workers: int = typer.Option(2, "--workers", help="Parallel processes [-] (at most 2); Ray tasks instead when "
                                                     "RAY_ADDRESS is set."),
    friction: list[str] | None = typer.Option(None, "--friction",
                                                 help="AXIS=MODEL: friction model reference for a joint (saved "
                                                      "folder, runs:/, models:/<name>@<alias>), repeatable; others "
                                                      "keep the robot file's."),
    ff_friction: bool = typer.Option(False, "--ff-friction", help="The NC's friction feed-forward: each joint's "
                                     "static friction curve [Nm] at the commanded velocity added to the motor torque."),
    backlash_comp: bool = typer.Option(False, "--backlash-comp", help="The NC's backlash compensation: each drive's "
                                       "setpoint moved by half its play [rad] towards the flank the predicted gear "
                                       "torque loads."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object: ranking (score [-]) and feature "
                                                       "rows (nominal_mm, tolerance_mm, deviation_mm per pose)."),
) -> None:
    """Simulate the program in every pose, measure the virtual parts (ISO 10791-7 features) and rank the poses."""
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import load_poses

    if not program.exists():
        raise InputError("program not found", source=str(program))
    from greybench.commands.compensate import _friction as friction_refs  # the one AXIS=MODEL parser
    from simulate.robot.friction import joint_rows

    robot_path = resolve_robot(robot)
    rob = load_robot(robot_path)  # validate before any worker starts
    refs = friction_refs(friction)
    try:
        joint_rows(rob, refs)   # every model reference resolves, for its axis, before any work
    except InputError as exc:
        raise InputError(exc.message, source=exc.source, field="--friction" if refs and exc.field and
                         exc.field.startswith("friction[") else exc.field) from None
    placements = load_poses(poses)
    # refused before anything is written: the poses, and with --shares the component re-runs, run in turn
    check_cost(program, None, spacing, simulations=len(placements) * (1 + (len(COMPONENTS) if shares else 0)))
    if out_dir is not None:
        if out_dir.exists() and not out_dir.is_dir():
            raise InputError("output must be a folder", source=str(out_dir))
        out_dir.mkdir(parents=True, exist_ok=True)
    settings = RankSettings(spacing=spacing * MM, probe_spacing=probe_spacing * MM, stiffness_scale=stiffness_scale,
                            size=size, ff_friction=ff_friction,
                            backlash_comp=backlash_comp)
    comps = Components(deflection=False, servo=False) if ideal else Components()
    n_jobs = len(placements) * (1 + (len(COMPONENTS) if shares else 0))
    with progress("simulating poses", total=n_jobs) as advance:
        r = rank_poses(program, robot_path, placements, settings=settings, components=comps, shares=shares,
                       out_dir=out_dir, workers=workers, advance=advance, friction=refs,
                       ray_address=os.environ.get("RAY_ADDRESS"))
    if out_dir is not None:
        from simulate.evaluation.report import write_report

        write_report(r, out_dir, program=program, trajectories=r.trajectories)
    if as_json:
        emit_json(ranking_json(r))
        return
    print_ranking(r)
    if out_dir is not None:
        out.print(f"report: {out_dir / 'report.md'}")


def trace_cmd(
    workpiece: Path = typer.Option(..., "--workpiece", help="Pose folder written by rank-poses (workpiece.npz) "
                                                            "or the .npz itself."),
    point: str = typer.Option(..., "--point", help="Point x,y,z [mm], workpiece frame."),
    radius: float = typer.Option(1.5, "--radius", help="Search radius around the point [mm]."),
    program: Path | None = typer.Option(None, "--program", help="G-code program to show line texts (default: "
                                                                   "the one recorded in meta.json)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object with the lines and times."),
) -> None:
    """Time stamps and program lines that machined the surface near a point (paper 3.8)."""
    import numpy as np

    from simulate.evaluation.trace import resolve_workpiece, trace_point
    from simulate.machining.virtual_workpiece import VirtualWorkpiece
    from simulate.toolpath.switching import axes_of

    parts = point.split(",")
    try:
        xyz = np.array([float(v) for v in parts], float)
    except ValueError:
        raise InputError(f"expected three numbers x,y,z in mm, got '{point}'", field="point") from None
    if xyz.shape != (3,) or not np.all(np.isfinite(xyz)):
        raise InputError(f"expected three finite numbers x,y,z in mm, got '{point}'", field="point")
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
