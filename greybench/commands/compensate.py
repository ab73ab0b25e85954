"""``greybench compensate`` and ``greybench bench compensate``: pre-compensate a program from the
machining simulation (:mod:`simulate.compensation`, outputs :mod:`simulate.compensation_report`)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import List, Optional

import typer
from rich.table import Table

from greybench.support import DATA_DIR, emit_json, out, progress, resolve_robot
from identify.errors import InputError
from simulate import defaults as DEFAULTS


def _friction(specs: list[str]) -> dict:
    """``AXIS=REF`` options -> {axis: model reference}."""
    fr = {}
    for s in specs or []:
        axis, sep, ref = s.partition("=")
        if not sep or not axis.strip().isdigit() or not 1 <= int(axis) <= 6 or not ref.strip():
            raise InputError(f"expected AXIS=MODEL with AXIS 1..6, got '{s}'", field="friction")
        if int(axis) in fr:
            raise InputError(f"axis {axis} given twice", field="friction")
        fr[int(axis)] = ref.strip()
    return fr


def compensation_job(program: Path, robot: str, pose: Path, name: Optional[str], *, spacing_mm: float,
                     probe_spacing_mm: float, size: Optional[int], friction: dict):
    """The loaded program, the :class:`simulate.pipeline.MachiningJob` (ranking settings: trimmed stock,
    Table-2 rows scored, spindle speed required, exactly as ``rank-poses`` simulates) and the placement."""
    from simulate.evaluation.ranking import RankSettings
    from simulate.pipeline import MachiningJob, load_program, piece_size
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import load_poses, select_pose

    if not program.exists():
        raise InputError("program not found", source=str(program))
    placement = select_pose(load_poses(pose), name, source=str(pose))
    rob = load_robot(resolve_robot(robot))
    setup = load_program(program, require_spindle=True)
    sz = piece_size(setup, size)
    rs = RankSettings(spacing=spacing_mm * 1e-3, probe_spacing=probe_spacing_mm * 1e-3, size=sz or 0)
    settings = rs.machining()
    if sz is None:
        from dataclasses import replace

        settings = replace(settings, size=0, features=False)
    settings.validate()
    job = MachiningJob(program=setup, robot=rob, placement=placement, friction=friction, settings=settings)
    return setup, job, placement, rob


def run_compensation(program: Path, robot: str, pose: Path, name: Optional[str], out_dir: Path, *,
                     iterations: int = 4, stiffness_scale: float = 1.0, check_scales=(), gain: float = 1.0,
                     spacing_mm: float = DEFAULTS.RANKING_DEXEL_SPACING * 1e3,
                     probe_spacing_mm: float = DEFAULTS.PROBE_SPACING * 1e3, size: Optional[int] = None,
                     friction: Optional[dict] = None, show_progress: bool = True) -> dict:
    """Compensate, evaluate and write every output (the command's work; the service calls it too).

    ``stiffness_scale`` [-]: the robot the *evaluation* simulates is that much stiffer than the model
    the compensation iterates with (both programs); ``check_scales`` add more such evaluations.
    Returns the summary (:func:`simulate.compensation_report.summary`) with the files.
    """
    from simulate.compensation import CompensationSettings, compensate, pipeline_simulator
    from simulate.compensation_report import write_outputs

    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("output path exists and is not a folder", source=str(out_dir), field="out")
    for v, opt in [(stiffness_scale, "stiffness-scale")] + [(c, "check-scale") for c in check_scales]:
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and v == v and 0 < v < float("inf")):
            raise InputError(f"must be > 0, got {v!r}", field=opt)
    cs = CompensationSettings(iterations=iterations, gain=gain)
    cs.validate()
    setup, job, placement, rob = compensation_job(program, robot, pose, name, spacing_mm=spacing_mm,
                                                  probe_spacing_mm=probe_spacing_mm, size=size,
                                                  friction=friction or {})
    scales = sorted({float(stiffness_scale), *map(float, check_scales)} - {1.0})
    n_steps = len(setup.interp.t)
    total = n_steps * (iterations + 1 + 2 * len(scales))
    with progress("compensating", total=total, enabled=show_progress) as adv:
        sim = pipeline_simulator(job, advance=adv)
        res = compensate(setup, sim, cs, checks=scales, require_spindle=True,
                         header=f"compensated by greybench for robot {rob.name or robot}, pose {placement.name}")
    title = f"{program.name}, robot {rob.name or robot}, pose {placement.name}"
    return write_outputs(res, out_dir, robot=rob, placement=placement, components=job.components,
                         substeps=job.settings.substeps, title=title, scale=float(stiffness_scale))


def print_info(info: dict) -> None:
    ev = info.get("evaluation")
    if ev is not None:
        t = Table(title=f"Table-2 deviations [µm] before / after compensation (robot stiffness x{ev['stiffness_scale']:g})")
        for c in ("row", "tol", "before", "after"):
            t.add_column(c, justify="left" if c == "row" else "right")
        for r in ev["rows_mm"]:
            t.add_row(r["name"], f"{r['tolerance'] * 1e3:.0f}", f"{r['before'] * 1e3:+.1f}", f"{r['after'] * 1e3:+.1f}")
        t.add_row("sum |deviation|", "", f"{ev['sum_before_mm'] * 1e3:.1f}", f"{ev['sum_after_mm'] * 1e3:.1f}")
        out.print(t)
        out.print(f"ratio after/before: {ev['ratio']:.3f}; rows worse than max(10 %, 2 µm): "
                  f"{', '.join(ev['rows_worse']) or 'none'}")
    for c in info.get("checks", []):
        if c is not None:
            out.print(f"stiffness x{c['stiffness_scale']:g}: sum {c['sum_before_mm'] * 1e3:.1f} -> "
                      f"{c['sum_after_mm'] * 1e3:.1f} µm, ratio {c['ratio']:.3f}")
    out.print(f"best iteration {info['best_iteration']}; largest offset {info['max_offset_mm'] * 1e3:.1f} µm; "
              f"time ratio {info['time_ratio']:.3f}; peak speed ratio {info['speed_ratio']:.3f}")
    for f in info.get("files", []):
        if f.endswith("report.md"):
            out.print(f"report: {f}")


def compensate_cmd(
    program: Path = typer.Option(..., "--program", help="G-code program; its stock <stem>.stock.json must sit "
                                                        "next to it."),
    robot: str = typer.Option("max100", "--robot", help="Robot name in data/robots or a robot TOML path."),
    pose: Path = typer.Option(..., "--pose", help="Pose file (JSON): workpiece frame in the robot base frame [m, rad]."),
    name: Optional[str] = typer.Option(None, "--name", help="Pose name in the file (default: the first)."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder: compensated.nc, compensated.stock.json, "
                                                    "offsets.csv [mm, rad], feedforward.csv [Nm], report.md, "
                                                    "deviation.png."),
    iterations: int = typer.Option(4, "--iterations", help="Largest number of corrected programs simulated [-]."),
    stiffness_scale: float = typer.Option(1.0, "--stiffness-scale",
                                          help="Joint stiffness multiplier [-] of the robot the before/after "
                                               "evaluation simulates (both programs); the compensation itself "
                                               "iterates with the robot file's model (1)."),
    check_scale: Optional[List[float]] = typer.Option(None, "--check-scale",
                                                      help="Also evaluate both programs with this stiffness "
                                                           "multiplier [-] (repeatable, e.g. 0.8 and 1.2)."),
    gain: float = typer.Option(1.0, "--gain", help="Damping of the update [-] (0 < gain <= 1.5)."),
    spacing: float = typer.Option(DEFAULTS.RANKING_DEXEL_SPACING * 1e3, "--spacing",
                                  help="Dexel spacing [mm] (the ranking's default)."),
    probe_spacing: float = typer.Option(DEFAULTS.PROBE_SPACING * 1e3, "--probe-spacing",
                                        help="Virtual CMM point distance [mm]."),
    size: Optional[int] = typer.Option(None, "--size", help="Test piece size [mm] (160 or 320; default: the "
                                                            "stock's size_mm)."),
    friction: Optional[List[str]] = typer.Option(None, "--friction",
                                                 help="AXIS=MODEL: friction model reference for a joint (saved "
                                                      "folder, runs:/, models:/), repeatable; others keep the "
                                                      "robot file's."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (deviations in mm)."),
) -> None:
    """Pre-compensate a program from the simulation: correct the commanded path against the predicted
    tool deviation (deflection, tracking error with friction and backlash) and iterate."""
    info = run_compensation(program, robot, pose, name, out_dir, iterations=iterations,
                            stiffness_scale=stiffness_scale, check_scales=tuple(check_scale or ()), gain=gain,
                            spacing_mm=spacing, probe_spacing_mm=probe_spacing, size=size,
                            friction=_friction(friction), show_progress=not as_json)
    if as_json:
        emit_json(info)
        return
    print_info(info)


def bench_compensate(
    spacing: float = typer.Option(1.0, "--spacing", help="Dexel spacing [mm]."),
    iterations: int = typer.Option(2, "--iterations", help="Corrected programs simulated [-]."),
    pose_name: str = typer.Option("near", "--pose", help="Pose of data/poses/iso160.json."),
) -> None:
    """Time per iteration and the reduction of the Table-2 sum on the 160 test piece, one pose."""
    from simulate.compensation import CompensationSettings, compensate, pipeline_simulator

    program = DATA_DIR / "programs" / "iso160.nc"
    poses = DATA_DIR / "poses" / "iso160.json"
    setup, job, placement, _ = compensation_job(program, "max100", poses, pose_name, spacing_mm=spacing,
                                                probe_spacing_mm=DEFAULTS.PROBE_SPACING * 1e3, size=160,
                                                friction={})
    rows = []
    t0 = time.perf_counter()
    with progress("compensating", total=iterations + 1) as adv:
        def seen(it):
            rows.append(it)
            adv(1)

        res = compensate(setup, pipeline_simulator(job), CompensationSettings(iterations=iterations),
                         on_iteration=seen, require_spindle=True)
    wall = time.perf_counter() - t0
    t = Table(title=f"compensate iso160, pose {placement.name}, dexel spacing {spacing:g} mm")
    for c in ("iteration", "simulation [s]", "sum |dev| [µm]", "ratio to original", "path RMS [µm]", "time ratio",
              "pieces"):
        t.add_column(c, justify="right")
    s0 = rows[0].table_sum
    for it in rows:
        t.add_row(str(it.index) + (" *" if it.index == res.best else ""), f"{it.wall_time:.1f}",
                  f"{it.table_sum * 1e6:.1f}", f"{it.table_sum / s0:.3f}", f"{it.path_rms * 1e6:.1f}",
                  f"{it.time_ratio:.3f}", str(it.pieces))
    out.print(t)
    per = sum(it.wall_time for it in rows[1:]) / max(1, len(rows) - 1)
    out.print(f"total {wall:.1f} s; {per:.1f} s per iteration (simulation of a corrected program); "
              f"{wall - sum(it.wall_time for it in rows):.1f} s writing and interpolating the programs; "
              f"reduction reached: {rows[res.best].table_sum / s0:.3f} of the original sum (* chosen)")


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    from greybench.support import guarded

    app.command("compensate")(guarded(compensate_cmd))
    bench_app.command("compensate")(guarded(bench_compensate))
