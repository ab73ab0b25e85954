"""Friction diagnosis commands: ``greybench diagnose`` (:func:`identify.workflows.diagnose_files`)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from greybench import options as o
from greybench.support import out, print_table, progress, show, warn
from identify.diagnosis_defaults import SCORE_THRESHOLD
from identify.workflows import DIAGNOSE_STEPS, diagnose_files


def diagnose(
    train: Annotated[Path, typer.Option("--train", help="Training axis record (.csv/.parquet; t [s], q [rad], tau "
                                                        "[Nm], optional qd [rad/s], qdd [rad/s^2], temp [degC], "
                                                        "tau_load [Nm]).")],
    test: Annotated[Path, typer.Option("--test", help="Held-out axis record of the same joint (same columns, SI "
                                                      "units).")],
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder: the extended model (params.json), baseline/, "
                                                        "report.md with PNG plots, diagnosis.json.")],
    seed: Annotated[int, typer.Option("--seed", help="Seed of the baseline's genetic algorithm [-].")] = 0,
    generations: Annotated[int, typer.Option("--generations", help="GA generations of the LuGre baseline [-].")] = 30,
    threshold: Annotated[float, typer.Option("--threshold", help="Held-out RMS torque a cause must explain to be "
                                             "named, as a share of the held-out residual's noise RMS [-] (scale-free: "
                                             "the same for a record in other units).")] = SCORE_THRESHOLD,
    track: Annotated[bool, typer.Option("--track/--no-track", help="Log both models as runs of the MLflow experiment "
                                                                   "'diagnose' (gain [-] as a metric).")] = True,
    cutoff: o.Cutoff = None,
    linear: o.Linear = False,
    as_json: Annotated[bool, typer.Option("--json", help='Print {"cause", "ranking", "baseline", "extended", "gain"} '
                                                         "(RMSE and scores in Nm, gain relative) as one JSON "
                                                         "object.")] = False,
) -> None:
    """Name what the LuGre model gets wrong (load, temperature, position, asymmetry, inertia, drift, gravity or none)
    by held-out nested-model tests, extend the model with the named causes, refit and report the test
    RMSE gain [-]."""
    from identify.records import derivative_note

    with progress("diagnose", total=len(DIAGNOSE_STEPS)) as advance:
        d = diagnose_files(train, test, out_dir, seed=seed, generations=generations, threshold=threshold, track=track,
                           linear=linear, cutoff=cutoff, advance=advance, on_warnings=warn)
    # the JSON object is the diagnosis JSON contract; the cut-off is in MLflow
    show(as_json, d.result.to_json(), lambda: out.print(derivative_note(d.train), highlight=False),
         lambda: print_table(*d.table(threshold)), lambda: out.print(d.gain_text()))


COMMANDS = {"diagnose": diagnose}
