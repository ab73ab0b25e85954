"""The segments a G-code program is read into: straight moves and arcs (SI units, workpiece frame).

Their own module so that the reader (:mod:`simulate.toolpath.gcode`) and the transformations of its
output (cutter compensation, :mod:`simulate.toolpath.cutter_comp`) share them without importing
each other.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Linear:
    """A straight move.

    Attributes
    ----------
    start, end : numpy.ndarray, shape (3,)
        Tool tip (TCP) positions in the workpiece frame, m.
    feed : float
        Programmed path speed, m/s (for rapids: the feed modal at that time, unused).
    rapid : bool
        ``True`` for ``G0`` (the interpolator uses its rapid speed instead of ``feed``).
    line : int
        1-based line of the program that commanded this move.
    spindle : float
        Spindle speed, rev/s (0 when off).
    tool : int
        Tool in the spindle: the ``T`` of the last ``M6`` (a ``T`` after it only preselects the
        next tool), or the last ``T`` while no ``M6`` has come; 0 if none was selected.
    blend : bool
        ``G64`` (continuous-path blending) was active for this move; ``False`` under ``G61``.

    blend_tolerance : float
        m, the ``G64 P`` tolerance in force (0 when none was given or under ``G61``). The
        interpolator never rounds a corner (it blends only junctions it can pass on the exact path),
        so the path deviation is 0 and always within this tolerance; it is kept for the record.
    spindle_ccw : bool
        The spindle turns counter-clockwise (``M4``); ``False`` for ``M3`` or a stopped spindle.
        ``spindle`` stays a positive speed either way.
    retract : bool
        A ``G53`` or ``G28`` move: given in machine coordinates (the placement frame, no work
        offset). For a robot these are retracts and returns, not cuts.
    dwell : float
        s, pause at the end of the move (``G4 P`` after it, ``G82 P`` at the hole bottom).
        Recorded only: the interpolator does not hold there.
    """

    start: np.ndarray
    end: np.ndarray
    feed: float
    rapid: bool
    line: int
    spindle: float = 0.0
    tool: int = 0
    blend: bool = False
    blend_tolerance: float = 0.0
    spindle_ccw: bool = False
    retract: bool = False
    dwell: float = 0.0

    @property
    def length(self) -> float:
        """Path length, m."""
        return float(np.linalg.norm(self.end - self.start))


@dataclass(frozen=True)
class Arc:
    """A circular (or helical) move, kept exact.

    Attributes
    ----------
    start, end : numpy.ndarray, shape (3,)
        Programmed end points in the workpiece frame, m. Both lie exactly on the circle.
    center : numpy.ndarray, shape (3,)
        Circle centre, m, in the plane of ``start`` (a helix rises from there along ``normal``).
    normal : numpy.ndarray, shape (3,)
        Unit normal of the arc plane (+z for G17, +y for G18, +x for G19).
    radius : float
        m.
    sweep : float
        Signed sweep angle, rad: positive = counter-clockwise about ``normal`` (``G3``),
        negative = clockwise (``G2``); a full circle is +-2 pi.
    feed : float
        Programmed path speed, m/s.
    line : int
        1-based program line.
    spindle : float
        Spindle speed, rev/s (0 when off).
    tool : int
        Tool in the spindle (as for :class:`Linear`).
    blend : bool
        ``G64`` was active for this move.

    blend_tolerance : float
        m, the ``G64 P`` tolerance in force (0 when none was given or under ``G61``). The
        interpolator never rounds a corner (it blends only junctions it can pass on the exact path),
        so the path deviation is 0 and always within this tolerance; it is kept for the record.
    spindle_ccw : bool
        The spindle turns counter-clockwise (``M4``); ``False`` for ``M3`` or a stopped spindle.
        ``spindle`` stays a positive speed either way.
    dwell : float
        s, pause at the end of the move (``G4 P``), as for :class:`Linear`.
    """

    start: np.ndarray
    end: np.ndarray
    center: np.ndarray
    normal: np.ndarray
    radius: float
    sweep: float
    feed: float
    line: int
    spindle: float = 0.0
    tool: int = 0
    blend: bool = False
    blend_tolerance: float = 0.0
    spindle_ccw: bool = False
    dwell: float = 0.0

    @property
    def rise(self) -> float:
        """Helix rise along ``normal`` from start to end, m (0 for a planar arc)."""
        return float(np.dot(self.end - self.start, self.normal))

    @property
    def length(self) -> float:
        """Path length (helix length), m."""
        return float(math.hypot(self.radius * abs(self.sweep), self.rise))

    def point_at(self, fraction: np.ndarray) -> np.ndarray:
        """Points at path fractions ``0..1`` (arc length / length), shape (N, 3), m."""
        fraction = np.asarray(fraction, dtype=float)
        u = (self.start - self.center)
        u = u - np.dot(u, self.normal) * self.normal
        u = u / np.linalg.norm(u)
        w = np.cross(self.normal, u)
        phi = self.sweep * fraction
        return (self.center[None, :] + self.radius * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w)
                + (self.rise * fraction)[:, None] * self.normal[None, :])


Segment = Linear | Arc
