"""Where the gears float in their play: each joint's flank changes per program section or line.

A gear changes its state (on the positive flank, in the play, on the negative flank; the drive's
:class:`simulate.robot.drive.Contact`) where the torque it transmits changes sign. At a joint's
velocity reversal that happens once or twice. Where the transmitted torque stays near zero for a
while (in machining: the process torque about the joint nearly cancels its friction, as in climb
milling along a wall), the link leaves its flank and comes back many times a second and the tool
rattles by up to the play times the lever (docs/drive-model.md, "The 12-14 Hz gear rattle").

No correction of the path holds such a gear on a flank: the correction puts the tool on the
nominal surface, so the cut there, and with it the process torque, is the nominal one
(docs/compensation.md). The compensation report therefore lists, per line of the original program
and joint, the flank changes before and after where the corrected program leaves a gear rattling
(:func:`rattling_gears`).

Sections are named by the program's own comments: a section starts at a line that holds only a
comment and runs to the line before the next such line (a run of comment lines is one section,
named by its last comment, so a header's comments name the set-up lines after them).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from simulate import defaults as DEFAULTS

#: a line holding only a comment, its text
_COMMENT_LINE = re.compile(r"^\s*\(([^()]*)\)\s*$")
#: longest section name kept [characters]
NAME_CHARS = 60
#: flank changes per second [1/s] from which a gear counts as rattling in its play: on iso160 the
#: process-closed rattle of a gear that carries nothing (12-14 Hz, docs/drive-model.md) made 10-29
#: per second along a wall, a slow drift through the play under a near-cancelling load 3-6 per
#: second (as with a constant load and no process) and the reversals of a contour fewer; chosen
#: between them
RATTLE_RATE = 8.0
#: shortest stretch [s] a rattle is looked for on: the cuts along which a gear floats (a test piece's
#: walls, passes, circle and angle runs) take 2-11 s on iso160; corners, lead-ins and step-overs
#: 0.1-0.5 s, where joints reverse and a gear's contact bounces as it changes flank, every cycle a
#: change
MIN_STRETCH = 0.5


@dataclass(frozen=True)
class Section:
    """A program section: lines ``first_line .. last_line`` (1-based, inclusive), named by its comment."""

    name: str
    first_line: int
    last_line: int


@dataclass(frozen=True)
class GearPlay:
    """One joint's gear over one program section or line.

    Attributes
    ----------
    section : str
        The section's name (its comment).
    line : int or None
        The program line (1-based) where counted per line, None where per section.
    joint : int
        1..6.
    flank_changes : int
        Changes of the gear's state between consecutive 2 ms cycles (leaving a flank or reaching
        one: a crossing of the play from flank to flank counts twice) [-].
    in_play : float
        Share of the stretch's cycles with the gear in its play [-].
    cycles : int
        The stretch's 2 ms cycles [-].
    """

    section: str
    line: int | None
    joint: int
    flank_changes: int
    in_play: float
    cycles: int


def program_sections(text: str) -> list[Section]:
    """The program's sections (module docstring); lines before the first comment form ``"start"``."""
    lines = text.splitlines()
    starts: list[tuple[int, str]] = []
    prev_comment = False
    for i, raw in enumerate(lines, start=1):
        m = _COMMENT_LINE.match(raw)
        if m:
            name = " ".join(m.group(1).split())[:NAME_CHARS] or f"line {i}"
            if prev_comment:
                starts[-1] = (starts[-1][0], name)    # a run of comments: the last one names it
            else:
                starts.append((i, name))
        prev_comment = bool(m)
    if not starts or starts[0][0] > 1:
        starts.insert(0, (1, "start"))
    ends = [s for s, _ in starts[1:]] + [len(lines) + 1]
    return [Section(name, first, end - 1) for (first, name), end in zip(starts, ends, strict=True)]


def gear_play(text: str, line, contact, *, per_line: bool = False) -> list[GearPlay]:
    """Per section of ``text`` (or per program line) with at least two cycles and per joint: flank
    changes and share of the cycles in the play.

    Parameters
    ----------
    text : str
        The program whose lines ``line`` refers to.
    line : array (N,) of int
        Program line of each 2 ms cycle (1-based, :class:`simulate.toolpath.placement.JointTrajectory`);
        cycles with a line < 1 are left out.
    contact : array (N, J) of int
        Each gear's state at the end of each cycle: +1 / -1 on a flank, 0 in the play
        (:attr:`simulate.machining.simulation.MachiningResult.joint_contact`).
    per_line : bool
        Count per program line (a wall of a contour is usually one line) instead of per section.
    """
    line = np.asarray(line, np.int64)
    contact = np.asarray(contact)
    if contact.ndim != 2 or contact.shape[0] != line.shape[0]:
        raise ValueError(f"contact {contact.shape} does not match {line.shape[0]} cycles")
    sections = program_sections(text)
    groups: list[tuple[str, int | None, np.ndarray]]
    if per_line:
        firsts = np.array([sec.first_line for sec in sections])
        groups = [(sections[int(np.searchsorted(firsts, v, side="right")) - 1].name, int(v), line == v)
                  for v in np.unique(line[line >= 1])]
    else:
        groups = [(sec.name, None, (line >= sec.first_line) & (line <= sec.last_line)) for sec in sections]
    out = []
    for name, at, sel in groups:
        idx = np.flatnonzero(sel)
        if idx.size < 2:
            continue
        c = contact[idx]
        # only between cycles that follow each other: a stretch entered twice is not one stretch
        follows = np.diff(idx) == 1
        changes = ((np.diff(c, axis=0) != 0) & follows[:, None]).sum(axis=0)
        play = (c == 0).mean(axis=0)
        out += [GearPlay(name, at, j + 1, int(changes[j]), float(play[j]), int(idx.size)) for j in range(c.shape[1])]
    return out


def rattling_gears(before: list[GearPlay], after: list[GearPlay], *, min_changes: int = 10,
                   min_rate: float = RATTLE_RATE, min_time: float = MIN_STRETCH, factor: float = 1.5,
                   cycle: float = DEFAULTS.CYCLE) -> list[tuple[GearPlay | None, GearPlay]]:
    """Sections or lines and joints whose gear rattles after: on a stretch that took at least
    ``min_time`` [s] before (cycles of ``cycle`` [s]; after, where there is no before), at least
    ``min_changes`` flank changes after, at least ``min_rate`` per second [1/s] of the stretch after,
    and at least ``factor`` times as many as before. Returns (before or None where the original has no
    such stretch, after), in the order of the program after.

    Matched by section name, line and joint, the n-th of a kind with the n-th (the corrected program
    keeps the original's comments; count it per line of the original, :func:`gear_play`).
    """
    def keyed(plays):
        seen: dict[tuple, int] = {}
        out = {}
        for p in plays:
            k = (p.section, p.line, p.joint)
            n = seen.get(k, 0)
            seen[k] = n + 1
            out[(*k, n)] = p
        return out

    b = keyed(before)
    out: list[tuple[GearPlay | None, GearPlay]] = []
    for key, a in keyed(after).items():
        was = b.get(key)
        duration = a.cycles * cycle
        # the move's own length decides what it is (a corrected program may slow a step-over down)
        nominal = (was.cycles if was is not None else a.cycles) * cycle
        if (nominal >= min_time and a.flank_changes >= min_changes and a.flank_changes >= min_rate * duration
                and a.flank_changes >= factor * (was.flank_changes if was else 0)):
            out.append((was, a))
    return out
