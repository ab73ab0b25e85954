"""Pre-compensation of a program from the machining simulation (mirror compensation, iterated).

The tool tip the coupled loop predicts is the command plus the robot's deflection plus the servo
tracking error (friction, backlash), per 2 ms interpolation cycle in the workpiece frame
(:class:`simulate.pipeline.MachiningOutcome`). Mirror compensation moves the command against the
predicted deviation from the nominal path,

    x_cmd(k+1) = x_cmd(k) - (x_sim(k) - x_des),

and repeats until the ISO 10791-7 (Table-2) deviations stop improving (Reinl et al., IEEE/ASME AIM
2011; Carriere et al., Int. J. Adv. Manuf. Technol. 110:2361-2375, 2020; ``docs/compensation.md``).

Choices where the method is vague (stated so they can be replaced):

- **Normal deviation only.** The component of the deviation along the nominal path tangent is
  dropped: a shift along the tool's own path changes when a point is cut, not the cut surface, and
  correcting it would re-time the program (the correction must keep the program's feed and time).
- **Correction as a function of the nominal path.** The correction lives on the nominal arc length
  of each feed run (the feed moves between two rapids), on a 0.1 mm grid, smoothed over
  ``smoothing`` (the tool averages shorter detail; coarse dexel grids make the force jumpy). A
  simulated cycle of a corrected program is mapped back to the nominal arc length through the
  piece of the nominal segment it executes (same fraction of the piece).
- **Damped secant (Newton-like) update.** The deflection grows as the tool is moved into the
  wall (deeper cut, larger force), so the plain fixed point contracts only by the factor ``s/(1+s)``
  of that growth. From the second iteration on, the local sensitivity of the deviation to the
  correction, ``g = <de, dc> / <dc, dc>`` over a window of the path, is measured from the last two
  iterations and the step is ``-gain * e / g`` (``g`` clipped to ``[0.25, 1.5]``; ``g = 1`` where
  the correction did not change or the measured ``g`` is not positive: a response that is not local,
  such as a gear changing flank, :func:`update_correction`). With ``g = 1`` this is the mirror update.
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
- **Curvature limit.** The correction's curvature stays within what the interpolator passes at the
  original speed (:func:`limit_curvature`): a drive's own oscillation (gear rattle in the play,
  stick-slip) is not a function of the path and is not copied into the program.
- **Corners.** On an arc whose radius is at most the tool radius (the tool turning round a convex
  corner of the part) the correction is blended between its neighbours' (:func:`blend_corners`).
- **Choosing.** Iterate at most ``iterations`` times; stop after :data:`PATIENCE` iterations in a
  row that do not lower the objective below the lowest so far, or at one outside the contract. The
  result is, among the iterations within the contract that lower the objective (sum of |Table-2
  deviation| when the stock is a test piece, else the RMS normal path deviation) below the
  original's, the lowest objective of those that leave no Table-2 row worse than the original's by
  more than max(10 %, 2 µm) (:func:`worse_rows`), and only if there is none the lowest objective of
  all (:func:`better`): a correction that makes a feature of the part worse is not what a user asks
  for, but where every iteration does, trading much of the sum for one row fewer is no better
  (feasible first, then the objective, as a constrained search ranks its candidates). The
  iteration's outcome swings between iterations (a gear whose flank the corrected cut decides), so
  one worse step does not end it.
"""
from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from identify.errors import InputError
from simulate.pipeline import MachiningJob, ProgramSetup, load_program, run_job
from simulate.toolpath.gcode import Arc, Linear, _words
from simulate.toolpath.interpolation import PathLimits

if TYPE_CHECKING:
    from simulate.evaluation.features import FeatureTable
    from simulate.toolpath.placement import JointTrajectory

#: Grid of the correction along the nominal path [m].
GRID = 1e-4
#: The contract of a correction (not another program).
MAX_OFFSET = 1e-3          # m from the nominal path
TIME_RATIO = (0.8, 1.25)   # compensated / nominal program time [-]
#: Shares of the interpolator's junction jerk the correction's curvature may use, tried in turn until
#: the written program keeps its time contract (:func:`limit_curvature`).
#: Steps of 0.8: the largest share within the contract is kept (a halved share smoothed away much of the
#: correction the contract allowed).
CURVATURE_SHARES = tuple(0.9 * 0.8 ** i for i in range(10))
#: The corrected program keeps the original's feed on the cut: no cycle of a feed move below this share
#: of the original's speed at the same nominal arc length [-] (:func:`keep_speed`).
SPEED_KEEP = 0.95
#: Local rounds of :func:`keep_speed` and the factor on the curvature share where the program was slow.
SPEED_ROUNDS, SPEED_FACTOR = 8, 0.5
#: Iterations in a row that do not lower the lowest objective so far before the iteration stops [-].
PATIENCE = 2
#: A Table-2 row is worse after than before when its |deviation| grew by more than
#: max(WORSE_SHARE |before|, WORSE_FLOOR) [-, m].
WORSE_SHARE, WORSE_FLOOR = 0.1, 2e-6


