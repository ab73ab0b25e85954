"""Pose ranking (paper 3.8 and 4): simulate the program in every workpiece placement, measure the
virtual part like a CMM, score the Table-2 deviations and rank the placements.

Per pose (one worker process each, ``workers`` of them at a time, or one Ray task each with a Ray address:
:mod:`simulate.parallel`) one run of the machining pipeline
(:func:`simulate.pipeline.run_job`; the program is interpolated once for all poses): inverse kinematics
for the placement with switching points, the coupled loop with the axis servos and each joint's friction
model inside it, the translational compliance in the workpiece frame and the robot file's cutter, then
the virtual CMM (:mod:`simulate.evaluation.cmm`) and the ten rows (:mod:`simulate.evaluation.features`).

This is the one ranking of the project: ``greybench rank-poses`` (:func:`simulate.run.rank_program`) and
the service's simulation jobs (:mod:`service.pipeline`) both call :func:`rank_poses` and store
:func:`ranking_json` as ``ranking.json`` (and the service :func:`report_json` as ``report.json``).

Score (lower is better): ``sum over rows of |deviation| / tolerance``; ties broken by more rows in
tolerance, then by the pose name (:func:`rank_key`, the one sort key of every ranking).
Dimensionless, so a 15 um straightness tolerance weighs as much as
a 20 um diameter tolerance, which is how the paper colours Table 2 (best to worst per row).

Components (:class:`Components`): ``deflection`` (compliance x cutting force), ``friction`` (each joint's
friction model in the servo) and ``switching`` (the gear backlash, whose effect appears where an axis stops
or reverses, i.e. at the switching points of paper 3.7; the paper's switching analysis only marks these
points, the backlash model is what turns them into a path error). Switching one off and re-running
gives that component's contribution ``deviation(all) - deviation(all but it)`` per row; its share is
its contribution's magnitude over the sum of the three magnitudes, and its share of the score
``(score(all) - score(without)) / score(all)``.

The stock below ``stock_floor`` (default 2 mm under the lowest programmed cutting height) is left out of
the dexel grid: no tool reaches it and it would only multiply the horizontal rays.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from identify.errors import InputError
from identify.files import write_text_atomic
from simulate import defaults
from simulate.evaluation.cmm import Scan, write_scan
from simulate.evaluation.features import FeatureTable
from simulate.parallel import run_all
from simulate.pipeline import Components, MachiningJob, MachiningSettings, ProgramSetup, run_job
from simulate.toolpath.placement import Placement

if TYPE_CHECKING:
    from simulate.machining.simulation import StepTable
    from simulate.toolpath.setup import MachineSetup

#: The three component names whose share the report shows.
COMPONENTS = ("deflection", "friction", "switching")


@dataclass(frozen=True)
class RankSettings:
    """Simulation and measurement settings (SI).

    Attributes
    ----------
    spacing : float
        Dexel spacing, m (default :data:`simulate.defaults.RANKING_DEXEL_SPACING`, 0.25 mm: why there).
        On iso320 with max100 the 4-pose ranking takes about 36 s at 0.25 mm (0.5 mm: 15 s) on 2 cores.
    probe_spacing : float
        Virtual CMM point distance along a feature, m.
    material : str
        Name in ``data/materials.toml``.
    spindle_rpm : float or None
        rev/min; None: the program's ``S`` word.
    stiffness_scale : float
        Multiplies every joint stiffness (10 = ten times stiffer).
    size : int
        Test piece size, mm (160 or 320): which nominal geometry is measured.
    ff_friction : bool
        The NC's friction feed-forward on (each joint's friction model run along the commanded
        motion, :data:`simulate.robot.drive.DriveFlags.FF_FRICTION`); off: the NC does not know the friction.
    backlash_comp : bool
        The NC's load-dependent backlash compensation (:mod:`simulate.robot.backlash`).
    """

    spacing: float = defaults.RANKING_DEXEL_SPACING
    probe_spacing: float = defaults.PROBE_SPACING
    material: str = defaults.MATERIAL
    spindle_rpm: float | None = None
    stiffness_scale: float = 1.0
    size: int = 320
    ff_friction: bool = False
    backlash_comp: bool = False

    def machining(self) -> MachiningSettings:
        """The pipeline's settings: trimmed stock (:data:`simulate.defaults.STOCK_FLOOR`), features scored."""
        return MachiningSettings(spacing=self.spacing, probe_spacing=self.probe_spacing, material=self.material,
                                 spindle_rpm=self.spindle_rpm, require_spindle=True,
                                 stiffness_scale=self.stiffness_scale, stock_floor=defaults.STOCK_FLOOR,
                                 size=self.size, features=True, ff_friction=self.ff_friction,
                                 backlash_comp=self.backlash_comp)

    def validate(self) -> None:
        self.machining().validate()


