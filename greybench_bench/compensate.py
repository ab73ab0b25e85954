"""``greybench bench compensate``: time per compensation iteration and the reduction reached."""
from __future__ import annotations

import time

import typer
from rich.table import Table

from greybench.support import DATA_DIR, out, progress, resolve_robot
from simulate import defaults as DEFAULTS


def bench_compensate(
    spacing: float = typer.Option(1.0, "--spacing", help="Dexel spacing [mm]."),
    iterations: int = typer.Option(2, "--iterations", help="Corrected programs simulated [-]."),
    pose_name: str = typer.Option("near", "--pose", help="Pose of data/poses/iso160.json."),
) -> None:
    """Time per iteration and the reduction of the Table-2 sum on the 160 test piece, one pose (the
    iteration ``compensate`` runs, with the tool radius for the corners and the floors)."""
    from simulate.compensation import CompensationSettings, compensate, compensation_job, pipeline_simulator
    from simulate.evaluation.cutter import robot_cutter

    program = DATA_DIR / "programs" / "iso160.nc"
    poses = DATA_DIR / "poses" / "iso160.json"
    setup, job, placement, rob = compensation_job(program, resolve_robot("max100"), poses, pose_name,
                                                  spacing_mm=spacing, probe_spacing_mm=DEFAULTS.PROBE_SPACING * 1e3,
                                                  size=160, friction={})
    rows = []
    t0 = time.perf_counter()
    with progress("compensating", total=iterations + 1) as adv:
        def seen(it):
            rows.append(it)
            adv(1)

        res = compensate(setup, pipeline_simulator(job), CompensationSettings(iterations=iterations),
                         on_iteration=seen, require_spindle=True, tool_radius=robot_cutter(rob).radius)
    wall = time.perf_counter() - t0
    t = Table(title=f"compensate iso160, pose {placement.name}, dexel spacing {spacing:g} mm")
    for c in ("iteration", "simulation [s]", "sum of abs. deviation [µm]", "ratio to original", "path RMS [µm]",
              "time ratio", "pieces"):
        t.add_column(c, justify="right")
    s0 = rows[0].table_sum
    for it in rows:
        t.add_row(str(it.index) + (" *" if it.index == res.best else ""), f"{it.wall_time:.1f}",
                  f"{it.table_sum * 1e6:.1f}", f"{it.table_sum / s0:.3f}", f"{it.path_rms * 1e6:.1f}",
                  f"{it.time_ratio:.3f}", str(it.pieces))
    out.print(t)
    n_it = max(1, len(rows) - 1)
    per_sim = sum(it.wall_time for it in rows[1:]) / n_it
    per_it = (wall - rows[0].wall_time) / n_it
    out.print(f"total {wall:.1f} s; per iteration {per_it:.1f} s, of which {per_sim:.1f} s simulating the corrected "
              f"program and {per_it - per_sim:.1f} s updating, writing and interpolating it; reduction reached: "
              f"{rows[res.best].table_sum / s0:.3f} of the original sum (* chosen)")
