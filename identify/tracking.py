"""MLflow tracking of friction fits: runs, plots, pyfunc models, registry aliases, promotion.

Store: ``MLFLOW_TRACKING_URI`` when set (a real ``mlflow server`` works unchanged), else an
embedded SQLite store ``sqlite:///<cwd>/mlruns.db`` with artifacts in ``<cwd>/mlartifacts``.

Every fit is one run with
- params: the model name, its hyperparameters, axis, robot, record files and sizes, and the
  fitted parameters (``fitted.<name>``, SI units as in ``params.json``);
- metrics: ``loss`` per epoch (learned models), and ``train_rmse``, ``train_r2``,
  ``test_rmse``, ``test_r2`` [Nm, -] (test when a test record is given), ``fit_time_s``,
  ``n_parameters``;
- artifacts: the model (an MLflow pyfunc wrapping the saved model folder: ``mlflow.pyfunc.
  load_model(uri).predict(frame)`` takes a DataFrame with the axis-record columns and returns
  the torque [Nm]) and four plots: prediction and measurement over time, the parity plot of
  measured against predicted friction (paper Fig. 3), the friction-velocity hysteresis and the
  residual analysis (:mod:`identify.residual_analysis`: residual autocorrelation and
  velocity-residual cross-correlation with 99 % bands, also as ``residual_analysis.json`` and as
  ``resid_*`` metrics), all on the test record when given.

``compare`` makes one parent run with a child run per model (:func:`log_comparison`): the parent
carries ``<metric>/<model>`` metrics (one row in the MLflow compare view holds every model), the
comparison table, the overlay of all models' predictions and their residual analyses in one plot.

The store's location and the ``mlflow ui`` command are in :mod:`identify.tracking_store` (no mlflow,
numpy or models: the CLI's light paths), re-exported here.

Registered models are named per robot and axis (:func:`registered_name`, e.g.
``max100-axis1-friction``); every new version becomes ``challenger`` (an untested model never
drives a simulation by itself); only :func:`promote` makes a ``champion``: the first promotion
of a name makes the challenger champion, later ones move ``champion`` only when the
challenger's test RMSE is lower.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import pandas as pd

from identify.errors import InputError
from identify.metrics import Metrics
from identify.models import FrictionModel, load_model
from identify.records import AxisRecord, load_record, markdown_table, record_params, validate_frame
from identify.residual_analysis import ResidualAnalysis, residual_analysis
from identify.residual_analysis import figure as residual_figure
from identify.tracking_store import ARTIFACT_DIR, DB_FILE, artifact_root, tracking_uri, ui_command  # noqa: F401

MODEL_ARTIFACT = "model"
CHAMPION = "champion"
CHALLENGER = "challenger"
#: Key of the saved model folder inside the pyfunc's artifacts.
PYFUNC_ARTIFACT = "friction_model"


def _mlflow():
    """mlflow, pointed at the store, with its chatter kept off stdout and stderr.

    Artifact downloads (``predict --model runs:/...``, ``compare``) would draw progress bars
    on stderr: they are off unless the user sets ``MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR``.
    """
    import logging

    os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")
    import mlflow

    logging.getLogger("mlflow").setLevel(logging.ERROR)
    logging.getLogger("alembic").setLevel(logging.ERROR)
    warnings.filterwarnings("ignore", module="mlflow")
    mlflow.set_tracking_uri(tracking_uri())
    mlflow.set_registry_uri(tracking_uri())
    return mlflow


def ensure_experiment(name: str) -> str:
    """Id of the experiment ``name``, created (with the local artifact root) when missing."""
    mlflow = _mlflow()
    exp = mlflow.get_experiment_by_name(name)
    if exp is not None:
        return exp.experiment_id
    root = artifact_root(tracking_uri())
    location = f"{root}/{name}" if root else None
    return mlflow.create_experiment(name, artifact_location=location)


def registered_name(robot: str, axis: int) -> str:
    """Registered-model name per robot and axis, e.g. ``max100-axis1-friction``."""
    return f"{robot}-axis{axis}-friction"


def is_tracked_ref(ref: str) -> bool:
    """True for MLflow model URIs (``runs:/...``, ``models:/...``)."""
    return str(ref).startswith(("runs:/", "models:/"))


# ---- pyfunc ----------------------------------------------------------------------------
_PythonModel: type
try:
    import mlflow.pyfunc as _pyfunc

    _PythonModel = _pyfunc.PythonModel
except Exception:  # pragma: no cover - mlflow is a dependency
    _PythonModel = object


class FrictionPyfunc(_PythonModel):
    """MLflow pyfunc wrapper: a DataFrame of axis-record columns in, total torque [Nm] out."""

    def load_context(self, context) -> None:
        self.model = load_model(context.artifacts[PYFUNC_ARTIFACT])

    # The type hint tells mlflow the input is a DataFrame (mlflow >= 2.20 asks for one and warns
    # otherwise); DataFrame hints carry no schema, so any axis-record columns are accepted.
    def predict(self, context, model_input: pd.DataFrame, params: dict | None = None) -> pd.Series:
        frame = model_input if isinstance(model_input, pd.DataFrame) else pd.DataFrame(model_input)
        if "tau" not in frame.columns:  # prediction needs no measurement; the record format does
            frame = frame.assign(tau=0.0)
        record = validate_frame(frame, source="pyfunc input")
        return pd.Series(self.model.predict(record), name="tau_pred")


def _find_model_folder(root: Path) -> Path:
    hits = sorted(root.rglob("params.json"))
    hits = [h for h in hits if h.parent.name != "lugre" or not (h.parent.parent / "params.json").exists()]
    if not hits:
        raise InputError("no friction model (params.json) in the MLflow artifact", source=str(root))
    return min(hits, key=lambda h: len(h.parts)).parent


def load_tracked_model(ref: str) -> FrictionModel:
    """Load a friction model from ``runs:/<id>/model`` or ``models:/<name>@<alias>`` (or /<version>)."""
    mlflow = _mlflow()
    from mlflow.exceptions import MlflowException

    dst = Path(tempfile.mkdtemp(prefix="greybench-model-"))
    try:
        local = Path(mlflow.artifacts.download_artifacts(artifact_uri=ref, dst_path=str(dst)))
    except MlflowException as exc:
        raise InputError(f"cannot resolve MLflow model: {exc.message.splitlines()[0]}", source=ref) from None
    return load_model(_find_model_folder(local))


def load_any_model(ref: str) -> FrictionModel:
    """A friction model from a saved folder or an MLflow model URI (``runs:/...``, ``models:/...``)."""
    return load_tracked_model(ref) if is_tracked_ref(ref) else load_model(ref)


# ---- plots -----------------------------------------------------------------------------
def analyse_residual(record: AxisRecord, pred) -> ResidualAnalysis:
    """Residual analysis of a prediction ``pred`` [Nm] on ``record``: the residual
    ``tau - pred`` [Nm] against the input ``qd`` [rad/s] (:mod:`identify.residual_analysis`),
    lags up to 25 samples or 0.25 s, whichever is longer."""
    import numpy as np

    from identify.residual_analysis import MAX_LAG, MIN_LAG_WINDOW_S

    dt = record.sample_time
    max_lag = min(max(MAX_LAG, int(round(MIN_LAG_WINDOW_S / dt))), record.n - 1)
    return residual_analysis(record.tau - np.asarray(pred, dtype=float), record.qd, dt, max_lag=max_lag)


def overlay_figure(record: AxisRecord, preds: dict[str, np.ndarray], label: str):
    """Measured torque and every model's prediction [Nm] over time on one record (top), their
    errors (bottom), and a zoom on the 2 s around the largest error (right)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    import numpy as np

    fig = plt.figure(figsize=(13, 7))
    grid = fig.add_gridspec(2, 2, width_ratios=[3, 1.2], height_ratios=[3, 1.3])
    ax1, ax2 = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[1, 0])
    zoom = fig.add_subplot(grid[:, 1])
    errors = np.abs(np.stack([np.asarray(p, dtype=float) for p in preds.values()]) - record.tau)
    t0 = float(record.t[np.unravel_index(np.argmax(errors), errors.shape)[1]])
    sel = (record.t >= t0 - 1.0) & (record.t <= t0 + 1.0)
    ax1.plot(record.t, record.tau, lw=0.8, color="black", label="measured")
    zoom.plot(record.t[sel], record.tau[sel], lw=1.0, color="black", label="measured")
    for i, (name, p) in enumerate(preds.items()):
        p = np.asarray(p)
        colour = f"C{i % 10}"
        ax1.plot(record.t, p, lw=0.5, color=colour, label=name)
        ax2.plot(record.t, p - record.tau, lw=0.4, color=colour, label=name)
        zoom.plot(record.t[sel], p[sel], lw=0.8, color=colour, label=name)
    ax1.set_ylabel("torque [Nm]")
    ax1.set_title(f"prediction overlay on the {label}")
    ax1.legend(loc="upper right", fontsize=8, ncol=2)
    ax2.set_ylabel("error [Nm]")
    ax2.set_xlabel("t [s]")
    ax2.sharex(ax1)
    zoom.set_title(f"zoom: 2 s around t = {t0:.2f} s")
    zoom.set_xlabel("t [s]")
    zoom.set_ylabel("torque [Nm]")
    fig.tight_layout()
    return fig


