"""The identification workflows behind the ``greybench`` friction commands: checked inputs in, files
and MLflow runs written, typed results out; the caller parses the options and prints (SI inside).

Every workflow checks its inputs before any work (``InputError`` naming the file or the CLI option)
and reports progress to an :class:`identify.progress.Advance` (silent by default). Heavy modules
(pandas, MLflow, torch) are imported inside the functions.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from identify.errors import InputError
from identify.progress import Advance, Progress, quiet

if TYPE_CHECKING:
    import subprocess

    import pandas as pd

    from identify.axis_limits import AxisLimits
    from identify.diagnosis import DiagnosisResult, SavedDiagnosis
    from identify.metrics import Metrics
    from identify.models import FrictionModel
    from identify.plant import Effect, SynthResult
    from identify.records import AxisRecord
    from identify.tracking import FitRun
    from identify.trajectories import Trajectory

#: The six models of the paper's comparison, in the order of the workflow.
COMPARE_MODELS = ("coulomb-viscous", "stribeck", "lugre", "lstm", "residual", "greybox")


class Table(NamedTuple):
    """A result table for a command to print: title, column headers (units in brackets), rows and how
    many leading columns are left-aligned (the others right). Rich markup: ``\\[s]`` is a literal ``[s]``."""

    title: str
    columns: Sequence[str]
    rows: list[Sequence[object]]
    left: int = 1


def metrics_table(title: str, metrics: dict[str, Metrics], unit: str) -> Table:
    """RMSE and max error [``unit``: the record's torque unit], R^2 [-], NRMSE [-] and samples per record."""
    return Table(title, ("record", f"RMSE [{unit}]", "R^2", "NRMSE", f"max error [{unit}]", "samples"),
                 [(k, f"{m.rmse:.4f}", f"{m.r2:.5f}", f"{m.nrmse:.4f}", f"{m.max_error:.4f}", m.n)
                  for k, m in metrics.items()])


def params_table(est: FrictionModel) -> Table:
    """A fitted model's parameters with their units."""
    units = est.param_units()
    return Table(f"{est.name} parameters", ("parameter", "value", "unit"),
                 [(k, f"{v:.6g}", units.get(k, "")) for k, v in est.params_.items()])


def compare_table(rows: list[dict[str, Any]], test: Path, axis: int, unit: str) -> Table:
    """The ranking of :func:`identify.tracking.compare_models`: RMSE [``unit``], R^2 [-], fit time [s]."""
    return Table(f"compare on {test} (axis {axis}), sorted by test RMSE",
                 ("rank", "model", f"test RMSE \\[{unit}]", "test R^2", f"train RMSE \\[{unit}]", "fit time \\[s]",
                  "parameters"),
                 [(i, r["model"], f"{r['test_rmse']:.4f}", f"{r['test_r2']:.5f}", f"{r['train_rmse']:.4f}",
                   f"{r['fit_time_s']:.1f}", r["n_parameters"]) for i, r in enumerate(rows, 1)], left=2)


def train_robot_table(rows: list[dict[str, Any]], robot: str, model: str, parent: str | None) -> Table:
    """One row per axis of :func:`simulate.run.train_robot`: RMSE [Nm], R^2 [-], fit time [s], the run."""
    return Table(f"train-robot {robot}: {model} per axis (parent run {parent})",
                 ("axis", "train RMSE [Nm]", "train R^2", "test RMSE [Nm]", "fit time \\[s]", "registered", "run"),
                 [(r["axis"], f"{r['train_rmse']:.4f}", f"{r['train_r2']:.4f}",
                   f"{r['test_rmse']:.4f}" if "test_rmse" in r else "-", f"{r['fit_time_s']:.1f}",
                   f"{r['registered']} v{r['version']} ({r['alias']})" if r["registered"] else "-", r["run_id"])
                  for r in rows])


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


def trajectory_text(traj: Trajectory, limits: AxisLimits, out_file: Path) -> str:
    """Samples, duration [s] and the peaks of position [rad], velocity [rad/s], acceleration
    [rad/s^2] and jerk [rad/s^3] of a trajectory against the axis's limits."""
    p = traj.peaks()
    return (f"{traj.t.size} samples over {traj.t[-1]:.1f} s -> {out_file}\n"
            f"  position {p['q_min']:.4f}..{p['q_max']:.4f} rad, |qd| <= {p['qd']:.3f} rad/s "
            f"(limit {limits.vmax:.3f}), |qdd| <= {p['qdd']:.3f} rad/s^2 (limit {limits.amax:.3f}), "
            f"|jerk| <= {p['qddd']:.2f} rad/s^3 (limit {limits.jmax:.2f})")


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


def parse_joints(text: str, field: str = "--axes") -> list[int]:
    """Comma-separated joint numbers (``1,2,3``), sorted and without repeats; ``InputError`` naming ``field``."""
    try:
        axes = sorted({int(a) for a in text.split(",") if a.strip()})
    except ValueError:
        raise InputError(f"not a list of joint numbers: {text!r}", field=field) from None
    if not axes:
        raise InputError("no axis given", field=field)
    return axes


def load_pair(train: Path, test: Path | None, axis: int | None, *, linear: bool = False,
              cutoff: float | None = None) -> tuple[AxisRecord, AxisRecord | None]:
    """A training and an optional test record (joint ``axis`` of robot logs, errors naming ``--axis``);
    ``linear`` declares a linear axis (m, N). The test record is differentiated like the training
    record (``cutoff`` [Hz], else the one chosen for it): the model learns on that filter."""
    from identify.records import load_axis_record

    if axis is not None and axis < 1:
        raise InputError(f"axis must be >= 1, got {axis}", field="--axis")
    train_rec = load_axis_record(train, axis, linear=True if linear else None, cutoff_hz=cutoff, axis_field="--axis")
    test_rec = (load_axis_record(test, axis, linear=train_rec.linear, cutoff_hz=cutoff or train_rec.cutoff_hz,
                                 axis_field="--axis") if test is not None else None)
    return train_rec, test_rec


def record_warnings(*records: AxisRecord | None) -> list[str]:
    """The records' own warnings (axis kind assumed or contradicted, :func:`identify.records.axis_kind_warnings`),
    each once, in order."""
    return list(dict.fromkeys(w for r in records if r is not None for w in r.warnings))


@dataclass
class FitOutcome:
    """What :func:`fit_model` gives: the fit time [s], the metrics per record (``train``, ``test``;
    RMSE in the record's torque unit) and the MLflow run (None without tracking)."""

    fit_time: float
    metrics: dict[str, Metrics] = field(default_factory=dict)
    run: FitRun | None = None

    def run_text(self) -> str:
        """The MLflow run, its model and, when registered, the version and alias ('' without a run)."""
        run = self.run
        if run is None:
            return ""
        reg = f"; registered {run.registered} v{run.version} as {run.alias}" if run.registered else ""
        return f"MLflow run {run.run_id} (experiment {run.experiment}): model {run.model_uri}{reg}"

    def to_dict(self, model: str, est: FrictionModel, train: AxisRecord, warnings: Sequence[str] = (),
                out_dir: Path | None = None) -> dict[str, Any]:
        """The ``fit --json`` object: the fitted parameters with their units, fit time [s], the
        record's derivative cut-off [Hz], the run and the metrics per record (``train``, ``test``)."""
        return {"model": model, "params": est.params_, "units": est.param_units(), "fit_time": self.fit_time,
                "n_parameters": est.n_parameters(), "warnings": list(warnings), "derivative_cutoff_hz": train.cutoff_hz,
                "linear": train.linear, "out": str(out_dir) if out_dir else None,
                "run": self.run.to_dict() if self.run else None, **{k: v.to_dict() for k, v in self.metrics.items()}}


#: Characters a registered-model name is made of (others in a record's file name become ``-``).
_NAME_CHARS = r"A-Za-z0-9._-"


def fit_model_name(train: Path, axis: int, robot: str | None = None, name: str | None = None) -> str:
    """The registered-model name of a fit: ``name`` when given (``--name``); ``<robot>-axis<N>-friction``
    for an axis of a robot (``--robot``: the name the simulation looks up); else from the record,
    ``<file stem>-axis<N>-friction``, so a drive's model never takes the demo robot's name."""
    import re

    if name is not None:
        if not name or re.search(f"[^{_NAME_CHARS}]", name):
            raise InputError(f"not a model name: {name!r} (use letters, digits, '.', '_', '-')", field="--name")
        return name
    if robot:
        return f"{robot}-axis{axis}-friction"
    stem = re.sub(f"[^{_NAME_CHARS}]+", "-", Path(train).stem).strip("-.") or "record"
    return f"{stem}-axis{axis}-friction"


def fit_model(est: FrictionModel, train: AxisRecord, test: AxisRecord | None = None, *, out_dir: Path | None = None,
              track: bool = True, experiment: str = "friction", axis: int = 1, robot: str | None = None,
              register: bool = True, name: str | None = None, advance: Advance | None = None) -> FitOutcome:
    """Fit ``est`` on ``train``, score it on ``test``, save it into ``out_dir`` and, with ``track``, log
    it as an MLflow run (:func:`identify.tracking.log_fit`), registered as ``name`` (default
    ``<robot>-axis<N>-friction``; :func:`fit_model_name`) with alias challenger when ``register``."""
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
                              robot=robot, register=(name or registered_name(robot or "", axis)) if register else None,
                              extra_params=record_params(train))
    return outcome


