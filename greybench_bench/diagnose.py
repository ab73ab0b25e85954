"""``greybench bench diagnose``: confusion matrix over generated hidden-effect cases and the diagnosis time."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from greybench.support import out, progress
from identify.diagnosis import Cause, save_diagnosis
from identify.diagnosis import diagnose as run_diagnosis
from identify.diagnosis_cases import generated_cases, run_case


def confusion_table(rows: list[tuple[str, str]]) -> Table:
    """Confusion matrix (true effect x named cause) as a rich table."""
    labels = [c.value for c in Cause]
    counts = {(t, p): 0 for t in labels for p in labels}
    for t, p in rows:
        counts[(t, p)] += 1
    table = Table(title="confusion matrix: true effect (rows) x named cause (columns)")
    table.add_column("true \\ named")
    for p in labels:
        table.add_column(p, justify="right")
    for t in labels:
        if any(counts[(t, p)] for p in labels):
            table.add_row(t, *[str(counts[(t, p)]) or "" for p in labels])
    return table


def bench_diagnose(
    cases: int = typer.Option(36, "--cases", help="Generated cases for the confusion matrix [-]."),
    duration: float = typer.Option(25.0, "--duration", help="Length of each generated record [s] (1 kHz)."),
    speed_samples: int = typer.Option(60_000, "--speed-samples", help="Samples of the timed train and test records "
                                                                      "[-]."),
    seed: int = typer.Option(0, "--seed", help="Seed of the case generator [-]."),
    heavy: int = typer.Option(0, "--heavy", help="Instead: this many cases per hidden effect and noise level of "
                                                 "the generated heavy joint (motor-current records, noise 1, 2, 3, "
                                                 "5 % of the Coulomb level; docs/heavy-joints.md) [-]."),
) -> None:
    """Confusion matrix over generated hidden-effect cases (2x..10x noise RMS) and the diagnosis time on
    60,000-sample train and test records (target <= 60 s on 2 cores); with --heavy, the confusion matrix
    over generated heavy-joint cases (right cause >= 95 %, extended model within 1.2x the noise)."""
    import tempfile

    if heavy:
        bench_heavy(heavy, duration, seed)
        return

    from greybench.support import DATA_DIR
    from identify.axis_limits import load_axis_limits
    from identify.plant import synthesize
    from identify.records import validate_frame
    from identify.trajectories import test_trajectory, universal_trajectory

    limits = load_axis_limits(DATA_DIR / "robots" / "max100.toml", 1)
    tr, te = universal_trajectory(limits, duration=duration), test_trajectory(limits, duration=duration)
    rows, gains, ext_rmse = [], [], []
    with progress(f"diagnosing {cases} generated cases", total=cases) as advance:
        for effect, ratio, s_tr, s_te in generated_cases(cases, seed):
            res, _ = run_case(effect, ratio, s_tr, s_te, tr, te)
            rows.append((effect, res.cause.value))
            if effect != "none":
                gains.append(res.gain)
                ext_rmse.append(res.extended_test.rmse)
            advance(1)
    out.print(confusion_table(rows))
    effect_rows = [(t, p) for t, p in rows if t != "none"]
    clean_rows = [(t, p) for t, p in rows if t == "none"]
    right = sum(t == p for t, p in effect_rows)
    clean_ok = sum(p == "none" for _, p in clean_rows)

    # speed: 60k-sample train and test records
    d = speed_samples / 1000.0
    tr60, te60 = universal_trajectory(limits, duration=d), test_trajectory(limits, duration=d)
    a = validate_frame(synthesize(tr60.t, tr60.q, tr60.qd, tr60.qdd, seed=1, effect="load", magnitude=0.3).frame, "t60")
    b = validate_frame(synthesize(te60.t, te60.q, te60.qd, te60.qdd, seed=2, effect="load", magnitude=0.3).frame, "e60")
    with progress("timing diagnose on the long records"):
        t0 = time.perf_counter()
        res = run_diagnosis(a, b)
        t_diag = time.perf_counter() - t0
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            save_diagnosis(res, a, b, Path(tmp) / "out", track=False)
            t_save = time.perf_counter() - t0
            # a throwaway MLflow store: the bench must not write runs into the user's store
            import os

            old_uri = os.environ.get("MLFLOW_TRACKING_URI")
            os.environ["MLFLOW_TRACKING_URI"] = f"sqlite:///{Path(tmp) / 'mlruns.db'}"
            try:
                t0 = time.perf_counter()
                save_diagnosis(res, a, b, Path(tmp) / "out2", track=True, experiment="bench-diagnose")
                t_track = time.perf_counter() - t0
            finally:
                if old_uri is None:
                    os.environ.pop("MLFLOW_TRACKING_URI", None)
                else:
                    os.environ["MLFLOW_TRACKING_URI"] = old_uri
    table = Table(title=f"bench diagnose: {cases} cases of {duration:.0f} s records, one run")
    for col in ("item", "measured", "target", "note"):
        table.add_column(col)
    table.add_row("right cause named (hidden effect)", f"{right}/{len(effect_rows)} = "
                  f"{100 * right / max(len(effect_rows), 1):.1f} "
                  "%", ">= 95 %", "identifiable effect RMS 2x..10x the 0.02 Nm noise")
    table.add_row("clean records give none", f"{clean_ok}/{len(clean_rows)} = "
                  f"{100 * clean_ok / max(len(clean_rows), 1):.1f} %", ">= 95 %", "")
    if gains:
        table.add_row("test RMSE gain of the extension", f"median {100 * np.median(gains):.1f} %, "
                      f"min {100 * np.min(gains):.1f} %", "honest", "relative to the LuGre baseline")
        table.add_row("extended model test RMSE", f"median {np.median(ext_rmse):.4f} Nm, max {np.max(ext_rmse):.4f} Nm",
                      "near 0.02 Nm", "noise level 0.02 Nm")
    timing = ", ".join(f"{k} {v:.1f} s" for k, v in res.timings.items())
    table.add_row(f"diagnose, {a.n} + {b.n} samples", f"{t_diag:.1f} s", "<= 60 s (2 cores)", timing)
    table.add_row("  + report, plots, models written", f"{t_save:.1f} s", "", f"cause named: {res.cause.value}")
    table.add_row("  + MLflow logging of both "
                  "runs", f"{t_track - t_save:.1f} s", "", "identify.tracking (pyfunc models)")
    out.print(table)


#: Record length of the heavy-joint cases [s] (1 kHz), as in the diagnosis tests.
HEAVY_DURATION = 10.0


def heavy_table(outcomes) -> Table:
    """Per noise level: right cause named, and the extended model's held-out RMSE over the noise."""
    table = Table(title="heavy joints: right cause named and extended RMSE / noise RMS, per noise level")
    for col in ("noise [% of Coulomb]", "right cause", "extended / noise: median", "max", "target"):
        table.add_column(col, justify="right")
    for share in sorted({o.case.noise_share for o in outcomes}):
        rows = [o for o in outcomes if o.case.noise_share == share]
        ratio = [o.extended_over_noise for o in rows]
        table.add_row(f"{100 * share:g}", f"{sum(o.right for o in rows)}/{len(rows)}", f"{np.median(ratio):.3f}",
                      f"{np.max(ratio):.3f}", ">= 95 %, <= 1.2")
    return table


def bench_heavy(per_cell: int, duration: float, seed: int) -> None:
    """``bench diagnose --heavy``: the confusion matrix over generated heavy-joint cases."""
    from greybench.support import DATA_DIR
    from identify.diagnosis_cases import heavy_trajectories, run_heavy_case
    from identify.heavy_joint import heavy_cases

    tr, te = heavy_trajectories(DATA_DIR / "robots" / "max100.toml", min(duration, HEAVY_DURATION))
    cases = heavy_cases(per_cell, seed=seed)
    outcomes = []
    with progress(f"diagnosing {len(cases)} heavy-joint cases", total=len(cases)) as advance:
        for case in cases:
            outcomes.append(run_heavy_case(case, tr, te))
            advance(1)
    out.print(confusion_table([(o.case.effect, o.named) for o in outcomes]))
    out.print(heavy_table(outcomes))
    right = sum(o.right for o in outcomes)
    out.print(f"right cause named in {right}/{len(outcomes)} = {100 * right / len(outcomes):.1f} % of the cases "
              f"(goal >= 95 %); extended / noise at most {max(o.extended_over_noise for o in outcomes):.3f} "
              "(goal <= 1.2)", highlight=False)
