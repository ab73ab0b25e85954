"""The planner's view: one browser page per finished job (paper 3.8, the process-evaluation assistant).

``GET /simulations/{id}/view`` serves a page (``service/static/view/``) that shows the Table-2 ranking
(rows per pose with tolerance, in-tolerance values marked, best to worst coloured per row), the
coloured virtual workpiece of a chosen pose in 3D (three.js, shipped in ``service/static/vendor``: no
CDN, works offline) with the variable chosen from those the workpiece carries and a legend in units,
the program lines, time stamps, reversing axes and error components at a clicked point, the program
lines that cut a box-selected region, and download links for every result file. A compensation job's
page (``GET /compensations/{id}/view``) shows the Table-2 deviations before and after; a circle job's
(``GET /circles/{id}/view``) the roundness, radius error, reversal spikes and the polar plot; a placement
search's (``GET /placement-searches/{id}/view``) the best pose against the given poses, the heat map and the
search history.

Access is the API's: the page and every data route need a valid ``X-API-Key``, or a short-lived
signed link from ``POST /<jobs>/{id}/view-link`` (``?token=``: HMAC-SHA256 over the job id and the
expiry with the service's secret, :func:`sign` / :func:`verify`). A browser without either gets the
page's key form (401, no job data); the key a planner enters is kept in the tab's sessionStorage and
exchanged for a signed link. Job missing: 404; not finished: 409 (both a short HTML page).

Job kinds plug in with :func:`register`: a kind gives its URL prefix and a function returning the
page's *sections*, each a dict with ``type`` and ``title`` rendered by ``view.js``; call it before
:func:`add_routes`. Section types and their fields:

- ``ranking``: ``ranking`` (entries pose, rank, score, in_tolerance), ``rows`` (name, nominal_text,
  tolerance_mm, deviation_mm by pose), ``poses`` (per-pose summaries, optional ``shares``);
- ``workpiece``: ``poses``, ``variables`` (name, label, unit), ``colormap`` (sRGB triples),
  ``stock_rgb``, ``click_radius_mm``, ``urls`` by pose (mesh, values, click, box);
- ``before-after``: ``rows`` (name, tolerance_um, before_um, after_um);
- ``polar``: ``series`` (label, angle_deg, deviation_um: radial deviation from the nominal circle),
  optional ``marks`` (angle_deg, label), e.g. a circle (ballbar) test;
- ``table``: ``columns`` (labels with units), ``rows`` (lists of cells), optional ``digits`` per column,
  ``highlight`` (row indices), ``note``, ``empty`` (text when there are no rows), ``id`` (the table's
  ``data-id``);
- ``plot``: ``x_label``, ``y_label`` (with units), ``series`` (label, x, y, ``style`` points / line /
  step, colour);
- ``image``: ``url``, optional ``note``; ``summary``: ``items`` ([label with unit, value, optional
  decimals]); ``files``: ``files`` (name, bytes, url; :meth:`Context.files`).

The data routes are thin: the geometry and values come from :mod:`simulate.machining.surface_mesh`
and :mod:`simulate.machining.virtual_workpiece`, a click from :func:`simulate.evaluation.trace.trace_point`.
"""
from __future__ import annotations

import base64
import hashlib
import hmac
import html
import json
import os
import struct
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
from fastapi import Body, Depends, HTTPException, Query, Request, Security
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, HTMLResponse, Response
from pydantic import StrictInt

from identify.errors import InputError
from identify.files import atomic_file
from service.auth import HEADER, api_key_header, key_ok

if TYPE_CHECKING:
    from service.jobs import JobRecord
    from service.states import JobKind

STATIC = Path(__file__).parent / "static"
#: Lifetime of a signed view link unless the request asks otherwise [s], and the longest allowed.
LINK_SECONDS = 900
MAX_LINK_SECONDS = 86_400
#: Default search radius of a click [mm] (the ``trace`` command's).
CLICK_RADIUS_MM = 1.5
#: Most lattice nodes of the mesh sent to the browser: some 10^5 triangles for the test pieces.
VIEW_MAX_NODES = 3_000_000
MM = 1e-3


# ---- signed links -------------------------------------------------------------------------------
def secret(settings) -> bytes:
    """The service's secret for view links: ``GREYBENCH_VIEW_SECRET``, else 32 random bytes kept in
    ``<data dir>/view-secret`` (mode 0600, made on first use), so links survive a restart."""
    if settings.view_secret:
        return settings.view_secret.encode()
    path = Path(settings.data_dir) / "view-secret"
    try:
        return bytes.fromhex(path.read_text().strip())
    except (OSError, ValueError):
        pass
    value = os.urandom(32)
    with atomic_file(path, mode=0o600) as tmp:
        tmp.write_text(value.hex())
    return value


def _b64(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).rstrip(b"=").decode()


def sign(key: bytes, job_id: str, expires: int) -> str:
    """Token ``<job>.<expiry unix s>.<HMAC-SHA256 hex digest, base64url>`` for one job until ``expires``."""
    mac = hmac.new(key, f"view:{job_id}:{int(expires)}".encode(), hashlib.sha256).digest()
    return f"{job_id}.{int(expires)}.{_b64(mac)}"


def verify(key: bytes, token: str | None, job_id: str, now: float | None = None) -> bool:
    """True when ``token`` was signed with ``key`` for ``job_id`` and has not expired (constant-time)."""
    if not token or len(token) > 200:
        return False
    parts = token.split(".")
    if len(parts) != 3 or parts[0] != job_id or not parts[1].isdigit():
        return False
    expected = sign(key, job_id, int(parts[1]))
    if not hmac.compare_digest(expected.encode(), token.encode()):
        return False
    return int(parts[1]) > (time.time() if now is None else now)


# ---- job kinds ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class ViewKind:
    """A job kind's page: its URL prefix (``/simulations``) and ``sections(ctx) -> list of dict``."""

    kind: JobKind
    prefix: str
    title: str
    sections: Callable[[Context], list[dict]]


VIEWS: dict[str, ViewKind] = {}


def register(kind: JobKind, prefix: str, title: str, sections: Callable[[Context], list[dict]]) -> None:
    """Give job kind ``kind`` (a :class:`service.jobs.JobKind`) a page under ``<prefix>/{id}/view``."""
    VIEWS[prefix] = ViewKind(kind, prefix, title, sections)