@dataclass(frozen=True)
class CompensationSettings:
    """How the compensation iterates and writes the corrected program (SI).

    Attributes
    ----------
    iterations : int
        Largest number of corrected programs simulated [-].
    gain : float
        Damping of the update (1: full mirror / secant step) [-], in (0, 1.5].
    secant : bool
        Use the measured sensitivity from the second iteration on (module docstring).
    smoothing : float
        Box window of the deviation along the path [m], applied twice (a triangular kernel of twice
        the width): the tool (10 mm) averages shorter detail, and coarse dexel grids make the force,
        hence the deflection, ripple at the dexel spacing.
    sensitivity_window : float
        Window of the sensitivity estimate along the path [m].
    fit_tolerance : float
        Largest distance of the written pieces from the corrected samples [m].
    max_piece : float
        Longest piece a line or arc is split into [m].
    min_piece : float
        Shortest piece [m] (a line is not split below twice this).
    max_correction : float
        Cap on the correction's magnitude [m] (below the 1 mm contract).
    ramp : float
        Shortest piece [m] within this distance of where the original program changes speed
        (:func:`plan_pieces`).
    blend : bool
        Write ``G64`` (continuous-path blending, :mod:`simulate.toolpath.interpolation`) into the
        corrected program, before its first feed move, and keep every junction of the corrected pieces
        blendable at the programmed feed (:func:`_junction_limit`, :func:`curvature_limit`): the dense
        pieces then carry speed and acceleration across their junctions and the program keeps its
        feed, as an NC's compressor / look-ahead switched on by the program does. Off: the pieces run
        under the default ``G61`` (zero acceleration at every junction).
    keep_speed : bool
        Smooth the correction further where the written program would run slower than the original
        (:func:`keep_speed`); off (default): only the time contract lowers the curvature share. On
        iso160 (before ``blend``) it kept the feed (time 1.01-1.04x instead of 1.21-1.24x) but lost more
        correction than it gained (near: sum ratio 0.58 instead of 0.31; ``docs/compensation.md``).
    """

    iterations: int = 4
    gain: float = 1.0
    secant: bool = True
    smoothing: float = 2e-3
    sensitivity_window: float = 10e-3
    fit_tolerance: float = 0.5e-6
    max_piece: float = 20e-3
    min_piece: float = 0.25e-3
    max_correction: float = 0.5e-3
    ramp: float = 1e-3
    blend: bool = True
    keep_speed: bool = False

    def validate(self) -> None:
        """Raise ``InputError`` naming the setting (as the CLI option) that is out of range."""
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) or not 1 <= self.iterations <= 20:
            raise InputError(f"must be an integer in 1..20, got {self.iterations!r}", field="iterations")
        if not (math.isfinite(self.gain) and 0 < self.gain <= 1.5):
            raise InputError(f"must be in (0, 1.5], got {self.gain!r}", field="gain")
        for name in ("smoothing", "sensitivity_window", "fit_tolerance", "max_piece", "min_piece", "max_correction",
                     "ramp"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"must be > 0, got {v!r}", field=name.replace("_", "-"))
        if self.max_correction >= MAX_OFFSET:
            raise InputError(f"must stay below {MAX_OFFSET * 1e3:g} mm, got {self.max_correction * 1e3:g} mm",
                             field="max-correction")


# ----------------------------------------------------------------------------- nominal path


def _first_index(segs) -> int:
    """Segments the interpolator skips: the opening rapid (see ``interpolate``)."""
    return 1 if len(segs) > 1 and isinstance(segs[0], Linear) and segs[0].rapid else 0


def _is_feed(seg) -> bool:
    return isinstance(seg, Arc) or not seg.rapid


def _seg_point(seg, u: np.ndarray) -> np.ndarray:
    u = np.atleast_1d(np.asarray(u, float))
    if isinstance(seg, Arc):
        return seg.point_at(u)
    return seg.start[None, :] + u[:, None] * (seg.end - seg.start)[None, :]


def _seg_tangent(seg, u: np.ndarray) -> np.ndarray:
    """Unit tangent (N, 3) at fractions u."""
    u = np.atleast_1d(np.asarray(u, float))
    if isinstance(seg, Linear):
        d = (seg.end - seg.start) / seg.length
        return np.repeat(d[None, :], len(u), axis=0)
    ax = seg.start - seg.center
    ax = ax - np.dot(ax, seg.normal) * seg.normal
    ax /= np.linalg.norm(ax)
    w = np.cross(seg.normal, ax)
    phi = seg.sweep * u
    t = (seg.radius * seg.sweep * (-np.sin(phi)[:, None] * ax + np.cos(phi)[:, None] * w)
         + seg.rise * seg.normal[None, :])
    return t / np.linalg.norm(t, axis=1, keepdims=True)


@dataclass
class NominalPath:
    """The original program as a path: segments, arc length, feed runs.

    Attributes
    ----------
    setup : ProgramSetup
    text : str
        The program text.
    sigma0 : ndarray (M,)
        Nominal arc length [m] at the start of each segment (interpolator coordinates).
    run : ndarray of int (M,)
        Feed run of each segment (contiguous feed moves), -1 for rapids.
    runs : list of (float, float)
        Arc length range [m] of each run.
    """

    setup: ProgramSetup
    text: str
    sigma0: np.ndarray
    run: np.ndarray
    runs: list

    @classmethod
    def of(cls, setup: ProgramSetup) -> NominalPath:
        segs = setup.parsed.segments
        first = _first_index(segs)
        sigma0 = np.zeros(len(segs))
        acc = 0.0
        for i, s in enumerate(segs):
            sigma0[i] = acc
            if i >= first:
                acc += s.length
        run = np.full(len(segs), -1, np.int64)
        runs: list = []
        for i, s in enumerate(segs):
            if i < first or not _is_feed(s):
                continue
            if i > 0 and run[i - 1] >= 0:
                run[i] = run[i - 1]
                runs[-1] = (runs[-1][0], sigma0[i] + s.length)
            else:
                run[i] = len(runs)
                runs.append((sigma0[i], sigma0[i] + s.length))
        text = Path(setup.program).read_text(encoding="utf-8")
        return cls(setup, text, sigma0, run, runs)

    @property
    def segments(self):
        return self.setup.parsed.segments

    def frame(self, run: int, sigma: np.ndarray):
        """Path frame at arc lengths [m] of a feed run: unit tangent, sideways normal (horizontal
        where the path is not vertical) and upward normal, each (G, 3)."""
        idx = np.flatnonzero(self.run == run)
        starts = self.sigma0[idx]
        k = idx[np.clip(np.searchsorted(starts, sigma, side="right") - 1, 0, len(idx) - 1)]
        t = np.empty((len(sigma), 3))
        for i in np.unique(k):
            m = k == i
            L = self.segments[i].length
            t[m] = _seg_tangent(self.segments[i], np.clip((sigma[m] - self.sigma0[i]) / L, 0.0, 1.0))
        h = np.cross(np.array([0.0, 0.0, 1.0]), t)
        n = np.linalg.norm(h, axis=1)
        vertical = n < 0.1   # a plunge: any horizontal pair will do
        h[vertical] = np.cross(t[vertical], np.array([1.0, 0.0, 0.0]))
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        v = np.cross(t, h)
        return t, h, v

    def cycles(self):
        """Per nominal cycle: (segment index, fraction of the segment, arc length [m])."""
        it = self.setup.interp
        seg = np.asarray(it.segment, np.int64)
        lengths = np.array([s.length for s in self.segments])
        u = np.clip((it.s - self.sigma0[seg]) / lengths[seg], 0.0, 1.0)
        return seg, u, np.asarray(it.s, float)


