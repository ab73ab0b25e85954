"""``greybench machine`` and ``greybench bench machining`` (paper 3.3-3.7, Figure 4)."""
from __future__ import annotations

import json
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


def run(program, robot, pose, name, out_dir, ideal, spacing, no_deflection, no_friction, no_switching, material,
        stock, spindle_rpm, show_progress=True, stiffness_scale=1.0):
    from simulate.machining.cutting import Spindle, load_material
    from simulate.machining.simulation import simulate_machining, workpiece_compliance
    from simulate.robot.servo import simulate_servo

    prog, placement, rob, jt, wp, doc = _prepare(program, robot, pose, name, spacing, stock)
    mat = load_material(material)
    cutter = _cutter_from_stock(doc)
    rpm = spindle_rpm or max((getattr(s, "spindle", 0.0) for s in prog.segments), default=0.0) or 12000.0
    spindle = Spindle.from_rpm(rpm)
    Rm = placement.T[:3, :3]
    t_robot0 = time.perf_counter()
    C = None if (ideal or no_deflection) else workpiece_compliance(rob, jt.q, Rm, stiffness_scale)
    err = None
    if not (ideal or no_friction):
        sr = simulate_servo(rob, jt.t, jt.q, friction=True)
        err = sr.tcp_error(rob) @ Rm  # base -> workpiece: R^T e, row-wise
    t_robot_pre = time.perf_counter() - t_robot0
    switch = None if (ideal or no_switching) else jt.switch
    with progress("machining", total=len(jt.t), enabled=show_progress) as adv:
        res = simulate_machining(wp, cutter, jt.t, jt.line, jt.xyz, mat, spindle, compliance=C,
                                 tracking_error=err, switch=switch, advance=adv)
    res.timings["robot (compliance + servo, up-front)"] = t_robot_pre
    return wp, res


