"""Friction identification commands: synth, fit, predict, compare, train-robot, promote
(:mod:`identify.workflows`; fits are tracked in MLflow, :mod:`identify.tracking`)."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from greybench import options as o
from greybench.support import emit_json, out, print_table, progress, resolve_robot, show, warn
from identify import workflows as wf
from identify.models import MODELS, FrictionModel, make_seeded
from identify.plant import Effect
from identify.records import derivative_note
from identify.workflows import COMPARE_MODELS, load_pair, predict_record, record_warnings, synth_record

if TYPE_CHECKING:
    from identify.records import AxisRecord


def synth(
    trajectory_file: Annotated[Path, typer.Option("--trajectory", help="Trajectory table (t [s], q [rad], optional "
                                                                       "qd, qdd).")],
    out_file: Annotated[Path, typer.Option("--out", help="Output axis record, .csv or .parquet.")],
    effect: Annotated[Effect, typer.Option("--effect", help="Hidden effect the plain LuGre model does not "
                                                            "know.")] = Effect.NONE,
    magnitude: Annotated[float, typer.Option("--magnitude", help="Scale of the effect's strength (1 = "
                                                                 "default).")] = 1.0,
    seed: Annotated[int, typer.Option("--seed", help="Seed of noise, start temperature and load phase.")] = 0,
    config: Annotated[Path | None, typer.Option("--config", help="Plant parameters TOML (keys of PlantConfig, "
                                                                 "SI).")] = None,
    static_curve: Annotated[str | None, typer.Option("--static-curve", help="stribeck | lorentzian | hump "
                                                                            "(overrides config).")] = None,
    noise: Annotated[float | None, typer.Option("--noise", help="Torque noise standard deviation [Nm] (overrides "
                                                                "config).")] = None,
    positions_only: Annotated[bool, typer.Option("--positions-only", help="Write no qd/qdd (they must then be "
                                                                          "derived).")] = False,
    as_json: o.Json = False,
) -> None:
    """Simulate one joint (inertia, LuGre friction, sensor noise, optional hidden effect) following
    a trajectory; writes t [s], q [rad], qd [rad/s], qdd [rad/s^2], tau [Nm], temp [degC], tau_load [Nm]."""
    res = synth_record(trajectory_file, out_file, config=config, static_curve=static_curve, noise=noise,
                       effect=effect, magnitude=magnitude, seed=seed, positions_only=positions_only)
    cfg = res.config
    show(as_json, {"out": str(out_file), "samples": int(len(res.frame)), "effect": effect.value, "magnitude": magnitude,
                   "seed": seed, "noise": cfg.noise, "static_curve": cfg.static_curve},
         lambda: out.print(f"synthetic record ({effect.value}, magnitude {magnitude}, seed {seed}, static curve "
                           f"{cfg.static_curve}, noise {cfg.noise} Nm): {len(res.frame)} samples -> {out_file}"))


def _make(model: str, seed: int, epochs: int | None) -> FrictionModel:
    return make_seeded(model, seed, epochs, model_field="--model", epochs_field="--epochs")


def fit(
    model: Annotated[str, typer.Option("--model", help=f"Model name: {', '.join(MODELS)}.")],
    train: Annotated[Path, typer.Option("--train", help="Training axis record, or robot log (t, q1..qN, tau1..tauN) "
                                                        "with --axis (.csv/.parquet; SI: t [s], q [rad], tau [Nm], "
                                                        "...).")],
    test: Annotated[Path | None, typer.Option("--test", help="Test record (same format) for held-out metrics "
                                                             "[Nm].")] = None,
    out_dir: Annotated[Path | None, typer.Option("--out", help="Folder for the fitted model (params.json with units, "
                                                               "+ model files); the MLflow run holds it too.")] = None,
    axis: o.Axis = None,
    robot: Annotated[str | None, typer.Option("--robot", help="Robot name or file whose axis the record is: the "
                                                              "model registers as <robot>-axis<N>-friction, the "
                                                              "name the simulation uses (default: no robot; the "
                                                              "arm-coupling warning checks max100).")] = None,
    name: Annotated[str | None, typer.Option("--name", help="Registered-model name (default: <robot>-axis<N>-friction "
                                                            "with --robot, else <record file stem>-axis<N>-"
                                                            "friction).")] = None,
    cutoff: o.Cutoff = None,
    linear: o.Linear = False,
    seed: o.Seed = 0,
    epochs: o.Epochs = None,
    experiment: o.Experiment = "friction",
    track: o.Track = True,
    register: Annotated[bool, typer.Option("--register/--no-register", help="Register the fit (see --name) with "
                                                                            "alias challenger (promote makes the "
                                                                            "champion).")] = True,
    as_json: Annotated[bool, typer.Option("--json", help='Print {"model", "params", "train", "test", "run"} as one '
                                                         'JSON object.')] = False,
) -> None:
    """Fit a friction model (co-identifying inertia J [kg m^2] and offset c [Nm] unless the
    record has tau_rb [Nm]); track it in MLflow, save it, print RMSE [Nm], R^2, NRMSE, max error [Nm]."""
    from greybench.api import FitOptions, fit_friction

    def loaded(train_rec: AxisRecord, warnings: list[str]) -> None:
        warn(warnings)
        if not as_json:
            out.print(derivative_note(train_rec), highlight=False)

    res = fit_friction(model, train, test, out_dir=out_dir, progress=progress, on_loaded=loaded,
                       options=FitOptions(axis=axis, robot=robot, name=name, cutoff_hz=cutoff, linear=linear,
                                          seed=seed, epochs=epochs, experiment=experiment, track=track,
                                          register=register))
    if as_json:
        emit_json(res.to_dict())
        return
    print_table(*wf.params_table(res.estimator))
    where = f", saved to {out_dir}" if out_dir else ""
    print_table(*wf.metrics_table(f"{model}: fit in {res.outcome.fit_time:.2f} s{where}", res.metrics,
                                  res.train.units["tau"]))
    if res.run:
        out.print(res.outcome.run_text())


def predict(
    model_ref: Annotated[str, typer.Option("--model", help="Saved model folder, runs:/<run_id>/model or "
                                                           "models:/<name>@<alias>.")],
    data: Annotated[Path, typer.Option("--data", help="Axis record to predict (.csv/.parquet), or a robot log with "
                                                      "--axis.")],
    out_file: Annotated[Path, typer.Option("--out", help="Output table: the input columns plus tau_friction_pred "
                                                         "[Nm] (the friction) and tau_pred [Nm] (the total joint "
                                                         "torque: tau_friction_pred + tau_rb when the model was "
                                                         "fitted with tau_rb, else tau_friction_pred + J*qdd + "
                                                         "c).")],
    axis: o.Axis = None,
    cutoff: Annotated[float | None, typer.Option("--cutoff", help="Derivative cut-off [Hz] for records without "
                                                                  "qd/qdd (default: the one the model was fitted "
                                                                  "with, else chosen from the record).")] = None,
    as_json: o.Json = False,
) -> None:
    """Predict a record with a fitted model: the friction tau_friction_pred [Nm] and the total
    joint torque tau_pred [Nm], comparable to the measured tau.

    A model fitted on records with tau_rb [Nm] learned the friction tau - tau_rb, and gives
    tau_pred = tau_friction_pred + tau_rb (the record must then have tau_rb). A model fitted
    without tau_rb co-identified an inertia J [kg m^2] and an offset c [Nm]:
    tau_pred = tau_friction_pred + J*qdd + c. The metrics compare tau_pred with tau."""
    from identify.tracking import load_any_model

    est = load_any_model(model_ref)
    rec, _ = load_pair(data, None, axis, linear=bool(getattr(est, "linear_", False)),
                       cutoff=cutoff or getattr(est, "cutoff_hz_", None))
    warn(record_warnings(rec))
    _, m = predict_record(est, rec, out_file, source=str(data))
    show(as_json, {"model": est.name, "out": str(out_file), "metrics": m.to_dict(),
                   "derivative_cutoff_hz": rec.cutoff_hz}, lambda: out.print(derivative_note(rec), highlight=False),
         lambda: print_table(*wf.metrics_table(f"{est.name} on {data} -> {out_file}", {"data": m}, rec.units["tau"])))


def compare(
    train: Annotated[Path, typer.Option("--train", help="Training axis record (or robot log with --axis), SI "
                                                        "units.")],
    test: Annotated[Path, typer.Option("--test", help="Test axis record (same format); the table is sorted by its "
                                                      "RMSE [Nm].")],
    models: Annotated[str | None, typer.Option("--models", help="Comma-separated models (default: "
                                                                f"{','.join(COMPARE_MODELS)}).")] = None,
    axis: o.Axis = None,
    cutoff: o.Cutoff = None,
    linear: o.Linear = False,
    robot: Annotated[str, typer.Option("--robot", help="Robot name or file (recorded in the runs).")] = "max100",
    seed: o.Seed = 0,
    epochs: o.Epochs = None,
    experiment: o.Experiment = "compare",
    track: o.Track = True,
    as_json: Annotated[bool, typer.Option("--json", help='Print {"rows": [...]} sorted by test RMSE as one JSON '
                                                         'object.')] = False,
) -> None:
    """Fit several friction models on one record and rank them by test RMSE [Nm], with R^2,
    fit time [s] and parameter count; every fit is a run of one MLflow experiment."""
    from greybench.api import CompareOptions, compare_friction

    res = compare_friction(train, test, progress=progress, on_loaded=lambda _rec, warnings: warn(warnings),
                           options=CompareOptions(models=models, axis=axis, cutoff_hz=cutoff, linear=linear,
                                                  robot=robot, seed=seed, epochs=epochs, experiment=experiment,
                                                  track=track))
    if as_json:
        emit_json(res.to_dict())
        return
    print_table(*wf.compare_table(res.rows, test, res.axis, res.unit))
    if res.parent_run_id:
        out.print(f"MLflow experiment '{experiment}', parent run {res.parent_run_id}; open it with: greybench ui")


def train_robot(
    log: o.RobotLog,
    robot: o.Robot = "max100",
    model: Annotated[str, typer.Option("--model", help=f"Model name: {', '.join(MODELS)}.")] = "greybox",
    test: Annotated[Path | None, typer.Option("--test", help="Six-axis test log (same format) for test metrics "
                                                             "[Nm].")] = None,
    axes: Annotated[str, typer.Option("--axes", help="Comma-separated joints 1..6 to fit.")] = "1,2,3,4,5,6",
    seed: o.Seed = 0,
    epochs: o.Epochs = None,
    experiment: o.Experiment = "train-robot",
    register: o.Register = True,
    as_json: o.Json = False,
) -> None:
    """Fit one friction model per robot axis from a six-axis log (split by ``greybench prepare``:
    tau_rb [Nm] from the rigid-body model), one MLflow run per axis under a parent run."""
    from identify.workflows import parse_joints
    from simulate.run import train_robot as fit_robot

    axis_list = parse_joints(axes)
    _make(model, seed, epochs)  # unknown names fail before any work
    robot_file = resolve_robot(robot)
    rows, parent = fit_robot(log, robot_file, lambda: _make(model, seed, epochs), axis_list, test=test,
                             experiment=experiment, register=register, model_name=model, progress=progress)
    show(as_json, {"parent_run_id": parent, "experiment": experiment, "model": model, "robot": robot_file.stem,
                   "axes": rows}, lambda: print_table(*wf.train_robot_table(rows, robot_file.stem, model, parent)))


def promote(
    name: Annotated[str, typer.Option("--name", help="Registered model, e.g. max100-axis1-friction.")],
    as_json: o.Json = False,
) -> None:
    """Make the 'challenger' version 'champion': at once when there is no champion yet, otherwise
    only if its test RMSE [Nm] is lower; say by how much."""
    from identify.tracking import promote as do_promote

    res = do_promote(name)
    show(as_json, res.to_dict(), lambda: out.print(res.message(), soft_wrap=True, highlight=False))


COMMANDS = {"synth": synth, "fit": fit, "predict": predict, "compare": compare,
            "train-robot": train_robot, "promote": promote}
