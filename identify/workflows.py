"""The identification workflows behind the ``greybench`` friction commands: checked inputs in, files
and MLflow runs written, typed results out; the caller parses the options and prints (SI inside).

Every workflow checks its inputs before any work (``InputError`` naming the file or the CLI option)
and reports progress to an :class:`identify.progress.Advance` (silent by default). Heavy modules
(pandas, MLflow, torch) are imported inside the functions.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from identify.errors import InputError
from identify.progress import Advance

if TYPE_CHECKING:
    import subprocess

    import pandas as pd

    from identify.axis_limits import AxisLimits
    from identify.metrics import Metrics
    from identify.models import FrictionModel
    from identify.plant import Effect, SynthResult
    from identify.records import AxisRecord
    from identify.tracking import FitRun
    from identify.trajectories import Trajectory

#: The six models of the paper's comparison, in the order of the workflow.
COMPARE_MODELS = ("coulomb-viscous", "stribeck", "lugre", "lstm", "residual", "greybox")


def make_trajectory(kind: str, limits: AxisLimits, duration: float = 60.0, rate: float = 1000.0) -> Trajectory:
    """An excitation trajectory of ``kind`` (:data:`identify.trajectories.TRAJECTORIES`) within the
    axis's limits, ``duration`` [s] (not for ``stribeck``: its steps set it) sampled at ``rate`` [Hz]."""
    from identify.trajectories import TRAJECTORIES

    if duration <= 0:
        raise InputError("must be > 0", field="--duration")
    if rate <= 0:
        raise InputError("must be > 0", field="--rate")
    fn = TRAJECTORIES[kind]
    try:
        return fn(limits, rate=rate) if kind == "stribeck" else fn(limits, duration=duration, rate=rate)
    except ValueError as exc:
        raise InputError(str(exc), field="--duration") from None


def synth_record(trajectory: Path, out_file: Path, *, config: Path | None = None, static_curve: str | None = None,
                 noise: float | None = None, effect: Effect | str = "none", magnitude: float = 1.0, seed: int = 0,
                 positions_only: bool = False) -> SynthResult:
    """Simulate one joint (:func:`identify.plant.synthesize`) following the trajectory table (t [s],
    q [rad], optional qd, qdd) and write the record to ``out_file``. The plant is ``config`` (TOML of
    :class:`identify.plant.PlantConfig`, SI) with ``static_curve`` and ``noise`` [Nm] overriding it."""
    from identify.plant import PlantConfig, synthesize
    from identify.records import read_table, validate_frame, write_table

    cfg = PlantConfig.from_toml(config) if config else PlantConfig()
    overrides: dict[str, Any] = {k: v for k, v in (("static_curve", static_curve), ("noise", noise)) if v is not None}
    if overrides:
        cfg = replace(cfg, **overrides).validate("--static-curve/--noise")
    if magnitude < 0:
        raise InputError("must be >= 0", field="--magnitude")
    df = read_table(trajectory)
    rec = validate_frame(df.assign(tau=0.0) if "tau" not in df.columns else df, source=str(trajectory))
    has_d = "qd" in df.columns and "qdd" in df.columns
    res = synthesize(rec.t, rec.q, rec.qd if has_d else None, rec.qdd if has_d else None, config=cfg, effect=effect,
                     magnitude=magnitude, seed=seed, positions_only=positions_only)
    write_table(res.frame, out_file)
    return res


@dataclass
class FitOutcome:
    """What :func:`fit_model` gives: the fit time [s], the metrics per record (``train``, ``test``;
    RMSE in the record's torque unit) and the MLflow run (None without tracking)."""

    fit_time: float
    metrics: dict[str, Metrics] = field(default_factory=dict)
    run: FitRun | None = None


def fit_model(est: FrictionModel, train: AxisRecord, test: AxisRecord | None = None, *, out_dir: Path | None = None,
              track: bool = True, experiment: str = "friction", axis: int = 1, robot: str = "",
              register: bool = True, advance: Advance | None = None) -> FitOutcome:
    """Fit ``est`` on ``train``, score it on ``test``, save it into ``out_dir`` and, with ``track``, log
    it as an MLflow run (:func:`identify.tracking.log_fit`), registered as ``<robot>-axis<N>-friction``
    (alias challenger) when ``register``."""
    from identify.records import record_params

    adv = advance if advance is not None else Advance()
    adv.describe("fitting")
    t0 = time.perf_counter()
    est.fit(train)
    outcome = FitOutcome(fit_time=time.perf_counter() - t0, metrics={"train": est.train_metrics_})
    if test is not None:
        adv.describe("scoring the test record")
        outcome.metrics["test"] = est.score(test)
    if out_dir is not None:
        est.save(out_dir)
    if track:
        from identify.tracking import log_fit, registered_name

        adv.describe("logging to MLflow (plots, residual analysis, model)")
        outcome.run = log_fit(est, train, test, fit_time=outcome.fit_time, experiment=experiment, axis=axis,
                              robot=robot, register=registered_name(robot, axis) if register else None,
                              extra_params=record_params(train))
    return outcome


def predict_record(est: FrictionModel, rec: AxisRecord, out_file: Path, source: str = "") -> tuple[pd.DataFrame,
                                                                                                   Metrics]:
    """Write the record's columns plus ``tau_friction_pred`` (the friction) and ``tau_pred`` (the total
    joint torque, comparable to ``tau``) [Nm; N on a linear axis] to ``out_file``; gives the table and
    the metrics of ``tau_pred`` against ``tau``. A model fitted on the other axis kind is refused."""
    from identify.records import write_table

    if bool(getattr(est, "linear_", False)) != rec.linear:
        raise InputError(f"mixed units: the model was fitted on a {'rotary' if rec.linear else 'linear'} axis and "
                         f"the record is {'linear' if rec.linear else 'rotary'}", source=source, field="q")
    friction, tau_pred = est.predict_parts(rec)
    assert rec.frame is not None  # records read from a file keep their frame
    frame = rec.frame.copy()
    frame["tau_friction_pred"] = friction
    frame["tau_pred"] = tau_pred
    write_table(frame, out_file)
    return frame, est.score(rec)


def wait_until_answers(url: str, proc: subprocess.Popen[Any], timeout_s: float = 180.0, poll_s: float = 0.25) -> bool:
    """Wait until ``url`` answers an HTTP GET (any status below 500) while the server process ``proc``
    runs; False when it exits first or ``timeout_s`` [s] passes (``poll_s`` [s] between tries)."""
    import urllib.error
    import urllib.request

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        try:
            with urllib.request.urlopen(url, timeout=2.0) as resp:
                if resp.status < 500:
                    return True
        except urllib.error.HTTPError as exc:
            if exc.code < 500:
                return True
        except (urllib.error.URLError, OSError):
            pass
        time.sleep(poll_s)
    return False
