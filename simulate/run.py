"""The simulation workflows behind the ``greybench`` commands: checked inputs in, files written, typed
results out; the caller parses the options and prints (SI inside, ``*_mm`` arguments in mm).

Every workflow checks its inputs before any work (``InputError`` naming the file or the CLI option,
so the command exits 2 and writes nothing), runs the one machining pipeline
(:mod:`simulate.pipeline`, defaults from :mod:`simulate.defaults`) or the module that owns the
step, and reports progress through a :data:`identify.progress.Progress` factory (quiet by default).
Heavy modules are imported inside the functions: the CLI imports this module at start-up.
"""
from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

from identify.errors import InputError, read_json
from identify.progress import Advance, Progress, quiet
from simulate import defaults
from simulate.compensation.settings import CompensationSettings
from simulate.toolpath.setup import MachineSetup

if TYPE_CHECKING:
    import pandas as pd

    from identify.models import FrictionModel
    from identify.workflows import Table
    from simulate.evaluation.circle import CircleResult
    from simulate.evaluation.ranking import Components as RankComponents
    from simulate.evaluation.ranking import Ranking, RankSettings
    from simulate.evaluation.trace import Trace
    from simulate.explain.pipeline import Explanation
    from simulate.machining.simulation import MachiningResult
    from simulate.machining.tools import Cutter
    from simulate.pipeline import MachiningJob, MachiningOutcome
    from simulate.robot.model import Robot
    from simulate.toolpath.interpolation import PathLimits
    from simulate.toolpath.placement import JointTrajectory, Placement

MM = 1e-3
#: Folder with the robot files, poses, programs and sample records shipped with the project.
DATA_DIR = Path(__file__).resolve().parents[1] / "data"


