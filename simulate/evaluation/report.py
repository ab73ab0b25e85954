"""Pose-ranking report (paper 3.8, 4): markdown with PNG images in an output folder.

Contents: the ranking and its score; Table 2 with one column per pose coloured best (green) to worst
(red) per row like the paper; why the best pose wins (rows where it gains most score); per pose a
deviation colour map of the probe points (signed distance from the nominal surface, outward
positive = material left), force and deflection over time, the switching points on the part; for
the worst feature of each pose, the program lines and times that cut it (via :mod:`trace`); and
the component shares when the ranking was re-run with components switched off.
"""
from __future__ import annotations

import json
import math
from enum import IntFlag
from pathlib import Path

import numpy as np

from identify.files import atomic_file, write_text_atomic
from identify.records import markdown_table
from simulate.evaluation.features import MM, ROW_SURFACES, FeatureTable
from simulate.evaluation.ranking import COMPONENTS, Ranking, ranking_json
from simulate.evaluation.trace import trace_point
from simulate.figures import pyplot, save_png
from simulate.toolpath.switching import axes_of
from simulate.toolpath.testpiece import TestPiece, iso_test_piece


class SwitchAxis(IntFlag):
    """The bits of a step's switching integer (:mod:`simulate.toolpath.switching`: bit i - 1 for axis i)."""

    A1 = 1
    A2 = 2
    A3 = 4
    A4 = 8
    A5 = 16
    A6 = 32


def nominal_residuals(name: str, pts: np.ndarray, piece: TestPiece) -> np.ndarray:
    """Signed distance of probe points of scan feature ``name`` from the nominal surface, m
    (outward positive: material left standing)."""
    p = np.asarray(pts, float)
    if name == "circle_wall":
        c = np.asarray(piece.circle_center)
        return np.hypot(p[:, 0] - c[0], p[:, 1] - c[1]) - piece.circle_diameter / 2
    if name.startswith("square_wall_"):
        h = piece.square_side / 2
        axis, sign = {"xp": (0, 1), "xn": (0, -1), "yp": (1, 1), "yn": (1, -1)}[name[-2:]]
        return sign * (p[:, axis] - piece.square_center[axis]) - h
    if name.startswith("angle_edge_"):
        e = piece.angle_edges[int(name[-1]) - 1]
        d = (e.p1 - e.p0) / np.linalg.norm(e.p1 - e.p0)
        n = np.array([d[1], -d[0]])
        return (p[:, :2] - e.p0) @ n
    if name.startswith("slope_line_"):
        return (p[:, 2] - piece.slope_height(p[:, 0])) * math.cos(piece.slope_angle)
    z = {"circle_top": piece.circle_z[1], "circle_floor": piece.circle_z[0], "square_top": piece.square_z[1],
         "square_floor": piece.square_z[0], "slope_floor": 0.0}[name]
    return p[:, 2] - z


def _gain_driver(ranking: Ranking, best: str, other: str, row: str) -> str:
    """``"; mostly <component>: +a vs +b mm"``: the component whose contribution to ``row`` pushes the other
    pose's deviation furthest away from zero compared with the best pose (contributions signed along the other
    pose's deviation); ``"; no single component"`` when none does (the components interact); empty without
    component re-runs."""
    cb, co = ranking.contributions(best), ranking.contributions(other)
    if not cb or not co:
        return ""
    sgn = 1.0 if ranking.results[other].table[row].deviation >= 0 else -1.0
    push = {k: sgn * (co[k][row] - cb[k][row]) for k in cb}
    c = max(push, key=push.__getitem__)
    if push[c] <= 0:
        return "; no single component"
    return f"; mostly {c}: {cb[c][row] / MM:+.4f} vs {co[c][row] / MM:+.4f} mm"


# the names simulate.evaluation.circle draws with (new code: simulate.figures)
_plt = pyplot


def _save(fig, path: Path) -> str:
    return save_png(fig, path, dpi=100)


