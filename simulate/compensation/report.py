"""Outputs of a compensation (:mod:`simulate.compensation`): the corrected program, its stock, the
offset and feed-forward tables, a markdown report and a figure, written all or nothing.

Files in the output folder:

- ``compensated.nc``: the corrected program (same F and S words, same lines, feed lines split);
- ``compensated.stock.json``: a copy of the original stock (so ``rank-poses`` finds it beside it);
- ``offsets.csv``: one row per 2 ms cycle of the *original* program, as a controller's offset table
  would take it: ``t_s, line, dx_mm, dy_mm, dz_mm`` (the correction in the workpiece frame) and
  ``dq1_rad .. dq6_rad`` (the joint offsets that realise it with the tool orientation kept, from the
  inverse kinematics of the corrected points minus that of the nominal points);
- ``feedforward.csv``: one row per cycle of the *compensated* program: ``t_s, line`` and
  ``tau_f1_Nm .. tau_f6_Nm``, the friction each joint's model predicts along the commanded joints,
  the torque the NC's friction feed-forward adds (``--ff-friction`` runs the programs with it);
- ``report.md`` and ``deviation.png`` (normal deviation along the path before and after).

``summary.json`` and the report also list the gears the corrected program leaves rattling in their
play (:mod:`simulate.evaluation.gear_play`): per line of the original program and joint, flank changes
before and after; no path correction holds such a gear on a flank.
"""
from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from identify.files import atomic_files
from identify.records import markdown_table, write_table
from simulate.compensation.iterate import CompensationResult, worse_rows
from simulate.compensation.measure import table_sum
from simulate.compensation.settings import MAX_OFFSET, TIME_RATIO
from simulate.evaluation.gear_play import RATTLE_RATE, gear_play, rattling_gears
from simulate.figures import save_png

UM = 1e-6


def evaluation(result: CompensationResult, scale: float = 1.0) -> tuple:
    """(original, compensated) runs at a stiffness scale: the iteration's own at 1."""
    if scale == 1.0 or scale not in result.checks:
        return result.before, result.after
    return result.checks[scale]


def summary(result: CompensationResult, scale: float = 1.0) -> dict:
    """The ``--json`` object: Table-2 sums [mm] before/after at ``scale`` and at every check scale,
    their ratio, rows worse than allowed, the iterations and the contract figures."""
    def pair(sc):
        b, a = evaluation(result, sc)
        if b.table is None or a.table is None:
            return None
        sb, sa = table_sum(b.table), table_sum(a.table)
        return {"stiffness_scale": sc, "sum_before_mm": sb / 1e-3, "sum_after_mm": sa / 1e-3,
                "ratio": sa / sb if sb > 0 else None, "score_before": b.table.score, "score_after": a.table.score,
                "rows_worse": worse_rows(b.table, a.table),
                "rows_mm": [{"name": rb.name, "tolerance": rb.tolerance / 1e-3, "before": rb.deviation / 1e-3,
                             "after": ra.deviation / 1e-3} for rb, ra in zip(b.table.rows, a.table.rows, strict=True)]}

    best = result.iterations[result.best]
    return {"evaluation": pair(scale), "gears_rattling": gears_rattling(result),
            "checks": [pair(sc) for sc in sorted(result.checks) if sc != scale],
            "best_iteration": result.best,
            "iterations": [{"index": it.index, "table_sum_mm": None if it.table_sum is None else it.table_sum / 1e-3,
                            "score": it.score, "path_rms_um": it.path_rms / UM, "path_max_um": it.path_max / UM,
                            "max_offset_um": it.max_offset / UM, "time_ratio": it.time_ratio,
                            "speed_ratio": it.speed_ratio, "pieces": it.pieces, "wall_time_s": it.wall_time,
                            "rows_worse": it.rows_worse,
                            "composed": _composed(result, it)}
                           for it in result.iterations],
            "max_offset_mm": best.max_offset / 1e-3, "time_ratio": best.time_ratio, "speed_ratio": best.speed_ratio}


