"""``greybench compensate``: pre-compensate a program from the
machining simulation (:mod:`simulate.compensation`, outputs :mod:`simulate.compensation_report`)."""
from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from greybench.support import emit_json, out, progress, resolve_robot
from identify.errors import InputError
from simulate import defaults as DEFAULTS


def _friction(specs: list[str] | None) -> dict:
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


def print_info(info: dict) -> None:
    ev = info.get("evaluation")
    if ev is not None:
        t = Table(title="Table-2 deviations [µm] before / after compensation "
                        f"(robot stiffness x{ev['stiffness_scale']:g})")
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
    pose: Path = typer.Option(..., "--pose",
                              help="Pose file (JSON): workpiece frame in the robot base frame [m, rad]."),
    name: str | None = typer.Option(None, "--name", help="Pose name in the file (default: the first)."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder: compensated.nc, compensated.stock.json, "
                                                    "offsets.csv [mm, rad], feedforward.csv [Nm], report.md, "
                                                    "deviation.png."),
    iterations: int = typer.Option(4, "--iterations", help="Largest number of corrected programs simulated [-]."),
    stiffness_scale: float = typer.Option(1.0, "--stiffness-scale",
                                          help="Joint stiffness multiplier [-] of the robot the before/after "
                                               "evaluation simulates (both programs); the compensation itself "
                                               "iterates with the robot file's model (1)."),
    check_scale: list[float] | None = typer.Option(None, "--check-scale",
                                                      help="Also evaluate both programs with this stiffness "
                                                           "multiplier [-] (repeatable, e.g. 0.8 and 1.2)."),
    gain: float = typer.Option(1.0, "--gain", help="Damping of the update [-] (0 < gain <= 1.5)."),
    spacing: float = typer.Option(DEFAULTS.RANKING_DEXEL_SPACING * 1e3, "--spacing",
                                  help="Dexel spacing [mm] (the ranking's default)."),
    probe_spacing: float = typer.Option(DEFAULTS.PROBE_SPACING * 1e3, "--probe-spacing",
                                        help="Virtual CMM point distance [mm]."),
    size: int | None = typer.Option(None, "--size", help="Test piece size [mm] (160 or 320; default: the "
                                                            "stock's size_mm)."),
    friction: list[str] | None = typer.Option(None, "--friction",
                                                 help="AXIS=MODEL: friction model reference for a joint (saved "
                                                      "folder, runs:/, models:/), repeatable; others keep the "
                                                      "robot file's."),
    ff_friction: bool = typer.Option(False, "--ff-friction",
                                     help="Run both programs with the NC's friction feed-forward (feedforward.csv "
                                          "[Nm]: each joint's static friction curve at the commanded velocity), in "
                                          "the iteration and every evaluation; compare with rank-poses --ff-friction."),
    backlash_comp: bool = typer.Option(False, "--backlash-comp",
                                       help="Run both programs with the NC's backlash compensation: each drive's "
                                            "setpoint moved by half its play [rad] towards the flank the predicted "
                                            "gear torque loads; compare with rank-poses --backlash-comp."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (deviations in mm)."),
) -> None:
    """Pre-compensate a program from the simulation: correct the commanded path against the predicted
    tool deviation (deflection, tracking error with friction and backlash) and iterate."""
    from simulate.compensation_report import run_compensation
    from simulate.pipeline import load_program

    if not program.exists():
        raise InputError("program not found", source=str(program))
    # progress in simulated 2 ms steps: the original, the iterations, two runs per extra stiffness
    n = len(load_program(program, require_spindle=True).interp.t)
    scales = {float(stiffness_scale), *map(float, check_scale or ())} - {1.0}
    with progress("compensating", total=n * (iterations + 1 + 2 * len(scales))) as adv:
        info = run_compensation(program, resolve_robot(robot), pose, name, out_dir, iterations=iterations,
                                stiffness_scale=stiffness_scale, check_scales=tuple(check_scale or ()), gain=gain,
                                spacing_mm=spacing, probe_spacing_mm=probe_spacing, size=size,
                                friction=_friction(friction), ff_friction=ff_friction,
                                backlash_comp=backlash_comp, advance=adv)
    if as_json:
        emit_json(info)
        return
    print_info(info)


def register(app: typer.Typer) -> None:
    from greybench.support import guarded

    app.command("compensate")(guarded(compensate_cmd))
