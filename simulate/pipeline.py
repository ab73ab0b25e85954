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
        [rev/min], every move; None: each move at the program's S in force (a program with no S at all
        at :data:`simulate.defaults.SPINDLE_RPM`, stated in ``ProgramSetup.warnings``, when
        ``require_spindle`` is False; a cutting move with the spindle stopped is refused).
    require_spindle : bool
        Refuse a program that never sets the spindle speed (the ranking: forces would rest on a guess).
    require_units : bool
        Refuse a program whose first move comes before any ``G20``/``G21`` (False: read as mm, stated
        in ``ProgramSetup.warnings``).
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
    require_units: bool = False
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
        [rev/min], the highest speed the program cuts at.
    step_rpm : ndarray (N,)
        [rev/min] per step of ``interp``: the S in force (rapids with the spindle stopped take the
        speed of the cut before them, else after them: they cut nothing).
    step_tool : ndarray (N,) int
        Tool in the spindle per step of ``interp`` (``T`` of the last ``M6``; 0: none named).
    setup : MachineSetup or None
        The setup file's tables the program was read with (its tool table gives the cutters).
    warnings : list of str
        Assumptions the reading made (no units word, the default spindle speed), one line each.
    """

    program: Path
    source: str
    parsed: Program
    interp: Interpolation
    stock: Path | None
    stock_doc: dict
    spindle_rpm: float
    step_rpm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    step_tool: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    setup: MachineSetup | None = None
    warnings: list[str] = field(default_factory=list)


def load_program(program: str | Path, *, stock: str | Path | None = None, spindle_rpm: float | None = None,
                 require_spindle: bool = False, source: str | None = None,
                 setup: MachineSetup | None = None, require_units: bool = False) -> ProgramSetup:
    """Read and interpolate a program; find its stock (``<program stem>.stock.json`` unless given).

    ``setup``: work offsets and tool table [m] (:func:`simulate.toolpath.setup.read_setup`); default
    none, where only ``G54`` with zero offset and ``G43`` of the loaded tool are accepted.
    ``spindle_rpm`` [rev/min]: every move at this speed; None: the program's S per move
    (:func:`segment_speeds`). ``require_units``: refuse a program without ``G20``/``G21`` before
    its first move (otherwise read as mm with a warning).

    Raises ``InputError`` naming the program line, the stock file or the spindle.
    """
    from simulate.toolpath.gcode import read_program
    from simulate.toolpath.interpolation import PathLimits, interpolate

    program = Path(program)
    name = source or str(program)
    prog = read_program(program, require_units=require_units, **setup_tables(setup))
    stock = Path(stock) if stock is not None else program.with_name(program.stem + ".stock.json")
    doc = read_json(stock, missing="stock description not found (give --stock)")
    warnings = []
    if prog.units_assumed:
        warnings.append(f"{name}: line {prog.units_assumed}: no units word (G20/G21) before the first move: "
                        f"read as mm (--require-units refuses such a program)")
    seg_rpm, note = segment_speeds(prog, spindle_rpm, require_spindle=require_spindle, source=name)
    if note:
        warnings.append(note)
    interp = interpolate(prog, PathLimits())
    seg = np.clip(np.asarray(interp.segment, np.int64), 0, max(len(prog.segments) - 1, 0))
    step_rpm = seg_rpm[seg] if len(prog.segments) else np.full(len(interp.t), defaults.SPINDLE_RPM)
    tools = np.array([s.tool for s in prog.segments], np.int64)
    step_tool = tools[seg] if len(prog.segments) else np.zeros(len(interp.t), np.int64)
    cutting = [r for r, s in zip(seg_rpm, prog.segments, strict=True) if not getattr(s, "rapid", False)]
    top = float(max(cutting)) if cutting else float(seg_rpm.max()) if seg_rpm.size else defaults.SPINDLE_RPM
    return ProgramSetup(program=program, source=name, parsed=prog, interp=interp, stock=stock,
                        stock_doc=doc if isinstance(doc, dict) else {}, spindle_rpm=top, step_rpm=step_rpm,
                        step_tool=step_tool, setup=setup, warnings=warnings)


def segment_speeds(prog: Program, spindle_rpm: float | None = None, *, require_spindle: bool = False,
                   source: str = "<program>") -> tuple[np.ndarray, str]:
    """Spindle speed [rev/min] per segment of ``prog`` and the assumption made (or "").

    ``spindle_rpm`` given: every segment at it. Otherwise the S in force with ``M3``/``M4`` (the
    reader's ``spindle``); a program with no S at all runs at :data:`simulate.defaults.SPINDLE_RPM`
    (stated in the returned line; refused with ``require_spindle``); a program that does set a
    speed but feeds with the spindle stopped (no S yet, ``S0``, after ``M5``) is refused naming the
    line. Rapids with the spindle stopped take the speed of the cut before them (else after them).
    """
    n = len(prog.segments)
    if spindle_rpm is not None:
        return np.full(n, float(spindle_rpm)), ""
    rpm = np.array([float(getattr(s, "spindle", 0.0)) * 60.0 for s in prog.segments])  # rev/s -> rev/min
    if not (rpm > 0).any():
        if require_spindle:
            raise InputError("the program never switches the spindle on (no S word with M3/M4); give --spindle",
                             source=source)
        return (np.full(n, defaults.SPINDLE_RPM),
                f"{source}: no spindle speed (S with M3/M4) in the program: cut at the default "
                f"{defaults.SPINDLE_RPM:g} rev/min (--spindle sets it)" if n else "")
    for s, r in zip(prog.segments, rpm, strict=True):
        if r <= 0 and not getattr(s, "rapid", False):
            raise InputError("a cutting move with the spindle stopped (no S yet, S0 or after M5): give S with "
                             "M3/M4 before it, or --spindle", source=source, line=s.line)
    # rapids at a stopped spindle: forward fill, then back fill (the first speed)
    last = 0.0
    for i in range(n):
        last = rpm[i] if rpm[i] > 0 else last
        rpm[i] = last
    rpm[rpm <= 0] = rpm[rpm > 0][0]
    return rpm, ""


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
        The robot file's tool (the cutter of moves whose tool the setup's tool table does not
        describe; ``result.tools`` lists the tools each pass was cut with).
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
        job.program, stock=job.stock, spindle_rpm=s.spindle_rpm, require_spindle=s.require_spindle, setup=job.setup,
        require_units=s.require_units)
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
    from simulate.machining.cutting import load_material
    from simulate.machining.simulation import simulate_machining, workpiece_compliance
    from simulate.robot.stiffness import Compliance

    s, comp = job.settings, job.components
    s.validate()
    pj = prepared if prepared is not None else prepare(job)
    prog, robot, jt, size = pj.program, pj.robot, pj.trajectory, pj.size
    timings = dict(pj.timings)
    cutter = robot_cutter(robot)
    passes = program_passes(prog, cutter, jt, s.spindle_rpm)
    mat = load_material(s.material)
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
    try:
        res = simulate_machining(wp, cutter, jt.t, jt.line, jt.xyz, mat, passes.spindles[0], compliance=C,
                                 tracking_error=offset, switch=jt.switch if comp.switching else None,
                                 forces=prog.stock is not None, advance=advance, profile=profile, drive=drive,
                                 passes=passes, check_limits=True, feeding=_feeding(prog, n))
    except InputError as exc:   # a limit of the physically possible: the line is the program's
        if exc.source is None:
            raise type(exc)(exc.message, source=prog.source, line=exc.line, field=exc.field) from None
        raise
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


def program_cutters(prog: ProgramSetup, base: Cutter) -> dict[int, Cutter]:
    """The cutter of each tool number the program cuts with (docs/gcode.md, "Tools from the program").

    A tool the setup file's tool table lists is built from its diameter and cutting-edge fields,
    the robot file's tool (``base``) filling the fields it leaves out. With no tool table, a
    program that cuts with one tool (or none named) cuts with ``base``; one that cuts with several
    is refused (each pass would silently be cut with the robot's tool). A tool the table lacks is
    refused naming the first line it cuts on.
    """
    import math

    from simulate.machining.tools import make_cutter

    table = prog.setup.tools if prog.setup is not None else {}
    edges = prog.setup.cutting if prog.setup is not None else {}
    first: dict[int, int] = {}   # tool -> first line it cuts on
    used: set[int] = set()
    for seg in prog.parsed.segments:
        used.add(int(seg.tool))
        if not getattr(seg, "rapid", False):
            first.setdefault(int(seg.tool), int(seg.line))
    if not table:
        named = sorted(n for n in first if n)
        if len(named) > 1:
            raise InputError(f"the program cuts with tools {', '.join(f'T{n}' for n in named)} but no tool table "
                             f"describes them: give --setup with 'tools' (docs/gcode.md)", source=prog.source,
                             line=first[named[1]])
        return {}
    cutters: dict[int, Cutter] = {}
    for n in sorted(used):
        if n not in table:
            if n == 0 or n not in first:
                continue   # moves before any T, or rapids only: the robot's tool
            line = first[n]
            raise InputError(f"tool T{n} is not in the setup file's tool table (known: "
                             f"{', '.join(f'T{k}' for k in sorted(table))})", source=prog.source, line=line)
        e = edges.get(n)
        kind = (e.kind if e is not None and e.kind else None) or base.kind.value
        radius = table[n][1]
        rc = e.corner_radius if e is not None and e.corner_radius is not None else (
            base.corner_radius if kind == base.kind.value == "bull" and base.corner_radius < radius else None)
        try:
            cutters[n] = make_cutter(kind, 2.0 * radius, corner_radius=rc,
                                     flutes=e.flutes if e is not None and e.flutes else base.flutes,
                                     helix_deg=e.helix_deg if e is not None and e.helix_deg is not None
                                     else math.degrees(base.helix),
                                     length=e.flute_length if e is not None and e.flute_length else base.length)
        except InputError as exc:
            key = {"kind": "type", "length": "flute_length"}.get(exc.field or "", exc.field)
            raise InputError(exc.message, source="setup", field=f"tools.{n}.{key}") from None
    return cutters


def program_passes(prog: ProgramSetup, base: Cutter, jt: JointTrajectory, spindle_rpm: float | None = None):
    """The :class:`simulate.machining.simulation.ToolPasses` of a job: per 2 ms step of ``jt`` the
    cutter (:func:`program_cutters`) and spindle speed (``spindle_rpm`` [rev/min] when given, else
    ``prog.step_rpm``)."""
    from simulate.machining.cutting import Spindle
    from simulate.machining.simulation import ToolPasses

    n = len(jt.t)
    cutters = program_cutters(prog, base)
    if spindle_rpm is not None or len(prog.step_rpm) != n:
        rpm = np.full(n, float(spindle_rpm or prog.spindle_rpm))
    else:
        rpm = np.asarray(prog.step_rpm, float)
    tool = np.asarray(prog.step_tool, np.int64) if len(prog.step_tool) == n else np.zeros(n, np.int64)
    tool = np.where(np.isin(tool, list(cutters)), tool, 0) if cutters else np.zeros(n, np.int64)
    keys: dict[tuple[int, float], int] = {}
    index = np.empty(n, np.int64)
    for k, key in enumerate(zip(tool.tolist(), rpm.tolist(), strict=True)):
        index[k] = keys.setdefault(key, len(keys))
    entries = list(keys)
    return ToolPasses(tuple(cutters.get(t, base) for t, _ in entries),
                      tuple(Spindle.from_rpm(r) for _, r in entries), tuple(t for t, _ in entries), index)


def _feeding(prog: ProgramSetup, n: int) -> np.ndarray | None:
    """(n,) bool: the steps of feed moves (not rapids) of the program's interpolation (None when
    the rows are not the interpolation's)."""
    seg = np.asarray(prog.interp.segment, np.int64)
    if len(seg) != n or not prog.parsed.segments:
        return None
    rapid = np.array([bool(getattr(s, "rapid", False)) for s in prog.parsed.segments])
    return ~rapid[np.clip(seg, 0, len(rapid) - 1)]
