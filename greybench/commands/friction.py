"""Friction identification commands: trajectory, synth, fit, predict, compare, train-robot,
promote, ui. Fits are tracked in MLflow (:mod:`identify.tracking`)."""
from __future__ import annotations

import sys
import time
from enum import Enum
from pathlib import Path
from typing import Any

import typer
from rich.table import Table

from greybench.support import emit_json, err, guarded, out, progress, resolve_robot
from identify.axis_limits import load_axis_limits
from identify.errors import InputError
from identify.metrics import Metrics
from identify.models import MODELS, FrictionModel, make_seeded, parse_model_names
from identify.plant import Effect, PlantConfig, synthesize
from identify.records import (
    AxisRecord,
    derivative_note,
    load_axis_record,
    read_table,
    record_params,
    validate_frame,
    write_table,
)
from identify.trajectories import TRAJECTORIES


class TrajectoryKind(str, Enum):
    universal = "universal"
    test = "test"
    stribeck = "stribeck"
    presliding = "presliding"


def _metrics_table(title: str, rows: dict[str, Metrics], unit: str = "Nm") -> Table:
    table = Table(title=title)
    for col in ("record", f"RMSE [{unit}]", "R^2", "NRMSE", f"max error [{unit}]", "samples"):
        table.add_column(col, justify="right" if col != "record" else "left")
    for name, m in rows.items():
        table.add_row(name, f"{m.rmse:.4f}", f"{m.r2:.5f}", f"{m.nrmse:.4f}", f"{m.max_error:.4f}", str(m.n))
    return table


def _params_table(model: FrictionModel) -> Table:
    table = Table(title=f"{model.name} parameters")
    table.add_column("parameter")
    table.add_column("value", justify="right")
    table.add_column("unit")
    units = model.param_units()
    for k, v in model.params_.items():
        table.add_row(k, f"{v:.6g}", units.get(k, ""))
    return table


