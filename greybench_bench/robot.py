"""``greybench bench robot``: batch IK vs py-opw-kinematics, RNEA, the six two-mass drives vs real time."""
from __future__ import annotations

import time

import numpy as np
import typer
from rich.table import Table

from greybench.support import emit_json, out, progress, resolve_robot
from simulate.robot.kinematics import fk, ik_nearest
from simulate.robot.model import load_robot


def _timed(fn) -> tuple[float, float]:
    """(wall, cpu) seconds of one call; cpu is this process's CPU time (one thread here)."""
    w0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w0, time.process_time() - c0


def bench_robot(
    robot: str = typer.Option("max100", "--robot", help="Robot name (data/robots) or robot file (.toml)."),
    poses: int = typer.Option(1_000_000, "--poses", help="Poses for batch IK (-)."),
    ref_poses: int = typer.Option(100_000, "--ref-poses", help="Poses for py-opw-kinematics batch_inverse (-)."),
    samples: int = typer.Option(1_000_000, "--samples", help="RNEA samples (-)."),
    servo_seconds: float = typer.Option(60.0, "--servo-seconds", help="Simulated servo time (s) at a 2 ms cycle."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object with the figures."),
) -> None:
    """Batch IK poses/s (numba, 1 core) vs py-opw-kinematics, RNEA samples/s, servo speed vs real time.

    Rates are given per wall-clock second and per CPU second of this (single-threaded) process:
    on a machine shared with other jobs the CPU-time figure is the one-core speed.
    """
    import numba

    from simulate.robot.drive import CYCLE, simulate_drive
    from simulate.robot.dynamics import rnea
    from simulate.robot.kinematics import opw_parameters

    numba.set_num_threads(1)
    r = load_robot(resolve_robot(robot))
    rng = np.random.default_rng(0)
    q = rng.uniform(r.lower, r.upper, size=(poses, 6))
    T = fk(r, q)
    ik_nearest(r, T[:100], q[0])   # compile / load cache
    box: dict = {}
    with progress("batch IK"):
        ik_w, ik_c = _timed(lambda: box.update(res=ik_nearest(r, T, q[0])))
    res = box["res"]
    err = float(np.max(np.abs(fk(r, res.q[res.ok])[:, :3, 3] - T[res.ok, :3, 3])))
    ref = None
    try:
        import py_opw_kinematics as po
        from scipy.spatial.transform import RigidTransform
        km = po.KinematicModel(**opw_parameters(r), offsets=(0.0,) * 6, flip_axes=(False,) * 6)
        rob = po.Robot(km, degrees=False)
        n_ref = min(ref_poses, poses)
        P = RigidTransform.from_matrix(fk(r, q[:n_ref], tool=False))
        with progress("py-opw-kinematics batch_inverse"):
            ref = _timed(lambda: rob.batch_inverse(P, current_joints=q[0]))
        ref = (n_ref / ref[0], n_ref / ref[1])
    except ImportError:
        pass
    qd = rng.uniform(-1, 1, size=(samples, 6)) * r.vmax
    qdd = rng.uniform(-1, 1, size=(samples, 6)) * r.amax
    qs = rng.uniform(r.lower, r.upper, size=(samples, 6))
    rnea(r, qs[:10], qd[:10], qdd[:10])
    with progress("RNEA"):
        rn_w, rn_c = _timed(lambda: rnea(r, qs, qd, qdd))
    t = np.arange(0.0, servo_seconds, CYCLE)
    qc = (0.5 * (r.lower + r.upper) + 0.3 * np.sin(2 * np.pi * 0.4 * t)[:, None] * np.ones(6))
    sv_n = "/".join(str(n) for n in simulate_drive(r, t[:100], qc[:100]).substeps)
    with progress("drives"):
        sv_w, sv_c = _timed(lambda: simulate_drive(r, t, qc, friction=True, backlash=True))
    ik_rate = (poses / ik_w, poses / ik_c)
    rn_rate = (samples / rn_w, samples / rn_c)
    sv_x = (servo_seconds / sv_w, servo_seconds / sv_c)
    figures = {"ik_poses_per_s": ik_rate[0], "ik_poses_per_cpu_s": ik_rate[1], "ik_max_position_error_m": err,
               "py_opw_batch_inverse_poses_per_s": ref[0] if ref else None,
               "py_opw_batch_inverse_poses_per_cpu_s": ref[1] if ref else None,
               "ik_ratio_vs_py_opw": (ik_rate[1] / ref[1]) if ref else None,
               "rnea_samples_per_s": rn_rate[0], "rnea_samples_per_cpu_s": rn_rate[1],
               "servo_x_real_time": sv_x[0], "servo_x_real_time_cpu": sv_x[1], "threads": 1}
    if as_json:
        emit_json(figures)
        return
    table = Table(title=f"bench robot ({r.name}), one run, 1 thread")
    for col in ("item", "per wall s", "per CPU s", "target", "ratio / note"):
        table.add_column(col)
    table.add_row("batch IK (ik_nearest, numba)", f"{ik_rate[0] / 1e6:.2f} M poses/s",
                  f"{ik_rate[1] / 1e6:.2f} M poses/s", ">= 1 M poses/s",
                  (f"{ik_rate[1] / ref[1]:.1f}x py-opw-kinematics (target >= 2x)" if ref else "py-opw missing")
                  + f"; FK(IK) max err {err:.1e} m")
    if ref:
        table.add_row("py-opw-kinematics batch_inverse", f"{ref[0] / 1e6:.3f} M poses/s",
                      f"{ref[1] / 1e6:.3f} M poses/s", "", f"{min(ref_poses, poses)} poses")
    table.add_row("RNEA (numba)", f"{rn_rate[0] / 1e6:.2f} M samples/s", f"{rn_rate[1] / 1e6:.2f} M samples/s",
                  ">= 0.5 M samples/s", f"{rn_rate[1] / 5e5:.1f}x target")
    table.add_row(f"six two-mass drives ({sv_n} substeps, friction, backlash)", f"{sv_x[0]:.0f}x real time",
                  f"{sv_x[1]:.0f}x real time", ">= 20x", f"{servo_seconds:g} s simulated")
    out.print(table)