def _rank_colours(values: list[float]) -> list[tuple]:
    """Green (best, smallest |value|) to red (worst) per row, like the paper's Table 2."""
    import matplotlib

    cmap = matplotlib.colormaps["RdYlGn_r"]
    a = np.abs(np.asarray(values, float))
    order = np.argsort(np.argsort(a, kind="stable"), kind="stable")
    n = max(1, len(a) - 1)
    return [cmap(0.1 + 0.8 * o / n) for o in order]


def table2_image(ranking: Ranking, path: Path) -> str:
    plt = pyplot()
    poses = [p.name for p in ranking.placements]
    rows = ranking.results[poses[0]].table.rows
    cell, colours = [], []
    for r in rows:
        vals = [ranking.results[p].table[r.name].deviation for p in poses]
        cell.append([r.name, r.nominal_text(), f"{r.tolerance / MM:.3f}"] + [f"{v / MM:+.4f}" for v in vals])
        colours.append(["white"] * 3 + _rank_colours(vals))
    fig, ax = plt.subplots(figsize=(3 + 1.6 * len(poses) + 3, 0.45 * len(rows) + 1))
    ax.axis("off")
    t = ax.table(cellText=cell, cellColours=colours,
                 colLabels=["feature", "nominal [mm]", "tolerance [mm]"] + [f"{p} [mm]" for p in poses], loc="center")
    t.auto_set_font_size(False)
    t.set_fontsize(9)
    t.scale(1, 1.4)
    for (i, j), c in t.get_celld().items():
        if i > 0 and j >= 3 and abs(ranking.results[poses[j - 3]].table.rows[i - 1].deviation) <= \
                ranking.results[poses[j - 3]].table.rows[i - 1].tolerance:
            c.get_text().set_fontweight("bold")  # in tolerance, as the paper's bold values
    ax.set_title("Deviation [mm] per pose (green best, red worst per row; bold: in tolerance)")
    return save_png(fig, path, dpi=100)


def deviation_map(scan, piece: TestPiece, path: Path, title: str) -> str:
    plt = pyplot()
    pts, dev = [], []
    for name, p in scan.points.items():
        pts.append(p)
        dev.append(nominal_residuals(name, p, piece))
    P, D = np.concatenate(pts), np.concatenate(dev) / 1e-6
    lim = float(np.percentile(np.abs(D), 99)) or 1.0
    fig, ax = plt.subplots(figsize=(7, 6))
    sc = ax.scatter(P[:, 0] / MM, P[:, 1] / MM, c=D, s=4, cmap="coolwarm", vmin=-lim, vmax=lim)
    fig.colorbar(sc, ax=ax, label="deviation from nominal [µm] (+: material left)")
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm] (workpiece)")
    ax.set_ylabel("y [mm]")
    ax.set_title(title)
    return save_png(fig, path, dpi=100)


def process_plot(steps, path: Path, title: str) -> str:
    plt = pyplot()
    t = np.asarray(steps.t)
    f = np.linalg.norm(np.asarray(steps.force), axis=1)
    d = np.linalg.norm(np.asarray(steps.deflection), axis=1) / 1e-6
    e = np.linalg.norm(np.asarray(steps.tracking_error), axis=1) / 1e-6
    fig, axs = plt.subplots(3, 1, figsize=(9, 6), sharex=True)
    axs[0].plot(t, f, lw=0.5)
    axs[0].set_ylabel("|F| [N]")
    axs[1].plot(t, d, lw=0.5, color="C1")
    axs[1].set_ylabel("|deflection| [µm]")
    axs[2].plot(t, e, lw=0.5, color="C2")
    axs[2].set_ylabel("|tracking error| [µm]")
    axs[2].set_yscale("log")
    axs[2].set_xlabel("t [s]")
    axs[0].set_title(title)
    return save_png(fig, path, dpi=100)