def machine(
    program: Path = typer.Option(..., "--program", help="G-code program (mm or inch as programmed)."),
    robot: str = typer.Option("max100", "--robot", help="Robot name in data/robots or a robot TOML path."),
    pose: Path = typer.Option(..., "--pose", help="Pose file (JSON) [m, rad]."),
    name: Optional[str] = typer.Option(None, "--name", help="Pose name in the file (default: the first)."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder for the virtual workpiece (npz), PLY/GLB, PNG."),
    ideal: bool = typer.Option(False, "--ideal", help="No deflection, no friction tracking error, no switching bits."),
    spacing: float = typer.Option(0.25, "--spacing", help="Dexel spacing [mm]."),
    no_deflection: bool = typer.Option(False, "--no-deflection", help="Switch off the robot deflection."),
    no_friction: bool = typer.Option(False, "--no-friction", help="Switch off the servo/friction tracking error."),
    no_switching: bool = typer.Option(False, "--no-switching", help="Do not record the switching bits."),
    material: str = typer.Option("Al7075", "--material", help="Material in data/materials.toml (coefficients N/mm^2, N/mm)."),
    stock: Optional[Path] = typer.Option(None, "--stock", help="Stock description JSON [m or mm] (default: <program>.stock.json)."),
    spindle_rpm: Optional[float] = typer.Option(None, "--spindle", help="Spindle speed [rev/min] (default: program S word)."),
    variable: str = typer.Option("deflection", "--color", help="Variable for the colour map (deflection, force, ...)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (SI units)."),
) -> None:
    """Simulate machining with robot deflection and tracking error in the loop (paper Figure 4)."""
    from simulate.machining.virtual_workpiece import VARIABLES, VirtualWorkpiece, export_meshes, render_png

    if variable not in VARIABLES:
        raise InputError(f"unknown variable '{variable}' (one of {', '.join(VARIABLES)})", field="color")
    wp, res = run(program, robot, pose, name, out_dir, ideal, spacing, no_deflection, no_friction, no_switching,
                  material, stock, spindle_rpm, show_progress=not as_json)
    out_dir.mkdir(parents=True, exist_ok=True)
    vw = VirtualWorkpiece(wp, res.steps)
    vw.save(out_dir / "virtual_workpiece.npz")
    export_meshes(vw, out_dir, variable)
    render_png(vw, out_dir / f"render_{variable}.png", variable)
    summary = {"steps": int(len(res.steps.t)), "simulated_time": res.simulated_time, "wall_time": res.wall_time,
               "removed_volume": res.removed_volume, "peak_force": float(res.steps.peak_force.max()),
               "peak_deflection": float(np.linalg.norm(res.steps.deflection, axis=1).max())}
    if as_json:
        emit_json(summary)
        return
    table = Table(title=f"machining {program.name}")
    table.add_column("item")
    table.add_column("value", justify="right")
    for k, v in summary.items():
        table.add_row(k, f"{v:.6g}" if isinstance(v, float) else str(v))
    out.print(table)


def bench_machining(
    spacing: float = typer.Option(0.25, "--spacing", help="Dexel spacing [mm]."),
    max_steps: int = typer.Option(0, "--max-steps", help="Limit the number of 2 ms steps (0: whole program)."),
) -> None:
    """Steps/s of the coupled loop on the 320 test-piece finishing program, one pose."""
    import resource

    from simulate.machining.cutting import Spindle, load_material
    from simulate.machining.simulation import simulate_machining, workpiece_compliance
    from simulate.robot.servo import simulate_servo

    program = DATA_DIR / "programs" / "iso320.nc"
    pose = DATA_DIR / "poses" / "iso320.json"
    t0 = time.perf_counter()
    prog, placement, rob, jt, wp, doc = _prepare(program, "max100", pose, None, spacing, None)
    t_prep = time.perf_counter() - t0
    n = len(jt.t) if max_steps <= 0 else min(max_steps, len(jt.t))
    cutter = _cutter_from_stock(doc)
    t1 = time.perf_counter()
    Rm = placement.T[:3, :3]
    C = workpiece_compliance(rob, jt.q[:n], Rm)
    err = simulate_servo(rob, jt.t[:n], jt.q[:n], friction=True).tcp_error(rob) @ Rm
    t_robot = time.perf_counter() - t1
    # warm-up compile on a copy of a small piece
    small = wp.__class__.box([0, 0, 0], [0.02, 0.02, 0.01], spacing * 1e-3)
    pts = np.linspace([-0.01, 0.01, 0.008], [0.03, 0.01, 0.008], 50)
    simulate_machining(small, cutter, np.arange(50) * 0.002, np.zeros(50, int), pts, load_material("Al7075"),
                       Spindle.from_rpm(12000), compliance=np.zeros((50, 3, 3)))
    res = simulate_machining(wp, cutter, jt.t[:n], jt.line[:n], jt.xyz[:n], load_material("Al7075"),
                             Spindle.from_rpm(12000), compliance=C, tracking_error=err, switch=jt.switch[:n])
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    table = Table(title=f"machining bench: iso320 finishing, pose {placement.name}, spacing {spacing} mm")
    table.add_column("figure")
    table.add_column("value", justify="right")
    table.add_row("steps", f"{n}")
    table.add_row("simulated time [s]", f"{res.simulated_time:.2f}")
    table.add_row("wall time, loop [s]", f"{res.wall_time:.2f}")
    table.add_row("steps/s (target >= 5000)", f"{n / res.wall_time:,.0f}")
    table.add_row("simulated / wall (target >= 10)", f"{res.simulated_time / res.wall_time:.1f}")
    for k, v in res.timings.items():
        table.add_row(f"  {k} [s]", f"{v:.2f} ({v / res.wall_time * 100:.0f} %)")
    table.add_row("  python loop overhead [s]", f"{res.wall_time - sum(res.timings.values()):.2f}")
    table.add_row("robot compliance + servo up-front [s]", f"{t_robot:.2f}")
    table.add_row("setup (program, IK, stock) [s]", f"{t_prep:.2f}")
    table.add_row("dexel memory [MB]", f"{wp.nbytes / 1e6:.0f}")
    table.add_row("peak RSS [MB] (target < 4096)", f"{rss / 1e6:.0f}")
    table.add_row("removed volume [mm^3]", f"{res.removed_volume * 1e9:.0f}")
    out.print(table)


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    app.command("machine")(guarded(machine))
    bench_app.command("machining")(guarded(bench_machining))