def predict_record(est: FrictionModel, rec: AxisRecord, out_file: Path, source: str = "") -> tuple[pd.DataFrame,
                                                                                                   Metrics]:
    """Write the record's columns plus ``tau_friction_pred`` (the friction) and ``tau_pred`` (the total
    joint torque, comparable to ``tau``) [Nm; N on a linear axis] to ``out_file``; gives the table and
    the metrics of ``tau_pred`` against ``tau``. A model fitted on the other axis kind is refused. A
    record whose axis kind was declared (unit headers, or linear) gets unit headers on every record
    column (``q [m]``, ``tau_pred [N]``), so reading the output back gives the same axis kind; an
    undeclared rotary record keeps its plain headers."""
    from identify.records import write_table

    if bool(getattr(est, "linear_", False)) != rec.linear:
        raise InputError(f"mixed units: the model was fitted on a {'rotary' if rec.linear else 'linear'} axis and "
                         f"the record is {'linear' if rec.linear else 'rotary'}", source=source, field="q")
    friction, tau_pred = est.predict_parts(rec)
    assert rec.frame is not None  # records read from a file keep their frame
    frame = rec.frame.copy()
    frame["tau_friction_pred"] = friction
    frame["tau_pred"] = tau_pred
    if rec.linear or rec.kind_declared:
        # the axis kind travels with the table: read back, it is the same record (a linear one without
        # headers would come back rotary)
        units = rec.units
        frame = frame.rename(columns={c: f"{c} [{units[c]}]" for c in frame.columns if c in units})
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