@dataclass
class Context:
    """What a sections function gets: the request, the job record and URL helpers."""

    request: Request
    rec: JobRecord
    prefix: str
    token: str | None
    svc: Any = None   # service.app: its request helpers (passed in, no import back)

    @property
    def job_dir(self) -> Path:
        return self.request.app.state.manager.job_dir(self.rec.id)

    def url(self, tail: str) -> str:
        """A data URL of this job's view (the token appended, so links work in a plain browser)."""
        u = f"{self.prefix}/{self.rec.id}/view/{tail}"
        return u + (("&" if "?" in u else "?") + f"token={self.token}" if self.token else "")

    def read(self, name: str, read):
        """``read(path)`` of a result file, its recorded digest checked (:func:`service.app._result`)."""
        return self.svc._result(self.request, self.rec, name, read)

    def files(self) -> list[dict]:
        """Every file recorded when the job succeeded, with its size [bytes] and a download URL."""
        digests = self.request.app.state.store.files(self.rec.id) or {}
        out = []
        for name in sorted(digests):
            p = self.job_dir / name
            out.append({"name": name, "bytes": p.stat().st_size if p.is_file() else None,
                        "url": self.url(f"files/{name}")})
        return out


# ---- geometry and values --------------------------------------------------------------------
_CACHE: OrderedDict = OrderedDict()
_CACHE_LOCK = threading.Lock()
_CACHE_SIZE = 4


def _cached(key, make):
    """An LRU of a few loaded workpieces and meshes (one page asks for several variables)."""
    with _CACHE_LOCK:
        if key in _CACHE:
            _CACHE.move_to_end(key)
            return _CACHE[key]
    value = make()
    with _CACHE_LOCK:
        _CACHE[key] = value
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return value


def load_workpiece(path: Path, digest: str | None = None):
    """The :class:`simulate.machining.virtual_workpiece.VirtualWorkpiece` of a job file (cached by digest)."""
    from simulate.machining.virtual_workpiece import VirtualWorkpiece

    return _cached(("vw", str(path), digest), lambda: VirtualWorkpiece.load(path))


def mesh_of(vw, key):
    """Closed surface (:func:`simulate.machining.surface_mesh.surface_mesh`) at a lattice fine enough
    for the page and small enough to send (:data:`VIEW_MAX_NODES`), flat quads made by one step (the
    untouched stock faces above all) merged into rectangles
    (:func:`simulate.machining.surface_mesh.merge_flat_quads`): every vertex keeps its creating step,
    so each variable colours it exactly, with a third of the triangles."""
    from simulate.machining.surface_mesh import merge_flat_quads, surface_mesh

    def make():
        sm = surface_mesh(vw.workpiece, max_nodes=VIEW_MAX_NODES)
        return merge_flat_quads(sm, np.asarray(sm.vertex_step, np.int64))

    return _cached(("mesh", key), make)


#: Derived per-step variable of the page: the tool's deviation from the commanded path, the vector sum of
#: the deflection and the servo tracking error (both in the workpiece frame) [m]; shown in µm.
TOOL_DEVIATION = "tool_deviation"


class ViewVariable(str, Enum):
    """The values route's ``variable``: :data:`TOOL_DEVIATION` and the per-step variables of the virtual
    workpiece (``simulate.machining.virtual_workpiece.VARIABLES``, named here because importing that
    module loads the machining kernels; a test holds the two equal)."""

    tool_deviation = TOOL_DEVIATION
    deflection = "deflection"
    force = "force"
    tracking_error = "tracking_error"
    time = "time"
    line = "line"
    switch = "switch"
    peak_force = "peak_force"


def variables() -> list[dict]:
    """The variables the page colours by: the tool deviation (:data:`TOOL_DEVIATION`) and those the
    virtual workpiece carries, each with its display unit and factor from SI."""
    from simulate.machining.virtual_workpiece import DISPLAY_UNITS, VARIABLES

    labels = {"deflection": "tool deflection |d|", "force": "cutting force |F|", "tracking_error":
              "servo tracking error |e|", "time": "time stamp", "line": "program line", "switch":
              "switching bits (axes stopping or reversing)", "peak_force": "peak cutting force"}
    return [{"name": TOOL_DEVIATION, "label": "tool deviation |d + e|", "unit": "µm", "factor": 1e6,
             "categorical": False}] + [
        {"name": v, "label": labels.get(v, v.replace("_", " ")), "unit": DISPLAY_UNITS[v][1],
         "factor": DISPLAY_UNITS[v][0], "categorical": v in CATEGORICAL} for v in VARIABLES]


def vertex_values(vw, step: np.ndarray, variable: str) -> np.ndarray:
    """SI value of ``variable`` per vertex (NaN where no step made it: the stock surface)."""
    from simulate.machining.virtual_workpiece import step_values

    if variable != TOOL_DEVIATION:
        return step_values(vw, step, variable)
    dev = np.linalg.norm(vw.steps.tool_offset(), axis=1)
    out = np.full(len(step), np.nan)
    ok = step >= 0
    out[ok] = dev[step[ok]]
    return out


def frame(header: dict, *arrays: np.ndarray) -> bytes:
    """Binary answer: uint32 little-endian header length, the JSON header (padded with spaces to 4 bytes),
    then the arrays' raw little-endian bytes one after another (their dtypes and lengths in the header)."""
    head = json.dumps(header, separators=(",", ":")).encode()
    head += b" " * (-len(head) % 4)
    return struct.pack("<I", len(head)) + head + b"".join(np.ascontiguousarray(a).tobytes() for a in arrays)


def mesh_bytes(sm) -> bytes:
    """Vertices [mm, workpiece frame] float32 (n, 3) and triangle indices uint32 (m, 3) of a mesh."""
    v = np.asarray(sm.vertices, np.float64) / MM
    f = np.asarray(sm.faces, np.uint32)
    lo, hi = v.min(axis=0), v.max(axis=0)
    header = {"vertices": int(len(v)), "faces": int(len(f)), "bounds_mm": [lo.tolist(), hi.tolist()],
              "lattice_mm": float(sm.pitch) / MM, "arrays": [["position_mm", "float32", 3], ["index", "uint32", 3]]}
    return frame(header, v.astype("<f4"), f.astype("<u4"))


def values_bytes(vw, sm, variable: str) -> bytes:
    """Per vertex the value of ``variable`` in its display unit (float32, NaN on the stock surface) and
    the colour scale's ends (:func:`simulate.machining.virtual_workpiece.colour_range`) in that unit."""
    from simulate.machining.virtual_workpiece import DISPLAY_UNITS, colour_range

    vals = vertex_values(vw, np.asarray(sm.vertex_step), variable)
    lo, hi = colour_range(vals)
    factor, unit = (1e6, "µm") if variable == TOOL_DEVIATION else DISPLAY_UNITS[variable]
    header = {"variable": variable, "unit": unit, "range": [lo * factor, hi * factor], "vertices": int(len(vals)),
              "arrays": [["value", "float32", 1]]}
    return frame(header, (vals * factor).astype("<f4"))


