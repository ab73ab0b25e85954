"""The machining pipeline: one typed job in, one typed result out (paper Figure 4, sections 3.1-3.8).

    program -> interpolation (2 ms) -> placement + inverse kinematics (+ switching points)
            -> coupled loop: two-mass drives with each joint's friction model, removal, forces, deflection
            -> virtual workpiece -> virtual CMM scan -> Table-2 feature deviations

Every caller builds a :class:`MachiningJob` and calls :func:`run_job`: ``greybench machine``,
``rank-poses`` (:mod:`simulate.evaluation.ranking`), ``explain`` (:mod:`simulate.explain.simulation`)
and the service's jobs (``service/pipeline.py``). They only parse their inputs, call and print or
store the result. The defaults live in :mod:`simulate.defaults`.

Stages that do not depend on the pose (reading and interpolating the program) are held in a
:class:`ProgramSetup`, built once by :func:`load_program` and shared between the poses of a ranking;
the joint trajectory depends on the kinematics and the pose only (``explain`` reuses it across its
robot variants: pass it to :func:`run_job`).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from identify.errors import InputError, read_json
from simulate import defaults
from simulate.toolpath.setup import MachineSetup, setup_tables

if TYPE_CHECKING:  # the stages' types only: their modules load numba kernels, imported when a job runs
    from simulate.evaluation.cmm import Scan
    from simulate.evaluation.features import FeatureTable
    from simulate.machining.dexel import TriDexel
    from simulate.machining.simulation import MachiningResult, StepTable
    from simulate.machining.tools import Cutter
    from simulate.robot.model import Robot
    from simulate.toolpath.gcode import Program
    from simulate.toolpath.interpolation import Interpolation
    from simulate.toolpath.placement import JointTrajectory, Placement


@dataclass(frozen=True)
class Components:
    """Which error sources the simulation includes.

    Attributes
    ----------
    deflection : bool
        The robot yields to the cutting force: the gears wind up under the process torque ``-J^T F``
        in the drives (or quasi-statically, ``J K_gear^-1 J^T F``, without them), and the links and
        bearings deflect by their static compliance ``J K_link^-1 J^T F``; each compliance once
        (:mod:`simulate.robot.stiffness`).
    friction : bool
        Joint friction in the drives (each joint's friction model).
    switching : bool
        Gear backlash, whose effect appears where the load on a gear reverses (switching points, paper 3.7).
    servo : bool
        The drives (motor, gear, link, control) in the loop; False: no tracking error at all (an ideal drive).
    """

    deflection: bool = True
    friction: bool = True
    switching: bool = True
    servo: bool = True

    def label(self) -> str:
        off = [n for n in ("deflection", "friction", "switching", "servo") if not getattr(self, n)]
        return "all" if not off else "no " + ", no ".join(off)


@dataclass(frozen=True)
class MachiningSettings:
    """Simulation and measurement settings (SI).

    Attributes
    ----------
    spacing : float
        Dexel spacing [m] (:data:`simulate.defaults.DEXEL_SPACING`; the ranking uses
        :data:`simulate.defaults.RANKING_DEXEL_SPACING`).
    probe_spacing : float
        Virtual CMM probe point distance [m].
    material : str
        Name in ``data/materials.toml``.
    spindle_rpm : float or None
        [rev/min]; None: the program's S word (:data:`simulate.defaults.SPINDLE_RPM` when it has none
        and ``require_spindle`` is False).
    require_spindle : bool
        Refuse a program that never sets the spindle speed (the ranking: forces would rest on a guess).
    stiffness_scale : float
        Multiplies every joint stiffness, gears and links [-].
    substeps : int or None
        Drive substeps per 2 ms cycle [-]; None: per joint what its fastest mode needs
        (:func:`simulate.robot.drive.substeps_for`).
    friction_scale : float
        Factor on every joint's Coulomb and static friction levels [-] (1: as fitted).
    ff_friction : bool
        The NC's friction feed-forward (off: the controller does not know the friction).
    backlash_comp : bool
        The NC's load-dependent backlash compensation (:mod:`simulate.robot.backlash`): the drives'
        reference moved by half the play towards the flank the predicted gear torque loads.
    stock_floor : float or None
        Leave out the stock this far [m] below the lowest programmed cutting height; None: whole stock.
    capacity : tuple of int or None
        Dexel ray interval capacity (x, y, z); None: the dexel model's default.
    size : int or None
        ISO 10791-7 test-piece size [mm] for the virtual CMM; None: the stock JSON's ``size_mm``
        (no scan when it has none); 0: no scan.
    features : bool
        Evaluate the Table-2 feature deviations of the scan.
    """

    spacing: float = defaults.DEXEL_SPACING
    probe_spacing: float = defaults.PROBE_SPACING
    material: str = defaults.MATERIAL
    spindle_rpm: float | None = None
    require_spindle: bool = False
    stiffness_scale: float = 1.0
    substeps: int | None = None
    friction_scale: float = 1.0
    ff_friction: bool = False
    backlash_comp: bool = False
    stock_floor: float | None = None
    capacity: tuple | None = None
    size: int | None = None
    features: bool = False

    def validate(self) -> None:
        """Raise ``InputError`` naming the setting (as the CLI option) that is out of range."""
        for name in ("spacing", "probe_spacing", "stiffness_scale"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"must be > 0, got {v!r}", field=name.replace("_", "-"))
        if self.spacing > defaults.MAX_DEXEL_SPACING:
            raise InputError(f"dexel spacing above {defaults.MAX_DEXEL_SPACING * 1e3:g} mm cannot resolve the "
                             f"6 mm features", field="spacing")
        if self.spindle_rpm is not None and not (math.isfinite(self.spindle_rpm) and self.spindle_rpm > 0):
            raise InputError(f"spindle speed must be > 0 rev/min, got {self.spindle_rpm}", field="spindle")
        fs = self.friction_scale
        if isinstance(fs, bool) or not (isinstance(fs, (int, float)) and math.isfinite(fs) and fs >= 0):
            raise InputError(f"must be finite and >= 0, got {fs!r}", field="friction-scale")
        if self.substeps is not None and not (isinstance(self.substeps, int) and not isinstance(self.substeps, bool)
                                              and self.substeps >= 1):
            raise InputError(f"drive substeps must be an integer >= 1, got {self.substeps!r}", field="substeps")


@dataclass
class ProgramSetup:
    """The pose-independent part of a job: program, its interpolation, stock and spindle speed.

    Attributes
    ----------
    program : Path
    source : str
        Name of the program in messages.
    parsed : simulate.toolpath.gcode.Program
    interp : simulate.toolpath.interpolation.Interpolation
        The program at the 2 ms cycle (workpiece frame, m).
    stock : Path or None
        Stock description JSON; None: no stock, nothing is cut (the drives and the path only, e.g. a
        circular test).
    stock_doc : dict
        The stock JSON as read.
    spindle_rpm : float
        [rev/min].
    """

    program: Path
    source: str
    parsed: Program
    interp: Interpolation
    stock: Path | None
    stock_doc: dict
    spindle_rpm: float


def load_program(program: str | Path, *, stock: str | Path | None = None, spindle_rpm: float | None = None,
                 require_spindle: bool = False, source: str | None = None,
                 setup: MachineSetup | None = None) -> ProgramSetup:
    """Read and interpolate a program; find its stock (``<program stem>.stock.json`` unless given).

    ``setup``: work offsets and tool table [m] (:func:`simulate.toolpath.setup.read_setup`); default
    none, where only ``G54`` with zero offset and ``G43`` of the loaded tool are accepted.

    Raises ``InputError`` naming the program line, the stock file or the spindle.
    """
    from simulate.toolpath.gcode import read_program
    from simulate.toolpath.interpolation import PathLimits, interpolate

    program = Path(program)
    prog = read_program(program, **setup_tables(setup))
    stock = Path(stock) if stock is not None else program.with_name(program.stem + ".stock.json")
    doc = read_json(stock, missing="stock description not found (give --stock)")
    rpm = spindle_rpm
    if rpm is None:
        # segments carry the S word in rev/s (simulate.toolpath.gcode)
        speeds = [seg.spindle for seg in prog.segments if getattr(seg, "spindle", 0) > 0]
        rpm = float(max(speeds)) * 60.0 if speeds else 0.0
    if not rpm > 0:
        if require_spindle:
            raise InputError("the program never switches the spindle on (no S word with M3/M4); give --spindle",
                             source=source or str(program))
        rpm = defaults.SPINDLE_RPM
    return ProgramSetup(program=program, source=source or str(program), parsed=prog,
                        interp=interpolate(prog, PathLimits()), stock=stock,
                        stock_doc=doc if isinstance(doc, dict) else {}, spindle_rpm=float(rpm))


@dataclass
class MachiningJob:
    """One simulation: what to machine, with which robot, where, and how.

    Attributes
    ----------
    program : ProgramSetup or path
        A :func:`load_program` result (shared between poses), or the G-code file.
    robot : simulate.robot.model.Robot or path
        The robot file (kinematics, dynamics, stiffness, servo gains, backlash, tool, friction).
    placement : simulate.toolpath.placement.Placement
        Workpiece pose in the robot base frame [m, rad].
    friction : dict of int to str
        Per joint (1..6) a friction model reference replacing the robot file's (a saved model
        folder, ``runs:/<id>/model`` or ``models:/<name>@<alias>``); joints not listed keep the
        robot file's ``[joint.friction]``.
    components : Components
    settings : MachiningSettings
    stock : path, optional
        Stock description (when ``program`` is a path); default ``<program stem>.stock.json``.
    offset : ndarray (N, 3), optional
        Tool offset added to the path like a tracking error [m, workpiece frame] (``explain``'s
        thermal drift candidate).
    setup : MachineSetup, optional
        Work offsets and tool table [m] for reading ``program`` when it is a path
        (:func:`simulate.toolpath.setup.read_setup`).
    """

    program: ProgramSetup | str | Path
    robot: Robot | str | Path
    placement: Placement
    friction: dict[int, str] = field(default_factory=dict)
    components: Components = field(default_factory=Components)
    settings: MachiningSettings = field(default_factory=MachiningSettings)
    stock: str | Path | None = None
    offset: np.ndarray | None = None
    setup: MachineSetup | None = None


@dataclass
class MachiningOutcome:
    """What :func:`run_job` gives.

    Attributes
    ----------
    program : ProgramSetup
    robot : simulate.robot.model.Robot
    trajectory : simulate.toolpath.placement.JointTrajectory
        Commanded joints and tool tip every 2 ms, switching bits.
    workpiece : simulate.machining.dexel.TriDexel
        The machined virtual workpiece [m, workpiece frame].
    result : simulate.machining.simulation.MachiningResult
        Per-step process values (force [N], deflection and tracking error [m], switching bits),
        removed volume, loop timing.
    cutter : simulate.machining.tools.Cutter
        The robot file's tool.
    tracking_error : ndarray (N, 3)
        Tracking error used [m, workpiece frame] (servo error plus ``offset``).
    scan : simulate.evaluation.cmm.Scan or None
        Virtual CMM points when the stock is a test piece.
    table : simulate.evaluation.features.FeatureTable or None
        Table-2 deviations (``settings.features``).
    friction : list of dict
        Per joint: the friction model used (``{"joint", "kind", "source"}``).
    timings : dict
        Wall time [s] per stage.
    """

    program: ProgramSetup
    robot: Robot
    trajectory: JointTrajectory
    workpiece: TriDexel
    result: MachiningResult
    cutter: Cutter
    tracking_error: np.ndarray
    scan: Scan | None = None
    table: FeatureTable | None = None
    friction: list[dict] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def steps(self) -> StepTable:
        return self.result.steps


def piece_size(program: ProgramSetup, size: int | None) -> int | None:
    """Size [mm] of the ISO 10791-7 test piece the stock is, for the virtual CMM; None: not a test piece.

    ``size`` wins when given (0: no scan); it must agree with the stock's ``size_mm`` when that is
    there. Otherwise the stock's ``size_mm`` (written by ``greybench testpiece``).
    """
    from simulate.toolpath.testpiece import SIZES

    named = program.stock_doc.get("size_mm")
    if named is not None and (isinstance(named, bool) or not isinstance(named, (int, float)) or named not in SIZES):
        raise InputError(f"size_mm must be one of {', '.join(map(str, SIZES))}, got {named!r}",
                         source=str(program.stock), field="size_mm")
    if size == 0:
        return None
    if size is not None:
        if size not in SIZES:
            raise InputError(f"test-piece size must be one of {', '.join(map(str, SIZES))} mm, got {size}",
                             field="size")
        if named is not None and int(named) != size:
            raise InputError(f"--size {size} disagrees with the stock's size_mm {int(named)}",
                             source=str(program.stock), field="size_mm")
        return int(size)
    return None if named is None else int(named)


def stock_workpiece(program: ProgramSetup, settings: MachiningSettings) -> TriDexel:
    """The stock as a tri-dexel model at ``settings.spacing``, trimmed ``settings.stock_floor`` under
    the lowest programmed cutting height when that is set."""
    from simulate.machining.dexel import DEFAULT_CAPACITY, TriDexel, raise_floor, read_stock_solids

    cap = settings.capacity or DEFAULT_CAPACITY
    if program.stock is None:
        # no stock: a block of 2^3 dexel cells 1 m below the path, which no tool reaches (the loop's
        # removal rejects it by its bounding box)
        lo = program.interp.xyz.min(axis=0) - np.array([0.0, 0.0, 1.0])
        return TriDexel.box(lo, lo + 2 * settings.spacing, settings.spacing, capacity=cap)
    if settings.stock_floor is None:
        return TriDexel.from_stock_file(program.stock, settings.spacing, capacity=cap)
    floor = float(program.interp.xyz[:, 2].min()) - settings.stock_floor
    return TriDexel.from_solids(raise_floor(read_stock_solids(program.stock), floor), settings.spacing, capacity=cap)


def _robot(robot: Robot | str | Path) -> Robot:
    from simulate.robot.model import Robot, load_robot

    return robot if isinstance(robot, Robot) else load_robot(robot)


@dataclass
class PreparedJob:
    """The parts of a job before the coupled loop (:func:`prepare`).

    Attributes
    ----------
    program : ProgramSetup
    robot : simulate.robot.model.Robot
    trajectory : simulate.toolpath.placement.JointTrajectory
    size : int or None
        Test-piece size [mm] for the virtual CMM (None: no scan).
    timings : dict
        Wall time [s] per stage.
    """

    program: ProgramSetup
    robot: Robot
    trajectory: JointTrajectory
    size: int | None
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def steps(self) -> int:
        """Number of 2 ms steps of the coupled loop."""
        return len(self.trajectory.t)


def prepare(job: MachiningJob, *, trajectory: JointTrajectory | None = None) -> PreparedJob:
    """Read and interpolate the program (unless shared), load the robot, solve the inverse kinematics
    (unless ``trajectory`` is given: same kinematics, program and placement)."""
    from simulate.toolpath.placement import joint_trajectory

    s = job.settings
    s.validate()
    c0 = time.perf_counter()
    prog = job.program if isinstance(job.program, ProgramSetup) else load_program(
        job.program, stock=job.stock, spindle_rpm=s.spindle_rpm, require_spindle=s.require_spindle, setup=job.setup)
    size = piece_size(prog, s.size)
    robot = _robot(job.robot)
    jt = trajectory if trajectory is not None else joint_trajectory(robot, prog.interp, job.placement,
                                                                   source=prog.source)
    return PreparedJob(prog, robot, jt, size, {"program + kinematics": time.perf_counter() - c0})


def run_job(job: MachiningJob, *, prepared: PreparedJob | None = None, advance=None,
            profile: bool = False) -> MachiningOutcome:
    """Run one machining simulation (module docstring).

    Parameters
    ----------
    job : MachiningJob
    prepared : PreparedJob, optional
        :func:`prepare` of this job, when the caller needed it first (e.g. for the step count).
    advance : callable(n), optional
        Progress of the coupled loop in steps.
    profile : bool
        Run the clock-reading copy of the loop (``result.timings`` split by stage).

    Raises
    ------
    InputError
        Naming the file, line, key or setting at fault.
    """
    from simulate.evaluation.cutter import robot_cutter
    from simulate.machining.cutting import Spindle, load_material
    from simulate.machining.simulation import simulate_machining, workpiece_compliance
    from simulate.robot.stiffness import Compliance

    s, comp = job.settings, job.components
    s.validate()
    pj = prepared if prepared is not None else prepare(job)
    prog, robot, jt, size = pj.program, pj.robot, pj.trajectory, pj.size
    timings = dict(pj.timings)
    cutter = robot_cutter(robot)
    mat = load_material(s.material)
    rpm = s.spindle_rpm or prog.spindle_rpm
    c0 = time.perf_counter()
    R = job.placement.T[:3, :3]
    # each compliance once: the drives wind the gears up under the process torque, so the static
    # term holds only the links'; without the drives it holds the gears' too (quasi-static)
    part = Compliance.LINK if comp.servo else Compliance.TOTAL
    C = workpiece_compliance(robot, jt.q, R, s.stiffness_scale, part) if comp.deflection else None
    drive = None
    if comp.servo:
        from simulate.machining.simulation import loop_drive
        from simulate.robot.drive import drive_flags, drive_friction
        from simulate.robot.friction import loop_friction

        flags = drive_flags(friction=comp.friction, backlash=comp.switching, ff_friction=s.ff_friction)
        fp, fr = loop_friction(robot, job.friction, enabled=comp.friction)
        fp = drive_friction(robot, fp, scale=s.friction_scale, flags=flags)
        q_ref = jt.q
        if s.backlash_comp and comp.switching:
            from simulate.robot.backlash import nc_backlash_offset

            q_bl = nc_backlash_offset(robot, jt.t, jt.q, fp)
            q_ref = jt.q + q_bl
        drive = loop_drive(robot, q_ref, jt.t, R, fp, substeps=s.substeps, flags=flags, process=comp.deflection,
                           stiffness_scale=s.stiffness_scale)
    else:
        fr = [{"joint": j, "kind": "none", "source": "no drives"} for j in range(1, 7)]
    n = len(jt.t)
    offset = np.zeros((n, 3)) if job.offset is None else np.broadcast_to(np.asarray(job.offset, float), (n, 3))
    if drive is not None and q_ref is not jt.q:
        # the loop's error is J (q_link - q_ref); the tool's is against the program's q: add J (q_ref - q)
        offset = offset + np.einsum("nij,nj->ni", drive.jac, q_ref - jt.q)
    timings["robot (compliance, drive setup)"] = time.perf_counter() - c0
    c0 = time.perf_counter()
    wp = stock_workpiece(prog, s)
    timings["stock"] = time.perf_counter() - c0
    res = simulate_machining(wp, cutter, jt.t, jt.line, jt.xyz, mat, Spindle.from_rpm(rpm), compliance=C,
                             tracking_error=offset, switch=jt.switch if comp.switching else None,
                             forces=prog.stock is not None, advance=advance, profile=profile, drive=drive)
    err = res.steps.tracking_error
    timings["coupled loop"] = res.wall_time
    scan = table = None
    if size is not None:
        from simulate.evaluation.cmm import probe
        from simulate.toolpath.testpiece import iso_test_piece

        c0 = time.perf_counter()
        piece = iso_test_piece(size)
        try:
            scan = probe(wp, piece, spacing=s.probe_spacing, tool_diameter=cutter.diameter)
        except InputError as exc:
            # the stock's geometry does not hold the features: it is not that test piece
            raise InputError(f"not the {size} mm test piece for the virtual CMM: {exc.message}",
                             source=str(prog.stock), field="size") from None
        if s.features:
            from simulate.evaluation.features import evaluate_scan  # scipy.optimize: only when evaluated

            table = evaluate_scan(scan, piece)
        timings["cmm + features"] = time.perf_counter() - c0
    return MachiningOutcome(program=prog, robot=robot, trajectory=jt, workpiece=wp, result=res, cutter=cutter,
                            tracking_error=err, scan=scan, table=table, friction=fr or [], timings=timings)