#: What the list of gears left rattling means (the report and the job page).
RATTLE_NOTE = (
    "Lines of the original program (the corrected pieces counted on the line they were split from) "
    f"where a joint's gear rattles after the correction (at least {RATTLE_RATE:g} flank changes a "
    "second and 1.5 times as many as before). A gear rattles where the torque it carries stays near "
    "zero: mostly where the corrected cut's process torque about the joint nearly cancels its "
    "friction (the link then leaves the flank and comes back many times a second and the tool "
    "rattles by up to the play times the lever), or where the NC functions move a nearly still "
    "joint's setpoint back and forth. No correction of the path holds such a gear on a flank (the "
    "corrected cut is the nominal one); another placement or the other milling direction loads it. "
    "A row of such a feature that got worse after the correction most likely got worse by it.")


def gears_rattling(result: CompensationResult) -> list[dict]:
    """Lines of the original program and joints whose gear rattles in the compensated program and did
    not in the original (:func:`simulate.evaluation.gear_play.rattling_gears`), at the model's stiffness:
    ``section, line, text, joint, flank_changes_before, flank_changes_after, in_play_before, in_play_after``
    (shares of the line's 2 ms cycles [-]); the compensated program's pieces are counted on the
    original line they were split from. Empty where the runs have no drive states."""
    b, a = result.before, result.after
    if b.contact is None or a.contact is None or b.trajectory is None or a.trajectory is None:
        return []
    segs = result.path.segments
    # each piece of the corrected program on the original line it was split from; other lines left out
    a_line = np.asarray(a.trajectory.line, np.int64)
    to_original = np.full(max(int(a_line.max(initial=0)), max(result.program.pieces, default=0)) + 1, -1, np.int64)
    for out, (i, _ua, _ub) in result.program.pieces.items():
        to_original[out] = segs[i].line
    a_lines = to_original[np.clip(a_line, 0, None)]
    text = result.path.text
    pairs = rattling_gears(gear_play(text, b.trajectory.line, b.contact, per_line=True),
                           gear_play(text, a_lines, a.contact, per_line=True))
    src = text.splitlines()
    return [{"section": af.section, "line": af.line, "text": src[af.line - 1].strip() if af.line else "",
             "joint": af.joint, "flank_changes_before": None if bf is None else bf.flank_changes,
             "flank_changes_after": af.flank_changes, "in_play_before": None if bf is None else bf.in_play,
             "in_play_after": af.in_play} for bf, af in pairs]


def offsets_table(result: CompensationResult, robot, placement) -> pd.DataFrame:
    """Per cycle of the original program: t_s, line, dx_mm, dy_mm, dz_mm, dq1_rad..dq6_rad."""
    from simulate.toolpath.placement import joint_trajectory

    path = result.path
    it = path.setup.interp
    c = result.correction.on_cycles(path)
    cols = {"t_s": it.t, "line": it.line, "dx_mm": c[:, 0] / 1e-3, "dy_mm": c[:, 1] / 1e-3, "dz_mm": c[:, 2] / 1e-3}
    q0 = result.before.trajectory.q if result.before.trajectory is not None else None
    if q0 is not None and robot is not None:
        jt = joint_trajectory(robot, replace(it, xyz=it.xyz + c), placement, source=path.setup.source,
                              check_speed=False)
        dq = (jt.q - q0 + np.pi) % (2 * np.pi) - np.pi
        for j in range(6):
            cols[f"dq{j + 1}_rad"] = dq[:, j]
    return pd.DataFrame(cols)


def feedforward_table(result: CompensationResult, robot) -> pd.DataFrame:
    """Per cycle of the compensated program: t_s, line, tau_f1_Nm..tau_f6_Nm, the friction [Nm] each
    joint's model predicts along the commanded joints (:func:`simulate.robot.drive.nc_friction`, the
    model's own dynamics; the steady curve at a held speed): what the NC's friction feed-forward
    (``--ff-friction``, :data:`simulate.robot.drive.DriveFlags.FF_FRICTION`) adds to the motor torque
    when it runs the compensated program (the drive interpolates it linearly within a cycle)."""
    from simulate.robot.drive import DriveFlags, command_velocity, drive_friction, load_torques, nc_friction

    jt = result.after.trajectory
    assert jt is not None  # the pipeline simulator records every run's joints
    t, q = np.asarray(jt.t, float), np.asarray(jt.q, float)
    v = command_velocity(t, q)
    a = command_velocity(t, v)
    model, jl = load_torques(robot, q, v, a)
    ff = nc_friction(drive_friction(robot), t, q, v, model + jl * a, int(DriveFlags.FF_FRICTION))
    cols = {"t_s": jt.t, "line": jt.line}
    for j in range(6):
        cols[f"tau_f{j + 1}_Nm"] = ff[:, j]
    return pd.DataFrame(cols)


