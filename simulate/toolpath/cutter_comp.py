"""Cutter radius compensation ``G41``/``G42`` in the XY plane: the programmed contour -> the tool
centre path, with the RS-274/NGC rules as LinuxCNC's interpreter applies them (docs/gcode.md).

- Every line and arc of the contour is offset by the tool radius ``r`` to the left (``G41``) or
  the right (``G42``) of the direction of travel; an arc keeps its centre, its radius grows by ``r``
  when the tool is outside it and shrinks by ``r`` when inside (a radius <= 0 is refused).
- Entry: the first move with XY motion after ``G41``/``G42`` is a straight line from the current,
  uncompensated point to its programmed end offset perpendicular to it.
- Corners between consecutive moves (at a programmed point ``Q``): tangent joins need nothing; an
  *outside* corner (the tool on the convex side) gets an arc of radius ``r`` about ``Q`` from the
  one offset to the next, turning as the path turns; at an *inside* corner both offsets are cut
  back to their intersection next to ``Q``. A move too short for that (the tool would gouge) is
  refused, as LinuxCNC does.
- Exit: the last compensated move ends at its offset end point; the move after ``G40`` starts there.
- Z-only moves keep the offset XY point; lines may change z (ramps: a cut-back line still ends at
  its programmed z, as LinuxCNC keeps it); helical arcs are refused under compensation.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from simulate.toolpath.segments import Arc, Linear, Segment

_EPS = 1e-12


def _rot_left(v: np.ndarray) -> np.ndarray:
    return np.array([-v[1], v[0]])


@dataclass
class _Offset:
    """One contour move and its offset curve (XY), with the trimmed ends."""

    seg: Segment
    start: np.ndarray      # (2,) offset start (trimmed)
    end: np.ndarray        # (2,) offset end (trimmed)
    centre: np.ndarray | None = None   # arcs: (2,)
    radius: float = 0.0    # arcs: offset radius
    trim_start: float = 0.0  # arcs: angle cut from the start, rad (>= 0, along the travel)
    trim_end: float = 0.0

    @property
    def is_arc(self) -> bool:
        return self.centre is not None


def _tangent(seg: Segment, at_end: bool) -> np.ndarray:
    """Unit XY direction of travel at the start or end of ``seg``."""
    if isinstance(seg, Linear):
        d = (seg.end - seg.start)[:2]
        return d / np.linalg.norm(d)
    p = (seg.end if at_end else seg.start)[:2] - seg.center[:2]
    t = _rot_left(p) / np.linalg.norm(p)
    return t if seg.sweep > 0 else -t


def _offset(seg: Segment, r: float, side: float, err: Callable[[str, int], Exception]) -> _Offset:
    """``side`` +1 for G41 (tool left of the path), -1 for G42."""
    if isinstance(seg, Linear):
        n = side * r * _rot_left(_tangent(seg, False))
        return _Offset(seg, seg.start[:2] + n, seg.end[:2] + n)
    if abs(seg.rise) > 1e-12:
        raise err("a helix (arc with a z move) under cutter compensation is not supported", seg.line)
    # the tool is inside a ccw arc when it is on the left (G41), outside when on the right
    inside = (seg.sweep > 0) == (side > 0)
    radius = seg.radius - r if inside else seg.radius + r
    if radius <= 1e-12:
        raise err(f"tool radius {r * 1e3:.4f} mm is not smaller than the arc radius "
                  f"{seg.radius * 1e3:.4f} mm (the tool does not fit inside the arc)", seg.line)
    c = seg.center[:2]

    def on(p):
        u = p[:2] - c
        return c + radius * u / np.linalg.norm(u)

    return _Offset(seg, on(seg.start), on(seg.end), centre=c.copy(), radius=radius)


def _intersections(a: _Offset, b: _Offset) -> list[np.ndarray]:
    """Points where the (unbounded) offset curves of ``a`` and ``b`` meet."""
    if not a.is_arc and not b.is_arc:
        da, db = a.end - a.start, b.end - b.start
        den = da[0] * db[1] - da[1] * db[0]
        if abs(den) < _EPS * max(np.dot(da, da), np.dot(db, db), _EPS):
            return []
        w = b.start - a.start
        s = (w[0] * db[1] - w[1] * db[0]) / den
        return [a.start + s * da]
    if a.is_arc and b.is_arc:
        assert a.centre is not None and b.centre is not None
        d = float(np.linalg.norm(b.centre - a.centre))
        if d < _EPS or d > a.radius + b.radius or d < abs(a.radius - b.radius):
            return []
        x = (d * d + a.radius ** 2 - b.radius ** 2) / (2 * d)
        h = math.sqrt(max(a.radius ** 2 - x * x, 0.0))
        u = (b.centre - a.centre) / d
        m = a.centre + x * u
        return [m + h * _rot_left(u), m - h * _rot_left(u)]
    line, circ = (a, b) if not a.is_arc else (b, a)
    assert circ.centre is not None
    d = line.end - line.start
    f = line.start - circ.centre
    qa, qb, qc = np.dot(d, d), 2 * np.dot(f, d), np.dot(f, f) - circ.radius ** 2
    disc = qb * qb - 4 * qa * qc
    if disc < 0:
        return []
    sq = math.sqrt(disc)
    return [line.start + t * d for t in ((-qb - sq) / (2 * qa), (-qb + sq) / (2 * qa))]


def _angle_along(o: _Offset, p_from: np.ndarray, p_to: np.ndarray) -> float:
    """Angle (rad, >= 0 along the travel of arc ``o``) from p_from to p_to, in [0, 2 pi)."""
    assert o.centre is not None and isinstance(o.seg, Arc)
    a0 = math.atan2(p_from[1] - o.centre[1], p_from[0] - o.centre[0])
    a1 = math.atan2(p_to[1] - o.centre[1], p_to[0] - o.centre[0])
    d = (a1 - a0) if o.seg.sweep > 0 else (a0 - a1)
    return d % (2 * math.pi)


def _param_on(o: _Offset, p: np.ndarray) -> float:
    """Fraction 0..1 of point ``p`` along the current (trimmed) offset of ``o``."""
    if not o.is_arc:
        d = o.end - o.start
        return float(np.dot(p - o.start, d) / np.dot(d, d))
    assert isinstance(o.seg, Arc)
    full = abs(o.seg.sweep) - o.trim_start - o.trim_end
    along = _angle_along(o, o.start, p)
    if along > full + 1e-9 and along > math.pi:
        along -= 2 * math.pi   # just before the start
    return along / full if full > 0 else 0.0


def _turn(t_in: np.ndarray, t_out: np.ndarray) -> tuple[float, float]:
    return float(t_in[0] * t_out[1] - t_in[1] * t_out[0]), float(np.dot(t_in, t_out))


def compensate(moves: list[Segment], radius: float, left: bool,
               err: Callable[[str, int], Exception]) -> list[Segment]:
    """The tool centre path for ``moves`` (the programmed contour under G41/G42, in order; the first
    move with XY motion is the entry, from the uncompensated point it starts at). Module docstring
    for the rules; ``radius`` in m.

    ``err(message, line)`` builds the exception for a contour that cannot be compensated.
    """
    side = 1.0 if left else -1.0
    # moves with XY motion (an arc always has it, a full circle too); the rest are z-only
    xy = [i for i, s in enumerate(moves) if isinstance(s, Arc) or np.linalg.norm((s.end - s.start)[:2]) > 1e-12]
    if not xy:
        return list(moves)
    if radius == 0.0:
        return list(moves)
    first = xy[0]
    if not isinstance(moves[first], Linear):
        raise err("the first move after G41/G42 must be a straight line (the entry move)", moves[first].line)
    offs = {i: _offset(moves[i], radius, side, err) for i in xy}
    offs[first].start = moves[first].start[:2].copy()   # the entry starts where the tool is
    corner_arcs: dict[int, Arc] = {}   # before move i
    for a_i, b_i in zip(xy, xy[1:], strict=False):
        a, b = offs[a_i], offs[b_i]
        q = moves[b_i].start[:2]
        cross, dot = _turn(_tangent(moves[a_i], True), _tangent(moves[b_i], False))
        if abs(cross) < 1e-9 and dot > 0:
            continue   # tangent: the offsets meet at q + r n
        outside = (cross < 0) if left else (cross > 0)
        if abs(cross) < 1e-9:
            outside = True   # a reversal: around the end point
        if outside:
            z = float(moves[b_i].start[2])
            u0, u1 = a.end - q, b.start - q
            sweep = math.atan2(u0[0] * u1[1] - u0[1] * u1[0], float(np.dot(u0, u1)))
            if abs(cross) < 1e-9:
                sweep = -side * math.pi
            centre = np.array([q[0], q[1], z])
            seg_b = moves[b_i]
            corner_arcs[b_i] = Arc(start=np.array([a.end[0], a.end[1], z]), end=np.array([b.start[0], b.start[1], z]),
                                   center=centre, normal=np.array([0.0, 0.0, 1.0]), radius=radius, sweep=sweep,
                                   feed=seg_b.feed, line=seg_b.line, spindle=seg_b.spindle, tool=seg_b.tool,
                                   blend=seg_b.blend, blend_tolerance=seg_b.blend_tolerance,
                                   spindle_ccw=seg_b.spindle_ccw)
            continue
        pts = _intersections(a, b)
        if not pts:
            raise err("the tool does not fit into the inside corner (the offset paths do not meet)",
                      moves[b_i].line)
        p = min(pts, key=lambda v: float(np.linalg.norm(v - q)))
        fa, fb = _param_on(a, p), _param_on(b, p)
        if not (fa > 1e-9 or a_i == first) or fa > 1 + 1e-9 or fb < -1e-9 or fb >= 1 - 1e-9:
            raise err("a move is too short for the tool radius at this inside corner (the tool would gouge)",
                      moves[b_i].line)
        if a.is_arc:
            a.trim_end += _angle_along(a, p, a.end)
        if b.is_arc:
            b.trim_start += _angle_along(b, b.start, p)
        a.end, b.start = p.copy(), p.copy()

    out: list[Segment] = list(moves[:first])
    for i in range(first, len(moves)):
        seg = moves[i]
        if i not in offs:
            # a z-only move at the offset point the tool has reached
            prev = out[-1].end
            out.append(replace(seg, start=np.array([prev[0], prev[1], seg.start[2]]),
                               end=np.array([prev[0], prev[1], seg.end[2]])))
            continue
        if i in corner_arcs:
            out.append(corner_arcs[i])
        o = offs[i]
        start = seg.start.copy() if i == first else out[-1].end.copy()
        if isinstance(seg, Linear):
            # cutting back moves XY only: a ramp still ends at its programmed z (as LinuxCNC does)
            out.append(replace(seg, start=start, end=np.array([o.end[0], o.end[1], seg.end[2]])))
        else:
            assert o.centre is not None
            z = float(seg.start[2])
            sign = 1.0 if seg.sweep > 0 else -1.0
            sweep = seg.sweep - sign * (o.trim_start + o.trim_end)
            out.append(replace(seg, start=start, end=np.array([o.end[0], o.end[1], z]),
                               center=np.array([o.centre[0], o.centre[1], z]), radius=o.radius, sweep=sweep))
    return out