def switching_plot(xyz, switch, path: Path, title: str) -> str:
    plt = pyplot()
    xyz = np.asarray(xyz)
    sw = np.asarray(switch)
    fig, ax = plt.subplots(figsize=(7, 6))
    ax.plot(xyz[:, 0] / MM, xyz[:, 1] / MM, lw=0.4, color="0.6")
    k = np.nonzero(sw)[0]
    for bit in SwitchAxis:
        sel = k[(sw[k] & bit) != 0]
        if len(sel):
            ax.scatter(xyz[sel, 0] / MM, xyz[sel, 1] / MM, s=10, label=f"{bit.name} ({len(sel)})")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm] (workpiece)")
    ax.set_ylabel("y [mm]")
    ax.set_title(title)
    return save_png(fig, path, dpi=100)


def worst_point(table: FeatureTable, scan, piece: TestPiece) -> tuple[str, str, np.ndarray, float]:
    """(row, scan feature, point (3,) m, deviation m): the worst row's probe point farthest from nominal."""
    row = table.worst
    best = (row.name, "", np.zeros(3), 0.0)
    for name in ROW_SURFACES[row.name]:
        if name not in scan:
            continue
        r = nominal_residuals(name, scan[name], piece)
        k = int(np.argmax(np.abs(r)))
        if abs(r[k]) >= abs(best[3]) or not best[1]:
            best = (row.name, name, scan[name][k], float(r[k]))
    return best


