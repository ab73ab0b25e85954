"""Friction diagnosis commands: ``greybench diagnose``."""
from __future__ import annotations

from pathlib import Path

import typer
from rich.markup import escape
from rich.table import Table

from greybench.support import emit_json, guarded, out, progress
from identify.diagnosis import SCORE_THRESHOLD, save_diagnosis
from identify.diagnosis import diagnose as run_diagnosis
from identify.errors import InputError
from identify.records import derivative_note, load_record, record_params


def diagnose(
    train: Path = typer.Option(..., "--train", help="Training axis record (.csv/.parquet; t [s], q [rad], tau [Nm], "
                                                      "optional qd [rad/s], qdd [rad/s^2], temp [degC], tau_load "
                                                      "[Nm])."),
    test: Path = typer.Option(..., "--test", help="Held-out axis record of the same joint (same columns, SI units)."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder: the extended model (params.json), baseline/, "
                                                    "report.md with PNG plots, diagnosis.json."),
    seed: int = typer.Option(0, "--seed", help="Seed of the baseline's genetic algorithm [-]."),
    generations: int = typer.Option(30, "--generations", help="GA generations of the LuGre baseline [-]."),
    threshold: float = typer.Option(SCORE_THRESHOLD, "--threshold",
                                    help="Held-out RMS torque a cause must explain to be named, as a share of the "
                                         "held-out residual's noise RMS [-] (scale-free: the same for a record in "
                                         "other units)."),
    track: bool = typer.Option(True, "--track/--no-track", help="Log both models as runs of the MLflow experiment "
                                                                "'diagnose' (gain [-] as a metric)."),
    cutoff: float | None = typer.Option(None, "--cutoff", help="Derivative cut-off [Hz] for records without "
                                                                   "qd/qdd (default: chosen from the training "
                                                                   "record's sampling rate and position spectrum)."),
    linear: bool = typer.Option(False, "--linear", help="A linear axis: q [m], qd [m/s], tau [N] (also declared by "
                                                        "record headers such as 'q [m]', 'tau [N]')."),
    as_json: bool = typer.Option(False, "--json", help='Print {"cause", "ranking", "baseline", "extended", "gain"} '
                                                       "(RMSE and scores in Nm, gain relative) as one JSON object."),
) -> None:
    """Name what the LuGre model gets wrong (load, temperature, position, asymmetry, inertia, drift, gravity or none)
    by held-out nested-model tests, extend the model with the named causes, refit and report the test
    RMSE gain [-]."""
    if generations < 1:
        raise InputError("must be >= 1", field="--generations")
    if not threshold >= 0:
        raise InputError("must be >= 0", field="--threshold")
    train_rec = load_record(train, linear=True if linear else None, cutoff_hz=cutoff)
    test_rec = load_record(test, linear=train_rec.linear, cutoff_hz=cutoff or train_rec.cutoff_hz)
    if (train_rec.tau_rb is None) != (test_rec.tau_rb is None):
        raise InputError("both records need a 'tau_rb' column, or neither", source=str(test), field="tau_rb")
    with progress("diagnosing (baseline fit, held-out tests, extended refit)", total=None):
        result = run_diagnosis(train_rec, test_rec, seed=seed, generations=generations, threshold=threshold)
        saved = save_diagnosis(result, train_rec, test_rec, out_dir, track=track,
                               extra_params=record_params(train_rec))
    if as_json:
        emit_json(result.to_json())  # the diagnosis JSON contract; the cut-off is in MLflow
        return
    out.print(derivative_note(train_rec), highlight=False)
    a = result.analysis
    mu = f"m{a.unit}"
    table = Table(title=f"diagnosis: {result.cause.value} (threshold {a.threshold * 1e3:.3g} {mu} held-out RMS = "
                        f"{threshold:g} x noise RMS {a.noise * 1e3:.3g} {mu})")
    for col in ("cause", escape(f"score [{mu}]"), escape(f"alone [{mu}]"), "named"):
        table.add_column(col, justify="left" if col == "cause" else "right")
    for s in result.analysis.ranking:
        table.add_row(s.cause.value, f"{s.score * 1e3:+.2f}", f"{s.alone * 1e3:+.2f}", "yes" if s.selected else "no")
    out.print(table)
    out.print(f"baseline {result.baseline.name}: test RMSE {result.baseline_test.rmse:.5g} {a.unit}; "
              f"extended {result.extended_label}: test RMSE {result.extended_test.rmse:.5g} {a.unit}; "
              f"gain {result.gain * 100:+.1f} %\nreport: {saved.report}")


def register(app: typer.Typer) -> None:
    app.command("diagnose")(guarded(diagnose))