@dataclass
class Correction:
    """A correction along the nominal path: per feed run a grid of arc lengths and offsets.

    Attributes
    ----------
    grids : list of ndarray (G,)
        Arc length [m] per run.
    values : list of ndarray (G, 3)
        Offset of the command [m, workpiece frame] per run.
    """

    grids: list
    values: list

    @classmethod
    def zero(cls, path: NominalPath) -> Correction:
        grids = [np.linspace(a, b, max(2, int(math.ceil((b - a) / GRID)) + 1)) for a, b in path.runs]
        return cls(grids, [np.zeros((len(g), 3)) for g in grids])

    def at(self, run: int, sigma: np.ndarray) -> np.ndarray:
        g, v = self.grids[run], self.values[run]
        return np.stack([np.interp(sigma, g, v[:, k]) for k in range(3)], axis=1)

    def on_cycles(self, path: NominalPath) -> np.ndarray:
        """The offset at every nominal cycle (N, 3) [m] (zero on rapids)."""
        seg, _, sig = path.cycles()
        out = np.zeros((len(seg), 3))
        runs = path.run[seg]
        for r in range(len(self.grids)):
            m = runs == r
            if m.any():
                out[m] = self.at(r, sig[m])
        return out

    def max_norm(self) -> float:
        return max((float(np.linalg.norm(v, axis=1).max()) for v in self.values), default=0.0)

    def smooth(self) -> SmoothCorrection:
        """The same correction through a C2 cubic spline (for writing blended pieces)."""
        return SmoothCorrection(self)


class SmoothCorrection:
    """A :class:`Correction` read through a cubic spline of its grid values instead of linearly.

    Why: linear interpolation puts all the bend of one 0.1 mm grid cell into a kink at its node
    (a curvature ``k`` gives a kink of ``k * GRID``: 3.7 mrad at 37 1/m), which pieces shorter than a
    cell turn at a single junction, beyond what a blended junction passes at the feed
    (:func:`_junction_limit`); through the spline a piece of length ``L`` turns by about ``k L``.
    Beyond the grid's ends it holds the end values, as ``np.interp`` does.
    """

    def __init__(self, corr: Correction):
        from scipy.interpolate import CubicSpline

        self.grids = corr.grids
        self.values = corr.values
        self._linear = corr   # runs too short for a spline
        self._spl = [CubicSpline(g, v, axis=0) if len(g) >= 4 else None
                     for g, v in zip(corr.grids, corr.values, strict=True)]

    def at(self, run: int, sigma: np.ndarray) -> np.ndarray:
        g, spl = self.grids[run], self._spl[run]
        sigma = np.atleast_1d(np.asarray(sigma, float))
        if spl is None:
            return self._linear.at(run, sigma)
        return spl(np.clip(sigma, g[0], g[-1]))


# ----------------------------------------------------------------------------- writing the program


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


def _junction_limit(feed: float, limits: PathLimits, blend: bool = False) -> float:
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
    the original program's speed there (:func:`_junction_limit`), down to ``shortest`` [m]: a polyline
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
            return _seg_point(seg, u) + correction.at(r, s0 + np.asarray(u) * L)

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
                a[m] += _seg_point(segs[i], ua[m])
                b[m] += _seg_point(segs[i], ub[m])
            a[0] = segs[seg_i[0]].start   # the run starts at the rapid's uncorrected end
            ta, tb = _piece_tangents(segs, seg_i, a, b)
            turn = np.linalg.norm(ta[1:] - tb[:-1], axis=1)
            # the original's own direction changes between its segments are not the correction's
            edge = seg_i[1:] != seg_i[:-1]
            for k in np.flatnonzero(edge):
                t1 = _seg_tangent(segs[seg_i[k]], np.array([1.0]))[0]
                t2 = _seg_tangent(segs[seg_i[k + 1]], np.array([0.0]))[0]
                turn[k] = max(0.0, turn[k] - float(np.linalg.norm(t2 - t1)))
            # blended (G64): every junction blendable at the feed cap, wherever the original slows down
            v_j = np.minimum(feed[:-1], feed[1:])
            if not s.blend:
                v_j = np.minimum(speed(sb[:-1]), v_j)
            lim_turn = np.array([_junction_limit(v, lim, s.blend) for v in v_j])
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
            return _seg_point(seg, u) + read.at(r, s0 + np.asarray(u) * L)

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