def trajectory(
    kind: TrajectoryKind = typer.Argument(..., help="universal | test (Universal Trajectory and its test variant), "
                                                     "stribeck (constant-velocity steps) | presliding (slow motion)."),
    axis: int = typer.Option(1, "--axis", help="Joint number 1..6 whose limits apply."),
    robot: str = typer.Option("max100", "--robot", help="Robot name in data/robots or a robot TOML path."),
    duration: float = typer.Option(60.0, "--duration", help="Duration [s] (universal, test, presliding)."),
    rate: float = typer.Option(1000.0, "--rate", help="Sampling rate [Hz]."),
    out_file: Path = typer.Option(..., "--out", help="Output table, .csv or .parquet: t [s], q [rad], qd [rad/s], qdd "
                                                     "[rad/s^2]."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object with the peaks."),
) -> None:
    """Generate an excitation trajectory within the axis's position, velocity [rad/s],
    acceleration [rad/s^2] and jerk [rad/s^3] limits from the robot file."""
    if duration <= 0:
        raise InputError("must be > 0", field="--duration")
    if rate <= 0:
        raise InputError("must be > 0", field="--rate")
    limits = load_axis_limits(resolve_robot(robot), axis)
    fn = TRAJECTORIES[kind.value]
    try:
        traj = fn(limits, rate=rate) if kind is TrajectoryKind.stribeck else fn(limits, duration=duration, rate=rate)
    except ValueError as exc:
        raise InputError(str(exc), field="--duration") from None
    write_table(traj.to_frame(), out_file)
    summary = {"kind": kind.value, "axis": axis, "samples": int(traj.t.size), "duration": float(traj.t[-1]),
               "peaks": traj.peaks(), "limits": limits.__dict__, "out": str(out_file)}
    if as_json:
        emit_json(summary)
    else:
        p = traj.peaks()
        out.print(f"{kind.value} trajectory, axis {axis}: {traj.t.size} samples over {traj.t[-1]:.1f} s -> {out_file}\n"
                  f"  position {p['q_min']:.4f}..{p['q_max']:.4f} rad, |qd| <= {p['qd']:.3f} rad/s "
                  f"(limit {limits.vmax:.3f}), |qdd| <= {p['qdd']:.3f} rad/s^2 (limit {limits.amax:.3f}), "
                  f"|jerk| <= {p['qddd']:.2f} rad/s^3 (limit {limits.jmax:.2f})")


def synth(
    trajectory_file: Path = typer.Option(..., "--trajectory", help="Trajectory table (t [s], q [rad], optional qd, "
                                                                   "qdd)."),
    out_file: Path = typer.Option(..., "--out", help="Output axis record, .csv or .parquet."),
    effect: Effect = typer.Option(Effect.NONE, "--effect", help="Hidden effect the plain LuGre model does not know."),
    magnitude: float = typer.Option(1.0, "--magnitude", help="Scale of the effect's strength (1 = default)."),
    seed: int = typer.Option(0, "--seed", help="Seed of noise, start temperature and load phase."),
    config: Path | None = typer.Option(None, "--config", help="Plant parameters TOML (keys of PlantConfig, SI)."),
    static_curve: str | None = typer.Option(None, "--static-curve", help="stribeck | lorentzian | hump (overrides "
                                                                         "config)."),
    noise: float | None = typer.Option(None, "--noise", help="Torque noise standard deviation [Nm] (overrides "
                                                             "config)."),
    positions_only: bool = typer.Option(False, "--positions-only", help="Write no qd/qdd (they must then be derived)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object describing the record."),
) -> None:
    """Simulate one joint (inertia, LuGre friction, sensor noise, optional hidden effect) following
    a trajectory; writes t [s], q [rad], qd [rad/s], qdd [rad/s^2], tau [Nm], temp [degC], tau_load [Nm]."""
    cfg = PlantConfig.from_toml(config) if config else PlantConfig()
    overrides: dict[str, Any] = {}
    if static_curve is not None:
        overrides["static_curve"] = static_curve
    if noise is not None:
        overrides["noise"] = noise
    if overrides:
        from dataclasses import replace
        cfg = replace(cfg, **overrides).validate("--static-curve/--noise")
    if magnitude < 0:
        raise InputError("must be >= 0", field="--magnitude")
    df = read_table(trajectory_file)
    rec = validate_frame(df.assign(tau=0.0) if "tau" not in df.columns else df, source=str(trajectory_file))
    has_d = "qd" in df.columns and "qdd" in df.columns
    res = synthesize(rec.t, rec.q, rec.qd if has_d else None, rec.qdd if has_d else None, config=cfg, effect=effect,
                     magnitude=magnitude, seed=seed, positions_only=positions_only)
    write_table(res.frame, out_file)
    summary = {"out": str(out_file), "samples": int(len(res.frame)), "effect": effect.value, "magnitude": magnitude,
               "seed": seed, "noise": cfg.noise, "static_curve": cfg.static_curve}
    if as_json:
        emit_json(summary)
    else:
        out.print(f"synthetic record ({effect.value}, magnitude {magnitude}, seed {seed}, static curve "
                  f"{cfg.static_curve}, noise {cfg.noise} Nm): {len(res.frame)} samples -> {out_file}")


#: The six models of the paper's comparison, in the order of the workflow.
COMPARE_MODELS = ("coulomb-viscous", "stribeck", "lugre", "lstm", "residual", "greybox")


def _check_axis(axis: int | None) -> None:
    if axis is not None and axis < 1:
        raise InputError(f"axis must be >= 1, got {axis}", field="--axis")


def _make(model: str, seed: int, epochs: int | None) -> FrictionModel:
    return make_seeded(model, seed, epochs, model_field="--model", epochs_field="--epochs")


def _load(path: Path, axis: int | None, **kw: Any) -> AxisRecord:
    return load_axis_record(path, axis, axis_field="--axis", **kw)


def _robot_name(robot: str) -> str:
    return Path(resolve_robot(robot)).stem


def fit(
    model: str = typer.Option(..., "--model", help=f"Model name: {', '.join(MODELS)}."),
    train: Path = typer.Option(..., "--train", help="Training axis record, or robot log (t, q1..qN, tau1..tauN) with "
                                                    "--axis (.csv/.parquet; SI: t [s], q [rad], tau [Nm], ...)."),
    test: Path | None = typer.Option(None, "--test", help="Test record (same format) for held-out metrics [Nm]."),
    out_dir: Path | None = typer.Option(None, "--out", help="Folder for the fitted model (params.json with units, "
                                                               "+ model files); the MLflow run holds it too."),
    axis: int | None = typer.Option(None, "--axis", help="Joint N >= 1 (picks q<N>, tau<N> [rad, Nm; m, N when "
                                                            "linear] from a robot log with any number of joints; "
                                                            "names the registered model). Default 1."),
    robot: str = typer.Option("max100", "--robot", help="Robot name or file; names the registered model."),
    cutoff: float | None = typer.Option(None, "--cutoff", help="Derivative cut-off [Hz] for records without "
                                                                   "qd/qdd (default: chosen from each record's "
                                                                   "sampling rate and position spectrum)."),
    linear: bool = typer.Option(False, "--linear", help="A linear axis: q [m], qd [m/s], tau [N] (also declared by "
                                                        "record headers such as 'q [m]', 'tau [N]')."),
    seed: int = typer.Option(0, "--seed", help="Random seed of the identification (GA, torch)."),
    epochs: int | None = typer.Option(None, "--epochs", help="Adam epochs [passes] for learned models (default per "
                                                             "model)."),
    experiment: str = typer.Option("friction", "--experiment", help="MLflow experiment name."),
    track: bool = typer.Option(True, "--track/--no-track", help="Record the fit as an MLflow run (default on)."),
    register: bool = typer.Option(True, "--register/--no-register", help="Register the model as "
                                                                         "<robot>-axis<N>-friction "
                                                                         "with alias challenger (greybench promote "
                                                                         "makes "
                                                                         "the champion)."),
    as_json: bool = typer.Option(False, "--json", help='Print {"model", "params", "train", "test", "run"} as one JSON '
                                                       'object.'),
) -> None:
    """Fit a friction model (co-identifying inertia J [kg m^2] and offset c [Nm] unless the
    record has tau_rb [Nm]); track it in MLflow, save it, print RMSE [Nm], R^2, NRMSE, max error [Nm]."""
    _check_axis(axis)
    est = _make(model, seed, epochs)
    train_rec = _load(train, axis, linear=True if linear else None, cutoff_hz=cutoff)
    # the test record is differentiated like the training record (the model learned on that filter)
    test_rec = (_load(test, axis, linear=train_rec.linear, cutoff_hz=cutoff or train_rec.cutoff_hz)
                if test else None)
    robot_name = _robot_name(robot)
    from simulate.coupling import coupling_warnings

    warnings = coupling_warnings(train_rec, resolve_robot(robot), axis)
    for w in warnings:
        err.print(f"[bold yellow]warning:[/] {w}", highlight=False, markup=True, soft_wrap=True)
    if not as_json:
        out.print(derivative_note(train_rec), highlight=False)
    run = None
    with progress(f"fit {model}") as advance:
        advance.describe("fitting")
        t0 = time.perf_counter()
        est.fit(train_rec)
        fit_time = time.perf_counter() - t0
        metrics = {"train": est.train_metrics_}
        if test_rec is not None:
            advance.describe("scoring the test record")
            metrics["test"] = est.score(test_rec)
        if out_dir is not None:
            est.save(out_dir)
        if track:
            from identify.tracking import log_fit, registered_name

            advance.describe("logging to MLflow (plots, residual analysis, model)")
            run = log_fit(est, train_rec, test_rec, fit_time=fit_time, experiment=experiment, axis=axis or 1,
                          robot=robot_name, register=registered_name(robot_name, axis or 1) if register else None,
                          extra_params=record_params(train_rec))
    if as_json:
        emit_json({"model": model, "params": est.params_, "units": est.param_units(), "fit_time": fit_time,
                   "n_parameters": est.n_parameters(), "warnings": warnings,
                   "derivative_cutoff_hz": train_rec.cutoff_hz, "linear": train_rec.linear,
                   "out": str(out_dir) if out_dir else None, "run": run.to_dict() if run else None,
                   **{k: v.to_dict() for k, v in metrics.items()}})
    else:
        out.print(_params_table(est))
        where = f", saved to {out_dir}" if out_dir else ""
        out.print(_metrics_table(f"{model}: fit in {fit_time:.2f} s{where}", metrics, train_rec.units["tau"]))
        if run:
            reg = f"; registered {run.registered} v{run.version} as {run.alias}" if run.registered else ""
            out.print(f"MLflow run {run.run_id} (experiment {run.experiment}): model {run.model_uri}{reg}")


def predict(
    model_ref: str = typer.Option(..., "--model", help="Saved model folder, runs:/<run_id>/model or "
                                                       "models:/<name>@<alias>."),
    data: Path = typer.Option(..., "--data", help="Axis record to predict (.csv/.parquet), or a robot log with "
                                                  "--axis."),
    out_file: Path = typer.Option(..., "--out", help="Output table: the input columns plus tau_friction_pred [Nm] "
                                                     "(the friction) and tau_pred [Nm] (the total joint torque: "
                                                     "tau_friction_pred + tau_rb when the model was fitted with "
                                                     "tau_rb, else tau_friction_pred + J*qdd + c)."),
    axis: int | None = typer.Option(None, "--axis", help="Joint N >= 1 when --data is a robot log (t, q1..qN, "
                                                         "tau1..tauN)."),
    cutoff: float | None = typer.Option(None, "--cutoff", help="Derivative cut-off [Hz] for records without qd/qdd "
                                                                   "(default: the one the model was fitted with, "
                                                                   "else chosen from the record)."),
    as_json: bool = typer.Option(False, "--json", help="Print metrics as one JSON object."),
) -> None:
    """Predict a record with a fitted model: the friction tau_friction_pred [Nm] and the total
    joint torque tau_pred [Nm], comparable to the measured tau.

    A model fitted on records with tau_rb [Nm] learned the friction tau - tau_rb, and gives
    tau_pred = tau_friction_pred + tau_rb (the record must then have tau_rb). A model fitted
    without tau_rb co-identified an inertia J [kg m^2] and an offset c [Nm]:
    tau_pred = tau_friction_pred + J*qdd + c. The metrics compare tau_pred with tau."""
    _check_axis(axis)
    from identify.tracking import load_any_model

    est = load_any_model(model_ref)
    rec = _load(data, axis, linear=getattr(est, "linear_", None) or None,
                           cutoff_hz=cutoff or getattr(est, "cutoff_hz_", None))
    if getattr(est, "linear_", False) != rec.linear:
        raise InputError(f"mixed units: the model was fitted on a {'linear' if est.linear_ else 'rotary'} axis and "
                         f"the record is {'linear' if rec.linear else 'rotary'}", source=str(data), field="q")
    friction, tau_pred = est.predict_parts(rec)
    assert rec.frame is not None  # records read from a file keep their frame
    frame = rec.frame.copy()
    frame["tau_friction_pred"] = friction
    frame["tau_pred"] = tau_pred
    write_table(frame, out_file)
    m = est.score(rec)
    if as_json:
        emit_json({"model": est.name, "out": str(out_file), "metrics": m.to_dict(),
                   "derivative_cutoff_hz": rec.cutoff_hz})
    else:
        out.print(derivative_note(rec), highlight=False)
        out.print(_metrics_table(f"{est.name} on {data} -> {out_file}", {"data": m}, rec.units["tau"]))


def compare(
    train: Path = typer.Option(..., "--train", help="Training axis record (or robot log with --axis), SI units."),
    test: Path = typer.Option(..., "--test", help="Test axis record (same format); the table is sorted by its RMSE "
                                                  "[Nm]."),
    models: str | None = typer.Option(None, "--models", help="Comma-separated models (default: "
                                                             f"{','.join(COMPARE_MODELS)})."),
    axis: int | None = typer.Option(None, "--axis", help="Joint N >= 1 (robot logs; recorded in the runs)."),
    cutoff: float | None = typer.Option(None, "--cutoff", help="Derivative cut-off [Hz] for records without qd/qdd "
                                                                   "(default: chosen from the training record)."),
    linear: bool = typer.Option(False, "--linear", help="A linear axis: q [m], tau [N]."),
    robot: str = typer.Option("max100", "--robot", help="Robot name or file (recorded in the runs)."),
    seed: int = typer.Option(0, "--seed", help="Random seed of every fit."),
    epochs: int | None = typer.Option(None, "--epochs", help="Adam epochs [passes] for the learned models (default per "
                                                             "model)."),
    experiment: str = typer.Option("compare", "--experiment", help="MLflow experiment holding the runs."),
    track: bool = typer.Option(True, "--track/--no-track", help="Record every fit as an MLflow run (default on)."),
    as_json: bool = typer.Option(False, "--json", help='Print {"rows": [...]} sorted by test RMSE as one JSON object.'),
) -> None:
    """Fit several friction models on one record and rank them by test RMSE [Nm], with R^2,
    fit time [s] and parameter count; every fit is a run of one MLflow experiment."""
    _check_axis(axis)
    names = parse_model_names(models, COMPARE_MODELS, "--models")
    train_rec = _load(train, axis, linear=True if linear else None, cutoff_hz=cutoff)
    test_rec = _load(test, axis, linear=train_rec.linear, cutoff_hz=cutoff or train_rec.cutoff_hz)
    robot_name = _robot_name(robot)
    from identify.tracking import compare_models

    models_ = [_make(name, seed, epochs) for name in names]  # unknown names and bad --epochs fail first
    with progress("compare", total=len(names) + (1 if track else 0)) as advance:
        rows, parent = compare_models(models_, train_rec, test_rec, track=track, experiment=experiment,
                                      axis=axis or 1, robot=robot_name, advance=advance,
                                      params={"train_file": str(train), "test_file": str(test)})
    if as_json:
        emit_json({"experiment": experiment if track else None, "parent_run_id": parent, "axis": axis or 1,
                   "rows": rows})
        return
    table = Table(title=f"compare on {test} (axis {axis or 1}), sorted by test RMSE")
    u = train_rec.units["tau"]
    # units escaped: rich would read "[s]" as markup
    for col in ("rank", "model", f"test RMSE \\[{u}]", "test R^2", f"train RMSE \\[{u}]", "fit time \\[s]",
                "parameters"):
        table.add_column(col, justify="left" if col == "model" else "right")
    for i, r in enumerate(rows, 1):
        table.add_row(str(i), r["model"], f"{r['test_rmse']:.4f}", f"{r['test_r2']:.5f}", f"{r['train_rmse']:.4f}",
                      f"{r['fit_time_s']:.1f}", str(r["n_parameters"]))
    out.print(table)
    if parent:
        out.print(f"MLflow experiment '{experiment}', parent run {parent}; open it with: greybench ui")


def train_robot(
    log: Path = typer.Option(..., "--log", help="Six-axis log: t [s], q1..q6 [rad], tau1..tau6 [Nm] (.csv/.parquet)."),
    robot: str = typer.Option("max100", "--robot", help="Robot name (data/robots) or robot file (.toml)."),
    model: str = typer.Option("greybox", "--model", help=f"Model name: {', '.join(MODELS)}."),
    test: Path | None = typer.Option(None, "--test", help="Six-axis test log (same format) for test metrics [Nm]."),
    axes: str = typer.Option("1,2,3,4,5,6", "--axes", help="Comma-separated joints 1..6 to fit."),
    seed: int = typer.Option(0, "--seed", help="Random seed of every fit."),
    epochs: int | None = typer.Option(None, "--epochs", help="Adam epochs [passes] for learned models."),
    experiment: str = typer.Option("train-robot", "--experiment", help="MLflow experiment name."),
    register: bool = typer.Option(True, "--register/--no-register", help="Register each axis as "
                                                                         "<robot>-axis<N>-friction."),
    as_json: bool = typer.Option(False, "--json", help='Print {"parent_run_id", "axes": [...]} as one JSON object.'),
) -> None:
    """Fit one friction model per robot axis from a six-axis log (split by ``greybench prepare``:
    tau_rb [Nm] from the rigid-body model), one MLflow run per axis under a parent run."""
    import tempfile

    from identify.tracking import fit_axes
    from simulate.robot.model import load_robot
    from simulate.robot.prepare import prepare_log

    try:
        axis_list = sorted({int(a) for a in axes.split(",") if a.strip()})
    except ValueError:
        raise InputError(f"not a list of joint numbers: {axes!r}", field="--axes") from None
    if not axis_list:
        raise InputError("no axis given", field="--axes")
    for a in axis_list:
        _check_axis(a)
    _make(model, seed, epochs)  # unknown names fail before any work
    rob = load_robot(resolve_robot(robot))
    for a in axis_list:
        if a > 6:
            raise InputError(f"--axis {a}: the robot model and `prepare` handle joints 1..6", field="--axes")
    robot_name = _robot_name(robot)
    with tempfile.TemporaryDirectory(prefix="greybench-train-robot-") as tmp:
        with progress("train-robot: splitting the logs (rigid-body model)"):
            train_paths = prepare_log(rob, log, Path(tmp) / "train").paths
            test_paths = prepare_log(rob, test, Path(tmp) / "test").paths if test else None
        with progress(f"train-robot {model}", total=len(axis_list)) as advance:
            rows, parent = fit_axes(lambda: _make(model, seed, epochs), {a: train_paths[a - 1] for a in axis_list},
                                    {a: test_paths[a - 1] for a in axis_list} if test_paths else None,
                                    experiment=experiment, robot=robot_name, register=register, advance=advance,
                                    params={"log": str(log), "test_log": str(test) if test else "",
                                            "format": Path(log).suffix.lower()})
    if as_json:
        emit_json({"parent_run_id": parent, "experiment": experiment, "model": model, "robot": robot_name,
                   "axes": rows})
        return
    table = Table(title=f"train-robot {robot_name}: {model} per axis (parent run {parent})")
    for col in ("axis", "train RMSE [Nm]", "train R^2", "test RMSE [Nm]", "fit time \\[s]", "registered", "run"):
        table.add_column(col)
    for r in rows:
        table.add_row(str(r["axis"]), f"{r['train_rmse']:.4f}", f"{r['train_r2']:.4f}",
                      f"{r['test_rmse']:.4f}" if "test_rmse" in r else "-", f"{r['fit_time_s']:.1f}",
                      f"{r['registered']} v{r['version']} ({r['alias']})" if r["registered"] else "-", r["run_id"])
    out.print(table)


def promote(
    name: str = typer.Option(..., "--name", help="Registered model, e.g. max100-axis1-friction."),
    as_json: bool = typer.Option(False, "--json", help="Print the decision as one JSON object (RMSE in Nm)."),
) -> None:
    """Make the 'challenger' version 'champion': at once when there is no champion yet, otherwise
    only if its test RMSE [Nm] is lower; say by how much."""
    from identify.tracking import promote as do_promote

    res = do_promote(name)
    if as_json:
        emit_json(res.to_dict())
    else:
        out.print(res.message(), soft_wrap=True, highlight=False)


def ui(
    host: str = typer.Option("127.0.0.1", "--host", help="Interface to listen on."),
    port: int = typer.Option(5000, "--port", help="TCP port."),
    print_only: bool = typer.Option(False, "--print-only", help="Print the mlflow ui command instead of running it."),
) -> None:
    """Start the MLflow UI on the tracking store (MLFLOW_TRACKING_URI or ./mlruns.db); its URL is
    printed once the UI answers (starting takes seconds to a minute), then it runs until Ctrl-C."""
    import shlex
    import subprocess

    from greybench.support import err, wait_until_answers
    from identify.tracking import ui_command

    if not 0 < port < 65536:
        raise InputError("must be 1..65535", field="--port")
    cmd = ui_command(host, port)
    if print_only:
        out.print(" ".join(shlex.quote(c) for c in cmd), highlight=False, soft_wrap=True)
        return
    local = {"0.0.0.0": "127.0.0.1", "::": "[::1]"}.get(host, f"[{host}]" if ":" in host else host)
    url = f"http://{local}:{port}/"
    proc = subprocess.Popen(cmd, stdout=2)  # mlflow's own messages to stderr: stdout carries only the URL
    try:
        with progress(f"starting the MLflow UI on port {port}"):
            up = wait_until_answers(url, proc)
        if not up:
            proc.terminate()
            code = proc.wait()
            err.print(f"error: the MLflow UI did not answer at {url} (exit code {code}; is the port taken?)",
                      highlight=False, markup=False, soft_wrap=True)
            raise typer.Exit(code=1)
        out.print(f"MLflow UI: {url}", highlight=False, soft_wrap=True)
        sys.stdout.flush()
        raise typer.Exit(code=proc.wait())
    except KeyboardInterrupt:
        proc.terminate()
        raise typer.Exit(code=proc.wait()) from None


def register(app: typer.Typer) -> None:
    app.command("trajectory")(guarded(trajectory))
    app.command("synth")(guarded(synth))
    app.command("fit")(guarded(fit))
    app.command("predict")(guarded(predict))
    app.command("compare")(guarded(compare))
    app.command("train-robot")(guarded(train_robot))
    app.command("promote")(guarded(promote))
    app.command("ui")(guarded(ui))
