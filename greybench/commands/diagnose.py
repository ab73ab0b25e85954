"""Friction diagnosis commands: ``greybench diagnose`` and ``greybench bench diagnose``."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.markup import escape
from rich.table import Table

from greybench.commands.friction import derivative_note, record_params
from greybench.support import emit_json, guarded, out, progress
from identify.diagnosis import CANDIDATES, SCORE_THRESHOLD, Cause, diagnose as run_diagnosis, save_diagnosis
from identify.errors import InputError
from identify.records import load_record


def diagnose(
    train: Path = typer.Option(..., "--train", help="Training axis record (.csv/.parquet; t [s], q [rad], tau [Nm], "
                                                      "optional qd [rad/s], qdd [rad/s^2], temp [degC], tau_load [Nm])."),
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
    cutoff: Optional[float] = typer.Option(None, "--cutoff", help="Derivative cut-off [Hz] for records without "
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


# ---- generated cases (bench and tests) -------------------------------------------------
def effect_rms(effect: str, t, q, qd, qdd, seed: int, magnitude: float = 1.0, identifiable: bool = True) -> float:
    """RMS torque [Nm] the hidden ``effect`` adds at ``magnitude``.

    Same seed, same noise: the difference of the records with and without the effect is
    exactly the effect's torque. With ``identifiable`` (the default used for the generated
    cases), the part that the baseline's own parameters absorb is removed first -- the
    least-squares projection on the plant's dry friction, ``qd``, ``qdd`` and a constant, i.e.
    what refitting the friction levels, viscous coefficient, inertia and offset soaks up. A
    temperature effect on a record that stays at one temperature only changes the levels
    and is no error of a model fitted there; the identifiable RMS is what a model *must*
    get wrong without the effect.
    """
    from identify.plant import PlantConfig, synthesize

    a = synthesize(t, q, qd, qdd, seed=seed)
    b = synthesize(t, q, qd, qdd, seed=seed, effect=effect, magnitude=magnitude)
    d = b.frame["tau"].to_numpy() - a.frame["tau"].to_numpy()
    if identifiable:
        qd_s = a.frame["qd"].to_numpy()
        dry = a.friction - PlantConfig().nu * qd_s
        X = np.column_stack([dry, qd_s, a.frame["qdd"].to_numpy(), np.ones(d.size)])
        beta, *_ = np.linalg.lstsq(X, d, rcond=None)
        d = d - X @ beta
    return float(np.sqrt(np.mean(d ** 2)))


def magnitude_for(effect: str, ratio: float, t, q, qd, qdd, seed: int, noise: float = 0.02) -> float:
    """Plant ``magnitude`` at which the effect's identifiable RMS (:func:`effect_rms`) is ``ratio``
    times the noise RMS [-] (a few secant steps: the temperature effect is not linear in it)."""
    target = ratio * noise
    m = target / max(effect_rms(effect, t, q, qd, qdd, seed), 1e-12)
    for _ in range(3):
        r = effect_rms(effect, t, q, qd, qdd, seed, m)
        if abs(r - target) < 0.02 * target:
            break
        m *= target / max(r, 1e-12)
    return float(m)


def generated_cases(n_cases: int, seed: int = 0, ratios=(2.0, 3.0, 5.0, 10.0), clean_share: float = 0.25):
    """Seeded cases ``(effect, ratio, train_seed, test_seed)``.

    A share ``clean_share`` of the cases is clean (``none``); the rest cycle through the six
    effects so each appears about equally often, in a seeded random order, each at a ratio
    (identifiable effect RMS / noise RMS, :func:`effect_rms`) drawn from ``ratios``.
    """
    rng = np.random.default_rng(seed)
    from identify.plant import Effect

    effects = [c.value for c in CANDIDATES if c.value in {e.value for e in Effect}]  # what the plant can hide
    n_clean = int(round(clean_share * n_cases))
    kinds = ["none"] * n_clean + [effects[i % len(effects)] for i in range(n_cases - n_clean)]
    kinds = [kinds[i] for i in rng.permutation(len(kinds))]
    cases = []
    for i, effect in enumerate(kinds):
        ratio = 0.0 if effect == "none" else float(rng.choice(ratios))
        cases.append((effect, ratio, 1000 + i, 5000 + i))
    return cases


def run_case(effect: str, ratio: float, train_seed: int, test_seed: int, train_traj, test_traj, generations: int = 15):
    """Synthesise a train/test pair with a hidden effect and diagnose it blind; returns the result."""
    from identify.plant import synthesize
    from identify.records import validate_frame

    mag = 0.0 if effect == "none" else magnitude_for(effect, ratio, train_traj.t, train_traj.q, train_traj.qd,
                                                     train_traj.qdd, train_seed)
    recs = []
    for traj, s, name in ((train_traj, train_seed, "train"), (test_traj, test_seed, "test")):
        frame = synthesize(traj.t, traj.q, traj.qd, traj.qdd, seed=s, effect=effect, magnitude=mag).frame
        recs.append(validate_frame(frame, f"{name}-{effect}-{s}"))
    return run_diagnosis(recs[0], recs[1], generations=generations), mag


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
    speed_samples: int = typer.Option(60_000, "--speed-samples", help="Samples of the timed train and test records [-]."),
    seed: int = typer.Option(0, "--seed", help="Seed of the case generator [-]."),
) -> None:
    """Confusion matrix over generated hidden-effect cases (2x..10x noise RMS) and the diagnosis time on
    60,000-sample train and test records (target <= 60 s on 2 cores)."""
    import tempfile

    from identify.axis_limits import load_axis_limits
    from identify.plant import synthesize
    from identify.records import validate_frame
    from identify.trajectories import test_trajectory, universal_trajectory

    from greybench.support import DATA_DIR

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
                  f"{100 * right / max(len(effect_rows), 1):.1f} %", ">= 95 %", "identifiable effect RMS 2x..10x the 0.02 Nm noise")
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
    table.add_row("  + MLflow logging of both runs", f"{t_track - t_save:.1f} s", "", "identify.tracking (pyfunc models)")
    out.print(table)


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    app.command("diagnose")(guarded(diagnose))
    bench_app.command("diagnose")(guarded(bench_diagnose))
