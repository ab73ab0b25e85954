"""Writing the corrected program: feed lines split into corrected pieces, planned so that every
junction stays passable at the feed.

- **The corrected path as G-code.** Every feed line of the original program is kept and split into
  pieces of the same kind (G1 lines stay lines, G2/G3 arcs become shorter arcs of the same
  direction with the centre moved onto the bisector of the corrected end points), whose end points
  carry the correction; a line is split until the piecewise path is within ``fit_tolerance`` of the
  corrected samples. F, S, T and M words are kept (F on the first piece, as programmed), rapids and
  all other lines are copied unchanged, so the program stays the same program with the same feeds.
  The program switches on ``G64`` before its first feed move: junctions the interpolator can cross at
  the feed are blended (speed and acceleration carried across, the path kept exactly,
  :mod:`simulate.toolpath.interpolation`), and the pieces are planned so that every junction of the
  correction is such a junction (``CompensationSettings.blend``), so the dense pieces keep the feed.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from identify.errors import InputError
from simulate.compensation.path import Correction, NominalPath, SmoothCorrection, seg_point, seg_tangent
from simulate.compensation.settings import GRID, CompensationSettings
from simulate.toolpath.gcode import Arc, Linear, _words
from simulate.toolpath.interpolation import PathLimits


@dataclass
class WrittenProgram:
    """A corrected program and where its pieces lie on the nominal path.

    Attributes
    ----------
    text : str
    pieces : dict of int to (int, float, float)
        Output line (1-based) -> (nominal segment, start fraction, end fraction).
    n_pieces : int
    """

    text: str
    pieces: dict
    n_pieces: int


def _fmt(v: float) -> str:
    s = f"{v:.6f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


_PLANE_OF = {2: (17, (0, 1)), 1: (18, (2, 0)), 0: (19, (1, 2))}   # normal axis -> (G code, in-plane axes)


def _arc_piece(seg: Arc, a: np.ndarray, b: np.ndarray):
    """Centre (3,) [m] of the sub-arc from a to b: the nominal centre moved onto the chord's bisector."""
    n_ax = int(np.argmax(np.abs(seg.normal)))
    _, (i, j) = _PLANE_OF[n_ax]
    pa, pb, c = a[[i, j]], b[[i, j]], seg.center[[i, j]]
    chord = pb - pa
    d = float(np.linalg.norm(chord))
    mid = 0.5 * (pa + pb)
    if d > 0:
        u = chord / d
        c = c - np.dot(c - mid, u) * u
    centre = a.copy()
    centre[i], centre[j] = c
    return centre, (i, j)


def _piece_error(seg, a, b, pts, frac) -> float:
    """Largest distance [m] of target points from the piece a -> b of the kind of ``seg``."""
    if len(pts) == 0:
        return 0.0
    if isinstance(seg, Linear):
        d = b - a
        L = float(np.linalg.norm(d))
        rel = pts - a
        if L == 0:
            return float(np.linalg.norm(rel, axis=1).max())
        d = d / L
        perp = rel - (rel @ d)[:, None] * d
        return float(np.linalg.norm(perp, axis=1).max())
    centre, (i, j) = _arc_piece(seg, a, b)
    n = seg.normal
    r = float(np.linalg.norm(a[[i, j]] - centre[[i, j]]))
    v = pts[:, [i, j]] - centre[[i, j]]
    radial = np.abs(np.linalg.norm(v, axis=1) - r)
    axial = np.abs((pts - (a + frac[:, None] * (b - a))) @ n)   # rise linear in the arc fraction
    return float(np.sqrt(radial ** 2 + axial ** 2).max())


