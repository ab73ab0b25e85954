"""The files of a placement search: ``best.json``, ``report.md``, ``history.csv`` and ``heatmap.png``.

- ``best.json``: the given pose file unchanged plus the best placement found (when it is not a given
  pose), a pose file ``rank-poses`` reads;
- ``report.md``: the search (settings, stop reason, history), the best placement against every
  given pose per Table-2 row, which rows make it better and which error component (deflection or
  servo tracking) changed;
- ``history.csv``: one row per candidate (unit-named columns);
- ``heatmap.png``: the score over x-y of the base frame at the best yaw and z. Simulating a grid is
  far beyond any budget, so the map shows the *predicted* score of a least-squares fit of the
  simulated scores on the screen's two proxies (switching points, compliance), evaluated by the
  screen at each grid point; placements that fail the screen are grey, the given poses and the best
  are marked. With fewer than four simulated candidates it shows the compliance proxy instead.

Everything is computed (the heat map drawn) before the first file is written, and each file is
written atomically: a failure leaves ``out_dir`` as it was, other files in it are kept.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from identify.files import atomic_file
from identify.records import markdown_table, write_table
from simulate.figures import pyplot, save_png
from simulate.placement.screen import screen
from simulate.placement.search import CandidateStatus, SearchResult

MM = 1e-3
UM = 1e-6
#: Grid points per axis of the heat map [-].
HEATMAP_GRID = 15
#: Name of the best placement in ``best.json`` (made unique against the given names).
BEST_NAME = "optimised"


def best_name(result: SearchResult) -> str:
    """The best placement's name in ``best.json``: a given pose keeps its name."""
    b = result.best
    if b.origin == "given":
        return b.name
    taken = {c.name for c in result.given}
    name, k = BEST_NAME, 2
    while name in taken:
        name, k = f"{BEST_NAME}_{k}", k + 1
    return name


def best_document(result: SearchResult, given_doc: dict) -> dict:
    """The given pose document unchanged plus the best placement (when it is not a given pose)."""
    doc = json.loads(json.dumps(given_doc))
    b = result.best
    if b.origin != "given":
        doc["poses"].append({"name": best_name(result), "xyz": [float(v) for v in b.placement.xyz],
                             "rpy": [float(v) for v in b.placement.rpy],
                             "description": f"found by greybench optimize-pose (seed {result.settings.seed}): "
                                            f"score {b.score:.4f}, {100 * result.improvement:.2f} % below the best "
                                            f"given pose '{result.best_given.name}'"})
    return doc


def summary(result: SearchResult) -> dict:
    """The ``--json`` object: the best pose, its score, every given pose's score, the improvement."""
    b, g = result.best, result.best_given
    counts = {s.value: sum(c.status is s for c in result.candidates) for s in CandidateStatus}
    return {"best": {"name": best_name(result), "candidate": b.name, "origin": b.origin,
                     "xyz_m": [float(v) for v in b.placement.xyz], "rpy_rad": [float(v) for v in b.placement.rpy],
                     "score": b.score, "in_tolerance": b.in_tolerance},
            "given": [{"name": c.name, "score": c.score, "in_tolerance": c.in_tolerance} for c in result.given],
            "best_given": g.name, "improvement": result.improvement, "score_reduction": g.score - b.score,
            "candidates": counts, "wall_time_s": result.wall_time, "budget_s": result.settings.budget_s,
            "stop_reason": result.stop_reason, "backend": result.backend, "seed": result.settings.seed}


def history_table(result: SearchResult) -> pd.DataFrame:
    rows = []
    for c in result.candidates:
        s = c.screen
        rows.append({"index": c.index, "name": c.name, "origin": c.origin, "status": c.status.value,
                     "x_mm": c.placement.xyz[0] / MM, "y_mm": c.placement.xyz[1] / MM,
                     "z_mm": c.placement.xyz[2] / MM, "yaw_deg": math.degrees(c.placement.rpy[2]),
                     "score": c.score, "predicted_score": c.predicted, "in_tolerance": c.in_tolerance,
                     "switching_points": s.switching, "compliance_um_per_n": s.compliance / UM,
                     "limit_margin_deg": math.degrees(s.limit_margin), "wrist_deg": math.degrees(s.wrist_angle),
                     "rms_deflection_um": c.stats.get("rms_deflection_m", math.nan) / UM,
                     "rms_tracking_error_um": c.stats.get("rms_tracking_error_m", math.nan) / UM,
                     "started_s": c.started_s, "wall_s": c.wall_s, "message": c.message})
    return pd.DataFrame(rows)


