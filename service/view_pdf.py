"""The printable report of a job: one PDF (A4 pages) of what the planner's page shows, for the shop floor or a
customer (``GET <prefix>/{id}/view/report.pdf``, :func:`service.view.add_routes`).

The pages are drawn from the page's own *sections* (:mod:`service.view`), so the PDF says what the page says:
the job's header (program, robot, pose file, spacing, friction model per axis with its version, when it ran),
Table 2 with the page's colour rule (green in tolerance; orange to red out of it, by the factor over the
tolerance; the rank among the poses as a number), the coloured part of every pose (the tool deflection on its
legend's scale, rendered by :func:`simulate.machining.virtual_workpiece.render_mesh_png`), summaries,
tables, the circle's polar trace, the job's images and the list of files. matplotlib's ``PdfPages`` writes it
(no hand-written PDF).
"""
from __future__ import annotations

import io
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

#: A4 portrait [inch].
PAGE = (8.27, 11.69)
#: Most rows of a table on one page (the CSV files have them all).
MAX_ROWS = 40


def _text(v, digits=None) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(v):
            return "-"
        return f"{v:.{digits}f}" if digits is not None else (f"{v:.0f}" if float(v).is_integer() else f"{v:.4g}")
    return str(v)


def cell_colour(cell: dict) -> tuple:
    """The page's colour rule of a Table-2 cell (``view.js`` cellStyle) as RGB 0..1: green in tolerance, orange
    (just over) to red (10x the tolerance and more), white without a value."""
    import colorsys

    if not cell or cell.get("in_tolerance") is None:
        return (1.0, 1.0, 1.0)
    if cell["in_tolerance"]:
        return colorsys.hls_to_rgb(120 / 360, 0.84, 0.45)
    t = min(1.0, math.log10(max(1.0, float(cell.get("factor") or 1.0))))
    return colorsys.hls_to_rgb(40 * (1 - t) / 360, 0.80 - 0.14 * t, 0.80)


class Report:
    """Pages of one PDF: a text cursor from the top of the current page, new pages as they fill."""

    def __init__(self, pdf, title: str):
        self.pdf, self.title = pdf, title
        self.fig: Any = None   # the matplotlib figure of the page being filled
        self.y = 0.0
        self.pages = 0

    def new_page(self):
        self.flush()
        from simulate.figures import pyplot

        self.fig = pyplot().figure(figsize=PAGE)
        self.pages += 1
        self.fig.text(0.06, 0.975, self.title, fontsize=9, color="0.35")
        self.fig.text(0.94, 0.975, f"page {self.pages}", fontsize=9, color="0.35", ha="right")
        self.y = 0.95

    def flush(self):
        if self.fig is not None:
            from simulate.figures import pyplot

            self.pdf.savefig(self.fig)
            pyplot().close(self.fig)
            self.fig = None

    def room(self, height: float):
        if self.fig is None or self.y - height < 0.04:
            self.new_page()

    def heading(self, text: str):
        self.room(0.2)   # no heading alone at the foot of a page
        self.fig.text(0.06, self.y - 0.02, text, fontsize=12, weight="bold")
        self.y -= 0.04

    def note(self, text: str, size: float = 7.5):
        import textwrap

        lines = textwrap.wrap(text, 120)
        self.room(0.013 * len(lines) + 0.01)
        self.fig.text(0.06, self.y - 0.012, "\n".join(lines), fontsize=size, va="top", color="0.25")
        self.y -= 0.013 * len(lines) + 0.012

    def table(self, columns: list[str], rows: list[list], colours: list[list] | None = None,
              widths: list[float] | None = None, size: float = 7.5):
        for start in range(0, max(len(rows), 1), MAX_ROWS):
            part = rows[start:start + MAX_ROWS]
            h = 0.017 * (len(part) + 1)
            self.room(h + 0.01)
            ax = self.fig.add_axes((0.06, self.y - h, 0.88, h))
            ax.axis("off")
            labels = columns if any(columns) else None
            h -= 0 if labels else 0.017
            body = [[v if isinstance(v, str) else _text(v) for v in r] for r in part] or [["-"] * len(columns)]
            tab = ax.table(cellText=body, colLabels=labels, loc="upper left", cellLoc="left", colLoc="left",
                           cellColours=colours[start:start + MAX_ROWS] if colours else None,
                           colWidths=widths, bbox=(0, 0, 1, 1))
            tab.auto_set_font_size(False)
            tab.set_fontsize(size)
            for (r, _), c in tab.get_celld().items():
                c.set_linewidth(0.3)
                if r == 0 and labels:
                    c.set_text_props(weight="bold")
                    c.set_facecolor((0.94, 0.95, 0.97))
            self.y -= h + 0.015

    def image(self, png: bytes | Path, height: float = 0.42, caption: str = ""):
        from PIL import Image

        img = Image.open(io.BytesIO(png) if isinstance(png, bytes) else png)
        self.room(height + 0.03)
        ax = self.fig.add_axes((0.06, self.y - height, 0.88, height))
        ax.imshow(np.asarray(img.convert("RGB")))
        ax.axis("off")
        self.y -= height + 0.01
        if caption:
            self.note(caption)

    def axes(self, height: float, projection: str | None = None):
        self.room(height + 0.03)
        ax = self.fig.add_axes((0.15, self.y - height, 0.7, height), projection=projection)
        self.y -= height + 0.02
        return ax