@dataclass(frozen=True)
class UIRun:
    """How :func:`run_ui` ended: the UI's URL, whether it answered, and its exit code."""

    url: str
    answered: bool
    code: int


def run_ui(host: str, port: int, on_ready: Callable[[str], None], progress: Progress = quiet) -> UIRun:
    """Start the MLflow UI on the tracking store (:func:`identify.tracking_store.ui_command`; its own messages
    go to stderr), call ``on_ready(url)`` once it answers and run it until it exits or Ctrl-C stops it;
    stop it at once when it does not answer (a taken port)."""
    import subprocess

    from identify.tracking_store import ui_command

    if not 0 < port < 65536:
        raise InputError("must be 1..65535", field="--port")
    local = {"0.0.0.0": "127.0.0.1", "::": "[::1]"}.get(host, f"[{host}]" if ":" in host else host)
    url = f"http://{local}:{port}/"
    proc = subprocess.Popen(ui_command(host, port), stdout=2)
    try:
        with progress(f"starting the MLflow UI on port {port}", None):
            up = wait_until_answers(url, proc)
        if not up:
            proc.terminate()
            return UIRun(url, False, proc.wait())
        on_ready(url)
        return UIRun(url, True, proc.wait())
    except KeyboardInterrupt:
        proc.terminate()
        return UIRun(url, True, proc.wait())


