"""``greybench bench explain``: times of the explain stages on the small test program."""
from __future__ import annotations

import time
from pathlib import Path

import typer
from rich.table import Table

from greybench.support import DATA_DIR, out


def bench_explain(
    spacing: float = typer.Option(1.0, "--spacing", help="Dexel spacing [mm]."),
) -> None:
    """Times of the explain stages on the small test program (tests/explain/data), one hidden stiffness change."""
    import numpy as np

    from simulate.evaluation.cmm import probe
    from simulate.explain.comparison import compare_points
    from simulate.explain.measured import MeasuredScan
    from simulate.explain.pipeline import explain_part
    from simulate.explain.simulation import load_setup, simulate_part
    from simulate.robot.model import load_robot

    d = Path(__file__).resolve().parents[1] / "tests" / "explain" / "data"
    rob = load_robot(DATA_DIR / "robots" / "max100.toml")
    setup = load_setup(d / "small160.nc", d / "small160.poses.json", "near", spacing=spacing * 1e-3)
    c0 = time.perf_counter()
    n_steps = len(setup.trajectory(rob).t)
    t_setup = time.perf_counter() - c0
    hidden = rob.with_changes(stiffness=rob.stiffness * np.array([1, 0.5, 1, 1, 1, 1]))
    simulate_part(rob, setup)  # compile / warm caches
    c0 = time.perf_counter()
    ms = simulate_part(hidden, setup)
    t_sim = time.perf_counter() - c0
    scan = probe(ms.workpiece, setup.piece)
    keep = {k: v for k, v in scan.points.items() if k.startswith(("circle_wall", "square_wall", "circle_floor",
                                                                   "square_floor"))}
    meas = MeasuredScan(points=keep, lines={k: np.zeros(len(v), np.int64) for k, v in keep.items()}, source="<bench>")
    c0 = time.perf_counter()
    nominal = simulate_part(rob, setup)
    cmp = compare_points(meas, nominal.workpiece, nominal.steps, setup.piece)
    t_cmp = time.perf_counter() - c0
    c0 = time.perf_counter()
    ex = explain_part(meas, rob, setup, nominal=nominal, max_sims=2)
    t_all = time.perf_counter() - c0
    t = Table(title=f"explain bench: small 160 program, pose near, spacing {spacing} mm, hidden stiffness:2 x0.5")
    t.add_column("figure")
    t.add_column("value", justify="right")
    t.add_row("steps", f"{n_steps}")
    t.add_row("setup (IK, switching) \\[s]", f"{t_setup:.2f}")
    t.add_row("one simulation \\[s]", f"{t_sim:.2f}")
    t.add_row("steps/s of one simulation", f"{n_steps / t_sim:,.0f}")
    t.add_row("probe points compared", f"{len(cmp.residual)}")
    t.add_row("nominal simulation + comparison \\[s]", f"{t_cmp:.2f}")
    for k, v in ex.timings.items():
        t.add_row(f"  explain: {k} \\[s]", f"{v:.2f}")
    t.add_row("explain total (nominal given) \\[s]", f"{t_all:.2f}")
    t.add_row("calibration re-simulations", f"{len(ex.calibration.history) if ex.calibration else 0}")
    t.add_row("explain / one simulation \\[-]", f"{t_all / t_sim:.1f}")
    t.add_row("cause named", ex.cause)
    t.add_row("rms before / after \\[µm]", f"{ex.rms_before * 1e6:.2f} / {ex.rms_after * 1e6:.2f}")
    out.print(t)
