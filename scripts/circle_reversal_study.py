"""The circle's reversal split against friction and the split's windows (docs/drive-model.md, section
"Doubled friction in yz and zx").

Simulates the R 50 mm, 2000 mm/min circle of the shipped robot in the planes xy, yz and zx at the
iso320 poses pose1 and pose3, with the robot file's friction, doubled friction levels and no friction,
and prints as markdown:

- the largest reversal spike [µm], normal -> doubled friction (ratio), for several spike + settle
  windows [deg] of :func:`simulate.evaluation.circle.split_reversal`;
- at A1's first reversal (xy pose1) the step of A1's link error q_cmd - q [µrad] and its overshoot
  beyond the new level [µrad], with friction, doubled, 4x, without play and without friction.

With ``--figure PATH`` it also draws yz pose3's reversals (radial deviation [µm] and the reversing
joints' link errors [µrad] over the travelled angle [deg], normal and doubled friction, the shipped
windows marked). About 10 s after the numba kernels are compiled.

    python scripts/circle_reversal_study.py [--figure docs/circle-reversal-yz.png]
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from identify.records import markdown_table
from simulate.evaluation import circle as C
from simulate.evaluation.circle import CircleRun, CircleSpec, Plane, joint_reversals, simulate_circle
from simulate.robot.drive import command_velocity
from simulate.robot.model import load_robot
from simulate.toolpath.placement import load_poses, select_pose

ROOT = Path(__file__).resolve().parents[1]
PLANES = ("xy", "yz", "zx")
POSES = ("pose1", "pose3")
#: spike + settle windows [deg] compared (the first is the shipped one)
WINDOWS = ((C.SPIKE_WINDOW_DEG, C.SETTLE_WINDOW_DEG), (25.0, 15.0), (35.0, 20.0), (45.0, 25.0))


def largest_spike(run: CircleRun, spike_deg: float, settle_deg: float) -> float:
    """The largest |spike| [µm] of the run with the given windows [deg]."""
    shipped = C.split_reversal

    def split(*args: Any, **kw: Any) -> C.ReversalSplit:
        kw.update(spike_deg=spike_deg, settle_deg=settle_deg)
        return shipped(*args, **kw)

    C.split_reversal = split    # evaluate_circle calls it by module name
    try:
        return C.evaluate_run(run).largest_reversal_spike_um
    finally:
        C.split_reversal = shipped


def a1_step_and_overshoot(run: CircleRun) -> tuple[float, float]:
    """A1's link error at its first reversal: step between the levels 0.1 s before and 1.4-1.8 s
    after, overshoot beyond the level after [rad]."""
    qd = command_velocity(run.t, run.q_cmd)
    sel = np.nonzero(run.segment == 1)[0]
    k = next(sel[i] for i, j in joint_reversals(qd[sel]) if j == 0)
    e = run.q_cmd[:, 0] - run.q[:, 0]
    before, after = e[k - 50], float(np.mean(e[k + 700:k + 900]))
    return abs(after - before), float(np.max(np.sign(after - before) * (e[k:k + 700] - after)))


def figure(runs: dict[str, CircleRun], path: Path) -> None:
    """yz pose3's reversals: radial deviation and link errors of the reversing joints, normal and
    doubled friction, the shipped windows marked."""
    from simulate.figures import pyplot, save_png

    plt = pyplot()
    res = {k: C.evaluate_run(r) for k, r in runs.items()}
    groups: dict[float, list[int]] = {}
    for s in res["normal"].spikes:
        groups.setdefault(round(s.angle_deg, 1), []).append(s.joint)
    fig, axes = plt.subplots(2, len(groups), figsize=(5.2 * len(groups), 7.5), squeeze=False)
    for i, (a_rev, joints) in enumerate(sorted(groups.items())):
        for key, colour in (("normal", "tab:blue"), ("friction x2", "tab:red"), ("no friction", "0.5")):
            r, run = res[key], runs[key]
            trav = np.degrees(np.unwrap(np.radians(r.angle_deg)) - math.radians(r.angle_deg[0]))
            x = (trav - (a_rev - r.angle_deg[0]) % 360.0 + 180.0) % 360.0 - 180.0
            o = np.argsort(x)
            m = (x[o] > -30) & (x[o] < 90)
            axes[0, i].plot(x[o][m], r.deviation_um[o][m], color=colour, lw=1, label=key)
            e = (run.q_cmd - run.q)[run.segment == 1]
            for j, style in zip([j for j in joints if j in (1, 2, 3)][:2], ("-", "--"), strict=False):
                axes[1, i].plot(x[o][m], e[o][m][:, j - 1] * 1e6, style, color=colour, lw=1, label=f"{key}, A{j}")
        for ax in axes[:, i]:
            for v in (-C.BEFORE_WINDOW_DEG, 0.0, C.SPIKE_WINDOW_DEG, C.SPIKE_WINDOW_DEG + C.SETTLE_WINDOW_DEG):
                ax.axvline(v, color="k", lw=0.5)
            ax.grid(alpha=0.3)
        axes[0, i].set_title(f"reversal at {a_rev:.0f} deg: {'+'.join(f'A{j}' for j in joints)}", fontsize=10)
        axes[0, i].set_ylabel("radial deviation [µm]")
        axes[1, i].set_ylabel("link error q_cmd - q [µrad]")
        axes[1, i].set_xlabel("travelled angle from the reversal [deg]")
        axes[0, i].legend(fontsize=7)
        axes[1, i].legend(fontsize=7)
    fig.suptitle("yz, pose3, R 50 mm, F 2000 mm/min: vertical lines are the split's windows (before 10 deg, "
                 "spike 15 deg, settled 10 deg)", fontsize=10)
    save_png(fig, path, dpi=80)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--figure", type=Path, help="PNG of yz pose3's reversals")
    args = ap.parse_args(argv)
    robot = load_robot(ROOT / "data" / "robots" / "max100.toml")
    poses = load_poses(ROOT / "data" / "poses" / "iso320.json")
    variants: dict[str, dict[str, Any]] = {"normal": {}, "friction x2": {"friction_scale": 2.0},
                                           "no friction": {"friction": False}}
    runs = {(plane, pose, key): simulate_circle(robot, select_pose(poses, pose),
                                                CircleSpec(0.05, 2.0 / 60, Plane(plane)), **kw)
            for plane in PLANES for pose in POSES for key, kw in variants.items()}

    def cell(plane: str, pose: str, sw: float, aw: float) -> str:
        a, b = (largest_spike(runs[plane, pose, key], sw, aw) for key in ("normal", "friction x2"))
        return f"{a:.1f} -> {b:.1f} ({b / a:.2f})"

    print("Largest reversal spike [µm], normal -> doubled friction (ratio):\n")
    print("\n".join(markdown_table(["windows spike + settle [deg]", *(f"{pl} {po}" for pl in PLANES for po in POSES)],
                                   [[f"{sw:g} + {aw:g}", *(cell(pl, po, sw, aw) for pl in PLANES for po in POSES)]
                                    for sw, aw in WINDOWS])))
    pose1 = select_pose(poses, "pose1")
    a1: dict[str, dict[str, Any]] = {"friction and play": {}, "friction x2": {"friction_scale": 2.0},
                                     "friction x4": {"friction_scale": 4.0}, "no play": {"backlash": False},
                                     "no friction": {"friction": False}}
    rows = []
    for name, kw in a1.items():
        step, over = a1_step_and_overshoot(simulate_circle(robot, pose1, CircleSpec(0.05, 2.0 / 60, Plane.XY), **kw))
        rows.append([name, f"{step * 1e6:.0f}", f"{over * 1e6:.1f}"])
    print("\nA1's first reversal, xy pose1: link error q_cmd - q [µrad]\n")
    print("\n".join(markdown_table(["variant", "step [µrad]", "overshoot beyond the new level [µrad]"], rows)))
    if args.figure:
        figure({key: runs["yz", "pose3", key] for key in variants}, args.figure)
        print(f"\nfigure: {args.figure}")


if __name__ == "__main__":
    main()
