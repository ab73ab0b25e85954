"""``greybench bench machining``: coupled steps per CPU second of the machining loop (paper Figure 4)
with the two-mass drives and friction inside, and where the time goes."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from greybench.support import DATA_DIR, out, resolve_robot
from identify.errors import InputError
from simulate.run import cutter_from_robot, machining_job


def bench_machining(
    spacing: float = typer.Option(0.25, "--spacing", help="Dexel spacing [mm]."),
    max_steps: int = typer.Option(0, "--max-steps", help="Limit the number of 2 ms steps (0: whole program) [-]."),
    threads: int = typer.Option(1, "--threads", help="numba threads for the loop [-] (1: the one-core figure)."),
    reference_steps: int = typer.Option(3000, "--reference-steps",
                                        help="Steps for the per-step-call reference (0: skip) [-]."),
    greybox: Path | None = typer.Option(None, "--greybox",
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

    from simulate.machining.cutting import Spindle, force_model, load_material, step_forces, substeps
    from simulate.machining.removal import RemovalBuffers, remove_horizontal, remove_vertical
    from simulate.machining.simulation import simulate_machining, workpiece_compliance

    if threads < 1:
        raise InputError(f"threads must be >= 1, got {threads}", field="threads")
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]  # set at run time
    program = DATA_DIR / "programs" / "iso320.nc"
    pose = DATA_DIR / "poses" / "iso320.json"
    t0 = time.perf_counter()
    from simulate.pipeline import prepare, stock_workpiece

    job = machining_job(program, resolve_robot("max100"), pose, None, spacing_mm=spacing)
    pj = prepare(job)
    placement, rob, jt = job.placement, pj.robot, pj.trajectory
    cutter = cutter_from_robot(rob)
    wp = stock_workpiece(pj.program, job.settings)
    t_prep = time.perf_counter() - t0
    n = len(jt.t) if max_steps <= 0 else min(max_steps, len(jt.t))
    mat, spindle = load_material("Al7075"), Spindle.from_rpm(12000)
    t1, c1 = time.perf_counter(), time.process_time()
    Rm = placement.T[:3, :3]
    from simulate.robot.stiffness import Compliance

    C = workpiece_compliance(rob, jt.q[:n], Rm, part=Compliance.LINK)   # the drives take the gears' compliance
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
        # each step a numba parallel region) against the compiled loop, both uncoupled, on a cutting
        # window (the square contour): the workpiece is first brought to the window's start by the loop
        start = min(5000, max(1, n - reference_steps - 1))
        m = min(reference_steps, n - start)
        w0_ = wp.copy()
        simulate_machining(w0_, cutter, jt.t[:start + 1], jt.line[:start + 1], jt.xyz[:start + 1], mat, spindle)
        wref = w0_.copy()
        buf = RemovalBuffers.sized(wref, cutter.radius, 0.01)
        model = force_model(cutter, mat, spindle, substeps(0.002, spindle.omega, cutter.flutes, per_tooth=4))
        dex, grid, tool = wref.rays, wref.grid, cutter.shape
        out4 = np.zeros(4)
        w0, c0 = time.perf_counter(), time.process_time()
        for k in range(start + 1, start + m):
            p0, p1 = jt.xyz[k - 1], jt.xyz[k]
            _, _, ztop = remove_vertical(dex.z, grid, p0, p1, tool, k)
            k0, nl, _ = remove_horizontal(dex, grid, p0, p1, tool, k, True, buf, ztop)
            step_forces(buf.samples, k0, nl, grid, p0, p1, 0.002, jt.t[k], model, out4)
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
    table.add_row(escape("simulated / loop time"), f"{res.simulated_time / wall:.1f}",
                  f"{res.simulated_time / cpu:.1f}", ">= 10")
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
        table.add_row(escape("one compiled loop, same steps [steps/s]"), f"{m / ref_loop[0]:,.0f}",
                      f"{m / ref_loop[1]:,.0f}", f"{(m / ref_loop[1]) / (m / rc_):.1f}x per CPU s")
    table.add_row(escape("robot compliance + drive setup, up-front [s]"), f"{t_robot:.2f}", f"{c_robot:.2f}", "")
    table.add_row(escape("setup (program, IK, stock) [s]"), f"{t_prep:.2f}", "", "")
    table.add_row(escape(f"surface mesh (stride {stride}, {n_tri:,} triangles) [s]"), f"{t_mesh:.2f}", "", "")
    table.add_row(escape("dexel memory [MB]"), f"{dexel_mb:.0f}", "", "")
    table.add_row(escape("peak RSS [MB]"), f"{rss / 1e6:.0f}", "", "< 4096 (before the profiled run)")
    table.add_row(escape("removed volume [mm^3]"), f"{res.removed_volume * 1e9:.0f}", "", "")
    table.add_row(escape("peak force [N] / peak deflection [µm]"), f"{res.steps.peak_force.max():.1f}",
                  f"{np.linalg.norm(res.steps.deflection, axis=1).max() * 1e6:.1f}", "")
    out.print(table)


def _bench_greybox(rob, folder: Path | None):
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
