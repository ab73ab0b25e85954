"""Pose ranking (paper 3.8 and 4): simulate the program in every workpiece placement, measure the
virtual part like a CMM, score the Table-2 deviations and rank the placements.

Per pose (one worker process each, at most ``workers`` at a time):

1. interpolation of the program (shared by all poses, computed once) and inverse kinematics for the
   placement (:func:`simulate.toolpath.placement.joint_trajectory`), with switching points;
2. servo tracking error ``p(q_act) - p(q_cmd)`` from the cascaded servo with LuGre friction and gear
   backlash (:func:`simulate.robot.servo.simulate_servo`), turned into the workpiece frame;
3. the coupled removal / force / deflection loop (:func:`simulate.machining.simulation.simulate_machining`)
   with the translational compliance ``J K^-1 J^T`` in the workpiece frame and the cutter of the robot
   file's ``[tool]`` (:func:`simulate.evaluation.cutter.robot_cutter`: the tool belongs to the robot
   file, where ``explain`` calibrates its radius; the stock file only describes the blank);
4. the virtual CMM (:mod:`simulate.evaluation.cmm`) and the ten rows (:mod:`simulate.evaluation.features`).

Score (lower is better): ``sum over rows of |deviation| / tolerance``; ties broken by more rows in
tolerance, then by the pose name. Dimensionless, so a 15 um straightness tolerance weighs as much as
a 20 um diameter tolerance, which is how the paper colours Table 2 (best to worst per row).

Components (:class:`Components`): ``deflection`` (compliance x cutting force), ``friction`` (LuGre
friction in the servo) and ``switching`` (the gear backlash, whose effect appears where an axis stops
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
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from identify.errors import InputError
from simulate.evaluation.cmm import Scan, probe, write_scan
from simulate.evaluation.features import FeatureTable, evaluate_scan
from simulate.toolpath.placement import Placement
from simulate.toolpath.testpiece import iso_test_piece


@dataclass(frozen=True)
class Components:
    """Which error sources the simulation includes (module docstring)."""

    deflection: bool = True
    friction: bool = True
    switching: bool = True
    servo: bool = True  # False: no tracking error at all (an ideal drive)

    def label(self) -> str:
        off = [n for n in ("deflection", "friction", "switching", "servo") if not getattr(self, n)]
        return "all" if not off else "no " + ", no ".join(off)


#: The three component names whose share the report shows.
COMPONENTS = ("deflection", "friction", "switching")


@dataclass(frozen=True)
class RankSettings:
    """Simulation and measurement settings (SI).

    Attributes
    ----------
    spacing : float
        Dexel spacing, m (default 0.5 mm). Wall and face positions stay continuous at any spacing, but
        the cutting force integrates over the dexels in the tool, so coarse grids make the force, and
        with it the deflection, jump as whole dexels enter and leave the cutter. Measured on iso320 with
        max100 (4 poses, deviations vs 0.25 mm): at 2 mm the slope straightness is 0.085 mm instead of
        0.006 mm and the square sides are 0.1 mm off; at 0.5 mm every row is within 0.02 mm of the
        0.25 mm value, the best pose is the same at 2, 1, 0.5 and 0.25 mm, and the ranking takes
        about 20 s (0.25 mm: 55 s) on 2 cores.
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
    """

    spacing: float = 0.5e-3
    probe_spacing: float = 2e-3
    material: str = "Al7075"
    spindle_rpm: float | None = None
    stiffness_scale: float = 1.0
    size: int = 320

    def validate(self) -> None:
        for name in ("spacing", "probe_spacing", "stiffness_scale"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"must be > 0, got {v!r}", field=name.replace("_", "-"))
        if self.spacing > 5e-3:
            raise InputError("dexel spacing above 5 mm cannot resolve the 6 mm features", field="spacing")


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
    steps: object = None
    tcp_error: np.ndarray | None = None
    workpiece_file: Path | None = None
    timings: dict = field(default_factory=dict)
    xyz: np.ndarray | None = None
    switch: np.ndarray | None = None

    @property
    def score(self) -> float:
        return self.table.score


@dataclass(frozen=True)
class RankEntry:
    pose: str
    score: float
    in_tolerance: int
    rank: int


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
    """

    entries: list[RankEntry]
    results: dict[str, PoseResult]
    variants: dict[tuple[str, str], PoseResult]
    placements: list[Placement]
    wall_time: float = 0.0
    settings: RankSettings = field(default_factory=RankSettings)

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


def _stock_solids(stock_file: Path, floor: float):
    from simulate.machining.dexel import raise_floor, read_stock_solids

    return raise_floor(read_stock_solids(stock_file), floor)


@dataclass(frozen=True)
class _Job:
    program: str
    stock: str | None
    robot: str
    placement: Placement
    components: Components
    settings: RankSettings
    interp: object  # Interpolation, shared
    spindle_rpm: float
    out_dir: str | None
    keep_steps: bool


