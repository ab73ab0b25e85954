"""The circle's reversal split on the shipped robot (docs/drive-model.md, sections "The virtual circular
test on the shipped robot" and "Doubled friction in yz and zx").

Simulates the R 50 mm, 2000 mm/min circle of the shipped robot in the planes xy, yz and zx at the
iso320 poses pose1..pose4 and the iso160 poses near and far_rotated, with the robot file's friction,
doubled friction levels and no friction, and prints as markdown:

- per plane and pose the largest reversal spike and lost motion [µm] of the shipped split
  (:func:`simulate.evaluation.circle.split_reversal`, the transient modelled): no friction /
  friction / doubled friction and the ratios;
- the same spikes for fit spans of 40, 60 (shipped) and 80 deg (convergence);
- the former fixed-window split (spike 15 deg, settled line over the 10 deg after it;
  :func:`former_split`, kept here for comparison only) on the same runs;
- at A1's first reversal (xy pose1) the step of A1's link error q_cmd - q [µrad] and its overshoot
  beyond the new level [µrad], with friction, doubled, 4x, without play and without friction.

With ``--figure PATH`` it also draws yz pose3's reversals (radial deviation [µm] and the reversing
joints' link errors [µrad] over the travelled angle [deg], normal and doubled friction, the former
windows and the shipped fit span marked). About a minute after the numba kernels are compiled.

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
CASES = (("iso320", "pose1"), ("iso320", "pose2"), ("iso320", "pose3"), ("iso320", "pose4"),
         ("iso160", "near"), ("iso160", "far_rotated"))
VARIANTS: dict[str, dict[str, Any]] = {"no friction": {"friction": False}, "normal": {},
                                       "friction x2": {"friction_scale": 2.0}}
#: the former fixed windows [deg]: spike window, settled line after it, line before the reversal
FORMER = (15.0, 10.0, 10.0)


def former_split(trav_deg: Any, dev: Any, at_deg: float, *, neighbours: Any = (), **_: Any) -> C.ReversalSplit:
    """The former split, for comparison only: least-squares lines over the 10 deg before the reversal and
    over the 10 deg after a 15 deg spike window (windows shrunk in proportion where another reversal is
    closer), the lost motion their step at the reversal, the spike the extreme beyond their band within
    the spike window."""
    spike_deg, settle_deg, before_deg = FORMER
    t, d = np.asarray(trav_deg, float), np.asarray(dev, float)
    te, de = np.concatenate([t - 360.0, t, t + 360.0]), np.concatenate([d, d, d])
    gaps = (np.asarray(neighbours, float) % 360.0 - at_deg) % 360.0
    gaps = gaps[gaps > 1e-9]
    fa = min(1.0, (float(gaps.min()) if gaps.size else 360.0) / (spike_deg + settle_deg))
    fb = min(1.0, (float((360.0 - gaps).min()) if gaps.size else 360.0) / before_deg)

    def line(lo: float, hi: float) -> np.poly1d:
        sel = (te >= lo) & (te < hi)
        if np.count_nonzero(sel) < 2:
            return np.poly1d([float(de[np.argmin(np.abs(te - lo))])])
        return np.poly1d(np.polyfit(te[sel] - at_deg, de[sel], 1))

    lb = line(at_deg - fb * before_deg, at_deg)
    la = line(at_deg + fa * spike_deg, at_deg + fa * (spike_deg + settle_deg))
    sel = np.nonzero((te >= at_deg) & (te <= at_deg + fa * spike_deg))[0]
    x, y = te[sel] - at_deg, de[sel]
    hi, lo = np.maximum(la(x), lb(x)), np.minimum(la(x), lb(x))
    excess = np.where(y > hi, y - hi, np.where(y < lo, y - lo, 0.0))
    m = int(np.argmax(np.abs(excess)))
    return C.ReversalSplit(lost_motion=float(la(0.0) - lb(0.0)), spike=float(excess[m]), index=int(sel[m] % t.size))


def evaluate_with(run: CircleRun, split: Any = None, **kw: Any) -> C.CircleResult:
    """:func:`simulate.evaluation.circle.evaluate_run` with another split function or the shipped one's
    keywords changed (``span_deg``)."""
    shipped = C.split_reversal
    fn = split or shipped
    C.split_reversal = lambda *a, **k: fn(*a, **{**k, **kw})   # evaluate_circle calls it by module name
    try:
        return C.evaluate_run(run)
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
            for v in (-FORMER[2], 0.0, FORMER[0], FORMER[0] + FORMER[1]):
                ax.axvline(v, color="k", lw=0.5)
            ax.axvline(C.FIT_SPAN_DEG, color="k", lw=0.5, ls="--")
            ax.grid(alpha=0.3)
        axes[0, i].set_title(f"reversal at {a_rev:.0f} deg: {'+'.join(f'A{j}' for j in joints)}", fontsize=10)
        axes[0, i].set_ylabel("radial deviation [µm]")
        axes[1, i].set_ylabel("link error q_cmd - q [µrad]")
        axes[1, i].set_xlabel("travelled angle from the reversal [deg]")
        axes[0, i].legend(fontsize=7)
        axes[1, i].legend(fontsize=7)
    fig.suptitle("yz, pose3, R 50 mm, F 2000 mm/min: solid lines the former split's windows (before 10 deg, "
                 "spike 15 deg, settled 10 deg), dashed the shipped fit span (60 deg)", fontsize=10)
    save_png(fig, path, dpi=80)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--figure", type=Path, help="PNG of yz pose3's reversals")
    args = ap.parse_args(argv)
    robot = load_robot(ROOT / "data" / "robots" / "max100.toml")
    pose_sets = {name: load_poses(ROOT / "data" / "poses" / f"{name}.json") for name in ("iso320", "iso160")}
    runs = {(plane, pose, key): simulate_circle(robot, select_pose(pose_sets[ps], pose),
                                                CircleSpec(0.05, 2.0 / 60, Plane(plane)), **kw)
            for plane in PLANES for ps, pose in CASES for key, kw in VARIANTS.items()}
    keys = list(VARIANTS)

    def figures(split: Any = None, **kw: Any) -> dict[tuple[str, str, str], tuple[float, float]]:
        out = {}
        for k, run in runs.items():
            r = evaluate_with(run, split, **kw)
            out[k] = (r.largest_reversal_spike_um, r.largest_lost_motion_um)
        return out

    def rows(fig: dict) -> list[list[str]]:
        out = []
        for plane in PLANES:
            for _, pose in CASES:
                sp = [fig[plane, pose, k][0] for k in keys]
                lm = [fig[plane, pose, k][1] for k in keys]
                out.append([plane, pose, " / ".join(f"{v:.1f}" for v in sp), f"{sp[1] / sp[0]:.1f}x",
                            f"{sp[2] / sp[1]:.2f}x", " / ".join(f"{v:.0f}" for v in lm), f"{lm[1] / lm[0]:.1f}x",
                            f"{lm[2] / lm[1]:.2f}x"])
        return out

    header = ["plane", "pose", "spike µm: no friction / friction / x2", "friction / none", "x2 / friction",
              "lost motion µm: no friction / friction / x2", "friction / none", "x2 / friction"]
    shipped = figures()
    print("Shipped split (transient modelled, fit span 60 deg), largest |spike| and |lost motion|:\n")
    print("\n".join(markdown_table(header, rows(shipped))))
    spans = {span: figures(span_deg=span) for span in (40.0, 80.0)}
    print("\nLargest spike [µm], no friction / friction / x2, for fit spans of 40, 60 and 80 deg:\n")
    print("\n".join(markdown_table(
        ["plane", "pose", "40 deg", "60 deg", "80 deg"],
        [[plane, pose, *(" / ".join(f"{f[plane, pose, k][0]:.1f}" for k in keys)
                         for f in (spans[40.0], shipped, spans[80.0]))]
         for plane in PLANES for _, pose in CASES])))
    print("\nFormer split (fixed windows: spike 15 deg, settled line over the 10 deg after it):\n")
    print("\n".join(markdown_table(header, rows(figures(former_split)))))
    pose1 = select_pose(pose_sets["iso320"], "pose1")
    a1: dict[str, dict[str, Any]] = {"friction and play": {}, "friction x2": {"friction_scale": 2.0},
                                     "friction x4": {"friction_scale": 4.0}, "no play": {"backlash": False},
                                     "no friction": {"friction": False}}
    a1_rows = []
    for name, kw in a1.items():
        step, over = a1_step_and_overshoot(simulate_circle(robot, pose1, CircleSpec(0.05, 2.0 / 60, Plane.XY), **kw))
        a1_rows.append([name, f"{step * 1e6:.0f}", f"{over * 1e6:.1f}"])
    print("\nA1's first reversal, xy pose1: link error q_cmd - q [µrad]\n")
    print("\n".join(markdown_table(["variant", "step [µrad]", "overshoot beyond the new level [µrad]"], a1_rows)))
    if args.figure:
        names = {"no friction": "no friction", "normal": "normal", "friction x2": "friction x2"}
        figure({names[k]: runs["yz", "pose3", k] for k in keys}, args.figure)
        print(f"\nfigure: {args.figure}")


if __name__ == "__main__":
    main()
