"""The Python API: the workflows of the ``greybench`` commands as functions with typed options and results.

Each entry point takes its files, an options dataclass (every field with its unit and the command's
default; keyword arguments override single fields) and a :data:`identify.progress.Progress` factory
(quiet by default), and gives a result dataclass. The commands parse their options into the same
dataclasses and call the same functions, so a script and the console run the same work with the same
defaults (``tests/examples/test_api.py`` checks the defaults). Bad input raises
:class:`identify.errors.InputError` naming the file, line, column or option, before any work.

SI units inside; options in the command's units say so in their names (``spacing_mm``, ``radius_mm``,
``feed_mm_min``). Heavy modules (numba, torch, MLflow, pandas) are imported when a function runs.

    import greybench
    fit = greybench.fit_friction("lugre", "train.csv", "test.csv", out_dir="model")
    ranked = greybench.rank_placements("data/programs/iso160.nc", "data/poses/iso160.json",
                                       size=160, friction={1: "model"})
    print(ranked.best, ranked.scores)
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

from identify.progress import Progress, quiet
from identify.workflows import COMPARE_MODELS
from simulate import defaults
from simulate.compensation.settings import CompensationSettings

if TYPE_CHECKING:
    from identify.axis_limits import AxisLimits
    from identify.metrics import Metrics
    from identify.models import FrictionModel
    from identify.plant import SynthResult
    from identify.records import AxisRecord
    from identify.tracking import FitRun
    from identify.trajectories import Trajectory
    from identify.workflows import FitOutcome
    from simulate.evaluation.circle import CircleResult
    from simulate.evaluation.ranking import Ranking
    from simulate.explain.pipeline import Explanation

__all__ = ["CircleOptions", "CircleTestResult", "CompareOptions", "ComparisonResult", "CompensationOptions",
           "CompensationResult", "ExplainOptions", "ExplanationResult", "FitOptions", "FitResult", "RankOptions",
           "RankingResult", "TrajectoryResult", "circle_test", "compare_friction", "compensate_program", "explain_part",
           "fit_friction", "rank_placements", "synthesize", "trajectory"]

#: m per mm, and mm per m (the defaults in mm as the commands compute them).
_MM = 1e-3
_MM_PER_M = 1e3

PathLike = str | Path
_O = TypeVar("_O")


def _options(cls: type[_O], options: _O | None, overrides: Mapping[str, Any]) -> _O:
    """``options`` (or the defaults of ``cls``) with ``overrides`` replacing single fields; an unknown
    name is a ``TypeError`` naming it and the fields."""
    known = {f.name for f in fields(cls)}  # type: ignore[arg-type]  # cls is a dataclass
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise TypeError(f"{cls.__name__} has no field {', '.join(unknown)} (fields: {', '.join(sorted(known))})")
    base = options if options is not None else cls()
    return replace(base, **overrides) if overrides else base  # type: ignore[type-var]


def _path(p: PathLike | None) -> Path | None:
    return None if p is None else Path(p)


# ---- friction identification ---------------------------------------------------------------------
@dataclass(frozen=True)
class TrajectoryResult:
    """What :func:`trajectory` gives.

    Attributes
    ----------
    trajectory : Trajectory
        Samples ``t`` [s], ``q`` [rad], ``qd`` [rad/s], ``qdd`` [rad/s^2].
    limits : AxisLimits
        The axis's limits it keeps within (position [rad], vmax [rad/s], amax [rad/s^2], jmax [rad/s^3]).
    out_file : Path
        The table written.
    """

    trajectory: Trajectory
    limits: AxisLimits
    out_file: Path

    def to_dict(self, kind: str, axis: int) -> dict[str, Any]:
        """The ``greybench trajectory --json`` object: samples, duration [s], peaks and limits (SI)."""
        traj = self.trajectory
        return {"kind": kind, "axis": axis, "samples": int(traj.t.size), "duration": float(traj.t[-1]),
                "peaks": traj.peaks(), "limits": self.limits.__dict__, "out": str(self.out_file)}


def trajectory(kind: Literal["universal", "test", "stribeck", "presliding"], out_file: PathLike, *, axis: int = 1,
               robot: str = "max100", duration_s: float = 60.0, rate_hz: float = 1000.0) -> TrajectoryResult:
    """An excitation trajectory of ``kind`` within the position [rad], velocity [rad/s], acceleration
    [rad/s^2] and jerk [rad/s^3] limits of joint ``axis`` of ``robot`` (a name in ``data/robots`` or a
    TOML path), ``duration_s`` [s] long (not for ``stribeck``, whose steps set it) sampled at
    ``rate_hz`` [Hz], written to ``out_file`` (.csv or .parquet: t [s], q [rad], qd [rad/s], qdd
    [rad/s^2]); ``greybench trajectory``."""
    from identify import workflows as wf
    from identify.axis_limits import load_axis_limits
    from identify.records import write_table
    from simulate.run import resolve_robot

    limits = load_axis_limits(resolve_robot(robot), axis)
    traj = wf.make_trajectory(kind, limits, duration_s, rate_hz)
    write_table(traj.to_frame(), Path(out_file))
    return TrajectoryResult(traj, limits, Path(out_file))


def synthesize(trajectory_file: PathLike, out_file: PathLike, *, seed: int = 0, static_curve: str | None = None,
               noise_nm: float | None = None, effect: str = "none", magnitude: float = 1.0,
               config: PathLike | None = None, positions_only: bool = False) -> SynthResult:
    """A synthetic axis record of the plant (inertia, LuGre friction, sensor noise ``noise_nm`` [Nm]
    standard deviation, an optional hidden ``effect``) following a trajectory table, written to
    ``out_file``: t [s], q [rad], qd [rad/s], qdd [rad/s^2], tau [Nm], temp [degC], tau_load [Nm];
    ``greybench synth`` (:func:`identify.workflows.synth_record`). The result holds the plant's
    parameters (``config``) and the table (``frame``)."""
    from identify.workflows import synth_record

    return synth_record(Path(trajectory_file), Path(out_file), config=_path(config), static_curve=static_curve,
                        noise=noise_nm, effect=effect, magnitude=magnitude, seed=seed, positions_only=positions_only)


@dataclass(frozen=True)
class FitOptions:
    """How :func:`fit_friction` fits (``greybench fit``'s options).

    Attributes
    ----------
    axis : int or None
        Joint N >= 1 of a robot log (``q<N>``, ``tau<N>``); names the registered model. None: 1.
    robot : str or None
        Robot name or TOML path whose axis the record is: the model registers as
        ``<robot>-axis<N>-friction`` (the name the simulation looks up). None: no robot (the
        arm-coupling warning checks max100).
    name : str or None
        Registered-model name (default from ``robot`` or the record's file name).
    cutoff_hz : float or None
        Derivative cut-off [Hz] for records without qd/qdd (None: chosen from the record).
    linear : bool
        A linear axis: q [m], tau [N].
    seed : int
        Random seed [-].
    epochs : int or None
        Adam epochs [passes] of a learned model (None: the model's default).
    experiment : str
        MLflow experiment.
    track : bool
        Log the fit as an MLflow run (``MLFLOW_TRACKING_URI``, default ``./mlruns.db``).
    register : bool
        Register the tracked fit with alias ``challenger``.
    """

    axis: int | None = None
    robot: str | None = None
    name: str | None = None
    cutoff_hz: float | None = None
    linear: bool = False
    seed: int = 0
    epochs: int | None = None
    experiment: str = "friction"
    track: bool = True
    register: bool = True


@dataclass(frozen=True)
class FitResult:
    """What :func:`fit_friction` gives.

    Attributes
    ----------
    model : str
        The model type (``lugre``, ...).
    estimator : FrictionModel
        The fitted model: ``params_`` (units in ``param_units()``), ``predict``, ``save``.
    train, test : AxisRecord, AxisRecord or None
        The records as read (SI; ``cutoff_hz`` [Hz] of the derivatives).
    outcome : FitOutcome
        Fit time [s], metrics per record (RMSE, max error in the record's torque unit [Nm or N]) and
        the MLflow run.
    warnings : list of str
        Doubts about the records (axis kind assumed, an axis the arm loads).
    registered_name : str
        The registered-model name (used when tracked and registered).
    out_dir : Path or None
        Where the model was saved.
    """

    model: str
    estimator: FrictionModel
    train: AxisRecord
    test: AxisRecord | None
    outcome: FitOutcome
    warnings: list[str]
    registered_name: str
    out_dir: Path | None = None

    @property
    def params(self) -> dict[str, float]:
        """The fitted parameters (SI; units in :attr:`units`)."""
        return dict(self.estimator.params_)

    @property
    def units(self) -> dict[str, str]:
        """The unit of each parameter."""
        return dict(self.estimator.param_units())

    @property
    def metrics(self) -> dict[str, Metrics]:
        """``train`` and ``test`` metrics of the total torque (RMSE [Nm], R^2 [-], NRMSE [-])."""
        return self.outcome.metrics

    @property
    def run(self) -> FitRun | None:
        """The MLflow run (None without tracking)."""
        return self.outcome.run

    def to_dict(self) -> dict[str, Any]:
        """The ``greybench fit --json`` object."""
        return self.outcome.to_dict(self.model, self.estimator, self.train, self.warnings, self.out_dir)


def fit_friction(model: str, train: PathLike, test: PathLike | None = None, *, out_dir: PathLike | None = None,
                 options: FitOptions | None = None, progress: Progress = quiet,
                 on_loaded: Callable[[AxisRecord, list[str]], None] | None = None, **overrides: Any) -> FitResult:
    """Fit a friction model of type ``model`` (:data:`identify.models.MODELS`) on the axis record
    ``train`` (t [s], q [rad], tau [Nm], optional qd, qdd, temp, tau_rb, tau_load; or a robot log with
    ``axis``), co-identifying an inertia J [kg m^2] and offset c [Nm] unless the record has tau_rb;
    score it on ``test``, save it into ``out_dir`` and log it to MLflow (``greybench fit``).

    ``on_loaded(train_record, warnings)`` is called once the records are read, before the fit (the
    command prints the warnings and the derivative note there). Progress: one step, ``fit <model>``.
    """
    from identify import workflows as wf
    from identify.models import make_seeded
    from simulate.coupling import coupling_warnings
    from simulate.run import resolve_robot

    o = _options(FitOptions, options, overrides)
    est = make_seeded(model, o.seed, o.epochs, model_field="--model", epochs_field="--epochs")
    train_p, out_p = Path(train), _path(out_dir)
    robot_file = resolve_robot(o.robot or "max100")
    robot = robot_file.stem if o.robot else None
    name = wf.fit_model_name(train_p, o.axis or 1, robot, o.name)
    train_rec, test_rec = wf.load_pair(train_p, _path(test), o.axis, linear=o.linear, cutoff=o.cutoff_hz)
    warnings = [*wf.record_warnings(train_rec, test_rec), *coupling_warnings(train_rec, robot_file, o.axis)]
    if on_loaded is not None:
        on_loaded(train_rec, warnings)
    with progress(f"fit {model}", None) as advance:
        outcome = wf.fit_model(est, train_rec, test_rec, out_dir=out_p, track=o.track, experiment=o.experiment,
                               axis=o.axis or 1, robot=robot, register=o.register, name=name, advance=advance)
    return FitResult(model, est, train_rec, test_rec, outcome, warnings, name, out_p)


@dataclass(frozen=True)
class CompareOptions:
    """How :func:`compare_friction` compares (``greybench compare``'s options).

    Attributes
    ----------
    models : sequence of str, str or None
        Model types, or one comma-separated string (None: the six of the paper,
        :data:`identify.workflows.COMPARE_MODELS`).
    axis, cutoff_hz, linear, seed, epochs, experiment, track
        As :class:`FitOptions` (``cutoff_hz`` [Hz], ``epochs`` [passes]).
    robot : str
        Robot name or TOML path, recorded in the runs.
    """

    models: Sequence[str] | None = None
    axis: int | None = None
    cutoff_hz: float | None = None
    linear: bool = False
    robot: str = "max100"
    seed: int = 0
    epochs: int | None = None
    experiment: str = "compare"
    track: bool = True


@dataclass(frozen=True)
class ComparisonResult:
    """What :func:`compare_friction` gives.

    Attributes
    ----------
    rows : list of dict
        Per model, best first: ``model``, ``test_rmse``, ``train_rmse`` [record's torque unit],
        ``test_r2``, ``train_r2`` [-], ``fit_time_s`` [s], ``n_parameters`` and ``run_id``.
    parent_run_id : str or None
        The MLflow parent run (None without tracking).
    experiment : str or None
        The MLflow experiment (None without tracking).
    axis : int
        The joint compared.
    unit : str
        The torque unit of the RMSE columns (Nm, or N on a linear axis).
    warnings : list of str
        Doubts about the records.
    """

    rows: list[dict[str, Any]]
    parent_run_id: str | None
    experiment: str | None
    axis: int
    unit: str
    warnings: list[str] = field(default_factory=list)

    @property
    def best(self) -> str:
        """The model with the lowest test RMSE."""
        return str(self.rows[0]["model"])

    def to_dict(self) -> dict[str, Any]:
        """The ``greybench compare --json`` object."""
        return {"experiment": self.experiment, "parent_run_id": self.parent_run_id, "axis": self.axis,
                "rows": self.rows}


def compare_friction(train: PathLike, test: PathLike, *, options: CompareOptions | None = None,
                     progress: Progress = quiet, on_loaded: Callable[[AxisRecord, list[str]], None] | None = None,
                     **overrides: Any) -> ComparisonResult:
    """Fit several friction models on ``train`` and rank them by the test RMSE [Nm] on ``test``
    (records as :func:`fit_friction` reads them); with ``track`` one MLflow parent run with a child
    run per model (``greybench compare``). ``on_loaded`` as in :func:`fit_friction`. Progress: one
    step per model and one for the comparison's log."""
    from identify import workflows as wf
    from identify.models import make_seeded, parse_model_names
    from identify.tracking import compare_models
    from simulate.run import resolve_robot

    o = _options(CompareOptions, options, overrides)
    text = o.models if isinstance(o.models, str) or o.models is None else ",".join(o.models)
    names = parse_model_names(text, COMPARE_MODELS, "--models")
    train_p, test_p = Path(train), Path(test)
    train_rec, test_rec = wf.load_pair(train_p, test_p, o.axis, linear=o.linear, cutoff=o.cutoff_hz)
    assert test_rec is not None
    warnings = wf.record_warnings(train_rec, test_rec)
    if on_loaded is not None:
        on_loaded(train_rec, warnings)
    robot_name = resolve_robot(o.robot).stem
    models = [make_seeded(n, o.seed, o.epochs, model_field="--model", epochs_field="--epochs")
              for n in names]  # unknown names and bad epochs fail first
    with progress("compare", len(names) + (1 if o.track else 0)) as advance:
        rows, parent = compare_models(models, train_rec, test_rec, track=o.track, experiment=o.experiment,
                                      axis=o.axis or 1, robot=robot_name, advance=advance,
                                      params={"train_file": str(train_p), "test_file": str(test_p)})
    return ComparisonResult(rows, parent, o.experiment if o.track else None, o.axis or 1, train_rec.units["tau"],
                            warnings)


# ---- placements ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RankOptions:
    """How :func:`rank_placements` simulates and measures (``greybench rank-poses``'s options).

    Attributes
    ----------
    robot : str
        Robot name in ``data/robots`` or a TOML path.
    spacing_mm : float
        Dexel spacing [mm].
    probe_spacing_mm : float
        Virtual CMM probe point distance [mm].
    stiffness_scale : float
        Joint stiffness multiplier [-].
    shares : bool
        Re-run each pose with deflection, friction and switching off in turn (4x the time).
    ideal : bool
        Ideal robot: no deflection and no tracking error.
    size : int
        Test piece size [mm]: 160 or 320.
    workers : int
        Simulations at once [-] (processes; Ray tasks when ``RAY_ADDRESS`` is set).
    friction : mapping of int to str
        Joint 1..6 -> friction model reference (saved folder, ``runs:/<id>/model``,
        ``models:/<name>@<alias>``) in place of the robot file's.
    ff_friction : bool
        The NC's friction feed-forward.
    backlash_comp : bool
        The NC's backlash compensation.
    setup : str or Path or None
        Setup file (work offsets, tool table; ``docs/gcode.md``).
    """

    robot: str = "max100"
    spacing_mm: float = defaults.RANKING_DEXEL_SPACING * _MM_PER_M
    probe_spacing_mm: float = defaults.PROBE_SPACING * _MM_PER_M
    stiffness_scale: float = 1.0
    shares: bool = False
    ideal: bool = False
    size: int = 320
    workers: int = 2
    friction: Mapping[int, str] = field(default_factory=dict)
    ff_friction: bool = False
    backlash_comp: bool = False
    setup: PathLike | None = None


@dataclass(frozen=True)
class RankingResult:
    """What :func:`rank_placements` gives.

    Attributes
    ----------
    ranking : Ranking
        Poses best first (``entries``), each pose's Table-2 feature deviations [m] (``results``) and
        the component re-runs (``variants``).
    out_dir : Path or None
        Where the report, per-pose scans [m] and virtual workpieces were written.
    """

    ranking: Ranking
    out_dir: Path | None = None

    @property
    def best(self) -> str:
        """The best pose's name."""
        return self.ranking.entries[0].pose

    @property
    def order(self) -> list[str]:
        """Pose names, best first."""
        return [e.pose for e in self.ranking.entries]

    @property
    def scores(self) -> dict[str, float]:
        """Score per pose [-]: sum of |deviation| / tolerance over the Table-2 rows (lower is better)."""
        return {e.pose: float(e.score) for e in self.ranking.entries}

    def deviations_mm(self, pose: str) -> dict[str, float]:
        """The Table-2 deviation of each feature of ``pose`` [mm]."""
        return {row.name: float(row.deviation / _MM) for row in self.ranking.results[pose].table.rows}

    def to_dict(self) -> dict[str, Any]:
        """The ``greybench rank-poses --json`` object (``ranking.json``)."""
        from simulate.evaluation.ranking import ranking_json

        return ranking_json(self.ranking)


def rank_placements(program: PathLike, poses: PathLike, out_dir: PathLike | None = None, *,
                    options: RankOptions | None = None, progress: Progress = quiet, **overrides: Any) -> RankingResult:
    """Simulate the G-code ``program`` (its stock ``<stem>.stock.json`` beside it) in every pose of the
    pose file ``poses`` (workpiece frames in the robot base frame [m, rad]), measure the virtual parts
    (ISO 10791-7 features) and rank the poses (``greybench rank-poses``); with ``out_dir`` the report,
    scans and workpieces. Progress in simulations (``simulating poses``)."""
    from simulate.evaluation.ranking import Components, RankSettings
    from simulate.run import rank_program, resolve_robot

    o = _options(RankOptions, options, overrides)
    settings = RankSettings(spacing=o.spacing_mm * _MM, probe_spacing=o.probe_spacing_mm * _MM,
                            stiffness_scale=o.stiffness_scale, size=o.size, ff_friction=o.ff_friction,
                            backlash_comp=o.backlash_comp)
    comps = Components(deflection=False, servo=False) if o.ideal else Components()
    out_p = _path(out_dir)
    r = rank_program(Path(program), resolve_robot(o.robot), Path(poses), settings=settings, components=comps,
                     shares=o.shares, out_dir=out_p, workers=o.workers, friction=dict(o.friction),
                     progress=progress, setup=_path(o.setup))
    return RankingResult(r, out_p)


# ---- compensation ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CompensationOptions:
    """How :func:`compensate_program` compensates (``greybench compensate``'s options).

    Attributes
    ----------
    robot : str
        Robot name in ``data/robots`` or a TOML path.
    name : str or None
        Pose name in the pose file (None: the first).
    iterations : int
        Largest number of corrected programs simulated [-].
    stiffness_scale : float
        Joint stiffness multiplier [-] of the robot the before/after evaluation simulates (the
        iteration itself uses the robot file's model).
    check_scales : sequence of float
        More stiffness multipliers [-] both programs are evaluated at.
    gain : float
        Damping of the update [-] (0 < gain <= 1.5).
    spacing_mm, probe_spacing_mm : float
        Dexel spacing and probe point distance [mm].
    size : int or None
        Test piece size [mm] (None: the stock's ``size_mm``).
    friction : mapping of int to str
        Joint 1..6 -> friction model reference, as in :class:`RankOptions`.
    ff_friction, backlash_comp : bool
        The NC's friction feed-forward and backlash compensation, in the iteration and every evaluation.
    """

    robot: str = "max100"
    name: str | None = None
    iterations: int = CompensationSettings.iterations
    stiffness_scale: float = 1.0
    check_scales: Sequence[float] = ()
    gain: float = 1.0
    spacing_mm: float = defaults.RANKING_DEXEL_SPACING * _MM_PER_M
    probe_spacing_mm: float = defaults.PROBE_SPACING * _MM_PER_M
    size: int | None = None
    friction: Mapping[int, str] = field(default_factory=dict)
    ff_friction: bool = False
    backlash_comp: bool = False


@dataclass(frozen=True)
class CompensationResult:
    """What :func:`compensate_program` gives.

    Attributes
    ----------
    info : dict
        The summary (``summary.json``, ``greybench compensate --json``): Table-2 sums before and
        after [mm] (``evaluation``), the checks, the iterations, ``max_offset_mm`` [mm], time and peak
        speed ratios [-], ``files``.
    out_dir : Path
        The output folder (``compensated.nc``, ``offsets.csv``, ``feedforward.csv``, ``report.md``, ...).
    """

    info: dict[str, Any]
    out_dir: Path

    @property
    def program(self) -> Path:
        """The compensated program (``compensated.nc``)."""
        return self.out_dir / "compensated.nc"

    @property
    def sum_before_mm(self) -> float | None:
        """Sum of |Table-2 deviation| of the original program [mm] (None without the features)."""
        ev = self.info.get("evaluation")
        return None if ev is None else float(ev["sum_before_mm"])

    @property
    def sum_after_mm(self) -> float | None:
        """Sum of |Table-2 deviation| of the compensated program [mm] (None without the features)."""
        ev = self.info.get("evaluation")
        return None if ev is None else float(ev["sum_after_mm"])

    @property
    def ratio(self) -> float | None:
        """``sum_after_mm / sum_before_mm`` [-]: below 1 the compensation helped."""
        ev = self.info.get("evaluation")
        return None if ev is None or ev["ratio"] is None else float(ev["ratio"])

    def to_dict(self) -> dict[str, Any]:
        """The ``greybench compensate --json`` object."""
        return self.info


def compensate_program(program: PathLike, pose: PathLike, out_dir: PathLike, *,
                       options: CompensationOptions | None = None, progress: Progress = quiet,
                       **overrides: Any) -> CompensationResult:
    """Pre-compensate ``program`` for the pose ``options.name`` of the pose file ``pose``: correct the
    commanded path against the tool deviation the simulation predicts (deflection, tracking error
    with friction and backlash), iterate, evaluate both programs and write every file into
    ``out_dir`` (``greybench compensate``). Progress in the original program's 2 ms steps per
    simulation (``compensating``), with a total known before the work starts."""
    from simulate.compensation import run_compensation
    from simulate.run import compensation_steps, resolve_robot

    o = _options(CompensationOptions, options, overrides)
    program_p, out_p = Path(program), Path(out_dir)
    checks = tuple(o.check_scales)
    steps = compensation_steps(program_p, o.iterations, o.stiffness_scale, checks)
    with progress("compensating", steps) as adv:
        info = run_compensation(program_p, resolve_robot(o.robot), Path(pose), o.name, out_p,
                                iterations=o.iterations, stiffness_scale=o.stiffness_scale, check_scales=checks,
                                gain=o.gain, spacing_mm=o.spacing_mm, probe_spacing_mm=o.probe_spacing_mm,
                                size=o.size, friction=dict(o.friction), ff_friction=o.ff_friction,
                                backlash_comp=o.backlash_comp, advance=adv)
    return CompensationResult(info, out_p)


# ---- circle test ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CircleOptions:
    """The circle of :func:`circle_test` (``greybench circle``'s options).

    Attributes
    ----------
    robot : str
        Robot name in ``data/robots`` or a TOML path.
    name : str or None
        Pose name in the pose file (None: the first).
    radius_mm : float
        Circle radius [mm].
    feed_mm_min : float
        Feed along the circle [mm/min].
    plane : str
        Plane of the workpiece frame: ``xy``, ``yz`` or ``zx``.
    center_mm : sequence of 3 float
        Centre in the workpiece frame [mm].
    cw : bool
        Clockwise about the plane normal (G2).
    friction, backlash : bool
        Joint friction and gear play on.
    friction_scale : float
        Factor on every joint's Coulomb and static friction levels [-].
    ff_friction : bool
        The NC's friction feed-forward.
    """

    robot: str = "max100"
    name: str | None = None
    radius_mm: float = 50.0
    feed_mm_min: float = 2000.0
    plane: str = "xy"
    center_mm: Sequence[float] = (0.0, 0.0, 0.0)
    cw: bool = False
    friction: bool = True
    backlash: bool = True
    friction_scale: float = 1.0
    ff_friction: bool = False


@dataclass(frozen=True)
class CircleTestResult:
    """What :func:`circle_test` gives.

    Attributes
    ----------
    result : CircleResult
        The trace: angle [deg], radial deviation [µm], joint positions [rad], reversal spikes.
    summary : dict
        ``summary.json`` (``greybench circle --json``): the figures [µm], the options, the files.
    """

    result: CircleResult
    summary: dict[str, Any]

    @property
    def roundness_um(self) -> float:
        """Circular deviation G (ISO 230-4) [µm]."""
        return float(self.result.roundness_um)

    @property
    def radius_error_um(self) -> float:
        """Least-squares radius minus nominal [µm]."""
        return float(self.result.radius_error_um)

    def to_dict(self) -> dict[str, Any]:
        """The ``greybench circle --json`` object."""
        return self.summary


def circle_test(pose: PathLike, out_dir: PathLike, *, options: CircleOptions | None = None,
                progress: Progress = quiet, **overrides: Any) -> CircleTestResult:
    """The virtual circular test (ISO 230-4, ballbar) of the robot at a pose of the pose file ``pose``:
    simulate the circle through the machining pipeline (drives, friction models, no cutting), evaluate
    it and write ``circle.csv``, ``circle.png`` and ``summary.json`` into ``out_dir`` (``greybench
    circle``)."""
    from simulate.run import circle_test as run_circle_test
    from simulate.run import resolve_robot

    o = _options(CircleOptions, options, overrides)
    result, summary = run_circle_test(resolve_robot(o.robot), Path(pose), o.name, Path(out_dir),
                                      radius_mm=o.radius_mm, feed_mm_min=o.feed_mm_min, plane=o.plane,
                                      center_mm=tuple(o.center_mm), cw=o.cw, friction=o.friction,
                                      backlash=o.backlash, friction_scale=o.friction_scale,
                                      ff_friction=o.ff_friction, progress=progress)
    return CircleTestResult(result, summary)


# ---- explain a measured part --------------------------------------------------------------------------
@dataclass(frozen=True)
class ExplainOptions:
    """How :func:`explain_part` simulates and calibrates (``greybench explain``'s options).

    Attributes
    ----------
    robot : str
        The nominal robot: a name in ``data/robots`` or a TOML path.
    name : str or None
        Pose name in the pose file (None: the first).
    spacing_mm : float
        Dexel spacing of the simulation [mm]: the spacing the scan was simulated at (a coarser grid
        alone differs by some micrometres).
    size : int or None
        Test piece size [mm] (None: the stock's ``size_mm``).
    max_sims : int
        Re-simulations for the calibration [-] (>= 1).
    """

    robot: str = "max100"
    name: str | None = None
    spacing_mm: float = defaults.DEXEL_SPACING * _MM_PER_M
    size: int | None = None
    max_sims: int = 3


@dataclass(frozen=True)
class ExplanationResult:
    """What :func:`explain_part` gives.

    Attributes
    ----------
    explanation : Explanation
        The causes ranked, the comparison before and after, the calibrated robot.
    out_dir : Path or None
        Where ``report.md``, ``robot_calibrated.toml`` and ``explain.json`` were written.
    """

    explanation: Explanation
    out_dir: Path | None = None

    @property
    def cause(self) -> str:
        """The named cause (``stiffness:<axis>``, ``backlash:<axis>``, ``friction:<axis>``, ``tool_radius``,
        ``thermal`` or ``none``)."""
        return self.explanation.cause

    @property
    def rms_before_m(self) -> float:
        """RMS measured - simulated before the calibration [m]."""
        return float(self.explanation.rms_before)

    @property
    def rms_after_m(self) -> float:
        """RMS measured - simulated after the calibration [m]."""
        return float(self.explanation.rms_after)

    @property
    def gain(self) -> float:
        """``1 - rms_after / rms_before`` [-]."""
        return float(self.explanation.gain)

    def to_dict(self) -> dict[str, Any]:
        """The ``greybench explain --json`` object (SI: m, rad, Nm/rad)."""
        return self.explanation.as_json()


def explain_part(measured: PathLike, program: PathLike, pose: PathLike, out_dir: PathLike | None = None, *,
                 options: ExplainOptions | None = None, progress: Progress = quiet,
                 **overrides: Any) -> ExplanationResult:
    """Compare a measured CMM scan (``feature,x,y,z`` [m, workpiece frame]) with the simulated part of
    ``program`` at a pose of ``pose``, name the cause, calibrate it by re-simulating and, with
    ``out_dir``, write the report (``greybench explain``). Cost, scan and reach are checked first."""
    from simulate.run import explain_measured, resolve_robot

    o = _options(ExplainOptions, options, overrides)
    out_p = _path(out_dir)
    ex = explain_measured(Path(measured), Path(program), resolve_robot(o.robot), Path(pose), o.name, out_dir=out_p,
                          spacing_mm=o.spacing_mm, size=o.size, max_sims=o.max_sims, progress=progress)
    return ExplanationResult(ex, out_p)