def _surrogate(result: SearchResult):
    """Least-squares ``score ~ a + b switching + c compliance`` over the simulated candidates, or None."""
    sims = [c for c in result.simulated if math.isfinite(c.score) and math.isfinite(c.screen.compliance)]
    if len(sims) < 4:
        return None
    A = np.array([[1.0, c.screen.switching, c.screen.compliance / UM] for c in sims])
    y = np.array([c.score for c in sims])
    if np.linalg.matrix_rank(A) < 3:
        return None
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    pred = A @ coef
    r2 = 1 - float(np.sum((y - pred) ** 2) / max(np.sum((y - y.mean()) ** 2), 1e-300))
    return coef, r2, len(sims)


def heatmap(result: SearchResult, robot, interp, grid: int = HEATMAP_GRID, source: str = "") -> tuple[Any, dict]:
    """Draw the heat map (module docstring): the figure (for :func:`simulate.figures.save_png`) and what
    it shows."""
    plt = pyplot()
    sp, b, st = result.space, result.best, result.settings
    xs = np.linspace(*sp.x, grid)
    ys = np.linspace(*sp.y, grid)
    params = {"z_m": float(b.placement.xyz[2]), "yaw_rad": float(b.placement.rpy[2])}
    sw = np.full((grid, grid), np.nan)
    comp = np.full((grid, grid), np.nan)
    for i, y in enumerate(ys):
        for j, x in enumerate(xs):
            res = screen(robot, interp, sp.placement("map", dict(params, x_m=x, y_m=y)), limit_margin=st.limit_margin,
                         wrist_margin=st.wrist_margin, source=source)
            if res.ok:
                sw[i, j], comp[i, j] = res.switching, res.compliance / UM
    fit = _surrogate(result)
    if fit is not None:
        coef, r2, n = fit
        value = coef[0] + coef[1] * sw + coef[2] * comp
        label = f"predicted score [-] (fit R² {r2:.2f}, {n} simulations)"
        what = (f"predicted score: least-squares fit on switching points and compliance of {n} simulations "
                f"(R² {r2:.2f})")
    else:
        value = comp
        label = "compliance, largest eigenvalue, path mean [µm/N]"
        what = "compliance proxy (fewer than four simulations to fit a score prediction)"
    fig, ax = plt.subplots(figsize=(7.5, 6.0))
    cmap = plt.get_cmap("viridis").with_extremes(bad="lightgrey")
    X, Y = np.meshgrid(xs / MM, ys / MM)
    m = ax.pcolormesh(X, Y, np.ma.masked_invalid(value), cmap=cmap, shading="nearest")
    fig.colorbar(m, ax=ax, label=label)
    for c in result.simulated:
        if c.origin != "given":
            ax.plot(c.placement.xyz[0] / MM, c.placement.xyz[1] / MM, ".", color="black", ms=4)
    for c in result.given:
        ax.plot(c.placement.xyz[0] / MM, c.placement.xyz[1] / MM, "o", mfc="white", mec="black", ms=8)
        ax.annotate(f"{c.name} ({c.score:.2f})", (c.placement.xyz[0] / MM, c.placement.xyz[1] / MM),
                    textcoords="offset points", xytext=(6, 6), fontsize=8,
                    bbox=dict(boxstyle="round", fc="white", alpha=0.7))
    ax.plot(b.placement.xyz[0] / MM, b.placement.xyz[1] / MM, "*", color="red", mec="black", ms=16)
    ax.annotate(f"best ({b.score:.2f})", (b.placement.xyz[0] / MM, b.placement.xyz[1] / MM),
                textcoords="offset points", xytext=(8, -12), fontsize=8, color="darkred",
                bbox=dict(boxstyle="round", fc="white", alpha=0.7))
    ax.set_xlabel("workpiece origin x, robot base frame [mm]")
    ax.set_ylabel("workpiece origin y, robot base frame [mm]")
    ax.set_title(f"yaw {math.degrees(params['yaw_rad']):.1f} deg, z {params['z_m'] / MM:.0f} mm; grey: fails the "
                 f"screen\nwhite: given poses, red star: best, dots: other simulations (their own yaw and z)",
                 fontsize=9)
    ax.set_aspect("equal")
    return fig, {"shows": what, "feasible_cells": int(np.isfinite(comp).sum()), "cells": grid * grid}