@dataclass
class PoseResult:
    """What one pose simulation gives.

    Attributes
    ----------
    pose : str
    components : Components
    table : FeatureTable
    scan : Scan
    steps : simulate.machining.simulation.StepTable or None
        Process values per 2 ms step (kept for the report; None when not requested).
    tcp_error : numpy.ndarray or None, (N, 3)
        Servo tracking error in the workpiece frame, m.
    workpiece_file : Path or None
        Saved virtual workpiece (``VirtualWorkpiece.save``) when an output folder was given.
    timings : dict
        s per stage.
    xyz, switch : numpy.ndarray or None
        Commanded tool tip (N, 3) m in the workpiece frame and switching bits (N,), for the report.
    """

    pose: str
    components: Components
    table: FeatureTable
    scan: Scan
    steps: StepTable | None = None
    tcp_error: np.ndarray | None = None
    workpiece_file: Path | None = None
    timings: dict = field(default_factory=dict)
    xyz: np.ndarray | None = None
    switch: np.ndarray | None = None
    friction: list = field(default_factory=list)
    worker: int = 0

    @property
    def score(self) -> float:
        return self.table.score


def rank_key(result: PoseResult) -> tuple[float, int, str]:
    """The sort key of a ranking (best first): score [-], then more rows in tolerance, then the pose name."""
    return (result.score, -result.table.n_in_tolerance, result.pose)


@dataclass(frozen=True)
class RankEntry:
    """One ranked pose: ``score`` [-] (sum of |deviation| / tolerance), ``in_tolerance`` (rows of 10),
    ``rank`` (1 = best) and ``worst_feature`` (the row with the largest |deviation| / tolerance)."""

    pose: str
    score: float
    in_tolerance: int
    rank: int
    worst_feature: str = ""


@dataclass
class Ranking:
    """Poses ranked best first, with the full results and component re-runs.

    Attributes
    ----------
    entries : list of RankEntry
        Best first.
    results : dict of str to PoseResult
        All components on, by pose.
    variants : dict of (str, str) to PoseResult
        ``(pose, component switched off)`` re-runs.
    placements : list of Placement
        In the pose file's order.
    wall_time : float
        s.
    settings : RankSettings
    workers : int
        Processes the simulations ran in (1: this process; Ray: the tasks at once).
    """

    entries: list[RankEntry]
    results: dict[str, PoseResult]
    variants: dict[tuple[str, str], PoseResult]
    placements: list[Placement]
    wall_time: float = 0.0
    settings: RankSettings = field(default_factory=RankSettings)
    workers: int = 1

    @property
    def best(self) -> str:
        return self.entries[0].pose

    @property
    def trajectories(self) -> dict:
        """Per pose (xyz (N, 3) m, switching bits (N,)) of the ranked runs."""
        return {p: (r.xyz, r.switch) for p, r in self.results.items() if r.xyz is not None}

    def contributions(self, pose: str) -> dict[str, dict[str, float]]:
        """Per component and row: ``deviation(all) - deviation(without it)``, m."""
        full = self.results[pose].table
        out = {}
        for c in COMPONENTS:
            v = self.variants.get((pose, c))
            if v is None:
                continue
            out[c] = {r.name: r.deviation - v.table[r.name].deviation for r in full.rows}
        return out

    def shares(self, pose: str) -> dict[str, dict[str, float]]:
        """Per row: each component's share (0..1) of the summed contribution magnitudes; key ``score``:
        each component's share of the score, ``(score(all) - score(without)) / score(all)``."""
        con = self.contributions(pose)
        if not con:
            return {}
        full = self.results[pose].table
        out: dict[str, dict[str, float]] = {}
        for r in full.rows:
            tot = sum(abs(con[c][r.name]) for c in con)
            out[r.name] = {c: (abs(con[c][r.name]) / tot if tot > 0 else 0.0) for c in con}
        out["score"] = {c: (full.score - self.variants[(pose, c)].score) / full.score if full.score > 0 else 0.0
                        for c in con}
        return out


# ----------------------------------------------------------------------------- one pose


@dataclass(frozen=True)
class _Job:
    program: ProgramSetup  # shared interpolation
    robot: str
    placement: Placement
    components: Components
    settings: RankSettings
    friction: tuple  # ((joint, model reference), ...) replacing the robot file's
    out_dir: str | None
    keep_steps: bool


