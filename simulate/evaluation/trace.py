"""Trace a surface area of the virtual workpiece back to time stamps and program lines (paper 3.8:
"select workpiece surface areas ... to gather a set of assigned timestamps").

Every dexel end made by the simulation stores the index of the 2 ms step that created it; the step
table holds that step's time, program line, force, deflection, tracking error and switching bits.
A trace collects the machined ends within ``radius`` of a point (workpiece frame) and groups them by
program line with their time span and the largest deflection and force among them.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from identify.errors import InputError

#: File names inside a virtual-workpiece folder written by ``rank-poses``.
WORKPIECE_FILE = "workpiece.npz"
META_FILE = "meta.json"


@dataclass(frozen=True)
class TraceLine:
    """Dexel ends near the point that one program line created.

    Attributes
    ----------
    line : int
        1-based program line.
    text : str
        The program line ('' when the program is not available).
    t_first, t_last : float
        s, first and last step time among these ends.
    n_ends : int
    max_deflection : float
        m, largest |deflection| of the creating steps.
    max_force : float
        N, largest |force| of the creating steps.
    switching : int
        OR of the switching bits of the creating steps (bit i-1: axis i stopped or reversed).
    """

    line: int
    text: str
    t_first: float
    t_last: float
    n_ends: int
    max_deflection: float
    max_force: float
    switching: int


@dataclass(frozen=True)
class Trace:
    """Result of :func:`trace_point`.

    Attributes
    ----------
    point : numpy.ndarray, (3,)
        m, workpiece frame.
    radius : float
        m.
    lines : list of TraceLine
        By first time.
    n_ends : int
        Machined ends found (stock-surface ends are not counted).
    times : numpy.ndarray
        s, sorted unique step times of the ends.
    """

    point: np.ndarray
    radius: float
    lines: list[TraceLine]
    n_ends: int
    times: np.ndarray


def resolve_workpiece(path: str | Path) -> tuple[Path, dict]:
    """The ``workpiece.npz`` of a folder (or the file itself) and the folder's ``meta.json`` (or {})."""
    p = Path(path)
    f = p / WORKPIECE_FILE if p.is_dir() else p
    if not f.exists():
        raise InputError(f"no virtual workpiece ({WORKPIECE_FILE}) here; give a pose folder written by "
                         "rank-poses", source=str(p))
    meta = {}
    m = f.parent / META_FILE
    if m.exists():
        try:
            meta = json.loads(m.read_text())
        except json.JSONDecodeError as exc:
            raise InputError(f"invalid JSON: {exc.msg}", source=str(m), line=exc.lineno, column=exc.colno) from None
    return f, meta


def _program_lines(program: str | None) -> list[str]:
    if not program:
        return []
    p = Path(program)
    try:
        return p.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return []


def trace_point(vw, point, radius: float = 1e-3, program: str | None = None) -> Trace:
    """Program lines and times of the machined dexel ends within ``radius`` of ``point``.

    Parameters
    ----------
    vw : simulate.machining.virtual_workpiece.VirtualWorkpiece
    point : array_like, (3,)
        m, workpiece frame.
    radius : float
        m (> 0).
    program : str, optional
        Program file, to show the text of each line.
    """
    p = np.asarray(point, float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise InputError("point must be 3 finite numbers x,y,z", field="point")
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"radius must be > 0, got {radius!r}", field="radius")
    steps = []
    for axis in range(3):
        pts, step, _ = vw.workpiece.ends(axis)
        near = (step >= 0) & (np.sum((pts - p) ** 2, axis=1) <= radius * radius)
        steps.append(step[near])
    st = np.concatenate(steps).astype(np.int64)
    table = vw.steps
    text = _program_lines(program)
    lines: list[TraceLine] = []
    if len(st):
        ln = np.asarray(table.line)[st]
        for line in np.unique(ln):
            s = st[ln == line]
            t = np.asarray(table.t)[s]
            d = np.linalg.norm(np.asarray(table.deflection)[s], axis=1)
            f = np.linalg.norm(np.asarray(table.force)[s], axis=1)
            sw = int(np.bitwise_or.reduce(np.asarray(table.switch)[s].astype(np.int64)))
            lines.append(TraceLine(line=int(line), text=text[line - 1].strip() if 0 < line <= len(text) else "",
                                   t_first=float(t.min()), t_last=float(t.max()), n_ends=int(len(s)),
                                   max_deflection=float(d.max()), max_force=float(f.max()), switching=sw))
        lines.sort(key=lambda x: x.t_first)
    times = np.unique(np.asarray(table.t)[st]) if len(st) else np.zeros(0)
    return Trace(point=p, radius=float(radius), lines=lines, n_ends=int(len(st)), times=times)