def plot(result: CompensationResult, path: Path) -> None:
    """Normal deviation of the tool from the nominal path before and after, and the correction."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 4.2))
    x0 = 0.0
    for r, g in enumerate(result.path.runs and result.deviation_before.grids):
        x = x0 + (g - g[0]) / 1e-3
        b = np.linalg.norm(result.deviation_before.values[r], axis=1) / UM
        a = np.linalg.norm(result.deviation_after.values[r], axis=1) / UM
        c = np.linalg.norm(result.correction.values[r], axis=1) / UM
        ax.plot(x, b, color="tab:red", lw=0.8, label="before" if r == 0 else None)
        ax.plot(x, a, color="tab:green", lw=0.8, label="after" if r == 0 else None)
        ax.plot(x, c, color="tab:blue", lw=0.6, ls="--", label="correction |dx|" if r == 0 else None)
        if r:
            ax.axvline(x0, color="0.7", lw=0.5)
        x0 = x[-1] + 5.0
    ax.set_xlabel("path length along the feed moves [mm] (grey: a rapid between runs)")
    ax.set_ylabel("normal deviation from the nominal path [µm]")
    ax.set_title("Tool deviation from the nominal path (deflection + tracking error), before and after compensation")
    ax.legend(loc="upper right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, path, dpi=110)


def _ratio(r: float | None) -> str:
    """A sum ratio for the report; ``-`` where the original's sum was 0 (no ratio)."""
    return "-" if r is None else f"{r:.3f}"


def _or_dash(v: float | None, scale: float | None = None) -> str:
    """A count as it is, a share times ``scale`` to whole numbers; ``-`` for None."""
    if v is None:
        return "-"
    return f"{v * scale:.0f}" if scale is not None else str(v)


def report_text(result: CompensationResult, info: dict, title: str, scale: float) -> str:
    ev = info["evaluation"]
    lines = [f"# Compensation: {title}", ""]
    lines += ["Mirror compensation from the machining simulation, iterated (simulate/compensation/, "
              "docs/compensation.md). Deviations: ISO 10791-7 Table-2 rows of the virtual CMM, µm.", ""]
    if ev is not None:
        lines += [f"## Table 2 before / after (robot stiffness x{scale:g} against the model)", ""]
        lines += markdown_table(
            ("row", "tol [µm]", "before [µm]", "after [µm]", "after/before"),
            [(r["name"], f"{r['tolerance'] * 1e3:.0f}", f"{r['before'] * 1e3:+.1f}", f"{r['after'] * 1e3:+.1f}",
              f"{abs(r['after']) / abs(r['before']) if r['before'] else float('nan'):.2f}") for r in ev["rows_mm"]])
        lines += ["", f"Sum of |deviation|: before {ev['sum_before_mm'] * 1e3:.1f} µm, after "
                      f"{ev['sum_after_mm'] * 1e3:.1f} µm, **ratio {_ratio(ev['ratio'])}**; score "
                      f"{ev['score_before']:.2f} -> {ev['score_after']:.2f}. Rows worse than before by more than "
                      f"max(10 %, 2 µm): {', '.join(ev['rows_worse']) or 'none'}.", ""]
    checks = [c for c in info["checks"] if c is not None]   # None: no Table-2 rows (not a test-piece stock)
    if checks:
        lines += ["## Robustness: the robot stiffer or softer than the compensating model", ""]
        lines += markdown_table(
            ("stiffness scale", "sum before [µm]", "sum after [µm]", "ratio", "rows worse"),
            [(f"{c['stiffness_scale']:g}", f"{c['sum_before_mm'] * 1e3:.1f}", f"{c['sum_after_mm'] * 1e3:.1f}",
              _ratio(c["ratio"]), ", ".join(c["rows_worse"]) or "none") for c in checks])
        lines.append("")
    rattling = info.get("gears_rattling") or []
    if rattling:
        lines += ["## Gears left rattling in their play", "", RATTLE_NOTE, ""]
        lines += markdown_table(
            ("program section", "line", "joint", "flank changes before", "after", "in the play before [%]",
             "after [%]"),
            [(g["section"], f"{g['line']}: `{g['text']}`", f"A{g['joint']}", _or_dash(g["flank_changes_before"]),
              g["flank_changes_after"], _or_dash(g["in_play_before"], 100.0), _or_dash(g["in_play_after"], 100.0))
             for g in rattling])
        lines.append("")
    lines += ["## Iterations (model stiffness)", ""]
    lines += markdown_table(
        ("iteration", "sum of abs. deviation [µm]", "score", "rows worse", "path RMS [µm]", "path max [µm]",
         "max offset [µm]", "time ratio", "peak speed ratio", "pieces", "wall [s]"),
        [(f"{it['index']}{_composed_label(it.get('composed'))}"
          f"{' (chosen)' if it['index'] == info['best_iteration'] else ''}",
          "-" if it["table_sum_mm"] is None else f"{it['table_sum_mm'] * 1e3:.1f}",
          "-" if it["score"] is None else f"{it['score']:.2f}",
          "-" if it["rows_worse"] is None else it["rows_worse"], f"{it['path_rms_um']:.1f}",
          f"{it['path_max_um']:.1f}", f"{it['max_offset_um']:.1f}", f"{it['time_ratio']:.3f}",
          f"{it['speed_ratio']:.3f}", it["pieces"], f"{it['wall_time_s']:.1f}") for it in info["iterations"]])
    lines += ["", "## The corrected program", "",
              f"- largest offset from the nominal path {info['max_offset_mm'] * 1e3:.1f} µm "
              f"(contract <= {MAX_OFFSET * 1e3:g} mm);",
              f"- program time {info['time_ratio']:.3f} x the original's (contract {TIME_RATIO[0]}-{TIME_RATIO[1]});",
              f"- peak path speed {info['speed_ratio']:.3f} x the original's (contract <= 1);",
              "- same F and S words; feed lines split into pieces of the same kind whose end points carry the "
              "correction.", "",
              "Files: `compensated.nc`, `compensated.stock.json` (the original stock), `offsets.csv` (per 2 ms cycle "
              "of the original program: correction in mm, joint offsets in rad), `feedforward.csv` (per cycle of the "
              "compensated program: friction torque per joint in Nm), `deviation.png`.", "",
              "![deviation](deviation.png)", ""]
    return "\n".join(lines)