def _run_job(job: _Job) -> PoseResult:
    """Simulate and measure one pose (runs in a worker process)."""
    from simulate.machining.cutting import Spindle, load_material
    from simulate.machining.dexel import TriDexel
    from simulate.machining.simulation import simulate_machining, workpiece_compliance
    from simulate.evaluation.cutter import robot_cutter
    from simulate.machining.virtual_workpiece import VirtualWorkpiece
    from simulate.robot.model import load_robot
    from simulate.robot.servo import simulate_servo
    from simulate.toolpath.placement import joint_trajectory

    try:  # one numba thread per worker: the workers already fill the cores
        import numba

        numba.set_num_threads(1)
    except (ImportError, ValueError):
        pass
    s, comp, pl = job.settings, job.components, job.placement
    timings = {}
    c0 = time.perf_counter()
    robot = load_robot(job.robot)
    ip = job.interp
    jt = joint_trajectory(robot, ip, pl, source=job.program)
    R = pl.T[:3, :3]
    timings["kinematics"] = time.perf_counter() - c0
    c0 = time.perf_counter()
    err = None
    if comp.servo:
        sv = simulate_servo(robot, jt.t, jt.q, friction=comp.friction, backlash=comp.switching)
        err = sv.tcp_error(robot) @ R  # base -> workpiece frame: R^T e, row-wise
    C = workpiece_compliance(robot, jt.q, R, s.stiffness_scale) if comp.deflection else None
    timings["servo+compliance"] = time.perf_counter() - c0
    c0 = time.perf_counter()
    floor = float(ip.xyz[:, 2].min()) - 2e-3
    if job.stock is not None:
        solids = _stock_solids(Path(job.stock), floor)
        wp = TriDexel.from_solids(solids, s.spacing)
    else:
        raise InputError("no stock description next to the program (expected <program>.stock.json)",
                         source=job.program)
    cutter = robot_cutter(robot)
    res = simulate_machining(wp, cutter, jt.t, jt.line, jt.xyz, load_material(s.material),
                             Spindle.from_rpm(job.spindle_rpm), compliance=C, tracking_error=err,
                             switch=jt.switch, forces=comp.deflection)
    timings["machining"] = time.perf_counter() - c0
    c0 = time.perf_counter()
    piece = iso_test_piece(s.size)
    scan = probe(wp, piece, spacing=s.probe_spacing, tool_diameter=float(robot.tool.diameter))
    table = evaluate_scan(scan, piece)
    timings["cmm+fits"] = time.perf_counter() - c0
    wfile = None
    if job.out_dir is not None:
        d = Path(job.out_dir) / pl.name
        d.mkdir(parents=True, exist_ok=True)
        write_scan(scan, d / "scan.csv")
        wfile = VirtualWorkpiece(wp, res.steps).save(d / "workpiece.npz")
        meta = {"program": str(Path(job.program).resolve()), "robot": str(job.robot), "pose": pl.name,
                "xyz": pl.xyz.tolist(), "rpy": pl.rpy.tolist(), "spacing_m": s.spacing,
                "components": comp.label(), "units": "m, workpiece frame"}
        tmp = d / ".meta.json.tmp"
        tmp.write_text(json.dumps(meta, indent=1))
        os.replace(tmp, d / "meta.json")
    keep = job.keep_steps
    return PoseResult(pose=pl.name, components=comp, table=table, scan=scan,
                      steps=res.steps if keep else None, tcp_error=err if keep else None, workpiece_file=wfile,
                      timings=timings, xyz=jt.xyz if keep else None, switch=jt.switch if keep else None)


def _program_spindle(program) -> float:
    speeds = [seg.spindle for seg in program.segments if seg.spindle > 0]
    return float(max(speeds)) * 60.0 if speeds else 0.0


def rank_poses(program: str | Path, robot: str | Path, placements: list[Placement], *,
               settings: RankSettings | None = None, components: Components | None = None,
               shares: bool = False, out_dir: str | Path | None = None, workers: int = 2,
               advance=None) -> Ranking:
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
        Parallel processes (at most 2 on the shared machine).
    advance : callable(n), optional
        Called once per finished simulation.
    """
    from simulate.toolpath.gcode import read_program
    from simulate.toolpath.interpolation import PathLimits, interpolate

    settings = settings or RankSettings()
    settings.validate()
    components = components or Components()
    program = Path(program)
    prog = read_program(program)
    stock = program.with_name(program.stem + ".stock.json")
    rpm = settings.spindle_rpm or _program_spindle(prog)
    if not rpm > 0:
        raise InputError("the program never switches the spindle on (no S word with M3/M4); give --spindle",
                         source=str(program))
    ip = interpolate(prog, PathLimits())
    t0 = time.perf_counter()
    jobs = []
    for pl in placements:
        jobs.append(_Job(str(program), str(stock) if stock.exists() else None, str(robot), pl, components,
                         settings, ip, rpm, None if out_dir is None else str(out_dir), True))
    if shares:
        for pl in placements:
            for c in COMPONENTS:
                jobs.append(_Job(str(program), str(stock) if stock.exists() else None, str(robot), pl,
                                 replace(components, **{c: False}), settings, ip, rpm, None, False))
    results: list[PoseResult] = []
    workers = max(1, min(int(workers), 2, len(jobs)))
    if workers == 1:
        for j in jobs:
            results.append(_run_job(j))
            if advance:
                advance(1)
    else:
        with ProcessPoolExecutor(max_workers=workers) as ex:
            futs = [ex.submit(_run_job, j) for j in jobs]
            for f in futs:
                results.append(f.result())
                if advance:
                    advance(1)
    n = len(placements)
    main = {r.pose: r for r in results[:n]}
    variants = {}
    for k, r in enumerate(results[n:]):
        variants[(r.pose, COMPONENTS[k % len(COMPONENTS)])] = r
    ordered = sorted(main.values(), key=lambda r: (r.score, -r.table.n_in_tolerance, r.pose))
    entries = [RankEntry(r.pose, r.score, r.table.n_in_tolerance, i + 1) for i, r in enumerate(ordered)]
    return Ranking(entries=entries, results=main, variants=variants, placements=list(placements),
                   wall_time=time.perf_counter() - t0, settings=settings)