def resolve_robot(name_or_path: str) -> Path:
    """A robot given by name (``max100`` -> ``data/robots/max100.toml``) or by path; ``InputError``
    naming the file or ``robot`` (with the known names)."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        if not p.exists():
            raise InputError("robot file not found", source=str(p))
        return p
    candidate = DATA_DIR / "robots" / f"{name_or_path}.toml"
    if not candidate.exists():
        known = sorted(x.stem for x in (DATA_DIR / "robots").glob("*.toml"))
        raise InputError(f"unknown robot '{name_or_path}' (known: {', '.join(known)})", field="robot")
    return candidate


def _folder(out_dir: Path | None, field: str = "out") -> None:
    """Refuse an output path that exists and is not a folder."""
    if out_dir is not None and out_dir.exists() and not out_dir.is_dir():
        raise InputError("output path exists and is not a folder", source=str(out_dir), field=field)


def _program(program: Path) -> None:
    if not program.exists():
        raise InputError("program not found", source=str(program))


def check_cost(program: Path, stock: Path | None, spacing_mm: float, simulations: int = 1,
               setup: MachineSetup | None = None) -> None:
    """Refuse a machining run before any work when its estimated cut time or memory exceeds the limits
    of :class:`simulate.costs.CostLimits` (the service's defaults): ``InputError`` naming ``--program``
    (and its line), ``--spacing`` [mm] or ``--stock``. Missing files are left to the workflow's own checks."""
    from simulate.costs import CostFields, check_machining_cost

    stock = stock if stock is not None else program.with_name(program.stem + ".stock.json")
    if not (program.is_file() and stock.is_file()):
        return
    check_machining_cost(program.read_text(errors="replace"), stock.read_text(errors="replace"), spacing_mm * MM,
                         simulations=simulations, source=str(program), stock_source=str(stock),
                         fields=CostFields(program="--program", spacing="--spacing", stock="--stock"), setup=setup)


# ---- submission checks: the CLI and the service alike ------------------------------------------
def check_digits(text: str, source: str, field: str | None = None) -> None:
    """``InputError`` naming the line and column of the first digit outside 0-9 (Python reads Arabic-Indic
    and other Unicode digits as numbers; no controller does)."""
    for lineno, line in enumerate(text.splitlines(), start=1):
        for col, ch in enumerate(line, start=1):
            if ch.isdigit() and not ch.isascii():
                raise InputError(f"non-ASCII digit '{ch}' (U+{ord(ch):04X}): G-code numbers use the digits 0-9",
                                 source=source, field=field, line=lineno, column=col)


def check_program_text(text: str, source: str, field: str | None = None, *, spindle_rpm: float | None = None,
                       setup: MachineSetup | None = None) -> None:
    """The program checks every machining submission passes before any work (``greybench rank-poses`` and
    the service's jobs): ASCII digits (:func:`check_digits`), the program parses (``InputError`` naming
    the line), it has motion (not empty or comments only) and, without a default ``spindle_rpm``
    [rev/min], it switches the spindle on."""
    from simulate.toolpath.gcode import parse_program
    from simulate.toolpath.setup import setup_tables

    check_digits(text, source, field)
    prog = parse_program(text, source=source, **setup_tables(setup))
    if not prog.segments:
        raise InputError("the program has no motion (empty, or only comments and settings)", source=source,
                         field=field)
    if spindle_rpm is None and not any(getattr(seg, "spindle", 0) > 0 for seg in prog.segments):
        raise InputError("the program never switches the spindle on (no S word with M3/M4 before a cut)",
                         source=source, field=field)


def check_material(name: str | None, field: str = "material") -> None:
    """``InputError`` naming ``field`` for a material not in ``data/materials.toml`` (None: the default)."""
    from simulate.machining.cutting import load_material

    if name is None:
        return
    try:
        load_material(name)
    except InputError as exc:
        raise InputError(exc.message, source="materials.toml", field=field) from None


def check_reach(text: str, source: str, rob: Robot, placements: Sequence[Placement], fields: Sequence[str], *,
                setup: MachineSetup | None = None) -> None:
    """``InputError`` naming ``fields[i]`` (and the program line) when placement ``i`` puts a point of the
    program out of reach, beyond a joint limit or above a joint speed limit: the pipeline's own check
    (:func:`simulate.toolpath.placement.joint_trajectory`) before any simulation starts."""
    from simulate.toolpath.gcode import parse_program
    from simulate.toolpath.interpolation import PathLimits, interpolate
    from simulate.toolpath.placement import joint_trajectory
    from simulate.toolpath.setup import setup_tables

    interp = interpolate(parse_program(text, source=source, **setup_tables(setup)), PathLimits())
    for placement, field in zip(placements, fields, strict=True):
        try:
            joint_trajectory(rob, interp, placement, source=source)
        except InputError as exc:
            raise InputError(exc.message, source=source, field=field, line=exc.line) from None


# ---- one part: greybench machine --------------------------------------------------------------
def cutter_from_robot(rob: Robot) -> Cutter:
    """The cutter the robot carries: its file's ``[tool]`` table, via
    :func:`simulate.evaluation.cutter.robot_cutter` (the one source for ``machine``, ``rank-poses`` and
    ``explain``). Bad values raise ``InputError`` naming the robot file and the ``tool.*`` key."""
    from simulate.evaluation.cutter import robot_cutter

    try:
        return robot_cutter(rob)
    except InputError as exc:
        key = {"kind": "type"}.get(exc.field or "", exc.field) or "type"
        raise InputError(exc.message, source=rob.source or None, field=f"tool.{key}") from None


def machining_job(program: Path, robot: Path, pose: Path, name: str | None, *, ideal: bool = False,
                  spacing_mm: float | None = None, no_deflection: bool = False, no_friction: bool = False,
                  no_switching: bool = False, no_tracking: bool = False, material: str | None = None,
                  stock: Path | None = None, spindle_rpm: float | None = None, stiffness_scale: float = 1.0,
                  size: int | None = None, probe_spacing_mm: float | None = None,
                  setup: Path | None = None, require_units: bool = False) -> MachiningJob:
    """The :class:`simulate.pipeline.MachiningJob` of ``greybench machine``'s options (mm -> m).

    ``ideal`` switches off deflection, tracking error and backlash; ``no_friction`` runs the servo
    without joint friction (its tracking error stays); ``no_tracking`` drops the tracking error
    altogether; ``no_switching`` drops the gear backlash (the switching-point effect) and its bits.
    Defaults: :mod:`simulate.defaults`. A job whose cut time or memory exceeds the limits is refused
    (:func:`check_cost`). ``setup``: a setup file (work offsets, tool table;
    :mod:`simulate.toolpath.setup`). ``require_units``: refuse a program without ``G20``/``G21``.
    """
    from simulate.pipeline import Components, MachiningJob, MachiningSettings
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import load_poses, select_pose
    from simulate.toolpath.setup import read_setup

    spacing_mm = defaults.DEXEL_SPACING / MM if spacing_mm is None else spacing_mm
    probe_spacing_mm = defaults.PROBE_SPACING / MM if probe_spacing_mm is None else probe_spacing_mm
    if not (spacing_mm > 0 and math.isfinite(spacing_mm)):
        raise InputError(f"dexel spacing must be > 0 mm, got {spacing_mm}", field="spacing")
    if not (probe_spacing_mm > 0 and math.isfinite(probe_spacing_mm)):
        raise InputError(f"probe spacing must be > 0 mm, got {probe_spacing_mm}", field="probe-spacing")
    tables = None if setup is None else read_setup(setup)
    check_cost(program, stock, spacing_mm, setup=tables)
    placement = select_pose(load_poses(pose), name, source=str(pose))
    rob = load_robot(robot)
    cutter_from_robot(rob)  # tool errors name the robot file's key
    comp = Components(deflection=not (ideal or no_deflection), friction=not no_friction,
                      switching=not (ideal or no_switching), servo=not (ideal or no_tracking))
    settings = MachiningSettings(spacing=spacing_mm * MM, probe_spacing=probe_spacing_mm * MM,
                                 material=material or defaults.MATERIAL, spindle_rpm=spindle_rpm,
                                 stiffness_scale=stiffness_scale, size=size, require_units=require_units)
    return MachiningJob(program=program, robot=rob, placement=placement, components=comp, settings=settings,
                        stock=stock, setup=tables)


#: Files :func:`write_machining_outputs` writes besides the optional scan (its progress total).
OUTPUT_STAGES = ("virtual workpiece (npz)", "surface meshes (PLY, GLB, legend)", "top view (PNG)",
                 "oblique view (PNG)")


class MachiningSummary(TypedDict):
    """``greybench machine --json`` (SI)."""

    steps: int
    simulated_time: float   # [s]
    wall_time: float        # [s]
    removed_volume: float   # [m^3]
    peak_force: float       # [N]
    peak_deflection: float  # [m]
    tools: list[dict[str, Any]]   # per tool: tool (T), diameter [m], flutes, spindle_rpm [rev/min],
    #                               steps, removed_volume [m^3], peak_force [N]


#: The unit of each :class:`MachiningSummary` number, for labels.
MACHINING_UNITS = {"simulated_time": "s", "wall_time": "s", "removed_volume": "m^3", "peak_force": "N",
                   "peak_deflection": "m"}


def machine_part(job: MachiningJob, out_dir: Path, variable: str = "deflection", progress: Progress = quiet,
                 on_warnings: Callable[[list[str]], None] | None = None) -> MachiningSummary:
    """Simulate one part and write its outputs (:func:`write_machining_outputs`) into ``out_dir``.

    ``variable`` colours the surface (one of :data:`simulate.machining.virtual_workpiece.VARIABLES`).
    Colour variable and output folder are checked before any work. Progress: the coupled loop in
    2 ms steps ("machining"), then the files ("writing outputs"). ``on_warnings`` gets the
    assumptions the program's reading made (no units word, the default spindle speed) before the loop.
    """
    from simulate.machining.virtual_workpiece import VARIABLES
    from simulate.pipeline import prepare, run_job

    if variable not in VARIABLES:
        raise InputError(f"unknown variable '{variable}' (one of {', '.join(VARIABLES)})", field="color")
    _folder(out_dir)
    pj = prepare(job)
    if on_warnings is not None and pj.program.warnings:
        on_warnings(pj.program.warnings)
    with progress("machining", pj.steps) as adv:
        mo = run_job(job, prepared=pj, advance=adv)
    with progress("writing outputs", len(OUTPUT_STAGES) + (mo.scan is not None)) as adv:
        write_machining_outputs(mo, out_dir, variable, advance=adv)
    return machining_summary(_result(mo))


def write_machining_outputs(mo: MachiningOutcome, out_dir: Path, variable: str = "deflection",
                            advance: Advance | None = None) -> list[Path]:
    """Write ``virtual_workpiece.npz``, ``surface_<variable>.ply/.glb``, ``render_<variable>.png`` (top
    view of the machined surface points), ``render3d_<variable>.png`` (oblique view of the mesh) and,
    when the outcome has a scan, the virtual CMM's ``scan.csv`` (:func:`simulate.evaluation.cmm.write_scan`)
    into ``out_dir``: all are written into a temporary folder next to it first and moved in only
    when every one succeeded, so a failure leaves nothing half-written. ``advance`` counts the files of
    :data:`OUTPUT_STAGES` (+ scan).

    The npz is compressed in a second thread while the meshes and pictures are made (zlib releases
    the GIL), so on two cores its time is hidden."""
    from concurrent.futures import ThreadPoolExecutor

    from identify.files import atomic_files
    from simulate.machining.dexel import TriDexel
    from simulate.machining.virtual_workpiece import VirtualWorkpiece, export_meshes, render_mesh_png, render_png

    adv = advance if advance is not None else Advance()
    assert isinstance(mo.workpiece, TriDexel)  # the pipeline's stages are typed object
    out_dir = Path(out_dir)
    with atomic_files(out_dir) as tmp:
        vw = VirtualWorkpiece(mo.workpiece, _result(mo).steps)
        with ThreadPoolExecutor(1, thread_name_prefix="greybench-npz") as pool:
            saved = pool.submit(vw.save, tmp / "virtual_workpiece.npz")
            adv.describe(OUTPUT_STAGES[1])
            export_meshes(vw, tmp, variable)
            adv(1)
            adv.describe(OUTPUT_STAGES[2])
            render_png(vw, tmp / f"render_{variable}.png", variable)
            adv(1)
            adv.describe(OUTPUT_STAGES[3])
            render_mesh_png(vw, tmp / f"render3d_{variable}.png", variable)
            adv(1)
            if mo.scan is not None:
                from simulate.evaluation.cmm import Scan, write_scan

                assert isinstance(mo.scan, Scan)
                adv.describe("scan.csv")
                write_scan(mo.scan, tmp / "scan.csv")
                adv(1)
            adv.describe(OUTPUT_STAGES[0])
            saved.result()
            adv(1)
        names = sorted(f.name for f in tmp.iterdir())
    return [out_dir / n for n in names]


def _result(mo: MachiningOutcome) -> MachiningResult:
    """The outcome's per-step process values (the pipeline types its stages as object)."""
    from simulate.machining.simulation import MachiningResult

    assert isinstance(mo.result, MachiningResult)
    return mo.result


def machining_summary(res: MachiningResult) -> MachiningSummary:
    """Steps, simulated and wall time [s], removed volume [m^3], peak force [N], peak deflection [m]."""
    import numpy as np

    n = len(res.steps.t)
    return {"steps": int(n), "simulated_time": float(res.simulated_time), "wall_time": float(res.wall_time),
            "removed_volume": float(res.removed_volume),
            "peak_force": float(res.steps.peak_force.max()) if n else 0.0,
            "peak_deflection": float(np.linalg.norm(res.steps.deflection, axis=1).max()) if n else 0.0,
            "tools": [{"tool": u.tool, "diameter": u.diameter, "flutes": u.flutes, "spindle_rpm": list(u.spindle_rpm),
                       "steps": u.steps, "removed_volume": u.removed_volume, "peak_force": u.peak_force}
                      for u in res.tools]}


# ---- placements: greybench rank-poses, optimize-pose ---------------------------------------------
def rank_program(program: Path, robot: Path, poses: Path, *, settings: RankSettings,
                 components: RankComponents, shares: bool = False, out_dir: Path | None = None, workers: int = 2,
                 friction: dict[int, str] | None = None, progress: Progress = quiet,
                 setup: Path | None = None, ray_address: str | None = None) -> Ranking:
    """Simulate the program in every pose of the pose file, measure and rank the virtual parts
    (:func:`simulate.evaluation.ranking.rank_poses`); with ``out_dir`` also the report
    (:func:`simulate.evaluation.report.write_report`). ``friction``: joint -> model reference in place
    of the robot file's (errors name ``--friction``). ``workers`` processes, or Ray tasks on the cluster
    at ``ray_address`` (None: ``RAY_ADDRESS`` when set; ``""``: no Ray). Progress in simulations
    ("simulating poses"). ``setup``: a setup file (work offsets, tool table; :mod:`simulate.toolpath.setup`).
    The one ranking workflow: ``greybench rank-poses`` and the service's simulation jobs call it."""
    from simulate.evaluation.ranking import COMPONENTS, rank_poses
    from simulate.robot.friction import joint_rows
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import load_poses
    from simulate.toolpath.setup import read_setup

    _program(program)
    rob = load_robot(robot)  # validate before any worker starts
    try:
        joint_rows(rob, friction)   # every model reference resolves, for its axis, before any work
    except InputError as exc:
        field = "--friction" if friction and exc.field and exc.field.startswith("friction[") else exc.field
        raise InputError(exc.message, source=exc.source, field=field) from None
    placements = load_poses(poses)
    tables = None if setup is None else read_setup(setup)
    text = program.read_text(errors="replace")
    # the service's submission checks (one function each), before any worker starts
    check_program_text(text, str(program), "--program", spindle_rpm=settings.spindle_rpm, setup=tables)
    check_material(settings.material)
    # refused before anything is written: the poses, and with shares the component re-runs, run in turn
    n_jobs = len(placements) * (1 + (len(COMPONENTS) if shares else 0))
    check_cost(program, None, settings.spacing / MM, simulations=n_jobs, setup=tables)
    check_reach(text, str(program), rob, placements, ["--poses"] * len(placements), setup=tables)
    _folder(out_dir)
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    with progress("simulating poses", n_jobs) as advance:
        r = rank_poses(program, robot, placements, settings=settings, components=components, shares=shares,
                       out_dir=out_dir, workers=workers, advance=advance, friction=friction,
                       ray_address=(os.environ.get("RAY_ADDRESS") if ray_address is None else ray_address) or None,
                       setup=tables)
    if out_dir is not None:
        from simulate.evaluation.report import write_report

        write_report(r, out_dir, program=program, trajectories=r.trajectories)
    return r


@dataclass(frozen=True)
class PlacementOutcome:
    """What :func:`optimize_placement` gives: ``info`` (``summary.json``: best pose [m, rad], scores [-],
    improvement [-], candidates, stop reason, wall time [s]; NaN where not scored) and the test-piece
    ``size`` [mm] it scored."""

    info: dict[str, Any]
    size: int

    def summary(self) -> dict[str, Any]:
        """The search in (item, value) rows for a summary table: best pose [mm, deg], scores [-],
        improvement [%], candidates, stop reason and wall time [s] (rich markup: ``\\[mm]``)."""
        info, b = self.info, self.info["best"]
        return {"best pose": f"{b['name']} ({b['origin']})",
                "best xyz \\[mm]": ", ".join(f"{v / MM:.1f}" for v in b["xyz_m"]),
                "best yaw \\[deg]": f"{math.degrees(b['rpy_rad'][2]):.1f}", "best score \\[-]": b["score"],
                **{f"given {g['name']} score \\[-]": g["score"] for g in info["given"]},
                "improvement \\[%]": 100 * info["improvement"], "candidates": json.dumps(info["candidates"]),
                "stopped": info["stop_reason"], "wall time \\[s]": info["wall_time_s"]}


def optimize_placement(program: Path, robot: Path, poses: Path, out_dir: Path, *, budget_s: float, workers: int = 2,
                       seed: int = 0, spacing_mm: float = defaults.RANKING_DEXEL_SPACING / MM,
                       size: int | None = None, xy_margin_mm: float = 400.0, z_margin_mm: float = 100.0,
                       max_simulations: int | None = None, robot_name: str = "",
                       progress: Progress = quiet, setup: Path | None = None) -> PlacementOutcome:
    """Search x, y, z and yaw of the workpiece for the lowest ranking score within ``budget_s`` [s]
    (:mod:`simulate.placement.search`) and write best.json, report.md, heatmap.png, history.csv and
    summary.json into ``out_dir`` (:func:`simulate.placement.report.write_outputs`). ``size`` [mm]
    defaults to the stock's ``size_mm``. Progress in seconds of the budget. ``setup``: a setup file
    (work offsets, tool table; :mod:`simulate.toolpath.setup`)."""
    from simulate.evaluation.ranking import RankSettings
    from simulate.placement.report import write_outputs
    from simulate.placement.search import SearchSettings, plan_search, run_search
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import parse_poses
    from simulate.toolpath.setup import read_setup

    _program(program)
    _folder(out_dir)
    load_robot(robot)
    doc = read_json(poses, missing="pose file not found")
    placements = parse_poses(doc, source=str(poses))
    if size is None:
        stock = read_json(program.with_name(program.stem + ".stock.json"),
                          missing="stock description not found next to the program")
        size = stock.get("size_mm") if isinstance(stock, dict) else None
        if size not in (160, 320):
            raise InputError("the stock names no test-piece size_mm: give --size 160 or 320", field="size")
    assert size is not None
    settings = SearchSettings(budget_s=budget_s, workers=workers, seed=seed,
                              rank=RankSettings(spacing=spacing_mm * MM, size=int(size)),
                              max_simulations=max_simulations, xy_margin=xy_margin_mm * MM,
                              z_margin=z_margin_mm * MM)
    tables = None if setup is None else read_setup(setup)
    check_cost(program, None, spacing_mm, simulations=1, setup=tables)
    plan = plan_search(program, robot, placements, settings, poses_source=str(poses),
                       setup=tables)  # every check first
    with progress("placement search", round(budget_s)) as advance:
        done = [0]

        def report(elapsed: float, text: str) -> None:
            step = int(min(elapsed, budget_s)) - done[0]   # whole seconds of the budget
            if step > 0:
                advance(step)
                done[0] += step
            advance.describe(text)

        result = run_search(plan, progress=report, ray_address=os.environ.get("RAY_ADDRESS") or None)
        advance.describe("writing the report and the heat map")
        info = write_outputs(result, out_dir, given_doc=doc, robot=plan.robot, interp=plan.program.interp,
                             program=str(program), robot_name=robot_name or robot.stem, poses=str(poses),
                             size=int(size))
    return PlacementOutcome(info=info, size=int(size))


# ---- compensation, explain --------------------------------------------------------------------
def compensation_steps(program: Path, iterations: int = CompensationSettings.iterations, stiffness_scale: float = 1.0,
                       check_scales: Sequence[float] = ()) -> int:
    """The progress total of :func:`simulate.compensation.job.run_compensation`
    (:func:`simulate.compensation.job.progress_total`: the original program's 2 ms steps per
    simulation, for the original, the iterations, two runs per stiffness multiplier [-] other than 1)."""
    from simulate.compensation import progress_total
    from simulate.pipeline import load_program
    from simulate.toolpath.interpolation import Interpolation

    _program(program)
    interp = load_program(program, require_spindle=True).interp
    assert isinstance(interp, Interpolation)  # the pipeline's stages are typed object
    return progress_total(len(interp), iterations, stiffness_scale, check_scales)


def write_explanation(ex: Explanation, out_dir: Path, measured_name: str) -> None:
    """``explain``'s files: the calibrated robot file ``robot_calibrated.toml``, ``report.md`` with its
    PNGs (:func:`simulate.explain.report.write_report`) and ``explain.json`` (SI)."""
    import json

    from identify.files import write_text_atomic
    from simulate.explain.report import write_report
    from simulate.robot.model import save_robot

    out_dir.mkdir(parents=True, exist_ok=True)
    save_robot(ex.calibrated_robot, out_dir / "robot_calibrated.toml")
    write_report(ex, out_dir, measured_name)
    write_text_atomic(out_dir / "explain.json", json.dumps(ex.as_json(), indent=1))


def explain_measured(measured: Path, program: Path, robot: Path, pose: Path, name: str | None, *,
                     out_dir: Path | None = None, spacing_mm: float = defaults.DEXEL_SPACING / MM,
                     size: int | None = None, max_sims: int = 3, progress: Progress = quiet) -> Explanation:
    """Compare a measured CMM scan with the simulated part, name the cause, calibrate it by
    re-simulating (:func:`simulate.explain.pipeline.explain_part`) and, with ``out_dir``, write
    :func:`write_explanation`'s files. Cost, scan and reachability are checked before the long part."""
    from simulate.explain.measured import is_table, read_measured_scan
    from simulate.explain.pipeline import explain_part, simulations_needed
    from simulate.explain.simulation import load_setup
    from simulate.robot.model import load_robot

    if max_sims < 1:
        raise InputError("must be >= 1", field="--max-sims")
    _folder(out_dir, "--out")
    # refused before any work: the nominal run, the re-machined sensitivities and the calibration
    check_cost(program, None, spacing_mm, simulations=simulations_needed(max_sims))
    rob = load_robot(robot)
    setup = load_setup(program, pose, name, spacing=spacing_mm * MM, size=size)
    if is_table(measured):
        raise InputError("a feature deviation table (JSON) allows only a feature-by-feature comparison, which "
                         "cannot separate the candidate causes; give the CMM scan (scan.csv)", source=str(measured))
    meas = read_measured_scan(measured, setup.piece)
    setup.trajectory(rob)  # reachability errors before the long part
    with progress("explaining (simulate, compare, calibrate)", None):
        ex = explain_part(meas, rob, setup, max_sims=max_sims)
    if out_dir is not None:
        write_explanation(ex, out_dir, str(measured))
    return ex


# ---- toolpath, robot ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Interpolated:
    """What :func:`interpolate_program` gives: the robot's name, the placement, the joint trajectory and
    its summary (samples, duration [s], path length [m], peak speed [m/s], switching steps per axis)."""

    robot: str
    placement: Placement
    trajectory: JointTrajectory
    summary: dict[str, Any]


def trajectory_frame(jt: JointTrajectory) -> pd.DataFrame:
    """Columns t [s], line, x, y, z (workpiece, m), q1..q6 (rad), qd1..qd6 (rad/s), switch."""
    import pandas as pd

    cols = {"t": jt.t, "line": jt.line, "x": jt.xyz[:, 0], "y": jt.xyz[:, 1], "z": jt.xyz[:, 2]}
    cols.update({f"q{i + 1}": jt.q[:, i] for i in range(6)})
    cols.update({f"qd{i + 1}": jt.qd[:, i] for i in range(6)})
    cols["switch"] = jt.switch
    return pd.DataFrame(cols)


def interpolate_program(program: Path, robot: Path, pose: Path, name: str | None, limits: PathLimits,
                        out_file: Path, progress: Progress = quiet, setup: Path | None = None) -> Interpolated:
    """Interpolate a program at the NC cycle (jerk-limited, look-ahead), transform it to the robot's
    joint angles and velocities for one placement, mark axis stops and reversals, and write the table
    of :func:`trajectory_frame` (.csv or .parquet). Progress in 4 stages. ``setup``: a setup file
    (work offsets, tool table; :mod:`simulate.toolpath.setup`)."""
    from identify.records import write_table
    from simulate.robot.model import load_robot
    from simulate.toolpath.gcode import read_program
    from simulate.toolpath.interpolation import interpolate
    from simulate.toolpath.placement import joint_trajectory, load_poses, select_pose
    from simulate.toolpath.setup import read_setup, setup_tables

    if out_file.suffix.lower() not in (".csv", ".parquet"):
        raise InputError("output must end in .csv or .parquet", source=str(out_file))
    limits.validate()
    with progress("interpolate", 4) as advance:
        advance.describe("reading the program")
        tables = setup_tables(None if setup is None else read_setup(setup))
        prog = read_program(program, **tables)
        placement = select_pose(load_poses(pose), name, source=str(pose))
        rob = load_robot(robot)
        advance(1)
        advance.describe("interpolating")
        ip = interpolate(prog, limits)
        advance(1)
        advance.describe("inverse kinematics")
        jt = joint_trajectory(rob, ip, placement, source=str(program))
        advance(1)
        advance.describe(f"writing {out_file}")
        write_table(trajectory_frame(jt), out_file)
        advance(1)
    summary = {"out": str(out_file), "pose": placement.name, "samples": len(ip), "duration_s": ip.duration,
               "path_length_m": prog.length, "max_speed_m_s": float(ip.v.max()),
               "switching_steps": int((jt.switch > 0).sum()),
               "switching_per_axis": [int(((jt.switch >> i) & 1).sum()) for i in range(6)]}
    return Interpolated(rob.name, placement, jt, summary)


def train_robot(log: Path, robot: Path, make: Callable[[], FrictionModel], axes: Sequence[int], *,
                test: Path | None = None, experiment: str = "train-robot", register: bool = True,
                model_name: str = "", progress: Progress = quiet) -> tuple[list[dict[str, Any]], str]:
    """Fit one friction model (``make()``, called ``model_name``) per robot axis from a six-axis log,
    split by the rigid-body model into axis records with tau_rb [Nm]
    (:func:`simulate.robot.prepare.prepare_log`), one MLflow run per axis under a parent run
    (:func:`identify.tracking.fit_axes`). Gives the per-axis rows and the parent run id."""
    import tempfile

    from identify.tracking import fit_axes
    from simulate.robot.model import load_robot
    from simulate.robot.prepare import prepare_log

    for a in axes:
        if a < 1:
            raise InputError(f"axis must be >= 1, got {a}", field="--axis")
    for a in axes:
        if a > 6:
            raise InputError(f"--axis {a}: the robot model and `prepare` handle joints 1..6", field="--axes")
    rob = load_robot(robot)
    with tempfile.TemporaryDirectory(prefix="greybench-train-robot-") as tmp:
        with progress("train-robot: splitting the logs (rigid-body model)", None):
            train_paths = prepare_log(rob, log, Path(tmp) / "train").paths
            test_paths = prepare_log(rob, test, Path(tmp) / "test").paths if test else None
        with progress(f"train-robot {model_name}", len(axes)) as advance:
            return fit_axes(make, {a: train_paths[a - 1] for a in axes},
                            {a: test_paths[a - 1] for a in axes} if test_paths else None,
                            experiment=experiment, robot=robot.stem, register=register, advance=advance,
                            params={"log": str(log), "test_log": str(test) if test else "",
                                    "format": log.suffix.lower()})


def _table_out(path: Path) -> None:
    if path.suffix.lower() not in (".csv", ".parquet", ".pq"):
        raise InputError("output must end in .csv or .parquet", source=str(path))
    if not path.parent.exists():
        raise InputError("output folder does not exist", source=str(path.parent))


def prepare_records(rob: Robot, log: Path, out_dir: Path, window_s: float) -> tuple[dict[str, Any], Table]:
    """Split a six-axis log into axis records with tau_rb and tau_load [Nm]
    (:func:`simulate.robot.prepare.prepare_log`, Savitzky-Golay window ``window_s`` [s]); gives the
    run's summary (records, samples, sampling period [s]) and the table of records per axis."""
    from identify.workflows import Table
    from simulate.robot.prepare import prepare_log

    if not window_s > 0:
        raise InputError("must be > 0 [s]", field="window")
    res = prepare_log(rob, log, out_dir, window_s=window_s)
    return ({"robot": rob.name, "log": str(log), "records": [str(p) for p in res.paths], "samples": res.n_samples,
             "dt_s": res.dt, "savgol_window_samples": res.window},
            Table(f"prepare ({rob.name}): {res.n_samples} samples at {res.dt * 1e3:.3g} ms", ("axis", "record"),
                  [(f"A{i + 1}", p) for i, p in enumerate(res.paths)], left=2))


def test_piece(out_file: Path, size: int = 320, tool_diameter_mm: float = 10.0, allowance_mm: float = 0.5,
               feed_mm_min: float = 2000.0, spindle_rpm: float = 12000.0) -> tuple[dict[str, Any], dict[str, str]]:
    """Write the finishing program of the ISO 10791-7 style test piece of ``size`` [mm] and its stock
    (:func:`simulate.toolpath.testpiece.write_test_piece`); gives the run's summary and the piece's
    dimensions for a summary table (circle diameter, square side [mm], slope [deg])."""
    from simulate.toolpath.testpiece import Technology, iso_test_piece, write_test_piece

    tech = Technology(tool_diameter=tool_diameter_mm / 1e3, allowance=allowance_mm / 1e3, feed=feed_mm_min,
                      spindle=spindle_rpm)
    prog, stock = write_test_piece(out_file, size=size, tech=tech)
    piece = iso_test_piece(size)
    return ({"program": str(prog), "stock": str(stock), "size_mm": size, "tool_diameter_mm": tool_diameter_mm,
             "allowance_mm": allowance_mm, "lines": len(prog.read_text().splitlines())},
            {"program": str(prog), "stock": str(stock),
             "circle diameter \\[mm]": f"{piece.circle_diameter * 1e3:g}", "square side \\[mm]":
             f"{piece.square_side * 1e3:g}", "slope \\[deg]": f"{math.degrees(piece.slope_angle):g}"})


def forward_table(rob: Robot, in_file: Path, out_file: Path, *, flange: bool = False) -> dict[str, Any]:
    """Forward kinematics of a joint table (q1..q6 [rad]) into a pose table (x, y, z [m], qw, qx, qy,
    qz) of the TCP, or of the flange; gives the run's summary (robot, files, number of poses, frame)."""
    from simulate.robot.kinematics import fk
    from simulate.robot.tables import JOINT_COLUMNS, frame_from_poses, numeric_columns, read_table, write_table

    _table_out(out_file)
    q = numeric_columns(read_table(in_file), JOINT_COLUMNS, str(in_file))
    write_table(frame_from_poses(fk(rob, q, tool=not flange)), out_file)
    return {"robot": rob.name, "in": str(in_file), "out": str(out_file), "poses": len(q),
            "frame": "flange" if flange else "tcp"}


def inverse_table(rob: Robot, in_file: Path, out_file: Path, *, q_start: Sequence[float] | None = None,
                  independent: bool = False) -> dict[str, Any]:
    """Inverse kinematics (analytic) of a pose table (x, y, z [m], qw, qx, qy, qz) into a joint table
    (q1..q6 [rad], ok, status; unreachable rows NaN), along a continuous path from ``q_start`` [rad]
    (default: mid of the limits for axes 2, 3, 5, 0 for 1, 4, 6) or each pose nearest it
    (``independent``); gives the run's summary: robot, files, number of poses, ``ok`` (with a valid
    solution), ``mode`` and ``status`` (number per :class:`simulate.robot.kinematics.IKStatus`)."""
    import numpy as np
    import pandas as pd

    from simulate.robot.kinematics import IKStatus, ik_nearest, ik_path
    from simulate.robot.tables import JOINT_COLUMNS, poses_from_frame, read_table, write_table

    _table_out(out_file)
    T = poses_from_frame(read_table(in_file), str(in_file))
    mid = np.array([False, True, True, False, True, False])
    q0 = np.asarray(q_start, float) if q_start is not None else np.where(mid, 0.5 * (rob.lower + rob.upper), 0.0)
    res = ik_nearest(rob, T, q0) if independent else ik_path(rob, T, q0)
    cols: dict[str, Any] = {c: res.q[:, i] for i, c in enumerate(JOINT_COLUMNS)}
    cols["ok"] = res.ok
    cols["status"] = [IKStatus(s).name for s in res.status]
    write_table(pd.DataFrame(cols), out_file)
    return {"robot": rob.name, "in": str(in_file), "out": str(out_file), "poses": len(res.ok), "ok": int(res.ok.sum()),
            "mode": "independent" if independent else "path",
            "status": {s.name: int(np.sum(res.status == s)) for s in IKStatus}}


def circle_test(robot: Path, pose: Path, name: str | None, out_dir: Path, *, radius_mm: float = 50.0,
                feed_mm_min: float = 2000.0, plane: str = "xy", center_mm: Sequence[float] = (0.0, 0.0, 0.0),
                cw: bool = False, friction: bool = True, backlash: bool = True, friction_scale: float = 1.0,
                ff_friction: bool = False, progress: Progress = quiet) -> tuple[CircleResult, dict[str, Any]]:
    """The virtual circular test (ISO 230-4) at a pose: simulate the circle of ``radius_mm`` [mm] at
    ``feed_mm_min`` [mm/min] about ``center_mm`` [mm, workpiece frame]
    (:func:`simulate.evaluation.circle.simulate_circle`), evaluate it and, only then, write circle.csv,
    circle.png and summary.json into ``out_dir``; gives the result and the summary."""
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import load_poses, select_pose

    spec = circle_spec(radius_mm, feed_mm_min, plane, center_mm, cw)
    placement = select_pose(load_poses(pose), name, source=str(pose))
    return run_circle(load_robot(robot), placement, spec, out_dir, friction=friction, backlash=backlash,
                      friction_scale=friction_scale, ff_friction=ff_friction, progress=progress)


def circle_spec(radius_mm: float, feed_mm_min: float, plane: str, center_mm: Sequence[float] = (0.0, 0.0, 0.0),
                cw: bool = False) -> Any:
    """The circle from its options: radius [mm], feed [mm/min], plane (xy, yz, zx; any case), centre [mm,
    workpiece frame], clockwise; ``InputError`` naming the option (``CircleSpec`` checks them)."""
    from typing import cast

    from simulate.evaluation.circle import CircleSpec, Plane

    return CircleSpec(radius=radius_mm * MM, feed=feed_mm_min / 6e4, plane=cast(Plane, plane.lower()),
                      center=tuple(v * MM for v in center_mm), ccw=not cw)


def run_circle(rob: Robot, placement: Placement, spec: Any, out_dir: Path, *, friction: bool = True,
               backlash: bool = True, friction_scale: float = 1.0, ff_friction: bool = False,
               friction_models: dict[int, str] | None = None, info: dict[str, Any] | None = None,
               progress: Progress = quiet) -> tuple[CircleResult, dict[str, Any]]:
    """Simulate, evaluate and only then write one circle (``circle.csv``, ``circle.png``,
    ``summary.json`` in ``out_dir``): the one sequence behind ``greybench circle`` and the service's
    circle jobs. ``friction_models``: joint 1..6 -> model reference replacing the robot file's;
    ``info`` is added to the summary (the service's request options)."""
    from simulate.evaluation.circle import evaluate_run, simulate_circle, write_outputs

    with progress("circle: simulating", None) as advance:
        run = simulate_circle(rob, placement, spec, friction=friction, backlash=backlash,
                              friction_scale=friction_scale, ff_friction=ff_friction,
                              friction_models=friction_models, advance=advance)
        result = evaluate_run(run)
    title = (f"{rob.name}, pose {placement.name}" + ("" if friction else ", no friction") + ("" if backlash else
             ", no backlash") + (f", friction x{friction_scale:g}" if friction_scale != 1 else ""))
    with progress("circle: writing the trace and the plot", None):
        summary = write_outputs(result, out_dir, title=title, info={
            "robot": rob.name, "pose": placement.name, "radius_mm": spec.radius / MM,
            "feed_mm_min": spec.feed * 6e4, "plane": spec.plane.value, "center_mm": [v / MM for v in spec.center],
            "cw": not spec.ccw, "friction": friction, "backlash": backlash, "friction_scale": friction_scale,
            "ff_friction": ff_friction, **(info or {}), "friction_models": run.friction})
    return result, summary


def circle_rows(result: CircleResult, summary: dict[str, Any]) -> dict[str, Any]:
    """The circle's figures [µm, to 0.1 µm as the spike table] and files, for a summary table."""
    um = {"roundness_um": result.roundness_um, "radius_error_um": result.radius_error_um,
          "largest_excursion_um": result.largest_excursion_um,
          "largest_reversal_spike_um": result.largest_reversal_spike_um,
          "largest_lost_motion_um": result.largest_lost_motion_um}
    return {**{k: f"{v:.1f}" for k, v in um.items()}, "csv": str(summary["csv"]), "png": str(summary["png"])}


def trace_json(tr: Trace, point_mm: Sequence[float], radius_mm: float) -> dict[str, Any]:
    """The ``trace --json`` object: the point [mm], the radius [mm] and per program line its times [s],
    dexel ends, largest deflection [m] and force [N] and the switching axes (1-based)."""
    from simulate.toolpath.switching import axes_of

    return {"point_mm": list(point_mm), "radius_mm": radius_mm, "n_ends": tr.n_ends,
            "lines": [{"line": ln.line, "text": ln.text, "t_first_s": ln.t_first, "t_last_s": ln.t_last,
                       "n_ends": ln.n_ends, "max_deflection_m": ln.max_deflection, "max_force_n": ln.max_force,
                       "switching_axes": axes_of(ln.switching)} for ln in tr.lines]}


def explanation_tables(ex: Explanation) -> list[Table]:
    """The causes ranked by score (dBIC [-]) with the held-out gain [%] and the fitted change, and
    the RMS measured - simulated [µm] per feature before and after the calibration."""
    from identify.workflows import Table

    return [Table(f"explain: cause {ex.cause} (score = dBIC vs no discrepancy; named above 10)",
                  ("cause", "score", "held-out gain \\[%]", "fitted change"),
                  [(f.cause, f"{f.score:.1f}", f"{f.heldout_gain * 100:.1f}", ", ".join(f"{v:.3g}" for v in f.theta))
                   for f in ex.choice.ranking[:8]]),
            Table("RMS measured - simulated \\[µm]", ("feature", "before", "after"),
                  [*[(k, f"{b * 1e6:.2f}", f"{a * 1e6:.2f}") for k, (b, a) in ex.rms_by_feature().items()],
                   ("all", f"{ex.rms_before * 1e6:.2f}", f"{ex.rms_after * 1e6:.2f}")])]


_COLOURS = ("green", "chartreuse3", "yellow", "dark_orange", "red")


def _colour(rank: int, n: int) -> str:
    return _COLOURS[round(rank * (len(_COLOURS) - 1) / (n - 1))] if n > 1 else _COLOURS[0]


def ranking_tables(r: Ranking) -> list[Table]:
    """The feature deviations [mm] per pose (coloured green, smallest |deviation| of a row, .. red,
    largest; bold in tolerance), the pose ranking (score [-]) and, with variants, each component's
    share of the score [%]."""
    from identify.workflows import Table
    from simulate.evaluation.ranking import COMPONENTS

    poses = [p.name for p in r.placements]

    def cells(row: str) -> list[str]:
        devs = [r.results[p].table[row] for p in poses]
        rank = {i: k for k, i in enumerate(sorted(range(len(devs)), key=lambda i: abs(devs[i].deviation)))}
        return [f"[{_colour(rank[i], len(devs))}{' bold' if d.in_tolerance else ''}]{d.deviation / MM:+.4f}[/]"
                for i, d in enumerate(devs)]

    tables = [Table("Feature deviations \\[mm] (ISO 10791-7, paper Table 2); green best .. red worst per row, bold: "
                    "in tolerance", ("feature", "nominal \\[mm]", "tolerance \\[mm]", *poses),
                    [(row.name, row.nominal_text(), f"{row.tolerance / MM:.3f}", *cells(row.name))
                     for row in r.results[poses[0]].table.rows]),
              Table("Pose ranking (score = sum |deviation|/tolerance, lower is better)",
                    ("rank", "pose", "score", "in tolerance"),
                    [(e.rank, f"[{_colour(e.rank - 1, len(poses))}]{e.pose}[/]", f"{e.score:.2f}",
                      f"{e.in_tolerance}/10") for e in r.entries], left=0)]
    if r.variants:
        tables.append(Table("Component share of the score (re-run with the component switched off)",
                            ("pose", *COMPONENTS), [(p, *[f"{100 * r.shares(p).get('score', {}).get(c, 0.0):.0f}%"
                                                          for c in COMPONENTS]) for p in poses]))
    return tables


def trace_table(tr: Trace, point: str, radius_mm: float) -> Table:
    """Per program line near ``point`` (as typed, mm): times [s], dexel ends, largest deflection [µm]
    and force [N], switching axes."""
    from identify.workflows import Table
    from simulate.toolpath.switching import axes_of

    return Table(f"{tr.n_ends} machined dexel ends within {radius_mm:g} mm of ({point}) mm",
                 ("line", "program", "t \\[s]", "ends", "max deflection \\[µm]", "max force \\[N]", "switching"),
                 [(ln.line, ln.text, f"{ln.t_first:.3f}..{ln.t_last:.3f}", ln.n_ends,
                   f"{ln.max_deflection / 1e-6:.1f}", f"{ln.max_force:.1f}",
                   ",".join(f"A{a}" for a in axes_of(ln.switching)) or "-") for ln in tr.lines], left=7)


def spike_table(result: CircleResult) -> Table:
    """The circle's reversal spikes: angle [deg], joint, excursion, spike and lost motion [µm]."""
    from identify.workflows import Table

    return Table("reversal spikes", ("angle \\[deg]", "joint", "excursion [µm]", "spike [µm]", "lost motion [µm]"),
                 [(f"{s.angle_deg:.1f}", s.name, f"{s.height_um:+.1f}", f"{s.spike_um:+.1f}",
                   f"{s.lost_motion_um:+.1f}") for s in result.spikes], left=0)


def trace_workpiece(workpiece: Path, point: Sequence[float], radius: float, program: Path | None = None) -> Trace:
    """The program lines and times that machined the surface within ``radius`` [m] of ``point`` [m,
    workpiece frame] (:func:`simulate.evaluation.trace.trace_point`) of a saved virtual workpiece (a
    rank-poses pose folder or the .npz); line texts from ``program`` or the one recorded with it."""
    import numpy as np

    from simulate.evaluation.trace import resolve_workpiece, trace_point
    from simulate.machining.virtual_workpiece import VirtualWorkpiece

    f, meta = resolve_workpiece(workpiece)
    prog = str(program) if program is not None else meta.get("program")
    return trace_point(VirtualWorkpiece.load(f), np.asarray(point, float), radius, program=prog)


#: rattling gears the compensation summary names (the report lists them all)
RATTLE_LINES = 8


def compensation_summary(info: dict) -> tuple[list[Table], list[str]]:
    """``greybench compensate``'s summary of a run (:func:`simulate.compensation.job.run_compensation`'s
    dict): the Table-2 rows [µm] before and after with their sums, and lines: the ratio and the rows
    worse than max(10 %, 2 µm), each stiffness check's sums [µm] and ratio, the gears the corrected
    program leaves rattling in their play, the chosen iteration, the largest offset [µm], time and peak
    speed ratios, the report's path."""
    from identify.workflows import Table

    tables, lines = [], []
    ev = info.get("evaluation")
    if ev is not None:
        tables.append(Table(f"Table-2 deviations \\[µm] before / after compensation (robot stiffness "
                            f"x{ev['stiffness_scale']:g})", ("row", "tol", "before", "after"),
                            [*[(r["name"], f"{r['tolerance'] * 1e3:.0f}", f"{r['before'] * 1e3:+.1f}",
                                f"{r['after'] * 1e3:+.1f}") for r in ev["rows_mm"]],
                             ("sum |deviation|", "", f"{ev['sum_before_mm'] * 1e3:.1f}",
                              f"{ev['sum_after_mm'] * 1e3:.1f}")]))
        lines.append(f"ratio after/before: {ev['ratio']:.3f}; rows worse than max(10 %, 2 µm): "
                     f"{', '.join(ev['rows_worse']) or 'none'}")
    lines += [f"stiffness x{c['stiffness_scale']:g}: sum {c['sum_before_mm'] * 1e3:.1f} -> "
              f"{c['sum_after_mm'] * 1e3:.1f} µm, ratio {c['ratio']:.3f}" for c in info.get("checks", []) if c]
    rattling = info.get("gears_rattling") or []
    if rattling:
        shown = rattling[:RATTLE_LINES]
        more = f"; {len(rattling) - len(shown)} more in report.md" if len(rattling) > len(shown) else ""
        lines.append("gears left rattling in their play (flank changes before -> after, per line of the program): "
                     + "; ".join(f"line {g['line']} A{g['joint']} {g['flank_changes_before'] or 0} -> "
                                 f"{g['flank_changes_after']}" for g in shown) + more)
    lines.append(f"best iteration {info['best_iteration']}; largest offset {info['max_offset_mm'] * 1e3:.1f} µm; "
                 f"time ratio {info['time_ratio']:.3f}; peak speed ratio {info['speed_ratio']:.3f}")
    lines += [f"report: {f}" for f in info.get("files", []) if f.endswith("report.md")]
    return tables, lines