def _composed(result: CompensationResult, it) -> list | None:
    """For the program composed per feature group: per feed run its original program lines (first,
    last) and the iteration whose correction it carries (0: none)."""
    if it.composed is None:
        return None
    path = result.path
    out = []
    for r, k in sorted(it.composed.items()):
        lines = [int(seg.line) for i, seg in enumerate(path.segments) if path.run[i] == r]
        out.append({"lines": [min(lines), max(lines)], "iteration": int(k)})
    return out


def _composed_label(composed: list | None) -> str:
    """' (per feature: lines 11-21 from 3, lines 49-64 uncorrected, ...)' for the composed program."""
    if not composed:
        return ""
    parts = [f"lines {c['lines'][0]}-{c['lines'][1]} " + (f"from {c['iteration']}" if c["iteration"] else "uncorrected")
             for c in composed]
    return f" (per feature: {', '.join(parts)})"


def write_outputs(result: CompensationResult, out_dir: Path, *, robot, placement, title: str,
                  scale: float = 1.0, ff_friction: bool = False, backlash_comp: bool = False) -> dict:
    """Write every file (module docstring) into ``out_dir``: staged in a temporary folder and moved
    in only when all succeeded. Returns the summary (:func:`summary`) with the file paths,
    ``ff_friction`` and ``backlash_comp`` (the NC functions the programs were simulated with)."""
    out_dir = Path(out_dir)
    with atomic_files(out_dir) as tmp:
        info = summary(result, scale)
        info["ff_friction"] = bool(ff_friction)
        info["backlash_comp"] = bool(backlash_comp)
        (tmp / "compensated.nc").write_text(result.program.text, encoding="utf-8")
        assert result.path.setup.stock is not None  # load_program refuses a program without its stock
        shutil.copyfile(result.path.setup.stock, tmp / "compensated.stock.json")
        write_table(offsets_table(result, robot, placement), tmp / "offsets.csv")
        write_table(feedforward_table(result, robot), tmp / "feedforward.csv")
        plot(result, tmp / "deviation.png")
        (tmp / "report.md").write_text(report_text(result, info, title, scale), encoding="utf-8")
        (tmp / "summary.json").write_text(json.dumps(info, indent=1), encoding="utf-8")
        names = sorted(f.name for f in tmp.iterdir())
    info["files"] = [str(out_dir / n) for n in names]
    return info