def ranking_page(rep: Report, s: dict):
    poses = [e["pose"] for e in s["ranking"]]
    rows, colours = [], []
    for r in s["rows"]:
        cells = r.get("cells") or {}
        row = [r["name"], r.get("nominal_text") or "-", f"{r['tolerance_mm']:.3f}"]
        col = [(1, 1, 1)] * 3
        for p in poses:
            c, v = cells.get(p) or {}, r["deviation_mm"].get(p)
            text = "-" if v is None else f"{v:+.4f}"
            if c.get("in_tolerance"):
                text += "  ok"
            elif c.get("factor") is not None:
                text += f"  {c['factor']:.1f}x"
            row.append(f"({c.get('rank', '-')}) {text}")
            col.append(cell_colour(c))
        rows.append(row)
        colours.append(col)
    rows.append(["score (sum |dev.| / tol.) [-]", "", ""] + [f"{e['score']:.2f}" for e in s["ranking"]])
    rows.append(["rows in tolerance", "", ""] + [f"{e['in_tolerance']} / {len(s['rows'])}" for e in s["ranking"]])
    colours += [[(1, 1, 1)] * (3 + len(poses))] * 2
    n = len(poses)
    rep.table(["row", "nominal", "tolerance [mm]"] + [f"{e['pose']} (rank {e['rank']})" for e in s["ranking"]], rows,
              colours, widths=[0.3, 0.09, 0.09] + [0.52 / n] * n)
    rep.note("Deviation [mm] per pose, poses best first. Colour: green where |deviation| <= tolerance ('ok'); orange "
             "to red out of tolerance, by the factor over it (shown, 'x'; full red at 10x). (k): the pose's rank in "
             "that row (1: smallest |deviation|), which says nothing about the tolerance. Tolerances: the ISO "
             "10791-7 rows as the paper's Table 2 prints them.")


def workpiece_pages(rep: Report, s: dict, load: Callable[[str], Path]):
    """The deflection-coloured part of every pose (``load(pose)``: the pose's npz), each on the scale of its
    legend (the renderer's, the pose's own range: compare the legends' numbers, not the colours)."""
    import tempfile

    from simulate.machining.virtual_workpiece import VirtualWorkpiece, render_mesh_png

    for pose in s["poses"]:
        vw = VirtualWorkpiece.load(load(pose))
        with tempfile.TemporaryDirectory() as tmp:
            png = Path(tmp) / "part.png"
            render_mesh_png(vw, png, "deflection", max_nodes=150_000, width_px=800)
            rep.image(png.read_bytes(), height=0.36, caption=f"pose {pose}: the machined part coloured by the tool "
                      "deflection |d| [µm] on this pose's own scale (its legend: compare the numbers between poses, "
                      "not the colours); stock surface grey.")


