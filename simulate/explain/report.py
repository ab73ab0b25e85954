"""Report of an explanation: measured vs simulated deviations side by side, before and after calibration.

``report.md`` in the output folder with PNGs (matplotlib, Agg): a polar roundness plot of the circle
wall (measured, simulated before, simulated after calibration; deviations magnified around the nominal
circle), straightness plots of every straight feature (deviation along the feature), the discrepancy
against time with the switching points, the cause ranking, the signatures and the RMS per feature
before and after. The gain is the re-simulated one (:mod:`simulate.explain.pipeline`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from identify.files import atomic_file
from identify.records import markdown_table
from simulate.figures import pyplot, save_png

UM = 1e6


def roundness_plot(ex, path: Path) -> str | None:
    """Polar plot of the circle wall: measured vs simulated before and after (deviation in um)."""
    b, a = ex.before, ex.after
    m = b.feature == "circle_wall"
    if m.sum() < 8:
        return None
    plt = pyplot()
    c = np.asarray(ex.setup.piece.circle_center)
    fig, axs = plt.subplots(1, 2, subplot_kw={"projection": "polar"}, figsize=(11, 5))
    phi = np.arctan2(b.points[m, 1] - c[1], b.points[m, 0] - c[0])
    o = np.argsort(phi)
    ma = a.feature == "circle_wall"
    phia = np.arctan2(a.points[ma, 1] - c[1], a.points[ma, 0] - c[0])
    oa = np.argsort(phia)
    allv = np.concatenate([b.measured[m], b.simulated[m], a.simulated[ma]]) * UM
    base = max(10.0, 1.5 * float(np.max(np.abs(allv)))) if len(allv) else 10.0
    for ax, (title, ph, sim, oo) in zip(axs, (("before calibration", phi, b.simulated[m], o),
                                               ("after calibration", phia, a.simulated[ma], oa)), strict=True):
        ax.plot(phi[o], base + b.measured[m][o] * UM, "k.", ms=2, label="measured")
        ax.plot(ph[oo], base + sim[oo] * UM, "-", color="tab:red", lw=1, label="simulated")
        ax.plot(np.linspace(0, 2 * np.pi, 200), np.full(200, base), ":", color="grey", lw=0.8, label="nominal")
        ax.set_title(f"circle wall, {title}\n(radius axis: {base:.0f} µm + deviation [µm])", fontsize=9)
        ax.set_rlim(0, base + float(np.max(np.abs(allv))) * 1.1 + 1)
        ax.legend(fontsize=7, loc="lower left")
    return save_png(fig, path, dpi=110)


def _along(points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Coordinate along a straight feature [m]: the principal direction of its points."""
    p = points - points.mean(axis=0)
    if len(p) < 2:
        return np.zeros(len(p))
    _, _, vt = np.linalg.svd(p, full_matrices=False)
    d = vt[0]
    if d[np.argmax(np.abs(d))] < 0:
        d = -d
    return p @ d


def straightness_plot(ex, path: Path) -> str | None:
    """One panel per straight feature: deviation along it, measured and simulated, before and after."""
    b, a = ex.before, ex.after
    feats = [f for f in b.features() if f != "circle_wall"]
    if not feats:
        return None
    plt = pyplot()
    n = len(feats)
    fig, axs = plt.subplots(n, 1, figsize=(9, 1.9 * n + 0.6), squeeze=False)
    for ax, f in zip(axs[:, 0], feats, strict=True):
        m = b.feature == f
        s = _along(b.points[m], b.normals[m][0])
        o = np.argsort(s)
        ma = a.feature == f
        sa = _along(a.points[ma], a.normals[ma][0]) if ma.any() else s
        oa = np.argsort(sa)
        ax.plot(s[o] * 1e3, b.measured[m][o] * UM, "k.", ms=2, label="measured")
        ax.plot(s[o] * 1e3, b.simulated[m][o] * UM, "-", color="tab:red", lw=1, label="simulated before")
        if ma.any():
            ax.plot(sa[oa] * 1e3, a.simulated[ma][oa] * UM, "-", color="tab:green", lw=1, label="simulated after")
        ax.set_ylabel(f"{f}\n[µm]", fontsize=7)
        ax.tick_params(labelsize=7)
    axs[0, 0].legend(fontsize=7, ncol=3)
    axs[-1, 0].set_xlabel("position along the feature [mm]")
    fig.suptitle("straightness: deviation from the nominal surface (outward +)", fontsize=9)
    return save_png(fig, path, dpi=110)