# ----------------------------------------------------------------------------- simulating and measuring


@dataclass
class SimulationRun:
    """One simulated program.

    Attributes
    ----------
    setup : ProgramSetup
        The program simulated (its interpolation).
    tip : ndarray (N, 3)
        Predicted tool tip per 2 ms cycle [m, workpiece frame]: command + deflection + tracking error.
    table : simulate.evaluation.features.FeatureTable or None
        Table-2 deviations (test-piece stock).
    trajectory : simulate.toolpath.placement.JointTrajectory or None
        Commanded joints [rad] per cycle.
    wall_time : float
        [s].
    friction : list of dict
        The friction model used per joint (``{"joint", "kind", "source"}``) when the pipeline says.
    contact : ndarray (N, 6) of int or None
        Each gear's state per cycle (+1 / -1 on a flank, 0 in the play) when the drives ran.
    """

    setup: ProgramSetup
    tip: np.ndarray
    table: FeatureTable | None = None
    trajectory: JointTrajectory | None = None
    wall_time: float = 0.0
    friction: list = field(default_factory=list)
    contact: np.ndarray | None = None


#: ``simulate(setup, stiffness_scale) -> SimulationRun``; ``stiffness_scale`` multiplies the model's.
Simulator = Callable[[ProgramSetup, float], SimulationRun]


def pipeline_simulator(job: MachiningJob, advance=None) -> Simulator:
    """The machining pipeline (:func:`simulate.pipeline.run_job`) with ``job``'s robot, placement,
    friction, components and settings, for any program (same stock)."""
    from simulate.pipeline import _robot

    robot = _robot(job.robot)

    def simulate(setup: ProgramSetup, scale: float = 1.0) -> SimulationRun:
        c0 = time.perf_counter()
        settings = replace(job.settings, stiffness_scale=job.settings.stiffness_scale * scale)
        mo = run_job(replace(job, program=setup, robot=robot, settings=settings), advance=advance)
        st = mo.steps
        tip = np.asarray(mo.trajectory.xyz) + st.deflection + st.tracking_error
        return SimulationRun(setup, tip, mo.table, mo.trajectory, time.perf_counter() - c0, list(mo.friction),
                             mo.result.joint_contact)

    return simulate


def table_sum(table) -> float:
    """Sum of |deviation| over the Table-2 rows [m]."""
    return float(sum(abs(r.deviation) for r in table.rows))


def path_deviation(path: NominalPath, written: WrittenProgram | None, run: SimulationRun, points=None):
    """Deviation of the predicted tip from the nominal path, normal to it, per cycle of ``run``.

    Returns (run index (N,) int, -1 off the feed runs; nominal arc length (N,) [m]; normal
    deviation (N, 3) [m]). A cycle of a corrected program is mapped to the nominal path through the
    fraction of the piece it executes. ``points`` (N, 3) [m] replaces the predicted tip (the
    command gives the correction the written program realises).
    """
    tip = run.tip if points is None else np.asarray(points, float)
    segs = run.setup.parsed.segments
    it = run.setup.interp
    seg = np.asarray(it.segment, np.int64)
    first = _first_index(segs)
    lengths = np.array([s.length for s in segs])
    cum = np.concatenate(([0.0], np.cumsum(lengths[first:])))
    s0 = np.zeros(len(segs))
    s0[first:] = cum[:-1]
    u = np.clip((np.asarray(it.s) - s0[seg]) / np.maximum(lengths[seg], 1e-15), 0.0, 1.0)
    n = len(seg)
    if written is None:
        nseg, unom = seg, u
    else:
        nseg = np.full(n, -1, np.int64)
        unom = np.zeros(n)
        for j in np.unique(seg):
            p = written.pieces.get(segs[j].line)
            if p is None:
                continue
            m = seg == j
            nseg[m] = p[0]
            unom[m] = p[1] + u[m] * (p[2] - p[1])
    runs = np.where(nseg >= 0, path.run[np.maximum(nseg, 0)], -1)
    sigma = np.zeros(n)
    dev = np.zeros((n, 3))
    nom = path.segments
    for i in np.unique(nseg[runs >= 0]):
        m = nseg == i
        x = _seg_point(nom[i], unom[m])
        t = _seg_tangent(nom[i], unom[m])
        d = tip[m] - x
        dev[m] = d - np.sum(d * t, axis=1, keepdims=True) * t
        sigma[m] = path.sigma0[i] + unom[m] * nom[i].length
    return runs, sigma, dev


def _box(x: np.ndarray, width: float) -> np.ndarray:
    from scipy.ndimage import uniform_filter1d

    k = max(1, int(round(width / GRID)))
    return uniform_filter1d(x, size=k, axis=0, mode="nearest") if k > 1 else x


def deviation_field(path: NominalPath, written: WrittenProgram | None, run: SimulationRun,
                    smoothing: float, points=None) -> Correction:
    """The normal deviation of ``run`` (or of ``points``) on the correction grid of every feed run,
    smoothed [m]."""
    runs, sigma, dev = path_deviation(path, written, run, points)
    grid = Correction.zero(path)
    for r, g in enumerate(grid.grids):
        m = runs == r
        if m.sum() < 2:
            continue
        order = np.argsort(sigma[m], kind="stable")
        sg, dv = sigma[m][order], dev[m][order]
        vals = np.stack([np.interp(g, sg, dv[:, k]) for k in range(3)], axis=1)
        # smoothed in the path's own frame (sideways, upwards), so that a deviation that turns with
        # the path round a corner is not shortened by averaging directions; two box passes: a
        # triangular kernel, which also suppresses the force ripple of the dexel grid
        _, h, v = path.frame(r, g)
        side = _box(_box(np.sum(vals * h, axis=1), smoothing), smoothing)
        up = _box(_box(np.sum(vals * v, axis=1), smoothing), smoothing)
        grid.values[r] = side[:, None] * h + up[:, None] * v
    return grid


