"""``greybench machine`` and ``greybench bench machining`` (paper 3.3-3.7, Figure 4)."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from greybench.support import DATA_DIR, emit_json, guarded, out, progress, resolve_robot
from identify.errors import InputError


def _prepare(program: Path, robot: str, pose: Path, name, spacing_mm: float, stock: Optional[Path]):
    from simulate.machining.dexel import TriDexel
    from simulate.robot.model import load_robot
    from simulate.toolpath.gcode import read_program
    from simulate.toolpath.interpolation import interpolate
    from simulate.toolpath.placement import joint_trajectory, load_poses, select_pose

    if not (spacing_mm > 0):
        raise InputError(f"dexel spacing must be > 0 mm, got {spacing_mm}", field="spacing")
    prog = read_program(program)
    stock = stock or program.with_suffix(".stock.json")
    if not stock.exists():
        raise InputError("stock description not found (give --stock)", source=str(stock))
    placement = select_pose(load_poses(pose), name, source=str(pose))
    rob = load_robot(resolve_robot(robot))
    ip = interpolate(prog)
    jt = joint_trajectory(rob, ip, placement, source=str(program))
    wp = TriDexel.from_stock_file(stock, spacing_mm * 1e-3)
    doc = json.loads(stock.read_text())
    return prog, placement, rob, jt, wp, doc


def _cutter_from_stock(doc):
    from simulate.machining.tools import make_cutter

    tool = doc.get("tool", {}) if isinstance(doc, dict) else {}
    return make_cutter(tool.get("type", "flat"), float(tool.get("diameter", 0.01)), flutes=int(tool.get("flutes", 4)),
                       helix_deg=float(tool.get("helix_deg", 30.0)), length=float(tool.get("length", 0.03)))


def tracking_error(rob, jt, placement, friction: bool):
    """Servo tracking error along the joint trajectory, in the workpiece frame (N, 3) [m].

    The axis servo (:func:`simulate.robot.servo.simulate_servo`) runs with or without joint
    friction; without friction the error is still not zero (the position loop lags unless its
    feed-forward is ideal). The process force is not fed into the servo as ``tau_ext = -J^T F``:
    the force is only known inside the coupled loop, and the servo's velocity integrator rejects
    such slowly varying loads, so their tracking error is small against the deflection ``C F``
    (a second pass with ``tau_ext`` would double the run time for a second-order effect).
    """
    from simulate.robot.servo import simulate_servo

    sr = simulate_servo(rob, jt.t, jt.q, friction=friction)
    return sr.tcp_error(rob) @ placement.T[:3, :3]  # base -> workpiece: R^T e, row-wise


def run(program, robot, pose, name, out_dir, ideal, spacing, no_deflection, no_friction, no_switching, material,
        stock, spindle_rpm, show_progress=True, stiffness_scale=1.0, no_tracking=False):
    """Prepare and run the coupled loop; returns ``(workpiece, MachiningResult)``.

    ``ideal`` switches off deflection, tracking error and switching bits; ``no_friction`` runs the
    servo without joint friction (its tracking error stays); ``no_tracking`` drops the tracking
    error altogether. ``stiffness_scale`` multiplies the robot's joint stiffness.
    """
    from simulate.machining.cutting import Spindle, load_material
    from simulate.machining.simulation import simulate_machining, workpiece_compliance

    prog, placement, rob, jt, wp, doc = _prepare(program, robot, pose, name, spacing, stock)
    mat = load_material(material)
    cutter = _cutter_from_stock(doc)
    # segments carry the S word in rev/s (simulate.toolpath.gcode); 12000 rev/min if never set
    rpm = spindle_rpm or 60.0 * max((getattr(s, "spindle", 0.0) for s in prog.segments), default=0.0) or 12000.0
    spindle = Spindle.from_rpm(rpm)
    Rm = placement.T[:3, :3]
    t_robot0 = time.perf_counter()
    C = None if (ideal or no_deflection) else workpiece_compliance(rob, jt.q, Rm, stiffness_scale)
    err = None if (ideal or no_tracking) else tracking_error(rob, jt, placement, friction=not no_friction)
    t_robot_pre = time.perf_counter() - t_robot0
    switch = None if (ideal or no_switching) else jt.switch
    with progress("machining", total=len(jt.t), enabled=show_progress) as adv:
        res = simulate_machining(wp, cutter, jt.t, jt.line, jt.xyz, mat, spindle, compliance=C,
                                 tracking_error=err, switch=switch, advance=adv)
    res.timings["robot (compliance + servo, up-front)"] = t_robot_pre
    return wp, res


def write_outputs(wp, res, out_dir: Path, variable: str = "deflection") -> list[Path]:
    """Write ``virtual_workpiece.npz``, ``surface_<variable>.ply/.glb``, ``render_<variable>.png`` (top
    view of the machined surface points) and ``render3d_<variable>.png`` (oblique view of the mesh)
    into ``out_dir``: all are written into a temporary folder next to it first and moved in only
    when every one succeeded, so a failure leaves nothing half-written."""
    import shutil
    import tempfile

    from simulate.machining.virtual_workpiece import VirtualWorkpiece, export_meshes, render_mesh_png, render_png

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir, prefix=".machine-"))
    try:
        vw = VirtualWorkpiece(wp, res.steps)
        vw.save(tmp / "virtual_workpiece.npz")
        export_meshes(vw, tmp, variable)
        render_png(vw, tmp / f"render_{variable}.png", variable)
        render_mesh_png(vw, tmp / f"render3d_{variable}.png", variable)
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
    name: Optional[str] = typer.Option(None, "--name", help="Pose name in the file (default: the first)."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder for the virtual workpiece (npz), PLY/GLB, PNG."),
    ideal: bool = typer.Option(False, "--ideal", help="No deflection, no tracking error, no switching bits."),
    spacing: float = typer.Option(0.25, "--spacing", help="Dexel spacing [mm]."),
    no_deflection: bool = typer.Option(False, "--no-deflection", help="Switch off the robot deflection."),
    no_friction: bool = typer.Option(False, "--no-friction",
                                     help="Servo without joint friction (its tracking error stays) [-]."),
    no_tracking: bool = typer.Option(False, "--no-tracking", help="Switch off the servo tracking error [-]."),
    no_switching: bool = typer.Option(False, "--no-switching", help="Do not record the switching bits."),
    material: str = typer.Option("Al7075", "--material", help="Material in data/materials.toml (coefficients N/mm^2, N/mm)."),
    stock: Optional[Path] = typer.Option(None, "--stock", help="Stock description JSON [m or mm] (default: <program>.stock.json)."),
    spindle_rpm: Optional[float] = typer.Option(None, "--spindle", help="Spindle speed [rev/min] (default: program S word)."),
    variable: str = typer.Option("deflection", "--color", help="Variable for the colour map (deflection [m], force [N], ...)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (SI units)."),
) -> None:
    """Simulate machining with robot deflection and tracking error in the loop (paper Figure 4)."""
    from simulate.machining.virtual_workpiece import VARIABLES

    if variable not in VARIABLES:
        raise InputError(f"unknown variable '{variable}' (one of {', '.join(VARIABLES)})", field="color")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("output path exists and is not a folder", source=str(out_dir), field="out")
    wp, res = run(program, robot, pose, name, out_dir, ideal, spacing, no_deflection, no_friction, no_switching,
                  material, stock, spindle_rpm, show_progress=not as_json, no_tracking=no_tracking)
    write_outputs(wp, res, out_dir, variable)
    info = summary(res)
    if as_json:
        emit_json(info)
        return
    table = Table(title=f"machining {program.name}")
    table.add_column("item")
    table.add_column("value", justify="right")
    units = {"simulated_time": "s", "wall_time": "s", "removed_volume": "m^3", "peak_force": "N",
             "peak_deflection": "m"}
    for k, v in info.items():
        table.add_row(f"{k} ({units[k]})" if k in units else k, f"{v:.6g}" if isinstance(v, float) else str(v))
    out.print(table)


def bench_machining(
    spacing: float = typer.Option(0.25, "--spacing", help="Dexel spacing [mm]."),
    max_steps: int = typer.Option(0, "--max-steps", help="Limit the number of 2 ms steps (0: whole program) [-]."),
    threads: int = typer.Option(1, "--threads", help="numba threads for the loop [-] (1: the one-core figure)."),
    reference_steps: int = typer.Option(3000, "--reference-steps",
                                        help="Steps for the per-step-call reference (0: skip) [-]."),
) -> None:
    """Steps/s of the coupled loop on the 320 test-piece finishing program, one pose.

    Wall and CPU time of the loop (on a machine shared with other jobs the CPU figure is the
    speed the code has), where the time goes (removal / engagement / forces / robot), memory, and
    the ratio against calling the same removal and force kernels once per step from Python.
    """
    import resource

    import numba
    from rich.markup import escape

    from simulate.machining.cutting import Spindle, load_material, step_forces, substeps
    from simulate.machining.removal import RemovalBuffers, remove_horizontal, remove_vertical
    from simulate.machining.simulation import simulate_machining, workpiece_compliance

    if threads < 1:
        raise InputError(f"threads must be >= 1, got {threads}", field="threads")
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    program = DATA_DIR / "programs" / "iso320.nc"
    pose = DATA_DIR / "poses" / "iso320.json"
    t0 = time.perf_counter()
    prog, placement, rob, jt, wp, doc = _prepare(program, "max100", pose, None, spacing, None)
    t_prep = time.perf_counter() - t0
    n = len(jt.t) if max_steps <= 0 else min(max_steps, len(jt.t))
    cutter = _cutter_from_stock(doc)
    mat, spindle = load_material("Al7075"), Spindle.from_rpm(12000)
    t1, c1 = time.perf_counter(), time.process_time()
    Rm = placement.T[:3, :3]
    C = workpiece_compliance(rob, jt.q[:n], Rm)
    from simulate.robot.servo import simulate_servo
    err = simulate_servo(rob, jt.t[:n], jt.q[:n], friction=True).tcp_error(rob) @ Rm
    t_robot, c_robot = time.perf_counter() - t1, time.process_time() - c1
    # warm-up (compile or load the cache) on a small piece
    small = wp.__class__.box([0, 0, 0], [0.02, 0.02, 0.01], spacing * 1e-3)
    pts = np.linspace([-0.01, 0.01, 0.008], [0.03, 0.01, 0.008], 50)
    simulate_machining(small, cutter, np.arange(50) * 0.002, np.zeros(50, int), pts, mat, spindle,
                       compliance=np.zeros((50, 3, 3)))
    ref = None
    if reference_steps > 0:
        # the per-step design (the same removal + force kernels called once per step from Python,
        # each step a numba parallel region) against the compiled loop, both uncoupled, on a cutting window (the square contour): the workpiece
        # is first brought to the window's start by the loop
        start = min(5000, max(1, n - reference_steps - 1))
        m = min(reference_steps, n - start)
        w0_ = wp.copy()
        simulate_machining(w0_, cutter, jt.t[:start + 1], jt.line[:start + 1], jt.xyz[:start + 1], mat, spindle)
        wref = w0_.copy()
        buf = RemovalBuffers(wref, cutter.radius, 0.01)
        nsub = substeps(0.002, spindle.omega, cutter.flutes, per_tooth=4)
        fx, fy, fz = wref.families
        nx, ny, nz = wref.shape
        out4 = np.zeros(4)
        w0, c0 = time.perf_counter(), time.process_time()
        for k in range(start + 1, start + m):
            p0, p1 = jt.xyz[k - 1], jt.xyz[k]
            _, _, ztop = remove_vertical(fz.lo, fz.hi, fz.lo_step, fz.hi_step, fz.count, wref.lower, wref.spacing,
                                         nx, ny, p0, p1, cutter.radius, cutter.corner_radius, cutter.length, k)
            k0, nl, _ = remove_horizontal(fx.lo, fx.hi, fx.lo_step, fx.hi_step, fx.count, fy.lo, fy.hi, fy.lo_step,
                                          fy.hi_step, fy.count, wref.lower, wref.spacing, nx, ny, nz, p0, p1,
                                          cutter.radius, cutter.corner_radius, cutter.length, k, True, buf.samp_ang,
                                          buf.samp_eng, buf.samp_cnt, buf.layer_removed, ztop)
            step_forces(buf.samp_ang, buf.samp_eng, buf.samp_cnt, k0, nl, wref.lower[2], wref.spacing, p0, p1, 0.002,
                        jt.t[k], cutter.radius, cutter.corner_radius, cutter.length, cutter.flutes,
                        float(np.tan(cutter.helix)), spindle.omega, spindle.phase, mat.kc, mat.ke, nsub, out4)
        ref = (start, m - 1, time.perf_counter() - w0, time.process_time() - c0)
        del wref
        w0, c0 = time.perf_counter(), time.process_time()
        simulate_machining(w0_, cutter, jt.t[start:start + m], jt.line[start:start + m], jt.xyz[start:start + m],
                           mat, spindle)
        ref_loop = (time.perf_counter() - w0, time.process_time() - c0)
        del w0_
    res = simulate_machining(wp, cutter, jt.t[:n], jt.line[:n], jt.xyz[:n], mat, spindle, compliance=C,
                             tracking_error=err, switch=jt.switch[:n])
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    t_mesh0 = time.perf_counter()
    from simulate.machining.surface_mesh import surface_mesh
    sm = surface_mesh(wp)
    t_mesh = time.perf_counter() - t_mesh0
    rss = max(rss, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
    wall, cpu = res.wall_time, res.cpu_time
    table = Table(title=f"machining bench: iso320 finishing, pose {placement.name}, spacing {spacing} mm, "
                        f"{numba.get_num_threads()} numba thread(s), one run")
    table.add_column("figure")  # labels go through escape(): "[s]" would be read as markup
    table.add_column("per wall s", justify="right")
    table.add_column("per CPU s", justify="right")
    table.add_column("target / note", justify="right")
    table.add_row(escape("steps"), f"{n}", "", "")
    table.add_row(escape("loop time [s]"), f"{wall:.2f}", f"{cpu:.2f}", "CPU: this process, all threads")
    table.add_row(escape("steps/s"), f"{n / wall:,.0f}", f"{n / cpu:,.0f}", f">= 5000 ({n / cpu / 5000:.2f}x on CPU)")
    table.add_row(escape("simulated / loop time"), f"{res.simulated_time / wall:.1f}", f"{res.simulated_time / cpu:.1f}",
                  ">= 10")
    parts = {k: v for k, v in res.timings.items() if k in ("removal", "engagement", "forces", "robot")}
    for k, v in parts.items():
        table.add_row(escape(f"  {k} [s]"), f"{v:.2f}", "", f"{v / wall * 100:.0f} % of the loop")
    table.add_row(escape("    of removal: z-rays [s]"), f"{res.timings.get('removal, z-rays', 0.0):.2f}", "", "")
    table.add_row(escape("  loop overhead [s]"), f"{wall - sum(parts.values()):.2f}", "", "")
    if ref is not None:
        start, m, rw, rc_ = ref
        table.add_row(escape(f"per-step kernel calls, steps {start}-{start + m} [steps/s]"), f"{m / rw:,.0f}",
                      f"{m / rc_:,.0f}", "same kernels, one call per step, no coupling")
        table.add_row(escape(f"one compiled loop, same steps [steps/s]"), f"{m / ref_loop[0]:,.0f}",
                      f"{m / ref_loop[1]:,.0f}", f"{(m / ref_loop[1]) / (m / rc_):.1f}x per CPU s")
    table.add_row(escape("robot compliance + servo, up-front [s]"), f"{t_robot:.2f}", f"{c_robot:.2f}", "")
    table.add_row(escape("setup (program, IK, stock) [s]"), f"{t_prep:.2f}", "", "")
    table.add_row(escape(f"surface mesh (stride {sm.stride}, {len(sm.faces):,} triangles) [s]"), f"{t_mesh:.2f}", "", "")
    table.add_row(escape("dexel memory [MB]"), f"{wp.nbytes / 1e6:.0f}", "", "")
    table.add_row(escape("peak RSS [MB]"), f"{rss / 1e6:.0f}", "", "< 4096")
    table.add_row(escape("removed volume [mm^3]"), f"{res.removed_volume * 1e9:.0f}", "", "")
    table.add_row(escape("peak force [N] / peak deflection [um]"), f"{res.steps.peak_force.max():.1f}",
                  f"{np.linalg.norm(res.steps.deflection, axis=1).max() * 1e6:.1f}", "")
    out.print(table)


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    app.command("machine")(guarded(machine))
    bench_app.command("machining")(guarded(bench_machining))
