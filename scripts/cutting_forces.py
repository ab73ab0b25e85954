"""Simulated against analytic cutting force along the ISO 10791-7 finishing programs, per segment.

Usage (from the repository root)::

    PYTHONPATH=. python scripts/cutting_forces.py [iso160 iso320] [--spacings 0.25 0.125]

Runs each program's commanded path (no robot: the engagement the closed form describes) through
the removal and force kernels at each dexel spacing [mm], on the ranking's stock (2 mm under the
lowest cut), and prints a Markdown table per piece: for every segment whose engagement is known in
closed form (the contours and the deep wall, all down milling at the stock's radial allowance),
the mean revolution-mean force [N] simulated and analytic (Altintas' closed form over
``[phi_st, pi]``, docs/cutting-forces.md), the worst step's deviation from the analytic force of
its own engagement [%], the largest revolution-mean force and the largest instantaneous force [N]
at each spacing, and the ratio of the first spacing's peak to the second's.
"""
from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
R = 5e-3          # m, the programs' D10 flat end mill
N = 3             # teeth of the robot file's tool
#: arc length [m] left out at each end of a segment (entry corners, acceleration)
END_MARGIN = 12e-3


def blocks(program: Path) -> dict[int, str]:
    """Program line -> the comment block it belongs to ('square', 'circle', 'angle', 'slope', 'wall')."""
    out, label = {}, ""
    for i, text in enumerate(program.read_text().splitlines(), start=1):
        m = re.match(r"\((\w+)", text.strip())
        if m:
            word = m.group(1).lower()
            label = "wall" if "inner wall" in text else word
        # feed moves only (rapids and plunges in a block are no cut of its feature)
        out[i] = label if re.match(r"G[123]\b", text.strip()) and "F500" not in text else ""
    return out


def engagement_of(piece: str, stock: dict, block: str, seg_xyz: np.ndarray, ramp) -> tuple | None:
    """(phi_st [rad], depth(x) [m] callable) of a segment, or None where no closed form applies."""
    allowance = stock["allowance"]
    names = {b["name"]: b for b in stock["blanks"]}
    z = float(seg_xyz[0, 2])
    straight = np.allclose(seg_xyz[:, 2], z)
    if block in ("square", "angle") and straight:
        b = names[block]
        depth = b["top"]["z0"] - z
        return math.pi - math.acos(1 - allowance / R), (lambda x, d=depth: np.full_like(x, d))
    if block == "circle":
        b = names["circle"]
        rho = float(np.median(np.hypot(seg_xyz[:, 0], seg_xyz[:, 1])))
        rs = b["radius"]
        gamma = math.acos((rho * rho + R * R - rs * rs) / (2 * rho * R))
        depth = b["top"]["z0"] - z
        return math.pi - gamma, (lambda x, d=depth: np.full_like(x, d))
    if block == "wall":
        b = names["slope"]
        edge = max(v[1] for v in b["vertices"])
        y = float(seg_xyz[0, 1])
        ae = R - (y - edge)
        top = b["top"]
        mid = edge - 0.5 * ae   # the middle of the strip the wall cut takes

        def depth(x):
            # the strip's top: the stock's sloped top or, lower, what the slope passes left: a flat end
            # mill ramping up along x cuts a point at distance dy from its path lowest when its axis
            # was sqrt(R^2 - dy^2) before it
            h = top["z0"] + top["dzdx"] * x
            for y_p, zfun in ramp:
                dy = abs(y_p - mid)
                if dy < R:
                    h = np.minimum(h, zfun(x - math.sqrt(R * R - dy * dy)))
            return h - z
        return math.pi - math.acos(1 - ae / R), depth
    return None


def run(piece: str, spacing_mm: float):
    from simulate.machining.cutting import Spindle, load_material
    from simulate.machining.simulation import simulate_machining
    from simulate.machining.tools import make_cutter
    from simulate.pipeline import MachiningSettings, load_program, stock_workpiece

    prog = load_program(ROOT / "data" / "programs" / f"{piece}.nc")
    wp = stock_workpiece(prog, MachiningSettings(spacing=spacing_mm * 1e-3, stock_floor=2e-3))
    cutter = make_cutter("flat", 2 * R, flutes=N, helix_deg=30, length=0.05)
    ip = prog.interp
    mat = load_material("Al7075")
    res = simulate_machining(wp, cutter, ip.t, ip.line, ip.xyz, mat, Spindle.from_rpm(prog.spindle_rpm))
    return prog, res.steps, mat