def update_correction(corr: Correction, dev: Correction, prev: tuple | None,
                      s: CompensationSettings) -> Correction:
    """One damped mirror / secant step (module docstring): ``c - gain * e / g``, capped."""
    out = []
    for r in range(len(corr.grids)):
        c, e = corr.values[r], dev.values[r]
        g = np.ones(len(c))
        if s.secant and prev is not None:
            dc = c - prev[0].values[r]
            de = e - prev[1].values[r]
            num = _box(np.sum(dc * de, axis=1), s.sensitivity_window)
            den = _box(np.sum(dc * dc, axis=1), s.sensitivity_window)
            # a sensitivity <= 0 (a deeper command left the tip further out: not the local response of
            # a deflection, e.g. a gear that changed flank) gets the mirror step; clipped to 0.25 it got
            # the largest step, four times the mirror's, where the measurement is least to be trusted
            ok = (den > (0.5e-6) ** 2) & (num > 0)
            g[ok] = np.clip(num[ok] / den[ok], 0.25, 1.5)
        new = c - s.gain * e / g[:, None]
        norm = np.linalg.norm(new, axis=1, keepdims=True)
        out.append(new * np.minimum(1.0, s.max_correction / np.maximum(norm, 1e-300)))
    return Correction(corr.grids, out)


def blend_corners(path: NominalPath, corr: Correction, tool_radius: float) -> Correction:
    """On arcs of radius at most ``tool_radius`` [m], replace the correction by a blend, linear along
    the arc in the path frame (sideways, upwards), from the correction where the arc starts to where
    it ends.

    Such an arc turns the tool round a convex corner of the part: its flank only touches the corner
    point, so the deviation there is no surface of its own, while correcting it moves the tool into
    the ends of both adjacent walls (a tool pushed in by ``rho`` cuts a wall within ``sqrt(2 R rho)``
    of the corner). Blending keeps each wall's own correction up to the corner.
    """
    out = [v.copy() for v in corr.values]
    for i, seg in enumerate(path.segments):
        r = int(path.run[i])
        if r < 0 or not isinstance(seg, Arc) or seg.radius > tool_radius * (1 + 1e-3):
            continue
        g = corr.grids[r]
        a, b = path.sigma0[i], path.sigma0[i] + seg.length
        m = (g >= a) & (g <= b)
        if m.sum() < 2:
            continue
        ends = np.array([a, b])
        _, h, v = path.frame(r, g[m])
        _, he, ve = path.frame(r, ends)
        ce = corr.at(r, ends)
        w = (g[m] - a) / (b - a)
        side = (1 - w) * np.sum(ce[0] * he[0]) + w * np.sum(ce[1] * he[1])
        up = (1 - w) * np.sum(ce[0] * ve[0]) + w * np.sum(ce[1] * ve[1])
        out[r][m] = side[:, None] * h + up[:, None] * v
    return Correction(corr.grids, out)


def curvature_limit(path: NominalPath, run: int, sigma: np.ndarray, limits: PathLimits | None = None,
                    share: float = 0.9, blend: bool = False) -> np.ndarray:
    """Largest curvature [1/m] a correction may add at arc lengths ``sigma`` [m] of a feed run without
    slowing the program down.

    The interpolator sees a path written as pieces through junctions: a direction change ``dt`` at a
    junction costs the jerk ``v dt / T^2`` (:mod:`simulate.toolpath.interpolation`, limit ``beta J``).
    A corrected path of curvature ``k`` turns by ``k v T`` per cycle at speed ``v``, so the original
    speed is kept only while ``v^2 k / T <= beta J``, i.e. ``k <= share beta J T / v^2`` at the
    original program's local speed ``v`` (``share`` 0.9, the margin of :func:`_junction_limit`).

    With ``blend`` (``G64``) a junction is blended while ``dt (v / T^2 + A / T) <= beta J``
    (:mod:`simulate.toolpath.interpolation`): ``k <= share beta J T / (v (v + A T))``, at the original's
    local speed as above, so that the corrected program is not slower than the original anywhere; where
    the original cruises this is the blending rule at the feed. (At the feed cap everywhere, i.e. also
    where the original slows down for a corner, it smoothed away more correction near the corners:
    iso160 near, plain NC, sum ratio 0.382 instead of 0.320, square straightness 246 instead of 145 µm,
    both before the smoothing weight of :func:`limit_curvature` was made smooth.)
    """
    lim = limits or PathLimits()
    it = path.setup.interp
    v = np.interp(sigma, np.asarray(it.s, float), np.asarray(it.v, float))
    v = np.clip(v, 1e-4, None)
    return share * lim.junction_jerk_share * lim.jerk * lim.cycle / (v * (v + (lim.acceleration * lim.cycle
                                                                             if blend else 0.0)))