def figures(model: FrictionModel, record: AxisRecord, label: str, pred=None) -> dict[str, Any]:
    """The three diagnostic figures of a fit on ``record`` (matplotlib, Agg).

    Returns a dict file name -> Figure: ``prediction_time.png`` (measured and predicted
    torque over time, with the error), ``parity.png`` (measured vs predicted friction torque
    with the identity line, paper Fig. 3) and ``hysteresis.png`` (friction vs velocity).
    ``pred`` [Nm] is the model's prediction on ``record`` when already computed.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    pred = model.predict(record) if pred is None else pred
    rigid = model.rigid_part(record)
    tu, vu = record.units["tau"], record.units["qd"]  # Nm, rad/s (N, m/s on a linear axis)
    f_meas = record.tau - rigid
    f_pred = pred - rigid
    out = {}
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax1.plot(record.t, record.tau, lw=0.6, label="measured")
    ax1.plot(record.t, pred, lw=0.6, label=f"{model.name}")
    ax1.set_ylabel(f"torque [{tu}]")
    ax1.legend(loc="upper right")
    ax1.set_title(f"{model.name} on {label}")
    ax2.plot(record.t, pred - record.tau, lw=0.5, color="C3")
    ax2.set_ylabel(f"error [{tu}]")
    ax2.set_xlabel("t [s]")
    fig.tight_layout()
    out["prediction_time.png"] = fig

    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    ax.scatter(f_meas, f_pred, s=1, alpha=0.3)
    lim = [float(min(f_meas.min(), f_pred.min())), float(max(f_meas.max(), f_pred.max()))]
    ax.plot(lim, lim, color="red", lw=1)
    ax.set_xlabel(f"measured friction torque [{tu}]")
    ax.set_ylabel(f"predicted friction torque [{tu}]")
    ax.set_title(f"parity, {model.name} on {label}")
    fig.tight_layout()
    out["parity.png"] = fig

    fig, ax = plt.subplots(figsize=(7, 5))
    ax.scatter(record.qd, f_meas, s=1, alpha=0.2, label="measured")
    ax.plot(record.qd, f_pred, lw=0.5, color="C1", label=model.name)
    ax.set_xscale("symlog", linthresh=1e-3)
    ax.set_xlabel(f"qd [{vu}] (symlog)")
    ax.set_ylabel(f"friction torque [{tu}]")
    ax.legend(loc="upper left")
    ax.set_title(f"friction-velocity hysteresis, {label}")
    fig.tight_layout()
    out["hysteresis.png"] = fig
    return out


# ---- runs ------------------------------------------------------------------------------
@dataclass
class FitRun:
    """A tracked fit.

    Attributes
    ----------
    run_id : str
    experiment : str
    model_uri : str
        ``runs:/<run_id>/model``.
    registered : str or None
        Registered-model name, when registered.
    version : str or None
        Its new version.
    alias : str or None
        ``challenger`` (the alias the new version got; only :func:`promote` makes a champion).
    """

    run_id: str
    experiment: str
    model_uri: str
    registered: str | None = None
    version: str | None = None
    alias: str | None = None

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def _pip_requirements() -> list[str]:
    from importlib.metadata import PackageNotFoundError, version

    reqs = []
    for pkg in ("torch", "numpy", "pandas", "scipy", "numba", "pygad", "mlflow"):
        with contextlib.suppress(PackageNotFoundError):
            reqs.append(f"{pkg}=={version(pkg)}")
    return reqs


def log_fit(model: FrictionModel, train: AxisRecord, test: AxisRecord | None = None, *, fit_time: float,
            experiment: str = "friction", run_name: str | None = None, axis: int | None = None,
            robot: str | None = None, register: str | None = None, parent_run_id: str | None = None,
            extra_params: dict | None = None, plots: bool = True) -> FitRun:
    """Record a fitted model as one MLflow run (see the module docstring); optionally register it.

    Parameters
    ----------
    model : FrictionModel
        Fitted.
    train, test : AxisRecord
        The records it was fitted and tested on (plots use the test record when given).
    fit_time : float
        Fit wall time [s].
    experiment : str
        Experiment name (created when missing).
    register : str, optional
        Registered-model name; the new version gets the alias ``challenger``.
    parent_run_id : str, optional
        Nest the run under this parent (``train-robot``).
    """
    mlflow = _mlflow()
    import matplotlib.pyplot as plt
    from mlflow.entities import Metric
    from mlflow.tracking import MlflowClient

    exp_id = ensure_experiment(experiment)
    tags = {"mlflow.parentRunId": parent_run_id} if parent_run_id else {}
    client = MlflowClient()
    run = client.create_run(exp_id, run_name=run_name or model.name, tags=tags)
    run_id = run.info.run_id
    try:
        params = {"model": model.name, "train_file": train.source, "train_samples": train.n,
                  **{f"hp.{k}": v for k, v in model.get_hyperparameters().items()},
                  **{f"fitted.{k}": f"{v:.8g}" for k, v in model.params_.items()}}
        if test is not None:
            params.update(test_file=test.source, test_samples=test.n)
        if axis is not None:
            params["axis"] = axis
        if robot is not None:
            params["robot"] = robot
        params.update(extra_params or {})
        with mlflow.start_run(run_id=run_id, nested=bool(parent_run_id)):
            mlflow.log_params({k: str(v)[:6000] for k, v in params.items()})
            if axis is not None:
                mlflow.set_tag("axis", str(axis))
            if robot is not None:
                mlflow.set_tag("robot", robot)
            history = getattr(model, "history_", None)
            if history is not None and history.loss:
                now = int(1000 * __import__("time").time())
                metrics = [Metric("loss", float(v), now, i + 1) for i, v in enumerate(history.loss)]
                for i in range(0, len(metrics), 1000):
                    client.log_batch(run_id, metrics=metrics[i:i + 1000])
            scores: dict[str, Metrics] = {"train": model.score(train)}
            if test is not None:
                scores["test"] = model.score(test)
            final = {"fit_time_s": fit_time, "n_parameters": model.n_parameters()}
            for part, m in scores.items():
                final.update({f"{part}_rmse": m.rmse, f"{part}_r2": m.r2, f"{part}_nrmse": m.nrmse,
                              f"{part}_max_error": m.max_error})
            rec, label = (test, "test record") if test is not None else (train, "training record")
            pred = model.predict(rec)
            resid = analyse_residual(rec, pred)
            final.update(resid.metrics())
            mlflow.log_metrics(final)
            mlflow.log_dict({"record": label, **resid.to_dict()}, "residual_analysis.json")
            if plots:
                figs = figures(model, rec, label, pred=pred)
                figs["residual_analysis.png"] = residual_figure({model.name: resid},
                                                                title=f"{model.name} on the {label}")
                for fname, fig in figs.items():
                    mlflow.log_figure(fig, f"plots/{fname}")
                    plt.close(fig)
            with tempfile.TemporaryDirectory() as tmp:
                folder = model.save(Path(tmp) / "friction_model")
                mlflow.log_artifact(str(folder / "params.json"))
                mlflow.pyfunc.log_model(name=MODEL_ARTIFACT, python_model=FrictionPyfunc(),
                                        artifacts={PYFUNC_ARTIFACT: str(folder)},
                                        pip_requirements=_pip_requirements())
    except BaseException:
        client.set_terminated(run_id, status="FAILED")
        raise
    result = FitRun(run_id=run_id, experiment=experiment, model_uri=f"runs:/{run_id}/{MODEL_ARTIFACT}")
    if register:
        version, alias = register_version(result.model_uri, register)
        result.registered, result.version, result.alias = register, version, alias
    return result


def register_version(model_uri: str, name: str) -> tuple[str, str]:
    """Register ``model_uri`` under ``name`` as the ``challenger`` (champion only via :func:`promote`)."""
    mlflow = _mlflow()
    from mlflow.tracking import MlflowClient

    client = MlflowClient()
    mv = mlflow.register_model(model_uri, name)
    client.set_registered_model_alias(name, CHALLENGER, mv.version)
    return str(mv.version), CHALLENGER


@dataclass
class Promotion:
    """Outcome of :func:`promote`.

    Attributes
    ----------
    name : str
        Registered-model name.
    promoted : bool
        Whether ``champion`` moved to the challenger.
    champion_version : str or None
        The champion before the decision (None: there was none, the challenger became the first).
    challenger_version : str
        The challenger compared.
    champion_rmse, challenger_rmse : float
        Their test RMSE [Nm] (champion NaN when there was none).
    improvement : float
        champion_rmse - challenger_rmse [Nm] (positive: the challenger is better; NaN for a first
        champion).
    improvement_pct : float
        The same relative to the champion [%].
    """

    name: str
    promoted: bool
    champion_version: str | None
    challenger_version: str
    champion_rmse: float
    challenger_rmse: float
    improvement: float
    improvement_pct: float

    def message(self) -> str:
        if self.champion_version is None:
            return (f"{self.name}: version {self.challenger_version} becomes the first champion (test RMSE "
                    f"{self.challenger_rmse:.4f} Nm)")
        if self.promoted:
            return (f"{self.name}: champion moved to version {self.challenger_version} (test RMSE "
                    f"{self.challenger_rmse:.4f} Nm, better by {self.improvement:.4f} Nm = {self.improvement_pct:.1f}% "
                    f"than version {self.champion_version} at {self.champion_rmse:.4f} Nm)")
        return (f"{self.name}: champion stays version {self.champion_version} (test RMSE {self.champion_rmse:.4f} Nm); "
                f"challenger version {self.challenger_version} at {self.challenger_rmse:.4f} Nm is not better "
                f"(worse by {-self.improvement:.4f} Nm = {-self.improvement_pct:.1f}%)")

    def to_dict(self) -> dict:
        return {**self.__dict__, "message": self.message()}


def _version_test_rmse(client, name: str, mv) -> float:
    run = client.get_run(mv.run_id)
    rmse = run.data.metrics.get("test_rmse")
    if rmse is None:
        raise InputError(f"version {mv.version} has no test_rmse (fit it with --test)", source=name,
                         field="test_rmse")
    return float(rmse)


def promote(name: str) -> Promotion:
    """Make the ``challenger`` version ``champion``: at once when the name has no champion yet,
    otherwise only when the challenger's test RMSE is lower. The challenger must have been
    tested (a ``test_rmse`` metric) in both cases; a promoted challenger loses its alias.

    Raises
    ------
    InputError
        Unknown registered model, no challenger alias, or a version without ``test_rmse``.
    """
    _mlflow()
    from mlflow.exceptions import MlflowException
    from mlflow.tracking import MlflowClient

    client = MlflowClient()
    try:
        client.get_registered_model(name)
    except MlflowException:
        raise InputError("no such registered model", source=tracking_uri(), field=name) from None
    try:
        chall = client.get_model_version_by_alias(name, CHALLENGER)
    except MlflowException:
        raise InputError(f"has no '{CHALLENGER}' alias (register another fit first)", source=name,
                         field=CHALLENGER) from None
    try:
        champ = client.get_model_version_by_alias(name, CHAMPION)
    except MlflowException:
        champ = None
    r_chall = _version_test_rmse(client, name, chall)
    nan = float("nan")
    if champ is None:
        client.set_registered_model_alias(name, CHAMPION, chall.version)
        client.delete_registered_model_alias(name, CHALLENGER)
        return Promotion(name=name, promoted=True, champion_version=None, challenger_version=str(chall.version),
                         champion_rmse=nan, challenger_rmse=r_chall, improvement=nan, improvement_pct=nan)
    r_champ = _version_test_rmse(client, name, champ)
    better = r_chall < r_champ
    if better:
        client.set_registered_model_alias(name, CHAMPION, chall.version)
        client.delete_registered_model_alias(name, CHALLENGER)
    diff = r_champ - r_chall
    return Promotion(name=name, promoted=better, champion_version=str(champ.version),
                     challenger_version=str(chall.version), champion_rmse=r_champ, challenger_rmse=r_chall,
                     improvement=diff, improvement_pct=100.0 * diff / r_champ if r_champ > 0 else nan)


def start_parent_run(experiment: str, run_name: str, params: dict | None = None) -> str:
    """Create a parent run (e.g. ``train-robot``) and return its id; end it with :func:`end_run`."""
    _mlflow()
    from mlflow.tracking import MlflowClient

    client = MlflowClient()
    run = client.create_run(ensure_experiment(experiment), run_name=run_name)
    for k, v in (params or {}).items():
        client.log_param(run.info.run_id, k, str(v))
    return run.info.run_id


def end_run(run_id: str, status: str = "FINISHED", metrics: dict | None = None) -> None:
    _mlflow()
    from mlflow.tracking import MlflowClient

    client = MlflowClient()
    for k, v in (metrics or {}).items():
        client.log_metric(run_id, k, float(v))
    client.set_terminated(run_id, status=status)


#: Per-model metrics of a comparison's parent run, logged as ``<metric>/<model>``.
COMPARISON_METRICS = ("test_rmse", "test_r2", "train_rmse", "fit_time_s", "n_parameters", "resid_acf_outside_pct",
                      "resid_xcorr_outside_pct")


def log_comparison(parent_run_id: str, models: dict[str, FrictionModel], record: AxisRecord,
                   rows: list[dict], label: str = "test record") -> dict[str, ResidualAnalysis]:
    """Make a parent run the comparison dashboard of its child fits.

    Logs on ``parent_run_id``: metrics ``<metric>/<model>`` for every row and every name in
    :data:`COMPARISON_METRICS` (test RMSE [Nm], R^2 [-], fit time [s], parameter count [-],
    shares of residual-correlation lags outside their bands [%]), ``best_test_rmse`` [Nm], the
    tag ``best_model``, the table ``comparison.json`` (MLflow table artifact) and a markdown
    summary as the run's description; plots ``plots/prediction_overlay.png`` (every model's
    prediction over the measurement) and ``plots/residual_analysis.png`` (all models' residual
    correlations with their bands). Returns the residual analyses by model name.
    """
    _mlflow()  # configured tracking store
    import matplotlib.pyplot as plt
    from mlflow.entities import Metric
    from mlflow.tracking import MlflowClient

    client = MlflowClient()
    preds = {name: model.predict(record) for name, model in models.items()}
    analyses = {name: analyse_residual(record, pred) for name, pred in preds.items()}
    now = int(1000 * __import__("time").time())
    metrics = []
    for row in rows:
        extra = analyses[row["model"]].metrics() if row["model"] in analyses else {}
        for key in COMPARISON_METRICS:
            value = row.get(key, extra.get(key))
            if value is not None:
                metrics.append(Metric(f"{key}/{row['model']}", float(value), now, 0))
    best = min(rows, key=lambda r: r["test_rmse"])
    metrics.append(Metric("best_test_rmse", float(best["test_rmse"]), now, 0))
    client.log_batch(parent_run_id, metrics=metrics)
    client.set_tag(parent_run_id, "best_model", best["model"])
    cells = []
    table = []
    for i, row in enumerate(sorted(rows, key=lambda r: r["test_rmse"]), 1):
        a = analyses.get(row["model"])
        outside = a.auto_outside_pct if a else float("nan")
        cells.append((i, row["model"], f"{row['test_rmse']:.4f}", f"{row['test_r2']:.5f}", f"{row['fit_time_s']:.1f}",
                      f"{outside:.0f}"))
        table.append({"rank": i, "model": row["model"], "test_rmse_nm": row["test_rmse"], "test_r2": row["test_r2"],
                      "train_rmse_nm": row.get("train_rmse"), "fit_time_s": row["fit_time_s"],
                      "n_parameters": row.get("n_parameters"), "resid_acf_outside_pct": outside,
                      "resid_xcorr_outside_pct": a.cross_outside_pct if a else float("nan"),
                      "run_id": row.get("run_id")})
    lines = [f"Comparison of {len(rows)} friction models on the {label}, sorted by test RMSE.", ""]
    lines += markdown_table(("rank", "model", "test RMSE [Nm]", "test R^2", "fit time [s]",
                             "residual ACF outside band [%]"), cells)
    client.set_tag(parent_run_id, "mlflow.note.content", "\n".join(lines))
    client.log_table(parent_run_id, data=pd.DataFrame(table), artifact_file="comparison.json")
    client.log_dict(parent_run_id, {name: {"record": label, **a.to_dict()} for name, a in analyses.items()},
                    "residual_analysis.json")
    for fname, fig in (("prediction_overlay.png", overlay_figure(record, preds, label)),
                       ("residual_analysis.png", residual_figure(analyses, title=f"all models on the {label}"))):
        client.log_figure(parent_run_id, fig, f"plots/{fname}")
        plt.close(fig)
    return analyses


class _Progress(Protocol):
    def __call__(self, n: float = 1) -> None: ...

    def describe(self, text: str) -> None: ...


def compare_models(models: list[FrictionModel], train: AxisRecord, test: AxisRecord, *, track: bool = True,
                   experiment: str = "compare", axis: int = 1, robot: str | None = None,
                   advance: _Progress | None = None, params: dict | None = None) -> tuple[list[dict], str | None]:
    """Fit every (unfitted) model on ``train`` and score it on ``test``: rows ``{"model", "test_rmse",
    "test_r2", "train_rmse", "train_r2", "fit_time_s", "n_parameters"[, "run_id"]}`` (RMSE in the
    record's torque unit, times in s) sorted by test RMSE, and the parent run id (None without
    ``track``). With ``track`` each fit is a child run of one parent run in ``experiment``, and the
    parent logs the comparison (:func:`log_comparison`); a failure marks the parent FAILED.
    ``advance`` (``advance(n)``, ``advance.describe(text)``) is told of every model and log."""
    import time

    names = [m.name for m in models]
    parent = None
    if track:
        parent = start_parent_run(experiment, "compare", {**(params or {}), "models": ",".join(names),
                                                          "axis": axis, "robot": robot or ""})
    rows: list[dict[str, Any]] = []
    fitted = {}
    try:
        for i, est in enumerate(models, 1):
            if advance:
                advance.describe(f"fitting {est.name}, model {i} of {len(models)}")
            t0 = time.perf_counter()
            est.fit(train)
            fit_time = time.perf_counter() - t0
            te = est.score(test)
            row = {"model": est.name, "test_rmse": te.rmse, "test_r2": te.r2, "train_rmse": est.train_metrics_.rmse,
                   "train_r2": est.train_metrics_.r2, "fit_time_s": fit_time, "n_parameters": est.n_parameters()}
            if parent is not None:
                if advance:
                    advance.describe(f"logging {est.name} to MLflow")
                run = log_fit(est, train, test, fit_time=fit_time, experiment=experiment, axis=axis, robot=robot,
                              parent_run_id=parent, extra_params=record_params(train))
                row["run_id"] = run.run_id
                fitted[est.name] = est
            rows.append(row)
            if advance:
                advance(1)
        if parent is not None:
            if advance:
                advance.describe("logging the comparison (overlay, residual analysis) to MLflow")
            log_comparison(parent, fitted, test, rows)
            if advance:
                advance(1)
    except BaseException:
        if parent:
            end_run(parent, status="FAILED")
        raise
    rows.sort(key=lambda r: r["test_rmse"])
    if parent:
        end_run(parent)
    return rows, parent


def fit_axes(make: Callable[[], FrictionModel], train: dict[int, Path], test: dict[int, Path] | None = None, *,
             experiment: str = "train-robot", robot: str = "", register: bool = True,
             advance: _Progress | None = None, params: dict | None = None) -> tuple[list[dict], str]:
    """Fit one new model (``make()``) per axis on the axis records ``train[axis]`` and score it on
    ``test[axis]``: one child run per axis (registered as ``<robot>-axis<N>-friction`` with
    ``register``) under one parent run of ``experiment``. Rows ``{"axis", "train_rmse", "train_r2",
    "fit_time_s"[, "test_rmse", "test_r2"], "run_id", ...}`` (RMSE in Nm, times in s) in axis order,
    and the parent run id; a failure marks the parent FAILED."""
    import time

    axes = sorted(train)
    kind = make().name
    parent = start_parent_run(experiment, f"train-robot {robot} {kind}",
                              {**(params or {}), "robot": robot, "model": kind, "axes": ",".join(map(str, axes))})
    rows = []
    try:
        for a in axes:
            if advance:
                advance.describe(f"axis {a}: fitting and logging")
            rec = load_record(train[a])
            rec_t = load_record(test[a]) if test else None
            est = make()
            t0 = time.perf_counter()
            est.fit(rec)
            fit_time = time.perf_counter() - t0
            run = log_fit(est, rec, rec_t, fit_time=fit_time, experiment=experiment, axis=a, robot=robot,
                          run_name=f"{kind} axis {a}", parent_run_id=parent,
                          register=registered_name(robot, a) if register else None)
            row = {"axis": a, "train_rmse": est.train_metrics_.rmse, "train_r2": est.train_metrics_.r2,
                   "fit_time_s": fit_time, **run.to_dict()}
            if rec_t is not None:
                m = est.score(rec_t)
                row.update(test_rmse=m.rmse, test_r2=m.r2)
            rows.append(row)
            if advance:
                advance(1)
    except BaseException:
        end_run(parent, status="FAILED")
        raise
    end_run(parent)
    return rows, parent
