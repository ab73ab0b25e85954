"""``greybench machine`` (paper 3.3-3.7, Figure 4)."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import typer

from greybench.support import check_cost, emit_json, guarded, print_summary, progress, resolve_robot
from identify.errors import InputError
from simulate import defaults as DEFAULTS


def cutter_from_robot(rob):
    """The cutter the robot carries: its file's ``[tool]`` table, via
    :func:`simulate.evaluation.cutter.robot_cutter` (the one source for ``machine``, ``rank-poses`` and
    ``explain``). Bad values raise ``InputError`` naming the robot file and the ``tool.*`` key.
    """
    from simulate.evaluation.cutter import robot_cutter

    try:
        return robot_cutter(rob)
    except InputError as exc:
        key = {"kind": "type"}.get(exc.field, exc.field) or "type"
        raise InputError(exc.message, source=rob.source or None, field=f"tool.{key}") from None


def machining_job(program: Path, robot: str, pose: Path, name, *, ideal=False, spacing_mm=None,
                  no_deflection=False, no_friction=False, no_switching=False, no_tracking=False, material=None,
                  stock: Path | None = None, spindle_rpm=None, stiffness_scale=1.0, size=None,
                  probe_spacing_mm=None):
    """The :class:`simulate.pipeline.MachiningJob` of ``greybench machine``'s options (mm -> m).

    ``ideal`` switches off deflection, tracking error and backlash; ``no_friction`` runs the servo
    without joint friction (its tracking error stays); ``no_tracking`` drops the tracking error
    altogether; ``no_switching`` drops the gear backlash (the switching-point effect) and its bits.
    Defaults: :mod:`simulate.defaults`.
    """
    from simulate import defaults
    from simulate.pipeline import Components, MachiningJob, MachiningSettings
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import load_poses, select_pose

    spacing_mm = defaults.DEXEL_SPACING * 1e3 if spacing_mm is None else spacing_mm
    probe_spacing_mm = defaults.PROBE_SPACING * 1e3 if probe_spacing_mm is None else probe_spacing_mm
    if not (spacing_mm > 0 and np.isfinite(spacing_mm)):
        raise InputError(f"dexel spacing must be > 0 mm, got {spacing_mm}", field="spacing")
    if not (probe_spacing_mm > 0 and np.isfinite(probe_spacing_mm)):
        raise InputError(f"probe spacing must be > 0 mm, got {probe_spacing_mm}", field="probe-spacing")
    placement = select_pose(load_poses(pose), name, source=str(pose))
    rob = load_robot(resolve_robot(robot))
    cutter_from_robot(rob)  # tool errors name the robot file's key
    comp = Components(deflection=not (ideal or no_deflection), friction=not no_friction,
                      switching=not (ideal or no_switching), servo=not (ideal or no_tracking))
    settings = MachiningSettings(spacing=spacing_mm * 1e-3, probe_spacing=probe_spacing_mm * 1e-3,
                                 material=material or defaults.MATERIAL, spindle_rpm=spindle_rpm,
                                 stiffness_scale=stiffness_scale, size=size)
    return MachiningJob(program=program, robot=rob, placement=placement, components=comp, settings=settings,
                        stock=stock)


#: Files :func:`write_outputs` writes besides the optional scan (its progress total).
OUTPUT_STAGES = ("virtual workpiece (npz)", "surface meshes (PLY, GLB, legend)", "top view (PNG)",
                 "oblique view (PNG)")


def write_outputs(wp, res, out_dir: Path, variable: str = "deflection", scan=None, advance=None) -> list[Path]:
    """Write ``virtual_workpiece.npz``, ``surface_<variable>.ply/.glb``, ``render_<variable>.png`` (top
    view of the machined surface points), ``render3d_<variable>.png`` (oblique view of the mesh) and,
    when ``scan`` is given, the virtual CMM's ``scan.csv`` (:func:`simulate.evaluation.cmm.write_scan`)
    into ``out_dir``: all are written into a temporary folder next to it first and moved in only
    when every one succeeded, so a failure leaves nothing half-written. ``advance`` (a
    :func:`greybench.support.progress` handle) counts the files of :data:`OUTPUT_STAGES` (+ scan).

    The npz is compressed in a second thread while the meshes and pictures are made (zlib releases
    the GIL), so on two cores its time is hidden."""
    import shutil
    import tempfile
    from concurrent.futures import ThreadPoolExecutor

    from greybench.support import Advance
    from simulate.machining.virtual_workpiece import VirtualWorkpiece, export_meshes, render_mesh_png, render_png

    adv = advance if advance is not None else Advance()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir, prefix=".machine-"))
    try:
        vw = VirtualWorkpiece(wp, res.steps)
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
            if scan is not None:
                from simulate.evaluation.cmm import write_scan

                adv.describe("scan.csv")
                write_scan(scan, tmp / "scan.csv")
                adv(1)
            adv.describe(OUTPUT_STAGES[0])
            saved.result()
            adv(1)
        paths = []
        for f in sorted(tmp.iterdir()):
            dest = out_dir / f.name
            os.replace(f, dest)
            paths.append(dest)
        return paths
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def summary(res) -> dict:
    """The ``--json`` object (SI): steps, simulated_time [s], wall_time [s], removed_volume [m^3],
    peak_force [N], peak_deflection [m]."""
    return {"steps": int(len(res.steps.t)), "simulated_time": float(res.simulated_time),
            "wall_time": float(res.wall_time), "removed_volume": float(res.removed_volume),
            "peak_force": float(res.steps.peak_force.max()) if len(res.steps.t) else 0.0,
            "peak_deflection": float(np.linalg.norm(res.steps.deflection, axis=1).max()) if len(res.steps.t) else 0.0}


def machine(
    program: Path = typer.Option(..., "--program", help="G-code program (mm or inch as programmed)."),
    robot: str = typer.Option("max100", "--robot", help="Robot name in data/robots or a robot TOML path."),
    pose: Path = typer.Option(..., "--pose", help="Pose file (JSON) [m, rad]."),
    name: str | None = typer.Option(None, "--name", help="Pose name in the file (default: the first)."),
    out_dir: Path = typer.Option(..., "--out",
                                 help="Output folder for the virtual workpiece (npz, m), PLY/GLB, PNG, scan.csv (m)."),
    ideal: bool = typer.Option(False, "--ideal", help="No deflection, no tracking error, no backlash."),
    spacing: float = typer.Option(DEFAULTS.DEXEL_SPACING * 1e3, "--spacing", help="Dexel spacing [mm]."),
    no_deflection: bool = typer.Option(False, "--no-deflection", help="Switch off the robot deflection."),
    no_friction: bool = typer.Option(False, "--no-friction",
                                     help="Servo without joint friction (its tracking error stays) [-]."),
    no_tracking: bool = typer.Option(False, "--no-tracking", help="Switch off the servo tracking error [-]."),
    no_switching: bool = typer.Option(False, "--no-switching",
                                      help="No gear backlash (the switching-point effect), no switching bits."),
    material: str = typer.Option(DEFAULTS.MATERIAL, "--material",
                                 help="Material in data/materials.toml (coefficients N/mm^2, N/mm)."),
    stock: Path | None = typer.Option(None, "--stock",
                                      help="Stock description JSON [m or mm] (default: <program>.stock.json)."),
    spindle_rpm: float | None = typer.Option(None, "--spindle",
                                             help="Spindle speed [rev/min] (default: program S word)."),
    variable: str = typer.Option("deflection", "--color",
                                 help="Variable for the colour map (deflection [m], force [N], ...)."),
    size: int | None = typer.Option(None, "--size",
                                       help="Test-piece size [mm] (160 or 320) for the virtual CMM's scan.csv "
                                            "(default: the stock JSON's size_mm; neither: no scan)."),
    probe_spacing: float = typer.Option(DEFAULTS.PROBE_SPACING * 1e3, "--probe-spacing",
                                        help="Virtual CMM probe point distance [mm]."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (SI units)."),
) -> None:
    """Simulate machining with robot deflection and tracking error in the loop (paper Figure 4).

    The cutter is the robot file's [tool] (the robot carries spindle and tool). When the stock is an
    ISO 10791-7 test piece (its JSON names size_mm, or --size), the virtual CMM probes the result
    and OUT gets scan.csv (feature,x,y,z; workpiece frame, m).
    """
    from simulate.machining.virtual_workpiece import VARIABLES

    if variable not in VARIABLES:
        raise InputError(f"unknown variable '{variable}' (one of {', '.join(VARIABLES)})", field="color")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("output path exists and is not a folder", source=str(out_dir), field="out")
    from simulate.pipeline import prepare, run_job

    check_cost(program, stock, spacing)
    job = machining_job(program, robot, pose, name, ideal=ideal, spacing_mm=spacing, no_deflection=no_deflection,
                        no_friction=no_friction, no_switching=no_switching, no_tracking=no_tracking,
                        material=material, stock=stock, spindle_rpm=spindle_rpm, size=size,
                        probe_spacing_mm=probe_spacing)
    pj = prepare(job)
    # progress on stderr also with --json (stdout carries only the JSON object)
    with progress("machining", total=pj.steps) as adv:
        mo = run_job(job, prepared=pj, advance=adv)
    res = mo.result
    with progress("writing outputs", total=len(OUTPUT_STAGES) + (mo.scan is not None)) as adv:
        write_outputs(mo.workpiece, res, out_dir, variable, scan=mo.scan, advance=adv)
    info = summary(res)
    if as_json:
        emit_json(info)
        return
    units = {"simulated_time": "s", "wall_time": "s", "removed_volume": "m^3", "peak_force": "N",
             "peak_deflection": "m"}
    print_summary(f"machining {program.name}", {f"{k} ({units[k]})" if k in units else k: v for k, v in info.items()})


def register(app: typer.Typer) -> None:
    app.command("machine")(guarded(machine))
