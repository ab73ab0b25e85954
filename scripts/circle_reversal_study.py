"""The circle's reversal split against friction and the split's windows (docs/drive-model.md, section
"Doubled friction in yz and zx").

Simulates the R 50 mm, 2000 mm/min circle of the shipped robot in the planes xy, yz and zx at the
iso320 poses pose1 and pose3, with the robot file's friction, doubled friction levels and no friction,
and prints as markdown:

- the largest reversal spike [µm], normal -> doubled friction (ratio), for several spike + settle
  windows [deg] of :func:`simulate.evaluation.circle.split_reversal`;
- the same with the transient modelled (:func:`transient_split`, a study, not the shipped split);
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


def transient_split(trav_deg: Any, dev: Any, at_deg: float, *, neighbours: Any = (), span_deg: float = 60.0,
                    deg_per_s: float = 2.0 / 60 / 0.05 * 180 / math.pi, **_: Any) -> C.ReversalSplit:
    """A study, not the shipped split: the settled trace after the reversal fitted together with the
    transient, ``F = quadratic + exp(-(x - x0) / (tau w)) (A cos + B sin)(2 pi f (x - x0) / w)`` over
    ``span_deg`` after the reversal (less the next reversal's before window), from the first extreme
    ``x0`` of ``F - L_b`` within 20 deg on; ``f`` 2..20 Hz and ``tau`` 0.05..0.8 s on a grid, the
    polynomial and the oscillation's amplitudes by least squares (``w`` the circle's deg/s). Lost
    motion and spike as the shipped split, with this quadratic as the settled trace after."""
    t, d = np.asarray(trav_deg, float), np.asarray(dev, float)
    te, de = np.concatenate([t - 360.0, t, t + 360.0]), np.concatenate([d, d, d])
    gaps = (np.asarray(neighbours, float) % 360.0 - at_deg) % 360.0
    gaps = gaps[gaps > 1e-9]
    ahead = float(gaps.min()) if gaps.size else 360.0
    behind = float((360.0 - gaps).min()) if gaps.size else 360.0
    before = min(1.0, behind / C.BEFORE_WINDOW_DEG) * C.BEFORE_WINDOW_DEG
    sel = (te >= at_deg - before) & (te < at_deg)
    lb = np.poly1d(np.polyfit(te[sel] - at_deg, de[sel], 1))
    end = min(span_deg, ahead - (C.BEFORE_WINDOW_DEG if gaps.size else 0.0))
    idx = np.nonzero((te >= at_deg) & (te < at_deg + end))[0]
    x, y = te[idx] - at_deg, de[idx]
    scan = x < min(20.0, end / 2)
    x0 = x[int(np.argmax(np.abs(y[scan] - lb(x[scan]))))]
    xf, yf = x[x >= x0], y[x >= x0]
    best: tuple[float, Any] | None = None
    for hz in np.arange(2.0, 20.01, 0.25):
        om = 2 * np.pi * hz / deg_per_s
        for tau in (0.05, 0.1, 0.2, 0.3, 0.5, 0.8):
            env = np.exp(-(xf - x0) / (tau * deg_per_s))
            a = np.stack([np.ones_like(xf), xf, xf ** 2, env * np.cos(om * (xf - x0)), env * np.sin(om * (xf - x0))], 1)
            coef = np.linalg.lstsq(a, yf, rcond=None)[0]
            r = float(np.sum((a @ coef - yf) ** 2))
            if best is None or r < best[0]:
                best = (r, coef)
    assert best is not None
    la = np.poly1d(best[1][:3][::-1])
    hi, lo = np.maximum(la(x), lb(x)), np.minimum(la(x), lb(x))
    excess = np.where(y > hi, y - hi, np.where(y < lo, y - lo, 0.0))
    m = int(np.argmax(np.abs(excess)))
    return C.ReversalSplit(lost_motion=float(la(0.0) - lb(0.0)), spike=float(excess[m]), index=int(idx[m] % t.size))


def largest_transient_spike(run: CircleRun, span_deg: float) -> float:
    """The largest |spike| [µm] of the run with :func:`transient_split`."""
    shipped = C.split_reversal

    def split(*args: Any, **kw: Any) -> C.ReversalSplit:
        return transient_split(*args, neighbours=kw.get("neighbours", ()), span_deg=span_deg)

    C.split_reversal = split
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
    def cell_t(plane: str, pose: str, span: float) -> str:
        n0, a, b = (largest_transient_spike(runs[plane, pose, key], span)
                    for key in ("no friction", "normal", "friction x2"))
        return f"{n0:.1f} / {a:.1f} -> {b:.1f} ({b / a:.2f})"

    print("\nThe same with the transient modelled (transient_split, a study): largest reversal spike [µm],\n"
          "no friction / normal -> doubled friction (ratio):\n")
    print("\n".join(markdown_table(["fit span [deg]", *(f"{pl} {po}" for pl in PLANES for po in POSES)],
                                   [[f"{span:g}", *(cell_t(pl, po, span) for pl in PLANES for po in POSES)]
                                    for span in (40.0, 60.0, 80.0)])))
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