def polar_page(rep: Report, s: dict):
    ax = rep.axes(0.45, projection="polar")
    for series in s["series"]:
        a = np.radians(np.asarray(series["angle_deg"], float))
        ax.plot(a, np.asarray(series["deviation_um"], float), lw=0.9, label=series["label"])
    for m in s.get("marks") or []:
        ax.axvline(np.radians(m["angle_deg"]), color="0.4", lw=0.6)
    ax.set_title("radial deviation [µm] over the angle", fontsize=9)
    ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(-0.15, -0.12))
    if s.get("marks"):
        rep.note("Reversals (lines): " + "; ".join(f"{m['angle_deg']:.1f} deg {m['label']}" for m in s["marks"]))


def build(title: str, sections: list[dict], *, load_npz: Callable[[str], Path] | None = None,
          load_file: Callable[[str], Path] | None = None) -> bytes:
    """The PDF of a page's sections; ``load_npz(pose)`` / ``load_file(name)`` give a job file's path (checked
    against its recorded digest by the caller)."""
    from matplotlib.backends.backend_pdf import PdfPages

    buf = io.BytesIO()
    with PdfPages(buf, metadata={"Title": title, "Creator": "greybench service"}) as pdf:
        rep = Report(pdf, title)
        rep.new_page()
        for s in sections:
            kind = s["type"]
            if kind == "workpiece" and not s.get("poses"):
                continue
            rep.heading(s.get("title") or kind)
            if kind == "header":
                rep.table(["", ""], [[k, _text(v, d[0] if d else None)] for k, v, *d in s["items"]], widths=[0.3, 0.7])
                rep.table(["axis", "friction model: kind (registered name and version, or source)"],
                          s.get("friction") or [["-", "-"]], widths=[0.15, 0.85])
            elif kind == "summary":
                rep.table(["", ""], [[k, _text(v, d[0] if d else None)] for k, v, *d in s["items"]], widths=[0.6, 0.4])
            elif kind == "ranking":
                ranking_page(rep, s)
            elif kind == "workpiece" and load_npz is not None:
                workpiece_pages(rep, s, load_npz)
            elif kind == "before-after":
                rep.table(["row", "tolerance [µm]", "before [µm]", "after [µm]"],
                          [[r["name"], _text(r["tolerance_um"], 0), _text(r["before_um"], 1), _text(r["after_um"], 1)]
                           for r in s["rows"]])
            elif kind == "table":
                digits = s.get("digits") or [None] * len(s["columns"])
                rep.table(s["columns"], [[_text(v, digits[j]) for j, v in enumerate(r)] for r in s["rows"]]
                          or [[s.get("empty", "none")] + [""] * (len(s["columns"]) - 1)])
                if len(s["rows"]) > MAX_ROWS:
                    rep.note(f"{len(s['rows'])} rows over {math.ceil(len(s['rows']) / MAX_ROWS)} pages")
            elif kind == "polar":
                polar_page(rep, s)
            elif kind == "plot":
                ax = rep.axes(0.3)
                for series in s["series"]:
                    style: dict[str, dict[str, Any]] = {"points": dict(ls="none", marker="o", ms=3),
                                                        "step": dict(drawstyle="steps-post")}
                    ax.plot(series["x"], series["y"], color=series.get("colour"), label=series["label"],
                            **style.get(series.get("style"), {}))
                ax.set_xlabel(s["x_label"], fontsize=8)
                ax.set_ylabel(s["y_label"], fontsize=8)
                ax.legend(fontsize=7)
            elif kind == "image" and load_file is not None:
                name = s["url"].split("/view/files/", 1)[1].split("?", 1)[0]
                rep.image(load_file(name), height=0.4, caption=s.get("note", ""))
            elif kind == "files":
                rows = [[f["name"], _text(None if f["bytes"] is None else f["bytes"] / 1024, 1)] for f in s["files"]]
                rep.table(["file", "size [KiB]"], rows, widths=[0.8, 0.2])
            if s.get("note") and kind not in ("image",):
                rep.note(s["note"])
        rep.flush()
    return buf.getvalue()