def _split(seg, target: Callable, ua: float, ub: float, s: CompensationSettings, out: list,
           shortest: Callable) -> None:
    """Split [ua, ub] of a nominal segment until the piece is within ``fit_tolerance`` of the target
    (not below ``shortest(ua, ub)`` [m])."""
    L = seg.length * (ub - ua)
    long = s.max_piece < L or (isinstance(seg, Arc) and abs(seg.sweep) * (ub - ua) > math.pi / 4)
    if 2 * shortest(ua, ub) <= L or long:
        n = max(3, int(math.ceil(L / GRID)))
        uu = np.linspace(ua, ub, n + 1)[1:-1]
        a, b = target(np.array([ua]))[0], target(np.array([ub]))[0]
        err = _piece_error(seg, a, b, target(uu), (uu - ua) / (ub - ua))
        if long or err > s.fit_tolerance:
            um = 0.5 * (ua + ub)
            _split(seg, target, ua, um, s, out, shortest)
            _split(seg, target, um, ub, s, out, shortest)
            return
    out.append((ua, ub))


def junction_limit(feed: float, limits: PathLimits, blend: bool = False) -> float:
    """Largest direction change [rad] at a junction the interpolator passes at ``feed`` [m/s]: 90 % of its
    junction rule ``v dt / T^2 <= beta J``, or with ``blend`` (``G64``) 90 % of its blending rule
    ``dt (v / T^2 + A / T) <= beta J`` (:mod:`simulate.toolpath.interpolation`)."""
    v = max(min(feed, limits.max_speed), 1e-6)
    T = limits.cycle
    per_rad = v / T ** 2 + (limits.acceleration / T if blend else 0.0)
    return 0.9 * limits.junction_jerk_share * limits.jerk / per_rad


def _piece_tangents(segs, seg_i: np.ndarray, a: np.ndarray, b: np.ndarray):
    """Unit tangents (K, 3) at the start and the end of pieces a -> b of the kinds of ``segs[seg_i]``
    (sub-arcs: centre on the bisector, as written)."""
    d = b - a
    ta = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-15)
    tb = ta.copy()
    arc = np.array([isinstance(segs[i], Arc) for i in seg_i])
    if arc.any():
        k = np.flatnonzero(arc)
        n = np.array([segs[i].normal for i in seg_i[k]])
        sign = np.sign([segs[i].sweep for i in seg_i[k]])[:, None]
        cn = np.array([segs[i].center for i in seg_i[k]])

        def plane(x):
            return x - np.sum(x * n, axis=1, keepdims=True) * n

        ap, bp, cp = plane(a[k]), plane(b[k]), plane(cn)
        ch = bp - ap
        u = ch / np.maximum(np.linalg.norm(ch, axis=1, keepdims=True), 1e-15)
        mid = 0.5 * (ap + bp)
        c = cp - np.sum((cp - mid) * u, axis=1, keepdims=True) * u
        ra, rb = ap - c, bp - c
        r = np.linalg.norm(ra, axis=1, keepdims=True)
        ang = np.abs(np.arctan2(np.linalg.norm(np.cross(ra, rb), axis=1), np.sum(ra * rb, axis=1)))[:, None]
        rise = np.sum(d[k] * n, axis=1, keepdims=True)
        for t, rv in ((ta, ra), (tb, rb)):
            tin = sign * np.cross(n, rv) / np.maximum(r, 1e-15)
            v = tin * r * ang + n * rise
            t[k] = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-15)
    return ta, tb