def write_report(ranking: Ranking, out_dir: str | Path, program: str | Path | None = None,
                 trajectories: dict | None = None) -> Path:
    """Write ``report.md`` and its PNGs into ``out_dir`` (pose folders must hold ``workpiece.npz``)."""
    from simulate.machining.virtual_workpiece import VirtualWorkpiece

    out = Path(out_dir)
    img = out / "images"
    img.mkdir(parents=True, exist_ok=True)
    piece = iso_test_piece(ranking.settings.size)
    poses = [p.name for p in ranking.placements]
    md = ["# Pose ranking: ISO 10791-7 test piece", ""]
    md.append(f"Program `{program}`; {len(poses)} poses simulated in {ranking.wall_time:.1f} s; dexel spacing "
              f"{ranking.settings.spacing / MM:g} mm, probe spacing {ranking.settings.probe_spacing / MM:g} mm.")
    md.append("")
    md.append("Score = sum over the ten rows of |deviation| / tolerance (lower is better); ties: more rows in "
              "tolerance.")
    md += [""] + markdown_table(("rank", "pose", "score", "rows in tolerance"),
                                [(e.rank, e.pose, f"{e.score:.2f}", f"{e.in_tolerance}/10") for e in ranking.entries])
    md += ["", "## Table 2: feature deviations [mm]", "",
           f"![table 2]({img.name}/{table2_image(ranking, img / 'table2.png')})", ""]
    rows = ranking.results[poses[0]].table.rows
    table2 = []
    for r in rows:
        vals = []
        for p in poses:
            fr = ranking.results[p].table[r.name]
            s = f"{fr.deviation / MM:+.4f}"
            vals.append(f"**{s}**" if fr.in_tolerance else s)
        table2.append([r.name, r.nominal_text(), f"{r.tolerance / MM:.3f}", *vals])
    md += markdown_table(("feature", "nominal [mm]", "tolerance [mm]", *(f"{p} [mm]" for p in poses)), table2)
    # why the best wins
    best = ranking.best
    md += ["", "## Why the best pose wins", ""]
    bt = ranking.results[best].table
    for e in ranking.entries[1:]:
        ot = ranking.results[e.pose].table
        gains = sorted(((ot[r.name].ratio - r.ratio, r.name) for r in bt.rows), reverse=True)[:3]
        txt = ", ".join(f"{n} ({g:+.2f}{_gain_driver(ranking, best, e.pose, n)})" for g, n in gains)
        md.append(f"- {best} vs {e.pose}: score {bt.score:.2f} vs {e.score:.2f}; largest gains in "
                  f"|deviation|/tolerance: {txt}.")
    if ranking.variants:
        sb = ranking.shares(best).get("score", {})
        md.append(f"- Component shares of {best}'s score: "
                  + ", ".join(f"{c} {100 * sb.get(c, 0.0):.0f}%" for c in COMPONENTS)
                  + "; a gain is attributed to the component whose contribution pushes the other pose's deviation "
                    "furthest from zero compared with the best pose (contribution = deviation with all components "
                    "minus deviation without it).")
    else:
        md.append("- Component shares: re-run with `--shares` to attribute each gain to deflection, friction or "
                  "switching.")
    if ranking.variants:
        md += ["", "## Component shares (re-runs with one component switched off)", ""]
        md.append("Contribution = deviation(all) - deviation(without it), mm; share of the score = "
                  "(score(all) - score(without)) / score(all).")
        for p in poses:
            sh = ranking.shares(p)
            con = ranking.contributions(p)
            if not sh:
                continue
            cells = []
            for r in rows:
                share = sh[r.name]
                drv = max(share, key=share.__getitem__)
                cells.append([r.name, *(f"{con[c][r.name] / MM:+.4f}" for c in con),
                              f"{drv} ({100 * share[drv]:.0f}%)"])
            cells.append(["share of the score", *(f"{100 * sh['score'][c]:.0f}%" for c in con), ""])
            md += ["", f"### {p}", ""] + markdown_table(("feature", *(f"{c} [mm]" for c in con), "driver"), cells)
    md += ["", "## Per pose", ""]
    for p in poses:
        res = ranking.results[p]
        md += [f"### {p} (rank {next(e.rank for e in ranking.entries if e.pose == p)}, score {res.score:.2f})", ""]
        md.append(f"![deviations {p}]({img.name}/"
                  f"{deviation_map(res.scan, piece, img / f'{p}_deviation.png', f'{p}: probe deviations')})")
        if res.steps is not None:
            plot = process_plot(res.steps, img / f"{p}_process.png", f"{p}: force, deflection, tracking error")
            md.append(f"![process {p}]({img.name}/{plot})")
        if trajectories and p in trajectories:
            xyz, sw = trajectories[p]
            md.append(f"![switching {p}]({img.name}/"
                      f"{switching_plot(xyz, sw, img / f'{p}_switching.png', f'{p}: switching points')})")
        row, feat, point, dev = worst_point(res.table, res.scan, piece)
        md += ["", f"Worst feature: **{row}** ({res.table[row].deviation / MM:+.4f} mm, "
                   f"{res.table[row].ratio:.1f} x tolerance); largest probe deviation {dev / 1e-6:+.1f} um on "
                   f"`{feat}` at ({', '.join(f'{v / MM:.2f}' for v in point)}) mm.", ""]
        if res.workpiece_file is not None and Path(res.workpiece_file).exists():
            vw = VirtualWorkpiece.load(res.workpiece_file)
            tr = trace_point(vw, point, radius=max(2 * ranking.settings.spacing, 1.5e-3),
                             program=str(program) if program else None)
            md.append(f"`greybench trace --workpiece {Path(res.workpiece_file).parent} --point "
                      f"{','.join(f'{v / MM:.3f}' for v in point)}` gives {tr.n_ends} dexel ends from these lines:")
            md += [""] + markdown_table(
                ("line", "program", "t [s]", "max deflection [µm]", "max force [N]", "switching axes"),
                [(ln.line, f"`{ln.text}`", f"{ln.t_first:.3f}..{ln.t_last:.3f}", f"{ln.max_deflection / 1e-6:.1f}",
                  f"{ln.max_force:.1f}", ",".join(f"A{a}" for a in axes_of(ln.switching)) or "-")
                 for ln in tr.lines[:8]])
        md.append("")
    path = out / "report.md"
    with atomic_file(path) as tmp:
        tmp.write_text("\n".join(md) + "\n", encoding="utf-8")
    summary = ranking_json(ranking)   # what `rank-poses --json` prints: unit-named fields
    write_text_atomic(out / "ranking.json", json.dumps(summary, indent=1))
    return path