def limit_curvature(path: NominalPath, corr: Correction, s: CompensationSettings,
                    limits: PathLimits | None = None, max_passes: int = 400, share=0.9) -> Correction:
    """Smooth the correction locally until its curvature (second derivative along the path of the
    sideways and the upward component) stays below :func:`curvature_limit`.

    Why: a deviation the drives make on their own, e.g. a gear rattling in its play (a limit cycle
    whose phase the state, not the path, sets) or friction stick-slip, appears as a fast wave along
    the path. A mirror correction cannot cancel it (it is not a function of the commanded path), and
    writing it into the program makes the interpolator slow down at every junction (the program
    then takes longer than its contract allows). Only the part of the correction the program can
    carry at its own speed is kept; the mean (b/2 of a loaded gear, the deflection) stays.

    Each pass replaces the correction, where the limit is exceeded (widened by ``s.smoothing``), by
    its box average over ``s.smoothing``, blended in with a smooth weight so that no kink is made at
    the edge of the smoothed zone. ``share``: a float, or per run an array over its grid (lowered
    locally by :func:`keep_speed`).
    """
    out = []
    for r, g in enumerate(corr.grids):
        v = corr.values[r]
        if len(g) < 5:
            out.append(v)
            continue
        kmax = curvature_limit(path, r, g, limits, share[r] if isinstance(share, (list, tuple)) else share,
                               blend=s.blend)
        _, h, up = path.frame(r, g)
        comp = np.stack([np.sum(v * h, axis=1), np.sum(v * up, axis=1)], axis=1)
        dg = float(g[1] - g[0])
        for _ in range(max_passes):
            # curvature vector by the three-point second difference (np.gradient applied twice spans five
            # points and does not see a kink at one grid node, which a piece shorter than a cell turns at once)
            k = np.zeros(len(g))
            k[1:-1] = np.linalg.norm(np.diff(comp, 2, axis=0), axis=1) / dg ** 2
            bad = k > kmax
            bad[:2] = bad[-2:] = False   # one-sided differences at the run's ends
            if not bad.any():
                break
            # the zone (bad widened by 2 smoothing) as 0/1, then smoothed twice: the weight rises over about
            # 2 smoothing with a bounded second difference (clipping after smoothing made it a step within
            # one node, i.e. a kink in the output wherever the box average differed from the correction)
            zone = (_box(bad.astype(float), 2 * s.smoothing) > 1e-9).astype(float)
            w = _box(_box(zone, s.smoothing), s.smoothing)
            comp = comp + w[:, None] * (_box(comp, s.smoothing) - comp)
        out.append(comp[:, :1] * h + comp[:, 1:] * up)
    return Correction(corr.grids, out)


def ramp_in(path: NominalPath, corr: Correction, s: CompensationSettings, limits: PathLimits | None = None,
            share: float = 0.9) -> Correction:
    """Bring each feed run's correction in from zero after the run's start, where the written program
    starts from the uncorrected end of the rapid before it (:func:`write_program`).

    A correction ``c`` there would be taken up by the first pieces, which stay at least ``s.ramp``
    long while the original speeds up (:func:`plan_pieces`), as kinks the interpolator slows down for.
    The correction is zero until ``2 s.ramp`` after the original first cruises at the run's largest
    feed (past the last such piece), then rises as a smoothstep ``3 w^2 - 2 w^3`` over
    ``L = sqrt(6 c / k)``, whose largest curvature ``6 c / L^2`` is the curvature limit ``k`` at that
    feed (:func:`curvature_limit`), ``c`` the largest correction within 20 mm after the ramp's start.
    The test piece's runs begin with a plunge and a lead-in arc in the air, which take the ramp.
    """
    lim = limits or PathLimits()
    it0 = path.setup.interp
    s0, v0 = np.asarray(it0.s, float), np.asarray(it0.v, float)
    out = []
    for r, g in enumerate(corr.grids):
        v = corr.values[r]
        idx = np.flatnonzero(path.run == r)
        feed = min(max(path.segments[i].feed for i in idx), lim.max_speed)
        feed = max(feed, 1e-4)
        k = share * lim.junction_jerk_share * lim.jerk * lim.cycle / (
            feed * (feed + (lim.acceleration * lim.cycle if s.blend else 0.0)))   # as curvature_limit
        m = (s0 >= g[0]) & (s0 <= g[-1]) & (v0 >= 0.95 * feed)
        start = (float(s0[m][0]) if m.any() else g[0]) + 2 * s.ramp   # beyond the pieces of >= s.ramp
        c = float(np.linalg.norm(v[(g >= start) & (g <= start + 20e-3)], axis=1).max(initial=0.0))
        L = max(math.sqrt(6 * c / k), GRID)
        w = np.clip((g - start) / L, 0.0, 1.0)
        out.append(v * (w * w * (3 - 2 * w))[:, None])
    return Correction(corr.grids, out)


def slow_grid(path: NominalPath, written: WrittenProgram, setup: ProgramSetup, s: CompensationSettings) -> list:
    """Per feed run a mask over its grid: within ``s.smoothing`` of a cycle where the written program
    runs below ``SPEED_KEEP`` of the original's speed at the same nominal arc length. Where the
    original slows down itself (a corner, a run's start) the mask marks the corrected program's
    slower recovery after it too: a chain of short pieces, each junction at zero acceleration,
    speeds up slowly (:mod:`simulate.toolpath.interpolation`), and a smoother correction there
    needs fewer pieces."""
    it0 = path.setup.interp
    runs, sigma, _ = path_deviation(path, written, SimulationRun(setup, np.asarray(setup.interp.xyz)))
    v_orig = np.interp(sigma, np.asarray(it0.s, float), np.asarray(it0.v, float))
    slow = (runs >= 0) & (np.asarray(setup.interp.v) < SPEED_KEEP * v_orig)
    out = []
    for r, g in enumerate(Correction.zero(path).grids):
        sg = np.sort(sigma[slow & (runs == r)])
        if len(sg) == 0:
            out.append(np.zeros(len(g), bool))
            continue
        i = np.searchsorted(sg, g)
        left, right = sg[np.clip(i - 1, 0, len(sg) - 1)], sg[np.clip(i, 0, len(sg) - 1)]
        out.append(np.minimum(np.abs(g - left), np.abs(g - right)) <= s.smoothing)
    return out