def _run_job(job: _Job) -> PoseResult:
    """Simulate and measure one pose (runs in a worker process): one :func:`simulate.pipeline.run_job`."""
    from simulate.machining.virtual_workpiece import VirtualWorkpiece
    from simulate.parallel import single_threaded

    single_threaded()  # one numba thread per worker: the workers already fill the cores
    comp, pl = job.components, job.placement
    mo = run_job(MachiningJob(program=job.program, robot=job.robot, placement=pl, friction=dict(job.friction),
                              components=comp, settings=job.settings.machining()))
    res, scan, table = mo.result, mo.scan, mo.table
    if scan is None or table is None:  # only with size 0 (no virtual CMM): nothing to rank on
        raise InputError("ranking needs the test piece's virtual CMM scan: size must be 160 or 320 mm", field="size")
    wfile = None
    if job.out_dir is not None:
        d = Path(job.out_dir) / pl.name
        d.mkdir(parents=True, exist_ok=True)
        write_scan(scan, d / "scan.csv")
        wfile = VirtualWorkpiece(mo.workpiece, res.steps).save(d / "workpiece.npz")
        meta = {"program": str(Path(job.program.program).resolve()), "robot": str(job.robot), "pose": pl.name,
                "xyz": pl.xyz.tolist(), "rpy": pl.rpy.tolist(), "spacing_m": job.settings.spacing,  # m, rad
                "components": comp.label(), "friction": mo.friction, "units": "m, workpiece frame"}
        write_text_atomic(d / "meta.json", json.dumps(meta, indent=1))
    keep = job.keep_steps
    jt = mo.trajectory
    return PoseResult(pose=pl.name, components=comp, table=table, scan=scan,
                      steps=res.steps if keep else None, tcp_error=mo.tracking_error if keep else None,
                      workpiece_file=wfile, timings=mo.timings, xyz=jt.xyz if keep else None,
                      switch=jt.switch if keep else None, friction=mo.friction, worker=os.getpid())


def rank_poses(program: str | Path, robot: str | Path, placements: list[Placement], *,
               settings: RankSettings | None = None, components: Components | None = None,
               shares: bool = False, out_dir: str | Path | None = None, workers: int = 2,
               advance=None, friction: dict | None = None, ray_address: str | None = None,
               setup: MachineSetup | None = None) -> Ranking:
    """Simulate, measure and rank every placement (module docstring).

    Parameters
    ----------
    program : path
        G-code; its stock description ``<stem>.stock.json`` must sit next to it.
    robot : path
        Robot TOML.
    placements : list of Placement
    settings : RankSettings
    components : Components
        Error sources of the ranked runs (default all on).
    shares : bool
        Also re-run each pose with deflection, friction and switching switched off in turn.
    out_dir : path, optional
        Per pose ``<out_dir>/<pose>/scan.csv`` and ``workpiece.npz`` (ranked runs only).
    workers : int
        Worker processes on this machine: ``min(workers, simulations)`` run at once (1: in this process).
    advance : callable(n), optional
        Called once per finished simulation.
    friction : dict of int to str, optional
        Per joint (1..6) a friction model reference (saved folder, ``runs:/``, ``models:/``) replacing the
        robot file's (:class:`simulate.pipeline.MachiningJob`).
    ray_address : str, optional
        Run the simulations as Ray tasks on this cluster (``RAY_ADDRESS``) instead of ``workers`` processes.
    setup : MachineSetup, optional
        Work offsets and tool table [m] for reading the program (:mod:`simulate.toolpath.setup`).
    """
    from simulate.pipeline import load_program

    settings = settings or RankSettings()
    settings.validate()
    components = components or Components()
    program = Path(program)
    stock = program.with_name(program.stem + ".stock.json")
    if not stock.exists():
        raise InputError("no stock description next to the program (expected <program>.stock.json)",
                         source=str(program))
    prog = load_program(program, stock=stock, spindle_rpm=settings.spindle_rpm, require_spindle=True, setup=setup)
    fr = tuple(sorted((int(j), str(m)) for j, m in (friction or {}).items()))
    t0 = time.perf_counter()
    out = None if out_dir is None else str(out_dir)
    jobs = [_Job(prog, str(robot), pl, components, settings, fr, out, True) for pl in placements]
    if shares:
        for pl in placements:
            for c in COMPONENTS:
                jobs.append(_Job(prog, str(robot), pl, replace(components, **{c: False}), settings, fr, None, False))
    # worker processes on this machine, or Ray tasks when a Ray address is given (simulate.parallel)
    n_workers = max(1, min(int(workers), len(jobs)))
    results: list[PoseResult] = run_all(_run_job, jobs, workers=n_workers, ray_address=ray_address, advance=advance)
    n = len(placements)
    main = {r.pose: r for r in results[:n]}
    variants = {}
    for k, r in enumerate(results[n:]):
        variants[(r.pose, COMPONENTS[k % len(COMPONENTS)])] = r
    ordered = sorted(main.values(), key=rank_key)
    entries = [RankEntry(r.pose, r.score, r.table.n_in_tolerance, i + 1, r.table.worst.name)
               for i, r in enumerate(ordered)]
    return Ranking(entries=entries, results=main, variants=variants, placements=list(placements),
                   wall_time=time.perf_counter() - t0, settings=settings, workers=n_workers)


