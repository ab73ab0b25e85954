"""``greybench bench ranking``: wall time of rank-poses with 1 and 2 workers and with the component re-runs."""
from __future__ import annotations

import time
from pathlib import Path

import typer
from rich.table import Table

from greybench.support import DATA_DIR, out, resolve_robot
from simulate import defaults as DEFAULTS
from simulate.evaluation.features import MM
from simulate.evaluation.ranking import COMPONENTS, RankSettings, rank_poses


def bench_ranking(
    program: Path = typer.Option(DATA_DIR / "programs" / "iso320.nc",
                                 "--program", help="G-code program."),
    poses: Path = typer.Option(DATA_DIR / "poses" / "iso320.json", "--poses",
                               help="Pose file (JSON) [m, rad]."),
    spacing: float = typer.Option(DEFAULTS.RANKING_DEXEL_SPACING * 1e3, "--spacing",
                                  help="Dexel spacing [mm] (coarser grids make the cutting force, hence the "
                                       "deflection, jumpy)."),
) -> None:
    """Rank the poses with 2 and 1 worker processes, and with 2 plus the component re-runs (``--shares``, what
    ``make demo`` runs): wall times [s] and ratios, one run each."""
    from simulate.toolpath.placement import load_poses

    placements = load_poses(poses)
    robot_path = resolve_robot("max100")
    settings = RankSettings(spacing=spacing * MM)
    t = Table(title=f"bench ranking: {len(placements)} poses of {program.name}, dexel {spacing:g} mm "
                    "(target <= 120 s on 2 cores)")
    for c in ("workers", "component re-runs", "simulations", "wall \\[s]", "per simulation \\[s]", "ratio to 1 worker",
              "best pose"):
        t.add_column(c, justify="right")
    rows = []
    for w, sh in ((2, False), (1, False), (2, True)):
        c0 = time.perf_counter()
        r = rank_poses(program, robot_path, placements, settings=settings, workers=w, shares=sh)
        n_sim = len(placements) * (1 + (len(COMPONENTS) if sh else 0))
        rows.append((w, sh, n_sim, time.perf_counter() - c0, r.best))
    base = next(x[3] / x[2] for x in rows if x[0] == 1)
    for w, sh, n_sim, s, best in rows:
        t.add_row(str(w), "yes" if sh else "no", str(n_sim), f"{s:.1f}", f"{s / n_sim:.1f}",
                  f"{base / (s / n_sim):.2f}", best)
    out.print(t)
    out.print("ratio to 1 worker: simulations per second relative to the 1-worker run.")