def keep_speed(path: NominalPath, corr: Correction, s: CompensationSettings, header: str, file: Path, load,
               t_nom: float):
    """Write the correction as a program that keeps the original's feed: ``(setup, written, correction)``.

    The curvature limit (:func:`limit_curvature`) is the interpolator's junction rule at the edge;
    where the written program still runs slower than ``SPEED_KEEP`` of the original at the same place
    (a junction it must slow down for, and the slow re-acceleration over short pieces after it,
    :mod:`simulate.toolpath.interpolation`), the share of the limit is lowered there by
    ``SPEED_FACTOR`` and the program written again (interpolation only), ``SPEED_ROUNDS`` times at most.
    Why: a slower feed makes a thinner chip, a smaller cutting force and a smaller deflection than the
    correction was computed for; on iso160 the program ran below 90 % of its feed on 43 % of the cutting
    cycles and the square's walls got 100-200 µm gouges where it slowed. If the program then still
    runs longer than the time contract, the share is lowered everywhere (``CURVATURE_SHARES``).
    ``load(file) -> ProgramSetup`` reads a written program.
    """
    for share in CURVATURE_SHARES:
        local = [np.full(len(g), share) for g in corr.grids]
        rounds = SPEED_ROUNDS if s.keep_speed else 0
        for rnd in range(rounds + 1):
            out = limit_curvature(path, ramp_in(path, corr, s), s, share=local)
            wp = write_program(path, out, s, header=header)
            file.write_text(wp.text, encoding="utf-8")
            setup = load(file)
            if rnd == rounds:
                break
            slow = slow_grid(path, wp, setup, s)
            if not any(m.any() for m in slow):
                break
            for r, m in enumerate(slow):
                local[r][m] *= SPEED_FACTOR
        if setup.interp.duration / t_nom <= TIME_RATIO[1]:
            break
    return setup, wp, out


# ----------------------------------------------------------------------------- the iteration


@dataclass(frozen=True)
class Iteration:
    """One simulated program of the iteration (0: the original).

    Attributes
    ----------
    index : int
    table_sum : float or None
        Sum of |Table-2 deviation| [m].
    score : float or None
        Ranking score, sum of |deviation| / tolerance [-].
    path_rms : float
        RMS normal deviation of the tip from the nominal path over the feed runs [m].
    path_max : float
        Largest normal deviation [m].
    max_offset : float
        Largest correction [m].
    time_ratio : float
        Program time / original program time [-].
    speed_ratio : float
        Peak path speed on the feed moves / the original's [-] (:func:`feed_peak_speed`).
    pieces : int
        Feed pieces written.
    wall_time : float
        [s] of the simulation.
    rows_worse : int or None
        Table-2 rows worse than the original's (:func:`worse_rows`); None without a table.
    """

    index: int
    table_sum: float | None
    score: float | None
    path_rms: float
    path_max: float
    max_offset: float
    time_ratio: float
    speed_ratio: float
    pieces: int
    wall_time: float
    rows_worse: int | None = None

    @property
    def within_contract(self) -> bool:
        return (self.max_offset <= MAX_OFFSET and TIME_RATIO[0] <= self.time_ratio <= TIME_RATIO[1]
                and self.speed_ratio <= 1.0 + 1e-6)

    def objective(self) -> float:
        return self.table_sum if self.table_sum is not None else self.path_rms


@dataclass
class CompensationResult:
    """What :func:`compensate` gives.

    Attributes
    ----------
    path : NominalPath
    program : WrittenProgram
        The best corrected program.
    correction : Correction
        Its correction [m].
    before, after : SimulationRun
        The original and the best corrected program, simulated with the model.
    iterations : list of Iteration
    best : int
        Index of the best iteration (0: no improvement found; the program is then the original's
        pieces with a zero correction).
    deviation_before, deviation_after : Correction
        Normal deviation fields [m] (unsmoothed grid values) for the figure.
    checks : dict of float to (SimulationRun, SimulationRun)
        Stiffness scale [-] -> (original, corrected) simulated with the robot that much stiffer.
    """

    path: NominalPath
    program: WrittenProgram
    correction: Correction
    before: SimulationRun
    after: SimulationRun
    iterations: list
    best: int
    deviation_before: Correction
    deviation_after: Correction
    checks: dict = field(default_factory=dict)


def feed_peak_speed(setup: ProgramSetup) -> float:
    """Largest path speed [m/s] on the feed moves (G1/G2/G3) of an interpolated program. Rapids are
    left out: the corrected program moves them by micrometres, which changes the top speed of a short
    rapid that never reaches its cap."""
    segs = setup.parsed.segments
    feed = np.array([_is_feed(sg) for sg in segs])[np.asarray(setup.interp.segment)]
    return float(np.max(setup.interp.v[feed])) if feed.any() else 0.0


def worse_rows(before, after) -> list[str]:
    """Names of the Table-2 rows whose |deviation| grew by more than max(10 %, 2 µm) from ``before``
    to ``after`` (:class:`simulate.evaluation.features.FeatureTable`)."""
    return [rb.name for rb, ra in zip(before.rows, after.rows, strict=True)
            if abs(ra.deviation) > abs(rb.deviation) + max(WORSE_SHARE * abs(rb.deviation), WORSE_FLOOR)]