def _f(v: float, fmt: str = ".3f") -> str:
    return format(v, fmt) if isinstance(v, (int, float)) and math.isfinite(v) else "-"


def report_text(result: SearchResult, *, program: str, robot: str, poses: str, size: int, heat: dict) -> str:
    b, g = result.best, result.best_given
    st = result.settings
    name = best_name(result)
    counts = summary(result)["candidates"]
    lines = [f"# Placement search: {Path(program).name} with {Path(robot).stem}", ""]
    lines += [f"Budget {st.budget_s:g} s on {st.workers} workers ({result.backend}), seed {st.seed}, dexel spacing "
              f"{st.rank.spacing / MM:g} mm; searched x {sp_range(result.space.x)}, y {sp_range(result.space.y)}, "
              f"z {sp_range(result.space.z)} mm, every yaw; roll/pitch "
              f"{math.degrees(result.space.roll):.1f}/{math.degrees(result.space.pitch):.1f} deg. "
              f"Stopped: {result.stop_reason} after {result.wall_time:.0f} s. Candidates: "
              + ", ".join(f"{v} {k}" for k, v in counts.items() if v) + ".", ""]
    if b.origin == "given":
        lines += [f"**No placement beat the given poses**: the best is the given pose `{b.name}` "
                  f"(score {b.score:.4f}); `best.json` holds the given poses unchanged.", ""]
    else:
        lines += [f"**Best: `{name}`** at x {b.placement.xyz[0] / MM:.1f}, y {b.placement.xyz[1] / MM:.1f}, "
                  f"z {b.placement.xyz[2] / MM:.1f} mm, yaw {math.degrees(b.placement.rpy[2]):.1f} deg: score "
                  f"**{b.score:.4f}** against {g.score:.4f} of the best given pose `{g.name}` "
                  f"(**{100 * result.improvement:.2f} %** lower), {b.in_tolerance}/10 rows in tolerance "
                  f"({g.in_tolerance}/10).", ""]
    edges = [f"{ax} {'lower' if v - lo < hi - v else 'upper'}" for ax, v, (lo, hi) in
             zip("xyz", b.placement.xyz, (result.space.x, result.space.y, result.space.z), strict=True)
             if min(v - lo, hi - v) < 0.02 * (hi - lo)]
    if b.origin != "given" and edges:
        lines += [f"The best lies at the edge of the searched box ({', '.join(edges)}): a wider box "
                  f"(`--xy-margin-mm`, `--z-margin-mm`) may hold a better placement.", ""]
    lines += ["Check it (the same simulation, so the same scores):", "", "```",
              f"greybench rank-poses --program {program} --robot {robot} --poses best.json --size {size} "
              f"--spacing {st.rank.spacing / MM:g}", "```", ""]
    # per Table-2 row: best vs every given pose
    given = result.given
    cols = ([f"`{name}`"] if b.origin != "given" else []) + [f"`{c.name}`" for c in given]
    gr = {r["name"]: r for r in g.rows}
    changes, cells = [], []
    for k, r in enumerate(b.rows):
        vals = ([r["deviation_m"]] if b.origin != "given" else []) + [c.rows[k]["deviation_m"] for c in given]
        d = (abs(r["deviation_m"]) - abs(gr[r["name"]]["deviation_m"])) / r["tolerance_m"]
        changes.append((d, r["name"]))
        cells.append([r["name"], f"{r['tolerance_m'] / MM:.3f}", *(f"{v / MM:+.4f}" for v in vals), f"{d:+.3f}"])
    lines += ["## Table-2 rows [mm]: best against the given poses", ""]
    lines += markdown_table(("row", "tolerance", *cols, "change of abs(dev)/tol (best vs best given)"), cells)
    lines.append("")
    better = sorted([c for c in changes if c[0] < 0])
    worse = sorted([c for c in changes if c[0] > 0], reverse=True)
    if b.origin != "given":
        lines += ["**Why it is better**: the score is the sum of |deviation|/tolerance; it drops most on "
                  + ", ".join(f"{n} ({d:+.3f})" for d, n in better[:3]) + "."
                  + (" It rises on " + ", ".join(f"{n} ({d:+.3f})" for d, n in worse[:3]) + "." if worse else ""),
                  ""]
        bd, gd = b.stats.get("rms_deflection_m", math.nan), g.stats.get("rms_deflection_m", math.nan)
        bt, gt = b.stats.get("rms_tracking_error_m", math.nan), g.stats.get("rms_tracking_error_m", math.nan)
        comp = "deflection" if abs(bd - gd) >= abs(bt - gt) else "servo tracking (friction, backlash)"
        lines += markdown_table(("component along the cut", "best", "best given"), [
            ("RMS deflection [µm]", _f(bd / UM, ".2f"), _f(gd / UM, ".2f")),
            ("RMS servo tracking error [µm]", _f(bt / UM, ".2f"), _f(gt / UM, ".2f")),
            ("switching points [-]", b.screen.switching, g.screen.switching),
            ("compliance, path mean [µm/N]", _f(b.screen.compliance / UM), _f(g.screen.compliance / UM)),
            ("smallest joint-limit margin [deg]", _f(math.degrees(b.screen.limit_margin), ".1f"),
             _f(math.degrees(g.screen.limit_margin), ".1f")),
            ("smallest wrist angle from singular [deg]", _f(math.degrees(b.screen.wrist_angle), ".1f"),
             _f(math.degrees(g.screen.wrist_angle), ".1f"))])
        lines += ["",
                  f"The component that changed most is the **{comp}**. (Component shares by switching each off: "
                  f"`rank-poses --shares` on `best.json`.)", ""]
    lines += ["## Heat map", "", "![score over x-y](heatmap.png)", "",
              f"{heat['shows']}; {heat['feasible_cells']} of {heat['cells']} grid placements pass the screen.", ""]
    n_skip = counts.get("skipped", 0)
    lines += ["## Search history", "", f"The candidates in the order drawn, the skipped ones left out here ({n_skip} "
              "dominated on both proxies; `history.csv` has every candidate and column).", ""]
    history = []
    for c in result.candidates:
        if c.status is CandidateStatus.skipped:
            continue
        sc = _f(c.score, ".4f") if c.status is CandidateStatus.simulated else "-"
        history.append((c.index, c.name, c.status.value, f"{c.placement.xyz[0] / MM:.1f}",
                        f"{c.placement.xyz[1] / MM:.1f}", f"{c.placement.xyz[2] / MM:.1f}",
                        f"{math.degrees(c.placement.rpy[2]):.1f}", sc,
                        c.screen.switching if c.screen.switching >= 0 else "-", _f(c.screen.compliance / UM),
                        c.message[:120]))
    lines += markdown_table(("#", "name", "status", "x [mm]", "y [mm]", "z [mm]", "yaw [deg]", "score", "switching",
                             "compliance [µm/N]", "note"), history)
    lines += ["", "Method: `docs/placement-search.md`.", ""]
    return "\n".join(lines)