def viridis(n: int = 64) -> list[list[int]]:
    """The colour map of the GLB and PNG exports (matplotlib's viridis) as ``n`` sRGB triples."""
    import matplotlib

    c = matplotlib.colormaps["viridis"](np.linspace(0.0, 1.0, n))[:, :3]
    return np.round(c * 255).astype(int).tolist()


#: Variables coloured by category, not by a scale: neighbouring program lines (and switching bit patterns)
#: must look different, which a continuous map does not give.
CATEGORICAL = ("line", "switch")


def tab20() -> list[list[int]]:
    """matplotlib's qualitative tab20 as sRGB triples: the colours of the categorical variables (a line
    number or bit pattern k gets colour k mod 20)."""
    import matplotlib

    c = np.asarray(matplotlib.colormaps["tab20"](np.arange(20)))[:, :3]   # a listed map: index k is colour k
    return np.round(c * 255).astype(int).tolist()


def binary_response(request, data: bytes):
    """``application/octet-stream``, gzip-compressed when the client accepts it (meshes shrink to ~half)."""
    import gzip

    headers = {"Cache-Control": "private, max-age=3600", "Vary": "Accept-Encoding"}
    if "gzip" in request.headers.get("accept-encoding", ""):
        data = gzip.compress(data, compresslevel=5)
        headers["Content-Encoding"] = "gzip"
    return Response(data, media_type="application/octet-stream", headers=headers)


# ---- click and box ---------------------------------------------------------------------------
def _near_steps(vw, inside_fn) -> np.ndarray:
    """Step indices of the machined dexel ends (all three families) for which ``inside_fn(points)``."""
    out = []
    for axis in range(3):
        pts, step, _ = vw.workpiece.ends(axis)
        ok = step >= 0
        out.append(step[ok][inside_fn(pts[ok])])
    return np.concatenate(out).astype(np.int64)


def components_at(vw, steps: np.ndarray) -> dict:
    """The path error's two parts at the steps that cut a spot: tool deflection (compliance x force) and the
    servo tracking error (friction, backlash and dynamics of the drives), as mean magnitudes [µm] and
    shares of their sum [-]. A split by magnitude: the two are vectors and may partly cancel, so the
    shares say which part is larger there, not how much each moved the surface."""
    if len(steps) == 0:
        return {}
    d = float(np.mean(np.linalg.norm(np.asarray(vw.steps.deflection)[steps], axis=1)))
    e = float(np.mean(np.linalg.norm(np.asarray(vw.steps.tracking_error)[steps], axis=1)))
    total = d + e
    return {"deflection_um": d / 1e-6, "tracking_error_um": e / 1e-6,
            "deflection_share": d / total if total > 0 else 0.0,
            "tracking_error_share": e / total if total > 0 else 0.0}


def _line_rows(lines) -> list[dict]:
    from simulate.toolpath.switching import axes_of

    return [{"line": ln.line, "text": ln.text, "t_first_s": ln.t_first, "t_last_s": ln.t_last, "n_ends": ln.n_ends,
             "max_deflection_um": ln.max_deflection / 1e-6, "max_force_n": ln.max_force,
             "reversing_axes": axes_of(ln.switching)} for ln in lines]


def click(vw, program: Path, point_mm, radius_mm: float) -> dict:
    """What ``greybench trace`` answers for a point [mm]: program lines with time stamps, the axes
    stopping or reversing there (switching bits), and the error components (:func:`components_at`)."""
    from simulate.evaluation.trace import trace_point
    from simulate.toolpath.switching import axes_of

    p = np.asarray(point_mm, float) * MM
    r = float(radius_mm) * MM
    tr = trace_point(vw, p, r, program=str(program))
    steps = _near_steps(vw, lambda pts: np.sum((pts - p) ** 2, axis=1) <= r * r)
    bits = int(np.bitwise_or.reduce(np.asarray(vw.steps.switch)[steps].astype(np.int64))) if len(steps) else 0
    return {"point_mm": list(map(float, point_mm)), "radius_mm": float(radius_mm), "n_ends": tr.n_ends,
            "t_first_s": float(tr.times[0]) if len(tr.times) else None,
            "t_last_s": float(tr.times[-1]) if len(tr.times) else None,
            "reversing_axes": axes_of(bits), "components": components_at(vw, steps), "lines": _line_rows(tr.lines)}


def box(vw, program: Path, lo_mm, hi_mm) -> dict:
    """The program lines whose steps cut the machined dexel ends inside an axis-aligned box [mm],
    grouped as :func:`simulate.evaluation.trace.trace_point` groups a point's (by first time)."""
    from simulate.evaluation.trace import TraceLine, _program_lines

    lo = np.asarray(lo_mm, float) * MM
    hi = np.asarray(hi_mm, float) * MM
    if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise InputError("a box needs 3 finite numbers for each corner (mm)", field="min_mm")
    if np.any(hi < lo):
        raise InputError("each max_mm coordinate must be >= the min_mm one", field="max_mm")
    st = _near_steps(vw, lambda pts: np.all((pts >= lo) & (pts <= hi), axis=1))
    table = vw.steps
    text = _program_lines(str(program))
    lines = []
    if len(st):
        ln = np.asarray(table.line)[st]
        for line in np.unique(ln):
            s = st[ln == line]
            t = np.asarray(table.t)[s]
            lines.append(TraceLine(line=int(line), text=text[line - 1].strip() if 0 < line <= len(text) else "",
                                   t_first=float(t.min()), t_last=float(t.max()), n_ends=int(len(s)),
                                   max_deflection=float(np.linalg.norm(np.asarray(table.deflection)[s], axis=1).max()),
                                   max_force=float(np.linalg.norm(np.asarray(table.force)[s], axis=1).max()),
                                   switching=int(np.bitwise_or.reduce(np.asarray(table.switch)[s].astype(np.int64)))))
        lines.sort(key=lambda x: x.t_first)
    return {"min_mm": (lo / MM).tolist(), "max_mm": (hi / MM).tolist(), "n_ends": int(len(st)),
            "components": components_at(vw, st), "lines": _line_rows(lines)}


# ---- sections of the job kinds --------------------------------------------------------------
def tolerance_cells(deviation_mm: dict, tolerance_mm: float) -> dict:
    """Per pose the cell of one Table-2 row: ``in_tolerance`` (|deviation| <= tolerance, the rule of
    :attr:`simulate.evaluation.features.FeatureRow.in_tolerance`), ``factor`` (|deviation| / tolerance [-],
    the row's term of the score) and ``rank`` among the poses (1: smallest |deviation|; ties share the
    lower rank). The tolerance is the report's (the ISO 10791-7 rows of :mod:`simulate.evaluation.features`)."""
    mags = {p: abs(float(v)) for p, v in deviation_mm.items() if _num(v) is not None}
    out: dict = {}
    for p in deviation_mm:
        if p not in mags:
            out[p] = {"in_tolerance": None, "factor": None, "rank": None}
            continue
        out[p] = {"in_tolerance": bool(mags[p] <= tolerance_mm),
                  "factor": mags[p] / tolerance_mm if tolerance_mm > 0 else None,
                  "rank": 1 + sum(m < mags[p] for m in mags.values())}
    return out