def time_plot(ex, path: Path) -> str:
    """Discrepancy against the time its surface was cut, before and after; switching points marked."""
    plt = pyplot()
    b, a = ex.before, ex.after
    jt = ex.setup.trajectory(ex.robot)
    fig, ax = plt.subplots(figsize=(9, 3))
    ax.plot(b.t, b.residual * UM, ".", ms=2, color="tab:red", label="measured - simulated, before")
    ax.plot(a.t, a.residual * UM, ".", ms=2, color="tab:green", label="after calibration")
    sw = np.asarray(jt.switch)
    ts = np.asarray(jt.t)[sw != 0]
    tmin, tmax = np.nanmin(b.t) - 0.5, np.nanmax(b.t) + 0.5
    for t in ts[(ts > tmin) & (ts < tmax)][:400]:
        ax.axvline(t, color="grey", lw=0.3, alpha=0.5)
    ax.set_xlabel("time of cut [s] (grey: axis stops / reversals)")
    ax.set_ylabel("[µm]")
    ax.legend(fontsize=7)
    return save_png(fig, path, dpi=110)


def write_report(ex, out_dir: str | Path, measured_source: str = "") -> Path:
    """Write ``report.md`` and its PNGs into ``out_dir``."""
    out = Path(out_dir)
    img = out / "images"
    img.mkdir(parents=True, exist_ok=True)
    md = ["# Explaining a measured part", ""]
    md.append(f"Measured: `{measured_source}`; program `{ex.setup.program}`, pose `{ex.setup.placement.name}`, "
              f"robot `{ex.robot.source or ex.robot.name}`; {len(ex.before.residual)} probe points compared at the "
              f"measured positions; dexel spacing {ex.setup.spacing * 1e3:g} mm.")
    md += ["", f"**Cause: `{ex.cause}`**"]
    if ex.calibration is not None:
        c = ex.calibration
        md[-1] += (f"; calibrated `{c.before.param}`: {c.before.value:.6g} -> {c.after.value:.6g} {c.before.unit} "
                  f"({len(c.history)} re-simulations).")
    else:
        md[-1] += (": no candidate explains the discrepancy better than the noise; the robot file is unchanged.")
    md += ["", f"RMS measured - simulated: **{ex.rms_before * UM:.2f} um before**, "
               f"**{ex.rms_after * UM:.2f} um after** calibration (re-simulated, not predicted); "
               f"gain = 1 - after/before = **{ex.gain * 100:.1f} %**.", ""]
    md += ["## Measured vs simulated deviations", ""]
    p = roundness_plot(ex, img / "roundness.png")
    if p:
        md.append(f"![roundness]({img.name}/{p})")
    p = straightness_plot(ex, img / "straightness.png")
    if p:
        md.append(f"![straightness]({img.name}/{p})")
    md.append(f"![discrepancy over time]({img.name}/{time_plot(ex, img / 'discrepancy_time.png')})")
    rms = [(f, int((ex.before.feature == f).sum()), f"{rb * UM:.2f}", f"{ra * UM:.2f}")
           for f, (rb, ra) in ex.rms_by_feature().items()]
    rms.append(("**all**", len(ex.before.residual), f"{ex.rms_before * UM:.2f}", f"{ex.rms_after * UM:.2f}"))
    md += ["", "## RMS per feature [µm]", ""] + markdown_table(("feature", "points", "before", "after"), rms)
    if ex.features_before is not None:
        table2 = []
        for k, (m, s) in ex.features_before.items():
            sa = ex.features_after[k][1] if ex.features_after else float("nan")
            table2.append((k, f"{m * 1e3:+.4f}", f"{s * 1e3:+.4f}", f"{sa * 1e3:+.4f}"))
        md += ["", "## Table 2 rows [mm]: measured vs simulated", ""] + markdown_table(
            ("row", "measured", "simulated before", "simulated after"), table2)
    cs = dict(ex.cause_signatures.rows()) if ex.cause_signatures is not None else {}
    md += ["", "## Signatures of the discrepancy", ""] + markdown_table(
        ("signature", "measured - simulated", "fitted cause"),
        [(k, v, cs.get(k, "-")) for k, v in ex.signatures.rows()])
    md += ["", "## Cause ranking", "",
           "Score: dBIC of the cause's sensitivity fit against no discrepancy (larger is better; a cause is named "
           "above 10 with at least 10 % held-out RMS gain).", ""]
    md += markdown_table(("cause", "score", "held-out gain", "fitted change"),
                         [(f.cause, f"{f.score:.1f}", f"{f.heldout_gain * 100:.1f} %",
                           ", ".join(f"{v:.3g}" for v in f.theta)) for f in ex.choice.ranking])
    md += ["", "Timings [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in ex.timings.items()), ""]
    path = out / "report.md"
    with atomic_file(path) as tmp:
        tmp.write_text("\n".join(md) + "\n", encoding="utf-8")
    return path