def sp_range(r: tuple) -> str:
    return f"{r[0] / MM:.0f}..{r[1] / MM:.0f}"


def write_outputs(result: SearchResult, out_dir: str | Path, *, given_doc: dict, robot, interp, program: str,
                  robot_name: str, poses: str, size: int) -> dict:
    """Write every file (module docstring) into ``out_dir``; returns :func:`summary` with the file names."""
    out_dir = Path(out_dir)
    fig, heat = heatmap(result, robot, interp, source=program)
    try:
        history = history_table(result)
        info = summary(result)
        info["heatmap"] = heat["shows"]
        texts = {"best.json": json.dumps(best_document(result, given_doc), indent=1) + "\n",
                 "report.md": report_text(result, program=program, robot=robot_name, poses=poses, size=size,
                                          heat=heat),
                 "summary.json": json.dumps(finite(info), indent=1) + "\n"}
    except BaseException:
        pyplot().close(fig)
        raise
    save_png(fig, out_dir / "heatmap.png", dpi=110)
    write_table(history, out_dir / "history.csv")
    for name, text in texts.items():
        with atomic_file(out_dir / name) as tmp:
            tmp.write_text(text, encoding="utf-8")
    info["files"] = [str(out_dir / f) for f in sorted(["heatmap.png", "history.csv", *texts])]
    return info


def finite(obj):
    """``obj`` with NaN and infinities as None (JSON has neither)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    return obj
