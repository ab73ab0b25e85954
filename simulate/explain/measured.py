"""Reading what was measured: a CMM scan (``scan.csv``) or a Table-2 feature deviation table.

Scan: the virtual CMM's format (:mod:`simulate.evaluation.cmm`): header ``feature,x,y,z``, one probe
point per row, workpiece frame, metres. It is read with :func:`simulate.evaluation.cmm.read_scan`
(line-numbered format errors) and then checked against the nominal test piece: every feature must be
one the virtual CMM knows, and every point must lie within :data:`~simulate.explain.comparison.SEARCH`
of its nominal surface; errors name the file, line and field.

Feature table: the ``--json`` output of ``greybench rank-poses`` or its ``ranking.json``
(``{"features": [{"name", "nominal_mm", "tolerance_mm", "deviation_mm": {pose: value}}]}``, mm); the
column of the pose given with ``--name`` is used (or the only one). Files of older versions, with
``"deviation"`` per row and a top-level ``"unit"`` (``"mm"`` or ``"m"``), are read too. Only a
feature-by-feature comparison is possible then.
"""
from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from identify.errors import InputError
from simulate.toolpath.testpiece import TestPiece


@dataclass
class MeasuredScan:
    """Probe points per feature (workpiece frame, m) and their line numbers in the file."""

    points: dict[str, np.ndarray]
    lines: dict[str, np.ndarray]
    source: str


@dataclass
class MeasuredTable:
    """Table-2 deviations (m; the slope angle row as a length, like the table) of one pose."""

    deviations: dict[str, float]
    source: str
    pose: str = ""
    lines: dict[str, int] = field(default_factory=dict)


def _line_numbers(path: Path, n_by_feature: dict[str, int]) -> dict[str, np.ndarray]:
    """File line of every row per feature, in the order :func:`read_scan` returns them."""
    acc: dict[str, list] = {}
    rows = csv.reader(path.read_text(encoding="utf-8").splitlines())
    header = [h.strip().lower() for h in next(rows)]
    col = header.index("feature")
    for lineno, row in enumerate(rows, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        acc.setdefault(row[col].strip(), []).append(lineno)
    return {k: np.asarray(acc.get(k, [0] * n), np.int64) for k, n in n_by_feature.items()}


def read_measured_scan(path: str | Path, piece: TestPiece) -> MeasuredScan:
    """Read and check a scan (module docstring)."""
    from simulate.evaluation.cmm import read_scan
    from simulate.explain.comparison import SEARCH, feature_geometry

    path = Path(path)
    scan = read_scan(path)
    lines = _line_numbers(path, {k: len(v) for k, v in scan.points.items()})
    geos = feature_geometry(piece)
    for name, pts in scan.points.items():
        if name not in geos:
            raise InputError(f"unknown feature '{name}' (known: {', '.join(geos)})", source=str(path),
                             line=int(lines[name][0]), field="feature")
        dev = geos[name].deviation(pts)
        bad = np.nonzero(np.abs(dev) > SEARCH)[0]
        if len(bad):
            i = int(bad[0])
            raise InputError(f"point of '{name}' lies {dev[i] * 1e3:+.3f} mm from the nominal surface (more than "
                             f"{SEARCH * 1e3:g} mm): wrong frame or units (metres expected)?", source=str(path),
                             line=int(lines[name][i]), field="x")
    return MeasuredScan(points=dict(scan.points), lines=lines, source=str(path))


def read_measured_table(path: str | Path, pose: str | None) -> MeasuredTable:
    """Read a feature deviation table (module docstring); values in mm are converted to m."""
    from simulate.evaluation.features import TABLE2

    path = Path(path)
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("measured file not found", source=src) from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc.msg}", source=src, line=exc.lineno, column=exc.colno) from None
    feats = doc.get("features") if isinstance(doc, dict) else None
    if not isinstance(feats, list) or not feats:
        raise InputError("expected an object with a non-empty 'features' list", source=src, field="features")
    unit = doc.get("unit", "mm")   # older files: unit-less "deviation" plus this key
    legacy_scale = {"mm": 1e-3, "m": 1.0}.get(unit)
    known = dict(TABLE2)
    text_lines = text.splitlines()

    def line_of(needle: str) -> int | None:
        for i, ln in enumerate(text_lines, start=1):
            if needle in ln:
                return i
        return None

    out: dict[str, float] = {}
    lines: dict[str, int] = {}
    for i, f in enumerate(feats):
        where = f"features[{i}]"
        if not isinstance(f, dict) or "name" not in f:
            raise InputError("needs a 'name'", source=src, field=where)
        name = f["name"]
        ln = line_of(f'"{name}"')
        if name not in known:
            raise InputError(f"unknown feature row '{name}' (known: {', '.join(known)})", source=src, line=ln,
                             field=f"{where}.name")
        if "deviation_mm" in f:
            key, scale = "deviation_mm", 1e-3
        else:
            if legacy_scale is None:
                raise InputError(f"unit must be 'mm' or 'm', got {unit!r}", source=src, field="unit")
            key, scale = "deviation", legacy_scale
        dv = f.get(key)
        if isinstance(dv, dict):
            if pose is None:
                if len(dv) != 1:
                    raise InputError(f"several poses ({', '.join(dv)}); give --name", source=src, line=ln,
                                     field=f"{where}.{key}")
                pose = next(iter(dv))
            if pose not in dv:
                raise InputError(f"no deviation for pose '{pose}'", source=src, line=ln, field=f"{where}.{key}")
            dv = dv[pose]
        if isinstance(dv, bool) or not isinstance(dv, (int, float)) or not np.isfinite(dv):
            raise InputError(f"{key} must be a finite number, got {dv!r}", source=src, line=ln,
                             field=f"{where}.{key}")
        out[name] = float(dv) * scale
        lines[name] = ln or 0
    return MeasuredTable(deviations=out, source=src, pose=pose or "", lines=lines)


def is_table(path: str | Path) -> bool:
    """A feature table (JSON) rather than a scan (CSV): by suffix, else by the first character."""
    p = Path(path)
    if p.suffix.lower() == ".json":
        return True
    if p.suffix.lower() == ".csv":
        return False
    try:
        head = p.read_text(encoding="utf-8", errors="replace").lstrip()[:1]
    except FileNotFoundError:
        raise InputError("measured file not found", source=str(p)) from None
    return head in "{["
