"""``greybench machine`` and ``greybench bench machining`` (paper 3.3-3.7, Figure 4)."""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from greybench.support import DATA_DIR, check_cost, emit_json, guarded, out, progress, print_summary, resolve_robot
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
                  stock: Optional[Path] = None, spindle_rpm=None, stiffness_scale=1.0, size=None,
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
    name: Optional[str] = typer.Option(None, "--name", help="Pose name in the file (default: the first)."),
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
    material: str = typer.Option(DEFAULTS.MATERIAL, "--material", help="Material in data/materials.toml (coefficients N/mm^2, N/mm)."),
    stock: Optional[Path] = typer.Option(None, "--stock", help="Stock description JSON [m or mm] (default: <program>.stock.json)."),
    spindle_rpm: Optional[float] = typer.Option(None, "--spindle", help="Spindle speed [rev/min] (default: program S word)."),
    variable: str = typer.Option("deflection", "--color", help="Variable for the colour map (deflection [m], force [N], ...)."),
    size: Optional[int] = typer.Option(None, "--size",
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


def bench_machining(
    spacing: float = typer.Option(0.25, "--spacing", help="Dexel spacing [mm]."),
    max_steps: int = typer.Option(0, "--max-steps", help="Limit the number of 2 ms steps (0: whole program) [-]."),
    threads: int = typer.Option(1, "--threads", help="numba threads for the loop [-] (1: the one-core figure)."),
    reference_steps: int = typer.Option(3000, "--reference-steps",
                                        help="Steps for the per-step-call reference (0: skip) [-]."),
    greybox: Optional[Path] = typer.Option(None, "--greybox",
                                           help="Saved grey-box model folder for joints 1-3 (default: fit one with "
                                                "5 epochs on a seeded synthetic 4 s record)."),
) -> None:
    """Steps/s of the coupled loop (two-mass drives with friction inside) on the 320 test-piece program, one pose.

    Coupled steps per CPU second on one thread with the robot file's conventional LuGre friction and
    with a grey-box LuGre model on joints 1-3 beside it, and the drives' share of the loop time.

    Wall and CPU time of the loop (on a machine shared with other jobs the CPU figure is the
    speed the code has), memory, and the ratio against calling the same removal and force kernels
    once per step from Python. Where the time goes (removal / engagement / forces / robot) comes
    from a second run of the same program on a fresh workpiece with the clock-reading copy of the
    loop (:func:`simulate.machining.simulation.profiling_kernel`; the production loop reads no
    clock so that numba can cache it); its compile time and its slowdown against the production
    loop are printed too.
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
    from simulate.pipeline import prepare, stock_workpiece

    job = machining_job(program, "max100", pose, None, spacing_mm=spacing)
    pj = prepare(job)
    placement, rob, jt, cutter = job.placement, pj.robot, pj.trajectory, cutter_from_robot(pj.robot)
    wp = stock_workpiece(pj.program, job.settings)
    t_prep = time.perf_counter() - t0
    n = len(jt.t) if max_steps <= 0 else min(max_steps, len(jt.t))
    mat, spindle = load_material("Al7075"), Spindle.from_rpm(12000)
    t1, c1 = time.perf_counter(), time.process_time()
    Rm = placement.T[:3, :3]
    C = workpiece_compliance(rob, jt.q[:n], Rm)
    from simulate.machining.simulation import loop_drive
    from simulate.robot.friction import loop_friction

    fp_lugre, _ = loop_friction(rob)   # max100: inline (conventional) LuGre on every joint

    def servo_of(fp):   # the two-mass drives (fresh state) stepped inside the loop
        return loop_drive(rob, jt.q[:n], jt.t[:n], Rm, fp)

    t_robot, c_robot = time.perf_counter() - t1, time.process_time() - c1
    fp_grey, grey_note = _bench_greybox(rob, greybox)
    # warm-up (compile or load the cache) on a small piece
    small = wp.__class__.box([0, 0, 0], [0.02, 0.02, 0.01], spacing * 1e-3)
    pts = np.linspace([-0.01, 0.01, 0.008], [0.03, 0.01, 0.008], 50)
    simulate_machining(small, cutter, np.arange(50) * 0.002, np.zeros(50, int), pts, mat, spindle,
                       compliance=np.zeros((50, 3, 3)))
    t_comp = time.perf_counter()
    simulate_machining(small.__class__.box([0, 0, 0], [0.02, 0.02, 0.01], spacing * 1e-3), cutter,
                       np.arange(50) * 0.002, np.zeros(50, int), pts, mat, spindle,
                       compliance=np.zeros((50, 3, 3)), profile=True)
    t_comp = time.perf_counter() - t_comp
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
                             switch=jt.switch[:n], drive=servo_of(fp_lugre))
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    t_mesh0 = time.perf_counter()
    from simulate.machining.surface_mesh import surface_mesh
    sm = surface_mesh(wp)
    t_mesh = time.perf_counter() - t_mesh0
    rss = max(rss, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
    wall, cpu = res.wall_time, res.cpu_time
    n_tri, stride, dexel_mb = len(sm.faces), sm.stride, wp.nbytes / 1e6
    del sm
    # the time split: the same run again, fresh stock, clock-reading (uncached) copy of the loop
    wp_prof = stock_workpiece(pj.program, job.settings)
    prof = simulate_machining(wp_prof, cutter, jt.t[:n], jt.line[:n], jt.xyz[:n], mat, spindle, compliance=C,
                              switch=jt.switch[:n], profile=True, drive=servo_of(fp_lugre))
    del wp_prof
    # the same with grey-box LuGre friction on joints 1-3: cached loop, then the clock-reading copy
    grey = simulate_machining(stock_workpiece(pj.program, job.settings), cutter, jt.t[:n], jt.line[:n], jt.xyz[:n],
                              mat, spindle, compliance=C, switch=jt.switch[:n], drive=servo_of(fp_grey))
    grey_prof = simulate_machining(stock_workpiece(pj.program, job.settings), cutter, jt.t[:n], jt.line[:n],
                                   jt.xyz[:n], mat, spindle, compliance=C, switch=jt.switch[:n], profile=True,
                                   drive=servo_of(fp_grey))
    table = Table(title=f"machining bench: iso320 finishing, pose {placement.name}, spacing {spacing} mm, "
                        f"{numba.get_num_threads()} numba thread(s), cutter {cutter.diameter * 1e3:g} mm "
                        f"{cutter.flutes} flutes (robot file), one run")
    table.add_column("figure")  # labels go through escape(): "[s]" would be read as markup
    table.add_column("per wall s", justify="right")
    table.add_column("per CPU s", justify="right")
    table.add_column("target / note", justify="right")
    table.add_row(escape("steps"), f"{n}", "", "")
    table.add_row(escape("loop time [s]"), f"{wall:.2f}", f"{cpu:.2f}", "CPU: this process, all threads")
    table.add_row(escape("steps/s, conventional LuGre (robot file)"), f"{n / wall:,.0f}", f"{n / cpu:,.0f}",
                  f">= 5000, goal 20000 ({n / cpu / 5000:.2f}x on CPU)")
    table.add_row(escape(f"steps/s, grey-box LuGre joints 1-3 ({grey_note})"), f"{n / grey.wall_time:,.0f}",
                  f"{n / grey.cpu_time:,.0f}", f"{grey.cpu_time / cpu:.2f}x the LuGre CPU time")
    # the drives' share: the loop's own clock split (ticks of drive_cycle) of the profiled runs
    nsd = "/".join(str(n) for n in servo_of(fp_lugre).n_sub)
    for label, pr in (("conventional LuGre", prof), ("grey-box joints 1-3", grey_prof)):
        d = pr.timings.get("drive", 0.0)
        table.add_row(escape(f"drive share of the loop, {label} ({nsd} substeps per joint)"),
                      f"{d:.2f} s", "", f"{d / max(pr.wall_time, 1e-12) * 100:.1f} % of the profiled loop")
    table.add_row(escape("simulated / loop time"), f"{res.simulated_time / wall:.1f}", f"{res.simulated_time / cpu:.1f}",
                  ">= 10")
    pw = prof.wall_time
    table.add_row(escape("profiled run (clock-reading copy) [s]"), f"{pw:.2f}", f"{prof.cpu_time:.2f}",
                  f"{pw / wall:.2f}x the cached loop; split below")
    parts = {k: v for k, v in prof.timings.items() if k in ("removal", "engagement", "forces", "robot", "drive")}
    for k, v in parts.items():
        table.add_row(escape(f"  {k} [s]"), f"{v:.2f}", "", f"{v / pw * 100:.0f} % of the profiled loop")
    table.add_row(escape("    of removal: z-rays [s]"), f"{prof.timings.get('removal, z-rays', 0.0):.2f}", "", "")
    table.add_row(escape("  loop overhead [s]"), f"{pw - sum(parts.values()):.2f}", "", "")
    table.add_row(escape("  compile of the profiling copy [s]"), f"{t_comp:.1f}", "", "once per process, not cached")
    if ref is not None:
        start, m, rw, rc_ = ref
        table.add_row(escape(f"per-step kernel calls, steps {start}-{start + m} [steps/s]"), f"{m / rw:,.0f}",
                      f"{m / rc_:,.0f}", "same kernels, one call per step, no coupling")
        table.add_row(escape(f"one compiled loop, same steps [steps/s]"), f"{m / ref_loop[0]:,.0f}",
                      f"{m / ref_loop[1]:,.0f}", f"{(m / ref_loop[1]) / (m / rc_):.1f}x per CPU s")
    table.add_row(escape("robot compliance + drive setup, up-front [s]"), f"{t_robot:.2f}", f"{c_robot:.2f}", "")
    table.add_row(escape("setup (program, IK, stock) [s]"), f"{t_prep:.2f}", "", "")
    table.add_row(escape(f"surface mesh (stride {stride}, {n_tri:,} triangles) [s]"), f"{t_mesh:.2f}", "", "")
    table.add_row(escape("dexel memory [MB]"), f"{dexel_mb:.0f}", "", "")
    table.add_row(escape("peak RSS [MB]"), f"{rss / 1e6:.0f}", "", "< 4096 (before the profiled run)")
    table.add_row(escape("removed volume [mm^3]"), f"{res.removed_volume * 1e9:.0f}", "", "")
    table.add_row(escape("peak force [N] / peak deflection [um]"), f"{res.steps.peak_force.max():.1f}",
                  f"{np.linalg.norm(res.steps.deflection, axis=1).max() * 1e6:.1f}", "")
    out.print(table)


def _bench_greybox(rob, folder: Optional[Path]):
    """Loop friction with a grey-box model on joints 1-3 (the given folder, or one fitted on the spot)."""
    import tempfile
    from dataclasses import replace

    from simulate.robot.friction import loop_friction

    note = "given"
    if folder is None:
        from identify.axis_limits import AxisLimits
        from identify.models import make_model
        from identify.plant import PlantConfig, synthesize
        from identify.records import validate_frame
        from identify.trajectories import universal_trajectory

        tr = universal_trajectory(AxisLimits(-3.2, 3.2, 2.1, 6.0, 60.0), duration=4.0)
        rec = validate_frame(synthesize(tr.t, tr.q, tr.qd, tr.qdd, config=replace(PlantConfig(), static_curve="hump"),
                                        seed=1).frame, "bench")
        folder = make_model("greybox", epochs=5).fit(rec).save(Path(tempfile.mkdtemp(prefix="greybench-bench-")) / "gb")
        note = "fitted, 5 epochs"
    fp, _ = loop_friction(rob, {1: str(folder), 2: str(folder), 3: str(folder)})
    return fp, note


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    app.command("machine")(guarded(machine))
    bench_app.command("machining")(guarded(bench_machining))