# ----------------------------------------------------------------------------- JSON


def feature_json(row) -> dict:
    """One Table-2 row (:class:`simulate.evaluation.features.FeatureRow`) with its unit in every
    field name: ``nominal_mm`` (a length) or ``nominal_deg`` (the slope angle), both null for form
    rows (roundness, straightness: no nominal size) and the 30/60 deg row (two nominals; see
    ``nominal_text``); ``tolerance_mm``. The deviations are added per pose by :func:`ranking_json`."""
    nominal = row.nominal_display()
    deg = row.nominal_unit == "rad"
    return {"name": row.name, "nominal_mm": None if deg else nominal, "nominal_deg": nominal if deg else None,
            "nominal_text": row.nominal_text(), "tolerance_mm": row.tolerance / 1e-3}


def ranking_json(r: Ranking) -> dict:
    """The ``rank-poses --json`` object and ``ranking.json`` (of ``rank-poses --out`` and of a service
    simulation job alike): ``{"ranking": [{"rank", "pose", "score", "in_tolerance", "worst_feature"}],
    "features": [{"name", "nominal_mm", "nominal_deg", "nominal_text", "tolerance_mm",
    "deviation_mm": {pose: value}, "in_tolerance": {pose: bool}, "worst_instance": {pose: name}}]}``.
    Lengths in mm as in the paper's Table 2 (the angle rows' deviations and tolerances are lengths too);
    ``score`` is dimensionless (sum of |deviation| / tolerance), ``in_tolerance`` a count of rows,
    ``worst_feature`` the row with the largest |deviation| / tolerance, ``worst_instance`` the wall, edge
    or line a row's deviation comes from."""
    poses = [p.name for p in r.placements]
    feats = []
    for row in r.results[poses[0]].table.rows:
        rows = {p: r.results[p].table[row.name] for p in poses}
        feats.append({**feature_json(row), "deviation_mm": {p: x.deviation / 1e-3 for p, x in rows.items()},
                      "in_tolerance": {p: x.in_tolerance for p, x in rows.items()},
                      "worst_instance": {p: x.worst_instance for p, x in rows.items()}})
    return {"ranking": [{"rank": e.rank, "pose": e.pose, "score": e.score, "in_tolerance": e.in_tolerance,
                         "worst_feature": e.worst_feature} for e in r.entries], "features": feats}


def pose_summary(r: Ranking, pose: str) -> dict:
    """One pose's process figures, units in the keys: ``steps`` (2 ms cycles), ``simulated_time_s`` [s],
    ``switching_points`` (cycles with a switching bit), ``peak_force_n`` [N], ``peak_deflection_m`` [m],
    ``max_tracking_error_m`` and ``rms_tracking_error_m`` [m] (servo error in the workpiece frame),
    ``score`` [-], ``in_tolerance`` (rows), ``worst_feature``, ``friction`` (per joint the model kind and
    source) and, with the component re-runs, ``shares`` (:meth:`Ranking.shares`, 0..1)."""
    res = r.results[pose]
    table = res.table
    out: dict = {"pose": pose, "score": float(table.score), "in_tolerance": int(table.n_in_tolerance),
                 "worst_feature": table.worst.name, "friction": [dict(f) for f in res.friction]}
    steps = res.steps
    if steps is not None:
        n = len(steps.t)
        terr = np.zeros((n, 3)) if res.tcp_error is None else np.asarray(res.tcp_error)
        out.update({"steps": int(n), "simulated_time_s": float(steps.t[-1] - steps.t[0]) if n > 1 else 0.0,
                    "switching_points": int(np.count_nonzero(res.switch)) if res.switch is not None else 0,
                    "peak_force_n": float(steps.peak_force.max()) if n else 0.0,
                    "peak_deflection_m": float(np.linalg.norm(steps.deflection, axis=1).max()) if n else 0.0,
                    "max_tracking_error_m": float(np.linalg.norm(terr, axis=1).max()) if n else 0.0,
                    "rms_tracking_error_m": float(np.sqrt(np.mean(np.sum(terr ** 2, axis=1)))) if n else 0.0})
    if r.variants:
        out["shares"] = r.shares(pose)
    return out


def report_json(r: Ranking) -> dict:
    """``report.json`` of a ranking: ``{"poses": [pose_summary per pose, pose-file order], "features":
    ranking_json's feature rows}`` (mm, deg, N, m, s as the keys say)."""
    return {"poses": [pose_summary(r, p.name) for p in r.placements], "features": ranking_json(r)["features"]}