def _iso(t) -> str | None:
    """A Unix time [s] as ISO 8601 UTC to the second."""
    import datetime as dt

    if _num(t) is None:
        return None
    return dt.datetime.fromtimestamp(float(t), dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _friction_text(entry: dict) -> str:
    """One joint's friction model as the report names it: kind and registered name/version, or its source."""
    m = entry.get("model")
    where = f"{m.get('name')} v{m.get('version')}" if isinstance(m, dict) else entry.get("source", "-")
    return f"{entry.get('kind', '-')} ({where})"


def job_header(ctx: Context, report: dict) -> dict:
    """What the planner needs to file the result: program, robot, pose file, dexel spacing, the friction
    model per axis (kind and registered version, from the report: what the run used), and when it ran."""
    req = ctx.rec.request or {}
    opts = req.get("options") or {}
    per_axis: dict[int, set] = {}
    for pose in report.get("poses", []):
        for f in pose.get("friction") or []:
            per_axis.setdefault(int(f.get("joint", 0)), set()).add(_friction_text(f))
    friction = [[f"A{j}", ", ".join(sorted(v))] for j, v in sorted(per_axis.items())]
    poses = req.get("poses") or []
    items = [["program", req.get("program_source", "-")], ["robot", req.get("robot", "-")],
             ["pose file", f"{req['pose_set']}.json" if req.get("pose_set") else "inline poses"],
             ["poses", ", ".join(p.get("name", "?") for p in poses) or "-"],
             ["dexel spacing [mm]", _num(opts.get("spacing_mm")), 3],
             ["components", ", ".join(k for k in ("deflection", "friction", "switching") if opts.get(k, True))
              + (" (with shares)" if opts.get("shares") else "")],
             ["ran (UTC)", f"{_iso(ctx.rec.started) or '-'} .. {_iso(ctx.rec.finished) or '-'}"]]
    return {"type": "header", "title": "Job", "items": items, "friction": friction, "pdf": ctx.url("report.pdf")}


def job_scales(ctx: Context, poses: list[str], digests: dict) -> dict:
    """The colour scale shared by all poses of the job, per variable, in its display unit: the smallest and
    largest value at the machined dexel ends of every pose (:func:`scale_of`). The surface the page draws
    passes through a subset of those ends, so every vertex of every pose gets a colour inside it."""
    ranges: dict[str, list] = {}
    for p in poses:
        name = f"workpiece/{p}.npz"
        for var, (lo, hi) in ctx.read(name, lambda path, n=name: scale_of(path, digests[n])).items():
            r = ranges.setdefault(var, [lo, hi])
            r[0], r[1] = min(r[0], lo), max(r[1], hi)
    return ranges


_SCALES: dict = {}


def scale_of(path: Path, digest: str | None) -> dict:
    """Per variable the (lo, hi) of one workpiece's machined dexel ends in display units (kept per file and
    digest: a few numbers; the workpiece itself is not kept, so the page's LRU keeps its meshes)."""
    from simulate.machining.virtual_workpiece import VirtualWorkpiece, colour_range

    key = (str(path), digest)
    if key not in _SCALES:
        vw = VirtualWorkpiece.load(path)
        steps = np.unique(_near_steps(vw, lambda pts: np.ones(len(pts), bool)))
        _SCALES[key] = {}
        for v in variables():
            lo, hi = colour_range(vertex_values(vw, steps, v["name"]))
            _SCALES[key][v["name"]] = (lo * v["factor"], hi * v["factor"])
    return _SCALES[key]


def placement_frames(ctx: Context, poses: list[str]) -> dict:
    """Per pose the workpiece frame in the robot base frame as a 4x4 row-major matrix [mm] (the pose file's
    xyz and rpy, :attr:`simulate.toolpath.placement.Placement.T`): the page draws the part in the base frame."""
    from simulate.toolpath.placement import parse_poses

    given = {p.get("name"): p for p in (ctx.rec.request or {}).get("poses") or []}
    out = {}
    for name in poses:
        if name in given:
            T = parse_poses({"poses": [given[name]]}, source="request")[0].T.copy()
            T[:3, 3] /= MM
            out[name] = T.reshape(-1).tolist()
    return out


def simulation_sections(ctx: Context) -> list[dict]:
    """The job's header, ranking (Table 2 per pose), the 3D workpiece, the printable report, downloads."""
    report = ctx.read("report.json", lambda p: json.loads(p.read_text()))
    ranking = ctx.read("ranking.json", lambda p: json.loads(p.read_text()))["ranking"]
    poses = [e["pose"] for e in ranking]
    from service.schemas import feature_row

    rows = []
    for stored in report["features"]:
        r = feature_row(stored)
        dev = {p: r.deviation_mm.get(p) for p in poses}
        rows.append({"name": r.name, "nominal_text": r.nominal_text, "tolerance_mm": r.tolerance_mm,
                     "deviation_mm": dev, "cells": tolerance_cells(dev, r.tolerance_mm)})
    digests = ctx.request.app.state.store.files(ctx.rec.id) or {}
    with_npz = [p for p in poses if f"workpiece/{p}.npz" in digests]
    summaries = {s["pose"]: s for s in report["poses"]}
    return [
        job_header(ctx, report),
        {"type": "ranking", "title": "Table 2: deviation per pose [mm]", "ranking": ranking, "rows": rows,
         "poses": [summaries.get(p, {"pose": p}) for p in poses]},
        {"type": "workpiece", "title": "Virtual workpiece", "poses": with_npz, "variables": variables(),
         "colormap": viridis(), "categorical": tab20(), "stock_rgb": [200, 200, 200],
         "click_radius_mm": CLICK_RADIUS_MM, "scales": job_scales(ctx, with_npz, digests),
         "frames": placement_frames(ctx, with_npz),
         "urls": {p: {"mesh": ctx.url(f"workpiece/{p}/mesh"), "values": ctx.url(f"workpiece/{p}/values"),
                      "click": ctx.url(f"workpiece/{p}/click"), "box": ctx.url(f"workpiece/{p}/box")}
                  for p in with_npz},
         "note": "" if with_npz else "this job was run before the service kept the virtual workpiece: "
                                     "submit it again to see the part"},
        {"type": "files", "title": "Result files", "files": ctx.files()},
    ]


def compensation_sections(ctx: Context) -> list[dict]:
    """Table-2 deviations before and after compensation, the deviation plot, downloads."""
    info = ctx.rec.result or {}
    ev = info.get("evaluation") or {}
    out: list[dict] = [{"type": "summary", "title": "Compensation", "items": [
        ["sum of |deviation| before [µm]", _um(ev.get("sum_before_mm"))],
        ["sum of |deviation| after [µm]", _um(ev.get("sum_after_mm"))],
        ["after / before [-]", ev.get("ratio")], ["score before [-]", ev.get("score_before")],
        ["score after [-]", ev.get("score_after")], ["chosen iteration", info.get("best_iteration")],
        ["largest offset from the nominal path [µm]", _um(info.get("max_offset_mm"))],
        ["program time ratio [-]", info.get("time_ratio")]]}]
    if ev.get("rows_mm"):
        out.append({"type": "before-after", "title": "Table 2 before / after compensation [µm]",
                    "rows": [{"name": r["name"], "tolerance_um": _um(r["tolerance"]), "before_um": _um(r["before"]),
                              "after_um": _um(r["after"])} for r in ev["rows_mm"]]})
    rattling = info.get("gears_rattling") or []
    if rattling:
        from simulate.compensation.report import RATTLE_NOTE

        out.append({"type": "table", "title": "Gears left rattling in their play", "id": "gears",
                    "columns": ["program section", "line", "joint", "flank changes before", "after",
                                "in the play before [%]", "after [%]"],
                    "rows": [[g.get("section"), f"{g.get('line')}: {g.get('text', '')}", f"A{g.get('joint')}",
                              g.get("flank_changes_before"), g.get("flank_changes_after"),
                              _pct(g.get("in_play_before")), _pct(g.get("in_play_after"))] for g in rattling],
                    "digits": [None, None, None, None, None, 0, 0],
                    "note": RATTLE_NOTE})
    digests = ctx.request.app.state.store.files(ctx.rec.id) or {}
    if "out/deviation.png" in digests:
        out.append({"type": "image", "title": "Tool deviation from the nominal path, before and after",
                    "url": ctx.url("files/out/deviation.png")})
    out.append({"type": "files", "title": "Result files", "files": ctx.files()})
    return out


def _um(mm):
    return None if mm is None else float(mm) * 1e3


def _pct(share):
    return None if share is None else float(share) * 100.0


#: Most samples of a circle trace the page draws (the CSV has every one): every k-th sample kept, which at
#: this count still resolves a reversal spike (a few degrees wide) to under 0.2 deg.
POLAR_MAX_POINTS = 2000


def _read_json(ctx: Context, name: str) -> dict:
    return ctx.read(name, lambda p: json.loads(p.read_text()))


def _read_csv(ctx: Context, name: str):
    import pandas as pd

    return ctx.read(name, lambda p: pd.read_csv(p))


def _num(v):
    """A finite float or None (JSON has no NaN)."""
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if np.isfinite(f) else None


def circle_sections(ctx: Context) -> list[dict]:
    """A circle (ballbar) job: roundness and radius error [µm], the reversal spikes, the polar plot (the
    job's ``circle.png`` and the trace of ``circle.csv`` drawn by the page), downloads."""
    s = _read_json(ctx, "out/summary.json")
    c = s.get("center_offset_um") or [None, None]
    spikes = s.get("reversal_spikes") or []
    excursion = s.get("largest_excursion_um", s.get("largest_spike_um"))   # the deprecated name: older jobs
    # one number format per row: [label with unit, value, decimals]
    out: list[dict] = [{"type": "summary", "title": "Circle test", "items": [
        ["roundness (circular deviation G, ISO 230-4) [µm]", _num(s.get("roundness_um")), 1],
        ["radius error (least-squares radius - nominal) [µm]", _num(s.get("radius_error_um")), 1],
        ["centre offset, in-plane axes [µm]", ", ".join("-" if _num(v) is None else f"{float(v):.1f}" for v in c)],
        ["largest reversal spike, beyond the settled trace [µm]", _num(s.get("largest_reversal_spike_um")), 1],
        ["largest lost motion, step of the settled trace [µm]", _num(s.get("largest_lost_motion_um")), 1],
        ["largest excursion after a reversal (lost motion and spike) [µm]", _num(excursion), 1],
        ["radius [mm]", _num(s.get("radius_mm")), 3], ["feed [mm/min]", _num(s.get("feed_mm_min")), 1],
        ["plane, direction", f"{s.get('plane', '-')}, {'clockwise (G2)' if s.get('cw') else 'counter-clockwise (G3)'}"],
        ["robot, pose", f"{s.get('robot', '-')}, {s.get('pose', '-')}"],
        ["friction, backlash, friction feed-forward", ", ".join(
            "-" if s.get(k) is None else ("on" if s.get(k) else "off")
            for k in ("friction", "backlash", "ff_friction"))],
        ["friction scale [-]", _num(s.get("friction_scale")), 2]]},
        {"type": "table", "title": "Reversal spikes (one row per reversal)", "id": "spikes",
         "columns": ["angle [deg]", "joints reversing", "spike [µm]", "lost motion [µm]", "excursion [µm]"],
         "rows": [[_num(g[0].get("angle_deg")), ", ".join(str(r.get("joint")) for r in g), _num(g[0].get("spike_um")),
                   _num(g[0].get("lost_motion_um")), _num(g[0].get("height_um"))] for g in reversal_groups(spikes)],
         "digits": [1, None, 1, 1, 1],
         "note": "where a joint's commanded velocity changes sign along the circle, split as a ballbar analysis "
                 "splits it: the spike is the transient peak beyond the settled trace, the lost motion the "
                 "step of the settled trace across the reversal (after minus before), the excursion the extreme "
                 "of the radial deviation just after the reversal relative to its value there (both together; "
                 "outward positive)",
         "empty": "no joint reverses on this circle"}]
    digests = ctx.request.app.state.store.files(ctx.rec.id) or {}
    # the page draws the polar plot from circle.csv; the job's circle.png (the same plot) is in the files
    if "out/circle.csv" in digests:
        df = _read_csv(ctx, "out/circle.csv")
        step = max(1, -(-len(df) // POLAR_MAX_POINTS))
        keep = df.iloc[::step]
        thinned = "" if step == 1 else f" (1 in {step} samples of circle.csv drawn)"
        out.append({"type": "polar", "title": f"Radial deviation over the angle [µm]{thinned}",
                    "series": [{"label": "radial deviation", "angle_deg": keep["angle_deg"].round(4).tolist(),
                                "deviation_um": keep["radial_deviation_um"].round(4).tolist()}],
                    "marks": _spike_marks(spikes)})
    out.append({"type": "files", "title": "Result files", "files": ctx.files()})
    return out


def reversal_groups(spikes: list[dict]) -> list[list[dict]]:
    """The reversals of a circle: the joints reversing at the same angle with the same split (the evaluation
    splits the trace once per sample, so joints reversing together carry identical numbers) as one group, in
    the order of the summary."""
    groups: dict = {}
    for r in spikes:
        key = tuple(None if _num(r.get(k)) is None else round(float(r[k]), 6)
                    for k in ("angle_deg", "spike_um", "lost_motion_um", "height_um"))
        groups.setdefault(key, []).append(r)
    return list(groups.values())


def _spike_marks(spikes: list[dict]) -> list[dict]:
    """One polar mark per reversal angle: joints reversing at the same sample share it (as in the job's
    polar plot), labelled as the CLI's table and the plot name them: the joints, the reversal spike
    beyond the settled trace and the lost motion [µm] (those of the largest |spike| there)."""
    groups: dict = {}
    for r in spikes:
        a = _num(r.get("angle_deg"))
        if a is not None:
            groups.setdefault(round(a, 6), []).append(r)
    out = []
    for a, rs in groups.items():
        top = max(rs, key=lambda r: abs(_num(r.get("spike_um")) or 0.0))
        spike, lost = _num(top.get("spike_um")), _num(top.get("lost_motion_um"))
        out.append({"angle_deg": a, "label": f"{'+'.join(str(r.get('joint')) for r in rs)} spike "
                    f"{'-' if spike is None else f'{spike:+.1f}'} µm, lost motion "
                    f"{'-' if lost is None else f'{lost:+.1f}'} µm"})
    return out


#: Rows of the history table the page shows (``history.csv`` has every candidate).
HISTORY_ROWS = 300


def placement_sections(ctx: Context) -> list[dict]:
    """A placement search: the best pose against the given poses (pose, scores, rows in tolerance, the
    improvement), the heat map, the search history (score per simulated candidate, table), downloads."""
    s = _read_json(ctx, "out/summary.json")
    best_doc = _read_json(ctx, "out/best.json")
    where = {p.get("name"): p for p in best_doc.get("poses", [])}
    b = s.get("best") or {}
    best_score = _num(b.get("score"))

    def pose_row(name, origin, xyz_m, rpy_rad, score, in_tol):
        xyz = [None if _num(v) is None else float(v) / MM for v in (xyz_m or [None] * 3)]
        rpy = [None if _num(v) is None else float(np.degrees(float(v))) for v in (rpy_rad or [None] * 3)]
        score = _num(score)
        # how much lower the best score is than this pose's [%]: the search's improvement for the best given
        gain = None if score in (None, 0) or best_score is None else 100.0 * (score - best_score) / score
        return [name, origin, *xyz, *rpy, score, in_tol, gain]

    rows = [pose_row(b.get("name"), f"best ({b.get('origin', '-')})", b.get("xyz_m"), b.get("rpy_rad"),
                     b.get("score"), b.get("in_tolerance"))]
    for g in s.get("given") or []:
        p = where.get(g.get("name"), {})
        rows.append(pose_row(g.get("name"), "given", p.get("xyz"), p.get("rpy"), g.get("score"),
                             g.get("in_tolerance")))
    counts = s.get("candidates") or {}
    imp = _num(s.get("improvement"))
    out = [{"type": "summary", "title": "Placement search", "items": [
        ["best placement", f"{b.get('name', '-')} ({b.get('origin', '-')})"],
        ["best score (sum of |deviation| / tolerance) [-]", best_score],
        ["best given pose, its score [-]", f"{s.get('best_given', '-')}, "
         + next((f"{float(g['score']):.4f}" for g in s.get("given") or [] if g.get("name") == s.get("best_given")
                 and _num(g.get("score")) is not None), "-")],
        ["improvement over the best given pose [%]", None if imp is None else 100.0 * imp],
        ["score reduction [-]", _num(s.get("score_reduction"))],
        ["candidates", ", ".join(f"{v} {k}" for k, v in counts.items() if v) or "-"],
        ["stopped", s.get("stop_reason", "-")],
        ["wall time / budget [s]", f"{_num(s.get('wall_time_s')) or 0:.0f} / {_num(s.get('budget_s')) or 0:.0f}"],
        ["seed, backend", f"{s.get('seed', '-')}, {s.get('backend', '-')}"]]},
        {"type": "table", "title": "Best pose against the given poses", "id": "poses",
         "columns": ["pose", "origin", "x [mm]", "y [mm]", "z [mm]", "roll [deg]", "pitch [deg]", "yaw [deg]",
                     "score [-]", "rows in tolerance", "best is lower by [%]"],
         "rows": rows, "digits": [None, None, 1, 1, 1, 1, 1, 1, 4, None, 2], "highlight": [0],
         "note": "workpiece origin in the robot base frame; score: sum of |deviation| / tolerance over the "
                 "Table-2 rows, lower is better; last column: (pose's score - best score) / pose's score"}]
    digests = ctx.request.app.state.store.files(ctx.rec.id) or {}
    if "out/heatmap.png" in digests:
        out.append({"type": "image", "title": "Heat map: score over the workpiece position x-y",
                    "url": ctx.url("files/out/heatmap.png"), "note": s.get("heatmap", "")})
    if "out/history.csv" in digests:
        h = _read_csv(ctx, "out/history.csv")
        sim = h[(h["status"] == "simulated") & np.isfinite(_pd_num(h["score"]))] if len(h) else h
        if len(sim):
            idx = sim["index"].astype(float).to_numpy()
            score = _pd_num(sim["score"])
            given = (sim["origin"] == "given").to_numpy()
            out.append({"type": "plot", "title": "Search history: score per simulated candidate",
                        "x_label": "candidate [-] (order drawn)", "y_label": "score [-]", "series": [
                            {"label": "given poses", "x": idx[given].tolist(), "y": score[given].tolist(),
                             "style": "points", "colour": "#d62728"},
                            {"label": "candidates", "x": idx[~given].tolist(), "y": score[~given].tolist(),
                             "style": "points", "colour": "#1f77b4"},
                            {"label": "best so far", "x": idx.tolist(),
                             "y": np.minimum.accumulate(score).tolist(), "style": "step", "colour": "#2ca02c"}]})
        shown = h[h["status"] != "skipped"] if len(h) else h
        cols = [("index", "#", 0), ("name", "name", None), ("origin", "origin", None), ("status", "status", None),
                ("x_mm", "x [mm]", 1), ("y_mm", "y [mm]", 1), ("z_mm", "z [mm]", 1), ("yaw_deg", "yaw [deg]", 1),
                ("score", "score [-]", 4), ("in_tolerance", "rows in tolerance", 0),
                ("switching_points", "switching points [-]", 0), ("compliance_um_per_n", "compliance [µm/N]", 3),
                ("message", "note", None)]
        cols = [c for c in cols if c[0] in h.columns]
        out.append({"type": "table", "title": f"Search history ({len(shown)} of {len(h)} candidates; skipped ones "
                                              "in history.csv)", "id": "history",
                    "columns": [c[1] for c in cols], "digits": [c[2] for c in cols],
                    "rows": [[_cell(v) for v in row] for row in
                             shown[[c[0] for c in cols]].head(HISTORY_ROWS).itertuples(index=False)]})
    out.append({"type": "files", "title": "Result files", "files": ctx.files()})
    return out


def _pd_num(col) -> np.ndarray:
    """A column as floats, NaN where it is not a number."""
    import pandas as pd

    return pd.to_numeric(col, errors="coerce").to_numpy(float)


def _cell(v):
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return _num(v)
    return None if v is None else str(v)


def _register_builtin() -> None:
    from service.states import JobKind

    register(JobKind.simulation, "/simulations", "pose ranking", simulation_sections)
    register(JobKind.compensation, "/compensations", "compensation", compensation_sections)
    register(JobKind.circle, "/circles", "circle test", circle_sections)
    register(JobKind.placement_search, "/placement-searches", "placement search", placement_sections)


_register_builtin()


# ---- the printable report ----------------------------------------------------------------------
_PDFS: OrderedDict = OrderedDict()


def printable(ctx: Context, view: ViewKind) -> bytes:
    """The job's PDF (:func:`service.view_pdf.build` of the page's sections), kept for a few jobs (by the
    job's recorded digests): a job's files do not change once it has succeeded."""
    from service import view_pdf

    digests = ctx.request.app.state.store.files(ctx.rec.id) or {}
    key = (ctx.rec.id, tuple(sorted(digests.items())))
    with _CACHE_LOCK:
        if key in _PDFS:
            return _PDFS[key]
    sections = view.sections(ctx)

    def npz(pose: str) -> Path:
        return ctx.read(f"workpiece/{pose}.npz", lambda p: p)

    def file(name: str) -> Path:
        return ctx.read(name, lambda p: p)

    title = f"greybench {view.title} job {ctx.rec.id}, finished {_iso(ctx.rec.finished) or '-'}"
    pdf = view_pdf.build(title, sections, load_npz=npz, load_file=file)
    with _CACHE_LOCK:
        _PDFS[key] = pdf
        while len(_PDFS) > _CACHE_SIZE:
            _PDFS.popitem(last=False)
    return pdf


# ---- pages and routes -------------------------------------------------------------------------
def _page(status: int, title: str, message: str):
    """A short HTML page for a refused or unfinished job (no traceback, no job data)."""
    body = (f"<!doctype html><html lang=en><head><meta charset=utf-8><title>{html.escape(title)}</title>"
            f"<link rel=stylesheet href=/view-static/view/view.css></head><body><main class=notice>"
            f"<h1>{html.escape(title)}</h1><p>{html.escape(message)}</p></main></body></html>")
    return HTMLResponse(body, status_code=status)


def add_routes(app, settings, keyed: list, svc: ModuleType) -> None:
    """Register the view routes of every kind in :data:`VIEWS` and the static files (call last); ``svc``
    is :mod:`service.app`, whose request helpers the routes share (passed in: no import back)."""
    from fastapi.staticfiles import StaticFiles
    from starlette.middleware.gzip import GZipMiddleware

    from service.paths import JOB_ID_PATTERN, NAME_PATTERN, NotFound, check_job_id, check_name, inside
    from service.schemas import ErrorBody, Responses
    from service.states import JobState

    key_bytes = secret(settings)
    job_id_param = PathParam(pattern=JOB_ID_PATTERN, description="job id (32 hex digits)")
    token_param = Query(None, max_length=200, description="signed view link token (from POST .../view-link)")
    errors: Responses = {401: {"model": ErrorBody}, 404: {"model": ErrorBody}, 409: {"model": ErrorBody}}
    # the page answers HTML; schema errors (422) stay JSON like every route's
    html_errors = {200: {"content": {"text/html": {}}, "description": "the page"},
                   401: {"content": {"text/html": {}}, "description": "the key form (no job data)"},
                   404: {"content": {"text/html": {}}, "description": "no such job"},
                   409: {"content": {"text/html": {}}, "description": "the job has not succeeded"}}
    # the three.js build and the page's own files: public code, no job data; gzip halves the download
    app.mount("/view-static", GZipMiddleware(StaticFiles(directory=STATIC), minimum_size=1024), name="view-static")
    index = (STATIC / "view" / "index.html").read_text()

    def allowed(request: Request, job_id: str, key: str | None, token: str | None) -> bool:
        # a valid link opens its job only; a valid key opens its own jobs (service.auth.may_see)
        linked = verify(key_bytes, token, job_id)
        if linked:
            request.state.view_link = job_id
        if key_ok(key, request.app.state.settings.keys()):
            request.state.api_key = key
            return True
        return linked

    def for_kind(view: ViewKind):
        prefix, kind = view.prefix, view.kind
        tag = prefix.strip("/")

        def access(request: Request, job_id: str = job_id_param, token: str | None = token_param,
                   key: str | None = Security(api_key_header)) -> Context:
            """Dependency of the data routes: 401 without a valid key or link, then the job (404)."""
            check_job_id(job_id)
            if not allowed(request, job_id, key, token):
                raise HTTPException(status_code=401, detail=f"missing or invalid {HEADER} header or view link",
                                    headers={"WWW-Authenticate": HEADER})
            return Context(request, svc._job(request, job_id, kind), prefix, token, svc)

        @app.get(f"{prefix}/{{job_id}}/view", tags=[tag], responses=html_errors,
                 name=f"{kind.value}_view", summary=f"Planner's page of a {view.title} job (HTML)")
        def page(request: Request, job_id: str = job_id_param, token: str | None = token_param,
                 key: str | None = Security(api_key_header)):
            if not allowed(request, job_id, key, token):
                # the key form only: the page asks for a key (kept for the browser session) or a link
                return HTMLResponse(index, status_code=401, headers={"WWW-Authenticate": HEADER})
            check_job_id(job_id)
            try:
                rec = svc._job(request, job_id, kind)
            except NotFound as exc:
                return _page(404, "Job not found", exc.message)
            if rec.state is not JobState.succeeded:
                done = "" if rec.state is not JobState.running else f" ({rec.progress * 100:.0f} % done)"
                reason = f": {rec.error['message']}" if rec.error else ""
                return _page(409, f"Job {rec.state.value}", f"Job {job_id} is {rec.state.value}{done}{reason}; "
                                                            "its page shows once it has succeeded.")
            return HTMLResponse(index, headers={"Cache-Control": "no-store"})

        @app.post(f"{prefix}/{{job_id}}/view-link", dependencies=keyed, tags=[tag], responses=errors,
                  name=f"{kind.value}_view_link", summary="A short-lived signed link to the job's page")
        def view_link(request: Request, job_id: str = job_id_param,
                      expires_s: Annotated[StrictInt, Body(embed=True, ge=10, le=MAX_LINK_SECONDS,
                                                            description="lifetime of the link [s]")] = LINK_SECONDS
                      ) -> dict:
            svc._job(request, job_id, kind)
            expires = int(time.time()) + int(expires_s)
            token = sign(key_bytes, job_id, expires)
            return {"url": f"{prefix}/{job_id}/view?token={token}", "token": token, "expires_unix_s": expires,
                    "expires_s": int(expires_s)}

        @app.get(f"{prefix}/{{job_id}}/view/data", tags=[tag], responses=errors,
                 name=f"{kind.value}_view_data", summary="What the page shows (sections), JSON")
        def data(ctx: Context = Depends(access)) -> dict:
            svc._succeeded(ctx.rec)
            return {"job": ctx.rec.id, "kind": ctx.rec.kind.value, "title": view.title,
                    "finished": ctx.rec.finished, "sections": view.sections(ctx), "pdf": ctx.url("report.pdf")}

        @app.get(f"{prefix}/{{job_id}}/view/report.pdf", tags=[tag], responses={**errors, 200: {
                 "content": {"application/pdf": {}}, "description": "the printable report (A4 pages)"}},
                 name=f"{kind.value}_view_pdf", summary="The printable report of the job's page (PDF)")
        def report_pdf(ctx: Context = Depends(access)):
            svc._succeeded(ctx.rec)
            pdf = printable(ctx, view)
            return Response(pdf, media_type="application/pdf", headers={
                "Content-Disposition": f'attachment; filename="greybench-{view.kind.value}-{ctx.rec.id[:8]}.pdf"',
                "Cache-Control": "private, max-age=3600"})

        @app.get(f"{prefix}/{{job_id}}/view/files/{{name:path}}", tags=[tag], responses=errors,
                 name=f"{kind.value}_view_file",
                 response_class=FileResponse, summary="A result file of the job (download)")
        def file(ctx: Context = Depends(access), name: str = PathParam(max_length=300)):
            digests = ctx.request.app.state.store.files(ctx.rec.id) or {}
            svc._succeeded(ctx.rec)
            if name not in digests:
                raise NotFound(f"no file '{name[:100]}' in job {ctx.rec.id}")
            inside(ctx.job_dir, *name.split("/"))
            return ctx.read(name, lambda p: FileResponse(p, filename=p.name))

        if kind.value != "simulation":
            return

        def workpiece(ctx: Context, pose: str):
            check_name(pose, "pose")
            svc._succeeded(ctx.rec)
            name = f"workpiece/{pose}.npz"
            digests = ctx.request.app.state.store.files(ctx.rec.id) or {}
            if name not in digests:
                raise NotFound(f"no virtual workpiece for pose '{pose}' in job {ctx.rec.id}")
            vw = ctx.read(name, lambda p: load_workpiece(p, digests[name]))
            return vw, (ctx.rec.id, pose, digests[name])

        pose_param = PathParam(pattern=NAME_PATTERN, description="pose name")
        binary: Responses = {200: {"content": {"application/octet-stream": {}},
                               "description": "uint32 header length, JSON header, raw little-endian arrays"}}

        @app.get(f"{prefix}/{{job_id}}/view/workpiece/{{pose}}/mesh", tags=[tag], responses={**errors, **binary},
                 name=f"{kind.value}_view_mesh",
                 summary="Surface mesh of a pose's virtual workpiece (binary: vertices [mm], triangles)")
        def mesh(ctx: Context = Depends(access), pose: str = pose_param):
            vw, key = workpiece(ctx, pose)
            return binary_response(ctx.request, mesh_bytes(mesh_of(vw, key)))

        @app.get(f"{prefix}/{{job_id}}/view/workpiece/{{pose}}/values", tags=[tag], responses={**errors, **binary},
                 name=f"{kind.value}_view_values",
                 summary="Per-vertex values of a variable in its display unit (binary, float32)")
        def values(ctx: Context = Depends(access), pose: str = pose_param,
                   variable: Annotated[ViewVariable, Query(description="the variable to colour by")] =
                   ViewVariable.deflection):
            vw, key = workpiece(ctx, pose)
            return binary_response(ctx.request, values_bytes(vw, mesh_of(vw, key), variable.value))

        @app.get(f"{prefix}/{{job_id}}/view/workpiece/{{pose}}/click", tags=[tag], responses=errors,
                 name=f"{kind.value}_view_click",
                 summary="Program lines, time stamps, reversing axes and error components at a point")
        def click_point(ctx: Context = Depends(access), pose: str = pose_param,
                        x_mm: float = Query(..., allow_inf_nan=False, description="point x [mm], workpiece frame"),
                        y_mm: float = Query(..., allow_inf_nan=False, description="point y [mm]"),
                        z_mm: float = Query(..., allow_inf_nan=False, description="point z [mm]"),
                        radius_mm: float = Query(CLICK_RADIUS_MM, gt=0, le=50, allow_inf_nan=False,
                                                 description="search radius [mm]")) -> dict:
            vw, _ = workpiece(ctx, pose)
            return click(vw, ctx.job_dir / "program.nc", (x_mm, y_mm, z_mm), radius_mm)

        @app.get(f"{prefix}/{{job_id}}/view/workpiece/{{pose}}/box", tags=[tag], responses=errors,
                 name=f"{kind.value}_view_box", summary="Program lines that cut the machined surface inside a box")
        def box_select(ctx: Context = Depends(access), pose: str = pose_param,
                       min_mm: str = Query(..., max_length=100, description="corner x,y,z [mm]"),
                       max_mm: str = Query(..., max_length=100, description="opposite corner x,y,z [mm]")) -> dict:
            vw, _ = workpiece(ctx, pose)
            return box(vw, ctx.job_dir / "program.nc", _xyz(min_mm, "min_mm"), _xyz(max_mm, "max_mm"))

    for view in list(VIEWS.values()):
        for_kind(view)


def _xyz(text: str, field: str) -> list[float]:
    try:
        v = [float(s) for s in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3 or not all(np.isfinite(v)):
        raise InputError(f"expected three finite numbers x,y,z in mm, got '{text[:60]}'", field=field)
    return v