def plan_pieces(path: NominalPath, correction: Correction | SmoothCorrection, s: CompensationSettings,
                limits: PathLimits | None = None, shortest: float = 0.05e-3) -> dict:
    """Pieces (start, end fraction) of every feed segment: split until within ``fit_tolerance``, then
    further where the correction turns the path at a junction by more than the interpolator passes at
    the original program's speed there (:func:`junction_limit`), down to ``shortest`` [m]: a polyline
    through a curved correction turns by about its curvature times the piece length.

    Within ``s.ramp`` [m] of where the original program changes speed (below 95 % of the feed), pieces
    stay at least ``ramp`` long: the interpolator holds the acceleration at zero at every junction, so a chain of short
    pieces could only change speed slowly and the program would take longer.
    """
    lim = limits or PathLimits()
    if s.blend and isinstance(correction, Correction):
        correction = correction.smooth()
    # blended junctions (G64) carry the acceleration: short pieces need not be longer where the speed changes
    ramp = 0.0 if s.blend else s.ramp
    segs = path.segments
    it = path.setup.interp
    s_nom, v_nom = np.asarray(it.s, float), np.asarray(it.v, float)

    def speed(sig):
        return np.interp(sig, s_nom, v_nom)

    # arc lengths where the original runs below 95 % of its feed (speeding up or slowing down)
    feed_c = np.array([min(seg.feed, lim.max_speed) for seg in segs])[np.asarray(it.segment)]
    slow_s = np.sort(s_nom[(v_nom < 0.95 * feed_c) & (path.run[np.asarray(it.segment)] >= 0)])

    def cruising(sa, sb, feed=None):
        """No speed change of the original within ``ramp`` of [sa, sb]."""
        lo = np.searchsorted(slow_s, np.asarray(sa) - ramp, side="left")
        hi = np.searchsorted(slow_s, np.asarray(sb) + ramp, side="right")
        return hi == lo

    plan: dict = {}
    for i, seg in enumerate(segs):
        if path.run[i] < 0:
            continue
        r, s0, L = int(path.run[i]), path.sigma0[i], seg.length

        def target(u, seg=seg, r=r, s0=s0, L=L):
            return seg_point(seg, u) + correction.at(r, s0 + np.asarray(u) * L)

        def short(ua, ub, s0=s0, L=L, feed=seg.feed):
            return s.min_piece if cruising(s0 + ua * L, s0 + ub * L, feed) else max(ramp, s.min_piece)

        spans: list = []
        _split(seg, target, 0.0, 1.0, s, spans, short)
        plan[i] = spans
    for r in range(len(path.runs)):
        idx = [i for i in plan if path.run[i] == r]
        for _ in range(30):
            seg_i = np.array([i for i in idx for _ in plan[i]])
            ua = np.array([a for i in idx for a, _ in plan[i]])
            ub = np.array([b for i in idx for _, b in plan[i]])
            lengths = np.array([segs[i].length for i in seg_i])
            feed = np.array([segs[i].feed for i in seg_i])
            sa = path.sigma0[seg_i] + ua * lengths
            sb = path.sigma0[seg_i] + ub * lengths
            a, b = correction.at(r, sa), correction.at(r, sb)
            for i in np.unique(seg_i):   # one call per segment: points of all its pieces
                m = seg_i == i
                a[m] += seg_point(segs[i], ua[m])
                b[m] += seg_point(segs[i], ub[m])
            a[0] = segs[seg_i[0]].start   # the run starts at the rapid's uncorrected end
            ta, tb = _piece_tangents(segs, seg_i, a, b)
            turn = np.linalg.norm(ta[1:] - tb[:-1], axis=1)
            # the original's own direction changes between its segments are not the correction's
            edge = seg_i[1:] != seg_i[:-1]
            for k in np.flatnonzero(edge):
                t1 = seg_tangent(segs[seg_i[k]], np.array([1.0]))[0]
                t2 = seg_tangent(segs[seg_i[k + 1]], np.array([0.0]))[0]
                turn[k] = max(0.0, turn[k] - float(np.linalg.norm(t2 - t1)))
            # blended (G64): every junction blendable at the feed cap, wherever the original slows down
            v_j = np.minimum(feed[:-1], feed[1:])
            if not s.blend:
                v_j = np.minimum(speed(sb[:-1]), v_j)
            lim_turn = np.array([junction_limit(v, lim, s.blend) for v in v_j])
            least = np.where(cruising(sa, sb, feed), shortest, max(ramp, shortest))
            if s.blend:
                # the curvature limit is the blending rule for one junction per cycle: pieces down to half
                # a cycle's travel at the feed keep a path at that curvature blendable
                least = np.minimum(least, 0.5 * np.minimum(feed, lim.max_speed) * lim.cycle)
            long = (sb - sa) > 2 * least
            mark = np.zeros(len(seg_i), bool)
            bad = turn > lim_turn
            mark[:-1] |= bad & long[:-1]
            mark[1:] |= bad & long[1:]
            if not mark.any():
                break
            new: dict = {i: [] for i in idx}
            for kk in range(len(seg_i)):
                i = int(seg_i[kk])
                if mark[kk]:
                    m = 0.5 * (ua[kk] + ub[kk])
                    new[i] += [(ua[kk], m), (m, ub[kk])]
                else:
                    new[i].append((ua[kk], ub[kk]))
            plan.update(new)
    return plan


