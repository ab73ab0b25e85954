"""``greybench explain``: name what the simulation gets wrong
about a measured part, calibrate it, and measure the gain."""
from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from greybench.support import check_cost, emit_json, guarded, out, progress, resolve_robot
from identify.errors import InputError
from simulate import defaults as DEFAULTS


def explain(
    measured: Path = typer.Option(..., "--measured", help="CMM scan CSV 'feature,x,y,z' [m, workpiece frame], or the "
                                                         "feature deviation table JSON of rank-poses --json [mm]."),
    program: Path = typer.Option(..., "--program", help="G-code program (mm or inch as programmed); its stock "
                                                        "<stem>.stock.json [m] must sit next to it."),
    robot: str = typer.Option("max100", "--robot", help="Nominal robot: name in data/robots or a TOML path [SI]."),
    pose: Path = typer.Option(..., "--pose", help="Pose file (JSON) [m, rad]."),
    name: str | None = typer.Option(None, "--name", help="Pose name in the pose file (default: the first)."),
    out_dir: Path | None = typer.Option(None, "--out", help="Output folder: report.md with PNGs, the calibrated "
                                                               "robot file robot_calibrated.toml, explain.json."),
    spacing: float = typer.Option(DEFAULTS.DEXEL_SPACING * 1e3, "--spacing",
                                  help="Dexel spacing of the simulation [mm]; use the spacing the scan was simulated "
                                       "at (greybench machine: the same default): a coarser grid alone differs by "
                                       "some micrometres, which explain would try to attribute to a cause."),
    size: int | None = typer.Option(None, "--size", help="Test piece size [mm] (160 or 320; default: size_mm of "
                                                            "the stock file)."),
    max_sims: int = typer.Option(3, "--max-sims", help="Re-simulations for the calibration [-] (>= 1)."),
    as_json: bool = typer.Option(False, "--json", help='Print {"cause", "ranking", "calibrated", "rms_before", '
                                                       '"rms_after", "gain"} (SI: m, rad, Nm/rad) as one JSON object.'),
) -> None:
    """Compare the measured part with the simulation point by point and feature by feature, name the cause
    (stiffness:<axis>, backlash:<axis>, friction:<axis>, tool_radius, thermal or none), calibrate it by
    re-simulating and report the RMS before and after [m]."""
    from simulate.explain.measured import is_table, read_measured_scan
    from simulate.explain.pipeline import explain_part
    from simulate.explain.simulation import load_setup
    from simulate.robot.model import load_robot, save_robot

    if max_sims < 1:
        raise InputError("must be >= 1", field="--max-sims")
    if out_dir is not None and out_dir.exists() and not out_dir.is_dir():
        raise InputError("output path exists and is not a folder", source=str(out_dir), field="--out")
    from simulate.explain.pipeline import simulations_needed

    # refused before any work: the nominal run, the re-machined sensitivities and the calibration
    check_cost(program, None, spacing, simulations=simulations_needed(max_sims))
    rob = load_robot(resolve_robot(robot))
    setup = load_setup(program, pose, name, spacing=spacing * 1e-3, size=size)
    if is_table(measured):
        raise InputError("a feature deviation table (JSON) allows only a feature-by-feature comparison, which "
                         "cannot separate the candidate causes; give the CMM scan (scan.csv)", source=str(measured))
    meas = read_measured_scan(measured, setup.piece)
    setup.trajectory(rob)  # reachability errors before the long part
    with progress("explaining (simulate, compare, calibrate)", total=None):
        ex = explain_part(meas, rob, setup, max_sims=max_sims)
    if out_dir is not None:
        import json

        from identify.files import write_text_atomic
        from simulate.explain.report import write_report

        out_dir.mkdir(parents=True, exist_ok=True)
        save_robot(ex.calibrated_robot, out_dir / "robot_calibrated.toml")
        write_report(ex, out_dir, str(measured))
        write_text_atomic(out_dir / "explain.json", json.dumps(ex.as_json(), indent=1))
    if as_json:
        emit_json(ex.as_json())
        return
    t = Table(title=f"explain: cause {ex.cause} (score = dBIC vs no discrepancy; named above 10)")
    for c in ("cause", "score", "held-out gain \\[%]", "fitted change"):
        t.add_column(c, justify="left" if c == "cause" else "right")
    for f in ex.choice.ranking[:8]:
        t.add_row(f.cause, f"{f.score:.1f}", f"{f.heldout_gain * 100:.1f}", ", ".join(f"{v:.3g}" for v in f.theta))
    out.print(t)
    ft = Table(title="RMS measured - simulated \\[um]")
    for c in ("feature", "before", "after"):
        ft.add_column(c, justify="left" if c == "feature" else "right")
    for feature, (b, a) in ex.rms_by_feature().items():
        ft.add_row(feature, f"{b * 1e6:.2f}", f"{a * 1e6:.2f}")
    ft.add_row("all", f"{ex.rms_before * 1e6:.2f}", f"{ex.rms_after * 1e6:.2f}")
    out.print(ft)
    if ex.calibration is not None:
        cal = ex.calibration
        out.print(f"calibrated {cal.before.param}: {cal.before.value:.6g} -> {cal.after.value:.6g} {cal.before.unit}")
    out.print(f"gain (1 - rms_after/rms_before): {ex.gain * 100:.1f} %" +
              (f"; report {out_dir / 'report.md'}" if out_dir is not None else ""))


def register(app: typer.Typer) -> None:
    app.command("explain")(guarded(explain))