@dataclass(frozen=True)
class Diagnosed:
    """What :func:`diagnose_files` gives: the training record (its derivative note), the diagnosis and
    where it was saved."""

    train: AxisRecord
    result: DiagnosisResult
    saved: SavedDiagnosis

    def table(self, threshold: float) -> Table:
        """Every candidate: its held-out gain and gain alone [m<torque unit>], the decision and why (the
        untested ones last); ``threshold`` [-] as given (a share of the noise RMS)."""
        res, a = self.result, self.result.analysis
        mu = f"m{a.unit}"  # escaped: rich would read "[mNm]" as markup
        return Table(f"diagnosis: {res.cause.value} (threshold {a.threshold * 1e3:.3g} {mu} held-out RMS = "
                     f"{threshold:g} x noise RMS {a.noise * 1e3:.3g} {mu})",
                     ("cause", f"held-out gain \\[{mu}]", f"alone \\[{mu}]", "decision", "why"),
                     [*[(s.cause.value, f"{s.score * 1e3:+.2f}", f"{s.alone * 1e3:+.2f}", s.verdict.value, s.why)
                        for s in a.ranking],
                      *[(c.value, "-", "-", "not tested", why) for c, why in a.excluded.items()]])

    def gain_text(self) -> str:
        """Test RMSE [torque unit] of the baseline and the extended model, the gain [%], the report."""
        res, unit = self.result, self.result.analysis.unit
        return (f"baseline {res.baseline.name}: test RMSE {res.baseline_test.rmse:.5g} {unit}; extended "
                f"{res.extended_label}: test RMSE {res.extended_test.rmse:.5g} {unit}; gain {res.gain * 100:+.1f} %\n"
                f"report: {self.saved.report}")


#: The steps :func:`diagnose_files` reports, one each (the diagnosis's stages, then saving).
DIAGNOSE_STEPS = ("baseline fit", "held-out tests", "extended refit", "saving the report, plots and runs")


def diagnose_files(train: Path, test: Path, out_dir: Path, *, seed: int = 0, generations: int = 30,
                   threshold: float | None = None, track: bool = True, linear: bool = False,
                   cutoff: float | None = None, advance: Advance | None = None,
                   on_warnings: Callable[[list[str]], None] | None = None) -> Diagnosed:
    """Diagnose a friction record pair (:func:`identify.diagnosis.diagnose`: baseline fit, held-out
    tests, extended refit) and save it into ``out_dir`` (:func:`identify.diagnosis.save_diagnosis`,
    with MLflow runs when ``track``). ``threshold`` [-] as a share of the held-out noise RMS (default
    :data:`identify.diagnosis.SCORE_THRESHOLD`); ``cutoff`` [Hz] for records without qd/qdd;
    ``on_warnings`` gets the records' warnings (:func:`record_warnings`) before the long work starts;
    ``advance`` is told each of :data:`DIAGNOSE_STEPS` and advanced by one as each ends."""
    from identify.diagnosis import SCORE_THRESHOLD, diagnose, save_diagnosis
    from identify.records import load_record, record_params

    threshold = SCORE_THRESHOLD if threshold is None else threshold
    if generations < 1:
        raise InputError("must be >= 1", field="--generations")
    if not threshold >= 0:
        raise InputError("must be >= 0", field="--threshold")
    train_rec = load_record(train, linear=True if linear else None, cutoff_hz=cutoff)
    test_rec = load_record(test, linear=train_rec.linear, cutoff_hz=cutoff or train_rec.cutoff_hz)
    if (train_rec.tau_rb is None) != (test_rec.tau_rb is None):
        raise InputError("both records need a 'tau_rb' column, or neither", source=str(test), field="tau_rb")
    if on_warnings is not None:
        on_warnings(record_warnings(train_rec, test_rec))
    adv = advance if advance is not None else Advance()
    result = diagnose(train_rec, test_rec, seed=seed, generations=generations, threshold=threshold, advance=adv)
    adv.describe(DIAGNOSE_STEPS[-1])
    saved = save_diagnosis(result, train_rec, test_rec, out_dir, track=track, extra_params=record_params(train_rec))
    adv(1)
    return Diagnosed(train_rec, result, saved)
