"""Canned drilling cycles ``G73``, ``G81``, ``G82``, ``G83`` expanded into straight moves.

The semantics are RS-274/NGC's as LinuxCNC's interpreter implements them
(``src/emc/rs274ngc/interp_cycles.cc``, ``convert_cycle_xy`` and ``convert_cycle_g8x``; docs/gcode.md),
in the XY plane (``G17``), one hole per call:

1. If the initial level is below the R plane: rapid straight up to R (the initial level is then R).
2. Rapid in XY to the hole at the current height, rapid down to R.
3. The cycle from R:

   - ``G81``: feed to the bottom Z.
   - ``G82``: feed to the bottom, dwell ``P`` seconds there.
   - ``G83`` (peck, full retract): feed down by ``Q``, rapid out to R, rapid back to
     ``RAPID_DELTA`` above the depth reached; repeat while the next depth is above the bottom, then
     feed to the bottom.
   - ``G73`` (peck, chip break): as ``G83`` but the retract is ``RAPID_DELTA`` only.

4. Rapid out to the clearance level: the initial level (``G98``) or R (``G99``).

All heights are in the placement frame (m), already resolved from the program's ``R`` and ``Z``.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

#: m, LinuxCNC's G83_RAPID_DELTA (0.010 inch): the re-approach clearance of G83 and the retract of G73
RAPID_DELTA = 0.010 * 0.0254


class DrillCycle(IntEnum):
    """The supported canned cycles, by G number."""

    G73 = 73
    G81 = 81
    G82 = 82
    G83 = 83


@dataclass(frozen=True)
class CycleLevels:
    """Heights of one hole, m (placement frame z).

    Attributes
    ----------
    initial : float
        Z before the first cycle of this series (the ``G98`` retract level).
    r : float
        The R plane (feeds start here; the ``G99`` retract level).
    bottom : float
        The hole bottom (``Z``). Must not be above ``r``.
    retract_to_r : bool
        ``G99`` (retract to R) instead of ``G98`` (retract to the initial level).
    """

    initial: float
    r: float
    bottom: float
    retract_to_r: bool = False


@dataclass(frozen=True)
class CycleMove:
    """One straight move of an expanded cycle: ``end`` (3,), m; ``rapid``; ``dwell`` s at the end."""

    end: np.ndarray
    rapid: bool
    dwell: float = 0.0


def drill_moves(cycle: DrillCycle, start: np.ndarray, hole_xy: tuple[float, float], levels: CycleLevels, *,
                peck: float = 0.0, dwell: float = 0.0) -> list[CycleMove]:
    """Moves of one hole from ``start`` (3,), m (docstring of the module). Zero-length moves are kept
    (the caller drops them).

    Parameters
    ----------
    peck : float
        m, ``Q`` of ``G73``/``G83`` (> 0).
    dwell : float
        s, ``P`` of ``G82``.
    """
    if levels.bottom > levels.r:
        raise ValueError("R plane below the hole bottom")
    if cycle in (DrillCycle.G73, DrillCycle.G83) and not peck > 0:
        raise ValueError("peck Q must be > 0")
    x, y = hole_xy
    moves: list[CycleMove] = []
    z = float(start[2])
    initial = levels.initial
    if initial < levels.r:
        moves.append(CycleMove(np.array([start[0], start[1], levels.r]), rapid=True))
        initial = z = levels.r
    clear = levels.r if levels.retract_to_r else initial

    def go(h: float, rapid: bool, pause: float = 0.0) -> None:
        moves.append(CycleMove(np.array([x, y, h]), rapid=rapid, dwell=pause))

    go(z, rapid=True)
    go(levels.r, rapid=True)
    if cycle in (DrillCycle.G73, DrillCycle.G83):
        k = 1
        # depths r - k q strictly above the bottom are pecks (a float margin of 1e-12 m keeps an exact
        # multiple from adding a zero-depth peck)
        while levels.r - k * peck > levels.bottom + 1e-12:
            depth = levels.r - k * peck
            go(depth, rapid=False)
            if cycle == DrillCycle.G83:
                go(levels.r, rapid=True)
            go(depth + RAPID_DELTA, rapid=True)
            k += 1
    go(levels.bottom, rapid=False, pause=dwell if cycle == DrillCycle.G82 else 0.0)
    go(clear, rapid=True)
    return moves