def better(it: Iteration, than: Iteration, original: Iteration) -> bool:
    """Whether ``it`` is a better result than ``than`` (module docstring, *Choosing*): within the
    contract and below the original's objective; then no row worse beats some row worse; then a lower
    objective. The original (index 0) is the fallback every candidate must beat."""
    if it.index == 0 or not it.within_contract or it.objective() >= original.objective():
        return False
    if than.index == 0:
        return True
    return (bool(it.rows_worse), it.objective()) < (bool(than.rows_worse), than.objective())


def _path_stats(dev: Correction) -> tuple[float, float]:
    v = np.concatenate([np.linalg.norm(x, axis=1) for x in dev.values]) if dev.values else np.zeros(1)
    return float(np.sqrt(np.mean(v ** 2))), float(v.max())


def _load(path_file: Path, nominal: NominalPath, spindle_rpm: float | None, require_spindle: bool) -> ProgramSetup:
    return load_program(path_file, stock=nominal.setup.stock, spindle_rpm=spindle_rpm, require_spindle=require_spindle,
                        source=str(path_file))


def compensate(nominal: ProgramSetup, simulate: Simulator, settings: CompensationSettings | None = None, *,
               checks=(), header: str = "", on_iteration=None, spindle_rpm: float | None = None,
               require_spindle: bool = False, tool_radius: float | None = None) -> CompensationResult:
    """Iterate the mirror compensation of ``nominal`` (module docstring).

    Parameters
    ----------
    nominal : ProgramSetup
        The original program (:func:`simulate.pipeline.load_program`).
    simulate : Simulator
        Usually :func:`pipeline_simulator`.
    settings : CompensationSettings
    checks : iterable of float
        Stiffness scales [-] at which both programs are simulated again after the iteration (the
        robot stiffer (>1) or softer (<1) than the model the compensation used).
    header : str
        Comment written at the top of the corrected program.
    on_iteration : callable(Iteration), optional
        Called after every simulation (progress).
    spindle_rpm, require_spindle
        As for :func:`simulate.pipeline.load_program` of the corrected programs.
    tool_radius : float, optional
        Cutter radius [m]: arcs of at most this radius get the correction blended between their
        neighbours' (:func:`blend_corners`).
    """
    s = settings or CompensationSettings()
    s.validate()
    for sc in checks:
        if not (math.isfinite(sc) and sc > 0):
            raise InputError(f"stiffness scale must be > 0, got {sc!r}", field="check-scale")
    path = NominalPath.of(nominal)
    t_nom = nominal.interp.duration
    v_nom = feed_peak_speed(nominal)
    corr = Correction.zero(path)
    run = simulate(nominal, 1.0)
    raw = deviation_field(path, None, run, GRID)
    dev = deviation_field(path, None, run, s.smoothing)
    rms, mx = _path_stats(raw)
    it0 = Iteration(0, table_sum(run.table) if run.table is not None else None,
                    run.table.score if run.table is not None else None, rms, mx, 0.0, 1.0, 1.0, 0, run.wall_time,
                    None if run.table is None else 0)
    iters = [it0]
    if on_iteration:
        on_iteration(it0)
    real = corr
    best = (0, corr, run, None, raw)
    run0, before_raw = run, raw
    prev = None
    stale, lowest = 0, it0.objective()

    def load(f: Path) -> ProgramSetup:
        return _load(f, path, spindle_rpm, require_spindle)

    with tempfile.TemporaryDirectory(prefix="greybench-compensate-") as tmp:
        for k in range(1, s.iterations + 1):
            new = update_correction(real, dev, prev, s)
            prev = (real, dev)
            blended = blend_corners(path, new, tool_radius) if tool_radius else new
            # written so that the program keeps the original's feed (interpolation only, no simulation)
            setup, wp, corr = keep_speed(path, blended, s, f"{header} iteration {k}".strip(),
                                         Path(tmp) / f"iteration{k}.nc", load, t_nom)
            run = simulate(setup, 1.0)
            raw = deviation_field(path, wp, run, GRID)
            dev = deviation_field(path, wp, run, s.smoothing)
            # the correction the pieces realise (a run starts at an uncorrected rapid end): the update
            # starts from it, so what the program cannot realise does not wind up
            real = deviation_field(path, wp, run, GRID, points=setup.interp.xyz)
            rms, mx = _path_stats(raw)
            it = Iteration(k, table_sum(run.table) if run.table is not None else None,
                           run.table.score if run.table is not None else None, rms, mx, corr.max_norm(),
                           setup.interp.duration / t_nom, feed_peak_speed(setup) / v_nom, wp.n_pieces,
                           run.wall_time,
                           None if run.table is None or run0.table is None else len(worse_rows(run0.table, run.table)))
            iters.append(it)
            if on_iteration:
                on_iteration(it)
            if better(it, iters[best[0]], it0):
                best = (k, corr, run, wp, raw)
            # progress is the objective's, whatever the rows: a step may pass through more rows worse
            stale = 0 if it.objective() < lowest else stale + 1
            lowest = min(lowest, it.objective())
            if not it.within_contract or stale >= PATIENCE:
                break
        k, corr_b, run_b, wp_b, raw_b = best
        if wp_b is None:   # nothing improved: the original's pieces, no correction
            wp_b = write_program(path, corr_b, s, header=f"{header} no correction".strip())
        out = {}
        for sc in checks:
            f = Path(tmp) / "best.nc"
            f.write_text(wp_b.text, encoding="utf-8")
            setup_b = _load(f, path, spindle_rpm, require_spindle)
            out[float(sc)] = (simulate(nominal, float(sc)), simulate(setup_b, float(sc)))
    return CompensationResult(path, wp_b, corr_b, run0, run_b, iters, k, before_raw, raw_b, out)