def segment_rows(piece: str, spacings: list[float]) -> list[dict]:
    from simulate.machining.closed_form import mean_force_local

    stock = json.loads((ROOT / "data" / "programs" / f"{piece}.stock.json").read_text())
    lab = blocks(ROOT / "data" / "programs" / f"{piece}.nc")
    runs = [run(piece, sp) for sp in spacings]
    prog, _, mat = runs[0]
    ip = prog.interp
    rpm = prog.spindle_rpm
    # the slope passes (ramps along x): each one's path y [m] and tip height [m] as a function of x
    ramp = []
    for ln in np.unique(ip.line):
        sel0 = ip.line == ln
        if lab.get(int(ln)) == "slope" and np.ptp(ip.xyz[sel0, 2]) > 1e-4:
            xr, zr = ip.xyz[sel0, 0], ip.xyz[sel0, 2]
            order = np.argsort(xr)
            ramp.append((float(np.median(ip.xyz[sel0, 1])),
                         lambda x, xr=xr[order], zr=zr[order]: np.interp(x, xr, zr)))

    rows = []
    for ln in np.unique(ip.line):
        ln = int(ln)
        block = lab.get(ln, "")
        sel = ip.line == ln
        idx = np.where(sel)[0]
        if len(idx) < 10 or block not in ("square", "circle", "angle", "wall"):
            continue
        s = ip.s[idx]
        vmax = ip.v[idx].max()
        keep = (s > s[0] + END_MARGIN) & (s < s[-1] - END_MARGIN) & (ip.v[idx] > 0.999 * vmax)
        idx = idx[keep]
        if len(idx) < 10:
            continue
        eng = engagement_of(piece, stock, block, ip.xyz[idx], ramp)
        if eng is None:
            continue
        phi_st, depth = eng
        vel = (ip.xyz[idx] - ip.xyz[idx - 1]) / np.diff(ip.t)[idx - 1, None]
        speed = np.linalg.norm(vel[:, :2], axis=1)
        c = speed / (N * rpm / 60.0)
        a = depth(ip.xyz[idx, 0])
        ref = np.zeros((len(idx), 3))
        for q in range(len(idx)):
            u = np.array([vel[q, 0], vel[q, 1], 0.0]) / speed[q]
            left = np.array([-u[1], u[0], 0.0])
            fl = mean_force_local(phi_st, math.pi, a[q], c[q], N, mat.kc, mat.ke)
            ref[q] = fl[0] * u + fl[1] * left - np.array([0.0, 0.0, fl[2]])
        row: dict[object, object] = {"line": ln, "block": block, "steps": len(idx),
                                     "analytic_N": float(np.linalg.norm(ref, axis=1).mean())}
        for sp, (_, st, _) in zip(spacings, runs, strict=True):
            F = st.force[idx]
            err = np.linalg.norm(F - ref, axis=1) / np.linalg.norm(ref, axis=1)
            row[sp] = {"mean_N": float(np.linalg.norm(F, axis=1).mean()), "worst_pct": float(100 * err.max()),
                       "max_N": float(np.linalg.norm(F, axis=1).max()), "peak_N": float(st.peak_force[idx].max())}
        rows.append(row)
    return rows


def table(piece: str, spacings: list[float], rows: list[dict]) -> str:
    a, b = spacings[0], spacings[1] if len(spacings) > 1 else spacings[0]
    head = (f"| {piece} line | feature | steps | analytic mean [N] | mean {a:g} mm [N] | worst step {a:g} mm [%] "
            f"| worst step {b:g} mm [%] | max mean {a:g} / {b:g} mm [N] | peak {a:g} / {b:g} mm [N] | peak ratio [-] |")
    lines = [head, "|" + "---|" * 10]
    for r in rows:
        ra, rb = r[a], r[b]
        ratio = f"{ra['peak_N'] / rb['peak_N']:.3f}" if rb["peak_N"] > 0 else "-"
        lines.append(f"| {r['line']} | {r['block']} | {r['steps']} | {r['analytic_N']:.1f} | {ra['mean_N']:.1f} "
                     f"| {ra['worst_pct']:.1f} | {rb['worst_pct']:.1f} | {ra['max_N']:.1f} / {rb['max_N']:.1f} "
                     f"| {ra['peak_N']:.1f} / {rb['peak_N']:.1f} | {ratio} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pieces", nargs="*", default=["iso160", "iso320"])
    ap.add_argument("--spacings", nargs="+", type=float, default=[0.25, 0.125], help="dexel spacings [mm]")
    args = ap.parse_args()
    for piece in args.pieces:
        rows = segment_rows(piece, args.spacings)
        print(table(piece, args.spacings, rows))
        print()


if __name__ == "__main__":
    main()