def write_program(path: NominalPath, correction: Correction, settings: CompensationSettings,
                  header: str = "") -> WrittenProgram:
    """The corrected program's text (module docstring): feed lines split into corrected pieces.

    Raises ``InputError`` for a program in incremental coordinates (G91): its later lines would
    inherit the correction.
    """
    segs = path.segments
    by_line = {s.line: i for i, s in enumerate(segs) if path.run[i] >= 0}
    # the pieces' end points through the spline under G64
    read: Correction | SmoothCorrection = correction.smooth() if settings.blend else correction
    plan = plan_pieces(path, read, settings)
    unit = 1e-3
    out_lines: list[str] = []
    pieces: dict = {}
    n_pieces = 0
    src = str(path.setup.program)
    lines = path.text.splitlines()
    header_done = not header
    blend_done = False
    for lineno, raw in enumerate(lines, start=1):
        words = _words(raw, src, lineno) if raw.strip() != "%" else []
        for letter, value, _wtext, col in words:
            if letter == "G" and int(value) in (20, 21):
                unit = 0.0254 if int(value) == 20 else 1e-3
            if letter == "G" and int(value) == 91:
                raise InputError("incremental coordinates (G91) cannot be compensated: program in G90",
                                 source=src, line=lineno, column=col)
        if not header_done and raw.strip() and raw.strip() != "%":
            out_lines.append(f"({header})")
            header_done = True
        i = by_line.get(lineno)
        if i is None:
            out_lines.append(raw)
            continue
        if settings.blend and not blend_done:
            out_lines.append("G64 (continuous path: the corrected pieces keep the feed across their junctions)")
            blend_done = True
        seg = segs[i]
        r = int(path.run[i])
        s0, L = path.sigma0[i], seg.length

        def target(u, seg=seg, r=r, s0=s0, L=L):
            return seg_point(seg, u) + read.at(r, s0 + np.asarray(u) * L)

        spans = plan[i]
        keep_g = [w for w in words if w[0] == "G" and int(w[1]) not in (0, 1, 2, 3)]
        first_words = [w[2] for w in words if w[0] == "N"] + [w[2] for w in keep_g]
        tail = [w[2] for w in words if w[0] in "FST"]
        m_first = [w[2] for w in words if w[0] == "M" and int(w[1]) not in (2, 5, 30)]
        m_last = [w[2] for w in words if w[0] == "M" and int(w[1]) in (2, 5, 30)]
        motion = "G1" if isinstance(seg, Linear) else ("G3" if seg.sweep > 0 else "G2")
        def rounded(v, unit=unit):
            return np.round(v / unit, 6) * unit   # as printed: the controller starts the next piece there

        a = rounded(target(np.array([0.0]))[0])
        if i == 0 or path.run[i - 1] != r:
            a = seg.start   # a run starts where the rapid before it ended, uncorrected
        for k, (ua, ub) in enumerate(spans):
            b = rounded(target(np.array([ub]))[0])
            parts = list(first_words) if k == 0 else []
            parts.append(motion)
            parts += [f"{ax}{_fmt(b[m] / unit)}" for m, ax in enumerate("XYZ")]
            if isinstance(seg, Arc):
                centre, (pi, pj) = _arc_piece(seg, a, b)
                letters = {0: "I", 1: "J", 2: "K"}
                parts += [f"{letters[m]}{_fmt((centre[m] - a[m]) / unit)}" for m in (pi, pj)]
            if k == 0:
                parts += tail + m_first
            if k == len(spans) - 1:
                parts += m_last
            out_lines.append(" ".join(parts))
            pieces[len(out_lines)] = (i, ua, ub)
            n_pieces += 1
            a = b
    return WrittenProgram("\n".join(out_lines) + "\n", pieces, n_pieces)
